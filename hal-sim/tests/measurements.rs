//! What the simulated drive measures, as a real drive's platform would: the bridge voltages
//! averaged over a tick, the shaft encoder (and its injected faults), the driver temperature from
//! the thermal model.

use std::f64::consts::TAU;

use drive_core::Drive;
use drive_core::control::TICK_MICROS;
use drive_core::faults::Inputs;
use drive_core::od::Obj;
use hal_sim::DEFAULT_MOTOR;
use hal_sim::encoder::{EncoderFault, EncoderKind};
use hal_sim::inject::Change;
use hal_sim::motor::{Motor, MotorCatalog, MotorInputs};
use hal_sim::plant::Plant;

/// The NEMA 17 at 24 V, 1/16 microsteps (3200 a turn), 1000 mA, speed 3200 pps.
fn plant() -> Plant {
    let params = MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().expect("catalogue motor");
    let mut plant = Plant::new(Drive::factory(), Motor::new(params, MotorInputs::default()));
    for (obj, v) in [(Obj::Microsteps, 16), (Obj::PhaseCurrent, 1000), (Obj::MaxSpeed, 3200)] {
        set(&mut plant, obj, v);
    }
    plant
}

fn set(plant: &mut Plant, obj: Obj, value: u32) {
    assert_eq!(plant.write(obj, value), Ok(()), "{obj:?} = {value}");
}

fn run(plant: &mut Plant, secs: f64) {
    plant.run_for(secs);
}

/// One tick; what the drive will measure at the next one.
fn tick(plant: &mut Plant) -> Inputs {
    let t = plant.next_tick();
    plant.advance_to(t);
    plant.measurements()
}

fn encoder(plant: &Plant) -> Option<u32> {
    plant.measurements().encoder
}

#[test]
fn at_standstill_the_mean_bridge_voltage_is_r_times_i() {
    let mut p = plant();
    // Half a step off the full step: both phases carry current.
    set(&mut p, Obj::RelativeMove, 8);
    run(&mut p, 0.2);
    let r = p.motor().params().r_ohm;
    let m = tick(&mut p);
    let (v, i) = (m.phase_mv.expect("voltages"), m.phase_ma.expect("currents"));
    for k in 0..2 {
        let want = r * f64::from(i[k]);
        assert!(i[k].abs() > 300, "phase {k}: {i:?} mA");
        assert!((f64::from(v[k]) - want).abs() <= 0.01 * want.abs() + 2.0, "phase {k}: {v:?} mV, R·i {want} mV");
    }
}

#[test]
fn at_speed_what_r_and_l_do_not_explain_is_the_back_emf() {
    let mut p = plant();
    set(&mut p, Obj::Mode, 1);
    set(&mut p, Obj::MaxSpeed, 9600);
    // Three turns a second: an electrical frequency of 150 Hz, 133 ticks a cycle.
    run(&mut p, 1.5);
    let params = p.motor().params().clone();
    let (r, l, t) = (params.r_ohm, params.l_henry, TICK_MICROS as f64 * 1e-6);
    let mut before = tick(&mut p);
    let (mut emf, mut km_omega, mut n) = (0.0, 0.0, 0.0);
    for _ in 0..2000 {
        let now = tick(&mut p);
        let (i0, i1, v) = (before.phase_ma.expect("i"), now.phase_ma.expect("i"), now.phase_mv.expect("v"));
        let e = |k: usize| {
            let (i0, i1) = (f64::from(i0[k]) * 1e-3, f64::from(i1[k]) * 1e-3);
            f64::from(v[k]) * 1e-3 - r * 0.5 * (i0 + i1) - l * (i1 - i0) / t
        };
        emf += e(0).hypot(e(1));
        km_omega += params.km_nm_per_a * p.motor().omega().abs();
        n += 1.0;
        before = now;
    }
    let (emf, km_omega) = (emf / n, km_omega / n);
    assert!(km_omega > 3.0, "K_m·ω {km_omega} V: not at speed");
    println!("back-EMF from the measurements {emf:.4} V, K_m·ω {km_omega:.4} V");
    assert!((emf / km_omega - 1.0).abs() < 0.03, "back-EMF from the measurements {emf} V, K_m·ω {km_omega} V");
}

/// The rotor's position in turns from the start.
fn turns(p: &Plant) -> f64 {
    p.motor().rotor_full_steps() / f64::from(p.motor().params().steps_per_rev)
}

#[test]
fn an_incremental_encoder_counts_four_times_its_lines_up_with_the_setpoint() {
    for cpr in [200, 1000, 1600] {
        let mut p = plant();
        p.set_encoder(EncoderKind::Incremental { cpr });
        assert_eq!(encoder(&p), Some(0));
        set(&mut p, Obj::RelativeMove, 3200);
        run(&mut p, 1.5);
        let counts = f64::from(4 * cpr) * turns(&p);
        assert_eq!(encoder(&p), Some(counts.floor() as u32), "{cpr} lines");
        assert!((counts - f64::from(4 * cpr)).abs() < 2.0, "{cpr} lines: {counts}");
        // Back past the power-up position: the count wraps below 0.
        set(&mut p, Obj::Direction, 1);
        set(&mut p, Obj::RelativeMove, 4800);
        run(&mut p, 2.0);
        let counts = f64::from(4 * cpr) * turns(&p);
        assert_eq!(encoder(&p), Some((counts.floor() as i64) as u32), "{cpr} lines");
        assert!(encoder(&p).expect("reads") > u32::MAX - 4 * cpr);
    }
}

#[test]
fn absolute_encoders_read_the_angle_and_the_turns() {
    let mut p = plant();
    // The rotor a quarter turn and 7 counts on from the model's angle 0 before power-up.
    p.motor_mut().reset_at_full_steps(50.0 + 7.5 * 200.0 / 4096.0);
    p.set_encoder(EncoderKind::Abs12);
    assert_eq!(encoder(&p), Some(1024 + 7));
    p.set_encoder(EncoderKind::Abs12Mt);
    assert_eq!(encoder(&p), Some(1024 + 7));
    p.motor_mut().reset_at_full_steps(-2.0 * 200.0 + 50.0 + 7.5 * 200.0 / 4096.0);
    assert_eq!(encoder(&p), Some((-2i32 * 4096 + 1024 + 7) as u32));
    p.set_encoder(EncoderKind::Abs12);
    assert_eq!(encoder(&p), Some(1024 + 7));
    // Turning, the single-turn angle follows the rotor modulo a turn.
    set(&mut p, Obj::RelativeMove, 8000);
    run(&mut p, 3.5);
    let angle = (turns(&p).rem_euclid(1.0) * 4096.0).floor() as u32;
    assert_eq!(encoder(&p), Some(angle));
    assert!((p.motor().angle_in_turn() / TAU * 4096.0 - f64::from(angle)).abs() < 1.0);
    p.set_encoder(EncoderKind::None);
    assert_eq!(encoder(&p), None);
}

#[test]
fn noise_jitters_each_reading_within_its_bounds_the_same_way_every_run() {
    let readings = || {
        let mut p = plant();
        run(&mut p, 0.05);
        let still = encoder(&p).expect("reads") as i64;
        p.inject(Change::Encoder(EncoderFault::Noise(3)));
        let r: Vec<i64> = (0..400).map(|_| tick(&mut p).encoder.expect("reads") as i32 as i64 - still).collect();
        r
    };
    let r = readings();
    assert!(r.iter().all(|d| d.abs() <= 3), "{r:?}");
    for d in -3..=3 {
        assert!(r.contains(&d), "{d} never read");
    }
    assert_eq!(r, readings(), "seeded: the same run reads the same");
}

#[test]
fn a_lost_encoder_reads_nothing_and_an_incremental_one_misses_the_counts_meanwhile() {
    let mut p = plant();
    p.inject(Change::Encoder(EncoderFault::Lost));
    assert_eq!(tick(&mut p).encoder, None);
    set(&mut p, Obj::RelativeMove, 800);
    run(&mut p, 1.0);
    assert_eq!(encoder(&p), None);
    p.inject(Change::Encoder(EncoderFault::Ok));
    assert_eq!(encoder(&p), Some(0), "the counter saw no edges");
    set(&mut p, Obj::RelativeMove, 800);
    run(&mut p, 1.0);
    let counted = encoder(&p).expect("reads") as i32;
    assert!((counted - 1000).abs() <= 2, "a quarter turn counted: {counted}");
    // An absolute encoder's line break loses nothing.
    p.set_encoder(EncoderKind::Abs12Mt);
    let before = encoder(&p).expect("reads");
    p.inject(Change::Encoder(EncoderFault::Lost));
    set(&mut p, Obj::RelativeMove, 800);
    run(&mut p, 1.0);
    assert_eq!(encoder(&p), None);
    p.inject(Change::Encoder(EncoderFault::Ok));
    let after = encoder(&p).expect("reads");
    assert!((after.wrapping_sub(before) as i32 - 1024).abs() <= 2, "{before} -> {after}");
}

#[test]
fn a_frozen_encoder_stops_counting_while_the_rotor_turns() {
    let mut p = plant();
    set(&mut p, Obj::RelativeMove, 800);
    run(&mut p, 1.0);
    let at = encoder(&p).expect("reads");
    let rotor = turns(&p);
    p.inject(Change::Encoder(EncoderFault::Frozen));
    set(&mut p, Obj::RelativeMove, 1600);
    for _ in 0..20 {
        run(&mut p, 0.05);
        assert_eq!(encoder(&p), Some(at));
    }
    assert!(turns(&p) - rotor > 0.49, "the rotor turned on");
    // The coupling grips again: counting resumes from where it stopped.
    p.inject(Change::Encoder(EncoderFault::Ok));
    set(&mut p, Obj::RelativeMove, 800);
    run(&mut p, 1.0);
    let counted = encoder(&p).expect("reads") as i32 - at as i32;
    assert!((counted - 1000).abs() <= 2, "{counted}");
}

#[test]
fn a_hold_at_high_current_heats_the_driver_into_its_over_temperature_fault() {
    let mut p = plant();
    // 4 A: 0.5 Ω · 16 A² + 1 W = 9 W, 36 K above the ambient in the end.
    set(&mut p, Obj::PhaseCurrent, 4000);
    set(&mut p, Obj::OverTemperature, 40);
    run(&mut p, 0.02);
    let (i_a, i_b) = p.motor().phase_currents();
    assert!((i_a.hypot(i_b) - 4.0).abs() < 0.01, "{i_a} A, {i_b} A");
    p.inject(Change::DriverTemperature(38.0));
    let params = p.thermal().params();
    let ambient = p.thermal().ambient_c();
    let mut fired = None;
    let t0 = p.next_tick().as_micros();
    while fired.is_none() && p.next_tick().as_micros() - t0 < 8_000_000 {
        run(&mut p, 0.01);
        if p.drive().state().read(Obj::ErrorStatus) & 1 != 0 {
            fired = Some((p.next_tick().as_micros() - t0) as f64 * 1e-6);
        }
    }
    let settle = params.steady_rise_k(16.0);
    // The measured temperature reads 41 (> 40) from 40.5 °C on: when the first-order response
    // from 38 °C towards ambient + 36 K gets there.
    let start = 38.0 - ambient;
    let want = -params.tau_s * ((settle - (40.5 - ambient)) / (settle - start)).ln();
    let fired = fired.expect("over-temperature within 8 s");
    assert!((fired - want).abs() < 0.03, "fired after {fired} s, the model says {want} s");
    assert_eq!(p.drive().state().read(Obj::AlarmCode), 15);
    // The power stage is off: no conduction losses, the standing 1 W alone draws the driver
    // towards ambient + 4 K.
    let rise = p.thermal().temperature_c() - ambient;
    run(&mut p, 1.0);
    assert_eq!(p.motor().phase_currents(), (0.0, 0.0));
    let want = 4.0 + (rise - 4.0) * (-1.0 / params.tau_s).exp();
    let now = p.thermal().temperature_c() - ambient;
    assert!((now - want).abs() < 0.01, "{now} K above ambient, the model says {want}");
}
