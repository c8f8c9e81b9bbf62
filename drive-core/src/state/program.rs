//! Multi-segment programs (seed 002 §7, registers 1024-1536): moves, speeds, waits and loops a
//! master stores once and starts by one command or one input, run on the bus side one
//! instruction at a time, each move planned as a motion command's is. The program is kept in a
//! [`ProgramMemory`] of its own, which the drive is handed beside the PVT point table.
//!
//! The program is a stream of instructions in the map's registers, each a code word and its
//! parameter words (32-bit ones high word first): 1 absolute run (two words, pulses), 2
//! relative run (two), 51 start speed, 53 stop speed, 54 run speed (one each, 0.01 rev/s), 61
//! acceleration, 62 deceleration (one each, rev/s²), 65 wait then jump (two: `0x00BB` the
//! instruction to go on at, then the wait in ms), 66 loop (two: the count, then the instruction
//! to jump back to), 100 the end of a segment. Segment 1 starts at 1024, each next one after
//! the previous one's end code; 0x21CB says how many there are (1-32).
//!
//! Choices where seed 002 is silent: a jump address is an instruction's number (0 the first at
//! 1024; the manual's 8-bit field reaches its 256 instructions) and must lie in the jumping
//! segment; a loop's count is how many times its body runs in all (1 runs it once, so the jump
//! is not taken; 0 loops for ever), and a loop met again after it ran out counts afresh; each
//! segment starts with the manual's defaults (start and stop speed 1 rev/s, run speed
//! 10 rev/s, both ramps 100 rev/s²); the next instruction follows a move once the axis stands on
//! its target; a move that ends anywhere else (a stop, a limit, a fault, the enable) ends the
//! program. Waits are in ms.

use super::DriveState;
use super::control::SetPoint;
use super::memory::{ProgramMemory, WORDS};
use crate::controller::Shared;
use crate::modes::{Command, WorkMode};
use crate::motion::scurve::Limits;
use crate::od::{Obj, ObjError, refuse};
use crate::pdu::Words;
use crate::units::Instant;
use core::borrow::Borrow;

/// Instructions a program holds at most (§7: "at most 256 data").
pub const MAX_INSTRUCTIONS: u16 = 256;
/// Segments a program holds at most (0327).
pub const MAX_SEGMENTS: u8 = 32;
/// Counted loops one segment may hold: their counters are kept while it runs.
pub const MAX_LOOPS: usize = 8;
/// Input function 25: bit 0 of the segment an input selects (26-29 bits 1-4).
pub(crate) const INPUT_SELECT_BIT0: u32 = 25;
/// How often a running move is checked for its end, µs.
const CHECK_EVERY: u64 = 5_000;
/// Instructions one service carries out at most (a loop with neither move nor wait in it
/// yields to the bus between rounds).
const STEPS_PER_SERVICE: u16 = 64;

/// One instruction, its values in the map's units.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Instruction {
    /// Run to a position, pulses (1).
    Absolute(i32),
    /// Run by a distance, pulses (2).
    Relative(i32),
    /// Start speed, 0.01 rev/s (51).
    StartSpeed(u16),
    /// Stop speed, 0.01 rev/s (53).
    StopSpeed(u16),
    /// Run speed, 0.01 rev/s (54).
    Speed(u16),
    /// Acceleration, rev/s² (61).
    Accel(u16),
    /// Deceleration, rev/s² (62).
    Decel(u16),
    /// Wait `ms`, then go on at instruction `to` (65).
    WaitJump { to: u16, ms: u16 },
    /// Jump back to `to` until the body ran `count` times (66; 0 for ever).
    Loop { count: u16, to: u16 },
    /// The segment's end (100).
    End,
}

impl Instruction {
    /// The instruction at word `at` of the program in `memory` and its length in words; `None`
    /// for an unknown code, a value out of the manual's range, or one that runs past the
    /// program's end.
    pub(crate) fn decode(memory: &ProgramMemory, at: usize) -> Option<(Self, usize)> {
        let p = |k: usize| memory.word(at + k);
        let (code, a) = (p(0)?, p(1));
        let two = || Some((a?, p(2)?));
        let span = |lo: u16, hi: u16| a.filter(|v| (lo..=hi).contains(v));
        Some(match code {
            1 | 2 => {
                let (hi, lo) = two()?;
                let v = (u32::from(hi) << 16 | u32::from(lo)) as i32;
                (if code == 1 { Self::Absolute(v) } else { Self::Relative(v) }, 3)
            }
            51 => (Self::StartSpeed(span(1, 2000)?), 2),
            53 => (Self::StopSpeed(span(1, 2000)?), 2),
            54 => (Self::Speed(span(1, 5000)?), 2),
            61 => (Self::Accel(span(5, 10_000)?), 2),
            62 => (Self::Decel(span(5, 10_000)?), 2),
            65 => {
                let (to, ms) = two()?;
                // A (the high byte) is 0 in the manual's encoding.
                (to <= 0xFF).then_some(())?;
                (Self::WaitJump { to, ms }, 3)
            }
            66 => {
                let (count, to) = two()?;
                (Self::Loop { count, to }, 3)
            }
            100 => (Self::End, 1),
            _ => return None,
        })
    }
}

/// The speeds a segment's moves run with, in the drive's units (microsteps a second, and a
/// second squared).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Speeds {
    start: u32,
    stop: u32,
    run: u32,
    accel: u32,
    decel: u32,
}

/// What the running segment waits for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Step {
    /// Nothing: the next instruction is due.
    Next,
    /// The axis to stand on `target`; looked at next at `check`.
    Moving { target: i64, check: Instant },
    /// The time to go on at instruction `to` (`left` µs of the wait when paused).
    Waiting { until: Instant, left: u64, to: u16 },
}

/// Where a segment begins: its first word and the number of its first instruction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Start {
    word: u16,
    index: u16,
}

/// A running segment.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Run {
    /// Its number, 1-32.
    segment: u8,
    start: Start,
    /// The word and the number of the next instruction.
    at: u16,
    index: u16,
    speeds: Speeds,
    step: Step,
    paused: bool,
    /// The counted loops met: the loop instruction's number and the runs of its body left.
    loops: [(u16, u16); MAX_LOOPS],
}

/// The program's state on the bus side (the program itself is in the drive's [`ProgramMemory`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Program {
    /// Whether the register map offers programs (a program window: seed 002's); without it the
    /// program commands are refused and a save leaves the saved program as it is.
    pub(crate) offered: bool,
    /// Whether the program window holds seed 004's position data groups (`groups`) rather than
    /// seed 002's segments.
    pub(crate) groups: bool,
    /// The first segment the last check or start found in error (1-32), 0 none.
    error: u8,
    run: Option<Run>,
    /// The running chain of position data groups.
    pub(crate) chain: Option<super::groups::Chain>,
}

/// What a register map's program window holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ProgramKind {
    /// No program window.
    #[default]
    None,
    /// Seed 002's multi-segment programs.
    Segments,
    /// Seed 004's position data groups.
    Groups,
}

/// The speeds of a segment's start (§7's defaults), in microsteps at `per_rev` a revolution.
fn default_speeds(per_rev: u32) -> Option<Speeds> {
    Some(Speeds {
        start: centi_rev(100, per_rev)?,
        stop: centi_rev(100, per_rev)?,
        run: centi_rev(1000, per_rev)?,
        accel: per_rev.checked_mul(100)?,
        decel: per_rev.checked_mul(100)?,
    })
}

/// `v` × 0.01 rev/s in microsteps a second, if the drive runs that speed (150-300 000; 151 at
/// least as a start or stop speed, as 0x606B/0x606D).
fn centi_rev(v: u16, per_rev: u32) -> Option<u32> {
    let pps = u32::from(v).checked_mul(per_rev)? / 100;
    (151..=300_000).contains(&pps).then_some(pps)
}

impl Speeds {
    /// The speeds after `i`, if it sets one the drive can run.
    fn after(mut self, i: Instruction, per_rev: u32) -> Option<Self> {
        let ramp = |v: u16| per_rev.checked_mul(u32::from(v));
        match i {
            Instruction::StartSpeed(v) => self.start = centi_rev(v, per_rev)?,
            Instruction::StopSpeed(v) => self.stop = centi_rev(v, per_rev)?,
            Instruction::Speed(v) => self.run = centi_rev(v, per_rev)?,
            Instruction::Accel(v) => self.accel = ramp(v)?.min(i32::MAX as u32),
            Instruction::Decel(v) => self.decel = ramp(v)?.min(i32::MAX as u32),
            _ => {}
        }
        Some(self)
    }

    /// A move's set-point at these speeds (start and stop speeds no faster than the run's).
    fn setpoint(&self, target: i64) -> SetPoint {
        let v = self.run as f32;
        let limits = Limits { v_max: v, a_max: self.accel as f32, d_max: self.decel as f32, jerk: None };
        SetPoint { target, limits, depart: (self.start as f32).min(v), arrive: (self.stop as f32).min(v) }
    }
}

impl Run {
    /// The counter of the loop instruction `index`: found, or a free one taken with `count`.
    fn counter(&mut self, index: u16, count: u16) -> Option<&mut u16> {
        let k = self.loops.iter().position(|&(i, _)| i == index).or_else(|| {
            let free = self.loops.iter().position(|&(i, _)| i == u16::MAX)?;
            if let Some(slot) = self.loops.get_mut(free) {
                *slot = (index, count);
            }
            Some(free)
        })?;
        self.loops.get_mut(k).map(|(_, left)| left)
    }

    /// Frees the counter of the loop instruction `index`.
    fn free(&mut self, index: u16) {
        for slot in self.loops.iter_mut().filter(|(i, _)| *i == index) {
            *slot = (u16::MAX, 0);
        }
    }
}

impl<P: Borrow<Shared>, G: Borrow<ProgramMemory>> DriveState<P, G> {
    /// Sets what the register map's program window holds, at power-up.
    pub(crate) fn set_program_kind(&mut self, kind: ProgramKind) {
        self.program.offered = kind != ProgramKind::None;
        self.program.groups = kind == ProgramKind::Groups;
    }

    /// Register `k` of the program (seed 002's 1024 + k), 0 past its end or without a program.
    pub fn program_word(&self, k: usize) -> u16 {
        self.program_memory().and_then(|m| m.word(k)).unwrap_or(0)
    }

    /// Writes `words` into the program from register `k`: refused (busy) while a program runs or
    /// a save is under way, and without a program (unknown).
    pub(crate) fn write_program(&mut self, k: usize, words: &Words<'_>) -> Result<(), ObjError> {
        refuse(self.program.offered && k.saturating_add(words.len()) <= WORDS, ObjError::Unknown)?;
        refuse(self.program.run.is_none() && self.storage & super::STORAGE_SAVING == 0, ObjError::Busy)?;
        refuse(self.groups_writable(k, words.len()), ObjError::Busy)?;
        let memory = self.programs.borrow();
        for (j, w) in words.iter().enumerate() {
            memory.set_word(k + j, w);
        }
        Ok(())
    }

    /// The program's memory, for the store, if the register map offers programs.
    pub fn program_memory(&self) -> Option<&ProgramMemory> {
        self.program.offered.then(|| self.programs.borrow())
    }

    /// Where segment `segment` (1-based) begins, once segments 1..=0x21CB check: the first
    /// segment in error otherwise.
    fn locate(&self, segment: u8) -> Result<Start, u8> {
        let count = self.param(Obj::ProgramSegments).clamp(1, u32::from(MAX_SEGMENTS)) as u8;
        let (mut at, mut index) = (0usize, 0u16);
        let mut found = Start { word: 0, index: 0 };
        let (memory, per_rev) = (self.programs.borrow(), self.per_rev());
        for s in 1..=count {
            let start = Start { word: at as u16, index };
            if s == segment {
                found = start;
            }
            let mut speeds = default_speeds(per_rev).ok_or(s)?;
            let (mut loops, mut lowest, mut highest) = (0, u16::MAX, 0);
            // Walk to the end code, checking each instruction; then the jumps' targets.
            loop {
                let (i, len) = Instruction::decode(memory, at).filter(|_| index < MAX_INSTRUCTIONS).ok_or(s)?;
                speeds = speeds.after(i, per_rev).ok_or(s)?;
                if let Instruction::WaitJump { to, .. } | Instruction::Loop { to, .. } = i {
                    (lowest, highest) = (lowest.min(to), highest.max(to));
                    loops += usize::from(matches!(i, Instruction::Loop { count, .. } if count != 0));
                }
                (at, index) = (at + len, index + 1);
                if i == Instruction::End {
                    break;
                }
            }
            if loops > MAX_LOOPS || lowest < start.index || highest >= index {
                return Err(s);
            }
        }
        if segment == 0 || segment > count {
            return Err(segment);
        }
        Ok(found)
    }

    /// The segment the inputs select (1 + the bits of the inputs with functions 25-29 that are
    /// active), if an input has such a function.
    pub(crate) fn input_segment(&self) -> Option<u8> {
        let mut has = false;
        let mut bits = 0u8;
        let active = self.active_inputs();
        for k in 0..super::inputs::INPUT_FUNCTION_OBJECTS.len() {
            let f = self.input_function(k);
            if let Some(bit) = f.checked_sub(INPUT_SELECT_BIT0).filter(|&b| b < 5) {
                has = true;
                bits |= u8::from(active & (1 << k) != 0) << bit;
            }
        }
        has.then_some(bits + 1)
    }

    /// 0x21CD, 0x21CE and 0x21CF: the segment the inputs select, the one in error, the running one
    /// (0 for none).
    pub(crate) fn program_live(&self, obj: Obj) -> u32 {
        u32::from(match obj {
            Obj::ProgramInputSegment => self.input_segment().unwrap_or(0),
            Obj::ProgramErrorSegment => self.program.error,
            _ => self.program.run.map_or(0, |r| r.segment),
        })
    }

    /// Whether a program runs (paused included): motion commands other than the stops are
    /// refused meanwhile.
    pub(crate) fn program_runs(&self) -> bool {
        self.program.run.is_some() || self.program.chain.is_some()
    }

    /// Checks the program commands 14-18 of the motion command.
    pub(crate) fn check_program_command(&self, command: Command) -> Result<(), ObjError> {
        refuse(self.program.offered, ObjError::Unsupported)?;
        if self.program.groups {
            return match command {
                Command::ProgramStart => self.check_group_start(),
                Command::ProgramStep => self.check_group_step(),
                Command::ProgramEnd => Ok(()),
                _ => Err(ObjError::Unsupported),
            };
        }
        refuse(command != Command::ProgramStep, ObjError::Unsupported)?;
        match command {
            // As 0x200F = 2.
            Command::ProgramSave => {
                refuse(self.can_save, ObjError::Unsupported)?;
                refuse(self.ctl.axis.is_still() && self.storage & super::STORAGE_SAVING == 0, ObjError::Busy)
            }
            Command::ProgramStart if !self.program.run.is_some_and(|r| r.paused) => {
                refuse(self.program.run.is_none(), ObjError::Busy)?;
                refuse(!matches!(self.mode(), WorkMode::Pvt | WorkMode::Follow), ObjError::NotNow)?;
                refuse(self.ctl.axis.is_still(), ObjError::Busy)?;
                // The program itself is checked when it starts (`program_start`).
                self.may_move()
            }
            Command::ProgramStart => self.may_move(),
            _ => Ok(()),
        }
    }

    /// The segment a start runs: the inputs', or else 0x21CC's.
    fn selected_segment(&self) -> u8 {
        self.input_segment().unwrap_or(self.param(Obj::ProgramSelect) as u8 + 1)
    }

    /// Carries out the program command `command`, which
    /// [`DriveState::check_program_command`] accepted: a start is refused (04) if the program
    /// has a segment in error, which a check and a refused start report in 0x21CE.
    pub(crate) fn program_command(&mut self, command: Command) -> Result<(), ObjError> {
        if self.program.groups {
            match command {
                Command::ProgramStart => return self.group_start(),
                Command::ProgramStep => self.group_step(),
                Command::ProgramEnd if self.program.chain.take().is_some() => {
                    let decel = self.param(Obj::PpDecel);
                    self.ctl.axis.stop_ramp(decel);
                }
                _ => {}
            }
            return Ok(());
        }
        match command {
            Command::ProgramCheck => self.program.error = self.locate(1).err().unwrap_or(0),
            Command::ProgramSave => self.apply(Obj::SystemControl, 2),
            Command::ProgramStart => return self.program_start(),
            Command::ProgramPause => {
                let now = self.now;
                if let Some(run) = self.program.run.as_mut().filter(|r| !r.paused) {
                    run.paused = true;
                    if let Step::Waiting { until, left, .. } = &mut run.step {
                        *left = until.since(now);
                    }
                    let decel = run.speeds.decel;
                    self.ctl.axis.stop_ramp(decel);
                }
            }
            Command::ProgramEnd => {
                if let Some(run) = self.program.run.take() {
                    self.ctl.axis.stop_ramp(run.speeds.decel);
                }
            }
            _ => {}
        }
        Ok(())
    }

    /// Starts the selected segment, or resumes a paused one; refused if a segment is in error.
    fn program_start(&mut self) -> Result<(), ObjError> {
        let now = self.now;
        if let Some(run) = self.program.run.as_mut() {
            run.paused = false;
            match &mut run.step {
                Step::Waiting { until, left, .. } => *until = now.plus_micros(*left),
                // The move it stopped in is made again, to its target.
                Step::Moving { target, .. } => {
                    let target = *target;
                    run.step = Step::Next;
                    self.program_move(target);
                }
                Step::Next => {}
            }
            return Ok(());
        }
        let segment = self.selected_segment();
        match self.locate(segment) {
            Ok(start) => {
                self.program.error = 0;
                let speeds = default_speeds(self.per_rev());
                self.program.run = speeds.map(|speeds| Run {
                    segment,
                    start,
                    at: start.word,
                    index: start.index,
                    speeds,
                    step: Step::Next,
                    paused: false,
                    loops: [(u16::MAX, 0); MAX_LOOPS],
                });
                Ok(())
            }
            Err(s) => {
                self.program.error = s;
                Err(ObjError::NotNow)
            }
        }
    }

    /// Ends the program (a stop, a fault, a disable): the motion already stopping is theirs.
    pub(crate) fn program_stopped(&mut self) {
        (self.program.run, self.program.chain) = (None, None);
    }

    /// When [`DriveState::program_service`] has something to do.
    pub(crate) fn program_due(&self) -> Option<Instant> {
        if self.program.chain.is_some() {
            return self.groups_due();
        }
        let run = self.program.run.filter(|r| !r.paused)?;
        Some(match run.step {
            Step::Next => self.now,
            Step::Moving { check, .. } => check,
            Step::Waiting { until, .. } => until,
        })
    }

    /// Runs the program on: the next instructions up to a move or a wait, the end of a move,
    /// the end of a wait.
    pub(crate) fn program_service(&mut self) {
        if self.program.chain.is_some() {
            return self.groups_service();
        }
        for _ in 0..STEPS_PER_SERVICE {
            let Some(mut run) = self.program.run.filter(|r| !r.paused) else { return };
            match run.step {
                Step::Moving { target, .. } => {
                    if !self.ctl.axis.is_still() {
                        run.step = Step::Moving { target, check: self.now.plus_micros(CHECK_EVERY) };
                        self.program.run = Some(run);
                        return;
                    }
                    // Stopped anywhere else, by a stop, a limit, a fault or the enable: over.
                    if self.ctl.axis.setpoint().whole != target {
                        self.program.run = None;
                        return;
                    }
                    run.step = Step::Next;
                }
                Step::Waiting { until, to, .. } => {
                    if self.now < until {
                        return;
                    }
                    run.step = Step::Next;
                    self.jump(&mut run, to);
                }
                Step::Next => {
                    let Some((i, len)) = Instruction::decode(self.programs.borrow(), usize::from(run.at)) else {
                        // Changed under the run (it cannot be): end it rather than guess.
                        self.program.run = None;
                        return;
                    };
                    (run.at, run.index) = (run.at + len as u16, run.index + 1);
                    let here = self.ctl.axis.setpoint().whole;
                    match i {
                        Instruction::Absolute(p) => run.step = Step::Moving { target: i64::from(p), check: self.now },
                        Instruction::Relative(d) => {
                            run.step = Step::Moving { target: here.saturating_add(i64::from(d)), check: self.now };
                        }
                        Instruction::WaitJump { to, ms } => {
                            run.step = Step::Waiting { until: self.now.plus_micros(u64::from(ms) * 1000), left: 0, to };
                        }
                        Instruction::Loop { count, to } => {
                            let index = run.index - 1;
                            // 0 loops for ever, with no counter.
                            let jump = count == 0
                                || match run.counter(index, count) {
                                    Some(left) if *left > 1 => {
                                        *left -= 1;
                                        true
                                    }
                                    _ => false,
                                };
                            if jump {
                                self.jump(&mut run, to);
                            } else {
                                run.free(index);
                            }
                        }
                        Instruction::End => {
                            self.program.run = None;
                            return;
                        }
                        set => run.speeds = run.speeds.after(set, self.per_rev()).unwrap_or(run.speeds),
                    }
                    self.program.run = Some(run);
                    if let Step::Moving { target, .. } = run.step
                        && target != here
                        && !self.program_move(target)
                    {
                        return;
                    }
                    continue;
                }
            }
            self.program.run = Some(run);
        }
    }

    /// Goes on at instruction `to` of the running segment (checked to lie in it).
    fn jump(&self, run: &mut Run, to: u16) {
        let (mut at, mut index) = (usize::from(run.start.word), run.start.index);
        while index < to {
            let Some((_, len)) = Instruction::decode(self.programs.borrow(), at) else { break };
            (at, index) = (at + len, index + 1);
        }
        (run.at, run.index) = (at as u16, index);
    }

    /// Plans the running segment's move to `target` and waits for it; a move the drive refuses
    /// ends the program (false).
    fn program_move(&mut self, target: i64) -> bool {
        let Some(run) = self.program.run else { return false };
        match self.plan_program_move(&run.speeds.setpoint(target)) {
            Ok(target) => {
                self.pp = super::control::Pp::default();
                if let Some(r) = self.program.run.as_mut() {
                    r.step = Step::Moving { target, check: self.now.plus_micros(CHECK_EVERY) };
                }
                true
            }
            Err(_) => {
                self.program.run = None;
                false
            }
        }
    }
}
