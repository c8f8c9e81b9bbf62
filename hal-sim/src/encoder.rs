//! An encoder on the simulated motor's shaft: what the drive reads into
//! [`Inputs::encoder`](drive_core::faults::Inputs::encoder) at each control tick.
//!
//! - [`EncoderKind::Incremental`]: a quadrature encoder of CPR lines, counted ×4 (a count every
//!   edge), 0 at the rotor's power-up position, wrapping at 2^32.
//! - [`EncoderKind::Abs12`]: a single-turn absolute encoder, the rotor's angle in 4096ths of a
//!   turn (0 where the model's rotor angle is 0, which is where it starts unless a test sets it).
//! - [`EncoderKind::Abs12Mt`]: a multi-turn absolute encoder, turns × 4096 + angle, wrapping at
//!   2^32.
//!
//! Every kind counts up when the rotor turns the way a rising microstep setpoint turns it (the
//! model's θ rises with the commanded electrical angle). A count is the floor of the shaft's
//! position in counts, so a rotor resting on an edge reads one count or the next, as a real one
//! does.
//!
//! Injected faults ([`EncoderFault`]): noise adds a uniform random jitter of ±N counts to each
//! reading, from a generator seeded with [`NOISE_SEED`] and the tick's number, so a run gives the
//! same readings every time; a lost encoder (line break) reads `None`; a frozen one (a slipped
//! coupling) keeps the count where it stopped. Repaired ([`EncoderFault::Ok`]), a frozen shaft or
//! an incremental counter that missed the edges of a line break counts on from where it stopped:
//! the difference to the rotor stays (an absolute encoder's line break loses nothing).

use std::f64::consts::TAU;
use std::fmt;
use std::str::FromStr;

use crate::motor::Motor;

/// Line counts an incremental encoder may have (seed 000's 0x6054 range).
pub const INCREMENTAL_CPR: [u32; 8] = [200, 400, 500, 600, 800, 1000, 1200, 1600];
/// Counts per turn of the absolute encoders: 12 bits.
pub const ABSOLUTE_COUNTS: u32 = 4096;
/// The seed of the noise generator (with the tick's number).
pub const NOISE_SEED: u64 = 0x5EED_E9C0_DE12_3457;

/// Which encoder is fitted (`--encoder`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EncoderKind {
    /// None: the drive reads `None`.
    None,
    /// Incremental, this many lines a turn (one of [`INCREMENTAL_CPR`]), counted ×4.
    Incremental {
        /// Lines per revolution.
        cpr: u32,
    },
    /// Absolute single-turn, 12 bits.
    Abs12,
    /// Absolute multi-turn: turns × 4096 + the 12-bit angle, wrapping at 2^32.
    Abs12Mt,
}

impl Default for EncoderKind {
    /// `inc:1000`.
    fn default() -> Self {
        Self::Incremental { cpr: 1000 }
    }
}

impl EncoderKind {
    /// Counts in one turn of the shaft (0 without an encoder).
    pub fn counts_per_turn(self) -> u32 {
        match self {
            Self::None => 0,
            Self::Incremental { cpr } => 4 * cpr,
            Self::Abs12 | Self::Abs12Mt => ABSOLUTE_COUNTS,
        }
    }
}

impl FromStr for EncoderKind {
    type Err = String;

    /// `inc:CPR` (CPR one of [`INCREMENTAL_CPR`]), `abs12`, `abs12mt` or `none`.
    fn from_str(s: &str) -> Result<Self, String> {
        match s.trim() {
            "none" => Ok(Self::None),
            "abs12" => Ok(Self::Abs12),
            "abs12mt" => Ok(Self::Abs12Mt),
            other => {
                let cpr = other
                    .strip_prefix("inc:")
                    .ok_or(format!("unknown encoder {s:?} (inc:CPR, abs12, abs12mt or none)"))?;
                let cpr: u32 = cpr.trim().parse().map_err(|_| format!("{cpr:?}: not a line count"))?;
                if INCREMENTAL_CPR.contains(&cpr) {
                    Ok(Self::Incremental { cpr })
                } else {
                    Err(format!("{cpr} lines: the drive takes {INCREMENTAL_CPR:?}"))
                }
            }
        }
    }
}

impl fmt::Display for EncoderKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::None => f.write_str("none"),
            Self::Incremental { cpr } => write!(f, "inc:{cpr}"),
            Self::Abs12 => f.write_str("abs12"),
            Self::Abs12Mt => f.write_str("abs12mt"),
        }
    }
}

/// What can go wrong with the encoder (see the module documentation).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EncoderFault {
    /// Each reading gets a uniform random jitter of up to this many counts either way (0: none).
    Noise(u32),
    /// The line is broken: the drive reads nothing.
    Lost,
    /// The coupling slipped: the count stays where it is while the rotor turns.
    Frozen,
    /// Line and coupling repaired (the noise stays as set).
    Ok,
}

/// The encoder on one motor's shaft.
#[derive(Clone, Debug, PartialEq)]
pub struct Encoder {
    kind: EncoderKind,
    /// Counts between the rotor's position and the encoder's: the power-up zero of an incremental
    /// encoder, and what a slipped coupling or missed edges added.
    offset: i64,
    /// The count where it stopped: a frozen shaft, or an incremental counter that sees no edges
    /// while its line is broken.
    held: Option<i64>,
    lost: bool,
    noise: u32,
}

impl Encoder {
    /// An encoder of `kind` fitted to `motor` now (power-up): an incremental one reads 0 here.
    pub fn new(kind: EncoderKind, motor: &Motor) -> Self {
        let offset = match kind {
            EncoderKind::Incremental { .. } => -rotor_counts(kind, motor),
            _ => 0,
        };
        Self { kind, offset, held: None, lost: false, noise: 0 }
    }

    /// Which encoder it is.
    pub fn kind(&self) -> EncoderKind {
        self.kind
    }

    /// Applies `fault` with the rotor where `motor` has it.
    pub fn apply(&mut self, fault: EncoderFault, motor: &Motor) {
        let here = self.shaft(motor);
        match fault {
            EncoderFault::Noise(n) => self.noise = n,
            EncoderFault::Frozen => self.held = Some(here),
            EncoderFault::Lost => {
                self.lost = true;
                if matches!(self.kind, EncoderKind::Incremental { .. }) {
                    self.held = Some(here);
                }
            }
            EncoderFault::Ok => {
                if let Some(h) = self.held.take() {
                    self.offset = h - rotor_counts(self.kind, motor);
                }
                self.lost = false;
            }
        }
    }

    /// The shaft's count, before noise and wrapping.
    fn shaft(&self, motor: &Motor) -> i64 {
        self.held.unwrap_or_else(|| rotor_counts(self.kind, motor) + self.offset)
    }

    /// What the drive reads at tick number `tick`: `None` without an encoder or with its line
    /// broken.
    pub fn reading(&self, motor: &Motor, tick: u64) -> Option<u32> {
        if self.kind == EncoderKind::None || self.lost {
            return None;
        }
        let count = self.shaft(motor) + jitter(self.noise, tick);
        Some(match self.kind {
            EncoderKind::Abs12 => count.rem_euclid(i64::from(ABSOLUTE_COUNTS)) as u32,
            // Two's complement truncation: wraps at 2^32 both ways.
            _ => count as u32,
        })
    }
}

/// The rotor's position in whole counts of `kind` from the model's angle 0 (floor), exact at
/// any number of turns.
fn rotor_counts(kind: EncoderKind, motor: &Motor) -> i64 {
    let per_turn = i64::from(kind.counts_per_turn());
    // Rounding can put an angle a hair below a whole turn on the next turn's first count.
    let within = ((motor.angle_in_turn() / TAU * per_turn as f64).floor() as i64).min(per_turn - 1).max(0);
    motor.turns() * per_turn + within
}

/// A uniform jitter in `-amplitude..=amplitude` for tick `tick`, the same for the same tick.
fn jitter(amplitude: u32, tick: u64) -> i64 {
    if amplitude == 0 {
        return 0;
    }
    let a = i64::from(amplitude);
    fastrand::Rng::with_seed(NOISE_SEED ^ tick).i64(-a..=a)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kinds_parse_and_print() {
        for s in ["none", "abs12", "abs12mt", "inc:200", "inc:1600"] {
            assert_eq!(s.parse::<EncoderKind>().map(|k| k.to_string()), Ok(s.to_string()));
        }
        assert_eq!("inc:1000".parse(), Ok(EncoderKind::Incremental { cpr: 1000 }));
        assert_eq!(EncoderKind::default().counts_per_turn(), 4000);
        for bad in ["inc:300", "inc:", "inc:x", "abs16", ""] {
            assert!(bad.parse::<EncoderKind>().is_err(), "{bad}");
        }
    }

    #[test]
    fn jitter_is_bounded_deterministic_and_covers_its_range() {
        let draws: Vec<i64> = (0..2000).map(|k| jitter(3, k)).collect();
        assert!(draws.iter().all(|d| d.abs() <= 3));
        for v in -3..=3 {
            assert!(draws.contains(&v), "{v} never drawn");
        }
        assert_eq!(draws, (0..2000).map(|k| jitter(3, k)).collect::<Vec<_>>());
        assert!((0..100).all(|k| jitter(0, k) == 0));
    }
}
