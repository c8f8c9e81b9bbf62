//! The axis: executes one planned segment at a time, a sample at every control tick.
//!
//! Positions are whole microsteps (`i64`) with a fixed-point fraction. A move or speed change is
//! planned in `f32` from the state at the tick it starts on, relative to the whole part of that
//! position, then sampled into a [`Track`] that the tick walks in integers: nothing drifts
//! however far the axis travels, and a move ends exactly on its integer target.

use super::cubic::{Ahead, Cubic, Rates, Walk};
use super::scurve::{Limits, PlanError, Profile, State};
use super::track::{Finish, Track, Walker};
use crate::units::Instant;
use crate::units::TICK_MICROS;
use fixed::types::U0F32;

/// The segment being executed.
// One segment lives in the axis (no heap): the size of the track variant is what it costs.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug)]
enum Segment {
    /// Standing on the anchor.
    Still,
    /// Walking the axis' track; `at` is the tick of the walker's sample.
    Track { walker: Walker, at: Instant },
    /// A stop ramp of closed form ([`Walker::stop_ramp`]), off the track; `at` is the tick of
    /// the walker's sample, `left` the ticks left until it stands.
    Ramp { walker: Walker, at: Instant, left: u32 },
    /// A PVT segment from the anchor, started at the control tick `start`. Evaluated exactly in
    /// integers (walked tick by tick, `walk`); held on its end point until the next segment
    /// replaces it or the run ends.
    Cubic { start: Instant, cubic: Cubic, walk: Walk, rates: Rates },
    /// Following a pulse input from the control tick `start` on: each tick moves the anchor by
    /// the pulses counted ([`Axis::add_pulses`]); `velocity` is their rate, smoothed.
    Follow { start: Instant, velocity: f32 },
}

/// The setpoint of one tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Setpoint {
    /// Whole microsteps.
    pub whole: i64,
    /// The fraction of a microstep beyond `whole`.
    pub fraction: U0F32,
    /// Velocity in microsteps per second.
    pub velocity: f32,
    /// Acceleration in microsteps per second squared.
    pub acceleration: f32,
}

/// One axis of motion.
#[derive(Clone, Copy, Debug)]
pub struct Axis {
    anchor: i64,
    /// The fraction beyond `anchor` standing still, in 2^-32 microstep: where a speed change
    /// to rest stopped.
    rest: u32,
    segment: Segment,
    /// The track of [`Segment::Track`] (kept apart, so that a plan samples into it in place).
    track: Track,
    /// The setpoint of the last tick.
    last: Setpoint,
    /// The time of the last tick: plans start on the tick grid it sets.
    grid: Option<Instant>,
    /// The first piece of a move appended to the track ([`Axis::then_move_to`]), until the walk
    /// reaches it.
    joint: Option<u8>,
    /// The walk has reached the appended move (taken by [`Axis::take_joined`]).
    joined: bool,
    /// Counts the changes of course: every plan, stop, halt, PVT segment and declared position
    /// (not the walk). Two owners of copies of one axis tell by it which of them changed it.
    version: u32,
    /// The frame of the positions: what the declared positions ([`Axis::set_position`]) have
    /// shifted them by since the start, so that an owner that takes a plan made in another
    /// frame moves its last setpoint into it (no step burst).
    frame: i64,
}

/// 2^-32: the weight of a fraction's lowest bit.
const TWO_POW_M32: f32 = 1.0 / 4_294_967_296.0;

/// One tick of a stop ramp with `left` ticks left: its last tick stands where the one before
/// left the walk (as a track's last piece does).
fn ramp_step(walker: &mut Walker, left: &mut u32) {
    if *left > 1 {
        walker.ramp_step();
    }
    *left -= 1;
}

/// Whole control ticks from `start` to `now` (a PVT segment starts on a tick).
fn cubic_tick(start: Instant, now: Instant) -> u64 {
    now.since(start) / TICK_MICROS
}

impl Axis {
    /// An axis standing at `position`.
    pub fn new(position: i64) -> Self {
        Self {
            anchor: position,
            rest: 0,
            segment: Segment::Still,
            track: Track::standing(position),
            last: Setpoint { whole: position, fraction: U0F32::ZERO, velocity: 0.0, acceleration: 0.0 },
            grid: None,
            joint: None,
            joined: false,
            version: 0,
            frame: 0,
        }
    }

    /// The count of changes of course ([`Axis::version`] is bumped by every one).
    pub fn version(&self) -> u32 {
        self.version
    }

    fn changed(&mut self) {
        self.version = self.version.wrapping_add(1);
    }

    /// Whether a move appended to the one under way ([`Axis::then_move_to`]) is yet to be
    /// reached: the course is the same as before until then.
    pub fn appends(&self) -> bool {
        self.joint.is_some()
    }

    /// The time of the last tick (none yet: `None`).
    pub fn last_tick(&self) -> Option<Instant> {
        self.grid
    }

    /// The tick the segment under way is sampled at: a plan's first tick, until a tick walks it.
    /// `None` standing.
    pub fn activation(&self) -> Option<Instant> {
        match self.segment {
            Segment::Still => None,
            Segment::Track { at, .. } | Segment::Ramp { at, .. } => Some(at),
            Segment::Cubic { start, .. } | Segment::Follow { start, .. } => Some(start),
        }
    }

    /// Takes `plan`'s course, planned on a copy of this axis from its state at the plan's first
    /// tick: a motion keeps the setpoint this axis gave last (what moves at the next tick counts
    /// from there); a plan to stand halts this axis where it is if it moves (a stop), or is taken
    /// whole if it stands (a declared position). Whether this axis is now `plan` but for its
    /// last tick (not when it halted).
    pub fn take_plan(&mut self, plan: &Self) -> bool {
        match plan.activation() {
            None if !self.is_still() => {
                self.halt();
                return false;
            }
            None => self.copy_of(plan),
            Some(_) => {
                let (mut last, grid) = (self.last, self.grid);
                // The last setpoint in the plan's frame: a position declared before the plan
                // shifted it there.
                last.whole = last.whole.wrapping_add(plan.frame.wrapping_sub(self.frame));
                self.copy_of(plan);
                (self.last, self.grid) = (last, grid);
            }
        }
        true
    }

    /// Becomes `other`, of whose track only the pieces in use are copied (a move uses 7 of 17).
    fn copy_of(&mut self, other: &Self) {
        self.follow_walk_of(other);
        self.track.copy_from(&other.track);
    }

    /// Takes the last tick's setpoint and time of `other`, an axis that took this one's plan
    /// ([`Axis::take_plan`]) and is otherwise the same.
    pub fn follow_tick_of(&mut self, other: &Self) {
        (self.last, self.grid) = (other.last, other.grid);
    }

    /// Takes `other`'s course and walk but keeps this axis' track: what one owner learns of the
    /// other's axis when both hold the same track (the tick never writes one). Cheaper than a
    /// copy by the track's 700 bytes.
    pub fn follow_walk_of(&mut self, other: &Self) {
        let Self { anchor, rest, segment, track: _, last, grid, joint, joined, version, frame } = *other;
        (self.anchor, self.rest, self.segment, self.last, self.grid) = (anchor, rest, segment, last, grid);
        (self.joint, self.joined, self.version, self.frame) = (joint, joined, version, frame);
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
            Segment::Track { .. } => self.track.target(),
            Segment::Still => Some(self.anchor),
            Segment::Ramp { .. } | Segment::Cubic { .. } | Segment::Follow { .. } => None,
        }
    }

    /// The tick a plan made at `now` starts on: the first on the grid of the ticks that is at or
    /// after `now` and after the last tick (whose setpoint is out already).
    pub fn next_tick(&self, now: Instant) -> Instant {
        match self.grid {
            Some(t) => {
                let late = now.since(t);
                t.plus_micros(late.div_ceil(TICK_MICROS).max(1) * TICK_MICROS)
            }
            None => now,
        }
    }

    /// The whole microsteps of the position at the tick `at` and the state there relative to
    /// them: what a plan that starts on that tick starts from.
    fn rebased(&self, at: Instant) -> (i64, State) {
        match &self.segment {
            Segment::Still => (self.anchor, State { p: self.rest as f32 * TWO_POW_M32, ..State::default() }),
            Segment::Track { walker, at: now } => {
                let track = &self.track;
                let mut w = *walker;
                let mut t = *now;
                while t.plus_micros(TICK_MICROS) <= at && !w.ended(track) {
                    w.step(track);
                    t = t.plus_micros(TICK_MICROS);
                }
                let whole = w.position().0;
                (whole, w.state(whole))
            }
            &Segment::Ramp { walker, at: now, left } => {
                let (mut w, mut t, mut left) = (walker, now, left);
                while t.plus_micros(TICK_MICROS) <= at && left > 0 {
                    ramp_step(&mut w, &mut left);
                    t = t.plus_micros(TICK_MICROS);
                }
                let whole = w.position().0;
                let state = if left > 0 { w.state(whole) } else { w.rest_state(whole) };
                (whole, state)
            }
            Segment::Cubic { start, cubic, rates, .. } => {
                let k = cubic_tick(*start, at);
                let o = cubic.at(k);
                let whole = cubic.p0.saturating_add(o.whole);
                let p = o.fraction as f32 * TWO_POW_M32;
                (whole, State { p, v: rates.velocity(k), a: rates.acceleration(k) })
            }
            // Nothing is planned from a pulse input's course (a stop halts it).
            Segment::Follow { .. } => (self.anchor, State::default()),
        }
    }

    /// Follows the pulse input from the first tick at or after `now` on (standing: else nothing
    /// is done). Returns whether it was done.
    pub fn follow_pulses(&mut self, now: Instant) -> bool {
        if !self.is_still() {
            return false;
        }
        let start = self.next_tick(now);
        self.changed();
        (self.rest, self.joint) = (0, None);
        self.segment = Segment::Follow { start, velocity: 0.0 };
        true
    }

    /// Whether the axis follows the pulse input.
    pub fn follows_pulses(&self) -> bool {
        matches!(self.segment, Segment::Follow { .. })
    }

    /// Moves the setpoint by `pulses` microsteps at the tick `now`, if the axis follows the pulse
    /// input: a control tick calls it before [`Axis::tick`] with what its input counted since the
    /// last one.
    pub fn add_pulses(&mut self, now: Instant, pulses: i16) {
        if let Segment::Follow { start, velocity } = &mut self.segment
            && now >= *start
        {
            self.anchor = self.anchor.saturating_add(i64::from(pulses));
            // A pulse train's rate from whole pulses a tick, smoothed over about 16 ticks.
            let rate = f32::from(pulses) * crate::units::TICK_HZ as f32;
            *velocity += (rate - *velocity) * (1.0 / 16.0);
        }
    }

    /// Follows the PVT segment `cubic` from the control tick `start` on (from wherever the axis
    /// is: the caller joins segments end to start), with what was prepared of it in `ahead`
    /// (the rest is built now, in place: a prepared walk is 290 bytes, each copy of it 240
    /// instructions on the Cortex-M4). `ahead` is empty after.
    pub fn follow(&mut self, start: Instant, cubic: Cubic, ahead: &mut Option<Ahead>) {
        // Built from scratch only if what was prepared is another segment's.
        let prepared = match &mut *ahead {
            Some(a) if a.cubic == cubic => a,
            other => other.insert(Ahead::new(cubic)),
        };
        let (walk, rates) = prepared.built();
        self.segment = Segment::Cubic { start, cubic, walk: *walk, rates: *rates };
        *ahead = None;
        self.changed();
        self.anchor = cubic.p0;
    }

    /// Ends a PVT segment that has arrived at rest: the axis stands exactly on its end point.
    pub fn stand_on_cubic_end(&mut self) {
        if let Segment::Cubic { cubic, .. } = self.segment {
            self.changed();
            (self.anchor, self.rest) = (cubic.p1(), 0);
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

    /// Moves to `target`, arriving at `arrive_v` (the stop speed, from which the drive jumps to
    /// rest), from whatever the axis is doing on the first tick at or after `now`. `depart_v` is
    /// the speed it may jump to from rest (the start speed).
    ///
    /// The move is planned in place (a track is 700 bytes, and a microcontroller's stack is
    /// short): if the plan fails, the axis [halts](Axis::halt). To keep an axis as it was when a
    /// plan fails, plan on a copy and take it only if the plan succeeds.
    pub fn move_to(
        &mut self,
        now: Instant,
        target: i64,
        depart_v: f32,
        arrive_v: f32,
        limits: &Limits,
    ) -> Result<(), PlanError> {
        self.plan_to(now, target, depart_v, arrive_v, false, limits)
    }

    /// Moves through `target` at `pass_v` and keeps that speed beyond it, until the next plan
    /// (a set-point that follows without a stop). Planned in place, as [`Axis::move_to`]: the
    /// axis halts if the plan fails.
    pub fn pass_through(
        &mut self,
        now: Instant,
        target: i64,
        depart_v: f32,
        pass_v: f32,
        limits: &Limits,
    ) -> Result<(), PlanError> {
        self.plan_to(now, target, depart_v, pass_v, true, limits)
    }

    fn plan_to(
        &mut self,
        now: Instant,
        target: i64,
        depart_v: f32,
        arrive_v: f32,
        cruise: bool,
        limits: &Limits,
    ) -> Result<(), PlanError> {
        let at = self.next_tick(now);
        let (anchor, mut start) = self.rebased(at);
        let goal = target.saturating_sub(anchor) as f32;
        let direction = if goal >= start.p { 1.0 } else { -1.0 };
        if self.is_still() && start.p != goal {
            start.v = direction * depart_v.min(limits.v_max);
        }
        // The planner takes the arrival speed as a magnitude, in the direction of the move.
        let arrive_v = arrive_v.min(limits.v_max);
        let finish = if cruise { Finish::Cruise } else { Finish::Stand(target) };
        self.plan_in_place(anchor, at, finish, |profile| {
            Profile::to_position_into(profile, start, goal, arrive_v, limits)
        })
    }

    /// Whether the last planned profile has run its course (standing, or cruising at its speed).
    pub fn settled(&self) -> bool {
        match &self.segment {
            Segment::Track { walker, .. } => walker.cruising(&self.track),
            Segment::Ramp { .. } => false,
            Segment::Still | Segment::Cubic { .. } | Segment::Follow { .. } => true,
        }
    }

    /// Changes speed to `v` (signed) from whatever the axis is doing on the first tick at or
    /// after `now`, then keeps it. From rest it may jump to `depart_v` first. Planned in place,
    /// as [`Axis::move_to`]: the axis halts if the plan fails.
    pub fn run_at(&mut self, now: Instant, v: f32, depart_v: f32, limits: &Limits) -> Result<(), PlanError> {
        let at = self.next_tick(now);
        let (anchor, mut start) = self.rebased(at);
        if self.is_still() && v != 0.0 {
            start.v = libm::copysignf(depart_v.min(libm::fabsf(v)), v);
        }
        self.plan_in_place(anchor, at, Finish::Cruise, |profile| Profile::to_velocity_into(profile, start, v, limits))
    }

    /// Plans a profile (positions relative to `anchor`) and samples it into the axis' own
    /// segment, to start on the tick `at`; halts if the plan fails.
    fn plan_in_place(
        &mut self,
        anchor: i64,
        at: Instant,
        finish: Finish,
        plan: impl FnOnce(&mut Profile) -> Result<(), PlanError>,
    ) -> Result<(), PlanError> {
        let mut profile = Profile::EMPTY;
        self.joint = None;
        self.changed();
        let planned = plan(&mut profile).and_then(|()| {
            if self.track.sample(&profile, anchor, finish) {
                self.segment = Segment::Track { walker: Walker::new(&self.track), at };
                Ok(())
            } else {
                Err(PlanError::NoSolution)
            }
        });
        if planned.is_err() {
            self.halt();
        }
        planned
    }

    /// Appends a move to `target` to the one under way, to start where it ends (at rest on its
    /// target, or passing through it at speed): planned now, so that the control tick only
    /// walks on into it. `depart_v` and `arrive_v` as for [`Axis::move_to`]. Refused (and
    /// nothing changes) unless the axis follows a move it has not finished, or if the two do
    /// not fit in one track. [`Axis::take_joined`] tells when the walk reaches it.
    pub fn then_move_to(
        &mut self,
        target: i64,
        depart_v: f32,
        arrive_v: f32,
        limits: &Limits,
    ) -> Result<(), PlanError> {
        let Segment::Track { walker, .. } = &self.segment else { return Err(PlanError::NoSolution) };
        let (anchor, mut start) = self.track.end_state().ok_or(PlanError::NoSolution)?;
        // A walk already in the final cruise would jump: the caller plans from here instead.
        if walker.cruising(&self.track) {
            return Err(PlanError::NoSolution);
        }
        let goal = target.saturating_sub(anchor) as f32;
        if start.v == 0.0 && start.p != goal {
            start.v = if goal >= start.p { depart_v.min(limits.v_max) } else { -depart_v.min(limits.v_max) };
        }
        let mut profile = Profile::EMPTY;
        Profile::to_position_into(&mut profile, start, goal, arrive_v.min(limits.v_max), limits)?;
        self.joint = Some(self.track.append(&profile, anchor, target).ok_or(PlanError::NoSolution)?);
        self.changed();
        Ok(())
    }

    /// Whether the walk has reached the move appended by [`Axis::then_move_to`] since this was
    /// last asked.
    pub fn take_joined(&mut self) -> bool {
        core::mem::take(&mut self.joined)
    }

    /// Decelerates to rest at `decel` (pps²) from what the axis does, with no jerk limit: a ramp
    /// of closed form that a control tick can afford (the watchdog, a PVT FIFO running dry, a
    /// stop command). Stops at once where the axis is if `decel` is 0.
    pub fn stop_ramp(&mut self, decel: u32) {
        if decel == 0 {
            return self.halt();
        }
        self.joint = None;
        let last = self.last;
        let (mut walker, at) = match self.segment {
            Segment::Still => return,
            // The pulse source's own ramp is the motion: a ramp of the drive's would run on
            // beyond where the source stopped.
            Segment::Follow { .. } => return self.halt(),
            Segment::Track { walker, at } | Segment::Ramp { walker, at, .. } => (walker, at),
            Segment::Cubic { start, .. } => {
                (Walker::moving(last.whole, last.fraction.to_bits(), last.velocity), self.grid.unwrap_or(start))
            }
        };
        let left = walker.stop_ramp(decel);
        self.changed();
        self.segment = Segment::Ramp { walker, at, left };
    }

    /// Stops at once where the axis is (seed 000 0x6053, disable, faults): no ramp.
    pub fn halt(&mut self) {
        // Standing on a whole microstep already, nothing changes (a fault halts every tick).
        if !self.is_still() || self.rest != 0 || self.anchor != self.last.whole {
            self.changed();
        }
        (self.anchor, self.rest) = (self.last.whole, 0);
        self.segment = Segment::Still;
        self.joint = None;
        self.last = Setpoint { fraction: U0F32::ZERO, velocity: 0.0, acceleration: 0.0, ..self.last };
    }

    /// Declares the present position to be `position` (only while still; a moving axis keeps
    /// its course). Returns whether it was done.
    pub fn set_position(&mut self, position: i64) -> bool {
        if !self.is_still() {
            return false;
        }
        self.changed();
        self.frame = self.frame.wrapping_add(position.wrapping_sub(self.last.whole));
        // The track is the planner's: standing, the axis does not read it.
        (self.anchor, self.rest, self.joint, self.joined) = (position, 0, None, false);
        self.last = Setpoint { whole: position, fraction: U0F32::ZERO, velocity: 0.0, acceleration: 0.0 };
        true
    }

    /// The setpoint of the tick at `now` and the whole microsteps moved since the last tick.
    /// Integers only (and `f32` for the rates): the track's next sample, or the PVT walk.
    pub fn tick(&mut self, now: Instant) -> (Setpoint, i64) {
        self.grid = Some(now);
        let (whole, fraction, velocity, acceleration) = match &mut self.segment {
            Segment::Still => (self.anchor, self.rest, 0.0, 0.0),
            Segment::Track { walker, at } => {
                let track = &self.track;
                while at.plus_micros(TICK_MICROS) <= now && !walker.ended(track) {
                    walker.step(track);
                    *at = at.plus_micros(TICK_MICROS);
                }
                if self.joint.is_some_and(|j| walker.piece() >= j) {
                    (self.joint, self.joined) = (None, true);
                }
                let (whole, fraction) = walker.position();
                if walker.ended(track) {
                    // Exactly on the target (or where the speed reached zero): the new anchor.
                    (self.anchor, self.rest) = (whole, fraction);
                    self.segment = Segment::Still;
                    (whole, fraction, 0.0, 0.0)
                } else {
                    (whole, fraction, walker.velocity(), walker.acceleration())
                }
            }
            Segment::Ramp { walker, at, left } => {
                while at.plus_micros(TICK_MICROS) <= now && *left > 0 {
                    ramp_step(walker, left);
                    *at = at.plus_micros(TICK_MICROS);
                }
                let (whole, fraction) = walker.position();
                if *left == 0 {
                    // Where the speed reached zero: the new anchor.
                    (self.anchor, self.rest) = (whole, fraction);
                    self.segment = Segment::Still;
                    (whole, fraction, 0.0, 0.0)
                } else {
                    (whole, fraction, walker.velocity(), walker.acceleration())
                }
            }
            Segment::Cubic { start, cubic, walk, rates, .. } => {
                // Exact: whole microsteps and fraction straight from the integer walk.
                let k = cubic_tick(*start, now);
                let o = walk.at(cubic, k);
                (cubic.p0.saturating_add(o.whole), o.fraction, rates.velocity(k), rates.acceleration(k))
            }
            Segment::Follow { velocity, .. } => (self.anchor, 0, *velocity, 0.0),
        };
        let moved = whole.saturating_sub(self.last.whole);
        self.last = Setpoint { whole, fraction: U0F32::from_bits(fraction), velocity, acceleration };
        (self.last, moved)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// What the control tick does on its own (walk, stop ramps, halts, a declared position)
    /// leaves the planner's track as planned: a plan handed to the tick is never written there.
    #[test]
    fn the_tick_never_writes_the_track() {
        let limits = Limits { v_max: 20_000.0, a_max: 50_000.0, d_max: 50_000.0, jerk: Some(1e6) };
        let mut axis = Axis::new(0);
        let t0 = Instant::from_micros(0);
        assert!(axis.move_to(t0, 100_000, 0.0, 0.0, &limits).is_ok());
        let planned = axis.track;
        let mut now = t0;
        for k in 0..20_000u32 {
            now = now.plus_micros(TICK_MICROS);
            axis.tick(now);
            if k == 5_000 {
                axis.stop_ramp(30_000);
            }
        }
        assert!(axis.is_still(), "the ramp ends at rest");
        axis.halt();
        assert!(axis.set_position(7));
        axis.tick(now.plus_micros(TICK_MICROS));
        assert_eq!(axis.track, planned);
        assert_eq!(axis.setpoint().whole, 7);
    }
}
