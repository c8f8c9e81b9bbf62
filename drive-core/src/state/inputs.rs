//! The inputs' functions on the bus side (our 0x21BA-0x21C2; seed 002's 0400-0416, 0429): an
//! input turning active, or its pseudo-input written 1, carries out its function here, planned
//! as a write of the motion command would be; an enable input holds 0x6011 at its level. The
//! control tick reads the inputs, latches their activations for this side and stops a motion
//! heading into an active limit switch (`controller::io`); the homing takes its switches from
//! the inputs' functions (`homing`).
//!
//! Choices where seed 002 is silent: an input acts on its activation (its edge), not while it
//! stays active, so that a held jog input jogs once it is pressed and a stop (6) ends it; the
//! levels an input is in at power-up are no activation. A command an input gives is refused as
//! the same write over the bus would be, and then nothing moves; the master sees the refusal in
//! nothing but the motion not happening (seed 002 has no status for it). An enable input sets
//! 0x6011 to its level when the level changes (and at power-up); a master's write of 0x6011
//! in between stands until the next change.

use super::DriveState;
use super::memory::ProgramMemory;
use crate::controller::Shared;
use crate::controller::handoff::Clears;
use crate::modes::Command;
use crate::od::Obj;
use crate::units::Instant;
use core::borrow::Borrow;

/// IN1-IN7's function objects.
pub(crate) const INPUT_FUNCTION_OBJECTS: [Obj; 7] = [
    Obj::InputFunction1,
    Obj::InputFunction2,
    Obj::InputFunction3,
    Obj::InputFunction4,
    Obj::InputFunction5,
    Obj::InputFunction6,
    Obj::InputFunction7,
];
/// Input function 9: the positive limit switch.
pub(crate) const INPUT_LIMIT_POSITIVE: u32 = 9;
/// Input function 10: the negative limit switch.
pub(crate) const INPUT_LIMIT_NEGATIVE: u32 = 10;
/// Input function 11: the home switch.
pub(crate) const INPUT_HOME: u32 = 11;
/// Input function 20: enable.
const INPUT_ENABLE: u32 = 20;
/// Input function 21: touch probe 1 (the tick captures the position into 0x21DB).
pub(crate) const INPUT_PROBE_1: u32 = 21;
/// Input function 22: touch probe 2 (0x21DD).
pub(crate) const INPUT_PROBE_2: u32 = 22;

/// 0x2193 bit 2: positive overtravel (seed 004's P-OT).
pub const P_OT: u16 = 1 << 2;
/// 0x2193 bit 3: negative overtravel (N-OT).
pub const N_OT: u16 = 1 << 3;

/// The overtravel signals of the communication IO `comm` that act (bit 0 positive, bit 1
/// negative): those of the limits no input is (`positive`, `negative`: the inputs that are).
pub(crate) fn overtravel(comm: u32, positive: u8, negative: u8) -> u8 {
    let comm = comm as u16;
    u8::from(positive == 0 && comm & P_OT != 0) | u8::from(negative == 0 && comm & N_OT != 0) << 1
}

/// The bus side's memory of the inputs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Inputs {
    /// The pseudo-inputs (0x21C2) already acted on.
    pseudo_seen: u8,
    /// The enable input's level last acted on (none yet).
    enable_seen: Option<bool>,
}

impl<P: Borrow<Shared>, G: Borrow<ProgramMemory>> DriveState<P, G> {
    /// The function of IN k+1 (0x21BA-0x21C0).
    pub(crate) fn input_function(&self, k: usize) -> u32 {
        INPUT_FUNCTION_OBJECTS.get(k).map_or(0, |&obj| self.param(obj))
    }

    /// The inputs active now, or set as pseudo-inputs: bit k IN k+1.
    pub(crate) fn active_inputs(&self) -> u8 {
        self.ctl.status.inputs | self.param(Obj::PseudoInputs) as u8
    }

    /// Whether an input with function `function` is active now (or its pseudo-input set).
    pub(crate) fn input_active(&self, function: u32) -> bool {
        let active = self.active_inputs();
        (0..INPUT_FUNCTION_OBJECTS.len()).any(|k| active & (1 << k) != 0 && self.input_function(k) == function)
    }

    /// The enable an enable input asks for, if an input has that function.
    fn enable_asked(&self) -> Option<bool> {
        let has = (0..INPUT_FUNCTION_OBJECTS.len()).any(|k| self.input_function(k) == INPUT_ENABLE);
        has.then(|| self.input_active(INPUT_ENABLE))
    }

    /// When [`DriveState::inputs_service`] has something to do: now, if an input turned active,
    /// a pseudo-input changed, or an enable input's level is not yet acted on (once a level:
    /// a refused enable does not make the service due again and again).
    pub(crate) fn inputs_due(&self) -> Option<Instant> {
        let pseudo = self.param(Obj::PseudoInputs) as u8;
        let enable = self.enable_asked().is_some_and(|on| self.inputs.enable_seen != Some(on));
        let due = self.ctl.status.input_edges != 0 || pseudo != self.inputs.pseudo_seen || enable;
        due.then_some(self.now)
    }

    /// Carries out the functions of the inputs that turned active since the last time, and the
    /// enable input's level.
    pub(crate) fn inputs_service(&mut self) {
        let pseudo = self.param(Obj::PseudoInputs) as u8;
        let taken = self.ctl.status.input_edges;
        let edges = taken | (pseudo & !self.inputs.pseudo_seen);
        self.clear_status(Clears { input_edges: taken, ..Clears::NONE });
        self.inputs.pseudo_seen = pseudo;
        for k in 0..INPUT_FUNCTION_OBJECTS.len() {
            let function = self.input_function(k);
            if edges & (1 << k) == 0 || !Command::from_raw(function).is_some_and(|c| c != Command::None) {
                continue;
            }
            // Refused as the same write over the bus would be: nothing moves.
            let _ = self.write_undoable(Obj::MotionCommand.def(), function);
        }
        if let Some(on) = self.enable_asked()
            && self.inputs.enable_seen != Some(on)
        {
            self.inputs.enable_seen = Some(on);
            if on != (self.param(Obj::Enable) == 1) {
                let _ = self.write_undoable(Obj::Enable.def(), u32::from(on));
            }
        }
    }

    /// Whether a motion heading up (`up`) runs into an active limit switch (the settings know
    /// which inputs are limits).
    pub(crate) fn limit_ahead(&self, up: bool) -> bool {
        let io = &self.settings.io;
        let limits = if up { io.limit_positive } else { io.limit_negative };
        self.active_inputs() & limits != 0 || io.overtravel & if up { 1 } else { 2 } != 0
    }
}
