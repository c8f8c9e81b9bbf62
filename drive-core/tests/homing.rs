//! The homing's steps and the step notifications by property, on the drive alone: a switch
//! whose level follows the setpoint (as a rotor that follows it exactly would make it), no motor.

use drive_core::faults::Inputs;
use drive_core::od::Obj;
use drive_core::{Drive, Instant};
use proptest::prelude::*;

/// One tick, µs.
const TICK: u64 = 50;

/// A factory drive, its clock, where the motor physically is (the steps it was told to make,
/// from 0), and the switch: EXT1 (0x6031 bit 7) low (actuated, NPN) from `edge` up if `above`,
/// else down.
struct Axis {
    drive: Drive,
    now: u64,
    physical: i64,
    edge: i64,
    above: bool,
}

impl Axis {
    fn new(edge: i64, above: bool) -> Self {
        let mut a = Self { drive: Drive::factory(), now: 1_000_000, physical: 0, edge, above };
        // The drive's clock set before anything is planned on it.
        a.tick();
        a
    }

    fn set(&mut self, obj: Obj, value: u32) {
        let state = self.drive.state_mut();
        assert_eq!(state.check(obj, value), Ok(()), "{obj:?} = {value}");
        state.apply(obj, value);
    }

    fn read(&self, obj: Obj) -> u32 {
        self.drive.state().read(obj)
    }

    fn position(&self) -> i64 {
        self.drive.state().controller().axis().setpoint().whole
    }

    /// One tick: the switch read where the motor is, the steps of the tick made, then the bus
    /// side's work in time if due.
    fn tick(&mut self) {
        let p = self.physical;
        let actuated = if self.above { p >= self.edge } else { p <= self.edge };
        // The switch pulls the pin low when actuated; the pull-up holds it high otherwise.
        let levels = if actuated { 0 } else { 1 << 7 };
        let now = Instant::from_micros(self.now);
        self.physical += self.drive.tick_with(now, &Inputs { levels, ..Inputs::default() }).steps;
        self.drive.state_mut().service(now);
        self.now += TICK;
    }

    fn run(&mut self, secs: f64) {
        for _ in 0..(secs * 20_000.0) as u32 {
            self.tick();
        }
    }

    /// Runs until the axis stands (at most 10 s), and a tick more: the switch's level is read
    /// a tick after the motor got there.
    fn settle(&mut self) {
        for _ in 0..200_000 {
            self.tick();
            if self.drive.state().controller().axis().is_still() {
                break;
            }
        }
        self.tick();
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// The home-switch methods end with the position 0x2169 where the setpoint first met the
    /// switch's edge in the method's direction, from any start on either side of it.
    #[test]
    fn home_switch_methods_home_on_the_edge(
        start in -4000i32..4000,
        edge in -3000i64..3000,
        method in prop_oneof![Just(19u32), Just(20), Just(21), Just(22)],
        offset in -100_000i32..100_000,
    ) {
        let above = method <= 20;
        let mut a = Axis::new(edge, above);
        a.set(Obj::MaxSpeed, 20_000);
        a.set(Obj::AbsoluteMove, start as u32);
        a.settle();
        prop_assert_eq!(a.physical, i64::from(start));
        a.set(Obj::HomingSearchSpeed, 20_000);
        a.set(Obj::HomingCreepSpeed, 2000);
        a.set(Obj::HomingAccel, 400_000);
        a.set(Obj::HomingOffset, offset as u32);
        a.set(Obj::HomingMethod, method);
        a.set(Obj::HomingControl, 1);
        let mut left = 400_000;
        while a.read(Obj::HomingResult) == 1 && left > 0 {
            a.tick();
            left -= 1;
        }
        prop_assert_eq!(a.read(Obj::HomingResult), 2);
        // Where the position reads the offset: the first place on the switch's far side of the
        // edge in the final approach's direction (a tick at 2000 pps is 0.1 microstep).
        let up = matches!(method, 20 | 21);
        let past = i64::from(a.read(Obj::Position) as i32) - i64::from(offset);
        let found = a.physical - past;
        let expect = match (up, above) {
            (true, true) => edge,       // rising into the switch
            (false, true) => edge - 1,  // leaving it downwards
            (true, false) => edge + 1,  // leaving it upwards
            (false, false) => edge,     // falling into it
        };
        prop_assert_eq!(found, expect);
    }

    /// A notification bit sets exactly when a move reaches or passes its position, either way.
    #[test]
    fn notifications_set_exactly_when_passed(
        from in -5000i32..5000,
        to in -5000i32..5000,
        at in -5000i32..5000,
    ) {
        let mut a = Axis::new(i64::MAX, true);
        a.set(Obj::MaxSpeed, 50_000);
        a.set(Obj::AbsoluteMove, from as u32);
        a.settle();
        a.set(Obj::NotifyPos1, at as u32);
        a.set(Obj::NotifyStatus, 3);
        a.run(0.01);
        prop_assert_eq!(a.read(Obj::NotifyStatus), 0);
        a.set(Obj::AbsoluteMove, to as u32);
        a.settle();
        prop_assert_eq!(a.position(), i64::from(to));
        let passed = if from < to { from < at && at <= to } else { to <= at && at < from };
        prop_assert_eq!(a.read(Obj::NotifyStatus) & 1 == 1, passed);
    }
}
