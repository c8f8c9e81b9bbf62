//! The inputs' and outputs' functions (our 0x21BA-0x21C9, seed 002's 0400-0430) on the
//! simulated machine, tick by tick: limit inputs stop a motion heading into them and refuse
//! commands towards them; command inputs, pressed or set as pseudo-inputs, run their command once
//! an activation; an enable input holds the power stage at its level; a home input is the
//! homing's switch; outputs show the alarm, in-position, general, motor-free and ready states at
//! their logic.

use drive_core::od::{Obj, ObjError};
use hal_sim::inject::Change;
use hal_sim::machine::{Machine, Switch};
use hal_sim::plant::Plant;

/// Microsteps a full step here.
const PER_STEP: i64 = 16;
/// 0x6031's bits: EXT1 (IN1), EXT2 (IN2), EXT3 (IN3), GPIO1 (IN4).
const EXT1: u32 = 7;
const EXT2: u32 = 8;
const GPIO1: u32 = 0;
/// OUT1-OUT4: GPIO5-GPIO8.
const OUT: [u16; 4] = [1 << 4, 1 << 5, 1 << 6, 1 << 11];

/// The NEMA 17 at 24 V, 1/16 microsteps, with `switches` on its machine, in mode 0 at 3200 pps.
fn plant(switches: &[&str]) -> Plant {
    let switches = switches.iter().map(|s| Switch::parse(s).expect("switch spec")).collect();
    let mut plant = Plant::factory_on(Machine::new(switches, None));
    for (obj, v) in [(Obj::Microsteps, 16), (Obj::PhaseCurrent, 1000), (Obj::MaxSpeed, 3200)] {
        set(&mut plant, obj, v);
    }
    plant.run_for(0.02);
    plant
}

fn set(plant: &mut Plant, obj: Obj, value: u32) {
    assert_eq!(plant.write(obj, value), Ok(()), "{obj:?} = {value}");
}

fn position(plant: &Plant) -> i64 {
    plant.outputs().expect("ticked").setpoint.whole
}

fn outputs(plant: &Plant) -> u16 {
    plant.outputs().expect("ticked").gpio
}

#[test]
fn limit_inputs_stop_a_motion_heading_into_them_and_refuse_commands_towards_them() {
    // NPN limit switches 20 full steps up (IN1) and 30 down (IN2), pulled up, active low.
    let mut p = plant(&["ext1:npn:20", "ext2:npn:-30:below"]);
    set(&mut p, Obj::GpioConfig, (1 << (2 * EXT1)) | (1 << (2 * EXT2)));
    set(&mut p, Obj::InputLogic, 0b11);
    set(&mut p, Obj::InputFunction1, 9);
    set(&mut p, Obj::InputFunction2, 10);
    p.run_for(0.01);
    // Jog up into the positive limit: it stops past it at the stop deceleration.
    set(&mut p, Obj::MotionCommand, 4);
    p.run_for(3.0);
    let stopped = position(&p);
    assert!(p.outputs().expect("ticked").setpoint.velocity == 0.0, "stands");
    assert!((20 * PER_STEP..80 * PER_STEP).contains(&stopped), "stopped past the limit at 20 full steps: {stopped}");
    // Towards it again: refused, nothing moves; away from it: free, until the other limit.
    assert_eq!(p.write(Obj::MotionCommand, 4), Err(ObjError::NotNow));
    set(&mut p, Obj::CommandTarget, 10_000);
    assert_eq!(p.write(Obj::MotionCommand, 1), Err(ObjError::NotNow));
    p.run_for(0.2);
    assert_eq!(position(&p), stopped, "a refused command moves nothing");
    set(&mut p, Obj::MotionCommand, 5);
    p.run_for(5.0);
    let back = position(&p);
    assert!((-100 * PER_STEP..-30 * PER_STEP).contains(&back), "stopped past the negative limit: {back}");
    // The native map's moves are stopped by the tick all the same.
    set(&mut p, Obj::RelativeMove, 100_000);
    p.run_for(0.5);
    assert!(position(&p) > back, "moving up, away from the negative limit");
}

#[test]
fn command_inputs_and_pseudo_inputs_run_their_command_once_an_activation() {
    let mut p = plant(&[]);
    // IN4 (GPIO1): absolute run to 0x21A1; IN5, IN6 pseudo-inputs: jog up, stop.
    set(&mut p, Obj::InputFunction4, 1);
    set(&mut p, Obj::InputFunction5, 4);
    set(&mut p, Obj::InputFunction6, 6);
    set(&mut p, Obj::CommandTarget, 3200);
    p.machine_mut().drive_pin(GPIO1, Some(false));
    p.run_for(0.1);
    assert_eq!(position(&p), 0, "nothing before the input turns active");
    p.machine_mut().drive_pin(GPIO1, Some(true));
    p.run_for(2.0);
    assert_eq!(position(&p), 3200, "the run to 0x21A1");
    // Held active, it does not run again: a new target waits for the next activation.
    set(&mut p, Obj::CommandTarget, 0);
    p.run_for(1.0);
    assert_eq!(position(&p), 3200);
    p.machine_mut().drive_pin(GPIO1, Some(false));
    p.run_for(0.01);
    p.machine_mut().drive_pin(GPIO1, Some(true));
    p.run_for(2.0);
    assert_eq!(position(&p), 0, "the next activation runs to the new target");
    // Pseudo-inputs: IN5 jogs up, IN6 stops it.
    set(&mut p, Obj::PseudoInputs, 1 << 4);
    p.run_for(0.5);
    assert!(position(&p) > 200, "jogging: {}", position(&p));
    set(&mut p, Obj::PseudoInputs, (1 << 4) | (1 << 5));
    p.run_for(1.0);
    let at = position(&p);
    p.run_for(0.5);
    assert_eq!(position(&p), at, "stopped");
    // Released and set again, IN5 jogs again.
    set(&mut p, Obj::PseudoInputs, 0);
    p.run_for(0.01);
    set(&mut p, Obj::PseudoInputs, 1 << 4);
    p.run_for(0.3);
    assert!(position(&p) > at, "a second activation");
}

#[test]
fn an_enable_input_holds_the_power_stage_at_its_level() {
    let mut p = plant(&[]);
    set(&mut p, Obj::InputFunction2, 20);
    p.machine_mut().drive_pin(EXT2, Some(false));
    p.run_for(0.05);
    assert!(!p.outputs().expect("ticked").enabled, "released: disabled");
    assert_eq!(p.drive().state().read(Obj::Enable), 0);
    p.machine_mut().drive_pin(EXT2, Some(true));
    p.run_for(0.05);
    assert!(p.outputs().expect("ticked").enabled, "active: enabled");
    // The pseudo-input enables too, while it is set.
    p.machine_mut().drive_pin(EXT2, Some(false));
    set(&mut p, Obj::PseudoInputs, 1 << 1);
    p.run_for(0.05);
    assert!(p.outputs().expect("ticked").enabled);
    set(&mut p, Obj::PseudoInputs, 0);
    p.run_for(0.05);
    assert!(!p.outputs().expect("ticked").enabled);
}

#[test]
fn a_home_input_is_the_homing_switch() {
    // The home switch 40 full steps down on IN2 (EXT2), NPN, pulled up, active low; 0x216C
    // names no input: the input's function 11 makes it the home switch.
    let mut p = plant(&["ext2:npn:-40:below"]);
    set(&mut p, Obj::GpioConfig, 1 << (2 * EXT2));
    set(&mut p, Obj::InputLogic, 0b10);
    set(&mut p, Obj::InputFunction2, 11);
    set(&mut p, Obj::HomingInputs, 0);
    // CiA 402 method 21: the home switch below, approached from above.
    set(&mut p, Obj::HomingMethod, 21);
    p.run_for(0.01);
    set(&mut p, Obj::HomingControl, 1);
    p.run_for(20.0);
    assert_eq!(p.drive().state().read(Obj::HomingResult), 2, "homed");
    // The edge approached from below is where the switch releases: -39.5 with its hysteresis.
    let rotor = p.rotor_microsteps() / PER_STEP as f64;
    assert!((rotor + 39.5).abs() < 1.0, "at the switch's edge: {rotor} full steps");
}

#[test]
fn outputs_show_their_functions_at_their_logic() {
    let mut p = plant(&[]);
    // OUT1 alarm, OUT2 in position, OUT3 general, OUT4 ready (inverted).
    for (obj, v) in [
        (Obj::OutputFunction1, 2),
        (Obj::OutputFunction2, 3),
        (Obj::OutputFunction3, 1),
        (Obj::OutputFunction4, 5),
        (Obj::OutputLogic, 0b1000),
    ] {
        set(&mut p, obj, v);
    }
    p.run_for(0.01);
    let o = outputs(&p);
    assert_eq!(
        [o & OUT[0], o & OUT[1], o & OUT[2], o & OUT[3]],
        [OUT[0], OUT[1], 0, 0],
        "no alarm, in position, off, ready (low)"
    );
    // 0x6031 shows what they drive, inverted as the manual has it (1 low).
    let shown = p.drive().state().read(Obj::GpioValue) as u16;
    assert_eq!(shown & (OUT[0] | OUT[2]), OUT[2], "OUT1 high, OUT3 low");
    set(&mut p, Obj::GeneralOutputs, 0b100);
    p.run_for(0.01);
    assert_eq!(outputs(&p) & OUT[2], OUT[2], "the general output on");
    set(&mut p, Obj::RelativeMove, 3200);
    p.run_for(0.1);
    assert_eq!(outputs(&p) & OUT[1], 0, "moving: not in position");
    p.run_for(2.0);
    assert_eq!(outputs(&p) & OUT[1], OUT[1], "on the target again");
    set(&mut p, Obj::Enable, 0);
    p.run_for(0.01);
    assert_eq!(outputs(&p) & OUT[3], OUT[3], "not ready: high (inverted)");
    set(&mut p, Obj::Enable, 1);
    p.inject(Change::Supply(70.0));
    p.run_for(0.05);
    assert_eq!(outputs(&p) & OUT[0], 0, "an alarm turns the alarm output off");
    assert_eq!(outputs(&p) & OUT[3], OUT[3], "and the drive is not ready");
}

/// Touch probes (input functions 21 and 22; seed 003's 0x2022 = 32, 64): the position at the
/// input's activation, within a microstep of the rotor's at the edge (open loop: the setpoint,
/// crossed at a steady speed; in a ramp the open-loop rotor swings a few microsteps about it),
/// kept until the status bit is cleared, then taken again at the next activation.
#[test]
fn a_touch_probe_captures_the_position_at_its_edge() {
    // A PNP cam from 100 full steps up on EXT1 (IN1): 1600 microsteps at 1/16, crossed at the
    // cruise of a move to 3200.
    let mut p = plant(&["ext1:pnp:100"]);
    set(&mut p, Obj::InputFunction1, 21);
    set(&mut p, Obj::RelativeMove, 3200);
    // The rotor where the input first reads active, tick by tick.
    let mut rotor_at_edge = None;
    for _ in 0..40_000 {
        p.run_for(0.00005);
        if rotor_at_edge.is_none() && p.drive().state().read(Obj::ProbeStatus) & 1 != 0 {
            rotor_at_edge = Some(p.rotor_microsteps());
        }
    }
    let captured = p.drive().state().read_i32(Obj::ProbePosition1);
    let rotor = rotor_at_edge.expect("the probe fired");
    assert!((captured - 1600).abs() <= 1, "captured {captured} at the cam's 1600");
    assert!((f64::from(captured) - rotor).abs() <= 1.0, "captured {captured}, the rotor at {rotor:.2}");
    assert_eq!(position(&p), 3200);
    // Back below the cam and up again: no new capture while the bit is set...
    set(&mut p, Obj::RelativeMove, (-3200i32) as u32);
    p.run_for(2.0);
    set(&mut p, Obj::RelativeMove, 2000);
    p.run_for(2.0);
    assert_eq!(p.drive().state().read_i32(Obj::ProbePosition1), captured);
    // ... and after a clear, the next activation captures again.
    set(&mut p, Obj::ProbeStatus, 1);
    assert_eq!(p.drive().state().read(Obj::ProbeStatus), 0);
    set(&mut p, Obj::RelativeMove, (-2000i32) as u32);
    p.run_for(2.0);
    set(&mut p, Obj::RelativeMove, 3200);
    p.run_for(2.0);
    assert_eq!(p.drive().state().read(Obj::ProbeStatus), 1, "probe 1 again; probe 2 not wired");
    assert!((p.drive().state().read_i32(Obj::ProbePosition1) - 1600).abs() <= 1);
}

/// A contact that bounces for 5 ms when the rotor reaches it: without a filter (0x21FC = 50 µs,
/// one tick) the drive sees IN4 turn active several times; filtered over 10 ms, once, and a
/// touch probe on it captures where the contact first closed.
#[test]
fn a_bouncing_input_counts_once_through_its_filter() {
    let activations = |filter_us: u32| {
        // A contact to ground 10 full steps up on GPIO1 (IN4), pulled up: active low.
        let mut p = plant(&["gpio1:contact:10:bounce=5"]);
        set(&mut p, Obj::GpioConfig, 1);
        set(&mut p, Obj::InputLogic, 1 << 3);
        set(&mut p, Obj::InputFunction4, 21);
        set(&mut p, Obj::InputFilter4, filter_us);
        set(&mut p, Obj::MaxSpeed, 800);
        // The pull-up reaches the pin at the next tick: the input settles before the move.
        p.run_for(0.05);
        assert_eq!(p.drive().state().read(Obj::InputStates), 0, "open: inactive");
        set(&mut p, Obj::RelativeMove, 20 * PER_STEP as u32);
        let (mut count, mut was) = (0, false);
        for _ in 0..(0.5 / 50e-6) as u32 {
            p.run_for(50e-6);
            let active = p.drive().state().read(Obj::InputStates) & (1 << 3) != 0;
            count += u32::from(active && !was);
            was = active;
        }
        let probe = p.drive().state().read(Obj::ProbePosition1) as i32;
        (count, probe)
    };
    let (bouncing, _) = activations(50);
    assert!(bouncing > 1, "unfiltered: {bouncing} activations");
    let (filtered, probe) = activations(10_000);
    assert_eq!(filtered, 1);
    // Where the contact closed: 10 full steps, within the switch's hysteresis.
    assert!((probe - 10 * PER_STEP as i32).abs() <= PER_STEP as i32, "captured at {probe}");
}
