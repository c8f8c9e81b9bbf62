//! A timed byte stream ([`oracle::chunks`]) fed to a factory drive (address 1, 9600 baud).
//!
//! Whenever time passes the drive's `deadline()` (and the timer is not late) `on_timer` is called
//! at the deadline. After every call the drive's deadline must be the reference framer's, and any
//! reply must answer the frame that just ended, which must be a request to address 1 (no gap, no
//! overrun, good CRC), and be shaped as that function's reply ([`oracle::check_reply`]).

use super::oracle::{self, Line, Reference, Timing};
use drive_core::{Drive, Instant};
use std::sync::OnceLock;

/// A factory drive built once: each execution clones it, cheaper than building it.
fn factory() -> Drive {
    static DRIVE: OnceLock<Drive> = OnceLock::new();
    DRIVE.get_or_init(Drive::factory).clone()
}

/// Checks the drive against the reference after a call.
fn check(drive: &mut Drive, reference: &mut Reference) {
    assert_eq!(
        drive.deadline().map(Instant::as_micros),
        reference.deadline(),
        "the drive's framer and the reference disagree on the frame in progress"
    );
    let ended = reference.take();
    let Some(reply) = drive.take_reply() else { return };
    match ended.as_ref().and_then(|c| c.request()) {
        Some(req) => _ = oracle::check_reply(req, reply),
        None => panic!("reply {reply:02X?} without a request to answer (ended: {ended:02X?})"),
    }
}

struct Harness {
    drive: Drive,
    reference: Reference,
    now: u64,
}

impl Line for Harness {
    fn now(&self) -> u64 {
        self.now
    }

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

/// One execution.
pub fn run(data: &[u8]) {
    let timing = Timing::of(9600);
    let mut h = Harness { drive: factory(), reference: Reference::new(timing), now: 0 };
    oracle::replay(data, timing, &mut h);
    h.drive.on_timer(Instant::from_micros(h.now));
    h.reference.timer(h.now);
    check(&mut h.drive, &mut h.reference);
}
