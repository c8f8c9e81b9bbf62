//! The saved parameters in flash, through `sequential-storage`'s map over a [`NorFlash`].
//!
//! Three records, each one map item (a CRC-checked write that a power cut leaves either whole or
//! ignored, with the crate's repair of torn pages on the next access):
//!
//! - [`PARAMS_KEY`]: every object a save covers ([`Params::covers`]), as one record, so that a
//!   power cut during a save leaves the complete old set or the complete new set, never a mix.
//!   The record is a header `[format, 0, count (u16)]` and `count` entries `(register address
//!   (u16), value (u32))`, little endian. Loading ignores addresses this firmware does not save
//!   (an object dropped by an update) and values its ranges refuse; objects the record lacks (added
//!   by an update) keep their factory values: how a newer image reads an older store's record. A
//!   record of another [`FORMAT`] is not read at all; one of a newer format (a newer firmware's,
//!   found after a rollback) is kept, and this firmware refuses to save over it
//!   ([`STORAGE_NEWER`]). The formats together are the store's [`VERSION`].
//! - [`POSITION_KEY`]: the position saved at power loss (0x6055), an `i32`, small and quick so it
//!   fits in the power supply's hold-up time.
//! - [`FAULTS_KEY`]: the fault history 0x213C..0x214F and the alarm count 0x2136
//!   ([`FaultHistory`]), saved whenever an alarm is recorded ([`SystemRequest::SaveFaults`]):
//!   `[format, 0, count (u16), 10 entries (u32), newest first]`, little endian, 44 bytes. A record
//!   of another [`FAULTS_FORMAT`] or length is not read (the history starts empty).
//! - [`PROGRAM_KEYS`]: the multi-segment program of a map that offers one (seed 002's registers
//!   1024-1536, the drive's [`ProgramMemory`]), saved with the parameters in
//!   [`PROGRAM_CHUNKS`] records of up to 256 bytes (the store's buffer holds one),
//!   `[format, chunk, crc (u16)]` and the chunk's words high byte first, in one of two banks of
//!   keys: a save writes the bank the last one did not, then the commit record
//!   [`PROGRAM_COMMIT_KEY`] `[format, bank, crc (u16)]` (the CRC-16 of the whole program). A
//!   power cut before the commit leaves the old program, after it the new one; a bank whose
//!   chunks do not make the committed CRC is not loaded (the program reads empty).
//!
//! The functions are async as the flash traits are; the drive state machine is not: the platform
//! [`Store::load`]s before it builds the [`Drive`] and performs the saves that
//! [`Drive::take_system_request`](crate::Drive::take_system_request) asks for: with
//! [`Store::serve`] if it can lend the drive for the flash operation, or as a [`Job`] taken from
//! the drive, run on the flash without it, then reported back, if the drive sits behind a lock
//! that the control tick also takes.

use core::borrow::Borrow;
use core::ops::Range;

use embedded_storage_async::nor_flash::NorFlash;
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapConfigError, MapStorage};

use crate::drive::{
    Drive, Params, STORAGE_CORRUPT, STORAGE_EMPTY, STORAGE_FSET, STORAGE_NEWER, STORAGE_SAVE_FAILED, SystemRequest,
};
pub use crate::faults::FaultHistory;
use crate::faults::HISTORY_LEN;
use crate::maps::RegisterMap;
use crate::od::{Access, OBJECTS, Storage};
use crate::state::ProgramMemory;
use crate::state::Shared;
use crate::state::memory::WORDS as PROGRAM_WORDS;

/// Map key of the parameter record.
pub const PARAMS_KEY: u8 = 0;
/// Map key of the power-down position record.
pub const POSITION_KEY: u8 = 1;
/// Map key of the fault history record.
pub const FAULTS_KEY: u8 = 2;
/// Map keys of the program's records, one a chunk: bank 0, then bank 1.
pub const PROGRAM_KEYS: core::ops::Range<u8> = 3..3 + 2 * PROGRAM_CHUNKS as u8;
/// Map key of the program's commit record: which bank holds the program saved last.
pub const PROGRAM_COMMIT_KEY: u8 = PROGRAM_KEYS.end;
/// Program bytes a record holds.
const PROGRAM_CHUNK: usize = 256;
/// Records the program takes.
pub const PROGRAM_CHUNKS: usize = (2 * PROGRAM_WORDS).div_ceil(PROGRAM_CHUNK);
/// Format of the program records.
pub const PROGRAM_FORMAT: u8 = 1;
/// The store's version: the formats of its records that this firmware writes and reads (the
/// parameter record's [`FORMAT`], [`FAULTS_FORMAT`], [`PROGRAM_FORMAT`]). An image's header
/// names the lowest store version it reads (`update::Header::store`), and a drive refuses an
/// image that needs a newer store than its own.
pub const VERSION: u16 = 1;
/// Format of the parameter record; bumped only if the entry layout changes (new objects do not).
pub const FORMAT: u8 = VERSION as u8;
/// Format of the fault history record.
pub const FAULTS_FORMAT: u8 = 1;
/// Bytes of the fault history record.
pub const FAULTS_RECORD: usize = HEADER + 4 * HISTORY_LEN;

impl FaultHistory {
    /// The record (see the module documentation).
    pub fn encode(&self) -> [u8; FAULTS_RECORD] {
        let mut out = [0u8; FAULTS_RECORD];
        let [lo, hi] = self.count.to_le_bytes();
        if let Some((head, entries)) = out.split_first_chunk_mut::<HEADER>() {
            *head = [FAULTS_FORMAT, 0, lo, hi];
            for (chunk, e) in entries.as_chunks_mut::<4>().0.iter_mut().zip(self.entries) {
                *chunk = e.to_le_bytes();
            }
        }
        out
    }

    /// Reads a record.
    pub fn decode(record: &[u8]) -> Result<Self, DecodeError> {
        let (&[format, _, lo, hi], entries) = record.split_first_chunk::<HEADER>().ok_or(DecodeError::Length)?;
        if format != FAULTS_FORMAT {
            return Err(DecodeError::Format(format));
        }
        if record.len() != FAULTS_RECORD {
            return Err(DecodeError::Length);
        }
        let mut history = Self { count: u16::from_le_bytes([lo, hi]), ..Self::default() };
        for (e, chunk) in history.entries.iter_mut().zip(entries.as_chunks::<4>().0) {
            *e = u32::from_le_bytes(*chunk);
        }
        Ok(history)
    }
}

/// How many objects the parameter record holds (as [`Params::covers`], at compile time).
pub const SAVED: usize = {
    let mut n = 0;
    let mut i = 0;
    while i < OBJECTS.len() {
        #[allow(clippy::indexing_slicing)]
        let d = &OBJECTS[i];
        if matches!(d.storage(), Storage::Rom) && matches!(d.access(), Access::Rw) {
            n += 1;
        }
        i += 1;
    }
    n
};

/// Bytes of the record header.
const HEADER: usize = 4;
/// Bytes of one entry.
const ENTRY: usize = 6;
/// Bytes of the parameter record.
pub const RECORD: usize = HEADER + ENTRY * SAVED;
/// The crate's work buffer: key and value, rounded up to its largest flash word (32 bytes).
const BUFFER: usize = (1 + RECORD).next_multiple_of(32);
const _: () =
    assert!(4 + PROGRAM_CHUNK <= RECORD && FAULTS_RECORD <= RECORD, "every record fits a parameter record's room");

/// Writes the parameter record of `params` into `out`; its length, or `None` if `out` is short.
pub fn encode(params: &Params, out: &mut [u8]) -> Option<usize> {
    let out = out.get_mut(..RECORD)?;
    let (head, mut rest) = out.split_first_chunk_mut::<HEADER>()?;
    let [lo, hi] = (SAVED as u16).to_le_bytes();
    *head = [FORMAT, 0, lo, hi];
    for d in OBJECTS.iter().filter(|d| Params::covers(d)) {
        let (entry, tail) = rest.split_first_chunk_mut::<ENTRY>()?;
        let [a0, a1] = d.addr.to_le_bytes();
        let [v0, v1, v2, v3] = params.get(d.obj).to_le_bytes();
        *entry = [a0, a1, v0, v1, v2, v3];
        rest = tail;
    }
    Some(RECORD)
}

/// Why a parameter record was not read.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DecodeError {
    /// A format this firmware does not know.
    Format(u8),
    /// The length does not match the header's entry count.
    Length,
}

/// Reads a parameter record into `params`. Unknown addresses and refused values are skipped;
/// objects the record lacks keep the value they had. On an error `params` is unchanged.
pub fn decode(record: &[u8], params: &mut Params) -> Result<(), DecodeError> {
    let (&[format, _, lo, hi], entries) = record.split_first_chunk::<HEADER>().ok_or(DecodeError::Length)?;
    if format != FORMAT {
        return Err(DecodeError::Format(format));
    }
    if entries.len() != ENTRY * usize::from(u16::from_le_bytes([lo, hi])) {
        return Err(DecodeError::Length);
    }
    for &[a0, a1, v0, v1, v2, v3] in entries.as_chunks::<ENTRY>().0 {
        let addr = u16::from_le_bytes([a0, a1]);
        if let Some(d) = OBJECTS.iter().find(|d| d.addr == addr) {
            // Refused values (a range narrowed by an update) keep the present one.
            let _ = params.set(d.obj, u32::from_le_bytes([v0, v1, v2, v3]));
        }
    }
    Ok(())
}

/// What power-up found in the store.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Loaded {
    /// The saved values, factory values where none could be read.
    pub params: Params,
    /// Storage status bits for 0x2120: [`STORAGE_EMPTY`] or [`STORAGE_CORRUPT`], or 0.
    pub status: u8,
}

/// A flash error, or one of the map's (corruption it could not repair, full storage, ...).
pub type Error<S> = sequential_storage::Error<<S as embedded_storage_async::nor_flash::ErrorType>::Error>;

/// The parameter store on the pages `range` of a flash.
pub struct Store<S: NorFlash> {
    map: MapStorage<u8, S, Cache<Uncached, Uncached, Uncached, u8>>,
    buf: [u8; BUFFER],
}

impl<S: NorFlash> core::fmt::Debug for Store<S> {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Store").field("range", &self.map.flash_range()).finish_non_exhaustive()
    }
}

impl<S: NorFlash> Store<S> {
    /// The store on the flash pages `range` (whole erase pages, at least two).
    pub fn new(flash: S, range: Range<u32>) -> Result<Self, MapConfigError> {
        let config = MapConfig::try_new(range)?;
        Ok(Self { map: MapStorage::new(flash, config, Cache::new_uncached()), buf: [0; BUFFER] })
    }

    /// Reads the saved parameters, the power-down position and the fault history. A missing
    /// record gives factory values (an empty history); a store the map cannot read gives factory values and is erased, so that the next
    /// save works. Never fails: what went wrong is in the status bits.
    pub async fn load(&mut self) -> Loaded {
        let mut params = Params::factory();
        let mut status = STORAGE_EMPTY;
        let mut found_other = false;
        let mut unreadable = self
            .read(PARAMS_KEY..FAULTS_KEY + 1, &mut |key, record| match key {
                PARAMS_KEY => {
                    status = match decode(record, &mut params) {
                        Ok(()) => 0,
                        // A newer firmware's store (a rollback after an update that changed
                        // it): kept for that firmware, not saved over (0x2120 bit 5).
                        Err(DecodeError::Format(f)) if f > FORMAT => STORAGE_CORRUPT | STORAGE_NEWER,
                        Err(_) => STORAGE_CORRUPT,
                    }
                }
                POSITION_KEY => {
                    // An `i32`, little endian, as the crate stores one.
                    if let Some(&bytes) = record.first_chunk::<4>() {
                        params.set_saved_position(i32::from_le_bytes(bytes));
                    }
                    found_other = true;
                }
                _ => {
                    found_other = true;
                    // A record this firmware cannot read is a history lost, not a reason to drop
                    // the parameters.
                    if let Ok(history) = FaultHistory::decode(record) {
                        params.set_fault_history(&history);
                    }
                }
            })
            .await;
        // No record, yet the pages are not erased: not a store of ours (or one torn beyond
        // repair). Saving into it would fail on programmed words.
        if status & STORAGE_EMPTY != 0 && !found_other && !self.is_erased().await {
            unreadable = true;
        }
        if unreadable {
            params = Params::factory();
            status = STORAGE_CORRUPT;
            // If even the erase fails, saves will fail and say so (0x2120 bit 4).
            let _ = self.map.erase_all().await;
        }
        Loaded { params, status }
    }

    /// Power-up: [`Store::load`], or with `fset_low` (FSET held low for 5 s) the factory values,
    /// saved at once after the store is erased (status [`STORAGE_FSET`], and
    /// [`STORAGE_SAVE_FAILED`] if that save failed). Build the drive from the result with
    /// [`Drive::boot`].
    pub async fn power_up(&mut self, fset_low: bool) -> Loaded {
        if !fset_low {
            return self.load().await;
        }
        let params = Params::factory();
        let saved = match self.erase().await {
            Ok(()) => self.save(&params).await,
            Err(e) => Err(e),
        };
        let failed = if saved.is_ok() { 0 } else { STORAGE_SAVE_FAILED };
        Loaded { params, status: STORAGE_FSET | failed }
    }

    /// Performs the request `drive` makes of its platform, if any: [`Job::take`], [`Store::run`]
    /// and [`Job::finish`] in one call, for a platform that can lend the drive for the flash
    /// operation. Returns the request and how it went; [`SystemRequest::BootLoader`] is the
    /// platform's to act on. Call it outside the control tick, after the reply has been sent.
    pub async fn serve<M: RegisterMap, P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &mut self,
        drive: &mut Drive<M, P, G>,
    ) -> Option<(SystemRequest, Result<(), Error<S>>)> {
        let job = Job::take(drive)?;
        let done = self.run(&job, drive.state().program_memory()).await;
        job.finish(drive, done.is_ok());
        Some((job.request(), done))
    }

    /// Carries out `job` on the flash, without the drive; report the result with [`Job::finish`].
    /// A parameter save saves the program too where the drive's map offers one (`program`: its
    /// [`DriveState::program_memory`](crate::state::DriveState::program_memory), which the
    /// drive leaves unchanged while the save is under way). A boot loader request has nothing to
    /// write here.
    pub async fn run(&mut self, job: &Job, program: Option<&ProgramMemory>) -> Result<(), Error<S>> {
        match job {
            Job::Save(params) => {
                self.save(params).await?;
                match program {
                    Some(memory) => self.save_program(memory).await,
                    None => Ok(()),
                }
            }
            Job::SavePosition(position) => self.save_position(*position).await,
            Job::SaveFaults(history) => self.save_faults(history).await,
            Job::BootLoader | Job::Restart => Ok(()),
        }
    }

    /// Whether every byte of the store's pages reads erased (0xFF); a failed read counts as not.
    async fn is_erased(&mut self) -> bool {
        let range = self.map.flash_range();
        let mut at = range.start;
        while at < range.end {
            let n = (range.end - at).min(BUFFER as u32);
            let chunk = self.buf.get_mut(..n as usize).unwrap_or_default();
            if self.map.flash().read(at, chunk).await.is_err() || chunk.iter().any(|&b| b != 0xFF) {
                return false;
            }
            at += n;
        }
        true
    }

    /// Saves `params` as one record (see the module documentation).
    pub async fn save(&mut self, params: &Params) -> Result<(), Error<S>> {
        self.write(Record::Params(params)).await
    }

    /// Saves the program in `memory` into the bank the last save did not use, then commits it
    /// (see the module documentation).
    pub async fn save_program(&mut self, memory: &ProgramMemory) -> Result<(), Error<S>> {
        let bank = self.program_commit().await.map_or(0, |(bank, _)| bank ^ 1);
        self.write(Record::Program { memory, bank, crc: program_crc(memory) }).await
    }

    /// The bank and CRC of the program saved last, if a commit record says.
    async fn program_commit(&mut self) -> Option<(u8, [u8; 2])> {
        let mut commit = None;
        self.read(PROGRAM_COMMIT_KEY..PROGRAM_COMMIT_KEY + 1, &mut |_, record| {
            if let Some(&[PROGRAM_FORMAT, bank @ 0..=1, lo, hi]) = record.first_chunk::<4>() {
                commit = Some((bank, [lo, hi]));
            }
        })
        .await;
        commit
    }

    /// Writes the records of `what`: one write of the crate's for every record (one copy of its
    /// code in a firmware).
    async fn write(&mut self, what: Record<'_>) -> Result<(), Error<S>> {
        for k in 0..=PROGRAM_CHUNKS {
            let mut out = [0u8; RECORD];
            let Some((key, n)) = what.encode(k, &mut out) else {
                return if k == 0 { Err(sequential_storage::Error::BufferTooSmall(RECORD)) } else { Ok(()) };
            };
            self.map.store_item(&mut self.buf, &key, &out.get(..n).unwrap_or_default()).await?;
        }
        Ok(())
    }

    /// Loads the saved program into `memory`: whether a whole one was found (else `memory` reads
    /// as an empty program, all zero).
    pub async fn load_program(&mut self, memory: &ProgramMemory) -> bool {
        let bytes = 2 * PROGRAM_WORDS;
        let Some((bank, crc)) = self.program_commit().await else { return false };
        let first = PROGRAM_KEYS.start + bank * PROGRAM_CHUNKS as u8;
        let mut torn = false;
        self.read(first..first + PROGRAM_CHUNKS as u8, &mut |key, record| {
            let chunk = usize::from(key - first);
            let start = chunk * PROGRAM_CHUNK;
            let n = PROGRAM_CHUNK.min(bytes - start);
            match record.split_first_chunk::<4>() {
                Some((&[PROGRAM_FORMAT, k, lo, hi], body))
                    if usize::from(k) == chunk && body.len() == n && [lo, hi] == crc =>
                {
                    for (k, &[hi, lo]) in body.as_chunks::<2>().0.iter().enumerate() {
                        memory.set_word(start / 2 + k, u16::from_be_bytes([hi, lo]));
                    }
                }
                _ => torn = true,
            }
        })
        .await;
        let whole = !torn && u16::from_le_bytes(crc) == program_crc(memory);
        if !whole {
            memory.clear();
        }
        whole
    }

    /// Reads the records `keys`, handing each one found to `each`: one read of the crate's for
    /// every record (one copy of its code in a firmware). Whether a read failed.
    async fn read(&mut self, keys: core::ops::Range<u8>, each: &mut dyn FnMut(u8, &[u8])) -> bool {
        let mut failed = false;
        for key in keys {
            match self.map.fetch_item::<&[u8]>(&mut self.buf, &key).await {
                Ok(Some(record)) => each(key, record),
                Ok(None) => {}
                Err(_) => failed = true,
            }
        }
        failed
    }

    /// Saves the power-down position (0x6055): one small record, for the power-loss detector.
    pub async fn save_position(&mut self, position: i32) -> Result<(), Error<S>> {
        self.write(Record::Position(position)).await
    }

    /// Saves the fault history and alarm count: one small record.
    pub async fn save_faults(&mut self, history: &FaultHistory) -> Result<(), Error<S>> {
        self.write(Record::Faults(history)).await
    }

    /// Erases every page of the store.
    pub async fn erase(&mut self) -> Result<(), Error<S>> {
        self.map.erase_all().await
    }

    /// The flash under the store.
    pub fn flash(&mut self) -> &mut S {
        self.map.flash()
    }

    /// Ends the store, giving back its flash.
    pub fn into_flash(self) -> S {
        self.map.destroy().0
    }
}

/// A request taken from the drive together with what the flash operation needs, so that the
/// platform can release the drive (a lock the control tick also takes) while the flash is written.
#[derive(Clone, Debug, PartialEq, Eq)]
#[allow(clippy::large_enum_variant, reason = "no heap to box into; one job exists at a time")]
pub enum Job {
    /// Save this set: the drive's parameters when the request was taken.
    Save(Params),
    /// Save this power-down position (0x6055).
    SavePosition(i32),
    /// Save this fault history: the drive's when the request was taken.
    SaveFaults(FaultHistory),
    /// Jump to the boot loader: the platform's to act on, nothing for the store.
    BootLoader,
    /// Restart: the platform's to act on, nothing for the store.
    Restart,
}

impl Job {
    /// Takes the drive's pending request, if any, with a copy of its parameters for a save. The
    /// drive shows the save in progress (0x2120 bit 3) and refuses another until [`Job::finish`].
    pub fn take<M: RegisterMap, P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        drive: &mut Drive<M, P, G>,
    ) -> Option<Self> {
        Some(match drive.take_system_request()? {
            SystemRequest::Save => Job::Save(drive.state().params()),
            SystemRequest::SavePosition(position) => Job::SavePosition(position),
            SystemRequest::SaveFaults => Job::SaveFaults(drive.state().fault_history()),
            SystemRequest::BootLoader => Job::BootLoader,
            SystemRequest::Restart => Job::Restart,
        })
    }

    /// The request this job carries out.
    pub fn request(&self) -> SystemRequest {
        match self {
            Job::Save(_) => SystemRequest::Save,
            Job::SavePosition(position) => SystemRequest::SavePosition(*position),
            Job::SaveFaults(_) => SystemRequest::SaveFaults,
            Job::BootLoader => SystemRequest::BootLoader,
            Job::Restart => SystemRequest::Restart,
        }
    }

    /// Tells the drive how the job went (`ok`: the flash holds what it was asked to hold). Only a
    /// parameter save has a status in the drive (0x2120 bits 3 and 4).
    pub fn finish<M: RegisterMap, P: Borrow<Shared>, G: Borrow<ProgramMemory>>(
        &self,
        drive: &mut Drive<M, P, G>,
        ok: bool,
    ) {
        if matches!(self, Job::Save(_)) {
            drive.save_done(ok);
        }
    }
}

/// Byte `i` of the program in `memory` as a record holds it: its words high byte first.
fn program_byte(memory: &ProgramMemory, i: usize) -> u8 {
    let [hi, lo] = memory.word(i / 2).unwrap_or(0).to_be_bytes();
    if i.is_multiple_of(2) { hi } else { lo }
}

/// The CRC-16 of the program in `memory`, over its bytes as the records hold them.
fn program_crc(memory: &ProgramMemory) -> u16 {
    (0..2 * PROGRAM_WORDS).fold(crate::crc::INIT, |c, i| crate::crc::update(c, program_byte(memory, i)))
}

/// What a save writes: its records, built one at a time into the store's buffer-sized scratch.
enum Record<'a> {
    Params(&'a Params),
    Position(i32),
    Faults(&'a FaultHistory),
    /// The program, into a bank (0 or 1), then its commit; its CRC, in each.
    Program {
        memory: &'a ProgramMemory,
        bank: u8,
        crc: u16,
    },
}

impl Record<'_> {
    /// Record `k` of this save into `out`: its key and length, `None` past the last one.
    fn encode(&self, k: usize, out: &mut [u8; RECORD]) -> Option<(u8, usize)> {
        let first = |bytes: &[u8], out: &mut [u8; RECORD]| {
            let n = bytes.len().min(RECORD);
            out.get_mut(..n)?.copy_from_slice(bytes.get(..n)?);
            Some(n)
        };
        match (self, k) {
            (Self::Params(params), 0) => Some((PARAMS_KEY, encode(params, out)?)),
            // An `i32`, little endian, as the crate stores one.
            (Self::Position(position), 0) => Some((POSITION_KEY, first(&position.to_le_bytes(), out)?)),
            (Self::Faults(history), 0) => Some((FAULTS_KEY, first(&history.encode(), out)?)),
            (&Self::Program { memory, bank, crc }, k) if k <= PROGRAM_CHUNKS => {
                let bytes = 2 * PROGRAM_WORDS;
                let [lo, hi] = crc.to_le_bytes();
                let (head, body) = out.split_first_chunk_mut::<4>()?;
                if k == PROGRAM_CHUNKS {
                    // The commit, once every chunk is written.
                    *head = [PROGRAM_FORMAT, bank, lo, hi];
                    return Some((PROGRAM_COMMIT_KEY, 4));
                }
                let start = k * PROGRAM_CHUNK;
                let n = PROGRAM_CHUNK.min(bytes - start);
                *head = [PROGRAM_FORMAT, k as u8, lo, hi];
                for (i, b) in body.iter_mut().take(n).enumerate() {
                    *b = program_byte(memory, start + i);
                }
                Some((PROGRAM_KEYS.start + bank * PROGRAM_CHUNKS as u8 + k as u8, 4 + n))
            }
            _ => None,
        }
    }
}

/// Flash bytes one item of `len` value bytes occupies on a flash `S` (header, key, padding).
pub const fn item_bytes<S: NorFlash>(len: usize) -> usize {
    let header = MapStorage::<u8, S, Cache<Uncached, Uncached, Uncached, u8>>::item_overhead_size() as usize;
    header + (1 + len).next_multiple_of(S::WRITE_SIZE)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::od::Obj;

    #[test]
    fn a_record_round_trips() {
        let mut p = Params::factory();
        assert!(p.set(Obj::NodeId, 9));
        assert!(p.set(Obj::PhaseCurrent, 1500));
        assert!(p.set(Obj::AnalogMinPos, (-5i32) as u32));
        let mut buf = [0u8; RECORD];
        assert_eq!(encode(&p, &mut buf), Some(RECORD));
        let mut back = Params::factory();
        assert_eq!(decode(&buf, &mut back), Ok(()));
        assert_eq!(back, p);
        assert_eq!(encode(&p, &mut [0u8; RECORD - 1]), None);
    }

    #[test]
    fn unknown_addresses_are_ignored_and_missing_ones_keep_their_values() {
        // An older or newer firmware's record: node id 9, an address we do not have, a value our
        // range refuses (microsteps 257), and nothing else.
        let mut rec = [FORMAT, 0, 3, 0].to_vec();
        for (addr, v) in [(0x2028u16, 9u32), (0x2FFF, 77), (0x600C, 257)] {
            rec.extend(addr.to_le_bytes());
            rec.extend(v.to_le_bytes());
        }
        let mut p = Params::factory();
        assert_eq!(decode(&rec, &mut p), Ok(()));
        let mut want = Params::factory();
        want.set(Obj::NodeId, 9);
        assert_eq!(p, want);
    }

    #[test]
    fn bad_records_change_nothing() {
        let mut p = Params::factory();
        p.set(Obj::GroupId, 5);
        let before = p.clone();
        assert_eq!(decode(&[2, 0, 0, 0], &mut p), Err(DecodeError::Format(2)));
        assert_eq!(decode(&[FORMAT, 0, 1, 0, 0x28, 0x20, 9], &mut p), Err(DecodeError::Length));
        assert_eq!(decode(&[FORMAT], &mut p), Err(DecodeError::Length));
        assert_eq!(p, before);
    }

    #[test]
    fn a_job_holds_the_set_of_its_request_and_the_drive_shows_it_until_finished() {
        use crate::drive::{STORAGE_SAVE_FAILED, STORAGE_SAVING};
        use crate::{Drive, DriveConfig};
        let mut drive = Drive::new(DriveConfig { can_save: true, ..DriveConfig::default() });
        assert_eq!(Job::take(&mut drive), None);
        drive.state_mut().apply(Obj::GroupId, 5);
        drive.state_mut().apply(Obj::SystemControl, 2);
        let job = Job::take(&mut drive);
        assert_eq!(job.as_ref().map(Job::request), Some(SystemRequest::Save));
        assert_eq!(Job::take(&mut drive), None, "taken once");
        // A change after the request is not part of the set being written.
        drive.state_mut().apply(Obj::GroupId, 6);
        let saved = match &job {
            Some(Job::Save(params)) => Some(params.get(Obj::GroupId)),
            _ => None,
        };
        assert_eq!(saved, Some(5));
        assert_eq!(drive.state().read(Obj::StorageStatus) as u8 & STORAGE_SAVING, STORAGE_SAVING);
        if let Some(job) = &job {
            job.finish(&mut drive, false);
        }
        assert_eq!(
            drive.state().read(Obj::StorageStatus) as u8 & (STORAGE_SAVING | STORAGE_SAVE_FAILED),
            STORAGE_SAVE_FAILED
        );
        // A position job leaves the parameter save status alone.
        Job::SavePosition(7).finish(&mut drive, true);
        assert_eq!(drive.state().read(Obj::StorageStatus) as u8 & STORAGE_SAVE_FAILED, STORAGE_SAVE_FAILED);
    }

    #[test]
    fn a_fault_history_record_round_trips_and_bad_ones_are_refused() {
        let entries = [11 << 24 | 30, 13 << 24 | 20, 10 << 24 | 0x00FF_FFFF, 0, 0, 0, 0, 0, 0, 0];
        let h = FaultHistory { entries, count: 300 };
        let record = h.encode();
        assert_eq!(FaultHistory::decode(&record), Ok(h));
        let other: heapless::Vec<u8, FAULTS_RECORD> = [9].iter().chain(record.iter().skip(1)).copied().collect();
        assert_eq!(FaultHistory::decode(&other), Err(DecodeError::Format(9)));
        let short = record.split_last().map_or(&[][..], |(_, r)| r);
        assert_eq!(FaultHistory::decode(short), Err(DecodeError::Length));
        assert_eq!(FaultHistory::decode(&[FAULTS_FORMAT, 0]), Err(DecodeError::Length));
    }

    #[test]
    fn a_booted_history_shows_and_only_a_new_alarm_asks_for_a_save() {
        use crate::faults::Inputs;
        use crate::{DriveConfig, Instant};
        let hot = Inputs { temperature_c: Some(100), ..Inputs::default() };
        // A full history: the new alarm pushes the oldest out.
        let mut h = FaultHistory { count: 12, ..FaultHistory::default() };
        for (k, e) in h.entries.iter_mut().enumerate() {
            *e = (10 + k as u32) << 24 | (100 - k as u32);
        }
        let mut p = Params::factory();
        p.set_fault_history(&h);
        assert_eq!(p.fault_history(), h);
        let mut drive = Drive::boot(DriveConfig { can_save: true, ..DriveConfig::default() }, &p, 0);
        assert_eq!(drive.state().fault_history(), h);
        assert!(!drive.has_system_request());
        assert_eq!(Job::take(&mut drive), None, "what was loaded is saved already");
        drive.tick_with(Instant::from_micros(1_000_000), &hot);
        assert!(drive.has_system_request());
        let job = Job::take(&mut drive);
        let mut want = FaultHistory { count: 13, ..FaultHistory::default() };
        for (w, e) in want.entries.iter_mut().zip([15 << 24 | 10].iter().chain(&h.entries)) {
            *w = *e;
        }
        assert_eq!(job, Some(Job::SaveFaults(want)));
        assert_eq!(job.map(|j| j.request()), Some(SystemRequest::SaveFaults));
        assert_eq!(Job::take(&mut drive), None, "once");
        // A partial history fills up from where it ended; without storage nothing is asked.
        let short = FaultHistory { entries: [13 << 24 | 7, 11 << 24 | 3, 0, 0, 0, 0, 0, 0, 0, 0], count: 2 };
        p.set_fault_history(&short);
        let mut drive = Drive::boot(DriveConfig::default(), &p, 0);
        drive.tick_with(Instant::from_micros(500_000), &hot);
        let shown = drive.state().fault_history();
        let entries = [15 << 24 | 5, 13 << 24 | 7, 11 << 24 | 3, 0, 0, 0, 0, 0, 0, 0];
        assert_eq!(shown, FaultHistory { entries, count: 3 });
        assert!(!drive.has_system_request());
        assert_eq!(drive.take_system_request(), None);
    }

    /// A program's records hold its words high byte first, 256 bytes a chunk, each with the
    /// CRC-16 of all of them, as a program kept in the PVT table's bytes was saved: a program
    /// saved before it had a memory of its own loads unchanged.
    #[test]
    fn a_program_record_holds_its_words_high_byte_first() {
        let memory = ProgramMemory::new();
        for k in 0..PROGRAM_WORDS {
            memory.set_word(k, (k as u16).wrapping_mul(0x0101).wrapping_add(0x1234));
        }
        let bytes: heapless::Vec<u8, { 2 * PROGRAM_WORDS }> =
            (0..PROGRAM_WORDS).flat_map(|k| memory.word(k).unwrap_or(0).to_be_bytes()).collect();
        let crc = crate::crc::crc16(&bytes);
        let record = Record::Program { memory: &memory, bank: 1, crc: program_crc(&memory) };
        assert_eq!(program_crc(&memory), crc);
        let mut out = [0u8; RECORD];
        for k in 0..PROGRAM_CHUNKS {
            let start = k * PROGRAM_CHUNK;
            let n = PROGRAM_CHUNK.min(bytes.len() - start);
            let key = PROGRAM_KEYS.start + PROGRAM_CHUNKS as u8 + k as u8;
            assert_eq!(record.encode(k, &mut out), Some((key, 4 + n)));
            let [lo, hi] = crc.to_le_bytes();
            assert_eq!(out[..4], [PROGRAM_FORMAT, k as u8, lo, hi]);
            assert_eq!(out.get(4..4 + n), bytes.get(start..start + n));
        }
        assert_eq!(record.encode(PROGRAM_CHUNKS, &mut out), Some((PROGRAM_COMMIT_KEY, 4)));
    }

    #[test]
    fn read_only_and_ram_objects_are_not_saved() {
        let mut p = Params::factory();
        assert!(!p.set(Obj::SavedPosition, 5), "0x6055 has its own record");
        assert!(!p.set(Obj::MaxSpeed, 5), "RAM");
        assert!(!p.set(Obj::StorageStatus, 1), "live");
        assert!(!p.set(Obj::NodeId, 0), "out of range");
    }
}
