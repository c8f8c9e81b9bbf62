//! The simulator's motor driven through the G474's bridges (`--power-stage bridges`,
//! `hal_sim::bridges`): the current loop on the ADC's view, the PWM's delay, dead time and the
//! comparators, against the ideal chopper.

mod common;

use common::write;
use drive_core::Drive;
use drive_core::od::Obj;
use hal_sim::bridges::{PowerStage, SensingOptions};
use hal_sim::inject::Change;
use hal_sim::motor::{Motor, MotorCatalog, MotorInputs, PhaseFault};
use hal_sim::plant::Plant;

/// A factory drive on the catalogue's motor `name` at 24 V through `stage`.
fn plant(name: &str, stage: PowerStage) -> Plant {
    let params = MotorCatalog::builtin().get(name).cloned().expect("catalogue motor");
    let mut plant = Plant::new(Drive::factory(), Motor::new(params, MotorInputs::default()));
    plant.set_power_stage(stage, SensingOptions::default());
    plant
}

/// Runs the ticks of `secs`, the drive's timer served at each (as a board's bus task does).
fn run(plant: &mut Plant, secs: f64) {
    for _ in 0..(secs * 20_000.0).round() as u32 {
        let t = plant.next_tick();
        plant.advance_to(t);
        plant.drive_mut().on_timer(t);
    }
}

/// 1/32 microsteps, 1000 mA, 32 000 pps (5 turns a second) reached at 77 440 pps² (level 1:
/// 0.41 s), then a relative move of 32 000 microsteps (1 000 full steps): at speed from 0.41 s
/// to 1.0 s.
fn start_move(plant: &mut Plant) {
    let settings =
        [(0x600C, 0x20), (0x600D, 1000), (0x600A, 1), (0x600B, 1), (0x6003, 0), (0x6004, 0x7D00), (0x6002, 0)];
    for (reg, v) in settings {
        write(plant, reg, v);
    }
    write(plant, 0x6005, 0);
    write(plant, 0x6006, 0x7D00);
}

/// Over `secs` at constant speed, the current vector's amplitude over its reference's: the mean,
/// the share of ticks more than 5 % off, and the worst tick.
fn amplitude(plant: &mut Plant, secs: f64) -> (f64, f64, f64) {
    let (mut sum, mut n, mut off, mut worst) = (0.0, 0u32, 0u32, 1.0f64);
    for _ in 0..(secs * 20_000.0) as u32 {
        run(plant, 50e-6);
        let reference = plant.bridges().expect("bridges").reference();
        let wanted = reference[0].hypot(reference[1]);
        let (a, b) = plant.motor().phase_currents();
        if wanted > 0.0 {
            let ratio = a.hypot(b) / wanted;
            sum += ratio;
            n += 1;
            off += u32::from((ratio - 1.0).abs() > 0.05);
            worst = if (ratio - 1.0).abs() > (worst - 1.0).abs() { ratio } else { worst };
        }
    }
    let n = f64::from(n.max(1));
    (sum / n, f64::from(off) / n, worst)
}

#[test]
fn a_move_through_the_bridges_ends_where_the_choppers_does_and_the_current_tracks() {
    for params in MotorCatalog::builtin().motors() {
        let mut ends = Vec::new();
        for stage in [PowerStage::Chopper, PowerStage::Bridges] {
            let mut p = plant(&params.name, stage);
            run(&mut p, 0.05);
            start_move(&mut p);
            run(&mut p, 0.45);
            let speed = p.motor().speed_rps();
            let tracking = (stage == PowerStage::Bridges).then(|| amplitude(&mut p, 0.3));
            run(&mut p, 1.5);
            let set = p.outputs().map_or(0.0, |o| o.setpoint.whole as f64);
            let rotor = p.rotor_microsteps();
            println!(
                "{} {stage:?}: at speed {speed:.2} rev/s, current amplitude over its reference (mean, share of ticks beyond 5 %, worst) {tracking:?}; end: setpoint {set}, rotor {rotor:.2} microsteps",
                params.name
            );
            assert_eq!(set, 32_000.0, "{}", params.name);
            assert!((rotor - set).abs() < 32.0, "{} {stage:?}: rotor {rotor}", params.name);
            if let Some((mean, off, worst)) = tracking {
                assert!((speed - 5.0).abs() < 0.5, "{} not at speed: {speed}", params.name);
                // The ADC's noise (2 codes, 11 mA) moves single ticks: at most one in a thousand
                // more than 5 % off, none beyond 6 %.
                assert!((mean - 1.0).abs() < 0.01, "{}: mean {mean}", params.name);
                assert!(off <= 0.001 && (worst - 1.0).abs() < 0.06, "{}: {off} off, worst {worst}", params.name);
            }
            ends.push(rotor);
        }
        assert!((ends[0] - ends[1]).abs() < 32.0, "{}: {ends:?}", params.name);
    }
}

/// The NEMA 17 through the bridges at 1/16 microsteps, standing on a full step for 50 ms with
/// phase A at 1 A.
fn holding_a_full_step() -> Plant {
    let mut p = plant(hal_sim::DEFAULT_MOTOR, PowerStage::Bridges);
    for (obj, v) in [(Obj::Microsteps, 16), (Obj::PhaseCurrent, 1000)] {
        assert_eq!(p.write(obj, v), Ok(()));
    }
    p.run_for(0.05);
    assert!(p.motor().phase_currents().0 > 0.9);
    p
}

#[test]
fn a_shorted_output_trips_the_comparator_and_the_drive_latches_the_over_current() {
    // The short (0.1 Ω, 5 µH) across the loop's 1-3 V (the currents' noise moves it) raises the
    // current with a 50 µs time constant: the 10 A trip comes in the first or the second period;
    // the comparator turns both bridges off in the sub-step (12.5 µs) it is passed.
    let mut p = holding_a_full_step();
    assert!(p.bridges().expect("bridges").trips().is_empty());
    // An injection acts at the next tick.
    let shorted_at = p.next_tick().as_micros() as f64 * 1e-6;
    p.inject(Change::Phase(0, PhaseFault::Short));
    p.run_for(0.001);
    let trips = p.bridges().expect("bridges").trips().to_vec();
    let first = trips.first().expect("a trip");
    println!("shorted at {shorted_at:.6} s, tripped at {:.6} s: {trips:?}", first.at_s);
    assert_eq!(first.phase, 0);
    assert!(first.at_s - shorted_at <= 100e-6 + 1e-9, "{} s after the short", first.at_s - shorted_at);
    // The drive read the over-current (errors bit 3, alarm 10) and turned its bridges off.
    assert_eq!(p.drive().state().read(Obj::ErrorStatus), 1 << 3);
    assert_eq!(p.drive().state().read(Obj::AlarmCode), 10);
    assert!(!p.outputs().expect("ticked").enabled);
    p.run_for(0.05);
    assert!(p.motor().phase_currents().0.abs() < 1e-3);
}

#[test]
fn an_open_winding_is_found_by_the_drives_own_regulation() {
    // The board has no open-load flag: the winding driven at the supply's limit with no current
    // is what says it is open.
    let mut p = holding_a_full_step();
    assert_eq!(p.drive().state().read(Obj::ErrorStatus), 0);
    p.inject(Change::Phase(0, PhaseFault::Open));
    // 1 ms of periods at the limit, and the tick that reads it.
    p.run_for(0.0008);
    assert_eq!(p.drive().state().read(Obj::ErrorStatus), 0, "not before a millisecond");
    p.run_for(0.0005);
    assert_eq!(p.drive().state().read(Obj::ErrorStatus), 1 << 1);
    assert_eq!(p.drive().state().read(Obj::AlarmCode), 11);
    assert!(!p.outputs().expect("ticked").enabled);
}

#[test]
fn a_winding_starved_by_speed_is_not_taken_for_open() {
    // At speed the supply runs short of the back-EMF and the voltage sits at the limit: at 24 V
    // the windings still carry most of their current, at 12 V almost none (the motor stalls);
    // neither is an open winding.
    for supply_v in [24.0, 12.0] {
        let motor = MotorCatalog::builtin().get("23HS30-3004S").cloned().expect("catalogue motor");
        let mut p = Plant::new(Drive::factory(), Motor::new(motor, MotorInputs { supply_v, ..MotorInputs::default() }));
        p.set_power_stage(PowerStage::Bridges, SensingOptions::default());
        start_move(&mut p);
        let mut at_limit = 0;
        let limit_mv = (supply_v * 0.9 * 0.97 * 1e3) as u32;
        for _ in 0..40_000 {
            run(&mut p, 50e-6);
            let applied = p.bridges().expect("bridges").applied_mv();
            if applied.iter().any(|v| v.unsigned_abs() >= limit_mv) {
                at_limit += 1;
            }
        }
        println!("{supply_v} V: periods at the supply's limit: {at_limit}");
        assert!(at_limit > 1_000, "{at_limit}");
        assert_eq!(p.drive().state().read(Obj::ErrorStatus), 0, "{supply_v} V");
        assert_eq!(p.outputs().map(|o| o.setpoint.whole), Some(32_000));
    }
}

/// A plant on `name` at `supply_v` through the bridges, 0x600D at the motor's rated current,
/// the current loop's objects `params` says before power-up.
fn powered_up(name: &str, supply_v: f64, mut params: drive_core::Params) -> Plant {
    let motor = MotorCatalog::builtin().get(name).cloned().expect("catalogue motor");
    assert!(params.set(Obj::PhaseCurrent, (motor.rated_current_a * 1e3).round() as u32));
    let drive = Drive::boot(drive_core::DriveConfig::default(), &params, 0);
    let mut plant = Plant::new(drive, Motor::new(motor, MotorInputs { supply_v, ..MotorInputs::default() }));
    plant.set_power_stage(PowerStage::Bridges, SensingOptions::default());
    plant
}

#[test]
fn the_power_up_tune_measures_r_and_l_within_5_percent_and_sets_the_gains() {
    for motor in MotorCatalog::builtin().motors() {
        for supply_v in [12.0, 48.0] {
            let p = powered_up(&motor.name, supply_v, drive_core::Params::factory());
            let read = |obj| p.drive().state().read(obj);
            let (r, l) = (f64::from(read(Obj::MotorResistance)) * 1e-3, f64::from(read(Obj::MotorInductance)) * 1e-6);
            let loop_ = p.bridges().and_then(|b| b.settings()).copied().expect("a tuned loop");
            println!(
                "{} at {supply_v} V: R {:.3} Ω ({:+.2} %), L {:.3} mH ({:+.2} %), KP {} (0.1 V/A), KI {} (0.01 V/A a period)",
                motor.name,
                r,
                100.0 * (r / motor.r_ohm - 1.0),
                l * 1e3,
                100.0 * (l / motor.l_henry - 1.0),
                read(Obj::CurrentKp),
                read(Obj::CurrentKi)
            );
            assert!((r / motor.r_ohm - 1.0).abs() < 0.05, "{} R {r}", motor.name);
            assert!((l / motor.l_henry - 1.0).abs() < 0.05, "{} L {l}", motor.name);
            assert_eq!(read(Obj::CurrentKp), (loop_.kp() * 10.0).round() as u32);
            assert_eq!(read(Obj::CurrentKi), (loop_.ki() * 100.0).round() as u32);
        }
    }
}

#[test]
fn without_the_tune_the_loop_runs_on_the_objects_gains() {
    let mut params = drive_core::Params::factory();
    for (obj, v) in [(Obj::CurrentAutoTune, 0), (Obj::CurrentKp, 400), (Obj::CurrentKi, 90)] {
        assert!(params.set(obj, v));
    }
    let mut p = powered_up(hal_sim::DEFAULT_MOTOR, 24.0, params);
    let loop_ = p.bridges().and_then(|b| b.settings()).copied().expect("a loop");
    assert!((loop_.kp() - 40.0).abs() < 1e-4 && (loop_.ki() - 0.9).abs() < 1e-6, "{loop_:?}");
    // The objects as the drive had them: R and L the factory's, nothing measured.
    assert_eq!(p.drive().state().read(Obj::MotorResistance), 1400);
    // The gains are written with the tune off; the tune's own switch acts at the next power-up.
    assert_eq!(p.write(Obj::CurrentKp, 500), Ok(()));
    assert_eq!(p.write(Obj::CurrentAutoTune, 1), Ok(()));
    assert_eq!(p.write(Obj::CurrentKp, 600), Err(drive_core::od::ObjError::ReadOnly));
    // The motor holds its current on these gains.
    assert_eq!(p.write(Obj::PhaseCurrent, 1000), Ok(()));
    p.run_for(0.05);
    assert!((p.motor().phase_currents().0 - 1.0).abs() < 0.02);
}

#[test]
fn an_open_winding_at_power_up_fails_the_tune_and_the_drive_reads_it_open() {
    let motor = MotorCatalog::builtin().get(hal_sim::DEFAULT_MOTOR).cloned().expect("catalogue motor");
    let mut m = Motor::new(motor, MotorInputs::default());
    m.set_phase_fault(1, PhaseFault::Open);
    let mut p = Plant::new(Drive::factory(), m);
    p.set_power_stage(PowerStage::Bridges, SensingOptions::default());
    assert!(p.bridges().and_then(|b| b.settings()).is_none());
    assert_eq!(p.drive().state().read(Obj::MotorResistance), 1400, "nothing measured");
    assert_eq!(p.write(Obj::PhaseCurrent, 1000), Ok(()));
    p.run_for(0.01);
    // Phase loss on both (errors bits 1 and 2), the bridges never on.
    assert_eq!(p.drive().state().read(Obj::ErrorStatus) & 0b110, 0b110);
    assert_eq!(p.motor().phase_currents(), (0.0, 0.0));
}

#[test]
fn the_decay_sets_how_fast_the_current_follows_through_the_bridges() {
    // A step of 0x600D from 500 to 1000 mA at rest on a full step (phase A carries it): the
    // share of the step made, summed over the six periods after the write (the faster the loop,
    // the more), by decay.
    let mut made = Vec::new();
    for decay in [0, 2, 3] {
        let mut p = plant(hal_sim::DEFAULT_MOTOR, PowerStage::Bridges);
        for (obj, v) in [(Obj::Microsteps, 16), (Obj::PhaseCurrent, 500), (Obj::CurrentDecay, decay)] {
            assert_eq!(p.write(obj, v), Ok(()));
        }
        run(&mut p, 0.05);
        assert_eq!(p.write(Obj::PhaseCurrent, 1000), Ok(()));
        let mut sum = 0.0;
        for _ in 0..6 {
            p.advance_to(p.next_tick());
            sum += (p.motor().phase_currents().0 - 0.5) / 0.5;
        }
        made.push(sum);
    }
    println!("shares of the step made over six periods, decay 0, 2, 3: {made:.3?}");
    assert!(made[0] < made[1] - 0.2 && made[1] < made[2] - 0.01, "{made:?}");
}

#[test]
fn after_a_restart_the_bridges_power_up_again_with_the_drive() {
    let mut p = powered_up(hal_sim::DEFAULT_MOTOR, 24.0, drive_core::Params::factory());
    // The drive powers up again from a store where the tune is off and the gains set by hand.
    let mut params = drive_core::Params::factory();
    for (obj, v) in [(Obj::CurrentAutoTune, 0), (Obj::CurrentKp, 400), (Obj::CurrentKi, 90)] {
        assert!(params.set(obj, v));
    }
    *p.drive_mut() = hal_sim::plant::IntoDrive::into_drive(Drive::boot(drive_core::DriveConfig::default(), &params, 0));
    p.restarted();
    let loop_ = p.bridges().and_then(|b| b.settings()).copied().expect("a loop");
    assert!((loop_.kp() - 40.0).abs() < 1e-4, "{loop_:?}");
    // The platform's current loop is the new drive's too: its gains take writes.
    assert_eq!(p.write(Obj::CurrentKp, 500), Ok(()));
    assert_eq!(p.write(Obj::PhaseCurrent, 1000), Ok(()));
    p.run_for(0.05);
    assert!((p.motor().phase_currents().0 - 1.0).abs() < 0.02);
}
