//! The drive driving the physical motor model in simulated time: the seed examples lose no step
//! with the defaults and the NEMA 17; a load or an acceleration beyond the motor's torque does.

mod common;

use common::{send, write};
use drive_core::od::Obj;
use drive_core::{Drive, Instant};
use hal_sim::DEFAULT_MOTOR;
use hal_sim::motor::{Motor, MotorCatalog, MotorInputs};
use hal_sim::plant::Plant;

fn plant(inputs: MotorInputs) -> Plant {
    let params = MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().expect("catalogue motor");
    Plant::new(Drive::factory(), Motor::new(params, inputs))
}

/// Runs for `secs` of simulated time; the largest |rotor - setpoint| in microsteps on the way.
fn run(plant: &mut Plant, secs: f64) -> f64 {
    let end = plant.next_tick().as_micros() + (secs * 1e6) as u64;
    let mut worst = 0.0f64;
    while plant.next_tick().as_micros() < end {
        let t = plant.next_tick();
        plant.advance_to(t);
        let set = plant.outputs().map_or(0.0, |o| o.setpoint.whole as f64 + o.setpoint.fraction.to_num::<f64>());
        worst = worst.max((plant.rotor_microsteps() - set).abs());
        plant.drive_mut().on_timer(Instant::from_micros(t.as_micros()));
    }
    worst
}

fn setpoint(plant: &Plant) -> f64 {
    plant.outputs().map_or(0.0, |o| o.setpoint.whole as f64)
}

/// §9.4.1-9.4.2 settings: 1/32, 1000 mA, 32000 pps.
fn section_9_4(plant: &mut Plant) {
    for (reg, v) in [(0x600C, 0x20), (0x600D, 0x3E8), (0x6003, 0), (0x6004, 0x7D00), (0x6002, 0)] {
        write(plant, reg, v);
    }
}

#[test]
fn seed_examples_lose_no_step() {
    // §9.4.1: relative 32000.
    let mut p = plant(MotorInputs::default());
    section_9_4(&mut p);
    write(&mut p, 0x6005, 0);
    write(&mut p, 0x6006, 0x7D00);
    let worst = run(&mut p, 6.0);
    assert_eq!(setpoint(&p), 32000.0);
    assert!((p.rotor_microsteps() - 32000.0).abs() < 3.2, "rotor {}", p.rotor_microsteps());
    // The rotor lags by its load angle at speed (half a full step here); a lost step would show
    // as a jump of four full steps (one electrical cycle). Two full steps is the pull-out limit.
    assert!(worst < 64.0, "following error {worst} microsteps");
    // §9.4.2: absolute back to -32000.
    write(&mut p, 0x6044, 0xFFFF);
    write(&mut p, 0x6045, 0x8300);
    let worst = run(&mut p, 10.0);
    assert!((p.rotor_microsteps() + 32000.0).abs() < 3.2, "rotor {}", p.rotor_microsteps());
    assert!(worst < 64.0, "{worst}");
    // §9.4.3: velocity mode at 32000 pps, then back to position mode (decelerates).
    write(&mut p, 0x6007, 1);
    write(&mut p, 0x6003, 0);
    write(&mut p, 0x6004, 0x7D00);
    let worst = run(&mut p, 10.0);
    write(&mut p, 0x6007, 0);
    let worst = worst.max(run(&mut p, 10.0));
    assert!(worst < 64.0, "{worst}");
    assert!((p.rotor_microsteps() - setpoint(&p)).abs() < 3.2);
}

#[test]
fn a_load_beyond_the_torque_loses_steps() {
    // K_m·I at 1 A is 0.21 N·m: a 0.3 N·m load back-drives the motor.
    let mut p = plant(MotorInputs { load_torque_nm: 0.3, ..MotorInputs::default() });
    section_9_4(&mut p);
    write(&mut p, 0x6005, 0);
    write(&mut p, 0x6006, 0x7D00);
    run(&mut p, 6.0);
    assert_eq!(setpoint(&p), 32000.0, "the open-loop drive believes it arrived");
    let lost = (setpoint(&p) - p.rotor_microsteps()) / 32.0;
    assert!(lost > 4.0, "lost only {lost} full steps");
}

#[test]
fn a_step_to_full_speed_loses_steps() {
    // Level 0 disables the ramp: 0 -> 32000 pps (5 rev/s) at once. The bare rotor follows that
    // (the motor's start-stop rate is above 1000 full steps/s); with a load of 12 times the
    // rotor's inertia it cannot.
    let mut p = plant(MotorInputs { load_inertia_kgm2: 1e-4, ..MotorInputs::default() });
    section_9_4(&mut p);
    write(&mut p, 0x600A, 0);
    write(&mut p, 0x600B, 0);
    write(&mut p, 0x6008, 32000);
    write(&mut p, 0x6009, 32000);
    write(&mut p, 0x6005, 0);
    write(&mut p, 0x6006, 0x7D00);
    run(&mut p, 3.0);
    let lost = (setpoint(&p) - p.rotor_microsteps()).abs() / 32.0;
    assert!(lost > 4.0, "lost only {lost} full steps");
}

fn write32(plant: &mut Plant, reg: u16, value: i32) {
    let [a, b, c, d] = value.to_be_bytes();
    let [rh, rl] = reg.to_be_bytes();
    let r = send(plant, &[0x01, 0x10, rh, rl, 0x00, 0x02, 0x04, a, b, c, d]);
    assert_eq!(r[1], 0x10, "{reg:04X}: {r:02X?}");
}

#[test]
fn profile_position_time_points_on_the_rotor() {
    // §5.11.3: a move, a buffered second set-point, an ignored third, then one that changes
    // immediately; the rotor follows every one of them without losing a step.
    let mut p = plant(MotorInputs::default());
    write(&mut p, 0x600C, 0x20);
    write(&mut p, 0x600D, 0x3E8);
    write(&mut p, 0x6007, 4);
    write32(&mut p, 0x6072, 16_000);
    write32(&mut p, 0x6067, 40_000);
    write32(&mut p, 0x6069, 40_000);
    write32(&mut p, 0x6074, 16_000);
    write(&mut p, 0x6070, 0x10);
    write(&mut p, 0x6070, 0x00);
    let mut worst = run(&mut p, 0.3);
    write32(&mut p, 0x6074, 32_000);
    write(&mut p, 0x6070, 0x10);
    write(&mut p, 0x6070, 0x00);
    write32(&mut p, 0x6074, 99_999);
    write(&mut p, 0x6070, 0x10);
    write(&mut p, 0x6070, 0x00);
    worst = worst.max(run(&mut p, 4.0));
    assert_eq!(setpoint(&p), 32_000.0, "the third set-point was ignored");
    write32(&mut p, 0x6074, 0);
    write(&mut p, 0x6070, 0x30);
    worst = worst.max(run(&mut p, 0.5));
    write32(&mut p, 0x6074, 6_400);
    write(&mut p, 0x6070, 0x20);
    write(&mut p, 0x6070, 0x30);
    worst = worst.max(run(&mut p, 4.0));
    assert_eq!(setpoint(&p), 6_400.0);
    assert!((p.rotor_microsteps() - 6_400.0).abs() < 3.2, "rotor {}", p.rotor_microsteps());
    assert!(worst < 64.0, "{worst}");
}

#[test]
fn section_9_4_4_common_settings() {
    // §9.4.4's settings, then §9.4.1's move with them. Its last line (0x200F = 2, save) needs the
    // parameter store, which a bare plant has not: tests/tests/seed_000_motion.rs saves them
    // through a real master and power-cycles the simulator.
    let mut p = plant(MotorInputs::default());
    for (reg, v) in [
        (0x600C, 0x20),
        (0x600D, 0x3E8),
        (0x6008, 0x258),
        (0x6009, 0x258),
        (0x600A, 8),
        (0x600B, 8),
        (0x6013, 3),
        (0x6014, 0),
    ] {
        write(&mut p, reg, v);
    }
    write(&mut p, 0x6003, 0);
    write(&mut p, 0x6004, 0x7D00);
    write(&mut p, 0x6005, 0);
    write(&mut p, 0x6006, 0x7D00);
    let worst = run(&mut p, 6.0);
    assert!((p.rotor_microsteps() - 32000.0).abs() < 3.2 && worst < 64.0);
}

/// Seed 003's power-up jog (0x2013, our 0x21D8) on the simulated rotor: saved on, the drive on
/// the EC-57 map turns the shaft 30° forward, then 15° back, and stands.
#[test]
fn the_power_up_jog_turns_the_rotor_30_degrees_and_back_15() {
    let mut params = drive_core::Params::factory();
    for (obj, v) in [(Obj::RegisterMap, 3), (Obj::PowerUpJog, 1), (Obj::Microsteps, 16), (Obj::PhaseCurrent, 1000)] {
        assert!(params.set(obj, v), "{obj:?}");
    }
    let drive = Drive::boot_with_map(drive_core::DriveConfig::default(), drive_core::maps::Maps::ec57(), &params, 0);
    let motor = MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().expect("catalogue motor");
    let mut plant = Plant::new(drive, Motor::new(motor, MotorInputs::default()));
    // Degrees of the shaft from the rotor's full steps (200 a turn).
    let degrees = |p: &Plant| p.motor().rotor_full_steps() * 360.0 / 200.0;
    let mut farthest = f64::MIN;
    for _ in 0..300 {
        plant.run_for(0.005);
        farthest = farthest.max(degrees(&plant));
    }
    assert!((farthest - 30.0).abs() < 1.0, "30° forward: {farthest:.2}°");
    assert!((degrees(&plant) - 15.0).abs() < 0.5, "15° back: {:.2}°", degrees(&plant));
}

/// Seed 003's 0x2006 (our 0x21DA): disabled, the motor is held where it stands at the standstill
/// current, against a load that turns a freed rotor; a fault frees it all the same.
#[test]
fn a_disabled_drive_holds_the_rotor_when_asked_to() {
    let motor = || MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().expect("catalogue motor");
    let run = |hold: u32| {
        let mut params = drive_core::Params::factory();
        for (obj, v) in [(Obj::DisabledHold, hold), (Obj::PhaseCurrent, 1000), (Obj::IdleCurrent, 50)] {
            assert!(params.set(obj, v), "{obj:?}");
        }
        let drive = Drive::boot(drive_core::DriveConfig::default(), &params, 0);
        let mut plant = Plant::new(drive, Motor::new(motor(), MotorInputs::default()));
        plant.run_for(0.1);
        assert_eq!(plant.write(Obj::Enable, 0), Ok(()));
        plant.inject(hal_sim::inject::Change::LoadTorque(0.05));
        plant.run_for(1.0);
        let out = plant.outputs().expect("ticked");
        let at = (plant.motor().rotor_full_steps(), out.enabled, out.current_ma);
        // An over-voltage latches a fault: the stage off, held or not.
        plant.inject(hal_sim::inject::Change::Supply(70.0));
        plant.run_for(0.05);
        assert!(!plant.outputs().expect("ticked").enabled, "a fault frees the motor");
        at
    };
    let (held, on, current) = run(1);
    assert!(held.abs() < 0.5, "held within half a step: {held:.2}");
    assert!(on && current == 500, "the stage on at the standstill current: {current} mA");
    let (freed, on, _) = run(0);
    assert!(!on, "freed");
    assert!(freed.abs() > 1.0, "a freed rotor turns under the load: {freed:.2} steps");
}

/// Seed 003's soft start (0x200B/0x200C, our 0x21E0/0x21E1): energised with it on, the motor's
/// phase current rises over the set time instead of at once, at power-up and at each enable.
#[test]
fn a_soft_start_ramps_the_motor_current_up() {
    let motor = || MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().expect("catalogue motor");
    // The larger phase current's magnitude, mA, as the drive measures it, after `secs` more.
    let current_after = |plant: &mut Plant, secs: f64| {
        plant.run_for(secs);
        let [a, b] = plant.measurements().phase_ma.expect("measured");
        a.unsigned_abs().max(b.unsigned_abs())
    };
    let power_up = |soft: u32| {
        let mut params = drive_core::Params::factory();
        for (obj, v) in [(Obj::SoftStart, soft), (Obj::SoftStartTime, 400), (Obj::PhaseCurrent, 1000)] {
            assert!(params.set(obj, v), "{obj:?}");
        }
        let drive = Drive::boot(drive_core::DriveConfig::default(), &params, 0);
        Plant::new(drive, Motor::new(motor(), MotorInputs::default()))
    };
    // At once: the full current (the motor stands at its full step: one phase carries it all)
    // within a few of the winding's time constants.
    let mut plant = power_up(0);
    assert!(current_after(&mut plant, 0.02) > 950);
    // Ramped over 400 ms: a quarter after 100 ms, half after 200, all of it after 400.
    let mut plant = power_up(1);
    let at = [0.1, 0.1, 0.2, 0.1].map(|dt| current_after(&mut plant, dt));
    for (got, want) in at.iter().zip([250, 500, 1000, 1000]) {
        assert!(got.abs_diff(want) < 60, "currents {at:?} mA");
    }
    // Freed and energised again: the ramp starts over.
    assert_eq!(plant.write(Obj::Enable, 0), Ok(()));
    assert!(current_after(&mut plant, 0.05) < 30, "freed");
    assert_eq!(plant.write(Obj::Enable, 1), Ok(()));
    let again = current_after(&mut plant, 0.1);
    assert!(again.abs_diff(250) < 60, "{again} mA 100 ms after the enable");
}
