//! The STM32G474CE's flash, decided once: where the boot loader, the two image slots, the
//! update state and the parameter store lie, and why. `memory.x` follows this table (a test in
//! `tests/tests/board.rs` holds the two together), the board's store uses [`PARAMS`], and
//! `docs/board-g474.md` shows it.
//!
//! The chip runs with its flash as two banks of 256 KiB (option bit DBANK = 1, 2 KiB pages): a
//! bank can be erased and programmed while code runs from the other one. The layout is
//! embassy-boot's (ACTIVE, DFU, STATE): the boot loader copies a verified update from DFU into
//! ACTIVE page by page, logging each step in STATE, so that a power cut at any point resumes or
//! reverts the copy at the next reset, and an image that does not mark itself booted is swapped
//! back. The running image and the boot loader are in bank 1; everything written while the drive
//! runs (the update being received, the update state, the parameters) is in bank 2, so neither a
//! transfer nor a save stalls the fetches of the running code and its control tick.
//!
//! The G474's own bank swap (BFB2) was weighed: it boots the other bank without a copy, but the
//! swap is an option-byte write (not power-fail safe on its own), the parameter store would
//! change address with every swap, and a rollback still needs a loader that decides.

/// One region of the flash: `name`, what it holds, from `start` (an address), `len` bytes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Region {
    /// The region's name, as `memory.x` names it.
    pub name: &'static str,
    /// The address of its first byte.
    pub start: u32,
    /// Its size in bytes (whole 2 KiB pages).
    pub len: u32,
    /// What it holds and why it is this size.
    pub why: &'static str,
}

impl Region {
    /// Its name in `memory.x`: cortex-m-rt links the program into the region called FLASH.
    pub fn linker_name(&self) -> &'static str {
        if *self == ACTIVE { "FLASH" } else { self.name }
    }

    /// The address just past it.
    pub const fn end(&self) -> u32 {
        self.start + self.len
    }
}

/// The start of flash.
pub const FLASH_START: u32 = 0x0800_0000;
/// One bank: 256 KiB.
pub const BANK: u32 = 256 * 1024;
/// A flash page, the unit of erase, in dual-bank mode.
pub const PAGE: u32 = 2 * 1024;

/// embassy-boot's boot loader: it checks the update state and swaps the slots if asked.
pub const BOOTLOADER: Region = Region {
    name: "BOOTLOADER",
    start: FLASH_START,
    len: 32 * 1024,
    why: "embassy-boot's boot loader (`bootloader/`: its flash driver, no logs, about 5 KiB); the region leaves room for logs or a recovery over the bus. The QEMU build, which has none, puts the image's first two words here (firmware/boot_stub.x)",
};

/// The image that runs.
pub const ACTIVE: Region = Region {
    name: "ACTIVE",
    start: BOOTLOADER.end(),
    len: BANK - BOOTLOADER.len,
    why: "the running image: the rest of bank 1; the image's budget is 192 KiB, so 32 KiB are room to grow",
};

/// Where an update is received.
pub const DFU: Region = Region {
    name: "DFU",
    start: FLASH_START + BANK,
    len: ACTIVE.len + PAGE,
    why: "the update being received, in bank 2 beside the running code; embassy-boot's swap needs one page more than ACTIVE",
};

/// The update's progress.
pub const STATE: Region = Region {
    name: "STATE",
    start: DFU.end(),
    len: 2 * PAGE,
    why: "embassy-boot's state: a magic word and a progress entry of 8 bytes for each step of the swap (2 + 4 x 112 pages)",
};

/// The parameter store: parameters, the power-down position, the fault history and a map's
/// multi-segment program (DS-CLS9), each a record of `sequential-storage`'s map.
pub const PARAMS: Region = Region {
    name: "PARAMS",
    start: STATE.end(),
    len: 16 * 1024,
    why: "the parameter store (parameters, position, fault history, the DS-CLS9 program in two banks of records): 8 pages, so that the store's wear levelling spreads saves",
};

/// What is left at the end of bank 2.
pub const FREE: Region = Region {
    name: "FREE",
    start: PARAMS.end(),
    len: FLASH_START + 2 * BANK - PARAMS.end(),
    why: "not used: room for a second store or a larger state",
};

/// Every region, in address order.
pub const REGIONS: [Region; 6] = [BOOTLOADER, ACTIVE, DFU, STATE, PARAMS, FREE];

/// Checked when this is compiled: the regions tile both banks, page-aligned, and embassy-boot's
/// conditions on its partitions hold.
const _: () = {
    let mut at = FLASH_START;
    let mut i = 0;
    while i < REGIONS.len() {
        let r = REGIONS[i];
        assert!(r.start == at, "the regions leave a gap or overlap");
        assert!(r.start.is_multiple_of(PAGE) && r.len.is_multiple_of(PAGE), "a region is not whole pages");
        at = r.end();
        i += 1;
    }
    assert!(at == FLASH_START + 2 * BANK, "the regions do not end at the end of flash");
    assert!(ACTIVE.end() == FLASH_START + BANK, "the running image crosses into bank 2");
    assert!(DFU.start >= FLASH_START + BANK, "the update is not in bank 2");
    // embassy-boot's `assert_partitions`: DFU one page larger, STATE holding its progress log.
    assert!(DFU.len >= ACTIVE.len + PAGE);
    assert!(2 + 4 * (ACTIVE.len / PAGE) <= STATE.len / 8);
    assert!(ACTIVE.len >= 192 * 1024, "the image's budget does not fit its slot");
};
