//! Trajectories as the control tick runs them: pieces of constant jerk sampled on the tick grid
//! and walked by forward differences in integers.
//!
//! The planner ([`super::scurve`]) works in `f64`, once, outside the tick. [`Track::from_profile`]
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
//! use drive_core::motion::track::{Track, Walker};
//! // 1000 microsteps, 1000 pps², 1000 pps: 1 s up, 1 s down (20 000 ticks each).
//! let lim = Limits { v_max: 1_000.0, a_max: 1_000.0, d_max: 1_000.0, jerk: None };
//! let prof = Profile::to_position(State::default(), 1_000.0, 0.0, &lim).unwrap();
//! let track = Track::from_profile(&prof, 5, false).unwrap();
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

/// A trajectory sampled on the control ticks: sample 0 is the tick it is activated on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Track {
    pieces: [Piece; MAX_PIECES],
    n: u8,
    end: End,
}

/// `x` in fixed point: times `scale` (a power of two), truncated, saturating.
fn fixed(x: f64, scale: f64) -> i64 {
    (x * scale) as i64
}

/// 2^40, 2^48, 2^56: the scales of a piece's differences.
const Q40: f64 = 1_099_511_627_776.0;
const Q48: f64 = Q40 * 256.0;
const Q56: f64 = Q48 * 256.0;

impl Track {
    /// A track that stands on `position` from its first tick.
    pub const fn standing(position: i64) -> Self {
        const NONE: Piece = Piece { ticks: 0, frac: 0, whole: 0, d1: 0, d2: 0, d3: 0 };
        Self { pieces: [NONE; MAX_PIECES], n: 0, end: End::Target(position) }
    }

    /// Samples `profile` (positions relative to `anchor`) at the control ticks, its start on
    /// sample 0. A move (`cruise` false) stands on its end position rounded to the microstep; a
    /// speed change (`cruise`) keeps its end speed for ever, or stands where it stopped. `None`
    /// if a phase lasts longer than 2.5 days of ticks.
    pub fn from_profile(profile: &Profile, anchor: i64, cruise: bool) -> Option<Self> {
        let mut track = Self::standing(anchor);
        track.sample(profile, anchor, cruise).then_some(track)
    }

    /// [`Track::from_profile`] into `self`; whether it fits.
    pub fn sample(&mut self, profile: &Profile, anchor: i64, cruise: bool) -> bool {
        let (rate, h) = (f64::from(TICK_HZ), 1.0 / f64::from(TICK_HZ));
        let duration = profile.duration();
        let last = libm::ceil(duration * rate);
        if last.is_nan() || last > LONGEST as f64 {
            return false;
        }
        let end = profile.at(duration);
        self.n = 0;
        let mut phases = profile.phases().peekable();
        while let Some((t0, s, jerk)) = phases.next() {
            let t1 = phases.peek().map_or(duration, |&(t, _, _)| t);
            let (k0, k1) = (libm::ceil(t0 * rate), libm::ceil(t1 * rate).min(last));
            if k1 <= k0 {
                continue;
            }
            let tau = k0 * h - t0;
            let p = s.p + tau * (s.v + tau * (s.a / 2.0 + tau * jerk / 6.0));
            let v = s.v + tau * (s.a + tau * jerk / 2.0);
            let a = s.a + tau * jerk;
            self.push((k1 - k0) as u32, anchor, p, v, a, jerk);
        }
        self.end = match (cruise, end.v != 0.0) {
            (true, true) => {
                let tau = last * h - duration;
                self.push(FOREVER, anchor, end.p + end.v * tau, end.v, 0.0, 0.0);
                End::Cruise
            }
            (true, false) => {
                let floor = libm::floor(end.p);
                End::Rest(anchor.saturating_add(floor as i64), ((end.p - floor) * 4_294_967_296.0) as u32)
            }
            (false, _) => End::Target(anchor.saturating_add(libm::round(end.p) as i64)),
        };
        true
    }

    /// Appends a piece of `ticks` that starts at `p` (relative to `anchor`) with velocity `v`,
    /// acceleration `a` and jerk `j` (per second).
    fn push(&mut self, ticks: u32, anchor: i64, p: f64, v: f64, a: f64, j: f64) {
        let h = 1.0 / f64::from(TICK_HZ);
        // The Taylor coefficients in ticks, then the forward differences at the first tick.
        let (c1, c2, c3) = (v * h, a / 2.0 * h * h, j / 6.0 * h * h * h);
        let floor = libm::floor(p);
        let piece = Piece {
            ticks,
            frac: ((p - floor) * 4_294_967_296.0) as u32,
            whole: anchor.saturating_add(floor as i64),
            d1: fixed(c1 + c2 + c3, Q40),
            d2: fixed(2.0 * c2 + 6.0 * c3, Q48),
            d3: fixed(6.0 * c3, Q56),
        };
        if let Some(slot) = self.pieces.get_mut(usize::from(self.n)) {
            *slot = piece;
            self.n += 1;
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

    /// The state here in `f64`, the position relative to `anchor` (for the planner).
    pub fn state(&self, anchor: i64) -> State {
        const ONE: f64 = 18_446_744_073_709_551_616.0;
        let rate = f64::from(TICK_HZ);
        let per = rate / ONE;
        let rel = self.p - (i128::from(anchor) << 64);
        let (d1, d2, d3) = (self.d1 as f64, self.d2 as f64, self.d3 as f64);
        State { p: rel as f64 / ONE, v: (d1 - d2 / 2.0 + d3 / 3.0) * per, a: (d2 - d3) * per * rate }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::motion::scurve::Limits;

    fn walk(prof: &Profile, cruise: bool, ticks: usize) -> (Track, Walker, f64) {
        let track = Track::from_profile(prof, 0, cruise).unwrap_or(Track::standing(0));
        let mut w = Walker::new(&track);
        let mut worst = 0.0f64;
        for k in 0..ticks {
            let t = k as f64 / f64::from(TICK_HZ);
            if t < prof.duration() {
                let (whole, frac) = w.position();
                let p = whole as f64 + f64::from(frac) / 4_294_967_296.0;
                worst = worst.max((p - prof.position(t)).abs());
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
        let t = 200_000.0 / f64::from(TICK_HZ) - prof.duration();
        let expected = prof.at(prof.duration()).p - 20_000.0 * t;
        let (whole, frac) = w.position();
        assert!((whole as f64 + f64::from(frac) / 4_294_967_296.0 - expected).abs() < 1e-3);
    }
}
