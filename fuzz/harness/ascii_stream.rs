//! The Modbus ASCII [`Framer`] fed a timed byte stream, against a reference decoder written here
//! from the serial-line spec (§2.5.2) and independent of the framer's code.
//!
//! The input is the chunks of [`oracle::chunks`], timed around the spec's one-second
//! inter-character timeout. A chunk whose first byte is 0xFF (0xFE) is an ADU to send as a good
//! line in upper (lower) case: so that the fuzzer reaches whole frames with a matching LRC; any
//! other chunk is sent as it is (noise, or lines of its own). The harness drives the framer as a
//! slave would: bytes as they come, and `expire` at the framer's deadline unless the timer is
//! late. After every call the framer's outcomes, deadline and state must be the reference's.

use super::oracle::{self, Timing};
use drive_core::Instant;
use drive_core::ascii::{DEFAULT_TIMEOUT_MICROS, Framer, MAX_LINE, RxError, encode};

/// The inter-character timeout the harness runs: the spec's default.
pub const TIMEOUT: u64 = DEFAULT_TIMEOUT_MICROS;

/// The stream's timing for [`oracle::chunks`]: silences around the timeout where the RTU
/// targets have t1.5 and t3.5, characters of 10 bits at 9600 baud, and bytes spaced one at a
/// time across the timeout.
pub const TIMING: Timing = Timing { t15: TIMEOUT, t35: TIMEOUT, char: 1042, step: TIMEOUT / 28 };

/// What a receiver reports for one byte or one timer call.
pub type Outcome = Result<Vec<u8>, RxError>;

/// The most hex digits between `:` and CR: the ADU of 254 bytes and its LRC.
const MAX_DIGITS: usize = MAX_LINE - 3;

/// A line receiver written from the spec: it keeps the characters of the line in progress and
/// decodes them only when CR LF ends it. (The slave's harness, `ascii_slave`, frames with it too.)
#[derive(Default)]
pub struct Reference {
    /// The characters after `:` of the frame in progress.
    line: Option<Vec<u8>>,
    last: u64,
}

impl Reference {
    /// Idle: waiting for a `:`.
    pub fn new() -> Self {
        Self::default()
    }

    fn timed_out(&self, t: u64) -> bool {
        self.line.is_some() && t - self.last > TIMEOUT
    }

    /// The line is still silent at `t`: a frame in progress times out.
    pub fn timer(&mut self, t: u64) -> Option<Outcome> {
        self.timed_out(t).then(|| {
            self.line = None;
            Err(RxError::Timeout)
        })
    }

    /// When the frame in progress times out if nothing more comes.
    pub fn deadline(&self) -> Option<u64> {
        self.line.as_ref().map(|_| self.last + TIMEOUT + 1)
    }

    /// Byte `b` arrives at `t`: a frame's ADU at its LF, the reason a frame was dropped, or
    /// nothing.
    pub fn byte(&mut self, t: u64, b: u8) -> Option<Outcome> {
        let timeout = self.timer(t);
        if b == b':' {
            // A `:` always starts a frame; the one it interrupts is dropped.
            let restart = self.line.replace(Vec::new()).map(|_| Err(RxError::Restart));
            self.last = t;
            return timeout.or(restart);
        }
        if timeout.is_some() {
            return timeout;
        }
        let line = self.line.as_mut()?;
        self.last = t;
        line.push(b);
        let n = line.len();
        let verdict = if n >= 2 && line[n - 2] == b'\r' {
            if b == b'\n' { Some(decode(&line[..n - 2])) } else { Some(Err(RxError::BadChar)) }
        } else if b == b'\r' {
            None
        } else if !b.is_ascii_hexdigit() {
            Some(Err(RxError::BadChar))
        } else if n > MAX_DIGITS {
            Some(Err(RxError::Overrun))
        } else {
            None
        };
        if verdict.is_some() {
            self.line = None;
        }
        verdict
    }
}

/// The frame of a line's hex digits (all checked to be hex digits): its ADU, or what is wrong.
fn decode(digits: &[u8]) -> Outcome {
    if !digits.len().is_multiple_of(2) {
        return Err(RxError::OddLength);
    }
    if digits.len() < 6 {
        return Err(RxError::TooShort);
    }
    let bytes: Vec<u8> = digits
        .chunks(2)
        .map(|p| u8::from_str_radix(std::str::from_utf8(p).expect("hex digits"), 16).expect("hex digits"))
        .collect();
    // The LRC makes the bytes sum to 0 modulo 256.
    if !bytes.iter().map(|&b| u32::from(b)).sum::<u32>().is_multiple_of(256) {
        return Err(RxError::Lrc);
    }
    Ok(bytes[..bytes.len() - 1].to_vec())
}

struct Harness {
    framer: Framer,
    reference: Reference,
    now: u64,
}

impl Harness {
    fn check_state(&self) {
        assert_eq!(self.framer.deadline().map(Instant::as_micros), self.reference.deadline(), "deadline");
        assert_eq!(self.framer.in_frame(), self.reference.line.is_some(), "in a frame");
    }
}

impl oracle::Line for Harness {
    fn now(&self) -> u64 {
        self.now
    }

    fn advance(&mut self, to: u64, late: bool) {
        if !late {
            while let Some(d) = self.framer.deadline().map(Instant::as_micros) {
                if d > to {
                    break;
                }
                let got = self.framer.expire(Instant::from_micros(d));
                assert_eq!(got.map(Err), self.reference.timer(d), "timer at {d}");
                self.check_state();
            }
        }
        self.now = to;
    }

    /// Bytes arriving together, in one call.
    fn rx(&mut self, bytes: &[u8]) {
        let now = Instant::from_micros(self.now);
        let mut got = Vec::new();
        if let [b] = bytes {
            got.extend(self.framer.push(now, *b).map(|r| r.map(<[u8]>::to_vec)));
        } else {
            self.framer.extend(now, bytes, |r| got.push(r.map(<[u8]>::to_vec)));
        }
        let expected: Vec<Outcome> = bytes.iter().filter_map(|&b| self.reference.byte(self.now, b)).collect();
        assert_eq!(got, expected, "outcomes of {:?} at {}", String::from_utf8_lossy(bytes), self.now);
        self.check_state();
    }
}

/// The bytes a chunk sends: a good line for a marked ADU, else the chunk itself.
pub fn line_of(bytes: &[u8]) -> Vec<u8> {
    let mut out = [0u8; MAX_LINE];
    match bytes {
        [m @ (0xFE | 0xFF), adu @ ..] => match encode(adu, &mut out) {
            Some(n) => {
                let mut l = out[..n].to_vec();
                if *m == 0xFE {
                    l.make_ascii_lowercase();
                }
                l
            }
            None => bytes.to_vec(),
        },
        _ => bytes.to_vec(),
    }
}

/// One execution.
pub fn run(data: &[u8]) {
    let mut h = Harness { framer: Framer::new(TIMEOUT), reference: Reference::new(), now: 0 };
    // Then silence: a frame left in progress times out.
    oracle::replay_as(data, TIMING, &mut h, |b| line_of(b).into(), TIMEOUT + 1);
    assert!(!h.framer.in_frame(), "a frame outlived the timeout");
}
