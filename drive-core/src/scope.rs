//! The drive's oscilloscope and black box: the control tick records rows of chosen signals
//! into memory it shares with the bus side, which reads a finished capture out. Nothing of
//! registers: the tick hands each row's values over through [`Recorder::record`].
//!
//! A [`Recorder`] is armed with a [`Config`] (up to [`MAX_SIGNALS`] signals, a divider of the
//! tick rate, a trigger, the share of the capture before the trigger, one shot or repeated).
//! Armed, it records into a ring of rows; at the trigger it records the rest of the capture
//! and holds it ([`Phase::Done`]), numbered by its sequence counter, until it is acknowledged
//! by that number ([`Recorder::acknowledge`]): a repeated recorder then arms again. A master
//! reads the phase and the sequence number before and after the rows: the same number, done
//! both times, is a whole capture.
//!
//! ```
//! use drive_core::scope::{Config, Memory, Phase, Recorder, Signal, Trigger};
//! let memory = Memory::new();
//! let mut scope = Recorder::new();
//! let mut config = Config::OFF;
//! config.signals[0] = Signal::CommandedPosition; // two words a row
//! config.signals[1] = Signal::FollowingError; // one word
//! config.trigger = Trigger::Rising { signal: Signal::CommandedPosition, level: 10 };
//! config.pre_percent = 50;
//! scope.arm(&config).unwrap();
//! assert_eq!((scope.rows(), scope.row_words()), (2730, 3)); // 8192 words / 3
//! for tick in 0..3000 {
//!     scope.record(&memory, |s| if s == Signal::CommandedPosition { tick } else { -1 });
//! }
//! assert_eq!(scope.phase(), Phase::Done);
//! // The trigger row (position 10) is at index 10: only 10 rows came before it.
//! assert_eq!(scope.trigger_row(), 10);
//! assert_eq!(scope.word(&memory, 3 * 10 + 1), Some(10)); // low word of row 10's position
//! assert_eq!(scope.word(&memory, 3 * 10 + 2), Some(0xFFFF)); // its following error, -1
//! ```

use core::sync::atomic::{AtomicU16, Ordering};

/// The words (16 bits) a recorder's memory holds: 16 KiB.
pub const WORDS: usize = 8192;
/// The signals a row holds at most.
pub const MAX_SIGNALS: usize = 8;

/// Every signal's value at one tick, by its code (index 0, no signal, is 0): what the tick
/// gathers for a row, at the same cost whichever signals it holds.
pub type Frame = [i32; 16];

macro_rules! signals {
    ($($(#[doc = $doc:literal])* $id:ident = $code:literal, $words:literal, $signed:literal, $name:literal, $unit:literal;)*) => {
        /// A signal the tick can record. Each is one word (16 bits, saturated) or two (32 bits,
        /// the high word first) of a row, in the unit its doc says.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        #[repr(u8)]
        pub enum Signal {
            /// No signal: the slot is empty.
            None = 0,
            $($(#[doc = $doc])* $id = $code,)*
        }

        impl Signal {
            /// Every signal, by code.
            pub const ALL: [Signal; 0 $(+ { let _ = $code; 1 })*] = [$(Signal::$id,)*];

            /// The signal of code `code` (0 is [`Signal::None`]).
            pub const fn from_code(code: u16) -> Option<Self> {
                match code {
                    0 => Some(Signal::None),
                    $($code => Some(Signal::$id),)*
                    _ => None,
                }
            }

            /// Its words in a row: 0 for none, 1 or 2.
            pub const fn words(self) -> u16 {
                match self {
                    Signal::None => 0,
                    $(Signal::$id => $words,)*
                }
            }

            /// Whether its words are a signed number (else unsigned, or bits).
            pub const fn signed(self) -> bool {
                match self {
                    Signal::None => false,
                    $(Signal::$id => $signed,)*
                }
            }

            /// Its name, for tables and plots.
            pub const fn name(self) -> &'static str {
                match self {
                    Signal::None => "none",
                    $(Signal::$id => $name,)*
                }
            }

            /// Its unit.
            pub const fn unit(self) -> &'static str {
                match self {
                    Signal::None => "",
                    $(Signal::$id => $unit,)*
                }
            }
        }
    };
}

signals! {
    /// The position setpoint after the command filter: microsteps in open loop, encoder counts
    /// in closed loop.
    CommandedPosition = 1, 2, true, "commanded position", "microsteps or counts";
    /// The measured position: the encoder's with the zero offset in closed loop, the encoder
    /// count (0x6089) in open loop.
    ActualPosition = 2, 2, true, "actual position", "microsteps or counts";
    /// The closed loop's following error, setpoint minus measured (0 in open loop).
    FollowingError = 3, 1, true, "following error", "counts";
    /// The setpoint's velocity.
    CommandedVelocity = 4, 2, true, "commanded velocity", "microsteps or counts per second";
    /// The measured velocity in closed loop, the commanded one in open loop (as 0x607F).
    ActualVelocity = 5, 2, true, "actual velocity", "microsteps or counts per second";
    /// Phase A's measured current.
    PhaseCurrentA = 6, 1, true, "phase A current", "mA";
    /// Phase B's measured current.
    PhaseCurrentB = 7, 1, true, "phase B current", "mA";
    /// The current amplitude the tick commands (standstill reduction and soft start included).
    CurrentCommand = 8, 1, false, "current command", "mA";
    /// The supply voltage.
    SupplyVoltage = 9, 1, false, "supply voltage", "mV";
    /// The power stage's temperature.
    Temperature = 10, 1, true, "temperature", "°C";
    /// Status: 0x6001's bits (bit 3 busy while the motor moves) and 0x6000's in the high byte.
    Status = 11, 1, false, "status", "bits";
    /// Faults: 0x2135's bits and 0x2138's in the high byte.
    Faults = 12, 1, false, "faults", "bits";
    /// The closed loop's output: the share of the phase current it drives.
    LoopOutput = 13, 1, false, "loop output", "1/10000";
    /// The pins' levels, 1 high (bits as 0x6031).
    Inputs = 14, 1, false, "pin levels", "bits";
    /// The alarms recorded since power-up (0x2136).
    Alarms = 15, 1, false, "alarm count", "count";
}

/// What starts the part of a capture after the trigger.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Trigger {
    /// At once: the capture is all after the trigger.
    Now,
    /// A motion starts: the busy bit of [`Signal::Status`] rises.
    MoveStart,
    /// `signal` rises from below `level` to `level` or above.
    Rising {
        /// The signal watched.
        signal: Signal,
        /// Its level.
        level: i32,
    },
    /// `signal` falls from above `level` to `level` or below.
    Falling {
        /// The signal watched.
        signal: Signal,
        /// Its level.
        level: i32,
    },
    /// `signal` crosses `level` either way.
    Crossing {
        /// The signal watched.
        signal: Signal,
        /// Its level.
        level: i32,
    },
    /// A bit of `mask` in `signal` turns on.
    BitsSet {
        /// The signal watched (status, faults, pin levels).
        signal: Signal,
        /// Its bits.
        mask: u32,
    },
    /// A bit of `mask` in `signal` turns off.
    BitsCleared {
        /// The signal watched.
        signal: Signal,
        /// Its bits.
        mask: u32,
    },
    /// An alarm is recorded ([`Signal::Alarms`] changes).
    Alarm,
}

impl Trigger {
    /// The trigger of code `kind` (0 now, 1 a move's start, 2-4 `signal` rising to, falling
    /// to or crossing `level`, 5-6 bits of `level` in `signal` set or cleared, 7 an alarm).
    pub const fn from_code(kind: u16, signal: Signal, level: i32) -> Option<Self> {
        let mask = level as u32;
        Some(match kind {
            0 => Trigger::Now,
            1 => Trigger::MoveStart,
            2 => Trigger::Rising { signal, level },
            3 => Trigger::Falling { signal, level },
            4 => Trigger::Crossing { signal, level },
            5 => Trigger::BitsSet { signal, mask },
            6 => Trigger::BitsCleared { signal, mask },
            7 => Trigger::Alarm,
            _ => return None,
        })
    }

    /// Its code, signal and level (or mask): what [`Trigger::from_code`] takes.
    pub const fn code(self) -> (u16, Signal, i32) {
        match self {
            Trigger::Now => (0, Signal::None, 0),
            Trigger::MoveStart => (1, Signal::None, 0),
            Trigger::Rising { signal, level } => (2, signal, level),
            Trigger::Falling { signal, level } => (3, signal, level),
            Trigger::Crossing { signal, level } => (4, signal, level),
            Trigger::BitsSet { signal, mask } => (5, signal, mask as i32),
            Trigger::BitsCleared { signal, mask } => (6, signal, mask as i32),
            Trigger::Alarm => (7, Signal::None, 0),
        }
    }

    /// The signal it watches.
    const fn watched(self) -> Signal {
        match self {
            Trigger::Now => Signal::None,
            Trigger::MoveStart => Signal::Status,
            Trigger::Alarm => Signal::Alarms,
            Trigger::Rising { signal, .. }
            | Trigger::Falling { signal, .. }
            | Trigger::Crossing { signal, .. }
            | Trigger::BitsSet { signal, .. }
            | Trigger::BitsCleared { signal, .. } => signal,
        }
    }

    /// Whether the watched signal's change from `was` to `is` fires it.
    fn fires(self, was: i32, is: i32) -> bool {
        let rises = |level| was < level && is >= level;
        let falls = |level| was > level && is <= level;
        let (was_bits, is_bits) = (was as u32, is as u32);
        match self {
            Trigger::Now => true,
            Trigger::MoveStart => !was_bits & is_bits & u32::from(STATUS_BUSY) != 0,
            Trigger::Rising { level, .. } => rises(level),
            Trigger::Falling { level, .. } => falls(level),
            Trigger::Crossing { level, .. } => rises(level) || falls(level),
            Trigger::BitsSet { mask, .. } => !was_bits & is_bits & mask != 0,
            Trigger::BitsCleared { mask, .. } => was_bits & !is_bits & mask != 0,
            Trigger::Alarm => was != is,
        }
    }
}

/// [`Signal::Status`]'s busy bit (0x6001 bit 3).
const STATUS_BUSY: u16 = 1 << 3;

/// What a recorder records: checked when it is armed ([`Recorder::arm`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Config {
    /// The signals of a row, in order; [`Signal::None`] slots are left out.
    pub signals: [Signal; MAX_SIGNALS],
    /// A row every this many ticks (1..=[`MAX_DIVIDER`]).
    pub divider: u16,
    /// What starts the capture's second part.
    pub trigger: Trigger,
    /// The share of the capture before the trigger, percent (0..=100; none for
    /// [`Trigger::Now`]).
    pub pre_percent: u8,
    /// Armed again when a capture is acknowledged (else idle).
    pub repeat: bool,
}

/// The slowest rate: a row every this many ticks (0.5 s at 20 kHz).
pub const MAX_DIVIDER: u16 = 10_000;

impl Config {
    /// No signal, every tick, at once, one shot: what a recorder must be given signals for.
    pub const OFF: Self =
        Self { signals: [Signal::None; MAX_SIGNALS], divider: 1, trigger: Trigger::Now, pre_percent: 0, repeat: false };

    /// The words of a row.
    pub fn row_words(&self) -> u16 {
        self.signals.iter().map(|s| s.words()).sum()
    }
}

/// The black box's signals: the last second before a fault and a quarter after, at 1.25 ms.
pub const BLACK_BOX: Config = Config {
    signals: [
        Signal::CommandedVelocity,
        Signal::FollowingError,
        Signal::CurrentCommand,
        Signal::SupplyVoltage,
        Signal::Temperature,
        Signal::Status,
        Signal::Faults,
        Signal::None,
    ],
    divider: 25,
    trigger: Trigger::Alarm,
    pre_percent: 80,
    repeat: true,
};

/// Why a recorder refused to arm.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ArmError {
    /// No signal chosen.
    NoSignal,
    /// The divider is 0 or beyond [`MAX_DIVIDER`].
    Divider,
    /// The pre-trigger share is beyond 100 %.
    PreTrigger,
    /// The trigger watches no signal where it needs one.
    TriggerSignal,
}

/// Where a recorder is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
#[repr(u8)]
pub enum Phase {
    /// Not recording; no capture held.
    #[default]
    Idle = 0,
    /// Recording, waiting for the trigger.
    Armed = 1,
    /// Triggered, recording the rest of the capture.
    Triggered = 2,
    /// A capture is held for read-out.
    Done = 3,
}

/// A recorder's memory: [`WORDS`] words, written by the tick, read by the bus side. Its words
/// are atomic (plain loads and stores on a Cortex-M), so that the two may share it; a capture
/// is whole when the recorder said it was done before and after it was read.
pub struct Memory {
    words: [AtomicU16; WORDS],
}

impl Memory {
    /// Zeroed. A `const fn`, so that a microcontroller builds it where it is stored (a static).
    pub const fn new() -> Self {
        Self { words: [const { AtomicU16::new(0) }; WORDS] }
    }

    /// Word `i`.
    pub fn get(&self, i: usize) -> Option<u16> {
        self.words.get(i).map(|w| w.load(Ordering::Relaxed))
    }

    /// The `n` words from word `at` (as far as the memory goes).
    fn slots(&self, at: usize, n: usize) -> core::slice::Iter<'_, AtomicU16> {
        self.words.get(at..at + n).unwrap_or_default().iter()
    }
}

impl Default for Memory {
    fn default() -> Self {
        Self::new()
    }
}

impl Clone for Memory {
    fn clone(&self) -> Self {
        let m = Self::new();
        for (to, from) in m.words.iter().zip(&self.words) {
            to.store(from.load(Ordering::Relaxed), Ordering::Relaxed);
        }
        m
    }
}

impl core::fmt::Debug for Memory {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("Memory { .. }")
    }
}

/// The scope's and the black box's memories (32 KiB), shared by the tick and the bus side.
#[derive(Clone, Debug, Default)]
pub struct Recordings {
    /// The scope's.
    pub scope: Memory,
    /// The black box's.
    pub black_box: Memory,
}

impl Recordings {
    /// Both zeroed (a `const fn`, for a static).
    pub const fn new() -> Self {
        Self { scope: Memory::new(), black_box: Memory::new() }
    }
}

/// A recorder's state: its configuration in force, where it writes, its capture.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Recorder {
    config: Config,
    phase: Phase,
    /// Captures finished since power-up (wrapping): the number of the one held.
    sequence: u16,
    row_words: u16,
    /// Rows the memory holds at this row's width.
    rows: u16,
    /// Rows kept before the trigger (at most).
    pre_rows: u16,
    /// The ring's next row.
    head: u16,
    /// Rows written since armed (up to `rows`).
    filled: u16,
    /// Ticks until the next row.
    countdown: u16,
    /// The capture's first row in the ring.
    start: u16,
    /// The capture's rows.
    len: u16,
    /// The trigger's row in the capture.
    trigger_row: u16,
    /// Rows still to record after the trigger.
    post: u16,
    /// The watched signal at the last row (`None` before the first).
    last: Option<i32>,
    /// When the trigger's row was recorded, µs.
    trigger_us: u64,
    /// The mean time between the capture's rows after the trigger, µs (the platform's ticks',
    /// not assumed).
    period_us: u32,
}

impl Default for Recorder {
    fn default() -> Self {
        Self::new()
    }
}

impl Recorder {
    /// Idle, with nothing captured.
    pub const fn new() -> Self {
        Self {
            config: Config::OFF,
            phase: Phase::Idle,
            sequence: 0,
            row_words: 0,
            rows: 0,
            pre_rows: 0,
            head: 0,
            filled: 0,
            countdown: 0,
            start: 0,
            len: 0,
            trigger_row: 0,
            post: 0,
            last: None,
            trigger_us: 0,
            period_us: 0,
        }
    }

    /// Checks `config` and arms with it (a capture held is dropped).
    pub fn arm(&mut self, config: &Config) -> Result<(), ArmError> {
        let row_words = config.row_words();
        if row_words == 0 {
            return Err(ArmError::NoSignal);
        }
        if config.divider == 0 || config.divider > MAX_DIVIDER {
            return Err(ArmError::Divider);
        }
        if config.pre_percent > 100 {
            return Err(ArmError::PreTrigger);
        }
        let watched = config.trigger.watched();
        if watched == Signal::None && !matches!(config.trigger, Trigger::Now) {
            return Err(ArmError::TriggerSignal);
        }
        let rows = (WORDS / usize::from(row_words)) as u16;
        let pre_rows = if config.trigger == Trigger::Now {
            0
        } else {
            (u32::from(rows) * u32::from(config.pre_percent) / 100).min(u32::from(rows) - 1) as u16
        };
        *self = Self {
            config: *config,
            phase: Phase::Armed,
            row_words,
            rows,
            pre_rows,
            // A row at the first tick.
            countdown: 1,
            sequence: self.sequence,
            ..Self::new()
        };
        Ok(())
    }

    /// Armed and recording again after a pause: the rows before it are dropped, so that the
    /// rows before a trigger are the ones just before it, evenly spaced.
    fn resume(&mut self) {
        if self.phase == Phase::Armed {
            (self.filled, self.last, self.countdown) = (0, None, 1);
        }
    }

    /// Stops recording and drops a capture held.
    pub fn stop(&mut self) {
        self.phase = Phase::Idle;
    }

    /// The capture numbered `sequence` has been read: a repeated recorder arms again, another
    /// stops. Any other number (a capture since, or none held) is ignored.
    pub fn acknowledge(&mut self, sequence: u16) {
        if self.phase == Phase::Done && sequence == self.sequence {
            if self.config.repeat {
                let config = self.config;
                let _ = self.arm(&config);
            } else {
                self.phase = Phase::Idle;
            }
        }
    }

    /// Whether it records (armed or triggered).
    pub const fn is_recording(&self) -> bool {
        matches!(self.phase, Phase::Armed | Phase::Triggered)
    }

    /// One tick: records a row if one is due ([`Recorder::due`]), with the signals' values
    /// from `value`.
    pub fn record(&mut self, memory: &Memory, value: impl Fn(Signal) -> i32) {
        if self.due() {
            self.row(memory, &frame_of(value), 0);
        }
    }

    /// One tick of the divider: whether a row is due now (never while not recording).
    #[inline]
    pub fn due(&mut self) -> bool {
        if !self.is_recording() {
            return false;
        }
        self.countdown = self.countdown.saturating_sub(1);
        if self.countdown == 0 {
            self.countdown = self.config.divider;
        }
        self.countdown == self.config.divider
    }

    /// Records a row of the signals' values in `frame` at `now_us` and watches the trigger's
    /// signal.
    pub fn row(&mut self, memory: &Memory, frame: &Frame, now_us: u64) {
        let value = |s: Signal| frame.get(s as usize).copied().unwrap_or(0);
        let row_words = usize::from(self.row_words);
        let mut slots = memory.slots(usize::from(self.head) * row_words, row_words);
        let mut put = |w: u16| {
            if let Some(slot) = slots.next() {
                slot.store(w, Ordering::Relaxed);
            }
        };
        for &s in &self.config.signals {
            let v = value(s);
            match (s.words(), s.signed()) {
                (0, _) => {}
                (1, true) => put(v.clamp(-32768, 32767) as u16),
                (1, false) => put(v.clamp(0, 65535) as u16),
                _ => {
                    put((v >> 16) as u16);
                    put(v as u16);
                }
            }
        }
        let row = self.head;
        self.head = if self.head + 1 >= self.rows { 0 } else { self.head + 1 };
        self.filled = self.filled.saturating_add(1).min(self.rows);
        match self.phase {
            Phase::Armed => {
                let is = value(self.config.trigger.watched());
                let fired = match self.last {
                    Some(was) => self.config.trigger.fires(was, is),
                    None => self.config.trigger == Trigger::Now,
                };
                self.last = Some(is);
                if fired {
                    let pre = self.pre_rows.min(self.filled - 1);
                    self.trigger_row = pre;
                    self.start = (row + self.rows - pre) % self.rows;
                    self.post = self.rows - self.pre_rows - 1;
                    self.len = pre + 1 + self.post;
                    self.phase = Phase::Triggered;
                    self.trigger_us = now_us;
                    self.finish_if_full(now_us);
                }
            }
            Phase::Triggered => {
                self.post = self.post.saturating_sub(1);
                self.finish_if_full(now_us);
            }
            Phase::Idle | Phase::Done => {}
        }
    }

    #[cold]
    fn finish_if_full(&mut self, now_us: u64) {
        if self.post == 0 {
            self.phase = Phase::Done;
            self.sequence = self.sequence.wrapping_add(1);
            let rows = u64::from(self.len - self.trigger_row - 1);
            let took = now_us.saturating_sub(self.trigger_us);
            self.period_us = (took + rows / 2).checked_div(rows).map_or(0, |us| us.min(u64::from(u32::MAX)) as u32);
        }
    }

    /// The mean time between the capture's rows after its trigger, µs (0 when the trigger
    /// ended it, or none is held).
    pub const fn period_us(&self) -> u32 {
        if matches!(self.phase, Phase::Done) { self.period_us } else { 0 }
    }

    /// Where it is.
    pub const fn phase(&self) -> Phase {
        self.phase
    }

    /// The number of the capture held (captures finished since power-up, wrapping).
    pub const fn sequence(&self) -> u16 {
        self.sequence
    }

    /// The configuration in force.
    pub const fn config(&self) -> &Config {
        &self.config
    }

    /// The words of a row.
    pub const fn row_words(&self) -> u16 {
        self.row_words
    }

    /// The rows the memory holds at this row's width.
    pub const fn rows(&self) -> u16 {
        self.rows
    }

    /// The rows of the capture held (0 while none is).
    pub const fn len(&self) -> u16 {
        if matches!(self.phase, Phase::Done) { self.len } else { 0 }
    }

    /// Whether no capture is held.
    pub const fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The trigger's row in the capture.
    pub const fn trigger_row(&self) -> u16 {
        self.trigger_row
    }

    /// Word `k` of the capture, its rows in time order from the first (`None` past the
    /// memory). Past the capture's end, or before one is held, whatever the memory holds.
    pub fn word(&self, memory: &Memory, k: usize) -> Option<u16> {
        if k >= WORDS {
            return None;
        }
        let (row_words, rows) = (usize::from(self.row_words.max(1)), usize::from(self.rows.max(1)));
        let row = (usize::from(self.start) + k / row_words) % rows;
        memory.get(row * row_words + k % row_words).or(Some(0))
    }
}

/// The scope and the black box, as the tick owns them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Scopes {
    /// The scope a master configures.
    pub scope: Recorder,
    /// The black box: records [`BLACK_BOX`] unless the scope records, frozen by an alarm.
    pub black_box: Recorder,
    /// The fault history entry of the alarm the black box's capture holds (as the history
    /// holds it: code and time).
    pub black_box_fault: u32,
    /// The black box paused while the scope recorded.
    paused: bool,
}

impl Scopes {
    /// At power-up: the black box recording.
    pub fn new() -> Self {
        let mut black_box = Recorder::new();
        let _ = black_box.arm(&BLACK_BOX);
        Self { scope: Recorder::new(), black_box, black_box_fault: 0, paused: false }
    }

    /// One tick: whether a row is due, the scope's if it records, else the black box's (which
    /// starts its ring afresh after a pause).
    #[inline]
    pub fn due(&mut self) -> bool {
        if self.scope.is_recording() {
            self.paused = true;
            return self.scope.due();
        }
        if self.paused {
            self.paused = false;
            self.black_box.resume();
        }
        self.black_box.due()
    }

    /// The recorder that records: the scope's if it does, else the black box.
    pub fn active(&self) -> &Recorder {
        if self.scope.is_recording() { &self.scope } else { &self.black_box }
    }

    /// The row that is due into `memory` ([`Scopes::due`]) from `frame`, at `now_us`.
    pub fn row(&mut self, memory: &Recordings, frame: &Frame, now_us: u64) {
        if self.scope.is_recording() {
            self.scope.row(&memory.scope, frame, now_us);
        } else {
            self.black_box.row(&memory.black_box, frame, now_us);
        }
    }

    /// One tick's row, if one is due, into `memory`.
    pub fn record(&mut self, memory: &Recordings, value: impl Fn(Signal) -> i32) {
        if self.due() {
            self.row(memory, &frame_of(value), 0);
        }
    }
}

/// The frame of the values `value` gives.
fn frame_of(value: impl Fn(Signal) -> i32) -> Frame {
    let mut frame = [0; 16];
    for s in Signal::ALL {
        if let Some(slot) = frame.get_mut(s as usize) {
            *slot = value(s);
        }
    }
    frame
}

#[cfg(test)]
mod tests {
    use super::*;

    fn config(signals: &[Signal], trigger: Trigger, pre: u8) -> Config {
        let mut c = Config::OFF;
        for (slot, s) in c.signals.iter_mut().zip(signals) {
            *slot = *s;
        }
        (c.trigger, c.pre_percent) = (trigger, pre);
        c
    }

    fn capture(r: &Recorder, m: &Memory) -> std::vec::Vec<u16> {
        (0..usize::from(r.len() * r.row_words())).filter_map(|k| r.word(m, k)).collect()
    }

    extern crate std;

    #[test]
    fn a_capture_now_is_the_next_rows_in_order() {
        let m = Memory::new();
        let mut r = Recorder::new();
        assert!(r.arm(&config(&[Signal::FollowingError], Trigger::Now, 50)).is_ok());
        for t in 0..10_000 {
            r.record(&m, |_| t);
        }
        assert_eq!(r.phase(), Phase::Done);
        assert_eq!((r.len(), r.trigger_row(), r.sequence()), (8192, 0, 1));
        let c = capture(&r, &m);
        assert!(c.iter().enumerate().all(|(i, &w)| w == i as u16));
    }

    #[test]
    fn the_pre_trigger_share_comes_before_the_crossing() {
        let m = Memory::new();
        let mut r = Recorder::new();
        let mut c = config(
            &[Signal::CommandedPosition],
            Trigger::Falling { signal: Signal::CommandedPosition, level: -5000 },
            25,
        );
        c.divider = 3;
        assert!(r.arm(&c).is_ok());
        let mut t = 0;
        while r.phase() != Phase::Done {
            r.record(&m, |_| -t);
            t += 1;
        }
        assert_eq!(r.rows(), 4096);
        assert_eq!(r.trigger_row(), 1024);
        let rows = capture(&r, &m);
        let word = |k: usize| i32::from(rows.get(k).copied().unwrap_or_default());
        let at = |i: usize| (word(2 * i) << 16) | word(2 * i + 1);
        // The trigger's row is the first at or below the level; each row 3 ticks apart.
        assert!(at(1024) <= -5000 && at(1023) > -5000 && at(1024) > -5003);
        assert!((1..4096).all(|i| at(i) - at(i - 1) == -3));
    }

    #[test]
    fn acknowledged_a_repeated_recorder_arms_again_and_a_stale_number_is_ignored() {
        let m = Memory::new();
        let mut r = Recorder::new();
        let mut c = config(&[Signal::Status], Trigger::MoveStart, 10);
        c.repeat = true;
        assert!(r.arm(&c).is_ok());
        for t in 0..20_000 {
            r.record(&m, |_| if t >= 5000 { 8 } else { 0 });
        }
        assert_eq!((r.phase(), r.sequence(), r.trigger_row()), (Phase::Done, 1, 819));
        r.acknowledge(0);
        assert_eq!(r.phase(), Phase::Done);
        r.acknowledge(1);
        assert_eq!(r.phase(), Phase::Armed);
        assert_eq!(r.len(), 0);
    }

    #[test]
    fn a_trigger_is_its_code() {
        let s = Signal::Status;
        for t in [
            Trigger::Now,
            Trigger::MoveStart,
            Trigger::Rising { signal: s, level: -5 },
            Trigger::Falling { signal: s, level: 7 },
            Trigger::Crossing { signal: s, level: 0 },
            Trigger::BitsSet { signal: s, mask: 0x8000_0001 },
            Trigger::BitsCleared { signal: s, mask: 8 },
            Trigger::Alarm,
        ] {
            let (kind, signal, level) = t.code();
            assert_eq!(Trigger::from_code(kind, signal, level), Some(t));
        }
    }

    #[test]
    fn arming_checks_the_configuration() {
        let mut r = Recorder::new();
        assert_eq!(r.arm(&Config::OFF), Err(ArmError::NoSignal));
        let mut c = config(&[Signal::Faults], Trigger::BitsSet { signal: Signal::None, mask: 1 }, 0);
        assert_eq!(r.arm(&c), Err(ArmError::TriggerSignal));
        c.trigger = Trigger::Alarm;
        c.divider = 0;
        assert_eq!(r.arm(&c), Err(ArmError::Divider));
        assert_eq!(r.phase(), Phase::Idle);
    }

    #[test]
    fn after_the_scope_the_black_box_keeps_only_rows_since() {
        let m = Recordings::new();
        let mut s = Scopes::new();
        let value = |t: i32, alarm: bool| {
            move |sig| match sig {
                Signal::Alarms => i32::from(alarm),
                Signal::CommandedVelocity => t,
                _ => 0,
            }
        };
        for t in 0..50_000 {
            s.record(&m, value(t, false));
        }
        let mut c = config(&[Signal::Status], Trigger::Now, 0);
        c.divider = 2;
        assert!(s.scope.arm(&c).is_ok());
        let mut t = 50_000;
        while s.scope.is_recording() {
            s.record(&m, value(t, false));
            t += 1;
        }
        // 100 rows of the black box after the scope, then the alarm: none from before.
        let resumed = t;
        for _ in 0..2_500 {
            s.record(&m, value(t, false));
            t += 1;
        }
        s.record(&m, value(t, true));
        for _ in 0..10_000 {
            t += 1;
            s.record(&m, value(t, true));
        }
        let b = s.black_box;
        assert_eq!(b.phase(), Phase::Done);
        assert_eq!(b.trigger_row(), 100);
        let word = |k| i32::from(b.word(&m.black_box, k).unwrap_or_default());
        let first = (word(0) << 16) | word(1);
        assert!(first >= resumed, "the first row at {first}, the black box resumed at {resumed}");
    }

    #[test]
    fn the_black_box_holds_a_second_before_an_alarm() {
        let m = Recordings::new();
        let mut s = Scopes::new();
        let alarm_at = 100_000;
        for t in 0..200_000 {
            s.record(&m, |sig| match sig {
                Signal::Alarms => i32::from(t >= alarm_at),
                Signal::Temperature => t / 25,
                _ => 0,
            });
        }
        let b = s.black_box;
        assert_eq!(b.phase(), Phase::Done);
        assert_eq!(b.row_words(), 8);
        // 1024 rows of 1.25 ms: 819 before the alarm's (1.02 s), 204 after.
        assert_eq!((b.len(), b.trigger_row()), (1024, 819));
        let temp = |row: usize| b.word(&m.black_box, row * 8 + 5).unwrap_or_default() as i16 as i32;
        assert_eq!(temp(819), alarm_at / 25);
        assert_eq!(temp(0), alarm_at / 25 - 819);
    }
}
