//! The drive's state behind the object dictionary: the objects' values, the profile set-points,
//! the PVT points, the multi-segment programs, and the controller the control tick runs (see
//! [`crate::controller`]). What a write to an object does is here and in [`control`] (the motion
//! modes) and [`pvt`].

pub mod analog;
mod command;
pub mod control;
mod device;
pub mod groups;
pub mod homing;
mod inputs;
pub mod memory;
pub mod program;
pub mod pvt;
pub mod recording;
pub mod signals;
pub(crate) mod update;

use crate::controller::handoff::{Base, Clears, Orders};
use crate::controller::{Controller, Pvt, Settings};
use crate::faults::{FAULT_POSITION, FaultLog};
use crate::faults::{FaultHistory, HISTORY_LEN};
use crate::ident::Identity;
use crate::od::has_effect;
use crate::od::is_command;
use crate::od::{Access, OBJECTS, Obj, ObjError, ObjectDef, Storage};
use crate::servo::Feedback;
use crate::units::Instant;
use control::{Pp, runs_on, settings_of};
use core::borrow::Borrow;

pub use crate::controller::{STATUS_BUSY, STATUS_STALL, Shared, Status};
pub use memory::ProgramMemory;
pub use program::ProgramKind;

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
/// Storage status bit 5: the saved parameters are of a newer store version than this firmware
/// reads (with [`STORAGE_CORRUPT`]: factory values); saves are refused, so that the store stays
/// for the firmware that wrote it.
pub const STORAGE_NEWER: u8 = 1 << 5;
/// The storage status bits that say the store has failed: the store's alarm (0x2135 bit 5).
const STORE_FAILED: u8 = STORAGE_CORRUPT | STORAGE_SAVE_FAILED;

/// Requests the drive makes of its platform, collected with `Drive::take_system_request`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SystemRequest {
    /// Save every ROM object (0x200F = 2).
    Save,
    /// Jump to the boot loader (0x200F = 1).
    BootLoader,
    /// Restart as a power cycle would, once the reply has gone out (0x219F).
    Restart,
    /// Power is failing and 0x605E is on: save this position as 0x6055 before it is gone.
    SavePosition(i32),
    /// An alarm was recorded: save the fault history and the alarm count (0x213C..0x214F,
    /// 0x2136) as they are now, so that they survive a power cycle.
    SaveFaults,
}

/// The fault history objects, newest entry first.
const HISTORY_OBJECTS: [Obj; HISTORY_LEN] = [
    Obj::FaultHistory0,
    Obj::FaultHistory1,
    Obj::FaultHistory2,
    Obj::FaultHistory3,
    Obj::FaultHistory4,
    Obj::FaultHistory5,
    Obj::FaultHistory6,
    Obj::FaultHistory7,
    Obj::FaultHistory8,
    Obj::FaultHistory9,
];

/// The values of the saved objects: what a save writes and what power-up loads.
///
/// Only objects a save covers ([`Params::covers`]) can be set; the others stay at their factory
/// values and are ignored when a drive is built from a set, but for those with records of their
/// own: the power-down position 0x6055 and the fault history with the alarm count.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Params {
    pub(crate) values: [u32; Obj::COUNT],
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
        d.storage() == Storage::Rom && d.access() == Access::Rw
    }

    /// Copies the values of the objects a save covers into `values` (indexed by object), and
    /// leaves the others.
    pub(crate) fn copy_saved_into(&self, values: &mut [u32; Obj::COUNT]) {
        for ((v, p), d) in values.iter_mut().zip(self.values.iter()).zip(OBJECTS.iter()) {
            if Self::covers(d) {
                *v = *p;
            }
        }
    }

    /// Gives the objects a save does not cover their factory values, in place, but the
    /// power-down position (a record of its own): what a drive is built from.
    pub(crate) fn keep_saved(&mut self) {
        for (v, d) in self.values.iter_mut().zip(OBJECTS.iter()) {
            if !Self::covers(d) && d.obj != Obj::SavedPosition {
                *v = d.default;
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
        let ok = Self::covers(d) && d.accepts(value);
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
/// `P` holds the memories shared with the tick (the PVT point table and the recordings, 41 KB)
/// and `G` the multi-segment programs' memory (1 KB): the state owns them by default; a
/// microcontroller keeps each in a static of its own and lends it (`&'static Shared`,
/// `&'static ProgramMemory`), so that building the state never passes them
/// through its stack.
#[derive(Clone, Debug)]
pub struct DriveState<P = Shared, G = ProgramMemory> {
    pub(crate) params: [u32; Obj::COUNT],
    /// Storage status bits (0x2120): `STORAGE_*`.
    storage: u8,
    identity: &'static Identity,
    can_save: bool,
    pub(crate) request: Option<SystemRequest>,
    /// The time of the event being handled (a frame, a tick): when a command takes effect.
    pub(crate) now: Instant,
    /// The profile position and velocity modes' set-points.
    pub(crate) pp: Pp,
    /// Which slots of `table` hold PVT points.
    pub(crate) pvt: Pvt,
    /// The PVT points and the recordings (41 KB: kept out of [`Checkpoint`]).
    pub(crate) shared: P,
    /// The multi-segment programs (1 KB: kept out of [`Checkpoint`]; a program write is one
    /// object's, refused whole or done).
    pub(crate) programs: G,
    /// The settings the controller runs, built from the objects whenever one of them changes
    /// ([`DriveState::refresh_settings`]) and handed to the tick whole.
    pub(crate) settings: Settings,
    /// What the control tick owns: the motion, supervision, the loops and the running status.
    pub(crate) ctl: Controller,
    /// The alarm count when the platform was last asked to save the history (changed only by
    /// taking requests, so kept out of [`Checkpoint`] too).
    faults_saved: u16,
    /// The history was cleared (0x200F = 5) and not yet handed to the platform to save.
    history_unsaved: bool,
    /// 0x21D4's zero: the setpoint's count of moved microsteps at its last clear.
    command_base: u32,
    /// Why the last motion command did not move the motor (0x21F7): kept out of [`Checkpoint`],
    /// as it says why a request was refused.
    not_moving: u8,
    /// What the tick's controller was at the last sync, where the tick owns one of its own
    /// ([`crate::controller::handoff`]); unused where `ctl` is ticked itself.
    base: Base,
    /// Orders for the tick's controller since the last sync.
    orders: Orders,
    /// A frame for this drive arrived since the tick last learned of one (its watchdog
    /// restarts): a message for the tick, not part of its model, and kept out of
    /// [`Checkpoint`] (a refused write was still a frame heard).
    heard: bool,
    /// The built-in homing.
    pub(crate) homing: homing::Homing,
    /// The analog input's follower.
    pub(crate) analog: analog::Analog,
    /// What the inputs' functions did.
    pub(crate) inputs: inputs::Inputs,
    /// The multi-segment program's run.
    pub(crate) program: program::Program,
    /// The factory values were restored by the request being served: the register map sets
    /// its own over them before the save is taken.
    pub(crate) factory_restored: bool,
    /// How long after a request its motion starts, µs: 0 where `ctl` is ticked itself; where the
    /// tick owns a controller of its own, longer than planning and handing over take.
    margin: u64,
    /// The power state machine's state (a latched fault shows over it: `device_state`).
    device: crate::power::DeviceState,
    /// When a quick stop is next checked for rest.
    quick_check: Instant,
    /// The register maps the platform carries (bit n: 0x2190 = n).
    maps: u8,
    /// Whether the platform's power stage is the drive's own, run by its current loop
    /// (`windings`): the loop's objects 0x210B-0x210D act only then.
    current_loop: bool,
    /// The power-up jog's next move (0x21D8).
    jog: command::Jog,
    /// What the signal objects left to do (`signals`).
    pub(crate) signals: signals::Signals,
    /// The firmware update: the transfer (kept out of [`Checkpoint`]: only 0x15 and the
    /// platform change it, and 0x2256's orders are carried out once a request is taken whole).
    pub(crate) updates: update::Updates,
    /// The transfer's order (0x2256) of the request being served, carried out at its end.
    update_order: u8,
    /// The password was given since power-up (0x225F) or set (0x225D).
    unlocked: bool,
}

/// `ma` in percent of `of` mA (0 for none).
fn percent(ma: u16, of: u32) -> u32 {
    (u32::from(ma) * 100).checked_div(of).unwrap_or(0)
}

/// Whether the motion command `value` (0x21A0) plans a motion; the others act at once.
fn plans_motion_command(value: u32) -> bool {
    crate::modes::Command::from_raw(value).is_some_and(crate::modes::Command::plans)
}

/// Whether writing `obj` plans a motion (`state::control`): the commands but a declared
/// position and the PVT objects.
fn plans_motion(obj: Obj) -> bool {
    is_command(obj)
        && has_effect(obj)
        && !crate::od::is_pvt_command(obj)
        && !matches!(obj, Obj::Position | Obj::HomingControl)
        && !recording::is_order(obj)
        && !update::is_order(obj)
}

/// Everything of a [`DriveState`] but the PVT point table and the programs' memory: what a
/// multi-object write restores when a later object of it is refused. (A table slot written by
/// such a write lies beyond the restored count of points, so it is not a point.) The model of
/// the controller is taken whole: no sync runs inside a request, so all of it is the bus side's
/// until the request ends.
#[derive(Clone, Debug)]
pub struct Checkpoint {
    params: [u32; Obj::COUNT],
    storage: u8,
    request: Option<SystemRequest>,
    now: Instant,
    ctl: Controller,
    pp: Pp,
    pvt: Pvt,
    orders: Orders,
    homing: homing::Homing,
    device: crate::power::DeviceState,
    program: program::Program,
    history_unsaved: bool,
    command_base: u32,
    update_order: u8,
    unlocked: bool,
}

impl DriveState {
    /// Factory state.
    pub fn new(identity: &'static Identity, can_save: bool) -> Self {
        let (table, programs) = (Shared::new(), ProgramMemory::new());
        Self::booted(identity, can_save, &Params::factory().values, 0, FaultLog::default(), table, programs)
    }
}

impl<P: Borrow<Shared>, G: Borrow<ProgramMemory>> DriveState<P, G> {
    /// The state at power-up with the object values `params`, the storage status `storage`, the
    /// fault history `faults` (as saved: not to be saved again), the shared memories `shared` and
    /// the programs' memory `programs` (their contents kept).
    ///
    /// One struct expression, out of line: built in a local and then modified, the state would
    /// be copied once more. (The compiler still builds it in a temporary and copies it to the
    /// caller's place, which is why a microcontroller lends the shared memories: see
    /// `Drive::boot_with_table`.)
    #[inline(never)]
    pub(crate) fn booted(
        identity: &'static Identity,
        can_save: bool,
        params: &[u32; Obj::COUNT],
        storage: u8,
        faults: FaultLog,
        shared: P,
        programs: G,
    ) -> Self {
        let get = |obj: Obj| params.get(obj as usize).copied().unwrap_or(0);
        let feedback = Feedback::from_objects(get(Obj::Feedback), get(Obj::EncoderCpr));
        let settings = Settings { store_failed: storage & STORE_FAILED != 0, ..settings_of(params) };
        Self {
            faults_saved: faults.count,
            history_unsaved: false,
            command_base: 0,
            not_moving: 0,
            ctl: Controller::restored(&settings, feedback, faults, get(Obj::MotorDirection) == 1),
            settings,
            params: *params,
            storage,
            identity,
            can_save,
            request: None,
            now: Instant::from_micros(0),
            pp: Pp::default(),
            pvt: Pvt::default(),
            shared,
            programs,
            base: Base::default(),
            orders: Orders::default(),
            heard: false,
            homing: homing::Homing::default(),
            analog: analog::Analog::default(),
            inputs: inputs::Inputs::default(),
            program: program::Program::default(),
            factory_restored: false,
            margin: 0,
            device: if get(Obj::Enable) == 1 {
                crate::power::DeviceState::OperationEnabled
            } else {
                crate::power::DeviceState::SwitchOnDisabled
            },
            quick_check: Instant::from_micros(0),
            maps: u8::MAX,
            current_loop: false,
            jog: if get(Obj::PowerUpJog) == 1 { command::Jog::Start } else { command::Jog::Done },
            signals: signals::Signals::default(),
            updates: update::Updates::default(),
            update_order: 0,
            unlocked: false,
        }
    }

    /// Everything but the PVT table and the programs' memory, to [`DriveState::restore`] later.
    pub fn checkpoint(&self) -> Checkpoint {
        // Naming every field: a new one must be decided on here.
        let Self {
            params,
            storage,
            identity: _,
            can_save: _,
            request,
            now,
            pp,
            pvt,
            shared: _,
            programs: _,
            // Built again from the objects by the restore.
            settings: _,
            ctl,
            faults_saved: _,
            history_unsaved,
            command_base,
            // Says why a refused request was refused: not undone with it.
            not_moving: _,
            base: _,
            orders,
            heard: _,
            homing,
            analog: _,
            inputs: _,
            program,
            factory_restored: _,
            margin: _,
            device,
            quick_check: _,
            maps: _,
            current_loop: _,
            jog: _,
            // Set only after the write that sets it succeeded.
            signals: _,
            updates: _,
            update_order,
            unlocked,
        } = self;
        Checkpoint {
            params: *params,
            storage: *storage,
            request: *request,
            now: *now,
            ctl: ctl.clone(),
            pp: *pp,
            pvt: *pvt,
            orders: *orders,
            homing: *homing,
            device: *device,
            program: *program,
            history_unsaved: *history_unsaved,
            command_base: *command_base,
            update_order: *update_order,
            unlocked: *unlocked,
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
            let written = value(self, item).and_then(|w| w.map_or(Ok(()), |(d, v)| self.write_undoable(d, v)));
            if let Err(e) = written {
                self.restore(saved);
                return Err(e);
            }
        }
        Ok(())
    }

    /// Goes back to `c`.
    pub fn restore(&mut self, c: Checkpoint) {
        let Checkpoint {
            params,
            storage,
            request,
            now,
            ctl,
            pp,
            pvt,
            orders,
            homing,
            device,
            program,
            history_unsaved,
            command_base,
            update_order,
            unlocked,
        } = c;
        (self.update_order, self.unlocked) = (update_order, unlocked);
        (self.params, self.storage, self.request, self.now, self.orders) = (params, storage, request, now, orders);
        (self.ctl, self.pp, self.pvt, self.homing, self.device) = (ctl, pp, pvt, homing, device);
        (self.program, self.history_unsaved, self.command_base) = (program, history_unsaved, command_base);
        // A factory reset undone with the rest: the map's own factory values are not set over
        // the restored ones (a request starts with none pending: the slave takes it at its end).
        self.factory_restored = false;
        self.refresh_settings();
    }

    /// Whether the motor stands: the axis has ended its motion and the command path's shaping
    /// has brought the motor onto it (0x6001's busy bit, 0x21AE, 0x2181's target reached).
    pub(crate) fn motor_still(&self) -> bool {
        self.ctl.axis.is_still() && self.ctl.shaping_settled()
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
        self.ctl.power_state(&self.settings)
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

    /// Builds the controller's settings again from the objects. A zero offset (0x6087) written
    /// is the controller's from then on.
    #[inline(never)]
    pub(crate) fn refresh_settings(&mut self) {
        let new = Settings { store_failed: self.storage & STORE_FAILED != 0, ..settings_of(&self.params) };
        if new.zero_offset != self.settings.zero_offset {
            self.ctl.zero_offset = new.zero_offset;
        }
        self.settings = new;
        self.orders.settings = true;
    }

    /// The settings the controller runs.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// The storage status bits (0x2120): `STORAGE_*`.
    pub fn storage(&self) -> u8 {
        self.storage
    }

    /// The position setpoint in whole microsteps (it never wraps; 0x600E..F shows its low 32 bits).
    pub fn position(&self) -> i64 {
        self.ctl.axis.setpoint().whole
    }

    /// Microsteps a revolution at the resolution in force (0x600C; 0 is full steps): what a
    /// map's units per revolution and a program's speeds convert by.
    pub(crate) fn per_rev(&self) -> u32 {
        let microsteps = self.params.get(Obj::Microsteps as usize).copied().unwrap_or(0).max(1);
        (crate::units::FULL_STEPS_PER_REV as u32).saturating_mul(microsteps)
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
        self.can_save && (self.ctl.faults.count != self.faults_saved || self.history_unsaved)
    }

    /// [`SystemRequest::SaveFaults`] if [due](DriveState::fault_save_due); the history counts as
    /// saved from here on (if the save fails, the next alarm saves the whole history again).
    pub(crate) fn take_fault_save(&mut self) -> Option<SystemRequest> {
        let due = self.fault_save_due();
        self.faults_saved = self.ctl.faults.count;
        self.history_unsaved = false;
        due.then_some(SystemRequest::SaveFaults)
    }

    /// Whether a request for the platform is waiting (`Drive::take_system_request`).
    pub(crate) fn has_request(&self) -> bool {
        self.request.is_some() || self.fault_save_due()
    }

    /// The fault history and alarm count as the objects show them now.
    pub fn fault_history(&self) -> FaultHistory {
        let mut history = FaultHistory { count: self.ctl.faults.count, ..FaultHistory::default() };
        for (k, e) in history.entries.iter_mut().enumerate() {
            *e = self.history(k);
        }
        history
    }

    /// The identification strings.
    pub fn identity(&self) -> &'static Identity {
        self.identity
    }

    /// The value of `obj` as its registers show it (S32 as two's complement).
    pub fn read(&self, obj: Obj) -> u32 {
        self.read_def(obj.def())
    }

    /// The value of the object `d` declares: from the running status for live objects, else stored.
    #[inline]
    pub fn read_def(&self, d: &ObjectDef) -> u32 {
        if d.is_live() { self.live(d.obj) } else { self.params.get(d.obj as usize).copied().unwrap_or(0) }
    }

    /// [`DriveState::live`], with the positions that masters poll read inline, not through its
    /// match of every live object (for the layout maps' plain read).
    #[inline(always)]
    pub(crate) fn polled(&self, obj: Obj) -> u32 {
        // The axis's own state, not a copy: the registers show the low 32 bits.
        let setpoint = self.ctl.axis.setpoint().whole;
        match obj {
            Obj::Position => setpoint as u32,
            Obj::ActualPosition => setpoint.wrapping_sub(self.ctl.servo.following) as u32,
            _ => self.live(obj),
        }
    }

    /// The value of the live object `obj` (of any other, its stored value).
    pub(crate) fn live(&self, obj: Obj) -> u32 {
        let s = &self.ctl.status;
        match obj {
            Obj::Position | Obj::ActualPosition => self.polled(obj),
            Obj::ErrorStatus => u32::from(s.error),
            Obj::ControllerStatus => {
                u32::from(s.controller | self.fifo_status() | if self.motor_still() { 0 } else { STATUS_BUSY })
            }
            Obj::PvtCount => u32::from(self.pvt.count()),
            Obj::PvtFault => u32::from(self.pvt.fault),
            Obj::NotifyStatus => u32::from(s.notify),
            Obj::GpioValue => u32::from(s.gpio),
            Obj::AnalogIn => u32::from(s.analog_in),
            Obj::HomingResult => self.homing_outcome(),
            Obj::StatusWord => u32::from(self.statusword()),
            Obj::DeviceStatus => u32::from(self.device_status()),
            Obj::ErrorRegister => u32::from(self.error_register()),
            Obj::PvtPointer => u32::from(s.pvt_pointer),
            Obj::RealSpeed => self.ctl.real_speed() as u32,
            Obj::NotMovingCode => u32::from(self.not_moving),
            Obj::FollowingError => self.ctl.servo.following as i32 as u32,
            Obj::EncoderPosition => s.encoder as u32,
            Obj::StorageStatus => u32::from(self.storage),
            Obj::AlarmCode => u32::from(self.ctl.alarm_code()),
            Obj::DriveFaults => u32::from(s.faults),
            Obj::CommStatus => u32::from(s.comm),
            Obj::AlarmCount => u32::from(self.ctl.faults.count),
            Obj::RunState => u32::from(self.run_state()),
            Obj::TargetPosition => self.ctl.axis.target().unwrap_or(self.ctl.axis.setpoint().whole) as u32,
            Obj::SupplyVoltage => u32::from(s.supply_mv),
            Obj::MotorCurrent => u32::from(s.current_ma),
            Obj::ProgramInputSegment | Obj::ProgramErrorSegment | Obj::ProgramRunning => self.program_live(obj),
            Obj::InputStates => u32::from(self.active_inputs()),
            Obj::CommandCount => self.ctl.commanded.wrapping_sub(self.command_base),
            Obj::ProbePosition1 => self.ctl.probe[0] as u32,
            Obj::ProbePosition2 => self.ctl.probe[1] as u32,
            Obj::ProbeStatus => u32::from(s.probes),
            Obj::GroupRunning | Obj::GroupNext | Obj::GroupSource => self.groups_live(obj),
            Obj::ElectricalAngle => {
                // An electrical cycle is 4 full steps: a 50th of a revolution.
                let cycle = i64::from((self.per_rev() / 50).max(1));
                (self.ctl.axis.setpoint().whole.rem_euclid(cycle) * 360 / cycle) as u32
            }
            Obj::PulseRate if self.mode() == crate::modes::WorkMode::Follow => self.ctl.real_speed() as u32,
            Obj::PulseRate => 0,
            Obj::AnalogSpeed => self.analog_speed() as u32,
            Obj::CurrentCommand => self.current_command(),
            Obj::Load => percent(s.current_ma, self.param(Obj::PhaseCurrent)),
            Obj::OutputStates => u32::from(self.ctl.outputs_on(&self.settings)),
            Obj::EncoderSignals | Obj::EncoderAngle | Obj::EncoderTurns => self.encoder_live(obj),
            Obj::SerialFormat => self.serial_format(),
            Obj::SignalInputs1 | Obj::SignalInputs2 => self.signal_inputs(obj),
            Obj::ScopeState
            | Obj::ScopeSequence
            | Obj::ScopeRows
            | Obj::ScopeRowWords
            | Obj::ScopeTriggerRow
            | Obj::BlackBoxState
            | Obj::BlackBoxSequence
            | Obj::BlackBoxRows
            | Obj::BlackBoxTriggerRow
            | Obj::BlackBoxFault
            | Obj::ScopeRowPeriod
            | Obj::BlackBoxRowPeriod => self.recording_live(obj),
            Obj::UpdateState
            | Obj::UpdateReason
            | Obj::UpdateReceived
            | Obj::UpdateLength
            | Obj::UpdateVersion
            | Obj::FirmwareVersion
            | Obj::FirmwareKey
            | Obj::FirmwareState
            | Obj::WriteLock => self.update_live(obj),
            // The ten entries are consecutive objects.
            h if (Obj::FaultHistory0 as usize..=Obj::FaultHistory9 as usize).contains(&(h as usize)) => {
                self.history(h as usize - Obj::FaultHistory0 as usize)
            }
            _ => self.params.get(obj as usize).copied().unwrap_or(0),
        }
    }

    /// 0x21E7: the share of the phase current the tick sets, percent: the standstill current
    /// once the axis has stood for the standstill delay (or is held while disabled), 100 while
    /// it moves, 0 de-energised (the soft start's ramp aside).
    fn current_command(&self) -> u32 {
        let s = &self.settings;
        let state = self.ctl.power_state(&self.settings);
        let held = state == crate::modes::PowerState::Disabled && s.hold_disabled;
        if state != crate::modes::PowerState::On && !held {
            return 0;
        }
        let stood =
            self.motor_still() && self.ctl.still_since.is_some_and(|since| self.now.since(since) >= s.idle_delay_us);
        if held || stood { s.idle_current_pct } else { 100 }
    }

    /// 0x21E9, 0x21EB and 0x21ED: the encoder's quadrature levels, its angle in microsteps and
    /// its turns (0 without an encoder).
    fn encoder_live(&self, obj: Obj) -> u32 {
        let Some(e) = self.ctl.servo.feedback.encoder() else { return 0 };
        let (counts, cpr) = (self.ctl.servo.encoder, i64::from(e.counts_per_rev().max(1)));
        match obj {
            // A, B of the quadrature count: 00, 01, 11, 10.
            Obj::EncoderSignals => [0, 1, 3, 2].get(counts.rem_euclid(4) as usize).copied().unwrap_or(0),
            Obj::EncoderAngle => (counts.rem_euclid(cpr).saturating_mul(i64::from(self.per_rev())) / cpr) as u32,
            _ => counts.div_euclid(cpr) as i32 as u32,
        }
    }

    /// Fault history entry `k` (0 the newest), as the tick will have it once it has taken a
    /// clear ordered since the last sync.
    fn history(&self, k: usize) -> u32 {
        if self.ctl.clear_history { 0 } else { self.ctl.history(k) }
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
    /// these against a precomputed interval (`maps::native`): an object with a check beyond its range
    /// must not be plain (a test compares the two).
    pub(crate) const fn plain(d: &ObjectDef) -> bool {
        matches!(d.access(), Access::Rw)
            && matches!(d.storage(), Storage::Ram | Storage::Rom)
            && !has_effect(d.obj)
            && !runs_on(d.obj)
            && !matches!(
                d.obj,
                Obj::SystemControl | Obj::RegisterMap | Obj::CurrentAutoTune | Obj::CurrentKp | Obj::CurrentKi
            )
            && !signals::is_signal(d.obj)
            && !update::is_order(d.obj)
    }

    /// Whether the object `d` declares takes writes, and `value` is within its range.
    fn check_writable(d: &ObjectDef, value: u32) -> Result<(), ObjError> {
        if d.is_read_only() {
            return Err(ObjError::ReadOnly);
        }
        if !d.accepts(value) {
            return Err(ObjError::OutOfRange);
        }
        Ok(())
    }

    /// [`DriveState::check`] for the object `d` declares.
    #[inline(never)]
    pub fn check_def(&self, d: &ObjectDef, value: u32) -> Result<(), ObjError> {
        Self::check_writable(d, value)?;
        match (d.obj, value) {
            // No boot loader to jump to yet (see 0x200F's documentation).
            (Obj::SystemControl, 1) => Err(ObjError::Unsupported),
            (Obj::SystemControl, 2) if !self.can_save => Err(ObjError::Unsupported),
            // A map this platform does not carry would not answer after the restart.
            (Obj::RegisterMap, v) if self.maps & (1 << (v & 7)) == 0 => Err(ObjError::Unsupported),
            // A save keeps the bus side in the flash for up to a page erase (~22 ms), when a
            // stop or a re-target must not wait: never while moving. A second save waits for
            // the first to end.
            (Obj::SystemControl, 2 | 3) if !self.ctl.axis.is_still() || self.storage & STORAGE_SAVING != 0 => {
                Err(ObjError::Busy)
            }
            // The store holds a newer firmware's parameters: not overwritten by this one's.
            (Obj::SystemControl, 2 | 3) if self.storage & STORAGE_NEWER != 0 => Err(ObjError::NotNow),
            // The value it holds changes nothing: taken whatever the state (a dump loaded back).
            (Obj::CurrentAutoTune | Obj::CurrentKp | Obj::CurrentKi, v) if v == self.read(d.obj) => Ok(()),
            // No current loop runs them: an external driver regulates the current.
            (Obj::CurrentAutoTune | Obj::CurrentKp | Obj::CurrentKi, _) if !self.current_loop => {
                Err(ObjError::Unsupported)
            }
            // The power-up auto-tune sets the current loop's gains (seed 003: read only then).
            (Obj::CurrentKp | Obj::CurrentKi, _) if self.read(Obj::CurrentAutoTune) != 0 => Err(ObjError::ReadOnly),
            // Their writes (`signals`) are checked as they are made.
            (obj, v) if signals::is_signal(obj) => self.check_signal(obj, v),
            (obj, v) if recording::is_order(obj) => self.check_order(obj, v),
            (obj, v) if update::is_order(obj) => self.check_update_order(obj, v),
            (obj, _) if is_command(obj) => self.check_motion(obj, value),
            _ => Ok(()),
        }
    }

    /// [`DriveState::check_def`], then [`DriveState::apply_def`] if accepted; nothing changes if
    /// refused. A motion command is planned once: checking it plans the motion (a plan proves a
    /// move possible), and so does applying it, and a plan costs a Cortex-M4 hundreds of
    /// thousands of instructions, during which the control tick waits for the bus task.
    pub fn write_def(&mut self, d: &ObjectDef, value: u32) -> Result<(), ObjError> {
        if signals::is_signal(d.obj) {
            Self::check_writable(d, value)?;
            return self.write_signal(d.obj, value, false);
        }
        if d.obj == Obj::MotionCommand && !plans_motion_command(value) {
            Self::check_writable(d, value)?;
            return self.other_command(value);
        }
        if d.obj == Obj::DeviceControl {
            return self.write_in_order(core::iter::once(value), |_, v| Ok(Some((Obj::DeviceControl.def(), v))));
        }
        // The objects whose check is `check_motion` and whose write is `apply_motion`.
        if plans_motion(d.obj) {
            Self::check_writable(d, value)?;
            let written = self.write_motion(d.obj, value);
            return self.moved_or_why(written);
        }
        self.check_def(d, value)?;
        self.apply_def(d, value);
        Ok(())
    }

    /// Keeps why a motion command was refused for 0x21F7 (30 beyond the overspeed limit, 23
    /// not in the work mode or state in force: `ObjError::NotNow`), or 0 once one is taken;
    /// `written` passes on.
    fn moved_or_why(&mut self, written: Result<(), ObjError>) -> Result<(), ObjError> {
        self.not_moving = match written {
            Ok(()) => 0,
            Err(ObjError::Overspeed) => 30,
            Err(ObjError::NotNow) => 23,
            Err(_) => self.not_moving,
        };
        written
    }

    /// [`DriveState::write_def`] inside a write that a checkpoint undoes if refused: a motion
    /// command is planned on the axis and set-points themselves, with no copy (a refused plan
    /// may leave them halted, and the checkpoint restores them).
    fn write_undoable(&mut self, d: &ObjectDef, value: u32) -> Result<(), ObjError> {
        if signals::is_signal(d.obj) {
            Self::check_writable(d, value)?;
            return self.write_signal(d.obj, value, true);
        }
        if d.obj == Obj::MotionCommand && !plans_motion_command(value) {
            Self::check_writable(d, value)?;
            return self.other_command(value);
        }
        if d.obj == Obj::DeviceControl {
            return self.device_control(value);
        }
        if plans_motion(d.obj) {
            Self::check_writable(d, value)?;
            let planned = self.plan_motion_in_place(d.obj, value);
            self.moved_or_why(planned.map(|_| ()))?;
            self.commit_value(d.obj, value, planned == Ok(true));
            return Ok(());
        }
        self.check_def(d, value)?;
        self.apply_def(d, value);
        Ok(())
    }

    /// Plans the motion command `obj` = `value` on a copy of the axis and set-points, and takes
    /// them if the plan changes them; nothing changes if it is refused. Out of line: the copy
    /// (1 KB) is on the stack for this call only, not under every other write.
    #[inline(never)]
    fn write_motion(&mut self, obj: Obj, value: u32) -> Result<(), ObjError> {
        let mut planned = (self.ctl.axis, self.pp);
        let changed = self.plan_motion(obj, value, &mut planned)?;
        self.commit_motion(obj, value, changed.then_some(&planned));
        Ok(())
    }

    /// Writes `value` to the object `d` declares, which [`DriveState::check`] accepted.
    #[inline(always)]
    pub fn apply_def(&mut self, d: &ObjectDef, value: u32) {
        if d.access() == Access::Rw && d.storage() != Storage::Live && !is_command(d.obj) && d.obj != Obj::Password {
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

    /// Says that a frame for this drive arrived: the tick's watchdog restarts.
    pub(crate) fn frame_heard(&mut self) {
        self.heard = true;
    }

    /// Clears status bits here and orders the tick's controller to clear them too.
    pub(crate) fn clear_status(&mut self, clears: Clears) {
        clears.clear(&mut self.ctl.status, &mut self.pvt);
        self.orders.clear = self.orders.clear.or(clears);
    }

    /// Writes `value` to `obj`, which [`DriveState::check`] accepted.
    pub fn apply(&mut self, obj: Obj, value: u32) {
        let bits = value as u8;
        // A closed-loop stall latches the position error too (0x2135 bit 2): clearing the stall
        // as §5.5.2 says clears both, and the other way round.
        let position = |stall: bool| if stall { FAULT_POSITION } else { 0 };
        let stall = |position: bool| if position { STATUS_STALL } else { 0 };
        match obj {
            Obj::ErrorStatus => self.clear_status(Clears { error: bits, ..Clears::NONE }),
            Obj::ControllerStatus => self.clear_status(Clears {
                controller: bits & !STATUS_BUSY,
                faults: position(bits & STATUS_STALL != 0),
                ..Clears::NONE
            }),
            Obj::NotifyStatus => self.clear_status(Clears { notify: bits, ..Clears::NONE }),
            Obj::StorageStatus => {
                self.storage &= !(bits & !STORAGE_SAVING);
                self.refresh_settings();
            }
            Obj::DriveFaults => self.clear_status(Clears {
                faults: bits,
                controller: stall(bits & FAULT_POSITION != 0),
                ..Clears::NONE
            }),
            Obj::CommStatus => self.clear_status(Clears { comm: bits, ..Clears::NONE }),
            Obj::CommandCount => self.command_base = self.ctl.commanded,
            Obj::ProbeStatus => self.clear_status(Clears { probes: bits, ..Clears::NONE }),
            Obj::PvtFault => self.clear_status(Clears { pvt_fault: bits, ..Clears::NONE }),
            Obj::GpioValue => {
                // Only outputs take the written level (§5.7.2).
                let outputs = self.settings.pins.outputs;
                let s = &mut self.ctl.status;
                s.gpio_out = (s.gpio_out & !outputs) | (value as u16 & outputs);
                s.gpio = (s.gpio & !outputs) | (value as u16 & outputs);
                self.orders.write_outputs(outputs, value as u16);
            }
            Obj::Position => {
                let position = i64::from(value as i32);
                if self.ctl.axis.set_position(position) && self.ctl.servo.feedback.encoder().is_some() {
                    // Closed loop: the position is the encoder's plus the zero offset.
                    self.set_param(Obj::ZeroOffset, position.wrapping_sub(self.ctl.servo.encoder) as u32);
                }
            }
            Obj::HomingControl => self.homing_command(value),
            // A set-point or a homing it starts may be refused: all of it, or nothing (the
            // checkpoint out of line, in `write_in_order`).
            Obj::DeviceControl => {
                let _ = self.write_in_order(core::iter::once(value), |_, v| Ok(Some((Obj::DeviceControl.def(), v))));
            }
            Obj::MotionCommand if !plans_motion_command(value) => {
                let _ = self.other_command(value);
            }
            obj if recording::is_order(obj) => self.apply_order(obj, value),
            obj if update::is_order(obj) => self.apply_update_order(obj, value),
            obj if has_effect(obj) => self.apply_motion(obj, value),
            _ => {
                self.set_param(obj, value);
                if obj == Obj::SystemControl {
                    if value == 4 {
                        self.clear_alarms();
                    }
                    if value == 5 {
                        (self.ctl.clear_history, self.orders.clear_history) = (true, true);
                        self.history_unsaved = true;
                    }
                    if value == 3 {
                        self.restore_factory();
                        self.factory_restored = true;
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
    /// status are untouched). Out of line: the factory set (600 bytes) is on the stack for this
    /// call only.
    #[inline(never)]
    pub fn restore_factory(&mut self) {
        Params::factory().copy_saved_into(&mut self.params);
        self.refresh_settings();
    }

    /// Sets `obj` to `value` as its factory value (a register map's own, see
    /// `RegisterMap::factory_settings`).
    pub(crate) fn set_factory_value(&mut self, obj: Obj, value: u32) {
        self.set_param(obj, value);
    }

    /// The platform finished the save it was asked for ([`SystemRequest::Save`]); `ok` if the
    /// flash holds the new set.
    pub fn save_done(&mut self, ok: bool) {
        let s = &mut self.storage;
        *s &= !STORAGE_SAVING;
        if !ok {
            *s |= STORAGE_SAVE_FAILED;
            // The store's alarm, where 0x21F8 detects it.
            self.refresh_settings();
        }
    }
}
