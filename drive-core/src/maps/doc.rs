//! The Markdown register reference of a layout map, generated from its table and the objects'
//! declarations (`docs/registers-NAME.md`).

use super::layout::{Entry, Layout, Scale, View, Walk, WordOrder};
use crate::od::{Access, Range, Type, Unit};
use core::fmt::{self, Write};

/// The microsteps a revolution at the factory resolution (0x600C = 0: full steps), for the
/// defaults a map shows in its own units.
const FACTORY_PER_REV: i64 = super::layout::FULL_STEPS_PER_REV;

/// What a map's reference says beside its table: its title, the decisions where its manual is
/// silent or contradicts itself, and a remark for some registers.
pub struct Reference {
    /// The title.
    pub title: &'static str,
    /// The decisions and protocol notes, one paragraph each.
    pub notes: &'static [&'static str],
    /// Remarks by register, in place of the object's own text.
    pub remarks: &'static [(u16, &'static str)],
    /// Whether the manual numbers its registers in decimal (below 0x2000: the drive's own
    /// registers keep their hexadecimal numbers). A sub-indexed layout's registers show as
    /// their index and sub-index (`0x2003.1`).
    pub decimal: bool,
}

/// Writes the reference of `layout`.
pub fn write_layout(out: &mut impl Write, layout: &Layout, r: &Reference) -> fmt::Result {
    writeln!(out, "# Register reference: {}", r.title)?;
    writeln!(out)?;
    writeln!(
        out,
        "Generated from the map's layout table by `cargo xtask docs`; a test fails when this file is stale."
    )?;
    writeln!(out)?;
    let order = match layout.order {
        WordOrder::HighFirst => "high word first",
        WordOrder::LowFirst => "low word first",
        WordOrder::Setting => "high word first, or low word first as the word-order register says",
    };
    let walk = match layout.walk {
        Walk::Address => "by address",
        Walk::List => {
            "in the order of this table (a request starts at an entry's register and goes on through the entries below it, whatever their addresses)"
        }
    };
    writeln!(out, "- 32-bit values take two registers, {order}; multi-register requests walk the registers {walk}.")?;
    if !layout.halves {
        writeln!(out, "- A 32-bit value is written whole (0x10 with both registers); one half alone is refused.")?;
    }
    let e = &layout.exceptions;
    writeln!(
        out,
        "- Exception codes: no such register {}, write to a read-only register {}, read of a write-only one {}, value out of range {}, byte count {}, one half of a 32-bit value {}, busy {}, power stage off {}, fault latched {}, not in this mode or state {}, no trajectory within the limits {}, not done by the drive {}. A refused request changes nothing; a multi-register write is all or nothing.",
        e.unknown.code(),
        e.read_only.code(),
        e.write_only.code(),
        e.out_of_range.code(),
        e.byte_count.code(),
        e.split.code(),
        e.busy.code(),
        e.disabled.code(),
        e.faulted.code(),
        e.not_now.code(),
        e.infeasible.code(),
        e.unsupported.code(),
    )?;
    for n in r.notes {
        writeln!(out, "- {n}")?;
    }
    if layout.scope {
        writeln!(
            out,
            "- The scope and the black box: registers 0x2220-0x2240 and the capture windows 0x4000-0x5FFF and 0xA000-0xBFFF are the native map's (`registers.md`, \"The scope\"), answered in this map's exception codes."
        )?;
    }
    writeln!(out)?;
    writeln!(out, "| Register | Words | Name | Access | Values | Default | Unit | Drive object | Description |")?;
    writeln!(out, "|---|---|---|---|---|---|---|---|---|")?;
    // The program window and the reserved ranges, in address order among the entries.
    let mut extra: heapless::Vec<(u16, Extra), 16> = heapless::Vec::new();
    if let Some(p) = layout.program {
        let _ = extra.push((p.first, Extra::Program(p)));
    }
    for &(first, last) in layout.reserved {
        let _ = extra.push((first, Extra::Reserved(first, last)));
    }
    extra.sort_unstable_by_key(|(a, _)| *a);
    let mut extra = extra.into_iter().peekable();
    for entry in layout.entries {
        while let Some((_, x)) = extra.next_if(|(a, _)| entry.addr > *a) {
            extra_row(out, x, r)?;
        }
        row(out, layout, entry, r)?;
    }
    for (_, x) in extra {
        extra_row(out, x, r)?;
    }
    Ok(())
}

/// A row of the reference that is not an object's.
#[derive(Clone, Copy)]
enum Extra {
    Program(super::layout::ProgramWindow),
    Reserved(u16, u16),
}

/// The program window (raw words) or a reserved range.
fn extra_row(out: &mut impl Write, x: Extra, r: &Reference) -> fmt::Result {
    let register =
        |out: &mut dyn Write, a: u16| if r.decimal { write!(out, "{a:04}") } else { write!(out, "0x{a:04X}") };
    let (first, last) = match x {
        Extra::Program(p) => (p.first, p.first + p.words - 1),
        Extra::Reserved(first, last) => (first, last),
    };
    write!(out, "| ")?;
    register(out, first)?;
    if last != first {
        write!(out, "-")?;
        register(out, last)?;
    }
    write!(out, " | {} | ", last - first + 1)?;
    match x {
        Extra::Program(p) if p.kind == crate::state::ProgramKind::Groups => writeln!(
            out,
            "position data groups | rw | see the notes | 0 |  | - | The groups, eight registers each (see the notes), saved with the parameters. |"
        ),
        Extra::Program(_) => writeln!(
            out,
            "multi-segment program | rw | 0..65535 | 0 |  | - | The program's instructions (see the notes), saved with the parameters. |"
        ),
        Extra::Reserved(..) => {
            let text = r
                .remarks
                .iter()
                .find(|(a, _)| *a == first)
                .map_or("Reserved: the drive has nothing for it (see the notes).", |(_, t)| t);
            writeln!(out, "reserved | ro | 0 | 0 |  | - | {text} |")
        }
    }
}

fn row(out: &mut impl Write, layout: &Layout, e: &Entry, r: &Reference) -> fmt::Result {
    let d = e.obj.def();
    let access = match (e.view(), d.access()) {
        (View::ReadOnly, _) | (_, Access::Ro) => "ro",
        (View::WriteOnly, _) => "wo",
        (View::Declared, a) => a.name(),
    };
    if let Some(s) = layout.sub_index {
        let (index, sub) = s.keys.index_of(e.addr);
        write!(out, "| 0x{index:04X}.{sub} ")?;
    } else if r.decimal && e.addr < 0x2000 {
        write!(out, "| {:04} ", e.addr)?;
    } else {
        write!(out, "| 0x{:04X} ", e.addr)?;
    }
    write!(out, "| {} | {} | {access} | ", e.words(), d.name)?;
    values(out, e)?;
    write!(out, " | ")?;
    match d.ty() {
        Type::Str(_) => write!(out, "-")?,
        _ => {
            let v = if d.ty() == Type::S32 { i64::from(d.default as i32) } else { i64::from(d.default) };
            write!(out, "{}", e.scale.to_map(v, FACTORY_PER_REV).unwrap_or(v))?;
        }
    }
    write!(out, " | {} | 0x{:04X} | ", unit(e), d.addr)?;
    let text = r.remarks.iter().find(|(a, _)| *a == e.addr).map_or(d.doc, |(_, t)| t);
    for (i, line) in text.lines().map(str::trim).filter(|l| !l.is_empty()).enumerate() {
        write!(out, "{}{line}", if i > 0 { " " } else { "" })?;
    }
    writeln!(out, " |")
}

/// The values the map takes, in its own units where its scale is a fixed one.
fn values(out: &mut impl Write, e: &Entry) -> fmt::Result {
    let d = e.obj.def();
    if let Scale::Table(choices) = e.scale {
        for (i, c) in choices.iter().enumerate() {
            let sep = if i > 0 { ", " } else { "" };
            if c.lo == c.hi { write!(out, "{sep}{}", c.lo)? } else { write!(out, "{sep}{}..{}", c.lo, c.hi)? }
        }
        return Ok(());
    }
    match *e.scale {
        Scale::Field(k, 1) => return write!(out, "0, 1 (bit {k} of the drive object)"),
        Scale::Field(k, w) => return write!(out, "bits {k}-{} of the drive object", k + w - 1),
        Scale::Invert(mask) => return write!(out, "bits 0x{mask:X}, the drive object's inverted"),
        Scale::PulsesPerRev => return write!(out, "multiples of 200 to 51200"),
        _ => {}
    }
    let map = |v: i64| match *e.scale {
        Scale::One => v,
        s => s.to_map(v, FACTORY_PER_REV).unwrap_or(v),
    };
    match (*d.range, *e.scale) {
        (Range::Any, _) | (_, Scale::PerRev(..) | Scale::Gear) => write!(out, "as the drive object"),
        (Range::Span(a, b), _) => {
            let (a, b) = (map(i64::from(a)), map(i64::from(b)));
            write!(out, "{}..{}", a.min(b), a.max(b))
        }
        (Range::Set(set), _) => {
            for (i, v) in set.iter().enumerate() {
                write!(out, "{}{}", if i > 0 { ", " } else { "" }, map(i64::from(*v)))?;
            }
            Ok(())
        }
        (Range::Bits(mask), _) => write!(out, "bits 0x{mask:X}"),
        (Range::Magnitude(a, b), _) => write!(out, "±{}..±{}", map(i64::from(a)), map(i64::from(b))),
    }
}

/// The map's unit of `e`.
pub fn unit(e: &Entry) -> &'static str {
    match (*e.scale, e.obj.def().unit) {
        (Scale::PerRev(1, 10), Unit::Pps) => "0.1 rev/s",
        (Scale::PerRev(1, 10), Unit::Pps2) => "0.1 rev/s²",
        (Scale::PerRev(1, 100), Unit::Pps) => "0.01 rev/s",
        (Scale::PerRev(1, 1), Unit::Pps2) => "rev/s²",
        (Scale::Ratio(100, 1), Unit::MilliAmps) => "0.1 A",
        (Scale::Ratio(1000, 1), Unit::MilliVolts) => "V",
        (Scale::PerRev(1, 60), Unit::Pps) => "r/min",
        (Scale::PulsesPerRev, _) => "pulse/rev",
        (Scale::PerRev(1, 6), Unit::Pps2) => "10 r/min/s",
        (Scale::Ratio(1000, 1), Unit::Pps) => "kHz",
        (Scale::Gear, _) => "group unit",
        (Scale::One | Scale::Ratio(-1, 1) | Scale::Table(_) | Scale::Field(..) | Scale::Invert(_), u) => u.symbol(),
        _ => "see the description",
    }
}
