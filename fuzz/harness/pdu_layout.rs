//! Request frames to a drive whose map is a layout table (`drive_core::maps::layout`): low word
//! first, scaled units, vendor exception codes. The input is records `[ctl, len, pdu..]`, each
//! sent as one frame with its CRC after a silence; `ctl` bits 0-1 choose the function (0x03,
//! 0x06, 0x10, 0x17), bit 2 fixes the quantities and byte counts to the data given, bits 3-5 the
//! control ticks before the frame (0, 1, 20, 200, 2000).
//!
//! The oracle: every frame is answered (a normal reply or an exception of the layout's codes);
//! an exception changes nothing; a read returns its quantity of registers, each what the
//! layout's model of that register says (the object's value scaled, in the layout's word order).

use super::oracle;
use drive_core::maps::layout::{Entry, Exceptions, Layout, LayoutMap, Scale, SpoiltCodes, Walk, WordOrder};
use drive_core::od::{OBJECTS, Obj};
use drive_core::pdu::Exception;
use drive_core::{Drive, DriveConfig};

/// The layout's objects (shared with `drive-core/tests/layout_map.rs`).
pub static ENTRIES: [Entry; 10] = [
    Entry::new(0x0000, Obj::Mode, &Scale::One),
    Entry::new(0x0001, Obj::MaxSpeed, &Scale::PerRev(1, 10)),
    Entry::new(0x0003, Obj::AbsoluteMove, &Scale::One),
    Entry::new(0x0005, Obj::RelativeMove, &Scale::One),
    Entry::new(0x0007, Obj::Position, &Scale::One),
    Entry::new(0x0009, Obj::Microsteps, &Scale::One),
    Entry::new(0x000A, Obj::Enable, &Scale::One),
    Entry::new(0x000B, Obj::PhaseCurrent, &Scale::Ratio(100, 1)),
    Entry::new(0x000C, Obj::EncoderPosition, &Scale::One),
    Entry::new(0x000E, Obj::ControllerStatus, &Scale::One),
];

/// How a request walks [`ENTRIES`].
const WALK: Walk = Walk::Address;

/// The layout: low word first, vendor codes for the refusals.
pub static LAYOUT: Layout = Layout {
    entries: &ENTRIES,
    order: WordOrder::LowFirst,
    exceptions: Exceptions {
        unknown: Exception::IllegalDataAddress,
        read_only: Exception::Vendor(0x0B),
        out_of_range: Exception::IllegalDataValue,
        busy: Exception::Vendor(0x06),
        disabled: Exception::Vendor(0x0C),
        faulted: Exception::Vendor(0x0D),
        not_now: Exception::Vendor(0x0E),
        infeasible: Exception::Vendor(0x0F),
        unsupported: Exception::IllegalFunction,
        write_only: Exception::IllegalDataAddress,
        split: Exception::IllegalDataAddress,
        byte_count: Exception::IllegalDataValue,
        function: Exception::IllegalFunction,
    },
    walk: WALK,
    halves: true,
    spoilt: SpoiltCodes::DROPPED,
    defaults: &[],
    program: None,
    reserved: &[],
    sub_index: None,
    address: None,
    scope: false,
    index: Some(&INDEX),
};

/// The table's compiled lookup: the fuzzer reaches the plain reads and writes too.
static INDEX: drive_core::maps::compiled::Compiled = drive_core::compiled!(ENTRIES, WALK);

/// Every code the layout answers, and the request-level ones.
const CODES: [u8; 10] = [0x01, 0x02, 0x03, 0x04, 0x06, 0x0B, 0x0C, 0x0D, 0x0E, 0x0F];

/// t3.5 at the factory 9600 baud.
const T35: u64 = 4010;

fn snapshot(drive: &Drive<LayoutMap>) -> (Vec<u32>, i64) {
    let s = drive.state();
    (OBJECTS.iter().filter(oracle::compared).map(|d| s.read_def(d)).collect(), s.position())
}

/// What register `reg` reads as by the layout: `None` where the layout has no object.
fn model(drive: &Drive<LayoutMap>, reg: u32) -> Option<u16> {
    let e = ENTRIES
        .iter()
        .find(|e| (u32::from(e.addr)..u32::from(e.addr) + u32::from(e.obj.def().words())).contains(&reg))?;
    let d = e.obj.def();
    // The layout has no enumeration: its values are the drive's, scaled.
    let scaled = oracle::map_value(drive.state(), e) as u32;
    let k = reg - u32::from(e.addr);
    Some(if d.words() == 2 && k == 1 { (scaled >> 16) as u16 } else { scaled as u16 })
}

/// One execution.
pub fn run(data: &[u8]) {
    let mut drive = Drive::with_map(DriveConfig::default(), LayoutMap::new(&LAYOUT));
    let mut now = 0u64;
    oracle::requests(data, &mut drive, &mut now, |drive, now, ctl, mut pdu| {
        if ctl & 4 != 0 {
            oracle::fix_lengths(&mut pdu);
        }
        let before = snapshot(drive);
        let (frame, reply) = oracle::exchange(drive, now, T35, &pdu);
        if frame.len() > oracle::MAX_FRAME {
            return;
        }
        let Some(reply) = reply else { panic!("no reply to {frame:02X?}") };
        // The map's codes go beyond the Modbus four that `check_reply` knows.
        if oracle::vendor_exception(&frame, &reply, &CODES) {
            assert_eq!(snapshot(drive), before, "exception {:#04X} to {frame:02X?} changed the drive", reply[2]);
            return;
        }
        assert!(!oracle::check_reply(&frame, &reply), "{reply:02X?} to {frame:02X?}");
        if let [0x03, n, regs @ ..] = reply.get(1..reply.len() - 2).unwrap_or_default() {
            let (addr, qty) = (oracle::be16(&pdu, 1) as u32, oracle::be16(&pdu, 3));
            assert_eq!(usize::from(*n), 2 * qty, "byte count of {frame:02X?}");
            for (i, w) in regs.chunks(2).enumerate() {
                let got = u16::from_be_bytes([w[0], w[1]]);
                assert_eq!(Some(got), model(drive, addr + i as u32), "register {:#06X}", addr + i as u32);
            }
        }
    });
}
