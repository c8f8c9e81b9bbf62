//! Register maps: how a master's registers reach the drive's objects. [`native`] is the drive's
//! own map (seed 000), indexed at compile time; [`layout`] serves any other map from a table of
//! addresses, word orders, scales and exception codes over the same objects.

pub mod cls9;
#[cfg(feature = "docs")]
pub mod doc;
pub mod ec57;
pub mod exceptions;
pub mod index;
pub mod jmc;
pub mod layout;
pub mod native;
pub mod servo;

use crate::pdu::{Exception, Parser, Words};
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
            Self::Layout(m) => match m.window(addr) {
                Some((w, codes)) => (w, Some(codes)),
                None => return m.read_sealing(drive, addr, out, crc),
            },
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
                if m.window(addr).is_none() {
                    return m.write(drive, addr, values);
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

    fn parser(&self) -> Option<Parser> {
        match self {
            Self::Native(m) => m.parser(),
            Self::Layout(m) => m.parser(),
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
