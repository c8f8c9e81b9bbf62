//! Profile position (PP) and profile velocity (PV) modes: seed 000 §5.11.3, time points 1-5, on
//! the statusword and the position.

mod common;
use common::Bus;
use drive_core::Instant;
use drive_core::control::{SW_SETPOINT_ACK, SW_TARGET_REACHED, TICK_MICROS};
use drive_core::od::Obj;

fn run(bus: &mut Bus, us: u64) -> Vec<(f64, f64)> {
    let mut trace = Vec::new();
    let end = bus.now + us;
    while bus.now < end {
        bus.now += TICK_MICROS;
        let out = bus.drive.tick(Instant::from_micros(bus.now));
        trace.push((out.setpoint.whole as f64, f64::from(out.setpoint.velocity)));
    }
    trace
}

fn write(bus: &mut Bus, reg: u16, value: u16) {
    let [rh, rl] = reg.to_be_bytes();
    let [vh, vl] = value.to_be_bytes();
    let r = bus.request(&[0x01, 0x06, rh, rl, vh, vl]).expect("answered");
    assert_eq!(r[1], 0x06, "write {reg:04X} = {value:04X}: {r:02X?}");
}

fn write32(bus: &mut Bus, reg: u16, value: i32) {
    let [a, b, c, d] = value.to_be_bytes();
    let [rh, rl] = reg.to_be_bytes();
    let r = bus.request(&[0x01, 0x10, rh, rl, 0x00, 0x02, 0x04, a, b, c, d]).expect("answered");
    assert_eq!(r[1], 0x10, "write {reg:04X} = {value}: {r:02X?}");
}

fn statusword(bus: &Bus) -> u16 {
    bus.drive.state().read(Obj::StatusWord) as u16
}

fn position(bus: &Bus) -> i32 {
    bus.drive.state().read_i32(Obj::Position)
}

/// PP mode, run speed 10000 pps, acceleration and deceleration 100000 pps².
fn pp_bus() -> Bus {
    let mut bus = Bus::factory();
    write(&mut bus, 0x6007, 4);
    write32(&mut bus, 0x6072, 10_000);
    write32(&mut bus, 0x6067, 100_000);
    write32(&mut bus, 0x6069, 100_000);
    bus
}

#[test]
fn time_points_1_to_4_buffered_set_points() {
    let mut bus = pp_bus();
    // 1: a target and the rising edge of bit 4: acknowledged, the move starts.
    write32(&mut bus, 0x6074, 20_000);
    write(&mut bus, 0x6070, 0x0010);
    assert_eq!(statusword(&bus) & SW_SETPOINT_ACK, SW_SETPOINT_ACK);
    write(&mut bus, 0x6070, 0x0000);
    assert_eq!(statusword(&bus) & SW_SETPOINT_ACK, 0, "the buffer is free again");
    run(&mut bus, 200_000);
    assert_eq!(statusword(&bus) & SW_TARGET_REACHED, 0);
    // 2-3: a second set-point with its own speed, while moving: buffered.
    write32(&mut bus, 0x6074, 30_000);
    write32(&mut bus, 0x6072, 5_000);
    write(&mut bus, 0x6070, 0x0010);
    write(&mut bus, 0x6070, 0x0000);
    assert_eq!(statusword(&bus) & SW_SETPOINT_ACK, SW_SETPOINT_ACK, "held while buffered");
    // 4: the buffer is full: a third set-point is ignored.
    write32(&mut bus, 0x6074, -5_000);
    write(&mut bus, 0x6070, 0x0010);
    write(&mut bus, 0x6070, 0x0000);
    let trace = run(&mut bus, 6_000_000);
    // The first move stops on its target before the second starts (bit 9 clear).
    let stop = trace.iter().position(|&(p, _)| p == 20_000.0).expect("reaches 20000");
    assert_eq!(trace[stop].1, 0.0, "stands on the first target");
    assert!(trace.iter().all(|&(_, v)| v <= 10_000.0 + 1e-6));
    assert!(trace[stop..].iter().all(|&(_, v)| v <= 5_000.0 + 1e-6), "second move at its own speed");
    assert_eq!(position(&bus), 30_000);
    assert_eq!(statusword(&bus), SW_TARGET_REACHED, "reached, buffer empty, not acknowledging");
}

#[test]
fn time_point_5_change_immediately() {
    let mut bus = pp_bus();
    write32(&mut bus, 0x6074, 20_000);
    write(&mut bus, 0x6070, 0x0010);
    write(&mut bus, 0x6070, 0x0000);
    run(&mut bus, 300_000);
    let here = position(&bus);
    assert!(here > 0 && here < 20_000);
    // Bit 5 set: the new target replaces the running one at once, relative (bit 6) to it.
    write32(&mut bus, 0x6074, -25_000);
    write(&mut bus, 0x6070, 0x0070);
    let trace = run(&mut bus, 3_000_000);
    assert!(trace.iter().all(|&(p, _)| p < 20_000.0), "never went on to the old target");
    assert_eq!(position(&bus), -5_000, "20000 - 25000");
    // Velocity continuous across the change: the trapezoid changes speed at most by a·dt a tick
    // (but for the jump from the stop speed, 600 pps, to rest at the end).
    for w in trace.windows(2).filter(|w| w[1].1 != 0.0) {
        // (The rates are `f32`: good to a few thousandths of a pps at these speeds.)
        assert!((w[1].1 - w[0].1).abs() <= 100_000.0 * 50e-6 + 0.01, "{w:?}");
    }
}

#[test]
fn bit_9_passes_through_the_first_target() {
    let mut bus = pp_bus();
    write32(&mut bus, 0x6074, 20_000);
    write(&mut bus, 0x6070, 0x0010);
    write(&mut bus, 0x6070, 0x0000);
    run(&mut bus, 100_000);
    write32(&mut bus, 0x6074, 40_000);
    write(&mut bus, 0x6070, 0x0210);
    let trace = run(&mut bus, 5_000_000);
    let at = trace.iter().position(|&(p, _)| p >= 20_000.0).expect("passes 20000");
    assert!(trace[at].1 > 9_000.0, "did not stop at the first target: {:?}", trace[at]);
    assert_eq!(position(&bus), 40_000);
}

#[test]
fn halt_stops_and_release_resumes() {
    let mut bus = pp_bus();
    write32(&mut bus, 0x6074, 50_000);
    write(&mut bus, 0x6070, 0x0010);
    run(&mut bus, 500_000);
    write(&mut bus, 0x6070, 0x0110);
    run(&mut bus, 500_000);
    let stopped = position(&bus);
    assert!(stopped < 50_000);
    run(&mut bus, 200_000);
    assert_eq!(position(&bus), stopped, "halted");
    write(&mut bus, 0x6070, 0x0010);
    run(&mut bus, 10_000_000);
    assert_eq!(position(&bus), 50_000);
}

#[test]
fn profile_velocity_mode() {
    let mut bus = Bus::factory();
    write(&mut bus, 0x6007, 5);
    write32(&mut bus, 0x6067, 100_000);
    write32(&mut bus, 0x6069, 100_000);
    write32(&mut bus, 0x6072, -8_000);
    // Halt 1 -> 0 starts it on the start ramp.
    write(&mut bus, 0x6070, 0x0100);
    write(&mut bus, 0x6070, 0x0000);
    let trace = run(&mut bus, 500_000);
    assert_eq!(trace.last().map(|t| t.1), Some(-8_000.0));
    assert_eq!(statusword(&bus) & SW_TARGET_REACHED, SW_TARGET_REACHED, "speed reached");
    // A new speed while running: a smooth change.
    write32(&mut bus, 0x6072, 4_000);
    let trace = run(&mut bus, 500_000);
    assert_eq!(trace.last().map(|t| t.1), Some(4_000.0));
    for w in trace.windows(2) {
        assert!((w[1].1 - w[0].1).abs() <= 100_000.0 * 50e-6 + 0.01, "{w:?}");
    }
    // Halt 0 -> 1 decelerates to a stop.
    write(&mut bus, 0x6070, 0x0100);
    run(&mut bus, 500_000);
    assert!(bus.drive.state().read(Obj::ControllerStatus) & 0x08 == 0);
}
