//! Every frame of seed 000 §9.3 gets the reply printed in the manual, byte for byte.

mod common;
use common::Bus;
use drive_core::od::Obj;

const READ: [u8; 8] = [0x01, 0x03, 0x60, 0x0C, 0x00, 0x02, 0x1A, 0x08];
const READ_REPLY: [u8; 9] = [0x01, 0x03, 0x04, 0x00, 0x00, 0x04, 0x0A, 0x78, 0xF4];
const WRITE: [u8; 8] = [0x01, 0x06, 0x60, 0x0C, 0x00, 0x20, 0x56, 0x11];
const WRITE_MANY: [u8; 17] =
    [0x01, 0x10, 0x60, 0x0C, 0x00, 0x04, 0x08, 0x00, 0x00, 0x02, 0x92, 0x00, 0x00, 0x00, 0x00, 0x9F, 0xF5];
const WRITE_MANY_REPLY: [u8; 8] = [0x01, 0x10, 0x60, 0x0C, 0x00, 0x04, 0x1F, 0xC9];

fn exchange(bus: &mut Bus, frame: &[u8]) -> Option<Vec<u8>> {
    bus.send(frame);
    bus.wait(10_000).pop()
}

#[test]
fn read_600c_600d() {
    // The manual's drive had resolution 0 and a phase current of 0x040A = 1034 mA.
    let mut bus = Bus::factory();
    assert!(bus.request(&[0x01, 0x06, 0x60, 0x0D, 0x04, 0x0A]).is_some());
    assert_eq!(exchange(&mut bus, &READ).as_deref(), Some(&READ_REPLY[..]));
}

#[test]
fn write_600c() {
    let mut bus = Bus::factory();
    assert_eq!(exchange(&mut bus, &WRITE).as_deref(), Some(&WRITE[..]));
    assert_eq!(bus.drive.state().read(Obj::Microsteps), 32);
}

#[test]
fn write_600c_to_600f() {
    let mut bus = Bus::factory();
    bus.drive.state_mut().set_position(12345);
    assert_eq!(exchange(&mut bus, &WRITE_MANY).as_deref(), Some(&WRITE_MANY_REPLY[..]));
    let st = bus.drive.state();
    // The manual's text says 588 beside 0x0292; 0x0292 is 658, which is what the frame carries.
    assert_eq!((st.read(Obj::Microsteps), st.read(Obj::PhaseCurrent), st.read_i32(Obj::Position)), (0, 658, 0));
}

#[test]
fn section_9_4_writes_32_bit_objects_half_by_half() {
    // §9.4.1: speed 0x6003 (high) then 0x6004 (low), relative move 0x6005 then 0x6006.
    let mut bus = Bus::factory();
    for (reg, value) in [(0x600C, 0x0020), (0x600D, 0x03E8), (0x6003, 0x0000), (0x6004, 0x7D00), (0x6002, 0)] {
        let [rh, rl] = u16::to_be_bytes(reg);
        let [vh, vl] = u16::to_be_bytes(value);
        let req = [0x01, 0x06, rh, rl, vh, vl];
        assert_eq!(bus.request(&req), common::reply(&req));
    }
    assert_eq!(bus.drive.state().read_i32(Obj::MaxSpeed), 32000);
    assert!(bus.request(&[0x01, 0x06, 0x60, 0x05, 0x00, 0x00]).is_some());
    assert_eq!(bus.drive.state().read(Obj::RelativeMove), 0, "the high half alone is only staged");
    assert!(bus.request(&[0x01, 0x06, 0x60, 0x06, 0x7D, 0x00]).is_some());
    assert_eq!(bus.drive.state().read(Obj::RelativeMove), 32000);
}
