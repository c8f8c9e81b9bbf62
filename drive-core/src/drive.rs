//! The serial slave: frames in (RTU, or Modbus ASCII lines: 0x2192), requests executed on the
//! drive's state through a register map, replies out; the diagnostic counters.

use crate::ascii;
use crate::controller::Outputs;
use crate::controller::Shared;
use crate::controller::handoff::{Handover, Lent, TickSide};
use crate::crc;
use crate::faults::{FaultLog, Inputs};
use crate::ident::Identity;
use crate::maps::{NativeMap, RegisterMap, Spoilt};
use crate::od::Obj;
use crate::pdu::{Exception, FileRecords, MAX_READ, Request, SubIndex, Words};
use crate::rtu::{self, MAX_FRAME, RxError};
use crate::state::ProgramMemory;
use crate::units::{Baud, Instant, SlaveAddr};
use crate::update::{self, RecordError};
use core::borrow::Borrow;

pub use crate::state::{
    Checkpoint, DriveState, Params, STATUS_BUSY, STATUS_STALL, STORAGE_CORRUPT, STORAGE_EMPTY, STORAGE_FSET,
    STORAGE_NEWER, STORAGE_SAVE_FAILED, STORAGE_SAVING, Status, SystemRequest,
};

/// What a platform gives a drive at power-up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DriveConfig {
    /// Overrides the node id object (0x2028) for this run.
    pub address: Option<SlaveAddr>,
    /// Overrides the baud rate object (0x202A) for this run.
    pub baud: Option<Baud>,
    /// The identification strings.
    pub identity: &'static Identity,
    /// Whether the platform can save parameters (0x200F = 2); without it a save is refused (04).
    /// With it, the platform serves [`SystemRequest::Save`] (a parameter store serves it).
    pub can_save: bool,
}

impl Default for DriveConfig {
    fn default() -> Self {
        Self { address: None, baud: None, identity: &Identity::SIMULATOR, can_save: false }
    }
}

/// The framing of the serial line: the object 0x2192 at power-up chooses it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineFraming {
    /// RTU: binary frames ended by t3.5 of silence, checked by their CRC.
    Rtu,
    /// Modbus ASCII: lines `:`, hex, LRC, CR LF ([`crate::ascii`]), with the spec's one-second
    /// inter-character timeout.
    Ascii,
}

impl LineFraming {
    /// The framing the object 0x2192 chooses by its `value`: 1 ASCII, else RTU.
    pub const fn of(value: u32) -> Self {
        if value == 1 { Self::Ascii } else { Self::Rtu }
    }
}

/// The Modbus serial-line diagnostic counters (function 0x08, sub-functions 0x0B-0x12).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// 0x0B: frames with a good CRC (ASCII: LRC) seen on the bus, for any address.
    pub bus_messages: u16,
    /// 0x0C: frames dropped for a bad CRC, a gap inside the frame, or too short to hold a function
    /// code and a CRC; in ASCII, lines dropped for a bad LRC, a character that is no hex digit
    /// (CR LF at their end excepted), an odd number of digits, too few for an address, a function
    /// code and an LRC, a `:` before their end, or a silence over the inter-character timeout.
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
    /// 0x12: frames lost to a receive overrun (longer than 256 bytes; ASCII lines longer than 513
    /// characters).
    pub overruns: u16,
}

/// A drive on a serial line: the RTU slave and the drive state behind it, with its PVT point
/// table (`P`) and its programs' memory (`G`), owned or lent ([`DriveState`]).
#[derive(Clone, Debug)]
pub struct Drive<M: RegisterMap = NativeMap, P = Shared, G = ProgramMemory> {
    line: Line,
    address: SlaveAddr,
    /// The CRC register after `address`, the first byte of every reply.
    address_crc: u16,
    baud: Baud,
    listen_only: bool,
    counters: Counters,
    framing: Framing,
    /// The reply: an RTU frame, or an ASCII line (built binary at its start, then encoded in
    /// place: [`ascii::encode_in_place`]).
    tx: [u8; ascii::MAX_LINE],
    tx_len: usize,
    map: M,
    state: DriveState<P, G>,
}

/// The receiver of the framing in force, one or the other in the same memory (the ASCII
/// framer, 288 bytes, is no larger than the RTU one). The slave looks at which once a call.
///
/// The tag is a byte of its own (`repr(u8)`) rather than a value the RTU framer's fields leave
/// free: the RTU path then reads its framer as it did before there was a choice.
#[derive(Clone, Debug)]
#[repr(u8)]
enum Line {
    Rtu(rtu::Framer),
    /// A line that ended waits in the framer ([`ascii::Framer::ended`]) until it is served.
    Ascii(ascii::Framer),
}

/// What the slave needs of its map's framing on every request, asked of the map once when the
/// drive is built (it is fixed for the map's life) and kept as plain data, so that no request
/// pays a call into the map for it.
#[derive(Clone, Copy, Debug)]
struct Framing {
    /// [`RegisterMap::sub_index`]: `None` for Modbus's PDUs. The slave decodes the commonest
    /// requests itself, by [`Request::short`] or the [`SubIndex::keys`].
    sub_index: Option<SubIndex>,
    /// [`RegisterMap::address_extra`].
    address_extra: usize,
}

impl Framing {
    fn of(map: &impl RegisterMap) -> Self {
        Self { sub_index: map.sub_index(), address_extra: map.address_extra() }
    }
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
        Self::boot_with_table(config, map, params, storage, Shared::new())
    }
}

impl<M: RegisterMap, P: Borrow<Shared>> Drive<M, P> {
    /// [`Drive::boot_with_map`] with the PVT point table `table` (its points are not read: the
    /// table starts empty), and a programs' memory of its own.
    pub fn boot_with_table(config: DriveConfig, map: M, params: &Params, storage: u8, table: P) -> Self {
        Self::boot_with_memory(config, map, params, storage, table, ProgramMemory::new())
    }

    /// [`Drive::boot_in_with_memory`] with a programs' memory of the drive's own.
    pub fn boot_in<'a>(
        slot: &'a mut core::mem::MaybeUninit<Self>,
        config: DriveConfig,
        map: M,
        params: &mut Params,
        storage: u8,
        table: P,
    ) -> &'a mut Self {
        Self::boot_in_with_memory(slot, config, map, params, storage, table, ProgramMemory::new())
    }
}

impl<M: RegisterMap, P: Borrow<Shared>, G: Borrow<ProgramMemory>> Drive<M, P, G> {
    /// [`Drive::boot_with_map`] with the PVT point table `table` (its points are not read: the
    /// table starts empty) and the programs' memory `programs` (its program is kept: power-up
    /// may have loaded it). A microcontroller lends both from statics of its own
    /// (`&'static Shared`, `&'static ProgramMemory`), so the drive it builds is under 7 KB (the
    /// image transfer's digest and staged record are 0.7 KB of it) instead of 49 KB:
    ///
    /// ```
    /// use drive_core::{Drive, DriveConfig, Params};
    /// use drive_core::controller::Shared;
    /// use drive_core::maps::NativeMap;
    /// use drive_core::state::ProgramMemory;
    /// let (table, programs) = (Shared::new(), ProgramMemory::new());
    /// let d = Drive::boot_with_memory(DriveConfig::default(), NativeMap::new(), &Params::factory(), 0, &table, &programs);
    /// assert!(core::mem::size_of_val(&d) < 7 * 1024);
    /// ```
    #[inline(never)]
    pub fn boot_with_memory(config: DriveConfig, map: M, params: &Params, storage: u8, table: P, programs: G) -> Self {
        let mut params = params.clone();
        let faults = FaultLog::restored(&params.fault_history());
        params.keep_saved();
        let mut drive = Self::assemble(config, map, &mut params, faults, storage, table, programs);
        drive.map_power_up(storage);
        drive
    }

    /// [`Drive::boot_with_memory`] built in `slot`, where a microcontroller keeps its drive, from
    /// `params` (settled in place: the objects a save does not cover take their factory values,
    /// and the config's overrides are applied), so that no copy of them is on the stack.
    #[inline(never)]
    pub fn boot_in_with_memory<'a>(
        slot: &'a mut core::mem::MaybeUninit<Self>,
        config: DriveConfig,
        map: M,
        params: &mut Params,
        storage: u8,
        table: P,
        programs: G,
    ) -> &'a mut Self {
        let faults = FaultLog::restored(&params.fault_history());
        params.keep_saved();
        let drive = slot.write(Self::assemble(config, map, params, faults, storage, table, programs));
        drive.map_power_up(storage);
        drive
    }

    /// The register map's part of power-up: whether it offers programs, and with nothing saved
    /// (`storage`) its own factory settings over the drive's.
    fn map_power_up(&mut self, storage: u8) {
        self.state.set_program_kind(self.map.program_kind());
        if storage & (STORAGE_EMPTY | STORAGE_CORRUPT | STORAGE_FSET) != 0 {
            self.map.factory_settings(&mut self.state);
        }
    }

    /// The drive [`Drive::boot_with_memory`] builds from `params` (what a save covers, and the
    /// power-down position), with `faults` the history loaded; inlined into each caller.
    #[inline(always)]
    fn assemble(
        config: DriveConfig,
        map: M,
        params: &mut Params,
        faults: FaultLog,
        storage: u8,
        table: P,
        programs: G,
    ) -> Self {
        // The values are settled first and the drive is one struct expression (as the state is,
        // `DriveState::booted`), so that the drive is not built aside and copied once more.
        let pulses = params.get(Obj::PulseAtPowerUp) == 1;
        let values = &mut params.values;
        let mut set = |obj: Obj, value: u32| {
            if let Some(v) = values.get_mut(obj as usize) {
                *v = value;
            }
        };
        if let Some(a) = config.address {
            set(Obj::NodeId, u32::from(a.get()));
            set(Obj::AddressSource, 1);
        }
        if let Some(b) = config.baud {
            set(Obj::BaudRate, b.get());
        }
        if pulses {
            // Seed 002's 0296 = 0 (external pulses): the drive powers up following them.
            set(Obj::Mode, crate::modes::WorkMode::Follow.raw());
        }
        if map.starts_disabled() {
            // CiA 402: switch on disabled at power-up, whatever the enable holds.
            set(Obj::Enable, 0);
        }
        let values = &params.values;
        let get = |obj: Obj| values.get(obj as usize).copied().unwrap_or(0);
        // The serial settings in force are those of power-up; writes take effect at the next one.
        // A serial port with an address of its own answers at it unless 0x21D1 takes the node id.
        let node = match map.fixed_address() {
            Some(a) if get(Obj::AddressSource) == 0 => u32::from(a),
            _ => get(Obj::NodeId),
        };
        let address = SlaveAddr::new(node as u8).unwrap_or(SlaveAddr::BROADCAST);
        let baud = Baud::new(get(Obj::BaudRate)).unwrap_or(Baud::FACTORY);
        let line = match LineFraming::of(get(Obj::LineFraming)) {
            LineFraming::Rtu => Line::Rtu(rtu::Framer::new(baud)),
            LineFraming::Ascii => Line::Ascii(ascii::Framer::new(ascii::DEFAULT_TIMEOUT_MICROS)),
        };
        Self {
            line,
            address,
            address_crc: crc::update(crc::INIT, address.get()),
            baud,
            listen_only: false,
            counters: Counters::default(),
            framing: Framing::of(&map),
            tx: [0; ascii::MAX_LINE],
            tx_len: 0,
            map,
            state: DriveState::booted(
                config.identity,
                config.can_save,
                values,
                storage & !STORAGE_SAVING,
                faults,
                table,
                programs,
            ),
        }
    }

    /// The same drive answering through the map `f` makes of its own (the native map into
    /// [`Maps`](crate::maps::Maps), say).
    pub fn map_into<N: RegisterMap>(self, f: impl FnOnce(M) -> N) -> Drive<N, P, G> {
        let Self { line, address, address_crc, baud, listen_only, counters, tx, tx_len, map, mut state, .. } = self;
        let map = f(map);
        state.set_program_kind(map.program_kind());
        let framing = Framing::of(&map);
        Drive { line, address, address_crc, baud, listen_only, counters, framing, tx, tx_len, map, state }
    }

    /// The address this drive answers to.
    pub fn address(&self) -> SlaveAddr {
        self.address
    }

    /// The baud rate the framing is timed for.
    pub fn baud(&self) -> Baud {
        self.baud
    }

    /// The framing of the serial line, fixed at power-up (0x2192).
    pub fn line_framing(&self) -> LineFraming {
        match self.line {
            Line::Rtu(_) => LineFraming::Rtu,
            Line::Ascii(_) => LineFraming::Ascii,
        }
    }

    /// The register map the drive answers through.
    pub fn map(&self) -> &M {
        &self.map
    }

    /// The drive state behind the registers.
    pub fn state(&self) -> &DriveState<P, G> {
        &self.state
    }

    /// The drive state, for the platform (inputs, motion).
    pub fn state_mut(&mut self) -> &mut DriveState<P, G> {
        &mut self.state
    }

    /// The diagnostic counters.
    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    /// Bytes received at `now`. A frame that had already ended is processed first
    /// ([`Drive::frame_due`]).
    ///
    /// In ASCII a line ends at its LF, and waits: it is served by the next [`Drive::on_timer`]
    /// (at once: [`Drive::deadline`] is then the time of its last byte) or the next `on_rx`, as
    /// an RTU frame that has ended, so that a platform that syncs before serving a request sees
    /// it in [`Drive::frame_due`] first. Only if a `:` follows it in the same call is it served
    /// here, before that `:` starts the next line (without the platform's sync); of two lines
    /// that ask for an answer in one call (a master that did not wait for the first answer) the
    /// platform then takes the later answer only.
    pub fn on_rx(&mut self, now: Instant, bytes: &[u8]) {
        if bytes.is_empty() {
            return;
        }
        match &mut self.line {
            // The bytes of one call arrived together: only the first can follow a silence.
            Line::Rtu(framer) if !framer.ended(now) => framer.extend(now, bytes),
            Line::Rtu(_) => self.rtu_rx_after_end(now, bytes),
            Line::Ascii(_) => self.ascii_rx(now, bytes),
        }
    }

    /// RTU bytes after a silence that ended the frame before them: that frame is served first.
    // Out of line: `on_rx` stays small enough to inline into the platform's calls.
    #[inline(never)]
    fn rtu_rx_after_end(&mut self, now: Instant, bytes: &[u8]) {
        self.state.now = now;
        self.end_frame();
        if let Line::Rtu(framer) = &mut self.line {
            framer.extend(now, bytes);
        }
    }

    /// Time passes: a frame whose t3.5 has run out is processed; in ASCII a line that ended is,
    /// and one silent for longer than the inter-character timeout is dropped.
    pub fn on_timer(&mut self, now: Instant) {
        // The time a request is served at, the time its motion is planned for.
        self.state.now = now;
        match &mut self.line {
            Line::Rtu(framer) => {
                if framer.ended(now) {
                    self.end_frame();
                }
            }
            Line::Ascii(_) => self.ascii_timer(now),
        }
    }

    /// One control tick at `now` (every [`TICK_MICROS`](crate::units::TICK_MICROS)): runs the
    /// motion and says what the output stage does.
    pub fn tick(&mut self, now: Instant) -> Outputs {
        self.state.tick(now)
    }

    /// [`Drive::tick`] with what the drive measures: faults and protections are checked against it.
    pub fn tick_with(&mut self, now: Instant, inputs: &Inputs) -> Outputs {
        self.state.tick_with(now, inputs)
    }

    /// Whether the model of the controller holds something the tick's own controller has not
    /// taken in: where the tick owns a controller of its own, a change to hand over by a sync.
    pub fn has_changes(&self) -> bool {
        self.state.has_changes()
    }

    /// Lends the model of the controller to a control tick that owns a controller of its own,
    /// for [`TickSide::sync`](crate::controller::handoff::TickSide::sync); then
    /// [`DriveState::synced`]. See [`crate::controller::handoff`].
    pub fn lend(&mut self) -> Lent<'_> {
        self.state.lend()
    }

    /// Syncs the model with `tick` at `now` where both run in one thread (a simulator, a test):
    /// [`TickSide::sync`](crate::controller::handoff::TickSide::sync) with [`Drive::lend`], then
    /// [`DriveState::synced`] unless the sync waits for a plan's first tick.
    pub fn sync_here(&mut self, tick: &mut TickSide, now: Instant) -> Handover {
        let handover = tick.sync(now, &mut self.lend());
        if handover != Handover::Waiting {
            self.state.synced();
        }
        handover
    }

    /// Whether a request is complete at `now`, to be served by the next [`Drive::on_timer`] or
    /// [`Drive::on_rx`]: where the tick owns a controller of its own, the moment to sync the
    /// model first.
    ///
    /// In ASCII, whether a line has ended (at its LF) and waits.
    pub fn frame_due(&self, now: Instant) -> bool {
        match &self.line {
            Line::Rtu(framer) => framer.ended(now),
            Line::Ascii(framer) => framer.ended().is_some(),
        }
    }

    /// When [`Drive::on_timer`] next has something to do: the end of the RTU frame in progress
    /// (t3.5 after its last byte); in ASCII, the time of the last byte if a line has ended and
    /// waits, else the inter-character timeout's expiry while a line is in progress.
    pub fn deadline(&self) -> Option<Instant> {
        match &self.line {
            Line::Rtu(framer) => framer.deadline(),
            Line::Ascii(framer) => framer.ended().map(|(_, at)| at).or_else(|| framer.deadline()),
        }
    }

    /// The reply frame to send, once.
    pub fn take_reply(&mut self) -> Option<&[u8]> {
        let n = core::mem::take(&mut self.tx_len);
        if n == 0 { None } else { self.tx.get(..n) }
    }

    /// [`Drive::take_reply`] and [`Drive::lend`] at once: where the tick owns a controller of its
    /// own, the reply goes out while the tick takes in what the request changed.
    pub fn reply_and_lend(&mut self) -> (Option<&[u8]>, Lent<'_>) {
        let n = core::mem::take(&mut self.tx_len);
        let reply = if n == 0 { None } else { self.tx.get(..n) };
        (reply, self.state.lend())
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

    /// Ends the frame that has ended (RTU), or the line that ended and waits (ASCII,
    /// [`Drive::end_line`]): serves it if its CRC is good, else counts it and answers it as the
    /// map answers a spoilt frame; the receiver then waits for the next.
    // Inlined into its callers, which call one of two functions out of line, neither of which
    // saves registers for the other's path.
    #[inline(always)]
    fn end_frame(&mut self) {
        if self.framing.sub_index.is_some() { self.end_sub_indexed_frame() } else { self.end_modbus_frame() }
    }

    /// [`Drive::end_frame`] of a frame to a map with Modbus's requests (and of an ASCII line).
    #[inline(never)]
    fn end_modbus_frame(&mut self) {
        self.end_rtu_frame::<false>();
    }

    /// [`Drive::end_frame`] of an RTU frame to a map whose requests name registers by an index
    /// and a sub-index (and of an ASCII line to it): an instance of its own, out of line, so that
    /// neither this nor Modbus's RTU path decodes (or holds registers for) the other's requests.
    #[inline(never)]
    fn end_sub_indexed_frame(&mut self) {
        self.end_rtu_frame::<true>();
    }

    /// [`Drive::end_frame`]: `SUB_INDEX`, the map's requests have a [`SubIndex`].
    #[inline(always)]
    fn end_rtu_frame<const SUB_INDEX: bool>(&mut self) {
        let Line::Rtu(framer) = &self.line else { return self.end_line() };
        let ((_, error), crc_ok) = (framer.frame(), framer.crc_ok());
        let c = &mut self.counters;
        match error {
            Some(RxError::Overrun) => c.overruns = c.overruns.wrapping_add(1),
            Some(RxError::Gap { after_frame }) => {
                c.bus_errors = c.bus_errors.wrapping_add(1);
                self.frame_exception(if after_frame { Spoilt::Early } else { Spoilt::Gap });
            }
            None if !crc_ok => {
                c.bus_errors = c.bus_errors.wrapping_add(1);
                self.frame_exception(Spoilt::Crc);
            }
            None => self.serve_frame::<false, SUB_INDEX>(),
        }
        if let Line::Rtu(framer) = &mut self.line {
            framer.clear();
        }
    }

    /// [`Drive::end_frame`] of an ASCII line: served if its LRC is good, else counted and
    /// answered as a frame spoilt by its CRC (any other verdict was counted as the line was
    /// dropped).
    ///
    /// This and the ASCII path's other functions are out of line and `cold` so that the RTU
    /// path's code is laid out as it was before there was a choice (an ASCII line's few hundred
    /// instructions more are nothing beside its characters' time on the line).
    #[cold]
    #[inline(never)]
    fn end_line(&mut self) {
        let Line::Ascii(framer) = &self.line else { return };
        match framer.ended() {
            Some((bytes, _)) if ascii::lrc(bytes) == 0 => self.serve_frame::<true, false>(),
            Some(_) => {
                self.counters.bus_errors = self.counters.bus_errors.wrapping_add(1);
                self.frame_exception(Spoilt::Crc);
            }
            None => {}
        }
        if let Line::Ascii(framer) = &mut self.line {
            framer.clear();
        }
    }

    /// Serves a frame with a good check, then the map's own factory settings if it restored the
    /// drive's. `ASCII`: the frame is an ASCII line's, and so is the reply. `SUB_INDEX`: an RTU
    /// frame to a map with a [`SubIndex`]. (One instance each, inlined into `end_frame`,
    /// `end_sub_indexed_frame` and `end_line`: the RTU path pays no test of the framing.)
    #[inline(always)]
    fn serve_frame<const ASCII: bool, const SUB_INDEX: bool>(&mut self) {
        self.serve::<ASCII, SUB_INDEX>();
        if core::mem::take(&mut self.state.factory_restored) {
            // The map's own factory settings go over the drive's, before the save.
            self.map.factory_settings(&mut self.state);
        }
    }

    /// ASCII bytes (see [`Drive::on_rx`]): a line that ended before them is served first, then
    /// the bytes go to the framer, up to a `:` behind a line that ended in them, which is served
    /// before the `:` starts the next.
    // Out of line, as `ascii_timer`: `on_rx` and `on_timer` stay small enough for the RTU path
    // to inline them into the platform's calls (see also `end_line`).
    #[cold]
    #[inline(never)]
    fn ascii_rx(&mut self, now: Instant, bytes: &[u8]) {
        let mut rest = bytes;
        while !rest.is_empty() {
            if matches!(&self.line, Line::Ascii(framer) if framer.ended().is_some()) {
                self.state.now = now;
                self.end_frame();
            }
            let Self { line: Line::Ascii(framer), counters, .. } = self else { return };
            let mut taken = rest.len();
            for (i, &b) in rest.iter().enumerate() {
                if b == b':' && framer.ended().is_some() {
                    taken = i;
                    break;
                }
                // A line that ended waits in the framer, to be served, or with a bad LRC counted
                // and answered as the map has it; a line dropped otherwise is counted now.
                match framer.push(now, b) {
                    Some(Err(ascii::RxError::Lrc)) | Some(Ok(_)) | None => {}
                    Some(Err(ascii::RxError::Overrun)) => counters.overruns = counters.overruns.wrapping_add(1),
                    Some(Err(_)) => counters.bus_errors = counters.bus_errors.wrapping_add(1),
                }
            }
            rest = rest.get(taken..).unwrap_or_default();
        }
    }

    /// ASCII time passes (see [`Drive::on_timer`]): a line that ended is served, one silent for
    /// longer than the inter-character timeout dropped.
    #[cold]
    #[inline(never)]
    fn ascii_timer(&mut self, now: Instant) {
        let Line::Ascii(framer) = &mut self.line else { return };
        if framer.ended().is_some() {
            self.end_frame();
        } else if framer.expire(now).is_some() {
            self.counters.bus_errors = self.counters.bus_errors.wrapping_add(1);
        }
    }

    /// Answers a frame `spoilt` with the exception code the map has for it, if it has one, from
    /// the address and the function code the frame began with, if it began with this drive's
    /// address (a broadcast, another drive's frame or one too short to say are not answered) and
    /// not in listen-only mode.
    // Out of line: the request path keeps to its own work.
    #[cold]
    #[inline(never)]
    fn frame_exception(&mut self, spoilt: Spoilt) {
        let Some(code) = self.map.spoilt_frame(&self.state, spoilt) else { return };
        let (frame, ascii) = self.line.received();
        let (Some(&to), Some(&function)) = (frame.first(), frame.get(1)) else { return };
        if to != self.address.get() || self.listen_only || function & 0x80 != 0 {
            return;
        }
        self.counters.exceptions = self.counters.exceptions.wrapping_add(1);
        if let Some(head) = self.tx.first_chunk_mut::<3>() {
            *head = [to, function | 0x80, code];
            self.tx_len = if ascii { seal_line(&mut self.tx, 3) } else { seal(&mut self.tx, 3, self.address_crc) };
        }
    }

    /// Serves a frame with a good CRC (`ASCII`: LRC) that sits in the framer (`SUB_INDEX`: see
    /// [`Drive::serve_frame`]).
    // Inlined into `serve_frame`, its one caller.
    #[inline(always)]
    fn serve<const ASCII: bool, const SUB_INDEX: bool>(&mut self) {
        let Self { line, address, address_crc, listen_only, counters, framing, tx, tx_len, map, state, .. } = self;
        counters.bus_messages = counters.bus_messages.wrapping_add(1);
        // The frame and the bytes of its check: an RTU frame and its CRC, or the bytes of an ASCII
        // line and its LRC.
        let (frame, check, head_crc) = match line {
            Line::Rtu(framer) if !ASCII => (framer.frame().0, 2, Some(framer.head_crc())),
            Line::Ascii(framer) if ASCII => (framer.ended().map_or(&[][..], |(bytes, _)| bytes), 1, None),
            _ => return,
        };
        let Some((&to, rest)) = frame.split_first() else {
            return;
        };
        let broadcast = to == SlaveAddr::BROADCAST.get();
        if !broadcast && to != address.get() {
            return;
        }
        counters.slave_messages = counters.slave_messages.wrapping_add(1);
        state.frame_heard();
        let pdu = rest.get(..rest.len().saturating_sub(check)).unwrap_or_default();
        let function = pdu.first().copied().unwrap_or(0);
        if function & 0x80 != 0 {
            // Codes 0x80-0xFF are exception replies, never requests: there is no way to answer.
            counters.no_responses = counters.no_responses.wrapping_add(1);
            return;
        }
        let mut server = Server { map, state, counters, listen_only, address_crc: *address_crc };
        let silent = broadcast || *server.listen_only;
        let Some((head, body)) = tx.split_first_chunk_mut::<2>() else {
            return;
        };
        let body = body.get_mut(..MAX_FRAME - 4).unwrap_or_default();
        // A register read or write (0x03, 0x04, 0x06, 0x10 in Modbus's PDU; 0x03, 0x06, 0x10 with
        // a sub-index), answered: the commonest requests, decoded inline by one match on their
        // bytes, with no checks of silence. (An RTU frame with a sub-index has an instance of
        // its own: `end_frame`; an ASCII line with one is decoded by the map.)
        let short = if silent {
            None
        } else if SUB_INDEX {
            framing.sub_index.and_then(|s| s.keys.short(pdu))
        } else if ASCII && framing.sub_index.is_some() {
            None
        } else {
            Request::short(pdu)
        };
        let result = match short {
            Some(req) => server.execute(&req, body),
            None => {
                // A server of its own: only this path puts one in memory for the call.
                let mut general = Server {
                    map: &mut *server.map,
                    state: &mut *server.state,
                    counters: &mut *server.counters,
                    listen_only: &mut *server.listen_only,
                    address_crc: server.address_crc,
                };
                match general.decoded(framing.sub_index, pdu, silent, body, tx_len) {
                    Some(result) => result,
                    None => return,
                }
            }
        };
        let len = match result {
            Ok(Outcome::Sealed(n, sum)) if !ASCII => {
                *head = [address.get(), function];
                *tx_len = match tx.get_mut(2 + n..4 + n) {
                    Some(c) => {
                        c.copy_from_slice(&sum.to_le_bytes());
                        4 + n
                    }
                    None => 0,
                };
                return;
            }
            Ok(Outcome::Reply(n) | Outcome::Sealed(n, _)) => {
                *head = [address.get(), function];
                n
            }
            Ok(Outcome::Echo) => {
                // The request's register (with what the map puts after it) and value or count: the
                // request's first bytes, its address this drive's.
                let n = 5 + framing.address_extra;
                if pdu.len() == n && !ASCII {
                    // The whole request (a one-register write): the reply is the request frame,
                    // whose CRC is checked already. (An ASCII line is encoded anew: the
                    // request's may have lower-case digits.)
                    match (tx.first_chunk_mut::<8>(), frame.first_chunk::<8>()) {
                        // Modbus's frame of 8 bytes at once: a call of memcpy costs more.
                        (Some(to), Some(from)) if frame.len() == 8 => *to = *from,
                        _ => put(tx, 0, frame),
                    }
                    *tx_len = frame.len();
                    return;
                }
                *head = [address.get(), function];
                let echo = pdu.get(1..n).unwrap_or_default();
                match (body.first_chunk_mut::<4>(), echo.first_chunk::<4>()) {
                    // Modbus's 4 bytes at once: a call of memcpy, or a loop set up for any
                    // length, costs more.
                    (Some(to), Some(from)) if echo.len() == 4 => *to = *from,
                    _ => {
                        for (d, &b) in body.iter_mut().zip(echo) {
                            *d = b;
                        }
                    }
                }
                // The reply is the request's first bytes: the framer has their CRC.
                if let Some(sum) = head_crc
                    && 2 + echo.len() == rtu::HEAD
                    && let Some(c) = tx.get_mut(rtu::HEAD..rtu::HEAD + 2)
                {
                    c.copy_from_slice(&sum.to_le_bytes());
                    *tx_len = rtu::HEAD + 2;
                    return;
                }
                echo.len()
            }
            Ok(Outcome::Silent) => {
                counters.no_responses = counters.no_responses.wrapping_add(1);
                return;
            }
            Err(e) => {
                let code = server.map.request_exception(e).code();
                counters.exceptions = counters.exceptions.wrapping_add(1);
                *head = [address.get(), function | 0x80];
                if let Some(b) = body.first_mut() {
                    // The PDU layer's refusals in the map's codes (the map's own are already).
                    *b = code;
                }
                1
            }
        };
        *tx_len = if ASCII { seal_line(tx, 2 + len) } else { seal(tx, 2 + len, *address_crc) };
    }
}

impl Line {
    /// The frame received and whether it is an ASCII line's: an RTU frame with its CRC, or the
    /// bytes an ASCII line that ended decoded to, with its LRC.
    fn received(&self) -> (&[u8], bool) {
        match self {
            Line::Rtu(framer) => (framer.frame().0, false),
            Line::Ascii(framer) => (framer.ended().map_or(&[][..], |(bytes, _)| bytes), true),
        }
    }
}

/// Turns the first `n` bytes of `buf`, a binary reply, into the ASCII line that carries it; the
/// line's length, or 0 if it does not fit.
// Out of line and cold: see `Drive::end_line`.
#[cold]
#[inline(never)]
fn seal_line(buf: &mut [u8], n: usize) -> usize {
    ascii::encode_in_place(buf, n).unwrap_or(0)
}

/// Appends the CRC to the first `n` bytes of `buf`, a reply that begins with this drive's address
/// (`address_crc`: the CRC register after it); the frame's length, or 0 if it does not fit.
#[inline(always)]
fn seal(buf: &mut [u8], n: usize, address_crc: u16) -> usize {
    let sum = crc::update_bytes(address_crc, buf.get(1..n).unwrap_or_default());
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
    /// [`Outcome::Reply`] and the reply's CRC, run as its bytes were made.
    Sealed(usize, u16),
    /// A write's reply: the request's register, with the map's [`RegisterMap::address_extra`]
    /// bytes after it, and its value or count.
    Echo,
    /// No reply (force listen-only mode, restart from listen-only mode).
    Silent,
}

/// The parts of a drive that execute a request.
struct Server<'a, M, P, G> {
    map: &'a mut M,
    state: &'a mut DriveState<P, G>,
    counters: &'a mut Counters,
    listen_only: &'a mut bool,
    /// The CRC register after the reply's first byte, this drive's address.
    address_crc: u16,
}

/// Conformity level of device identification: regular, stream and individual access.
const CONFORMITY: u8 = 0x82;

impl<M: RegisterMap, P: Borrow<Shared>, G: Borrow<ProgramMemory>> Server<'_, M, P, G> {
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

    /// A request that the slave's inline decoding did not take (one of another kind, an ASCII
    /// line's to a map with a [`SubIndex`], a malformed one, one not to be answered), decoded by
    /// the map's decoder or Modbus's and executed if it may be: its result to answer, or `None`,
    /// counted. Out of line: the short paths do not hold registers for it (nor a server in
    /// memory for its calls), and every kind of frame shares one instance.
    #[inline(never)]
    fn decoded(
        &mut self,
        sub_index: Option<SubIndex>,
        pdu: &[u8],
        silent: bool,
        out: &mut [u8],
        tx_len: &mut usize,
    ) -> Option<Result<Outcome, Exception>> {
        let request = match sub_index {
            Some(s) => (s.parse)(pdu),
            None => Request::parse(pdu),
        };
        if silent && !request.as_ref().is_ok_and(|req| self.silent_allowed(req)) {
            self.counters.no_responses = self.counters.no_responses.wrapping_add(1);
            return None;
        }
        // One call of `execute` for both: what may execute without an answer executes, and its
        // reply is dropped (a reply not yet taken with it).
        let result = request.and_then(|req| self.execute(&req, out));
        if silent {
            *tx_len = 0;
            self.counters.no_responses = self.counters.no_responses.wrapping_add(1);
            return None;
        }
        Some(result)
    }

    /// Executes `req`, writing the reply's data (after the function code) into `out`.
    // Inlined into the request path: a call here costs more than a short request's work.
    #[inline(always)]
    fn execute(&mut self, req: &Request<'_>, out: &mut [u8]) -> Result<Outcome, Exception> {
        match *req {
            // One call site for both (the read is inlined at each).
            Request::ReadHolding { addr, qty } | Request::ReadInput { addr, qty } => {
                let function = if matches!(req, Request::ReadHolding { .. }) { 0x03 } else { 0x04 };
                self.read(function, addr, qty, out)
            }
            Request::WriteSingle { addr, value } => {
                self.may_write(addr, 1)?;
                self.map.write(self.state, addr, Words::new(&value.to_be_bytes()))?;
                self.settle()?;
                Ok(Outcome::Echo)
            }
            Request::WriteMultiple { addr, values } => {
                self.may_write(addr, values.len())?;
                self.map.write(self.state, addr, values)?;
                self.settle()?;
                Ok(Outcome::Echo)
            }
            Request::ReadWrite { read_addr, read_qty, write_addr, values } => {
                self.may_write(write_addr, values.len())?;
                self.map.check_read(read_addr, read_qty)?;
                self.map.write(self.state, write_addr, values)?;
                self.settle()?;
                self.read(0x17, read_addr, read_qty, out)
            }
            Request::WriteFileRecord { records } => self.file_records(records, out),
            Request::Diagnostics { sub, data } => self.diagnostics(sub, data, out),
            Request::ReadDeviceId { code, object } => {
                // The application name says which map answers.
                let mut id = *self.state.identity();
                if let Some(name) = self.map.application_name() {
                    id.user_application_name = name;
                }
                device_id(&id, code, object, out)
            }
        }
    }

    /// Refuses a write of `n` registers from `addr` while the drive's writes are locked
    /// (0x225C), unless it writes no more than the unlock object 0x225F.
    #[inline(always)]
    fn may_write(&self, addr: u16, n: usize) -> Result<(), Exception> {
        if !self.state.locked() {
            return Ok(());
        }
        let unlock = Obj::Unlock.def().addr;
        let within = addr >= unlock && usize::from(addr) + n <= usize::from(unlock) + 2;
        if within && self.map.is_native(addr) { Ok(()) } else { Err(Exception::IllegalFunction) }
    }

    /// Carries out the transfer's order of the write just taken, if it gave one.
    #[inline(always)]
    fn settle(&mut self) -> Result<(), Exception> {
        self.state.settle_update().map_err(crate::maps::native::native_exception)
    }

    /// 0x15: an image's records, taken in order, all of them or none (but an image refused,
    /// which fails the transfer); the reply echoes the request.
    #[inline(never)]
    fn file_records(&mut self, records: FileRecords<'_>, out: &mut [u8]) -> Result<Outcome, Exception> {
        if self.state.locked() {
            return Err(Exception::IllegalFunction);
        }
        let (transfer, target) = self.state.transfer_mut();
        let target = *target.ok_or(Exception::IllegalFunction)?;
        let saved = records.iter().nth(1).is_some().then(|| transfer.clone());
        for r in records.iter() {
            let taken = update::record_offset(r.file, r.record)
                .ok_or(RecordError::PastEnd)
                .and_then(|offset| transfer.record(&target, offset, r.data));
            if let Err(e) = taken {
                if let (Some(saved), false) = (saved, matches!(e, RecordError::Refused(_))) {
                    *transfer = saved;
                }
                return Err(match e {
                    RecordError::Order | RecordError::PastEnd => Exception::IllegalDataAddress,
                    RecordError::Refused(_) => Exception::IllegalDataValue,
                    RecordError::Busy | RecordError::NotReady => Exception::ServerDeviceFailure,
                });
            }
        }
        let echo = records.bytes();
        put(out, 0, &[echo.len() as u8]);
        put(out, 1, echo);
        Ok(Outcome::Reply(1 + echo.len()))
    }

    /// A read by `function`: the byte count and the registers, sealed as they are made.
    #[inline(always)]
    fn read(&mut self, function: u8, addr: u16, qty: u16, out: &mut [u8]) -> Result<Outcome, Exception> {
        let n = 2 * usize::from(qty.min(MAX_READ));
        let (count, data) = out.split_first_mut().ok_or(Exception::ServerDeviceFailure)?;
        *count = n as u8;
        let crc = crc::update(crc::update(self.address_crc, function), n as u8);
        let data = data.get_mut(..n).ok_or(Exception::ServerDeviceFailure)?;
        let crc = self.map.read_sealing(self.state, addr, data, crc)?;
        Ok(Outcome::Sealed(1 + n, crc))
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
