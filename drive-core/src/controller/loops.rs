//! The encoder, the closed loops and stall detection at each tick (see [`crate::servo`] for what
//! they do).

use super::{Controller, STATUS_STALL, Settings};
use crate::faults::{FAULT_POSITION, Inputs};
use crate::motion::axis::Setpoint;
use crate::servo::{Encoder, Feedback, Micro, STEPS_PER_REV, SensorlessInput, small};
use crate::units::Instant;
use fixed::types::U0F32;

impl Controller {
    /// The encoder reading of this tick: 0x6089, and in closed loop the measured position. The
    /// first reading of a closed loop places the standing axis on the measured position.
    pub(crate) fn sense(&mut self, s: &Settings, inputs: &Inputs) {
        let Some(raw) = inputs.encoder else { return };
        let kind = self.servo.encoder_kind(s.encoder_cpr);
        // A reversed motor's encoder counts the other way.
        let raw = match (self.reversed, kind) {
            (false, _) => raw,
            (true, Encoder::SingleTurn) => 4096u32.wrapping_sub(raw) & 0xFFF,
            (true, _) => raw.wrapping_neg(),
        };
        let first = self.servo.read(kind, raw);
        self.status.encoder = self.servo.encoder as i32;
        let Feedback::Closed(encoder) = self.servo.feedback else { return };
        if first && matches!(encoder, Encoder::Incremental { .. }) && s.auto_save {
            // §5.5.15: the incremental closed loop starts from the power-down position.
            self.zero_offset = s.saved_position;
            self.raise(super::Events::ZERO_OFFSET);
        }
        // While the power stage is off the setpoint follows the rotor (turned by hand, say), so
        // that enabling does not jump back.
        if (first || !self.power_stage_on(s)) && self.axis.is_still() {
            let measured = self.measured();
            if measured != self.axis.setpoint().whole {
                self.axis.set_position(measured);
            }
        }
    }

    /// The sensorless detector's present estimates: the load angle (rad, in the direction of
    /// motion) and the back-EMF magnitude (V), both low-passed. For traces and tuning.
    pub fn stall_estimate(&self) -> (f32, f32) {
        (self.servo.sensorless.load_angle(), self.servo.sensorless.emf)
    }

    /// The measured position (closed loop): encoder position + zero offset 0x6087.
    pub(crate) fn measured(&self) -> i64 {
        self.servo.encoder.wrapping_add(i64::from(self.zero_offset))
    }

    /// 0x607F: the measured speed in closed loop, the commanded one in open loop.
    pub(crate) fn real_speed(&self) -> i32 {
        let v = match self.servo.feedback {
            Feedback::Open => libm::roundf(self.axis.setpoint().velocity),
            Feedback::Closed(_) => libm::roundf(self.servo.speed),
        };
        v as i32
    }

    /// The electrical angle and the share of the phase current to drive for the setpoint `sp`,
    /// with the stall detection of the loop in force.
    /// `moved` is the whole microsteps the setpoint moved this tick: in open loop the angle
    /// advances by them, so that declaring a position (0x600E) does not turn the motor.
    pub(crate) fn commutate(
        &mut self,
        s: &Settings,
        now: Instant,
        sp: &Setpoint,
        moved: i64,
        inputs: &Inputs,
    ) -> (Setpoint, f32) {
        let per_step = u32::from(s.microsteps).max(1);
        if per_step != self.servo.last_per_step {
            // A new resolution: the same electrical angle in the new microsteps.
            let (new, old) = (i64::from(per_step), i64::from(self.servo.last_per_step.max(1)));
            self.servo.last_angle = (self.servo.last_angle.saturating_mul(2 * new).div_euclid(old) + 1).div_euclid(2);
            self.servo.last_per_step = per_step;
        }
        let Feedback::Closed(encoder) = self.servo.feedback else {
            self.detect_stall_sensorless(s, now, sp, inputs, per_step);
            return (Setpoint { whole: self.servo.last_angle.saturating_add(moved), ..*sp }, 1.0);
        };
        let per_rev = encoder.counts_per_rev();
        let rotor = self.servo.rotor_angle(per_rev, per_step);
        let following = sp.whole.saturating_sub(self.measured());
        self.servo.following = following;
        let to_micro = (STEPS_PER_REV as f32 * per_step as f32) / per_rev as f32;
        let error = (small(following) + sp.fraction.to_num::<f32>()) * to_micro;
        let velocity = sp.velocity * to_micro;
        let at = |m: Micro, velocity: f32| Setpoint {
            whole: m.whole,
            fraction: U0F32::from_bits((m.fraction * 4_294_967_296.0) as u32),
            velocity,
            acceleration: 0.0,
        };
        if !self.power_stage_on(s) {
            self.servo.relax();
            return (at(rotor, 0.0), 0.0);
        }
        if libm::fabsf(error) > s.following_limit as f32 {
            // A following error beyond 0x605C: the position error alarm (25) and the stall bit.
            self.status.controller |= STATUS_STALL;
            self.latch(now, 0, FAULT_POSITION);
            if !self.stall_caught() {
                self.stop_motion();
            }
            self.servo.relax();
            return (at(rotor, 0.0), 0.0);
        }
        let drive = if s.servo_loop {
            let g = s.gains;
            self.servo.servo_loop(rotor, error / per_step as f32, per_step, &g)
        } else {
            self.servo.position_loop(rotor, error, per_step)
        };
        (at(drive.angle, velocity), drive.current)
    }

    /// Open loop: the sensorless stall detection (0x2107), from the phase currents and voltages.
    fn detect_stall_sensorless(&mut self, s: &Settings, now: Instant, sp: &Setpoint, inputs: &Inputs, per_step: u32) {
        let (Some(mut ma), Some(mut mv)) = (inputs.phase_ma, inputs.phase_mv) else {
            return self.servo.sensorless.reset();
        };
        let mut emf = inputs.back_emf_mv;
        if self.reversed {
            // A reversed motor's phase B is driven inverted.
            (ma[1], mv[1]) = (ma[1].saturating_neg(), mv[1].saturating_neg());
            if let Some([_, b]) = &mut emf {
                *b = b.saturating_neg();
            }
        }
        if !s.stall_detect || !self.power_stage_on(s) {
            return self.servo.sensorless.reset();
        }
        let x = SensorlessInput {
            i: ma.map(|m| m as f32 * 1e-3),
            v: mv.map(|m| m as f32 * 1e-3),
            e: emf.map(|e| e.map(|m| m as f32 * 1e-3)),
            r: s.motor_r,
            l: s.motor_l,
            speed: sp.velocity / per_step as f32,
            min_speed: s.stall_min_speed,
            limit_cos: s.stall_limit_cos,
        };
        if self.servo.sensorless.update(now, &x) && self.status.controller & STATUS_STALL == 0 {
            self.status.controller |= STATUS_STALL;
            if !self.stall_caught() && s.stall_stop {
                self.stop_motion();
            }
        }
    }
}
