//! RTU framing by line silence (Modbus over serial line V1.02, §2.5.1.1).
//!
//! Bytes arrive with time stamps; a frame ends after t3.5 of silence. A gap of more than t1.5
//! inside a frame spoils the whole frame, which is then dropped when it ends.

use crate::units::{Baud, Instant};

/// The longest RTU frame: address, 253-byte PDU, CRC.
pub const MAX_FRAME: usize = 256;

/// What the receiver found wrong with a frame, or that it is fine.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RxError {
    /// A silence longer than t1.5 between two characters: inside a frame, or (`after_frame`)
    /// after bytes that made a whole frame with its CRC, a frame that a next one followed
    /// before t3.5.
    Gap {
        /// The bytes before the silence were a whole frame (address, function, CRC).
        after_frame: bool,
    },
    /// More than [`MAX_FRAME`] bytes.
    Overrun,
}

/// The bytes of a Modbus write's reply before its CRC: address, function, register, value or
/// count.
pub const HEAD: usize = 6;

/// Assembles frames from time-stamped bytes.
#[derive(Clone, Debug)]
pub struct Framer {
    buf: [u8; MAX_FRAME],
    len: usize,
    /// When the last byte arrived; meaningful while `len > 0`.
    last: Instant,
    error: Option<RxError>,
    /// CRC register over the bytes received so far: computed as they arrive, so that the check
    /// at the end of the frame costs nothing (as a receive interrupt would do it).
    crc: u16,
    /// The CRC register after the frame's first [`HEAD`] bytes: a Modbus write's reply echoes
    /// them, so its CRC is known when the request has come (the receive path pays a comparison
    /// a byte).
    head_crc: u16,
    t15: u64,
    t35: u64,
}

impl Framer {
    /// An idle receiver timed for `baud`.
    pub const fn new(baud: Baud) -> Self {
        Self {
            buf: [0; MAX_FRAME],
            len: 0,
            last: Instant::from_micros(0),
            error: None,
            crc: crate::crc::INIT,
            head_crc: crate::crc::INIT,
            t15: baud.t15_micros(),
            t35: baud.t35_micros(),
        }
    }

    /// The CRC register over the frame's first [`HEAD`] bytes; while fewer have come, a stale
    /// value.
    pub fn head_crc(&self) -> u16 {
        self.head_crc
    }

    /// t3.5 in microseconds.
    pub const fn t35_micros(&self) -> u64 {
        self.t35
    }

    /// Whether the frame being received has ended: the line has been quiet for t3.5 at `now`.
    pub fn ended(&self, now: Instant) -> bool {
        self.len > 0 && now.since(self.last) >= self.t35
    }

    /// When the frame being received ends if nothing more arrives.
    pub fn deadline(&self) -> Option<Instant> {
        (self.len > 0).then(|| self.last.plus_micros(self.t35))
    }

    /// Adds one byte received at `now`. The caller first takes an ended frame ([`Framer::ended`]).
    pub fn push(&mut self, now: Instant, byte: u8) {
        self.extend(now, &[byte]);
    }

    /// Adds bytes received together at `now` (no silence between them). The caller first takes
    /// an ended frame ([`Framer::ended`]).
    pub fn extend(&mut self, now: Instant, bytes: &[u8]) {
        // No bytes is no event on the line: neither a gap nor a new end of silence.
        if bytes.is_empty() {
            return;
        }
        if self.len > 0 && now.since(self.last) > self.t15 {
            self.error.get_or_insert(RxError::Gap { after_frame: self.crc_ok() });
        }
        self.last = now;
        // Byte by byte: a frame's last byte usually comes alone (a receive interrupt), where a
        // call to memcpy, or a loop set up for many bytes, would cost more than the copy. Length
        // and CRC in locals, so that the compiler keeps them in registers.
        let (mut len, mut crc) = (self.len, self.crc);
        for &b in bytes {
            let Some(slot) = self.buf.get_mut(len) else {
                self.error = Some(RxError::Overrun);
                break;
            };
            *slot = b;
            len += 1;
            crc = crate::crc::update(crc, b);
            if len == HEAD {
                self.head_crc = crc;
            }
        }
        (self.len, self.crc) = (len, crc);
    }

    /// The received frame (whatever its state), and what went wrong while receiving it.
    pub fn frame(&self) -> (&[u8], Option<RxError>) {
        (self.buf.get(..self.len).unwrap_or_default(), self.error)
    }

    /// The frame buffer, to process an ended frame in place.
    pub fn frame_mut(&mut self) -> &mut [u8] {
        self.buf.get_mut(..self.len).unwrap_or_default()
    }

    /// Forgets the frame; the next byte starts a new one.
    pub fn clear(&mut self) {
        self.len = 0;
        self.error = None;
        self.crc = crate::crc::INIT;
    }

    /// Whether the frame holds an address, a function code and a CRC that matches the bytes
    /// before it (the CRC register run over a frame and its own CRC ends at 0).
    pub fn crc_ok(&self) -> bool {
        self.len >= 4 && self.crc == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(us: u64) -> Instant {
        Instant::from_micros(us)
    }

    #[test]
    fn frame_ends_after_t35_not_before() {
        let mut f = Framer::new(Baud::FACTORY);
        f.push(at(0), 1);
        f.push(at(1000), 2);
        assert!(!f.ended(at(1000 + 4009)));
        assert!(f.ended(at(1000 + 4010)));
        assert_eq!(f.deadline(), Some(at(5010)));
        assert_eq!(f.frame(), (&[1u8, 2][..], None));
    }

    #[test]
    fn gap_over_t15_spoils_frame() {
        let mut f = Framer::new(Baud::FACTORY);
        f.push(at(0), 1);
        f.push(at(1718), 2);
        assert_eq!(f.frame().1, None);
        f.push(at(1718 + 1719), 3);
        assert_eq!(f.frame().1, Some(RxError::Gap { after_frame: false }));
    }

    #[test]
    fn the_head_crc_is_the_crc_of_the_first_bytes() {
        let mut f = Framer::new(Baud::FACTORY);
        let frame = [1u8, 0x10, 0x20, 0x03, 0x00, 0x01, 0x02, 0x00, 0x32, 0xAA, 0xBB];
        f.extend(at(0), &frame[..3]);
        f.extend(at(10), &frame[3..]);
        assert_eq!(f.head_crc(), crate::crc::update_bytes(crate::crc::INIT, &frame[..HEAD]));
    }

    #[test]
    fn overrun_after_256_bytes() {
        let mut f = Framer::new(Baud::new(115_200).unwrap_or(Baud::FACTORY));
        for i in 0..=MAX_FRAME {
            f.push(at(i as u64), 0);
        }
        assert_eq!(f.frame().0.len(), MAX_FRAME);
        assert_eq!(f.frame().1, Some(RxError::Overrun));
    }
}
