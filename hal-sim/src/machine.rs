//! The machine around the simulated motor: limit and home switches at rotor positions, wired to
//! the drive's EXT or GPIO pins; an analog source on its analog input; and (in the motor model,
//! [`crate::motor::Motor::set_hard_stops`]) hard stops that block the rotor.
//!
//! A switch is actuated while the rotor is on its side of a position (in full steps), with
//! hysteresis. Its output is an NPN (sinks when actuated: the pin low) or PNP (sources: the pin
//! high) transistor or a plain contact to ground; when it does not drive the pin, the pin floats
//! to what the drive's pull makes it ([`PinMode`]), low without one. When the actuation changes,
//! a mechanical contact bounces: its output toggles at random for `bounce_ms` before it settles.
//!
//! Specs for `--switch` (repeatable): `PIN:KIND:AT[:OPTION...]`: PIN `ext1`..`ext3` or
//! `gpio1`..`gpio8`; KIND `npn`, `pnp` or `contact` (to ground); AT the position in full steps
//! from the power-up position; options `below` (actuated at and below AT; the default is at and
//! above), `to=POS` (actuated only up to POS: a cam), `hyst=STEPS` (released only that far
//! back; default 0.5), `bounce=MS` (default 0), `nc` (normally closed: drives the pin while
//! *not* actuated). `--hard-stop LOW:HIGH` (full
//! steps, either side may be empty) blocks the rotor beyond them; `--analog` a source on the
//! analog input.

use drive_core::controller::io::{PIN_EXT1, PIN_EXT2, PIN_EXT3, PinConfig, PinMode, PulseInput};

/// What drives a switch's pin.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Output {
    /// An NPN open collector: pulls the pin low when on.
    Npn,
    /// A PNP open collector: pulls the pin high when on.
    Pnp,
    /// A mechanical contact to ground: the pin low when closed.
    Contact,
}

/// A switch on the machine.
#[derive(Clone, Debug, PartialEq)]
pub struct Switch {
    /// The pin, as a bit number of 0x6031 (7 EXT1, 8 EXT2, 9 EXT3, 0-6 GPIO1-7, 11 GPIO8).
    pub pin: u32,
    /// What drives the pin.
    pub output: Output,
    /// Where it is actuated, full steps.
    pub at: f64,
    /// Actuated at and above `at` (else at and below).
    pub above: bool,
    /// How far back the rotor must go to release it, full steps.
    pub hysteresis: f64,
    /// How long its contact bounces after a change, ms.
    pub bounce_ms: f64,
    /// Normally closed: it drives the pin while not actuated.
    pub normally_closed: bool,
    /// The far end of the actuated range, if it has one (a cam): above `at` up to it, or below
    /// down to it.
    pub until: Option<f64>,
    actuated: Option<bool>,
    bounce_until_s: f64,
    next_toggle_s: f64,
    bouncing_on: bool,
}

impl Switch {
    /// A switch on `pin` (0x6031 bit) driven by `output`, actuated from `at` full steps up
    /// (`above`) or down, no bounce, half a step of hysteresis.
    pub fn new(pin: u32, output: Output, at: f64, above: bool) -> Self {
        Self {
            pin,
            output,
            at,
            above,
            hysteresis: 0.5,
            bounce_ms: 0.0,
            normally_closed: false,
            until: None,
            actuated: None,
            bounce_until_s: 0.0,
            next_toggle_s: 0.0,
            bouncing_on: false,
        }
    }

    /// Parses a `--switch` spec (see the module documentation).
    pub fn parse(spec: &str) -> Result<Self, String> {
        let mut parts = spec.split(':');
        let pin = parse_pin(parts.next().unwrap_or(""))?;
        let output = match parts.next().unwrap_or("") {
            "npn" => Output::Npn,
            "pnp" => Output::Pnp,
            "contact" => Output::Contact,
            k => return Err(format!("no switch kind {k:?} (npn, pnp, contact)")),
        };
        let number = |t: &str| t.parse::<f64>().ok().filter(|v| v.is_finite()).ok_or(format!("bad number {t:?}"));
        let at = number(parts.next().ok_or("a switch needs PIN:KIND:AT")?)?;
        let mut s = Switch::new(pin, output, at, true);
        for option in parts {
            match option.split_once('=') {
                None if option == "below" => s.above = false,
                None if option == "above" => s.above = true,
                None if option == "nc" => s.normally_closed = true,
                Some(("hyst", v)) => s.hysteresis = number(v)?.abs(),
                Some(("bounce", v)) => s.bounce_ms = number(v)?.max(0.0),
                Some(("to", v)) => s.until = Some(number(v)?),
                _ => return Err(format!("no switch option {option:?} (below, above, nc, hyst=, bounce=, to=)")),
            }
        }
        Ok(s)
    }

    /// Whether the rotor at `position` (full steps) actuates it now, with the hysteresis.
    fn actuation(&self, position: f64) -> bool {
        let was = self.actuated.unwrap_or(false);
        let back = if was { self.hysteresis } else { 0.0 };
        if self.above {
            position >= self.at - back && self.until.is_none_or(|u| position <= u + back)
        } else {
            position <= self.at + back && self.until.is_none_or(|u| position >= u - back)
        }
    }

    /// Whether its output drives the pin at time `t` (s) with the rotor at `position`: on, with
    /// the contact's bounce after a change.
    fn drives(&mut self, t: f64, position: f64, rng: &mut fastrand::Rng) -> bool {
        let now = self.actuation(position);
        if self.actuated.is_some_and(|was| was != now) && self.bounce_ms > 0.0 {
            self.bounce_until_s = t + self.bounce_ms * 1e-3;
            self.next_toggle_s = t;
        }
        self.actuated = Some(now);
        let on = now != self.normally_closed;
        if t < self.bounce_until_s {
            if t >= self.next_toggle_s {
                self.bouncing_on = rng.bool();
                // Contacts chatter at tens of µs to a millisecond.
                self.next_toggle_s = t + 50e-6 + rng.f64() * 0.9e-3;
            }
            return self.bouncing_on;
        }
        on
    }
}

/// 0x6031's bit number of the pin `name` (`ext1`..`ext3`, `gpio1`..`gpio8`).
pub(crate) fn parse_pin(name: &str) -> Result<u32, String> {
    let pin = match name {
        "ext1" => PIN_EXT1.trailing_zeros(),
        "ext2" => PIN_EXT2.trailing_zeros(),
        "ext3" => PIN_EXT3.trailing_zeros(),
        "gpio8" => 11,
        g => match g.strip_prefix("gpio").and_then(|k| k.parse::<u32>().ok()) {
            Some(k @ 1..=7) => k - 1,
            _ => return Err(format!("no pin {name:?} (ext1..ext3, gpio1..gpio8)")),
        },
    };
    Ok(pin)
}

/// What the analog input sees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Analog {
    /// A constant voltage, V, with uniform noise of ± `noise` V.
    Constant {
        /// Volts.
        volts: f64,
        /// Noise amplitude, V.
        noise: f64,
    },
    /// A linear ramp from `from` to `to` V over `seconds`, then steady.
    Ramp {
        /// Start, V.
        from: f64,
        /// End, V.
        to: f64,
        /// Duration, s.
        seconds: f64,
    },
    /// A sine around `mid` V of amplitude `amp` V and period `period` s.
    Sine {
        /// Mean, V.
        mid: f64,
        /// Amplitude, V.
        amp: f64,
        /// Period, s.
        period: f64,
    },
}

impl Analog {
    /// Parses `--analog`: `V` or `V~NOISE` (constant), `ramp=FROM/TO/S`, `sine=MID/AMP/S`.
    pub fn parse(spec: &str) -> Result<Self, String> {
        let number = |t: &str| t.parse::<f64>().ok().filter(|v| v.is_finite()).ok_or(format!("bad number {t:?}"));
        let three = |v: &str| -> Result<[f64; 3], String> {
            let n: Vec<f64> = v.split('/').map(number).collect::<Result<_, _>>()?;
            n.try_into().map_err(|_| format!("{spec:?} needs three numbers A/B/C"))
        };
        Ok(match spec.split_once('=') {
            Some(("ramp", v)) => {
                let [from, to, seconds] = three(v)?;
                Analog::Ramp { from, to, seconds }
            }
            Some(("sine", v)) => {
                let [mid, amp, period] = three(v)?;
                Analog::Sine { mid, amp, period }
            }
            None => match spec.split_once('~') {
                Some((v, n)) => Analog::Constant { volts: number(v)?, noise: number(n)?.abs() },
                None => Analog::Constant { volts: number(spec)?, noise: 0.0 },
            },
            _ => return Err(format!("no analog source {spec:?} (V, V~NOISE, ramp=A/B/S, sine=M/A/S)")),
        })
    }

    /// The volts at time `t`, s.
    fn volts(&self, t: f64, rng: &mut fastrand::Rng) -> f64 {
        match *self {
            Analog::Constant { volts, noise } => volts + noise * (2.0 * rng.f64() - 1.0),
            Analog::Ramp { from, to, seconds } => from + (to - from) * (t / seconds.max(1e-9)).clamp(0.0, 1.0),
            Analog::Sine { mid, amp, period } => mid + amp * (std::f64::consts::TAU * t / period.max(1e-9)).sin(),
        }
    }
}

/// Full scale of the analog input: the ADC's 3.3 V reference (seed 000 §3.9: 0-3.3 V).
pub const ANALOG_FULL_SCALE_V: f64 = 3.3;

/// The switches and the analog source, and what they make of the pins.
#[derive(Clone, Debug, PartialEq)]
pub struct Machine {
    /// The switches.
    pub switches: Vec<Switch>,
    /// The analog source, if one is connected.
    pub analog: Option<Analog>,
    /// The pulse source on the pulse input, if one is connected (`--pulses`).
    pub pulses: Option<crate::pulses::PulseSource>,
    /// The drive's pulse input timer.
    counter: crate::pulses::Counter,
    /// Pins an outside source drives (a button, a PLC output): their bits (as 0x6031), and
    /// their levels.
    driven: (u16, u16),
    rng: fastrand::Rng,
}

impl Default for Machine {
    fn default() -> Self {
        Self {
            switches: Vec::new(),
            analog: None,
            pulses: None,
            counter: Default::default(),
            driven: (0, 0),
            rng: fastrand::Rng::with_seed(0x5EED),
        }
    }
}

impl Machine {
    /// `switches` and `analog`, the bounces drawn from a fixed seed (a run is the same every time).
    pub fn new(switches: Vec<Switch>, analog: Option<Analog>) -> Self {
        Self { switches, analog, ..Self::default() }
    }

    /// The pins' levels (1 high, bits as 0x6031) at time `t` (s) with the rotor at `position`
    /// (full steps), the drive's pins set up as `pins` and its outputs at `outputs`: an output
    /// pin reads what the drive drives; an input what a switch drives, else its pull.
    pub fn levels(&mut self, t: f64, position: f64, pins: &PinConfig, outputs: u16) -> u16 {
        let mut levels = outputs & pins.outputs;
        let (driven, high) = self.driven;
        for k in 0..12u32 {
            let bit = 1u16 << k;
            if pins.outputs & bit != 0 {
                continue;
            }
            if driven & bit != 0 {
                levels |= high & bit;
                continue;
            }
            let mut level = pins.mode(k) == PinMode::PullUp;
            for s in self.switches.iter_mut().filter(|s| s.pin == k) {
                if s.drives(t, position, &mut self.rng) {
                    level = s.output == Output::Pnp;
                }
            }
            if level {
                levels |= bit;
            }
        }
        levels
    }

    /// The analog input's 12-bit code at time `t` (s), `None` without a source.
    pub fn analog_code(&mut self, t: f64) -> Option<u16> {
        let v = self.analog?.volts(t, &mut self.rng);
        Some((v / ANALOG_FULL_SCALE_V * 4095.0).round().clamp(0.0, 4095.0) as u16)
    }

    /// Drives the input pin `pin` (a bit number of 0x6031) `Some(high)` from outside (a button,
    /// a PLC's output), or lets it go (`None`: its switches and pull again).
    pub fn drive_pin(&mut self, pin: u32, level: Option<bool>) {
        let bit = 1u16.checked_shl(pin).unwrap_or(0);
        let (driven, high) = &mut self.driven;
        match level {
            Some(l) => {
                *driven |= bit;
                *high = if l { *high | bit } else { *high & !bit };
            }
            None => *driven &= !bit,
        }
    }

    /// The pulse input's count at time `t` (s), its timer set up as `input` (a source connected
    /// later counts on from where the last left it).
    pub fn pulse_count(&mut self, t: f64, input: &PulseInput) -> u16 {
        if let Some(p) = &mut self.pulses {
            p.run_to(t, &mut self.counter, input);
        }
        self.counter.count
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_npn_switch_pulls_low_when_actuated_and_floats_to_the_pull_otherwise() {
        let mut m = Machine::new(vec![Switch::parse("ext1:npn:100:below").unwrap()], None);
        let up = PinConfig::new(0, 0, 1, 0, false); // EXT1 enabled, falling edge, NPN: pull-up
        assert_eq!(m.levels(0.0, 200.0, &up, 0) & PIN_EXT1, PIN_EXT1);
        assert_eq!(m.levels(0.0, 100.0, &up, 0) & PIN_EXT1, 0);
        // Hysteresis: released half a step beyond.
        assert_eq!(m.levels(0.0, 100.3, &up, 0) & PIN_EXT1, 0);
        assert_eq!(m.levels(0.0, 100.6, &up, 0) & PIN_EXT1, PIN_EXT1);
        // A wrong pull: the pin never goes high.
        let down = PinConfig::new(0, 0, 1, 1, false);
        assert_eq!(m.levels(0.0, 200.0, &down, 0) & PIN_EXT1, 0);
    }

    #[test]
    fn a_bouncing_contact_chatters_then_settles() {
        let mut m = Machine::new(vec![Switch::parse("ext2:pnp:10:bounce=5").unwrap()], None);
        let pins = PinConfig::new(0, 0, 2, 2, false); // EXT2 rising, type 0: pulled down
        assert_eq!(m.levels(0.0, 0.0, &pins, 0) & PIN_EXT2, 0);
        let mut changes = 0;
        let mut last = 0;
        for k in 0..200 {
            let l = m.levels(0.001 + k as f64 * 50e-6, 11.0, &pins, 0) & PIN_EXT2;
            changes += u32::from(l != last);
            last = l;
        }
        assert!(changes > 2, "{changes}");
        assert_eq!(m.levels(0.02, 11.0, &pins, 0) & PIN_EXT2, PIN_EXT2);
    }

    #[test]
    fn specs_parse() {
        assert_eq!(Switch::parse("gpio8:contact:-5:hyst=2:nc").unwrap().pin, 11);
        assert!(Switch::parse("ext4:npn:0").is_err());
        assert_eq!(Analog::parse("ramp=0/3.3/2").unwrap(), Analog::Ramp { from: 0.0, to: 3.3, seconds: 2.0 });
        assert_eq!(Analog::parse("1.5~0.02").unwrap(), Analog::Constant { volts: 1.5, noise: 0.02 });
    }
}
