//! Signed firmware images: what an image says it is (its [`Header`]: board, version, length,
//! the lowest store version it reads) and who made it (an Ed25519 signature over the SHA-512
//! of the header and the program, checked against a public key built into the drive).
//!
//! An image is the header ([`HEADER_LEN`] bytes), the program (the header's `length` bytes)
//! and the signature ([`SIGNATURE_LEN`] bytes). The signature signs the 64-byte SHA-512 digest
//! of the header and the program, as embassy-boot's `verify_and_mark_updated` checks a DFU
//! slot, so that the drive may check an image as it arrives ([`Verifier`]: the digest is taken
//! as the bytes come, in any number of pieces) and the boot loader once more before it swaps.
//! `cargo xtask sign` makes images, `cargo xtask keygen` key pairs.
//!
//! ```
//! use drive_core::update::{Board, Header, Refusal, Verifier, HEADER_LEN};
//! let header = Header { board: Board::Simulator, version: 0x0001_0200, length: 4, store: 1 };
//! let mut image = header.to_bytes().to_vec();
//! image.extend_from_slice(b"code");
//! let mut v = Verifier::new();
//! v.absorb(&image);
//! // No signature made with the key: refused, and why.
//! assert_eq!(v.finish(&[0; 64], &[0; 32], Board::Simulator, 1), Err(Refusal::Signature));
//! assert_eq!(Header::parse(&image[..HEADER_LEN]), Ok(header));
//! ```

use ed25519_dalek::{Signature, VerifyingKey};
use sha2::{Digest, Sha512};

/// The header's length, bytes.
pub const HEADER_LEN: usize = 32;
/// The signature's length, bytes (Ed25519).
pub const SIGNATURE_LEN: usize = 64;
/// A public key's length, bytes (Ed25519).
pub const KEY_LEN: usize = 32;
/// The header's first bytes.
pub const MAGIC: [u8; 4] = *b"OSFW";
/// The header format this drive reads.
pub const FORMAT: u16 = 1;

/// Bytes of an image slot (embassy-boot's ACTIVE; DFU is one page more): the G474's bank 1
/// after its 32 KiB boot loader, and the same in the simulator and under QEMU.
pub const SLOT_LEN: u32 = 224 * 1024;
/// A flash page, the unit of erase.
pub const PAGE: u32 = 2048;
/// Where in a slot an image's trailer lies, its last page: the header and the signature, which
/// the drive writes there once the image has checked, so that the program starts the slot (its
/// vector table where the boot loader jumps) and a slot says which image it holds.
pub const TRAILER: u32 = SLOT_LEN - PAGE;
/// The trailer's length: header and signature.
pub const TRAILER_LEN: usize = HEADER_LEN + SIGNATURE_LEN;
/// The longest program a slot takes: the slot up to its trailer.
pub const MAX_PROGRAM: u32 = TRAILER;

/// The key a key file's text holds (`cargo xtask keygen`'s `.key` and `.pub`): 64 hex digits,
/// whitespace around them; `None` for anything else. A `const fn`, so that a firmware builds its
/// key in.
///
/// ```
/// use drive_core::update::{key_from_hex, TEST_KEY};
/// let text = "3622c52d7d4bb9133ed708391372418beb7b6e050db4c50b1d63a9e18a2d2607\n";
/// assert_eq!(key_from_hex(text), Some(TEST_KEY));
/// assert_eq!(key_from_hex("36 22"), None);
/// ```
pub const fn key_from_hex(text: &str) -> Option<[u8; KEY_LEN]> {
    const fn digit(c: u8) -> Option<u8> {
        match c {
            b'0'..=b'9' => Some(c - b'0'),
            b'a'..=b'f' => Some(c - b'a' + 10),
            b'A'..=b'F' => Some(c - b'A' + 10),
            _ => None,
        }
    }
    let mut rest = text.as_bytes();
    while let [c, tail @ ..] = rest
        && c.is_ascii_whitespace()
    {
        rest = tail;
    }
    let mut key = [0u8; KEY_LEN];
    let mut i = 0;
    while i < KEY_LEN {
        let [h, l, tail @ ..] = rest else { return None };
        let (Some(h), Some(l)) = (digit(*h), digit(*l)) else { return None };
        #[allow(clippy::indexing_slicing, reason = "i < KEY_LEN, the array's length")]
        {
            key[i] = h << 4 | l;
        }
        rest = tail;
        i += 1;
    }
    while let [c, tail @ ..] = rest {
        if !c.is_ascii_whitespace() {
            return None;
        }
        rest = tail;
    }
    Some(key)
}

/// The public key of the repository's test key pair (`keys/test.key`, `keys/test.pub`): what
/// the simulator and the tests check images against. A firmware built with it says so in its
/// identification; a user's drives carry the user's own.
pub const TEST_KEY: [u8; KEY_LEN] = [
    0x36, 0x22, 0xC5, 0x2D, 0x7D, 0x4B, 0xB9, 0x13, 0x3E, 0xD7, 0x08, 0x39, 0x13, 0x72, 0x41, 0x8B, 0xEB, 0x7B, 0x6E,
    0x05, 0x0D, 0xB4, 0xC5, 0x0B, 0x1D, 0x63, 0xA9, 0xE1, 0x8A, 0x2D, 0x26, 0x07,
];

/// The board an image is built for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u16)]
pub enum Board {
    /// The STM32G474CE board.
    G474 = 1,
    /// QEMU's emulated STM32L475.
    Qemu = 2,
    /// The simulator (`hal-sim`), which boots an image's header.
    Simulator = 3,
}

impl Board {
    /// The board of code `code`.
    pub const fn from_code(code: u16) -> Option<Self> {
        match code {
            1 => Some(Board::G474),
            2 => Some(Board::Qemu),
            3 => Some(Board::Simulator),
            _ => None,
        }
    }
}

/// What an image says it is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Header {
    /// The board it runs on.
    pub board: Board,
    /// Its version: major << 16 | minor << 8 | patch.
    pub version: u32,
    /// The program's length, bytes.
    pub length: u32,
    /// The lowest parameter store version it reads.
    pub store: u16,
}

/// Why an image is refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Refusal {
    /// It does not start with [`MAGIC`], or is of a header format this drive does not read.
    NotAnImage,
    /// It is for another board.
    Board,
    /// Fewer or more bytes than its header says.
    Length,
    /// Its signature is not the key's over its bytes: unsigned, signed with another key, or
    /// changed since it was signed.
    Signature,
    /// It needs a newer parameter store than this drive's.
    Store,
}

impl Header {
    /// The header's bytes (little-endian): magic, format, board, version, length, store
    /// version, zeros.
    pub fn to_bytes(&self) -> [u8; HEADER_LEN] {
        let mut b = [0u8; HEADER_LEN];
        let fields: [&[u8]; 6] = [
            &MAGIC,
            &FORMAT.to_le_bytes(),
            &(self.board as u16).to_le_bytes(),
            &self.version.to_le_bytes(),
            &self.length.to_le_bytes(),
            &self.store.to_le_bytes(),
        ];
        let mut at = 0;
        for f in fields {
            if let Some(slot) = b.get_mut(at..at + f.len()) {
                slot.copy_from_slice(f);
            }
            at += f.len();
        }
        b
    }

    /// The header in `b` (its first [`HEADER_LEN`] bytes).
    pub fn parse(b: &[u8]) -> Result<Self, Refusal> {
        let bytes = |at: usize, n: usize| b.get(at..at + n).ok_or(Refusal::NotAnImage);
        let u16_at = |at| bytes(at, 2).map(|s| u16::from_le_bytes(s.try_into().unwrap_or_default()));
        let u32_at = |at| bytes(at, 4).map(|s| u32::from_le_bytes(s.try_into().unwrap_or_default()));
        if bytes(0, 4)? != MAGIC || u16_at(4)? != FORMAT {
            return Err(Refusal::NotAnImage);
        }
        let board = Board::from_code(u16_at(6)?).ok_or(Refusal::Board)?;
        Ok(Self { board, version: u32_at(8)?, length: u32_at(12)?, store: u16_at(16)? })
    }

    /// The image's whole length: header, program and signature.
    pub const fn image_len(&self) -> u64 {
        HEADER_LEN as u64 + self.length as u64 + SIGNATURE_LEN as u64
    }
}

/// Checks an image as its bytes come (header and program, in order, in any pieces), then its
/// signature.
#[derive(Clone, Debug, Default)]
pub struct Verifier {
    digest: Sha512,
    header: [u8; HEADER_LEN],
    taken: u64,
}

impl Verifier {
    /// Nothing taken yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// The next bytes of the header and the program.
    pub fn absorb(&mut self, bytes: &[u8]) {
        for (k, b) in (self.taken..).zip(bytes).take_while(|(k, _)| *k < HEADER_LEN as u64) {
            if let Some(slot) = self.header.get_mut(k as usize) {
                *slot = *b;
            }
        }
        self.digest.update(bytes);
        self.taken += bytes.len() as u64;
    }

    /// The verdict on what was taken, with its `signature`, against `key`, for a drive on
    /// `board` whose store is of version `store`: the header if the image may be booted.
    pub fn finish(
        self,
        signature: &[u8; SIGNATURE_LEN],
        key: &[u8; KEY_LEN],
        board: Board,
        store: u16,
    ) -> Result<Header, Refusal> {
        let header = Header::parse(&self.header)?;
        if header.board != board {
            return Err(Refusal::Board);
        }
        if self.taken != HEADER_LEN as u64 + u64::from(header.length) {
            return Err(Refusal::Length);
        }
        let digest: [u8; 64] = self.digest.finalize().into();
        let key = VerifyingKey::from_bytes(key).map_err(|_| Refusal::Signature)?;
        key.verify_strict(&digest, &Signature::from_bytes(signature)).map_err(|_| Refusal::Signature)?;
        if header.store > store {
            return Err(Refusal::Store);
        }
        Ok(header)
    }
}

/// The SHA-512 digest of `bytes`: what an image's signature signs (of its header and program).
pub fn digest(bytes: &[u8]) -> [u8; 64] {
    Sha512::digest(bytes).into()
}

/// Registers in one file of Modbus's file records (function 0x15): record numbers 0-9999.
pub const FILE_REGISTERS: u32 = 10_000;

/// The byte of an image where record `record` of file `file` starts: an image is sent as
/// files 1, 2, … of 10 000 registers (20 000 bytes) each, a register two bytes, high byte first.
/// `None` for a file number of 0 or a record number past 9999, which Modbus does not have.
///
/// ```
/// use drive_core::update::record_offset;
/// assert_eq!(record_offset(1, 0), Some(0));
/// assert_eq!(record_offset(1, 122), Some(244));
/// assert_eq!(record_offset(2, 0), Some(20_000));
/// assert_eq!(record_offset(0, 0), None);
/// assert_eq!(record_offset(1, 10_000), None);
/// ```
pub const fn record_offset(file: u16, record: u16) -> Option<u32> {
    if file == 0 || record as u32 >= FILE_REGISTERS {
        return None;
    }
    Some(((file as u32 - 1) * FILE_REGISTERS + record as u32) * 2)
}

/// What a drive takes images for: its board, the key they must be signed with, and its
/// parameter store's version.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Target {
    /// The board this drive is.
    pub board: Board,
    /// The public key images are checked against.
    pub key: [u8; KEY_LEN],
    /// The version of the parameter store's format this drive writes.
    pub store: u16,
}

impl Target {
    /// Whether its key is the repository's test key, which anyone can sign with.
    pub const fn test_key(&self) -> bool {
        let (mut a, mut b) = (self.key.as_slice(), TEST_KEY.as_slice());
        while let ([x, rest_a @ ..], [y, rest_b @ ..]) = (a, b) {
            if *x != *y {
                return false;
            }
            (a, b) = (rest_a, rest_b);
        }
        true
    }
}

/// What the boot loader's state says of the running image (0x2261).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(u8)]
pub enum BootState {
    /// It runs for good (confirmed, or never updated).
    #[default]
    Confirmed = 0,
    /// Swapped in at the last reset, on trial: it confirms itself once it has served the bus,
    /// else the next reset swaps the one before back.
    Trial = 1,
    /// The last update did not confirm itself and was swapped back out: this is the image
    /// before it.
    RolledBack = 2,
    /// An update is marked for the boot loader and swapped in at the next reset (a board without
    /// a boot loader, QEMU's, keeps it marked).
    Marked = 3,
}

/// Where a transfer stands (0x2250).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(u8)]
pub enum Phase {
    /// No image: none sent since power-up, or the last one abandoned.
    #[default]
    Idle = 0,
    /// Records are arriving; the next one is expected at [`Status::received`].
    Receiving = 1,
    /// The image is whole and its signature good; its last bytes are being written.
    Verifying = 2,
    /// Checked and in the DFU slot: install it (0x2256 = 2) to boot it.
    Ready = 3,
    /// Refused, for [`Status::reason`]; the running image stays. A transfer from its first
    /// record starts again.
    Failed = 4,
    /// Being checked once more in the slot, marked for the boot loader, and restarted into.
    Installing = 5,
}

/// Why a transfer failed (0x2251).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(u8)]
pub enum Reason {
    /// It has not.
    #[default]
    None = 0,
    /// Not an image ([`Refusal::NotAnImage`]).
    NotAnImage = 1,
    /// For another board.
    Board = 2,
    /// Installed with fewer bytes than its header says.
    Length = 3,
    /// Unsigned, signed with another key, or changed since it was signed.
    Signature = 4,
    /// It needs a newer parameter store than this drive's.
    Store = 5,
    /// Its program is longer than a slot takes ([`MAX_PROGRAM`]).
    TooLarge = 6,
    /// The flash did not take it, or did not hold it when it was checked again.
    Flash = 7,
}

impl From<Refusal> for Reason {
    fn from(r: Refusal) -> Self {
        match r {
            Refusal::NotAnImage => Reason::NotAnImage,
            Refusal::Board => Reason::Board,
            Refusal::Length => Reason::Length,
            Refusal::Signature => Reason::Signature,
            Refusal::Store => Reason::Store,
        }
    }
}

/// What the update objects read (0x2250-0x2255, 0x2259).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Status {
    /// Where the transfer stands.
    pub phase: Phase,
    /// Why it failed, while [`Phase::Failed`].
    pub reason: Reason,
    /// The image's bytes taken, in order from its first.
    pub received: u32,
    /// The image's whole length (header, program, signature) once its header has come, else 0.
    pub length: u32,
    /// The version its header says, once it has come, else 0.
    pub version: u32,
}

/// Why a record or an order was not taken. Nothing of the transfer changed, but for
/// [`RecordError::Refused`], which leaves it failed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RecordError {
    /// Not the next record: the transfer expects [`Status::received`] (or starts again at 0).
    Order,
    /// Past the end its header gives the image.
    PastEnd,
    /// The flash has not yet taken the last record, or the image is being installed.
    Busy,
    /// Not ready to install: no whole, checked image.
    NotReady,
    /// The image is refused, for this reason (also in [`Status::reason`]).
    Refused(Reason),
}

/// Bytes of program a transfer holds until the flash takes them: a request's records (at most
/// 244 bytes), what a double word left of the request before (at most 6: records are whole
/// registers) and the last double word's padding.
const STAGE: usize = 264;
/// The flash's unit of programming: bytes written are whole double words.
pub const WRITE_UNIT: usize = 8;

/// What the platform is to do with the flash for a transfer ([`Transfer::job`]), then report
/// with [`Transfer::done`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Job<'a> {
    /// Write `bytes` (whole double words) at `offset` of the DFU slot, erasing each page as the
    /// writes enter it: offsets only grow within a transfer, and a transfer's first write is at 0.
    Write {
        /// Where in the DFU slot.
        offset: u32,
        /// What, a multiple of [`WRITE_UNIT`] bytes.
        bytes: &'a [u8],
    },
    /// Check the slot once more ([`check_slot`]), mark it for the boot loader, and restart.
    Install,
}

/// The receiving end of an image sent in records (Modbus function 0x15): it takes them in
/// order, checks the image as it comes, and says what to write where ([`Transfer::job`]). No
/// flash is touched here: the platform writes, then reports ([`Transfer::done`]).
///
/// A record at byte 0 starts a transfer again; the same record twice in a row (a master that
/// lost the reply and repeats it) is taken once.
///
/// ```
/// use drive_core::update::{Board, Header, Job, Phase, Target, Transfer, TEST_KEY};
/// let target = Target { board: Board::Simulator, key: TEST_KEY, store: 1 };
/// let header = Header { board: Board::Simulator, version: 0x0001_0200, length: 16, store: 1 };
/// let mut t = Transfer::new();
/// t.record(&target, 0, &header.to_bytes()).unwrap();
/// t.record(&target, 32, &[0xAB; 12]).unwrap();
/// // Whole double words go to the flash; the rest waits for the next record.
/// assert_eq!(t.job(), Some(Job::Write { offset: 0, bytes: &[0xAB; 8] }));
/// t.done(true);
/// assert_eq!((t.status().phase, t.status().received, t.status().length), (Phase::Receiving, 44, 112));
/// assert!(t.record(&target, 0x100, &[0; 4]).is_err(), "not the next record");
/// ```
#[derive(Clone, Debug)]
pub struct Transfer {
    status: Status,
    verifier: Verifier,
    header: Option<Header>,
    signature: [u8; SIGNATURE_LEN],
    /// Program bytes not yet written, the first at `written` of the slot.
    stage: heapless::Vec<u8, STAGE>,
    written: u32,
    /// The bytes of `stage` the platform is writing ([`Transfer::job`]).
    taken: usize,
    /// The trailer (header and signature) is in the slot.
    trailer_written: bool,
    /// The platform is carrying out the install.
    installing: bool,
    /// The last record taken: its offset, length and CRC.
    last: Option<(u32, usize, u32)>,
}

impl Default for Transfer {
    fn default() -> Self {
        Self {
            status: Status::default(),
            verifier: Verifier::new(),
            header: None,
            signature: [0; SIGNATURE_LEN],
            stage: heapless::Vec::new(),
            written: 0,
            taken: 0,
            trailer_written: false,
            installing: false,
            last: None,
        }
    }
}

/// The CRC of a record, to know it again when it is repeated.
const RECORD_CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

impl Transfer {
    /// No transfer.
    pub fn new() -> Self {
        Self::default()
    }

    /// Where it stands.
    pub fn status(&self) -> Status {
        self.status
    }

    /// The header of the image received, once it has come.
    pub fn header(&self) -> Option<Header> {
        self.header
    }

    /// Takes `data`, the image's bytes from `offset`, for a drive that is `target`.
    pub fn record(&mut self, target: &Target, offset: u32, data: &[u8]) -> Result<(), RecordError> {
        if self.taken > 0 || self.installing || self.status.phase == Phase::Verifying {
            return Err(RecordError::Busy);
        }
        let crc = RECORD_CRC.checksum(data);
        if self.last == Some((offset, data.len(), crc)) {
            return Ok(());
        }
        let end = offset.checked_add(data.len() as u32).ok_or(RecordError::PastEnd)?;
        if offset == 0 {
            *self = Self { status: Status { phase: Phase::Receiving, ..Status::default() }, ..Self::default() };
        } else if self.status.phase != Phase::Receiving || offset != self.status.received {
            return Err(RecordError::Order);
        }
        // Registers are two bytes: an image of an odd length ends with a byte of padding.
        if self.header.is_some_and(|h| u64::from(end) > h.image_len().next_multiple_of(2)) {
            return Err(RecordError::PastEnd);
        }
        if self.stage.len() + data.len() + WRITE_UNIT > STAGE {
            return Err(RecordError::Busy);
        }
        for (at, &b) in (offset..).zip(data) {
            match self.header {
                Some(h) if u64::from(at) >= h.image_len() => break,
                _ => self.take(target, at, b)?,
            }
        }
        let end = self.header.map_or(end, |h| end.min(h.image_len() as u32));
        self.status.received = end;
        self.last = Some((offset, data.len(), crc));
        match self.header {
            Some(h) if u64::from(end) == h.image_len() => self.finish(target),
            _ => Ok(()),
        }
    }

    /// Takes byte `at` of the image.
    fn take(&mut self, target: &Target, at: u32, b: u8) -> Result<(), RecordError> {
        let Some(h) = self.header else {
            self.verifier.absorb(&[b]);
            if at + 1 == HEADER_LEN as u32 {
                let h = Header::parse(&self.verifier.header).map_err(|r| self.fail(r.into()))?;
                if h.board != target.board {
                    return Err(self.fail(Reason::Board));
                }
                if h.length > MAX_PROGRAM {
                    return Err(self.fail(Reason::TooLarge));
                }
                self.header = Some(h);
                self.status.length = h.image_len() as u32;
                self.status.version = h.version;
            }
            return Ok(());
        };
        let program_end = HEADER_LEN as u32 + h.length;
        if at < program_end {
            self.verifier.absorb(&[b]);
            // Room checked by the caller.
            let _ = self.stage.push(b);
        } else if let Some(s) = self.signature.get_mut((at - program_end) as usize) {
            *s = b;
        }
        Ok(())
    }

    /// The image is whole: its program's last double word padded, its signature checked.
    fn finish(&mut self, target: &Target) -> Result<(), RecordError> {
        while !self.stage.len().is_multiple_of(WRITE_UNIT) {
            let _ = self.stage.push(0xFF);
        }
        let verifier = core::mem::take(&mut self.verifier);
        match verifier.finish(&self.signature, &target.key, target.board, target.store) {
            Ok(_) => {
                self.status.phase = Phase::Verifying;
                Ok(())
            }
            Err(r) => Err(self.fail(r.into())),
        }
    }

    /// Leaves the transfer failed for `reason`.
    fn fail(&mut self, reason: Reason) -> RecordError {
        self.status.phase = Phase::Failed;
        self.status.reason = reason;
        self.stage.clear();
        self.taken = 0;
        self.last = None;
        RecordError::Refused(reason)
    }

    /// Abandons the transfer (0x2256 = 1): nothing is marked, the slot is written again by the
    /// next one. Refused while the image is being installed.
    pub fn abort(&mut self) -> Result<(), RecordError> {
        if self.installing || self.status.phase == Phase::Installing {
            return Err(RecordError::Busy);
        }
        *self = Self::default();
        Ok(())
    }

    /// Whether [`Transfer::install`] would be taken: the image is whole, checked and written.
    pub fn can_install(&self) -> Result<(), RecordError> {
        match self.status.phase {
            Phase::Ready if !self.installing => Ok(()),
            Phase::Installing | Phase::Verifying => Err(RecordError::Busy),
            // A transfer that stopped short: the image is not whole.
            Phase::Receiving => Err(RecordError::Refused(Reason::Length)),
            _ => Err(RecordError::NotReady),
        }
    }

    /// Installs the image (0x2256 = 2): the platform checks the slot once more, marks it for the
    /// boot loader and restarts ([`Job::Install`]). An image that stopped short fails for
    /// [`Reason::Length`].
    pub fn install(&mut self) -> Result<(), RecordError> {
        match self.can_install() {
            Ok(()) => {
                self.status.phase = Phase::Installing;
                Ok(())
            }
            Err(RecordError::Refused(r)) => Err(self.fail(r)),
            Err(e) => Err(e),
        }
    }

    /// What the platform is to do next, if anything: write the program's whole double words,
    /// then the trailer once the image has checked, or install it.
    pub fn job(&mut self) -> Option<Job<'_>> {
        let whole = self.stage.len() - self.stage.len() % WRITE_UNIT;
        if whole > 0 {
            self.taken = whole;
            return Some(Job::Write { offset: self.written, bytes: self.stage.get(..whole)? });
        }
        if self.status.phase == Phase::Verifying && !self.trailer_written {
            self.taken = TRAILER_LEN;
            // The trailer goes through the stage, empty now: header, then signature.
            let header = self.header?.to_bytes();
            let _ = self.stage.extend_from_slice(&header);
            let _ = self.stage.extend_from_slice(&self.signature);
            return Some(Job::Write { offset: TRAILER, bytes: self.stage.get(..TRAILER_LEN)? });
        }
        if self.status.phase == Phase::Installing && !self.installing {
            self.installing = true;
            return Some(Job::Install);
        }
        None
    }

    /// The platform did the last [`Transfer::job`]; `ok` if the flash took it (for an install:
    /// the slot checked and marked, the restart next). A failure leaves the transfer failed for
    /// [`Reason::Flash`].
    pub fn done(&mut self, ok: bool) {
        if !ok {
            let _ = self.fail(Reason::Flash);
            self.installing = false;
            return;
        }
        if self.installing {
            return;
        }
        let n = core::mem::take(&mut self.taken);
        if self.status.phase == Phase::Verifying && self.stage.len() == TRAILER_LEN && n == TRAILER_LEN {
            self.trailer_written = true;
            self.stage.clear();
            self.status.phase = Phase::Ready;
            return;
        }
        let rest = self.stage.get(n..).unwrap_or_default();
        let mut kept = heapless::Vec::new();
        let _ = kept.extend_from_slice(rest);
        self.stage = kept;
        self.written += n as u32;
    }
}

/// The check of the image a slot holds, a piece at a time ([`check_slot`] runs it whole): its
/// trailer first, then the program in the pieces [`SlotCheck::next`] names, then the verdict. A
/// platform whose watchdog is fed by another task lets that task run between pieces.
#[derive(Clone, Debug)]
pub struct SlotCheck {
    header: Header,
    signature: [u8; SIGNATURE_LEN],
    verifier: Verifier,
    at: u32,
}

impl SlotCheck {
    /// Bytes of program a piece holds at most.
    pub const PIECE: u32 = 2048;

    /// The check of the slot whose trailer (its bytes at [`TRAILER`]) is `trailer`.
    pub fn start(trailer: &[u8; TRAILER_LEN]) -> Result<Self, Refusal> {
        let (head, sig) = trailer.split_at(HEADER_LEN);
        let header = Header::parse(head)?;
        if header.length > MAX_PROGRAM {
            return Err(Refusal::Length);
        }
        let mut verifier = Verifier::new();
        verifier.absorb(head);
        let signature = sig.try_into().map_err(|_| Refusal::Signature)?;
        Ok(Self { header, signature, verifier, at: 0 })
    }

    /// The next piece of program to read, where and how long; `None` once all are taken.
    pub fn next(&self) -> Option<(u32, usize)> {
        (self.at < self.header.length).then(|| (self.at, (self.header.length - self.at).min(Self::PIECE) as usize))
    }

    /// Takes the piece [`SlotCheck::next`] named, as the slot holds it.
    pub fn absorb(&mut self, piece: &[u8]) {
        self.verifier.absorb(piece);
        self.at += piece.len() as u32;
    }

    /// The verdict, once every piece is taken, for a drive that is `target`.
    pub fn finish(self, target: &Target) -> Result<Header, Refusal> {
        if self.next().is_some() {
            return Err(Refusal::Length);
        }
        self.verifier.finish(&self.signature, &target.key, target.board, target.store)
    }
}

/// Checks the image a slot holds ([`TRAILER`]: its header and signature after its program),
/// reading the slot through `read(offset, buf)` (false: the flash failed): what an install does
/// before it marks the slot for the boot loader, so that what boots is what was signed, as the
/// flash holds it.
pub fn check_slot(mut read: impl FnMut(u32, &mut [u8]) -> bool, target: &Target) -> Result<Header, Refusal> {
    let mut trailer = [0u8; TRAILER_LEN];
    if !read(TRAILER, &mut trailer) {
        return Err(Refusal::NotAnImage);
    }
    let mut check = SlotCheck::start(&trailer)?;
    let mut buf = [0u8; 256];
    while let Some((at, n)) = check.next() {
        let piece = buf.get_mut(..n.min(256)).unwrap_or_default();
        if !read(at, piece) {
            return Err(Refusal::Length);
        }
        check.absorb(piece);
    }
    check.finish(target)
}
