//! Register maps as layout tables over the drive's objects: for each register the object, its
//! word order, the scale between the map's unit and the drive's, and for each refusal the map's
//! exception code. The transaction rules are the same for every layout:
//!
//! - a 32-bit object written one half at a time is staged: its high half alone is kept until
//!   its low half comes, which completes the value with the staged high half (or the present
//!   one), in the layout's word order;
//! - a write of several objects is all or nothing: each value is checked on the drive that has
//!   taken the ones before it (a speed, then a move), and the drive goes back to a checkpoint if
//!   one is refused;
//! - a refused request changes nothing, and its reason ([`ObjError`]) becomes the layout's code.
//!
//! ```
//! use drive_core::maps::layout::{Entry, Exceptions, Layout, LayoutMap, Scale, WordOrder};
//! use drive_core::od::Obj;
//! use drive_core::{Drive, DriveConfig, Instant};
//! static ENTRIES: [Entry; 1] = [Entry { addr: 0x0100, obj: Obj::PhaseCurrent, scale: Scale::Ratio(100, 1) }];
//! static LAYOUT: Layout = Layout { entries: &ENTRIES, order: WordOrder::LowFirst, exceptions: Exceptions::MODBUS };
//! let mut drive = Drive::with_map(DriveConfig::default(), LayoutMap::new(&LAYOUT));
//! // Write 12 (× 100 mA) to register 0x0100 of node 1.
//! drive.on_rx(Instant::from_micros(0), &[0x01, 0x06, 0x01, 0x00, 0x00, 0x0C, 0x88, 0x33]);
//! drive.on_timer(Instant::from_micros(4_011));
//! assert!(drive.take_reply().is_some());
//! assert_eq!(drive.state().read(Obj::PhaseCurrent), 1200);
//! ```

use super::native::{Op, RegisterMap};
use crate::motion::cubic::Table;
use crate::od::{Access, Obj, ObjError, ObjectDef, Type};
use crate::pdu::{Exception, Words};
use crate::state::DriveState;
use core::borrow::Borrow;

/// Full steps a revolution of the motors the drive runs (1.8°), for scales per revolution.
pub const FULL_STEPS_PER_REV: i64 = 200;

/// The order of a 32-bit object's two registers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WordOrder {
    /// High word at the lower address (the native map).
    HighFirst,
    /// Low word at the lower address.
    LowFirst,
}

/// How a map's value becomes the drive's: `drive = map × scale`, rounded to the nearest.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scale {
    /// The same unit.
    One,
    /// `drive = map × num / den`.
    Ratio(i64, i64),
    /// Per revolution of the motor: `drive = map × microsteps a revolution × num / den` (a
    /// speed in 0.1 rev/s is `PerRev(1, 10)` of the drive's microsteps a second). The
    /// revolution follows the microstep resolution 0x600C.
    PerRev(i64, i64),
}

/// `n / d` rounded to the nearest (halves away from zero); `None` for `d == 0` or overflow.
fn div_round(n: i128, d: i128) -> Option<i128> {
    if d == 0 {
        return None;
    }
    let (n, d) = if d < 0 { (n.checked_neg()?, d.checked_neg()?) } else { (n, d) };
    let half = d / 2;
    if n >= 0 { n.checked_add(half)?.checked_div(d) } else { n.checked_sub(half)?.checked_div(d) }
}

impl Scale {
    /// The factor as a fraction, given the microsteps a revolution.
    const fn fraction(self, per_rev: i64) -> (i128, i128) {
        match self {
            Scale::One => (1, 1),
            Scale::Ratio(n, d) => (n as i128, d as i128),
            Scale::PerRev(n, d) => (n as i128 * per_rev as i128, d as i128),
        }
    }

    /// The drive's value of the map's `v`.
    fn to_drive(self, v: i64, per_rev: i64) -> Option<i64> {
        let (n, d) = self.fraction(per_rev);
        i64::try_from(div_round(i128::from(v).checked_mul(n)?, d)?).ok()
    }

    /// The map's value of the drive's `v`.
    fn to_map(self, v: i64, per_rev: i64) -> Option<i64> {
        let (n, d) = self.fraction(per_rev);
        i64::try_from(div_round(i128::from(v).checked_mul(d)?, n)?).ok()
    }
}

/// One object's place in a layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Entry {
    /// Its first register.
    pub addr: u16,
    /// The object (numeric: one or two registers, as the drive declares it).
    pub obj: Obj,
    /// The map's unit against the drive's.
    pub scale: Scale,
}

/// The exception code a layout answers to each reason a request is refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Exceptions {
    /// No object at a register.
    pub unknown: Exception,
    /// A write to a read-only object.
    pub read_only: Exception,
    /// A value out of range (or beyond the map's scale).
    pub out_of_range: Exception,
    /// The axis moves, a run goes or a save is under way.
    pub busy: Exception,
    /// The power stage is off.
    pub disabled: Exception,
    /// A latched fault.
    pub faulted: Exception,
    /// Not in this mode or state.
    pub not_now: Exception,
    /// No trajectory within the limits.
    pub infeasible: Exception,
    /// The drive does not do this.
    pub unsupported: Exception,
}

impl Exceptions {
    /// The Modbus convention: 02 address, 03 value, 04 any refusal.
    pub const MODBUS: Self = Self {
        unknown: Exception::IllegalDataAddress,
        read_only: Exception::IllegalDataAddress,
        out_of_range: Exception::IllegalDataValue,
        busy: Exception::ServerDeviceFailure,
        disabled: Exception::ServerDeviceFailure,
        faulted: Exception::ServerDeviceFailure,
        not_now: Exception::ServerDeviceFailure,
        infeasible: Exception::ServerDeviceFailure,
        unsupported: Exception::ServerDeviceFailure,
    };

    /// The code for `e`.
    pub const fn of(&self, e: ObjError) -> Exception {
        match e {
            ObjError::Unknown => self.unknown,
            ObjError::ReadOnly => self.read_only,
            ObjError::OutOfRange => self.out_of_range,
            ObjError::Busy => self.busy,
            ObjError::Disabled => self.disabled,
            ObjError::Faulted => self.faulted,
            ObjError::NotNow => self.not_now,
            ObjError::Infeasible => self.infeasible,
            ObjError::Unsupported => self.unsupported,
        }
    }
}

/// A register layout: its entries in address order, without overlaps.
#[derive(Clone, Copy, Debug)]
pub struct Layout {
    /// The objects, by increasing address.
    pub entries: &'static [Entry],
    /// The order of every 32-bit object's registers.
    pub order: WordOrder,
    /// The codes of the refusals.
    pub exceptions: Exceptions,
}

impl Layout {
    /// The entry holding register `reg`, and the register's place in it (0 or 1).
    fn at(&self, reg: u32) -> Option<(&Entry, u32)> {
        let i = self.entries.partition_point(|e| u32::from(e.addr) <= reg).checked_sub(1)?;
        let e = self.entries.get(i)?;
        let k = reg - u32::from(e.addr);
        (k < u32::from(e.obj.def().words())).then_some((e, k))
    }

    /// Whether register `k` (0 or 1) of a 32-bit object is its high half.
    const fn is_high(&self, k: u32) -> bool {
        matches!((self.order, k), (WordOrder::HighFirst, 0) | (WordOrder::LowFirst, 1))
    }
}

/// Microsteps a revolution at the drive's resolution (0x600C; 0 is full steps).
fn per_rev<P: Borrow<Table>>(drive: &DriveState<P>) -> i64 {
    FULL_STEPS_PER_REV * i64::from(drive.read(Obj::Microsteps).max(1))
}

/// The drive's raw value as a number: two's complement for a signed object.
const fn signed(d: &ObjectDef, raw: u32) -> i64 {
    match d.ty {
        Type::S32 => raw as i32 as i64,
        _ => raw as i64,
    }
}

/// The map's number as the object's raw bits, if it fits the object's type.
fn raw_of(d: &ObjectDef, v: i64) -> Option<u32> {
    match d.ty {
        Type::U8 => u8::try_from(v).ok().map(u32::from),
        Type::U16 => u16::try_from(v).ok().map(u32::from),
        Type::U32 => u32::try_from(v).ok(),
        Type::S32 => i32::try_from(v).ok().map(|v| v as u32),
        Type::Str(_) => None,
    }
}

/// A layout's map: the layout and the staged high halves.
#[derive(Clone, Debug)]
pub struct LayoutMap {
    layout: &'static Layout,
    /// The staged high half of each object, by object index.
    staged: [Option<u16>; Obj::COUNT],
}

/// The most objects one write can reach (123 registers).
const MAX_OBJECTS: usize = 123;

impl LayoutMap {
    /// A map over `layout` with nothing staged.
    pub fn new(layout: &'static Layout) -> Self {
        Self { layout, staged: [None; Obj::COUNT] }
    }

    /// The map's value of `e` now, as register bits (32 at most).
    fn map_value<P: Borrow<Table>>(&self, drive: &DriveState<P>, e: &Entry) -> u32 {
        let d = e.obj.def();
        let v = signed(d, drive.read_def(d));
        // A drive value beyond the map's range reads as its low bits.
        e.scale.to_map(v, per_rev(drive)).unwrap_or(v) as u32
    }

    /// The drive's raw value of the map's register bits `bits` for `e`.
    fn drive_value<P: Borrow<Table>>(&self, drive: &DriveState<P>, e: &Entry, bits: u32) -> Result<u32, ObjError> {
        let d = e.obj.def();
        let v = e.scale.to_drive(signed(d, bits), per_rev(drive)).ok_or(ObjError::OutOfRange)?;
        raw_of(d, v).ok_or(ObjError::OutOfRange)
    }

    /// Decodes a write into what it does to each object, or the first address error.
    fn plan<P: Borrow<Table>>(
        &self,
        drive: &DriveState<P>,
        addr: u16,
        values: &Words<'_>,
        plan: &mut heapless::Vec<(&'static Entry, Op), MAX_OBJECTS>,
    ) -> Result<(), ObjError> {
        let end = u32::from(addr) + values.len() as u32;
        let mut reg = u32::from(addr);
        let word = |r: u32| values.get((r - u32::from(addr)) as usize).map(u32::from).ok_or(ObjError::Unknown);
        while reg < end {
            let (e, k) = self.layout.at(reg).ok_or(ObjError::Unknown)?;
            let d = e.obj.def();
            if d.access == Access::Ro || matches!(d.ty, Type::Str(_)) {
                return Err(ObjError::ReadOnly);
            }
            let op = if d.words() == 1 {
                reg += 1;
                Op::Commit(word(reg - 1)?)
            } else {
                let first = u32::from(e.addr);
                let both = k == 0 && first + 1 < end;
                let (hi_reg, lo_reg) = if self.layout.is_high(0) { (first, first + 1) } else { (first + 1, first) };
                if both {
                    reg = first + 2;
                    Op::Commit(word(hi_reg)? << 16 | word(lo_reg)?)
                } else if self.layout.is_high(k) {
                    reg += 1;
                    Op::Stage(word(reg - 1)? as u16)
                } else {
                    reg += 1;
                    // The low half completes the staged high half, or the present one.
                    let hi = match self.staged.get(e.obj as usize).copied().flatten() {
                        Some(hi) => u32::from(hi),
                        None => self.map_value(drive, e) >> 16,
                    };
                    Op::Commit(hi << 16 | word(reg - 1)?)
                }
            };
            plan.push((e, op)).map_err(|_| ObjError::Unknown)?;
        }
        Ok(())
    }
}

impl RegisterMap for LayoutMap {
    fn read<P: Borrow<Table>>(&self, drive: &DriveState<P>, addr: u16, out: &mut [u8]) -> Result<(), Exception> {
        for (slot, reg) in out.chunks_exact_mut(2).zip(u32::from(addr)..) {
            let (e, k) = self.layout.at(reg).ok_or(self.layout.exceptions.unknown)?;
            let v = self.map_value(drive, e);
            let w = if e.obj.def().words() == 1 {
                v as u16
            } else if self.layout.is_high(k) {
                (v >> 16) as u16
            } else {
                v as u16
            };
            slot.copy_from_slice(&w.to_be_bytes());
        }
        Ok(())
    }

    fn check_read(&self, addr: u16, qty: u16) -> Result<(), Exception> {
        let all = (u32::from(addr)..u32::from(addr) + u32::from(qty)).all(|r| self.layout.at(r).is_some());
        if all { Ok(()) } else { Err(self.layout.exceptions.unknown) }
    }

    fn write<P: Borrow<Table>>(
        &mut self,
        drive: &mut DriveState<P>,
        addr: u16,
        values: Words<'_>,
    ) -> Result<(), Exception> {
        let ex = self.layout.exceptions;
        let mut plan = heapless::Vec::new();
        self.plan(drive, addr, &values, &mut plan).map_err(|e| ex.of(e))?;
        // Each value in the drive's unit as the writes before it left the drive (a scale may
        // depend on an object written earlier in the request).
        drive
            .write_in_order(&plan, |drive, &(e, op)| match op {
                Op::Commit(bits) => self.drive_value(drive, e, bits).map(|v| Some((e.obj.def(), v))),
                Op::Stage(_) => Ok(None),
            })
            .map_err(|e| ex.of(e))?;
        for &(e, op) in &plan {
            if let Some(s) = self.staged.get_mut(e.obj as usize) {
                *s = if let Op::Stage(hi) = op { Some(hi) } else { None };
            }
        }
        Ok(())
    }
}
