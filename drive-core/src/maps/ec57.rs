//! The EC-57 map (seed 003): registers addressed by an index and a sub-index byte (`01 03 20 00
//! 00 00 01` reads 0x2000 sub-index 0), walked in (index, sub-index) order, at most 16 a request,
//! with the manual's own exception codes; the drive's native registers in a window (sub-index
//! 0xFF), since the EC-57's motion comes over a fieldbus this drive does not have.
//!
//! ```
//! use drive_core::maps::Maps;
//! use drive_core::od::Obj;
//! use drive_core::{Drive, DriveConfig, Instant};
//! let mut drive = Drive::with_map(DriveConfig::default(), Maps::ec57());
//! // §1.3.2: 0x2005 (pulses a revolution) = 10 000: 50 microsteps a full step.
//! drive.on_rx(Instant::from_micros(0), &[0x01, 0x06, 0x20, 0x05, 0x00, 0x27, 0x10, 0x90, 0x91]);
//! drive.on_timer(Instant::from_micros(4_011));
//! assert_eq!(drive.take_reply(), Some(&[0x01, 0x06, 0x20, 0x05, 0x00, 0x27, 0x10, 0x90, 0x91][..]));
//! assert_eq!(drive.state().read(Obj::Microsteps), 50);
//! ```

use super::compiled::Compiled;
use super::layout::{Choice, Entry, Exceptions, Layout, Scale, SpoiltCodes, Walk, WordOrder, ZERO_ONE};
use crate::od::Obj;
use crate::pdu::{Exception, Keys, Request, SubIndex, Words};

/// The requests' index and sub-index (§1.3): the table's 0x2000-0x20FF with sub-indices 0-15
/// are keys below the window; from 0x1000 on, sub-index 0xFF names the drive's native register
/// at the index (the window). At most 16 registers a request.
pub const KEYS: Keys =
    Keys { base: 0x2000, indexes: 0x100, bits: 4, window: 0x1000, window_sub: WINDOW_SUB, max: MAX_REGISTERS };
/// The most registers a request reads or writes (§1.3.1).
pub const MAX_REGISTERS: u16 = 16;
/// The sub-index that addresses the drive's native register at the index (the window).
pub const WINDOW_SUB: u8 = 0xFF;
/// The answer to a frame whose CRC is wrong, while 0x21D2 asks for one (§1.3.4's example).
const CRC_ERROR: u8 = 0x01;

/// Exception 02: a function other than 03, 06 and 16 (and 0x08, 0x15 and 0x2B).
const FUNCTION: Exception = Exception::Vendor(2);
/// Exception 03: an index and sub-index outside the table.
const ADDRESS: Exception = Exception::Vendor(3);
/// Exception 04: more than 16 registers (or none).
const COUNT: Exception = Exception::Vendor(4);
/// Exception 05: a read of a write-only register, a write of a read-only one.
const ACCESS: Exception = Exception::Vendor(5);
/// Exception 06: a value out of range, or one the drive cannot take now.
const VALUE: Exception = Exception::Vendor(6);

/// The key of the table's (index, sub-index) ([`KEYS`]).
pub const fn key(index: u16, sub: u8) -> u16 {
    KEYS.key(index, sub)
}

/// The (index, sub-index) of a table key.
pub const fn index_of(key: u16) -> (u16, u8) {
    KEYS.index_of(key)
}

/// Decodes an EC-57 request PDU: 03, 06 and 16 with the sub-index byte after the index (their
/// register number a table's key, or in the window the native register at the index), the
/// Modbus diagnostics 0x08, the firmware update's write file record 0x15 and identification 0x2B
/// as Modbus has them ([`Request::parse`]); any other function is refused.
///
/// ```
/// use drive_core::maps::ec57::parse;
/// use drive_core::pdu::Request;
/// use drive_core::Exception;
/// assert_eq!(parse(&[0x03, 0x20, 0x03, 0x01, 0x00, 0x02]), Ok(Request::ReadHolding { addr: 0x31, qty: 2 }));
/// assert_eq!(parse(&[0x03, 0x60, 0x0C, 0xFF, 0x00, 0x01]), Ok(Request::ReadHolding { addr: 0x600C, qty: 1 }));
/// assert_eq!(parse(&[0x03, 0x20, 0x00, 0x00, 0x00, 0x20]), Err(Exception::Vendor(4)));
/// assert_eq!(parse(&[0x03, 0x20, 0x31, 0x00, 0x00, 0x01]), Ok(Request::ReadHolding { addr: 0x310, qty: 1 }));
/// assert_eq!(parse(&[0x02, 0x00, 0x00, 0x00, 0x00, 0x04]), Err(Exception::Vendor(2)));
/// assert_eq!(parse(&[0x08, 0x00, 0x00, 0x12, 0x34]), Ok(Request::Diagnostics { sub: 0, data: &[0x12, 0x34] }));
/// ```
#[inline(never)]
pub fn parse(pdu: &[u8]) -> Result<Request<'_>, Exception> {
    let (&function, data) = pdu.split_first().ok_or(FUNCTION)?;
    match function {
        0x03 | 0x06 | 0x10 => {}
        0x08 | 0x15 | 0x2B => return Request::parse(pdu),
        _ => return Err(FUNCTION),
    }
    let (&[ih, il, sub, wh, wl], rest) = data.split_first_chunk::<5>().ok_or(VALUE)?;
    let word = u16::from_be_bytes([wh, wl]);
    if function != 0x06 && !(1..=MAX_REGISTERS).contains(&word) {
        return Err(COUNT);
    }
    let addr = KEYS.register(u16::from_be_bytes([ih, il]), sub).ok_or(ADDRESS)?;
    match (function, rest) {
        (0x03, []) => Ok(Request::ReadHolding { addr, qty: word }),
        (0x06, []) => Ok(Request::WriteSingle { addr, value: word }),
        (0x10, [count, values @ ..])
            if usize::from(*count) == 2 * usize::from(word) && values.len() == 2 * usize::from(word) =>
        {
            Ok(Request::WriteMultiple { addr, values: Words::new(values) })
        }
        _ => Err(VALUE),
    }
}

/// 0x2022.1-5: 1 origin (the homing's home switch, the drive's 11), 2 positive and 4 negative
/// limit (9, 10), 8 quick stop (the motion command 7), 16 custom and 0 none (the drive's 0: the
/// master reads the input in 0x2014), 32 and 64 touch probes 1 and 2 (21, 22).
static INPUT_FUNCTIONS: &[Choice] = &[
    Choice { lo: 0, hi: 0, drive: 0 },
    Choice { lo: 1, hi: 1, drive: 11 },
    Choice { lo: 2, hi: 2, drive: 9 },
    Choice { lo: 4, hi: 4, drive: 10 },
    Choice { lo: 8, hi: 8, drive: 7 },
    Choice { lo: 16, hi: 16, drive: 0 },
    Choice { lo: 32, hi: 32, drive: 21 },
    Choice { lo: 64, hi: 64, drive: 22 },
];

/// 0x2025.1-3: 1 alarm output (the drive's 2), 2 in position (3), 16 master-controlled (1, the
/// general output of 0x21C7), 0 none.
static OUTPUT_FUNCTIONS: &[Choice] = &[
    Choice { lo: 0, hi: 0, drive: 0 },
    Choice { lo: 1, hi: 1, drive: 2 },
    Choice { lo: 2, hi: 2, drive: 3 },
    Choice { lo: 16, hi: 16, drive: 1 },
];

/// 0x2020: 0 in position when the plan has ended, 10 when the drive says (the encoder within the
/// window in closed loop).
static IN_POSITION: &[Choice] = &[Choice { lo: 0, hi: 0, drive: 0 }, Choice { lo: 10, hi: 10, drive: 1 }];

/// 0x201D: 1 clears the fault history (0x200F = 5), 0 does nothing.
static HISTORY_CLEAR: &[Choice] = &[Choice { lo: 0, hi: 0, drive: 0 }, Choice { lo: 1, hi: 1, drive: 5 }];

/// 0x201E: 1 clears the alarms (0x200F = 4), 0 does nothing.
static ALARM_CLEAR: &[Choice] = &[Choice { lo: 0, hi: 0, drive: 0 }, Choice { lo: 1, hi: 1, drive: 4 }];

/// 0x2030: bit 0 saves the parameters (0x200F = 2), bit 1 restores the factory ones and saves
/// them (0x200F = 3), 0 does nothing.
static SAVE: &[Choice] =
    &[Choice { lo: 0, hi: 0, drive: 0 }, Choice { lo: 1, hi: 1, drive: 2 }, Choice { lo: 2, hi: 2, drive: 3 }];

/// Speeds in r/min.
const RPM: Scale = Scale::PerRev(1, 60);
/// The fault list's code: the alarm code in bits 24-31 of a fault history entry.
const FAULT_CODE: Scale = Scale::Field(24, 8);

/// The table (§1.2), by (index, sub-index) as [`key`] makes them.
pub static ENTRIES: [Entry; 60] = [
    Entry::new(key(0x2000, 0), Obj::NodeId, &Scale::One),
    Entry::new(key(0x2001, 0), Obj::AddressSource, &Scale::One),
    Entry::new(key(0x2002, 0), Obj::MotorDirection, &Scale::One),
    Entry::new(key(0x2003, 1), Obj::IdleDelay, &Scale::One),
    Entry::new(key(0x2003, 2), Obj::IdleCurrent, &Scale::One),
    Entry::new(key(0x2004, 0), Obj::PhaseCurrent, &Scale::One),
    Entry::new(key(0x2005, 0), Obj::Microsteps, &Scale::PulsesPerRev),
    Entry::new(key(0x2006, 0), Obj::DisabledHold, &Scale::One),
    Entry::new(key(0x2007, 0), Obj::CurrentAutoTune, &Scale::One),
    Entry::new(key(0x2008, 0), Obj::CurrentKp, &Scale::One),
    Entry::new(key(0x2009, 0), Obj::CurrentKi, &Scale::One),
    Entry::new(key(0x200A, 0), Obj::CurrentKc, &Scale::One),
    Entry::new(key(0x200B, 0), Obj::SoftStartTime, &Scale::One),
    Entry::new(key(0x200C, 0), Obj::SoftStart, &Scale::One),
    Entry::new(key(0x200D, 0), Obj::SupplyVoltage, &Scale::Ratio(1000, 1)),
    Entry::new(key(0x200E, 0), Obj::PositionErrorAlarm, &Scale::One),
    Entry::new(key(0x200F, 0), Obj::PositionErrorAngle, &Scale::One),
    Entry::new(key(0x2010, 0), Obj::CommandCount, &Scale::Field(16, 16)).narrow().read_only(),
    Entry::new(key(0x2011, 0), Obj::CommandCount, &Scale::Field(0, 16)).narrow().clear(),
    Entry::new(key(0x2012, 0), Obj::OverspeedLimit, &Scale::One),
    Entry::new(key(0x2013, 0), Obj::PowerUpJog, &Scale::One),
    Entry::new(key(0x2014, 0), Obj::InputStates, &Scale::One),
    Entry::new(key(0x2015, 0), Obj::CommandFilter, &Scale::One),
    Entry::new(key(0x2016, 0), Obj::CommandFilterTime, &Scale::One),
    Entry::new(key(0x2017, 0), Obj::RealSpeed, &RPM).narrow(),
    Entry::new(key(0x2018, 0), Obj::FollowingError, &Scale::One).narrow(),
    Entry::new(key(0x2019, 0), Obj::Feedback, &Scale::Table(&ZERO_ONE)),
    Entry::new(key(0x201A, 1), Obj::SoftwareRevision, &Scale::One),
    Entry::new(key(0x201A, 2), Obj::HardwareRevision, &Scale::One),
    Entry::new(key(0x201A, 3), Obj::SoftwareRevision, &Scale::One),
    Entry::new(key(0x201B, 0), Obj::FaultMask, &Scale::One),
    Entry::new(key(0x201C, 1), Obj::FaultHistory0, &FAULT_CODE).narrow(),
    Entry::new(key(0x201C, 2), Obj::FaultHistory1, &FAULT_CODE).narrow(),
    Entry::new(key(0x201C, 3), Obj::FaultHistory2, &FAULT_CODE).narrow(),
    Entry::new(key(0x201C, 4), Obj::FaultHistory3, &FAULT_CODE).narrow(),
    Entry::new(key(0x201C, 5), Obj::FaultHistory4, &FAULT_CODE).narrow(),
    Entry::new(key(0x201C, 6), Obj::FaultHistory5, &FAULT_CODE).narrow(),
    Entry::new(key(0x201C, 7), Obj::FaultHistory6, &FAULT_CODE).narrow(),
    Entry::new(key(0x201C, 8), Obj::FaultHistory7, &FAULT_CODE).narrow(),
    Entry::new(key(0x201C, 9), Obj::FaultHistory8, &FAULT_CODE).narrow(),
    Entry::new(key(0x201D, 0), Obj::SystemControl, &Scale::Table(&HISTORY_CLEAR)),
    Entry::new(key(0x201E, 0), Obj::SystemControl, &Scale::Table(&ALARM_CLEAR)),
    Entry::new(key(0x201F, 0), Obj::NotMovingCode, &Scale::One),
    Entry::new(key(0x2020, 0), Obj::InPositionSource, &Scale::Table(&IN_POSITION)),
    Entry::new(key(0x2021, 0), Obj::InputLogic, &Scale::One),
    Entry::new(key(0x2022, 1), Obj::InputFunction1, &Scale::Table(&INPUT_FUNCTIONS)),
    Entry::new(key(0x2022, 2), Obj::InputFunction2, &Scale::Table(&INPUT_FUNCTIONS)),
    Entry::new(key(0x2022, 3), Obj::InputFunction3, &Scale::Table(&INPUT_FUNCTIONS)),
    Entry::new(key(0x2022, 4), Obj::InputFunction4, &Scale::Table(&INPUT_FUNCTIONS)),
    Entry::new(key(0x2022, 5), Obj::InputFunction5, &Scale::Table(&INPUT_FUNCTIONS)),
    Entry::new(key(0x2023, 1), Obj::InputFilter1, &Scale::One),
    Entry::new(key(0x2023, 2), Obj::InputFilter2, &Scale::One),
    Entry::new(key(0x2023, 3), Obj::InputFilter3, &Scale::One),
    Entry::new(key(0x2023, 4), Obj::InputFilter4, &Scale::One),
    Entry::new(key(0x2023, 5), Obj::InputFilter5, &Scale::One),
    Entry::new(key(0x2024, 0), Obj::OutputLogic, &Scale::Invert(0x7)),
    Entry::new(key(0x2025, 1), Obj::OutputFunction1, &Scale::Table(&OUTPUT_FUNCTIONS)),
    Entry::new(key(0x2025, 2), Obj::OutputFunction2, &Scale::Table(&OUTPUT_FUNCTIONS)),
    Entry::new(key(0x2025, 3), Obj::OutputFunction3, &Scale::Table(&OUTPUT_FUNCTIONS)),
    Entry::new(key(0x2030, 0), Obj::SystemControl, &Scale::Table(&SAVE)).write_only(),
];

/// The table's exception codes (§1.3.4, table 1.3): 03 no such register, 05 the wrong access,
/// 06 a value out of range; the drive's refusals for its state (busy, disabled, faulted, not
/// now), which the manual has no code for, are 06 as well: the value cannot be taken.
pub const EXCEPTIONS: Exceptions = Exceptions {
    unknown: ADDRESS,
    read_only: ACCESS,
    out_of_range: VALUE,
    busy: VALUE,
    disabled: VALUE,
    faulted: VALUE,
    not_now: VALUE,
    infeasible: VALUE,
    unsupported: VALUE,
    write_only: ACCESS,
    split: ADDRESS,
    byte_count: VALUE,
    function: FUNCTION,
};

/// How a request walks [`ENTRIES`].
const WALK: Walk = Walk::List;

/// The EC-57 layout: the table, and the native map in the window.
pub static LAYOUT: Layout = Layout {
    entries: &ENTRIES,
    order: WordOrder::HighFirst,
    exceptions: EXCEPTIONS,
    walk: WALK,
    halves: false,
    spoilt: SpoiltCodes { gap: None, early: None, crc: Some(CRC_ERROR) },
    defaults: &DEFAULTS,
    program: None,
    reserved: &[],
    sub_index: Some(&SUB_INDEX),
    // The serial port's address (§1.3): an EC-57's switches address its fieldbus.
    address: Some(1),
    scope: false,
    index: Some(&INDEX),
};

/// The table's compiled lookup.
static INDEX: Compiled = compiled!(ENTRIES, WALK);

/// The requests' index and sub-index (§1.3): [`KEYS`], and the map's own decoder.
static SUB_INDEX: SubIndex = SubIndex { parse, keys: KEYS };

/// The manual's factory values where they differ from the drive's: the standstill current after
/// 50 ms at 50 %, 1 A peak, 10 000 pulses a revolution (the table prints 1000, outside its own
/// range 6400-51200; its example writes 10 000), no position error alarm, in position at the
/// plan's end, IN1 touch probe 1, IN2-IN5 origin, the limits and custom, OUT1 and OUT2 the
/// alarm output, an overspeed limit of 1600 r/min, the fault detection mask 0xC3, IN1-IN5
/// filtered over 1 ms.
static DEFAULTS: [(u16, i32); 20] = [
    (key(0x2003, 1), 50),
    (key(0x2003, 2), 50),
    (key(0x2004, 0), 1000),
    (key(0x2005, 0), 10_000),
    (key(0x2012, 0), 1600),
    (key(0x201B, 0), 0xC3),
    (key(0x200E, 0), 0),
    (key(0x2020, 0), 0),
    (key(0x2022, 1), 32),
    (key(0x2022, 2), 1),
    (key(0x2022, 3), 2),
    (key(0x2022, 4), 4),
    (key(0x2022, 5), 16),
    (key(0x2023, 1), 1000),
    (key(0x2023, 2), 1000),
    (key(0x2023, 3), 1000),
    (key(0x2023, 4), 1000),
    (key(0x2023, 5), 1000),
    (key(0x2025, 1), 1),
    (key(0x2025, 2), 1),
];

/// What the reference says beside the table: the decisions where seed 003 is silent or
/// contradicts itself.
#[cfg(feature = "docs")]
pub static REFERENCE: super::doc::Reference = super::doc::Reference {
    title: "EC-57 map (seed 003)",
    notes: &[
        "Chosen with 0x2190 = 3 (in this map: index 0x2190, sub-index 0xFF), saved, from the next power-up; `hal-sim --map ec57` for one run. Writing 3 to the native map's 0x2190 and saving switches to it; 0x2190 sub-index 0xFF = 0 and a save (0x2030 = 1) switch back.",
        "Requests carry a sub-index byte after the two-byte index (§1.3): `01 03 20 00 00 00 01` reads 0x2000 sub-index 0. Functions 03, 06 and 16; a multi-register request walks the table below in its (index, sub-index) order from the entry it names (0x2003 has sub-indices 1 and 2, no 0), 16 registers at most. Replies are the manual's: 03 returns the byte count and values, 06 echoes the request, 16 echoes index, sub-index and count. The Modbus diagnostics 0x08, identification 0x2B and the firmware update's write file record 0x15 (`updates.md`) are answered too.",
        "Exception codes (§1.3.4, table 1.3): 02 a function other than 03, 06, 16 (and 0x08, 0x15, 0x2B); 03 an index and sub-index outside the table; 04 more than 16 registers, or none; 05 a read of the write-only 0x2030 or a write of a read-only register; 06 a value out of range, a wrong length or byte count, and a value the drive cannot take in its state (writing 0x2005 while the motor moves, say), which the manual has no code for.",
        "A frame whose CRC is wrong is dropped, as §1.3.4's text and the Modbus serial line say; 0x21D2 = 1 (in the window) answers it with exception 01 as the manual's example does (`01 83 01 80 F0`), if it began with this drive's address.",
        "The window: sub-index 0xFF addresses the drive's native register at the index (seed 000's map, `registers.md`): `01 03 60 0C FF 00 01` reads the native 0x600C. The EC-57's motion comes over its fieldbus, which this drive does not have; the window is how a master moves it (0x21A0 motion commands, 0x6005 relative moves, ...), saves (0x200F), and switches maps (0x2190). Its refusals take this map's codes: 02 → 03, 03 and 04 → 06.",
        "0x2000 is the node id and 0x2001 its source, from the next power-up once saved (0x2030 = 1): 0 (the factory value) the serial port's fixed address 1, as the manual says of the EC-57's serial port; 1 the address 0x2000 holds (1-127). A platform that sets the address (the simulator's `--address`, its `--axes`) overrides both.",
        "0x2005 is the resolution as pulses a revolution of a 1.8° motor: any multiple of 200 up to 51 200 (the drive runs any whole number of microsteps a full step up to 256); others are refused (06). Where the manual's range is narrower than the drive's, the drive's applies: 0x2005 takes 200-6200 too, 0x2003.1 1-32 767 ms, and 0x2003.2 10-100 % (0-9 refused: below 10 % a stepper holds nothing).",
        "0x2004 (peak current) is in mA (the drive's 0-6000), 0x200D the supply in volts, 0x2017 the speed in r/min (the encoder's in closed loop, the command's in open loop), 0x2018 the closed loop's following error in encoder counts (0 in open loop; read only, the manual's R/W/S and default 1000 being a misprint for a measurement), 0x2014 the inputs' states (bit 0 IN1).",
        "0x201C.1-9 is the fault list, newest first: each entry the alarm code of the drive's fault history (10 over-current, 11 phase loss, 13 under-voltage, 14 over-voltage, 15 over-temperature, 25 position error, 26 overload, 27 encoder lost, 30 communication timeout); read only (the manual's R/W/S: a history is not written). 0x201D = 1 empties it (saved at once: it stays empty after a power cycle), 0x201E = 1 clears the latched alarms; 0 does nothing for either.",
        "0x2010 and 0x2011 are the high and low words of the position commands received: the microsteps the drive's setpoint has moved since power-up or the last clear, signed (two's complement over the two words) and wrapping; a position preset or a homing's new zero is no motion. Writing 1 to 0x2011 clears it; other values are refused (06), and 0x2010 is read only.",
        "0x2006 = 1 holds the motor where it stands, at the standstill current (0x2003.2 of 0x2004), while the drive is disabled (the native 0x6011 = 0 in the window); a fault or a power loss frees it all the same; 0 frees it.",
        "0x200E and 0x200F are the closed loop's position error alarm (25) and its angle in degrees of the shaft: 0x200E = 1 latches the alarm when the following error goes beyond 0x200F's angle (converted to microsteps at the resolution in force); 0x200F = 0 leaves the drive's own limit (0x21D0 in encoder counts, or 0x605C's 64 microsteps); 0x200E = 0, the manual's factory value, lets the loop follow without the alarm. Open loop has no following error: 0x2019 = 1 (closed loop, from the next power-up) needs the encoder the drive's 0x6054 describes.",
        "0x2013 = 1 (saved) jogs the motor at power-up: 30° forward, then 15° back, at the drive's jog speed (0x21A5, 2 000 microsteps/s from the factory) and its PP ramps (0x6067, 0x6069), then it stands; a motion command, a stop or an alarm before it is done ends it, and a drive that cannot move at power-up does not jog.",
        "0x2020 says when the in-position output is on: 0 (the manual's factory value) once the plan has ended, 10 while the axis stands on its target within the drive's window (0x21C9, encoder counts) in closed loop; in open loop both are the plan's end.",
        "0x2021 bit k inverts IN k+1; 0x2022.1-5 give IN1-IN5 a function: 1 origin (the homing's home switch), 2 positive limit, 4 negative limit (a motion heading into an active limit stops at the stop deceleration, and a command towards it is refused), 8 quick stop (stops at the quick-stop deceleration), 16 custom and 0 none (the master reads it in 0x2014); both read back as 0; 32 and 64 touch probes 1 and 2 (any input may be either; the manual offers probe 2 on IN1 and IN2): at the input's first activation after its status bit was cleared, the control tick captures the position (the encoder's in closed loop, the setpoint's in open loop) into the drive's 0x21DB (probe 1) or 0x21DD (probe 2), with 0x21DF bits 0 and 1 saying a capture is there (write 1 to re-arm): through the window, as the EC-57 has them on its fieldbus. IN1-IN3 are the drive's EXT1-EXT3, IN4 and IN5 GPIO1 and GPIO2.",
        "0x2024 bit k set: OUT k+1 is high when on (the drive's output logic inverted); 0x2025.1-3: 1 alarm output (on while no alarm is latched), 2 in position, 16 master-controlled (the drive's general output, 0x21C7 in the window), 0 none. OUT1-OUT3 are the drive's GPIO5-GPIO7.",
        "0x2030 (write only): 1 saves the parameters, 2 restores the factory ones and saves them (both refused with 06 while the motor moves); 0 does nothing. Saved parameters are kept across power cycles; the drive saves nothing on its own.",
        "0x2007-0x200A are the current loop of the drive's own power stage (the G474's bridges; the simulator's `--power-stage bridges`), read at power-up: 0x2007 = 1 (factory) measures both windings' R and L at power-up (about a second at 0x2004's current, one winding then the other, before the drive answers; the native 0x2108 and 0x2109 read them) and sets the gains from them; 0x2008 (KP, 0.1 V/A: the volts across a winding per ampere of error) and 0x2009 (KI, 0.01 V/A added each PWM period) then read what the tune set and refuse writes (05); with 0x2007 = 0 they are written and run as set, on the R and L of 0x2108 and 0x2109. 0x200A (Kc, ‰, read only) is the share of what the loop's winding model missed that corrects its next prediction, 250. The factory KP 300 and KI 30 are the manual's; a tune replaces them (a NEMA 17 of 1.4 Ω and 3 mH gets 475 and 112). Where the power stage has no current loop (the simulator's chopper, the firmware under QEMU) 0x2007-0x2009 refuse changes (06, the drive's refusal in its state) and read their stored values. A write of the value a register holds is taken in any state (a dump loaded back).",
        "0x2012 is the overspeed limit in r/min of the shaft (0-3000, 1600 from the factory; 0, which the manual leaves open, turns it off), and it is saved with the rest (0x2030 = 1) although the table prints it R/W: a commissioned limit that fell back to 1600 at every power-up would be no limit. A motion whose speed is beyond it is refused (06) and moves nothing, and 0x201F reads 30; 0x201F reads 23 when the work mode or state in force does not take the command (another mode's command, a speed of 0, a PVT run's points missing), and 0 once a motion command is taken. The speed the motor runs at (the encoder's in closed loop; the command's in open loop, where a PVT segment or the pulse input can ask more than a plan would) beyond the limit latches the overspeed alarm (31 in 0x201C's list) while 0x201B bit 3 detects it (the factory 0xC3 does not); a stop or a slow-down is never refused.",
        "0x201B is the fault detection mask: a detection whose bit is clear latches nothing. Bit 0 the over-current by the measured currents (the native 0x2133; the over-current trip in hardware turns the bridges off and latches the alarm whatever the mask says, as a masked trip would otherwise have the bridges switched into the short again each period), 1 the over-voltage, 2 the EEPROM: the parameter store found corrupt at power-up or a save that failed (alarm 32; the native 0x2120 bits 1 and 4), 3 the command overspeed (0x2012, alarm 31), 11 the op-amp fault: the current sensing's zero at power-up more than 256 codes of 4096 from mid-scale (alarm 33). The table leaves 4-10 and 12-15 unnamed; the drive gives 6 the under-voltage and 7 the phase loss (an open winding), which the factory value 0xC3 sets with 0 and 1, so that the manual's factory mask leaves the EEPROM, the command overspeed and the op-amp fault off and the rest on. The other unnamed bits have no detection behind them: a value that sets one is refused (06). The over-temperature, the overload and the encoder lost have no bit: they protect the drive and the motor; the position error has its own switch (0x200E).",
        "0x2023.1-5 are IN1-IN5's filter times in µs (50-60 000, 1000 from the factory; the manual gives no unit: a millisecond is the usual debounce of a switch, 60 ms the longest a contact bounces): a change of the input's level counts once it has held that long, counting the tick it came at (its bounces meanwhile ignored), for its function (0x2022), its state in 0x2014 and a touch probe's capture, which takes the position where the change began; 50, one control tick, takes every change at once. The drive's external stops (the native 0x6042, EXT1-EXT3 = IN1-IN3) are the same debouncer.",
        "0x2015 = 1 smooths the position command by a moving average (the manual's FIR filter) over 0x2016 µs (50-25 600, to the nearest 50 µs control tick, 1000 from the factory; the manual gives no unit, and µs is 0x2023's: the drive's tick is the shortest, 512 ticks the longest it keeps): each corner of the commanded velocity becomes a ramp that long, the motion is delayed by half of it, and a move still ends exactly on its target. Every command passes through it (the window's moves, PVT, pulse following, homing); the busy bit stays set until the motor stands on the target, and a change of either register takes effect once the filter's output stands on its input.",
    ],
    remarks: &[],
    decimal: false,
};
