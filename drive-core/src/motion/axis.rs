//! The axis: executes one planned segment at a time, evaluated by time at every control tick.
//!
//! Positions are whole microsteps in an `i64` anchor plus an `f64` offset from it that the
//! planner works in. Every re-plan moves the whole part of the present position into the anchor,
//! so the offset stays small and a move ends exactly on its (integer) target however far the
//! axis has travelled: nothing drifts over 2^31 microsteps.

use super::cubic::{Ahead, Cubic, Rates, Walk};
use super::scurve::{Limits, PlanError, Profile, State};
use crate::units::Instant;
use crate::units::TICK_MICROS;
use fixed::types::U0F32;

/// What to do when a profile has run its course.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Then {
    /// A move: stand on the target.
    Stand,
    /// A speed change: keep the speed reached.
    Cruise,
}

/// The segment being executed.
// One segment lives in the axis (no heap): the size of the profile variant is what it costs.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug)]
enum Segment {
    /// Standing on the anchor.
    Still,
    /// Following a profile that started at `start`, positions relative to the anchor.
    Profile { profile: Profile, start: Instant, then: Then },
    /// Constant speed `v` from `start`, where the position was `p0` (relative to the anchor).
    Cruise { start: Instant, p0: f64, v: f64 },
    /// A PVT segment from the anchor, started at the control tick `start`. Evaluated exactly in
    /// integers (walked tick by tick, `walk`); held on its end point until the next segment
    /// replaces it or the run ends. `ahead` is the next segment, prepared while this one runs
    /// (it fits in the size of the profile variant).
    Cubic { start: Instant, cubic: Cubic, walk: Walk, rates: Rates, ahead: Option<Ahead> },
}

/// The setpoint of one tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setpoint {
    /// Whole microsteps.
    pub whole: i64,
    /// The fraction of a microstep beyond `whole`.
    pub fraction: U0F32,
    /// Velocity in microsteps per second.
    pub velocity: f64,
    /// Acceleration in microsteps per second squared.
    pub acceleration: f64,
}

/// One axis of motion.
#[derive(Clone, Copy, Debug)]
pub struct Axis {
    anchor: i64,
    segment: Segment,
    /// The setpoint of the last tick.
    last: Setpoint,
}

/// Seconds from `start` to `now`.
fn seconds(start: Instant, now: Instant) -> f64 {
    now.since(start) as f64 * 1e-6
}

/// 2^-32: the weight of a fraction's lowest bit.
const TWO_POW_M32: f64 = 1.0 / 4_294_967_296.0;

/// Whole control ticks from `start` to `now` (a PVT segment starts on a tick).
fn cubic_tick(start: Instant, now: Instant) -> u64 {
    now.since(start) / TICK_MICROS
}

/// Whole part (floor) and fraction of a position offset; `f64 as i64` saturates, never panics.
fn split(anchor: i64, p: f64) -> (i64, f64) {
    let floor = libm::floor(p);
    (anchor.saturating_add(floor as i64), p - floor)
}

impl Axis {
    /// An axis standing at `position`.
    pub fn new(position: i64) -> Self {
        Self {
            anchor: position,
            segment: Segment::Still,
            last: Setpoint { whole: position, fraction: U0F32::ZERO, velocity: 0.0, acceleration: 0.0 },
        }
    }

    /// Whether the axis is standing still with nothing to do.
    pub fn is_still(&self) -> bool {
        matches!(self.segment, Segment::Still)
    }

    /// The setpoint of the last tick.
    pub fn setpoint(&self) -> Setpoint {
        self.last
    }

    /// Where a move now in progress will stop (its target), if it is a move.
    pub fn target(&self) -> Option<i64> {
        match &self.segment {
            Segment::Profile { profile, then: Then::Stand, .. } => {
                Some(self.anchor.saturating_add(libm::round(profile.at(profile.duration()).p) as i64))
            }
            Segment::Still => Some(self.anchor),
            _ => None,
        }
    }

    /// Position, velocity and acceleration at `now`, relative to the anchor.
    fn state_at(&self, now: Instant) -> State {
        // By reference: a profile is large, and this runs every tick.
        match &self.segment {
            Segment::Still => State { p: 0.0, v: 0.0, a: 0.0 },
            Segment::Profile { profile, start, .. } => profile.at(seconds(*start, now)),
            Segment::Cruise { start, p0, v } => State { p: p0 + v * seconds(*start, now), v: *v, a: 0.0 },
            Segment::Cubic { start, cubic, rates, .. } => {
                let k = cubic_tick(*start, now);
                let o = cubic.at(k);
                let p = o.whole as f64 + f64::from(o.fraction) * TWO_POW_M32;
                State { p, v: rates.velocity(k), a: rates.acceleration(k) }
            }
        }
    }

    /// Follows the PVT segment `cubic` from the control tick `start` on (from wherever the axis
    /// is: the caller joins segments end to start), with what [`Axis::prepare`] built of it.
    pub fn follow(&mut self, start: Instant, cubic: Cubic) {
        let ahead = match self.segment {
            Segment::Cubic { ahead: Some(a), .. } if a.cubic == cubic => a,
            _ => Ahead::new(cubic),
        };
        let (walk, rates) = ahead.finish();
        self.anchor = cubic.p0;
        self.segment = Segment::Cubic { start, cubic, walk, rates, ahead: None };
    }

    /// Whether [`Axis::prepare`] has work to do: the axis follows a PVT segment and the next
    /// one is not built yet.
    pub fn preparing(&self) -> bool {
        matches!(&self.segment, Segment::Cubic { ahead, .. } if !ahead.is_some_and(|a| a.is_built()))
    }

    /// Builds a piece of `next`, the PVT segment that will follow the one running (one 128-bit
    /// division or the rates, see [`Ahead`]), so that its first tick does not build it all.
    /// Nothing happens unless the axis follows a PVT segment.
    pub fn prepare(&mut self, next: Cubic) {
        if let Segment::Cubic { ahead, .. } = &mut self.segment {
            match ahead {
                Some(a) if a.cubic == next => {
                    a.advance();
                }
                _ => *ahead = Some(Ahead::new(next)),
            }
        }
    }

    /// Ends a PVT segment that has arrived at rest: the axis stands exactly on its end point.
    pub fn stand_on_cubic_end(&mut self) {
        if let Segment::Cubic { cubic, .. } = self.segment {
            self.anchor = cubic.p1();
            self.segment = Segment::Still;
        }
    }

    /// The PVT segment being followed and its start tick.
    pub fn cubic(&self) -> Option<(Instant, Cubic)> {
        match &self.segment {
            &Segment::Cubic { start, cubic, .. } => Some((start, cubic)),
            _ => None,
        }
    }

    /// The anchor moved to the whole part of the position at `now`, and the state at `now`
    /// relative to it. Nothing changes: a plan from it commits both only if it succeeds (and
    /// the axis is not copied aside for that: it holds a 680-byte profile, and the planner's
    /// stack on a microcontroller is short).
    fn rebased(&self, now: Instant) -> (i64, State) {
        let s = self.state_at(now);
        let (whole, frac) = split(self.anchor, s.p);
        (whole, State { p: frac, ..s })
    }

    /// Moves to `target`, arriving at `arrive_v` (the stop speed, from which the drive jumps to
    /// rest), from whatever the axis is doing at `now`. `depart_v` is the speed it may jump to
    /// from rest (the start speed).
    ///
    /// The move is planned in place (a profile is 680 bytes, and a microcontroller's stack is
    /// short): if the plan fails, the axis [halts](Axis::halt). To keep an axis as it was when a
    /// plan fails, plan on a copy and take it only if the plan succeeds.
    pub fn move_to(
        &mut self,
        now: Instant,
        target: i64,
        depart_v: f64,
        arrive_v: f64,
        limits: &Limits,
    ) -> Result<(), PlanError> {
        self.plan_to(now, target, depart_v, arrive_v, Then::Stand, limits)
    }

    /// Moves through `target` at `pass_v` and keeps that speed beyond it, until the next plan
    /// (a set-point that follows without a stop). Planned in place, as [`Axis::move_to`]: the
    /// axis halts if the plan fails.
    pub fn pass_through(
        &mut self,
        now: Instant,
        target: i64,
        depart_v: f64,
        pass_v: f64,
        limits: &Limits,
    ) -> Result<(), PlanError> {
        self.plan_to(now, target, depart_v, pass_v, Then::Cruise, limits)
    }

    fn plan_to(
        &mut self,
        now: Instant,
        target: i64,
        depart_v: f64,
        arrive_v: f64,
        then: Then,
        limits: &Limits,
    ) -> Result<(), PlanError> {
        let (anchor, mut start) = self.rebased(now);
        let goal = target.saturating_sub(anchor) as f64;
        let direction = if goal >= start.p { 1.0 } else { -1.0 };
        if self.is_still() && start.p != goal {
            start.v = direction * depart_v.min(limits.v_max);
        }
        // The planner takes the arrival speed as a magnitude, in the direction of the move.
        let arrive_v = arrive_v.min(limits.v_max);
        self.plan_in_place(anchor, now, then, |profile| {
            Profile::to_position_into(profile, start, goal, arrive_v, limits)
        })
    }

    /// Whether the last planned profile has run its course (standing, or cruising at its speed).
    pub fn settled(&self) -> bool {
        !matches!(self.segment, Segment::Profile { .. })
    }

    /// Changes speed to `v` (signed) from whatever the axis is doing at `now`, then keeps it.
    /// From rest it may jump to `depart_v` first. Planned in place, as [`Axis::move_to`]: the
    /// axis halts if the plan fails.
    pub fn run_at(&mut self, now: Instant, v: f64, depart_v: f64, limits: &Limits) -> Result<(), PlanError> {
        let (anchor, mut start) = self.rebased(now);
        if self.is_still() && v != 0.0 {
            start.v = libm::copysign(depart_v.min(libm::fabs(v)), v);
        }
        self.plan_in_place(anchor, now, Then::Cruise, |profile| Profile::to_velocity_into(profile, start, v, limits))
    }

    /// Plans a profile into the axis' own segment, to start at `now` with the anchor moved to
    /// `anchor` (the state the plan starts from is relative to it); halts if the plan fails.
    fn plan_in_place(
        &mut self,
        anchor: i64,
        now: Instant,
        then: Then,
        plan: impl FnOnce(&mut Profile) -> Result<(), PlanError>,
    ) -> Result<(), PlanError> {
        self.segment = Segment::Profile { profile: Profile::EMPTY, start: now, then };
        let planned = match &mut self.segment {
            Segment::Profile { profile, .. } => plan(profile),
            _ => Err(PlanError::NoSolution),
        };
        match planned {
            Ok(()) => self.anchor = anchor,
            Err(_) => self.halt(),
        }
        planned
    }

    /// Stops at once where the axis is (seed 000 0x6053, disable, faults): no ramp.
    pub fn halt(&mut self) {
        self.anchor = self.last.whole;
        self.segment = Segment::Still;
        self.last = Setpoint { fraction: U0F32::ZERO, velocity: 0.0, acceleration: 0.0, ..self.last };
    }

    /// Declares the present position to be `position` (only while still; a moving axis keeps
    /// its course). Returns whether it was done.
    pub fn set_position(&mut self, position: i64) -> bool {
        if !self.is_still() {
            return false;
        }
        *self = Self::new(position);
        true
    }

    /// Evaluates the segment at `now` and returns the setpoint and the whole microsteps moved
    /// since the last tick.
    pub fn tick(&mut self, now: Instant) -> (Setpoint, i64) {
        if let Segment::Cubic { start, cubic, walk, rates, .. } = &mut self.segment {
            // Exact: whole microsteps and fraction straight from the integer walk.
            let k = cubic_tick(*start, now);
            let o = walk.at(cubic, k);
            let whole = cubic.p0.saturating_add(o.whole);
            let moved = whole.saturating_sub(self.last.whole);
            let fraction = U0F32::from_bits(o.fraction);
            self.last = Setpoint { whole, fraction, velocity: rates.velocity(k), acceleration: rates.acceleration(k) };
            return (self.last, moved);
        }
        let s = match &self.segment {
            Segment::Profile { profile, start, then } if seconds(*start, now) >= profile.duration() => {
                let (end, duration, start) = (profile.at(profile.duration()), profile.duration(), *start);
                match *then {
                    Then::Stand => {
                        // Exactly on the target: the whole part is the new anchor.
                        let (whole, _) = split(self.anchor, libm::round(end.p));
                        self.anchor = whole;
                        self.segment = Segment::Still;
                        State { p: 0.0, v: 0.0, a: 0.0 }
                    }
                    Then::Cruise if end.v == 0.0 => {
                        let (whole, frac) = split(self.anchor, end.p);
                        self.anchor = whole;
                        self.segment = Segment::Still;
                        State { p: frac, v: 0.0, a: 0.0 }
                    }
                    Then::Cruise => {
                        // The same line as the profile's end, extrapolated back to its start.
                        self.segment = Segment::Cruise { start, p0: end.p - end.v * duration, v: end.v };
                        self.state_at(now)
                    }
                }
            }
            &Segment::Cruise { start, p0, v } if libm::fabs(p0 + v * seconds(start, now)) > 65536.0 => {
                // Keep the offset small: restart the cruise from here, on a whole microsecond.
                let s = self.state_at(now);
                let (whole, frac) = split(self.anchor, s.p);
                self.anchor = whole;
                self.segment = Segment::Cruise { start: now, p0: frac, v };
                State { p: frac, ..s }
            }
            _ => self.state_at(now),
        };
        let (whole, frac) = split(self.anchor, s.p);
        let moved = whole.saturating_sub(self.last.whole);
        // `saturating_from_num` panics on NaN; a planner fault must not take the drive down.
        let fraction = if frac.is_nan() { U0F32::ZERO } else { U0F32::saturating_from_num(frac) };
        self.last = Setpoint { whole, fraction, velocity: s.v, acceleration: s.a };
        (self.last, moved)
    }
}
