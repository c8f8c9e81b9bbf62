//! The layering of drive-core's modules, read from their sources: the lower layers import
//! nothing from the layers above them (motion knows nothing of registers or of the control loop).

use std::collections::BTreeSet;
use std::path::Path;

const SRC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/src");

/// The top-level modules a module's files name through `crate::`, `use crate::{..}` included
/// (re-exports at the crate root count as the root, "").
fn imports(module: &str) -> BTreeSet<String> {
    let dir = Path::new(SRC).join(module);
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .map(|d| d.filter_map(|e| e.ok()).map(|e| e.path()).collect())
        .unwrap_or_else(|_| vec![Path::new(SRC).join(format!("{module}.rs"))]);
    files.retain(|p| p.extension().is_some_and(|e| e == "rs"));
    assert!(!files.is_empty(), "no sources for {module}");
    let mut out = BTreeSet::new();
    for f in files {
        let Ok(text) = std::fs::read_to_string(&f) else { panic!("cannot read {}", f.display()) };
        for (i, _) in text.match_indices("crate::") {
            let rest = &text[i + "crate::".len()..];
            let name: String = rest.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
            let first = name.chars().next();
            // `crate::Drive` (a root re-export) or `crate::{..}` names the root.
            out.insert(if first.is_some_and(|c| c.is_ascii_lowercase()) { name } else { String::new() });
        }
    }
    out.remove(module);
    out
}

fn assert_only(module: &str, allowed: &[&str]) {
    let got = imports(module);
    let extra: Vec<_> = got.iter().filter(|m| !allowed.contains(&m.as_str())).collect();
    assert!(extra.is_empty(), "{module} imports {extra:?} (it may import {allowed:?})");
}

#[test]
fn the_lower_layers_import_nothing_from_above() {
    // Leaves: units, FPU arithmetic, checksums, the PDU's types, identification, modes, the power states.
    for leaf in ["units", "math", "crc", "pdu", "ident", "modes", "power"] {
        assert_only(leaf, &[]);
    }
    assert_only("rtu", &["crc", "units"]);
    assert_only("motion", &["math", "units"]);
    // The store persists what the faults part keeps, not the other way round.
    assert!(!imports("faults").contains("store"), "faults imports the store");
    // The closed loop's and supervision's data know nothing of the drive or its dictionary
    // (faults names the history objects), and the controller the tick owns nothing of the bus
    // side: no dictionary, no maps, no planning of modes.
    assert_only("servo", &["math", "units"]);
    assert_only("faults", &["od", "units"]);
    assert_only("controller", &["faults", "math", "modes", "motion", "servo", "units"]);
}

/// Every top-level module of drive-core.
const MODULES: [&str; 18] = [
    "units",
    "math",
    "crc",
    "pdu",
    "ident",
    "modes",
    "power",
    "rtu",
    "motion",
    "od",
    "servo",
    "faults",
    "controller",
    "state",
    "maps",
    "drive",
    "store",
    "",
];

#[test]
fn no_module_imports_one_that_imports_it_back() {
    // Imports form no cycle: the modules can be ordered so that each imports only earlier ones.
    let graph: Vec<(&str, BTreeSet<String>)> =
        MODULES.iter().filter(|m| !m.is_empty()).map(|&m| (m, imports(m))).collect();
    let mut placed: BTreeSet<String> = BTreeSet::from([String::new()]);
    while placed.len() < graph.len() + 1 {
        let next: Vec<&str> = graph
            .iter()
            .filter(|(m, deps)| !placed.contains(*m) && deps.iter().all(|d| placed.contains(d)))
            .map(|(m, _)| *m)
            .collect();
        let left: Vec<_> = graph.iter().filter(|(m, _)| !placed.contains(*m)).collect();
        assert!(!next.is_empty(), "these modules import each other in a cycle: {left:?}");
        placed.extend(next.iter().map(|m| m.to_string()));
    }
}

#[test]
fn every_module_is_in_the_list() {
    for e in std::fs::read_dir(SRC).unwrap().filter_map(|e| e.ok()) {
        let name = e.file_name().to_string_lossy().trim_end_matches(".rs").to_string();
        if name != "lib" {
            assert!(MODULES.contains(&name.as_str()), "{name} is not in MODULES");
        }
    }
}

#[test]
fn the_reader_sees_imports() {
    // The check is only as good as its reader: these imports exist.
    assert!(imports("rtu").contains("crc"));
    assert!(imports("state").contains("motion"));
}
