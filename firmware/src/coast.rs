//! Coasting: the power stage's steps in a control tick that cannot run the drive, because the
//! bus task holds it. Serving a request that plans a motion holds it for about 1.1-1.3 ms on the
//! Cortex-M4 (`cargo xtask tick-cost`), 21-27 ticks at 20 kHz; stopping the pulses for that long
//! and then emitting the steps of those ticks at once would jerk a motor running at speed.
//!
//! While it waits, the stage keeps stepping at the speed of the last tick that ran, from its
//! setpoint; the next tick that runs takes the steps coasted from its own. No step is lost or
//! added: coasting only moves steps earlier or later, by what the speed changed while waiting
//! (`a·T²/2`: 0.09 microstep after 1.5 ms at 77 440 pps²). A step back that only coasting would
//! cause (it ran a fraction ahead of a braking axis) is not taken while the axis moves on: the
//! coming ticks absorb it.

use drive_core::motion::axis::Setpoint;

/// 2^16: the scale of the speed a tick in 16.16 fixed point.
const Q16: f32 = 65_536.0;

/// What coasting needs of the last tick that ran, and the steps it has coasted since. Integers
/// and `f32` only: it runs in the tick's interrupt.
#[derive(Clone, Copy, Debug)]
pub struct Coast {
    /// Ticks a second, as `f32`.
    tick_hz: f32,
    /// The distance of one tick at the last tick's speed, in 2^-32 microstep.
    rate: i64,
    /// Where coasting stands, beyond the last setpoint's whole microstep, in 2^-32 microstep;
    /// `None` until a coasting tick starts from the setpoint's fraction.
    position: Option<i64>,
    /// The fraction of the last setpoint, in 2^-32 microstep.
    fraction: u32,
    /// Microsteps emitted beyond the drive's own count (signed): coasted, or held back.
    surplus: i64,
}

impl Coast {
    /// Coasting for a stage stepped by a tick of `tick_hz`; nothing to coast yet.
    pub const fn new(tick_hz: u32) -> Self {
        Self { tick_hz: tick_hz as f32, rate: 0, position: None, fraction: 0, surplus: 0 }
    }

    /// A tick that ran the drive, which asked for `steps` with the commutation setpoint `sp`:
    /// the steps to emit now, those coasted ahead taken from them.
    pub fn ticked(&mut self, steps: i64, sp: &Setpoint) -> i64 {
        let due = steps.saturating_sub(self.surplus);
        let direction = if sp.velocity > 0.0 {
            1
        } else if sp.velocity < 0.0 {
            -1
        } else {
            0
        };
        let backwards = (due < 0 && direction > 0) || (due > 0 && direction < 0);
        // Coasting ran ahead of an axis that slowed: hold the step back until it catches up.
        let emit = if backwards && self.surplus != 0 { 0 } else { due };
        self.surplus = self.surplus.saturating_add(emit).saturating_sub(steps);
        // Microsteps a tick in 16.16 (the FPU converts to `i32`: up to 32 767 a tick), then 32.32.
        let per_tick = (sp.velocity / self.tick_hz * Q16) as i32;
        self.rate = i64::from(per_tick) << 16;
        (self.fraction, self.position) = (sp.fraction.to_bits(), None);
        emit
    }

    /// A tick that could not run the drive: the whole microsteps to emit to keep the last speed.
    pub fn coasting(&mut self) -> i64 {
        let before = self.position.unwrap_or(i64::from(self.fraction));
        let after = before.saturating_add(self.rate);
        self.position = Some(after);
        // Whole microsteps crossed: the difference of the floors.
        let n = (after >> 32) - (before >> 32);
        self.surplus = self.surplus.saturating_add(n);
        n
    }
}

// Host tests only: the HIL suite includes this file for the board, where there is no `std`.
#[cfg(all(test, not(target_os = "none")))]
mod tests {
    use super::*;
    use drive_core::control::TICK_HZ;
    use fixed::types::U0F32;

    /// The setpoint of an axis at `p` microsteps moving at `v` pps.
    fn at(p: f64, v: f64) -> Setpoint {
        let whole = p.floor();
        Setpoint { whole: whole as i64, fraction: U0F32::from_num(p - whole), velocity: v as f32, acceleration: 0.0 }
    }

    /// Runs an axis whose position at tick `k` is `pos(k)` (and velocity `vel(k)`), the ticks
    /// in `waiting` coasting; returns the steps emitted each tick.
    fn run(
        pos: impl Fn(u32) -> f64,
        vel: impl Fn(u32) -> f64,
        ticks: u32,
        waiting: core::ops::Range<u32>,
    ) -> std::vec::Vec<i64> {
        let mut coast = Coast::new(TICK_HZ);
        let mut last = pos(0).floor() as i64;
        let mut out = std::vec::Vec::new();
        for k in 1..=ticks {
            if waiting.contains(&k) {
                out.push(coast.coasting());
            } else {
                let sp = at(pos(k), vel(k));
                out.push(coast.ticked(sp.whole - last, &sp));
                last = sp.whole;
            }
        }
        out
    }

    #[test]
    fn a_wait_while_cruising_keeps_the_pulses_coming_and_loses_none() {
        // 4000 pps: 0.2 microstep a tick. 30 ticks waiting.
        let v = 4000.0;
        let steps = run(|k| 0.3 + f64::from(k) * 0.2, |_| v, 100, 40..70);
        let during: i64 = steps.get(39..69).unwrap().iter().sum();
        assert_eq!(during, 6, "30 ticks at 0.2 microstep a tick, from 0.3 + 39 x 0.2");
        assert_eq!(steps.iter().sum::<i64>(), 20, "exactly the axis' 20 microsteps");
        assert!(steps.iter().all(|&s| s >= 0), "never backwards: {steps:?}");
        // Nothing is left over for the ticks after the wait.
        assert_eq!(steps.get(69).copied(), Some(0));
    }

    #[test]
    fn an_axis_that_brakes_during_the_wait_gets_no_step_back() {
        // Braking hard from 20000 pps (one microstep a tick) at 4e6 pps²: coasting runs ahead.
        let (v0, a) = (20_000.0, -4.0e6);
        let t = |k: u32| f64::from(k) / f64::from(TICK_HZ);
        let pos = |k: u32| 0.5 + v0 * t(k) + 0.5 * a * t(k) * t(k);
        let steps = run(pos, |k| v0 + a * t(k), 100, 10..40);
        assert!(steps.iter().all(|&s| s >= 0), "never backwards: {steps:?}");
        assert_eq!(steps.iter().sum::<i64>(), pos(100).floor() as i64);
    }

    #[test]
    fn a_stop_takes_back_what_was_coasted_beyond_it() {
        // Moving at 2 microsteps a tick, then standing still at 10.5: coasting went beyond it.
        let pos = |k: u32| if k < 5 { 0.5 + 2.0 * f64::from(k) } else { 10.5 };
        let vel = |k: u32| if k < 5 { 40_000.0 } else { 0.0 };
        let steps = run(pos, vel, 20, 4..9);
        assert_eq!(steps.iter().sum::<i64>(), 10, "ends on the axis' position");
        assert!(steps.iter().any(|&s| s < 0), "the surplus is stepped back once the axis stands");
    }
}
