//! `drivectl`: the commissioning tool for OpenStep drives on a Modbus bus (RTU or ASCII).

use std::io::{IsTerminal, Write};
use std::ops::RangeInclusive;
use std::process::ExitCode;
use std::time::{Duration, Instant};

use clap::{Parser, Subcommand};
use drive_core::scope::Phase;
use drivectl::dict::Map as DriveMap;
use drivectl::dict::{Dictionary, Map};
use drivectl::link::{Error, Framing, LineFormat, Link, Parity, Target};
use drivectl::{
    Drive, ScanEvent, ScanTimeouts, Settings, Value, parse_assignment, scan, scan_every_format, scope, update,
};
use indicatif::{ProgressBar, ProgressStyle};

/// Commission OpenStep drives over their Modbus link: find them, read and write their settings
/// by name, keep the settings in a file, move, jog, home and watch them. Works with every
/// register map the drive answers with (native, jmc, cls9, ec57, servo); values are in the map's
/// units.
#[derive(Parser)]
#[command(version)]
struct Cli {
    /// Serial port of the RS-485 adapter.
    #[arg(long, conflicts_with = "tcp", global = true)]
    port: Option<String>,
    /// Baud rate on the serial port (over TCP: the bus's, which a scan's waits follow).
    #[arg(long, default_value_t = 9600, global = true)]
    baud: u32,
    /// Parity on the serial port: none (8N1), even (8E1) or odd (8O1).
    #[arg(long, default_value = "none", value_parser = parse_parity, global = true)]
    parity: Parity,
    /// The simulator's TCP endpoint (raw RTU frames, or ASCII lines with --ascii): `hal-sim --tcp
    /// HOST:PORT`.
    #[arg(long, global = true)]
    tcp: Option<String>,
    /// Modbus ASCII framing (`:`, hex, LRC, CR LF) instead of RTU: a drive whose line framing
    /// 0x2192 (the servo map's P□600) was 1 at power-up.
    #[arg(long, global = true)]
    ascii: bool,
    /// Slave address of the drive.
    #[arg(long, short = 'a', default_value_t = 1, global = true)]
    address: u8,
    /// The drive's register map, if not the one its identification names (native, jmc, cls9,
    /// ec57, servo).
    #[arg(long, global = true)]
    map: Option<String>,
    /// How long one request may take, ms [default: 1000; a scan works its waits out from the
    /// baud rate and parity, and this sets the wait at each address].
    #[arg(long, global = true)]
    timeout: Option<u64>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Every drive on the bus: address, map, identification, each printed as it is found.
    Scan {
        /// First address asked.
        #[arg(long, default_value_t = 1)]
        from: u8,
        /// Last address asked.
        #[arg(long, default_value_t = 247)]
        to: u8,
        /// Try every baud rate and parity a drive takes (serial port only), each drive printed
        /// with the settings it answered at.
        #[arg(long)]
        all_bauds: bool,
    },
    /// The registers of a map (`--map`, default native): name, address, registers, access, unit;
    /// then its reserved ranges.
    List,
    /// Reads registers by name or address.
    Get {
        /// Names (`max-speed`, seed 004: `group3.target`) or addresses (`0x6003`, seed 003:
        /// `0x2003.1`).
        #[arg(required = true)]
        keys: Vec<String>,
    },
    /// Writes registers: NAME=VALUE (or ADDR=VALUE), in the map's units.
    Set {
        /// Assignments, written in order.
        #[arg(required = true)]
        assignments: Vec<String>,
    },
    /// Writes every saved setting to a TOML file (`-`: standard output).
    Dump {
        /// The file.
        #[arg(default_value = "-")]
        file: String,
    },
    /// Writes the settings of a TOML file (from `dump`) to the drive.
    Load {
        /// The file.
        file: String,
        /// Save them to the drive's flash afterwards.
        #[arg(long)]
        save: bool,
    },
    /// Runs to a position (microsteps, or the map's unit).
    Move {
        /// Target position, or distance with --relative.
        #[arg(allow_hyphen_values = true)]
        target: String,
        /// A distance from where the axis stands.
        #[arg(long)]
        relative: bool,
        /// Run speed (the map's unit of the command speed).
        #[arg(long)]
        speed: Option<i64>,
        /// Wait for the axis to stand and print where it stands.
        #[arg(long)]
        wait: bool,
    },
    /// Jogs until `stop`.
    Jog {
        /// `+` forward, `-` backward.
        #[arg(allow_hyphen_values = true, value_parser = ["+", "-"])]
        direction: String,
        /// Jog speed (the map's unit).
        #[arg(long)]
        speed: Option<i64>,
    },
    /// Runs the homing.
    Home {
        /// Homing method (0x2160's numbers).
        #[arg(long, allow_hyphen_values = true)]
        method: Option<i64>,
        /// Wait for the result.
        #[arg(long)]
        wait: bool,
    },
    /// Stops the axis at its deceleration (--quick: the emergency deceleration).
    Stop {
        /// Stop at the emergency deceleration.
        #[arg(long)]
        quick: bool,
        /// Wait for the axis to stand and print where it stands.
        #[arg(long)]
        wait: bool,
    },
    /// Energises the motor (`on`) or frees it (`off`).
    Enable {
        /// `on` or `off`.
        #[arg(value_parser = ["on", "off"], default_value = "on")]
        state: String,
    },
    /// Clears the latched alarms.
    Clear,
    /// Saves the settings to the drive's flash.
    Save,
    /// Restores the factory settings and saves them.
    FactoryReset,
    /// Records signals with the drive's scope: configures and arms it, waits for its capture,
    /// reads it and writes it as CSV and PNG.
    Scope {
        /// Up to 8 signals, by name or code (`drivectl scope --signals help` lists them).
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "commanded-position,actual-position,following-error,commanded-velocity"
        )]
        signals: Vec<String>,
        /// A row every this many control ticks (50 µs each), 2 at least.
        #[arg(long, default_value_t = 2)]
        divider: u16,
        /// What triggers it: now, move, alarm, rising|falling|crossing:SIGNAL:LEVEL,
        /// set|cleared:SIGNAL:MASK.
        #[arg(long, default_value = "move")]
        trigger: String,
        /// The share of the capture before the trigger, percent.
        #[arg(long, default_value_t = 10)]
        pre: u8,
        /// Once armed, a relative move of this many microsteps (the map's unit): a step response.
        #[arg(long, allow_hyphen_values = true)]
        r#move: Option<i64>,
        /// The move's speed.
        #[arg(long)]
        speed: Option<i64>,
        /// The capture as CSV (`-`: standard output).
        #[arg(long)]
        csv: Option<String>,
        /// The capture drawn as PNG.
        #[arg(long)]
        png: Option<std::path::PathBuf>,
        /// How long to wait for the trigger and the capture, s.
        #[arg(long, default_value_t = 60)]
        wait: u64,
        /// Capture again and again, redrawing the PNG and printing a line a capture, until
        /// Ctrl-C (or --count captures).
        #[arg(long)]
        live: bool,
        /// With --live: stop after this many captures.
        #[arg(long)]
        count: Option<u32>,
        /// Read only this many rows of each capture, the trigger as far into them as into the
        /// capture: a quicker read-out (with --live, a faster refresh).
        #[arg(long)]
        rows: Option<usize>,
    },
    /// Reads the black box's capture (the second before the last alarm and a quarter after)
    /// and writes it as CSV and PNG; the black box then records again.
    Blackbox {
        /// The capture as CSV (`-`: standard output).
        #[arg(long)]
        csv: Option<String>,
        /// The capture drawn as PNG.
        #[arg(long)]
        png: Option<std::path::PathBuf>,
    },
    /// Updates the firmware with a signed image (`cargo xtask sign`): sends it in file records
    /// (0x15), which the drive checks as they come, has the drive install it and restart, and
    /// reads the new version back.
    Update {
        /// The image.
        file: std::path::PathBuf,
        /// Every drive a scan of addresses 1-247 finds, one after the other (else --address).
        #[arg(long)]
        all: bool,
        /// Send and check only: the drive keeps the image ready until `--install-only` (or
        /// another transfer), and runs on.
        #[arg(long, conflicts_with = "install_only")]
        no_install: bool,
        /// Install the image the drive holds ready, sending nothing.
        #[arg(long)]
        install_only: bool,
    },
    /// The drive's state on one screen, refreshed until Ctrl-C (--once: printed once).
    Status {
        /// Print once and exit.
        #[arg(long)]
        once: bool,
        /// Refresh period, ms.
        #[arg(long, default_value_t = 250)]
        every: u64,
    },
}

/// `--parity`'s value.
fn parse_parity(name: &str) -> Result<Parity, String> {
    Parity::from_name(name).ok_or_else(|| format!("{name:?}: none, even or odd"))
}

/// The serial line's settings `--baud` and `--parity` give.
fn format(cli: &Cli) -> LineFormat {
    LineFormat { baud: cli.baud, parity: cli.parity }
}

fn target(cli: &Cli) -> Result<Target, Error> {
    match (&cli.port, &cli.tcp) {
        (Some(port), _) => Ok(Target::Serial { port: port.clone(), format: format(cli) }),
        (None, Some(at)) => Ok(Target::Tcp(at.clone())),
        (None, None) => Err(Error::Usage("say where the bus is: --port DEVICE [--baud B] or --tcp HOST:PORT".into())),
    }
}

fn framing(cli: &Cli) -> Framing {
    if cli.ascii { Framing::Ascii } else { Framing::Rtu }
}

fn map_arg(cli: &Cli) -> Result<Option<Map>, Error> {
    match &cli.map {
        None => Ok(None),
        Some(name) => Map::from_name(name)
            .map(Some)
            .ok_or_else(|| Error::Usage(format!("no map {name:?}: native, jmc, cls9, ec57 or servo"))),
    }
}

/// Prints a line; a closed pipe (`drivectl list | head`) ends the program quietly.
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        if let Err(e) = writeln!(std::io::stdout(), $($arg)*) {
            if e.kind() == std::io::ErrorKind::BrokenPipe {
                std::process::exit(0);
            }
        }
    }};
}

fn show(v: &Value, unit: &str) -> String {
    if unit.is_empty() { v.to_string() } else { format!("{v} {unit}") }
}

async fn run(cli: Cli) -> Result<(), Error> {
    let limit = Duration::from_millis(cli.timeout.unwrap_or(1000));
    if let Command::List = cli.command {
        let dict = Dictionary::of(map_arg(&cli)?.unwrap_or(Map::Native));
        for r in &dict.registers {
            let access = match (r.readable, r.writable) {
                (true, true) => "rw",
                (true, false) => "ro",
                _ => "wo",
            };
            say!(
                "{:<28} {:<10} {} {access} {:<4} {:<10} {}",
                r.name,
                r.at.to_string(),
                r.words,
                if r.saved { "save" } else { "" },
                r.unit,
                r.about
            );
        }
        for r in &dict.reserved {
            let at = format!("0x{:04X}-0x{:04X}", r.first, r.last);
            say!("{:<28} {at:<10} {} ro {:<4} {:<10} {}", "reserved", r.last - r.first + 1, "", "", r.about);
        }
        return Ok(());
    }
    if let Command::Scan { from, to, all_bauds } = cli.command {
        return scan_command(&cli, from..=to, all_bauds).await;
    }
    if let Command::Update { file, all, no_install, install_only } = &cli.command {
        let bytes = std::fs::read(file).map_err(|e| Error::Usage(format!("{}: {e}", file.display())))?;
        let steps = Steps { send: !install_only, install: !no_install };
        return update_command(&cli, &update::Image::new(bytes)?, *all, steps).await;
    }
    let link = Link::connect_with(target(&cli)?, framing(&cli), cli.address, map_arg(&cli)?, limit).await?;
    let mut drive = Drive::new(link).await?;
    match cli.command {
        Command::Scan { .. } | Command::List | Command::Update { .. } => {}
        Command::Get { keys } => {
            for key in keys {
                let r = drive.register(&key)?;
                let v = drive.get(&r).await?;
                say!("{} = {}", r.name, show(&v, r.unit));
            }
        }
        Command::Set { assignments } => {
            for a in assignments {
                let (key, v) = parse_assignment(&a)?;
                let r = drive.register(&key)?;
                drive.set(&r, v).await.map_err(|e| Error::Usage(format!("{} = {v}: {e}", r.name)))?;
                say!("{} = {}", r.name, show(&Value::Number(v), r.unit));
            }
        }
        Command::Dump { file } => {
            let text = drive.dump().await?.to_toml();
            if file == "-" {
                print!("{text}");
            } else {
                std::fs::write(&file, text).map_err(|e| Error::Usage(format!("{file}: {e}")))?;
            }
        }
        Command::Load { file, save } => {
            let text = std::fs::read_to_string(&file).map_err(|e| Error::Usage(format!("{file}: {e}")))?;
            let n = drive.load(&Settings::from_toml(&text)?).await?;
            if save {
                drive.save().await?;
            }
            say!("{n} setting(s) written{}", if save { " and saved" } else { "" });
        }
        Command::Move { target, relative, speed, wait } => {
            let t = drivectl::dict::parse_int(&target)
                .ok_or_else(|| Error::Usage(format!("{target:?} is not a whole number")))?;
            drive.move_to(t, relative, speed).await?;
            if wait {
                say!("standing at {}", drive.wait_standing(Duration::from_secs(600)).await?);
            }
        }
        Command::Jog { direction, speed } => drive.jog(direction == "+", speed).await?,
        Command::Home { method, wait } => {
            drive.home(method).await?;
            if wait {
                match drive.wait_homed(Duration::from_secs(600)).await? {
                    2 => say!("homed"),
                    r => return Err(Error::Usage(format!("the homing ended without a home (result {r})"))),
                }
            }
        }
        Command::Stop { quick, wait } => {
            drive.stop(quick).await?;
            if wait {
                say!("standing at {}", drive.wait_standing(Duration::from_secs(60)).await?);
            }
        }
        Command::Enable { state } => drive.enable(state == "on").await?,
        Command::Clear => drive.clear().await?,
        Command::Save => drive.save().await?,
        Command::FactoryReset => drive.factory_reset().await?,
        Command::Scope { signals, divider, trigger, pre, r#move, speed, csv, png, wait, live, count, rows } => {
            let setup = scope::Setup {
                signals: signals.iter().map(|s| scope::signal(s)).collect::<Result<_, _>>()?,
                divider,
                trigger: scope::trigger(&trigger)?,
                pre_percent: pre,
                repeat: live,
            };
            let mut taken = 0u32;
            let started = std::time::Instant::now();
            loop {
                // Live, the scope is repeated: reading a capture arms it again.
                if taken == 0 || r#move.is_some() {
                    drive.scope_arm(&setup).await?;
                }
                if let Some(distance) = r#move {
                    // The share before the trigger filled first, so that the capture holds it.
                    tokio::time::sleep(Duration::from_secs_f64(setup.pre_trigger_s())).await;
                    drive.move_to(distance, true, speed).await?;
                }
                // Armed: a spinner; triggered: a bar over the time the rest of the capture takes.
                let bar = ProgressBar::new_spinner();
                let after_ms = (setup.capture_s() - setup.pre_trigger_s()) * 1e3;
                let mut triggered: Option<std::time::Instant> = None;
                drive
                    .scope_wait(Duration::from_secs(wait), |p| {
                        if p == Phase::Triggered && triggered.is_none() {
                            triggered = Some(std::time::Instant::now());
                            bar.set_length(after_ms as u64);
                            bar.set_style(
                                ProgressStyle::with_template("triggered, recording {bar:40} {pos}/{len} ms")
                                    .unwrap_or_else(|_| ProgressStyle::default_bar()),
                            );
                        }
                        match triggered {
                            Some(at) => bar.set_position((at.elapsed().as_secs_f64() * 1e3).min(after_ms) as u64),
                            None => {
                                bar.set_message("armed, waiting for the trigger");
                                bar.tick();
                            }
                        }
                    })
                    .await?;
                bar.finish_and_clear();
                let read = ProgressBar::new(0);
                read.set_style(
                    ProgressStyle::with_template("reading {bar:40} {pos}/{len} registers")
                        .unwrap_or_else(|_| ProgressStyle::default_bar()),
                );
                let t0 = std::time::Instant::now();
                let capture = drive
                    .capture(false, rows, |done, of| {
                        read.set_length(of as u64);
                        read.set_position(done as u64);
                    })
                    .await?;
                read.finish_and_clear();
                let took = t0.elapsed().as_secs_f64();
                taken += 1;
                write_capture(&capture, csv.as_deref(), png.as_deref(), "scope")?;
                if !live {
                    eprintln!(
                        "capture {}: {} rows of {} signals, {:.3} s from the trigger's {:.3} s before, read in {took:.2} s",
                        capture.sequence,
                        capture.rows.len(),
                        capture.signals.len(),
                        capture.time(capture.rows.len().saturating_sub(1)),
                        -capture.time(0),
                    );
                    break;
                }
                let rate = f64::from(taken) / started.elapsed().as_secs_f64();
                say!("{}", live_line(&capture, rate));
                if count.is_some_and(|n| taken >= n) {
                    break;
                }
            }
        }
        Command::Blackbox { csv, png } => {
            let capture = drive.capture(true, None, |_, _| {}).await?;
            write_capture(&capture, csv.as_deref(), png.as_deref(), "black box")?;
            eprintln!(
                "black box capture {}: {} rows, the alarm at row {} ({:.3} s before it)",
                capture.sequence,
                capture.rows.len(),
                capture.trigger_row,
                -capture.time(0)
            );
        }
        Command::Status { once, every } => loop {
            let rows = drive.status().await?;
            if !once {
                // Clear the screen and go home: one screen, refreshed.
                print!("\x1b[2J\x1b[H");
            }
            say!("drive {} ({} map)", drive.link.slave(), drive.dict.map.name());
            for (r, v) in rows {
                say!("  {:<20} {}", r.name, show(&v, r.unit));
            }
            if once {
                break;
            }
            tokio::time::sleep(Duration::from_millis(every)).await;
        },
    }
    Ok(())
}

/// Writes `capture` as CSV (`-`: standard output) and PNG, where asked.
fn write_capture(
    capture: &scope::Capture,
    csv: Option<&str>,
    png: Option<&std::path::Path>,
    what: &str,
) -> Result<(), Error> {
    match csv {
        Some("-") => print!("{}", capture.to_csv()),
        Some(file) => std::fs::write(file, capture.to_csv()).map_err(|e| Error::Usage(format!("{file}: {e}")))?,
        None => {}
    }
    if let Some(png) = png {
        capture.plot(png, &format!("drive {what}: capture {}", capture.sequence))?;
    }
    Ok(())
}

/// One line of `scope --live`: each signal's range in the capture, and the captures a second.
fn live_line(capture: &scope::Capture, rate: f64) -> String {
    let mut line = format!("#{:<5} {rate:5.2}/s", capture.sequence);
    for (i, s) in capture.signals.iter().enumerate() {
        let values = capture.rows.iter().map(|r| r[i]);
        let (lo, hi) = values.fold((i64::MAX, i64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
        line.push_str(&format!("  {} {lo}..{hi}", scope::kebab(s.name())));
    }
    line
}

/// `scan`: each drive printed on stdout as it is found, a progress line on stderr while it is a
/// terminal, and the count and time on stderr at the end.
async fn scan_command(cli: &Cli, addresses: RangeInclusive<u8>, all_bauds: bool) -> Result<(), Error> {
    let started = Instant::now();
    let framing = framing(cli);
    let probe = cli.timeout.map(Duration::from_millis);
    let timeouts = |format| {
        let computed = ScanTimeouts::of(format, framing);
        probe.map_or(computed, |p| computed.with_probe(p))
    };
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::new(addresses.clone().count() as u64)
    } else {
        ProgressBar::hidden()
    };
    bar.set_style(
        ProgressStyle::with_template("scanning{msg} {pos}/{len}").unwrap_or_else(|_| ProgressStyle::default_bar()),
    );
    let report = |event: ScanEvent<'_>| match event {
        ScanEvent::Format(format) => {
            bar.set_message(format!(" at {format}"));
            bar.set_position(0);
        }
        ScanEvent::Asked { done, .. } => bar.set_position(done as u64),
        ScanEvent::Found(f) => {
            let id = &f.identity;
            let at = f.format.map(|format| format!("  at {format}")).unwrap_or_default();
            bar.suspend(|| {
                say!(
                    "{:>3}  {:<6}  {} {} {} ({}){at}",
                    f.address,
                    f.map.name(),
                    id.object(0),
                    id.object(1),
                    id.object(2),
                    id.object(5)
                );
                let _ = std::io::stdout().flush();
            });
        }
    };
    let found = match (&cli.port, all_bauds) {
        (Some(port), true) => scan_every_format(port, framing, addresses.clone(), timeouts, report).await?,
        (None, true) => {
            return Err(Error::Usage(
                "--all-bauds needs a serial port (--port): a TCP link carries frames with no baud rate or parity to try"
                    .into(),
            ));
        }
        (_, false) => {
            let waits = timeouts(format(cli));
            let mut link = Link::connect_raw(target(cli)?, framing, waits.probe).await?;
            scan(&mut link, addresses.clone(), waits, report).await?
        }
    };
    bar.finish_and_clear();
    let n = found.len();
    let settings = if all_bauds { format!(" at {} settings", LineFormat::every().count()) } else { String::new() };
    eprintln!("{n} drive(s); {} address(es){settings} in {:.1} s", addresses.count(), started.elapsed().as_secs_f64());
    if n == 0 { Err(Error::Usage("no drive answered".into())) } else { Ok(()) }
}

/// What `update` does to each drive.
#[derive(Clone, Copy)]
struct Steps {
    send: bool,
    install: bool,
}

/// `update`: the image to the drive at `--address`, or to every drive a scan finds, one after
/// the other; a line for each on stdout, a progress bar on stderr while it is a terminal. A
/// drive that fails is named with its reason, and the others still go.
async fn update_command(cli: &Cli, image: &update::Image, all: bool, steps: Steps) -> Result<(), Error> {
    let limit = Duration::from_millis(cli.timeout.unwrap_or(1000));
    let framing = framing(cli);
    eprintln!(
        "image {} for board {:?}, {} bytes",
        update::version(image.header.version),
        image.header.board,
        image.bytes.len()
    );
    let drives: Vec<(u8, Option<DriveMap>)> = if all {
        let waits = ScanTimeouts::of(format(cli), framing);
        let mut link = Link::connect_raw(target(cli)?, framing, waits.probe).await?;
        let found = scan(&mut link, 1..=247, waits, |_| {}).await?;
        found.iter().map(|f| (f.address, Some(f.map))).collect()
    } else {
        vec![(cli.address, map_arg(cli)?)]
    };
    if drives.is_empty() {
        return Err(Error::Usage("no drive answered the scan".into()));
    }
    let mut link = Link::connect_raw(target(cli)?, framing, limit).await?;
    let mut failed = 0;
    for (address, map) in drives {
        link.set_slave(address);
        match update_one(&mut link, map, image, steps).await {
            Ok(line) => say!("drive {address}: {line}"),
            Err(e) => {
                failed += 1;
                say!("drive {address}: failed: {e}");
            }
        }
    }
    if failed > 0 { Err(Error::Usage(format!("{failed} drive(s) not updated"))) } else { Ok(()) }
}

/// One drive's update: what it ran, the transfer (time, speed, against the wire's limit), the
/// install, and the version it runs after its restart.
async fn update_one(
    link: &mut Link,
    map: Option<DriveMap>,
    image: &update::Image,
    steps: Steps,
) -> Result<String, Error> {
    link.map = match map {
        Some(m) => m,
        None => DriveMap::from_application_name(link.identify().await?.object(6)),
    };
    let format = link.line_format();
    let mut u = update::Updater { link };
    u.check().await?;
    let was = u.running().await?;
    let mut line = update::version(was);
    if steps.send {
        let bar = if std::io::stderr().is_terminal() {
            ProgressBar::new(image.bytes.len() as u64)
        } else {
            ProgressBar::hidden()
        };
        bar.set_style(
            ProgressStyle::with_template("sending {bar:40} {bytes}/{total_bytes} {bytes_per_sec} {eta}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        let t0 = Instant::now();
        u.send(image, |n| bar.set_position(u64::from(n))).await?;
        bar.finish_and_clear();
        let took = t0.elapsed().as_secs_f64();
        let wire = update::wire_limit(image, format).as_secs_f64();
        line += &format!(
            ", sent {} bytes in {took:.1} s ({:.0} B/s; {:.2}x the wire's {wire:.1} s at {format}), checked",
            image.bytes.len(),
            image.bytes.len() as f64 / took,
            took / wire
        );
    }
    if !steps.install {
        u.ready().await?;
    }
    if steps.install {
        u.install().await?;
        let now = u.restarted(image.header.version, Duration::from_secs(60)).await?;
        if now != image.header.version {
            return Err(Error::Usage(format!(
                "restarted still running {} (the boot loader kept the old image)",
                update::version(now)
            )));
        }
        let state = update::boot_state(u.boot_state().await?);
        line += &format!(", installed, restarted: {}, {state}", update::version(now));
    }
    Ok(line)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let runtime = match tokio::runtime::Builder::new_current_thread().enable_all().build() {
        Ok(r) => r,
        Err(e) => {
            eprintln!("drivectl: {e}");
            return ExitCode::FAILURE;
        }
    };
    match runtime.block_on(run(cli)) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("drivectl: {e}");
            ExitCode::FAILURE
        }
    }
}
