//! The simulated stepper against what a real one does: it holds, it follows a gentle ramp, it
//! loses steps when asked too much, and its torque falls with speed. An open-loop step generator
//! (trapezoidal speed profile, microsteps at a 20 kHz control tick) stands in for the drive.
//!
//! `cargo test --release -p hal-sim --test motor_model -- --nocapture` prints the figures: holding
//! deflection, pull-out torque against speed, and how much faster than real time the model runs.

use std::f64::consts::SQRT_2;
use std::path::PathBuf;
use std::time::Instant;

use hal_sim::motor::{DriverCommand, Motor, MotorCatalog, MotorInputs, MotorParams};
use hal_sim::plot::{plot_trace, plot_trace_csv};
use hal_sim::trace::{Trace, TraceRow, load_csv};

/// Microsteps per full step of the test's step generator.
const USTEPS: u32 = 16;
/// The step generator's control tick, s (20 kHz).
const TICK: f64 = 50e-6;

fn nema17() -> MotorParams {
    MotorCatalog::builtin().get("17HS19-2004S1").expect("17HS19-2004S1 in motors.toml").clone()
}

fn at_24v() -> MotorInputs {
    MotorInputs { supply_v: 24.0, ..MotorInputs::default() }
}

/// A trapezoidal speed profile from rest to rest over `distance` full steps (a triangle if the
/// distance is too short to reach `v_max`), then standing still.
#[derive(Clone, Copy, Debug)]
struct Trapezoid {
    /// Cruise speed, full steps/s.
    v_max: f64,
    /// Acceleration and deceleration, full steps/s².
    accel: f64,
    /// Distance, full steps.
    distance: f64,
}

impl Trapezoid {
    fn from_rev(v_max_rps: f64, accel_rps2: f64, distance_rev: f64) -> Self {
        Self { v_max: v_max_rps * 200.0, accel: accel_rps2 * 200.0, distance: distance_rev * 200.0 }
    }

    /// (peak speed, accelerating time, cruising time)
    fn phases(&self) -> (f64, f64, f64) {
        let v = self.v_max.min((self.accel * self.distance).sqrt());
        let ta = v / self.accel;
        let tc = (self.distance - v * ta) / v;
        (v, ta, tc.max(0.0))
    }

    fn duration(&self) -> f64 {
        let (_, ta, tc) = self.phases();
        2.0 * ta + tc
    }

    /// (position in full steps, velocity in full steps/s) at time t.
    fn at(&self, t: f64) -> (f64, f64) {
        let (v, ta, tc) = self.phases();
        let a = self.accel;
        if t <= 0.0 {
            (0.0, 0.0)
        } else if t < ta {
            (0.5 * a * t * t, a * t)
        } else if t < ta + tc {
            (0.5 * v * ta + v * (t - ta), v)
        } else if t < 2.0 * ta + tc {
            let d = 2.0 * ta + tc - t;
            (self.distance - 0.5 * a * d * d, a * d)
        } else {
            (self.distance, 0.0)
        }
    }
}

/// How a run went, in full steps.
#[derive(Clone, Copy, Debug)]
struct Outcome {
    /// Commanded position at the end.
    commanded: f64,
    /// Rotor position at the end.
    rotor: f64,
    /// Largest |commanded − rotor| during the run.
    max_error: f64,
}

impl Outcome {
    fn final_error(&self) -> f64 {
        self.commanded - self.rotor
    }
}

/// Runs the motor for `duration` s under an open-loop step generator: every tick the commanded
/// position (full steps, velocity in full steps/s) is rounded to a microstep and sent at `current`
/// A. `load(t)` sets the load torque (N·m) each tick. Optionally records a trace every tick.
fn drive(
    motor: &mut Motor,
    duration: f64,
    current: f64,
    profile: impl Fn(f64) -> (f64, f64),
    load: impl Fn(f64) -> f64,
    mut trace: Option<&mut Trace>,
) -> Outcome {
    let ticks = (duration / TICK).round() as u64;
    let mut max_error: f64 = 0.0;
    let mut commanded = 0.0;
    for k in 0..ticks {
        let t = k as f64 * TICK;
        let (position, velocity) = profile(t);
        let usteps = (position * f64::from(USTEPS)).round() as i64;
        commanded = usteps as f64 / f64::from(USTEPS);
        let mut inputs = motor.inputs();
        inputs.load_torque_nm = load(t);
        motor.set_inputs(inputs);
        motor.advance(&DriverCommand::at_microstep(usteps, USTEPS, current), TICK);
        max_error = max_error.max((commanded - motor.rotor_full_steps()).abs());
        if let Some(trace) = trace.as_deref_mut() {
            trace.offer_with(|| TraceRow::from_motor(motor, usteps as f64, velocity * f64::from(USTEPS), USTEPS));
        }
    }
    Outcome { commanded, rotor: motor.rotor_full_steps(), max_error }
}

fn no_load(_: f64) -> f64 {
    0.0
}

/// A load ramped in linearly from `from` s over `ramp` s to `torque`, then held: a step of load
/// would ring the (lightly damped) rotor to twice its deflection.
fn ramped_load(torque: f64, from: f64, ramp: f64) -> impl Fn(f64) -> f64 {
    move |t| torque * ((t - from) / ramp).clamp(0.0, 1.0)
}

fn out_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
}

#[test]
fn holds_at_standstill_deflects_under_load_and_slips_above_holding_torque() {
    let p = nema17();
    let rated = p.rated_current_a;
    let peak = p.peak_static_torque(rated);
    let hold = |load: f64| {
        let mut m = Motor::new(p.clone(), at_24v());
        drive(&mut m, 0.6, rated, |_| (0.0, 0.0), ramped_load(load, 0.1, 0.2), None)
    };

    let idle = hold(0.0);
    println!("standstill at {rated} A: largest deflection {:.4} full step", idle.max_error);
    assert!(idle.max_error < 0.05, "holding with no load: {idle:?}");

    let held = hold(0.8 * peak);
    let expected = (0.8f64).asin() / std::f64::consts::FRAC_PI_2;
    println!(
        "load {:.3} N·m (0.8 × K_m·I = 0.8 × {peak:.3}): deflection {:.3} full step at the end, {:.3} at most \
         (ideal asin(0.8) = {expected:.3})",
        0.8 * peak,
        held.final_error(),
        held.max_error
    );
    assert!(held.max_error < 1.0, "deflection under 0.8 × holding torque: {held:?}");
    assert!(held.final_error() > 0.3, "a load opposing positive rotation pushes the rotor back: {held:?}");

    let slipped = hold(1.2 * peak);
    println!(
        "load {:.3} N·m (1.2 × K_m·I): rotor {:.1} full steps from the command",
        1.2 * peak,
        slipped.final_error()
    );
    assert!(slipped.final_error() > 4.0, "1.2 × holding torque must back-drive the motor: {slipped:?}");
}

#[test]
fn two_phases_at_rated_current_give_the_datasheet_holding_torque() {
    let p = nema17();
    // θe = 45° (half a full step) at amplitude √2·I: each phase at the rated current.
    let current = SQRT_2 * p.rated_current_a;
    let hold = |load: f64| {
        let mut m = Motor::new(p.clone(), at_24v());
        m.reset_at_full_steps(0.5);
        drive(&mut m, 0.6, current, |_| (0.5, 0.0), ramped_load(load, 0.1, 0.2), None)
    };
    let below = hold(0.9 * p.holding_torque_nm);
    let above = hold(1.1 * p.holding_torque_nm);
    println!(
        "two phases at {} A, datasheet holding torque {} N·m: 0.9× deflects {:.3} full step, 1.1× slips {:.1}",
        p.rated_current_a,
        p.holding_torque_nm,
        below.final_error(),
        above.final_error()
    );
    assert!(below.max_error < 1.0, "{below:?}");
    assert!(above.final_error() > 4.0, "{above:?}");
}

#[test]
fn gentle_ramp_to_5_rev_per_s_loses_no_step() {
    let p = nema17();
    let mut m = Motor::new(p.clone(), at_24v());
    let profile = Trapezoid::from_rev(5.0, 25.0, 5.0);
    let mut trace = Trace::new(4);
    let out = drive(&mut m, profile.duration() + 0.2, p.rated_current_a, |t| profile.at(t), no_load, Some(&mut trace));
    println!(
        "0 → 5 rev/s at 25 rev/s², 5 rev: commanded {} full steps, rotor {:.3}, final error {:.3}, largest {:.3}",
        out.commanded,
        out.rotor,
        out.final_error(),
        out.max_error
    );
    assert_eq!(out.commanded, 1000.0);
    assert!(out.final_error().abs() < 0.5, "lost steps on a gentle ramp: {out:?}");
    assert!(out.max_error < 1.0, "{out:?}");

    let csv = out_dir().join("motor_gentle_ramp.csv");
    let png = out_dir().join("motor_gentle_ramp.png");
    trace.save_csv(&csv).unwrap();
    assert_eq!(load_csv(&csv).unwrap().len(), trace.rows().len());
    plot_trace(trace.rows(), &png, "17HS19-2004S1 at 24 V: 0 → 5 rev/s at 25 rev/s², 5 rev").unwrap();
    let from_csv = out_dir().join("motor_gentle_ramp_from_csv.png");
    plot_trace_csv(&csv, &from_csv).unwrap();
    println!(
        "trace: {} ({} rows), plots: {}, {}",
        csv.display(),
        trace.rows().len(),
        png.display(),
        from_csv.display()
    );
}

#[test]
fn aggressive_acceleration_loses_steps() {
    let p = nema17();
    let run = |ramp_s: f64, trace: Option<&mut Trace>| {
        // 0 → 20 rev/s in `ramp_s`, 3 rev, then stop as hard.
        let profile = Trapezoid::from_rev(20.0, 20.0 / ramp_s, 3.0);
        let mut m = Motor::new(p.clone(), at_24v());
        drive(&mut m, profile.duration() + 0.1, p.rated_current_a, |t| profile.at(t), no_load, trace)
    };
    // In 5 ms (4000 rev/s²) the bare rotor needs J·α = 0.21 N·m, half of K_m·I: the model follows,
    // lagging more than a full step at the end of the ramp.
    let five = run(5e-3, None);
    // In 2 ms (10000 rev/s²) it needs J·α = 0.52 N·m, more than K_m·I = 0.42 N·m: it cannot.
    let mut trace = Trace::new(2);
    let two = run(2e-3, Some(&mut trace));
    println!(
        "0 → 20 rev/s, 3 rev, bare rotor: in 5 ms final error {:.2} full steps (largest lag {:.2}); \
         in 2 ms rotor {:.1} of {} full steps, lost {:.1}",
        five.final_error(),
        five.max_error,
        two.rotor,
        two.commanded,
        two.final_error()
    );
    let png = out_dir().join("motor_aggressive.png");
    plot_trace(trace.rows(), &png, "17HS19-2004S1 at 24 V: 0 → 20 rev/s in 2 ms").unwrap();
    println!("plot: {}", png.display());
    assert!(two.final_error().abs() >= 4.0, "the model must not be a follower: {two:?}");
}

#[test]
fn large_load_inertia_loses_steps_where_the_bare_motor_does_not() {
    let p = nema17();
    // 0 → 10 rev/s at 500 rev/s², 4 rev.
    let profile = Trapezoid::from_rev(10.0, 500.0, 4.0);
    let run = |load_inertia: f64| {
        let mut m = Motor::new(p.clone(), MotorInputs { load_inertia_kgm2: load_inertia, ..at_24v() });
        drive(&mut m, profile.duration() + 0.2, p.rated_current_a, |t| profile.at(t), no_load, None)
    };
    let bare = run(0.0);
    // 100 × the rotor's inertia: J·α = 8.3e-4 kg·m² × 3142 rad/s² = 2.6 N·m, far over K_m·I.
    let heavy = run(100.0 * p.rotor_inertia_kgm2);
    println!(
        "0 → 10 rev/s at 500 rev/s²: bare rotor error {:.3} full steps, with 100 × rotor inertia {:.1}",
        bare.final_error(),
        heavy.final_error()
    );
    assert!(bare.final_error().abs() < 0.5, "{bare:?}");
    assert!(heavy.final_error().abs() >= 4.0, "{heavy:?}");
}

/// True if the motor, with `load_inertia` kg·m² on its shaft, brought gently to `speed_rps`, then
/// loaded (ramped in over 0.1 s) with `load` N·m and run on for 0.15 s, stays within 2 full steps
/// of the command throughout.
fn carries(p: &MotorParams, load_inertia: f64, speed_rps: f64, load: f64) -> bool {
    let profile = Trapezoid::from_rev(speed_rps, 50.0, 1e6);
    let at_speed = speed_rps / 50.0 + 0.05;
    let mut m = Motor::new(p.clone(), MotorInputs { load_inertia_kgm2: load_inertia, ..at_24v() });
    let out =
        drive(&mut m, at_speed + 0.25, p.rated_current_a, |t| profile.at(t), ramped_load(load, at_speed, 0.1), None);
    out.max_error < 2.0
}

/// The largest load (N·m) the motor carries at constant speed, by bisection to 1/1024 of
/// 1.25 × K_m·I.
fn pull_out_torque(p: &MotorParams, load_inertia: f64, speed_rps: f64) -> f64 {
    let (mut lo, mut hi) = (0.0, 1.25 * p.peak_static_torque(p.rated_current_a));
    assert!(carries(p, load_inertia, speed_rps, lo), "no load at {speed_rps} rev/s");
    assert!(!carries(p, load_inertia, speed_rps, hi), "carries 1.25 × K_m·I at {speed_rps} rev/s");
    for _ in 0..10 {
        let mid = 0.5 * (lo + hi);
        if carries(p, load_inertia, speed_rps, mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    lo
}

/// Pull-out torque against speed, measured as datasheets do it: through a coupling with a load
/// inertia on the shaft (here 330 g·cm², the figure one maker's 42 mm datasheet states for its
/// curves), which keeps the rotor's natural frequency below the detent ripple at 1 rev/s. The bare
/// rotor's curve is printed too: there the detent torque (4 periods per electrical cycle, 200 Hz
/// at 1 rev/s) meets the lightly damped rotor's natural frequency (~250 Hz, lower under load) and
/// the low-speed pull-out torque dips, the low-speed resonance real steppers have.
#[test]
fn pull_out_torque_falls_with_speed() {
    let p = nema17();
    let dyno_inertia = 3.3e-5;
    println!(
        "pull-out torque, {} at 24 V, {} A (K_m·I = {:.3} N·m), N·m:",
        p.name,
        p.rated_current_a,
        p.peak_static_torque(p.rated_current_a)
    );
    println!("  speed (rev/s)   rpm   330 g·cm² load   bare rotor");
    let mut curve = Vec::new();
    for speed in [1.0, 2.0, 5.0, 10.0, 15.0, 20.0] {
        let loaded = pull_out_torque(&p, dyno_inertia, speed);
        let bare = pull_out_torque(&p, 0.0, speed);
        println!("  {speed:13.1} {:5.0} {loaded:16.3} {bare:12.3}", speed * 60.0);
        curve.push((speed, loaded));
    }
    let at = |s: f64| curve.iter().find(|c| c.0 == s).unwrap().1;
    assert!(at(1.0) > at(5.0) && at(5.0) > at(15.0), "{curve:?}");
    assert!(at(1.0) > 0.9 * p.peak_static_torque(p.rated_current_a), "{curve:?}");
    assert!(at(15.0) < 0.8 * at(1.0), "{curve:?}");
}

/// At speed the supply cannot push the commanded current through the winding against the
/// back-EMF and the reactance: the current vector's magnitude falls below its command.
#[test]
fn current_falls_behind_at_speed() {
    let p = nema17();
    let magnitude_at = |speed_rps: f64, png: Option<&str>| {
        let profile = Trapezoid::from_rev(speed_rps, 50.0, 1e6);
        let at_speed = speed_rps / 50.0 + 0.05;
        let mut m = Motor::new(p.clone(), at_24v());
        let mut trace = Trace::new(1);
        drive(&mut m, at_speed + 0.05, p.rated_current_a, |t| profile.at(t), no_load, Some(&mut trace));
        if let Some(name) = png {
            let path = out_dir().join(name);
            let title = format!("17HS19-2004S1 at 24 V, {} A: up to {speed_rps} rev/s at 50 rev/s²", p.rated_current_a);
            plot_trace(trace.rows(), &path, &title).unwrap();
            println!("plot: {}", path.display());
        }
        let cruise: Vec<f64> = trace.rows().iter().filter(|r| r.t_s > at_speed).map(|r| r.i_a.hypot(r.i_b)).collect();
        cruise.iter().sum::<f64>() / cruise.len() as f64
    };
    let slow = magnitude_at(2.0, None);
    let fast = magnitude_at(20.0, Some("motor_20rps.png"));
    println!("|i| at 24 V, {} A commanded: {slow:.3} A at 2 rev/s, {fast:.3} A at 20 rev/s", p.rated_current_a);
    assert!((slow - p.rated_current_a).abs() < 0.02, "{slow}");
    assert!(fast < 0.8 * p.rated_current_a, "{fast}");
}

#[test]
fn disabled_bridge_lets_the_currents_decay_and_leaves_only_detent() {
    let p = nema17();
    let mut m = Motor::new(p.clone(), at_24v());
    m.advance(&DriverCommand::at_microstep(0, USTEPS, p.rated_current_a), 0.05);
    assert!((m.phase_currents().0 - p.rated_current_a).abs() < 0.01);
    m.advance(&DriverCommand::DISABLED, 0.002);
    assert_eq!(m.phase_currents(), (0.0, 0.0));
    // Below detent + friction the unpowered rotor stays near its detent position ...
    m.set_inputs(MotorInputs { load_torque_nm: 0.5 * p.detent_nm, ..at_24v() });
    m.advance(&DriverCommand::DISABLED, 0.2);
    assert!(m.rotor_full_steps().abs() < 0.25, "{}", m.rotor_full_steps());
    // ... above it, the load turns it.
    m.set_inputs(MotorInputs { load_torque_nm: 3.0 * (p.detent_nm + p.static_friction_nm), ..at_24v() });
    m.advance(&DriverCommand::DISABLED, 0.2);
    assert!(m.rotor_full_steps() < -4.0, "{}", m.rotor_full_steps());
}

#[test]
fn nema23_follows_a_gentle_ramp() {
    let p = MotorCatalog::builtin().get("23HS30-3004S").expect("23HS30-3004S in motors.toml").clone();
    let mut m = Motor::new(p.clone(), at_24v());
    let profile = Trapezoid::from_rev(5.0, 25.0, 5.0);
    let out = drive(&mut m, profile.duration() + 0.2, p.rated_current_a, |t| profile.at(t), no_load, None);
    println!(
        "23HS30-3004S, 0 → 5 rev/s: final error {:.3}, largest {:.3} full steps",
        out.final_error(),
        out.max_error
    );
    assert!(out.final_error().abs() < 0.5, "{out:?}");
}

#[test]
fn runs_faster_than_real_time() {
    let p = nema17();
    let mut m = Motor::new(p.clone(), at_24v());
    let profile = Trapezoid::from_rev(10.0, 50.0, 100.0);
    let simulated = profile.duration();
    let start = Instant::now();
    let out = drive(&mut m, simulated, p.rated_current_a, |t| profile.at(t), no_load, None);
    let wall = start.elapsed().as_secs_f64();
    let factor = simulated / wall;
    println!(
        "real-time factor: {simulated:.2} s simulated in {wall:.3} s wall = {factor:.1} × real time \
         ({:.0} sub-steps/s of {:.1} µs; {} build)",
        simulated / m.substep_s() / wall,
        m.substep_s() * 1e6,
        if cfg!(debug_assertions) { "debug" } else { "release" }
    );
    assert!(out.final_error().abs() < 0.5, "{out:?}");
    if !cfg!(debug_assertions) {
        assert!(factor > 1.0, "the model must keep up with real time in a release build");
    }
}
