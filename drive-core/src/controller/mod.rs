//! The controller: what the control tick owns and runs every 50 µs. The motion it was handed
//! (an [`Axis`] walking a plan or a PVT run), supervision (faults, power loss, the communication
//! watchdog), the closed loop with stall detection, and the output stage's orders.
//!
//! The controller plans nothing and reads no register: each tick runs [`Settings`], checked
//! values the bus side builds from the dictionary whenever one of them changes and hands over
//! whole, which the tick never writes, over the [`Controller`]'s own state, with what it
//! measures ([`Inputs`]). The closed loop's zero offset is state: the first reading may set it
//! ([`Events::ZERO_OFFSET`]), and a zero offset the bus side writes replaces it. What it decides on its own and
//! the bus side must know (a stop it started, a set-point it joined, power failing) it reports
//! as [`Events`].

pub mod handoff;
pub mod io;
mod loops;
mod record;
pub(crate) mod run;
mod supervise;

use crate::faults::{FaultLog, Inputs};
use crate::modes::PowerState;
use crate::motion::axis::{Axis, Setpoint};
use crate::motion::cubic::{Ahead, Table};
use crate::motion::shaping::{MovingAverage, ShapingState};
use crate::scope::{Recordings, Scopes};
use crate::servo::{Feedback, Gains, Servo};
use crate::units::Instant;
use fixed::types::{U0F16, U0F32};

pub use run::{Pvt, STATUS_FIFO_EMPTY, STATUS_FIFO_HIGH, STATUS_FIFO_LOW};

/// Controller status bit 0: external stop 1 (EXT1) stopped the motor.
pub const STATUS_EXT1: u8 = 1 << 0;
/// Controller status bit 1: external stop 2 (EXT2) stopped the motor.
pub const STATUS_EXT2: u8 = 1 << 1;
/// Controller status bit 4: external stop 3 (EXT3) stopped the motor.
pub const STATUS_EXT3: u8 = 1 << 4;
/// The external stops' bits: moves are refused while one is set (§5.6).
pub const STATUS_EXT: u8 = STATUS_EXT1 | STATUS_EXT2 | STATUS_EXT3;
/// Controller status bit 2: a stall was detected (write 1 to clear). Moves are refused while it
/// is set if the stall stopped the motor (0x6043 = 1, or the closed loop's following error).
pub const STATUS_STALL: u8 = 1 << 2;
/// Controller status bit 3: the motor is executing a move.
pub const STATUS_BUSY: u8 = 1 << 3;

/// What the output stage is told at one tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Outputs {
    /// The position setpoint, with its fraction: microsteps in open loop, encoder counts in
    /// closed loop (see [`crate::servo`]).
    pub setpoint: Setpoint,
    /// The electrical angle the power stage drives, in microsteps of `microsteps` a full step
    /// (four full steps an electrical turn): the setpoint in open loop, the closed loop's
    /// commutation otherwise.
    pub commutation: Setpoint,
    /// Whole microsteps of `commutation` to step this tick (signed): what a STEP/DIR stage emits.
    pub steps: i64,
    /// Phase current amplitude in mA; 0 frees the motor.
    pub current_ma: u16,
    /// Whether the power stage is on: enabled (0x6011), no fault latched, not freed by power loss.
    /// Off, the bridges are open and `current_ma` is 0.
    pub enabled: bool,
    /// The coil output's PWM duty in percent (0x6038; see [`io`] for when it is cut).
    pub coil_duty: u8,
    /// The output pins' levels, 1 high (bits as 0x6031; inputs' bits 0).
    pub gpio: u16,
    /// How the pins are set up (directions, pulls, drivers).
    pub pins: io::PinConfig,
    /// Microsteps per full step that positions count in (0x600C; 0 counts full steps).
    pub microsteps: u16,
    /// The share of fast decay in the chopper's off-time (0x6010).
    pub fast_decay: U0F16,
    /// How the pulse input's counter counts (0x21B7, 0x21B8).
    pub pulse: io::PulseInput,
    /// Whether `commutation` follows the measured rotor (an encoder's closed loop): the
    /// windings then keep its angle as it is (no damping of their own,
    /// [`crate::windings::DAMPING_GAIN`]).
    pub closed_loop: bool,
}

/// The drive's running status bits and measurements: what the live objects report.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Status {
    /// Error status bits (0x6000).
    pub error: u8,
    /// Controller status bits (0x6001).
    pub controller: u8,
    /// Step-notification bits (0x6061).
    pub notify: u8,
    /// GPIO levels (0x6031), inverted as the manual has them.
    pub gpio: u16,
    /// What the master wrote to the output pins' bits of 0x6031 (inverted: 1 low).
    pub gpio_out: u16,
    /// Analog input code (0x605F).
    pub analog_in: u16,
    /// PVT pointer (0x601A).
    pub pvt_pointer: u16,
    /// Encoder position in counts (0x6089).
    pub encoder: i32,
    /// Drive fault bits beyond 0x6000 (0x2135): `faults::FAULT_*`.
    pub faults: u8,
    /// Communication status bits (0x2138): `faults::COMM_TIMEOUT`.
    pub comm: u8,
    /// The supply voltage last measured, mV (0x21AF).
    pub supply_mv: u16,
    /// The larger phase current last measured, mA (0x21B0).
    pub current_ma: u16,
    /// The inputs IN1-IN7 active (bit k: IN k+1).
    pub inputs: u8,
    /// The inputs that turned active since the bus side last took them.
    pub input_edges: u8,
    /// Touch probes captured (0x21DF: bit 0 probe 1, bit 1 probe 2).
    pub probes: u8,
}

/// The settings the controller runs, checked and converted from the dictionary's values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    /// The master enabled the power stage (0x6011 = 1).
    pub enabled: bool,
    /// Disabled, the motor is held at the standstill current (0x21DA).
    pub hold_disabled: bool,
    /// Ticks the current takes to rise to its setting after the stage is energised (0x21E0 and
    /// 0x21E1); 0: at once.
    pub soft_start_ticks: u16,
    /// The deceleration of a stop the controller starts on its own (watchdog, PVT FIFO dry, PVT
    /// stop), pps²; 0 stops at once.
    pub stop_decel: u32,
    /// Phase current, mA (0x600D).
    pub phase_current_ma: u32,
    /// Standstill current, percent of the phase current (0x2102).
    pub idle_current_pct: u32,
    /// Standstill delay before the current drops, µs (0x6035).
    pub idle_delay_us: u64,
    /// Microsteps a full step (0x600C).
    pub microsteps: u16,
    /// Fast-decay share (0x6010).
    pub fast_decay: U0F16,
    /// Coil output duty, percent (0x6038).
    pub brake_duty: u8,
    /// The coil output is a general output (0x2141 = 1), not a brake.
    pub coil_general: bool,
    /// External stops enabled (0x6013: bits 0, 1, 4).
    pub ext_enable: u8,
    /// External stops on the rising edge (0x6014), else the falling one.
    pub ext_rising: u8,
    /// External stop confirmation delay, µs (0x6042).
    pub ext_delay_us: u32,
    /// The pins' directions and modes (0x602E, 0x602F, 0x6013..0x6015).
    pub pins: io::PinConfig,
    /// Step notification positions (0x6062, 0x6064).
    pub notify: [i64; 2],
    /// The step notifications' output pulse (0x2140).
    pub notify_output: io::NotifyOutput,
    /// Under-voltage level, mV.
    pub under_voltage_mv: u32,
    /// Over-voltage level, mV.
    pub over_voltage_mv: u32,
    /// Over-temperature level, °C.
    pub over_temperature_c: u32,
    /// Over-current level, mA.
    pub over_current_ma: u32,
    /// Communication timeout, µs; 0 is off.
    pub comm_timeout_us: u64,
    /// Below this supply the motor is freed (0 when 0x6082 bit 0 is off), mV.
    pub free_below_mv: u32,
    /// Below this supply the brake is applied (0 when 0x6082 bit 1 is off), mV.
    pub brake_below_mv: u32,
    /// The power-down position save is on (0x605E = 1).
    pub auto_save: bool,
    /// The position saved at the last power loss (0x6055).
    pub saved_position: i32,
    /// Encoder lines (0x6054): open loop counts an incremental encoder of this many for 0x6089.
    pub encoder_cpr: u32,
    /// Zero offset (0x6087), closed loop: the measured position is the encoder's plus this.
    pub zero_offset: i32,
    /// Following-error limit, microsteps (0x605C).
    pub following_limit: u32,
    /// The servo loop (0x605D = 1) instead of the position loop.
    pub servo_loop: bool,
    /// The servo loop's gains (0x6057..0x605A).
    pub gains: Gains,
    /// Sensorless stall detection on (0x2107).
    pub stall_detect: bool,
    /// A stall stops the motion (0x6053).
    pub stall_stop: bool,
    /// Winding resistance, Ω, and inductance, H.
    pub motor_r: f32,
    /// Winding inductance, H.
    pub motor_l: f32,
    /// Minimum speed for stall detection, full steps per second.
    pub stall_min_speed: f32,
    /// The cosine of the load angle beyond which the rotor has pulled out (the angle is within
    /// 45°-175°: beyond it is a cosine below this).
    pub stall_limit_cos: f32,
    /// The pulse input's format and filter (0x21B7, 0x21B8).
    pub pulse: io::PulseInput,
    /// The inputs' and outputs' functions (0x21BA-0x21C9).
    pub io: io::IoFunctions,
    /// The overspeed limit (0x21F6) as the speed the tick compares: microsteps a second in
    /// open loop, encoder counts a second in closed loop; 0 off.
    pub overspeed: [f32; 2],
    /// The detections that latch (0x21F8, [`crate::faults::detect`]).
    pub detect: u16,
    /// The parameter store has failed (0x2120 bit 1 or 4): the store's alarm while detected.
    pub store_failed: bool,
    /// The command path's moving average (0x2210, 0x2211).
    pub shaping: MovingAverage,
}

/// What the controller did on its own at a tick, for the bus side to take into account: a set
/// of flags (one byte, so that a tick with nothing to report costs one comparison).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Events(u8);

impl Events {
    /// The controller stopped the motion (fault, stall, watchdog, PVT FIFO dry): any set-point
    /// or PVT run is over.
    pub const STOPPED: Self = Self(1 << 0);
    /// The walk passed into the set-point appended after the running one.
    pub const JOINED: Self = Self(1 << 1);
    /// The supply began failing: the power-down position save is due if it is on.
    pub const POWER_FAILING: Self = Self(1 << 2);
    /// The closed loop's first reading set the zero offset (§5.5.15) to the settings' value.
    pub const ZERO_OFFSET: Self = Self(1 << 3);
    /// The watch the bus side armed saw what it waited for: the controller holds the position
    /// where it did, and the axis is stopping.
    pub const CAUGHT: Self = Self(1 << 4);
    /// An input turned active: its function is the bus side's to carry out.
    pub const INPUT: Self = Self(1 << 5);

    /// Whether every flag of `e` is set.
    pub const fn has(self, e: Self) -> bool {
        self.0 & e.0 == e.0
    }

    /// Whether no flag is set.
    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    fn set(&mut self, e: Self) {
        self.0 |= e.0;
    }
}

/// The memories the tick and the bus side share: the PVT points the bus side stores and the
/// tick runs, and the recordings the tick makes and the bus side reads out (41 KB: a
/// microcontroller keeps them in a static and lends them, `&'static Shared`).
#[derive(Clone, Debug, Default)]
pub struct Shared {
    /// The PVT points.
    pub table: Table,
    /// The scope's and the black box's memories.
    pub recordings: Recordings,
}

impl Shared {
    /// Empty (a `const fn`, so that a static is built in place).
    pub const fn new() -> Self {
        Self { table: Table::new(), recordings: Recordings::new() }
    }
}

/// Fast-decay shares of 0x6010's values 0..=3: 0, 1/2, 3/4, 7/8.
pub const DECAY: [U0F16; 4] = [U0F16::ZERO, U0F16::lit("0.5"), U0F16::lit("0.75"), U0F16::lit("0.875")];

/// What the control tick owns: the state its ticks carry from one to the next. What it runs is
/// [`Settings`], handed to each tick apart (the owner of the controller keeps them).
#[derive(Clone, Debug)]
pub struct Controller {
    /// Zero offset (0x6087), closed loop: the measured position is the encoder's plus this.
    /// The settings' value, but for the closed loop's first reading, which sets it from the
    /// power-down position ([`Events::ZERO_OFFSET`]).
    pub(crate) zero_offset: i32,
    /// The motion being executed.
    pub(crate) axis: Axis,
    /// The running status bits and measurements.
    pub(crate) status: Status,
    /// The fault history and the supervision's memory.
    pub(crate) faults: FaultLog,
    /// The whole microsteps the setpoint has moved since power-up, signed and wrapping (what
    /// 0x21D4 counts from its last clear).
    pub(crate) commanded: u32,
    /// The fault history is to be emptied (0x200F = 5): by the tick of a controller ticked
    /// where it is kept, by the sync where the tick owns one of its own.
    pub(crate) clear_history: bool,
    /// The touch probes' captured positions (0x21DB, 0x21DD).
    pub(crate) probe: [i32; 2],
    /// The closed loop and stall detection.
    pub(crate) servo: Servo,
    /// The PVT run, if one runs.
    pub(crate) run: Option<run::Run>,
    /// The next PVT segment's walk, built a piece a tick before it starts.
    pub(crate) ahead: Option<Ahead>,
    /// The pins' memory (debouncers, the notifications' last position).
    pub(crate) io: io::Pins,
    /// Since when the axis has stood still (for the standstill current).
    pub(crate) still_since: Option<Instant>,
    /// Ticks since the power stage was energised (saturating).
    energised: u16,
    /// What happened since the bus side last took the events.
    pub(crate) events: Events,
    /// A frame for this drive arrived since the last tick (the watchdog restarts).
    pub(crate) heard: bool,
    /// What the tick watches for on the bus side's behalf (a homing step).
    pub(crate) watch: Option<Watch>,
    /// Pins whose external stop is suspended (the switches a homing searches).
    pub(crate) suspend: u16,
    /// Where the setpoint was when the watch saw its condition.
    pub(crate) caught: Option<i64>,
    /// The motor turns the other way (0x21CA at power-up): the electrical angle out, the
    /// encoder and phase B in, mirrored (each where it is used, so that what a board never
    /// measures stays known to the compiler).
    pub(crate) reversed: bool,
    /// The command path's shaping: the tick's own (the bus side's model keeps none of it but
    /// whether it has settled, [`Controller::shaping_settled`]).
    pub(crate) shaping: ShapingState,
    /// Whether the shaping's output stood on its input at the last tick.
    pub(crate) shaping_settled: bool,
    /// The scope and the black box (their rows are in [`Shared::recordings`]).
    pub(crate) scopes: Scopes,
}

/// A reversed motor's electrical angle `a` and steps: the other way round (phase B inverted).
#[cold]
#[inline(never)]
fn mirror(a: &mut Setpoint, steps: &mut i64) {
    let fraction = U0F32::from_bits(0u32.wrapping_sub(a.fraction.to_bits()));
    let carry = i64::from(a.fraction.to_bits() != 0);
    let whole = a.whole.saturating_neg().saturating_sub(carry);
    *a = Setpoint { whole, fraction, velocity: -a.velocity, acceleration: -a.acceleration };
    *steps = steps.saturating_neg();
}

/// A condition the tick watches for while the plan of `version` runs, for the bus side (a
/// homing's search): when it holds, the tick notes the setpoint's position, stops the axis
/// (a ramp at `decel`, 0 at once) and raises [`Events::CAUGHT`]. The tick decides nothing else.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Watch {
    /// The condition.
    pub on: WatchOn,
    /// The axis version of the plan it belongs to: a watch outlives no change of course.
    pub version: u32,
    /// The stop's deceleration, pps².
    pub decel: u32,
    /// The direction the axis must move in (true positive) for the condition to count: a
    /// switch passed while the axis still brakes from the step before is not the step's edge.
    pub up: bool,
}

/// What a [`Watch`] waits for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WatchOn {
    /// Any of some pins (bits of 0x6031) at its level.
    Pins {
        /// The pins' bits.
        pins: u16,
        /// Each pin's level (its bit set: high).
        high: u16,
    },
    /// The encoder's index pulse.
    Index,
    /// A stall (the sensorless detection, or the closed loop's following error).
    Stall,
}

impl Controller {
    /// A controller at power-up with `settings`, standing at 0, with no fault history: what a
    /// test or a tool runs on its own, without a drive around it.
    pub fn new(settings: &Settings, feedback: Feedback) -> Self {
        Self::restored(settings, feedback, FaultLog::default(), false)
    }

    /// The controller at power-up, standing at 0, with the fault history loaded.
    pub(crate) fn restored(settings: &Settings, feedback: Feedback, faults: FaultLog, reversed: bool) -> Self {
        Self {
            zero_offset: settings.zero_offset,
            axis: Axis::new(0),
            status: Status::default(),
            faults,
            commanded: 0,
            clear_history: false,
            probe: [0; 2],
            servo: Servo::new(feedback),
            run: None,
            ahead: None,
            io: io::Pins::default(),
            still_since: None,
            energised: 0,
            watch: None,
            suspend: 0,
            caught: None,
            events: Events::default(),
            heard: false,
            reversed,
            shaping: ShapingState::default(),
            shaping_settled: true,
            scopes: Scopes::new(),
        }
    }

    /// Whether the command path's shaping stood on the axis' setpoint at the last tick: a
    /// motion the axis has finished still moves the motor until it has.
    pub fn shaping_settled(&self) -> bool {
        self.shaping_settled
    }

    /// The scope and the black box.
    pub fn scopes(&self) -> &Scopes {
        &self.scopes
    }

    /// The running status.
    pub fn status(&self) -> &Status {
        &self.status
    }

    /// The motion being executed.
    pub fn axis(&self) -> &Axis {
        &self.axis
    }

    /// The motion being executed, for the bus side that plans it.
    pub fn axis_mut(&mut self) -> &mut Axis {
        &mut self.axis
    }

    /// What happened on its own since the last call.
    pub fn take_events(&mut self) -> Events {
        core::mem::take(&mut self.events)
    }

    /// Sets the event `e`.
    pub(crate) fn raise(&mut self, e: Events) {
        self.events.set(e);
    }

    /// What the power stage does with `s`: a fault first, then the master's enable, then power
    /// loss.
    pub fn power_state(&self, s: &Settings) -> PowerState {
        if self.faulted() {
            PowerState::Faulted
        } else if !s.enabled {
            PowerState::Disabled
        } else if self.faults.freed {
            PowerState::Freed
        } else {
            PowerState::On
        }
    }

    /// Whether the power stage drives the motor.
    pub(crate) fn power_stage_on(&self, s: &Settings) -> bool {
        self.power_state(s) == PowerState::On
    }

    /// Decelerates to rest at the stop deceleration (a ramp of closed form) and ends a PVT run.
    pub(crate) fn decelerate_to_stop(&mut self, s: &Settings) {
        self.axis.stop_ramp(s.stop_decel);
        self.run = None;
        self.events.set(Events::STOPPED);
    }

    /// Stops the setpoint where it is and ends a PVT run.
    pub(crate) fn stop_motion(&mut self) {
        self.axis.halt();
        self.run = None;
        self.events.set(Events::STOPPED);
    }

    /// One control tick of `s` at `now` with what the drive measures: supervision, the next PVT
    /// segment (its points from `pvt` and `shared`'s table), the motion, the loops, the scope's
    /// or the black box's row into `shared`'s recordings; what the output stage does.
    pub fn tick(&mut self, s: &Settings, now: Instant, inputs: &Inputs, pvt: &mut Pvt, shared: &Shared) -> Outputs {
        let table = &shared.table;
        self.sense(s, inputs);
        self.supervise(s, now, inputs);
        self.pins(s, now, inputs.levels);
        if self.watch.is_some() {
            self.check_watch(inputs);
        }
        if let Some(code) = inputs.analog {
            self.status.analog_in = code;
        }
        self.pvt_tick(s, now, pvt, table);
        self.count_pulses(s, now, inputs.pulses);
        let (setpoint, moved) = self.axis.tick(now);
        self.commanded = self.commanded.wrapping_add(moved as u32);
        // The command path's shaping (0x2210): nothing to do while it is off and settled.
        let (setpoint, moved) = if s.shaping.ticks() > 1 || self.shaping.ticks() > 1 {
            s.shaping.process(&mut self.shaping, &setpoint, moved)
        } else {
            (setpoint, moved)
        };
        self.notify(s, setpoint.whole);
        if self.axis.take_joined() {
            self.events.set(Events::JOINED);
        }
        let (commutation, share) = self.commutate(s, now, &setpoint, moved, inputs);
        let steps = commutation.whole.saturating_sub(self.servo.last_angle);
        self.servo.last_angle = commutation.whole;
        // Standstill current reduction once the motor has stood for the delay.
        self.shaping_settled = self.shaping.settled();
        let still = self.axis.is_still() && self.shaping_settled;
        let since = *self.still_since.get_or_insert(now);
        if !still {
            self.still_since = None;
        }
        let state = self.power_state(s);
        // Held while disabled (0x21DA): at the standstill current, where it stands.
        let held = state == PowerState::Disabled && s.hold_disabled;
        let idle = held || (still && now.since(since) >= s.idle_delay_us);
        let full = s.phase_current_ma * if idle { s.idle_current_pct } else { 100 } / 100;
        let enabled = state == PowerState::On || held;
        let mut current = (full as f32 * share.clamp(0.0, 1.0)) as u32;
        // Soft start (0x21E1): the current rises from 0 over its time after the stage is energised.
        if !enabled {
            self.energised = 0;
        } else {
            if self.energised < s.soft_start_ticks {
                // At most 7 A of 60 000 ticks: within 32 bits.
                current = current * u32::from(self.energised) / u32::from(s.soft_start_ticks);
            }
            // Energised without a soft start counts as ramped: one switched on later does not
            // dip the current.
            self.energised = if s.soft_start_ticks == 0 { u16::MAX } else { self.energised.saturating_add(1) };
        }
        let gpio = self.output_levels(s);
        let function_pins = s.io.output_pins;
        if function_pins != 0 {
            // 0x6031 shows what an output with a function drives (inverted, as the manual has it).
            self.status.gpio = (self.status.gpio & !function_pins) | (!gpio & function_pins);
        }
        let current_ma = if enabled { current as u16 } else { 0 };
        if self.scopes.due() {
            let tick = record::Tick { now, setpoint: &setpoint, current_ma, share, inputs };
            self.record(&tick, &shared.recordings);
        }
        let (mut commutation, mut steps) = (commutation, steps);
        if self.reversed {
            mirror(&mut commutation, &mut steps);
        }
        Outputs {
            setpoint,
            commutation,
            steps,
            current_ma,
            enabled,
            coil_duty: self.coil_duty(s),
            gpio,
            pins: s.pins,
            microsteps: s.microsteps,
            fast_decay: s.fast_decay,
            pulse: s.pulse,
            closed_loop: matches!(self.servo.feedback, Feedback::Closed(_)),
        }
    }
}
