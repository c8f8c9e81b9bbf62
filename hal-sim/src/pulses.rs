//! The pulse input: a step-train source wired to the drive's two pulse lines, and the drive's
//! input timer counting what it sees on them as the drive sets it up (work mode 3).
//!
//! The source drives the lines as a pulse generator or a PLC's pulse output does: pulse and
//! direction, double pulse (CW on one line, CCW on the other), or an encoder's quadrature. It
//! runs a trapezoid (or a constant rate) and emits whole pulses, each at its time on the profile,
//! 50 % duty. The counter is the STM32 timer's model: its input filter suppresses a level that
//! lasts less than the filter's length (ICxF at 170 MHz), and it counts the edges it sees in the
//! drive's format, whatever the source's wiring: a source wired for another format is counted
//! wrong, as on a real machine.
//!
//! `--pulses WIRING:RATE[:count=N][:accel=A][:at=MS]`: WIRING `step-dir`, `cw-ccw` or
//! `quadrature`; RATE pulses a second (signed: the direction); `count` stops after N pulses,
//! decelerating to arrive; `accel` ramps at A pulses/s² (0: jumps to the rate); `at` starts MS
//! ms after power-up.

use drive_core::controller::io::PulseInput;
use drive_core::modes::PulseFormat;

/// The filter's length in timer clocks for ICxF = 0..=15 (STM32 reference manuals: N samples
/// at f_DTS divided as each setting says).
const FILTER_CLOCKS: [u32; 16] = [1, 2, 4, 8, 12, 16, 24, 32, 48, 64, 80, 96, 128, 160, 192, 256];
/// The input timer's clock (the G474's 170 MHz, no division).
const TIMER_HZ: f64 = 170e6;

/// The shortest level the filter `filter` lets through, s.
pub fn filter_width_s(filter: u8) -> f64 {
    f64::from(FILTER_CLOCKS.get(usize::from(filter)).copied().unwrap_or(256)) / TIMER_HZ
}

/// How a source drives the two lines.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wiring {
    /// A pulse on line A, the direction on line B (high: negative).
    StepDir,
    /// Positive pulses on line A, negative ones on line B.
    CwCcw,
    /// Quadrature: A leads B going positive; a pulse is one edge of either.
    Quadrature,
}

/// What the source runs: a trapezoid of pulses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Train {
    /// How it is wired.
    pub wiring: Wiring,
    /// The rate it runs at, pulses a second (signed: the direction).
    pub rate: f64,
    /// Pulses to emit, if it stops (it decelerates to arrive on the last).
    pub count: Option<u64>,
    /// Its acceleration and deceleration, pulses/s²; 0 jumps to the rate and stops from it.
    pub accel: f64,
    /// When it starts, s of simulated time.
    pub at_s: f64,
}

impl Train {
    /// Parses a `--pulses` spec (see the module documentation).
    pub fn parse(spec: &str) -> Result<Self, String> {
        let mut parts = spec.split(':');
        let wiring = match parts.next().unwrap_or("") {
            "step-dir" => Wiring::StepDir,
            "cw-ccw" => Wiring::CwCcw,
            "quadrature" => Wiring::Quadrature,
            w => return Err(format!("no wiring {w:?} (step-dir, cw-ccw, quadrature)")),
        };
        let number = |t: &str| t.parse::<f64>().ok().filter(|v| v.is_finite()).ok_or(format!("bad number {t:?}"));
        let rate = number(parts.next().ok_or("a pulse train needs WIRING:RATE")?)?;
        let mut train = Train { wiring, rate, count: None, accel: 0.0, at_s: 0.0 };
        for option in parts {
            match option.split_once('=') {
                Some(("count", v)) => train.count = Some(v.parse().map_err(|_| format!("bad count {v:?}"))?),
                Some(("accel", v)) => train.accel = number(v)?.abs(),
                Some(("at", v)) => train.at_s = number(v)?.max(0.0) * 1e-3,
                _ => return Err(format!("no pulse option {option:?} (count=, accel=, at=)")),
            }
        }
        Ok(train)
    }

    /// Pulses emitted (as a real number) and the rate's magnitude `t` s after the start.
    fn at(&self, t: f64) -> (f64, f64) {
        let v = self.rate.abs();
        if t <= 0.0 || v == 0.0 {
            return (0.0, 0.0);
        }
        let Some(n) = self.count.map(|n| n as f64) else {
            return if self.accel == 0.0 {
                (v * t, v)
            } else if t < v / self.accel {
                (0.5 * self.accel * t * t, self.accel * t)
            } else {
                (v * t - 0.5 * v * v / self.accel, v)
            };
        };
        if self.accel == 0.0 {
            return if v * t < n { (v * t, v) } else { (n, 0.0) };
        }
        // The peak: the rate, or lower if the count is too short to reach it.
        let a = self.accel;
        let peak = v.min((n * a).sqrt());
        let t_ramp = peak / a;
        let ramp = 0.5 * peak * t_ramp;
        let t_cruise = (n - 2.0 * ramp) / peak;
        let end = 2.0 * t_ramp + t_cruise;
        if t < t_ramp {
            (0.5 * a * t * t, a * t)
        } else if t < t_ramp + t_cruise {
            (ramp + peak * (t - t_ramp), peak)
        } else if t < end {
            let left = end - t;
            (n - 0.5 * a * left * left, a * left)
        } else {
            (n, 0.0)
        }
    }
}

/// The input timer: what the drive counts of the two lines.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counter {
    /// The count, wrapping as the 16-bit timer's.
    pub count: u16,
    /// The levels the filter let through.
    seen: (bool, bool),
}

impl Counter {
    /// A level change of a line (`b`: line B) to `level` that holds `width` s, counted as
    /// `input` sets up the timer.
    fn edge(&mut self, input: &PulseInput, b: bool, level: bool, width: f64) {
        if width < filter_width_s(input.filter) {
            return;
        }
        let old = self.seen;
        if b {
            self.seen.1 = level;
        } else {
            self.seen.0 = level;
        }
        let rising = level && if b { !old.1 } else { !old.0 };
        let delta: i16 = match input.format {
            PulseFormat::StepDir if rising && !b => {
                if self.seen.1 {
                    -1
                } else {
                    1
                }
            }
            PulseFormat::CwCcw if rising => {
                if b {
                    -1
                } else {
                    1
                }
            }
            PulseFormat::Quadrature => {
                let phase = |(a, b): (bool, bool)| match (a, b) {
                    (false, false) => 0i16,
                    (true, false) => 1,
                    (true, true) => 2,
                    (false, true) => 3,
                };
                match (phase(self.seen) - phase(old)).rem_euclid(4) {
                    1 => 1,
                    3 => -1,
                    // No change, or two steps at once: the decoder cannot tell, and counts none.
                    _ => 0,
                }
            }
            _ => 0,
        };
        self.count = self.count.wrapping_add_signed(delta);
    }
}

/// A source of pulses on the lines, and what the drive's timer counts of them.
#[derive(Clone, Debug, PartialEq)]
pub struct PulseSource {
    /// What it runs.
    pub train: Train,
    /// Pulses emitted so far (signed: the direction).
    emitted: i64,
    /// The rate at the last call, pulses a second.
    last_rate: f64,
    /// The lines' levels as the source drives them.
    lines: (bool, bool),
}

impl PulseSource {
    /// A source that will run `train`, nothing emitted yet.
    pub fn new(train: Train) -> Self {
        Self { train, emitted: 0, last_rate: 0.0, lines: (false, false) }
    }

    /// Pulses emitted so far (signed).
    pub fn emitted(&self) -> i64 {
        self.emitted
    }

    /// Runs the source up to `t` (s), its pulses counted by the drive's timer `counter` set up
    /// as `input`. Called at every control tick: the pulses since the last call are as narrow as
    /// the faster of the two calls' rates makes them.
    pub fn run_to(&mut self, t: f64, counter: &mut Counter, input: &PulseInput) {
        let (p, rate) = self.train.at(t - self.train.at_s);
        let v = rate.max(core::mem::replace(&mut self.last_rate, rate));
        let sign = if self.train.rate < 0.0 { -1 } else { 1 };
        let target = sign * p.floor() as i64;
        while self.emitted != target {
            let up = target > self.emitted;
            self.pulse(up, v.max(1e-9), counter, input);
            self.emitted += if up { 1 } else { -1 };
        }
    }

    /// One pulse in direction `up` at the rate `v` (pulses a second): the lines' edges, each
    /// given to the counter with how long its level lasts.
    fn pulse(&mut self, up: bool, v: f64, c: &mut Counter, input: &PulseInput) {
        match self.train.wiring {
            Wiring::StepDir => {
                if self.lines.1 == up {
                    // DIR changes between pulses, and holds.
                    self.lines.1 = !up;
                    c.edge(input, true, !up, f64::INFINITY);
                }
                c.edge(input, false, true, 0.5 / v);
                c.edge(input, false, false, 0.5 / v);
            }
            Wiring::CwCcw => {
                let b = !up;
                c.edge(input, b, true, 0.5 / v);
                c.edge(input, b, false, 0.5 / v);
            }
            Wiring::Quadrature => {
                // 00 → 10 → 11 → 01 going up: one line changes a pulse, each level lasts two.
                let (a, b) = self.lines;
                let change_a = (a == b) == up;
                if change_a {
                    self.lines.0 = !a;
                    c.edge(input, false, !a, 2.0 / v);
                } else {
                    self.lines.1 = !b;
                    c.edge(input, true, !b, 2.0 / v);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn input(format: PulseFormat, filter: u8) -> PulseInput {
        PulseInput { format, filter }
    }

    /// The count after `secs` s of 50 µs ticks.
    fn count(train: Train, secs: f64, input: &PulseInput) -> (i64, u16) {
        let mut s = PulseSource::new(train);
        let mut c = Counter::default();
        for k in 0..=(secs * 20_000.0) as u32 {
            s.run_to(f64::from(k) * 50e-6, &mut c, input);
        }
        (s.emitted(), c.count)
    }

    #[test]
    fn each_wiring_is_counted_exactly_in_its_own_format() {
        for (wiring, format) in [
            (Wiring::StepDir, PulseFormat::StepDir),
            (Wiring::CwCcw, PulseFormat::CwCcw),
            (Wiring::Quadrature, PulseFormat::Quadrature),
        ] {
            for rate in [5_000.0, -5_000.0] {
                let train = Train { wiring, rate, count: Some(1234), accel: 1e6, at_s: 0.0 };
                let (emitted, count) = count(train, 1.0, &input(format, 1));
                assert_eq!(emitted, 1234 * rate.signum() as i64);
                assert_eq!(count as i16, 1234 * rate.signum() as i16, "{wiring:?} at {rate}");
            }
        }
    }

    #[test]
    fn another_format_counts_wrong_and_the_filter_drops_narrow_pulses() {
        let train = Train { wiring: Wiring::StepDir, rate: -1000.0, count: Some(100), accel: 0.0, at_s: 0.0 };
        // Pulse and direction read as double pulse: the steps count up whatever DIR says.
        assert_eq!(count(train, 1.0, &input(PulseFormat::CwCcw, 1)).1 as i16, 99);
        // 400 kpps pulses are 1.25 µs wide: filter 15 (1.5 µs) drops them, 14 (1.13 µs) not.
        let fast = Train { wiring: Wiring::CwCcw, rate: 400_000.0, count: Some(4000), accel: 0.0, at_s: 0.0 };
        assert_eq!(count(fast, 1.0, &input(PulseFormat::CwCcw, 15)).1, 0);
        assert_eq!(count(fast, 1.0, &input(PulseFormat::CwCcw, 14)).1, 4000);
    }

    #[test]
    fn the_trapezoid_ends_on_its_count() {
        let t = Train { wiring: Wiring::StepDir, rate: 200_000.0, count: Some(40_000), accel: 1e6, at_s: 0.0 };
        // 0.2 s up, 0.2 s down, 0 s between: 40 000 pulses at 0.4 s.
        assert!((t.at(0.2).0 - 20_000.0).abs() < 1e-6);
        assert_eq!(t.at(0.4), (40_000.0, 0.0));
    }
}
