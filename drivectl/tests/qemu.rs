//! `drivectl` commissions the firmware itself, running on QEMU's emulated STM32L475 (`cargo
//! xtask qemu`): found by a scan, settings by name, a move that ends on its target, a capture
//! of the firmware's own tick by its scope, a dump.
//! Skipped, with a message, when QEMU 10 is not installed (`.ci/install` installs it).

use std::process::{Command, Output};

use drive_tests::qemu::{boot, qemu_10};
use drivectl::Settings;

fn drivectl(at: &str, args: &[&str]) -> String {
    let out: Output =
        Command::new(env!("CARGO_BIN_EXE_drivectl")).args(["--tcp", at]).args(args).output().expect("run drivectl");
    assert!(out.status.success(), "drivectl {args:?}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn drivectl_commissions_the_firmware_under_qemu() {
    if !qemu_10() {
        eprintln!("SKIPPED: qemu-system-arm 10 is not installed (.ci/install installs it from bookworm-backports)");
        return;
    }
    let (_fw, at) = boot();
    let scan = drivectl(&at, &["--timeout", "300", "scan", "--to", "3"]);
    assert!(scan.lines().next().is_some_and(|l| l.contains("native") && l.contains("OpenStep Motion")), "{scan}");
    assert_eq!(scan.lines().count(), 1, "{scan}");

    assert_eq!(drivectl(&at, &["get", "microsteps", "phase-current"]), "microsteps = 0\nphase-current = 658 mA\n");
    drivectl(&at, &["set", "microsteps=16", "command-speed=8000"]);
    assert_eq!(drivectl(&at, &["get", "microsteps"]), "microsteps = 16\n");
    assert_eq!(drivectl(&at, &["move", "3200", "--wait"]), "standing at 3200\n");
    assert!(drivectl(&at, &["status", "--once"]).contains("position             3200 step"));

    // The scope: the firmware's tick records a move; drivectl reads the capture whole.
    let dir = tempfile::tempdir().expect("temp dir");
    let csv = dir.path().join("capture.csv");
    let path = csv.to_str().expect("path");
    drivectl(
        &at,
        &[
            "scope",
            "--signals",
            "commanded-position,commanded-velocity,status",
            "--divider",
            "20",
            "--move",
            "1600",
            "--csv",
            path,
        ],
    );
    let text = std::fs::read_to_string(&csv).expect("the capture");
    let rows: Vec<Vec<f64>> =
        text.lines().skip(1).map(|l| l.split(',').map(|v| v.parse().expect("number")).collect()).collect();
    let t = rows.iter().position(|r| r[0] >= 0.0).expect("the trigger's row");
    // 1638 rows of 5 registers; 10 % of them before the trigger at most (QEMU's tick runs
    // slower than the wall clock drivectl waits by to fill them), the rest after it.
    assert!(t <= 163 && rows.len() - t == 1638 - 163, "{} rows, the trigger's {t}", rows.len());
    assert!(rows[..t].iter().all(|r| r[1] == 3200.0 && r[2] == 0.0), "standing before the trigger");
    assert!((rows[t][3] as u32) & 8 != 0, "busy at the trigger's row");
    // The rows' times are the firmware's clock's (QEMU's tick runs at 1 kHz: 20 ms a row):
    // never more than 8000 steps/s between two, never back.
    let period = rows[1][0] - rows[0][0];
    assert!((period - 0.020).abs() < 0.002, "rows {period} s apart");
    assert!(rows.windows(2).all(|w| (0.0..=8000.0 * (w[1][0] - w[0][0]) + 1.0).contains(&(w[1][1] - w[0][1]))));
    assert_eq!(rows.last().map(|r| r[1]), Some(4800.0), "the move ends within the capture, on its target");

    let dump = Settings::from_toml(&drivectl(&at, &["dump"])).expect("a TOML dump");
    assert_eq!(dump.map, "native");
    assert_eq!(dump.settings.get("microsteps"), Some(&16));
    assert_eq!(dump.settings.get("command-speed"), Some(&8000));
}
