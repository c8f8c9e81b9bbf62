//! The EC-57 map (seed 003) at the level of frames: every frame §1.3 prints, byte for byte; each
//! exception of §1.3.4 with nothing changed; the (index, sub-index) walk; the native window;
//! the address source at power-up; and the table's objects acting on the drive.

mod common;

use common::{MapRig, frame};
use drive_core::maps::Maps;
use drive_core::od::Obj;
use drive_core::{Drive, DriveConfig, Params};

/// A fresh EC-57 drive (nothing saved: the manual's factory values) that can save, 1 ms after
/// power-up.
fn rig() -> MapRig {
    let config = DriveConfig { can_save: true, ..DriveConfig::default() };
    let empty = drive_core::drive::STORAGE_EMPTY;
    MapRig::with_drive(Drive::boot_with_map(config, Maps::ec57(), &Params::factory(), empty))
}

/// The frame the manual prints, as hex text, in bytes.
fn hex(text: &str) -> Vec<u8> {
    text.split_whitespace().map(|b| u8::from_str_radix(b, 16).expect("hex")).collect()
}

impl MapRig {
    /// Sends the manual's request and returns the reply.
    fn manual(&mut self, request: &str) -> Option<Vec<u8>> {
        self.exchange(&hex(request))
    }

    /// Every object's value but the diagnostics' ([`Obj::is_diagnostic`]).
    fn objects(&self) -> Vec<u32> {
        let st = self.drive.state();
        drive_core::od::OBJECTS.iter().filter(|d| !d.obj.is_diagnostic()).map(|d| st.read(d.obj)).collect()
    }

    /// Reads `n` registers from (index, sub); the values or the exception code.
    fn read_sub(&mut self, index: u16, sub: u8, n: u16) -> Result<Vec<u16>, u8> {
        let [a, b] = index.to_be_bytes();
        let [c, d] = n.to_be_bytes();
        let pdu = self.request(&[1, 0x03, a, b, sub, c, d])?;
        Ok(pdu[2..].chunks(2).map(|w| u16::from_be_bytes([w[0], w[1]])).collect())
    }

    /// Saves with 0x2030 = 1: the parameters the platform is then asked to save.
    fn saved(&mut self) -> Params {
        self.write_sub(0x2030, 0, 1).expect("save");
        assert_eq!(self.drive.take_system_request(), Some(drive_core::SystemRequest::Save));
        self.drive.state().params()
    }

    /// Writes one register at (index, sub); the exception code if refused.
    fn write_sub(&mut self, index: u16, sub: u8, v: u16) -> Result<(), u8> {
        let [a, b] = index.to_be_bytes();
        let [c, d] = v.to_be_bytes();
        let pdu = self.request(&[1, 0x06, a, b, sub, c, d])?;
        assert_eq!(pdu, [0x06, a, b, sub, c, d], "a write's reply echoes it");
        Ok(())
    }
}

#[test]
fn every_printed_frame_byte_for_byte() {
    let mut r = rig();
    // §1.3.1 (1).
    assert_eq!(r.manual("01 03 20 00 00 00 01 4B F4"), Some(hex("01 03 02 00 01 79 84")));
    // §1.3.1 (2) reads 0x2000, 0x2001, 0x2002 and 0x2003.1 as 1, 2, 0 and 500: set them so.
    r.write_sub(0x2001, 0, 2).expect("address source 2");
    r.write_sub(0x2003, 1, 500).expect("standstill delay");
    assert_eq!(r.manual("01 03 20 00 00 00 04 8B F7"), Some(hex("01 03 08 00 01 00 02 00 00 01 F4 FC C0")));
    // §1.3.2: 0x2005 = 10 000 pulses a revolution.
    assert_eq!(r.manual("01 06 20 05 00 27 10 90 91"), Some(hex("01 06 20 05 00 27 10 90 91")));
    assert_eq!(r.drive.state().read(Obj::Microsteps), 50);
    assert_eq!(r.read_sub(0x2005, 0, 1), Ok(vec![10_000]));
    // 0x2003.1 = 50 ms.
    assert_eq!(r.manual("01 06 20 03 01 00 32 5A 30"), Some(hex("01 06 20 03 01 00 32 5A 30")));
    assert_eq!(r.drive.state().read(Obj::IdleDelay), 50);
    // 0x2030 = 1 saves.
    assert_eq!(r.manual("01 06 20 30 00 00 01 44 A1"), Some(hex("01 06 20 30 00 00 01 44 A1")));
    assert_eq!(r.drive.take_system_request(), Some(drive_core::SystemRequest::Save));
    r.drive.save_done(true);
    // §1.3.3: 0x2000 = 1 and 0x2001 = 1 in one request.
    assert_eq!(r.manual("01 10 20 00 00 00 02 04 00 01 00 01 AC 49"), Some(hex("01 10 20 00 00 00 02 09 56")));
    assert_eq!(r.drive.state().read(Obj::AddressSource), 1);
}

#[test]
fn each_exception_of_the_manual_changes_nothing() {
    let mut r = rig();
    let before = r.objects();
    // (1) A wrong CRC is dropped (the text)...
    assert_eq!(r.manual("01 03 20 00 00 00 01 4B F3"), None);
    // (2)-(6) as printed.
    assert_eq!(r.manual("01 02 00 00 00 00 04 0B E1"), Some(hex("01 82 02 C1 61")));
    assert_eq!(r.manual("01 03 20 31 00 00 01 45 08"), Some(hex("01 83 03 01 31")));
    assert_eq!(r.manual("01 03 20 00 00 00 20 8B EC"), Some(hex("01 83 04 40 F3")));
    assert_eq!(r.manual("01 03 20 30 00 00 01 44 F4"), Some(hex("01 83 05 81 33")));
    assert_eq!(r.manual("01 06 20 01 00 00 08 8A 5B"), Some(hex("01 86 06 C2 62")));
    assert_eq!(r.objects(), before);
    // ... or answered with 01 as the example does, once 0x21D2 (in the window) says so.
    r.write_sub(0x21D2, 0xFF, 1).expect("CRC error answer");
    assert_eq!(r.manual("01 03 20 00 00 00 01 4B F3"), Some(hex("01 83 01 80 F0")));
    // Not for another drive's frame.
    assert_eq!(r.exchange(&hex("02 03 20 00 00 00 01 4B F3")), None);
}

#[test]
fn more_refusals_in_the_manuals_codes() {
    let mut r = rig();
    let before = r.objects();
    // Read-only registers refuse writes (05), the bus voltage say.
    assert_eq!(r.write_sub(0x200D, 0, 1), Err(5));
    // 0x2003 has no sub-index 0; 0x2000 no 1; sub-indices beyond 15 do not exist.
    assert_eq!(r.read_sub(0x2003, 0, 1), Err(3));
    assert_eq!(r.read_sub(0x2000, 1, 1), Err(3));
    assert_eq!(r.read_sub(0x2000, 0x10, 1), Err(3));
    // None, or 17, registers: 04; a write of 17 too.
    assert_eq!(r.read_sub(0x2000, 0, 0), Err(4));
    assert_eq!(r.read_sub(0x2000, 0, 17), Err(4));
    let mut body = vec![1, 0x10, 0x20, 0x00, 0x00, 0x00, 17, 34];
    body.extend([0u8; 34]);
    assert_eq!(r.request(&body), Err(4));
    // A byte count that is not the quantity's: 06.
    assert_eq!(r.request(&[1, 0x10, 0x20, 0x00, 0x00, 0x00, 0x01, 0x04, 0x00, 0x01]), Err(6));
    // A run of the walk past the table's end: 03.
    assert_eq!(r.read_sub(0x2030, 0, 1), Err(5));
    assert_eq!(r.read_sub(0x2025, 3, 2), Err(5), "0x2030 follows 0x2025.3: write only");
    // Not a multiple of 200 pulses a revolution, a function the drive has no such code for.
    assert_eq!(r.write_sub(0x2005, 0, 10_001), Err(6));
    assert_eq!(r.write_sub(0x2022, 1, 3), Err(6));
    // All or nothing: 0x2000 = 7 and then 0x2001 = 9 (out of range) changes neither.
    assert_eq!(r.request(&[1, 0x10, 0x20, 0x00, 0x00, 0x00, 0x02, 0x04, 0x00, 0x07, 0x00, 0x09]), Err(6));
    // Functions the manual does not list: 02.
    assert_eq!(r.request(&[1, 0x04, 0x20, 0x00, 0x00, 0x00, 0x01]), Err(2));
    assert_eq!(r.request(&[1, 0x17, 0x20, 0x00, 0x00, 0x00, 0x01]), Err(2));
    // A window refusal in this map's codes: no native register 0x6004 (02 → 03), a value out of
    // range (03 → 06).
    assert_eq!(r.read_sub(0x6000, 0xFF, 1).map(|_| ()), Ok(()));
    assert_eq!(r.write_sub(0x600C, 0xFF, 257), Err(6));
    assert_eq!(r.read_sub(0x2000, 0xFF, 1), Err(3), "the window holds native registers only");
    assert_eq!(r.objects(), before);
    // The saving refusal: 0x2030 while the motor runs.
    r.write_sub(0x21A3, 0xFF, 0).expect("velocity high");
    r.write_sub(0x21A4, 0xFF, 2000).expect("velocity low");
    r.write_sub(0x21A0, 0xFF, 3).expect("run");
    r.run(20_000);
    assert_eq!(r.write_sub(0x2030, 0, 1), Err(6));
    assert_eq!(r.drive.take_system_request(), None);
}

#[test]
fn requests_walk_the_index_and_sub_index_order() {
    let mut r = rig();
    r.write_sub(0x2003, 2, 40).expect("standstill current");
    // 0x2003.1, 0x2003.2, 0x2004, 0x2005: the factory 50 ms, 40 %, 1000 mA, 10 000 pulses.
    assert_eq!(r.read_sub(0x2003, 1, 4), Ok(vec![50, 40, 1000, 10_000]));
    // A write across sub-indices and indices: 0x2003.2 = 60, 0x2004 = 1500.
    assert!(r.request(&[1, 0x10, 0x20, 0x03, 0x02, 0x00, 0x02, 0x04, 0x00, 60, 0x05, 0xDC]).is_ok());
    assert_eq!(r.drive.state().read(Obj::IdleCurrent), 60);
    assert_eq!(r.drive.state().read(Obj::PhaseCurrent), 1500);
    // The versions, 0x201A.1-3.
    let v = r.read_sub(0x201A, 1, 3).expect("versions");
    assert_eq!(v[0], r.drive.state().read(Obj::SoftwareRevision) as u16);
    assert_eq!(v[1], r.drive.state().read(Obj::HardwareRevision) as u16);
}

#[test]
fn the_window_moves_the_motor() {
    let mut r = rig();
    // 0x21A1 (command target, two registers) = 3200, then command 2 (relative run).
    let pdu = r.request(&[1, 0x10, 0x21, 0xA1, 0xFF, 0x00, 0x02, 0x04, 0x00, 0x00, 0x0C, 0x80]).expect("target");
    assert_eq!(pdu, [0x10, 0x21, 0xA1, 0xFF, 0x00, 0x02]);
    r.write_sub(0x21A0, 0xFF, 2).expect("relative run");
    for _ in 0..400 {
        r.run(10_000);
    }
    assert_eq!(r.drive.state().read_i32(Obj::Position), 3200);
    // The native map's registers read back through the window.
    assert_eq!(r.read_sub(0x600E, 0xFF, 2), Ok(vec![0, 3200]));
    // The position commands received: 3200, high word first over 0x2010 and 0x2011.
    assert_eq!(r.read_sub(0x2010, 0, 2), Ok(vec![0, 3200]));
    // Back by 4200 (a relative run of -4200): -1000 over the two words.
    let back = (-4200i32).to_be_bytes();
    r.request(&[1, 0x10, 0x21, 0xA1, 0xFF, 0x00, 0x02, 0x04, back[0], back[1], back[2], back[3]]).expect("target");
    r.write_sub(0x21A0, 0xFF, 2).expect("relative run");
    for _ in 0..400 {
        r.run(10_000);
    }
    assert_eq!(r.read_sub(0x2010, 0, 2), Ok(vec![0xFFFF, (-1000i16) as u16]));
    // A preset of the position is no motion.
    r.write_sub(0x6007, 0xFF, 0).expect("position mode");
    r.request(&[1, 0x10, 0x60, 0x0E, 0xFF, 0x00, 0x02, 0x04, 0x00, 0x01, 0x00, 0x00]).expect("preset");
    assert_eq!(r.read_sub(0x2010, 0, 2), Ok(vec![0xFFFF, (-1000i16) as u16]));
    // Writing 1 to 0x2011 clears; other values and 0x2010 are refused.
    assert_eq!(r.write_sub(0x2011, 0, 2), Err(6));
    assert_eq!(r.write_sub(0x2010, 0, 0), Err(5));
    r.write_sub(0x2011, 0, 1).expect("clear");
    assert_eq!(r.read_sub(0x2010, 0, 2), Ok(vec![0, 0]));
    // The fault list is empty, and the speed at rest 0.
    assert_eq!(r.read_sub(0x201C, 1, 9), Ok(vec![0; 9]));
    assert_eq!(r.read_sub(0x2017, 0, 1), Ok(vec![0]));
}

#[test]
fn an_over_voltage_lands_in_the_fault_list_and_0x201e_clears_it() {
    let mut r = rig();
    r.inputs.supply_mv = Some(70_000);
    r.run(5_000);
    r.inputs.supply_mv = Some(24_000);
    r.run(5_000);
    assert_eq!(r.read_sub(0x201C, 1, 2), Ok(vec![14, 0]), "over-voltage, alarm 14, newest first");
    assert_ne!(r.drive.state().read(Obj::AlarmCode), 0);
    assert_eq!(r.read_sub(0x200D, 0, 1), Ok(vec![24]), "bus voltage, V");
    r.write_sub(0x201E, 0, 1).expect("clear the alarm");
    assert_eq!(r.drive.state().read(Obj::AlarmCode), 0);
    assert_eq!(r.read_sub(0x201C, 1, 1), Ok(vec![14]), "the list keeps it");
    let count = r.drive.state().read(Obj::AlarmCount);
    // 0x201D = 1 empties the list at once, and asks for its save.
    while r.drive.take_system_request().is_some() {}
    r.write_sub(0x201D, 0, 1).expect("clear the history");
    assert_eq!(r.read_sub(0x201C, 1, 9), Ok(vec![0; 9]));
    assert_eq!(r.drive.take_system_request(), Some(drive_core::SystemRequest::SaveFaults));
    assert_eq!(r.drive.state().fault_history().entries, [0; 10]);
    r.run(1_000);
    assert_eq!(r.read_sub(0x201C, 1, 9), Ok(vec![0; 9]), "the tick's history is empty too");
    assert_eq!(r.drive.state().read(Obj::AlarmCount), count, "the count goes on");
    // A new alarm lands in the emptied list.
    r.inputs.supply_mv = Some(70_000);
    r.run(5_000);
    assert_eq!(r.read_sub(0x201C, 1, 2), Ok(vec![14, 0]));
}

#[test]
fn io_settings_act_in_the_drives_terms() {
    let mut r = rig();
    // IN1 a positive limit, IN2 quick stop, OUT1 in position, OUT1 high when on.
    r.write_sub(0x2022, 1, 2).expect("IN1");
    r.write_sub(0x2022, 2, 8).expect("IN2");
    r.write_sub(0x2025, 1, 2).expect("OUT1");
    r.write_sub(0x2024, 0, 1).expect("output polarity");
    let st = r.drive.state();
    assert_eq!((st.read(Obj::InputFunction1), st.read(Obj::InputFunction2)), (9, 7));
    assert_eq!(st.read(Obj::OutputFunction1), 3);
    assert_eq!(st.read(Obj::OutputLogic), 0b110, "OUT1 high when on: the drive's logic bit clear");
    assert_eq!(r.read_sub(0x2024, 0, 1), Ok(vec![1]));
    // The input states: IN1 active.
    r.write_sub(0x21C2, 0xFF, 1).expect("pseudo-input IN1");
    assert_eq!(r.read_sub(0x2014, 0, 1), Ok(vec![1]));
    // Touch probe 2 on IN3 (64: the drive's 22).
    r.write_sub(0x2022, 3, 64).expect("IN3 probe 2");
    assert_eq!(r.drive.state().read(Obj::InputFunction3), 22);
    assert_eq!(r.read_sub(0x2022, 3, 1), Ok(vec![64]));
    // The factory defaults of the manual: IN1 probe 1, IN2 origin, IN3 and IN4 the limits, OUT2
    // alarm.
    let r = rig();
    let st = r.drive.state();
    assert_eq!(
        [Obj::InputFunction1, Obj::InputFunction2, Obj::InputFunction3, Obj::InputFunction4, Obj::OutputFunction2]
            .map(|o| st.read(o)),
        [21, 11, 9, 10, 2]
    );
}

#[test]
fn the_address_follows_its_source_at_power_up() {
    let boot = |source: u32| {
        let mut params = Params::factory();
        params.set(Obj::NodeId, 5);
        params.set(Obj::AddressSource, source);
        let drive = Drive::boot_with_map(DriveConfig::default(), Maps::ec57(), &params, 0);
        drive.address().get()
    };
    assert_eq!(boot(0), 1, "the serial port's fixed address");
    assert_eq!(boot(1), 5);
    assert_eq!(boot(2), 5);
    // Other maps answer at the node id whatever the source.
    let mut params = Params::factory();
    params.set(Obj::NodeId, 5);
    assert_eq!(Drive::boot_with_map(DriveConfig::default(), Maps::cls9(), &params, 0).address().get(), 5);
    // The frame helper stays in use for a broadcast write: executed, not answered.
    let mut r = rig();
    assert_eq!(r.exchange(&frame(&[0, 0x06, 0x20, 0x03, 0x01, 0x00, 0x64])), None);
    assert_eq!(r.drive.state().read(Obj::IdleDelay), 100);
}

/// 0x2013 = 1, saved: at power-up the motor turns 30° forward, then 15° back, and stands; with a
/// 10 000-pulse revolution that is 833 then back to 417. A drive powered up with it off stands.
#[test]
fn the_power_up_jog() {
    let boot = |jog: u32| {
        let mut params = Params::factory();
        assert!(params.set(Obj::PowerUpJog, jog));
        assert!(params.set(Obj::Microsteps, 50));
        MapRig::with_drive(Drive::boot_with_map(DriveConfig::default(), Maps::ec57(), &params, 0))
    };
    let mut r = boot(1);
    let mut farthest = 0;
    for _ in 0..60_000 {
        r.run(50);
        farthest = farthest.max(r.drive.state().read_i32(Obj::Position));
    }
    assert_eq!(farthest, 10_000 / 12, "30° forward");
    assert_eq!(r.drive.state().read_i32(Obj::Position), 10_000 / 12 - 10_000 / 24, "15° back");
    assert_eq!(r.read_sub(0x2013, 0, 1), Ok(vec![1]));
    let mut r = boot(0);
    r.run(1_000_000);
    assert_eq!(r.drive.state().read_i32(Obj::Position), 0);
    // A stop during the first move ends the jog: no move back.
    let mut r = boot(1);
    r.run(100_000);
    r.write_sub(0x21A0, 0xFF, 6).expect("stop");
    r.run(500_000);
    let stopped = r.drive.state().read_i32(Obj::Position);
    assert!((1..10_000 / 12).contains(&stopped), "stopped on the way: {stopped}");
    r.run(1_000_000);
    assert_eq!(r.drive.state().read_i32(Obj::Position), stopped);
}

/// 0x200B/0x200C: the soft start's time and switch, in the manual's range (10-3000 ms), on the
/// drive's 0x21E0/0x21E1; the output stage's current rises over the time at the next enable.
#[test]
fn the_soft_start_registers() {
    let mut r = rig();
    assert_eq!(r.read_sub(0x200B, 0, 2), Ok(vec![100, 0]), "0x200B then 0x200C");
    assert_eq!(r.write_sub(0x200B, 0, 5), Err(0x06), "below the manual's 10 ms");
    assert_eq!(r.write_sub(0x200C, 0, 2), Err(0x06));
    r.write_sub(0x200B, 0, 400).expect("400 ms");
    r.write_sub(0x200C, 0, 1).expect("on");
    let st = r.drive.state();
    assert_eq!((st.read(Obj::SoftStartTime), st.read(Obj::SoftStart)), (400, 1));
    // The current the output stage drives at the next tick.
    let current = |r: &mut MapRig| {
        r.now += 50;
        let out = r.drive.tick_with(drive_core::Instant::from_micros(r.now), &r.inputs);
        u32::from(out.current_ma)
    };
    // The standing motor's current: 0x2003.2's half of 0x2004's.
    let standing = current(&mut r);
    assert_eq!(standing, 500);
    // Freed, then energised again: the enable acts at its frame's t3.5 (4 ms at 9600 baud) of
    // the 10 ms an exchange runs; 94 ms more are a quarter of the ramp.
    r.write_sub(0x6011, 0xFF, 0).expect("free");
    assert_eq!(current(&mut r), 0);
    r.write_sub(0x6011, 0xFF, 1).expect("enable");
    r.run(94_000);
    let quarter = current(&mut r);
    assert!(quarter.abs_diff(standing / 4) <= standing / 50, "{quarter} of {standing} mA");
    r.run(300_000);
    assert_eq!(current(&mut r), standing);
}

/// What a platform that ends requests by their length asks of the drive's map: the sub-index
/// byte after the register, in this map alone.
#[test]
fn the_sub_index_is_one_byte_after_the_register() {
    use drive_core::maps::{NAMES, RegisterMap};
    for (id, name) in NAMES.iter().enumerate() {
        assert_eq!(Maps::by_id(id as u32).address_extra(), usize::from(*name == "ec57"), "{name}");
    }
    assert_eq!(rig().drive.map().address_extra(), 1);
}

#[test]
fn the_current_loop_registers() {
    let mut r = rig();
    // The manual's factory values: the tune on, KP 300, KI 30; Kc the loop's correction, 250‰.
    assert_eq!(r.read_sub(0x2007, 0, 4), Ok(vec![1, 300, 30, 250]));
    // A drive whose power stage is an external driver runs no current loop: refused (06).
    let before = r.objects();
    assert_eq!(r.write_sub(0x2007, 0, 0), Err(6));
    assert_eq!(r.objects(), before);
    r.drive.state_mut().set_current_loop(true);
    // While the tune is on, the gains are its: read only (05). Kc always is.
    assert_eq!(r.write_sub(0x2008, 0, 400), Err(5));
    assert_eq!(r.write_sub(0x200A, 0, 100), Err(5));
    assert_eq!(r.write_sub(0x2007, 0, 2), Err(6), "0-1");
    assert_eq!(r.objects(), before);
    // The tune off, the gains are written within their ranges and read back.
    assert_eq!(r.write_sub(0x2007, 0, 0), Ok(()));
    assert_eq!(r.write_sub(0x2008, 0, 49), Err(6), "50-32767");
    assert_eq!(r.write_sub(0x2009, 0, 2001), Err(6), "10-2000");
    assert_eq!(r.write_sub(0x2008, 0, 764), Ok(()));
    assert_eq!(r.write_sub(0x2009, 0, 112), Ok(()));
    assert_eq!(r.read_sub(0x2007, 0, 3), Ok(vec![0, 764, 112]));
    // The native objects they are.
    let st = r.drive.state();
    assert_eq!((st.read(Obj::CurrentAutoTune), st.read(Obj::CurrentKp), st.read(Obj::CurrentKi)), (0, 764, 112));
}

/// 0x2012 and 0x201F: a motion beyond the overspeed limit moves nothing and reads 30; one
/// within it moves and reads 0; a limit lowered under the running speed latches the overspeed
/// alarm (31) and stops the motor; the limit is saved with 0x2030.
#[test]
fn the_overspeed_limit_and_the_not_moving_code() {
    let mut r = rig();
    assert_eq!(r.read_sub(0x2012, 0, 1), Ok(vec![1600]), "the manual's factory value");
    assert_eq!(r.read_sub(0x201F, 0, 1), Ok(vec![0]));
    assert_eq!(r.write_sub(0x2012, 0, 3001), Err(0x06));
    assert_eq!(r.write_sub(0x201F, 0, 0), Err(0x05), "read only");
    // 60 r/min at 10 000 pulses a revolution: 10 000 pulses a second.
    r.write_sub(0x2012, 0, 60).expect("60 r/min");
    let speed = |r: &mut MapRig, pps: i32| {
        let [a, b, c, d] = pps.to_be_bytes();
        r.request(&[1, 0x10, 0x60, 0x03, 0xFF, 0x00, 0x02, 0x04, a, b, c, d]).expect("speed");
    };
    let relative = |r: &mut MapRig, steps: i32| {
        let [a, b, c, d] = steps.to_be_bytes();
        r.request(&[1, 0x10, 0x60, 0x05, 0xFF, 0x00, 0x02, 0x04, a, b, c, d]).map(|_| ())
    };
    speed(&mut r, 12_000);
    let before = r.objects();
    assert_eq!(relative(&mut r, 5_000), Err(0x06), "72 r/min asked");
    r.run(100_000);
    assert_eq!(r.drive.state().read_i32(Obj::Position), 0, "nothing moved");
    assert_eq!(r.read_sub(0x201F, 0, 1), Ok(vec![30]));
    assert_eq!(r.objects(), before, "and nothing else changed");
    // Within it: the move runs, and the code is 0 again.
    speed(&mut r, 9_000);
    relative(&mut r, 5_000).expect("54 r/min");
    assert_eq!(r.read_sub(0x201F, 0, 1), Ok(vec![0]));
    r.run(3_000_000);
    assert_eq!(r.drive.state().read_i32(Obj::Position), 5_000);
    // The limit lowered under a running move's speed: the factory mask (0x201B = 0xC3) does not
    // detect the command overspeed, and the motor runs on; with bit 3 set the alarm stops it.
    relative(&mut r, 20_000).expect("54 r/min");
    // Cruising at 54 r/min after the ramp (0x600A's level 8, 5 210 pulses a second squared).
    r.run(2_500_000);
    r.write_sub(0x2012, 0, 30).expect("30 r/min");
    r.run(20_000);
    assert_eq!(r.read_sub(0x201C, 1, 1), Ok(vec![0]), "not detected");
    let running = r.drive.state().read_i32(Obj::Position);
    assert_eq!(r.read_sub(0x201B, 0, 1), Ok(vec![0xC3]));
    r.write_sub(0x201B, 0, 0xC3 | 0x08).expect("detect the command overspeed");
    r.run(20_000);
    let stopped = r.drive.state().read_i32(Obj::Position);
    assert!(running < stopped && stopped < 25_000, "{running} {stopped}");
    assert_eq!(r.read_sub(0x201C, 1, 1), Ok(vec![31]), "the overspeed alarm in the fault list");
    r.run(100_000);
    assert_eq!(r.drive.state().read_i32(Obj::Position), stopped, "stopped where it was");
    // Saved with the rest.
    r.write_sub(0x2012, 0, 1200).expect("1200 r/min");
    assert_eq!(r.saved().get(Obj::OverspeedLimit), 1200);
}

/// 0x201B: a cleared bit keeps its detection from latching (the over-voltage, the EEPROM, the
/// op-amp fault); the hardware over-current trip latches whatever the mask; the unnamed bits
/// with no detection are refused; the mask is saved with 0x2030.
#[test]
fn the_fault_detection_mask() {
    let mut r = rig();
    assert_eq!(r.read_sub(0x201B, 0, 1), Ok(vec![0xC3]), "the manual's factory value");
    for unnamed in [1u16 << 4, 1 << 5, 1 << 8, 1 << 10, 1 << 15] {
        assert_eq!(r.write_sub(0x201B, 0, 0xC3 | unnamed), Err(0x06), "{unnamed:#x}");
    }
    // Over-voltage masked (bit 1 clear): 70 V latches nothing, and the motor stays powered.
    r.write_sub(0x201B, 0, 0xC1).expect("mask the over-voltage");
    r.inputs.supply_mv = Some(70_000);
    r.run(5_000);
    assert_eq!(r.read_sub(0x201C, 1, 1), Ok(vec![0]), "masked: no alarm");
    assert_eq!(r.drive.state().read(Obj::AlarmCode), 0);
    // Unmasked, the same supply latches alarm 14.
    r.write_sub(0x201B, 0, 0xC3).expect("detect it again");
    r.run(5_000);
    assert_eq!(r.read_sub(0x201C, 1, 1), Ok(vec![14]));
    r.inputs.supply_mv = Some(24_000);
    r.write_sub(0x201E, 0, 1).expect("clear the alarm");
    // The op-amp fault (bit 11): the sensing's check at power-up failed.
    r.inputs.sensing_fault = true;
    r.run(5_000);
    assert_eq!(r.drive.state().read(Obj::AlarmCode), 0, "not detected from the factory");
    r.write_sub(0x201B, 0, 0xC3 | 0x800).expect("detect the op-amp fault");
    r.run(5_000);
    assert_eq!(r.read_sub(0x201C, 1, 1), Ok(vec![33]));
    r.inputs.sensing_fault = false;
    r.write_sub(0x201E, 0, 1).expect("clear the alarm");
    // The software over-current masked (bit 0 clear): 9 A read latches nothing; the hardware
    // trip latches alarm 10 all the same.
    r.write_sub(0x201B, 0, 0xC2).expect("mask the over-current");
    r.inputs.phase_ma = Some([9_000, 0]);
    r.run(5_000);
    assert_eq!(r.drive.state().read(Obj::AlarmCode), 0);
    r.inputs.tripped = true;
    r.run(1_000);
    assert_eq!(r.read_sub(0x201C, 1, 1), Ok(vec![10]), "the trip in hardware");
    (r.inputs.tripped, r.inputs.phase_ma) = (false, None);
    r.write_sub(0x201E, 0, 1).expect("clear the alarm");
    // The EEPROM (bit 2): a save that fails.
    r.write_sub(0x201B, 0, 0xC3 | 0x04).expect("detect the store's failure");
    assert_eq!(r.saved().get(Obj::FaultMask), 0xC7, "the mask is among the saved");
    r.drive.save_done(false);
    r.run(1_000);
    assert_eq!(r.read_sub(0x201C, 1, 1), Ok(vec![32]), "the store's alarm");
    // Cleared in 0x2120 (the native storage status, bit 4) and then the alarm: gone.
    r.write_sub(0x2120, 0xFF, 0x10).expect("clear the failed save");
    r.write_sub(0x201E, 0, 1).expect("clear the alarm");
    r.run(1_000);
    assert_eq!(r.drive.state().read(Obj::AlarmCode), 0);
}

/// 0x2023.1-5: IN1-IN5's filter times, µs, 1000 from the factory, 50-60 000, read in one
/// request, saved with 0x2030; the drive's objects take them.
#[test]
fn the_input_filter_times() {
    let mut r = rig();
    assert_eq!(r.read_sub(0x2023, 1, 5), Ok(vec![1000; 5]));
    assert_eq!(r.write_sub(0x2023, 1, 49), Err(0x06));
    assert_eq!(r.write_sub(0x2023, 5, 60_001), Err(0x06));
    r.write_sub(0x2023, 2, 50).expect("one tick: no filter");
    r.write_sub(0x2023, 5, 60_000).expect("60 ms");
    assert_eq!(r.read_sub(0x2023, 1, 5), Ok(vec![1000, 50, 1000, 1000, 60_000]));
    let st = r.drive.state();
    assert_eq!((st.read(Obj::InputFilter2), st.read(Obj::InputFilter5)), (50, 60_000));
    assert_eq!(r.saved().get(Obj::InputFilter5), 60_000);
}

/// 0x2015/0x2016: the command filter's switch and time (µs, 50-25 600, factory off and 1000),
/// refused out of range, read back, saved with 0x2030; the drive's objects take them.
#[test]
fn the_command_filter_registers() {
    let mut r = rig();
    assert_eq!(r.read_sub(0x2015, 0, 2), Ok(vec![0, 1000]));
    assert_eq!(r.write_sub(0x2015, 0, 2), Err(0x06));
    assert_eq!(r.write_sub(0x2016, 0, 49), Err(0x06));
    assert_eq!(r.write_sub(0x2016, 0, 25_601), Err(0x06));
    r.write_sub(0x2016, 0, 5_000).expect("5 ms");
    r.write_sub(0x2015, 0, 1).expect("on");
    assert_eq!(r.read_sub(0x2015, 0, 2), Ok(vec![1, 5_000]));
    assert_eq!(r.drive.state().settings().shaping.ticks(), 100, "5 ms of 50 µs ticks");
    let saved = r.saved();
    assert_eq!((saved.get(Obj::CommandFilter), saved.get(Obj::CommandFilterTime)), (1, 5_000));
}

/// The slave's inline decoding of the commonest requests ([`ec57::KEYS`]) takes exactly what
/// the map's own decoder takes of reads, writes and block writes, and decodes it alike; it
/// takes nothing else (the decoder refuses it, or decodes another function).
#[test]
fn the_inline_decoding_agrees_with_the_maps_decoder() {
    use drive_core::maps::ec57;
    let indexes: [u16; 10] = [0x0000, 0x0FFF, 0x1000, 0x1FFF, 0x2000, 0x2003, 0x20FF, 0x2100, 0x600C, 0xFFFF];
    let subs = (0..=17).chain([0x7F, 0xFE, 0xFF]);
    let subs: Vec<u8> = subs.collect();
    let words = (0..=18).chain([0x7F, 0x100, 0x7FFF, 0xFFFF]);
    let words: Vec<u16> = words.collect();
    let (mut taken, mut pdus) = (0, 0);
    for function in [0x02, 0x03, 0x04, 0x06, 0x08, 0x10, 0x17] {
        for &index in &indexes {
            for &sub in &subs {
                for &word in &words {
                    let mut pdu = vec![function];
                    pdu.extend_from_slice(&index.to_be_bytes());
                    pdu.push(sub);
                    pdu.extend_from_slice(&word.to_be_bytes());
                    // No tail; a byte count and values for the word's registers; one too few.
                    let n = 2 * usize::from(word.min(20));
                    let tails = [
                        vec![],
                        [vec![n as u8], vec![0x5A; n]].concat(),
                        [vec![n as u8], vec![0x5A; n.saturating_sub(1)]].concat(),
                    ];
                    for tail in tails {
                        let pdu = [pdu.clone(), tail].concat();
                        pdus += 1;
                        let short = ec57::KEYS.short(&pdu);
                        let parsed = ec57::parse(&pdu);
                        if matches!(function, 0x03 | 0x06 | 0x10) {
                            assert_eq!(short, parsed.ok(), "{pdu:02X?}");
                        } else {
                            assert_eq!(short, None, "{pdu:02X?}");
                        }
                        taken += usize::from(short.is_some());
                    }
                }
            }
        }
    }
    assert!(taken > 1_000 && taken < pdus / 4, "{taken} of {pdus}");
}
