//! PVT mode (seed 000 §5.10), synchronous positioning (§5.9) and group starts (0x200E).
//!
//! Points are written to 0x6027..0x602C and pushed with 0x6017 = 2 (or, with 0x2112 = 1, by
//! completing the time 0x602B..2C, so one 0x10 write of six registers is one point). Between
//! points the position follows the cubic Hermite polynomial of the two points' positions and
//! velocities ([`crate::motion::cubic`]), evaluated exactly at every control tick.
//!
//! Decisions where the manual is silent:
//! - **The first point of a run** is reached from where the axis stands, at rest, in the point's
//!   time; its time may be 0 only if the axis already stands on it. Only the first point pushed
//!   (after a clear) may have time 0, and a mode 2 loop of that point alone is refused, so a
//!   run never has more than a few segments of no time in a row (all pass in one tick).
//! - **Storage.** Modes 1 and 2 append pushed points at indices 0, 1, ... (0x601B-0x6023 index
//!   them, inclusive); mode 3 is a ring over the same 1000 slots, each point leaving it when its
//!   segment starts. The capacity is 0x6019 in modes 1 and 2 and the FIFO depth 0x6024 in mode 3
//!   (0 in either: the whole table, 1000). 0x2110 says how many points are stored or queued.
//!   Changing the PVT mode 0x6018 clears the points; 0x6018 and a clear (0x6017 = 3) are refused
//!   while a run is active.
//! - **Infeasible points are refused**, with exception 04 and nothing stored: a point whose
//!   segment from the previously pushed point would move faster than 200 kpps somewhere (the
//!   manual's top speed), or that takes no time and is not the first point. A start
//!   is refused (04) when the drive cannot move (disabled, an error or stop bit, already moving),
//!   0x6007 is not 2, the run's indices lie outside the stored points, a junction between phases
//!   of mode 2 or the approach to the first point is infeasible, or (modes 1 and 2) the last
//!   point's velocity is not 0.
//! - **Mode 2** runs the acceleration phase once, the loop phase 0x6021 times (0: not at all), the
//!   deceleration phase once; each phase from its start index to its end index inclusive.
//! - **End of a run, underflow.** A run ends when no point follows. On a point of velocity 0 the
//!   axis stands exactly on it. Otherwise (mode 3: the FIFO ran dry while moving) it is an
//!   underflow: 0x2111 bit 0 is set and the axis decelerates from the point's velocity to rest
//!   with the deceleration of 0x600B (a trapezoid: the segment's acceleration may be beyond what
//!   the S-curve's jerk could take back soon), with no jump in position or velocity.
//! - Controller status bits 5-7 (FIFO empty, below the low mark, above the high mark) show the
//!   FIFO's state in mode 3 (0x6018 = 2) and are 0 otherwise; writing 1 to them does nothing.
//! - 0x6017 = 0 stops a run by decelerating as an underflow does (0x6053 stops at once).
//! - 0x601A reads the table index of the point the running segment heads to.
//!
//! **Group start.** Writing a group number g (1-127) to 0x2113, by broadcast (address 0) or to one
//! drive, starts every drive whose group id 0x200E is g: in PVT mode (0x6007 = 2) its PVT run, in
//! position mode (0x6007 = 0) the synchronous move to 0x6049..4A at the speed 0x6047..48 (§5.9),
//! with the S-curve of the position mode. One broadcast frame, `00 06 21 13 00 gg CRC`, starts a
//! whole group. Drives of other groups (and of group 0) ignore it; a member that cannot start
//! refuses it as a start would (04, or nothing if broadcast). 0x2114 = g stops the group as
//! 0x6017 = 0 does. Any start, including 0x6017 = 1, takes effect at the first control tick the
//! plan margin after the frame (the next tick where the tick is not apart), so every drive that
//! receives one frame starts in the same tick.

use super::DriveState;
use super::memory::ProgramMemory;
use crate::controller::Shared;
use crate::controller::handoff::RunOrder;
use crate::controller::run::{Phase, Source};
use crate::modes::{PvtMode, WorkMode};
use crate::motion::axis::Axis;
use crate::motion::cubic::{Cubic, Point, TABLE_SIZE, V_MAX};
use crate::od::{Obj, ObjError, refuse};
use crate::units::Instant;
use core::borrow::Borrow;

pub use crate::controller::run::{FAULT_UNDERFLOW, STATUS_FIFO_EMPTY, STATUS_FIFO_HIGH, STATUS_FIFO_LOW};

/// The 0x6017 operations.
const OP_STOP: u32 = 0;
const OP_START: u32 = 1;
const OP_PUSH: u32 = 2;
const OP_CLEAR: u32 = 3;

/// What a start begins, on the next control tick.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Start {
    /// The PVT run of 0x6018.
    Pvt,
    /// The synchronous move of 0x6047/0x6049.
    Sync,
}

/// What an accepted PVT write does.
#[derive(Clone, Copy, Debug)]
enum Effect {
    None,
    Push(Point),
    Clear,
    Start(Start),
    /// Decelerate to rest from what the axis does now.
    Stop,
}

impl<P: Borrow<Shared>, G: Borrow<ProgramMemory>> DriveState<P, G> {
    fn pvt_mode(&self) -> PvtMode {
        PvtMode::from_raw(self.param(Obj::PvtMode)).unwrap_or_default()
    }

    /// How many points may be stored now.
    fn capacity(&self) -> u16 {
        let limit = if self.pvt_mode() == PvtMode::Fifo {
            self.param(Obj::PvtFifoDepth)
        } else {
            self.param(Obj::PvtMaxPoints)
        };
        if limit == 0 { TABLE_SIZE as u16 } else { limit.min(TABLE_SIZE as u32) as u16 }
    }

    /// The stored point `i` of the table (modes 1, 2) or the ring's `i`-th slot.
    fn stored(&self, i: u16) -> Option<Point> {
        self.shared.borrow().table.get(usize::from(i))
    }

    /// The point in the PVT registers 0x6027..0x602C.
    fn point_registers(&self) -> Point {
        Point {
            position: self.param(Obj::PvtPosition) as i32,
            velocity: self.param(Obj::PvtVelocity) as i32,
            time_ms: self.param(Obj::PvtTime) as u16,
        }
    }

    /// Controller status bits 5-7 (mode 3 only).
    pub(crate) fn fifo_status(&self) -> u8 {
        if self.pvt_mode() != PvtMode::Fifo {
            return 0;
        }
        let n = u32::from(self.pvt.len);
        let bit = |on: bool, b: u8| if on { b } else { 0 };
        bit(n == 0, STATUS_FIFO_EMPTY)
            | bit(n < self.param(Obj::PvtFifoLow), STATUS_FIFO_LOW)
            | bit(n > self.param(Obj::PvtFifoHigh), STATUS_FIFO_HIGH)
    }

    /// Whether `p` may be pushed now.
    fn check_push(&self, p: Point) -> Result<(), ObjError> {
        refuse(self.pvt.len < self.capacity(), ObjError::NotNow)?;
        refuse((p.velocity as f32).abs() <= V_MAX, ObjError::Infeasible)?;
        match self.pvt.last {
            // Only a first point may take no time (a run's start where the axis stands).
            Some(prev) => refuse(p.time_ms > 0 && Cubic::between(prev, p).feasible(), ObjError::Infeasible),
            None => Ok(()),
        }
    }

    /// The source and first point of the run that a start would begin now, or why not.
    fn plan_run(&self) -> Result<(Source, u16, Point), ObjError> {
        refuse(self.mode() == WorkMode::Pvt, ObjError::NotNow)?;
        self.may_move()?;
        refuse(self.ctl.axis.is_still() && self.ctl.run.is_none(), ObjError::Busy)?;
        let len = self.pvt.len;
        let (source, first) = if self.pvt_mode() == PvtMode::Fifo {
            refuse(len > 0, ObjError::NotNow)?;
            (Source::Fifo, self.pvt.head)
        } else {
            let p = |a, b, n| Phase::new(self.param(a), self.param(b), n);
            let phases = if self.pvt_mode() == PvtMode::Single {
                [p(Obj::PvtM1Start, Obj::PvtM1End, 1), Phase::default(), Phase::default()]
            } else {
                [
                    p(Obj::PvtM2AccStart, Obj::PvtM2AccEnd, 1),
                    p(Obj::PvtM2LoopStart, Obj::PvtM2LoopEnd, self.param(Obj::PvtM2Loops)),
                    p(Obj::PvtM2DecStart, Obj::PvtM2DecEnd, 1),
                ]
            };
            for ph in phases.iter().filter(|ph| ph.times > 0) {
                refuse(ph.first <= ph.last && ph.last < len, ObjError::NotNow)?;
            }
            // Points within a phase follow each other in the table, checked when pushed; the
            // junctions between phases are checked here.
            let at = |i: u16| self.stored(i).ok_or(ObjError::NotNow);
            let joins = |a: u16, b: u16| -> Result<(), ObjError> {
                refuse(Cubic::between(at(a)?, at(b)?).feasible(), ObjError::Infeasible)
            };
            let [acc, lp, dec] = phases;
            let last = if self.pvt_mode() == PvtMode::Single {
                acc.last
            } else {
                if lp.times > 0 {
                    // A loop of no time would pass its points endlessly within one tick.
                    refuse(lp.first < lp.last || at(lp.first)?.time_ms > 0, ObjError::NotNow)?;
                    joins(acc.last, lp.first)?;
                    joins(lp.last, dec.first)?;
                    if lp.times > 1 {
                        joins(lp.last, lp.first)?;
                    }
                } else {
                    joins(acc.last, dec.first)?;
                }
                dec.last
            };
            refuse(at(last)?.velocity == 0, ObjError::NotNow)?;
            (Source::table(phases), acc.first)
        };
        let p = self.stored(first).ok_or(ObjError::NotNow)?;
        refuse(Cubic::new(self.ctl.axis.setpoint().whole, 0, p).feasible(), ObjError::Infeasible)?;
        Ok((source, first, p))
    }

    /// Plans on `axis` (a copy of the drive's) the synchronous move that a start would begin
    /// now, or says why not (and `axis` is to be dropped).
    fn plan_sync(&self, now: Instant, axis: &mut Axis) -> Result<(), ObjError> {
        let planner = self.planner();
        let speed = (self.param(Obj::SyncSpeed) as i32) as f32;
        refuse(self.mode() == WorkMode::Position && speed != 0.0, ObjError::NotNow)?;
        planner.may_move?;
        refuse(self.ctl.axis.is_still(), ObjError::Busy)?;
        let target = i64::from(self.param(Obj::SyncPosition) as i32);
        let (depart, arrive) = planner.jumps(speed.abs());
        axis.move_to(now, target, depart, arrive, &planner.scurve_limits(speed)).map_err(|_| ObjError::Infeasible)
    }

    /// Whether the synchronous move can start now: planned on a copy of the axis. Out of line,
    /// as every copy of the axis (1 KB) in the write path: its frame is on the stack for this
    /// call only.
    #[inline(never)]
    fn check_sync(&self) -> Result<(), ObjError> {
        let mut scratch = self.ctl.axis;
        self.plan_sync(self.plan_time(), &mut scratch)
    }

    /// Starts the synchronous move, which [`DriveState::check_sync`] accepted. Out of line, as
    /// [`DriveState::check_sync`].
    #[inline(never)]
    fn start_sync(&mut self) {
        let mut axis = self.ctl.axis;
        if self.plan_sync(self.plan_time(), &mut axis).is_ok() {
            self.ctl.axis = axis;
        }
    }

    /// What a start (0x6017 = 1, or a group start) does in the present work mode.
    fn plan_start(&self) -> Result<Effect, ObjError> {
        match self.mode() {
            WorkMode::Pvt => self.plan_run().map(|_| Effect::Start(Start::Pvt)),
            WorkMode::Position => self.check_sync().map(|()| Effect::Start(Start::Sync)),
            _ => Err(ObjError::NotNow),
        }
    }

    /// What writing `value` to the PVT object `obj` does, or why it is refused.
    fn plan_pvt(&self, obj: Obj, value: u32) -> Result<Effect, ObjError> {
        let running = self.ctl.run.is_some();
        let member = self.param(Obj::GroupId) != 0 && self.param(Obj::GroupId) == value;
        match (obj, value) {
            (Obj::PvtControl, OP_STOP) => Ok(self.stop_effect()),
            (Obj::PvtControl, OP_START) => self.plan_start(),
            (Obj::PvtControl, OP_PUSH) => {
                self.check_push(self.point_registers()).map(|()| Effect::Push(self.point_registers()))
            }
            (Obj::PvtControl, OP_CLEAR) | (Obj::PvtMode, _) if running => Err(ObjError::Busy),
            (Obj::PvtControl, _) => Ok(Effect::Clear),
            (Obj::PvtMode, v) if PvtMode::from_raw(v) != Some(self.pvt_mode()) => Ok(Effect::Clear),
            (Obj::PvtTime, _) if self.param(Obj::PvtAutoPush) == 1 => {
                let p = Point { time_ms: value as u16, ..self.point_registers() };
                self.check_push(p).map(|()| Effect::Push(p))
            }
            (Obj::GroupStart, _) if member => self.plan_start(),
            (Obj::GroupStop, _) if member => Ok(self.stop_effect()),
            _ => Ok(Effect::None),
        }
    }

    fn stop_effect(&self) -> Effect {
        let moving = self.ctl.run.is_some() || (self.mode() == WorkMode::Position && !self.ctl.axis.is_still());
        if moving { Effect::Stop } else { Effect::None }
    }

    /// Checks a write to a PVT object.
    pub(crate) fn check_pvt(&self, obj: Obj, value: u32) -> Result<(), ObjError> {
        self.plan_pvt(obj, value).map(|_| ())
    }

    /// Writes a PVT object, which [`DriveState::check_pvt`] accepted.
    pub(crate) fn apply_pvt(&mut self, obj: Obj, value: u32) {
        let effect = self.plan_pvt(obj, value);
        self.set_param(obj, value);
        // A start is planned here, on the bus side: the motion starts on the next control tick.
        match effect {
            Ok(Effect::Start(Start::Sync)) => return self.start_sync(),
            Ok(Effect::Start(Start::Pvt)) => return self.start_run(),
            _ => {}
        }
        let pvt = &mut self.pvt;
        match effect {
            Ok(Effect::Push(p)) => {
                let slot = (usize::from(pvt.head) + usize::from(pvt.len)) % TABLE_SIZE;
                self.shared.borrow().table.set(slot, p);
                pvt.len += 1;
                pvt.last = Some(p);
                self.orders.pushed = self.orders.pushed.saturating_add(1);
            }
            Ok(Effect::Clear) => {
                (pvt.head, pvt.len, pvt.last) = (0, 0, None);
                self.orders.set_queue(pvt);
            }
            Ok(Effect::Start(_)) => {}
            Ok(Effect::Stop) => {
                self.end_run();
                // The tick stops from where its axis is when the order arrives.
                self.orders.stop = true;
                // 0x600B's ramp, without its jerk limit: a PVT segment may end with more
                // acceleration than the jerk could take back in time.
                self.ctl.axis.stop_ramp(self.settings.stop_decel);
            }
            Ok(Effect::None) | Err(_) => {}
        }
    }

    /// Starts the PVT run on the next control tick: its first segment from where the axis
    /// stands (built here, not in the tick).
    fn start_run(&mut self) {
        let Ok((source, _, _)) = self.plan_run() else { return };
        self.ctl.start_run(self.plan_time(), source, &mut self.pvt, &self.shared.borrow().table);
        if let Some(run) = self.ctl.run {
            self.orders.run = Some(RunOrder::Start(run, self.ctl.status.pvt_pointer));
            self.orders.set_queue(&self.pvt);
        }
    }

    /// Ends the PVT run, if one runs: here, and by an order to the tick.
    pub(crate) fn end_run(&mut self) {
        if self.ctl.run.take().is_some() {
            self.orders.run = Some(RunOrder::End);
        }
    }
}
