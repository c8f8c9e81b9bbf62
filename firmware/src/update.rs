//! Firmware images on the board: the drive's transfer (`drive_core::update`) written into the
//! DFU slot after each reply, the install (the slot checked once more as the flash holds it,
//! marked for embassy-boot's boot loader, a reset), and the new image's confirmation once it has
//! served the bus. Each board says where its DFU slot and the boot loader's state lie in the flash
//! its parameter store uses (`board::dfu_at`, `board::state_at`).

use defmt::{info, warn};
use drive_core::update::{self, BootState, Header, Job, SlotCheck, Target};
use embassy_boot::{FirmwareState, State};
use embedded_storage_async::nor_flash::{ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};

use crate::app::Drive;
use crate::board;

/// The public key images must be signed with: the `.pub` file `OSD_UPDATE_KEY` names (64 hex
/// digits), the repository's test key unless a build sets it (`.cargo/config.toml`).
pub const KEY: [u8; 32] = match update::key_from_hex(include_str!(env!("OSD_UPDATE_KEY"))) {
    Some(key) => key,
    None => panic!("OSD_UPDATE_KEY: not a key file (64 hex digits)"),
};
/// The build takes images signed with the repository's test key, which anyone can sign with.
pub const TEST: bool = TARGET.test_key();
/// What this build takes images for.
pub const TARGET: Target = Target { board: board::IMAGE_BOARD, key: KEY, store: drive_core::store::VERSION };

/// A part of the board's flash addressed from 0, `len` bytes: `at` gives an access's offset in
/// the flash (`None` outside the part).
struct Part<'a, F> {
    flash: &'a mut F,
    at: fn(u32, u32) -> Option<u32>,
    len: u32,
}

impl<F: NorFlash> Part<'_, F> {
    fn to(&self, offset: u32, len: usize) -> Result<u32, NorFlashErrorKind> {
        (self.at)(offset, len as u32).ok_or(NorFlashErrorKind::OutOfBounds)
    }
}

impl<F: NorFlash> ErrorType for Part<'_, F> {
    type Error = NorFlashErrorKind;
}

impl<F: NorFlash> ReadNorFlash for Part<'_, F> {
    const READ_SIZE: usize = F::READ_SIZE;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let at = self.to(offset, bytes.len())?;
        self.flash.read(at, bytes).await.map_err(|e| e.kind())
    }

    fn capacity(&self) -> usize {
        self.len as usize
    }
}

impl<F: NorFlash> NorFlash for Part<'_, F> {
    const WRITE_SIZE: usize = F::WRITE_SIZE;
    const ERASE_SIZE: usize = F::ERASE_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let at = self.to(from, to.saturating_sub(from) as usize)?;
        self.flash.erase(at, at + (to - from)).await.map_err(|e| e.kind())
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let at = self.to(offset, bytes.len())?;
        self.flash.write(at, bytes).await.map_err(|e| e.kind())
    }
}

fn dfu<F: NorFlash>(flash: &mut F) -> Part<'_, F> {
    Part { flash, at: board::dfu_at, len: update::SLOT_LEN + update::PAGE }
}

fn state<F: NorFlash>(flash: &mut F) -> Part<'_, F> {
    Part { flash, at: board::state_at, len: board::STATE_LEN }
}

/// The update state word embassy-boot's calls read and write through (a double word).
#[repr(align(8))]
struct Word([u8; 8]);

/// The running image's version: its trailer's, where ACTIVE has one of this board's (an image
/// an update installed), else the build's.
pub fn running_version() -> u32 {
    match Header::parse(&board::active_trailer()) {
        Ok(h) if h.board == board::IMAGE_BOARD => h.version,
        _ => drive_core::ident::VERSION,
    }
}

/// The update's part of the Modbus task.
pub struct Updates {
    /// The DFU page the transfer erased last: a page is erased as the writes enter it.
    erased: Option<u32>,
    /// The running image is on trial: it confirms itself once it has served the bus.
    trial: bool,
}

impl Updates {
    /// At power-up: what the boot loader's state says of the running image, told to `drive`
    /// with what images it takes.
    pub fn power_up<F: NorFlash>(flash: &mut F, drive: &mut Drive) -> Self {
        let mut word = Word([0; 8]);
        let read = embassy_futures::block_on(FirmwareState::new(state(flash), &mut word.0).get_state());
        let boot = match read {
            Ok(State::Swap) if board::BOOT_LOADER => BootState::Trial,
            Ok(State::Swap) => BootState::Marked,
            Ok(State::Revert) => BootState::RolledBack,
            Ok(_) => BootState::Confirmed,
            Err(_) => {
                warn!("update state unreadable");
                BootState::Confirmed
            }
        };
        let version = running_version();
        info!("image {=u32:#x}, boot state {=u8}{}", version, boot as u8, if TEST { ", test key" } else { "" });
        drive.state_mut().set_updates(Some(TARGET), version);
        drive.state_mut().set_boot_state(boot);
        Self { erased: None, trial: boot == BootState::Trial }
    }

    /// After a reply: the image on trial confirms itself once the drive has answered a request
    /// addressed to it, then the flash does what the transfer asks. True once an image is
    /// installed: the caller resets once the reply is out.
    pub async fn serve<F: NorFlash>(&mut self, drive: &mut Drive, flash: &mut F) -> bool {
        if self.trial && drive.counters().slave_messages > 0 {
            let mut word = Word([0; 8]);
            match embassy_futures::block_on(FirmwareState::new(state(flash), &mut word.0).mark_booted()) {
                Ok(()) => {
                    self.trial = false;
                    drive.state_mut().set_boot_state(BootState::Confirmed);
                    info!("image confirmed");
                }
                Err(_) => warn!("confirming the image failed"),
            }
        }
        let mut installed = false;
        loop {
            let (transfer, _) = drive.state_mut().transfer_mut();
            let ok = match transfer.job() {
                Some(Job::Write { offset, bytes }) => self.write(flash, offset, bytes),
                Some(Job::Install) => {
                    installed = install(flash).await;
                    installed
                }
                None => return installed,
            };
            transfer.done(ok);
        }
    }

    /// Writes `bytes` at `offset` of the DFU slot, erasing each page the write enters (a
    /// transfer writes forward from 0).
    fn write<F: NorFlash>(&mut self, flash: &mut F, offset: u32, bytes: &[u8]) -> bool {
        let mut part = dfu(flash);
        if offset == 0 {
            self.erased = None;
        }
        let end = offset + bytes.len() as u32;
        let mut page = offset / update::PAGE;
        let written = embassy_futures::block_on(async {
            while page * update::PAGE < end {
                if self.erased != Some(page) {
                    part.erase(page * update::PAGE, (page + 1) * update::PAGE).await?;
                    self.erased = Some(page);
                }
                page += 1;
            }
            part.write(offset, bytes).await
        });
        if written.is_err() {
            warn!("update: writing {=usize} bytes at {=u32} failed", bytes.len(), offset);
        }
        written.is_ok()
    }
}

/// The install: the slot checked once more as the flash holds it, then marked for the boot
/// loader. The check reads the slot a piece at a time and lets the other tasks run between pieces
/// (192 KiB take about 180 ms of digest on the Cortex-M4, `cargo xtask tick-cost`): the sense task
/// feeds the watchdog meanwhile. Out of line: the check's buffer and digest are on the stack for
/// this call only.
#[inline(never)]
async fn install<F: NorFlash>(flash: &mut F) -> bool {
    let mut part = dfu(flash);
    let mut trailer = [0u8; update::TRAILER_LEN];
    let check = match part.read(update::TRAILER, &mut trailer).await {
        Ok(()) => SlotCheck::start(&trailer),
        Err(_) => Err(update::Refusal::NotAnImage),
    };
    let Ok(mut check) = check else {
        warn!("update: the slot holds no image");
        return false;
    };
    let mut buf = [0u8; 256];
    let mut pieces = 0u32;
    while let Some((at, n)) = check.next() {
        let piece = buf.get_mut(..n.min(256)).unwrap_or_default();
        if part.read(at, piece).await.is_err() {
            warn!("update: the slot cannot be read");
            return false;
        }
        check.absorb(piece);
        pieces += 1;
        if pieces.is_multiple_of(8) {
            embassy_futures::yield_now().await;
        }
    }
    let header = match check.finish(&TARGET) {
        Ok(h) => h,
        Err(_) => {
            warn!("update: the slot does not check");
            return false;
        }
    };
    let mut word = Word([0; 8]);
    let marked = FirmwareState::new(state(flash), &mut word.0).mark_updated().await.is_ok();
    if marked {
        info!("image {=u32:#x} marked for the boot loader: restarting", header.version);
    }
    marked
}
