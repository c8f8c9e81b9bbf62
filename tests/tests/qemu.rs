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
    assert_eq!(write(&mut ctx, 0x2190, 5).await, Err(ExceptionCode::IllegalDataValue));
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

/// One raw RTU exchange on QEMU's serial line: `body` with its CRC, and the reply's bytes up to
/// a 30 ms gap (`None` if nothing came within `wait`).
fn exchange(s: &mut std::net::TcpStream, body: &[u8], wait: Duration) -> Option<Vec<u8>> {
    use std::io::Write;
    let mut frame = body.to_vec();
    frame.extend_from_slice(&drive_core::crc::crc16(body).to_le_bytes());
    s.write_all(&frame).expect("to QEMU's serial port");
    receive(s, wait)
}

/// The bytes that arrive on QEMU's serial line up to a 30 ms gap (`None` if nothing came within
/// `wait`).
fn receive(s: &mut std::net::TcpStream, wait: Duration) -> Option<Vec<u8>> {
    use std::io::Read;
    let mut reply = Vec::new();
    let mut buf = [0u8; 512];
    s.set_read_timeout(Some(wait)).expect("a read timeout");
    while let Ok(n) = s.read(&mut buf) {
        if n == 0 {
            break;
        }
        reply.extend_from_slice(&buf[..n]);
        s.set_read_timeout(Some(Duration::from_millis(30))).expect("a read timeout");
    }
    (!reply.is_empty()).then_some(reply)
}

/// Waits for the drive at `at` to answer the device identification (every map answers it), as
/// after a restart; the connection is closed again, for the next master.
fn wait_up(at: &str) {
    let start = Instant::now();
    let mut s = std::net::TcpStream::connect(at).expect("QEMU's serial port");
    while exchange(&mut s, &[1, 0x2B, 0x0E, 1, 0], Duration::from_millis(300)).is_none_or(|r| r.get(1) != Some(&0x2B)) {
        assert!(start.elapsed() < Duration::from_secs(30), "the drive did not come back after the reset");
        // Let the drive's receiver drop a request cut by the restart (frames.rs: 250 ms).
        std::thread::sleep(Duration::from_millis(300));
    }
}

/// Runs `f` with tokio-modbus on the drive at `at`, unit 1, in a runtime of its own: once `f`
/// is done the runtime and its tasks end and the connection closes, so that QEMU's serial port
/// (one client at a time) takes the next one.
fn on_modbus<T>(at: &str, f: impl AsyncFnOnce(&mut tokio_modbus::client::Context) -> T) -> T {
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().expect("a runtime");
    runtime.block_on(async {
        let stream = TcpStream::connect(at).await.expect("connect to QEMU's USART");
        stream.set_nodelay(true).expect("TCP_NODELAY");
        let mut ctx = rtu::attach_slave(coalesced(stream), Slave(1));
        f(&mut ctx).await
    })
}

/// Chooses map `id` (0x2190) and saves it (0x200F = 2), both at their native addresses, which
/// every map but EC-57 has; the save is given time to end before the chip restarts.
async fn switch_to(ctx: &mut tokio_modbus::client::Context, id: u16) {
    write(ctx, 0x2190, id).await.expect("a map the firmware carries");
    write(ctx, 0x200F, 2).await.expect("a save at rest");
    tokio::time::sleep(Duration::from_millis(500)).await;
}

/// An EC-57 request (seed 003: the sub-index after the index) and its reply, CRC checked.
fn ec57(s: &mut std::net::TcpStream, body: &[u8]) -> Vec<u8> {
    let reply = exchange(s, body, Duration::from_secs(2)).unwrap_or_else(|| panic!("no reply to {body:02x?}"));
    assert!(drive_core::crc::frame_ok(&reply), "reply {reply:02x?} to {body:02x?}");
    reply
}

#[test]
fn every_map_is_served_under_qemu_across_restarts() {
    if !qemu_10() {
        eprintln!("SKIPPED: qemu-system-arm 10 is not installed (.ci/install installs it from bookworm-backports)");
        return;
    }
    let (_fw, at, monitor) = drive_tests::qemu::boot_with_monitor();
    let restart = || {
        drive_tests::qemu::reset(&monitor);
        wait_up(&at);
    };
    // Native: a setting every map reaches, then the JMC map, saved, and a restart.
    on_modbus(&at, async |ctx| {
        write(ctx, 0x600D, 1000).await.expect("phase current");
        switch_to(ctx, 1).await;
    });
    restart();

    // JMC (seed 001): its registers, its profile acceleration in 0.1 rev/s², back to 0x2190.
    on_modbus(&at, async |ctx| {
        assert_eq!(read(ctx, 0x2190, 1).await, vec![1], "the JMC map after the restart");
        assert_eq!(read(ctx, 0x6083, 1).await, vec![1600], "JMC's factory PP acceleration");
        write(ctx, 0x6083, 1200).await.expect("PP acceleration");
        assert_eq!(read(ctx, 0x6083, 1).await, vec![1200]);
        assert_eq!(write(ctx, 0x2190, 9).await, Err(ExceptionCode::IllegalDataValue), "no map 9");
        switch_to(ctx, 2).await;
    });
    restart();

    // DS-CLS9 (seed 002): decimal registers; 0241 is the phase current the native map set.
    on_modbus(&at, async |ctx| {
        assert_eq!(read(ctx, 0x2190, 1).await, vec![2], "the DS-CLS9 map after the restart");
        assert_eq!(read(ctx, 241, 1).await, vec![1000], "the phase current, saved in the native map");
        write(ctx, 213, 50).await.expect("standstill current, %");
        assert_eq!(read(ctx, 213, 1).await, vec![50]);
        assert_eq!(write(ctx, 213, 5).await, Err(ExceptionCode::IllegalDataValue), "under 10 %");
        switch_to(ctx, 3).await;
    });
    restart();

    // EC-57 (seed 003): sub-indexed frames, one byte longer than the other maps' (no master we
    // did not write frames them; drivectl does, and this test does it by hand).
    {
        let mut s = std::net::TcpStream::connect(&at).expect("QEMU's serial port");
        assert_eq!(ec57(&mut s, &[1, 3, 0x21, 0x90, 0xFF, 0, 1]).get(..5), Some(&[1, 3, 2, 0, 3][..]), "the map");
        let standstill = ec57(&mut s, &[1, 3, 0x20, 0x03, 2, 0, 1]);
        assert_eq!(standstill.get(3..5), Some(&[0, 50][..]), "0x2003.2, saved in the DS-CLS9 map");
        let delay = [1, 6, 0x20, 0x03, 1, 0x01, 0x2C];
        assert_eq!(ec57(&mut s, &delay).get(..7), Some(&delay[..]), "0x2003.1 = 300 ms, echoed");
        assert_eq!(ec57(&mut s, &[1, 3, 0x20, 0x03, 1, 0, 1]).get(3..5), Some(&[0x01, 0x2C][..]));
        let window = ec57(&mut s, &[1, 3, 0x60, 0x0D, 0xFF, 0, 1]);
        assert_eq!(window.get(3..5), Some(&[0x03, 0xE8][..]), "the native phase current in the window");
        // Out of the table: the manual's exception 03.
        assert_eq!(ec57(&mut s, &[1, 3, 0x20, 0x03, 7, 0, 1]).get(1..3), Some(&[0x83, 0x03][..]));
        // On to the servo map through the window, saved (0x2030 = 1).
        ec57(&mut s, &[1, 6, 0x21, 0x90, 0xFF, 0, 4]);
        ec57(&mut s, &[1, 6, 0x20, 0x30, 0, 0, 1]);
        std::thread::sleep(Duration::from_millis(500));
    }
    restart();

    // Servo (seed 004): P□602, a position data group low word first, the standstill current of
    // the DS-CLS9 map as the drive's, then back to the native map.
    on_modbus(&at, async |ctx| {
        assert_eq!(read(ctx, 0x2190, 1).await, vec![4], "the servo map after the restart");
        write(ctx, 0x025A, 50).await.expect("P602");
        assert_eq!(read(ctx, 0x025A, 1).await, vec![50]);
        let group = [3200, 0, 600, 1, 0, 0, 1, 1];
        drive_tests::write_many(ctx, 0x0600, &group).await.expect("group 0");
        assert_eq!(read(ctx, 0x0600, 8).await, group.to_vec());
        assert_eq!(write(ctx, 0x0607, 3).await, Err(ExceptionCode::IllegalDataValue), "no type 3");
        assert_eq!(read(ctx, 0x0100, 2).await, vec![0, 0], "a parameter the excerpt does not describe");
        write(ctx, 0x025A, 0).await.expect("P602 off");
        switch_to(ctx, 0).await;
    });
    restart();

    on_modbus(&at, async |ctx| {
        assert_eq!(read(ctx, 0x2190, 1).await, vec![0], "native again");
        assert_eq!(read(ctx, 0x2102, 2).await, vec![50, 300], "what the other maps set, saved");
        assert_eq!(read(ctx, 0x600D, 1).await, vec![1000]);
    });
}

#[test]
fn back_to_back_frames_of_256_bytes_are_all_taken() {
    if !qemu_10() {
        eprintln!("SKIPPED: qemu-system-arm 10 is not installed (.ci/install installs it from bookworm-backports)");
        return;
    }
    use std::io::Write;
    let (_fw, at, _) = drive_tests::qemu::boot_with_monitor();
    let mut s = std::net::TcpStream::connect(&at).expect("QEMU's serial port");
    // Bus counters first (0x08 sub-function 0x0A clears them).
    exchange(&mut s, &[1, 8, 0, 0x0A, 0, 0], Duration::from_secs(2)).expect("counters cleared");
    // The longest requests there are, 255 bytes with their CRC (a 0x10 write of 123 registers),
    // sent in one burst with no gap: four to other drives on the bus (taken whole and ignored),
    // one broadcast (refused, silently: 0x6000.. holds read-only words), then a read.
    let frame = |unit: u8, start: u16, first: u16| {
        let mut f = vec![unit, 0x10];
        f.extend(start.to_be_bytes());
        f.extend([0, 123, 246]);
        for k in 0..123u16 {
            f.extend((first + k).to_be_bytes());
        }
        f.extend(drive_core::crc::crc16(&f).to_le_bytes());
        assert_eq!(f.len(), 255);
        f
    };
    let mut burst = Vec::new();
    for unit in 2..=5 {
        burst.extend(frame(unit, 0x6000, 0));
    }
    burst.extend(frame(0, 0x6000, 0));
    let read = [1, 3, 0x60, 0x0C, 0, 2];
    burst.extend(&read);
    burst.extend(drive_core::crc::crc16(&read).to_le_bytes());
    let sent = Instant::now();
    s.write_all(&burst).expect("the burst");
    // Only the read is answered: the other frames are not this drive's, and a broadcast gets no
    // reply (its refusal included).
    let reply = receive(&mut s, Duration::from_secs(10)).expect("the read's reply");
    println!("{} bytes in one burst, the read answered {:?} after the last byte was sent", burst.len(), sent.elapsed());
    assert_eq!(reply, [1, 3, 4, 0, 0, 2, 0x92, 0x7A, 0xFE], "the read after the burst");
    // Every frame was taken whole: six frames with a good CRC on the bus (then this request),
    // none with a bad one, none overrun; two of them for this drive (the broadcast, the read).
    let counter = |s: &mut std::net::TcpStream, sub: u8| {
        let r = exchange(s, &[1, 8, 0, sub, 0, 0], Duration::from_secs(2)).expect("a counter");
        u16::from_be_bytes([r[4], r[5]])
    };
    assert_eq!(counter(&mut s, 0x0B), 7, "bus messages: the burst's six and this request");
    assert_eq!(counter(&mut s, 0x0C), 0, "bus communication errors (a lost byte spoils a CRC)");
    assert_eq!(counter(&mut s, 0x12), 0, "character overruns");
    assert_eq!(counter(&mut s, 0x0E), 2 + 3 + 1, "frames for this drive: the burst's two and these four requests");
}
