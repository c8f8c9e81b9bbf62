//! System control 0x200F and the storage status 0x2120 as the drive state machine sees them: the
//! requests it makes of its platform, what it refuses, and what power-up takes from the store.

mod common;

use common::{Bus, reply};
use drive_core::drive::{STORAGE_CORRUPT, STORAGE_SAVE_FAILED, STORAGE_SAVING};
use drive_core::od::Obj;
use drive_core::{Drive, DriveConfig, Params, SystemRequest};

fn saving_drive() -> Bus {
    Bus::new(Drive::new(DriveConfig { can_save: true, ..Default::default() }))
}

fn storage_status(bus: &Bus) -> u32 {
    bus.drive.state().read(Obj::StorageStatus)
}

#[test]
fn a_save_is_requested_then_reported() {
    let mut bus = saving_drive();
    bus.request(&[0x01, 0x06, 0x60, 0x0D, 0x05, 0xDC]); // phase current 1500
    assert_eq!(bus.request(&[0x01, 0x06, 0x20, 0x0F, 0x00, 0x02]), reply(&[0x01, 0x06, 0x20, 0x0F, 0x00, 0x02]));
    assert_eq!(bus.drive.take_system_request(), Some(SystemRequest::Save));
    assert_eq!(bus.drive.take_system_request(), None, "once");
    assert_eq!(bus.drive.state().params().get(Obj::PhaseCurrent), 1500, "what the platform saves");
    assert_eq!(storage_status(&bus), u32::from(STORAGE_SAVING));
    // A second save while the first runs: refused, nothing asked; bit 3 cannot be cleared.
    assert_eq!(bus.request(&[0x01, 0x06, 0x20, 0x0F, 0x00, 0x02]), reply(&[0x01, 0x86, 0x04]));
    bus.request(&[0x01, 0x06, 0x21, 0x20, 0x00, 0x08]);
    assert_eq!((bus.drive.take_system_request(), storage_status(&bus)), (None, u32::from(STORAGE_SAVING)));
    bus.drive.save_done(true);
    assert_eq!(storage_status(&bus), 0);
    // A failed save leaves bit 4 until the next save or until cleared.
    bus.request(&[0x01, 0x06, 0x20, 0x0F, 0x00, 0x02]);
    bus.drive.save_done(false);
    assert_eq!(storage_status(&bus), u32::from(STORAGE_SAVE_FAILED));
    bus.request(&[0x01, 0x06, 0x21, 0x20, 0x00, 0x10]);
    assert_eq!(storage_status(&bus), 0);
}

#[test]
fn factory_settings_are_saved_where_the_platform_can() {
    let mut bus = saving_drive();
    bus.request(&[0x01, 0x06, 0x60, 0x0A, 0x00, 0x02]);
    bus.request(&[0x01, 0x06, 0x20, 0x0F, 0x00, 0x03]);
    assert_eq!(bus.drive.take_system_request(), Some(SystemRequest::Save));
    assert_eq!(bus.drive.state().params(), Params::factory());
    // Without storage the values are restored and nothing is asked.
    let mut bus = Bus::factory();
    bus.request(&[0x01, 0x06, 0x60, 0x0A, 0x00, 0x02]);
    assert!(bus.request(&[0x01, 0x06, 0x20, 0x0F, 0x00, 0x03]).is_some());
    assert_eq!((bus.drive.take_system_request(), bus.drive.state().read(Obj::AccelLevel)), (None, 8));
}

#[test]
fn no_save_nor_factory_reset_while_moving() {
    let mut bus = saving_drive();
    bus.request(&[0x01, 0x06, 0x60, 0x0D, 0x05, 0xDC]);
    // Velocity mode at 2000 pps.
    bus.request(&[0x01, 0x06, 0x60, 0x07, 0x00, 0x01]);
    bus.request(&[0x01, 0x10, 0x60, 0x03, 0x00, 0x02, 0x04, 0x00, 0x00, 0x07, 0xD0]);
    assert_ne!(bus.drive.state().read(Obj::ControllerStatus) & 8, 0, "moving");
    let before = bus.snapshot();
    for v in [2, 3, 1] {
        assert_eq!(bus.request(&[0x01, 0x06, 0x20, 0x0F, 0x00, v]), reply(&[0x01, 0x86, 0x04]), "0x200F = {v}");
    }
    assert_eq!(bus.snapshot(), before);
    assert_eq!(bus.drive.take_system_request(), None);
}

#[test]
fn power_loss_asks_for_the_position_only_when_enabled() {
    let mut bus = saving_drive();
    assert!(bus.drive.state_mut().set_position(-123_456));
    assert!(!bus.drive.state_mut().power_lost());
    assert_eq!(bus.drive.take_system_request(), None);
    bus.request(&[0x01, 0x06, 0x60, 0x5E, 0x00, 0x01]);
    assert!(bus.drive.state_mut().power_lost());
    assert_eq!(bus.drive.take_system_request(), Some(SystemRequest::SavePosition(-123_456)));
}

#[test]
fn power_up_takes_the_saved_values() {
    let mut p = Params::factory();
    assert!(p.set(Obj::NodeId, 7) && p.set(Obj::BaudRate, 19200) && p.set(Obj::PhaseCurrent, 900));
    p.set_saved_position(-42);
    let drive = Drive::boot(DriveConfig::default(), &p, STORAGE_CORRUPT | STORAGE_SAVING);
    assert_eq!((drive.address().get(), drive.baud().get()), (7, 19200));
    let st = drive.state();
    assert_eq!((st.read(Obj::PhaseCurrent), st.read_i32(Obj::SavedPosition)), (900, -42));
    assert_eq!(st.read(Obj::StorageStatus), u32::from(STORAGE_CORRUPT), "no save runs at power-up");
    assert_eq!(
        st.params(),
        {
            p.set_saved_position(0);
            p
        },
        "0x6055 is not part of a save"
    );
}
