//! Issue 40's command filter on the simulated motor (our 0x2210/0x2211, seed 003's
//! 0x2015/0x2016): a move with no ramp (0x600A = 0x600B = 0: the velocity jumps to speed and back
//! to rest) through the moving average has its velocity's corners rounded over the filter's time,
//! and ends on the same microstep, the rotor with it.

use drive_core::od::Obj;
use hal_sim::DEFAULT_MOTOR;
use hal_sim::motor::{Motor, MotorCatalog, MotorInputs};
use hal_sim::plant::Plant;

/// The ticks a second.
const TICK_HZ: f64 = 20_000.0;

/// A factory drive, 1/16, 1 A, no ramps, 2000 microsteps a second, the filter `micros` (0: off);
/// moves 3000 microsteps and returns each tick's setpoint velocity and the end: the setpoint's
/// position (whole, fraction) and the rotor's.
fn move_through(micros: u32) -> (Vec<f64>, (i64, u32), f64) {
    let params = MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().expect("catalogue motor");
    let mut p = Plant::new(drive_core::Drive::factory(), Motor::new(params, MotorInputs::default()));
    let settings = [(Obj::Microsteps, 16), (Obj::PhaseCurrent, 1000), (Obj::AccelLevel, 0), (Obj::DecelLevel, 0)];
    for (obj, v) in settings.into_iter().chain([(Obj::MaxSpeed, 2000)]) {
        assert_eq!(p.write(obj, v), Ok(()), "{obj:?}");
    }
    if micros > 0 {
        assert_eq!(p.write(Obj::CommandFilterTime, micros), Ok(()));
        assert_eq!(p.write(Obj::CommandFilter, 1), Ok(()));
    }
    p.run_for(0.05);
    assert_eq!(p.write(Obj::RelativeMove, 3000), Ok(()));
    let mut velocity = Vec::new();
    for _ in 0..(2.0 * TICK_HZ) as u32 {
        p.advance_to(p.next_tick());
        velocity.push(f64::from(p.outputs().expect("ticked").setpoint.velocity));
    }
    let end = p.outputs().expect("ticked").setpoint;
    (velocity, (end.whole, end.fraction.to_bits()), p.rotor_microsteps())
}

/// The ticks the velocity takes from 10 % to 90 % of `top` on its way up.
fn rise_ticks(velocity: &[f64], top: f64) -> usize {
    let first = |share: f64| velocity.iter().position(|&v| v >= share * top).unwrap_or(velocity.len());
    first(0.9) - first(0.1)
}

#[test]
fn the_filter_rounds_the_corners_over_its_time_and_ends_on_the_same_microstep() {
    let (raw, raw_end, raw_rotor) = move_through(0);
    let (smooth, smooth_end, smooth_rotor) = move_through(20_000);
    let top = 2000.0;
    // Unfiltered: a jump to speed within a tick. Through 20 ms (400 ticks): a ramp of 400 ticks,
    // 10 % to 90 % in 320.
    assert!(rise_ticks(&raw, top) <= 1, "{}", rise_ticks(&raw, top));
    let rise = rise_ticks(&smooth, top);
    assert!((310..=330).contains(&rise), "{rise} ticks");
    // Its steepest change: the speed over the filter's ticks, once a tick.
    let steepest = smooth.windows(2).map(|w| (w[1] - w[0]).abs()).fold(0.0, f64::max);
    // (The input's 0.1 microstep a tick is 25 or 26 of the filter's 1/256: 2 % over.)
    assert!(steepest <= top / 400.0 * 1.03, "{steepest} a tick");
    println!("rise 10-90 %: {rise} ticks; steepest change {steepest:.2} microsteps/s a tick");
    // The same end, exactly; the rotor there too.
    assert_eq!(raw_end, (3000, 0));
    assert_eq!(smooth_end, (3000, 0));
    assert!((smooth_rotor - 3000.0).abs() < 1.0 && (raw_rotor - 3000.0).abs() < 1.0, "{smooth_rotor} {raw_rotor}");
}
