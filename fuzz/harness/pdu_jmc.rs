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
use drive_core::maps::layout::{FULL_STEPS_PER_REV, Scale, View};
use drive_core::od::{OBJECTS, Obj, Type};
use drive_core::{Drive, DriveConfig};

/// Every code the map answers, and the request-level ones.
const CODES: [u8; 9] = [0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0x0B];

/// t3.5 at the factory 9600 baud.
const T35: u64 = 4010;

fn snapshot(drive: &Drive<Maps>) -> (Vec<u32>, i64, drive_core::power::DeviceState) {
    let s = drive.state();
    (OBJECTS.iter().map(|d| s.read_def(d)).collect(), s.position(), s.device_state())
}

/// The registers a read of `qty` from `addr` gets by the list walk, or `None` if it cannot be
/// read (no entry starts there, the walk runs out or meets a write-only entry).
fn model(drive: &Drive<Maps>, addr: u16, qty: usize) -> Option<Vec<u16>> {
    let first = ENTRIES.iter().position(|e| e.addr == addr)?;
    let low_first = drive.state().read(Obj::MapWordOrder) == 1;
    let per_rev = FULL_STEPS_PER_REV * i64::from(drive.state().read(Obj::Microsteps).max(1));
    let mut out = Vec::new();
    for e in ENTRIES.get(first..)? {
        if out.len() >= qty {
            break;
        }
        if e.view == View::WriteOnly {
            return None;
        }
        let d = e.obj.def();
        if let Type::Str(n) = d.ty {
            out.extend((0..usize::from(n).div_ceil(2)).map(|k| drive.state().text_word(e.obj, k)));
            continue;
        }
        let raw = drive.state().read_def(d);
        let v = if d.ty == Type::S32 { i64::from(raw as i32) } else { i64::from(raw) };
        let m = match e.scale {
            Scale::One => v,
            Scale::Ratio(n, den) => round(v * i64::from(den), i64::from(n)),
            Scale::PerRev(n, den) => round(v * i64::from(den), i64::from(n) * per_rev),
            Scale::Table(choices) => choices.iter().find(|c| i64::from(c.drive) == v).map_or(v, |c| i64::from(c.lo)),
        } as u32;
        if e.narrow {
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

/// `n / d` to the nearest, halves away from zero.
fn round(n: i64, d: i64) -> i64 {
    if n >= 0 { (n + d / 2) / d } else { (n - d / 2) / d }
}

/// One execution.
pub fn run(data: &[u8]) {
    let mut drive = Drive::with_map(DriveConfig::default(), Maps::jmc());
    let mut now = 0u64;
    oracle::requests(data, &mut drive, &mut now, |drive, now, ctl, mut pdu| {
        if ctl & 0x40 != 0 && pdu.len() >= 3 {
            let e = &ENTRIES[usize::from(pdu[1]) % ENTRIES.len()];
            pdu[1..3].copy_from_slice(&e.addr.to_be_bytes());
        }
        if ctl & 4 != 0 {
            oracle::fix_lengths(&mut pdu);
        }
        let before = snapshot(drive);
        let expected = match pdu.as_slice() {
            [0x03, a, b, c, d] => {
                let qty = usize::from(u16::from_be_bytes([*c, *d]));
                (1..=125).contains(&qty).then(|| model(drive, u16::from_be_bytes([*a, *b]), qty))
            }
            _ => None,
        };
        let (frame, reply) = oracle::exchange(drive, now, T35, &pdu);
        if frame.len() > oracle::MAX_FRAME {
            return;
        }
        let Some(reply) = reply else { panic!("no reply to {frame:02X?}") };
        // The map's codes go beyond the Modbus four that `check_reply` knows.
        if oracle::vendor_exception(&frame, &reply, &CODES) {
            assert_eq!(snapshot(drive), before, "exception {:#04X} to {frame:02X?} changed the drive", reply[2]);
            assert!(!matches!(expected, Some(Some(_))), "a readable walk refused: {frame:02X?}");
            return;
        }
        assert!(!oracle::check_reply(&frame, &reply), "{reply:02X?} to {frame:02X?}");
        if let [0x03, n, regs @ ..] = reply.get(1..reply.len() - 2).unwrap_or_default() {
            let got: Vec<u16> = regs.chunks(2).map(|w| u16::from_be_bytes([w[0], w[1]])).collect();
            assert_eq!(usize::from(*n), 2 * got.len(), "byte count of {frame:02X?}");
            assert_eq!(Some(Some(got)), expected, "read {frame:02X?}");
        }
    });
}
