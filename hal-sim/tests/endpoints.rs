//! The simulator as masters see it: the binary's command line and first line, raw RTU frames over
//! TCP and over the pseudo-terminal, masters that come and go, frames that get no answer.

use std::fs::{File, OpenOptions};
use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::os::fd::AsFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::thread;
use std::time::{Duration, Instant};

use drive_core::crc::crc16;
use hal_sim::{Endpoint, SimOptions, Simulator};
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use nix::sys::termios::{SetArg, cfmakeraw, tcgetattr, tcsetattr};

/// How long anything may take before a test gives up.
const LIMIT: Duration = Duration::from_secs(5);
/// How long a frame that gets no answer is listened to.
const QUIET: Duration = Duration::from_millis(300);

/// Read 0x600C..0x600D (microstep resolution, phase current) from node 1.
const READ: [u8; 8] = [0x01, 0x03, 0x60, 0x0C, 0x00, 0x02, 0x1A, 0x08];
/// Its answer with factory settings: resolution 0, 658 mA.
const REPLY: [u8; 9] = [0x01, 0x03, 0x04, 0x00, 0x00, 0x02, 0x92, 0x7A, 0xFE];

/// `body` with its CRC appended.
fn frame(body: &[u8]) -> Vec<u8> {
    let mut f = body.to_vec();
    f.extend_from_slice(&crc16(body).to_le_bytes());
    f
}

/// The simulator binary, killed when dropped.
struct Sim {
    child: Child,
    endpoint: String,
}

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts the binary with `args` and reads its first line, `listening on <endpoint>`.
fn start(args: &[&str]) -> Sim {
    let mut child = Command::new(env!("CARGO_BIN_EXE_hal-sim"))
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .spawn()
        .expect("spawn hal-sim");
    let stdout = child.stdout.take().expect("stdout");
    let mut sim = Sim { child, endpoint: String::new() };
    let (tx, rx) = mpsc::channel();
    thread::spawn(move || {
        let mut line = String::new();
        let _ = BufReader::new(stdout).read_line(&mut line);
        let _ = tx.send(line);
    });
    let line = rx.recv_timeout(LIMIT).expect("first line in time");
    let endpoint = line.strip_suffix('\n').and_then(|l| l.strip_prefix("listening on ")).expect("listening on ..");
    sim.endpoint = endpoint.to_owned();
    sim
}

/// The simulator library on a thread of this process.
fn start_in_process(opts: SimOptions) -> String {
    let sim = Simulator::bind(opts).expect("bind");
    let at = sim.endpoint().to_owned();
    sim.spawn();
    at
}

fn connect(at: &str) -> TcpStream {
    let s = TcpStream::connect(at).expect("connect");
    s.set_read_timeout(Some(LIMIT)).expect("read timeout");
    s
}

/// Opens the pseudo-terminal as a serial master would, raw.
fn open_pts(path: impl AsRef<Path>) -> File {
    let f = OpenOptions::new().read(true).write(true).custom_flags(nix::libc::O_NOCTTY).open(path).expect("open pts");
    let mut t = tcgetattr(&f).expect("tcgetattr");
    cfmakeraw(&mut t);
    tcsetattr(&f, SetArg::TCSANOW, &t).expect("tcsetattr");
    f
}

/// Reads up to `n` bytes, for at most `limit`: what came.
fn read_for(line: &mut (impl Read + AsFd), n: usize, limit: Duration) -> Vec<u8> {
    let end = Instant::now() + limit;
    let mut got = Vec::new();
    while got.len() < n {
        let left = end.saturating_duration_since(Instant::now());
        if left.is_zero() {
            break;
        }
        let ready = {
            let mut fds = [PollFd::new(line.as_fd(), PollFlags::POLLIN)];
            let ms = PollTimeout::try_from(left.as_millis().max(1)).expect("timeout");
            poll(&mut fds, ms).expect("poll") > 0
        };
        if ready {
            let mut buf = vec![0; n - got.len()];
            let k = line.read(&mut buf).expect("read");
            if k == 0 {
                break;
            }
            got.extend_from_slice(&buf[..k]);
        }
    }
    got
}

/// Sends `request` and returns the `n`-byte answer.
fn ask(line: &mut (impl Read + Write + AsFd), request: &[u8], n: usize) -> Vec<u8> {
    line.write_all(request).expect("send");
    let got = read_for(line, n, LIMIT);
    assert_eq!(got.len(), n, "answer to {request:02X?} in time, got {got:02X?}");
    got
}

/// Sends `request` and checks that nothing comes back.
fn ask_silence(line: &mut (impl Read + Write + AsFd), request: &[u8]) {
    line.write_all(request).expect("send");
    let got = read_for(line, 1, QUIET);
    assert!(got.is_empty(), "no answer to {request:02X?}, got {got:02X?}");
}

/// Sets 0x600C (microstep resolution) to `value` with 0x06 and checks the echo.
fn set_resolution(line: &mut (impl Read + Write + AsFd), value: u8) {
    let request = frame(&[0x01, 0x06, 0x60, 0x0C, 0x00, value]);
    assert_eq!(ask(line, &request, 8), request, "0x06 echoes the request");
}

/// Reads 0x600C alone.
fn resolution(line: &mut (impl Read + Write + AsFd)) -> u16 {
    let reply = ask(line, &frame(&[0x01, 0x03, 0x60, 0x0C, 0x00, 0x01]), 7);
    assert_eq!(reply[..3], [0x01, 0x03, 0x02]);
    assert_eq!(crc16(&reply[..5]).to_le_bytes(), reply[5..]);
    u16::from_be_bytes([reply[3], reply[4]])
}

#[test]
fn tcp_answers_with_factory_settings() {
    let sim = start(&["--tcp", "127.0.0.1:0"]);
    assert!(sim.endpoint.starts_with("127.0.0.1:") && !sim.endpoint.ends_with(":0"), "{}", sim.endpoint);
    let mut master = connect(&sim.endpoint);
    assert_eq!(ask(&mut master, &READ, REPLY.len()), REPLY);
}

#[test]
fn pty_answers_with_factory_settings() {
    let sim = start(&[]);
    assert!(sim.endpoint.starts_with("/dev/pts/"), "{}", sim.endpoint);
    let mut master = open_pts(&sim.endpoint);
    assert_eq!(ask(&mut master, &READ, REPLY.len()), REPLY);
}

#[test]
fn pty_link_replaces_a_stale_one_and_masters_come_and_go() {
    let dir = tempfile::tempdir().expect("tempdir");
    let link = dir.path().join("drive");
    std::os::unix::fs::symlink("/dev/pts/does-not-exist", &link).expect("stale link");
    let sim = start(&["--pty", link.to_str().expect("utf-8 path")]);
    assert_eq!(std::fs::read_link(&link).expect("link"), Path::new(&sim.endpoint));

    let mut first = open_pts(&link);
    assert_eq!(ask(&mut first, &READ, REPLY.len()), REPLY);
    set_resolution(&mut first, 32);
    drop(first);
    // A second master finds the drive as the first one left it.
    let mut second = open_pts(&link);
    assert_eq!(resolution(&mut second), 32);
    drop(second);
    let mut third = open_pts(&sim.endpoint);
    assert_eq!(resolution(&mut third), 32);
}

#[test]
fn pty_link_never_replaces_a_file() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("drive");
    std::fs::write(&path, "keep me").expect("file");
    let out = Command::new(env!("CARGO_BIN_EXE_hal-sim"))
        .args(["--pty", path.to_str().expect("utf-8 path")])
        .stdin(Stdio::null())
        .output()
        .expect("run hal-sim");
    assert_eq!(out.status.code(), Some(1));
    assert!(out.stdout.is_empty());
    assert_eq!(std::fs::read_to_string(&path).expect("still a file"), "keep me");
}

#[test]
fn tcp_masters_come_and_go() {
    let sim = start(&["--tcp", "127.0.0.1:0"]);
    let mut first = connect(&sim.endpoint);
    set_resolution(&mut first, 16);
    drop(first);
    let mut second = connect(&sim.endpoint);
    assert_eq!(resolution(&mut second), 16);
    drop(second);
    let mut third = connect(&sim.endpoint);
    assert_eq!(ask(&mut third, &READ, REPLY.len()), frame(&[0x01, 0x03, 0x04, 0x00, 0x10, 0x02, 0x92]));
}

#[test]
fn bad_crc_gets_no_answer_and_the_next_frame_does() {
    let mut bad = READ;
    bad[7] ^= 0x01;
    let sim = start(&["--tcp", "127.0.0.1:0"]);
    let mut master = connect(&sim.endpoint);
    ask_silence(&mut master, &bad);
    assert_eq!(ask(&mut master, &READ, REPLY.len()), REPLY);

    let sim = start(&[]);
    let mut master = open_pts(&sim.endpoint);
    ask_silence(&mut master, &bad);
    assert_eq!(ask(&mut master, &READ, REPLY.len()), REPLY);
}

#[test]
fn address_option_and_other_slaves() {
    let sim = start(&["--tcp", "127.0.0.1:0", "--address", "5", "--baud", "115200"]);
    let mut master = connect(&sim.endpoint);
    ask_silence(&mut master, &READ);
    let reply = ask(&mut master, &frame(&[0x05, 0x03, 0x60, 0x0C, 0x00, 0x02]), 9);
    assert_eq!(reply, frame(&[0x05, 0x03, 0x04, 0x00, 0x00, 0x02, 0x92]));
    // The options go through the drive's own objects: node id 0x2028, baud rate 0x202A..B.
    assert_eq!(ask(&mut master, &frame(&[0x05, 0x03, 0x20, 0x28, 0x00, 0x01]), 7), frame(&[0x05, 0x03, 0x02, 0, 5]));
    let baud = ask(&mut master, &frame(&[0x05, 0x03, 0x20, 0x2A, 0x00, 0x02]), 9);
    assert_eq!(baud, frame(&[0x05, 0x03, 0x04, 0x00, 0x01, 0xC2, 0x00]));
}

/// Sets the master's side of the pseudo-terminal to `baud` and `parity` (0 none, 1 even, 2 odd)
/// as serialport and libmodbus do: PARENB and PARODD, and input parity checking.
fn set_line(master: &File, baud: u32, parity: u8) {
    use rustix::termios::{ControlModes, InputModes, OptionalActions, tcgetattr, tcsetattr};
    let mut t = tcgetattr(master).expect("tcgetattr");
    t.set_speed(baud).expect("speed");
    t.control_modes.set(ControlModes::PARENB, parity != 0);
    t.control_modes.set(ControlModes::PARODD, parity == 2);
    t.input_modes.set(InputModes::INPCK, parity != 0);
    tcsetattr(master, OptionalActions::Now, &t).expect("tcsetattr");
}

/// On the pseudo-terminal the drive hears a master only at its own baud rate and parity, as a
/// UART would; the terminal starts at the drive's settings, and 0x2100 shows `--parity`.
#[test]
fn a_pty_drive_hears_only_its_baud_rate_and_parity() {
    let sim = start(&["--baud", "38400", "--parity", "even"]);
    let mut master = open_pts(&sim.endpoint);
    assert_eq!(ask(&mut master, &READ, REPLY.len()), REPLY, "the terminal starts at the drive's settings");
    for (baud, parity) in [(9600, 1), (38400, 0), (38400, 2), (57600, 1)] {
        set_line(&master, baud, parity);
        ask_silence(&mut master, &READ);
    }
    set_line(&master, 38400, 1);
    assert_eq!(ask(&mut master, &READ, REPLY.len()), REPLY);
    assert_eq!(ask(&mut master, &frame(&[0x01, 0x03, 0x21, 0x00, 0x00, 0x01]), 7), frame(&[0x01, 0x03, 0x02, 0, 1]));
    let err = refused(&["--parity", "mark"]);
    assert!(err.contains("none, even, odd"), "{err}");
}

/// Runs the binary with `args`, which it must refuse with exit code 2 before listening.
fn refused(args: &[&str]) -> String {
    let mut child = Command::new(env!("CARGO_BIN_EXE_hal-sim"))
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn hal-sim");
    let end = Instant::now() + LIMIT;
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        if Instant::now() > end {
            let _ = child.kill();
            let _ = child.wait();
            panic!("hal-sim {args:?} still running");
        }
        thread::sleep(Duration::from_millis(10));
    };
    let mut out = String::new();
    let mut err = String::new();
    child.stdout.take().expect("stdout").read_to_string(&mut out).expect("stdout");
    child.stderr.take().expect("stderr").read_to_string(&mut err).expect("stderr");
    assert_eq!(status.code(), Some(2), "hal-sim {args:?}: {err}");
    assert_eq!(out, "", "nothing on stdout");
    err
}

#[test]
fn bad_command_lines_exit_2() {
    let err = refused(&["--baud", "1200"]);
    assert!(err.contains("unsupported baud rate 1200") && err.contains("115200"), "{err}");
    let err = refused(&["--address", "0"]);
    assert!(err.contains("invalid slave address 0"), "{err}");
    refused(&["--address", "300"]);
    refused(&["--tcp", "127.0.0.1:0", "--pty", "/tmp/x"]);
}

#[test]
fn library_serves_on_a_thread() {
    let at = start_in_process(SimOptions { endpoint: Endpoint::Tcp("127.0.0.1:0".into()), ..Default::default() });
    let mut master = connect(&at);
    assert_eq!(ask(&mut master, &READ, REPLY.len()), REPLY);

    let at = start_in_process(SimOptions::default());
    let mut master = open_pts(&at);
    assert_eq!(ask(&mut master, &READ, REPLY.len()), REPLY);
}

#[test]
fn a_frame_left_unfinished_ends_with_its_connection() {
    let at = start_in_process(SimOptions { endpoint: Endpoint::Tcp("127.0.0.1:0".into()), ..Default::default() });
    let mut first = connect(&at);
    first.write_all(&READ[..5]).expect("half a frame");
    drop(first);
    // The next master's frame follows at once, yet is not glued to the half frame before it.
    let mut second = connect(&at);
    assert_eq!(ask(&mut second, &READ, REPLY.len()), REPLY);
}

#[test]
fn drive_can_be_set_up_before_it_runs() {
    let mut sim = Simulator::bind(SimOptions {
        endpoint: Endpoint::Tcp("127.0.0.1:0".into()),
        address: Some(9),
        ..Default::default()
    })
    .expect("bind");
    assert_eq!(sim.drive().address().get(), 9);
    sim.drive_mut().state_mut().set_position(-2);
    let at = sim.endpoint().to_owned();
    sim.spawn();
    let mut master = connect(&at);
    // Motor position, 0x600E..F, high word first.
    let reply = ask(&mut master, &frame(&[0x09, 0x03, 0x60, 0x0E, 0x00, 0x02]), 9);
    assert_eq!(reply, frame(&[0x09, 0x03, 0x04, 0xFF, 0xFF, 0xFF, 0xFE]));
}

#[test]
fn saved_parameters_survive_a_kill_and_fset_low_restores_the_factory_ones() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let args = ["--tcp", "127.0.0.1:0", "--flash", flash.to_str().expect("utf-8 path")];
    let sim = start(&args);
    let mut master = connect(&sim.endpoint);
    // 1/32 microstepping and 1500 mA, then save (0x200F = 2).
    let write = frame(&[0x01, 0x10, 0x60, 0x0C, 0x00, 0x02, 0x04, 0x00, 0x20, 0x05, 0xDC]);
    assert_eq!(ask(&mut master, &write, 8), frame(&[0x01, 0x10, 0x60, 0x0C, 0x00, 0x02]));
    let save = frame(&[0x01, 0x06, 0x20, 0x0F, 0x00, 0x02]);
    assert_eq!(ask(&mut master, &save, 8), save);
    // Storage status: bit 0 (nothing was saved at power-up) only; the save is over and went well.
    let status = frame(&[0x01, 0x03, 0x21, 0x20, 0x00, 0x01]);
    assert_eq!(ask(&mut master, &status, 7), frame(&[0x01, 0x03, 0x02, 0x00, 0x01]));
    drop(master);
    drop(sim); // SIGKILL

    let saved = frame(&[0x01, 0x03, 0x04, 0x00, 0x20, 0x05, 0xDC]);
    let sim = start(&args);
    let mut master = connect(&sim.endpoint);
    assert_eq!(ask(&mut master, &READ, 9), saved);
    assert_eq!(ask(&mut master, &status, 7), frame(&[0x01, 0x03, 0x02, 0x00, 0x00]));
    drop(master);
    drop(sim);

    let fset = [&args[..], &["--fset-low"]].concat();
    let sim = start(&fset);
    let mut master = connect(&sim.endpoint);
    assert_eq!(ask(&mut master, &READ, 9), REPLY, "factory values");
    assert_eq!(ask(&mut master, &status, 7), frame(&[0x01, 0x03, 0x02, 0x00, 0x04]), "FSET bit");
    drop(master);
    drop(sim);

    let sim = start(&args);
    let mut master = connect(&sim.endpoint);
    assert_eq!(ask(&mut master, &READ, 9), REPLY, "the factory values were saved");
}

/// Reads 0x600C from `node`; `None` if nothing answers.
fn resolution_of(line: &mut (impl Read + Write + AsFd), node: u8) -> Option<u16> {
    line.write_all(&frame(&[node, 0x03, 0x60, 0x0C, 0x00, 0x01])).expect("send");
    let reply = read_for(line, 7, QUIET);
    if reply.is_empty() {
        return None;
    }
    assert_eq!(reply, frame(&[node, 0x03, 0x02, reply[3], reply[4]]), "answered by node {node} alone");
    Some(u16::from_be_bytes([reply[3], reply[4]]))
}

#[test]
fn axes_share_one_bus_each_answering_its_own_address() {
    let dir = tempfile::tempdir().expect("temp dir");
    let trace = dir.path().join("bus.csv");
    let sim = start(&["--tcp", "127.0.0.1:0", "--axes", "2,5,9", "--trace", trace.to_str().expect("utf-8")]);
    let mut master = connect(&sim.endpoint);
    // A broadcast reaches every drive and gets no answer.
    ask_silence(&mut master, &frame(&[0x00, 0x06, 0x60, 0x0C, 0x00, 16]));
    // One drive answers its own write; the others keep the broadcast value.
    let write = frame(&[0x05, 0x06, 0x60, 0x0C, 0x00, 32]);
    assert_eq!(ask(&mut master, &write, 8), write);
    assert_eq!([2, 5, 9].map(|n| resolution_of(&mut master, n)), [Some(16), Some(32), Some(16)]);
    // Nobody at 1: silence.
    assert_eq!(resolution_of(&mut master, 1), None);
    // Each drive has its own trace.
    for n in [2, 5, 9] {
        let path = hal_sim::axis_trace_path(&trace, n);
        assert!(path.ends_with(format!("bus-axis{n}.csv")), "{}", path.display());
        assert!(std::fs::metadata(&path).expect("trace file").len() > 0);
    }
}

#[test]
fn axes_are_counted_or_listed() {
    let sim = start(&["--tcp", "127.0.0.1:0", "--axes", "3"]);
    let mut master = connect(&sim.endpoint);
    assert_eq!([1, 2, 3, 4].map(|n| resolution_of(&mut master, n)), [Some(0), Some(0), Some(0), None]);
    // The same address twice, or 0, is a bad command line.
    for bad in ["1,1", "0,2", "x"] {
        let status = Command::new(env!("CARGO_BIN_EXE_hal-sim"))
            .args(["--tcp", "127.0.0.1:0", "--axes", bad])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .expect("run hal-sim");
        assert_eq!(status.code(), Some(2), "--axes {bad}");
    }
}

/// With `--wire` the pseudo-terminal is as slow as the line: a read of 125 registers at 9600
/// baud (8 bytes out, 255 back, 10 bits each) is answered no sooner than the line allows, and
/// the same read without it at once.
#[test]
fn pty_on_the_wire_takes_the_lines_time() {
    let read_125 = frame(&[0x01, 0x03, 0x60, 0x00, 0x00, 0x7D]);
    let wire = (8.0 + 255.0) * 10.0 / 9600.0;
    let timed = |args: &[&str]| {
        let sim = start(args);
        let mut line = open_pts(&sim.endpoint);
        let t = Instant::now();
        ask(&mut line, &read_125, 255);
        t.elapsed().as_secs_f64()
    };
    let paced = timed(&["--wire"]);
    assert!(paced >= wire, "{paced:.3} s, the line's {wire:.3} s");
    let instant = timed(&[]);
    assert!(instant < wire, "{instant:.3} s without --wire");
}
