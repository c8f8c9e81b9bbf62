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

use super::layout::{Choice, Entry, Exceptions, Layout, Scale, Walk, WordOrder};
use crate::od::Obj;
use crate::pdu::Exception;

/// 0.1 rev/s (or rev/s²) in the drive's microsteps a second (or a second squared).
const TENTH_REV: Scale = Scale::PerRev(1, 10);

/// The modes of 0x6060/0x6061: 1 profile position, 3 profile velocity, 6 homing.
static MODES: [Choice; 3] =
    [Choice { lo: 1, hi: 1, drive: 4 }, Choice { lo: 3, hi: 3, drive: 5 }, Choice { lo: 6, hi: 6, drive: 6 }];

/// 0x605A: 1 the deceleration 0x6084, 2 the quick-stop deceleration 0x6085, 3-32767 at once;
/// 0 (the manual's default, which it does not define) as 2.
static QUICK_STOP: [Choice; 4] = [
    Choice { lo: 2, hi: 2, drive: 2 },
    Choice { lo: 1, hi: 1, drive: 1 },
    Choice { lo: 3, hi: 32_767, drive: 0xFFFF },
    Choice { lo: 0, hi: 0, drive: 2 },
];

/// 0x6098: §6.3's methods 1-8 are the homing engine's -3 to -10 (left, CW, is the negative
/// direction; the CW limit is the negative limit switch, the CCW limit the positive one).
/// (As 0x2160 holds them: a 16-bit register, -3 is 0xFFFD.)
static HOMING_METHODS: [Choice; 8] = [
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
    Entry::new(0x1001, Obj::ErrorRegister, Scale::One),
    Entry::new(0x1008, Obj::DeviceName, Scale::One),
    Entry::new(0x1009, Obj::HardwareVersion, Scale::One),
    Entry::new(0x100A, Obj::SoftwareVersion, Scale::One),
    Entry::new(0x6000, Obj::MapWordOrder, Scale::One),
    Entry::new(0x605A, Obj::QuickStopOption, Scale::Table(&QUICK_STOP)),
    Entry::new(0x6040, Obj::DeviceControl, Scale::One).write_only(),
    Entry::new(0x6060, Obj::Mode, Scale::Table(&MODES)).write_only(),
    Entry::new(0x6081, Obj::PpRunSpeed, TENTH_REV),
    Entry::new(0x6083, Obj::PpAccel, TENTH_REV).narrow(),
    Entry::new(0x6084, Obj::PpDecel, TENTH_REV).narrow(),
    Entry::new(0x6085, Obj::QuickStopDecel, TENTH_REV).narrow(),
    Entry::new(0x607A, Obj::PpTarget, Scale::One),
    Entry::new(0x607C, Obj::HomingOffset, Scale::Ratio(-1, 1)),
    Entry::new(0x6098, Obj::HomingMethod, Scale::Table(&HOMING_METHODS)),
    Entry::new(0x6099, Obj::HomingSearchSpeed, TENTH_REV),
    Entry::new(0x609A, Obj::HomingAccel, TENTH_REV).narrow(),
    Entry::new(0x609B, Obj::HomingZeroSpeed, TENTH_REV),
    Entry::new(0x6041, Obj::DeviceStatus, Scale::One),
    Entry::new(0x6061, Obj::Mode, Scale::Table(&MODES)).read_only(),
    Entry::new(0x6064, Obj::Position, Scale::One).read_only(),
    Entry::new(0x606C, Obj::RealSpeed, TENTH_REV),
    Entry::new(0x200F, Obj::SystemControl, Scale::One),
    Entry::new(0x2028, Obj::NodeId, Scale::One),
    Entry::new(0x202A, Obj::BaudRate, Scale::One),
    Entry::new(0x2100, Obj::Parity, Scale::One),
    Entry::new(0x2165, Obj::HomingCreepSpeed, TENTH_REV),
    Entry::new(0x216B, Obj::HomingTimeout, Scale::One),
    Entry::new(0x216C, Obj::HomingInputs, Scale::One),
    Entry::new(0x216D, Obj::HomingPolarity, Scale::One),
    Entry::new(0x2190, Obj::RegisterMap, Scale::One),
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
};

/// The JMC layout.
pub static LAYOUT: Layout =
    Layout { entries: &ENTRIES, order: WordOrder::Setting, exceptions: EXCEPTIONS, walk: Walk::List, halves: false };
