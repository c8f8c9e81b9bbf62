//! Modbus ASCII framing (Modbus over serial line V1.02, §2.5.2): a line `:`, two hexadecimal
//! characters a byte of address, function and data, the LRC, CR LF.
//!
//! A frame's end is its CR LF, not a silence: a good frame is ready at its LF, and the receiver
//! hands over the binary ADU (address, function, data), the bytes the RTU side hands the slave
//! once their CRC is checked. The LRC is checked as the characters arrive.
//!
//! Lower-case hex digits are accepted on receipt and never sent. The spec lists `0`-`9`, `A`-`F`,
//! but a lower-case digit cannot be taken for a framing character and means the same byte, so
//! refusing it would only turn away masters that send it (Python's `a2b_hex`, on which pymodbus's
//! ASCII framer decodes, reads both); replies are upper case, as the spec and the manual print them.

use crate::units::Instant;

/// The longest ADU: address, function code and 252 data bytes (a 253-byte PDU).
pub const MAX_ADU: usize = 254;

/// The longest line, the spec's 513 characters: `:`, the ADU and its LRC as hex, CR LF. Also
/// the size of a transmit buffer that holds any reply.
pub const MAX_LINE: usize = line_len(MAX_ADU);

/// The spec's default inter-character timeout in ASCII mode: one second.
pub const DEFAULT_TIMEOUT_MICROS: u64 = 1_000_000;

/// The fewest bytes a frame decodes to: address, function code, LRC.
const MIN_BYTES: usize = 3;

/// The length of the line that carries an ADU of `adu_len` bytes.
pub const fn line_len(adu_len: usize) -> usize {
    1 + 2 * (adu_len + 1) + 2
}

/// The LRC of `bytes`: the two's complement of their sum modulo 256, so that the bytes and their
/// LRC sum to 0.
///
/// The manual's example (a read of one register at 0201h from node 1):
/// ```
/// use drive_core::ascii::lrc;
/// // 01 + 03 + 02 + 01 + 00 + 01 = 08, whose two's complement is F8.
/// assert_eq!(lrc(&[0x01, 0x03, 0x02, 0x01, 0x00, 0x01]), 0xF8);
/// ```
pub fn lrc(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0u8, |s, &b| s.wrapping_add(b)).wrapping_neg()
}

/// Why a frame was dropped: one report per frame, so that the slave can count it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RxError {
    /// A character that is neither a hex digit nor the CR LF that ends the line (a CR not
    /// followed by LF included). The rest of the line is ignored up to the next `:`.
    BadChar,
    /// A `:` before the frame in progress ended: that frame is dropped and a new one starts.
    Restart,
    /// An odd number of hex digits.
    OddLength,
    /// Fewer bytes than address, function code and LRC.
    TooShort,
    /// More than [`MAX_LINE`] characters. The rest of the line is ignored up to the next `:`.
    Overrun,
    /// The LRC does not match the bytes before it.
    Lrc,
    /// A silence longer than the inter-character timeout inside the frame.
    Timeout,
}

/// Where the receiver is in a line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum State {
    /// Outside a frame: everything but `:` is ignored.
    Idle,
    /// After `:`, taking hex digits.
    Digits,
    /// After the CR that should end the frame.
    Cr,
}

/// Assembles ASCII frames from time-stamped bytes.
#[derive(Clone, Debug)]
pub struct Framer {
    /// The bytes decoded so far, the LRC last once the line is whole.
    buf: [u8; MAX_ADU + 1],
    /// The bytes in `buf`: of the frame in progress, or in [`State::Idle`] of the line that
    /// ended last ([`Framer::ended`]; 0 once another verdict or [`Framer::clear`] came).
    len: usize,
    /// The first digit of a byte whose second has not come yet.
    high: Option<u8>,
    /// The sum of the decoded bytes: 0 over a whole frame and its LRC.
    sum: u8,
    state: State,
    /// When the last byte arrived: of the frame in progress outside [`State::Idle`], of any
    /// byte after the line that ended last in it.
    last: Instant,
    timeout: u64,
}

impl Framer {
    /// An idle receiver that drops a frame after a silence of more than `timeout_micros` between
    /// two of its characters ([`DEFAULT_TIMEOUT_MICROS`] is the spec's).
    pub const fn new(timeout_micros: u64) -> Self {
        Self {
            buf: [0; MAX_ADU + 1],
            len: 0,
            high: None,
            sum: 0,
            state: State::Idle,
            last: Instant::from_micros(0),
            timeout: timeout_micros,
        }
    }

    /// The inter-character timeout in microseconds.
    pub const fn timeout_micros(&self) -> u64 {
        self.timeout
    }

    /// Whether a frame is in progress (a `:` came and its line has not ended).
    pub fn in_frame(&self) -> bool {
        self.state != State::Idle
    }

    /// The first instant at which the frame in progress has timed out if nothing more arrives:
    /// when to call [`Framer::expire`].
    pub fn deadline(&self) -> Option<Instant> {
        self.in_frame().then(|| self.last.plus_micros(self.timeout.saturating_add(1)))
    }

    /// Drops the frame in progress if the line has been silent for longer than the timeout at
    /// `now`, and says so. A frame that times out is reported once, here or at the next byte.
    pub fn expire(&mut self, now: Instant) -> Option<RxError> {
        (self.in_frame() && now.since(self.last) > self.timeout).then(|| self.drop_frame(RxError::Timeout))
    }

    /// Adds one byte received at `now`: a good frame's ADU at its LF, the reason a frame was
    /// dropped, or nothing.
    pub fn push(&mut self, now: Instant, byte: u8) -> Option<Result<&[u8], RxError>> {
        // A frame that timed out is dropped before the byte is looked at: a `:` after the silence
        // starts the next frame, anything else is noise.
        let timed_out = self.expire(now);
        if byte == b':' {
            let restarted = self.in_frame().then_some(RxError::Restart);
            self.start(now);
            return timed_out.or(restarted).map(Err);
        }
        if let Some(e) = timed_out {
            return Some(Err(e));
        }
        self.last = now;
        match (self.state, byte) {
            (State::Idle, _) => None,
            (State::Digits, b'\r') => {
                self.state = State::Cr;
                None
            }
            (State::Digits, _) => self.digit(byte).err().map(|e| Err(self.drop_frame(e))),
            (State::Cr, b'\n') => Some(self.end()),
            (State::Cr, _) => Some(Err(self.drop_frame(RxError::BadChar))),
        }
    }

    /// The line that ended last at its CR LF with the bytes of a frame, a good LRC or a bad one,
    /// kept while the receiver waits for the next `:`: its bytes as decoded (the LRC last: they
    /// sum to 0 if it matched, [`lrc`] of them is 0) and when the last byte came (its LF, or
    /// noise after it). `None` once the next `:` came, after any other verdict, or after
    /// [`Framer::clear`].
    ///
    /// A slave that serves a frame after its LF rather than at it (after syncing with whatever
    /// the request reads) finds it here, and a slave that answers a frame spoilt by its LRC
    /// finds its address and function code.
    pub fn ended(&self) -> Option<(&[u8], Instant)> {
        match self.state {
            State::Idle if self.len > 0 => Some((self.buf.get(..self.len).unwrap_or_default(), self.last)),
            _ => None,
        }
    }

    /// Adds bytes received together at `now`, handing `each` every push's outcome in order.
    pub fn extend(&mut self, now: Instant, bytes: &[u8], mut each: impl FnMut(Result<&[u8], RxError>)) {
        for &b in bytes {
            if let Some(r) = self.push(now, b) {
                each(r);
            }
        }
    }

    /// Forgets the frame in progress; the receiver waits for a `:`.
    pub fn clear(&mut self) {
        self.state = State::Idle;
        self.len = 0;
        self.high = None;
        self.sum = 0;
    }

    fn start(&mut self, now: Instant) {
        self.clear();
        self.state = State::Digits;
        self.last = now;
    }

    fn drop_frame(&mut self, e: RxError) -> RxError {
        self.clear();
        e
    }

    /// Takes one character between `:` and CR.
    fn digit(&mut self, c: u8) -> Result<(), RxError> {
        let v = hex_value(c).ok_or(RxError::BadChar)?;
        match self.high.take() {
            None if self.len >= self.buf.len() => Err(RxError::Overrun),
            None => {
                self.high = Some(v);
                Ok(())
            }
            Some(h) => {
                let b = h << 4 | v;
                // In range: a first digit was taken only with room for its byte.
                if let Some(slot) = self.buf.get_mut(self.len) {
                    *slot = b;
                }
                self.len += 1;
                self.sum = self.sum.wrapping_add(b);
                Ok(())
            }
        }
    }

    /// The LF after CR: the frame's verdict.
    fn end(&mut self) -> Result<&[u8], RxError> {
        let error = if self.high.is_some() {
            Some(RxError::OddLength)
        } else if self.len < MIN_BYTES {
            Some(RxError::TooShort)
        } else if self.sum != 0 {
            Some(RxError::Lrc)
        } else {
            None
        };
        let adu = self.len.saturating_sub(1);
        // The frame's bytes stay (`ended`) until the next `:`, unless they make no frame.
        self.state = State::Idle;
        self.sum = 0;
        match error {
            Some(RxError::Lrc) => Err(RxError::Lrc),
            Some(e) => Err(self.drop_frame(e)),
            None => Ok(self.buf.get(..adu).unwrap_or_default()),
        }
    }
}

impl Default for Framer {
    /// A receiver with the spec's one-second timeout.
    fn default() -> Self {
        Self::new(DEFAULT_TIMEOUT_MICROS)
    }
}

/// The value of a hex digit, either case.
const fn hex_value(c: u8) -> Option<u8> {
    match c {
        b'0'..=b'9' => Some(c - b'0'),
        b'A'..=b'F' => Some(c - b'A' + 10),
        b'a'..=b'f' => Some(c - b'a' + 10),
        _ => None,
    }
}

/// Upper-case hex digits, as sent.
const HEX: [u8; 16] = *b"0123456789ABCDEF";

/// Writes the line that carries `adu` (address, function, data) into `out`: `:`, the bytes and
/// their LRC in upper-case hex, CR LF. Its length ([`line_len`]), or `None` if `adu` is shorter
/// than an address and a function code, longer than [`MAX_ADU`], or `out` too short.
///
/// ```
/// use drive_core::ascii::encode;
/// let mut line = [0u8; drive_core::ascii::MAX_LINE];
/// let n = encode(&[0x01, 0x03, 0x02, 0x01, 0x00, 0x01], &mut line);
/// assert_eq!(n.and_then(|n| line.get(..n)), Some(&b":010302010001F8\r\n"[..]));
/// ```
pub fn encode(adu: &[u8], out: &mut [u8]) -> Option<usize> {
    if !(2..=MAX_ADU).contains(&adu.len()) {
        return None;
    }
    let n = line_len(adu.len());
    let (first, rest) = out.get_mut(..n)?.split_first_mut()?;
    *first = b':';
    let (pairs, _) = rest.as_chunks_mut::<2>();
    let check = lrc(adu);
    for (pair, &b) in pairs.iter_mut().zip(adu.iter().chain(core::iter::once(&check))) {
        *pair = [hex_digit(b >> 4), hex_digit(b)];
    }
    if let Some(end) = pairs.last_mut() {
        *end = *b"\r\n";
    }
    Some(n)
}

/// [`encode`] in place: the first `n` bytes of `buf`, an ADU (address, function, data), become
/// the line that carries it, which takes `buf`'s first [`line_len`]`(n)` bytes. Its length, or
/// `None` if `n` is below 2 or over [`MAX_ADU`], or `buf` too short (then `buf` is unchanged).
///
/// A slave builds its binary reply at the start of its transmit buffer, as for RTU, and turns it
/// into its line here: a buffer of [`MAX_LINE`] bytes holds any reply, and no second one is
/// needed.
///
/// ```
/// use drive_core::ascii::encode_in_place;
/// let mut buf = [0u8; 32];
/// buf[..6].copy_from_slice(&[0x01, 0x03, 0x02, 0x01, 0x00, 0x01]);
/// assert_eq!(encode_in_place(&mut buf, 6), Some(17));
/// assert_eq!(&buf[..17], b":010302010001F8\r\n");
/// ```
pub fn encode_in_place(buf: &mut [u8], n: usize) -> Option<usize> {
    if !(2..=MAX_ADU).contains(&n) {
        return None;
    }
    let len = line_len(n);
    let line = buf.get_mut(..len)?;
    let check = lrc(line.get(..n).unwrap_or_default());
    let (first, rest) = line.split_first_mut()?;
    let (pairs, _) = rest.as_chunks_mut::<2>();
    if let Some(end) = pairs.last_mut() {
        *end = *b"\r\n";
    }
    if let Some(pair) = pairs.get_mut(n) {
        *pair = [hex_digit(check >> 4), hex_digit(check)];
    }
    // From the last byte back: byte `i` (at `i` in `buf`) becomes the pair at `1 + 2i`, after
    // every byte not yet read (`0..i`). `pairs` starts at `buf`'s 1, so byte `i` is the pair `i`
    // as a byte of `rest` at `i - 1`: read it before its pair overwrites it.
    for i in (0..n).rev() {
        let b = if i == 0 { *first } else { rest.get(i - 1).copied().unwrap_or(0) };
        let (pairs, _) = rest.as_chunks_mut::<2>();
        if let Some(pair) = pairs.get_mut(i) {
            *pair = [hex_digit(b >> 4), hex_digit(b)];
        }
    }
    *first = b':';
    Some(len)
}

/// The upper-case hex digit of the low nibble of `v`.
fn hex_digit(v: u8) -> u8 {
    HEX.get(usize::from(v & 0xF)).copied().unwrap_or(b'0')
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(us: u64) -> Instant {
        Instant::from_micros(us)
    }

    /// Every outcome of feeding `line` at time 0.
    fn feed(f: &mut Framer, line: &[u8]) -> ([u8; MAX_ADU], usize, Option<RxError>) {
        let (mut adu, mut n, mut err) = ([0u8; MAX_ADU], 0, None);
        f.extend(at(0), line, |r| match r {
            Ok(a) => {
                n = a.len();
                adu.get_mut(..n).unwrap_or_default().copy_from_slice(a);
            }
            Err(e) => err = Some(e),
        });
        (adu, n, err)
    }

    #[test]
    fn lower_case_is_read_as_upper() {
        let mut f = Framer::default();
        let (adu, n, err) = feed(&mut f, b":0103040a0b1f4084\r\n");
        assert_eq!((adu.get(..n), err), (Some(&[1u8, 3, 4, 0x0A, 0x0B, 0x1F, 0x40][..]), None));
    }

    #[test]
    fn the_verdicts() {
        let cases: [(&[u8], RxError); 7] = [
            (b":0103X20000F8\r\n", RxError::BadChar),
            (b":010302000002F8\rX", RxError::BadChar),
            (b":010302000002F8\n", RxError::BadChar),
            (b":01030200002F8\r\n", RxError::OddLength),
            (b":01FE\r\n", RxError::TooShort),
            (b":010302000002F9\r\n", RxError::Lrc),
            (b":0103:", RxError::Restart),
        ];
        for (line, e) in cases {
            let mut f = Framer::default();
            assert_eq!(feed(&mut f, line).2, Some(e), "{line:?}");
        }
    }

    #[test]
    fn a_gap_over_the_timeout_drops_the_frame() {
        let mut f = Framer::new(1000);
        assert_eq!(f.push(at(0), b':'), None);
        assert_eq!(f.push(at(1000), b'0'), None);
        assert_eq!(f.deadline(), Some(at(2001)));
        assert_eq!(f.expire(at(2000)), None);
        assert_eq!(f.push(at(2001), b'1'), Some(Err(RxError::Timeout)));
        assert!(!f.in_frame());
        // By the timer, and a `:` after the silence starts the next frame.
        assert_eq!(f.push(at(3000), b':'), None);
        assert_eq!(f.expire(at(4001)), Some(RxError::Timeout));
        assert_eq!(f.expire(at(4001)), None);
        assert_eq!(f.push(at(5000), b':'), None);
        assert_eq!(f.push(at(6001), b':'), Some(Err(RxError::Timeout)));
        assert!(f.in_frame());
    }
}
