// The closed loop on the physical motor model: the encoder corrects what a load takes away, the
// servo loop holds its target, and a following error beyond 0x605C (or 0x21D0's encoder counts)
// latches alarm 25. Included by `closed_loop.rs` (the ideal chopper) and `closed_loop_bridges.rs`
// (the G474's bridges: the servo loop's current then on the rotor's q axis, field-oriented),
// each with its `STAGE`.

use drive_core::od::Obj;
use drive_core::{Drive, DriveConfig, Params};
use hal_sim::DEFAULT_MOTOR;
use hal_sim::encoder::EncoderFault;
use hal_sim::inject::Change;
use hal_sim::motor::{Motor, MotorCatalog, MotorInputs};
use hal_sim::plant::Plant;

/// Encoder counts a turn: 1000 lines ×4.
const COUNTS: f64 = 4000.0;

/// The NEMA 17 at 24 V, 1/16 microsteps, 1000 mA, with the given feedback and loop.
fn plant(feedback: u32, torque_loop: u32) -> Plant {
    plant_with(feedback, torque_loop, MotorInputs::default())
}

/// [`plant`] with the motor's load and supply.
fn plant_with(feedback: u32, torque_loop: u32, inputs: MotorInputs) -> Plant {
    let mut params = Params::factory();
    for (obj, v) in [
        (Obj::Feedback, feedback),
        (Obj::EncoderCpr, 1000),
        (Obj::TorqueLoop, torque_loop),
        (Obj::Microsteps, 16),
        (Obj::PhaseCurrent, 1000),
        (Obj::StallLength, 255),
    ] {
        assert!(params.set(obj, v), "{obj:?}");
    }
    let motor = MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().expect("catalogue motor");
    let mut plant = Plant::new(Drive::boot(DriveConfig::default(), &params, 0), Motor::new(motor, inputs));
    plant.set_power_stage(STAGE, hal_sim::bridges::SensingOptions::default());
    plant
}

fn set(plant: &mut Plant, obj: Obj, value: u32) {
    assert_eq!(plant.write(obj, value), Ok(()), "{obj:?} = {value}");
}

fn read(plant: &Plant, obj: Obj) -> i32 {
    plant.drive().state().read_i32(obj)
}

fn run(plant: &mut Plant, secs: f64) {
    plant.run_for(secs);
}

/// The rotor in position units: microsteps (1/16) in open loop, encoder counts in closed loop.
fn rotor(plant: &Plant, closed: bool) -> f64 {
    let full = plant.motor().rotor_full_steps();
    if closed { full * COUNTS / 200.0 } else { full * 16.0 }
}

/// Moves four turns at two turns a second (in the loop's units), with 330 g·cm² of load inertia,
/// and steps a load of `load_nm` in while cruising, for half a second from 0.8 s + `phase_us`;
/// returns the final |rotor − target| in full steps. The example `closed_loop` draws this move.
fn loaded_move(closed: bool, torque_loop: u32, load_nm: f64, phase_us: f64) -> (Plant, f64) {
    let inputs = MotorInputs { load_inertia_kgm2: 3.3e-5, ..MotorInputs::default() };
    let mut p = plant_with(u32::from(closed), torque_loop, inputs);
    let per_turn = if closed { COUNTS } else { 3200.0 };
    set(&mut p, Obj::MaxSpeed, (2.0 * per_turn) as u32);
    set(&mut p, Obj::RelativeMove, (4.0 * per_turn) as u32);
    run(&mut p, 0.8 + phase_us * 1e-6);
    p.inject(Change::LoadTorque(load_nm));
    run(&mut p, 0.5);
    p.inject(Change::LoadTorque(0.0));
    run(&mut p, 3.0);
    let target = 4.0 * per_turn;
    let off = (rotor(&p, closed) - target).abs() / (per_turn / 200.0);
    (p, off)
}

#[test]
fn a_load_step_that_makes_the_open_loop_lose_steps_leaves_the_closed_loop_on_target() {
    // K_m · 1 A = 0.21 N·m; 0.17 N·m (81 %) pulls the open loop out at 2 turns/s, and the load
    // then drives the rotor back. The closed loops hold with a margin: at 0.19 N·m (91 %) the
    // position loop's rotor can come to rest with 0.02 N·m to spare, too little to break away
    // from the detent torque, and whether it does depends on the phase the load comes in at.
    // So three phases, a step apart.
    let load = 0.17;
    for phase_us in [0.0, 150.0, 300.0] {
        let (open, lost) = loaded_move(false, 0, load, phase_us);
        assert!(lost >= 4.0, "the open loop should lose steps: {lost} full steps off");
        assert_eq!(open.drive().state().position(), 12_800);
        for torque_loop in [0, 1] {
            let (p, off) = loaded_move(true, torque_loop, load, phase_us);
            assert_eq!(p.drive().state().position(), 16_000, "loop {torque_loop}");
            assert!(off < 0.25, "loop {torque_loop}, phase {phase_us} µs: {off} full steps off target");
            assert_eq!(read(&p, Obj::DriveFaults), 0);
            assert_eq!(read(&p, Obj::ControllerStatus), 0);
        }
    }
}

#[test]
fn the_closed_loop_reads_the_encoder_into_its_objects() {
    let mut p = plant(1, 0);
    set(&mut p, Obj::MaxSpeed, 4000);
    set(&mut p, Obj::RelativeMove, 8000);
    run(&mut p, 1.0);
    // Cruising at 4000 counts/s: the measured speed says so (a count every five ticks: the
    // reading ripples, its mean does not).
    let mut sum = 0;
    for _ in 0..200 {
        p.advance_to(p.next_tick());
        sum += read(&p, Obj::RealSpeed);
    }
    assert!((sum / 200 - 4000).abs() < 40, "{}", sum / 200);
    run(&mut p, 2.0);
    assert_eq!(read(&p, Obj::Position), 8000);
    assert!((read(&p, Obj::EncoderPosition) - 8000).abs() <= 4, "{}", read(&p, Obj::EncoderPosition));
    assert!(read(&p, Obj::FollowingError).abs() <= 4);
    // Declaring a position sets the zero offset; the motor does not move.
    set(&mut p, Obj::Position, 100);
    run(&mut p, 0.2);
    assert_eq!(read(&p, Obj::ZeroOffset), 100 - read(&p, Obj::EncoderPosition));
    assert!((rotor(&p, true) - 8000.0).abs() < 4.0);
    assert_eq!(read(&p, Obj::Position), 100);
}

#[test]
fn a_blocked_rotor_latches_the_position_error() {
    for torque_loop in [0, 1] {
        let mut p = plant(1, torque_loop);
        // 1.5 full steps of following error (at 1/16): 24 microsteps.
        set(&mut p, Obj::StallLength, 24);
        set(&mut p, Obj::MaxSpeed, 4000);
        set(&mut p, Obj::RelativeMove, 40_000);
        run(&mut p, 0.5);
        let before = rotor(&p, true);
        p.inject(Change::Blocked(true));
        run(&mut p, 0.2);
        assert_eq!(read(&p, Obj::DriveFaults), 1 << 2, "loop {torque_loop}");
        assert_eq!(read(&p, Obj::AlarmCode), 25);
        assert_eq!(read(&p, Obj::ControllerStatus) & (1 << 2), 1 << 2);
        assert!(!p.outputs().expect("ticked").enabled);
        // Nothing turned while blocked; a move is refused until the bits are cleared.
        assert!((rotor(&p, true) - before).abs() < 1.0);
        let state = p.drive().state();
        assert!(state.check(Obj::RelativeMove, 100).is_err());
        p.inject(Change::Blocked(false));
        set(&mut p, Obj::DriveFaults, 0x0F);
        set(&mut p, Obj::ControllerStatus, 0xFF);
        run(&mut p, 0.1);
        set(&mut p, Obj::RelativeMove, 400);
        run(&mut p, 1.0);
        assert_eq!(read(&p, Obj::DriveFaults), 0);
        let target = p.drive().state().position() as f64;
        assert!((rotor(&p, true) - target).abs() < 4.0, "loop {torque_loop}");
    }
}

/// A move at 4000 microsteps a second for half a second, then the rotor blocked.
fn move_then_block(p: &mut Plant) {
    set(p, Obj::MaxSpeed, 4000);
    set(p, Obj::RelativeMove, 400_000);
    run(p, 0.5);
    p.inject(Change::Blocked(true));
}

/// The rotor freed and the position error cleared, `obj` set to `value`, then
/// [`move_then_block`] again.
fn clear_then_block_again(p: &mut Plant, obj: Obj, value: u32) {
    p.inject(Change::Blocked(false));
    set(p, obj, value);
    set(p, Obj::DriveFaults, 0x0F);
    set(p, Obj::ControllerStatus, 0xFF);
    run(p, 0.1);
    move_then_block(p);
}

/// Seed 002's 0258 (our 0x21D0): a position error limit in encoder counts replaces 0x605C's
/// microsteps while it is not 0.
#[test]
fn a_position_error_limit_in_encoder_counts_replaces_the_stall_length() {
    let mut p = plant(1, 0);
    // 4000 counts: a turn, 3 200 microsteps; 0x605C's 255 microsteps no longer count.
    set(&mut p, Obj::PositionErrorLimit, 4000);
    move_then_block(&mut p);
    // 0.3 s blocked at 4 000 microsteps a second: about 1 200 microsteps behind, past 255.
    run(&mut p, 0.3);
    assert_eq!(read(&p, Obj::DriveFaults), 0, "within a turn");
    run(&mut p, 1.0);
    assert_eq!(read(&p, Obj::AlarmCode), 25, "a turn behind");
    assert_eq!(read(&p, Obj::DriveFaults), 1 << 2);
    // Back to 0: 0x605C's 255 microsteps again.
    clear_then_block_again(&mut p, Obj::PositionErrorLimit, 0);
    run(&mut p, 0.2);
    assert_eq!(read(&p, Obj::AlarmCode), 25, "0x605C's 255 microsteps");
}

#[test]
fn a_lost_encoder_latches_alarm_27() {
    let mut p = plant(1, 0);
    run(&mut p, 0.1);
    p.inject(Change::Encoder(EncoderFault::Lost));
    run(&mut p, 0.01);
    assert_eq!(read(&p, Obj::DriveFaults), 1 << 3);
    assert_eq!(read(&p, Obj::AlarmCode), 27);
    assert!(!p.outputs().expect("ticked").enabled);
}

/// Seed 003's 0x200F (our 0x21D6): a position error angle in degrees of the shaft replaces the
/// other limits while it is not 0; its 0x200E (0x21D7) = 0 lets the loop follow without the
/// alarm. Through the EC-57 map, the alarm lands in its fault list 0x201C.1.
#[test]
fn a_position_error_angle_in_degrees_and_its_alarm_switch() {
    let mut p = plant(1, 0);
    // 90°: 800 microsteps at 1/16; 0x605C's 255 no longer count.
    set(&mut p, Obj::PositionErrorAngle, 90);
    move_then_block(&mut p);
    // 0.15 s blocked at 4 000 microsteps a second: about 600 behind, within 90°.
    run(&mut p, 0.15);
    assert_eq!(read(&p, Obj::DriveFaults), 0, "within 90°");
    run(&mut p, 0.3);
    assert_eq!(read(&p, Obj::AlarmCode), 25, "beyond 90°");
    // The alarm off: two turns behind and no alarm.
    clear_then_block_again(&mut p, Obj::PositionErrorAlarm, 0);
    run(&mut p, 2.0);
    assert_eq!(read(&p, Obj::DriveFaults), 0, "no alarm with 0x21D7 = 0");
    assert!(read(&p, Obj::FollowingError).abs() > 4000, "a turn behind and more");
}

/// The same through the EC-57 map's registers: 0x200E = 1 and 0x200F = 45° written as the
/// manual has them (sub-indexed frames), an overload stops the rotor, the alarm is in the fault
/// list 0x201C.1.
#[test]
fn the_ec57_position_error_alarm_lands_in_its_fault_list() {
    let mut params = Params::factory();
    for (obj, v) in [
        (Obj::RegisterMap, 3),
        (Obj::Feedback, 1),
        (Obj::EncoderCpr, 1000),
        (Obj::Microsteps, 16),
        (Obj::PhaseCurrent, 1000),
    ] {
        assert!(params.set(obj, v), "{obj:?}");
    }
    let motor = MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().expect("catalogue motor");
    let drive = Drive::boot_with_map(DriveConfig::default(), drive_core::maps::Maps::ec57(), &params, 0);
    let mut p = Plant::new(drive, Motor::new(motor, MotorInputs::default()));
    let request = |p: &mut Plant, body: &[u8]| {
        let reply = p.request(body).unwrap_or_else(|| panic!("no reply to {body:02X?}"));
        assert_eq!(reply[1] & 0x80, 0, "{body:02X?} refused: {reply:02X?}");
        reply
    };
    // 0x200E = 1, 0x200F = 45: 400 microsteps at 1/16.
    request(&mut p, &[1, 0x06, 0x20, 0x0E, 0, 0, 1]);
    request(&mut p, &[1, 0x06, 0x20, 0x0F, 0, 0, 45]);
    // A run at 4000 microsteps a second through the window: 0x21A3 velocity, 0x21A0 = 3.
    request(&mut p, &[1, 0x10, 0x21, 0xA3, 0xFF, 0, 2, 4, 0, 0, 0x0F, 0xA0]);
    request(&mut p, &[1, 0x06, 0x21, 0xA0, 0xFF, 0, 3]);
    run(&mut p, 0.5);
    p.inject(Change::Blocked(true));
    run(&mut p, 0.5);
    assert_eq!(read(&p, Obj::AlarmCode), 25);
    let list = request(&mut p, &[1, 0x03, 0x20, 0x1C, 1, 0, 2]);
    assert_eq!(&list[2..7], &[4, 0, 25, 0, 0], "the fault list: 25 newest, nothing before");
}

/// Seed 003's 0x2020 (our 0x21D9): the in-position output (OUT1, function 3) from the drive's
/// encoder window (1) or from the plan's end (0). A blocked rotor with the position error alarm
/// off: the plan ends, the encoder is far behind.
#[test]
fn the_in_position_output_from_the_encoder_or_from_the_plan() {
    /// OUT1, GPIO5.
    const OUT1: u16 = 1 << 4;
    let mut p = plant(1, 0);
    set(&mut p, Obj::OutputFunction1, 3);
    set(&mut p, Obj::PositionErrorAlarm, 0);
    set(&mut p, Obj::MaxSpeed, 4000);
    p.inject(Change::Blocked(true));
    set(&mut p, Obj::RelativeMove, 2000);
    run(&mut p, 1.5);
    assert!(p.drive().state().controller().axis().is_still(), "the plan has ended");
    assert!(read(&p, Obj::FollowingError).abs() > 1000, "the rotor far behind");
    let gpio = |p: &Plant| p.outputs().expect("ticked").gpio;
    assert_eq!(gpio(&p) & OUT1, 0, "not in position by the encoder");
    set(&mut p, Obj::InPositionSource, 0);
    run(&mut p, 0.01);
    assert_eq!(gpio(&p) & OUT1, OUT1, "in position by the plan");
}

/// A touch probe in closed loop captures the encoder's position (counts) at the input's edge:
/// within a count of the rotor's.
#[test]
fn a_touch_probe_captures_the_encoder_in_closed_loop() {
    let mut p = plant(1, 0);
    let cam = hal_sim::machine::Switch::parse("ext1:pnp:100").expect("switch");
    *p.machine_mut() = hal_sim::machine::Machine::new(vec![cam], None);
    set(&mut p, Obj::InputFunction1, 22);
    set(&mut p, Obj::MaxSpeed, 4000);
    set(&mut p, Obj::RelativeMove, 4000);
    let mut rotor_at_edge = None;
    for _ in 0..40_000 {
        // One tick at a time: the rotor as the tick that captured saw it.
        p.advance_to(p.next_tick());
        if rotor_at_edge.is_none() && read(&p, Obj::ProbeStatus) & 2 != 0 {
            rotor_at_edge = Some(rotor(&p, true));
        }
    }
    let rotor = rotor_at_edge.expect("probe 2 fired");
    let captured = f64::from(read(&p, Obj::ProbePosition2));
    // 100 full steps: half a turn, 2000 counts.
    assert!((captured - 2000.0).abs() <= 2.0, "captured {captured} at the cam's 2000 counts");
    assert!((captured - rotor).abs() <= 1.0, "captured {captured}, the rotor at {rotor:.2} counts");
}
