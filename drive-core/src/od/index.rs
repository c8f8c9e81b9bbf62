//! Register → object lookup in constant time, built when compiling from [`OBJECTS`].
//!
//! Registers are grouped in pages (the high byte of the address). Each page spans from its first
//! object to the end of its last; every register of that span knows the index of the object at or
//! after it. Reserved registers between objects thus lead to the next object.

use super::OBJECTS;

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

#[allow(clippy::indexing_slicing)]
const SPAN: usize = {
    let last = PAGES[N_PAGES - 1];
    last.offset + (last.end - last.first) as usize
};

#[allow(clippy::indexing_slicing)]
static INDEX: [u8; SPAN] = {
    assert!(OBJECTS.len() < 256);
    let mut index = [0u8; SPAN];
    let mut p = 0;
    let mut i = 0;
    while p < N_PAGES {
        let page = PAGES[p];
        let mut reg = page.first;
        while reg < page.end {
            while OBJECTS[i].end() <= reg {
                i += 1;
            }
            index[page.offset + (reg - page.first) as usize] = i as u8;
            reg += 1;
        }
        p += 1;
    }
    index
};

/// For `qty` registers from `addr` that lie in one page's span, the index in [`OBJECTS`] of the
/// object at or after `addr`.
///
/// ```
/// use drive_core::od::{index::locate, OBJECTS};
/// let i = locate(0x6003, 2).unwrap();
/// assert_eq!(OBJECTS[i].addr, 0x6003);
/// assert_eq!(OBJECTS[locate(0x6012, 1).unwrap()].addr, 0x6013); // reserved: the next object
/// assert_eq!(locate(0x6000, 0x8C), None); // past the page's last object
/// assert_eq!(locate(0x0000, 1), None);
/// ```
pub fn locate(addr: u16, qty: u16) -> Option<usize> {
    let (addr, end) = (u32::from(addr), u32::from(addr) + u32::from(qty));
    let page = PAGES.iter().find(|p| p.first >> 8 == addr >> 8)?;
    if addr < page.first || end > page.end {
        return None;
    }
    INDEX.get(page.offset + (addr - page.first) as usize).map(|&i| usize::from(i))
}
