//! The drive on an STM32G431CB: Embassy wires the board's peripherals to `drive-core`.
//!
//! All the drive's logic lives in `drive-core`; this crate only moves bytes and time into it and
//! replies out. Built for `thumbv7em-none-eabihf` (see `board` for the pin map).
//!
//! On the host the crate is an empty program: its embedded dependencies are target-only, so
//! `cargo test --workspace` can build every member without a cross toolchain.
#![cfg_attr(target_os = "none", no_std, no_main)]

/// Host stub: there is nothing to run off the microcontroller (the drive on a host is `hal-sim`).
#[cfg(not(target_os = "none"))]
fn main() {}

#[cfg(target_os = "none")]
mod board;

#[cfg(target_os = "none")]
mod app {
    use defmt::{info, unwrap, warn};
    use defmt_rtt as _;
    use drive_core::ident::Identity;
    use drive_core::od::Obj;
    use drive_core::store::Store;
    use drive_core::{Drive, DriveConfig, Instant, SystemRequest};
    use embassy_embedded_hal::adapter::BlockingAsync;
    use embassy_executor::Spawner;
    use embassy_futures::select::{Either, select, select4};
    use embassy_stm32::exti::ExtiInput;
    use embassy_stm32::flash::{Blocking, Flash};
    use embassy_stm32::mode::Async;
    use embassy_stm32::usart::BufferedUart;
    use embassy_time::{Duration, Timer};
    use embedded_io_async::{Read, Write};
    use panic_probe as _;

    use crate::board::{self, Board, Inputs};

    /// Who this board says it is (0x1022 hardware version "G431").
    const IDENTITY: Identity = Identity {
        model_name: "OSD-42 G431",
        user_application_name: "firmware",
        hardware_version: "G431",
        ..Identity::SIMULATOR
    };

    /// The parameter store on the flash's last pages.
    type FlashStore = Store<BlockingAsync<Flash<'static, Blocking>>>;

    /// How long FSET must be held low at power-up to restore the factory settings (§3.11).
    const FSET_HOLD: Duration = Duration::from_secs(5);

    #[embassy_executor::main]
    async fn main(spawner: Spawner) {
        let Board { flash, mut uart, motor, mut inputs } = board::init();
        let fset_low = fset_held(&mut inputs.fset).await;
        let Ok(mut store) = Store::new(BlockingAsync::new(flash), board::STORE) else {
            defmt::panic!("the store's flash range is not whole pages");
        };
        // The parameters are loaded before the drive answers anything.
        let loaded = store.power_up(fset_low).await;
        let config = DriveConfig { identity: IDENTITY, can_save: true, ..DriveConfig::default() };
        // One static drive (its PVT table is 10 KB): a task taking it by value would keep a copy
        // in its future and in main's.
        let drive = unwrap!(cortex_m::singleton!(: Drive = Drive::boot(config, &loaded.params, loaded.status)));
        board::set_serial(&mut uart, drive.baud(), drive.state().read(Obj::Parity));
        info!(
            "drive up: node {}, {} baud, storage status {:#x}",
            drive.address().get(),
            drive.baud().get(),
            loaded.status
        );
        spawner.spawn(unwrap!(modbus(uart, drive, store)));
        // Held, not dropped: a dropped pin returns to analog mode and the driver's inputs would float.
        let _motor = motor;
        watch_inputs(inputs).await
    }

    /// Whether FSET is held low from power-up for [`FSET_HOLD`] (released earlier: no reset).
    async fn fset_held(fset: &mut ExtiInput<'static, Async>) -> bool {
        // Let the pull-up charge the pin before reading it.
        Timer::after_millis(1).await;
        if fset.is_high() {
            return false;
        }
        info!("FSET low at power-up: factory settings if held {} s", FSET_HOLD.as_secs());
        matches!(select(fset.wait_for_high(), Timer::after(FSET_HOLD)).await, Either::Second(()))
    }

    /// The RTU slave: bytes in with their arrival time, t3.5 from a timer, replies out.
    ///
    /// t3.5 comes from an embassy-time timer on `drive.deadline()`. The USART's receiver timeout
    /// (RTOF, reachable through `unstable-pac`) would time the silence in hardware; that is a later
    /// issue, and needs its own interrupt handler because the buffered driver clears RTOF unseen.
    #[embassy_executor::task]
    async fn modbus(mut uart: BufferedUart<'static>, drive: &'static mut Drive, mut store: FlashStore) -> ! {
        let mut buf = [0u8; 64];
        loop {
            let deadline = drive.deadline();
            let timeout = async {
                match deadline {
                    Some(at) => Timer::at(embassy_time::Instant::from_micros(at.as_micros())).await,
                    None => core::future::pending().await,
                }
            };
            match select(uart.read(&mut buf), timeout).await {
                // A chunk shares one stamp: with a read woken per byte, chunks are one byte unless
                // the task ran late, and then the stamp is late by at most that delay.
                Either::First(Ok(n)) => drive.on_rx(now(), buf.get(..n).unwrap_or_default()),
                Either::First(Err(e)) => warn!("uart: {}", e),
                Either::Second(()) => drive.on_timer(now()),
            }
            if let Some(reply) = drive.take_reply()
                && let Err(e) = uart.write_all(reply).await
            {
                warn!("uart: {}", e);
            }
            // After the reply: a save blocks this task for up to ~25 ms (a page erase).
            match store.serve(drive).await {
                Some((SystemRequest::Save, Err(_))) => warn!("parameter save failed"),
                Some((SystemRequest::SavePosition(_), Err(_))) => warn!("power-down position not saved"),
                _ => {}
            }
        }
    }

    /// Now, on the drive's clock (embassy-time's, in microseconds).
    fn now() -> Instant {
        Instant::from_micros(embassy_time::Instant::now().as_micros())
    }

    /// Logs input changes; they reach the GPIO object (0x6031) in a later issue.
    async fn watch_inputs(inputs: Inputs) -> ! {
        let Inputs { ext: [mut e1, mut e2, mut e3], mut fset } = inputs;
        loop {
            select4(e1.wait_for_any_edge(), e2.wait_for_any_edge(), e3.wait_for_any_edge(), fset.wait_for_any_edge())
                .await;
            info!("inputs: EXT1..3 {} {} {}, FSET {}", e1.is_high(), e2.is_high(), e3.is_high(), fset.is_high());
        }
    }
}
