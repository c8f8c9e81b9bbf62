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
    write_scope(out)
}

/// The scope's signals and the capture windows.
fn write_scope(out: &mut impl Write) -> fmt::Result {
    use crate::scope::{BLACK_BOX, Signal, WORDS};
    writeln!(out)?;
    writeln!(out, "## The scope")?;
    writeln!(out)?;
    writeln!(
        out,
        "The scope (0x2220-0x2237) records up to 8 signals a row every 0x2228 control ticks (50 µs) into {WORDS} registers: 0x4000-0x{:04X} hold the capture, its rows in time order, each row its signals' registers in the order of 0x2220-0x2227 (a two-register signal high word first). The black box (0x2238-0x2240) records its signals unless the scope records; an alarm freezes the {} rows before it and the rest after it, at 0x{:04X}-0x{:04X}. A read of the windows may take 1-125 registers anywhere in them. Read 0x2230-0x2231 (0x2238-0x2239) before and after the rows: the same sequence number, state 3 both times, is a whole capture, its rows 0x2236 (0x223F) µs apart; then write that number to 0x2232 (0x223A).",
        0x4000 + WORDS - 1,
        (WORDS / usize::from(BLACK_BOX.row_words())) * usize::from(BLACK_BOX.pre_percent) / 100,
        0xA000,
        0xA000 + WORDS - 1,
    )?;
    writeln!(out)?;
    writeln!(out, "| Code | Signal | Registers | Unit | Black box |")?;
    writeln!(out, "|---|---|---|---|---|")?;
    for s in Signal::ALL {
        let boxed = if BLACK_BOX.signals.contains(&s) { "yes" } else { "" };
        let sign = if s.signed() { "signed" } else { "unsigned" };
        writeln!(out, "| {} | {} | {} ({sign}) | {} | {boxed} |", s as u8, s.name(), s.words(), s.unit())?;
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
