//! Faults and protections: measurements in, latched bits, alarm codes, history, the safe state,
//! the brake and power loss (module `drive_core::faults`).

mod common;

use common::Bus;
use drive_core::control::Outputs;
use drive_core::faults::{Inputs, alarm};
use drive_core::od::Obj;
use drive_core::{Drive, DriveConfig, Instant, Params, SystemRequest};

const NOMINAL: Inputs = Inputs {
    supply_mv: Some(24_000),
    temperature_c: Some(30),
    phase_ma: Some([0, 0]),
    coil_open: [false; 2],
    phase_mv: None,
    back_emf_mv: None,
    encoder: None,
    levels: 0,
    analog: None,
    index: false,
    pulses: 0,
    tripped: false,
    sensing_fault: false,
};

/// A factory drive with a move speed set.
fn drive() -> Bus {
    let mut bus = Bus::factory();
    assert_eq!(write32(&mut bus, 0x6003, 4000), None);
    bus
}

/// Writes one register; whether the drive accepted it (a normal reply).
fn write(bus: &mut Bus, addr: u16, value: u16) -> bool {
    let [ah, al] = addr.to_be_bytes();
    let [vh, vl] = value.to_be_bytes();
    let reply = bus.request(&[1, 6, ah, al, vh, vl]).unwrap_or_default();
    reply.get(1) == Some(&6)
}

/// Writes a 32-bit object as one 0x10 request; the exception code, if any.
fn write32(bus: &mut Bus, addr: u16, value: u32) -> Option<u8> {
    let [ah, al] = addr.to_be_bytes();
    let v = value.to_be_bytes();
    let reply = bus.request(&[1, 0x10, ah, al, 0, 2, 4, v[0], v[1], v[2], v[3]]).unwrap_or_default();
    if reply.get(1) == Some(&0x90) { reply.get(2).copied() } else { None }
}

/// Ticks every 50 µs for `us` with `inputs`; the last outputs.
fn run(bus: &mut Bus, inputs: &Inputs, us: u64) -> Outputs {
    let end = bus.now + us;
    let mut out = bus.drive.tick_with(Instant::from_micros(bus.now), inputs);
    while bus.now < end {
        bus.now += 50;
        out = bus.drive.tick_with(Instant::from_micros(bus.now), inputs);
    }
    out
}

fn read(bus: &Bus, obj: Obj) -> u32 {
    bus.drive.state().read(obj)
}

#[test]
fn under_voltage_latches_frees_the_motor_and_refuses_moves_until_cleared() {
    let mut bus = drive();
    assert!(run(&mut bus, &NOMINAL, 1000).enabled);
    let low = Inputs { supply_mv: Some(9_000), ..NOMINAL };
    let out = run(&mut bus, &low, 1000);
    assert!(!out.enabled);
    assert_eq!(out.current_ma, 0);
    assert_eq!(read(&bus, Obj::ErrorStatus), 1 << 5);
    assert_eq!(read(&bus, Obj::AlarmCode), u32::from(alarm::UNDER_VOLTAGE));
    assert_eq!(read(&bus, Obj::AlarmCount), 1);
    assert_eq!(read(&bus, Obj::FaultHistory0) >> 24, u32::from(alarm::UNDER_VOLTAGE));
    // Supply back: still latched, and a move is refused with 04 and changes nothing.
    let out = run(&mut bus, &NOMINAL, 1000);
    assert!(!out.enabled);
    let before = bus.snapshot();
    assert_eq!(write32(&mut bus, 0x6005, 1000), Some(4));
    assert_eq!(bus.snapshot(), before);
    assert_eq!(run(&mut bus, &NOMINAL, 10_000).setpoint.whole, 0);
    // Clearing the bit ends the safe state; the history keeps the entry.
    assert!(write(&mut bus, 0x6000, 1 << 5));
    assert_eq!(read(&bus, Obj::ErrorStatus), 0);
    assert_eq!(read(&bus, Obj::AlarmCode), 0);
    assert!(run(&mut bus, &NOMINAL, 50).enabled);
    assert_eq!(write32(&mut bus, 0x6005, 1000), None);
    assert_eq!(run(&mut bus, &NOMINAL, 2_000_000).setpoint.whole, 1000);
    assert_eq!(read(&bus, Obj::AlarmCount), 1);
}

#[test]
fn a_condition_still_present_latches_again_with_a_new_entry() {
    let mut bus = drive();
    let low = Inputs { supply_mv: Some(8_000), ..NOMINAL };
    run(&mut bus, &low, 200_000);
    assert!(write(&mut bus, 0x6000, 0x3F));
    run(&mut bus, &low, 100);
    assert_eq!(read(&bus, Obj::ErrorStatus), 1 << 5);
    assert_eq!(read(&bus, Obj::AlarmCount), 2);
    // Newest first, time stamps in 100 ms since power-up (the bus clock starts at 1 s).
    let (new, old) = (read(&bus, Obj::FaultHistory0), read(&bus, Obj::FaultHistory1));
    assert_eq!((new >> 24, old >> 24), (13, 13));
    assert_eq!(old & 0xFF_FFFF, 10);
    assert_eq!(new & 0xFF_FFFF, 12);
    assert_eq!(read(&bus, Obj::FaultHistory2), 0);
}

#[test]
fn each_measurement_sets_its_bit_and_code() {
    type Case = (fn(&mut Inputs), Obj, u32, u8);
    let cases: [Case; 7] = [
        (|i| i.coil_open = [true, false], Obj::ErrorStatus, 1 << 1, alarm::PHASE_LOSS),
        (|i| i.coil_open = [false, true], Obj::ErrorStatus, 1 << 2, alarm::PHASE_LOSS),
        (|i| i.phase_ma = Some([-8001, 0]), Obj::ErrorStatus, 1 << 3, alarm::OVER_CURRENT),
        (|i| i.phase_ma = Some([0, 9000]), Obj::ErrorStatus, 1 << 4, alarm::OVER_CURRENT),
        (|i| i.temperature_c = Some(86), Obj::ErrorStatus, 1 << 0, alarm::OVER_TEMPERATURE),
        (|i| i.supply_mv = Some(60_001), Obj::DriveFaults, 1 << 0, alarm::OVER_VOLTAGE),
        (|i| i.supply_mv = Some(9_999), Obj::ErrorStatus, 1 << 5, alarm::UNDER_VOLTAGE),
    ];
    for (make, obj, bit, code) in cases {
        let mut bus = drive();
        let mut inputs = NOMINAL;
        make(&mut inputs);
        assert!(!run(&mut bus, &inputs, 100).enabled, "{obj:?} {bit:#x}");
        assert_eq!(read(&bus, obj), bit, "{obj:?} {bit:#x}");
        let other = if obj == Obj::ErrorStatus { Obj::DriveFaults } else { Obj::ErrorStatus };
        assert_eq!(read(&bus, other), 0);
        assert_eq!(read(&bus, Obj::AlarmCode), u32::from(code));
        assert_eq!(read(&bus, Obj::FaultHistory0) >> 24, u32::from(code));
    }
    // At the thresholds exactly: no fault.
    let mut bus = drive();
    let edge = Inputs { supply_mv: Some(10_000), temperature_c: Some(85), phase_ma: Some([8000, -8000]), ..NOMINAL };
    assert!(run(&mut bus, &edge, 100).enabled);
    assert_eq!((read(&bus, Obj::ErrorStatus), read(&bus, Obj::DriveFaults)), (0, 0));
}

#[test]
fn the_most_severe_alarm_shows_and_each_gets_an_entry() {
    let mut bus = drive();
    let both = Inputs { supply_mv: Some(9_000), coil_open: [true, false], ..NOMINAL };
    run(&mut bus, &both, 100);
    assert_eq!(read(&bus, Obj::AlarmCount), 2);
    assert_eq!(read(&bus, Obj::AlarmCode), u32::from(alarm::PHASE_LOSS));
    run(&mut bus, &NOMINAL, 100);
    assert!(write(&mut bus, 0x6000, 1 << 1));
    assert_eq!(read(&bus, Obj::AlarmCode), u32::from(alarm::UNDER_VOLTAGE));
}

#[test]
fn overload_after_two_seconds_above_one_and_a_half_times_the_setting() {
    let mut bus = drive();
    // 0x600D = 658 mA: 1.5 times is 987.
    let high = Inputs { phase_ma: Some([1000, 0]), ..NOMINAL };
    assert!(run(&mut bus, &high, 1_999_000).enabled);
    // A dip below resets the count.
    run(&mut bus, &NOMINAL, 50);
    assert!(run(&mut bus, &high, 1_999_000).enabled);
    assert!(!run(&mut bus, &high, 1_000).enabled);
    assert_eq!(read(&bus, Obj::DriveFaults), 1 << 1);
    assert_eq!(read(&bus, Obj::AlarmCode), u32::from(alarm::OVERLOAD));
    // With no current set, a measured offset is no overload.
    let mut bus = drive();
    assert!(write(&mut bus, 0x600D, 0));
    let offset = Inputs { phase_ma: Some([30, -20]), ..NOMINAL };
    run(&mut bus, &offset, 3_000_000);
    assert_eq!(read(&bus, Obj::DriveFaults), 0);
}

/// PVT mode 1 with two points (0, then 1000 microsteps 100 ms later), its start requested.
fn pvt_started() -> Bus {
    let mut bus = drive();
    assert!(write(&mut bus, 0x6007, 2));
    for (position, time) in [(0, 0), (1000, 100)] {
        assert_eq!(write32(&mut bus, 0x6027, position), None);
        assert_eq!(write32(&mut bus, 0x602B, time), None);
        assert!(write(&mut bus, 0x6017, 2));
    }
    assert!(write(&mut bus, 0x601C, 1));
    assert!(write(&mut bus, 0x6017, 1));
    bus
}

#[test]
fn a_pvt_start_accepted_before_a_fault_does_not_run() {
    // Without a fault the run goes to its last point.
    let mut bus = pvt_started();
    assert_eq!(run(&mut bus, &NOMINAL, 300_000).setpoint.whole, 1000);
    let mut bus = pvt_started();
    let hot = Inputs { temperature_c: Some(100), ..NOMINAL };
    assert_eq!(run(&mut bus, &hot, 300_000).setpoint.whole, 0);
    assert!(write(&mut bus, 0x6000, 1));
    assert_eq!(run(&mut bus, &NOMINAL, 300_000).setpoint.whole, 0, "the start was cancelled");
}

#[test]
fn a_fault_stops_a_moving_axis_where_it_is() {
    let mut bus = drive();
    assert_eq!(write32(&mut bus, 0x6005, 100_000), None);
    let moving = run(&mut bus, &NOMINAL, 500_000).setpoint.whole;
    assert!(moving > 0);
    let open = Inputs { coil_open: [false, true], ..NOMINAL };
    let stopped = run(&mut bus, &open, 50).setpoint.whole;
    assert!(stopped - moving < 10);
    assert_eq!(run(&mut bus, &NOMINAL, 500_000).setpoint.whole, stopped);
    assert_eq!(read(&bus, Obj::ControllerStatus) & (1 << 3), 0);
}

#[test]
fn the_brake_is_released_while_enabled_and_applied_on_disable_and_fault() {
    let mut bus = drive();
    assert_eq!(run(&mut bus, &NOMINAL, 100).coil_duty, 0);
    assert!(write(&mut bus, 0x6038, 60));
    assert_eq!(run(&mut bus, &NOMINAL, 100).coil_duty, 60);
    assert!(write(&mut bus, 0x6011, 0));
    assert_eq!(run(&mut bus, &NOMINAL, 100).coil_duty, 0);
    assert!(write(&mut bus, 0x6011, 1));
    assert_eq!(run(&mut bus, &NOMINAL, 100).coil_duty, 60);
    let hot = Inputs { temperature_c: Some(120), ..NOMINAL };
    assert_eq!(run(&mut bus, &hot, 100).coil_duty, 0);
    assert_eq!(run(&mut bus, &NOMINAL, 100).coil_duty, 0);
    assert!(write(&mut bus, 0x6000, 1));
    assert_eq!(run(&mut bus, &NOMINAL, 100).coil_duty, 60);
}

#[test]
fn power_loss_frees_the_motor_and_applies_the_brake_as_configured() {
    let mut bus = drive();
    assert!(write(&mut bus, 0x6038, 100));
    // Free below 21 V only.
    assert!(write(&mut bus, 0x6082, 1));
    assert!(write(&mut bus, 0x6083, 21_000));
    assert!(write(&mut bus, 0x6084, 20_000));
    let sagging = Inputs { supply_mv: Some(20_500), ..NOMINAL };
    let out = run(&mut bus, &sagging, 100);
    assert!(!out.enabled && out.current_ma == 0 && out.coil_duty == 0);
    assert_eq!(read(&bus, Obj::ErrorStatus), 0, "power loss is not a fault");
    assert_eq!(write32(&mut bus, 0x6005, 100), Some(4));
    // Back above: driven again, without clearing anything.
    assert!(run(&mut bus, &NOMINAL, 100).enabled);
    // Brake only, below 20 V: the motor holds, the brake is applied.
    assert!(write(&mut bus, 0x6082, 2));
    let out = run(&mut bus, &sagging, 100);
    assert!(out.enabled && out.coil_duty == 100);
    let out = run(&mut bus, &Inputs { supply_mv: Some(19_500), ..NOMINAL }, 100);
    assert!(out.enabled && out.current_ma > 0 && out.coil_duty == 0);
}

#[test]
fn power_loss_requests_the_position_save_once_per_drop() {
    let mut bus = drive();
    assert!(write(&mut bus, 0x605E, 1));
    assert_eq!(write32(&mut bus, 0x6005, 1234), None);
    run(&mut bus, &NOMINAL, 1_000_000);
    assert_eq!(bus.drive.take_system_request(), None);
    let ramp = |mv| Inputs { supply_mv: Some(mv), ..NOMINAL };
    run(&mut bus, &ramp(10_500), 1000);
    assert_eq!(bus.drive.take_system_request(), None);
    run(&mut bus, &ramp(9_500), 1000);
    assert_eq!(bus.drive.take_system_request(), Some(SystemRequest::SavePosition(1234)));
    run(&mut bus, &ramp(4_000), 1000);
    assert_eq!(bus.drive.take_system_request(), None);
    // Power comes back, then fails again: a second save.
    run(&mut bus, &NOMINAL, 1000);
    run(&mut bus, &ramp(9_000), 1000);
    assert_eq!(bus.drive.take_system_request(), Some(SystemRequest::SavePosition(1234)));
}

#[test]
fn without_measurements_nothing_is_detected() {
    let mut bus = drive();
    assert!(run(&mut bus, &Inputs::default(), 1000).enabled);
    bus.drive.tick(Instant::from_micros(bus.now + 50));
    assert_eq!((read(&bus, Obj::ErrorStatus), read(&bus, Obj::AlarmCount)), (0, 0));
}

#[test]
fn the_new_objects_reject_bad_writes() {
    let mut bus = drive();
    let before = bus.snapshot();
    // Read-only history and alarm code (02), thresholds out of range (03).
    for (addr, value, code) in [
        (0x2134u16, 0u16, 2u8),
        (0x213C, 0, 2),
        (0x2136, 0, 2),
        (0x2132, 39, 3),
        (0x2133, 10_001, 3),
        (0x2135, 0x80, 3),
    ] {
        let [ah, al] = addr.to_be_bytes();
        let [vh, vl] = value.to_be_bytes();
        let reply = bus.request(&[1, 6, ah, al, vh, vl]).unwrap_or_default();
        assert_eq!(reply.get(1..3), Some(&[0x86, code][..]), "{addr:#x}");
    }
    assert_eq!(bus.snapshot(), before);
}

/// Reads 0x6001 (any valid frame to this drive restarts the watchdog).
fn poll(bus: &mut Bus) {
    assert!(bus.request(&[1, 3, 0x60, 0x01, 0, 1]).is_some());
}

#[test]
fn the_watchdog_decelerates_a_moving_axis_and_sets_its_bit() {
    let mut bus = drive();
    // Off by default.
    run(&mut bus, &NOMINAL, 2_000_000);
    assert_eq!(read(&bus, Obj::CommStatus), 0);
    assert!(write(&mut bus, 0x2137, 5));
    assert!(write(&mut bus, 0x6007, 1));
    assert_eq!(write32(&mut bus, 0x6003, 4000), None);
    // Polled every 400 ms it runs on; a frame to another drive does not count.
    for _ in 0..5 {
        run(&mut bus, &NOMINAL, 390_000);
        poll(&mut bus);
    }
    bus.send(&common::frame(&[2, 3, 0x60, 0x01, 0, 1]));
    let out = run(&mut bus, &NOMINAL, 390_000);
    assert_eq!(read(&bus, Obj::CommStatus), 0);
    assert_eq!(out.setpoint.velocity, 4000.0);
    // 500 ms after the last frame to it: the bit, and a ramp down (level 8, 5210 pps²), not a jump.
    let out = run(&mut bus, &NOMINAL, 120_000);
    assert_eq!(read(&bus, Obj::CommStatus), 1);
    assert!(out.setpoint.velocity > 3000.0 && out.setpoint.velocity < 4000.0, "{}", out.setpoint.velocity);
    let out = run(&mut bus, &NOMINAL, 1_500_000);
    assert_eq!(out.setpoint.velocity, 0.0);
    assert!(out.enabled, "the watchdog stops, it does not free the motor");
    // Refused until cleared.
    assert!(write(&mut bus, 0x6007, 0));
    let before = bus.snapshot();
    assert_eq!(write32(&mut bus, 0x6005, 100), Some(4));
    assert_eq!(bus.snapshot(), before);
    assert!(write(&mut bus, 0x2138, 1));
    assert_eq!(write32(&mut bus, 0x6005, 100), None);
}

/// A refused write is still a frame for this drive: the watchdog restarts, though the write's
/// checkpoint undoes everything else it did.
#[test]
fn a_refused_multi_object_write_restarts_the_watchdog() {
    let mut bus = drive();
    assert!(write(&mut bus, 0x2137, 5));
    for _ in 0..5 {
        run(&mut bus, &NOMINAL, 390_000);
        // 0x2137 = 5 (as it is), then 0x2138 = 2 (not a bit it has): refused whole.
        let reply = bus.request(&[1, 0x10, 0x21, 0x37, 0, 2, 4, 0, 5, 0, 2]).unwrap_or_default();
        assert_eq!(reply.get(1), Some(&0x90), "{reply:02X?}");
    }
    run(&mut bus, &NOMINAL, 390_000);
    assert_eq!(read(&bus, Obj::CommStatus), 0);
    run(&mut bus, &NOMINAL, 120_000);
    assert_eq!(read(&bus, Obj::CommStatus), 1);
}

#[test]
fn the_watchdog_counts_from_power_up() {
    let mut params = Params::factory();
    assert!(params.set(Obj::CommTimeout, 1));
    let mut drive = Drive::boot(DriveConfig::default(), &params, 0);
    let mut t = 0;
    while t < 99_950 {
        drive.tick_with(Instant::from_micros(t), &NOMINAL);
        t += 50;
    }
    assert_eq!(drive.state().read(Obj::CommStatus), 0);
    drive.tick_with(Instant::from_micros(100_000), &NOMINAL);
    assert_eq!(drive.state().read(Obj::CommStatus), 1);
    // At rest nothing else happens.
    assert_eq!(drive.state().read(Obj::ErrorStatus), 0);
    assert!(drive.tick_with(Instant::from_micros(100_050), &NOMINAL).enabled);
}

/// Found by the soak: a drive powered up while its clock already read 99 s (as a drive restarted
/// on a running simulated bus) timed out on its first tick.
#[test]
fn the_watchdog_counts_from_power_up_when_the_clock_does_not_start_at_zero() {
    let mut params = Params::factory();
    assert!(params.set(Obj::CommTimeout, 1));
    let mut drive = Drive::boot(DriveConfig::default(), &params, 0);
    let start = 99_000_000;
    let mut t = start;
    while t < start + 99_950 {
        drive.tick_with(Instant::from_micros(t), &NOMINAL);
        t += 50;
    }
    assert_eq!(drive.state().read(Obj::CommStatus), 0);
    drive.tick_with(Instant::from_micros(start + 100_000), &NOMINAL);
    assert_eq!(drive.state().read(Obj::CommStatus), 1);
}

/// 0x21F8 takes exactly the bits `faults::detect` names, and its factory value all but the
/// store's.
#[test]
fn the_fault_mask_takes_the_named_detections() {
    use drive_core::faults::detect;
    use drive_core::od::Range;
    assert_eq!(*Obj::FaultMask.def().range, Range::Bits(u32::from(detect::ALL)));
    assert_eq!(Obj::FaultMask.def().default, u32::from(detect::ALL & !detect::STORE));
}

/// 0x21F6 and 0x21F7 in the native map: a move or a run beyond the overspeed limit is refused
/// (04) with nothing moved and 0x21F7 at 30; within it the move runs and 0x21F7 is 0 again; a
/// limit lowered under the running speed latches the overspeed alarm.
#[test]
fn the_overspeed_limit_refuses_faster_motion_and_says_why() {
    let mut bus = drive();
    run(&mut bus, &NOMINAL, 1000);
    // 4000 full steps a second is 1200 r/min: over a limit of 600.
    assert!(write(&mut bus, 0x21F6, 600));
    assert!(!write(&mut bus, 0x21F6, 3001), "beyond the manual's 3000");
    let before = bus.snapshot();
    assert_eq!(write32(&mut bus, 0x6005, 1000), Some(4));
    assert_eq!(read(&bus, Obj::NotMovingCode), 30);
    run(&mut bus, &NOMINAL, 100_000);
    assert_eq!(bus.drive.state().position(), 0);
    assert_eq!(bus.snapshot(), before, "nothing else changed");
    // A homing that moves searches at 0x2163 (3200 full steps a second, 960 r/min): refused
    // too; method 35 (the present position) moves nothing and is taken.
    assert!(write(&mut bus, 0x2160, 33));
    assert!(!write(&mut bus, 0x2161, 1));
    assert_eq!(read(&bus, Obj::NotMovingCode), 30);
    assert!(write(&mut bus, 0x2160, 35));
    assert!(write(&mut bus, 0x2161, 1));
    run(&mut bus, &NOMINAL, 10_000);
    // Velocity mode: the run at 0x6003 is refused too.
    assert!(write(&mut bus, 0x6007, 1));
    assert_eq!(write32(&mut bus, 0x6003, 4000), Some(4));
    // 1000 full steps a second (300 r/min) runs, and the code is 0 again.
    assert_eq!(write32(&mut bus, 0x6003, 1000), None);
    assert_eq!(read(&bus, Obj::NotMovingCode), 0);
    run(&mut bus, &NOMINAL, 500_000);
    assert!(bus.drive.state().position() > 0);
    // A limit lowered under the running speed: the next tick latches the overspeed alarm (31),
    // and the power stage is off.
    assert!(write(&mut bus, 0x21F6, 100));
    let out = run(&mut bus, &NOMINAL, 100);
    assert!(!out.enabled);
    assert_eq!(read(&bus, Obj::DriveFaults) & 0x10, 0x10);
    assert_eq!(read(&bus, Obj::AlarmCode), u32::from(alarm::OVERSPEED));
}
