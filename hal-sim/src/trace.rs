//! Motion traces: what the drive commanded against what the simulated rotor did, as CSV.
//!
//! A row is (t_s, commanded_position_usteps, commanded_velocity_pps, rotor_position_usteps,
//! rotor_velocity_pps, i_a, i_b, gpio_out, coil_pct): time in seconds, positions in microsteps
//! from the start, velocities in microsteps per second ("pulses per second"), phase currents in
//! amperes, the drive's output pins' levels (1 high, bits as 0x6031) and the coil output's PWM
//! duty in percent. Rows are
//! decimated: only every Nth row offered is kept, so a long run at the model's 80 kHz stays small.
//!
//! [`Trace`] keeps its rows in memory (for tests and [`crate::plot`]); [`TraceWriter`] streams them
//! to any `Write` (a file given with `--trace FILE.csv`) and keeps nothing.

use std::fs::File;
use std::io::{self, BufRead, BufReader, BufWriter, Write};
use std::path::Path;

use crate::motor::Motor;

/// The CSV header line (without its newline), naming the columns of [`TraceRow`] in order.
pub const CSV_HEADER: &str = "t_s,commanded_position_usteps,commanded_velocity_pps,rotor_position_usteps,rotor_velocity_pps,i_a,i_b,gpio_out,coil_pct";

/// One sample of a trace.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TraceRow {
    /// Time, s.
    pub t_s: f64,
    /// Commanded position, microsteps from the start.
    pub commanded_position_usteps: f64,
    /// Commanded velocity, microsteps per second.
    pub commanded_velocity_pps: f64,
    /// Rotor position, microsteps from the start.
    pub rotor_position_usteps: f64,
    /// Rotor velocity, microsteps per second.
    pub rotor_velocity_pps: f64,
    /// Phase A current, A.
    pub i_a: f64,
    /// Phase B current, A.
    pub i_b: f64,
    /// The drive's output pins' levels (1 high, bits as 0x6031).
    pub gpio_out: u16,
    /// The coil output's PWM duty, %.
    pub coil_pct: u8,
}

impl TraceRow {
    /// A row from the motor's state now (time, rotor position and speed, currents) and the
    /// command, with `microsteps_per_step` microsteps per full step.
    pub fn from_motor(
        motor: &Motor,
        commanded_position_usteps: f64,
        commanded_velocity_pps: f64,
        microsteps_per_step: u32,
    ) -> Self {
        let (i_a, i_b) = motor.phase_currents();
        Self {
            t_s: motor.time_s(),
            commanded_position_usteps,
            commanded_velocity_pps,
            rotor_position_usteps: motor.rotor_microsteps(microsteps_per_step),
            rotor_velocity_pps: motor.speed_microsteps_per_s(microsteps_per_step),
            i_a,
            i_b,
            gpio_out: 0,
            coil_pct: 0,
        }
    }

    /// Writes the row as one CSV line (with its newline). Times to 0.1 µs, positions to 10⁻⁴
    /// microstep, velocities to 10⁻³ microstep/s, currents to 10 µA.
    pub fn write_csv_line<W: Write>(&self, out: &mut W) -> io::Result<()> {
        writeln!(
            out,
            "{:.7},{:.4},{:.3},{:.4},{:.3},{:.5},{:.5},{},{}",
            self.t_s,
            self.commanded_position_usteps,
            self.commanded_velocity_pps,
            self.rotor_position_usteps,
            self.rotor_velocity_pps,
            self.i_a,
            self.i_b,
            self.gpio_out,
            self.coil_pct
        )
    }

    /// Parses one CSV line of nine numbers.
    pub fn parse_csv_line(line: &str) -> Result<Self, String> {
        let mut v = [0.0; 9];
        let mut fields = line.trim().split(',');
        for (k, slot) in v.iter_mut().enumerate() {
            let field = fields.next().ok_or_else(|| format!("only {k} fields in {line:?}"))?;
            *slot = field.trim().parse().map_err(|e| format!("field {} of {line:?}: {e}", k + 1))?;
        }
        if fields.next().is_some() {
            return Err(format!("more than 9 fields in {line:?}"));
        }
        let [t_s, cp, cv, rp, rv, i_a, i_b, gpio, coil] = v;
        Ok(Self {
            t_s,
            commanded_position_usteps: cp,
            commanded_velocity_pps: cv,
            rotor_position_usteps: rp,
            rotor_velocity_pps: rv,
            i_a,
            i_b,
            gpio_out: gpio as u16,
            coil_pct: coil as u8,
        })
    }
}

/// Keeps every Nth of the rows offered to it, starting with the first.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Decimator {
    every: u32,
    offered: u64,
}

impl Decimator {
    /// Keep one row in `every` (0 counts as 1: keep all).
    pub fn new(every: u32) -> Self {
        Self { every: every.max(1), offered: 0 }
    }

    /// Counts one offered row; true if it is to be kept.
    pub fn take(&mut self) -> bool {
        let keep = self.offered.is_multiple_of(u64::from(self.every));
        self.offered += 1;
        keep
    }

    /// Rows offered so far.
    pub fn offered(&self) -> u64 {
        self.offered
    }
}

/// A decimated trace kept in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct Trace {
    decimator: Decimator,
    rows: Vec<TraceRow>,
}

impl Trace {
    /// An empty trace keeping one row in `every` offered.
    pub fn new(every: u32) -> Self {
        Self { decimator: Decimator::new(every), rows: Vec::new() }
    }

    /// Offers a row, built only if it is to be kept; true if it was.
    pub fn offer_with(&mut self, row: impl FnOnce() -> TraceRow) -> bool {
        let keep = self.decimator.take();
        if keep {
            self.rows.push(row());
        }
        keep
    }

    /// Offers a row; true if it was kept.
    pub fn offer(&mut self, row: TraceRow) -> bool {
        self.offer_with(|| row)
    }

    /// Keeps a row whatever the decimation (e.g. the last one of a run).
    pub fn push(&mut self, row: TraceRow) {
        self.rows.push(row);
    }

    /// The rows kept.
    pub fn rows(&self) -> &[TraceRow] {
        &self.rows
    }

    /// Writes the header and the rows as CSV.
    pub fn write_csv<W: Write>(&self, out: W) -> io::Result<()> {
        let mut out = BufWriter::new(out);
        writeln!(out, "{CSV_HEADER}")?;
        for row in &self.rows {
            row.write_csv_line(&mut out)?;
        }
        out.flush()
    }

    /// Writes the trace to a CSV file (created or truncated).
    pub fn save_csv(&self, path: impl AsRef<Path>) -> io::Result<()> {
        self.write_csv(File::create(path)?)
    }
}

/// Reads the rows of a trace CSV (header first, as [`Trace::write_csv`] and [`TraceWriter`]
/// write it). Blank lines are skipped, and so is a last line without its newline.
pub fn read_csv<R: BufRead>(mut input: R) -> io::Result<Vec<TraceRow>> {
    let bad = |what: String| io::Error::new(io::ErrorKind::InvalidData, what);
    let mut text = String::new();
    input.read_to_string(&mut text)?;
    // Whole lines only: a trace is read while the simulator writes it, and its last row may be
    // half written.
    let mut lines = text.split_inclusive('\n').filter(|l| l.ends_with('\n'));
    let header = lines.next().unwrap_or_default();
    if header.trim() != CSV_HEADER {
        return Err(bad(format!("not a trace CSV: header {header:?}")));
    }
    let mut rows = Vec::new();
    for line in lines {
        if !line.trim().is_empty() {
            rows.push(TraceRow::parse_csv_line(line).map_err(bad)?);
        }
    }
    Ok(rows)
}

/// Reads a trace CSV file.
pub fn load_csv(path: impl AsRef<Path>) -> io::Result<Vec<TraceRow>> {
    read_csv(BufReader::new(File::open(path)?))
}

/// A decimated trace streamed as CSV to a writer as it is recorded; nothing is kept in memory.
#[derive(Debug)]
pub struct TraceWriter<W: Write> {
    decimator: Decimator,
    out: BufWriter<W>,
    written: u64,
}

impl TraceWriter<File> {
    /// Creates (or truncates) a CSV file and writes the header.
    pub fn create(path: impl AsRef<Path>, every: u32) -> io::Result<Self> {
        Self::new(File::create(path)?, every)
    }
}

impl<W: Write> TraceWriter<W> {
    /// Writes the header to `out`; then keeps one row in `every` offered.
    pub fn new(out: W, every: u32) -> io::Result<Self> {
        let mut out = BufWriter::new(out);
        writeln!(out, "{CSV_HEADER}")?;
        Ok(Self { decimator: Decimator::new(every), out, written: 0 })
    }

    /// Offers a row, built only if it is to be kept; true if it was written.
    pub fn offer_with(&mut self, row: impl FnOnce() -> TraceRow) -> io::Result<bool> {
        if !self.decimator.take() {
            return Ok(false);
        }
        row().write_csv_line(&mut self.out)?;
        self.written += 1;
        Ok(true)
    }

    /// Writes a row whatever the decimation.
    pub fn push(&mut self, row: &TraceRow) -> io::Result<()> {
        row.write_csv_line(&mut self.out)?;
        self.written += 1;
        Ok(())
    }

    /// Rows written so far.
    pub fn written(&self) -> u64 {
        self.written
    }

    /// Flushes and returns the writer.
    pub fn finish(self) -> io::Result<W> {
        self.out.into_inner().map_err(|e| e.into_error())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(k: u32) -> TraceRow {
        let x = f64::from(k);
        TraceRow {
            t_s: x * 1e-5,
            commanded_position_usteps: x * 1.5,
            commanded_velocity_pps: 100.0,
            rotor_position_usteps: x * 1.5 - 0.25,
            rotor_velocity_pps: 99.5,
            i_a: 1.25,
            i_b: -0.5,
            gpio_out: 0x800,
            coil_pct: 40,
        }
    }

    #[test]
    fn decimates_and_round_trips() {
        let mut trace = Trace::new(10);
        for k in 0..95 {
            trace.offer(row(k));
        }
        assert_eq!(trace.rows().len(), 10);
        assert_eq!(trace.rows()[1], row(10));
        let mut csv = Vec::new();
        trace.write_csv(&mut csv).unwrap();
        let text = String::from_utf8(csv.clone()).unwrap();
        assert!(text.starts_with(CSV_HEADER));
        let back = read_csv(&csv[..]).unwrap();
        assert_eq!(back.len(), trace.rows().len());
        for (a, b) in back.iter().zip(trace.rows()) {
            // Times are written to 0.1 µs.
            assert!((a.t_s - b.t_s).abs() < 1e-9);
            assert_eq!(TraceRow { t_s: b.t_s, ..*a }, *b);
        }

        let mut streamed = TraceWriter::new(Vec::new(), 10).unwrap();
        for k in 0..95 {
            streamed.offer_with(|| row(k)).unwrap();
        }
        assert_eq!(streamed.written(), 10);
        assert_eq!(streamed.finish().unwrap(), csv);
    }

    #[test]
    fn refuses_what_is_not_a_trace() {
        assert!(read_csv(&b"a,b\n1,2\n"[..]).is_err());
        assert!(read_csv(format!("{CSV_HEADER}\n1,2,3\n").as_bytes()).is_err());
    }
}
