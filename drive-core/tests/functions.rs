//! Function codes beyond plain reads and writes: 0x17, 0x08 diagnostics, 0x2B/0x0E identification,
//! and the 32-bit object rules.

mod common;
use common::{Bus, frame, reply};
use drive_core::od::Obj;

#[test]
fn read_write_multiple_writes_then_reads() {
    let mut bus = Bus::factory();
    // Write 0x6008..9 = 1000, 2000; read 0x6008..B.
    let r = bus.request(&[0x01, 0x17, 0x60, 0x08, 0x00, 0x04, 0x60, 0x08, 0x00, 0x02, 0x04, 0x03, 0xE8, 0x07, 0xD0]);
    assert_eq!(r, reply(&[0x01, 0x17, 0x08, 0x03, 0xE8, 0x07, 0xD0, 0x00, 0x08, 0x00, 0x08]));
}

#[test]
fn read_125_registers_across_reserved_ones() {
    let mut bus = Bus::factory();
    bus.drive.state_mut().set_position(-3);
    let r = bus.request(&[0x01, 0x03, 0x60, 0x00, 0x00, 0x7D]).expect("answered");
    assert_eq!((r.len(), r[2]), (3 + 250 + 2, 250));
    let reg = |a: usize| u16::from_be_bytes([r[3 + 2 * a], r[4 + 2 * a]]);
    assert_eq!(reg(0x08), 600, "start speed");
    assert_eq!(reg(0x0D), 658, "phase current");
    assert_eq!((reg(0x0E), reg(0x0F)), (0xFFFF, 0xFFFD), "position -3, high word first");
    assert_eq!(reg(0x12), 0, "0x6012 is reserved");
    assert_eq!((reg(0x6D), reg(0x6E)), (0, 600), "PP stop speed");
}

#[test]
fn reserved_registers_cannot_be_written() {
    let mut bus = Bus::factory();
    assert_eq!(bus.request(&[0x01, 0x06, 0x60, 0x12, 0x00, 0x00]), reply(&[0x01, 0x86, 0x02]));
}

#[test]
fn diagnostics_echo_and_counters() {
    let mut bus = Bus::factory();
    let echo = [0x01, 0x08, 0x00, 0x00, 0xA5, 0x37, 0x12, 0x34];
    assert_eq!(bus.request(&echo), reply(&echo));
    bus.send(&[0x01, 0x02]); // a frame with a bad CRC
    bus.wait(10_000);
    bus.request(&[0x02, 0x03, 0x60, 0x00, 0x00, 0x01]); // for another slave
    bus.request(&[0x01, 0x63, 0x00]); // exception 01
    bus.request(&[0x00, 0x06, 0x60, 0x08, 0x01, 0x00]); // broadcast
    let counter = |bus: &mut Bus, sub: u8| {
        let r = bus.request(&[0x01, 0x08, 0x00, sub, 0x00, 0x00]).expect("answered");
        u16::from_be_bytes([r[4], r[5]])
    };
    // Each counter request is itself a message to this slave, counted before it is answered.
    assert_eq!(counter(&mut bus, 0x0B), 5, "bus messages: echo, other slave, exception, broadcast, this");
    assert_eq!(counter(&mut bus, 0x0C), 1, "bus errors");
    assert_eq!(counter(&mut bus, 0x0D), 1, "exceptions");
    assert_eq!(counter(&mut bus, 0x0E), 7, "slave messages");
    assert_eq!(counter(&mut bus, 0x0F), 1, "no response: the broadcast");
    assert_eq!(counter(&mut bus, 0x10), 0);
    assert_eq!(counter(&mut bus, 0x11), 0);
    assert_eq!(counter(&mut bus, 0x12), 0);
    assert_eq!(bus.request(&[0x01, 0x08, 0x00, 0x0A, 0x00, 0x00]), reply(&[0x01, 0x08, 0x00, 0x0A, 0x00, 0x00]));
    assert_eq!(counter(&mut bus, 0x0E), 1);
}

#[test]
fn listen_only_until_restart() {
    let mut bus = Bus::factory();
    assert_eq!(bus.request(&[0x01, 0x08, 0x00, 0x04, 0x00, 0x00]), None);
    assert_eq!(bus.request(&[0x01, 0x06, 0x60, 0x08, 0x01, 0x00]), None);
    assert_eq!(bus.drive.state().read(Obj::StartSpeed), 600, "listen-only executes no write");
    assert_eq!(bus.request(&[0x01, 0x08, 0x00, 0x01, 0x00, 0x00]), None, "restart is not answered");
    let restart = [0x01, 0x08, 0x00, 0x01, 0xFF, 0x00];
    assert_eq!(bus.request(&restart), reply(&restart));
}

#[test]
fn device_identification() {
    let mut bus = Bus::factory();
    let r = bus.request(&[0x01, 0x2B, 0x0E, 0x01, 0x00]).expect("answered");
    let id = drive_core::ident::Identity::SIMULATOR;
    let mut want = vec![0x01, 0x2B, 0x0E, 0x01, 0x82, 0x00, 0x00, 0x03];
    for (i, s) in [id.vendor_name, id.product_code, id.revision].iter().enumerate() {
        want.extend([i as u8, s.len() as u8]);
        want.extend(s.as_bytes());
    }
    assert_eq!(r, frame(&want));
    // Regular: 7 objects; individual: just the one.
    let r = bus.request(&[0x01, 0x2B, 0x0E, 0x02, 0x00]).expect("answered");
    assert_eq!(r[7], 7);
    let r = bus.request(&[0x01, 0x2B, 0x0E, 0x04, 0x04]).expect("answered");
    assert_eq!(&r[7..10], &[1, 4, id.product_name.len() as u8]);
    // Stream access asked for an object outside the category restarts at 0.
    let r = bus.request(&[0x01, 0x2B, 0x0E, 0x01, 0x05]).expect("answered");
    assert_eq!((r[7], r[8]), (3, 0));
}

#[test]
fn text_objects_read_as_ascii() {
    let mut bus = Bus::factory();
    let r = bus.request(&[0x01, 0x03, 0x10, 0x22, 0x00, 0x04]).expect("answered");
    assert_eq!(&r[3..11], b"SIM1V010");
}

#[test]
fn high_half_stages_low_half_commits() {
    let mut bus = Bus::factory();
    // Negative speed, half by half: -1000 = 0xFFFF_FC18.
    bus.request(&[0x01, 0x06, 0x60, 0x03, 0xFF, 0xFF]);
    assert_eq!(bus.drive.state().read_i32(Obj::MaxSpeed), 0);
    assert_eq!(bus.request(&[0x01, 0x03, 0x60, 0x03, 0x00, 0x02]), reply(&[0x01, 0x03, 0x04, 0, 0, 0, 0]));
    bus.request(&[0x01, 0x06, 0x60, 0x04, 0xFC, 0x18]);
    assert_eq!(bus.drive.state().read_i32(Obj::MaxSpeed), -1000);
    // A low half alone completes with the present high half.
    bus.request(&[0x01, 0x06, 0x60, 0x04, 0xFF, 0x38]);
    assert_eq!(bus.drive.state().read_i32(Obj::MaxSpeed), -200);
    // A rejected completion keeps the staged half: a corrected low half then succeeds.
    bus.request(&[0x01, 0x06, 0x60, 0x03, 0x00, 0x04]); // stage 0x0004_xxxx
    assert_eq!(bus.request(&[0x01, 0x06, 0x60, 0x04, 0x00, 0x00]), reply(&[0x01, 0x86, 0x03]), "262144 > 200000");
    assert_eq!(bus.drive.state().read_i32(Obj::MaxSpeed), -200);
    bus.request(&[0x01, 0x06, 0x60, 0x03, 0x00, 0x02]);
    bus.request(&[0x01, 0x06, 0x60, 0x04, 0x71, 0x00]);
    assert_eq!(bus.drive.state().read_i32(Obj::MaxSpeed), 160_000);
}

#[test]
fn status_bits_clear_by_writing_one() {
    let mut bus = Bus::factory();
    let s = bus.drive.state_mut().status_mut();
    s.error = 0b10_0011;
    s.controller = 0b1100; // stall and busy
    bus.request(&[0x01, 0x06, 0x60, 0x00, 0x00, 0x21]);
    bus.request(&[0x01, 0x06, 0x60, 0x01, 0x00, 0xFF]);
    let st = bus.drive.state().status();
    assert_eq!((st.error, st.controller), (0b10, 0b1000), "busy cannot be cleared");
}

#[test]
fn writing_position_sets_it() {
    let mut bus = Bus::factory();
    bus.request(&[0x01, 0x10, 0x60, 0x0E, 0x00, 0x02, 0x04, 0xFF, 0xFF, 0xFF, 0xFE]);
    assert_eq!(bus.drive.state().position(), -2);
}

#[test]
fn factory_restore_resets_rom_objects() {
    let mut bus = Bus::factory();
    bus.request(&[0x01, 0x06, 0x60, 0x0A, 0x00, 0x02]); // ROM
    bus.request(&[0x01, 0x06, 0x60, 0x02, 0x00, 0x01]); // RAM
    assert!(bus.request(&[0x01, 0x06, 0x20, 0x0F, 0x00, 0x03]).is_some());
    let st = bus.drive.state();
    assert_eq!((st.read(Obj::AccelLevel), st.read(Obj::Direction)), (8, 1));
}
