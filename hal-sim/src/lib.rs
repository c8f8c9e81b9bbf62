//! Simulated drives ([`drive_core::Drive`]) on a pseudo-terminal or a TCP port, in real time,
//! where any Modbus-RTU master can reach them.
//!
//! With [`SimOptions::axes`] several drives, each with its own motor (and trace), share one
//! simulated RS-485 bus behind the one endpoint: every drive receives every byte at the same
//! instant, only the addressed drive answers, a broadcast reaches all. Replies are not echoed to
//! the other drives: a master on a pseudo-terminal or TCP does not keep the line's silence after a
//! reply, so the others would see reply and next request as one garbled frame.
//!
//! The loop stamps each chunk of bytes it reads with the monotonic time since [`Simulator::run`]
//! started and hands it to [`Drive::on_rx`]; between chunks it waits (`poll(2)`) until more bytes
//! come or [`Drive::deadline`] passes (rounded up to the next millisecond), then calls
//! [`Drive::on_timer`]. Every reply the drive makes is written out at once, in full. So frames end
//! by line silence (t3.5) exactly as on a serial line, and a master that leaves more than t1.5
//! between two bytes of a frame gets no answer.
//!
//! On a pseudo-terminal a drive hears a master only at its own baud rate and parity ([`LineFormat`]),
//! as a UART garbles characters sent at other settings: the loop reads the settings the master set
//! on the terminal (its termios) with each chunk, and a drive whose settings differ does not see the
//! chunk. The terminal starts at the (first) drive's settings, so that a master that sets none
//! talks at them. Over TCP every drive hears every byte (no baud rate travels there).
//!
//! Parameters are kept in a [`SimFlash`] (in memory, or in a file with [`SimOptions::flash`])
//! through drive-core's [`Store`]: loaded before the endpoint opens, saved on the I/O side of the
//! loop after the reply to 0x200F = 2 or 3 has gone out (see [`serve_request`]), never inside the
//! control tick.
//!
//! Over TCP, raw RTU frames travel (address, PDU, CRC: no MBAP header). One master connection is
//! served at a time, the next one when it closes; a frame left unfinished by a master that goes
//! away ends with it (its reply, if any, is dropped). The drive and its state outlive connections.
//!
//! ```
//! use std::io::{Read, Write};
//! use std::time::Duration;
//! use hal_sim::{Endpoint, SimOptions, Simulator};
//!
//! let sim = Simulator::bind(SimOptions { endpoint: Endpoint::Tcp("127.0.0.1:0".into()), ..Default::default() })?;
//! let at = sim.endpoint().to_owned(); // "127.0.0.1:PORT", the port the system picked
//! sim.spawn();
//! let mut master = std::net::TcpStream::connect(&at)?;
//! master.set_read_timeout(Some(Duration::from_secs(3)))?;
//! // Read 0x600C..0x600D (microstep resolution, phase current) from node 1.
//! master.write_all(&[0x01, 0x03, 0x60, 0x0C, 0x00, 0x02, 0x1A, 0x08])?;
//! let mut reply = [0; 9];
//! master.read_exact(&mut reply)?;
//! assert_eq!(reply, [0x01, 0x03, 0x04, 0x00, 0x00, 0x02, 0x92, 0x7A, 0xFE]);
//! # Ok::<(), std::io::Error>(())
//! ```

use std::cell::Cell;
use std::convert::Infallible;
use std::fs::{self, File};
use std::io::{self, ErrorKind, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::os::fd::{AsFd, BorrowedFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::thread::{self, JoinHandle};
use std::time::Duration;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};

use drive_core::maps::Maps;
use drive_core::od::{Obj, Range};
use drive_core::store::Store;
use drive_core::{Baud, DriveConfig, Instant, SlaveAddr, SystemRequest};

/// The simulator's drive: whichever register map 0x2190 (or `--map`) chose.
pub type Drive = drive_core::Drive<Maps>;
use nix::errno::Errno;
use nix::fcntl::{FcntlArg, OFlag, fcntl};
use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use nix::pty::openpty;
use nix::sys::termios::{FlushArg, tcflush};
use nix::unistd::ttyname;
use rustix::termios::{ControlModes, InputModes, OptionalActions};

use crate::flash::{PAGES, SimFlash, block_on};
use crate::motor::{Motor, MotorCatalog, MotorInputs};
use crate::plant::Plant;

pub mod bridges;
pub mod encoder;
pub mod flash;
pub mod inject;
pub mod machine;
pub mod motor;
pub mod plant;
pub mod plot;
pub mod pulses;
pub mod script;
pub mod slots;
pub mod soak;
pub mod thermal;
pub mod torque_speed;
pub mod trace;
pub mod tracking;
pub mod updates;

/// Where masters reach the simulated drive.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Endpoint {
    /// A new pseudo-terminal, raw (8N1, no echo); the endpoint is the path of its slave end
    /// (`/dev/pts/N`), which masters open and close as they like.
    Pty {
        /// Also put a symlink here pointing to the pseudo-terminal, replacing a symlink already
        /// there (never another kind of file).
        link: Option<PathBuf>,
    },
    /// A TCP listener at `HOST:PORT` (port 0: one the system picks); each connection carries raw
    /// RTU frames with their CRC and no MBAP header.
    Tcp(String),
}

impl Default for Endpoint {
    fn default() -> Self {
        Self::Pty { link: None }
    }
}

/// How to start a [`Simulator`]. The default: a pseudo-terminal, the drive's factory settings,
/// the NEMA 17 motor at 24 V without load.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SimOptions {
    /// Where masters reach the drive.
    pub endpoint: Endpoint,
    /// The slave address, instead of the drive's node id (factory 1). The drive takes 1-127.
    pub address: Option<u8>,
    /// The baud rate the frame timing (t1.5, t3.5) follows and a master on the pseudo-terminal
    /// must set, instead of the drive's (factory 9600): one of [`Baud::SUPPORTED`].
    pub baud: Option<u32>,
    /// The parity (0x2100: 0 none, 1 even, 2 odd), instead of the drive's (factory none).
    pub parity: Option<u8>,
    /// The motor and its surroundings.
    pub motor: MotorOptions,
    /// Keep the parameter store's flash in this file (created erased if missing), so that saved
    /// parameters survive a restart. Without it the flash is in memory: saves work for the run.
    pub flash: Option<PathBuf>,
    /// FSET held low at power-up (as for 5 s or more): factory settings are restored and saved.
    pub fset_low: bool,
    /// Several drives on one bus, at these addresses, each with its own motor (the same model)
    /// and its own trace ([`axis_trace_path`]). Empty: one drive, at `address`.
    pub axes: Vec<u8>,
    /// Faults and disturbances at set times after power-up (`--fault`), on every axis.
    pub faults: Vec<inject::Scheduled>,
    /// The encoder on each motor's shaft (`--encoder`).
    pub encoder: encoder::EncoderKind,
    /// Switches and the analog source around each motor (`--switch`, `--analog`).
    pub machine: machine::Machine,
    /// Hard stops at these rotor positions, full steps from the power-up position (`--hard-stop`).
    pub hard_stops: (Option<f64>, Option<f64>),
    /// The register map's number (0x2190) for this run, instead of the saved one (`--map`).
    pub map: Option<u8>,
    /// Simulated seconds a wall-clock second (`--time-scale`; 0 or 1: real time).
    pub time_scale: u32,
    /// The ideal chopper or the board's bridges (`--power-stage`).
    pub power_stage: bridges::PowerStage,
    /// The pseudo-terminal carries bytes at the line's speed (`--wire`): a request is heard
    /// once its bytes would have arrived, a reply's last byte leaves as long after its start as
    /// the line takes. Off, bytes pass at once.
    pub wire: bool,
}

/// The trace or flash file of the drive at `address` when several share the bus: `-axisN`
/// before the extension (`run.csv` → `run-axis2.csv`).
pub fn axis_trace_path(path: &Path, address: u8) -> PathBuf {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let name = match path.extension() {
        Some(ext) => format!("{stem}-axis{address}.{}", ext.to_string_lossy()),
        None => format!("{stem}-axis{address}"),
    };
    path.with_file_name(name)
}

/// Which motor the drive turns, and what it turns.
#[derive(Clone, Debug, PartialEq)]
pub struct MotorOptions {
    /// A motor of the catalogue (`motors.toml`).
    pub name: String,
    /// Supply voltage, load inertia and load torque.
    pub inputs: MotorInputs,
    /// Record a trace (CSV) here, one row per this many ticks.
    pub trace: Option<(PathBuf, u32)>,
}

impl Default for MotorOptions {
    fn default() -> Self {
        Self { name: DEFAULT_MOTOR.into(), inputs: MotorInputs::default(), trace: None }
    }
}

/// The motor of the simulator unless told otherwise: a NEMA 17.
pub const DEFAULT_MOTOR: &str = "17HS19-2004S1";

/// What a test can watch of a running simulator, updated at every wake-up of its loop.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Snapshot {
    /// Simulated time, µs.
    pub time_us: u64,
    /// Rotor position in the drive's microsteps.
    pub rotor_microsteps: f64,
    /// The drive's position setpoint, whole microsteps.
    pub setpoint: i64,
    /// The setpoint's velocity, microsteps per second.
    pub velocity: f64,
    /// Whether the drive's power stage is on.
    pub enabled: bool,
    /// The coil output's PWM duty the drive outputs, % (a brake: 0 applied).
    pub coil_duty: u8,
    /// The drive's output pins' levels (1 high, bits as 0x6031).
    pub gpio_out: u16,
    /// The larger of the two phase currents' magnitudes in the motor, A.
    pub current_a: f64,
}

/// Simulated drives (one, or several on one bus) with their endpoint open, ready to run.
#[derive(Debug)]
pub struct Simulator {
    plants: Vec<Plant>,
    /// Each drive's parameter store and power-up, in the order of the plants.
    stores: Vec<Powered>,
    port: Port,
    endpoint: String,
    snapshots: Vec<Arc<Mutex<Snapshot>>>,
    /// Simulated seconds a wall second.
    time_scale: u32,
    /// The pseudo-terminal at the line's speed ([`SimOptions::wire`]).
    wire: bool,
}

/// The open endpoint.
#[derive(Debug)]
enum Port {
    /// The master end of the pseudo-terminal (non-blocking), and a slave fd kept open so that
    /// masters can come and go (with no slave open, reads on the master end fail with EIO).
    Pty {
        master: File,
        slave: OwnedFd,
    },
    Tcp(TcpListener),
}

impl Simulator {
    /// Builds the drive and opens the endpoint: a new pseudo-terminal set raw (and the symlink),
    /// or a bound TCP listener. An address or baud rate the drive does not take is an
    /// [`ErrorKind::InvalidInput`] error.
    pub fn bind(opts: SimOptions) -> io::Result<Simulator> {
        let (plants, stores): (Vec<_>, Vec<_>) = powered(&opts)?.into_iter().unzip();
        let (port, endpoint) = match opts.endpoint {
            Endpoint::Pty { link } => {
                let format = stores.first().map_or(LineFormat::FACTORY, |p| p.format);
                open_pty(link.as_deref(), format)?
            }
            Endpoint::Tcp(addr) => {
                let listener = TcpListener::bind(&addr).map_err(|e| annotate(e, &addr))?;
                let at = listener.local_addr()?.to_string();
                (Port::Tcp(listener), at)
            }
        };
        let snapshots = plants.iter().map(|_| Arc::default()).collect();
        Ok(Simulator { plants, stores, port, endpoint, snapshots, time_scale: opts.time_scale, wire: opts.wire })
    }

    /// Where masters reach the drive: `/dev/pts/N`, or the bound `HOST:PORT`.
    pub fn endpoint(&self) -> &str {
        &self.endpoint
    }

    /// The (first) drive, as it will start.
    pub fn drive(&self) -> &Drive {
        self.plants.first().map(Plant::drive).unwrap_or_else(|| unreachable!("a simulator has a drive"))
    }

    /// The (first) drive, to set up before it runs (its state, its status); the loop owns it then.
    pub fn drive_mut(&mut self) -> &mut Drive {
        self.plants.first_mut().map(Plant::drive_mut).unwrap_or_else(|| unreachable!("a simulator has a drive"))
    }

    /// Every drive and its motor, in the order of [`SimOptions::axes`], to set up before it runs.
    pub fn plants_mut(&mut self) -> &mut [Plant] {
        &mut self.plants
    }

    /// A handle to inject faults into the (first) plant while the simulator runs.
    pub fn injector(&self) -> inject::Injector {
        self.plants.first().map(Plant::injector).unwrap_or_default()
    }

    /// What the running loop publishes of the (first) motor and drive.
    pub fn snapshot(&self) -> Arc<Mutex<Snapshot>> {
        self.snapshots.first().map(Arc::clone).unwrap_or_default()
    }

    /// What the running loop publishes of each motor and drive, in the order of the axes.
    pub fn snapshots(&self) -> Vec<Arc<Mutex<Snapshot>>> {
        self.snapshots.clone()
    }

    /// Runs the drive on a new thread, forever (see [`Simulator::run`]).
    pub fn spawn(self) -> JoinHandle<io::Result<Infallible>> {
        thread::spawn(move || self.run())
    }

    /// Runs the drive on this thread, serving one master after another. Bad frames, masters that
    /// go away and failed reads or writes do not end it: it returns only if `poll(2)` fails.
    pub fn run(self) -> io::Result<Infallible> {
        self.run_until(&AtomicBool::new(false))?;
        Err(io::Error::other("the simulator loop ended without being switched off"))
    }

    /// Runs the drive on a new thread until [`PowerSwitch::off`]: a power cycle for tests, with
    /// the same flash file given to the next [`Simulator::bind`].
    pub fn power_on(self) -> PowerSwitch {
        let off = Arc::new(AtomicBool::new(false));
        let endpoint = self.endpoint.clone();
        let flag = Arc::clone(&off);
        let thread = thread::spawn(move || self.run_until(&flag));
        PowerSwitch { off, endpoint, thread }
    }

    /// [`Simulator::run`] until `off` is set (seen within a millisecond while a master is
    /// connected, at the next connection attempt while none is over TCP).
    fn run_until(self, off: &AtomicBool) -> io::Result<()> {
        let Simulator { mut plants, mut stores, port, snapshots, time_scale, wire, .. } = self;
        let clock = Clock::start(time_scale);
        let mut sim = Sim { plants: &mut plants, stores: &mut stores, snapshots: &snapshots, off };
        match port {
            Port::Pty { master, slave } => {
                let mut line = PtyLine { master, slave, wire };
                while !off.load(Ordering::Relaxed) {
                    serve(&mut sim, &clock, &mut line)?;
                }
            }
            Port::Tcp(listener) => {
                while !off.load(Ordering::Relaxed) {
                    match listener.accept() {
                        Ok(_) if off.load(Ordering::Relaxed) => {}
                        Ok((stream, _)) => {
                            serve(&mut sim, &clock, &mut TcpLine::new(stream))?;
                            settle(&mut sim, &clock);
                        }
                        Err(e) if e.kind() == ErrorKind::Interrupted => {}
                        Err(e) => {
                            // Out of fds, a connection aborted before accept: wait and try again.
                            eprintln!("hal-sim: accept: {e}");
                            thread::sleep(Duration::from_millis(100));
                        }
                    }
                }
            }
        }
        Ok(())
    }
}

/// A simulator running on its own thread, which a test can switch off ([`Simulator::power_on`]).
#[derive(Debug)]
pub struct PowerSwitch {
    off: Arc<AtomicBool>,
    endpoint: String,
    thread: JoinHandle<io::Result<()>>,
}

impl PowerSwitch {
    /// Where masters reach the drive.
    pub fn endpoint(&self) -> &str {
        &self.endpoint
    }

    /// Switches the drive off and waits until it is: its endpoint and flash file are closed, and
    /// whatever it saved is in the file. Masters still connected are cut off.
    pub fn off(self) -> io::Result<()> {
        self.off.store(true, Ordering::Relaxed);
        // Wakes a TCP loop waiting in accept(2); a pseudo-terminal loop wakes by itself.
        let _ = TcpStream::connect(&self.endpoint);
        self.thread.join().map_err(|_| io::Error::other("simulator thread panicked"))?
    }
}

/// The parameter store on the whole of `flash`.
pub fn store(flash: SimFlash) -> io::Result<Store<SimFlash>> {
    let end = u32::try_from(flash.bytes().len()).map_err(|_| invalid("flash too large".into()))?;
    Store::new(flash, 0..end).map_err(|e| invalid(format!("flash of {end} bytes: {e:?}")))
}

/// Powers the drive up on `store` ([`Store::power_up`]): the saved parameters, or with
/// `fset_low` the factory values, saved.
pub fn boot(store: &mut Store<SimFlash>, config: DriveConfig, fset_low: bool, map: Option<u8>) -> Drive {
    boot_with_parity(store, config, fset_low, map, None)
}

/// [`boot`], the parity object (0x2100) `parity` for this run if given, as
/// [`DriveConfig::baud`] does the baud rate's.
fn boot_with_parity(
    store: &mut Store<SimFlash>,
    config: DriveConfig,
    fset_low: bool,
    map: Option<u8>,
    parity: Option<u8>,
) -> Drive {
    let mut loaded = block_on(store.power_up(fset_low));
    if let Some(p) = parity {
        loaded.params.set(Obj::Parity, u32::from(p));
    }
    let map = Maps::by_id(map.map_or(loaded.params.get(Obj::RegisterMap), u32::from));
    let drive = Drive::boot_with_map(config, map, &loaded.params, loaded.status);
    if let Some(table) = drive.state().program_memory() {
        block_on(store.load_program(table));
    }
    drive
}

/// Does what the drive asks of its platform ([`Store::serve`]); failures are logged (the drive
/// shows a failed save in 0x2120). The boot loader is never asked for: the simulator's drive
/// refuses 0x200F = 1. True if the drive asked to be restarted (0x219F), which the caller does.
pub fn serve_request(drive: &mut Drive, store: &mut Store<SimFlash>) -> bool {
    let mut restart = false;
    while let Some((request, done)) = block_on(store.serve(drive)) {
        restart |= request == SystemRequest::Restart;
        if let Err(e) = done {
            eprintln!("hal-sim: {request:?} failed: {e:?}");
        }
    }
    restart
}

/// A drive's parameter store, its image slots, and how it powers up again after a restart.
#[derive(Debug)]
struct Powered {
    store: Store<SimFlash>,
    firmware: updates::Firmware,
    config: DriveConfig,
    map: Option<u8>,
    parity: Option<u8>,
    /// The line settings the drive powered up with, in force until it restarts.
    format: LineFormat,
}

impl Powered {
    /// Powers the drive up (again): the boot loader on its slots, then the image from its store.
    fn boot(&mut self, fset_low: bool) -> Drive {
        if let Err(e) = self.firmware.boot() {
            eprintln!("hal-sim: {e}");
        }
        let config = DriveConfig { identity: self.firmware.identity(self.config.identity), ..self.config };
        let mut drive = boot_with_parity(&mut self.store, config, fset_low, self.map, self.parity);
        self.firmware.configure(&mut drive);
        self.format = LineFormat::of(&drive);
        drive
    }
}

/// A serial line's settings as a UART has them: baud rate and parity, 8 data bits and 1 stop bit
/// (the drive's 8N1, 8E1 or 8O1; a second stop bit from a master is idle line to the receiver).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LineFormat {
    /// Bits a second.
    pub baud: u32,
    /// 0 none, 1 even, 2 odd (0x2100's values).
    pub parity: u8,
}

impl LineFormat {
    /// The drive's factory settings: 9600 baud, no parity.
    pub const FACTORY: LineFormat = LineFormat { baud: 9600, parity: 0 };

    /// The settings `drive` powered up with: its baud rate and its parity (0x2100), which a write
    /// changes only from the next power-up, as on the board.
    pub fn of(drive: &Drive) -> LineFormat {
        LineFormat { baud: drive.baud().get(), parity: drive.state().read(Obj::Parity).min(2) as u8 }
    }
}

/// The drives and motors `opts` ask for, traces open, without parameter stores (a save is
/// refused with 04): for batch runs.
pub fn plants(opts: &SimOptions) -> io::Result<Vec<Plant>> {
    let map = Maps::by_id(opts.map.map_or(0, u32::from));
    Ok(build(opts, |_, config| Ok((Drive::with_map(config, map.clone()), ())))?
        .into_iter()
        .map(|(plant, ())| plant)
        .collect())
}

/// The drives and motors `opts` ask for, traces open, each powered up from its own store: the
/// `--flash` file (`-axisN` added with several axes), or erased flash in memory.
fn powered(opts: &SimOptions) -> io::Result<Vec<(Plant, Powered)>> {
    build(opts, |address, config| {
        let flash = match &opts.flash {
            Some(path) => {
                let path = match address {
                    Some(a) if !opts.axes.is_empty() => axis_trace_path(path, a),
                    _ => path.clone(),
                };
                SimFlash::open(&path).map_err(|e| annotate(e, path.display()))?
            }
            None => SimFlash::erased(PAGES),
        };
        let config = DriveConfig { can_save: true, ..config };
        let mut powered = Powered {
            store: store(flash)?,
            firmware: updates::Firmware::new(),
            config,
            map: opts.map,
            parity: opts.parity,
            format: LineFormat::FACTORY,
        };
        let drive = powered.boot(opts.fset_low);
        Ok((drive, powered))
    })
}

/// One plant per address of `opts`, its drive from `power_up(address, config)`.
fn build<T>(
    opts: &SimOptions,
    mut power_up: impl FnMut(Option<u8>, DriveConfig) -> io::Result<(Drive, T)>,
) -> io::Result<Vec<(Plant, T)>> {
    let params = MotorCatalog::builtin()
        .get(&opts.motor.name)
        .cloned()
        .ok_or_else(|| invalid(format!("no motor {:?} in the catalogue", opts.motor.name)))?;
    let addresses =
        if opts.axes.is_empty() { vec![opts.address] } else { opts.axes.iter().map(|&a| Some(a)).collect() };
    let mut plants = Vec::new();
    for (i, &address) in addresses.iter().enumerate() {
        if addresses.get(..i).is_some_and(|before| before.contains(&address)) {
            return Err(invalid(format!("address {} twice on the bus", address.unwrap_or(0))));
        }
        let (drive, extra) = power_up(address, drive_config(&SimOptions { address, ..opts.clone() })?)?;
        let mut plant = Plant::new(drive, Motor::new(params.clone(), opts.motor.inputs));
        plant.set_power_stage(opts.power_stage, bridges::SensingOptions::default());
        plant.schedule(opts.faults.clone());
        plant.set_encoder(opts.encoder);
        *plant.machine_mut() = opts.machine.clone();
        plant.motor_mut().set_hard_stops(opts.hard_stops.0, opts.hard_stops.1);
        if let Some((path, every)) = &opts.motor.trace {
            let path = match address {
                Some(a) if !opts.axes.is_empty() => axis_trace_path(path, a),
                _ => path.clone(),
            };
            plant.trace_to(&path, *every).map_err(|e| annotate(e, path.display()))?;
        }
        plants.push((plant, extra));
    }
    Ok(plants)
}

/// The drive configuration `opts` ask for, if the drive takes it.
fn drive_config(opts: &SimOptions) -> io::Result<DriveConfig> {
    let address = match opts.address {
        None => None,
        Some(a) => {
            let node_id = Obj::NodeId.def();
            let takes = node_id.range.accepts(node_id.ty(), u32::from(a));
            let range = match *node_id.range {
                Range::Span(lo, hi) => format!(" (the drive takes {lo}-{hi})"),
                _ => String::new(),
            };
            let addr = SlaveAddr::new(a).filter(|_| takes);
            Some(addr.ok_or_else(|| invalid(format!("invalid slave address {a}{range}")))?)
        }
    };
    let baud = match opts.baud {
        None => None,
        Some(b) => {
            let rates = Baud::SUPPORTED.map(|r| r.to_string()).join(", ");
            Some(Baud::new(b).ok_or_else(|| invalid(format!("unsupported baud rate {b} (the drive takes {rates})")))?)
        }
    };
    if let Some(p) = opts.parity.filter(|p| *p > 2) {
        return Err(invalid(format!("invalid parity {p} (0 none, 1 even, 2 odd)")));
    }
    Ok(DriveConfig { address, baud, ..Default::default() })
}

fn invalid(msg: String) -> io::Error {
    io::Error::new(ErrorKind::InvalidInput, msg)
}

/// `e`, with what it was about in front of its message.
fn annotate(e: io::Error, what: impl std::fmt::Display) -> io::Error {
    io::Error::new(e.kind(), format!("{what}: {e}"))
}

/// Opens a raw pseudo-terminal at the drive's settings `format` and, with `link`, the symlink to it.
fn open_pty(link: Option<&Path>, format: LineFormat) -> io::Result<(Port, String)> {
    let pty = openpty(None, None)?;
    let mut termios = rustix::termios::tcgetattr(&pty.slave)?;
    termios.make_raw();
    termios.set_speed(format.baud)?;
    // As a serial library sets a parity (see `PtyLine::format`).
    termios.control_modes.set(ControlModes::PARENB, format.parity != 0);
    termios.control_modes.set(ControlModes::PARODD, format.parity == 2);
    termios.input_modes.set(InputModes::INPCK, format.parity != 0);
    rustix::termios::tcsetattr(&pty.slave, OptionalActions::Now, &termios)?;
    let flags = OFlag::from_bits_retain(fcntl(&pty.master, FcntlArg::F_GETFL)?);
    fcntl(&pty.master, FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK))?;
    let path = ttyname(&pty.slave)?;
    if let Some(link) = link {
        make_link(&path, link).map_err(|e| annotate(e, link.display()))?;
    }
    let endpoint = path.to_string_lossy().into_owned();
    Ok((Port::Pty { master: File::from(pty.master), slave: pty.slave }, endpoint))
}

/// Puts a symlink at `link` to `target`, replacing a symlink (but nothing else) already there.
fn make_link(target: &Path, link: &Path) -> io::Result<()> {
    match fs::symlink_metadata(link) {
        Ok(meta) if meta.file_type().is_symlink() => fs::remove_file(link)?,
        Ok(_) => return Err(io::Error::new(ErrorKind::AlreadyExists, "exists and is not a symlink")),
        Err(e) if e.kind() == ErrorKind::NotFound => {}
        Err(e) => return Err(e),
    }
    std::os::unix::fs::symlink(target, link)
}

/// Simulated time: wall time since the loop started, less what the host did not let the
/// serving loop simulate.
///
/// A small shared machine may not run a thread for hundreds of milliseconds, and eight traced
/// axes may take longer to simulate than the time they cover. Caught up in one go, such a gap
/// would run the drives for that long with their bus deaf, which no real drive does (a PVT FIFO
/// would run dry with the master's points waiting in the socket). So one step of the serving
/// loop simulates at most [`MAX_STEP`]: beyond it the simulated world pauses, as a chip halted by
/// a debugger does, and runs slower than wall time while the host cannot keep pace. Time with no
/// master connected passes in full.
struct Clock {
    origin: std::time::Instant,
    /// Simulated seconds a wall second.
    scale: u64,
    /// Wall time not simulated.
    lost: Cell<Duration>,
    /// The simulated time of the serving loop's last step; `None` after it stopped serving.
    last: Cell<Option<Instant>>,
}

/// The most simulated time one step of the serving loop covers (it wakes every [`PACE`]).
const MAX_STEP: u64 = 100_000;

impl Clock {
    fn start(scale: u32) -> Self {
        let scale = u64::from(scale.max(1));
        Self { origin: std::time::Instant::now(), scale, lost: Cell::new(Duration::ZERO), last: Cell::new(None) }
    }

    /// Wall time since the start, less the time lost, times the scale.
    fn now(&self) -> Instant {
        let t = self.origin.elapsed().saturating_sub(self.lost.get());
        Instant::from_micros(u64::try_from(t.as_micros()).unwrap_or(u64::MAX).saturating_mul(self.scale))
    }

    /// The wall time `sim_us` of simulated time takes.
    fn wall(&self, sim_us: u64) -> Duration {
        Duration::from_micros(sim_us.div_ceil(self.scale))
    }

    /// The time of the serving loop's next step: [`Clock::now`], or [`MAX_STEP`] after the last
    /// step when the host fell further behind (the rest is lost).
    fn step(&self) -> Instant {
        let mut now = self.now();
        if let Some(last) = self.last.get() {
            let late = now.since(last).saturating_sub(MAX_STEP * self.scale);
            self.lost.set(self.lost.get() + self.wall(late));
            now = Instant::from_micros(now.as_micros() - late);
        }
        self.last.set(Some(now));
        now
    }

    /// The loop stops serving (waits for a master): that time passes in full.
    fn idle(&self) {
        self.last.set(None);
    }
}

/// How long `poll(2)` waits at `now` for `wake`: rounded up to the next millisecond, so that
/// `wake` has passed when it returns.
fn poll_wait(wake: Instant, now: Instant) -> Duration {
    Duration::from_millis(wake.since(now).div_ceil(1000))
}

/// What a read from a line found.
enum Recv {
    /// This many bytes.
    Data(usize),
    /// Nothing for now.
    Nothing,
    /// The master went away for good.
    Closed,
}

/// A byte stream to one master (or to whoever opens the pseudo-terminal).
trait Line: AsFd {
    /// Reads what has arrived.
    fn recv(&mut self, buf: &mut [u8]) -> Recv;
    /// Writes a reply in full; an error means the master went away.
    fn send(&mut self, frame: &[u8]) -> io::Result<()>;
    /// The settings the master sends at, where the line has any (TCP carries none).
    fn format(&self) -> Option<LineFormat> {
        None
    }
}

/// The plants on the bus, their stores and what they publish, as the loop sees them.
struct Sim<'a> {
    plants: &'a mut [Plant],
    stores: &'a mut [Powered],
    snapshots: &'a [Arc<Mutex<Snapshot>>],
    /// The power switch: set, the loop ends.
    off: &'a AtomicBool,
}

impl Sim<'_> {
    /// Brings every simulated motor and drive up to `now`, and publishes the result.
    fn catch_up(&mut self, now: Instant) {
        for (plant, snapshot) in self.plants.iter_mut().zip(self.snapshots) {
            plant.advance_to(now);
            // A trace is read while the simulator runs (and after it is killed): keep it current.
            let _ = plant.flush_trace();
            if let Ok(mut s) = snapshot.lock() {
                let out = plant.outputs();
                let (a, b) = plant.motor().phase_currents();
                *s = Snapshot {
                    time_us: now.as_micros(),
                    rotor_microsteps: plant.rotor_microsteps(),
                    setpoint: out.map_or(0, |o| o.setpoint.whole),
                    velocity: out.map_or(0.0, |o| f64::from(o.setpoint.velocity)),
                    enabled: out.is_some_and(|o| o.enabled),
                    coil_duty: out.map_or(0, |o| o.coil_duty),
                    gpio_out: out.map_or(0, |o| o.gpio),
                    current_a: a.abs().max(b.abs()),
                };
            }
        }
    }

    /// The earliest time a drive's framer has something to do.
    fn deadline(&self) -> Option<Instant> {
        self.plants.iter().filter_map(|p| p.drive().deadline()).min()
    }

    /// Bytes on the bus at `now`, after the motors have caught up: every drive at the master's
    /// settings receives them (at others a UART would make other characters of them, with framing
    /// and parity errors, where no frame of the master's survives). Sends what the drives answer;
    /// `Err` when the master has gone.
    fn receive(&mut self, now: Instant, bytes: &[u8], line: &mut impl Line) -> io::Result<()> {
        self.catch_up(now);
        let heard = line.format();
        for (plant, powered) in self.plants.iter_mut().zip(self.stores.iter()) {
            if heard.is_some_and(|f| f != powered.format) {
                continue;
            }
            let drive = plant.drive_mut();
            drive.on_rx(now, bytes);
            // A frame that had ended before these bytes came was answered first.
            if let Some(reply) = drive.take_reply() {
                line.send(reply)?;
            }
        }
        Ok(())
    }

    /// Does what the drives ask of their platform (saves, a restart), each with its own store.
    fn serve_requests(&mut self) {
        for (plant, p) in self.plants.iter_mut().zip(self.stores.iter_mut()) {
            let restart = serve_request(plant.drive_mut(), &mut p.store);
            if p.firmware.serve(plant.drive_mut()) || restart {
                // Seed 004's 0541h, or an image installed: powered up again, as after a power cycle.
                *plant.drive_mut() = p.boot(false);
                plant.restarted();
            }
        }
    }

    /// Time passes: frames that have ended are served, replies sent (or dropped without `line`).
    fn timer<L: Line>(&mut self, now: Instant, mut line: Option<&mut L>) -> io::Result<()> {
        self.catch_up(now);
        for plant in self.plants.iter_mut() {
            let drive = plant.drive_mut();
            drive.on_timer(now);
            if let (Some(reply), Some(line)) = (drive.take_reply(), line.as_mut()) {
                line.send(reply)?;
            }
        }
        Ok(())
    }
}

/// How often the loop wakes up to keep the motor in pace with wall time, at the least.
const PACE: Duration = Duration::from_millis(1);

/// Runs the drive on `line` until the master goes away or the power is switched off (`Ok`), or
/// `poll(2)` fails.
fn serve(sim: &mut Sim<'_>, clock: &Clock, line: &mut impl Line) -> io::Result<()> {
    let served = serve_steps(sim, clock, line);
    clock.idle();
    served
}

/// The loop of [`serve`].
fn serve_steps(sim: &mut Sim<'_>, clock: &Clock, line: &mut impl Line) -> io::Result<()> {
    let mut buf = [0u8; 512];
    while !sim.off.load(Ordering::Relaxed) {
        let ready = {
            let mut fds = [PollFd::new(line.as_fd(), PollFlags::POLLIN)];
            let deadline = sim.deadline();
            let pace = clock.now().plus_micros(PACE.as_micros() as u64);
            let wake = deadline.map_or(pace, |d| d.min(pace));
            match poll(
                &mut fds,
                PollTimeout::try_from(poll_wait(wake, clock.now()).as_millis().div_ceil(u128::from(clock.scale)))
                    .unwrap_or(PollTimeout::MAX),
            ) {
                Ok(0) | Err(Errno::EINTR) => false,
                Ok(_) => true,
                Err(e) => return Err(e.into()),
            }
        };
        let now = clock.step();
        if ready {
            match line.recv(&mut buf) {
                Recv::Data(n) => {
                    if sim.receive(now, buf.get(..n).unwrap_or_default(), line).is_err() {
                        return Ok(());
                    }
                }
                Recv::Nothing => {}
                Recv::Closed => return Ok(()),
            }
        }
        if sim.timer(now, Some(&mut *line)).is_err() {
            return Ok(());
        }
        // After the reply: the save runs here, on the I/O side; the motor catches up after it.
        sim.serve_requests();
    }
    Ok(())
}

/// Ends the frame a master left unfinished when it went away; its reply has nowhere to go.
fn settle(sim: &mut Sim<'_>, clock: &Clock) {
    while let Some(deadline) = sim.deadline() {
        let now = clock.now();
        match deadline.since(now) {
            0 => {
                let _ = sim.timer::<TcpLine>(now, None);
                sim.serve_requests();
            }
            wait => thread::sleep(clock.wall(wait)),
        }
    }
}

/// The master end of the pseudo-terminal.
struct PtyLine {
    master: File,
    slave: OwnedFd,
    /// Bytes take the line's time ([`SimOptions::wire`]).
    wire: bool,
}

impl PtyLine {
    /// With [`SimOptions::wire`], waits as long as `bytes` take on the line at the master's
    /// settings.
    fn on_the_wire(&self, bytes: usize) {
        if let Some(f) = self.format().filter(|f| self.wire && f.baud > 0) {
            let bits = if f.parity == 0 { 10 } else { 11 };
            thread::sleep(Duration::from_secs_f64(bytes as f64 * f64::from(bits) / f64::from(f.baud)));
        }
    }
}

impl AsFd for PtyLine {
    fn as_fd(&self) -> BorrowedFd<'_> {
        self.master.as_fd()
    }
}

impl Line for PtyLine {
    fn recv(&mut self, buf: &mut [u8]) -> Recv {
        match self.master.read(buf) {
            Ok(n) if n > 0 => {
                self.on_the_wire(n);
                Recv::Data(n)
            }
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::Interrupted) => Recv::Nothing,
            other => {
                // EIO (no slave open: cannot happen while we hold one) or end of file: poll(2)
                // may report this at once again, so do not spin.
                if let Err(e) = other
                    && e.raw_os_error() != Some(Errno::EIO as i32)
                {
                    eprintln!("hal-sim: pty read: {e}");
                }
                thread::sleep(Duration::from_millis(1));
                Recv::Nothing
            }
        }
    }

    fn send(&mut self, frame: &[u8]) -> io::Result<()> {
        // Replies that no master read are stale, as bytes sent on a line nobody listens to: drop
        // them, so that they neither reach the next master nor fill the buffer and block us.
        let _ = tcflush(&self.slave, FlushArg::TCIFLUSH);
        self.on_the_wire(frame.len());
        let mut rest = frame;
        let mut waits = 0;
        while !rest.is_empty() {
            match self.master.write(rest) {
                Ok(0) => break,
                Ok(n) => rest = rest.get(n..).unwrap_or_default(),
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) if e.kind() == ErrorKind::WouldBlock && waits < 100 => {
                    waits += 1;
                    thread::sleep(Duration::from_micros(100));
                }
                Err(e) => {
                    eprintln!("hal-sim: reply dropped: {e}");
                    break;
                }
            }
        }
        // Whoever has the terminal open may read or not; the line itself never goes away.
        Ok(())
    }

    /// The baud rate and parity the master set on the terminal. A Linux pseudo-terminal keeps the
    /// speed and PARODD but clears PARENB on every change, so parity shows as input parity checking
    /// (INPCK), which serial libraries (serialport, tokio-serial, libmodbus) set with a parity.
    fn format(&self) -> Option<LineFormat> {
        let t = rustix::termios::tcgetattr(&self.slave).ok()?;
        let parity = if t.control_modes.contains(ControlModes::PARODD) {
            2
        } else if t.control_modes.contains(ControlModes::PARENB) || t.input_modes.contains(InputModes::INPCK) {
            1
        } else {
            0
        };
        Some(LineFormat { baud: t.output_speed(), parity })
    }
}

/// One TCP connection.
struct TcpLine {
    stream: TcpStream,
}

impl TcpLine {
    fn new(stream: TcpStream) -> Self {
        // A reply is one small write; a master that stops reading is dropped after a while.
        let _ = stream.set_nodelay(true);
        let _ = stream.set_write_timeout(Some(Duration::from_secs(1)));
        Self { stream }
    }
}

impl AsFd for TcpLine {
    fn as_fd(&self) -> BorrowedFd<'_> {
        self.stream.as_fd()
    }
}

impl Line for TcpLine {
    fn recv(&mut self, buf: &mut [u8]) -> Recv {
        match self.stream.read(buf) {
            Ok(0) => Recv::Closed,
            Ok(n) => Recv::Data(n),
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::Interrupted) => Recv::Nothing,
            Err(_) => Recv::Closed,
        }
    }

    fn send(&mut self, frame: &[u8]) -> io::Result<()> {
        self.stream.write_all(frame)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(us: u64) -> Instant {
        Instant::from_micros(us)
    }

    #[test]
    fn poll_waits_until_the_deadline_has_passed() {
        let ms = Duration::from_millis;
        assert_eq!(poll_wait(at(4010), at(0)), ms(5));
        assert_eq!(poll_wait(at(4010), at(3010)), ms(1));
        assert_eq!(poll_wait(at(4010), at(4010)), ms(0));
        assert_eq!(poll_wait(at(4010), at(9000)), ms(0));
    }

    #[test]
    fn a_stall_beyond_one_step_is_not_simulated_and_idle_time_passes() {
        let clock = Clock::start(1);
        let first = clock.step();
        thread::sleep(Duration::from_millis(150));
        let second = clock.step();
        assert_eq!(second.since(first), MAX_STEP, "a 150 ms stall simulates one step");
        clock.idle();
        thread::sleep(Duration::from_millis(150));
        let third = clock.step();
        assert!(third.since(second) >= 150_000, "waiting for a master: {} µs", third.since(second));
    }

    #[test]
    fn options_reach_the_drive() {
        let opts = SimOptions { address: Some(7), baud: Some(115_200), ..Default::default() };
        let config = drive_config(&opts).unwrap();
        let drive = drive_core::Drive::new(config);
        assert_eq!(drive.address().get(), 7);
        assert_eq!(drive.baud().get(), 115_200);
        let factory = drive_core::Drive::new(drive_config(&SimOptions::default()).unwrap());
        assert_eq!((factory.address().get(), factory.baud().get()), (1, 9600));
    }

    #[test]
    fn options_the_drive_refuses() {
        for opts in [
            SimOptions { baud: Some(1200), ..Default::default() },
            SimOptions { address: Some(0), ..Default::default() },
            SimOptions { address: Some(128), ..Default::default() },
        ] {
            let e = drive_config(&opts).unwrap_err();
            assert_eq!(e.kind(), ErrorKind::InvalidInput, "{opts:?}");
        }
        let e = drive_config(&SimOptions { baud: Some(1200), ..Default::default() }).unwrap_err();
        assert!(e.to_string().contains("1200") && e.to_string().contains("9600"), "{e}");
    }
}
