//! Time-optimal, jerk-limited ("double S") profiles for one axis, planned online from any state.
//!
//! A [`Profile`] takes the axis from its current state (position, velocity, acceleration) to a target
//! position ([`Profile::to_position`]) or velocity ([`Profile::to_velocity`]) in minimum time,
//! subject to a speed limit, an acceleration limit that depends on whether the speed is increasing
//! (`a_max`) or decreasing (`d_max`), and optionally a jerk limit. Without a jerk limit the profile is
//! the classic trapezoid (the acceleration may jump).
//!
//! # How it is solved
//!
//! Every time-optimal profile to a rest-like end state (`a = 0`) is made of at most two *pulses*
//! separated by an optional cruise at `±v_max`:
//!
//! * pulse 1 takes `(v0, a0)` to a turning velocity `vp` with `a = 0`,
//! * an optional cruise at `vp = ±v_max`,
//! * pulse 2 takes `(vp, 0)` to `(v_target, 0)`.
//!
//! A pulse is the fastest possible change of velocity. With the speed as the independent variable
//! and `E = a²/2`, the jerk limit is `|dE/dv| ≤ j`, so the fastest pulse is the pointwise *minimum* of
//! a few simple bounds: the rise from the start state, the fall to the end state, the acceleration
//! limit (two levels when the speed passes through zero, `d_max` while braking and `a_max` after;
//! smoothed by the jerk so that the acceleration is back under the lower level at the crossing) and,
//! when the start is beyond a limit, the brake line that returns to it at full jerk. The envelope is
//! piecewise linear in `v`; each linear piece is one phase of constant jerk (`±j` or `0`), so a pulse
//! is built in closed form. This covers all of Ruckig's UDDU / UDUD shapes with or without reaching
//! the acceleration limit, the brake pre-phase (start beyond `a_max`/`d_max`, or moving faster than
//! `v_max`), reversals, overshoot-and-return and the asymmetric limits.
//!
//! The turning velocity `vp` is the only unknown: on each side of the direct profile the distance
//! covered by "pulse 1 + pulse 2" is monotonic in `vp`; the cruise variants at `±v_max` are
//! direct. Two one-parameter families fill the distances in between, with the depth of a "dip"
//! of the acceleration towards zero as their unknown:
//!
//! * already accelerating towards the final velocity: the acceleration first falls at full jerk
//!   and rises again (Ruckig's UDUD without a turn),
//! * faster than `v_max`: the braking eases off as the speed reaches `v_max` (a full dip is "brake
//!   to `v_max`, cruise").
//!
//! Each family is solved in closed form (`pulse_closed`): a pulse between zero accelerations
//! at one limit is symmetric in time, so it covers its mean speed times its duration (`Δv/l +
//! l/j`, or `2√(Δv/j)` short of the limit), and every pulse above is cut from one or two such
//! pulses (the tail of one when it starts accelerating, the head of one when it ends so, two
//! when the speed passes zero between `d_max` and `a_max`). A turn's speed is `vp = vi ± z²`
//! from the direct profile's end `vi`, where the distance is smooth in `z`, and is found by
//! safeguarded Newton steps on that closed form (a quadratic in `vp` while both pulses reach the
//! limit, a quartic in `z` short of it), as is an accelerating dip's depth; the braking dip at
//! `v_max`, and a dip whose pulse passes through zero speed between two limits, by a bracketed
//! Illinois / bisection search on its closed form (its slope has no simple form). The
//! candidates whose distance range holds the move's are compared by their closed-form
//! durations and only the fastest is built: every move from within the limits. A start with
//! more acceleration than zero speed allows ramps down at full jerk through it. Past zero speed
//! the limit is `a_max`, reached at full jerk from the acceleration the speed passed zero with
//! (at most `d_max`, or more from a start beyond it); from a start at speed it holds at once.
//! Where no closed form applies (a ramp through zero speed that would overshoot the end speed)
//! or its result does not land within rounding, a bracketed search over the same families
//! builds and measures the pulses themselves: none of the 180 000 plans of the comparison with
//! Ruckig, none of 200 000 first plans in each of the hunts' regions (`search_share`).
//!
//! Above `v_max` the speed only ever decreases (or is still being pushed
//! up by a start acceleration that is ramped down at full jerk); it is eased into `v_max` rather
//! than braked at full deceleration down to `v_max` and then undershot, as Ruckig's brake does, so
//! from such starts it is often faster than Ruckig.
//!
//! # Precision and cost
//!
//! The planner computes in `f32`, which the Cortex-M4F's FPU does in one instruction (`f64`
//! would be software there: several times the code and the time). Positions are relative to the
//! drive's anchor (the whole microsteps where the move starts), so they are the move's own
//! distances: a profile lands on its target to the rounding of the terms it sums (2^-18 of
//! their magnitudes, about the speed times the duration), and the track the tick walks stands
//! on the integer target exactly ([`super::track::Finish`]). The limits are those the drive
//! sets: S-curves at the manual's accelerations (5 210 to 77 440 pps²) with a jerk of the larger
//! one over a jerk time of 1 ms to 1 s, so that a jerk phase changes the speed by more than the
//! speed's own rounding (2^-24 of it); trapezoids at 100 pps² and more. A start acceleration
//! whose ramp to zero would change the speed by less than that is taken as zero. The property
//! suite (`drive-core/tests/profile_scurve.rs`) covers that domain.
//!
//! [`Profile::position`] finds the phase (binary search over at most [`MAX_PHASES`] start times) and
//! evaluates one cubic in Horner form; [`Profile::at`] adds the velocity and acceleration.
//! [`Profile::position_q32`] adds a floor and two conversions to return whole microsteps and a
//! 32-bit fraction for a step generator.
//!
//! The control tick does not evaluate a profile: it walks a track sampled from it
//! ([`super::track`]).
//!
//! Planning evaluates a few closed forms (each a few dozen `f32` operations and a square root
//! or two) a few times each, then builds the winner's pulses directly; a pulse needs the
//! envelope's walk (a sort of at most 48 numbers) only with a dip or a brake line.
//! `cargo bench -p drive-core --bench tick` measures it next to Ruckig, and `cargo xtask
//! tick-cost` a whole move request on the M4 (docs/performance.md). Planning belongs outside
//! the 20 kHz tick. A [`Profile`] is 340 bytes on the Cortex-M4.
//!
//! ```
//! use drive_core::motion::scurve::{Limits, Profile, State};
//! let lim = Limits { v_max: 10_000.0, a_max: 50_000.0, d_max: 50_000.0, jerk: Some(1.0e6) };
//! // 20 000 microsteps from rest: 0.05 s of jerk up to a_max, 0.15 s at a_max, 0.05 s back to
//! // a = 0 at 10 000 pps (1250 microsteps), cruise 1.75 s, brake the same way.
//! let prof = Profile::to_position(State::default(), 20_000.0, 0.0, &lim).unwrap();
//! assert!((prof.duration() - 2.25).abs() < 1e-9);
//! let mid = prof.at(1.125);
//! assert!((mid.p - 10_000.0).abs() < 1e-6 && (mid.v - 10_000.0).abs() < 1e-9);
//! assert_eq!(prof.at(10.0), State { p: 20_000.0, v: 0.0, a: 0.0 });
//! ```

use super::whole::floor;
use crate::math::sqrt;
use libm::fabsf as fabs;

/// The kinematic limits of a move. All values are in microsteps and seconds.
///
/// ```
/// use drive_core::motion::scurve::Limits;
/// // 2 rev/s at 6400 µsteps/rev, accelerate at 77 440 pps², brake at 5 210 pps², jerk-limited.
/// let lim = Limits { v_max: 12_800.0, a_max: 77_440.0, d_max: 5_210.0, jerk: Some(2.0e6) };
/// assert!(lim.d_max < lim.a_max);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Largest speed |v| (microsteps/s), > 0.
    pub v_max: f32,
    /// Largest |a| while the speed |v| is increasing (microsteps/s²), > 0.
    pub a_max: f32,
    /// Largest |a| while the speed |v| is decreasing (microsteps/s²), > 0.
    pub d_max: f32,
    /// Largest |da/dt| (microsteps/s³), > 0; `None` for an infinite jerk (trapezoidal profile).
    /// At most 1000 times the larger acceleration (a jerk time of 1 ms, the drive's shortest):
    /// sharper, a jerk phase would change the speed by less than `f32` resolves.
    pub jerk: Option<f32>,
}

/// The kinematic state of the axis: position (microsteps, relative to the drive's anchor),
/// velocity (microsteps/s) and acceleration (microsteps/s²).
///
/// ```
/// use drive_core::motion::scurve::State;
/// let s = State { p: 12.5, v: -300.0, a: 0.0 };
/// assert_eq!(State::default(), State { p: 0.0, v: 0.0, a: 0.0 });
/// assert!(s.v < 0.0);
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct State {
    /// Position (microsteps).
    pub p: f32,
    /// Velocity (microsteps/s).
    pub v: f32,
    /// Acceleration (microsteps/s²).
    pub a: f32,
}

/// Why a profile could not be planned.
///
/// ```
/// use drive_core::motion::scurve::{Limits, PlanError, Profile, State};
/// let bad = Limits { v_max: 0.0, a_max: 1.0, d_max: 1.0, jerk: None };
/// assert_eq!(Profile::to_position(State::default(), 1.0, 0.0, &bad), Err(PlanError::InvalidLimits));
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlanError {
    /// A limit is zero, negative, NaN or infinite.
    InvalidLimits,
    /// The start state contains NaN or an infinity.
    InvalidState,
    /// The target is NaN or infinite, or its speed is negative or above `v_max`.
    InvalidTarget,
    /// The numerical solution failed (not expected for finite inputs of sane magnitude).
    NoSolution,
}

/// The most constant-jerk phases a [`Profile`] holds (7 for symmetric limits, more when the move
/// starts beyond a limit or passes through zero speed with `a_max ≠ d_max`).
pub const MAX_PHASES: usize = 16;

/// One phase of constant jerk, with its start state precomputed.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
struct Phase {
    /// Start time (s) from the beginning of the profile.
    t0: f32,
    /// Position at `t0`.
    p: f32,
    /// Velocity at `t0`.
    v: f32,
    /// Half the acceleration at `t0`.
    a2: f32,
    /// A sixth of the jerk.
    j6: f32,
}

/// A planned motion: at most [`MAX_PHASES`] phases of constant jerk, evaluated in closed form.
///
/// It is `Copy` and has a fixed size (no heap). Evaluating it never drifts: each phase is evaluated
/// from its own precomputed start state, and at and after [`Profile::duration`] a position profile
/// returns exactly its target.
///
/// ```
/// use drive_core::motion::scurve::{Limits, Profile, State};
/// // Trapezoid (no jerk limit): 1000 microsteps, accelerate at 4000 pps², brake at 2000 pps².
/// let lim = Limits { v_max: 1_000.0, a_max: 4_000.0, d_max: 2_000.0, jerk: None };
/// let prof = Profile::to_position(State::default(), 1_000.0, 0.0, &lim).unwrap();
/// // 0.25 s to reach 1000 pps (125 steps), 0.5 s to stop (250 steps), 0.625 s cruise in between.
/// assert!((prof.duration() - 1.375).abs() < 1e-12);
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Profile {
    phases: [Phase; MAX_PHASES],
    n: usize,
    duration: f32,
    end: State,
}

impl Phase {
    const ZERO: Phase = Phase { t0: 0.0, p: 0.0, v: 0.0, a2: 0.0, j6: 0.0 };
}

impl Profile {
    /// No motion: what a profile is before it is planned into (`to_position_into`).
    pub const EMPTY: Profile =
        Profile { phases: [Phase::ZERO; MAX_PHASES], n: 0, duration: 0.0, end: State { p: 0.0, v: 0.0, a: 0.0 } };
}

// ------------------------------------------------------------------------------------------------
// Internal representation of the limits and of one velocity pulse.

/// Validated limits; `j` is infinite for a trapezoid.
#[derive(Clone, Copy, Debug)]
struct Lim {
    v: f32,
    acc: f32,
    dec: f32,
    j: f32,
}

impl Lim {
    fn new(l: &Limits) -> Result<Lim, PlanError> {
        let ok = |x: f32| x.is_finite() && x > 0.0;
        let j = match l.jerk {
            Some(j) if ok(j) => j,
            Some(_) => return Err(PlanError::InvalidLimits),
            None => f32::INFINITY,
        };
        if ok(l.v_max) && ok(l.a_max) && ok(l.d_max) {
            // Two levels whose jerk-smoothed switch at zero speed (|a_max² − d_max²|/2j of
            // speed) is narrower than `f32` resolves at the top speed are one, the lower: a
            // pulse could not place the switch.
            let (lo, hi) = (l.a_max.min(l.d_max), l.a_max.max(l.d_max));
            if j.is_finite() && (hi - lo) * (hi + lo) < 16.0 * f32::EPSILON * l.v_max * j {
                return Ok(Lim { v: l.v_max, acc: lo, dec: lo, j });
            }
            Ok(Lim { v: l.v_max, acc: l.a_max, dec: l.d_max, j })
        } else {
            Err(PlanError::InvalidLimits)
        }
    }

    fn smooth(&self) -> bool {
        self.j.is_finite()
    }

    /// The velocity reached by bringing the acceleration to zero at full jerk.
    fn v_nat(&self, v: f32, a: f32) -> f32 {
        if self.smooth() { v + a * fabs(a) / (2.0 * self.j) } else { v }
    }
}

/// A segment of constant jerk: duration, start acceleration, jerk.
#[derive(Clone, Copy, Debug, Default)]
struct Seg {
    t: f32,
    a: f32,
    j: f32,
}

const PULSE_SEGS: usize = 10;

/// The segments of one pulse (a fastest velocity change).
#[derive(Clone, Copy, Debug)]
struct Pulse {
    segs: [Seg; PULSE_SEGS],
    n: usize,
}

impl Pulse {
    const EMPTY: Pulse = Pulse { segs: [Seg { t: 0.0, a: 0.0, j: 0.0 }; PULSE_SEGS], n: 0 };

    fn push(&mut self, t: f32, a: f32, j: f32) -> Result<(), PlanError> {
        if t.is_nan() {
            return Err(PlanError::NoSolution);
        }
        if t <= 0.0 {
            return Ok(());
        }
        let slot = self.segs.get_mut(self.n).ok_or(PlanError::NoSolution)?;
        *slot = Seg { t, a, j };
        self.n += 1;
        Ok(())
    }

    fn iter(&self) -> impl Iterator<Item = &Seg> {
        self.segs.iter().take(self.n)
    }

    /// Duration, distance and scale of the rounding (the terms' magnitudes summed) of the pulse
    /// when it starts at velocity `v`.
    fn time_dist(&self, mut v: f32) -> Eval {
        let mut e = Eval { t: 0.0, d: 0.0, mag: 0.0 };
        for s in self.iter() {
            let dp = s.t * (v + s.t * (0.5 * s.a + s.t * s.j / 6.0));
            e.d += dp;
            // Not |dp|: a segment through zero speed goes far out and back, and its terms cancel.
            e.mag += s.t * (fabs(v) + s.t * (0.5 * fabs(s.a) + s.t * fabs(s.j) / 6.0));
            v += s.t * (s.a + 0.5 * s.j * s.t);
            e.t += s.t;
        }
        e
    }
}

/// The relative rounding accepted in a candidate's sums: 32 `f32` ulps of the terms' magnitude
/// (a pulse sums a few dozen rounded terms).
const ROUNDING: f32 = 32.0 * f32::EPSILON;

/// Duration, distance and scale of the rounding (at least the path length) of a candidate.
#[derive(Clone, Copy, Debug)]
struct Eval {
    t: f32,
    d: f32,
    mag: f32,
}

impl Eval {
    /// The distance error accepted for this candidate: the rounding of its positions.
    fn tol(&self) -> f32 {
        ROUNDING * self.mag + 1e-5
    }
}

/// A velocity `base + off`: a turn or a dip close to a known velocity (start, natural or final)
/// is a small offset from it, which keeps its own precision. Moving a pulse's end by `δ` moves
/// its end position by about `v·δ/a`, or `2v·√(δ/j)` from `a = 0`: one ulp of a high speed
/// (2^-24 of it) can move it by far more than the rounding the planner accepts.
#[derive(Clone, Copy, Debug)]
struct Vel {
    base: f32,
    off: f32,
}

impl Vel {
    const fn of(v: f32) -> Vel {
        Vel { base: v, off: 0.0 }
    }

    fn val(self) -> f32 {
        self.base + self.off
    }
}

/// An optional "dip" of the acceleration towards `a` as the velocity passes `v` (used when braking
/// from above `v_max`).
#[derive(Clone, Copy, Debug)]
struct Dip {
    v: Vel,
    a: f32,
}

/// The envelope of `E = a²/2` over the shifted, normalised velocity `x` (acceleration ≥ 0,
/// velocity increasing from `x = 0` to `x = w`).
struct Walk {
    j: f32,
    e0: f32,
    w: f32,
    /// `a_max²/2` (speed increasing: normalised velocity > 0).
    ca: f32,
    /// `d_max²/2` (speed decreasing: normalised velocity < 0).
    cd: f32,
    /// `x` at which the velocity is zero.
    xz: f32,
    brk: bool,
    dip: Option<(f32, f32)>,
}

const WALK_LINES: usize = 9;
const WALK_POINTS: usize = 48;
const WALK_PIECES: usize = 12;

impl Walk {
    /// The acceleration limit, smoothed by the jerk: value and slope.
    fn g(&self, x: f32) -> (f32, f32) {
        let (ca, cd, j, xz) = (self.ca, self.cd, self.j, self.xz);
        if cd >= ca {
            if x >= xz {
                (ca, 0.0)
            } else {
                let s = ca + j * (xz - x);
                if s < cd { (s, -j) } else { (cd, 0.0) }
            }
        } else if x < xz {
            (cd, 0.0)
        } else if xz <= 0.0 {
            // From a start at zero speed or on: `a_max` whatever the acceleration was before.
            (ca, 0.0)
        } else {
            let s = self.rise_from() + j * (x - xz);
            if s < ca { (s, j) } else { (ca, 0.0) }
        }
    }

    /// With `d_max` below `a_max`, what `E` is at most as the speed passes zero, whence it may
    /// rise to `a_max` at full jerk: `d_max`, or where the brake line passes zero speed from a
    /// start beyond it.
    fn rise_from(&self) -> f32 {
        if self.brk { self.cd.max(self.e0 - self.j * self.xz) } else { self.cd }
    }

    /// The envelope at `x`: value and slope of the active bound.
    fn env(&self, x: f32) -> (f32, f32) {
        let j = self.j;
        let (mut e, mut k) = (self.e0 + j * x, j);
        let b = j * (self.w - x);
        if b < e {
            e = b;
            k = -j;
        }
        let (mut c, mut ck) = self.g(x);
        if self.brk {
            let br = self.e0 - j * x;
            if br > c {
                c = br;
                ck = -j;
            }
        }
        if c < e {
            e = c;
            k = ck;
        }
        if let Some((xd, ed)) = self.dip {
            let dv = ed + j * fabs(x - xd);
            if dv < e {
                e = dv;
                k = if x < xd { -j } else { j };
            }
        }
        (e, k)
    }

    /// The acceleration limit over the whole pulse when the envelope is the plain one (no dip,
    /// no brake line, the speed kept on one side of zero or the two limits equal): the pulse is
    /// then a ramp up, a hold at the limit if it reaches it and a ramp down, in closed form.
    fn one_level(&self, lim: &Lim) -> Option<f32> {
        if self.dip.is_some() || self.brk {
            return None;
        }
        let (ca, cd, j, xz, w) = (self.ca, self.cd, self.j, self.xz, self.w);
        if cd == ca {
            Some(lim.acc)
        } else if cd > ca {
            // `g` is `ca` from the zero speed on, `cd` before its jerk-smoothed switch.
            if xz <= 0.0 {
                Some(lim.acc)
            } else if w <= xz - (cd - ca) / j {
                Some(lim.dec)
            } else {
                None
            }
        } else if w <= xz {
            Some(lim.dec)
        } else if xz <= 0.0 {
            Some(lim.acc)
        } else {
            None
        }
    }

    /// The pulse of [`Walk::one_level`] at the acceleration limit `level`, appended to `out`
    /// with the sign `s`: from `a0` up at full jerk to the peak (the limit, or where the ramp
    /// down must begin), held, and down to zero. The speed changes by `w = (2·ap² − a0²)/2j`
    /// plus the hold's.
    fn one_level_segments(&self, a0: f32, s: f32, level: f32, out: &mut Pulse) -> Result<(), PlanError> {
        if self.w <= 0.0 {
            return Ok(());
        }
        let j = self.j;
        let peak_sq = self.e0 + j * self.w;
        if peak_sq >= level * level {
            let hold = (self.w - (level * level - self.e0) / j) / level;
            out.push((level - a0) / j, s * a0, s * j)?;
            out.push(hold, s * level, 0.0)?;
            out.push(level / j, s * level, -s * j)
        } else {
            // At least the start acceleration: a pulse that only ramps it down (w = a0²/2j),
            // rounded.
            let peak = sqrt(peak_sq).max(a0);
            out.push((peak - a0) / j, s * a0, s * j)?;
            out.push(peak / j, s * peak, -s * j)
        }
    }

    /// The segments of the envelope, appended to `out` with the sign `s` (denormalisation).
    fn segments(&self, a_start: f32, s: f32, out: &mut Pulse) -> Result<(), PlanError> {
        if self.w <= 0.0 {
            return Ok(());
        }
        let j = self.j;
        // Lines E = c + k x of every bound, to find all the kinks of the envelope.
        let mut lines = [(0.0f32, 0.0f32); WALK_LINES];
        let mut nl = 0usize;
        let mut add_line = |c: f32, k: f32| {
            if let Some(l) = lines.get_mut(nl) {
                *l = (c, k);
                nl += 1;
            }
        };
        add_line(self.e0, j);
        add_line(j * self.w, -j);
        if self.brk {
            add_line(self.e0, -j);
        }
        add_line(self.ca, 0.0);
        if self.cd != self.ca {
            add_line(self.cd, 0.0);
            if self.cd > self.ca {
                add_line(self.ca + j * self.xz, -j);
            } else {
                add_line(self.rise_from() - j * self.xz, j);
            }
        }
        if let Some((xd, ed)) = self.dip {
            add_line(ed - j * xd, j);
            add_line(ed + j * xd, -j);
        }
        let mut pts = [0.0f32; WALK_POINTS];
        let mut np = 0usize;
        let w = self.w;
        let mut add_pt = |x: f32| {
            if x > 0.0
                && x < w
                && let Some(p) = pts.get_mut(np)
            {
                *p = x;
                np += 1;
            }
        };
        add_pt(0.0);
        let lines = lines.get(..nl).unwrap_or(&[]);
        for (i, &(c1, k1)) in lines.iter().enumerate() {
            for &(c2, k2) in lines.iter().skip(i + 1) {
                if k1 != k2 {
                    add_pt((c2 - c1) / (k1 - k2));
                }
            }
        }
        add_pt(self.xz);
        if self.cd > self.ca {
            add_pt(self.xz - (self.cd - self.ca) / j);
        } else if self.cd < self.ca {
            add_pt(self.xz + (self.ca - self.rise_from()) / j);
        }
        if let Some((xd, _)) = self.dip {
            add_pt(xd);
        }
        let pts = pts.get_mut(..np).unwrap_or(&mut []);
        sort_few(pts);

        // Merge the intervals into pieces of equal slope: (x0, x1, slope).
        let mut pieces = [(0.0f32, 0.0f32, 0.0f32); WALK_PIECES];
        let mut nq = 0usize;
        let mut x_prev = 0.0;
        for &x in pts.iter().chain(core::iter::once(&w)) {
            if x <= x_prev {
                continue;
            }
            let (_, k) = self.env(0.5 * (x_prev + x));
            let merged = match nq.checked_sub(1).and_then(|i| pieces.get_mut(i)) {
                Some(last) if last.2 == k => {
                    last.1 = x;
                    true
                }
                _ => false,
            };
            if !merged {
                let slot = pieces.get_mut(nq).ok_or(PlanError::NoSolution)?;
                *slot = (x_prev, x, k);
                nq += 1;
            }
            x_prev = x;
        }
        let pieces = pieces.get(..nq).unwrap_or(&[]);

        // Acceleration of each constant piece (its level), then the segments.
        let level = |i: usize, p: &(f32, f32, f32)| -> f32 {
            if i == 0 { a_start } else { sqrt(2.0 * self.env(0.5 * (p.0 + p.1)).0.max(0.0)) }
        };
        let mut a_prev = a_start;
        for (i, p) in pieces.iter().enumerate() {
            if p.2 == 0.0 {
                let a = level(i, p);
                if a.is_nan() || a <= 0.0 {
                    return Err(PlanError::NoSolution);
                }
                out.push((p.1 - p.0) / a, s * a, 0.0)?;
                a_prev = a;
            } else {
                let a_end = match pieces.get(i + 1) {
                    None => 0.0,
                    Some(q) if q.2 == 0.0 => level(i + 1, q),
                    Some(_) => sqrt(2.0 * self.env(p.1).0.max(0.0)),
                };
                let da = a_end - a_prev;
                let jj = if da >= 0.0 { j } else { -j };
                out.push(fabs(da) / j, s * a_prev, s * jj)?;
                a_prev = a_end;
            }
        }
        Ok(())
    }
}

/// The fastest change from `(vs, a_s)` to `(ve, 0)`, optionally with a dip at `dip.v`, into
/// `out` (the caller's: returned by value, every call site would keep a pulse of its own on the
/// stack).
fn pulse(vs: Vel, a_s: f32, ve: Vel, lim: &Lim, dip: Option<Dip>, out: &mut Pulse) -> Result<(), PlanError> {
    *out = Pulse::EMPTY;
    if !lim.smooth() {
        // The change with the offsets apart (see `Vel`): at a low acceleration, a large speed's
        // rounding alone would move the end by more than the rounding accepted.
        let dv = (ve.base - vs.base) + (ve.off - vs.off);
        let s = if dv >= 0.0 { 1.0 } else { -1.0 };
        let (u0, u1, du) = (s * vs.val(), s * ve.val(), s * dv);
        if du > 0.0 {
            if u0 < 0.0 && u1 > 0.0 {
                out.push(-u0 / lim.dec, s * lim.dec, 0.0)?;
                out.push(u1 / lim.acc, s * lim.acc, 0.0)?;
            } else if u0 >= 0.0 {
                out.push(du / lim.acc, s * lim.acc, 0.0)?;
            } else {
                out.push(du / lim.dec, s * lim.dec, 0.0)?;
            }
        }
        return Ok(());
    }
    let (walk, a0, s) = walk_for(vs, a_s, ve, lim, dip, out)?;
    match walk.one_level(lim) {
        Some(level) => walk.one_level_segments(a0, s, level, out),
        None => walk.segments(a0, s, out),
    }
}

/// Sets up the envelope of a jerk-limited pulse (pushing the counter-ramp, if any, into `out`).
/// Returns the envelope, the start acceleration (normalised, ≥ 0) and the sign.
fn walk_for(
    vs: Vel,
    a_s: f32,
    ve: Vel,
    lim: &Lim,
    dip: Option<Dip>,
    out: &mut Pulse,
) -> Result<(Walk, f32, f32), PlanError> {
    let j = lim.j;
    // Bases and offsets are subtracted apart: a small offset stays exact (see `Vel`).
    let vn = lim.v_nat(vs.base, a_s);
    let s = if (ve.base - vn) + (ve.off - vs.off) >= 0.0 { 1.0 } else { -1.0 };
    let (u0, an) = (s * vs.val(), s * a_s);
    // The envelope starts at v_nat when the start acceleration is first ramped to zero.
    let (us, a0, v_env) = if an < 0.0 {
        out.push(-an / j, a_s, s * j)?;
        (u0 - an * an / (2.0 * j), 0.0, vn)
    } else {
        (u0, an, vs.base)
    };
    let mut walk = Walk {
        j,
        e0: 0.5 * a0 * a0,
        w: (s * ((ve.base - v_env) + (ve.off - vs.off))).max(0.0),
        ca: 0.5 * lim.acc * lim.acc,
        cd: 0.5 * lim.dec * lim.dec,
        xz: -us,
        brk: false,
        dip: dip.map(|d| (s * ((d.v.base - v_env) + (d.v.off - vs.off)), 0.5 * d.a * d.a)),
    };
    walk.brk = walk.e0 > walk.g(0.0).0;
    Ok((walk, a0, s))
}

/// The range of dip accelerations `[a_lo, a_hi]` for a dip at velocity `v` in the fastest pulse
/// `(vs, a_s) → (ve, 0)`: `a_hi` is the pulse's own acceleration there (no dip), `a_lo` the
/// deepest dip the jerk allows coming from the start. `None` if the pulse does not pass `v`.
fn dip_bounds(vs: f32, a_s: f32, ve: f32, lim: &Lim, v: f32) -> Result<Option<(f32, f32)>, PlanError> {
    let mut scratch = Pulse::EMPTY;
    let (walk, _, s) = walk_for(Vel::of(vs), a_s, Vel::of(ve), lim, None, &mut scratch)?;
    // x = s·v − us, and xz = −us.
    let x = s * v + walk.xz;
    if !(x > 0.0 && x < walk.w) {
        return Ok(None);
    }
    let a_hi = sqrt(2.0 * walk.env(x).0.max(0.0));
    let a_lo = sqrt(2.0 * (walk.e0 - walk.j * x).max(0.0)).min(a_hi);
    Ok(Some((a_lo, a_hi)))
}

// ------------------------------------------------------------------------------------------------
// Root finding.

const ROOT_ITERS: usize = 200;

/// Finds `x` in `[xa, xb]` with `f(x) ≈ 0`, given `f(xa)`, `f(xb)` of opposite signs (if they are
/// not, the endpoint nearer to zero is returned). Illinois (modified regula falsi), bisecting when
/// three steps have not halved the bracket; stops at `|f| ≤ ftol`, when the bracket cannot shrink, or after
/// `ROOT_ITERS` evaluations.
///
/// `f` is a trait object: one copy of the search serves every family (generic, each would inline
/// its pulses into a copy of its own: 1.4 KB of flash on the Cortex-M4).
fn solve(
    f: &mut dyn FnMut(f32) -> Result<f32, PlanError>,
    mut xa: f32,
    mut fa: f32,
    mut xb: f32,
    mut fb: f32,
    ftol: f32,
) -> Result<f32, PlanError> {
    let (mut best, mut fbest) = if fabs(fa) < fabs(fb) { (xa, fabs(fa)) } else { (xb, fabs(fb)) };
    if fbest <= ftol || (fa > 0.0) == (fb > 0.0) {
        return Ok(best);
    }
    let mut side = 0i8;
    // Bisect when three steps have not halved the bracket (Illinois stalls on one side).
    let mut width_ref = fabs(xb - xa);
    for it in 0..ROOT_ITERS {
        let mut x = (xa * fb - xb * fa) / (fb - fa);
        let (lo, hi) = if xa < xb { (xa, xb) } else { (xb, xa) };
        if it % 3 == 2 {
            let w = hi - lo;
            if w > 0.5 * width_ref {
                x = 0.5 * (xa + xb);
            }
            width_ref = w;
        }
        if !(x > lo && x < hi) {
            x = 0.5 * (xa + xb);
        }
        if !(x > lo && x < hi) {
            break; // the bracket cannot shrink any more
        }
        let fx = f(x)?;
        if fabs(fx) < fbest {
            best = x;
            fbest = fabs(fx);
        }
        if fabs(fx) <= ftol {
            return Ok(x);
        }
        if (fx > 0.0) == (fa > 0.0) {
            xa = x;
            fa = fx;
            if side == -1 {
                fb *= 0.5;
            }
            side = -1;
        } else {
            xb = x;
            fb = fx;
            if side == 1 {
                fa *= 0.5;
            }
            side = 1;
        }
    }
    Ok(best)
}

// ------------------------------------------------------------------------------------------------
// Planning.

/// A candidate position profile.
#[derive(Clone, Copy, Debug)]
enum Cand {
    /// Pulse to `vp`, cruise for `cruise` s, pulse to the target velocity.
    Turn { vp: Vel, cruise: f32 },
    /// One braking pulse with a dip to `a` at `v`.
    Dip { v: Vel, a: f32 },
}

/// Duration and distance of "pulse to vp, pulse to vf".
fn turn_td(v0: f32, a0: f32, vp: Vel, vf: f32, lim: &Lim) -> Result<Eval, PlanError> {
    let mut p = Pulse::EMPTY;
    pulse(Vel::of(v0), a0, vp, lim, None, &mut p)?;
    let e1 = p.time_dist(v0);
    pulse(vp, 0.0, Vel::of(vf), lim, None, &mut p)?;
    let e2 = p.time_dist(vp.val());
    Ok(Eval { t: e1.t + e2.t, d: e1.d + e2.d, mag: e1.mag + e2.mag })
}

fn dip_td(v0: f32, a0: f32, vf: f32, lim: &Lim, dip: Dip) -> Result<Eval, PlanError> {
    let mut p = Pulse::EMPTY;
    pulse(Vel::of(v0), a0, Vel::of(vf), lim, Some(dip), &mut p)?;
    Ok(p.time_dist(v0))
}

/// The fastest candidate for a move of `d` from `(v0, a0)`, arriving at the velocity `vf`, and
/// its evaluation. Out of line, as [`assemble_position`]: the two run one after the other,
/// and their frames are not on the stack together (a microcontroller's stack is short).
#[inline(never)]
fn fastest_position(v0: f32, a0: f32, vf: f32, d: f32, lim: &Lim) -> Result<(Cand, Eval), PlanError> {
    search_position(v0, a0, vf, d, lim)
}

/// The acceleration limit a pulse between zero accelerations keeps from the speed `from` to
/// `to`: `a_max` if the speed grows, `d_max` if it falls; `None` if it passes through zero
/// with two different limits (the envelope walk builds that pulse).
fn one_limit(from: f32, to: f32, lim: &Lim) -> Option<f32> {
    if from * to < 0.0 && lim.acc != lim.dec {
        None
    } else if fabs(to) >= fabs(from) {
        Some(lim.acc)
    } else {
        Some(lim.dec)
    }
}

/// The duration of a pulse between zero accelerations that changes the speed by `dv ≥ 0` at the
/// acceleration limit `l`, and its slope in `dv` (infinite at `dv = 0` under a jerk limit).
///
/// ```text
/// dv ≥ l²/j:  T = dv/l + l/j        (up to l, hold, down)
/// dv < l²/j:  T = 2·√(dv/j)         (up and down at full jerk)
/// ```
fn pulse_time(dv: f32, l: f32, j: f32) -> (f32, f32) {
    if !j.is_finite() {
        (dv / l, 1.0 / l)
    } else if dv * j >= l * l {
        (dv / l + l / j, 1.0 / l)
    } else {
        let r = sqrt(dv * j);
        (2.0 * r / j, 1.0 / r)
    }
}

/// A pulse in closed form: its duration, distance, and the distance's slopes in the end speed
/// and (from no acceleration) in the start speed.
#[derive(Clone, Copy, Debug)]
struct Closed {
    t: f32,
    d: f32,
    d_end: f32,
    d_start: f32,
}

/// The fastest pulse from `(vs, a_s)` to `(ve, 0)` in closed form ([`Closed`]) when it needs no
/// dip: one acceleration limit (a start acceleration beyond it first returns to it at full
/// jerk), or through zero speed from `d_max` to `a_max` (a start acceleration beyond `d_max`
/// first returns to it; one beyond what zero speed allows ramps down at full jerk through it,
/// then `a_max`'s pulse). `None` otherwise (that ramp would overshoot `ve`).
///
/// A pulse between zero accelerations is symmetric in time: it covers its mean speed times its
/// duration. This one is cut from such pulses. A start acceleration towards `ve` makes it the
/// tail of the pulse from the speed a ramp at full jerk would have started at; one against it
/// is first ramped to zero. Through zero speed with two limits, the acceleration there, `a_z`,
/// is at most the lower limit and what the ramps from the start and to the end allow: the pulse
/// is the head of one at `d_max` ending `a_z/j` after zero speed, then the tail of one at
/// `a_max` that began `a_z/j` before it.
fn pulse_closed(vs: Vel, a_s: f32, ve: Vel, lim: &Lim) -> Option<Closed> {
    let j = lim.j;
    let vn = lim.v_nat(vs.base, a_s);
    let s = if (ve.base - vn) + (ve.off - vs.off) >= 0.0 { 1.0 } else { -1.0 };
    let an = s * a_s;
    // Normalised: the speed `u = s·v` rises by `w ≥ 0` from `u0` with an acceleration `a0 ≥ 0`
    // (a ramp at full jerk of `a` over `a/j` changes the speed by `a·τ/2`: no `j·τ³`, which is
    // 0·∞ for a trapezoid).
    let (t_lead, d_lead, u0, a0, w) = if an < 0.0 {
        let tau = -an / j;
        (tau, tau * (vs.val() + tau * a_s / 3.0), s * (vn + vs.off), 0.0, s * ((ve.base - vn) + (ve.off - vs.off)))
    } else {
        (0.0, 0.0, s * vs.val(), an, s * ((ve.base - vs.base) + (ve.off - vs.off)))
    };
    let ue = u0 + w.max(0.0);
    let c = if u0 >= 0.0 || ue <= 0.0 || lim.acc == lim.dec {
        one_level(u0, a0, w, ue, if u0 >= 0.0 { lim.acc } else { lim.dec }, j)
    } else {
        // Beyond `d_max` before zero speed, the acceleration first returns to it at full jerk.
        let (t_pre, d_pre, u0, a0) = if a0 > lim.dec && u0 + (a0 * a0 - lim.dec * lim.dec) / (2.0 * j) < 0.0 {
            let (tb, db, dv) = ramp_down(u0, a0, lim.dec, j);
            (tb, db, u0 + dv, lim.dec)
        } else {
            (0.0, 0.0, u0, a0)
        };
        let a_lo = lim.acc.min(lim.dec);
        let a_z = a_lo.min(sqrt(a0 * a0 - 2.0 * j * u0)).min(sqrt(2.0 * j * ue));
        let c = if a0 > lim.dec || a0 * a0 > a_z * a_z - 2.0 * j * u0 {
            // More acceleration than zero speed allows even ramped down at once: it ramps down
            // at full jerk through zero speed, then `a_max`'s pulse from there (the limit first
            // regained if beyond it); `None` if that overshoots the end speed.
            let a_zd = sqrt(a0 * a0 + 2.0 * j * u0);
            // (A pulse to the natural velocity ends there: beyond it only by the rounding of
            // `a0²`, against which a small speed is the difference of large terms.)
            if a_zd.is_nan() || a_zd * a_zd > 2.0 * j * ue + ROUNDING * a0 * a0 {
                return None;
            }
            let a_zd = a_zd.min(sqrt(2.0 * j * ue));
            let (tz, dz, _) = ramp_down(u0, a0, a_zd, j);
            let rest = one_level(0.0, a_zd, ue, ue, lim.acc, j);
            // (The slope in the start speed is not this pulse's: it starts accelerating.)
            Closed { t: tz + rest.t, d: dz + rest.d, d_end: rest.d_end, d_start: f32::NAN }
        } else {
            let (tau0, tau1) = (a0 / j, a_z / j);
            let uv = u0 - 0.5 * a0 * tau0;
            let ez = 0.5 * a_z * tau1;
            let (t1, dt1) = pulse_time(ez - uv, lim.dec, j);
            let (t2, dt2) = pulse_time(ue + ez, lim.acc, j);
            let (m1, m2) = (0.5 * (uv + ez), 0.5 * (ue - ez));
            let d1 = m1 * t1 - tau0 * (uv + a0 * tau0 / 6.0) - tau1 * (ez - a_z * tau1 / 6.0);
            let d2 = m2 * t2 - tau1 * (a_z * tau1 / 6.0 - ez);
            Closed {
                t: t1 - tau0 - 2.0 * tau1 + t2,
                d: d1 + d2,
                d_end: 0.5 * t2 + m2 * dt2,
                d_start: 0.5 * t1 - m1 * dt1,
            }
        };
        Closed { t: t_pre + c.t, d: d_pre + c.d, ..c }
    };
    Some(Closed { t: t_lead + c.t, d: d_lead + s * c.d, ..c })
}

/// [`pulse_closed`] at one acceleration limit `level`, normalised: the speed rises by `w`
/// from `u0` to `ue` with the acceleration `a0 ≥ 0` at the start. (Inlined: it is most of
/// every pulse's closed form.)
#[inline(always)]
fn one_level(u0: f32, a0: f32, w: f32, ue: f32, level: f32, j: f32) -> Closed {
    // Beyond the limit, the acceleration first returns to it at full jerk.
    // (The speed change is kept apart from the speeds, as `w` is: see `Vel`.)
    let (t_brake, d_brake, u0, a0, w) = if a0 > level {
        let (tb, db, dv) = ramp_down(u0, a0, level, j);
        (tb, db, u0 + dv, level, w - dv)
    } else {
        (0.0, 0.0, u0, a0, w)
    };
    let tau0 = a0 / j;
    let lead0 = 0.5 * a0 * tau0;
    let uv = u0 - lead0;
    let (t, dt) = pulse_time(w.max(0.0) + lead0, level, j);
    let m = 0.5 * (uv + ue);
    let d = d_brake + m * t - tau0 * (uv + a0 * tau0 / 6.0);
    Closed { t: t_brake + t - tau0, d, d_end: 0.5 * t + m * dt, d_start: 0.5 * t - m * dt }
}

/// A ramp at full jerk `j` of the acceleration from `a0` down to `a1`, normalised, from the
/// speed `u0`: its duration, distance and change of speed.
#[inline(always)]
fn ramp_down(u0: f32, a0: f32, a1: f32, j: f32) -> (f32, f32, f32) {
    let t = (a0 - a1) / j;
    (t, t * (u0 + t * (0.5 * a0 - (a0 - a1) / 6.0)), 0.5 * t * (a0 + a1))
}

/// Duration, distance and the distance's slope in `w` of "pulse from `(v0, a0)` to `(w, 0)`,
/// pulse to `(vf, 0)`" in closed form ([`pulse_closed`]); `None` if a pulse is not of that
/// kind.
fn turn_closed(v0: f32, a0: f32, w: Vel, vf: f32, lim: &Lim) -> Option<(f32, f32, f32)> {
    let p1 = pulse_closed(Vel::of(v0), a0, w, lim)?;
    let p2 = pulse_closed(w, 0.0, Vel::of(vf), lim)?;
    Some((p1.t + p2.t, p1.d + p2.d, p1.d_end + p2.d_start))
}

/// Duration, distance and the distance's slope in `a` of the dip family in closed form: from
/// `(v0, a0)` with the acceleration towards the final velocity (the sign `s`), its magnitude
/// `s·a0` first ramped at full jerk to `a` (between 0 and `s·a0`), then the pulse to `(vf, 0)`
/// from there (the tail of a pulse between zero accelerations, as in [`pulse_closed`]). `None`
/// unless the pulse keeps one acceleration limit and `a` is within it.
fn dip_closed(v0: f32, a0: f32, a: f32, vf: f32, s: f32, lim: &Lim) -> Option<(f32, f32, f32)> {
    let j = lim.j;
    let tau = (s * a0 - a) / j;
    let ramp = tau * (v0 + tau * (0.5 * a0 - s * j * tau / 6.0));
    let apex = v0 + tau * (a0 - 0.5 * s * j * tau);
    let lead = a / j;
    let u = apex - s * 0.5 * a * lead;
    let l = one_limit(u, vf, lim)?;
    if a > l {
        return None;
    }
    let (t, dt) = pulse_time((s * (vf - u)).max(0.0), l, j);
    let m = 0.5 * (u + vf);
    let d = ramp + m * t - lead * (u + s * j * lead * lead / 6.0);
    // d(ramp)/da = −apex/j; the pulse's mean speed falls by s·a/j and its speed change grows
    // by 2a/j as the dip deepens; the lead's distance changes by u/j − 3s·a²/2j².
    let slope = -apex / j + (2.0 * m * dt - s * t) * a / j - (u / j - 1.5 * s * a * lead / j);
    Some((tau + t - lead, d, slope))
}

/// Duration and distance of the dip family ([`dip_closed`]) with a dip to `a`, from the pulse's
/// closed form ([`pulse_closed`]), which also takes a pulse through zero speed between two
/// limits; `None` if the pulse is not of its kinds.
fn dip_two(v0: f32, a0: f32, a: f32, vf: f32, s: f32, lim: &Lim) -> Option<(f32, f32)> {
    let j = lim.j;
    let an = s * a0;
    let tau = (an - a) / j;
    let ramp = tau * (v0 + tau * (0.5 * a0 - s * j * tau / 6.0));
    let apex = Vel { base: v0, off: s * ((an - a) * (an + a)) / (2.0 * j) };
    let p = pulse_closed(apex, s * a, Vel::of(vf), lim)?;
    Some((tau + p.t, ramp + p.d))
}

/// The fastest position profile in closed form: from `(v0, a0)`, with pulses of the kinds
/// [`pulse_closed`] takes ([`turn_closed`], [`dip_closed`], [`dip_two`], [`brake_dip`]).
///
/// The distance of "pulse to `w`, pulse to `vf`" grows with the turning speed `w` on each side
/// of the direct profile: above the larger of the natural and the final velocity (`hi`) up to
/// `v_max`, and below the smaller (`lo`) down to `−v_max`. A family is a candidate when its
/// range of distances holds the move's: a cruise at `±v_max` beyond the turns there, a turn on
/// either side, and, when the start acceleration is already towards the final velocity, a dip
/// of it towards zero (from the direct pulse, no dip, to a dip to zero, the turn at the
/// natural velocity). Each solves its closed form: a turn's speed is `w = vi ± z²` from the
/// side's inner end `vi`, where the distance is smooth in `z` (a pulse between nearly equal
/// speeds lasts as √Δv); a dip's depth is its acceleration. Safeguarded Newton steps find
/// them (the distance is a quadratic in `w` while both pulses reach the limit, and a quartic in
/// `z` otherwise); a dip whose pulse passes through zero speed between two limits, the
/// bracketed search on its closed form. The fastest candidate's pulses are then built (`p1`, `p2`) and checked to
/// land within rounding; `None` if the move is not of this kind or the check fails (the search
/// then plans it).
fn closed_pulses(
    v0: f32,
    a0: f32,
    vf: f32,
    d: f32,
    lim: &Lim,
    p1: &mut Pulse,
    p2: &mut Pulse,
) -> Result<Option<(Cand, Eval)>, PlanError> {
    let vmax = lim.v;
    let vn = lim.v_nat(v0, a0);
    if fabs(vf) > vmax {
        return Ok(None);
    }
    let turn = |w: Vel| turn_closed(v0, a0, w, vf, lim);
    let mut best: Option<(f32, Cand)> = None;
    let mut consider = |t: f32, c: Cand| {
        if t.is_finite() && best.is_none_or(|(bt, _)| t < bt) {
            best = Some((t, c));
        }
    };
    // From within the limits, beyond the turns at ±v_max is the cruise there: nothing covers
    // the distance sooner than reaching the top speed at once and braking at the last moment.
    // From beyond them, a braking that eases off at v_max may be sooner.
    let within = fabs(v0) <= vmax && fabs(vn) <= vmax;
    let Some(top) = turn(Vel::of(vmax)) else { return Ok(None) };
    if d >= top.1 {
        let cruise = (d - top.1) / vmax;
        consider(top.0 + cruise, Cand::Turn { vp: Vel::of(vmax), cruise });
    }
    if !within || d < top.1 {
        let Some(bottom) = turn(Vel::of(-vmax)) else { return Ok(None) };
        if d <= bottom.1 {
            let cruise = (bottom.1 - d) / vmax;
            consider(bottom.0 + cruise, Cand::Turn { vp: Vel::of(-vmax), cruise });
        }
        if (!within || d > bottom.1) && closed_turns(v0, a0, vf, d, lim, (top, bottom), &mut consider).is_none() {
            return Ok(None);
        }
        if !within && lim.smooth() && brake_dip(v0, a0, vf, d, lim, &mut consider).is_none() {
            return Ok(None);
        }
    }
    let Some((_, cand)) = best else { return Ok(None) };
    let e = match cand {
        Cand::Turn { vp, cruise } => {
            pulse(Vel::of(v0), a0, vp, lim, None, p1)?;
            pulse(vp, 0.0, Vel::of(vf), lim, None, p2)?;
            let (e1, e2) = (p1.time_dist(v0), p2.time_dist(vp.val()));
            let v = vp.val();
            Eval { t: e1.t + e2.t + cruise, d: e1.d + e2.d + cruise * v, mag: e1.mag + e2.mag + fabs(cruise * v) }
        }
        Cand::Dip { v, a } => {
            pulse(Vel::of(v0), a0, Vel::of(vf), lim, Some(Dip { v, a }), p1)?;
            *p2 = Pulse::EMPTY;
            p1.time_dist(v0)
        }
    };
    Ok((fabs(e.d - d) <= e.tol()).then_some((cand, e)))
}

/// The braking family of [`closed_pulses`] from beyond `v_max`, given to `consider`: one
/// braking pulse whose deceleration eases off to `a` as it passes `±v_max` (the head of a pulse
/// that would end `a/j` later, then the tail of one from there, [`pulse_closed`]), between the
/// deepest dip the jerk allows and none. Its depth is found by the bracketed search on this
/// closed form: its slope has no simple form. `None` if a pulse is not of that kind.
fn brake_dip(v0: f32, a0: f32, vf: f32, d: f32, lim: &Lim, consider: &mut dyn FnMut(f32, Cand)) -> Option<()> {
    let (vmax, vn) = (lim.v, lim.v_nat(v0, a0));
    let vd = if (if fabs(vn) > vmax { vn } else { v0 }) > 0.0 { vmax } else { -vmax };
    let s = if vf >= vn { 1.0 } else { -1.0 };
    let Some((a_lo, a_hi)) = dip_bounds(v0, a0, vf, lim, vd).ok()? else { return Some(()) };
    let dist = |a: f32| -> Option<(f32, f32)> {
        let tau = a / lim.j;
        let end = Vel { base: vd, off: s * 0.5 * a * tau };
        let head = pulse_closed(Vel::of(v0), a0, end, lim)?;
        let tail = pulse_closed(Vel::of(vd), s * a, Vel::of(vf), lim)?;
        let cut = tau * (end.val() - s * a * tau / 6.0);
        Some((head.t - tau + tail.t, head.d - cut + tail.d))
    };
    let (e_lo, e_hi) = (dist(a_lo)?, dist(a_hi)?);
    let (f_lo, f_hi) = (e_lo.1 - d, e_hi.1 - d);
    if (f_lo > 0.0) == (f_hi > 0.0) {
        return Some(());
    }
    let ftol = 2.0 * f32::EPSILON * fabs(d).max(1.0);
    let mut f = |a: f32| dist(a).map(|e| e.1 - d).ok_or(PlanError::NoSolution);
    let a = solve(&mut f, a_lo, f_lo, a_hi, f_hi, ftol).ok()?;
    consider(dist(a)?.0, Cand::Dip { v: Vel::of(vd), a });
    Some(())
}

/// The candidates of [`closed_pulses`] strictly between the cruises at `±v_max` (`ends`: the
/// turns there), given to `consider` (duration, candidate); `None` if one cannot be solved in
/// closed form.
fn closed_turns(
    v0: f32,
    a0: f32,
    vf: f32,
    d: f32,
    lim: &Lim,
    ends: ((f32, f32, f32), (f32, f32, f32)),
    consider: &mut dyn FnMut(f32, Cand),
) -> Option<()> {
    let (vmax, vn, (top, bottom)) = (lim.v, lim.v_nat(v0, a0), ends);
    let ftol = 2.0 * f32::EPSILON * fabs(d).max(1.0);
    let turn = |w: Vel| turn_closed(v0, a0, w, vf, lim);
    let (hi, lo) = (vn.max(vf), vn.min(vf));
    let (inner_hi, inner_lo) = (turn(Vel::of(hi))?, turn(Vel::of(lo))?);
    for (vi, sg, inner, far) in [(hi, 1.0, inner_hi, top), (lo, -1.0, inner_lo, bottom)] {
        if fabs(vi) <= vmax && sg * (d - inner.1) > 0.0 && sg * (far.1 - d) > 0.0 {
            let at = |z: f32| Vel { base: vi, off: sg * z * z };
            let f = |z: f32| turn(at(z)).map(|(_, dist, slope)| (dist - d, slope * 2.0 * sg * z));
            let z_max = sqrt(vmax - sg * vi);
            let (f0, f_max) = (inner.1 - d, far.1 - d);
            // The first guess: the root of the distance's quadratic from `±v_max`, exact while
            // both pulses reach the limit (its curvature in `w` is ±(1/l1 + 1/l2)); else the
            // secant's in `z²`.
            let curve = sg * (1.0 / lim.acc + 1.0 / lim.dec);
            let root = (far.2 * far.2 - 2.0 * curve * f_max).max(0.0);
            let step = -2.0 * f_max / (far.2 + sqrt(root));
            let guess = sqrt(vmax + sg * step - sg * vi);
            let guess = if guess > 0.0 && guess < z_max { guess } else { z_max * sqrt(f0 / (f0 - f_max)) };
            let z = newton(&f, guess, z_max, f0, f_max, ftol)?;
            let (t, _, _) = turn(at(z))?;
            consider(t, Cand::Turn { vp: at(z), cruise: 0.0 });
        }
    }
    let s = if vf >= vn { 1.0 } else { -1.0 };
    let an = s * a0;
    if lim.smooth() && an > 0.0 && fabs(vn) <= vmax {
        // The direct pulse (no dip) and the turn at the natural velocity (a dip to zero).
        // From beyond the limit, the direct pulse first returns to it: a dip to the limit.
        let (direct, none) = (if s > 0.0 { inner_hi } else { inner_lo }, if s > 0.0 { inner_lo } else { inner_hi });
        let (f_deep, f_none) = (none.1 - d, direct.1 - d);
        if (f_deep > 0.0) != (f_none > 0.0) {
            let a = match one_limit(v0, vf, lim) {
                Some(l) => {
                    let a_top = an.min(l);
                    let f = |a: f32| dip_closed(v0, a0, a, vf, s, lim).map(|(_, dist, slope)| (dist - d, slope));
                    newton(&f, a_top * f_deep / (f_deep - f_none), a_top, f_deep, f_none, ftol)?
                }
                // Through zero speed between two limits: the bracketed search on the closed
                // form, whose slope has no simple form here.
                None => {
                    let mut f =
                        |a: f32| dip_two(v0, a0, a, vf, s, lim).map(|(_, dist)| dist - d).ok_or(PlanError::NoSolution);
                    solve(&mut f, 0.0, f_deep, an, f_none, ftol).ok()?
                }
            };
            let (t, _) = dip_two(v0, a0, a, vf, s, lim)?;
            let apex = Vel { base: v0, off: s * ((an - a) * (an + a)) / (2.0 * lim.j) };
            consider(t, Cand::Dip { v: apex, a });
        }
    }
    Some(())
}

/// The most Newton steps [`newton`] takes (each halves the bracket at least every other step).
const NEWTON_ITERS: usize = 40;

/// The root in `[0, x_max]` of `f` (value and slope), given its values `f0` at 0 and `f_max`
/// at `x_max` of opposite signs: Newton steps from the guess `x`, a bisection whenever a step
/// leaves the bracket; stops at `|f| ≤ ftol` or when the bracket cannot shrink.
fn newton(
    f: &dyn Fn(f32) -> Option<(f32, f32)>,
    mut x: f32,
    x_max: f32,
    f0: f32,
    f_max: f32,
    ftol: f32,
) -> Option<f32> {
    if fabs(f0) <= ftol {
        return Some(0.0);
    }
    if fabs(f_max) <= ftol {
        return Some(x_max);
    }
    if (f0 > 0.0) == (f_max > 0.0) || !x_max.is_finite() {
        return None;
    }
    // The side of the bracket where `f` has `f0`'s sign, and the other.
    let (mut near, mut far) = (0.0, x_max);
    for _ in 0..NEWTON_ITERS {
        let (lo, hi) = if near < far { (near, far) } else { (far, near) };
        if !(x > lo && x < hi) {
            x = 0.5 * (near + far);
            if !(x > lo && x < hi) {
                return Some(x);
            }
        }
        let (fx, slope) = f(x)?;
        if fabs(fx) <= ftol {
            return Some(x);
        }
        if (fx > 0.0) == (f0 > 0.0) {
            near = x;
        } else {
            far = x;
        }
        let step = fx / slope;
        x = if step.is_finite() { x - step } else { 0.5 * (near + far) };
    }
    Some(x)
}

/// [`closed_pulses`] without keeping the pulses (for the tests).
#[cfg(test)]
fn closed_form(v0: f32, a0: f32, vf: f32, d: f32, lim: &Lim) -> Result<Option<(Cand, Eval)>, PlanError> {
    let (mut p1, mut p2) = (Pulse::EMPTY, Pulse::EMPTY);
    closed_pulses(v0, a0, vf, d, lim, &mut p1, &mut p2)
}

/// Plans the closed form ([`closed_pulses`]) into `out` from the pulses it measured, not
/// built twice; whether it applies.
#[inline(never)]
fn closed_position(out: &mut Profile, start: State, a0: f32, d: f32, lim: &Lim, end: State) -> Result<bool, PlanError> {
    let (mut p1, mut p2) = (Pulse::EMPTY, Pulse::EMPTY);
    let Some((cand, eval)) = closed_pulses(start.v, a0, end.v, d, lim, &mut p1, &mut p2)? else {
        return Ok(false);
    };
    let (vp, cruise) = match cand {
        Cand::Turn { vp, cruise } => (vp, cruise),
        Cand::Dip { .. } => (Vel::of(0.0), 0.0),
    };
    let mut segs = [Seg::default(); MAX_PHASES];
    let mut ns = 0usize;
    let mut cruise_at = None;
    for (i, s) in p1.iter().enumerate() {
        *segs.get_mut(ns).ok_or(PlanError::NoSolution)? = *s;
        ns = i + 1;
    }
    if cruise > 0.0 {
        cruise_at = Some((ns, vp.val()));
        *segs.get_mut(ns).ok_or(PlanError::NoSolution)? = Seg { t: cruise, a: 0.0, j: 0.0 };
        ns += 1;
    }
    for s in p2.iter() {
        *segs.get_mut(ns).ok_or(PlanError::NoSolution)? = *s;
        ns += 1;
    }
    build_checked(out, State { a: a0, ..start }, segs.get(..ns).unwrap_or(&[]), cruise_at, end, eval, lim)?;
    Ok(true)
}

/// [`fastest_position`] by searching every family of profiles.
fn search_position(v0: f32, a0: f32, vf: f32, d: f32, lim: &Lim) -> Result<(Cand, Eval), PlanError> {
    let vmax = lim.v;
    // Root searches stop at this residual; candidates are accepted within their own rounding.
    let ftol = 2.0 * f32::EPSILON * fabs(d).max(1.0);
    let mut best: Option<(f32, Cand, Eval)> = None;
    let consider = |best: &mut Option<(f32, Cand, Eval)>, c: Cand, e: Eval, residual: f32| {
        if e.t.is_finite() && fabs(residual) <= e.tol() && best.is_none_or(|(bt, _, _)| e.t < bt) {
            *best = Some((e.t, c, e));
        }
    };
    // A family whose shortest possible duration is no better than the best so far is skipped.
    let beaten = |best: &Option<(f32, Cand, Eval)>, t_min: f32| best.is_some_and(|(bt, _, _)| t_min >= bt);
    // A bracket [fa, fb] around zero, up to the rounding of each end.
    let brackets = |fa: f32, ea: &Eval, fb: f32, eb: &Eval| {
        (fa <= ea.tol() && fb >= -eb.tol()) || (fa >= -ea.tol() && fb <= eb.tol())
    };

    // Cruise at +v_max or -v_max.
    let ep = turn_td(v0, a0, Vel::of(vmax), vf, lim)?;
    let em = turn_td(v0, a0, Vel::of(-vmax), vf, lim)?;
    for (e, v) in [(ep, vmax), (em, -vmax)] {
        let c = (d - e.d) / v;
        if c >= -e.tol() / vmax {
            let c = c.max(0.0);
            let e = Eval { t: e.t + c, d: e.d + c * v, mag: e.mag + fabs(c * v) };
            consider(&mut best, Cand::Turn { vp: Vel::of(v), cruise: c }, e, e.d - d);
        }
    }

    // Turning velocity above both the natural and the final velocity, or below both: from the
    // inner end `vi` (the direct profile), `vp = vi ± u²`. A pulse between nearly equal speeds
    // lasts as √Δv, so in `u` the distance has no infinite slope at `vi`, and its offset from
    // `vi` keeps its precision (see `Vel`).
    let vn = lim.v_nat(v0, a0);
    for (vi, sg, e_far) in [(vn.max(vf), 1.0, ep), (vn.min(vf), -1.0, em)] {
        if !(-vmax..=vmax).contains(&vi) {
            continue;
        }
        let u_far = sqrt(vmax - sg * vi);
        let vp_at = |u: f32| if u < u_far { Vel { base: vi, off: sg * u * u } } else { Vel::of(sg * vmax) };
        let e_in = turn_td(v0, a0, Vel::of(vi), vf, lim)?;
        // The duration grows away from the direct profile: the inner end is the shortest.
        if brackets(e_in.d - d, &e_in, e_far.d - d, &e_far) && !beaten(&best, e_in.t.min(e_far.t)) {
            let mut dist = |u: f32| turn_td(v0, a0, vp_at(u), vf, lim).map(|e| e.d - d);
            let u = solve(&mut dist, 0.0, e_in.d - d, u_far, e_far.d - d, ftol)?;
            let vp = vp_at(u);
            let e = turn_td(v0, a0, vp, vf, lim)?;
            consider(&mut best, Cand::Turn { vp, cruise: 0.0 }, e, e.d - d);
        }
    }

    // Between the direct pulse and "ramp to a = 0, then pulse": one pulse whose acceleration
    // first dips towards zero at full jerk from the start acceleration (UDUD without a turn).
    // The dip's apex must be within ±v_max (a start above v_max dips at v_max, below).
    let s_direct = if vf >= vn { 1.0 } else { -1.0 };
    if lim.smooth() && s_direct * a0 > 0.0 && fabs(vn) <= vmax {
        let an = fabs(a0);
        // An offset from v0: a shallow dip's apex is closer to it than v0's rounding.
        let apex = |a: f32| Vel { base: v0, off: s_direct * ((an - a) * (an + a)) / (2.0 * lim.j) };
        // The largest dip acceleration whose apex is within the speed limit.
        let a_top = if fabs(v0) <= vmax {
            an
        } else {
            let vd = if v0 > 0.0 { vmax } else { -vmax };
            sqrt((an * an - 2.0 * lim.j * fabs(v0 - vd)).max(0.0))
        };
        let eval = |a: f32| dip_td(v0, a0, vf, lim, Dip { v: apex(a), a });
        let (e0, e1) = (eval(0.0)?, eval(a_top)?);
        if brackets(e0.d - d, &e0, e1.d - d, &e1) && !beaten(&best, e0.t.min(e1.t)) {
            let a = solve(&mut |a| eval(a).map(|e| e.d - d), 0.0, e0.d - d, a_top, e1.d - d, ftol)?;
            let e = eval(a)?;
            consider(&mut best, Cand::Dip { v: apex(a), a }, e, e.d - d);
        }
    }

    // Braking from above v_max: one pulse whose deceleration eases off (dips towards a = 0)
    // as it passes ±v_max; a dip to zero is "brake to v_max, cruise", found above.
    if lim.smooth() && (fabs(v0) > vmax || fabs(vn) > vmax) {
        // The pulse's envelope starts at v_nat whenever the start acceleration must first be
        // ramped down (it then carries the speed there), so the limit it crosses while braking
        // is the one on v_nat's side; a start above +v_max can be swept beyond -v_max.
        let sigma = if fabs(vn) > vmax { vn } else { v0 };
        let vd = if sigma > 0.0 { vmax } else { -vmax };
        if let Some((a_lo, a_hi)) = dip_bounds(v0, a0, vf, lim, vd)? {
            let eval = |a: f32| dip_td(v0, a0, vf, lim, Dip { v: Vel::of(vd), a });
            let (e0, e1) = (eval(a_lo)?, eval(a_hi)?);
            if brackets(e0.d - d, &e0, e1.d - d, &e1) && !beaten(&best, e0.t.min(e1.t)) {
                let a = solve(&mut |a| eval(a).map(|e| e.d - d), a_lo, e0.d - d, a_hi, e1.d - d, ftol)?;
                let e = eval(a)?;
                consider(&mut best, Cand::Dip { v: Vel::of(vd), a }, e, e.d - d);
            }
        }
    }

    let (_, cand, eval) = best.ok_or(PlanError::NoSolution)?;
    Ok((cand, eval))
}

/// The profile of the candidate `cand` (evaluated as `eval`) from `start`, moving at `v0` with
/// the acceleration `a0`, to `end`, into `out`; checked to meet it within rounding.
#[inline(never)]
fn assemble_position(
    out: &mut Profile,
    start: State,
    a0: f32,
    cand: Cand,
    eval: Eval,
    lim: &Lim,
    end: State,
) -> Result<(), PlanError> {
    let (v0, vf) = (start.v, end.v);
    let mut segs = [Seg::default(); MAX_PHASES];
    let mut ns = 0usize;
    let mut add = |p: &Pulse| -> Result<(), PlanError> {
        for s in p.iter() {
            *segs.get_mut(ns).ok_or(PlanError::NoSolution)? = *s;
            ns += 1;
        }
        Ok(())
    };
    // The cruise phase (index, exact velocity): it starts from v_max exactly, not from the
    // integrated velocity, so that a long cruise does not accumulate its rounding.
    let mut cruise_at = None;
    // One pulse at a time, in one buffer.
    let mut p = Pulse::EMPTY;
    match cand {
        Cand::Turn { vp, cruise } => {
            pulse(Vel::of(v0), a0, vp, lim, None, &mut p)?;
            add(&p)?;
            if cruise > 0.0 {
                cruise_at = Some((p.n, vp.val()));
                p = Pulse::EMPTY;
                p.push(cruise, 0.0, 0.0)?;
                add(&p)?;
            }
            pulse(vp, 0.0, Vel::of(vf), lim, None, &mut p)?;
            add(&p)?;
        }
        Cand::Dip { v, a } => {
            pulse(Vel::of(v0), a0, Vel::of(vf), lim, Some(Dip { v, a }), &mut p)?;
            add(&p)?;
        }
    }
    build_checked(out, State { a: a0, ..start }, segs.get(..ns).unwrap_or(&[]), cruise_at, end, eval, lim)
}

/// Builds `out` from `segs` and checks that the integrated end meets `end` (the last phase lands
/// on it) to within rounding.
fn build_checked(
    out: &mut Profile,
    start: State,
    segs: &[Seg],
    cruise_at: Option<(usize, f32)>,
    end: State,
    eval: Eval,
    lim: &Lim,
) -> Result<(), PlanError> {
    out.build_into(start, segs, cruise_at, end)?;
    let last = out.eval_end();
    let tol = eval.tol() + 4.0 * f32::EPSILON * fabs(start.p);
    // (The end time of a long profile is rounded: up to a few ulp of the duration at full a.)
    let tol_v = ROUNDING * lim.v + 8.0 * f32::EPSILON * out.duration * lim.acc.max(lim.dec);
    if fabs(last.p - end.p) > tol || fabs(last.v - end.v) > tol_v {
        return Err(PlanError::NoSolution);
    }
    Ok(())
}

fn finite(s: &State) -> bool {
    s.p.is_finite() && s.v.is_finite() && s.a.is_finite()
}

impl Profile {
    /// Plans the fastest move from `start` to `target_p`, arriving with speed `target_v` (≥ 0, in
    /// the direction of the move, i.e. velocity `target_v · sign(target_p − start.p)`; ignored when
    /// `target_p == start.p`) and zero acceleration.
    ///
    /// `start` may be anything finite: moving towards or away from the target, faster than
    /// `v_max`, accelerating beyond `a_max`/`d_max`. The profile first brakes back inside the
    /// limits when it must. Without a jerk limit, `start.a` is ignored (the acceleration may jump).
    ///
    /// ```
    /// use drive_core::motion::scurve::{Limits, Profile, State};
    /// let lim = Limits { v_max: 2.0e4, a_max: 77_440.0, d_max: 77_440.0, jerk: Some(1.0e7) };
    /// // Moving at 15 000 pps away from the target: reverse, then come back to stop on it.
    /// let start = State { p: 1_000.0, v: 15_000.0, a: 0.0 };
    /// let prof = Profile::to_position(start, 0.0, 0.0, &lim).unwrap();
    /// assert_eq!(prof.at(0.0), start);
    /// assert_eq!(prof.at(prof.duration()), State { p: 0.0, v: 0.0, a: 0.0 });
    /// assert!(prof.at(0.25).p > 2_000.0); // it overshoots before returning
    /// ```
    ///
    /// # Errors
    /// [`PlanError::InvalidLimits`], [`PlanError::InvalidState`] or [`PlanError::InvalidTarget`]
    /// for invalid inputs (see [`PlanError`]); [`PlanError::NoSolution`] if the numerical search
    /// fails, which is not expected for inputs of sane magnitude.
    pub fn to_position(start: State, target_p: f32, target_v: f32, lim: &Limits) -> Result<Profile, PlanError> {
        let mut prof = Profile::EMPTY;
        Profile::to_position_into(&mut prof, start, target_p, target_v, lim)?;
        Ok(prof)
    }

    /// [`Profile::to_position`] into `out`, which holds the profile if it succeeds (and is of no
    /// use if it fails): a profile is 340 bytes, and returned by value it would be on a
    /// microcontroller's stack once more in every frame it passes through.
    pub fn to_position_into(
        out: &mut Profile,
        start: State,
        target_p: f32,
        target_v: f32,
        lim: &Limits,
    ) -> Result<(), PlanError> {
        let lim = Lim::new(lim)?;
        if !finite(&start) {
            return Err(PlanError::InvalidState);
        }
        if !(target_p.is_finite() && (0.0..=lim.v).contains(&target_v)) {
            return Err(PlanError::InvalidTarget);
        }
        let d = target_p - start.p;
        if !d.is_finite() {
            return Err(PlanError::InvalidTarget);
        }
        let v0 = start.v;
        let a0 = if lim.smooth() { start.a } else { 0.0 };
        let vf = if d > 0.0 {
            target_v
        } else if d < 0.0 {
            -target_v
        } else {
            0.0
        };
        let end = State { p: target_p, v: vf, a: 0.0 };
        if d == 0.0 && v0 == 0.0 && a0 == 0.0 {
            return out.build_into(start, &[], None, end);
        }

        // The closed form lands within the rounding its root search accepts; built, it may
        // land just beyond: the search then plans it.
        if closed_position(out, start, a0, d, &lim, end) == Ok(true) {
            return Ok(());
        }
        let (cand, eval) = fastest_position(v0, a0, vf, d, &lim)?;
        assemble_position(out, start, a0, cand, eval, &lim, end)
    }

    /// Plans the fastest change from `start` to the velocity `target_v` (signed, |target_v| ≤
    /// `v_max`) with zero acceleration. At [`Profile::duration`] the axis moves at `target_v`;
    /// after it the caller continues at constant velocity (`at` clamps `t` to the duration).
    ///
    /// ```
    /// use drive_core::motion::scurve::{Limits, Profile, State};
    /// let lim = Limits { v_max: 1.0e4, a_max: 5_210.0, d_max: 5_210.0, jerk: None };
    /// // Stop from 5210 pps: exactly one second at d_max, 2605 microsteps.
    /// let prof = Profile::to_velocity(State { p: 0.0, v: 5_210.0, a: 0.0 }, 0.0, &lim).unwrap();
    /// assert!((prof.duration() - 1.0).abs() < 1e-12);
    /// assert!((prof.at(1.0).p - 2_605.0).abs() < 1e-9);
    /// ```
    ///
    /// # Errors
    /// As [`Profile::to_position`]; the target is invalid if it is not finite or |target_v| > `v_max`.
    pub fn to_velocity(start: State, target_v: f32, lim: &Limits) -> Result<Profile, PlanError> {
        let mut prof = Profile::EMPTY;
        Profile::to_velocity_into(&mut prof, start, target_v, lim)?;
        Ok(prof)
    }

    /// [`Profile::to_velocity`] into `out`, as [`Profile::to_position_into`].
    pub fn to_velocity_into(out: &mut Profile, start: State, target_v: f32, lim: &Limits) -> Result<(), PlanError> {
        let lim = Lim::new(lim)?;
        if !finite(&start) {
            return Err(PlanError::InvalidState);
        }
        if !(0.0..=lim.v).contains(&fabs(target_v)) {
            return Err(PlanError::InvalidTarget);
        }
        let a0 = if lim.smooth() { start.a } else { 0.0 };
        let mut p = Pulse::EMPTY;
        pulse(Vel::of(start.v), a0, Vel::of(target_v), &lim, None, &mut p)?;
        let start = State { a: a0, ..start };
        out.build_into(start, p.segs.get(..p.n).unwrap_or(&[]), None, start)?;
        let e = out.eval_end();
        out.end = State { p: e.p, v: target_v, a: 0.0 };
        Ok(())
    }

    /// Precomputes the phase start states into `self`; the phase `cruise.0` (if any) starts at
    /// velocity `cruise.1` exactly.
    fn build_into(
        &mut self,
        start: State,
        segs: &[Seg],
        cruise: Option<(usize, f32)>,
        end: State,
    ) -> Result<(), PlanError> {
        // Every phase beyond the profile's stays zero, as in a new one.
        self.phases = [Phase::ZERO; MAX_PHASES];
        let (mut t, mut p, mut v) = (0.0, start.p, start.v);
        let mut n = 0usize;
        for s in segs {
            if let Some((i, vc)) = cruise
                && i == n
            {
                v = vc;
            }
            let ph = self.phases.get_mut(n).ok_or(PlanError::NoSolution)?;
            *ph = Phase { t0: t, p, v, a2: 0.5 * s.a, j6: s.j / 6.0 };
            n += 1;
            p += s.t * (v + s.t * (0.5 * s.a + s.t * s.j / 6.0));
            v += s.t * (s.a + 0.5 * s.j * s.t);
            t += s.t;
        }
        if n == 0 {
            // A zero-length profile still answers `at(0)` with the start state.
            if let Some(ph) = self.phases.get_mut(0) {
                *ph = Phase { t0: 0.0, p: start.p, v: start.v, a2: 0.5 * start.a, j6: 0.0 };
            }
        }
        (self.n, self.duration, self.end) = (n, t, end);
        if !(t.is_finite() && p.is_finite() && v.is_finite()) {
            return Err(PlanError::NoSolution);
        }
        Ok(())
    }

    /// The state integrated to the end of the last phase (before snapping to the target).
    fn eval_end(&self) -> State {
        match self.n.checked_sub(1).and_then(|i| self.phases.get(i)) {
            Some(ph) => eval(ph, self.duration - ph.t0),
            None => self.at(0.0),
        }
    }

    /// The duration of the profile (s); 0 for a move that has nothing to do.
    pub fn duration(&self) -> f32 {
        self.duration
    }

    /// The phases of constant jerk in order: for each, its start time (s from the profile's
    /// start) and the state there, with the jerk (microsteps/s³) it keeps until the next one.
    ///
    /// ```
    /// use drive_core::motion::scurve::{Limits, Profile, State};
    /// let lim = Limits { v_max: 1_000.0, a_max: 1_000.0, d_max: 1_000.0, jerk: None };
    /// let prof = Profile::to_position(State::default(), 3_000.0, 0.0, &lim).unwrap();
    /// let starts: Vec<f32> = prof.phases().map(|(t0, _, _)| t0).collect();
    /// assert_eq!(starts, [0.0, 1.0, 3.0]);
    /// ```
    pub fn phases(&self) -> impl Iterator<Item = (f32, State, f32)> + '_ {
        let phases = self.phases.get(..self.n).unwrap_or(&[]);
        phases.iter().map(|ph| (ph.t0, State { p: ph.p, v: ph.v, a: 2.0 * ph.a2 }, 6.0 * ph.j6))
    }

    fn phase(&self, t: f32) -> Option<&Phase> {
        let phases = self.phases.get(..self.n.max(1)).unwrap_or(&[]);
        let i = phases.partition_point(|ph| ph.t0 <= t);
        phases.get(i.saturating_sub(1))
    }

    /// The state at time `t` (s) after the start; `t` is clamped to `[0, duration]`. At and after
    /// the duration (and for a NaN `t`) it returns the end state exactly: the target position, the
    /// final velocity and zero acceleration.
    ///
    /// ```
    /// use drive_core::motion::scurve::{Limits, Profile, State};
    /// let lim = Limits { v_max: 1_000.0, a_max: 1_000.0, d_max: 1_000.0, jerk: None };
    /// let prof = Profile::to_position(State::default(), 3_000.0, 0.0, &lim).unwrap();
    /// // 1 s up to 1000 pps (500 steps), 2 s cruise, 1 s down.
    /// assert_eq!(prof.at(0.5), State { p: 125.0, v: 500.0, a: 1_000.0 });
    /// assert_eq!(prof.at(4.0), State { p: 3_000.0, v: 0.0, a: 0.0 });
    /// ```
    pub fn at(&self, t: f32) -> State {
        if t.is_nan() || t >= self.duration {
            return self.end;
        }
        let t = if t > 0.0 { t } else { 0.0 };
        match self.phase(t) {
            Some(ph) => eval(ph, t - ph.t0),
            None => self.end,
        }
    }

    /// The position only at time `t` (the cheap per-tick evaluation: one cubic in Horner form).
    /// Same clamping as [`Profile::at`].
    ///
    /// ```
    /// use drive_core::motion::scurve::{Limits, Profile, State};
    /// let lim = Limits { v_max: 1_000.0, a_max: 1_000.0, d_max: 1_000.0, jerk: None };
    /// let prof = Profile::to_position(State::default(), 3_000.0, 0.0, &lim).unwrap();
    /// assert_eq!(prof.position(2.0), 1_500.0);
    /// ```
    pub fn position(&self, t: f32) -> f32 {
        if t.is_nan() || t >= self.duration {
            return self.end.p;
        }
        let t = if t > 0.0 { t } else { 0.0 };
        match self.phase(t) {
            Some(ph) => {
                let dt = t - ph.t0;
                ph.p + dt * (ph.v + dt * (ph.a2 + dt * ph.j6))
            }
            None => self.end.p,
        }
    }

    /// The position at time `t` split into whole microsteps (rounded down) and a fraction in units
    /// of 2⁻³² microstep, for a step generator that counts integers. Saturates outside the `i64`
    /// range. Same clamping as [`Profile::at`].
    ///
    /// ```
    /// use drive_core::motion::scurve::{Limits, Profile, State};
    /// let lim = Limits { v_max: 1_000.0, a_max: 1_000.0, d_max: 1_000.0, jerk: None };
    /// let start = State { p: -10.0, v: 0.0, a: 0.0 };
    /// let prof = Profile::to_position(start, 2_990.0, 0.0, &lim).unwrap();
    /// assert_eq!(prof.position_q32(0.05), (-9, 1 << 30)); // -10 + 1.25 = -8.75
    /// ```
    pub fn position_q32(&self, t: f32) -> (i64, u32) {
        let p = self.position(t);
        let whole = floor(p);
        let frac = (p - whole) * 4_294_967_296.0;
        (whole as i64, frac as u32)
    }
}

/// Sorts a few numbers (by `f32::total_cmp`, as `sort_unstable_by` would): an insertion sort,
/// for the planner sorts a few dozen at most and the library's sort costs 2 KB of flash.
fn sort_few(xs: &mut [f32]) {
    for i in 1..xs.len() {
        let mut j = i;
        while let Some(pair) = j.checked_sub(1).and_then(|h| xs.get_mut(h..=j)) {
            match pair {
                [a, b] if a.total_cmp(b).is_gt() => pair.swap(0, 1),
                _ => break,
            }
            j -= 1;
        }
    }
}

/// Evaluates a phase `dt` after its start.
fn eval(ph: &Phase, dt: f32) -> State {
    if ph.a2 == 0.0 && ph.j6 == 0.0 {
        // Constant speed, the long part of most moves: the same numbers as below with the zero
        // terms left out (a Cortex-M4F does f32 in software, tens of instructions an operation).
        return State { p: ph.p + dt * ph.v, v: ph.v, a: 0.0 };
    }
    let a = 2.0 * ph.a2 + 6.0 * ph.j6 * dt;
    let v = ph.v + dt * (2.0 * ph.a2 + 3.0 * ph.j6 * dt);
    let p = ph.p + dt * (ph.v + dt * (ph.a2 + dt * ph.j6));
    State { p, v, a }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use super::{Lim, closed_form, search_position, sort_few};
    use crate::motion::scurve::Limits;

    /// The closed form leaves at most 0.1 % of the hunts' plans to the search: the first plan of
    /// `SEARCH_SHARE_N` cases (20 000) of each region, drawn as `tests/profile_scurve.rs`'s
    /// `hunt_case` draws them (S-curves and trapezoids, within the limits and up to twice
    /// beyond). Prints the counts (`--nocapture`).
    #[test]
    fn search_share() {
        let cases = std::env::var("SEARCH_SHARE_N").ok().and_then(|n| n.parse().ok()).unwrap_or(20_000);
        let mut seed = 7u64;
        let mut next = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let log = |x: f32, lo: f32, hi: f32| lo * libm::powf(hi / lo, x);
        let sign = |x: f32| if x < 0.5 { -1.0f32 } else { 1.0 };
        for (smooth, wide) in [(true, false), (true, true), (false, false), (false, true)] {
            let (mut left, mut n) = (0, 0);
            for _ in 0..cases {
                let r: [f32; 16] = core::array::from_fn(|_| next());
                let acc = |x: f32, y: f32, z: f32| {
                    if smooth || x < 0.5 { 5_210.0 + y * (77_440.0 - 5_210.0) } else { log(z, 100.0, 1e6) }
                };
                let a_max = acc(r[0], r[1], r[2]);
                let d_max = if r[3] < 0.5 { a_max } else { acc(r[4], r[5], r[6]) };
                let jerk = Some(a_max.max(d_max) / log(r[7], 1e-3, 1.0)).filter(|_| smooth);
                let v_max = log(r[8], 50.0, 2e5);
                let v0 = sign(r[9]) * r[10] * v_max * if wide { 2.0 } else { 1.0 };
                let a_big = a_max.max(d_max);
                let k = match (r[11] * 4.0) as u32 {
                    0 => 2.0 * r[12],
                    1 => 0.9 + 0.2 * r[12],
                    2 if r[13] < 0.5 => a_max / a_big,
                    2 => 1.0,
                    _ => 0.5 + 1.5 * r[12],
                };
                let a0 = if wide { sign(r[14]) } else { v0.signum() } * k * a_big;
                let v_end = if r[15] < 0.75 { 0.0 } else { r[13] * v_max };
                let d = match wide {
                    false => sign(r[2]) * log(r[6], 1e-3, 10.0),
                    true if r[5] < 0.1 => 0.0,
                    true => sign(r[2]) * log(r[6], 1e-6, 1e3),
                };
                let Ok(lim) = Lim::new(&Limits { v_max, a_max, d_max, jerk }) else { continue };
                let a0 = if lim.smooth() { a0 } else { 0.0 };
                let vf = if d > 0.0 { v_end } else { -v_end };
                n += 1;
                left += usize::from(matches!(closed_form(v0, a0, if d == 0.0 { 0.0 } else { vf }, d, &lim), Ok(None)));
            }
            let (kind, region) = (if smooth { "S-curve" } else { "trapezoid" }, if wide { "wide" } else { "narrow" });
            std::println!("{kind}, {region}: the search plans {left} of {n}");
            assert!(left * 1000 <= n, "{kind}, {region}: the search plans {left} of {n}");
        }
    }

    proptest::proptest! {
        /// Where the closed form answers, the full search finds a profile of the same
        /// duration: the closed form never gives a slower move. It answers every move from
        /// within the limits (from rest, cruising, accelerating, braking); from beyond them (up
        /// to twice the speed and the acceleration), it answers or leaves the move to the
        /// search.
        #[test]
        fn the_closed_form_is_the_fastest_profile(
            d in proptest::prop_oneof![-1e6f32..1e6, -2e3f32..2e3, -10f32..10.0],
            v0 in proptest::prop_oneof![-1.0f32..1.0, proptest::prelude::Just(0.0)],
            a0 in proptest::prop_oneof![-1.0f32..1.0, proptest::prelude::Just(0.0)],
            beyond in proptest::prop_oneof![3 => proptest::prelude::Just(1.0f32), 1 => 1.0f32..2.0],
            vf in proptest::prop_oneof![0.0f32..1.0, proptest::prelude::Just(0.0)],
            v_max in 100.0f32..200_000.0,
            a_max in 1_000.0f32..200_000.0,
            d_max in proptest::option::of(1_000.0f32..200_000.0),
            jerk in proptest::option::of(1e5f32..1e9),
        ) {
            let d_max = d_max.unwrap_or(a_max);
            let Ok(lim) = Lim::new(&Limits { v_max, a_max, d_max, jerk }) else { return Ok(()) };
            // A start within the limits (a speed, an acceleration whose ramp to zero stays within
            // the speed limit), or beyond them by `beyond`; an end speed of the move's direction.
            let v0 = v0 * v_max * beyond;
            let a0 = match (lim.smooth(), beyond > 1.0) {
                (false, _) => 0.0,
                (true, true) => a0 * beyond * lim.acc.max(lim.dec),
                (true, false) => {
                    let room = (lim.v - libm::fabsf(v0)) * 2.0 * lim.j;
                    a0 * lim.acc.min(lim.dec).min(libm::sqrtf(room))
                }
            };
            let vf = if d == 0.0 { 0.0 } else { vf * v_max * d.signum() };
            let found = closed_form(v0, a0, vf, d, &lim);
            if beyond == 1.0 {
                proptest::prop_assert!(matches!(found, Ok(Some(_))), "{found:?}");
            }
            if let Ok(Some((_, fast))) = found {
                let (_, full) = search_position(v0, a0, vf, d, &lim).map_err(|e| proptest::test_runner::TestCaseError::fail(std::format!("{e:?}")))?;
                // Each a sum of phases rounded apart: equal up to rounding.
                proptest::prop_assert!((fast.t - full.t).abs() <= 2.0 * super::ROUNDING * full.t + 1e-6, "{} vs {}", fast.t, full.t);
            }
        }

        /// The planner's small sort orders as the library's does, signed zeros and all.
        #[test]
        fn sort_few_is_the_library_sort(mut xs in proptest::collection::vec(
            proptest::prop_oneof![proptest::num::f32::ANY, proptest::prelude::Just(0.0), proptest::prelude::Just(-0.0)],
            0..40,
        )) {
            let mut expected = xs.clone();
            expected.sort_unstable_by(f32::total_cmp);
            sort_few(&mut xs);
            proptest::prop_assert_eq!(xs.iter().map(|x| x.to_bits()).collect::<Vec<_>>(), expected.iter().map(|x| x.to_bits()).collect::<Vec<_>>());
        }
    }
}
