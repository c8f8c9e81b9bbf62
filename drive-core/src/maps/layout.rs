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
//! static ENTRIES: [Entry; 1] = [Entry::new(0x0100, Obj::PhaseCurrent, &Scale::Ratio(100, 1))];
//! static LAYOUT: Layout = Layout::by_address(&ENTRIES, WordOrder::LowFirst, Exceptions::MODBUS);
//! let mut drive = Drive::with_map(DriveConfig::default(), LayoutMap::new(&LAYOUT));
//! // Write 12 (× 100 mA) to register 0x0100 of node 1.
//! drive.on_rx(Instant::from_micros(0), &[0x01, 0x06, 0x01, 0x00, 0x00, 0x0C, 0x88, 0x33]);
//! drive.on_timer(Instant::from_micros(4_011));
//! assert!(drive.take_reply().is_some());
//! assert_eq!(drive.state().read(Obj::PhaseCurrent), 1200);
//! ```

use super::compiled::{self, Compiled, Fast};
use super::native::{NativeMap, Op, RegisterMap, Spoilt};
use crate::od::{Access, OBJECTS, Obj, ObjError, ObjectDef, Range, Type};
use crate::pdu::{Exception, SubIndex, Words};
use crate::scope::WORDS;
use crate::state::Shared;
use crate::state::recording::{BLACK_BOX_WINDOW, SCOPE_WINDOW};
use crate::state::{DriveState, ProgramMemory};
use core::borrow::Borrow;

pub use super::exceptions::Exceptions;
pub use crate::units::FULL_STEPS_PER_REV;

/// The order of a 32-bit object's two registers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WordOrder {
    /// High word at the lower address (the native map).
    HighFirst,
    /// Low word at the lower address.
    LowFirst,
    /// As the setting 0x2191 says (0 high word first): a map whose manual makes it a register.
    Setting,
}

/// How a multi-register request walks a layout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Walk {
    /// By register address: the entries are in address order, a request covers the addresses
    /// from its start.
    Address,
    /// By the layout's list: a request starts at an entry's address and goes on through the
    /// entries that follow it in the list, whatever their addresses (JMC's §8).
    List,
}

/// One value of a [`Scale::Table`]: the map's values `lo..=hi` mean the drive's `drive`, which
/// reads back as `lo`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Choice {
    /// The lowest map value.
    pub lo: i32,
    /// The highest map value.
    pub hi: i32,
    /// The drive's value.
    pub drive: i32,
}

/// What a layout lets a master do with an entry, beyond what its object allows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum View {
    /// As the object declares.
    Declared,
    /// Read only.
    ReadOnly,
    /// Write only: a read is refused.
    WriteOnly,
}

/// How a map's value becomes the drive's: `drive = map × scale`, rounded to the nearest.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scale {
    /// The same unit.
    One,
    /// `drive = map × num / den`.
    Ratio(i16, i16),
    /// Per revolution of the motor: `drive = map × microsteps a revolution × num / den` (a
    /// speed in 0.1 rev/s is `PerRev(1, 10)` of the drive's microsteps a second). The
    /// revolution follows the microstep resolution 0x600C.
    PerRev(i16, i16),
    /// An enumeration: the map's values and the drive's, one by one (a value not listed is out
    /// of range). A reference to a static slice, so that a scale is 8 bytes.
    Table(&'static &'static [Choice]),
    /// A field of the drive's value: `width` bits from bit `shift` (a register a bit: seed
    /// 002's pseudo-inputs; the alarm code in a fault history entry: seed 003's fault list); a
    /// write changes that field alone.
    Field(u8, u8),
    /// The drive's bits `mask` inverted (an output's active level where the map's 1 is the
    /// drive's 0: seed 003's output polarity); a value beyond `mask` is out of range.
    Invert(u16),
    /// The microsteps a full step as pulses a revolution of a 1.8° motor: a multiple of 200
    /// (the drive's full stepping, 0, reads as 200).
    PulsesPerRev,
    /// A position in the position data groups' unit: `drive = map × 0x219B / 0x219C` (seed
    /// 004's electronic gear 05F8h/05F9h). The layout map applies the gear in force; alone
    /// (the functions below) it is the factory's 1:1.
    Gear,
}

/// `n / d` rounded to the nearest (halves away from zero); `None` for `d == 0` or overflow.
/// (64 bits hold every product: a 32-bit value times a factor below 2^31.)
#[inline(always)]
fn div_round(n: i64, d: i64) -> Option<i64> {
    if d == 0 {
        return None;
    }
    let (n, d) = if d < 0 { (n.checked_neg()?, d.checked_neg()?) } else { (n, d) };
    let half = d / 2;
    if n >= 0 { n.checked_add(half)?.checked_div(d) } else { n.checked_sub(half)?.checked_div(d) }
}

impl Scale {
    /// The factor as a fraction, given the microsteps a revolution.
    const fn fraction(self, per_rev: i64) -> (i64, i64) {
        match self {
            Scale::One | Scale::Table(_) | Scale::Field(..) | Scale::Invert(_) | Scale::PulsesPerRev | Scale::Gear => {
                (1, 1)
            }
            Scale::Ratio(n, d) => (n as i64, d as i64),
            Scale::PerRev(n, d) => (n as i64 * per_rev, d as i64),
        }
    }

    /// The drive's value of the map's `v`.
    pub fn to_drive(self, v: i64, per_rev: i64) -> Option<i64> {
        match self {
            Scale::Table(choices) => {
                return choices
                    .iter()
                    .find(|c| (i64::from(c.lo)..=i64::from(c.hi)).contains(&v))
                    .map(|c| i64::from(c.drive));
            }
            Scale::Invert(mask) => return (0..=i64::from(mask)).contains(&v).then_some(v ^ i64::from(mask)),
            Scale::PulsesPerRev => {
                let steps = FULL_STEPS_PER_REV;
                return (v % steps == 0).then_some(v / steps);
            }
            _ => {}
        }
        let (n, d) = self.fraction(per_rev);
        div_round(v.checked_mul(n)?, d)
    }

    /// The map's value of the drive's `v`.
    pub fn to_map(self, v: i64, per_rev: i64) -> Option<i64> {
        match self {
            Scale::Table(choices) => {
                return choices.iter().find(|c| i64::from(c.drive) == v).map(|c| i64::from(c.lo));
            }
            Scale::Invert(mask) => return Some(v ^ i64::from(mask)),
            Scale::PulsesPerRev => return Some(v.max(1) * FULL_STEPS_PER_REV),
            _ => {}
        }
        let (n, d) = self.fraction(per_rev);
        div_round(v.checked_mul(d)?, n)
    }
}

/// One object's place in a layout: 8 bytes (a map's table is a few hundred of them).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Entry {
    /// Its first register.
    pub addr: u16,
    /// The object (numeric: one or two registers, as the drive declares it).
    pub obj: Obj,
    /// [`Entry::view`] in bits 0-1, [`Entry::is_narrow`] bit 2, [`Entry::is_wide`] bit 3,
    /// [`Entry::is_clear`] bit 4.
    flags: u8,
    /// The map's unit against the drive's (a reference: the entries share their few scales).
    pub scale: &'static Scale,
}

/// [`Entry`]'s flags: one register for a 32-bit object.
const NARROW: u8 = 1 << 2;
/// [`Entry`]'s flags: two registers for a 16-bit object.
const WIDE: u8 = 1 << 3;
/// [`Entry`]'s flags: the bits of its view.
const VIEW: u8 = 3;
/// [`Entry`]'s flags: a write of 1 clears.
const CLEAR: u8 = 1 << 4;

impl Entry {
    /// `obj` at `addr`, in the map's unit `scale`, with the object's own access.
    pub const fn new(addr: u16, obj: Obj, scale: &'static Scale) -> Self {
        Self { addr, obj, flags: 0, scale }
    }

    /// The entry, one register wide: a 32-bit object whose values the map keeps within 16 bits
    /// (a value beyond them reads as the nearest 16-bit one: 0xFFFF, or for a signed object
    /// -32768 or 32767; a signed object's register is signed).
    pub const fn narrow(self) -> Self {
        Self { flags: self.flags | NARROW, ..self }
    }

    /// The entry, two registers wide: a 16-bit object that the map gives 32 bits.
    pub const fn wide(self) -> Self {
        Self { flags: self.flags | WIDE, ..self }
    }

    /// The entry, a clear: a write of 1 writes the drive's 0 (a counter's clear: seed 003's
    /// 0x2011), any other value is out of range; a read reads the object in the entry's scale.
    pub const fn clear(self) -> Self {
        Self { flags: self.flags | CLEAR, ..self }
    }

    /// Whether a write of 1 clears ([`Entry::clear`]).
    pub const fn is_clear(&self) -> bool {
        self.flags & CLEAR != 0
    }

    /// Whether the entry is one register for a 32-bit object ([`Entry::narrow`]).
    pub const fn is_narrow(&self) -> bool {
        self.flags & NARROW != 0
    }

    /// Whether the entry is two registers for a 16-bit object ([`Entry::wide`]).
    pub const fn is_wide(&self) -> bool {
        self.flags & WIDE != 0
    }

    /// What the map lets a master do with it.
    pub const fn view(&self) -> View {
        match self.flags & VIEW {
            1 => View::ReadOnly,
            2 => View::WriteOnly,
            _ => View::Declared,
        }
    }

    /// Its registers.
    pub fn words(&self) -> u32 {
        if self.is_narrow() {
            1
        } else if self.is_wide() {
            2
        } else {
            u32::from(self.obj.def().words())
        }
    }

    /// The register of a narrow entry whose map value is `v`.
    fn narrow_word(&self, v: u32) -> u16 {
        match self.obj.def().ty() {
            Type::S32 => (v as i32).clamp(i32::from(i16::MIN), i32::from(i16::MAX)) as i16 as u16,
            _ => v.min(0xFFFF) as u16,
        }
    }

    /// The entry, read only.
    pub const fn read_only(self) -> Self {
        Self { flags: (self.flags & !VIEW) | 1, ..self }
    }

    /// The entry, write only.
    pub const fn write_only(self) -> Self {
        Self { flags: (self.flags & !VIEW) | 2, ..self }
    }
}

/// The first register of each of `entries`, in their order: what [`compiled::table`] hashes.
#[allow(clippy::indexing_slicing)] // const evaluation: out of bounds is a compile error
pub const fn addresses<const N: usize>(entries: &[Entry; N]) -> [u16; N] {
    let mut addrs = [0u16; N];
    let mut i = 0;
    while i < N {
        addrs[i] = entries[i].addr;
        i += 1;
    }
    addrs
}

/// The compiled lookup's flags of each entry ([`compiled::Fast::flags`]).
#[allow(clippy::indexing_slicing)]
const fn fast_flags<const N: usize>(entries: &[Entry; N]) -> [u8; N] {
    let mut fast = [0u8; N];
    let mut i = 0;
    while i < N {
        let e = &entries[i];
        let d = &OBJECTS[e.obj as usize];
        let number = !matches!(d.ty(), Type::Str(_));
        let (linear, scale) = match *e.scale {
            Scale::One => (true, compiled::ONE),
            Scale::Ratio(..) => (true, compiled::RATIO),
            Scale::PerRev(..) => (true, compiled::PER_REV),
            Scale::Gear => (true, compiled::GEAR),
            _ => (false, compiled::ONE),
        };
        let words = if e.is_narrow() {
            1
        } else if e.is_wide() {
            2
        } else {
            d.words()
        };
        let mut f = scale;
        if words == 2 {
            f |= compiled::TWO;
        }
        if matches!(d.ty(), Type::S32) {
            f |= compiled::SIGNED;
        }
        if d.is_live() {
            f |= compiled::LIVE;
        }
        if e.is_narrow() {
            f |= compiled::NARROW;
        }
        let whole = !e.is_narrow() && !e.is_wide() && !e.is_clear();
        if number && linear && whole && !matches!(e.view(), View::WriteOnly) {
            f |= compiled::READ;
        }
        let interval = matches!(*d.range, Range::Any | Range::Span(..));
        if number
            && linear
            && interval
            && !e.is_clear()
            && !e.is_wide()
            && !matches!(e.view(), View::ReadOnly)
            && DriveState::<Shared>::plain(d)
        {
            f |= compiled::WRITE;
        }
        fast[i] = f;
        i += 1;
    }
    fast
}

/// What the plain paths need of each entry ([`compiled::Fast`]) of a layout that `walk`s them.
/// An entry's run: none from one that is not [`compiled::READ`], else its own registers and the
/// run of the entry a request walks on to (the next in the list, or the one that begins where it
/// ends), at most 255.
#[allow(clippy::indexing_slicing)]
pub const fn fast_entries<const N: usize>(entries: &[Entry; N], walk: Walk) -> [Fast; N] {
    let flags = fast_flags(entries);
    let mut fast = [Fast { addr: 0, obj: Obj::NodeId, flags: 0, run: 0 }; N];
    let mut i = N;
    while i > 0 {
        i -= 1;
        let mut run = 0;
        if flags[i] & compiled::READ != 0 {
            let words: u32 = if flags[i] & compiled::TWO != 0 { 2 } else { 1 };
            let on = i + 1 < N
                && match walk {
                    Walk::List => true,
                    Walk::Address => entries[i].addr as u32 + words == entries[i + 1].addr as u32,
                };
            let total = words + if on { fast[i + 1].run as u32 } else { 0 };
            run = if total > 255 { 255 } else { total as u8 };
        }
        fast[i] = Fast { addr: entries[i].addr, obj: entries[i].obj, flags: flags[i], run };
    }
    fast
}

/// A layout's [`Compiled`] lookup from its entries (a static array) and its [`Walk`], built
/// when compiling.
#[macro_export]
macro_rules! compiled {
    ($entries:path, $walk:expr) => {{
        const ADDRS: [u16; $entries.len()] = $crate::maps::layout::addresses(&$entries);
        const TABLE: (usize, u32) = $crate::maps::compiled::table(&ADDRS);
        static SLOTS: [u8; TABLE.0] = $crate::maps::compiled::slots::<{ TABLE.0 }>(&ADDRS, TABLE.1);
        static FAST: [$crate::maps::compiled::Fast; $entries.len()] =
            $crate::maps::layout::fast_entries(&$entries, $walk);
        $crate::maps::compiled::Compiled { mul: TABLE.1, slots: &SLOTS, fast: &FAST }
    }};
}

/// A register layout: its entries, how requests walk them, and the codes of its refusals.
#[derive(Clone, Copy, Debug)]
pub struct Layout {
    /// The objects: by increasing address for [`Walk::Address`], in the manual's list order for
    /// [`Walk::List`]; without overlaps.
    pub entries: &'static [Entry],
    /// The order of every 32-bit object's registers.
    pub order: WordOrder,
    /// The codes of the refusals.
    pub exceptions: Exceptions,
    /// How a multi-register request walks the entries.
    pub walk: Walk,
    /// Whether a 32-bit object may be written one half at a time (staged); if not, such a
    /// write is refused with [`Exceptions::split`].
    pub halves: bool,
    /// The exception codes of frames spoilt by their timing or CRC, where the map answers them.
    pub spoilt: SpoiltCodes,
    /// The map's factory settings where its manual's differ from the drive's: register values
    /// in the map's units, set after the drive's factory values (a drive with nothing saved, a
    /// factory reset).
    pub defaults: &'static [(u16, i32)],
    /// The program window, if the map has one (seed 002's multi-segment programs at 1024-1536,
    /// seed 004's position data groups at 0600h-06FFh): raw words the drive keeps as written, in
    /// its program memory.
    pub program: Option<ProgramWindow>,
    /// Registers that read 0 and refuse writes with [`Exceptions::unsupported`]: the manual's
    /// registers the drive has nothing for (each documented in the map's reference), as
    /// inclusive ranges.
    pub reserved: &'static [(u16, u16)],
    /// Requests that name a register by an index and a sub-index (seed 003), if the map's are
    /// such; `None`: Modbus's requests.
    pub sub_index: Option<&'static SubIndex>,
    /// The serial port's own address, which the drive answers to from power-up while the
    /// address source 0x21D1 is 0 (seed 003's, 1); `None`: the node id 0x2028 always.
    pub address: Option<u8>,
    /// Whether the scope's and the black box's registers are the native map's, at their native
    /// addresses ([`SCOPE_RANGES`]); a sub-indexed layout reaches them through its window.
    pub scope: bool,
    /// The lookup compiled from the entries ([`compiled!`](crate::compiled)), which the
    /// commonest requests take; `None`: every request walks the table.
    pub index: Option<&'static Compiled>,
}

/// The native map's scope and black box (0x2220-0x2240), firmware update and write lock
/// (0x2250-0x2261), and its capture windows (0x4000, 0xA000), as inclusive ranges: a
/// [`Layout::scope`] layout answers them as the native map does,
/// a request within one of them, in the layout's codes.
pub const SCOPE_RANGES: [(u16, u16); 3] = [
    (0x2220, 0x2261),
    (SCOPE_WINDOW, SCOPE_WINDOW + (WORDS - 1) as u16),
    (BLACK_BOX_WINDOW, BLACK_BOX_WINDOW + (WORDS - 1) as u16),
];

/// A map's window of raw program words.
#[derive(Clone, Copy, Debug)]
pub struct ProgramWindow {
    /// Its first register.
    pub first: u16,
    /// Its registers.
    pub words: u16,
    /// What it holds.
    pub kind: crate::state::ProgramKind,
    /// Whether a value may be word `k` of it (a value it refuses is out of range); `None`: any.
    pub check: Option<fn(usize, u16) -> bool>,
}

/// The exception codes a map answers a frame with that its timing or CRC spoilt, if the frame
/// began with this drive's address; `None` drops such a frame, as the Modbus serial line has it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SpoiltCodes {
    /// A silence over t1.5 inside the frame (seed 002: 0x0C), answered once the line has been
    /// quiet for t3.5.
    pub gap: Option<u8>,
    /// A frame that followed a whole one before t3.5 (seed 002: 0x0D).
    pub early: Option<u8>,
    /// A wrong CRC, answered while 0x21D2 asks for it (seed 003: 0x01).
    pub crc: Option<u8>,
}

impl SpoiltCodes {
    /// Every spoilt frame dropped.
    pub const DROPPED: Self = Self { gap: None, early: None, crc: None };
}

/// The values 0 and 1 as themselves: a map's switch over an object whose range is wider (the
/// feedback 0x2104, open or closed loop without the multi-turn encoder's 2: seed 002's 0217, seed
/// 003's 0x2019).
pub static ZERO_ONE: &[Choice] = &[Choice { lo: 0, hi: 0, drive: 0 }, Choice { lo: 1, hi: 1, drive: 1 }];

impl Layout {
    /// A layout walked by address that stages halves.
    pub const fn by_address(entries: &'static [Entry], order: WordOrder, exceptions: Exceptions) -> Self {
        Self {
            entries,
            order,
            exceptions,
            walk: Walk::Address,
            halves: true,
            spoilt: SpoiltCodes::DROPPED,
            defaults: &[],
            program: None,
            reserved: &[],
            sub_index: None,
            address: None,
            scope: false,
            index: None,
        }
    }

    /// The entries a request of `qty` registers from `addr` covers, each with the place of its
    /// first covered register in it (0 or 1) and how many of its registers are covered; `None`
    /// if a register has no entry.
    fn covered(&self, addr: u16, qty: u32, mut each: impl FnMut(&'static Entry, u32, u32)) -> Option<()> {
        let entries: &'static [Entry] = self.entries;
        let (mut i, mut k) = match self.walk {
            Walk::Address => {
                let i = entries.partition_point(|e| e.addr <= addr).checked_sub(1)?;
                (i, u32::from(addr) - u32::from(entries.get(i)?.addr))
            }
            Walk::List => (self.find(addr)?, 0),
        };
        let mut left = qty;
        let mut reg = u32::from(addr);
        while left > 0 {
            let e = entries.get(i)?;
            if self.walk == Walk::Address && u32::from(e.addr) + k != reg {
                return None;
            }
            let words = e.words();
            if k >= words {
                return None;
            }
            let n = (words - k).min(left);
            each(e, k, n);
            (left, reg, i, k) = (left - n, reg + n, i + 1, 0);
        }
        Some(())
    }

    /// The entry whose first register is `addr`: by the compiled lookup, or else a binary
    /// search over a layout in address order, a scan of a list.
    pub(super) fn find(&self, addr: u16) -> Option<usize> {
        if let Some(index) = self.index {
            return Self::find_compiled(index, addr).map(|(i, _)| i);
        }
        let entries = self.entries;
        let addr_of = |i: usize| entries.get(i).map_or(u16::MAX, |e| e.addr);
        let i = match self.walk {
            Walk::Address => entries.partition_point(|e| e.addr < addr),
            Walk::List => entries.iter().position(|e| e.addr == addr)?,
        };
        (addr_of(i) == addr).then_some(i)
    }

    /// [`Layout::find`] by the compiled lookup `index`, the layout's, with what it compiled
    /// of the entry.
    #[inline(always)]
    fn find_compiled(index: &Compiled, addr: u16) -> Option<(usize, &Fast)> {
        let i = index.candidate(addr)?;
        let fast = index.fast.get(i)?;
        (fast.addr == addr).then_some((i, fast))
    }

    /// The place in the program of `qty` registers from `addr`, if they are in its window;
    /// `Err` if they begin in it but run past its end.
    pub(super) fn in_program(&self, addr: u16, qty: usize) -> Option<Result<usize, ()>> {
        let window = self.program?;
        let k = usize::from(addr.checked_sub(window.first)?);
        let words = usize::from(window.words).min(crate::state::memory::WORDS);
        (k < words).then_some(())?;
        Some(if k + qty <= words { Ok(k) } else { Err(()) })
    }

    /// Whether `qty` registers from `addr` are all reserved ([`Layout::reserved`]); `Err` if
    /// they begin in a reserved range and run past it.
    pub(super) fn in_reserved(&self, addr: u16, qty: usize) -> Option<Result<(), ()>> {
        let &(_, last) = self.reserved.iter().find(|(first, last)| (*first..=*last).contains(&addr))?;
        Some(if usize::from(addr) + qty <= usize::from(last) + 1 { Ok(()) } else { Err(()) })
    }
}

/// The low `width` bits set.
const fn mask(width: u8) -> u32 {
    match 1u32.checked_shl(width as u32) {
        Some(b) => b - 1,
        None => u32::MAX,
    }
}

/// Whether register `k` (0 or 1) of a 32-bit object is its high half in `order`.
fn is_high<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(order: WordOrder, drive: &DriveState<P, G>, k: u32) -> bool {
    let high_first = match order {
        WordOrder::HighFirst => true,
        WordOrder::LowFirst => false,
        WordOrder::Setting => drive.read(Obj::MapWordOrder) == 0,
    };
    (k == 0) == high_first
}

/// The drive's raw value of the register bits `bits` of a [`compiled::WRITE`] entry `e` whose
/// compiled flags are `fast`, if the object takes it: what [`LayoutMap::drive_value`] and the
/// object's range check give these entries, by their flags, inlined into the plain write.
#[inline(always)]
fn plain_value<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
    drive: &DriveState<P, G>,
    e: &Fast,
    scale: Option<&Scale>,
    bits: u32,
) -> Option<u32> {
    let fast = e.flags;
    // The map's register is signed as the object is.
    let v = if fast & compiled::SIGNED == 0 {
        i64::from(bits)
    } else if fast & compiled::NARROW != 0 {
        i64::from(bits as u16 as i16)
    } else {
        i64::from(bits as i32)
    };
    let v = match (fast & compiled::SCALE, scale) {
        (compiled::ONE, _) => v,
        (compiled::GEAR, _) => {
            let (num, den) = gear(drive);
            div_round(v.saturating_mul(num), den)?
        }
        (_, None) => return None,
        (_, Some(&Scale::Ratio(n, den))) => div_round(v.checked_mul(i64::from(n))?, i64::from(den))?,
        (_, Some(&Scale::PerRev(n, den))) => {
            div_round(v.checked_mul(i64::from(n) * i64::from(drive.per_rev()))?, i64::from(den))?
        }
        _ => return None,
    };
    // A [`compiled::WRITE`] entry's object takes one interval of values, within its type.
    let d = e.obj.def();
    let (lo, hi) = match *d.range {
        Range::Span(lo, hi) => (i64::from(lo), i64::from(hi)),
        _ => (i64::MIN, i64::MAX),
    };
    let (type_lo, type_hi) = match d.ty() {
        Type::U8 => (0, i64::from(u8::MAX)),
        Type::U16 => (0, i64::from(u16::MAX)),
        Type::U32 => (0, i64::from(u32::MAX)),
        Type::S32 => (i64::from(i32::MIN), i64::from(i32::MAX)),
        Type::Str(_) => return None,
    };
    (v >= lo.max(type_lo) && v <= hi.min(type_hi)).then_some(v as u32)
}

/// The map's value now of a [`compiled::READ`] entry `e`, the layout's `entries[i]`, as
/// register bits: what [`LayoutMap::map_value`] gives these entries, by their flags.
#[inline(always)]
fn plain_map_value<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
    drive: &DriveState<P, G>,
    e: &Fast,
    entries: &[Entry],
    i: usize,
) -> u32 {
    let fast = e.flags;
    let raw = if fast & compiled::LIVE != 0 {
        drive.polled(e.obj)
    } else {
        drive.params.get(e.obj as usize).copied().unwrap_or(0)
    };
    if fast & compiled::SCALE == compiled::ONE {
        return raw;
    }
    let v = if fast & compiled::SIGNED != 0 { i64::from(raw as i32) } else { i64::from(raw) };
    // A drive value beyond the map's range reads as its low bits.
    let map = if fast & compiled::SCALE == compiled::GEAR {
        let (num, den) = gear(drive);
        div_round(v.saturating_mul(den), num)
    } else {
        match entries.get(i).map(|e| *e.scale) {
            Some(Scale::Ratio(n, den)) => v.checked_mul(i64::from(den)).and_then(|x| div_round(x, i64::from(n))),
            Some(Scale::PerRev(n, den)) => {
                v.checked_mul(i64::from(den)).and_then(|x| div_round(x, i64::from(n) * i64::from(drive.per_rev())))
            }
            _ => None,
        }
    };
    map.unwrap_or(v) as u32
}

/// The 32-bit value of a two-register write whose registers came as `first`, `second`.
fn joined<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
    order: WordOrder,
    drive: &DriveState<P, G>,
    first: u32,
    second: u32,
) -> u32 {
    if is_high(order, drive, 0) { first << 16 | second } else { second << 16 | first }
}

/// The position data groups' electronic gear (0x219B / 0x219C), both at least 1.
fn gear<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(drive: &DriveState<P, G>) -> (i64, i64) {
    (i64::from(drive.read(Obj::GearNumerator).max(1)), i64::from(drive.read(Obj::GearDenominator).max(1)))
}

/// The drive's raw value as a number: two's complement for a signed object.
const fn signed(d: &ObjectDef, raw: u32) -> i64 {
    match d.ty() {
        Type::S32 => raw as i32 as i64,
        _ => raw as i64,
    }
}

/// The map's number as the object's raw bits, if it fits the object's type.
fn raw_of(d: &ObjectDef, v: i64) -> Option<u32> {
    match d.ty() {
        Type::U8 => u8::try_from(v).ok().map(u32::from),
        Type::U16 => u16::try_from(v).ok().map(u32::from),
        Type::U32 => u32::try_from(v).ok(),
        Type::S32 => i32::try_from(v).ok().map(|v| v as u32),
        Type::Str(_) => None,
    }
}

/// A layout's map: the layout and the staged high halves, which the native map of a
/// [`Layout::sub_index`] layout's window shares (a half is the object's, whichever register
/// staged it).
#[derive(Clone, Debug)]
pub struct LayoutMap {
    layout: &'static Layout,
    native: NativeMap,
}

/// The most objects one write can reach (123 registers).
const MAX_OBJECTS: usize = 123;

impl LayoutMap {
    /// A map over `layout` with nothing staged.
    pub fn new(layout: &'static Layout) -> Self {
        Self { layout, native: NativeMap::new() }
    }

    /// The layout.
    pub fn layout(&self) -> &'static Layout {
        self.layout
    }

    fn staged(&self, obj: Obj) -> Option<u16> {
        self.native.staged(obj)
    }

    fn set_staged(&mut self, obj: Obj, v: Option<u16>) {
        self.native.set_staged(obj, v);
    }

    /// Whether `addr` is in the window onto the native map (a [`Layout::sub_index`] layout's,
    /// or a [`Layout::scope`] layout's scope registers).
    fn in_window(&self, addr: u16) -> bool {
        self.layout.sub_index.is_some_and(|s| addr >= s.keys.window)
            || (self.layout.scope && SCOPE_RANGES.iter().any(|&(lo, hi)| (lo..=hi).contains(&addr)))
    }

    /// The native map of the window, if `addr` is in it, and the codes its refusals take.
    pub(super) fn window(&self, addr: u16) -> Option<(&NativeMap, &'static Exceptions)> {
        self.in_window(addr).then_some((&self.native, &self.layout.exceptions))
    }

    /// [`LayoutMap::window`], to write through.
    pub(super) fn window_mut(&mut self, addr: u16) -> Option<(&mut NativeMap, &'static Exceptions)> {
        self.in_window(addr).then_some((&mut self.native, &self.layout.exceptions))
    }

    /// The map's value of `e` now, as register bits (32 at most).
    #[inline(always)]
    fn map_value<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(&self, drive: &DriveState<P, G>, e: &Entry) -> u32 {
        let d = e.obj.def();
        let raw = drive.read_def(d);
        let v = signed(d, raw);
        match *e.scale {
            // The same unit: the raw bits (what the conversion below gives, without it).
            Scale::One => raw,
            Scale::Field(shift, width) => raw.checked_shr(u32::from(shift)).unwrap_or(0) & mask(width),
            Scale::Gear => {
                let (num, den) = gear(drive);
                div_round(v.saturating_mul(den), num).unwrap_or(v) as u32
            }
            // A drive value beyond the map's range reads as its low bits.
            scale => scale.to_map(v, i64::from(drive.per_rev())).unwrap_or(v) as u32,
        }
    }

    /// The drive's raw value of the map's register bits `bits` for `e`.
    fn drive_value<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &DriveState<P, G>,
        e: &Entry,
        bits: u32,
    ) -> Result<u32, ObjError> {
        if e.is_clear() {
            return if bits == 1 { Ok(0) } else { Err(ObjError::OutOfRange) };
        }
        let d = e.obj.def();
        if let Scale::Field(shift, width) = *e.scale {
            let field = mask(width).checked_shl(u32::from(shift)).unwrap_or(0);
            if bits & !mask(width) != 0 {
                return Err(ObjError::OutOfRange);
            }
            let old = drive.read_def(d);
            return Ok(old & !field | bits.checked_shl(u32::from(shift)).unwrap_or(0));
        }
        // The map's register is signed as the object is.
        let v = match d.ty() {
            Type::S32 if e.is_narrow() => i64::from(bits as u16 as i16),
            _ => signed(d, bits),
        };
        let v = if *e.scale == Scale::Gear {
            let (num, den) = gear(drive);
            div_round(v.saturating_mul(num), den)
        } else {
            e.scale.to_drive(v, i64::from(drive.per_rev()))
        };
        raw_of(d, v.ok_or(ObjError::OutOfRange)?).ok_or(ObjError::OutOfRange)
    }

    /// Decodes a write into what it does to each object, or the first address error.
    fn plan<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &DriveState<P, G>,
        addr: u16,
        values: &Words<'_>,
        plan: &mut heapless::Vec<(&'static Entry, Op), MAX_OBJECTS>,
    ) -> Result<(), Exception> {
        let ex = self.layout.exceptions;
        let order = self.layout.order;
        let mut at = 0usize;
        let mut refused = None;
        let walked = self.layout.covered(addr, values.len() as u32, |e, k, n| {
            if refused.is_some() {
                return;
            }
            let d = e.obj.def();
            let mut word = || {
                at += 1;
                values.get(at - 1).map_or(0, u32::from)
            };
            let op = if d.access() == Access::Ro || e.view() == View::ReadOnly || matches!(d.ty(), Type::Str(_)) {
                Err(ex.read_only)
            } else if e.words() == 1 {
                Ok(Op::Commit(word()))
            } else if n == 2 {
                let (first, second) = (word(), word());
                Ok(Op::Commit(joined(order, drive, first, second)))
            } else if !self.layout.halves {
                Err(ex.split)
            } else if is_high(order, drive, k) {
                Ok(Op::Stage(word() as u16))
            } else {
                // The low half completes the staged high half, or the present one.
                let hi = match self.staged(e.obj) {
                    Some(hi) => u32::from(hi),
                    None => self.map_value(drive, e) >> 16,
                };
                Ok(Op::Commit(hi << 16 | word()))
            };
            match op {
                Ok(op) => {
                    if plan.push((e, op)).is_err() {
                        refused = Some(ex.unknown);
                    }
                }
                Err(x) => refused = Some(x),
            }
        });
        match (refused, walked) {
            (Some(x), _) => Err(x),
            (None, None) => Err(ex.unknown),
            (None, Some(())) => Ok(()),
        }
    }
}

impl LayoutMap {
    /// The commonest read, sealed as it is made: whole entries that the compiled lookup marks
    /// [`compiled::READ`], from the entry at `addr` on as the layout walks them, within its
    /// [`Fast::run`] (checked once). `None` for anything else (a text, a field,
    /// a table, a narrow or wide entry, part of an entry, a refusal, a layout without a compiled
    /// lookup), which the general walk answers. (No entry lies in a window, the program or a
    /// reserved range: a test checks each layout.)
    #[inline(never)]
    pub(super) fn read_plain<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &DriveState<P, G>,
        addr: u16,
        out: &mut [u8],
        mut crc: u16,
    ) -> Option<u16> {
        let layout = self.layout;
        let index = layout.index?;
        let (mut i, first) = Layout::find_compiled(index, addr)?;
        // Every register asked for is in the entries' plain run from the first.
        if out.len() / 2 > usize::from(first.run) {
            return None;
        }
        let put = |w: u32, slot: &mut [u8; 2], crc: &mut u16| {
            let [hi, lo] = (w as u16).to_be_bytes();
            *slot = [hi, lo];
            *crc = crate::crc::update(crate::crc::update(*crc, hi), lo);
        };
        let mut slots = out.as_chunks_mut::<2>().0;
        while let Some((slot, rest)) = slots.split_first_mut() {
            let e = index.fast.get(i)?;
            let v = plain_map_value(drive, e, layout.entries, i);
            if e.flags & compiled::TWO == 0 {
                put(v, slot, &mut crc);
                slots = rest;
            } else {
                let (next, rest) = rest.split_first_mut()?;
                let (first, second) = if is_high(layout.order, drive, 0) { (v >> 16, v) } else { (v, v >> 16) };
                put(first, slot, &mut crc);
                put(second, next, &mut crc);
                slots = rest;
            }
            i += 1;
        }
        Some(crc)
    }

    /// The commonest write: one whole entry that the compiled lookup marks [`compiled::WRITE`]
    /// (a plain setting, [`DriveState::plain`]: any value in its range is taken and stored,
    /// whatever the drive does), its value converted and checked, then stored. `None` (nothing
    /// changed) for anything else or a value refused, which the general path answers.
    #[inline(always)]
    pub(super) fn write_plain<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &mut self,
        drive: &mut DriveState<P, G>,
        addr: u16,
        values: &Words<'_>,
    ) -> Option<()> {
        let layout = self.layout;
        let index = layout.index?;
        let (i, e) = Layout::find_compiled(index, addr)?;
        if e.flags & compiled::WRITE == 0 {
            return None;
        }
        let bits = match (e.flags & compiled::TWO != 0, values.len()) {
            (false, 1) => u32::from(values.get(0)?),
            (true, 2) => joined(layout.order, drive, u32::from(values.get(0)?), u32::from(values.get(1)?)),
            _ => return None,
        };
        let v = plain_value(drive, e, layout.entries.get(i).map(|e| e.scale), bits)?;
        *drive.params.get_mut(e.obj as usize)? = v;
        self.set_staged(e.obj, None);
        Some(())
    }
}

impl LayoutMap {
    /// A write that [`LayoutMap::write_plain`] did not take: the program window, the reserved
    /// registers, and the table walked. Out of line: its plan (123 objects at most) is on the
    /// stack for a layout's writes only, not under every write of the maps it is a variant of.
    #[inline(never)]
    pub(super) fn write_walked<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &mut self,
        drive: &mut DriveState<P, G>,
        addr: u16,
        values: Words<'_>,
    ) -> Result<(), Exception> {
        let ex = self.layout.exceptions;
        if let Some(window) = self.layout.in_program(addr, values.len()) {
            let k = window.map_err(|()| ex.unknown)?;
            if let Some(check) = self.layout.program.and_then(|p| p.check) {
                let bad = values.iter().enumerate().any(|(j, v)| !check(k + j, v));
                if bad {
                    return Err(ex.out_of_range);
                }
            }
            return drive.write_program(k, &values).map_err(|x| ex.of(x));
        }
        if let Some(reserved) = self.layout.in_reserved(addr, values.len()) {
            reserved.map_err(|()| ex.unknown)?;
            return Err(ex.unsupported);
        }
        let mut plan = heapless::Vec::new();
        self.plan(drive, addr, &values, &mut plan)?;
        if let [(e, Op::Commit(bits))] = plan.as_slice() {
            // One object: its own write is all or nothing, no checkpoint needed.
            let v = self.drive_value(drive, e, *bits).map_err(|x| ex.of(x))?;
            drive.write_def(e.obj.def(), v).map_err(|x| ex.of(x))?;
            self.set_staged(e.obj, None);
            return Ok(());
        }
        // Each value in the drive's unit as the writes before it left the drive (a scale may
        // depend on an object written earlier in the request).
        drive
            .write_in_order(&plan, |drive, &(e, op)| match op {
                Op::Commit(bits) => self.drive_value(drive, e, bits).map(|v| Some((e.obj.def(), v))),
                Op::Stage(_) => Ok(None),
            })
            .map_err(|e| ex.of(e))?;
        for &(e, op) in &plan {
            self.set_staged(e.obj, if let Op::Stage(hi) = op { Some(hi) } else { None });
        }
        Ok(())
    }
}

impl RegisterMap for LayoutMap {
    #[inline(always)]
    fn read_sealing<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &DriveState<P, G>,
        addr: u16,
        out: &mut [u8],
        crc: u16,
    ) -> Result<u16, Exception> {
        if let Some(crc) = self.read_plain(drive, addr, out, crc) {
            return Ok(crc);
        }
        self.read(drive, addr, out)?;
        Ok(crate::crc::update_bytes(crc, out))
    }

    fn read<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &DriveState<P, G>,
        addr: u16,
        out: &mut [u8],
    ) -> Result<(), Exception> {
        let ex = self.layout.exceptions;
        let order = self.layout.order;
        let qty = (out.len() / 2) as u32;
        if let Some(window) = self.layout.in_program(addr, qty as usize) {
            let k = window.map_err(|()| ex.unknown)?;
            for (j, slot) in out.chunks_exact_mut(2).enumerate() {
                slot.copy_from_slice(&drive.program_word(k + j).to_be_bytes());
            }
            return Ok(());
        }
        if let Some(reserved) = self.layout.in_reserved(addr, qty as usize) {
            reserved.map_err(|()| ex.unknown)?;
            out.fill(0);
            return Ok(());
        }
        let mut slots = out.chunks_exact_mut(2);
        let mut refused = None;
        let walked = self.layout.covered(addr, qty, |e, k, n| {
            if e.view() == View::WriteOnly {
                refused = refused.or(Some(ex.write_only));
            }
            let d = e.obj.def();
            let v = self.map_value(drive, e);
            for j in k..k + n {
                let w = match d.ty() {
                    Type::Str(_) => drive.text_word(e.obj, j as usize),
                    _ if e.is_narrow() => e.narrow_word(v),
                    _ if d.words() == 1 && !e.is_wide() => v as u16,
                    _ if is_high(order, drive, j) => (v >> 16) as u16,
                    _ => v as u16,
                };
                if let Some(slot) = slots.next() {
                    slot.copy_from_slice(&w.to_be_bytes());
                }
            }
        });
        match (refused, walked) {
            (Some(x), _) => Err(x),
            (None, None) => Err(ex.unknown),
            (None, Some(())) => Ok(()),
        }
    }

    fn check_read(&self, addr: u16, qty: u16) -> Result<(), Exception> {
        let ex = self.layout.exceptions;
        if let Some(window) = self.layout.in_program(addr, usize::from(qty)) {
            return window.map(|_| ()).map_err(|()| ex.unknown);
        }
        if let Some(reserved) = self.layout.in_reserved(addr, usize::from(qty)) {
            return reserved.map_err(|()| ex.unknown);
        }
        let mut refused = None;
        let walked = self.layout.covered(addr, u32::from(qty), |e, _, _| {
            if e.view() == View::WriteOnly {
                refused = refused.or(Some(ex.write_only));
            }
        });
        match (refused, walked) {
            (Some(x), _) => Err(x),
            (None, None) => Err(ex.unknown),
            (None, Some(())) => Ok(()),
        }
    }

    fn write<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &mut self,
        drive: &mut DriveState<P, G>,
        addr: u16,
        values: Words<'_>,
    ) -> Result<(), Exception> {
        if self.write_plain(drive, addr, &values).is_some() {
            return Ok(());
        }
        self.write_walked(drive, addr, values)
    }

    fn request_exception(&self, e: Exception) -> Exception {
        let ex = &self.layout.exceptions;
        match e {
            Exception::IllegalFunction => ex.function,
            Exception::ByteCount => ex.byte_count,
            // Seed 003's codes mean other things than Modbus's.
            e if self.layout.sub_index.is_some() => ex.native(e),
            e => e,
        }
    }

    fn program_kind(&self) -> crate::state::ProgramKind {
        self.layout.program.map_or(crate::state::ProgramKind::None, |p| p.kind)
    }

    fn sub_index(&self) -> Option<SubIndex> {
        self.layout.sub_index.copied()
    }

    fn address_extra(&self) -> usize {
        usize::from(self.layout.sub_index.is_some())
    }

    fn spoilt_frame<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &DriveState<P, G>,
        spoilt: Spoilt,
    ) -> Option<u8> {
        let codes = self.layout.spoilt;
        match spoilt {
            Spoilt::Gap => codes.gap,
            Spoilt::Early => codes.early,
            Spoilt::Crc => codes.crc.filter(|_| drive.read(Obj::CrcErrorReply) == 1),
        }
    }

    fn fixed_address(&self) -> Option<u8> {
        self.layout.address
    }

    fn factory_settings<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(&self, drive: &mut DriveState<P, G>) {
        for &(addr, value) in self.layout.defaults {
            let Some(e) = self.layout.entries.iter().find(|e| e.addr == addr) else { continue };
            // A default the drive does not take (a unit it cannot convert) leaves its own.
            if let Ok(raw) = self.drive_value(drive, e, value as u32) {
                drive.set_factory_value(e.obj, raw);
            }
        }
    }
}
