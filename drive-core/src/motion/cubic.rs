//! PVT segments: the cubic Hermite polynomial between two position-velocity points, evaluated
//! exactly at every control tick, and the compact point table.
//!
//! A segment from `(p0, v0)` to `(p1, v1)` lasting `N` ticks is evaluated at tick `k` as the exact
//! rational number
//!
//! ```text
//! p(k) - p0 = [R·Δ·(3k²N − 2k³) + N·v0·(k³ − 2k²N + kN²) + N·v1·(k³ − k²N)] / (R·N³)
//! ```
//!
//! (`Δ = p1 − p0`, `R` = ticks per second), the Hermite form `h01·Δ + T·(h10·v0 + h11·v1)` with
//! `s = k/N`, `T = N/R`, multiplied out in `i128`. The whole microsteps are the floor of that
//! number and the fraction its remainder, so nothing drifts and `k = N` lands on `p1` exactly.
//! Every segment is evaluated relative to its own integer start point.
//!
//! Bounds that keep the `i128` arithmetic from overflowing: `N ≤ 65535 ms · 20` ticks,
//! `|v| < 2^31`, `|Δ| ≤ 2^40` (clamped; a feasible segment is far below: at most
//! 1.5 · 200 kpps · 65.5 s ≈ 2^24.2). The largest term is then below 2^118.

use crate::control::TICK_HZ;

/// Points the table holds (seed 000 0x6019: up to 1000).
pub const TABLE_SIZE: usize = 1000;
/// The fastest a segment may move anywhere along it, in pps: the manual's top speed (0x6003).
pub const V_MAX: f64 = 200_000.0;
/// Control ticks per millisecond of PVT time.
const TICKS_PER_MS: u64 = TICK_HZ as u64 / 1000;
/// Largest |Δ| the evaluation takes (see the module documentation).
const DELTA_LIMIT: i64 = 1 << 40;

/// One PVT point as the master writes it (0x6027..0x602C).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Point {
    /// Absolute position, microsteps.
    pub position: i32,
    /// Velocity at the point, pps.
    pub velocity: i32,
    /// Time since the previous point, ms (the table stores 16 bits: at most 65.535 s).
    pub time_ms: u16,
}

/// A point as stored: 10 bytes (position, velocity, time, little-endian), so 1000 points take
/// 10 000 bytes of RAM instead of 12 000 for an aligned struct.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Packed([u8; 10]);

impl Packed {
    fn pack(p: Point) -> Self {
        let [a, b, c, d] = p.position.to_le_bytes();
        let [e, f, g, h] = p.velocity.to_le_bytes();
        let [i, j] = p.time_ms.to_le_bytes();
        Self([a, b, c, d, e, f, g, h, i, j])
    }

    fn unpack(self) -> Point {
        let [a, b, c, d, e, f, g, h, i, j] = self.0;
        Point {
            position: i32::from_le_bytes([a, b, c, d]),
            velocity: i32::from_le_bytes([e, f, g, h]),
            time_ms: u16::from_le_bytes([i, j]),
        }
    }
}

/// The PVT point storage: a fixed array of [`TABLE_SIZE`] packed points (no heap). Which slots
/// hold points (a table from 0, or a ring) is kept by the caller.
#[derive(Clone, Debug)]
pub struct Table {
    slots: [Packed; TABLE_SIZE],
}

impl Table {
    /// Every slot empty. A constant, so that a table is built where it is stored: built by a
    /// function it would be a 10 KB stack temporary, more than a microcontroller's stack holds.
    pub const EMPTY: Self = Self { slots: [Packed([0; 10]); TABLE_SIZE] };
}

impl Default for Table {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Table {
    /// The point in slot `i`, if there is such a slot.
    pub fn get(&self, i: usize) -> Option<Point> {
        self.slots.get(i).map(|p| p.unpack())
    }

    /// Stores `p` in slot `i` (nothing happens outside the table).
    pub fn set(&mut self, i: usize, p: Point) {
        if let Some(s) = self.slots.get_mut(i) {
            *s = Packed::pack(p);
        }
    }
}

/// One segment: from an integer start position and velocity to a point, over whole ticks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Cubic {
    /// Start position, microsteps.
    pub p0: i64,
    delta: i64,
    v0: i64,
    v1: i64,
    /// Duration in control ticks.
    n: u64,
}

/// Position within a segment: whole microsteps from its start, and the fraction beyond, in
/// units of 2^-32 microstep.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Offset {
    /// Whole microsteps from the start (the floor).
    pub whole: i64,
    /// The fraction of a microstep beyond `whole`, times 2^32.
    pub fraction: u32,
}

impl Cubic {
    /// The segment from `(p0, v0)` to the point `to`, lasting `to.time_ms`.
    pub fn new(p0: i64, v0: i32, to: Point) -> Self {
        let delta = i64::from(to.position).saturating_sub(p0).clamp(-DELTA_LIMIT, DELTA_LIMIT);
        Self { p0, delta, v0: i64::from(v0), v1: i64::from(to.velocity), n: u64::from(to.time_ms) * TICKS_PER_MS }
    }

    /// The segment between two stored points.
    pub fn between(from: Point, to: Point) -> Self {
        Self::new(i64::from(from.position), from.velocity, to)
    }

    /// Duration in control ticks.
    pub fn ticks(&self) -> u64 {
        self.n
    }

    /// The end position.
    pub fn p1(&self) -> i64 {
        self.p0.saturating_add(self.delta)
    }

    /// The end velocity, pps.
    pub fn v1(&self) -> i64 {
        self.v1
    }

    /// The position at tick `k` (clamped to the segment), exactly: floor and fraction.
    pub fn at(&self, k: u64) -> Offset {
        let n = i128::from(self.n);
        if n == 0 {
            return Offset { whole: self.delta, fraction: 0 };
        }
        let k = i128::from(k.min(self.n));
        let (r, d, v0, v1) = (i128::from(TICK_HZ), i128::from(self.delta), i128::from(self.v0), i128::from(self.v1));
        let (k2, n2) = (k * k, n * n);
        let k3 = k2 * k;
        let num = r * d * (3 * k2 * n - 2 * k3) + n * v0 * (k3 - 2 * k2 * n + k * n2) + n * v1 * (k3 - k2 * n);
        let den = r * n2 * n;
        let (whole, rem) = (num.div_euclid(den), num.rem_euclid(den));
        Offset { whole: whole as i64, fraction: ((rem << 32) / den) as u32 }
    }

    /// Seconds of tick `k` and of the whole segment.
    fn times(&self, k: u64) -> (f64, f64) {
        let t = self.n as f64 / f64::from(TICK_HZ);
        let s = if self.n == 0 { 1.0 } else { k.min(self.n) as f64 / self.n as f64 };
        (s, t)
    }

    /// Velocity at tick `k`, pps.
    pub fn velocity(&self, k: u64) -> f64 {
        let (s, t) = self.times(k);
        if t == 0.0 {
            return self.v1 as f64;
        }
        let (d, v0, v1) = (self.delta as f64, self.v0 as f64, self.v1 as f64);
        d / t * (6.0 * s - 6.0 * s * s) + v0 * (3.0 * s * s - 4.0 * s + 1.0) + v1 * (3.0 * s * s - 2.0 * s)
    }

    /// Acceleration at tick `k`, pps².
    pub fn acceleration(&self, k: u64) -> f64 {
        let (s, t) = self.times(k);
        if t == 0.0 {
            return 0.0;
        }
        let (d, v0, v1) = (self.delta as f64, self.v0 as f64, self.v1 as f64);
        d / (t * t) * (6.0 - 12.0 * s) + v0 / t * (6.0 * s - 4.0) + v1 / t * (6.0 * s - 2.0)
    }

    /// The largest speed anywhere on the segment, pps. The velocity is the quadratic
    /// `a s² + b s + c` in `s`, so it is the larger of the ends and the vertex.
    pub fn peak_speed(&self) -> f64 {
        let (v0, v1) = (self.v0 as f64, self.v1 as f64);
        let ends = libm::fabs(v0).max(libm::fabs(v1));
        let t = self.n as f64 / f64::from(TICK_HZ);
        if t == 0.0 {
            return ends;
        }
        let d = self.delta as f64 / t;
        let (a, b) = (-6.0 * d + 3.0 * v0 + 3.0 * v1, 6.0 * d - 4.0 * v0 - 2.0 * v1);
        if a == 0.0 {
            return ends;
        }
        let s = -b / (2.0 * a);
        if s > 0.0 && s < 1.0 { ends.max(libm::fabs(a * s * s + b * s + v0)) } else { ends }
    }

    /// Whether the motor can follow the segment: no jump (a segment of no time must stay where it
    /// is with the same velocity) and no speed above [`V_MAX`].
    pub fn feasible(&self) -> bool {
        if self.n == 0 {
            return self.delta == 0 && self.v0 == self.v1;
        }
        self.peak_speed() <= V_MAX
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn exact(c: &Cubic, k: u64) -> f64 {
        let o = c.at(k);
        o.whole as f64 + f64::from(o.fraction) / 4294967296.0
    }

    #[test]
    fn ends_exactly_on_both_points() {
        let c = Cubic::new(-5, 300, Point { position: 1234, velocity: -700, time_ms: 37 });
        assert_eq!(c.at(0), Offset { whole: 0, fraction: 0 });
        assert_eq!(c.at(c.ticks()), Offset { whole: 1239, fraction: 0 });
        assert_eq!(c.p1(), 1234);
    }

    #[test]
    fn straight_line_is_linear() {
        // 1000 pps for 10 ms: 10 microsteps, half a microstep every tick.
        let c = Cubic::new(0, 1000, Point { position: 10, velocity: 1000, time_ms: 10 });
        for k in 0..=200 {
            assert!((exact(&c, k) - k as f64 * 0.05).abs() < 1e-9, "tick {k}");
        }
        assert!((c.velocity(77) - 1000.0).abs() < 1e-9);
        assert!(c.acceleration(3).abs() < 1e-9);
    }

    #[test]
    fn packs_into_ten_bytes() {
        let p = Point { position: i32::MIN, velocity: -2, time_ms: 65535 };
        assert_eq!(Packed::pack(p).unpack(), p);
        assert_eq!(core::mem::size_of::<Table>(), 10 * TABLE_SIZE);
    }

    #[test]
    fn feasibility() {
        let zero = Point::default();
        assert!(Cubic::between(zero, Point { position: 0, velocity: 0, time_ms: 0 }).feasible());
        assert!(!Cubic::between(zero, Point { position: 1, velocity: 0, time_ms: 0 }).feasible());
        // 1000 microsteps in 10 ms from rest to rest peaks at 1.5 × 100 kpps.
        let c = Cubic::between(zero, Point { position: 1000, velocity: 0, time_ms: 10 });
        assert!((c.peak_speed() - 150_000.0).abs() < 1e-6);
        assert!(c.feasible());
        assert!(!Cubic::between(zero, Point { position: 1400, velocity: 0, time_ms: 10 }).feasible());
        assert!(!Cubic::between(zero, Point { position: 0, velocity: 200_001, time_ms: 10 }).feasible());
    }

    #[test]
    fn extreme_values_do_not_overflow() {
        let far = Point { position: i32::MAX, velocity: i32::MIN, time_ms: u16::MAX };
        let c = Cubic::new(i64::MIN, i32::MAX, far);
        for k in [0, 1, c.ticks() / 3, c.ticks() - 1, c.ticks(), u64::MAX] {
            let _ = c.at(k);
        }
    }
}
