//! Analog positioning (§5.13, 0x6077..0x607E, in the PP mode) and analog speed (§3.9, our
//! 0x2170..0x2173, in the velocity mode): the analog input 0x605F sets the target.
//!
//! The bus side reads the input every 10 ms and averages the readings over the adjustment
//! interval 0x6079 (a boxcar filter: ADC noise averages out); at the end of each interval the
//! mean code gives a position (linear from 0x607B at the start code 0x6078 to 0x607D at code
//! 4095; below the start code, 0x607B) or a speed (0 at the start code and below, 0x2171 at
//! code 4095). A new target is planned only when it differs from the one in force by more than
//! the dead band: 0x607A for a position (the manual's trigger value, compared with the target
//! in force rather than the last reading, so that a slow ramp still moves the motor), 0x2173
//! for a speed. With the filter and the dead band a noisy constant input leaves the motor
//! standing, where acting on every reading would make it hunt.

use super::DriveState;
use super::control::Pp;
use super::memory::ProgramMemory;
use crate::controller::Shared;
use crate::modes::WorkMode;
use crate::od::Obj;
use crate::units::Instant;
use core::borrow::Borrow;

/// How often the input is read, µs.
const READ_EVERY: u64 = 10_000;

/// The bus side's analog follower: the readings of the interval, and the target in force.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Analog {
    sum: u32,
    readings: u16,
    /// A target is in force.
    following: bool,
    /// The next reading (none yet: now).
    next: Option<Instant>,
    /// The end of the interval.
    interval_end: Option<Instant>,
    /// The target in force: a position or a speed.
    target: i32,
}

/// Which target the analog input sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Follow {
    Position,
    Speed,
}

/// The position of the mean code `code` with start code `start` and the positions `min`, `max`
/// at the start code and at 4095 (§5.13).
///
/// ```
/// # use drive_core::state::analog::position_of;
/// assert_eq!(position_of(2047, 0, 0, 64_000), 31_992);
/// assert_eq!(position_of(100, 1000, -500, 500), -500);
/// assert_eq!(position_of(4095, 1000, -500, 500), 500);
/// ```
pub fn position_of(code: u32, start: u32, min: i64, max: i64) -> i64 {
    let span = i64::from(4095u32.saturating_sub(start).max(1));
    let above = i64::from(code.saturating_sub(start).min(4095));
    min + (max - min) * above.min(span) / span
}

impl<P: Borrow<Shared>, G: Borrow<ProgramMemory>> DriveState<P, G> {
    /// What the analog input follows now, if anything: positions in the PP mode with 0x6077 on,
    /// speeds in the velocity mode with 0x2170 on.
    fn follows(&self) -> Option<Follow> {
        match self.mode() {
            WorkMode::ProfilePosition if self.param(Obj::AnalogPosEnable) == 1 => Some(Follow::Position),
            WorkMode::Velocity if self.param(Obj::AnalogSpeedEnable) == 1 => Some(Follow::Speed),
            _ => None,
        }
    }

    /// When [`DriveState::analog_service`] reads the input next, while it follows it.
    pub(crate) fn analog_due(&self) -> Option<Instant> {
        self.follows().map(|_| self.analog.next.unwrap_or(self.now))
    }

    /// Reads the input if due, and at the end of an interval plans the new target.
    pub(crate) fn analog_service(&mut self) {
        let Some(follow) = self.follows() else {
            self.analog = Analog::default();
            return;
        };
        let now = self.now;
        if self.analog.next.is_some_and(|t| now < t) {
            return;
        }
        let interval = u64::from(self.param(Obj::AnalogInterval)).max(10) * 1000;
        let a = &mut self.analog;
        a.next = Some(now.plus_micros(READ_EVERY));
        a.sum += u32::from(self.ctl.status.analog_in);
        a.readings += 1;
        let end = *a.interval_end.get_or_insert(now.plus_micros(interval));
        if now < end {
            return;
        }
        let code = a.sum / u32::from(a.readings.max(1));
        (a.sum, a.readings, a.interval_end) = (0, 0, Some(now.plus_micros(interval)));
        if self.may_move().is_err() {
            return;
        }
        let start = self.param(Obj::AnalogStartCode);
        match follow {
            Follow::Position => {
                let (min, max) = (self.param(Obj::AnalogMinPos) as i32, self.param(Obj::AnalogMaxPos) as i32);
                let target = position_of(code, start, i64::from(min), i64::from(max));
                let band = i64::from(self.param(Obj::AnalogTrigger));
                if self.analog.following && (target - i64::from(self.analog.target)).abs() <= band {
                    return;
                }
                self.follow_position(target);
            }
            Follow::Speed => {
                let full = i64::from(self.param(Obj::AnalogSpeedFull) as i32);
                let speed = position_of(code, start, 0, full);
                let band = i64::from(self.param(Obj::AnalogSpeedDeadband));
                if self.analog.following && (speed - i64::from(self.analog.target)).abs() <= band {
                    return;
                }
                self.follow_speed(speed);
            }
        }
    }

    /// The speed the analog input asks for (0x21E5): the target in force while it sets a speed.
    pub(crate) fn analog_speed(&self) -> i32 {
        let speed = self.follows() == Some(Follow::Speed) && self.analog.following;
        if speed { self.analog.target } else { 0 }
    }

    /// Plans a PP move to `target` with the PP set-point's limits (from wherever the axis is).
    fn follow_position(&mut self, target: i64) {
        let planner = self.planner();
        let speed = ((self.param(Obj::PpRunSpeed) as i32) as f32).abs();
        let sp = planner.pp_setpoint(target, speed);
        let at = self.plan_time();
        if self.ctl.axis.move_to(at, sp.target, sp.depart, sp.arrive, &sp.limits).is_ok() {
            self.pp = Pp::default();
            self.pp.active = Some(sp);
            (self.analog.following, self.analog.target) = (true, target as i32);
        }
    }

    /// Plans the velocity mode's run at `speed` (its S-curve, as 0x6003 writes it).
    fn follow_speed(&mut self, speed: i64) {
        let v = speed as f32;
        let planner = self.planner();
        let limits = planner.scurve_limits(v);
        let (depart, _) = planner.jumps(v);
        let at = self.plan_time();
        if self.ctl.axis.run_at(at, v, depart, &limits).is_ok() {
            (self.analog.following, self.analog.target) = (true, speed as i32);
        }
    }
}
