//! The drive's boot loader: embassy-boot on the STM32G474CE. At every reset it reads the update
//! state (STATE); if an update is marked, it swaps DFU and ACTIVE page by page, logging each step
//! in STATE (a power cut resumes the swap), or swaps them back if the image it started last time
//! never confirmed itself; then it starts the image in ACTIVE.
//!
//! The partitions are the flash map's (`firmware/src/flash_map.rs`, compiled in here, so that the
//! boot loader and the firmware cannot disagree), as offsets from the start of flash: the flash
//! driver addresses both banks from there, as the firmware's parameter store does.
//!
//! - **Single-bank mode** (option bit DBANK = 0): the map's pages and bank 2 are not where the
//!   build says, and embassy-stm32's flash driver panics on it. The loader then writes nothing
//!   and starts ACTIVE as it is (at the same address in either mode); the firmware checks DBANK
//!   itself, halts with its power stage off and says why over RTT (`docs/board-g474.md`).
//! - **A flash error** while the loader reads or swaps: it stops, and starts nothing. ACTIVE may
//!   hold half of each image then, and a mix of two images must not drive a motor; retrying at
//!   once could erase the same worn page in a loop. The power stage stays off (its pins are in
//!   their reset state); the next reset or power-up tries again, and the swap resumes from its
//!   log. A panic (only embassy-boot's checks of the partitions, which the flash map's own
//!   compile-time checks already hold) stops the same way.

#![no_std]
#![no_main]

use core::cell::RefCell;

use cortex_m_rt::entry;
use embassy_boot_stm32::{BootLoader, BootLoaderConfig, State};
use embassy_embedded_hal::flash::partition::BlockingPartition;
use embassy_stm32::flash::{Blocking, Flash};
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::NoopRawMutex;

/// The firmware's flash map: one source of truth for where each region lies.
#[allow(dead_code)]
#[path = "../../firmware/src/flash_map.rs"]
mod flash_map;

use flash_map::{ACTIVE, DFU, FLASH_START, PAGE, Region, STATE};

/// The unit of a swap step, and the loader's buffer: one page (2 KiB in dual-bank mode).
const PAGE_SIZE: usize = PAGE as usize;

type SharedFlash = Mutex<NoopRawMutex, RefCell<Flash<'static, Blocking>>>;

/// `region` as a partition of the whole flash: its offset from the start of flash and its size.
fn partition(flash: &SharedFlash, region: Region) -> BlockingPartition<'_, NoopRawMutex, Flash<'static, Blocking>> {
    BlockingPartition::new(flash, region.start - FLASH_START, region.len)
}

#[entry]
fn main() -> ! {
    let p = embassy_stm32::init(Default::default());
    let loader = if embassy_stm32::pac::FLASH.optr().read().dbank() {
        let flash: SharedFlash = Mutex::new(RefCell::new(Flash::new_blocking(p.FLASH)));
        let config = BootLoaderConfig {
            active: partition(&flash, ACTIVE),
            dfu: partition(&flash, DFU),
            state: partition(&flash, STATE),
        };
        match BootLoader::try_prepare::<_, _, _, PAGE_SIZE>(config) {
            Ok(loader) => loader,
            Err(_) => stop(),
        }
    } else {
        // Single-bank mode: nothing written, ACTIVE started as it is (see above).
        BootLoader { state: State::Boot }
    };
    // SAFETY: ACTIVE holds an image linked there, its vector table first (the firmware's
    // memory.x); nothing of the loader is used after the jump.
    unsafe { loader.load(ACTIVE.start) }
}

/// Starts nothing: sleeps until a reset.
fn stop() -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    stop()
}
