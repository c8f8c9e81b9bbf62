//! The closed loop against the open loop on one loaded move, with its figures and pictures:
//! `cargo run --release -p hal-sim --example closed_loop [DIR]` writes `DIR/closed-loop-*.png`
//! (default `docs/img`) and prints, for each loop, the largest following error under the load,
//! the settling time at the end of the move and the overshoot.
//!
//! The move: four turns at two turns a second on the NEMA 17 at 24 V, 1000 mA, 1/16 microsteps,
//! with 330 g·cm² of load; from 0.8 s to 1.3 s a load torque of 0.17 N·m (81 % of K_m·I), which
//! makes the open loop pull out and lose steps (the test `closed_loop` runs the same move).

use std::path::PathBuf;

use drive_core::od::Obj;
use drive_core::{Drive, DriveConfig, Params};
use hal_sim::DEFAULT_MOTOR;
use hal_sim::inject::Change;
use hal_sim::motor::{Motor, MotorCatalog, MotorInputs};
use hal_sim::plant::Plant;
use hal_sim::plot::plot_trace;
use hal_sim::trace::TraceRow;

/// Microsteps and encoder counts a full step.
const MICRO: f64 = 16.0;
const COUNTS: f64 = 20.0;
/// The load torque stepped in while cruising, N·m.
const LOAD_NM: f64 = 0.17;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = PathBuf::from(std::env::args().nth(1).unwrap_or_else(|| "docs/img".into()));
    for (name, feedback, torque_loop) in [("open", 0, 0), ("position-loop", 1, 0), ("servo-loop", 1, 1)] {
        let mut params = Params::factory();
        for (obj, v) in [
            (Obj::Feedback, feedback),
            (Obj::EncoderCpr, 1000),
            (Obj::TorqueLoop, torque_loop),
            (Obj::Microsteps, 16),
            (Obj::PhaseCurrent, 1000),
            (Obj::StallLength, 255),
        ] {
            assert!(params.set(obj, v));
        }
        let motor = MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().ok_or("no catalogue motor")?;
        let inputs = MotorInputs { load_inertia_kgm2: 3.3e-5, ..MotorInputs::default() };
        let mut p = Plant::new(Drive::boot(DriveConfig::default(), &params, 0), Motor::new(motor, inputs));
        // Position units a full step, and to microsteps.
        let unit = if feedback == 1 { COUNTS } else { MICRO };
        let state = p.drive_mut().state_mut();
        for (obj, v) in [(Obj::MaxSpeed, 400.0 * unit), (Obj::RelativeMove, 800.0 * unit)] {
            state.check(obj, v as u32).map_err(|e| format!("{obj:?}: {e:?}"))?;
            state.apply(obj, v as u32);
        }
        let target = 800.0 * MICRO;
        let mut rows = Vec::new();
        let (mut worst_load, mut overshoot, mut settled_at, mut end_at) = (0.0f64, 0.0f64, None, None);
        while p.next_tick().as_micros() < 4_000_000 {
            let t = p.next_tick().as_micros();
            if t == 800_000 {
                p.inject(Change::LoadTorque(LOAD_NM));
            }
            if t == 1_300_000 {
                p.inject(Change::LoadTorque(0.0));
            }
            p.advance_to(p.next_tick());
            let out = p.outputs().ok_or("no tick")?;
            let commanded = (out.setpoint.whole as f64 + out.setpoint.fraction.to_num::<f64>()) * MICRO / unit;
            let row = TraceRow::from_motor(p.motor(), commanded, f64::from(out.setpoint.velocity) * MICRO / unit, 16);
            let error = row.commanded_position_usteps - row.rotor_position_usteps;
            if (800_000..1_300_000).contains(&t) {
                worst_load = worst_load.max(error.abs());
            }
            if end_at.is_none()
                && out.setpoint.velocity == 0.0
                && p.drive().state().position() as f64 * MICRO / unit == target
            {
                end_at = Some(t);
            }
            if end_at.is_some() {
                overshoot = overshoot.max(row.rotor_position_usteps - target);
                // Settled: within a tenth of a full step of the target from here on.
                if (row.rotor_position_usteps - target).abs() > 0.1 * MICRO {
                    settled_at = None;
                } else if settled_at.is_none() {
                    settled_at = Some(t);
                }
            }
            if t.is_multiple_of(1000) {
                rows.push(row);
            }
        }
        let last = rows.last().copied().unwrap_or_default();
        let settle_ms = match (end_at, settled_at) {
            (Some(e), Some(s)) => format!("{:.1} ms", s.saturating_sub(e) as f64 * 1e-3),
            _ => "never".into(),
        };
        println!(
            "{name:13}: largest following error under the load {:.2} full steps; final error {:.3} full steps; \
             settling (within 0.1 full step) {settle_ms} after the profile ends; overshoot {:.3} full steps",
            worst_load / MICRO,
            (target - last.rotor_position_usteps) / MICRO,
            overshoot.max(0.0) / MICRO
        );
        let png = dir.join(format!("closed-loop-{name}.png"));
        plot_trace(&rows, &png, &format!("{name}: 800 full steps, {LOAD_NM} N·m from 0.8 s to 1.3 s"))?;
    }
    Ok(())
}
