//! The oracle, written from the Modbus specs (Modbus over serial line V1.02 §2.5.1, application
//! protocol V1.1b3) and independent of the drive's code: CRC bit by bit, framing by line silence,
//! the shapes of replies, and the timed chunk encoding the stream targets share.

use drive_core::rtu::RxError;

/// The drive's address.
pub const ADDR: u8 = 1;
/// The longest RTU frame: address, 253-byte PDU, CRC.
pub const MAX_FRAME: usize = 256;

/// CRC-16/MODBUS register after one more byte, bit by bit (the drive uses a table).
pub fn crc_step(crc: u16, b: u8) -> u16 {
    let mut crc = crc ^ u16::from(b);
    for _ in 0..8 {
        crc = if crc & 1 != 0 { (crc >> 1) ^ 0xA001 } else { crc >> 1 };
    }
    crc
}

/// CRC-16/MODBUS of `bytes`.
pub fn crc16_bitwise(bytes: &[u8]) -> u16 {
    bytes.iter().fold(0xFFFF, |c, &b| crc_step(c, b))
}

/// Whether `frame` ends in the CRC (low byte first) of at least one byte before it.
pub fn crc_ok(frame: &[u8]) -> bool {
    frame.len() >= 3 && {
        let (body, sum) = frame.split_at(frame.len() - 2);
        crc16_bitwise(body) == u16::from_le_bytes([sum[0], sum[1]])
    }
}

/// `body` followed by its CRC.
pub fn seal(body: &[u8]) -> Vec<u8> {
    let mut f = body.to_vec();
    f.extend_from_slice(&crc16_bitwise(body).to_le_bytes());
    f
}

/// Big-endian word at `at`.
pub fn be16(b: &[u8], at: usize) -> usize {
    usize::from(u16::from_be_bytes([b[at], b[at + 1]]))
}

/// The line's timing at a baud rate, from §2.5.1.1.
#[derive(Clone, Copy, Debug)]
pub struct Timing {
    /// t1.5: a longer silence inside a frame spoils it (rounded down).
    pub t15: u64,
    /// t3.5: a silence this long ends a frame (rounded down).
    pub t35: u64,
    /// One 11-bit character (rounded up).
    pub char: u64,
    /// The unit of the spacing of bytes sent one at a time: 31 of them reach past t1.5.
    pub step: u64,
}

impl Timing {
    /// The timing at `bps`: 11-bit characters; above 19200 baud the spec fixes t1.5 at 750 µs and
    /// t3.5 at 1750 µs.
    pub const fn of(bps: u64) -> Self {
        let (t15, t35) = if bps > 19_200 {
            (750, 1750)
        } else {
            (15 * 11 * 1_000_000 / (10 * bps), 35 * 11 * 1_000_000 / (10 * bps))
        };
        Self { t15, t35, char: (11_000_000u64).div_ceil(bps), step: t35 / 62 }
    }
}

/// A chunk of bytes of a timed stream.
pub struct Chunk<'a> {
    /// The silence before it, in µs.
    pub delta: u64,
    /// Whether the platform's timer is late: no `on_timer` at the deadline in that silence.
    pub late: bool,
    /// `Some(d)`: the bytes arrive one at a time, `d` µs apart; `None`: in one call.
    pub spacing: Option<u64>,
    /// The bytes.
    pub bytes: &'a [u8],
}

/// Decodes a timed stream: a sequence of `[gap, len, bytes..]`, where `gap % 8` chooses the
/// silence before the chunk and `gap / 8` (`j`, 0..=31) fine-tunes it: 0 none, 1 `j` µs, 2 around
/// t1.5 (t1.5 - 16 + `j`), 3 around t3.5, 4 about one character, 5 long (t3.5 + `j` * 5 ms), 6 as
/// 5 with the timer late, 7 none and the bytes one at a time `j` steps apart (across t1.5); then
/// `len` bytes (fewer if the input ends).
pub fn chunks(data: &[u8], t: Timing) -> impl Iterator<Item = Chunk<'_>> {
    let mut rest = data;
    std::iter::from_fn(move || {
        let [gap, len, tail @ ..] = rest else { return None };
        let (bytes, next) = tail.split_at(usize::from(*len).min(tail.len()));
        rest = next;
        let j = u64::from(gap / 8);
        let (delta, late) = match gap % 8 {
            0 | 7 => (0, false),
            1 => (j, false),
            2 => (t.t15 - 16 + j, false),
            3 => (t.t35 - 16 + j, false),
            4 => (t.char + j, false),
            5 => (t.t35 + j * 5000, false),
            _ => (t.t35 + j * 5000, true),
        };
        Some(Chunk { delta, late, spacing: (gap % 8 == 7).then_some(j * t.step), bytes })
    })
}

/// A receiver under test, fed a timed stream by [`replay`].
pub trait Line {
    /// The current time, µs.
    fn now(&self) -> u64;
    /// Time passes to `to`; the timer fires at the deadline unless it is `late`.
    fn advance(&mut self, to: u64, late: bool);
    /// Bytes arrive now.
    fn rx(&mut self, bytes: &[u8]);
}

/// Feeds the timed stream `data` (see [`chunks`]) to `line`, then a second of silence so that
/// the last frame ends.
pub fn replay(data: &[u8], t: Timing, line: &mut impl Line) {
    replay_as(data, t, line, |b| std::borrow::Cow::Borrowed(b), 1_000_000);
}

/// [`replay`] with each chunk's bytes as `bytes_of` makes them (an ASCII line of a marked ADU),
/// then `silence` µs of silence.
pub fn replay_as<F>(data: &[u8], t: Timing, line: &mut impl Line, bytes_of: F, silence: u64)
where
    F: for<'a> Fn(&'a [u8]) -> std::borrow::Cow<'a, [u8]>,
{
    for c in chunks(data, t) {
        line.advance(line.now() + c.delta, c.late);
        let bytes = bytes_of(c.bytes);
        match c.spacing {
            Some(d) => {
                for (i, &b) in bytes.iter().enumerate() {
                    if i > 0 {
                        line.advance(line.now() + d, false);
                    }
                    line.rx(&[b]);
                }
            }
            None if !bytes.is_empty() => line.rx(&bytes),
            None => {}
        }
    }
    line.advance(line.now() + silence, false);
}

/// A frame that ended on the line, as the reference received it.
#[derive(Debug)]
pub struct Closed {
    /// Every byte, including those beyond [`MAX_FRAME`].
    pub bytes: Vec<u8>,
    /// A silence over t1.5 inside it: whether the bytes before the first one made a whole
    /// frame with its CRC.
    pub gap: Option<bool>,
    /// Whether the bytes kept (the first [`MAX_FRAME`]) are at least four and end in their CRC.
    pub crc_ok: bool,
}

impl Closed {
    /// What a receiver reports of it: an overrun before a gap (the frame is lost either way,
    /// and the overrun is what the diagnostic counters keep apart).
    pub fn error(&self) -> Option<RxError> {
        expected_error(self.bytes.len(), self.gap)
    }

    /// The bytes a receiver keeps.
    pub fn kept(&self) -> &[u8] {
        &self.bytes[..self.bytes.len().min(MAX_FRAME)]
    }

    /// The request to this drive that it is, if any: a frame free of errors with an address, a
    /// function code and a good CRC, addressed to [`ADDR`] with a function code below 0x80.
    pub fn request(&self) -> Option<&[u8]> {
        (self.error().is_none() && self.crc_ok && self.bytes[0] == ADDR && self.bytes[1] & 0x80 == 0)
            .then_some(&self.bytes[..])
    }
}

fn expected_error(len: usize, gap: Option<bool>) -> Option<RxError> {
    if len > MAX_FRAME { Some(RxError::Overrun) } else { gap.map(|after_frame| RxError::Gap { after_frame }) }
}

/// Framing by line silence: a frame ends after t3.5 of silence, a silence over t1.5 inside it
/// spoils it, bytes beyond 256 overrun it.
pub struct Reference {
    t: Timing,
    cur: Vec<u8>,
    /// `crcs[i]`: the CRC register over the first `i` bytes kept.
    crcs: Vec<u16>,
    last: u64,
    gap: Option<bool>,
    /// The frame that ended since the last [`Reference::take`].
    ended: Option<Closed>,
}

impl Reference {
    /// An idle line with timing `t`.
    pub fn new(t: Timing) -> Self {
        Self { t, cur: Vec::new(), crcs: vec![0xFFFF], last: 0, gap: None, ended: None }
    }

    fn close(&mut self) {
        let crc_ok = self.crc_ok();
        let bytes = std::mem::take(&mut self.cur);
        self.crcs.truncate(1);
        assert!(self.ended.is_none(), "two frames ended in one call");
        self.ended = Some(Closed { bytes, gap: std::mem::take(&mut self.gap), crc_ok });
    }

    /// Byte `b` arrives at `t`.
    pub fn byte(&mut self, t: u64, b: u8) {
        if !self.cur.is_empty() {
            let since = t - self.last;
            if since >= self.t.t35 {
                self.close();
            } else if since > self.t.t15 && self.gap.is_none() {
                self.gap = Some(self.crc_ok());
            }
        }
        if self.cur.len() < MAX_FRAME {
            let c = crc_step(self.crcs[self.cur.len()], b);
            self.crcs.push(c);
        }
        self.cur.push(b);
        self.last = t;
    }

    /// The line is still silent at `t`.
    pub fn timer(&mut self, t: u64) {
        if self.ends_by(t) {
            self.close();
        }
    }

    /// Whether the frame in progress has ended by `t` (t3.5 of silence).
    pub fn ends_by(&self, t: u64) -> bool {
        !self.cur.is_empty() && t - self.last >= self.t.t35
    }

    /// When the frame in progress ends if nothing more arrives.
    pub fn deadline(&self) -> Option<u64> {
        (!self.cur.is_empty()).then(|| self.last + self.t.t35)
    }

    /// The frame that ended, once.
    pub fn take(&mut self) -> Option<Closed> {
        self.ended.take()
    }

    /// The bytes of the frame in progress a receiver keeps.
    pub fn kept(&self) -> &[u8] {
        &self.cur[..self.cur.len().min(MAX_FRAME)]
    }

    /// What is wrong with the frame in progress so far.
    pub fn error(&self) -> Option<RxError> {
        expected_error(self.cur.len(), self.gap)
    }

    /// Whether the bytes kept of the frame in progress are at least four and end in their CRC.
    pub fn crc_ok(&self) -> bool {
        let k = self.kept();
        let n = k.len();
        n >= 4 && self.crcs[n - 2] == u16::from_le_bytes([k[n - 2], k[n - 1]])
    }
}

/// Checks the shape of `reply`, a reply of the drive at [`ADDR`] to the request frame `req`
/// (address to CRC): 5..=256 bytes, CRC-valid, from [`ADDR`], with the request's function code
/// (or that | 0x80 and an exception code 1..=4, 5 bytes) and shaped as that function's reply.
/// Whether it is an exception.
pub fn check_reply(req: &[u8], reply: &[u8]) -> bool {
    assert!((5..=MAX_FRAME).contains(&reply.len()), "reply length {}: {reply:02X?}", reply.len());
    assert!(drive_core::crc::frame_ok(reply), "bad CRC (drive's check): {reply:02X?}");
    assert!(crc_ok(reply), "bad CRC (bitwise check): {reply:02X?}");
    assert_eq!(reply[0], ADDR, "reply from the wrong address: {reply:02X?}");
    let f = req[1];
    if reply[1] == f | 0x80 {
        assert_eq!(reply.len(), 5, "exception reply {reply:02X?} to {req:02X?}");
        assert!((1..=4).contains(&reply[2]), "exception code {reply:02X?} to {req:02X?}");
        return true;
    }
    assert_eq!(reply[1], f, "function code of {reply:02X?} answering {req:02X?}");
    match f {
        0x03 | 0x04 | 0x17 => {
            let qty = be16(req, 4);
            assert!((1..=125).contains(&qty), "read of {qty} answered: {req:02X?}");
            assert_eq!(usize::from(reply[2]), 2 * qty, "{reply:02X?} answering {req:02X?}");
            assert_eq!(reply.len(), 5 + 2 * qty, "{reply:02X?} answering {req:02X?}");
        }
        0x06 => assert_eq!(reply, req, "0x06 is echoed"),
        0x10 => {
            assert_eq!(reply.len(), 8, "{reply:02X?} answering {req:02X?}");
            assert_eq!(reply[..6], req[..6], "{reply:02X?} answering {req:02X?}");
        }
        0x08 => {
            assert_eq!(reply[2..4], req[2..4], "sub-function echoed: {reply:02X?} answering {req:02X?}");
            if be16(req, 2) == 0 {
                assert_eq!(reply, req, "0x08/0x00 is echoed");
            }
        }
        0x2B => assert_eq!(reply[2], 0x0E, "{reply:02X?} answering {req:02X?}"),
        0x15 => assert_eq!(reply, req, "0x15 is echoed"),
        _ => panic!("normal reply {reply:02X?} to unsupported function {f:02X}"),
    }
    false
}

/// Makes the quantities and byte counts of a request agree with its data.
pub fn fix_lengths(pdu: &mut Vec<u8>) {
    let regs = |bytes: usize| (bytes / 2).clamp(1, 123) as u16;
    match pdu.first() {
        Some(0x10) if pdu.len() >= 6 => {
            let n = regs(pdu.len() - 6);
            pdu.truncate(6 + 2 * usize::from(n));
            pdu.resize(6 + 2 * usize::from(n), 0);
            pdu[3..5].copy_from_slice(&n.to_be_bytes());
            pdu[5] = (2 * n) as u8;
        }
        Some(0x03) if pdu.len() >= 5 => {
            let q = (pdu[4] % 16).max(1);
            pdu[3] = 0;
            pdu[4] = q;
            pdu.truncate(5);
        }
        _ => {}
    }
}

/// Sends `pdu` to the drive at [`ADDR`] as one frame after a silence of `t35` at `*now`, lets
/// t3.5 pass and returns the frame and the reply.
pub fn exchange<M: drive_core::maps::RegisterMap>(
    drive: &mut drive_core::Drive<M>,
    now: &mut u64,
    t35: u64,
    pdu: &[u8],
) -> (Vec<u8>, Option<Vec<u8>>) {
    let mut frame = vec![ADDR];
    frame.extend_from_slice(pdu);
    let frame = seal(&frame);
    *now += t35;
    drive.on_rx(drive_core::Instant::from_micros(*now), &frame);
    *now += t35 + 1;
    drive.on_timer(drive_core::Instant::from_micros(*now));
    let reply = drive.take_reply().map(<[u8]>::to_vec);
    (frame, reply)
}

/// Whether `reply` is an exception; if so, checks it is one of `codes` to `frame`'s function.
pub fn vendor_exception(frame: &[u8], reply: &[u8], codes: &[u8]) -> bool {
    if reply.get(1).is_none_or(|f| f & 0x80 == 0) {
        return false;
    }
    assert!(reply.len() == 5 && crc_ok(reply), "exception reply {reply:02X?} to {frame:02X?}");
    assert_eq!(reply[1], frame[1] | 0x80, "{reply:02X?} answering {frame:02X?}");
    assert!(codes.contains(&reply[2]), "code {:#04X} to {frame:02X?}", reply[2]);
    true
}

/// The records `[ctl, len, pdu..]` of a PDU target's input: for each, the control ticks run
/// first (`ctl` bits 3-5: 0, 1, 20, 200, 2000, each 50 µs after `*now`) and then the request
/// PDU (bits 0-1 choose the function: 0x03, 0x06, 0x10, 0x17; the data follow it).
pub fn requests<M: drive_core::maps::RegisterMap>(
    data: &[u8],
    drive: &mut drive_core::Drive<M>,
    now: &mut u64,
    mut each: impl FnMut(&mut drive_core::Drive<M>, &mut u64, u8, Vec<u8>),
) {
    let mut rest = data;
    while let [ctl, len, tail @ ..] = rest {
        let (body, next) = tail.split_at(usize::from(*len).min(tail.len()));
        rest = next;
        let ticks = [0u64, 1, 20, 200, 2000][usize::from((ctl >> 3) & 7) % 5];
        for _ in 0..ticks {
            *now += 50;
            drive.tick(drive_core::Instant::from_micros(*now));
        }
        let mut pdu = vec![[0x03u8, 0x06, 0x10, 0x17][usize::from(ctl & 3)]];
        pdu.extend_from_slice(body);
        each(drive, now, *ctl, pdu);
    }
}

/// Whether a snapshot compares `d`: every object but the diagnostics
/// (`Obj::is_diagnostic`).
pub fn compared(d: &&drive_core::od::ObjectDef) -> bool {
    !d.obj.is_diagnostic()
}

/// `n / d` to the nearest, halves away from zero.
pub fn round(n: i64, d: i64) -> i64 {
    if n >= 0 { (n + d / 2) / d } else { (n - d / 2) / d }
}

/// The value of a layout entry `e` in the map's unit, as a model computes it from the drive's
/// object (an enumeration value the table does not list reads as the drive's).
pub fn map_value(state: &drive_core::DriveState, e: &drive_core::maps::layout::Entry) -> i64 {
    use drive_core::maps::layout::{FULL_STEPS_PER_REV, Scale};
    let d = e.obj.def();
    let raw = state.read_def(d);
    let v = if d.ty() == drive_core::od::Type::S32 { i64::from(raw as i32) } else { i64::from(raw) };
    let per_rev = FULL_STEPS_PER_REV * i64::from(state.read(drive_core::od::Obj::Microsteps).max(1));
    match *e.scale {
        Scale::One => v,
        Scale::Ratio(n, den) => round(v * i64::from(den), i64::from(n)),
        Scale::PerRev(n, den) => round(v * i64::from(den), i64::from(n) * per_rev),
        Scale::Table(choices) => choices.iter().find(|c| i64::from(c.drive) == v).map_or(v, |c| i64::from(c.lo)),
        Scale::Field(k, w) => (v >> k) & ((1 << w) - 1),
        Scale::Invert(mask) => v ^ i64::from(mask),
        Scale::PulsesPerRev => v.max(1) * FULL_STEPS_PER_REV,
        Scale::Gear => {
            let num = i64::from(state.read(drive_core::od::Obj::GearNumerator).max(1));
            let den = i64::from(state.read(drive_core::od::Obj::GearDenominator).max(1));
            round(v * den, num)
        }
    }
}

/// Register `k` (0 or 1) of a layout entry `e`, as a model computes it from the drive's object:
/// one register clamped for a narrow entry (signed for a signed object), else the map's value,
/// its high word first or second as the map's word order (`high_first`) says.
pub fn entry_register(
    state: &drive_core::DriveState,
    e: &drive_core::maps::layout::Entry,
    k: u32,
    high_first: bool,
) -> u16 {
    let m = map_value(state, e);
    if e.is_narrow() && e.obj.def().ty() == drive_core::od::Type::S32 {
        m.clamp(i64::from(i16::MIN), i64::from(i16::MAX)) as i16 as u16
    } else if e.is_narrow() {
        (m as u32).min(0xFFFF) as u16
    } else if e.words() == 1 || (k == 0) != high_first {
        m as u16
    } else {
        (m as u32 >> 16) as u16
    }
}

/// What a [`Layout::scope`](drive_core::maps::layout::Layout::scope) layout answers a read of
/// `qty` registers from `addr` in its scope ranges: the native map's answer there (`None`
/// refused); `None` outside them.
pub fn scope_model(
    drive: &drive_core::Drive<drive_core::maps::Maps>,
    addr: u16,
    qty: usize,
) -> Option<Option<Vec<u16>>> {
    use drive_core::maps::RegisterMap;
    let ranges = drive_core::maps::layout::SCOPE_RANGES;
    ranges.iter().any(|&(lo, hi)| (lo..=hi).contains(&addr)).then(|| {
        let mut out = vec![0u8; 2 * qty];
        let read = drive_core::maps::NativeMap::new().read(drive.state(), addr, &mut out);
        read.ok().map(|()| out.chunks(2).map(|w| u16::from_be_bytes([w[0], w[1]])).collect())
    })
}

/// A compatibility map's run: the records of `data` as [`requests`] reads them, bit 6 of `ctl`
/// taking the address from `entries` (the data's first byte picks one). Every frame is answered
/// (a normal reply, or an exception of `codes` that changes nothing `snapshot` sees); a read of
/// 1-125 registers returns what `model` says, and one `model` can read is not refused.
pub fn map_requests<S: PartialEq + core::fmt::Debug>(
    data: &[u8],
    drive: &mut drive_core::Drive<drive_core::maps::Maps>,
    entries: &[drive_core::maps::layout::Entry],
    codes: &[u8],
    t35: u64,
    snapshot: fn(&drive_core::Drive<drive_core::maps::Maps>) -> S,
    model: fn(&drive_core::Drive<drive_core::maps::Maps>, u16, usize) -> Option<Vec<u16>>,
) {
    let mut now = 0u64;
    requests(data, drive, &mut now, |drive, now, ctl, mut pdu| {
        if ctl & 0x40 != 0 && pdu.len() >= 3 && !entries.is_empty() {
            let e = &entries[usize::from(pdu[1]) % entries.len()];
            pdu[1..3].copy_from_slice(&e.addr.to_be_bytes());
        }
        if ctl & 4 != 0 {
            fix_lengths(&mut pdu);
        }
        let before = snapshot(drive);
        let expected = match pdu.as_slice() {
            [0x03, a, b, c, d] => {
                let qty = usize::from(u16::from_be_bytes([*c, *d]));
                (1..=125).contains(&qty).then(|| model(drive, u16::from_be_bytes([*a, *b]), qty))
            }
            _ => None,
        };
        let (frame, reply) = exchange(drive, now, t35, &pdu);
        if frame.len() > MAX_FRAME {
            return;
        }
        let Some(reply) = reply else { panic!("no reply to {frame:02X?}") };
        // A map's codes may go beyond the Modbus four that `check_reply` knows.
        if vendor_exception(&frame, &reply, codes) {
            assert_eq!(snapshot(drive), before, "exception {:#04X} to {frame:02X?} changed the drive", reply[2]);
            assert!(!matches!(expected, Some(Some(_))), "a readable request refused: {frame:02X?}");
            return;
        }
        assert!(!check_reply(&frame, &reply), "{reply:02X?} to {frame:02X?}");
        if let [0x03, n, regs @ ..] = reply.get(1..reply.len() - 2).unwrap_or_default() {
            let got: Vec<u16> = regs.chunks(2).map(|w| u16::from_be_bytes([w[0], w[1]])).collect();
            assert_eq!(usize::from(*n), 2 * got.len(), "byte count of {frame:02X?}");
            assert_eq!(Some(Some(got)), expected, "read {frame:02X?}");
        }
    });
}
