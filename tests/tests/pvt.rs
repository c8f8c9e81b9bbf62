//! PVT streamed by a real master (tokio-modbus) to several drives on one simulated bus, in real
//! time at 115200 baud: the path of every tick against the exact cubic (from the drives' traces),
//! exact final positions, axes started in the same tick by one broadcast, mode 2's phase order,
//! mode 3 streaming refilled on the low watermark, and the underflow.

use std::path::PathBuf;
use std::time::Duration;

use drive_core::motion::cubic::Point;
use hal_sim::trace::{TraceRow, load_csv};
use hal_sim::{Endpoint, MotorOptions, SimOptions, Simulator, axis_trace_path};
use tokio::net::TcpStream;
use tokio::time::{Instant, sleep, timeout};
use tokio_modbus::client::{Context, Reader, Writer, rtu};
use tokio_modbus::prelude::{Slave, SlaveContext};

const LIMIT: Duration = Duration::from_secs(10);
/// How long a run may take in wall time: the simulator pauses while the host stalls it, and a
/// small shared machine stalls it for seconds in all.
const RUN_LIMIT: Duration = Duration::from_secs(30);
/// 0x6001 bits: busy, FIFO below the low mark, above the high mark.
const BUSY: u16 = 1 << 3;
const FIFO_LOW: u16 = 1 << 6;
const FIFO_HIGH: u16 = 1 << 7;
/// Control ticks per second.
const TICK_HZ: f64 = 20_000.0;

/// A master on the bus of a simulator, and where the drives' traces go.
struct Bus {
    ctx: Context,
    trace: PathBuf,
    _dir: tempfile::TempDir,
}

impl Bus {
    /// Drives at `axes` on one bus at 115200 baud, tracing every tick (when `trace`).
    async fn start(axes: &[u8], trace: bool) -> Bus {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("run.csv");
        let sim = Simulator::bind(SimOptions {
            endpoint: Endpoint::Tcp("127.0.0.1:0".into()),
            baud: Some(115_200),
            axes: axes.to_vec(),
            motor: MotorOptions { trace: trace.then(|| (path.clone(), 1)), ..Default::default() },
            ..Default::default()
        })
        .expect("bind");
        let at = sim.endpoint().to_string();
        sim.spawn();
        let ctx = rtu::attach_slave(TcpStream::connect(at).await.expect("connect"), Slave(axes[0]));
        Bus { ctx, trace: path, _dir: dir }
    }

    async fn write(&mut self, node: u8, reg: u16, words: &[u16]) {
        self.ctx.set_slave(Slave(node));
        let r =
            timeout(LIMIT, self.ctx.write_multiple_registers(reg, words)).await.expect("in time").expect("transport");
        assert_eq!(r, Ok(()), "node {node}: write {reg:04X} = {words:04X?}");
    }

    async fn read(&mut self, node: u8, reg: u16, n: u16) -> Vec<u16> {
        self.ctx.set_slave(Slave(node));
        timeout(LIMIT, self.ctx.read_holding_registers(reg, n))
            .await
            .expect("in time")
            .expect("transport")
            .expect("no exception")
    }

    async fn position(&mut self, node: u8) -> i32 {
        let p = self.read(node, 0x600E, 2).await;
        (i32::from(p[0] as i16) << 16) | i32::from(p[1])
    }

    /// A broadcast write: tokio-modbus waits for a reply that never comes, so it is given 30 ms.
    async fn broadcast(&mut self, reg: u16, v: u16) {
        self.ctx.set_slave(Slave::broadcast());
        let r = timeout(Duration::from_millis(30), self.ctx.write_single_register(reg, v)).await;
        assert!(r.is_err(), "a broadcast is not answered: {r:?}");
    }

    /// One point in one 0x10 write of 0x6027..0x602C (push on time, 0x2112 = 1).
    async fn push(&mut self, node: u8, p: Point) {
        self.write(node, 0x6027, &point_words(p)).await;
    }

    /// Pushes `p` to node 1 and reads 0x6001 back in one 0x17 request; counts it in `pushed`.
    async fn push_read_status(&mut self, p: Point, pushed: &mut usize) -> u16 {
        self.ctx.set_slave(Slave(1));
        let r = timeout(LIMIT, self.ctx.read_write_multiple_registers(0x6001, 1, 0x6027, &point_words(p)))
            .await
            .expect("in time")
            .expect("transport")
            .expect("no exception");
        *pushed += 1;
        r[0]
    }

    async fn wait_idle(&mut self, nodes: &[u8], within: Duration) {
        let end = Instant::now() + within;
        for &n in nodes {
            while self.read(n, 0x6001, 1).await[0] & BUSY != 0 {
                assert!(Instant::now() < end, "node {n} still busy");
                sleep(Duration::from_millis(20)).await;
            }
        }
    }

    /// The trace of the drive at `node` (after the run: the simulator flushes it as it goes).
    fn trace(&self, node: u8) -> Vec<TraceRow> {
        load_csv(axis_trace_path(&self.trace, node)).expect("trace")
    }

    /// PVT mode, push on time, group 1, 1/16 microstepping, on every node.
    async fn setup(&mut self, nodes: &[u8], pvt_mode: u16) {
        for &n in nodes {
            self.write(n, 0x600C, &[16]).await;
            self.write(n, 0x200E, &[1]).await;
            self.write(n, 0x6007, &[2]).await;
            self.write(n, 0x6018, &[pvt_mode]).await;
            self.write(n, 0x2112, &[1]).await;
        }
    }
}

fn point_words(p: Point) -> [u16; 6] {
    let [a, b, c, d] = p.position.to_be_bytes();
    let [e, f, g, h] = p.velocity.to_be_bytes();
    [
        u16::from_be_bytes([a, b]),
        u16::from_be_bytes([c, d]),
        u16::from_be_bytes([e, f]),
        u16::from_be_bytes([g, h]),
        0,
        p.time_ms,
    ]
}

/// Points sampled every `dt_ms` from a trajectory `f(t) = (position, velocity)` over `t_end`
/// seconds; the first (at t = 0, at rest at 0) takes no time.
fn sample(f: impl Fn(f64) -> (f64, f64), dt_ms: u16, t_end: f64) -> Vec<Point> {
    let n = (t_end * 1000.0 / f64::from(dt_ms)).round() as u32;
    (0..=n)
        .map(|i| {
            let t = f64::from(i) * f64::from(dt_ms) * 1e-3;
            let (p, v) = f(t);
            Point { position: p.round() as i32, velocity: v.round() as i32, time_ms: if i == 0 { 0 } else { dt_ms } }
        })
        .collect()
}

/// Minimum-jerk blend 0 → 1 over s in [0, 1], and its derivative.
fn min_jerk(s: f64) -> (f64, f64) {
    let s = s.clamp(0.0, 1.0);
    (10.0 * s.powi(3) - 15.0 * s.powi(4) + 6.0 * s.powi(5), 30.0 * s * s - 60.0 * s.powi(3) + 30.0 * s.powi(4))
}

/// The exact cubic Hermite path through `points` from rest at 0, one position per tick.
fn cubic_path(points: &[Point]) -> Vec<f64> {
    let mut out = vec![0.0];
    let (mut p0, mut v0) = (0.0, 0.0);
    for p in points {
        let n = u32::from(p.time_ms) * 20;
        let t = f64::from(n) / TICK_HZ;
        let (p1, v1) = (f64::from(p.position), f64::from(p.velocity));
        for k in 1..=n {
            let s = f64::from(k) / f64::from(n);
            let (s2, s3) = (s * s, s * s * s);
            out.push(
                (2.0 * s3 - 3.0 * s2 + 1.0) * p0
                    + (s3 - 2.0 * s2 + s) * t * v0
                    + (-2.0 * s3 + 3.0 * s2) * p1
                    + (s3 - s2) * t * v1,
            );
        }
        (p0, v0) = (p1, v1);
    }
    out
}

/// The tick (from the simulator's start) at which a row was recorded: rows are written after the
/// motor has advanced over the tick.
fn tick_of(r: &TraceRow) -> i64 {
    (r.t_s * TICK_HZ).round() as i64 - 1
}

/// Finds the tick at which the run `want` (one position per tick from its start) began in the
/// trace, and checks every tick of it: within 0.5 microstep of the exact cubic (the trace prints
/// 10⁻⁴ microstep). Returns the start tick.
fn check_run(rows: &[TraceRow], want: &[f64]) -> i64 {
    let commanded: Vec<(i64, f64)> = rows.iter().map(|r| (tick_of(r), r.commanded_position_usteps)).collect();
    let first_tick = commanded[0].0;
    let at = |tick: i64| commanded.get(usize::try_from(tick - first_tick).ok()?).map(|c| c.1);
    let moved = commanded.iter().find(|c| c.1 != 0.0).expect("the axis moved").0;
    let error = |start: i64, step: usize| {
        want.iter()
            .enumerate()
            .step_by(step)
            .map(|(k, w)| at(start + k as i64).map_or(f64::INFINITY, |p| (p - w).abs()))
            .fold(0.0, f64::max)
    };
    // The run began before the first visible movement (a cosine stays on 0 for a while).
    let start = (moved - want.len() as i64..=moved)
        .min_by(|&a, &b| error(a, 97).total_cmp(&error(b, 97)))
        .expect("a candidate");
    let worst = error(start, 1);
    assert!(worst <= 0.5, "off the cubic by {worst} microsteps (run from tick {start})");
    start
}

/// Also draws the XY path; the plot in docs/pvt.md comes from
/// `PVT_CIRCLE_PNG=$PWD/docs/img/pvt-circle.png cargo test -p drive-tests --test pvt circle`.
#[tokio::test(flavor = "current_thread")]
async fn circle_on_two_axes_follows_the_cubic_in_step() {
    let mut bus = Bus::start(&[1, 2], true).await;
    bus.setup(&[1, 2], 0).await;
    // Radius 1600 microsteps (100 full steps at 1/16), once round in 1 s, minimum-jerk in angle.
    let r = 1600.0;
    let angle = |t: f64| {
        let (s, ds) = min_jerk(t);
        (std::f64::consts::TAU * s, std::f64::consts::TAU * ds)
    };
    let x = sample(|t| (r * (angle(t).0.cos() - 1.0), -r * angle(t).0.sin() * angle(t).1), 20, 1.0);
    let y = sample(|t| (r * angle(t).0.sin(), r * angle(t).0.cos() * angle(t).1), 20, 1.0);
    for (node, points) in [(1, &x), (2, &y)] {
        for p in points {
            bus.push(node, *p).await;
        }
        bus.write(node, 0x601B, &[0, points.len() as u16 - 1]).await;
        assert_eq!(bus.read(node, 0x2110, 1).await, vec![points.len() as u16]);
    }
    // One broadcast frame starts group 1.
    bus.broadcast(0x2113, 1).await;
    bus.wait_idle(&[1, 2], RUN_LIMIT).await;
    assert_eq!(bus.position(1).await, x.last().unwrap().position);
    assert_eq!(bus.position(2).await, y.last().unwrap().position);
    sleep(Duration::from_millis(50)).await;
    let (tx, ty) = (bus.trace(1), bus.trace(2));
    let start_x = check_run(&tx, &cubic_path(&x[1..]));
    let start_y = check_run(&ty, &cubic_path(&y[1..]));
    assert_eq!(start_x, start_y, "both axes started in the same tick");
    let plot = bus.trace.with_file_name("circle.png");
    let from = |rows: &[TraceRow]| rows.iter().filter(|r| tick_of(r) >= start_x).copied().collect::<Vec<_>>();
    hal_sim::plot::plot_xy(&from(&tx), &from(&ty), &plot, "PVT circle, two drives on one bus").expect("plot");
    if let Ok(out) = std::env::var("PVT_CIRCLE_PNG") {
        std::fs::copy(&plot, out).expect("copy the plot");
    }
}

#[tokio::test(flavor = "current_thread")]
async fn sine_and_minimum_jerk_move_land_exactly() {
    let mut bus = Bus::start(&[3, 4], true).await;
    bus.setup(&[3, 4], 0).await;
    // A sine of 2 periods of 0.5 s (as 1 − cos, from rest to rest); a minimum-jerk move of
    // 12800 microsteps in 1 s.
    let w = std::f64::consts::TAU / 0.5;
    let sine = sample(|t| (2000.0 * (1.0 - (w * t).cos()), 2000.0 * w * (w * t).sin()), 10, 1.0);
    let mj = sample(|t| (12800.0 * min_jerk(t).0, 12800.0 * min_jerk(t).1), 25, 1.0);
    for (node, points) in [(3, &sine), (4, &mj)] {
        for p in points {
            bus.push(node, *p).await;
        }
        bus.write(node, 0x601B, &[0, points.len() as u16 - 1]).await;
    }
    bus.broadcast(0x2113, 1).await;
    bus.wait_idle(&[3, 4], RUN_LIMIT).await;
    assert_eq!(bus.position(3).await, sine.last().unwrap().position);
    assert_eq!(bus.position(4).await, 12800);
    sleep(Duration::from_millis(50)).await;
    let a = check_run(&bus.trace(3), &cubic_path(&sine[1..]));
    let b = check_run(&bus.trace(4), &cubic_path(&mj[1..]));
    assert_eq!(a, b);
}

/// `nodes` drives with the same move, started by one broadcast: the first tick that moves is the
/// same on every one.
async fn group_start(nodes: &[u8]) {
    let mut bus = Bus::start(nodes, true).await;
    bus.setup(nodes, 0).await;
    let points = [Point { position: 0, velocity: 0, time_ms: 0 }, Point { position: 1600, velocity: 0, time_ms: 100 }];
    for &n in nodes {
        for p in points {
            bus.push(n, p).await;
        }
        bus.write(n, 0x601C, &[1]).await;
    }
    bus.broadcast(0x2113, 1).await;
    bus.wait_idle(nodes, RUN_LIMIT).await;
    sleep(Duration::from_millis(50)).await;
    let mut first = vec![];
    for &n in nodes {
        assert_eq!(bus.position(n).await, 1600);
        let rows = bus.trace(n);
        let moved = rows.iter().find(|r| r.commanded_position_usteps != 0.0).expect("moved");
        first.push(tick_of(moved));
        check_run(&rows, &cubic_path(&points[1..]));
    }
    assert!(first.iter().all(|&t| t == first[0]), "first moving ticks {first:?}");
}

#[tokio::test(flavor = "current_thread")]
async fn two_axes_start_in_the_same_tick() {
    group_start(&[1, 2]).await;
}

#[tokio::test(flavor = "current_thread")]
async fn eight_axes_start_in_the_same_tick() {
    group_start(&[1, 2, 3, 4, 5, 6, 7, 8]).await;
}

/// §5.9: each drive is given its own target and speed, one broadcast starts them together.
#[tokio::test(flavor = "current_thread")]
async fn synchronous_positioning_starts_by_one_broadcast() {
    let nodes = [1, 2, 3];
    let mut bus = Bus::start(&nodes, true).await;
    for (n, target, speed) in [(1, 6400, 20_000), (2, -3200, 10_000), (3, 12_345, 30_000)] {
        bus.write(n, 0x200E, &[4]).await;
        let words = |v: i32| [(v >> 16) as u16, v as u16];
        bus.write(n, 0x6047, &[words(speed), words(target)].concat()).await;
    }
    bus.broadcast(0x2113, 4).await;
    bus.wait_idle(&nodes, RUN_LIMIT).await;
    assert_eq!([bus.position(1).await, bus.position(2).await, bus.position(3).await], [6400, -3200, 12_345]);
    sleep(Duration::from_millis(50)).await;
    let first: Vec<i64> = nodes
        .iter()
        .map(|&n| tick_of(bus.trace(n).iter().find(|r| r.commanded_position_usteps != 0.0).expect("moved")))
        .collect();
    assert!(first.iter().all(|&t| t == first[0]), "first moving ticks {first:?}");
}

/// The phases are read off the drive's own trace, not by polling the point pointer: a poll can
/// miss a 60 ms segment when the host stalls the master.
#[tokio::test(flavor = "current_thread")]
async fn mode_2_runs_the_phases_in_order() {
    let mut bus = Bus::start(&[1], true).await;
    bus.setup(&[1], 1).await;
    let pts = [(10, 1000, 60), (70, 1000, 60), (10, 1000, 60), (40, 0, 60)]
        .map(|(position, velocity, time_ms)| Point { position, velocity, time_ms });
    for p in pts {
        bus.push(1, p).await;
    }
    // Acceleration 0..=0, loop 1..=2 twice, deceleration 3..=3.
    bus.write(1, 0x601D, &[0, 0, 1, 2, 2, 3, 3]).await;
    bus.write(1, 0x6017, &[1]).await;
    bus.wait_idle(&[1], RUN_LIMIT).await;
    assert_eq!(bus.position(1).await, 40);
    assert_eq!(bus.read(1, 0x601A, 1).await, vec![3], "the pointer ends on the last point");
    sleep(Duration::from_millis(50)).await;
    let phases = [0, 1, 2, 1, 2, 3].map(|i| pts[i]);
    check_run(&bus.trace(1), &cubic_path(&phases));
}

#[tokio::test(flavor = "current_thread")]
async fn fifo_underflow_decelerates_and_is_reported() {
    let mut bus = Bus::start(&[1], false).await;
    bus.setup(&[1], 2).await;
    for i in 1..=5 {
        bus.push(1, Point { position: 40 * i, velocity: 2000, time_ms: 20 }).await;
    }
    bus.write(1, 0x6017, &[1]).await;
    bus.wait_idle(&[1], RUN_LIMIT).await;
    assert_eq!(bus.read(1, 0x2111, 1).await, vec![1], "underflow");
    assert_eq!(bus.read(1, 0x6001, 1).await[0] & (1 << 5), 1 << 5, "FIFO empty");
    assert!(bus.position(1).await > 200, "decelerated beyond the last point");
    bus.write(1, 0x2111, &[1]).await;
    assert_eq!(bus.read(1, 0x2111, 1).await, vec![0]);
}

/// Mode 3: 10 000 points of 10 ms (100 s), refilled whenever the FIFO is below its low mark, with
/// one 0x17 request a point (write the point, read 0x6001 back). No underflow, exact end.
#[tokio::test(flavor = "current_thread")]
async fn streams_ten_thousand_points_refilled_on_the_low_mark() {
    let mut bus = Bus::start(&[1], false).await;
    bus.setup(&[1], 2).await;
    // The deepest FIFO, low mark at 5 s of points. A round trip wakes two threads, which a small
    // shared machine may each leave asleep for milliseconds: 100 points a second leave margin.
    bus.write(1, 0x6024, &[1000, 500, 960]).await;
    let period = 2.0;
    let w = std::f64::consts::TAU / period;
    let points = sample(|t| (3200.0 * (1.0 - (w * t).cos()), 3200.0 * w * (w * t).sin()), 10, 100.0);
    assert_eq!(points.len(), 10_001);
    let mut next = 0;
    while next < points.len() && bus.push_read_status(points[next], &mut next).await & FIFO_HIGH == 0 {}
    let began = Instant::now();
    bus.write(1, 0x6017, &[1]).await;
    let (mut refills, mut pushed_in_refills, mut refill_time) = (0, 0, Duration::ZERO);
    while next < points.len() {
        let status = bus.read(1, 0x6001, 1).await[0];
        assert_eq!(status & BUSY, BUSY, "running");
        if status & FIFO_LOW != 0 {
            refills += 1;
            let t = Instant::now();
            let from = next;
            while next < points.len() && bus.push_read_status(points[next], &mut next).await & FIFO_HIGH == 0 {}
            pushed_in_refills += next - from;
            refill_time += t.elapsed();
        } else {
            sleep(Duration::from_millis(50)).await;
        }
    }
    bus.wait_idle(&[1], RUN_LIMIT).await;
    let elapsed = began.elapsed();
    assert_eq!(bus.read(1, 0x2111, 1).await, vec![0], "no underflow");
    assert_eq!(bus.position(1).await, points.last().unwrap().position);
    let rate = pushed_in_refills as f64 / refill_time.as_secs_f64();
    eprintln!(
        "10 000 points in {:.1} s, {refills} refills, {rate:.0} points/s while refilling (one 0x17 request a point)",
        elapsed.as_secs_f64()
    );
}
