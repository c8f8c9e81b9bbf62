//! Pull-out torque against speed through the ideal chopper and through the G474's bridges
//! (issue 39's acceptance), with its figure and table:
//! `cargo run --release -p hal-sim --example torque_speed -- [PNG]` measures each catalogue
//! motor at 12, 24 and 48 V and 0-20 rev/s (`hal_sim::torque_speed`), draws `PNG` (default
//! `docs/img/torque-speed.png`), writes the table beside it (the same name, `.csv`) and prints
//! it as Markdown: a row a motor, supply and stage, the bridges' torque over the chopper's under
//! theirs.

use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

use hal_sim::bridges::PowerStage;
use hal_sim::motor::MotorCatalog;
use hal_sim::plot::plot_torque_speed;
use hal_sim::torque_speed::{CSV_HEADER, SPEEDS_RPS, SUPPLIES_V, compare, csv_row, measure, setups};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let png = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "docs/img/torque-speed.png".into()));
    let started = Instant::now();
    let curves = measure(&setups(MotorCatalog::builtin().motors(), &SUPPLIES_V), &SPEEDS_RPS);
    let elapsed = started.elapsed().as_secs_f64();
    let title = "Pull-out torque, 1/32 microsteps at the rated current: chopper (solid), G474 bridges (dashed)";
    plot_torque_speed(&curves, &png, title)?;
    let rows = compare(&curves);
    let mut csv = format!("{CSV_HEADER}\n");
    for row in &rows {
        writeln!(csv, "{}", csv_row(row))?;
    }
    std::fs::write(png.with_extension("csv"), csv)?;

    let speeds = SPEEDS_RPS.iter().map(|v| format!(" {v} |")).collect::<String>();
    println!("| motor | supply | stage |{speeds}");
    println!("|---|---|---|{}", "---:|".repeat(SPEEDS_RPS.len()));
    for curve in &curves {
        let s = &curve.setup;
        let cells = curve.points.iter().map(|p| format!(" {:.3} |", p.torque_nm)).collect::<String>();
        let stage = if s.stage == PowerStage::Chopper { "chopper" } else { "bridges" };
        println!("| {} | {} V | {stage} |{cells}", s.motor.name, s.supply_v);
        if s.stage == PowerStage::Bridges {
            let mine = rows.iter().filter(|r| r.motor == s.motor.name && r.supply_v == s.supply_v);
            let ratio = |r: f64| if r.is_finite() { format!(" {r:.3} |") } else { " ∞ |".into() };
            let cells = mine.map(|r| ratio(r.ratio())).collect::<String>();
            println!("| | | bridges / chopper |{cells}");
        }
    }
    for row in rows.iter().filter(|r| r.chopper.alarm != 0 || r.bridges.alarm != 0) {
        println!(
            "{} at {} V, {} rev/s: alarm {} (chopper), {} (bridges) at the lightest load not carried",
            row.motor, row.supply_v, row.chopper.speed_rps, row.chopper.alarm, row.bridges.alarm
        );
    }
    println!("measured in {elapsed:.1} s; {} and its .csv written", png.display());
    Ok(())
}
