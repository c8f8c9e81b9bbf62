//! Trajectories as the control tick runs them: pieces of constant jerk sampled on the tick grid
//! and walked by forward differences in integers.
//!
//! The planner ([`super::scurve`]) works in `f32`, once, outside the tick. [`Track::from_profile`]
//! samples its phases at the control ticks into at most [`MAX_PIECES`] pieces, each a start
//! position (whole microsteps and a 32-bit fraction) and three forward differences in fixed
//! point. Walking a piece ([`Walker::step`]) is then three 128-bit additions a tick whatever the
//! phase, with no floating point; a move ends on its integer target exactly, for the track
//! stands there after its last piece.
//!
//! The walker keeps the position and the differences in Q64.64 (`i128`). A piece stores the
//! differences in `i64`: the first in Q24.40, the second in Q16.48, the third in Q8.56. Rounding
//! the third to 2^-57 microstep adds up over a piece of `n` ticks to at most `n³/6 · 2^-57`:
//! 0.001 microstep after 5 s of constant jerk; the first and second add less.
//!
//! ```
//! use drive_core::motion::scurve::{Limits, Profile, State};
//! use drive_core::motion::track::{Finish, Track, Walker};
//! // 1000 microsteps, 1000 pps², 1000 pps: 1 s up, 1 s down (20 000 ticks each).
//! let lim = Limits { v_max: 1_000.0, a_max: 1_000.0, d_max: 1_000.0, jerk: None };
//! let prof = Profile::to_position(State::default(), 1_000.0, 0.0, &lim).unwrap();
//! let track = Track::from_profile(&prof, 5, Finish::Stand(1_005)).unwrap();
//! let mut w = Walker::new(&track);
//! for _ in 0..20_000 {
//!     w.step(&track);
//! }
//! // Half-way: 500 microsteps from the start at 5, at the top speed.
//! assert_eq!(w.position(), (505, 0));
//! assert!((w.velocity() - 1_000.0).abs() < 0.01);
//! assert_eq!(track.target(), Some(1_005));
//! ```

use super::scurve::{MAX_PHASES, Profile, State};
use crate::units::TICK_HZ;

/// The most pieces a track holds: a piece a phase of the profile, and the cruise after it.
pub const MAX_PIECES: usize = MAX_PHASES + 1;

/// The longest piece, in ticks (2.5 days); a piece of [`FOREVER`] ticks never ends.
const LONGEST: u64 = u32::MAX as u64 - 1;
/// The length of a piece that lasts until the track is replaced (a cruise).
const FOREVER: u32 = u32::MAX;

/// One piece of constant jerk: where it starts and its forward differences at its first tick.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Piece {
    /// Ticks it lasts ([`FOREVER`]: until replaced).
    ticks: u32,
    /// The fraction of the start position, in 2^-32 microstep.
    frac: u32,
    /// The whole microsteps of the start position.
    whole: i64,
    /// First difference, Q24.40 microsteps.
    d1: i64,
    /// Second difference, Q16.48.
    d2: i64,
    /// Third difference, Q8.56.
    d3: i64,
}

/// What a track does after its last piece.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum End {
    /// Stand on this position (a move's target).
    Target(i64),
    /// Stand where a speed change to rest stopped: whole microsteps and fraction (2^-32).
    Rest(i64, u32),
    /// Nothing: the last piece lasts until the track is replaced.
    Cruise,
}

/// How a sampled profile ends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Finish {
    /// A move: the track stands on this target (whole microsteps) after its last piece. The
    /// profile ends on it up to the rounding of its `f32` positions (2^-24 of the distance).
    Stand(i64),
    /// A speed change: the end speed is kept for ever, or the track stands where it stopped.
    Cruise,
}

/// A trajectory sampled on the control ticks: sample 0 is the tick it is activated on.
#[derive(Clone, Copy, Debug)]
pub struct Track {
    pieces: [Piece; MAX_PIECES],
    n: u8,
    end: End,
}

/// Two tracks are equal if they walk the same: their pieces in use and their ends.
impl PartialEq for Track {
    fn eq(&self, other: &Self) -> bool {
        self.end == other.end && self.used() == other.used()
    }
}

impl Eq for Track {}

/// 1/6, a multiplication where a division would be a library call on the Cortex-M4.
const SIXTH: f32 = 1.0 / 6.0;

/// `x` in fixed point: times `scale` (a power of two), truncated, saturating. Out of line: a
/// library conversion in four places of the planning.
#[inline(never)]
fn fixed(x: f32, scale: f32) -> i64 {
    (x * scale) as i64
}

/// `v / TICK_HZ` in Q24.40 (a speed's step a tick) to the last bit: the speed times a power
/// of two is exact in `f32`, the odd part of the tick rate divides it in integers. The `f32`
/// product alone would be off by 2^-24 of the speed (a cruise at 4000 pps walking at
/// 3999.9998). Beyond 2^27 pps, as a product.
fn step_q40(v: f32) -> i64 {
    const SHIFT: u32 = TICK_HZ.trailing_zeros();
    const ODD: i64 = (TICK_HZ >> SHIFT) as i64;
    let scaled = v * const { (1u64 << (40 - SHIFT)) as f32 };
    if libm::fabsf(v) < const { (1u64 << 27) as f32 } { (scaled as i64) / ODD } else { fixed(v / TICK_HZ as f32, Q40) }
}

/// 2^40, 2^48, 2^56: the scales of a piece's differences.
const Q40: f32 = 1_099_511_627_776.0;
const Q48: f32 = Q40 * 256.0;
const Q56: f32 = Q48 * 256.0;

impl Track {
    /// A track that stands on `position` from its first tick.
    pub const fn standing(position: i64) -> Self {
        const NONE: Piece = Piece { ticks: 0, frac: 0, whole: 0, d1: 0, d2: 0, d3: 0 };
        Self { pieces: [NONE; MAX_PIECES], n: 0, end: End::Target(position) }
    }

    /// Samples `profile` (positions relative to `anchor`) at the control ticks, its start on
    /// sample 0, to end as `finish` says. `None` if a phase lasts longer than 2.5 days of ticks.
    pub fn from_profile(profile: &Profile, anchor: i64, finish: Finish) -> Option<Self> {
        let mut track = Self::standing(anchor);
        track.sample(profile, anchor, finish).then_some(track)
    }

    /// [`Track::from_profile`] into `self`; whether it fits.
    pub fn sample(&mut self, profile: &Profile, anchor: i64, finish: Finish) -> bool {
        self.n = 0;
        self.sample_after(profile, anchor, finish)
    }

    /// Samples `profile` into the pieces after the present ones (its sample 0 is the tick after
    /// their last); whether it fits (if not, nothing changes).
    fn sample_after(&mut self, profile: &Profile, anchor: i64, finish: Finish) -> bool {
        let (rate, h) = (TICK_HZ as f32, 1.0 / TICK_HZ as f32);
        let duration = profile.duration();
        let last = super::whole::ceil(duration * rate);
        if last.is_nan() || last > LONGEST as f32 {
            return false;
        }
        let (kept, end) = (self.n, profile.at(duration));
        let mut fits = true;
        let mut phases = profile.phases().peekable();
        // Each phase's first tick is the one after the previous phase's last.
        let mut k0 = 0.0;
        while let Some((t0, s, jerk)) = phases.next() {
            let t1 = phases.peek().map_or(duration, |&(t, _, _)| t);
            let k1 = super::whole::ceil(t1 * rate).min(last);
            if k1 > k0 {
                let tau = k0 * h - t0;
                let p = s.p + tau * (s.v + tau * (0.5 * s.a + tau * SIXTH * jerk));
                let v = s.v + tau * (s.a + tau * 0.5 * jerk);
                let a = s.a + tau * jerk;
                fits &= self.push((k1 - k0) as u32, anchor, p, v, a, jerk);
                k0 = k1;
            }
        }
        let end = match (finish, end.v != 0.0) {
            (Finish::Cruise, true) => {
                let tau = last * h - duration;
                fits &= self.push(FOREVER, anchor, end.p + end.v * tau, end.v, 0.0, 0.0);
                End::Cruise
            }
            (Finish::Cruise, false) => {
                let floor = super::whole::floor(end.p);
                End::Rest(anchor.saturating_add(floor as i64), ((end.p - floor) * 4_294_967_296.0) as u32)
            }
            (Finish::Stand(target), _) => End::Target(target),
        };
        if fits {
            self.end = end;
        } else {
            self.n = kept;
        }
        fits
    }

    /// Where a move appended now would start: the whole microsteps and the state relative to
    /// them at the tick after the last piece (a move's target at rest, or the start of the
    /// cruise that ends a pass through a target, which the move replaces). `None` for a
    /// speed change to rest.
    pub fn end_state(&self) -> Option<(i64, State)> {
        match self.end {
            End::Target(p) => Some((p, State::default())),
            End::Cruise => {
                let last = self.piece(self.n.checked_sub(1)?)?;
                let v = last.d1 as f32 / Q40 * TICK_HZ as f32;
                Some((last.whole, State { p: last.frac as f32 / 4_294_967_296.0, v, a: 0.0 }))
            }
            End::Rest(..) => None,
        }
    }

    /// Appends `profile` (a move to `target` from [`Track::end_state`], positions relative to
    /// `anchor`), replacing a final cruise, or one tick after a move's end at rest; the index of
    /// its first piece, or `None` if it does not fit (and nothing changes).
    pub fn append(&mut self, profile: &Profile, anchor: i64, target: i64) -> Option<u8> {
        let kept = self.n;
        match self.end {
            End::Cruise => self.n = self.n.saturating_sub(1),
            // A tick on the target at rest first, as a move that ends and one that starts.
            End::Target(p) => {
                self.push(1, p, 0.0, 0.0, 0.0, 0.0);
            }
            End::Rest(..) => {}
        }
        let joint = self.n;
        if self.sample_after(profile, anchor, Finish::Stand(target)) {
            Some(joint)
        } else {
            self.n = kept;
            None
        }
    }

    /// The number of pieces.
    pub fn pieces(&self) -> u8 {
        self.n
    }

    /// Appends a piece of `ticks` that starts at `p` (relative to `anchor`) with velocity `v`,
    /// acceleration `a` and jerk `j` (per second); whether there was room for it.
    fn push(&mut self, ticks: u32, anchor: i64, p: f32, v: f32, a: f32, j: f32) -> bool {
        const H: f32 = 1.0 / TICK_HZ as f32;
        // The Taylor coefficients in ticks, then the forward differences at the first tick.
        let (c2, c3) = (a * (0.5 * H * H), j * (SIXTH * H * H * H));
        let floor = super::whole::floor(p);
        let piece = Piece {
            ticks,
            frac: ((p - floor) * 4_294_967_296.0) as u32,
            whole: anchor.saturating_add(floor as i64),
            d1: step_q40(v).saturating_add(fixed(c2 + c3, Q40)),
            d2: fixed(2.0 * c2 + 6.0 * c3, Q48),
            d3: fixed(6.0 * c3, Q56),
        };
        match self.pieces.get_mut(usize::from(self.n)) {
            Some(slot) => {
                *slot = piece;
                self.n += 1;
                true
            }
            None => false,
        }
    }

    /// The target of a move: where the track stands after its last piece; `None` if it is a
    /// speed change.
    pub fn target(&self) -> Option<i64> {
        match self.end {
            End::Target(p) => Some(p),
            End::Rest(..) | End::Cruise => None,
        }
    }

    /// The pieces in use.
    /// Becomes `other`, copying only the pieces it uses.
    pub(crate) fn copy_from(&mut self, other: &Self) {
        let used = other.used();
        if let Some(to) = self.pieces.get_mut(..used.len()) {
            to.copy_from_slice(used);
        }
        (self.n, self.end) = (other.n, other.end);
    }

    fn used(&self) -> &[Piece] {
        self.pieces.get(..usize::from(self.n)).unwrap_or(&[])
    }

    fn piece(&self, i: u8) -> Option<&Piece> {
        if i < self.n { self.pieces.get(usize::from(i)) } else { None }
    }
}

/// The position on a [`Track`] at one of its ticks, and how to get to the next.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Walker {
    /// The piece walked; past the last when the track has ended.
    i: u8,
    /// Ticks into the piece.
    j: u32,
    /// Position, Q64.64 microsteps.
    p: i128,
    /// Forward differences at `j`, Q64.64.
    d1: i128,
    d2: i128,
    d3: i128,
}

/// One microstep in Q64.64, as `f32`.
const Q64_ONE: f32 = 18_446_744_073_709_551_616.0;

/// 1 pps² in Q64.64 microsteps a tick squared: 2^64 / 20 kHz².
const PER_TICK_SQUARED: i128 = ((1u128 << 64) / (TICK_HZ as u128 * TICK_HZ as u128)) as i128;

/// `2^-n` as `f32`, for `n < 127`.
const fn two_pow_minus(n: u32) -> f32 {
    f32::from_bits((127 - n) << 23)
}

/// A Q64.64 number as `f32`: its bits from `2^(31 - FRAC)` down to `2^-FRAC` (saturating
/// beyond), then the 32 below them (`FRAC ≤ 32`). Two conversions the FPU makes; the second
/// is of a positive remainder, so a small negative number loses nothing to cancellation.
#[inline]
fn to_f32<const FRAC: u32>(x: i128) -> f32 {
    let high = (x >> (64 - FRAC)).clamp(i128::from(i32::MIN), i128::from(i32::MAX)) as i32;
    let low = (x >> (32 - FRAC)) as u32;
    high as f32 * const { two_pow_minus(FRAC) } + low as f32 * const { two_pow_minus(FRAC + 32) }
}

impl Walker {
    /// At sample 0 of `track`.
    pub fn new(track: &Track) -> Self {
        let mut w = Self { i: 0, j: 0, p: 0, d1: 0, d2: 0, d3: 0 };
        w.load(track);
        w
    }

    /// Starts the piece `i` of `track`, or ends the walk if there is none.
    fn load(&mut self, track: &Track) {
        self.j = 0;
        match track.piece(self.i) {
            Some(pc) => {
                self.p = (i128::from(pc.whole) << 64) | (i128::from(pc.frac) << 32);
                (self.d1, self.d2, self.d3) =
                    (i128::from(pc.d1) << 24, i128::from(pc.d2) << 16, i128::from(pc.d3) << 8);
            }
            None => {
                self.i = track.n;
                (self.d1, self.d2, self.d3) = (0, 0, 0);
                match track.end {
                    End::Target(p) => self.p = i128::from(p) << 64,
                    End::Rest(p, frac) => self.p = (i128::from(p) << 64) | (i128::from(frac) << 32),
                    End::Cruise => {}
                }
            }
        }
    }

    /// A walker standing at `whole` and `fraction` (2^-32) moving at `velocity` (pps, below
    /// 2.5 Mpps), on no track: what a stop ramp starts from when the axis followed no track.
    pub fn moving(whole: i64, fraction: u32, velocity: f32) -> Self {
        let step = (velocity / TICK_HZ as f32 * const { 1u32 << 24 } as f32) as i32;
        let p = (i128::from(whole) << 64) | (i128::from(fraction) << 32);
        Self { i: 0, j: 0, p, d1: i128::from(step) << 40, d2: 0, d3: 0 }
    }

    /// Turns this walker into a ramp from its state to rest at `decel` (pps², above 0) with no
    /// jerk limit, walked by [`Walker::ramp_step`] off any track: the position and the next
    /// tick's step are kept, the speed falls by `decel / 20 kHz` a tick. Returns the ticks the
    /// ramp lasts: after one step fewer it stands. Closed form in integers and `f32`: what a
    /// control tick runs when it must stop on its own (the watchdog, a PVT FIFO running dry),
    /// and it writes no track (a track is the planner's alone).
    ///
    /// ```
    /// use drive_core::motion::scurve::{Limits, Profile, State};
    /// use drive_core::motion::track::{Finish, Track, Walker};
    /// let lim = Limits { v_max: 4_000.0, a_max: 1e5, d_max: 1e5, jerk: None };
    /// let prof = Profile::to_velocity(State::default(), 4_000.0, &lim).unwrap();
    /// let track = Track::from_profile(&prof, 0, Finish::Cruise).unwrap();
    /// let mut w = Walker::new(&track);
    /// for _ in 0..20_000 {
    ///     w.step(&track);
    /// }
    /// // At 4000 pps, stop at 8000 pps²: half a second, 1000 microsteps.
    /// let (from, _) = w.position();
    /// let ticks = w.stop_ramp(8_000);
    /// assert_eq!(ticks, 10_001);
    /// for _ in 1..ticks {
    ///     w.ramp_step();
    /// }
    /// assert!((w.position().0 - from - 1_000).abs() <= 1);
    /// ```
    pub fn stop_ramp(&mut self, decel: u32) -> u32 {
        let rate = TICK_HZ as f32;
        let speed = to_f32::<24>(self.d1).abs() * rate;
        // Ticks to rest: the speed over the deceleration.
        // Steps `k` of the ramp are `v − (k + ½)·decel` a tick: the last is the last not below 0.
        let ticks = (speed / decel.max(1) as f32 * rate + 1.5) as u32;
        let d2 = i128::from(decel) * PER_TICK_SQUARED;
        (self.i, self.j) = (0, 0);
        self.d2 = if self.d1 < 0 { d2 } else { -d2 };
        self.d3 = 0;
        // The first step is the present one, then each smaller by the deceleration.
        self.d1 += self.d2 / 2;
        ticks
    }

    /// To the next tick of a [stop ramp](Walker::stop_ramp).
    #[inline]
    pub fn ramp_step(&mut self) {
        self.p += self.d1;
        self.d1 += self.d2;
    }

    /// To the next tick of `track`.
    #[inline]
    pub fn step(&mut self, track: &Track) {
        let ticks = match track.piece(self.i) {
            Some(pc) => pc.ticks,
            None => return,
        };
        if ticks == FOREVER || self.j + 1 < ticks {
            self.j = self.j.wrapping_add(u32::from(ticks != FOREVER));
            self.p += self.d1;
            self.d1 += self.d2;
            self.d2 += self.d3;
        } else {
            self.i += 1;
            self.load(track);
        }
    }

    /// The index of the piece walked (the number of pieces once the track has ended).
    pub fn piece(&self) -> u8 {
        self.i
    }

    /// Whether the track has ended (it stands on its target).
    pub fn ended(&self, track: &Track) -> bool {
        self.i >= track.n
    }

    /// Whether the walk is in the cruise that ends a speed change.
    pub fn cruising(&self, track: &Track) -> bool {
        track.piece(self.i).is_some_and(|pc| pc.ticks == FOREVER)
    }

    /// Whole microsteps (the floor) and the fraction beyond, in 2^-32 microstep.
    #[inline]
    pub fn position(&self) -> (i64, u32) {
        ((self.p >> 64) as i64, (self.p >> 32) as u32)
    }

    /// Velocity, microsteps a second (`f32`, from the differences: `D1 − D2/2 + D3/3` a tick;
    /// good to 0.002 pps up to 2.5 Mpps).
    pub fn velocity(&self) -> f32 {
        (to_f32::<24>(self.d1) - 0.5 * to_f32::<32>(self.d2) + to_f32::<32>(self.d3) * (1.0 / 3.0)) * TICK_HZ as f32
    }

    /// Acceleration, microsteps a second squared (`D2 − D3` a tick squared; good to 0.1 pps²
    /// up to 2·10^8 pps²).
    pub fn acceleration(&self) -> f32 {
        let rate = TICK_HZ as f32;
        to_f32::<32>(self.d2 - self.d3) * rate * rate
    }

    /// The state here in `f32`, the position relative to `anchor` (for the planner).
    pub fn state(&self, anchor: i64) -> State {
        let per = TICK_HZ as f32 / Q64_ONE;
        let (d1, d2, d3) = (self.d1 as f32, self.d2 as f32, self.d3 as f32);
        State { v: (d1 - d2 / 2.0 + d3 / 3.0) * per, a: (d2 - d3) * per * TICK_HZ as f32, ..self.rest_state(anchor) }
    }

    /// [`Walker::state`] standing: the position, no speed (a stop ramp that has ended).
    pub fn rest_state(&self, anchor: i64) -> State {
        let rel = self.p - (i128::from(anchor) << 64);
        State { p: rel as f32 / Q64_ONE, ..State::default() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::scurve::Limits;

    fn walk(prof: &Profile, cruise: bool, ticks: usize) -> (Track, Walker, f32) {
        let finish =
            if cruise { Finish::Cruise } else { Finish::Stand(libm::roundf(prof.at(prof.duration()).p) as i64) };
        let track = Track::from_profile(prof, 0, finish).unwrap_or(Track::standing(0));
        let mut w = Walker::new(&track);
        let (mut worst, mut reach) = (0.0f32, 1.0f32);
        for k in 0..ticks {
            let t = k as f32 / TICK_HZ as f32;
            if t < prof.duration() {
                let (whole, frac) = w.position();
                // Beyond the rounding of the profile's own `f32` positions, as far as they reach.
                let p = whole as f64 + f64::from(frac) / 4_294_967_296.0;
                let q = prof.position(t);
                reach = reach.max(q.abs());
                let off = (p - f64::from(q)).abs() - 8.0 * f64::from(f32::EPSILON * reach);
                worst = worst.max(off as f32);
            }
            w.step(&track);
        }
        (track, w, worst)
    }

    #[test]
    fn an_s_curve_walks_on_its_profile_and_ends_on_target() {
        let lim = Limits { v_max: 32_000.0, a_max: 77_440.0, d_max: 5_210.0, jerk: Some(7.7e6) };
        let start = State { p: 0.25, v: 0.0, a: 0.0 };
        let prof = Profile::to_position(start, 100_000.0, 0.0, &lim).unwrap_or(Profile::EMPTY);
        let (track, w, worst) = walk(&prof, false, 400_000);
        assert!(worst < 1e-4, "{worst}");
        assert!(w.ended(&track));
        assert_eq!(w.position(), (100_000, 0));
    }

    #[test]
    fn a_speed_change_cruises_on() {
        let lim = Limits { v_max: 50_000.0, a_max: 10_000.0, d_max: 10_000.0, jerk: Some(1e6) };
        let prof = Profile::to_velocity(State::default(), -20_000.0, &lim).unwrap_or(Profile::EMPTY);
        let (track, w, worst) = walk(&prof, true, 200_000);
        assert!(worst < 1e-4, "{worst}");
        assert!(w.cruising(&track));
        assert!((w.velocity() + 20_000.0).abs() < 1e-2);
        // 10 s at -20 kpps from the ramp's end: the position follows the line exactly.
        let t = 200_000.0 / TICK_HZ as f32 - prof.duration();
        let expected = prof.at(prof.duration()).p - 20_000.0 * t;
        let (whole, frac) = w.position();
        let off = whole as f64 + f64::from(frac) / 4_294_967_296.0 - f64::from(expected);
        assert!(off.abs() < 1e-3 + 4.0 * f64::from(f32::EPSILON * expected.abs()), "{off}");
    }

    #[test]
    fn an_appended_move_starts_a_tick_after_the_first_stands_on_its_target() {
        let lim = Limits { v_max: 10_000.0, a_max: 100_000.0, d_max: 100_000.0, jerk: None };
        let first = Profile::to_position(State::default(), 2_000.0, 0.0, &lim).unwrap_or(Profile::EMPTY);
        let mut track = Track::from_profile(&first, 0, Finish::Stand(2_000)).unwrap_or(Track::standing(0));
        let (anchor, start) = track.end_state().unwrap_or_default();
        assert_eq!((anchor, start), (2_000, State::default()));
        let second = Profile::to_position(start, -500.0, 0.0, &lim).unwrap_or(Profile::EMPTY);
        let joint = track.append(&second, anchor, 1_500);
        assert_eq!(joint, Some(4), "three pieces of the first move, its tick at rest");
        let mut w = Walker::new(&track);
        let mut at_rest_on_target = 0;
        while !w.ended(&track) {
            if w.position() == (2_000, 0) && w.velocity() == 0.0 {
                at_rest_on_target += 1;
            }
            w.step(&track);
        }
        assert_eq!(at_rest_on_target, 2, "its last sample and the tick at rest");
        assert_eq!(w.position(), (1_500, 0));
        // No room for a third: nothing changes.
        let many = Limits { jerk: Some(1e6), ..lim };
        let mut refused = false;
        for target in [9_000.0, 0.0, 9_000.0] {
            let before = track;
            let (anchor, start) = track.end_state().unwrap_or_default();
            let p = Profile::to_position(start, target - anchor as f32, 0.0, &many).unwrap_or(Profile::EMPTY);
            if track.append(&p, anchor, target as i64).is_none() {
                assert_eq!(track, before);
                refused = true;
                break;
            }
        }
        assert!(refused, "three more S-curves fitted in 17 pieces");
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]

        /// Any move from any state: the walk stays on the planned profile at every tick and
        /// ends exactly on the (rounded) target.
        #[test]
        fn the_walk_follows_any_profile(
            p0 in 0.0f32..1.0,
            v0 in -20_000.0f32..20_000.0,
            a0 in -50_000.0f32..50_000.0,
            target in -30_000i64..30_000,
            v_max in 1_000.0f32..40_000.0,
            a_max in 20_000.0f32..200_000.0,
            d_max in 20_000.0f32..200_000.0,
            jerk in proptest::option::of(1e6f32..1e8),
        ) {
            let lim = Limits { v_max, a_max, d_max, jerk };
            let start = State { p: p0, v: v0, a: if jerk.is_some() { a0 } else { 0.0 } };
            let Ok(prof) = Profile::to_position(start, target as f32, 0.0, &lim) else {
                return Ok(());
            };
            let ticks = (prof.duration() * TICK_HZ as f32) as usize + 2;
            proptest::prop_assume!(ticks < 400_000);
            let (track, w, worst) = walk(&prof, false, ticks);
            proptest::prop_assert!(worst < 1e-3, "{}", worst);
            proptest::prop_assert!(w.ended(&track));
            proptest::prop_assert_eq!(w.position(), (target, 0));
        }
    }
}
