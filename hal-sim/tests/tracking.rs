//! Issue 39's acceptance: through the G474's bridges the current vector's amplitude is within
//! 5 % of its reference up to the speed where the supply runs out (`hal_sim::tracking`), each
//! catalogue motor at 12, 24 and 48 V, 1-20 rev/s. Prints the table `docs/current-loop.md`
//! shows.

use hal_sim::motor::MotorCatalog;
use hal_sim::torque_speed::SUPPLIES_V;
use hal_sim::tracking::sweeps;

#[test]
fn the_current_tracks_its_reference_until_the_supply_runs_out() {
    let started = std::time::Instant::now();
    let all = sweeps(MotorCatalog::builtin().motors(), &SUPPLIES_V);
    println!("measured in {:.1} s", started.elapsed().as_secs_f64());
    println!("| motor | supply | rev/s | in step | mean | beyond 5 % | worst | at the limit |");
    println!("|---|---|---:|---|---:|---:|---:|---:|");
    for s in &all {
        for p in &s.points {
            println!(
                "| {} | {} V | {} | {} | {:.3} | {:.4} | {:.3} | {:.3} |",
                s.motor, s.supply_v, p.speed_rps, p.in_step, p.mean, p.off, p.worst, p.saturated
            );
        }
    }
    println!(
        "\n| motor | supply | runs out at, rev/s | speeds within | mean | beyond 5 % | worst | first speed beyond: mean |"
    );
    println!("|---|---|---:|---|---:|---:|---:|---|");
    for s in &all {
        let within: Vec<_> = s.within_supply().collect();
        let furthest = |f: fn(&hal_sim::tracking::Point) -> f64| {
            within.iter().map(|p| f(p)).fold(1.0, |a: f64, b| if (b - 1.0).abs() > (a - 1.0).abs() { b } else { a })
        };
        let beyond = s.points.iter().find(|p| p.speed_rps >= s.supply_out_rps);
        println!(
            "| {} | {} V | {:.2} | {}-{} | {:.3} | {:.4} | {:.3} | {} |",
            s.motor,
            s.supply_v,
            s.supply_out_rps,
            within.first().map_or(0.0, |p| p.speed_rps),
            within.last().map_or(0.0, |p| p.speed_rps),
            furthest(|p| p.mean),
            within.iter().map(|p| p.off).fold(0.0, f64::max),
            furthest(|p| p.worst),
            beyond.map_or("-".into(), |p| format!("{} rev/s: {:.3}", p.speed_rps, p.mean)),
        );
    }
    let mut failed = Vec::new();
    for s in &all {
        let within: Vec<_> = s.within_supply().collect();
        // Every setup has speeds within its supply to check (the NEMA 23 at 12 V the fewest).
        assert!(!within.is_empty(), "{} at {} V: no speed within the supply", s.motor, s.supply_v);
        failed.extend(within.iter().filter(|p| !p.tracks()).map(|p| (s.motor.clone(), s.supply_v, **p)));
    }
    assert!(failed.is_empty(), "not tracking within the supply: {failed:#?}");
}
