//! The control tick apart from the bus side (the firmware's arrangement: the tick owns its
//! controller, the bus side a model synced with it) does exactly what one controller shared by
//! both does: the same outputs at every tick and the same replies, through moves, re-targets,
//! reversals, stops, PP set-points, PVT runs and their stop, a fault and its clearing, and the
//! communication watchdog.

use drive_core::control::{Outputs, TICK_MICROS};
use drive_core::{Drive, crc};
use hal_sim::DEFAULT_MOTOR;
use hal_sim::inject::Change;
use hal_sim::motor::{Motor, MotorCatalog, MotorInputs};
use hal_sim::plant::Plant;
use proptest::prelude::*;

fn motor() -> Motor {
    let params = MotorCatalog::builtin().get(DEFAULT_MOTOR).cloned().expect("catalogue motor");
    Motor::new(params, MotorInputs::default())
}

fn w16(reg: u16, v: u16) -> Vec<u8> {
    let ([rh, rl], [vh, vl]) = (reg.to_be_bytes(), v.to_be_bytes());
    vec![1, 0x06, rh, rl, vh, vl]
}

fn w32(reg: u16, v: i32) -> Vec<u8> {
    let ([rh, rl], [a, b, c, d]) = (reg.to_be_bytes(), v.to_be_bytes());
    vec![1, 0x10, rh, rl, 0, 2, 4, a, b, c, d]
}

fn point(p: i32, v: i32, t: i32) -> Vec<u8> {
    let mut body = vec![1, 0x10, 0x60, 0x27, 0x00, 0x06, 0x0C];
    for x in [p, v, t] {
        body.extend(x.to_be_bytes());
    }
    body
}

fn read(reg: u16, n: u16) -> Vec<u8> {
    let ([rh, rl], [nh, nl]) = (reg.to_be_bytes(), n.to_be_bytes());
    vec![1, 0x03, rh, rl, nh, nl]
}

/// What happens at a time (ms after power-up).
enum Step {
    Frame(Vec<u8>),
    Inject(Change),
}

/// Runs `steps` on both arrangements to `end_ms`; every tick's outputs and every reply must be
/// the same, and the motor must have moved. Returns the split plant's outputs at the end and
/// the replies.
fn both(steps: Vec<(u64, Step)>, end_ms: u64) -> (Outputs, Vec<Vec<u8>>) {
    let (out, replies, moved) = both_compared(steps, end_ms);
    assert!(moved > 0, "the scenario moves the motor");
    (out, replies)
}

/// [`both`] without the motion check; the steps taken too.
fn both_compared(steps: Vec<(u64, Step)>, end_ms: u64) -> (Outputs, Vec<Vec<u8>>, i64) {
    let mut split = Plant::new(Drive::factory(), motor());
    let mut shared = Plant::combined(Drive::factory(), motor());
    let mut steps = steps.into_iter().peekable();
    let mut replies = Vec::new();
    let mut moved = 0i64;
    while split.next_tick().as_micros() < end_ms * 1000 {
        let now = split.next_tick();
        assert_eq!(now, shared.next_tick());
        while let Some((_, step)) = steps.next_if(|(at, _)| at * 1000 <= now.as_micros()) {
            match step {
                Step::Frame(body) => {
                    let mut frame = body.clone();
                    frame.extend(crc::crc16(&body).to_le_bytes());
                    split.drive_mut().on_rx(now, &frame);
                    shared.drive_mut().on_rx(now, &frame);
                }
                Step::Inject(c) => {
                    split.inject(c);
                    shared.inject(c);
                }
            }
        }
        split.advance_to(now);
        shared.advance_to(now);
        let t = now.plus_micros(TICK_MICROS / 2);
        for p in [&mut split, &mut shared] {
            p.drive_mut().on_timer(t);
        }
        let (a, b) =
            (split.drive_mut().take_reply().map(<[u8]>::to_vec), shared.drive_mut().take_reply().map(<[u8]>::to_vec));
        assert_eq!(a, b, "replies at {} µs", now.as_micros());
        replies.extend(a);
        let (a, b) = (split.outputs(), shared.outputs());
        assert_eq!(a, b, "outputs at {} µs", now.as_micros());
        moved += a.map_or(0, |o| o.steps.abs());
    }
    assert_eq!(
        split.drive().state().read(drive_core::od::Obj::Position),
        shared.drive().state().read(drive_core::od::Obj::Position)
    );
    (split.outputs().expect("ticked"), replies, moved)
}

/// A request of the kinds a master sends a drive while it moves: speeds, moves, re-targets,
/// stops, modes, the controlword and PP targets, enable, fault clearing, the watchdog, ramp
/// levels, a declared position, PVT control, reads.
fn any_request() -> impl Strategy<Value = Vec<u8>> {
    prop_oneof![
        (0..60_000i32).prop_map(|v| w32(0x6003, v)),
        (-200_000..200_000i32).prop_map(|v| w32(0x6005, v)),
        (-200_000..200_000i32).prop_map(|v| w32(0x6044, v)),
        Just(w16(0x6053, 0)),
        prop::sample::select(vec![0u16, 1, 4, 5]).prop_map(|m| w16(0x6007, m)),
        (0..0x40u16).prop_map(|cw| w16(0x6070, cw)),
        (-100_000..100_000i32).prop_map(|v| w32(0x6074, v)),
        (0..40_000i32).prop_map(|v| w32(0x6072, v)),
        (0..2u16).prop_map(|e| w16(0x6011, e)),
        Just(w16(0x6000, 0xFF)),
        (0..3u16).prop_map(|t| w16(0x2137, t)),
        (0..9u16).prop_map(|l| w16(0x600A, l)),
        (0..9u16).prop_map(|l| w16(0x600B, l)),
        (-1_000..1_000i32).prop_map(|v| w32(0x600E, v)),
        (0..4u16).prop_map(|c| w16(0x6017, c)),
        Just(read(0x6000, 2)),
        Just(read(0x600E, 2)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Whatever a master sends, whenever: the handoff gives every tick the outputs and every
    /// request the reply of one shared controller.
    #[test]
    fn any_requests_any_time(requests in prop::collection::vec((10..120u64, any_request()), 1..24)) {
        let mut at = 0;
        let steps = requests
            .into_iter()
            .map(|(gap, body)| {
                at += gap;
                frame(at, body)
            })
            .collect();
        both_compared(steps, at + 500);
    }
}

fn frame(at: u64, body: Vec<u8>) -> (u64, Step) {
    (at, Step::Frame(body))
}

#[test]
fn moves_retargets_reversals_and_stops() {
    let (out, replies) = both(
        vec![
            frame(10, w16(0x600C, 32)),
            frame(100, w32(0x6003, 32_000)),
            frame(200, w32(0x6005, 200_000)),
            frame(300, w32(0x6044, 400_000)),
            frame(500, w32(0x6044, 0)),
            frame(700, read(0x600E, 2)),
            frame(900, w16(0x6053, 0)),
            frame(1000, w32(0x6005, 2_000)),
            frame(1200, w32(0x6005, -50_000)),
        ],
        2500,
    );
    assert!(replies.iter().all(|r| r[1] & 0x80 == 0), "{replies:02X?}");
    assert_eq!(out.setpoint.velocity, 0.0);
}

#[test]
fn profile_position_set_points_buffered_and_immediate() {
    let (_, replies) = both(
        vec![
            frame(10, w16(0x6007, 4)),
            frame(50, w32(0x6072, 20_000)),
            frame(100, w32(0x6074, 30_000)),
            frame(150, w16(0x6070, 0x10)),
            frame(250, w16(0x6070, 0x00)),
            // Buffered behind the running one.
            frame(300, w32(0x6074, 10_000)),
            frame(350, w16(0x6070, 0x10)),
            frame(600, w16(0x6070, 0x00)),
            // Immediate, while moving.
            frame(700, w32(0x6074, 60_000)),
            frame(720, w16(0x6070, 0x30)),
            frame(1500, read(0x6071, 1)),
        ],
        3000,
    );
    assert!(replies.iter().all(|r| r[1] & 0x80 == 0), "{replies:02X?}");
}

/// A PVT run from the table at 20 000 pps, started at 120 ms.
fn pvt_run() -> Vec<(u64, Step)> {
    let mut steps = vec![frame(10, w16(0x6007, 2)), frame(20, w16(0x6018, 0)), frame(30, w16(0x2112, 1))];
    for (k, (p, v, t)) in [(0, 0, 0), (1000, 20_000, 100), (3000, 20_000, 100), (4000, 0, 100)].into_iter().enumerate()
    {
        steps.push(frame(50 + 10 * k as u64, point(p, v, t)));
    }
    steps.extend([frame(100, w16(0x601C, 3)), frame(120, w16(0x6017, 1))]);
    steps
}

#[test]
fn pvt_runs_from_the_table_and_a_stop_ends_them() {
    let mut steps = pvt_run();
    steps.extend([frame(250, w16(0x6017, 0)), frame(400, read(0x600E, 2))]);
    // The stop decelerates at 0x600B's level 8 (5210 pps²): 3.8 s from 20000 pps.
    let (out, replies) = both(steps, 4500);
    assert!(replies.iter().all(|r| r[1] & 0x80 == 0), "{replies:02X?}");
    assert_eq!(out.setpoint.velocity, 0.0);
}

/// The motion command's emergency stop (0x21A0 = 7) ends a PVT run at the quick-stop
/// deceleration 0x2183 (320 000 pps²: 63 ms from 20 000 pps).
#[test]
fn the_motion_commands_stop_ends_a_pvt_run() {
    let mut steps = pvt_run();
    steps.extend([frame(250, w16(0x21A0, 7)), frame(340, read(0x6001, 1))]);
    let (out, replies) = both(steps, 400);
    assert!(replies.iter().all(|r| r[1] & 0x80 == 0), "{replies:02X?}");
    assert_eq!(out.setpoint.velocity, 0.0);
    // 0x6001 bit 3 (busy) is clear: the run is over.
    let status = replies.last().expect("the status read");
    assert_eq!(status.get(4).map(|b| b & 0x08), Some(0), "{status:02X?}");
}

#[test]
fn a_fault_stops_and_clearing_it_moves_again() {
    let (_, replies) = both(
        vec![
            frame(10, w32(0x6003, 20_000)),
            frame(50, w32(0x6005, 1_000_000)),
            (200, Step::Inject(Change::DriverTemperature(150.0))),
            (400, Step::Inject(Change::DriverTemperature(40.0))),
            frame(500, read(0x6000, 1)),
            frame(520, w16(0x6000, 0xFF)),
            frame(540, w32(0x6005, 5_000)),
        ],
        1200,
    );
    assert!(replies.len() >= 4);
}

#[test]
fn the_watchdog_stops_a_move_when_the_master_falls_silent() {
    let (out, _) = both(
        vec![
            frame(10, w16(0x2137, 2)),
            frame(50, w32(0x6003, 20_000)),
            frame(100, w32(0x6005, 1_000_000)),
            frame(150, read(0x600E, 2)),
        ],
        1500,
    );
    assert_eq!(out.setpoint.velocity, 0.0);
}

/// A position declared and a move planned in one action of the bus side, before a sync (a
/// homing's offset move does so): the tick takes the plan in the declared position's frame, so
/// the stage emits the move's steps and no burst of the shift between the two frames.
#[test]
fn a_declared_position_and_a_move_before_a_sync_emit_the_move_only() {
    use drive_core::od::Obj;
    for split in [true, false] {
        let mut p =
            if split { Plant::new(Drive::factory(), motor()) } else { Plant::combined(Drive::factory(), motor()) };
        for (obj, v) in [(Obj::Microsteps, 16), (Obj::MaxSpeed, 3200)] {
            assert_eq!(p.write(obj, v), Ok(()));
        }
        p.run_for(0.02);
        let r0 = p.rotor_microsteps();
        assert_eq!(p.write(Obj::Position, 10_000), Ok(()));
        assert_eq!(p.write(Obj::AbsoluteMove, 11_600), Ok(()));
        p.run_for(2.0);
        let moved = p.rotor_microsteps() - r0;
        assert!((moved - 1600.0).abs() < 0.5, "split {split}: the rotor moved {moved}, not 1600");
        assert_eq!(p.drive().state().read(Obj::Position), 11_600);
    }
}
