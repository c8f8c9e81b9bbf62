//! Register maps: how the registers of a vendor's protocol reach the drive's objects.

use super::exceptions::Exceptions;
use super::index;
use crate::crc;
use crate::od::{Access, OBJECTS, Obj, ObjError, ObjectDef, Range, Storage, Type, is_command};
use crate::pdu::{Exception, MAX_WRITE, SubIndex, Words};
use crate::scope::WORDS;
use crate::state::Shared;
use crate::state::recording::{BLACK_BOX_WINDOW, SCOPE_WINDOW};
use crate::state::{DriveState, ProgramMemory};
use core::borrow::Borrow;
use heapless::Vec;

/// A vendor's register layout over the drive's objects.
pub trait RegisterMap {
    /// Reads `out.len() / 2` registers from `addr` into `out`, big-endian.
    fn read<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &DriveState<P, G>,
        addr: u16,
        out: &mut [u8],
    ) -> Result<(), Exception>;
    /// [`RegisterMap::read`], and the CRC register `crc` run on over the bytes read. A map that
    /// makes its bytes one register at a time runs it as it goes, so that the reply is not read
    /// a second time to seal it.
    #[inline(always)]
    fn read_sealing<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &DriveState<P, G>,
        addr: u16,
        out: &mut [u8],
        crc: u16,
    ) -> Result<u16, Exception> {
        self.read(drive, addr, out)?;
        Ok(crate::crc::update_bytes(crc, out))
    }
    /// Whether `qty` registers from `addr` could be read (checked before 0x17 writes anything).
    fn check_read(&self, addr: u16, qty: u16) -> Result<(), Exception>;
    /// Writes `values` from `addr`: all of them, or none and an exception.
    fn write<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &mut self,
        drive: &mut DriveState<P, G>,
        addr: u16,
        values: Words<'_>,
    ) -> Result<(), Exception>;
    /// The code this map answers to a request the PDU layer refused (`e`: the Modbus code).
    fn request_exception(&self, e: Exception) -> Exception {
        e
    }
    /// Whether the drive powers up switch on disabled whatever 0x6011 holds (a CiA 402 map).
    fn starts_disabled(&self) -> bool {
        false
    }
    /// The application name device identification (0x2B, object 6) reports, if the map has
    /// its own.
    fn application_name(&self) -> Option<&'static str> {
        None
    }
    /// Sets the map's own factory settings over the drive's factory values (a drive with
    /// nothing saved, a factory reset); most maps have none.
    fn factory_settings<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(&self, _drive: &mut DriveState<P, G>) {}
    /// What the map's program window holds (seed 002's multi-segment programs, seed 004's
    /// position data groups), if it has one: without one the drive refuses the program commands
    /// and saves no program.
    fn program_kind(&self) -> crate::state::ProgramKind {
        crate::state::ProgramKind::None
    }
    /// How the map's requests name registers, if by an index and a sub-index byte after it
    /// (seed 003): the map's own decoder of request PDUs and its keys; `None`: Modbus's PDUs
    /// ([`Request::parse`](crate::pdu::Request::parse)). The slave asks once, at power-up.
    fn sub_index(&self) -> Option<SubIndex> {
        None
    }
    /// The bytes a register request (0x03, 0x06, 0x10) carries after its register address, which
    /// a write's reply echoes with it: none in Modbus's requests, seed 003's sub-index 1. (A
    /// platform that ends requests by their length, not by the line's silence, counts them.)
    fn address_extra(&self) -> usize {
        0
    }
    /// The exception code a frame `spoilt` is answered with, if it began with this drive's
    /// address; `None` drops it, as the Modbus serial line has it.
    fn spoilt_frame<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        _drive: &DriveState<P, G>,
        _spoilt: Spoilt,
    ) -> Option<u8> {
        None
    }
    /// The serial port's own address, which the drive answers to from power-up while the
    /// address source 0x21D1 is 0 (seed 003's, 1); `None`: the node id 0x2028 always.
    fn fixed_address(&self) -> Option<u8> {
        None
    }
    /// Whether register `addr` of this map is the native map's register `addr` (the native
    /// map's own, or a layout's window onto it): where a locked drive takes 0x225F.
    fn is_native(&self, _addr: u16) -> bool {
        false
    }
}

/// What spoilt a frame the framing dropped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Spoilt {
    /// A silence over t1.5 inside it.
    Gap,
    /// It followed a whole frame before t3.5.
    Early,
    /// Its CRC is wrong.
    Crc,
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
    /// The staged high word of each 32-bit object, by its [`STAGE_SLOT`].
    staged: [Option<u16>; STAGE_SLOTS],
}

impl Default for NativeMap {
    fn default() -> Self {
        Self { staged: [None; STAGE_SLOTS] }
    }
}

/// Whether the object `d` declares can be staged: a 32-bit one a master can write (a write to
/// a read-only one is refused before anything is staged).
const fn stageable(d: &ObjectDef) -> bool {
    d.words() == 2 && !matches!(d.access(), Access::Ro) && !matches!(d.storage(), Storage::Const)
}

/// The objects that can be staged.
pub(super) const STAGE_SLOTS: usize = {
    let (mut n, mut i) = (0, 0);
    while i < OBJECTS.len() {
        #[allow(clippy::indexing_slicing)] // const evaluation: out of bounds is a compile error
        if stageable(&OBJECTS[i]) {
            n += 1;
        }
        i += 1;
    }
    n
};

/// Each object's place in [`NativeMap::staged`], in the order of the objects; `u8::MAX` for
/// an object that is never staged. (One place an object would take 600 bytes of RAM for the
/// few that can be staged.)
pub(super) const STAGE_SLOT: [u8; Obj::COUNT] = {
    let mut slot = [u8::MAX; Obj::COUNT];
    let (mut n, mut i) = (0u8, 0);
    while i < OBJECTS.len() {
        #[allow(clippy::indexing_slicing)] // const evaluation: out of bounds is a compile error
        if stageable(&OBJECTS[i]) {
            slot[i] = n;
            n += 1;
        }
        i += 1;
    }
    slot
};

/// What writing one object amounts to, in every map.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Op {
    /// The complete value (in the map's unit and bits): checked, then applied.
    Commit(u32),
    /// The high word of a 32-bit object alone: kept until its low word comes.
    Stage(u16),
}

/// The native exception for an object error: the Modbus convention (02 address, 03 value, 04
/// any refusal).
pub const fn native_exception(e: ObjError) -> Exception {
    Exceptions::MODBUS.of(e)
}

impl NativeMap {
    /// A map with nothing staged.
    pub fn new() -> Self {
        Self::default()
    }

    /// The staged high half of `obj`, if any.
    pub(super) fn staged(&self, obj: Obj) -> Option<u16> {
        let slot = STAGE_SLOT.get(obj as usize)?;
        self.staged.get(usize::from(*slot)).copied().flatten()
    }

    /// Stages `v` as the high half of `obj` (`None`: nothing staged).
    pub(super) fn set_staged(&mut self, obj: Obj, v: Option<u16>) {
        if let Some(s) = STAGE_SLOT.get(obj as usize).and_then(|&slot| self.staged.get_mut(usize::from(slot))) {
            *s = v;
        }
    }

    /// Decodes a write of `values` from `addr` object by object, noting what to do to each, and
    /// checks the addresses and access. Whether any of them is a command (an object whose write
    /// does more than store it).
    ///
    /// Each complete value is also checked against `drive` as it stands, in the same pass, and
    /// the first refusal goes to `refused`: an address error anywhere in the request still comes
    /// first, and a request with commands among several objects is checked again by the caller.
    #[inline]
    fn plan<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &DriveState<P, G>,
        addr: u16,
        values: Words<'_>,
        plan: &mut Plan,
        refused: &mut Option<ObjError>,
    ) -> Result<bool, ObjError> {
        let first = index::locate(addr, values.len() as u16).ok_or(ObjError::Unknown)?;
        let end = u32::from(addr) + values.len() as u32;
        // The objects of a write are contiguous, so they take the words in order.
        let mut words = values.iter().map(u32::from);
        let mut reg = u32::from(addr);
        let mut commands = false;
        for d in OBJECTS.get(first..).unwrap_or_default() {
            if reg >= end {
                break;
            }
            if u32::from(d.addr) > reg {
                return Err(ObjError::Unknown);
            }
            // The common case, a plain one-register setting, by one table entry: writable, no
            // command, its value checked against an interval.
            if let Some(&(lo, hi)) = PLAIN.get(d.obj as usize).filter(|&&b| b != NOT_PLAIN) {
                let v = words.next().ok_or(ObjError::Unknown)?;
                if refused.is_none() && !(u32::from(lo)..=u32::from(hi)).contains(&v) {
                    *refused = Some(ObjError::OutOfRange);
                }
                plan.push(Step::new(d, Op::Commit(v))).map_err(|_| ObjError::Unknown)?;
                reg += 1;
                continue;
            }
            if d.access() == Access::Ro {
                return Err(ObjError::ReadOnly);
            }
            let mut word = || words.next().ok_or(ObjError::Unknown);
            let op = match d.ty() {
                Type::U8 | Type::U16 => Op::Commit(word()?),
                Type::U32 | Type::S32 => {
                    if reg > u32::from(d.addr) {
                        // The low word alone completes the value with the staged high word, or
                        // the present one if none is staged.
                        let hi = match self.staged(d.obj) {
                            Some(hi) => u32::from(hi),
                            None => drive.read_def(d) >> 16,
                        };
                        Op::Commit(hi << 16 | word()?)
                    } else if reg + 1 < end {
                        let hi = word()?;
                        Op::Commit(hi << 16 | word()?)
                    } else {
                        Op::Stage(word()? as u16)
                    }
                }
                Type::Str(_) => return Err(ObjError::ReadOnly),
            };
            let command = is_command(d.obj);
            commands |= command;
            // A command is checked as it is written (`write_def`): checking a motion command
            // plans the motion, and so does writing it.
            if let Op::Commit(v) = op
                && refused.is_none()
                && !command
            {
                *refused = drive.check_def(d, v).err();
            }
            plan.push(Step::new(d, op)).map_err(|_| ObjError::Unknown)?;
            reg = d.end();
        }
        if reg < end { Err(ObjError::Unknown) } else { Ok(commands) }
    }

    /// Commits a write that includes a command: a command may depend on values written before
    /// it in the same request (a speed, then a move), so each value is checked on the drive that
    /// has taken the ones before, all or nothing ([`DriveState::write_in_order`]).
    #[inline(never)]
    fn commit_in_order<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &mut self,
        drive: &mut DriveState<P, G>,
        plan: &Plan,
    ) -> Result<(), Exception> {
        drive
            .write_in_order(plan.iter(), |_, s| {
                Ok(match s.get() {
                    (d, Op::Commit(v)) => Some((d, v)),
                    (_, Op::Stage(_)) => None,
                })
            })
            .map_err(native_exception)?;
        for (d, op) in plan.iter().map(|s| s.get()) {
            self.set_staged(d.obj, if let Op::Stage(hi) = op { Some(hi) } else { None });
        }
        Ok(())
    }

    /// Writes `values` from `addr` through a plan: everything is checked before anything
    /// changes, all or nothing.
    // Out of line, with its plan on the stack: a one-register write does without both.
    #[inline(never)]
    fn write_planned<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &mut self,
        drive: &mut DriveState<P, G>,
        addr: u16,
        values: Words<'_>,
    ) -> Result<(), Exception> {
        let mut plan = Plan::new();
        let mut refused = None;
        let commands = self.plan(drive, addr, values, &mut plan, &mut refused).map_err(native_exception)?;
        if commands && plan.len() > 1 {
            return self.commit_in_order(drive, &plan);
        }
        // Values independent of each other, all checked by the plan but a command, which is the
        // only value if there is one: apply them, the command checked as it is written.
        if let Some(e) = refused {
            return Err(native_exception(e));
        }
        for (d, op) in plan.iter().map(|s| s.get()) {
            match op {
                Op::Commit(v) if is_command(d.obj) => {
                    drive.write_def(d, v).map_err(native_exception)?;
                    self.set_staged(d.obj, None);
                }
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

/// The raw values a plain object ([`DriveState::plain`]) of one register accepts, as `lo..=hi`:
/// the same as its [`Range::accepts`](crate::od::Range::accepts) for its type, in two comparisons
/// instead of two matches on its type and range. Empty ([`NOT_PLAIN`]) for other objects, and
/// where the values are not one interval (sets, bit masks, magnitudes).
static PLAIN: [(u16, u16); Obj::COUNT] = {
    let mut table = [NOT_PLAIN; Obj::COUNT];
    let mut i = 0;
    while i < Obj::COUNT {
        #[allow(clippy::indexing_slicing)] // const evaluation: out of bounds is a compile error
        {
            if DriveState::<Shared>::plain(&OBJECTS[i])
                && OBJECTS[i].words() == 1
                && let Some(bounds) = interval(OBJECTS[i].ty(), *OBJECTS[i].range)
            {
                table[i] = bounds;
            }
        }
        i += 1;
    }
    table
};

/// The interval of an object that is not plain: empty.
const NOT_PLAIN: (u16, u16) = (1, 0);

/// The raw values `range` accepts for a one-register `ty` as one interval, if they are one.
const fn interval(ty: Type, range: Range) -> Option<(u16, u16)> {
    let max = match ty {
        Type::U8 => u8::MAX as i64,
        Type::U16 => u16::MAX as i64,
        _ => return None,
    };
    match range {
        Range::Any => Some((0, max as u16)),
        // Within the type; an empty span stays empty.
        Range::Span(lo, hi) => {
            let (lo, hi) = (lo as i64, hi as i64);
            let lo = if lo < 0 { 0 } else { lo };
            let hi = if hi > max { max } else { hi };
            if lo > hi { Some((1, 0)) } else { Some((lo as u16, hi as u16)) }
        }
        _ => None,
    }
}

/// The register of an [`index::OTHER`] entry `e`: a live value or a text.
#[inline(never)]
fn other_word<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(drive: &DriveState<P, G>, e: u32) -> u16 {
    let Some(obj) = OBJECTS.get((e & index::OTHER_OBJ) as usize).map(|d| d.obj) else { return 0 };
    if e & index::OTHER_TEXT != 0 {
        return drive.text_word(obj, ((e >> index::OTHER_WORD) & 15) as usize);
    }
    // High word first.
    let shift = if e & index::OTHER_HIGH != 0 { 16 } else { 0 };
    (drive.live(obj) >> shift) as u16
}

/// One object of a plan and what to do with it: 8 bytes (a declaration's reference beside an
/// [`Op`] took 12, and a plan lives on a microcontroller's short stack).
#[derive(Clone, Copy, Debug)]
struct Step {
    obj: Obj,
    stage: bool,
    value: u32,
}

impl Step {
    fn new(d: &ObjectDef, op: Op) -> Self {
        match op {
            Op::Commit(value) => Self { obj: d.obj, stage: false, value },
            Op::Stage(hi) => Self { obj: d.obj, stage: true, value: u32::from(hi) },
        }
    }

    /// The object's declaration and the operation.
    fn get(self) -> (&'static ObjectDef, Op) {
        (self.obj.def(), if self.stage { Op::Stage(self.value as u16) } else { Op::Commit(self.value) })
    }
}

/// The most objects a write can touch: the longest run of objects without a register between
/// them (a write that meets a register without an object is refused), at most [`MAX_WRITE`].
const PLAN_CAPACITY: usize = {
    let (mut longest, mut run, mut i) = (1, 1, 1);
    while i < OBJECTS.len() {
        #[allow(clippy::indexing_slicing)] // const evaluation: out of bounds is a compile error
        {
            run = if OBJECTS[i].addr as u32 == OBJECTS[i - 1].end() { run + 1 } else { 1 };
        }
        if run > longest {
            longest = run;
        }
        i += 1;
    }
    if longest < MAX_WRITE as usize { longest } else { MAX_WRITE as usize }
};

/// The objects a write touches and what it does to each, checked before anything changes.
type Plan = Vec<Step, PLAN_CAPACITY>;

impl RegisterMap for NativeMap {
    fn is_native(&self, _addr: u16) -> bool {
        true
    }

    #[inline(always)]
    fn read<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &DriveState<P, G>,
        addr: u16,
        out: &mut [u8],
    ) -> Result<(), Exception> {
        // The same loop; the CRC it runs, unused, is left out by the compiler.
        self.read_sealing(drive, addr, out, crc::INIT).map(|_| ())
    }

    #[inline(always)]
    fn read_sealing<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &DriveState<P, G>,
        addr: u16,
        out: &mut [u8],
        crc: u16,
    ) -> Result<u16, Exception> {
        let Some(regs) = index::registers(addr, (out.len() / 2) as u16) else {
            read_window(drive, addr, out)?;
            return Ok(crc::update_bytes(crc, out));
        };
        let mut crc = crc;
        for (slot, &e) in out.as_chunks_mut::<2>().0.iter_mut().zip(regs) {
            // A stored value, or a reserved register (shifted out), as the index entry says;
            // OTHER is past the end of `params`.
            let w = match drive.params.get((e >> 16) as usize) {
                Some(&p) => (u64::from(p) >> (e & 63)) as u16,
                None => other_word(drive, e),
            };
            let [hi, lo] = w.to_be_bytes();
            *slot = [hi, lo];
            crc = crc::update(crc::update(crc, hi), lo);
        }
        Ok(crc)
    }

    /// A read must lie within one page (256 registers sharing the high byte), from the page's
    /// first object to its last (reserved registers between objects read as 0), or within a
    /// capture window.
    fn check_read(&self, addr: u16, qty: u16) -> Result<(), Exception> {
        match index::locate(addr, qty) {
            Some(_) => Ok(()),
            None if in_window(addr, qty) => Ok(()),
            None => Err(Exception::IllegalDataAddress),
        }
    }

    #[inline(always)]
    fn write<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &mut self,
        drive: &mut DriveState<P, G>,
        addr: u16,
        values: Words<'_>,
    ) -> Result<(), Exception> {
        // Registers that are all plain one-register settings (0x06 to a parameter, a block of
        // parameters), the commonest writes: the same checks as the plan of `write_planned`
        // makes, without the plan. Anything else (or an address error) goes there.
        let Some(regs) = index::registers(addr, values.len() as u16).filter(|r| !r.is_empty()) else {
            return self.write_planned(drive, addr, values);
        };
        // Each register the first of a plain one-register object (shift 0; other objects have
        // an empty interval) with its value inside the interval, or the plan decides, and finds
        // the exception to give.
        let mut plain = true;
        for (&e, &v) in regs.iter().zip(values.pairs()) {
            // The entry turned half over: the object's index if its shift is 0, else past the
            // table's end, so that one bounds check tests both.
            let Some(&(lo, hi)) = PLAIN.get(e.rotate_right(16) as usize) else {
                plain = false;
                break;
            };
            let v = u16::from_be_bytes(v);
            if v < lo || v > hi {
                plain = false;
                break;
            }
        }
        if !plain {
            return self.write_planned(drive, addr, values);
        }
        // A plain setting is stored and nothing else (what `apply_def` does for it); its index
        // entry holds its object index, which is its place in `params`. (It has one register:
        // nothing of it is ever staged.)
        for (&e, &v) in regs.iter().zip(values.pairs()) {
            if let Some(p) = drive.params.get_mut((e >> 16) as usize) {
                *p = u32::from(u16::from_be_bytes(v));
            }
        }
        Ok(())
    }
}

/// Whether `qty` registers from `addr` lie in one capture window (0x4000 the scope's,
/// 0xA000 the black box's; 8192 registers each).
fn in_window(addr: u16, qty: u16) -> bool {
    let end = u32::from(addr) + u32::from(qty);
    [SCOPE_WINDOW, BLACK_BOX_WINDOW].iter().any(|&w| addr >= w && end <= u32::from(w) + WORDS as u32)
}

/// A read of a capture window ([`in_window`]): the capture's rows in time order. Out of line:
/// the objects' reads do not carry it.
#[inline(never)]
fn read_window<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
    drive: &DriveState<P, G>,
    addr: u16,
    out: &mut [u8],
) -> Result<(), Exception> {
    if !in_window(addr, (out.len() / 2) as u16) {
        return Err(Exception::IllegalDataAddress);
    }
    for (slot, reg) in out.chunks_exact_mut(2).zip(u32::from(addr)..) {
        slot.copy_from_slice(&drive.window_word(reg).unwrap_or(0).to_be_bytes());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A plan holds the longest run of objects with no register between them, and a write of
    /// all of that run's registers is planned (its values refused or not, never for room).
    #[test]
    fn a_plan_holds_the_longest_write() {
        let runs = OBJECTS.windows(2).fold((1usize, 1usize), |(longest, run), w| match w {
            [a, b] if u32::from(b.addr) == a.end() => (longest.max(run + 1), run + 1),
            _ => (longest, 1),
        });
        assert_eq!(PLAN_CAPACITY, runs.0.min(usize::from(MAX_WRITE)));
        let drive = DriveState::new(&crate::ident::Identity::SIMULATOR, false);
        // Every run of writable objects, planned whole with the values they hold.
        let contiguous = |a: &ObjectDef, b: &ObjectDef| u32::from(b.addr) == a.end();
        for run in OBJECTS.chunk_by(contiguous) {
            for w in run.split(|d| d.access() == Access::Ro || matches!(d.ty(), Type::Str(_))).filter(|w| !w.is_empty())
            {
                let mut words: Vec<u8, 256> = Vec::new();
                for d in w {
                    let v = drive.read_def(d);
                    let bytes = if d.words() == 2 { v.to_be_bytes() } else { [0, 0, (v >> 8) as u8, v as u8] };
                    let _ = words.extend_from_slice(bytes.get(4 - 2 * usize::from(d.words())..).unwrap_or_default());
                }
                let expected: usize = w.iter().map(|d| 2 * usize::from(d.words())).sum();
                assert_eq!(words.len(), expected);
                let addr = w.first().map_or(0, |d| d.addr);
                let (mut plan, mut refused) = (Plan::new(), None);
                let planned = NativeMap::new().plan(&drive, addr, Words::new(&words), &mut plan, &mut refused);
                assert!(planned.is_ok(), "{addr:#06x}: {planned:?}");
                assert_eq!(plan.len(), w.len());
            }
        }
    }

    /// The precomputed intervals agree with the declarations, and a plain object is checked for
    /// its range only.
    #[test]
    fn plain_intervals_match_check_def() {
        let drive = DriveState::new(&crate::ident::Identity::SIMULATOR, false);
        let mut plain = 0;
        for (d, bounds) in OBJECTS.iter().zip(PLAIN.iter()) {
            if *bounds == NOT_PLAIN {
                continue;
            }
            let (lo, hi) = (u32::from(bounds.0), u32::from(bounds.1));
            plain += 1;
            let probes =
                [0, 1, 2, 3, 100, 255, 256, 1000, 6000, 6001, 0xFFFF, 0x1_0000, 0x7FFF_FFFF, 0x8000_0000, u32::MAX];
            let edges = [lo.wrapping_sub(1), lo, lo.wrapping_add(1), hi.wrapping_sub(1), hi, hi.wrapping_add(1)];
            for v in probes.into_iter().chain(edges) {
                let fast = (lo..=hi).contains(&v);
                assert_eq!(fast, d.range.accepts(d.ty(), v), "{} {v:#X}", d.name);
                assert_eq!(fast, drive.check_def(d, v).is_ok(), "{} {v:#X}", d.name);
            }
        }
        assert!(plain > 20, "{plain} plain objects");
    }

    /// The word a register shows, from the declarations: 0 where no object is.
    fn declared(drive: &DriveState, reg: u16) -> u16 {
        let Some(d) = OBJECTS.iter().find(|d| d.addr <= reg && u32::from(reg) < d.end()) else { return 0 };
        let k = reg - d.addr;
        match d.ty() {
            // Not told.
            _ if d.obj == Obj::Password => 0,
            Type::Str(_) => drive.text_word(d.obj, usize::from(k)),
            Type::U32 | Type::S32 if k == 0 => (drive.read_def(d) >> 16) as u16,
            _ => drive.read_def(d) as u16,
        }
    }

    /// Reads through the compile-time register index show what the declarations say, register by
    /// register and in long reads across reserved registers, live objects and texts included.
    #[test]
    fn reads_match_the_declarations() {
        let mut drive = DriveState::new(&crate::ident::Identity::SIMULATOR, false);
        for (k, p) in drive.params.iter_mut().enumerate() {
            *p = 0x0102_0304u32.wrapping_mul(k as u32 + 1);
        }
        *drive.status_mut() = crate::state::Status {
            error: 3,
            controller: 5,
            notify: 1,
            gpio: 0x1234,
            gpio_out: 0,
            analog_in: 777,
            pvt_pointer: 9,
            encoder: -5,
            faults: 0x03,
            comm: 0x01,
            supply_mv: 24_000,
            current_ma: 1_500,
            inputs: 0,
            input_edges: 0,
            probes: 2,
        };
        let map = NativeMap::new();
        for d in OBJECTS.iter() {
            for reg in d.addr..d.addr + d.words() {
                let mut out = [0u8; 2];
                assert_eq!(map.read(&drive, reg, &mut out), Ok(()), "{reg:#06X}");
                assert_eq!(u16::from_be_bytes(out), declared(&drive, reg), "{reg:#06X}");
            }
            let mut out = [0u8; 250];
            let qty = (0..=125u16).rev().find(|&q| index::locate(d.addr, q).is_some()).unwrap_or(0);
            let out = out.get_mut(..2 * usize::from(qty)).unwrap_or_default();
            assert_eq!(map.read(&drive, d.addr, out), Ok(()), "{:#06X}+{qty}", d.addr);
            for (reg, w) in (d.addr..).zip(out.as_chunks::<2>().0) {
                assert_eq!(u16::from_be_bytes(*w), declared(&drive, reg), "{reg:#06X}");
            }
        }
    }

    /// A block of plain settings is written whole or not at all, and a block that is not all
    /// plain settings keeps the address errors before the value errors.
    #[test]
    fn plain_blocks_are_all_or_nothing() {
        let mut map = NativeMap::new();
        let mut drive = DriveState::new(&crate::ident::Identity::SIMULATOR, false);
        let words = |vs: &[u16]| vs.iter().flat_map(|v| v.to_be_bytes()).collect::<heapless::Vec<u8, 64>>();
        // 0x601B..=0x6024: PVT indices, 0..=1000.
        let bad = words(&[1, 2, 3, 4, 1001, 6, 7, 8, 9, 10]);
        let before = drive.params;
        assert_eq!(map.write(&mut drive, 0x601B, Words::new(&bad)), Err(Exception::IllegalDataValue));
        assert_eq!(drive.params, before);
        let good = words(&[1, 2, 3, 4, 5, 6, 7, 8, 9, 10]);
        assert_eq!(map.write(&mut drive, 0x601B, Words::new(&good)), Ok(()));
        assert_eq!(drive.read(Obj::PvtFifoDepth), 10);
        // 0x6019..=0x601B runs over the read-only PVT pointer: 02 despite the bad value before it.
        let mixed = words(&[1001, 0, 0]);
        let before = drive.params;
        assert_eq!(map.write(&mut drive, 0x6019, Words::new(&mixed)), Err(Exception::IllegalDataAddress));
        assert_eq!(drive.params, before);
    }

    /// A one-register write to a plain setting (the short path) stores exactly the values its
    /// declaration accepts, refuses the others with 03 and leaves the drive unchanged.
    #[test]
    fn single_plain_writes_follow_the_declaration() {
        for (d, bounds) in OBJECTS.iter().zip(PLAIN.iter()) {
            if *bounds == NOT_PLAIN {
                continue;
            }
            for v in [0u16, 1, 2, 3, 7, 100, 255, 256, 600, 1000, 6000, 6001, 0x7FFF, 0xFFFF] {
                let mut map = NativeMap::new();
                let mut drive = DriveState::new(&crate::ident::Identity::SIMULATOR, false);
                let before = drive.params;
                let bytes = v.to_be_bytes();
                let result = map.write(&mut drive, d.addr, Words::new(&bytes));
                if d.range.accepts(d.ty(), u32::from(v)) {
                    assert_eq!(result, Ok(()), "{} {v}", d.name);
                    assert_eq!(drive.read_def(d), u32::from(v), "{} {v}", d.name);
                } else {
                    assert_eq!(result, Err(Exception::IllegalDataValue), "{} {v}", d.name);
                    assert_eq!(drive.params, before, "{} {v}", d.name);
                }
            }
        }
    }
}
