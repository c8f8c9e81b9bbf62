//! The drive's inputs and outputs through a master we did not write (tokio-modbus over TCP) on
//! the simulator with switches on its machine: external stops latch and refuse moves until
//! cleared; seed 000 §9.4.4's settings and §5.6's zero search; the built-in homing; step
//! notifications; analog positioning; a 12 V supply; a negative relative move.

use std::sync::{Arc, Mutex};
use std::time::Duration;

use drive_tests::{read_values, write, write_many};
use hal_sim::machine::{Analog, Machine, Switch};
use hal_sim::motor::MotorInputs;
use hal_sim::{Endpoint, MotorOptions, PowerSwitch, SimOptions, Simulator, Snapshot};
use tokio::net::TcpStream;
use tokio::time::sleep;
use tokio_modbus::client::{Context, rtu};
use tokio_modbus::prelude::{ExceptionCode, Slave};

/// One simulator at a time: each runs its motor in real time (see `faults.rs`).
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// A running simulator with `switches` and `analog` on its machine, and a master on it.
struct Rig {
    _turn: std::sync::MutexGuard<'static, ()>,
    ctx: Context,
    _sim: PowerSwitch,
    snapshot: Arc<Mutex<Snapshot>>,
    /// Microsteps a full step (0x600C as last written).
    per_step: f64,
}

async fn rig(switches: &[&str], analog: Option<&str>, supply_v: f64) -> Rig {
    let switches = switches.iter().map(|s| Switch::parse(s).expect("switch spec")).collect();
    rig_on(Machine::new(switches, analog.map(|a| Analog::parse(a).expect("analog spec"))), supply_v).await
}

#[allow(clippy::await_holding_lock)] // see faults.rs: one runtime a test
async fn rig_on(machine: Machine, supply_v: f64) -> Rig {
    let turn = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let opts = SimOptions {
        endpoint: Endpoint::Tcp("127.0.0.1:0".into()),
        machine,
        motor: MotorOptions { inputs: MotorInputs { supply_v, ..MotorInputs::default() }, ..MotorOptions::default() },
        ..Default::default()
    };
    let sim = Simulator::bind(opts).expect("bind simulator");
    let snapshot = sim.snapshot();
    let sim = sim.power_on();
    let stream = TcpStream::connect(sim.endpoint()).await.expect("connect");
    let mut r = Rig { _turn: turn, ctx: rtu::attach_slave(stream, Slave(1)), _sim: sim, snapshot, per_step: 16.0 };
    // 1/16 microsteps, 1 A, 3200 pps (200 full steps a second).
    r.set(0x600C, 16).await;
    r.set(0x600D, 1000).await;
    r.set32(0x6003, 3200).await;
    r
}

impl Rig {
    async fn reg(&mut self, addr: u16) -> u16 {
        read_values(&mut self.ctx, addr, 1).await[0]
    }

    async fn reg32(&mut self, addr: u16) -> i32 {
        let w = read_values(&mut self.ctx, addr, 2).await;
        ((u32::from(w[0]) << 16) | u32::from(w[1])) as i32
    }

    async fn set(&mut self, addr: u16, v: u16) {
        assert_eq!(write(&mut self.ctx, addr, v).await, Ok(()), "{addr:#06x} = {v}");
        if addr == 0x600C {
            self.per_step = f64::from(v.max(1));
        }
    }

    async fn try_set32(&mut self, addr: u16, v: i32) -> Result<(), ExceptionCode> {
        let v = v as u32;
        write_many(&mut self.ctx, addr, &[(v >> 16) as u16, v as u16]).await
    }

    async fn set32(&mut self, addr: u16, v: i32) {
        assert_eq!(self.try_set32(addr, v).await, Ok(()), "{addr:#06x} = {v}");
    }

    /// The rotor, full steps from power-up.
    fn rotor(&self) -> f64 {
        self.snapshot.lock().expect("snapshot").rotor_microsteps / self.per_step
    }

    /// Waits until the axis is at rest (0x6001 bit 3 clear), within `secs`.
    async fn wait_still(&mut self, secs: u64) {
        for _ in 0..secs * 50 {
            sleep(Duration::from_millis(20)).await;
            if self.reg(0x6001).await & 8 == 0 {
                return;
            }
        }
        panic!("still moving after {secs} s");
    }
}

/// Every input, edge and sensor type through the master: a switch 40 full steps ahead on the
/// input, the stop enabled as (0x6013 bit, rising, 0x6015); the move stops and the input's bit
/// (0x6001) latches, moves are refused until it is cleared.
#[tokio::test(flavor = "current_thread")]
async fn each_ext_input_edge_and_sensor_type_stops_a_move_and_latches() {
    let cases = [
        ("ext1:npn:40", 1u16, 0u16, 0u16, 1u16),
        ("ext2:pnp:40", 2, 2, 0, 2),
        ("ext3:pnp:40:nc", 16, 0, 1, 16),
        ("ext1:npn:40:nc", 1, 1, 1, 1),
    ];
    for (switch, enable, rising, kind, bit) in cases {
        let mut r = rig(&[switch], None, 24.0).await;
        r.set(0x6042, 5).await;
        r.set(0x6013, enable).await;
        r.set(0x6014, rising).await;
        r.set(0x6015, kind).await;
        r.set32(0x6005, 3200).await;
        r.wait_still(3).await;
        assert_eq!(r.reg(0x6001).await, bit, "{switch}: its bit alone");
        let at = r.rotor();
        assert!((40.0..100.0).contains(&at), "{switch}: stopped past the switch at 40: {at}");
        assert_eq!(r.try_set32(0x6005, -800).await, Err(ExceptionCode::ServerDeviceFailure), "{switch}");
        r.set(0x6001, bit).await;
        r.set32(0x6005, -800).await;
        r.wait_still(3).await;
        assert!((r.rotor() - (at - 50.0)).abs() < 0.5, "{switch}: moves again");
    }
}

#[tokio::test(flavor = "current_thread")]
async fn an_ext_stop_latches_refuses_moves_until_cleared_and_a_negative_move_goes_back() {
    // A home switch 40 full steps back, an NPN output with a bouncing contact: EXT1 on the
    // falling edge, type 0 (pulled up), the default 100 ms confirmation.
    let mut r = rig(&["ext1:npn:-40:below:bounce=3"], None, 24.0).await;
    r.set(0x6013, 1).await;
    r.set(0x6014, 0).await;
    r.set(0x6015, 0).await;
    // A relative move of -3200 (signed, as appendix 1 types it): 200 full steps back.
    r.set32(0x6005, -3200).await;
    r.wait_still(3).await;
    let status = r.reg(0x6001).await;
    assert_eq!(status & 0b1_0011, 1, "EXT1's bit alone: {status:#x}");
    // Confirmed 100 ms after the edge (20 full steps at 200 a second), then the moves'
    // deceleration (0x600B's level).
    let at = r.rotor();
    assert!((-160.0..-40.0).contains(&at), "stopped past the switch: {at}");
    // 0x6031 bit 7: EXT1 low (the switch actuated), shown as 1.
    assert_eq!(r.reg(0x6031).await & (1 << 7), 1 << 7);
    // Moves are refused until the bit is cleared; nothing moves meanwhile.
    assert_eq!(r.try_set32(0x6005, 800).await, Err(ExceptionCode::ServerDeviceFailure));
    sleep(Duration::from_millis(200)).await;
    assert!((r.rotor() - at).abs() < 0.1);
    r.set(0x6001, 1).await;
    r.set32(0x6005, 3200).await;
    r.wait_still(3).await;
    assert!((r.rotor() - (at + 200.0)).abs() < 0.5, "a move of 3200 forward: {}", r.rotor());
    // Leaving the switch is no falling edge: nothing latched.
    assert_eq!(r.reg(0x6001).await & 1, 0);
    // Back by -3200 again: 200 full steps back, onto the switch: it stops again, once.
    r.set32(0x6005, -3200).await;
    r.wait_still(3).await;
    assert_eq!(r.reg(0x6001).await & 1, 1);
}

#[tokio::test(flavor = "current_thread")]
async fn the_manuals_settings_and_zero_search() {
    let mut r = rig(&["ext1:npn:-30:below", "ext2:npn:-400:below"], None, 24.0).await;
    // §9.4.4: 32 microsteps, 1000 mA (0x3E8), start and stop speed 600, acceleration and
    // deceleration levels 8, EXT1 and EXT2 enabled on the falling edge, then the save.
    for (addr, v) in [(0x600C, 0x20), (0x600D, 0x3E8), (0x6008, 0x258), (0x6009, 0x258), (0x600A, 8), (0x600B, 8)] {
        r.set(addr, v).await;
    }
    r.set(0x6013, 3).await;
    r.set(0x6014, 0).await;
    r.set(0x200F, 2).await;
    // §5.6: towards the switch in the velocity mode, the EXT stop, the position set to 0.
    r.set(0x6007, 1).await;
    r.set32(0x6003, -6400).await;
    r.wait_still(5).await;
    assert_eq!(r.reg(0x6001).await & 0b11, 1, "EXT1 stopped it");
    r.set(0x6001, 1).await;
    r.set(0x6007, 0).await;
    r.set32(0x600E, 0).await;
    assert_eq!(r.reg32(0x600E).await, 0);
    // Where the motor stopped, past the switch by the confirmation and the ramp (the built-in
    // homing is the precise way).
    let zero = r.rotor();
    assert!((-120.0..-30.0).contains(&zero), "stopped past the switch at -30: {zero}");
    // The position counts from there: 3200 microsteps of 1/32 are 100 full steps.
    r.set32(0x6003, 6400).await;
    r.set32(0x6044, 3200).await;
    r.wait_still(3).await;
    assert!((r.rotor() - (zero + 100.0)).abs() < 0.5, "{} from {zero}", r.rotor());
}

#[tokio::test(flavor = "current_thread")]
async fn the_built_in_homing_finds_the_home_switch() {
    let mut r = rig(&["ext1:npn:25:hyst=0.2"], None, 24.0).await;
    // Method 19 (home switch actuated above home, found moving down) on EXT1, active low,
    // pulled up (0x602F's EXT1 field), home = 500.
    r.set32(0x602F, 1 << 14).await;
    r.set(0x2160, 19).await;
    r.set(0x216C, 1).await;
    r.set(0x216D, 0).await;
    r.set32(0x2169, 500).await;
    r.set(0x2161, 1).await;
    for _ in 0..250 {
        sleep(Duration::from_millis(20)).await;
        if r.reg(0x2162).await != 1 {
            break;
        }
    }
    assert_eq!(r.reg(0x2162).await, 2, "homed");
    let past = f64::from(r.reg32(0x600E).await - 500) / 16.0;
    let home = r.rotor() - past;
    assert!((home - 25.0).abs() < 0.5, "the home at the switch's edge: {home}");
}

#[tokio::test(flavor = "current_thread")]
async fn step_notifications_both_ways() {
    let mut r = rig(&[], None, 24.0).await;
    r.set32(0x6062, 1000).await;
    r.set32(0x6064, -500).await;
    r.set32(0x6044, 2000).await;
    r.wait_still(3).await;
    assert_eq!(r.reg(0x6061).await, 1);
    r.set32(0x6044, -1000).await;
    r.wait_still(3).await;
    assert_eq!(r.reg(0x6061).await, 3);
    r.set(0x6061, 3).await;
    assert_eq!(r.reg(0x6061).await, 0);
}

#[tokio::test(flavor = "current_thread")]
async fn analog_positioning_follows_the_input() {
    // 0 → 3.3 V over 2 s: the target from 0 to 16 000.
    let mut r = rig(&[], Some("ramp=0/3.3/2"), 24.0).await;
    r.set32(0x607D, 16_000).await;
    r.set(0x6007, 4).await;
    r.set(0x6077, 1).await;
    sleep(Duration::from_millis(3500)).await;
    assert_eq!(r.reg(0x605F).await, 4095);
    assert_eq!(r.reg32(0x600E).await, 16_000);
    assert!((r.rotor() - 1000.0).abs() < 1.0, "{}", r.rotor());
}

#[tokio::test(flavor = "current_thread")]
async fn a_12_v_supply_moves() {
    let mut r = rig(&[], None, 12.0).await;
    assert_eq!(r.reg(0x6000).await, 0, "no under-voltage alarm at 12 V");
    r.set32(0x6005, 3200).await;
    r.wait_still(3).await;
    assert!((r.rotor() - 200.0).abs() < 0.5, "{}", r.rotor());
}

/// Work mode 3, the manual's encoder follower, with 0x21B7 = 3: an encoder's quadrature on the
/// pulse input moves the motor one microstep an edge; moves are refused (04) meanwhile, and
/// mode 0 stops the following.
#[tokio::test(flavor = "current_thread")]
async fn mode_3_follows_an_encoder_on_the_pulse_input() {
    // 4 000 edges back at up to 8 000 a second, from 300 ms after power-up.
    let train = hal_sim::pulses::Train::parse("quadrature:-8000:count=4000:accel=100000:at=300").expect("train");
    let mut machine = Machine::default();
    machine.pulses = Some(hal_sim::pulses::PulseSource::new(train));
    let mut r = rig_on(machine, 24.0).await;
    r.set(0x21B7, 3).await;
    r.set(0x6007, 3).await;
    assert_eq!(r.try_set32(0x6005, 800).await, Err(ExceptionCode::ServerDeviceFailure), "moves are refused");
    sleep(Duration::from_millis(1_200)).await;
    assert_eq!(r.reg32(0x600E).await, -4_000, "one microstep an edge");
    assert!((r.rotor() + 250.0).abs() < 0.1, "the rotor followed: {} full steps", r.rotor());
    r.set(0x6007, 0).await;
    r.set32(0x6005, 800).await;
    r.wait_still(3).await;
    assert_eq!(r.reg32(0x600E).await, -3_200, "mode 0 moves again");
}
