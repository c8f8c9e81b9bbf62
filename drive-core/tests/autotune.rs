//! The auto-tune (issue 39, item 3's acceptance: "R and L within 5 % of the catalogue's for every
//! motor, at 12 and 48 V, with the ADC's noise on"): each motor of `hal-sim/motors.toml` through
//! the winding model of `winding/` (one period of delay, zero-order hold, the timers'
//! quantisation, 300 ns of dead time), the current read through the board's 12-bit sensing
//! (5.37 mA a code) with an offset of a few codes and Gaussian noise. `cargo test -p drive-core
//! --test autotune -- --nocapture` prints the table of `docs/current-loop.md`.

mod winding;

use drive_core::autotune::{Autotune, Error, Estimate, Step};
use drive_core::current::{CurrentLoopSettings, CurrentLoopState};
use winding::{Motor, PWM_HZ, Sensing, Winding, catalogue};

/// Runs a measurement to its end: the estimate and the periods it took.
fn measure(motor: &Motor, v_bus: f64, test_current: f32, mut sensing: Sensing) -> (Result<Estimate, Error>, u32) {
    let mut tune = Autotune::new(test_current, PWM_HZ as f32).unwrap_or_else(|e| panic!("{e:?}"));
    let mut w = Winding::new(motor, v_bus);
    for n in 0..100_000 {
        match tune.step(sensing.read(w.i), v_bus as f32) {
            Step::Apply(v) => w.period(v),
            Step::Done(result) => return (result, n),
        }
    }
    panic!("{}: no end", motor.name)
}

/// The noise of the acceptance: 3 codes (16 mA) standard deviation, 4 codes of offset.
/// The loop `s` on `w` at 24 V: 0.5 A for 100 ms, then a step to 0.75 A; the step's share made
/// at each of the 400 periods after it.
fn step_response(s: &CurrentLoopSettings, mut w: Winding) -> Vec<f64> {
    let mut state = CurrentLoopState::default();
    let mut y = Vec::new();
    for k in 0..2_400 {
        let reference = if k < 2_000 { 0.5 } else { 0.75 };
        if k >= 2_000 {
            y.push((w.i - 0.5) / 0.25);
        }
        let v = s.step(&mut state, [reference, 0.0], [w.i as f32, 0.0], [0.0; 2], 24.0);
        w.period(v[0]);
    }
    y
}

fn noisy(seed: u64) -> Sensing {
    Sensing::new(4.0, 3.0, seed)
}

#[test]
fn r_and_l_within_5_percent_at_12_and_48_volts_with_noise() {
    println!(
        "| motor | bus | R (catalogue) | R measured (worst of 10) | L (catalogue) | L measured (worst of 10) | lost volts | time |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut failures = Vec::new();
    for motor in catalogue() {
        for v_bus in [12.0, 48.0] {
            let test_current = (0.5 * motor.rated) as f32;
            let (mut worst_r, mut worst_l, mut lost, mut periods) = (0.0f64, 0.0f64, 0.0, 0);
            for seed in 0..10 {
                let (result, n) = measure(&motor, v_bus, test_current, noisy(seed));
                let e = result.unwrap_or_else(|e| panic!("{} at {v_bus} V: {e:?}", motor.name));
                let (dr, dl) = (f64::from(e.resistance) / motor.r - 1.0, f64::from(e.inductance) / motor.l - 1.0);
                if dr.abs() > worst_r.abs() {
                    worst_r = dr;
                }
                if dl.abs() > worst_l.abs() {
                    worst_l = dl;
                }
                if dr.abs() > 0.05 || dl.abs() > 0.05 {
                    failures.push(format!("{} {v_bus} V seed {seed}: {e:?}", motor.name));
                }
                (lost, periods) = (e.lost_volts, n);
            }
            println!(
                "| {} | {v_bus} V | {} Ω | {:+.2} % | {} mH | {:+.2} % | {lost:.3} V | {:.0} ms |",
                motor.name,
                motor.r,
                worst_r * 100.0,
                motor.l * 1000.0,
                worst_l * 100.0,
                f64::from(periods) / PWM_HZ * 1000.0
            );
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}

#[test]
fn motors_beyond_the_catalogue() {
    // Small and large windings around the catalogue's, at 24 V, with the same noise.
    for (name, r, l, rated) in [
        ("0.3 Ω, 0.4 mH, 4 A", 0.3, 0.4e-3, 4.0),
        ("0.8 Ω, 1.2 mH, 2.8 A", 0.8, 1.2e-3, 2.8),
        ("4 Ω, 12 mH, 1 A", 4.0, 12e-3, 1.0),
        ("12 Ω, 40 mH, 0.4 A", 12.0, 40e-3, 0.4),
    ] {
        let motor = Motor { name: name.into(), r, l, rated, km: 0.0, teeth: 50.0 };
        let (result, _) = measure(&motor, 24.0, (0.5 * rated) as f32, noisy(1));
        let e = result.unwrap_or_else(|e| panic!("{name}: {e:?}"));
        let (dr, dl) = (f64::from(e.resistance) / r - 1.0, f64::from(e.inductance) / l - 1.0);
        println!("{name}: R {:+.2} %, L {:+.2} %", dr * 100.0, dl * 100.0);
        assert!(dr.abs() < 0.05 && dl.abs() < 0.05, "{name}: {e:?}");
    }
}

#[test]
fn the_loop_tuned_from_the_measurement_makes_the_step() {
    use drive_core::current::recommended_bandwidth;
    for motor in catalogue() {
        let (result, _) = measure(&motor, 24.0, (0.5 * motor.rated) as f32, noisy(3));
        let e = result.unwrap_or_else(|e| panic!("{}: {e:?}", motor.name));
        let s = CurrentLoopSettings::new(
            e.resistance,
            e.inductance,
            24.0,
            PWM_HZ as f32,
            recommended_bandwidth(PWM_HZ as f32),
        )
        .and_then(|s| s.with_dead_time(winding::DEAD_TIME as f32, 0.05))
        .unwrap_or_else(|e| panic!("{e:?}"));
        let y = step_response(&s, Winding::new(&motor, 24.0));
        let overshoot = y.iter().fold(0.0f64, |m, &v| m.max(v - 1.0));
        println!("{}: tuned to {:?}: i[3] {:.3}, overshoot {:.1} %", motor.name, e, y[3], overshoot * 100.0);
        assert!(y[3] >= 0.9 && overshoot <= 0.05, "{}", motor.name);
    }
}

#[test]
fn what_it_refuses() {
    let motor = catalogue().remove(0);
    // An open winding: no current.
    let open = Motor { r: 1.0e4, ..motor.clone() };
    assert_eq!(measure(&open, 24.0, 1.0, noisy(0)).0, Err(Error::NoCurrent));
    // A bus out of range.
    assert_eq!(measure(&motor, 0.5, 1.0, noisy(0)).0, Err(Error::Supply));
    // Settings.
    assert_eq!(Autotune::new(0.0, 20_000.0).err(), Some(Error::Settings));
    assert_eq!(Autotune::new(f32::NAN, 20_000.0).err(), Some(Error::Settings));
    assert_eq!(Autotune::new(1.0, 0.0).err(), Some(Error::Settings));
    // A current beyond twice the test current (a winding shorted at the bridge: 10 mΩ, 1 µH)
    // stops it at once.
    let short = Motor { r: 0.01, l: 1.0e-6, ..motor.clone() };
    assert_eq!(measure(&short, 24.0, 1.0, noisy(0)).0, Err(Error::OverCurrent));
    // Once over, it stays over at 0 V.
    let mut tune = Autotune::new(1.0, 20_000.0).unwrap_or_else(|e| panic!("{e:?}"));
    assert_eq!(tune.step(0.0, 0.0), Step::Done(Err(Error::Supply)));
    assert_eq!(tune.step(0.0, 24.0), Step::Done(Err(Error::Supply)));
}

#[test]
fn more_noise_and_offset() {
    // Quantisation alone, and twice the acceptance's noise with a larger offset either way.
    for motor in catalogue() {
        for (sigma, offset) in [(0.0, 0.0), (6.0, 12.0), (6.0, -12.0)] {
            for v_bus in [12.0, 48.0] {
                let (mut worst_r, mut worst_l) = (0.0f64, 0.0f64);
                for seed in 0..5 {
                    let (result, _) =
                        measure(&motor, v_bus, (0.5 * motor.rated) as f32, Sensing::new(offset, sigma, seed));
                    let e = result.unwrap_or_else(|e| panic!("{}: {e:?}", motor.name));
                    worst_r = worst_r.max((f64::from(e.resistance) / motor.r - 1.0).abs());
                    worst_l = worst_l.max((f64::from(e.inductance) / motor.l - 1.0).abs());
                }
                println!(
                    "{} at {v_bus} V, noise {sigma} codes, offset {offset}: |ΔR| ≤ {:.2} %, |ΔL| ≤ {:.2} %",
                    motor.name,
                    worst_r * 100.0,
                    worst_l * 100.0
                );
                assert!(worst_r < 0.05 && worst_l < 0.05, "{}", motor.name);
            }
        }
    }
}

#[test]
fn half_a_period_of_delay() {
    // If the timers took the voltage half a period after the sample (updates at the bottom of
    // the count too) instead of a whole one: what the measurement and the tuned loop make of it.
    use drive_core::current::recommended_bandwidth;
    for motor in catalogue() {
        for v_bus in [12.0, 48.0] {
            let mut tune = Autotune::new((0.5 * motor.rated) as f32, PWM_HZ as f32).unwrap_or_else(|e| panic!("{e:?}"));
            let mut w = Winding::new(&motor, v_bus);
            w.half_delay = true;
            let mut sensing = noisy(5);
            let e = loop {
                match tune.step(sensing.read(w.i), v_bus as f32) {
                    Step::Apply(v) => w.period(v),
                    Step::Done(result) => break result.unwrap_or_else(|e| panic!("{e:?}")),
                }
            };
            let (dr, dl) = (f64::from(e.resistance) / motor.r - 1.0, f64::from(e.inductance) / motor.l - 1.0);
            let s = CurrentLoopSettings::new(
                motor.r as f32,
                motor.l as f32,
                24.0,
                PWM_HZ as f32,
                recommended_bandwidth(PWM_HZ as f32),
            )
            .unwrap_or_else(|e| panic!("{e:?}"));
            let mut w = Winding::new(&motor, 24.0);
            w.half_delay = true;
            let y = step_response(&s, w);
            let overshoot = y.iter().fold(0.0f64, |m, &v| m.max(v - 1.0));
            println!(
                "{} at {v_bus} V, half a period of delay: R {:+.2} %, L {:+.2} %; the loop's step (24 V) i[1..5] {:.3?}, overshoot {:.1} %",
                motor.name,
                dr * 100.0,
                dl * 100.0,
                &y[1..5],
                overshoot * 100.0
            );
            assert!(dr.abs() < 0.05 && dl.abs() < 0.05, "{}", motor.name);
        }
    }
}
