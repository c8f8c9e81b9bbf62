//! A master we did not write (tokio-modbus) talks to the simulated drive over TCP (raw RTU
//! frames) and over a pseudo-terminal.

use std::time::Duration;

use hal_sim::{Endpoint, SimOptions, Simulator};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::time::timeout;
use tokio_modbus::client::{Client, Context, Reader, Writer, rtu};
use tokio_modbus::prelude::{ExceptionCode, Request, Response, Slave};

use drive_tests::{LIMIT, read, vendor_name, write, write_many};

/// Starts a simulator on its own thread and returns its endpoint.
fn start(endpoint: Endpoint) -> String {
    let sim = Simulator::bind(SimOptions { endpoint, ..Default::default() }).expect("bind simulator");
    let at = sim.endpoint().to_string();
    sim.spawn();
    at
}

async fn tcp_master(at: &str, slave: u8) -> Context {
    let stream = TcpStream::connect(at).await.expect("connect");
    rtu::attach_slave(stream, Slave(slave))
}

fn pty_master(path: &str, slave: u8) -> Context {
    let port = tokio_serial::SerialStream::open(&tokio_serial::new(path, 9600)).expect("open pty");
    rtu::attach_slave(port, Slave(slave))
}

/// Every register of every page of the native map, read through the master.
async fn snapshot(ctx: &mut Context) -> Vec<u16> {
    let mut all = Vec::new();
    for (addr, n) in [(0x101A, 12), (0x200E, 30), (0x2100, 1), (0x6000, 125), (0x607D, 14)] {
        all.extend(read(ctx, addr, n).await.expect("readable page"));
    }
    all
}

/// The checks every transport must pass.
async fn conversation(ctx: &mut Context) {
    assert_eq!(read(ctx, 0x600C, 2).await, Ok(vec![0, 658]), "factory resolution and current");
    assert_eq!(write(ctx, 0x600C, 32).await, Ok(()));
    let input = timeout(LIMIT, ctx.read_input_registers(0x600C, 1)).await.expect("in time").expect("transport");
    assert_eq!(input, Ok(vec![32]));
    // §9.4.1 writes the speed half by half; the value is complete after the low half.
    write(ctx, 0x6003, 0).await.expect("high half");
    write(ctx, 0x6004, 0x7D00).await.expect("low half");
    assert_eq!(read(ctx, 0x6003, 2).await, Ok(vec![0, 32000]));
    // 0x17: write 0x6008..9, read 0x6008..B.
    let rw = timeout(LIMIT, ctx.read_write_multiple_registers(0x6008, 4, 0x6008, &[700, 800]))
        .await
        .expect("in time")
        .expect("transport");
    assert_eq!(rw, Ok(vec![700, 800, 8, 8]));
    assert_eq!(vendor_name(ctx).await.as_deref(), Some(&b"OpenStep Motion"[..]));
}

#[tokio::test(flavor = "current_thread")]
async fn tcp_conversation() {
    let at = start(Endpoint::Tcp("127.0.0.1:0".into()));
    conversation(&mut tcp_master(&at, 1).await).await;
}

#[tokio::test(flavor = "current_thread")]
async fn pty_conversation() {
    let at = start(Endpoint::Pty { link: None });
    conversation(&mut pty_master(&at, 1)).await;
    // Masters come and go: a second one finds the drive as the first left it.
    let mut again = pty_master(&at, 1);
    assert_eq!(read(&mut again, 0x600C, 1).await, Ok(vec![32]));
}

#[tokio::test(flavor = "current_thread")]
async fn exception_matrix_leaves_state_unchanged() {
    let at = start(Endpoint::Tcp("127.0.0.1:0".into()));
    let mut ctx = tcp_master(&at, 1).await;
    write_many(&mut ctx, 0x6003, &[0xFFFF, 0xFC18]).await.expect("speed -1000");
    write(&mut ctx, 0x600A, 3).await.expect("acceleration level 3");
    let before = snapshot(&mut ctx).await;

    // 01: a function the drive does not have (write single coil).
    let r = timeout(LIMIT, ctx.write_single_coil(0, true)).await.expect("in time").expect("transport");
    assert_eq!(r, Err(ExceptionCode::IllegalFunction));
    // 02: no object, a read-only object, a write into a reserved register.
    assert_eq!(read(&mut ctx, 0x0000, 1).await, Err(ExceptionCode::IllegalDataAddress));
    assert_eq!(write(&mut ctx, 0x605F, 1).await, Err(ExceptionCode::IllegalDataAddress));
    assert_eq!(write(&mut ctx, 0x6012, 1).await, Err(ExceptionCode::IllegalDataAddress));
    // 03: out of range, and a multi-register write that is all or nothing.
    assert_eq!(write(&mut ctx, 0x600C, 257).await, Err(ExceptionCode::IllegalDataValue));
    assert_eq!(write_many(&mut ctx, 0x6008, &[100, 200, 9]).await, Err(ExceptionCode::IllegalDataValue));
    assert_eq!(write_many(&mut ctx, 0x6003, &[0x0004, 0]).await, Err(ExceptionCode::IllegalDataValue));
    // 04: the boot loader, which the simulator does not have.
    assert_eq!(write(&mut ctx, 0x200F, 1).await, Err(ExceptionCode::ServerDeviceFailure));
    assert_eq!(snapshot(&mut ctx).await, before, "exceptions changed nothing");
    // The simulator serves one TCP master at a time.
    drop(ctx);

    // Silent drops: another slave's address gets no answer at all...
    let mut other = tcp_master(&at, 9).await;
    assert!(timeout(Duration::from_millis(300), other.write_single_register(0x600C, 64)).await.is_err());
    // ...nor does a frame with a bad CRC, sent raw.
    let mut raw = TcpStream::connect(&at).await.expect("connect");
    raw.write_all(&[0x01, 0x06, 0x60, 0x0C, 0x00, 0x40, 0x00, 0x00]).await.expect("send");
    let mut buf = [0u8; 16];
    assert!(timeout(Duration::from_millis(300), raw.read(&mut buf)).await.is_err(), "no answer to a bad CRC");
    drop(raw);
    drop(other);
    let mut ctx = tcp_master(&at, 1).await;
    assert_eq!(snapshot(&mut ctx).await, before, "silent drops changed nothing");
}

#[tokio::test(flavor = "current_thread")]
async fn diagnostics_through_a_custom_request() {
    let at = start(Endpoint::Tcp("127.0.0.1:0".into()));
    let mut ctx = tcp_master(&at, 1).await;
    let echo = [0x00, 0x00, 0xCA, 0xFE];
    let r = timeout(LIMIT, ctx.call(Request::Custom(0x08, echo.to_vec().into()))).await.expect("in time");
    assert!(matches!(r, Ok(Ok(Response::Custom(0x08, ref b))) if b[..] == echo[..]), "{r:?}");
    // Slave message count (0x0E): the echo and this request.
    let r =
        timeout(LIMIT, ctx.call(Request::Custom(0x08, vec![0x00, 0x0E, 0x00, 0x00].into()))).await.expect("in time");
    assert!(matches!(r, Ok(Ok(Response::Custom(0x08, ref b))) if b[..] == [0x00, 0x0E, 0x00, 0x02]), "{r:?}");
}

#[tokio::test(flavor = "current_thread")]
async fn broadcast_is_executed_and_not_answered() {
    let at = start(Endpoint::Tcp("127.0.0.1:0".into()));
    // tokio-modbus waits for an answer even to a broadcast, so this one is sent raw:
    // address 0, write 0x6008 = 1234.
    let mut raw = TcpStream::connect(&at).await.expect("connect");
    raw.write_all(&[0x00, 0x06, 0x60, 0x08, 0x04, 0xD2, 0x95, 0x44]).await.expect("send");
    let mut buf = [0u8; 16];
    assert!(timeout(Duration::from_millis(300), raw.read(&mut buf)).await.is_err(), "broadcasts are not answered");
    drop(raw);
    let mut ctx = tcp_master(&at, 1).await;
    assert_eq!(read(&mut ctx, 0x6008, 1).await, Ok(vec![1234]));
}
