//! The motor direction 0x21CA (seed 002's 0201) on the simulated motor: with 1 at power-up the
//! shaft turns the other way for the same commands in open loop, in both closed loops (the
//! encoder read mirrored) and with the sensorless stall detection on (phase B read mirrored, no
//! false stall); positions read as commanded.

use drive_core::od::Obj;
use drive_core::{Drive, DriveConfig, Params};
use hal_sim::DEFAULT_MOTOR;
use hal_sim::motor::{Motor, MotorCatalog, MotorInputs};
use hal_sim::plant::Plant;

/// Objects set before power-up.
type Settings = &'static [(Obj, u32)];

/// A drive booted with `settings` (and 1/16 microsteps, 1 A, a 1000-line encoder) turning the
/// NEMA 17.
fn plant(settings: &[(Obj, u32)]) -> Plant {
    let mut params = Params::factory();
    let base = [(Obj::EncoderCpr, 1000), (Obj::Microsteps, 16), (Obj::PhaseCurrent, 1000), (Obj::StallLength, 255)];
    for &(obj, v) in base.iter().chain(settings) {
        assert!(params.set(obj, v), "{obj:?}");
    }
    let motor = MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().expect("catalogue motor");
    let mut p = Plant::new(Drive::boot(DriveConfig::default(), &params, 0), Motor::new(motor, MotorInputs::default()));
    p.run_for(0.05);
    p
}

/// Moves 100 full steps up (1 600 microsteps, or 2 000 counts in closed loop) at 200 full steps
/// a second: the rotor's travel in full steps, and the position the drive reads.
fn move_up(p: &mut Plant, closed: bool) -> (f64, i32) {
    let start = p.motor().rotor_full_steps();
    let (distance, speed) = if closed { (2000, 4000) } else { (1600, 3200) };
    assert_eq!(p.write(Obj::MaxSpeed, speed), Ok(()));
    assert_eq!(p.write(Obj::RelativeMove, distance), Ok(()));
    p.run_for(2.0);
    (p.motor().rotor_full_steps() - start, p.drive().state().read_i32(Obj::Position))
}

#[test]
fn a_reversed_motor_turns_the_other_way_in_every_loop() {
    let cases: [(&str, Settings, bool); 4] = [
        ("open loop", &[], false),
        ("position loop", &[(Obj::Feedback, 1), (Obj::TorqueLoop, 0)], true),
        ("servo loop", &[(Obj::Feedback, 1), (Obj::TorqueLoop, 1)], true),
        ("sensorless detection", &[(Obj::StallDetect, 1), (Obj::StallStop, 1)], false),
    ];
    for (name, settings, closed) in cases {
        let mut forward = plant(settings);
        let (travel, position) = move_up(&mut forward, closed);
        assert!((travel - 100.0).abs() < 0.2, "{name}: forward {travel} full steps");
        let reversed: Vec<_> = settings.iter().copied().chain([(Obj::MotorDirection, 1)]).collect();
        let mut back = plant(&reversed);
        let (travel_back, position_back) = move_up(&mut back, closed);
        assert!((travel_back + 100.0).abs() < 0.2, "{name}: reversed {travel_back} full steps");
        assert_eq!(position_back, position, "{name}: the position reads as commanded");
        let status = back.drive().state().read(Obj::ControllerStatus);
        assert_eq!(status & 0b100, 0, "{name}: no stall");
        assert_eq!(back.drive().state().read(Obj::ErrorStatus), 0, "{name}: no alarm");
    }
}

#[test]
fn the_direction_takes_effect_at_the_next_power_up() {
    let mut p = plant(&[]);
    assert_eq!(p.write(Obj::MotorDirection, 1), Ok(()));
    let (travel, _) = move_up(&mut p, false);
    assert!((travel - 100.0).abs() < 0.2, "still forward until a restart: {travel}");
}
