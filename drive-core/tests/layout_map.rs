//! A second register layout over the same drive (`drive_core::maps::layout`): other addresses, low
//! word first, a speed in 0.1 rev/s, a current in 100 mA, other exception codes. It passes the
//! native map's transactional tests: half-writes stage and complete, multi-object writes are all
//! or nothing, and a refused request changes nothing.

mod common;

// The layout is the one the `pdu_layout` fuzz target drives.
#[allow(dead_code)]
#[path = "../../fuzz/harness/mod.rs"]
mod harness;

use common::frame;
use drive_core::maps::layout::LayoutMap;
use drive_core::od::{OBJECTS, Obj};
use drive_core::{Drive, DriveConfig, Instant};
use harness::pdu_layout::LAYOUT;

#[derive(Clone)]
struct Rig {
    drive: Drive<LayoutMap>,
    now: u64,
}

impl Rig {
    fn new() -> Self {
        let mut r = Self { drive: Drive::with_map(DriveConfig::default(), LayoutMap::new(&LAYOUT)), now: 0 };
        r.run(1_000);
        r
    }

    /// Lets `us` pass: control ticks, and the timer at the framer's deadline.
    fn run(&mut self, us: u64) -> Option<Vec<u8>> {
        let end = self.now + us;
        let mut reply = None;
        while self.now < end {
            self.now += 50;
            self.drive.tick(Instant::from_micros(self.now));
            if self.drive.deadline().is_some_and(|d| d.as_micros() <= self.now) {
                self.drive.on_timer(Instant::from_micros(self.now));
                if let Some(r) = self.drive.take_reply() {
                    assert!(reply.is_none(), "two replies");
                    reply = Some(r.to_vec());
                }
            }
        }
        reply
    }

    /// The reply's PDU, or the exception code.
    fn request(&mut self, pdu: &[u8]) -> Result<Vec<u8>, u8> {
        let mut body = vec![1];
        body.extend_from_slice(pdu);
        self.drive.on_rx(Instant::from_micros(self.now), &frame(&body));
        let Some(r) = self.run(10_000) else { panic!("no reply to {pdu:02X?}") };
        assert_eq!(r.first(), Some(&1));
        let pdu = r.get(1..r.len() - 2).unwrap_or_default().to_vec();
        match pdu.as_slice() {
            [f, code] if f & 0x80 != 0 => Err(*code),
            _ => Ok(pdu),
        }
    }

    fn write(&mut self, addr: u16, words: &[u16]) -> Result<(), u8> {
        let mut pdu = vec![0x10];
        pdu.extend(addr.to_be_bytes());
        pdu.extend((words.len() as u16).to_be_bytes());
        pdu.push(2 * words.len() as u8);
        for w in words {
            pdu.extend(w.to_be_bytes());
        }
        self.request(&pdu).map(|_| ())
    }

    fn write1(&mut self, addr: u16, w: u16) -> Result<(), u8> {
        let mut pdu = vec![0x06];
        pdu.extend(addr.to_be_bytes());
        pdu.extend(w.to_be_bytes());
        self.request(&pdu).map(|_| ())
    }

    fn read(&mut self, addr: u16, qty: u16) -> Result<Vec<u16>, u8> {
        let mut pdu = vec![0x03];
        pdu.extend(addr.to_be_bytes());
        pdu.extend(qty.to_be_bytes());
        let r = self.request(&pdu)?;
        Ok(r.get(2..).unwrap_or_default().chunks(2).map(|c| u16::from_be_bytes([c[0], c[1]])).collect())
    }

    fn get(&self, obj: Obj) -> i64 {
        let v = self.drive.state().read(obj);
        if obj.def().ty() == drive_core::od::Type::S32 { i64::from(v as i32) } else { i64::from(v) }
    }

    /// Every object's value and the position: equal snapshots mean nothing changed.
    fn snapshot(&self) -> (Vec<u32>, i64) {
        let st = self.drive.state();
        (OBJECTS.iter().filter(|d| !d.obj.is_diagnostic()).map(|d| st.read(d.obj)).collect(), st.position())
    }
}

/// A request of a test case.
type Write = fn(&mut Rig) -> Result<(), u8>;

/// -10 as the low and high words of a 32-bit value.
const MINUS_TEN: [u16; 2] = [0xFFF6, 0xFFFF];

#[test]
fn values_are_in_the_layouts_units_and_word_order() {
    let mut r = Rig::new();
    r.write1(0x0009, 16).unwrap();
    // 2.5 rev/s at 16 microsteps of 200 steps: 8000 microsteps a second; low word first.
    r.write(0x0001, &[25, 0]).unwrap();
    assert_eq!(r.get(Obj::MaxSpeed), 8000);
    assert_eq!(r.read(0x0001, 2), Ok(vec![25, 0]));
    r.write(0x0001, &MINUS_TEN).unwrap();
    assert_eq!(r.get(Obj::MaxSpeed), -3200);
    assert_eq!(r.read(0x0001, 2), Ok(MINUS_TEN.to_vec()));
    // 1.2 A as 12 hundreds of mA.
    r.write1(0x000B, 12).unwrap();
    assert_eq!(r.get(Obj::PhaseCurrent), 1200);
    assert_eq!(r.read(0x000B, 1), Ok(vec![12]));
}

#[test]
fn high_half_stages_low_half_commits() {
    let mut r = Rig::new();
    r.write1(0x0009, 16).unwrap();
    // Low word first: the high half is the second register; alone it is kept.
    r.write1(0x0002, 0xFFFF).unwrap();
    assert_eq!(r.get(Obj::MaxSpeed), 0);
    assert_eq!(r.read(0x0001, 2), Ok(vec![0, 0]));
    r.write1(0x0001, 0xFFF6).unwrap();
    assert_eq!(r.get(Obj::MaxSpeed), -3200);
    // A low half alone completes with the present high half.
    r.write1(0x0001, 0xFFFE).unwrap();
    assert_eq!(r.get(Obj::MaxSpeed), -640);
    // A refused completion keeps the staged half: a corrected low half then succeeds.
    r.write1(0x0002, 0x0001).unwrap(); // 65 536 × 320 pps: beyond 200 kpps
    let before = r.snapshot();
    assert_eq!(r.write1(0x0001, 0x0000), Err(3));
    assert_eq!(r.snapshot(), before);
    r.write1(0x0002, 0x0000).unwrap();
    r.write1(0x0001, 500).unwrap();
    assert_eq!(r.get(Obj::MaxSpeed), 160_000);
}

#[test]
fn a_write_of_several_objects_is_all_or_nothing() {
    let mut r = Rig::new();
    r.write1(0x0009, 16).unwrap();
    // Mode, speed and an absolute move in one request: the move takes the speed written before
    // it, and runs to its target.
    r.write(0x0000, &[0, 25, 0, 6400, 0]).unwrap();
    assert!(r.get(Obj::ControllerStatus) & 0x08 != 0, "moving");
    r.run(3_000_000);
    assert_eq!(r.drive.state().position(), 6400);
    assert_eq!(r.read(0x0007, 2), Ok(vec![6400, 0]));
    // A refused value at the end undoes the ones before it: the speed stays.
    let before = r.snapshot();
    assert_eq!(r.write(0x0009, &[32, 1, 99]), Err(3), "9.9 A is out of range");
    assert_eq!(r.snapshot(), before);
    // A move refused after its speed was taken: neither happens.
    assert_eq!(r.write(0x0001, &[0, 0, 100, 0]), Err(0x0E), "speed 0: not now");
    assert_eq!(r.snapshot(), before);
}

#[test]
fn refusals_answer_the_layouts_codes_and_change_nothing() {
    let mut r = Rig::new();
    r.write1(0x0009, 16).unwrap();
    r.write(0x0001, &[25, 0]).unwrap();
    let before = r.snapshot();
    let cases: [(&str, Write, u8); 4] = [
        ("no object", |r| r.write1(0x0020, 1), 0x02),
        ("read-only", |r| r.write(0x000C, &[1, 0]), 0x0B),
        ("out of range", |r| r.write1(0x0000, 7), 0x03),
        ("beyond the map's scale", |r| r.write(0x0001, &[0, 0x7FFF]), 0x03),
    ];
    for (what, write, code) in cases {
        assert_eq!(write(&mut r), Err(code), "{what}");
        assert_eq!(r.snapshot(), before, "{what} changed something");
    }
    assert_eq!(r.read(0x000F, 1), Err(0x02), "a read past the layout");
    // Disabled, then moving: the drive's reasons in this layout's codes.
    r.write1(0x000A, 0).unwrap();
    let before = r.snapshot();
    assert_eq!(r.write(0x0003, &[100, 0]), Err(0x0C));
    assert_eq!(r.snapshot(), before);
    r.write1(0x000A, 1).unwrap();
    r.write(0x0003, &[0x0000, 0x0001]).unwrap(); // 65 536 microsteps away
    let before_position = r.drive.state().position();
    assert_eq!(r.write(0x0007, &[0, 0]), Err(0x06), "setting the position while moving");
    assert!(r.drive.state().position() >= before_position);
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig::with_cases(300))]

    /// Any write to the layout, and any read: a refused write changes nothing, a read answers
    /// every register it covers or nothing.
    #[test]
    fn refused_writes_change_nothing(
        writes in proptest::collection::vec((0u16..16, proptest::collection::vec(proptest::num::u16::ANY, 1..6)), 1..12),
        read in (0u16..16, 1u16..16),
    ) {
        let mut r = Rig::new();
        r.write1(0x0009, 16).unwrap();
        for (addr, words) in &writes {
            // A twin that hears nothing while the request is served: a move under way goes on
            // in both.
            let (mut twin, start) = (r.clone(), r.now);
            let result = if words.len() == 1 { r.write1(*addr, words[0]) } else { r.write(*addr, words) };
            if result.is_err() {
                twin.run(r.now - start);
                proptest::prop_assert_eq!(r.snapshot(), twin.snapshot(), "{:?} at {:#06X}", words, addr);
            }
            r.run(1_000);
        }
        match r.read(read.0, read.1) {
            Ok(regs) => proptest::prop_assert_eq!(regs.len(), usize::from(read.1)),
            Err(code) => proptest::prop_assert_eq!(code, 0x02),
        }
    }
}
