//! Register maps: how the registers of a vendor's protocol reach the drive's objects.

use super::{Access, OBJECTS, Obj, ObjError, ObjectDef, Type, index};
use crate::control::has_effect;
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

/// What writing one object amounts to.
#[derive(Clone, Copy, Debug)]
enum Op {
    /// The complete value: checked, then applied.
    Commit(u32),
    /// The high word of a 32-bit object alone: kept until its low word comes.
    Stage(u16),
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

    /// What `values` (written from register `addr`) do to the object `d`, which starts at or
    /// before register `reg` and is the first object of the write or follows the previous one.
    #[inline]
    fn op(&self, drive: &DriveState, d: &ObjectDef, addr: u32, reg: u32, values: Words<'_>) -> Result<Op, ObjError> {
        let word = |r: u32| values.get((r - addr) as usize).map(u32::from).ok_or(ObjError::Unknown);
        match d.ty {
            Type::U8 | Type::U16 => Ok(Op::Commit(word(reg)?)),
            Type::U32 | Type::S32 => {
                let low = u32::from(d.addr) + 1;
                if reg == low {
                    let hi = match self.staged(d.obj) {
                        Some(hi) => u32::from(hi),
                        None => drive.read_def(d) >> 16,
                    };
                    Ok(Op::Commit(hi << 16 | word(low)?))
                } else if low < addr + values.len() as u32 {
                    Ok(Op::Commit(word(reg)? << 16 | word(low)?))
                } else {
                    Ok(Op::Stage(word(reg)? as u16))
                }
            }
            Type::Str(_) => Err(ObjError::ReadOnly),
        }
    }

    /// Decodes a write of `values` from `addr` object by object, noting what to do to each; the
    /// addresses and access are checked here, the values by the caller.
    /// Whether any of them is a command (an object whose write does more than store it).
    fn plan(&self, drive: &DriveState, addr: u16, values: Words<'_>, plan: &mut Plan) -> Result<bool, ObjError> {
        let first = index::locate(addr, values.len() as u16).ok_or(ObjError::Unknown)?;
        let (addr, end) = (u32::from(addr), u32::from(addr) + values.len() as u32);
        let mut reg = addr;
        let mut commands = false;
        for d in OBJECTS.get(first..).unwrap_or_default() {
            if reg >= end {
                break;
            }
            if u32::from(d.addr) > reg {
                return Err(ObjError::Unknown);
            }
            if d.access == Access::Ro {
                return Err(ObjError::ReadOnly);
            }
            let op = self.op(drive, d, addr, reg, values)?;
            commands |= has_effect(d.obj);
            plan.push((d, op)).map_err(|_| ObjError::Unknown)?;
            reg = d.end();
        }
        if reg < end { Err(ObjError::Unknown) } else { Ok(commands) }
    }
}

/// The objects a write touches and what it does to each, checked before anything changes.
type Plan = Vec<(&'static ObjectDef, Op), { MAX_WRITE as usize }>;

impl RegisterMap for NativeMap {
    #[inline]
    fn read(&self, drive: &DriveState, addr: u16, out: &mut [u8]) -> Result<(), Exception> {
        let first = index::locate(addr, (out.len() / 2) as u16).ok_or(Exception::IllegalDataAddress)?;
        let (base, end) = (u32::from(addr), u32::from(addr) + (out.len() / 2) as u32);
        // Reserved registers between objects read as 0.
        out.fill(0);
        let mut put = |reg: u32, w: u16| {
            if reg >= base {
                let at = 2 * (reg - base) as usize;
                if let Some(slot) = out.get_mut(at..at + 2) {
                    slot.copy_from_slice(&w.to_be_bytes());
                }
            }
        };
        for d in OBJECTS.get(first..).unwrap_or_default() {
            let at = u32::from(d.addr);
            if at >= end {
                break;
            }
            match d.ty {
                Type::U8 | Type::U16 => put(at, drive.read_def(d) as u16),
                Type::U32 | Type::S32 => {
                    let v = drive.read_def(d);
                    put(at, (v >> 16) as u16);
                    put(at + 1, v as u16);
                }
                Type::Str(_) => {
                    for k in 0..d.words() {
                        put(at + u32::from(k), drive.text_word(d.obj, usize::from(k)));
                    }
                }
            }
        }
        Ok(())
    }

    /// A read must lie within one page (256 registers sharing the high byte), from the page's
    /// first object to its last; reserved registers between objects read as 0.
    fn check_read(&self, addr: u16, qty: u16) -> Result<(), Exception> {
        index::locate(addr, qty).map(|_| ()).ok_or(Exception::IllegalDataAddress)
    }

    fn write(&mut self, drive: &mut DriveState, addr: u16, values: Words<'_>) -> Result<(), Exception> {
        // Everything is checked before anything changes: all or nothing.
        let mut plan = Plan::new();
        let commands = self.plan(drive, addr, values, &mut plan).map_err(native_exception)?;
        if commands && plan.len() > 1 {
            // A command may depend on values written before it in the same request (a speed,
            // then a move): check each on a copy that has taken the ones before, then commit.
            // The drive itself takes them, and goes back to the checkpoint if one is refused
            // (a clone would copy the 10 KB PVT table).
            let saved = drive.checkpoint();
            for &(d, op) in plan.iter() {
                if let Op::Commit(v) = op {
                    if let Err(e) = drive.check_def(d, v) {
                        drive.restore(saved);
                        return Err(native_exception(e));
                    }
                    drive.apply_def(d, v);
                }
            }
            for &(d, op) in plan.iter() {
                self.set_staged(d.obj, if let Op::Stage(hi) = op { Some(hi) } else { None });
            }
            return Ok(());
        }
        // Values independent of each other: check them all, then apply them.
        for &(d, op) in plan.iter() {
            if let Op::Commit(v) = op {
                drive.check_def(d, v).map_err(native_exception)?;
            }
        }
        for &(d, op) in plan.iter() {
            match op {
                Op::Commit(v) => {
                    self.set_staged(d.obj, None);
                    drive.apply_def(d, v);
                }
                Op::Stage(hi) => self.set_staged(d.obj, Some(hi)),
            }
        }
        Ok(())
    }
}
