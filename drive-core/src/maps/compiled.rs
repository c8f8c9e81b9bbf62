//! A layout's lookup, compiled from its entries when compiling (the `compiled!` macro of
//! [`layout`](super::layout)): the entry that begins at a register in one probe, and for each
//! entry what the request path's shortcuts need to know of it, so that the commonest requests do
//! not walk the table or match on the entry's flags, scale and object.
//!
//! The lookup is a perfect hash table of the entries' first registers: a multiplier chosen when
//! compiling gives each entry a slot of its own, which holds its index plus one (0: none). A
//! map's registers are few and scattered over pages (a few dozen in JMC's 0x60xx, seed 003's
//! keys): a table a register, as the native map's, would be mostly empty.

use crate::od::Obj;

/// The most entries a layout may have (a slot is a byte: an entry's index plus one).
pub const MAX_ENTRIES: usize = 127;

/// [`Compiled::fast`]'s flag: the entry is read by the layout map's plain read (a number, whole,
/// in a linear scale, readable).
pub const READ: u8 = 1;
/// [`Compiled::fast`]'s flag: the entry is written by the plain write (a plain setting of the
/// drive whose values are one interval, in a linear scale, writable, not a clear or wide).
pub const WRITE: u8 = 2;
/// [`Compiled::fast`]'s flag: the entry has two registers.
pub const TWO: u8 = 4;
/// [`Compiled::fast`]'s bits: the entry's linear scale, [`ONE`], [`RATIO`], [`PER_REV`] or
/// [`GEAR`] (any for an entry that is neither [`READ`] nor [`WRITE`]).
pub const SCALE: u8 = 3 << 3;
/// [`SCALE`]: the same unit.
pub const ONE: u8 = 0;
/// [`SCALE`]: a ratio.
pub const RATIO: u8 = 1 << 3;
/// [`SCALE`]: per revolution of the motor.
pub const PER_REV: u8 = 2 << 3;
/// [`SCALE`]: the position data groups' electronic gear.
pub const GEAR: u8 = 3 << 3;
/// [`Compiled::fast`]'s flag: the object is signed (S32).
pub const SIGNED: u8 = 1 << 5;
/// [`Compiled::fast`]'s flag: the object's value is the drive's running state (live).
pub const LIVE: u8 = 1 << 6;
/// [`Compiled::fast`]'s flag: one register for a 32-bit object (narrow).
pub const NARROW: u8 = 1 << 7;

/// A layout's compiled lookup.
#[derive(Clone, Copy, Debug)]
pub struct Compiled {
    /// The hash's multiplier ([`table`]).
    pub mul: u32,
    /// The hash table: a power of two of slots.
    pub slots: &'static [u8],
    /// Per entry, what the plain paths need of it.
    pub fast: &'static [Fast],
}

/// What the plain read and write need of an entry, in one place: they touch nothing else of
/// it but a scale other than [`ONE`] or [`GEAR`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fast {
    /// The entry's first register.
    pub addr: u16,
    /// Its object.
    pub obj: Obj,
    /// Its flags: [`READ`], [`WRITE`], [`TWO`], [`SCALE`], [`SIGNED`], [`LIVE`], [`NARROW`].
    pub flags: u8,
    /// The registers a plain read may take from it on: its own and those of the [`READ`]
    /// entries a request walks on to, without a gap (0 if it is not [`READ`]), at most 255.
    pub run: u8,
}

/// The slot a register hashes to in a table of `len` (a power of two) slots.
#[inline(always)]
const fn hash(addr: u16, mul: u32, len: usize) -> usize {
    ((addr as u32).wrapping_mul(mul) >> 16) as usize & (len - 1)
}

impl Compiled {
    /// The index of the only entry that may begin at `addr` (the caller compares its address).
    #[inline(always)]
    pub fn candidate(&self, addr: u16) -> Option<usize> {
        let slot = *self.slots.get(hash(addr, self.mul, self.slots.len()))?;
        usize::from(slot).checked_sub(1)
    }
}

/// Whether `mul` gives each of `addrs` a slot of its own in a table of `n` slots.
#[allow(clippy::indexing_slicing)] // const evaluation: out of bounds is a compile error
const fn perfect(addrs: &[u16], mul: u32, n: usize) -> bool {
    let mut taken = [false; 8 * MAX_ENTRIES + 8];
    let mut i = 0;
    while i < addrs.len() {
        let at = hash(addrs[i], mul, n);
        if taken[at] {
            return false;
        }
        taken[at] = true;
        i += 1;
    }
    true
}

/// The size and multiplier of the table for the registers `addrs` (all different): the
/// smallest power of two of at least twice as many slots, up to 8 times, for which one of a few
/// thousand odd multipliers from 2^32 / φ gives each register a slot of its own. (Each map's is
/// found in the smallest table.)
pub const fn table(addrs: &[u16]) -> (usize, u32) {
    assert!(addrs.len() <= MAX_ENTRIES);
    let mut n = (2 * addrs.len()).next_power_of_two();
    while n <= (8 * addrs.len()).next_power_of_two() {
        let mut k = 0u32;
        while k < 4096 {
            let mul = 0x9E37_79B1u32.wrapping_add(k.wrapping_mul(0x2545_F492));
            if perfect(addrs, mul, n) {
                return (n, mul);
            }
            k += 1;
        }
        n *= 2;
    }
    // None found (two entries begin at one register?): [`slots`] refuses to compile it.
    (n, 0)
}

/// The hash table of `addrs` with `mul` (`N` and `mul` from [`table`]).
#[allow(clippy::indexing_slicing)]
pub const fn slots<const N: usize>(addrs: &[u16], mul: u32) -> [u8; N] {
    assert!(perfect(addrs, mul, N));
    let mut slots = [0u8; N];
    let mut i = 0;
    while i < addrs.len() {
        slots[hash(addrs[i], mul, N)] = (i + 1) as u8;
        i += 1;
    }
    slots
}
