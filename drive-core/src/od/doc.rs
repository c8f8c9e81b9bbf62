//! The Markdown register reference, generated from the declarations.

use super::{OBJECTS, ObjectDef, Range, Type};
use core::fmt::{self, Write};

/// Writes the register reference of the native map (`docs/registers.md`).
pub fn write_native(out: &mut impl Write) -> fmt::Result {
    writeln!(out, "# Register reference: native map (MSME/PMC007 compatible)")?;
    writeln!(out)?;
    writeln!(
        out,
        "Generated from `drive-core/src/od/native.rs` by `cargo xtask docs`; a test fails when this file is stale."
    )?;
    writeln!(out)?;
    writeln!(
        out,
        "- 32-bit objects take two registers, **high word at the lower address**. Writing the high word alone stages it; writing the low word completes the value (with the staged high word, or the present one) and commits it; writing both in one 0x10 request commits at once. For `cmd` objects the commit is the command."
    )?;
    writeln!(
        out,
        "- Function codes 0x03 and 0x04 read the same objects. A read may span the reserved registers between the objects of one page (registers sharing the high byte): they read as 0. A read outside that, or a write that touches a register without an object, is refused as a whole."
    )?;
    writeln!(
        out,
        "- Exceptions: 01 unsupported function or diagnostics sub-function; 02 register without an object, or a write to a read-only object; 03 value out of range, or wrong quantities and lengths; 04 a valid request the drive cannot act on now (e.g. a move while disabled, a save while moving). A multi-register write is all or nothing."
    )?;
    writeln!(
        out,
        "- Access: `ro` read only, `rw` read/write, `cmd` a write runs a command, `w1c` write 1 to clear a bit. Storage: `ROM` kept in flash when saved (0x200F = 2; 0x6055 by the power-down save), `RAM` reset at power-up, `live` the drive's running state, `const` firmware constants."
    )?;
    writeln!(out)?;
    writeln!(out, "| Register | Name | Type | Access | Storage | Range | Default | Unit | Description |")?;
    writeln!(out, "|---|---|---|---|---|---|---|---|---|")?;
    for d in OBJECTS.iter() {
        row(out, d)?;
    }
    Ok(())
}

fn row(out: &mut impl Write, d: &ObjectDef) -> fmt::Result {
    if d.words() > 1 {
        write!(out, "| 0x{:04X}..0x{:04X} ", d.addr, d.end() - 1)?;
    } else {
        write!(out, "| 0x{:04X} ", d.addr)?;
    }
    write!(out, "| {} | {} | {} | {} | ", d.name, d.ty().name(), d.access().name(), d.storage().name())?;
    range(out, d)?;
    write!(out, " | ")?;
    match d.ty() {
        Type::Str(_) => write!(out, "-")?,
        Type::S32 => write!(out, "{}", d.default as i32)?,
        _ => write!(out, "{}", d.default)?,
    }
    write!(out, " | {} | ", d.unit.symbol())?;
    for (i, line) in d.doc.lines().map(str::trim).filter(|l| !l.is_empty()).enumerate() {
        if i > 0 {
            write!(out, " ")?;
        }
        write!(out, "{line}")?;
    }
    writeln!(out, " |")
}

fn range(out: &mut impl Write, d: &ObjectDef) -> fmt::Result {
    match *d.range {
        Range::Any => match d.ty() {
            Type::U8 => write!(out, "0..255"),
            Type::U16 => write!(out, "0..65535"),
            Type::U32 => write!(out, "0..4294967295"),
            Type::S32 => write!(out, "-2147483648..2147483647"),
            Type::Str(n) => write!(out, "{n} bytes"),
        },
        Range::Span(a, b) => write!(out, "{a}..{b}"),
        Range::Set(set) => {
            for (i, v) in set.iter().enumerate() {
                write!(out, "{}{v}", if i > 0 { ", " } else { "" })?;
            }
            Ok(())
        }
        Range::Bits(mask) => write!(out, "bits 0x{mask:X}"),
        Range::Magnitude(a, b) => write!(out, "±{a}..±{b}"),
    }
}
