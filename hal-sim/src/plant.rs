//! The drive and its motor on one simulated clock: every control tick the drive's outputs set the
//! chopper's command, and the motor model integrates until the next tick.
//!
//! A serial endpoint keeps the clock in pace with wall time ([`Plant::advance_to`] at each wake-up);
//! scenario tests run it as fast as it goes.

use std::f64::consts::FRAC_PI_2;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;

use drive_core::control::{Outputs, TICK_MICROS};
use drive_core::faults::Inputs;
use drive_core::{Drive, Instant};

use crate::inject::{Change, Injector, Scheduled, Supply};
use crate::motor::{DriverCommand, Motor, MotorInputs, PhaseFault};
use crate::trace::{CSV_HEADER, Decimator, TraceRow};

/// A drive driving a simulated motor.
#[derive(Debug)]
pub struct Plant {
    drive: Drive,
    motor: Motor,
    /// The time of the next control tick.
    next_tick: Instant,
    last: Option<Outputs>,
    trace: Option<(BufWriter<File>, Decimator)>,
    /// The supply, steady or ramping.
    supply: Supply,
    /// The driver temperature the drive measures, °C.
    temperature_c: f64,
    /// Changes still to come, latest first.
    schedule: Vec<Scheduled>,
    /// Changes sent from another thread.
    injector: Injector,
}

/// Driver temperature at power-up, °C.
pub const AMBIENT_C: f64 = 25.0;

/// Microsteps per full step that a resolution object value means (0: full steps).
pub fn microsteps_per_step(resolution: u16) -> u32 {
    u32::from(resolution.max(1))
}

/// The chopper command for the drive's outputs: the electrical angle it commutates, with its
/// fraction of a microstep, at the commanded current.
pub fn driver_command(out: &Outputs) -> DriverCommand {
    if !out.enabled || out.current_ma == 0 {
        return DriverCommand::DISABLED;
    }
    let per_step = microsteps_per_step(out.microsteps);
    let angle = &out.commutation;
    let whole = DriverCommand::at_microstep(angle.whole, per_step, f64::from(out.current_ma) * 1e-3);
    let fraction: f64 = angle.fraction.to_num();
    DriverCommand {
        theta_e: whole.theta_e + fraction * FRAC_PI_2 / f64::from(per_step),
        fast_decay: out.fast_decay.to_num(),
        ..whole
    }
}

impl Plant {
    /// `drive` and `motor`, at time 0.
    pub fn new(drive: Drive, motor: Motor) -> Self {
        let supply = Supply::steady(motor.inputs().supply_v);
        Self {
            drive,
            motor,
            next_tick: Instant::from_micros(0),
            last: None,
            trace: None,
            supply,
            temperature_c: AMBIENT_C,
            schedule: Vec::new(),
            injector: Injector::default(),
        }
    }

    /// Applies `change` now (at the next tick's time).
    pub fn inject(&mut self, change: Change) {
        let t = self.next_tick.as_micros() as f64 * 1e-6;
        let inputs = self.motor.inputs();
        match change {
            Change::Supply(v) => self.supply = Supply::steady(v),
            Change::SupplyRamp { to_v, seconds } => {
                self.supply = Supply::ramp(self.supply.at(t), to_v, t, seconds);
            }
            Change::LoadTorque(nm) => self.motor.set_inputs(MotorInputs { load_torque_nm: nm, ..inputs }),
            Change::Blocked(b) => self.motor.set_blocked(b),
            Change::Phase(k, fault) => self.motor.set_phase_fault(k, fault),
            Change::DriverTemperature(c) => self.temperature_c = c,
        }
    }

    /// Applies each change at its time after power-up (the simulated time 0).
    pub fn schedule(&mut self, mut changes: Vec<Scheduled>) {
        changes.sort_by_key(|c| std::cmp::Reverse(c.at_us));
        self.schedule = changes;
    }

    /// A handle through which another thread injects changes while the plant runs.
    pub fn injector(&self) -> Injector {
        self.injector.clone()
    }

    /// What the drive measures now: the supply, the driver temperature, the bridge currents and
    /// the power stage's open-load flags (an open winding while the bridge drives it).
    pub fn measurements(&self) -> Inputs {
        let (a, b) = self.motor.phase_currents();
        let ma = |i: f64| (i * 1e3).round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
        let open = |f: PhaseFault| f == PhaseFault::Open && self.motor.bridge_on();
        let [fa, fb] = self.motor.phase_faults();
        Inputs {
            supply_mv: Some((self.motor.inputs().supply_v.max(0.0) * 1e3).round().min(f64::from(u32::MAX)) as u32),
            temperature_c: Some(self.temperature_c.round().clamp(-40.0, 300.0) as i16),
            phase_ma: Some([ma(a), ma(b)]),
            coil_open: [open(fa), open(fb)],
            ..Inputs::default()
        }
    }

    /// Applies the changes that are due at the next tick, and the supply's ramp.
    fn disturb(&mut self) {
        for change in self.injector.take() {
            self.inject(change);
        }
        while let Some(next) = self.schedule.last().copied() {
            if next.at_us > self.next_tick.as_micros() {
                break;
            }
            self.schedule.pop();
            self.inject(next.change);
        }
        let v = self.supply.at(self.next_tick.as_micros() as f64 * 1e-6);
        let inputs = self.motor.inputs();
        if inputs.supply_v != v {
            self.motor.set_inputs(MotorInputs { supply_v: v, ..inputs });
        }
    }

    /// Records one row every `every` ticks into a CSV file at `path` from now on.
    pub fn trace_to(&mut self, path: &Path, every: u32) -> io::Result<()> {
        let mut out = BufWriter::new(File::create(path)?);
        writeln!(out, "{CSV_HEADER}")?;
        self.trace = Some((out, Decimator::new(every.max(1))));
        Ok(())
    }

    /// The drive.
    pub fn drive(&self) -> &Drive {
        &self.drive
    }

    /// The drive, to feed it bytes and time.
    pub fn drive_mut(&mut self) -> &mut Drive {
        &mut self.drive
    }

    /// The motor.
    pub fn motor(&self) -> &Motor {
        &self.motor
    }

    /// The motor, to change its load or supply.
    pub fn motor_mut(&mut self) -> &mut Motor {
        &mut self.motor
    }

    /// The drive's outputs at the last tick.
    pub fn outputs(&self) -> Option<Outputs> {
        self.last
    }

    /// The rotor position in the drive's microsteps (at the last tick's resolution).
    pub fn rotor_microsteps(&self) -> f64 {
        let per_step = self.last.map_or(1, |o| microsteps_per_step(o.microsteps));
        self.motor.rotor_microsteps(per_step)
    }

    /// Runs every control tick up to and including `now`.
    pub fn advance_to(&mut self, now: Instant) {
        while self.next_tick <= now {
            self.disturb();
            let out = self.drive.tick_with(self.next_tick, &self.measurements());
            let cmd = driver_command(&out);
            self.motor.advance(&cmd, TICK_MICROS as f64 * 1e-6);
            if let Some((file, every)) = &mut self.trace
                && every.take()
            {
                let per_step = microsteps_per_step(out.microsteps);
                let commanded = out.setpoint.whole as f64 + out.setpoint.fraction.to_num::<f64>();
                let row = TraceRow::from_motor(&self.motor, commanded, out.setpoint.velocity, per_step);
                if row.write_csv_line(file).is_err() {
                    self.trace = None;
                }
            }
            self.last = Some(out);
            self.next_tick = self.next_tick.plus_micros(TICK_MICROS);
        }
    }

    /// The simulated time of the next tick.
    pub fn next_tick(&self) -> Instant {
        self.next_tick
    }

    /// Flushes the trace file.
    pub fn flush_trace(&mut self) -> io::Result<()> {
        match &mut self.trace {
            Some((file, _)) => file.flush(),
            None => Ok(()),
        }
    }
}
