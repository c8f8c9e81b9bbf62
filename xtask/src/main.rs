//! `cargo xtask <task>`: the one place that orchestrates checks, the firmware build and the
//! external Modbus masters.
//!
//! - `ci`: everything CI runs (format, lints, host tests, firmware build and size, real masters).
//! - `docs`: regenerate the register references from the declarations and the board doc's pin and
//!   flash tables from the firmware's.
//! - `masters`: run pymodbus and mbpoll against the simulator (native and DS-CLS9 maps).
//! - `firmware`: cross-build the firmware, print its size and its stack by the call graph against
//!   the budgets, fail if it does not fit the chip or if the tick reaches software floating
//!   point; then the boot loader (`bootloader/`), its size against its region.
//! - `qemu --tcp HOST:PORT [--map NAME]`: build the QEMU variant and run it with its USART on that
//!   port (switched to map NAME as a master would: 0x2190, a save, a reset), and QEMU's monitor on
//!   the port it prints second (`system_reset` restarts the chip, its store kept).
//! - `hil`: build the hardware-in-the-loop suite (`probe-rs` runs it on a board).
//! - `tick-cost`: the control tick's instruction count under QEMU (`-icount`): the firmware's, and
//!   the drive core's alone with the closed loops and the stall detection (CI runs the latter).

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

const TARGET: &str = "thumbv7em-none-eabihf";
/// The flash budget of the G474 image with every map: at most 192 KiB, so that it fits its
/// 224 KiB slot (ACTIVE, `firmware/src/flash_map.rs`) with room for what comes. `firmware` fails
/// over it.
const FLASH_BUDGET: u64 = 192 * 1024;
/// The RAM budget: the statics plus the stack's peak, as `tick-cost` measures it (it fails over
/// it), 96 KiB of the G474's SRAM1 and SRAM2 (`memory.x`).
const RAM_BUDGET: u64 = 96 * 1024;
/// The control work of a 20 kHz period (the current loop and the tick), instructions: a mean of
/// 30 % of the period at 170 MHz in every case, and half the period in any one. `tick-cost` (and
/// so CI) fails over it.
const TICK_MEAN_BUDGET: f64 = 2550.0;
/// See [`TICK_MEAN_BUDGET`].
const TICK_MOST_BUDGET: f64 = 4250.0;
/// What the program's slot and the linker's RAM hold (`memory.x`): ACTIVE, 224 KiB, and 96 KiB.
/// Over these the build cannot link or run.
const FLASH_CAPACITY: u64 = 224 * 1024;
const RAM_CAPACITY: u64 = 96 * 1024;
/// Free stack the measured peak must leave on the G474 (`tick-cost` fails otherwise): the QEMU
/// build's tasks are not the board's, and a measurement samples where interrupts land.
const STACK_MARGIN: u64 = 1024;
/// The QEMU build's parameter store: the L475's SRAM2, behaving as flash (`firmware/src/board/qemu.rs`).
const QEMU_STORE_RAM: u64 = 0x1000_0000;
/// Its size in words (16 KiB, as the G474's PARAMS region).
const QEMU_STORE_WORDS: usize = 16 * 1024 / 4;
/// The end of the G474's RAM: flip-link puts the statics below it and the stack below them.
const RAM_END: u64 = 0x2000_0000 + RAM_CAPACITY;
/// Where the program's slot starts (ACTIVE, behind the boot loader): QEMU starts the core there.
const ACTIVE_START: u64 = 0x0800_8000;
/// The start of flash: the boot loader's region (BOOTLOADER, `firmware/src/flash_map.rs`), up to
/// ACTIVE, where the core starts.
const BOOTLOADER_START: u64 = 0x0800_0000;
/// The boot loader's region, 32 KiB: `firmware` fails if the boot loader does not fit it.
const BOOTLOADER_CAPACITY: u64 = ACTIVE_START - BOOTLOADER_START;

fn main() -> ExitCode {
    let task = std::env::args().nth(1).unwrap_or_default();
    let result = match task.as_str() {
        "ci" => ci(),
        "docs" => {
            run(cargo().args(["test", "-q", "-p", "drive-core", "--test", "registers_doc"]).env("UPDATE_DOCS", "1"))
                .and_then(|()| {
                    run(cargo().args(["test", "-q", "-p", "drive-tests", "--test", "board"]).env("UPDATE_DOCS", "1"))
                })
        }
        "masters" => masters(),
        "firmware" => firmware(),
        "qemu" => qemu(&std::env::args().skip(2).collect::<Vec<_>>()),
        "hil" => hil(),
        "tick-cost" => tick_cost().and_then(|()| core_tick_cost()),
        "keygen" => keygen(&std::env::args().skip(2).collect::<Vec<_>>()),
        "sign" => sign(&std::env::args().skip(2).collect::<Vec<_>>()),
        "image" => image(&std::env::args().skip(2).collect::<Vec<_>>()),
        // The soak in release (the simulator runs ~30x faster than in a debug build).
        "soak" => run(cargo()
            .args(["run", "--release", "-q", "-p", "hal-sim", "--bin", "soak", "--"])
            .args(std::env::args().skip(2))),
        _ => Err(format!(
            "usage: cargo xtask <ci|docs|masters|firmware|qemu --tcp HOST:PORT|hil|tick-cost|soak [--seed S --hours H --minutes M --axes N --trace]|keygen PREFIX|sign --key FILE --board g474|qemu|sim --version X.Y.Z [--store N] PROGRAM IMAGE|image --key FILE --version X.Y.Z [IMAGE]>, not {task:?}"
        )),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask {task}: {e}");
            ExitCode::FAILURE
        }
    }
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().map(Path::to_path_buf).unwrap_or_default()
}

fn cargo() -> Command {
    let mut c = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    c.current_dir(root());
    c
}

fn run(cmd: &mut Command) -> Result<(), String> {
    eprintln!("$ {cmd:?}");
    let status = cmd.status().map_err(|e| format!("{cmd:?}: {e}"))?;
    if status.success() { Ok(()) } else { Err(format!("{cmd:?} failed: {status}")) }
}

fn step(name: &str) {
    eprintln!("\n=== {name} ===");
}

fn ci() -> Result<(), String> {
    step("rustfmt");
    run(cargo().args(["fmt", "--all", "--check"]))?;
    // The boot loader is a workspace of its own.
    run(cargo().current_dir(root().join("bootloader")).args(["fmt", "--check"]))?;
    step("clippy (host)");
    run(cargo().args(["clippy", "--workspace", "--all-targets", "--", "-D", "warnings"]))?;
    step("rustdoc (host): every doc link resolves and names a public item");
    run(cargo().args(["doc", "--no-deps"]).env("RUSTDOCFLAGS", "-D warnings"))?;
    step("clippy (firmware)");
    // The G474 binary and its HIL suite.
    run(cargo().args(firmware_args("clippy", &["--bin", "firmware", "--test", "hil"])).args(["--", "-D", "warnings"]))?;
    // The boot loader, a workspace of its own, in the target directory its build uses.
    run(cargo()
        .current_dir(root().join("bootloader"))
        .args(["clippy", "--release", "--target", TARGET, "--target-dir"])
        .arg(bootloader_target())
        .args(["--", "-D", "warnings"]))?;
    // drive-tests' `qemu` test boots the firmware under QEMU (`cargo xtask qemu`) for tokio-modbus.
    step("tests (host, including the register reference, tokio-modbus and the firmware under QEMU)");
    // The default members: the firmware is cross-built below; on the host only its framing by
    // length (QEMU's) has tests.
    run(cargo().arg("test"))?;
    run(cargo().args(["test", "-p", "firmware", "--bins"]))?;
    step("firmware build and size");
    firmware()?;
    step("`cargo run --release` from firmware/, up to the probe (the runner here prints the image's sections)");
    run(cargo()
        .current_dir(root().join("firmware"))
        .args(["run", "--release"])
        .env("CARGO_TARGET_THUMBV7EM_NONE_EABIHF_RUNNER", "arm-none-eabi-size"))?;
    step("QEMU firmware build and clippy (with the tick-cost program)");
    run(cargo()
        .args(firmware_args("clippy", &["--no-default-features", "--features", "tick-cost", "--bins"]))
        .args(["--", "-D", "warnings"]))?;
    step("control tick cost on the Cortex-M4 (QEMU)");
    core_tick_cost()?;
    step("the firmware's tick under QEMU: cost, and the handover of plans while the bus task plans re-targets");
    tick_cost()?;
    step("HIL suite build");
    hil()?;
    step("external masters");
    masters()
}

/// `cargo <verb> -p firmware` for the microcontroller, with `extra` arguments.
fn firmware_args<'a>(verb: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let mut v = vec![verb, "-p", "firmware", "--target", TARGET, "--profile", "firmware"];
    v.extend_from_slice(extra);
    v
}

fn elf_dir() -> PathBuf {
    root().join("target").join(TARGET).join("firmware")
}

/// The sections of `elf`: name, size and address, as `arm-none-eabi-size -A` lists them.
fn section_table(elf: &Path) -> Result<Vec<(String, u64, u64)>, String> {
    let out = Command::new("arm-none-eabi-size")
        .arg("-A")
        .arg(elf)
        .output()
        .map_err(|e| format!("arm-none-eabi-size (install binutils-arm-none-eabi, .ci/install does): {e}"))?;
    Ok(String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| {
            let mut f = l.split_whitespace();
            let name = f.next()?.to_string();
            let size = f.next()?.parse().ok()?;
            let addr = f.next()?.parse().ok()?;
            Some((name, size, addr))
        })
        .collect())
}

/// The total size of the sections of `table` called `name`.
fn section_size(table: &[(String, u64, u64)], name: &str) -> u64 {
    table.iter().filter(|(n, _, _)| n == name).map(|(_, size, _)| size).sum()
}

/// Builds the G474 firmware, reports it by part against the flash and RAM budgets, and fails
/// over either or if it does not fit the chip.
fn firmware() -> Result<(), String> {
    run(cargo().args(firmware_args("build", &[])))?;
    let elf = elf_dir().join("firmware");
    let sections = section_table(&elf)?;
    let size = |name: &str| section_size(&sections, name);
    let flash = size(".boot_stub") + size(".vector_table") + size(".text") + size(".rodata") + size(".data");
    let statics = size(".data") + size(".bss") + size(".uninit");
    println!(
        "firmware (STM32G474CE): flash {flash} B of the {FLASH_BUDGET} B budget ({:.1} %), in a {FLASH_CAPACITY} B slot",
        percent(flash, FLASH_BUDGET)
    );
    println!(
        "firmware (STM32G474CE): RAM {statics} B of statics, {} B of stack below them (its peak, and the RAM \
         budget of {RAM_BUDGET} B: cargo xtask tick-cost)",
        RAM_CAPACITY - statics
    );
    if flash == 0 {
        return Err(format!("no sections read from {}", elf.display()));
    }
    check_boot(&elf, false)?;
    flash_by_part(&elf, flash)?;
    call_graph_checks(&elf, statics)?;
    if flash > FLASH_CAPACITY || statics > RAM_CAPACITY {
        return Err("the firmware does not fit the chip".into());
    }
    if flash > FLASH_BUDGET {
        return Err(format!("the firmware, {flash} B, is OVER its flash budget of {FLASH_BUDGET} B"));
    }
    if statics > RAM_BUDGET {
        return Err(format!("the firmware's statics, {statics} B, are OVER the RAM budget of {RAM_BUDGET} B"));
    }
    // The QEMU build shares the output path: keep the board's ELF for `tick-cost`.
    std::fs::copy(&elf, elf_dir().join("firmware-g474")).map_err(|e| e.to_string())?;
    bootloader()
}

/// The boot loader's target directory: its own, it is a workspace of its own.
fn bootloader_target() -> PathBuf {
    root().join("target").join("bootloader")
}

/// Builds the boot loader (`bootloader/`, a workspace of its own, size-optimised) into
/// `target/bootloader`, reports its flash against its region and its RAM, and fails unless it
/// fits the region and starts at the start of flash.
fn bootloader() -> Result<(), String> {
    let dir = bootloader_target();
    let started = Instant::now();
    run(cargo()
        .current_dir(root().join("bootloader"))
        .args(["build", "--release", "--target", TARGET, "--target-dir"])
        .arg(&dir))?;
    let elf = dir.join(TARGET).join("release").join("bootloader");
    let sections = section_table(&elf)?;
    let size = |name: &str| section_size(&sections, name);
    let flash = size(".vector_table") + size(".text") + size(".rodata") + size(".data");
    let statics = size(".data") + size(".bss") + size(".uninit");
    println!(
        "boot loader (STM32G474CE): flash {flash} B of its {BOOTLOADER_CAPACITY} B region ({:.1} %), built in {:.1} s",
        percent(flash, BOOTLOADER_CAPACITY),
        started.elapsed().as_secs_f64()
    );
    let g = CallGraph::read(&elf)?;
    let stack = g.roots("Reset", true).first().map(|&r| g.depth(r, &mut vec![], &mut Default::default()));
    println!(
        "boot loader (STM32G474CE): RAM {statics} B of statics, {} B of stack by the call graph (its page buffer \
         included), of the {RAM_CAPACITY} B the image has after it",
        stack.map_or_else(|| "?".into(), |s| s.to_string())
    );
    let vectors = symbol(&nm_symbols(&elf, &[])?, "__vector_table")?;
    if flash == 0 || vectors != BOOTLOADER_START {
        return Err(format!(
            "the boot loader's vector table is at {vectors:#x}, not at the start of flash ({BOOTLOADER_START:#x})"
        ));
    }
    if flash > BOOTLOADER_CAPACITY {
        return Err(format!("the boot loader, {flash} B, does NOT FIT its {BOOTLOADER_CAPACITY} B region"));
    }
    if statics + stack.unwrap_or(0) > RAM_CAPACITY {
        return Err("the boot loader's RAM does not fit the chip".into());
    }
    Ok(())
}

/// The G474's control tick interrupt.
const TICK_HANDLER: &str = "ADC1_2";

/// Library routines of software floating point that the tick must not reach: `f64` arithmetic,
/// comparisons and conversions, and the 64/128-bit integer conversions to and from `f32` (the
/// FPU converts only 32-bit integers).
fn is_soft_float(name: &str) -> bool {
    let Some(rest) = name.strip_prefix("__") else { return false };
    let aeabi =
        ["aeabi_d", "aeabi_l2f", "aeabi_ul2f", "aeabi_f2l", "aeabi_f2ul", "aeabi_i2d", "aeabi_ui2d", "aeabi_f2d"];
    let libgcc =
        ["adddf3", "subdf3", "muldf3", "divdf3", "floattisf", "floattidf", "floatuntisf", "fixsfti", "fixdfti"];
    aeabi.iter().any(|p| rest.starts_with(p)) || libgcc.iter().any(|p| rest.starts_with(p))
}

/// The firmware's functions and their direct calls, from the disassembly: by start address,
/// each one's name, the addresses it calls or jumps to, and its stack frame (registers pushed,
/// FPU registers pushed, `sub sp`).
struct CallGraph {
    names: std::collections::BTreeMap<u64, String>,
    calls: std::collections::BTreeMap<u64, Vec<u64>>,
    frames: std::collections::BTreeMap<u64, u64>,
}

impl CallGraph {
    fn read(elf: &Path) -> Result<Self, String> {
        let out = Command::new("arm-none-eabi-objdump")
            .args(["-d", "--no-show-raw-insn", "-C"])
            .arg(elf)
            .output()
            .map_err(|e| format!("arm-none-eabi-objdump (binutils-arm-none-eabi, .ci/install): {e}"))?;
        let text = String::from_utf8_lossy(&out.stdout);
        let mut g = Self { names: Default::default(), calls: Default::default(), frames: Default::default() };
        let mut current = None;
        for line in text.lines() {
            if let Some((addr, rest)) = line.split_once(" <")
                && let Some(name) = rest.strip_suffix(">:")
                && let Ok(addr) = u64::from_str_radix(addr, 16)
            {
                if !name.starts_with('$') {
                    g.names.insert(addr, name.to_string());
                    current = Some(addr);
                }
                continue;
            }
            let Some(from) = current else { continue };
            let mut fields = line.split('\t').skip(1);
            let (Some(op), Some(arg)) = (fields.next(), fields.next()) else { continue };
            let op = op.trim();
            if matches!(op, "bl" | "b" | "b.w" | "blx")
                && let Some(target) = arg.split_whitespace().next().and_then(|a| u64::from_str_radix(a, 16).ok())
            {
                g.calls.entry(from).or_default().push(target);
            }
            let registers = || arg.split('{').nth(1).map_or(0, |r| r.split(',').count() as u64);
            let bytes = match op {
                "push" | "push.w" => 4 * registers(),
                "stmdb" if arg.starts_with("sp!") => 4 * registers(),
                "vpush" => {
                    // `{d8-d15}` or a list.
                    let list = arg.split('{').nth(1).unwrap_or("").trim_end_matches('}');
                    match list.split_once('-') {
                        Some((lo, hi)) => {
                            let n = |r: &str| r.trim().trim_start_matches(['d', 's']).parse::<u64>().unwrap_or(0);
                            let size = if list.starts_with('d') { 8 } else { 4 };
                            size * (n(hi) - n(lo) + 1)
                        }
                        None => 8 * registers(),
                    }
                }
                "sub" | "sub.w" | "subw" if arg.starts_with("sp,") => {
                    arg.split('#').nth(1).and_then(|n| n.split_whitespace().next()?.parse().ok()).unwrap_or(0)
                }
                _ => 0,
            };
            *g.frames.entry(from).or_default() += bytes;
        }
        Ok(g)
    }

    /// The function that holds address `a`.
    fn owner(&self, a: u64) -> Option<u64> {
        self.names.range(..=a).next_back().map(|(&s, _)| s)
    }

    /// The functions whose name is `name`, or contains it.
    fn roots(&self, name: &str, exact: bool) -> Vec<u64> {
        let hit = |n: &String| if exact { n == name } else { n.contains(name) };
        self.names.iter().filter(|(_, n)| hit(n)).map(|(&a, _)| a).collect()
    }

    /// Every function reachable from `root` through direct calls.
    fn reachable(&self, root: u64) -> std::collections::BTreeSet<u64> {
        let mut seen = std::collections::BTreeSet::new();
        let mut todo = vec![root];
        while let Some(f) = todo.pop() {
            if seen.insert(f) {
                todo.extend(self.calls.get(&f).into_iter().flatten().filter_map(|&t| self.owner(t)));
            }
        }
        seen
    }

    /// The deepest stack below `f` through direct calls (a call back into a function already on
    /// the path counts nothing more: the firmware does not recurse).
    fn depth(&self, f: u64, path: &mut Vec<u64>, memo: &mut std::collections::BTreeMap<u64, u64>) -> u64 {
        if let Some(&d) = memo.get(&f) {
            return d;
        }
        if path.contains(&f) {
            return 0;
        }
        path.push(f);
        let callees: Vec<u64> = self.calls.get(&f).into_iter().flatten().filter_map(|&t| self.owner(t)).collect();
        let below = callees.into_iter().map(|c| self.depth(c, path, memo)).max().unwrap_or(0);
        path.pop();
        let d = self.frames.get(&f).copied().unwrap_or(0) + below;
        memo.insert(f, d);
        d
    }
}

/// From the firmware's call graph (direct calls, from the disassembly): fails if a software
/// floating-point routine is reachable from the control tick's interrupt (the tick runs on the
/// FPU's `f32` and integers only), and reports the stack the call graph allows.
fn call_graph_checks(elf: &Path, statics: u64) -> Result<(), String> {
    let g = CallGraph::read(elf)?;
    let root = g.roots(TICK_HANDLER, true).first().copied();
    let seen = root.map(|r| g.reachable(r)).unwrap_or_default();
    if seen.len() < 10 {
        return Err(format!("the call graph from {TICK_HANDLER} has {} functions: not read", seen.len()));
    }
    let soft: Vec<&str> =
        seen.iter().filter_map(|a| g.names.get(a)).map(String::as_str).filter(|n| is_soft_float(n)).collect();
    println!(
        "firmware (STM32G474CE): the control tick ({TICK_HANDLER}) reaches {} functions, {} of software floating point",
        seen.len(),
        soft.len()
    );
    // The deepest task (the executor polls one at a time) with the tick interrupt on top of it,
    // and the Cortex-M4F's exception frame with the FPU context (26 words).
    let mut memo = Default::default();
    let task = g.roots("TaskStorage<F>::poll", false).into_iter().map(|r| g.depth(r, &mut vec![], &mut memo)).max();
    let tick = root.map(|r| g.depth(r, &mut vec![], &mut memo));
    if let (Some(task), Some(tick)) = (task, tick) {
        let bound = task + tick + 104;
        println!(
            "firmware (STM32G474CE): stack by the call graph (direct calls only): the deepest task {task} B + the tick \
             interrupt {tick} B + 104 B of exception frame = {bound} B; with the statics {} B ({:.1} % of the {RAM_BUDGET} B \
             budget)",
            statics + bound,
            percent(statics + bound, RAM_BUDGET)
        );
    }
    // A float's panic message (`f32::clamp` asserts its bounds ordered, which the compiler
    // cannot always prove) links core's float formatting, 13 KB: none in the firmware.
    let panics: Vec<&str> = g
        .names
        .values()
        .map(String::as_str)
        .filter(|n| n.contains("f32>::clamp") || n.contains("fmt::float"))
        .collect();
    if !panics.is_empty() {
        return Err(format!("the firmware links a float's panic or formatting: {panics:?}"));
    }
    if soft.is_empty() { Ok(()) } else { Err(format!("the control tick reaches software floating point: {soft:?}")) }
}

/// Where the flash goes, by the part of the firmware each symbol belongs to: the first of these
/// whose path the (demangled) symbol name contains. Code inlined into a function counts where it
/// is inlined, so the split is approximate.
const PARTS: &[(&str, &[&str])] = &[
    ("S-curve planner", &["drive_core::motion::scurve"]),
    ("PVT segments", &["drive_core::motion::cubic", "drive_core::state::pvt", "drive_core::controller::run"]),
    ("axis and tracks", &["drive_core::motion::axis", "drive_core::motion::track"]),
    (
        "software float, libm and 64/128-bit arithmetic",
        &[
            "compiler_builtins::float",
            "compiler_builtins::int",
            "libm::",
            "__aeabi_d",
            "__aeabi_f",
            "__aeabi_l",
            "__aeabi_ul",
            "__aeabi_i2d",
            "__aeabi_ui2d",
            "__float",
            "__fix",
        ],
    ),
    ("object dictionary and maps", &["drive_core::od", "drive_core::maps"]),
    ("parameter store", &["sequential_storage", "drive_core::store", "embassy_embedded_hal"]),
    ("drive: requests, tick, loops, faults", &["drive_core::"]),
    ("Embassy executor and tasks", &["embassy_executor"]),
    ("Embassy HAL and time", &["embassy_", "stm32_metapac"]),
    (
        "firmware: board, tasks, interrupts",
        &[
            "firmware::",
            "TIM",
            "USART",
            "EXTI",
            "ADC",
            "HardFault",
            "DefaultHandler",
            "SysTick",
            "__INTERRUPTS",
            "__EXCEPTIONS",
            "Reset",
        ],
    ),
    ("defmt", &["defmt"]),
    (
        "core: panics, formatting, memcpy",
        &["core::", "compiler_builtins::mem", "__aeabi_mem", "<usize as", "<u32 as", "<i32 as", "<str as"],
    ),
];

/// Prints the `flash` of the firmware at `elf` by [`PARTS`], then what no part names and what
/// has no symbol (merged strings, alignment, the initial values of `.data`).
fn flash_by_part(elf: &Path, flash: u64) -> Result<(), String> {
    let mut sizes = vec![0u64; PARTS.len() + 1];
    for line in nm_symbols(elf, &["-S", "-C"])?.lines() {
        let mut f = line.splitn(4, ' ');
        let (Some(addr), Some(size), Some(kind), Some(name)) = (f.next(), f.next(), f.next(), f.next()) else {
            continue;
        };
        // Flash holds code and constants from 0x08000000.
        if !addr.starts_with("08") || !matches!(kind, "t" | "T" | "r" | "R" | "W" | "w") {
            continue;
        }
        let size = u64::from_str_radix(size, 16).unwrap_or(0);
        let part = PARTS.iter().position(|(_, keys)| keys.iter().any(|k| name.contains(k))).unwrap_or(PARTS.len());
        sizes[part] += size;
    }
    println!("firmware (STM32G474CE): flash by part (symbol sizes; inlined code counts where it is inlined):");
    for (i, size) in sizes.iter().enumerate() {
        let name = PARTS.get(i).map_or("other symbols: anonymous constants, strings", |(n, _)| n);
        println!("  {size:>6} B  {name}");
    }
    println!(
        "  {:>6} B  no symbol: merged strings, alignment, .data's values",
        flash.saturating_sub(sizes.iter().sum())
    );
    Ok(())
}

fn percent(part: u64, whole: u64) -> f64 {
    part as f64 * 100.0 / whole as f64
}

/// Builds the QEMU variant; returns its ELF (copied aside, the G474 build shares the path).
fn build_qemu() -> Result<PathBuf, String> {
    run(cargo().args(firmware_args("build", &["--no-default-features", "--features", "qemu"])))?;
    let elf = elf_dir().join("firmware-qemu");
    // Copied aside under a name of this process's, then renamed: tests boot QEMU from several
    // processes at once, and a rename never shows another one a half-written file.
    let part = elf_dir().join(format!("firmware-qemu.{}", std::process::id()));
    std::fs::copy(elf_dir().join("firmware"), &part).map_err(|e| format!("{}: {e}", part.display()))?;
    check_boot(&part, true)?;
    std::fs::rename(&part, &elf).map_err(|e| format!("{}: {e}", elf.display()))?;
    Ok(elf)
}

/// `qemu --tcp HOST:PORT [--exit-on-eof]`: boots the QEMU variant with USART1 as a TCP server
/// on HOST:PORT (port 0: a free one), prints `listening on HOST:PORT` once the drive answers a
/// read, then runs until QEMU ends (or, with `--exit-on-eof`, until stdin closes).
fn qemu(args: &[String]) -> Result<(), String> {
    let usage = "usage: cargo xtask qemu --tcp HOST:PORT [--map native|jmc|cls9|ec57|servo] [--exit-on-eof]";
    let endpoint = match args {
        [flag, e, ..] if flag == "--tcp" => e.clone(),
        _ => return Err(usage.into()),
    };
    let exit_on_eof = args.iter().any(|a| a == "--exit-on-eof");
    let map = match args.iter().position(|a| a == "--map").map(|i| args.get(i + 1)) {
        None => None,
        Some(name) => {
            let id = name.and_then(|n| drive_core::maps::NAMES.iter().position(|m| m == n)).ok_or(usage)?;
            Some(u16::try_from(id).map_err(|e| e.to_string())?)
        }
    };
    let (host, port) = endpoint.rsplit_once(':').ok_or(usage)?;
    let port = match port.parse::<u16>().map_err(|e| format!("{endpoint}: {e}"))? {
        // QEMU does not say which port it took: take a free one for it.
        0 => TcpListener::bind((host, 0)).and_then(|l| l.local_addr()).map_err(|e| e.to_string())?.port(),
        p => p,
    };
    let elf = build_qemu()?;
    let started = Instant::now();
    let monitor_port = free_port()?;
    let monitor_at = format!("tcp:127.0.0.1:{monitor_port},server=on,wait=off");
    let mut qemu = spawn_qemu(&elf, host, port, &["-monitor", &monitor_at])?;
    let first_answer = probe(host, port, &mut qemu.0, Duration::from_millis(100))?;
    eprintln!(
        "QEMU: first answer {:.1} ms after launch (100 ms retries); that request's round trip {:.2} ms",
        (started.elapsed() - Duration::from_millis(100)).as_secs_f64() * 1e3,
        first_answer.as_secs_f64() * 1e3
    );
    // QEMU's store is empty at its first boot: the drive starts in the native map.
    if let Some(id) = map.filter(|&id| id != 0) {
        switch_map(host, port, monitor_port, &mut qemu.0, id)?;
    }
    println!("listening on {host}:{port}");
    println!("monitor on 127.0.0.1:{monitor_port}");
    std::io::stdout().flush().map_err(|e| e.to_string())?;
    if exit_on_eof {
        // Whoever started us is gone or done: stop QEMU with us.
        let _ = std::io::stdin().read_to_end(&mut Vec::new());
        return Ok(());
    }
    let status = qemu.0.wait().map_err(|e| e.to_string())?;
    if status.success() { Ok(()) } else { Err(format!("qemu: {status}")) }
}

/// The first `n` bytes of section `name` of `elf`.
fn section_bytes(elf: &Path, name: &str, n: usize) -> Result<Vec<u8>, String> {
    // A name of this process's: tests check the QEMU image from several processes at once.
    let file = elf.file_name().map_or_else(String::new, |f| f.to_string_lossy().into_owned());
    let out = elf.with_file_name(format!("{file}.{}.{}.bin", std::process::id(), name.trim_start_matches('.')));
    let status = Command::new("arm-none-eabi-objcopy")
        .args(["-O", "binary", "--only-section", name])
        .arg(elf)
        .arg(&out)
        .status()
        .map_err(|e| format!("arm-none-eabi-objcopy (binutils-arm-none-eabi, .ci/install): {e}"))?;
    let bytes = std::fs::read(&out).map_err(|e| format!("{}: {e}", out.display()));
    let _ = std::fs::remove_file(&out);
    match bytes?.get(..n) {
        Some(b) if status.success() => Ok(b.to_vec()),
        _ => Err(format!("{} has no {n} bytes of {name}", elf.display())),
    }
}

/// Fails unless `elf` starts where it is started: its vector table at ACTIVE, and with `stub`
/// (the QEMU build, which has no boot loader) the boot loader's stand-in at the start of flash
/// holding the same stack pointer and reset vector (`firmware/boot_stub.x`), where QEMU starts
/// the core. Without it (the G474 build) nothing of the image may lie in the boot loader's
/// region: flashing the image must leave the boot loader whole.
fn check_boot(elf: &Path, stub: bool) -> Result<(), String> {
    let vectors = symbol(&nm_symbols(elf, &[])?, "__vector_table")?;
    if vectors != ACTIVE_START {
        return Err(format!("the vector table is at {vectors:#x}, not at ACTIVE ({ACTIVE_START:#x})"));
    }
    if stub {
        let (stub, table) = (section_bytes(elf, ".boot_stub", 8)?, section_bytes(elf, ".vector_table", 8)?);
        if stub != table {
            return Err(format!("the boot stand-in {stub:02x?} is not the vector table's {table:02x?}"));
        }
        return Ok(());
    }
    let below: Vec<String> = section_table(elf)?
        .into_iter()
        .filter(|&(_, size, addr)| size > 0 && (BOOTLOADER_START..ACTIVE_START).contains(&addr))
        .map(|(name, _, addr)| format!("{name} at {addr:#x}"))
        .collect();
    if below.is_empty() { Ok(()) } else { Err(format!("the image writes into the boot loader's region: {below:?}")) }
}

/// Boots `elf` on QEMU's b-l475e-iot01a with USART1 a TCP server on `host:port`.
fn spawn_qemu(elf: &Path, host: &str, port: u16, extra: &[&str]) -> Result<Qemu, String> {
    let child = Command::new("qemu-system-arm")
        .args(["-M", "b-l475e-iot01a", "-nographic", "-kernel"])
        .arg(elf)
        .arg("-serial")
        .arg(format!("tcp:{host}:{port},server=on,wait=off,nodelay=on"))
        .args(extra)
        // Not our stdout: whoever reads the `listening on` line may close it afterwards.
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .spawn()
        .map_err(|e| format!("qemu-system-arm (QEMU 10, .ci/install installs it): {e}"))?;
    Ok(Qemu(child))
}

fn free_port() -> Result<u16, String> {
    TcpListener::bind(("127.0.0.1", 0)).and_then(|l| l.local_addr()).map(|a| a.port()).map_err(|e| e.to_string())
}

/// One raw RTU request (CRC appended) and its `reply_len`-byte reply.
fn transact(s: &mut TcpStream, body: &[u8], reply_len: usize) -> Result<Vec<u8>, String> {
    let mut frame = body.to_vec();
    frame.extend_from_slice(&drive_core::crc::crc16(body).to_le_bytes());
    s.write_all(&frame).map_err(|e| e.to_string())?;
    let mut reply = vec![0u8; reply_len];
    s.read_exact(&mut reply).map_err(|e| format!("reply to {body:02x?}: {e}"))?;
    Ok(reply)
}

/// Writes `v` to the native register `reg` of node 1 (0x06); fails unless the write is echoed.
fn write_register(s: &mut TcpStream, reg: u16, v: u16) -> Result<(), String> {
    let ([rh, rl], [vh, vl]) = (reg.to_be_bytes(), v.to_be_bytes());
    let reply = transact(s, &[1, 6, rh, rl, vh, vl], 8)?;
    if reply.get(1) == Some(&6) { Ok(()) } else { Err(format!("{reg:#06x} = {v} refused: {reply:02x?}")) }
}

/// A parameter save (0x200F = 2) to its end: 0x2120 bit 3 is set while it runs, bit 4 if it
/// failed; fails on a failure or at `deadline`.
fn save(s: &mut TcpStream, deadline: Instant) -> Result<(), String> {
    write_register(s, 0x200F, 2)?;
    loop {
        let status = transact(s, &[1, 3, 0x21, 0x20, 0, 1], 7)?;
        match status.get(4) {
            Some(b) if b & 0x10 != 0 => return Err(format!("the parameter save failed: 0x2120 = {b:#04x}")),
            Some(b) if b & 0x08 == 0 => return Ok(()),
            _ if Instant::now() > deadline => return Err("the parameter save did not end".into()),
            _ => {}
        }
    }
}

/// Where `tick-cost` re-targets its move: once past this position, an absolute move to that.
const RETARGETS: [(i32, u16); 4] = [(1000, 12_000), (3000, 14_000), (5000, 16_000), (7000, 18_000)];

/// The paint of the firmware's free stack (`firmware/src/stack.rs`).
const STACK_PAINT: u64 = 0x214B_5453;

/// `-icount` shift of `tick-cost`: an instruction takes 2^4 = 16 virtual ns, so a count of the
/// 4 MHz SysTick (250 ns) is 15.6 instructions. Shifts 3 and 4 agree (idle 500, stepping ~2700);
/// with shifts 0-2 QEMU 10.0 reads the same SysTick value before and after most ticks.
const ICOUNT_SHIFT: u32 = 4;

/// The symbol table of `elf`, as `arm-none-eabi-nm` with `options` prints it.
fn nm_symbols(elf: &Path, options: &[&str]) -> Result<String, String> {
    let nm = Command::new("arm-none-eabi-nm")
        .args(options)
        .arg(elf)
        .output()
        .map_err(|e| format!("arm-none-eabi-nm: {e}"))?;
    Ok(String::from_utf8_lossy(&nm.stdout).into_owned())
}

/// The address of `name` in a symbol table from [`nm_symbols`].
fn symbol(symbols: &str, name: &str) -> Result<u64, String> {
    symbols
        .lines()
        .find_map(|l| l.strip_suffix(name).filter(|l| l.ends_with(' ')).and_then(|l| l.split_whitespace().next()))
        .and_then(|a| u64::from_str_radix(a, 16).ok())
        .ok_or(format!("no {name} symbol"))
}

/// The control tick's cost in instructions: the QEMU build under `-icount` (instructions set the
/// virtual clock) counts SysTick across each tick into `TICK_COST`, read here through QEMU's
/// monitor while idle and during a move.
fn tick_cost() -> Result<(), String> {
    let elf = build_qemu()?;
    let symbols = nm_symbols(&elf, &[])?;
    let addr = symbol(&symbols, "TICK_COST")?;
    let (stack_end, stack_start) = (symbol(&symbols, "_stack_end")?, symbol(&symbols, "_stack_start")?);
    // The board's layout, to hold the measured peak against.
    let g474_elf = elf_dir().join("firmware-g474");
    if !g474_elf.exists() {
        firmware()?;
    }
    let g474_stack_start = symbol(&nm_symbols(&g474_elf, &[])?, "_stack_start")?;
    let (port, mon) = (free_port()?, free_port()?);
    let monitor_at = format!("tcp:127.0.0.1:{mon},server=on,wait=off");
    let mut qemu = spawn_qemu(
        &elf,
        "127.0.0.1",
        port,
        &["-icount", &format!("shift={ICOUNT_SHIFT},align=off"), "-monitor", &monitor_at],
    )?;
    // Generous: under -icount a reply takes a few hundred ms.
    probe("127.0.0.1", port, &mut qemu.0, Duration::from_millis(1000))?;
    // `n` words of the emulated chip's memory at `at`, through QEMU's monitor.
    let read_memory = |at: u64, n: usize| -> Result<Vec<u64>, String> {
        let text = monitor(mon, &format!("xp /{n}wx 0x{at:x}"))?;
        // QEMU prints four words a line, each line after its address and a colon.
        let words: Vec<u64> = text
            .lines()
            .filter_map(|l| l.split_once(": ").filter(|(a, _)| a.trim().len() == 16).map(|(_, w)| w))
            .flat_map(|w| w.split_whitespace().map(|x| u64::from_str_radix(x.trim_start_matches("0x"), 16)))
            .collect::<Result<_, _>>()
            .map_err(|e| format!("{}: {e}", text.chars().take(500).collect::<String>()))?;
        if words.len() == n { Ok(words) } else { Err(format!("{} of {n} words from the monitor", words.len())) }
    };
    let read_stats = || read_memory(addr, 8);
    let stack_words = usize::try_from((stack_start - stack_end) / 4).map_err(|e| e.to_string())?;
    // The firmware painted its free stack at power-up (`firmware/src/stack.rs`): the deepest
    // word without the paint is as far as the stack has gone.
    let stack_peak = || -> Result<u64, String> {
        let untouched = read_memory(stack_end, stack_words)?.iter().take_while(|&&w| w == STACK_PAINT).count();
        Ok(stack_start - stack_end - 4 * untouched as u64)
    };
    std::thread::sleep(Duration::from_millis(500));
    let idle = read_stats()?;
    let stack_booted = stack_peak()?;
    let mut s = TcpStream::connect(("127.0.0.1", port)).map_err(|e| e.to_string())?;
    s.set_read_timeout(Some(Duration::from_secs(2))).map_err(|e| e.to_string())?;
    let read_word = |s: &mut TcpStream, reg: u16, n: u16| -> Result<Vec<u8>, String> {
        let ([rh, rl], [_, nl]) = (reg.to_be_bytes(), n.to_be_bytes());
        transact(s, &[1, 3, rh, rl, 0, nl], 5 + 2 * usize::from(n))
    };
    let position = |s: &mut TcpStream| -> Result<i32, String> {
        let r = read_word(s, 0x600E, 2)?;
        Ok(i32::from_be_bytes([r[3], r[4], r[5], r[6]]))
    };
    // Forward at 4000 pps, a relative move of 8000 steps (native map, node 1) in one 0x10 write
    // of 0x6002..0x6006 (three objects, the last a command: the drive commits them in order,
    // with a checkpoint to roll back to, the deepest write path), then re-targeted four times
    // while it cruises by absolute moves, each further: the bus task plans while the tick runs
    // the axis, and hands each plan over at the tick it was planned for. Four plans let the
    // tick interrupt land at more depths of the planner's stack.
    let words: [u16; 5] = [0, 0, 4000, 0, 8000];
    let mut request = vec![1, 0x10, 0x60, 0x02, 0, 5, 10];
    request.extend(words.iter().flat_map(|w| w.to_be_bytes()));
    transact(&mut s, &request, 8)?;
    // Virtual time crawls under -icount (bytes too): poll rather than sleep.
    let deadline = Instant::now() + Duration::from_secs(90);
    for (past, target) in RETARGETS {
        while position(&mut s)? < past {
            if Instant::now() > deadline {
                return Err(format!("the move did not pass {past}"));
            }
        }
        write_register(&mut s, 0x6044, 0)?;
        write_register(&mut s, 0x6045, target)?;
    }
    while read_word(&mut s, 0x6001, 1)?[4] & 0x08 != 0 {
        if Instant::now() > deadline {
            return Err("the move did not end".into());
        }
    }
    let end = position(&mut s)?;
    let after = read_stats()?;
    let stack_served = stack_peak()?;
    // Then two parameter saves (the first into the empty store, the second replacing its
    // record): the store's frames in the bus task, without the drive's lock, with control ticks
    // landing on top of them.
    for _ in 0..2 {
        save(&mut s, deadline)?;
    }
    let stack_saved = stack_peak()?;
    // The store's RAM (`firmware/src/board/qemu.rs`), erased at power-up: what the saves programmed.
    let programmed =
        4 * read_memory(QEMU_STORE_RAM, QEMU_STORE_WORDS)?.iter().filter(|&&w| w != u64::from(u32::MAX)).count();
    drop(qemu);
    let per_count = 250.0 / f64::from(1u32 << ICOUNT_SHIFT);
    let per_tick = |n: u64, sum: u64| if n == 0 { 0.0 } else { sum as f64 * per_count / n as f64 };
    let (idle_n, idle_sum) = (idle.first().copied().unwrap_or(0), idle.get(1).copied().unwrap_or(0));
    let (moving_n, moving_sum) = (after.get(2).copied().unwrap_or(0), after.get(3).copied().unwrap_or(0));
    println!("control tick under QEMU -icount (resolution {per_count:.1} instructions, averaged):");
    println!("  idle:     {:.0} instructions per tick ({idle_n} ticks)", per_tick(idle_n, idle_sum));
    println!("  stepping: {:.0} instructions per tick ({moving_n} ticks)", per_tick(moving_n, moving_sum));
    println!("  longest:  {:.0} instructions or fewer", (after.get(4).copied().unwrap_or(0) + 1) as f64 * per_count);
    let word = |i: usize| after.get(i).copied().unwrap_or(0);
    // Steps are counted in 32 bits by the firmware.
    let (emitted, missed, handed) = (word(6) as u32 as i32, word(5), word(7));
    println!(
        "  handover: {handed} plans taken over by the tick at their first tick, {missed} late or dropped; \
         no tick waits for the bus task (it owns nothing the tick needs)"
    );
    let goal = RETARGETS.last().map_or(0, |&(_, t)| i32::from(t));
    println!("  steps:    {emitted} emitted by the stage, the drive ends at {end} (a move re-targeted to {goal})");
    println!(
        "  stack:    {stack_booted} B at the most after booting, {stack_served} B after these requests, \
         {stack_saved} B after two parameter saves, of the {} B below the statics",
        stack_start - stack_end
    );
    println!("  store:    {programmed} B of the emulated flash programmed by the saves");
    if programmed == 0 {
        return Err("the parameter saves programmed nothing".into());
    }
    if end != goal || emitted != end {
        return Err(format!("the stage emitted {emitted} steps, the drive stands at {end}: {goal} both expected"));
    }
    // The board: its statics (flip-link puts them at the end of RAM) and its stack below them.
    let (g474_statics, g474_stack) = (RAM_END - g474_stack_start, g474_stack_start - 0x2000_0000);
    let peak = stack_booted.max(stack_served).max(stack_saved);
    let ram = g474_statics + peak;
    println!(
        "  G474 RAM: {g474_statics} B of statics + this stack peak {peak} B = {ram} B of the {RAM_BUDGET} B budget \
         ({:.1} %){}",
        percent(ram, RAM_BUDGET),
        if ram > RAM_BUDGET { ": OVER the budget" } else { "" }
    );
    if ram > RAM_BUDGET {
        return Err(format!("the G474's RAM, {ram} B measured, is over its {RAM_BUDGET} B budget"));
    }
    if peak + STACK_MARGIN > g474_stack {
        return Err(format!(
            "the stack peak {peak} B leaves less than {STACK_MARGIN} B of the G474's {g474_stack} B below its statics"
        ));
    }
    if missed != 0 {
        return Err(format!("{missed} plans were taken over after their first tick or dropped"));
    }
    // The move and its four re-targets at least (saves and reads plan nothing).
    if handed < 1 + RETARGETS.len() as u64 {
        return Err(format!(
            "{handed} plans handed over: the move and its re-targets did not all go through the handoff"
        ));
    }
    Ok(())
}

/// `-icount` shift of the `tick_cost` program: an instruction takes 256 virtual ns, a SysTick
/// count 250 ns, so a count is 250/256 of an instruction.
const CORE_ICOUNT_SHIFT: u32 = 8;
/// The G474's receive ring (`firmware/src/board/g474.rs`): two requests of the longest (ASCII
/// lines).
const RX_RING: usize = 2 * drive_core::ascii::MAX_LINE;
/// Bytes a second on the line at 115 200 baud, 8N1 (10 bits a byte).
const BYTES_PER_S_AT_115200: f64 = 11_520.0;
/// Cycles of one 20 kHz control tick on the 170 MHz Cortex-M4 of the G474.
const TICK_CYCLES: f64 = 170e6 / 20e3;

/// The drive core's tick alone on the Cortex-M4 instruction set, cruising in open loop, with the
/// closed loops and with the sensorless stall detection (`firmware/src/bin/tick_cost.rs`): runs
/// it under QEMU and prints instructions a tick and the share of a 20 kHz tick they would take
/// on the G474 at one cycle an instruction. Fails if the program does (a case not cruising).
fn core_tick_cost() -> Result<(), String> {
    run(cargo()
        .args(firmware_args("build", &["--no-default-features", "--features", "tick-cost", "--bin", "tick_cost"])))?;
    let out = Command::new("qemu-system-arm")
        .args(["-M", "b-l475e-iot01a", "-nographic", "-serial", "none", "-monitor", "none"])
        .args(["-semihosting-config", "enable=on,target=native", "-icount"])
        .arg(format!("shift={CORE_ICOUNT_SHIFT},align=off"))
        .arg("-kernel")
        .arg(elf_dir().join("tick_cost"))
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("qemu-system-arm (QEMU 10, .ci/install installs it): {e}"))?;
    let text = String::from_utf8_lossy(&out.stdout);
    let per_count = 250.0 / f64::from(1u32 << CORE_ICOUNT_SHIFT);
    println!("control tick of drive-core on the Cortex-M4 (QEMU -icount), the cases of firmware/src/bin/tick_cost.rs:");
    let mut over_budget = false;
    let mut longest_request = 0.0f64;
    let mut image: Vec<(String, f64)> = Vec::new();
    for line in text.lines() {
        // `tick_cost NAME mean M most N counts`
        let words: Vec<&str> = line.split_whitespace().collect();
        match words.as_slice() {
            ["tick_cost", name, "mean", mean, "most", most, "counts"] => {
                let count = |w: &str| w.parse::<f64>().map(|c| c * per_count).map_err(|e| format!("{line}: {e}"));
                let (mean, most) = (count(mean)?, count(most)?);
                let over = |v: f64, budget: f64| if v > budget { " OVER" } else { "" };
                println!(
                    "  {name:15} {mean:5.0} instructions{} (most {most:5.0}{}): {:4.1} % of a 20 kHz tick at 170 MHz, one cycle an instruction",
                    over(mean, TICK_MEAN_BUDGET),
                    over(most, TICK_MOST_BUDGET),
                    100.0 * mean / TICK_CYCLES
                );
                over_budget |= mean > TICK_MEAN_BUDGET || most > TICK_MOST_BUDGET;
            }
            // `request NAME N counts`
            ["request", name, spent, "counts"] => {
                let spent = spent.parse::<f64>().map_err(|e| format!("{line}: {e}"))? * per_count;
                longest_request = longest_request.max(spent);
                println!(
                    "  request {name:14} {spent:7.0} instructions to serve ({:.2} ms of the bus task; the tick runs on meanwhile)",
                    spent / 170e3,
                );
            }
            // `image NAME N counts`: the image check's parts.
            ["image", name, spent, "counts"] => {
                let spent = spent.parse::<f64>().map_err(|e| format!("{line}: {e}"))? * per_count;
                image.push((name.to_string(), spent));
                println!("  image check: {name:14} {spent:8.0} instructions ({:.1} ms at 170 MHz)", spent / 170e3);
            }
            // `tick_cost handover synced N planned M counts`
            ["tick_cost", "handover", "synced", synced, "planned", planned, "counts"] => {
                let count = |w: &str| w.parse::<f64>().map(|c| c * per_count).map_err(|e| format!("{line}: {e}"));
                let (synced, planned) = (count(synced)?, count(planned)?);
                println!(
                    "  ticks that synced the bus task's model: at most {synced:.0} instructions{}; that took a plan over: at most {planned:.0}",
                    if synced > TICK_MOST_BUDGET { " OVER" } else { "" }
                );
                over_budget |= synced > TICK_MOST_BUDGET;
            }
            _ => println!("  {line}"),
        }
    }
    if !out.status.success() {
        return Err(format!("tick_cost under QEMU: {}", out.status));
    }
    // The board's receive ring must hold what arrives while the Modbus task serves the longest
    // request (the tick preempting it meanwhile: its mean share counted in) at the fastest baud.
    let serving_s = longest_request / (170e6 * (1.0 - TICK_MEAN_BUDGET / TICK_CYCLES));
    let arriving = serving_s * BYTES_PER_S_AT_115200;
    println!(
        "  receive ring: the longest request here keeps the Modbus task {:.2} ms, {arriving:.0} bytes at 115 200 \
         baud, of the G474's {RX_RING} B ring",
        serving_s * 1e3
    );
    if arriving > RX_RING as f64 {
        return Err(format!(
            "a request keeps the Modbus task long enough for {arriving:.0} bytes to overrun the {RX_RING} B ring"
        ));
    }
    // The install's check of the largest image (the slot's 192 KiB budget): the digest of its
    // bytes, a piece of 2 KiB at a time with the other tasks run between pieces (the sense task
    // feeds the watchdog), and the signature's check in one go, the longest stretch without them.
    let part = |name: &str| image.iter().find(|(n, _)| n == name).map(|&(_, v)| v);
    let (Some(digest), Some(signature)) = (part("digest_8k"), part("signature")) else {
        return Err("tick_cost printed no image check".into());
    };
    let share = 170e6 * (1.0 - TICK_MEAN_BUDGET / TICK_CYCLES);
    let (install_s, stretch_s) = ((digest * 24.0 + signature) / share, signature.max(digest / 4.0) / share);
    println!(
        "  install check of a 192 KiB image: {:.0} ms of the bus task at 170 MHz, the tick preempting it; at most {:.1} ms without the other tasks (the watchdog allows {WATCHDOG_MS} ms)",
        install_s * 1e3,
        stretch_s * 1e3
    );
    if stretch_s * 1e3 > f64::from(WATCHDOG_MS) / 5.0 {
        return Err(format!("the install's check keeps the other tasks waiting {:.0} ms", stretch_s * 1e3));
    }
    if over_budget {
        return Err(format!(
            "OVER the control work's budget: a mean of {TICK_MEAN_BUDGET:.0} instructions (30 % of a period), at most {TICK_MOST_BUDGET:.0} in one"
        ));
    }
    Ok(())
}

/// The G474's independent watchdog: it resets the chip after this many ms without a feed, which
/// the sense task gives; the install's check may keep that task waiting a fifth of it at most.
const WATCHDOG_MS: u32 = 500;

/// How long `probe` tries to reach the drive under QEMU.
const PROBE_FOR: Duration = Duration::from_secs(60);

/// QEMU, killed when dropped.
struct Qemu(Child);

impl Drop for Qemu {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Asks for the device identification (0x2B/0x0E, which every map answers) until the drive
/// answers (QEMU boots in tens of ms; a request sent before the USART is on is lost), waiting
/// `patience` for each answer; returns the round trip of the answered request.
fn probe(host: &str, port: u16, qemu: &mut Child, patience: Duration) -> Result<Duration, String> {
    // Basic identification, from object 0.
    let request = [0x01, 0x2B, 0x0E, 0x01, 0x00, 0x70, 0x77];
    // Generous: a loaded machine slows QEMU's boot and its serial line.
    let deadline = Instant::now() + PROBE_FOR;
    while Instant::now() < deadline {
        if let Ok(Some(status)) = qemu.try_wait() {
            return Err(format!("qemu exited: {status}"));
        }
        let Ok(mut s) = TcpStream::connect((host, port)) else {
            std::thread::sleep(Duration::from_millis(5));
            continue;
        };
        eprintln!("QEMU: serial port open after {:.1} ms", (Instant::now() + PROBE_FOR - deadline).as_secs_f64() * 1e3);
        s.set_read_timeout(Some(patience)).map_err(|e| e.to_string())?;
        for _ in 0..50 {
            let sent = Instant::now();
            s.write_all(&request).map_err(|e| e.to_string())?;
            let mut head = [0u8; 3];
            if s.read_exact(&mut head).is_ok() && head == [0x01, 0x2B, 0x0E] {
                let rtt = sent.elapsed();
                // The rest of the reply, and a late answer to an earlier attempt: here, not at
                // the next client.
                std::thread::sleep(patience);
                let _ = s.read(&mut [0u8; 512]);
                return Ok(rtt);
            }
            // A partial or garbled answer: let the drive's receiver clear. It waits up to 250 ms
            // for the rest of a request of known length (firmware/src/frames.rs): a retry sooner
            // would complete a request that lost its first bytes with the head of the next, and
            // every retry after it would stay out of step.
            std::thread::sleep(Duration::from_millis(300));
        }
    }
    Err(format!("the drive under QEMU did not answer on {host}:{port}"))
}

/// Sends `command` to QEMU's monitor at `port` and returns what it printed.
fn monitor(port: u16, command: &str) -> Result<String, String> {
    let mut m = TcpStream::connect(("127.0.0.1", port)).map_err(|e| format!("QEMU's monitor: {e}"))?;
    m.set_read_timeout(Some(Duration::from_millis(500))).map_err(|e| e.to_string())?;
    m.write_all(format!("{command}\n").as_bytes()).map_err(|e| e.to_string())?;
    let mut text = String::new();
    let mut buf = [0u8; 4096];
    while let Ok(k) = m.read(&mut buf) {
        if k == 0 {
            break;
        }
        text.push_str(&String::from_utf8_lossy(&buf[..k]));
    }
    Ok(text)
}

/// Switches the drive under QEMU, at the native map, to map number `id` as a master would:
/// 0x2190 = id, a save (0x200F = 2, until 0x2120 bit 3 clears), then a reset of the emulated
/// chip through the monitor (its store, in RAM, stays), and waits for it to answer again.
fn switch_map(host: &str, port: u16, monitor_port: u16, qemu: &mut Child, id: u16) -> Result<(), String> {
    let mut s = TcpStream::connect((host, port)).map_err(|e| e.to_string())?;
    s.set_read_timeout(Some(Duration::from_secs(2))).map_err(|e| e.to_string())?;
    write_register(&mut s, 0x2190, id)?;
    save(&mut s, Instant::now() + Duration::from_secs(10))?;
    drop(s);
    monitor(monitor_port, "system_reset")?;
    probe(host, port, qemu, Duration::from_millis(100)).map(drop)
}

/// Builds the embedded-test HIL suite for the G474 (it runs with `probe-rs` on a board).
fn hil() -> Result<(), String> {
    run(cargo().args(firmware_args("build", &["--test", "hil"])))
}

/// `path` as text, for a command's argument.
fn path_str(path: &Path) -> Result<&str, String> {
    path.to_str().ok_or_else(|| format!("{} is not UTF-8", path.display()))
}

/// A simulator process, killed when dropped.
struct Sim(Child, String);

impl Drop for Sim {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

fn start_sim(args: &[&str]) -> Result<Sim, String> {
    // The dev build the tests already made (hal-sim is optimised in the dev profile): a release
    // build of the simulator would cost CI minutes for nothing the masters can tell.
    let bin = root().join("target/debug/hal-sim");
    let mut child =
        Command::new(&bin).args(args).stdout(Stdio::piped()).spawn().map_err(|e| format!("{}: {e}", bin.display()))?;
    let mut line = String::new();
    let stdout = child.stdout.take().ok_or("no stdout")?;
    BufReader::new(stdout).read_line(&mut line).map_err(|e| e.to_string())?;
    let endpoint = line.trim().strip_prefix("listening on ").ok_or(format!("unexpected first line {line:?}"))?;
    eprintln!("simulator listening on {endpoint}");
    Ok(Sim(child, endpoint.to_string()))
}

fn masters() -> Result<(), String> {
    run(cargo().args(["build", "-p", "hal-sim"]))?;
    let venv = root().join("target/venv/bin/python");
    let python = if venv.exists() { venv } else { PathBuf::from("python3") };
    let script = root().join("tests/masters");

    let sim = start_sim(&[])?;
    run(Command::new(&python).arg(script.join("pymodbus_check.py")).arg(&sim.1))?;
    drop(sim);
    let sim = start_sim(&["--tcp", "127.0.0.1:0"])?;
    run(Command::new(&python).arg(script.join("pymodbus_check.py")).arg(&sim.1))?;
    drop(sim);
    // A firmware update: an image of 40 KB signed with the test key, sent over the
    // pseudo-terminal, installed, the new version read back.
    let dir = root().join("target/masters");
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let program: Vec<u8> = (0..40_000u32).map(|i| (i * 31 + i / 997) as u8).collect();
    std::fs::write(dir.join("program.bin"), program).map_err(|e| e.to_string())?;
    let key = root().join("keys/test.key");
    let (program, image) = (dir.join("program.bin"), dir.join("sim.img"));
    let args =
        ["--key", path_str(&key)?, "--board", "sim", "--version", "3.2.1", path_str(&program)?, path_str(&image)?];
    sign(&args.map(String::from))?;
    let sim = start_sim(&[])?;
    run(Command::new(&python).arg(script.join("pymodbus_update.py")).arg(&sim.1).arg(&image))?;
    drop(sim);
    let sim = start_sim(&[])?;
    run(Command::new("bash").arg(script.join("mbpoll_check.sh")).arg(&sim.1))?;
    drop(sim);
    // The DS-CLS9 map, with a home cam and two limit switches for its homing.
    let switches = ["--switch", "ext1:pnp:40:to=44", "--switch", "ext2:pnp:-120:below", "--switch", "ext3:pnp:120"];
    let sim = start_sim(&[&["--map", "cls9"][..], &switches[..]].concat())?;
    run(Command::new(&python).arg(script.join("pymodbus_cls9.py")).arg(&sim.1))?;
    drop(sim);
    // The EC-57 map, over the pseudo-terminal and over TCP.
    let sim = start_sim(&["--map", "ec57"])?;
    run(Command::new(&python).arg(script.join("pymodbus_ec57.py")).arg(&sim.1))?;
    drop(sim);
    let sim = start_sim(&["--map", "ec57", "--tcp", "127.0.0.1:0"])?;
    run(Command::new(&python).arg(script.join("pymodbus_ec57.py")).arg(&sim.1))?;
    drop(sim);
    // Its fault detection mask, the supply stepped to 70 V after 2 s.
    let sim = start_sim(&["--map", "ec57", "--tcp", "127.0.0.1:0", "--fault", "2000:supply=70"])?;
    run(Command::new(&python).arg(script.join("pymodbus_ec57.py")).arg(&sim.1).arg("mask"))?;
    drop(sim);
    // The servo map, RTU then ASCII (P□600, saved, 0541h restart), over the pseudo-terminal and
    // over TCP; two cams where its position data groups end, to see the rotor there.
    let cams = ["--switch", "ext1:pnp:3195:to=3205", "--switch", "ext2:pnp:-1605:to=-1595"];
    for tcp in [&[][..], &["--tcp", "127.0.0.1:0"][..]] {
        let sim = start_sim(&[&["--map", "servo"][..], &cams[..], tcp].concat())?;
        run(Command::new(&python).arg(script.join("pymodbus_servo.py")).arg(&sim.1))?;
    }
    Ok(())
}

/// `cargo xtask keygen PREFIX`: a new Ed25519 key pair from the system's random source,
/// `PREFIX.key` (the 32-byte secret seed in hex, readable by its owner only) and `PREFIX.pub`
/// (the public key in hex, which a firmware is built with). An existing file is not replaced.
fn keygen(args: &[String]) -> Result<(), String> {
    let [prefix] = args else { return Err("usage: cargo xtask keygen PREFIX".into()) };
    let mut seed = [0u8; 32];
    getrandom::fill(&mut seed).map_err(|e| format!("no random source: {e}"))?;
    let key = ed25519_dalek::SigningKey::from_bytes(&seed);
    let (secret, public) = (PathBuf::from(format!("{prefix}.key")), PathBuf::from(format!("{prefix}.pub")));
    for path in [&secret, &public] {
        if path.exists() {
            return Err(format!("{} exists: not replaced", path.display()));
        }
    }
    write_private(&secret, &format!("{}\n", hex(&seed)))?;
    std::fs::write(&public, format!("{}\n", hex(key.verifying_key().as_bytes()))).map_err(|e| e.to_string())?;
    eprintln!("{} (keep it secret), {}", secret.display(), public.display());
    Ok(())
}

/// Writes `text` to a new file at `path` that only its owner may read.
fn write_private(path: &Path, text: &str) -> Result<(), String> {
    use std::io::Write as _;
    use std::os::unix::fs::OpenOptionsExt as _;
    let mut f = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    f.write_all(text.as_bytes()).map_err(|e| e.to_string())
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The 32 bytes written in hex in the file at `path`.
fn read_key(path: &str) -> Result<[u8; 32], String> {
    let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
    drive_core::update::key_from_hex(&text).ok_or(format!("{path}: not 32 bytes in hex"))
}

/// `cargo xtask image --key FILE --version X.Y.Z [IMAGE]`: the G474 firmware built to take images
/// signed with the key pair of FILE (its `.pub` beside it, as `keygen` writes them), its program
/// as `objcopy -O binary` gives it, and that program signed with FILE: an image to send to drives
/// that run a firmware built with the same key (`target/firmware-g474.img` unless IMAGE says).
fn image(args: &[String]) -> Result<(), String> {
    let usage = "usage: cargo xtask image --key FILE --version X.Y.Z [IMAGE]";
    let (mut key, mut version, mut out) = (None, None, None);
    let mut it = args.iter();
    while let Some(a) = it.next() {
        match a.as_str() {
            "--key" => key = it.next().cloned(),
            "--version" => version = it.next().cloned(),
            other if out.is_none() => out = Some(PathBuf::from(other)),
            _ => return Err(usage.into()),
        }
    }
    let (Some(key), Some(version)) = (key, version) else { return Err(usage.into()) };
    let secret = ed25519_dalek::SigningKey::from_bytes(&read_key(&key)?);
    let public = Path::new(&key).with_extension("pub");
    let public = std::fs::canonicalize(&public).map_err(|e| format!("{}: {e}", public.display()))?;
    if read_key(path_str(&public)?)? != secret.verifying_key().to_bytes() {
        return Err(format!("{} is not the public key of {key}", public.display()));
    }
    run(cargo().args(firmware_args("build", &[])).env("OSD_UPDATE_KEY", &public))?;
    let elf = elf_dir().join("firmware");
    let program = elf_dir().join("firmware-g474.bin");
    let status = Command::new("arm-none-eabi-objcopy")
        .args(["-O", "binary"])
        .arg(&elf)
        .arg(&program)
        .status()
        .map_err(|e| format!("arm-none-eabi-objcopy (binutils-arm-none-eabi, .ci/install): {e}"))?;
    if !status.success() {
        return Err(format!("objcopy: {status}"));
    }
    let out = out.unwrap_or_else(|| root().join("target/firmware-g474.img"));
    let args = ["--key", &key, "--board", "g474", "--version", &version, path_str(&program)?, path_str(&out)?];
    sign(&args.map(String::from))
}

/// `cargo xtask sign --key FILE --board B --version X.Y.Z [--store N] PROGRAM IMAGE`: the image
/// of PROGRAM (raw bytes, as `objcopy -O binary` gives them): header, program, and the
/// signature with the secret key in FILE (`drive_core::update`).
fn sign(args: &[String]) -> Result<(), String> {
    use drive_core::update::{Board, Header, digest};
    use ed25519_dalek::Signer as _;
    let usage = "usage: cargo xtask sign --key FILE --board g474|qemu|sim --version X.Y.Z [--store N] PROGRAM IMAGE";
    let (mut key, mut board, mut version, mut store, mut files) = (None, None, None, 1u16, Vec::new());
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = || it.next().cloned().ok_or(usage.to_string());
        match a.as_str() {
            "--key" => key = Some(value()?),
            "--board" => {
                board = Some(match value()?.as_str() {
                    "g474" => Board::G474,
                    "qemu" => Board::Qemu,
                    "sim" => Board::Simulator,
                    other => return Err(format!("no board {other:?}: g474, qemu or sim")),
                })
            }
            "--version" => {
                let v = value()?;
                let parts: Vec<u32> = v.split('.').filter_map(|p| p.parse().ok()).collect();
                version = match parts[..] {
                    [major, minor, patch] if major < 0x10000 && minor < 0x100 && patch < 0x100 => {
                        Some(major << 16 | minor << 8 | patch)
                    }
                    _ => return Err(format!("{v:?} is not a version X.Y.Z")),
                };
            }
            "--store" => store = value()?.parse().map_err(|_| usage.to_string())?,
            _ => files.push(a.clone()),
        }
    }
    let (Some(key), Some(board), Some(version), [program, image]) = (key, board, version, &files[..]) else {
        return Err(usage.into());
    };
    let secret = ed25519_dalek::SigningKey::from_bytes(&read_key(&key)?);
    let code = std::fs::read(program).map_err(|e| format!("{program}: {e}"))?;
    let length = u32::try_from(code.len()).map_err(|_| format!("{program} is too long"))?;
    let header = Header { board, version, length, store };
    let mut bytes = header.to_bytes().to_vec();
    bytes.extend_from_slice(&code);
    let signature = secret.sign(&digest(&bytes));
    bytes.extend_from_slice(&signature.to_bytes());
    std::fs::write(image, &bytes).map_err(|e| format!("{image}: {e}"))?;
    eprintln!(
        "{image}: {} bytes, {board:?} version {}.{}.{}",
        bytes.len(),
        version >> 16,
        version >> 8 & 0xFF,
        version & 0xFF
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    use drive_core::update::{Board, SIGNATURE_LEN, TEST_KEY, Verifier};

    /// `sign` with the repository's test key makes an image the drive takes.
    #[test]
    fn a_signed_image_verifies_with_the_test_key() {
        let dir = std::env::temp_dir().join(format!("xtask-sign-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (program, image) = (dir.join("program.bin"), dir.join("image.bin"));
        std::fs::write(&program, [0xA5u8; 1000]).unwrap();
        let key = super::root().join("keys/test.key");
        let args: Vec<String> = [
            "--key",
            key.to_str().unwrap(),
            "--board",
            "sim",
            "--version",
            "1.2.3",
            program.to_str().unwrap(),
            image.to_str().unwrap(),
        ]
        .map(String::from)
        .to_vec();
        super::sign(&args).unwrap();
        let bytes = std::fs::read(&image).unwrap();
        let (body, signature) = bytes.split_at(bytes.len() - SIGNATURE_LEN);
        let mut v = Verifier::new();
        v.absorb(body);
        let header = v.finish(signature.try_into().unwrap(), &TEST_KEY, Board::Simulator, 1).unwrap();
        assert_eq!((header.version, header.length), (0x0001_0203, 1000));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
