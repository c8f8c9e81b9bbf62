//! The boot loader's memory description, `memory.x` in this directory, on the linker's search
//! path (the linker, run from this workspace's root, finds it in its working directory first
//! anyway), and a rebuild when it or the flash map changes.

use std::{env, fs, path::PathBuf};

fn main() {
    println!("cargo:rerun-if-changed=memory.x");
    println!("cargo:rerun-if-changed=../firmware/src/flash_map.rs");
    let out = PathBuf::from(env::var_os("OUT_DIR").expect("cargo sets OUT_DIR"));
    fs::copy("memory.x", out.join("memory.x")).expect("bootloader/memory.x");
    println!("cargo:rustc-link-search={}", out.display());
}
