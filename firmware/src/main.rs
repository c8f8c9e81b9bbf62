//! The drive on an STM32: Embassy wires the board's peripherals to `drive-core`.
//!
//! All the drive's logic lives in `drive-core`; this crate only moves bytes and time into it,
//! replies out, and the control tick's outputs to the power stage. Two boards share the
//! application (`app`): the STM32G474CE drive (feature `g474`, the default, `board::g474`) and
//! QEMU's b-l475e-iot01a (feature `qemu`, `board::qemu`), which has no timers and no baud timing
//! and so gets its own small board layer on the PAC.
//!
//! On the host the crate is an empty program: its embedded dependencies are target-only, so
//! `cargo test --workspace` can build every member without a cross toolchain.
#![cfg_attr(target_os = "none", no_std, no_main)]

/// Host stub: there is nothing to run off the microcontroller (the drive on a host is `hal-sim`).
#[cfg(not(target_os = "none"))]
fn main() {}

#[cfg_attr(not(feature = "qemu"), allow(dead_code, reason = "used by the QEMU build and the host tests"))]
mod frames;

#[allow(dead_code, reason = "the table is read whole by the tests; the board uses its store's region")]
mod flash_map;

#[cfg(target_os = "none")]
mod app;
#[cfg(target_os = "none")]
mod power;
#[cfg(target_os = "none")]
mod stack;
#[cfg(target_os = "none")]
mod update;

#[cfg(all(target_os = "none", feature = "g474", feature = "qemu"))]
compile_error!("features `g474` and `qemu` select different chips: build with `--no-default-features --features qemu`");

#[cfg(target_os = "none")]
mod board {
    #[cfg(feature = "g474")]
    mod g474;
    #[cfg(feature = "g474")]
    pub use g474::*;
    #[cfg(feature = "qemu")]
    mod qemu;
    #[cfg(feature = "qemu")]
    pub use qemu::*;
}

/// Panics and faults: the power stage goes off before anything else, then the panic is logged
/// with where it happened (file, line and message), and the core halts until the independent
/// watchdog (or, under QEMU, nothing) restarts it.
#[cfg(target_os = "none")]
mod fault {
    use crate::board;

    #[panic_handler]
    fn panic(info: &core::panic::PanicInfo) -> ! {
        board::power_off();
        defmt::error!("{}", defmt::Display2Format(info));
        halt()
    }

    #[defmt::panic_handler]
    fn defmt_panic() -> ! {
        board::power_off();
        halt()
    }

    #[cortex_m_rt::exception]
    unsafe fn HardFault(frame: &cortex_m_rt::ExceptionFrame) -> ! {
        board::power_off();
        defmt::error!("hard fault at pc {=u32:#x} (lr {=u32:#x})", frame.pc(), frame.lr());
        halt()
    }

    fn halt() -> ! {
        cortex_m::interrupt::disable();
        loop {
            cortex_m::asm::wfi();
        }
    }
}

#[cfg(all(target_os = "none", feature = "g474"))]
mod run {
    use core::sync::atomic::Ordering;

    use defmt::{info, unwrap};
    use defmt_rtt as _;
    use drive_core::store::{Loaded, Store};
    use embassy_embedded_hal::adapter::BlockingAsync;
    use embassy_executor::Spawner;
    use embassy_futures::select::{Either, select};
    use embassy_stm32::exti::ExtiInput;
    use embassy_stm32::flash::{Blocking, Flash};
    use embassy_stm32::mode::Async;
    use embassy_time::{Duration, Ticker, Timer};

    use crate::app;
    use crate::board::{self, Board, Inputs, ParamStore, Sense};

    /// How long FSET must be held low from power-up to restore the factory settings (§3.11).
    const FSET_HOLD: Duration = Duration::from_secs(5);

    #[embassy_executor::main]
    async fn main(spawner: Spawner) {
        crate::stack::paint();
        let Board { flash, mut uart, mut stage, mut inputs, encoder, sense, mut watchdog } = board::init();
        // Power-up, before the drive answers anything: the FSET check and the parameters from
        // flash, then the drive, then the UART at their baud rate and parity.
        let (store, mut loaded) = power_up(flash, &mut inputs.fset);
        // The bridges' over-current trip from the saved setting (a change takes effect at the
        // next power-up).
        stage.bridges.set_over_current(loaded.params.get(drive_core::od::Obj::OverCurrent));
        // The current loop from its objects: tuned (the measurements written into them) or as set.
        stage.power_up_loop(&mut loaded.params);
        if !stage.has_loop() {
            defmt::warn!("no current loop: the bridges stay off, and the drive reads both windings open");
        }
        let (drive, baud, parity) = app::start(&mut loaded.params, loaded.status, true);
        drive.state_mut().set_current_loop(true);
        board::set_serial(&mut uart, baud, parity);
        info!("drive up: {} baud, parity {}, storage status {:#x}", baud.get(), parity, loaded.status);
        board::start_tick(stage, encoder);
        watchdog.unleash();
        spawner.spawn(unwrap!(app::modbus(drive, uart, store)));
        spawner.spawn(unwrap!(watch_inputs(inputs)));
        sense_loop(sense, watchdog).await
    }

    /// The FSET check, then the store's power-up (with FSET held, factory values saved).
    ///
    /// Nothing else runs yet (no task spawned, the watchdog not started), so this is polled to
    /// completion rather than awaited, and out of line: its state (about 2 KB) is on the stack for
    /// this call only, neither in the main task's static storage nor in its poll frame.
    #[inline(never)]
    fn power_up(
        flash: Flash<'static, Blocking>,
        fset: &mut ExtiInput<'static, Async>,
    ) -> (&'static mut ParamStore, Loaded) {
        // Where the Modbus task will use it (its buffer holds a whole record): kept once, not
        // moved from frame to frame.
        let Some(slot) = cortex_m::singleton!(: Option<ParamStore> = None) else {
            defmt::panic!("the store made twice");
        };
        let Ok(store) = Store::new(BlockingAsync::new(flash), board::STORE) else {
            defmt::panic!("the store's flash range is not whole pages");
        };
        let store = slot.insert(store);
        embassy_futures::block_on(async {
            let fset_low = fset_held(fset).await;
            let loaded = store.power_up(fset_low).await;
            if let Some(table) = app::program_memory(&loaded.params) {
                store.load_program(table).await;
            }
            (store, loaded)
        })
    }

    /// Whether FSET is held low from power-up for [`FSET_HOLD`]; released earlier, nothing is reset.
    async fn fset_held(fset: &mut ExtiInput<'static, Async>) -> bool {
        // Let the pull-up charge the pin before reading it.
        Timer::after_millis(1).await;
        if fset.is_high() {
            return false;
        }
        info!("FSET low at power-up: factory settings if held {} s", FSET_HOLD.as_secs());
        matches!(select(fset.wait_for_high(), Timer::after(FSET_HOLD)).await, Either::Second(()))
    }

    /// Every 10 ms: the ADCs' last bus voltage and bridge temperature to the control tick (which
    /// also reads the encoder itself) and the analog input into 0x605F; the watchdog is fed only
    /// while the control tick runs.
    async fn sense_loop(
        mut sense: Sense,
        mut watchdog: embassy_stm32::wdg::IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG>,
    ) -> ! {
        let mut ticker = Ticker::every(Duration::from_millis(10));
        let mut last_ticks = app::TICKS.load(Ordering::Relaxed);
        let mut n: u32 = 0;
        loop {
            ticker.next().await;
            n = n.wrapping_add(1);
            let (v, t, a) = sense.read_adc();
            Sense::publish(v, t, a);
            if n.is_multiple_of(100) {
                let cost = board::TICK_CYCLES_MAX.load(Ordering::Relaxed);
                info!(
                    "bus {} mV, bridges {} °C{}, longest tick {} cycles, stack peak {} B",
                    board::supply_mv(v),
                    board::bridge_temperature_c(t),
                    if board::power_stage::tripped() { " (over-current trip)" } else { "" },
                    cost,
                    crate::stack::peak()
                );
            }
            let ticks = app::TICKS.load(Ordering::Relaxed);
            if ticks != last_ticks {
                watchdog.pet();
            }
            last_ticks = ticks;
        }
    }

    /// FSET after power-up is only logged (it acts at power-up, `fset_held`). The EXT inputs
    /// are the control tick's: it samples them every tick (`board::measure`).
    #[embassy_executor::task]
    async fn watch_inputs(inputs: Inputs) -> ! {
        let Inputs { mut fset } = inputs;
        loop {
            fset.wait_for_falling_edge().await;
            info!("FSET pressed");
        }
    }
}

#[cfg(all(target_os = "none", feature = "qemu"))]
mod run {
    use core::sync::atomic::{AtomicBool, Ordering};

    use defmt::unwrap;
    use defmt_rtt as _;
    use embassy_embedded_hal::adapter::BlockingAsync;
    use embassy_executor::raw::Executor;

    use crate::{app, board};

    /// Set when a task was woken: the executor has work.
    static WORK: AtomicBool = AtomicBool::new(true);

    /// Called by embassy when a task is woken (from a task or an interrupt).
    #[unsafe(export_name = "__pender")]
    fn pender(_context: *mut ()) {
        WORK.store(true, Ordering::Release);
    }

    /// The raw executor, sleeping with WFI: QEMU runs WFE (the thread executor's sleep) as a
    /// no-op, which would spin the host CPU and starve QEMU's serial I/O.
    #[cortex_m_rt::entry]
    fn main() -> ! {
        crate::stack::paint();
        let Some(executor) = cortex_m::singleton!(: Executor = Executor::new(core::ptr::null_mut())) else {
            defmt::panic!("executor created twice");
        };
        let executor: &'static Executor = executor;
        power_up(executor.spawner());
        loop {
            WORK.store(false, Ordering::Release);
            // SAFETY: polled from this one thread only, never re-entered.
            unsafe { executor.poll() };
            // A wake after the poll sets WORK; with interrupts masked WFI still wakes on one.
            cortex_m::interrupt::free(|_| {
                if !WORK.load(Ordering::Acquire) {
                    cortex_m::asm::wfi();
                }
            });
        }
    }

    /// The parameters from the store, the drive, the board, and the Modbus task with the store.
    ///
    /// Out of line: the store and the loaded parameters are on the stack for this call only, not
    /// in `main`'s frame under every task the executor polls.
    #[inline(never)]
    fn power_up(spawner: embassy_executor::Spawner) {
        let (store, mut loaded) = load();
        let (drive, _, _) = app::start(&mut loaded.params, loaded.status, true);
        let serial = board::init();
        spawner.spawn(unwrap!(app::modbus(drive, serial, store)));
    }

    /// The store and what power-up loads from it. Out of line, as on the board: the state of the
    /// loading (about 3 KB) is on the stack for this call only, not under the drive being built.
    #[inline(never)]
    fn load() -> (&'static mut board::ParamStore, drive_core::store::Loaded) {
        // QEMU does not model the flash: the store runs on RAM, empty at every boot.
        let (Some(flash), Some(slot)) =
            (board::param_flash(), cortex_m::singleton!(: Option<board::ParamStore> = None))
        else {
            defmt::panic!("the store's RAM taken twice");
        };
        let Ok(store) = drive_core::store::Store::new(BlockingAsync::new(flash), board::STORE) else {
            defmt::panic!("the store's range is not whole pages");
        };
        let store = slot.insert(store);
        let loaded = embassy_futures::block_on(async {
            let loaded = store.power_up(false).await;
            if let Some(table) = app::program_memory(&loaded.params) {
                store.load_program(table).await;
            }
            loaded
        });
        (store, loaded)
    }
}
