//! A physical two-phase hybrid stepper motor and its chopper driver, for the simulator.
//!
//! # The motor (Bodson, Chiasson, Novotnak, Rekowski, IEEE T-CST 1993)
//!
//! State: rotor angle θ (mechanical, rad), speed ω (rad/s), phase currents i_a, i_b (A). With N rotor
//! teeth (N = steps_per_rev / 4, 50 for a 1.8° motor), winding resistance R, inductance L, torque and
//! back-EMF constant K_m, inertia J = rotor + load, viscous friction B, detent amplitude K_d:
//!
//! ```text
//! L di_a/dt = v_a − R i_a + K_m ω sin(Nθ)
//! L di_b/dt = v_b − R i_b − K_m ω cos(Nθ)
//! J dω/dt   = −K_m i_a sin(Nθ) + K_m i_b cos(Nθ) − B ω − K_d sin(4Nθ) − τ_load − τ_c
//! dθ/dt     = ω
//! ```
//!
//! τ_c is Coulomb friction of magnitude `static_friction_nm + load_friction_nm`: while the rotor is
//! at rest it holds it as long as the other torques stay within that magnitude; while it turns it
//! opposes the motion with the same magnitude (a single static = kinetic level). τ_load is a constant
//! gravity-like torque ([`MotorInputs::load_torque_nm`]): it acts at rest as in motion, and a
//! positive value opposes positive rotation (a weight the motor lifts when it turns forwards).
//!
//! With the currents following i_a = I cos θe, i_b = I sin θe the electrical torque is
//! K_m I sin(θe − Nθ): the rotor settles where Nθ = θe, and one full step is θe += π/2
//! (θ += 2π / steps_per_rev). The largest static torque is K_m I, reached a full step away from
//! equilibrium. `motors.toml` explains how K_m follows from the datasheet holding torque.
//!
//! # The chopper (current-regulating H-bridge per phase)
//!
//! Each phase has an H-bridge on the supply V, switched at a PWM period T (25 µs, 40 kHz, by
//! default: [`ChopperConfig`]). The model is the period-averaged one: at the start of each period
//! the current loop picks the bridge voltage that brings the phase current exactly to its reference
//! i_ref = I cos θe (resp. I sin θe) at the end of the period, given the current it measures and
//! the back-EMF e at that moment (a dead-beat, cycle-by-cycle regulator, which is what a peak- or
//! average-current chopper achieves when the supply allows):
//!
//! ```text
//! v = e + R (i_ref − i·a) / (1 − a),   a = exp(−R T / L)      (exact solution of L di/dt = v − R i − e)
//! v = clamp(v, −V, +V)
//! ```
//!
//! and holds it for the period. The clamp is the point: at speed the back-EMF K_m ω and the
//! reactance ωN·L ask for more than the supply can give, the current falls behind and below its
//! reference, the torque falls with speed, and past the pull-out torque the motor loses steps.
//! Only θe mod 2π matters to the chopper: callers should pass it wrapped (see
//! [`DriverCommand::at_microstep`]) so that it keeps its precision on long moves.
//!
//! Disabled, the bridge is off: each phase current decays through the freewheel diodes against the
//! supply (v = −V·sign(i)) until it reaches zero, where the diodes block it; a back-EMF above the
//! supply drives current back into it through the same diodes. There is no torque then but detent,
//! friction and the load.
//!
//! # The bridges instead of the chopper
//!
//! [`Motor::advance_bridges`] takes the voltages of a model of the board's power stage
//! ([`crate::bridges`]) in place of the dead-beat regulator: held over each PWM period, the
//! supply clamping them, the dead time's loss against the current each sub-step, and the
//! comparators' trip (both bridges off, the current cut at the threshold) checked after each.
//!
//! # Injected faults
//!
//! [`PhaseFault::Open`]: the winding carries no current whatever the bridge does; its terminals
//! show the back-EMF. [`PhaseFault::Short`]: the bridge output is shorted (0.1 Ω, 5 µH of wiring),
//! so the bridge current, which the drive measures, is limited by nothing but that and the supply,
//! and the winding, bypassed, makes no torque. [`Motor::set_blocked`]: the rotor is held where it
//! is (a jammed load), whatever the torque.
//!
//! # What the drive measures of the bridge
//!
//! [`Motor::take_bridge_means`] gives the bridge voltages and the summed squared bridge currents
//! averaged since its last call (the drive takes them once a control tick). The voltage is what
//! the drive knows from its PWM duties and the supply: while the bridge drives, the voltage it
//! applies (even into an open or shorted output); while it is off, ∓V through the freewheel
//! diodes while a current flows, and 0 when none does (the terminals then float at the back-EMF,
//! which no duty tells).
//!
//! # Integration
//!
//! Sub-steps of T / [`ChopperConfig::substeps`] (12.5 µs, 80 kHz, by default). The bridge voltage is
//! held over each sub-step, and the back-EMF is taken at its start, so the currents are advanced by
//! the exact solution of the linear equation, i ← i_∞ + (i − i_∞)·exp(−R h / L) with
//! i_∞ = (v − e) / R: stable for any L/R. Then ω and θ by semi-implicit (symplectic) Euler, with the
//! torque from the new currents: ω ← ω + h·τ/J, θ ← θ + h·ω.
//!
//! # Multi-turn position
//!
//! The angle is kept as a whole-turn counter (`i64`) plus the angle within the turn in [0, 2π), not
//! as one unbounded `f64`. An `f64` angle would represent positions well enough for a long time
//! (at 10⁶ turns its resolution is still ~10⁻⁹ rad against 1.2·10⁻⁴ rad for a 1/256 microstep) but
//! every sub-step adds h·ω to it, and the rounding of that addition, and of sin(Nθ)'s argument,
//! grows with the distance travelled: after a day at 20 rev/s (1.7·10⁶ turns, 7·10⁹ sub-steps) a
//! rounding bias could add up to radians. With the split, every sub-step works on a small angle
//! with constant precision, and [`Motor::rotor_microsteps`] is exact to well below a microstep up
//! to 2⁵³ microsteps (far past 2³¹: 1.7·10¹¹ turns at 1/256).

use std::f64::consts::{FRAC_PI_2, TAU};
use std::fmt;
use std::path::Path;

use serde::Deserialize;

/// The built-in motor catalogue: `hal-sim/motors.toml`, compiled in.
pub const BUILTIN_CATALOG_TOML: &str = include_str!("../motors.toml");

/// A motor's constants, as a datasheet gives them (see `motors.toml` for each figure's source).
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MotorParams {
    /// The motor's part number, e.g. `17HS19-2004S1`.
    pub name: String,
    /// Phase winding resistance R, Ω.
    pub r_ohm: f64,
    /// Phase winding inductance L, H.
    pub l_henry: f64,
    /// Torque constant K_m, N·m/A (equal to the back-EMF constant in V·s/rad).
    pub km_nm_per_a: f64,
    /// Rotor moment of inertia, kg·m².
    pub rotor_inertia_kgm2: f64,
    /// Detent (cogging) torque amplitude K_d, N·m: the unpowered torque −K_d sin(4Nθ).
    pub detent_nm: f64,
    /// Viscous friction coefficient B, N·m·s/rad.
    pub viscous_nms: f64,
    /// Coulomb friction of the motor itself (bearings), N·m: static and kinetic.
    pub static_friction_nm: f64,
    /// Rated phase current, A.
    pub rated_current_a: f64,
    /// Datasheet holding torque, N·m, both phases at rated current. For reference and checks: the
    /// model uses [`MotorParams::km_nm_per_a`].
    pub holding_torque_nm: f64,
    /// Full steps per revolution (200 for 1.8°): four per rotor tooth.
    #[serde(default = "default_steps_per_rev")]
    pub steps_per_rev: u32,
}

fn default_steps_per_rev() -> u32 {
    200
}

impl MotorParams {
    /// The number of rotor teeth N (pole pairs of the electrical cycle): `steps_per_rev / 4`.
    pub fn rotor_teeth(&self) -> f64 {
        f64::from(self.steps_per_rev / 4)
    }

    /// The largest static torque of a microstepping drive at current amplitude `current` (A):
    /// K_m · I, reached one full step away from the commanded position.
    pub fn peak_static_torque(&self, current: f64) -> f64 {
        self.km_nm_per_a * current
    }

    /// Checks that the figures make a motor the model can run: positive R, L, K_m, inertia and
    /// rated current, non-negative detent and frictions, `steps_per_rev` a non-zero multiple of 4.
    pub fn validate(&self) -> Result<(), CatalogError> {
        let bad = |what: &str| Err(CatalogError::Invalid(format!("motor {:?}: {what}", self.name)));
        let positive = [
            ("r_ohm", self.r_ohm),
            ("l_henry", self.l_henry),
            ("km_nm_per_a", self.km_nm_per_a),
            ("rotor_inertia_kgm2", self.rotor_inertia_kgm2),
            ("rated_current_a", self.rated_current_a),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return bad(&format!("{field} must be a positive number, not {v}"));
            }
        }
        let non_negative = [
            ("detent_nm", self.detent_nm),
            ("viscous_nms", self.viscous_nms),
            ("static_friction_nm", self.static_friction_nm),
            ("holding_torque_nm", self.holding_torque_nm),
        ];
        for (field, v) in non_negative {
            if !(v.is_finite() && v >= 0.0) {
                return bad(&format!("{field} must be zero or positive, not {v}"));
            }
        }
        if self.steps_per_rev == 0 || !self.steps_per_rev.is_multiple_of(4) {
            return bad(&format!("steps_per_rev must be a non-zero multiple of 4, not {}", self.steps_per_rev));
        }
        Ok(())
    }
}

/// Why a motor catalogue could not be loaded.
#[derive(Debug)]
pub enum CatalogError {
    /// The file could not be read.
    Io(std::io::Error),
    /// The file is not a valid catalogue (TOML syntax, unknown or missing fields).
    Parse(toml::de::Error),
    /// A motor's figures are out of range, or two motors share a name.
    Invalid(String),
}

impl fmt::Display for CatalogError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io(e) => write!(f, "cannot read the motor catalogue: {e}"),
            Self::Parse(e) => write!(f, "bad motor catalogue: {e}"),
            Self::Invalid(what) => write!(f, "bad motor catalogue: {what}"),
        }
    }
}

impl std::error::Error for CatalogError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Io(e) => Some(e),
            Self::Parse(e) => Some(e),
            Self::Invalid(_) => None,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CatalogFile {
    motor: Vec<MotorParams>,
}

/// A list of motors, read from a TOML file of `[[motor]]` tables (the format of `motors.toml`).
#[derive(Clone, Debug, PartialEq)]
pub struct MotorCatalog {
    motors: Vec<MotorParams>,
}

impl MotorCatalog {
    /// The catalogue compiled into the simulator (`hal-sim/motors.toml`).
    pub fn builtin() -> Self {
        Self::from_toml_str(BUILTIN_CATALOG_TOML).expect("the built-in motors.toml is valid")
    }

    /// Parses and validates a catalogue.
    pub fn from_toml_str(text: &str) -> Result<Self, CatalogError> {
        let file: CatalogFile = toml::from_str(text).map_err(CatalogError::Parse)?;
        for (k, m) in file.motor.iter().enumerate() {
            m.validate()?;
            if file.motor[..k].iter().any(|other| other.name.eq_ignore_ascii_case(&m.name)) {
                return Err(CatalogError::Invalid(format!("motor {:?} appears twice", m.name)));
            }
        }
        Ok(Self { motors: file.motor })
    }

    /// Reads, parses and validates a catalogue file.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, CatalogError> {
        Self::from_toml_str(&std::fs::read_to_string(path).map_err(CatalogError::Io)?)
    }

    /// The motor of that name (ASCII case ignored).
    pub fn get(&self, name: &str) -> Option<&MotorParams> {
        self.motors.iter().find(|m| m.name.eq_ignore_ascii_case(name))
    }

    /// All motors, in file order.
    pub fn motors(&self) -> &[MotorParams] {
        &self.motors
    }
}

/// The run-time conditions around the motor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MotorInputs {
    /// The bridge supply voltage, V: the most either phase can be driven with.
    pub supply_v: f64,
    /// Load inertia seen at the motor shaft, kg·m², added to the rotor's.
    pub load_inertia_kgm2: f64,
    /// Constant (gravity-like) load torque, N·m: acts at rest and in motion; positive opposes
    /// positive rotation, and a load above the holding torque back-drives the motor.
    pub load_torque_nm: f64,
    /// Extra Coulomb friction of the load, N·m, added to the motor's own: it only ever opposes
    /// motion (and holds the rotor at rest up to that level).
    pub load_friction_nm: f64,
}

impl Default for MotorInputs {
    /// 24 V, no load.
    fn default() -> Self {
        Self { supply_v: 24.0, load_inertia_kgm2: 0.0, load_torque_nm: 0.0, load_friction_nm: 0.0 }
    }
}

/// The chopper's timing.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChopperConfig {
    /// PWM period T, s: the bridge voltages are decided at the start of each period and held.
    pub pwm_period_s: f64,
    /// Integration sub-steps per PWM period (at least 1).
    pub substeps: u32,
}

impl Default for ChopperConfig {
    /// 40 kHz PWM (25 µs), two sub-steps a period: the model integrates at 80 kHz (12.5 µs).
    fn default() -> Self {
        Self { pwm_period_s: 25e-6, substeps: 2 }
    }
}

/// What the drive asks of the chopper.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriverCommand {
    /// Commanded electrical angle θe, rad: the currents follow I cos θe, I sin θe. One full step is
    /// π/2. Only its value modulo 2π matters.
    pub theta_e: f64,
    /// Current amplitude I, A (peak per phase).
    pub current: f64,
    /// Whether the bridges are on. Off: the currents freewheel to zero; no torque but detent.
    pub enabled: bool,
    /// The share of fast decay in the chopper's off-time, 0..=1: when a phase current must
    /// fall, the bridge can reverse at most this share of the supply across the winding (fast
    /// decay); the rest of the time it shorts it (slow decay). 1 is the ideal chopper.
    pub fast_decay: f64,
}

impl DriverCommand {
    /// Bridges off.
    pub const DISABLED: Self = Self { theta_e: 0.0, current: 0.0, enabled: false, fast_decay: 1.0 };

    /// Bridges on, holding or moving to the microstep `position` (counted from the start, where
    /// θe = 0), with `microsteps_per_step` microsteps per full step, at current amplitude `current`.
    /// The angle is reduced modulo one electrical cycle (4 full steps) in integers first, so it is
    /// exact at any position.
    pub fn at_microstep(position: i64, microsteps_per_step: u32, current: f64) -> Self {
        let cycle = 4 * i64::from(microsteps_per_step.max(1));
        let in_cycle = position.rem_euclid(cycle);
        Self {
            theta_e: in_cycle as f64 * FRAC_PI_2 / f64::from(microsteps_per_step.max(1)),
            current,
            enabled: true,
            fast_decay: 1.0,
        }
    }

    /// Bridges on at the electrical angle of a fractional full-step position (`full_steps` × π/2,
    /// reduced modulo 4 full steps first), at current amplitude `current`.
    pub fn at_full_steps(full_steps: f64, current: f64) -> Self {
        Self { theta_e: full_steps.rem_euclid(4.0) * FRAC_PI_2, current, enabled: true, fast_decay: 1.0 }
    }
}

/// What the bridges apply over a PWM period when a bridge model drives the motor
/// ([`Motor::advance_bridges`], [`crate::bridges`]) instead of the ideal chopper.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BridgeVolts {
    /// The mean voltage across each winding over the period as the PWM duties set it, V (the
    /// supply clamps it); `None`: the bridges are off (the currents freewheel through the diodes).
    pub volts: Option<[f64; 2]>,
    /// The voltage the dead time takes off each winding against its current, V (faded over
    /// [`DEAD_FADE_A`] around zero, where the PWM's ripple crosses it).
    pub dead_volts: f64,
    /// The bridge current beyond which the comparator trips, A: both bridges off from that
    /// sub-step on, the current cut at the threshold.
    pub trip_a: f64,
}

/// The current around zero over which the dead time's loss fades (the PWM's current ripple).
pub const DEAD_FADE_A: f64 = 0.02;

/// How the windings are driven over a sub-step.
#[derive(Clone, Copy, Debug)]
enum Regulation<'a> {
    /// The ideal chopper of the module documentation.
    Chopper(&'a DriverCommand),
    /// The voltages of a bridge model.
    Bridges(&'a BridgeVolts),
}

/// Averages over an interval of what the drive knows of its bridges ([`Motor::take_bridge_means`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BridgeMeans {
    /// Mean voltage applied to phases A and B, V.
    pub volts: [f64; 2],
    /// Mean of i_a² + i_b² (bridge currents), A².
    pub current_sq: f64,
}

/// What is wrong with one phase's winding or wiring (see the module documentation).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PhaseFault {
    /// Healthy.
    #[default]
    None,
    /// The winding is open (broken wire, unplugged).
    Open,
    /// The bridge output is shorted (across the winding, or a winding short).
    Short,
}

/// Resistance of a shorted bridge output, Ω.
const SHORT_OHM: f64 = 0.1;
/// Inductance of a shorted bridge output, H.
const SHORT_HENRY: f64 = 5e-6;

/// One simulated motor with its chopper driver. See the module documentation for the model.
#[derive(Clone, Debug)]
pub struct Motor {
    params: MotorParams,
    inputs: MotorInputs,
    chopper: ChopperConfig,
    // Derived from the above.
    teeth: f64,
    h: f64,
    decay_h: f64,
    decay_pwm: f64,
    inertia: f64,
    // State.
    turns: i64,
    angle: f64,
    omega: f64,
    i_a: f64,
    i_b: f64,
    v_a: f64,
    v_b: f64,
    bridge_on: bool,
    /// The voltages the bridges apply over the present PWM period, as the drive commands them.
    bridge_v: [f64; 2],
    /// Since the last [`Motor::take_bridge_means`]: ∫ the drive's known bridge voltage dt per
    /// phase, ∫ (i_a² + i_b²) dt, and the time.
    v_integral: [f64; 2],
    current_sq_integral: f64,
    integral_s: f64,
    torque_e: f64,
    substep: u64,
    carry_s: f64,
    // Injected faults.
    phase_faults: [PhaseFault; 2],
    blocked: bool,
    /// Hard stops, full steps: the rotor cannot go below the first or above the second.
    hard_stops: (Option<f64>, Option<f64>),
    short_decay_h: f64,
    /// The phase whose current tripped the comparator since the last [`Motor::advance_bridges`].
    tripped: Option<usize>,
}

impl Motor {
    /// A motor at rest at θ = 0 (on a full step), no current, with the default chopper (40 kHz,
    /// 80 kHz integration).
    pub fn new(params: MotorParams, inputs: MotorInputs) -> Self {
        Self::with_chopper(params, inputs, ChopperConfig::default())
    }

    /// A motor at rest at θ = 0 with the given chopper timing.
    ///
    /// # Panics
    /// If the parameters do not [validate](MotorParams::validate), or the PWM period is not
    /// positive.
    pub fn with_chopper(params: MotorParams, inputs: MotorInputs, chopper: ChopperConfig) -> Self {
        if let Err(e) = params.validate() {
            panic!("{e}");
        }
        assert!(chopper.pwm_period_s > 0.0 && chopper.pwm_period_s.is_finite(), "PWM period must be positive");
        let chopper = ChopperConfig { substeps: chopper.substeps.max(1), ..chopper };
        let mut motor = Self {
            teeth: params.rotor_teeth(),
            h: 0.0,
            decay_h: 0.0,
            decay_pwm: 0.0,
            inertia: 0.0,
            params,
            inputs,
            chopper,
            turns: 0,
            angle: 0.0,
            omega: 0.0,
            i_a: 0.0,
            i_b: 0.0,
            v_a: 0.0,
            v_b: 0.0,
            bridge_on: false,
            bridge_v: [0.0; 2],
            v_integral: [0.0; 2],
            current_sq_integral: 0.0,
            integral_s: 0.0,
            torque_e: 0.0,
            substep: 0,
            carry_s: 0.0,
            phase_faults: [PhaseFault::None; 2],
            blocked: false,
            hard_stops: (None, None),
            short_decay_h: 0.0,
            tripped: None,
        };
        motor.derive();
        motor
    }

    fn derive(&mut self) {
        let p = &self.params;
        self.h = self.chopper.pwm_period_s / f64::from(self.chopper.substeps);
        self.decay_h = (-p.r_ohm * self.h / p.l_henry).exp();
        self.decay_pwm = (-p.r_ohm * self.chopper.pwm_period_s / p.l_henry).exp();
        self.inertia = p.rotor_inertia_kgm2 + self.inputs.load_inertia_kgm2.max(0.0);
        self.short_decay_h = (-SHORT_OHM * self.h / SHORT_HENRY).exp();
    }

    /// Injects a fault into phase A (`phase` 0) or B (1) from now on; `PhaseFault::None` repairs it.
    pub fn set_phase_fault(&mut self, phase: usize, fault: PhaseFault) {
        if let Some(f) = self.phase_faults.get_mut(phase) {
            *f = fault;
        }
    }

    /// The faults of phases A and B.
    pub fn phase_faults(&self) -> [PhaseFault; 2] {
        self.phase_faults
    }

    /// Holds the rotor where it is (`true`, a blocked rotor) or lets it go.
    pub fn set_blocked(&mut self, blocked: bool) {
        self.blocked = blocked;
        if blocked {
            self.omega = 0.0;
        }
    }

    /// Whether the rotor is held.
    pub fn blocked(&self) -> bool {
        self.blocked
    }

    /// Puts hard stops at `low` and `high` full steps from the start (either may be absent): the
    /// rotor meets them and stays there, at no speed, while the torque pushes it on (an
    /// inelastic end stop, as a machine's frame).
    pub fn set_hard_stops(&mut self, low: Option<f64>, high: Option<f64>) {
        self.hard_stops = (low, high);
    }

    /// At a hard stop: the rotor back on it, its speed into it gone.
    fn meet_hard_stops(&mut self) {
        let position = self.rotor_full_steps();
        let stop = match self.hard_stops {
            (Some(low), _) if position < low => low,
            (_, Some(high)) if position > high => high,
            _ => return,
        };
        let spr = f64::from(self.params.steps_per_rev);
        let turns = (stop / spr).floor();
        self.turns = turns as i64;
        self.angle = ((stop - turns * spr) * TAU / spr).clamp(0.0, TAU * (1.0 - f64::EPSILON));
        self.omega = 0.0;
    }

    /// Whether the bridges drove the phases over the last sub-step.
    pub fn bridge_on(&self) -> bool {
        self.bridge_on
    }

    /// The motor's constants.
    pub fn params(&self) -> &MotorParams {
        &self.params
    }

    /// The run-time conditions.
    pub fn inputs(&self) -> MotorInputs {
        self.inputs
    }

    /// Changes the run-time conditions (supply, load) from now on; the state is kept.
    pub fn set_inputs(&mut self, inputs: MotorInputs) {
        self.inputs = inputs;
        self.derive();
    }

    /// The chopper timing.
    pub fn chopper(&self) -> ChopperConfig {
        self.chopper
    }

    /// Changes the PWM period and sub-steps (for a bridge model at the board's PWM rate): only
    /// before the motor first advances, so that the periods start at time 0.
    ///
    /// # Panics
    /// If the PWM period is not positive.
    pub fn set_chopper(&mut self, chopper: ChopperConfig) {
        assert!(chopper.pwm_period_s > 0.0 && chopper.pwm_period_s.is_finite(), "PWM period must be positive");
        self.chopper = ChopperConfig { substeps: chopper.substeps.max(1), ..chopper };
        self.derive();
    }

    /// The integration sub-step, s.
    pub fn substep_s(&self) -> f64 {
        self.h
    }

    /// Simulated time since the start, s.
    pub fn time_s(&self) -> f64 {
        self.substep as f64 * self.h
    }

    /// Advances the model by `duration` seconds with the drive's command held. Time goes in whole
    /// sub-steps; what is left over is carried to the next call, so many short calls add up exactly.
    pub fn advance(&mut self, cmd: &DriverCommand, duration: f64) {
        let total = self.carry_s + duration.max(0.0);
        // The small tolerance makes 100 µs at 12.5 µs sub-steps 8 sub-steps, not 7 and a remainder.
        let n = ((total / self.h) + 1e-9).floor();
        self.carry_s = (total - n * self.h).max(0.0);
        self.advance_substeps(cmd, n as u64);
    }

    /// Advances the model by `n` integration sub-steps with the drive's command held.
    pub fn advance_substeps(&mut self, cmd: &DriverCommand, n: u64) {
        for _ in 0..n {
            self.substep(Regulation::Chopper(cmd));
        }
    }

    /// Advances the model by `duration` seconds (whole sub-steps, the rest carried as in
    /// [`Motor::advance`]) with the bridges' voltages `bridges` instead of the chopper: taken at
    /// the start of each PWM period, the dead time's loss against the current each sub-step, the
    /// comparator checked after each. The phase that tripped the comparator, if one did (both
    /// bridges are then off for the rest of the call).
    pub fn advance_bridges(&mut self, bridges: &BridgeVolts, duration: f64) -> Option<usize> {
        let total = self.carry_s + duration.max(0.0);
        let n = ((total / self.h) + 1e-9).floor();
        self.carry_s = (total - n * self.h).max(0.0);
        self.tripped = None;
        for _ in 0..n as u64 {
            self.substep(Regulation::Bridges(bridges));
        }
        self.tripped.take()
    }

    fn substep(&mut self, reg: Regulation<'_>) {
        let p = &self.params;
        let km = p.km_nm_per_a;
        let (s, c) = (self.teeth * self.angle).sin_cos();
        // Back-EMF as a voltage opposing the drive: L di/dt = v − R i − e.
        let e_a = -km * self.omega * s;
        let e_b = km * self.omega * c;
        let supply = self.inputs.supply_v.max(0.0);

        let period_start = self.substep.is_multiple_of(u64::from(self.chopper.substeps));
        let (cmd, dead_volts) = match reg {
            Regulation::Chopper(cmd) => (Some(cmd), 0.0),
            Regulation::Bridges(b) => {
                if period_start {
                    // Until the period's end, unless the comparator trips first.
                    self.bridge_on = b.volts.is_some() && self.tripped.is_none();
                    if let (true, Some([va, vb])) = (self.bridge_on, b.volts) {
                        self.v_a = va.clamp(-supply, supply);
                        self.v_b = vb.clamp(-supply, supply);
                        self.bridge_v = [self.v_a, self.v_b];
                    }
                }
                (None, b.dead_volts)
            }
        };
        if let (true, Some(cmd)) = (period_start, cmd) {
            // Start of a PWM period: the current loop decides the bridge voltages.
            self.bridge_on = cmd.enabled;
            if cmd.enabled {
                let (se, ce) = cmd.theta_e.sin_cos();
                let a = self.decay_pwm;
                // Driving the current down (against its sign) only fast decay reverses the supply.
                let down = supply * cmd.fast_decay.clamp(0.0, 1.0);
                let dead_beat = |i_ref: f64, i: f64, e: f64| {
                    let v = e + p.r_ohm * (i_ref - i * a) / (1.0 - a);
                    if v * i < 0.0 { v.clamp(-down, down) } else { v.clamp(-supply, supply) }
                };
                self.v_a = dead_beat(cmd.current * ce, self.i_a, e_a);
                self.v_b = dead_beat(cmd.current * se, self.i_b, e_b);
                self.bridge_v = [self.v_a, self.v_b];
            }
        }
        let (i_a0, i_b0) = (self.i_a, self.i_b);

        let [fault_a, fault_b] = self.phase_faults;
        let (short_decay, bridge_on) = (self.short_decay_h, self.bridge_on);
        let phase = |i: f64, v: &mut f64, e: f64, fault: PhaseFault| {
            // A shorted output is a bare R-L with no back-EMF; an open winding carries nothing.
            let (r, d, e) = match fault {
                PhaseFault::None => (p.r_ohm, self.decay_h, e),
                PhaseFault::Short => (SHORT_OHM, short_decay, 0.0),
                PhaseFault::Open => {
                    *v = e.clamp(-supply, supply);
                    return 0.0;
                }
            };
            if bridge_on {
                // The dead time: while both switches of a leg are off, the diode the current
                // flows through sets the leg's voltage, against the current.
                let loss = dead_volts * (i / DEAD_FADE_A).clamp(-1.0, 1.0);
                let i_inf = (*v - loss - e) / r;
                i_inf + (i - i_inf) * d
            } else {
                *v = freewheel_voltage(i, e, supply);
                freewheel(i, *v, e, r, d)
            }
        };
        self.i_a = phase(self.i_a, &mut self.v_a, e_a, fault_a);
        self.i_b = phase(self.i_b, &mut self.v_b, e_b, fault_b);
        if let Regulation::Bridges(b) = reg
            && self.bridge_on
        {
            // The comparators on the shunts: beyond the threshold the break input clears both
            // timers' outputs within the sub-step; the current is cut where it crossed. They see
            // the PWM's ripple, which the period-averaged currents do not carry: centre-aligned,
            // the winding gets ±V for D·T/2 twice a period, D = |v|/V, so the current swings
            // V·D·(1 − D)·T/(2L) peak to peak about its mean (50 mA at most in a 3 mH winding
            // at 24 V, 7 A in a shorted output's 5 µH at D = 0.06).
            let t = self.chopper.pwm_period_s;
            for (k, fault) in [fault_a, fault_b].into_iter().enumerate() {
                let henry = match fault {
                    PhaseFault::None => p.l_henry,
                    PhaseFault::Short => SHORT_HENRY,
                    PhaseFault::Open => continue,
                };
                let share = self.bridge_v.get(k).map_or(0.0, |v| (v.abs() / supply.max(1e-9)).min(1.0));
                let half_ripple = supply * share * (1.0 - share) * t / (4.0 * henry);
                let i = if k == 0 { &mut self.i_a } else { &mut self.i_b };
                if i.abs() + half_ripple > b.trip_a {
                    *i = (b.trip_a - half_ripple).max(0.0).copysign(*i);
                    self.tripped.get_or_insert(k);
                }
            }
            if self.tripped.is_some() {
                self.bridge_on = false;
            }
        }
        let known = |i0: f64, v: f64, commanded: f64| {
            if self.bridge_on {
                commanded
            } else if i0 != 0.0 {
                v
            } else {
                0.0
            }
        };
        let [va, vb] = self.bridge_v;
        self.v_integral[0] += self.h * known(i_a0, self.v_a, va);
        self.v_integral[1] += self.h * known(i_b0, self.v_b, vb);
        // Trapezoid over the sub-step.
        let sq = |i0: f64, i1: f64| 0.5 * (i0 * i0 + i1 * i1);
        self.current_sq_integral += self.h * (sq(i_a0, self.i_a) + sq(i_b0, self.i_b));
        self.integral_s += self.h;

        // Mechanics, with the new currents: semi-implicit Euler. A bypassed winding makes no torque.
        let torque_current = |i: f64, fault: PhaseFault| if fault == PhaseFault::Short { 0.0 } else { i };
        self.torque_e = km * (-torque_current(self.i_a, fault_a) * s + torque_current(self.i_b, fault_b) * c);
        // sin(4x) from sin x, cos x: 2 sin 2x cos 2x.
        let detent = -p.detent_nm * 2.0 * (2.0 * s * c) * (c * c - s * s);
        let torque = self.torque_e + detent - p.viscous_nms * self.omega - self.inputs.load_torque_nm;
        let coulomb = p.static_friction_nm + self.inputs.load_friction_nm.max(0.0);
        let j = self.inertia;
        if self.blocked {
            self.omega = 0.0;
        } else if self.omega == 0.0 {
            // At rest: friction holds the rotor as long as it can.
            if torque.abs() > coulomb {
                self.omega = self.h * (torque - coulomb.copysign(torque)) / j;
            }
        } else {
            let omega = self.omega + self.h * (torque - coulomb.copysign(self.omega)) / j;
            // Friction cannot reverse the motion: crossing zero, the rotor stops (and sticks, if
            // friction can hold it on the next sub-step).
            self.omega = if omega * self.omega < 0.0 { 0.0 } else { omega };
        }
        self.angle += self.h * self.omega;
        if !(0.0..TAU).contains(&self.angle) {
            let whole = (self.angle / TAU).floor();
            self.turns += whole as i64;
            self.angle -= whole * TAU;
            // Rounding can leave exactly TAU or a hair below zero.
            if self.angle >= TAU {
                self.angle -= TAU;
                self.turns += 1;
            } else if self.angle < 0.0 {
                self.angle += TAU;
                self.turns -= 1;
            }
        }
        if self.hard_stops != (None, None) {
            self.meet_hard_stops();
        }
        self.substep += 1;
    }

    /// Rotor position in microsteps from the start (θ = 0), with `microsteps_per_step` per full
    /// step. Positive in the direction of increasing θe.
    pub fn rotor_microsteps(&self, microsteps_per_step: u32) -> f64 {
        self.rotor_full_steps() * f64::from(microsteps_per_step)
    }

    /// Rotor position in full steps from the start.
    pub fn rotor_full_steps(&self) -> f64 {
        let spr = f64::from(self.params.steps_per_rev);
        self.turns as f64 * spr + self.angle * spr / TAU
    }

    /// Whole turns made from the start (floor: −1 just below the start).
    pub fn turns(&self) -> i64 {
        self.turns
    }

    /// The rotor angle within the current turn, [0, 2π) rad.
    pub fn angle_in_turn(&self) -> f64 {
        self.angle
    }

    /// The rotor angle θ from the start, rad (turns · 2π + angle in the turn). Loses resolution on
    /// very long runs; [`Motor::rotor_microsteps`] does not.
    pub fn theta(&self) -> f64 {
        self.turns as f64 * TAU + self.angle
    }

    /// Rotor speed ω, rad/s.
    pub fn omega(&self) -> f64 {
        self.omega
    }

    /// Rotor speed, revolutions per second.
    pub fn speed_rps(&self) -> f64 {
        self.omega / TAU
    }

    /// Rotor speed in microsteps per second, with `microsteps_per_step` per full step.
    pub fn speed_microsteps_per_s(&self, microsteps_per_step: u32) -> f64 {
        self.speed_rps() * f64::from(self.params.steps_per_rev) * f64::from(microsteps_per_step)
    }

    /// The rotor's electrical angle Nθ reduced to [0, 2π): where θe would have to be for zero
    /// torque (stable equilibrium).
    pub fn electrical_angle(&self) -> f64 {
        (self.teeth * self.angle).rem_euclid(TAU)
    }

    /// Phase currents (i_a, i_b), A.
    pub fn phase_currents(&self) -> (f64, f64) {
        (self.i_a, self.i_b)
    }

    /// The bridge voltages (v_a, v_b) applied over the last sub-step, V.
    pub fn phase_voltages(&self) -> (f64, f64) {
        (self.v_a, self.v_b)
    }

    /// The bridge voltages as the drive knows them and i_a² + i_b², averaged since the last call
    /// (see the module documentation); zeros if no time has passed.
    pub fn take_bridge_means(&mut self) -> BridgeMeans {
        let t = core::mem::take(&mut self.integral_s);
        let [va, vb] = core::mem::take(&mut self.v_integral);
        let sq = core::mem::take(&mut self.current_sq_integral);
        if t > 0.0 { BridgeMeans { volts: [va / t, vb / t], current_sq: sq / t } } else { BridgeMeans::default() }
    }

    /// Electrical torque K_m(−i_a sin Nθ + i_b cos Nθ) of the last sub-step, N·m.
    pub fn electrical_torque(&self) -> f64 {
        self.torque_e
    }

    /// Puts the rotor at `full_steps` from the start (θ = full_steps · 2π / steps_per_rev) at rest,
    /// with no current. For tests and scenario set-up.
    pub fn reset_at_full_steps(&mut self, full_steps: f64) {
        let spr = f64::from(self.params.steps_per_rev);
        let turns = (full_steps / spr).floor();
        self.turns = turns as i64;
        self.angle = ((full_steps - turns * spr) / spr * TAU).clamp(0.0, TAU.next_down());
        self.omega = 0.0;
        self.i_a = 0.0;
        self.i_b = 0.0;
        self.v_a = 0.0;
        self.v_b = 0.0;
        self.torque_e = 0.0;
    }
}

/// The bridge-off terminal voltage of one phase: the freewheel diodes clamp it to the supply.
fn freewheel_voltage(i: f64, e: f64, supply: f64) -> f64 {
    if i != 0.0 {
        // Current flows back to the supply through the diodes, against it.
        -supply.copysign(i)
    } else {
        // Open winding: the terminals show the back-EMF, which the diodes clamp.
        e.clamp(-supply, supply)
    }
}

/// One bridge-off sub-step of one phase: exact exponential towards (v − e)/R, stopping at zero
/// where the diodes block a current that would reverse.
fn freewheel(i: f64, v: f64, e: f64, r: f64, decay: f64) -> f64 {
    let i_inf = (v - e) / r;
    let next = i_inf + (i - i_inf) * decay;
    if i != 0.0 && next * i < 0.0 { 0.0 } else { next }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_catalogue_loads_and_km_matches_holding_torque() {
        let cat = MotorCatalog::builtin();
        assert!(cat.motors().len() >= 2);
        for m in cat.motors() {
            let t = std::f64::consts::SQRT_2 * m.km_nm_per_a * m.rated_current_a;
            assert!((t / m.holding_torque_nm - 1.0).abs() < 0.005, "{}: √2·K_m·I = {t}", m.name);
        }
        assert!(cat.get("17hs19-2004s1").is_some());
    }

    #[test]
    fn bad_catalogues_are_refused() {
        assert!(matches!(MotorCatalog::from_toml_str("[[motor]]\nname = 1"), Err(CatalogError::Parse(_))));
        let one = BUILTIN_CATALOG_TOML.split("[[motor]]").nth(1).unwrap();
        let twice = format!("[[motor]]{one}[[motor]]{one}");
        assert!(matches!(MotorCatalog::from_toml_str(&twice), Err(CatalogError::Invalid(_))));
        let odd = format!("[[motor]]{}", one.replace("steps_per_rev = 200", "steps_per_rev = 202"));
        assert!(matches!(MotorCatalog::from_toml_str(&odd), Err(CatalogError::Invalid(_))));
    }

    #[test]
    fn microstep_angle_is_reduced_exactly() {
        let far = DriverCommand::at_microstep(i64::MAX - 3, 256, 1.0);
        let near = DriverCommand::at_microstep((i64::MAX - 3).rem_euclid(1024), 256, 1.0);
        assert_eq!(far.theta_e, near.theta_e);
        assert_eq!(DriverCommand::at_microstep(-1, 16, 1.0).theta_e, 63.0 * FRAC_PI_2 / 16.0);
    }

    #[test]
    fn position_is_kept_across_turns() {
        let mut m = Motor::new(MotorCatalog::builtin().motors()[0].clone(), MotorInputs::default());
        m.reset_at_full_steps(-0.5);
        assert_eq!(m.turns(), -1);
        assert!((m.rotor_full_steps() + 0.5).abs() < 1e-12);
        m.reset_at_full_steps(1e12 + 0.25);
        assert!((m.rotor_microsteps(256) - (1e12 + 0.25) * 256.0).abs() < 1.0);
    }

    #[test]
    fn advance_carries_the_remainder() {
        let mut m = Motor::new(MotorCatalog::builtin().motors()[0].clone(), MotorInputs::default());
        for _ in 0..1000 {
            m.advance(&DriverCommand::DISABLED, 1e-5);
        }
        assert!((m.time_s() - 1e-2).abs() <= m.substep_s());
    }
}
