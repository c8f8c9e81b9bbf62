//! Seed 000 §9.4.1-9.4.4 replayed by a real master (tokio-modbus) over the simulator's serial
//! endpoint, in real time, against the physical motor model.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use drive_tests::read_values as read;
use hal_sim::{Endpoint, SimOptions, Simulator, Snapshot};
use tokio::net::TcpStream;
use tokio::time::sleep;
use tokio_modbus::client::{Context, rtu};
use tokio_modbus::prelude::Slave;

async fn start() -> (Context, Arc<Mutex<Snapshot>>) {
    let sim = Simulator::bind(SimOptions { endpoint: Endpoint::Tcp("127.0.0.1:0".into()), ..Default::default() })
        .expect("bind");
    let at = sim.endpoint().to_string();
    let snapshot = sim.snapshot();
    sim.spawn();
    let ctx = rtu::attach_slave(TcpStream::connect(at).await.expect("connect"), Slave(1));
    (ctx, snapshot)
}

async fn write(ctx: &mut Context, reg: u16, v: u16) {
    assert_eq!(drive_tests::write(ctx, reg, v).await, Ok(()), "write {reg:04X} = {v:04X}");
}

/// Polls the busy bit (§9.4: read 0x6001, bit 3) until it clears.
async fn wait_idle(ctx: &mut Context, within: Duration) {
    let end = tokio::time::Instant::now() + within;
    while read(ctx, 0x6001, 1).await[0] & 0x08 != 0 {
        assert!(tokio::time::Instant::now() < end, "still busy");
        sleep(Duration::from_millis(50)).await;
    }
}

fn rotor(s: &Arc<Mutex<Snapshot>>) -> f64 {
    s.lock().expect("snapshot").rotor_microsteps
}

/// §9.4.1: 1/32, 1000 mA, 32000 pps, forward, 32000 steps: five revolutions of the rotor.
#[tokio::test(flavor = "current_thread")]
async fn relative_move_turns_the_rotor_five_revolutions() {
    let (mut ctx, snapshot) = start().await;
    for (reg, v) in
        [(0x600C, 0x0020), (0x600D, 0x03E8), (0x6003, 0), (0x6004, 0x7D00), (0x6002, 0), (0x6005, 0), (0x6006, 0x7D00)]
    {
        write(&mut ctx, reg, v).await;
    }
    assert_ne!(read(&mut ctx, 0x6001, 1).await[0] & 0x08, 0, "busy while moving");
    wait_idle(&mut ctx, Duration::from_secs(10)).await;
    assert_eq!(read(&mut ctx, 0x600E, 2).await, vec![0, 32000]);
    sleep(Duration::from_millis(100)).await;
    let r = rotor(&snapshot);
    // 32000 microsteps at 1/32 = 1000 full steps = 5 revolutions; within a tenth of a full step.
    assert!((r - 32000.0).abs() < 3.2, "rotor at {r} microsteps");
}

/// §9.4.2: absolute moves there and back.
#[tokio::test(flavor = "current_thread")]
async fn absolute_moves() {
    let (mut ctx, snapshot) = start().await;
    for (reg, v) in [(0x600C, 0x0020), (0x600D, 0x03E8), (0x600A, 1), (0x600B, 1), (0x6003, 0), (0x6004, 0x7D00)] {
        write(&mut ctx, reg, v).await;
    }
    for target in [32000i32, -6400, 0] {
        let [a, b, c, d] = target.to_be_bytes();
        write(&mut ctx, 0x6044, u16::from_be_bytes([a, b])).await;
        write(&mut ctx, 0x6045, u16::from_be_bytes([c, d])).await;
        wait_idle(&mut ctx, Duration::from_secs(10)).await;
        let p = read(&mut ctx, 0x600E, 2).await;
        assert_eq!((i32::from(p[0] as i16) << 16) | i32::from(p[1]), target);
        sleep(Duration::from_millis(100)).await;
        let r = rotor(&snapshot);
        assert!((r - f64::from(target)).abs() < 3.2, "rotor at {r}, target {target}");
    }
}

/// §9.4.3: velocity mode at 32000 pps = 300 rpm at 1/32.
#[tokio::test(flavor = "current_thread")]
async fn velocity_mode_at_300_rpm() {
    let (mut ctx, snapshot) = start().await;
    for (reg, v) in
        [(0x600C, 0x0020), (0x600D, 0x03E8), (0x600A, 1), (0x600B, 1), (0x6007, 1), (0x6003, 0), (0x6004, 0x7D00)]
    {
        write(&mut ctx, reg, v).await;
    }
    // Level 1 (77440 pps²) reaches 32000 pps in under half a second.
    sleep(Duration::from_millis(1000)).await;
    let (t0, r0) = {
        let s = *snapshot.lock().expect("snapshot");
        (s.time_us, s.rotor_microsteps)
    };
    sleep(Duration::from_millis(1000)).await;
    let (t1, r1) = {
        let s = *snapshot.lock().expect("snapshot");
        (s.time_us, s.rotor_microsteps)
    };
    let rpm = (r1 - r0) / ((t1 - t0) as f64 * 1e-6) / 6400.0 * 60.0;
    assert!((rpm - 300.0).abs() < 3.0, "{rpm} rpm");
    assert_ne!(read(&mut ctx, 0x6001, 1).await[0] & 0x08, 0, "busy while running");
    // Back to position mode: decelerates to a stop.
    write(&mut ctx, 0x6007, 0).await;
    wait_idle(&mut ctx, Duration::from_secs(5)).await;
}

/// §9.4.4: the common settings, saved (0x200F = 2), kept across a power cycle on the same flash,
/// then §9.4.1's move with them.
#[tokio::test(flavor = "current_thread")]
async fn common_settings_saved_and_used_after_a_power_cycle() {
    const SETTINGS: [(u16, u16); 8] = [
        (0x600C, 0x0020),
        (0x600D, 0x03E8),
        (0x6008, 0x0258),
        (0x6009, 0x0258),
        (0x600A, 8),
        (0x600B, 8),
        (0x6013, 3),
        (0x6014, 0),
    ];
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let opts = || SimOptions {
        endpoint: Endpoint::Tcp("127.0.0.1:0".into()),
        flash: Some(flash.clone()),
        ..Default::default()
    };

    let sim = Simulator::bind(opts()).expect("bind").power_on();
    let mut ctx = rtu::attach_slave(TcpStream::connect(sim.endpoint()).await.expect("connect"), Slave(1));
    for (reg, v) in SETTINGS {
        write(&mut ctx, reg, v).await;
    }
    write(&mut ctx, 0x200F, 2).await;
    // Storage status 0x2120: bit 3 save running, bit 4 last save failed.
    assert_eq!(read(&mut ctx, 0x2120, 1).await[0] & 0x18, 0, "saved");
    drop(ctx);
    sim.off().expect("power off");

    let sim = Simulator::bind(opts()).expect("bind");
    let snapshot = sim.snapshot();
    let sim = sim.power_on();
    let mut ctx = rtu::attach_slave(TcpStream::connect(sim.endpoint()).await.expect("connect"), Slave(1));
    for (reg, v) in SETTINGS {
        assert_eq!(read(&mut ctx, reg, 1).await, vec![v], "0x{reg:04X} after the power cycle");
    }
    for (reg, v) in [(0x6003, 0), (0x6004, 0x7D00), (0x6002, 0), (0x6005, 0), (0x6006, 0x7D00)] {
        write(&mut ctx, reg, v).await;
    }
    wait_idle(&mut ctx, Duration::from_secs(10)).await;
    sleep(Duration::from_millis(100)).await;
    let r = rotor(&snapshot);
    assert!((r - 32000.0).abs() < 3.2, "rotor at {r} microsteps");
    drop(ctx);
    sim.off().expect("power off");
}
