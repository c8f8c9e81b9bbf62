//! A NOR flash like the STM32G474's parameter store, in memory or backed by a file, that can lose
//! power in the middle of any program or erase operation.
//!
//! Pages of 2 KiB, 8-byte (double-word) programming, erased bytes 0xFF. As on the STM32G4, a
//! double word is programmed once between erases: programming one that is not fully erased is an
//! error ([`FlashError::NotErased`]) and changes nothing, unless the new double word is all zeros
//! (RM0440, 3.3.7), which embassy-boot's state log relies on. With a file (`hal-sim --flash FILE`)
//! every operation writes the bytes it changed through to the file at once, so the flash survives
//! the process being killed at any moment.
//!
//! A power cut ([`SimFlash::cut_after`]) lets a number of operations (each `write` or `erase`
//! call is one) complete, then tears the next one as [`Tear`] says and fails it and everything
//! after it with [`FlashError::PowerCut`]: the microcontroller is off. A restart is a new
//! [`SimFlash`] on the same bytes.
//!
//! The time an operation would take on the G474 (datasheet typical: 81.7 µs a double word,
//! 22.02 ms a page erase) is added up in [`SimFlash::busy`]; nothing waits for it.

use std::fs::{File, OpenOptions};
use std::future::Future;
use std::io::{self, ErrorKind};
use std::os::unix::fs::FileExt;
use std::path::Path;
use std::pin::pin;
use std::task::{Context, Poll, Waker};
use std::time::Duration;

use embedded_storage_async::nor_flash::{ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};

/// Bytes in a page (the erase unit), as the G474's in dual-bank mode.
pub const PAGE: usize = 2048;
/// Bytes programmed at once, as the G474's double word.
pub const WORD: usize = 8;
/// Pages of the simulator's store: the G474's parameter store (PARAMS, 16 KiB in bank 2,
/// `firmware/src/flash_map.rs`).
pub const PAGES: usize = 8;
/// Datasheet typical time to program one double word.
const PROGRAM_TIME: Duration = Duration::from_nanos(81_690);
/// Datasheet typical time to erase one page.
const ERASE_TIME: Duration = Duration::from_micros(22_020);

/// What an operation cut by a power loss leaves behind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Tear {
    /// Nothing of it happened.
    Nothing,
    /// A write programmed its first half of double words (rounded down); an erase erased the first
    /// half of each of its pages.
    Half,
    /// A write programmed all its double words but the last, which got only some of its bits; an
    /// erase set only some bits of each byte (the page reads as garbage).
    Garbled,
    /// All of it happened; the power went before the caller heard so.
    Complete,
}

impl Tear {
    /// Every kind of tear.
    pub const ALL: [Tear; 4] = [Tear::Nothing, Tear::Half, Tear::Garbled, Tear::Complete];
}

/// Why an operation failed.
#[derive(Debug)]
pub enum FlashError {
    /// Offset or length not a multiple of the word or page.
    NotAligned,
    /// Outside the flash.
    OutOfBounds,
    /// A double word programmed again before an erase.
    NotErased,
    /// The power is gone (see [`SimFlash::cut_after`]).
    PowerCut,
    /// The backing file could not be written.
    Io(io::ErrorKind),
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::NotAligned => NorFlashErrorKind::NotAligned,
            FlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            _ => NorFlashErrorKind::Other,
        }
    }
}

/// The simulated flash.
#[derive(Debug)]
pub struct SimFlash {
    bytes: Vec<u8>,
    file: Option<File>,
    ops: u64,
    cut: Option<(u64, Tear)>,
    dead: bool,
    erases: Vec<u64>,
    busy: Duration,
}

impl SimFlash {
    /// An erased flash of `pages` pages in memory.
    pub fn erased(pages: usize) -> Self {
        Self::from_bytes(vec![0xFF; pages * PAGE])
    }

    /// A flash in memory holding `bytes` (a whole number of pages, as a restart finds them).
    pub fn from_bytes(bytes: Vec<u8>) -> Self {
        let pages = bytes.len() / PAGE;
        Self { bytes, file: None, ops: 0, cut: None, dead: false, erases: vec![0; pages], busy: Duration::ZERO }
    }

    /// The flash of [`PAGES`] pages kept in the file at `path`, created erased if missing. A file
    /// of another size is refused ([`ErrorKind::InvalidData`]): it is not this flash.
    pub fn open(path: &Path) -> io::Result<Self> {
        let file = OpenOptions::new().read(true).write(true).create(true).truncate(false).open(path)?;
        let len = file.metadata()?.len();
        let size = (PAGES * PAGE) as u64;
        let bytes = if len == 0 {
            let bytes = vec![0xFF; PAGES * PAGE];
            file.write_all_at(&bytes, 0)?;
            bytes
        } else if len == size {
            let mut bytes = vec![0; PAGES * PAGE];
            file.read_exact_at(&mut bytes, 0)?;
            bytes
        } else {
            let msg = format!("{}: {len} bytes, not a flash image of {size} bytes", path.display());
            return Err(io::Error::new(ErrorKind::InvalidData, msg));
        };
        Ok(Self { file: Some(file), ..Self::from_bytes(bytes) })
    }

    /// The bytes of the flash.
    pub fn bytes(&self) -> &[u8] {
        &self.bytes
    }

    /// Program and erase operations so far.
    pub fn ops(&self) -> u64 {
        self.ops
    }

    /// Erases of each page so far.
    pub fn erase_counts(&self) -> &[u64] {
        &self.erases
    }

    /// How long the operations so far would have kept the G474's flash busy.
    pub fn busy(&self) -> Duration {
        self.busy
    }

    /// Cuts the power after `n` more operations complete: the next one is torn as `tear` says.
    pub fn cut_after(&mut self, n: u64, tear: Tear) {
        self.cut = Some((self.ops + n, tear));
    }

    /// Whether the power has been cut.
    pub fn is_dead(&self) -> bool {
        self.dead
    }

    /// Counts an operation; the tear to apply if the power goes now.
    fn begin(&mut self) -> Result<Option<Tear>, FlashError> {
        if self.dead {
            return Err(FlashError::PowerCut);
        }
        let tear = match self.cut {
            Some((at, tear)) if at == self.ops => {
                self.dead = true;
                Some(tear)
            }
            _ => None,
        };
        self.ops += 1;
        Ok(tear)
    }

    /// Writes the changed range through to the file.
    fn persist(&mut self, from: usize, to: usize) -> Result<(), FlashError> {
        match (&self.file, self.bytes.get(from..to)) {
            (Some(file), Some(b)) => file.write_all_at(b, from as u64).map_err(|e| FlashError::Io(e.kind())),
            _ => Ok(()),
        }
    }

    fn check(&self, offset: u32, len: usize, align: usize) -> Result<usize, FlashError> {
        let from = offset as usize;
        if !from.is_multiple_of(align) || !len.is_multiple_of(align) {
            return Err(FlashError::NotAligned);
        }
        if from + len > self.bytes.len() {
            return Err(FlashError::OutOfBounds);
        }
        Ok(from)
    }
}

impl ErrorType for SimFlash {
    type Error = FlashError;
}

impl ReadNorFlash for SimFlash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        if self.dead {
            return Err(FlashError::PowerCut);
        }
        let from = self.check(offset, bytes.len(), 1)?;
        bytes.copy_from_slice(self.bytes.get(from..from + bytes.len()).ok_or(FlashError::OutOfBounds)?);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.bytes.len()
    }
}

impl NorFlash for SimFlash {
    const WRITE_SIZE: usize = WORD;
    const ERASE_SIZE: usize = PAGE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        let len = (to as usize).checked_sub(from as usize).ok_or(FlashError::OutOfBounds)?;
        let start = self.check(from, len, PAGE)?;
        let tear = self.begin()?;
        for page in (start..start + len).step_by(PAGE) {
            let bytes = self.bytes.get_mut(page..page + PAGE).ok_or(FlashError::OutOfBounds)?;
            match tear {
                None | Some(Tear::Complete) => bytes.fill(0xFF),
                Some(Tear::Nothing) => {}
                Some(Tear::Half) => bytes.iter_mut().take(PAGE / 2).for_each(|b| *b = 0xFF),
                Some(Tear::Garbled) => bytes.iter_mut().for_each(|b| *b |= 0x5A),
            }
            if let Some(n) = self.erases.get_mut(page / PAGE) {
                *n += 1;
            }
            self.busy += ERASE_TIME;
        }
        self.persist(start, start + len)?;
        if tear.is_some() { Err(FlashError::PowerCut) } else { Ok(()) }
    }

    async fn write(&mut self, offset: u32, data: &[u8]) -> Result<(), FlashError> {
        let start = self.check(offset, data.len(), WORD)?;
        let target = self.bytes.get(start..start + data.len()).ok_or(FlashError::OutOfBounds)?;
        let programmed_over = |(t, d): (&[u8], &[u8])| t.iter().any(|&b| b != 0xFF) && d.iter().any(|&b| b != 0);
        if target.chunks(WORD).zip(data.chunks(WORD)).any(programmed_over) {
            return Err(FlashError::NotErased);
        }
        let tear = self.begin()?;
        let words = data.len() / WORD;
        let (full, partial) = match tear {
            None | Some(Tear::Complete) => (words, false),
            Some(Tear::Nothing) => (0, false),
            Some(Tear::Half) => (words / 2, false),
            Some(Tear::Garbled) => (words.saturating_sub(1), words > 0),
        };
        let programmed = full * WORD + if partial { WORD } else { 0 };
        let target = self.bytes.get_mut(start..start + programmed).ok_or(FlashError::OutOfBounds)?;
        for (i, (t, &d)) in target.iter_mut().zip(data).enumerate() {
            // Programming only clears bits. A torn last word: only some of those that were to go to
            // 0 did.
            *t &= if i >= full * WORD { d | 0xA5 } else { d };
        }
        self.busy += PROGRAM_TIME * (full + usize::from(partial)) as u32;
        self.persist(start, start + programmed)?;
        if tear.is_some() { Err(FlashError::PowerCut) } else { Ok(()) }
    }
}

/// Runs `future` to its end on this thread. The simulated flash never makes it wait, so this is
/// one poll in practice; a future that does wait is polled again after a yield.
pub fn block_on<F: Future>(future: F) -> F::Output {
    let mut future = pin!(future);
    let mut cx = Context::from_waker(Waker::noop());
    loop {
        if let Poll::Ready(out) = future.as_mut().poll(&mut cx) {
            return out;
        }
        std::thread::yield_now();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn programs_once_and_erases_to_ff() {
        let mut f = SimFlash::erased(2);
        block_on(f.write(8, &[0; 8])).unwrap();
        assert!(matches!(block_on(f.write(8, &[1; 8])), Err(FlashError::NotErased)));
        // Zeros over a programmed double word, as the G474 allows.
        block_on(f.write(8, &[0; 8])).unwrap();
        block_on(f.write(0, &[0x0F; 8])).unwrap();
        block_on(f.write(0, &[0; 8])).unwrap();
        assert_eq!(&f.bytes()[..16], &[0; 16]);
        assert!(matches!(block_on(f.write(4, &[0; 8])), Err(FlashError::NotAligned)));
        assert!(matches!(block_on(f.write(4096, &[0; 8])), Err(FlashError::OutOfBounds)));
        block_on(f.erase(0, 2048)).unwrap();
        assert!(f.bytes().iter().all(|&b| b == 0xFF));
        assert_eq!((f.ops(), f.erase_counts()), (5, &[1, 0][..]));
    }

    #[test]
    fn a_cut_tears_the_operation_and_stops_everything_after_it() {
        for (tear, want) in [
            (Tear::Nothing, [0xFF; 4]),
            (Tear::Half, [0x00, 0x00, 0xFF, 0xFF]),
            (Tear::Garbled, [0x00, 0x00, 0x00, 0xA5]),
        ] {
            let mut f = SimFlash::erased(1);
            f.cut_after(1, tear);
            block_on(f.write(0, &[0; 8])).unwrap();
            assert!(matches!(block_on(f.write(8, &[0; 32])), Err(FlashError::PowerCut)));
            let words: Vec<u8> = (1..5).map(|w| f.bytes()[w * 8]).collect();
            assert_eq!(words, want, "{tear:?}");
            assert!(matches!(block_on(f.read(0, &mut [0; 1])), Err(FlashError::PowerCut)));
        }
        let mut f = SimFlash::erased(1);
        block_on(f.write(0, &[0; 2048])).unwrap();
        f.cut_after(0, Tear::Half);
        assert!(block_on(f.erase(0, 2048)).is_err());
        assert_eq!((f.bytes()[1023], f.bytes()[1024]), (0xFF, 0x00));
    }

    #[test]
    fn a_file_keeps_the_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("flash.bin");
        let mut f = SimFlash::open(&path).unwrap();
        block_on(f.write(16, &[1, 2, 3, 4, 5, 6, 7, 8])).unwrap();
        drop(f);
        let f = SimFlash::open(&path).unwrap();
        assert_eq!(&f.bytes()[16..24], &[1, 2, 3, 4, 5, 6, 7, 8]);
        std::fs::write(&path, [0u8; 100]).unwrap();
        assert_eq!(SimFlash::open(&path).unwrap_err().kind(), ErrorKind::InvalidData);
    }
}
