//! The exception matrix: each exception code and each silent drop, and nothing changes after them.

mod common;
use common::{Bus, frame, reply};
use drive_core::od::Obj;

/// A drive with some non-default state, so that a change would show.
fn busy_bus() -> Bus {
    let mut bus = Bus::factory();
    for req in [
        &[0x01, 0x06, 0x60, 0x0C, 0x00, 0x20][..],
        &[0x01, 0x10, 0x60, 0x03, 0x00, 0x02, 0x04, 0x00, 0x00, 0x7D, 0x00],
        &[0x01, 0x06, 0x60, 0x02, 0x00, 0x01],
    ] {
        assert!(bus.request(req).is_some_and(|r| r[1] & 0x80 == 0));
    }
    bus.drive.state_mut().status_mut().error = 0x21;
    bus
}

/// Sends `body` and checks the exception `code` comes back and no state changed.
fn refused(body: &[u8], code: u8) {
    let mut bus = busy_bus();
    let before = bus.snapshot();
    let exceptions = bus.drive.counters().exceptions;
    assert_eq!(bus.request(body), reply(&[body[0], body[1] | 0x80, code]), "request {body:02X?}");
    assert_eq!(bus.snapshot(), before, "state changed by {body:02X?}");
    assert_eq!(bus.drive.counters().exceptions, exceptions + 1);
}

/// Sends raw bytes and checks that nothing is answered and no state changed.
fn dropped(bytes: &[u8]) {
    let mut bus = busy_bus();
    let before = bus.snapshot();
    bus.send(bytes);
    assert_eq!(bus.wait(20_000), Vec::<Vec<u8>>::new(), "answered {bytes:02X?}");
    assert_eq!(bus.snapshot(), before);
}

#[test]
fn illegal_function_01() {
    refused(&[0x01, 0x05, 0x00, 0x01, 0xFF, 0x00], 1); // write coil: not supported
    refused(&[0x01, 0x01, 0x00, 0x00, 0x00, 0x01], 1);
    refused(&[0x01, 0x08, 0x00, 0x03, 0x00, 0x00], 1); // diagnostics sub-function 3
    refused(&[0x01, 0x2B, 0x0D, 0x00, 0x00], 1); // MEI type other than 0x0E
}

#[test]
fn illegal_data_address_02() {
    refused(&[0x01, 0x03, 0x00, 0x00, 0x00, 0x01], 2); // no object at 0
    refused(&[0x01, 0x03, 0x5F, 0xFF, 0x00, 0x02], 2); // starts before the page's first object
    refused(&[0x01, 0x03, 0x20, 0xFF, 0x00, 0x02], 2); // crosses from page 0x20 into 0x21
    refused(&[0x01, 0x03, 0x30, 0x00, 0x00, 0x01], 2); // a page without objects
    refused(&[0x01, 0x04, 0x60, 0x8A, 0x00, 0x02], 2); // runs past the last object
    refused(&[0x01, 0x06, 0x60, 0x12, 0x00, 0x00], 2); // write into a reserved register
    refused(&[0x01, 0x06, 0x60, 0x5F, 0x00, 0x01], 2); // analog input is read only
    refused(&[0x01, 0x06, 0x10, 0x1A, 0x41, 0x41], 2); // device name is read only
    // A multi-register write that ends on a read-only object changes nothing before it.
    refused(&[0x01, 0x10, 0x60, 0x59, 0x00, 0x07, 0x0E, 0, 9, 0, 9, 0, 9, 0, 9, 0, 1, 0, 1, 0, 7], 2);
    refused(&[0x01, 0x2B, 0x0E, 0x04, 0x07], 2); // no device identification object 7
}

#[test]
fn illegal_data_value_03() {
    refused(&[0x01, 0x03, 0x60, 0x00, 0x00, 0x00], 3); // quantity 0
    refused(&[0x01, 0x03, 0x60, 0x00, 0x00, 0x7E], 3); // quantity 126
    refused(&[0x01, 0x03, 0x60, 0x00, 0x00], 3); // short PDU
    refused(&[0x01, 0x06, 0x60, 0x0C, 0x01, 0x01], 3); // resolution 257 is beyond 256
    refused(&[0x01, 0x06, 0x20, 0x28, 0x00, 0x80], 3); // node id 128
    refused(&[0x01, 0x06, 0x60, 0x07, 0x00, 0x07], 3); // no mode 7
    refused(&[0x01, 0x06, 0x60, 0x11, 0x01, 0x00], 3); // a U8 object gets 256
    // Speed 200001 pps in one atomic write.
    refused(&[0x01, 0x10, 0x60, 0x03, 0x00, 0x02, 0x04, 0x00, 0x03, 0x0D, 0x41], 3);
    // Low half completing an out-of-range value with the present high half (0).
    refused(&[0x01, 0x06, 0x60, 0x73, 0x00, 0x10], 3); // run speed 16 < 150
    // Byte count disagrees with the quantity.
    refused(&[0x01, 0x10, 0x60, 0x08, 0x00, 0x02, 0x02, 0x02, 0x58], 3);
    refused(&[0x01, 0x10, 0x60, 0x08, 0x00, 0x7C, 0xF8], 3); // quantity 124
    // All or nothing: a good value before a bad one is not written.
    refused(&[0x01, 0x10, 0x60, 0x08, 0x00, 0x04, 0x08, 0x01, 0x00, 0x01, 0x00, 0x00, 0x09, 0x00, 0x01], 3);
    refused(&[0x01, 0x08, 0x00, 0x0B, 0x00, 0x01], 3); // counter request with data other than 0
    refused(&[0x01, 0x2B, 0x0E, 0x05, 0x00], 3); // read device id code 5
    refused(&[0x01, 0x17, 0x60, 0x00, 0x00, 0x01, 0x60, 0x08, 0x00, 0x7A, 0xF4], 3); // write part 122
}

#[test]
fn server_device_failure_04() {
    // A drive on a platform without storage (the default configuration) cannot save; none has a
    // boot loader to jump to yet.
    refused(&[0x01, 0x06, 0x20, 0x0F, 0x00, 0x02], 4);
    refused(&[0x01, 0x06, 0x20, 0x0F, 0x00, 0x01], 4);
}

#[test]
fn read_write_checks_the_read_before_writing() {
    // 0x17 writing 0x6008 and reading past the last object: refused with 02, 0x6008 unchanged.
    refused(&[0x01, 0x17, 0x60, 0x90, 0x00, 0x01, 0x60, 0x08, 0x00, 0x01, 0x02, 0x01, 0x00], 2);
}

#[test]
fn silent_drops() {
    let good = frame(&[0x01, 0x06, 0x60, 0x0C, 0x00, 0x40]);
    let mut bad_crc = good.clone();
    *bad_crc.last_mut().unwrap() ^= 1;
    dropped(&bad_crc);
    dropped(&frame(&[0x02, 0x06, 0x60, 0x0C, 0x00, 0x40])); // another slave
    dropped(&frame(&[0x00, 0x03, 0x60, 0x0C, 0x00, 0x01])); // broadcast read: nothing to do
    dropped(&[0x01]); // too short to hold a CRC
    dropped(&[0x01, 0x7E, 0x80]); // a valid CRC but no function code
    dropped(&frame(&[0x01, 0x83, 0x02])); // an exception reply is not a request
    let mut long = vec![0x01, 0x10, 0x60, 0x1B, 0x00, 0x7B, 0xF6];
    long.resize(300, 0);
    dropped(&frame(&long)); // more than 256 bytes
}

#[test]
fn busy_bus_really_differs_from_factory() {
    // Guards the tests above: a snapshot must be able to see a change.
    assert_ne!(busy_bus().snapshot(), Bus::factory().snapshot());
    assert_eq!(busy_bus().drive.state().read(Obj::Microsteps), 32);
}

/// Each refusal of a valid value says why (a map turns the reason into its own code; the native
/// map answers 04 to all of them).
#[test]
fn refusals_say_why() {
    use drive_core::modes::PowerState;
    use drive_core::od::ObjError;
    use drive_core::{Drive, Instant};
    let mut drive = Drive::factory();
    drive.tick(Instant::from_micros(50));
    let st = drive.state_mut();
    // Speed 0, or another work mode's command: not now.
    assert_eq!(st.check(Obj::RelativeMove, 100), Err(ObjError::NotNow));
    st.apply(Obj::MaxSpeed, 4000);
    assert_eq!(st.check(Obj::RelativeMove, 100), Ok(()));
    assert!(st.check(Obj::SystemControl, 1) == Err(ObjError::Unsupported));
    // A latched error bit: faulted.
    st.status_mut().error = 0x01;
    assert_eq!(st.power_state(), PowerState::Faulted);
    assert_eq!(st.check(Obj::RelativeMove, 100), Err(ObjError::Faulted));
    st.status_mut().error = 0;
    // The power stage off: disabled.
    st.apply(Obj::Enable, 0);
    assert_eq!(st.power_state(), PowerState::Disabled);
    assert_eq!(st.check(Obj::RelativeMove, 100), Err(ObjError::Disabled));
    st.apply(Obj::Enable, 1);
    assert_eq!(st.power_state(), PowerState::On);
    // Moving: a save and a position set wait for rest.
    st.apply(Obj::RelativeMove, 100_000);
    drive.tick(Instant::from_micros(100));
    let st = drive.state_mut();
    assert_eq!(st.check(Obj::Position, 0), Err(ObjError::Busy));
    assert!(ObjError::Busy.is_refusal() && !ObjError::OutOfRange.is_refusal());
}
