//! `cargo xtask <task>`: the one place that orchestrates checks, the firmware build and the
//! external Modbus masters.
//!
//! - `ci`: everything CI runs (format, lints, host tests, firmware build and size, real masters).
//! - `docs`: regenerate `docs/registers.md` from the object declarations.
//! - `masters`: run pymodbus and mbpoll against the simulator.
//! - `firmware`: cross-build the firmware, print its size, fail over the budget.
//! - `qemu --tcp HOST:PORT`: build the QEMU variant and run it with its USART on that port.
//! - `hil`: build the hardware-in-the-loop suite (`probe-rs` runs it on a board).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

const TARGET: &str = "thumbv7em-none-eabihf";
/// The budget for the G431 build, with every feature.
const FLASH_BUDGET: u64 = 64 * 1024;
/// RAM budget: statics plus the stack allowance below.
const RAM_BUDGET: u64 = 24 * 1024;
/// Stack set aside in the RAM budget (flip-link gives the stack the rest of RAM, 27 KB).
const STACK_ALLOWANCE: u64 = 8 * 1024;

fn main() -> ExitCode {
    let task = std::env::args().nth(1).unwrap_or_default();
    let result = match task.as_str() {
        "ci" => ci(),
        "docs" => {
            run(cargo().args(["test", "-q", "-p", "drive-core", "--test", "registers_doc"]).env("UPDATE_DOCS", "1"))
        }
        "masters" => masters(),
        "firmware" => firmware(),
        "qemu" => qemu(&std::env::args().skip(2).collect::<Vec<_>>()),
        "hil" => hil(),
        _ => Err(format!("usage: cargo xtask <ci|docs|masters|firmware|qemu --tcp HOST:PORT|hil>, not {task:?}")),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask {task}: {e}");
            ExitCode::FAILURE
        }
    }
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().map(Path::to_path_buf).unwrap_or_default()
}

fn cargo() -> Command {
    let mut c = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    c.current_dir(root());
    c
}

fn run(cmd: &mut Command) -> Result<(), String> {
    eprintln!("$ {cmd:?}");
    let status = cmd.status().map_err(|e| format!("{cmd:?}: {e}"))?;
    if status.success() { Ok(()) } else { Err(format!("{cmd:?} failed: {status}")) }
}

fn step(name: &str) {
    eprintln!("\n=== {name} ===");
}

fn ci() -> Result<(), String> {
    step("rustfmt");
    run(cargo().args(["fmt", "--all", "--check"]))?;
    step("clippy (host)");
    run(cargo().args(["clippy", "--workspace", "--all-targets", "--", "-D", "warnings"]))?;
    step("clippy (firmware)");
    run(cargo().args([
        "clippy",
        "-p",
        "firmware",
        "--target",
        TARGET,
        "--profile",
        "firmware",
        "--",
        "-D",
        "warnings",
    ]))?;
    step("tests (host, including the register reference and tokio-modbus)");
    // The default members: the firmware is cross-built below, never for the host.
    run(cargo().arg("test"))?;
    step("firmware build and size");
    firmware()?;
    step("QEMU firmware build and clippy");
    run(cargo()
        .args(firmware_args("clippy", &["--no-default-features", "--features", "qemu"]))
        .args(["--", "-D", "warnings"]))?;
    step("HIL suite build");
    hil()?;
    step("tokio-modbus against the firmware under QEMU");
    run(cargo().args(["test", "-p", "drive-tests", "--test", "qemu", "--", "--nocapture"]))?;
    step("external masters");
    masters()
}

/// `cargo <verb> -p firmware` for the microcontroller, with `extra` arguments.
fn firmware_args<'a>(verb: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut v = vec![verb, "-p", "firmware", "--target", TARGET, "--profile", "firmware"];
    v.extend_from_slice(extra);
    v
}

fn elf_dir() -> PathBuf {
    root().join("target").join(TARGET).join("firmware")
}

/// Builds the G431 firmware and checks it against the flash and RAM budgets.
fn firmware() -> Result<(), String> {
    run(cargo().args(firmware_args("build", &[])))?;
    let elf = elf_dir().join("firmware");
    let out = Command::new("arm-none-eabi-size")
        .arg("-A")
        .arg(&elf)
        .output()
        .map_err(|e| format!("arm-none-eabi-size (install binutils-arm-none-eabi, .ci/install does): {e}"))?;
    let sections = String::from_utf8_lossy(&out.stdout);
    let size = |name: &str| -> u64 {
        sections
            .lines()
            .filter_map(|l| {
                let mut f = l.split_whitespace();
                (f.next() == Some(name)).then(|| f.next().and_then(|n| n.parse::<u64>().ok())).flatten()
            })
            .sum()
    };
    let flash = size(".vector_table") + size(".text") + size(".rodata") + size(".data");
    let statics = size(".data") + size(".bss") + size(".uninit");
    let ram = statics + STACK_ALLOWANCE;
    println!("firmware (STM32G431CB): flash {flash} B of {FLASH_BUDGET} B ({:.1} %)", percent(flash, FLASH_BUDGET));
    println!(
        "firmware (STM32G431CB): RAM {statics} B of statics + {STACK_ALLOWANCE} B stack = {ram} B of {RAM_BUDGET} B ({:.1} %)",
        percent(ram, RAM_BUDGET)
    );
    if flash == 0 {
        return Err(format!("no sections read from {}", elf.display()));
    }
    if flash > FLASH_BUDGET || ram > RAM_BUDGET {
        return Err("the firmware is over its size budget".into());
    }
    Ok(())
}

fn percent(part: u64, whole: u64) -> f64 {
    part as f64 * 100.0 / whole as f64
}

/// Builds the QEMU variant; returns its ELF (copied aside, the G431 build shares the path).
fn build_qemu() -> Result<PathBuf, String> {
    run(cargo().args(firmware_args("build", &["--no-default-features", "--features", "qemu"])))?;
    let elf = elf_dir().join("firmware-qemu");
    std::fs::copy(elf_dir().join("firmware"), &elf).map_err(|e| format!("{}: {e}", elf.display()))?;
    Ok(elf)
}

/// `qemu --tcp HOST:PORT [--exit-on-eof]`: boots the QEMU variant with USART1 as a TCP server
/// on HOST:PORT (port 0: a free one), prints `listening on HOST:PORT` once the drive answers a
/// read, then runs until QEMU ends (or, with `--exit-on-eof`, until stdin closes).
fn qemu(args: &[String]) -> Result<(), String> {
    let usage = "usage: cargo xtask qemu --tcp HOST:PORT [--exit-on-eof]";
    let endpoint = match args {
        [flag, e, ..] if flag == "--tcp" => e.clone(),
        _ => return Err(usage.into()),
    };
    let exit_on_eof = args.iter().any(|a| a == "--exit-on-eof");
    let (host, port) = endpoint.rsplit_once(':').ok_or(usage)?;
    let port = match port.parse::<u16>().map_err(|e| format!("{endpoint}: {e}"))? {
        // QEMU does not say which port it took: take a free one for it.
        0 => TcpListener::bind((host, 0)).and_then(|l| l.local_addr()).map_err(|e| e.to_string())?.port(),
        p => p,
    };
    let elf = build_qemu()?;
    let started = Instant::now();
    let child = Command::new("qemu-system-arm")
        .args(["-M", "b-l475e-iot01a", "-nographic", "-monitor", "none", "-kernel"])
        .arg(&elf)
        .arg("-serial")
        .arg(format!("tcp:{host}:{port},server=on,wait=off"))
        // Not our stdout: whoever reads the `listening on` line may close it afterwards.
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .spawn()
        .map_err(|e| format!("qemu-system-arm (QEMU 10, .ci/install installs it): {e}"))?;
    let mut qemu = Qemu(child);
    let first_answer = probe(host, port, &mut qemu.0)?;
    eprintln!(
        "QEMU: first answer {:.1} ms after launch; a read request's round trip {:.2} ms",
        started.elapsed().as_secs_f64() * 1e3,
        first_answer.as_secs_f64() * 1e3
    );
    println!("listening on {host}:{port}");
    std::io::stdout().flush().map_err(|e| e.to_string())?;
    if exit_on_eof {
        // Whoever started us is gone or done: stop QEMU with us.
        let _ = std::io::stdin().read_to_end(&mut Vec::new());
        return Ok(());
    }
    let status = qemu.0.wait().map_err(|e| e.to_string())?;
    if status.success() { Ok(()) } else { Err(format!("qemu: {status}")) }
}

/// QEMU, killed when dropped.
struct Qemu(Child);

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Reads 0x600C..0x600D until the drive answers (QEMU boots in tens of ms); returns the round
/// trip of the answered read.
fn probe(host: &str, port: u16, qemu: &mut Child) -> Result<Duration, String> {
    let request = [0x01, 0x03, 0x60, 0x0C, 0x00, 0x02, 0x1A, 0x08];
    let deadline = Instant::now() + Duration::from_secs(20);
    while Instant::now() < deadline {
        if let Ok(Some(status)) = qemu.try_wait() {
            return Err(format!("qemu exited: {status}"));
        }
        let Ok(mut s) = TcpStream::connect((host, port)) else {
            std::thread::sleep(Duration::from_millis(5));
            continue;
        };
        s.set_read_timeout(Some(Duration::from_millis(200))).map_err(|e| e.to_string())?;
        for _ in 0..50 {
            let sent = Instant::now();
            s.write_all(&request).map_err(|e| e.to_string())?;
            let mut reply = [0u8; 9];
            if s.read_exact(&mut reply).is_ok() && reply.get(..3) == Some(&[0x01, 0x03, 0x04][..]) {
                return Ok(sent.elapsed());
            }
            // A partial or garbled answer: let the drive's silence timeout clear its receiver.
            std::thread::sleep(Duration::from_millis(50));
        }
    }
    Err(format!("the drive under QEMU did not answer on {host}:{port}"))
}

/// Builds the embedded-test HIL suite for the G431 (it runs with `probe-rs` on a board).
fn hil() -> Result<(), String> {
    run(cargo().args(firmware_args("build", &["--test", "hil"])))
}

/// A simulator process, killed when dropped.
struct Sim(Child, String);

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn start_sim(args: &[&str]) -> Result<Sim, String> {
    let bin = root().join("target/release/hal-sim");
    let mut child =
        Command::new(&bin).args(args).stdout(Stdio::piped()).spawn().map_err(|e| format!("{}: {e}", bin.display()))?;
    let mut line = String::new();
    let stdout = child.stdout.take().ok_or("no stdout")?;
    BufReader::new(stdout).read_line(&mut line).map_err(|e| e.to_string())?;
    let endpoint = line.trim().strip_prefix("listening on ").ok_or(format!("unexpected first line {line:?}"))?;
    eprintln!("simulator listening on {endpoint}");
    Ok(Sim(child, endpoint.to_string()))
}

fn masters() -> Result<(), String> {
    run(cargo().args(["build", "--release", "-p", "hal-sim"]))?;
    let venv = root().join("target/venv/bin/python");
    let python = if venv.exists() { venv } else { PathBuf::from("python3") };
    let script = root().join("tests/masters");

    let sim = start_sim(&[])?;
    run(Command::new(&python).arg(script.join("pymodbus_check.py")).arg(&sim.1))?;
    drop(sim);
    let sim = start_sim(&["--tcp", "127.0.0.1:0"])?;
    run(Command::new(&python).arg(script.join("pymodbus_check.py")).arg(&sim.1))?;
    drop(sim);
    let sim = start_sim(&[])?;
    run(Command::new("bash").arg(script.join("mbpoll_check.sh")).arg(&sim.1))
}
