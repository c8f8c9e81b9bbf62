//! Faults and protections: what the drive measures ([`Inputs`]) checked at every control tick
//! against its thresholds, the latched safe state a fault leaves it in, the brake, power-loss
//! behaviour and the fault history.
//!
//! - A fault latches a bit (0x6000 or 0x2135) and, on the bit's rising edge, an entry of the fault
//!   history (0x213C..0x214F) with seed 002's alarm code. While any bit is latched the power stage
//!   is off (`Outputs::enabled` false, current 0), the brake is applied, the axis and any PVT run
//!   are stopped and moves are refused (04). Writing 1 clears a bit; a condition still present
//!   latches it again at the next tick, with a new history entry.
//! - Power loss (0x6082..0x6084) is not a fault: below 0x6083 (with 0x6082 bit 0) the motor is
//!   freed and the axis stopped, below 0x6084 (with bit 1) the brake is applied, for as long as
//!   the supply stays below. When the supply first falls below the highest of these levels and
//!   the under-voltage threshold, [`DriveState::power_lost`] is called once (the position save of
//!   0x605E); it is armed again once the supply is back above that level.
//! - The brake 0x6038 is the release duty of a spring-applied brake: while the power stage is on,
//!   `Outputs::brake_duty` is 0x6038 (released); off (disabled, faulted) or in power loss below
//!   0x6084 it is 0 (applied). With 0x6038 = 0 the duty is always 0: no brake fitted.

use crate::drive::DriveState;
use crate::modes::PowerState;
use crate::motion::cubic::Table;
use crate::od::Obj;
use crate::units::Instant;
use core::borrow::BorrowMut;

/// 0x6000 bit 0: driver over-temperature.
pub const ERR_OVER_TEMPERATURE: u8 = 1 << 0;
/// 0x6000 bit 1: coil A open.
pub const ERR_COIL_A_OPEN: u8 = 1 << 1;
/// 0x6000 bit 2: coil B open.
pub const ERR_COIL_B_OPEN: u8 = 1 << 2;
/// 0x6000 bit 3: phase A over-current.
pub const ERR_A_OVER_CURRENT: u8 = 1 << 3;
/// 0x6000 bit 4: phase B over-current.
pub const ERR_B_OVER_CURRENT: u8 = 1 << 4;
/// 0x6000 bit 5: supply under-voltage.
pub const ERR_UNDER_VOLTAGE: u8 = 1 << 5;
/// 0x2135 bit 0: supply over-voltage.
pub const FAULT_OVER_VOLTAGE: u8 = 1 << 0;
/// 0x2135 bit 1: overload, a phase current above 1.5 times 0x600D for 2 s.
pub const FAULT_OVERLOAD: u8 = 1 << 1;
/// 0x2135 bit 2: position error, closed loop: a following error beyond 0x605C.
pub const FAULT_POSITION: u8 = 1 << 2;
/// 0x2135 bit 3: the encoder is lost (closed loop, no reading).
pub const FAULT_ENCODER: u8 = 1 << 3;

/// 0x2138 bit 0: the communication timeout 0x2137 ran out.
pub const COMM_TIMEOUT: u8 = 1 << 0;

/// Seed 002's alarm codes.
pub mod alarm {
    /// Motor phase over-current.
    pub const OVER_CURRENT: u8 = 10;
    /// Phase loss: a coil open (not connected).
    pub const PHASE_LOSS: u8 = 11;
    /// Supply under-voltage.
    pub const UNDER_VOLTAGE: u8 = 13;
    /// Supply over-voltage.
    pub const OVER_VOLTAGE: u8 = 14;
    /// Driver over-temperature (our code: seed 002 files it under "other").
    pub const OVER_TEMPERATURE: u8 = 15;
    /// Position error: the following error beyond its limit.
    pub const POSITION_ERROR: u8 = 25;
    /// Overload: current above 1.5 times the setting for over 2 s.
    pub const OVERLOAD: u8 = 26;
    /// Encoder lost (our code: seed 002 files it under "other").
    pub const ENCODER: u8 = 27;
}

/// The 0x6000 bits with their alarm codes, most severe first.
const ERROR_ALARMS: [(u8, u8); 6] = [
    (ERR_A_OVER_CURRENT, alarm::OVER_CURRENT),
    (ERR_B_OVER_CURRENT, alarm::OVER_CURRENT),
    (ERR_COIL_A_OPEN, alarm::PHASE_LOSS),
    (ERR_COIL_B_OPEN, alarm::PHASE_LOSS),
    (ERR_UNDER_VOLTAGE, alarm::UNDER_VOLTAGE),
    (ERR_OVER_TEMPERATURE, alarm::OVER_TEMPERATURE),
];
/// The 0x2135 bits with their alarm codes, most severe first.
const FAULT_ALARMS: [(u8, u8); 4] = [
    (FAULT_OVER_VOLTAGE, alarm::OVER_VOLTAGE),
    (FAULT_ENCODER, alarm::ENCODER),
    (FAULT_POSITION, alarm::POSITION_ERROR),
    (FAULT_OVERLOAD, alarm::OVERLOAD),
];

/// Entries in the fault history.
pub const HISTORY_LEN: usize = 10;
/// How long a phase current may stay above 1.5 times the setting before it is an overload, µs.
pub const OVERLOAD_MICROS: u64 = 2_000_000;

/// What the drive measures, given to each control tick. `None`: the platform does not measure it,
/// and nothing is checked against it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Inputs {
    /// Supply (bus) voltage, mV.
    pub supply_mv: Option<u32>,
    /// Driver (power stage) temperature, °C.
    pub temperature_c: Option<i16>,
    /// Measured phase currents A and B, mA (signed).
    pub phase_ma: Option<[i32; 2]>,
    /// The power stage's open-load flags for coils A and B.
    pub coil_open: [bool; 2],
    /// The bridge voltages applied to phases A and B, averaged over the tick that just ended, mV
    /// (signed; PWM duty times the supply). With `phase_ma` they feed the sensorless stall
    /// detection: the back-EMF is what the winding's resistance and inductance do not explain.
    pub phase_mv: Option<[i32; 2]>,
    /// The encoder's raw reading, read by the closed loop (our object 0x2104 says which encoder):
    /// an incremental encoder's quadrature counter in ×4 counts, wrapping at 2^32 (a platform with
    /// a 16-bit counter extends it); an absolute single-turn encoder's 12-bit angle; a multi-turn
    /// one's turns × 4096 + angle, wrapping at 2^32. `None` in closed loop: the encoder is lost
    /// (line break, no answer).
    pub encoder: Option<u32>,
}

/// The fault history and the supervision's memory between ticks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct FaultLog {
    /// Ring of entries (code << 24 | time in 100 ms); `head` is where the next one goes.
    entries: [u32; HISTORY_LEN],
    head: u8,
    len: u8,
    /// Alarms raised since power-up (0x2136), wrapping.
    pub(crate) count: u16,
    /// Since when a phase current has been above 1.5 times the setting.
    overload_since: Option<Instant>,
    /// The supply is below the power-fail level: [`DriveState::power_lost`] has been called.
    power_failing: bool,
    /// Power loss with 0x6082 bit 0: the motor is freed.
    pub(crate) freed: bool,
    /// Power loss with 0x6082 bit 1: the brake is applied.
    pub(crate) braked: bool,
    /// The last valid frame addressed to this drive or broadcast (none: power-up, time 0).
    last_frame: Option<Instant>,
}

impl FaultLog {
    fn record(&mut self, code: u8, now: Instant) {
        let stamp = (now.as_micros() / 100_000) as u32 & 0x00FF_FFFF;
        if let Some(e) = self.entries.get_mut(usize::from(self.head)) {
            *e = u32::from(code) << 24 | stamp;
        }
        self.head = (self.head + 1) % HISTORY_LEN as u8;
        self.len = (self.len + 1).min(HISTORY_LEN as u8);
        self.count = self.count.wrapping_add(1);
    }

    /// The log of a history loaded at power-up: its entries (up to the first empty one) and count.
    pub(crate) fn restored(history: &FaultHistory) -> Self {
        let len = history.entries.iter().take_while(|&&e| e != 0).count();
        let mut log = Self { count: history.count, ..Self::default() };
        // The ring holds the oldest first.
        let newest_first = history.entries.get(..len).unwrap_or_default();
        for (slot, &e) in log.entries.iter_mut().zip(newest_first.iter().rev()) {
            *slot = e;
        }
        log.len = len as u8;
        log.head = (len % HISTORY_LEN) as u8;
        log
    }

    /// History entry `k`, 0 the newest; 0 where there is none.
    pub(crate) fn entry(&self, k: usize) -> u32 {
        if k >= usize::from(self.len) {
            return 0;
        }
        let at = (usize::from(self.head) + HISTORY_LEN - 1 - k) % HISTORY_LEN;
        self.entries.get(at).copied().unwrap_or(0)
    }
}

/// The fault history objects, newest entry first.
pub(crate) const HISTORY_OBJECTS: [Obj; HISTORY_LEN] = [
    Obj::FaultHistory0,
    Obj::FaultHistory1,
    Obj::FaultHistory2,
    Obj::FaultHistory3,
    Obj::FaultHistory4,
    Obj::FaultHistory5,
    Obj::FaultHistory6,
    Obj::FaultHistory7,
    Obj::FaultHistory8,
    Obj::FaultHistory9,
];

/// The fault history as the flash keeps it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FaultHistory {
    /// 0x213C..0x214F: code << 24 | time stamp, newest first; 0 where there is no entry.
    pub entries: [u32; HISTORY_LEN],
    /// 0x2136: alarms raised, wrapping.
    pub count: u16,
}

impl FaultHistory {
    /// The history `state` shows now.
    pub fn of<P: BorrowMut<Table>>(state: &DriveState<P>) -> Self {
        let mut history = Self { count: state.read(Obj::AlarmCount) as u16, ..Self::default() };
        for (e, obj) in history.entries.iter_mut().zip(HISTORY_OBJECTS) {
            *e = state.read(obj);
        }
        history
    }
}

/// The most severe alarm code among latched `bits` of `table`, if any.
fn code_of(table: &[(u8, u8)], bits: u8) -> Option<u8> {
    table.iter().find(|(bit, _)| bits & bit != 0).map(|&(_, code)| code)
}

impl<P: BorrowMut<Table>> DriveState<P> {
    /// Whether a fault is latched (0x6000 or 0x2135): the power stage stays off.
    pub fn faulted(&self) -> bool {
        self.status.error != 0 || self.status.faults != 0
    }

    /// The alarm code 0x2134 shows: the most severe latched alarm, 0 for none.
    pub(crate) fn alarm_code(&self) -> u8 {
        code_of(&ERROR_ALARMS, self.status.error).or_else(|| code_of(&FAULT_ALARMS, self.status.faults)).unwrap_or(0)
    }

    /// Checks the measurements at `now`: latches faults, records them, and applies the fault and
    /// power-loss reactions to the motion.
    pub(crate) fn supervise(&mut self, now: Instant, inputs: &Inputs) {
        let (error, faults) = self.detect(now, inputs);
        self.latch(now, error, faults);
        self.power_loss(inputs);
        self.watchdog(now);
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

    /// The fault bits the measurements show at `now` (0x6000, 0x2135).
    fn detect(&mut self, now: Instant, inputs: &Inputs) -> (u8, u8) {
        let (mut error, mut faults) = (0u8, 0u8);
        if let Some(mv) = inputs.supply_mv {
            if mv < self.param(Obj::UnderVoltage) {
                error |= ERR_UNDER_VOLTAGE;
            }
            if mv > self.param(Obj::OverVoltage) {
                faults |= FAULT_OVER_VOLTAGE;
            }
        }
        if let Some(t) = inputs.temperature_c
            && i64::from(t) > i64::from(self.param(Obj::OverTemperature))
        {
            error |= ERR_OVER_TEMPERATURE;
        }
        if self.servo.feedback.encoder().is_some() && inputs.encoder.is_none() {
            faults |= FAULT_ENCODER;
        }
        let [open_a, open_b] = inputs.coil_open;
        error |= if open_a { ERR_COIL_A_OPEN } else { 0 } | if open_b { ERR_COIL_B_OPEN } else { 0 };
        match inputs.phase_ma {
            Some([a, b]) => {
                let limit = i64::from(self.param(Obj::OverCurrent));
                let over = |i: i32| i64::from(i).abs() > limit;
                error |= if over(a) { ERR_A_OVER_CURRENT } else { 0 } | if over(b) { ERR_B_OVER_CURRENT } else { 0 };
                // Overload: either phase above 1.5 times the setting, continuously. With a
                // setting of 0 there is no current to compare with (over-current still applies).
                let load = i64::from(self.param(Obj::PhaseCurrent)) * 3 / 2;
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
        (error, faults)
    }

    /// A valid frame addressed to this drive (or broadcast) arrived: the communication watchdog
    /// starts again.
    pub(crate) fn heard(&mut self) {
        self.faults.last_frame = Some(self.now);
    }

    /// The communication watchdog (0x2137): when it runs out, the status bit and a stop.
    fn watchdog(&mut self, now: Instant) {
        let limit = u64::from(self.param(Obj::CommTimeout)) * 100_000;
        // Before the first frame the watchdog counts from the first tick: the clock need not
        // start at 0 when the drive powers up.
        let since = now.since(*self.faults.last_frame.get_or_insert(now));
        if limit != 0 && since >= limit && self.status.comm & COMM_TIMEOUT == 0 {
            self.status.comm |= COMM_TIMEOUT;
            self.decelerate_to_stop();
        }
    }

    /// Power-loss behaviour (0x6082..0x6084) and the power-down position save.
    fn power_loss(&mut self, inputs: &Inputs) {
        let Some(mv) = inputs.supply_mv else {
            (self.faults.freed, self.faults.braked) = (false, false);
            return;
        };
        let control = self.param(Obj::PowerLossControl);
        let free_at = if control & 1 != 0 { self.param(Obj::PowerLossFreeVoltage) } else { 0 };
        let brake_at = if control & 2 != 0 { self.param(Obj::PowerLossBrakeVoltage) } else { 0 };
        self.faults.freed = mv < free_at;
        self.faults.braked = mv < brake_at;
        let failing = mv < free_at.max(brake_at).max(self.param(Obj::UnderVoltage));
        if failing && !self.faults.power_failing {
            self.power_lost();
        }
        self.faults.power_failing = failing;
    }

    /// What the power stage does: a fault first, then the master's enable, then power loss.
    pub fn power_state(&self) -> PowerState {
        if self.faulted() {
            PowerState::Faulted
        } else if self.param(Obj::Enable) != 1 {
            PowerState::Disabled
        } else if self.faults.freed {
            PowerState::Freed
        } else {
            PowerState::On
        }
    }

    /// Whether the power stage drives the motor.
    pub(crate) fn power_stage_on(&self) -> bool {
        self.power_state() == PowerState::On
    }

    /// The brake's release duty (0x6038) while the power stage is on and power loss does not
    /// apply it; else 0, applied.
    pub(crate) fn brake_duty(&self) -> u8 {
        if self.power_stage_on() && !self.faults.braked { self.param(Obj::Brake) as u8 } else { 0 }
    }

    /// History entry `k` (0 newest) of the fault history.
    pub(crate) fn history(&self, k: usize) -> u32 {
        self.faults.entry(k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_history_keeps_the_last_ten_newest_first() {
        let mut log = FaultLog::default();
        assert_eq!(log.entry(0), 0);
        for k in 0..12u64 {
            log.record(10 + k as u8, Instant::from_micros(k * 100_000));
        }
        assert_eq!(log.count, 12);
        assert_eq!(log.entry(0), 21 << 24 | 11);
        assert_eq!(log.entry(9), 12 << 24 | 2);
        assert_eq!(log.entry(10), 0);
    }

    #[test]
    fn time_stamps_wrap_after_24_bits() {
        let mut log = FaultLog::default();
        log.record(13, Instant::from_micros((1 << 24) * 100_000 + 250_000));
        assert_eq!(log.entry(0), 13 << 24 | 2);
    }
}
