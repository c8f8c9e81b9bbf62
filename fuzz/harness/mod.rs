//! The fuzz targets' logic, shared by the libFuzzer binaries (`fuzz_targets/`) and the stable
//! corpus replay (`drive-core/tests/fuzz_corpus.rs`): a path include rather than a crate, because
//! the fuzz crate is a workspace of its own that builds on nightly only.
//!
//! Each target is a `run(data)` that panics when the drive disagrees with the oracle.

pub mod ascii_slave;
pub mod ascii_stream;
pub mod oracle;
pub mod pdu_cls9;
pub mod pdu_ec57;
pub mod pdu_jmc;
pub mod pdu_layout;
pub mod pdu_native;
pub mod pdu_servo;
pub mod rtu_frame;
pub mod rtu_stream;
pub mod update;

/// A target's entry point.
pub type Run = fn(&[u8]);

/// The targets and their entry points, for the replay.
pub const TARGETS: [(&str, Run); 11] = [
    ("rtu_stream", rtu_stream::run),
    ("rtu_frame", rtu_frame::run),
    ("pdu_native", pdu_native::run),
    ("pdu_layout", pdu_layout::run),
    ("pdu_jmc", pdu_jmc::run),
    ("pdu_cls9", pdu_cls9::run),
    ("pdu_ec57", pdu_ec57::run),
    ("pdu_servo", pdu_servo::run),
    ("ascii_stream", ascii_stream::run),
    ("ascii_slave", ascii_slave::run),
    ("update", update::run),
];
