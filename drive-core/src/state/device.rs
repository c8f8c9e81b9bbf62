//! The power state machine on the drive ([`crate::power`]): the device controlword 0x2180 and
//! statusword 0x2181, the quick stop, the fault reset, and the error register 0x2185.
//!
//! The state machine drives the enable 0x6011: the motor is energised exactly in operation
//! enabled and quick stop active, so the native map's enable stays a shortcut through it (1:
//! operation enabled, 0: switch on disabled). A latched fault, an EXT stop, a stall that stopped
//! the motor or the communication timeout shows as the fault state; a fault reset clears them
//! all (a condition still present latches again) and leaves the drive switch on disabled.

use super::DriveState;
use super::memory::ProgramMemory;
use crate::controller::Shared;
use crate::faults::{FAULT_OVER_VOLTAGE, FAULT_OVERLOAD, FAULT_POSITION};
use crate::modes::{PowerState, WorkMode};
use crate::od::{Obj, ObjError};
use crate::power::{Command, DeviceState, QuickStopOption};
use crate::state::control::{SW_SETPOINT_ACK, SW_TARGET_REACHED};
use crate::units::Instant;
use core::borrow::Borrow;

/// Controlword bit 4: new set-point (PP), start the homing (homing mode).
const CW_START: u16 = 1 << 4;
/// Controlword bit 7: fault reset.
const CW_FAULT_RESET: u16 = 1 << 7;
/// Controlword bit 8: halt.
const CW_HALT: u16 = 1 << 8;
/// The controlword bits the profile modes take (0x6070's: 4, 5, 6, 8, 9).
const CW_PROFILE: u16 = 0x0370;

/// How often a quick stop is checked for rest, µs.
const QUICK_STOP_CHECK: u64 = 1_000;

impl<P: Borrow<Shared>, G: Borrow<ProgramMemory>> DriveState<P, G> {
    /// The power state, a latched fault first.
    pub fn device_state(&self) -> DeviceState {
        if self.may_move() == Err(ObjError::Faulted) { DeviceState::Fault } else { self.device }
    }

    /// Writes the device controlword; the caller undoes everything if it is refused (a
    /// set-point or a homing it starts may be).
    pub(crate) fn device_control(&mut self, value: u32) -> Result<(), ObjError> {
        let old = self.param(Obj::DeviceControl) as u16;
        let new = value as u16;
        self.set_param(Obj::DeviceControl, value);
        let shown = self.device_state();
        match Command::decode(new) {
            Command::FaultReset if shown == DeviceState::Fault && old & CW_FAULT_RESET == 0 => {
                return self.fault_reset();
            }
            Command::FaultReset => return Ok(()),
            // Outside a reset, a latched fault ignores the controlword.
            _ if shown == DeviceState::Fault => return Ok(()),
            cmd => {
                if let Some(next) = self.device.on(cmd) {
                    self.enter(next)?;
                }
            }
        }
        if self.device == DeviceState::OperationEnabled {
            self.operate(old, new)?;
        }
        Ok(())
    }

    /// Goes to the state `next`, switching the power stage with it.
    fn enter(&mut self, next: DeviceState) -> Result<(), ObjError> {
        let was = self.device.energised();
        if next == DeviceState::QuickStopActive {
            return self.quick_stop();
        }
        if next.energised() && !was {
            self.write_undoable(Obj::Enable.def(), 1)?;
        } else if !next.energised() && was {
            self.write_undoable(Obj::Enable.def(), 0)?;
        }
        self.device = next;
        Ok(())
    }

    /// The quick stop: the ramp of the quick stop option 0x2182.
    fn quick_stop(&mut self) -> Result<(), ObjError> {
        let option = QuickStopOption::from_raw(self.param(Obj::QuickStopOption)).unwrap_or_default();
        self.end_motion();
        match option {
            QuickStopOption::Disable => {
                self.write_undoable(Obj::Enable.def(), 0)?;
                self.device = DeviceState::SwitchOnDisabled;
                return Ok(());
            }
            QuickStopOption::Immediate => self.ctl.axis.halt(),
            o if o.quick() => self.ctl.axis.stop_ramp(self.param(Obj::QuickStopDecel)),
            _ => self.ctl.axis.stop_ramp(self.param(Obj::PpDecel)),
        }
        self.device = DeviceState::QuickStopActive;
        self.quick_check = self.now.plus_micros(QUICK_STOP_CHECK);
        self.quick_stop_settle();
        Ok(())
    }

    /// Ends the set-points, a PVT run and a homing, as a stop does.
    fn end_motion(&mut self) {
        self.pp = super::Pp::default();
        self.end_run();
        if self.homing_outcome() == crate::state::homing::Outcome::Running as u32 {
            self.homing_command(0);
        }
    }

    /// A quick stop at rest leaves for switch on disabled, unless its option stays; still
    /// moving, it is checked again later.
    pub(crate) fn quick_stop_settle(&mut self) {
        let option = QuickStopOption::from_raw(self.param(Obj::QuickStopOption)).unwrap_or_default();
        if self.device != DeviceState::QuickStopActive || option.stays() {
            return;
        }
        if self.ctl.axis.is_still() {
            self.set_param(Obj::Enable, 0);
            self.device = DeviceState::SwitchOnDisabled;
        } else {
            self.quick_check = self.now.plus_micros(QUICK_STOP_CHECK);
        }
    }

    /// When a quick stop is to be checked for rest ([`DriveState::service`]).
    pub(crate) fn device_due(&self) -> Option<Instant> {
        let option = QuickStopOption::from_raw(self.param(Obj::QuickStopOption)).unwrap_or_default();
        (self.device == DeviceState::QuickStopActive && !option.stays()).then_some(self.quick_check)
    }

    /// Clears every latch that shows as the fault state, and leaves the drive switch on disabled.
    fn fault_reset(&mut self) -> Result<(), ObjError> {
        self.clear_alarms();
        if self.device.energised() {
            self.write_undoable(Obj::Enable.def(), 0)?;
        }
        self.device = DeviceState::SwitchOnDisabled;
        Ok(())
    }

    /// The controlword's mode bits in operation enabled.
    fn operate(&mut self, old: u16, new: u16) -> Result<(), ObjError> {
        let rise = |bit: u16| new & bit != 0 && old & bit == 0;
        match self.mode() {
            m if m.is_profile() => self.write_undoable(Obj::ControlWord.def(), u32::from(new & CW_PROFILE)),
            WorkMode::Homing if rise(CW_HALT) => self.write_undoable(Obj::HomingControl.def(), 0),
            WorkMode::Homing if rise(CW_START) && new & CW_HALT == 0 => {
                self.write_undoable(Obj::HomingControl.def(), 1)
            }
            _ => Ok(()),
        }
    }

    /// The native enable 0x6011 was written `value`: the state machine follows.
    pub(crate) fn enable_written(&mut self, value: u32) {
        if value == 1 && !self.device.energised() {
            self.device = DeviceState::OperationEnabled;
        } else if value == 0 {
            self.device = DeviceState::SwitchOnDisabled;
        }
    }

    /// The device statusword 0x2181.
    pub(crate) fn device_status(&self) -> u16 {
        let bit = |on: bool, k: u16| if on { 1 << k } else { 0 };
        let mut sw = self.device_state().statusword();
        let cw = self.param(Obj::DeviceControl) as u16;
        let still = self.motor_still();
        sw |= bit(self.ctl.power_state(&self.settings) == PowerState::Freed, 7);
        sw |= bit(cw & CW_HALT != 0, 8) | bit(!still, 9);
        let [home, negative, positive] = self.switches();
        sw |= bit(home, 11) | bit(negative, 14) | bit(positive, 15);
        use crate::state::homing::Outcome;
        sw |= match self.mode() {
            WorkMode::ProfilePosition => {
                // Bit 12 as seed 001 has it: a new set-point can be taken (CiA 402's set-point
                // acknowledge, 0x6071's, inverted).
                let sw = self.statusword();
                (sw & SW_TARGET_REACHED)
                    | bit(sw & SW_SETPOINT_ACK == 0, 12)
                    | bit(self.ctl.status.faults & FAULT_POSITION != 0, 13)
            }
            WorkMode::ProfileVelocity => bit(self.ctl.axis.settled(), 10) | bit(still, 12),
            WorkMode::Homing => {
                let outcome = self.homing_outcome();
                let failed = outcome == Outcome::Timeout as u32 || outcome == Outcome::Interrupted as u32;
                bit(outcome != Outcome::Running as u32, 10)
                    | bit(outcome == Outcome::Homed as u32, 12)
                    | bit(failed, 13)
            }
            _ => 0,
        };
        sw
    }

    /// The error register 0x2185.
    pub(crate) fn error_register(&self) -> u8 {
        let s = &self.ctl.status;
        let bit = |on: bool, k: u8| if on { 1 << k } else { 0 };
        let current = s.error & 0x18 != 0 || s.faults & FAULT_OVERLOAD != 0;
        let voltage = s.error & 0x20 != 0 || s.faults & FAULT_OVER_VOLTAGE != 0;
        let any = s.error != 0 || s.faults != 0 || s.comm != 0;
        bit(any, 0)
            | bit(current, 1)
            | bit(voltage, 2)
            | bit(s.error & 0x01 != 0, 3)
            | bit(s.comm != 0, 4)
            | bit(s.faults & FAULT_POSITION != 0, 5)
            | bit(s.error & 0x06 != 0, 7)
    }
}
