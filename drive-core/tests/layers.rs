//! The layering of drive-core's modules, read from their sources: every top-level part imports
//! exactly what its row of `docs/architecture.md` says, the parts import each other in no circle,
//! the files of a part's directory neither, and the tick side names no object of the dictionary.
//!
//! An import is a path in code (comments are not read) that starts at `crate::` or `super::`,
//! `use` trees included; `super::` is resolved from the file and the inline module it stands in,
//! and a name the crate root re-exports counts as the module it comes from.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const SRC: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/src");

/// Each top-level part and the parts it imports: the imports column of `docs/architecture.md`.
const ALLOWED: [(&str, &[&str]); 23] = [
    ("units", &[]),
    ("math", &[]),
    ("current", &[]),
    ("autotune", &["current"]),
    ("crc", &[]),
    ("rtu", &["crc", "units"]),
    ("ascii", &["units"]),
    ("pdu", &[]),
    ("modes", &[]),
    ("power", &[]),
    ("ident", &[]),
    ("motion", &["math", "units"]),
    ("od", &["ident", "modes", "power", "scope", "units"]),
    ("servo", &["math", "units"]),
    ("scope", &[]),
    ("update", &[]),
    ("faults", &["units"]),
    ("controller", &["faults", "modes", "motion", "scope", "servo", "units"]),
    ("windings", &["autotune", "controller", "current", "motion"]),
    (
        "state",
        &[
            "controller",
            "faults",
            "ident",
            "math",
            "modes",
            "motion",
            "od",
            "pdu",
            "power",
            "scope",
            "servo",
            "units",
            "update",
        ],
    ),
    ("maps", &["crc", "ident", "od", "pdu", "scope", "state", "units"]),
    (
        "drive",
        &[
            "ascii",
            "controller",
            "crc",
            "faults",
            "ident",
            "maps",
            "modes",
            "od",
            "pdu",
            "rtu",
            "state",
            "units",
            "update",
        ],
    ),
    ("store", &["crc", "drive", "faults", "maps", "od", "state", "units"]),
];

/// The parts the control tick runs: they name no object of the dictionary (`Obj`).
const TICK_SIDE: [&str; 6] = ["controller", "faults", "servo", "motion", "scope", "windings"];

/// The source files of the top-level module `module`: its file, or every file of its directory.
fn files(module: &str) -> Vec<PathBuf> {
    let dir = Path::new(SRC).join(module);
    let mut files: Vec<_> = match std::fs::read_dir(&dir) {
        Ok(d) => {
            d.filter_map(|e| e.ok()).map(|e| e.path()).filter(|p| p.extension().is_some_and(|e| e == "rs")).collect()
        }
        Err(_) => vec![Path::new(SRC).join(format!("{module}.rs"))],
    };
    files.sort();
    assert!(!files.is_empty(), "no sources for {module}");
    files
}

/// The module path of a file: `maps/layout.rs` is `["maps", "layout"]`, `maps/mod.rs` `["maps"]`.
fn module_of(file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(SRC).unwrap_or(file);
    let mut path: Vec<String> = rel.iter().map(|s| s.to_string_lossy().trim_end_matches(".rs").to_string()).collect();
    if path.last().is_some_and(|l| l == "mod" || l == "lib") {
        path.pop();
    }
    path
}

/// `text` without its comments (line and block, doc comments included), each replaced by
/// blanks so that offsets keep their place.
fn code(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = b.to_vec();
    let (mut i, mut in_str) = (0, false);
    while i < b.len() {
        match (b[i], b.get(i + 1)) {
            (b'\\', _) if in_str => i += 1,
            (b'"', _) => in_str = !in_str,
            (b'/', Some(b'/')) if !in_str => {
                while i < b.len() && b[i] != b'\n' {
                    out[i] = b' ';
                    i += 1;
                }
                continue;
            }
            (b'/', Some(b'*')) if !in_str => {
                while i < b.len() && !(b[i] == b'*' && b.get(i + 1) == Some(&b'/')) {
                    out[i] = if b[i] == b'\n' { b'\n' } else { b' ' };
                    i += 1;
                }
                out[i..(i + 2).min(b.len())].fill(b' ');
                i += 2;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The inline modules of `code` (`mod tests { .. }`): each one's name and the span of its body.
fn inline_modules(code: &str) -> Vec<(String, std::ops::Range<usize>)> {
    let mut out = Vec::new();
    let b = code.as_bytes();
    for (at, _) in code.match_indices("mod ") {
        if at > 0 && (b[at - 1].is_ascii_alphanumeric() || b[at - 1] == b'_') {
            continue;
        }
        let rest = &code[at + 4..];
        let name: String = rest.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
        let after = rest[name.len()..].trim_start();
        if name.is_empty() || !after.starts_with('{') {
            continue;
        }
        let open = code.len() - after.len();
        let mut depth = 0;
        for (k, c) in code[open..].char_indices() {
            match c {
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        out.push((name, open..open + k));
                        break;
                    }
                }
                _ => {}
            }
        }
    }
    out
}

/// The paths a path expression or `use` tree starting at `s` names, each as its segments
/// (`{a, b::c}` gives `[a]` and `[b, c]`; `self` in a tree is its prefix).
fn tree(s: &str) -> Vec<Vec<String>> {
    let s = s.trim_start();
    if let Some(inner) = s.strip_prefix('{') {
        let (mut depth, mut start, mut out) = (0, 0, Vec::new());
        for (k, c) in inner.char_indices() {
            match c {
                '{' => depth += 1,
                '}' if depth == 0 => {
                    out.extend(tree(&inner[start..k]));
                    return out;
                }
                '}' => depth -= 1,
                ',' if depth == 0 => {
                    out.extend(tree(&inner[start..k]));
                    start = k + 1;
                }
                _ => {}
            }
        }
        return out;
    }
    let name: String = s.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
    if name.is_empty() {
        return vec![];
    }
    match s[name.len()..].trim_start().strip_prefix("::") {
        Some(rest) => tree(rest)
            .into_iter()
            .map(|mut p| {
                if p.first().is_none_or(|f| f != "self") {
                    p.insert(0, name.clone());
                } else {
                    p[0] = name.clone();
                }
                p
            })
            .chain(tree(rest).is_empty().then(|| vec![name.clone()]))
            .collect(),
        None => vec![vec![name]],
    }
}

/// The names the crate root re-exports (`pub use state::{DriveState, ..}`), and their modules.
fn reexports() -> BTreeMap<String, String> {
    let lib = code(&std::fs::read_to_string(Path::new(SRC).join("lib.rs")).unwrap_or_default());
    let mut out = BTreeMap::new();
    for (at, _) in lib.match_indices("pub use ") {
        for path in tree(&lib[at + "pub use ".len()..]) {
            if let (Some(module), Some(name)) = (path.first(), path.last()) {
                out.insert(name.clone(), module.clone());
            }
        }
    }
    out
}

/// Every path of `file`'s code that starts at `crate::` or `super::`, made absolute (from the
/// crate root), with root re-exports resolved to their modules.
fn absolute_paths(file: &Path) -> Vec<Vec<String>> {
    let text = std::fs::read_to_string(file).unwrap_or_else(|e| panic!("cannot read {}: {e}", file.display()));
    let code = code(&text);
    let inline = inline_modules(&code);
    let here = module_of(file);
    let roots = reexports();
    let mut out = Vec::new();
    let b = code.as_bytes();
    for start in ["crate::", "super::"] {
        for (at, _) in code.match_indices(start) {
            if at > 0 && (b[at - 1].is_ascii_alphanumeric() || b[at - 1] == b'_' || b[at - 1] == b':') {
                continue;
            }
            // The module the path stands in: the file's, and the inline modules around it.
            let mut base = here.clone();
            base.extend(inline.iter().filter(|(_, span)| span.contains(&at)).map(|(n, _)| n.clone()));
            if start == "crate::" {
                base.clear();
            } else {
                base.pop();
            }
            for path in tree(&code[at + start.len()..]) {
                let mut abs = base.clone();
                let mut segs = path.into_iter().peekable();
                while segs.peek().is_some_and(|s| s == "super") {
                    segs.next();
                    abs.pop();
                }
                abs.extend(segs);
                if let Some(module) = abs.first().and_then(|f| roots.get(f)) {
                    abs.insert(0, module.clone());
                }
                out.push(abs);
            }
        }
    }
    out
}

/// The top-level modules `module`'s files import (itself left out).
fn imports(module: &str) -> BTreeSet<String> {
    let mut out: BTreeSet<String> =
        files(module).iter().flat_map(|f| absolute_paths(f)).filter_map(|p| p.first().cloned()).collect();
    out.remove(module);
    out
}

/// The files of the directory module `dir` but its `mod.rs` (the module's root, as `lib.rs` is
/// the crate's), each with the sibling files it imports.
fn sibling_imports(dir: &str) -> BTreeMap<String, BTreeSet<String>> {
    let all = files(dir);
    let names: BTreeSet<String> = all.iter().filter_map(|f| module_of(f).get(1).cloned()).collect();
    all.iter()
        .filter_map(|f| {
            let me = module_of(f).get(1)?.clone();
            let deps = absolute_paths(f)
                .into_iter()
                .filter(|p| p.first().is_some_and(|m| m == dir))
                .filter_map(|p| p.get(1).cloned())
                .filter(|s| names.contains(s) && *s != me)
                .collect();
            Some((me, deps))
        })
        .collect()
}

/// The circles of `graph`: each set of nodes that reach each other through their imports (its
/// strongly connected components of more than one node).
fn circles(graph: &BTreeMap<String, BTreeSet<String>>) -> Vec<BTreeSet<String>> {
    let reach = |from: &String| {
        let mut seen = BTreeSet::new();
        let mut todo = vec![from.clone()];
        while let Some(m) = todo.pop() {
            for d in graph.get(&m).into_iter().flatten() {
                if seen.insert(d.clone()) {
                    todo.push(d.clone());
                }
            }
        }
        seen
    };
    let reached: BTreeMap<&String, BTreeSet<String>> = graph.keys().map(|m| (m, reach(m))).collect();
    let mut out: Vec<BTreeSet<String>> = Vec::new();
    for (m, r) in &reached {
        let circle: BTreeSet<String> =
            r.iter().filter(|d| reached.get(d).is_some_and(|back| back.contains(*m))).cloned().collect();
        if circle.len() > 1 && !out.contains(&circle) {
            out.push(circle);
        }
    }
    out
}

#[test]
fn every_part_imports_what_its_row_says() {
    for (module, allowed) in ALLOWED {
        let got = imports(module);
        let allowed: BTreeSet<String> = allowed.iter().map(|s| s.to_string()).collect();
        let extra: Vec<_> = got.difference(&allowed).collect();
        let unused: Vec<_> = allowed.difference(&got).collect();
        assert!(extra.is_empty(), "{module} imports {extra:?}, which it may not (it may import {allowed:?})");
        assert!(unused.is_empty(), "{module} no longer imports {unused:?}: drop it from ALLOWED and the doc's table");
    }
}

#[test]
fn no_parts_import_each_other_in_a_circle() {
    let graph: BTreeMap<String, BTreeSet<String>> = ALLOWED
        .iter()
        .map(|(m, _)| (m.to_string(), imports(m).into_iter().filter(|d| !d.is_empty()).collect()))
        .collect();
    let left = circles(&graph);
    assert!(left.is_empty(), "these parts import each other in a circle: {left:?}");
}

#[test]
fn no_files_of_a_part_import_each_other_in_a_circle() {
    let found: Vec<_> = ["controller", "maps", "motion", "od", "state"]
        .into_iter()
        .map(|dir| (dir, circles(&sibling_imports(dir))))
        .filter(|(_, c)| !c.is_empty())
        .collect();
    assert!(found.is_empty(), "files of a directory import each other in a circle: {found:?}");
}

#[test]
fn the_tick_side_names_no_object() {
    for module in TICK_SIDE {
        for f in files(module) {
            let code = code(&std::fs::read_to_string(&f).unwrap_or_default());
            let named = code.match_indices("Obj").any(|(at, _)| {
                let b = code.as_bytes();
                let before = at.checked_sub(1).map(|k| b[k]);
                let after = b.get(at + 3).copied();
                !before.is_some_and(|c| c.is_ascii_alphanumeric() || c == b'_')
                    && !after.is_some_and(|c| c.is_ascii_alphanumeric() || c == b'_')
            });
            assert!(!named, "{} names `Obj`", f.display());
        }
    }
}

#[test]
fn every_module_is_in_the_list() {
    for e in std::fs::read_dir(SRC).unwrap().filter_map(|e| e.ok()) {
        let name = e.file_name().to_string_lossy().trim_end_matches(".rs").to_string();
        if name != "lib" {
            assert!(ALLOWED.iter().any(|(m, _)| *m == name), "{name} is not in ALLOWED");
        }
    }
}

#[test]
fn the_architecture_table_says_what_the_test_asserts() {
    let doc = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/architecture.md")).unwrap();
    let mut rows = BTreeMap::new();
    for line in doc.lines().filter(|l| l.starts_with("| ") && !l.starts_with("| part") && !l.starts_with("|--")) {
        let cells: Vec<&str> = line.trim_matches('|').split(" | ").map(str::trim).collect();
        let (Some(module), Some(imports)) = (cells.get(1), cells.last()) else { continue };
        let ticked = |s: &str| -> Vec<String> { s.split('`').skip(1).step_by(2).map(str::to_string).collect() };
        let Some(first) = ticked(module).into_iter().next() else { continue };
        let name: String = first.chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_').collect();
        let imports: BTreeSet<String> = ticked(imports).into_iter().collect();
        rows.insert(name, imports);
    }
    for (module, allowed) in ALLOWED {
        let allowed: BTreeSet<String> = allowed.iter().map(|s| s.to_string()).collect();
        assert_eq!(rows.get(module), Some(&allowed), "docs/architecture.md's row for {module}");
    }
}

#[test]
fn the_reader_sees_imports() {
    // The check is only as good as its reader: these imports exist.
    assert!(imports("rtu").contains("crc"));
    assert!(imports("state").contains("motion"));
    assert!(sibling_imports("maps").get("layout").is_some_and(|d| d.contains("native")));
    assert!(sibling_imports("motion").get("axis").is_some_and(|d| d.contains("cubic")));
    // Trees, `self`, `super::` out of an inline module, root re-exports and comments.
    assert_eq!(tree("{a, b::{self, c}}"), [vec!["a"], vec!["b"], vec!["b", "c"]]);
    assert_eq!(tree("x::y;"), [vec!["x", "y"]]);
    let stripped = code("a // crate::x\nb /* super::y */ c \"// no\"");
    assert!(!stripped.contains("crate") && !stripped.contains("super") && stripped.contains("c \"// no\""));
    assert_eq!(stripped.len(), 40);
    assert_eq!(reexports().get("Drive").map(String::as_str), Some("drive"));
    let inline = inline_modules("fn f() {}\nmod tests { use super::*; fn g() { {} } }\n");
    assert_eq!(inline.iter().map(|(n, _)| n.as_str()).collect::<Vec<_>>(), ["tests"]);
    // A circle is found, not what only leads into one.
    let graph: BTreeMap<String, BTreeSet<String>> =
        [("a", vec!["b"]), ("b", vec!["a"]), ("c", vec!["a"]), ("d", vec![])]
            .into_iter()
            .map(|(m, d)| (m.to_string(), d.into_iter().map(str::to_string).collect()))
            .collect();
    assert_eq!(circles(&graph), [BTreeSet::from(["a".to_string(), "b".to_string()])]);
}
