//! Register maps: how a master's registers reach the drive's objects. [`native`] is the drive's
//! own map (seed 000), indexed at compile time; [`layout`] serves any other map from a table of
//! addresses, word orders, scales and exception codes over the same objects.

#[macro_use]
pub mod layout;
pub mod cls9;
pub mod compiled;
#[cfg(feature = "docs")]
pub mod doc;
pub mod ec57;
pub mod exceptions;
pub mod index;
pub mod jmc;
pub mod native;
pub mod servo;

use crate::pdu::{Exception, SubIndex, Words};
use crate::state::Shared;
use crate::state::{DriveState, ProgramMemory};
use core::borrow::Borrow;
use layout::LayoutMap;
pub use native::{NativeMap, RegisterMap, Spoilt};

/// The maps' names, by their number in the register map object 0x2190.
pub const NAMES: [&str; 5] = ["native", "jmc", "cls9", "ec57", "servo"];

/// The map the drive answers with: the native one or a layout, as 0x2190 chose at power-up.
#[derive(Clone, Debug)]
pub enum Maps {
    /// The native map (seed 000).
    Native(NativeMap),
    /// A compatibility map, from its layout.
    Layout(LayoutMap),
}

impl Maps {
    /// The map of 0x2190's value `id` (an unknown one is the native map). Out of line: inlined
    /// into a microcontroller's power-up, each map's value would have a place in its frame, the
    /// deepest of the stack.
    #[inline(never)]
    pub fn by_id(id: u32) -> Self {
        match id {
            1 => Self::jmc(),
            2 => Self::cls9(),
            3 => Self::ec57(),
            4 => Self::servo(),
            _ => Self::Native(NativeMap::new()),
        }
    }

    /// Whether the map of 0x2190's value `id` has a program window (seed 002's multi-segment
    /// programs, seed 004's position data groups), without building it: where power-up loads
    /// the program before the drive exists.
    pub const fn has_program_id(id: u32) -> bool {
        id == 2 || id == 4
    }

    /// The map named `name` ([`NAMES`]), if there is one.
    pub fn by_name(name: &str) -> Option<Self> {
        NAMES.iter().position(|n| *n == name).map(|id| Self::by_id(id as u32))
    }

    /// The JMC map (seed 001).
    pub fn jmc() -> Self {
        Self::Layout(LayoutMap::new(&jmc::LAYOUT))
    }

    /// The DS-CLS9 map (seed 002).
    pub fn cls9() -> Self {
        Self::Layout(LayoutMap::new(&cls9::LAYOUT))
    }

    /// The EC-57 map (seed 003).
    pub fn ec57() -> Self {
        Self::Layout(LayoutMap::new(&ec57::LAYOUT))
    }

    /// The servo map (seed 004).
    pub fn servo() -> Self {
        Self::Layout(LayoutMap::new(&servo::LAYOUT))
    }
}

impl RegisterMap for Maps {
    // Each map's code has one call site, so that it is inlined once: the native map's serves
    // the native map and a sub-indexed layout's window.
    fn read<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &DriveState<P, G>,
        addr: u16,
        out: &mut [u8],
    ) -> Result<(), Exception> {
        // One call site of each map's read: the CRC run, unused, is left out by the compiler.
        self.read_sealing(drive, addr, out, crate::crc::INIT).map(|_| ())
    }

    #[inline(always)]
    fn read_sealing<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &DriveState<P, G>,
        addr: u16,
        out: &mut [u8],
        crc: u16,
    ) -> Result<u16, Exception> {
        let (native, codes) = match self {
            Self::Native(m) => (m, None),
            Self::Layout(m) => {
                // The commonest reads first: their entries lie outside the window.
                if let Some(crc) = m.read_plain(drive, addr, out, crc) {
                    return Ok(crc);
                }
                match m.window(addr) {
                    Some((w, codes)) => (w, Some(codes)),
                    None => {
                        m.read(drive, addr, out)?;
                        return Ok(crate::crc::update_bytes(crc, out));
                    }
                }
            }
        };
        native.read_sealing(drive, addr, out, crc).map_err(|e| codes.map_or(e, |c| c.native(e)))
    }

    fn check_read(&self, addr: u16, qty: u16) -> Result<(), Exception> {
        let (native, codes) = match self {
            Self::Native(m) => (m, None),
            Self::Layout(m) => match m.window(addr) {
                Some((w, codes)) => (w, Some(codes)),
                None => return m.check_read(addr, qty),
            },
        };
        native.check_read(addr, qty).map_err(|e| codes.map_or(e, |c| c.native(e)))
    }

    fn write<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &mut self,
        drive: &mut DriveState<P, G>,
        addr: u16,
        values: Words<'_>,
    ) -> Result<(), Exception> {
        let (native, codes) = match self {
            Self::Native(m) => (m, None),
            Self::Layout(m) => {
                // The commonest writes first: their entries lie outside the window.
                if m.write_plain(drive, addr, &values).is_some() {
                    return Ok(());
                }
                if m.window(addr).is_none() {
                    return m.write_walked(drive, addr, values);
                }
                match m.window_mut(addr) {
                    Some((w, codes)) => (w, Some(codes)),
                    None => return Err(Exception::IllegalDataAddress),
                }
            }
        };
        native.write(drive, addr, values).map_err(|e| codes.map_or(e, |c| c.native(e)))
    }

    fn request_exception(&self, e: Exception) -> Exception {
        match self {
            Self::Native(m) => m.request_exception(e),
            Self::Layout(m) => m.request_exception(e),
        }
    }

    fn starts_disabled(&self) -> bool {
        // CiA 402's state machine powers up switch on disabled, and a servo with its servo-on
        // off; the others energise as the native map does.
        matches!(self, Self::Layout(m) if core::ptr::eq(m.layout(), &jmc::LAYOUT) || core::ptr::eq(m.layout(), &servo::LAYOUT))
    }

    fn program_kind(&self) -> crate::state::ProgramKind {
        match self {
            Self::Native(m) => m.program_kind(),
            Self::Layout(m) => m.program_kind(),
        }
    }

    fn factory_settings<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(&self, drive: &mut DriveState<P, G>) {
        if let Self::Layout(m) = self {
            m.factory_settings(drive);
        }
    }

    fn application_name(&self) -> Option<&'static str> {
        match self {
            Self::Native(_) => None,
            Self::Layout(m) if core::ptr::eq(m.layout(), &jmc::LAYOUT) => Some("drive-core, JMC map (seed 001)"),
            Self::Layout(m) if core::ptr::eq(m.layout(), &cls9::LAYOUT) => Some("drive-core, DS-CLS9 map (seed 002)"),
            Self::Layout(m) if core::ptr::eq(m.layout(), &ec57::LAYOUT) => Some("drive-core, EC-57 map (seed 003)"),
            Self::Layout(m) if core::ptr::eq(m.layout(), &servo::LAYOUT) => Some("drive-core, servo map (seed 004)"),
            Self::Layout(_) => Some("drive-core, layout map"),
        }
    }

    fn sub_index(&self) -> Option<SubIndex> {
        match self {
            Self::Native(m) => m.sub_index(),
            Self::Layout(m) => m.sub_index(),
        }
    }

    fn address_extra(&self) -> usize {
        match self {
            Self::Native(m) => m.address_extra(),
            Self::Layout(m) => m.address_extra(),
        }
    }

    fn spoilt_frame<P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &DriveState<P, G>,
        spoilt: Spoilt,
    ) -> Option<u8> {
        match self {
            Self::Native(m) => m.spoilt_frame(drive, spoilt),
            Self::Layout(m) => m.spoilt_frame(drive, spoilt),
        }
    }

    fn is_native(&self, addr: u16) -> bool {
        match self {
            Self::Native(_) => true,
            Self::Layout(m) => m.window(addr).is_some(),
        }
    }

    fn fixed_address(&self) -> Option<u8> {
        match self {
            Self::Native(m) => m.fixed_address(),
            Self::Layout(m) => m.fixed_address(),
        }
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]
    use super::layout::{Layout, LayoutMap, SCOPE_RANGES, Walk};
    use super::{Maps, NAMES, RegisterMap, compiled};
    use crate::od::Obj;
    use crate::pdu::Words;
    use crate::state::DriveState;

    /// Every map's layout, by its name.
    fn layouts() -> impl Iterator<Item = &'static Layout> {
        let layouts = NAMES.iter().filter_map(|name| match Maps::by_name(name) {
            Some(Maps::Layout(m)) => Some(m.layout()),
            _ => None,
        });
        let all: heapless::Vec<&'static Layout, 8> = layouts.collect();
        assert_eq!(all.len(), NAMES.len() - 1);
        all.into_iter()
    }

    /// A drive whose settings hold arbitrary bits (the plain paths and the walk must agree on
    /// any), with a sane resolution and gear.
    fn scrambled() -> DriveState {
        let mut drive = DriveState::new(&crate::ident::Identity::SIMULATOR, false);
        for (i, p) in drive.params.iter_mut().enumerate() {
            *p = (i as u32 + 1).wrapping_mul(2_654_435_761) >> (i % 17);
        }
        drive.params[Obj::Microsteps as usize] = 16;
        drive.params[Obj::GearNumerator as usize] = 3;
        drive.params[Obj::GearDenominator as usize] = 7;
        drive.params[Obj::MapWordOrder as usize] = 1;
        drive
    }

    /// Each map's table is the smallest, and every entry has a slot of its own in it.
    #[test]
    fn every_entry_has_a_slot_of_its_own() {
        for layout in layouts() {
            let index = layout.index.unwrap();
            assert_eq!(index.slots.len(), (2 * layout.entries.len()).next_power_of_two());
            assert_eq!(index.slots.iter().filter(|&&s| s != 0).count(), layout.entries.len());
        }
    }

    #[test]
    fn the_lookup_finds_every_entry_and_nothing_else() {
        for layout in layouts() {
            assert!(layout.index.is_some());
            for addr in 0..=u16::MAX {
                assert_eq!(layout.find(addr), layout.entries.iter().position(|e| e.addr == addr), "{addr:#06x}");
            }
        }
    }

    /// What lets the plain paths go first: no entry begins in a window onto the native map, the
    /// program or a reserved range.
    #[test]
    fn no_entry_lies_in_a_window_the_program_or_a_reserved_range() {
        for layout in layouts() {
            let map = LayoutMap::new(layout);
            for e in layout.entries {
                assert!(map.window(e.addr).is_none(), "{:#06x}", e.addr);
                assert!(layout.in_program(e.addr, 1).is_none(), "{:#06x}", e.addr);
                assert!(layout.in_reserved(e.addr, 1).is_none(), "{:#06x}", e.addr);
                let in_scope = SCOPE_RANGES.iter().any(|&(lo, hi)| (lo..=hi).contains(&e.addr));
                assert!(!(layout.scope && in_scope), "{:#06x}", e.addr);
            }
        }
    }

    /// Whether a read of `qty` registers from entry `i` takes whole entries that the compiled
    /// lookup marks [`compiled::READ`], one after the other as the layout's walk goes on.
    fn plain_entries(layout: &Layout, i: usize, qty: usize) -> bool {
        let fast = layout.index.unwrap().fast;
        let flags = |j: usize| fast[j].flags;
        let mut n = 0;
        for (j, e) in layout.entries.iter().enumerate().skip(i) {
            if n >= qty {
                break;
            }
            let gap = layout.walk == Walk::Address && usize::from(e.addr) != usize::from(layout.entries[i].addr) + n;
            if flags(j) & compiled::READ == 0 || gap {
                return false;
            }
            n += if flags(j) & compiled::TWO != 0 { 2 } else { 1 };
        }
        n == qty
    }

    /// The plain read gives the walk's registers and their CRC wherever it answers, and it
    /// answers exactly the reads of whole plain entries that the walk takes one after the other
    /// ([`compiled::Compiled::run`]).
    #[test]
    fn the_plain_read_reads_as_the_walk() {
        let drive = scrambled();
        for layout in layouts() {
            let map = LayoutMap::new(layout);
            for (i, e) in layout.entries.iter().enumerate() {
                for qty in 1..=6 {
                    let (mut plain, mut walked) = ([0u8; 12], [0u8; 12]);
                    let (plain, walked) = (&mut plain[..2 * qty], &mut walked[..2 * qty]);
                    let answer = map.read_plain(&drive, e.addr, plain, 0x1234);
                    assert_eq!(answer.is_some(), plain_entries(layout, i, qty), "{:#06x} {qty}", e.addr);
                    let Some(crc) = answer else { continue };
                    assert_eq!(map.read(&drive, e.addr, walked), Ok(()), "{:#06x} {qty}", e.addr);
                    assert_eq!(plain, walked, "{:#06x} {qty}", e.addr);
                    assert_eq!(crc, crate::crc::update_bytes(0x1234, walked));
                }
            }
        }
    }

    /// The plain write changes what the walk's write changes wherever it answers, and nothing
    /// where it does not; it answers every value the walk takes for an entry it marks.
    #[test]
    fn the_plain_write_writes_as_the_walk() {
        let drive = scrambled();
        let values: [u16; 8] = [0, 1, 2, 100, 0x7FFF, 0x8000, 0xFFFF, 12_345];
        for layout in layouts() {
            let mut answered = 0;
            let fast = layout.index.unwrap().fast;
            for (e, flags) in layout.entries.iter().zip(fast.iter().map(|f| f.flags)) {
                let two = flags & compiled::TWO != 0;
                for &a in &values {
                    for &b in &values[..if two { values.len() } else { 1 }] {
                        let bytes = [(a >> 8) as u8, a as u8, (b >> 8) as u8, b as u8];
                        let words = Words::new(&bytes[..if two { 4 } else { 2 }]);
                        let (mut plain, mut walked) = (drive.clone(), drive.clone());
                        let answer = LayoutMap::new(layout).write_plain(&mut plain, e.addr, &words);
                        if flags & compiled::WRITE == 0 {
                            // (The walk is not run here: these settings hold bits out of their
                            // objects' ranges, which a write with an effect would act on.)
                            assert!(answer.is_none(), "{:#06x}", e.addr);
                            assert_eq!(plain.params, drive.params, "{:#06x}", e.addr);
                            continue;
                        }
                        let taken = LayoutMap::new(layout).write_walked(&mut walked, e.addr, words);
                        if answer.is_none() {
                            assert_eq!(plain.params, drive.params, "{:#06x}", e.addr);
                            assert!(taken.is_err(), "{:#06x} {a} {b}: not taken", e.addr);
                            continue;
                        }
                        answered += 1;
                        assert_eq!(taken, Ok(()), "{:#06x} {a} {b}", e.addr);
                        assert_eq!(plain.params, walked.params, "{:#06x} {a} {b}", e.addr);
                    }
                }
            }
            assert!(answered > 0);
        }
    }
}
