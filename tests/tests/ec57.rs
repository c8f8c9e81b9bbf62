//! The EC-57 map (seed 003) on the simulator through a raw master (no stock master speaks the
//! sub-index byte; pymodbus does with custom requests, `tests/masters/pymodbus_ec57.py`): chosen
//! in the native map with tokio-modbus, switched by a save and a restart, then every frame of
//! §1.3 and §1.3.4 byte for byte over the simulator's TCP endpoint (raw RTU frames), a setting
//! kept across a power cycle, and the map switched back.

use std::path::Path;
use std::time::Duration;

use drive_tests::{master, read_values, write};
use hal_sim::PowerSwitch;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::time::{sleep, timeout};

/// The manual's hex text in bytes.
fn hex(text: &str) -> Vec<u8> {
    text.split_whitespace().map(|b| u8::from_str_radix(b, 16).expect("hex")).collect()
}

/// A raw master: frames out as given, the reply in as it comes (none within 300 ms: `None`).
struct Raw(TcpStream);

impl Raw {
    async fn connect(sim: &PowerSwitch) -> Self {
        Self(TcpStream::connect(sim.endpoint()).await.expect("connect"))
    }

    async fn exchange(&mut self, frame: &[u8]) -> Option<Vec<u8>> {
        self.0.write_all(frame).await.expect("send");
        let mut reply = Vec::new();
        let mut buf = [0u8; 256];
        // The reply's bytes until the line has been quiet for 100 ms.
        while let Ok(Ok(n)) =
            timeout(Duration::from_millis(if reply.is_empty() { 300 } else { 100 }), self.0.read(&mut buf)).await
        {
            if n == 0 {
                break;
            }
            reply.extend_from_slice(&buf[..n]);
        }
        (!reply.is_empty()).then_some(reply)
    }

    async fn manual(&mut self, request: &str) -> Option<Vec<u8>> {
        self.exchange(&hex(request)).await
    }
}

fn power_on(flash: &Path) -> PowerSwitch {
    drive_tests::power_on(flash, hal_sim::machine::Machine::default(), 1, &[]).0
}

/// Once a save has had its time, `sim` switched off and on again on the same flash.
async fn restart(sim: PowerSwitch, flash: &Path) -> PowerSwitch {
    sleep(Duration::from_millis(200)).await;
    sim.off().expect("off");
    power_on(flash)
}

#[tokio::test]
async fn the_manuals_frames_on_the_wire_after_a_switch_from_the_native_map() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    // Chosen in the native map (0x2190 = 3), saved, restarted.
    let sim = power_on(&flash);
    let mut ctx = master(&sim).await;
    assert_eq!(write(&mut ctx, 0x2190, 3).await, Ok(()));
    assert_eq!(write(&mut ctx, 0x200F, 2).await, Ok(()));
    drop(ctx);
    let sim = restart(sim, &flash).await;
    let mut raw = Raw::connect(&sim).await;
    // §1.3: the manual's frames and replies, byte for byte. A fresh map: 0x2003.1 is the
    // drive's own 500 ms (the map's factory values are for a drive with nothing saved).
    assert_eq!(raw.manual("01 03 20 00 00 00 01 4B F4").await, Some(hex("01 03 02 00 01 79 84")));
    assert_eq!(raw.manual("01 06 20 01 00 00 02 0A 5C").await, Some(hex("01 06 20 01 00 00 02 0A 5C")));
    assert_eq!(raw.manual("01 03 20 00 00 00 04 8B F7").await, Some(hex("01 03 08 00 01 00 02 00 00 01 F4 FC C0")));
    assert_eq!(raw.manual("01 06 20 05 00 27 10 90 91").await, Some(hex("01 06 20 05 00 27 10 90 91")));
    assert_eq!(raw.manual("01 06 20 03 01 00 32 5A 30").await, Some(hex("01 06 20 03 01 00 32 5A 30")));
    assert_eq!(raw.manual("01 10 20 00 00 00 02 04 00 01 00 01 AC 49").await, Some(hex("01 10 20 00 00 00 02 09 56")));
    // §1.3.4: a wrong CRC is dropped; the others as printed.
    assert_eq!(raw.manual("01 03 20 00 00 00 01 4B F3").await, None);
    assert_eq!(raw.manual("01 02 00 00 00 00 04 0B E1").await, Some(hex("01 82 02 C1 61")));
    assert_eq!(raw.manual("01 03 20 31 00 00 01 45 08").await, Some(hex("01 83 03 01 31")));
    assert_eq!(raw.manual("01 03 20 00 00 00 20 8B EC").await, Some(hex("01 83 04 40 F3")));
    assert_eq!(raw.manual("01 03 20 30 00 00 01 44 F4").await, Some(hex("01 83 05 81 33")));
    assert_eq!(raw.manual("01 06 20 01 00 00 08 8A 5B").await, Some(hex("01 86 06 C2 62")));
    // The CRC error answered once 0x21D2 (the window: sub-index 0xFF) says so.
    assert_eq!(raw.manual("01 06 21 D2 FF 00 01 7F 29").await, Some(hex("01 06 21 D2 FF 00 01 7F 29")));
    assert_eq!(raw.manual("01 03 20 00 00 00 01 4B F3").await, Some(hex("01 83 01 80 F0")));
    // Saved (0x2030 = 1): the resolution is kept across a power cycle.
    assert_eq!(raw.manual("01 06 20 30 00 00 01 44 A1").await, Some(hex("01 06 20 30 00 00 01 44 A1")));
    drop(raw);
    let sim = restart(sim, &flash).await;
    let mut raw = Raw::connect(&sim).await;
    assert_eq!(raw.manual("01 03 20 05 00 00 01 4B 38").await, Some(hex("01 03 02 27 10 A2 78")));
    // Back to the native map: 0x2190 (window) = 0, saved, restarted.
    assert_eq!(raw.manual("01 06 21 90 FF 00 00 AA 91").await, Some(hex("01 06 21 90 FF 00 00 AA 91")));
    assert_eq!(raw.manual("01 06 20 30 00 00 01 44 A1").await, Some(hex("01 06 20 30 00 00 01 44 A1")));
    drop(raw);
    let sim = restart(sim, &flash).await;
    let mut ctx = master(&sim).await;
    assert_eq!(read_values(&mut ctx, 0x600C, 1).await, vec![50], "the native map, 50 microsteps");
}
