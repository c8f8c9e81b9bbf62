//! The G474's image slots (embassy-boot's ACTIVE, DFU and STATE) on one [`SimFlash`], run by
//! embassy-boot's own boot loader and updater, so that a power cut can be tested at every flash
//! operation of an update: the transfer into DFU, the marks in STATE, the boot loader's swap and
//! its rollback.
//!
//! The three regions lie in one flash, in the G474's order and sizes (`firmware/src/flash_map.rs`),
//! so that one operation counter and one [`SimFlash::cut_after`] span a whole update. A reset is
//! [`Slots::boot`]: the boot loader's `prepare_boot`, then what ACTIVE holds.
//!
//! ```
//! use drive_core::update::{Board, Header, TRAILER};
//! use hal_sim::slots::{Slots, UPDATE_START};
//! let header = Header { board: Board::Simulator, version: 2, length: 8, store: 1 };
//! let mut slots = Slots::new();
//! slots.write_dfu(0, &[0x42; 8]).unwrap();
//! slots.write_dfu(TRAILER, &header.to_bytes()).unwrap();
//! slots.mark_updated().unwrap();
//! let boot = slots.boot().unwrap(); // the swap
//! assert_eq!((boot.state, boot.header), (UPDATE_START, Some(header)));
//! slots.mark_booted().unwrap();
//! assert_eq!(slots.boot().unwrap().header, Some(header));
//! ```

use std::cell::{Ref, RefCell};

use drive_core::update::{HEADER_LEN, Header, PAGE as IMAGE_PAGE, SLOT_LEN, TRAILER};
use embassy_boot::{
    AlignedBuffer, BlockingFirmwareState, BlockingFirmwareUpdater, BootLoader, BootLoaderConfig, FirmwareUpdaterConfig,
    State,
};
use embassy_embedded_hal::flash::partition::BlockingPartition;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embedded_storage::nor_flash::{ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};
use embedded_storage_async::nor_flash as nor_async;

use crate::flash::{FlashError, PAGE, SimFlash, WORD, block_on};

/// Where ACTIVE starts in the flash: the running image.
pub const ACTIVE: u32 = 0;
/// ACTIVE's length: an image slot.
pub const ACTIVE_LEN: u32 = SLOT_LEN;
/// Where DFU starts: the update being received.
pub const DFU: u32 = ACTIVE + ACTIVE_LEN;
/// DFU's length: one page more than ACTIVE, the room embassy-boot's swap moves pages through.
pub const DFU_LEN: u32 = SLOT_LEN + IMAGE_PAGE;
/// Where STATE starts: embassy-boot's magic word and progress log.
pub const STATE: u32 = DFU + DFU_LEN;
/// STATE's length: the G474's two pages, room for the progress of a swap and a rollback.
pub const STATE_LEN: u32 = 2 * IMAGE_PAGE;
/// Pages of the whole flash.
pub const PAGES: usize = ((STATE + STATE_LEN) / IMAGE_PAGE) as usize;

/// What the application finds in STATE after a reset that swapped an update in: it runs on
/// trial and must confirm ([`Slots::mark_booted`]) or be rolled back at the next reset.
pub const UPDATE_START: State = State::Swap;

const _: () = assert!(PAGE as u32 == IMAGE_PAGE, "the simulated flash's page is not the slots' page");

/// A [`SimFlash`] through the blocking NorFlash traits embassy-boot takes; the simulated flash
/// never waits, so each call is one poll.
#[derive(Debug)]
pub struct Blocking(pub SimFlash);

impl ErrorType for Blocking {
    type Error = FlashError;
}

impl ReadNorFlash for Blocking {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        block_on(nor_async::ReadNorFlash::read(&mut self.0, offset, bytes))
    }

    fn capacity(&self) -> usize {
        nor_async::ReadNorFlash::capacity(&self.0)
    }
}

impl NorFlash for Blocking {
    const WRITE_SIZE: usize = WORD;
    const ERASE_SIZE: usize = PAGE;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), FlashError> {
        block_on(nor_async::NorFlash::erase(&mut self.0, from, to))
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), FlashError> {
        block_on(nor_async::NorFlash::write(&mut self.0, offset, bytes))
    }
}

/// Why a slot operation failed.
#[derive(Debug, PartialEq, Eq)]
pub enum SlotError {
    /// The power was cut during it (see [`SimFlash::cut_after`]).
    PowerCut,
    /// The flash refused an operation: misaligned, out of bounds, or not erased.
    Flash(NorFlashErrorKind),
    /// An update was written while one is on trial (embassy-boot's `BadState`): the running
    /// image must confirm itself first.
    BadState,
}

/// What a reset found and did.
#[derive(Debug, PartialEq, Eq)]
pub struct Boot {
    /// The boot loader's answer (`prepare_boot`): `Swap` when STATE asked for a swap, whether it
    /// swapped the update in or rolled an unconfirmed one back.
    pub loader: State,
    /// STATE's magic as the started application reads it: [`UPDATE_START`] if it runs on trial,
    /// `Revert` once an update was rolled back, `Boot` otherwise.
    pub state: State,
    /// The header in ACTIVE's trailer: the image that runs, `None` if there is none.
    pub header: Option<Header>,
}

type Partition<'a> = BlockingPartition<'a, NoopRawMutex, Blocking>;

/// ACTIVE, DFU and STATE on one simulated flash, driven by embassy-boot.
pub struct Slots {
    flash: Mutex<NoopRawMutex, RefCell<Blocking>>,
    /// The DFU page the transfer erased last, as one long-lived updater remembers it: it erases
    /// a page when a write enters another one.
    erased: Option<u32>,
}

impl Default for Slots {
    fn default() -> Self {
        Self::new()
    }
}

impl Slots {
    /// Slots on an erased flash: no image, nothing to do.
    pub fn new() -> Self {
        Self::from_flash(SimFlash::erased(PAGES))
    }

    /// Slots on `flash` (of [`PAGES`] pages), as a power-up finds it.
    pub fn from_flash(flash: SimFlash) -> Self {
        assert_eq!(flash.bytes().len(), PAGES * PAGE, "not a flash of the slots' size");
        Self { flash: Mutex::new(RefCell::new(Blocking(flash))), erased: None }
    }

    /// The flash.
    pub fn flash(&self) -> Ref<'_, SimFlash> {
        Ref::map(self.flash.borrow().borrow(), |b| &b.0)
    }

    /// The flash, to cut its power.
    pub fn flash_mut(&mut self) -> &mut SimFlash {
        &mut self.flash.get_mut().get_mut().0
    }

    /// The flash, to power up on its bytes.
    pub fn into_flash(self) -> SimFlash {
        self.flash.into_inner().into_inner().0
    }

    /// ACTIVE's bytes: the image that runs.
    pub fn active(&self) -> Ref<'_, [u8]> {
        self.region(ACTIVE, ACTIVE_LEN)
    }

    /// DFU's bytes: the update received, or after a swap the image before it, one page on.
    pub fn dfu(&self) -> Ref<'_, [u8]> {
        self.region(DFU, DFU_LEN)
    }

    fn region(&self, start: u32, len: u32) -> Ref<'_, [u8]> {
        Ref::map(self.flash(), |f| &f.bytes()[start as usize..(start + len) as usize])
    }

    /// The header in ACTIVE's trailer, if it holds one.
    pub fn active_header(&self) -> Option<Header> {
        Header::parse(&self.active()[TRAILER as usize..][..HEADER_LEN]).ok()
    }

    /// Writes `bytes` of an update at `offset` into DFU through embassy-boot's updater, which
    /// erases each page as the transfer enters it. A transfer writes ascending offsets, 8-byte
    /// aligned, whole double words.
    pub fn write_dfu(&mut self, offset: u32, bytes: &[u8]) -> Result<(), SlotError> {
        let Some(last) = bytes.len().checked_sub(1) else { return Ok(()) };
        if offset == 0 {
            // A transfer starts again: its first page is erased again.
            self.erased = None;
        }
        // An updater lives for one call here and would erase the page it starts in again: bytes
        // continuing the page this transfer erased are programmed as the updater would (a
        // write), the rest goes through it.
        let head = if self.erased == Some(offset / IMAGE_PAGE) {
            bytes.len().min((IMAGE_PAGE - offset % IMAGE_PAGE) as usize)
        } else {
            0
        };
        let (continued, entering) = bytes.split_at(head);
        let result = (|| {
            let (mut dfu, state) = self.partitions();
            if !continued.is_empty() {
                dfu.write(offset, continued).map_err(|e| self.error(e.kind()))?;
            }
            if !entering.is_empty() {
                let mut word = AlignedBuffer([0; WORD]);
                let mut updater = BlockingFirmwareUpdater::new(FirmwareUpdaterConfig { dfu, state }, &mut word.0);
                updater.write_firmware(offset as usize + head, entering).map_err(|e| self.updater_error(e))?;
            }
            Ok(())
        })();
        if result.is_ok() {
            self.erased = Some((offset + last as u32) / IMAGE_PAGE);
        }
        result
    }

    /// Asks the boot loader to swap DFU in at the next reset (embassy-boot's `mark_updated`,
    /// without its signature check: the drive checks an image as it arrives).
    pub fn mark_updated(&mut self) -> Result<(), SlotError> {
        self.erased = None;
        self.with_state(|s| s.mark_updated())
    }

    /// Confirms the running image: the boot loader keeps it (embassy-boot's `mark_booted`).
    pub fn mark_booted(&mut self) -> Result<(), SlotError> {
        self.with_state(|s| s.mark_booted())
    }

    /// STATE's magic, as the application reads it.
    pub fn state(&mut self) -> Result<State, SlotError> {
        self.with_state(|s| s.get_state())
    }

    /// A reset: the boot loader swaps, resumes or rolls back as STATE says, then the image in
    /// ACTIVE would start.
    pub fn boot(&mut self) -> Result<Boot, SlotError> {
        self.erased = None;
        // A page at a time: one read and one write a page, the fewest operations a swap can take.
        let mut page = AlignedBuffer([0; PAGE]);
        let active = BlockingPartition::new(&self.flash, ACTIVE, ACTIVE_LEN);
        let (dfu, state) = self.partitions();
        let mut loader = BootLoader::new(BootLoaderConfig { active, dfu, state });
        let loader_state = loader.prepare_boot(&mut page.0).map_err(|e| match e {
            embassy_boot::BootError::Flash(kind) => self.error(kind),
            embassy_boot::BootError::BadMagic => SlotError::Flash(NorFlashErrorKind::Other),
        })?;
        let state = loader.read_state(&mut page.0).map_err(|_| self.error(NorFlashErrorKind::Other))?;
        Ok(Boot { loader: loader_state, state, header: self.active_header() })
    }

    fn partitions(&self) -> (Partition<'_>, Partition<'_>) {
        (BlockingPartition::new(&self.flash, DFU, DFU_LEN), BlockingPartition::new(&self.flash, STATE, STATE_LEN))
    }

    fn with_state<T>(
        &mut self,
        f: impl FnOnce(&mut BlockingFirmwareState<'_, Partition<'_>>) -> Result<T, embassy_boot::FirmwareUpdaterError>,
    ) -> Result<T, SlotError> {
        let mut word = AlignedBuffer([0; WORD]);
        let (_, state) = self.partitions();
        let result = f(&mut BlockingFirmwareState::new(state, &mut word.0));
        result.map_err(|e| self.updater_error(e))
    }

    fn updater_error(&self, e: embassy_boot::FirmwareUpdaterError) -> SlotError {
        match e {
            embassy_boot::FirmwareUpdaterError::Flash(kind) => self.error(kind),
            embassy_boot::FirmwareUpdaterError::BadState => SlotError::BadState,
            embassy_boot::FirmwareUpdaterError::Signature(_) => SlotError::Flash(NorFlashErrorKind::Other),
        }
    }

    /// A flash error, or the power cut that caused it (the partitions keep only its kind).
    fn error(&self, kind: NorFlashErrorKind) -> SlotError {
        if self.flash().is_dead() { SlotError::PowerCut } else { SlotError::Flash(kind) }
    }

    /// Programs an image into ACTIVE as a probe flashing the drive would: `program` from the
    /// slot's start, `trailer` at [`TRAILER`], STATE erased (nothing to do at boot).
    pub fn install(&mut self, program: &[u8], trailer: &[u8]) -> Result<(), SlotError> {
        self.erased = None;
        let flash = &mut self.flash.get_mut().get_mut().0;
        for (start, len) in [(ACTIVE, ACTIVE_LEN), (STATE, STATE_LEN)] {
            block_on(nor_async::NorFlash::erase(flash, start, start + len)).map_err(flash_error)?;
        }
        for (at, bytes) in [(0, program), (TRAILER, trailer)] {
            let mut padded = bytes.to_vec();
            padded.resize(bytes.len().next_multiple_of(WORD), 0xFF);
            block_on(nor_async::NorFlash::write(flash, ACTIVE + at, &padded)).map_err(flash_error)?;
        }
        Ok(())
    }
}

fn flash_error(e: FlashError) -> SlotError {
    match e {
        FlashError::PowerCut => SlotError::PowerCut,
        e => SlotError::Flash(e.kind()),
    }
}
