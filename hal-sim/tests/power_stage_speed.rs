//! How fast the simulator runs with the G474's bridges (`--power-stage bridges`): simulated
//! seconds a wall-clock second on one core, which must be at least 50 (issue 39, item 6). Alone
//! in its test binary, so that no other test shares the run's time.

use std::time::Instant;

use drive_core::Drive;
use drive_core::od::Obj;
use hal_sim::bridges::{PowerStage, SensingOptions};
use hal_sim::motor::{Motor, MotorCatalog, MotorInputs};
use hal_sim::plant::Plant;

/// Simulated seconds a wall second over 10 s of the NEMA 17 turning at 5 turns a second
/// (velocity mode, 1/32, 1 A) through `stage`.
fn speed(stage: PowerStage) -> f64 {
    let params = MotorCatalog::builtin().get(hal_sim::DEFAULT_MOTOR).cloned().expect("catalogue motor");
    let mut plant = Plant::new(Drive::factory(), Motor::new(params, MotorInputs::default()));
    plant.set_power_stage(stage, SensingOptions::default());
    for (obj, v) in [(Obj::Microsteps, 32), (Obj::PhaseCurrent, 1000), (Obj::AccelLevel, 1), (Obj::Mode, 1)] {
        assert_eq!(plant.write(obj, v), Ok(()), "{obj:?}");
    }
    assert_eq!(plant.write(Obj::MaxSpeed, 32_000), Ok(()));
    let secs = 10.0;
    let start = Instant::now();
    plant.run_for(secs);
    let wall = start.elapsed().as_secs_f64();
    let turned = plant.motor().rotor_full_steps() / 200.0;
    println!("{stage:?}: {secs} s simulated in {wall:.3} s: {:.0}× real time ({turned:.1} turns)", secs / wall);
    assert!(turned > 40.0, "the motor did not turn: {turned} turns");
    secs / wall
}

#[test]
fn the_bridges_run_at_least_50_times_faster_than_real_time() {
    let chopper = speed(PowerStage::Chopper);
    let bridges = speed(PowerStage::Bridges);
    println!("bridges at {:.2} of the chopper's speed", bridges / chopper);
    assert!(bridges >= 50.0, "{bridges:.1}× real time");
}
