//! `hal-sim`: one simulated drive on a pseudo-terminal (default) or a TCP port; with `--axes`,
//! several on one simulated bus behind it.
//!
//! Prints `listening on <endpoint>` as its first line on stdout, then serves masters until killed.
//! Exit code 2: a bad command line (including an address or baud rate the drive does not take).
//!
//! With `--script FILE` it runs the script's requests in simulated time instead, with no endpoint,
//! prints the replies and a summary (see [`hal_sim::script`]) and exits: 0 when the script ran,
//! 1 when a line does not parse (nothing runs then; stderr names the line) or the file cannot be
//! read.

use std::io::{self, BufWriter, ErrorKind, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::Parser;
use hal_sim::motor::MotorInputs;
use hal_sim::{Endpoint, MotorOptions, SimOptions, Simulator};

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
    /// Several drives on one simulated RS-485 bus: N drives at addresses 1..=N, or a list of
    /// addresses (`2,5,9`). Each has its own motor and its own trace (`FILE-axisA.csv`).
    #[arg(long, value_name = "N|A,B,..", value_parser = parse_axes, conflicts_with_all = ["address", "script"])]
    axes: Option<Axes>,
    /// Baud rate [default: the drive's, factory 9600]: the frame timing (t1.5, t3.5) follows it,
    /// and on the pseudo-terminal the drive hears only a master set to it.
    #[arg(long, value_name = "B")]
    baud: Option<u32>,
    /// Parity, `none`, `even` or `odd` [default: the drive's 0x2100, factory none]; 8 data bits,
    /// 1 stop bit. On the pseudo-terminal the drive hears only a master set to it.
    #[arg(long, value_name = "P", value_parser = parse_parity, conflicts_with = "script")]
    parity: Option<u8>,
    /// Keep the drive's parameter flash (16 KiB, as the STM32G474's parameter store) in FILE,
    /// created erased if missing: parameters saved with 0x200F = 2 are back after a restart.
    /// Without it the flash is in memory and saves last for the run.
    #[arg(long, value_name = "FILE", conflicts_with = "script")]
    flash: Option<PathBuf>,
    /// Start with FSET held low (as for 5 s or more at power-up): factory settings are restored
    /// and saved (0x2120 bit 2 shows it).
    #[arg(long, conflicts_with = "script")]
    fset_low: bool,
    /// The motor, by name in the catalogue (hal-sim/motors.toml).
    #[arg(long, value_name = "NAME", default_value = hal_sim::DEFAULT_MOTOR)]
    motor: String,
    /// Supply voltage, V.
    #[arg(long, value_name = "V", default_value_t = 24.0)]
    supply: f64,
    /// Load inertia at the shaft, kg·m².
    #[arg(long, value_name = "KGM2", default_value_t = 0.0)]
    load_inertia: f64,
    /// Constant load torque, N·m (positive opposes positive rotation).
    #[arg(long, value_name = "NM", default_value_t = 0.0)]
    load_torque: f64,
    /// Inject a fault or disturbance MS ms after power-up (repeatable): `supply=V` (a step),
    /// `supply=V/RAMP_MS` (a linear ramp from the present voltage), `load=NM` (a load-torque
    /// step), `blocked` / `free` (rotor held / released), `open-a`, `open-b` (coil open),
    /// `short-a`, `short-b` (bridge output shorted: over-current), `heal-a`, `heal-b` (repaired),
    /// `temp=C` (the driver temperature becomes C: the ambient steps by the difference),
    /// `encoder-noise=N` (±N counts of jitter), `encoder-lost` (line break), `encoder-frozen`
    /// (slipped coupling), `encoder-ok` (repaired), `input=PIN:high|low|free` (an input's wire
    /// driven by the machine's controller, or left to the switches; PIN ext1-ext3, gpio1-gpio8).
    #[arg(long = "fault", value_name = "MS:SPEC")]
    faults: Vec<hal_sim::inject::Scheduled>,
    /// The encoder on the motor shaft: `inc:CPR` (incremental, CPR 200, 400, 500, 600, 800,
    /// 1000, 1200 or 1600 lines, counted x4, 0 at power-up), `abs12` (absolute single-turn,
    /// 12 bits), `abs12mt` (multi-turn: turns x 4096 + angle) or `none`.
    #[arg(long, value_name = "KIND", default_value = "inc:1000")]
    encoder: hal_sim::encoder::EncoderKind,
    /// A switch on the machine (repeatable): `PIN:KIND:AT[:OPTION..]`. PIN `ext1`..`ext3` or
    /// `gpio1`..`gpio8`; KIND `npn`, `pnp` (open collector, pulls low / high when actuated) or
    /// `contact` (to ground); AT the rotor position in full steps from power-up where it is
    /// actuated, at and above it unless `below`; options `to=POS` (actuated only up to POS: a
    /// cam), `hyst=STEPS` (released that far back,
    /// default 0.5), `bounce=MS` (the contact chatters that long after a change), `nc` (normally
    /// closed). E.g. `--switch ext1:npn:-400:below:bounce=3` is a home switch 400 steps back.
    #[arg(long = "switch", value_name = "SPEC", value_parser = hal_sim::machine::Switch::parse)]
    switches: Vec<hal_sim::machine::Switch>,
    /// Hard stops that block the rotor: `LOW:HIGH` in full steps from power-up, either may be
    /// empty (`-2000:` is one stop 2000 steps back).
    #[arg(long, value_name = "LOW:HIGH", value_parser = parse_hard_stops)]
    hard_stop: Option<(Option<f64>, Option<f64>)>,
    /// A source on the analog input (0-3.3 V full scale): `V`, `V~NOISE` (uniform noise of
    /// ±NOISE V), `ramp=FROM/TO/S` or `sine=MID/AMP/PERIOD_S`.
    #[arg(long, value_name = "SPEC", value_parser = hal_sim::machine::Analog::parse)]
    analog: Option<hal_sim::machine::Analog>,
    /// A pulse source on the pulse input (work mode 3): `WIRING:RATE[:count=N][:accel=A][:at=MS]`,
    /// WIRING `step-dir`, `cw-ccw` or `quadrature`, RATE pulses a second (signed), `count` stops
    /// after N pulses, `accel` ramps at A pulses/s², `at` starts MS ms after power-up. E.g.
    /// `--pulses step-dir:20000:count=100000:accel=50000`.
    #[arg(long, value_name = "SPEC", value_parser = hal_sim::pulses::Train::parse)]
    pulses: Option<hal_sim::pulses::Train>,
    /// The register map to answer with for this run, instead of the saved 0x2190: `native`
    /// (seed 000), `jmc` (seed 001), `cls9` (seed 002), `ec57` (seed 003) or `servo` (seed 004).
    #[arg(long, value_name = "NAME", value_parser = parse_map)]
    map: Option<u8>,
    /// Simulated seconds a wall-clock second while masters talk (1: real time): long moves of
    /// a manual's routine in a test's time.
    #[arg(long, value_name = "N", default_value_t = 1)]
    time_scale: u32,
    /// The pseudo-terminal carries bytes at the line's speed (the baud rate and parity the
    /// master set), as an RS-485 line does: for timing a master's traffic. Off, bytes pass at
    /// once.
    #[arg(long)]
    wire: bool,
    /// How the motor's windings are driven: `bridges` (the G474's power stage, as the board:
    /// the current loop on the ADC's view, one period of PWM delay, dead time, the comparators'
    /// trip) or `chopper` (ideal: each current brought to its reference every period).
    #[arg(long, value_name = "KIND", default_value = "bridges")]
    power_stage: hal_sim::bridges::PowerStage,
    /// Record time, commanded and rotor position and velocity, and phase currents as CSV.
    #[arg(long, value_name = "FILE.csv")]
    trace: Option<PathBuf>,
    /// Run the requests of this script in simulated time, as fast as possible, without an
    /// endpoint; print the replies and a summary, then exit (one command a line: `at <ms> <hex>`
    /// delivers a request, its CRC appended; `until <ms>` runs to that time; `#` comments).
    #[arg(long, value_name = "FILE", conflicts_with_all = ["pty", "tcp"])]
    script: Option<PathBuf>,
    /// Keep one trace row per this many control ticks (20 kHz).
    #[arg(long, value_name = "N", default_value_t = 20)]
    trace_every: u32,
    /// Render a trace CSV to a PNG plot and exit.
    #[arg(long, num_args = 2, value_names = ["TRACE.csv", "PLOT.png"])]
    plot: Option<Vec<PathBuf>>,
}

/// `LOW:HIGH` of `--hard-stop`, either side empty for none.
fn parse_hard_stops(s: &str) -> Result<(Option<f64>, Option<f64>), String> {
    let (low, high) = s.split_once(':').ok_or("LOW:HIGH")?;
    let side = |t: &str| -> Result<Option<f64>, String> {
        if t.trim().is_empty() { Ok(None) } else { t.trim().parse().map(Some).map_err(|e| format!("{t:?}: {e}")) }
    };
    Ok((side(low)?, side(high)?))
}

/// A map's number (0x2190) from its name.
fn parse_map(name: &str) -> Result<u8, String> {
    let names = drive_core::maps::NAMES;
    names
        .iter()
        .position(|n| *n == name)
        .map(|i| i as u8)
        .ok_or_else(|| format!("{name:?}: one of {}", names.join(", ")))
}

/// The parity object's value (0x2100) from its name.
fn parse_parity(name: &str) -> Result<u8, String> {
    const NAMES: [&str; 3] = ["none", "even", "odd"];
    NAMES
        .iter()
        .position(|n| *n == name)
        .map(|i| i as u8)
        .ok_or_else(|| format!("{name:?}: one of {}", NAMES.join(", ")))
}

/// The addresses of `--axes`.
#[derive(Clone, Debug)]
struct Axes(Vec<u8>);

/// `N` (addresses 1..=N) or a comma-separated list of addresses.
fn parse_axes(s: &str) -> Result<Axes, String> {
    let number = |t: &str| t.trim().parse::<u8>().map_err(|e| format!("{t:?}: {e}"));
    let list = if s.contains(',') {
        s.split(',').map(number).collect::<Result<Vec<_>, _>>()?
    } else {
        (1..=number(s)?).collect()
    };
    if list.is_empty() { Err("no axis".into()) } else { Ok(Axes(list)) }
}

fn main() -> ExitCode {
    let args = Args::parse();
    if let Some([csv, png]) = args.plot.as_deref() {
        return match hal_sim::plot::plot_trace_csv(csv, png) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                eprintln!("hal-sim: {e}");
                ExitCode::FAILURE
            }
        };
    }
    let motor = MotorOptions {
        name: args.motor,
        inputs: MotorInputs {
            supply_v: args.supply,
            load_inertia_kgm2: args.load_inertia,
            load_torque_nm: args.load_torque,
            ..MotorInputs::default()
        },
        trace: args.trace.map(|path| (path, args.trace_every)),
    };
    let mut machine = hal_sim::machine::Machine::new(args.switches, args.analog);
    machine.pulses = args.pulses.map(hal_sim::pulses::PulseSource::new);
    let hard_stops = args.hard_stop.unwrap_or_default();
    if let Some(path) = &args.script {
        let opts = SimOptions {
            address: args.address,
            baud: args.baud,
            motor,
            faults: args.faults,
            encoder: args.encoder,
            machine,
            hard_stops,
            map: args.map,
            power_stage: args.power_stage,
            ..Default::default()
        };
        return run_script(path, &opts);
    }
    let endpoint = match args.tcp {
        Some(addr) => Endpoint::Tcp(addr),
        None => Endpoint::Pty { link: args.pty },
    };
    let opts = SimOptions {
        endpoint,
        address: args.address,
        baud: args.baud,
        parity: args.parity,
        motor,
        flash: args.flash,
        fset_low: args.fset_low,
        axes: args.axes.map(|a| a.0).unwrap_or_default(),
        faults: args.faults,
        encoder: args.encoder,
        machine,
        hard_stops,
        map: args.map,
        time_scale: args.time_scale,
        power_stage: args.power_stage,
        wire: args.wire,
    };
    let sim = match Simulator::bind(opts) {
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

/// `--script`: runs the script at `path` on the plant `opts` describe, replies to stdout.
fn run_script(path: &Path, opts: &SimOptions) -> ExitCode {
    let text = match std::fs::read_to_string(path) {
        Ok(text) => text,
        Err(e) => {
            eprintln!("hal-sim: {}: {e}", path.display());
            return ExitCode::FAILURE;
        }
    };
    let mut plant = match hal_sim::script::plant(opts) {
        Ok(plant) => plant,
        Err(e) => {
            eprintln!("hal-sim: {e}");
            return ExitCode::from(if e.kind() == ErrorKind::InvalidInput { 2 } else { 1 });
        }
    };
    let mut out = BufWriter::new(io::stdout().lock());
    match hal_sim::script::run_script(&text, &mut plant, &mut out) {
        Ok(_) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("hal-sim: {}: {e}", path.display());
            ExitCode::FAILURE
        }
    }
}
