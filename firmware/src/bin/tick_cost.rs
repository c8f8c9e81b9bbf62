//! The control tick's cost on the Cortex-M4 instruction set, with the closed loops and the stall
//! detection running: `cargo xtask tick-cost` builds this (feature `tick-cost`) for QEMU's
//! STM32L475 (Cortex-M4F, as the G431) and runs it under `-icount shift=8`, where every
//! instruction takes 256 virtual ns and SysTick counts every 250 ns (the 4 MHz reset clock): one
//! count is 0.98 instructions.
//!
//! No board, no Embassy: the drive core alone, booted, set moving through its objects, and
//! ticked every 50 µs of its own time, each tick given what a drive measures. The measured
//! window holds only [`Drive::tick_with`]; making up the measurements is outside it. Most cases
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
//! - `sensorless`: open loop with the stall detection (0x2107 = 1), fed the phase currents and
//!   bridge voltages of a motor turning 30° electrical behind its current.
//!
//! It prints one line a case through semihosting, then ends QEMU.
#![no_std]
#![no_main]

use core::mem::MaybeUninit;

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{Peripherals, SYST};
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use drive_core::control::{Outputs, TICK_MICROS};
use drive_core::crc::crc16;
use drive_core::faults::Inputs;
use drive_core::od::Obj;
use drive_core::{Drive, DriveConfig, Instant, Params};
// The chip's interrupt vectors; defmt's linker script wants a logger to be linked.
use {defmt_rtt as _, stm32_metapac as _};

/// What every case measures besides its loop's own inputs: all within the thresholds.
const MEASURED: Inputs = Inputs {
    supply_mv: Some(24_000),
    temperature_c: Some(40),
    phase_ma: Some([700, -300]),
    coil_open: [false; 2],
    phase_mv: None,
    encoder: None,
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
}

impl Case {
    const ALL: [Case; 8] = [
        Case::Open,
        Case::OpenRamp,
        Case::OpenPvt,
        Case::OpenMeasured,
        Case::PositionLoop,
        Case::ServoLoop,
        Case::ServoLoopRamp,
        Case::Sensorless,
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
        }
    }

    /// The objects the case sets before power-up, besides 1/32 microsteps and 1000 mA.
    fn settings(self) -> &'static [(Obj, u32)] {
        match self {
            Case::Open | Case::OpenRamp | Case::OpenPvt | Case::OpenMeasured => &[],
            Case::PositionLoop => &[(Obj::Feedback, 1), (Obj::TorqueLoop, 0)],
            Case::ServoLoop | Case::ServoLoopRamp => &[(Obj::Feedback, 1), (Obj::TorqueLoop, 1)],
            Case::Sensorless => &[(Obj::StallDetect, 1)],
        }
    }

    /// What the tick after `last` (none: the first) measures.
    fn measure(self, last: Option<&Outputs>) -> Inputs {
        let Some(last) = last else {
            // Power-up: the encoder reads 0, nothing turns yet.
            return match self {
                Case::Open | Case::OpenRamp | Case::OpenPvt => Inputs::default(),
                Case::PositionLoop | Case::ServoLoop | Case::ServoLoopRamp => Inputs { encoder: Some(0), ..MEASURED },
                Case::OpenMeasured | Case::Sensorless => MEASURED,
            };
        };
        match self {
            Case::Open | Case::OpenRamp | Case::OpenPvt => Inputs::default(),
            Case::OpenMeasured => MEASURED,
            // Closed loop: the setpoint is in encoder counts.
            Case::PositionLoop | Case::ServoLoop | Case::ServoLoopRamp => {
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
                let va = r * ia + l * dia - emf * libm::sinf(rotor);
                let vb = r * ib + l * dib + emf * libm::cosf(rotor);
                let m = |x: f32| libm::roundf(x * 1e3) as i32;
                Inputs { phase_ma: Some([m(ia), m(ib)]), phase_mv: Some([m(va), m(vb)]), ..MEASURED }
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

/// A drive, its clock and the outputs of its last tick.
struct Rig<'a> {
    case: Case,
    drive: &'a mut Drive,
    now: u64,
    last: Outputs,
}

impl<'a> Rig<'a> {
    /// The drive of `case`, booted into `slot` and ticked once; `None` if a setting is refused.
    fn new(case: Case, slot: &'a mut MaybeUninit<Drive>) -> Option<Self> {
        let mut params = Params::factory();
        let settings = [(Obj::Microsteps, 32), (Obj::PhaseCurrent, 1000), (Obj::AccelLevel, 1)];
        if !settings.iter().chain(case.settings()).all(|&(obj, v)| params.set(obj, v)) {
            return None;
        }
        let drive = boot_into(slot, &params);
        let last = drive.tick_with(Instant::from_micros(0), &case.measure(None));
        Some(Self { case, drive, now: 0, last })
    }

    /// The next tick; the SysTick counts it took.
    fn tick(&mut self) -> u32 {
        self.now += TICK_MICROS;
        let inputs = self.case.measure(Some(&self.last));
        let before = SYST::get_current();
        self.last = self.drive.tick_with(Instant::from_micros(self.now), &inputs);
        let after = SYST::get_current();
        // SysTick counts down, 24 bits.
        before.wrapping_sub(after) & SYST_MASK
    }

    /// Ticks for `us` microseconds.
    fn run(&mut self, us: u64) {
        let end = self.now + us;
        while self.now < end {
            self.tick();
        }
    }

    /// Writes `value` to `obj` as the dictionary would; whether it was accepted.
    fn set(&mut self, obj: Obj, value: u32) -> bool {
        let state = self.drive.state_mut();
        let fits = state.check(obj, value).is_ok();
        if fits {
            state.apply(obj, value);
        }
        fits
    }

    /// Sends the request `body` (its CRC appended) as one burst, ticks until its t3.5 has passed
    /// and fires the timer; whether the reply is a normal one (not an exception).
    fn request(&mut self, body: &[u8]) -> bool {
        self.timed_request(body).0
    }

    /// [`Rig::request`], and the SysTick counts the drive took to serve it at t3.5 (the
    /// `on_timer` call, which the firmware's bus task makes holding the drive).
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
        let before = SYST::get_current();
        self.drive.on_timer(deadline);
        let spent = before.wrapping_sub(SYST::get_current()) & SYST_MASK;
        (matches!(self.drive.take_reply(), Some(r) if r.get(1) == body.get(1)), spent)
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

/// Builds the drive in `slot`, static: the drive (the table inside, unlike the firmware's, which
/// lends it) is 12 KB and the stack below the statics about 19 KB, so the one copy `Drive::boot`
/// makes goes through this frame only.
#[inline(never)]
fn boot_into<'a>(slot: &'a mut MaybeUninit<Drive>, params: &Params) -> &'a mut Drive {
    slot.write(Drive::boot(DriveConfig::default(), params, 0))
}

/// Cost of the measured ticks of `case`: (mean, most) SysTick counts, whether the drive was in
/// the situation named (moving, powered, no fault) throughout.
fn run(case: Case, slot: &mut MaybeUninit<Drive>) -> (u32, u32, bool) {
    let Some(mut rig) = Rig::new(case, slot) else { return (0, 0, false) };
    let (ok, setup_us) = match case {
        Case::OpenPvt => (rig.start_pvt(), 50_000),
        Case::OpenRamp | Case::ServoLoopRamp => {
            (rig.set(Obj::MaxSpeed, 32_000) && rig.set(Obj::RelativeMove, 10_000_000), 100_000)
        }
        _ => (rig.set(Obj::MaxSpeed, 32_000) && rig.set(Obj::RelativeMove, 10_000_000), 1_000_000),
    };
    rig.run(setup_us);
    let (mut sum, mut most, mut moving) = (0u64, 0, ok);
    for _ in 0..MEASURED_TICKS {
        let spent = rig.tick();
        sum += u64::from(spent);
        most = most.max(spent);
        let state = rig.drive.state();
        let accelerating = rig.last.setpoint.acceleration != 0.0;
        moving &= state.read(Obj::DriveFaults) == 0
            && state.read(Obj::ControllerStatus) == 0x08
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

/// What serving a request costs (the time the bus task holds the drive, so the time a control
/// tick may wait): a read, a relative move from rest (planned), a re-targeting absolute move
/// while cruising at 32000 pps (planned from the moving state), one behind the axis (a reversal),
/// a stop, and a relative move too short to reach the speed limit. Prints a line each;
/// whether every request was accepted.
fn requests(slot: &mut MaybeUninit<Drive>) -> bool {
    let Some(mut rig) = Rig::new(Case::Open, slot) else { return false };
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
    // Too short to reach the speed limit: the planner searches the turning speed.
    measure(&mut rig, "short_move", &write32(0x6005, 2_000));
    ok
}

#[entry]
fn main() -> ! {
    let Some(mut core) = Peripherals::take() else { exit(false) };
    core.SYST.set_clock_source(SystClkSource::Core);
    core.SYST.set_reload(SYST_MASK);
    core.SYST.clear_current();
    core.SYST.enable_counter();
    let Some(slot) = cortex_m::singleton!(: MaybeUninit<Drive> = MaybeUninit::uninit()) else { exit(false) };
    let mut all_ok = true;
    for case in Case::ALL {
        let (mean, most, ok) = run(case, slot);
        all_ok &= ok;
        hprintln!(
            "tick_cost {} mean {} most {} counts{}",
            case.name(),
            mean,
            most,
            if ok { "" } else { " NOT IN ITS SITUATION" }
        );
    }
    all_ok &= requests(slot);
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
