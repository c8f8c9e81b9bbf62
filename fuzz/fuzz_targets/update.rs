//! libFuzzer entry of `harness::update` (see there; `drive-core/tests/fuzz_corpus.rs` replays the corpus).
#![no_main]

#[allow(dead_code)]
#[path = "../harness/mod.rs"]
mod harness;

libfuzzer_sys::fuzz_target!(|data: &[u8]| harness::update::run(data));
