//! An image sent over the bus in file records (0x15): taken in order, checked as it comes,
//! written where the slot has it, installed on order; every bad image refused with its reason and
//! every bad request with its exception, the rest of the drive unchanged; the write lock.

mod common;

use common::MapRig;
use common::images::{image, test_key};
use drive_core::maps::{Maps, RegisterMap};
use drive_core::od::Obj;
use drive_core::update::{self, Board, Job, PAGE, SLOT_LEN, TEST_KEY, TRAILER, TRAILER_LEN, Target, check_slot};
use ed25519_dalek::SigningKey;

/// A program of `n` bytes that are not all alike.
fn program(n: usize) -> Vec<u8> {
    (0..n).map(|i| (i * 7 + i / 251) as u8).collect()
}

const TARGET: Target = Target { board: Board::Simulator, key: TEST_KEY, store: 1 };

/// A drive taking images, with the DFU slot its platform writes.
struct Rig {
    rig: MapRig,
    dfu: Vec<u8>,
    /// Where the last write ended: writes only go forward within a transfer.
    end: u32,
    /// The page last erased, as embassy-boot's updater erases a page when a write enters it.
    erased: Option<u32>,
    installs: usize,
}

impl Rig {
    fn new(map: Maps) -> Self {
        let mut rig = MapRig::new(map);
        rig.drive.state_mut().set_updates(Some(TARGET), 0x0001_0000);
        Self { rig, dfu: vec![0xFF; (SLOT_LEN + PAGE) as usize], end: 0, erased: None, installs: 0 }
    }

    /// Does what the transfer asks of the flash, as a platform does after each reply.
    fn serve(&mut self) {
        loop {
            let (transfer, _) = self.rig.drive.state_mut().transfer_mut();
            match transfer.job() {
                Some(Job::Write { offset, bytes }) => {
                    assert_eq!(bytes.len() % update::WRITE_UNIT, 0);
                    assert!(offset == 0 || offset >= self.end, "a write at {offset} after one to {}", self.end);
                    if offset == 0 {
                        self.erased = None;
                    }
                    for (at, &b) in (offset..).zip(bytes) {
                        let page = at / PAGE;
                        if self.erased != Some(page) {
                            self.dfu[(page * PAGE) as usize..((page + 1) * PAGE) as usize].fill(0xFF);
                            self.erased = Some(page);
                        }
                        assert_eq!(self.dfu[at as usize], 0xFF, "written twice");
                        self.dfu[at as usize] = b;
                    }
                    self.end = offset + bytes.len() as u32;
                    transfer.done(true);
                }
                Some(Job::Install) => {
                    self.installs += 1;
                    transfer.done(true);
                }
                None => return,
            }
        }
    }

    /// A 0x15 request of one record: `data` from byte `offset` of the image.
    fn send(&mut self, offset: u32, data: &[u8]) -> Result<Vec<u8>, u8> {
        let reg = offset / 2;
        let (file, record) = ((reg / 10_000 + 1) as u16, (reg % 10_000) as u16);
        let mut pdu = vec![1, 0x15, (7 + data.len()) as u8, 6];
        pdu.extend_from_slice(&file.to_be_bytes());
        pdu.extend_from_slice(&record.to_be_bytes());
        pdu.extend_from_slice(&((data.len() / 2) as u16).to_be_bytes());
        pdu.extend_from_slice(data);
        let reply = self.rig.request(&pdu);
        self.serve();
        reply
    }

    /// Sends `image` in records of up to 244 bytes (as many as a request carries, each of
    /// them within its file); the first refusal.
    fn send_all(&mut self, image: &[u8]) -> Result<(), (u32, u8)> {
        let mut padded = image.to_vec();
        if padded.len() % 2 == 1 {
            padded.push(0);
        }
        let mut at = 0u32;
        while (at as usize) < padded.len() {
            let to_file_end = 20_000 - at % 20_000;
            let n = (padded.len() - at as usize).min(244).min(to_file_end as usize);
            self.send(at, &padded[at as usize..at as usize + n]).map_err(|e| (at, e))?;
            at += n as u32;
        }
        Ok(())
    }

    /// 0x2250-0x2255: state, failure, bytes received, the image's length.
    fn status(&mut self) -> (u16, u16, u32, u32) {
        let st = self.rig.drive.state();
        let [a, b, c, d] =
            [Obj::UpdateState, Obj::UpdateReason, Obj::UpdateReceived, Obj::UpdateLength].map(|o| st.read(o));
        (a as u16, b as u16, c, d)
    }

    fn write32(&mut self, addr: u16, v: u32) -> Result<Vec<u8>, u8> {
        let [a, b] = addr.to_be_bytes();
        let [c, d, e, f] = v.to_be_bytes();
        self.rig.request(&[1, 0x10, a, b, 0, 2, 4, c, d, e, f])
    }
}

#[test]
fn a_signed_image_lands_in_the_slot_and_installs_on_order() {
    let mut r = Rig::new(Maps::by_id(0));
    let prog = program(20_001 * 2 + 13);
    let img = image(&test_key(), Board::Simulator, &prog, 1);
    r.send_all(&img).expect("taken");
    let len = img.len() as u32;
    let regs = r.rig.read(0x2250, 6).expect("status over the bus");
    assert_eq!(regs, [3, 0, (len >> 16) as u16, len as u16, (len >> 16) as u16, len as u16]);
    assert_eq!(r.status(), (3, 0, len, len), "ready");
    assert_eq!(r.rig.read(0x2257, 2).expect("version"), [0x0002, 0x0100]);
    // The program from the slot's start, the trailer in its last page.
    assert_eq!(&r.dfu[..prog.len()], &prog[..]);
    assert_eq!(
        &r.dfu[TRAILER as usize..TRAILER as usize + TRAILER_LEN],
        &[&img[..32], &img[img.len() - 64..]].concat()[..]
    );
    let read = |at: u32, buf: &mut [u8]| {
        buf.copy_from_slice(&r.dfu[at as usize..at as usize + buf.len()]);
        true
    };
    assert_eq!(check_slot(read, &TARGET).map(|h| h.version), Ok(0x0002_0100));
    // Installing: once, then the platform restarts.
    r.rig.write(0x2256, 2).expect("install");
    r.serve();
    assert_eq!((r.installs, r.status().0), (1, 5));
    assert_eq!(r.rig.write(0x2256, 2), Err(4), "installing already");
}

#[test]
fn every_bad_image_is_refused_with_its_reason_and_nothing_installs() {
    let key = test_key();
    let prog = program(3000);
    let good = image(&key, Board::Simulator, &prog, 1);
    let last = |img: &[u8]| (img.len() as u32 - 1) / 244 * 244;
    let cases: Vec<(&str, Vec<u8>, u32, u16)> = vec![
        ("unsigned", [&good[..good.len() - 64], &[0u8; 64]].concat(), last(&good), 4),
        ("foreign key", image(&SigningKey::from_bytes(&[7; 32]), Board::Simulator, &prog, 1), last(&good), 4),
        ("another board", image(&key, Board::G474, &prog, 1), 0, 2),
        ("not an image", [&b"ELF\x7f"[..], &good[4..]].concat(), 0, 1),
        ("newer store", image(&key, Board::Simulator, &prog, 2), last(&good), 5),
        (
            "corrupted",
            {
                let mut c = good.clone();
                c[1000] ^= 0x10;
                c
            },
            last(&good),
            4,
        ),
        (
            "too large",
            {
                let mut h = good[..32].to_vec();
                h[12..16].copy_from_slice(&(update::MAX_PROGRAM + 2).to_le_bytes());
                [h, good[32..].to_vec()].concat()
            },
            0,
            6,
        ),
    ];
    for (name, img, at, reason) in cases {
        let mut r = Rig::new(Maps::by_id(0));
        assert_eq!(r.send_all(&img), Err((at, 3)), "{name}: exception 03 at the record that shows it");
        let (state, why, ..) = r.status();
        assert_eq!((state, why), (4, reason), "{name}");
        assert_eq!(r.rig.write(0x2256, 2), Err(4), "{name}: nothing to install");
        assert_eq!(r.installs, 0);
        // A transfer from its start begins again.
        r.send_all(&good).expect("the good image after");
        assert_eq!(r.status().0, 3, "{name}");
    }
    // Truncated: taken as far as it goes, refused at the install, and says why.
    let mut r = Rig::new(Maps::by_id(0));
    r.send_all(&good[..2000]).expect("the records are in order");
    assert_eq!(r.status().0, 1);
    assert_eq!(r.rig.write(0x2256, 2), Err(4));
    assert_eq!((r.status().0, r.status().1), (4, 3), "failed: fewer bytes than its header says");
    assert_eq!(r.installs, 0);
}

#[test]
fn bad_records_change_nothing() {
    let img = image(&test_key(), Board::Simulator, &program(2000), 1);
    let mut r = Rig::new(Maps::by_id(0));
    r.send(0, &img[..244]).expect("first");
    let before = (r.status(), r.dfu.clone(), r.rig.snapshot_params());
    // Out of order, past the end, a record of an odd file, a broadcast: nothing changes.
    assert_eq!(r.send(488, &img[488..732]), Err(2));
    assert_eq!(r.send(2, &img[2..246]), Err(2));
    assert_eq!(r.rig.request(&[1, 0x15, 9, 6, 0, 0, 0, 0, 0, 1, 0, 0]), Err(2), "file 0");
    assert_eq!(r.rig.request(&[1, 0x15, 9, 5, 0, 1, 0, 0x7A, 0, 1, 0, 0]), Err(2), "reference type 5");
    assert_eq!(r.rig.request(&[1, 0x15, 10, 6, 0, 1, 0, 0x7A, 0, 1, 0, 0]), Err(3), "byte count");
    assert!(r.rig.exchange(&common::frame(&[0, 0x15, 9, 6, 0, 1, 0, 0x7A, 0, 1, 1, 2])).is_none(), "broadcast");
    let mut pdu = vec![1, 0x15, 7 + 232 + 9, 6, 0, 1, 0, 0x7A, 0, 116];
    pdu.extend_from_slice(&img[244..476]);
    pdu.extend_from_slice(&[6, 0, 1, 0x01, 0xF4, 0, 1, 0, 0]);
    assert_eq!(r.rig.request(&pdu), Err(2), "a second record out of order: neither taken");
    assert_eq!((r.status(), r.dfu.clone(), r.rig.snapshot_params()), before);
    // The same record again (a master that lost the reply) is taken once.
    r.send(0, &img[..244]).expect("repeated");
    r.send(244, &img[244..488]).expect("the next");
    r.send(244, &img[244..488]).expect("repeated");
    assert_eq!(r.status().2, 488);
    r.send_all(&img).expect("from the start");
    assert_eq!(r.status().0, 3);
}

#[test]
fn records_of_any_whole_registers_are_taken() {
    // Records that leave 2, 4 or 6 bytes short of a double word before a full one.
    let img = image(&test_key(), Board::Simulator, &program(5000), 1);
    for first in [2usize, 100, 242, 244] {
        let mut r = Rig::new(Maps::by_id(0));
        r.send(0, &img[..first]).expect("first");
        let mut at = first;
        while at < img.len() {
            let n = (img.len() - at).min(244);
            let mut data = img[at..at + n].to_vec();
            if data.len() % 2 == 1 {
                data.push(0);
            }
            r.send(at as u32, &data).unwrap_or_else(|e| panic!("a first record of {first}: at {at}: {e}"));
            at += n;
        }
        assert_eq!(r.status().0, 3, "a first record of {first}");
    }
}

#[test]
fn no_install_while_moving_and_records_while_moving() {
    let img = image(&test_key(), Board::Simulator, &program(1000), 1);
    let mut r = Rig::new(Maps::by_id(0));
    r.write32(0x6003, 3200).expect("speed");
    r.write32(0x6005, 32_000).expect("move");
    r.rig.run(2_000);
    r.send_all(&img).expect("taken while moving");
    assert_eq!(r.rig.write(0x2256, 2), Err(4), "no restart while the axis moves");
    assert_eq!(r.status().0, 3, "still ready");
    r.rig.run(12_000_000);
    r.rig.write(0x2256, 2).expect("at rest");
}

#[test]
fn the_write_lock_refuses_every_write_and_update_until_unlocked() {
    // Each map reaches the native registers: its own addresses (native), at the native
    // addresses (JMC), through the sub-index 0xFF window (EC-57).
    for (name, map, sub) in
        [("native", Maps::by_id(0), None), ("jmc", Maps::jmc(), None), ("ec57", Maps::ec57(), Some(0xFF))]
    {
        let mut r = Rig::new(map);
        let request = |r: &mut Rig, function: u8, addr: u16, words: &[u16]| {
            let mut pdu = vec![1, function];
            pdu.extend_from_slice(&addr.to_be_bytes());
            pdu.extend(sub);
            if function == 0x10 {
                pdu.extend_from_slice(&(words.len() as u16).to_be_bytes());
                pdu.push(2 * words.len() as u8);
            }
            words.iter().for_each(|w| pdu.extend_from_slice(&w.to_be_bytes()));
            r.rig.request(&pdu).map(|_| ())
        };
        let password = [0x1234, 0x5678];
        request(&mut r, 0x10, 0x225D, &password).unwrap_or_else(|e| panic!("{name}: set the password: {e}"));
        assert_eq!(r.rig.drive.state().read(Obj::WriteLock), 2, "{name}: unlocked by whoever set it");
        request(&mut r, 0x10, 0x225F, &[0, 0]).unwrap_or_else(|e| panic!("{name}: lock: {e}"));
        assert_eq!(r.rig.drive.state().read(Obj::WriteLock), 1);
        let before = r.rig.snapshot_params();
        let locked = r.rig.drive.map().request_exception(drive_core::Exception::IllegalFunction).code();
        assert_eq!(request(&mut r, 0x06, 0x2228, &[5]), Err(locked), "{name}: a write");
        assert_eq!(request(&mut r, 0x10, 0x225D, &[0, 0]), Err(locked), "{name}: the password");
        let img = image(&test_key(), Board::Simulator, &program(100), 1);
        assert_eq!(r.send(0, &img[..100]), Err(locked), "{name}: an update");
        assert!(request(&mut r, 0x10, 0x225F, &[0x1234, 0x5679]).is_err(), "{name}: a wrong password");
        assert_eq!(r.rig.snapshot_params(), before, "{name}: nothing changed");
        assert_eq!((r.status().0, r.rig.drive.state().read(Obj::WriteLock)), (0, 1));
        // Reads go on; the password is not told.
        assert_eq!(r.rig.drive.state().read(Obj::ScopeDivider), 2);
        if sub.is_none() {
            assert_eq!(r.rig.read(0x225D, 2).expect("read"), [0, 0]);
        }
        request(&mut r, 0x10, 0x225F, &password).unwrap_or_else(|e| panic!("{name}: unlock: {e}"));
        request(&mut r, 0x06, 0x2228, &[5]).expect("unlocked");
        r.send(0, &img[..100]).expect("unlocked");
    }
}

#[test]
fn a_saved_password_locks_at_power_up_and_factory_settings_clear_it() {
    let mut params = drive_core::Params::factory();
    params.set(Obj::Password, 77);
    let drive = drive_core::Drive::boot_with_map(drive_core::DriveConfig::default(), Maps::by_id(0), &params, 0);
    let mut rig = MapRig::with_drive(drive);
    assert_eq!(rig.drive.state().read(Obj::WriteLock), 1);
    assert_eq!(rig.write(0x6002, 1), Err(1));
    // FSET at power-up restores the factory settings, which have no password.
    let drive = drive_core::Drive::boot_with_map(
        drive_core::DriveConfig::default(),
        Maps::by_id(0),
        &drive_core::Params::factory(),
        0,
    );
    let mut rig = MapRig::with_drive(drive);
    assert_eq!(rig.drive.state().read(Obj::WriteLock), 0);
    rig.write(0x6002, 1).expect("no lock");
}
