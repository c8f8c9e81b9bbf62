//! The control tick's cost on the Cortex-M4 instruction set, with the closed loops and the stall
//! detection running: `cargo xtask tick-cost` builds this (feature `tick-cost`) for QEMU's
//! STM32L475 (Cortex-M4F, as the G474) and runs it under `-icount shift=8`, where every
//! instruction takes 256 virtual ns and SysTick counts every 250 ns (the 4 MHz reset clock): one
//! count is 0.98 instructions.
//!
//! No board, no Embassy: the drive core alone, booted, set moving through its objects, and
//! ticked every 50 µs of its own time, each tick given what a drive measures, arranged as the
//! firmware arranges it: the tick owns a `TickSide`, the drive's model is lent to it before and
//! after each request. The measured window holds the control work of a PWM period as the board's
//! interrupt does it: the current loop (`drive_core::windings`: the period's voltages, then the
//! tick's outputs taken as the next reference), the tick and, when the model is lent, its sync;
//! making up the measurements is outside it, and so are the board's register accesses. Most cases
//! cruise at 32000 pps (1/32 microsteps, acceleration level 1, a relative move of ten million
//! steps; in closed loop the same in encoder counts) for a second, then 4000 ticks are measured:
//!
//! - `open`: open loop, no measurements (the host benchmark `tick cruise`'s case);
//! - `open_ramp`: the same from 100 ms into the move, in its S-curve's ramp (jerk, then constant
//!   acceleration: the phases that cost the most to evaluate);
//! - `open_pvt`: PVT mode 1 (four points 100 ms apart, up to 20000 pps and back to rest, pushed
//!   by Modbus frames as a master does), measured from 50 ms to 250 ms, inside its cubic segments;
//! - `open_measured`: open loop with the supply, temperature and phase currents (the fault checks);
//! - `position_loop` / `servo_loop`: closed loop (0x2104 = 1, a 1000-line encoder) with 0x605D =
//!   0 / 1, the encoder following the setpoint exactly;
//! - `servo_loop_ramp`: the servo loop in the ramp, as `open_ramp` (the costliest tick of a move);
//! - `sensorless`: open loop with the stall detection (0x2107 = 1), fed the phase currents,
//!   bridge voltages and the current loop's back-EMF estimate of a motor turning 30° electrical
//!   behind its current.
//!
//! - `io_functions`: open loop with every input and output given a function (0x21BA-0x21C6:
//!   limit and home switches, commands; alarm, in position, general, ready), the inputs
//!   inactive, each through its filter (0x21F9-0x21FF at 1 ms);
//! - `open_filtered`: open loop through the command filter (0x2210 = 1, 0x2211 at its longest,
//!   25.6 ms);
//! - `servo_scope`: the servo loop with the scope recording 8 signals (12 words) a row every
//!   second tick (10 kHz), armed on a level its following error never reaches (the black box
//!   records in the other cases, a row every 25 ticks): the scope's fastest (a row costs
//!   about 400 instructions: at every tick the mean would be 2 706, over the budget).
//!
//! It prints one line a case through semihosting, then ends QEMU.
#![no_std]
#![no_main]

use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicU32, Ordering};

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{Peripherals, SYST};
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use drive_core::control::{Outputs, TICK_MICROS};
use drive_core::controller::Shared;
use drive_core::controller::handoff::{Handover, TickSide};
use drive_core::crc::crc16;
use drive_core::current::{CurrentLoopSettings, recommended_bandwidth};
use drive_core::faults::Inputs;
use drive_core::maps::NativeMap;
use drive_core::od::Obj;
use drive_core::windings::{DEAD_BAND_A, DEAD_TIME_S, WindingSettings, WindingState};
use drive_core::{DriveConfig, Instant, Params};
// The chip's interrupt vectors; defmt's linker script wants a logger to be linked.
use {defmt_rtt as _, stm32_metapac as _};

/// The drive as the firmware has it: the PVT table in a static of its own (a case's points are
/// beyond the queue of the next case's new drive).
type Drive = drive_core::Drive<NativeMap, &'static Shared>;

/// The PVT points of every case's drive.
static SHARED: Shared = Shared::new();

/// What every case measures besides its loop's own inputs: all within the thresholds.
const MEASURED: Inputs = Inputs {
    supply_mv: Some(24_000),
    temperature_c: Some(40),
    phase_ma: Some([700, -300]),
    coil_open: [false; 2],
    phase_mv: None,
    back_emf_mv: None,
    encoder: None,
    levels: 0,
    analog: None,
    index: false,
    pulses: 0,
    tripped: false,
    sensing_fault: false,
};

/// The cases, in the order printed.
#[derive(Clone, Copy, PartialEq)]
enum Case {
    Open,
    OpenRamp,
    OpenPvt,
    OpenMeasured,
    PositionLoop,
    ServoLoop,
    ServoLoopRamp,
    Sensorless,
    IoFunctions,
    OpenFiltered,
    ServoScope,
}

impl Case {
    const ALL: [Case; 11] = [
        Case::Open,
        Case::OpenRamp,
        Case::OpenPvt,
        Case::OpenMeasured,
        Case::PositionLoop,
        Case::ServoLoop,
        Case::ServoLoopRamp,
        Case::Sensorless,
        Case::IoFunctions,
        Case::OpenFiltered,
        Case::ServoScope,
    ];

    fn name(self) -> &'static str {
        match self {
            Case::Open => "open",
            Case::OpenRamp => "open_ramp",
            Case::OpenPvt => "open_pvt",
            Case::OpenMeasured => "open_measured",
            Case::PositionLoop => "position_loop",
            Case::ServoLoop => "servo_loop",
            Case::ServoLoopRamp => "servo_loop_ramp",
            Case::Sensorless => "sensorless",
            Case::IoFunctions => "io_functions",
            Case::OpenFiltered => "open_filtered",
            Case::ServoScope => "servo_scope",
        }
    }

    /// The objects the case sets before power-up, besides 1/32 microsteps and 1000 mA.
    fn settings(self) -> &'static [(Obj, u32)] {
        match self {
            Case::Open | Case::OpenRamp | Case::OpenPvt | Case::OpenMeasured => &[],
            Case::PositionLoop => &[(Obj::Feedback, 1), (Obj::TorqueLoop, 0)],
            Case::ServoLoop | Case::ServoLoopRamp | Case::ServoScope => &[(Obj::Feedback, 1), (Obj::TorqueLoop, 1)],
            Case::Sensorless => &[(Obj::StallDetect, 1)],
            Case::IoFunctions => &[
                (Obj::InputFunction1, 9),
                (Obj::InputFunction2, 10),
                (Obj::InputFunction3, 11),
                (Obj::InputFunction4, 4),
                (Obj::InputFunction5, 5),
                (Obj::InputFunction6, 6),
                (Obj::InputFunction7, 13),
                (Obj::OutputFunction1, 2),
                (Obj::OutputFunction2, 3),
                (Obj::OutputFunction3, 1),
                (Obj::OutputFunction4, 5),
                (Obj::InputFilter1, 1000),
                (Obj::InputFilter2, 1000),
                (Obj::InputFilter3, 1000),
                (Obj::InputFilter4, 1000),
                (Obj::InputFilter5, 1000),
                (Obj::InputFilter6, 1000),
                (Obj::InputFilter7, 1000),
            ],
            Case::OpenFiltered => &[(Obj::CommandFilter, 1), (Obj::CommandFilterTime, 25_600)],
        }
    }

    /// What the tick after `last` (none: the first) measures.
    fn measure(self, last: Option<&Outputs>) -> Inputs {
        let Some(last) = last else {
            // Power-up: the encoder reads 0, nothing turns yet.
            return match self {
                Case::Open | Case::OpenRamp | Case::OpenPvt | Case::IoFunctions | Case::OpenFiltered => {
                    Inputs::default()
                }
                Case::PositionLoop | Case::ServoLoop | Case::ServoLoopRamp | Case::ServoScope => {
                    Inputs { encoder: Some(0), ..MEASURED }
                }
                Case::OpenMeasured | Case::Sensorless => MEASURED,
            };
        };
        match self {
            Case::Open | Case::OpenRamp | Case::OpenPvt | Case::IoFunctions | Case::OpenFiltered => Inputs::default(),
            Case::OpenMeasured => MEASURED,
            // Closed loop: the setpoint is in encoder counts.
            Case::PositionLoop | Case::ServoLoop | Case::ServoLoopRamp | Case::ServoScope => {
                Inputs { encoder: Some(last.setpoint.whole as u32), ..MEASURED }
            }
            Case::Sensorless => {
                // 1/32 microsteps: a microstep is π/64 electrical.
                let per = core::f32::consts::FRAC_PI_2 / 32.0;
                let c = &last.commutation;
                let theta = ((c.whole % 128) as f32 + c.fraction.to_num::<f32>()) * per;
                let w = c.velocity * per;
                let (r, l, km, i) = (1.4, 3.0e-3, 0.21, f32::from(last.current_ma) * 1e-3);
                let rotor = theta - 30f32.to_radians();
                let (s, co) = (libm::sinf(theta), libm::cosf(theta));
                let (ia, ib) = (i * co, i * s);
                let (dia, dib) = (-i * w * s, i * w * co);
                let emf = km * w / 50.0;
                let (ea, eb) = (-emf * libm::sinf(rotor), emf * libm::cosf(rotor));
                let (va, vb) = (r * ia + l * dia + ea, r * ib + l * dib + eb);
                let m = |x: f32| libm::roundf(x * 1e3) as i32;
                // The current loop's back-EMF estimate too, as the board's stage gives it.
                Inputs {
                    phase_ma: Some([m(ia), m(ib)]),
                    phase_mv: Some([m(va), m(vb)]),
                    back_emf_mv: Some([m(ea), m(eb)]),
                    ..MEASURED
                }
            }
        }
    }
}

/// Ticks measured a case.
const MEASURED_TICKS: u32 = 4000;
/// The SysTick counter's width.
const SYST_MASK: u32 = 0x00FF_FFFF;
/// The drive's address (factory).
const SLAVE: u8 = 1;

/// How long after a request its motion starts, as on the G474 (`board::g474::PLAN_MARGIN_US`).
const PLAN_MARGIN_US: u64 = 2_000;

/// A drive (the bus side), the tick's side, their clock and the outputs of the last tick.
struct Rig<'a> {
    case: Case,
    drive: &'a mut Drive,
    tick: &'a mut TickSide,
    /// The drive's model is lent to the tick: the next tick syncs it (as the firmware's tick
    /// does when the Modbus task has lent it).
    lent: bool,
    now: u64,
    last: Outputs,
    /// The current loop each period, as the board's interrupt runs it before the tick.
    windings: WindingSettings,
    regulation: WindingState,
}

/// The most counts of a tick that synced the model, and of one that took a plan over, in every
/// case and request.
static SYNC_MOST: [AtomicU32; 2] = [const { AtomicU32::new(0) }; 2];

impl<'a> Rig<'a> {
    /// The drive of `case`, booted into `slot` (its tick's side into `tick`) and ticked once;
    /// `None` if a setting is refused.
    fn new(case: Case, slot: &'a mut MaybeUninit<Drive>, tick: &'a mut MaybeUninit<TickSide>) -> Option<Self> {
        let mut params = Params::factory();
        let settings = [(Obj::Microsteps, 32), (Obj::PhaseCurrent, 1000), (Obj::AccelLevel, 1)];
        if !settings.iter().chain(case.settings()).all(|&(obj, v)| params.set(obj, v)) {
            return None;
        }
        let drive = boot_into(slot, &mut params);
        drive.state_mut().set_plan_margin(PLAN_MARGIN_US);
        let tick = tick.write(drive.state().tick_side());
        let last = tick.tick(Instant::from_micros(0), &case.measure(None), &SHARED);
        let pwm = 1e6 / TICK_MICROS as f32;
        let current = CurrentLoopSettings::new(1.4, 3.0e-3, 24.0, pwm, recommended_bandwidth(pwm))
            .and_then(|s| s.with_dead_time(DEAD_TIME_S, DEAD_BAND_A))
            .ok()?;
        let (windings, mut regulation) = (WindingSettings::new(current), WindingState::default());
        windings.command(&mut regulation, &last);
        Some(Self { case, drive, tick, lent: false, now: 0, last, windings, regulation })
    }

    /// The next tick (a sync first if the model is lent, as the firmware's tick); the SysTick
    /// counts it took.
    fn tick(&mut self) -> u32 {
        self.now += TICK_MICROS;
        let inputs = self.case.measure(Some(&self.last));
        let now = Instant::from_micros(self.now);
        // The windings' currents as the ADC gives them: the reference, read 3 % short.
        let phase_ma = self.regulation.reference().unwrap_or_default().map(|a| (a * 970.0) as i32);
        let before = SYST::get_current();
        let shares = self.windings.period(&mut self.regulation, phase_ma, 24_000);
        let handover = if self.lent { Some(self.tick.sync(now, &mut self.drive.lend())) } else { None };
        self.last = self.tick.tick(now, &inputs, &SHARED);
        self.windings.command(&mut self.regulation, &self.last);
        let after = SYST::get_current();
        core::hint::black_box(shares);
        // SysTick counts down, 24 bits.
        let spent = before.wrapping_sub(after) & SYST_MASK;
        match handover {
            Some(Handover::Waiting) | None => {}
            Some(h) => {
                self.lent = false;
                self.drive.state_mut().synced();
                let planned = matches!(h, Handover::Planned | Handover::Late(_));
                for (most, counts) in SYNC_MOST.iter().zip([true, planned]) {
                    if counts {
                        most.fetch_max(spent, Ordering::Relaxed);
                    }
                }
            }
        }
        spent
    }

    /// Ticks until the tick has synced the model lent to it.
    fn sync(&mut self) {
        self.lent = true;
        while self.lent {
            self.tick();
        }
    }

    /// Ticks for `us` microseconds.
    fn run(&mut self, us: u64) {
        let end = self.now + us;
        while self.now < end {
            self.tick();
        }
    }

    /// Writes `value` to `obj` as the dictionary would, and hands it to the tick; whether it was
    /// accepted.
    fn set(&mut self, obj: Obj, value: u32) -> bool {
        let state = self.drive.state_mut();
        let fits = state.check(obj, value).is_ok();
        if fits {
            state.apply(obj, value);
            self.sync();
        }
        fits
    }

    /// Sends the request `body` (its CRC appended) as one burst, ticks until its t3.5 has passed,
    /// syncs the model and fires the timer, then hands what it changed to the tick; whether the
    /// reply is a normal one (not an exception).
    fn request(&mut self, body: &[u8]) -> bool {
        self.timed_request(body).0
    }

    /// [`Rig::request`], and the SysTick counts the drive took to serve it at t3.5 (the
    /// `on_timer` call, which the firmware's bus task makes while the tick runs on).
    fn timed_request(&mut self, body: &[u8]) -> (bool, u32) {
        let mut frame = [0u8; 32];
        let n = body.len();
        let Some(dst) = frame.get_mut(..n) else { return (false, 0) };
        dst.copy_from_slice(body);
        let Some(crc) = frame.get_mut(n..n + 2) else { return (false, 0) };
        crc.copy_from_slice(&crc16(body).to_le_bytes());
        self.drive.on_rx(Instant::from_micros(self.now), frame.get(..n + 2).unwrap_or_default());
        let Some(deadline) = self.drive.deadline() else { return (false, 0) };
        while self.now + TICK_MICROS <= deadline.as_micros() {
            self.tick();
        }
        self.sync();
        let before = SYST::get_current();
        self.drive.on_timer(Instant::from_micros(deadline.as_micros().max(self.now)));
        let spent = before.wrapping_sub(SYST::get_current()) & SYST_MASK;
        let ok = matches!(self.drive.take_reply(), Some(r) if r.get(1) == body.get(1));
        if self.drive.has_changes() {
            self.sync();
        }
        (ok, spent)
    }

    /// The scope armed with 8 signals (12 words: positions, following error, velocities, phase
    /// A's current, the loop's output, the current command), a row every second tick, on a
    /// level the following error never reaches: it records throughout.
    fn arm_scope(&mut self) -> bool {
        let signals = [1, 2, 3, 4, 5, 6, 13, 8];
        drive_core::state::recording::SIGNALS.iter().zip(signals).all(|(&obj, code)| self.set(obj, code))
            && self.set(Obj::ScopeTrigger, 2)
            && self.set(Obj::ScopeTriggerSignal, 3)
            && self.set(Obj::ScopeTriggerLevel, 32_767)
            && self.set(Obj::ScopeDivider, 2)
            && self.set(Obj::ScopeControl, 1)
    }

    /// PVT mode 1 with push on time: four points, 100 ms apart, from rest up to 20000 pps and
    /// back to rest 4000 steps on, then the run started.
    fn start_pvt(&mut self) -> bool {
        let write16 = |reg: u16, v: u16| {
            let ([rh, rl], [vh, vl]) = (reg.to_be_bytes(), v.to_be_bytes());
            [SLAVE, 0x06, rh, rl, vh, vl]
        };
        let mut ok = [write16(0x6007, 2), write16(0x6018, 0), write16(0x2112, 1)].iter().all(|b| self.request(b));
        for (p, v, t) in [(0i32, 0i32, 0u32), (1000, 20_000, 100), (3000, 20_000, 100), (4000, 0, 100)] {
            let mut body = [0u8; 19];
            body[..7].copy_from_slice(&[SLAVE, 0x10, 0x60, 0x27, 0x00, 0x06, 0x0C]);
            body[7..11].copy_from_slice(&p.to_be_bytes());
            body[11..15].copy_from_slice(&v.to_be_bytes());
            body[15..19].copy_from_slice(&t.to_be_bytes());
            ok &= self.request(&body);
        }
        ok && self.request(&write16(0x601C, 3)) && self.request(&write16(0x6017, 1))
    }
}

/// Builds the drive in `slot`, lending it the table as the firmware does.
fn boot_into<'a>(slot: &'a mut MaybeUninit<Drive>, params: &mut Params) -> &'a mut Drive {
    Drive::boot_in(slot, DriveConfig::default(), NativeMap::new(), params, 0, &SHARED)
}

/// Cost of the measured ticks of `case`: (mean, most) SysTick counts, whether the drive was in
/// the situation named (moving, powered, no fault) throughout.
fn run(case: Case, slot: &mut MaybeUninit<Drive>, tick: &mut MaybeUninit<TickSide>) -> (u32, u32, bool) {
    let Some(mut rig) = Rig::new(case, slot, tick) else { return (0, 0, false) };
    let (ok, setup_us) = match case {
        Case::OpenPvt => (rig.start_pvt(), 50_000),
        Case::OpenRamp | Case::ServoLoopRamp => {
            (rig.set(Obj::MaxSpeed, 32_000) && rig.set(Obj::RelativeMove, 10_000_000), 100_000)
        }
        Case::ServoScope => {
            (rig.arm_scope() && rig.set(Obj::MaxSpeed, 32_000) && rig.set(Obj::RelativeMove, 10_000_000), 1_000_000)
        }
        _ => (rig.set(Obj::MaxSpeed, 32_000) && rig.set(Obj::RelativeMove, 10_000_000), 1_000_000),
    };
    rig.run(setup_us);
    let (mut sum, mut most, mut moving) = (0u64, 0, ok);
    for _ in 0..MEASURED_TICKS {
        let spent = rig.tick();
        sum += u64::from(spent);
        most = most.max(spent);
        // What the tick's controller runs (the bus side's model is synced only for requests).
        let ctl = rig.tick.controller();
        // (The command filter's acceleration carries its 1/256 microstep's quantisation: a few
        // thousand pps² either way while cruising, against the ramp's 77 440.)
        let accelerating = rig.last.setpoint.acceleration.abs() > 5_000.0;
        moving &= ctl.status().faults == 0
            && ctl.status().error == 0
            && ctl.status().controller == 0
            && !ctl.axis().is_still()
            && (case != Case::ServoScope || ctl.scopes().scope.is_recording())
            && match case {
                Case::OpenPvt => rig.last.setpoint.velocity > 0.0,
                Case::OpenRamp | Case::ServoLoopRamp => accelerating,
                _ => (rig.last.setpoint.velocity - 32_000.0).abs() < 0.5 && !accelerating,
            };
    }
    ((sum / u64::from(MEASURED_TICKS)) as u32, most, moving)
}

/// A write of the 32-bit object at `reg` (function 0x10, two registers) to node 1.
fn write32(reg: u16, v: i32) -> [u8; 11] {
    let ([rh, rl], [a, b, c, d]) = (reg.to_be_bytes(), v.to_be_bytes());
    [SLAVE, 0x10, rh, rl, 0x00, 0x02, 0x04, a, b, c, d]
}

/// What serving a request costs (from its last byte to the reply; the tick runs on meanwhile,
/// and the plan must be ready before its first tick, `PLAN_MARGIN_US` on): a read, a relative move from rest (planned), a re-targeting absolute move
/// while cruising at 32000 pps (planned from the moving state), one behind the axis (a reversal),
/// a stop, and a relative move too short to reach the speed limit. Prints a line each;
/// whether every request was accepted.
fn requests(slot: &mut MaybeUninit<Drive>, tick: &mut MaybeUninit<TickSide>) -> bool {
    let Some(mut rig) = Rig::new(Case::Open, slot, tick) else { return false };
    let mut ok = rig.set(Obj::MaxSpeed, 32_000);
    let mut measure = |rig: &mut Rig, name: &str, body: &[u8]| {
        let (accepted, spent) = rig.timed_request(body);
        ok &= accepted;
        hprintln!("request {} {} counts{}", name, spent, if accepted { "" } else { " REFUSED" });
    };
    measure(&mut rig, "read", &[SLAVE, 0x03, 0x60, 0x0C, 0x00, 0x02]);
    measure(&mut rig, "relative_move", &write32(0x6005, 10_000_000));
    rig.run(1_000_000);
    measure(&mut rig, "retarget", &write32(0x6044, 20_000_000));
    rig.run(100_000);
    measure(&mut rig, "reverse", &write32(0x6044, 0));
    rig.run(100_000);
    measure(&mut rig, "stop", &[SLAVE, 0x06, 0x60, 0x53, 0x00, 0x00]);
    rig.run(100_000);
    // Too short to reach the speed limit: the planner solves for the turning speed.
    measure(&mut rig, "short_move", &write32(0x6005, 2_000));
    ok
}

/// What checking an image costs the bus task: the digest of 8 KiB (the install's check of a slot
/// scales with its length) and the signature's check (a well-formed signature that does not
/// verify costs what one that does costs). Prints a line each.
fn image_check() {
    use drive_core::update::{Board, HEADER_LEN, Header, TEST_KEY, Verifier};
    const N: usize = 8 * 1024;
    let header = Header { board: Board::Qemu, version: 1, length: (N - HEADER_LEN) as u32, store: 1 };
    let mut block = [0x5Au8; 1024];
    let mut v = Verifier::new();
    let before = SYST::get_current();
    for k in 0..N / block.len() {
        if k == 0 {
            if let Some(head) = block.get_mut(..HEADER_LEN) {
                head.copy_from_slice(&header.to_bytes());
            }
        } else if let Some(head) = block.get_mut(..HEADER_LEN) {
            head.fill(0x5A);
        }
        v.absorb(&block);
    }
    let digest = before.wrapping_sub(SYST::get_current()) & SYST_MASK;
    // R: a point that decompresses (the key's); s: 1.
    let mut signature = [0u8; 64];
    let (r, s) = signature.split_at_mut(32);
    r.copy_from_slice(&TEST_KEY);
    if let Some(low) = s.first_mut() {
        *low = 1;
    }
    let before = SYST::get_current();
    let verdict = v.finish(&signature, &TEST_KEY, Board::Qemu, 1);
    let check = before.wrapping_sub(SYST::get_current()) & SYST_MASK;
    hprintln!("image digest_8k {} counts", digest);
    hprintln!("image signature {} counts{}", check, if verdict.is_err() { "" } else { " VERIFIED?" });
}

#[entry]
fn main() -> ! {
    let Some(mut core) = Peripherals::take() else { exit(false) };
    core.SYST.set_clock_source(SystClkSource::Core);
    core.SYST.set_reload(SYST_MASK);
    core.SYST.clear_current();
    core.SYST.enable_counter();
    let (Some(slot), Some(tick)) = (
        cortex_m::singleton!(: MaybeUninit<Drive> = MaybeUninit::uninit()),
        cortex_m::singleton!(: MaybeUninit<TickSide> = MaybeUninit::uninit()),
    ) else {
        exit(false)
    };
    let mut all_ok = true;
    for case in Case::ALL {
        let (mean, most, ok) = run(case, slot, tick);
        all_ok &= ok;
        hprintln!(
            "tick_cost {} mean {} most {} counts{}",
            case.name(),
            mean,
            most,
            if ok { "" } else { " NOT IN ITS SITUATION" }
        );
    }
    all_ok &= requests(slot, tick);
    image_check();
    let [synced, planned] = SYNC_MOST.each_ref().map(|m| m.load(Ordering::Relaxed));
    hprintln!("tick_cost handover synced {} planned {} counts", synced, planned);
    exit(all_ok)
}

fn exit(ok: bool) -> ! {
    debug::exit(if ok { debug::EXIT_SUCCESS } else { debug::EXIT_FAILURE });
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(_: &core::panic::PanicInfo) -> ! {
    hprintln!("tick_cost: panic");
    exit(false)
}
