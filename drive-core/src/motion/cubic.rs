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

use crate::units::TICK_HZ;
use core::sync::atomic::{AtomicU8, Ordering};

/// Points the table holds (seed 000 0x6019: up to 1000).
pub const TABLE_SIZE: usize = 1000;
/// The fastest a segment may move anywhere along it, in pps: the manual's top speed (0x6003).
pub const V_MAX: f32 = 200_000.0;
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

/// The largest speed a stored point keeps, pps: 24 bits of velocity. The drive stores no point
/// above [`V_MAX`] (a push beyond it is refused), far below this.
pub const V_STORED: i32 = (1 << 23) - 1;

/// A point as stored: 9 bytes (position, velocity in 24 bits, time; little-endian), so 1000
/// points take 9 000 bytes of RAM instead of 12 000 for an aligned struct.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Packed([u8; 9]);

impl Packed {
    fn pack(p: Point) -> Self {
        let [a, b, c, d] = p.position.to_le_bytes();
        let [e, f, g, _] = p.velocity.clamp(-V_STORED, V_STORED).to_le_bytes();
        let [i, j] = p.time_ms.to_le_bytes();
        Self([a, b, c, d, e, f, g, i, j])
    }

    fn unpack(self) -> Point {
        let [a, b, c, d, e, f, g, i, j] = self.0;
        Point {
            position: i32::from_le_bytes([a, b, c, d]),
            // Sign-extended from 24 bits.
            velocity: i32::from_le_bytes([0, e, f, g]) >> 8,
            time_ms: u16::from_le_bytes([i, j]),
        }
    }
}

/// The PVT point storage: a fixed array of [`TABLE_SIZE`] packed points (no heap). Which slots
/// hold points (a table from 0, or a ring) is kept by the caller.
///
/// Its bytes are atomic, so that the bus side may store a point through `&Table` while the
/// control tick reads another: a microcontroller shares one table between the two, and a
/// point is published by the handoff that tells the tick it exists (its release and acquire
/// order the bytes).
#[derive(Debug)]
pub struct Table {
    slots: [[AtomicU8; 9]; TABLE_SIZE],
}

impl Table {
    /// Every slot empty. A `const fn`, so that a table is built where it is stored (a static):
    /// built at run time it would be a 9 KB stack temporary, more than a microcontroller's stack
    /// holds.
    pub const fn new() -> Self {
        Self { slots: [const { [const { AtomicU8::new(0) }; 9] }; TABLE_SIZE] }
    }
}

impl Default for Table {
    fn default() -> Self {
        Self::new()
    }
}

impl Clone for Table {
    fn clone(&self) -> Self {
        let t = Self::new();
        for (i, p) in (0..TABLE_SIZE).filter_map(|i| self.get(i).map(|p| (i, p))) {
            t.set(i, p);
        }
        t
    }
}

impl Table {
    /// The point in slot `i`, if there is such a slot.
    pub fn get(&self, i: usize) -> Option<Point> {
        self.slots.get(i).map(|s| Packed(s.each_ref().map(|b| b.load(Ordering::Relaxed))).unpack())
    }

    /// Stores `p` in slot `i` (nothing happens outside the table).
    pub fn set(&self, i: usize, p: Point) {
        if let Some(s) = self.slots.get(i) {
            for (b, v) in s.iter().zip(Packed::pack(p).0) {
                b.store(v, Ordering::Relaxed);
            }
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
    /// The segment from `(p0, v0)` to the point `to`, lasting `to.time_ms`. Out of line: its
    /// 64-bit clamp is in six callers, all planning.
    #[inline(never)]
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
        if self.n == 0 {
            return Offset { whole: self.delta, fraction: 0 };
        }
        let den = self.den();
        let (whole, rem) = div_floor(self.num(k.min(self.n)), den);
        Offset { whole: whole as i64, fraction: ((rem << 32) / den.value) as u32 }
    }

    /// The numerator of the position at tick `k` over [`Cubic::den`] (module documentation). `k`
    /// may run a few ticks past the end: the bounds hold up to `N + 3`.
    fn num(&self, k: u64) -> i128 {
        let n = i128::from(self.n);
        let k = i128::from(k);
        let (r, d, v0, v1) = (i128::from(TICK_HZ), i128::from(self.delta), i128::from(self.v0), i128::from(self.v1));
        let (k2, n2) = (k * k, n * n);
        let k3 = k2 * k;
        r * d * (3 * k2 * n - 2 * k3) + n * v0 * (k3 - 2 * k2 * n + k * n2) + n * v1 * (k3 - k2 * n)
    }

    /// The numerator's coefficients `[A, B, C]`: `num(k) = A·k³ + B·k² + C·k`.
    fn coefficients(&self) -> [i128; 3] {
        let n = i128::from(self.n);
        let (r, d, v0, v1) = (i128::from(TICK_HZ), i128::from(self.delta), i128::from(self.v0), i128::from(self.v1));
        [n * (v0 + v1) - 2 * r * d, 3 * r * d * n - n * n * (2 * v0 + v1), n * n * n * v0]
    }

    /// The denominator of the position, `R·N³` (positive for a segment of some time). Out of
    /// line: a 128-bit product in four callers, each once a segment.
    #[inline(never)]
    fn den(&self) -> Den {
        let n = i128::from(self.n);
        Den { value: i128::from(TICK_HZ) * n * n * n, n: self.n }
    }

    /// The velocity and acceleration as polynomials in the segment's time, in `f32` (the
    /// control tick builds and evaluates them on the FPU).
    pub fn rates(&self) -> Rates {
        // Velocities are within ±2^31 by construction, Δ of a feasible segment far below.
        let f = |x: i64| x.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32 as f32;
        let (v0, v1) = (f(self.v0), f(self.v1));
        if self.n == 0 {
            return Rates { n: 0, per_tick: 0.0, v0: v1, v1, b: 0.0, a: 0.0, acc0: 0.0, acc1: 0.0 };
        }
        let per_tick = 1.0 / self.n.min(u64::from(u32::MAX)) as u32 as f32;
        let per_second = TICK_HZ as f32 * per_tick;
        let d = f(self.delta) * per_second;
        let (a, b) = (3.0 * v0 + 3.0 * v1 - 6.0 * d, 6.0 * d - 4.0 * v0 - 2.0 * v1);
        Rates { n: self.n, per_tick, v0, v1, b, a, acc0: b * per_second, acc1: 2.0 * a * per_second }
    }

    /// Velocity at tick `k`, pps: [`Rates::velocity`].
    pub fn velocity(&self, k: u64) -> f32 {
        self.rates().velocity(k)
    }

    /// Acceleration at tick `k`, pps²: [`Rates::acceleration`].
    pub fn acceleration(&self, k: u64) -> f32 {
        self.rates().acceleration(k)
    }

    /// The largest speed anywhere on the segment, pps. The velocity is the quadratic
    /// `a s² + b s + c` in `s`, so it is the larger of the ends and the vertex.
    pub fn peak_speed(&self) -> f32 {
        let (v0, v1) = (self.v0 as f32, self.v1 as f32);
        let ends = libm::fabsf(v0).max(libm::fabsf(v1));
        if self.n == 0 {
            return ends;
        }
        let d = self.delta as f32 * TICK_HZ as f32 / self.n as f32;
        let (a, b) = (3.0 * v0 + 3.0 * v1 - 6.0 * d, 6.0 * d - 4.0 * v0 - 2.0 * v1);
        if a == 0.0 {
            return ends;
        }
        let s = -b / (2.0 * a);
        if s > 0.0 && s < 1.0 { ends.max(libm::fabsf(a * s * s + b * s + v0)) } else { ends }
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

/// A segment's velocity `v0 + s·(b + s·a)` and acceleration `acc0 + s·acc1` at `s = k/N`
/// (the derivatives of the Hermite cubic), their coefficients computed once a segment so that a
/// tick evaluates two short polynomials. A segment of no time has its end velocity throughout.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rates {
    /// The segment's ticks, `N`.
    n: u64,
    /// `1/N`: the share of the segment a tick is.
    per_tick: f32,
    v0: f32,
    v1: f32,
    b: f32,
    a: f32,
    acc0: f32,
    acc1: f32,
}

impl Rates {
    /// The share of the segment at tick `k`, in [0, 1]; `None` for a segment of no time.
    fn share(&self, k: u64) -> Option<f32> {
        match self.n {
            0 => None,
            n if k >= n => Some(1.0),
            // Below `N`, which fits in 32 bits: the FPU converts it.
            _ => Some(k as u32 as f32 * self.per_tick),
        }
    }

    /// Velocity at tick `k`, pps: exactly the points' velocities at both ends.
    ///
    /// ```
    /// use drive_core::motion::cubic::{Cubic, Point};
    /// // From rest to rest, 1000 microsteps in 10 ms (200 ticks): 150 kpps half-way.
    /// let c = Cubic::new(0, 0, Point { position: 1000, velocity: 0, time_ms: 10 });
    /// let r = c.rates();
    /// assert_eq!((r.velocity(0), r.velocity(100), r.velocity(200)), (0.0, 150_000.0, 0.0));
    /// ```
    pub fn velocity(&self, k: u64) -> f32 {
        match self.share(k) {
            None => self.v1,
            Some(s) if s >= 1.0 => self.v1,
            Some(s) => self.v0 + s * (self.b + s * self.a),
        }
    }

    /// Acceleration at tick `k`, pps².
    pub fn acceleration(&self, k: u64) -> f32 {
        self.share(k).map_or(0.0, |s| self.acc0 + s * self.acc1)
    }
}

/// `q·den + r` with `0 ≤ r < den`: an exact rational over a fixed denominator, added to without
/// dividing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Mixed {
    q: i128,
    r: i128,
}

impl Mixed {
    /// `x·2^32 / den` (`den > 0`, below 2^95). One division when `x·2^32` fits in `i128`, as it
    /// does for any segment shorter than about 20 s; else `x = a·den + b`, then
    /// `b·2^32 = c·den + e` (the same quotient and remainder), so no product exceeds `den·2^32`.
    fn scaled(x: i128, den: Den) -> Self {
        if x.unsigned_abs() < 1 << 94 {
            let (q, r) = div_floor(x << 32, den);
            return Self { q, r };
        }
        let (a, b) = div_floor(x, den);
        let (c, e) = div_floor(b << 32, den);
        Self { q: (a << 32) + c, r: e }
    }

    /// `x·2^32 / den` from `x = a·den + b` (`(a, b)`): the remainder's fraction the second of
    /// [`Mixed::scaled`]'s two divisions.
    fn from_whole((a, b): (i128, i128), den: Den) -> Self {
        let (c, e) = div_floor(b << 32, den);
        Self { q: (a << 32) + c, r: e }
    }

    /// Adds `o`, both over `den`.
    fn add(&mut self, o: Mixed, den: Den) {
        let den = den.value;
        self.q += o.q;
        self.r += o.r;
        if self.r >= den {
            self.r -= den;
            self.q += 1;
        }
    }
}

/// A segment's denominator `R·N³` with its `N`, which it is divided through: `R·N³` is a product
/// of numbers under 2^32, so a division by it is divisions of 32-bit digits by 32-bit divisors,
/// each two of the Cortex-M4's own 32-bit divisions ([`div_digit`]), where the library's 128-bit
/// division works a bit at a time (the control tick prepares segments with it, see [`Ahead`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Den {
    /// `R·N³`; 1 for a segment of no time.
    value: i128,
    /// `N`, ticks; 0 for a segment of no time.
    n: u64,
}

impl Den {
    /// The denominator of a segment of no time, which nothing is divided by.
    const UNIT: Den = Den { value: 1, n: 0 };
}

/// Floor division by `den` with its remainder in `[0, den)`: `x` divided by `R` and by `N` three
/// times, the factors multiplied together while their product stays under 2^32 (for a segment
/// under 3.2 s, two divisions: by `R·N` and by `N²`); floor divisions by positive numbers compose.
fn div_floor(x: i128, den: Den) -> (i128, i128) {
    if den.n == 0 {
        return (x, 0);
    }
    let mut q = x;
    let mut acc = u64::from(TICK_HZ);
    for _ in 0..3 {
        let product = acc * den.n;
        if product <= u64::from(u32::MAX) {
            acc = product;
        } else {
            q = floor_div_u32(q, acc as u32);
            acc = den.n;
        }
    }
    q = floor_div_u32(q, acc as u32);
    (q, x - q * den.value)
}

/// `floor(x / d)`, `d > 0`.
fn floor_div_u32(x: i128, d: u32) -> i128 {
    let (q, r) = div_u32(x.unsigned_abs(), d);
    // |x| / d ≤ |x| ≤ 2^127: the negations wrap only at i128::MIN / 1, which they give back.
    let q = q as i128;
    if x >= 0 {
        q
    } else if r == 0 {
        q.wrapping_neg()
    } else {
        q.wrapping_neg().wrapping_sub(1)
    }
}

/// `m / d` and its remainder, `d > 0`, a 32-bit digit at a time from the top (the digits
/// taken apart and put together by constant shifts: registers, where a loop's variable shifts of
/// a `u128` are library calls).
fn div_u32(m: u128, d: u32) -> (u128, u32) {
    let (q3, r) = div_digit(0, (m >> 96) as u32, d);
    let (q2, r) = div_digit(r, (m >> 64) as u32, d);
    let (q1, r) = div_digit(r, (m >> 32) as u32, d);
    let (q0, r) = div_digit(r, m as u32, d);
    let high = (u64::from(q3) << 32) | u64::from(q2);
    let low = (u64::from(q1) << 32) | u64::from(q0);
    ((u128::from(high) << 64) | u128::from(low), r)
}

/// `(hi·2^32 + lo) / d` and its remainder for `hi < d` (the quotient fits in 32 bits), by two
/// 16-bit digits, each estimated with a 32-bit division by the divisor's normalised top half
/// and corrected at most twice (Hacker's Delight, `divlu`): two hardware divisions, where a
/// 64-bit `/` is a library call.
fn div_digit(hi: u32, lo: u32, d: u32) -> (u32, u32) {
    const B: u64 = 1 << 16;
    let s = d.leading_zeros();
    let v = d << s;
    let (vn1, vn0) = (v >> 16, v & 0xFFFF);
    let un32 = if s == 0 { hi } else { (hi << s) | (lo >> (32 - s)) };
    let un10 = lo << s;
    let (un1, un0) = (un10 >> 16, un10 & 0xFFFF);
    // One 16-bit digit of the quotient from `top` (the remainder so far and the next digit):
    // the estimate is never under the digit, and over it by at most 2.
    let digit = |top: u32, next: u32| -> u32 {
        let mut q = top / vn1;
        let mut rhat = top - q * vn1;
        while u64::from(q) >= B || u64::from(q) * u64::from(vn0) > (u64::from(rhat) << 16) + u64::from(next) {
            q -= 1;
            rhat += vn1;
            if u64::from(rhat) >= B {
                break;
            }
        }
        q
    };
    let q1 = digit(un32, un1);
    let un21 = (un32 << 16).wrapping_add(un1).wrapping_sub(q1.wrapping_mul(v));
    let q0 = digit(un21, un0);
    let r = (un21 << 16).wrapping_add(un0).wrapping_sub(q0.wrapping_mul(v)) >> s;
    ((q1 << 16) | q0, r)
}

/// The most ticks [`Walk::at`] steps through; beyond, it starts again from the exact position.
const MAX_STRIDE: u64 = 64;

/// A segment walked tick by tick: the same exact position as [`Cubic::at`] (floor and fraction),
/// by forward differences of the numerator polynomial, kept as mixed numbers over its
/// denominator. Where `Cubic::at` divides 128-bit integers every tick, which a Cortex-M4 does in
/// software at thousands of instructions, a step of the walk is three exact additions.
///
/// ```
/// use drive_core::motion::cubic::{Cubic, Point, Walk};
/// let c = Cubic::new(7, 300, Point { position: 1234, velocity: -700, time_ms: 37 });
/// let mut w = Walk::new(&c, 0);
/// for k in 0..=c.ticks() + 2 {
///     assert_eq!(w.at(&c, k), c.at(k));
/// }
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Walk {
    /// The tick `pos` is at.
    k: u64,
    den: Den,
    /// The position times 2^32: whole microsteps in `q >> 32`, the fraction in its low bits.
    pos: Mixed,
    /// The first, second and third forward differences at `k`.
    d1: Mixed,
    d2: Mixed,
    d3: Mixed,
}

const ZERO: Mixed = Mixed { q: 0, r: 0 };

impl Walk {
    /// The walk of `c` standing at tick `k` (clamped to the segment).
    pub fn new(c: &Cubic, k: u64) -> Self {
        let k = k.min(c.n);
        if c.n == 0 || k == 0 {
            let mut w = Self::blank(c);
            for i in 1..=3 {
                w.scale_difference(c, i);
            }
            return w;
        }
        let den = c.den();
        let [n0, n1, n2, n3] = [k, k + 1, k + 2, k + 3].map(|j| c.num(j));
        let (d1, d2, d3) = (n1 - n0, n2 - 2 * n1 + n0, n3 - 3 * n2 + 3 * n1 - n0);
        Self {
            k,
            den,
            pos: Mixed::scaled(n0, den),
            d1: Mixed::scaled(d1, den),
            d2: Mixed::scaled(d2, den),
            d3: Mixed::scaled(d3, den),
        }
    }

    /// The walk of `c` at its start with no difference computed yet (all zero).
    fn blank(c: &Cubic) -> Self {
        let den = if c.n == 0 { Den::UNIT } else { c.den() };
        Self { k: 0, den, pos: ZERO, d1: ZERO, d2: ZERO, d3: ZERO }
    }

    /// Computes the `i`-th forward difference (1-3) at the start of `c` (one 128-bit division):
    /// with `num(k) = A·k³ + B·k² + C·k`, they are `A + B + C`, `6A + 2B` and `6A`.
    fn scale_difference(&mut self, c: &Cubic, i: u8) {
        self.difference_whole(c, i);
        self.difference_rest(i);
    }

    /// The `i`-th difference (1-3).
    fn difference(&mut self, i: u8) -> &mut Mixed {
        match i {
            1 => &mut self.d1,
            2 => &mut self.d2,
            _ => &mut self.d3,
        }
    }

    /// The first half of [`Walk::scale_difference`]: the `i`-th difference's numerator divided
    /// by the denominator, its quotient and remainder kept in the difference until
    /// [`Walk::difference_rest`].
    fn difference_whole(&mut self, c: &Cubic, i: u8) {
        let (q, r) = if c.n == 0 {
            (0, 0)
        } else {
            let [a, b, cc] = c.coefficients();
            let x = match i {
                1 => a + b + cc,
                2 => 6 * a + 2 * b,
                _ => 6 * a,
            };
            div_floor(x, self.den)
        };
        *self.difference(i) = Mixed { q, r };
    }

    /// The second half: the remainder's 32 bits of fraction.
    fn difference_rest(&mut self, i: u8) {
        let den = self.den;
        let d = self.difference(i);
        *d = Mixed::from_whole((d.q, d.r), den);
    }

    /// The position of `c` (the segment this walk was made for) at tick `k`, as [`Cubic::at`]:
    /// forward from where the walk stands, or from the exact position for a step back or a long
    /// stride.
    pub fn at(&mut self, c: &Cubic, k: u64) -> Offset {
        if c.n == 0 {
            return Offset { whole: c.delta, fraction: 0 };
        }
        let k = k.min(c.n);
        if k < self.k || k - self.k > MAX_STRIDE {
            *self = Self::new(c, k);
        }
        while self.k < k {
            self.pos.add(self.d1, self.den);
            self.d1.add(self.d2, self.den);
            self.d2.add(self.d3, self.den);
            self.k += 1;
        }
        Offset { whole: (self.pos.q >> 32) as i64, fraction: self.pos.q as u32 }
    }
}

/// The walk and rates of a segment that has not started yet, built a piece at a time
/// ([`Ahead::advance`]: the rates, then one 128-bit division, up to about 1 500 Cortex-M4
/// instructions each) in the control ticks before it starts: all at once they cost a tick
/// several times what following a segment does.
///
/// ```
/// use drive_core::motion::cubic::{Ahead, Cubic, Point, Walk};
/// let c = Cubic::new(7, 300, Point { position: 1234, velocity: -700, time_ms: 37 });
/// let mut ahead = Ahead::new(c);
/// assert!(!ahead.advance()); // the rates; three differences (two divisions each) to go
/// assert_eq!(ahead.built(), (&Walk::new(&c, 0), &c.rates()));
/// ```
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ahead {
    /// The segment being prepared.
    pub cubic: Cubic,
    walk: Walk,
    rates: Rates,
    /// Pieces built: the rates, then the walk's third, second and first differences, each in
    /// two divisions.
    built: u8,
}

impl Ahead {
    /// The pieces: the rates and two divisions for each of three differences.
    const PIECES: u8 = 7;

    /// Nothing built yet.
    pub fn new(cubic: Cubic) -> Self {
        let blank = Rates { n: 0, per_tick: 0.0, v0: 0.0, v1: 0.0, b: 0.0, a: 0.0, acc0: 0.0, acc1: 0.0 };
        Self { cubic, walk: Walk::blank(&cubic), rates: blank, built: 0 }
    }

    /// Builds one more piece; whether all are built.
    pub fn advance(&mut self) -> bool {
        match self.built {
            0 => self.rates = self.cubic.rates(),
            // Differences 3, 2, 1: the quotient by the denominator, then the fraction.
            i @ 1..=6 => {
                let which = 3 - (i - 1) / 2;
                if i % 2 == 1 {
                    self.walk.difference_whole(&self.cubic, which);
                } else {
                    self.walk.difference_rest(which);
                }
            }
            _ => return true,
        }
        self.built += 1;
        self.built >= Self::PIECES
    }

    /// Whether every piece is built.
    pub fn is_built(&self) -> bool {
        self.built >= Self::PIECES
    }

    /// The walk from the segment's start and its rates, the pieces not built yet built now.
    pub fn built(&mut self) -> (&Walk, &Rates) {
        while !self.advance() {}
        (&self.walk, &self.rates)
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
    fn packs_into_nine_bytes() {
        for velocity in [-2, 0, 1, V_MAX as i32, -(V_MAX as i32), V_STORED, -V_STORED] {
            let p = Point { position: i32::MIN, velocity, time_ms: 65535 };
            assert_eq!(Packed::pack(p).unpack(), p);
        }
        // Beyond 24 bits a speed is kept at the largest stored (the drive refuses it before).
        let fast = Point { position: 5, velocity: i32::MIN, time_ms: 1 };
        assert_eq!(Packed::pack(fast).unpack().velocity, -V_STORED);
        assert_eq!(core::mem::size_of::<Table>(), 9 * TABLE_SIZE);
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
        let mut walk = Walk::new(&c, 0);
        for k in [0, 1, c.ticks() / 3, c.ticks() - 1, c.ticks(), u64::MAX] {
            assert_eq!(walk.at(&c, k), c.at(k), "tick {k}");
            let mut from = Walk::new(&c, k.saturating_sub(MAX_STRIDE));
            assert_eq!(from.at(&c, k), c.at(k), "tick {k}, walked");
        }
    }

    #[test]
    fn rates_end_on_the_points() {
        let c = Cubic::new(-5, 300, Point { position: 1234, velocity: -700, time_ms: 37 });
        let r = c.rates();
        assert_eq!((r.velocity(0), r.velocity(c.ticks()), r.velocity(u64::MAX)), (300.0, -700.0, -700.0));
        // The acceleration is the velocity's derivative: a central difference over two ticks.
        let dt = 1.0 / TICK_HZ as f32;
        for k in [1, 100, 739] {
            let slope = (r.velocity(k + 1) - r.velocity(k - 1)) / (2.0 * dt);
            // The rates are `f32`: a difference of two of them is good to about 1e-4.
            assert!((slope - r.acceleration(k)).abs() < 1e-3 * slope.abs().max(1.0), "tick {k}");
        }
        let none = Cubic::new(3, 5, Point { position: 3, velocity: 5, time_ms: 0 }).rates();
        assert_eq!((none.velocity(0), none.acceleration(0)), (5.0, 0.0));
    }

    proptest::proptest! {

        /// Walking a segment with any strides, forward and back, gives the exact position of
        /// every tick it lands on.
        #[test]
        fn the_walk_is_the_exact_position(
            p0 in proptest::prelude::any::<i32>(),
            v0 in -200_000i32..=200_000,
            to in proptest::prelude::any::<i32>(),
            v1 in -200_000i32..=200_000,
            time_ms in 0u16..=300,
            strides in proptest::collection::vec(-30i64..=90, 1..80),
        ) {
            let c = Cubic::new(i64::from(p0), v0, Point { position: to, velocity: v1, time_ms });
            let mut walk = Walk::new(&c, 0);
            let mut k = 0u64;
            for stride in strides {
                k = k.saturating_add_signed(stride).min(c.ticks() + 5);
                proptest::prop_assert_eq!(walk.at(&c, k), c.at(k), "tick {}", k);
            }
            for k in 0..=c.ticks().min(400) {
                proptest::prop_assert_eq!(walk.at(&c, k), c.at(k), "tick {}", k);
            }
        }

        /// The floor division by a segment's denominator is the library's Euclidean
        /// division, for segments of every length and numerators of every size.
        #[test]
        fn div_floor_is_euclidean(
            x in -(1i128 << 125)..(1i128 << 125),
            time_ms in 1u16..=65535,
            shift in 0u32..126,
        ) {
            let c = Cubic::new(0, 0, Point { position: 0, velocity: 0, time_ms });
            let den = c.den();
            for x in [x, x >> shift, -(x >> shift), den.value - 1, -den.value, 0] {
                let (q, r) = div_floor(x, den);
                proptest::prop_assert_eq!((q, r), (x.div_euclid(den.value), x.rem_euclid(den.value)));
            }
        }

        /// A 64-by-32-bit digit division is the library's, for every divisor's size.
        #[test]
        fn div_digit_is_the_library_division(d in 1u32..=u32::MAX, lo in proptest::prelude::any::<u32>(), hi_share in 0.0f64..1.0, bits in 0u32..32) {
            let d = (d >> bits).max(1);
            let hi = (f64::from(d - 1) * hi_share) as u32;
            let x = (u64::from(hi) << 32) | u64::from(lo);
            let (q, r) = div_digit(hi, lo, d);
            proptest::prop_assert_eq!((u64::from(q), u64::from(r)), (x / u64::from(d), x % u64::from(d)));
        }

        /// A segment prepared ahead, however far the preparation got, starts as one prepared
        /// when it starts.
        #[test]
        fn prepared_ahead_is_prepared_at_the_start(
            p0 in proptest::prelude::any::<i32>(),
            v0 in -200_000i32..=200_000,
            to in proptest::prelude::any::<i32>(),
            v1 in -200_000i32..=200_000,
            time_ms in 0u16..=65535,
            pieces in 0usize..6,
        ) {
            let c = Cubic::new(i64::from(p0), v0, Point { position: to, velocity: v1, time_ms });
            let mut ahead = Ahead::new(c);
            for _ in 0..pieces {
                ahead.advance();
            }
            proptest::prop_assert_eq!(ahead.built(), (&Walk::new(&c, 0), &c.rates()));
        }
    }
}
