//! Request frames to a drive answering through the servo map (seed 004,
//! `drive_core::maps::servo`): the parameter area with its reserved ranges, 32-bit values whole
//! and low word first, per-revolution units and the groups' gear, the communication IO and the
//! jogs (signals that act: servo-on, starts, jogs, homing), the position data groups' window.
//! The input is records as for `pdu_cls9`.
//!
//! The oracle: every frame is answered (a normal reply or one of the Modbus codes 1-4); an
//! exception changes nothing (the groups' words included); a read returns its quantity of
//! registers, each what a model of the layout written here says (the object's value in the
//! map's unit, 0 in a reserved range, a group's stored word).

use super::oracle;
use drive_core::maps::Maps;
use drive_core::maps::servo::{ENTRIES, LAYOUT};
use drive_core::od::OBJECTS;
use drive_core::{Drive, DriveConfig};

/// Every code the map answers.
const CODES: [u8; 4] = [0x01, 0x02, 0x03, 0x04];

/// t3.5 at the factory 9600 baud.
const T35: u64 = 4010;

/// The groups' window.
const GROUPS: u16 = 0x0600;
/// Its words.
const GROUP_WORDS: usize = drive_core::state::groups::WORDS;

/// Everything a refusal must leave as it was: every object but the current command (the
/// standstill current lowers it in time), and the groups.
fn snapshot(drive: &Drive<Maps>) -> (Vec<u32>, i64) {
    let s = drive.state();
    let groups = (0..GROUP_WORDS).map(|k| u32::from(s.program_word(k)));
    let objects = OBJECTS.iter().filter(oracle::compared).map(|d| s.read_def(d));
    (objects.chain(groups).collect(), s.position())
}

/// The registers a read of `qty` from `addr` gets, or `None` if one of them has no entry.
fn model(drive: &Drive<Maps>, addr: u16, qty: usize) -> Option<Vec<u16>> {
    if let Some(answer) = oracle::scope_model(drive, addr, qty) {
        return answer;
    }
    if let Some(k) = usize::from(addr).checked_sub(usize::from(GROUPS)).filter(|&k| k < GROUP_WORDS) {
        return (k + qty <= GROUP_WORDS).then(|| (k..k + qty).map(|j| drive.state().program_word(j)).collect());
    }
    let reserved = |reg: u32| LAYOUT.reserved.iter().find(|(a, b)| (u32::from(*a)..=u32::from(*b)).contains(&reg));
    if let Some(&(_, last)) = reserved(u32::from(addr)) {
        return (usize::from(addr) + qty <= usize::from(last) + 1).then(|| vec![0; qty]);
    }
    (0..qty as u32)
        .map(|k| {
            let reg = u32::from(addr) + k;
            let e = ENTRIES.iter().find(|e| (u32::from(e.addr)..u32::from(e.addr) + e.words()).contains(&reg))?;
            Some(oracle::entry_register(drive.state(), e, reg - u32::from(e.addr), false))
        })
        .collect()
}

/// One execution.
pub fn run(data: &[u8]) {
    let mut drive = Drive::with_map(DriveConfig::default(), Maps::servo());
    oracle::map_requests(data, &mut drive, &ENTRIES, &CODES, T35, snapshot, model);
}
