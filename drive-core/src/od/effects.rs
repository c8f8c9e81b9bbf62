//! Which objects' writes do more than store a value: the commands, whose effect the drive's state
//! carries out (motion, PVT), and which a write therefore checks as it is written.

use super::Obj;

/// Whether writing `obj` does more than store its value.
pub(crate) const fn has_effect(obj: Obj) -> bool {
    matches!(
        obj,
        Obj::RelativeMove
            | Obj::AbsoluteMove
            | Obj::MaxSpeed
            | Obj::Mode
            | Obj::Stop
            | Obj::Enable
            | Obj::Position
            | Obj::Microsteps
            | Obj::ControlWord
            | Obj::PpRunSpeed
            | Obj::ZeroOffset
            | Obj::HomingControl
            | Obj::DeviceControl
            | Obj::MotionCommand
            | Obj::CommandTarget
            | Obj::CommandVelocity
    ) || is_pvt_command(obj)
        || is_signal(obj)
        || matches!(obj, Obj::ScopeControl | Obj::ScopeRead | Obj::BlackBoxRead)
}

/// Whether `obj` is one of the signal and view objects whose write is writes of other objects
/// (`state::signals`).
pub(crate) const fn is_signal(obj: Obj) -> bool {
    matches!(
        obj,
        Obj::CommInputs
            | Obj::SpeedJog
            | Obj::PositionJog
            | Obj::TeachPosition
            | Obj::SerialFormat
            | Obj::Restart
            | Obj::SignalInputs1
            | Obj::SignalInputs2
    )
}

/// Whether `obj` is one of the PVT and group objects whose write does more than store.
pub(crate) const fn is_pvt_command(obj: Obj) -> bool {
    matches!(obj, Obj::PvtControl | Obj::PvtMode | Obj::PvtTime | Obj::GroupStart | Obj::GroupStop)
}

/// Whether writing each object does more than store it ([`has_effect`]), by object index: one
/// load instead of a chain of comparisons, on every object of every write.
static COMMAND: [bool; Obj::COUNT] = {
    let mut table = [false; Obj::COUNT];
    let mut i = 0;
    while i < Obj::COUNT {
        #[allow(clippy::indexing_slicing)] // const evaluation: out of bounds is a compile error
        {
            table[i] = has_effect(Obj::ALL[i]);
        }
        i += 1;
    }
    table
};

/// Whether writing `obj` does more than store the value: [`has_effect`], by table.
#[inline(always)]
pub(crate) fn is_command(obj: Obj) -> bool {
    COMMAND.get(obj as usize).copied().unwrap_or(true)
}
