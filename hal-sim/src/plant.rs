//! The drive and its motor on one simulated clock: every control tick the drive's outputs set the
//! chopper's command, and the motor model integrates until the next tick.
//!
//! What the drive measures ([`Plant::measurements`]) is what a real drive's platform measures:
//! the supply, the driver temperature (a thermal model, [`crate::thermal`]), the bridge currents,
//! the bridge voltages averaged over the tick that just ended (PWM duties times the supply), the
//! open-load flags and the shaft encoder ([`crate::encoder`]); never the model's rotor angle.
//!
//! A serial endpoint keeps the clock in pace with wall time ([`Plant::advance_to`] at each wake-up);
//! scenario tests run it as fast as it goes.

use std::f64::consts::FRAC_PI_2;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::Path;

use crate::Drive;
use crate::bridges::{Bridges, LoopSetup, PowerStage, SensingOptions, TRIP_SHARE};
use drive_core::Instant;
use drive_core::control::{Outputs, TICK_MICROS};
use drive_core::controller::handoff::TickSide;
use drive_core::faults::Inputs;
use drive_core::od::{CURRENT_LOOP_OBJECTS, Obj, ObjError};
use drive_core::windings::LoopObjects;

use crate::encoder::{Encoder, EncoderKind};
use crate::inject::{Change, Injector, Scheduled, Supply};
use crate::machine::Machine;
use crate::motor::{BridgeMeans, DriverCommand, Motor, MotorInputs, PhaseFault};
use crate::thermal::{Thermal, ThermalParams};
use crate::trace::{CSV_HEADER, Decimator, TraceRow};

/// A drive driving a simulated motor.
#[derive(Debug)]
pub struct Plant {
    drive: Drive,
    /// The control tick's own controller, synced with the drive's model as on a microcontroller
    /// ([`drive_core::controller::handoff`]); `None` ticks the drive's controller itself.
    tick: Option<TickSide>,
    motor: Motor,
    /// The time of the next control tick.
    next_tick: Instant,
    last: Option<Outputs>,
    trace: Option<(BufWriter<File>, Decimator)>,
    /// The supply, steady or ramping.
    supply: Supply,
    /// The driver's temperature.
    thermal: Thermal,
    /// The encoder on the shaft.
    encoder: Encoder,
    /// The bridge's averages over the last tick.
    bridge: BridgeMeans,
    /// Changes still to come, latest first.
    schedule: Vec<Scheduled>,
    /// Changes sent from another thread.
    injector: Injector,
    /// Switches and the analog source.
    machine: Machine,
    /// What the drive measured at the last tick.
    last_inputs: Option<Inputs>,
    /// The rotor's whole turns at the last tick: the incremental encoder's index pulse comes
    /// once a turn, where the rotor was at power-up.
    last_turns: i64,
    /// The G474's bridges, with [`PowerStage::Bridges`]; `None`: the ideal chopper.
    bridges: Option<Bridges>,
    /// The bridges' sensing, for their power-up again after a restart.
    sensing: SensingOptions,
}

/// Ambient and driver temperature at power-up, °C.
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

/// A drive the plant can run: the simulator's, or one with the native map (which it answers
/// through the same map).
pub trait IntoDrive {
    /// The simulator's drive.
    fn into_drive(self) -> Drive;
}

impl IntoDrive for Drive {
    fn into_drive(self) -> Drive {
        self
    }
}

impl IntoDrive for drive_core::Drive {
    fn into_drive(self) -> Drive {
        self.map_into(drive_core::maps::Maps::Native)
    }
}

impl Plant {
    /// `drive` and `motor`, at time 0, with the default encoder (`inc:1000`) and the driver at
    /// [`AMBIENT_C`].
    ///
    /// The control tick owns a controller of its own, synced with the drive's model before a
    /// tick that has something to take in and after every tick, as the firmware does at its
    /// syncs: what the master and the tests see goes through the handoff.
    pub fn new(drive: impl IntoDrive, motor: Motor) -> Self {
        let drive = drive.into_drive();
        let tick = Some(drive.state().tick_side());
        Self { tick, ..Self::combined(drive, motor) }
    }

    /// A factory drive turning the catalogue's default motor ([`crate::DEFAULT_MOTOR`]) at 24 V
    /// in `machine`: what the scenario tests start from.
    pub fn factory_on(machine: crate::machine::Machine) -> Self {
        let params = crate::motor::MotorCatalog::builtin()
            .get(crate::DEFAULT_MOTOR)
            .cloned()
            .expect("the built-in catalogue has the default motor");
        let mut plant =
            Self::new(drive_core::Drive::factory(), Motor::new(params, crate::motor::MotorInputs::default()));
        *plant.machine_mut() = machine;
        plant
    }

    /// [`Plant::new`] with the drive's own controller ticked (no handoff): what the handoff is
    /// compared against.
    pub fn combined(drive: impl IntoDrive, motor: Motor) -> Self {
        let drive = drive.into_drive();
        let supply = Supply::steady(motor.inputs().supply_v);
        let encoder = Encoder::new(EncoderKind::default(), &motor);
        Self {
            tick: None,
            drive,
            motor,
            next_tick: Instant::from_micros(0),
            last: None,
            trace: None,
            supply,
            thermal: Thermal::new(ThermalParams::SMALL_DRIVE, AMBIENT_C),
            encoder,
            bridge: BridgeMeans::default(),
            schedule: Vec::new(),
            injector: Injector::default(),
            machine: Machine::default(),
            last_inputs: None,
            last_turns: 0,
            bridges: None,
            sensing: SensingOptions::default(),
        }
    }

    /// Drives the motor through `stage`: the ideal chopper (the default), or the board's bridges
    /// with `sensing` ([`crate::bridges`]). Only before the first tick.
    pub fn set_power_stage(&mut self, stage: PowerStage, sensing: SensingOptions) {
        if self.last.is_some() {
            return;
        }
        self.sensing = sensing;
        self.bridges = match stage {
            PowerStage::Chopper => None,
            PowerStage::Bridges => Some(self.power_up_bridges(sensing)),
        };
    }

    /// The drive has powered up again (a restart: it was built anew from its store): the
    /// bridges power up with it, their current loop from its objects as they now are (tuned
    /// again, or as set), as at power-up.
    pub fn restarted(&mut self) {
        if self.bridges.is_some() {
            self.bridges = Some(self.power_up_bridges(self.sensing));
        }
    }

    /// The bridges as the drive powers them up: its current loop from its objects (0x210B,
    /// 0x2108, 0x2109, 0x210C, 0x210D, 0x600D), and a tune's results written back into them.
    fn power_up_bridges(&mut self, sensing: SensingOptions) -> Bridges {
        let state = self.drive.state();
        let word = |obj: Obj| state.read(obj).min(u32::from(u16::MAX)) as u16;
        let setup = LoopSetup {
            auto_tune: state.read(Obj::CurrentAutoTune) != 0,
            objects: LoopObjects::from_words(CURRENT_LOOP_OBJECTS.map(word)),
            test_ma: word(Obj::PhaseCurrent),
        };
        let bridges = Bridges::new(&mut self.motor, sensing, setup);
        let state = self.drive.state_mut();
        state.set_current_loop(true);
        if let Some(t) = bridges.tuned() {
            for (obj, v) in CURRENT_LOOP_OBJECTS.into_iter().zip(t.words()) {
                state.apply(obj, u32::from(v));
            }
        }
        bridges
    }

    /// The power stage, with [`PowerStage::Bridges`].
    pub fn bridges(&self) -> Option<&Bridges> {
        self.bridges.as_ref()
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
            Change::DriverTemperature(c) => self.thermal.force(c),
            Change::Encoder(fault) => self.encoder.apply(fault, &self.motor),
            Change::Input(pin, level) => self.machine.drive_pin(pin, level),
        }
    }

    /// Fits an encoder of `kind` now, as at power-up: an incremental one counts from the rotor's
    /// present position.
    pub fn set_encoder(&mut self, kind: EncoderKind) {
        self.encoder = Encoder::new(kind, &self.motor);
    }

    /// The switches and the analog source around the motor, to add or move them.
    pub fn machine_mut(&mut self) -> &mut Machine {
        &mut self.machine
    }

    /// The encoder on the shaft.
    pub fn encoder(&self) -> &Encoder {
        &self.encoder
    }

    /// The driver's thermal model.
    pub fn thermal(&self) -> &Thermal {
        &self.thermal
    }

    /// Replaces the thermal model's constants, keeping the temperature.
    pub fn set_thermal(&mut self, params: ThermalParams) {
        let c = self.thermal.temperature_c();
        self.thermal = Thermal::new(params, self.thermal.ambient_c());
        self.thermal.force(c);
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

    /// What the drive measures now: the supply, the driver temperature, the bridge currents, the
    /// bridge voltages averaged over the last tick, the power stage's open-load flags (an open
    /// winding while the bridge drives it) and the encoder (its noise drawn for the next tick).
    pub fn measurements(&self) -> Inputs {
        let (a, b) = self.motor.phase_currents();
        // Amperes to mA, volts to mV.
        let milli = |x: f64| (x * 1e3).round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)) as i32;
        let open = |f: PhaseFault| f == PhaseFault::Open && self.motor.bridge_on();
        let [fa, fb] = self.motor.phase_faults();
        Inputs {
            supply_mv: Some((self.motor.inputs().supply_v.max(0.0) * 1e3).round().min(f64::from(u32::MAX)) as u32),
            temperature_c: Some(self.thermal.temperature_c().round().clamp(-40.0, 300.0) as i16),
            phase_ma: Some(match &self.bridges {
                Some(bridges) => bridges.reading_ma(),
                None => [milli(a), milli(b)],
            }),
            // The G474's bridges have no open-load flags: the drive's own regulation tells.
            coil_open: match &self.bridges {
                Some(bridges) => bridges.open(),
                None => [open(fa), open(fb)],
            },
            phase_mv: Some(match &self.bridges {
                Some(bridges) => bridges.applied_mv(),
                None => self.bridge.volts.map(milli),
            }),
            back_emf_mv: self.bridges.as_ref().map(|b| b.back_emf_mv()),
            encoder: self.encoder.reading(&self.motor, self.next_tick.as_micros() / TICK_MICROS),
            // The pins and the analog input: the machine's, at the tick (`Plant::tick`).
            levels: 0,
            analog: None,
            index: false,
            pulses: 0,
            tripped: self.bridges.as_ref().is_some_and(Bridges::tripped),
            // The bridges' sensing, its zero at power-up as the firmware checks it.
            sensing_fault: self.bridges.as_ref().is_some_and(|b| !drive_core::windings::sensing_ok(b.zero_codes())),
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

    /// What the drive measured at the last tick (its pins' levels among them).
    pub fn last_inputs(&self) -> Option<Inputs> {
        self.last_inputs
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

    /// Writes `value` to `obj` as a request would: checked, then applied; refused as the drive
    /// refuses it.
    pub fn write(&mut self, obj: Obj, value: u32) -> Result<(), ObjError> {
        self.drive.state_mut().write_def(obj.def(), value)
    }

    /// Sends the request `body` (its CRC appended) at the next tick and runs until the drive
    /// answers it (10 ms at most): the reply, or `None`.
    pub fn request(&mut self, body: &[u8]) -> Option<Vec<u8>> {
        let mut frame = body.to_vec();
        frame.extend(drive_core::crc::crc16(body).to_le_bytes());
        let now = self.next_tick();
        self.drive.on_rx(now, &frame);
        for _ in 0..200 {
            let t = self.next_tick();
            self.advance_to(t);
            self.drive.on_timer(t);
            if let Some(reply) = self.drive.take_reply() {
                return Some(reply.to_vec());
            }
        }
        None
    }

    /// Runs the control ticks of the next `secs` of simulated time.
    pub fn run_for(&mut self, secs: f64) {
        let end = self.next_tick.plus_micros((secs * 1e6) as u64);
        self.advance_to(end);
    }

    /// Runs every control tick up to and including `now`.
    pub fn advance_to(&mut self, now: Instant) {
        while self.next_tick <= now {
            self.disturb();
            if let Some(bridges) = &mut self.bridges {
                // The ADC at the PWM's centre, which the tick and the current loop read.
                bridges.sample(&self.motor);
            }
            let out = self.tick();
            let cmd = driver_command(&out);
            let tick_s = TICK_MICROS as f64 * 1e-6;
            match &mut self.bridges {
                None => self.motor.advance(&cmd, tick_s),
                Some(bridges) => {
                    let setting_ma = self.drive.state().read(drive_core::od::Obj::OverCurrent);
                    let trip_a = TRIP_SHARE * f64::from(setting_ma) * 1e-3;
                    bridges.period(&mut self.motor, &out, trip_a, tick_s);
                }
            }
            self.bridge = self.motor.take_bridge_means();
            self.thermal.advance(self.bridge.current_sq, tick_s);
            if let Some((file, every)) = &mut self.trace
                && every.take()
            {
                let per_step = microsteps_per_step(out.microsteps);
                let commanded = out.setpoint.whole as f64 + out.setpoint.fraction.to_num::<f64>();
                let row = TraceRow {
                    gpio_out: out.gpio,
                    coil_pct: out.coil_duty,
                    ..TraceRow::from_motor(&self.motor, commanded, f64::from(out.setpoint.velocity), per_step)
                };
                if row.write_csv_line(file).is_err() {
                    self.trace = None;
                }
            }
            self.last = Some(out);
            self.next_tick = self.next_tick.plus_micros(TICK_MICROS);
        }
    }

    /// One control tick at the next tick's time: the drive's, or the tick's own controller's
    /// between two syncs.
    fn tick(&mut self) -> Outputs {
        let (now, mut inputs) = (self.next_tick, self.measurements());
        // The pins as the switches and the drive's own outputs make them at this tick.
        let t = now.as_micros() as f64 * 1e-6;
        let (pins, gpio) = self.last.map_or((Default::default(), 0), |o| (o.pins, o.gpio));
        inputs.levels = self.machine.levels(t, self.motor.rotor_full_steps(), &pins, gpio);
        inputs.analog = self.machine.analog_code(t);
        let pulse = self.last.map(|o| o.pulse).unwrap_or_default();
        inputs.pulses = self.machine.pulse_count(t, &pulse);
        let turns = self.motor.turns();
        let incremental = matches!(self.encoder.kind(), crate::encoder::EncoderKind::Incremental { .. });
        inputs.index = incremental && turns != core::mem::replace(&mut self.last_turns, turns);
        self.last_inputs = Some(inputs);
        let Some(tick) = &mut self.tick else {
            let out = self.drive.tick_with(now, &inputs);
            // The bus side's work in time, as a board's bus task does when its timer wakes it.
            self.drive.state_mut().service(now);
            return out;
        };
        if self.drive.has_changes() {
            self.drive.sync_here(tick, now);
        }
        let out = tick.tick(now, &inputs, self.drive.state().shared());
        self.drive.sync_here(tick, now.plus_micros(TICK_MICROS));
        self.drive.state_mut().service(now);
        out
    }

    /// Starts the plant's clock at `t` instead of 0: a drive powered up while others on its bus
    /// have been running. Only before the first tick.
    pub fn start_at(&mut self, t: Instant) {
        if self.last.is_none() {
            self.next_tick = t;
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
