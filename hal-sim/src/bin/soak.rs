//! `soak`: several simulated drives on one bus under seeded random traffic for simulated hours
//! (see [`hal_sim::soak`]). `cargo xtask soak` runs it in release.

use std::process::ExitCode;

use clap::Parser;
use hal_sim::soak::{Config, run};

/// Soak the simulated drives: random legal traffic, disturbances, checks all along.
#[derive(Parser)]
struct Args {
    /// The seed of every random choice: the same seed replays the same run.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Simulated hours to run (added to --minutes).
    #[arg(long, default_value_t = 0.0)]
    hours: f64,
    /// Simulated minutes to run (added to --hours; 5 if neither is given).
    #[arg(long, default_value_t = 0.0)]
    minutes: f64,
    /// Drives on the bus.
    #[arg(long, default_value_t = 4)]
    axes: u8,
    /// Print figures every this many simulated seconds.
    #[arg(long, default_value_t = 600)]
    progress: u64,
    /// Print every operation as it is done (to follow a replayed failure).
    #[arg(long)]
    trace: bool,
    /// How the windings are driven: `chopper` (ideal) or `bridges` (the G474's power stage).
    #[arg(long, value_name = "KIND", default_value = "chopper")]
    power_stage: hal_sim::bridges::PowerStage,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let mut minutes = args.hours * 60.0 + args.minutes;
    if minutes <= 0.0 {
        minutes = 5.0;
    }
    let cfg = Config {
        seed: args.seed,
        duration_us: (minutes * 60e6) as u64,
        axes: args.axes,
        progress_s: args.progress,
        trace: args.trace,
        power_stage: args.power_stage,
    };
    eprintln!(
        "soak: seed {}, {} drives, {minutes} simulated minutes, power stage {:?}",
        cfg.seed, cfg.axes, cfg.power_stage
    );
    match run(&cfg) {
        Ok(report) => {
            println!("soak passed: seed {}, {} drives: {report}", cfg.seed, cfg.axes);
            ExitCode::SUCCESS
        }
        Err(failure) => {
            eprintln!("{failure}");
            ExitCode::FAILURE
        }
    }
}
