//! Request frames to a drive answering through the DS-CLS9 map (seed 002,
//! `drive_core::maps::cls9`): decimal registers walked by address with gaps, 32-bit values
//! whole and high word first, signed 16-bit speeds, per-revolution units, enumerations, the
//! control command 0323. The input is records `[ctl, len, pdu..]` as for `pdu_jmc`: `ctl` bits
//! 0-1 choose the function (0x03, 0x06, 0x10, 0x17), bit 2 fixes the quantities and byte counts
//! to the data given, bits 3-5 the control ticks before the frame, bit 6 takes the address from
//! the table (the data's first byte picks the entry).
//!
//! The oracle: every frame is answered (a normal reply or one of the Modbus codes 1-4); an
//! exception changes nothing (the program's registers included; 0176 reports a refused start's
//! segment in error); a read returns its quantity of
//! registers, each what a model of the address walk written here says (the object's value in
//! the map's unit, a program register's stored word).

use super::oracle;
use drive_core::maps::Maps;
use drive_core::maps::cls9::ENTRIES;
use drive_core::od::{OBJECTS, Obj};
use drive_core::state::memory::WORDS;
use drive_core::{Drive, DriveConfig};

/// Every code the map answers.
const CODES: [u8; 4] = [0x01, 0x02, 0x03, 0x04];

/// t3.5 at the factory 9600 baud.
const T35: u64 = 4010;

/// Everything a refusal must leave as it was: every object but 0176 (the segment in error, which
/// a start refused for the program's errors reports, as the manual has it), and the program.
fn snapshot(drive: &Drive<Maps>) -> (Vec<u32>, i64) {
    let s = drive.state();
    let program = (0..WORDS).map(|k| u32::from(s.program_word(k)));
    let objects =
        OBJECTS.iter().filter(|d| d.obj != Obj::ProgramErrorSegment).filter(oracle::compared).map(|d| s.read_def(d));
    (objects.chain(program).collect(), s.position())
}

/// The registers a read of `qty` from `addr` gets, or `None` if one of them has no entry.
fn model(drive: &Drive<Maps>, addr: u16, qty: usize) -> Option<Vec<u16>> {
    if let Some(answer) = oracle::scope_model(drive, addr, qty) {
        return answer;
    }
    // The program's window, 1024-1536: its words as stored, read whole or not at all.
    if let Some(k) = usize::from(addr).checked_sub(1024).filter(|&k| k < WORDS) {
        return (k + qty <= WORDS).then(|| (k..k + qty).map(|j| drive.state().program_word(j)).collect());
    }
    (0..qty as u32)
        .map(|k| {
            let reg = u32::from(addr) + k;
            let e = ENTRIES.iter().find(|e| (u32::from(e.addr)..u32::from(e.addr) + e.words()).contains(&reg))?;
            Some(oracle::entry_register(drive.state(), e, reg - u32::from(e.addr), true))
        })
        .collect()
}

/// One execution.
pub fn run(data: &[u8]) {
    let mut drive = Drive::with_map(DriveConfig::default(), Maps::cls9());
    oracle::map_requests(data, &mut drive, &ENTRIES, &CODES, T35, snapshot, model);
}
