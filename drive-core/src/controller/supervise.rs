//! Supervision at each tick: faults latched from the measurements, power loss, the
//! communication watchdog (see [`crate::faults`] for what each one means).

use super::{Controller, Settings};
use crate::faults::{
    COMM_TIMEOUT, ERR_A_OVER_CURRENT, ERR_B_OVER_CURRENT, ERR_COIL_A_OPEN, ERR_COIL_B_OPEN, ERR_OVER_TEMPERATURE,
    ERR_UNDER_VOLTAGE, ERROR_ALARMS, FAULT_ALARMS, FAULT_ENCODER, FAULT_OVER_VOLTAGE, FAULT_OVERLOAD, FAULT_OVERSPEED,
    FAULT_SENSING, FAULT_STORE, Inputs, OVERLOAD_MICROS, code_of, detect,
};
use crate::units::Instant;

impl Controller {
    /// Whether a fault is latched (0x6000 or 0x2135): the power stage stays off.
    pub fn faulted(&self) -> bool {
        self.status.error != 0 || self.status.faults != 0
    }

    /// The alarm code 0x2134 shows: the most severe latched alarm, 0 for none.
    pub(crate) fn alarm_code(&self) -> u8 {
        let comm = (self.status.comm & COMM_TIMEOUT != 0).then_some(crate::faults::alarm::COMM_TIMEOUT);
        code_of(&ERROR_ALARMS, self.status.error)
            .or_else(|| code_of(&FAULT_ALARMS, self.status.faults))
            .or(comm)
            .unwrap_or(0)
    }

    /// Checks the measurements at `now`: latches faults, records them, and applies the fault and
    /// power-loss reactions to the motion.
    pub(crate) fn supervise(&mut self, s: &Settings, now: Instant, inputs: &Inputs) {
        if let Some(mv) = inputs.supply_mv {
            self.status.supply_mv = mv.min(u32::from(u16::MAX)) as u16;
        }
        if let Some([a, b]) = inputs.phase_ma {
            self.status.current_ma = a.unsigned_abs().max(b.unsigned_abs()).min(u32::from(u16::MAX)) as u16;
        }
        if core::mem::take(&mut self.clear_history) {
            self.faults.clear_history();
        }
        let (error, faults) = self.detect(s, now, inputs);
        self.latch(now, error, faults);
        self.power_loss(s, inputs);
        self.watchdog(s, now);
        if self.faulted() || self.faults.freed {
            // The power stage is off: the setpoint stops where it is, and a run or set-point
            // accepted before the fault does not start.
            self.stop_motion();
        }
    }

    /// Latches the fault bits `error` (0x6000) and `faults` (0x2135), with a history entry for
    /// each bit that was not latched yet.
    pub(crate) fn latch(&mut self, now: Instant, error: u8, faults: u8) {
        let (new_error, new_faults) = (error & !self.status.error, faults & !self.status.faults);
        if new_error | new_faults == 0 {
            return;
        }
        for &(bit, code) in ERROR_ALARMS.iter() {
            if new_error & bit != 0 {
                self.faults.record(code, now);
            }
        }
        for &(bit, code) in FAULT_ALARMS.iter() {
            if new_faults & bit != 0 {
                self.faults.record(code, now);
            }
        }
        self.status.error |= error;
        self.status.faults |= faults;
    }

    /// The fault bits the measurements show at `now` (0x6000, 0x2135), the detections the
    /// mask 0x21F8 leaves out taken off.
    fn detect(&mut self, s: &Settings, now: Instant, inputs: &Inputs) -> (u8, u8) {
        let on = |bit: u16| s.detect & bit != 0;
        let (mut error, mut faults) = (0u8, 0u8);
        if let Some(mv) = inputs.supply_mv {
            if mv < s.under_voltage_mv && on(detect::UNDER_VOLTAGE) {
                error |= ERR_UNDER_VOLTAGE;
            }
            if mv > s.over_voltage_mv && on(detect::OVER_VOLTAGE) {
                faults |= FAULT_OVER_VOLTAGE;
            }
        }
        if let Some(t) = inputs.temperature_c
            && i64::from(t) > i64::from(s.over_temperature_c)
        {
            error |= ERR_OVER_TEMPERATURE;
        }
        if self.servo.feedback.encoder().is_some() && inputs.encoder.is_none() {
            faults |= FAULT_ENCODER;
        }
        // The speed 0x607F reads (the encoder's in closed loop, the command's in open loop).
        let [open, closed] = s.overspeed;
        let (limit, speed) = match self.servo.feedback {
            crate::servo::Feedback::Closed(_) => (closed, self.servo.speed),
            crate::servo::Feedback::Open => (open, self.axis.setpoint().velocity),
        };
        if limit > 0.0 && libm::fabsf(speed) > limit && on(detect::OVERSPEED) {
            faults |= FAULT_OVERSPEED;
        }
        if s.store_failed && on(detect::STORE) {
            faults |= FAULT_STORE;
        }
        if inputs.sensing_fault && on(detect::SENSING) {
            faults |= FAULT_SENSING;
        }
        if on(detect::PHASE_LOSS) {
            let [open_a, open_b] = inputs.coil_open;
            error |= if open_a { ERR_COIL_A_OPEN } else { 0 } | if open_b { ERR_COIL_B_OPEN } else { 0 };
        }
        match inputs.phase_ma {
            Some([a, b]) => {
                if on(detect::OVER_CURRENT) || inputs.tripped {
                    let limit = i64::from(s.over_current_ma);
                    let over = |i: i32| i64::from(i).abs() > limit;
                    error |=
                        if over(a) { ERR_A_OVER_CURRENT } else { 0 } | if over(b) { ERR_B_OVER_CURRENT } else { 0 };
                }
                // Overload: either phase above 1.5 times the setting, continuously. With a
                // setting of 0 there is no current to compare with (over-current still applies).
                let load = i64::from(s.phase_current_ma) * 3 / 2;
                if load > 0 && i64::from(a).abs().max(i64::from(b).abs()) > load {
                    let since = *self.faults.overload_since.get_or_insert(now);
                    if now.since(since) >= OVERLOAD_MICROS {
                        faults |= FAULT_OVERLOAD;
                    }
                } else {
                    self.faults.overload_since = None;
                }
            }
            None => self.faults.overload_since = None,
        }
        // The hardware trip is an over-current whatever the currents read now.
        if inputs.tripped && error & (ERR_A_OVER_CURRENT | ERR_B_OVER_CURRENT) == 0 {
            error |= ERR_A_OVER_CURRENT | ERR_B_OVER_CURRENT;
        }
        (error, faults)
    }

    /// A valid frame addressed to this drive (or broadcast) arrived: the communication
    /// watchdog starts again at the next tick (a flag: the request path only sets it).
    #[inline(always)]
    pub(crate) fn heard(&mut self) {
        self.heard = true;
    }

    /// The communication watchdog (0x2137): when it runs out, the status bit and a stop.
    fn watchdog(&mut self, s: &Settings, now: Instant) {
        let limit = s.comm_timeout_us;
        if core::mem::take(&mut self.heard) {
            self.faults.last_frame = Some(now);
        }
        // Before the first frame the watchdog counts from the first tick: the clock need not
        // start at 0 when the drive powers up.
        let since = now.since(*self.faults.last_frame.get_or_insert(now));
        if limit != 0 && since >= limit && self.status.comm & COMM_TIMEOUT == 0 {
            self.status.comm |= COMM_TIMEOUT;
            self.faults.record(crate::faults::alarm::COMM_TIMEOUT, now);
            self.decelerate_to_stop(s);
        }
    }

    /// Power-loss behaviour (0x6082..0x6084): the motor freed, the brake applied, and the event
    /// for the power-down position save.
    fn power_loss(&mut self, s: &Settings, inputs: &Inputs) {
        let Some(mv) = inputs.supply_mv else {
            (self.faults.freed, self.faults.braked) = (false, false);
            return;
        };
        self.faults.freed = mv < s.free_below_mv;
        self.faults.braked = mv < s.brake_below_mv;
        let failing = mv < s.free_below_mv.max(s.brake_below_mv).max(s.under_voltage_mv);
        if failing && !self.faults.power_failing {
            self.raise(super::Events::POWER_FAILING);
        }
        self.faults.power_failing = failing;
    }

    /// History entry `k` (0 newest) of the fault history.
    pub(crate) fn history(&self, k: usize) -> u32 {
        self.faults.entry(k)
    }
}
