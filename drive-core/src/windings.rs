//! The windings' regulation between two control ticks: the tick's outputs (the electrical angle
//! it commutates and the current it asks for) turned into each winding's voltage once a PWM
//! period by the current loop ([`crate::current`]), on the currents as the board measures them.
//!
//! The board (the firmware's ADC interrupt, the simulator's bridges) calls, each period, at the
//! centre of the PWM where the currents are sampled:
//!
//! 1. [`WindingSettings::period`] with the currents just measured: the voltages for the next
//!    period, from the reference the last tick set (the loop acts first: its voltages must reach
//!    the timers before the next period starts, and the tick can take half a period);
//! 2. the control tick, then [`WindingSettings::command`] with its outputs: the reference for
//!    the next period.
//!
//! The reference is (I·cos θe, I·sin θe): the current I the tick asks for at the electrical angle
//! θe of its commutation (four full steps an electrical turn), worked out in the angle's own
//! microsteps so that it stays exact however far the motor has turned. Off (the tick frees the
//! motor, or a fault) the loop's memory is cleared and the bridges are to be off.
//!
//! ```
//! use drive_core::windings::{WindingSettings, WindingState, electrical_angle};
//! use drive_core::current::CurrentLoopSettings;
//! use drive_core::motion::axis::Setpoint;
//! use fixed::types::U0F32;
//! // A full step beyond a thousand electrical turns, at 16 microsteps a step: 90°.
//! let at = Setpoint { whole: 16 * 4 * 1000 + 16, fraction: U0F32::ZERO, velocity: 0.0, acceleration: 0.0 };
//! assert!((electrical_angle(&at, 16) - core::f32::consts::FRAC_PI_2).abs() < 1e-6);
//! let loop_ = CurrentLoopSettings::new(1.4, 3.0e-3, 24.0, 20_000.0, 32_189.0).unwrap();
//! let settings = WindingSettings::new(loop_);
//! let mut state = WindingState::default();
//! // Nothing commanded yet: the bridges stay off.
//! assert_eq!(settings.period(&mut state, [0, 0], 24_000), None);
//! ```

use crate::autotune::{self, Autotune, Estimate, Step};
use crate::controller::Outputs;
use crate::current::{CosSin, CurrentLoopSettings, CurrentLoopState, bridge_shares, recommended_bandwidth};
use crate::motion::axis::Setpoint;

/// Full steps an electrical turn of a two-phase hybrid stepper.
pub const STEPS_PER_ELECTRICAL_TURN: u32 = 4;

/// The electrical angle of the commutation `at`, rad within [0, 2π), at `microsteps` a full step
/// (0 counts full steps).
pub fn electrical_angle(at: &Setpoint, microsteps: u16) -> f32 {
    let per_turn = STEPS_PER_ELECTRICAL_TURN * u32::from(microsteps.max(1));
    // Within a turn, as a u32 (the FPU converts that; an i64 takes a library routine); a
    // power of two of microsteps a turn, the usual case, by a mask rather than a 64-bit division.
    let turn = if per_turn.is_power_of_two() {
        at.whole as u32 & (per_turn - 1)
    } else {
        at.whole.rem_euclid(i64::from(per_turn)) as u32
    };
    // The fraction's bits as a u32, scaled: one conversion of the FPU, rounded as `to_num` does.
    let within = turn as f32 + at.fraction.to_bits() as f32 * (1.0 / 4_294_967_296.0);
    within * (core::f32::consts::TAU / per_turn as f32)
}

/// Periods (1 ms at 20 kHz) a winding must look open before [`WindingState::open`] says so:
/// longer than a step's rise to the limit, short beside the fault's reaction.
pub const OPEN_PERIODS: u16 = 20;
/// The smallest reference, mA, against which a winding can look open: under it the currents'
/// noise and the dead time decide.
pub const OPEN_MIN_MA: f32 = 100.0;
/// The share of its reference under which a winding's current, at the supply's limit, means the
/// winding is open.
pub const OPEN_SHARE: f32 = 0.1;
/// The fastest the electrical angle turns, rad a period, while a winding can be told open: 1 turn
/// a second of a 1.8° motor at 20 kHz. Faster, a back-EMF beyond the supply (the NEMA 23 from 4
/// turns a second at 12 V) starves the windings as an open one would; the check waits for the
/// motor to slow down.
pub const OPEN_MAX_TURN: f32 = 0.016;

/// Counts the periods in a row a winding has looked open: driven at the supply's `limit` with
/// `volts` towards `reference` A, and `measured` A under [`OPEN_SHARE`] of it.
fn looks_open(periods: &mut u16, volts: f32, reference: f32, measured: f32, limit: f32) {
    let starved = reference.abs() * 1e3 >= OPEN_MIN_MA && measured.abs() < OPEN_SHARE * reference.abs();
    let at_limit = volts.abs() >= 0.99 * limit && volts * reference > 0.0;
    *periods = if starved && at_limit { periods.saturating_add(1) } else { 0 };
}

/// The share of the correction's voltage that goes into the back-EMF's estimate each period: slow
/// beside the correction (0.25), so that the two do not ring with the rotor (at 0.1 the NEMA 17
/// at 48 V lost a third of its pull-out torque around 12 turns a second; `docs/current-loop.md`,
/// *Torque-speed*).
pub const EMF_GAIN: f32 = 0.03;

/// The cosine and sine of an angle of at most a few tenths of a radian (the electrical angle's
/// turn in a period), by their series to the fourth and third order: within 5e-5 up to 0.35 rad
/// (28 turns a second of a 50-pole-pair motor at 20 kHz); beyond, the exact ones.
fn small_turn(angle: f32) -> CosSin {
    if angle.abs() > 0.35 || !angle.is_finite() {
        return if angle.is_finite() { CosSin::of(angle) } else { CosSin { cos: 1.0, sin: 0.0 } };
    }
    let a2 = angle * angle;
    CosSin { cos: 1.0 - a2 * (0.5 - a2 * (1.0 / 24.0)), sin: angle * (1.0 - a2 * (1.0 / 6.0)) }
}

/// Mid-band stability, open loop. Beyond the speed where the supply runs out the loop is at its
/// limit and the windings are driven by a voltage, not a current; a stepper so driven is
/// unstable about its load angle (the rotor's oscillation grows until it loses step: the
/// mid-band resonance; undamped, the NEMA 23 at 12 V keeps a fifth of the chopper's pull-out
/// torque at 6 turns a second). The windings damp it as V/f drives of synchronous motors do
/// (Perera, Blaabjerg et al., IEEE Trans. Ind. Appl. 39(3), 2003): the commutation is slowed by
/// the electrical power's rise over its mean, Δθ = −g·Δθ_cmd·ΔP/(V_bus·I) a period, Δθ_cmd the
/// commanded turn of the period: a rotor that falls behind draws more power, and the field
/// waits for it. The gain scales with the speed, so a standing motor is left alone. g = 0.25,
/// set by the torque-speed sweep (`docs/current-loop.md`, *Torque-speed*): any g from 0.2 to
/// 0.4 keeps the bridges at 0.95 of the chopper or above at every point; at 0.1 the NEMA 23 at
/// 12 V keeps only three quarters of it at 6 rev/s.
pub const DAMPING_GAIN: f32 = 0.25;
/// The share of the difference that the electrical power's mean takes each period: a corner of
/// 3 Hz, under the rotor's oscillation at speed (10-40 Hz).
pub const POWER_MEAN_SHARE: f32 = 0.001;
/// The share of the damping's angle given back each period: it returns to the commanded angle
/// with a time constant of 0.1 s, and at rest the motor stands at its commanded microstep.
pub const DAMPING_LEAK: f32 = 0.0005;
/// The largest angle the damping moves the commutation by, rad: under half a full step.
pub const DAMPING_MAX: f32 = 0.6;

/// How much the loop's gains are scaled for each of 0x6010's decays (0-3: 0 %, 50 %, 75 % and
/// 87.5 % of fast decay in a chopper's off-time): the drive's bridges have no chopper and no
/// decay, and 0x6010 sets how fast the loop is instead, as more fast decay makes a chopper's
/// current follow faster at the cost of ripple. The closed loop's pole per period is 0.5, 0.35,
/// 0.2 (the factory decay 2: [`crate::current::RECOMMENDED_POLE`]) and 0.1; the PI's gains scale
/// with 1 − pole, so by these shares of the factory decay's.
pub const DECAY_GAINS: [f32; 4] = [0.625, 0.8125, 1.0, 1.125];

/// The decay 0x6010 gives as its share of fast decay (`Outputs::fast_decay`), 0-3.
fn decay_index(fast: fixed::types::U0F16) -> u8 {
    // Half-way between 0x6010's shares: 0.25, 0.625, 0.8125.
    match fast.to_bits() {
        0..0x4000 => 0,
        0x4000..0xA000 => 1,
        0xA000..0xD000 => 2,
        _ => 3,
    }
}

/// The winding regulation's settings: the current loop's, validated (worked out off the tick),
/// one for each decay of 0x6010 ([`DECAY_GAINS`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WindingSettings {
    /// By decay; the factory decay's (2) is the loop's own.
    current: [CurrentLoopSettings; 4],
}

/// What the regulation remembers from period to period.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct WindingState {
    /// The current loop's memory.
    current: CurrentLoopState,
    /// The windings' reference currents for the coming period, A; `None`: the bridges off.
    reference: Option<[f32; 2]>,
    /// The rotation of the electrical angle over a period at the commanded speed, its cosine
    /// and sine: what the back-EMF turns through from one period to the next.
    turn: CosSin,
    /// The back-EMF the windings meet over the coming period, V: what the model has missed,
    /// integrated and turned with the rotor (fed forward to the current loop).
    back_emf: [f32; 2],
    /// The decay the last tick gave (0x6010, 0-3), which picks the loop's gains.
    decay: u8,
    /// The voltages asked for the coming period, mV (0 while off).
    next_mv: [i32; 2],
    /// The voltages across the windings over the period that just ended, mV (0 while off).
    applied_mv: [i32; 2],
    /// Periods in a row each winding has looked open ([`OPEN_PERIODS`]).
    open_for: [u16; 2],
    /// The last tick asked a current of bridges with no loop ([`command_or_open`]).
    asked_without_loop: bool,
    /// The current's amplitude the last tick asked for, A.
    amps: f32,
    /// Whether the last tick's commutation followed the measured rotor ([`Outputs::closed_loop`]).
    closed_loop: bool,
    /// The electrical power's mean, W ([`POWER_MEAN_SHARE`]).
    power_mean: f32,
    /// The angle the damping moves the commutation by, rad ([`DAMPING_GAIN`]).
    damping: f32,
}

impl WindingState {
    /// The voltages across the windings over the period that just ended, mV (0 while off):
    /// the sensorless stall detection's `phase_mv`.
    pub fn applied_mv(&self) -> [i32; 2] {
        self.applied_mv
    }

    /// The back-EMF the loop estimates and feeds forward, mV: the sensorless stall detection's
    /// `back_emf_mv`.
    pub fn back_emf_mv(&self) -> [i32; 2] {
        self.back_emf.map(|v| (v * 1e3) as i32)
    }

    /// Whether each winding is open: for [`OPEN_PERIODS`] in a row, turning no faster than
    /// [`OPEN_MAX_TURN`], the loop has driven it at the supply's limit towards a reference of
    /// [`OPEN_MIN_MA`] or more, and its current stayed under [`OPEN_SHARE`] of that reference.
    /// The board has no open-load flag of its own; this is its `coil_open`. With no loop (a
    /// tune that failed), both while the tick asks a current ([`command_or_open`]).
    pub fn open(&self) -> [bool; 2] {
        if self.asked_without_loop { [true; 2] } else { self.open_for.map(|n| n >= OPEN_PERIODS) }
    }

    /// The reference currents of the coming period, A; `None` while the bridges are off.
    pub fn reference(&self) -> Option<[f32; 2]> {
        self.reference
    }
}

impl WindingSettings {
    /// The regulation with the current loop `current` at the factory decay, its gains scaled
    /// for the others ([`DECAY_GAINS`]).
    pub fn new(current: CurrentLoopSettings) -> Self {
        let scaled = |k: f32| current.with_gains(current.kp() * k, current.ki() * k).unwrap_or(current);
        Self { current: DECAY_GAINS.map(scaled) }
    }

    /// The current loop's settings at the factory decay (2).
    pub fn current_loop(&self) -> &CurrentLoopSettings {
        let [_, _, factory, _] = &self.current;
        factory
    }

    /// Takes one tick's outputs: the reference of the next period, or off.
    pub fn command(&self, state: &mut WindingState, out: &Outputs) {
        if !out.enabled || out.current_ma == 0 {
            *state = WindingState::default();
            return;
        }
        let amps = f32::from(out.current_ma) * 1e-3;
        let at = CosSin::of(electrical_angle(&out.commutation, out.microsteps) + state.damping);
        (state.amps, state.closed_loop) = (amps, out.closed_loop);
        state.reference = Some([amps * at.cos, amps * at.sin]);
        let per_turn = (STEPS_PER_ELECTRICAL_TURN * u32::from(out.microsteps.max(1))) as f32;
        let step = out.commutation.velocity * core::f32::consts::TAU / per_turn * self.current_loop().period();
        state.turn = small_turn(step);
        state.decay = decay_index(out.fast_decay);
    }

    /// One PWM period from the currents measured now, `phase_ma`, and the bus, `supply_mv`: each
    /// winding's voltage over the next period as a share of the bus in 1/32768
    /// ([`bridge_shares`]); `None`: the bridges off.
    pub fn period(&self, state: &mut WindingState, phase_ma: [i32; 2], supply_mv: u32) -> Option<[i16; 2]> {
        state.applied_mv = state.next_mv;
        let Some(reference) = state.reference else {
            state.next_mv = [0; 2];
            return None;
        };
        let v_bus = supply_mv as f32 * 1e-3;
        let measured = phase_ma.map(|ma| ma as f32 * 1e-3);
        damp(state, measured, v_bus);
        let current = self.current.get(usize::from(state.decay)).unwrap_or(self.current_loop());
        let volts = current.step(&mut state.current, reference, measured, state.back_emf, v_bus);
        // What reaches the windings: the dead time takes back what the loop added for it.
        let ([va, vb], [ra, rb]) = (volts, reference);
        let reach = |v: f32, i_ref: f32| v - current.dead_time_feed_forward(i_ref, v_bus);
        // To the mV below (a truncation: the FPU's conversion, not a rounding routine).
        state.next_mv = [(reach(va, ra) * 1e3) as i32, (reach(vb, rb) * 1e3) as i32];
        // What the model still misses is mostly the back-EMF, a vector turning with the rotor:
        // the correction's current as a voltage (−c/b) integrated into the estimate fed forward,
        // which is turned with the rotor to the next period, as is the correction, so that both
        // follow it with no lag at a steady speed (integrals in the rotating frame).
        let turn =
            |[x, y]: [f32; 2]| [state.turn.cos * x - state.turn.sin * y, state.turn.sin * x + state.turn.cos * y];
        let [pa, pb] = &mut state.current.phases;
        let missed = [pa.correction, pb.correction];
        let gain = EMF_GAIN / current.volt_gain();
        let [ea, eb] = state.back_emf;
        state.back_emf = turn([ea - gain * missed[0], eb - gain * missed[1]]);
        [pa.correction, pb.correction] = turn(missed);
        let limit = CurrentLoopSettings::limit(v_bus);
        // Too fast to tell: no reference counts as starved.
        let reference = if state.turn.sin.abs() > OPEN_MAX_TURN { [0.0; 2] } else { reference };
        let ([open_a, open_b], [va, vb], [ra, rb], [ia, ib]) = (&mut state.open_for, volts, reference, measured);
        looks_open(open_a, va, ra, ia, limit);
        looks_open(open_b, vb, rb, ib, limit);
        Some(bridge_shares(volts, v_bus))
    }
}

/// The damping's period ([`DAMPING_GAIN`]): the electrical power the windings took over the
/// period that just ended (its voltages and the currents at its end) against its mean moves the
/// commutation's angle for the next tick. Closed loop, the angle is left as the rotor sets it.
fn damp(state: &mut WindingState, measured: [f32; 2], v_bus: f32) {
    let [va, vb] = state.applied_mv.map(|mv| mv as f32 * 1e-3);
    let power = va * measured[0] + vb * measured[1];
    state.power_mean += POWER_MEAN_SHARE * (power - state.power_mean);
    let scale = v_bus * state.amps;
    if state.closed_loop || scale.is_nan() || scale <= 0.0 {
        state.damping = 0.0;
        return;
    }
    // The commanded turn of a period is `turn`'s angle (its sine: a few hundredths of a radian).
    let slow = DAMPING_GAIN * state.turn.sin * (power - state.power_mean) / scale;
    // Constant bounds: `clamp`'s check of their order folds away (no panic is linked).
    state.damping = (state.damping * (1.0 - DAMPING_LEAK) - slow).clamp(-DAMPING_MAX, DAMPING_MAX);
}

/// Takes one tick's outputs into `state` for the loop `settings` ([`WindingSettings::command`]),
/// or for none (a power-up tune that failed: an open winding, no motor): then the bridges stay
/// off, and while the tick asks a current both windings read open ([`WindingState::open`]), so
/// that the drive latches the phase loss (alarm 11).
pub fn command_or_open(settings: Option<&WindingSettings>, state: &mut WindingState, out: &Outputs) {
    match settings {
        Some(s) => s.command(state, out),
        None => state.asked_without_loop = out.enabled && out.current_ma != 0,
    }
}

/// The current loop as the drive's objects hold it, in their units (0x2108 R in mΩ, 0x2109 L in
/// µH, 0x210C KP in 0.1 V/A, 0x210D KI in 0.01 V/A a PWM period): what the platform reads at
/// power-up to run the loop without a tune, and writes back after one.
///
/// ```
/// use drive_core::windings::LoopObjects;
/// let tuned = LoopObjects { r_mohm: 1400, l_uh: 3000, kp: 300, ki: 30 }.settings(24.0, 20_000.0).unwrap();
/// assert!((tuned.current_loop().kp() - 30.0).abs() < 1e-6);
/// assert_eq!(LoopObjects::of(&tuned), LoopObjects { r_mohm: 1400, l_uh: 3000, kp: 300, ki: 30 });
/// ```
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LoopObjects {
    /// The winding's resistance, mΩ.
    pub r_mohm: u16,
    /// The winding's inductance, µH.
    pub l_uh: u16,
    /// The proportional gain, 0.1 V/A.
    pub kp: u16,
    /// The integral gain, 0.01 V/A a PWM period.
    pub ki: u16,
}

impl LoopObjects {
    /// The objects' ranges (0x2108/0x2109, 0x210C, 0x210D), which [`LoopObjects::of`] keeps to.
    const R_L: (u16, u16) = (10, 60_000);
    const KP: (u16, u16) = (50, 32_767);
    const KI: (u16, u16) = (10, 2_000);

    /// The loop these objects describe on a bus of `v_bus` V at `pwm_hz`, the board's dead time
    /// compensated.
    pub fn settings(&self, v_bus: f32, pwm_hz: f32) -> Result<WindingSettings, crate::current::Error> {
        let (r, l) = (f32::from(self.r_mohm) * 1e-3, f32::from(self.l_uh) * 1e-6);
        let current = CurrentLoopSettings::new(r, l, v_bus, pwm_hz, recommended_bandwidth(pwm_hz))?
            .with_gains(f32::from(self.kp) * 0.1, f32::from(self.ki) * 0.01)?
            .with_dead_time(DEAD_TIME_S, DEAD_BAND_A)?;
        Ok(WindingSettings::new(current))
    }

    /// The objects from their words: R, L, KP, KI (the dictionary's `CURRENT_LOOP_OBJECTS`).
    pub fn from_words([r_mohm, l_uh, kp, ki]: [u16; 4]) -> Self {
        Self { r_mohm, l_uh, kp, ki }
    }

    /// The objects' words, in the order [`LoopObjects::from_words`] takes them.
    pub fn words(&self) -> [u16; 4] {
        [self.r_mohm, self.l_uh, self.kp, self.ki]
    }

    /// The objects of `settings`, rounded into their units and ranges.
    pub fn of(settings: &WindingSettings) -> Self {
        let c = settings.current_loop();
        // Not `clamp`: with bounds it cannot prove ordered, that is a panic (and float formatting).
        let unit = |x: f32, (lo, hi): (u16, u16)| libm::roundf(x).max(f32::from(lo)).min(f32::from(hi)) as u16;
        Self {
            r_mohm: unit(c.resistance() * 1e3, Self::R_L),
            l_uh: unit(c.inductance() * 1e6, Self::R_L),
            kp: unit(c.kp() * 10.0, Self::KP),
            ki: unit(c.ki() * 100.0, Self::KI),
        }
    }
}

/// The widest the currents' zero may lie from the 12-bit ADC's mid-scale at power-up, codes
/// (0.2 V of 3.3 V): an op-amp's own offset is tens of codes at the board's gain of 8; an
/// amplifier or a shunt that has failed reads far off, or at a rail.
pub const SENSING_ZERO_WINDOW: u16 = 256;

/// Whether the current sensing passes its check at power-up: each phase's code at zero current
/// (`zero`, measured with the bridges off) within [`SENSING_ZERO_WINDOW`] of mid-scale. Else
/// the drive's sensing fault (`faults::Inputs::sensing_fault`).
///
/// ```
/// use drive_core::windings::sensing_ok;
/// assert!(sensing_ok([2048 + 7, 2048 - 5]));
/// assert!(!sensing_ok([2048, 4095]));
/// ```
pub fn sensing_ok(zero: [u16; 2]) -> bool {
    zero.iter().all(|z| z.abs_diff(2048) <= SENSING_ZERO_WINDOW)
}

/// The dead time the board's bridges have, s (`firmware/src/board/power_stage.rs`), which the
/// current loop compensates.
pub const DEAD_TIME_S: f32 = 300e-9;
/// The reference current over which the dead-time compensation fades, A: a few of the ADC's codes.
pub const DEAD_BAND_A: f32 = 0.05;

/// The windings' power-up auto-tune: [`Autotune`] on one winding, then the other, each on its
/// own bridge, a PWM period at a time (the other at 0 V); the loop's settings from their mean R
/// and L (one motor), at the recommended bandwidth and the board's dead time compensated.
///
/// One winding at a time: its current then holds the rotor on that winding's own axis whatever
/// its size, so the rotor stays still through the pulses. Both at once, the current vector's
/// angle swings with each pulse, the rotor follows it, and its back-EMF takes up to 7 % off the
/// inductance measured at 48 V (the simulator's NEMA 23).
#[derive(Clone, Debug)]
pub struct PowerUpTune {
    windings: [Autotune; 2],
    results: [Option<Result<Estimate, autotune::Error>>; 2],
    pwm_hz: f32,
    /// The bus at the last period, V: the loop's nominal one.
    v_bus: f32,
}

/// What the power-up tune does this period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TuneStep {
    /// Put these shares of the bus across the windings over the next period
    /// ([`bridge_shares`]).
    Apply([i16; 2]),
    /// Over (the bridges to 0 V): the loop's settings ([`WindingSettings::new`] takes them) and
    /// the two estimates, or why not.
    Done(Result<(CurrentLoopSettings, [Estimate; 2]), autotune::Error>),
}

impl PowerUpTune {
    /// A tune at `test_current_ma` (see [`Autotune::new`]: the upper level; the motor's rated
    /// current or under), at `pwm_hz`.
    pub fn new(test_current_ma: u16, pwm_hz: f32) -> Result<Self, autotune::Error> {
        let tune = Autotune::new(f32::from(test_current_ma) * 1e-3, pwm_hz)?;
        Ok(Self { windings: [tune.clone(), tune], results: [None; 2], pwm_hz, v_bus: 0.0 })
    }

    /// One PWM period from the currents sampled now and the bus.
    pub fn step(&mut self, phase_ma: [i32; 2], supply_mv: u32) -> TuneStep {
        let v_bus = supply_mv as f32 * 1e-3;
        self.v_bus = v_bus;
        let [tune_a, tune_b] = &mut self.windings;
        let [result_a, result_b] = &mut self.results;
        let [ma, mb] = phase_ma;
        let volts = match (&result_a, &result_b) {
            (None, _) => match tune_a.step(ma as f32 * 1e-3, v_bus) {
                Step::Apply(v) => [v, 0.0],
                Step::Done(done) => {
                    *result_a = Some(done);
                    [0.0; 2]
                }
            },
            (Some(Ok(_)), None) => match tune_b.step(mb as f32 * 1e-3, v_bus) {
                Step::Apply(v) => [0.0, v],
                Step::Done(done) => {
                    *result_b = Some(done);
                    [0.0; 2]
                }
            },
            _ => [0.0; 2],
        };
        match self.results {
            [Some(a), Some(b)] => TuneStep::Done(self.settings(a, b)),
            // A winding that failed ends the tune.
            [Some(Err(e)), _] => TuneStep::Done(Err(e)),
            _ => TuneStep::Apply(bridge_shares(volts, v_bus)),
        }
    }

    fn settings(
        &self,
        a: Result<Estimate, autotune::Error>,
        b: Result<Estimate, autotune::Error>,
    ) -> Result<(CurrentLoopSettings, [Estimate; 2]), autotune::Error> {
        let (a, b) = (a?, b?);
        let (r, l) = (0.5 * (a.resistance + b.resistance), 0.5 * (a.inductance + b.inductance));
        let current = CurrentLoopSettings::new(r, l, self.v_bus, self.pwm_hz, recommended_bandwidth(self.pwm_hz))
            .and_then(|s| s.with_dead_time(DEAD_TIME_S, DEAD_BAND_A))
            .map_err(|_| autotune::Error::OutOfRange)?;
        Ok((current, [a, b]))
    }
}

#[cfg(test)]
mod tests {
    use fixed::types::{U0F16, U0F32};

    use super::*;

    /// Outputs asking `ma` at microstep `whole` of 16 a step, turning at `velocity` microsteps/s.
    fn outputs(ma: u16, whole: i64, velocity: f32) -> Outputs {
        let at = Setpoint { whole, fraction: U0F32::ZERO, velocity, acceleration: 0.0 };
        Outputs {
            setpoint: at,
            commutation: at,
            steps: 0,
            current_ma: ma,
            enabled: ma > 0,
            coil_duty: 0,
            gpio: 0,
            pins: Default::default(),
            microsteps: 16,
            // The factory decay (0x6010 = 2): the loop's own gains.
            fast_decay: U0F16::from_bits(0xC000),
            pulse: Default::default(),
            closed_loop: false,
        }
    }

    /// The NEMA 17 (1.4 Ω, 3 mH) on 24 V.
    fn settings() -> WindingSettings {
        let pwm = 20_000.0;
        let current = CurrentLoopSettings::new(1.4, 3.0e-3, 24.0, pwm, crate::current::recommended_bandwidth(pwm));
        WindingSettings::new(current.unwrap_or_else(|e| unreachable!("{e:?}")))
    }

    #[test]
    fn the_reference_is_the_current_at_the_electrical_angle_and_off_clears_it() {
        let s = settings();
        let mut st = WindingState::default();
        // 8 microsteps of 16: half a full step, 45°.
        s.command(&mut st, &outputs(1000, -64 * 7 + 8, 0.0));
        let [a, b] = st.reference().unwrap_or_default();
        let half = core::f32::consts::FRAC_1_SQRT_2;
        assert!((a - half).abs() < 1e-4 && (b - half).abs() < 1e-4, "{a} {b}");
        assert!(s.period(&mut st, [0, 0], 24_000).is_some());
        s.command(&mut st, &outputs(0, 8, 0.0));
        assert_eq!(st, WindingState::default());
        assert_eq!(s.period(&mut st, [700, 700], 24_000), None);
    }

    #[test]
    fn an_open_winding_is_found_after_its_periods_at_the_limit() {
        let s = settings();
        let mut st = WindingState::default();
        s.command(&mut st, &outputs(1000, 0, 0.0));
        for k in 1..=OPEN_PERIODS + 2 {
            let _ = s.period(&mut st, [0, 0], 24_000);
            // Phase A at 1 A carries nothing; phase B's reference is 0: never open.
            assert_eq!(st.open(), [k >= OPEN_PERIODS, false], "period {k}");
        }
        // Its current back: no longer open.
        let _ = s.period(&mut st, [1000, 0], 24_000);
        assert_eq!(st.open(), [false, false]);
    }

    #[test]
    fn a_turning_back_emf_is_followed_without_knowing_the_motor() {
        // The winding model (zero-order hold, one period of delay) with 12 V of back-EMF turning
        // at 250 Hz electrical (5 turns a second of a 50-pole-pair motor): 1 A turning with it.
        let s = settings();
        let (r, l, t) = (1.4f32, 3.0e-3f32, 50e-6f32);
        let a = libm::expf(-r * t / l);
        let b = (1.0 - a) / r;
        let velocity = 5.0 * 200.0 * 16.0; // microsteps/s
        let omega = velocity * core::f32::consts::TAU / 64.0;
        let mut st = WindingState::default();
        let (mut i, mut acting) = ([0.0f32; 2], [0.0f32; 2]);
        let mut worst = 0.0f32;
        for k in 0..2_000u32 {
            let time = k as f32 * t;
            let whole = (velocity * time) as i64;
            s.command(&mut st, &outputs(1000, whole, velocity));
            let ma = i.map(|x| libm::roundf(x * 1e3) as i32);
            let next = s.period(&mut st, ma, 24_000).unwrap_or_default().map(|v| f32::from(v) * 24.0 / 32_768.0);
            let theta = omega * (time + 0.5 * t);
            let emf = [-12.0 * libm::sinf(theta), 12.0 * libm::cosf(theta)];
            i = [a * i[0] + b * (acting[0] - emf[0]), a * i[1] + b * (acting[1] - emf[1])];
            acting = next;
            if k > 1_000 {
                worst = worst.max((libm::hypotf(i[0], i[1]) - 1.0).abs());
            }
        }
        assert!(worst < 0.02, "{worst}");
    }

    #[test]
    fn the_damping_holds_the_field_back_while_the_power_rises_open_loop_only() {
        let s = settings();
        // Forward at 5 turns a second; then a period of 4 A against the loop's voltage: a power
        // far above its mean, the rotor falling behind.
        let run = |closed_loop: bool, velocity: f32| {
            let mut st = WindingState::default();
            let mut out = outputs(1000, 0, velocity);
            out.closed_loop = closed_loop;
            s.command(&mut st, &out);
            let _ = s.period(&mut st, [0, 0], 24_000);
            s.command(&mut st, &out);
            let _ = s.period(&mut st, [4000, 0], 24_000);
            st.damping
        };
        let held = run(false, 16_000.0);
        // ΔP ≈ 4 A · 24 V · 0.9, over 24 V · 1 A, times the turn of a period (0.079 rad) and g.
        assert!((-0.08..-0.06).contains(&held), "{held}");
        assert!(run(false, -16_000.0) > 0.06, "backwards: the angle moves the other way");
        assert_eq!(run(true, 16_000.0), 0.0, "closed loop: the rotor sets the angle");
        assert_eq!(run(false, 0.0), 0.0, "at rest: nothing to damp");
    }

    #[test]
    fn the_power_up_tune_measures_both_windings_and_sets_the_loop() {
        // Two windings of 1.4 Ω and 3 mH (the second 3 % off), 24 V, sensed to 5 mA.
        let (t, l) = (50e-6f32, [3.0e-3f32, 3.09e-3]);
        let mut tune = PowerUpTune::new(1000, 20_000.0).unwrap_or_else(|e| unreachable!("{e:?}"));
        let (mut i, mut acting) = ([0.0f32; 2], [0.0f32; 2]);
        let mut periods = 0u32;
        let (current, estimates) = loop {
            periods += 1;
            let ma = i.map(|x| 5 * libm::roundf(x * 200.0) as i32);
            let next = match tune.step(ma, 24_000) {
                TuneStep::Apply(shares) => shares.map(|s| f32::from(s) * 24.0 / 32_768.0),
                TuneStep::Done(done) => break done.unwrap_or_else(|e| unreachable!("{e:?}")),
            };
            for ((i, l), v) in i.iter_mut().zip(l).zip(acting) {
                let a = libm::expf(-1.4 * t / l);
                *i = a * *i + (1.0 - a) / 1.4 * v;
            }
            acting = next;
        };
        let loop_ = current;
        assert!((loop_.resistance() - 1.4).abs() < 0.03, "{}", loop_.resistance());
        assert!((loop_.inductance() - 3.045e-3).abs() < 0.05e-3, "{}", loop_.inductance());
        assert!((estimates[1].inductance / estimates[0].inductance - 1.03).abs() < 0.01, "{estimates:?}");
        assert!(periods < 25_000, "{periods} periods");
    }

    #[test]
    fn an_open_winding_fails_the_power_up_tune() {
        let mut tune = PowerUpTune::new(1000, 20_000.0).unwrap_or_else(|e| unreachable!("{e:?}"));
        let result = (0..40_000).find_map(|_| match tune.step([0, 0], 24_000) {
            TuneStep::Done(done) => Some(done.map(|_| ())),
            TuneStep::Apply(_) => None,
        });
        assert_eq!(result, Some(Err(autotune::Error::NoCurrent)));
    }

    #[test]
    fn the_decay_picks_the_loops_speed() {
        let s = settings();
        let factory = *s.current_loop();
        for (fast, k) in [(0x0000u16, 0.625f32), (0x8000, 0.8125), (0xC000, 1.0), (0xE000, 1.125)] {
            let mut st = WindingState::default();
            let mut out = outputs(100, 0, 0.0);
            out.fast_decay = U0F16::from_bits(fast);
            s.command(&mut st, &out);
            // From rest, the first period's voltage is the proportional step (no dead time here).
            let v = s.period(&mut st, [0, 0], 24_000).unwrap_or_default();
            // 0.1 A from rest: (kp + ki)·0.1 A, 4.9 V at the factory decay, within the bridge.
            let expected = (factory.kp() + factory.ki()) * k * 0.1 * 32_768.0 / 24.0;
            assert!((f32::from(v[0]) - expected).abs() < 2.0, "{fast:#x}: {v:?} {expected}");
        }
    }
}
