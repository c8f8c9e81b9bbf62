//! The handoff with a planning margin, as on a microcontroller: the bus side plans a request's
//! motion for a tick `margin` later, lends its model, and the tick takes the plan over at that
//! tick, seamlessly; a plan lent late is taken late (and said so); a plan the tick's own stop
//! overtook is dropped and the motor stays stopped.

use drive_core::control::{Outputs, TICK_MICROS};
use drive_core::controller::handoff::{Handover, TickSide};
use drive_core::faults::Inputs;
use drive_core::od::Obj;
use drive_core::{Drive, Instant};

mod common;
use common::frame;

const MARGIN_US: u64 = 2_000;

fn w16(reg: u16, v: u16) -> Vec<u8> {
    let ([rh, rl], [vh, vl]) = (reg.to_be_bytes(), v.to_be_bytes());
    frame(&[1, 0x06, rh, rl, vh, vl])
}

fn w32(reg: u16, v: i32) -> Vec<u8> {
    let ([rh, rl], [a, b, c, d]) = (reg.to_be_bytes(), v.to_be_bytes());
    frame(&[1, 0x10, rh, rl, 0, 2, 4, a, b, c, d])
}

/// Serves `request` on `drive` at `now` (the frame arrived whole t3.5 earlier); whether accepted.
fn serve(drive: &mut Drive, now: Instant, request: &[u8]) -> bool {
    let t35 = drive.baud().t35_micros();
    drive.on_rx(Instant::from_micros(now.as_micros() - t35), request);
    drive.on_timer(now);
    drive.take_reply().is_some_and(|r| r[1] & 0x80 == 0)
}

fn tick_time(k: u64) -> Instant {
    Instant::from_micros(1_000_000 + k * TICK_MICROS)
}

/// A drive at 20000 pps (0x6003; its factory speed is 0).
fn drive() -> Drive {
    let mut d = Drive::factory();
    assert!(serve(&mut d, Instant::from_micros(500_000), &w32(0x6003, 20_000)));
    d
}

/// A drive whose tick owns its controller, with the planning margin.
fn split() -> (Drive, TickSide) {
    let mut d = drive();
    d.state_mut().set_plan_margin(MARGIN_US);
    let tick = d.state().tick_side();
    (d, tick)
}

/// Ticks `tick` at tick `k`, syncing first if `lent`; the handover if it synced.
fn tick_at(d: &mut Drive, tick: &mut TickSide, k: u64, lent: bool, inputs: &Inputs) -> (Outputs, Option<Handover>) {
    let now = tick_time(k);
    let h = lent.then(|| synced(d, tick, now));
    let out = tick.tick(now, inputs, d.state().shared());
    (out, h)
}

/// Syncs `d`'s model into `tick` at `now`; once synced, the model's axis is the tick's (the
/// sync copies back only what the tick changed).
fn synced(d: &mut Drive, tick: &mut TickSide, now: Instant) -> Handover {
    let h = d.sync_here(tick, now);
    if h != Handover::Waiting {
        let walk = |a: &drive_core::motion::axis::Axis| (a.setpoint(), a.target(), a.version(), a.activation());
        assert_eq!(walk(d.state().controller().axis()), walk(tick.controller().axis()), "after {h:?} at {now:?}");
    }
    h
}

#[test]
fn a_plan_takes_over_at_its_tick_as_if_requested_a_margin_later() {
    let (mut d, mut tick) = split();
    let mut shared = drive();
    let request_at = 100;
    let margin_ticks = MARGIN_US / TICK_MICROS;
    let mut lent = false;
    let mut planned_at = None;
    for k in 0..40_000u64 {
        let (out, h) = tick_at(&mut d, &mut tick, k, lent, &Inputs::default());
        match h {
            Some(Handover::Waiting) | None => {}
            Some(Handover::Planned) => {
                (lent, planned_at) = (false, Some(k));
            }
            Some(other) => panic!("{other:?} at tick {k}"),
        }
        let expected = shared.tick(tick_time(k));
        assert_eq!(out, expected, "tick {k}");
        // Requests arrive between ticks.
        if k == request_at {
            assert!(serve(&mut d, tick_time(k).plus_micros(10), &w32(0x6005, 20_000)));
            lent = true;
        }
        if k == request_at + margin_ticks {
            assert!(serve(&mut shared, tick_time(k).plus_micros(10), &w32(0x6005, 20_000)));
        }
    }
    assert_eq!(planned_at, Some(request_at + margin_ticks + 1));
    // A sync before a request refreshes the model.
    assert_eq!(synced(&mut d, &mut tick, tick_time(40_000)), Handover::Done);
    let position = |d: &Drive| d.state().read(drive_core::od::Obj::Position);
    assert!(position(&d) > 0);
    assert_eq!(position(&d), position(&shared), "the model learns where the axis is");
}

#[test]
fn a_plan_lent_late_is_taken_late() {
    let (mut d, mut tick) = split();
    assert!(serve(&mut d, tick_time(10), &w32(0x6005, 20_000)));
    // The first tick that syncs is 30 ticks after the plan's first.
    let first = 10 + MARGIN_US / TICK_MICROS;
    for k in 0..first + 30 {
        tick_at(&mut d, &mut tick, k, false, &Inputs::default());
    }
    let (_, h) = tick_at(&mut d, &mut tick, first + 30, true, &Inputs::default());
    assert_eq!(h, Some(Handover::Late(30)));
}

#[test]
fn a_plan_overtaken_by_a_fault_is_dropped_and_nothing_moves() {
    let (mut d, mut tick) = split();
    let hot = Inputs { temperature_c: Some(150), ..Inputs::default() };
    let (mut lent, mut handovers, mut stopped_at) = (false, Vec::new(), None);
    for k in 0..3_000u64 {
        match k {
            10 => lent = serve(&mut d, tick_time(k), &w32(0x6005, 200_000)),
            // A re-target while moving, overtaken by a fault before its first tick.
            1_000 => lent = serve(&mut d, tick_time(k), &w32(0x6044, -5_000)),
            _ => {}
        }
        let inputs = if k >= 1_010 { hot } else { Inputs::default() };
        let (out, h) = tick_at(&mut d, &mut tick, k, lent, &inputs);
        if let Some(h) = h.filter(|&h| h != Handover::Waiting) {
            handovers.push(h);
            lent = false;
        }
        if k >= 1_010 {
            assert_eq!(*stopped_at.get_or_insert(out.setpoint.whole), out.setpoint.whole, "tick {k}: stopped");
            assert!(!out.enabled);
        }
    }
    assert_eq!(handovers, [Handover::Planned, Handover::Dropped]);
    assert!(stopped_at.is_some_and(|p| p > 0), "the move had started");
    assert_ne!(d.state().read(drive_core::od::Obj::ErrorStatus), 0, "the model shows the fault");
}

/// As `cargo xtask tick-cost` drives the firmware under QEMU: a move, re-targeted four times
/// while it cruises; each request served on a freshly synced model and handed over `deliver`
/// ticks later. The tick's steps add up to the model's position, which is the last target.
fn retargets(margin_us: u64, deliver: u64) -> (i64, i64, Vec<Handover>) {
    let mut d = drive();
    d.state_mut().set_plan_margin(margin_us);
    let mut tick = d.state().tick_side();
    let mut requests: Vec<Vec<u8>> =
        vec![frame(&[1, 0x10, 0x60, 0x02, 0, 5, 10, 0, 0, 0, 0, 0x0F, 0xA0, 0, 0, 0x1F, 0x40])];
    let retargets = [(1000, 12_000u16), (3000, 14_000), (5000, 16_000), (7000, 18_000)];
    let (mut emitted, mut handovers, mut lend_at, mut next) = (0i64, Vec::new(), None, 0usize);
    for k in 0..200_000u64 {
        let lent = lend_at.is_some_and(|at| k >= at);
        let (out, h) = tick_at(&mut d, &mut tick, k, lent, &Inputs::default());
        emitted += out.steps;
        if std::env::var("DBG").is_ok()
            && (h.is_some_and(|h| h != Handover::Waiting && h != Handover::Done) || k % 5000 == 0)
        {
            eprintln!(
                "{k} {h:?} set {} com {} emitted {emitted} v {}",
                out.setpoint.whole, out.commutation.whole, out.setpoint.velocity
            );
        }
        if let Some(h) = h.filter(|&h| h != Handover::Waiting) {
            if h != Handover::Done {
                handovers.push(h);
            }
            lend_at = None;
        }
        if lend_at.is_none()
            && requests.is_empty()
            && let Some(&(past, target)) = retargets.get(next)
            && out.setpoint.whole >= past
        {
            requests = vec![w16(0x6044, 0), w16(0x6045, target)];
            next += 1;
        }
        if lend_at.is_none() && !requests.is_empty() {
            // Synced at this tick: the model is fresh; serve one request, hand it over later.
            assert_eq!(synced(&mut d, &mut tick, tick_time(k + 1)), Handover::Done);
            let r = requests.remove(0);
            assert!(serve(&mut d, tick_time(k).plus_micros(10), &r));
            lend_at = Some(k + deliver);
        }
    }
    assert_eq!(synced(&mut d, &mut tick, tick_time(200_000)), Handover::Done);
    (emitted, d.state().position(), handovers)
}

#[test]
fn re_targets_handed_over_in_time_end_where_the_model_says() {
    let (emitted, position, handovers) = retargets(20_000, 20);
    assert_eq!((emitted, position), (18_000, 18_000));
    assert!(handovers.iter().all(|&h| h == Handover::Planned), "{handovers:?}");
    assert_eq!(handovers.len(), 5);
}

#[test]
fn re_targets_handed_over_late_still_end_where_the_model_says() {
    let (emitted, position, handovers) = retargets(2_000, 100);
    assert_eq!((emitted, position), (18_000, 18_000));
    assert!(handovers.iter().all(|&h| matches!(h, Handover::Late(_))), "{handovers:?}");
}

/// Serves `requests` (each at its tick) as the firmware does, handing each over `deliver`
/// ticks later; the handovers that were not plain syncs, the steps the tick emitted and the
/// model's position at the end.
fn served(requests: &[(u64, Vec<u8>)], ticks: u64, deliver: u64) -> (Vec<Handover>, i64, i64) {
    let (mut d, mut tick) = split();
    let (mut handovers, mut lend_at, mut emitted) = (Vec::new(), None, 0);
    for k in 0..ticks {
        let lent = lend_at.is_some_and(|at| k >= at);
        let (out, h) = tick_at(&mut d, &mut tick, k, lent, &Inputs::default());
        emitted += out.steps;
        if let Some(h) = h.filter(|&h| h != Handover::Waiting) {
            if h != Handover::Done {
                handovers.push(h);
            }
            lend_at = None;
        }
        if let Some((_, r)) = requests.iter().find(|(at, _)| *at == k) {
            assert!(lend_at.is_none(), "a request while one is handed over");
            assert_eq!(synced(&mut d, &mut tick, tick_time(k + 1)), Handover::Done);
            assert!(serve(&mut d, tick_time(k).plus_micros(10), r), "request at tick {k}");
            lend_at = Some(k + deliver);
        }
    }
    assert_eq!(synced(&mut d, &mut tick, tick_time(ticks)), Handover::Done);
    (handovers, emitted, d.state().position())
}

/// A stop (0x6053) handed over while the axis moves halts it where the tick has it, and the
/// model learns that halt; a move after it starts from there.
#[test]
fn a_stop_handed_over_while_moving_halts_the_tick_and_the_model_learns_it() {
    let requests = [(10, w32(0x6005, 200_000)), (20_000, w16(0x6053, 0)), (30_000, w32(0x6005, 1_000))];
    let (handovers, emitted, position) = served(&requests, 60_000, 30);
    // The stop is taken as a plan that halts the moving tick (not its plan whole).
    assert_eq!(handovers, [Handover::Planned, Handover::Planned, Handover::Planned]);
    assert!(position > 1_000 && position < 200_000, "stopped on the way: {position}");
    assert_eq!(emitted, position, "the tick emitted what the model says");
}

#[test]
fn a_buffered_set_point_appended_to_the_running_one_is_never_late() {
    let requests = [
        (10, w16(0x6007, 4)),
        (20, w32(0x6072, 20_000)),
        (30, w32(0x6074, 30_000)),
        (40, w16(0x6070, 0x10)),
        (200, w16(0x6070, 0x00)),
        (300, w32(0x6074, 10_000)),
        // Buffered behind the running one: appended to its track, handed over ticks later.
        (400, w16(0x6070, 0x10)),
    ];
    let (handovers, ..) = served(&requests, 20_000, 5);
    assert_eq!(handovers, [Handover::Planned, Handover::Planned]);
}

/// A fault history cleared on the bus side (0x200F = 5) is empty on the tick's side once it has
/// synced, and reads empty from the request on; an alarm after it lands in the emptied history.
#[test]
fn a_cleared_fault_history_reaches_the_tick() {
    let (mut d, mut tick) = split();
    let over = Inputs { supply_mv: Some(70_000), ..Inputs::default() };
    let fine = Inputs { supply_mv: Some(24_000), ..Inputs::default() };
    for k in 0..10 {
        tick_at(&mut d, &mut tick, k, true, if k < 5 { &over } else { &fine });
    }
    let code = |d: &Drive| d.state().read(drive_core::od::Obj::FaultHistory0) >> 24;
    assert_eq!(code(&d), 14, "over-voltage in the history");
    assert!(serve(&mut d, tick_time(10), &w16(0x200F, 5)));
    assert_eq!(code(&d), 0, "empty from the request on");
    tick_at(&mut d, &mut tick, 11, true, &fine);
    tick_at(&mut d, &mut tick, 12, true, &fine);
    assert_eq!(code(&d), 0, "the tick's history is empty too");
    assert!(serve(&mut d, tick_time(13), &w16(0x200F, 4)));
    for k in 14..20 {
        tick_at(&mut d, &mut tick, k, true, &over);
    }
    assert_eq!(code(&d), 14, "a new alarm in the emptied history");
    assert_eq!(d.state().read(drive_core::od::Obj::FaultHistory1), 0);
}

/// A refused write is still a frame for this drive: the tick's watchdog (0x2137, 500 ms)
/// restarts, though the write's checkpoint undoes everything else it did.
#[test]
fn a_refused_multi_object_write_restarts_the_tick_watchdog() {
    let (mut d, mut tick) = split();
    assert!(serve(&mut d, tick_time(0), &w16(0x2137, 5)));
    let fine = Inputs { supply_mv: Some(24_000), ..Inputs::default() };
    // 0x2137 = 5 (as it is), then 0x2138 = 2 (not a bit it has): refused whole.
    let refused = frame(&[1, 0x10, 0x21, 0x37, 0, 2, 4, 0, 5, 0, 2]);
    let per_400_ms = 400_000 / TICK_MICROS;
    for k in 1..=5 * per_400_ms {
        if k % per_400_ms == 0 {
            assert!(!serve(&mut d, tick_time(k), &refused));
        }
        tick_at(&mut d, &mut tick, k, true, &fine);
    }
    assert_eq!(d.state().read(Obj::CommStatus), 0, "heard every 400 ms");
    for k in 5 * per_400_ms + 1..=5 * per_400_ms + 600_000 / TICK_MICROS {
        tick_at(&mut d, &mut tick, k, true, &fine);
    }
    assert_eq!(d.state().read(Obj::CommStatus), 1, "600 ms after the last frame: timed out");
}

/// A fault the master clears (0x6000, write 1 to clear) once its cause is gone is cleared in
/// the tick's controller at the next sync (an order: the tick's other bits stay its own).
#[test]
fn a_fault_cleared_over_the_bus_is_cleared_in_the_tick() {
    let (mut d, mut tick) = split();
    let hot = Inputs { temperature_c: Some(150), ..Inputs::default() };
    for k in 0..10 {
        tick_at(&mut d, &mut tick, k, false, &hot);
    }
    assert_eq!(synced(&mut d, &mut tick, tick_time(2_001)), Handover::Done);
    let error = |t: &TickSide| t.controller().status().error;
    assert_ne!(error(&tick), 0, "over-temperature latched");
    for k in 10..20 {
        tick_at(&mut d, &mut tick, k, false, &Inputs::default());
    }
    assert_ne!(error(&tick), 0, "latched after its cause is gone");
    assert!(serve(&mut d, tick_time(20), &w16(0x6000, 0x3F)));
    assert_eq!(d.state().read(drive_core::od::Obj::ErrorStatus), 0, "the reply's model");
    tick_at(&mut d, &mut tick, 21, true, &Inputs::default());
    assert_eq!(error(&tick), 0, "the tick's own");
}

/// The closed loop's first reading takes the zero offset from the power-down position (§5.5.15,
/// 0x605E on, an incremental encoder): that offset is the tick's own state, which a later
/// change of other settings leaves alone and a write of 0x6087 replaces; the model reads what
/// the tick uses.
#[test]
fn the_zero_offset_set_by_the_first_reading_survives_other_settings_and_yields_to_0x6087() {
    let mut params = drive_core::Params::factory();
    for (obj, v) in [(Obj::Feedback, 1), (Obj::AutoSave, 1)] {
        assert!(params.set(obj, v), "{obj:?}");
    }
    params.set_saved_position(5_000);
    let mut d = Drive::boot(drive_core::DriveConfig::default(), &params, 0);
    d.state_mut().set_plan_margin(MARGIN_US);
    let mut tick = d.state().tick_side();
    let reading = Inputs { encoder: Some(0), ..Inputs::default() };
    let offset = |d: &Drive| d.state().read(Obj::ZeroOffset) as i32;
    let (out, _) = tick_at(&mut d, &mut tick, 0, false, &reading);
    assert_eq!(out.setpoint.whole, 5_000, "measured: the encoder's 0 plus the power-down position");
    // Another setting, served before the model learned the offset, handed over: the tick keeps
    // its offset, and the setpoint stays where it stood.
    assert!(serve(&mut d, tick_time(0).plus_micros(10), &w16(0x600D, 800)));
    let (out, h) = tick_at(&mut d, &mut tick, 1, true, &reading);
    assert_eq!(h, Some(Handover::Done));
    assert_eq!(tick.settings().phase_current_ma, 800);
    assert_eq!(out.setpoint.whole, 5_000);
    assert_eq!(offset(&d), 5_000, "the model learns the tick's offset");
    let (out, _) = tick_at(&mut d, &mut tick, 2, true, &reading);
    assert_eq!(out.setpoint.whole, 5_000);
    // The master's zero offset replaces it: the measured position moves with it.
    assert!(serve(&mut d, tick_time(2), &w32(0x6087, 1_000)));
    tick_at(&mut d, &mut tick, 3, true, &reading);
    let (out, _) = tick_at(&mut d, &mut tick, 4, false, &reading);
    assert_eq!(out.setpoint.whole, 1_000);
    assert_eq!(offset(&d), 1_000);
}

/// Pushes the PVT point (`position`, `velocity`, `time_ms`) at tick `k`: its registers, then
/// 0x6017 = 2.
fn push(d: &mut Drive, k: u64, position: i32, velocity: i32, time_ms: u16) {
    let ([p0, p1, p2, p3], [v0, v1, v2, v3], [t0, t1]) =
        (position.to_be_bytes(), velocity.to_be_bytes(), time_ms.to_be_bytes());
    let point = frame(&[1, 0x10, 0x60, 0x27, 0, 6, 12, p0, p1, p2, p3, v0, v1, v2, v3, 0, 0, t0, t1]);
    assert!(serve(d, tick_time(k), &point), "point at {position}");
    assert!(serve(d, tick_time(k), &w16(0x6017, 2)), "push at {position}");
}

/// PVT mode 3 (the FIFO) with the tick apart: a queue emptied and refilled between two syncs
/// reaches the tick whole; points pushed while the tick walks the queue join what it has left;
/// the run ends exactly on the last point.
#[test]
fn pvt_points_pushed_while_the_tick_walks_the_fifo_join_its_queue() {
    let (mut d, mut tick) = split();
    let fine = Inputs { supply_mv: Some(24_000), ..Inputs::default() };
    assert!(serve(&mut d, tick_time(0), &w16(0x6007, 2)));
    assert!(serve(&mut d, tick_time(0), &w16(0x6018, 2)));
    for i in 1..=3 {
        push(&mut d, 0, 40 * i, 2000, 20);
    }
    tick_at(&mut d, &mut tick, 1, true, &fine);
    assert_eq!(d.state().read(Obj::PvtCount), 3);
    // Emptied and two pushed before the next sync: the tick's queue is those two.
    assert!(serve(&mut d, tick_time(2), &w16(0x6017, 3)));
    push(&mut d, 2, 20, 2000, 20);
    push(&mut d, 2, 60, 2000, 20);
    tick_at(&mut d, &mut tick, 3, true, &fine);
    assert_eq!(d.state().read(Obj::PvtCount), 2, "the queue the bus side left");
    assert!(serve(&mut d, tick_time(4), &w16(0x6017, 1)), "start");
    // 20 ms a point: one pushed every 10 ms keeps the queue filling, up to 30 points.
    let (mut next, mut k, mut last) = (100, 5, None);
    while k < 200_000 {
        if k % 200 == 0 && next <= 60 + 40 * 28 {
            push(&mut d, k, next, 2000, 20);
            next += 40;
        } else if k % 200 == 0 && next == 60 + 40 * 29 {
            push(&mut d, k, next, 0, 20);
            next += 40;
        }
        let (out, _) = tick_at(&mut d, &mut tick, k, true, &fine);
        last = Some(out);
        if next > 60 + 40 * 29 && d.state().read(Obj::ControllerStatus) & 0x08 == 0 {
            break;
        }
        k += 1;
    }
    assert_eq!(d.state().read(Obj::PvtFault), 0, "no underflow");
    let end = i64::from(60 + 40 * 29);
    assert_eq!(last.map(|o| o.setpoint.whole), Some(end), "the tick ends on the last point");
    assert_eq!(d.state().position(), end);
    assert_eq!(d.state().read(Obj::PvtCount), 0);
}

#[test]
fn a_tick_side_made_after_ticks_on_the_model_itself_takes_in_nothing_twice() {
    // Ticked on its own model (one owner), the drive's orders and plans are in that controller.
    let mut d = drive();
    assert!(serve(&mut d, tick_time(0), &w32(0x6005, 20_000)));
    for k in 0..2_000 {
        d.tick_with(tick_time(k + 1), &Inputs::default());
    }
    assert!(!d.has_changes(), "nothing left to hand over");
    let moved = d.state().position();
    assert!(moved > 0);
    // A tick side split off now starts where the model is: its first sync replays no plan.
    let mut tick = d.state().tick_side();
    assert_eq!(synced(&mut d, &mut tick, tick_time(2_001)), Handover::Done);
    let out = tick.tick(tick_time(2_001), &Inputs::default(), d.state().shared());
    assert!(out.setpoint.whole >= moved && out.setpoint.whole - moved < 10, "{} after {moved}", out.setpoint.whole);
}
