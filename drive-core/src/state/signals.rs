//! Signals a master sets as bits (seed 004's communication IO 0451h, its jogs 0528h/0529h) and
//! the objects that are views or actions over others (the teach position, the serial format, the
//! restart): each write becomes writes of the drive's own objects (the enable, the motion
//! command, the position), all or nothing, and the bits are kept for reading back.
//!
//! A communication IO signal acts as the same signal from an input would, while no input carries
//! its function (seed 004: "only while the signal is not assigned to CN3"): servo on is the
//! enable function (20), the overtravels the limit switches (9, 10), alarm reset the alarm
//! clear (13), POS-START and POS-STEP the program commands (16, 19), START-HOME the homing (12),
//! POS0-2 the segment-select bits (25-27).

use super::DriveState;
use super::inputs::INPUT_FUNCTION_OBJECTS;
use super::memory::ProgramMemory;
use crate::controller::Shared;
use crate::modes::Command;
use crate::od::{Obj, ObjError, refuse};
use crate::units::Instant;
use core::borrow::Borrow;

/// 0x2193 bit 0: servo on.
pub const SON: u16 = 1 << 0;
pub use super::inputs::{N_OT, P_OT};
/// 0x2193 bit 4: alarm reset (rising edge).
pub const ALM_RST: u16 = 1 << 4;
/// 0x2193 bit 5: clear the position error (rising edge).
pub const CLR: u16 = 1 << 5;
/// 0x2193 bits 9-11: the position data group (POS0-2).
pub const POS_SHIFT: u32 = 9;
/// 0x2193 bit 13: start the selected group (rising edge).
pub const POS_START: u16 = 1 << 13;
/// 0x2193 bit 14: step to the next group (rising edge).
pub const POS_STEP: u16 = 1 << 14;
/// 0x2193 bit 15: start homing (rising edge).
pub const START_HOME: u16 = 1 << 15;

/// A jog register's bit 15: the motor energised for the jog.
pub const JOG_ON: u16 = 1 << 15;
/// A jog register's bit 0: positive.
pub const JOG_PLUS: u16 = 1 << 0;
/// A jog register's bit 1: negative.
pub const JOG_MINUS: u16 = 1 << 1;

/// Input function 20 (enable), 13 (alarm clear), 12 (home), 16 and 19 (program start, step).
const INPUT_ENABLE: u32 = 20;

/// The input functions of 0x21F4's and 0x21F5's digits.
const SIGNAL_FUNCTIONS: [[u32; 4]; 2] = [[12, 16, 19, 13], [25, 26, 27, INPUT_ENABLE]];

/// The baud rates of the serial format's digit 0 (0x21F1).
pub const SERIAL_BAUDS: [u32; 7] = [4800, 9600, 19_200, 38_400, 57_600, 115_200, 51_200];

pub(crate) use crate::od::is_signal;

/// What the signals left to do in time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Signals {
    /// A jog's bit 15 fell while moving: de-energise once at rest.
    disable_at_rest: bool,
}

/// One write a signal makes: an object's value, or the position jog's move.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Action {
    Write(Obj, u32),
    JogMove(i64),
}
/// Appends the write `obj` = `value` to `out`.
fn push(out: &mut heapless::Vec<Action, MAX_ACTIONS>, obj: Obj, value: u32) -> Result<(), ObjError> {
    out.push(Action::Write(obj, value)).map_err(|_| ObjError::Busy)
}

/// The most writes one signal write makes.
const MAX_ACTIONS: usize = 8;

impl<P: Borrow<Shared>, G: Borrow<ProgramMemory>> DriveState<P, G> {
    /// Whether an input carries `function`: then the communication IO's signal for it is ignored.
    fn input_has(&self, function: u32) -> bool {
        INPUT_FUNCTION_OBJECTS.iter().any(|&o| self.param(o) == function)
    }

    /// 0x21F1 now: the baud rate's and the framing's digits.
    pub(crate) fn serial_format(&self) -> u32 {
        let baud = SERIAL_BAUDS.iter().position(|&b| b == self.param(Obj::BaudRate)).unwrap_or(1) as u32;
        let format = self.param(Obj::LineFraming) * 3 + self.param(Obj::Parity).min(2);
        format << 4 | baud
    }

    /// The writes `obj` = `value` makes, in order; refused if it cannot be made now.
    fn signal_actions(&self, obj: Obj, value: u32) -> Result<heapless::Vec<Action, MAX_ACTIONS>, ObjError> {
        let mut out = heapless::Vec::new();
        let (old, new) = (self.param(obj) as u16, value as u16);
        let rose = |bit: u16| new & bit != 0 && old & bit == 0;
        match obj {
            Obj::CommInputs => {
                if new & SON != old & SON && !self.input_has(INPUT_ENABLE) {
                    push(&mut out, Obj::Enable, u32::from(new & SON != 0))?;
                }
                if rose(ALM_RST) && !self.input_has(Command::AlarmClear.raw()) {
                    push(&mut out, Obj::SystemControl, 4)?;
                    // Servo on still asked: on again once the alarm is gone (refused if it is not).
                    if new & SON != 0 && !self.input_has(INPUT_ENABLE) {
                        push(&mut out, Obj::Enable, 1)?;
                    }
                }
                if rose(CLR) && self.ctl.servo.following != 0 {
                    refuse(self.ctl.axis.is_still(), ObjError::Busy)?;
                    push(&mut out, Obj::Position, self.live(Obj::ActualPosition))?;
                }
                for (bit, command) in
                    [(START_HOME, Command::Home), (POS_START, Command::ProgramStart), (POS_STEP, Command::ProgramStep)]
                {
                    if rose(bit) && !self.input_has(command.raw()) {
                        push(&mut out, Obj::MotionCommand, command.raw())?;
                    }
                }
            }
            Obj::SpeedJog | Obj::PositionJog => {
                refuse(new & JOG_ON != 0 || new & (JOG_PLUS | JOG_MINUS) == 0, ObjError::NotNow)?;
                if new & JOG_ON != 0 && self.param(Obj::Enable) == 0 {
                    push(&mut out, Obj::Enable, 1)?;
                }
                let dir = |v: u16| match v & (JOG_PLUS | JOG_MINUS) {
                    JOG_PLUS => 1,
                    JOG_MINUS => -1,
                    _ => 0,
                };
                if obj == Obj::SpeedJog && dir(new) != dir(old) {
                    let command = match dir(new) {
                        1 => Command::JogPositive,
                        -1 => Command::JogNegative,
                        _ => Command::Stop,
                    };
                    if command != Command::Stop || !self.ctl.axis.is_still() {
                        push(&mut out, Obj::MotionCommand, command.raw())?;
                    }
                }
                if obj == Obj::PositionJog && (rose(JOG_PLUS) || rose(JOG_MINUS)) && dir(new) != 0 {
                    refuse(self.ctl.axis.is_still(), ObjError::Busy)?;
                    // A running chain of groups owns the axis, as it does against the jog commands.
                    refuse(!self.program_runs(), ObjError::NotNow)?;
                    let distance = i64::from(self.param(Obj::JogDistance)) * i64::from(dir(new));
                    out.push(Action::JogMove(distance)).map_err(|_| ObjError::Busy)?;
                }
                if old & JOG_ON != 0 && new & JOG_ON == 0 {
                    if obj == Obj::SpeedJog && !self.ctl.axis.is_still() {
                        push(&mut out, Obj::MotionCommand, Command::Stop.raw())?;
                    }
                    if self.ctl.axis.is_still() {
                        push(&mut out, Obj::Enable, 0)?;
                    }
                }
            }
            Obj::TeachPosition => push(&mut out, Obj::Position, value)?,
            Obj::SerialFormat => {
                let baud = SERIAL_BAUDS.get(value as usize & 0xF).filter(|&&b| b != 51_200);
                let format = value >> 4 & 0xF;
                let baud = *baud.ok_or(ObjError::OutOfRange)?;
                refuse(format <= 5, ObjError::OutOfRange)?;
                push(&mut out, Obj::BaudRate, baud)?;
                push(&mut out, Obj::Parity, format % 3)?;
                push(&mut out, Obj::LineFraming, format / 3)?;
            }
            Obj::SignalInputs1 | Obj::SignalInputs2 => {
                let functions =
                    SIGNAL_FUNCTIONS.get(usize::from(obj == Obj::SignalInputs2)).copied().unwrap_or_default();
                let mut now = INPUT_FUNCTION_OBJECTS.map(|o| self.param(o));
                let mut named = 0u8;
                for (k, &f) in functions.iter().enumerate() {
                    let digit = value >> (4 * k) & 0xF;
                    for slot in now.iter_mut().filter(|s| **s == f) {
                        *slot = 0;
                    }
                    if let Some(input) = (digit as usize).checked_sub(1) {
                        refuse(input < 7 && named & (1 << input) == 0, ObjError::OutOfRange)?;
                        named |= 1 << input;
                        if let Some(slot) = now.get_mut(input) {
                            *slot = f;
                        }
                    }
                }
                for (&o, &f) in INPUT_FUNCTION_OBJECTS.iter().zip(&now) {
                    if self.param(o) != f {
                        push(&mut out, o, f)?;
                    }
                }
            }
            Obj::Restart => {
                refuse(self.ctl.axis.is_still() && self.storage & super::STORAGE_SAVING == 0, ObjError::Busy)?;
            }
            _ => {}
        }
        Ok(out)
    }

    /// Whether `obj` = `value` may be written now, as far as can be told without making its
    /// writes (each is checked as it is made).
    pub(crate) fn check_signal(&self, obj: Obj, value: u32) -> Result<(), ObjError> {
        self.signal_actions(obj, value).map(|_| ())
    }

    /// Writes the signal object `obj` = `value` (in range): its writes all or nothing, then the
    /// bits kept. `undoable`: inside a write whose checkpoint undoes it if refused later.
    pub(crate) fn write_signal(&mut self, obj: Obj, value: u32, undoable: bool) -> Result<(), ObjError> {
        let actions = self.signal_actions(obj, value)?;
        let jog_off = matches!(obj, Obj::SpeedJog | Obj::PositionJog)
            && self.param(obj) as u16 & JOG_ON != 0
            && value as u16 & JOG_ON == 0;
        // Inside a write that has its own checkpoint, that one undoes these writes too.
        let saved = (!undoable).then(|| self.checkpoint());
        for &a in &actions {
            if let Err(e) = self.write_one(a) {
                if let Some(c) = saved {
                    self.restore(c);
                }
                return Err(e);
            }
        }
        if jog_off && !self.ctl.axis.is_still() {
            self.signals.disable_at_rest = true;
        }
        if obj == Obj::Restart {
            self.request = Some(super::SystemRequest::Restart);
            return Ok(());
        }
        if !matches!(obj, Obj::SerialFormat | Obj::SignalInputs1 | Obj::SignalInputs2) {
            self.set_param(obj, value);
        }
        Ok(())
    }

    /// One write of a signal: an object's, or the position jog's move.
    fn write_one(&mut self, action: Action) -> Result<(), ObjError> {
        match action {
            Action::Write(obj, value) => self.write_undoable(obj.def(), value),
            Action::JogMove(distance) => self.position_jog_move(distance),
        }
    }

    /// The position jog's move by `distance` at the jog speed.
    fn position_jog_move(&mut self, distance: i64) -> Result<(), ObjError> {
        let v = self.param(Obj::JogSpeed) as f32;
        let limits = crate::motion::scurve::Limits {
            v_max: v,
            a_max: self.param(Obj::PpAccel) as f32,
            d_max: self.param(Obj::PpDecel) as f32,
            jerk: None,
        };
        let start = self.param(Obj::PpStartSpeed) as f32;
        let stop = self.param(Obj::PpStopSpeed) as f32;
        let here = self.ctl.axis.setpoint().whole;
        let target = here.saturating_add(distance);
        let sp = super::control::SetPoint { target, limits, depart: start.min(v), arrive: stop.min(v) };
        self.plan_program_move(&sp).map(|_| ())
    }

    /// When [`DriveState::signals_service`] has something to do.
    pub(crate) fn signals_due(&self) -> Option<Instant> {
        (self.signals.disable_at_rest && self.ctl.axis.is_still()).then_some(self.now)
    }

    /// A jog switched off while moving: de-energised once at rest.
    pub(crate) fn signals_service(&mut self) {
        if self.signals_due().is_some() {
            self.signals.disable_at_rest = false;
            let _ = self.write_undoable(Obj::Enable.def(), 0);
        }
    }

    /// 0x21F4 or 0x21F5 now: for each digit's signal, the first input that carries it.
    pub(crate) fn signal_inputs(&self, obj: Obj) -> u32 {
        let functions = SIGNAL_FUNCTIONS.get(usize::from(obj == Obj::SignalInputs2)).copied().unwrap_or_default();
        let digit =
            |f: u32| INPUT_FUNCTION_OBJECTS.iter().position(|&o| self.param(o) == f).map_or(0, |k| k as u32 + 1);
        functions.iter().enumerate().fold(0, |v, (k, &f)| v | digit(f) << (4 * k))
    }

    /// The position data group the communication IO's POS0-2 select.
    pub(crate) fn comm_group(&self) -> u8 {
        (self.param(Obj::CommInputs) >> POS_SHIFT & 0b111) as u8
    }
}
