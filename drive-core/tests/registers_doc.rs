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

/// `docs/NAME`, a map's reference generated from its layout, is current (rewritten with
/// `UPDATE_DOCS`), and shows each entry's register as `number` writes it.
fn check_map_reference(
    name: &str,
    layout: &drive_core::maps::layout::Layout,
    reference: &drive_core::maps::doc::Reference,
    number: fn(u16) -> String,
) {
    let mut text = String::new();
    drive_core::maps::doc::write_layout(&mut text, layout, reference).expect("formatting");
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs").join(name);
    if std::env::var_os("UPDATE_DOCS").is_some() {
        std::fs::write(&path, &text).unwrap_or_else(|e| panic!("write docs/{name}: {e}"));
    }
    let on_disk = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(on_disk == text, "docs/{name} is stale: run `cargo xtask docs`");
    for e in layout.entries {
        assert!(text.contains(&format!("| {} |", number(e.addr))), "{} missing", number(e.addr));
    }
}

/// `docs/registers-jmc.md`, the JMC map's reference.
#[test]
fn jmc_reference_is_current() {
    use drive_core::maps::jmc;
    check_map_reference("registers-jmc.md", &jmc::LAYOUT, &jmc::REFERENCE, |a| format!("0x{a:04X}"));
}

/// `docs/registers-cls9.md`, the DS-CLS9 map's reference: decimal register numbers below 0x2000.
#[test]
fn cls9_reference_is_current() {
    use drive_core::maps::cls9;
    check_map_reference("registers-cls9.md", &cls9::LAYOUT, &cls9::REFERENCE, |a| {
        if a < 0x2000 { format!("{a:04}") } else { format!("0x{a:04X}") }
    });
}

/// `docs/registers-ec57.md`, the EC-57 map's reference: registers as index and sub-index.
#[test]
fn ec57_reference_is_current() {
    use drive_core::maps::ec57;
    check_map_reference("registers-ec57.md", &ec57::LAYOUT, &ec57::REFERENCE, |a| {
        let (index, sub) = ec57::index_of(a);
        format!("0x{index:04X}.{sub}")
    });
}

/// `docs/registers-servo.md`, the servo map's reference.
#[test]
fn servo_reference_is_current() {
    use drive_core::maps::servo;
    check_map_reference("registers-servo.md", &servo::LAYOUT, &servo::REFERENCE, |a| format!("0x{a:04X}"));
}
