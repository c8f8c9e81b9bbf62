//! PVT mode on the drive state, tick by tick: the path against the exact cubic, exact landing,
//! mode 2's phase order, mode 3's FIFO and its underflow, refusals, group starts.

mod common;

use common::{Bus, frame};
use drive_core::control::{Outputs, TICK_MICROS};
use drive_core::motion::cubic::Point;
use drive_core::od::{Obj, ObjError};
use drive_core::pvt::{FAULT_UNDERFLOW, STATUS_FIFO_EMPTY, STATUS_FIFO_HIGH, STATUS_FIFO_LOW};
use drive_core::{Drive, DriveConfig, Instant, SlaveAddr};
use proptest::prelude::*;

/// A drive whose clock the test ticks.
struct Rig {
    drive: Drive,
    t: u64,
}

impl Rig {
    fn new() -> Self {
        Self::with(Drive::factory())
    }

    fn with(drive: Drive) -> Self {
        let mut r = Self { drive, t: 0 };
        r.tick();
        r
    }

    fn write(&mut self, obj: Obj, v: i64) -> Result<(), ObjError> {
        let st = self.drive.state_mut();
        st.check(obj, v as u32)?;
        st.apply(obj, v as u32);
        Ok(())
    }

    fn set(&mut self, obj: Obj, v: i64) {
        self.write(obj, v).unwrap_or_else(|e| panic!("{obj:?} = {v}: {e:?}"));
    }

    fn read(&self, obj: Obj) -> u32 {
        self.drive.state().read(obj)
    }

    fn tick(&mut self) -> Outputs {
        self.t += TICK_MICROS;
        self.drive.tick(Instant::from_micros(self.t))
    }

    fn push(&mut self, p: Point) -> Result<(), ObjError> {
        self.set(Obj::PvtPosition, p.position.into());
        self.set(Obj::PvtVelocity, p.velocity.into());
        self.set(Obj::PvtTime, p.time_ms.into());
        self.write(Obj::PvtControl, 2)
    }

    fn busy(&self) -> bool {
        self.read(Obj::ControllerStatus) & 0x08 != 0
    }
}

fn pos(o: &Outputs) -> f64 {
    o.setpoint.whole as f64 + o.setpoint.fraction.to_num::<f64>()
}

fn pt(position: i32, velocity: i32, time_ms: u16) -> Point {
    Point { position, velocity, time_ms }
}

/// The exact cubic Hermite position between (p0, v0) and (p1, v1) over `t_s`, at `t`, in f64.
fn hermite(p0: f64, v0: f64, p1: f64, v1: f64, t_s: f64, t: f64) -> f64 {
    let s = t / t_s;
    let (s2, s3) = (s * s, s * s * s);
    (2.0 * s3 - 3.0 * s2 + 1.0) * p0
        + (s3 - 2.0 * s2 + s) * t_s * v0
        + (-2.0 * s3 + 3.0 * s2) * p1
        + (s3 - s2) * t_s * v1
}

/// The reference position at each tick of a run from `start` (at rest) through `points`.
fn reference(start: f64, points: &[Point]) -> Vec<f64> {
    let mut out = vec![start];
    let (mut p0, mut v0) = (start, 0.0);
    for p in points {
        let n = u64::from(p.time_ms) * 20;
        let t_s = n as f64 / 20_000.0;
        for k in 1..=n {
            out.push(hermite(p0, v0, f64::from(p.position), f64::from(p.velocity), t_s, k as f64 / 20_000.0));
        }
        (p0, v0) = (f64::from(p.position), f64::from(p.velocity));
    }
    out
}

/// Runs a started run to its end; the positions of every tick from the start tick on.
fn run(r: &mut Rig) -> Vec<Outputs> {
    let mut out = vec![r.tick()];
    for _ in 0..2_000_000 {
        if !r.busy() {
            break;
        }
        out.push(r.tick());
    }
    assert!(!r.busy(), "still running");
    out
}

fn check_path(got: &[Outputs], want: &[f64]) {
    assert!(got.len() >= want.len(), "{} ticks, {} expected", got.len(), want.len());
    for (k, (o, w)) in got.iter().zip(want).enumerate() {
        let p = pos(o);
        assert!((p - w).abs() <= 0.5, "tick {k}: at {p}, the cubic is at {w}");
        assert!((p - w).abs() < 1e-6, "tick {k}: at {p}, the cubic is at {w} (exact arithmetic)");
    }
}

/// A sine, 4000 microsteps of amplitude, one period in 400 ms sampled every 20 ms.
fn sine() -> Vec<Point> {
    let w = std::f64::consts::TAU / 0.4;
    (0..=20)
        .map(|i| {
            let t = f64::from(i) * 0.02;
            let v = if i == 20 { 0 } else { (4000.0 * w * (w * t).cos()) as i32 };
            pt((4000.0 * (w * t).sin()).round() as i32, if i == 0 { 0 } else { v }, if i == 0 { 0 } else { 20 })
        })
        .collect()
}

#[test]
fn mode_1_follows_the_exact_cubic_and_lands_exactly() {
    let mut r = Rig::new();
    r.set(Obj::Mode, 2);
    let pts = sine();
    for p in &pts {
        r.push(*p).unwrap();
    }
    assert_eq!(r.read(Obj::PvtCount), pts.len() as u32);
    r.set(Obj::PvtM1Start, 0);
    r.set(Obj::PvtM1End, pts.len() as i64 - 1);
    r.set(Obj::PvtControl, 1);
    let got = run(&mut r);
    check_path(&got, &reference(0.0, &pts));
    let last = got.last().unwrap();
    assert_eq!((last.setpoint.whole, last.setpoint.fraction.to_bits()), (i64::from(pts[20].position), 0));
    assert_eq!(r.read(Obj::Position) as i32, pts[20].position);
    assert_eq!(r.read(Obj::PvtPointer), 20);
}

#[test]
fn a_run_starts_at_the_next_tick_from_where_the_axis_stands() {
    let mut r = Rig::new();
    r.set(Obj::Position, 1000);
    r.set(Obj::Mode, 2);
    let pts = [pt(1100, 0, 50), pt(900, 0, 50)];
    for p in pts {
        r.push(p).unwrap();
    }
    r.set(Obj::PvtM1End, 1);
    r.set(Obj::PvtControl, 1);
    check_path(&run(&mut r), &reference(1000.0, &pts));
    assert_eq!(r.drive.state().position(), 900);
}

/// Mode 2 over 0: accelerate to 1000 pps; 1..=2: forth and back at speed; 3: decelerate to rest.
const MODE_2: [Point; 4] = [
    Point { position: 10, velocity: 1000, time_ms: 20 },
    Point { position: 50, velocity: 1000, time_ms: 40 },
    Point { position: 10, velocity: 1000, time_ms: 40 },
    Point { position: 30, velocity: 0, time_ms: 40 },
];

fn mode_2(loops: i64) -> Rig {
    let mut r = Rig::new();
    r.set(Obj::Mode, 2);
    r.set(Obj::PvtMode, 1);
    for p in MODE_2 {
        r.push(p).unwrap();
    }
    for (obj, v) in [
        (Obj::PvtM2AccStart, 0),
        (Obj::PvtM2AccEnd, 0),
        (Obj::PvtM2LoopStart, 1),
        (Obj::PvtM2LoopEnd, 2),
        (Obj::PvtM2Loops, loops),
        (Obj::PvtM2DecStart, 3),
        (Obj::PvtM2DecEnd, 3),
    ] {
        r.set(obj, v);
    }
    r.set(Obj::PvtControl, 1);
    r
}

#[test]
fn mode_2_runs_acceleration_loops_and_deceleration_in_order() {
    let mut r = mode_2(3);
    let mut order = vec![];
    let mut path = vec![];
    loop {
        path.push(r.tick());
        let p = r.read(Obj::PvtPointer);
        if order.last() != Some(&p) {
            order.push(p);
        }
        if !r.busy() {
            break;
        }
    }
    // The pointer shows the point each segment heads to: 0, then (1, 2) three times, then 3.
    let indices = [0, 1, 2, 1, 2, 1, 2, 3];
    assert_eq!(order, indices);
    assert_eq!(path.len(), (20 + 3 * 80 + 40) * 20 + 1);
    let sequence: Vec<Point> = indices.iter().map(|&i| MODE_2[i as usize]).collect();
    check_path(&path, &reference(0.0, &sequence));
    assert_eq!(r.drive.state().position(), 30);
    // A loop count of 0 skips the loop: acceleration, then deceleration.
    let mut r = mode_2(0);
    let path = run(&mut r);
    assert_eq!(path.len(), (20 + 40) * 20 + 1);
    check_path(&path, &reference(0.0, &[MODE_2[0], MODE_2[3]]));
}

#[test]
fn mode_3_streams_refilled_fifo_with_status_bits() {
    let mut r = Rig::new();
    r.set(Obj::Mode, 2);
    r.set(Obj::PvtMode, 2);
    r.set(Obj::PvtFifoDepth, 8);
    r.set(Obj::PvtFifoLow, 3);
    r.set(Obj::PvtFifoHigh, 6);
    assert_eq!(r.read(Obj::ControllerStatus) as u8, STATUS_FIFO_EMPTY | STATUS_FIFO_LOW);
    // A ramp up to 2000 pps, 200 points at speed, a ramp down.
    let mut pts = vec![pt(20, 2000, 20)];
    for i in 1..=200 {
        pts.push(pt(20 + 40 * i, 2000, 20));
    }
    let end = pts.last().unwrap().position + 20;
    pts.push(pt(end, 0, 20));
    let mut next = 0;
    while next < 7 {
        r.push(pts[next]).unwrap();
        next += 1;
    }
    assert_eq!(r.read(Obj::ControllerStatus) as u8, STATUS_FIFO_HIGH);
    assert_eq!(r.push(pts[next]), Ok(()));
    next += 1;
    // Full: refused, nothing changes.
    let before = r.read(Obj::PvtCount);
    assert_eq!(r.push(pts[next]), Err(ObjError::NotNow));
    assert_eq!(r.read(Obj::PvtCount), before);
    r.set(Obj::PvtControl, 1);
    let mut got = vec![];
    loop {
        got.push(r.tick());
        // The master refills when the low bit shows.
        while r.read(Obj::ControllerStatus) as u8 & STATUS_FIFO_LOW != 0 && next < pts.len() {
            r.push(pts[next]).unwrap();
            next += 1;
        }
        if !r.busy() {
            break;
        }
    }
    assert_eq!(next, pts.len());
    assert_eq!(r.read(Obj::PvtFault), 0, "no underflow");
    check_path(&got, &reference(0.0, &pts));
    assert_eq!(r.drive.state().position(), i64::from(end));
    assert_eq!(r.read(Obj::ControllerStatus) as u8, STATUS_FIFO_EMPTY | STATUS_FIFO_LOW);
}

#[test]
fn underflow_decelerates_without_a_jump_and_sets_the_fault() {
    let mut r = Rig::new();
    r.set(Obj::Mode, 2);
    r.set(Obj::PvtMode, 2);
    for i in 1..=5 {
        r.push(pt(40 * i, 2000, 20)).unwrap();
    }
    r.set(Obj::PvtControl, 1);
    let mut prev = pos(&r.tick());
    let mut ticks = 0;
    while r.busy() {
        let o = r.tick();
        let p = pos(&o);
        // The first segment peaks at 2667 pps, 0.133 microstep a tick: never more, never back.
        assert!(p - prev <= 0.14 && p >= prev, "jump {prev} -> {p}");
        prev = p;
        ticks += 1;
        assert!(ticks < 100_000);
    }
    assert_eq!(r.read(Obj::PvtFault), u32::from(FAULT_UNDERFLOW));
    assert!(r.drive.state().position() > 200, "decelerated beyond the last point");
    r.set(Obj::PvtFault, 1);
    assert_eq!(r.read(Obj::PvtFault), 0);
}

#[test]
fn refusals_change_nothing() {
    let mut r = Rig::new();
    // Not in PVT mode: no start.
    assert_eq!(r.write(Obj::PvtControl, 1), Err(ObjError::NotNow));
    r.set(Obj::Mode, 2);
    // Nothing stored: no start.
    assert_eq!(r.write(Obj::PvtControl, 1), Err(ObjError::NotNow));
    r.push(pt(0, 0, 0)).unwrap();
    // 1000 microsteps in 5 ms from rest to rest peaks at 300 kpps.
    assert_eq!(r.push(pt(1000, 0, 5)), Err(ObjError::Infeasible));
    // A jump: no time, another position.
    assert_eq!(r.push(pt(10, 0, 0)), Err(ObjError::Infeasible));
    assert_eq!(r.push(pt(0, 250_000, 100)), Err(ObjError::Infeasible));
    assert_eq!(r.read(Obj::PvtCount), 1);
    // Longer than the table's 16-bit time: out of range.
    assert_eq!(r.write(Obj::PvtTime, 65_536), Err(ObjError::OutOfRange));
    r.push(pt(1000, 0, 100)).unwrap();
    // Index beyond the stored points.
    r.set(Obj::PvtM1End, 2);
    assert_eq!(r.write(Obj::PvtControl, 1), Err(ObjError::NotNow));
    // The last point must be at rest.
    r.push(pt(1100, 500, 100)).unwrap();
    assert_eq!(r.write(Obj::PvtControl, 1), Err(ObjError::NotNow));
    // The approach to the first point from where the axis stands must be feasible.
    r.set(Obj::PvtM1Start, 1);
    r.set(Obj::PvtM1End, 1);
    r.set(Obj::Position, -100_000);
    assert_eq!(r.write(Obj::PvtControl, 1), Err(ObjError::Infeasible));
    r.set(Obj::Position, 0);
    // Disabled: refused; enabled: runs, and clear and mode changes are refused while it does.
    r.set(Obj::Enable, 0);
    assert_eq!(r.write(Obj::PvtControl, 1), Err(ObjError::Disabled));
    r.set(Obj::Enable, 1);
    r.set(Obj::PvtControl, 1);
    r.tick();
    assert!(r.busy());
    assert_eq!(r.write(Obj::PvtControl, 3), Err(ObjError::Busy));
    assert_eq!(r.write(Obj::PvtMode, 2), Err(ObjError::Busy));
    assert_eq!(r.write(Obj::PvtControl, 1), Err(ObjError::Busy));
    assert_eq!(r.read(Obj::PvtCount), 3);
    // 0x6017 = 0 decelerates to rest.
    r.set(Obj::PvtControl, 0);
    for _ in 0..100_000 {
        if !r.busy() {
            break;
        }
        r.tick();
    }
    assert!(!r.busy());
    assert!(r.drive.state().position() < 1000, "stopped short of the point");
    r.set(Obj::PvtControl, 3);
    assert_eq!(r.read(Obj::PvtCount), 0);
}

#[test]
fn a_refused_point_in_a_multi_register_write_changes_nothing() {
    let mut bus = Bus::factory();
    let w = |bus: &mut Bus, reg: u16, v: u16| {
        let [a, b] = reg.to_be_bytes();
        let [c, d] = v.to_be_bytes();
        bus.request(&[1, 6, a, b, c, d])
    };
    w(&mut bus, 0x6007, 2).unwrap();
    w(&mut bus, 0x2112, 1).unwrap();
    let point = |p: i32, v: i32, t: i32| {
        let mut f = vec![1, 0x10, 0x60, 0x27, 0, 6, 12];
        for x in [p, v, t] {
            f.extend_from_slice(&x.to_be_bytes());
        }
        f
    };
    // One 0x10 write is one point with push on time.
    assert_eq!(bus.request(&point(0, 0, 0)), Some(frame(&[1, 0x10, 0x60, 0x27, 0, 6])));
    assert_eq!(bus.drive.state().read(Obj::PvtCount), 1);
    let before = bus.snapshot();
    // Too fast: 04, and neither the point registers nor the count change.
    assert_eq!(bus.request(&point(5000, 0, 10)), Some(frame(&[1, 0x90, 4])));
    assert_eq!(bus.snapshot(), before);
    assert_eq!(bus.drive.state().read(Obj::PvtCount), 1);
    // A start with the last point not at rest, a clear... refused or not, checked against the
    // whole state: a refused request changes nothing.
    assert_eq!(bus.request(&point(10, 100, 10)), Some(frame(&[1, 0x10, 0x60, 0x27, 0, 6])));
    w(&mut bus, 0x601C, 1).unwrap();
    let before = bus.snapshot();
    assert_eq!(w(&mut bus, 0x6017, 1), Some(frame(&[1, 0x86, 4])));
    assert_eq!(w(&mut bus, 0x2113, 0), Some(frame(&[1, 0x86, 3])), "group 0 is no group");
    assert_eq!(bus.snapshot(), before);
}

/// Feeds one frame to several drives as one bus would: the same bytes at the same times.
fn broadcast(drives: &mut [Drive], t: &mut u64, body: &[u8]) {
    for d in drives.iter_mut() {
        d.on_rx(Instant::from_micros(*t), &frame(body));
    }
}

fn two_drives_in_group(group: [u8; 3]) -> (Vec<Drive>, u64) {
    let mut drives: Vec<Drive> =
        (1..=3).map(|a| Drive::new(DriveConfig { address: SlaveAddr::new(a), ..Default::default() })).collect();
    for (d, g) in drives.iter_mut().zip(group) {
        let st = d.state_mut();
        for (obj, v) in [(Obj::GroupId, u32::from(g)), (Obj::Mode, 2)] {
            st.check(obj, v).unwrap();
            st.apply(obj, v);
        }
        for p in [pt(0, 0, 0), pt(500, 0, 100)] {
            for (obj, v) in
                [(Obj::PvtPosition, p.position as u32), (Obj::PvtVelocity, 0), (Obj::PvtTime, p.time_ms.into())]
            {
                st.apply(obj, v);
            }
            st.check(Obj::PvtControl, 2).unwrap();
            st.apply(Obj::PvtControl, 2);
        }
        st.apply(Obj::PvtM1End, 1);
    }
    (drives, 1_000_000 + 37)
}

#[test]
fn a_broadcast_group_start_starts_the_members_in_the_same_tick() {
    let (mut drives, mut t) = two_drives_in_group([5, 5, 6]);
    broadcast(&mut drives, &mut t, &[0, 6, 0x21, 0x13, 0, 5]);
    let mut first_move = [None; 3];
    // Ticks on the 50 µs grid; the frame ends t3.5 (4.01 ms at 9600 baud) after its last byte.
    let mut tick = 0u64;
    while tick < 200_000 {
        let now = Instant::from_micros(tick * TICK_MICROS);
        for (i, d) in drives.iter_mut().enumerate() {
            d.on_timer(now);
            assert_eq!(d.take_reply(), None, "a broadcast is not answered");
            let o = d.tick(now);
            if first_move[i].is_none() && (o.setpoint.whole != 0 || o.setpoint.fraction.to_bits() != 0) {
                first_move[i] = Some(tick);
            }
        }
        tick += 1;
    }
    let start = (t + 4011).div_ceil(TICK_MICROS);
    // The first tick at or after the frame's end has k = 0 (still at 0); the next one moves.
    assert_eq!(first_move[0], Some(start + 1));
    assert_eq!(first_move[1], first_move[0]);
    assert_eq!(first_move[2], None, "group 6 did not start");
    assert_eq!(drives[0].state().position(), 500);
    assert_eq!(drives[1].state().position(), 500);
}

#[test]
fn group_start_runs_synchronous_positioning() {
    let mut r = Rig::new();
    r.set(Obj::GroupId, 9);
    r.set(Obj::SyncSpeed, 20_000);
    r.set(Obj::SyncPosition, -3000);
    // Another group: accepted, nothing happens.
    r.set(Obj::GroupStart, 8);
    r.tick();
    assert!(!r.busy());
    r.set(Obj::GroupStart, 9);
    // Planned as the start arrives, busy at once, moving from the next tick on.
    assert!(r.busy());
    assert_eq!(r.drive.state().position(), 0);
    r.tick();
    assert!(r.busy());
    for _ in 0..100_000 {
        if !r.busy() {
            break;
        }
        r.tick();
    }
    assert_eq!(r.drive.state().position(), -3000);
    // Speed 0 cannot start: refused.
    r.set(Obj::SyncSpeed, 0);
    assert_eq!(r.write(Obj::GroupStart, 9), Err(ObjError::NotNow));
}

/// Random feasible PVT runs, streamed in mode 3.
fn points() -> impl Strategy<Value = Vec<Point>> {
    prop::collection::vec((-3000i32..3000, -40_000i32..40_000, 1u16..40), 1..12).prop_map(|raw| {
        let mut pos = 0i32;
        let n = raw.len();
        raw.into_iter()
            .enumerate()
            .map(|(i, (dp, v, t))| {
                pos += dp.signum() * (dp.abs() * i32::from(t) / 40);
                pt(pos, if i + 1 == n { 0 } else { v }, t)
            })
            .collect()
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// At every tick within 0.5 microstep of the exact cubic (in fact within 1e-6), continuous
    /// across points, on the last point exactly.
    #[test]
    fn streamed_runs_follow_the_cubic(pts in points()) {
        let mut r = Rig::new();
        r.set(Obj::Mode, 2);
        r.set(Obj::PvtMode, 2);
        let mut stored = vec![];
        for p in &pts {
            if r.push(*p).is_ok() {
                stored.push(*p);
            }
        }
        prop_assume!(stored.last().is_some_and(|p| p.velocity == 0));
        prop_assume!(r.write(Obj::PvtControl, 1).is_ok());
        let got = run(&mut r);
        let want = reference(0.0, &stored);
        check_path(&got, &want);
        for w in got.windows(2) {
            // Continuity: never more than 200 kpps (10 microsteps a tick) between two ticks.
            prop_assert!((pos(&w[1]) - pos(&w[0])).abs() <= 10.0 + 1e-9);
        }
        prop_assert_eq!(r.drive.state().position(), i64::from(stored.last().unwrap().position));
    }
}

#[test]
fn only_the_first_point_may_take_no_time() {
    let mut r = Rig::new();
    r.set(Obj::Mode, 2);
    r.push(pt(0, 0, 0)).unwrap();
    assert_eq!(r.push(pt(0, 0, 0)), Err(ObjError::Infeasible));
    r.push(pt(100, 0, 50)).unwrap();
    assert_eq!(r.read(Obj::PvtCount), 2);
}

#[test]
fn points_of_no_time_pass_in_the_tick_they_start() {
    let mut r = Rig::new();
    r.set(Obj::Mode, 2);
    r.set(Obj::PvtMode, 1);
    r.push(pt(0, 0, 0)).unwrap();
    r.push(pt(100, 0, 50)).unwrap();
    // A loop of point 0 alone (no time) is refused.
    r.set(Obj::PvtM2Loops, 1000);
    r.set(Obj::PvtM2DecEnd, 1);
    assert_eq!(r.write(Obj::PvtControl, 1), Err(ObjError::NotNow));
    // Acceleration 0..=0, no loop, deceleration 0..=1: the approach and two points of no time,
    // then 50 ms, exactly on the cubic from the first tick.
    r.set(Obj::PvtM2Loops, 0);
    r.set(Obj::PvtControl, 1);
    let got = run(&mut r);
    assert_eq!(r.drive.state().position(), 100);
    assert_eq!(got.len(), 1 + 1000);
    check_path(&got, &reference(0.0, &[pt(100, 0, 50)]));
}

proptest! {
    /// One segment anywhere in the ranges the drive takes, at any tick: the exact evaluation is
    /// within 0.5 microstep of the cubic (computed in f64), and exactly on both points.
    #[test]
    fn any_segment_is_evaluated_exactly(
        p0 in -2_000_000_000i64..2_000_000_000,
        v0 in -200_000i32..200_000,
        v1 in -200_000i32..200_000,
        delta in -5_000_000i64..5_000_000,
        time_ms in 1u16..=65_535,
        at in 0.0f64..=1.0,
    ) {
        let to = Point { position: (p0 + delta).clamp(i32::MIN.into(), i32::MAX.into()) as i32, velocity: v1, time_ms };
        let c = drive_core::motion::cubic::Cubic::new(p0, v0, to);
        let n = c.ticks();
        let k = (at * n as f64) as u64;
        let t_s = n as f64 / 20_000.0;
        let want = hermite(0.0, f64::from(v0), (i64::from(to.position) - p0) as f64, f64::from(v1), t_s, k as f64 / 20_000.0);
        let o = c.at(k);
        let got = o.whole as f64 + f64::from(o.fraction) / 4_294_967_296.0;
        prop_assert!((got - want).abs() <= 0.5, "tick {k} of {n}: {got} against {want}");
        prop_assert_eq!(c.at(0).whole, 0);
        prop_assert_eq!(c.at(n).whole + p0, i64::from(to.position));
        prop_assert_eq!(c.at(n).fraction, 0);
    }
}
