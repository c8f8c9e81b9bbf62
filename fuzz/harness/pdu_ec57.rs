//! Request frames to a drive answering through the EC-57 map (seed 003,
//! `drive_core::maps::ec57`): the sub-index byte after the index, the table walked in (index,
//! sub-index) order, at most 16 registers, the native registers in the window (sub-index 0xFF),
//! the manual's exception codes. The input is records `[ctl, len, pdu..]` as for `pdu_jmc`:
//! `ctl` bits 0-1 choose the function (0x03, 0x06, 0x10, and 0x17, which the map does not
//! serve), bit 2 fixes the quantities and byte counts to the data given, bits 3-5 the control
//! ticks before the frame, bit 6 takes the index and sub-index from the table (the data's
//! first byte picks the entry), bit 7 from the native objects with the window's sub-index.
//!
//! The oracle: every frame is answered, with a normal reply in the manual's format (a read's
//! byte count and registers, a write's echo of index, sub-index and value or count) or one of
//! the codes 02-06; an exception changes nothing; a read of the table returns what a model of
//! the walk written here says (the object's value in the map's unit).

use super::oracle::{self, crc_ok, exchange, map_value, requests};
use drive_core::maps::Maps;
use drive_core::maps::ec57::{ENTRIES, MAX_REGISTERS, WINDOW_SUB, index_of, key};
use drive_core::od::{OBJECTS, Type};
use drive_core::{Drive, DriveConfig};

/// The map's codes.
const CODES: [u8; 5] = [0x02, 0x03, 0x04, 0x05, 0x06];

/// t3.5 at the factory 9600 baud.
const T35: u64 = 4010;

/// Everything a refusal must leave as it was: every object.
fn snapshot(drive: &Drive<Maps>) -> (Vec<u32>, i64) {
    let s = drive.state();
    (OBJECTS.iter().filter(oracle::compared).map(|d| s.read_def(d)).collect(), s.position())
}

/// The registers a read of `qty` from the table's `(index, sub)` gets, or `None` if there is no
/// entry there or the walk runs past the table's end.
fn model(drive: &Drive<Maps>, index: u16, sub: u8, qty: usize) -> Option<Vec<u16>> {
    if !(0x2000..=0x20FF).contains(&index) || sub > 15 {
        return None;
    }
    let first = ENTRIES.iter().position(|e| e.addr == key(index, sub))?;
    let walked = ENTRIES.get(first..first + qty)?;
    walked
        .iter()
        .map(|e| {
            if e.view() == drive_core::maps::layout::View::WriteOnly {
                return None;
            }
            let m = map_value(drive.state(), e);
            Some(if e.is_narrow() && e.obj.def().ty() == Type::S32 {
                m.clamp(i64::from(i16::MIN), i64::from(i16::MAX)) as i16 as u16
            } else if e.is_narrow() {
                (m as u32).min(0xFFFF) as u16
            } else {
                m as u16
            })
        })
        .collect()
}

/// Sets the quantity and byte count of `pdu` (function, index, sub-index, ...) to its data.
fn fix_lengths(pdu: &mut Vec<u8>) {
    match pdu.first() {
        Some(0x03) => pdu.resize(6, 0),
        Some(0x06) => pdu.resize(6, 0),
        Some(0x10) if pdu.len() >= 7 => {
            let values = (pdu.len() - 7) / 2;
            pdu.truncate(7 + 2 * values);
            pdu[4..6].copy_from_slice(&(values as u16).to_be_bytes());
            pdu[6] = (2 * values) as u8;
        }
        _ => {}
    }
}

/// One execution.
pub fn run(data: &[u8]) {
    let mut drive = Drive::with_map(DriveConfig::default(), Maps::ec57());
    let mut now = 0u64;
    requests(data, &mut drive, &mut now, |drive, now, ctl, mut pdu| {
        if pdu.len() >= 4 {
            let pick = usize::from(pdu[1]);
            if ctl & 0x40 != 0 {
                let (index, sub) = index_of(ENTRIES[pick % ENTRIES.len()].addr);
                pdu[1..3].copy_from_slice(&index.to_be_bytes());
                pdu[3] = sub;
            } else if ctl & 0x80 != 0 {
                pdu[1..3].copy_from_slice(&OBJECTS[pick % OBJECTS.len()].addr.to_be_bytes());
                pdu[3] = WINDOW_SUB;
            }
        }
        if ctl & 4 != 0 {
            fix_lengths(&mut pdu);
        }
        let before = snapshot(drive);
        let expected = match pdu.as_slice() {
            [0x03, ih, il, sub, qh, ql] => {
                let qty = usize::from(u16::from_be_bytes([*qh, *ql]));
                (1..=usize::from(MAX_REGISTERS))
                    .contains(&qty)
                    .then(|| model(drive, u16::from_be_bytes([*ih, *il]), *sub, qty))
            }
            _ => None,
        };
        let (frame, reply) = exchange(drive, now, T35, &pdu);
        if frame.len() > oracle::MAX_FRAME {
            return;
        }
        let Some(reply) = reply else { panic!("no reply to {frame:02X?}") };
        assert!(crc_ok(&reply) && reply[0] == frame[0], "{reply:02X?} to {frame:02X?}");
        if reply[1] & 0x80 != 0 {
            assert_eq!(reply.len(), 5, "exception {reply:02X?} to {frame:02X?}");
            assert_eq!(reply[1], frame[1] | 0x80, "{reply:02X?} answering {frame:02X?}");
            assert!(CODES.contains(&reply[2]), "code {:#04X} to {frame:02X?}", reply[2]);
            assert_eq!(snapshot(drive), before, "exception {:#04X} to {frame:02X?} changed the drive", reply[2]);
            assert!(!matches!(expected, Some(Some(_))), "a readable request refused: {frame:02X?}");
            return;
        }
        let body = &reply[1..reply.len() - 2];
        match pdu[0] {
            0x03 => {
                let qty = usize::from(u16::from_be_bytes([pdu[4], pdu[5]]));
                assert!((1..=usize::from(MAX_REGISTERS)).contains(&qty), "read of {qty}: {frame:02X?}");
                assert_eq!(body.len(), 2 + 2 * qty, "{reply:02X?} answering {frame:02X?}");
                assert_eq!(usize::from(body[1]), 2 * qty);
                if let Some(Some(want)) = expected {
                    let got: Vec<u16> = body[2..].chunks(2).map(|w| u16::from_be_bytes([w[0], w[1]])).collect();
                    assert_eq!(got, want, "read {frame:02X?}");
                }
            }
            0x06 => assert_eq!(reply, frame, "0x06 is echoed"),
            0x10 => assert_eq!(body, &pdu[..6], "0x10 echoes index, sub-index and count: {frame:02X?}"),
            f => panic!("function {f:#04X} served: {frame:02X?}"),
        }
    });
}
