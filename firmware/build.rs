//! Puts the chip's memory description, the workspace's `memory.x` (STM32G474CE, its flash map in
//! `src/flash_map.rs`), on the linker search path for the microcontroller build; `cortex-m-rt`'s
//! `link.x` includes it.
//!
//! The QEMU build (`qemu` feature, QEMU's STM32L475VG) links with the same layout: the linker
//! looks for an included script in its working directory, the workspace root, before the search
//! path, so a second description could not take over anyway. The program's slot (ACTIVE, from
//! 0x08008000) and its 96 KiB of RAM from 0x20000000 lie inside the L475's 1 MiB of flash and
//! its 96 KiB SRAM1, so the emulated build has the board's layout and stack. QEMU has no boot
//! loader: that build alone also links `boot_stub.x`, the image's initial stack pointer and reset
//! vector in the boot loader's first two words, where QEMU starts the core. The G474 build leaves
//! that region to the boot loader (`bootloader/`).

use std::{env, fs, path::PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=../memory.x");
    println!("cargo:rerun-if-changed=src/flash_map.rs");
    println!("cargo:rerun-if-changed=boot_stub.x");
    // embedded-test's macro tests this cfg.
    println!("cargo::rustc-check-cfg=cfg(rust_analyzer)");
    // The host stub links like any host program.
    if env::var("CARGO_CFG_TARGET_OS").as_deref() != Ok("none") {
        return;
    }
    let src = "../memory.x";
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy(src, out.join("memory.x")).expect("memory description at the workspace root");
    println!("cargo:rustc-link-search={}", out.display());
    if env::var_os("CARGO_FEATURE_QEMU").is_some() {
        fs::copy("boot_stub.x", out.join("boot_stub.x")).expect("firmware/boot_stub.x");
        println!("cargo:rustc-link-arg-bins=-Tboot_stub.x");
    }
    // The HIL suite's harness (embedded-test, a dev-dependency) brings its own linker script.
    println!("cargo:rustc-link-arg-tests=-Tembedded-test.x");
}
