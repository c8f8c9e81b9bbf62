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
