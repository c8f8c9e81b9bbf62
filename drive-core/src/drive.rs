//! The drive: its state behind the object dictionary, and the RTU slave in front of it.

use crate::control::{Pp, has_effect, runs_on, settings_of};
use crate::controller::{Controller, Outputs, Pvt};
use crate::crc;
use crate::faults::{FaultHistory, HISTORY_OBJECTS};
use crate::faults::{FaultLog, Inputs};
use crate::ident::Identity;
use crate::motion::cubic::Table;
use crate::od::map::is_command;
use crate::od::{Access, NativeMap, OBJECTS, Obj, ObjError, ObjectDef, RegisterMap, Storage};
use crate::pdu::{Exception, MAX_READ, Request, Words};
use crate::rtu::{Framer, MAX_FRAME, RxError};
use crate::servo::Feedback;
use crate::units::{Baud, Instant, SlaveAddr};
use core::borrow::BorrowMut;

pub use crate::controller::{STATUS_BUSY, STATUS_STALL, Status};

/// Storage status (0x2120) bit 0: no saved parameters were found at power-up; factory values.
pub const STORAGE_EMPTY: u8 = 1 << 0;
/// Storage status bit 1: the saved parameters could not be read at power-up (corrupt store or a
/// record format this firmware does not know); factory values (a store the flash map cannot read
/// is erased, so that the next save works).
pub const STORAGE_CORRUPT: u8 = 1 << 1;
/// Storage status bit 2: FSET was held low at power-up; factory values restored and saved.
pub const STORAGE_FSET: u8 = 1 << 2;
/// Storage status bit 3: a save is in progress (read only: it clears when the save ends).
pub const STORAGE_SAVING: u8 = 1 << 3;
/// Storage status bit 4: the last save failed; the flash holds the set saved before it.
pub const STORAGE_SAVE_FAILED: u8 = 1 << 4;

/// What a platform gives a drive at power-up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DriveConfig {
    /// Overrides the node id object (0x2028) for this run.
    pub address: Option<SlaveAddr>,
    /// Overrides the baud rate object (0x202A) for this run.
    pub baud: Option<Baud>,
    /// The identification strings.
    pub identity: Identity,
    /// Whether the platform can save parameters (0x200F = 2); without it a save is refused (04).
    /// With it, the platform serves [`SystemRequest::Save`] (see [`crate::store::Store::serve`]).
    pub can_save: bool,
}

impl Default for DriveConfig {
    fn default() -> Self {
        Self { address: None, baud: None, identity: Identity::SIMULATOR, can_save: false }
    }
}

/// Requests the drive makes of its platform, collected with [`Drive::take_system_request`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SystemRequest {
    /// Save every ROM object (0x200F = 2).
    Save,
    /// Jump to the boot loader (0x200F = 1).
    BootLoader,
    /// Power is failing and 0x605E is on: save this position as 0x6055 before it is gone.
    SavePosition(i32),
    /// An alarm was recorded: save the fault history and the alarm count (0x213C..0x214F,
    /// 0x2136) as they are now, so that they survive a power cycle.
    SaveFaults,
}

/// The values of the saved objects: what a save writes and what power-up loads.
///
/// Only objects a save covers ([`Params::covers`]) can be set; the others stay at their factory
/// values and are ignored when a drive is built from a set, but for those with records of their
/// own: the power-down position 0x6055 and the fault history with the alarm count.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Params {
    values: [u32; Obj::COUNT],
}

impl Params {
    /// Every object at its factory value.
    pub fn factory() -> Self {
        let mut values = [0; Obj::COUNT];
        for (v, d) in values.iter_mut().zip(OBJECTS.iter()) {
            *v = d.default;
        }
        Self { values }
    }

    /// Whether a save (0x200F = 2) covers the object `d` declares: the ROM objects a master can
    /// write. 0x6055 (ROM, read only) has its own record, written at power loss.
    pub fn covers(d: &ObjectDef) -> bool {
        d.storage == Storage::Rom && d.access == Access::Rw
    }

    /// Copies the values of the objects a save covers into `values` (indexed by object), and
    /// leaves the others.
    fn copy_saved_into(&self, values: &mut [u32; Obj::COUNT]) {
        for ((v, p), d) in values.iter_mut().zip(self.values.iter()).zip(OBJECTS.iter()) {
            if Self::covers(d) {
                *v = *p;
            }
        }
    }

    /// The value of `obj`.
    pub fn get(&self, obj: Obj) -> u32 {
        self.values.get(obj as usize).copied().unwrap_or(0)
    }

    /// Sets `obj` to `value` if a save covers it and its range accepts the value; whether it did.
    pub fn set(&mut self, obj: Obj, value: u32) -> bool {
        let d = obj.def();
        let ok = Self::covers(d) && d.range.accepts(d.ty, value);
        if ok && let Some(v) = self.values.get_mut(obj as usize) {
            *v = value;
        }
        ok
    }

    /// Sets the position saved at the last power loss (0x6055), which has its own record.
    pub fn set_saved_position(&mut self, position: i32) {
        if let Some(v) = self.values.get_mut(Obj::SavedPosition as usize) {
            *v = position as u32;
        }
    }

    /// The fault history and alarm count loaded at power-up (their own record).
    pub fn fault_history(&self) -> FaultHistory {
        let mut history = FaultHistory { count: self.get(Obj::AlarmCount) as u16, ..FaultHistory::default() };
        for (e, obj) in history.entries.iter_mut().zip(HISTORY_OBJECTS) {
            *e = self.get(obj);
        }
        history
    }

    /// Sets the fault history and alarm count, which have their own record.
    pub fn set_fault_history(&mut self, history: &FaultHistory) {
        let pairs = history.entries.iter().zip(HISTORY_OBJECTS).map(|(&e, obj)| (obj, e));
        for (obj, value) in pairs.chain([(Obj::AlarmCount, u32::from(history.count))]) {
            if let Some(v) = self.values.get_mut(obj as usize) {
                *v = value;
            }
        }
    }
}

impl Default for Params {
    fn default() -> Self {
        Self::factory()
    }
}

/// Everything the object dictionary reads and writes.
///
/// `P` holds the PVT point table (10 KB): the state owns it by default; a microcontroller keeps
/// it in a static of its own and lends it (`&'static mut Table`), so that building the state
/// never passes 10 KB through its stack.
#[derive(Clone, Debug)]
pub struct DriveState<P = Table> {
    pub(crate) params: [u32; Obj::COUNT],
    /// Storage status bits (0x2120): `STORAGE_*`.
    storage: u8,
    identity: Identity,
    can_save: bool,
    request: Option<SystemRequest>,
    /// The time of the event being handled (a frame, a tick): when a command takes effect.
    pub(crate) now: Instant,
    /// The profile position and velocity modes' set-points.
    pub(crate) pp: Pp,
    /// Which slots of `table` hold PVT points.
    pub(crate) pvt: Pvt,
    /// The PVT points (10 KB: kept out of [`Checkpoint`]).
    pub(crate) table: P,
    /// What the control tick owns: the motion, supervision, the loops and the running status.
    pub(crate) ctl: Controller,
    /// The alarm count when the platform was last asked to save the history (changed only by
    /// taking requests, so kept out of [`Checkpoint`] too).
    faults_saved: u16,
}

/// Everything of a [`DriveState`] but the PVT point table: what a multi-object write restores
/// when a later object of it is refused. (A table slot written by such a write lies beyond the
/// restored count of points, so it is not a point.)
#[derive(Clone, Debug)]
pub struct Checkpoint {
    params: [u32; Obj::COUNT],
    storage: u8,
    status: Status,
    request: Option<SystemRequest>,
    now: Instant,
    axis: crate::motion::axis::Axis,
    pp: Pp,
    pvt: Pvt,
    run: Option<crate::controller::run::Run>,
}

impl DriveState {
    /// Factory state.
    pub fn new(identity: Identity, can_save: bool) -> Self {
        Self::booted(identity, can_save, Params::factory().values, 0, FaultLog::default(), Table::EMPTY)
    }
}

impl<P: BorrowMut<Table>> DriveState<P> {
    /// The state at power-up with the object values `params`, the storage status `storage` and
    /// the fault history `faults` (as saved: not to be saved again).
    ///
    /// One struct expression, out of line: built in a local and then modified, the state would
    /// be copied once more. (The compiler still builds it in a temporary and copies it to the
    /// caller's place, which is why a microcontroller lends the 10 KB table: see
    /// [`Drive::boot_with_table`].)
    #[inline(never)]
    fn booted(
        identity: Identity,
        can_save: bool,
        params: [u32; Obj::COUNT],
        storage: u8,
        faults: FaultLog,
        table: P,
    ) -> Self {
        let get = |obj: Obj| params.get(obj as usize).copied().unwrap_or(0);
        let feedback = Feedback::from_objects(get(Obj::Feedback), get(Obj::EncoderCpr));
        Self {
            faults_saved: faults.count,
            ctl: Controller::new(settings_of(&params), feedback, faults),
            params,
            storage,
            identity,
            can_save,
            request: None,
            now: Instant::from_micros(0),
            pp: Pp::default(),
            pvt: Pvt::default(),
            table,
        }
    }

    /// Everything but the PVT table, to [`DriveState::restore`] later.
    pub fn checkpoint(&self) -> Checkpoint {
        // Naming every field: a new one must be decided on here.
        let Self { params, storage, identity: _, can_save: _, request, now, pp, pvt, table: _, ctl, faults_saved: _ } =
            self;
        Checkpoint {
            params: *params,
            storage: *storage,
            status: ctl.status,
            request: *request,
            now: *now,
            axis: ctl.axis,
            pp: *pp,
            pvt: *pvt,
            run: ctl.run,
        }
    }

    /// Writes values in order, all or nothing, as every map's multi-object write does: `value`
    /// turns each item into its object and value, reading the drive as the writes before it left
    /// it, or into nothing to write; at the first refusal the drive goes back to how it was
    /// before the first write, and the refusal is returned. Out of line: the checkpoint
    /// (everything but the PVT table) is on the stack only here.
    #[inline(never)]
    pub fn write_in_order<T>(
        &mut self,
        items: impl IntoIterator<Item = T>,
        mut value: impl FnMut(&Self, T) -> Result<Option<(&'static ObjectDef, u32)>, ObjError>,
    ) -> Result<(), ObjError> {
        let saved = self.checkpoint();
        for item in items {
            let written = value(self, item).and_then(|w| w.map_or(Ok(()), |(d, v)| self.write_def(d, v)));
            if let Err(e) = written {
                self.restore(saved);
                return Err(e);
            }
        }
        Ok(())
    }

    /// Goes back to `c`.
    pub fn restore(&mut self, c: Checkpoint) {
        let Checkpoint { params, storage, status, request, now, axis, pp, pvt, run } = c;
        (self.params, self.storage, self.request, self.now) = (params, storage, request, now);
        (self.ctl.status, self.ctl.axis, self.ctl.run, self.pp, self.pvt) = (status, axis, run, pp, pvt);
        self.refresh_settings();
    }

    /// The running status.
    pub fn status(&self) -> &Status {
        &self.ctl.status
    }

    /// The running status, for the platform's inputs (GPIO levels, the analog input).
    pub fn status_mut(&mut self) -> &mut Status {
        &mut self.ctl.status
    }

    /// What the power stage does ([`Controller::power_state`]).
    pub fn power_state(&self) -> crate::modes::PowerState {
        self.ctl.power_state()
    }

    /// Whether a fault is latched ([`Controller::faulted`]).
    pub fn faulted(&self) -> bool {
        self.ctl.faulted()
    }

    /// The sensorless stall detector's estimates ([`Controller::stall_estimate`]).
    pub fn stall_estimate(&self) -> (f32, f32) {
        self.ctl.stall_estimate()
    }

    /// What the control tick owns.
    pub fn controller(&self) -> &Controller {
        &self.ctl
    }

    /// Builds the controller's settings again from the objects.
    #[inline(never)]
    pub(crate) fn refresh_settings(&mut self) {
        self.ctl.settings = settings_of(&self.params);
    }

    /// The storage status bits (0x2120): `STORAGE_*`.
    pub fn storage(&self) -> u8 {
        self.storage
    }

    /// The position setpoint in whole microsteps (it never wraps; 0x600E..F shows its low 32 bits).
    pub fn position(&self) -> i64 {
        self.ctl.axis.setpoint().whole
    }

    /// Declares the present position, as writing 0x600E..F does; refused while moving.
    pub fn set_position(&mut self, position: i64) -> bool {
        self.ctl.axis.set_position(position)
    }

    /// The present values of the objects a save covers: what 0x200F = 2 writes.
    pub fn params(&self) -> Params {
        let mut p = Params::factory();
        for (v, (now, d)) in p.values.iter_mut().zip(self.params.iter().zip(OBJECTS.iter())) {
            if Params::covers(d) {
                *v = *now;
            }
        }
        p
    }

    /// Power is failing: if the power-down save is on (0x605E = 1), asks the platform to save the
    /// position ([`SystemRequest::SavePosition`]), replacing any request still pending (a
    /// parameter save could not finish on the remaining charge anyway). The power-loss detector
    /// calls this once; whether it asked is returned.
    pub fn power_lost(&mut self) -> bool {
        let on = self.read(Obj::AutoSave) == 1;
        if on {
            self.request = Some(SystemRequest::SavePosition(self.position() as i32));
        }
        on
    }

    /// Whether an alarm was recorded since the history was last handed to a platform that saves.
    fn fault_save_due(&self) -> bool {
        self.can_save && self.ctl.faults.count != self.faults_saved
    }

    /// [`SystemRequest::SaveFaults`] if [due](DriveState::fault_save_due); the history counts as
    /// saved from here on (if the save fails, the next alarm saves the whole history again).
    fn take_fault_save(&mut self) -> Option<SystemRequest> {
        let due = self.fault_save_due();
        self.faults_saved = self.ctl.faults.count;
        due.then_some(SystemRequest::SaveFaults)
    }

    /// Whether a request for the platform is waiting ([`Drive::take_system_request`]).
    fn has_request(&self) -> bool {
        self.request.is_some() || self.fault_save_due()
    }

    /// The fault history and alarm count as the objects show them now.
    pub fn fault_history(&self) -> FaultHistory {
        let mut history = FaultHistory { count: self.ctl.faults.count, ..FaultHistory::default() };
        for (k, e) in history.entries.iter_mut().enumerate() {
            *e = self.ctl.history(k);
        }
        history
    }

    /// The identification strings.
    pub fn identity(&self) -> &Identity {
        &self.identity
    }

    /// The value of `obj` as its registers show it (S32 as two's complement).
    pub fn read(&self, obj: Obj) -> u32 {
        self.read_def(obj.def())
    }

    /// The value of the object `d` declares: from the running status for live objects, else stored.
    #[inline]
    pub fn read_def(&self, d: &ObjectDef) -> u32 {
        if d.storage == Storage::Live {
            self.live(d.obj)
        } else {
            self.params.get(d.obj as usize).copied().unwrap_or(0)
        }
    }

    fn live(&self, obj: Obj) -> u32 {
        let s = &self.ctl.status;
        match obj {
            // The axis's own state, not a copy: the register shows the low 32 bits of the setpoint.
            Obj::Position => self.ctl.axis.setpoint().whole as u32,
            Obj::ErrorStatus => u32::from(s.error),
            Obj::ControllerStatus => {
                u32::from(s.controller | self.fifo_status() | if self.ctl.axis.is_still() { 0 } else { STATUS_BUSY })
            }
            Obj::PvtCount => u32::from(self.pvt.count()),
            Obj::PvtFault => u32::from(self.pvt.fault),
            Obj::NotifyStatus => u32::from(s.notify),
            Obj::GpioValue => u32::from(s.gpio),
            Obj::AnalogIn => u32::from(s.analog_in),
            Obj::StatusWord => u32::from(self.statusword()),
            Obj::PvtPointer => u32::from(s.pvt_pointer),
            Obj::RealSpeed => self.ctl.real_speed() as u32,
            Obj::FollowingError => self.ctl.servo.following as i32 as u32,
            Obj::EncoderPosition => s.encoder as u32,
            Obj::StorageStatus => u32::from(self.storage),
            Obj::AlarmCode => u32::from(self.ctl.alarm_code()),
            Obj::DriveFaults => u32::from(s.faults),
            Obj::CommStatus => u32::from(s.comm),
            Obj::AlarmCount => u32::from(self.ctl.faults.count),
            Obj::FaultHistory0 => self.ctl.history(0),
            Obj::FaultHistory1 => self.ctl.history(1),
            Obj::FaultHistory2 => self.ctl.history(2),
            Obj::FaultHistory3 => self.ctl.history(3),
            Obj::FaultHistory4 => self.ctl.history(4),
            Obj::FaultHistory5 => self.ctl.history(5),
            Obj::FaultHistory6 => self.ctl.history(6),
            Obj::FaultHistory7 => self.ctl.history(7),
            Obj::FaultHistory8 => self.ctl.history(8),
            Obj::FaultHistory9 => self.ctl.history(9),
            _ => self.params.get(obj as usize).copied().unwrap_or(0),
        }
    }

    /// `obj` read as a signed value.
    pub fn read_i32(&self, obj: Obj) -> i32 {
        self.read(obj) as i32
    }

    /// Word `k` of a text object: two ASCII bytes, first one high, zero padded.
    pub fn text_word(&self, obj: Obj, k: usize) -> u16 {
        let text = match obj {
            Obj::DeviceName => self.identity.device_name,
            Obj::HardwareVersion => self.identity.hardware_version,
            Obj::SoftwareVersion => self.identity.software_version,
            _ => "",
        }
        .as_bytes();
        let byte = |i: usize| text.get(i).copied().unwrap_or(0);
        u16::from_be_bytes([byte(2 * k), byte(2 * k + 1)])
    }

    /// Whether writing `value` to `obj` would be accepted; nothing changes.
    pub fn check(&self, obj: Obj, value: u32) -> Result<(), ObjError> {
        self.check_def(obj.def(), value)
    }

    /// Whether `d` is a plain setting: [`DriveState::check_def`] accepts any value in its range
    /// whatever the drive's state, and [`DriveState::apply_def`] stores it. The write path checks
    /// these against a precomputed interval (`od::map`): an object with a check beyond its range
    /// must not be plain (a test compares the two).
    pub(crate) const fn plain(d: &ObjectDef) -> bool {
        matches!(d.access, Access::Rw)
            && matches!(d.storage, Storage::Ram | Storage::Rom)
            && !has_effect(d.obj)
            && !runs_on(d.obj)
            && !matches!(d.obj, Obj::SystemControl)
    }

    /// Whether the object `d` declares takes writes, and `value` is within its range.
    fn check_writable(d: &ObjectDef, value: u32) -> Result<(), ObjError> {
        if d.access == Access::Ro || d.storage == Storage::Const {
            return Err(ObjError::ReadOnly);
        }
        if !d.range.accepts(d.ty, value) {
            return Err(ObjError::OutOfRange);
        }
        Ok(())
    }

    /// [`DriveState::check`] for the object `d` declares.
    #[inline(always)]
    pub fn check_def(&self, d: &ObjectDef, value: u32) -> Result<(), ObjError> {
        Self::check_writable(d, value)?;
        match (d.obj, value) {
            // No boot loader to jump to yet (see 0x200F's documentation).
            (Obj::SystemControl, 1) => Err(ObjError::Unsupported),
            (Obj::SystemControl, 2) if !self.can_save => Err(ObjError::Unsupported),
            // A flash erase stalls the STM32G431's single bank for ~22 ms: never while moving. A
            // second save waits for the first to end.
            (Obj::SystemControl, 2 | 3) if !self.ctl.axis.is_still() || self.storage & STORAGE_SAVING != 0 => {
                Err(ObjError::Busy)
            }
            (obj, _) if is_command(obj) => self.check_motion(obj, value),
            _ => Ok(()),
        }
    }

    /// [`DriveState::check_def`], then [`DriveState::apply_def`] if accepted; nothing changes if
    /// refused. A motion command is planned once: checking it plans the motion (a plan proves a
    /// move possible), and so does applying it, and a plan costs a Cortex-M4 hundreds of
    /// thousands of instructions, during which the control tick waits for the bus task.
    pub fn write_def(&mut self, d: &ObjectDef, value: u32) -> Result<(), ObjError> {
        // The objects whose check is `check_motion` and whose write is `apply_motion`.
        if is_command(d.obj) && has_effect(d.obj) && !crate::pvt::is_pvt_command(d.obj) && d.obj != Obj::Position {
            Self::check_writable(d, value)?;
            let mut planned = (self.ctl.axis, self.pp);
            let changed = self.plan_motion(d.obj, value, &mut planned)?;
            self.commit_motion(d.obj, value, changed.then_some(&planned));
            return Ok(());
        }
        self.check_def(d, value)?;
        self.apply_def(d, value);
        Ok(())
    }

    /// Writes `value` to the object `d` declares, which [`DriveState::check`] accepted.
    #[inline(always)]
    pub fn apply_def(&mut self, d: &ObjectDef, value: u32) {
        if d.access == Access::Rw && d.storage != Storage::Live && !is_command(d.obj) {
            // A setting: stored, and handed to the controller if it runs it.
            if let Some(p) = self.params.get_mut(d.obj as usize) {
                *p = value;
            }
            if runs_on(d.obj) {
                self.refresh_settings();
            }
        } else {
            self.apply(d.obj, value);
        }
    }

    /// Writes `value` to `obj`, which [`DriveState::check`] accepted.
    pub fn apply(&mut self, obj: Obj, value: u32) {
        let s = &mut self.ctl.status;
        match obj {
            Obj::ErrorStatus => s.error &= !(value as u8),
            Obj::ControllerStatus => s.controller &= !(value as u8 & !STATUS_BUSY),
            Obj::NotifyStatus => s.notify &= !(value as u8),
            Obj::StorageStatus => self.storage &= !(value as u8 & !STORAGE_SAVING),
            Obj::DriveFaults => s.faults &= !(value as u8),
            Obj::CommStatus => s.comm &= !(value as u8),
            Obj::PvtFault => self.pvt.fault &= !(value as u8),
            Obj::GpioValue => {
                // Only outputs take the written level.
                let outputs = self.params.get(Obj::GpioDirection as usize).copied().unwrap_or(0) as u16;
                s.gpio = (s.gpio & !outputs) | (value as u16 & outputs);
            }
            Obj::Position => {
                let position = i64::from(value as i32);
                if self.ctl.axis.set_position(position) && self.ctl.servo.feedback.encoder().is_some() {
                    // Closed loop: the position is the encoder's plus the zero offset.
                    self.set_param(Obj::ZeroOffset, position.wrapping_sub(self.ctl.servo.encoder) as u32);
                }
            }
            obj if has_effect(obj) => self.apply_motion(obj, value),
            _ => {
                self.set_param(obj, value);
                if obj == Obj::SystemControl {
                    if value == 3 {
                        self.restore_factory();
                    }
                    // Factory settings are saved too, so that they survive a restart as §3.11's
                    // FSET reset does; without storage they hold until power-off.
                    if (value == 2 || value == 3) && self.can_save {
                        self.storage = (self.storage & !STORAGE_SAVE_FAILED) | STORAGE_SAVING;
                        self.request = Some(SystemRequest::Save);
                    }
                }
            }
        }
    }

    /// Puts every object a save covers back to its factory value (RAM objects, 0x6055 and the
    /// status are untouched).
    pub fn restore_factory(&mut self) {
        Params::factory().copy_saved_into(&mut self.params);
        self.refresh_settings();
    }

    /// The platform finished the save it was asked for ([`SystemRequest::Save`]); `ok` if the
    /// flash holds the new set.
    pub fn save_done(&mut self, ok: bool) {
        let s = &mut self.storage;
        *s &= !STORAGE_SAVING;
        if !ok {
            *s |= STORAGE_SAVE_FAILED;
        }
    }
}

/// The Modbus serial-line diagnostic counters (function 0x08, sub-functions 0x0B-0x12).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// 0x0B: frames with a good CRC seen on the bus, for any address.
    pub bus_messages: u16,
    /// 0x0C: frames dropped for a bad CRC, a gap inside the frame, or too short to hold a function
    /// code and a CRC.
    pub bus_errors: u16,
    /// 0x0D: exception replies sent.
    pub exceptions: u16,
    /// 0x0E: frames addressed to this drive or broadcast.
    pub slave_messages: u16,
    /// 0x0F: frames addressed to this drive or broadcast that were not answered.
    pub no_responses: u16,
    /// 0x10: negative acknowledges (never sent by this drive).
    pub naks: u16,
    /// 0x11: busy replies (never sent by this drive).
    pub busy: u16,
    /// 0x12: frames lost to a receive overrun (longer than 256 bytes).
    pub overruns: u16,
}

/// A drive on a serial line: the RTU slave and the drive state behind it.
#[derive(Clone, Debug)]
pub struct Drive<M: RegisterMap = NativeMap, P = Table> {
    framer: Framer,
    address: SlaveAddr,
    baud: Baud,
    listen_only: bool,
    counters: Counters,
    tx: [u8; MAX_FRAME],
    tx_len: usize,
    map: M,
    state: DriveState<P>,
}

impl Drive<NativeMap> {
    /// A drive with factory settings and the native map.
    pub fn factory() -> Self {
        Self::new(DriveConfig::default())
    }

    /// A drive with the native map.
    pub fn new(config: DriveConfig) -> Self {
        Self::with_map(config, NativeMap::new())
    }

    /// A drive with the native map that starts from the saved `params` (loaded from the store
    /// before the drive answers anything) and the storage status bits `storage` (`STORAGE_*`).
    pub fn boot(config: DriveConfig, params: &Params, storage: u8) -> Self {
        Self::boot_with_map(config, NativeMap::new(), params, storage)
    }
}

impl<M: RegisterMap> Drive<M> {
    /// A drive whose registers are laid out by `map`.
    pub fn with_map(config: DriveConfig, map: M) -> Self {
        Self::boot_with_map(config, map, &Params::factory(), 0)
    }

    /// [`Drive::boot`] with the registers laid out by `map`. The node id and baud rate in force
    /// are those of `params` unless `config` overrides them (and the override is what the objects
    /// then show, and what a save stores).
    pub fn boot_with_map(config: DriveConfig, map: M, params: &Params, storage: u8) -> Self {
        Self::boot_with_table(config, map, params, storage, Table::EMPTY)
    }
}

impl<M: RegisterMap, P: BorrowMut<Table>> Drive<M, P> {
    /// [`Drive::boot_with_map`] with the PVT point table `table` (its points are not read: the
    /// table starts empty). A microcontroller passes a `&'static mut Table` from a static of
    /// its own, so the drive it builds is about 3 KB instead of 13 KB:
    ///
    /// ```
    /// use drive_core::{Drive, DriveConfig, Params};
    /// use drive_core::motion::cubic::Table;
    /// use drive_core::od::map::NativeMap;
    /// let mut table = Table::EMPTY;
    /// let d = Drive::boot_with_table(DriveConfig::default(), NativeMap::new(), &Params::factory(), 0, &mut table);
    /// assert!(core::mem::size_of_val(&d) < 4 * 1024);
    /// ```
    #[inline(never)]
    pub fn boot_with_table(config: DriveConfig, map: M, params: &Params, storage: u8, table: P) -> Self {
        // The values are settled first and the drive is one struct expression (as the state is,
        // `DriveState::booted`), so that the drive is not built aside and copied once more.
        let mut values = Params::factory().values;
        params.copy_saved_into(&mut values);
        let mut set = |obj: Obj, value: u32| {
            if let Some(v) = values.get_mut(obj as usize) {
                *v = value;
            }
        };
        // The power-down position is not in the saved set proper (it has its own record).
        set(Obj::SavedPosition, params.get(Obj::SavedPosition));
        if let Some(a) = config.address {
            set(Obj::NodeId, u32::from(a.get()));
        }
        if let Some(b) = config.baud {
            set(Obj::BaudRate, b.get());
        }
        let get = |obj: Obj| values.get(obj as usize).copied().unwrap_or(0);
        let faults = FaultLog::restored(&params.fault_history());
        // The serial settings in force are those of power-up; writes take effect at the next one.
        let address = SlaveAddr::new(get(Obj::NodeId) as u8).unwrap_or(SlaveAddr::BROADCAST);
        let baud = Baud::new(get(Obj::BaudRate)).unwrap_or(Baud::FACTORY);
        Self {
            framer: Framer::new(baud),
            address,
            baud,
            listen_only: false,
            counters: Counters::default(),
            tx: [0; MAX_FRAME],
            tx_len: 0,
            map,
            state: DriveState::booted(
                config.identity,
                config.can_save,
                values,
                storage & !STORAGE_SAVING,
                faults,
                table,
            ),
        }
    }

    /// The address this drive answers to.
    pub fn address(&self) -> SlaveAddr {
        self.address
    }

    /// The baud rate the framing is timed for.
    pub fn baud(&self) -> Baud {
        self.baud
    }

    /// The drive state behind the registers.
    pub fn state(&self) -> &DriveState<P> {
        &self.state
    }

    /// The drive state, for the platform (inputs, motion).
    pub fn state_mut(&mut self) -> &mut DriveState<P> {
        &mut self.state
    }

    /// The diagnostic counters.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// Bytes received at `now`. A frame that had already ended is processed first.
    pub fn on_rx(&mut self, now: Instant, bytes: &[u8]) {
        if bytes.is_empty() {
            return;
        }
        self.state.now = now;
        // The bytes of one call arrived together: only the first can follow a silence.
        if self.framer.ended(now) {
            self.end_frame();
        }
        self.framer.extend(now, bytes);
    }

    /// Time passes: a frame whose t3.5 has run out is processed.
    pub fn on_timer(&mut self, now: Instant) {
        self.state.now = now;
        if self.framer.ended(now) {
            self.end_frame();
        }
    }

    /// One control tick at `now` (every [`TICK_MICROS`](crate::control::TICK_MICROS)): runs the
    /// motion and says what the output stage does.
    pub fn tick(&mut self, now: Instant) -> Outputs {
        self.state.tick(now)
    }

    /// [`Drive::tick`] with what the drive measures: faults and protections are checked against it.
    pub fn tick_with(&mut self, now: Instant, inputs: &Inputs) -> Outputs {
        self.state.tick_with(now, inputs)
    }

    /// When [`Drive::on_timer`] next has something to do.
    pub fn deadline(&self) -> Option<Instant> {
        self.framer.deadline()
    }

    /// The reply frame to send, once.
    pub fn take_reply(&mut self) -> Option<&[u8]> {
        let n = core::mem::take(&mut self.tx_len);
        if n == 0 { None } else { self.tx.get(..n) }
    }

    /// A request the drive makes of its platform (save, boot loader, power-down position, fault
    /// history), once. A fault history save comes after any other request (a power-down position
    /// first, while the charge lasts).
    ///
    /// On [`SystemRequest::Save`] the platform takes [`DriveState::params`] at once, writes them
    /// outside the control tick, and reports with [`Drive::save_done`]; on
    /// [`SystemRequest::SaveFaults`] it takes [`DriveState::fault_history`] at once.
    pub fn take_system_request(&mut self) -> Option<SystemRequest> {
        self.state.request.take().or_else(|| self.state.take_fault_save())
    }

    /// Whether [`Drive::take_system_request`] has something: a platform that must prepare for a
    /// flash operation (finish sending a reply) asks this first.
    pub fn has_system_request(&self) -> bool {
        self.state.has_request()
    }

    /// The save the drive asked for has ended; `ok` if the flash holds the new set (else the
    /// storage status shows [`STORAGE_SAVE_FAILED`]).
    pub fn save_done(&mut self, ok: bool) {
        self.state.save_done(ok);
    }

    fn end_frame(&mut self) {
        let (_, error) = self.framer.frame();
        let c = &mut self.counters;
        match error {
            Some(RxError::Overrun) => c.overruns = c.overruns.wrapping_add(1),
            Some(RxError::Gap) => c.bus_errors = c.bus_errors.wrapping_add(1),
            None if !self.framer.crc_ok() => c.bus_errors = c.bus_errors.wrapping_add(1),
            None => self.serve(),
        }
        self.framer.clear();
    }

    /// Serves a frame with a good CRC that sits in the framer.
    fn serve(&mut self) {
        let Self { framer, address, listen_only, counters, tx, tx_len, map, state, .. } = self;
        counters.bus_messages = counters.bus_messages.wrapping_add(1);
        let (frame, _) = framer.frame();
        let Some((&to, rest)) = frame.split_first() else {
            return;
        };
        let broadcast = to == SlaveAddr::BROADCAST.get();
        if !broadcast && to != address.get() {
            return;
        }
        counters.slave_messages = counters.slave_messages.wrapping_add(1);
        state.ctl.heard(state.now);
        let pdu = rest.get(..rest.len().saturating_sub(2)).unwrap_or_default();
        let function = pdu.first().copied().unwrap_or(0);
        if function & 0x80 != 0 {
            // Codes 0x80-0xFF are exception replies, never requests: there is no way to answer.
            counters.no_responses = counters.no_responses.wrapping_add(1);
            return;
        }
        let request = Request::parse(pdu);
        let mut server = Server { map, state, counters, listen_only };
        if broadcast || *server.listen_only {
            // Execute what may execute without an answer, and answer nothing.
            if let Ok(req) = request
                && server.silent_allowed(&req)
            {
                let mut scratch = [0u8; MAX_FRAME];
                let _ = server.execute(&req, &mut scratch);
            }
            counters.no_responses = counters.no_responses.wrapping_add(1);
            return;
        }
        let Some((head, body)) = tx.split_first_chunk_mut::<2>() else {
            return;
        };
        let body = body.get_mut(..MAX_FRAME - 4).unwrap_or_default();
        let len = match request.and_then(|req| server.execute(&req, body)) {
            Ok(Outcome::Reply(n)) => {
                *head = [address.get(), function];
                n
            }
            Ok(Outcome::Silent) => {
                counters.no_responses = counters.no_responses.wrapping_add(1);
                return;
            }
            Err(e) => {
                counters.exceptions = counters.exceptions.wrapping_add(1);
                *head = [address.get(), function | 0x80];
                if let Some(b) = body.first_mut() {
                    *b = e.code();
                }
                1
            }
        };
        *tx_len = seal(tx, 2 + len);
    }
}

/// Appends the CRC to the first `n` bytes of `buf`; the frame's length, or 0 if it does not fit.
#[inline(always)]
fn seal(buf: &mut [u8], n: usize) -> usize {
    let sum = crc::crc16(buf.get(..n).unwrap_or_default());
    match buf.get_mut(n..n + 2) {
        Some(c) => {
            c.copy_from_slice(&sum.to_le_bytes());
            n + 2
        }
        None => 0,
    }
}

/// What a request produced.
enum Outcome {
    /// A normal reply with this many bytes after the function code.
    Reply(usize),
    /// No reply (force listen-only mode, restart from listen-only mode).
    Silent,
}

/// The parts of a drive that execute a request.
struct Server<'a, M, P> {
    map: &'a mut M,
    state: &'a mut DriveState<P>,
    counters: &'a mut Counters,
    listen_only: &'a mut bool,
}

/// Conformity level of device identification: regular, stream and individual access.
const CONFORMITY: u8 = 0x82;

impl<M: RegisterMap, P: BorrowMut<Table>> Server<'_, M, P> {
    /// Whether a request executes when it gets no answer (broadcast, listen-only mode).
    fn silent_allowed(&self, req: &Request<'_>) -> bool {
        match *req {
            Request::Diagnostics { sub: 0x01, .. } => true,
            _ if *self.listen_only => false,
            Request::WriteSingle { .. } | Request::WriteMultiple { .. } => true,
            Request::Diagnostics { sub, .. } => matches!(sub, 0x04 | 0x0A),
            _ => false,
        }
    }

    /// Executes `req`, writing the reply's data (after the function code) into `out`.
    // Inlined into the request path: a call here costs more than a short request's work.
    #[inline(always)]
    fn execute(&mut self, req: &Request<'_>, out: &mut [u8]) -> Result<Outcome, Exception> {
        match *req {
            Request::ReadHolding { addr, qty } | Request::ReadInput { addr, qty } => self.read(addr, qty, out),
            Request::WriteSingle { addr, value } => {
                let bytes = value.to_be_bytes();
                self.map.write(self.state, addr, Words::new(&bytes))?;
                put(out, 0, &addr.to_be_bytes());
                put(out, 2, &bytes);
                Ok(Outcome::Reply(4))
            }
            Request::WriteMultiple { addr, values } => {
                self.map.write(self.state, addr, values)?;
                put(out, 0, &addr.to_be_bytes());
                put(out, 2, &(values.len() as u16).to_be_bytes());
                Ok(Outcome::Reply(4))
            }
            Request::ReadWrite { read_addr, read_qty, write_addr, values } => {
                self.map.check_read(read_addr, read_qty)?;
                self.map.write(self.state, write_addr, values)?;
                self.read(read_addr, read_qty, out)
            }
            Request::Diagnostics { sub, data } => self.diagnostics(sub, data, out),
            Request::ReadDeviceId { code, object } => device_id(self.state.identity(), code, object, out),
        }
    }

    #[inline(always)]
    fn read(&mut self, addr: u16, qty: u16, out: &mut [u8]) -> Result<Outcome, Exception> {
        let n = 2 * usize::from(qty.min(MAX_READ));
        let (count, data) = out.split_first_mut().ok_or(Exception::ServerDeviceFailure)?;
        *count = n as u8;
        self.map.read(self.state, addr, data.get_mut(..n).ok_or(Exception::ServerDeviceFailure)?)?;
        Ok(Outcome::Reply(1 + n))
    }

    fn diagnostics(&mut self, sub: u16, data: &[u8], out: &mut [u8]) -> Result<Outcome, Exception> {
        let zero = data == [0, 0];
        let c = &mut *self.counters;
        let value = match sub {
            0x00 => {
                put(out, 0, &sub.to_be_bytes());
                put(out, 2, data);
                return Ok(Outcome::Reply(2 + data.len()));
            }
            0x01 => {
                if !(zero || data == [0xFF, 0x00]) {
                    return Err(Exception::IllegalDataValue);
                }
                let was_listening = core::mem::take(self.listen_only);
                *c = Counters::default();
                if was_listening {
                    return Ok(Outcome::Silent);
                }
                u16::from_be_bytes([data.first().copied().unwrap_or(0), 0])
            }
            0x02..=0x12 if !zero => return Err(Exception::IllegalDataValue),
            0x02 => 0,
            0x04 => {
                *self.listen_only = true;
                return Ok(Outcome::Silent);
            }
            0x0A => {
                *c = Counters::default();
                0
            }
            0x0B => c.bus_messages,
            0x0C => c.bus_errors,
            0x0D => c.exceptions,
            0x0E => c.slave_messages,
            0x0F => c.no_responses,
            0x10 => c.naks,
            0x11 => c.busy,
            0x12 => c.overruns,
            _ => return Err(Exception::IllegalFunction),
        };
        put(out, 0, &sub.to_be_bytes());
        put(out, 2, &value.to_be_bytes());
        Ok(Outcome::Reply(4))
    }
}

/// Copies `bytes` into `out` at `at`, as far as it fits.
#[inline(always)]
fn put(out: &mut [u8], at: usize, bytes: &[u8]) {
    if let Some(dst) = out.get_mut(at..at + bytes.len()) {
        dst.copy_from_slice(bytes);
    }
}

/// Read device identification (0x2B / 0x0E): `[0x0E, code, conformity, more, next, count, objects..]`.
fn device_id(id: &Identity, code: u8, object: u8, out: &mut [u8]) -> Result<Outcome, Exception> {
    let last = match code {
        1 => 2,
        2 | 3 => 6,
        4 => {
            id.object(object).ok_or(Exception::IllegalDataAddress)?;
            object
        }
        _ => return Err(Exception::IllegalDataValue),
    };
    // Stream access restarts at 0 when asked for an object outside the category.
    let first = if code == 4 || object <= last { object } else { 0 };
    put(out, 0, &[0x0E, code, CONFORMITY, 0, 0, 0]);
    let mut n = 6;
    let mut count = 0u8;
    for oid in first..=last {
        let text = id.object(oid).unwrap_or("").as_bytes();
        let text = text.get(..text.len().min(240)).unwrap_or_default();
        if n + 2 + text.len() > out.len() {
            // Does not fit: tell the master where to continue.
            put(out, 3, &[0xFF, oid]);
            break;
        }
        put(out, n, &[oid, text.len() as u8]);
        put(out, n + 2, text);
        n += 2 + text.len();
        count += 1;
    }
    put(out, 5, &[count]);
    Ok(Outcome::Reply(n))
}
