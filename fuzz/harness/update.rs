//! The firmware update's requests (0x15 write file record, the install and abort orders) from
//! fuzz bytes, against a drive that takes the simulator's images, its platform writing the DFU
//! slot as it is asked: records in order, out of order, repeated, overlapping, past the end,
//! corrupted, malformed requests and garbage.
//!
//! The input is a sequence of operations, each a byte `op % 8` and its arguments:
//!
//! - 0 `k`: record `k` of a signed image (of the few it is sent in);
//! - 1 `k at xor`: record `k` with a byte changed;
//! - 2 `file record n data..`: `n` registers (at most 120) of the given bytes at file
//!   `file % 4` (0 is no file), record `record`;
//! - 3 `n bytes..`: a 0x15 request of those bytes after its function code, as they come;
//! - 4 `v`: 0x2256 = `v % 4` (1 abort, 2 install, 3 out of range);
//! - 5 `f`: the platform does the flash jobs asked for (the first fails if `f` is odd);
//! - 6 `j k`: records `j` and `k` in one request;
//! - 7: a broadcast of record 0.
//!
//! The oracle: every reply is a well-formed answer or exception; a refused record (02, 04)
//! changes nothing of the transfer; the flash is only written where the transfer's contract says
//! (whole double words, each once between erases, ascending within a transfer); and nothing is
//! marked for boot (the install job) unless the slot holds the signed image, program and
//! trailer, as [`check_slot`] reads it.

use super::oracle::{self, ADDR};
use drive_core::update::{self, Board, Header, Job, PAGE, SLOT_LEN, Status, TEST_KEY, Target, check_slot};
use drive_core::{Drive, DriveConfig};
use std::sync::OnceLock;

const TARGET: Target = Target { board: Board::Simulator, key: TEST_KEY, store: 1 };
/// t3.5 at the factory 9600 baud.
const T35: u64 = 4010;
const RECORD: usize = 244;

/// The signed image: a program of 700 bytes, version 2.0.0.
fn image() -> &'static [u8] {
    static IMAGE: OnceLock<Vec<u8>> = OnceLock::new();
    IMAGE.get_or_init(|| {
        use ed25519_dalek::Signer as _;
        let secret = update::key_from_hex(include_str!("../../keys/test.key")).unwrap_or([0; 32]);
        let key = ed25519_dalek::SigningKey::from_bytes(&secret);
        let program: Vec<u8> = (0..700u32).map(|i| (i * 13 + 5) as u8).collect();
        let header = Header { board: Board::Simulator, version: 0x0002_0000, length: 700, store: 1 };
        let mut bytes = header.to_bytes().to_vec();
        bytes.extend_from_slice(&program);
        let signature = key.sign(&update::digest(&bytes));
        bytes.extend_from_slice(&signature.to_bytes());
        bytes
    })
}

/// Record `k` of the image: its offset and bytes.
fn record(k: usize) -> (u32, Vec<u8>) {
    let img = image();
    let n = img.len().div_ceil(RECORD);
    let at = (k % n) * RECORD;
    let mut data = img[at..(at + RECORD).min(img.len())].to_vec();
    if data.len() % 2 == 1 {
        data.push(0);
    }
    (at as u32, data)
}

/// One sub-request of a 0x15 request.
fn sub(file: u16, record: u16, data: &[u8]) -> Vec<u8> {
    let mut s = vec![6];
    s.extend_from_slice(&file.to_be_bytes());
    s.extend_from_slice(&record.to_be_bytes());
    s.extend_from_slice(&((data.len() / 2) as u16).to_be_bytes());
    s.extend_from_slice(data);
    s
}

/// A 0x15 request of `subs`.
fn request(subs: &[Vec<u8>]) -> Vec<u8> {
    let body: Vec<u8> = subs.concat();
    let mut pdu = vec![0x15, body.len() as u8];
    pdu.extend_from_slice(&body);
    pdu
}

fn at(offset: u32) -> (u16, u16) {
    let reg = offset / 2;
    ((reg / 10_000 + 1) as u16, (reg % 10_000) as u16)
}

/// The platform's DFU slot.
struct Slot {
    bytes: Vec<u8>,
    erased: Option<u32>,
    end: u32,
}

impl Slot {
    fn write(&mut self, offset: u32, bytes: &[u8]) {
        assert_eq!(bytes.len() % update::WRITE_UNIT, 0, "a write of {} bytes", bytes.len());
        assert_eq!(offset as usize % update::WRITE_UNIT, 0, "a write at {offset}");
        assert!(offset == 0 || offset >= self.end, "a write at {offset} after one to {}", self.end);
        assert!(offset as usize + bytes.len() <= SLOT_LEN as usize, "past the slot");
        if offset == 0 {
            self.erased = None;
        }
        for (a, &b) in (offset..).zip(bytes) {
            let page = a / PAGE;
            if self.erased != Some(page) {
                self.bytes[(page * PAGE) as usize..((page + 1) * PAGE) as usize].fill(0xFF);
                self.erased = Some(page);
            }
            assert_eq!(self.bytes[a as usize], 0xFF, "a byte at {a} written twice");
            self.bytes[a as usize] = b;
        }
        self.end = offset + bytes.len() as u32;
    }

    fn check(&self) -> Result<Header, update::Refusal> {
        let read = |at: u32, buf: &mut [u8]| match self.bytes.get(at as usize..at as usize + buf.len()) {
            Some(b) => {
                buf.copy_from_slice(b);
                true
            }
            None => false,
        };
        check_slot(read, &TARGET)
    }
}

fn status(drive: &Drive) -> Status {
    drive.state().transfer().status()
}

/// The platform's flash jobs; the first fails if `fail`.
fn serve(drive: &mut Drive, slot: &mut Slot, mut fail: bool) {
    loop {
        let (t, _) = drive.state_mut().transfer_mut();
        let ok = match t.job() {
            Some(Job::Write { offset, bytes }) if !fail => {
                slot.write(offset, bytes);
                true
            }
            Some(Job::Install) => {
                let header = slot.check().expect("marked for boot: the slot does not check");
                let img = image();
                assert_eq!(&slot.bytes[..700], &img[32..732], "marked for boot: another program");
                assert_eq!(header.version, 0x0002_0000);
                true
            }
            Some(_) => false,
            None => return,
        };
        fail = false;
        t.done(ok);
    }
}

pub fn run(data: &[u8]) {
    static FACTORY: OnceLock<Drive> = OnceLock::new();
    let mut drive = FACTORY
        .get_or_init(|| {
            let mut d = Drive::new(DriveConfig::default());
            d.state_mut().set_updates(Some(TARGET), 1);
            d
        })
        .clone();
    let mut slot = Slot { bytes: vec![0xFF; (SLOT_LEN + PAGE) as usize], erased: None, end: 0 };
    let mut now = 0u64;
    let mut rest = data;
    let mut take = || -> Option<u8> {
        let (&b, tail) = rest.split_first()?;
        rest = tail;
        Some(b)
    };
    while let Some(op) = take() {
        let mut arg = || take().unwrap_or(0);
        let pdu = match op % 8 {
            0 => {
                let (off, data) = record(usize::from(arg()));
                let (f, r) = at(off);
                request(&[sub(f, r, &data)])
            }
            1 => {
                let (off, mut data) = record(usize::from(arg()));
                let i = usize::from(arg()) % data.len();
                data[i] ^= arg().max(1);
                let (f, r) = at(off);
                request(&[sub(f, r, &data)])
            }
            2 => {
                let file = u16::from(arg() % 4);
                let rec = u16::from_be_bytes([arg(), arg()]);
                let n = usize::from(arg() % 121);
                let data: Vec<u8> = (0..2 * n).map(|_| arg()).collect();
                request(&[sub(file, rec, &data)])
            }
            3 => {
                let n = usize::from(arg());
                let mut pdu = vec![0x15];
                pdu.extend((0..n).map(|_| arg()));
                pdu
            }
            4 => vec![0x06, 0x22, 0x56, 0, arg() % 4],
            5 => {
                serve(&mut drive, &mut slot, arg() % 2 == 1);
                continue;
            }
            6 => {
                let ((oj, dj), (ok, dk)) = (record(usize::from(arg())), record(usize::from(arg())));
                // Both within a request's 251 bytes: the first record's head only.
                let (fj, rj) = at(oj);
                let (fk, rk) = at(ok);
                let short = &dj[..dj.len().min(110)];
                let short_k = &dk[..dk.len().min(110)];
                request(&[sub(fj, rj, short), sub(fk, rk, short_k)])
            }
            _ => {
                let (off, data) = record(0);
                let (f, r) = at(off);
                let mut frame = vec![0];
                frame.extend_from_slice(&request(&[sub(f, r, &data)]));
                let before = status(&drive);
                now += T35;
                drive.on_rx(drive_core::Instant::from_micros(now), &oracle::seal(&frame));
                now += T35 + 1;
                drive.on_timer(drive_core::Instant::from_micros(now));
                assert!(drive.take_reply().is_none(), "a broadcast answered");
                assert_eq!(status(&drive), before, "a broadcast 0x15 taken");
                continue;
            }
        };
        let before = status(&drive);
        let (frame, reply) = oracle::exchange(&mut drive, &mut now, T35, &pdu);
        if frame.len() > drive_core::rtu::MAX_FRAME {
            continue;
        }
        let reply = reply.unwrap_or_else(|| panic!("no reply to {frame:02X?}"));
        assert_eq!(reply[0], ADDR);
        let exception = oracle::check_reply(&frame, &reply);
        let after = status(&drive);
        if exception && pdu[0] == 0x15 && reply[2] != 3 {
            assert_eq!(after, before, "exception {:#04X} to {frame:02X?} changed the transfer", reply[2]);
        }
        if let Some(h) = drive.state().transfer().header() {
            assert!(u64::from(after.received) <= h.image_len(), "{after:?}");
        }
        if after.phase == update::Phase::Ready {
            assert_eq!(after.received, image().len() as u32, "ready with part of an image: {after:?}");
        }
    }
    serve(&mut drive, &mut slot, false);
    if status(&drive).phase == update::Phase::Ready {
        assert!(slot.check().is_ok(), "ready, and the slot does not check");
    }
}
