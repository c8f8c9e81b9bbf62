//! Pull-out torque against speed (issue 39's acceptance: the G474's bridges within 10 % of the
//! ideal chopper), measured on the simulated motor as a dynamometer measures it.
//!
//! **Pull-out torque** at a speed is the largest constant load the motor carries while it runs
//! at that speed in open loop. The drive (factory settings, 1/32 microsteps, the phase current
//! 0x600D at the motor's rated current) accelerates the unloaded motor in velocity mode at
//! acceleration level 1 (77 440 microsteps/s², 12.1 rev/s²: 20 rev/s in 1.65 s), lets it settle
//! at speed for [`SETTLE_S`], ramps the load from 0 over [`RAMP_S`] and holds it for [`HOLD_S`].
//! Loaded only at speed, the curve is what the motor carries at constant speed, not what it can
//! accelerate; the ramp is slow beside the rotor's natural oscillation (about 200-250 Hz at rated
//! current), so that the load does not ring the rotor as a step would. At 0 rev/s it is the
//! holding torque: the largest load, ramped in the same way, that moves the standing rotor less
//! than a full step (the peak of the static torque curve is a full step from the commanded
//! position). A motor that does not reach a speed unloaded has a pull-out torque of 0 there.
//!
//! The largest load is found by bisection ([`pull_out`]) to 1 % of itself or 0.1 % of the
//! holding torque K_m·I, whichever is larger.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Mutex, PoisonError};

use drive_core::od::Obj;

use crate::bridges::{PowerStage, SensingOptions};
use crate::inject::Change;
use crate::motor::{Motor, MotorInputs, MotorParams};
use crate::plant::Plant;

/// The speeds of the curve, rev/s.
pub const SPEEDS_RPS: [f64; 12] = [0.0, 1.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0, 16.0, 18.0, 20.0];
/// The supplies of the curves, V.
pub const SUPPLIES_V: [f64; 3] = [12.0, 24.0, 48.0];
/// Microsteps a full step (0x600C).
pub const MICROSTEPS: u16 = 32;
/// Time at speed before the load comes, s.
pub const SETTLE_S: f64 = 0.1;
/// Time the load ramps from 0 to its value over, s.
pub const RAMP_S: f64 = 0.1;
/// Time the full load is held, s.
pub const HOLD_S: f64 = 0.3;
/// The rotor's lag behind the setpoint, full steps, beyond which a turning motor has lost
/// synchronism.
///
/// In synchronism the lag is the load angle (at most a full step, where the torque peaks) plus
/// the currents' lag behind their reference (at speed the supply runs short and the winding's
/// inductance delays the current by up to a quarter of an electrical turn, another full step:
/// near pull-out lags up to 2.5 full steps are carried at speed). A lost step slips a whole
/// electrical turn, 4 full steps, and under a constant load the rotor goes on slipping: 3 full
/// steps lies between the two.
pub const SLIP_FULL_STEPS: f64 = 3.0;
/// The standing rotor's displacement, full steps, that a load beyond the holding torque makes.
pub const HOLD_FULL_STEPS: f64 = 1.0;
/// The bisection's upper bound over the holding torque K_m·I: above the static torque curve's
/// peak with the bearings' friction and the detent added.
const UPPER: f64 = 1.25;
/// The bisection stops within this share of the load found...
const RELATIVE_TOLERANCE: f64 = 0.01;
/// ... or of the holding torque, whichever is larger.
const ABSOLUTE_TOLERANCE: f64 = 0.001;
/// The control ticks a second.
pub const TICKS_PER_S: f64 = 20_000.0;

/// What a curve is measured on: the catalogue's motor, a supply and a power stage.
#[derive(Clone, Debug)]
pub struct Setup {
    /// The motor.
    pub motor: MotorParams,
    /// The supply, V.
    pub supply_v: f64,
    /// The power stage.
    pub stage: PowerStage,
}

impl Setup {
    /// The phase current the drive is set to, mA: the motor's rated current.
    pub fn current_ma(&self) -> u16 {
        (self.motor.rated_current_a * 1e3).round().clamp(0.0, f64::from(u16::MAX)) as u16
    }

    /// The holding torque of the drive's current, N·m: K_m·I.
    pub fn holding_nm(&self) -> f64 {
        self.motor.peak_static_torque(f64::from(self.current_ma()) * 1e-3)
    }
}

/// Each motor at each supply through the chopper and through the bridges.
pub fn setups(motors: &[MotorParams], supplies_v: &[f64]) -> Vec<Setup> {
    let mut all = Vec::new();
    for motor in motors {
        for &supply_v in supplies_v {
            for stage in [PowerStage::Chopper, PowerStage::Bridges] {
                all.push(Setup { motor: motor.clone(), supply_v, stage });
            }
        }
    }
    all
}

/// One run under one load.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trial {
    /// Whether the motor carried the load: the rotor's lag stayed within the limit and the
    /// drive kept its bridges on.
    pub carried: bool,
    /// The largest lag of the rotor behind the setpoint, microsteps (until the run failed).
    pub worst_lag: f64,
    /// The drive's alarm code (0x2134) at the end: 0, or the fault that turned its bridges off.
    pub alarm: u32,
}

/// Writes `value` to the register `reg` through a Modbus request (function 0x06).
///
/// # Panics
/// If the drive refuses it.
fn write(plant: &mut Plant, reg: u16, value: u16) {
    let [rh, rl] = reg.to_be_bytes();
    let [vh, vl] = value.to_be_bytes();
    let reply = plant.request(&[0x01, 0x06, rh, rl, vh, vl]);
    assert!(reply.as_ref().is_some_and(|r| r.get(1) == Some(&0x06)), "{reg:04X} = {value}: {reply:02X?}");
}

/// Runs one control tick, the drive's timer served as a board's bus task does; whether the
/// rotor's lag is within `limit` microsteps and the bridges are on, the worst lag kept.
fn tick(plant: &mut Plant, limit: f64, worst: &mut f64) -> bool {
    let t = plant.next_tick();
    plant.advance_to(t);
    plant.drive_mut().on_timer(t);
    let Some(out) = plant.outputs() else { return true };
    let lag = out.setpoint.whole as f64 + out.setpoint.fraction.to_num::<f64>() - plant.rotor_microsteps();
    *worst = worst.max(lag.abs());
    out.enabled && lag.abs() < limit
}

/// A drive on `setup`'s motor run up to a speed, unloaded.
pub struct SpunUp {
    /// The drive and its motor, at speed (or where the run-up failed).
    pub plant: Plant,
    /// Whether the rotor kept within [`SLIP_FULL_STEPS`] of the setpoint and the drive kept its
    /// bridges on ([`HOLD_FULL_STEPS`] standing).
    pub carried: bool,
    /// The largest lag of the rotor behind the setpoint so far, microsteps.
    pub worst_lag: f64,
    /// The lag beyond which the motor has lost synchronism, microsteps.
    pub limit: f64,
}

impl SpunUp {
    /// Runs one control tick, the drive's timer served as a board's bus task does: whether the
    /// motor still carries its load.
    pub fn tick(&mut self) -> bool {
        self.carried = self.carried && tick(&mut self.plant, self.limit, &mut self.worst_lag);
        self.carried
    }
}

/// A factory drive on `setup`'s motor and supply, set as the module documentation describes,
/// its setpoint run up to `speed_rps` in velocity mode, unloaded (standing for 0).
///
/// # Panics
/// If the drive refuses a setting, or its setpoint does not reach the speed.
pub fn spin_up(setup: &Setup, speed_rps: f64) -> SpunUp {
    let inputs = MotorInputs { supply_v: setup.supply_v, ..MotorInputs::default() };
    let mut plant = Plant::new(drive_core::Drive::factory(), Motor::new(setup.motor.clone(), inputs));
    plant.set_power_stage(setup.stage, SensingOptions::default());
    for (reg, value) in [(0x600C, MICROSTEPS), (0x600D, setup.current_ma()), (0x600A, 1), (0x600B, 1)] {
        write(&mut plant, reg, value);
    }
    let per_rev = f64::from(setup.motor.steps_per_rev) * f64::from(MICROSTEPS);
    let pps = (speed_rps * per_rev).round() as i32;
    let limit = f64::from(MICROSTEPS) * if pps == 0 { HOLD_FULL_STEPS } else { SLIP_FULL_STEPS };
    let mut run = SpunUp { plant, carried: true, worst_lag: 0.0, limit };
    if pps != 0 {
        // Velocity mode: the speed's sign is the direction (0x6003 high word, 0x6004 low).
        write(&mut run.plant, 0x6007, 1);
        let [h0, h1, l0, l1] = pps.to_be_bytes();
        write(&mut run.plant, 0x6003, u16::from_be_bytes([h0, h1]));
        write(&mut run.plant, 0x6004, u16::from_be_bytes([l0, l1]));
        let ramp_s = f64::from(pps) / f64::from(drive_core::control::LEVELS[0]);
        let mut at_speed = false;
        for _ in 0..((ramp_s + 0.5) * TICKS_PER_S) as u32 {
            let carried = run.tick();
            at_speed =
                run.plant.outputs().is_some_and(|o| (f64::from(o.setpoint.velocity) - f64::from(pps)).abs() < 1.0);
            if !carried || at_speed {
                break;
            }
        }
        assert!(!run.carried || at_speed, "{}: the setpoint did not reach {pps} pps", setup.motor.name);
    }
    run
}

/// Runs `setup` at `speed_rps` under `load_nm` as the module documentation describes.
///
/// # Panics
/// If the drive refuses a setting, or its setpoint does not reach the speed.
pub fn trial(setup: &Setup, speed_rps: f64, load_nm: f64) -> Trial {
    let mut run = spin_up(setup, speed_rps);
    for (secs, from, to) in [(SETTLE_S, 0.0, 0.0), (RAMP_S, 0.0, load_nm), (HOLD_S, load_nm, load_nm)] {
        let ticks = (secs * TICKS_PER_S).round() as u32;
        for k in 1..=ticks {
            if !run.carried {
                break;
            }
            run.plant.inject(Change::LoadTorque(from + (to - from) * f64::from(k) / f64::from(ticks)));
            run.tick();
        }
    }
    Trial { carried: run.carried, worst_lag: run.worst_lag, alarm: run.plant.drive().state().read(Obj::AlarmCode) }
}

/// A point of a curve.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    /// The speed, rev/s.
    pub speed_rps: f64,
    /// The pull-out torque, N·m.
    pub torque_nm: f64,
    /// The drive's alarm code after the lightest load it did not carry: 0 when the motor lost
    /// synchronism, else the fault that stopped it first.
    pub alarm: u32,
}

/// The pull-out torque of `setup` at `speed_rps`: the largest load [`trial`] finds carried, by
/// bisection between 0 and 1.25 times the holding torque.
pub fn pull_out(setup: &Setup, speed_rps: f64) -> Point {
    let unloaded = trial(setup, speed_rps, 0.0);
    if !unloaded.carried {
        return Point { speed_rps, torque_nm: 0.0, alarm: unloaded.alarm };
    }
    let holding = setup.holding_nm();
    let (mut lo, mut hi) = (0.0, UPPER * holding);
    let mut alarm = trial(setup, speed_rps, hi).alarm;
    while hi - lo > (RELATIVE_TOLERANCE * lo).max(ABSOLUTE_TOLERANCE * holding) {
        let mid = 0.5 * (lo + hi);
        let t = trial(setup, speed_rps, mid);
        if t.carried {
            lo = mid;
        } else {
            (hi, alarm) = (mid, t.alarm);
        }
    }
    Point { speed_rps, torque_nm: lo, alarm }
}

/// A measured curve.
#[derive(Clone, Debug)]
pub struct Curve {
    /// What it was measured on.
    pub setup: Setup,
    /// Its points, in the order of the speeds asked.
    pub points: Vec<Point>,
}

/// The curves of `setups` at `speeds` (rev/s), the points shared out over the machine's cores.
pub fn measure(setups: &[Setup], speeds: &[f64]) -> Vec<Curve> {
    let jobs: Vec<(usize, f64)> = (0..setups.len()).flat_map(|k| speeds.iter().map(move |&v| (k, v))).collect();
    let next = AtomicUsize::new(0);
    let done = Mutex::new(Vec::with_capacity(jobs.len()));
    let threads = std::thread::available_parallelism().map_or(1, usize::from).min(jobs.len());
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| {
                loop {
                    let job = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&(k, v)) = jobs.get(job) else { break };
                    let point = pull_out(&setups[k], v);
                    done.lock().unwrap_or_else(PoisonError::into_inner).push((job, point));
                }
            });
        }
    });
    let mut done = done.into_inner().unwrap_or_else(PoisonError::into_inner);
    done.sort_by_key(|d| d.0);
    let mut curves: Vec<Curve> = setups.iter().map(|s| Curve { setup: s.clone(), points: Vec::new() }).collect();
    for (job, point) in done {
        curves[jobs[job].0].points.push(point);
    }
    curves
}

/// A speed of a motor at a supply, through both stages.
#[derive(Clone, Debug)]
pub struct Comparison {
    /// The motor's name.
    pub motor: String,
    /// The supply, V.
    pub supply_v: f64,
    /// The chopper's point.
    pub chopper: Point,
    /// The bridges' point.
    pub bridges: Point,
}

impl Comparison {
    /// The bridges' pull-out torque over the chopper's (1 where both are 0, infinite where only
    /// the chopper's is).
    pub fn ratio(&self) -> f64 {
        let (c, b) = (self.chopper.torque_nm, self.bridges.torque_nm);
        if c == 0.0 && b == 0.0 { 1.0 } else { b / c }
    }
}

/// The chopper's points against the bridges' of the same motor, supply and speed (a curve
/// measured through one stage only is left out).
pub fn compare(curves: &[Curve]) -> Vec<Comparison> {
    let mut rows = Vec::new();
    for chopper in curves.iter().filter(|c| c.setup.stage == PowerStage::Chopper) {
        let same = |c: &&Curve| {
            c.setup.stage == PowerStage::Bridges
                && c.setup.motor.name == chopper.setup.motor.name
                && c.setup.supply_v == chopper.setup.supply_v
        };
        let Some(bridges) = curves.iter().find(same) else { continue };
        for (&c, &b) in chopper.points.iter().zip(&bridges.points) {
            rows.push(Comparison {
                motor: chopper.setup.motor.name.clone(),
                supply_v: chopper.setup.supply_v,
                chopper: c,
                bridges: b,
            });
        }
    }
    rows
}

/// The header of [`csv_row`]'s table.
pub const CSV_HEADER: &str = "motor,supply_v,speed_rps,chopper_nm,bridges_nm,ratio,chopper_alarm,bridges_alarm";

/// A row of the comparisons' table.
pub fn csv_row(c: &Comparison) -> String {
    format!(
        "{},{},{},{:.4},{:.4},{:.3},{},{}",
        c.motor,
        c.supply_v,
        c.chopper.speed_rps,
        c.chopper.torque_nm,
        c.bridges.torque_nm,
        c.ratio(),
        c.chopper.alarm,
        c.bridges.alarm
    )
}
