//! The STM32G474CE board (LQFP48): clocks, pin map and peripheral setup. Nothing else knows a
//! pin name; `tests/tests/board.rs` checks each alternate function against the chip's data.
//!
//! The pin map is [`pins`]: every signal, its pin, peripheral and alternate function.
//!
//! Flash: two banks ([`crate::flash_map`]); the program runs from bank 1 behind the boot
//! loader, and the parameter store ([`STORE`]) is in bank 2, so a save's page erase does not
//! stall the code. [`init`] checks first that the option bytes set the dual-bank mode this
//! layout needs.
//!
//! Clock: HSI16 / 4 × 85 / 2 = 170 MHz SYSCLK from the PLL, range-1 boost mode; AHB, APB1 and
//! APB2 undivided, so USART1 and every timer count at 170 MHz.
//!
//! Timers: TIM15 is embassy-time's free-running 1 MHz clock (the time stamps of received bytes
//! and the t3.5 timer); TIM8 and TIM1 drive the two H-bridges at 20 kHz ([`power_stage`]), and
//! the end of their ADC sequence each period is the control tick (interrupt priority 0, above
//! all others: the current loop, then the tick); TIM2 counts the encoder;
//! TIM3 the pulse input (its encoder interface in the format 0x21B7 asks for); TIM17 the coil
//! output's PWM.
//!
//! The power stage is the drive's own ([`power_stage`]: two H-bridges, their currents sampled
//! at the PWM centre, the bus voltage, the bridges' NTC, the over-current trip in hardware); the
//! external STEP/DIR driver's outputs (STEP, DIR, ENABLE, the current reference) are gone. Each
//! PWM period the current loop (`drive_core::windings`) sets the windings' voltages from the
//! currents just sampled and the electrical angle and current the last tick asked ([`Stage`]),
//! with its gains from the power-up auto-tune ([`Stage::tune`]).

use core::cell::{Cell, RefCell};
use core::ops::Range;

use cortex_m::singleton;
use critical_section::Mutex;
use drive_core::Baud;
use drive_core::control::TICK_HZ;
use drive_core::controller::io::{PinConfig, PinMode, PulseInput};
use drive_core::faults::Inputs as Measured;
use drive_core::modes::PulseFormat;
use drive_core::store::Store;
use embassy_embedded_hal::adapter::BlockingAsync;
use embassy_stm32::comp;
use embassy_stm32::exti::{self, ExtiInput};
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::gpio::Pull;
use embassy_stm32::interrupt::{self, InterruptExt, Priority};
use embassy_stm32::mode::Async;
use embassy_stm32::pac;
use embassy_stm32::peripherals::TIM2;
use embassy_stm32::rcc::{Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk};
use embassy_stm32::timer::qei::{Config as QeiConfig, Qei};
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_stm32::{bind_interrupts, peripherals};

use crate::flash_map;
#[path = "pins.rs"]
#[allow(
    dead_code,
    reason = "the whole table is read by the tests and the doc; the code uses the pins it sets up itself"
)]
pub mod pins;
#[path = "power_stage.rs"]
pub mod power_stage;
use drive_core::windings::{
    LoopObjects, PowerUpTune, TuneStep, WindingSettings, WindingState, command_or_open, sensing_ok,
};
use power_stage::Bridges;
pub use power_stage::bridge_temperature_c;

use crate::power::PowerStage;

bind_interrupts!(struct Irqs {
    USART1 => usart::BufferedInterruptHandler<peripherals::USART1>;
    EXTI15_10 => exti::InterruptHandler<interrupt::typelevel::EXTI15_10>;
    ADC1_2 => TickHandler;
    // The over-current comparators' own interrupts (an output edge through EXTI), not used:
    // the comparators act on the timers' break input. embassy's `Comp` wants them bound.
    COMP1_2_3 => comp::InterruptHandler<peripherals::COMP2>;
    COMP4_5_6 => comp::InterruptHandler<peripherals::COMP5>;
});

/// What the 0x1022 hardware version says.
pub const HARDWARE: &str = "G474";
/// How long after a request its motion starts, µs: serving a move takes up to 0.9 ms of the
/// 170 MHz core (`cargo xtask tick-cost`), and the plan is handed over at the next tick.
pub const PLAN_MARGIN_US: u64 = 2_000;
/// Timer clock (PCLK1 = PCLK2 = SYSCLK).
pub const TIMER_HZ: u32 = 170_000_000;
/// Timer counts (and core cycles) in one control tick.
#[allow(dead_code, reason = "the HIL suite's nominal tick period")]
pub const TICK_COUNTS: u32 = TIMER_HZ / TICK_HZ;
/// The over-current trip until the drive's setting (0x2133) is loaded from flash: the top of the
/// setting's range. The bridges are off meanwhile.
const OVER_CURRENT_UNTIL_LOADED_MA: u32 = 10_000;

/// Receive ring: two requests of the longest (an ASCII line, 513 characters; an RTU frame is
/// 256 bytes), so that requests sent back to back (to other drives on the bus, broadcasts) are
/// all held while the task serves one of them.
const RX_BUF: usize = 2 * drive_core::ascii::MAX_LINE;
/// Transmit ring: the longest reply whole (an ASCII line), so that the task hands it over at once.
const TX_BUF: usize = drive_core::ascii::MAX_LINE;

/// The RS-485 port.
pub type Serial = BufferedUart<'static>;

/// The parameter store's pages, as offsets from the start of flash (the flash driver's
/// addressing): [`flash_map::PARAMS`], in bank 2.
pub const STORE: Range<u32> =
    flash_map::PARAMS.start - flash_map::FLASH_START..flash_map::PARAMS.end() - flash_map::FLASH_START;

/// The board images are built for (an image's header).
pub const IMAGE_BOARD: drive_core::update::Board = drive_core::update::Board::G474;
/// embassy-boot's boot loader starts the image and swaps an update in.
pub const BOOT_LOADER: bool = true;
/// Bytes of the boot loader's state ([`flash_map::STATE`]).
pub const STATE_LEN: u32 = flash_map::STATE.len;

/// Where an access of `len` bytes at `offset` of the DFU slot lies in the flash driver's
/// addressing ([`flash_map::DFU`], in bank 2).
pub fn dfu_at(offset: u32, len: u32) -> Option<u32> {
    within(flash_map::DFU, offset, len)
}

/// Where an access of `len` bytes at `offset` of the boot loader's state lies.
pub fn state_at(offset: u32, len: u32) -> Option<u32> {
    within(flash_map::STATE, offset, len)
}

fn within(region: flash_map::Region, offset: u32, len: u32) -> Option<u32> {
    (offset.checked_add(len)? <= region.len).then_some(region.start - flash_map::FLASH_START + offset)
}

/// The header in the running image's trailer (ACTIVE's last page): what an update installed.
pub fn active_trailer() -> [u8; drive_core::update::HEADER_LEN] {
    let at = flash_map::ACTIVE.start + drive_core::update::TRAILER;
    // SAFETY: ACTIVE is this chip's flash, mapped and readable; nothing writes it while the image
    // that lies in it runs.
    unsafe { core::ptr::read_volatile(at as *const [u8; drive_core::update::HEADER_LEN]) }
}

/// The parameter store on the flash. The blocking driver's `NorFlash` programs and erases
/// without a critical section, so interrupts (the control tick) stay enabled during a save.
pub type ParamStore = Store<BlockingAsync<Flash<'static, Blocking>>>;

/// The board's peripherals, configured.
pub struct Board {
    /// The flash, for the parameter store at [`STORE`].
    pub flash: Flash<'static, Blocking>,
    /// The RS-485 port (USART1, driver enable in hardware).
    pub uart: Serial,
    /// The power stage, with the pins the control tick sets.
    pub stage: Stage,
    /// The digital inputs.
    pub inputs: Inputs,
    /// The encoder's quadrature counter (TIM2), for the control tick.
    pub encoder: Qei<'static, TIM2>,
    /// The slow analog readings.
    pub sense: Sense,
    /// The independent watchdog, not yet started.
    pub watchdog: IndependentWatchdog<'static, peripherals::IWDG>,
}

/// The digital inputs, with edge interrupts.
pub struct Inputs {
    /// The factory-settings button.
    pub fset: ExtiInput<'static, Async>,
}

/// The slow analog readings: the bus voltage, the bridges' NTC and the analog input, which the
/// ADCs convert every PWM period after the phase currents ([`power_stage`]).
pub struct Sense;

/// The ADC's reference, VDDA, mV.
const VDDA_MV: u32 = 3300;
/// The bus voltage divider on PB12: 100 kΩ from the supply, 4.7 kΩ to ground (73.5 V full scale).
const DIVIDER_TOP_OHM: u32 = 100_000;
/// See [`DIVIDER_TOP_OHM`].
const DIVIDER_BOTTOM_OHM: u32 = 4_700;

impl Sense {
    /// The last raw 12-bit readings of the bus voltage, the bridges' NTC and the analog input.
    pub fn read_adc(&mut self) -> (u16, u16, u16) {
        power_stage::slow_samples()
    }

    /// Hands the bus voltage and temperature readings to the control tick, which checks them
    /// (under- and over-voltage, power loss, over-temperature), and the analog input's code.
    pub fn publish(supply_code: u16, ntc_code: u16, analog_code: u16) {
        let supply = supply_mv(supply_code);
        let temperature = bridge_temperature_c(ntc_code);
        critical_section::with(|cs| {
            let m = MEASURED.borrow(cs);
            let analog = Some(analog_code);
            m.set(Measured { supply_mv: Some(supply), temperature_c: temperature, analog, ..m.get() });
        });
    }
}

/// Millivolts of supply a code of the bus voltage reading, Q15 (17.95 mV a code): the current
/// loop converts a reading every PWM period, and a multiplication is what the exact formula's
/// 64-bit division (a library call) is not.
const SUPPLY_MV_PER_CODE_Q15: u32 = ((VDDA_MV as u64 * (DIVIDER_TOP_OHM + DIVIDER_BOTTOM_OHM) as u64 * 32_768
    + 4_095 * DIVIDER_BOTTOM_OHM as u64 / 2)
    / (4_095 * DIVIDER_BOTTOM_OHM as u64)) as u32;

/// The supply voltage, mV, of a bus voltage reading (12 bits).
pub const fn supply_mv(code: u16) -> u32 {
    // 4095 codes of 588 245: within 32 bits.
    let code = if code > 4_095 { 4_095 } else { code as u32 };
    (code * SUPPLY_MV_PER_CODE_Q15) >> 15
}

// Within a millivolt of the exact division at every code.
const _: () = {
    let mut code = 0u16;
    while code <= 4_095 {
        let exact = code as u64 * VDDA_MV as u64 * (DIVIDER_TOP_OHM + DIVIDER_BOTTOM_OHM) as u64
            / (4_095 * DIVIDER_BOTTOM_OHM as u64);
        let q = supply_mv(code) as u64;
        assert!(q + 1 >= exact && q <= exact + 1);
        code += 1;
    }
};

/// What the control tick gives the drive: the last supply and temperature of the sense task (none
/// before its first reading), and the encoder, read by the tick itself.
static MEASURED: Mutex<Cell<Measured>> = Mutex::new(Cell::new(Measured {
    supply_mv: None,
    temperature_c: None,
    phase_ma: None,
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
}));

/// The encoder's 16-bit quadrature counter, owned by the control tick, with the count extended to
/// 32 bits and the counter's value it was extended from.
struct Encoder {
    qei: Qei<'static, TIM2>,
    count: u32,
    last: u16,
}

/// The encoder, handed over by [`start_tick`].
static ENCODER: Mutex<RefCell<Option<Encoder>>> = Mutex::new(RefCell::new(None));

/// This tick's measurements: [`MEASURED`] with the encoder's count now. TIM2 counts at most a
/// few hundred counts in a tick, so the signed 16-bit difference extends it.
fn measure(cs: critical_section::CriticalSection<'_>, stage: Regulated) -> Measured {
    let encoder = ENCODER.borrow_ref_mut(cs).as_mut().map(|e| {
        let raw = e.qei.count();
        e.count = e.count.wrapping_add(raw.wrapping_sub(e.last) as i16 as u32);
        e.last = raw;
        e.count
    });
    // EXT1-3 on PA4-6, sampled every tick: the drive confirms an edge by reading the level again
    // after 0x6042, so a tick's sample is what it needs.
    let idr = pac::GPIOA.idr().read().0;
    let levels = ((idr >> 4) & 0b111) as u16 * drive_core::controller::io::PIN_EXT1;
    let index = pac::TIM2.sr().read().ccif(2);
    if index {
        pac::TIM2.sr().modify(|w| w.set_ccif(2, false));
    }
    let pulses = pac::TIM3.cnt().read().cnt();
    Measured {
        encoder,
        levels,
        index,
        pulses,
        supply_mv: Some(stage.supply_mv),
        phase_ma: Some(stage.phase_ma),
        phase_mv: Some(stage.applied_mv),
        back_emf_mv: Some(stage.back_emf_mv),
        coil_open: stage.open,
        tripped: stage.tripped,
        sensing_fault: stage.sensing_fault,
        ..MEASURED.borrow(cs).get()
    }
}

/// The power stage as the control tick drives it: the two H-bridges ([`Bridges`]) under the
/// windings' regulation, with the board's pins, coil output and pulse input that the tick's
/// outputs set too.
///
/// Each PWM period, at the end of the ADCs' sequence, [`Stage::regulate`] runs the current loop
/// on the currents just sampled towards the reference the last tick set, and writes the
/// voltages for the next period; then the tick runs and its outputs become the next reference
/// (`PowerStage::command`). The bridges are on while the tick asks a current and the tune gave
/// the loop its gains.
pub struct Stage {
    /// The two H-bridges.
    pub bridges: Bridges,
    /// The current loop's settings from the power-up tune; `None` before it, or if it failed
    /// (no motor, an open winding): the bridges stay off and the tick reads both windings open.
    windings: Option<WindingSettings>,
    /// The current loop's memory and reference.
    regulation: WindingState,
    /// Whole microsteps of the commutation the tick stepped since power-up (signed).
    steps: i64,
    /// The pins as last set up, and the outputs' levels (set again only when they change).
    pins: Option<(PinConfig, u16)>,
    /// The pulse input as last set up.
    pulse: Option<PulseInput>,
}

/// What the stage measured in a period, for the tick.
#[derive(Clone, Copy)]
struct Regulated {
    phase_ma: [i32; 2],
    supply_mv: u32,
    applied_mv: [i32; 2],
    back_emf_mv: [i32; 2],
    open: [bool; 2],
    tripped: bool,
    sensing_fault: bool,
}

impl Stage {
    /// The commutation the tick has stepped through, whole microsteps since power-up.
    pub fn commanded(&self) -> i64 {
        self.steps
    }

    /// Whether the current loop has its settings (from the tune or the objects): without them
    /// the bridges stay off.
    pub fn has_loop(&self) -> bool {
        self.windings.is_some()
    }

    /// The current loop as the parameters `params` say at power-up (0x210B, 0x2108, 0x2109,
    /// 0x210C, 0x210D): tuned ([`Stage::tune`], its results written into them) or from them.
    /// With no loop (a failed tune, objects the loop refuses) the bridges stay off.
    pub fn power_up_loop(&mut self, params: &mut drive_core::Params) {
        use drive_core::od::{CURRENT_LOOP_OBJECTS, Obj};
        let word = |obj: Obj| params.get(obj).min(u32::from(u16::MAX)) as u16;
        let objects = LoopObjects::from_words(CURRENT_LOOP_OBJECTS.map(word));
        if params.get(Obj::CurrentAutoTune) == 0 {
            let v_bus = supply_mv(power_stage::slow_samples().0) as f32 * 1e-3;
            self.windings = objects.settings(v_bus, power_stage::PWM_HZ as f32).ok();
            return;
        }
        self.tune(word(Obj::PhaseCurrent));
        if let Some(settings) = &self.windings {
            for (obj, v) in CURRENT_LOOP_OBJECTS.into_iter().zip(LoopObjects::of(settings).words()) {
                params.set(obj, u32::from(v));
            }
        }
    }

    /// The power-up auto-tune of both windings at `test_current_ma` (`drive_core::windings::
    /// PowerUpTune`: one winding, then the other), a PWM period at a time on the ADCs' end of
    /// sequence, about a second; before the tick starts (nothing else drives the bridges). Its
    /// result is logged; failed, the bridges stay off.
    fn tune(&mut self, test_current_ma: u16) {
        let Ok(mut tune) = PowerUpTune::new(test_current_ma.clamp(100, 10_000), power_stage::PWM_HZ as f32) else {
            return;
        };
        self.bridges.set_phase_voltages([0, 0]);
        if !self.bridges.enable() {
            defmt::warn!("auto-tune: the bridges do not turn on (over-current trip)");
            return;
        }
        let result = loop {
            if !power_stage::wait_for_sample() {
                break Err(drive_core::autotune::Error::NoCurrent);
            }
            let samples = self.bridges.samples();
            let phase_ma = self.bridges.phase_ma(&samples);
            match tune.step(phase_ma, supply_mv(samples.bus)) {
                TuneStep::Apply(shares) => self.bridges.set_phase_voltages(shares),
                TuneStep::Done(done) => break done,
            }
        };
        self.bridges.set_phase_voltages([0, 0]);
        self.bridges.disable();
        match result {
            Ok((settings, [a, b])) => {
                defmt::info!(
                    "auto-tune: A {} mΩ {} µH, B {} mΩ {} µH",
                    (a.resistance * 1e3) as u32,
                    (a.inductance * 1e6) as u32,
                    (b.resistance * 1e3) as u32,
                    (b.inductance * 1e6) as u32,
                );
                self.windings = Some(WindingSettings::new(settings));
            }
            Err(e) => defmt::warn!("auto-tune failed: {}; the bridges stay off", defmt::Debug2Format(&e)),
        }
    }

    /// One PWM period, before the tick: the currents and the bus just sampled, the current loop's
    /// voltages for the next period (the bridges on while it gives some).
    fn regulate(&mut self) -> Regulated {
        let samples = self.bridges.samples();
        let phase_ma = self.bridges.phase_ma(&samples);
        let supply_mv = supply_mv(samples.bus);
        let shares = self.windings.as_ref().and_then(|w| w.period(&mut self.regulation, phase_ma, supply_mv));
        match shares {
            Some(shares) => {
                self.bridges.set_phase_voltages(shares);
                if !self.bridges.enabled() {
                    // Off after a trip until the tick turns the bridges off (its fault reaction).
                    self.bridges.enable();
                }
            }
            None if self.bridges.enabled() => {
                self.bridges.disable();
                self.bridges.set_phase_voltages([0, 0]);
            }
            None => {}
        }
        let open = self.regulation.open();
        let (applied_mv, back_emf_mv) = (self.regulation.applied_mv(), self.regulation.back_emf_mv());
        let (tripped, sensing_fault) = (power_stage::tripped(), !sensing_ok(self.bridges.zero()));
        Regulated { phase_ma, supply_mv, applied_mv, back_emf_mv, open, tripped, sensing_fault }
    }
}

impl PowerStage for Stage {
    fn command(&mut self, out: &drive_core::control::Outputs) {
        // With no loop (a failed tune) the windings read open while a current is asked.
        command_or_open(self.windings.as_ref(), &mut self.regulation, out);
    }

    fn step(&mut self, steps: i64) {
        self.steps = self.steps.wrapping_add(steps);
    }

    fn set_current(&mut self, milliamps: u16) {
        if milliamps == 0 {
            // Off at once, not at the next period; a trip is forgotten with the fault that
            // reported it (the drive turns the bridges on again only once that is cleared).
            self.bridges.disable();
            self.bridges.clear_trip();
        }
    }

    fn set_pins(&mut self, pins: &PinConfig, levels: u16) {
        if self.pins == Some((*pins, levels)) {
            return;
        }
        self.pins = Some((*pins, levels));
        use pac::gpio::vals::{Moder, Ot, Pupdr};
        let pull = |k: u32| match pins.mode(k) {
            PinMode::PullUp => Pupdr::PULL_UP,
            PinMode::PullDown => Pupdr::PULL_DOWN,
            _ => Pupdr::FLOATING,
        };
        // EXT1-3 (0x6031 bits 7-9) on PA4-6: inputs, their pulls.
        for (k, pin) in [(7, 4), (8, 5), (9, 6)] {
            pac::GPIOA.pupdr().modify(|w| w.set_pupdr(pin, pull(k)));
        }
        // GPIO8 (bit 11) on PB7.
        let g = pac::GPIOB;
        if pins.outputs & GPIO8 != 0 {
            let ot = if pins.mode(11) == PinMode::PushPull { Ot::PUSH_PULL } else { Ot::OPEN_DRAIN };
            g.otyper().modify(|w| w.set_ot(7, ot));
            g.bsrr().write(|w| if levels & GPIO8 != 0 { w.set_bs(7, true) } else { w.set_br(7, true) });
            g.moder().modify(|w| w.set_moder(7, Moder::OUTPUT));
        } else {
            g.pupdr().modify(|w| w.set_pupdr(7, pull(11)));
            g.moder().modify(|w| w.set_moder(7, Moder::INPUT));
        }
    }

    fn set_coil(&mut self, duty: u8) {
        let ccr = u32::from(duty.min(100)) * COIL_PWM_PERIOD / 100;
        pac::TIM17.ccr(0).write(|w| w.set_ccr(ccr as u16));
    }

    fn set_pulse_input(&mut self, input: &PulseInput) {
        if self.pulse == Some(*input) {
            return;
        }
        self.pulse = Some(*input);
        use pac::timer::vals::{FilterValue, Sms};
        // RM0440's encoder interface: clock plus direction counts one edge of CH2's clock a
        // pulse (either edge counts each pulse once) with CH1's level for the direction (CC1P =
        // 1: high counts down); the directional clock counts CH2's edges up and CH1's down
        // (CCxP = 1: rising edges); quadrature counts every edge of both, CH1 inverted so that
        // A on CH2 leading counts up. Not yet checked on a board (docs/board-g474.md).
        let (sms, clock_rising) = match input.format {
            PulseFormat::StepDir => (Sms::ENCODER_UP_X1, false),
            PulseFormat::CwCcw => (Sms::ENCODER_DIR_X1, true),
            PulseFormat::Quadrature => (Sms::ENCODER_MODE_3, false),
        };
        let t = pac::TIM3;
        t.cr1().modify(|w| w.set_cen(false));
        t.ccer().modify(|w| {
            // CH1 inverted in every format (see above).
            w.set_ccp(0, true);
            w.set_ccp(1, clock_rising);
        });
        let f = FilterValue::from_bits(input.filter.min(15));
        t.ccmr_input(0).modify(|w| {
            w.set_icf(0, f);
            w.set_icf(1, f);
        });
        t.smcr().modify(|w| w.set_sms(sms));
        t.cr1().modify(|w| w.set_cen(true));
    }
}

/// GPIO8's bit in 0x6031.
const GPIO8: u16 = 1 << 11;

/// Timer counts in a period of the coil output's PWM: 20 kHz at 170 MHz.
const COIL_PWM_PERIOD: u32 = 8500;

/// Cuts the power stage with raw register writes, whatever state the drivers are in: every
/// switch of the bridges off (MOE off on TIM8 and TIM1). For the panic and fault handlers.
pub fn power_off() {
    power_stage::off();
    // The coil off too: a brake applies, a valve or magnet drops.
    pac::TIM17.ccr(0).write(|w| w.set_ccr(0));
}

/// The power stage the tick interrupt drives, handed over by [`start_tick`].
static STAGE: Mutex<RefCell<Option<Stage>>> = Mutex::new(RefCell::new(None));

/// The electrical angle the tick has stepped the stage through, whole microsteps since
/// power-up ([`Stage::commanded`]); `None` before [`start_tick`].
#[allow(dead_code, reason = "read by the HIL suite")]
pub fn commanded_steps() -> Option<i64> {
    critical_section::with(|cs| STAGE.borrow_ref(cs).as_ref().map(Stage::commanded))
}

/// Cycles the last control tick took (DWT cycle counter), and the most any took.
pub static TICK_CYCLES: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);
/// The longest control tick so far, in cycles.
pub static TICK_CYCLES_MAX: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);
/// Shortest and longest time between the starts of two control ticks, in cycles (the jitter).
pub static TICK_PERIOD_MIN: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(u32::MAX);
/// See [`TICK_PERIOD_MIN`].
pub static TICK_PERIOD_MAX: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);
/// Cycle count at the start of the last tick (0: none yet).
static TICK_LAST_START: core::sync::atomic::AtomicU32 = core::sync::atomic::AtomicU32::new(0);

/// The 20 kHz control tick on the ADCs' end of sequence, each PWM period: the current loop, then
/// the tick.
struct TickHandler;

impl interrupt::typelevel::Handler<interrupt::typelevel::ADC1_2> for TickHandler {
    unsafe fn on_interrupt() {
        use core::sync::atomic::Ordering::Relaxed;
        let start = cortex_m::peripheral::DWT::cycle_count();
        let last = TICK_LAST_START.swap(start, Relaxed);
        if last != 0 {
            let period = start.wrapping_sub(last);
            TICK_PERIOD_MIN.fetch_min(period, Relaxed);
            TICK_PERIOD_MAX.fetch_max(period, Relaxed);
        }
        critical_section::with(|cs| {
            if let Some(stage) = STAGE.borrow_ref_mut(cs).as_mut() {
                // `samples` clears the end-of-sequence flag that raised this interrupt.
                let regulated = stage.regulate();
                crate::app::control_tick(crate::app::now(), || measure(cs, regulated), stage);
            } else {
                pac::ADC1.isr().write(|w| w.set_jeos(true));
            }
        });
        let cycles = cortex_m::peripheral::DWT::cycle_count().wrapping_sub(start);
        TICK_CYCLES.store(cycles, Relaxed);
        TICK_CYCLES_MAX.fetch_max(cycles, Relaxed);
    }
}

/// Hands the power stage and the encoder to the control tick and starts it: the ADCs' end of
/// sequence each PWM period ([`TICK_HZ`]).
pub fn start_tick(stage: Stage, encoder: Qei<'static, TIM2>) {
    let last = encoder.count();
    critical_section::with(|cs| {
        STAGE.borrow_ref_mut(cs).replace(stage);
        ENCODER.borrow_ref_mut(cs).replace(Encoder { qei: encoder, count: 0, last });
    });
    pac::ADC1.isr().write(|w| w.set_jeos(true));
    pac::ADC1.ier().modify(|w| w.set_jeosie(true));
    interrupt::ADC1_2.set_priority(Priority::P0);
    interrupt::ADC1_2.unpend();
    // SAFETY: the handler (TickHandler) only touches STAGE and the drive through their mutexes.
    unsafe { interrupt::ADC1_2.enable() };
}

/// Sets up clocks and peripherals; the UART runs 8N1 at the factory 9600 baud until
/// [`set_serial`] sets the drive's (known once the parameters are loaded from flash).
// Out of line: inlined, its temporaries would enlarge the main task's poll frame, which is on
// the stack under the drive's construction (`app::start`).
#[inline(never)]
pub fn init() -> Board {
    let mut config = embassy_stm32::Config::default();
    let rcc = &mut config.rcc;
    rcc.pll = Some(Pll {
        source: PllSource::HSI,
        prediv: PllPreDiv::DIV4, // 4 MHz PLL input
        mul: PllMul::MUL85,      // 340 MHz VCO
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2), // 170 MHz
    });
    rcc.sys = Sysclk::PLL1_R;
    rcc.boost = true; // required above 150 MHz
    // ADC1/ADC2 on SYSCLK (embassy divides it by 4: 42.5 MHz); the reset value selects no clock,
    // and `Adc::new` then panics.
    rcc.mux.adc12sel = embassy_stm32::rcc::mux::Adcsel::SYS;
    check_option_bytes();
    let p = embassy_stm32::init(config);

    // The tick's cost is measured with the cycle counter.
    if let Some(mut core) = cortex_m::Peripherals::take() {
        core.DCB.enable_trace();
        core.DWT.enable_cycle_counter();
    }

    // The bridges first: their outputs driven off and the over-current trip armed.
    let bridges = Bridges::new(
        power_stage::Parts {
            tim8: p.TIM8,
            tim1: p.TIM1,
            a1_high: p.PC6,
            a1_low: p.PC10,
            a2_high: p.PB8,
            a2_low: p.PC11,
            b1_high: p.PB9,
            b1_low: p.PB1,
            b2_high: p.PA8,
            b2_low: p.PA11,
            shunt_a: p.PA3,
            shunt_b: p.PB13,
            opamp_a: p.OPAMP1,
            opamp_b: p.OPAMP3,
            comp_a: p.COMP2,
            comp_b: p.COMP5,
            dac_a: p.DAC3,
            dac_b: p.DAC4,
            adc1: p.ADC1,
            adc2: p.ADC2,
            bus_voltage: p.PB12,
            ntc: p.PB2,
            analog_in: p.PB14,
        },
        OVER_CURRENT_UNTIL_LOADED_MA,
    );

    let uart_config = uart_config(Baud::FACTORY, 0);
    // Each singleton! yields once; a second `init` already panicked in `embassy_stm32::init`.
    let (Some(tx_buf), Some(rx_buf)) =
        (singleton!(: [u8; TX_BUF] = [0; TX_BUF]), singleton!(: [u8; RX_BUF] = [0; RX_BUF]))
    else {
        defmt::panic!("board::init called twice");
    };
    let uart =
        defmt::unwrap!(BufferedUart::new_with_de(p.USART1, p.PA10, p.PA9, p.PA12, Irqs, tx_buf, rx_buf, uart_config));
    // Below the control tick: a burst of bytes delays the tick by one short handler at most.
    interrupt::USART1.set_priority(Priority::P2);
    interrupt::EXTI15_10.set_priority(Priority::P3);

    let stage =
        Stage { bridges, windings: None, regulation: WindingState::default(), steps: 0, pins: None, pulse: None };
    let _ = (p.TIM17, p.PA7); // owned by the raw timer setup below
    setup_coil_pwm();
    let _ = (p.TIM3, p.PB4, p.PB5);
    setup_pulse_input();
    // EXT1-3 and GPIO8: inputs at reset, set up by the control tick's outputs (`set_pins`).
    let _ = (p.PA4, p.PA5, p.PA6, p.PB7);

    let inputs = Inputs { fset: ExtiInput::new(p.PC13, p.EXTI13, Pull::Up, Irqs) };
    let encoder = Qei::new(p.TIM2, p.PA0, p.PA1, QeiConfig::default());
    // The encoder's index (Z) on PA2, TIM2 channel 3: a rising edge sets CC3IF, which the tick
    // reads and clears (`measure`), so that a pulse shorter than a tick is not missed.
    let _ = p.PA2;
    pac::TIM2.ccmr_input(1).modify(|w| w.set_ccs(0, pac::timer::vals::CcmrInputCcs::TI4));
    pac::TIM2.ccer().modify(|w| w.set_cce(2, true));
    let z = pins::ENCODER_Z.number();
    pac::GPIOA.afr(z / 8).modify(|w| w.set_afr(z % 8, pins::ENCODER_Z.af_number()));
    pac::GPIOA.moder().modify(|w| w.set_moder(z, pac::gpio::vals::Moder::ALTERNATE));
    let watchdog = IndependentWatchdog::new(p.IWDG, 500_000);
    Board { flash: Flash::new_blocking(p.FLASH), uart, stage, inputs, encoder, sense: Sense, watchdog }
}

/// Halts, before any peripheral is set up (the power stage off), unless the option bytes put
/// the flash in the dual-bank mode that [`flash_map`] is laid out for (DBANK = 1, the G474CE's
/// factory setting). In single-bank mode the pages are 4 KiB and bank 2's addresses are not
/// where the parameter store and the update slot are: nothing would be where the build says.
fn check_option_bytes() {
    if !pac::FLASH.optr().read().dbank() {
        defmt::panic!(
            "the flash is in single-bank mode (option bit DBANK = 0): this firmware needs DBANK = 1 (docs/board-g474.md)"
        );
    }
}

/// The UART settings for `baud` and `parity` (object 0x2100: 0 none, 1 even, 2 odd).
fn uart_config(baud: Baud, parity: u32) -> usart::Config {
    let mut config = usart::Config::default();
    config.baudrate = baud.get();
    // 8 data bits either way: with parity the USART frames 9 bits.
    config.parity = match parity {
        1 => usart::Parity::ParityEven,
        2 => usart::Parity::ParityOdd,
        _ => usart::Parity::ParityNone,
    };
    // Wake the reader at every byte so each one is time-stamped close to its arrival (t1.5/t3.5).
    config.eager_reads = Some(1);
    // embassy-stm32 0.6 writes DEDT from `de_assertion_time` too: keep both the same.
    config.de_assertion_time = 16; // one bit time of DE before the start bit
    config.de_deassertion_time = 16;
    config
}

/// Runs the UART at the drive's power-up settings: `baud` and `parity` (0x2100).
pub fn set_serial(uart: &mut Serial, baud: Baud, parity: u32) {
    if uart.set_config(&uart_config(baud, parity)).is_err() {
        defmt::warn!("uart: {} baud not reachable from the kernel clock", baud.get());
    }
}

/// TIM3 on PB4 (CH1) and PB5 (CH2): the pulse input's counter, both channels inputs on their
/// own lines; the format and filter are the drive's (`set_pulse_input`, at the first tick).
fn setup_pulse_input() {
    pac::RCC.apb1enr1().modify(|w| w.set_tim3en(true));
    let t = pac::TIM3;
    t.psc().write_value(0);
    t.arr().write(|w| w.set_arr(u16::MAX));
    t.ccmr_input(0).modify(|w| {
        w.set_ccs(0, pac::timer::vals::CcmrInputCcs::TI4);
        w.set_ccs(1, pac::timer::vals::CcmrInputCcs::TI4);
    });
    for pin in [pins::PULSE_B, pins::PULSE_A] {
        let n = pin.number();
        pac::GPIOB.afr(n / 8).modify(|w| w.set_afr(n % 8, pin.af_number()));
        pac::GPIOB.moder().modify(|w| w.set_moder(n, pac::gpio::vals::Moder::ALTERNATE));
    }
}

/// TIM17 channel 1 on PA7: the coil output's 20 kHz PWM, duty 0 until the drive asks for it.
fn setup_coil_pwm() {
    pac::RCC.apb2enr().modify(|w| w.set_tim17en(true));
    let t = pac::TIM17;
    t.psc().write_value(0);
    t.arr().write(|w| w.set_arr((COIL_PWM_PERIOD - 1) as u16));
    t.ccr(0).write(|w| w.set_ccr(0));
    t.ccmr_output(0).modify(|w| {
        w.set_ocm(0, pac::timer::vals::Ocm::PWM_MODE1);
        w.set_ocpe(0, true);
    });
    t.ccer().modify(|w| w.set_cce(0, true));
    t.bdtr().modify(|w| w.set_moe(true));
    t.egr().write(|w| w.set_ug(true));
    t.cr1().modify(|w| w.set_cen(true));
    let g = pac::GPIOA;
    let n = pins::COIL.number();
    g.afr(n / 8).modify(|w| w.set_afr(n % 8, pins::COIL.af_number()));
    g.moder().modify(|w| w.set_moder(n, pac::gpio::vals::Moder::ALTERNATE));
}
