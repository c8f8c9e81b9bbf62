//! The RTU [`Framer`] alone, fed a timed byte stream: framing gets many executions cheaply.
//!
//! The input is a baud selector byte (one of the seven supported rates) and then the chunks of
//! [`oracle::chunks`]. The harness drives the framer as `Drive` does (an ended frame is taken
//! before the next byte, or at the deadline by the timer unless it is late) and, after every call,
//! compares everything the framer shows with the reference framer: the deadline, whether the
//! frame has ended (one µs before the deadline and at it), the bytes kept, the error
//! (overrun, else gap), the CRC verdict, and each ended frame as it is taken.

use super::oracle::{self, Closed, Line, Reference, Timing};
use drive_core::rtu::Framer;
use drive_core::{Baud, Instant};

/// The rates the drive supports (object 0x202A).
const RATES: [u32; 7] = [4800, 9600, 19_200, 38_400, 51_200, 57_600, 115_200];

struct Harness {
    framer: Framer,
    reference: Reference,
    now: u64,
}

impl Harness {
    /// The framer's frame in progress is the reference's.
    fn check(&self) {
        let (f, r) = (&self.framer, &self.reference);
        assert_eq!(f.deadline().map(Instant::as_micros), r.deadline(), "deadline");
        // The length and the last byte: the bytes before were compared when they were last (all
        // are compared when the frame ends), and a full comparison per byte costs a frame's
        // length squared.
        let (bytes, error) = f.frame();
        assert_eq!((bytes.len(), bytes.last()), (r.kept().len(), r.kept().last()), "frame in progress");
        assert_eq!(error, r.error(), "error of the frame in progress ({} bytes)", bytes.len());
        assert_eq!(f.crc_ok(), r.crc_ok(), "CRC verdict on {bytes:02X?}");
        let now = Instant::from_micros(self.now);
        assert_eq!(f.ended(now), r.ends_by(self.now), "ended at {}", self.now);
    }

    /// The framer says its frame ended at `t`: it must be the frame the reference closed.
    fn take(&mut self, closed: Option<Closed>) {
        let Some(c) = closed else { panic!("the framer ended a frame the reference did not") };
        let (bytes, error) = self.framer.frame();
        assert_eq!(bytes, c.kept(), "bytes of the ended frame");
        assert_eq!(error, c.error(), "error of the ended frame ({} bytes, gap {:?})", c.bytes.len(), c.gap);
        assert_eq!(self.framer.crc_ok(), c.crc_ok, "CRC verdict on the ended frame {bytes:02X?}");
        let kept = bytes.to_vec();
        assert_eq!(self.framer.frame_mut(), &kept[..], "frame_mut");
        self.framer.clear();
        assert_eq!(self.framer.frame(), (&[][..], None), "a cleared frame");
        assert_eq!(self.framer.deadline(), None, "a cleared frame's deadline");
    }
}

impl Line for Harness {
    fn now(&self) -> u64 {
        self.now
    }

    fn advance(&mut self, to: u64, late: bool) {
        if !late {
            while let Some(d) = self.framer.deadline().map(Instant::as_micros) {
                if d > to {
                    break;
                }
                assert!(!self.framer.ended(Instant::from_micros(d - 1)), "ended before the deadline");
                assert!(self.framer.ended(Instant::from_micros(d)), "not ended at the deadline");
                self.reference.timer(d);
                let closed = self.reference.take();
                self.take(closed);
                self.now = d;
                self.check();
            }
        }
        self.now = to;
        self.check();
    }

    /// Bytes arrive together at `now` (never none: `Drive::on_rx` passes no empty call on).
    fn rx(&mut self, bytes: &[u8]) {
        let now = Instant::from_micros(self.now);
        for &b in bytes {
            self.reference.byte(self.now, b);
        }
        let closed = self.reference.take();
        if self.framer.ended(now) {
            self.take(closed);
        } else {
            assert!(closed.is_none(), "the reference ended a frame the framer did not: {closed:02X?}");
        }
        match bytes {
            [b] => self.framer.push(now, *b),
            _ => self.framer.extend(now, bytes),
        }
        self.check();
    }
}

/// One execution.
pub fn run(data: &[u8]) {
    let Some((&sel, stream)) = data.split_first() else { return };
    let bps = RATES[usize::from(sel) % RATES.len()];
    let timing = Timing::of(u64::from(bps));
    let Some(baud) = Baud::new(bps) else { panic!("{bps} baud is supported") };
    let framer = Framer::new(baud);
    assert_eq!(framer.t35_micros(), timing.t35, "t3.5 at {bps} baud");
    let mut h = Harness { framer, reference: Reference::new(timing), now: 0 };
    oracle::replay(stream, timing, &mut h);
    assert_eq!(h.framer.deadline(), None, "a frame outlived a second of silence");
}
