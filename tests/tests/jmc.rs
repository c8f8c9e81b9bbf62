//! The JMC map (seed 001) through a master we did not write (tokio-modbus over TCP) on the
//! simulator: commissioned in the native map and switched with a save and a restart; §6.1's,
//! §6.2's and §6.3's routines replayed frame by frame with both word orders, the rotor ending
//! where each routine says; the exception cases with nothing changed; an EXT stop as the fault
//! state and its reset. The simulator runs 100 times faster than wall time (`--time-scale`):
//! §6.1's single point is 62.5 revolutions at 1 rev/s.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use drive_tests::{LIMIT, master, read, read_values, write, write_many};
use hal_sim::machine::{Machine, Switch};
use hal_sim::{PowerSwitch, Snapshot};
use tokio::time::{sleep, timeout};
use tokio_modbus::client::{Context, Reader};
use tokio_modbus::prelude::{ExceptionCode, ReadCode};

/// Simulated seconds a wall second.
const SCALE: u32 = 100;

/// One simulator at a time: each runs its motor at `SCALE` times wall time.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// The machine: a home cam from 40 to 44 full steps on EXT1, the CW (negative) limit at -120
/// on EXT2, the CCW (positive) limit at 120 on EXT3; NPN switches, actuated low.
fn machine() -> Machine {
    let switches = ["ext1:npn:40:to=44:hyst=0.2", "ext2:npn:-120:below:hyst=0.2", "ext3:npn:120:hyst=0.2"];
    Machine::new(switches.iter().map(|s| Switch::parse(s).expect("switch spec")).collect(), None)
}

fn power_on(flash: &Path, faults: &[&str]) -> (PowerSwitch, Arc<Mutex<Snapshot>>) {
    drive_tests::power_on(flash, machine(), SCALE, faults)
}

/// A drive commissioned in the native map and restarted in the JMC map, and its master.
struct Jmc {
    _turn: std::sync::MutexGuard<'static, ()>,
    _dir: tempfile::TempDir,
    _sim: PowerSwitch,
    ctx: Context,
    snapshot: Arc<Mutex<Snapshot>>,
    /// 0x6000: 32-bit values low word first.
    low_first: bool,
}

async fn jmc() -> Jmc {
    jmc_with(&[], &[]).await
}

/// [`jmc`] with the native map's `settings` written before the switch, and the simulator's
/// `faults` (`--fault` specs) after the restart.
#[allow(clippy::await_holding_lock)] // one runtime a test, one simulator at a time
async fn jmc_with(settings: &[(u16, &[u16])], faults: &[&str]) -> Jmc {
    let turn = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let (sim, _) = power_on(&flash, &[]);
    let mut ctx = master(&sim).await;
    // In the native map: 1/16 microsteps, pull-ups on EXT1-3, the switches' inputs (home EXT1,
    // negative EXT2, positive EXT3), a creep speed of 100 full steps a second, then the JMC
    // map, saved.
    // 1/16 microsteps: the JMC positions count them (seed 001 §5: "the target position depends
    // on the microstep setting").
    let common: [(u16, &[u16]); 4] =
        [(0x600C, &[16]), (0x602F, &[0x0005, 0x4000]), (0x216C, &[0x0321]), (0x2165, &[0, 1600])];
    let switch: [(u16, &[u16]); 2] = [(0x2190, &[1]), (0x200F, &[2])];
    for &(addr, words) in common.iter().chain(settings).chain(&switch) {
        assert_eq!(write_many(&mut ctx, addr, words).await, Ok(()), "{addr:#06x}");
    }
    assert_eq!(read_values(&mut ctx, 0x2120, 1).await[0] & 0x18, 0, "saved");
    drop(ctx);
    sim.off().expect("off");
    let (sim, snapshot) = power_on(&flash, faults);
    let ctx = master(&sim).await;
    Jmc { _turn: turn, _dir: dir, _sim: sim, ctx, snapshot, low_first: false }
}

impl Jmc {
    async fn set(&mut self, addr: u16, v: u16) {
        assert_eq!(write(&mut self.ctx, addr, v).await, Ok(()), "{addr:#06x} = {v:#06x}");
    }

    /// A 32-bit register, in the word order 0x6000 says.
    async fn set32(&mut self, addr: u16, v: i32) {
        let (hi, lo) = ((v as u32 >> 16) as u16, v as u16);
        let words = if self.low_first { [lo, hi] } else { [hi, lo] };
        assert_eq!(write_many(&mut self.ctx, addr, &words).await, Ok(()), "{addr:#06x} = {v}");
    }

    async fn get(&mut self, addr: u16) -> u16 {
        read_values(&mut self.ctx, addr, 1).await[0]
    }

    async fn get32(&mut self, addr: u16) -> i32 {
        let w = read_values(&mut self.ctx, addr, 2).await;
        let (hi, lo) = if self.low_first { (w[1], w[0]) } else { (w[0], w[1]) };
        ((u32::from(hi) << 16) | u32::from(lo)) as i32
    }

    async fn word_order(&mut self, low_first: bool) {
        self.set(0x6000, u16::from(low_first)).await;
        self.low_first = low_first;
    }

    /// The rotor, microsteps from power-up.
    fn rotor(&self) -> f64 {
        self.snapshot.lock().expect("snapshot").rotor_microsteps
    }

    /// Waits until statusword bit 9 (moving) is clear, within `secs` simulated seconds.
    async fn wait_still(&mut self, secs: u64) {
        for _ in 0..secs * 10 / u64::from(SCALE) + 50 {
            sleep(Duration::from_millis(100)).await;
            if self.get(0x6041).await & (1 << 9) == 0 {
                return;
            }
        }
        panic!("still moving after {secs} s");
    }

    /// Waits until a homing has ended (statusword bit 12 homed or 13 error) and the axis stands,
    /// within `secs` simulated seconds; the statusword then.
    async fn wait_homed(&mut self, secs: u64) -> u16 {
        for _ in 0..secs * 10 / u64::from(SCALE) + 50 {
            sleep(Duration::from_millis(100)).await;
            let sw = self.get(0x6041).await;
            if sw & 0x3000 != 0 && sw & (1 << 9) == 0 {
                return sw;
            }
        }
        panic!("no homing end after {secs} s");
    }

    /// Waits until the velocity actual value 0x606C reads `v` (0.1 rev/s), within 2 s of wall time.
    async fn wait_speed(&mut self, v: i32) {
        for _ in 0..100 {
            if self.get32(0x606C).await == v {
                return;
            }
            sleep(Duration::from_millis(20)).await;
        }
        panic!("0x606C never read {v}");
    }

    /// The rotor's speed, microsteps a second, over at least half a simulated second.
    async fn measured_speed(&mut self) -> f64 {
        let at = || {
            let s = self.snapshot.lock().expect("snapshot");
            (s.rotor_microsteps, s.time_us)
        };
        let (a, t) = at();
        for _ in 0..200 {
            sleep(Duration::from_millis(5)).await;
            let (b, u) = at();
            if u >= t + 500_000 {
                return (b - a) / ((u - t) as f64 * 1e-6);
            }
        }
        panic!("the simulation does not advance");
    }

    /// §6.1's power-up: 0x0001, 0x0003, 0x000F.
    async fn enable(&mut self) {
        for cw in [0x0001, 0x0003, 0x000F] {
            self.set(0x6040, cw).await;
        }
        assert_eq!(self.get(0x6041).await & 0x6F, 0x27, "operation enabled");
    }
}

#[tokio::test(flavor = "current_thread")]
async fn the_map_is_chosen_by_a_saved_setting_and_identifies_itself() {
    let mut d = jmc().await;
    let id = timeout(LIMIT, d.ctx.read_device_identification(ReadCode::Regular, 0))
        .await
        .expect("in time")
        .expect("transport")
        .expect("identification");
    let app = id.device_id_objects.iter().find(|o| o.id == 6).map(|o| String::from_utf8_lossy(&o.value).to_string());
    assert_eq!(app.as_deref(), Some("drive-core, JMC map (seed 001)"));
    // Switch on disabled at power-up; the name and versions at 0x1008-0x100A.
    assert_eq!(d.get(0x6041).await & 0x6F, 0x40);
    let name = read_values(&mut d.ctx, 0x1008, 12).await;
    assert_eq!(name[0], u16::from_be_bytes(*b"OS"), "{name:04X?}");
    // The native registers are gone, the map's own vendor object is there to switch back.
    assert_eq!(code(read(&mut d.ctx, 0x600C, 1).await), Some(0x0B));
    assert_eq!(d.get(0x2190).await, 1);
}

#[tokio::test(flavor = "current_thread")]
async fn the_position_routines_end_where_they_say_in_both_word_orders() {
    let mut d = jmc().await;
    d.enable().await;
    d.set(0x6060, 1).await;
    assert_eq!(d.get(0x6061).await, 1);
    // §6.1's single point (lines 620-640), in each word order: 200 000 steps at 1 rev/s.
    let mut end = 0.0;
    for low_first in [false, true] {
        d.word_order(low_first).await;
        d.set32(0x6081, 10).await;
        d.set(0x6083, 100).await;
        d.set(0x6084, 100).await;
        d.set32(0x607A, 200_000 + if low_first { 1000 } else { 0 }).await;
        assert_ne!(d.get(0x6041).await & (1 << 12), 0, "a new set-point can be taken");
        d.set(0x6040, 0x001F).await;
        d.set(0x6040, 0x000F).await;
        d.wait_still(70).await;
        end = if low_first { 201_000.0 } else { 200_000.0 };
        assert_eq!(d.get32(0x6064).await, end as i32);
        assert!((d.rotor() - end).abs() < 0.5, "rotor at {} for {end}", d.rotor());
        let sw = d.get(0x6041).await;
        assert_eq!(sw & 0x6F, 0x27, "{sw:#06x}");
        assert_ne!(sw & (1 << 10), 0, "target reached: {sw:#06x}");
    }
    // The multi-point examples (lines 644-714) from there, in absolute terms for the first: stop
    // between points (0x001F), go on without a stop (0x025F: bit 6 relative), change at once
    // (0x007F then 0x027F: relative).
    for (first, clear, second, relative) in [(0x001F, 0x000F, 0x001F, false), (0x025F, 0x024F, 0x025F, true)] {
        let base = end as i32;
        d.set32(0x6081, 50).await;
        d.set32(0x607A, if relative { 200_000 } else { base + 200_000 }).await;
        d.set(0x6040, first).await;
        d.set(0x6040, clear).await;
        d.set32(0x6081, 100).await;
        d.set32(0x607A, if relative { 600_000 } else { base + 600_000 }).await;
        d.set(0x6040, second).await;
        d.wait_still(60).await;
        end = f64::from(base + if relative { 800_000 } else { 600_000 });
        assert_eq!(d.get32(0x6064).await, end as i32, "controlword {first:#06x}");
        assert!((d.rotor() - end).abs() < 0.5, "rotor at {} for {end}", d.rotor());
        d.set(0x6040, 0x000F).await;
    }
}

#[tokio::test(flavor = "current_thread")]
async fn the_velocity_routine_runs_changes_speed_and_stops() {
    let mut d = jmc().await;
    d.enable().await;
    // §6.2 (lines 764-792), in each word order.
    d.set(0x6060, 3).await;
    for low_first in [false, true] {
        d.word_order(low_first).await;
        d.set(0x6040, 0x010F).await;
        d.set32(0x6081, 10).await;
        d.set(0x6083, 100).await;
        d.set(0x6084, 100).await;
        d.set(0x6040, 0x000F).await;
        d.wait_speed(10).await;
        let speed = d.measured_speed().await;
        assert!((speed - 3200.0).abs() < 100.0, "1 rev/s: {speed} microsteps a second");
        d.set32(0x6081, 100).await;
        d.wait_speed(100).await;
        d.set(0x6040, 0x010F).await;
        d.wait_still(5).await;
        let sw = d.get(0x6041).await;
        assert_ne!(sw & (1 << 8), 0, "halted: {sw:#06x}");
        assert_ne!(sw & (1 << 12), 0, "speed 0: {sw:#06x}");
    }
}

#[tokio::test(flavor = "current_thread")]
async fn the_homing_routine_and_methods_home_on_the_switches() {
    let mut d = jmc().await;
    d.enable().await;
    // §6.3 (line 872), the parameters in one 0x10 in §8's order: offset 1000, method 1, speed
    // 10 rev/s, acceleration 100 rev/s², zero offset speed 10 rev/s.
    d.set(0x6060, 6).await;
    let words = [0x0000, 0x03E8, 0x0001, 0x0000, 0x0064, 0x03E8, 0x0000, 0x0064];
    assert_eq!(write_many(&mut d.ctx, 0x607C, &words).await, Ok(()));
    // Method 1 at 2000 full steps a second towards the CW limit, then the offset move.
    d.set(0x6040, 0x001F).await;
    let sw = d.wait_homed(10).await;
    assert_eq!(sw & 0x3400, 0x1400, "homing attained, no error: {sw:#06x}");
    assert_eq!(d.get32(0x6064).await, 0);
    let zero = d.rotor() / 16.0;
    assert!((zero - (-120.0 + 62.5)).abs() < 0.5, "the CW limit's edge plus 1000 microsteps: {zero}");
    // Methods 5 (the CW limit's edge, approached again moving left at the creep speed) and 8
    // (the origin cam's lower edge, approached again from below), without the offset move.
    d.set32(0x609B, 0).await;
    d.set32(0x607C, 0).await;
    d.set32(0x6099, 20).await;
    for (method, home) in [(5, -120.0), (8, 40.0)] {
        d.set(0x6040, 0x000F).await;
        d.set(0x6098, method).await;
        d.set(0x6040, 0x001F).await;
        assert_eq!(d.wait_homed(60).await & 0x3000, 0x1000, "method {method}: homed");
        let at = (d.rotor() - f64::from(d.get32(0x6064).await)) / 16.0;
        assert!((at - home).abs() < 0.2, "method {method}: home at {at} full steps, expected {home}");
    }
    // Bits 11, 14, 15: the home switch, the CW and CCW limits.
    assert_ne!(d.get(0x6041).await & (1 << 11), 0, "standing on the cam's edge");
    // The routine's one 0x10 again, low word first: offset 1000, method 2 (the CCW limit).
    d.word_order(true).await;
    let words = [0x03E8, 0x0000, 0x0002, 0x0064, 0x0000, 0x03E8, 0x0064, 0x0000];
    assert_eq!(write_many(&mut d.ctx, 0x607C, &words).await, Ok(()));
    d.set(0x6040, 0x000F).await;
    d.set(0x6040, 0x001F).await;
    assert_eq!(d.wait_homed(10).await & 0x3400, 0x1400, "homed");
    assert_eq!(d.get32(0x6064).await, 0);
    let zero = d.rotor() / 16.0;
    assert!((zero - (120.0 + 62.5)).abs() < 0.5, "the CCW limit's edge plus 1000 microsteps: {zero}");
}

/// The exception code of a refused request.
fn code<T>(r: Result<T, ExceptionCode>) -> Option<u8> {
    r.err().map(u8::from)
}

#[tokio::test(flavor = "current_thread")]
async fn refusals_change_nothing_and_an_ext_stop_is_a_fault_until_reset() {
    // The CCW limit (EXT3, NPN: its falling edge) is also an external stop.
    let mut d = jmc_with(&[(0x6013, &[0x10]), (0x6014, &[0]), (0x6015, &[0])], &[]).await;
    d.enable().await;
    d.set(0x6060, 1).await;
    let setpoint = |d: &Jmc| d.snapshot.lock().expect("snapshot").setpoint;
    let before = (read_values(&mut d.ctx, 0x6081, 6).await, setpoint(&d));
    assert_eq!(code(write(&mut d.ctx, 0x6090, 3).await), Some(0x0B), "no such register");
    assert_eq!(code(write(&mut d.ctx, 0x6041, 1).await), Some(5), "read only");
    assert_eq!(code(read(&mut d.ctx, 0x6040, 1).await), Some(7), "write only");
    assert_eq!(code(write(&mut d.ctx, 0x607A, 3).await), Some(2), "one half of a 32-bit value");
    assert_eq!(code(write(&mut d.ctx, 0x6060, 4).await), Some(3), "torque mode");
    assert_eq!(code(write_many(&mut d.ctx, 0x6083, &[50, 50, 0]).await), Some(3), "0x6085 = 0, all or nothing");
    assert_eq!((read_values(&mut d.ctx, 0x6081, 6).await, setpoint(&d)), before, "nothing changed");
    // Velocity mode towards the CCW limit at 120 full steps: the EXT stop there.
    d.set(0x6060, 3).await;
    d.set(0x6040, 0x010F).await;
    d.set32(0x6081, 10).await;
    d.set(0x6040, 0x000F).await;
    d.wait_still(5).await;
    let sw = d.get(0x6041).await;
    assert_eq!(sw & 0x4F, 0x08, "fault: {sw:#06x}");
    assert_ne!(sw & (1 << 15), 0, "on the CCW limit: {sw:#06x}");
    let at = d.rotor() / 16.0;
    // Confirmed 100 ms after the edge (0x6042), then 0x6084: about 30 full steps past it.
    assert!((120.0..160.0).contains(&at), "stopped past the limit: {at}");
    // Enabling does nothing in the fault state; a fault reset leaves switch on disabled.
    d.set(0x6040, 0x000F).await;
    assert_eq!(d.get(0x6041).await & 0x4F, 0x08);
    d.set(0x6040, 0x0080).await;
    assert_eq!(d.get(0x6041).await & 0x6F, 0x40, "switch on disabled");
    // Back off the limit.
    d.enable().await;
    d.set(0x6040, 0x010F).await;
    d.set32(0x6081, -10).await;
    d.set(0x6040, 0x000F).await;
    for _ in 0..50 {
        if d.rotor() / 16.0 < at - 10.0 {
            return;
        }
        sleep(Duration::from_millis(20)).await;
    }
    panic!("not moving back: {}", d.rotor() / 16.0);
}

/// An over-voltage from the simulator's fault injection (70 V from 200 s to 260 s of simulated
/// time: 2 s of wall time at `SCALE` for the master to start the motor first, on a loaded
/// machine too) while the motor runs: the fault state, the power stage off; a fault reset while
/// the supply is still high leaves it there; once the supply is back, a fault reset, and the
/// drive runs again.
#[tokio::test(flavor = "current_thread")]
async fn an_injected_over_voltage_is_a_fault_until_reset() {
    let mut d = jmc_with(&[], &["200000:supply=70", "260000:supply=24"]).await;
    d.enable().await;
    d.set(0x6060, 3).await;
    d.set(0x6040, 0x010F).await;
    d.set32(0x6081, 10).await;
    d.set(0x6040, 0x000F).await;
    let time = |d: &Jmc| d.snapshot.lock().expect("snapshot").time_us;
    assert!(time(&d) < 200_000_000, "running before the fault");
    d.wait_speed(10).await;
    while time(&d) < 200_000_000 {
        sleep(Duration::from_millis(10)).await;
    }
    let mut sw = 0;
    for _ in 0..200 {
        sw = d.get(0x6041).await;
        if sw & 0x08 != 0 {
            break;
        }
        sleep(Duration::from_millis(10)).await;
    }
    assert_eq!(sw & 0x4F, 0x08, "fault: {sw:#06x}");
    assert_ne!(d.get(0x1001).await & 0b101, 0, "error register: a voltage fault");
    assert!(!d.snapshot.lock().expect("snapshot").enabled, "the power stage is off");
    d.set(0x6040, 0x0080).await;
    if time(&d) < 259_000_000 {
        assert_eq!(d.get(0x6041).await & 0x4F, 0x08, "still over-voltage: still the fault state");
    }
    while time(&d) < 261_000_000 {
        sleep(Duration::from_millis(10)).await;
    }
    d.set(0x6040, 0x0000).await;
    d.set(0x6040, 0x0080).await;
    assert_eq!(d.get(0x6041).await & 0x6F, 0x40, "switch on disabled after the reset");
    assert_eq!(d.get(0x1001).await, 0);
    d.enable().await;
    d.set(0x6040, 0x010F).await;
    d.set(0x6040, 0x000F).await;
    d.wait_speed(10).await;
}
