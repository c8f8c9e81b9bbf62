//! The command path's shaping, between the axis' walk and the loops: what the tick does to the
//! setpoint stream before the motor follows it. One stage today, the moving average of the
//! position command ([`MovingAverage`], seed 003's FIR filter); an input shaper would be a
//! second stage of the same form (settings validated off the tick, a state, one `process` a
//! tick), run after it.
//!
//! The moving average of N ticks delays the command by (N − 1)/2 ticks and turns each corner of
//! its velocity into a ramp N ticks long: a master's position steps become motion at a bounded
//! acceleration. It works on the motion only (the axis' `moved` and its fraction), so a
//! position declared (0x600E) shifts the output with the input, and on integers (the position in
//! 1/256 microsteps), so that once the input has stood for N ticks the output stands exactly on
//! it.
//!
//! ```
//! use drive_core::motion::axis::Setpoint;
//! use drive_core::motion::shaping::{MovingAverage, ShapingState};
//! use fixed::types::U0F32;
//! let at = |whole| Setpoint { whole, fraction: U0F32::ZERO, velocity: 0.0, acceleration: 0.0 };
//! let fir = MovingAverage::new(4);
//! let mut state = ShapingState::default();
//! // A step of 8 microsteps comes out as four steps of 2, then stands on it.
//! let mut out = Vec::new();
//! for k in 0..6 {
//!     let (x, moved) = if k == 0 { (at(8), 8) } else { (at(8), 0) };
//!     out.push(fir.process(&mut state, &x, moved).0.whole);
//! }
//! assert_eq!(out, [2, 4, 6, 8, 8, 8]);
//! assert!(state.settled());
//! ```

use fixed::types::U0F32;

use super::axis::Setpoint;

/// The longest moving average, ticks: 25.6 ms at 20 kHz (seed 003's 0x2016 at most).
pub const MAX_TICKS: usize = 512;

/// The fraction of a microstep the filter counts in: 1/256.
const FRACTION_BITS: u32 = 8;

/// The largest movement a tick takes in, 1/256 microsteps (32 microsteps: 640 000 microsteps a
/// second, twice the drive's top speed): more is carried to the next ticks, so that the lag's
/// sum, at most N²/2 of it, stays within 32 bits.
const MAX_DELTA: i32 = 32 << FRACTION_BITS;

/// A moving average of the position command over `ticks` ticks (1: none), validated: what
/// [`MovingAverage::process`] runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MovingAverage {
    ticks: u16,
    /// 2^32 / (256 · ticks): the lag's remainder to a `U0F32` fraction by one multiplication.
    fraction_scale: u32,
}

impl Default for MovingAverage {
    /// None: the command passes as it is.
    fn default() -> Self {
        Self::new(1)
    }
}

impl MovingAverage {
    /// A moving average of `ticks` ticks, within 1 and [`MAX_TICKS`].
    pub fn new(ticks: u16) -> Self {
        let ticks = ticks.clamp(1, MAX_TICKS as u16);
        let fraction_scale = ((1u64 << 32) / (u64::from(ticks) << FRACTION_BITS)) as u32;
        Self { ticks, fraction_scale }
    }

    /// A moving average over `micros` µs at `tick_micros` a tick, to the nearest tick.
    ///
    /// ```
    /// use drive_core::motion::shaping::MovingAverage;
    /// assert_eq!(MovingAverage::over_micros(1000, 50).ticks(), 20);
    /// assert_eq!(MovingAverage::over_micros(25_600, 50).ticks(), 512);
    /// ```
    pub fn over_micros(micros: u32, tick_micros: u32) -> Self {
        let ticks = (micros + tick_micros / 2) / tick_micros.max(1);
        Self::new(ticks.min(MAX_TICKS as u32) as u16)
    }

    /// Its length, ticks.
    pub fn ticks(&self) -> u16 {
        self.ticks
    }

    /// One tick: the setpoint `x` the axis walked to, which `moved` whole microsteps of motion
    /// brought (the rest of its change is a position declared); the shaped setpoint, and the
    /// whole microsteps of motion it moved. A new length is taken once the output stands on
    /// the input, so that no change of it moves the motor.
    pub fn process(&self, state: &mut ShapingState, x: &Setpoint, moved: i64) -> (Setpoint, i64) {
        let fraction = (x.fraction.to_bits() >> (32 - FRACTION_BITS)) as i64;
        let last_fraction = core::mem::replace(&mut state.last_fraction, fraction as u8);
        if state.settled() && state.ticks != self.ticks {
            // Settled, the ring holds no motion: the new length starts from it.
            (state.ticks, state.head) = (self.ticks, 0);
        }
        let n = usize::from(state.ticks.max(1));
        if n == 1 {
            (state.last_whole, state.last_out) = (x.whole, x.whole);
            return (*x, moved);
        }
        // This tick's motion in 1/256 microsteps, with what earlier ticks could not take in.
        let motion = (moved << FRACTION_BITS) + fraction - i64::from(last_fraction) + state.carry;
        let delta = motion.clamp(-i64::from(MAX_DELTA), i64::from(MAX_DELTA)) as i32;
        state.carry = motion - i64::from(delta);
        // Lag · N (1/256 microsteps): N·x − the window's sum of x; it grows by N·Δ and falls by
        // the window's sum of Δ (the last N ticks' motion).
        let head = usize::from(state.head);
        let leaving = state.ring.get(head).copied().unwrap_or(0);
        if let Some(slot) = state.ring.get_mut(head) {
            *slot = delta as i16;
        }
        state.head = if head + 1 >= n { 0 } else { (head + 1) as u16 };
        state.window = state.window + delta - i32::from(leaving);
        state.lag = state.lag + n as i32 * delta - state.window;
        state.quiet = if delta == 0 { state.quiet.saturating_add(1) } else { 0 };
        // The output: x less the lag, lag / (256·N) microsteps as whole and fraction.
        let unit = (n as i32) << FRACTION_BITS;
        let (whole, rest) = (state.lag.div_euclid(unit), state.lag.rem_euclid(unit));
        let lag_fraction = (rest as u32).wrapping_mul(self.scale_for(n));
        let (fraction, borrow) = x.fraction.to_bits().overflowing_sub(lag_fraction);
        let out_whole = x.whole - i64::from(whole) - i64::from(borrow);
        // The motion out: the output's change less the position declared (x's change not moved).
        let declared = x.whole - state.last_whole - moved;
        let out_moved = out_whole - state.last_out - declared;
        (state.last_whole, state.last_out) = (x.whole, out_whole);
        // Its speed, the window's motion over N ticks, and its change this tick.
        let per_s = crate::units::TICK_HZ as f32 / unit as f32;
        let velocity = state.window as f32 * per_s;
        let acceleration = (delta - i32::from(leaving)) as f32 * per_s * crate::units::TICK_HZ as f32;
        let out = Setpoint { whole: out_whole, fraction: U0F32::from_bits(fraction), velocity, acceleration };
        (out, out_moved)
    }

    /// 2^32 / (256·n) for the length `n` the state runs (its own until it settles).
    fn scale_for(&self, n: usize) -> u32 {
        if n == usize::from(self.ticks) { self.fraction_scale } else { Self::new(n as u16).fraction_scale }
    }
}

/// What the moving average remembers from tick to tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ShapingState {
    /// The last ticks' motion, 1/256 microsteps, a ring of the length in force.
    ring: [i16; MAX_TICKS],
    /// Where the next tick's motion goes.
    head: u16,
    /// The length in force, ticks (a new one waits for the output to settle).
    ticks: u16,
    /// The ring's sum.
    window: i32,
    /// The lag · N, 1/256 microsteps.
    lag: i32,
    /// Motion beyond a tick's largest, for the next ticks (a jump of any size: 64 bits).
    carry: i64,
    /// Ticks in a row that took in no motion.
    quiet: u16,
    /// The input's fraction at the last tick, 1/256 microsteps.
    last_fraction: u8,
    /// The input's and the output's whole microsteps at the last tick (for the motion out).
    last_whole: i64,
    last_out: i64,
}

impl Default for ShapingState {
    fn default() -> Self {
        Self {
            ring: [0; MAX_TICKS],
            head: 0,
            ticks: 1,
            window: 0,
            lag: 0,
            carry: 0,
            quiet: u16::MAX,
            last_fraction: 0,
            last_whole: 0,
            last_out: 0,
        }
    }
}

impl ShapingState {
    /// The length in force, ticks (1: none).
    pub fn ticks(&self) -> u16 {
        self.ticks
    }

    /// Whether the output stands on the input: no motion taken in for the length in force
    /// (the ring holds none; the lag is 0 exactly) and none still to take in.
    pub fn settled(&self) -> bool {
        self.quiet >= self.ticks && self.carry == 0
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::vec::Vec;

    use proptest::prelude::*;

    use super::*;

    /// The input `x` microsteps and `fraction` (1/2^32), moved from the last by `moved`.
    fn at(whole: i64, fraction: u32) -> Setpoint {
        Setpoint { whole, fraction: U0F32::from_bits(fraction), velocity: 0.0, acceleration: 0.0 }
    }

    /// The output's position, microsteps.
    fn pos(s: &Setpoint) -> f64 {
        s.whole as f64 + f64::from(s.fraction.to_bits()) / 4_294_967_296.0
    }

    proptest! {
        /// Whatever the motion (steps of up to 30 microsteps a tick, fractions included), the
        /// output stands exactly on the input once the input has stood for N ticks; the whole
        /// microsteps it reports moved add up to its change; it never leaves the range the
        /// input's window spans.
        #[test]
        fn the_output_ends_exactly_on_the_input(
            ticks in 1u16..=512,
            steps in proptest::collection::vec((-30i64..30, any::<u32>()), 1..300),
        ) {
            let fir = MovingAverage::new(ticks);
            let mut st = ShapingState::default();
            let (mut whole, mut last_fraction) = (0i64, 0u32);
            let (mut out_sum, mut out_start) = (0i64, None);
            let mut history: Vec<f64> = std::vec![0.0];
            let run = steps.len() + usize::from(ticks) + 40;
            for k in 0..run {
                let (step, fraction) = steps.get(k).copied().unwrap_or((0, last_fraction));
                // `moved` is the whole microsteps of the motion: the floor's change.
                let before = whole as f64 + f64::from(last_fraction) / 4_294_967_296.0;
                let after = before + step as f64 + (f64::from(fraction) - f64::from(last_fraction)) / 4_294_967_296.0;
                let new_whole = after.floor() as i64;
                let moved = new_whole - whole;
                (whole, last_fraction) = (new_whole, fraction);
                let x = at(whole, fraction);
                let (y, y_moved) = fir.process(&mut st, &x, moved);
                out_start.get_or_insert(y.whole - y_moved);
                out_sum += y_moved;
                history.push(pos(&x));
                let lo = history.iter().rev().take(usize::from(ticks) + 1).copied().fold(f64::MAX, f64::min);
                let hi = history.iter().rev().take(usize::from(ticks) + 1).copied().fold(f64::MIN, f64::max);
                prop_assert!(pos(&y) >= lo - 1.0 / 128.0 && pos(&y) <= hi + 1.0 / 128.0, "{} in {lo}..{hi}", pos(&y));
                prop_assert_eq!(out_start.unwrap_or(0) + out_sum, y.whole);
                if k + 1 == run {
                    // The input's own 1/256 of a microstep: the output stands on it.
                    prop_assert_eq!(y.whole, x.whole);
                    prop_assert_eq!(y.fraction.to_bits() >> 24, x.fraction.to_bits() >> 24);
                    prop_assert!(st.settled());
                }
            }
        }
    }

    #[test]
    fn a_jump_beyond_a_ticks_largest_is_carried_and_ends_exactly() {
        let fir = MovingAverage::new(16);
        let mut st = ShapingState::default();
        let (mut y, mut moved) = fir.process(&mut st, &at(10_000, 0), 10_000);
        for _ in 0..400 {
            let (o, m) = fir.process(&mut st, &at(10_000, 0), 0);
            (y, moved) = (o, moved + m);
        }
        assert_eq!((y.whole, y.fraction.to_bits(), moved), (10_000, 0, 10_000));
        assert!(st.settled());
    }

    #[test]
    fn a_position_declared_passes_through_and_moves_nothing() {
        let fir = MovingAverage::new(10);
        let mut st = ShapingState::default();
        // Moving up 3 a tick for 5 ticks, then 1000 declared (no motion) at once.
        let mut x = 0;
        for _ in 0..5 {
            x += 3;
            let _ = fir.process(&mut st, &at(x, 0), 3);
        }
        let (before, _) = fir.process(&mut st, &at(x, 0), 0);
        let (after, moved) = fir.process(&mut st, &at(x + 1000, 0), 0);
        assert_eq!(moved, after.whole - before.whole - 1000, "only the lag's own motion");
        assert!(after.whole - before.whole - 1000 <= 2);
        for _ in 0..20 {
            let _ = fir.process(&mut st, &at(x + 1000, 0), 0);
        }
        assert_eq!(fir.process(&mut st, &at(x + 1000, 0), 0).0.whole, x + 1000);
    }

    #[test]
    fn a_velocity_corner_becomes_a_ramp_of_the_length() {
        // 10 microsteps a tick from rest: the output's speed rises over 8 ticks, evenly.
        let fir = MovingAverage::new(8);
        let mut st = ShapingState::default();
        let speeds: Vec<f32> = (1..=10).map(|k| fir.process(&mut st, &at(10 * k, 0), 10).0.velocity).collect();
        let per_tick = 10.0 * 20_000.0;
        for (k, v) in speeds.iter().enumerate() {
            let expected = per_tick * ((k + 1).min(8) as f32) / 8.0;
            assert!((v - expected).abs() < 1.0, "tick {k}: {v} against {expected}");
        }
    }

    #[test]
    fn a_new_length_waits_for_the_output_to_settle() {
        let (short, long) = (MovingAverage::new(4), MovingAverage::new(100));
        let mut st = ShapingState::default();
        let _ = short.process(&mut st, &at(8, 0), 8);
        // Asked for 100 ticks while 4 still lag: the 4 run on until settled.
        let outs: Vec<i64> = (0..4).map(|_| long.process(&mut st, &at(8, 0), 0).0.whole).collect();
        assert_eq!(outs, [4, 6, 8, 8]);
        assert_eq!(st.ticks(), 4, "settled only after the fourth tick of no motion");
        let _ = long.process(&mut st, &at(8, 0), 0);
        assert_eq!(st.ticks(), 100);
    }
}
