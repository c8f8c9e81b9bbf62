//! The drive's pins at each tick: the external stops (§5.6), the GPIO levels (§5.7), the step
//! notifications (§5.16) and the coil output (§3.10, §5.14).
//!
//! Pins are numbered as 0x6031's bits: GPIO1-7 in bits 0-6, EXT1 7, EXT2 8, EXT3/ENC1 9, ENC2
//! 10, GPIO8 11. [`Inputs::levels`](crate::faults::Inputs::levels) has a pin's level in its bit
//! (1 high); 0x6031 shows it inverted, as the manual has it (1 low).
//!
//! An external stop is a stop ramp at the deceleration of the moves (0x600B's level, 0x6069 in
//! the profile modes), started in the tick that confirms the edge. A stepper stopped dead from
//! speed overshoots by up to a pole pitch and may lose steps, which would leave the position a
//! zero search sets wrong by that much; a ramp the moves already use is one the motor follows.
//! A master that needs a shorter stop sets a harder deceleration (level 0 of 0x600B stops at
//! once).

use super::{Controller, STATUS_EXT1, STATUS_EXT2, STATUS_EXT3, Settings};
use crate::units::Instant;

/// 0x6031's bits of pins that exist (bits 0-11).
pub const PINS: u16 = 0x0FFF;
/// EXT1's bit in 0x6031, 0x602E and [`crate::faults::Inputs::levels`].
pub const PIN_EXT1: u16 = 1 << 7;
/// EXT2's bit.
pub const PIN_EXT2: u16 = 1 << 8;
/// EXT3's (ENC1's) bit.
pub const PIN_EXT3: u16 = 1 << 9;
/// ENC2's bit.
pub const PIN_ENC2: u16 = 1 << 10;
/// Pins that are inputs whatever 0x602E says.
pub const INPUT_ONLY: u16 = PIN_EXT1 | PIN_EXT2 | PIN_EXT3 | PIN_ENC2;

/// The pins of the inputs IN1-IN7 (seed 002's, our 0x21BA-0x21C0): EXT1-EXT3, GPIO1-GPIO4.
pub const IN_PINS: [u16; 7] = [PIN_EXT1, PIN_EXT2, PIN_EXT3, 1 << 0, 1 << 1, 1 << 2, 1 << 3];
/// The pins of the outputs OUT1-OUT4 (seed 002's, our 0x21C3-0x21C6): GPIO5-GPIO8.
pub const OUT_PINS: [u16; 4] = [1 << 4, 1 << 5, 1 << 6, 1 << 11];

/// What an output shows (our 0x21C3-0x21C6; seed 002's 0420-0423 are 100 more).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum OutputFunction {
    /// None (0): the pin is a GPIO as 0x602E, 0x602F and 0x6031 set it.
    #[default]
    None = 0,
    /// A general output (1): on while its bit of 0x21C7 is set.
    General = 1,
    /// Alarm (2): on while no alarm is latched.
    Alarm = 2,
    /// In position (3): on while the axis stands on its target within 0x21C9.
    InPosition = 3,
    /// Motor free (4): on while the power stage is off.
    Free = 4,
    /// Ready (5): on while the power stage drives the motor.
    Ready = 5,
    /// Speed coincidence (6; seed 004's /V-CMP): on while the speed is within the window
    /// (0x21F2) of the commanded one; in a position move and at rest, while in position.
    Coincidence = 6,
}

impl OutputFunction {
    /// The function of a register value, if it is one.
    pub const fn from_raw(v: u32) -> Option<Self> {
        Some(match v {
            0 => Self::None,
            1 => Self::General,
            2 => Self::Alarm,
            3 => Self::InPosition,
            4 => Self::Free,
            5 => Self::Ready,
            6 => Self::Coincidence,
            _ => return None,
        })
    }
}

/// What the tick does with the inputs' and outputs' functions (our 0x21BA-0x21C9).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct IoFunctions {
    /// The inputs with a function (bit k: IN k+1): the tick reads no other.
    pub inputs: u8,
    /// The pins of the outputs with a function: the tick sets no other.
    pub output_pins: u16,
    /// The inputs active low (bit k: IN k+1; 0x21C1).
    pub input_low: u8,
    /// The inputs that are positive limit switches (function 9).
    pub limit_positive: u8,
    /// The inputs that are negative limit switches (function 10).
    pub limit_negative: u8,
    /// The inputs that are touch probes 1 and 2 (functions 21, 22).
    pub probes: [u8; 2],
    /// OUT1-OUT4's functions.
    pub outputs: [OutputFunction; 4],
    /// The general outputs on (bit k: OUT k+1; 0x21C7).
    pub general: u8,
    /// The outputs active low (0x21C8).
    pub output_low: u8,
    /// The in-position window (0x21C9): counts of the encoder in closed loop; `u32::MAX` where
    /// the plan's end is the position (0x21D9 = 0).
    pub in_position: u32,
    /// The speed coincidence window (0x21F2), microsteps a second.
    pub speed_window: u32,
    /// The overtravel signals of the communication IO (0x2193 bits 2 and 3, while no input is
    /// that limit switch): bit 0 positive, bit 1 negative, acting as active limit switches.
    pub overtravel: u8,
    /// IN1-IN7's debouncers' delays, µs: the filter times 0x21F9-0x21FF less the sample of the
    /// tick a change comes at (a level must hold that long).
    pub input_delay_us: [u32; 7],
}

/// The three external stops: their pin, their bit in 0x6013/0x6014, their bit in 0x6001.
pub const EXT: [(u16, u8, u8); 3] =
    [(PIN_EXT1, 1 << 0, STATUS_EXT1), (PIN_EXT2, 1 << 1, STATUS_EXT2), (PIN_EXT3, 1 << 4, STATUS_EXT3)];

/// An input's pull or an output's driver, as 0x602F encodes them (2 bits a pin).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PinMode {
    /// Input, no pull (0).
    Floating,
    /// Input with a pull-up (1).
    PullUp,
    /// Input with a pull-down (2).
    PullDown,
    /// Analog input (3).
    Analog,
    /// Output, open drain (0).
    OpenDrain,
    /// Output, push-pull (1).
    PushPull,
}

/// How the pins are set up: directions (0x602E, 1 output) and 0x602F's 2-bit fields, with the
/// external stops' pulls of 0x6014/0x6015 in EXT1-3's fields while the stop is enabled.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PinConfig {
    /// 1 output, bit as 0x6031.
    pub outputs: u16,
    /// 2 bits a pin: pin `k` in bits `2k+1..2k` (0x602F's layout).
    pub fields: u32,
}

impl PinConfig {
    /// The pins as `dir` (0x602E), `config` (0x602F), and the external stops enabled in `ext`
    /// (0x6013) with edges `rising` (0x6014) for sensors of type `pnp` (0x6015 = 1): §5.6.3
    /// pulls type 0's rising edge down and its falling edge up, type 1's the other way round.
    pub fn new(dir: u16, config: u32, ext: u8, rising: u8, pnp: bool) -> Self {
        let outputs = dir & PINS & !INPUT_ONLY;
        let mut fields = config;
        for &(pin, bit, _) in EXT.iter() {
            if ext & bit != 0 {
                let up = (rising & bit != 0) == pnp;
                let shift = 2 * pin.trailing_zeros();
                fields = (fields & !(3 << shift)) | (if up { 1 } else { 2 }) << shift;
            }
        }
        Self { outputs, fields }
    }

    /// The same pins with `pins` push-pull outputs (an output with a function).
    pub fn with_outputs(self, pins: u16) -> Self {
        let mut fields = self.fields;
        for k in 0..16 {
            if pins & (1 << k) != 0 {
                fields = (fields & !(3 << (2 * k))) | (1 << (2 * k));
            }
        }
        Self { outputs: self.outputs | (pins & PINS), fields }
    }

    /// The mode of pin `k` (0..=11).
    ///
    /// ```
    /// use drive_core::controller::io::{PinConfig, PinMode};
    /// // EXT1 enabled, falling edge, NPN: pulled up; GPIO1 a push-pull output.
    /// let c = PinConfig::new(0b1, 0b01, 0b1, 0, false);
    /// assert_eq!((c.mode(7), c.mode(0), c.mode(1)), (PinMode::PullUp, PinMode::PushPull, PinMode::Floating));
    /// ```
    pub fn mode(&self, k: u32) -> PinMode {
        let field = self.fields.checked_shr(2 * k).unwrap_or(0) & 3;
        if self.outputs.checked_shr(k).unwrap_or(0) & 1 != 0 {
            return if field & 1 != 0 { PinMode::PushPull } else { PinMode::OpenDrain };
        }
        match field {
            0 => PinMode::Floating,
            1 => PinMode::PullUp,
            2 => PinMode::PullDown,
            _ => PinMode::Analog,
        }
    }
}

/// A pin's level against bounce, for the external stops (0x6042) and IN1-IN7 (0x21F9-0x21FF)
/// alike: a change of level starts the delay, further changes meanwhile are bounces, and when it
/// has run out the level is read again: changed still, the change counts (once), at the position
/// where it began; back, it was a pulse too short to count.
///
/// ```
/// use drive_core::controller::io::{Debouncer, Edge};
/// use drive_core::Instant;
/// let mut d = Debouncer::default();
/// let t = |ms: u64| Instant::from_micros(ms * 1000);
/// assert_eq!(d.update(t(0), false, 10_000, 5), None); // the first reading is no edge
/// assert_eq!(d.update(t(1), true, 10_000, 7), None); // rising: the delay starts
/// assert_eq!(d.update(t(2), false, 10_000, 9), None); // a bounce
/// assert_eq!(d.update(t(3), true, 10_000, 11), None);
/// assert_eq!(d.update(t(11), true, 10_000, 30), Some(Edge { rising: true, at: 7 })); // where it began
/// assert_eq!(d.update(t(12), false, 0, 31), Some(Edge { rising: false, at: 31 })); // no delay: at once
/// ```
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Debouncer {
    /// The position where the change being confirmed began.
    at: i64,
    /// When it began: the clock's low 32 bits, µs (a delay is at most 200 ms).
    since: u32,
    /// A change is being confirmed.
    pending: bool,
    /// The level confirmed, plus one (0: none read yet).
    level: u8,
}

/// A change of level a [`Debouncer`] confirmed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Edge {
    /// To high (else to low).
    pub rising: bool,
    /// The position where it began.
    pub at: i64,
}

impl Debouncer {
    /// Reads `level` at `now` with the axis at `position`, a change confirmed after `delay_us`:
    /// the change once it is.
    pub fn update(&mut self, now: Instant, level: bool, delay_us: u32, position: i64) -> Option<Edge> {
        // `Default` is all zero: "none yet" is stored as the level plus one.
        let Some(confirmed) = self.level.checked_sub(1).map(|l| l == 1) else {
            self.level = u8::from(level) + 1;
            return None;
        };
        let now = now.as_micros() as u32;
        if !self.pending {
            if level == confirmed {
                return None;
            }
            (self.pending, self.since, self.at) = (true, now, position);
        }
        if now.wrapping_sub(self.since) < delay_us {
            return None;
        }
        self.pending = false;
        if level == confirmed {
            return None;
        }
        self.level = u8::from(level) + 1;
        Some(Edge { rising: level, at: self.at })
    }

    /// Whether a change is being confirmed.
    pub fn pending(&self) -> bool {
        self.pending
    }

    /// Forgets a change being confirmed (the input was disabled).
    pub fn reset(&mut self) {
        self.pending = false;
    }
}

/// What the tick keeps of the pins between ticks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Pins {
    /// The external stops' debouncers.
    ext: [Debouncer; 3],
    /// The setpoint's position at the last tick, for the step notifications (the axis starts
    /// at 0).
    last_position: i64,
    /// Ticks the notification output's pulse still lasts.
    pulse_ticks: u16,
    /// The pulse input's count at the last tick (none before the first).
    pulses: Option<u16>,
    /// The inputs were read at least once (the first reading is no edge).
    inputs_read: bool,
    /// IN1-IN7's debouncers (0x21F9-0x21FF).
    inputs: [Debouncer; 7],
    /// IN1-IN7's levels as their debouncers confirmed them, bit k IN k+1 high.
    high: u8,
    /// The inputs whose debouncers are confirming a change.
    pending: u8,
    /// A limit switch stopped the axis, which has not stood still since.
    limit_stop: bool,
}

/// How the pulse input is set up (0x21B7, 0x21B8): what the platform's counter counts, and its
/// input filter (1-15, the STM32 timer's ICxF).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct PulseInput {
    /// How the two lines carry the pulses.
    pub format: crate::modes::PulseFormat,
    /// The input filter.
    pub filter: u8,
}

impl Controller {
    /// The pulses counted since the last tick, for the axis if it follows them (work mode 3),
    /// but for those heading into an active limit switch. The count is a 16-bit counter's: at
    /// the top speed of 300 kpps a tick counts 15.
    #[inline]
    pub(crate) fn count_pulses(&mut self, s: &Settings, now: Instant, count: u16) {
        let last = self.io.pulses.replace(count).unwrap_or(count);
        let pulses = count.wrapping_sub(last) as i16;
        let (io, active) = (&s.io, self.status.inputs);
        let blocked =
            (pulses > 0 && active & io.limit_positive != 0) || (pulses < 0 && active & io.limit_negative != 0);
        self.axis.add_pulses(now, if blocked { 0 } else { pulses });
    }
}

impl Controller {
    /// The touch probes among the inputs that `rose` (each where its change began, `at`): each
    /// not yet captured takes that position (the encoder's in closed loop, the setpoint's in
    /// open loop). Out of line: an edge's work.
    #[inline(never)]
    fn probe(&mut self, s: &Settings, rose: u8, at: &[i64; 7]) {
        for (k, (&inputs, slot)) in s.io.probes.iter().zip(self.probe.iter_mut()).enumerate() {
            let bit = 1 << k;
            let first = (0..7).find(|&i| rose & inputs & (1 << i) != 0);
            if let Some(i) = first
                && self.status.probes & bit == 0
            {
                *slot = at.get(i).copied().unwrap_or_default() as i32;
                self.status.probes |= bit;
            }
        }
    }

    /// The input pins at `now`: 0x6031's input levels and the external stops.
    #[inline]
    pub(crate) fn pins(&mut self, s: &Settings, now: Instant, levels: u16) {
        let inputs = PINS & !s.pins.outputs;
        self.status.gpio = (self.status.gpio_out & s.pins.outputs) | (!levels & inputs);
        if s.ext_enable != 0 {
            self.external_stops(s, now, levels);
        }
        self.functions(s, now, levels);
    }

    /// IN1-IN7: which are active (their levels through their debouncers, 0x21F9-0x21FF), the
    /// activations for the bus side (an input's function acts there), and the limit switches,
    /// which stop a motion heading into them.
    #[inline]
    fn functions(&mut self, s: &Settings, now: Instant, levels: u16) {
        let (inputs, input_low) = (s.io.inputs, s.io.input_low);
        if inputs | s.io.overtravel == 0 {
            return;
        }
        // IN1-IN3 are 0x6031's bits 7-9, IN4-IN7 its bits 0-3 (`IN_PINS`).
        let raw = ((levels >> 7) & 0b111) as u8 | (((levels & 0b1111) as u8) << 3);
        let position =
            if self.servo.feedback.encoder().is_some() { self.measured() } else { self.axis.setpoint().whole };
        let mut at = [position; 7];
        // The first reading is no edge: the debouncers take it as their levels.
        let first = !core::mem::replace(&mut self.io.inputs_read, true);
        // Only the inputs that changed or are confirming a change (none, mostly) are looked at.
        let busy = if first { 0x7F } else { (raw ^ self.io.high) | self.io.pending };
        if busy != 0 {
            self.debounce(s, now, raw, busy, position, &mut at);
        }
        if first {
            self.io.high = raw;
        }
        let active = (self.io.high ^ input_low) & inputs;
        let rose = if first { 0 } else { active & !self.status.inputs };
        self.status.inputs = active;
        if rose != 0 {
            self.status.input_edges |= rose;
            self.events.set(super::Events::INPUT);
            self.probe(s, rose, &at);
        }
        let v = self.axis.setpoint().velocity;
        let io = &s.io;
        let (up, down) = (active & io.limit_positive != 0, active & io.limit_negative != 0);
        let into = (v > 0.0 && (up || io.overtravel & 1 != 0)) || (v < 0.0 && (down || io.overtravel & 2 != 0));
        // The pulse following drops the pulses heading into a limit instead (`count_pulses`).
        if self.axis.is_still() {
            self.io.limit_stop = false;
        } else if into && !self.io.limit_stop && !self.axis.follows_pulses() {
            self.io.limit_stop = true;
            self.decelerate_to_stop(s);
        }
    }

    /// The debouncers of the inputs `busy` with the levels `raw`: the changes they confirm
    /// into the inputs' levels, each one's position where it began into `at`. Out of line: a
    /// change's work.
    #[inline(never)]
    fn debounce(&mut self, s: &Settings, now: Instant, raw: u8, busy: u8, position: i64, at: &mut [i64; 7]) {
        let io = &mut self.io;
        for (k, ((d, &delay), at)) in io.inputs.iter_mut().zip(&s.io.input_delay_us).zip(at).enumerate() {
            let bit = 1 << k;
            if busy & bit == 0 {
                continue;
            }
            if let Some(e) = d.update(now, raw & bit != 0, delay, position) {
                io.high = if e.rising { io.high | bit } else { io.high & !bit };
                *at = e.at;
            }
            io.pending = if d.pending() { io.pending | bit } else { io.pending & !bit };
        }
    }

    /// Whether the axis stands on its target: within 0x21C9's window of the encoder in closed
    /// loop.
    fn in_position(&self, s: &Settings) -> bool {
        let window = i64::from(s.io.in_position);
        self.axis.is_still() && (self.servo.feedback.encoder().is_none() || self.servo.following.abs() <= window)
    }

    /// The watch the bus side armed: its condition met while its plan runs, the setpoint's
    /// position noted and the axis stopped.
    #[inline(never)]
    pub(crate) fn check_watch(&mut self, inputs: &crate::faults::Inputs) {
        let Some(w) = self.watch else { return };
        let v = self.axis.setpoint().velocity;
        if self.axis.version() != w.version || v == 0.0 || (v > 0.0) != w.up {
            return;
        }
        let met = match w.on {
            super::WatchOn::Pins { pins, high } => !(inputs.levels ^ high) & pins != 0,
            super::WatchOn::Index => inputs.index,
            super::WatchOn::Stall => self.status.controller & super::STATUS_STALL != 0,
        };
        if met {
            self.catch(w.decel);
        }
    }

    /// The watch met: the setpoint's position noted, the axis stopped (a ramp at `decel`).
    fn catch(&mut self, decel: u32) {
        self.caught = Some(self.axis.setpoint().whole);
        self.watch = None;
        self.axis.stop_ramp(decel);
        self.events.set(super::Events::CAUGHT);
    }

    /// A stall just detected: if the watch waits for one (a homing against a hard stop), it is
    /// caught there and then, in place of the stall's own stop (which would end the homing).
    pub(crate) fn stall_caught(&mut self) -> bool {
        let armed = self.watch.is_some_and(|w| w.on == super::WatchOn::Stall && w.version == self.axis.version());
        if armed {
            self.catch(0);
        }
        armed
    }

    /// The enabled external stops: an edge confirmed stops the motor and latches its bit.
    #[inline(never)]
    fn external_stops(&mut self, s: &Settings, now: Instant, levels: u16) {
        let position = self.axis.setpoint().whole;
        let mut stop = false;
        for (d, &(pin, bit, status)) in self.io.ext.iter_mut().zip(EXT.iter()) {
            if s.ext_enable & bit == 0 || self.suspend & pin != 0 {
                d.reset();
            } else if d
                .update(now, levels & pin != 0, s.ext_delay_us, position)
                .is_some_and(|e| e.rising == (s.ext_rising & bit != 0))
            {
                self.status.controller |= status;
                stop = true;
            }
        }
        if stop {
            self.decelerate_to_stop(s);
        }
    }

    /// Step notifications: a bit for each position 0x6062/0x6064 the setpoint (at `position`
    /// now) reached or crossed since the last tick, and the notification output's pulse.
    #[inline]
    pub(crate) fn notify(&mut self, s: &Settings, position: i64) {
        self.io.pulse_ticks = self.io.pulse_ticks.saturating_sub(1);
        let last = core::mem::replace(&mut self.io.last_position, position);
        if last != position {
            self.notify_between(s, last, position);
        }
    }

    /// The notifications the setpoint reached or crossed going from `last` to `position`: the
    /// start of the step excluded, its end included.
    #[inline(never)]
    fn notify_between(&mut self, s: &Settings, last: i64, position: i64) {
        let [a, b] = s.notify;
        let (lo, hi) = if last < position { (last + 1, position) } else { (position, last - 1) };
        let hit = u8::from(lo <= a && a <= hi) | u8::from(lo <= b && b <= hi) << 1;
        if hit != 0 {
            self.status.notify |= hit;
            self.io.pulse_ticks = s.notify_output.pulse_ticks;
        }
    }

    /// The output pins' levels (1 high, bit as 0x6031): what 0x6031 holds for them (inverted),
    /// and the notification output high during its pulse.
    #[inline]
    pub(crate) fn output_levels(&self, s: &Settings) -> u16 {
        let pulse = if self.io.pulse_ticks != 0 { s.notify_output.pin } else { 0 };
        let mut levels = (!self.status.gpio_out | pulse) & s.pins.outputs;
        if s.io.output_pins == 0 {
            return levels;
        }
        let (alarm, ready) = (self.faulted(), self.power_stage_on(s));
        for (k, (&pin, &function)) in OUT_PINS.iter().zip(&s.io.outputs).enumerate() {
            let on = match function {
                OutputFunction::None => continue,
                OutputFunction::General => s.io.general & (1 << k) != 0,
                OutputFunction::Alarm => !alarm,
                OutputFunction::InPosition => self.in_position(s),
                OutputFunction::Free => !ready,
                OutputFunction::Ready => ready,
                OutputFunction::Coincidence => self.speed_coincides(s),
            };
            let high = on != (s.io.output_low & (1 << k) != 0);
            levels = if high { levels | pin } else { levels & !pin };
        }
        levels
    }

    /// The outputs whose function is on (bit k: OUT k+1), before 0x21C8 inverts them: from the
    /// levels the last tick drove (0x6031 shows them inverted).
    pub(crate) fn outputs_on(&self, s: &Settings) -> u8 {
        let io = &s.io;
        let mut on = 0u8;
        for (k, (&pin, &function)) in OUT_PINS.iter().zip(&io.outputs).enumerate() {
            let high = self.status.gpio & pin == 0;
            let active = function != OutputFunction::None && high != (io.output_low & (1 << k) != 0);
            on |= u8::from(active) << k;
        }
        on
    }

    /// Whether the speed is the commanded one within 0x21F2; in a position move and at rest,
    /// whether the axis is in position.
    #[inline(never)]
    fn speed_coincides(&self, s: &Settings) -> bool {
        if self.axis.is_still() || self.axis.target().is_some() {
            return self.in_position(s);
        }
        let error = self.real_speed() as f32 - self.axis.setpoint().velocity;
        error.abs() <= s.io.speed_window as f32
    }

    /// The coil output's duty (0x6038): in brake mode released only while the power stage is on
    /// and power loss does not apply it; as a general output (valve, magnet, DC load) the duty
    /// written, cut while a fault is latched.
    pub(crate) fn coil_duty(&self, s: &Settings) -> u8 {
        let on = if s.coil_general { !self.faulted() } else { self.power_stage_on(s) && !self.faults.braked };
        if on { s.brake_duty } else { 0 }
    }
}

/// The step notifications' output (our object 0x2150): a GPIO pulsed high when a notification
/// bit sets.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NotifyOutput {
    /// The pin's bit (as 0x6031), 0 for none.
    pub pin: u16,
    /// The pulse's length, control ticks.
    pub pulse_ticks: u16,
}

impl NotifyOutput {
    /// From 0x2150: bits 0-3 the GPIO (1-7 GPIO1-7, 8 GPIO8; 0 none), bits 8-15 the pulse in ms.
    ///
    /// ```
    /// use drive_core::controller::io::NotifyOutput;
    /// assert_eq!(NotifyOutput::from_object(0x0208), NotifyOutput { pin: 1 << 11, pulse_ticks: 40 });
    /// assert_eq!(NotifyOutput::from_object(0x0200).pin, 0);
    /// ```
    pub fn from_object(value: u32) -> Self {
        let pin = match value & 0xF {
            k @ 1..=7 => 1 << (k - 1),
            8 => 1 << 11,
            _ => 0,
        };
        let ms = (value >> 8) & 0xFF;
        Self { pin, pulse_ticks: if pin == 0 { 0 } else { (ms * crate::units::TICK_HZ / 1000) as u16 } }
    }
}
