//! The closed loop (seed 000 §5.8) and stall detection (§5.5.20-21, §5.8.7): what the drive does
//! with the encoder and the phase measurements of `faults::Inputs` at each tick.
//!
//! **Feedback** is our object 0x2104, read at power-up (as 0x6054: "restart after a change"):
//! 0 open loop; 1 closed loop with the encoder 0x6054 names (a CPR: incremental, counted ×4;
//! 12: absolute 12-bit single-turn); 2 closed loop with a 12-bit multi-turn absolute encoder.
//! In closed loop every position, speed and acceleration object counts encoder counts
//! (§5.5.5: 4 × CPR a turn, 4096 for the absolute encoder), 0x6089 is the encoder position,
//! 0x600E = 0x6089 + 0x6087 (the zero offset; writing 0x600E sets 0x6087), 0x607F the measured
//! speed. With an incremental encoder and 0x605E on, power-up takes 0x6055 as the position.
//!
//! **Commutation.** The drive drives the phases at an electrical angle, expressed in microsteps
//! of 0x600C (`Outputs::commutation`); four full steps are one
//! electrical turn (200 full steps a turn: a 1.8° motor). The encoder's electrical zero is the
//! rotor's position at the first reading after power-up: the drive has not moved it and holds it
//! at the angle of the setpoint, as an open-loop stepper does (a board whose rotor may sit off
//! that angle runs an alignment at power-up; the simulated rotor starts on it).
//! - Position loop (0x605D = 0, PID not used, §5.8.8): the phases follow the setpoint, except that
//!   they never lead the measured rotor by more than one full step (90° electrical, where the
//!   torque is largest): under a load beyond the open-loop pull-out torque the motor pushes with
//!   its full torque instead of slipping, and catches up with the setpoint when it can. No step
//!   is lost; a following error remains while the load holds the rotor back.
//! - Servo loop (0x605D = 1): the phases lead the measured rotor by exactly one full step, forward
//!   or back, with a current of `|u| × 0x600D` where u, clamped to ±1, is a PID on the following
//!   error e in full steps: u = KP/16 · e + KI·5 · ∫e dt + KD/4 · ė (ė in full steps per ms),
//!   with ė low-passed over 0x605A ticks (the prefilter) and the integral stopped while u is
//!   saturated in its direction (anti-windup). At the defaults (8, 4, 8) a following error of two
//!   full steps asks for the full current.
//!
//! **Stall.** Controller status bit 2 (write 1 to clear; while it is set, moves are refused).
//! - Closed loop: a following error beyond 0x605C microsteps (of 0x600C) latches the position
//!   error fault (0x2135 bit 2, alarm 25): the power stage goes off. A lost encoder (a reading of
//!   `None`) latches 0x2135 bit 3 (alarm 27).
//! - Open loop, sensorless (our 0x2107 = 1): from the phase currents and the bridge voltages the
//!   drive estimates the back-EMF, e = v − R·i − L·di/dt (R, L: our 0x2108, 0x2109), whose angle
//!   is the rotor's electrical angle plus 90°. The load angle δ between the current vector and
//!   the rotor is atan2(e·i, −e×i) in the direction of motion: a hybrid stepper pulls out at 90°.
//!   Both are averaged over about one full step of travel (a stepper rings inside each step at
//!   low speed). The first 30 ms at or above our 0x210A full steps a second learn the back-EMF a
//!   freely running motor gives per speed (below that speed the back-EMF is too small to tell, as
//!   §5.5.21 warns; a rotor still ringing from a dead stop needs that long to calm down). Then a
//!   stall is, for four ticks in a row, a back-EMF below half the learned one (the rotor held or
//!   slipping) that has lasted 2 ms or half a full step of travel more than it has not (a ring
//!   after a step in acceleration dips below it for a moment), or a |δ| beyond 110° − 4° × the
//!   signed threshold of 0x6039 bits 0-6 (clamped to 45°..175°: a positive threshold is more
//!   sensitive).
//!   With 0x6043 = 1 the axis then stops at once.

use crate::units::{Instant, TICK_MICROS};

/// Full steps in one turn of the motor (a 1.8° hybrid stepper).
pub const STEPS_PER_REV: i64 = 200;
/// Ticks in a row a stall condition must hold.
pub const STALL_TICKS: u8 = 4;
/// How long the commanded speed must have been above the minimum before detection starts, µs.
pub const STALL_SETTLE_MICROS: u64 = 30_000;
/// The control tick in seconds.
const TICK_S: f32 = TICK_MICROS as f32 * 1e-6;

/// The feedback the drive runs with: fixed at power-up from 0x2104 and 0x6054.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Feedback {
    /// Open loop: positions in microsteps, the encoder (if any) only shown in 0x6089.
    Open,
    /// Closed loop on an encoder.
    Closed(Encoder),
}

/// An encoder and how its readings count.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Encoder {
    /// Incremental: `counts` ×4 counts per turn, a counter wrapping at 2^32.
    Incremental {
        /// Counts per turn (4 × lines).
        counts: u32,
    },
    /// Absolute 12-bit single-turn: the angle, wrapping at 4096.
    SingleTurn,
    /// Absolute 12-bit multi-turn: turns × 4096 + angle, wrapping at 2^32.
    MultiTurn,
}

impl Encoder {
    /// Counts in one turn.
    pub const fn counts_per_rev(self) -> u32 {
        match self {
            Encoder::Incremental { counts } => counts,
            Encoder::SingleTurn | Encoder::MultiTurn => 4096,
        }
    }

    /// Counts moved from the reading `last` to `now` (shortest way round the reading's wrap).
    fn delta(self, last: u32, now: u32) -> i64 {
        match self {
            Encoder::SingleTurn => i64::from(((now.wrapping_sub(last) << 20) as i32) >> 20),
            _ => i64::from(now.wrapping_sub(last) as i32),
        }
    }

    /// The encoder position of a first reading: counts since power-up for an incremental
    /// encoder, the reading itself for an absolute one.
    fn first(self, raw: u32) -> i64 {
        match self {
            Encoder::Incremental { .. } => 0,
            Encoder::SingleTurn => i64::from(raw & 0xFFF),
            Encoder::MultiTurn => i64::from(raw as i32),
        }
    }
}

impl Feedback {
    /// The feedback of 0x2104 = `kind` with 0x6054 = `cpr` (12: the absolute encoder).
    pub const fn from_objects(kind: u32, cpr: u32) -> Self {
        match (kind, cpr) {
            (0, _) => Feedback::Open,
            (2, _) => Feedback::Closed(Encoder::MultiTurn),
            (_, 12) => Feedback::Closed(Encoder::SingleTurn),
            (_, lines) => Feedback::Closed(Encoder::Incremental { counts: lines.saturating_mul(4) }),
        }
    }

    /// The encoder of the closed loop, if it runs.
    pub const fn encoder(self) -> Option<Encoder> {
        match self {
            Feedback::Open => None,
            Feedback::Closed(e) => Some(e),
        }
    }
}

/// An angle or offset in microsteps: whole microsteps and a fraction, as the setpoint carries.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Micro {
    /// Whole microsteps (floor).
    pub whole: i64,
    /// The fraction in [0, 1).
    pub fraction: f32,
}

/// An `i64` that is small in practice (a tick's encoder counts, a following error) as `f32`,
/// saturated to `i32` first: the FPU converts that, where an `i64` conversion is a library call.
pub(crate) fn small(x: i64) -> f32 {
    x.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32 as f32
}

impl Micro {
    /// `counts` of an encoder with `per_rev` counts a turn, in microsteps of `per_step` a full
    /// step, exactly: whole part by integer division, the remainder as the fraction.
    pub fn from_counts(counts: i64, per_rev: u32, per_step: u32) -> Self {
        let per_rev = i64::from(per_rev.max(1));
        let num = counts.saturating_mul(STEPS_PER_REV * i64::from(per_step.max(1)));
        let whole = num.div_euclid(per_rev);
        // Below `per_rev`, a `u32`: the FPU converts it (an `i64` conversion is a library call).
        Self { whole, fraction: num.rem_euclid(per_rev) as u32 as f32 / per_rev as u32 as f32 }
    }

    /// This angle moved by `by` microsteps (small: at most a few full steps).
    pub fn plus(self, by: f32) -> Self {
        let by = if by.is_finite() { by } else { 0.0 };
        let f = self.fraction + by;
        let floor = libm::floorf(f);
        // `as i32`: the FPU's saturating conversion (`by` is a few full steps at most).
        Self {
            whole: self.whole.saturating_add(i64::from(floor as i32)),
            fraction: (f - floor).clamp(0.0, 0.999_999_9),
        }
    }
}

/// The sensorless stall detector's memory.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Sensorless {
    /// Phase currents at the last tick, A.
    last_i: Option<[f32; 2]>,
    /// Low-passed e·i and e×i, W.
    dot: f32,
    cross: f32,
    /// Low-passed back-EMF magnitude, V.
    pub(crate) emf: f32,
    /// Learned back-EMF of a freely running motor, V per full step a second.
    per_speed: f32,
    /// Since when the commanded speed has been above the minimum.
    fast_since: Option<Instant>,
    /// Ticks in a row the stall condition has held.
    count: u8,
    /// Seconds with a weak back-EMF, less those without (not below 0).
    held: f32,
    /// The direction of the last tick's motion, 1 or -1 ([`Sensorless::load_angle`] is in the
    /// direction of motion).
    sign: f32,
}

/// What the sensorless detector is told at one tick.
#[derive(Clone, Copy, Debug)]
pub(crate) struct SensorlessInput {
    /// Measured phase currents, A.
    pub i: [f32; 2],
    /// Bridge voltages averaged over the tick, V.
    pub v: [f32; 2],
    /// The power stage's own estimate of the back-EMF, V, if it makes one: taken as it is.
    pub e: Option<[f32; 2]>,
    /// Winding resistance, Ω, and inductance, H.
    pub r: f32,
    pub l: f32,
    /// Commanded speed, full steps per second (signed).
    pub speed: f32,
    /// The minimum speed for detection, full steps per second.
    pub min_speed: f32,
    /// The cosine of the load angle beyond which the rotor has pulled out.
    pub limit_cos: f32,
}

/// Bounds of the detector's low-pass weight per tick (the weight is the share of a full step
/// the motor travels in a tick).
const EMF_ALPHA_MIN: f32 = 1.0 / 256.0;
const EMF_ALPHA_MAX: f32 = 1.0 / 4.0;
/// How fast the learned back-EMF per speed follows a healthy motor.
const PER_SPEED_ALPHA: f32 = 1.0 / 1024.0;
/// The share of the learned back-EMF below which the rotor counts as held.
pub const EMF_SHARE: f32 = 0.5;
/// How long the back-EMF must be weak, s (net of the time it is not), or over how many full
/// steps of travel at the speed, whichever comes first: a rotor ringing after a step in
/// acceleration dips below the threshold for a moment, a held or slipping rotor stays there or
/// keeps coming back.
pub const STALL_WEAK_S: f32 = 0.002;
/// See [`STALL_WEAK_S`].
pub const STALL_WEAK_STEPS: f32 = 0.5;

impl Sensorless {
    /// One tick; whether the rotor has stalled.
    pub(crate) fn update(&mut self, now: Instant, x: &SensorlessInput) -> bool {
        let last = self.last_i.replace(x.i).unwrap_or(x.i);
        let [ia, ib] = x.i;
        let [la, lb] = last;
        let [va, vb] = x.v;
        let (ma, mb) = ((ia + la) * 0.5, (ib + lb) * 0.5);
        let raw = (va - x.r * ma - x.l * (ia - la) / TICK_S, vb - x.r * mb - x.l * (ib - lb) / TICK_S);
        let length = |(a, b): (f32, f32)| crate::math::sqrt(a * a + b * b);
        // The power stage's estimate is free of the sampling noise that puts a floor under the
        // tick's own (what matters at low speed), but it follows a sudden stop over a couple of
        // milliseconds: the weaker of the two counts.
        let ((ea, eb), magnitude) = match x.e {
            Some([a, b]) => ((a, b), length((a, b)).min(length(raw))),
            None => (raw, length(raw)),
        };
        let (dot, cross) = (ea * ma + eb * mb, ea * mb - eb * ma);
        // Averaged over about half a full step of travel: at low speed a stepper rings inside each
        // step, and its back-EMF dips with every ring.
        let speed = libm::fabsf(x.speed);
        let alpha = (1.5 * speed * TICK_S).clamp(EMF_ALPHA_MIN, EMF_ALPHA_MAX);
        self.dot += (dot - self.dot) * alpha;
        self.cross += (cross - self.cross) * alpha;
        self.emf += (magnitude - self.emf) * alpha;
        self.sign = if x.speed < 0.0 { -1.0 } else { 1.0 };
        if speed < x.min_speed || x.min_speed <= 0.0 {
            (self.fast_since, self.count, self.held, self.per_speed) = (None, 0, 0.0, 0.0);
            return false;
        }
        let since = *self.fast_since.get_or_insert(now);
        let per_speed = self.emf / speed;
        if now.since(since) < STALL_SETTLE_MICROS || self.per_speed == 0.0 {
            // Running freely: learn the back-EMF a full step a second gives.
            self.per_speed =
                if self.per_speed == 0.0 { per_speed } else { self.per_speed + (per_speed - self.per_speed) * 0.05 };
            return false;
        }
        // Too little back-EMF for the speed: the rotor is held or slipping; else the load angle.
        let weak = per_speed < self.per_speed * EMF_SHARE;
        // |atan2(y, x)| beyond the limit, without the arctangent: x below r·cos(limit).
        let [y, c] = self.pull();
        let pulled_out = c < x.limit_cos * crate::math::sqrt(y * y + c * c);
        let stalled = weak || pulled_out;
        if !stalled {
            self.per_speed += (per_speed - self.per_speed) * PER_SPEED_ALPHA;
        }
        // A weak back-EMF counts over time: up while weak, back down while not. A held rotor
        // stays weak, a slipping one is weak more than not; a ring after a step in acceleration
        // dips for a moment and recovers.
        self.held = if weak { self.held + TICK_S } else { (self.held - TICK_S).max(0.0) };
        self.count = if stalled { self.count.saturating_add(1) } else { 0 };
        self.count >= STALL_TICKS && (pulled_out || self.held >= STALL_WEAK_S || self.held * speed >= STALL_WEAK_STEPS)
    }

    /// The load angle's sine and cosine, each times the same magnitude, in the direction of
    /// motion.
    fn pull(&self) -> [f32; 2] {
        [self.sign * self.dot, -self.sign * self.cross]
    }

    /// The last estimated load angle, rad, in the direction of motion (for tests and traces).
    pub(crate) fn load_angle(&self) -> f32 {
        match self.pull() {
            [y, x] if y == 0.0 && x == 0.0 => 0.0,
            [y, x] => libm::atan2f(y, x),
        }
    }

    /// Forgets the motion: the next detection starts afresh.
    pub(crate) fn reset(&mut self) {
        *self = Self { last_i: None, ..Self::default() };
    }
}

/// The load-angle limit of the stall threshold 0x6039 (bits 0-6, signed), rad.
pub fn stall_limit(params: u32) -> f32 {
    let t = (((params & 0x7F) as u8) << 1) as i8 >> 1;
    let deg = (110.0 - 4.0 * f32::from(t)).clamp(45.0, 175.0);
    deg.to_radians()
}

/// The closed loop's memory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Servo {
    /// The feedback in force (from power-up).
    pub(crate) feedback: Feedback,
    /// The last raw reading.
    last_raw: Option<u32>,
    /// Encoder position, counts (unwrapped).
    pub(crate) encoder: i64,
    /// The encoder position at the electrical zero (the first reading).
    align: i64,
    /// Measured speed, counts per second, low-passed over ~13 ms.
    pub(crate) speed: f32,
    /// PID integral, in units of the full current.
    integral: f32,
    /// Low-passed rate of the following error, full steps per second.
    rate: f32,
    /// The last following error, full steps.
    last_error: f32,
    /// The last following error, counts (setpoint − measured).
    pub(crate) following: i64,
    /// The sensorless stall detector.
    pub(crate) sensorless: Sensorless,
    /// The whole microsteps of the last tick's electrical angle.
    pub(crate) last_angle: i64,
    /// The resolution `last_angle` counts in, microsteps a full step.
    pub(crate) last_per_step: u32,
}

/// What the closed loop asks of the power stage at one tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Drive {
    /// The electrical angle to drive, microsteps.
    pub angle: Micro,
    /// The share of the phase current to drive, 0..=1.
    pub current: f32,
}

/// The PID gains and filter of the servo loop, in physical units (see the module doc).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gains {
    /// Full current per full step of error.
    pub kp: f32,
    /// Full current per full step·second.
    pub ki: f32,
    /// Full current per full step per millisecond.
    pub kd: f32,
    /// The error rate's low-pass weight per tick.
    pub alpha: f32,
}

impl Gains {
    /// The gains of 0x6057..0x605A.
    pub fn from_objects(kp: u32, ki: u32, kd: u32, prefilter: u32) -> Self {
        Self { kp: kp as f32 / 16.0, ki: ki as f32 * 5.0, kd: kd as f32 / 4.0, alpha: 1.0 / prefilter.max(1) as f32 }
    }
}

impl Servo {
    /// The loop at power-up.
    pub(crate) const fn new(feedback: Feedback) -> Self {
        Self {
            feedback,
            last_raw: None,
            encoder: 0,
            align: 0,
            speed: 0.0,
            integral: 0.0,
            rate: 0.0,
            last_error: 0.0,
            following: 0,
            sensorless: Sensorless {
                last_i: None,
                dot: 0.0,
                cross: 0.0,
                emf: 0.0,
                per_speed: 0.0,
                fast_since: None,
                count: 0,
                held: 0.0,
                sign: 1.0,
            },
            last_angle: 0,
            last_per_step: 1,
        }
    }

    /// Counts a turn of the encoder in use (open loop: an incremental encoder of 0x6054 lines is
    /// assumed for 0x6089).
    pub(crate) fn encoder_kind(&self, cpr: u32) -> Encoder {
        match self.feedback {
            Feedback::Closed(e) => e,
            Feedback::Open => Encoder::Incremental { counts: cpr.saturating_mul(4) },
        }
    }

    /// Takes a reading; whether it was the first (the caller then places the axis).
    pub(crate) fn read(&mut self, encoder: Encoder, raw: u32) -> bool {
        let Some(last) = self.last_raw.replace(raw) else {
            self.encoder = encoder.first(raw);
            self.align = self.encoder;
            return true;
        };
        let moved = encoder.delta(last, raw);
        self.encoder = self.encoder.saturating_add(moved);
        // About 13 ms of low-pass: a count a tick is 20 000 counts/s, and at slow speed counts
        // come every few ticks.
        self.speed += (small(moved) / TICK_S - self.speed) * (1.0 / 256.0);
        false
    }

    /// The rotor's electrical angle in microsteps of `per_step` a full step.
    pub(crate) fn rotor_angle(&self, per_rev: u32, per_step: u32) -> Micro {
        Micro::from_counts(self.encoder.saturating_sub(self.align), per_rev, per_step)
    }

    /// Forgets the PID's memory (the power stage is off, or the loop restarts).
    pub(crate) fn relax(&mut self) {
        (self.integral, self.rate, self.last_error, self.following) = (0.0, 0.0, 0.0, 0);
    }

    /// The position loop: the setpoint's angle, at most a full step ahead of or behind the
    /// rotor. `error` is the following error in microsteps.
    pub(crate) fn position_loop(&self, rotor: Micro, error: f32, per_step: u32) -> Drive {
        let lead = per_step.max(1) as f32;
        // Not `clamp`: with bounds it cannot prove ordered, that is a panic (and float formatting).
        Drive { angle: rotor.plus(error.max(-lead).min(lead)), current: 1.0 }
    }

    /// The servo loop: the PID on `error` (full steps), a full step of lead in its direction.
    pub(crate) fn servo_loop(&mut self, rotor: Micro, error: f32, per_step: u32, g: &Gains) -> Drive {
        let rate = (error - self.last_error) / TICK_S;
        self.last_error = error;
        self.rate += (rate - self.rate) * g.alpha;
        let unclamped = g.kp * error + self.integral + g.kd * self.rate * 1e-3;
        // Anti-windup: integrate only while the output is not saturated in the error's direction.
        if libm::fabsf(unclamped) < 1.0 || (unclamped > 0.0) != (error > 0.0) {
            self.integral = (self.integral + g.ki * error * TICK_S).clamp(-1.0, 1.0);
        }
        let u = unclamped.clamp(-1.0, 1.0);
        let lead = if u < 0.0 { -(per_step.max(1) as f32) } else { per_step.max(1) as f32 };
        Drive { angle: rotor.plus(lead), current: libm::fabsf(u) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_convert_to_microsteps_exactly() {
        // 1000 lines ×4 = 4000 counts a turn = 200 full steps: 20 counts a full step.
        let m = Micro::from_counts(30, 4000, 16);
        assert_eq!((m.whole, m.fraction), (24, 0.0));
        let m = Micro::from_counts(-1, 4096, 1);
        assert_eq!(m.whole, -1);
        assert!((m.fraction - (1.0 - 200.0 / 4096.0)).abs() < 1e-6);
    }

    #[test]
    fn readings_unwrap_across_the_wrap() {
        let mut s = Servo::new(Feedback::Closed(Encoder::SingleTurn));
        assert!(s.read(Encoder::SingleTurn, 4090));
        assert_eq!(s.encoder, 4090);
        s.read(Encoder::SingleTurn, 5);
        assert_eq!(s.encoder, 4101);
        s.read(Encoder::SingleTurn, 4000);
        assert_eq!(s.encoder, 4000);
        let inc = Encoder::Incremental { counts: 4000 };
        let mut s = Servo::new(Feedback::Closed(inc));
        s.read(inc, u32::MAX - 1);
        s.read(inc, 3);
        assert_eq!(s.encoder, 5);
    }

    #[test]
    fn the_threshold_moves_the_limit() {
        assert!((stall_limit(0).to_degrees() - 110.0).abs() < 1e-3);
        assert!((stall_limit(5).to_degrees() - 90.0).abs() < 1e-3);
        // -10 as 7-bit two's complement.
        assert!((stall_limit(0x76).to_degrees() - 150.0).abs() < 1e-3);
        assert!((stall_limit(0x40).to_degrees() - 175.0).abs() < 1e-3);
    }

    #[test]
    fn the_position_loop_never_leads_the_rotor_by_more_than_a_full_step() {
        let s = Servo::new(Feedback::Closed(Encoder::SingleTurn));
        let rotor = Micro { whole: 100, fraction: 0.5 };
        assert_eq!(s.position_loop(rotor, 3.0, 16).angle, Micro { whole: 103, fraction: 0.5 });
        assert_eq!(s.position_loop(rotor, 40.0, 16).angle, Micro { whole: 116, fraction: 0.5 });
        assert_eq!(s.position_loop(rotor, -40.0, 16).angle, Micro { whole: 84, fraction: 0.5 });
    }

    #[test]
    fn the_servo_integral_stops_while_saturated() {
        let mut s = Servo::new(Feedback::Closed(Encoder::SingleTurn));
        let g = Gains::from_objects(8, 4, 8, 32);
        for _ in 0..20_000 {
            s.servo_loop(Micro { whole: 0, fraction: 0.0 }, 10.0, 16, &g);
        }
        // Saturated all along: the integral never grew.
        assert_eq!(s.integral, 0.0);
        for _ in 0..2_000 {
            s.servo_loop(Micro { whole: 0, fraction: 0.0 }, 0.5, 16, &g);
        }
        assert!(s.integral > 0.0 && s.integral <= 1.0);
    }
}
