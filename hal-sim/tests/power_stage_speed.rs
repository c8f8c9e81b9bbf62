//! How fast the simulator runs with the G474's bridges (`--power-stage bridges`): simulated
//! seconds a second of one core, which must be at least 50 (issue 39, item 6). The core's second
//! is the test thread's own CPU time, not the wall clock's: on a machine busy with other work
//! (CI builds beside the tests) the wall clock counts the time the thread waits for a core.

use std::time::Duration;

use nix::time::{ClockId, clock_gettime};

use drive_core::Drive;
use drive_core::od::Obj;
use hal_sim::bridges::{PowerStage, SensingOptions};
use hal_sim::motor::{Motor, MotorCatalog, MotorInputs};
use hal_sim::plant::Plant;

/// This thread's CPU time so far.
fn cpu_time() -> Duration {
    clock_gettime(ClockId::CLOCK_THREAD_CPUTIME_ID).map(Duration::from).expect("the thread's CPU clock")
}

/// Simulated seconds a second of the thread's CPU time over 10 s of the NEMA 17 turning at 5 turns a second
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
    let start = cpu_time();
    plant.run_for(secs);
    let cpu = (cpu_time() - start).as_secs_f64();
    let turned = plant.motor().rotor_full_steps() / 200.0;
    println!("{stage:?}: {secs} s simulated in {cpu:.3} s of CPU: {:.0}× real time ({turned:.1} turns)", secs / cpu);
    assert!(turned > 40.0, "the motor did not turn: {turned} turns");
    secs / cpu
}

#[test]
fn the_bridges_run_at_least_50_times_faster_than_real_time() {
    let chopper = speed(PowerStage::Chopper);
    let bridges = speed(PowerStage::Bridges);
    println!("bridges at {:.2} of the chopper's speed", bridges / chopper);
    assert!(bridges >= 50.0, "{bridges:.1}× real time");
}
