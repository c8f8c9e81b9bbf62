//! Faults and protections seen by a master we did not write (tokio-modbus over TCP), with the
//! faults injected into the running simulator (`Simulator::injector`): each reaction's bit, alarm
//! code and history entry, the motor freed or stopped, motion refused (04) until the bits are
//! cleared over Modbus; the brake; power loss with the position saved across a restart; the
//! communication watchdog.

use std::path::Path;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use hal_sim::inject::{Change, Injector};
use hal_sim::motor::PhaseFault;
use hal_sim::{Endpoint, PowerSwitch, SimOptions, Simulator, Snapshot};
use tokio::net::TcpStream;
use tokio::time::{sleep, timeout};
use tokio_modbus::client::{Context, Reader, Writer, rtu};
use tokio_modbus::prelude::{ExceptionCode, Slave};

const LIMIT: Duration = Duration::from_secs(3);

/// One simulator at a time: each runs its motor model in real time, and several at once in a
/// debug build fall behind wall time on a small machine (then catch up in bursts), which the
/// timed checks here cannot tell from the drive's own timing.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// A running simulator, a master connected to it, and handles on its plant.
struct Rig {
    _turn: std::sync::MutexGuard<'static, ()>,
    ctx: Context,
    sim: PowerSwitch,
    injector: Injector,
    snapshot: Arc<Mutex<Snapshot>>,
}

// Each test runs on its own current-thread runtime: the guard held across the connect only
// makes the other tests' threads wait, it cannot deadlock this one.
#[allow(clippy::await_holding_lock)]
async fn rig(flash: Option<&Path>) -> Rig {
    // A test that failed while holding the turn poisons it; the next one may still run.
    let turn = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let opts = SimOptions {
        endpoint: Endpoint::Tcp("127.0.0.1:0".into()),
        flash: flash.map(Path::to_owned),
        ..Default::default()
    };
    let sim = Simulator::bind(opts).expect("bind simulator");
    let (injector, snapshot) = (sim.injector(), sim.snapshot());
    let sim = sim.power_on();
    let stream = TcpStream::connect(sim.endpoint()).await.expect("connect");
    let ctx = rtu::attach_slave(stream, Slave(1));
    Rig { _turn: turn, ctx, sim, injector, snapshot }
}

impl Rig {
    async fn read(&mut self, addr: u16, n: u16) -> Result<Vec<u16>, ExceptionCode> {
        timeout(LIMIT, self.ctx.read_holding_registers(addr, n)).await.expect("answer in time").expect("transport")
    }

    async fn reg(&mut self, addr: u16) -> u16 {
        self.read(addr, 1).await.expect("readable")[0]
    }

    async fn write(&mut self, addr: u16, v: u16) -> Result<(), ExceptionCode> {
        timeout(LIMIT, self.ctx.write_single_register(addr, v)).await.expect("answer in time").expect("transport")
    }

    async fn write32(&mut self, addr: u16, v: i32) -> Result<(), ExceptionCode> {
        let v = v as u32;
        let words = [(v >> 16) as u16, v as u16];
        timeout(LIMIT, self.ctx.write_multiple_registers(addr, &words))
            .await
            .expect("answer in time")
            .expect("transport")
    }

    async fn position(&mut self) -> i32 {
        let w = self.read(0x600E, 2).await.expect("position");
        ((u32::from(w[0]) << 16) | u32::from(w[1])) as i32
    }

    fn snapshot(&self) -> Snapshot {
        *self.snapshot.lock().expect("snapshot")
    }

    /// Polls `addr` until it reads `want` (within 2 s).
    async fn wait_for(&mut self, addr: u16, want: u16) {
        for _ in 0..200 {
            if self.reg(addr).await == want {
                return;
            }
            sleep(Duration::from_millis(10)).await;
        }
        panic!("{addr:#06x} never read {want:#x} (last {:#x})", self.reg(addr).await);
    }

    /// Waits until the axis is at rest (0x6001 bit 3 clear).
    async fn wait_still(&mut self) {
        for _ in 0..500 {
            if self.reg(0x6001).await & 8 == 0 {
                return;
            }
            sleep(Duration::from_millis(10)).await;
        }
        panic!("the axis never stopped");
    }

    /// A relative move of `steps` at 3000 pps.
    async fn relative(&mut self, steps: i32) -> Result<(), ExceptionCode> {
        self.write32(0x6003, 3000).await.expect("speed");
        self.write32(0x6005, steps).await
    }

    fn off(self) {
        drop(self.ctx);
        self.sim.off().expect("off");
    }
}

#[tokio::test(flavor = "current_thread")]
async fn under_voltage_frees_the_motor_and_refuses_motion_until_cleared() {
    let mut r = rig(None).await;
    sleep(Duration::from_millis(50)).await;
    assert!(r.snapshot().enabled && r.snapshot().current_a > 0.5, "holding: {:?}", r.snapshot());
    r.injector.inject(Change::SupplyRamp { to_v: 8.0, seconds: 0.2 });
    r.wait_for(0x6000, 1 << 5).await;
    assert_eq!(r.reg(0x2134).await, 13);
    assert_eq!(r.reg(0x2136).await, 1);
    sleep(Duration::from_millis(50)).await;
    let s = r.snapshot();
    assert!(!s.enabled && s.current_a < 1e-3, "freed: {s:?}");
    // Supply back: still latched, and a move is refused and does nothing.
    r.injector.inject(Change::Supply(24.0));
    sleep(Duration::from_millis(50)).await;
    assert_eq!(r.relative(1000).await, Err(ExceptionCode::ServerDeviceFailure));
    sleep(Duration::from_millis(100)).await;
    assert_eq!(r.position().await, 0);
    assert!(!r.snapshot().enabled);
    // Cleared over Modbus: the motor holds again and moves.
    assert_eq!(r.write(0x6000, 1 << 5).await, Ok(()));
    assert_eq!(r.reg(0x6000).await, 0);
    assert_eq!(r.reg(0x2134).await, 0);
    assert_eq!(r.relative(1000).await, Ok(()));
    r.wait_still().await;
    assert_eq!(r.position().await, 1000);
    sleep(Duration::from_millis(200)).await;
    assert!(r.snapshot().enabled);
    assert!((r.snapshot().rotor_microsteps - 1000.0).abs() < 0.5, "{:?}", r.snapshot());
    r.off();
}

#[tokio::test(flavor = "current_thread")]
async fn an_open_coil_is_phase_loss_with_a_history_entry() {
    let mut r = rig(None).await;
    sleep(Duration::from_millis(50)).await;
    r.injector.inject(Change::Phase(0, PhaseFault::Open));
    r.wait_for(0x6000, 1 << 1).await;
    assert_eq!(r.reg(0x2134).await, 11);
    let entry = r.read(0x213C, 4).await.expect("history");
    assert_eq!(entry[0] >> 8, 11, "code in bits 31-24: {entry:04X?}");
    let stamp = (u32::from(entry[0] & 0xFF) << 16) | u32::from(entry[1]);
    let now_ds = (r.snapshot().time_us / 100_000) as u32;
    assert!(stamp <= now_ds && now_ds - stamp <= 5, "time stamp {stamp} at {now_ds} (100 ms)");
    assert_eq!(&entry[2..], &[0, 0], "one entry only");
    assert_eq!(r.relative(100).await, Err(ExceptionCode::ServerDeviceFailure));
    // Still open: clearing latches it again, with a second entry.
    assert_eq!(r.write(0x6000, 1 << 1).await, Ok(()));
    r.wait_for(0x2136, 2).await;
    assert_eq!(r.reg(0x6000).await, 1 << 1);
    // Repaired and cleared: back in service.
    r.injector.inject(Change::Phase(0, PhaseFault::None));
    sleep(Duration::from_millis(20)).await;
    assert_eq!(r.write(0x6000, 1 << 1).await, Ok(()));
    assert_eq!(r.relative(100).await, Ok(()));
    r.wait_still().await;
    assert_eq!(r.position().await, 100);
    assert_eq!(r.reg(0x6000).await, 0);
    r.off();
}

#[tokio::test(flavor = "current_thread")]
async fn over_temperature_stops_a_moving_axis() {
    let mut r = rig(None).await;
    assert_eq!(r.relative(100_000).await, Ok(()));
    sleep(Duration::from_millis(200)).await;
    r.injector.inject(Change::DriverTemperature(100.0));
    r.wait_for(0x6000, 1).await;
    assert_eq!(r.reg(0x2134).await, 15);
    r.wait_still().await;
    let stopped = r.position().await;
    assert!(stopped > 0 && stopped < 100_000);
    sleep(Duration::from_millis(100)).await;
    assert_eq!(r.position().await, stopped);
    assert!(!r.snapshot().enabled);
    r.injector.inject(Change::DriverTemperature(40.0));
    sleep(Duration::from_millis(20)).await;
    assert_eq!(r.write(0x6000, 1).await, Ok(()));
    assert_eq!(r.reg(0x6000).await, 0);
    assert!(r.snapshot().enabled);
    r.off();
}

#[tokio::test(flavor = "current_thread")]
async fn the_brake_is_released_while_enabled_and_applied_on_disable_and_fault() {
    let mut r = rig(None).await;
    assert_eq!(r.write(0x6038, 70).await, Ok(()));
    sleep(Duration::from_millis(20)).await;
    assert_eq!(r.snapshot().coil_duty, 70);
    assert_eq!(r.write(0x6011, 0).await, Ok(()));
    sleep(Duration::from_millis(20)).await;
    assert_eq!(r.snapshot().coil_duty, 0);
    assert_eq!(r.write(0x6011, 1).await, Ok(()));
    sleep(Duration::from_millis(20)).await;
    assert_eq!(r.snapshot().coil_duty, 70);
    // Phase A: at rest on a full step it carries the current (B, at zero reference, would not).
    r.injector.inject(Change::Phase(0, PhaseFault::Short));
    r.wait_for(0x6000, 1 << 3).await;
    assert_eq!(r.reg(0x2134).await, 10);
    sleep(Duration::from_millis(20)).await;
    assert_eq!(r.snapshot().coil_duty, 0);
    r.off();
}

#[tokio::test(flavor = "current_thread")]
async fn power_loss_saves_the_position_for_the_next_power_up() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let mut r = rig(Some(&flash)).await;
    assert_eq!(r.write(0x605E, 1).await, Ok(()));
    // Free the motor below 20 V, brake below 19 V.
    assert_eq!(r.write(0x6038, 100).await, Ok(()));
    assert_eq!(r.write(0x6082, 3).await, Ok(()));
    assert_eq!(r.write(0x6083, 20_000).await, Ok(()));
    assert_eq!(r.write(0x6084, 19_000).await, Ok(()));
    assert_eq!(r.relative(4321).await, Ok(()));
    r.wait_still().await;
    // Sagging to 19.5 V: freed (the power stage off applies the brake), no fault; the position
    // save is asked for now, below the highest level.
    r.injector.inject(Change::Supply(19.5));
    sleep(Duration::from_millis(30)).await;
    let s = r.snapshot();
    assert!(!s.enabled && s.coil_duty == 0, "{s:?}");
    assert_eq!(r.reg(0x6000).await, 0);
    assert_eq!(r.relative(10).await, Err(ExceptionCode::ServerDeviceFailure));
    r.injector.inject(Change::SupplyRamp { to_v: 0.0, seconds: 0.1 });
    sleep(Duration::from_millis(200)).await;
    r.off();

    let mut r = rig(Some(&flash)).await;
    assert_eq!(r.read(0x6055, 2).await, Ok(vec![0, 4321]));
    r.off();
}

#[tokio::test(flavor = "current_thread")]
async fn the_watchdog_stops_a_moving_axis() {
    let mut r = rig(None).await;
    // 1 s: the simulated clock follows wall time only on average (it starts behind while the
    // master connects and catches up in bursts), so the check before expiry keeps a margin.
    assert_eq!(r.write(0x2137, 10).await, Ok(()));
    assert_eq!(r.write(0x6007, 1).await, Ok(()));
    assert_eq!(r.write32(0x6003, 2000).await, Ok(()));
    sleep(Duration::from_millis(250)).await;
    assert_eq!(r.reg(0x2138).await, 0);
    // Silence for longer than 1 s: the axis ramps down by itself.
    sleep(Duration::from_millis(2500)).await;
    let s = r.snapshot();
    assert_eq!(s.velocity, 0.0, "{s:?}");
    assert!(s.enabled);
    assert_eq!(r.reg(0x2138).await, 1);
    assert_eq!(r.reg(0x6001).await & 8, 0);
    assert_eq!(r.write32(0x6003, 2000).await, Err(ExceptionCode::ServerDeviceFailure));
    assert_eq!(r.write(0x2138, 1).await, Ok(()));
    assert_eq!(r.write32(0x6003, 2000).await, Ok(()));
    assert_eq!(r.write(0x2137, 0).await, Ok(()));
    r.off();
}

#[tokio::test(flavor = "current_thread")]
async fn the_fault_history_survives_a_power_cycle() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let mut r = rig(Some(&flash)).await;
    sleep(Duration::from_millis(50)).await;
    r.injector.inject(Change::DriverTemperature(100.0));
    r.wait_for(0x6000, 1).await;
    assert_eq!(r.reg(0x2136).await, 1);
    let history = r.read(0x213C, 20).await.expect("history");
    assert_eq!(history[0] >> 8, 15, "{history:04X?}");
    assert!(history[2..].iter().all(|&w| w == 0), "{history:04X?}");
    // The simulator saves after its next wake-up (within a millisecond).
    sleep(Duration::from_millis(50)).await;
    r.off();

    let mut r = rig(Some(&flash)).await;
    assert_eq!(r.read(0x213C, 20).await, Ok(history));
    assert_eq!(r.reg(0x2136).await, 1);
    // A power-up at 25 °C raises nothing new.
    assert_eq!(r.reg(0x6000).await, 0);
    r.off();
}

#[tokio::test(flavor = "current_thread")]
async fn a_blocked_rotor_in_closed_loop_is_alarm_25_until_cleared() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    // Closed loop on the simulator's 1000-line encoder takes effect at the next power-up.
    let mut r = rig(Some(&flash)).await;
    for (addr, v) in [(0x2104, 1), (0x6054, 1000), (0x600C, 16), (0x605C, 24), (0x600D, 1000)] {
        assert_eq!(r.write(addr, v).await, Ok(()), "{addr:#x}");
    }
    assert_eq!(r.write(0x200F, 2).await, Ok(()));
    sleep(Duration::from_millis(100)).await;
    r.off();

    let mut r = rig(Some(&flash)).await;
    assert_eq!(r.reg(0x2104).await, 1);
    assert_eq!(r.write32(0x6003, 4000).await, Ok(()));
    // One turn is 4000 counts.
    assert_eq!(r.relative(40_000).await, Ok(()));
    sleep(Duration::from_millis(300)).await;
    r.injector.inject(Change::Blocked(true));
    r.wait_for(0x2134, 25).await;
    assert_eq!(r.reg(0x2135).await, 1 << 2);
    assert_eq!(r.reg(0x6001).await & (1 << 2), 1 << 2);
    let s = r.snapshot();
    assert!(!s.enabled && s.current_a < 0.05, "{s:?}");
    assert_eq!(r.relative(100).await, Err(ExceptionCode::ServerDeviceFailure));
    // Freed and cleared over Modbus: the axis moves again, on the encoder.
    r.injector.inject(Change::Blocked(false));
    assert_eq!(r.write(0x2135, 0x0F).await, Ok(()));
    assert_eq!(r.write(0x6001, 0xFF).await, Ok(()));
    let before = r.position().await;
    assert_eq!(r.relative(400).await, Ok(()));
    r.wait_still().await;
    assert_eq!(r.position().await, before + 400);
    let encoder = r.read(0x6089, 2).await.expect("encoder");
    let encoder = ((u32::from(encoder[0]) << 16) | u32::from(encoder[1])) as i32;
    let offset = r.read(0x6087, 2).await.expect("offset");
    let offset = ((u32::from(offset[0]) << 16) | u32::from(offset[1])) as i32;
    assert!((encoder + offset - (before + 400)).abs() <= 2, "{encoder} + {offset}");
    r.off();
}

#[tokio::test(flavor = "current_thread")]
async fn a_stall_in_open_loop_sets_bit_2_and_stops_the_motor() {
    let mut r = rig(None).await;
    for (addr, v) in [(0x2107, 1), (0x6043, 1), (0x600C, 16), (0x600D, 1000)] {
        assert_eq!(r.write(addr, v).await, Ok(()), "{addr:#x}");
    }
    assert_eq!(r.write32(0x6003, 9600).await, Ok(()));
    assert_eq!(r.relative(1_000_000).await, Ok(()));
    sleep(Duration::from_millis(1500)).await;
    assert_eq!(r.reg(0x6001).await, 1 << 3, "running freely: busy, no stall");
    r.injector.inject(Change::Blocked(true));
    r.wait_for(0x6001, 1 << 2).await;
    // Stopped (0x6043 = 1), not faulted: the power stage stays on, moves are refused. The
    // simulator publishes its snapshot as its loop catches up, which may be a step behind the
    // reply that showed the stall: a few milliseconds to show the stop.
    let mut s = r.snapshot();
    for _ in 0..50 {
        if s.velocity == 0.0 {
            break;
        }
        sleep(Duration::from_millis(2)).await;
        s = r.snapshot();
    }
    assert_eq!(s.velocity, 0.0, "{s:?}");
    assert!(s.enabled);
    assert_eq!(r.relative(100).await, Err(ExceptionCode::ServerDeviceFailure));
    r.injector.inject(Change::Blocked(false));
    assert_eq!(r.write(0x6001, 1 << 2).await, Ok(()));
    assert_eq!(r.relative(100).await, Ok(()));
    r.wait_still().await;
    r.off();
}
