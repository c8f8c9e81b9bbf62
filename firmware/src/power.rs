//! The motor's power stage as the control tick sees it.

use drive_core::control::Outputs;

use crate::coast::Coast;

/// What the control tick asks of a power stage, once per tick.
pub trait PowerStage {
    /// Steps `steps` microsteps (the sign is the direction) within the coming tick; steps that
    /// cannot start yet are kept and emitted later, never dropped.
    fn step(&mut self, steps: i64);
    /// Sets the phase current reference in mA; 0 frees the motor (stage disabled).
    fn set_current(&mut self, milliamps: u16);
    /// The stage's coasting state ([`Coast`]).
    fn coast(&mut self) -> &mut Coast;

    /// Applies one tick's outputs: current first, so a freed motor takes no step; the steps less
    /// those coasted ahead of them.
    fn apply(&mut self, out: &Outputs) {
        self.set_current(out.current_ma);
        let steps = self.coast().ticked(out.steps, &out.commutation);
        self.step(steps);
    }

    /// A tick that cannot run the drive (the bus task holds it): keeps stepping at the last
    /// tick's speed.
    fn coast_on(&mut self) {
        let steps = self.coast().coasting();
        self.step(steps);
    }
}
