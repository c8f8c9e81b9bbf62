//! Workspace-level tests of the drive: see `tests/`. Here, what every test's master does: the
//! requests of a real Modbus master (tokio-modbus), each bounded in time, and a simulator to
//! talk to.

use std::time::Duration;

use tokio::time::timeout;
use tokio_modbus::client::{Context, Reader, Writer};
use tokio_modbus::prelude::{ExceptionCode, ReadCode};

/// How long a request may take, answer included.
pub const LIMIT: Duration = Duration::from_secs(3);

/// Reads `n` holding registers from `addr`: the values, or the drive's exception.
///
/// # Panics
/// If no answer comes within [`LIMIT`], or the transport fails.
pub async fn read(ctx: &mut Context, addr: u16, n: u16) -> Result<Vec<u16>, ExceptionCode> {
    timeout(LIMIT, ctx.read_holding_registers(addr, n)).await.expect("answer in time").expect("transport")
}

/// Reads `n` holding registers from `addr`, which must not be refused.
///
/// # Panics
/// As [`read`], and on an exception.
pub async fn read_values(ctx: &mut Context, addr: u16, n: u16) -> Vec<u16> {
    read(ctx, addr, n).await.expect("no exception")
}

/// Writes one register (0x06).
///
/// # Panics
/// As [`read`].
pub async fn write(ctx: &mut Context, addr: u16, v: u16) -> Result<(), ExceptionCode> {
    timeout(LIMIT, ctx.write_single_register(addr, v)).await.expect("answer in time").expect("transport")
}

/// Writes registers from `addr` (0x10).
///
/// # Panics
/// As [`read`].
pub async fn write_many(ctx: &mut Context, addr: u16, v: &[u16]) -> Result<(), ExceptionCode> {
    timeout(LIMIT, ctx.write_multiple_registers(addr, v)).await.expect("answer in time").expect("transport")
}

/// The vendor name (object 0) of the basic device identification (0x2B / 0x0E).
///
/// # Panics
/// As [`read`], and on an exception.
pub async fn vendor_name(ctx: &mut Context) -> Option<Vec<u8>> {
    let id = timeout(LIMIT, ctx.read_device_identification(ReadCode::Basic, 0))
        .await
        .expect("answer in time")
        .expect("transport")
        .expect("identification");
    id.device_id_objects.iter().find(|o| o.id == 0).map(|o| o.value.to_vec())
}

/// A simulated drive on a TCP endpoint with its parameter flash in `flash`, running `scale`
/// times faster than wall time, with the switches of `machine` and the simulator's `faults`
/// (`--fault` specs); and its state's snapshot.
///
/// # Panics
/// If the simulator cannot bind or a fault spec does not parse.
pub fn power_on(
    flash: &std::path::Path,
    machine: hal_sim::machine::Machine,
    scale: u32,
    faults: &[&str],
) -> (hal_sim::PowerSwitch, std::sync::Arc<std::sync::Mutex<hal_sim::Snapshot>>) {
    let opts = hal_sim::SimOptions {
        endpoint: hal_sim::Endpoint::Tcp("127.0.0.1:0".into()),
        flash: Some(flash.to_owned()),
        machine,
        time_scale: scale,
        faults: faults.iter().map(|f| f.parse().expect("fault spec")).collect(),
        ..Default::default()
    };
    let (sim, snapshot, _) = power_on_with(opts);
    (sim, snapshot)
}

/// The simulator `opts` describe, switched on: its power switch, its snapshot, and the handle
/// that changes its machine while it runs (an input's wire, the supply).
///
/// # Panics
/// If the simulator cannot bind its endpoint.
pub fn power_on_with(
    opts: hal_sim::SimOptions,
) -> (hal_sim::PowerSwitch, std::sync::Arc<std::sync::Mutex<hal_sim::Snapshot>>, hal_sim::inject::Injector) {
    let sim = hal_sim::Simulator::bind(opts).expect("bind simulator");
    let (snapshot, injector) = (sim.snapshot(), sim.injector());
    (sim.power_on(), snapshot, injector)
}

/// A tokio-modbus RTU master over the simulator's TCP endpoint, to node 1.
///
/// # Panics
/// If the endpoint does not accept the connection.
pub async fn master(sim: &hal_sim::PowerSwitch) -> Context {
    let stream = tokio::net::TcpStream::connect(sim.endpoint()).await.expect("connect");
    tokio_modbus::client::rtu::attach_slave(stream, tokio_modbus::prelude::Slave(1))
}

/// The firmware under QEMU (`cargo xtask qemu`), for the tests that talk to it.
pub mod qemu {
    use std::io::{BufRead, BufReader};
    use std::path::Path;
    use std::process::{Child, ChildStdout, Command, Stdio};
    use std::time::{Duration, Instant};

    /// Whether QEMU 10's `qemu-system-arm` is installed.
    pub fn qemu_10() -> bool {
        Command::new("qemu-system-arm")
            .arg("--version")
            .output()
            .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).starts_with("QEMU emulator version 10."))
    }

    /// `cargo xtask qemu` and its stdout, stopped when dropped (its stdin closes, then it is killed).
    pub struct Firmware(
        Child,
        #[allow(dead_code, reason = "held open for the child's later output")] BufReader<ChildStdout>,
    );

    impl Drop for Firmware {
        fn drop(&mut self) {
            drop(self.0.stdin.take());
            let end = Instant::now() + Duration::from_secs(5);
            while Instant::now() < end {
                if let Ok(Some(_)) = self.0.try_wait() {
                    return;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }

    /// Builds and boots the QEMU firmware; returns it and the endpoint it listens on.
    ///
    /// # Panics
    /// If `cargo xtask qemu` does not start or does not say where it listens.
    pub fn boot() -> (Firmware, String) {
        let (fw, at, _) = boot_with_monitor();
        (fw, at)
    }

    /// [`boot`], and the endpoint of QEMU's monitor (`system_reset` restarts the emulated chip,
    /// its parameter store kept).
    ///
    /// # Panics
    /// If `cargo xtask qemu` does not start or does not say where it listens.
    pub fn boot_with_monitor() -> (Firmware, String, String) {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("workspace root");
        let mut child = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
            .args(["run", "-q", "-p", "xtask", "--", "qemu", "--tcp", "127.0.0.1:0", "--exit-on-eof"])
            .current_dir(root)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .expect("cargo xtask qemu");
        let mut stdout = BufReader::new(child.stdout.take().expect("piped stdout"));
        let mut line = String::new();
        stdout.read_line(&mut line).expect("first line of cargo xtask qemu");
        let at = line.trim().strip_prefix("listening on ").unwrap_or_else(|| panic!("unexpected line {line:?}"));
        let at = at.to_string();
        line.clear();
        stdout.read_line(&mut line).expect("second line of cargo xtask qemu");
        let monitor = line.trim().strip_prefix("monitor on ").unwrap_or_else(|| panic!("unexpected line {line:?}"));
        let monitor = monitor.to_string();
        (Firmware(child, stdout), at, monitor)
    }

    /// Restarts the emulated chip through QEMU's monitor at `monitor`.
    ///
    /// # Panics
    /// If the monitor cannot be reached.
    pub fn reset(monitor: &str) {
        use std::io::{Read, Write};
        let mut m = std::net::TcpStream::connect(monitor).expect("QEMU's monitor");
        m.write_all(b"system_reset\n").expect("to the monitor");
        m.set_read_timeout(Some(Duration::from_millis(300))).expect("a read timeout");
        let _ = m.read(&mut [0u8; 1024]);
    }
}
