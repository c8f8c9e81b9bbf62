//! `drivectl` commissions the firmware itself, running on QEMU's emulated STM32L475 (`cargo
//! xtask qemu`): found by a scan, settings by name, a move that ends on its target, a dump.
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

    let dump = Settings::from_toml(&drivectl(&at, &["dump"])).expect("a TOML dump");
    assert_eq!(dump.map, "native");
    assert_eq!(dump.settings.get("microsteps"), Some(&16));
    assert_eq!(dump.settings.get("command-speed"), Some(&8000));
}
