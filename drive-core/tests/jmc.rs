//! The JMC map (seed 001) at the level of frames: every frame the manual prints with a valid
//! CRC answered byte for byte, in the order its routines send them, with both word orders; the
//! exception codes of §4 with nothing changed; the set-points of §6.1 landing where the routine
//! says; and the power state machine of CiA 402 behind 0x6040/0x6041.

mod common;

use common::frame;
use drive_core::faults::Inputs;
use drive_core::maps::Maps;
use drive_core::od::{OBJECTS, Obj};
use drive_core::power::DeviceState;
use drive_core::{Drive, DriveConfig, Instant};

/// A JMC drive with a clock.
type Rig = common::MapRig;

fn jmc_rig() -> Rig {
    Rig::new(Maps::jmc())
}

impl Rig {
    fn write32(&mut self, addr: u16, v: i32) -> Result<(), u8> {
        let [a, b] = addr.to_be_bytes();
        let v = v as u32;
        let words = if self.drive.state().read(Obj::MapWordOrder) == 0 { [v >> 16, v] } else { [v, v >> 16] };
        let mut body = vec![1, 0x10, a, b, 0, 2, 4];
        for w in words {
            body.extend_from_slice(&(w as u16).to_be_bytes());
        }
        self.request(&body).map(|_| ())
    }

    fn statusword(&mut self) -> u16 {
        self.read(0x6041, 1).expect("statusword")[0]
    }

    /// Runs until the axis stands, at most `s` seconds.
    fn settle(&mut self, s: u64) {
        for _ in 0..s * 10 {
            if self.drive.state().controller().axis().is_still() {
                return;
            }
            self.run(100_000);
        }
        panic!("still moving after {s} s");
    }

    fn snapshot(&self) -> (Vec<u32>, DeviceState, i64) {
        let st = self.drive.state();
        (
            OBJECTS.iter().filter(|d| !d.obj.is_diagnostic()).map(|d| st.read_def(d)).collect(),
            st.device_state(),
            st.position(),
        )
    }
}

fn hex(s: &str) -> Vec<u8> {
    s.split_whitespace().map(|b| u8::from_str_radix(b, 16).expect("hex")).collect()
}

/// A routine's frames in the manual's order: each request (its CRC valid), and the reply the
/// manual prints, or where it prints none: the echo of a 0x06, the standard reply to a 0x10.
type Routine = &'static [(&'static str, Option<&'static str>)];

/// Every frame seed 001 prints with a valid CRC (`../shared/seed-frames.md`), in the order of
/// its sections, with the two misprints mended (line 519's missing byte, line 1040's function
/// code 06 for 86, the reply of lines 1005/1011 with its quantity 04 for 02).
const PRINTED: [(&str, Routine); 7] = [
    (
        "explanation (lines 519-600)",
        &[
            (
                "01 10 60 40 00 09 12 00 0F 00 01 00 00 00 64 00 64 00 64 00 64 00 03 0D 40 40 1C",
                Some("01 10 60 40 00 09 1F DB"),
            ),
            ("01 06 60 83 00 64 67 C9", None),
            ("01 06 60 84 00 64 D6 08", None),
            ("01 10 60 7A 00 02 04 00 03 0D 40 29 96", Some("01 10 60 7A 00 02 7E 11")),
            ("01 03 60 7A 00 02 FB D2", Some("01 03 04 00 03 0D 40 0F 53")),
            // 0x6000 = 1 (not printed as a frame), then lines 569 and 591.
            ("01 06 60 00 00 01 56 0A", None),
            ("01 10 60 7A 00 02 04 0D 40 00 03 9F 8F", Some("01 10 60 7A 00 02 7E 11")),
            ("01 03 60 7A 00 02 FB D2", Some("01 03 04 0D 40 00 03 B9 4A")),
            ("01 06 60 00 00 00 97 CA", None),
            ("01 10 60 7A 00 02 04 00 03 0D 40 29 96", Some("01 10 60 7A 00 02 7E 11")),
            ("01 03 60 7A 00 02 FB D2", Some("01 03 04 00 03 0D 40 0F 53")),
        ],
    ),
    (
        "position mode, one point (lines 608-640)",
        &[
            ("01 06 60 40 00 01 57 DE", None),
            ("01 06 60 40 00 03 D6 1F", None),
            ("01 06 60 40 00 0F D6 1A", None),
            ("01 06 60 60 00 01 56 14", None),
            ("01 10 60 81 00 02 04 00 00 00 0A 12 06", Some("01 10 60 81 00 02 0F E0")),
            ("01 06 60 83 00 64 67 C9", None),
            ("01 06 60 84 00 64 D6 08", None),
            ("01 10 60 81 00 04 08 00 00 00 0A 00 64 00 64 10 52", Some("01 10 60 81 00 04 8F E2")),
            ("01 10 60 7A 00 02 04 00 03 0D 40 29 96", Some("01 10 60 7A 00 02 7E 11")),
            ("01 06 60 40 00 1F D7 D6", None),
            ("01 06 60 40 00 0F D6 1A", None),
        ],
    ),
    (
        "position mode, points with a stop between (lines 646-658)",
        &[
            ("01 10 60 81 00 02 04 00 00 00 32 13 D4", Some("01 10 60 81 00 02 0F E0")),
            ("01 10 60 7A 00 02 04 00 03 0D 40 29 96", Some("01 10 60 7A 00 02 7E 11")),
            ("01 06 60 40 00 1F D7 D6", None),
            ("01 06 60 40 00 0F D6 1A", None),
            ("01 10 60 81 00 02 04 00 00 00 64 93 EA", Some("01 10 60 81 00 02 0F E0")),
            ("01 10 60 7A 00 02 04 00 09 27 C0 17 54", Some("01 10 60 7A 00 02 7E 11")),
            ("01 06 60 40 00 1F D7 D6", None),
        ],
    ),
    (
        "position mode, points without a stop and at once (lines 672-714)",
        &[
            ("01 06 60 40 00 0F D6 1A", None),
            ("01 10 60 81 00 02 04 00 00 00 32 13 D4", Some("01 10 60 81 00 02 0F E0")),
            ("01 10 60 7A 00 02 04 00 03 0D 40 29 96", Some("01 10 60 7A 00 02 7E 11")),
            ("01 06 60 40 02 5F D7 46", None),
            ("01 06 60 40 02 4F D6 8A", None),
            ("01 10 60 81 00 02 04 00 00 00 64 93 EA", Some("01 10 60 81 00 02 0F E0")),
            ("01 10 60 7A 00 02 04 00 09 27 C0 17 54", Some("01 10 60 7A 00 02 7E 11")),
            ("01 06 60 40 02 5F D7 46", None),
            ("01 06 60 40 02 4F D6 8A", None),
            ("01 10 60 81 00 02 04 00 00 00 32 13 D4", Some("01 10 60 81 00 02 0F E0")),
            ("01 10 60 7A 00 02 04 00 03 0D 40 29 96", Some("01 10 60 7A 00 02 7E 11")),
            ("01 06 60 40 00 7F D7 FE", None),
            ("01 06 60 40 00 6F D6 32", None),
            ("01 10 60 81 00 02 04 00 00 00 64 93 EA", Some("01 10 60 81 00 02 0F E0")),
            ("01 10 60 7A 00 02 04 00 09 27 C0 17 54", Some("01 10 60 7A 00 02 7E 11")),
            ("01 06 60 40 02 7F D6 9E", None),
        ],
    ),
    (
        "velocity mode (lines 764-792)",
        &[
            ("01 06 60 40 00 01 57 DE", None),
            ("01 06 60 40 00 03 D6 1F", None),
            ("01 06 60 40 00 0F D6 1A", None),
            ("01 06 60 60 00 03 D7 D5", None),
            ("01 06 60 40 01 0F D7 8A", None),
            ("01 10 60 81 00 02 04 00 00 00 0A 12 06", Some("01 10 60 81 00 02 0F E0")),
            ("01 06 60 83 00 64 67 C9", None),
            ("01 06 60 84 00 64 D6 08", None),
            ("01 10 60 81 00 04 08 00 00 00 0A 00 64 00 64 10 52", Some("01 10 60 81 00 04 8F E2")),
            ("01 06 60 40 00 0F D6 1A", None),
            ("01 10 60 81 00 02 04 00 00 00 64 93 EA", Some("01 10 60 81 00 02 0F E0")),
            ("01 06 60 40 01 0F D7 8A", None),
        ],
    ),
    (
        "homing mode (line 872)",
        &[
            ("01 06 60 40 00 01 57 DE", None),
            ("01 06 60 40 00 03 D6 1F", None),
            ("01 06 60 40 00 0F D6 1A", None),
            ("01 06 60 60 00 06 17 D6", None),
            ("01 06 60 98 00 01 D7 E5", None),
            ("01 06 60 9A 03 E8 B7 5B", None),
            ("01 10 60 99 00 02 04 00 00 00 64 93 40", Some("01 10 60 99 00 02 8F E7")),
            ("01 10 60 9B 00 02 04 00 00 00 64 12 99", Some("01 10 60 9B 00 02 2E 27")),
            ("01 10 60 7C 00 02 04 00 00 03 E8 5C 62", Some("01 10 60 7C 00 02 9E 10")),
            (
                "01 10 60 7C 00 08 10 00 00 03 E8 00 01 00 00 00 64 03 E8 00 00 00 64 09 42",
                Some("01 10 60 7C 00 08 1E 17"),
            ),
        ],
    ),
    (
        "function codes and exceptions (lines 930-1040)",
        &[
            ("01 10 60 7A 00 02 04 00 03 0D 40 29 96", Some("01 10 60 7A 00 02 7E 11")),
            ("01 03 60 7A 00 02 FB D2", Some("01 03 04 00 03 0D 40 0F 53")),
            ("01 10 60 83 00 02 04 00 64 00 64 53 EC", Some("01 10 60 83 00 02 AE 20")),
            ("01 06 60 90 00 03 D7 E6", Some("01 86 0B 03 A7")),
        ],
    ),
];

/// A JMC drive at 1/16 microsteps (set natively: the manual has no register for it), so that
/// the routines' 200 000 and 600 000 steps run in about a minute of simulated time each.
fn sixteenth() -> Rig {
    let mut r = jmc_rig();
    assert_eq!(r.drive.state_mut().write_def(Obj::Microsteps.def(), 16), Ok(()));
    r
}

#[test]
fn every_printed_frame_is_answered_as_printed() {
    for (routine, frames) in PRINTED {
        // Each routine from power-up, as the manual has them; the position routines that follow
        // the first one from where it left the drive.
        let mut r = sixteenth();
        if routine.starts_with("position mode, points") {
            for (req, _) in PRINTED[1].1 {
                r.exchange(&hex(req)).expect("answered");
            }
            r.settle(300);
        }
        for &(req, reply) in frames {
            let req = hex(req);
            let expected = match reply {
                Some(reply) => hex(reply),
                // The echo of a 0x06; the standard reply to a 0x10 (address, quantity, CRC).
                None if req[1] == 0x10 => frame(&req[..6]),
                None => req.clone(),
            };
            assert_eq!(r.exchange(&req), Some(expected), "{routine}: {req:02X?}");
        }
    }
    // Line 972: device 2's write of 0x6060 = 3 (its CRC printed as XX XX: D7 E6).
    let mut two =
        Drive::with_map(DriveConfig { address: drive_core::SlaveAddr::new(2), ..DriveConfig::default() }, Maps::jmc());
    two.on_rx(Instant::from_micros(0), &hex("02 06 60 60 00 03 D7 E6"));
    two.on_timer(Instant::from_micros(4_011));
    assert_eq!(two.take_reply(), Some(&hex("02 06 60 60 00 03 D7 E6")[..]));
}

/// The single point of §6.1 moves to its target and the statusword says so; §6.2 runs at
/// 0x6081 and changes speed; §6.3's parameters land in the drive's homing objects.
#[test]
fn the_routines_act_as_printed() {
    let mut r = sixteenth();
    for (req, _) in PRINTED[1].1 {
        r.exchange(&hex(req)).expect("answered");
    }
    assert_eq!(r.drive.state().device_state(), DeviceState::OperationEnabled);
    // 0x6081 = 10: 1 rev/s at 1/16 microsteps (3200 a revolution) is 3200 a second.
    assert_eq!(r.drive.state().read_i32(Obj::PpRunSpeed), 3200);
    assert_eq!(r.drive.state().read(Obj::PpAccel), 32_000);
    assert_ne!(r.statusword() & (1 << 9), 0, "moving");
    r.settle(200);
    assert_eq!(r.drive.state().position(), 200_000);
    let sw = r.statusword();
    assert_eq!(sw & 0x6F, 0x27, "operation enabled: {sw:#06x}");
    assert_ne!(sw & (1 << 10), 0, "target reached: {sw:#06x}");
    // §6.2's start: velocity mode, halted, parameters, then bit 8 cleared runs at 0x6081.
    for (req, _) in &PRINTED[4].1[3..10] {
        r.exchange(&hex(req)).expect("answered");
    }
    r.run(2_000_000);
    let v = |r: &Rig| f64::from(r.drive.state().controller().axis().setpoint().velocity);
    assert!((v(&r) - 3200.0).abs() < 0.01, "1 rev/s: {}", v(&r));
    r.exchange(&hex(PRINTED[4].1[10].0)).expect("answered");
    r.run(2_000_000);
    assert!((v(&r) - 32_000.0).abs() < 0.01, "10 rev/s: {}", v(&r));
    r.exchange(&hex(PRINTED[4].1[11].0)).expect("answered");
    r.settle(10);
    for (req, _) in &PRINTED[5].1[3..] {
        r.exchange(&hex(req)).expect("answered");
    }
    // JMC's method 1 is the engine's -3 (a 16-bit register).
    assert_eq!(r.drive.state().read(Obj::HomingMethod), 0xFFFD);
    assert_eq!(r.drive.state().read(Obj::HomingZeroSpeed), 32_000);
    assert_eq!(r.drive.state().read(Obj::HomingSearchSpeed), 32_000);
    assert_eq!(r.drive.state().read(Obj::HomingAccel), 320_000);
    assert_eq!(r.drive.state().read_i32(Obj::HomingOffset), -1000);
    assert_eq!(r.read(0x6061, 1), Ok(vec![6]));
}

/// 0x6000 = 1: 32-bit registers low word first (lines 569-571, 591).
#[test]
fn word_order_one_swaps_the_halves() {
    let mut r = jmc_rig();
    assert_eq!(r.write(0x6000, 1), Ok(()));
    let req = "01 10 60 7A 00 02 04 0D 40 00 03 9F 8F";
    assert_eq!(r.exchange(&hex(req)), Some(hex("01 10 60 7A 00 02 7E 11")));
    assert_eq!(r.drive.state().read_i32(Obj::PpTarget), 200_000);
    assert_eq!(r.exchange(&hex("01 03 60 7A 00 02 FB D2")), Some(hex("01 03 04 0D 40 00 03 B9 4A")));
    assert_eq!(r.write(0x6000, 0), Ok(()));
    assert_eq!(r.exchange(&hex("01 03 60 7A 00 02 FB D2")), Some(hex("01 03 04 00 03 0D 40 0F 53")));
}

/// §4's codes: each refusal answers its code and changes nothing.
#[test]
fn exceptions_change_nothing() {
    let mut r = jmc_rig();
    r.write(0x6040, 0x0F).expect("enable");
    let before = r.snapshot();
    // §7.5: no such register.
    assert_eq!(r.exchange(&hex("01 06 60 90 00 03 D7 E6")), Some(hex("01 86 0B 03 A7")));
    let cases: [(&[u8], u8); 9] = [
        // A read-only register written: 5.
        (&[1, 0x06, 0x60, 0x41, 0, 1], 5),
        (&[1, 0x10, 0x60, 0x64, 0, 2, 4, 0, 0, 0, 1], 5),
        // A write-only register read: 7.
        (&[1, 0x03, 0x60, 0x40, 0, 1], 7),
        (&[1, 0x03, 0x60, 0x5A, 0, 3], 7),
        // A byte count that is not twice the quantity: 8.
        (&[1, 0x10, 0x60, 0x83, 0, 2, 3, 0, 0x64, 0], 8),
        // A 32-bit register written one half at a time: 2.
        (&[1, 0x06, 0x60, 0x7A, 0, 3], 2),
        // Values out of range: 3 (torque mode 4, word order 2, homing method 9).
        (&[1, 0x06, 0x60, 0x60, 0, 4], 3),
        (&[1, 0x06, 0x60, 0x00, 0, 2], 3),
        (&[1, 0x06, 0x60, 0x98, 0, 9], 3),
    ];
    for (body, code) in cases {
        assert_eq!(r.request(body), Err(code), "{body:02X?}");
        assert_eq!(r.snapshot(), before, "{body:02X?} changed the drive");
    }
    // A 0x10 whose last value is refused writes none of those before it (all or nothing).
    let body = [1, 0x10, 0x60, 0x83, 0, 3, 6, 0, 0x32, 0, 0x32, 0, 0];
    assert_eq!(r.request(&body), Err(3));
    assert_eq!(r.snapshot(), before);
}

/// §6.1's multi-point examples (lines 644-714): stopping between points, going on without a
/// stop, changing at once; the "no stop" and "at once" frames set bit 6 (relative), so their
/// second target adds to the first.
#[test]
fn position_routines_land_where_the_controlword_says() {
    let cases: [(u16, u16, i64); 3] = [(0x001F, 0x000F, 600_000), (0x025F, 0x024F, 800_000), (0x007F, 0x006F, 800_000)];
    for (start, clear, end) in cases {
        let mut r = jmc_rig();
        for cw in [0x01, 0x03, 0x0F] {
            r.write(0x6040, cw).expect("power up");
        }
        r.write(0x6060, 1).expect("position mode");
        r.write(0x6083, 100).expect("acceleration");
        r.write(0x6084, 100).expect("deceleration");
        r.write32(0x6081, 50).expect("5 rev/s");
        r.write32(0x607A, 200_000).expect("first target");
        r.write(0x6040, start).expect("new set-point");
        r.write(0x6040, clear).expect("bit 4 cleared");
        r.run(50_000);
        r.write32(0x6081, 100).expect("10 rev/s");
        r.write32(0x607A, 600_000).expect("second target");
        let second = if start == 0x007F { 0x027F } else { start };
        r.write(0x6040, second).expect("second set-point");
        r.settle(2_000);
        assert_eq!(r.drive.state().position(), end, "controlword {start:#06x}");
        let sw = r.statusword();
        assert_ne!(sw & (1 << 10), 0, "target reached: {sw:#06x}");
    }
}

/// Every command in every state, as CiA 402's table has it, through the drive's own objects
/// (0x2180-0x2182 of the native map): the state after, its statusword bits and whether the
/// motor is energised. Commands the table does not have in a state change nothing.
#[test]
fn the_state_machine_follows_the_table() {
    use DeviceState as S;
    const SHUTDOWN: u16 = 0x06;
    const SWITCH_ON: u16 = 0x07;
    const ENABLE: u16 = 0x0F;
    const DISABLE_VOLTAGE: u16 = 0x00;
    const QUICK_STOP: u16 = 0x02;
    const RESET: u16 = 0x80;
    // The way to each state from power-up, and what each command leads to there.
    let table: [(S, &[u16], [S; 6]); 6] = [
        (
            S::SwitchOnDisabled,
            &[],
            [
                S::ReadyToSwitchOn,
                S::SwitchOnDisabled,
                S::OperationEnabled,
                S::SwitchOnDisabled,
                S::SwitchOnDisabled,
                S::SwitchOnDisabled,
            ],
        ),
        (
            S::ReadyToSwitchOn,
            &[SHUTDOWN],
            [
                S::ReadyToSwitchOn,
                S::SwitchedOn,
                S::OperationEnabled,
                S::SwitchOnDisabled,
                S::SwitchOnDisabled,
                S::ReadyToSwitchOn,
            ],
        ),
        (
            S::SwitchedOn,
            &[SHUTDOWN, SWITCH_ON],
            [
                S::ReadyToSwitchOn,
                S::SwitchedOn,
                S::OperationEnabled,
                S::SwitchOnDisabled,
                S::SwitchOnDisabled,
                S::SwitchedOn,
            ],
        ),
        (
            S::OperationEnabled,
            &[SHUTDOWN, SWITCH_ON, ENABLE],
            [
                S::ReadyToSwitchOn,
                S::SwitchedOn,
                S::OperationEnabled,
                S::SwitchOnDisabled,
                S::QuickStopActive,
                S::OperationEnabled,
            ],
        ),
        (
            S::QuickStopActive,
            &[SHUTDOWN, SWITCH_ON, ENABLE, QUICK_STOP],
            [
                S::QuickStopActive,
                S::QuickStopActive,
                S::OperationEnabled,
                S::SwitchOnDisabled,
                S::QuickStopActive,
                S::QuickStopActive,
            ],
        ),
        (
            S::Fault,
            &[SHUTDOWN, SWITCH_ON, ENABLE],
            [S::Fault, S::Fault, S::Fault, S::Fault, S::Fault, S::SwitchOnDisabled],
        ),
    ];
    let commands = [SHUTDOWN, SWITCH_ON, ENABLE, DISABLE_VOLTAGE, QUICK_STOP, RESET];
    for (state, path, after) in table {
        for (cmd, expected) in commands.into_iter().zip(after) {
            let mut b = common::Bus::factory();
            let write = |b: &mut common::Bus, addr: u16, v: u16| {
                let [a, c] = addr.to_be_bytes();
                let [d, e] = v.to_be_bytes();
                let reply = b.request(&[1, 0x06, a, c, d, e]);
                assert_eq!(reply, common::reply(&[1, 0x06, a, c, d, e]), "{addr:#06x} = {v:#06x}");
            };
            // Stay in quick stop active once stopped (option 6), and start from switch on
            // disabled (the native map powers up enabled).
            write(&mut b, 0x2182, 6);
            write(&mut b, 0x2180, DISABLE_VOLTAGE);
            for &cw in path {
                write(&mut b, 0x2180, cw);
            }
            if state == S::Fault {
                // An over-voltage latches: the fault state, the motor off.
                let inputs = Inputs { supply_mv: Some(70_000), ..Inputs::default() };
                b.drive.tick_with(Instant::from_micros(b.now), &inputs);
                b.drive.tick_with(Instant::from_micros(b.now + 50), &Inputs::default());
            }
            assert_eq!(b.drive.state().device_state(), state, "reaching {state:?}");
            write(&mut b, 0x2180, cmd);
            let st = b.drive.state();
            assert_eq!(st.device_state(), expected, "{state:?} on {cmd:#04x}");
            assert_eq!(st.read(Obj::DeviceStatus) as u16 & 0x6F, expected.statusword() & 0x6F);
            let out = b.drive.tick(Instant::from_micros(b.now + 100));
            assert_eq!(out.enabled, expected.energised(), "{state:?} on {cmd:#04x}: power stage");
        }
    }
}

/// A quick stop ramps down at 0x6085 and, with JMC's option 2, ends switch on disabled; a
/// fault (the over-voltage) shows as the fault state until bit 7 rises, which leaves the drive
/// switch on disabled; a fault reset with the condition still present stays in fault.
#[test]
fn quick_stop_and_fault_reset() {
    let mut r = jmc_rig();
    r.write(0x6040, 0x0F).expect("enable");
    r.write(0x6060, 3).expect("velocity mode");
    r.write(0x6085, 50).expect("quick-stop deceleration 5 rev/s²");
    r.write(0x605A, 2).expect("quick stop at 0x6085");
    r.write32(0x6081, 10).expect("1 rev/s");
    r.write(0x6040, 0x010F).expect("halt");
    r.write(0x6040, 0x000F).expect("run");
    r.run(1_000_000);
    assert_eq!(r.drive.state().controller().axis().setpoint().velocity, 200.0);
    r.write(0x6040, 0x000B).expect("quick stop");
    assert_eq!(r.statusword() & 0x6F, 0x07, "quick stop active");
    // 200 steps/s at 1000 steps/s²: 0.2 s.
    r.run(150_000);
    assert!(!r.drive.state().controller().axis().is_still(), "still ramping");
    r.run(200_000);
    assert!(r.drive.state().controller().axis().is_still());
    assert_eq!(r.statusword() & 0x6F, 0x40, "switch on disabled");
    assert_eq!(r.write32(0x607A, 100), Ok(()));
    // Faults.
    r.write(0x6040, 0x0F).expect("enable again");
    r.inputs.supply_mv = Some(70_000);
    r.run(1_000);
    assert_eq!(r.statusword() & 0x4F, 0x08, "fault");
    assert_ne!(r.read(0x1001, 1).expect("error register")[0] & 0b101, 0, "voltage");
    r.write(0x6040, 0x80).expect("fault reset");
    assert_eq!(r.statusword() & 0x4F, 0x08, "the over-voltage is still there");
    r.inputs.supply_mv = Some(24_000);
    r.write(0x6040, 0x00).expect("bit 7 down");
    r.write(0x6040, 0x80).expect("fault reset");
    assert_eq!(r.statusword() & 0x6F, 0x40, "switch on disabled");
    assert_eq!(r.read(0x1001, 1), Ok(vec![0]));
}

proptest::proptest! {
    /// 0.1 rev/s and 0.1 rev/s² become microsteps exactly at every resolution and come back as
    /// written: through the scale, and through the map's registers (a speed written reads back).
    #[test]
    fn tenth_revolution_units_round_trip(
        v in 0i64..=100_000,
        k in 0usize..9,
        speed in 1i32..=1500,
    ) {
        use drive_core::maps::layout::{Scale, FULL_STEPS_PER_REV};
        let microsteps = [0u32, 2, 4, 8, 16, 32, 64, 128, 256][k];
        let per_rev = FULL_STEPS_PER_REV * i64::from(microsteps.max(1));
        let scale = Scale::PerRev(1, 10);
        let drive = scale.to_drive(v, per_rev).expect("in range");
        // per_rev / 10 is a whole number of microsteps at every resolution: exact both ways.
        proptest::prop_assert_eq!(drive * 10, v * per_rev);
        proptest::prop_assert_eq!(scale.to_map(drive, per_rev), Some(v));
        // Through the registers: the resolution set natively, the speed written and read back.
        let mut r = jmc_rig();
        let d = r.drive.state_mut().write_def(Obj::Microsteps.def(), microsteps);
        proptest::prop_assert_eq!(d, Ok(()));
        let pps = i64::from(speed) * per_rev / 10;
        if (150..=300_000).contains(&pps) {
            proptest::prop_assert_eq!(r.write32(0x6081, speed), Ok(()));
            proptest::prop_assert_eq!(i64::from(r.drive.state().read_i32(Obj::PpRunSpeed)), pps);
            let w = r.read(0x6081, 2).expect("read");
            proptest::prop_assert_eq!((i32::from(w[0]) << 16) | i32::from(w[1]), speed);
        } else {
            proptest::prop_assert_eq!(r.write32(0x6081, speed), Err(3));
        }
    }
}

/// 0x2190 takes the maps the platform carries, refuses the others (04) with nothing changed,
/// and a number that is no map (03).
#[test]
fn the_register_map_takes_only_a_map_the_platform_carries() {
    let mut b = common::Bus::factory();
    assert_eq!(b.request(&[1, 0x06, 0x21, 0x90, 0, 1]), common::reply(&[1, 0x06, 0x21, 0x90, 0, 1]));
    assert_eq!(b.drive.state().read(Obj::RegisterMap), 1);
    assert_eq!(b.request(&[1, 0x06, 0x21, 0x90, 0, 5]), common::reply(&[1, 0x86, 0x03]));
    b.drive.state_mut().set_maps(1);
    assert_eq!(b.request(&[1, 0x06, 0x21, 0x90, 0, 0]), common::reply(&[1, 0x06, 0x21, 0x90, 0, 0]));
    assert_eq!(b.request(&[1, 0x06, 0x21, 0x90, 0, 1]), common::reply(&[1, 0x86, 0x04]));
    assert_eq!(b.drive.state().read(Obj::RegisterMap), 0);
}
