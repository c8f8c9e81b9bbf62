//! The control tick's cost on the Cortex-M4 instruction set, with the closed loops and the stall
//! detection running: `cargo xtask tick-cost` builds this (feature `tick-cost`) for QEMU's STM32L475 (Cortex-M4F, as
//! the G431) and runs it under `-icount shift=8`, where every instruction takes 256 virtual ns and
//! SysTick counts every 250 ns (the 4 MHz reset clock): one count is 0.98 instructions.
//!
//! No board, no Embassy: the drive core alone, booted, set moving through its objects, and
//! ticked every 50 µs of its own time, each tick given what a drive measures. The measured
//! window holds only [`Drive::tick_with`]; making up the measurements is outside it. Each case
//! cruises at 32000 pps (1/32 microsteps, acceleration level 1, a relative move of ten million
//! steps; in closed loop the same in encoder counts) for a second, then 4000 ticks are measured:
//!
//! - `open`: open loop, no measurements (the host benchmark `tick cruise`'s case);
//! - `open_measured`: open loop with the supply, temperature and phase currents (the fault checks);
//! - `position_loop` / `servo_loop`: closed loop (0x2104 = 1, a 1000-line encoder) with 0x605D =
//!   0 / 1, the encoder following the setpoint exactly;
//! - `sensorless`: open loop with the stall detection (0x2107 = 1), fed the phase currents and
//!   bridge voltages of a motor turning 30° electrical behind its current.
//!
//! It prints one line a case through semihosting, then ends QEMU.
#![no_std]
#![no_main]

use cortex_m::peripheral::syst::SystClkSource;
use cortex_m::peripheral::{Peripherals, SYST};
use cortex_m_rt::entry;
use cortex_m_semihosting::{debug, hprintln};
use drive_core::control::{Outputs, TICK_MICROS};
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
#[derive(Clone, Copy)]
enum Case {
    Open,
    OpenMeasured,
    PositionLoop,
    ServoLoop,
    Sensorless,
}

impl Case {
    const ALL: [Case; 5] = [Case::Open, Case::OpenMeasured, Case::PositionLoop, Case::ServoLoop, Case::Sensorless];

    fn name(self) -> &'static str {
        match self {
            Case::Open => "open",
            Case::OpenMeasured => "open_measured",
            Case::PositionLoop => "position_loop",
            Case::ServoLoop => "servo_loop",
            Case::Sensorless => "sensorless",
        }
    }

    /// The objects the case sets before power-up, besides 1/32 microsteps and 1000 mA.
    fn settings(self) -> &'static [(Obj, u32)] {
        match self {
            Case::Open | Case::OpenMeasured => &[],
            Case::PositionLoop => &[(Obj::Feedback, 1), (Obj::TorqueLoop, 0)],
            Case::ServoLoop => &[(Obj::Feedback, 1), (Obj::TorqueLoop, 1)],
            Case::Sensorless => &[(Obj::StallDetect, 1)],
        }
    }

    /// What the tick after `last` (none: the first) measures.
    fn measure(self, last: Option<&Outputs>) -> Inputs {
        let Some(last) = last else {
            // Power-up: the encoder reads 0, nothing turns yet.
            return match self {
                Case::Open => Inputs::default(),
                Case::PositionLoop | Case::ServoLoop => Inputs { encoder: Some(0), ..MEASURED },
                Case::OpenMeasured | Case::Sensorless => MEASURED,
            };
        };
        match self {
            Case::Open => Inputs::default(),
            Case::OpenMeasured => MEASURED,
            // Closed loop: the setpoint is in encoder counts.
            Case::PositionLoop | Case::ServoLoop => Inputs { encoder: Some(last.setpoint.whole as u32), ..MEASURED },
            Case::Sensorless => {
                // 1/32 microsteps: a microstep is π/64 electrical.
                let per = core::f32::consts::FRAC_PI_2 / 32.0;
                let c = &last.commutation;
                let theta = ((c.whole % 128) as f32 + c.fraction.to_num::<f32>()) * per;
                let w = c.velocity as f32 * per;
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

/// Cost of the measured ticks of `case`: (mean, most) SysTick counts, whether the drive was still
/// cruising without a fault at the end.
fn run(case: Case) -> (u32, u32, bool) {
    let mut params = Params::factory();
    let ok = [(Obj::Microsteps, 32), (Obj::PhaseCurrent, 1000), (Obj::AccelLevel, 1)]
        .iter()
        .chain(case.settings())
        .all(|&(obj, v)| params.set(obj, v));
    let mut drive = Drive::boot(DriveConfig::default(), &params, 0);
    let mut now = 0;
    let mut last = drive.tick_with(Instant::from_micros(now), &case.measure(None));
    let state = drive.state_mut();
    let ok = ok
        && [(Obj::MaxSpeed, 32_000), (Obj::RelativeMove, 10_000_000)].iter().all(|&(obj, v)| {
            let fits = state.check(obj, v).is_ok();
            state.apply(obj, v);
            fits
        });
    let mut tick = |drive: &mut Drive, last: &mut Outputs| -> u32 {
        now += TICK_MICROS;
        let inputs = case.measure(Some(last));
        let before = SYST::get_current();
        *last = drive.tick_with(Instant::from_micros(now), &inputs);
        let after = SYST::get_current();
        // SysTick counts down, 24 bits.
        before.wrapping_sub(after) & SYST_MASK
    };
    for _ in 0..1_000_000 / TICK_MICROS {
        tick(&mut drive, &mut last);
    }
    let (mut sum, mut most) = (0u64, 0);
    for _ in 0..MEASURED_TICKS {
        let spent = tick(&mut drive, &mut last);
        sum += u64::from(spent);
        most = most.max(spent);
    }
    let state = drive.state();
    let cruising = last.setpoint.velocity == 32_000.0
        && state.read(Obj::DriveFaults) == 0
        && state.read(Obj::ControllerStatus) == 0x08;
    ((sum / u64::from(MEASURED_TICKS)) as u32, most, ok && cruising)
}

#[entry]
fn main() -> ! {
    let Some(mut core) = Peripherals::take() else { exit(false) };
    core.SYST.set_clock_source(SystClkSource::Core);
    core.SYST.set_reload(SYST_MASK);
    core.SYST.clear_current();
    core.SYST.enable_counter();
    let mut all_ok = true;
    for case in Case::ALL {
        let (mean, most, ok) = run(case);
        all_ok &= ok;
        hprintln!(
            "tick_cost {} mean {} most {} counts{}",
            case.name(),
            mean,
            most,
            if ok { "" } else { " NOT CRUISING" }
        );
    }
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
