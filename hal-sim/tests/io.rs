//! The drive's pins on the simulated machine, tick by tick: external stops on every input, edge
//! and sensor type stop the motor in the tick that confirms the edge and latch their bit; a
//! bouncing switch stops once, a pulse shorter than 0x6042 not at all; step notifications in
//! both directions with their output pulse; GPIO outputs and inputs with the manual's inverted
//! bits; the coil output as a brake and as a general output; a hard stop holds the rotor.

use drive_core::od::{Obj, ObjError};
use hal_sim::machine::{Machine, Switch};
use hal_sim::plant::Plant;

/// Microsteps a full step here.
const PER_STEP: i64 = 16;

/// The NEMA 17 at 24 V, 1/16 microsteps, 1000 mA, 3200 pps (200 full steps a second), with
/// `switches` on its machine.
fn plant(switches: &[&str]) -> Plant {
    let switches = switches.iter().map(|s| Switch::parse(s).expect("switch spec")).collect();
    let mut plant = Plant::factory_on(Machine::new(switches, None));
    for (obj, v) in [(Obj::Microsteps, 16), (Obj::PhaseCurrent, 1000), (Obj::MaxSpeed, 3200)] {
        set(&mut plant, obj, v);
    }
    run(&mut plant, 0.05);
    plant
}

fn set(plant: &mut Plant, obj: Obj, value: u32) {
    assert_eq!(plant.write(obj, value), Ok(()), "{obj:?} = {value}");
}

fn run(plant: &mut Plant, secs: f64) {
    plant.run_for(secs);
}

/// One tick.
fn tick(plant: &mut Plant) {
    let now = plant.next_tick();
    plant.advance_to(now);
}

fn read(plant: &Plant, obj: Obj) -> u32 {
    plant.drive().state().read(obj)
}

fn level(plant: &Plant, pin: u32) -> bool {
    plant.last_inputs().expect("ticked").levels & (1 << pin) != 0
}

fn velocity(plant: &Plant) -> f32 {
    plant.outputs().expect("ticked").setpoint.velocity
}

/// Moves forward with EXT `k` (1-3) enabled on `edge` (true rising) for sensor `kind` (0x6015)
/// and delay `delay_ms`, towards the switch `spec`: the tick of the edge, the tick the stop
/// started (the setpoint slowing), and the plant.
fn run_into(spec: &str, k: usize, rising: bool, kind: u32, delay_ms: u32) -> (u64, u64, Plant) {
    let (bit, pin) = [(1u32, 7u32), (2, 8), (16, 9)][k - 1];
    let mut p = plant(&[spec]);
    set(&mut p, Obj::ExtStopEnable, bit);
    set(&mut p, Obj::ExtStopTrigger, if rising { bit } else { 0 });
    set(&mut p, Obj::SensorType, kind);
    set(&mut p, Obj::ExtDebounce, delay_ms);
    run(&mut p, 0.01);
    let idle = level(&p, pin);
    set(&mut p, Obj::RelativeMove, 100_000);
    let (mut edge, mut stop) = (None, None);
    let mut last_v = 0.0;
    for t in 0..200_000u64 {
        tick(&mut p);
        let (l, v) = (level(&p, pin), velocity(&p));
        if edge.is_none() && l != idle {
            assert_eq!(l, rising, "the pin moved to the trigger's level");
            edge = Some(t);
        }
        if edge.is_some() && v < last_v {
            stop = Some(t);
            break;
        }
        last_v = v;
    }
    let status = read(&p, Obj::ControllerStatus);
    let rotor = p.motor().rotor_full_steps();
    let gpio = read(&p, Obj::GpioValue);
    (
        edge.expect("the switch was reached"),
        stop.unwrap_or_else(|| {
            panic!("no stop: edge {edge:?} status {status:#x} rotor {rotor} gpio {gpio:#x} v {last_v}")
        }),
        p,
    )
}

#[test]
fn each_input_edge_and_sensor_type_stops_in_the_tick_that_confirms_the_edge() {
    // (switch, EXT, rising, 0x6015): the sensor's actuation drives the pin against the pull
    // (type 0), or a normally closed sensor lets go and the pull takes the pin (type 1).
    let cases = [
        ("ext1:npn:20", 1, false, 0),
        ("ext2:pnp:20", 2, true, 0),
        ("ext3:pnp:20:nc", 3, false, 1),
        ("ext1:npn:20:nc", 1, true, 1),
        ("ext2:contact:20", 2, false, 0),
    ];
    for (spec, k, rising, kind) in cases {
        for delay_ms in [0, 5] {
            let (edge, stop, mut p) = run_into(spec, k, rising, kind, delay_ms);
            let confirmed = edge + u64::from(delay_ms) * 20;
            assert!(stop == confirmed || stop == confirmed + 1, "{spec} {delay_ms} ms: edge {edge}, stop {stop}");
            let status_bit = [1u32, 2, 16][k - 1];
            assert_eq!(read(&p, Obj::ControllerStatus) & status_bit, status_bit, "{spec}: latched");
            run(&mut p, 0.5);
            assert_eq!(velocity(&p), 0.0, "{spec}: stopped");
            // Moves are refused until the master clears the bit; then they run again.
            let state = p.drive_mut().state_mut();
            assert_eq!(state.check(Obj::RelativeMove, 100), Err(ObjError::Faulted));
            state.apply(Obj::ControllerStatus, status_bit);
            assert_eq!(state.check(Obj::RelativeMove, 100), Ok(()));
        }
    }
}

#[test]
fn a_bouncing_switch_stops_once_and_settles_latched() {
    let (_, _, mut p) = run_into("ext1:contact:20:bounce=4", 1, false, 0, 10);
    run(&mut p, 2.0);
    let stopped_at = p.outputs().expect("ticked").setpoint.whole;
    assert_eq!(read(&p, Obj::ControllerStatus) & 1, 1);
    run(&mut p, 0.3);
    assert_eq!(p.outputs().expect("ticked").setpoint.whole, stopped_at);
}

#[test]
fn a_pulse_shorter_than_the_delay_does_not_stop() {
    // A cam 0.4 full steps wide passed at 200 steps/s: a 2 ms pulse against a 10 ms delay.
    let mut p = plant(&["ext1:npn:20:to=20.4:hyst=0"]);
    set(&mut p, Obj::ExtStopEnable, 1);
    set(&mut p, Obj::ExtDebounce, 10);
    set(&mut p, Obj::RelativeMove, 50 * PER_STEP as u32);
    let mut low_ticks = 0;
    for _ in 0..20_000 {
        tick(&mut p);
        low_ticks += u32::from(!level(&p, 7));
    }
    assert!((20..200).contains(&low_ticks), "a pulse of {low_ticks} ticks");
    assert_eq!(read(&p, Obj::ControllerStatus) & 1, 0);
    assert_eq!(p.outputs().expect("ticked").setpoint.whole, 50 * PER_STEP);
    // With a delay below the pulse it stops.
    let mut p = plant(&["ext1:npn:20:to=20.4:hyst=0"]);
    set(&mut p, Obj::ExtStopEnable, 1);
    set(&mut p, Obj::ExtDebounce, 1);
    set(&mut p, Obj::RelativeMove, 50 * PER_STEP as u32);
    run(&mut p, 1.0);
    assert_eq!(read(&p, Obj::ControllerStatus) & 1, 1);
    assert!(p.outputs().expect("ticked").setpoint.whole < 50 * PER_STEP, "the move did not end");
}

#[test]
fn the_levels_show_inverted_in_0x6031_and_the_pulls_follow_the_settings() {
    let mut p = plant(&["ext1:npn:-10:below", "gpio1:contact:-10:below"]);
    // EXT1 floats low without a pull: 0x6031 bit 7 reads 1 (low).
    assert_eq!(read(&p, Obj::GpioValue) & 0x81, 0x81);
    // Enabled for the falling edge, type 0: pulled up, the open NPN leaves it high.
    set(&mut p, Obj::ExtStopEnable, 1);
    // GPIO1 an input with a pull-up (0x602F bits 1-0 = 1).
    set(&mut p, Obj::GpioConfig, 1);
    run(&mut p, 0.01);
    assert_eq!(read(&p, Obj::GpioValue) & 0x81, 0);
    // Both switches actuated 10 steps back: both pins pulled low.
    set(&mut p, Obj::RelativeMove, (-20 * PER_STEP) as u32);
    run(&mut p, 0.5);
    assert_eq!(read(&p, Obj::GpioValue) & 0x81, 0x81);
    assert_eq!(read(&p, Obj::ControllerStatus) & 1, 1, "EXT1 stopped the move");
}

#[test]
fn gpio8_as_an_output_drives_its_pin_with_the_inverted_bit() {
    let mut p = plant(&[]);
    set(&mut p, Obj::GpioDirection, 1 << 11);
    set(&mut p, Obj::GpioConfig, 1 << 22); // push-pull
    run(&mut p, 0.001);
    // 0x6031 = 0: high.
    assert_eq!(p.outputs().expect("ticked").gpio & (1 << 11), 1 << 11);
    assert!(level(&p, 11));
    set(&mut p, Obj::GpioValue, 1 << 11);
    run(&mut p, 0.001);
    assert_eq!(p.outputs().expect("ticked").gpio & (1 << 11), 0);
    assert!(!level(&p, 11));
    // A write to an input's bit changes nothing: GPIO1 floats low (reads 1) before and after.
    set(&mut p, Obj::GpioValue, 1 << 11);
    assert_eq!(read(&p, Obj::GpioValue) & 1, 1);
    set(&mut p, Obj::GpioValue, 1 << 11);
    run(&mut p, 0.001);
    assert_eq!(read(&p, Obj::GpioValue) & 1, 1);
}

#[test]
fn step_notifications_set_in_both_directions_and_pulse_their_output() {
    let mut p = plant(&[]);
    set(&mut p, Obj::NotifyPos1, 1000);
    set(&mut p, Obj::NotifyPos2, (-500i32) as u32);
    set(&mut p, Obj::GpioDirection, 1 << 11);
    set(&mut p, Obj::GpioValue, 1 << 11); // low outside the pulse
    set(&mut p, Obj::NotifyOutput, (2 << 8) | 8); // GPIO8, 2 ms
    run(&mut p, 0.001);
    set(&mut p, Obj::AbsoluteMove, 2000);
    let (mut crossed, mut high) = (None, 0);
    for t in 0..20_000 {
        tick(&mut p);
        let out = p.outputs().expect("ticked");
        if crossed.is_none() && out.setpoint.whole >= 1000 {
            crossed = Some(t);
            assert_eq!(read(&p, Obj::NotifyStatus), 1, "set in the tick the setpoint reaches it");
        }
        high += u32::from(out.gpio & (1 << 11) != 0);
    }
    assert!(crossed.is_some());
    assert_eq!(high, 40, "a 2 ms pulse");
    // Back past -500: bit 1 too (and bit 0, crossed again); write 1 to clear.
    set(&mut p, Obj::AbsoluteMove, (-1000i32) as u32);
    run(&mut p, 2.0);
    assert_eq!(read(&p, Obj::NotifyStatus), 3);
    set(&mut p, Obj::NotifyStatus, 1);
    assert_eq!(read(&p, Obj::NotifyStatus), 2);
}

#[test]
fn the_coil_output_as_a_brake_and_as_a_general_output() {
    let mut p = plant(&[]);
    set(&mut p, Obj::Brake, 60);
    run(&mut p, 0.001);
    assert_eq!(p.outputs().expect("ticked").coil_duty, 60, "brake released while enabled");
    set(&mut p, Obj::Enable, 0);
    run(&mut p, 0.001);
    assert_eq!(p.outputs().expect("ticked").coil_duty, 0, "applied when disabled");
    set(&mut p, Obj::CoilMode, 1);
    run(&mut p, 0.001);
    assert_eq!(p.outputs().expect("ticked").coil_duty, 60, "a general output follows 0x6038");
    p.inject(hal_sim::inject::Change::DriverTemperature(120.0));
    run(&mut p, 0.001);
    assert_eq!(p.outputs().expect("ticked").coil_duty, 0, "cut while a fault is latched");
}

#[test]
fn a_hard_stop_holds_the_rotor_while_the_drive_pushes_on() {
    let mut p = plant(&[]);
    p.motor_mut().set_hard_stops(None, Some(10.0));
    set(&mut p, Obj::StallDetect, 0);
    set(&mut p, Obj::RelativeMove, 40 * PER_STEP as u32);
    run(&mut p, 1.0);
    let rotor = p.motor().rotor_full_steps();
    assert!((rotor - 10.0).abs() < 1e-9, "{rotor}");
    assert_eq!(p.outputs().expect("ticked").setpoint.whole, 40 * PER_STEP, "the setpoint went on");
}

/// The plant with an analog source `spec` (`--analog`'s syntax).
fn with_analog(spec: &str) -> Plant {
    let mut p = plant(&[]);
    *p.machine_mut() = Machine::new(Vec::new(), Some(hal_sim::machine::Analog::parse(spec).expect("analog spec")));
    p
}

/// The share of the ticks over `secs` in which the setpoint moves.
fn moving(p: &mut Plant, secs: f64) -> f64 {
    let ticks = (secs * 20_000.0) as u32;
    let n: u32 = (0..ticks)
        .map(|_| {
            tick(p);
            u32::from(velocity(p) != 0.0)
        })
        .sum();
    f64::from(n) / f64::from(ticks)
}

#[test]
fn analog_positioning_follows_a_ramp_and_holds_still_on_a_noisy_constant() {
    // 0 → 3.3 V over 4 s: the target runs from 0x607B (0) to 0x607D (64 000).
    let mut p = with_analog("ramp=0/3.3/4");
    set(&mut p, Obj::Mode, 4);
    set(&mut p, Obj::AnalogPosEnable, 1);
    run(&mut p, 2.0);
    let halfway = p.outputs().expect("ticked").setpoint.whole;
    // Behind the input by the interval's averaging, the planning and the motion's dynamics.
    assert!((24_000..36_000).contains(&halfway), "half-way up the ramp: {halfway}");
    run(&mut p, 4.0);
    assert_eq!(p.outputs().expect("ticked").setpoint.whole, 64_000);
    // 1.65 V with ±10 mV of noise (±12 codes, ±190 steps a reading): averaged over 100 ms and
    // with a dead band of 200 steps the motor stands; acting on every wobble (0 dead band and
    // a 10 ms interval) it hunts.
    let mut p = with_analog("1.65~0.01");
    set(&mut p, Obj::Mode, 4);
    set(&mut p, Obj::AnalogTrigger, 200);
    set(&mut p, Obj::AnalogPosEnable, 1);
    run(&mut p, 3.0);
    let at = p.outputs().expect("ticked").setpoint.whole;
    assert!((at - 32_008).abs() < 300, "near mid-scale: {at}");
    assert_eq!(moving(&mut p, 3.0), 0.0, "holds still");
    set(&mut p, Obj::AnalogTrigger, 0);
    set(&mut p, Obj::AnalogInterval, 10);
    let hunting = moving(&mut p, 3.0);
    assert!(hunting > 0.5, "without filter and dead band it hunts: moving {hunting}");
}

#[test]
fn analog_speed_follows_the_input_in_the_velocity_mode() {
    let mut p = with_analog("ramp=0/3.3/2");
    set(&mut p, Obj::Mode, 1);
    set(&mut p, Obj::AnalogSpeedEnable, 1);
    set(&mut p, Obj::AnalogSpeedFull, 3200);
    run(&mut p, 1.0);
    let v = velocity(&p);
    assert!((1200.0..2000.0).contains(&v), "half-way: {v} pps");
    run(&mut p, 2.0);
    // Within the dead band (0x2173, 50 pps) of full scale.
    assert!((velocity(&p) - 3200.0).abs() <= 50.0, "full scale: {}", velocity(&p));
    // Off: the input no longer sets the speed.
    set(&mut p, Obj::AnalogSpeedEnable, 0);
    set(&mut p, Obj::MaxSpeed, 0);
    run(&mut p, 2.0);
    assert_eq!(velocity(&p), 0.0);
}
