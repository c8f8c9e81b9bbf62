//! `cargo xtask <task>`: the one place that orchestrates checks, the firmware build and the
//! external Modbus masters.
//!
//! - `ci`: everything CI runs (format, lints, host tests, firmware build and size, real masters).
//! - `docs`: regenerate `docs/registers.md` from the object declarations.
//! - `masters`: run pymodbus and mbpoll against the simulator.
//! - `firmware`: cross-build the firmware and print its size.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, Stdio};

const TARGET: &str = "thumbv7em-none-eabihf";

fn main() -> ExitCode {
    let task = std::env::args().nth(1).unwrap_or_default();
    let result = match task.as_str() {
        "ci" => ci(),
        "docs" => {
            run(cargo().args(["test", "-q", "-p", "drive-core", "--test", "registers_doc"]).env("UPDATE_DOCS", "1"))
        }
        "masters" => masters(),
        "firmware" => firmware(),
        _ => Err(format!("usage: cargo xtask <ci|docs|masters|firmware>, not {task:?}")),
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
    step("external masters");
    masters()
}

fn firmware() -> Result<(), String> {
    run(cargo().args(["build", "-p", "firmware", "--target", TARGET, "--profile", "firmware"]))?;
    let elf = root().join("target").join(TARGET).join("firmware").join("firmware");
    match Command::new("arm-none-eabi-size").arg(&elf).status() {
        Ok(s) if s.success() => Ok(()),
        _ => {
            eprintln!("(arm-none-eabi-size not found: install binutils-arm-none-eabi for the size report)");
            Ok(())
        }
    }
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
