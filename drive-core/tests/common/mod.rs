//! Helpers shared by the drive-core tests: frames with CRC, a clocked exchange, state snapshots.
#![allow(dead_code, missing_docs)]

use drive_core::od::OBJECTS;
use drive_core::{Drive, Instant, crc};

/// `body` followed by its CRC, low byte first.
pub fn frame(body: &[u8]) -> Vec<u8> {
    let mut f = body.to_vec();
    f.extend_from_slice(&crc::crc16(body).to_le_bytes());
    f
}

/// A drive with a clock that the test moves.
pub struct Bus {
    pub drive: Drive,
    pub now: u64,
}

impl Bus {
    pub fn new(drive: Drive) -> Self {
        Self { drive, now: 1_000_000 }
    }

    pub fn factory() -> Self {
        Self::new(Drive::factory())
    }

    /// Sends `bytes` at the current time (all at once, as a pseudo-terminal delivers them).
    pub fn send(&mut self, bytes: &[u8]) {
        self.drive.on_rx(Instant::from_micros(self.now), bytes);
    }

    /// Lets `us` microseconds pass, firing the timer at its deadline; returns every reply sent.
    pub fn wait(&mut self, us: u64) -> Vec<Vec<u8>> {
        let end = self.now + us;
        let mut replies = Vec::new();
        while let Some(d) = self.drive.deadline() {
            if d.as_micros() > end {
                break;
            }
            self.now = self.now.max(d.as_micros());
            self.drive.on_timer(Instant::from_micros(self.now));
            replies.extend(self.drive.take_reply().map(<[u8]>::to_vec));
        }
        self.now = end;
        replies
    }

    /// Sends a frame (CRC appended) and returns the reply after the line has been quiet long enough.
    pub fn request(&mut self, body: &[u8]) -> Option<Vec<u8>> {
        self.send(&frame(body));
        let replies = self.wait(10_000);
        assert!(replies.len() <= 1, "one request, at most one reply: {replies:02X?}");
        replies.into_iter().next()
    }

    /// Every object's value and the drive's status: equal snapshots mean nothing changed.
    pub fn snapshot(&self) -> Vec<u32> {
        let st = self.drive.state();
        OBJECTS.iter().map(|d| st.read(d.obj)).collect()
    }
}

/// The reply `body` would get: `body` with its CRC.
pub fn reply(body: &[u8]) -> Option<Vec<u8>> {
    Some(frame(body))
}
