//! The parameter store on the simulated G474 flash: a power cut at every program and erase
//! operation of a save leaves the complete old set or the complete new set, and the drive boots
//! and answers; many saves wear the pages evenly.
//!
//! `cargo test -p hal-sim --test store_power_cuts -- --nocapture` prints the figures.

use std::time::{Duration, Instant as WallClock};

use drive_core::crc::crc16;
use drive_core::drive::{STORAGE_CORRUPT, STORAGE_EMPTY, STORAGE_SAVE_FAILED};
use drive_core::od::Obj;
use drive_core::state::ProgramMemory;
use drive_core::state::memory::WORDS;
use drive_core::store::{FAULTS_RECORD, FaultHistory, RECORD, SAVED, Store, item_bytes};
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

/// Fault history number `g`: `g` alarms, the last ten of them in the history, newest first.
fn history(g: u32) -> FaultHistory {
    let mut h = FaultHistory { count: g as u16, ..FaultHistory::default() };
    for (k, e) in h.entries.iter_mut().enumerate().take(g as usize) {
        let n = g - k as u32;
        *e = ((10 + n % 20) << 24) | (n * 37);
    }
    h
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

/// What the power cuts of one save ended with.
#[derive(Default)]
struct Cuts {
    /// Cut points tested.
    points: u32,
    /// Restarts that found the old set, and the new one.
    old: u32,
    new: u32,
    /// Most operations in one save.
    max_ops: u64,
}

impl Cuts {
    /// Runs `save` on a flash holding `before`, uncut, then cut at each of its operations with
    /// each tear; after each cut the restart must find exactly `old` or `new` (0x6055 and the
    /// fault history included),
    /// with a readable store, a drive that answers, and a store that takes the next save.
    fn every_cut(&mut self, before: &[u8], old: &Params, new: &Params, save: impl Fn(&mut Store<SimFlash>) -> bool) {
        let mut uncut = store_on(SimFlash::from_bytes(before.to_vec()));
        assert!(save(&mut uncut), "uncut save");
        let ops = uncut.flash().ops();
        self.max_ops = self.max_ops.max(ops);
        for k in 0..ops {
            for tear in Tear::ALL {
                let mut cut = SimFlash::from_bytes(before.to_vec());
                cut.cut_after(k, tear);
                let mut s = store_on(cut);
                assert!(!save(&mut s), "cut at op {k} ({tear:?}) went through");
                let bytes = s.into_flash().bytes().to_vec();
                let (loaded, status) = restart(&bytes);
                assert_eq!(status, 0, "cut at op {k} ({tear:?}): store unreadable");
                if loaded == *new {
                    self.new += 1;
                } else {
                    assert_eq!(loaded, *old, "cut at op {k} ({tear:?}): neither the old set nor the new");
                    self.old += 1;
                }
                let mut again = store_on(SimFlash::from_bytes(bytes));
                assert!(save(&mut again), "the save after the restart goes through");
                assert_eq!(restart(again.into_flash().bytes()), (new.clone(), 0));
                self.points += 1;
            }
        }
    }
}

#[test]
fn a_power_cut_at_every_operation_leaves_the_old_or_the_new_set() {
    // The records fall on the pages differently after 0-3 position records first: a cut that
    // only one layout meets (an erase cut after a migration) is met in one of them.
    for shift in 0..4 {
        println!("layout shifted by {shift} position records:");
        power_cuts(shift);
    }
}

fn power_cuts(shift: i32) {
    let mut store = store_on(SimFlash::erased(PAGES));
    for k in 0..shift {
        block_on(store.save_position(k)).expect("position save");
    }
    block_on(store.save(&set(0))).expect("first save");
    let mut params = Cuts::default();
    let mut positions = Cuts::default();
    let mut faults = Cuts::default();
    // Enough saves to fill every page and wrap around twice, with a power-down position and a
    // fault history now and then (records of their own, which a cut parameter save must not lose
    // either).
    let saves = 2 * (PAGES * PAGE) as u32 / item_bytes::<SimFlash>(RECORD) as u32 + 8;
    let mut current = set(0);
    if shift > 0 {
        current.set_saved_position(shift - 1);
    }
    for g in 1..=saves {
        if g % 7 == 0 {
            let mut next = current.clone();
            next.set_saved_position(g as i32 * -1000);
            let bytes = store.flash().bytes().to_vec();
            positions.every_cut(&bytes, &current, &next, |s| block_on(s.save_position(g as i32 * -1000)).is_ok());
            block_on(store.save_position(g as i32 * -1000)).expect("position save");
            current = next;
        }
        if g % 5 == 0 {
            let h = history(g);
            let mut next = current.clone();
            next.set_fault_history(&h);
            let bytes = store.flash().bytes().to_vec();
            faults.every_cut(&bytes, &current, &next, |s| block_on(s.save_faults(&h)).is_ok());
            block_on(store.save_faults(&h)).expect("fault history save");
            current = next;
        }
        let mut next = set(g);
        next.set_saved_position(current.get(Obj::SavedPosition) as i32);
        next.set_fault_history(&current.fault_history());
        let bytes = store.flash().bytes().to_vec();
        params.every_cut(&bytes, &current, &next, |s| block_on(s.save(&set(g))).is_ok());
        block_on(store.save(&set(g))).expect("save");
        current = next;
    }
    let erases = store.flash().erase_counts().to_vec();
    for (what, c) in [("parameter", &params), ("position", &positions), ("fault history", &faults)] {
        println!(
            "{what} saves: {} power cuts tested (every operation, up to {} a save, x {} tears): {} restarts found the old set, {} the new",
            c.points,
            c.max_ops,
            Tear::ALL.len(),
            c.old,
            c.new
        );
    }
    println!("{saves} parameter saves; erases per page {erases:?}");
    assert!(erases.iter().all(|&e| e >= 1), "every page was erased and reused: {erases:?}");
    assert!(params.new > 0 && params.old > 0, "both outcomes happen");
    assert!(faults.new > 0 && faults.old > 0, "both outcomes happen");
    println!(
        "fault history record: {FAULTS_RECORD} bytes, {} flash bytes a save",
        item_bytes::<SimFlash>(FAULTS_RECORD)
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
         erases per page {erases:?}; G474 flash time a save: mean {per_save:.2?}, worst {worst_busy:.2?}; \
         position record worst {position_busy:.2?}",
        item_bytes::<SimFlash>(RECORD)
    );
    assert!(max - min <= 1, "wear not spread: {erases:?}");
    // Each page erase frees a page's worth of records: no more erases than that needs.
    let per_page = (PAGE / item_bytes::<SimFlash>(RECORD)) as u64;
    assert!(max <= u64::from(CYCLES) / (PAGES as u64 * (per_page - 1)) + 2, "{erases:?}");
}

#[test]
fn a_failed_save_shows_in_the_status_and_keeps_the_old_set() {
    let mut store = store_on(SimFlash::erased(PAGES));
    block_on(store.save(&set(1))).expect("save");
    let mut drive = hal_sim::boot(&mut store, DriveConfig { can_save: true, ..Default::default() }, false, None);
    let st = drive.state_mut();
    st.check(Obj::PhaseCurrent, 2000).expect("in range");
    st.apply(Obj::PhaseCurrent, 2000);
    st.check(Obj::SystemControl, 2).expect("a save is allowed");
    st.apply(Obj::SystemControl, 2);
    store.flash().cut_after(0, Tear::Half);
    hal_sim::serve_request(&mut drive, &mut store);
    assert_eq!(drive.state().read(Obj::StorageStatus), u32::from(STORAGE_SAVE_FAILED));
    assert_eq!(restart(store.into_flash().bytes()), (set(1), 0));
}

#[test]
fn the_power_down_position_is_saved_when_enabled() {
    let mut store = store_on(SimFlash::erased(PAGES));
    block_on(store.save(&set(2))).expect("save");
    let mut drive = hal_sim::boot(&mut store, DriveConfig { can_save: true, ..Default::default() }, false, None);
    let st = drive.state_mut();
    assert!(st.set_position(98_765));
    assert!(!st.power_lost(), "0x605E is off");
    st.apply(Obj::AutoSave, 1);
    assert!(st.power_lost());
    let ops = store.flash().ops();
    let busy = store.flash().busy();
    hal_sim::serve_request(&mut drive, &mut store);
    println!(
        "power-down position: {} flash operations, {:.2?} of G474 flash time",
        store.flash().ops() - ops,
        store.flash().busy() - busy
    );
    let (loaded, _) = restart(store.into_flash().bytes());
    assert_eq!(loaded.get(Obj::SavedPosition) as i32, 98_765);
    assert_eq!(
        {
            let mut p = loaded;
            p.set_saved_position(0);
            p
        },
        set(2),
        "the parameters are untouched"
    );
}

/// Program number `g` (seed 002's 1024-1536, in a program memory): every byte differs from
/// programs `g - 1` and `g + 1`.
fn program(g: u8) -> ProgramMemory {
    let m = ProgramMemory::new();
    let byte = |i: usize| (i as u8).wrapping_mul(31).wrapping_add(g);
    for k in 0..WORDS {
        m.set_word(k, u16::from_be_bytes([byte(2 * k), byte(2 * k + 1)]));
    }
    m
}

fn program_bytes(m: &ProgramMemory) -> Vec<u8> {
    (0..WORDS).flat_map(|k| m.word(k).unwrap_or(0).to_be_bytes()).collect()
}

#[test]
fn a_power_cut_in_a_program_save_loads_the_old_program_the_new_or_none() {
    let mut store = store_on(SimFlash::erased(PAGES));
    block_on(store.save(&set(0))).expect("parameters");
    block_on(store.save_program(&program(0))).expect("first program");
    let (mut old, mut new, mut none, mut points) = (0, 0, 0, 0);
    // Enough saves to wrap around the pages (a program is five records and a commit, about
    // 1.4 KB, in one of two banks): two a page.
    for g in 1..=2 * PAGES as u8 {
        let before = store.flash().bytes().to_vec();
        let (was, next) = (program(g - 1), program(g));
        let mut uncut = store_on(SimFlash::from_bytes(before.clone()));
        block_on(uncut.save_program(&next)).expect("uncut save");
        for k in 0..uncut.flash().ops() {
            for tear in Tear::ALL {
                let mut cut = SimFlash::from_bytes(before.clone());
                cut.cut_after(k, tear);
                let mut s = store_on(cut);
                assert!(block_on(s.save_program(&next)).is_err(), "cut at op {k} ({tear:?}) went through");
                let bytes = s.into_flash().bytes().to_vec();
                assert_eq!(restart(&bytes), (set(0), 0), "the parameters survive a cut program save");
                let loaded = ProgramMemory::new();
                let whole = block_on(store_on(SimFlash::from_bytes(bytes)).load_program(&loaded));
                let got = program_bytes(&loaded);
                if !whole {
                    assert!(got.iter().all(|&b| b == 0), "a program not loaded reads empty");
                    none += 1;
                } else if got == program_bytes(&next) {
                    new += 1;
                } else {
                    assert_eq!(got, program_bytes(&was), "cut at op {k} ({tear:?}): a mix of two programs");
                    old += 1;
                }
                points += 1;
            }
        }
        block_on(store.save_program(&next)).expect("save");
        let loaded = ProgramMemory::new();
        assert!(block_on(store_on(SimFlash::from_bytes(store.flash().bytes().to_vec())).load_program(&loaded)));
        assert_eq!(program_bytes(&loaded), program_bytes(&next));
    }
    let erases = store.flash().erase_counts().to_vec();
    println!(
        "program saves: {points} power cuts tested: {old} loaded the old program, {new} the new, {none} none; erases per page {erases:?}"
    );
    assert!(erases.iter().sum::<u64>() > 0, "the saves wrapped around the pages");
    assert!(old > 0 && new > 0, "both outcomes happen");
    assert_eq!(none, 0, "a cut save never loses the program saved before");
}
