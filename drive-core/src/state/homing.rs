//! The built-in homing (our objects 0x2160..0x216D), with CiA 402's method numbers, for the
//! native map and for the compatibility maps' own homing objects.
//!
//! A homing is a few steps, each a constant-speed move towards a condition the control tick
//! watches for (a switch's level, the encoder's index pulse, a stall at a hard stop). The bus
//! side plans each step and arms its [`Watch`]; the tick, when the condition holds, notes the
//! setpoint's position there, stops the axis and raises [`Events::CAUGHT`]; the bus side then
//! plans the next step from wherever the axis is stopping. After the last step, standing, the
//! position is declared so that the last caught position is the homing offset 0x2169.
//!
//! Methods (0x2160; CiA 402 numbers, signed 16-bit):
//!
//! | method | reference | home at | final approach |
//! |---|---|---|---|
//! | 17 / 18 | negative / positive limit switch | where it releases | positive / negative |
//! | 19 / 20 | home switch active above home | its edge | negative / positive |
//! | 21 / 22 | home switch active below home | its edge | positive / negative |
//! | 1-6 | as 17, 18, 19, 20, 21, 22 | the first index pulse beyond the edge | the same |
//! | 33 / 34 | the index pulse | the first one | negative / positive |
//! | 35, 37 | none | the position now | no motion |
//! | -1 / -2 | a hard stop, found by the stall detection | where the stall is detected | positive / negative |
//! | -3 / -4 | negative / positive limit switch, at the search speed | where it actuates | negative / positive |
//! | -5 / -6 | home switch, searched negative / positive, reversing at that side's limit | where it actuates | either |
//! | -7 / -8 | as -3 / -4, then off the switch and back onto it at the creep speed | where it actuates | negative / positive |
//! | -9 / -10 | as -5 / -6, then off the switch and back onto it at the creep speed | where it actuates | negative / positive |
//!
//! Methods -3 to -10 are JMC's 1-8 (seed 001 §6.3). With a zero speed 0x216E the axis then
//! moves to position 0 at it (JMC's offset move: the zero is the offset 0x2169 away from the
//! home), and the homing ends there.
//!
//! Searches run at the search speed 0x2163 and every edge is found at the creep speed 0x2165:
//! the tick sees a switch's level once a tick, so the position is caught within one tick of
//! travel at that speed. Methods 7-14 and 23-30 (a home switch with a limit switch that
//! reverses the search) are refused (03): a master that needs them uses a limit or home switch
//! method with the EXT stops on its limits.

use super::DriveState;
use super::inputs::{INPUT_HOME, INPUT_LIMIT_NEGATIVE, INPUT_LIMIT_POSITIVE};
use super::memory::ProgramMemory;
use crate::controller::Shared;
use crate::controller::handoff::Clears;
use crate::controller::io::IN_PINS;
use crate::controller::{Events, STATUS_STALL, Watch, WatchOn};
use crate::faults::FAULT_POSITION;
use crate::motion::scurve::Limits;
use crate::od::{Obj, ObjError, refuse};
use crate::servo::Feedback;
use crate::units::Instant;
use core::borrow::Borrow;

/// How often a running homing is checked, µs: its timeout, and the axis coming to rest after
/// its last step (the tick reports what it caught at once).
const CHECK_EVERY: u64 = 10_000;

/// How a homing went (0x2162).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(u8)]
pub enum Outcome {
    /// Not homed since power-up.
    #[default]
    NotHomed = 0,
    /// Running.
    Running = 1,
    /// Homed: the position counts from the home.
    Homed = 2,
    /// The timeout 0x216B ran out first.
    Timeout = 3,
    /// Stopped before it ended: 0x2161 = 0, another motion command, a stop (0x6053, an EXT
    /// stop, the watchdog), a fault, or a stall it did not ask for.
    Interrupted = 4,
}

/// What ends a step (the switches' are the reference switch's).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Until {
    /// The reference switch actuated.
    Active,
    /// The reference switch released.
    Inactive,
    /// The encoder's index pulse.
    Index,
    /// A stall.
    Stall,
}

/// One step: a move in `up` (positive) or the other direction at the search or creep speed
/// until a condition; `home` if the position where it holds is the home.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Step {
    up: bool,
    fast: bool,
    until: Until,
    home: bool,
    /// The limit switch in the way reverses the search.
    reverse: bool,
}

/// A method's reference and approach.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Method {
    /// A switch (its input, 0x216C's field: 0 home, 1 negative limit, 2 positive limit),
    /// actuated above its edge (`above`) or below; found moving `up` or down; then the index.
    Switch { input: u8, above: bool, up: bool, index: bool },
    /// The index pulse, moving `up` or down.
    Index { up: bool },
    /// A hard stop, moving `up` or down.
    HardStop { up: bool },
    /// The position now.
    Here,
    /// A switch (0x216C's field) searched moving `up` at the search speed, reversing at the
    /// limit switch `reverse` (a field) if that comes first; the home where it actuates, or with
    /// `edge` where it actuates again, approached moving `up` at the creep speed after leaving it.
    Search { target: u8, up: bool, reverse: Option<u8>, edge: bool },
}

impl Method {
    /// Method `raw` (0x2160), if the drive does it.
    fn of(raw: u32) -> Option<Self> {
        let switch = |input, above, up, index| Some(Method::Switch { input, above, up, index });
        match raw as u16 as i16 {
            m @ (1 | 17) => switch(1, false, true, m == 1),
            m @ (2 | 18) => switch(2, true, false, m == 2),
            m @ (3 | 19) => switch(0, true, false, m == 3),
            m @ (4 | 20) => switch(0, true, true, m == 4),
            m @ (5 | 21) => switch(0, false, true, m == 5),
            m @ (6 | 22) => switch(0, false, false, m == 6),
            33 => Some(Method::Index { up: false }),
            34 => Some(Method::Index { up: true }),
            35 | 37 => Some(Method::Here),
            -1 => Some(Method::HardStop { up: true }),
            -2 => Some(Method::HardStop { up: false }),
            m @ -10..=-3 => {
                let n = (-3 - m) as u8; // 0..=7: JMC's method - 1
                let up = n % 2 == 1;
                let home = n % 4 >= 2;
                let target = if home {
                    0
                } else if up {
                    2
                } else {
                    1
                };
                let reverse = home.then_some(if up { 2 } else { 1 });
                Some(Method::Search { target, up, reverse, edge: n >= 4 })
            }
            _ => None,
        }
    }
}

/// The bus side's homing: the steps planned, the one running, what it caught.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Homing {
    /// How the last homing went.
    pub(crate) outcome: Outcome,
    steps: [Option<Step>; 4],
    /// The step running.
    at: usize,
    /// Where the home was caught.
    home: Option<i64>,
    /// The reference switch's pin (bit of 0x6031) and its active level (true high).
    pin: u16,
    active_high: bool,
    /// The limit switch that reverses a search, and its active level.
    limit: u16,
    limit_high: bool,
    /// Moving to position 0 after the home was declared.
    zeroing: bool,
    /// An edge method's final direction (up): the search's stop may have overshot the switch
    /// on that side, and then the axis passes back through it before approaching it again.
    edge_up: Option<bool>,
    /// When it gives up.
    deadline: Option<Instant>,
    /// The axis version of the running step's plan.
    version: u32,
    /// Waiting for the axis to stand before the position is declared.
    finishing: bool,
    /// When the next check is due ([`DriveState::homing_service`]).
    check_at: Instant,
}

/// The pin (bit of 0x6031) of 0x216C's input number `k` (1-3 EXT1-3, 4-11 GPIO1-8).
fn pin_of(k: u32) -> Option<u16> {
    match k {
        1..=3 => Some(1 << (6 + k)),
        4..=10 => Some(1 << (k - 4)),
        11 => Some(1 << 11),
        _ => None,
    }
}

impl<P: Borrow<Shared>, G: Borrow<ProgramMemory>> DriveState<P, G> {
    /// The pin of the home switch (`field` 0), the negative (1) or the positive limit switch (2),
    /// and whether it is active high: an input whose function (0x21BA-0x21C0) is that switch (11,
    /// 10, 9) with its level of 0x21C1, else 0x216C's input and 0x216D's level.
    pub(crate) fn homing_switch(&self, field: u8) -> Option<(u16, bool)> {
        let function = [INPUT_HOME, INPUT_LIMIT_NEGATIVE, INPUT_LIMIT_POSITIVE].get(usize::from(field)).copied();
        if let Some(k) = (0..IN_PINS.len()).find(|&k| Some(self.input_function(k)) == function) {
            let low = self.param(Obj::InputLogic) & (1 << k) != 0;
            return IN_PINS.get(k).map(|&pin| (pin, !low));
        }
        let k = (self.param(Obj::HomingInputs) >> (4 * field)) & 0xF;
        pin_of(k).map(|pin| (pin, self.param(Obj::HomingPolarity) & (1 << field) != 0))
    }

    /// Whether the home switch, the negative and the positive limit switch are actuated now (one
    /// without an input is not).
    pub(crate) fn switches(&self) -> [bool; 3] {
        let mut out = [false; 3];
        for (field, actuated) in (0..).zip(out.iter_mut()) {
            if let Some((pin, active_high)) = self.homing_switch(field) {
                // 0x6031 holds an input's level inverted.
                let high = self.ctl.status.gpio & pin == 0;
                *actuated = high == active_high;
            }
        }
        out
    }

    /// 0x2162.
    pub(crate) fn homing_outcome(&self) -> u32 {
        self.homing.outcome as u32
    }

    /// Whether the homing command `value` (0x2161: 1 start, 0 stop) may be written now.
    pub(crate) fn check_homing(&self, value: u32) -> Result<(), ObjError> {
        if value == 0 {
            return Ok(());
        }
        self.may_move()?;
        refuse(self.ctl.axis.is_still() && self.ctl.run.is_none(), ObjError::Busy)?;
        let method = Method::of(self.param(Obj::HomingMethod)).ok_or(ObjError::OutOfRange)?;
        if method != Method::Here {
            // Its speeds within the overspeed limit (0x21F6), as a motion command's.
            let planner = self.planner();
            planner.asked.set(self.param(Obj::HomingSearchSpeed).max(self.param(Obj::HomingCreepSpeed)) as f32);
            planner.within_overspeed(0.0)?;
        }
        match method {
            Method::Switch { input, .. } => refuse(self.homing_switch(input).is_some(), ObjError::NotNow),
            Method::HardStop { .. } => {
                // The stall must be seen: the closed loop's following error, or the sensorless
                // detection on and the creep above its minimum speed.
                let per_step = self.param(Obj::Microsteps).max(1);
                let closed = matches!(self.ctl.servo.feedback, Feedback::Closed(_));
                let creep_steps = self.param(Obj::HomingCreepSpeed) / per_step;
                let sensorless = self.param(Obj::StallDetect) == 1 && creep_steps >= self.param(Obj::StallMinSpeed);
                refuse(closed || sensorless, ObjError::NotNow)
            }
            Method::Search { target, reverse, .. } => {
                let has = |field: u8| self.homing_switch(field).is_some();
                refuse(has(target) && reverse.is_none_or(has), ObjError::NotNow)
            }
            Method::Index { .. } | Method::Here => Ok(()),
        }
    }

    /// Starts (1) or stops (0) a homing; [`DriveState::check_homing`] accepted it.
    pub(crate) fn homing_command(&mut self, value: u32) {
        if value == 0 {
            if self.homing.outcome == Outcome::Running {
                self.end_homing(Outcome::Interrupted);
                self.ctl.axis.stop_ramp(self.param(Obj::HomingAccel));
            }
            return;
        }
        let Some(method) = Method::of(self.param(Obj::HomingMethod)) else { return };
        let timeout = u64::from(self.param(Obj::HomingTimeout)) * 100_000;
        self.homing = Homing {
            outcome: Outcome::Running,
            deadline: (timeout != 0).then(|| self.now.plus_micros(timeout)),
            check_at: self.now.plus_micros(CHECK_EVERY),
            ..Homing::default()
        };
        let one = |s: Step| [Some(s), None, None, None];
        let switch = |f: u8| self.homing_switch(f).unwrap_or((0, false));
        let (home, negative, positive) = (switch(0), switch(1), switch(2));
        let field = move |f: u8| match f {
            0 => home,
            1 => negative,
            _ => positive,
        };
        match method {
            Method::Search { target, up, reverse, edge } => {
                let step = |up, fast, until, home, reverse| Some(Step { up, fast, until, home, reverse });
                let search = step(up, true, Until::Active, !edge, reverse.is_some());
                self.homing.steps = if edge {
                    [
                        search,
                        step(!up, false, Until::Active, false, false),
                        step(!up, false, Until::Inactive, false, false),
                        step(up, false, Until::Active, true, false),
                    ]
                } else {
                    [search, None, None, None]
                };
                self.homing.edge_up = edge.then_some(up);
                (self.homing.pin, self.homing.active_high) = field(target);
                if let Some(limit) = reverse {
                    (self.homing.limit, self.homing.limit_high) = field(limit);
                }
                self.suspend_stops(self.homing.pin | self.homing.limit);
            }
            Method::Here => self.homing.home = Some(self.ctl.axis.setpoint().whole),
            Method::Index { up } => {
                self.homing.steps = one(Step { up, fast: false, until: Until::Index, home: true, reverse: false })
            }
            Method::HardStop { up } => {
                // A stall bit left from before is not the stop this homing will feel.
                self.clear_status(Clears { controller: STATUS_STALL, ..Clears::NONE });
                self.homing.steps = one(Step { up, fast: false, until: Until::Stall, home: true, reverse: false })
            }
            Method::Switch { input, above, up, index } => {
                let (pin, active_high) = self.homing_switch(input).unwrap_or((0, false));
                // 0x6031 holds an input's level inverted.
                let high = self.ctl.status.gpio & pin == 0;
                let active = high == active_high;
                let step = |up, fast, until, home| Some(Step { up, fast, until, home, reverse: false });
                // The edge approached moving `up`: from the released side if the switch is
                // actuated on the far side of it, else from the actuated side.
                let into = up == above;
                let mut plan = match (into, active) {
                    (true, false) => [
                        step(up, true, Until::Active, false),
                        step(!up, false, Until::Inactive, false),
                        step(up, false, Until::Active, !index),
                        None,
                    ],
                    (true, true) => {
                        [step(!up, true, Until::Inactive, false), step(up, false, Until::Active, !index), None, None]
                    }
                    (false, false) => {
                        [step(!up, true, Until::Active, false), step(up, false, Until::Inactive, !index), None, None]
                    }
                    (false, true) => [step(up, false, Until::Inactive, !index), None, None, None],
                };
                // With the index, the home is the first index pulse beyond the edge.
                if index && let Some(free) = plan.iter_mut().find(|s| s.is_none()) {
                    *free = step(up, false, Until::Index, true);
                }
                self.homing.steps = plan;
                (self.homing.pin, self.homing.active_high) = (pin, active_high);
                // The reference switch's own external stop would stop every search on it.
                self.suspend_stops(pin);
            }
        }
        self.homing_step();
    }

    /// Plans the step the homing is at and arms its watch; finishes if there is none.
    fn homing_step(&mut self) {
        let Some(Some(step)) = self.homing.steps.get(self.homing.at).copied() else {
            self.homing.finishing = true;
            return self.homing_service();
        };
        let speed = self.param(if step.fast { Obj::HomingSearchSpeed } else { Obj::HomingCreepSpeed }) as f32;
        let accel = self.param(Obj::HomingAccel);
        let limits = Limits { v_max: speed, a_max: accel as f32, d_max: accel as f32, jerk: None };
        let v = if step.up { speed } else { -speed };
        let at = self.plan_time();
        if self.ctl.axis.run_at(at, v, 0.0, &limits).is_err() {
            return self.end_homing(Outcome::Interrupted);
        }
        let h = &mut self.homing;
        let level = |pin: u16, high: bool| if high { pin } else { 0 };
        let on = match step.until {
            Until::Active if step.reverse => WatchOn::Pins {
                pins: h.pin | h.limit,
                high: level(h.pin, h.active_high) | level(h.limit, h.limit_high),
            },
            Until::Active => WatchOn::Pins { pins: h.pin, high: level(h.pin, h.active_high) },
            Until::Inactive => WatchOn::Pins { pins: h.pin, high: level(h.pin, !h.active_high) },
            Until::Index => WatchOn::Index,
            Until::Stall => WatchOn::Stall,
        };
        // At a hard stop the axis halts: it cannot ramp down into the stop.
        let decel = if step.until == Until::Stall { 0 } else { accel };
        let version = self.ctl.axis.version();
        h.version = version;
        self.set_watch(Some(Watch { on, version, decel, up: step.up }));
    }

    /// What the tick reported, for a homing that runs: a caught position (the next step), a
    /// stop it did not make (interrupted).
    pub(crate) fn homing_events(&mut self, events: Events) {
        if self.homing.outcome != Outcome::Running {
            return;
        }
        if let (true, Some(at)) = (events.has(Events::CAUGHT), self.ctl.caught.take()) {
            let step = self.homing.steps.get(self.homing.at).copied().flatten();
            if let Some(s) = step.filter(|s| s.reverse)
                && !self.actuated(self.homing.pin, self.homing.active_high)
            {
                // The limit came first: the same search the other way, past it.
                if let Some(slot) = self.homing.steps.get_mut(self.homing.at) {
                    *slot = Some(Step { up: !s.up, reverse: false, ..s });
                }
                return self.homing_step();
            }
            if step.is_some_and(|s| s.home) {
                self.homing.home = Some(at);
            }
            if step.is_some_and(|s| s.until == Until::Stall) {
                // The stall at the hard stop is what was searched for, not a fault: cleared
                // now, before the closed loop's position error keeps the power stage off.
                self.clear_status(Clears { controller: STATUS_STALL, faults: FAULT_POSITION, ..Clears::NONE });
            }
            // An edge method's search that was moving away from the final direction when it
            // caught the switch stopped inside it or past it on that side: no passing back.
            let away = step.is_some_and(|s| self.homing.at == 0 && self.homing.edge_up.is_some_and(|f| s.up != f));
            self.homing.at += if away { 2 } else { 1 };
            return self.homing_step();
        }
        // A stop the tick made on its own; after the last step the axis is only settling (the
        // stall's latch may still stop it for a tick or two).
        if events.has(Events::STOPPED) && !self.homing.finishing {
            self.end_homing(Outcome::Interrupted);
        }
    }

    /// The homing's checks in time: the timeout, a step's plan replaced by another motion, the
    /// position declared once the axis stands after the last step.
    pub(crate) fn homing_service(&mut self) {
        let h = self.homing;
        if h.outcome != Outcome::Running {
            return;
        }
        self.homing.check_at = self.now.plus_micros(CHECK_EVERY);
        if h.deadline.is_some_and(|d| self.now >= d) {
            self.ctl.axis.stop_ramp(self.param(Obj::HomingAccel));
            return self.end_homing(Outcome::Timeout);
        }
        if !h.finishing || h.zeroing {
            if self.ctl.axis.version() != h.version {
                // Another command changed course: the watch went with its plan.
                self.end_homing(Outcome::Interrupted);
            } else if h.zeroing && self.ctl.axis.is_still() {
                self.end_homing(Outcome::Homed);
            }
            return;
        }
        if !self.ctl.axis.is_still() {
            return;
        }
        let Some(home) = h.home else { return self.end_homing(Outcome::Interrupted) };
        let here = self.ctl.axis.setpoint().whole;
        let offset = i64::from(self.param(Obj::HomingOffset) as i32);
        let position = offset.saturating_add(here.saturating_sub(home));
        self.apply(Obj::Position, position.clamp(i64::from(i32::MIN), i64::from(i32::MAX)) as i32 as u32);
        if self.param(Obj::HomingZeroSpeed) == 0 || position == 0 {
            return self.end_homing(Outcome::Homed);
        }
        self.zero_move();
    }

    /// JMC's offset move: to the zero, at the zero speed 0x216E.
    fn zero_move(&mut self) {
        let speed = self.param(Obj::HomingZeroSpeed) as f32;
        let accel = self.param(Obj::HomingAccel) as f32;
        let limits = Limits { v_max: speed, a_max: accel, d_max: accel, jerk: None };
        self.set_watch(None);
        if self.ctl.axis.move_to(self.plan_time(), 0, 0.0, 0.0, &limits).is_err() {
            return self.end_homing(Outcome::Interrupted);
        }
        (self.homing.zeroing, self.homing.version) = (true, self.ctl.axis.version());
    }

    /// Whether the switch on `pin`, active at `high`, is actuated (0x6031 holds levels inverted).
    fn actuated(&self, pin: u16, high: bool) -> bool {
        (self.ctl.status.gpio & pin == 0) == high
    }

    /// Ends the homing with `outcome`: the watch and the suspended stops go.
    fn end_homing(&mut self, outcome: Outcome) {
        self.homing = Homing { outcome, ..Homing::default() };
        self.set_watch(None);
        self.suspend_stops(0);
    }

    /// Arms `watch` for the tick, or cancels the one armed (`None`): in the model, and as an
    /// order.
    fn set_watch(&mut self, watch: Option<Watch>) {
        (self.ctl.watch, self.orders.watch) = (watch, Some(watch));
    }

    /// Suspends the external stops of `pins` (none: 0) while a homing searches them: in the
    /// model, and as an order.
    fn suspend_stops(&mut self, pins: u16) {
        (self.ctl.suspend, self.orders.suspend) = (pins, Some(pins));
    }

    /// When [`DriveState::homing_service`] has something to check: while a homing runs, every
    /// [`CHECK_EVERY`] (its timeout, the axis coming to rest).
    pub(crate) fn homing_due(&self) -> Option<Instant> {
        (self.homing.outcome == Outcome::Running).then_some(self.homing.check_at)
    }
}
