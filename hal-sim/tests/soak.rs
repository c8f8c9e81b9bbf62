//! The soak on a fixed seed, a few simulated minutes: several drives on one bus under random legal
//! traffic with disturbances and faults on the line (module `hal_sim::soak`). The day-long run is
//! `cargo xtask soak --hours 24`.

use hal_sim::bridges::PowerStage;
use hal_sim::soak::{Config, run};

#[test]
fn three_drives_for_three_simulated_minutes() {
    soak_three_minutes(PowerStage::Chopper);
}

/// The same through the G474's bridges: the current loop, its power-up tune after every power
/// cut, the sensorless stall detection on the ADC's view.
#[test]
fn three_drives_through_the_bridges_for_three_simulated_minutes() {
    soak_three_minutes(PowerStage::Bridges);
}

fn soak_three_minutes(power_stage: PowerStage) {
    let cfg = Config { seed: 2029, duration_us: 180_000_000, axes: 3, progress_s: 0, trace: false, power_stage };
    let report = match run(&cfg) {
        Ok(report) => report,
        Err(failure) => panic!("{failure}"),
    };
    println!("{report}");
    // The run did what a soak is for: traffic of every kind, and faults on the line.
    assert!(report.simulated_us >= cfg.duration_us);
    assert!(report.frames > 2_000, "{report}");
    assert!(report.moves > 20 && report.velocity_runs > 2 && report.pvt_streams > 1, "{report}");
    assert!(report.group_starts > 0 && report.saves > 0 && report.power_cuts > 0, "{report}");
    assert!(report.lost > 0 && report.corrupted > 0, "{report}");
}

#[test]
fn the_same_seed_replays_the_same_run() {
    let cfg = Config {
        seed: 5,
        duration_us: 20_000_000,
        axes: 2,
        progress_s: 0,
        trace: false,
        power_stage: PowerStage::Chopper,
    };
    let run_once = || match run(&cfg) {
        Ok(report) => hal_sim::soak::Report { wall: std::time::Duration::ZERO, ..report },
        Err(failure) => panic!("{failure}"),
    };
    let first = run_once();
    assert!(first.operations > 50, "{first}");
    assert_eq!(run_once(), first);
}
