//! The firmware update's and the write lock's objects (0x2250-0x2261): what a transfer says, the
//! orders a master gives it, and the password that locks a commissioned drive's writes.

use super::{DriveState, ProgramMemory, STORAGE_SAVING};
use crate::controller::Shared;
use crate::od::{Obj, ObjError};
use crate::update::{BootState, Phase, RecordError, Target, Transfer};
use core::borrow::Borrow;

/// 0x2256: abandon the transfer.
const ABORT: u32 = 1;
/// 0x2256: install the image ready.
const INSTALL: u32 = 2;

/// Whether writing `obj` is an order to the transfer or the lock.
pub(crate) const fn is_order(obj: Obj) -> bool {
    matches!(obj, Obj::UpdateControl | Obj::Unlock | Obj::Password)
}

/// The refusal of a transfer's order, as an object's.
const fn refusal(e: RecordError) -> ObjError {
    match e {
        RecordError::Busy => ObjError::Busy,
        _ => ObjError::NotNow,
    }
}

/// The firmware update's part of a drive's state.
#[derive(Clone, Debug, Default)]
pub(crate) struct Updates {
    /// The image being received.
    pub(crate) transfer: Transfer,
    /// What images this platform takes, if any.
    pub(crate) target: Option<Target>,
    /// The running image's version.
    pub(crate) version: u32,
    /// What the boot loader's state says of it.
    pub(crate) boot: BootState,
}

impl<P: Borrow<Shared>, G: Borrow<ProgramMemory>> DriveState<P, G> {
    /// Whether the drive's writes are locked: a password is set and has not been given since
    /// power-up.
    pub fn locked(&self) -> bool {
        self.param(Obj::Password) != 0 && !self.unlocked
    }

    /// Says what images this platform takes (`None`: none, 0x15 is refused) and the version of
    /// the image running.
    pub fn set_updates(&mut self, target: Option<Target>, version: u32) {
        self.updates.target = target;
        self.updates.version = version;
    }

    /// Says what the boot loader's state says of the running image (0x2261): on trial until the
    /// platform confirms it.
    pub fn set_boot_state(&mut self, boot: BootState) {
        self.updates.boot = boot;
    }

    /// The image transfer, for the slave's 0x15 and the platform's flash jobs.
    pub fn transfer_mut(&mut self) -> (&mut Transfer, Option<&Target>) {
        (&mut self.updates.transfer, self.updates.target.as_ref())
    }

    /// The image transfer.
    pub fn transfer(&self) -> &Transfer {
        &self.updates.transfer
    }

    /// Whether the order `value` to `obj` is taken.
    pub(crate) fn check_update_order(&self, obj: Obj, value: u32) -> Result<(), ObjError> {
        let t = &self.updates.transfer;
        match (obj, value) {
            (Obj::UpdateControl, INSTALL) if self.updates.target.is_none() => Err(ObjError::Unsupported),
            // The restart stops the motor and the bus side: never while moving or saving.
            (Obj::UpdateControl, INSTALL) if !self.ctl.axis.is_still() || self.storage & STORAGE_SAVING != 0 => {
                Err(ObjError::Busy)
            }
            // An image that stopped short is taken here and fails when the order is carried out,
            // so that 0x2251 says why.
            (Obj::UpdateControl, INSTALL) => match t.can_install() {
                Ok(()) | Err(RecordError::Refused(_)) => Ok(()),
                Err(e) => Err(refusal(e)),
            },
            (Obj::UpdateControl, ABORT) if t.status().phase == Phase::Installing => Err(ObjError::Busy),
            (Obj::Unlock, 0) => Ok(()),
            (Obj::Unlock, v) if v == self.param(Obj::Password) => Ok(()),
            (Obj::Unlock, _) => Err(ObjError::OutOfRange),
            _ => Ok(()),
        }
    }

    /// Carries out the order `value` to `obj`: the lock's at once, the transfer's once the
    /// request has been taken whole ([`DriveState::settle_update`]).
    pub(crate) fn apply_update_order(&mut self, obj: Obj, value: u32) {
        self.set_param(obj, value);
        match obj {
            Obj::UpdateControl => self.update_order = value as u8,
            Obj::Unlock => self.unlocked = value != 0,
            // The master that sets a password knows it: unlocked until the next power-up.
            _ => self.unlocked = value != 0,
        }
    }

    /// Carries out the transfer's order of the request just taken, if any: an install of an
    /// image that stopped short fails it (0x2251 = 3) and is refused.
    #[inline(always)]
    pub fn settle_update(&mut self) -> Result<(), ObjError> {
        // Every write comes here; an order is rare, and out of line.
        if self.update_order == 0 { Ok(()) } else { self.carry_out_update_order() }
    }

    #[cold]
    #[inline(never)]
    fn carry_out_update_order(&mut self) -> Result<(), ObjError> {
        let order = core::mem::take(&mut self.update_order);
        let t = &mut self.updates.transfer;
        match u32::from(order) {
            ABORT => t.abort().map_err(refusal),
            INSTALL => t.install().map_err(refusal),
            _ => Ok(()),
        }
    }

    /// What the update's and the lock's read-only objects say.
    pub(crate) fn update_live(&self, obj: Obj) -> u32 {
        let s = self.updates.transfer.status();
        match obj {
            Obj::UpdateState => s.phase as u32,
            Obj::UpdateReason => s.reason as u32,
            Obj::UpdateReceived => s.received,
            Obj::UpdateLength => s.length,
            Obj::UpdateVersion => s.version,
            Obj::FirmwareVersion => self.updates.version,
            Obj::FirmwareKey => self.updates.target.map_or(2, |t| u32::from(t.test_key())),
            Obj::FirmwareState => self.updates.boot as u32,
            Obj::WriteLock if self.param(Obj::Password) == 0 => 0,
            Obj::WriteLock => 1 + u32::from(self.unlocked),
            _ => 0,
        }
    }
}
