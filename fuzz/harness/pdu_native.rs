//! Well-formed request frames built from fuzz bytes, sent to a drive with the native map: most
//! executions get past the CRC and the parser into the dictionary's reads and writes (a stream of
//! random bytes seldom does).
//!
//! The input is a config byte (bit 0: the platform can save) and then records
//! `[ctl, len, pdu..]`, each sent as one frame, whole and with its CRC, after a silence. `ctl`:
//!
//! - bits 0-1: the address: 0 and 1 this drive, 2 broadcast, 3 another drive;
//! - bit 2: aim: the register address(es) become an object's (high or low word), so that writes
//!   reach the dictionary rather than holes in it;
//! - bit 3: fix the quantities and byte counts to the data given (reads 1..=125 registers);
//! - bits 4-6: before the frame, 0/1/20/200 control ticks (50 µs each), or 100 ms or 10 s of
//!   silence without ticks (6 and 7 as 0);
//! - bit 7: a save the drive asks for fails.
//!
//! The oracle, besides the shape of every reply ([`oracle::check_reply`]): a frame to this drive
//! is answered unless it is an exception code or listen-only mode is on or starts (tracked from
//! the spec's diagnostics); a frame to another drive, or one the drive must ignore, changes
//! nothing readable; neither do an exception reply (writes are all or nothing), a read or any
//! other request that is not a write. Reads (0x03, 0x04, the read of 0x17) return what the object
//! declarations say each register holds, within a page, or exception 02 outside it; a written
//! setting that stores its value reads back as written.

use super::oracle::{self, ADDR, be16};
use drive_core::control::TICK_MICROS;
use drive_core::od::{Access, OBJECTS, Obj, Storage, Type};
use drive_core::{Drive, DriveConfig, Instant, SystemRequest};
use std::sync::OnceLock;

/// t3.5 at the factory 9600 baud.
const T35: u64 = 4010;

/// A factory drive, built once per configuration: each execution clones it.
fn factory(can_save: bool) -> Drive {
    static DRIVES: [OnceLock<Drive>; 2] = [OnceLock::new(), OnceLock::new()];
    DRIVES[usize::from(can_save)].get_or_init(|| Drive::new(DriveConfig { can_save, ..DriveConfig::default() })).clone()
}

/// Everything the objects show.
fn snapshot(drive: &Drive) -> (Vec<u32>, i64) {
    let s = drive.state();
    (OBJECTS.iter().filter(oracle::compared).map(|d| s.read_def(d)).collect(), s.position())
}

/// The word register `reg` shows by the object declarations: 0 where no object is.
fn declared(drive: &Drive, reg: usize) -> u16 {
    let i = OBJECTS.partition_point(|d| d.end() as usize <= reg);
    let Some(d) = OBJECTS.get(i).filter(|d| usize::from(d.addr) <= reg && d.obj != Obj::Password) else {
        // A reserved register, or the password, which is not told.
        return 0;
    };
    let k = reg - usize::from(d.addr);
    let v = drive.state().read_def(d);
    match d.ty() {
        Type::Str(_) => drive.state().text_word(d.obj, k),
        Type::U32 | Type::S32 if k == 0 => (v >> 16) as u16,
        _ => v as u16,
    }
}

/// What reading `qty` registers from `addr` returns: within one page (the registers sharing the
/// high byte of an object's address), from the page's first object to the end of its last.
fn read_model(drive: &Drive, addr: usize, qty: usize) -> Result<Vec<u16>, u8> {
    if !(1..=125).contains(&qty) {
        return Err(3);
    }
    let end = addr + qty;
    // The capture windows: the scope's and the black box's, 8192 registers each.
    use drive_core::state::recording::{BLACK_BOX_WINDOW, SCOPE_WINDOW};
    const WORDS: usize = drive_core::scope::WORDS;
    for (window, black_box) in [(usize::from(SCOPE_WINDOW), false), (usize::from(BLACK_BOX_WINDOW), true)] {
        if (window..window + WORDS).contains(&addr) {
            let words = (addr..end).map(|r| drive.state().capture_word(black_box, r - window));
            return if end <= window + WORDS { Ok(words.map(|w| w.unwrap_or(0)).collect()) } else { Err(2) };
        }
    }
    let page: Vec<_> = OBJECTS.iter().filter(|d| usize::from(d.addr) >> 8 == addr >> 8).collect();
    match (page.first(), page.last()) {
        (Some(first), Some(last)) if usize::from(first.addr) <= addr && end <= last.end() as usize => {
            Ok((addr..end).map(|r| declared(drive, r)).collect())
        }
        _ => Err(2),
    }
}

/// What a frame does, by the spec's diagnostics and listen-only mode.
#[derive(Debug, PartialEq)]
enum Expect {
    /// Not for this drive, or nothing may execute: no reply and nothing changes.
    Ignored,
    /// No reply; a write may execute (broadcast).
    Silent,
    /// A reply, normal or exception.
    Reply,
}

struct Harness {
    drive: Drive,
    now: u64,
    listen_only: bool,
    save_fails: bool,
}

impl Harness {
    fn expect(&mut self, to: u8, pdu: &[u8]) -> Expect {
        if (to != ADDR && to != 0) || pdu.is_empty() || pdu[0] & 0x80 != 0 {
            return Expect::Ignored;
        }
        let sub = (pdu[0] == 0x08 && pdu.len() >= 3).then(|| be16(pdu, 1));
        let data = pdu.get(3..).unwrap_or_default();
        let restart = sub == Some(0x01) && (data == [0, 0] || data == [0xFF, 0]);
        let listen = sub == Some(0x04) && data == [0, 0];
        if self.listen_only {
            self.listen_only = !restart;
            return Expect::Ignored;
        }
        if to == 0 || listen {
            self.listen_only = listen;
            return if matches!(pdu[0], 0x06 | 0x10) { Expect::Silent } else { Expect::Ignored };
        }
        Expect::Reply
    }

    /// Serves what the drive asks of its platform: a save ends at once.
    fn serve_platform(&mut self) {
        if let Some(SystemRequest::Save) = self.drive.take_system_request() {
            self.drive.save_done(!self.save_fails);
        }
    }

    fn wait(&mut self, how: u8) {
        let ticks = match how {
            1 => 1,
            2 => 20,
            3 => 200,
            _ => 0,
        };
        self.now += match how {
            4 => 100_000,
            5 => 10_000_000,
            _ => 0,
        };
        for _ in 0..ticks {
            self.now += TICK_MICROS;
            let _ = self.drive.tick(Instant::from_micros(self.now));
            self.serve_platform();
        }
    }

    fn request(&mut self, ctl: u8, pdu: &[u8]) {
        let to = [ADDR, ADDR, 0, 2][usize::from(ctl & 3)];
        self.save_fails = ctl & 0x80 != 0;
        self.wait((ctl >> 4) & 7);
        let mut body = vec![to];
        body.extend_from_slice(pdu);
        let frame = oracle::seal(&body);
        let before = snapshot(&self.drive);
        // The frame arrives whole after a silence, and ends t3.5 later.
        self.now += 1;
        self.drive.on_rx(Instant::from_micros(self.now), &frame);
        self.drive.on_timer(Instant::from_micros(self.now + T35 - 1));
        assert_eq!(self.drive.take_reply(), None, "a reply before t3.5 to {frame:02X?}");
        self.now += T35;
        self.drive.on_timer(Instant::from_micros(self.now));
        assert_eq!(self.drive.deadline(), None, "a frame in progress after {frame:02X?}");
        let reply = self.drive.take_reply().map(<[u8]>::to_vec);
        let expect = self.expect(to, pdu);
        let unchanged = |h: &Self, why: &str| {
            assert!(snapshot(&h.drive) == before, "{why} changed the drive: {frame:02X?}");
        };
        let reply = match (expect, reply) {
            (Expect::Reply, Some(reply)) => reply,
            (Expect::Reply, None) => panic!("no reply to {frame:02X?}"),
            (e, Some(reply)) => panic!("reply {reply:02X?} to {frame:02X?} ({e:?})"),
            (Expect::Ignored, None) => return unchanged(self, "a frame to ignore"),
            (Expect::Silent, None) => return,
        };
        let exception = oracle::check_reply(&frame, &reply);
        let f = pdu[0];
        if exception || !matches!(f, 0x06 | 0x10 | 0x17) {
            unchanged(self, if exception { "an exception" } else { "a request that writes nothing" });
        }
        match f {
            0x03 | 0x04 => {
                let expected =
                    if pdu.len() == 5 { read_model(&self.drive, be16(pdu, 1), be16(pdu, 3)) } else { Err(3) };
                match expected {
                    Err(code) => assert_eq!(reply[1..3], [f | 0x80, code], "reply {reply:02X?} to {frame:02X?}"),
                    Ok(words) => assert_eq!(reply[3..reply.len() - 2], words_bytes(&words), "reply to {frame:02X?}"),
                }
            }
            0x17 if !exception => {
                let words = read_model(&self.drive, be16(pdu, 1), be16(pdu, 3));
                assert_eq!(Ok(reply[3..reply.len() - 2].to_vec()), words.map(|w| words_bytes(&w)), "{frame:02X?}");
            }
            0x17 if well_formed_rw(pdu) => {
                if let Err(code) = read_model(&self.drive, be16(pdu, 1), be16(pdu, 3)) {
                    assert_eq!(reply[2], code, "reply {reply:02X?} to {frame:02X?}");
                }
            }
            0x06 if !exception => self.reads_back(be16(pdu, 1), &pdu[3..5]),
            0x10 if !exception => self.reads_back(be16(pdu, 1), &pdu[6..]),
            _ => {}
        }
    }

    /// After a successful write of `values` from `addr` that wrote one object whole: if it is a
    /// setting that stores its value (read-write, in RAM or ROM; 0x200F runs a command), it holds
    /// the value written. (Within one write a later object may change an earlier one: a negative
    /// 0x6003 sets the direction 0x6002.)
    fn reads_back(&self, addr: usize, values: &[u8]) {
        let end = addr + values.len() / 2;
        let covered: Vec<_> =
            OBJECTS.iter().filter(|d| usize::from(d.addr) >= addr && d.end() as usize <= end).collect();
        if let [d] = covered[..]
            && d.access() == Access::Rw
            && matches!(d.storage(), Storage::Ram | Storage::Rom)
            && d.obj != Obj::SystemControl
        {
            let at = 2 * (usize::from(d.addr) - addr);
            let written = values[at..at + 2 * usize::from(d.words())].iter().fold(0u32, |v, &b| v << 8 | u32::from(b));
            let got = self.drive.state().read_def(d);
            assert_eq!(got, written, "{:?} at {:#06X} after writing {values:02X?} from {addr:#06X}", d.obj, d.addr);
        }
    }
}

fn words_bytes(words: &[u16]) -> Vec<u8> {
    words.iter().flat_map(|w| w.to_be_bytes()).collect()
}

/// Whether a 0x17 PDU parses: read 1..=125, write 1..=121 with the byte count and data to match.
fn well_formed_rw(pdu: &[u8]) -> bool {
    pdu.len() >= 10 && {
        let (rq, wq, count) = (be16(pdu, 3), be16(pdu, 7), usize::from(pdu[9]));
        (1..=125).contains(&rq) && (1..=121).contains(&wq) && count == 2 * wq && pdu.len() == 10 + count
    }
}

/// Points the register address at `at` to an object (its first or last register).
fn aim(pdu: &mut [u8], at: usize) {
    let w = be16(pdu, at);
    let d = &OBJECTS[w % OBJECTS.len()];
    let reg = d.addr + if w & 0x8000 != 0 { d.words() - 1 } else { 0 };
    pdu[at..at + 2].copy_from_slice(&reg.to_be_bytes());
}

/// Builds the PDU of a record: `raw` with the edits `ctl` asks for, at most 253 bytes.
fn build(ctl: u8, raw: &[u8]) -> Vec<u8> {
    let mut pdu = raw[..raw.len().min(253)].to_vec();
    let Some(&f) = pdu.first() else { return pdu };
    let need = match f {
        0x03 | 0x04 | 0x06 | 0x10 => 5,
        0x17 => 9,
        _ => 0,
    };
    if ctl & 0x0C != 0 && pdu.len() < need {
        pdu.resize(need, 0);
    }
    if ctl & 4 != 0 && need > 0 {
        aim(&mut pdu, 1);
        if f == 0x17 {
            aim(&mut pdu, 5);
        }
    }
    if ctl & 8 != 0 {
        let put = |pdu: &mut Vec<u8>, at: usize, v: usize| pdu[at..at + 2].copy_from_slice(&(v as u16).to_be_bytes());
        match f {
            0x03 | 0x04 => {
                pdu.truncate(5);
                let q = be16(&pdu, 3);
                put(&mut pdu, 3, 1 + q % 125);
            }
            0x06 => pdu.truncate(5),
            0x10 => {
                let qty = (pdu.len().saturating_sub(6) / 2).clamp(1, 123);
                pdu.resize(6 + 2 * qty, 0);
                put(&mut pdu, 3, qty);
                pdu[5] = (2 * qty) as u8;
            }
            0x17 => {
                let qty = (pdu.len().saturating_sub(10) / 2).clamp(1, 121);
                pdu.resize(10 + 2 * qty, 0);
                let q = be16(&pdu, 3);
                put(&mut pdu, 3, 1 + q % 125);
                put(&mut pdu, 7, qty);
                pdu[9] = (2 * qty) as u8;
            }
            0x2B => {
                pdu.resize(4, 0);
                pdu[1] = 0x0E;
            }
            _ => {}
        }
    }
    pdu
}

/// One execution.
pub fn run(data: &[u8]) {
    let Some((&config, mut rest)) = data.split_first() else { return };
    let mut h = Harness { drive: factory(config & 1 != 0), now: 0, listen_only: false, save_fails: false };
    while let [ctl, len, tail @ ..] = rest {
        let (raw, next) = tail.split_at(usize::from(*len).min(tail.len()));
        rest = next;
        let pdu = build(*ctl, raw);
        h.request(*ctl, &pdu);
    }
}
