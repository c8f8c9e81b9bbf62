//! The motor's power stage as the control tick sees it.

use drive_core::control::Outputs;
use drive_core::controller::io::{PinConfig, PulseInput};

/// What the control tick asks of a power stage, once per tick.
pub trait PowerStage {
    /// Steps `steps` microsteps (the sign is the direction) within the coming tick; steps that
    /// cannot start yet are kept and emitted later, never dropped.
    fn step(&mut self, steps: i64);
    /// Sets the phase current reference in mA; 0 frees the motor (stage disabled).
    fn set_current(&mut self, milliamps: u16);

    /// Sets the pins up as `pins` says (pulls, directions, drivers) and the outputs to `levels`
    /// (1 high, bits as 0x6031). A board without the pins ignores it.
    fn set_pins(&mut self, _pins: &PinConfig, _levels: u16) {}
    /// Sets the coil output's PWM duty, percent. A board without the output ignores it.
    fn set_coil(&mut self, _duty: u8) {}
    /// Sets the pulse input's counter up as `input` says (format, filter). A board without the
    /// input ignores it.
    fn set_pulse_input(&mut self, _input: &PulseInput) {}

    /// Takes one tick's outputs whole: a stage with its own current loop sets its next
    /// period's reference from them (`drive_core::windings`). A board without one ignores it.
    fn command(&mut self, _out: &Outputs) {}

    /// Applies one tick's outputs: current first, so a freed motor takes no step.
    fn apply(&mut self, out: &Outputs) {
        self.command(out);
        self.set_current(out.current_ma);
        self.step(out.steps);
        self.set_pins(&out.pins, out.gpio);
        self.set_coil(out.coil_duty);
        self.set_pulse_input(&out.pulse);
    }
}
