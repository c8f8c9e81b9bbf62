//! The parameter store across firmware versions, on the simulated G474 flash: a newer image
//! reads an older image's record (objects it dropped skipped, objects it lacked at their factory
//! values, values outside today's ranges refused); an older image that finds a newer store
//! version (a rollback after an update that changed it) says so at power-up, runs on factory
//! values and refuses to save over the store, which stays for the firmware that wrote it; FSET
//! ends it.

use drive_core::drive::{STORAGE_CORRUPT, STORAGE_FSET, STORAGE_NEWER};
use drive_core::od::Obj;
use drive_core::od::ObjError;
use drive_core::store::{FORMAT, PARAMS_KEY, VERSION};
use drive_core::{DriveConfig, Params};
use hal_sim::flash::{PAGES, SimFlash, block_on};
use sequential_storage::cache::{Cache, Uncached};
use sequential_storage::map::{MapConfig, MapStorage};

/// `flash` with `record` stored under `key`, as another firmware's store writes it.
fn with_record(flash: SimFlash, key: u8, record: &[u8]) -> SimFlash {
    let end = flash.bytes().len() as u32;
    let config = MapConfig::try_new(0..end).expect("whole pages");
    let mut map: MapStorage<u8, _, Cache<Uncached, Uncached, Uncached, u8>> =
        MapStorage::new(flash, config, Cache::new_uncached());
    let mut buf = [0u8; 2048];
    block_on(map.store_item(&mut buf, &key, &record)).expect("stored");
    map.destroy().0
}

/// A parameter record of `format` with these `(address, value)` entries.
fn record(format: u8, entries: &[(u16, u32)]) -> Vec<u8> {
    let mut r = vec![format, 0];
    r.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    for (a, v) in entries {
        r.extend_from_slice(&a.to_le_bytes());
        r.extend_from_slice(&v.to_le_bytes());
    }
    r
}

fn addr(obj: Obj) -> u16 {
    obj.def().addr
}

#[test]
fn a_newer_image_reads_an_older_images_record() {
    assert_eq!(u16::from(FORMAT), VERSION);
    // An older firmware's set: a start speed, an object it had at 0x2FFE that is gone, a phase
    // current beyond today's range; nothing of the objects added since.
    let old = record(FORMAT, &[(addr(Obj::StartSpeed), 812), (0x2FFE, 5), (addr(Obj::PhaseCurrent), 99_999)]);
    let mut store = hal_sim::store(with_record(SimFlash::erased(PAGES), PARAMS_KEY, &old)).expect("store");
    let drive = hal_sim::boot(&mut store, DriveConfig::default(), false, None);
    let s = drive.state();
    assert_eq!(s.read(Obj::StorageStatus), 0, "read whole");
    assert_eq!(s.read(Obj::StartSpeed), 812);
    let factory = Params::factory();
    assert_eq!(s.read(Obj::PhaseCurrent), factory.get(Obj::PhaseCurrent), "out of range: refused");
    assert_eq!(s.read(Obj::ScopeDivider), factory.get(Obj::ScopeDivider), "added since: factory");
}

#[test]
fn an_older_image_keeps_a_newer_store_and_says_so() {
    let newer = record(FORMAT + 1, &[(addr(Obj::StartSpeed), 812)]);
    let mut store = hal_sim::store(with_record(SimFlash::erased(PAGES), PARAMS_KEY, &newer)).expect("store");
    let mut drive = hal_sim::boot(&mut store, DriveConfig { can_save: true, ..DriveConfig::default() }, false, None);
    let status = drive.state().read(Obj::StorageStatus) as u8;
    assert_eq!(status, STORAGE_CORRUPT | STORAGE_NEWER, "said at power-up");
    assert_eq!(drive.state().read(Obj::StartSpeed), Params::factory().get(Obj::StartSpeed), "factory values");
    // A save is refused: the store stays for the firmware that wrote it.
    let save = drive.state_mut().write_def(Obj::SystemControl.def(), 2);
    assert_eq!(save, Err(ObjError::NotNow));
    hal_sim::serve_request(&mut drive, &mut store);
    let again = hal_sim::boot(&mut store, DriveConfig::default(), false, None);
    assert_eq!(again.state().read(Obj::StorageStatus) as u8, STORAGE_CORRUPT | STORAGE_NEWER, "still there");
    // FSET at power-up: factory values saved in this firmware's version; then read whole.
    let fset = hal_sim::boot(&mut store, DriveConfig::default(), true, None);
    assert_eq!(fset.state().read(Obj::StorageStatus) as u8, STORAGE_FSET);
    let after = hal_sim::boot(&mut store, DriveConfig::default(), false, None);
    assert_eq!(after.state().read(Obj::StorageStatus), 0);
}
