//! The G474 board's power stage in the simulator (issue 39, item 6): the motor driven from the
//! drive's bridge commands instead of the ideal chopper ([`crate::motor`]), with
//! [`PowerStage::Bridges`] (`--power-stage bridges`).
//!
//! Each PWM period (20 kHz, the control tick's rate), at the period's centre:
//!
//! - **the shunts as the ADC sees them** ([`Sensing`]): code = 2048 + offset − i/LSB + noise,
//!   rounded and within 0..=4095 (5.37 mA a code, ±11 A: `firmware/src/board/power_stage.rs`),
//!   read back as (zero − code)·LSB with the zero calibrated at power-up over 16 samples at no
//!   current, as the firmware does. The period-averaged winding model's current at a period's
//!   boundary is the current at the centre of the low sides' interval, where the board samples;
//! - **the windings' regulation**, `drive_core::windings` (the firmware's code) on that reading:
//!   the current loop with its gains from the catalogue's R and L (what the auto-tune measures,
//!   within 1 %), the recommended bandwidth, 300 ns of dead time compensated, the back-EMF
//!   estimated from what the loop's model misses; its reference (I·cos θe, I·sin θe) set by the
//!   last tick's outputs, the tick's new outputs taken after it, as the firmware's interrupt
//!   does; the open-winding check that stands for the board's missing open-load flags;
//! - **the PWM**: the loop's voltages quantised as the firmware's timers take them
//!   (`bridge_shares`, the legs centred, counts of 4 250, `MAX_CCR` 4 054) act over the whole of
//!   the next period (one period of delay), the supply clamping them; the dead time takes
//!   2·300 ns·20 kHz·V of mean voltage against each winding's current ([`BridgeVolts`]);
//! - **the comparators**: a bridge current beyond 125 % of the drive's over-current setting
//!   (0x2133, 10 A by default) turns both bridges off within the sub-step (12.5 µs), latched
//!   until the drive turns its bridges off; the drive sees the over-current in the next tick's
//!   phase current (the tripped phase read at the threshold), which its supervision reports
//!   (errors bit 3 or 4).

use std::str::FromStr;

use drive_core::autotune;
use drive_core::control::Outputs;
use drive_core::current::{CurrentLoopSettings, V_BUS_RANGE};
use drive_core::windings::{LoopObjects, PowerUpTune, TuneStep, WindingSettings, WindingState, command_or_open};

use crate::motor::{BridgeVolts, ChopperConfig, Motor};

/// How the simulator drives its motor's windings.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PowerStage {
    /// The ideal chopper: each winding's current brought to its reference every 25 µs, as far
    /// as the supply allows ([`crate::motor`]).
    #[default]
    Chopper,
    /// The G474's bridges: the current loop on the ADC's view, the PWM's delay, dead time and
    /// comparators (this module).
    Bridges,
}

impl FromStr for PowerStage {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "chopper" => Ok(Self::Chopper),
            "bridges" => Ok(Self::Bridges),
            _ => Err(format!("{s:?}: chopper or bridges")),
        }
    }
}

/// The PWM rate, Hz (`power_stage::PWM_HZ`): the control tick's.
pub const PWM_HZ: f64 = 20_000.0;
/// Integration sub-steps a PWM period (12.5 µs, as the chopper's).
pub const SUBSTEPS: u32 = 4;
/// The dead time, s (`power_stage::DEAD_TIME_NS`).
pub const DEAD_TIME_S: f64 = 300e-9;
/// The timers' half period in counts (`power_stage::PERIOD`).
const PERIOD_COUNTS: i32 = 4_250;
/// The highest compare value (`power_stage::MAX_CCR`): 4250 − ⌈(340 + 51)/2⌉.
const MAX_CCR: i32 = 4_054;
/// A phase current's ADC code, A: 3.3 V · 16 / (4095 · 8 · 15 · 20 mΩ) (`power_stage.rs`).
pub const AMPS_PER_CODE: f64 = 3.3 * 16.0 / (4095.0 * 8.0 * 15.0 * 0.020);
/// The comparators' threshold over the drive's over-current setting (`power_stage::TRIP_PERCENT`).
pub const TRIP_SHARE: f64 = 1.25;
/// Samples the zero is calibrated over at power-up (`power_stage::ZERO_SAMPLES`).
const ZERO_SAMPLES: u32 = 16;

/// The shunts' sensing: the op-amps' offsets and the noise, codes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensingOptions {
    /// Each phase's offset, codes: what the zero's calibration at power-up takes out.
    pub offset_codes: [f64; 2],
    /// The noise's standard deviation, codes (Gaussian).
    pub noise_codes: f64,
    /// The noise's seed.
    pub seed: u64,
}

impl Default for SensingOptions {
    /// 7 and −5 codes of offset, 2 codes (10.7 mA) of noise.
    fn default() -> Self {
        Self { offset_codes: [7.0, -5.0], noise_codes: 2.0, seed: 1 }
    }
}

/// The two shunts through the ADC.
#[derive(Clone, Debug)]
pub struct Sensing {
    options: SensingOptions,
    rng: fastrand::Rng,
    spare: Option<f64>,
    /// The zero codes the calibration found.
    zero: [f64; 2],
}

impl Sensing {
    /// The sensing `options` describe, its zero calibrated at no current.
    pub fn new(options: SensingOptions) -> Self {
        let mut sensing = Self { options, rng: fastrand::Rng::with_seed(options.seed), spare: None, zero: [0.0; 2] };
        let mut sum = [0.0; 2];
        for _ in 0..ZERO_SAMPLES {
            let codes = sensing.codes([0.0, 0.0]);
            sum[0] += codes[0];
            sum[1] += codes[1];
        }
        // The firmware keeps the average as a whole code.
        sensing.zero = sum.map(|s| (s / f64::from(ZERO_SAMPLES)).round());
        sensing
    }

    /// A standard normal sample (Box-Muller).
    fn gauss(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        let (u, v) = (1.0 - self.rng.f64(), self.rng.f64());
        let r = (-2.0 * u.ln()).sqrt();
        let (s, c) = (std::f64::consts::TAU * v).sin_cos();
        self.spare = Some(r * s);
        r * c
    }

    /// The ADC's codes for the currents `i`, A.
    fn codes(&mut self, i: [f64; 2]) -> [f64; 2] {
        let mut out = [0.0; 2];
        for ((out, i), offset) in out.iter_mut().zip(i).zip(self.options.offset_codes) {
            let code = 2048.0 + offset - i / AMPS_PER_CODE + self.options.noise_codes * self.gauss();
            *out = code.round().clamp(0.0, 4095.0);
        }
        out
    }

    /// The zero codes the calibration at power-up found (the firmware's `Bridges::zero`).
    pub fn zero_codes(&self) -> [u16; 2] {
        self.zero.map(|z| z.clamp(0.0, 4095.0) as u16)
    }

    /// The currents `i` as the drive reads them, A.
    pub fn read(&mut self, i: [f64; 2]) -> [f64; 2] {
        let codes = self.codes(i);
        [(self.zero[0] - codes[0]) * AMPS_PER_CODE, (self.zero[1] - codes[1]) * AMPS_PER_CODE]
    }
}

/// The winding's mean voltage over a period for `shares` of the bus (1/32768, what the firmware
/// gives `Bridges::set_phase_voltages`): the legs centred and quantised to timer counts, capped
/// at `MAX_CCR`.
pub fn pwm_volts(shares: [i16; 2], v_bus: f64) -> [f64; 2] {
    let leg = |v: i32| (((32_768 + v).clamp(0, 65_535) * PERIOD_COUNTS) >> 16).min(MAX_CCR);
    shares.map(|share| {
        let s = i32::from(share);
        f64::from(leg(s) - leg(-s)) / f64::from(PERIOD_COUNTS) * v_bus
    })
}

/// A comparator trip.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trip {
    /// The phase whose current tripped it, 0 (A) or 1 (B).
    pub phase: usize,
    /// The threshold, A.
    pub threshold_a: f64,
    /// When, s of simulated time (the end of the sub-step it tripped in).
    pub at_s: f64,
}

/// The power stage: the current loop, the ADC, the PWM's delay and the comparators.
#[derive(Clone, Debug)]
pub struct Bridges {
    settings: Option<WindingSettings>,
    /// What the power-up tune found.
    tuned: Option<LoopObjects>,
    state: WindingState,
    sensing: Sensing,
    /// The currents the ADC read at the last period's centre, A.
    measured: [f64; 2],
    /// The voltages the loop asked at the last sample: they act over the coming period.
    pending: Option<[f64; 2]>,
    /// The comparators' latch.
    latched: Option<Trip>,
    /// A trip the drive has not read yet.
    unreported: Option<Trip>,
    /// Every trip so far.
    trips: Vec<Trip>,
    /// What the drive reads at this tick, mA.
    reading_ma: [i32; 2],
}

impl Bridges {
    /// The power stage for `motor` (its PWM set to the board's 20 kHz, four sub-steps a period:
    /// only before it first advances), with `sensing`, its current loop set up as the drive's
    /// objects say at power-up ([`LoopSetup`]): tuned ([`Bridges::tuned`] then holds what the
    /// tune found, for the drive's objects), or from the objects. A tune that fails (an open
    /// winding) or objects the loop refuses leave the bridges with no loop: they stay off, and
    /// the drive reads both windings open once it asks a current.
    pub fn new(motor: &mut Motor, sensing: SensingOptions, setup: LoopSetup) -> Self {
        motor.set_chopper(ChopperConfig { pwm_period_s: 1.0 / PWM_HZ, substeps: SUBSTEPS });
        let mut sensing = Sensing::new(sensing);
        let v_bus = (motor.inputs().supply_v as f32).clamp(V_BUS_RANGE.0, V_BUS_RANGE.1);
        let (settings, tuned) = if setup.auto_tune {
            match tune(motor, &mut sensing, setup.test_ma) {
                Ok(settings) => (Some(settings), Some(LoopObjects::of(&settings))),
                Err(_) => (None, None),
            }
        } else {
            (setup.objects.settings(v_bus, PWM_HZ as f32).ok(), None)
        };
        Self {
            settings,
            tuned,
            state: WindingState::default(),
            sensing,
            measured: [0.0; 2],
            pending: None,
            latched: None,
            unreported: None,
            trips: Vec::new(),
            reading_ma: [0; 2],
        }
    }

    /// What the power-up tune found, in the drive's objects' units; `None` without a tune or if
    /// it failed.
    pub fn tuned(&self) -> Option<LoopObjects> {
        self.tuned
    }

    /// The current loop's settings; `None` if there is no loop (a failed tune).
    pub fn settings(&self) -> Option<&CurrentLoopSettings> {
        self.settings.as_ref().map(WindingSettings::current_loop)
    }

    /// Samples the currents at the period's centre (the time the motor is at).
    pub fn sample(&mut self, motor: &Motor) {
        let (a, b) = motor.phase_currents();
        self.measured = self.sensing.read([a, b]);
        let mut amps = self.measured;
        if let Some(trip) = self.unreported.take()
            && let Some(a) = amps.get_mut(trip.phase)
        {
            *a = trip.threshold_a.copysign(if *a == 0.0 { 1.0 } else { *a });
        }
        self.reading_ma = amps.map(|a| (a * 1e3).round() as i32);
    }

    /// The currents the ADC read at the last sample, A.
    pub fn measured(&self) -> [f64; 2] {
        self.measured
    }

    /// The references of the coming period, A (0 while off).
    pub fn reference(&self) -> [f64; 2] {
        self.state.reference().unwrap_or_default().map(f64::from)
    }

    /// The voltages the loop put across the windings over the period that just ended, mV (0
    /// while off): what the drive knows of them.
    pub fn applied_mv(&self) -> [i32; 2] {
        self.state.applied_mv()
    }

    /// The voltages the loop asked at the last sample, as the timers take them, V: they act over
    /// the coming period (`None` while off or tripped).
    pub fn asked_volts(&self) -> Option<[f64; 2]> {
        self.pending
    }

    /// The back-EMF the loop estimates, mV (`WindingState::back_emf_mv`).
    pub fn back_emf_mv(&self) -> [i32; 2] {
        self.state.back_emf_mv()
    }

    /// Whether the drive's regulation finds each winding open (`WindingState::open`).
    pub fn open(&self) -> [bool; 2] {
        self.state.open()
    }

    /// The phase currents the drive reads at this tick, mA: the ADC's, and a phase that tripped
    /// the comparator since the last sample at the threshold (reported once).
    pub fn reading_ma(&self) -> [i32; 2] {
        self.reading_ma
    }

    /// The trips so far.
    pub fn trips(&self) -> &[Trip] {
        &self.trips
    }

    /// The sensing's zero codes at power-up ([`Sensing::zero_codes`]).
    pub fn zero_codes(&self) -> [u16; 2] {
        self.sensing.zero_codes()
    }

    /// Whether the comparators hold the bridges off.
    pub fn tripped(&self) -> bool {
        self.latched.is_some()
    }

    /// One PWM period of `period_s` s from the sample just taken, as the firmware runs it: the
    /// loop's voltages for the next period from the reference the last tick set
    /// (`drive_core::windings`), then this tick's outputs `out` as the next reference; the motor
    /// advanced over this period with the voltages asked at the last sample, the comparators at
    /// `trip_a`.
    pub fn period(&mut self, motor: &mut Motor, out: &Outputs, trip_a: f64, period_s: f64) {
        let v_bus = motor.inputs().supply_v;
        let supply_mv = (v_bus.max(0.0) * 1e3).round() as u32;
        let measured_ma = self.measured.map(|a| (a * 1e3).round() as i32);
        let next = self
            .settings
            .as_ref()
            .and_then(|w| w.period(&mut self.state, measured_ma, supply_mv))
            .map(|shares| pwm_volts(shares, v_bus));
        command_or_open(self.settings.as_ref(), &mut self.state, out);
        let next = if self.state.reference().is_none() {
            // The drive turned its bridges off: the outputs go off at once, the latch clears.
            self.latched = None;
            self.pending = None;
            None
        } else if self.latched.is_some() {
            None
        } else {
            next
        };
        let acting = std::mem::replace(&mut self.pending, next);
        let bridges = BridgeVolts { volts: acting, dead_volts: 2.0 * DEAD_TIME_S * PWM_HZ * v_bus.max(0.0), trip_a };
        if let Some(phase) = motor.advance_bridges(&bridges, period_s) {
            let trip = Trip { phase, threshold_a: trip_a, at_s: motor.time_s() };
            self.latched = Some(trip);
            self.unreported = Some(trip);
            self.trips.push(trip);
            self.pending = None;
        }
    }
}

/// What the drive's objects say of the current loop at power-up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LoopSetup {
    /// 0x210B: tune at power-up.
    pub auto_tune: bool,
    /// 0x2108, 0x2109, 0x210C, 0x210D: the loop without a tune.
    pub objects: LoopObjects,
    /// 0x600D: the tune's test current, mA.
    pub test_ma: u16,
}

/// The power-up auto-tune (`drive_core::windings::PowerUpTune`, the firmware's) on `motor`
/// through `sensing`: a PWM period at a time, the tune's voltages quantised as the timers take
/// them and acting over the next period, the dead time against the current. On a copy of the
/// motor: the rotor's twitch during the tune (both windings carry current) is left out, and the
/// simulation starts at rest where it was.
fn tune(motor: &Motor, sensing: &mut Sensing, test_ma: u16) -> Result<WindingSettings, autotune::Error> {
    let mut m = motor.clone();
    let mut tune = PowerUpTune::new(test_ma.clamp(100, 10_000), PWM_HZ as f32)?;
    let v_bus = m.inputs().supply_v;
    let supply_mv = (v_bus.max(0.0) * 1e3).round() as u32;
    let dead_volts = 2.0 * DEAD_TIME_S * PWM_HZ * v_bus.max(0.0);
    let mut acting = None;
    loop {
        let (a, b) = m.phase_currents();
        let ma = sensing.read([a, b]).map(|i| (i * 1e3).round() as i32);
        let next = match tune.step(ma, supply_mv) {
            TuneStep::Apply(shares) => Some(pwm_volts(shares, v_bus)),
            TuneStep::Done(done) => return done.map(|(current, _)| WindingSettings::new(current)),
        };
        let volts = std::mem::replace(&mut acting, next);
        m.advance_bridges(&BridgeVolts { volts, dead_volts, trip_a: f64::INFINITY }, 1.0 / PWM_HZ);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pwm_caps_a_leg_at_max_ccr() {
        // Beyond the bus: one leg at MAX_CCR, the other at 0 (the loop itself asks 0.9 at most).
        let [full, zero] = pwm_volts([i16::MAX, 0], 24.0);
        assert!((full - 24.0 * 4054.0 / 4250.0).abs() < 0.01 && zero == 0.0, "{full}");
        let [v, minus] = pwm_volts([6827, -6827], 24.0);
        assert!((v - 5.0).abs() < 0.02 && (minus + 5.0).abs() < 0.02, "{v} {minus}");
    }

    #[test]
    fn the_sensing_reads_the_current_within_its_noise() {
        let mut s = Sensing::new(SensingOptions::default());
        let n = 2_000;
        let mut sum = 0.0;
        for _ in 0..n {
            sum += s.read([1.0, -1.0])[0];
        }
        // The calibration leaves half a code at most, the noise averages out.
        assert!((sum / f64::from(n) - 1.0).abs() < 0.8 * AMPS_PER_CODE, "{}", sum / f64::from(n));
        // Beyond the range: the ADC's full scale.
        assert!(s.read([20.0, 0.0])[0] < 11.1);
    }

    #[test]
    fn power_stage_parses() {
        assert_eq!("bridges".parse(), Ok(PowerStage::Bridges));
        assert_eq!("chopper".parse(), Ok(PowerStage::Chopper));
        assert!("pwm".parse::<PowerStage>().is_err());
    }
}
