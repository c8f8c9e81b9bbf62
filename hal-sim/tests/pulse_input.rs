//! Work mode 3 on the simulated motor: the drive follows a step train on its pulse input in
//! each format, both ways, up to the drive's top speed of 200 kpps without a lost step (the
//! rotor ends on the pulse count); a format that does not match the wiring, or a filter longer
//! than the pulses, does not follow; pulses while the power stage is off or after an external
//! stop are not followed, and following resumes when the master clears the stop; motion writes
//! are refused in the mode and change nothing.

use drive_core::od::{Obj, ObjError};
use hal_sim::machine::{Machine, Switch};
use hal_sim::plant::Plant;
use hal_sim::pulses::{PulseSource, Train, Wiring};

/// Microsteps a full step: 200 kpps is 1562.5 full steps a second (7.8 rev/s).
const PER_STEP: u32 = 128;

/// The NEMA 17 at 24 V, 1/128 microsteps, in work mode 3 with the pulse input set to `format`.
fn plant(format: u32) -> Plant {
    plant_at(format, 128)
}

/// [`plant`] at `microsteps` a full step.
fn plant_at(format: u32, microsteps: u32) -> Plant {
    let mut plant = Plant::factory_on(Machine::default());
    let objects =
        [(Obj::Microsteps, microsteps), (Obj::PhaseCurrent, 1500), (Obj::PulseFormat, format), (Obj::Mode, 3)];
    for (obj, v) in objects {
        set(&mut plant, obj, v);
    }
    plant.run_for(0.02);
    plant
}

fn set(plant: &mut Plant, obj: Obj, value: u32) {
    assert_eq!(plant.write(obj, value), Ok(()), "{obj:?} = {value}");
}

fn setpoint(plant: &Plant) -> i64 {
    plant.outputs().expect("ticked").setpoint.whole
}

/// Connects a source running `count` pulses (signed) on `wiring` at up to `rate` pps, ramping
/// at 10⁶ pps², from now on.
fn connect(plant: &mut Plant, wiring: Wiring, rate: f64, count: i64) {
    connect_ramping(plant, wiring, rate, count, 1e6);
}

/// [`connect`] ramping at `accel` (0: at the rate from the first pulse).
fn connect_ramping(plant: &mut Plant, wiring: Wiring, rate: f64, count: i64, accel: f64) {
    let at_s = plant.next_tick().as_micros() as f64 * 1e-6;
    let train = Train { wiring, rate: rate * count.signum() as f64, count: Some(count.unsigned_abs()), accel, at_s };
    plant.machine_mut().pulses = Some(PulseSource::new(train));
}

/// Runs `secs` tick by tick: the largest move of the setpoint in one tick.
fn run_watching(plant: &mut Plant, secs: f64) -> i64 {
    let mut last = setpoint(plant);
    let mut most = 0;
    for _ in 0..(secs * 20_000.0) as u32 {
        let now = plant.next_tick();
        plant.advance_to(now);
        let p = setpoint(plant);
        most = most.max((p - last).abs());
        last = p;
    }
    most
}

#[test]
fn every_format_is_followed_both_ways_at_the_top_speed_without_a_lost_step() {
    for (wiring, format) in [(Wiring::StepDir, 1), (Wiring::CwCcw, 2), (Wiring::Quadrature, 3)] {
        for count in [300_000i64, -300_000] {
            let mut p = plant(format);
            let (start, rotor0) = (setpoint(&p), p.rotor_microsteps());
            connect(&mut p, wiring, 200_000.0, count);
            // 0.2 s up, 1.3 s at 200 kpps, 0.2 s down, and time to settle.
            let most = run_watching(&mut p, 1.9);
            assert_eq!(setpoint(&p) - start, count, "{wiring:?} {count}: the setpoint ends on the count");
            assert!((10..=11).contains(&most), "{wiring:?}: 200 kpps is 10 pulses a tick: {most}");
            let moved = p.rotor_microsteps() - rotor0;
            let lost = (moved - count as f64).abs() / f64::from(PER_STEP);
            assert!(lost < 0.1, "{wiring:?} {count}: the rotor moved {moved}, {lost} full steps off");
            assert_eq!(p.drive().state().read(Obj::Mode), 3);
        }
    }
}

#[test]
fn a_format_unlike_the_wiring_or_a_filter_longer_than_the_pulses_does_not_follow() {
    // Pulse and direction counted as double pulse: every step counts up, the direction is lost.
    let mut p = plant(2);
    let start = setpoint(&p);
    connect(&mut p, Wiring::StepDir, 20_000.0, -10_000);
    p.run_for(1.0);
    assert_eq!(setpoint(&p) - start, 9_999, "the steps counted up, DIR's one edge down");
    // 200 kpps pulses are 2.5 µs wide: filter 15 lets levels of 1.5 µs through, and 300 kpps
    // pulses (1.67 µs) too; filter 15 with 400 kpps (1.25 µs) drops them all.
    let mut p = plant_at(1, 256);
    set(&mut p, Obj::PulseFilter, 15);
    let start = setpoint(&p);
    connect_ramping(&mut p, Wiring::StepDir, 400_000.0, 4_000, 0.0);
    p.run_for(0.1);
    assert_eq!(setpoint(&p), start, "the filter dropped every pulse");
    set(&mut p, Obj::PulseFilter, 14);
    connect_ramping(&mut p, Wiring::StepDir, 400_000.0, 4_000, 0.0);
    p.run_for(0.1);
    assert_eq!(setpoint(&p) - start, 4_000, "a filter of 1.13 µs lets them through");
}

#[test]
fn pulses_count_only_while_the_drive_follows_and_motion_writes_change_nothing() {
    let mut p = plant(1);
    let start = setpoint(&p);
    // Disabled: the pulses are not followed, and the motor does not move.
    set(&mut p, Obj::Enable, 0);
    connect(&mut p, Wiring::StepDir, 10_000.0, 1_000);
    p.run_for(0.3);
    assert_eq!(setpoint(&p), start);
    set(&mut p, Obj::Enable, 1);
    connect(&mut p, Wiring::StepDir, 10_000.0, 1_000);
    p.run_for(0.3);
    assert_eq!(setpoint(&p) - start, 1_000, "enabled again, the next pulses are followed");
    // Moves, a homing and a position are refused while the pulses own the axis.
    let here = setpoint(&p);
    assert_eq!(p.write(Obj::RelativeMove, 5_000), Err(ObjError::NotNow));
    assert_eq!(p.write(Obj::AbsoluteMove, 5_000), Err(ObjError::NotNow));
    assert_eq!(p.write(Obj::MotionCommand, 4), Err(ObjError::NotNow));
    assert_eq!(p.write(Obj::Position, 0), Err(ObjError::Busy));
    assert_eq!(p.write(Obj::HomingControl, 1), Err(ObjError::Busy));
    p.run_for(0.1);
    assert_eq!(setpoint(&p), here, "nothing moved");
    // Leaving the mode stops the following: pulses after it are not followed.
    set(&mut p, Obj::Mode, 0);
    set(&mut p, Obj::MaxSpeed, 3200);
    connect(&mut p, Wiring::StepDir, 10_000.0, 1_000);
    p.run_for(0.3);
    assert_eq!(setpoint(&p), here);
    assert_eq!(p.write(Obj::RelativeMove, 500), Ok(()), "mode 0 moves again");
    p.run_for(1.0);
    assert_eq!(setpoint(&p), here + 500);
}

#[test]
fn an_external_stop_halts_the_following_until_the_master_clears_it() {
    // A limit switch 10 full steps up, NPN, on EXT1 (falling edge).
    let mut p = Plant::factory_on(Machine::new(vec![Switch::parse("ext1:npn:10").expect("switch")], None));
    for (obj, v) in [(Obj::Microsteps, 16), (Obj::ExtStopEnable, 1), (Obj::ExtDebounce, 1), (Obj::Mode, 3)] {
        set(&mut p, obj, v);
    }
    p.run_for(0.02);
    connect(&mut p, Wiring::StepDir, 2_000.0, 1_000);
    p.run_for(0.7);
    let stopped = setpoint(&p);
    assert!((155..=170).contains(&stopped), "stopped at the switch (160 microsteps): {stopped}");
    assert_eq!(p.drive().state().read(Obj::ControllerStatus) & 1, 1, "EXT1's bit latched");
    // Clearing the bit resumes the following: pulses back off the switch are followed.
    set(&mut p, Obj::ControllerStatus, 1);
    p.run_for(0.01);
    connect(&mut p, Wiring::StepDir, 2_000.0, -100);
    p.run_for(0.2);
    assert_eq!(setpoint(&p), stopped - 100);
}

#[test]
fn pulses_into_an_active_limit_input_are_dropped_and_those_away_from_it_followed() {
    // IN1 (EXT1) the positive limit switch, an NPN switch 10 full steps up, pulled up, active low.
    let mut p = Plant::factory_on(Machine::new(vec![Switch::parse("ext1:npn:10").expect("switch")], None));
    let objects = [
        (Obj::Microsteps, 16),
        (Obj::GpioConfig, 1 << 14),
        (Obj::InputLogic, 1),
        (Obj::InputFunction1, 9),
        (Obj::Mode, 3),
    ];
    for (obj, v) in objects {
        set(&mut p, obj, v);
    }
    p.run_for(0.02);
    connect(&mut p, Wiring::StepDir, 2_000.0, 1_000);
    p.run_for(0.7);
    let at = setpoint(&p);
    assert!((150..=165).contains(&at), "stopped following at the limit (160 microsteps): {at}");
    assert_eq!(p.drive().state().read(Obj::Mode), 3, "still following");
    connect(&mut p, Wiring::StepDir, 2_000.0, -100);
    p.run_for(0.2);
    assert_eq!(setpoint(&p), at - 100, "pulses away from the limit are followed");
}
