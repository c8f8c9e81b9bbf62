//! Framing by logic for a line without baud timing (QEMU's serial port paces bytes about 1 ms
//! apart whatever the baud rate, far beyond t1.5): a request ends when it holds as many bytes
//! as its function code says, or after a silence long enough for any real pause (the caller's
//! choice; longer while [`Assembler::expects_more`], since the host may stall the line).
//!
//! The frame is then handed to the drive as if it had arrived in one burst, t3.5 before "now",
//! so drive-core's own framer, CRC check and counters see a well-timed frame.

/// The longest RTU frame.
pub const MAX_FRAME: usize = drive_core::rtu::MAX_FRAME;

/// The length of the RTU request that starts with `head`, once `head` holds enough of it to
/// tell; `None` while it does not, or for function codes whose length the request cannot tell
/// (those end by silence). `sub_index` is the bytes a map puts after a register address in
/// 03, 06 and 16 (the EC-57 map's sub-index: 1; every other map: 0).
pub fn request_len(head: &[u8], sub_index: usize) -> Option<usize> {
    let &fc = head.get(1)?;
    let counted = |at: usize, fixed: usize| head.get(at).map(|&n| fixed + usize::from(n));
    match fc {
        // Reads and single writes: address, code, register (and sub-index), 2 bytes, CRC.
        0x03 | 0x06 => Some(8 + sub_index),
        // Bits, input registers and diagnostics: address, code, 4 bytes, CRC.
        0x01 | 0x02 | 0x04 | 0x05 | 0x08 => Some(8),
        // Exception status, event counter and log, report server id: address, code, CRC.
        0x07 | 0x0B | 0x0C | 0x11 => Some(4),
        // Multiple registers: address, code, start (and sub-index), quantity, byte count, data, CRC.
        0x10 => counted(6 + sub_index, 9 + sub_index),
        0x0F => counted(6, 9),
        // Read/write multiple: two start/quantity pairs, byte count, data, CRC.
        0x17 => counted(10, 13),
        // Read and write file record: byte count, sub-requests, CRC.
        0x14 | 0x15 => counted(2, 5),
        // Read device identification (MEI 0x0E): MEI type, code, object id, CRC.
        0x2B => Some(7),
        // Mask write: reference, AND mask, OR mask, CRC.
        0x16 => Some(10),
        _ => None,
    }
}

/// Collects the bytes of one request.
pub struct Assembler {
    buf: [u8; MAX_FRAME],
    len: usize,
    sub_index: usize,
}

impl Assembler {
    /// Nothing received, for a map whose requests carry `sub_index` bytes after a register
    /// address (see [`request_len`]).
    pub const fn new(sub_index: usize) -> Self {
        Self { buf: [0; MAX_FRAME], len: 0, sub_index }
    }

    /// Adds a byte; true when the request is complete (its length reached, or the buffer full).
    pub fn push(&mut self, byte: u8) -> bool {
        if let Some(slot) = self.buf.get_mut(self.len) {
            *slot = byte;
            self.len += 1;
        }
        self.len == MAX_FRAME || request_len(self.bytes(), self.sub_index).is_some_and(|n| self.len >= n)
    }

    /// The bytes received so far.
    pub fn bytes(&self) -> &[u8] {
        self.buf.get(..self.len).unwrap_or_default()
    }

    /// Whether the bytes so far start a request whose length is known and not yet reached.
    pub fn expects_more(&self) -> bool {
        request_len(self.bytes(), self.sub_index).is_some_and(|n| self.len < n)
    }

    /// Whether nothing has been received.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Forgets the request; the next byte starts another.
    pub fn clear(&mut self) {
        self.len = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn complete_after(frame: &[u8]) -> Option<usize> {
        complete_after_in(frame, 0)
    }

    fn complete_after_in(frame: &[u8], sub_index: usize) -> Option<usize> {
        let mut a = Assembler::new(sub_index);
        frame.iter().position(|&b| a.push(b)).map(|i| i + 1)
    }

    #[test]
    fn fixed_length_requests_end_at_their_length() {
        assert_eq!(complete_after(&[1, 3, 0x60, 0, 0, 2, 0xDB, 0xCB, 9, 9]), Some(8));
        assert_eq!(complete_after(&[1, 0x2B, 0x0E, 1, 0, 0x70, 0x77]), Some(7));
        assert_eq!(complete_after(&[1, 0x07, 0x41, 0xE2]), Some(4));
    }

    #[test]
    fn counted_requests_end_after_their_data() {
        // 0x10: two registers, four data bytes.
        let f = [1, 0x10, 0x60, 0x05, 0, 2, 4, 0, 0, 0, 100, 0xAA, 0xBB];
        assert_eq!(complete_after(&f), Some(13));
        let mut g = [0u8; 20];
        g[1] = 0x17;
        g[10] = 2;
        assert_eq!(complete_after(&g), Some(15));
    }

    #[test]
    fn sub_indexed_requests_are_a_byte_longer() {
        // EC-57 (seed 003): `01 03 20 00 00 00 01` reads 0x2000 sub-index 0.
        assert_eq!(complete_after_in(&[1, 3, 0x20, 0, 0, 0, 1, 0xAA, 0xBB, 9], 1), Some(9));
        assert_eq!(complete_after_in(&[1, 6, 0x20, 5, 0, 0, 1, 0xAA, 0xBB, 9], 1), Some(9));
        // 16 with two registers: the byte count after the sub-index and the quantity.
        let f = [1, 0x10, 0x20, 0, 0, 0, 2, 4, 0, 1, 0, 2, 0xAA, 0xBB];
        assert_eq!(complete_after_in(&f, 1), Some(14));
        // The identification request has no register address.
        assert_eq!(complete_after_in(&[1, 0x2B, 0x0E, 1, 0, 0x70, 0x77], 1), Some(7));
    }

    #[test]
    fn a_partial_request_of_known_length_expects_more() {
        let mut a = Assembler::new(0);
        assert!(!a.expects_more());
        a.push(1);
        assert!(!a.expects_more(), "the function code is not known yet");
        a.push(3);
        assert!(a.expects_more());
        a.clear();
        a.push(1);
        a.push(0x41);
        assert!(!a.expects_more(), "unknown code: silence ends it");
    }

    #[test]
    fn unknown_codes_wait_for_silence_and_overruns_end_at_the_buffer() {
        assert_eq!(complete_after(&[1, 0x41, 0, 0, 0, 0, 0, 0, 0, 0]), None);
        assert_eq!(complete_after(&[1, 0x41].repeat(200)), Some(MAX_FRAME));
        assert_eq!(request_len(&[1], 0), None);
        assert_eq!(request_len(&[1, 0x10, 0, 0, 0, 1], 0), None);
    }
}
