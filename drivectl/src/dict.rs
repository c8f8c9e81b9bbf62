//! The registers of each map by name: built from the drive's own tables (the objects'
//! declarations and each compatibility map's layout), so that a name means what the drive serves.

use drive_core::maps::layout::{Layout, View, WordOrder};
use drive_core::maps::{Maps, NAMES, RegisterMap, cls9, doc, ec57, jmc};
use drive_core::od::{Access, OBJECTS, Obj, ObjectDef, Storage, Type};

/// A register map the drive can answer with (0x2190).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Map {
    /// The native map (seed 000).
    Native,
    /// JMC's CiA 402 drives (seed 001).
    Jmc,
    /// DS-CLS9 closed-loop steppers (seed 002).
    Cls9,
    /// The EC-57's sub-indexed serial port (seed 003).
    Ec57,
}

impl Map {
    /// Every map, by its number in 0x2190.
    pub const ALL: [Map; 4] = [Map::Native, Map::Jmc, Map::Cls9, Map::Ec57];

    /// Its name (`native`, `jmc`, `cls9`, `ec57`), as `hal-sim --map` takes it.
    pub fn name(self) -> &'static str {
        NAMES.get(self as usize).copied().unwrap_or("native")
    }

    /// The map named `name`.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }

    /// The map a drive answers with, from its device identification's application name
    /// (0x2B object 6): each compatibility map names itself there.
    pub fn from_application_name(name: &str) -> Self {
        Self::ALL
            .into_iter()
            .find(|m| Maps::by_id(*m as u32).application_name().is_some_and(|n| n == name))
            .unwrap_or(Map::Native)
    }

    /// The layout of a compatibility map.
    pub fn layout(self) -> Option<&'static Layout> {
        match self {
            Map::Native => None,
            Map::Jmc => Some(&jmc::LAYOUT),
            Map::Cls9 => Some(&cls9::LAYOUT),
            Map::Ec57 => Some(&ec57::LAYOUT),
        }
    }

    /// Whether requests carry a sub-index after the register (seed 003).
    pub fn sub_indexed(self) -> bool {
        self.layout().is_some_and(|l| l.sub_index.is_some())
    }
}

/// Where a register sits in a map.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Address {
    /// The register (seed 003: the index).
    pub register: u16,
    /// Seed 003's sub-index (0xFF: the native register `register`, through the map's window).
    pub sub: Option<u8>,
}

impl std::fmt::Display for Address {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.sub {
            Some(sub) => write!(f, "0x{:04X}.{sub}", self.register),
            None => write!(f, "0x{:04X}", self.register),
        }
    }
}

/// One register (or a pair, or a text) of a map, named after the drive object behind it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Register {
    /// Its name on the command line: the object's, in kebab case (`max-speed`); a second entry of
    /// the same object in one map gets `@` and its address.
    pub name: String,
    /// The drive object behind it.
    pub obj: Obj,
    /// Where it is.
    pub at: Address,
    /// Registers it spans.
    pub words: u16,
    /// Whether its value is signed (a 32-bit signed object).
    pub signed: bool,
    /// Whether it is ASCII text.
    pub text: bool,
    /// Whether a read is served.
    pub readable: bool,
    /// Whether a write is served (commands and write-1-to-clear bits included).
    pub writable: bool,
    /// Whether it is a setting the drive keeps once saved, which `dump` and `load` carry.
    pub saved: bool,
    /// Its unit in this map.
    pub unit: &'static str,
    /// The object's short description.
    pub about: &'static str,
}

/// Every register of a map, by name and address.
#[derive(Clone, Debug)]
pub struct Dictionary {
    /// The map.
    pub map: Map,
    /// Its registers in the map's order.
    pub registers: Vec<Register>,
}

/// `MaxSpeed` → `max-speed`.
fn kebab(obj: Obj) -> String {
    let mut out = String::new();
    for (i, c) in format!("{obj:?}").chars().enumerate() {
        if c.is_ascii_uppercase() {
            if i > 0 {
                out.push('-');
            }
            out.push(c.to_ascii_lowercase());
        } else {
            out.push(c);
        }
    }
    out
}

/// Object `d` at its native register (seed 003's window: with sub-index `sub`, where its
/// settings are not `dump`'s: the map's own registers carry those).
fn native(d: &ObjectDef, sub: Option<u8>) -> Register {
    Register {
        name: kebab(d.obj),
        obj: d.obj,
        at: Address { register: d.addr, sub },
        words: d.words(),
        signed: d.ty() == Type::S32,
        text: matches!(d.ty(), Type::Str(_)),
        readable: true,
        writable: d.access() != Access::Ro,
        saved: sub.is_none() && d.storage() == Storage::Rom && d.access() == Access::Rw,
        unit: d.unit.symbol(),
        about: d.name,
    }
}

impl Dictionary {
    /// The registers of `map`.
    pub fn of(map: Map) -> Self {
        let mut registers: Vec<Register> = Vec::new();
        match map.layout() {
            None => registers.extend(OBJECTS.iter().map(|d| native(d, None))),
            Some(layout) => {
                for e in layout.entries {
                    let d = e.obj.def();
                    let at = match layout.sub_index {
                        Some(s) => {
                            let (register, sub) = (s.index_of)(e.addr);
                            Address { register, sub: Some(sub) }
                        }
                        None => Address { register: e.addr, sub: None },
                    };
                    let writable = e.view() != View::ReadOnly && d.access() != Access::Ro;
                    let name = match registers.iter().any(|r| r.obj == e.obj) {
                        true => format!("{}@{at}", kebab(e.obj)),
                        false => kebab(e.obj),
                    };
                    registers.push(Register {
                        name,
                        obj: e.obj,
                        at,
                        words: e.words() as u16,
                        signed: d.ty() == Type::S32,
                        text: false,
                        readable: e.view() != View::WriteOnly,
                        writable,
                        saved: writable && d.storage() == Storage::Rom && d.access() == Access::Rw,
                        unit: doc::unit(e),
                        about: d.name,
                    });
                }
                // Seed 003's window: every other native object at its native register, sub-index
                // 0xFF (motion, the map switch 0x2190).
                if layout.sub_index.is_some() {
                    for d in OBJECTS.iter() {
                        if registers.iter().any(|r| r.obj == d.obj) {
                            continue;
                        }
                        registers.push(native(d, Some(0xFF)));
                    }
                }
            }
        }
        Self { map, registers }
    }

    /// The register named `key`, or at the address `key` (`0x6003`, `24579`, seed 003's
    /// `0x2003.1`).
    pub fn find(&self, key: &str) -> Option<&Register> {
        if let Some(r) = self.registers.iter().find(|r| r.name == key) {
            return Some(r);
        }
        let at = parse_address(key)?;
        self.registers
            .iter()
            .find(|r| r.at == at || (at.sub.is_none() && r.at.sub.is_none() && r.at.register == at.register))
    }

    /// The register of object `obj` (its first entry).
    pub fn of_object(&self, obj: Obj) -> Option<&Register> {
        self.registers.iter().find(|r| r.obj == obj)
    }

    /// Whether two-register values are low word first, given the map's word-order setting
    /// (0x2191's value) where the map makes it one.
    pub fn low_first(&self, setting: u16) -> bool {
        match self.map.layout().map(|l| l.order) {
            Some(WordOrder::LowFirst) => true,
            Some(WordOrder::Setting) => setting == 1,
            _ => false,
        }
    }
}

/// An address on the command line: decimal, `0x` hexadecimal, with seed 003's `.sub-index`.
pub fn parse_address(key: &str) -> Option<Address> {
    let (register, sub) = match key.split_once('.') {
        Some((r, s)) => (r, Some(parse_int(s)?)),
        None => (key, None),
    };
    let register = u16::try_from(parse_int(register)?).ok()?;
    let sub = match sub {
        Some(s) => Some(u8::try_from(s).ok()?),
        None => None,
    };
    Some(Address { register, sub })
}

/// A whole number, decimal or `0x` hexadecimal, signed.
pub fn parse_int(s: &str) -> Option<i64> {
    let (neg, digits) = match s.strip_prefix('-') {
        Some(rest) => (true, rest),
        None => (false, s),
    };
    let v = match digits.strip_prefix("0x").or_else(|| digits.strip_prefix("0X")) {
        Some(hex) => i64::from_str_radix(hex, 16).ok()?,
        None => digits.parse::<i64>().ok()?,
    };
    Some(if neg { -v } else { v })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_and_addresses_find_the_same_register() {
        let native = Dictionary::of(Map::Native);
        let r = native.find("max-speed").expect("named");
        assert_eq!((r.at.register, r.words, r.signed, r.unit), (0x6003, 2, true, "pps"));
        assert_eq!(native.find("0x6003"), Some(r));
        assert_eq!(native.find("24579"), Some(r));
        assert!(native.find("no-such-thing").is_none());
    }

    #[test]
    fn every_map_names_each_register_once() {
        for map in Map::ALL {
            let d = Dictionary::of(map);
            let mut names: Vec<_> = d.registers.iter().map(|r| &r.name).collect();
            names.sort();
            let n = names.len();
            names.dedup();
            assert_eq!(names.len(), n, "{map:?}");
        }
    }

    #[test]
    fn the_ec57_map_reaches_native_objects_through_its_window() {
        let d = Dictionary::of(Map::Ec57);
        let own = d.find("0x2005.0").expect("pulses a revolution");
        assert_eq!(own.unit, "pulse/rev");
        let map = d.find("register-map").expect("through the window");
        assert_eq!(map.at, Address { register: 0x2190, sub: Some(0xFF) });
    }

    #[test]
    fn a_map_is_known_by_its_application_name() {
        for map in Map::ALL {
            let name = Maps::by_id(map as u32).application_name().unwrap_or("drive-core");
            assert_eq!(Map::from_application_name(name), map);
        }
    }
}
