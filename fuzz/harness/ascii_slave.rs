//! A timed byte stream of Modbus ASCII lines and noise fed to a drive in ASCII mode (0x2192 = 1,
//! native map, address 1), against the spec's line receiver of `ascii_stream` and an RTU twin.
//!
//! The input is the chunks of [`oracle::chunks`] on `ascii_stream`'s timing (silences around the
//! one-second inter-character timeout, bytes one at a time across it, timers late). A chunk
//! whose first byte is 0xFF (0xFE) is an ADU sent as a good line in upper (lower) case, 0xFD
//! (0xFC) a PDU sent so to address 1, so that the fuzzer reaches requests the drive serves; any
//! other chunk is sent as it is (noise, broken lines, lines of its own).
//!
//! The harness models when the drive serves a line: a line that ended at its LF (with a good
//! LRC or a bad one) waits until the timer, the next call's bytes, or a `:` behind it in the same
//! call. After every call:
//!
//! - the drive's deadline is the model's: the time of the call that ended a waiting line, else
//!   the reference's inter-character timeout;
//! - a reply is a well-formed line (`:`, upper-case hex digits of an even count, its LRC, CR LF)
//!   from address 1, and only after a call that served a good line;
//! - its ADU is the reply an RTU drive (the twin) gives to the same frames as RTU frames: the
//!   twin's reply to the one line served, or to one of them if a call served several (a master
//!   that does not wait for an answer). Counters of dropped frames (0x08, sub-functions 0x0C and
//!   0x12) differ by design: the twin never sees a dropped line.

use super::ascii_stream::{Reference, TIMEOUT, TIMING, line_of};
use super::oracle;
use drive_core::ascii::{RxError, lrc};
use drive_core::od::Obj;
use drive_core::{Drive, DriveConfig, Instant, Params};
use std::sync::OnceLock;

/// When the stream starts: late enough for the twin to receive its first frame t3.5 before.
const START: u64 = 1_000_000;

/// t3.5 at the twin's 9600 baud, rounded up: the twin receives a frame this long before it
/// serves it.
const T35: u64 = 4011;

/// Factory drives built once: each execution clones them. The ASCII drive, and its RTU twin.
/// The ASCII drive's 0x2192 reads 0 as the twin's: the framing stays the one of power-up.
fn factory() -> (Drive, Drive) {
    static DRIVES: OnceLock<(Drive, Drive)> = OnceLock::new();
    DRIVES
        .get_or_init(|| {
            let mut p = Params::factory();
            assert!(p.set(Obj::LineFraming, 1));
            let mut ascii = Drive::boot(DriveConfig::default(), &p, 0);
            // The object back at the twin's 0, as if written since power-up (in force at the
            // next): both read the same.
            ascii.state_mut().write_def(Obj::LineFraming.def(), 0).expect("0x2192 = 0");
            (ascii, Drive::factory())
        })
        .clone()
}

/// A line that ended and waits in the drive, as the model has it.
enum Waiting {
    /// A good line's ADU.
    Frame(Vec<u8>),
    /// A line with a bad LRC (dropped when served: the native map answers no spoilt frame).
    Lrc,
}

struct Harness {
    drive: Drive,
    twin: Drive,
    reference: Reference,
    /// The line that waits, and when the call that ended it came.
    waiting: Option<(Waiting, u64)>,
    /// The good lines served in the call being checked.
    served: Vec<Vec<u8>>,
    now: u64,
}

impl Harness {
    fn serve_waiting(&mut self) {
        if let Some((Waiting::Frame(adu), _)) = self.waiting.take() {
            self.served.push(adu);
        }
    }

    fn deadline(&self) -> Option<u64> {
        match self.waiting {
            Some((_, at)) => Some(at),
            None => self.reference.deadline(),
        }
    }

    /// Checks the drive after a call against the model, and its reply against the twin's.
    fn check(&mut self) {
        assert_eq!(self.drive.deadline().map(Instant::as_micros), self.deadline(), "deadline");
        assert_eq!(self.drive.frame_due(Instant::from_micros(self.now)), self.waiting.is_some(), "frame due");
        let served = std::mem::take(&mut self.served);
        let mut expected = Vec::new();
        for adu in &served {
            let mut frame = adu.clone();
            frame.extend(drive_core::crc::crc16(adu).to_le_bytes());
            // Received t3.5 before, served at the same time as the line: a request's effects
            // depend on when it is served (a write refused while a move it started runs).
            self.twin.on_rx(Instant::from_micros(self.now - T35), &frame);
            self.twin.on_timer(Instant::from_micros(self.now));
            let reply = self.twin.take_reply().map(|r| r[..r.len() - 2].to_vec());
            expected.push((adu, reply));
        }
        let Some(reply) = self.drive.take_reply() else { return };
        let got = adu_of(reply);
        assert_eq!(got.first(), Some(&oracle::ADDR), "a reply from another address: {}", text(reply));
        let matches = |(req, want): &(&Vec<u8>, Option<Vec<u8>>)| match want {
            Some(want) if counts_dropped(req) => want.len() == got.len() && want.get(..4) == got.get(..4),
            Some(want) => *want == got,
            None => false,
        };
        assert!(
            expected.iter().any(matches),
            "reply {} to none of the lines served ({served:02X?}); the twin's: {expected:02X?}",
            text(reply)
        );
    }
}

/// Whether `req` reads a counter of dropped frames, which the twin does not see.
fn counts_dropped(req: &[u8]) -> bool {
    matches!(req, [_, 0x08, 0x00, 0x0C | 0x12, ..])
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// The ADU of a reply line, checked to be well formed.
fn adu_of(line: &[u8]) -> Vec<u8> {
    let hex = match line {
        [b':', hex @ .., b'\r', b'\n'] => hex,
        _ => panic!("not a line: {}", text(line)),
    };
    assert!(hex.len().is_multiple_of(2) && hex.len() >= 6, "odd or short: {}", text(line));
    let digit = |c: u8| match c {
        b'0'..=b'9' => c - b'0',
        b'A'..=b'F' => c - b'A' + 10,
        _ => panic!("not an upper-case hex digit {c:02X}: {}", text(line)),
    };
    let bytes: Vec<u8> = hex.chunks(2).map(|p| digit(p[0]) << 4 | digit(p[1])).collect();
    let (check, adu) = bytes.split_last().expect("bytes");
    assert_eq!(lrc(adu), *check, "LRC: {}", text(line));
    adu.to_vec()
}

impl oracle::Line for Harness {
    fn now(&self) -> u64 {
        self.now
    }

    fn advance(&mut self, to: u64, late: bool) {
        if !late {
            while let Some(d) = self.drive.deadline().map(Instant::as_micros) {
                if d > to {
                    break;
                }
                assert_eq!(Some(d), self.deadline(), "deadline");
                self.now = self.now.max(d);
                self.drive.on_timer(Instant::from_micros(self.now));
                if self.waiting.is_some() {
                    self.serve_waiting();
                } else {
                    self.reference.timer(self.now);
                }
                self.check();
            }
        }
        self.now = self.now.max(to);
    }

    fn rx(&mut self, bytes: &[u8]) {
        self.drive.on_rx(Instant::from_micros(self.now), bytes);
        // The line that waited is served first; one that ends in these bytes before a `:` is
        // served before it.
        self.serve_waiting();
        for &b in bytes {
            if b == b':' {
                self.serve_waiting();
            }
            match self.reference.byte(self.now, b) {
                Some(Ok(adu)) => self.waiting = Some((Waiting::Frame(adu), self.now)),
                Some(Err(RxError::Lrc)) => self.waiting = Some((Waiting::Lrc, self.now)),
                _ => {}
            }
        }
        self.check();
    }
}

/// The bytes a chunk sends: [`line_of`]'s, and a line to address 1 for a marked PDU.
fn slave_line_of(bytes: &[u8]) -> Vec<u8> {
    match bytes {
        [m @ (0xFC | 0xFD), pdu @ ..] => {
            let mut marked = vec![if *m == 0xFD { 0xFF } else { 0xFE }, oracle::ADDR];
            marked.extend(pdu);
            line_of(&marked)
        }
        _ => line_of(bytes),
    }
}

/// One execution.
pub fn run(data: &[u8]) {
    let (drive, twin) = factory();
    let mut h = Harness { drive, twin, reference: Reference::new(), waiting: None, served: Vec::new(), now: START };
    // Then silence: a line that waits is served, one in progress times out.
    oracle::replay_as(data, TIMING, &mut h, |b| slave_line_of(b).into(), TIMEOUT + 1);
    assert!(h.waiting.is_none() && h.drive.deadline().is_none(), "a line outlived the silence");
}
