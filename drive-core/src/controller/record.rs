//! The scope's and the black box's rows: the signals' values at the end of a tick.

use super::{Controller, STATUS_BUSY};
use crate::faults::Inputs;
use crate::motion::axis::Setpoint;
use crate::scope::{Frame, Phase, Recordings};
use crate::servo::Feedback;
use crate::units::Instant;

/// What a tick worked out that a row may hold, besides the controller's state.
pub(super) struct Tick<'a> {
    pub now: Instant,
    pub setpoint: &'a Setpoint,
    pub current_ma: u16,
    /// The closed loop's share of the phase current.
    pub share: f32,
    pub inputs: &'a Inputs,
}

/// `x` to the nearest integer (halves away from zero), saturated: an FPU conversion, not a
/// library call.
fn nearest(x: f32) -> i32 {
    (x + libm::copysignf(0.5, x)) as i32
}

/// `v` saturated to 32 bits.
fn wide(v: i64) -> i32 {
    v.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32
}

impl Controller {
    /// Every signal at the end of this tick, by code (`scope::Signal`): straight-line
    /// arithmetic, cheaper than choosing.
    #[inline(always)]
    fn frame(&self, t: &Tick<'_>) -> Frame {
        let closed = matches!(self.servo.feedback, Feedback::Closed(_));
        let st = &self.status;
        let [a, b] = t.inputs.phase_ma.unwrap_or_default();
        let busy = if self.axis.is_still() && self.shaping_settled { 0 } else { STATUS_BUSY };
        let commanded = nearest(t.setpoint.velocity);
        [
            0,
            wide(t.setpoint.whole),
            if closed { wide(self.measured()) } else { st.encoder },
            wide(self.servo.following),
            commanded,
            if closed { nearest(self.servo.speed) } else { commanded },
            a,
            b,
            i32::from(t.current_ma),
            i32::from(st.supply_mv),
            t.inputs.temperature_c.map_or(0, i32::from),
            i32::from(u16::from(st.controller | busy) | (u16::from(st.error) << 8)),
            i32::from(u16::from(st.faults) | (u16::from(st.comm) << 8)),
            if closed { nearest(t.share.clamp(0.0, 1.0) * 10_000.0) } else { 10_000 },
            i32::from(t.inputs.levels),
            i32::from(self.faults.count),
        ]
    }

    /// The row that is due ([`crate::scope::Scopes::due`]) of this tick, into `recordings`.
    #[inline(never)]
    pub(super) fn record(&mut self, t: &Tick<'_>, recordings: &Recordings) {
        let frame = self.frame(t);
        let waiting = self.scopes.black_box.phase() == Phase::Armed;
        self.scopes.row(recordings, &frame, t.now.as_micros());
        if waiting && self.scopes.black_box.phase() != Phase::Armed {
            self.scopes.black_box_fault = self.faults.entry(0);
        }
    }
}
