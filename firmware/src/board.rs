//! The STM32G431CB board: clocks, pin map and peripheral setup. Nothing else knows a pin name.
//!
//! | signal        | pin  | peripheral              | notes                                           |
//! |---------------|------|-------------------------|-------------------------------------------------|
//! | RS-485 TX     | PA9  | USART1_TX (AF7)         |                                                 |
//! | RS-485 RX     | PA10 | USART1_RX (AF7)         |                                                 |
//! | RS-485 DE     | PA12 | USART1_DE (AF7)         | driven by the USART; transceiver /RE tied to DE |
//! | STEP          | PB0  | GPIO out, push-pull     | idle low                                        |
//! | DIR           | PB1  | GPIO out, push-pull     | idle low                                        |
//! | ENABLE        | PB2  | GPIO out, push-pull     | active low on the usual drivers: high = off     |
//! | EXT1          | PA4  | GPIO in, pull-up, EXTI4 |                                                 |
//! | EXT2          | PA5  | GPIO in, pull-up, EXTI5 |                                                 |
//! | EXT3          | PA6  | GPIO in, pull-up, EXTI6 |                                                 |
//! | FSET          | PC13 | GPIO in, pull-up, EXTI13| factory-settings button to ground               |
//! | SWDIO / SWCLK | PA13 / PA14 | debug            | left alone for the probe (RTT logs)             |
//!
//! Flash: the last four 2 KiB pages ([`STORE`]) hold the parameter store; `memory.x` keeps the
//! program below them.
//!
//! Clock: HSI16 / 4 × 85 / 2 = 170 MHz SYSCLK from the PLL, range-1 boost mode; AHB, APB1 and
//! APB2 undivided, so USART1's kernel clock (PCLK2) is 170 MHz.

use core::ops::Range;

use cortex_m::singleton;
use drive_core::Baud;
use embassy_stm32::exti::{self, ExtiInput};
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::gpio::{Level, Output, Pull, Speed};
use embassy_stm32::mode::Async;
use embassy_stm32::rcc::{Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk};
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::{bind_interrupts, interrupt, peripherals};

bind_interrupts!(struct Irqs {
    USART1 => usart::BufferedInterruptHandler<peripherals::USART1>;
    EXTI4 => exti::InterruptHandler<interrupt::typelevel::EXTI4>;
    EXTI9_5 => exti::InterruptHandler<interrupt::typelevel::EXTI9_5>;
    EXTI15_10 => exti::InterruptHandler<interrupt::typelevel::EXTI15_10>;
});

/// Receive and transmit ring sizes: a whole RTU frame (256 bytes) fits either way.
const RX_BUF: usize = 256;
const TX_BUF: usize = 256;

/// The parameter store's pages, as offsets from the start of flash: the last 8 KiB of the 128.
pub const STORE: Range<u32> = 0x1E000..0x2_0000;

/// The board's peripherals, configured.
pub struct Board {
    /// The flash, for the parameter store at [`STORE`]. A page erase stalls code fetches for
    /// ~22 ms (one bank): the drive refuses saves while the axis moves.
    pub flash: Flash<'static, Blocking>,
    /// The RS-485 port (USART1, driver enable in hardware).
    pub uart: BufferedUart<'static>,
    /// Outputs to the external step/direction driver.
    pub motor: MotorPins,
    /// The digital inputs.
    pub inputs: Inputs,
}

/// STEP, DIR and ENABLE to an external step/direction driver.
#[expect(dead_code, reason = "the motion issue drives these; held now so the outputs stay defined")]
pub struct MotorPins {
    /// One microstep per rising edge.
    pub step: Output<'static>,
    /// Direction, sampled by the driver at each step.
    pub dir: Output<'static>,
    /// Driver enable, active low.
    pub enable: Output<'static>,
}

/// The digital inputs, with edge interrupts.
pub struct Inputs {
    /// EXT1..EXT3 (limit/home switches and general inputs).
    pub ext: [ExtiInput<'static, Async>; 3],
    /// The factory-settings button.
    pub fset: ExtiInput<'static, Async>,
}

/// Sets up clocks and peripherals; the UART runs 8N1 at the factory 9600 baud until
/// [`set_serial`] sets the drive's (known once the parameters are loaded from flash).
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
    let p = embassy_stm32::init(config);

    let uart_config = uart_config(Baud::FACTORY, 0);
    // Each singleton! yields once; a second `init` already panicked in `embassy_stm32::init`.
    let (Some(tx_buf), Some(rx_buf)) =
        (singleton!(: [u8; TX_BUF] = [0; TX_BUF]), singleton!(: [u8; RX_BUF] = [0; RX_BUF]))
    else {
        defmt::panic!("board::init called twice");
    };
    let uart =
        defmt::unwrap!(BufferedUart::new_with_de(p.USART1, p.PA10, p.PA9, p.PA12, Irqs, tx_buf, rx_buf, uart_config));

    let motor = MotorPins {
        step: Output::new(p.PB0, Level::Low, Speed::VeryHigh),
        dir: Output::new(p.PB1, Level::Low, Speed::Low),
        enable: Output::new(p.PB2, Level::High, Speed::Low), // motor off until told otherwise
    };
    let inputs = Inputs {
        ext: [
            ExtiInput::new(p.PA4, p.EXTI4, Pull::Up, Irqs),
            ExtiInput::new(p.PA5, p.EXTI5, Pull::Up, Irqs),
            ExtiInput::new(p.PA6, p.EXTI6, Pull::Up, Irqs),
        ],
        fset: ExtiInput::new(p.PC13, p.EXTI13, Pull::Up, Irqs),
    };
    Board { flash: Flash::new_blocking(p.FLASH), uart, motor, inputs }
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
pub fn set_serial(uart: &mut BufferedUart<'static>, baud: Baud, parity: u32) {
    if uart.set_config(&uart_config(baud, parity)).is_err() {
        defmt::warn!("uart: {} baud not reachable from the kernel clock", baud.get());
    }
}
