//! The native position and velocity modes (seed 000 §5.5, §9.4) on the control tick.

mod common;
use common::Bus;
use drive_core::control::TICK_MICROS;
use drive_core::od::Obj;
use drive_core::{Exception, Instant};

/// Runs control ticks for `us` microseconds; returns the largest |velocity| and |acceleration|.
/// The rates are `f32`: a limit holds to its precision, one part in 10^6.
fn run(bus: &mut Bus, us: u64) -> (f64, f64) {
    let (mut v, mut a) = (0.0f64, 0.0f64);
    let end = bus.now + us;
    while bus.now < end {
        bus.now += TICK_MICROS;
        let out = bus.drive.tick(Instant::from_micros(bus.now));
        v = v.max(f64::from(out.setpoint.velocity.abs()));
        a = a.max(f64::from(out.setpoint.acceleration.abs()));
    }
    (v, a)
}

fn write(bus: &mut Bus, reg: u16, value: u16) -> Option<Vec<u8>> {
    let [rh, rl] = reg.to_be_bytes();
    let [vh, vl] = value.to_be_bytes();
    bus.request(&[0x01, 0x06, rh, rl, vh, vl])
}

fn busy(bus: &Bus) -> bool {
    bus.drive.state().read(Obj::ControllerStatus) & 0x08 != 0
}

#[test]
fn section_9_4_1_relative_move() {
    let mut bus = Bus::factory();
    for (reg, v) in
        [(0x600C, 32), (0x600D, 1000), (0x6003, 0), (0x6004, 32000), (0x6002, 0), (0x6005, 0), (0x6006, 32000)]
    {
        write(&mut bus, reg, v).expect("answered");
    }
    assert!(busy(&bus), "busy as soon as the move is accepted");
    let (vmax, amax) = run(&mut bus, 10_000_000);
    assert!(!busy(&bus));
    assert_eq!(bus.drive.state().read_i32(Obj::Position), 32000);
    // Level 8 (5210 pps²) over 32000 steps peaks near 12800 pps, short of 32000.
    assert!(vmax <= 32000.0 * (1.0 + 1e-6) && vmax > 12000.0, "{vmax}");
    assert!(amax <= 5210.0 * (1.0 + 1e-6), "level 8: {amax}");
}

#[test]
fn relative_move_backwards_and_while_busy_is_ignored() {
    let mut bus = Bus::factory();
    bus.request(&[0x01, 0x10, 0x60, 0x03, 0x00, 0x02, 0x04, 0x00, 0x00, 0x7D, 0x00]).expect("speed");
    write(&mut bus, 0x6002, 1).expect("reverse");
    bus.request(&[0x01, 0x10, 0x60, 0x05, 0x00, 0x02, 0x04, 0x00, 0x00, 0x03, 0xE8]).expect("move 1000");
    run(&mut bus, 20_000);
    // Busy: a second relative move is ignored (normal reply).
    let r = bus.request(&[0x01, 0x10, 0x60, 0x05, 0x00, 0x02, 0x04, 0x00, 0x00, 0x03, 0xE8]).expect("answered");
    assert_eq!(r[1], 0x10);
    run(&mut bus, 5_000_000);
    assert_eq!(bus.drive.state().read_i32(Obj::Position), -1000);
}

#[test]
fn absolute_move_retargets_while_moving() {
    let mut bus = Bus::factory();
    bus.request(&[0x01, 0x10, 0x60, 0x03, 0x00, 0x02, 0x04, 0x00, 0x00, 0x7D, 0x00]).expect("speed");
    bus.request(&[0x01, 0x10, 0x60, 0x44, 0x00, 0x02, 0x04, 0x00, 0x01, 0x00, 0x00]).expect("to 65536");
    run(&mut bus, 500_000);
    let mid = bus.drive.state().read_i32(Obj::Position);
    assert!(mid > 0 && mid < 65536);
    bus.request(&[0x01, 0x10, 0x60, 0x44, 0x00, 0x02, 0x04, 0xFF, 0xFF, 0xF0, 0x00]).expect("to -4096");
    let (_, amax) = run(&mut bus, 20_000_000);
    assert!(amax <= 5210.0 * (1.0 + 1e-6), "{amax}");
    assert_eq!(bus.drive.state().read_i32(Obj::Position), -4096);
}

#[test]
fn velocity_mode_and_back_to_position_decelerates() {
    let mut bus = Bus::factory();
    write(&mut bus, 0x6007, 1).expect("velocity mode");
    bus.request(&[0x01, 0x10, 0x60, 0x03, 0x00, 0x02, 0x04, 0xFF, 0xFF, 0x83, 0x00]).expect("-32000");
    run(&mut bus, 8_000_000);
    let out = bus.drive.tick(Instant::from_micros(bus.now + TICK_MICROS));
    assert!((out.setpoint.velocity + 32000.0).abs() < 1e-6, "{}", out.setpoint.velocity);
    assert_eq!(bus.drive.state().read(Obj::Direction), 1);
    write(&mut bus, 0x6007, 0).expect("position mode");
    assert!(busy(&bus));
    run(&mut bus, 10_000_000);
    assert!(!busy(&bus));
}

#[test]
fn speed_zero_stops_velocity_mode_even_while_accelerating() {
    let mut bus = Bus::factory();
    write(&mut bus, 0x6007, 1).expect("velocity mode");
    bus.request(&[0x01, 0x10, 0x60, 0x03, 0x00, 0x02, 0x04, 0xFF, 0xFF, 0x83, 0x00]).expect("-32000");
    // Still accelerating at level 8 (5210 pps²) after one second.
    run(&mut bus, 1_000_000);
    assert!(busy(&bus));
    bus.request(&[0x01, 0x10, 0x60, 0x03, 0x00, 0x02, 0x04, 0x00, 0x00, 0x00, 0x00]).expect("speed 0");
    run(&mut bus, 10_000_000);
    assert!(!busy(&bus));
}

#[test]
fn refused_moves_do_not_move() {
    let mut bus = Bus::factory();
    // Speed 0: nothing to plan.
    let r = bus.request(&[0x01, 0x10, 0x60, 0x05, 0x00, 0x02, 0x04, 0x00, 0x00, 0x03, 0xE8]);
    assert_eq!(r, common::reply(&[0x01, 0x90, Exception::ServerDeviceFailure.code()]));
    bus.request(&[0x01, 0x10, 0x60, 0x03, 0x00, 0x02, 0x04, 0x00, 0x00, 0x7D, 0x00]).expect("speed");
    // Disabled.
    write(&mut bus, 0x6011, 0).expect("free");
    let r = bus.request(&[0x01, 0x10, 0x60, 0x05, 0x00, 0x02, 0x04, 0x00, 0x00, 0x03, 0xE8]);
    assert_eq!(r, common::reply(&[0x01, 0x90, 0x04]));
    write(&mut bus, 0x6011, 1).expect("enable");
    // An error bit set.
    bus.drive.state_mut().status_mut().error = 0x01;
    let r = bus.request(&[0x01, 0x10, 0x60, 0x05, 0x00, 0x02, 0x04, 0x00, 0x00, 0x03, 0xE8]);
    assert_eq!(r, common::reply(&[0x01, 0x90, 0x04]));
    run(&mut bus, 1_000_000);
    assert_eq!(bus.drive.state().read_i32(Obj::Position), 0);
    assert!(!busy(&bus));
}

#[test]
fn stop_halts_at_once() {
    let mut bus = Bus::factory();
    bus.request(&[0x01, 0x10, 0x60, 0x03, 0x00, 0x02, 0x04, 0x00, 0x00, 0x7D, 0x00]).expect("speed");
    bus.request(&[0x01, 0x10, 0x60, 0x05, 0x00, 0x02, 0x04, 0x00, 0x01, 0x00, 0x00]).expect("move");
    run(&mut bus, 300_000);
    write(&mut bus, 0x6053, 0).expect("stop");
    let at = bus.drive.state().read_i32(Obj::Position);
    run(&mut bus, 100_000);
    assert!(!busy(&bus));
    assert_eq!(bus.drive.state().read_i32(Obj::Position), at);
}

#[test]
fn far_travel_does_not_drift() {
    let mut bus = Bus::factory();
    // Level 0: no ramp, 200 kpps; 2^31 + 12345 microsteps away in three hops.
    write(&mut bus, 0x600A, 0).expect("no ramp");
    write(&mut bus, 0x600B, 0).expect("no ramp");
    bus.request(&[0x01, 0x10, 0x60, 0x03, 0x00, 0x02, 0x04, 0x00, 0x03, 0x0D, 0x40]).expect("200000 pps");
    let hop = 0x7FFF_FFFFu32 / 3 * 3 / 3;
    for _ in 0..3 {
        let [a, b, c, d] = hop.to_be_bytes();
        bus.request(&[0x01, 0x10, 0x60, 0x05, 0x00, 0x02, 0x04, a, b, c, d]).expect("move");
        let secs = u64::from(hop) / 200_000 + 1;
        // Tick coarsely: evaluation is by time, not by summing.
        let end = bus.now + secs * 1_000_000 + 100_000;
        while bus.now < end {
            bus.now += 1_000_000;
            bus.drive.tick(Instant::from_micros(bus.now));
        }
    }
    assert_eq!(bus.drive.state().read_i32(Obj::Position), (3 * i64::from(hop)) as i32);
}

#[test]
fn one_request_sets_the_speed_then_moves() {
    // 0x6002..0x6006 in one 0x10: direction, speed 32000, relative move 6400. The move is checked
    // with the speed written before it in the same request.
    let mut bus = Bus::factory();
    let r = bus.request(&[0x01, 0x10, 0x60, 0x02, 0x00, 0x05, 0x0A, 0, 0, 0, 0, 0x7D, 0x00, 0, 0, 0x19, 0x00]);
    assert_eq!(r.map(|r| r[1]), Some(0x10));
    run(&mut bus, 5_000_000);
    assert_eq!(bus.drive.state().read_i32(Obj::Position), 6400);
    // The same with a speed out of range: nothing is written, nothing moves.
    let r = bus.request(&[0x01, 0x10, 0x60, 0x02, 0x00, 0x05, 0x0A, 0, 0, 0, 0x04, 0x7D, 0x00, 0, 0, 0x19, 0x00]);
    assert_eq!(r.map(|r| r[1]), Some(0x90));
    run(&mut bus, 1_000_000);
    assert_eq!(bus.drive.state().read_i32(Obj::Position), 6400);
    assert_eq!(bus.drive.state().read_i32(Obj::MaxSpeed), 32000);
}
