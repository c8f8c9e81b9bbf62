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

/// The firmware takes an image over the bus under QEMU: sent in 0x15 records into its DFU slot
/// (RAM here: QEMU has no flash controller), checked by the Cortex-M4 as it arrives, a corrupted
/// one refused with its reason, installed on order: checked once more and marked for the boot
/// loader, which QEMU lacks, so the drive restarts and says an update is marked.
#[test]
fn the_firmware_takes_a_signed_image_under_qemu() {
    use drive_core::update::{Board, Header};
    use hal_sim::updates::{sign, test_secret};
    if !qemu_10() {
        eprintln!("SKIPPED: qemu-system-arm 10 is not installed (.ci/install installs it from bookworm-backports)");
        return;
    }
    let (_fw, at) = boot();
    let dir = tempfile::tempdir().expect("temp dir");
    let header = Header { board: Board::Qemu, version: 0x0002_0300, length: 0, store: 1 };
    let program: Vec<u8> = (0..6000u32).map(|i| (i * 7 + i / 255) as u8).collect();
    let image = sign(&test_secret(), header, &program);
    let mut corrupted = image.clone();
    corrupted[3000] ^= 0x40;
    let write = |name: &str, bytes: &[u8]| {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).expect("image");
        path.to_str().expect("path").to_string()
    };
    let (good, bad) = (write("good.img", &image), write("bad.img", &corrupted));
    assert!(drivectl(&at, &["get", "firmware-key"]).contains("= 1"), "a build with the test key");
    let run = |args: &[&str]| {
        Command::new(env!("CARGO_BIN_EXE_drivectl")).args(["--tcp", &at]).args(args).output().expect("drivectl")
    };
    let refused = run(&["update", &bad, "--no-install"]);
    let said = String::from_utf8_lossy(&refused.stdout).into_owned();
    assert!(!refused.status.success() && said.contains("refused (exception 03): its signature"), "{said}");
    let sent = drivectl(&at, &["update", &good, "--no-install"]);
    assert!(sent.contains("sent 6096 bytes") && sent.contains("checked"), "{sent}");
    assert_eq!(
        drivectl(&at, &["get", "update-state", "update-version"]),
        "update-state = 3\nupdate-version = 131840\n"
    );
    // Installed: the drive restarts (QEMU resets the chip) and answers again, the update marked.
    let _ = run(&["set", "update-control=2"]);
    let mut state = String::new();
    for _ in 0..50 {
        std::thread::sleep(std::time::Duration::from_millis(200));
        let out = run(&["--timeout", "300", "get", "firmware-state", "update-state"]);
        state = String::from_utf8_lossy(&out.stdout).into_owned();
        if out.status.success() {
            break;
        }
    }
    assert_eq!(state, "firmware-state = 3\nupdate-state = 0\n", "marked, and the transfer gone with the restart");
}
