//! The DS-CLS9 map (seed 002) at the level of frames: decimal registers, the control command
//! 0323's commands with the axis doing what the table says, soft limits on the side that is
//! enabled only, the status block, the exception cases with nothing changed, and the units
//! exact in both directions.

mod common;

use drive_core::maps::Maps;
use drive_core::od::{OBJECTS, Obj};
use drive_core::{Drive, DriveConfig, Params};

/// A DS-CLS9 drive with a clock.
type Rig = common::MapRig;

/// A drive at 3200 pulses a revolution, runs at 5 rev/s, ramps of 50 rev/s².
fn cls9_rig() -> Rig {
    let mut r = Rig::new(Maps::cls9());
    r.write32(242, 3200).expect("resolution");
    for (reg, v) in [(303, 50), (304, 50), (306, 500), (308, 200)] {
        r.set(reg, v).expect("setting");
    }
    r
}

impl Rig {
    /// Writes one register, a signed value.
    fn set(&mut self, addr: u16, v: i32) -> Result<(), u8> {
        self.write(addr, v as u16)
    }

    fn write32(&mut self, addr: u16, v: i32) -> Result<(), u8> {
        let [a, b] = addr.to_be_bytes();
        let mut body = vec![1, 0x10, a, b, 0, 2, 4];
        body.extend_from_slice(&v.to_be_bytes());
        self.request(&body).map(|_| ())
    }

    fn read32(&mut self, addr: u16) -> i32 {
        let w = self.read(addr, 2).expect("read");
        ((u32::from(w[0]) << 16) | u32::from(w[1])) as i32
    }

    fn command(&mut self, c: i32) -> Result<(), u8> {
        self.set(323, c)
    }

    /// The commanded position, microsteps (the pulses of this map).
    fn position(&self) -> i64 {
        i64::from(self.drive.state().read_i32(Obj::Position))
    }

    fn run_state(&mut self) -> u16 {
        self.read(109, 1).expect("run state")[0]
    }

    /// Runs until the axis stands (at most `s` seconds).
    fn settle(&mut self, s: u64) {
        for _ in 0..s * 100 {
            self.run(10_000);
            if self.run_state() != 3 {
                return;
            }
        }
        panic!("still moving after {s} s");
    }

    fn snapshot(&self) -> (Vec<u32>, i64) {
        let s = self.drive.state();
        (OBJECTS.iter().filter(|d| !d.obj.is_diagnostic()).map(|d| s.read_def(d)).collect(), self.position())
    }
}

#[test]
fn status_block_reads_in_the_manuals_units() {
    let mut r = cls9_rig();
    // 0104 and 0242: the resolution, pulses a revolution, two words.
    assert_eq!(r.read32(104), 3200);
    assert_eq!(r.read32(242), 3200);
    assert_eq!(r.drive.state().read(Obj::Microsteps), 16);
    // Energised and standing, no alarm; versions.
    assert_eq!(r.read(108, 2), Ok(vec![0, 2]));
    assert_eq!(r.read(110, 1), Ok(vec![100]));
    // Measured supply and current: 0.1 A and V.
    r.inputs.supply_mv = Some(24_400);
    r.inputs.phase_ma = Some([-1_250, 300]);
    r.run(1_000);
    assert_eq!(r.read(100, 2), Ok(vec![13, 24]));
    // (A current above 1.5 times the setting would be an overload in 2 s.)
    r.inputs.phase_ma = None;
    // A negative run: 0119 signed in 0.01 rev/s, 0117 the target.
    r.write32(313, -32_000).expect("target");
    r.command(1).expect("absolute run");
    r.run(400_000);
    assert_eq!(r.run_state(), 3);
    assert_eq!(r.read(119, 1).map(|w| w[0] as i16), Ok(-500), "5 rev/s backwards");
    assert_eq!(r.read32(117), -32_000);
    r.settle(10);
    assert_eq!(r.read32(126), -32_000);
    assert_eq!(r.read32(117), -32_000);
}

#[test]
fn absolute_runs_end_on_the_target_and_take_a_new_one_on_line() {
    let mut r = cls9_rig();
    r.write32(313, 48_000).expect("target");
    r.command(1).expect("absolute run");
    r.run(300_000);
    let on_the_way = r.position();
    assert!(on_the_way > 0 && on_the_way < 48_000, "{on_the_way}");
    // "Changing the target during the run takes effect."
    r.write32(313, 16_000).expect("new target");
    r.settle(10);
    assert_eq!(r.position(), 16_000);
    assert_eq!(r.read32(126), 16_000);
    // The distance's sign gives the direction; the speed is a magnitude (1-5000).
    assert_eq!(r.set(306, -500), Err(3));
    r.write32(313, 0).expect("target");
    r.command(1).expect("absolute run");
    r.settle(10);
    assert_eq!(r.position(), 0);
}

#[test]
fn relative_runs_go_by_the_distance_and_ignore_changes() {
    let mut r = cls9_rig();
    r.write32(313, 8_000).expect("distance");
    r.command(2).expect("relative run");
    r.run(100_000);
    // A new distance changes nothing of the run; a second relative run is refused.
    r.write32(313, -3_000).expect("distance");
    let before = r.snapshot();
    assert_eq!(r.command(2), Err(4));
    let after = r.snapshot();
    assert_eq!(before.0[Obj::CommandTarget as usize], after.0[Obj::CommandTarget as usize]);
    r.settle(10);
    assert_eq!(r.position(), 8_000);
    // Negative: the direction from the sign.
    r.command(2).expect("relative run");
    r.settle(10);
    assert_eq!(r.position(), 5_000);
}

#[test]
fn velocity_runs_and_jogs_run_until_stopped() {
    let mut r = cls9_rig();
    r.set(307, -300).expect("velocity");
    r.command(3).expect("velocity run");
    r.run(500_000);
    assert_eq!(r.read(119, 1).map(|w| w[0] as i16), Ok(-300));
    // A new velocity changes the run's speed.
    r.set(307, 200).expect("velocity");
    r.run(500_000);
    assert_eq!(r.read(119, 1).map(|w| w[0] as i16), Ok(200));
    // 6: a stop at the deceleration 0304: from 2 rev/s at 50 rev/s², 0.04 s and 128 pulses,
    // after the request's 4 ms on the line at 6 400 pulses a second.
    let at = r.position();
    r.command(6).expect("stop");
    r.settle(1);
    let stopped = r.position() - at;
    assert!((128..=160).contains(&stopped), "{stopped} pulses to stop");
    // 4 and 5: jogs at 0308 until a stop; 7 stops at the quick-stop deceleration.
    r.command(4).expect("jog +");
    r.run(300_000);
    assert_eq!(r.read(119, 1).map(|w| w[0] as i16), Ok(200));
    r.command(7).expect("emergency stop");
    r.run(20_000);
    assert_eq!(r.run_state(), 2);
    r.command(5).expect("jog -");
    r.run(300_000);
    assert_eq!(r.read(119, 1).map(|w| w[0] as i16), Ok(-200));
    r.command(6).expect("stop");
    r.settle(1);
}

#[test]
fn set_position_only_standing() {
    let mut r = cls9_rig();
    r.write32(321, 123_456).expect("preset");
    r.command(8).expect("set position");
    assert_eq!(r.read32(126), 123_456);
    r.command(4).expect("jog");
    r.run(100_000);
    r.write32(321, 0).expect("preset");
    let before = r.snapshot();
    assert_eq!(r.command(8), Err(4));
    // The refused command changed nothing but the time: the axis jogs on from where it was.
    assert!(r.position() > before.1);
    assert_eq!(r.drive.state().read(Obj::MotionCommand), 4);
    r.command(6).expect("stop");
    r.settle(1);
    r.command(8).expect("set position");
    assert_eq!(r.read32(126), 0);
}

#[test]
fn soft_limits_stop_moves_on_the_enabled_side_only() {
    let mut r = cls9_rig();
    r.write32(317, 10_000).expect("positive limit");
    r.write32(319, -10_000).expect("negative limit");
    // Disabled: a run goes through.
    r.write32(313, 12_000).expect("target");
    r.command(1).expect("run");
    r.settle(10);
    assert_eq!(r.position(), 12_000);
    // Positive on: beyond the limit the axis moves back freely, and no further out.
    r.set(324, 1).expect("limits");
    r.write32(313, 20_000).expect("target");
    r.command(1).expect("run");
    r.settle(10);
    assert_eq!(r.position(), 12_000, "no further out");
    r.write32(313, 0).expect("target");
    r.command(1).expect("run");
    r.settle(10);
    assert_eq!(r.position(), 0);
    r.write32(313, 30_000).expect("target");
    r.command(1).expect("run");
    r.settle(10);
    assert_eq!(r.position(), 10_000, "stops on the positive limit");
    // The jog towards it ends on it; the negative side is open.
    r.command(5).expect("jog -");
    r.run(200_000);
    r.command(4).expect("jog +");
    r.settle(10);
    assert_eq!(r.position(), 10_000);
    r.write32(313, -15_000).expect("target");
    r.command(1).expect("run");
    r.settle(10);
    assert_eq!(r.position(), -15_000, "negative limit off");
    // Both on: a velocity run towards the negative limit ends on it.
    r.set(324, 3).expect("limits");
    r.write32(313, 0).expect("target");
    r.command(1).expect("run");
    r.settle(10);
    r.set(307, -400).expect("velocity");
    r.command(3).expect("velocity run");
    r.settle(10);
    assert_eq!(r.position(), -10_000);
    // Other bits of 0324 are refused.
    assert_eq!(r.set(324, 4), Err(3));
}

#[test]
fn alarms_latch_a_safe_state_and_clear() {
    let mut r = cls9_rig();
    r.command(4).expect("jog");
    r.run(100_000);
    // Over-voltage: the alarm code 14 and enable off, the jog stopped; moves refused.
    r.inputs.supply_mv = Some(70_000);
    r.run(10_000);
    assert_eq!(r.read(108, 2), Ok(vec![14, 1]));
    let at = r.position();
    assert_eq!(r.command(1), Err(4));
    r.run(100_000);
    assert_eq!(r.position(), at);
    // While the cause holds, a clear latches again; once it is gone, 13 clears it.
    r.command(13).expect("alarm clear");
    r.run(1_000);
    assert_eq!(r.read(108, 1), Ok(vec![14]));
    r.inputs.supply_mv = Some(24_000);
    r.command(13).expect("alarm clear");
    r.run(1_000);
    assert_eq!(r.read(108, 2), Ok(vec![0, 2]));
    // 0206 = 2 clears too; 3 (restart) is refused.
    r.inputs.supply_mv = Some(8_000);
    r.run(1_000);
    assert_eq!(r.read(108, 1), Ok(vec![13]));
    r.inputs.supply_mv = Some(24_000);
    r.set(206, 2).expect("user command: alarm clear");
    r.run(1_000);
    assert_eq!(r.read(108, 2), Ok(vec![0, 2]));
    assert_eq!(r.set(206, 3), Err(4));
}

#[test]
fn refusals_change_nothing() {
    let mut r = cls9_rig();
    let before = r.snapshot();
    // No register 0102, 0105; a read across the gap after 0101.
    assert_eq!(r.read(102, 1), Err(2));
    assert_eq!(r.read(100, 3), Err(2));
    assert_eq!(r.set(105, 1), Err(2));
    // One half of a 32-bit value.
    assert_eq!(r.set(313, 5), Err(2));
    assert_eq!(r.set(314, 5), Err(2));
    // Values out of range: a resolution the drive does not have, a command it does not do, a
    // speed below the drive's, a read-only register.
    assert_eq!(r.write32(242, 300), Err(3));
    assert_eq!(r.command(20), Err(3));
    assert_eq!(r.command(9), Err(3));
    assert_eq!(r.set(306, 0), Err(3));
    assert_eq!(r.set(109, 2), Err(2));
    // A write of several registers is all or nothing: 0313 taken, 0317 out of range.
    let mut body = vec![1, 0x10, 0x01, 0x39, 0, 6, 12];
    for v in [1_000i32, 0, 2_100_000_000] {
        body.extend_from_slice(&v.to_be_bytes());
    }
    // 0313, then 0315 (not a register): refused whole.
    assert_eq!(r.request(&body), Err(2));
    assert_eq!(r.snapshot().0, before.0);
    assert_eq!(r.snapshot().1, before.1);
}

#[test]
fn the_map_is_a_saved_setting_and_switches_back() {
    let mut r = cls9_rig();
    // This rig chose the map for its run; the setting says which map the next power-up takes.
    assert_eq!(r.read(0x2190, 1), Ok(vec![0]));
    r.set(0x2190, 2).expect("this map");
    assert_eq!(r.read(0x2190, 1), Ok(vec![2]));
    assert_eq!(r.set(0x2190, 5), Err(3));
    r.set(0x2190, 0).expect("native");
    assert_eq!(r.drive.state().read(Obj::RegisterMap), 0);
}

/// With nothing saved the drive takes the manual's factory values where they differ from its
/// own, and a factory reset (0206 = 1) brings them back; the native map keeps the drive's.
#[test]
fn the_manuals_factory_values_with_nothing_saved_and_after_a_reset() {
    let empty = drive_core::drive::STORAGE_EMPTY;
    let config = DriveConfig { can_save: true, ..DriveConfig::default() };
    let cls9 = Drive::boot_with_map(config, Maps::cls9(), &Params::factory(), empty);
    let mut r = common::MapRig::with_drive(cls9);
    let defaults = vec![100, 100, 100, 100, 0, 1000, 1000, 1000, 1000, 1000];
    assert_eq!(r.read(301, 10), Ok(defaults.clone()));
    assert_eq!(r.read(420, 4), Ok(vec![101, 100, 100, 100]));
    r.set(306, 500).expect("0306");
    r.set(420, 102).expect("0420");
    r.set(206, 1).expect("parameter reset");
    assert_eq!(r.read(301, 10), Ok(defaults), "the manual's values again");
    assert_eq!(r.read(420, 1), Ok(vec![101]));
    assert_eq!(r.drive.take_system_request(), Some(drive_core::SystemRequest::Save), "and saved");
    let native = Drive::boot_with_map(DriveConfig::default(), Maps::by_id(0), &Params::factory(), empty);
    assert_eq!(native.state().read(Obj::CommandSpeed), Obj::CommandSpeed.def().default);
}

proptest::proptest! {
    /// 0.01 rev/s and rev/s² become microsteps exactly at every resolution and read back as
    /// written.
    #[test]
    fn units_round_trip(k in 0usize..9, speed in 1i32..=5000, accel in 5i32..=10_000) {
        use drive_core::maps::layout::{FULL_STEPS_PER_REV, Scale};
        let ppr = [200i32, 400, 800, 1600, 3200, 6400, 12_800, 25_600, 51_200][k];
        let per_rev = FULL_STEPS_PER_REV * i64::from(ppr / 200);
        for (scale, v) in [(Scale::PerRev(1, 100), speed), (Scale::PerRev(1, 1), accel)] {
            let drive = scale.to_drive(i64::from(v), per_rev).expect("in range");
            // A revolution is 200 × microsteps: 0.01 rev/s is a whole number of microsteps.
            proptest::prop_assert_eq!(drive * scale_den(scale), i64::from(v) * per_rev);
            proptest::prop_assert_eq!(scale.to_map(drive, per_rev), Some(i64::from(v)));
        }
        let mut r = cls9_rig();
        proptest::prop_assert_eq!(r.write32(242, ppr), Ok(()));
        let pps = i64::from(speed) * per_rev / 100;
        if (150..=300_000).contains(&pps) {
            proptest::prop_assert_eq!(r.set(308, speed), Ok(()));
            proptest::prop_assert_eq!(i64::from(r.drive.state().read(Obj::JogSpeed)), pps);
            proptest::prop_assert_eq!(r.read(308, 1), Ok(vec![speed as u16]));
        } else {
            let before = r.drive.state().read(Obj::JogSpeed);
            proptest::prop_assert_eq!(r.set(308, speed), Err(3));
            proptest::prop_assert_eq!(r.drive.state().read(Obj::JogSpeed), before);
        }
        proptest::prop_assert_eq!(r.set(303, accel), Ok(()));
        proptest::prop_assert_eq!(i64::from(r.drive.state().read(Obj::PpAccel)), i64::from(accel) * per_rev);
        proptest::prop_assert_eq!(r.read(303, 1), Ok(vec![accel as u16]));
    }
}

fn scale_den(s: drive_core::maps::layout::Scale) -> i64 {
    match s {
        drive_core::maps::layout::Scale::PerRev(_, d) => i64::from(d),
        _ => 1,
    }
}

/// §十三's timing exceptions, from a raw line (no real master sends them): a silence over 1.5
/// characters inside a frame is answered 0C, a whole frame followed by the next before 3.5
/// characters 0D, each after 3.5 characters of quiet, and nothing executes; another drive's
/// frame is not answered; a frame on time is served as usual.
#[test]
fn timing_exceptions_answer_spoilt_frames() {
    // 9600 baud: a character is 1.146 ms, t1.5 1.72 ms, t3.5 4.01 ms.
    let mut r = cls9_rig();
    let before = r.drive.state().read(Obj::JogSpeed);
    // 0308 = 100 (0x64), its last two bytes 2.5 ms late.
    let write = common::frame(&[1, 0x06, 0x01, 0x34, 0x00, 0x64]);
    let (head, tail) = write.split_at(6);
    r.drive.on_rx(drive_core::Instant::from_micros(r.now), head);
    r.run(2_500);
    r.drive.on_rx(drive_core::Instant::from_micros(r.now), tail);
    let reply = r.run(10_000).expect("an answer");
    assert_eq!(reply, common::frame(&[1, 0x86, 0x0C]));
    assert_eq!(r.drive.state().read(Obj::JogSpeed), before, "not executed");
    // The whole frame, then a read 2.5 ms after it: 0D, nothing executed.
    r.drive.on_rx(drive_core::Instant::from_micros(r.now), &write);
    r.run(2_500);
    r.drive.on_rx(drive_core::Instant::from_micros(r.now), &common::frame(&[1, 0x03, 0x01, 0x6D, 0x00, 0x01]));
    let reply = r.run(10_000).expect("an answer");
    assert_eq!(reply, common::frame(&[1, 0x86, 0x0D]));
    assert_eq!(r.drive.state().read(Obj::JogSpeed), before, "not executed");
    // Another drive's spoilt frame: no answer.
    let other = common::frame(&[2, 0x06, 0x01, 0x34, 0x00, 0x64]);
    r.drive.on_rx(drive_core::Instant::from_micros(r.now), &other[..3]);
    r.run(2_500);
    r.drive.on_rx(drive_core::Instant::from_micros(r.now), &other[3..]);
    assert_eq!(r.run(10_000), None);
    // On time: served.
    assert_eq!(r.set(308, 100), Ok(()));
    assert_ne!(r.drive.state().read(Obj::JogSpeed), before);
}

/// The native map drops a spoilt frame without an answer, as the Modbus serial line has it.
#[test]
fn the_native_map_drops_spoilt_frames() {
    let mut r = Rig::new(Maps::Native(drive_core::maps::NativeMap::new()));
    let write = common::frame(&[1, 0x06, 0x60, 0x0C, 0x00, 0x10]);
    r.drive.on_rx(drive_core::Instant::from_micros(r.now), &write[..4]);
    r.run(2_500);
    r.drive.on_rx(drive_core::Instant::from_micros(r.now), &write[4..]);
    assert_eq!(r.run(10_000), None);
    assert_eq!(r.drive.state().read(Obj::Microsteps), 0);
}

/// 0258, the position error threshold in encoder counts, is the closed loop's following-error
/// limit at the resolution in force; 0 leaves the drive's own (0x605C, microsteps).
#[test]
fn the_position_error_threshold_is_the_following_error_limit_in_encoder_counts() {
    let mut r = cls9_rig();
    let limit = |r: &Rig| r.drive.state().settings().following_limit;
    assert_eq!(limit(&r), 64, "0258 = 0: 0x605C's 64 microsteps");
    // A 1000-line encoder (4000 counts a revolution) at 3200 pulses a revolution.
    assert_eq!(r.set(246, 4000), Ok(()));
    assert_eq!(r.set(258, 4000), Ok(()));
    assert_eq!(limit(&r), 3200, "a revolution");
    assert_eq!(r.set(258, 1), Ok(()));
    assert_eq!(limit(&r), 1, "0.8 microsteps: one at least");
    r.write32(242, 51_200).expect("resolution");
    assert_eq!(r.set(258, 30_000), Ok(()));
    assert_eq!(limit(&r), 384_000, "7.5 revolutions at 51 200 a revolution");
    assert_eq!(r.set(258, 30_001), Err(3));
    assert_eq!(r.read(258, 1), Ok(vec![30_000]));
    assert_eq!(r.set(258, 0), Ok(()));
    assert_eq!(limit(&r), 64);
}
