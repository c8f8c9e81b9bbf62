//! `drivectl` against the simulated drive over TCP: the binary as a user runs it, and its
//! library for the bulk checks.

use std::process::{Command, Output, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use drive_core::od::{Access, OBJECTS, Obj, Range, Type};
use drivectl::dict::Address;
use drivectl::dict::{Dictionary, Map};
use drivectl::link::{Error, Framing, LineFormat, Link, Target};
use drivectl::{Drive, ScanTimeouts, Settings, Value};
use hal_sim::{Endpoint, PowerSwitch, SimOptions, Simulator, Snapshot};

/// A simulated drive (or several on one bus) on a free TCP port, with `map` if given.
fn power_on(axes: Vec<u8>, map: Option<u8>) -> (PowerSwitch, Arc<Mutex<Snapshot>>) {
    let opts = SimOptions { endpoint: Endpoint::Tcp("127.0.0.1:0".into()), axes, map, ..Default::default() };
    let sim = Simulator::bind(opts).expect("bind simulator");
    let snapshot = sim.snapshot();
    (sim.power_on(), snapshot)
}

/// Runs the binary against `sim` with `args`.
fn drivectl(sim: &PowerSwitch, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_drivectl"))
        .args(["--tcp", sim.endpoint()])
        .args(args)
        .output()
        .expect("run drivectl")
}

fn stdout(o: &Output) -> String {
    assert!(o.status.success(), "drivectl failed: {}", String::from_utf8_lossy(&o.stderr));
    String::from_utf8_lossy(&o.stdout).into_owned()
}

async fn drive(sim: &PowerSwitch) -> Drive {
    let link =
        Link::connect(Target::Tcp(sim.endpoint().into()), 1, None, Duration::from_secs(2)).await.expect("connect");
    Drive::new(link).await.expect("drive")
}

#[test]
fn scan_finds_every_drive_of_the_bus() {
    let (sim, _) = power_on((1..=8).collect(), None);
    let out = stdout(&drivectl(&sim, &["--timeout", "150", "scan", "--to", "12"]));
    let addresses: Vec<u8> = out
        .lines()
        .filter(|l| l.contains("OpenStep"))
        .filter_map(|l| l.split_whitespace().next()?.parse().ok())
        .collect();
    assert_eq!(addresses, (1..=8).collect::<Vec<_>>(), "{out}");
    assert_eq!(out.lines().count(), 8, "one line a drive: {out}");
    assert!(out.lines().all(|l| l.contains("native") && l.contains("OpenStep Motion")), "{out}");
}

/// Every map answers the scan's probe (diagnostics 0x08), and its identification names it.
#[tokio::test(flavor = "current_thread")]
async fn every_map_answers_the_probe_and_is_named() {
    for (id, map) in
        [(None, Map::Native), (Some(1), Map::Jmc), (Some(2), Map::Cls9), (Some(3), Map::Ec57), (Some(4), Map::Servo)]
    {
        let (sim, _) = power_on(vec![2], id);
        let timeouts = ScanTimeouts::of(LineFormat::default(), Framing::Rtu);
        let mut link =
            Link::connect_raw(Target::Tcp(sim.endpoint().into()), Framing::Rtu, timeouts.probe).await.expect("connect");
        link.set_slave(2);
        link.probe().await.unwrap_or_else(|e| panic!("{map:?}: {e}"));
        let found = drivectl::scan(&mut link, 1..=3, timeouts, |_| {}).await.expect("scan");
        assert_eq!(found.iter().map(|f| (f.address, f.map)).collect::<Vec<_>>(), [(2, map)]);
    }
}

/// A value of `ty` within `range` other than `default`, if there is one.
fn other_value(ty: Type, range: Range, default: u32) -> Option<i64> {
    let signed = ty == Type::S32;
    let default = if signed { i64::from(default as i32) } else { i64::from(default) };
    let max = match ty {
        Type::U8 => 0xFF,
        Type::U16 => 0xFFFF,
        Type::U32 | Type::S32 => i64::from(i32::MAX),
        Type::Str(_) => return None,
    };
    let candidates: Vec<i64> = match range {
        Range::Any => vec![max.min(1234), 1],
        Range::Span(lo, hi) => vec![
            i64::from(hi).min(max),
            i64::from(lo).max(0).max(if signed { i64::from(lo) } else { 0 }),
            (i64::from(lo) + i64::from(hi)) / 2,
        ],
        Range::Set(set) => set.iter().map(|v| if signed { i64::from(*v as i32) } else { i64::from(*v) }).collect(),
        Range::Bits(mask) => vec![i64::from(mask) & max, 1],
        Range::Magnitude(_, hi) => vec![i64::from(hi)],
    };
    candidates.into_iter().find(|v| *v != default && *v <= max)
}

/// Every writable object of the native map takes a value by name and reads it back by name.
#[tokio::test(flavor = "current_thread")]
async fn set_and_get_round_trip_by_name_for_every_writable_native_object() {
    let (sim, _) = power_on(Vec::new(), None);
    let mut d = drive(&sim).await;
    let mut checked = 0;
    let mut refused = Vec::new();
    let enable = d.register("enable").expect("enable");
    let mode = d.register("mode").expect("mode");
    let outputs = match d.get(&d.register("gpio-direction").expect("named")).await.expect("read") {
        Value::Number(v) => v,
        Value::Text(_) => 0,
    };
    // The communication IO and the jogs are signals that act (start, jog, home): their own
    // tests are in drive-core's `tests/servo.rs`.
    let signals = [Obj::CommInputs, Obj::SpeedJog, Obj::PositionJog];
    // The current loop's objects: the simulator's ideal chopper runs no current loop, so a
    // change is refused as unsupported (checked below; they act with `--power-stage bridges`,
    // hal-sim's `power_stage` tests).
    let current_loop = [Obj::CurrentAutoTune, Obj::CurrentKp, Obj::CurrentKi];
    // The password is not told: it reads 0 (drive-core's `tests/update_transfer.rs`).
    let secret = [Obj::Password];
    // Seed 004's signal inputs (P□512/P□513) are views of the inputs' functions whose digits
    // must name distinct inputs: every bit of their mask set is refused.
    let views = ["signal-inputs1", "signal-inputs2"];
    for def in OBJECTS.iter().filter(|d| {
        d.access() == Access::Rw
            && !signals.contains(&d.obj)
            && !current_loop.contains(&d.obj)
            && !secret.contains(&d.obj)
    }) {
        let r = d.dict.of_object(def.obj).expect("named").clone();
        if views.contains(&r.name.as_str()) {
            continue;
        }
        let Some(v) = other_value(def.ty(), *def.range, def.default) else { continue };
        // Each object from the factory state: its old value is written back after the check.
        let old = d.get(&r).await.expect("read");
        match d.set(&r, v).await {
            Ok(()) => {
                let back = d.get(&r).await.expect("read back");
                // The GPIO value's inputs read their pins: its outputs hold what was written.
                let (back, v) = match (def.obj, back) {
                    (Obj::GpioValue, Value::Number(b)) => (Value::Number(b & outputs), v & outputs),
                    (_, back) => (back, v),
                };
                if back != Value::Number(v) {
                    refused.push(format!("{} = {v}: reads {back}", r.name));
                }
                checked += 1;
            }
            Err(e) => refused.push(format!("{} = {v}: {e}", r.name)),
        }
        if let Value::Number(old) = old {
            let _ = d.set(&r, old).await;
        }
        // Leave the drive able to take the next write: energised, standing, in position mode.
        let _ = d.set(&enable, 1).await;
        let _ = d.set(&mode, 0).await;
    }
    assert!(refused.is_empty(), "refused: {refused:#?}");
    assert!(checked > 100, "{checked}");
    let tune = d.register("current-auto-tune").expect("named").clone();
    assert!(d.set(&tune, 0).await.is_err(), "no current loop: a change is refused");
    assert!(d.set(&tune, 1).await.is_ok(), "the value it holds is taken");
}

/// A dump loaded into a factory-fresh drive makes the two drives' settings identical.
#[test]
fn a_dump_loaded_into_a_fresh_drive_clones_its_settings() {
    for map in [None, Some(1), Some(2), Some(3), Some(4)] {
        let (a, _) = power_on(Vec::new(), map);
        let (b, _) = power_on(Vec::new(), map);
        let changes: &[&str] = match map {
            None => &["microsteps=32", "phase-current=1200", "pp-accel=40000", "idle-current=30", "homing-method=17"],
            Some(1) => &["pp-accel=500", "map-word-order=1", "homing-search-speed=30", "homing-offset=-1234"],
            Some(2) => &["idle-current=30", "phase-current=1500", "jog-speed=500"],
            Some(3) => &["microsteps=10000", "idle-current=70", "position-error-angle=90"],
            // The r/min registers come before the resolution 0x600C in the servo map's order:
            // `load` writes the resolution first. A position data group is carried too.
            _ => &[
                "microsteps=16",
                "jog-speed=300",
                "pp-accel=500",
                "gear-numerator=2",
                "group2.target=-3200",
                "group2.speed=300",
                "group2.type=2",
            ],
        };
        let mut args = vec!["set"];
        args.extend_from_slice(changes);
        stdout(&drivectl(&a, &args));
        let dir = tempfile::tempdir().expect("tempdir");
        let file = dir.path().join("a.toml");
        let file = file.to_str().expect("path");
        stdout(&drivectl(&a, &["dump", file]));
        let dumped = Settings::from_toml(&std::fs::read_to_string(file).expect("dump file")).expect("parses");
        let fresh = stdout(&drivectl(&b, &["dump"]));
        assert_ne!(Settings::from_toml(&fresh).expect("parses"), dumped, "{map:?}: the changes show");
        let loaded = stdout(&drivectl(&b, &["load", file]));
        assert!(loaded.contains(&format!("{} setting(s) written", dumped.settings.len())), "{loaded}");
        let after = stdout(&drivectl(&b, &["dump"]));
        assert_eq!(Settings::from_toml(&after).expect("parses"), dumped, "{map:?}");
    }
}

/// A move by drivectl turns the simulated rotor, and `--wait` reports where it stands.
#[test]
fn a_move_turns_the_rotor() {
    let (sim, snapshot) = power_on(Vec::new(), None);
    let out = stdout(&drivectl(&sim, &["move", "1600", "--relative", "--speed", "4000", "--wait"]));
    assert_eq!(out.trim(), "standing at 1600");
    let rotor = snapshot.lock().expect("snapshot").rotor_microsteps;
    assert!((rotor - 1600.0).abs() < 1.0, "rotor at {rotor}");
    let out = stdout(&drivectl(&sim, &["move", "-800", "--wait"]));
    assert_eq!(out.trim(), "standing at -800");
    let status = stdout(&drivectl(&sim, &["status", "--once"]));
    assert!(status.contains("position             -800 step"), "{status}");
}

/// A refused request: the exception's meaning in words and a failing exit status; nothing changed.
#[test]
fn a_refused_request_says_why_and_fails() {
    let (sim, _) = power_on(Vec::new(), None);
    let out = drivectl(&sim, &["set", "microsteps=300"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("exception 03") && err.contains("value out of range"), "{err}");
    assert_eq!(stdout(&drivectl(&sim, &["get", "microsteps"])).trim(), "microsteps = 0");
    let out = drivectl(&sim, &["get", "no-such-register"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("drivectl list"));
}

/// The EC-57 map: found by its identification, its sub-indexed registers by name, the native
/// objects through its window.
#[test]
fn the_ec57_map_speaks_sub_indices() {
    let (sim, _) = power_on(Vec::new(), Some(3));
    stdout(&drivectl(&sim, &["set", "microsteps=10000", "0x2003.2=70", "register-map=3"]));
    let out = stdout(&drivectl(&sim, &["get", "microsteps", "idle-current", "register-map", "0x2000.0"]));
    assert_eq!(
        out.lines().collect::<Vec<_>>(),
        ["microsteps = 10000 pulse/rev", "idle-current = 70 %", "register-map = 3", "node-id = 1"]
    );
    let out = drivectl(&sim, &["set", "microsteps=10001"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("exception 06"), "{out:?}");
}

#[tokio::test(flavor = "current_thread")]
async fn library_errors_name_the_map() {
    let (sim, _) = power_on(Vec::new(), Some(1));
    let mut d = drive(&sim).await;
    assert_eq!(d.dict.map, Map::Jmc);
    let err = d.move_to(100, true, None).await.expect_err("no motion command in the JMC map");
    assert!(matches!(err, Error::Usage(ref m) if m.contains("jmc map")), "{err}");
    assert_eq!(Dictionary::of(Map::Jmc).map, Map::Jmc);
}

/// Runs the binary on the serial port `port` at 9600 baud.
fn on_port(port: &str, args: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_drivectl"))
        .args(["--port", port, "--baud", "9600"])
        .args(args)
        .output()
        .expect("run drivectl");
    stdout(&o)
}

/// Over a serial port: the simulator's pseudo-terminal at 9600 baud, in the native map and in
/// the EC-57's (found by its identification, then framed with sub-indices on the same port).
#[test]
fn drivectl_over_a_serial_port() {
    let opts = SimOptions { endpoint: Endpoint::Pty { link: None }, ..Default::default() };
    let sim = Simulator::bind(opts).expect("bind simulator").power_on();
    let ec57 = SimOptions { endpoint: Endpoint::Pty { link: None }, map: Some(3), ..Default::default() };
    let ec57 = Simulator::bind(ec57).expect("bind simulator").power_on();
    assert_eq!(on_port(ec57.endpoint(), &["set", "0x2003.2=60"]), "idle-current = 60 %\n");
    assert_eq!(on_port(ec57.endpoint(), &["get", "idle-current"]), "idle-current = 60 %\n");
    let run = |args: &[&str]| on_port(sim.endpoint(), args);
    assert_eq!(run(&["get", "device-name", "phase-current"]), "device-name = \"OSD-42\"\nphase-current = 658 mA\n");
    run(&["set", "phase-current=900"]);
    assert_eq!(run(&["get", "phase-current"]), "phase-current = 900 mA\n");
    assert_eq!(run(&["move", "400", "--relative", "--wait"]), "standing at 400\n");
    assert!(run(&["scan", "--to", "2"]).starts_with("  1  native  OpenStep Motion"));
}

/// Jog, stop, home, enable and clear act on the simulated drive.
#[test]
fn jog_stop_home_enable_and_clear() {
    let (sim, snapshot) = power_on(Vec::new(), None);
    stdout(&drivectl(&sim, &["jog", "-", "--speed", "2000"]));
    std::thread::sleep(Duration::from_millis(300));
    assert!(stdout(&drivectl(&sim, &["get", "run-state"])).contains("run-state = 3"), "jogging");
    let out = stdout(&drivectl(&sim, &["stop", "--wait"]));
    let stood: i64 = out.trim().strip_prefix("standing at ").and_then(|p| p.parse().ok()).expect("a position");
    assert!(stood < -100, "jogged backward: {out}");
    let rotor = snapshot.lock().expect("snapshot").rotor_microsteps;
    assert!((rotor - stood as f64).abs() < 1.0, "rotor {rotor}, drive {stood}");
    // The factory method 35: the present position is home.
    assert_eq!(stdout(&drivectl(&sim, &["home", "--wait"])).trim(), "homed");
    assert!(stdout(&drivectl(&sim, &["get", "position"])).contains("position = 0 step"));
    stdout(&drivectl(&sim, &["enable", "off"]));
    assert!(!snapshot_enabled(&snapshot), "the stage is off");
    let out = drivectl(&sim, &["move", "100", "--relative"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("the power stage is off"), "{out:?}");
    stdout(&drivectl(&sim, &["enable", "on"]));
    stdout(&drivectl(&sim, &["clear"]));
    assert_eq!(stdout(&drivectl(&sim, &["move", "100", "--relative", "--wait"])).trim(), "standing at 100");
}

fn snapshot_enabled(snapshot: &Arc<Mutex<Snapshot>>) -> bool {
    std::thread::sleep(Duration::from_millis(50));
    snapshot.lock().expect("snapshot").enabled
}

/// A simulator over TCP powered up from the flash file `flash`.
fn on_flash(flash: &std::path::Path) -> PowerSwitch {
    let opts = SimOptions {
        endpoint: Endpoint::Tcp("127.0.0.1:0".into()),
        flash: Some(flash.to_path_buf()),
        ..Default::default()
    };
    Simulator::bind(opts).expect("bind simulator").power_on()
}

/// Save keeps the settings across a restart; factory-reset brings back the factory ones.
#[test]
fn save_and_factory_reset_survive_a_restart() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let on = || on_flash(&flash);
    let sim = on();
    stdout(&drivectl(&sim, &["set", "phase-current=1000"]));
    stdout(&drivectl(&sim, &["save"]));
    drop(sim);
    let sim = on();
    assert_eq!(stdout(&drivectl(&sim, &["get", "phase-current"])), "phase-current = 1000 mA\n");
    stdout(&drivectl(&sim, &["factory-reset"]));
    drop(sim);
    let sim = on();
    assert_eq!(stdout(&drivectl(&sim, &["get", "phase-current"])), "phase-current = 658 mA\n");
}

/// The servo map (seed 004): found by its identification, its registers by name in its units
/// (r/min, 10 r/min/s), 32-bit values low word first, the position data groups by name, the
/// reserved ranges named as such; a group run through the communication IO.
#[test]
fn the_servo_map_by_name_in_its_units() {
    let (sim, snapshot) = power_on(Vec::new(), Some(4));
    let out = stdout(&drivectl(&sim, &["get", "jog-speed", "pp-accel", "speed-window", "pp-accel@0x6067"]));
    assert_eq!(
        out.lines().collect::<Vec<_>>(),
        [
            "jog-speed = 600 r/min",
            "pp-accel = 960 10 r/min/s",
            "speed-window = 10 r/min",
            "pp-accel@0x6067 = 32000 pps²"
        ]
    );
    // 500 × 10 r/min/s at 200 microsteps a revolution: 16 667 pps².
    let out = stdout(&drivectl(
        &sim,
        &[
            "--map",
            "servo",
            "set",
            "jog-speed=300",
            "pp-accel=500",
            "group3.target=-3200",
            "group3.speed=600",
            "0x061F=2",
        ],
    ));
    assert!(out.contains("group3.type = 2"), "{out}");
    let out = stdout(&drivectl(
        &sim,
        &["--map", "servo", "get", "jog-speed", "pp-accel@0x6067", "group3.target", "group3.speed", "group3.type"],
    ));
    assert_eq!(
        out.lines().collect::<Vec<_>>(),
        [
            "jog-speed = 300 r/min",
            "pp-accel@0x6067 = 16667 pps²",
            "group3.target = -3200 group unit",
            "group3.speed = 600 r/min",
            "group3.type = 2"
        ]
    );
    // The target's words on the wire: low word first (§6.4).
    let runtime = tokio::runtime::Builder::new_current_thread().enable_all().build().expect("runtime");
    let words = runtime.block_on(async {
        let mut d = drive(&sim).await;
        assert_eq!(d.dict.map, Map::Servo);
        d.link.read(Address { register: 0x0618, sub: None }, 2).await.expect("read")
    });
    drop(runtime);
    assert_eq!(words, [0xF380, 0xFFFF]);
    // A value out of a group word's range, a reserved register, a command's value.
    let out = drivectl(&sim, &["set", "group3.speed=7000"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("exception 03"), "{out:?}");
    let out = drivectl(&sim, &["get", "0x0005"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("reserved in the servo map"), "{err}");
    let out = drivectl(&sim, &["move", "100"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("no register for the run target"), "{out:?}");
    // Group 0: absolute 400 at 600 r/min; servo on, then POS-START (0451h bit 13).
    stdout(&drivectl(&sim, &["set", "group0.target=400", "group0.speed=600", "group0.type=1"]));
    stdout(&drivectl(&sim, &["set", "comm-inputs=1", "comm-inputs=0x2001"]));
    let mut at = String::new();
    for _ in 0..100 {
        at = stdout(&drivectl(&sim, &["get", "actual-position", "run-state"]));
        if at == "actual-position = 400 step\nrun-state = 2\n" {
            break;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    assert_eq!(at, "actual-position = 400 step\nrun-state = 2\n");
    let rotor = snapshot.lock().expect("snapshot").rotor_microsteps;
    assert!((rotor - 400.0).abs() < 1.0, "rotor at {rotor}");
    let status = stdout(&drivectl(&sim, &["status", "--once"]));
    assert!(status.contains("servo map") && status.contains("actual-position      400 step"), "{status}");
    // Clear and save act through 0x200F (0520h-0540h are enumerations of it).
    stdout(&drivectl(&sim, &["clear"]));
    stdout(&drivectl(&sim, &["save"]));
}

/// `--ascii` against a drive whose line framing 0x2192 was 1 at power-up (written, saved, the
/// simulator restarted on the same flash file): reads, writes, refusals, a move, a scan; an RTU
/// request gets no answer; 0x2192 = 0 brings RTU back.
#[test]
fn ascii_framing_over_tcp() {
    let dir = tempfile::tempdir().expect("tempdir");
    let flash = dir.path().join("flash.bin");
    let on = || on_flash(&flash);
    let sim = on();
    stdout(&drivectl(&sim, &["set", "line-framing=1", "phase-current=1000"]));
    stdout(&drivectl(&sim, &["save"]));
    drop(sim);
    let sim = on();
    let rtu = drivectl(&sim, &["--timeout", "300", "get", "phase-current"]);
    assert!(String::from_utf8_lossy(&rtu.stderr).contains("no answer"), "{rtu:?}");
    let ascii = |args: &[&str]| {
        let mut all = vec!["--ascii"];
        all.extend_from_slice(args);
        drivectl(&sim, &all)
    };
    assert_eq!(
        stdout(&ascii(&["get", "phase-current", "line-framing"])),
        "phase-current = 1000 mA\nline-framing = 1\n"
    );
    stdout(&ascii(&["set", "phase-current=900", "max-speed=20000"]));
    assert_eq!(
        stdout(&ascii(&["get", "phase-current", "max-speed"])),
        "phase-current = 900 mA\nmax-speed = 20000 pps\n"
    );
    assert_eq!(stdout(&ascii(&["get", "device-name"])), "device-name = \"OSD-42\"\n");
    let out = ascii(&["set", "microsteps=300"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("exception 03") && err.contains("value out of range"), "{err}");
    assert_eq!(stdout(&ascii(&["move", "400", "--relative", "--speed", "4000", "--wait"])), "standing at 400\n");
    let scan = ascii(&["scan", "--to", "3"]);
    assert!(String::from_utf8_lossy(&scan.stderr).contains("1 drive(s)"), "{scan:?}");
    assert!(stdout(&scan).starts_with("  1  native"), "{scan:?}");
    let settings = Settings::from_toml(&stdout(&ascii(&["dump"]))).expect("a dump");
    assert_eq!(settings.settings.get("phase-current"), Some(&900));
    stdout(&ascii(&["set", "line-framing=0"]));
    stdout(&ascii(&["save"]));
    drop(sim);
    let sim = on();
    assert_eq!(stdout(&drivectl(&sim, &["get", "phase-current"])), "phase-current = 900 mA\n");
}

/// The servo map in ASCII on a serial port: P□600 (serial format 0x31: ASCII 8N1, 9600 baud)
/// saved and the drive restarted by 0541h, then every request in ASCII lines, by name.
#[test]
fn the_servo_map_in_ascii_on_a_serial_port() {
    let opts = SimOptions { endpoint: Endpoint::Pty { link: None }, map: Some(4), ..Default::default() };
    let sim = Simulator::bind(opts).expect("bind simulator").power_on();
    let port = sim.endpoint();
    assert_eq!(on_port(port, &["set", "serial-format=0x31"]), "serial-format = 49\n");
    on_port(port, &["save"]);
    on_port(port, &["set", "restart=1"]);
    std::thread::sleep(Duration::from_millis(100));
    assert_eq!(
        on_port(port, &["--ascii", "get", "serial-format", "jog-speed"]),
        "serial-format = 49\njog-speed = 600 r/min\n"
    );
    on_port(port, &["--ascii", "--map", "servo", "set", "group1.target=100000", "jog-speed=450"]);
    assert_eq!(
        on_port(port, &["--ascii", "--map", "servo", "get", "group1.target", "0x0130"]),
        "group1.target = 100000 group unit\njog-speed = 450 r/min\n"
    );
    let found = on_port(port, &["--ascii", "scan", "--to", "2"]);
    assert!(found.starts_with("  1  servo") && found.lines().count() == 1, "{found}");
}

/// The EC-57 map's sub-indexed requests in ASCII lines: the framing through its window (0x2192
/// at sub-index 0xFF), the save there too, and a restart.
#[tokio::test(flavor = "current_thread")]
async fn sub_indexed_requests_in_ascii() {
    let (sim, _) = power_on(Vec::new(), Some(3));
    stdout(&drivectl(&sim, &["set", "0x2003.2=60", "line-framing=1"]));
    stdout(&drivectl(&sim, &["save"]));
    stdout(&drivectl(&sim, &["set", "restart=1"]));
    tokio::time::sleep(Duration::from_millis(100)).await;
    let link = Link::connect_with(Target::Tcp(sim.endpoint().into()), Framing::Ascii, 1, None, Duration::from_secs(2))
        .await
        .expect("connect");
    assert_eq!((link.map, link.framing()), (Map::Ec57, Framing::Ascii));
    let mut d = Drive::new(link).await.expect("drive");
    let idle = d.register("idle-current").expect("named");
    assert_eq!(d.get(&idle).await.expect("read"), Value::Number(60));
    d.set(&idle, 40).await.expect("write");
    assert_eq!(d.get(&idle).await.expect("read"), Value::Number(40));
    let framing = d.register("line-framing").expect("through the window");
    assert_eq!(d.get(&framing).await.expect("read"), Value::Number(1));
}

/// Runs the binary with `args`, each line of its standard output stamped with when it came: the
/// lines, what it wrote to standard error, and how long it ran.
fn timed(args: &[&str]) -> (Vec<(Duration, String)>, String, Duration) {
    use std::io::{BufRead, BufReader, Read};
    let start = Instant::now();
    let mut child = Command::new(env!("CARGO_BIN_EXE_drivectl"))
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run drivectl");
    let out = child.stdout.take().expect("stdout");
    let lines = std::thread::spawn(move || {
        BufReader::new(out).lines().map_while(Result::ok).map(|l| (start.elapsed(), l)).collect::<Vec<_>>()
    });
    let mut err = String::new();
    child.stderr.take().expect("stderr").read_to_string(&mut err).expect("stderr");
    let status = child.wait().expect("wait");
    let took = start.elapsed();
    let lines = lines.join().expect("reader");
    assert!(status.success(), "drivectl {args:?}: {err}");
    (lines, err, took)
}

/// The address at the start of each line.
fn addresses(lines: &[(Duration, String)]) -> Vec<u8> {
    lines.iter().filter_map(|(_, l)| l.split_whitespace().next()?.parse().ok()).collect()
}

/// A scan of addresses 1-247 at 9600 baud over a serial port (the simulator's pseudo-terminal)
/// with three drives on the bus: all three found within 20 s, each printed as it is found; with
/// standard error no terminal, no progress, only the count at the end.
#[test]
fn a_scan_of_every_address_at_9600_baud_is_quick_and_prints_as_it_goes() {
    let opts = SimOptions { endpoint: Endpoint::Pty { link: None }, axes: vec![5, 100, 127], ..Default::default() };
    let sim = Simulator::bind(opts).expect("bind simulator").power_on();
    let (lines, err, took) = timed(&["--port", sim.endpoint(), "--baud", "9600", "scan"]);
    eprintln!("scan of 1-247 at 9600 baud: {took:?}; found at {:?}", lines.iter().map(|(t, _)| t).collect::<Vec<_>>());
    assert_eq!(addresses(&lines), [5, 100, 127], "{lines:?}");
    assert!(lines.iter().all(|(_, l)| l.contains("native  OpenStep Motion")), "{lines:?}");
    assert!(took <= Duration::from_secs(20), "{took:?}");
    // 120 empty addresses after 127 take over 4 s: each line came when its drive was found.
    for (t, l) in &lines {
        assert!(took.saturating_sub(*t) > Duration::from_secs(4), "{l:?} at {t:?} of {took:?}");
    }
    assert!(err.starts_with("3 drive(s); 247 address(es) in ") && err.lines().count() == 1, "{err:?}");
}

/// `--all-bauds` finds a drive at 38400 baud and even parity, at that setting only; over TCP it
/// is refused.
#[test]
fn all_bauds_finds_a_drive_at_38400_baud_even_parity() {
    let opts = SimOptions {
        endpoint: Endpoint::Pty { link: None },
        address: Some(3),
        baud: Some(38_400),
        parity: Some(1),
        ..Default::default()
    };
    let sim = Simulator::bind(opts).expect("bind simulator").power_on();
    let (lines, err, took) = timed(&["--port", sim.endpoint(), "scan", "--all-bauds", "--to", "5"]);
    eprintln!("--all-bauds of 1-5: {took:?}; found at {:?}", lines.iter().map(|(t, _)| t).collect::<Vec<_>>());
    assert_eq!(lines.len(), 1, "{lines:?}");
    assert!(lines.iter().all(|(_, l)| l.starts_with("  3  native") && l.ends_with("at 38400 8E1")), "{lines:?}");
    assert!(err.contains("5 address(es) at 21 settings"), "{err}");
    assert!(took <= Duration::from_secs(30), "{took:?}");
    let (tcp, _) = power_on(Vec::new(), None);
    let refused = drivectl(&tcp, &["scan", "--all-bauds"]);
    assert!(!refused.status.success(), "{refused:?}");
    assert!(String::from_utf8_lossy(&refused.stderr).contains("--all-bauds needs a serial port"), "{refused:?}");
}
