//! The application, the same on every board: the drive shared between the control tick and the
//! Modbus task, the tick itself and the RTU slave task.
//!
//! The drive sits behind a lock that masks no interrupt. The tasks (thread mode) take it for one
//! call each and never across an await. The control tick (a timer interrupt above every other
//! one) only tries it: when a task holds it (serving a request that plans a motion takes about
//! 1.3 ms), the tick does not wait, and the power stage coasts at the last speed (`coast`);
//! the drive's next tick evaluates its motion at that tick's time, so the wait costs it nothing.
//! Since the tick preempts the tasks and never the reverse, a task always finds the lock free.
//! A parameter save works the same way: the request and a copy of the parameters are taken
//! under the lock, the flash is written without it, and the result is reported under it.

use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicU32, Ordering};

use defmt::warn;
use drive_core::ident::Identity;
use drive_core::maps::NativeMap;
use drive_core::motion::cubic::Table;
use drive_core::{Baud, DriveConfig, Instant, Params};
use embassy_futures::select::{Either, select};
use embassy_time::Timer;
use embedded_io_async::{Read, Write};

use crate::board::Serial;
use crate::frames::MAX_FRAME;
use crate::power::PowerStage;

/// The drive of the firmware: the native map, and the PVT point table (9 KB) in a static of its
/// own, lent to the drive, so that building the drive (about 3 KB) never passes the table through
/// the stack.
pub type Drive = drive_core::Drive<NativeMap, &'static mut Table>;

/// The drive, once `start` has built it. A reference, so the mutex's initial value (`None`) is
/// zero and lives in .bss: an `Option<Drive>` would copy its initial image from flash.
static DRIVE: spin::Mutex<Option<&'static mut Drive>> = spin::Mutex::new(None);

/// Control ticks run since power-up (the watchdog is fed only while this advances).
pub static TICKS: AtomicU32 = AtomicU32::new(0);

/// Control ticks that found the drive held by a task and coasted.
pub static COASTED: AtomicU32 = AtomicU32::new(0);

/// Who this firmware says it is (0x1022 hardware version from the board).
fn identity(hardware: &'static str) -> Identity {
    Identity {
        model_name: "OSD-42",
        user_application_name: "firmware",
        hardware_version: hardware,
        ..Identity::SIMULATOR
    }
}

/// Builds the drive from the parameters power-up loaded (`params`, storage status bits
/// `status`); `can_save` if the board has a parameter store (else 0x200F = 2 is refused).
/// Returns the serial line settings in force: the baud rate and the parity (0x2100).
pub fn start(hardware: &'static str, params: &Params, status: u8, can_save: bool) -> (Baud, u32) {
    let config = DriveConfig { identity: identity(hardware), can_save, ..DriveConfig::default() };
    // singleton! yields its memory once; uninitialised (the slot) or all zeros (the empty
    // table), it is .bss with no flash image.
    let (Some(slot), Some(table)) = (
        cortex_m::singleton!(: MaybeUninit<Drive> = MaybeUninit::uninit()),
        cortex_m::singleton!(: Table = Table::EMPTY),
    ) else {
        defmt::panic!("app::start called twice");
    };
    let drive = boot_into(slot, config, params, status, table);
    let line = (drive.baud(), drive.state().read(drive_core::od::Obj::Parity));
    DRIVE.lock().replace(drive);
    line
}

/// Builds the drive in `slot`, lending it `table`. The compiler builds the drive (about 3 KB) in
/// this frame and copies it into the static; out of line, so the copy is on the stack for this
/// call only.
#[inline(never)]
fn boot_into(
    slot: &'static mut MaybeUninit<Drive>,
    config: DriveConfig,
    params: &Params,
    status: u8,
    table: &'static mut Table,
) -> &'static mut Drive {
    slot.write(Drive::boot_with_table(config, NativeMap::new(), params, status, table))
}

/// Runs `f` on the drive, if it has been started. For the tasks (thread mode), never from an
/// interrupt: the control tick may hold the drive only while it preempts them.
pub fn with_drive<R>(f: impl FnOnce(&mut Drive) -> R) -> Option<R> {
    DRIVE.lock().as_deref_mut().map(f)
}

/// One control tick at `now` with what the board measures (`inputs`, read only if the tick runs
/// the drive): the drive's motion, supervision and loops, then the power stage. Called from the
/// tick interrupt; if a task holds the drive, the stage coasts instead, and the tick does not
/// count (the watchdog is fed by drive ticks).
pub fn control_tick(now: Instant, inputs: impl FnOnce() -> drive_core::faults::Inputs, stage: &mut impl PowerStage) {
    match DRIVE.try_lock() {
        Some(mut drive) => {
            if let Some(d) = drive.as_deref_mut() {
                run_tick(d, now, inputs, stage);
            }
        }
        None => {
            stage.coast_on();
            COASTED.fetch_add(1, Ordering::Relaxed);
        }
    }
}

/// A tick that runs the drive, then its outputs to the stage. Out of line: its frame (about
/// 1 KB) is on the stack only when the tick runs the drive, which it never does while a task is
/// deep in a request (the task holds the drive then, and the tick coasts with a small frame).
/// The inputs are made here, so that what a board never measures is known to the compiler.
#[inline(never)]
fn run_tick(
    drive: &mut Drive,
    now: Instant,
    inputs: impl FnOnce() -> drive_core::faults::Inputs,
    stage: &mut impl PowerStage,
) {
    let out = drive.tick_with(now, &inputs());
    stage.apply(&out);
    TICKS.fetch_add(1, Ordering::Relaxed);
}

/// Now, on the drive's clock (embassy-time's, in microseconds).
pub fn now() -> Instant {
    Instant::from_micros(embassy_time::Instant::now().as_micros())
}

/// Copies the drive's pending reply out of the lock, so it is sent without holding the drive.
fn take_reply(d: &mut Drive, out: &mut [u8; MAX_FRAME]) -> usize {
    match d.take_reply() {
        Some(r) => out.get_mut(..r.len()).map_or(0, |dst| {
            dst.copy_from_slice(r);
            r.len()
        }),
        None => 0,
    }
}

async fn send(serial: &mut Serial, reply: &[u8; MAX_FRAME], n: usize) {
    if let Some(bytes) = reply.get(..n)
        && !bytes.is_empty()
        && serial.write_all(bytes).await.is_err()
    {
        warn!("uart: write failed");
    }
}

/// Carries out what the drive asked of its platform (a save), after the reply went out. The job
/// (request and parameter copy) is taken under the lock and the flash written without it, so the
/// control tick keeps its interrupt; a page erase still stalls every flash fetch for ~22 ms,
/// which is why the drive refuses saves while the axis moves.
///
/// Out of line: the save's state (about 2 KB) is on the stack while a save runs, not in the
/// Modbus task's frame for every request.
#[inline(never)]
pub fn serve_store(store: &mut crate::board::ParamStore) {
    use drive_core::store::Job;
    while let Some(job) = with_drive(Job::take).flatten() {
        // The flash driver is blocking, so the save completes in one poll. Polled here, not
        // awaited, the job and the save's state (about 1.7 KB) sit on the stack for the moment
        // instead of in the task's static storage.
        let done = embassy_futures::block_on(store.run(&job));
        with_drive(|d| job.finish(d, done.is_ok()));
        match (job, done) {
            (Job::Save(_), Err(_)) => warn!("parameter save failed"),
            (Job::SavePosition(_), Err(_)) => warn!("power-down position not saved"),
            (Job::SaveFaults(_), Err(_)) => warn!("fault history not saved"),
            // The drive refuses 0x200F = 1: there is no boot loader to jump to yet.
            _ => {}
        }
    }
}

/// Whether the drive asked for a flash operation that has not been carried out yet (a parameter
/// save, the power-down position, the fault history).
fn save_pending() -> bool {
    with_drive(|d| d.has_system_request()).unwrap_or(false)
}

/// The RTU slave on a line with baud timing: bytes in with their arrival time, t3.5 from a
/// timer on `drive.deadline()`, replies out, then the saves a request asked for into `store`.
#[cfg(not(feature = "qemu"))]
#[embassy_executor::task]
pub async fn modbus(mut serial: Serial, mut store: crate::board::ParamStore) -> ! {
    // Bytes come one or a few at a time: the task reads them as they arrive.
    let mut buf = [0u8; 16];
    let mut reply = [0u8; MAX_FRAME];
    loop {
        let deadline = with_drive(|d| d.deadline()).flatten();
        let timeout = async {
            match deadline {
                Some(at) => Timer::at(embassy_time::Instant::from_micros(at.as_micros())).await,
                None => core::future::pending().await,
            }
        };
        let n = match select(serial.read(&mut buf), timeout).await {
            // A chunk shares one stamp: with a read woken per byte, chunks are one byte unless
            // the task ran late, and then the stamp is late by at most that delay.
            Either::First(Ok(n)) => {
                let bytes = buf.get(..n).unwrap_or_default();
                with_drive(|d| {
                    d.on_rx(now(), bytes);
                    take_reply(d, &mut reply)
                })
            }
            Either::First(Err(_)) => {
                warn!("uart: receive error");
                None
            }
            Either::Second(()) => with_drive(|d| {
                d.on_timer(now());
                take_reply(d, &mut reply)
            }),
        };
        send(&mut serial, &reply, n.unwrap_or(0)).await;
        // The reply must be on the wire before a page erase stalls the flash: the USART
        // interrupt that feeds the transmitter runs from flash too, and a stalled reply would
        // reach the master with a gap that breaks its frame.
        if save_pending() && serial.flush().await.is_err() {
            warn!("uart: flush failed");
        }
        serve_store(&mut store);
    }
}

/// Silence that ends a request whose length its function code does not tell (or garbage) on a
/// line without baud timing. QEMU paces bytes about 1 ms apart; 20 ms is no pause a master makes
/// inside a frame.
#[cfg(feature = "qemu")]
const SILENCE: embassy_time::Duration = embassy_time::Duration::from_millis(20);
/// Silence that ends a request known to be incomplete: a loaded host can stall QEMU's serial
/// line for tens of milliseconds inside a frame.
#[cfg(feature = "qemu")]
const SILENCE_PARTIAL: embassy_time::Duration = embassy_time::Duration::from_millis(250);

/// The RTU slave on a line without baud timing (QEMU): a request ends by its length (see
/// `frames`) or by a long silence, then goes to the drive in one burst t3.5 before now.
#[cfg(feature = "qemu")]
#[embassy_executor::task]
pub async fn modbus(mut serial: Serial, mut store: crate::board::ParamStore) -> ! {
    // Bytes come one or a few at a time: the task reads them as they arrive.
    let mut buf = [0u8; 16];
    let mut reply = [0u8; MAX_FRAME];
    let mut frame = crate::frames::Assembler::new();
    loop {
        let silence = if frame.expects_more() { SILENCE_PARTIAL } else { SILENCE };
        let n = match select(serial.read(&mut buf), Timer::after(silence)).await {
            Either::First(Ok(n)) => {
                let mut sent = None;
                for &b in buf.get(..n).unwrap_or_default() {
                    if frame.push(b) {
                        sent = deliver(&mut frame, &mut reply);
                    }
                }
                sent
            }
            Either::First(Err(_)) => None,
            Either::Second(()) if !frame.is_empty() => deliver(&mut frame, &mut reply),
            Either::Second(()) => None,
        };
        send(&mut serial, &reply, n.unwrap_or(0)).await;
        if save_pending() && serial.flush().await.is_err() {
            warn!("uart: flush failed");
        }
        serve_store(&mut store);
    }
}

/// Hands a complete request to the drive as a burst that ended t3.5 ago, and takes its reply.
#[cfg(feature = "qemu")]
fn deliver(frame: &mut crate::frames::Assembler, reply: &mut [u8; MAX_FRAME]) -> Option<usize> {
    let n = with_drive(|d| {
        let t = now().as_micros();
        let t35 = d.baud().t35_micros();
        d.on_rx(Instant::from_micros(t.saturating_sub(t35)), frame.bytes());
        d.on_timer(Instant::from_micros(t.max(t35)));
        take_reply(d, reply)
    });
    frame.clear();
    n
}
