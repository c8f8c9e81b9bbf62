//! `hal-sim`: one simulated drive on a pseudo-terminal (default) or a TCP port.
//!
//! Prints `listening on <endpoint>` as its first line on stdout, then serves masters until killed.
//! Exit code 2: a bad command line (including an address or baud rate the drive does not take).

use std::io::{self, ErrorKind, Write};
use std::path::PathBuf;
use std::process::ExitCode;

use clap::Parser;
use hal_sim::{Endpoint, SimOptions, Simulator};

/// One simulated OpenStep drive, a Modbus-RTU slave, on a pseudo-terminal or a TCP port.
///
/// Prints `listening on <endpoint>` first: the pseudo-terminal's path (`/dev/pts/N`), which any
/// serial master can open, or the bound HOST:PORT with --tcp.
#[derive(Parser, Debug)]
#[command(version, about)]
struct Args {
    /// Also put a symlink at PATH pointing to the pseudo-terminal (replacing a stale one).
    #[arg(long, value_name = "PATH", conflicts_with = "tcp")]
    pty: Option<PathBuf>,
    /// Listen on TCP at HOST:PORT instead (port 0: any free port); each connection carries raw
    /// RTU frames with their CRC, no MBAP header.
    #[arg(long, value_name = "HOST:PORT")]
    tcp: Option<String>,
    /// Slave address, 1-127 [default: the drive's node id, factory 1].
    #[arg(long, value_name = "N")]
    address: Option<u8>,
    /// Baud rate the frame timing (t1.5, t3.5) follows [default: the drive's, factory 9600].
    #[arg(long, value_name = "B")]
    baud: Option<u32>,
}

fn main() -> ExitCode {
    let args = Args::parse();
    let endpoint = match args.tcp {
        Some(addr) => Endpoint::Tcp(addr),
        None => Endpoint::Pty { link: args.pty },
    };
    let sim = match Simulator::bind(SimOptions { endpoint, address: args.address, baud: args.baud }) {
        Ok(sim) => sim,
        Err(e) => {
            eprintln!("hal-sim: {e}");
            return ExitCode::from(if e.kind() == ErrorKind::InvalidInput { 2 } else { 1 });
        }
    };
    let mut out = io::stdout().lock();
    if let Err(e) = writeln!(out, "listening on {}", sim.endpoint()).and_then(|()| out.flush()) {
        eprintln!("hal-sim: stdout: {e}");
        return ExitCode::FAILURE;
    }
    drop(out);
    let Err(e) = sim.run();
    eprintln!("hal-sim: {e}");
    ExitCode::FAILURE
}
