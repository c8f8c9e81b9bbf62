//! `docs/registers.md` is generated from the object declarations; this test fails when it is stale.
//! `cargo xtask docs` (or `UPDATE_DOCS=1 cargo test -p drive-core --test registers_doc`) rewrites it.

use std::path::Path;

#[test]
fn register_reference_is_current() {
    let mut text = String::new();
    drive_core::od::doc::write_native(&mut text).expect("formatting into a String");
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/registers.md");
    if std::env::var_os("UPDATE_DOCS").is_some() {
        std::fs::write(&path, &text).expect("write docs/registers.md");
    }
    let on_disk = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(on_disk == text, "docs/registers.md is stale: run `cargo xtask docs`");
}

#[test]
fn every_object_is_in_the_reference() {
    let mut text = String::new();
    drive_core::od::doc::write_native(&mut text).expect("formatting into a String");
    for d in drive_core::od::OBJECTS.iter() {
        assert!(text.contains(&format!("| 0x{:04X}", d.addr)), "{} missing", d.name);
    }
    assert!(drive_core::od::OBJECTS.len() >= 90, "seed 000 has about 100 objects");
}

/// `docs/registers-jmc.md`, the JMC map's reference, from its layout.
#[test]
fn jmc_reference_is_current() {
    let mut text = String::new();
    let layout = &drive_core::maps::jmc::LAYOUT;
    drive_core::maps::doc::write_layout(&mut text, layout, &drive_core::maps::jmc::REFERENCE).expect("formatting");
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/registers-jmc.md");
    if std::env::var_os("UPDATE_DOCS").is_some() {
        std::fs::write(&path, &text).expect("write docs/registers-jmc.md");
    }
    let on_disk = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(on_disk == text, "docs/registers-jmc.md is stale: run `cargo xtask docs`");
    for e in layout.entries {
        assert!(text.contains(&format!("| 0x{:04X} |", e.addr)), "0x{:04X} missing", e.addr);
    }
}

/// `docs/registers-cls9.md`, the DS-CLS9 map's reference, from its layout.
#[test]
fn cls9_reference_is_current() {
    let mut text = String::new();
    let layout = &drive_core::maps::cls9::LAYOUT;
    drive_core::maps::doc::write_layout(&mut text, layout, &drive_core::maps::cls9::REFERENCE).expect("formatting");
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/registers-cls9.md");
    if std::env::var_os("UPDATE_DOCS").is_some() {
        std::fs::write(&path, &text).expect("write docs/registers-cls9.md");
    }
    let on_disk = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(on_disk == text, "docs/registers-cls9.md is stale: run `cargo xtask docs`");
    for e in layout.entries {
        let number = if e.addr < 0x2000 { format!("| {:04} |", e.addr) } else { format!("| 0x{:04X} |", e.addr) };
        assert!(text.contains(&number), "{} missing", e.addr);
    }
}
