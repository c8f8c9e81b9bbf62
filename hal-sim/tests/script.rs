//! Batch mode (`--script`): the runner on seed 000 §9.4.1, scripts that do not parse, frames that
//! come too close together, and the binary's exit codes.

use std::process::Command;

use drive_core::crc::crc16;
use hal_sim::SimOptions;
use hal_sim::script::{ScriptError, hex, plant, run_script};

/// Seed 000 §9.4.1: 1/32 microsteps, 1000 mA, 32000 pps forward, a relative move of 32000 steps,
/// written half-word by half-word with 0x06, one request every 10 ms.
const SECTION_9_4_1: &str = "\
# Seed 000 §9.4.1, one write every 10 ms (t3.5 is 4.01 ms at 9600 baud).
at 0  01 06 60 0C 00 20   # resolution 1/32
at 10 01 06 60 0D 03 E8   # phase current 1000 mA
at 20 01 06 60 03 00 00   # speed, high word
at 30 01 06 60 04 7D 00   # speed, low word: 32000 pps
at 40 01 06 60 02 00 00   # forward

at 50 01 06 60 05 00 00   # relative move, high word
at 60 01066006 7D00       # relative move, low word: 32000 steps, go
until 10000
";

/// The requests of [`SECTION_9_4_1`], without their CRC, and when they are sent (ms).
const REQUESTS: [(u64, [u8; 6]); 7] = [
    (0, [0x01, 0x06, 0x60, 0x0C, 0x00, 0x20]),
    (10, [0x01, 0x06, 0x60, 0x0D, 0x03, 0xE8]),
    (20, [0x01, 0x06, 0x60, 0x03, 0x00, 0x00]),
    (30, [0x01, 0x06, 0x60, 0x04, 0x7D, 0x00]),
    (40, [0x01, 0x06, 0x60, 0x02, 0x00, 0x00]),
    (50, [0x01, 0x06, 0x60, 0x05, 0x00, 0x00]),
    (60, [0x01, 0x06, 0x60, 0x06, 0x7D, 0x00]),
];

/// Runs `script` on a factory drive and the default motor; the output lines.
fn run(script: &str) -> (Result<hal_sim::script::Summary, ScriptError>, Vec<String>) {
    let mut plant = plant(&SimOptions::default()).expect("plant");
    let mut out = Vec::new();
    let result = run_script(script, &mut plant, &mut out);
    let text = String::from_utf8(out).expect("utf-8");
    (result, text.lines().map(str::to_owned).collect())
}

#[test]
fn section_9_4_1_every_write_echoed_and_the_rotor_on_target() {
    let (result, lines) = run(SECTION_9_4_1);
    let summary = result.expect("runs");
    assert_eq!(lines.len(), REQUESTS.len() + 1, "{lines:#?}");
    // Each write is echoed with its CRC, t3.5 (4.010 ms at 9600 baud) after it arrived.
    for ((at, body), line) in REQUESTS.iter().zip(&lines) {
        let mut echo = body.to_vec();
        echo.extend_from_slice(&crc16(body).to_le_bytes());
        assert_eq!(line, &format!("{}.010 reply {}", at + 4, hex(&echo)));
    }
    assert_eq!(summary.end.as_micros(), 10_000_000);
    assert_eq!(summary.setpoint, 32_000);
    assert!((summary.rotor - 32_000.0).abs() < 3.2, "rotor {}", summary.rotor);
    // The summary line says the same.
    let last = lines.last().expect("summary");
    let words: Vec<&str> = last.split(' ').collect();
    assert_eq!(words[..4], ["end", "10000.000", "setpoint", "32000"], "{last}");
    assert_eq!(words[4], "rotor", "{last}");
    let rotor: f64 = words[5].parse().expect("rotor");
    assert!((rotor - 32_000.0).abs() < 3.2, "{last}");
}

#[test]
fn a_line_that_does_not_parse_is_named_and_nothing_runs() {
    let cases = [
        ("at 0 01 03 600C 0002\nuntil 10\nmove 20\n", 3, "unknown command `move`"),
        ("# comment\n\nat 5 01 03 600C 0002\nat 4 01 03 600C 0002\n", 4, "time goes back"),
        ("at 1 01 03 600C 002\n", 1, "odd number of hex digits"),
        ("at 1 01 03 600C 00GG\n", 1, "not hex"),
        ("at 1\n", 1, "needs the bytes"),
        ("raw 1\n", 1, "`raw` needs the bytes"),
        ("until\n", 1, "needs a time"),
        ("until 1.0005\n", 1, "three decimals"),
        ("until -3\n", 1, "bad time"),
        ("until 10 20\n", 1, "unexpected `20`"),
    ];
    for (script, line_no, what) in cases {
        let (result, lines) = run(script);
        match result {
            Err(ScriptError::Parse { line, message }) => {
                assert_eq!(line, line_no, "{script:?}: {message}");
                assert!(message.contains(what), "{script:?}: {message}");
            }
            other => panic!("{script:?}: {other:?}"),
        }
        assert!(lines.is_empty(), "{script:?}: nothing runs, nothing is printed: {lines:?}");
    }
}

#[test]
fn requests_closer_than_t35_join_into_one_frame_that_gets_no_answer() {
    // §9.4.1 at 1 ms intervals: the requests run together into one 56-byte frame with a bad CRC.
    let script: String = REQUESTS
        .iter()
        .enumerate()
        .map(|(i, (_, body))| format!("at {i} {}\n", hex(body)))
        .chain(["until 1000\n".to_owned()])
        .collect();
    let (result, lines) = run(&script);
    assert_eq!(result.expect("runs").setpoint, 0);
    assert_eq!(lines, ["end 1000.000 setpoint 0 rotor 0.00"]);
}

#[test]
fn a_request_after_the_last_command_is_answered() {
    let (result, lines) = run("at 2.5 01 03 600C 0002\n");
    assert_eq!(result.expect("runs").end.as_micros(), 6_510);
    assert_eq!(lines, ["6.510 reply 01 03 04 00 00 02 92 7A FE", "end 6.510 setpoint 0 rotor 0.00"]);
}

#[test]
fn the_binary_runs_a_script_and_exits() {
    let dir = tempfile::tempdir().expect("tempdir");
    let good = dir.path().join("good.txt");
    let bad = dir.path().join("bad.txt");
    std::fs::write(&good, "at 1 01 03 600C 0002\nuntil 20\n").expect("write");
    std::fs::write(&bad, "until 20\nuntil 10\n").expect("write");
    let trace = dir.path().join("trace.csv");
    let sim = |args: &[&std::ffi::OsStr]| Command::new(env!("CARGO_BIN_EXE_hal-sim")).args(args).output().expect("run");

    let out = sim(&["--script".as_ref(), good.as_os_str(), "--trace".as_ref(), trace.as_os_str()]);
    assert_eq!(out.status.code(), Some(0), "{out:?}");
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        "5.010 reply 01 03 04 00 00 02 92 7A FE\nend 20.000 setpoint 0 rotor 0.00\n"
    );
    // One trace row per 20 ticks (1 ms) and the header.
    let rows = std::fs::read_to_string(&trace).expect("trace").lines().count();
    assert!((20..=23).contains(&rows), "{rows} lines");

    let out = sim(&["--script".as_ref(), bad.as_os_str()]);
    assert_eq!(out.status.code(), Some(1), "{out:?}");
    assert!(out.stdout.is_empty());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("line 2") && err.contains("time goes back"), "{err}");

    let out = sim(&["--script".as_ref(), good.as_os_str(), "--tcp".as_ref(), "127.0.0.1:0".as_ref()]);
    assert_eq!(out.status.code(), Some(2), "--script conflicts with --tcp: {out:?}");
}
