//! A byte stream with timing, fed to a factory drive (address 1, 9600 baud).
//!
//! The input is a sequence of chunks `[gap, len, bytes..]`:
//!
//! - `gap % 8` chooses the silence before the chunk, `gap / 8` (0..=31) fine-tunes it:
//!   0 none, 1 a few µs, 2 around t1.5 (1718 µs), 3 around t3.5 (4010 µs), 4 about one character
//!   (1146 µs), 5 long (t3.5 + up to 155 ms), 6 like 5 but the platform's timer is late (no
//!   `on_timer` at the deadline: `on_rx` must find the ended frame itself), 7 none, and the
//!   chunk's bytes arrive one at a time, `(gap / 8) * 64` µs apart (0..1984 µs, across t1.5);
//! - `len` bytes follow (fewer if the input ends); otherwise they arrive in one `on_rx` call.
//!
//! Whenever time passes the drive's `deadline()` (and the timer is not late) `on_timer` is called
//! at the deadline. After every call, every reply is checked against a reference framer written
//! here from the spec (a frame ends after t3.5 of silence, a silence over t1.5 inside it spoils it):
//! a reply must answer the frame that just ended, which must have reached address 1 with a good
//! CRC, no gap and at most 256 bytes; it must be 5..=256 bytes, CRC-valid, from address 1, with
//! the request's function code (or that | 0x80 and an exception code 1..=4, 5 bytes), and shaped
//! as that function's reply.
#![no_main]

use drive_core::{Drive, Instant, crc};
use libfuzzer_sys::fuzz_target;

/// The drive's address.
const ADDR: u8 = 1;
/// t1.5 and t3.5 at 9600 baud, as the spec rounds them down.
const T15: u64 = 1718;
const T35: u64 = 4010;
/// One 11-bit character at 9600 baud.
const CHAR: u64 = 1146;

/// CRC-16/MODBUS bit by bit, independent of the drive's table-driven one.
fn crc16_bitwise(bytes: &[u8]) -> u16 {
    let mut crc = 0xFFFFu16;
    for &b in bytes {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xA001 } else { crc >> 1 };
        }
    }
    crc
}

fn crc_ok(frame: &[u8]) -> bool {
    frame.len() >= 3 && {
        let (body, sum) = frame.split_at(frame.len() - 2);
        crc16_bitwise(body) == u16::from_le_bytes([sum[0], sum[1]])
    }
}

/// What the reference framer made of a frame that ended.
#[derive(Debug)]
enum Ended {
    /// A frame the drive must not answer (other address, broadcast, bad CRC, gap, overrun,
    /// exception function code, too short).
    Ignored,
    /// A request frame to this drive, which it may answer (it may also stay silent, e.g. in
    /// listen-only mode).
    Request(Vec<u8>),
}

/// Framing by line silence, from the spec.
#[derive(Default)]
struct Reference {
    cur: Vec<u8>,
    last: u64,
    gap: bool,
    ended: Option<Ended>,
}

impl Reference {
    fn close(&mut self) {
        let f = std::mem::take(&mut self.cur);
        // A frame needs an address, a function code and a CRC: four bytes at least.
        let good = !self.gap && (4..=256).contains(&f.len()) && crc_ok(&f) && f[0] == ADDR;
        self.gap = false;
        let e = if !good {
            Ended::Ignored
        } else if f[1] & 0x80 != 0 {
            Ended::Ignored
        } else {
            Ended::Request(f)
        };
        assert!(self.ended.is_none(), "two frames ended in one call");
        self.ended = Some(e);
    }

    fn byte(&mut self, t: u64, b: u8) {
        if !self.cur.is_empty() {
            let since = t - self.last;
            if since >= T35 {
                self.close();
            } else if since > T15 {
                self.gap = true;
            }
        }
        self.cur.push(b);
        self.last = t;
    }

    fn timer(&mut self, t: u64) {
        if !self.cur.is_empty() && t - self.last >= T35 {
            self.close();
        }
    }

    fn deadline(&self) -> Option<u64> {
        (!self.cur.is_empty()).then(|| self.last + T35)
    }
}

fn be16(b: &[u8], at: usize) -> usize {
    usize::from(u16::from_be_bytes([b[at], b[at + 1]]))
}

/// Checks the drive's reply (if any) against the frame that ended during the last call.
fn check(drive: &mut Drive, reference: &mut Reference) {
    assert_eq!(
        drive.deadline().map(Instant::as_micros),
        reference.deadline(),
        "the drive's framer and the reference disagree on the frame in progress"
    );
    let ended = reference.ended.take();
    let Some(reply) = drive.take_reply() else { return };
    assert!((5..=256).contains(&reply.len()), "reply length {}: {reply:02X?}", reply.len());
    assert!(crc::frame_ok(reply), "bad CRC (drive's check): {reply:02X?}");
    assert!(crc_ok(reply), "bad CRC (bitwise check): {reply:02X?}");
    assert_eq!(reply[0], ADDR, "reply from the wrong address: {reply:02X?}");
    let req = match ended {
        Some(Ended::Request(f)) => f,
        other => panic!("reply {reply:02X?} without a request to answer (ended: {other:02X?})"),
    };
    let f = req[1];
    if reply[1] == f | 0x80 {
        assert_eq!(reply.len(), 5, "exception reply {reply:02X?} to {req:02X?}");
        assert!((1..=4).contains(&reply[2]), "exception code {reply:02X?} to {req:02X?}");
        return;
    }
    assert_eq!(reply[1], f, "function code of {reply:02X?} answering {req:02X?}");
    match f {
        0x03 | 0x04 | 0x17 => {
            let qty = be16(&req, 4);
            assert!((1..=125).contains(&qty), "read of {qty} answered: {req:02X?}");
            assert_eq!(usize::from(reply[2]), 2 * qty, "{reply:02X?} answering {req:02X?}");
            assert_eq!(reply.len(), 5 + 2 * qty, "{reply:02X?} answering {req:02X?}");
        }
        0x06 => assert_eq!(reply, &req[..], "0x06 is echoed"),
        0x10 => {
            assert_eq!(reply.len(), 8, "{reply:02X?} answering {req:02X?}");
            assert_eq!(reply[..6], req[..6], "{reply:02X?} answering {req:02X?}");
        }
        0x08 => {
            assert_eq!(reply[2..4], req[2..4], "sub-function echoed: {reply:02X?} answering {req:02X?}");
            if be16(&req, 2) == 0 {
                assert_eq!(reply, &req[..], "0x08/0x00 is echoed");
            }
        }
        0x2B => assert_eq!(reply[2], 0x0E, "{reply:02X?} answering {req:02X?}"),
        _ => panic!("normal reply {reply:02X?} to unsupported function {f:02X}"),
    }
}

struct Harness {
    drive: Drive,
    reference: Reference,
    now: u64,
}

impl Harness {
    /// Time passes to `to`; the timer fires at the deadline unless it is `late`.
    fn advance(&mut self, to: u64, late: bool) {
        if !late {
            while let Some(d) = self.drive.deadline().map(Instant::as_micros) {
                if d > to {
                    break;
                }
                self.drive.on_timer(Instant::from_micros(d));
                self.reference.timer(d);
                check(&mut self.drive, &mut self.reference);
            }
        }
        self.now = to;
    }

    fn rx(&mut self, bytes: &[u8]) {
        self.drive.on_rx(Instant::from_micros(self.now), bytes);
        for &b in bytes {
            self.reference.byte(self.now, b);
        }
        check(&mut self.drive, &mut self.reference);
    }
}

fuzz_target!(|data: &[u8]| {
    let mut h = Harness { drive: Drive::factory(), reference: Reference::default(), now: 0 };
    let mut rest = data;
    while let [gap, len, tail @ ..] = rest {
        let n = usize::from(*len).min(tail.len());
        let (bytes, next) = tail.split_at(n);
        rest = next;
        let j = u64::from(gap / 8);
        let (delta, late) = match gap % 8 {
            0 | 7 => (0, false),
            1 => (j, false),
            2 => (T15 - 16 + j, false),
            3 => (T35 - 16 + j, false),
            4 => (CHAR + j, false),
            5 => (T35 + j * 5000, false),
            _ => (T35 + j * 5000, true),
        };
        h.advance(h.now + delta, late);
        if gap % 8 == 7 {
            for (i, &b) in bytes.iter().enumerate() {
                if i > 0 {
                    h.advance(h.now + j * 64, false);
                }
                h.rx(&[b]);
            }
        } else if !bytes.is_empty() {
            h.rx(bytes);
        }
    }
    // The line falls silent: the last frame ends.
    h.advance(h.now + 1_000_000, false);
    h.drive.on_timer(Instant::from_micros(h.now));
    h.reference.timer(h.now);
    check(&mut h.drive, &mut h.reference);
});
