//! QEMU's b-l475e-iot01a (STM32L475VG), on the PAC: the same application as the G474 board
//! over what QEMU 10 models.
//!
//! QEMU models RCC, GPIO, EXTI and the USARTs of this chip but not its timers, DMA or PWR, and
//! its USART takes 32-bit accesses only; embassy-stm32's `init` and UART driver do not run there
//! (see docs/board-g474.md). So this layer is small and direct:
//! - USART1 (QEMU's first serial port) with 32-bit register access, the RXNE interrupt filling
//!   a pipe, and transmission by polling TXE;
//! - SysTick at 1 kHz from the 4 MHz MSI reset clock: the embassy-time driver (microseconds,
//!   interpolated from the SysTick counter) and the control tick. `drive-core` evaluates the
//!   motion at the time it is given, so a slower tick only batches more steps per tick;
//! - no step timer: the drive core counts the steps (the position advances as on the board);
//! - no flash controller: the parameter store runs on RAM that behaves as flash ([`RamFlash`]),
//!   kept across a reset of the emulated chip (QEMU's `system_reset` leaves RAM as it was).

use core::cell::{Cell, RefCell};
use core::convert::Infallible;
use core::sync::atomic::{AtomicU32, Ordering};
use core::task::Waker;

use critical_section::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::pipe::Pipe;
use embassy_time_queue_utils::Queue;
use stm32_metapac as pac;

use crate::power::PowerStage;

/// What the 0x1022 hardware version says.
pub const HARDWARE: &str = "QEMU L475";
/// How long after a request its motion starts, µs: under `-icount` a planned move takes a few
/// virtual milliseconds, and the plan is handed over at the next tick (1 ms here).
pub const PLAN_MARGIN_US: u64 = 20_000;
/// SysTick clock: the core clock at reset (MSI, 4 MHz), which nothing here changes.
const CORE_HZ: u32 = 4_000_000;
/// SysTick counts in one millisecond.
const RELOAD: u32 = CORE_HZ / TICK_HZ - 1;
/// SysTick's rate: the clock of embassy-time and the control tick.
const TICK_HZ: u32 = 1000;

/// Received bytes, from the RXNE interrupt to the Modbus task: two frames of the longest, as the
/// board's receive ring.
static RX: Pipe<CriticalSectionRawMutex, { 2 * drive_core::ascii::MAX_LINE }> = Pipe::new();

/// USART1 as the RS-485 port (QEMU's line has no transceiver and no baud timing).
pub struct Serial(());

impl embedded_io_async::ErrorType for Serial {
    type Error = Infallible;
}

impl embedded_io_async::Read for Serial {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        Ok(RX.read(buf).await)
    }
}

impl embedded_io_async::Write for Serial {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        let u = pac::USART1;
        for &b in buf {
            while !u.isr().read().txe() {}
            u.tdr().write(|w| w.set_dr(u16::from(b)));
        }
        Ok(buf.len())
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        while !pac::USART1.isr().read().tc() {}
        Ok(())
    }
}

/// USART1's receive interrupt: every byte into the pipe (a full pipe drops it, like an overrun).
#[unsafe(no_mangle)]
extern "C" fn USART1() {
    let u = pac::USART1;
    let isr = u.isr().read();
    if isr.ore() {
        // Only the overrun flag: writing the whole ISR value to ICR clears TXE in QEMU's model.
        u.icr().write(|w| w.set_ore(true));
    }
    if isr.rxne() {
        let b = u.rdr().read().dr() as u8;
        let _ = RX.try_write(&[b]);
    }
}

/// Starts SysTick (time and control tick) and USART1 with its receive interrupt.
pub fn init() -> Serial {
    // SAFETY: called once, before anything else uses the core peripherals.
    let mut core = unsafe { cortex_m::Peripherals::steal() };
    core.SYST.set_clock_source(cortex_m::peripheral::syst::SystClkSource::Core);
    core.SYST.set_reload(RELOAD);
    core.SYST.clear_current();
    core.SYST.enable_interrupt();
    core.SYST.enable_counter();

    pac::RCC.apb2enr().modify(|w| w.set_usart1en(true));
    let u = pac::USART1;
    u.brr().write(|w| w.set_brr((CORE_HZ / 115_200) as u16));
    u.cr1().write(|w| {
        w.set_re(true);
        w.set_te(true);
        w.set_rxneie(true);
        w.set_ue(true);
    });
    // SAFETY: the handler only touches USART1 and the pipe (a critical-section mutex).
    unsafe { cortex_m::peripheral::NVIC::unmask(pac::Interrupt::USART1) };
    Serial(())
}

/// Nothing to cut under QEMU: no power stage.
pub fn power_off() {}

/// The parameter store's range in [`RamFlash`]: the size of the board's ([`crate::flash_map::PARAMS`]).
pub const STORE: core::ops::Range<u32> = 0..STORE_BYTES;
/// Bytes of the store.
const STORE_BYTES: u32 = crate::flash_map::PARAMS.len;
/// Bytes of [`RamFlash`]: SRAM2 but its last page, which keeps the marker.
const RAM_FLASH_BYTES: u32 = 32 * 1024 - PAGE;
/// A page of [`RamFlash`].
const PAGE: u32 = drive_core::update::PAGE;

/// The board images are built for (an image's header).
pub const IMAGE_BOARD: drive_core::update::Board = drive_core::update::Board::Qemu;
/// No boot loader: QEMU starts the image in ACTIVE; an update is received, checked and marked,
/// but nothing swaps it in.
pub const BOOT_LOADER: bool = false;
/// Bytes of the boot loader's state: two pages, as on the board.
pub const STATE_LEN: u32 = 2 * PAGE;
/// The DFU slot's program pages that [`RamFlash`] holds (after the store): an image's program of
/// up to 8 KiB; its trailer page follows them, then the state.
const DFU_PAGES: u32 = 4;

/// Where an access of `len` bytes at `offset` of the DFU slot lies in [`RamFlash`]: its first
/// [`DFU_PAGES`] pages and its trailer page, each a page of the 14 KiB after the store (the
/// L475's SRAM2 holds no 226 KiB slot).
pub fn dfu_at(offset: u32, len: u32) -> Option<u32> {
    let end = offset.checked_add(len)?;
    let trailer = drive_core::update::TRAILER;
    if end <= DFU_PAGES * PAGE {
        Some(STORE_BYTES + offset)
    } else if offset >= trailer && end <= trailer + PAGE {
        Some(STORE_BYTES + DFU_PAGES * PAGE + offset - trailer)
    } else {
        None
    }
}

/// Where an access of `len` bytes at `offset` of the boot loader's state lies in [`RamFlash`]:
/// its last two pages.
pub fn state_at(offset: u32, len: u32) -> Option<u32> {
    (offset.checked_add(len)? <= STATE_LEN).then_some(STORE_BYTES + (DFU_PAGES + 1) * PAGE + offset)
}

/// The header in the running image's trailer: none under QEMU (nothing installs one), read as
/// the board reads it.
pub fn active_trailer() -> [u8; drive_core::update::HEADER_LEN] {
    let at = crate::flash_map::ACTIVE.start + drive_core::update::TRAILER;
    // SAFETY: ACTIVE lies in the L475's flash, which QEMU maps readable (zero where no program is).
    unsafe { core::ptr::read_volatile(at as *const [u8; drive_core::update::HEADER_LEN]) }
}
/// Where [`RamFlash`] lives: the L475's SRAM2 (32 KiB at 0x10000000), outside the RAM that
/// `memory.x` gives the program (its SRAM1), where the G474 has its CCM SRAM.
const STORE_RAM: usize = 0x1000_0000;
/// Written after the store's bytes once they are erased: RAM that holds it has held a store
/// since QEMU started (QEMU's RAM starts zero, and a reset keeps it).
const FORMATTED: u32 = 0x5354_4F52;

/// QEMU does not model this chip's flash controller, so the parameter store runs on RAM that
/// behaves as NOR flash does (a write only clears bits, an erase sets a page to 0xFF, the
/// G474's write and page sizes): the same store and save path as the board. It lasts while QEMU
/// runs, across resets of the emulated chip, as flash lasts across the board's power cycles.
pub struct RamFlash(&'static mut [u8]);

/// The parameter store on [`RamFlash`], behind the adapter the board's flash uses.
pub type ParamStore = drive_core::store::Store<embassy_embedded_hal::adapter::BlockingAsync<RamFlash>>;

/// The store's RAM, and the update's after it (the first call only; `None` after): as the last
/// run left it, or erased if this is QEMU's first boot.
pub fn param_flash() -> Option<RamFlash> {
    static TAKEN: core::sync::atomic::AtomicBool = core::sync::atomic::AtomicBool::new(false);
    if TAKEN.swap(true, Ordering::AcqRel) {
        return None;
    }
    let marker = (STORE_RAM + RAM_FLASH_BYTES as usize) as *mut u32;
    // SAFETY: STORE_RAM..+RAM_FLASH_BYTES and the marker word after it are SRAM2 of the
    // STM32L475, outside the linker's RAM region (memory.x), so nothing else uses them; the flag
    // above hands them out once.
    let (bytes, formatted) = unsafe {
        (
            core::slice::from_raw_parts_mut(STORE_RAM as *mut u8, RAM_FLASH_BYTES as usize),
            core::ptr::read_volatile(marker) == FORMATTED,
        )
    };
    if !formatted {
        bytes.fill(0xFF);
        // SAFETY: as above.
        unsafe { core::ptr::write_volatile(marker, FORMATTED) };
    }
    Some(RamFlash(bytes))
}

/// A [`RamFlash`] access outside it or not aligned to its write or erase size.
#[derive(Debug)]
pub struct RamFlashError(embedded_storage::nor_flash::NorFlashErrorKind);

impl embedded_storage::nor_flash::NorFlashError for RamFlashError {
    fn kind(&self) -> embedded_storage::nor_flash::NorFlashErrorKind {
        self.0
    }
}

impl RamFlash {
    /// The bytes at `offset..offset + len`, if within the flash and aligned to `align`.
    fn range(&mut self, offset: u32, len: usize, align: usize) -> Result<&mut [u8], RamFlashError> {
        use embedded_storage::nor_flash::NorFlashErrorKind::{NotAligned, OutOfBounds};
        let start = offset as usize;
        if !start.is_multiple_of(align) || !len.is_multiple_of(align) {
            return Err(RamFlashError(NotAligned));
        }
        start.checked_add(len).and_then(|end| self.0.get_mut(start..end)).ok_or(RamFlashError(OutOfBounds))
    }
}

impl embedded_storage::nor_flash::ErrorType for RamFlash {
    type Error = RamFlashError;
}

impl embedded_storage::nor_flash::ReadNorFlash for RamFlash {
    const READ_SIZE: usize = 1;

    fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), RamFlashError> {
        bytes.copy_from_slice(self.range(offset, bytes.len(), 1)?);
        Ok(())
    }

    fn capacity(&self) -> usize {
        self.0.len()
    }
}

impl embedded_storage::nor_flash::NorFlash for RamFlash {
    /// The G474's: a double word.
    const WRITE_SIZE: usize = 8;
    /// The G474's page in dual-bank mode.
    const ERASE_SIZE: usize = 2048;

    fn erase(&mut self, from: u32, to: u32) -> Result<(), RamFlashError> {
        let len =
            to.checked_sub(from).ok_or(RamFlashError(embedded_storage::nor_flash::NorFlashErrorKind::OutOfBounds))?;
        self.range(from, len as usize, Self::ERASE_SIZE)?.fill(0xFF);
        Ok(())
    }

    fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), RamFlashError> {
        for (cell, b) in self.range(offset, bytes.len(), Self::WRITE_SIZE)?.iter_mut().zip(bytes) {
            *cell &= b;
        }
        Ok(())
    }
}

/// Milliseconds since boot, counted by the SysTick handler.
static MILLIS: Mutex<Cell<u64>> = Mutex::new(Cell::new(0));
/// The timers of embassy-time's queue, and the next time one is due.
static QUEUE: Mutex<RefCell<(Queue, u64)>> = Mutex::new(RefCell::new((Queue::new(), u64::MAX)));

/// Microseconds since boot: the millisecond count plus SysTick's progress through the next one.
fn micros() -> u64 {
    critical_section::with(|cs| {
        let before = cortex_m::peripheral::SYST::get_current();
        // Interrupts are off: a wrap since the last handler run shows as a pending SysTick. If it
        // is not pending, `before` was read before any wrap; if it is, `after` is read after it.
        let wrapped = cortex_m::peripheral::SCB::is_pendst_pending();
        let after = cortex_m::peripheral::SYST::get_current();
        let (ms, count) =
            if wrapped { (MILLIS.borrow(cs).get() + 1, after) } else { (MILLIS.borrow(cs).get(), before) };
        ms * 1000 + u64::from((RELOAD - count.min(RELOAD)) / (CORE_HZ / 1_000_000))
    })
}

/// embassy-time's driver on SysTick.
struct SysTickDriver;

impl embassy_time_driver::Driver for SysTickDriver {
    fn now(&self) -> u64 {
        micros()
    }

    fn schedule_wake(&self, at: u64, waker: &Waker) {
        critical_section::with(|cs| {
            let mut q = QUEUE.borrow_ref_mut(cs);
            let (queue, next) = &mut *q;
            if queue.schedule_wake(at, waker) {
                *next = queue.next_expiration(micros());
            }
        });
    }
}

embassy_time_driver::time_driver_impl!(static DRIVER: SysTickDriver = SysTickDriver);

/// The emulated chip's power stage: none. The drive core counts the steps itself; this counts
/// the steps the stage would emit, for `cargo xtask tick-cost` to check against the drive's
/// position (the handovers must neither lose nor add one), and notes whether the tick stepped.
struct NoStage {
    moving: bool,
    /// Steps emitted since power-up (signed).
    emitted: i64,
}

impl PowerStage for NoStage {
    fn step(&mut self, steps: i64) {
        self.moving = steps != 0;
        self.emitted = self.emitted.wrapping_add(steps);
    }
    fn set_current(&mut self, _milliamps: u16) {}
}

/// Read by `cargo xtask tick-cost` through QEMU's monitor. The control tick's cost in SysTick
/// counts (a count is 250 virtual ns, 15.6 instructions under `qemu -icount shift=4`): [0] idle
/// ticks, [1] their total counts, [2] ticks that stepped, [3] their total counts, [4] most
/// counts of one tick; [5] plans the tick took over after their first tick or dropped; [6] steps
/// the stage emitted since power-up (`i32` bits); [7] plans taken over at their first tick.
#[unsafe(no_mangle)]
static TICK_COST: [AtomicU32; 8] = [const { AtomicU32::new(0) }; 8];

/// Adds `v` to word `i` of [`TICK_COST`].
fn add_cost(i: usize, v: u32) {
    if let Some(w) = TICK_COST.get(i) {
        w.fetch_add(v, Ordering::Relaxed);
    }
}

/// Every millisecond: time, then the control tick, then the timers due.
#[cortex_m_rt::exception]
fn SysTick() {
    static mut STAGE: NoStage = NoStage { moving: false, emitted: 0 };
    critical_section::with(|cs| {
        let m = MILLIS.borrow(cs);
        m.set(m.get() + 1);
    });
    let now = micros();
    STAGE.moving = false;
    let emitted = STAGE.emitted;
    let before = cortex_m::peripheral::SYST::get_current();
    // The emulated chip measures nothing: no supervision of supply or temperature, open loop.
    crate::app::control_tick(drive_core::Instant::from_micros(now), drive_core::faults::Inputs::default, STAGE);
    // SysTick counts down and has just reloaded: no wrap within the tick.
    let spent = before.saturating_sub(cortex_m::peripheral::SYST::get_current());
    let at = if STAGE.moving { 2 } else { 0 };
    add_cost(at, 1);
    add_cost(at + 1, spent);
    if let Some(max) = TICK_COST.get(4) {
        max.fetch_max(spent, Ordering::Relaxed);
    }
    // Wrapping to 32 bits: the reader takes the words as `i32`.
    let steps = STAGE.emitted.wrapping_sub(emitted) as u32;
    add_cost(6, steps);
    let handed = |i: usize| crate::app::HANDOVERS.get(i).map_or(0, |c| c.load(Ordering::Relaxed));
    if let (Some(missed), Some(planned)) = (TICK_COST.get(5), TICK_COST.get(7)) {
        missed.store(handed(1) + handed(2), Ordering::Relaxed);
        planned.store(handed(0), Ordering::Relaxed);
    }
    critical_section::with(|cs| {
        let mut q = QUEUE.borrow_ref_mut(cs);
        let (queue, next) = &mut *q;
        if now >= *next {
            *next = queue.next_expiration(now);
        }
    });
}
