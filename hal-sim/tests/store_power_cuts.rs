//! The parameter store on the simulated G431 flash: a power cut at every program and erase
//! operation of a save leaves the complete old set or the complete new set, and the drive boots
//! and answers; many saves wear the pages evenly.
//!
//! `cargo test -p hal-sim --test store_power_cuts -- --nocapture` prints the figures.

use std::time::{Duration, Instant as WallClock};

use drive_core::crc::crc16;
use drive_core::drive::{STORAGE_CORRUPT, STORAGE_EMPTY};
use drive_core::od::Obj;
use drive_core::store::{RECORD, SAVED, Store, item_bytes};
use drive_core::{Drive, DriveConfig, Instant, Params};
use hal_sim::flash::{PAGE, PAGES, SimFlash, Tear, block_on};

/// Parameter set number `g`: every saved object that takes more than one value differs from the
/// sets before and after it.
fn set(g: u32) -> Params {
    let mut p = Params::factory();
    assert!(p.set(Obj::NodeId, 1 + g % 127));
    assert!(p.set(Obj::GroupId, g % 128));
    assert!(p.set(Obj::PhaseCurrent, 100 + g % 5000));
    assert!(p.set(Obj::JerkTime, 1 + g % 1000));
    assert!(p.set(Obj::StartSpeed, g % 65536));
    assert!(p.set(Obj::AnalogMinPos, (-(g as i32)) as u32));
    assert!(p.set(Obj::AnalogMaxPos, g.wrapping_mul(2_654_435_761)));
    assert!(p.set(Obj::PpAccel, 151 + g));
    assert!(p.set(Obj::GpioConfig, g & 0x00FF_FFFF));
    assert!(p.set(Obj::BaudRate, [9600, 19200, 115_200][g as usize % 3]));
    p
}

fn store_on(flash: SimFlash) -> Store<SimFlash> {
    hal_sim::store(flash).expect("store on the flash")
}

/// Powers up on `bytes`: what loads, and the drive answering a read of the phase current.
fn restart(bytes: &[u8]) -> (Params, u8) {
    let mut store = store_on(SimFlash::from_bytes(bytes.to_vec()));
    let loaded = block_on(store.load());
    let mut drive = Drive::boot(DriveConfig { can_save: true, ..Default::default() }, &loaded.params, loaded.status);
    let node = loaded.params.get(Obj::NodeId) as u8;
    let mut req = vec![node, 0x03, 0x60, 0x0D, 0x00, 0x01];
    req.extend(crc16(&req).to_le_bytes());
    drive.on_rx(Instant::from_micros(0), &req);
    drive.on_timer(Instant::from_micros(100_000));
    let reply = drive.take_reply().expect("the drive answers").to_vec();
    assert_eq!(reply[..3], [node, 0x03, 0x02]);
    assert_eq!(u16::from_be_bytes([reply[3], reply[4]]) as u32, loaded.params.get(Obj::PhaseCurrent));
    (loaded.params, loaded.status)
}

#[test]
fn a_power_cut_at_every_operation_leaves_the_old_or_the_new_set() {
    let mut flash = SimFlash::erased(PAGES);
    let mut store = store_on(flash);
    block_on(store.save(&set(0))).expect("first save");
    let mut points = 0;
    let mut max_ops = 0;
    let mut cut_with_erase = 0;
    // Enough saves to fill every page and wrap around twice, with a power-down position now and
    // then, which must survive cuts of the parameter saves too.
    let saves = 2 * (PAGES * PAGE) as u32 / item_bytes::<SimFlash>(RECORD) as u32 + 8;
    let mut position = None;
    for g in 1..=saves {
        if g % 7 == 0 {
            position = Some(g as i32 * -1000);
            block_on(store.save_position(g as i32 * -1000)).expect("position save");
        }
        flash = store.into_flash();
        let before = flash.bytes().to_vec();
        let ops0 = flash.ops();
        let erases0: u64 = flash.erase_counts().iter().sum();
        store = store_on(flash);
        block_on(store.save(&set(g))).expect("uncut save");
        let ops = store.flash().ops() - ops0;
        max_ops = max_ops.max(ops);
        let erased = store.flash().erase_counts().iter().sum::<u64>() > erases0;
        let (old, new) = (set(g - 1), set(g));
        for k in 0..ops {
            for tear in Tear::ALL {
                let mut cut = SimFlash::from_bytes(before.clone());
                cut.cut_after(k, tear);
                let mut s = store_on(cut);
                assert!(block_on(s.save(&new)).is_err(), "save {g}, cut at op {k} ({tear:?}) went through");
                let bytes = s.into_flash().bytes().to_vec();
                let (loaded, status) = restart(&bytes);
                assert_eq!(status, 0, "save {g}, cut at op {k} ({tear:?}): store unreadable");
                let which = if loaded == new {
                    "new"
                } else {
                    let mut want = old.clone();
                    want.set_saved_position(0);
                    let mut got = loaded.clone();
                    got.set_saved_position(0);
                    assert_eq!(got, want, "save {g}, cut at op {k} ({tear:?}): a mix");
                    "old"
                };
                let _ = which;
                assert_eq!(loaded.get(Obj::SavedPosition) as i32, position.unwrap_or(0), "position record lost");
                // The store works again after the restart: the next save goes through and loads.
                let mut again = store_on(SimFlash::from_bytes(bytes));
                block_on(again.save(&new)).expect("save after the restart");
                let (reloaded, _) = restart(again.into_flash().bytes());
                assert_eq!(reloaded.get(Obj::PhaseCurrent), new.get(Obj::PhaseCurrent));
                points += 1;
                cut_with_erase += u32::from(erased);
            }
        }
    }
    println!(
        "{saves} saves, up to {max_ops} operations each; {points} power cuts tested ({} operations x {} tears), \
         {cut_with_erase} of them in saves that erase a page",
        points / Tear::ALL.len(),
        Tear::ALL.len()
    );
}

#[test]
fn an_empty_or_garbage_flash_boots_with_factory_values_and_a_status_bit() {
    let (params, status) = restart(&vec![0xFF; PAGES * PAGE]);
    assert_eq!((params, status), (Params::factory(), STORAGE_EMPTY));
    // Noise, as from a flash image of something else.
    let noise: Vec<u8> = (0..PAGES * PAGE).map(|i| (i as u32).wrapping_mul(2_654_435_761).to_be_bytes()[0]).collect();
    let mut store = store_on(SimFlash::from_bytes(noise));
    let loaded = block_on(store.load());
    assert_eq!(loaded.params, Params::factory());
    assert_ne!(loaded.status & (STORAGE_CORRUPT | STORAGE_EMPTY), 0, "status {:#x}", loaded.status);
    // Saving works afterwards.
    block_on(store.save(&set(3))).expect("save after a garbage flash");
    assert_eq!(restart(store.into_flash().bytes()), (set(3), 0));
}

/// How many save cycles the wear test runs: the 100 000 (about 1 s in release, ~20 s in a
/// debug build).
const CYCLES: u32 = 100_000;

#[test]
fn a_hundred_thousand_saves_spread_wear_over_the_pages() {
    let mut store = store_on(SimFlash::erased(PAGES));
    let t0 = WallClock::now();
    let mut worst_busy = Duration::ZERO;
    let mut position_busy = Duration::ZERO;
    for g in 0..CYCLES {
        let busy0 = store.flash().busy();
        block_on(store.save(&set(g))).unwrap_or_else(|e| panic!("save {g}: {e:?}"));
        worst_busy = worst_busy.max(store.flash().busy() - busy0);
        if g % 1000 == 999 {
            let busy0 = store.flash().busy();
            block_on(store.save_position(g as i32)).expect("position");
            position_busy = position_busy.max(store.flash().busy() - busy0);
            let loaded = block_on(store.load());
            let mut want = set(g);
            want.set_saved_position(g as i32);
            assert_eq!((loaded.params, loaded.status), (want, 0), "after save {g}");
        }
    }
    let wall = t0.elapsed();
    let flash = store.into_flash();
    let erases = flash.erase_counts().to_vec();
    let (min, max) = (*erases.iter().min().unwrap(), *erases.iter().max().unwrap());
    let per_save = flash.busy() / CYCLES;
    println!(
        "{CYCLES} saves in {wall:.2?}; {SAVED} objects, record {RECORD} bytes, {} flash bytes a save; \
         erases per page {erases:?}; G431 flash time a save: mean {per_save:.2?}, worst {worst_busy:.2?}; \
         position record worst {position_busy:.2?}",
        item_bytes::<SimFlash>(RECORD)
    );
    assert!(max - min <= 1, "wear not spread: {erases:?}");
    // Each page erase frees a page's worth of records: no more erases than that needs.
    let per_page = (PAGE / item_bytes::<SimFlash>(RECORD)) as u64;
    assert!(max <= u64::from(CYCLES) / (PAGES as u64 * (per_page - 1)) + 2, "{erases:?}");
}
