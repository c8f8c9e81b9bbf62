//! Parameters that survive power loss, seen by a master we did not write (tokio-modbus over TCP):
//! values saved with 0x200F = 2 are back after the simulator is switched off and on again with
//! the same `--flash` file; factory reset through 0x200F = 3 and through FSET; node id and baud
//! rate take effect only after save and restart.

use std::path::Path;
use std::time::Duration;

use hal_sim::{Endpoint, PowerSwitch, SimOptions, Simulator};
use tokio::net::TcpStream;
use tokio::time::timeout;
use tokio_modbus::client::{Context, Reader, rtu};
use tokio_modbus::prelude::{ExceptionCode, Slave};

use drive_tests::{read, write, write_many};

/// Storage status 0x2120 bits.
const EMPTY: u16 = 1;
const FSET: u16 = 4;
const SAVING: u16 = 8;
const FAILED: u16 = 16;

/// Powers a simulator up on `flash` over TCP.
fn power_on(flash: &Path, fset_low: bool) -> PowerSwitch {
    let opts = SimOptions {
        endpoint: Endpoint::Tcp("127.0.0.1:0".into()),
        flash: Some(flash.to_owned()),
        fset_low,
        ..Default::default()
    };
    Simulator::bind(opts).expect("bind simulator").power_on()
}

async fn master(sim: &PowerSwitch, slave: u8) -> Context {
    let stream = TcpStream::connect(sim.endpoint()).await.expect("connect");
    rtu::attach_slave(stream, Slave(slave))
}

/// Saves and checks that the save ended well.
async fn save(ctx: &mut Context) {
    assert_eq!(write(ctx, 0x200F, 2).await, Ok(()));
    assert_eq!(read(ctx, 0x2120, 1).await.expect("status")[0] & (SAVING | FAILED), 0, "save ended well");
}

/// The settings these tests change, as the master reads them: group id, node id, baud rate,
/// parity, jerk time, start speed, phase current, microsteps, PP acceleration.
async fn settings(ctx: &mut Context) -> Vec<u16> {
    let mut all = Vec::new();
    for (addr, n) in [(0x200E, 1), (0x2028, 1), (0x202A, 2), (0x2100, 2), (0x6008, 1), (0x600C, 2), (0x6067, 2)] {
        all.extend(read(ctx, addr, n).await.expect("readable"));
    }
    all
}

/// Factory values of [`settings`].
const FACTORY: [u16; 11] = [0, 1, 0, 9600, 0, 50, 600, 0, 658, 0, 32000];

/// Writes values different from the factory's; the serial settings only where `serial`.
async fn change(ctx: &mut Context, serial: bool) {
    write(ctx, 0x200E, 12).await.expect("group");
    write(ctx, 0x2101, 200).await.expect("jerk time");
    write(ctx, 0x6008, 700).await.expect("start speed");
    write_many(ctx, 0x600C, &[32, 1500]).await.expect("microsteps and current");
    write_many(ctx, 0x6067, &[0x0001, 0x86A0]).await.expect("PP acceleration 100000");
    if serial {
        write(ctx, 0x2100, 1).await.expect("even parity");
    }
    // A RAM object: not saved.
    write_many(ctx, 0x6003, &[0, 1000]).await.expect("speed");
}

const CHANGED: [u16; 11] = [12, 1, 0, 9600, 0, 200, 700, 32, 1500, 1, 0x86A0];

#[tokio::test(flavor = "current_thread")]
async fn saved_values_are_back_after_a_restart_and_unsaved_ones_are_not() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let sim = power_on(&flash, false);
    let mut ctx = master(&sim, 1).await;
    assert_eq!(read(&mut ctx, 0x2120, 1).await, Ok(vec![EMPTY]), "a new flash holds nothing");
    assert_eq!(settings(&mut ctx).await, FACTORY);
    change(&mut ctx, false).await;
    assert_eq!(settings(&mut ctx).await, CHANGED);
    save(&mut ctx).await;
    // Changed after the save: lost at power-off.
    write(&mut ctx, 0x6008, 800).await.expect("start speed");
    drop(ctx);
    sim.off().expect("off");

    let sim = power_on(&flash, false);
    let mut ctx = master(&sim, 1).await;
    assert_eq!(settings(&mut ctx).await, CHANGED, "the saved set, not the later write");
    assert_eq!(read(&mut ctx, 0x6003, 2).await, Ok(vec![0, 0]), "RAM objects start at their defaults");
    assert_eq!(read(&mut ctx, 0x2120, 1).await, Ok(vec![0]));
    drop(ctx);
    sim.off().expect("off");
}

#[tokio::test(flavor = "current_thread")]
async fn factory_reset_through_system_control_is_saved() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let sim = power_on(&flash, false);
    let mut ctx = master(&sim, 1).await;
    change(&mut ctx, false).await;
    save(&mut ctx).await;
    assert_eq!(write(&mut ctx, 0x200F, 3).await, Ok(()));
    assert_eq!(settings(&mut ctx).await, FACTORY, "restored at once");
    assert_eq!(read(&mut ctx, 0x6003, 2).await, Ok(vec![0, 1000]), "RAM objects untouched");
    drop(ctx);
    sim.off().expect("off");

    let sim = power_on(&flash, false);
    let mut ctx = master(&sim, 1).await;
    assert_eq!(settings(&mut ctx).await, FACTORY, "and still after a restart");
    drop(ctx);
    sim.off().expect("off");
}

#[tokio::test(flavor = "current_thread")]
async fn factory_reset_through_fset() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let sim = power_on(&flash, false);
    let mut ctx = master(&sim, 1).await;
    change(&mut ctx, false).await;
    write(&mut ctx, 0x2028, 9).await.expect("node id 9");
    save(&mut ctx).await;
    drop(ctx);
    sim.off().expect("off");

    // FSET held low: the drive is back at node 1 with factory values, and says why.
    let sim = power_on(&flash, true);
    let mut ctx = master(&sim, 1).await;
    assert_eq!(settings(&mut ctx).await, FACTORY);
    assert_eq!(read(&mut ctx, 0x2120, 1).await, Ok(vec![FSET]));
    // The bit clears when written 1.
    write(&mut ctx, 0x2120, FSET).await.expect("clear");
    assert_eq!(read(&mut ctx, 0x2120, 1).await, Ok(vec![0]));
    drop(ctx);
    sim.off().expect("off");

    // The factory values were saved: FSET released, they stay.
    let sim = power_on(&flash, false);
    let mut ctx = master(&sim, 1).await;
    assert_eq!(settings(&mut ctx).await, FACTORY);
    assert_eq!(read(&mut ctx, 0x2120, 1).await, Ok(vec![0]));
    drop(ctx);
    sim.off().expect("off");
}

#[tokio::test(flavor = "current_thread")]
async fn node_id_and_baud_rate_take_effect_after_save_and_restart() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let sim = power_on(&flash, false);
    let mut ctx = master(&sim, 1).await;
    write(&mut ctx, 0x2028, 7).await.expect("node id 7");
    write_many(&mut ctx, 0x202A, &[0, 19200]).await.expect("19200 baud");
    // Still node 1 until saved and restarted.
    assert_eq!(read(&mut ctx, 0x2028, 1).await, Ok(vec![7]));
    drop(ctx);
    sim.off().expect("off");

    // Not saved: a typo is undone by a power cycle.
    let sim = power_on(&flash, false);
    let mut ctx = master(&sim, 1).await;
    assert_eq!(read(&mut ctx, 0x2028, 4).await, Ok(vec![1, 0, 0, 9600]));
    write(&mut ctx, 0x2028, 7).await.expect("node id 7");
    write_many(&mut ctx, 0x202A, &[0, 19200]).await.expect("19200 baud");
    change(&mut ctx, true).await;
    save(&mut ctx).await;
    // Saved, but this power-up's settings hold until the next.
    assert_eq!(read(&mut ctx, 0x600D, 1).await, Ok(vec![1500]));
    drop(ctx);
    sim.off().expect("off");

    let opts =
        SimOptions { endpoint: Endpoint::Tcp("127.0.0.1:0".into()), flash: Some(flash.clone()), ..Default::default() };
    let booted = Simulator::bind(opts).expect("bind");
    assert_eq!((booted.drive().address().get(), booted.drive().baud().get()), (7, 19200));
    let sim = booted.power_on();
    let mut at_7 = master(&sim, 7).await;
    assert_eq!(read(&mut at_7, 0x2028, 4).await, Ok(vec![7, 0, 0, 19200]));
    let mut want = CHANGED;
    want[1..5].copy_from_slice(&[7, 0, 19200, 1]);
    assert_eq!(settings(&mut at_7).await, want);
    drop(at_7);
    let mut at_1 = master(&sim, 1).await;
    assert!(
        timeout(Duration::from_millis(300), at_1.read_holding_registers(0x2028, 1)).await.is_err(),
        "node 1 is gone"
    );
    drop(at_1);
    sim.off().expect("off");

    // --address overrides the saved node id for a run.
    let opts = SimOptions { address: Some(3), flash: Some(flash), ..Default::default() };
    assert_eq!(Simulator::bind(opts).expect("bind").drive().address().get(), 3);
}

#[tokio::test(flavor = "current_thread")]
async fn no_save_while_moving_and_no_boot_loader() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let sim = power_on(&flash, false);
    let mut ctx = master(&sim, 1).await;
    write(&mut ctx, 0x600D, 1200).await.expect("current");
    // Velocity mode at 2000 pps: the axis moves until stopped.
    write(&mut ctx, 0x6007, 1).await.expect("velocity mode");
    write_many(&mut ctx, 0x6003, &[0, 2000]).await.expect("speed");
    tokio::time::sleep(Duration::from_millis(50)).await;
    assert_eq!(read(&mut ctx, 0x6001, 1).await.map(|s| s[0] & 8), Ok(8), "moving");
    assert_eq!(write(&mut ctx, 0x200F, 2).await, Err(ExceptionCode::ServerDeviceFailure));
    assert_eq!(write(&mut ctx, 0x200F, 3).await, Err(ExceptionCode::ServerDeviceFailure));
    assert_eq!(read(&mut ctx, 0x600D, 1).await, Ok(vec![1200]), "no factory reset either");
    assert_eq!(write(&mut ctx, 0x200F, 1).await, Err(ExceptionCode::ServerDeviceFailure), "no boot loader");
    assert_eq!(read(&mut ctx, 0x2120, 1).await, Ok(vec![EMPTY]), "nothing saved, nothing running");
    write(&mut ctx, 0x6053, 0).await.expect("stop");
    tokio::time::sleep(Duration::from_millis(20)).await;
    assert_eq!(read(&mut ctx, 0x6001, 1).await.map(|s| s[0] & 8), Ok(0), "stopped");
    save(&mut ctx).await;
    drop(ctx);
    sim.off().expect("off");

    let sim = power_on(&flash, false);
    let mut ctx = master(&sim, 1).await;
    assert_eq!(read(&mut ctx, 0x600D, 1).await, Ok(vec![1200]));
    drop(ctx);
    sim.off().expect("off");
}
