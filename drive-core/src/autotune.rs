//! The winding's resistance and inductance measured at power-up with voltage steps (issue 39,
//! item 3), for the current loop's gains ([`crate::current::CurrentLoopSettings::new`]).
//!
//! [`Autotune`] is the state machine the control tick runs on one winding, once a PWM period:
//! it is handed the current sampled at the period's centre and the bus voltage, and answers the
//! voltage to put across the winding over the next period ([`Step::Apply`]), until it has its
//! [`Estimate`] or an [`Error`] ([`Step::Done`]: 0 V from then on). The voltage is assumed to act
//! over the period after the one it was asked in, as the current loop's is. Its steps, about
//! half a second at 20 kHz:
//!
//! 1. **Offset** (64 periods at 0 V): the current's reading at rest, which the sensing's
//!    calibration left ([`Estimate::current_offset`]; every later reading is taken from it).
//! 2. **Probe**: a quarter of the bridge's voltage until the current reaches the test current
//!    (or 50 ms pass): the inductance roughly, volt-seconds over the current, for the regulator of
//!    the next steps (bandwidth 500 Hz, its integral's zero at 125 Hz: stable for an inductance
//!    from a third to three times the rough one, and needing no resistance).
//! 3. **Two levels**: the regulator holds half the test current, then the whole, 20 ms to settle
//!    and 100 ms averaged each: R is the slope between the two (mean voltage over mean current),
//!    and the intercept is the voltage the bridge loses whatever the current, its dead time and
//!    offsets ([`Estimate::lost_volts`]). One level's V/I would count that loss as resistance: 0.58
//!    V of dead time at 48 V is 41 % of the NEMA 17's 1.4 V at 1 A.
//! 4. **Pulses** for L (8 up from the lower level to the upper, 8 down, alternately): from a
//!    regulated level, a voltage step that moves the current to the other level in about 12
//!    periods, then the other level's voltage held for 10 periods. Over the pulse, exactly,
//!    L·Δi = ∫(v − v_lost − R·i) dt; each side is averaged over the 8 samples before the pulse
//!    and the last 8 of the hold, which takes the sensing's noise out of Δi eight times over, and
//!    up and down pulses err by the same lost voltage in opposite directions.
//!
//! `drive-core/tests/autotune.rs` runs it on each motor of `hal-sim/motors.toml` at 12 and 48 V
//! through the winding model of the current loop's tests, with the sensing's quantisation and
//! noise.
//!
//! ```
//! use drive_core::autotune::{Autotune, Step};
//! // An ideal winding of 2 Ω and 5 mH, no delay nor dead time, 24 V.
//! let (r, l, t) = (2.0f32, 5.0e-3f32, 1.0 / 20_000.0);
//! let mut tune = Autotune::new(0.8, 20_000.0).unwrap();
//! let (mut i, mut acting) = (0.0f32, 0.0f32);
//! let estimate = loop {
//!     match tune.step(i, 24.0) {
//!         Step::Apply(v) => {
//!             // The period that ends now ran with the voltage asked a period ago.
//!             i = i * (-r * t / l).exp() + (1.0 - (-r * t / l).exp()) * acting / r;
//!             acting = v;
//!         }
//!         Step::Done(result) => break result.unwrap(),
//!     }
//! };
//! assert!((estimate.resistance - 2.0).abs() < 0.01 && (estimate.inductance - 5.0e-3).abs() < 5.0e-5);
//! ```

use crate::current::{L_RANGE, MAX_MODULATION, PWM_RANGE, R_RANGE, V_BUS_RANGE};

/// Periods the current's offset is averaged over at rest.
const OFFSET_PERIODS: u32 = 64;
/// The probe's voltage: this share of the bridge's.
const PROBE_SHARE: f32 = 0.25;
/// The longest probe, periods (50 ms at 20 kHz).
const PROBE_PERIODS: u32 = 1_000;
/// The regulator's bandwidth as a share of the PWM rate (rad/s per Hz): 2π/40, 500 Hz at 20 kHz.
const REGULATOR_SHARE: f32 = core::f32::consts::TAU / 40.0;
/// The regulator's integral zero under its bandwidth.
const REGULATOR_ZERO: f32 = 4.0;
/// Periods a level settles before it is averaged (20 ms at 20 kHz).
const SETTLE_PERIODS: u32 = 400;
/// Periods a level is averaged over (100 ms at 20 kHz).
const AVERAGE_PERIODS: u32 = 2_048;
/// Pulses for the inductance, up and down alternately.
const PULSES: u32 = 16;
/// The periods a pulse is aimed to last.
const PULSE_AIM: f32 = 12.0;
/// The longest a pulse lasts, periods.
const PULSE_PERIODS: u32 = 200;
/// Periods the regulator settles at a level between pulses.
const BETWEEN_PULSES: u32 = 300;
/// Samples averaged on either side of a pulse.
const WINDOW: u32 = 8;
/// The least current the probe must reach, as a share of the test current: less is an open
/// winding (or a bridge that does not switch).
const LEAST_SHARE: f32 = 0.2;
/// Currents beyond this many test currents end the measurement.
const OVER_CURRENT: f32 = 2.0;

/// What the measurement found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Estimate {
    /// The winding's resistance, Ω (with the bridge's switches, wiring and shunt in series).
    pub resistance: f32,
    /// The winding's inductance, H.
    pub inductance: f32,
    /// The voltage the bridge loses at a positive current whatever its size, V: the dead time
    /// (2·t_dt·f_pwm·v_bus) and what offsets there are.
    pub lost_volts: f32,
    /// The current read at rest, A, which the sensing's zero calibration left.
    pub current_offset: f32,
}

/// Why a measurement gave up (0 V from then on).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error {
    /// The test current or the PWM rate is not a usable number (see [`Autotune::new`]).
    Settings,
    /// The bus voltage went out of [`V_BUS_RANGE`].
    Supply,
    /// The probe's voltage gave less than a fifth of the test current: an open winding, or a
    /// bridge that does not switch.
    NoCurrent,
    /// The current went beyond twice the test current.
    OverCurrent,
    /// R or L came out of the current loop's ranges ([`R_RANGE`], [`L_RANGE`]), or the levels
    /// did not differ.
    OutOfRange,
}

/// What to do this period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Step {
    /// Put this voltage across the winding over the next period, V.
    Apply(f32),
    /// The measurement is over: the bridge to 0 V.
    Done(Result<Estimate, Error>),
}

/// Where the measurement is.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Stage {
    Offset,
    Probe,
    /// Regulating at the lower level (0) or the upper (1) and averaging.
    Level(u8),
    /// Regulating at a level before a pulse.
    Between,
    Pulse,
    Hold,
    Done(Result<Estimate, Error>),
}

/// The measurement of one winding: see the module's documentation.
#[derive(Clone, Debug)]
pub struct Autotune {
    test_current: f32,
    period: f32,
    stage: Stage,
    /// Periods in the stage.
    count: u32,
    /// The voltages asked one and two periods ago: the second acts over the period that ended.
    asked: [f32; 2],
    /// The last sample less the offset, A.
    last: f32,
    offset: f32,
    sum_i: f32,
    sum_v: f32,
    /// The probe's voltage and its rough inductance.
    probe_volts: f32,
    rough_l: f32,
    /// The regulator: gains, integral, target.
    kp: f32,
    ki: f32,
    integral: f32,
    target: f32,
    /// The two levels' mean currents and voltages.
    levels: [(f32, f32); 2],
    resistance: f32,
    lost: f32,
    /// The pulses: how many done, the step's size, whether this one goes up.
    pulses: u32,
    pulse_volts: f32,
    up: bool,
    /// ∫(v − v_lost − R·i) dt since the window before the pulse began, V·s.
    flux: f32,
    /// Over the window before the pulse: Σ i and Σ flux.
    pre: (f32, f32),
    /// Over all pulses: Σ ±ΔΦ and Σ |Δi|.
    total: (f32, f32),
}

/// Whether `x` is finite and within `range`.
fn within(x: f32, range: (f32, f32)) -> bool {
    x.is_finite() && x >= range.0 && x <= range.1
}

impl Autotune {
    /// A measurement at `test_current` A (0.05-10 A; the upper level, the lower is half of it:
    /// up to the motor's rated current, half of it is a good choice), at `pwm_hz`.
    pub fn new(test_current: f32, pwm_hz: f32) -> Result<Self, Error> {
        if !within(test_current, (0.05, 10.0)) || !within(pwm_hz, PWM_RANGE) {
            return Err(Error::Settings);
        }
        Ok(Self {
            test_current,
            period: 1.0 / pwm_hz,
            stage: Stage::Offset,
            count: 0,
            asked: [0.0; 2],
            last: 0.0,
            offset: 0.0,
            sum_i: 0.0,
            sum_v: 0.0,
            probe_volts: 0.0,
            rough_l: 0.0,
            kp: 0.0,
            ki: 0.0,
            integral: 0.0,
            target: 0.0,
            levels: [(0.0, 0.0); 2],
            resistance: 0.0,
            lost: 0.0,
            pulses: 0,
            pulse_volts: 0.0,
            up: true,
            flux: 0.0,
            pre: (0.0, 0.0),
            total: (0.0, 0.0),
        })
    }

    /// One PWM period: `current` is the winding's current sampled now (A), `v_bus` the bus
    /// voltage (V).
    pub fn step(&mut self, current: f32, v_bus: f32) -> Step {
        if let Stage::Done(result) = self.stage {
            return Step::Done(result);
        }
        if !within(v_bus, V_BUS_RANGE) {
            return self.finish(Err(Error::Supply));
        }
        let i = current - self.offset;
        if !i.is_finite() || libm::fabsf(i) > OVER_CURRENT * self.test_current {
            return self.finish(Err(Error::OverCurrent));
        }
        let limit = MAX_MODULATION * v_bus;
        // The period that ended ran with the voltage asked two calls ago.
        let [last_asked, acting] = self.asked;
        self.flux += self.period * (acting - self.lost - self.resistance * 0.5 * (self.last + i));
        self.last = i;
        self.count += 1;
        let volts = match self.stage {
            Stage::Offset => self.offset_step(current),
            Stage::Probe => self.probe_step(i, limit),
            Stage::Level(n) => self.level_step(n, i, limit),
            Stage::Between => self.between_step(i, limit),
            Stage::Pulse => self.pulse_step(i, limit),
            Stage::Hold => self.hold_step(i, limit),
            Stage::Done(result) => return Step::Done(result),
        };
        match self.stage {
            Stage::Done(result) => self.finish(result),
            _ => {
                self.asked = [volts, last_asked];
                Step::Apply(volts)
            }
        }
    }

    /// Ends the measurement with `result`.
    fn finish(&mut self, result: Result<Estimate, Error>) -> Step {
        self.stage = Stage::Done(result);
        Step::Done(result)
    }

    /// Enters `stage` at its first period.
    fn enter(&mut self, stage: Stage) {
        self.stage = stage;
        self.count = 0;
        (self.sum_i, self.sum_v) = (0.0, 0.0);
    }

    fn offset_step(&mut self, raw: f32) -> f32 {
        self.sum_i += raw;
        if self.count >= OFFSET_PERIODS {
            self.offset = self.sum_i / OFFSET_PERIODS as f32;
            self.enter(Stage::Probe);
        }
        0.0
    }

    fn probe_step(&mut self, i: f32, limit: f32) -> f32 {
        if self.count == 1 {
            self.probe_volts = PROBE_SHARE * limit;
            self.flux = 0.0;
            return self.probe_volts;
        }
        if i < self.test_current && self.count < PROBE_PERIODS {
            return self.probe_volts;
        }
        if i < LEAST_SHARE * self.test_current {
            self.stage = Stage::Done(Err(Error::NoCurrent));
            return 0.0;
        }
        // Volt-seconds over the current: the winding's resistance and the bridge's loss make
        // this an overestimate, by little while the current is still rising steeply, which the
        // regulator's margin covers. `flux` counted every period since the first ask with the
        // voltage acting then (none in the first period: the delay).
        self.rough_l = self.flux / i;
        let bandwidth = REGULATOR_SHARE / self.period;
        self.kp = self.rough_l * bandwidth;
        self.ki = self.kp * bandwidth / REGULATOR_ZERO * self.period;
        // The regulator starts from the current reached, its integral at the probe's voltage
        // scaled to the lower level.
        self.integral = self.probe_volts * 0.5 * self.test_current / i;
        self.target = 0.5 * self.test_current;
        self.enter(Stage::Level(0));
        self.regulate(i, limit)
    }

    /// The regulator's voltage for the current `i`, within the bridge's.
    fn regulate(&mut self, i: f32, limit: f32) -> f32 {
        let error = self.target - i;
        let integral = (self.integral + self.ki * error).max(-limit).min(limit);
        let wanted = self.kp * error + integral;
        let out = wanted.max(-limit).min(limit);
        if (wanted - out) * error <= 0.0 {
            self.integral = integral;
        }
        out
    }

    fn level_step(&mut self, n: u8, i: f32, limit: f32) -> f32 {
        let volts = self.regulate(i, limit);
        if self.count > SETTLE_PERIODS {
            self.sum_i += i;
            self.sum_v += volts;
        }
        if self.count < SETTLE_PERIODS + AVERAGE_PERIODS {
            return volts;
        }
        let mean = (self.sum_i / AVERAGE_PERIODS as f32, self.sum_v / AVERAGE_PERIODS as f32);
        if n == 0 {
            self.levels[0] = mean;
            self.target = self.test_current;
            self.enter(Stage::Level(1));
            return volts;
        }
        self.levels[1] = mean;
        let [(i1, v1), (i2, v2)] = self.levels;
        self.resistance = (v2 - v1) / (i2 - i1);
        self.lost = v1 - self.resistance * i1;
        if !within(self.resistance, R_RANGE) {
            self.stage = Stage::Done(Err(Error::OutOfRange));
            return 0.0;
        }
        // Pulses of about PULSE_AIM periods between the levels: L·Δi/(n·T) on top of the level's
        // voltage, within what the bridge has either way.
        let wanted = self.rough_l * (i2 - i1) / (PULSE_AIM * self.period);
        self.pulse_volts = wanted.min(limit - v2).min(limit + v1).max(0.0);
        // The first pulse goes up from the lower level.
        self.target = i1;
        self.integral = v1;
        self.up = true;
        self.enter(Stage::Between);
        volts
    }

    fn between_step(&mut self, i: f32, limit: f32) -> f32 {
        let volts = self.regulate(i, limit);
        if self.count == BETWEEN_PULSES - WINDOW + 1 {
            (self.flux, self.pre) = (0.0, (0.0, 0.0));
        }
        if self.count > BETWEEN_PULSES - WINDOW {
            self.pre.0 += i;
            self.pre.1 += self.flux;
        }
        if self.count >= BETWEEN_PULSES {
            self.enter(Stage::Pulse);
            return self.pulse_voltage();
        }
        volts
    }

    /// The pulse's voltage: the level's, and the step towards the other.
    fn pulse_voltage(&self) -> f32 {
        let [(_, v1), (_, v2)] = self.levels;
        if self.up { v1 + self.pulse_volts } else { v2 - self.pulse_volts }
    }

    fn pulse_step(&mut self, i: f32, _limit: f32) -> f32 {
        let [(i1, _), (i2, v2)] = self.levels;
        let arrived = if self.up { i >= i2 } else { i <= i1 };
        if !arrived && self.count < PULSE_PERIODS {
            return self.pulse_voltage();
        }
        self.enter(Stage::Hold);
        let v1 = self.levels[0].1;
        if self.up { v2 } else { v1 }
    }

    fn hold_step(&mut self, i: f32, limit: f32) -> f32 {
        let [(i1, v1), (i2, v2)] = self.levels;
        let (to_current, to_volts) = if self.up { (i2, v2) } else { (i1, v1) };
        // The first two samples of the hold may still see the pulse (the delay): not averaged.
        if self.count > 2 {
            self.sum_i += i;
            self.sum_v += self.flux;
        }
        if self.count < WINDOW + 2 {
            return to_volts;
        }
        let n = WINDOW as f32;
        let (delta_i, delta_flux) = (self.sum_i / n - self.pre.0 / n, self.sum_v / n - self.pre.1 / n);
        if delta_i != 0.0 {
            self.total.0 += if delta_i > 0.0 { delta_flux } else { -delta_flux };
            self.total.1 += libm::fabsf(delta_i);
        }
        self.pulses += 1;
        if self.pulses >= PULSES {
            let inductance = self.total.0 / self.total.1;
            let result = if within(inductance, L_RANGE) {
                Ok(Estimate {
                    resistance: self.resistance,
                    inductance,
                    lost_volts: self.lost,
                    current_offset: self.offset,
                })
            } else {
                Err(Error::OutOfRange)
            };
            self.stage = Stage::Done(result);
            return 0.0;
        }
        // Regulate at the level reached, then pulse back.
        self.target = to_current;
        self.integral = to_volts;
        self.up = !self.up;
        self.enter(Stage::Between);
        self.regulate(i, limit)
    }
}
