//! The JMC map (seed 001, JMC iHSS57-R): CiA 402's objects over Modbus, walked in the order of
//! the manual's §8 list, 32-bit registers written whole with 0x10 only, their word order the
//! setting 0x6000, speeds in 0.1 rev/s and accelerations in 0.1 rev/s², the exception codes of
//! §4 (1-11).
//!
//! ```
//! use drive_core::maps::{Maps, jmc};
//! use drive_core::{Drive, DriveConfig, Instant};
//! let mut drive = Drive::with_map(DriveConfig::default(), Maps::jmc());
//! // §7.5: a write to 0x6090, which does not exist, answers exception 0x0B.
//! drive.on_rx(Instant::from_micros(0), &[0x01, 0x06, 0x60, 0x90, 0x00, 0x03, 0xD7, 0xE6]);
//! drive.on_timer(Instant::from_micros(4_011));
//! assert_eq!(drive.take_reply(), Some(&[0x01, 0x86, 0x0B, 0x03, 0xA7][..]));
//! ```

use super::compiled::Compiled;
use super::layout::{Choice, Entry, Exceptions, Layout, Scale, SpoiltCodes, Walk, WordOrder};
use crate::od::Obj;
use crate::pdu::Exception;

/// 0.1 rev/s (or rev/s²) in the drive's microsteps a second (or a second squared).
const TENTH_REV: Scale = Scale::PerRev(1, 10);

/// The modes of 0x6060/0x6061: 1 profile position, 3 profile velocity, 6 homing.
static MODES: &[Choice] =
    &[Choice { lo: 1, hi: 1, drive: 4 }, Choice { lo: 3, hi: 3, drive: 5 }, Choice { lo: 6, hi: 6, drive: 6 }];

/// 0x605A: 1 the deceleration 0x6084, 2 the quick-stop deceleration 0x6085, 3-32767 at once;
/// 0 (the manual's default, which it does not define) as 2.
static QUICK_STOP: &[Choice] = &[
    Choice { lo: 2, hi: 2, drive: 2 },
    Choice { lo: 1, hi: 1, drive: 1 },
    Choice { lo: 3, hi: 32_767, drive: 0xFFFF },
    Choice { lo: 0, hi: 0, drive: 2 },
];

/// 0x6098: §6.3's methods 1-8 are the homing engine's -3 to -10 (left, CW, is the negative
/// direction; the CW limit is the negative limit switch, the CCW limit the positive one).
/// (As 0x2160 holds them: a 16-bit register, -3 is 0xFFFD.) 0, the manual's default, is no
/// search: the present position becomes home (the engine's 35), so that the factory value
/// reads as 0 and writes back.
static HOMING_METHODS: &[Choice] = &[
    Choice { lo: 0, hi: 0, drive: 35 },
    Choice { lo: 1, hi: 1, drive: 0xFFFD },
    Choice { lo: 2, hi: 2, drive: 0xFFFC },
    Choice { lo: 3, hi: 3, drive: 0xFFFB },
    Choice { lo: 4, hi: 4, drive: 0xFFFA },
    Choice { lo: 5, hi: 5, drive: 0xFFF9 },
    Choice { lo: 6, hi: 6, drive: 0xFFF8 },
    Choice { lo: 7, hi: 7, drive: 0xFFF7 },
    Choice { lo: 8, hi: 8, drive: 0xFFF6 },
];

/// The registers, in §8's order, then ours (the map selection and the line's settings, at their
/// native addresses, so that a master can switch back).
pub static ENTRIES: [Entry; 31] = [
    Entry::new(0x1001, Obj::ErrorRegister, &Scale::One),
    Entry::new(0x1008, Obj::DeviceName, &Scale::One),
    Entry::new(0x1009, Obj::HardwareVersion, &Scale::One),
    Entry::new(0x100A, Obj::SoftwareVersion, &Scale::One),
    Entry::new(0x6000, Obj::MapWordOrder, &Scale::One),
    Entry::new(0x605A, Obj::QuickStopOption, &Scale::Table(&QUICK_STOP)),
    Entry::new(0x6040, Obj::DeviceControl, &Scale::One).write_only(),
    Entry::new(0x6060, Obj::Mode, &Scale::Table(&MODES)).write_only(),
    Entry::new(0x6081, Obj::PpRunSpeed, &TENTH_REV),
    Entry::new(0x6083, Obj::PpAccel, &TENTH_REV).narrow(),
    Entry::new(0x6084, Obj::PpDecel, &TENTH_REV).narrow(),
    Entry::new(0x6085, Obj::QuickStopDecel, &TENTH_REV).narrow(),
    Entry::new(0x607A, Obj::PpTarget, &Scale::One),
    Entry::new(0x607C, Obj::HomingOffset, &Scale::Ratio(-1, 1)),
    Entry::new(0x6098, Obj::HomingMethod, &Scale::Table(&HOMING_METHODS)),
    Entry::new(0x6099, Obj::HomingSearchSpeed, &TENTH_REV),
    Entry::new(0x609A, Obj::HomingAccel, &TENTH_REV).narrow(),
    Entry::new(0x609B, Obj::HomingZeroSpeed, &TENTH_REV),
    Entry::new(0x6041, Obj::DeviceStatus, &Scale::One),
    Entry::new(0x6061, Obj::Mode, &Scale::Table(&MODES)).read_only(),
    Entry::new(0x6064, Obj::Position, &Scale::One).read_only(),
    Entry::new(0x606C, Obj::RealSpeed, &TENTH_REV),
    Entry::new(0x200F, Obj::SystemControl, &Scale::One),
    Entry::new(0x2028, Obj::NodeId, &Scale::One),
    Entry::new(0x202A, Obj::BaudRate, &Scale::One),
    Entry::new(0x2100, Obj::Parity, &Scale::One),
    Entry::new(0x2165, Obj::HomingCreepSpeed, &TENTH_REV),
    Entry::new(0x216B, Obj::HomingTimeout, &Scale::One),
    Entry::new(0x216C, Obj::HomingInputs, &Scale::One),
    Entry::new(0x216D, Obj::HomingPolarity, &Scale::One),
    Entry::new(0x2190, Obj::RegisterMap, &Scale::One),
];

/// §4's codes: 2 illegal address, 3 illegal value, 4 device failure, 5 write to a read-only
/// register, 6 busy, 7 read of a write-only register, 8 byte count, 11 no such register.
pub const EXCEPTIONS: Exceptions = Exceptions {
    unknown: Exception::Vendor(0x0B),
    read_only: Exception::Vendor(0x05),
    out_of_range: Exception::IllegalDataValue,
    busy: Exception::Vendor(0x06),
    disabled: Exception::ServerDeviceFailure,
    faulted: Exception::ServerDeviceFailure,
    not_now: Exception::ServerDeviceFailure,
    infeasible: Exception::IllegalDataValue,
    unsupported: Exception::ServerDeviceFailure,
    write_only: Exception::Vendor(0x07),
    split: Exception::IllegalDataAddress,
    byte_count: Exception::Vendor(0x08),
    function: Exception::IllegalFunction,
};

/// How a request walks [`ENTRIES`].
const WALK: Walk = Walk::List;

/// The JMC layout.
pub static LAYOUT: Layout = Layout {
    entries: &ENTRIES,
    order: WordOrder::Setting,
    exceptions: EXCEPTIONS,
    walk: WALK,
    halves: false,
    spoilt: SpoiltCodes::DROPPED,
    defaults: &[],
    program: None,
    reserved: &[],
    sub_index: None,
    address: None,
    scope: true,
    index: Some(&INDEX),
};

/// The table's compiled lookup.
static INDEX: Compiled = compiled!(ENTRIES, WALK);

/// What the reference says beside the table: the decisions where seed 001 is silent or
/// contradicts itself.
#[cfg(feature = "docs")]
pub static REFERENCE: super::doc::Reference = super::doc::Reference {
    title: "JMC map (seed 001, iHSS57-R)",
    notes: &[
        "Chosen with 0x2190 = 1, saved (0x200F = 2), from the next power-up; `hal-sim --map jmc` for one run. 0x2190 = 0 and a save switch back to the native map. The map powers up switch on disabled (§6.1: \"after power-up the drive is disabled\").",
        "Serial line: the manual gives no baud rate, parity or node id, nor registers for them; the drive's own are here at their native addresses (0x2028 node id, factory 1; 0x202A baud rate, factory 9600; 0x2100 parity, factory none, 8N1), taking effect after a save and a restart.",
        "Functions: 0x03, 0x06 and 0x10 as the manual lists them; 0x04, 0x08, 0x17 and 0x2B (device identification, whose application name says \"JMC map\") answer as in the native map. A read takes up to 125 registers (§7.1 says 63, §7.2 126).",
        "Frames end at 3.5 characters of silence and a gap of more than 1.5 characters inside one drops it (the Modbus serial line), in place of the manual's 2 s receive timeout. A frame with a wrong CRC or parity is not answered (not codes 10 and 9): its address cannot be trusted.",
        "0x03 walks the table as 0x10 does (the manual says so for 0x10 only). A walk that reaches a read-only register refuses the write with code 5 (§8's tip names three read-only registers as written together).",
        "0x6000 (word order) is read-write as §8 has it (§5 says read only, and its own examples write it) and kept by a save.",
        "Controlword 0x6040: the state machine is the drive's own (CiA 402, see `docs/maps.md`). Fault reset is bit 7's rising edge (the bit table; the command table's \"bit8\" is the halt bit); quick stop is bit 2 = 0 as the command table and every example have it. 0x0001 and 0x0003 from switch on disabled change nothing, and 0x000F enables the operation from there, so the routines' 0x0001, 0x0003, 0x000F power up as printed.",
        "Statusword 0x6041: bits 0-6 as CiA 402 (bit 5 is 0 during a quick stop, as the state table has it), 7 warning (the supply below the free-wheel voltage), 8 halted, 9 moving, 10-13 per mode as §5 tabulates them (velocity mode's bit 13, maximum acceleration reached, stays 0), 11 the home switch, 14 the CW (negative) limit, 15 the CCW (positive) limit, as 0x216C assigns the inputs.",
        "Position mode: bit 6 (relative) adds the new target to the running target (§6.1: the previous and the new position summed); §6.1's \"no stop\" and \"at once\" examples set it, so their second target 600000 ends at 800000. Statusword bit 12 is 1 while a new set-point can be taken (§5), and a rising bit 4 while it is 0 is not taken (§6.1, line 474).",
        "Velocity mode runs at 0x6081 (its sign the direction) when bit 8 (halt) falls, and changes speed when 0x6081 is written; bit 8 stops it at 0x6084. 0x6081 takes the drive's ±150 to ±300 000 microsteps a second, in 0.1 rev/s at the resolution in force; 0 is refused (03): the mode stops with bit 8, as §6.2 does.",
        "Homing: left (CW) is the negative direction. Methods 1-8 as §6.3 describes them (method 8 as method 7 mirrored: the manual prints it with only its first word changed); the single-speed methods 1-4 run at 0x6099, the two-speed 5-8 search at 0x6099 and find the edge again at the creep speed 0x2165 (the manual names no object for the low speed). The home offset 0x607C: the zero is that far from the home (positive: CCW), where the axis then moves at 0x609B (the manual's offset move) and the homing ends; 0x609B = 0 stays at the home with the position -0x607C. 0x2165, 0x216B (timeout), 0x216C (which input is which switch) and 0x216D (polarity) are the drive's own, at their native addresses.",
        "0x605A: 1 stops at 0x6084, 2 at 0x6085, 3-32767 at once (energised); the manual's default 0 is undefined and reads as 2. Then switch on disabled.",
        "0x606C reads in 0.1 rev/s, as 0x6081 (the manual prints \"rps/min\"); 0x6083, 0x6084, 0x6085 and 0x609A are single registers 0-65535 (§8 prints INTEGER16, §5 UNSIGNED16).",
        "0x1008, 0x1009, 0x100A (the manual gives no length) are the drive's name in 8 registers, its hardware and its software version in 2 each.",
    ],
    remarks: &[
        (
            0x1001,
            "Error register: bit 0 any fault, 1 current, 2 voltage, 3 temperature, 4 communication (timeout 0x2137), 5 position error (closed loop), 7 a coil open.",
        ),
        (
            0x6040,
            "Controlword (write only): the power state machine (bits 0-3, 7), and in operation enabled bit 4 new set-point (PP) or start homing (mode 6), 5 change at once, 6 relative, 8 halt, 9 no stop between set-points.",
        ),
        (
            0x6060,
            "Modes of operation (write only): 1 profile position, 3 profile velocity, 6 homing; 4 (torque) is refused as the manual has it \"not supported\".",
        ),
        (0x6061, "Modes of operation display."),
        (0x6081, "Target velocity: the speed of a set-point (PP), the speed to run at (PV)."),
        (0x607C, "Home offset: the zero is this far from the home found (see the notes)."),
        (0x6098, "Homing method, §6.3's 1-8; 0 (the manual's default) takes the present position as home."),
        (0x6099, "Homing speed: the search for the switch."),
        (0x609A, "Homing acceleration and deceleration."),
        (0x609B, "Zero offset speed: the move from the home to the zero."),
        (0x6064, "Position actual value."),
        (0x606C, "Velocity actual value."),
    ],
    decimal: false,
};
