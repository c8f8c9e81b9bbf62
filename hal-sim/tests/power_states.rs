//! The power state machine (`drive_core::power`) on a simulated motor, with the control tick
//! apart from the bus side as on the firmware: a quick stop ramps the rotor down at its
//! deceleration and leaves the drive switch on disabled with the shaft free.

use drive_core::Drive;
use drive_core::od::Obj;
use drive_core::power::DeviceState;
use hal_sim::DEFAULT_MOTOR;
use hal_sim::motor::{Motor, MotorCatalog, MotorInputs};
use hal_sim::plant::Plant;

fn plant() -> Plant {
    let params = MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().expect("catalogue motor");
    let mut p = Plant::new(Drive::factory(), Motor::new(params, MotorInputs::default()));
    for (obj, v) in [(Obj::Microsteps, 16), (Obj::PhaseCurrent, 1000), (Obj::Mode, 5), (Obj::PpRunSpeed, 6400)] {
        assert_eq!(p.write(obj, v), Ok(()), "{obj:?}");
    }
    // Operation enabled, the profile velocity mode running at 6400 pps.
    for cw in [0x06, 0x07, 0x0F, 0x010F, 0x000F] {
        assert_eq!(p.write(Obj::DeviceControl, cw), Ok(()), "controlword {cw:#06x}");
    }
    p.run_for(1.0);
    p
}

fn speed(p: &mut Plant) -> f64 {
    let a = p.rotor_microsteps();
    p.run_for(0.01);
    (p.rotor_microsteps() - a) / 0.01
}

#[test]
fn a_quick_stop_ramps_down_at_its_deceleration_then_frees_the_shaft() {
    let mut p = plant();
    assert!((speed(&mut p) - 6400.0).abs() < 100.0);
    assert_eq!(p.write(Obj::QuickStopDecel, 64_000), Ok(()));
    assert_eq!(p.write(Obj::DeviceControl, 0x000B), Ok(()));
    assert_eq!(p.drive().state().device_state(), DeviceState::QuickStopActive);
    // 6400 pps at 64 000 pps²: 0.1 s; half way, half the speed.
    p.run_for(0.045);
    let v = speed(&mut p);
    assert!((v - 3200.0).abs() < 400.0, "half way down: {v}");
    p.run_for(0.2);
    assert!(speed(&mut p).abs() < 1.0);
    assert_eq!(p.drive().state().device_state(), DeviceState::SwitchOnDisabled);
    assert_eq!(p.drive().state().read(Obj::DeviceStatus) & 0x6F, 0x40);
    p.run_for(0.01);
    assert!(!p.outputs().is_some_and(|o| o.enabled), "the power stage is off");
    // Enabled again, it runs again (halt cleared).
    assert_eq!(p.write(Obj::DeviceControl, 0x010F), Ok(()));
    assert_eq!(p.write(Obj::DeviceControl, 0x000F), Ok(()));
    assert_eq!(p.drive().state().device_state(), DeviceState::OperationEnabled);
    p.run_for(0.5);
    assert!((speed(&mut p) - 6400.0).abs() < 100.0);
}
