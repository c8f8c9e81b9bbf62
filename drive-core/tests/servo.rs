//! The servo map (seed 004) at the level of frames: the parameters this excerpt describes, the
//! reserved ones, servo-on through the communication IO, both jogs, the position data groups'
//! chain on its step-change conditions, the communication timeout and its alarm cleared through
//! 0521h, the alarm history, refusals that change nothing, and the units both ways.

mod common;

use drive_core::maps::Maps;
use drive_core::od::{OBJECTS, Obj};

type Rig = common::MapRig;

/// Registers of §6.4.
const SPEED_JOG: u16 = 0x0528;
const POSITION_JOG: u16 = 0x0529;
const COMM_IO: u16 = 0x0451;
const SON: u16 = 1;
const POS_START: u16 = 1 << 13;
const POS_STEP: u16 = 1 << 14;

fn servo() -> Rig {
    Rig::new(Maps::servo())
}

impl Rig {
    /// Writes two registers low word first (0x10).
    fn write32(&mut self, addr: u16, v: i32) -> Result<(), u8> {
        let [a, b] = addr.to_be_bytes();
        let [h0, h1, l0, l1] = v.to_be_bytes();
        self.request(&[1, 0x10, a, b, 0, 2, 4, l0, l1, h0, h1]).map(|_| ())
    }

    fn read32(&mut self, addr: u16) -> i32 {
        let w = self.read(addr, 2).expect("read");
        ((u32::from(w[1]) << 16) | u32::from(w[0])) as i32
    }

    fn position(&self) -> i64 {
        i64::from(self.drive.state().read_i32(Obj::Position))
    }

    fn moving(&self) -> bool {
        self.drive.state().read(Obj::RunState) == 3
    }

    /// Runs until the axis stands (at most `s` seconds).
    fn settle(&mut self, s: u64) {
        for _ in 0..s * 100 {
            self.run(10_000);
            if !self.moving() {
                return;
            }
        }
        panic!("still moving after {s} s");
    }

    /// Writes group `g`: target, speed r/min, and attribute, conditions 1 and 2, next, type.
    fn group(&mut self, g: u16, target: i32, rpm: u16, [attr, c1, c2, next, kind]: [u16; 5]) {
        let [h0, h1, l0, l1] = target.to_be_bytes();
        let words = [u16::from_be_bytes([l0, l1]), u16::from_be_bytes([h0, h1]), rpm, attr, c1, c2, next, kind];
        let [a, b] = (0x0600 + 8 * g).to_be_bytes();
        let mut body = vec![1, 0x10, a, b, 0, 8, 16];
        for w in words {
            body.extend_from_slice(&w.to_be_bytes());
        }
        self.request(&body).expect("group written");
    }

    fn snapshot(&self) -> (Vec<u32>, i64) {
        let s = self.drive.state();
        (OBJECTS.iter().filter(|d| !d.obj.is_diagnostic()).map(|d| s.read_def(d)).collect(), self.position())
    }
}

#[test]
fn powers_up_servo_off_and_son_energises() {
    let mut r = servo();
    // 0457h: 1 enable off.
    assert_eq!(r.read(0x0457, 1), Ok(vec![1]));
    r.write(COMM_IO, SON).expect("servo on");
    r.run(2_000);
    assert_eq!(r.read(0x0457, 1), Ok(vec![2]));
    assert_eq!(r.read(COMM_IO, 1), Ok(vec![SON]));
    r.write(COMM_IO, 0).expect("servo off");
    r.run(2_000);
    assert_eq!(r.read(0x0457, 1), Ok(vec![1]));
}

#[test]
fn parameters_act_and_reserved_ones_refuse() {
    let mut r = servo();
    // P□304, jog speed, 60 r/min at the factory 200 pulses a revolution: 200 pps.
    r.write(0x0130, 60).expect("P304");
    assert_eq!(r.drive.state().read(Obj::JogSpeed), 200);
    assert_eq!(r.read(0x0130, 1), Ok(vec![60]));
    // P□601 node id 1-127; P□602 timeout.
    assert_eq!(r.write(0x0259, 0), Err(3));
    assert_eq!(r.write(0x0259, 128), Err(3));
    r.write(0x0259, 7).expect("P601");
    assert_eq!(r.drive.state().read(Obj::NodeId), 7);
    // P□600: 0x32 = ASCII 8E1... digit 1 = 4 (ASCII 8E1), digit 0 = 2 (19200).
    r.write(0x0258, 0x42).expect("P600");
    assert_eq!(r.drive.state().read(Obj::BaudRate), 19_200);
    assert_eq!(r.drive.state().read(Obj::Parity), 1);
    assert_eq!(r.drive.state().read(Obj::LineFraming), 1);
    assert_eq!(r.read(0x0258, 1), Ok(vec![0x42]));
    assert_eq!(r.write(0x0258, 0x66), Err(3));
    // A reserved parameter reads 0 and refuses writes with 04, the drive unchanged.
    let before = r.snapshot();
    assert_eq!(r.read(0x0100, 3), Ok(vec![0, 0, 0]));
    assert_eq!(r.write(0x0100, 1), Err(4));
    assert_eq!(r.snapshot(), before);
    // A read running from a reserved range into an object is refused.
    assert_eq!(r.read(0x012F, 2), Err(2));
    // No register: 02.
    assert_eq!(r.read(0x0700, 1), Err(2));
}

#[test]
fn speed_jog_runs_while_held() {
    let mut r = servo();
    r.write(0x0130, 300).expect("jog at 300 r/min"); // 1000 pps
    assert_eq!(r.write(SPEED_JOG, 1), Err(4), "jog bits need bit 15");
    r.write(SPEED_JOG, 0x8001).expect("jog +");
    r.run(500_000);
    assert!(r.moving() && r.position() > 100, "jogging positive: {}", r.position());
    r.write(SPEED_JOG, 0x8000).expect("release");
    r.settle(2);
    let stop = r.position();
    r.write(SPEED_JOG, 0x8002).expect("jog -");
    r.run(300_000);
    assert!(r.position() < stop);
    r.write(SPEED_JOG, 0).expect("off");
    r.settle(2);
    r.run(10_000);
    assert_eq!(r.read(0x0457, 1), Ok(vec![1]), "de-energised once at rest");
}

#[test]
fn position_jog_moves_one_distance_per_edge() {
    let mut r = servo();
    r.write(0x0130, 300).expect("jog speed");
    // 0x2196 at its native address, low word first as every 32-bit value of this map.
    r.write32(0x2196, 400).expect("jog distance");
    r.write(POSITION_JOG, 0x8000).expect("position jog on");
    r.write(POSITION_JOG, 0x8001).expect("+");
    r.settle(3);
    assert_eq!(r.position(), 400);
    r.write(POSITION_JOG, 0x8000).expect("release");
    r.write(POSITION_JOG, 0x8002).expect("-");
    r.settle(3);
    assert_eq!(r.position(), 0);
}

#[test]
fn four_group_chain_runs_on_its_conditions() {
    let mut r = servo();
    r.write(COMM_IO, SON).expect("servo on");
    // Group 0: absolute 1000 at 600 r/min, on arrival go to 1.
    r.group(0, 1000, 600, [0x01, 0, 0, 1, 1]);
    // Group 1: relative +500, then 200 ms after arrival go to 2.
    r.group(1, 500, 600, [0x02, 200, 0, 2, 2]);
    // Group 2: absolute -300, then wait for the input IN3 (condition value 3).
    r.group(2, -300, 300, [0x03, 3, 0, 3, 1]);
    // Group 3: relative +100, no condition: the chain ends there.
    r.group(3, 100, 300, [0x00, 0, 0, 0, 2]);
    assert_eq!(r.read(0x05F1, 1), Ok(vec![0]), "next: the selected group");
    r.write(COMM_IO, SON | POS_START).expect("start");
    r.run(5_000);
    assert_eq!(r.read(0x05F0, 1), Ok(vec![0]));
    let mut seen = vec![];
    let mut held_at = None;
    for ms in 0..6000 {
        r.run(1_000);
        let g = r.read(0x05F0, 1).expect("running group")[0];
        if seen.last() != Some(&g) {
            seen.push(g);
        }
        if g == 2 && !r.moving() && r.position() == -300 && held_at.is_none() {
            held_at = Some(ms);
        }
        if let Some(t) = held_at
            && ms == t + 300
        {
            assert_eq!(r.read(0x05F0, 1), Ok(vec![2]), "waits for IN3");
            r.inputs.levels |= 1 << 9; // IN3 (EXT3) high
        }
        if g == 0xFFFF && seen.len() > 1 {
            break;
        }
    }
    assert_eq!(seen, vec![0, 1, 2, 3, 0xFFFF]);
    assert_eq!(r.position(), -200);
    // 05F2h: the actual position in the groups' unit.
    assert_eq!(r.read32(0x05F2), -200);
}

#[test]
fn pos_step_steps_on_and_the_gear_scales_targets() {
    let mut r = servo();
    r.write(COMM_IO, SON).expect("servo on");
    r.write(0x05F8, 2).expect("numerator");
    r.write(0x05F9, 1).expect("denominator");
    // Group 5 waits 60 s after arrival; POS-STEP goes on with group 6 at once.
    r.group(5, 100, 600, [0x02, 60_000, 0, 6, 1]);
    r.group(6, 50, 600, [0x00, 0, 0, 0, 2]);
    // Select group 5 with POS0-2 (bits 9-11).
    r.write(COMM_IO, SON | 5 << 9).expect("select");
    assert_eq!(r.write(COMM_IO, SON | 5 << 9 | POS_STEP), Err(4), "nothing waits");
    r.write(COMM_IO, SON | 5 << 9 | POS_START).expect("start");
    r.settle(3);
    assert_eq!(r.position(), 200, "100 units of 2 microsteps");
    // The chain waits in group 5: it owns the axis, a position jog is refused.
    r.write(POSITION_JOG, 0x8000).expect("position jog on");
    assert_eq!(r.write(POSITION_JOG, 0x8001), Err(4));
    r.write(POSITION_JOG, 0x8000).expect("nothing moved");
    assert_eq!(r.position(), 200);
    r.write(COMM_IO, SON | 5 << 9).expect("release");
    r.write(COMM_IO, SON | 5 << 9 | POS_STEP).expect("step");
    r.settle(3);
    assert_eq!(r.position(), 300);
    assert_eq!(r.read32(0x05F2), 150);
}

#[test]
fn group_values_out_of_range_are_refused() {
    let mut r = servo();
    let before = r.snapshot();
    assert_eq!(r.write(0x0607, 3), Err(3), "type");
    assert_eq!(r.write(0x0606, 32), Err(3), "next group");
    assert_eq!(r.write(0x0602, 6001), Err(3), "speed");
    assert_eq!(r.write(0x0603, 0x0004), Err(3), "condition kind");
    assert_eq!(r.read(0x0600, 8), Ok(vec![0; 8]));
    assert_eq!(r.snapshot(), before);
    // A start of a group of type none changes nothing.
    r.write(COMM_IO, SON).expect("servo on");
    assert_eq!(r.write(COMM_IO, SON | POS_START), Err(4));
    assert_eq!(r.read(COMM_IO, 1), Ok(vec![SON]));
}

#[test]
fn refused_comm_io_bits_change_nothing() {
    let mut r = servo();
    let before = r.snapshot();
    for bit in [1, 6, 7, 8, 12] {
        assert_eq!(r.write(COMM_IO, 1 << bit), Err(3), "bit {bit}");
    }
    assert_eq!(r.snapshot(), before);
}

#[test]
fn overtravel_stops_and_refuses() {
    let mut r = servo();
    r.write(0x0130, 300).expect("jog speed");
    r.write(SPEED_JOG, 0x8001).expect("jog +");
    r.run(200_000);
    r.write(COMM_IO, SON | 1 << 2).expect("P-OT");
    r.settle(2);
    let at = r.position();
    assert_eq!(r.write(SPEED_JOG, 0x8000), Ok(()));
    assert_eq!(r.write(SPEED_JOG, 0x8001), Err(4), "towards the overtravel");
    assert_eq!(r.position(), at);
    r.write(SPEED_JOG, 0x8002).expect("away from it");
    r.run(100_000);
    assert!(r.position() < at);
}

#[test]
fn communication_timeout_stops_alarms_and_clears() {
    let mut r = servo();
    r.write(0x025A, 5).expect("P602 = 500 ms");
    r.write(0x0130, 300).expect("jog speed");
    r.write(SPEED_JOG, 0x8001).expect("jog +");
    r.run(400_000);
    assert!(r.moving());
    // The master falls silent.
    r.run(800_000);
    assert!(!r.moving(), "stopped");
    let alarm = r.read(0x044A, 1).expect("current alarm")[0];
    assert_eq!(alarm, 30);
    assert_eq!(r.read(0x0400, 1), Ok(vec![30]), "newest in the history");
    assert_eq!(r.write(SPEED_JOG, 0x8002), Err(4), "moves refused");
    r.write(0x0521, 1).expect("clear the alarm");
    assert_eq!(r.read(0x044A, 1), Ok(vec![0]));
    r.write(0x0520, 1).expect("clear the history");
    r.run(2_000);
    assert_eq!(r.read(0x0400, 10), Ok(vec![0; 10]));
}

#[test]
fn monitors_read_the_motion() {
    let mut r = servo();
    r.write(0x0130, 600).expect("jog speed"); // 2000 pps: 600 r/min
    r.write(SPEED_JOG, 0x8001).expect("jog +");
    r.run(1_000_000);
    assert_eq!(r.read32(0x0420), 600, "speed r/min");
    let feedback = i64::from(r.read32(0x0436));
    assert!((r.position() - feedback).abs() < 50, "feedback pulses: open loop, {feedback}");
    assert_eq!(r.read32(0x0438), 0, "no position error in open loop");
    let angle = r.read32(0x0422);
    assert!((0..360).contains(&angle));
    assert_eq!(r.read32(0x042C), 100, "full current while moving");
}

#[test]
fn factory_reset_and_versions() {
    let mut r = servo();
    r.write(0x0130, 300).expect("jog speed");
    r.write(0x0540, 1).expect("factory reset");
    assert_eq!(r.drive.state().read(Obj::JogSpeed), 2000);
    assert_eq!(r.read(0x01F7, 1), Ok(vec![10]), "P503's factory 10 r/min");
    assert_eq!(r.read(0x045E, 1).expect("software")[0] as u32, r.drive.state().read(Obj::SoftwareRevision));
}

#[test]
fn restart_is_requested_at_rest() {
    let mut r = servo();
    assert_eq!(r.write(0x0541, 2), Err(3));
    r.write(0x0541, 1).expect("restart");
    assert_eq!(r.drive.take_system_request(), Some(drive_core::SystemRequest::Restart));
}

#[test]
fn signal_allocation_moves_functions_between_inputs() {
    let mut r = servo();
    // §6.3's write: P□512 = 0064h, /START-HOME on IN4, /POS-START on IN6.
    r.write(0x0200, 0x0064).expect("P512");
    assert_eq!(r.drive.state().read(Obj::InputFunction4), 12);
    assert_eq!(r.drive.state().read(Obj::InputFunction6), 16);
    assert_eq!(r.read(0x0200, 1), Ok(vec![0x0064]));
    // /POS-START moves to IN2 (.1 = 2): IN6 loses it.
    r.write(0x0200, 0x0024).expect("moved");
    assert_eq!(r.drive.state().read(Obj::InputFunction6), 0);
    assert_eq!(r.drive.state().read(Obj::InputFunction2), 16);
    // Two signals on one input, or a terminal the drive does not have: 03, nothing changed.
    let before = r.snapshot();
    assert_eq!(r.write(0x0200, 0x0022), Err(3));
    assert_eq!(r.write(0x0200, 0x00B1), Err(3));
    assert_eq!(r.snapshot(), before);
    // P□513 .3: servo-on from IN1.
    r.write(0x0201, 0x1000).expect("P513");
    assert_eq!(r.drive.state().read(Obj::InputFunction1), 20);
    assert_eq!(r.read(0x0201, 1), Ok(vec![0x1000]));
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

    /// r/min and 10 r/min/s become the nearest microsteps a second (squared) at every
    /// resolution and read back as written; a position in the groups' unit becomes the nearest
    /// microstep through the gear and reads back as written (a gear of at least one microstep a
    /// unit).
    #[test]
    fn units_round_trip(
        k in 0usize..9,
        rpm in 45u16..=6000,
        accel in 1u16..=60_000,
        num in 1u16..=1000,
        extra in 0u16..=1000,
        position in -1_000_000i32..=1_000_000,
    ) {
        let microsteps = [0u16, 2, 4, 8, 16, 32, 64, 128, 256][k];
        let per_rev = 200 * i64::from(microsteps.max(1));
        let mut r = servo();
        proptest::prop_assert_eq!(r.write(0x600C, microsteps), Ok(()));
        let pps = (i64::from(rpm) * per_rev + 30) / 60;
        if (150..=300_000).contains(&pps) {
            proptest::prop_assert_eq!(r.write(0x0130, rpm), Ok(()));
            proptest::prop_assert_eq!(i64::from(r.drive.state().read(Obj::JogSpeed)), pps);
            proptest::prop_assert_eq!(r.read(0x0130, 1), Ok(vec![rpm]));
        } else {
            let before = r.drive.state().read(Obj::JogSpeed);
            proptest::prop_assert_eq!(r.write(0x0130, rpm), Err(3));
            proptest::prop_assert_eq!(r.drive.state().read(Obj::JogSpeed), before);
        }
        let pps2 = (i64::from(accel) * per_rev + 3) / 6;
        if pps2 >= 151 {
            proptest::prop_assert_eq!(r.write(0x05F5, accel), Ok(()));
            proptest::prop_assert_eq!(i64::from(r.drive.state().read(Obj::PpAccel)), pps2);
            proptest::prop_assert_eq!(r.read(0x05F5, 1), Ok(vec![accel]));
        }
        let den = num.saturating_sub(extra).max(1);
        proptest::prop_assert_eq!(r.write(0x05F8, num), Ok(()));
        proptest::prop_assert_eq!(r.write(0x05F9, den), Ok(()));
        let steps = i64::from(position) * i64::from(num);
        let want = if steps >= 0 { (steps + i64::from(den) / 2) / i64::from(den) } else { (steps - i64::from(den) / 2) / i64::from(den) };
        proptest::prop_assert_eq!(r.write32(0x05FD, position), Ok(()));
        proptest::prop_assert_eq!(r.position(), want);
        proptest::prop_assert_eq!(r.read32(0x05FD), position);
    }
}

/// A factory reset (0540h) refused with the rest of its write (0541h = 0 is out of range)
/// changes nothing, the map's own factory values included (found by `pdu_servo`).
#[test]
fn a_refused_write_with_a_factory_reset_changes_nothing() {
    let mut r = servo();
    r.write(0x01F7, 0).expect("P503 = 0");
    let before = r.snapshot();
    assert_eq!(r.request(&[1, 0x10, 0x05, 0x40, 0, 2, 4, 0, 1, 0, 0]).map(|_| ()), Err(3));
    assert_eq!(r.snapshot(), before);
    assert_eq!(r.read(0x01F7, 1), Ok(vec![0]));
}
