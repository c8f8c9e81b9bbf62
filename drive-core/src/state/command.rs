//! The motion command 0x21A0 (seed 002's control command 0323) and the soft limits 0x21A9-0x21AD:
//! runs, jogs and stops by one register, planned on the bus side as every other motion is.
//!
//! A run to a position or by a distance and a run at a speed ramp as the profile modes do
//! (0x6067, 0x6069, 0x606B, 0x606D) at 0x21B5, 0x21A3 or 0x21A5. With a soft limit enabled no
//! motion command goes beyond it: a target beyond it stops on it, and a run or a jog towards it
//! is a move to it at the run's speed. An axis already beyond a limit moves back freely and no
//! further out.
//!
//! Here too the power-up jog (0x21D8, seed 003's 0x2013): two moves at the jog speed once the
//! drive has powered up.

use super::DriveState;
use super::control::{Planner, Pp, SetPoint};
use super::memory::ProgramMemory;
use crate::controller::Shared;
use crate::controller::{STATUS_EXT, STATUS_STALL};
use crate::modes::{Command, PowerState, Running, WorkMode};
use crate::motion::axis::Axis;
use crate::od::{Obj, ObjError, refuse};
use core::borrow::Borrow;

/// 0x21AD: the positive soft limit on.
const LIMIT_POSITIVE: u32 = 1 << 0;
/// 0x21AD: the negative soft limit on.
const LIMIT_NEGATIVE: u32 = 1 << 1;

/// Seed 003's power-up jog (0x21D8): the move that comes next.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) enum Jog {
    /// None: done, ended, or not asked for.
    #[default]
    Done,
    /// The first move, 30° forward, at the first service.
    Start,
    /// The move back, once the axis stands on the first one's target (its low 32 bits: a
    /// jog's targets are a turn apart at most).
    Back(i32),
}

impl<P: Borrow<Shared>, G: Borrow<ProgramMemory>> DriveState<P, G> {
    /// Checks a motion command that does not plan (set position, home, clear the alarms).
    pub(crate) fn check_other_command(&self, value: u32) -> Result<(), ObjError> {
        let command = Command::from_raw(value).ok_or(ObjError::OutOfRange)?;
        if command.raw() >= Command::ProgramCheck.raw() {
            return self.check_program_command(command);
        }
        // A running program owns the axis.
        refuse(!self.program_runs() || matches!(command, Command::AlarmClear | Command::None), ObjError::NotNow)?;
        match command {
            Command::SetPosition => {
                refuse(self.ctl.axis.is_still(), ObjError::Busy)?;
                self.check(Obj::Position, self.param(Obj::PositionPreset))
            }
            Command::Home => self.check_homing(1),
            _ => Ok(()),
        }
    }

    /// Writes a motion command that does not plan, once [`DriveState::check_other_command`]
    /// accepts it.
    pub(crate) fn other_command(&mut self, value: u32) -> Result<(), ObjError> {
        self.check_other_command(value)?;
        match Command::from_raw(value) {
            Some(Command::SetPosition) => self.apply(Obj::Position, self.param(Obj::PositionPreset)),
            Some(Command::Home) => self.homing_command(1),
            Some(Command::AlarmClear) => self.clear_alarms(),
            Some(command) => self.program_command(command)?,
            None => {}
        }
        self.set_param(Obj::MotionCommand, value);
        Ok(())
    }

    /// Clears every latched alarm (seed 002's alarm clear): the fault bits, the communication
    /// timeout, the external stops and the stall; the enable stays as it is, so a drive whose
    /// fault is gone is energised again. A condition still present latches again.
    pub(crate) fn clear_alarms(&mut self) {
        for obj in [Obj::ErrorStatus, Obj::DriveFaults, Obj::CommStatus] {
            self.apply(obj, 0xFF);
        }
        self.apply(Obj::ControllerStatus, u32::from(STATUS_EXT | STATUS_STALL));
    }

    /// When the power-up jog's next move is due: now, with the axis standing.
    pub(crate) fn jog_due(&self) -> Option<crate::units::Instant> {
        (self.jog != Jog::Done && self.ctl.axis.is_still()).then_some(self.now)
    }

    /// The power-up jog's next move, if due: 30° forward, then 15° back from where the first
    /// ended (in encoder counts in closed loop). A move refused, or an axis standing anywhere but
    /// where the jog took it, ends the jog.
    pub(crate) fn jog_service(&mut self) {
        if self.jog_due().is_none() {
            return;
        }
        let here = self.ctl.axis.setpoint().whole;
        let turn = match self.ctl.servo.feedback.encoder() {
            Some(e) => i64::from(e.counts_per_rev()),
            None => i64::from(self.per_rev()),
        };
        let target = match self.jog {
            Jog::Start => here + turn / 12,
            Jog::Back(t) if t == here as i32 => here - turn / 24,
            _ => {
                self.jog = Jog::Done;
                return;
            }
        };
        let sp = self.planner().pp_setpoint(target, self.param(Obj::JogSpeed) as f32);
        let planned = self.plan_program_move(&sp);
        if planned.is_ok() {
            self.pp = Pp::default();
        }
        self.jog = match (self.jog, planned) {
            (Jog::Start, Ok(t)) => Jog::Back(t as i32),
            _ => Jog::Done,
        };
    }

    /// 0x21AE: 1 the power stage off, 2 energised and standing, 3 moving.
    pub(crate) fn run_state(&self) -> u8 {
        if self.ctl.power_state(&self.settings) != PowerState::On {
            1
        } else if self.motor_still() {
            2
        } else {
            3
        }
    }
}

impl Planner<'_> {
    /// Plans the motion command `value` on `axis` and `pp`: `Ok(true)` if it changes them.
    pub(super) fn plan_command(&self, axis: &mut Axis, pp: &mut Pp, value: u32) -> Result<bool, ObjError> {
        let command = Command::from_raw(value).ok_or(ObjError::OutOfRange)?;
        if !command.plans() {
            return Ok(false);
        }
        // A PVT run or the pulse input owns the axis: the motion command stops it, and moves it
        // in no other way.
        let stops = matches!(command, Command::Stop | Command::EmergencyStop);
        refuse(stops || !matches!(self.mode(), WorkMode::Pvt | WorkMode::Follow) && !self.program, ObjError::NotNow)?;
        let here = axis.setpoint().whole;
        let running = match command {
            Command::Absolute => {
                self.may_move?;
                self.run_to(axis, i64::from(self.param(Obj::CommandTarget) as i32))?;
                Running::Absolute
            }
            Command::Relative => {
                refuse(axis.is_still(), ObjError::Busy)?;
                self.may_move?;
                let target = here.saturating_add(i64::from(self.param(Obj::CommandTarget) as i32));
                self.run_to(axis, target)?;
                Running::Relative
            }
            Command::Velocity => {
                self.may_move?;
                self.run(axis, (self.param(Obj::CommandVelocity) as i32) as f32)?;
                Running::Velocity
            }
            Command::JogPositive | Command::JogNegative => {
                self.may_move?;
                let speed = self.param(Obj::JogSpeed) as f32;
                self.run(axis, if command == Command::JogPositive { speed } else { -speed })?;
                Running::Jog
            }
            Command::Stop => {
                axis.stop_ramp(self.param(Obj::PpDecel));
                Running::Nothing
            }
            Command::EmergencyStop => {
                axis.stop_ramp(self.param(Obj::QuickStopDecel));
                Running::Nothing
            }
            _ => return Ok(false),
        };
        *pp = Pp::commanded(running);
        Ok(true)
    }

    /// Plans a write of the target or the run velocity: an absolute run re-targets, a run
    /// changes its speed; otherwise the value is stored for the next command.
    pub(super) fn plan_command_change(&self, axis: &mut Axis, pp: &Pp, obj: Obj, value: u32) -> Result<bool, ObjError> {
        if axis.is_still() {
            return Ok(false);
        }
        match (obj, pp.running) {
            (Obj::CommandTarget, Running::Absolute) => {
                self.may_move?;
                self.run_to(axis, i64::from(value as i32))?;
            }
            (Obj::CommandVelocity, Running::Velocity) => {
                self.may_move?;
                self.run(axis, (value as i32) as f32)?;
            }
            _ => return Ok(false),
        }
        Ok(true)
    }

    /// Refuses (04) a motion heading up (`up`) into an active limit switch.
    fn away_from_limits(&self, up: bool) -> Result<(), ObjError> {
        refuse(self.limits & if up { 1 } else { 2 } == 0, ObjError::NotNow)
    }

    /// The enabled soft limits: the lowest and the highest position a motion command may reach.
    fn soft_limits(&self) -> (i64, i64) {
        let on = self.param(Obj::SoftLimits);
        let hi = if on & LIMIT_POSITIVE != 0 { i64::from(self.param(Obj::SoftLimitPositive) as i32) } else { i64::MAX };
        let lo = if on & LIMIT_NEGATIVE != 0 { i64::from(self.param(Obj::SoftLimitNegative) as i32) } else { i64::MIN };
        (lo, hi)
    }

    /// `target` as the soft limits let an axis at `here` go: no further out than a limit, or
    /// than `here` where the axis is beyond it already.
    fn soft_limited(&self, here: i64, target: i64) -> i64 {
        let (lo, hi) = self.soft_limits();
        if target > hi {
            hi.max(here.min(target))
        } else if target < lo {
            lo.min(here.max(target))
        } else {
            target
        }
    }

    /// A run to `target` (within the soft limits) at the run speed 0x21B5.
    fn run_to(&self, axis: &mut Axis, target: i64) -> Result<(), ObjError> {
        let speed = self.param(Obj::CommandSpeed) as f32;
        self.go(axis, &self.pp_setpoint(target, speed)).map(|_| ())
    }

    /// A program's move to `sp.target` (within the soft limits) at its set-point's speeds: the
    /// target it heads for.
    pub(super) fn program_move(&self, axis: &mut Axis, sp: &SetPoint) -> Result<i64, ObjError> {
        self.may_move?;
        self.asked.set(sp.limits.v_max);
        self.within_overspeed(libm::fabsf(axis.setpoint().velocity))?;
        self.go(axis, sp)
    }

    /// A move to `sp.target` within the soft limits, refused towards an active limit switch:
    /// the target it heads for.
    fn go(&self, axis: &mut Axis, sp: &SetPoint) -> Result<i64, ObjError> {
        let here = axis.setpoint().whole;
        if sp.target != here {
            self.away_from_limits(sp.target > here)?;
        }
        let target = self.soft_limited(here, sp.target);
        axis.move_to(self.now, target, sp.depart, sp.arrive, &sp.limits).map_err(|_| ObjError::Infeasible)?;
        Ok(target)
    }

    /// A run at `v` (its sign the direction), or a move to the soft limit it heads for.
    fn run(&self, axis: &mut Axis, v: f32) -> Result<(), ObjError> {
        self.away_from_limits(v > 0.0)?;
        let (lo, hi) = self.soft_limits();
        let here = axis.setpoint().whole;
        let (limit, far) = if v > 0.0 { (hi, i64::MAX) } else { (lo, i64::MIN) };
        if limit != far {
            return self.go(axis, &self.pp_setpoint(self.soft_limited(here, far), libm::fabsf(v))).map(|_| ());
        }
        let sp = self.pp_setpoint(0, v);
        axis.run_at(self.now, v, sp.depart, &sp.limits).map_err(|_| ObjError::Infeasible)
    }
}
