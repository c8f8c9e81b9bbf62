//! Puts the chip's memory description on the linker search path for the microcontroller build:
//! the workspace's `memory-g431.x` (STM32G431CB) or, with the `qemu` feature, `memory-l475.x`
//! (QEMU's STM32L475VG). `cortex-m-rt`'s `link.x` includes it as `memory.x`. No file of that
//! name may sit in the workspace root: the linker runs there and would find it first, whatever
//! the chip (the QEMU build once linked with the G431's 32 KiB of RAM and overflowed its stack).

use std::{env, fs, path::PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=../memory-g431.x");
    println!("cargo:rerun-if-changed=../memory-l475.x");
    // embedded-test's macro tests this cfg.
    println!("cargo::rustc-check-cfg=cfg(rust_analyzer)");
    // The host stub links like any host program.
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    let src = if env::var_os("CARGO_FEATURE_QEMU").is_some() { "../memory-l475.x" } else { "../memory-g431.x" };
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy(src, out.join("memory.x")).expect("memory description at the workspace root");
    println!("cargo:rustc-link-search={}", out.display());
    // The HIL suite's harness (embedded-test, a dev-dependency) brings its own linker script.
    println!("cargo:rustc-link-arg-tests=-Tembedded-test.x");
}
