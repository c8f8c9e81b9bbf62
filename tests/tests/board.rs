//! The board's tables against the chip and the docs: every pin's alternate function, and every
//! analog pin's ADC channel, op-amp or comparator input, against the STM32G474CE's data
//! (stm32-metapac's, generated from ST's), the power stage's half-bridges as complementary pairs
//! of the advanced timers, `memory.x` against the flash map, and `docs/board-g474.md`'s pin and
//! flash tables generated from both (`UPDATE_DOCS=1` rewrites them; otherwise a stale table fails).

#[path = "../../firmware/src/flash_map.rs"]
#[allow(dead_code, reason = "the firmware's table, read whole here")]
mod flash_map;
#[path = "../../firmware/src/board/pins.rs"]
#[allow(dead_code, reason = "the firmware's table, read whole here")]
mod pins;

use std::path::Path;

use stm32_metapac::metadata::{METADATA, MemoryRegionKind};

const ROOT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/..");

/// Whether the row is an analog input: a peripheral's signal on the pin with no alternate
/// function (the pin in analog mode).
fn analog(p: &pins::Pin) -> bool {
    !p.function.is_empty() && p.af.is_none()
}

#[test]
fn every_pin_has_the_function_the_board_gives_it_on_the_g474ce() {
    // The 48-pin package: the chip's data lists its pins, and only those.
    assert_eq!(METADATA.name, "STM32G474CE");
    assert_eq!(METADATA.pins.len(), 42, "the LQFP48/UFQFPN48 package's I/Os (PG10 is NRST)");
    for p in pins::PINS.iter().filter(|p| !p.pin.is_empty()) {
        assert!(METADATA.pins.iter().any(|c| c.name == p.pin), "{}: the chip has no pin {}", p.signal, p.pin);
        if p.function.is_empty() {
            continue; // plain GPIO: every pin is one
        }
        // The signal exactly as the chip's data names it: `IN11` is not `INN11` (a differential
        // input's negative side), `VINP1` is the op-amp's non-inverting input selector 1.
        let found: Vec<_> = METADATA
            .peripherals
            .iter()
            .filter(|q| q.name == p.peripheral)
            .flat_map(|q| q.pins.iter())
            .filter(|c| c.pin == p.pin && c.signal == p.function)
            .collect();
        assert!(!found.is_empty(), "{}: {} is not {}_{} on the G474CE", p.signal, p.pin, p.peripheral, p.function);
        // An alternate function's number; an analog signal (ADC channel, op-amp or comparator
        // input) has none in the data, and the board sets none.
        assert!(
            found.iter().any(|c| c.af == p.af),
            "{}: {} {}_{} is on alternate function {:?}, the board says {:?}",
            p.signal,
            p.pin,
            p.peripheral,
            p.function,
            found.iter().map(|c| c.af).collect::<Vec<_>>(),
            p.af
        );
        if analog(p) {
            let kind = METADATA.peripherals.iter().find(|q| q.name == p.peripheral).and_then(|q| q.registers.as_ref());
            assert!(
                kind.is_some_and(|r| ["adc", "opamp", "comp", "dac"].contains(&r.kind)),
                "{}: {} is analog on {}, which is not an analog peripheral",
                p.signal,
                p.pin,
                p.peripheral
            );
        }
    }
}

#[test]
fn no_pin_serves_two_signals() {
    let mut seen = std::collections::BTreeMap::new();
    for p in pins::PINS.iter().filter(|p| !p.pin.is_empty()) {
        if let Some(other) = seen.insert(p.pin, p) {
            // An analog pin may feed several peripherals (a shunt: op-amp and comparator), as one
            // signal; a pin on an alternate function has that function only.
            assert!(
                other.signal == p.signal && analog(other) && analog(p),
                "{} carries both {} ({}_{}) and {} ({}_{})",
                p.pin,
                other.signal,
                other.peripheral,
                other.function,
                p.signal,
                p.peripheral,
                p.function
            );
        }
    }
}

#[test]
fn every_half_bridge_is_a_complementary_pair_of_an_advanced_timer() {
    // Each leg: a channel's output for the high side, its complementary output for the low
    // side, of a timer with dead time and a break input (TIM1, TIM8: TIM_ADV in the data).
    let legs: Vec<_> = pins::BRIDGES.chunks(2).collect();
    assert_eq!(legs.len(), 4, "two H-bridges");
    for leg in &legs {
        let (high, low) = (leg[0], leg[1]);
        assert_eq!(high.peripheral, low.peripheral, "{} and {}: one timer", high.signal, low.signal);
        assert!(high.function.starts_with("CH") && !high.function.ends_with('N'), "{}: a channel", high.signal);
        assert_eq!(low.function, format!("{}N", high.function), "{}: the complement of {}", low.signal, high.signal);
        let block = METADATA
            .peripherals
            .iter()
            .find(|q| q.name == high.peripheral)
            .and_then(|q| q.registers.as_ref())
            .map(|r| r.block);
        assert_eq!(block, Some("TIM_ADV"), "{}: {} is not an advanced-control timer", high.signal, high.peripheral);
        assert!(pins::PINS.contains(&high) && pins::PINS.contains(&low), "{}: in the table", high.signal);
    }
    // Four different outputs: no channel drives two legs.
    let mut channels: Vec<_> = legs.iter().map(|l| (l[0].peripheral, l[0].function)).collect();
    channels.sort_unstable();
    channels.dedup();
    assert_eq!(channels.len(), 4, "four different timer channels");
}

#[test]
fn the_flash_map_is_the_chips_flash_in_dual_bank_mode() {
    // The dual-bank layout of the chip's data: two banks of 256 KiB in 2 KiB pages.
    let banks: Vec<_> = METADATA
        .memory
        .iter()
        .find(|layout| layout.iter().filter(|r| r.kind == MemoryRegionKind::Flash).count() == 2)
        .expect("the G474CE has a dual-bank layout")
        .iter()
        .filter(|r| r.kind == MemoryRegionKind::Flash)
        .collect();
    for (bank, start) in banks.iter().zip([flash_map::FLASH_START, flash_map::FLASH_START + flash_map::BANK]) {
        assert_eq!(bank.address, start);
        assert_eq!(bank.size, flash_map::BANK);
        assert_eq!(bank.settings.as_ref().map(|s| s.erase_size), Some(flash_map::PAGE));
    }
    let end = flash_map::REGIONS.last().map(flash_map::Region::end);
    assert_eq!(end, Some(flash_map::FLASH_START + 2 * flash_map::BANK));
}

/// `memory.x`'s MEMORY regions: name, origin, length in bytes.
fn memory_x() -> Vec<(String, u32, u32)> {
    let text = std::fs::read_to_string(Path::new(ROOT).join("memory.x")).expect("memory.x");
    let number = |s: &str| -> u32 {
        let s = s.trim();
        if let Some(k) = s.strip_suffix('K') {
            k.parse::<u32>().expect("a size") * 1024
        } else {
            u32::from_str_radix(s.trim_start_matches("0x"), 16).expect("an address")
        }
    };
    text.lines()
        .filter_map(|l| {
            let (name, rest) = l.split_once(':')?;
            let origin = rest.split("ORIGIN =").nth(1)?.split(',').next()?;
            let length = rest.split("LENGTH =").nth(1)?;
            Some((name.trim().to_string(), number(origin), number(length)))
        })
        .collect()
}

#[test]
fn memory_x_follows_the_flash_map() {
    let regions = memory_x();
    for r in flash_map::REGIONS {
        let found = regions.iter().find(|(name, _, _)| name == r.linker_name());
        assert_eq!(
            found.map(|(_, o, l)| (*o, *l)),
            Some((r.start, r.len)),
            "memory.x's {} is not the flash map's {} ({:#x}, {} B)",
            r.linker_name(),
            r.name,
            r.start,
            r.len
        );
    }
    // RAM: SRAM1 and SRAM2 for the program (the 96 KiB budget), the CCM SRAM apart.
    let ram = regions.iter().find(|(n, _, _)| n == "RAM").map(|(_, o, l)| (*o, *l));
    assert_eq!(ram, Some((0x2000_0000, 96 * 1024)));
    let sram: u32 = METADATA.memory[0].iter().filter(|r| r.name == "SRAM1" || r.name == "SRAM2").map(|r| r.size).sum();
    assert_eq!(sram, 96 * 1024, "SRAM1 + SRAM2 of the G474CE");
}

/// The pin table as `docs/board-g474.md` shows it.
fn pin_table() -> String {
    let mut t = String::from("| signal | pin | function | AF | notes |\n|---|---|---|---|---|\n");
    for p in pins::PINS {
        let function = match (p.peripheral, p.function) {
            ("GPIO", _) => "GPIO".to_string(),
            (q, "") if p.pin.is_empty() => format!("{q} (internal)"),
            (q, "") => q.to_string(),
            (q, f) => format!("{q}_{f}"),
        };
        let af = p.af.map_or(String::from(if analog(&p) { "analog" } else { "-" }), |a| a.to_string());
        let pin = if p.pin.is_empty() { "-" } else { p.pin };
        t.push_str(&format!("| {} | {pin} | {function} | {af} | {} |\n", p.signal, p.notes));
    }
    t
}

/// The flash map as `docs/board-g474.md` shows it.
fn flash_table() -> String {
    let mut t = String::from("| region | from | to | size | what and why |\n|---|---|---|---|---|\n");
    for r in flash_map::REGIONS {
        let name =
            if r.linker_name() == r.name { r.name.to_string() } else { format!("{} (`{}`)", r.name, r.linker_name()) };
        t.push_str(&format!("| {name} | {:#010x} | {:#010x} | {} KiB | {} |\n", r.start, r.end(), r.len / 1024, r.why));
    }
    t
}

/// `text` with the part between `<!-- NAME -->` and `<!-- /NAME -->` replaced by `body`.
fn splice(text: &str, name: &str, body: &str) -> String {
    let (open, close) = (format!("<!-- {name} -->\n"), format!("<!-- /{name} -->"));
    let start = text.find(&open).unwrap_or_else(|| panic!("docs/board-g474.md has no {open}")) + open.len();
    let end = text.find(&close).unwrap_or_else(|| panic!("docs/board-g474.md has no {close}"));
    format!("{}{body}{}", &text[..start], &text[end..])
}

#[test]
fn the_board_doc_shows_the_tables() {
    let path = Path::new(ROOT).join("docs/board-g474.md");
    let text = std::fs::read_to_string(&path).expect("docs/board-g474.md");
    let fresh = splice(&splice(&text, "pins", &pin_table()), "flash-map", &flash_table());
    if std::env::var_os("UPDATE_DOCS").is_some() {
        std::fs::write(&path, &fresh).expect("write docs/board-g474.md");
    } else {
        assert!(fresh == text, "docs/board-g474.md's tables are stale: run `cargo xtask docs`");
    }
}
