//! Injected faults act on the motor model physically, and the drive sees them only through what
//! it measures (supply, temperature, bridge currents, open-load flags).

use drive_core::Drive;
use drive_core::od::Obj;
use hal_sim::DEFAULT_MOTOR;
use hal_sim::inject::{Change, Scheduled};
use hal_sim::motor::{Motor, MotorCatalog, MotorInputs, PhaseFault};
use hal_sim::plant::Plant;

/// The NEMA 17 at 24 V, 1/16 microsteps, 1000 mA, speed 3200 pps (one turn a second).
fn plant() -> Plant {
    let params = MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().expect("catalogue motor");
    let mut plant = Plant::new(Drive::factory(), Motor::new(params, MotorInputs::default()));
    for (obj, v) in [(Obj::Microsteps, 16), (Obj::PhaseCurrent, 1000), (Obj::MaxSpeed, 3200)] {
        set(&mut plant, obj, v);
    }
    plant
}

fn set(plant: &mut Plant, obj: Obj, value: u32) {
    assert_eq!(plant.write(obj, value), Ok(()), "{obj:?} = {value}");
}

fn run(plant: &mut Plant, secs: f64) {
    plant.run_for(secs);
}

fn read(plant: &Plant, obj: Obj) -> u32 {
    plant.drive().state().read(obj)
}

/// The largest |phase current| over `secs`, A.
fn peak_current(plant: &mut Plant, phase: usize, secs: f64) -> f64 {
    let mut peak = 0.0f64;
    for _ in 0..(secs * 20_000.0) as u32 {
        run(plant, 50e-6);
        let (a, b) = plant.motor().phase_currents();
        peak = peak.max(if phase == 0 { a.abs() } else { b.abs() });
    }
    peak
}

#[test]
fn an_open_coil_carries_no_current_and_the_drive_latches_phase_loss() {
    let mut p = plant();
    // At rest on a full step phase A carries the whole current.
    run(&mut p, 0.05);
    assert!(p.motor().phase_currents().0 > 0.9);
    p.inject(Change::Phase(0, PhaseFault::Open));
    run(&mut p, 0.001);
    assert_eq!(p.motor().phase_currents().0, 0.0);
    assert_eq!(read(&p, Obj::ErrorStatus), 1 << 1);
    assert_eq!(read(&p, Obj::AlarmCode), 11);
    assert!(!p.outputs().expect("ticked").enabled);
}

#[test]
fn a_shorted_output_is_an_over_current_and_the_stage_goes_off() {
    let mut p = plant();
    run(&mut p, 0.05);
    p.inject(Change::Phase(0, PhaseFault::Short));
    run(&mut p, 0.001);
    assert_eq!(read(&p, Obj::ErrorStatus), 1 << 3);
    assert_eq!(read(&p, Obj::AlarmCode), 10);
    run(&mut p, 0.05);
    assert!(p.motor().phase_currents().0.abs() < 1e-3);
}

#[test]
fn a_blocked_rotor_stays_while_the_setpoint_moves() {
    let mut p = plant();
    run(&mut p, 0.05);
    p.inject(Change::Blocked(true));
    let held = p.rotor_microsteps();
    set(&mut p, Obj::RelativeMove, 3200);
    run(&mut p, 1.5);
    assert_eq!(p.outputs().expect("ticked").setpoint.whole, 3200);
    assert_eq!(p.rotor_microsteps(), held);
    p.inject(Change::Blocked(false));
    run(&mut p, 0.5);
    // Released, the rotor snaps to the nearest equilibrium of the field: a whole electrical cycle
    // (64 microsteps) away from the setpoint at most.
    assert!(
        (p.rotor_microsteps() - 3200.0).rem_euclid(64.0).min(64.0 - (p.rotor_microsteps() - 3200.0).rem_euclid(64.0))
            < 2.0
    );
}

#[test]
fn a_supply_ramp_lowers_the_current_at_speed_then_trips_under_voltage() {
    let mut p = plant();
    set(&mut p, Obj::UnderVoltage, 5000);
    set(&mut p, Obj::AccelLevel, 1);
    set(&mut p, Obj::Mode, 1);
    set(&mut p, Obj::MaxSpeed, 16_000);
    run(&mut p, 1.0);
    let at_24 = peak_current(&mut p, 0, 0.1);
    p.inject(Change::SupplyRamp { to_v: 6.0, seconds: 0.2 });
    run(&mut p, 0.2);
    assert_eq!(p.measurements().supply_mv, Some(6000));
    let at_6 = peak_current(&mut p, 0, 0.1);
    assert!(at_6 < 0.8 * at_24, "{at_6} A at 6 V, {at_24} A at 24 V");
    // Down to 4 V: under the threshold.
    p.inject(Change::SupplyRamp { to_v: 4.0, seconds: 0.01 });
    run(&mut p, 0.02);
    assert_eq!(read(&p, Obj::ErrorStatus), 1 << 5);
    assert_eq!(read(&p, Obj::AlarmCode), 13);
}

#[test]
fn scheduled_changes_apply_at_their_time() {
    let mut p = plant();
    p.schedule(vec!["300:temp=90".parse::<Scheduled>().expect("spec"), "100:load=0.1".parse().expect("spec")]);
    run(&mut p, 0.099);
    assert_eq!(p.motor().inputs().load_torque_nm, 0.0);
    run(&mut p, 0.002);
    assert_eq!(p.motor().inputs().load_torque_nm, 0.1);
    assert_eq!(read(&p, Obj::ErrorStatus), 0);
    run(&mut p, 0.2);
    assert_eq!(p.measurements().temperature_c, Some(90));
    assert_eq!(read(&p, Obj::ErrorStatus), 1);
    assert_eq!(read(&p, Obj::AlarmCode), 15);
}

#[test]
fn an_injector_reaches_the_plant_from_another_thread() {
    let mut p = plant();
    let injector = p.injector();
    std::thread::spawn(move || injector.inject(Change::Supply(70.0))).join().expect("thread");
    run(&mut p, 0.001);
    assert_eq!(p.motor().inputs().supply_v, 70.0);
    assert_eq!(read(&p, Obj::DriveFaults), 1);
    assert_eq!(read(&p, Obj::AlarmCode), 14);
}

#[test]
fn the_fault_history_survives_a_power_cycle() {
    use drive_core::DriveConfig;
    use drive_core::drive::SystemRequest;
    use hal_sim::flash::{PAGES, SimFlash};

    let params = MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().expect("catalogue motor");
    let config = DriveConfig { can_save: true, ..Default::default() };
    let mut store = hal_sim::store(SimFlash::erased(PAGES)).expect("store");
    let drive = hal_sim::boot(&mut store, config, false, None);
    let mut p = Plant::new(drive, Motor::new(params.clone(), MotorInputs::default()));
    run(&mut p, 0.05);
    p.inject(Change::Phase(0, PhaseFault::Open));
    run(&mut p, 0.1);
    hal_sim::serve_request(p.drive_mut(), &mut store);
    // Still open: cleared, it latches again, a second entry.
    set(&mut p, Obj::ErrorStatus, 1 << 1);
    run(&mut p, 0.2);
    hal_sim::serve_request(p.drive_mut(), &mut store);
    let history = |p: &Plant| (0x213C..0x2150).step_by(2).map(|k| read_at(p, k)).collect::<Vec<u32>>();
    let before = history(&p);
    assert_eq!(read(&p, Obj::AlarmCount), 2);
    assert_eq!(before[0] >> 24, 11);
    assert_eq!(before[1] >> 24, 11);
    assert!(before[0] & 0xFF_FFFF > before[1] & 0xFF_FFFF, "newest first: {before:08X?}");
    assert!(before[2..].iter().all(|&e| e == 0));

    // Power cycle on the same flash.
    let bytes = store.into_flash().bytes().to_vec();
    let mut store = hal_sim::store(SimFlash::from_bytes(bytes)).expect("store");
    let drive = hal_sim::boot(&mut store, config, false, None);
    let mut p = Plant::new(drive, Motor::new(params, MotorInputs::default()));
    assert_eq!(history(&p), before);
    assert_eq!(read(&p, Obj::AlarmCount), 2);
    assert_eq!(p.drive_mut().take_system_request(), None, "nothing new to save");
    // A new alarm goes on top of the old ones, and is saved.
    run(&mut p, 0.05);
    p.inject(Change::DriverTemperature(100.0));
    run(&mut p, 0.01);
    assert_eq!(read(&p, Obj::AlarmCount), 3);
    let after = history(&p);
    assert_eq!((after[0] >> 24, &after[1..3]), (15, &before[..2]));
    assert!(p.drive_mut().has_system_request());
    assert_eq!(p.drive_mut().take_system_request(), Some(SystemRequest::SaveFaults));
    assert_eq!(p.drive_mut().take_system_request(), None, "once");
}

/// The 32-bit object at register `addr`.
fn read_at(plant: &Plant, addr: u16) -> u32 {
    let obj = drive_core::od::OBJECTS.iter().find(|d| d.addr == addr).expect("an object").obj;
    read(plant, obj)
}
