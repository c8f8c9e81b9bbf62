//! Replays the fuzz corpora (`fuzz/corpus/<target>/`, and `fuzz/seeds/<target>/` where present)
//! through the fuzz targets' own harness and oracle, on the stable toolchain: the inputs that
//! reached new code, and every crash found, stay covered without libFuzzer or nightly.

#[allow(dead_code)]
#[path = "../../fuzz/harness/mod.rs"]
mod harness;

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::Path;

const FUZZ: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../fuzz");

/// The files of `dir`, sorted; none if it does not exist.
fn files(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut files: Vec<_> = std::fs::read_dir(dir)
        .map(|entries| entries.filter_map(|e| e.ok()).map(|e| e.path()).filter(|p| p.is_file()).collect())
        .unwrap_or_default();
    files.sort();
    files
}

#[test]
fn every_corpus_input_passes_the_oracle() {
    let mut failures = Vec::new();
    for (target, run) in harness::TARGETS {
        let corpus = files(&Path::new(FUZZ).join("corpus").join(target));
        // A missing or empty corpus would pass vacuously.
        assert!(!corpus.is_empty(), "no corpus in fuzz/corpus/{target}");
        let seeds = files(&Path::new(FUZZ).join("seeds").join(target));
        for path in corpus.iter().chain(&seeds) {
            let Ok(data) = std::fs::read(path) else { panic!("cannot read {}", path.display()) };
            if catch_unwind(AssertUnwindSafe(|| run(&data))).is_err() {
                failures.push(path.display().to_string());
            }
        }
        println!("{target}: {} corpus and {} seed inputs", corpus.len(), seeds.len());
    }
    assert!(failures.is_empty(), "inputs that fail the oracle:\n{}", failures.join("\n"));
}
