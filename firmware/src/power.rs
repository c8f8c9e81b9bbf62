//! The motor's power stage as the control tick sees it.

use drive_core::control::Outputs;

/// What the control tick asks of a power stage, once per tick.
pub trait PowerStage {
    /// Steps `steps` microsteps (the sign is the direction) within the coming tick; steps that
    /// cannot start yet are kept and emitted later, never dropped.
    fn step(&mut self, steps: i64);
    /// Sets the phase current reference in mA; 0 frees the motor (stage disabled).
    fn set_current(&mut self, milliamps: u16);

    /// Applies one tick's outputs: current first, so a freed motor takes no step.
    fn apply(&mut self, out: &Outputs) {
        self.set_current(out.current_ma);
        self.step(out.steps);
    }
}
