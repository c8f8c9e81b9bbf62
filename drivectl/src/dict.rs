//! The registers of each map by name: built from the drive's own tables (the objects'
//! declarations and each compatibility map's layout), so that a name means what the drive serves.

use drive_core::maps::layout::{Entry, Layout, ProgramWindow, Scale, View, WordOrder};
use drive_core::maps::{Maps, NAMES, RegisterMap, cls9, doc, ec57, jmc, servo};
use drive_core::od::{Access, OBJECTS, Obj, ObjectDef, Storage, Type};
use drive_core::state::ProgramKind;
use drive_core::state::groups::{GROUP_WORDS, GROUPS};

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
    /// A servo drive's Modbus chapter (seed 004): parameters P□abc at abc, position data groups.
    Servo,
}

impl Map {
    /// Every map, by its number in 0x2190.
    pub const ALL: [Map; 5] = [Map::Native, Map::Jmc, Map::Cls9, Map::Ec57, Map::Servo];

    /// Its name (`native`, `jmc`, `cls9`, `ec57`, `servo`), as `hal-sim --map` takes it.
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
            Map::Servo => Some(&servo::LAYOUT),
        }
    }

    /// What the map's reference says of the reserved range that starts at `first`.
    fn remark(self, first: u16) -> Option<&'static str> {
        let reference = match self {
            Map::Native => return None,
            Map::Jmc => &jmc::REFERENCE,
            Map::Cls9 => &cls9::REFERENCE,
            Map::Ec57 => &ec57::REFERENCE,
            Map::Servo => &servo::REFERENCE,
        };
        reference.remarks.iter().find(|(a, _)| *a == first).map(|(_, t)| *t)
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
    /// the same object in one map gets `@` and its address; a position data group's word
    /// `groupN.FIELD`.
    pub name: String,
    /// The drive object behind it; `None` for a raw word of a map's program window (seed 004's
    /// position data groups).
    pub obj: Option<Obj>,
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
    /// Whether it holds the object's value as the drive does (its unit, all its values and
    /// bits): where a command's drive value goes (0x200F = 2 saves).
    pub plain: bool,
    /// Its unit in this map.
    pub unit: &'static str,
    /// The object's short description.
    pub about: &'static str,
}

/// A range of registers a map reserves: the drive has nothing there (they read 0 and refuse
/// writes).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Reserved {
    /// The first register.
    pub first: u16,
    /// The last register.
    pub last: u16,
    /// What the map's reference says of it.
    pub about: &'static str,
}

/// Every register of a map, by name and address.
#[derive(Clone, Debug)]
pub struct Dictionary {
    /// The map.
    pub map: Map,
    /// Its registers in the map's order.
    pub registers: Vec<Register>,
    /// The ranges it reserves, by address.
    pub reserved: Vec<Reserved>,
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
        obj: Some(d.obj),
        at: Address { register: d.addr, sub },
        words: d.words(),
        signed: d.ty() == Type::S32,
        text: matches!(d.ty(), Type::Str(_)),
        readable: true,
        writable: d.access() != Access::Ro,
        saved: sub.is_none() && d.storage() == Storage::Rom && d.access() == Access::Rw,
        plain: true,
        unit: d.unit.symbol(),
        about: d.name,
    }
}

/// Whether entry `e` carries its object's whole value as a number, in some unit: not an
/// enumeration of some of its values (seed 004's 0520h, 1 clears the history, is 0x200F = 5),
/// a field of its bits or their inversion. Of several entries of one object, the first such one
/// is the object's register by name (seed 004's save is 0x200F, not 0520h).
fn whole(e: &Entry) -> bool {
    !matches!(e.scale, Scale::Table(_) | Scale::Field(..) | Scale::Invert(_))
}

/// The words of a position data group (seed 004 §6.4, drive-core's `state::groups`): offset,
/// name, registers, signed, unit, meaning.
const GROUP_FIELDS: [(u16, &str, u16, bool, &str, &str); 7] = [
    (0, "target", 2, true, "group unit", "position data group: target"),
    (2, "speed", 1, false, "r/min", "position data group: speed"),
    (3, "attribute", 1, false, "", "position data group: step-change conditions"),
    (4, "condition-1", 1, false, "", "position data group: condition 1's value"),
    (5, "condition-2", 1, false, "", "position data group: condition 2's value"),
    (6, "next", 1, false, "", "position data group: the next group"),
    (7, "type", 1, false, "", "position data group: 0 none, 1 absolute, 2 relative"),
];

// The table above follows drive-core's group of eight words.
const _: () = assert!(GROUP_WORDS == 8);

/// The registers of a position data groups' window: `groupN.FIELD`, raw words (the group's own
/// units), saved with the parameters.
fn groups(window: &ProgramWindow) -> impl Iterator<Item = Register> + '_ {
    (0..u16::from(GROUPS)).filter(|g| (g + 1) * GROUP_WORDS as u16 <= window.words).flat_map(move |g| {
        GROUP_FIELDS.iter().map(move |&(offset, field, words, signed, unit, about)| Register {
            name: format!("group{g}.{field}"),
            obj: None,
            at: Address { register: window.first + g * GROUP_WORDS as u16 + offset, sub: None },
            words,
            signed,
            text: false,
            readable: true,
            writable: true,
            saved: true,
            plain: false,
            unit,
            about,
        })
    })
}

impl Dictionary {
    /// The registers of `map`.
    pub fn of(map: Map) -> Self {
        let mut registers: Vec<Register> = Vec::new();
        let mut reserved = Vec::new();
        match map.layout() {
            None => registers.extend(OBJECTS.iter().map(|d| native(d, None))),
            Some(layout) => {
                let named = |obj: Obj| {
                    let mut of = layout.entries.iter().enumerate().filter(|(_, e)| e.obj == obj);
                    of.clone().find(|(_, e)| whole(e)).or_else(|| of.next()).map(|(i, _)| i)
                };
                for (i, e) in layout.entries.iter().enumerate() {
                    let d = e.obj.def();
                    let at = match layout.sub_index {
                        Some(s) => {
                            let (register, sub) = s.keys.index_of(e.addr);
                            Address { register, sub: Some(sub) }
                        }
                        None => Address { register: e.addr, sub: None },
                    };
                    let writable = e.view() != View::ReadOnly && d.access() != Access::Ro;
                    let name = match named(e.obj) == Some(i) {
                        true => kebab(e.obj),
                        false => format!("{}@{at}", kebab(e.obj)),
                    };
                    registers.push(Register {
                        name,
                        obj: Some(e.obj),
                        at,
                        words: e.words() as u16,
                        signed: d.ty() == Type::S32,
                        text: false,
                        readable: e.view() != View::WriteOnly,
                        writable,
                        saved: writable && d.storage() == Storage::Rom && d.access() == Access::Rw,
                        plain: *e.scale == Scale::One && !e.is_narrow() && !e.is_wide(),
                        unit: doc::unit(e),
                        about: d.name,
                    });
                }
                // Seed 003's window: every other native object at its native register, sub-index
                // 0xFF (motion, the map switch 0x2190).
                if layout.sub_index.is_some() {
                    for d in OBJECTS.iter() {
                        if registers.iter().any(|r| r.obj == Some(d.obj)) {
                            continue;
                        }
                        registers.push(native(d, Some(0xFF)));
                    }
                }
                // The scope and the black box, the native map's registers in these maps, in
                // address order among theirs.
                if layout.scope {
                    let in_scope = |d: &&drive_core::od::ObjectDef| {
                        drive_core::maps::layout::SCOPE_RANGES.iter().any(|&(lo, hi)| (lo..=hi).contains(&d.addr))
                    };
                    let at = registers.iter().position(|r| r.at.register > 0x2220).unwrap_or(registers.len());
                    registers.splice(at..at, OBJECTS.iter().filter(in_scope).map(|d| native(d, None)));
                }
                // Seed 004's position data groups, among the registers in address order.
                if let Some(window) = layout.program.filter(|p| p.kind == ProgramKind::Groups) {
                    let at = registers.iter().position(|r| r.at.register > window.first).unwrap_or(registers.len());
                    registers.splice(at..at, groups(&window));
                }
                reserved.extend(layout.reserved.iter().map(|&(first, last)| Reserved {
                    first,
                    last,
                    about: map.remark(first).unwrap_or("reserved: the drive has nothing for it"),
                }));
            }
        }
        Self { map, registers, reserved }
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

    /// The reserved range the address `key` is in, if it is one.
    pub fn reserved_at(&self, key: &str) -> Option<Reserved> {
        let at = parse_address(key).filter(|a| a.sub.is_none())?;
        self.reserved.iter().find(|r| (r.first..=r.last).contains(&at.register)).copied()
    }

    /// The register of object `obj`: the one named after it (of several entries, the one that
    /// carries its whole value).
    pub fn of_object(&self, obj: Obj) -> Option<&Register> {
        let name = kebab(obj);
        self.registers.iter().find(|r| r.obj == Some(obj) && r.name == name)
    }

    /// The register that holds object `obj`'s value as the drive does ([`Register::plain`]),
    /// where a command writes the drive's value: an entry of the map, or in seed 003's window
    /// the native register (sub-index 0xFF) where the map's own entries for it are
    /// enumerations (0x2030's 1 saves, 0x201D's 1 clears the history: 0x200F = 2, 5).
    pub fn plain(&self, obj: Obj) -> Option<Register> {
        if let Some(r) = self.registers.iter().find(|r| r.obj == Some(obj) && r.plain) {
            return Some(r.clone());
        }
        self.map.layout()?.sub_index?;
        let mut r = native(obj.def(), Some(0xFF));
        r.name = format!("{}@{}", r.name, r.at);
        Some(r)
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
    fn the_servo_map_names_its_registers_in_its_units() {
        let d = Dictionary::of(Map::Servo);
        assert_eq!(Map::from_name("servo"), Some(Map::Servo));
        assert_eq!(Map::from_application_name("drive-core, servo map (seed 004)"), Map::Servo);
        assert!(d.low_first(0), "low word first");
        let jog = d.find("jog-speed").expect("P304");
        assert_eq!((jog.at.register, jog.words, jog.unit, jog.saved), (0x0130, 1, "r/min", true));
        assert_eq!(d.find("304"), Some(jog), "P□304 by its register number");
        let accel = d.find("pp-accel").expect("05F5h");
        assert_eq!((accel.at.register, accel.words, accel.unit), (0x05F5, 1, "10 r/min/s"));
        assert_eq!(d.find("pp-accel@0x6067").map(|r| (r.words, r.unit)), Some((2, "pps²")));
        assert_eq!(d.find("pulse-rate").map(|r| r.unit), Some("kHz"));
        assert_eq!(d.find("actual-position@0x05F2").map(|r| (r.unit, r.signed)), Some(("group unit", true)));
        // The save is 0x200F; 0520h-0540h (1 clears, restores) are the object's other entries.
        assert_eq!(d.of_object(Obj::SystemControl).map(|r| r.at.register), Some(0x200F));
        assert_eq!(d.find("system-control@0x0540").map(|r| r.at.register), Some(0x0540));
    }

    #[test]
    fn the_servo_groups_are_named_raw_words() {
        let d = Dictionary::of(Map::Servo);
        let target = d.find("group3.target").expect("named");
        assert_eq!((target.at.register, target.words, target.signed, target.obj), (0x0618, 2, true, None));
        assert!(target.saved && target.writable);
        assert_eq!(d.find("0x0618"), Some(target));
        assert_eq!(d.find("group31.type").map(|r| r.at.register), Some(0x06FF));
        assert!(d.find("group32.type").is_none());
        let groups = d.registers.iter().filter(|r| r.name.starts_with("group") && r.obj.is_none()).count();
        assert_eq!(groups, 32 * 7);
        // In address order among the map's registers.
        let at: Vec<u16> = d.registers.iter().map(|r| r.at.register).collect();
        assert!(at.windows(2).all(|w| w[0] < w[1]), "{at:04X?}");
    }

    #[test]
    fn reserved_ranges_are_known() {
        let d = Dictionary::of(Map::Servo);
        assert!(d.find("0x0005").is_none());
        let r = d.reserved_at("0x0005").expect("reserved");
        assert_eq!(r.first, 0x0000);
        assert!(d.reserved_at("0x0130").is_none());
        assert!(Dictionary::of(Map::Native).reserved_at("0x0005").is_none());
    }

    #[test]
    fn a_save_is_the_system_control_in_every_map() {
        for map in Map::ALL {
            let d = Dictionary::of(map);
            let r = d.plain(Obj::SystemControl).expect("every map saves");
            assert_eq!(r.at.register, 0x200F, "{map:?}");
            assert_eq!(r.at.sub, map.sub_indexed().then_some(0xFF), "{map:?}");
        }
        assert!(Dictionary::of(Map::Servo).plain(Obj::MotionCommand).is_none());
    }

    #[test]
    fn a_map_is_known_by_its_application_name() {
        for map in Map::ALL {
            let name = Maps::by_id(map as u32).application_name().unwrap_or("drive-core");
            assert_eq!(Map::from_application_name(name), map);
        }
    }
}
