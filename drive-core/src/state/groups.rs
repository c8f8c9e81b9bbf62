//! Position data groups (seed 004's 05F0h-06FFh): up to 32 moves a master stores, each with a
//! target, a speed, the conditions on which the chain steps on and the group it steps to, run
//! one after the other on the bus side; each move is planned as a motion command's is. The
//! groups are kept in the programs' memory ([`ProgramMemory`]), eight words a group:
//!
//! | word | meaning |
//! |---|---|
//! | 0, 1 | target, low word first, in the groups' unit (0x219B / 0x219C microsteps) |
//! | 2 | speed, r/min (1-6000 for a move) |
//! | 3 | step-change attribute: bits 0-3 condition 1, bits 4-7 condition 2, bit 8 either (else both) |
//! | 4, 5 | condition 1's and condition 2's value |
//! | 6 | next group, 0-31 |
//! | 7 | type: 0 none, 1 absolute, 2 relative |
//!
//! A condition is 0 none, 1 arrival (the move ended on its target), 2 a time after arrival
//! (its value in ms), 3 an input active after arrival (its value 1-7 IN1-IN7, 8-23 bit 0-15 of
//! the communication IO 0x2193). Once the move has arrived, the chain steps on to the next group
//! when its conditions hold (both, or either with bit 8); a group with no condition, or a next
//! group of type none, ends the chain there. POS-START (the program start, 0x21A0 = 16) runs the
//! selected group: the inputs with the segment-select functions 25-27, or else the
//! communication IO's POS0-2; POS-STEP (0x21A0 = 19) steps on at once from a group that waits
//! after its arrival. A stop, a fault or the enable ends the chain.

use super::DriveState;
use super::control::SetPoint;
use super::memory::ProgramMemory;
use crate::controller::Shared;
use crate::motion::scurve::Limits;
use crate::od::{Obj, ObjError, refuse};
use crate::units::Instant;
use core::borrow::Borrow;

/// Groups the memory holds.
pub const GROUPS: u8 = 32;
/// Words a group takes.
pub const GROUP_WORDS: usize = 8;
/// The groups' words, from the first (05F0h's window starts at 0600h).
pub const WORDS: usize = GROUPS as usize * GROUP_WORDS;
/// The highest group speed, r/min.
pub const MAX_RPM: u16 = 6000;
/// How often a move or an input condition is checked, µs.
const CHECK_EVERY: u64 = 5_000;

/// `n / d` rounded to the nearest, halves away from zero (`d` > 0).
fn div_round(n: i64, d: i64) -> i64 {
    let half = d / 2;
    if n >= 0 { (n + half) / d } else { (n - half) / d }
}

/// A condition of a group's step change.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Condition {
    None,
    Arrival,
    /// Milliseconds after the arrival.
    After(u16),
    /// 1-7 IN1-IN7; 8-23 bit 0-15 of 0x2193.
    Input(u16),
}

impl Condition {
    fn of(kind: u16, value: u16) -> Option<Self> {
        Some(match kind {
            0 => Self::None,
            1 => Self::Arrival,
            2 => Self::After(value),
            3 if (1..=23).contains(&value) => Self::Input(value),
            _ => return None,
        })
    }
}

/// Whether `value` may be word `k` of the groups (a write's check: a value out of its range is
/// refused, 03).
pub fn word_ok(k: usize, value: u16) -> bool {
    match k % GROUP_WORDS {
        2 => value <= MAX_RPM,
        3 => value & !0x01FF == 0 && value & 0xF <= 3 && value >> 4 & 0xF <= 3,
        6 => value < u16::from(GROUPS),
        7 => value <= 2,
        _ => true,
    }
}

/// A group, decoded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Group {
    target: i32,
    rpm: u16,
    conditions: [Condition; 2],
    either: bool,
    next: u8,
    relative: bool,
}

impl Group {
    /// Group `g` of `memory`; `None` if its type is none or a word is out of its range.
    fn read(memory: &ProgramMemory, g: u8) -> Option<Self> {
        let at = usize::from(g) * GROUP_WORDS;
        let w = |k: usize| memory.word(at + k).filter(|&v| word_ok(k, v));
        let (lo, hi, rpm, attr, next, kind) = (w(0)?, w(1)?, w(2)?, w(3)?, w(6)?, w(7)?);
        let conditions = [Condition::of(attr & 0xF, w(4)?)?, Condition::of(attr >> 4 & 0xF, w(5)?)?];
        let relative = match kind {
            1 => false,
            2 => true,
            _ => return None,
        };
        let target = (u32::from(hi) << 16 | u32::from(lo)) as i32;
        Some(Self { target, rpm, conditions, either: attr & 0x100 != 0, next: next as u8, relative })
    }
}

/// What the running group waits for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Step {
    /// Its move to end on `target`; looked at next at `check`.
    Moving { target: i64, check: Instant },
    /// Its conditions, since it arrived at `since`; an input's looked at next at `check`.
    Arrived { since: Instant, check: Instant },
}

/// A running chain of groups.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Chain {
    group: u8,
    step: Step,
}

impl<P: Borrow<Shared>, G: Borrow<ProgramMemory>> DriveState<P, G> {
    /// The group a start runs: the inputs' segment-select bits 0-2, or else POS0-2.
    fn selected_group(&self) -> u8 {
        match self.input_segment() {
            Some(s) => (s - 1) & 0b111,
            None => self.comm_group(),
        }
    }

    /// 0x2198-0x219A: the running group, the next one, where the selection comes from.
    pub(crate) fn groups_live(&self, obj: Obj) -> u32 {
        let memory = self.programs.borrow();
        let chain = self.program.chain;
        match obj {
            Obj::GroupRunning => chain.map_or(0xFFFF, |c| u32::from(c.group)),
            Obj::GroupNext => match chain {
                Some(c) => Group::read(memory, c.group)
                    .and_then(|g| Group::read(memory, g.next).map(|_| u32::from(g.next)))
                    .unwrap_or(0xFFFF),
                None => u32::from(self.selected_group()),
            },
            _ => u32::from(self.input_segment().is_some()),
        }
    }

    /// Checks a start of the selected group (0x21A0 = 16 where the map has groups).
    pub(crate) fn check_group_start(&self) -> Result<(), ObjError> {
        refuse(self.program.chain.is_none() && self.ctl.axis.is_still(), ObjError::Busy)?;
        self.may_move()?;
        let g = Group::read(self.programs.borrow(), self.selected_group()).ok_or(ObjError::NotNow)?;
        self.group_setpoint(&g).map(|_| ())
    }

    /// Checks a step on (0x21A0 = 19): a group must wait after its arrival.
    pub(crate) fn check_group_step(&self) -> Result<(), ObjError> {
        let waits = matches!(self.program.chain, Some(Chain { step: Step::Arrived { .. }, .. }));
        refuse(self.program.groups && waits, ObjError::NotNow)
    }

    /// Starts the selected group; refused (nothing moves) if it cannot run.
    pub(crate) fn group_start(&mut self) -> Result<(), ObjError> {
        self.run_group(self.selected_group())
    }

    /// Steps on from the waiting group at once.
    pub(crate) fn group_step(&mut self) {
        if let Some(c) = self.program.chain {
            self.step_on(c.group);
        }
    }

    /// The set-point of group `g`'s move from where the axis stands.
    fn group_setpoint(&self, g: &Group) -> Result<SetPoint, ObjError> {
        let (num, den) = (i64::from(self.param(Obj::GearNumerator)), i64::from(self.param(Obj::GearDenominator)));
        let distance = div_round(i64::from(g.target) * num, den.max(1));
        let here = self.ctl.axis.setpoint().whole;
        let target = if g.relative { here.saturating_add(distance) } else { distance };
        let pps = u64::from(g.rpm) * u64::from(self.per_rev()) / 60;
        refuse((150..=300_000).contains(&pps), ObjError::OutOfRange)?;
        let v = pps as f32;
        let limits = Limits {
            v_max: v,
            a_max: self.param(Obj::PpAccel) as f32,
            d_max: self.param(Obj::PpDecel) as f32,
            jerk: None,
        };
        let (start, stop) = (self.param(Obj::PpStartSpeed) as f32, self.param(Obj::PpStopSpeed) as f32);
        Ok(SetPoint { target, limits, depart: start.min(v), arrive: stop.min(v) })
    }

    /// Runs group `g`'s move; the chain ends if it cannot.
    fn run_group(&mut self, g: u8) -> Result<(), ObjError> {
        let planned = Group::read(self.programs.borrow(), g)
            .ok_or(ObjError::NotNow)
            .and_then(|group| self.group_setpoint(&group))
            .and_then(|sp| self.plan_program_move(&sp));
        match planned {
            Ok(target) => {
                self.pp = super::control::Pp::default();
                let check = self.now.plus_micros(CHECK_EVERY);
                self.program.chain = Some(Chain { group: g, step: Step::Moving { target, check } });
                Ok(())
            }
            Err(e) => {
                self.program.chain = None;
                Err(e)
            }
        }
    }

    /// Goes on from group `g` with its next one, or ends the chain.
    fn step_on(&mut self, g: u8) {
        let memory = self.programs.borrow();
        match Group::read(memory, g).filter(|group| Group::read(memory, group.next).is_some()) {
            Some(group) => {
                let _ = self.run_group(group.next);
            }
            None => self.program.chain = None,
        }
    }

    /// Whether `condition` holds `elapsed` µs after the arrival.
    fn holds(&self, condition: Condition, elapsed: u64) -> Option<bool> {
        Some(match condition {
            Condition::None => return None,
            Condition::Arrival => true,
            Condition::After(ms) => elapsed >= u64::from(ms) * 1000,
            Condition::Input(k @ 1..=7) => self.input_level_active(usize::from(k - 1)),
            Condition::Input(k) => self.param(Obj::CommInputs) & (1 << (k - 8)) != 0,
        })
    }

    /// Whether IN k+1 is active: its pin's level (0x6031, which shows an input's level
    /// inverted) at 0x21C1's polarity, or its pseudo-input; whether or not it has a function.
    fn input_level_active(&self, k: usize) -> bool {
        let pin = crate::controller::io::IN_PINS.get(k).copied().unwrap_or(0);
        let high = self.ctl.status.gpio & pin == 0;
        let low_active = self.param(Obj::InputLogic) & (1 << k) != 0;
        (high != low_active) || self.param(Obj::PseudoInputs) & (1 << k) != 0
    }

    /// When [`DriveState::groups_service`] has something to do.
    pub(crate) fn groups_due(&self) -> Option<Instant> {
        let chain = self.program.chain?;
        Some(match chain.step {
            Step::Moving { check, .. } => check,
            Step::Arrived { since, check } => {
                let g = Group::read(self.programs.borrow(), chain.group)?;
                // A wait on time alone is due at its end; one on an input is polled.
                let at = |c: Condition| match c {
                    Condition::After(ms) => Some(since.plus_micros(u64::from(ms) * 1000)),
                    Condition::Input(_) => Some(check),
                    _ => None,
                };
                g.conditions.iter().filter_map(|&c| at(c)).min().unwrap_or(self.now)
            }
        })
    }

    /// Runs the chain on: a move's end, the conditions after it.
    pub(crate) fn groups_service(&mut self) {
        let Some(mut chain) = self.program.chain else { return };
        match chain.step {
            Step::Moving { target, .. } => {
                if !self.ctl.axis.is_still() {
                    chain.step = Step::Moving { target, check: self.now.plus_micros(CHECK_EVERY) };
                    self.program.chain = Some(chain);
                    return;
                }
                // Stopped anywhere else, by a stop, a limit, a fault or the enable: over.
                if self.ctl.axis.setpoint().whole != target {
                    self.program.chain = None;
                    return;
                }
                chain.step = Step::Arrived { since: self.now, check: self.now };
                self.program.chain = Some(chain);
                self.groups_service();
            }
            Step::Arrived { since, .. } => {
                let Some(g) = Group::read(self.programs.borrow(), chain.group) else {
                    self.program.chain = None;
                    return;
                };
                let elapsed = self.now.since(since);
                let [a, b] = g.conditions.map(|c| self.holds(c, elapsed));
                let go = match (a, b) {
                    (None, None) => {
                        // No condition: the chain ends with this group.
                        self.program.chain = None;
                        return;
                    }
                    (Some(x), None) | (None, Some(x)) => x,
                    (Some(x), Some(y)) => {
                        if g.either {
                            x || y
                        } else {
                            x && y
                        }
                    }
                };
                if go {
                    self.step_on(chain.group);
                } else {
                    chain.step = Step::Arrived { since, check: self.now.plus_micros(CHECK_EVERY) };
                    self.program.chain = Some(chain);
                }
            }
        }
    }

    /// Whether the groups' words `k..k + n` may be written now: not the running group's.
    pub(crate) fn groups_writable(&self, k: usize, n: usize) -> bool {
        self.program.chain.is_none_or(|c| {
            let at = usize::from(c.group) * GROUP_WORDS;
            k + n <= at || k >= at + GROUP_WORDS
        })
    }
}
