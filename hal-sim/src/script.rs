//! Batch mode: the drive and its motor run a script of timed requests in simulated time, as fast
//! as they go, with no endpoint (`hal-sim --script FILE`).
//!
//! A script has one command a line; `#` starts a comment, to the end of the line; blank lines are
//! skipped. Times are milliseconds since the start, with at most three decimals (1 µs), and never
//! go back from one command to the next.
//!
//! - `at <ms> <hex>`: the bytes of a request, without its CRC (the runner appends it, low byte
//!   first), reach the drive at `<ms>`, all at once. Hex digits come in pairs, spaced as you like:
//!   `01 06 600C 0020`. Requests meant as separate frames must lie at least t3.5 apart (4.01 ms at
//!   9600 baud, 1.75 ms above 19200): closer ones join into one frame, which fails its CRC and
//!   gets no answer, exactly as on a serial line.
//! - `raw <ms> <hex>`: these bytes as they are (no CRC appended) reach the drive at `<ms>`: a
//!   raw master's pieces of frames, with the silences between them that its times make.
//! - `until <ms>`: run to `<ms>`.
//!
//! The runner advances the plant ([`Plant::advance_to`]) up to each time; on the way it calls
//! [`Drive::on_timer`](drive_core::Drive::on_timer) at every [`Drive::deadline`](drive_core::Drive::deadline)
//! that falls due, so a frame ends when its t3.5 runs out. Every reply is printed when the drive
//! makes it, as `<ms> reply <hex>`: the frame as sent, CRC included. A frame still pending after
//! the last command is finished at its deadline. Last comes the summary line
//! `end <ms> setpoint <microsteps> rotor <microsteps>`: the drive's position setpoint and the
//! rotor's position in the drive's microsteps (two decimals).
//!
//! ```
//! use hal_sim::SimOptions;
//! use hal_sim::script::{plant, run_script};
//!
//! let mut plant = plant(&SimOptions::default())?;
//! let mut out = Vec::new();
//! // Read 0x600C..0x600D (microstep resolution, phase current) at 1 ms; stop at 10 ms.
//! run_script("at 1 01 03 600C 0002\nuntil 10\n", &mut plant, &mut out)?;
//! assert_eq!(
//!     String::from_utf8(out).unwrap(),
//!     "5.010 reply 01 03 04 00 00 02 92 7A FE\nend 10.000 setpoint 0 rotor 0.00\n"
//! );
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use std::fmt;
use std::io::{self, Write};

use drive_core::Instant;
use drive_core::crc::crc16;

use crate::plant::Plant;
use crate::{SimOptions, invalid};

/// One command of a script.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Command {
    /// Deliver these bytes (the CRC already appended) at this time.
    At(Instant, Vec<u8>),
    /// Run to this time.
    Until(Instant),
}

/// Why a script did not run to its end.
#[derive(Debug)]
pub enum ScriptError {
    /// Line `line` (from 1) is not a command.
    Parse {
        /// The line number, from 1.
        line: usize,
        /// What is wrong with it.
        message: String,
    },
    /// Writing the output failed.
    Io(io::Error),
}

impl fmt::Display for ScriptError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Parse { line, message } => write!(f, "line {line}: {message}"),
            Self::Io(e) => write!(f, "output: {e}"),
        }
    }
}

impl std::error::Error for ScriptError {}

impl From<io::Error> for ScriptError {
    fn from(e: io::Error) -> Self {
        Self::Io(e)
    }
}

/// Where a script left the drive and the motor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Summary {
    /// The simulated time at the end.
    pub end: Instant,
    /// The drive's position setpoint, whole microsteps.
    pub setpoint: i64,
    /// The rotor's position in the drive's microsteps.
    pub rotor: f64,
}

/// The plant `opts` describe: the drive with its address and baud rate, the motor of the
/// catalogue with its supply and load, and the trace file if any. The endpoint is not opened, and
/// there is no parameter store: a script's 0x200F = 2 is refused (04). Options the drive or the catalogue do not take are [`io::ErrorKind::InvalidInput`] errors.
pub fn plant(opts: &SimOptions) -> io::Result<Plant> {
    // One drive: a script talks to one.
    let single = SimOptions { axes: Vec::new(), ..opts.clone() };
    crate::plants(&single)?.into_iter().next().ok_or_else(|| invalid("no drive".into()))
}

/// Parses a whole script; the first line that is not a command is the error.
pub fn parse(text: &str) -> Result<Vec<Command>, ScriptError> {
    let mut commands = Vec::new();
    let mut last = Instant::from_micros(0);
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split_once('#').map_or(raw, |(code, _)| code);
        let mut words = line.split_whitespace();
        let Some(verb) = words.next() else {
            continue;
        };
        let error = |message: String| ScriptError::Parse { line: i + 1, message };
        let time = |word: Option<&str>| {
            let word = word.ok_or_else(|| error(format!("`{verb}` needs a time in ms")))?;
            let t = parse_ms(word).map_err(|m| error(format!("bad time `{word}`: {m}")))?;
            if t < last {
                return Err(error(format!("time goes back: {} ms after {} ms", ms(t), ms(last))));
            }
            Ok(t)
        };
        let command = match verb {
            "at" | "raw" => {
                let t = time(words.next())?;
                let mut bytes = Vec::new();
                for word in words {
                    parse_hex(word, &mut bytes).map_err(|m| error(format!("bad bytes `{word}`: {m}")))?;
                }
                if bytes.is_empty() {
                    return Err(error(format!("`{verb}` needs the bytes to send")));
                }
                // `at` is a request, to which its CRC is appended; `raw` bytes go as they are.
                if verb == "at" {
                    bytes.extend_from_slice(&crc16(&bytes).to_le_bytes());
                }
                Command::At(t, bytes)
            }
            "until" => {
                let t = time(words.next())?;
                if let Some(extra) = words.next() {
                    return Err(error(format!("unexpected `{extra}` after the time")));
                }
                Command::Until(t)
            }
            other => return Err(error(format!("unknown command `{other}` (expected `at`, `raw` or `until`)"))),
        };
        last = match command {
            Command::At(t, _) | Command::Until(t) => t,
        };
        commands.push(command);
    }
    Ok(commands)
}

/// Parses and runs `text` on `plant` (a new one: script times count from its start), printing the
/// replies and the summary to `out`. Nothing runs if a line does not parse.
pub fn run_script(text: &str, plant: &mut Plant, out: &mut impl Write) -> Result<Summary, ScriptError> {
    let commands = parse(text)?;
    let mut runner = Runner { plant, out };
    let mut now = Instant::from_micros(0);
    for command in &commands {
        match command {
            Command::At(t, bytes) => {
                now = runner.run_to(*t)?;
                let drive = runner.plant.drive_mut();
                drive.on_rx(now, bytes);
                // (A frame that had ended before these bytes is answered first: already done
                // at its deadline, so nothing here in practice.)
                runner.emit(now)?;
            }
            Command::Until(t) => now = runner.run_to(*t)?,
        }
    }
    if let Some(deadline) = runner.plant.drive().deadline() {
        now = runner.run_to(deadline.max(now))?;
    }
    let plant = runner.plant;
    let summary = Summary { end: now, setpoint: plant.drive().state().position(), rotor: plant.rotor_microsteps() };
    // Rounded first, so that a rotor a hair below zero does not print as -0.00.
    let rotor = (summary.rotor * 100.0).round() / 100.0 + 0.0;
    writeln!(runner.out, "end {} setpoint {} rotor {rotor:.2}", ms(now), summary.setpoint)?;
    runner.out.flush()?;
    plant.flush_trace()?;
    Ok(summary)
}

struct Runner<'a, W> {
    plant: &'a mut Plant,
    out: &'a mut W,
}

impl<W: Write> Runner<'_, W> {
    /// Runs the plant to `t`, ending frames at their deadlines on the way; returns `t`.
    fn run_to(&mut self, t: Instant) -> io::Result<Instant> {
        while let Some(deadline) = self.plant.drive().deadline().filter(|&d| d <= t) {
            self.plant.advance_to(deadline);
            self.plant.drive_mut().on_timer(deadline);
            self.emit(deadline)?;
        }
        self.plant.advance_to(t);
        Ok(t)
    }

    /// Prints the reply the drive has made, if any.
    fn emit(&mut self, now: Instant) -> io::Result<()> {
        if let Some(reply) = self.plant.drive_mut().take_reply() {
            writeln!(self.out, "{} reply {}", ms(now), hex(reply))?;
        }
        Ok(())
    }
}

/// `t` in milliseconds with three decimals.
fn ms(t: Instant) -> String {
    let us = t.as_micros();
    format!("{}.{:03}", us / 1000, us % 1000)
}

/// Bytes as upper-case hex pairs separated by spaces.
pub fn hex(bytes: &[u8]) -> String {
    let pairs: Vec<String> = bytes.iter().map(|b| format!("{b:02X}")).collect();
    pairs.join(" ")
}

/// A time in ms (`12`, `12.5`, `0.001`) as an instant.
fn parse_ms(word: &str) -> Result<Instant, &'static str> {
    let (whole, frac) = word.split_once('.').unwrap_or((word, ""));
    let digits = |s: &str| s.bytes().all(|b| b.is_ascii_digit());
    if (whole.is_empty() && frac.is_empty()) || !digits(whole) || !digits(frac) {
        return Err("not a number of milliseconds");
    }
    if frac.len() > 3 {
        return Err("more than three decimals (the step is 1 µs)");
    }
    let whole: u64 = if whole.is_empty() { 0 } else { whole.parse().map_err(|_| "too large")? };
    let frac: u64 = format!("{frac:0<3}").parse().map_err(|_| "not a number of milliseconds")?;
    whole.checked_mul(1000).and_then(|us| us.checked_add(frac)).map(Instant::from_micros).ok_or("too large")
}

/// Appends the bytes of a word of hex digit pairs to `out`.
fn parse_hex(word: &str, out: &mut Vec<u8>) -> Result<(), &'static str> {
    if !word.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err("not hex digits");
    }
    if !word.len().is_multiple_of(2) {
        return Err("an odd number of hex digits");
    }
    let digit = |b: u8| char::from(b).to_digit(16).unwrap_or(0) as u8;
    for pair in word.as_bytes().chunks_exact(2) {
        if let &[hi, lo] = pair {
            out.push(digit(hi) << 4 | digit(lo));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn times() {
        assert_eq!(parse_ms("12"), Ok(Instant::from_micros(12_000)));
        assert_eq!(parse_ms("12.5"), Ok(Instant::from_micros(12_500)));
        assert_eq!(parse_ms(".25"), Ok(Instant::from_micros(250)));
        assert_eq!(parse_ms("0.001"), Ok(Instant::from_micros(1)));
        for bad in ["", ".", "-1", "1e3", "1.0001", "x", "1.2.3", "+1"] {
            assert!(parse_ms(bad).is_err(), "{bad}");
        }
        assert_eq!(ms(Instant::from_micros(4_010)), "4.010");
    }

    #[test]
    fn hex_words() {
        let mut b = Vec::new();
        parse_hex("0106", &mut b).unwrap();
        parse_hex("60", &mut b).unwrap();
        parse_hex("0c", &mut b).unwrap();
        assert_eq!(b, [0x01, 0x06, 0x60, 0x0C]);
        assert!(parse_hex("123", &mut b).is_err());
        assert!(parse_hex("zz", &mut b).is_err());
        assert!(parse_hex("+1", &mut b).is_err());
        assert!(parse_hex("é", &mut b).is_err());
        assert_eq!(hex(&[0x01, 0xAB]), "01 AB");
    }
}
