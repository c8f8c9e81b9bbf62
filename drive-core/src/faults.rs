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
//!   the under-voltage threshold, the drive asks for the power-down position save once (the position save of
//!   0x605E); it is armed again once the supply is back above that level.
//! - The coil output 0x6038 is by default the release duty of a spring-applied brake: while the
//!   power stage is on, `Outputs::coil_duty` is 0x6038 (released); off (disabled, faulted) or in
//!   power loss below 0x6084 it is 0 (applied). As a general output (0x2141 = 1) it is the duty
//!   written, cut only while a fault is latched.

use crate::units::Instant;

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
/// 0x2135 bit 4: overspeed, the motor's speed beyond the overspeed limit (0x21F6).
pub const FAULT_OVERSPEED: u8 = 1 << 4;
/// 0x2135 bit 5: the parameter store failed (0x2120 bit 1 corrupt at power-up, or bit 4 a save
/// that failed).
pub const FAULT_STORE: u8 = 1 << 5;
/// 0x2135 bit 6: the current sensing failed its check at power-up (`Inputs::sensing_fault`).
pub const FAULT_SENSING: u8 = 1 << 6;

/// The fault detection mask's bits (0x21F8; seed 003's 0x201B): a detection whose bit is clear
/// latches nothing. The over-temperature, the overload, the encoder lost and the hardware
/// over-current trip have no bit (they protect the drive and the motor); the position error and
/// the communication timeout have their own switches (0x21D7, 0x2137 = 0).
pub mod detect {
    /// The over-current by the measured currents (0x2133; the hardware trip latches it all the
    /// same).
    pub const OVER_CURRENT: u16 = 1 << 0;
    /// The over-voltage (0x2131).
    pub const OVER_VOLTAGE: u16 = 1 << 1;
    /// The parameter store's failure (the manual's EEPROM).
    pub const STORE: u16 = 1 << 2;
    /// The overspeed (0x21F6; the manual's command overspeed).
    pub const OVERSPEED: u16 = 1 << 3;
    /// The under-voltage (0x2130).
    pub const UNDER_VOLTAGE: u16 = 1 << 6;
    /// The phase loss (an open winding).
    pub const PHASE_LOSS: u16 = 1 << 7;
    /// The current sensing's check (the manual's op-amp fault).
    pub const SENSING: u16 = 1 << 11;
    /// Every bit with a detection behind it.
    pub const ALL: u16 = OVER_CURRENT | OVER_VOLTAGE | STORE | OVERSPEED | UNDER_VOLTAGE | PHASE_LOSS | SENSING;
}

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
    /// The communication timeout 0x2137 ran out (our code: seed 004's communication error).
    pub const COMM_TIMEOUT: u8 = 30;
    /// Overspeed: the motor's speed beyond the overspeed limit 0x21F6 (our code).
    pub const OVERSPEED: u8 = 31;
    /// The parameter store failed (our code; seed 003's EEPROM detection).
    pub const STORE: u8 = 32;
    /// The current sensing failed its check (our code; seed 003's op-amp fault).
    pub const SENSING: u8 = 33;
}

/// The 0x6000 bits with their alarm codes, most severe first.
pub(crate) const ERROR_ALARMS: [(u8, u8); 6] = [
    (ERR_A_OVER_CURRENT, alarm::OVER_CURRENT),
    (ERR_B_OVER_CURRENT, alarm::OVER_CURRENT),
    (ERR_COIL_A_OPEN, alarm::PHASE_LOSS),
    (ERR_COIL_B_OPEN, alarm::PHASE_LOSS),
    (ERR_UNDER_VOLTAGE, alarm::UNDER_VOLTAGE),
    (ERR_OVER_TEMPERATURE, alarm::OVER_TEMPERATURE),
];
/// The 0x2135 bits with their alarm codes, most severe first.
pub(crate) const FAULT_ALARMS: [(u8, u8); 7] = [
    (FAULT_SENSING, alarm::SENSING),
    (FAULT_OVER_VOLTAGE, alarm::OVER_VOLTAGE),
    (FAULT_ENCODER, alarm::ENCODER),
    (FAULT_OVERSPEED, alarm::OVERSPEED),
    (FAULT_POSITION, alarm::POSITION_ERROR),
    (FAULT_OVERLOAD, alarm::OVERLOAD),
    (FAULT_STORE, alarm::STORE),
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
    /// The windings' back-EMF as the power stage's own current loop estimates it, mV (the
    /// G474's bridges: [`crate::windings::WindingState::back_emf_mv`]), filtered in the frame
    /// that turns with the current. The sensorless stall detection takes it where there is one,
    /// instead of working the back-EMF out from `phase_mv` and `phase_ma` tick by tick (whose
    /// L·di/dt turns the currents' sampling noise into volts).
    pub back_emf_mv: Option<[i32; 2]>,
    /// The encoder's raw reading, read by the closed loop (our object 0x2104 says which encoder):
    /// an incremental encoder's quadrature counter in ×4 counts, wrapping at 2^32 (a platform with
    /// a 16-bit counter extends it); an absolute single-turn encoder's 12-bit angle; a multi-turn
    /// one's turns × 4096 + angle, wrapping at 2^32. `None` in closed loop: the encoder is lost
    /// (line break, no answer).
    pub encoder: Option<u32>,
    /// The pins' levels, 1 high, bits as 0x6031 (`controller::io` numbers them).
    pub levels: u16,
    /// The analog input, 12-bit ADC code (0x605F), if the platform has one.
    pub analog: Option<u16>,
    /// The encoder's index pulse came since the last tick.
    pub index: bool,
    /// The pulse input's counter (work mode 3), wrapping at 2^16: counted up and down in the
    /// format the controller's outputs ask for.
    pub pulses: u16,
    /// The power stage's over-current trip in hardware holds its bridges off (the G474's
    /// comparators into the timers' break): the over-current (alarm 10) latches whatever the
    /// fault mask 0x21F8 says.
    pub tripped: bool,
    /// The current sensing failed its check at power-up (the op-amps' outputs at zero current
    /// far from mid-scale): the sensing fault (alarm 33) while 0x21F8 bit 11 is set.
    pub sensing_fault: bool,
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
    pub(crate) overload_since: Option<Instant>,
    /// The supply is below the power-fail level: the power-down save was asked for.
    pub(crate) power_failing: bool,
    /// Power loss with 0x6082 bit 0: the motor is freed.
    pub(crate) freed: bool,
    /// Power loss with 0x6082 bit 1: the brake is applied.
    pub(crate) braked: bool,
    /// The last valid frame addressed to this drive or broadcast (none: power-up, time 0).
    pub(crate) last_frame: Option<Instant>,
}

impl FaultLog {
    pub(crate) fn record(&mut self, code: u8, now: Instant) {
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

    /// Empties the history (the count goes on: a master that polls it still sees new alarms).
    /// The entries past `len` are never read: only the length goes.
    pub(crate) fn clear_history(&mut self) {
        (self.head, self.len) = (0, 0);
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

/// The fault history as the flash keeps it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FaultHistory {
    /// 0x213C..0x214F: code << 24 | time stamp, newest first; 0 where there is no entry.
    pub entries: [u32; HISTORY_LEN],
    /// 0x2136: alarms raised, wrapping.
    pub count: u16,
}

/// The most severe alarm code among latched `bits` of `table`, if any.
pub(crate) fn code_of(table: &[(u8, u8)], bits: u8) -> Option<u8> {
    table.iter().find(|(bit, _)| bits & bit != 0).map(|&(_, code)| code)
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
