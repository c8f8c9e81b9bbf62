//! The DS-CLS9 map (seed 002) through a master we did not write (tokio-modbus over TCP) on the
//! simulator: chosen in the native map and switched by a save and a restart, the settings
//! written in the map's units surviving a power cycle, the control command's runs moving the
//! rotor where the table says, a soft limit stopping it on the enabled side, an alarm stopping
//! it and clearing. The simulator runs 20 times faster than wall time (`--time-scale`).

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use drive_tests::{master, read_values, write, write_many};
use hal_sim::{PowerSwitch, Snapshot};
use tokio::time::sleep;
use tokio_modbus::client::Context;
use tokio_modbus::prelude::ExceptionCode;

/// Simulated seconds a wall second.
const SCALE: u32 = 20;

fn power_on(flash: &Path, scale: u32, faults: &[&str]) -> (PowerSwitch, Arc<Mutex<Snapshot>>) {
    drive_tests::power_on(flash, hal_sim::machine::Machine::default(), scale, faults)
}

struct Cls9 {
    _sim: PowerSwitch,
    ctx: Context,
    snapshot: Arc<Mutex<Snapshot>>,
}

/// A drive switched to the DS-CLS9 map in the native map, saved and restarted `scale` times
/// faster than wall time with the simulator's `faults`, and its master.
async fn cls9(flash: &Path, scale: u32, faults: &[&str]) -> Cls9 {
    let (sim, _) = power_on(flash, scale, &[]);
    let mut ctx = master(&sim).await;
    assert_eq!(write(&mut ctx, 0x2190, 2).await, Ok(()));
    assert_eq!(write(&mut ctx, 0x200F, 2).await, Ok(()));
    sleep(Duration::from_millis(100)).await;
    drop(ctx);
    sim.off().expect("off");
    let (sim, snapshot) = power_on(flash, scale, faults);
    let ctx = master(&sim).await;
    Cls9 { _sim: sim, ctx, snapshot }
}

impl Cls9 {
    async fn set(&mut self, addr: u16, v: i32) -> Result<(), ExceptionCode> {
        write(&mut self.ctx, addr, v as u16).await
    }

    async fn set32(&mut self, addr: u16, v: i32) {
        let words = [(v as u32 >> 16) as u16, v as u16];
        assert_eq!(write_many(&mut self.ctx, addr, &words).await, Ok(()), "{addr} = {v}");
    }

    async fn get(&mut self, addr: u16) -> u16 {
        read_values(&mut self.ctx, addr, 1).await[0]
    }

    async fn get32(&mut self, addr: u16) -> i32 {
        let w = read_values(&mut self.ctx, addr, 2).await;
        ((u32::from(w[0]) << 16) | u32::from(w[1])) as i32
    }

    /// Switches the drive off once its save is done and on again on `flash`.
    async fn restart(self, flash: &Path) -> Self {
        sleep(Duration::from_millis(100)).await;
        let Cls9 { _sim: sim, ctx, .. } = self;
        drop(ctx);
        sim.off().expect("off");
        let (sim, snapshot) = power_on(flash, SCALE, &[]);
        let ctx = master(&sim).await;
        Cls9 { _sim: sim, ctx, snapshot }
    }

    /// The rotor, microsteps (pulses) from power-up.
    fn rotor(&self) -> f64 {
        self.snapshot.lock().expect("snapshot").rotor_microsteps
    }

    /// Waits until 0109 says the axis stands, within `secs` simulated seconds.
    async fn wait_still(&mut self, secs: u64) {
        for _ in 0..secs * 10 / u64::from(SCALE) + 20 {
            sleep(Duration::from_millis(100)).await;
            if self.get(109).await != 3 {
                return;
            }
        }
        panic!("still moving after {secs} s");
    }
}

#[tokio::test(flavor = "current_thread")]
async fn commands_move_the_rotor_as_the_table_says() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let mut d = cls9(&flash, SCALE, &[]).await;
    assert_eq!(d.get(109).await, 2, "energised and standing in the DS-CLS9 map");

    // The settings in the map's units, saved through 0x200F, survive a power cycle.
    d.set32(242, 1600).await;
    for (reg, v) in [(303, 20), (304, 20), (306, 300), (308, 100)] {
        assert_eq!(d.set(reg, v).await, Ok(()), "{reg}");
    }
    assert_eq!(d.set(0x200F, 2).await, Ok(()));
    let mut d = d.restart(&flash).await;
    assert_eq!(d.get32(242).await, 1600);
    assert_eq!(read_values(&mut d.ctx, 303, 6).await, vec![20, 20, 35, 300, 125, 100]);

    // 1: ten revolutions (16 000 pulses) at 3 rev/s; the rotor ends there.
    d.set32(313, 16_000).await;
    assert_eq!(d.set(323, 1).await, Ok(()));
    d.wait_still(10).await;
    assert_eq!(d.get32(126).await, 16_000);
    assert!((d.rotor() - 16_000.0).abs() < 8.0, "rotor at {}", d.rotor());
    // 2: back by 4 000 pulses.
    d.set32(313, -4_000).await;
    assert_eq!(d.set(323, 2).await, Ok(()));
    d.wait_still(10).await;
    assert!((d.rotor() - 12_000.0).abs() < 8.0, "rotor at {}", d.rotor());
    // The positive soft limit at 14 000 stops a run to 20 000 on it.
    d.set32(317, 14_000).await;
    assert_eq!(d.set(324, 1).await, Ok(()));
    d.set32(313, 20_000).await;
    assert_eq!(d.set(323, 1).await, Ok(()));
    d.wait_still(10).await;
    assert!((d.rotor() - 14_000.0).abs() < 8.0, "rotor at {}", d.rotor());
    // A jog the other way runs until 6 stops it.
    assert_eq!(d.set(323, 5).await, Ok(()));
    sleep(Duration::from_millis(100)).await;
    assert!(d.rotor() < 14_000.0 - 100.0, "jogging back: {}", d.rotor());
    assert_eq!(d.set(323, 6).await, Ok(()));
    d.wait_still(2).await;
    let at = d.rotor();
    sleep(Duration::from_millis(100)).await;
    assert!((d.rotor() - at).abs() < 1.0, "stands");
}

#[tokio::test(flavor = "current_thread")]
async fn an_alarm_stops_the_run_and_clears() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    // 70 V from 2 s of simulated time to 6 s.
    let mut d = cls9(&flash, SCALE, &["2000:supply=70", "6000:supply=24"]).await;
    let time = |d: &Cls9| d.snapshot.lock().expect("snapshot").time_us;
    assert!(time(&d) < 2_000_000, "jogging before the alarm");
    assert_eq!(d.set(323, 4).await, Ok(()));
    while time(&d) < 2_200_000 {
        sleep(Duration::from_millis(10)).await;
    }
    // The alarm: code 14, the power stage off, the rotor stops; a run is refused.
    assert_eq!(read_values(&mut d.ctx, 108, 2).await, vec![14, 1]);
    assert_eq!(d.set(323, 4).await, Err(ExceptionCode::ServerDeviceFailure));
    let at = d.rotor();
    sleep(Duration::from_millis(50)).await;
    assert!((d.rotor() - at).abs() < 2.0, "the rotor stays");
    // While the supply is high, a clear latches again; once it is back, 13 clears the alarm
    // and the drive is energised again.
    assert_eq!(d.set(323, 13).await, Ok(()));
    assert_eq!(d.get(108).await, 14);
    while time(&d) < 6_200_000 {
        sleep(Duration::from_millis(10)).await;
    }
    assert_eq!(d.set(323, 13).await, Ok(()));
    sleep(Duration::from_millis(20)).await;
    assert_eq!(read_values(&mut d.ctx, 108, 2).await, vec![0, 2]);
}

/// §十三's timing exceptions from a raw master (the real masters cannot send them), on the
/// simulator in simulated time (`hal-sim --script`, whose `raw` command sends bytes as they are,
/// when it says): a write with a silence of 2.5 ms (over t1.5, under t3.5 at 9600 baud) inside it
/// is answered 0C at t3.5 after its last byte and not executed; a whole read followed 2.5 ms later
/// by another is answered 0D; the same write on time is served and acts.
#[test]
fn a_raw_master_gets_the_timing_exceptions() {
    let opts = hal_sim::SimOptions { map: Some(2), ..Default::default() };
    let mut plant = hal_sim::script::plant(&opts).expect("plant");
    // 0308 (jog speed) = 100 = 0x64: 01 06 0134 0064, CRC C8 13; a read of 0308: CRC C4 38.
    let script = "\
        raw 10 01 06 01\n\
        raw 12.5 34 00 64 C8 13\n\
        raw 30 01 03 01 34 00 01 C4 38\n\
        raw 32.5 01 03 01 34 00 01 C4 38\n\
        at 50 01 03 0134 0001\n\
        at 60 01 06 0134 0064\n\
        at 70 01 03 0134 0001\n\
        until 80\n";
    let mut out = Vec::new();
    hal_sim::script::run_script(script, &mut plant, &mut out).expect("script");
    let replies: Vec<String> = String::from_utf8(out).expect("utf-8").lines().map(str::to_string).collect();
    let reply = |body: &[u8]| hal_sim::script::hex(&with_crc(body));
    assert_eq!(
        replies[..5],
        [
            format!("16.510 reply {}", reply(&[1, 0x86, 0x0C])),
            format!("36.510 reply {}", reply(&[1, 0x83, 0x0D])),
            // Not executed: 0308 is its factory 2000 pps, 10.00 rev/s at 200 pulses a turn.
            format!("54.010 reply {}", reply(&[1, 0x03, 0x02, 0x03, 0xE8])),
            format!("64.010 reply {}", reply(&[1, 0x06, 0x01, 0x34, 0x00, 0x64])),
            format!("74.010 reply {}", reply(&[1, 0x03, 0x02, 0x00, 0x64])),
        ],
        "{replies:#?}"
    );
}

/// The CRC-16/MODBUS of `body`, appended low byte first.
fn with_crc(body: &[u8]) -> Vec<u8> {
    let mut crc = 0xFFFFu16;
    for &b in body {
        crc ^= u16::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 { (crc >> 1) ^ 0xA001 } else { crc >> 1 };
        }
    }
    let mut f = body.to_vec();
    f.extend_from_slice(&crc.to_le_bytes());
    f
}

/// 0296 = 0 (external pulses), 0244 = 2 (double pulse) and 0234 written in the map, saved: after
/// a power cycle the drive follows a CW/CCW train on its pulse input (one pulse a pulse of
/// 0242's resolution) and the rotor ends on the count; the control command's runs are refused.
#[tokio::test(flavor = "current_thread")]
async fn external_pulses_after_a_restart_move_the_rotor() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let mut d = cls9(&flash, SCALE, &[]).await;
    assert_eq!((d.get(106).await, d.get(244).await, d.get(296).await), (1, 1, 1), "factory: internal pulses");
    assert_eq!(d.set(244, 3).await, Err(ExceptionCode::IllegalDataValue), "the map offers formats 1 and 2");
    d.set32(242, 3200).await;
    for (reg, v) in [(244, 2), (234, 5), (296, 0), (0x200F, 2)] {
        assert_eq!(d.set(reg, v).await, Ok(()), "{reg}");
    }
    sleep(Duration::from_millis(100)).await;
    let Cls9 { _sim: sim, ctx, .. } = d;
    drop(ctx);
    sim.off().expect("off");
    // Five revolutions back (16 000 pulses on CCW) at up to 32 kpps, from 1 s after power-up.
    let train = hal_sim::pulses::Train::parse("cw-ccw:-32000:count=16000:accel=100000:at=1000").expect("train");
    let mut machine = hal_sim::machine::Machine::default();
    machine.pulses = Some(hal_sim::pulses::PulseSource::new(train));
    let (sim, snapshot) = drive_tests::power_on(&flash, machine, SCALE, &[]);
    let ctx = master(&sim).await;
    let mut d = Cls9 { _sim: sim, ctx, snapshot };
    assert_eq!((d.get(106).await, d.get(234).await, d.get(296).await), (2, 5, 0));
    assert_eq!(d.set(323, 4).await, Err(ExceptionCode::ServerDeviceFailure), "a jog is refused while following");
    // 1 s to the start, 0.8 s of pulses, in simulated time.
    sleep(Duration::from_millis(2_000 / u64::from(SCALE) + 300)).await;
    assert_eq!(d.get32(126).await, -16_000, "the position counted every pulse");
    assert!((d.rotor() + 16_000.0).abs() < 8.0, "rotor at {}", d.rotor());
}

/// Seed 002's multi-segment program through tokio-modbus, three segments: written to
/// 1024-1536, checked, saved by 0323 = 15, still there after a power cycle; segment 2 started by
/// a write of 0323, segment 1 (a wait, a loop and a jump) by the pseudo-input of IN1 (function
/// 16), segment 3 by the simulated input IN2 (EXT2, function 16) going high. The simulator's
/// trace shows each segment's moves, and a program with a jump out of its segment is refused with
/// that segment's number.
#[tokio::test(flavor = "current_thread")]
async fn a_saved_three_segment_program_runs_after_a_restart() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let trace = dir.path().join("motor.trace");
    let mut d = cls9(&flash, SCALE, &[]).await;
    d.set32(242, 3200).await;
    #[rustfmt::skip]
    let program: [u16; 33] = [
        54, 300,            // 0: run speed 3 rev/s
        61, 20, 62, 20,     // 1, 2: ramps 20 rev/s²
        1, 0, 16_000,       // 3: to 16 000
        65, 5, 2_000,       // 4: 2 s, then on at 5
        2, 0xFFFF, 0xF060,  // 5: back by 4 000
        66, 2, 5,           // 6: the body (5) twice
        100,                // 7: end of segment 1
        54, 50,             // 8: segment 2: 0.5 rev/s
        1, 0xFFFF, 0xF830,  // 9: to -2 000
        100,                // 10: end of segment 2
        54, 100,            // 11: segment 3: 1 rev/s
        1, 0, 1_000,        // 12: to 1 000
        100, 0, 0,          // 13: end (and two unused words)
    ];
    assert_eq!(write_many(&mut d.ctx, 1024, &program).await, Ok(()));
    for (reg, v) in [(327, 3), (328, 1), (323, 14)] {
        assert_eq!(d.set(reg, v).await, Ok(()), "{reg}");
    }
    assert_eq!(d.get(176).await, 0, "no segment in error");
    assert_eq!(d.set(323, 15).await, Ok(()), "saved");
    sleep(Duration::from_millis(100)).await;
    let Cls9 { _sim: sim, ctx, .. } = d;
    drop(ctx);
    sim.off().expect("off");
    let opts = hal_sim::SimOptions {
        endpoint: hal_sim::Endpoint::Tcp("127.0.0.1:0".into()),
        flash: Some(flash.clone()),
        time_scale: SCALE,
        motor: hal_sim::MotorOptions { trace: Some((trace.clone(), 20)), ..Default::default() },
        ..Default::default()
    };
    let (sim, snapshot, wires) = drive_tests::power_on_with(opts);
    let ctx = master(&sim).await;
    let mut d = Cls9 { _sim: sim, ctx, snapshot };
    assert_eq!(read_values(&mut d.ctx, 1024, 33).await, program.to_vec(), "the program survived");
    assert_eq!(read_values(&mut d.ctx, 327, 2).await, vec![3, 1]);
    // Segment 2 (0328 = 1), by a write of 0323.
    assert_eq!(d.set(323, 16).await, Ok(()));
    assert_eq!(d.get(178).await, 2, "segment 2 runs");
    d.wait_program(10).await;
    assert_eq!(d.get32(126).await, -2_000);
    assert!((d.rotor() + 2_000.0).abs() < 8.0, "rotor at {}", d.rotor());
    // Segment 1 by IN1 (function 16, start) through its pseudo-input.
    for (reg, v) in [(328, 0), (400, 16), (401, 16), (410, 1)] {
        assert_eq!(d.set(reg, v).await, Ok(()), "{reg}");
    }
    d.wait_segment(1).await;
    d.wait_program(20).await;
    assert_eq!(d.get32(126).await, 8_000, "to 16 000, then twice 4 000 back");
    assert!((d.rotor() - 8_000.0).abs() < 8.0, "rotor at {}", d.rotor());
    // Segment 3 by IN2 (EXT2) going high on its wire.
    assert_eq!(d.set(328, 2).await, Ok(()));
    wires.inject(hal_sim::inject::Change::Input(8, Some(true)));
    d.wait_segment(3).await;
    d.wait_program(5).await;
    assert_eq!(d.get32(126).await, 1_000);
    assert!((d.rotor() - 1_000.0).abs() < 8.0, "rotor at {}", d.rotor());

    // A jump out of its segment (segment 3 jumping to instruction 0): refused with 3.
    assert_eq!(write_many(&mut d.ctx, 1024 + 29, &[65, 0, 10, 100]).await, Ok(()));
    assert_eq!(d.set(323, 14).await, Ok(()));
    assert_eq!(d.get(176).await, 3);
    assert_eq!(d.set(323, 16).await, Err(ExceptionCode::ServerDeviceFailure));
    sleep(Duration::from_millis(100)).await;
    assert_eq!(d.get32(126).await, 1_000, "nothing moved");

    // The trace: -2 000 (segment 2), 16 000 held for the wait, 8 000 (segment 1), 1 000 (3).
    let Cls9 { _sim: sim, ctx, .. } = d;
    drop(ctx);
    sim.off().expect("off");
    let file = std::fs::File::open(&trace).expect("trace");
    let rows = hal_sim::trace::read_csv(std::io::BufReader::new(file)).expect("trace rows");
    let held = |at: f64, secs: f64| {
        let near: Vec<f64> =
            rows.iter().filter(|r| (r.commanded_position_usteps - at).abs() < 0.5).map(|r| r.t_s).collect();
        near.last().zip(near.first()).is_some_and(|(last, first)| last - first >= secs)
    };
    assert!(held(-2_000.0, 0.05), "segment 2 ends at -2 000");
    assert!(held(16_000.0, 1.9), "segment 1 waits 2 s at 16 000");
    assert!(held(12_000.0, 0.0), "then passes 12 000");
    assert!(held(8_000.0, 0.05), "and ends at 8 000");
    assert!(held(1_000.0, 0.05), "segment 3 ends at 1 000");
}

impl Cls9 {
    /// Waits until segment `n` runs (0178), within a second.
    async fn wait_segment(&mut self, n: u16) {
        for _ in 0..100 {
            if self.get(178).await == n {
                return;
            }
            sleep(Duration::from_millis(10)).await;
        }
        panic!("segment {n} does not run");
    }

    /// Waits until no program segment runs (0178 = 0), within `secs` simulated seconds.
    async fn wait_program(&mut self, secs: u64) {
        for _ in 0..secs * 100 / u64::from(SCALE) + 20 {
            sleep(Duration::from_millis(10)).await;
            if self.get(178).await == 0 {
                return;
            }
        }
        panic!("a segment still runs after {secs} s");
    }
}
