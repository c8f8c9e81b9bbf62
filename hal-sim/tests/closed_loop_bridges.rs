//! The closed loop through the G474's bridges (`suites/closed_loop.rs`): the drive's own current
//! loop on the ADC's view, the servo loop's current on the rotor's q axis (field-oriented: the
//! commutation one full step, 90° electrical, ahead of the measured rotor, i_d = 0).

/// The power stage the suite runs on.
const STAGE: hal_sim::bridges::PowerStage = hal_sim::bridges::PowerStage::Bridges;

include!("suites/closed_loop.rs");

/// The current vector's amplitude over `secs`, A (mean of the ticks).
fn mean_current(p: &mut Plant, secs: f64) -> f64 {
    let ticks = (secs * 20_000.0) as u32;
    let mut sum = 0.0;
    for _ in 0..ticks {
        p.advance_to(p.next_tick());
        let (a, b) = p.motor().phase_currents();
        sum += a.hypot(b);
    }
    sum / f64::from(ticks)
}

#[test]
fn the_servo_loop_holds_a_load_with_the_current_it_needs() {
    // 0.05 N·m on the NEMA 17 (K_m 0.21 N·m/A): 0.24 A on the q axis. Open loop holds it with
    // all of 0x600D's 1 A, whatever the load.
    let load = MotorInputs { load_torque_nm: 0.05, ..MotorInputs::default() };
    let mut open = plant_with(0, 0, load);
    run(&mut open, 0.5);
    let open_a = mean_current(&mut open, 0.2);
    let mut servo = plant_with(1, 1, load);
    run(&mut servo, 1.0);
    let servo_a = mean_current(&mut servo, 0.2);
    let error = read(&servo, Obj::FollowingError);
    let off = rotor(&servo, true) - f64::from(read(&servo, Obj::Position));
    println!(
        "0.05 N·m held: open loop {open_a:.3} A, servo loop {servo_a:.3} A ({:.0} %); following error {error} counts, rotor {off:+.2} counts off",
        100.0 * servo_a / open_a
    );
    assert!((open_a - 1.0).abs() < 0.02, "{open_a}");
    assert!(servo_a <= 0.4 * open_a, "{servo_a} A");
    assert!(error.abs() <= 2 && off.abs() <= 2.0, "{error} {off}");
    assert_eq!(read(&servo, Obj::DriveFaults), 0);
}
