//! The native motion modes (seed 000 §5.5): what writing a motion object does (planned here, on
//! the bus side, on a copy of the axis), the [`Settings`] the controller runs, built from the
//! objects, and what the drive makes of the controller's [`Events`] after a tick.
//!
//! Decisions where the manual is silent or contradicts itself:
//! - Direction 0x6002 = 0 ("forward") counts the position up, as §5.5.15 and §9.4.1 read. §5.5.4
//!   says a positive speed means direction 1; we keep its rule that writing a signed speed sets
//!   the direction, with the polarity of §5.5.3: a positive speed sets 0 and runs forward.
//! - A relative move while busy is ignored (normal reply, nothing changes), as §5.5.5 says. An
//!   absolute move while busy re-targets the running move on line, with no step in acceleration.
//!   A speed written while a position move runs re-plans it to the new speed.
//! - A move while the motor is disabled (0x6011 = 0), while a fault is latched (0x6000, 0x2135),
//!   while power loss frees the motor, or while a controller status bit (busy aside) is set is
//!   refused with exception 04 and nothing moves (also while the communication timeout bit 0x2138
//!   is set); so is a move that cannot
//!   be planned (speed 0), a position set while moving, and a resolution change while moving.
//! - The jerk of the S-curve is the larger of the acceleration and deceleration divided by the
//!   jerk time 0x2101 (our object, ms): the time the acceleration takes to build up.
//!
//! PVT (0x6007 = 2), synchronous positioning and group starts are in [`super::pvt`].

use super::DriveState;
use super::inputs::{INPUT_FUNCTION_OBJECTS, INPUT_LIMIT_NEGATIVE, INPUT_LIMIT_POSITIVE, INPUT_PROBE_1, INPUT_PROBE_2};
use super::memory::ProgramMemory;
use crate::controller::Shared;
use crate::controller::handoff::{Lent, Orders, TickSide};
use crate::controller::io::{IoFunctions, NotifyOutput, OUT_PINS, OutputFunction, PinConfig, PulseInput};
use crate::controller::{DECAY, Events, STATUS_EXT, STATUS_STALL, Settings};
use crate::faults::Inputs;
use crate::modes::{Command, PowerState, PulseFormat, Running, WorkMode};
use crate::motion::axis::Axis;
use crate::motion::scurve::Limits;
use crate::motion::shaping::MovingAverage;
use crate::od::{Obj, ObjError, refuse};
use crate::servo::{Gains, stall_limit};
use crate::units::Instant;
use core::borrow::Borrow;
use fixed::types::U0F16;

pub use crate::controller::Outputs;
pub use crate::units::{TICK_HZ, TICK_MICROS};

/// Accelerations of the levels 1..=8 of 0x600A/0x600B, in pps² (level 0: no ramp).
pub const LEVELS: [u32; 8] = [77_440, 48_410, 27_170, 21_510, 14_080, 10_460, 6_915, 5_210];

/// Controlword bit 4: a new set-point, on its rising edge.
pub const CW_NEW_SETPOINT: u16 = 1 << 4;
/// Controlword bit 5: change immediately, not after the running move.
pub const CW_IMMEDIATE: u16 = 1 << 5;
/// Controlword bit 6: the target is relative.
pub const CW_RELATIVE: u16 = 1 << 6;
/// Controlword bit 8: halt.
pub const CW_HALT: u16 = 1 << 8;
/// Controlword bit 9: change on set-point: pass through the running target without stopping.
pub const CW_CHANGE_ON_SETPOINT: u16 = 1 << 9;
/// Statusword bit 10: target reached (PP), target speed reached (PV).
pub const SW_TARGET_REACHED: u16 = 1 << 10;
/// Statusword bit 12: set-point acknowledge.
pub const SW_SETPOINT_ACK: u16 = 1 << 12;

/// A profile-position set-point, with the parameters it was given with.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SetPoint {
    pub(crate) target: i64,
    pub(crate) limits: Limits,
    pub(crate) depart: f32,
    pub(crate) arrive: f32,
}

impl Pp {
    /// No set-point, and the motion command `running` running.
    pub(super) fn commanded(running: Running) -> Self {
        Self { running, ..Self::default() }
    }
}

/// The state of the profile position and velocity modes (§5.11-5.12).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(crate) struct Pp {
    /// The set-point being executed.
    pub(crate) active: Option<SetPoint>,
    /// The one-deep buffer: the set-point that starts when the active one ends.
    buffered: Option<SetPoint>,
    /// Statusword bit 12.
    ack: bool,
    /// Stopped by the halt bit.
    halted: bool,
    /// The motion command (0x21A0) whose motion runs.
    pub(crate) running: Running,
}

/// Whether the controller runs `obj`'s value: a write to it builds the [`Settings`] again.
pub(crate) const fn runs_on(obj: Obj) -> bool {
    matches!(
        obj,
        Obj::Enable
            | Obj::Mode
            | Obj::PpDecel
            | Obj::DecelLevel
            | Obj::PhaseCurrent
            | Obj::IdleCurrent
            | Obj::IdleDelay
            | Obj::Microsteps
            | Obj::OverspeedLimit
            | Obj::FaultMask
            | Obj::InputFilter1
            | Obj::InputFilter2
            | Obj::InputFilter3
            | Obj::InputFilter4
            | Obj::InputFilter5
            | Obj::InputFilter6
            | Obj::InputFilter7
            | Obj::CommandFilter
            | Obj::CommandFilterTime
            | Obj::CurrentDecay
            | Obj::Brake
            | Obj::UnderVoltage
            | Obj::OverVoltage
            | Obj::OverTemperature
            | Obj::OverCurrent
            | Obj::CommTimeout
            | Obj::SpeedWindow
            | Obj::CommInputs
            | Obj::PowerLossControl
            | Obj::PowerLossFreeVoltage
            | Obj::PowerLossBrakeVoltage
            | Obj::AutoSave
            | Obj::SavedPosition
            | Obj::EncoderCpr
            | Obj::ZeroOffset
            | Obj::StallLength
            | Obj::TorqueLoop
            | Obj::Kp
            | Obj::Ki
            | Obj::Kd
            | Obj::PreFilter
            | Obj::StallDetect
            | Obj::StallStop
            | Obj::MotorResistance
            | Obj::MotorInductance
            | Obj::StallMinSpeed
            | Obj::StallParams
            | Obj::CoilMode
            | Obj::ExtStopEnable
            | Obj::ExtStopTrigger
            | Obj::SensorType
            | Obj::ExtDebounce
            | Obj::GpioDirection
            | Obj::GpioConfig
            | Obj::NotifyPos1
            | Obj::NotifyPos2
            | Obj::NotifyOutput
            | Obj::PulseFormat
            | Obj::PulseFilter
            | Obj::InputFunction1
            | Obj::InputFunction2
            | Obj::InputFunction3
            | Obj::InputFunction4
            | Obj::InputFunction5
            | Obj::InputFunction6
            | Obj::InputFunction7
            | Obj::InputLogic
            | Obj::OutputFunction1
            | Obj::OutputFunction2
            | Obj::OutputFunction3
            | Obj::OutputFunction4
            | Obj::GeneralOutputs
            | Obj::OutputLogic
            | Obj::InPositionWindow
            | Obj::InPositionSource
            | Obj::DisabledHold
            | Obj::SoftStartTime
            | Obj::SoftStart
            | Obj::PositionErrorLimit
            | Obj::PositionErrorAngle
            | Obj::PositionErrorAlarm
    )
}

/// The settings the controller runs, from the objects' values `params` (indexed by object).
#[inline(never)]
pub(crate) fn settings_of(params: &[u32; Obj::COUNT]) -> Settings {
    let get = |obj: Obj| params.get(obj as usize).copied().unwrap_or(0);
    let mode = WorkMode::from_raw(get(Obj::Mode)).unwrap_or_default();
    let control = get(Obj::PowerLossControl);
    let io = io_functions(&get);
    Settings {
        enabled: get(Obj::Enable) == 1,
        hold_disabled: get(Obj::DisabledHold) == 1,
        soft_start_ticks: if get(Obj::SoftStart) == 1 {
            (get(Obj::SoftStartTime) * (crate::units::TICK_HZ / 1000)) as u16
        } else {
            0
        },
        stop_decel: stop_deceleration(mode, get(Obj::PpDecel), get(Obj::DecelLevel)),
        phase_current_ma: get(Obj::PhaseCurrent),
        idle_current_pct: get(Obj::IdleCurrent),
        idle_delay_us: u64::from(get(Obj::IdleDelay)) * 1000,
        microsteps: get(Obj::Microsteps) as u16,
        fast_decay: DECAY.get(get(Obj::CurrentDecay) as usize).copied().unwrap_or(U0F16::ZERO),
        brake_duty: get(Obj::Brake) as u8,
        coil_general: get(Obj::CoilMode) == 1,
        ext_enable: get(Obj::ExtStopEnable) as u8,
        ext_rising: get(Obj::ExtStopTrigger) as u8,
        ext_delay_us: get(Obj::ExtDebounce) * 1000,
        pins: PinConfig::new(
            get(Obj::GpioDirection) as u16,
            get(Obj::GpioConfig),
            get(Obj::ExtStopEnable) as u8,
            get(Obj::ExtStopTrigger) as u8,
            get(Obj::SensorType) == 1,
        )
        .with_outputs(io.output_pins),
        notify: [i64::from(get(Obj::NotifyPos1) as i32), i64::from(get(Obj::NotifyPos2) as i32)],
        notify_output: NotifyOutput::from_object(get(Obj::NotifyOutput)),
        under_voltage_mv: get(Obj::UnderVoltage),
        over_voltage_mv: get(Obj::OverVoltage),
        over_temperature_c: get(Obj::OverTemperature),
        over_current_ma: get(Obj::OverCurrent),
        comm_timeout_us: u64::from(get(Obj::CommTimeout)) * 100_000,
        free_below_mv: if control & 1 != 0 { get(Obj::PowerLossFreeVoltage) } else { 0 },
        brake_below_mv: if control & 2 != 0 { get(Obj::PowerLossBrakeVoltage) } else { 0 },
        auto_save: get(Obj::AutoSave) == 1,
        saved_position: get(Obj::SavedPosition) as i32,
        encoder_cpr: get(Obj::EncoderCpr),
        zero_offset: get(Obj::ZeroOffset) as i32,
        following_limit: following_limit(
            get(Obj::StallLength),
            get(Obj::PositionErrorLimit),
            get(Obj::Microsteps),
            get(Obj::EncoderCpr),
            get(Obj::PositionErrorAngle),
            get(Obj::PositionErrorAlarm) == 1,
        ),
        servo_loop: get(Obj::TorqueLoop) == 1,
        gains: Gains::from_objects(get(Obj::Kp), get(Obj::Ki), get(Obj::Kd), get(Obj::PreFilter)),
        stall_detect: get(Obj::StallDetect) == 1,
        stall_stop: get(Obj::StallStop) == 1,
        motor_r: get(Obj::MotorResistance) as f32 * 1e-3,
        motor_l: get(Obj::MotorInductance) as f32 * 1e-6,
        stall_min_speed: get(Obj::StallMinSpeed) as f32,
        stall_limit_cos: crate::math::cos(stall_limit(get(Obj::StallParams))),
        pulse: PulseInput {
            format: PulseFormat::from_raw(get(Obj::PulseFormat)).unwrap_or_default(),
            filter: get(Obj::PulseFilter) as u8,
        },
        io,
        overspeed: overspeed(get(Obj::OverspeedLimit), get(Obj::Microsteps), get(Obj::EncoderCpr)),
        detect: get(Obj::FaultMask) as u16,
        // The store's state is the bus side's, not an object's: `refresh_settings` sets it.
        store_failed: false,
        shaping: if get(Obj::CommandFilter) == 1 {
            MovingAverage::over_micros(get(Obj::CommandFilterTime), crate::units::TICK_MICROS as u32)
        } else {
            MovingAverage::default()
        },
    }
}

/// The overspeed limit of `rpm` r/min (0x21F6; 0 off) as microsteps a second at `microsteps` a
/// full step (0x600C) and as counts a second of an encoder of `lines` (0x6054, four counts a
/// line).
///
/// ```
/// # use drive_core::state::control::overspeed;
/// // 1600 r/min at 1/16: 85 333 microsteps a second; with a 1000-line encoder 106 667 counts.
/// let [open, closed] = overspeed(1600, 16, 1000);
/// assert!((open - 85_333.3).abs() < 0.1 && (closed - 106_666.7).abs() < 0.1);
/// ```
pub fn overspeed(rpm: u32, microsteps: u32, lines: u32) -> [f32; 2] {
    let per_s = rpm as f32 / 60.0;
    let steps = crate::units::FULL_STEPS_PER_REV as f32 * microsteps.max(1) as f32;
    [per_s * steps, per_s * 4.0 * lines as f32]
}

/// The closed loop's following-error limit, microsteps: none without the `alarm` (0x21D7);
/// `degrees` of the shaft (0x21D6) while not 0; else `counts` encoder counts (0x21D0, at
/// `lines` × 4 a revolution) at `microsteps` (0x600C), or 0x605C's `steps` while `counts` is 0
/// (4 000 counts of a 1000-line encoder at 1/16 are 3 200 microsteps, 90° are 800).
fn following_limit(steps: u32, counts: u32, microsteps: u32, lines: u32, degrees: u32, alarm: bool) -> u32 {
    let per_rev = crate::units::FULL_STEPS_PER_REV as u32 * microsteps.max(1);
    if !alarm {
        return u32::MAX;
    }
    if degrees != 0 {
        // At most 360° × 51 200 microsteps a revolution: within 32 bits.
        return ((degrees * per_rev + 180) / 360).max(1);
    }
    if counts == 0 {
        return steps;
    }
    // At most 30 000 counts × 51 200 microsteps a revolution: within 32 bits.
    let lines = lines.max(1);
    ((counts * per_rev + 2 * lines) / (4 * lines)).max(1)
}

/// The inputs' and outputs' functions of the objects' values (`get`).
fn io_functions(get: &impl Fn(Obj) -> u32) -> IoFunctions {
    let inputs = INPUT_FUNCTION_OBJECTS.map(get);
    let with = |function: u32| inputs.iter().enumerate().fold(0u8, |m, (k, &f)| m | (u8::from(f == function) << k));
    let outputs = OUTPUT_FUNCTION_OBJECTS.map(|o| OutputFunction::from_raw(get(o)).unwrap_or_default());
    let output_pins =
        OUT_PINS.iter().zip(outputs).fold(0, |m, (&pin, f)| if f == OutputFunction::None { m } else { m | pin });
    IoFunctions {
        inputs: inputs.iter().enumerate().fold(0u8, |m, (k, &f)| m | (u8::from(f != 0) << k)),
        output_pins,
        input_low: get(Obj::InputLogic) as u8,
        limit_positive: with(INPUT_LIMIT_POSITIVE),
        limit_negative: with(INPUT_LIMIT_NEGATIVE),
        probes: [with(INPUT_PROBE_1), with(INPUT_PROBE_2)],
        outputs,
        general: get(Obj::GeneralOutputs) as u8,
        output_low: get(Obj::OutputLogic) as u8,
        // Without the encoder's say (0x21D9 = 0) every following error is within the window.
        in_position: if get(Obj::InPositionSource) == 0 { u32::MAX } else { get(Obj::InPositionWindow) },
        speed_window: get(Obj::SpeedWindow),
        overtravel: super::inputs::overtravel(
            get(Obj::CommInputs),
            with(INPUT_LIMIT_POSITIVE),
            with(INPUT_LIMIT_NEGATIVE),
        ),
        input_delay_us: INPUT_FILTER_OBJECTS.map(|o| get(o).saturating_sub(crate::units::TICK_MICROS as u32)),
    }
}

/// IN1-IN7's filter time objects.
pub(crate) const INPUT_FILTER_OBJECTS: [Obj; 7] = [
    Obj::InputFilter1,
    Obj::InputFilter2,
    Obj::InputFilter3,
    Obj::InputFilter4,
    Obj::InputFilter5,
    Obj::InputFilter6,
    Obj::InputFilter7,
];

/// OUT1-OUT4's function objects.
pub(crate) const OUTPUT_FUNCTION_OBJECTS: [Obj; 4] =
    [Obj::OutputFunction1, Obj::OutputFunction2, Obj::OutputFunction3, Obj::OutputFunction4];

/// The deceleration of a stop in `mode`, pps²: `pp_decel` (0x6068) in the profile modes, else
/// the level `level` of 0x600B; 0 (stop at once) for level 0, which has no ramp.
fn stop_deceleration(mode: WorkMode, pp_decel: u32, level: u32) -> u32 {
    if mode.is_profile() { pp_decel } else { LEVELS.get((level as usize).wrapping_sub(1)).copied().unwrap_or(0) }
}

impl<P: Borrow<Shared>, G: Borrow<ProgramMemory>> DriveState<P, G> {
    pub(crate) fn param(&self, obj: Obj) -> u32 {
        self.params.get(obj as usize).copied().unwrap_or(0)
    }

    pub(crate) fn set_param(&mut self, obj: Obj, value: u32) {
        if let Some(p) = self.params.get_mut(obj as usize) {
            *p = value;
        }
        if runs_on(obj) {
            self.refresh_settings();
        }
    }

    /// The work mode (0x6007).
    pub fn mode(&self) -> WorkMode {
        WorkMode::from_raw(self.param(Obj::Mode)).unwrap_or_default()
    }

    /// Whether the drive may start a motion, or why not: no fault, stop or timeout bit latched,
    /// and the power stage on (enabled, not freed by power loss).
    pub(crate) fn may_move(&self) -> Result<(), ObjError> {
        let s = &self.ctl.status;
        // An external stop latched, or a stall that stopped the motor: the master clears it first.
        let stall = if self.settings.stall_stop { STATUS_STALL } else { 0 };
        refuse(s.controller & (STATUS_EXT | stall) == 0 && s.comm == 0, ObjError::Faulted)?;
        // A quick stop holds the axis until the master enables the operation again.
        refuse(self.device != crate::power::DeviceState::QuickStopActive, ObjError::NotNow)?;
        match self.ctl.power_state(&self.settings) {
            PowerState::On => Ok(()),
            PowerState::Faulted => Err(ObjError::Faulted),
            PowerState::Disabled | PowerState::Freed => Err(ObjError::Disabled),
        }
    }

    /// The encoder position, counts, in closed loop.
    fn encoder_position(&self) -> Option<i64> {
        self.ctl.servo.feedback.encoder().map(|_| self.ctl.servo.encoder)
    }

    /// What planning reads of the drive ([`Planner`]).
    pub(crate) fn planner(&self) -> Planner<'_> {
        Planner {
            params: &self.params,
            now: self.plan_time(),
            may_move: self.may_move(),
            encoder: self.encoder_position(),
            limits: self.active_limits(),
            program: self.program_runs(),
            asked: core::cell::Cell::new(0.0),
            overspeed: self.overspeed_limit(),
        }
    }

    /// The overspeed limit (0x21F6) in the unit plans are made in: microsteps a second in open
    /// loop, encoder counts a second in closed loop; 0 off.
    fn overspeed_limit(&self) -> f32 {
        let [open, closed] = self.settings.overspeed;
        if self.encoder_position().is_some() { closed } else { open }
    }

    /// The limit switches active now: bit 0 the positive, bit 1 the negative.
    pub(super) fn active_limits(&self) -> u8 {
        u8::from(self.limit_ahead(true)) | (u8::from(self.limit_ahead(false)) << 1)
    }

    /// Plans writing `value` to the motion object `obj` at the plan time on `planned`, a copy of
    /// the axis and set-points: `Ok(true)` if the write changes them, `Ok(false)` if it leaves
    /// them as they are, or why it is refused (and `planned` is to be dropped).
    pub(crate) fn plan_motion(&self, obj: Obj, value: u32, planned: &mut (Axis, Pp)) -> Result<bool, ObjError> {
        self.planner().plan_motion(obj, value, &mut planned.0, &mut planned.1)
    }

    /// Plans writing `value` to the motion object `obj` on the drive's own axis and set-points,
    /// with no copy: for a multi-object write, whose checkpoint restores them if it is refused
    /// (a refused plan may have halted the axis). What [`DriveState::plan_motion`] returns.
    pub(crate) fn plan_motion_in_place(&mut self, obj: Obj, value: u32) -> Result<bool, ObjError> {
        let (may_move, encoder, limits) = (self.may_move(), self.encoder_position(), self.active_limits());
        let program = self.program_runs();
        let (asked, overspeed) = (core::cell::Cell::new(0.0), self.overspeed_limit());
        let now = self.plan_time();
        let planner = Planner { params: &self.params, now, may_move, encoder, limits, program, asked, overspeed };
        planner.plan_motion(obj, value, &mut self.ctl.axis, &mut self.pp)
    }

    /// Plans a program's (or the power-up jog's) move to `sp.target` on the drive's own axis:
    /// the target it heads for (within the soft limits), or why it is refused.
    pub(super) fn plan_program_move(&mut self, sp: &SetPoint) -> Result<i64, ObjError> {
        let (may_move, encoder, limits) = (self.may_move(), self.encoder_position(), self.active_limits());
        let (asked, overspeed) = (core::cell::Cell::new(0.0), self.overspeed_limit());
        let (now, program) = (self.plan_time(), true);
        let planner = Planner { params: &self.params, now, may_move, encoder, limits, program, asked, overspeed };
        planner.program_move(&mut self.ctl.axis, sp)
    }

    /// Checks a write to a motion object: refused when the drive cannot act on it now.
    pub(crate) fn check_motion(&self, obj: Obj, value: u32) -> Result<(), ObjError> {
        if crate::od::is_pvt_command(obj) {
            return self.check_pvt(obj, value);
        }
        if obj == Obj::HomingControl {
            return self.check_homing(value);
        }
        if obj == Obj::MotionCommand && !super::plans_motion_command(value) {
            return self.check_other_command(value);
        }
        self.check_planned(obj, value)
    }

    /// Plans `obj` = `value` on a copy of the axis and set-points, to see whether it may be
    /// written. Out of line, as [`DriveState::apply_motion`].
    #[inline(never)]
    fn check_planned(&self, obj: Obj, value: u32) -> Result<(), ObjError> {
        let mut scratch = (self.ctl.axis, self.pp);
        self.plan_motion(obj, value, &mut scratch).map(|_| ())
    }

    /// Writes a motion object, which [`DriveState::check_motion`] accepted.
    pub(crate) fn apply_motion(&mut self, obj: Obj, value: u32) {
        if crate::od::is_pvt_command(obj) {
            return self.apply_pvt(obj, value);
        }
        self.apply_planned(obj, value);
    }

    /// Plans and writes the motion object `obj` = `value`. Out of line: the copy of the axis it
    /// plans on is on the stack for this call only.
    #[inline(never)]
    fn apply_planned(&mut self, obj: Obj, value: u32) {
        let mut planned = (self.ctl.axis, self.pp);
        // Checked already: were it refused now, the axis stays.
        let changed = self.plan_motion(obj, value, &mut planned) == Ok(true);
        self.commit_motion(obj, value, changed.then_some(&planned));
    }

    /// Writes the motion object `obj` with the axis and set-points `planned` for it, if it
    /// changes them ([`DriveState::plan_motion`]).
    pub(crate) fn commit_motion(&mut self, obj: Obj, value: u32, planned: Option<&(Axis, Pp)>) {
        if let Some((axis, pp)) = planned {
            self.ctl.axis = *axis;
            self.pp = *pp;
        }
        self.commit_value(obj, value, planned.is_some());
    }

    /// Stores the motion object `obj` = `value` whose plan is in place (it `changed` the axis
    /// and set-points, or left them): the value, the direction a signed speed sets, and the end
    /// of a PVT run that a stop or a disable halted.
    pub(crate) fn commit_value(&mut self, obj: Obj, value: u32, changed: bool) {
        match obj {
            // Writing a signed speed sets the direction of relative moves (see the module doc).
            Obj::MaxSpeed if value != 0 => self.set_param(Obj::Direction, u32::from((value as i32) < 0)),
            _ => {}
        }
        if obj != Obj::Stop {
            self.set_param(obj, value);
        }
        let stops = obj == Obj::MotionCommand
            && matches!(Command::from_raw(value), Some(Command::Stop | Command::EmergencyStop));
        if changed && (stops || matches!(obj, Obj::Stop | Obj::Enable)) {
            // A stop ends a PVT run too, and a program.
            self.end_run();
            self.program_stopped();
        }
        if obj == Obj::Enable {
            self.enable_written(value);
        }
    }

    /// The PP/PV statusword: target reached and set-point acknowledge.
    pub(crate) fn statusword(&self) -> u16 {
        let reached = match self.mode() {
            WorkMode::ProfilePosition => self.ctl.axis.is_still() && self.pp.buffered.is_none(),
            WorkMode::ProfileVelocity => self.ctl.axis.settled(),
            _ => false,
        };
        (if reached { SW_TARGET_REACHED } else { 0 }) | if self.pp.ack { SW_SETPOINT_ACK } else { 0 }
    }

    /// What the controller did on its own: a stop ends the set-points, a joined set-point is
    /// the active one, failing power asks for the position save, the closed loop's first reading
    /// sets the zero offset. Out of line: most ticks have nothing to report.
    #[inline(never)]
    fn take_events(&mut self, events: Events) {
        if events.has(Events::STOPPED) {
            self.pp = Pp::default();
            self.program_stopped();
        }
        if events.has(Events::JOINED)
            && self.mode() == WorkMode::ProfilePosition
            && let Some(sp) = self.pp.buffered.take()
        {
            self.pp.active = Some(sp);
            if self.param(Obj::ControlWord) as u16 & CW_NEW_SETPOINT == 0 {
                self.pp.ack = false;
            }
        }
        if events.has(Events::POWER_FAILING) {
            self.power_lost();
        }
        if events.has(Events::ZERO_OFFSET) {
            self.set_param(Obj::ZeroOffset, self.ctl.zero_offset as u32);
        }
        self.homing_events(events);
        self.homing_service();
    }

    /// What the bus side does in time, without a request, if it is due at `now` (see
    /// [`DriveState::service_due`]): a homing's checks, the analog input's readings and
    /// targets. A platform calls it whenever its timer wakes it.
    pub fn service(&mut self, now: Instant) {
        if !self.service_is_due(now) {
            return;
        }
        self.now = now;
        self.homing_service();
        self.analog_service();
        self.follow_service();
        self.inputs_service();
        self.program_service();
        self.signals_service();
        self.jog_service();
        self.quick_stop_settle();
    }

    /// When [`DriveState::service`] has something to do: a homing's checks, the analog input's
    /// next reading.
    pub fn service_due(&self) -> Option<Instant> {
        let due = self.homing_due().into_iter().chain(self.analog_due()).chain(self.device_due());
        let due = due.chain(self.follow_due()).chain(self.inputs_due()).chain(self.program_due());
        due.chain(self.jog_due()).chain(self.signals_due()).min()
    }

    /// Whether [`DriveState::service`] has something to do at `now`: for a platform that must
    /// sync the model first, and so asks before.
    pub fn service_is_due(&self, now: Instant) -> bool {
        self.service_due().is_some_and(|due| now >= due)
    }

    /// When the pulse following (work mode 3) is to start: now, standing in the mode with the
    /// power stage on and no stop latched (again after a stop, once the master cleared it).
    fn follow_due(&self) -> Option<Instant> {
        let ready = self.mode() == WorkMode::Follow && self.ctl.axis.is_still() && self.may_move().is_ok();
        ready.then_some(self.now)
    }

    /// Starts the pulse following if it is due.
    fn follow_service(&mut self) {
        if self.follow_due().is_some() {
            let at = self.plan_time();
            self.ctl.axis.follow_pulses(at);
            self.pp = Pp::default();
        }
    }

    /// Lends the model of the controller to a control tick that owns a controller of its own,
    /// for [`Controller::sync`](crate::controller::Controller::sync); then
    /// [`DriveState::synced`]. See [`crate::controller::handoff`].
    pub(crate) fn lend(&mut self) -> Lent<'_> {
        Lent {
            model: &mut self.ctl,
            settings: &self.settings,
            pvt: &mut self.pvt,
            base: &mut self.base,
            orders: &mut self.orders,
            heard: &mut self.heard,
        }
    }

    /// The tick's side of this drive, where the tick runs apart from the bus side: a copy of the
    /// controller and the PVT queue, before the first tick.
    pub fn tick_side(&self) -> TickSide {
        TickSide::new(&self.settings, &self.ctl, &self.pvt)
    }

    /// The memories the tick's side shares: the PVT point table it reads, the recordings it
    /// writes.
    pub fn shared(&self) -> &Shared {
        self.shared.borrow()
    }

    /// After a sync: acts on what the tick reported (as [`DriveState::tick_with`] does).
    pub fn synced(&mut self) {
        if !self.ctl.events.is_empty() {
            let events = self.ctl.take_events();
            self.take_events(events);
        }
    }

    /// Whether the model holds something the tick's own controller has not taken in: a change
    /// to hand over by a sync.
    pub(crate) fn has_changes(&self) -> bool {
        self.ctl.axis.version() != self.base.version || self.orders != Orders::default() || self.heard
    }

    /// Where the control tick owns a controller of its own: motion starts `margin_us` after the
    /// request that commands it (planned from the axis as it will be then), which must be
    /// longer than serving a request and handing the plan over take.
    pub fn set_plan_margin(&mut self, margin_us: u64) {
        self.margin = margin_us;
    }

    /// Says that this platform's power stage is the drive's own, run by its current loop
    /// (`windings`), which reads 0x210B-0x210D at power-up; without it those refuse writes.
    pub fn set_current_loop(&mut self, on: bool) {
        self.current_loop = on;
    }

    /// The register maps this platform carries (bit n: 0x2190 = n; all of them unless said):
    /// 0x2190 refuses the others (04).
    pub fn set_maps(&mut self, maps: u8) {
        self.maps = maps;
    }

    /// The time the motion a request commands starts at (the plan's first tick is the first
    /// at or after it): the request's time, and the margin where the tick runs apart.
    // Out of line: eleven callers.
    #[inline(never)]
    pub(crate) fn plan_time(&self) -> Instant {
        self.now.plus_micros(self.margin)
    }

    /// One control tick at `now` on a platform that measures nothing: [`DriveState::tick_with`]
    /// with no measurement, so no fault is detected.
    pub fn tick(&mut self, now: Instant) -> Outputs {
        self.tick_with(now, &Inputs::default())
    }

    /// One control tick at `now`: the controller's tick (see [`crate::controller`]), then what it
    /// reports.
    pub fn tick_with(&mut self, now: Instant, inputs: &Inputs) -> Outputs {
        self.now = now;
        if core::mem::take(&mut self.heard) {
            self.ctl.heard();
        }
        let out = self.ctl.tick(&self.settings, now, inputs, &mut self.pvt, self.shared.borrow());
        // One owner: what the bus side ordered is in this controller already, and its plans
        // too; nothing is left for a tick side to take in.
        (self.orders, self.base.version) = (Orders::default(), self.ctl.axis.version());
        if !self.ctl.events.is_empty() {
            let events = self.ctl.take_events();
            self.take_events(events);
        }
        out
    }
}

/// What planning a motion command reads of the drive: the objects, the time of the request,
/// whether a motion may start, and the encoder position in closed loop. Apart from the axis and
/// set-points it plans on, so that those may be the drive's own (a write that is undone as a
/// whole if refused) or a copy.
pub(crate) struct Planner<'a> {
    params: &'a [u32; Obj::COUNT],
    pub(super) now: Instant,
    /// Whether a motion may start ([`DriveState::may_move`]).
    pub(crate) may_move: Result<(), ObjError>,
    /// The encoder position, counts, in closed loop.
    encoder: Option<i64>,
    /// The limit switches active (bit 0 positive, bit 1 negative): a motion command towards
    /// one is refused.
    pub(super) limits: u8,
    /// A program runs: it owns the axis, and motion commands but the stops are refused.
    pub(super) program: bool,
    /// The fastest speed the plan under way asked for ([`Planner::within_overspeed`]).
    pub(super) asked: core::cell::Cell<f32>,
    /// The overspeed limit (0x21F6) in the plan's unit, the settings' for the loop in force;
    /// 0 off.
    overspeed: f32,
}

impl Planner<'_> {
    pub(super) fn param(&self, obj: Obj) -> u32 {
        self.params.get(obj as usize).copied().unwrap_or(0)
    }

    pub(super) fn mode(&self) -> WorkMode {
        WorkMode::from_raw(self.param(Obj::Mode)).unwrap_or_default()
    }

    /// The S-curve limits of the native position and velocity modes, for a speed of `speed`.
    pub(crate) fn scurve_limits(&self, speed: f32) -> Limits {
        let level = |obj| LEVELS.get((self.param(obj) as usize).wrapping_sub(1)).map(|&a| a as f32);
        // Level 0 disables the ramp: the motor jumps to speed and stops from it.
        let (a, d) = (level(Obj::AccelLevel).unwrap_or(1e12), level(Obj::DecelLevel).unwrap_or(1e12));
        let jerk_s = (self.param(Obj::JerkTime).max(1) as f32) * 1e-3;
        self.ask(speed);
        Limits { v_max: libm::fabsf(speed), a_max: a, d_max: d, jerk: Some(a.max(d) / jerk_s) }
    }

    /// Start and stop speeds: the jumps from and to rest (all of the speed without a ramp).
    pub(crate) fn jumps(&self, speed: f32) -> (f32, f32) {
        let ramp = |obj, speed_obj| if self.param(obj) == 0 { speed } else { self.param(speed_obj) as f32 };
        (ramp(Obj::AccelLevel, Obj::StartSpeed), ramp(Obj::DecelLevel, Obj::StopSpeed))
    }

    /// The trapezoid limits of the PP and PV modes at `speed`, and their start and stop speeds.
    // Out of line: eight callers would each hold a copy.
    #[inline(never)]
    pub(crate) fn pp_setpoint(&self, target: i64, speed: f32) -> SetPoint {
        self.ask(speed);
        let limits = Limits {
            v_max: libm::fabsf(speed),
            a_max: self.param(Obj::PpAccel) as f32,
            d_max: self.param(Obj::PpDecel) as f32,
            jerk: None,
        };
        let (depart, arrive) = (self.param(Obj::PpStartSpeed) as f32, self.param(Obj::PpStopSpeed) as f32);
        SetPoint { target, limits, depart, arrive }
    }

    /// The axis and PP state after a controlword write in PP or PV mode.
    // Out of line: inlined, its set-points would be in `plan_motion`'s frame for every motion
    // write, not only the PP mode's.
    #[inline(never)]
    fn plan_controlword(&self, axis: &mut Axis, pp: &mut Pp, new: u16) -> Result<(), ObjError> {
        let old = self.param(Obj::ControlWord) as u16;
        let rise = |bit: u16| new & bit != 0 && old & bit == 0;
        let fall = |bit: u16| new & bit == 0 && old & bit != 0;
        let now = self.now;
        let run_speed = (self.param(Obj::PpRunSpeed) as i32) as f32;
        let failed = |_| ObjError::Infeasible;
        let mode = self.mode();
        if rise(CW_HALT) {
            pp.halted = true;
            if !axis.is_still() {
                let sp = self.pp_setpoint(0, libm::fabsf(axis.setpoint().velocity).max(1.0));
                axis.run_at(now, 0.0, 0.0, &sp.limits).map_err(failed)?;
            }
        } else if fall(CW_HALT) {
            pp.halted = false;
            self.may_move?;
            if mode == WorkMode::ProfileVelocity {
                let sp = self.pp_setpoint(0, run_speed);
                axis.run_at(now, run_speed, sp.depart, &sp.limits).map_err(failed)?;
            } else if let Some(sp) = pp.active {
                // PP: resume the interrupted move, and the buffered one after it.
                axis.move_to(now, sp.target, sp.depart, sp.arrive, &sp.limits).map_err(failed)?;
                if let Some(b) = pp.buffered {
                    axis.then_move_to(b.target, b.depart, b.arrive, &b.limits).map_err(|_| ObjError::Busy)?;
                }
            }
        }
        if mode == WorkMode::ProfilePosition && rise(CW_NEW_SETPOINT) && !pp.ack {
            // With the buffer full (acknowledge still set) a new set-point is ignored (§5.11.3, 4).
            self.may_move?;
            let value = i64::from(self.param(Obj::PpTarget) as i32);
            let base = match (pp.buffered, pp.active) {
                (_, Some(a)) if !axis.is_still() => a.target,
                _ => axis.setpoint().whole,
            };
            let target = if new & CW_RELATIVE != 0 { base.saturating_add(value) } else { value };
            let sp = self.pp_setpoint(target, run_speed);
            if axis.is_still() || new & CW_IMMEDIATE != 0 || pp.halted {
                if !pp.halted {
                    axis.move_to(now, sp.target, sp.depart, sp.arrive, &sp.limits).map_err(failed)?;
                }
                pp.active = Some(sp);
                pp.buffered = None;
            } else {
                if let (true, Some(a)) = (new & CW_CHANGE_ON_SETPOINT != 0, pp.active) {
                    // Keep going through the running target if the next one lies beyond it.
                    let here = axis.setpoint().whole;
                    let onward = (a.target - here).signum() == (sp.target - a.target).signum();
                    if onward {
                        let pass = a.limits.v_max.min(sp.limits.v_max);
                        axis.pass_through(now, a.target, a.depart, pass, &a.limits).map_err(failed)?;
                    }
                }
                // Planned now, after the running move: the control tick walks on into it. A
                // walk already cruising past its target starts it from where it is.
                if axis.then_move_to(sp.target, sp.depart, sp.arrive, &sp.limits).is_ok() {
                    pp.buffered = Some(sp);
                } else if axis.settled() {
                    axis.move_to(now, sp.target, sp.depart, sp.arrive, &sp.limits).map_err(failed)?;
                    pp.active = Some(sp);
                } else {
                    // The two moves do not fit in one track (more than 17 phases).
                    return Err(ObjError::Busy);
                }
            }
            pp.ack = true;
        }
        if fall(CW_NEW_SETPOINT) && pp.buffered.is_none() {
            pp.ack = false;
        }
        Ok(())
    }

    /// Plans writing `value` to the motion object `obj` at the plan time on `axis` and `pp`:
    /// `Ok(true)` if the write changes them, `Ok(false)` if it leaves them as they are, or why it
    /// is refused (and they are to be dropped, or restored).
    pub(super) fn plan_motion(&self, obj: Obj, value: u32, axis: &mut Axis, pp: &mut Pp) -> Result<bool, ObjError> {
        let before = libm::fabsf(axis.setpoint().velocity);
        self.asked.set(0.0);
        let changed = self.plan_motion_within(obj, value, axis, pp)?;
        self.within_overspeed(before)?;
        Ok(changed)
    }

    /// Records a speed the plan under way asks for, microsteps (counts in closed loop) a second.
    fn ask(&self, speed: f32) {
        self.asked.set(self.asked.get().max(libm::fabsf(speed)));
    }

    /// Refuses a plan that asked for a speed beyond the overspeed limit (0x21F6) and beyond
    /// `before`, the axis' speed when it was planned: a stop or a slow-down is never refused.
    pub(super) fn within_overspeed(&self, before: f32) -> Result<(), ObjError> {
        let (limit, asked) = (self.overspeed, self.asked.get());
        refuse(limit == 0.0 || asked <= limit || asked <= before, ObjError::Overspeed)
    }

    /// [`Planner::plan_motion`] before the overspeed check.
    fn plan_motion_within(&self, obj: Obj, value: u32, axis: &mut Axis, pp: &mut Pp) -> Result<bool, ObjError> {
        let now = self.now;
        let busy = !axis.is_still();
        let mode = self.mode();
        let speed = (self.param(Obj::MaxSpeed) as i32) as f32;
        let position = axis.setpoint().whole;
        let go_to = |axis: &mut Axis, target: i64, speed: f32| {
            let (depart, arrive) = self.jumps(libm::fabsf(speed));
            axis.move_to(now, target, depart, arrive, &self.scurve_limits(speed)).map_err(|_| ObjError::Infeasible)
        };
        if !matches!(obj, Obj::MotionCommand | Obj::CommandTarget | Obj::CommandVelocity) {
            // Any other motion write replaces a motion command's run.
            pp.running = Running::Nothing;
        }
        match obj {
            Obj::MotionCommand => return self.plan_command(axis, pp, value),
            Obj::CommandTarget | Obj::CommandVelocity => return self.plan_command_change(axis, pp, obj, value),
            Obj::RelativeMove | Obj::AbsoluteMove => {
                refuse(mode == WorkMode::Position && speed != 0.0, ObjError::NotNow)?;
                self.may_move?;
                let target = if obj == Obj::AbsoluteMove {
                    i64::from(value as i32)
                } else if busy {
                    return Ok(false);
                } else if self.param(Obj::Direction) == 0 {
                    position.saturating_add(i64::from(value as i32))
                } else {
                    position.saturating_sub(i64::from(value as i32))
                };
                go_to(axis, target, speed)?;
            }
            Obj::MaxSpeed => {
                let v = (value as i32) as f32;
                match (mode, axis.target()) {
                    (WorkMode::Velocity, _) => {
                        if v != 0.0 {
                            self.may_move?;
                        }
                        let (depart, _) = self.jumps(libm::fabsf(v));
                        // Speed 0 stops: the ramp's limits are those of the speed it stops from.
                        let limit = if v == 0.0 { libm::fabsf(axis.setpoint().velocity).max(1.0) } else { v };
                        axis.run_at(now, v, depart, &self.scurve_limits(limit)).map_err(|_| ObjError::Infeasible)?;
                    }
                    (WorkMode::Position, Some(target)) if busy => {
                        refuse(v != 0.0, ObjError::NotNow)?;
                        go_to(axis, target, v)?;
                    }
                    _ => return Ok(false),
                }
            }
            Obj::Mode => {
                // The declared set admits only modes.
                let new = WorkMode::from_raw(value).ok_or(ObjError::OutOfRange)?;
                if new == mode {
                    return Ok(false);
                }
                // Leaving a mode while moving: the manual decelerates from velocity to position;
                // leaving the pulse following stops it where the pulses left it.
                let following = axis.follows_pulses();
                refuse(
                    !busy || following || (mode == WorkMode::Velocity && new == WorkMode::Position),
                    ObjError::Busy,
                )?;
                if following {
                    axis.halt();
                } else if busy {
                    axis.run_at(now, 0.0, 0.0, &self.scurve_limits(speed)).map_err(|_| ObjError::Infeasible)?;
                }
                *pp = Pp::default();
            }
            Obj::ControlWord if mode.is_profile() => self.plan_controlword(axis, pp, value as u16)?,
            Obj::PpRunSpeed if mode == WorkMode::ProfileVelocity && busy && !pp.halted => {
                let v = (value as i32) as f32;
                let sp = self.pp_setpoint(0, v);
                axis.run_at(now, v, sp.depart, &sp.limits).map_err(|_| ObjError::Infeasible)?;
            }
            Obj::Stop => {
                axis.halt();
                *pp = Pp::default();
            }
            Obj::Enable if value == 0 => {
                axis.halt();
                *pp = Pp::default();
            }
            Obj::Enable => return Ok(false),
            Obj::Position | Obj::Microsteps => refuse(!busy, ObjError::Busy)?,
            Obj::ZeroOffset => {
                refuse(!busy, ObjError::Busy)?;
                if let Some(encoder) = self.encoder {
                    // The position moves with the offset, and the axis stands on it.
                    axis.set_position(encoder.wrapping_add(i64::from(value as i32)));
                }
            }
            _ => return Ok(false),
        }
        Ok(true)
    }
}
