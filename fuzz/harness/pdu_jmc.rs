//! Request frames to a drive answering through the JMC map (seed 001, `drive_core::maps::jmc`):
//! registers walked in §8's list order, 32-bit values whole and in the word order of 0x6000,
//! enumerations and per-revolution units, JMC's exception codes. The input is records
//! `[ctl, len, pdu..]`, each sent as one frame with its CRC after a silence: `ctl` bits 0-1
//! choose the function (0x03, 0x06, 0x10, 0x17), bit 2 fixes the quantities and byte counts to
//! the data given, bits 3-5 the control ticks before the frame (0, 1, 20, 200, 2000), bit 6
//! takes the address from the table (the data's first byte picks the entry).
//!
//! The oracle: every frame is answered (a normal reply or an exception of the map's codes); an
//! exception changes nothing; a read returns its quantity of registers, each what a model of
//! the list walk written here says (the object's value in the map's unit and word order).

use super::oracle;
use drive_core::maps::Maps;
use drive_core::maps::jmc::ENTRIES;
use drive_core::maps::layout::View;
use drive_core::od::{OBJECTS, Obj, Type};
use drive_core::{Drive, DriveConfig};

/// Every code the map answers, and the request-level ones.
const CODES: [u8; 9] = [0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0x0B];

/// t3.5 at the factory 9600 baud.
const T35: u64 = 4010;

fn snapshot(drive: &Drive<Maps>) -> (Vec<u32>, i64, drive_core::power::DeviceState) {
    let s = drive.state();
    (OBJECTS.iter().filter(oracle::compared).map(|d| s.read_def(d)).collect(), s.position(), s.device_state())
}

/// The registers a read of `qty` from `addr` gets by the list walk, or `None` if it cannot be
/// read (no entry starts there, the walk runs out or meets a write-only entry).
fn model(drive: &Drive<Maps>, addr: u16, qty: usize) -> Option<Vec<u16>> {
    if let Some(answer) = oracle::scope_model(drive, addr, qty) {
        return answer;
    }
    let first = ENTRIES.iter().position(|e| e.addr == addr)?;
    let low_first = drive.state().read(Obj::MapWordOrder) == 1;
    let mut out = Vec::new();
    for e in ENTRIES.get(first..)? {
        if out.len() >= qty {
            break;
        }
        if e.view() == View::WriteOnly {
            return None;
        }
        let d = e.obj.def();
        if let Type::Str(n) = d.ty() {
            out.extend((0..usize::from(n).div_ceil(2)).map(|k| drive.state().text_word(e.obj, k)));
            continue;
        }
        let m = oracle::map_value(drive.state(), e) as u32;
        if e.is_narrow() {
            out.push(m.min(0xFFFF) as u16);
        } else if d.words() == 1 {
            out.push(m as u16);
        } else if low_first {
            out.extend([m as u16, (m >> 16) as u16]);
        } else {
            out.extend([(m >> 16) as u16, m as u16]);
        }
    }
    (out.len() >= qty).then(|| out[..qty].to_vec())
}

/// One execution.
pub fn run(data: &[u8]) {
    let mut drive = Drive::with_map(DriveConfig::default(), Maps::jmc());
    oracle::map_requests(data, &mut drive, &ENTRIES, &CODES, T35, snapshot, model);
}
