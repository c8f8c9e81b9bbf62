//! The current's amplitude against its reference at speed, through the G474's bridges (issue
//! 39's acceptance: within 5 % up to the speed where the supply runs out).
//!
//! Each point runs the unloaded motor as the torque-speed sweep does ([`spin_up`]: factory
//! drive, 1/32 microsteps, the rated current, velocity mode at level 1), lets it settle at speed
//! for [`SETTLE_S`] and then, every PWM period for [`MEASURE_S`], compares the length of the
//! motor's current vector (its windings' true currents, not the ADC's reading) with the length of
//! the reference the loop regulates to.
//!
//! The supply **runs out** ([`supply_out_rps`]) where the voltage the rated current needs in the
//! unloaded motor reaches what the bridges give a winding, [`MAX_MODULATION`] of the bus:
//! unloaded, the rotor's teeth line up with the current, so the back-EMF K_m·ω is in phase with
//! the inductance's ωe·L·I and the winding needs √((R·I)² + (ωe·L·I + K_m·ω)²), ω the shaft's
//! speed and ωe = N·ω its electrical one. Each point also counts the periods the loop asked a
//! winding 99 % of that limit or more: a motor that rings at low speed (the rotor's natural
//! frequency near 200 full steps a second) touches it below that speed.

use drive_core::current::MAX_MODULATION;

use crate::bridges::PowerStage;
use crate::motor::MotorParams;
use crate::torque_speed::{SETTLE_S, Setup, TICKS_PER_S, spin_up};

/// The time measured at speed, s.
pub const MEASURE_S: f64 = 0.2;
/// The speeds swept, rev/s.
pub const SPEEDS_RPS: [f64; 20] =
    [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0, 11.0, 12.0, 13.0, 14.0, 15.0, 16.0, 17.0, 18.0, 19.0, 20.0];
/// The share of a period's voltage limit at which a winding counts as driven at the supply's
/// limit.
const AT_LIMIT: f64 = 0.99;

/// The current's tracking at one speed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    /// The speed, rev/s.
    pub speed_rps: f64,
    /// Whether the motor kept in step to the end (the sweep stops where it does not).
    pub in_step: bool,
    /// The current vector's length over the reference's, mean over the periods measured.
    pub mean: f64,
    /// The share of periods more than 5 % off.
    pub off: f64,
    /// The period furthest off: its ratio.
    pub worst: f64,
    /// The share of periods the loop asked a winding 99 % of its limit or more.
    pub saturated: f64,
}

impl Point {
    /// Whether the current tracks: the mean within 1 %, at most one period in a thousand more
    /// than 5 % off (the ADC's noise moves single periods), none more than 6 %.
    pub fn tracks(&self) -> bool {
        (self.mean - 1.0).abs() <= 0.01 && self.off <= 0.001 && (self.worst - 1.0).abs() <= 0.06
    }
}

/// The speed at which `motor`'s rated current at `supply_v` runs out of voltage, rev/s (see the
/// module documentation).
///
/// ```
/// use hal_sim::motor::MotorCatalog;
/// let nema23 = MotorCatalog::builtin().get("23HS30-3004S").cloned().unwrap();
/// // 3.39 V across R, and 7.32 V more every turn a second: 10.8 V at 1.40 rev/s.
/// let v = hal_sim::tracking::supply_out_rps(&nema23, 12.0);
/// assert!((v - 1.40).abs() < 0.01, "{v}");
/// ```
pub fn supply_out_rps(motor: &MotorParams, supply_v: f64) -> f64 {
    let i = motor.rated_current_a;
    let limit = f64::from(MAX_MODULATION) * supply_v;
    let teeth = f64::from(motor.steps_per_rev) / 4.0;
    let per_rps = std::f64::consts::TAU * (teeth * motor.l_henry * i + motor.km_nm_per_a);
    (limit * limit - (motor.r_ohm * i).powi(2)).max(0.0).sqrt() / per_rps
}

/// Measures the current's tracking for `motor` at `supply_v` through the bridges at
/// `speed_rps`, as the module documentation describes.
///
/// # Panics
/// If the drive refuses a setting, or its setpoint does not reach the speed.
pub fn point(motor: &MotorParams, supply_v: f64, speed_rps: f64) -> Point {
    let setup = Setup { motor: motor.clone(), supply_v, stage: PowerStage::Bridges };
    let mut run = spin_up(&setup, speed_rps);
    for _ in 0..(SETTLE_S * TICKS_PER_S).round() as u32 {
        run.tick();
    }
    let limit = AT_LIMIT * f64::from(MAX_MODULATION) * supply_v;
    let (mut sum, mut n, mut off, mut worst, mut saturated) = (0.0, 0u32, 0u32, 1.0f64, 0u32);
    for _ in 0..(MEASURE_S * TICKS_PER_S).round() as u32 {
        if !run.tick() {
            break;
        }
        let Some(bridges) = run.plant.bridges() else { break };
        let [ra, rb] = bridges.reference();
        let wanted = ra.hypot(rb);
        if wanted <= 0.0 {
            continue;
        }
        let (a, b) = run.plant.motor().phase_currents();
        let ratio = a.hypot(b) / wanted;
        sum += ratio;
        n += 1;
        off += u32::from((ratio - 1.0).abs() > 0.05);
        worst = if (ratio - 1.0).abs() > (worst - 1.0).abs() { ratio } else { worst };
        let at_limit = bridges.asked_volts().is_some_and(|v| v.iter().any(|v| v.abs() >= limit));
        saturated += u32::from(at_limit);
    }
    let periods = f64::from(n.max(1));
    Point {
        speed_rps,
        in_step: run.carried,
        mean: sum / periods,
        off: f64::from(off) / periods,
        worst,
        saturated: f64::from(saturated) / periods,
    }
}

/// A motor's tracking at a supply, from the lowest speed to where the motor falls out of step.
#[derive(Clone, Debug)]
pub struct Sweep {
    /// The motor's name.
    pub motor: String,
    /// The supply, V.
    pub supply_v: f64,
    /// The speed where the supply runs out ([`supply_out_rps`]), rev/s.
    pub supply_out_rps: f64,
    /// The points, in speed order; the last is the first out of step if the motor fell out.
    pub points: Vec<Point>,
}

impl Sweep {
    /// The points below the speed where the supply runs out ([`supply_out_rps`]), in step:
    /// where the current must track.
    pub fn within_supply(&self) -> impl Iterator<Item = &Point> {
        self.points.iter().filter(move |p| p.in_step && p.speed_rps < self.supply_out_rps)
    }
}

/// Sweeps [`SPEEDS_RPS`] for `motor` at `supply_v`.
pub fn sweep(motor: &MotorParams, supply_v: f64) -> Sweep {
    let mut points = Vec::new();
    for &speed in &SPEEDS_RPS {
        let p = point(motor, supply_v, speed);
        points.push(p);
        if !p.in_step {
            break;
        }
    }
    Sweep { motor: motor.name.clone(), supply_v, supply_out_rps: supply_out_rps(motor, supply_v), points }
}

/// Each motor at each supply, a thread each.
pub fn sweeps(motors: &[MotorParams], supplies_v: &[f64]) -> Vec<Sweep> {
    let jobs: Vec<(&MotorParams, f64)> = motors.iter().flat_map(|m| supplies_v.iter().map(move |&v| (m, v))).collect();
    std::thread::scope(|s| {
        let handles: Vec<_> = jobs.iter().map(|&(m, v)| s.spawn(move || sweep(m, v))).collect();
        handles.into_iter().map(|h| h.join().expect("a sweep thread panicked")).collect()
    })
}
