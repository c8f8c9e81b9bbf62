//! `drivectl scope` and `drivectl blackbox` against the simulated drive, through the binary as a
//! user runs it (over TCP and over a pseudo-terminal): a capture of a move is the simulator's
//! own trace of the same ticks, the triggers fire where they should, and a fault injected during
//! a move leaves its cause in the black box.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use hal_sim::trace::{TraceRow, load_csv};
use hal_sim::{Endpoint, MotorOptions, PowerSwitch, SimOptions, Simulator};

/// A simulated drive on `endpoint`, its trace of every tick in `trace` if given, `faults`
/// injected.
fn power_on(endpoint: Endpoint, trace: Option<&Path>, faults: &[&str]) -> PowerSwitch {
    let motor = MotorOptions { trace: trace.map(|p| (p.to_path_buf(), 1)), ..Default::default() };
    let faults = faults.iter().map(|f| f.parse().expect("fault")).collect();
    let opts = SimOptions { endpoint, motor, faults, ..Default::default() };
    Simulator::bind(opts).expect("bind simulator").power_on()
}

/// Runs the binary with `link` (`--tcp ..` or `--port ..`) and `args`; its standard error on
/// failure.
fn drivectl(link: &[&str], args: &[&str]) -> Output {
    let out = Command::new(env!("CARGO_BIN_EXE_drivectl")).args(link).args(args).output().expect("run drivectl");
    assert!(out.status.success(), "drivectl {args:?} failed: {}", String::from_utf8_lossy(&out.stderr));
    out
}

/// A capture's CSV: its header's columns and its rows.
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(path).expect("csv");
    let mut lines = text.lines();
    let header = lines.next().expect("header").split(',').map(String::from).collect();
    let rows = lines.map(|l| l.split(',').map(|v| v.parse().expect("number")).collect()).collect();
    (header, rows)
}

/// The trace row index `i` such that capture row `k` is trace row `i + k·divider` for every
/// row, comparing commanded positions (the capture's whole microsteps, the trace's with their
/// fraction) and velocities (the capture's to the nearest), searched around the move that starts after trace row
/// `after`.
fn aligned(trace: &[TraceRow], rows: &[Vec<f64>], divider: usize, trigger_row: usize, after: usize) -> Option<usize> {
    // The end of the move under way at `after`, then the next start.
    let still = after + trace.get(after..)?.iter().position(|r| r.commanded_velocity_pps == 0.0)?;
    let start = still + trace.get(still..)?.iter().position(|r| r.commanded_velocity_pps != 0.0)?;
    let matches = |i: usize| {
        rows.iter().enumerate().all(|(k, row)| {
            trace.get(i + k * divider).is_some_and(|t| {
                // The whole microsteps of the trace's (printed to 10⁻⁴), the velocity rounded.
                let p = t.commanded_position_usteps - row[1];
                (-1e-3..1.0 + 1e-3).contains(&p) && (t.commanded_velocity_pps - row[2]).abs() <= 0.5 + 1e-3
            })
        })
    };
    let first = start.checked_sub((trigger_row + 1) * divider)?;
    (first..start + divider).find(|&i| matches(i))
}

fn trigger_row(rows: &[Vec<f64>]) -> usize {
    rows.iter().position(|r| r[0] >= 0.0).expect("a row at the trigger")
}

#[test]
fn a_capture_of_a_move_is_the_simulators_trace_at_every_divider_over_tcp() {
    captures_match_the_trace(false);
}

#[test]
fn a_capture_of_a_move_is_the_simulators_trace_at_every_divider_over_a_pseudo_terminal() {
    captures_match_the_trace(true);
}

/// Three captures of moves at dividers 2, 3 and 10 against the simulator's trace of every tick.
fn captures_match_the_trace(pty: bool) {
    let dir = tempfile::tempdir().expect("temp dir");
    let trace = dir.path().join("trace.csv");
    let tty = dir.path().join("tty");
    let endpoint = if pty { Endpoint::Pty { link: Some(tty.clone()) } } else { Endpoint::Tcp("127.0.0.1:0".into()) };
    let sim = power_on(endpoint, Some(&trace), &[]);
    let link = if pty { ["--port", tty.to_str().expect("path")] } else { ["--tcp", sim.endpoint()] };
    let dividers = [2usize, 3, 10];
    let mut captures: Vec<PathBuf> = Vec::new();
    for (n, divider) in dividers.iter().enumerate() {
        let csv = dir.path().join(format!("capture-{divider}.csv"));
        let d = divider.to_string();
        let distance = if n % 2 == 0 { "2000" } else { "-2000" };
        drivectl(
            &link,
            &[
                "scope",
                "--signals",
                "commanded-position,commanded-velocity,phase-a-current",
                "--divider",
                &d,
                "--trigger",
                "move",
                "--pre",
                "10",
                "--move",
                distance,
                "--speed",
                "10000",
                "--csv",
                csv.to_str().expect("path"),
            ],
        );
        drivectl(&link, &["stop", "--wait"]);
        captures.push(csv);
    }
    sim.off().expect("power off");
    let trace = load_csv(&trace).expect("trace");
    let mut after = 0;
    for (divider, csv) in dividers.iter().zip(&captures) {
        let (header, rows) = read_csv(csv);
        assert_eq!(header, ["time_s", "commanded-position", "commanded-velocity", "phase-a-current"]);
        let t = trigger_row(&rows);
        let i = aligned(&trace, &rows, *divider, t, after)
            .unwrap_or_else(|| panic!("divider {divider}: no alignment of {} rows with the trace", rows.len()));
        // The rows' times are the trace's, from the trigger's row.
        for (k, row) in rows.iter().enumerate().step_by(97) {
            let dt = trace[i + k * divider].t_s - trace[i + t * divider].t_s;
            assert!((row[0] - dt).abs() < 1e-6, "divider {divider}, row {k}: {} against {dt}", row[0]);
        }
        // The phase current the tick measured is the motor's at the end of the tick before
        // (the sensing's own quantisation aside).
        let worst = rows
            .iter()
            .enumerate()
            .skip(1)
            .map(|(k, row)| (trace[i + k * divider - 1].i_a * 1e3 - row[3]).abs())
            .fold(0.0, f64::max);
        assert!(worst <= 2.0, "divider {divider}: phase A current off by {worst} mA");
        after = i + rows.len() * divider;
    }
}

#[test]
fn the_triggers_fire_where_they_should_over_a_pseudo_terminal() {
    let dir = tempfile::tempdir().expect("temp dir");
    let tty = dir.path().join("tty");
    let sim = power_on(Endpoint::Pty { link: Some(tty.clone()) }, None, &[]);
    let link = ["--port", tty.to_str().expect("path"), "--baud", "9600"];
    let csv = dir.path().join("c.csv");
    let capture = |trigger: &str, distance: &str| {
        drivectl(
            &link,
            &[
                "scope",
                "--signals",
                "commanded-position,commanded-velocity,status",
                "--divider",
                "5",
                "--trigger",
                trigger,
                "--pre",
                "20",
                "--move",
                distance,
                "--speed",
                "8000",
                "--csv",
                csv.to_str().expect("path"),
            ],
        );
        drivectl(&link, &["stop", "--wait"]);
        read_csv(&csv).1
    };
    // A level crossing: the first row at or past the level, the one before not.
    let rows = capture("rising:commanded-position:1500", "3000");
    let t = trigger_row(&rows);
    assert!(rows[t][1] >= 1500.0 && rows[t - 1][1] < 1500.0, "{:?} {:?}", rows[t - 1], rows[t]);
    let rows = capture("falling:commanded-velocity:-4000", "-3000");
    let t = trigger_row(&rows);
    assert!(rows[t][2] <= -4000.0 && rows[t - 1][2] > -4000.0, "{:?} {:?}", rows[t - 1], rows[t]);
    // A move's start: the busy bit (status bit 3) rises at the trigger's row.
    let rows = capture("move", "1000");
    let t = trigger_row(&rows);
    let busy = |r: &Vec<f64>| (r[3] as u32) & 8 != 0;
    assert!(busy(&rows[t]) && !busy(&rows[t - 1]));
    assert!(rows[..t].iter().all(|r| r[2] == 0.0) && rows[t + 1][2] != 0.0);
    // A bit set: the same edge by its mask.
    let rows = capture("set:status:8", "-1000");
    let t = trigger_row(&rows);
    assert!(busy(&rows[t]) && !busy(&rows[t - 1]));
    sim.off().expect("power off");
}

#[test]
fn a_fault_during_a_move_leaves_its_cause_in_the_black_box() {
    let dir = tempfile::tempdir().expect("temp dir");
    // The supply climbs from 24 V to 70 V over 400 ms, 3 s after power-up: the over-voltage
    // alarm (14) comes at 60 V, during the move.
    let sim = power_on(Endpoint::Tcp("127.0.0.1:0".into()), None, &["3000:supply=70/400"]);
    let link = ["--tcp", sim.endpoint()];
    drivectl(&link, &["move", "--relative", "100000", "--speed", "4000"]);
    std::thread::sleep(std::time::Duration::from_millis(4500));
    // The history's newest entry is the capture's: alarm 14.
    let got =
        String::from_utf8_lossy(&drivectl(&link, &["get", "black-box-fault", "fault-history0"]).stdout).into_owned();
    let values: Vec<&str> = got.lines().filter_map(|l| l.split(" = ").nth(1)).collect();
    assert_eq!(values.len(), 2, "{got}");
    assert_eq!(values[0], values[1], "{got}");
    assert_eq!(values[0].parse::<u32>().expect("number") >> 24, 14, "{got}");
    let csv = dir.path().join("box.csv");
    let out = drivectl(&link, &["blackbox", "--csv", csv.to_str().expect("path")]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(said.contains("the alarm at row 819"), "{said}");
    let (header, rows) = read_csv(&csv);
    let column = |name: &str| header.iter().position(|h| h == name).expect("column");
    let (supply, velocity, faults) = (column("supply-voltage"), column("commanded-velocity"), column("faults"));
    let t = trigger_row(&rows);
    assert_eq!(t, 819);
    // Before the alarm: moving, the supply rising through the last 400 ms; at it, above 60 V and
    // the over-voltage bit (0x2135 bit 0) set.
    assert!(rows[..t].iter().all(|r| r[velocity] == 4000.0));
    let ramp = (t as f64 - 0.4 / 1.25e-3) as usize;
    assert!(rows[ramp - 10][supply] < 24_500.0 && rows[t - 1][supply] > 55_000.0);
    assert!(rows[t][supply] >= 60_000.0);
    assert!(rows[..t].iter().all(|r| r[faults] == 0.0) && (rows[t][faults] as u32) & 1 == 1);
    // Read: the black box records again.
    let got = String::from_utf8_lossy(&drivectl(&link, &["get", "black-box-state"]).stdout).into_owned();
    assert_eq!(got.trim(), "black-box-state = 1");
    sim.off().expect("power off");
}
