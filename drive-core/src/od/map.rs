//! Register maps: how the registers of a vendor's protocol reach the drive's objects.

use super::{Access, OBJECTS, Obj, ObjError, Type, index};
use crate::drive::DriveState;
use crate::pdu::{Exception, MAX_WRITE, Words};
use heapless::Vec;

/// A vendor's register layout over the drive's objects.
pub trait RegisterMap {
    /// Reads `out.len() / 2` registers from `addr` into `out`, big-endian.
    fn read(&self, drive: &DriveState, addr: u16, out: &mut [u8]) -> Result<(), Exception>;
    /// Whether `qty` registers from `addr` could be read (checked before 0x17 writes anything).
    fn check_read(&self, addr: u16, qty: u16) -> Result<(), Exception>;
    /// Writes `values` from `addr`: all of them, or none and an exception.
    fn write(&mut self, drive: &mut DriveState, addr: u16, values: Words<'_>) -> Result<(), Exception>;
}

/// The drive's native map (seed 000): register numbers are object addresses, 32-bit objects are
/// high word first.
///
/// A 32-bit object written one half at a time (seed 000 §9.4 writes them with two 0x06 requests)
/// is staged: writing the high word stages it, writing the low word completes the value with the
/// staged high word (or the present one if none is staged), checks it and commits it. Writing
/// both words in one 0x10 commits at once. For command objects the commit is the command.
///
/// A read may span the reserved registers between the objects of one page (0x60xx, say): they
/// read as 0, so a master can poll a whole block. A write touches objects only.
///
/// Exception codes: a read outside a page's objects, a write to a register without an object,
/// or a write to a read-only object, is 02; a
/// value out of range, or a request whose lengths are wrong, 03; a valid value the drive cannot
/// act on now, 04.
#[derive(Clone, Debug)]
pub struct NativeMap {
    staged: [Option<u16>; Obj::COUNT],
}

impl Default for NativeMap {
    fn default() -> Self {
        Self { staged: [None; Obj::COUNT] }
    }
}

/// One step of a write, planned before anything is changed.
#[derive(Clone, Copy, Debug)]
enum Op {
    Commit(Obj, u32),
    Stage(Obj, u16),
}

/// The native exception for an object error.
pub const fn native_exception(e: ObjError) -> Exception {
    match e {
        ObjError::Unknown | ObjError::ReadOnly => Exception::IllegalDataAddress,
        ObjError::OutOfRange => Exception::IllegalDataValue,
        ObjError::Refused => Exception::ServerDeviceFailure,
    }
}

impl NativeMap {
    /// A map with nothing staged.
    pub fn new() -> Self {
        Self::default()
    }

    fn staged(&self, obj: Obj) -> Option<u16> {
        self.staged.get(obj as usize).copied().flatten()
    }

    fn set_staged(&mut self, obj: Obj, v: Option<u16>) {
        if let Some(s) = self.staged.get_mut(obj as usize) {
            *s = v;
        }
    }

    /// Plans a write of `values` from `addr` object by object, checking each value.
    fn plan(
        &self,
        drive: &DriveState,
        addr: u16,
        values: Words<'_>,
    ) -> Result<Vec<Op, { MAX_WRITE as usize }>, ObjError> {
        let mut ops = Vec::new();
        let mut reg = u32::from(addr);
        let end = reg + values.len() as u32;
        let mut i = index::locate(addr, values.len() as u16).ok_or(ObjError::Unknown)?;
        while reg < end {
            let d = OBJECTS.get(i).ok_or(ObjError::Unknown)?;
            if u32::from(d.addr) > reg {
                return Err(ObjError::Unknown);
            }
            if d.access == Access::Ro {
                return Err(ObjError::ReadOnly);
            }
            let word = |r: u32| values.get((r - u32::from(addr)) as usize).ok_or(ObjError::Unknown);
            let op = match d.ty {
                Type::Str(_) => return Err(ObjError::ReadOnly),
                Type::U8 | Type::U16 => Op::Commit(d.obj, u32::from(word(reg)?)),
                Type::U32 | Type::S32 => {
                    let low = u32::from(d.addr) + 1;
                    if reg == low {
                        let hi = match self.staged(d.obj) {
                            Some(hi) => u32::from(hi),
                            None => drive.read(d.obj) >> 16,
                        };
                        Op::Commit(d.obj, hi << 16 | u32::from(word(low)?))
                    } else if low < end {
                        Op::Commit(d.obj, u32::from(word(reg)?) << 16 | u32::from(word(low)?))
                    } else {
                        Op::Stage(d.obj, word(reg)?)
                    }
                }
            };
            if let Op::Commit(obj, v) = op {
                drive.check(obj, v)?;
            }
            ops.push(op).map_err(|_| ObjError::OutOfRange)?;
            reg = d.end();
            i += 1;
        }
        Ok(ops)
    }
}

impl RegisterMap for NativeMap {
    fn read(&self, drive: &DriveState, addr: u16, out: &mut [u8]) -> Result<(), Exception> {
        let mut i = index::locate(addr, (out.len() / 2) as u16).ok_or(Exception::IllegalDataAddress)?;
        // The object at or after `reg`, and its value, fetched once per object.
        let mut cur = OBJECTS.get(i);
        let mut value = cur.map_or(0, |d| drive.read(d.obj));
        for (reg, slot) in (u32::from(addr)..).zip(out.chunks_exact_mut(2)) {
            if cur.is_some_and(|d| d.end() <= reg) {
                i += 1;
                cur = OBJECTS.get(i);
                value = cur.map_or(0, |d| drive.read(d.obj));
            }
            let w = match cur {
                Some(d) if u32::from(d.addr) <= reg => {
                    let k = reg - u32::from(d.addr);
                    match d.ty {
                        Type::U8 | Type::U16 => value as u16,
                        Type::U32 | Type::S32 => (if k == 0 { value >> 16 } else { value }) as u16,
                        Type::Str(_) => drive.text_word(d.obj, k as usize),
                    }
                }
                // A reserved register between two objects of the page.
                _ => 0,
            };
            slot.copy_from_slice(&w.to_be_bytes());
        }
        Ok(())
    }

    /// A read must lie within one page (256 registers sharing the high byte), from the page's
    /// first object to its last; reserved registers between objects read as 0.
    fn check_read(&self, addr: u16, qty: u16) -> Result<(), Exception> {
        index::locate(addr, qty).map(|_| ()).ok_or(Exception::IllegalDataAddress)
    }

    fn write(&mut self, drive: &mut DriveState, addr: u16, values: Words<'_>) -> Result<(), Exception> {
        let ops = self.plan(drive, addr, values).map_err(native_exception)?;
        for op in ops {
            match op {
                Op::Commit(obj, v) => {
                    self.set_staged(obj, None);
                    drive.apply(obj, v);
                }
                Op::Stage(obj, hi) => self.set_staged(obj, Some(hi)),
            }
        }
        Ok(())
    }
}
