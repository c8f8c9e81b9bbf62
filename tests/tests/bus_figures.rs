//! How many PVT points a master can stream over RS-485 at 115200 baud to 1, 8 and 32 drives,
//! from the frames tokio-modbus actually sends and the drive actually answers (counted by a
//! byte-counting proxy in front of the simulator), and one rate measured against the simulator.
//!
//! On the wire a request costs its characters, then t3.5 of silence (after which the drive
//! answers at once), then the reply's characters and t3.5 again before the next request; a
//! broadcast has no reply. At 115200 baud 8N1 a character is 10 bits (86.8 µs) and t3.5 is the
//! fixed 1.75 ms of the Modbus serial-line specification for rates above 19200.
//!
//! Three ways to send one point (position, velocity, time; push on time, 0x2112 = 1):
//! - `write`: one 0x10 write of 0x6027..0x602C to each drive;
//! - `write+status`: one 0x17 request that writes the point and reads 0x6001 (the FIFO bits);
//! - `broadcast time`: a 0x10 write of position and velocity 0x6027..0x602A to each drive, then
//!   one broadcast 0x10 of the time 0x602B..2C, which pushes the point on every drive at once
//!   (the segment time is shared by all axes of an interpolated path).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use hal_sim::{Endpoint, SimOptions, Simulator};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::time::{Instant, timeout};
use tokio_modbus::client::{Context, Reader, Writer, rtu};
use tokio_modbus::prelude::{Slave, SlaveContext};

/// Seconds per character at 115200 baud, 8N1 (start, 8 data, stop).
const CHAR_S: f64 = 10.0 / 115_200.0;
/// t3.5 above 19200 baud.
const T35_S: f64 = 1.75e-3;

/// Bytes a master sent and received through the proxy.
#[derive(Default)]
struct Counts {
    sent: AtomicU64,
    received: AtomicU64,
}

/// Copies `from` to `to`, counting bytes into `n`.
async fn pump(
    mut from: tokio::net::tcp::OwnedReadHalf,
    mut to: tokio::net::tcp::OwnedWriteHalf,
    n: Arc<Counts>,
    up: bool,
) {
    let mut buf = [0u8; 512];
    while let Ok(k) = from.read(&mut buf).await {
        if k == 0 || to.write_all(&buf[..k]).await.is_err() {
            break;
        }
        let c = if up { &n.sent } else { &n.received };
        c.fetch_add(k as u64, Ordering::SeqCst);
    }
}

/// A simulator with one drive at 115200 baud, a counting proxy in front, a master through it.
async fn start() -> (Context, Arc<Counts>) {
    let sim = Simulator::bind(SimOptions {
        endpoint: Endpoint::Tcp("127.0.0.1:0".into()),
        baud: Some(115_200),
        ..Default::default()
    })
    .expect("bind");
    let at = sim.endpoint().to_string();
    sim.spawn();
    let proxy = TcpListener::bind("127.0.0.1:0").await.expect("proxy");
    let proxy_at = proxy.local_addr().expect("address");
    let counts = Arc::new(Counts::default());
    let c = Arc::clone(&counts);
    tokio::spawn(async move {
        let (master, _) = proxy.accept().await.expect("accept");
        let drive = TcpStream::connect(at).await.expect("connect");
        let (mr, mw) = master.into_split();
        let (dr, dw) = drive.into_split();
        tokio::join!(pump(mr, dw, Arc::clone(&c), true), pump(dr, mw, c, false));
    });
    let ctx = rtu::attach_slave(TcpStream::connect(proxy_at).await.expect("connect"), Slave(1));
    (ctx, counts)
}

/// Bytes sent and received by `f`, once the proxy has passed them on.
async fn bytes_of(counts: &Counts, f: impl AsyncFnOnce()) -> (u64, u64) {
    let before = (counts.sent.load(Ordering::SeqCst), counts.received.load(Ordering::SeqCst));
    f().await;
    tokio::time::sleep(Duration::from_millis(20)).await;
    (counts.sent.load(Ordering::SeqCst) - before.0, counts.received.load(Ordering::SeqCst) - before.1)
}

/// Bus time of one addressed exchange and of one broadcast, seconds.
fn exchange_s(request: u64, reply: u64) -> f64 {
    (request + reply) as f64 * CHAR_S + 2.0 * T35_S
}
fn broadcast_s(request: u64) -> f64 {
    request as f64 * CHAR_S + T35_S
}

#[tokio::test(flavor = "current_thread")]
async fn points_per_second_on_the_bus() {
    let (mut ctx, counts) = start().await;
    let ok = |r: tokio_modbus::Result<()>| r.expect("transport").expect("no exception");
    ok(ctx.write_single_register(0x6007, 2).await);
    ok(ctx.write_single_register(0x6018, 2).await);
    ok(ctx.write_single_register(0x2112, 1).await);
    // Position 0, velocity 0, 1 ms: the axis stands, as points that only a master's timing sees.
    let point = [0u16, 0, 0, 0, 0, 1];
    let write = bytes_of(&counts, async || ok(ctx.write_multiple_registers(0x6027, &point).await)).await;
    let status = bytes_of(&counts, async || {
        ctx.read_write_multiple_registers(0x6001, 1, 0x6027, &point).await.expect("transport").expect("no exception");
    })
    .await;
    let pos_vel = bytes_of(&counts, async || ok(ctx.write_multiple_registers(0x6027, &point[..4]).await)).await;
    let time = bytes_of(&counts, async || {
        ctx.set_slave(Slave::broadcast());
        // No reply comes: tokio-modbus is given 30 ms.
        assert!(timeout(Duration::from_millis(30), ctx.write_multiple_registers(0x602B, &[0, 1])).await.is_err());
        ctx.set_slave(Slave(1));
    })
    .await;
    // The frames: address, function, fields, CRC.
    assert_eq!(write, (21, 8), "0x10 of 6 registers and its reply");
    assert_eq!(status, (25, 7), "0x17 writing 6, reading 1, and its reply");
    assert_eq!(pos_vel, (17, 8), "0x10 of 4 registers and its reply");
    assert_eq!(time, (13, 0), "broadcast 0x10 of 2 registers: no reply");
    // Each way pushed one point into the FIFO (the split one with its broadcast time).
    let queued = ctx.read_holding_registers(0x2110, 1).await.expect("transport").expect("no exception");
    assert_eq!(queued, vec![3]);

    let per_point = |axes: f64| {
        (
            axes * exchange_s(write.0, write.1),
            axes * exchange_s(status.0, status.1),
            axes * exchange_s(pos_vel.0, pos_vel.1) + broadcast_s(time.0),
        )
    };
    let mut table = vec![];
    for axes in [1.0, 8.0, 32.0] {
        let (a, b, c) = per_point(axes);
        table.push([1.0 / a, 1.0 / b, 1.0 / c]);
        eprintln!(
            "{axes:>2} axes: {:6.1} {:6.1} {:6.1} points/s (write, write+status, broadcast time)",
            1.0 / a,
            1.0 / b,
            1.0 / c
        );
    }
    // The figures of docs/performance.md (Bus figures), to 0.1 point/s.
    let want = [[166.2, 159.3, 117.0], [20.8, 19.9, 20.7], [5.2, 5.0, 5.4]];
    for (got, want) in table.iter().zip(want) {
        for (g, w) in got.iter().zip(want) {
            assert!((g - w).abs() < 0.05, "{g:.2} points/s, docs/performance.md says {w}");
        }
    }
    // Silences are most of the bus time: 3.5 ms of the 6.0 ms of a written point.
    let silence = 2.0 * T35_S / exchange_s(write.0, write.1);
    assert!((silence - 0.58).abs() < 0.005, "{silence}");

    // Measured: back-to-back 0x10 point writes through the simulator. Its bytes arrive at once
    // (no character time on TCP), so an exchange takes t3.5 and the simulator's 1 ms wake-ups.
    let n = 300;
    let began = Instant::now();
    for _ in 0..n {
        ok(ctx.write_multiple_registers(0x6027, &point).await);
    }
    let rate = f64::from(n) / began.elapsed().as_secs_f64();
    eprintln!("measured against the simulator: {rate:.0} points/s (0x10 writes, one drive)");
    assert!(rate < 1.0 / T35_S, "no exchange is shorter than t3.5: {rate:.0}/s");
}
