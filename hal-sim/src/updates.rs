//! The simulated drive's firmware images: what its slots boot (ACTIVE's trailer says which, its
//! version; the simulator runs the same drive whatever the program's bytes), the transfer's
//! writes into DFU, the install, the new image's confirmation once it has served the bus, and
//! the boot loader's rollback of one that never confirms.

use std::io;

use drive_core::ident::{self, Identity};
use drive_core::update::{self, Board, BootState, Header, Job, TEST_KEY, Target};
use embassy_boot::State;

use crate::Drive;
use crate::slots::{SlotError, Slots, UPDATE_START};

/// What the simulator takes images for: its board, the repository's test key, its store's
/// format.
pub const TARGET: Target = Target { board: Board::Simulator, key: TEST_KEY, store: drive_core::store::VERSION };

/// A program that starts with these bytes stands for an image that fails its self-test: it
/// never confirms itself, so the boot loader rolls it back at the next reset.
pub const NO_CONFIRM: &[u8] = b"NO-CONFIRM";

/// One drive's image slots and what runs from them.
pub struct Firmware {
    slots: Slots,
    /// The image that runs is on trial: it confirms itself once it has served the bus.
    trial: bool,
    /// It would confirm itself (its program does not start with [`NO_CONFIRM`]).
    confirms: bool,
    /// Its version: its header's, or the build's where ACTIVE has no image of the simulator's.
    version: u32,
    /// What the boot loader's state says of it.
    boot: BootState,
}

impl std::fmt::Debug for Firmware {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Firmware").field("version", &self.version).field("trial", &self.trial).finish_non_exhaustive()
    }
}

impl Default for Firmware {
    fn default() -> Self {
        Self::new()
    }
}

impl Firmware {
    /// Erased slots: the drive runs the build's own image, as flashed by a probe.
    pub fn new() -> Self {
        Self { slots: Slots::new(), trial: false, confirms: true, version: ident::VERSION, boot: BootState::Confirmed }
    }

    /// A reset: the boot loader swaps, resumes or rolls back as the update state says, then the
    /// image in ACTIVE starts. Its version.
    pub fn boot(&mut self) -> io::Result<u32> {
        let boot = self.slots.boot().map_err(slot_error)?;
        self.version = boot.header.filter(|h| h.board == Board::Simulator).map_or(ident::VERSION, |h| h.version);
        self.trial = boot.state == UPDATE_START;
        self.boot = match boot.state {
            UPDATE_START => BootState::Trial,
            State::Revert => BootState::RolledBack,
            _ => BootState::Confirmed,
        };
        self.confirms = !self.slots.active().starts_with(NO_CONFIRM);
        Ok(self.version)
    }

    /// The version of the image that runs.
    pub fn version(&self) -> u32 {
        self.version
    }

    /// The update state as the running image reads it (embassy-boot's `State`).
    pub fn state(&mut self) -> io::Result<State> {
        self.slots.state().map_err(slot_error)
    }

    /// The identification of a drive running this image: its version, and that it takes images
    /// signed with the repository's test key.
    pub fn identity(&self, base: &Identity) -> &'static Identity {
        let v = self.version;
        let revision = format!("{}.{}.{} test-key", v >> 16, (v >> 8) & 0xFF, v & 0xFF);
        // A few dozen bytes a restart: the drive keeps `&'static` texts, as a firmware has them.
        Box::leak(Box::new(Identity { revision: Box::leak(revision.into_boxed_str()), ..*base }))
    }

    /// Tells `drive` what it runs and what images it takes.
    pub fn configure(&self, drive: &mut Drive) {
        drive.state_mut().set_updates(Some(TARGET), self.version);
        drive.state_mut().set_boot_state(self.boot);
    }

    /// Does what `drive`'s transfer asks of the flash; true once an image is installed, when
    /// the drive must restart into it.
    pub fn serve(&mut self, drive: &mut Drive) -> bool {
        if self.trial && self.confirms && drive.counters().slave_messages > 0 {
            // The self-test: the new image has powered up and answered the bus.
            match self.slots.mark_booted() {
                Ok(()) => {
                    self.trial = false;
                    self.boot = BootState::Confirmed;
                    drive.state_mut().set_boot_state(self.boot);
                }
                Err(e) => eprintln!("hal-sim: confirming the image failed: {e:?}"),
            }
        }
        let mut restart = false;
        loop {
            let (transfer, _) = drive.state_mut().transfer_mut();
            let ok = match transfer.job() {
                Some(Job::Write { offset, bytes }) => self.slots.write_dfu(offset, bytes).map_err(|e| format!("{e:?}")),
                Some(Job::Install) => self.install(),
                None => return restart,
            };
            if let Err(e) = &ok {
                eprintln!("hal-sim: update: {e}");
            }
            restart |= ok.is_ok() && transfer.status().phase == update::Phase::Installing;
            transfer.done(ok.is_ok());
        }
    }

    /// Checks the image in DFU once more as the flash holds it, and marks it for the boot loader.
    fn install(&mut self) -> Result<(), String> {
        let header = {
            let dfu = self.slots.dfu();
            let read = |at: u32, buf: &mut [u8]| match dfu.get(at as usize..at as usize + buf.len()) {
                Some(bytes) => {
                    buf.copy_from_slice(bytes);
                    true
                }
                None => false,
            };
            update::check_slot(read, &TARGET).map_err(|r| format!("the slot does not check: {r:?}"))?
        };
        self.slots.mark_updated().map_err(|e| format!("{e:?}"))?;
        eprintln!("hal-sim: image {:#08X} marked for boot", header.version);
        Ok(())
    }
}

/// The secret half of the repository's test key pair (`keys/test.key`), which the simulator's
/// images are signed with in the tests: public, as the pair is.
pub fn test_secret() -> [u8; 32] {
    const SECRET: [u8; 32] = match update::key_from_hex(include_str!("../../keys/test.key")) {
        Some(key) => key,
        None => panic!("keys/test.key: not 32 bytes in hex"),
    };
    SECRET
}

/// The image of `program` that `header` describes (its length set to the program's), signed
/// with `secret`, as `cargo xtask sign` makes one.
pub fn sign(secret: &[u8; 32], header: Header, program: &[u8]) -> Vec<u8> {
    use ed25519_dalek::Signer as _;
    let header = Header { length: program.len() as u32, ..header };
    let mut bytes = header.to_bytes().to_vec();
    bytes.extend_from_slice(program);
    let signature = ed25519_dalek::SigningKey::from_bytes(secret).sign(&update::digest(&bytes));
    bytes.extend_from_slice(&signature.to_bytes());
    bytes
}

fn slot_error(e: SlotError) -> io::Error {
    io::Error::other(format!("image slots: {e:?}"))
}
