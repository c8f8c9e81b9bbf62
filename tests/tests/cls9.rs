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

fn power_on(flash: &Path, faults: &[&str]) -> (PowerSwitch, Arc<Mutex<Snapshot>>) {
    drive_tests::power_on(flash, hal_sim::machine::Machine::default(), SCALE, faults)
}

struct Cls9 {
    _sim: PowerSwitch,
    ctx: Context,
    snapshot: Arc<Mutex<Snapshot>>,
}

/// A drive switched to the DS-CLS9 map in the native map, saved and restarted with the
/// simulator's `faults`, and its master.
async fn cls9(flash: &Path, faults: &[&str]) -> Cls9 {
    let (sim, _) = power_on(flash, &[]);
    let mut ctx = master(&sim).await;
    assert_eq!(write(&mut ctx, 0x2190, 2).await, Ok(()));
    assert_eq!(write(&mut ctx, 0x200F, 2).await, Ok(()));
    sleep(Duration::from_millis(100)).await;
    drop(ctx);
    sim.off().expect("off");
    let (sim, snapshot) = power_on(flash, faults);
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
    let mut d = cls9(&flash, &[]).await;
    assert_eq!(d.get(109).await, 2, "energised and standing in the DS-CLS9 map");

    // The settings in the map's units, saved through 0x200F, survive a power cycle.
    d.set32(242, 1600).await;
    for (reg, v) in [(303, 20), (304, 20), (306, 300), (308, 100)] {
        assert_eq!(d.set(reg, v).await, Ok(()), "{reg}");
    }
    assert_eq!(d.set(0x200F, 2).await, Ok(()));
    sleep(Duration::from_millis(100)).await;
    let Cls9 { _sim: sim, ctx, .. } = d;
    drop(ctx);
    sim.off().expect("off");
    let (sim, snapshot) = power_on(&flash, &[]);
    let ctx = master(&sim).await;
    let mut d = Cls9 { _sim: sim, ctx, snapshot };
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
    let mut d = cls9(&flash, &["2000:supply=70", "6000:supply=24"]).await;
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
