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
use drive_core::{Drive, Instant};

use crate::motor::{DriverCommand, Motor};
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
}

/// Microsteps per full step that a resolution object value means (0: full steps).
pub fn microsteps_per_step(resolution: u16) -> u32 {
    u32::from(resolution.max(1))
}

/// The chopper command for the drive's outputs: the setpoint's electrical angle, with its
/// fraction of a microstep, at the commanded current.
pub fn driver_command(out: &Outputs) -> DriverCommand {
    if out.current_ma == 0 {
        return DriverCommand::DISABLED;
    }
    let per_step = microsteps_per_step(out.microsteps);
    let whole = DriverCommand::at_microstep(out.setpoint.whole, per_step, f64::from(out.current_ma) * 1e-3);
    let fraction: f64 = out.setpoint.fraction.to_num();
    DriverCommand {
        theta_e: whole.theta_e + fraction * FRAC_PI_2 / f64::from(per_step),
        fast_decay: out.fast_decay.to_num(),
        ..whole
    }
}

impl Plant {
    /// `drive` and `motor`, at time 0.
    pub fn new(drive: Drive, motor: Motor) -> Self {
        Self { drive, motor, next_tick: Instant::from_micros(0), last: None, trace: None }
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
            let out = self.drive.tick(self.next_tick);
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
