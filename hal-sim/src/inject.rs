//! Fault and disturbance injection: what a test or the command line breaks on purpose, and what
//! the simulated drive measures of it.
//!
//! A [`Change`] applies to a [`Plant`](crate::plant::Plant) at a simulated time: from the command
//! line as `--fault MS:SPEC` (at MS ms after power-up), from test code through an [`Injector`]
//! (at once) or [`Plant::inject`](crate::plant::Plant::inject).

use std::fmt;
use std::sync::{Arc, Mutex};

use crate::encoder::EncoderFault;
use crate::motor::PhaseFault;

/// One injected fault or disturbance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Change {
    /// The supply jumps to this voltage, V (ending any ramp).
    Supply(f64),
    /// The supply ramps linearly from where it is to `to_v` volts in `seconds`, then stays.
    SupplyRamp {
        /// Final voltage, V.
        to_v: f64,
        /// Duration of the ramp, s.
        seconds: f64,
    },
    /// The constant load torque becomes this, N·m (a step).
    LoadTorque(f64),
    /// The rotor is held (true) or released.
    Blocked(bool),
    /// Phase A (0) or B (1) gets this fault (`PhaseFault::None` repairs it).
    Phase(usize, PhaseFault),
    /// The driver (power stage) temperature becomes this now, °C: the ambient steps by the
    /// difference, and the thermal model heats or cools the stage from there.
    DriverTemperature(f64),
    /// The shaft encoder gets this fault (noise, line break, slipped coupling) or is repaired.
    Encoder(EncoderFault),
    /// An input pin (0x6031's bit number) is driven high (`Some(true)`), low, or left to the
    /// machine's switches again (`None`): a wire the machine's controller sets.
    Input(u32, Option<bool>),
}

impl Change {
    /// Parses a `--fault` specification: `supply=V`, `supply=V/MS` (ramp to V in MS ms),
    /// `load=NM`, `blocked`, `free`, `open-a`, `open-b`, `short-a`, `short-b`, `heal-a`,
    /// `heal-b`, `temp=C`, `encoder-noise=N`, `encoder-lost`, `encoder-frozen`, `encoder-ok`,
    /// `input=PIN:high|low|free` (PIN `ext1`..`ext3`, `gpio1`..`gpio8`).
    pub fn parse(spec: &str) -> Result<Self, String> {
        let number =
            |t: &str| t.trim().parse::<f64>().ok().filter(|v| v.is_finite()).ok_or(format!("bad number {t:?}"));
        let (key, value) = spec.split_once('=').unwrap_or((spec, ""));
        let phase = |s: &str| match s {
            "a" => Ok(0),
            "b" => Ok(1),
            _ => Err(format!("no phase {s:?} (a or b)")),
        };
        Ok(match key.trim() {
            "supply" => match value.split_once('/') {
                Some((v, ms)) => Change::SupplyRamp { to_v: number(v)?, seconds: number(ms)?.max(0.0) * 1e-3 },
                None => Change::Supply(number(value)?),
            },
            "load" => Change::LoadTorque(number(value)?),
            "blocked" => Change::Blocked(true),
            "free" => Change::Blocked(false),
            "temp" => Change::DriverTemperature(number(value)?),
            "encoder-noise" => Change::Encoder(EncoderFault::Noise(
                value.trim().parse().map_err(|_| format!("bad count {value:?} (0 or more counts)"))?,
            )),
            "encoder-lost" => Change::Encoder(EncoderFault::Lost),
            "encoder-frozen" => Change::Encoder(EncoderFault::Frozen),
            "encoder-ok" => Change::Encoder(EncoderFault::Ok),
            "input" => {
                let (pin, level) = value.split_once(':').ok_or(format!("{spec:?}: expected input=PIN:LEVEL"))?;
                let level = match level.trim() {
                    "high" => Some(true),
                    "low" => Some(false),
                    "free" => None,
                    l => return Err(format!("no level {l:?} (high, low or free)")),
                };
                Change::Input(crate::machine::parse_pin(pin.trim())?, level)
            }
            k => match k.split_once('-') {
                Some(("open", p)) => Change::Phase(phase(p)?, PhaseFault::Open),
                Some(("short", p)) => Change::Phase(phase(p)?, PhaseFault::Short),
                Some(("heal", p)) => Change::Phase(phase(p)?, PhaseFault::None),
                _ => return Err(format!("unknown fault {spec:?}")),
            },
        })
    }
}

/// A change at a time: `--fault MS:SPEC`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scheduled {
    /// Simulated time after power-up, µs.
    pub at_us: u64,
    /// What happens then.
    pub change: Change,
}

impl std::str::FromStr for Scheduled {
    type Err = String;

    /// `MS:SPEC`, as [`Change::parse`].
    fn from_str(s: &str) -> Result<Self, String> {
        let (ms, spec) = s.split_once(':').ok_or(format!("{s:?}: expected MS:SPEC"))?;
        let ms: f64 = ms.trim().parse().map_err(|_| format!("{ms:?}: not a time in ms"))?;
        if !(ms >= 0.0 && ms.is_finite()) {
            return Err(format!("{ms}: not a time in ms"));
        }
        Ok(Scheduled { at_us: (ms * 1e3).round() as u64, change: Change::parse(spec)? })
    }
}

impl fmt::Display for Scheduled {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?} at {} ms", self.change, self.at_us as f64 * 1e-3)
    }
}

/// A handle on a running simulator's plant: changes sent through it apply at the plant's next
/// wake-up (within about a millisecond of simulated time).
#[derive(Clone, Debug, Default)]
pub struct Injector(Arc<Mutex<Vec<Change>>>);

impl Injector {
    /// Applies `change` as soon as the simulator runs next.
    pub fn inject(&self, change: Change) {
        if let Ok(mut q) = self.0.lock() {
            q.push(change);
        }
    }

    /// The changes sent since the last call.
    pub(crate) fn take(&self) -> Vec<Change> {
        self.0.lock().map(|mut q| std::mem::take(&mut *q)).unwrap_or_default()
    }
}

/// The supply: a level, or a ramp under way.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Supply {
    from_v: f64,
    to_v: f64,
    start_s: f64,
    seconds: f64,
}

impl Supply {
    /// A steady `v`.
    pub(crate) fn steady(v: f64) -> Self {
        Self { from_v: v, to_v: v, start_s: 0.0, seconds: 0.0 }
    }

    /// A ramp from `from_v` at `start_s` to `to_v` in `seconds`.
    pub(crate) fn ramp(from_v: f64, to_v: f64, start_s: f64, seconds: f64) -> Self {
        Self { from_v, to_v, start_s, seconds }
    }

    /// The voltage at `t` (s).
    pub(crate) fn at(&self, t: f64) -> f64 {
        if self.seconds <= 0.0 || t >= self.start_s + self.seconds {
            self.to_v
        } else {
            let k = ((t - self.start_s) / self.seconds).clamp(0.0, 1.0);
            self.from_v + (self.to_v - self.from_v) * k
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specifications_parse() {
        let s: Scheduled = "1500:supply=12/500".parse().unwrap();
        assert_eq!(s, Scheduled { at_us: 1_500_000, change: Change::SupplyRamp { to_v: 12.0, seconds: 0.5 } });
        assert_eq!(Change::parse("open-b"), Ok(Change::Phase(1, PhaseFault::Open)));
        assert_eq!(Change::parse("short-a"), Ok(Change::Phase(0, PhaseFault::Short)));
        assert_eq!(Change::parse("temp=95"), Ok(Change::DriverTemperature(95.0)));
        assert_eq!(Change::parse("load=0.2"), Ok(Change::LoadTorque(0.2)));
        assert_eq!(Change::parse("blocked"), Ok(Change::Blocked(true)));
        assert_eq!(Change::parse("encoder-noise=3"), Ok(Change::Encoder(EncoderFault::Noise(3))));
        assert_eq!(Change::parse("encoder-lost"), Ok(Change::Encoder(EncoderFault::Lost)));
        assert_eq!(Change::parse("encoder-frozen"), Ok(Change::Encoder(EncoderFault::Frozen)));
        assert_eq!(Change::parse("encoder-ok"), Ok(Change::Encoder(EncoderFault::Ok)));
        for bad in ["open-c", "supply=x", "load=NaN", "melt", "encoder-noise=-1", "encoder-noise", "encoder-gone"] {
            assert!(Change::parse(bad).is_err(), "{bad}");
        }
        assert!("x:blocked".parse::<Scheduled>().is_err());
        assert!("-1:blocked".parse::<Scheduled>().is_err());
    }

    #[test]
    fn a_ramp_goes_linearly_then_stays() {
        let r = Supply::ramp(24.0, 12.0, 1.0, 2.0);
        assert_eq!(r.at(0.5), 24.0);
        assert_eq!(r.at(2.0), 18.0);
        assert_eq!(r.at(5.0), 12.0);
        assert_eq!(Supply::steady(30.0).at(0.0), 30.0);
    }
}
