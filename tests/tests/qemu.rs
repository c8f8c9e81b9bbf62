//! A master we did not write (tokio-modbus) talks to the firmware itself, running on QEMU's
//! emulated STM32L475 (`cargo xtask qemu`): device identification, registers, a relative move
//! whose position advances and whose busy bit clears, a parameter save refused while it moves and
//! carried out at rest. Skipped, with a message, when QEMU 10's
//! `qemu-system-arm` is not installed (`.ci/install` installs it).

use std::time::{Duration, Instant};

use drive_tests::qemu::{boot, qemu_10};
use drive_tests::{read_values as read, vendor_name, write};
use tokio::net::TcpStream;
use tokio::time::timeout;
use tokio_modbus::client::rtu;
use tokio_modbus::prelude::{ExceptionCode, Slave};

/// The line as a serial port with a read timeout (VTIME) hands it to a master: bytes gathered
/// until a 3 ms gap. QEMU emits a reply byte by byte, and tokio-modbus 0.17's RTU decoder fails
/// (and resynchronises forever) on a 0x2B reply of which it has seen only two bytes; every other
/// reply it takes in any split.
fn coalesced(stream: TcpStream) -> tokio::io::DuplexStream {
    use tokio::io::{AsyncReadExt, AsyncWriteExt};
    let (ours, theirs) = tokio::io::duplex(1024);
    let (mut sock_rx, mut sock_tx) = stream.into_split();
    let (mut pipe_rx, mut pipe_tx) = tokio::io::split(ours);
    tokio::spawn(async move {
        let mut buf = vec![0u8; 512];
        loop {
            let Ok(mut n) = sock_rx.read(&mut buf).await else { return };
            if n == 0 {
                return;
            }
            while let Ok(Ok(m)) = timeout(Duration::from_millis(3), sock_rx.read(&mut buf[n..])).await {
                if m == 0 || n + m == buf.len() {
                    n += m;
                    break;
                }
                n += m;
            }
            if pipe_tx.write_all(&buf[..n]).await.is_err() {
                return;
            }
        }
    });
    tokio::spawn(async move { tokio::io::copy(&mut pipe_rx, &mut sock_tx).await });
    theirs
}

fn position(words: &[u16]) -> i32 {
    ((u32::from(words[0]) << 16) | u32::from(words[1])) as i32
}

#[tokio::test(flavor = "current_thread")]
async fn tokio_modbus_drives_the_firmware_under_qemu() {
    if !qemu_10() {
        eprintln!("SKIPPED: qemu-system-arm 10 is not installed (.ci/install installs it from bookworm-backports)");
        return;
    }
    let (_fw, at) = boot();
    let stream = TcpStream::connect(&at).await.expect("connect to QEMU's USART");
    // A request must not wait for the ACK of an earlier piece (Nagle against delayed ACK: 40 ms).
    stream.set_nodelay(true).expect("TCP_NODELAY");
    let mut ctx = rtu::attach_slave(coalesced(stream), Slave(1));

    assert_eq!(vendor_name(&mut ctx).await.as_deref(), Some(&b"OpenStep Motion"[..]));
    assert_eq!(read(&mut ctx, 0x600C, 2).await, vec![0, 658], "factory resolution and current");

    // Round trip of a two-register read (8-byte request, 9-byte reply).
    let mut rtts = Vec::new();
    for _ in 0..20 {
        let t = Instant::now();
        read(&mut ctx, 0x600C, 2).await;
        rtts.push(t.elapsed());
    }
    rtts.sort();
    println!("QEMU read round trip: median {:?}, max {:?} (20 reads)", rtts[10], rtts[19]);

    // The firmware carries every map: 0x2190 takes the JMC, DS-CLS9 and EC-57 maps (for the
    // next power-up) and refuses a map there is none of.
    write(&mut ctx, 0x2190, 1).await.expect("the JMC map is carried");
    assert_eq!(read(&mut ctx, 0x2190, 1).await, vec![1]);
    write(&mut ctx, 0x2190, 2).await.expect("the DS-CLS9 map is carried");
    assert_eq!(read(&mut ctx, 0x2190, 1).await, vec![2]);
    write(&mut ctx, 0x2190, 3).await.expect("the EC-57 map is carried");
    assert_eq!(read(&mut ctx, 0x2190, 1).await, vec![3]);
    assert_eq!(write(&mut ctx, 0x2190, 4).await, Err(ExceptionCode::IllegalDataValue));
    write(&mut ctx, 0x2190, 0).await.expect("back to the native map");

    // A write that is out of range changes nothing.
    assert_eq!(write(&mut ctx, 0x6011, 7).await, Err(ExceptionCode::IllegalDataValue));
    assert_eq!(read(&mut ctx, 0x6011, 1).await, vec![1], "still enabled");

    // §9.4.1 style: speed 4000 pps forward, then 2000 steps, each 32-bit value half by half.
    for (reg, v) in [(0x6003, 0), (0x6004, 4000), (0x6002, 0), (0x6005, 0), (0x6006, 2000)] {
        write(&mut ctx, reg, v).await.expect("accepted");
    }
    let start = Instant::now();
    // No save while the axis moves (a page erase would stall the chip's flash): refused, 04.
    assert_eq!(write(&mut ctx, 0x200F, 2).await, Err(ExceptionCode::ServerDeviceFailure));
    let mut seen = Vec::new();
    loop {
        let busy = read(&mut ctx, 0x6001, 1).await[0] & 0x08 != 0;
        let p = position(&read(&mut ctx, 0x600E, 2).await);
        seen.push(p);
        if !busy {
            break;
        }
        assert!(start.elapsed() < Duration::from_secs(20), "still busy; positions {seen:?}");
    }
    assert!(seen.iter().any(|&p| p > 0 && p < 2000), "the position advances during the move: {seen:?}");
    assert!(seen.windows(2).all(|w| w[0] <= w[1]), "monotonic: {seen:?}");
    assert_eq!(position(&read(&mut ctx, 0x600E, 2).await), 2000, "ends exactly on target");
    println!("move of 2000 steps at 4000 pps: idle after {:?}, {} position reads", start.elapsed(), seen.len());

    // At rest a save runs: into the store that QEMU's board keeps in RAM (empty at boot, 0x2120
    // bit 0), bit 3 while it runs, and no failure (bit 4).
    assert_eq!(read(&mut ctx, 0x2120, 1).await, vec![0x01], "the store is empty at boot");
    write(&mut ctx, 0x200F, 2).await.expect("a save at rest");
    let start = Instant::now();
    let status = loop {
        let status = read(&mut ctx, 0x2120, 1).await[0];
        if status & 0x08 == 0 {
            break status;
        }
        assert!(start.elapsed() < Duration::from_secs(10), "the save did not end");
    };
    assert_eq!(status & 0x10, 0, "the save failed: 0x2120 = {status:#04x}");
}
