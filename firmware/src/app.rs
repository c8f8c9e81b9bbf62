//! The application, the same on every board: the drive's two owners and the handoff between
//! them, the control tick, and the RTU slave task.
//!
//! The control tick (a timer interrupt above every other one) owns its controller
//! ([`TickSide`]: the motion it runs, supervision, the loops). The Modbus task owns the drive:
//! framing, the dictionary, the planner, and a model of the controller that requests read and
//! plan on. Neither ever waits for the other. Before the task serves a request it lends the tick
//! its model ([`LENT`]), and the tick, at its next start, syncs it (tells it what it did) and
//! hands it back; after the request, the task lends it again and the tick takes in what the
//! request changed, a planned motion at the tick it was planned for (the board's
//! `PLAN_MARGIN_US` after the request: longer than planning takes). See
//! `drive_core::controller::handoff`.
//!
//! The PVT point table is shared: the task stores points in slots the tick does not read yet,
//! and a sync tells the tick they are there. The multi-segment programs have a memory of their
//! own, which only the task uses.

use core::future::poll_fn;
use core::mem::MaybeUninit;
use core::ptr::null_mut;
use core::sync::atomic::{AtomicPtr, AtomicU32, Ordering};
use core::task::Poll;

use defmt::warn;

use crate::update::Updates;
use drive_core::controller::Shared;
use drive_core::controller::handoff::{Handover, Lent, TickSide};
use drive_core::ident::Identity;
use drive_core::maps::Maps;
use drive_core::state::ProgramMemory;
use drive_core::{Baud, DriveConfig, Instant, Params};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::signal::Signal;
use embassy_sync::waitqueue::AtomicWaker;
use embedded_io_async::Write;

use crate::board::Serial;
use crate::power::PowerStage;

/// The drive of the firmware: every register map (0x2190 chooses one at power-up), and the PVT
/// point table and the programs' memory in statics of their own.
pub type Drive = drive_core::Drive<Maps, &'static Shared, &'static ProgramMemory>;

/// The PVT points (9 KB: the task stores, the tick reads) and the recordings (32 KB: the
/// tick records, the task reads out).
static SHARED: Shared = Shared::new();

/// The multi-segment programs (1 KB): loaded at power-up, then the task's.
static PROGRAMS: ProgramMemory = ProgramMemory::new();

/// The tick's own, once `start` has built it: only the tick interrupt takes it after that.
static TICK: critical_section::Mutex<core::cell::RefCell<Option<&'static mut TickSide>>> =
    critical_section::Mutex::new(core::cell::RefCell::new(None));

/// The model the task lends to the tick (a `Lent`), or null: set by the task, cleared by the
/// tick once synced.
static LENT: AtomicPtr<()> = AtomicPtr::new(null_mut());
/// Wakes the task when the tick has synced its model.
static SYNCED: AtomicWaker = AtomicWaker::new();
/// Raised by the tick when the task should sync without waiting for a request (power failing,
/// a new alarm: their saves).
static ATTENTION: Signal<CriticalSectionRawMutex, ()> = Signal::new();

/// Control ticks run since power-up (the watchdog is fed only while this advances).
pub static TICKS: AtomicU32 = AtomicU32::new(0);
/// Plans handed over at their first tick, late (the task lent them after it), and dropped
/// (the tick had stopped on its own since they were planned).
pub static HANDOVERS: [AtomicU32; 3] = [const { AtomicU32::new(0) }; 3];

/// Who this firmware says it is (0x1022 hardware version from the board; the revision says
/// when the build takes images signed with the repository's test key).
static IDENTITY: Identity = Identity {
    model_name: "OSD-42",
    user_application_name: "firmware",
    hardware_version: crate::board::HARDWARE,
    revision: if crate::update::TEST {
        concat!(env!("CARGO_PKG_VERSION"), " test-key")
    } else {
        env!("CARGO_PKG_VERSION")
    },
    ..Identity::SIMULATOR
};

/// Builds the drive from the parameters power-up loaded (`params`, storage status bits
/// `status`) and hands the tick its side; `can_save` if the board has a parameter store (else
/// 0x200F = 2 is refused). Returns the drive, for the Modbus task, and the serial line settings
/// in force: the baud rate and the parity (0x2100).
#[allow(clippy::mut_from_ref, reason = "the drive is a singleton's memory, not borrowed from the inputs")]
pub fn start(params: &mut Params, status: u8, can_save: bool) -> (&'static mut Drive, Baud, u32) {
    let config = DriveConfig { identity: &IDENTITY, can_save, ..DriveConfig::default() };
    // singleton! yields its memory once; uninitialised, it is .bss with no flash image.
    let (Some(slot), Some(tick)) = (
        cortex_m::singleton!(: MaybeUninit<Drive> = MaybeUninit::uninit()),
        cortex_m::singleton!(: MaybeUninit<TickSide> = MaybeUninit::uninit()),
    ) else {
        defmt::panic!("app::start called twice");
    };
    let drive = boot_into(slot, config, params, status);
    drive.state_mut().set_plan_margin(crate::board::PLAN_MARGIN_US);
    let tick = tick_side_into(tick, drive);
    critical_section::with(|cs| TICK.borrow_ref_mut(cs).replace(tick));
    let (baud, parity) = (drive.baud(), drive.state().read(drive_core::od::Obj::Parity));
    (drive, baud, parity)
}

/// The programs' memory, if the map `params` choose offers programs: power-up loads the saved
/// program into it before the drive is built.
pub fn program_memory(params: &Params) -> Option<&'static ProgramMemory> {
    Maps::has_program_id(params.get(drive_core::od::Obj::RegisterMap)).then_some(&PROGRAMS)
}

/// Builds the drive in `slot`, lending it the table and the programs' memory.
fn boot_into(
    slot: &'static mut MaybeUninit<Drive>,
    config: DriveConfig,
    params: &mut Params,
    status: u8,
) -> &'static mut Drive {
    let map = Maps::by_id(params.get(drive_core::od::Obj::RegisterMap));
    Drive::boot_in_with_memory(slot, config, map, params, status, &SHARED, &PROGRAMS)
}

/// The tick's side of `drive` in `slot`; out of line as [`boot_into`].
#[inline(never)]
fn tick_side_into(slot: &'static mut MaybeUninit<TickSide>, drive: &Drive) -> &'static mut TickSide {
    slot.write(drive.state().tick_side())
}

/// One control tick at `now` with what the board measures (`inputs`): a sync first if the task
/// lent its model, then the controller's tick, then the power stage. Called from the tick
/// interrupt; it never waits for the task.
pub fn control_tick(now: Instant, inputs: impl FnOnce() -> drive_core::faults::Inputs, stage: &mut impl PowerStage) {
    critical_section::with(|cs| {
        if let Some(tick) = TICK.borrow_ref_mut(cs).as_deref_mut() {
            run_tick(tick, now, inputs, stage);
        }
    });
}

/// A tick of `tick`, then its outputs to the stage. Out of line, with the inputs made here, so
/// that what a board never measures is known to the compiler.
#[inline(never)]
fn run_tick(
    tick: &mut TickSide,
    now: Instant,
    inputs: impl FnOnce() -> drive_core::faults::Inputs,
    stage: &mut impl PowerStage,
) {
    let lent = LENT.load(Ordering::Acquire);
    if !lent.is_null() {
        // SAFETY: the task stored a pointer to a live `Lent` and touches neither it nor what it
        // borrows until it finds LENT null again (`sync`), which only this interrupt makes it.
        let lent = unsafe { &mut *lent.cast::<Lent<'static>>() };
        let handover = tick.sync(now, lent);
        if handover != Handover::Waiting {
            let counter = match handover {
                Handover::Planned => HANDOVERS.first(),
                Handover::Late(_) => HANDOVERS.get(1),
                Handover::Dropped => HANDOVERS.get(2),
                Handover::Waiting | Handover::Done => None,
            };
            if let Some(c) = counter {
                c.fetch_add(1, Ordering::Relaxed);
            }
            LENT.store(null_mut(), Ordering::Release);
            SYNCED.wake();
        }
    }
    let out = tick.tick(now, &inputs(), &SHARED);
    stage.apply(&out);
    if tick.needs_bus() {
        ATTENTION.signal(());
    }
    TICKS.fetch_add(1, Ordering::Relaxed);
}

/// Lends the drive's model to the tick and waits until the tick has synced it (at most one tick,
/// or until the first tick of a motion planned into it), then acts on what the tick reported.
pub async fn sync(drive: &mut Drive) {
    lend(&mut drive.lend()).await;
    drive.state_mut().synced();
}

/// Lends `lent` to the tick until it has synced it.
///
/// Awaited to the end wherever it is called (never raced in a `select`): dropped while the
/// model is lent, the tick would write into a model the task uses again.
async fn lend(lent: &mut Lent<'_>) {
    LENT.store(core::ptr::from_mut(lent).cast(), Ordering::Release);
    poll_fn(|cx| {
        SYNCED.register(cx.waker());
        if LENT.load(Ordering::Acquire).is_null() { Poll::Ready(()) } else { Poll::Pending }
    })
    .await;
}

/// After the drive had its say: the reply out while the tick takes in what the request changed
/// (a motion from the tick it was planned for), then the flash operations the request asked for.
async fn after_request(
    drive: &mut Drive,
    serial: &mut Serial,
    store: &mut crate::board::ParamStore,
    updates: &mut Updates,
) {
    let changed = drive.has_changes();
    let (reply, mut lent) = drive.reply_and_lend();
    let send = async {
        if let Some(bytes) = reply
            && serial.write_all(bytes).await.is_err()
        {
            warn!("uart: write failed");
        }
    };
    let hand_over = async {
        if changed {
            lend(&mut lent).await;
        }
    };
    embassy_futures::join::join(send, hand_over).await;
    if changed {
        drive.state_mut().synced();
    }
    // The reply must be on the wire before a page erase stalls the flash: the USART
    // interrupt that feeds the transmitter runs from flash too, and a stalled reply would
    // reach the master with a gap that breaks its frame.
    if drive.has_system_request() {
        if serial.flush().await.is_err() {
            warn!("uart: flush failed");
        }
        serve_store(drive, store);
    }
    // The DFU slot and the update state lie in bank 2 (QEMU: RAM), beside the running code.
    if updates.serve(drive, store.flash()).await {
        if serial.flush().await.is_err() {
            warn!("uart: flush failed");
        }
        cortex_m::peripheral::SCB::sys_reset();
    }
}

/// Now, on the drive's clock (embassy-time's, in microseconds).
pub fn now() -> Instant {
    Instant::from_micros(embassy_time::Instant::now().as_micros())
}

/// Carries out what the drive asked of its platform (a save), after the reply went out; the
/// control tick keeps running meanwhile, though a page erase stalls every flash fetch for
/// ~22 ms, which is why the drive refuses saves while the axis moves.
///
/// Out of line: the save's state (about 2 KB) is on the stack while a save runs, not in the
/// Modbus task's frame for every request.
#[inline(never)]
pub fn serve_store(drive: &mut Drive, store: &mut crate::board::ParamStore) {
    use drive_core::store::Job;
    while let Some(job) = Job::take(drive) {
        // The flash driver is blocking, so the save completes in one poll. Polled here, not
        // awaited, the job and the save's state (about 1.7 KB) sit on the stack for the moment
        // instead of in the task's static storage.
        let done = embassy_futures::block_on(store.run(&job, drive.state().program_memory()));
        job.finish(drive, done.is_ok());
        match (job, done) {
            (Job::Save(_), Err(_)) => warn!("parameter save failed"),
            (Job::SavePosition(_), Err(_)) => warn!("power-down position not saved"),
            (Job::SaveFaults(_), Err(_)) => warn!("fault history not saved"),
            // Seed 004's 0541h: the reply has gone out; start again as from power-up.
            (Job::Restart, _) => cortex_m::peripheral::SCB::sys_reset(),
            // The drive refuses 0x200F = 1: there is no boot loader to jump to yet.
            _ => {}
        }
    }
}

/// The RTU slave on a line with baud timing: bytes in with their arrival time, t3.5 from a
/// timer on `drive.deadline()`, the model synced before a request is served, replies out, the
/// request's changes handed to the tick, then the saves a request asked for into `store`.
#[cfg(not(feature = "qemu"))]
#[embassy_executor::task]
pub async fn modbus(drive: &'static mut Drive, mut serial: Serial, store: &'static mut crate::board::ParamStore) -> ! {
    use embassy_futures::select::{Either3, select3};
    use embassy_time::Timer;
    use embedded_io_async::Read;
    // Bytes come one or a few at a time: the task reads them as they arrive.
    let mut buf = [0u8; 16];
    let mut updates = Updates::power_up(store.flash(), drive);
    loop {
        // The end of a frame, or the bus side's own work in time (a homing's checks, the analog
        // input), whichever comes first.
        let deadline = drive.deadline().into_iter().chain(drive.state().service_due()).min();
        let timeout = async {
            match deadline {
                Some(at) => Timer::at(embassy_time::Instant::from_micros(at.as_micros())).await,
                None => core::future::pending().await,
            }
        };
        let event = select3(serial.read(&mut buf), timeout, ATTENTION.wait()).await;
        // A chunk shares one stamp: with a read woken per byte, chunks are one byte unless the
        // task ran late, and then the stamp is late by at most that delay.
        let now = now();
        // The model synced (one place that awaits it, for the task's size): before a frame that
        // completes a request, a request that ended or the bus side's own work in time (either
        // reads the tick's state), and when the tick asks.
        let synced = match event {
            Either3::First(Ok(_)) => drive.frame_due(now),
            Either3::First(Err(_)) => false,
            Either3::Second(()) | Either3::Third(()) => true,
        };
        if synced {
            sync(drive).await;
        }
        match event {
            Either3::First(Ok(n)) => drive.on_rx(now, buf.get(..n).unwrap_or_default()),
            Either3::First(Err(_)) => warn!("uart: receive error"),
            Either3::Second(()) => {
                drive.on_timer(now);
                drive.state_mut().service(now);
            }
            Either3::Third(()) => {}
        }
        after_request(drive, &mut serial, store, &mut updates).await;
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
pub async fn modbus(drive: &'static mut Drive, mut serial: Serial, store: &'static mut crate::board::ParamStore) -> ! {
    use embassy_futures::select::{Either3, select3};
    use embassy_time::Timer;
    use embedded_io_async::Read;
    // Bytes come one or a few at a time: the task reads them as they arrive.
    let mut buf = [0u8; 16];
    // The map's bytes after a register address (seed 003's sub-index) lengthen its requests.
    let mut frame = crate::frames::Assembler::new(drive_core::maps::RegisterMap::address_extra(drive.map()));
    let mut updates = Updates::power_up(store.flash(), drive);
    loop {
        let silence = if frame.expects_more() { SILENCE_PARTIAL } else { SILENCE };
        match select3(serial.read(&mut buf), Timer::after(silence), ATTENTION.wait()).await {
            Either3::First(Ok(n)) => {
                for &b in buf.get(..n).unwrap_or_default() {
                    if frame.push(b) {
                        deliver(drive, &mut frame, &mut serial, store, &mut updates).await;
                    }
                }
            }
            Either3::First(Err(_)) => {}
            Either3::Second(()) if !frame.is_empty() => {
                deliver(drive, &mut frame, &mut serial, store, &mut updates).await
            }
            // The bus side's own work in time (a homing's checks, the analog input), at the
            // silence's pace.
            Either3::Second(()) => {
                let now = now();
                if drive.state().service_is_due(now) {
                    sync(drive).await;
                    drive.state_mut().service(now);
                    after_request(drive, &mut serial, store, &mut updates).await;
                }
            }
            Either3::Third(()) => {
                sync(drive).await;
                after_request(drive, &mut serial, store, &mut updates).await;
            }
        }
    }
}

/// Hands a complete request to the drive as a burst that ended t3.5 ago, then what follows a
/// request.
#[cfg(feature = "qemu")]
async fn deliver(
    drive: &mut Drive,
    frame: &mut crate::frames::Assembler,
    serial: &mut Serial,
    store: &mut crate::board::ParamStore,
    updates: &mut Updates,
) {
    // The model synced before the request is served.
    sync(drive).await;
    let t = now().as_micros();
    let t35 = drive.baud().t35_micros();
    drive.on_rx(Instant::from_micros(t.saturating_sub(t35)), frame.bytes());
    drive.on_timer(Instant::from_micros(t.max(t35)));
    frame.clear();
    after_request(drive, serial, store, updates).await;
}
