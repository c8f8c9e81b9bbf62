//! Register → object lookup in constant time, built when compiling from [`OBJECTS`].
//!
//! Registers are grouped in pages (the high byte of the address). Each page spans from its first
//! object to the end of its last; every register of that span knows the index of the object at or
//! after it. Reserved registers between objects thus lead to the next object.

use crate::od::{OBJECTS, Obj, Storage, Type};

/// One page's span of registers.
#[derive(Clone, Copy)]
struct Page {
    first: u32,
    end: u32,
    offset: usize,
}

// Const evaluation runs when compiling: an index out of bounds there is a compile error.
#[allow(clippy::indexing_slicing)]
const fn new_page(i: usize) -> bool {
    i == 0 || OBJECTS[i].addr >> 8 != OBJECTS[i - 1].addr >> 8
}

const N_PAGES: usize = {
    let mut n = 0;
    let mut i = 0;
    while i < OBJECTS.len() {
        if new_page(i) {
            n += 1;
        }
        i += 1;
    }
    n
};

#[allow(clippy::indexing_slicing)]
const PAGES: [Page; N_PAGES] = {
    let mut pages = [Page { first: 0, end: 0, offset: 0 }; N_PAGES];
    let (mut p, mut i, mut offset) = (0, 0, 0);
    while i < OBJECTS.len() {
        if new_page(i) {
            if p > 0 {
                offset += (pages[p - 1].end - pages[p - 1].first) as usize;
            }
            pages[p] = Page { first: OBJECTS[i].addr as u32, end: 0, offset };
            p += 1;
        }
        // Objects do not straddle pages.
        assert!((OBJECTS[i].end() - 1) >> 8 == (OBJECTS[i].addr >> 8) as u32);
        pages[p - 1].end = OBJECTS[i].end();
        i += 1;
    }
    pages
};

/// The page of each high address byte, as an index in [`PAGES`]; `N_PAGES` where there is none.
/// A table rather than a search: one load finds the page.
#[allow(clippy::indexing_slicing)]
static PAGE_OF: [u8; 256] = {
    assert!(N_PAGES < 256);
    let mut of = [N_PAGES as u8; 256];
    let mut p = 0;
    while p < N_PAGES {
        of[(PAGES[p].first >> 8) as usize] = p as u8;
        p += 1;
    }
    of
};

#[allow(clippy::indexing_slicing)]
const SPAN: usize = {
    let last = PAGES[N_PAGES - 1];
    last.offset + (last.end - last.first) as usize
};

/// The high half of an [`INDEX`] entry whose register a read takes from the drive state (a
/// live object, a text), not from a stored value; the low half is then the object's index
/// ([`OTHER_OBJ`]), the register's place in the object from bit [`OTHER_WORD`], [`OTHER_TEXT`]
/// for a text, [`OTHER_HIGH`] for a 32-bit object's high word: what the read needs, without
/// the object's declaration.
pub(crate) const OTHER: u16 = u16::MAX;
/// The object's index in an [`OTHER`] entry.
pub(crate) const OTHER_OBJ: u32 = 0x1FF;
/// The shift of the register's place in the object in an [`OTHER`] entry (4 bits: a text has
/// at most 8 registers).
pub(crate) const OTHER_WORD: u32 = 9;
/// An [`OTHER`] entry's flag: a text.
pub(crate) const OTHER_TEXT: u32 = 1 << 13;
/// An [`OTHER`] entry's flag: a 32-bit object's high word.
pub(crate) const OTHER_HIGH: u32 = 1 << 14;

/// Every register of every page's span. A read takes a register from the stored value of object
/// `e >> 16` shifted right by `e as u16` (0 or 16 for the low or high word; 32, giving 0, for a
/// reserved register, whose high half is the object after it), unless the high half is
/// [`OTHER`]. So reads cost one entry per register, and an out-of-range index is the only branch.
/// (The shift in the low byte is where x86's shift instruction takes its count.)
#[allow(clippy::indexing_slicing)]
static INDEX: [u32; SPAN] = {
    assert!(OBJECTS.len() <= OTHER_OBJ as usize);
    let mut index = [0u32; SPAN];
    let mut p = 0;
    let mut i = 0;
    while p < N_PAGES {
        let page = PAGES[p];
        let mut reg = page.first;
        while reg < page.end {
            while OBJECTS[i].end() <= reg {
                i += 1;
            }
            let d = &OBJECTS[i];
            let stored = matches!(d.storage(), Storage::Ram | Storage::Rom);
            let entry = match d.ty() {
                // Reserved registers, and the password, which is not told: its value shifted out.
                _ if d.addr as u32 > reg || matches!(d.obj, Obj::Password) => ((i as u32) << 16) | 32,
                Type::U8 | Type::U16 if stored => (i as u32) << 16,
                // High word first.
                Type::U32 | Type::S32 if stored => ((i as u32) << 16) | ((d.addr as u32 + 1 - reg) * 16),
                _ => {
                    let k = reg - d.addr as u32;
                    assert!(k < 16);
                    let flags = match d.ty() {
                        Type::Str(_) => OTHER_TEXT,
                        Type::U32 | Type::S32 if k == 0 => OTHER_HIGH,
                        _ => 0,
                    };
                    ((OTHER as u32) << 16) | flags | (k << OTHER_WORD) | i as u32
                }
            };
            index[page.offset + (reg - page.first) as usize] = entry;
            reg += 1;
        }
        p += 1;
    }
    index
};

/// The [`INDEX`] entries of `qty` registers from `addr`, if they lie in one page's span.
#[inline(always)]
pub(crate) fn registers(addr: u16, qty: u16) -> Option<&'static [u32]> {
    let page = PAGE_OF.get(usize::from(addr >> 8)).and_then(|&p| PAGES.get(usize::from(p)))?;
    let (addr, end) = (u32::from(addr), u32::from(addr) + u32::from(qty));
    if addr < page.first || end > page.end {
        return None;
    }
    let at = page.offset + (addr - page.first) as usize;
    INDEX.get(at..at + (end - addr) as usize)
}

/// For `qty` registers from `addr` that lie in one page's span, the index in [`OBJECTS`] of the
/// object at or after `addr`.
///
/// ```
/// use drive_core::maps::index::locate;
/// use drive_core::od::OBJECTS;
/// let i = locate(0x6003, 2).unwrap();
/// assert_eq!(OBJECTS[i].addr, 0x6003);
/// assert_eq!(OBJECTS[locate(0x6012, 1).unwrap()].addr, 0x6013); // reserved: the next object
/// assert_eq!(locate(0x6000, 0x8C), None); // past the page's last object
/// assert_eq!(locate(0x0000, 1), None);
/// ```
#[inline(always)]
pub fn locate(addr: u16, qty: u16) -> Option<usize> {
    let e = *registers(addr, qty)?.first()?;
    Some((if (e >> 16) as u16 == OTHER { e & OTHER_OBJ } else { e >> 16 }) as usize)
}
