//! The object dictionary: every object of the drive declared once, with everything that the
//! dispatch, the range checks, the defaults, persistence and the register reference need.
//!
//! [`native`] is the drive's own map (seed 000, MSME/PMC007). A register map of another vendor is
//! another table over the same [`Obj`]ects, with its own addresses, units and exception codes.

#[cfg(feature = "docs")]
pub mod doc;
mod effects;
pub mod native;

pub(crate) use effects::{has_effect, is_command, is_pvt_command, is_signal};
pub use native::{OBJECTS, Obj};

/// The current loop's objects a power-up tune writes and the loop is built from at power-up:
/// R (0x2108), L (0x2109), KP (0x210C), KI (0x210D), in the order of
/// `windings::LoopObjects::words`.
pub const CURRENT_LOOP_OBJECTS: [Obj; 4] = [Obj::MotorResistance, Obj::MotorInductance, Obj::CurrentKp, Obj::CurrentKi];

/// How an object's value is encoded in registers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Type {
    /// Unsigned 8 bit, one register.
    U8,
    /// Unsigned 16 bit, one register.
    U16,
    /// Unsigned 32 bit, two registers, high word at the lower address.
    U32,
    /// Signed 32 bit, two registers, high word at the lower address.
    S32,
    /// ASCII text of this many bytes (even), two per register, first byte high, zero padded.
    Str(u8),
}

impl Type {
    /// Registers the object occupies.
    #[inline]
    pub const fn words(self) -> u16 {
        match self {
            Type::U8 | Type::U16 => 1,
            Type::U32 | Type::S32 => 2,
            Type::Str(n) => n.div_ceil(2) as u16,
        }
    }
    /// Name in the register reference.
    pub const fn name(self) -> &'static str {
        match self {
            Type::U8 => "U8",
            Type::U16 => "U16",
            Type::U32 => "U32",
            Type::S32 => "S32",
            Type::Str(_) => "string",
        }
    }
    /// Whether a raw register value fits the type (strings are never written).
    const fn fits(self, raw: u32) -> bool {
        match self {
            Type::U8 => raw <= 0xFF,
            Type::U16 => raw <= 0xFFFF,
            Type::U32 | Type::S32 => true,
            Type::Str(_) => false,
        }
    }
}

/// Who may do what with an object over the bus.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Access {
    /// Read only: a write is refused.
    Ro,
    /// Read and write.
    Rw,
    /// Writing runs a command (a completed write is the command); reading returns the last value.
    Cmd,
    /// Status bits: writing 1 to a bit clears it, writing 0 leaves it.
    W1c,
}

impl Access {
    /// Name in the register reference.
    pub const fn name(self) -> &'static str {
        match self {
            Access::Ro => "ro",
            Access::Rw => "rw",
            Access::Cmd => "cmd",
            Access::W1c => "w1c",
        }
    }
}

/// Where the value lives (seed 000's storage column).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Storage {
    /// Lost at power-off; starts at its default.
    Ram,
    /// Kept across power cycles once saved (0x200F = 2).
    Rom,
    /// Part of the drive's running state (position, status): read from it, not from a stored copy.
    Live,
    /// A constant of the firmware (identification strings).
    Const,
}

impl Storage {
    /// Name in the register reference.
    pub const fn name(self) -> &'static str {
        match self {
            Storage::Ram => "RAM",
            Storage::Rom => "ROM",
            Storage::Live => "live",
            Storage::Const => "const",
        }
    }
}

/// The values an object accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Range {
    /// Anything the type holds.
    Any,
    /// `min..=max`, compared as signed for S32 objects (an unsigned object's bounds are within
    /// `i32`: its values above are out of range).
    Span(i32, i32),
    /// One of these values.
    Set(&'static [u32]),
    /// Only these bits may be set.
    Bits(u32),
    /// Signed value whose magnitude is within `min..=max` (zero excluded when `min > 0`).
    Magnitude(u32, u32),
}

impl Range {
    /// Whether `raw` (as read from the registers) is within the range for type `ty`.
    ///
    /// ```
    /// use drive_core::od::{Range, Type};
    /// assert!(Range::Span(-200_000, 200_000).accepts(Type::S32, (-5i32) as u32));
    /// assert!(!Range::Span(1, 127).accepts(Type::U8, 128));
    /// assert!(!Range::Magnitude(150, 300_000).accepts(Type::S32, (-100i32) as u32));
    /// assert!(Range::Bits(0x13).accepts(Type::U8, 0x12));
    /// assert!(!Range::Any.accepts(Type::U16, 0x1_0000));
    /// ```
    #[inline(always)]
    pub fn accepts(self, ty: Type, raw: u32) -> bool {
        if !ty.fits(raw) {
            return false;
        }
        let v = match ty {
            Type::S32 => i64::from(raw as i32),
            _ => i64::from(raw),
        };
        self.contains(v, raw)
    }

    /// Whether the value `v` (its raw bits `raw`) is within the range.
    #[inline(always)]
    fn contains(self, v: i64, raw: u32) -> bool {
        match self {
            Range::Any => true,
            Range::Span(min, max) => i64::from(min) <= v && v <= i64::from(max),
            Range::Set(set) => set.contains(&raw),
            Range::Bits(mask) => raw & !mask == 0,
            Range::Magnitude(min, max) => (u64::from(min)..=u64::from(max)).contains(&v.unsigned_abs()),
        }
    }
}

/// The unit of an object's value.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Unit {
    /// A plain number, a code or a bit field.
    None,
    /// Microsteps (pulses) at the current resolution.
    Steps,
    /// Microsteps per second.
    Pps,
    /// Microsteps per second squared.
    Pps2,
    /// Milliamperes.
    MilliAmps,
    /// Millivolts.
    MilliVolts,
    /// Milliseconds.
    Millis,
    /// Bits per second.
    Baud,
    /// Percent.
    Percent,
    /// Encoder counts.
    Counts,
    /// Degrees Celsius.
    Celsius,
    /// Tenths of a second.
    DeciSeconds,
    /// Milliohms.
    MilliOhms,
    /// Microhenries.
    MicroHenries,
    /// Degrees of the motor shaft.
    Degrees,
    /// Tenths of a volt per ampere (a current loop's proportional gain).
    DeciVoltsPerAmp,
    /// Hundredths of a volt per ampere, added each PWM period (a current loop's integral gain).
    CentiVoltsPerAmpPeriod,
    /// Thousandths.
    PerMille,
    /// Revolutions of the motor shaft a minute.
    Rpm,
    /// Microseconds.
    Micros,
    /// Bytes.
    Bytes,
}

impl Unit {
    /// Symbol in the register reference.
    pub const fn symbol(self) -> &'static str {
        match self {
            Unit::None => "",
            Unit::Steps => "step",
            Unit::Pps => "pps",
            Unit::Pps2 => "pps²",
            Unit::MilliAmps => "mA",
            Unit::MilliVolts => "mV",
            Unit::Millis => "ms",
            Unit::Baud => "bit/s",
            Unit::Percent => "%",
            Unit::Counts => "count",
            Unit::Celsius => "°C",
            Unit::DeciSeconds => "100 ms",
            Unit::MilliOhms => "mΩ",
            Unit::MicroHenries => "µH",
            Unit::Degrees => "°",
            Unit::DeciVoltsPerAmp => "0.1 V/A",
            Unit::CentiVoltsPerAmpPeriod => "0.01 V/A a PWM period",
            Unit::PerMille => "‰",
            Unit::Rpm => "r/min",
            Unit::Micros => "µs",
            Unit::Bytes => "bytes",
        }
    }
}

/// The declaration of one object: 12 bytes in the firmware (its type, access and storage in one
/// byte; its name, unit and text only with the feature `docs`).
#[derive(Clone, Copy, Debug)]
pub struct ObjectDef {
    /// The object.
    pub obj: Obj,
    /// First register (the high word of a 32-bit object).
    pub addr: u16,
    /// Short name (feature `docs`).
    #[cfg(feature = "docs")]
    pub name: &'static str,
    /// [`ObjectDef::ty`] in bits 0-2, [`ObjectDef::access`] in bits 3-4, [`ObjectDef::storage`]
    /// in bits 5-6.
    kind: u8,
    /// Accepted values (a reference: the objects share their few distinct ranges).
    pub range: &'static Range,
    /// Factory value (raw register bits; S32 as two's complement).
    pub default: u32,
    /// Unit (feature `docs`).
    #[cfg(feature = "docs")]
    pub unit: Unit,
    /// What the object does, from the manual, with our decisions where it is silent (feature
    /// `docs`).
    #[cfg(feature = "docs")]
    pub doc: &'static str,
}

impl ObjectDef {
    /// [`ObjectDef::kind`] of a type, an access and a storage. Texts are 4 or 16 bytes (any
    /// other length reads as 16).
    pub(crate) const fn kind(ty: Type, access: Access, storage: Storage) -> u8 {
        let ty = match ty {
            Type::U8 => 0,
            Type::U16 => 1,
            Type::U32 => 2,
            Type::S32 => 3,
            Type::Str(4) => 4,
            Type::Str(_) => 5,
        };
        ty | (access as u8) << 3 | (storage as u8) << 5
    }

    /// Encoding.
    #[inline(always)]
    pub const fn ty(&self) -> Type {
        match self.kind & 7 {
            0 => Type::U8,
            1 => Type::U16,
            2 => Type::U32,
            3 => Type::S32,
            4 => Type::Str(4),
            _ => Type::Str(16),
        }
    }

    /// Whether the value is the drive's running state ([`Storage::Live`]), on the raw bits.
    #[inline(always)]
    pub const fn is_live(&self) -> bool {
        (self.kind >> 5) & 3 == Storage::Live as u8
    }

    /// Bus access.
    #[inline(always)]
    pub const fn access(&self) -> Access {
        match (self.kind >> 3) & 3 {
            0 => Access::Ro,
            1 => Access::Rw,
            2 => Access::Cmd,
            _ => Access::W1c,
        }
    }

    /// Where the value lives.
    #[inline(always)]
    pub const fn storage(&self) -> Storage {
        match (self.kind >> 5) & 3 {
            0 => Storage::Ram,
            1 => Storage::Rom,
            2 => Storage::Live,
            _ => Storage::Const,
        }
    }

    /// Whether a master cannot write it (read only, or a constant): on the raw bits, as the
    /// request path asks it.
    #[inline(always)]
    pub const fn is_read_only(&self) -> bool {
        (self.kind >> 3) & 3 == 0 || (self.kind >> 5) & 3 == 3
    }

    /// Whether `raw` (as read from the registers) is a value of its type within its range
    /// ([`Range::accepts`] with [`ObjectDef::ty`]), on the raw bits. Out of line: the write
    /// path and power-up each had a copy.
    #[inline(never)]
    pub fn accepts(&self, raw: u32) -> bool {
        let (fits, v) = match self.kind & 7 {
            0 => (raw <= 0xFF, i64::from(raw)),
            1 => (raw <= 0xFFFF, i64::from(raw)),
            2 => (true, i64::from(raw)),
            3 => (true, i64::from(raw as i32)),
            _ => (false, 0),
        };
        fits && self.range.contains(v, raw)
    }

    /// Registers the object occupies.
    pub const fn words(&self) -> u16 {
        self.ty().words()
    }
    /// The register after the object's last one.
    pub const fn end(&self) -> u32 {
        self.addr as u32 + self.ty().words() as u32
    }
}

/// Why an object access failed: each register map turns this into its own exception code.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ObjError {
    /// No object at that register.
    Unknown,
    /// The object cannot be written.
    ReadOnly,
    /// The value is outside the object's range.
    OutOfRange,
    /// The axis is moving, a run is going or a save is under way, and the request needs rest.
    Busy,
    /// The power stage is off (0x6006 = 0, or freed by a power loss).
    Disabled,
    /// A latched error, stop, stall or communication-timeout bit must be cleared first.
    Faulted,
    /// Not in the present work mode or state: another mode's command, a speed of 0, a PVT
    /// run's points missing or ending in motion, a full FIFO.
    NotNow,
    /// No trajectory takes the axis there within its limits (a PVT segment beyond the top
    /// speed, a junction or an approach the motor cannot follow).
    Infeasible,
    /// The drive does not do this: no boot loader to jump to, no flash to save to.
    Unsupported,
    /// The motion asks for a speed beyond the overspeed limit (0x21F6); 0x21F7 reads 30.
    Overspeed,
}

/// `Ok` if `ok`, else the refusal `why`.
pub(crate) const fn refuse(ok: bool, why: ObjError) -> Result<(), ObjError> {
    if ok { Ok(()) } else { Err(why) }
}

impl ObjError {
    /// Whether the value is valid and only the drive's state refuses it (a map's "device
    /// failure" exception, where the layout has one code for all of them).
    pub const fn is_refusal(self) -> bool {
        !matches!(self, Self::Unknown | Self::ReadOnly | Self::OutOfRange)
    }
}
