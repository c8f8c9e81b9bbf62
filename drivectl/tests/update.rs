//! `drivectl update` against simulated drives, through the binary as a user runs it: a bus of
//! three drives updated one after the other, each restarting into the new version with its
//! parameters kept; an image that does not confirm itself rolled back at the next reset; every
//! bad image refused with its reason and the running image kept; the transfer's time against the
//! wire's limit at 115 200 baud.

use std::path::Path;
use std::process::{Command, Output};

use drive_core::update::{Board, Header};
use hal_sim::updates::{NO_CONFIRM, sign, test_secret};
use hal_sim::{Endpoint, PowerSwitch, SimOptions, Simulator};

fn power_on(opts: SimOptions) -> PowerSwitch {
    Simulator::bind(opts).expect("bind simulator").power_on()
}

/// Runs the binary with `link` and `args`.
fn drivectl(link: &[&str], args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_drivectl")).args(link).args(args).output().expect("run drivectl")
}

fn text(out: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr))
}

/// `drivectl get NAME` as a number.
fn get(link: &[&str], name: &str) -> i64 {
    let out = drivectl(link, &["get", name]);
    assert!(out.status.success(), "{}", text(&out));
    let s = String::from_utf8_lossy(&out.stdout);
    s.split('=').nth(1).and_then(|v| v.split_whitespace().next()).and_then(|v| v.parse().ok()).expect("a number")
}

/// A program of `n` bytes, not all alike, starting with `head`.
fn program(head: &[u8], n: usize) -> Vec<u8> {
    let mut p: Vec<u8> = head.to_vec();
    p.extend((p.len()..n).map(|i| (i * 31 + i / 997) as u8));
    p
}

const VERSION: u32 = 0x0002_0100;

fn image(board: Board, program: &[u8]) -> Vec<u8> {
    sign(&test_secret(), Header { board, version: VERSION, length: 0, store: 1 }, program)
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> String {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write image");
    path.to_str().expect("path").to_string()
}

const BUILD: i64 = drive_core::ident::VERSION as i64;

#[test]
fn every_drive_of_a_bus_restarts_into_the_new_version_with_its_parameters() {
    let dir = tempfile::tempdir().expect("temp dir");
    let sim = power_on(SimOptions {
        endpoint: Endpoint::Tcp("127.0.0.1:0".into()),
        axes: vec![1, 2, 3],
        ..Default::default()
    });
    let tcp = ["--tcp", sim.endpoint()];
    for a in ["1", "2", "3"] {
        let link = [&tcp[..], &["-a", a]].concat();
        assert_eq!(get(&link, "firmware-version"), BUILD);
        assert!(drivectl(&link, &["set", "start-speed=812"]).status.success());
        assert!(drivectl(&link, &["save"]).status.success());
    }
    let file = write(dir.path(), "new.img", &image(Board::Simulator, &program(b"", 30_001)));
    let out = drivectl(&tcp, &["update", &file, "--all"]);
    let said = text(&out);
    assert!(out.status.success(), "{said}");
    for a in 1..=3 {
        let line = said.lines().find(|l| l.starts_with(&format!("drive {a}: "))).expect("a line a drive");
        assert!(line.contains("installed, restarted: 2.1.0, confirmed"), "{line}");
        assert!(line.contains("sent 30097 bytes"), "{line}");
        let address = a.to_string();
        let link = [&tcp[..], &["-a", &address]].concat();
        assert_eq!(get(&link, "firmware-version"), i64::from(VERSION));
        assert_eq!(get(&link, "start-speed"), 812, "drive {a}: the parameters kept");
    }
    // The identification says which image runs, and that it takes the test key's images.
    let scan = text(&drivectl(&tcp, &["scan", "--to", "3"]));
    assert_eq!(scan.matches("2.1.0 test-key").count(), 3, "{scan}");
}

#[test]
fn an_image_that_does_not_confirm_itself_is_rolled_back_at_the_next_reset() {
    let dir = tempfile::tempdir().expect("temp dir");
    let sim = power_on(SimOptions { endpoint: Endpoint::Tcp("127.0.0.1:0".into()), ..Default::default() });
    let tcp = ["--tcp", sim.endpoint()];
    let file = write(dir.path(), "bad.img", &image(Board::Simulator, &program(NO_CONFIRM, 5000)));
    let out = drivectl(&tcp, &["update", &file]);
    assert!(out.status.success(), "{}", text(&out));
    assert!(text(&out).contains("restarted: 2.1.0, on trial"), "{}", text(&out));
    // It runs, on trial, and never confirms; the next reset goes back.
    assert_eq!(get(&tcp, "firmware-version"), i64::from(VERSION));
    assert_eq!(get(&tcp, "firmware-state"), 1, "on trial");
    assert!(drivectl(&tcp, &["set", "restart=1"]).status.success());
    std::thread::sleep(std::time::Duration::from_millis(300));
    assert_eq!(get(&tcp, "firmware-version"), BUILD, "rolled back");
    assert_eq!(get(&tcp, "firmware-state"), 2, "rolled back");
    // A good image after it goes in and stays.
    let file = write(dir.path(), "good.img", &image(Board::Simulator, &program(b"", 5000)));
    assert!(drivectl(&tcp, &["update", &file]).status.success());
    assert!(drivectl(&tcp, &["set", "restart=1"]).status.success());
    std::thread::sleep(std::time::Duration::from_millis(300));
    assert_eq!(get(&tcp, "firmware-version"), i64::from(VERSION), "confirmed: kept");
    assert_eq!(get(&tcp, "firmware-state"), 0);
}

#[test]
fn every_bad_image_is_refused_with_its_reason_and_the_drive_runs_on() {
    let dir = tempfile::tempdir().expect("temp dir");
    let sim = power_on(SimOptions { endpoint: Endpoint::Tcp("127.0.0.1:0".into()), ..Default::default() });
    let tcp = ["--tcp", sim.endpoint()];
    let good = image(Board::Simulator, &program(b"", 3000));
    let foreign =
        sign(&[9; 32], Header { board: Board::Simulator, version: VERSION, length: 0, store: 1 }, &program(b"", 3000));
    let mut corrupted = good.clone();
    corrupted[2000] ^= 4;
    let mut unsigned = good.clone();
    let n = unsigned.len();
    unsigned[n - 64..].fill(0);
    let cases = [
        ("unsigned", unsigned, "refused (exception 03): its signature"),
        ("foreign key", foreign, "refused (exception 03): its signature"),
        (
            "another board",
            image(Board::G474, &program(b"", 3000)),
            "refused (exception 03): the image is for another board",
        ),
        ("corrupted", corrupted, "refused (exception 03): its signature"),
        ("truncated", good[..2500].to_vec(), "refused (exception 04): fewer bytes than the image's header says"),
        (
            "newer store",
            sign(&test_secret(), Header { board: Board::Simulator, version: VERSION, length: 0, store: 9 }, &[0; 100]),
            "refused (exception 03): the image needs a newer parameter store",
        ),
    ];
    for (name, bytes, why) in cases {
        let file = write(dir.path(), name, &bytes);
        let out = drivectl(&tcp, &["update", &file]);
        let said = text(&out);
        assert!(!out.status.success(), "{name}: {said}");
        assert!(said.contains(&format!("drive 1: failed: {why}")), "{name}: {said}");
        assert_eq!(get(&tcp, "firmware-version"), BUILD, "{name}: the running image stays");
    }
}

#[test]
fn a_192_kib_image_at_115200_baud_takes_within_1_3_times_the_wire() {
    let dir = tempfile::tempdir().expect("temp dir");
    let tty = dir.path().join("tty");
    let opts = SimOptions {
        endpoint: Endpoint::Pty { link: Some(tty.clone()) },
        baud: Some(115_200),
        wire: true,
        ..Default::default()
    };
    let _sim = power_on(opts);
    let port = ["--port", tty.to_str().expect("path"), "--baud", "115200"];
    let file = write(dir.path(), "big.img", &image(Board::Simulator, &program(b"", 192 * 1024)));
    let out = drivectl(&port, &["update", &file]);
    let said = text(&out);
    assert!(out.status.success(), "{said}");
    let ratio: f64 = said
        .split("B/s; ")
        .nth(1)
        .and_then(|s| s.split('x').next())
        .and_then(|s| s.parse().ok())
        .expect("the ratio to the wire");
    eprintln!("{said}");
    assert!(ratio <= 1.3, "{ratio}x the wire: {said}");
}
