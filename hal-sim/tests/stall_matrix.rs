//! The stall detection matrix: speeds (low, middle, near the torque limit) × loads (none, 50 %,
//! 90 % of K_m·I, a blocked rotor), open loop (sensorless, 0x2107) and closed loop (following
//! error, 0x605C), on the NEMA 17 at 24 V, 1/16 microsteps, 1000 mA.
//!
//! Each case runs twice from the same start: once with detection off, which tells whether the
//! stall is real (the rotor falls more than two full steps behind the angle it is driven to) and
//! when it began (the lag passes one full step, the pull-out point); once with detection on, which
//! gives the detection time and the lag then. "Lost" is the lag at detection beyond the pull-out
//! point, in full steps. The drive sees only what a real drive measures (phase currents, bridge
//! voltages, encoder); the true rotor angle is used only here, to score it.
//!
//! Both power stages: the ideal chopper, and the G474's bridges, where the drive's current
//! loop reads the currents as its ADC does (noise, offsets) and its back-EMF estimate feeds the
//! sensorless detection.
//!
//! `cargo test -p hal-sim --test stall_matrix -- --nocapture` prints the tables.

use drive_core::od::Obj;
use drive_core::{Drive, DriveConfig, Params};
use hal_sim::DEFAULT_MOTOR;
use hal_sim::bridges::{PowerStage, SensingOptions};
use hal_sim::inject::Change;
use hal_sim::motor::{Motor, MotorCatalog, MotorInputs};
use hal_sim::plant::Plant;

/// K_m · 1 A, N·m: the torque the motor holds with at this current.
const KM_I: f64 = 0.2086;
/// Microsteps a full step.
const MICRO: f64 = 16.0;
/// Encoder counts a full step (1000 lines ×4 a turn of 200 full steps).
const COUNTS_PER_STEP: f64 = 20.0;

#[derive(Clone, Copy, Debug, PartialEq)]
enum Load {
    None,
    Share(f64),
    Blocked,
}

/// A plant in open (`closed` false, sensorless detection `detect`) or closed loop (position
/// loop; `detect` false sets the largest 0x605C).
fn plant(stage: PowerStage, closed: bool, detect: bool) -> Plant {
    let mut params = Params::factory();
    let settings: &[(Obj, u32)] = if closed {
        &[(Obj::Feedback, 1), (Obj::EncoderCpr, 1000), (Obj::StallLength, if detect { 24 } else { 255 })]
    } else {
        &[(Obj::StallDetect, u32::from(detect)), (Obj::StallStop, 1)]
    };
    for &(obj, v) in settings.iter().chain(&[(Obj::Microsteps, 16), (Obj::PhaseCurrent, 1000), (Obj::AccelLevel, 4)]) {
        assert!(params.set(obj, v), "{obj:?}");
    }
    let motor = MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().expect("catalogue motor");
    let inputs = MotorInputs { load_inertia_kgm2: 3.3e-5, ..MotorInputs::default() };
    let mut p = Plant::new(Drive::boot(DriveConfig::default(), &params, 0), Motor::new(motor, inputs));
    p.set_power_stage(stage, SensingOptions::default());
    p
}

fn set(plant: &mut Plant, obj: Obj, value: u32) {
    let state = plant.drive_mut().state_mut();
    assert_eq!(state.check(obj, value), Ok(()), "{obj:?} = {value}");
    state.apply(obj, value);
}

/// How far the rotor lags the angle it is driven to, full steps: the commutated angle in open
/// loop (what it would follow), the setpoint in closed loop.
fn lag(plant: &Plant, closed: bool) -> f64 {
    let Some(out) = plant.outputs() else { return 0.0 };
    let rotor = plant.motor().rotor_full_steps();
    if closed {
        out.setpoint.whole as f64 / COUNTS_PER_STEP - rotor
    } else {
        (out.commutation.whole as f64 + out.commutation.fraction.to_num::<f64>()) / MICRO - rotor
    }
}

fn stall_bit(plant: &Plant) -> bool {
    plant.drive().state().read(Obj::ControllerStatus) & (1 << 2) != 0
}

/// What one run saw after the load came on: the pull-out time, the largest lag, the detection
/// time and the lag at detection (times in ms after the load).
#[derive(Clone, Copy, Debug, Default)]
struct Run {
    pull_out_ms: Option<f64>,
    max_lag: f64,
    detected_ms: Option<f64>,
    lag_at_detection: f64,
}

/// Cruises at `speed` full steps a second, puts the load on, and watches 300 ms.
fn run(stage: PowerStage, closed: bool, detect: bool, speed: f64, load: Load) -> Run {
    let mut p = plant(stage, closed, detect);
    let per_step = if closed { COUNTS_PER_STEP } else { MICRO };
    set(&mut p, Obj::MaxSpeed, (speed * per_step) as u32);
    set(&mut p, Obj::RelativeMove, 1_000_000);
    // Level 4 (21 510 pps²): at most 1.2 s to the top speed; then 0.3 s of cruise.
    let cruise_at = p.next_tick().plus_micros(1_500_000);
    p.advance_to(cruise_at);
    assert!(!stall_bit(&p), "stall before the load at {speed} full steps/s, closed {closed}");
    match load {
        Load::None => {}
        Load::Share(s) => p.inject(Change::LoadTorque(s * KM_I)),
        Load::Blocked => p.inject(Change::Blocked(true)),
    }
    let start = p.next_tick();
    let mut r = Run::default();
    while p.next_tick().since(start) < 300_000 {
        p.advance_to(p.next_tick());
        let ms = p.next_tick().since(start) as f64 * 1e-3;
        let l = lag(&p, closed);
        r.max_lag = r.max_lag.max(l);
        if l > 1.0 && r.pull_out_ms.is_none() {
            r.pull_out_ms = Some(ms);
        }
        if stall_bit(&p) && r.detected_ms.is_none() {
            r.detected_ms = Some(ms);
            r.lag_at_detection = l;
        }
    }
    r
}

#[test]
fn every_real_stall_is_caught_within_two_full_steps_and_nothing_else_is() {
    matrix(PowerStage::Chopper);
}

#[test]
fn through_the_bridges_every_real_stall_is_caught_within_two_full_steps_and_nothing_else_is() {
    matrix(PowerStage::Bridges);
}

fn matrix(stage: PowerStage) {
    let speeds = [("low", 150.0), ("middle", 600.0), ("near limit", 1400.0)];
    let loads = [Load::None, Load::Share(0.5), Load::Share(0.9), Load::Blocked];
    let mut failures = Vec::new();
    let mut table =
        format!("{stage:?}\nloop   | speed fs/s | load    | real | pull-out ms | detected ms | lost full steps\n");
    for closed in [false, true] {
        for (name, speed) in speeds {
            for load in loads {
                let truth = run(stage, closed, false, speed, load);
                let seen = run(stage, closed, true, speed, load);
                let real = truth.max_lag > 2.0;
                let lost = (seen.lag_at_detection - 1.0).max(0.0);
                let fmt = |t: Option<f64>| t.map_or("-".to_string(), |t| format!("{t:.2}"));
                table.push_str(&format!(
                    "{:6} | {name:10} {speed:5} | {:7} | {real:5} | {:>11} | {:>11} | {}\n",
                    if closed { "closed" } else { "open" },
                    match load {
                        Load::None => "none".to_string(),
                        Load::Share(s) => format!("{:.0} %", s * 100.0),
                        Load::Blocked => "blocked".to_string(),
                    },
                    fmt(truth.pull_out_ms),
                    fmt(seen.detected_ms),
                    if seen.detected_ms.is_some() { format!("{lost:.2}") } else { "-".to_string() },
                ));
                let case = format!("{} {name} {load:?}", if closed { "closed" } else { "open" });
                match (real, seen.detected_ms) {
                    (true, None) => failures.push(format!("{case}: missed")),
                    (true, Some(_)) if lost > 2.0 => failures.push(format!("{case}: {lost:.2} full steps lost")),
                    (false, Some(_)) => failures.push(format!("{case}: false alarm")),
                    _ => {}
                }
            }
        }
    }
    eprintln!("{table}");
    assert!(failures.is_empty(), "{failures:#?}");
}

/// Normal moves of the profile suite's kinds (short and long, slow and fast, every ramp
/// level's extremes, a re-target that reverses, velocity mode) with detection on: no stall bit,
/// and every move ends where it should.
#[test]
fn normal_moves_raise_no_stall() {
    normal_moves(PowerStage::Chopper);
}

#[test]
fn through_the_bridges_normal_moves_raise_no_stall() {
    normal_moves(PowerStage::Bridges);
}

fn normal_moves(stage: PowerStage) {
    for closed in [false, true] {
        let per_step = if closed { COUNTS_PER_STEP } else { MICRO };
        let mut p = plant(stage, closed, true);
        let mut target = 0i64;
        for (speed, level, distance) in
            [(100.0, 8, 40.0), (400.0, 1, 1000.0), (1000.0, 4, -3000.0), (2000.0, 1, 4000.0), (1400.0, 8, -200.0)]
        {
            set(&mut p, Obj::AccelLevel, level);
            set(&mut p, Obj::DecelLevel, level);
            set(&mut p, Obj::MaxSpeed, (speed * per_step) as u32);
            target += (distance * per_step) as i64;
            set(&mut p, Obj::AbsoluteMove, target as i32 as u32);
            p.advance_to(p.next_tick().plus_micros(5_000_000));
            assert!(!stall_bit(&p), "closed {closed}: stall on the move to {target}");
            let st = p.drive().state();
            assert_eq!(
                st.position(),
                target,
                "closed {closed}: status {:#x} faults {:#x} err {:#x} lag {}",
                st.read(Obj::ControllerStatus),
                st.read(Obj::DriveFaults),
                st.read(Obj::ErrorStatus),
                lag(&p, closed)
            );
            assert!((lag(&p, closed)).abs() < 0.3, "closed {closed}: rotor off target");
        }
        // A re-target that reverses while cruising fast.
        set(&mut p, Obj::MaxSpeed, (1500.0 * per_step) as u32);
        set(&mut p, Obj::AbsoluteMove, (target + (3000.0 * per_step) as i64) as i32 as u32);
        p.advance_to(p.next_tick().plus_micros(1_000_000));
        set(&mut p, Obj::AbsoluteMove, target as i32 as u32);
        p.advance_to(p.next_tick().plus_micros(5_000_000));
        assert!(!stall_bit(&p), "closed {closed}: stall on the reversal");
        // Velocity mode up, and stopped by speed 0 while still accelerating.
        set(&mut p, Obj::Mode, 1);
        set(&mut p, Obj::MaxSpeed, (-800.0 * per_step) as i32 as u32);
        p.advance_to(p.next_tick().plus_micros(2_000_000));
        set(&mut p, Obj::MaxSpeed, 0);
        p.advance_to(p.next_tick().plus_micros(2_000_000));
        assert!(!stall_bit(&p), "closed {closed}: stall in velocity mode");
        assert_eq!(p.drive().state().read(Obj::DriveFaults), 0);
    }
}
