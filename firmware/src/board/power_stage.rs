//! The drive's own power stage (issue 39): two H-bridges, one per phase of the motor, as four
//! half-bridges (legs) with complementary PWM and dead time; a shunt in the low side of each
//! bridge's first leg, amplified inside the chip (OPAMP1 and OPAMP3 as PGAs) into ADC1 and ADC2,
//! sampled at the centre of every PWM period together with the bus voltage, the bridges' NTC and
//! the analog input; and an over-current trip with no software in its path: a comparator on each
//! shunt (COMP2, COMP5) against a DAC threshold (DAC3, DAC4, internal) into the break input of
//! both timers. The pins, and why these peripherals: `docs/board-g474.md` (*The power stage*).
//!
//! - **Timers.** TIM8 drives phase A's legs (CH1, CH2) and phase B's first (CH3), TIM1 phase B's
//!   second (CH1): the 48-pin package has no fourth complementary pair on TIM8, and TIM1's CH2 and
//!   CH3 only on the RS-485 pins. TIM8's counter enable is its trigger output and TIM1 starts on
//!   it (trigger mode on ITR5), so that the two count in step. Centre-aligned at [`PWM_HZ`]: the
//!   counter runs 0 → [`PERIOD`] → 0; a leg's high side conducts while the counter is under its
//!   compare value (PWM mode 1), its low side around the top, each switch turned on
//!   [`DEAD_TIME_NS`] after the other went off.
//! - **Safe state.** From reset the gate drivers' inputs are pulled down on the board (the pins
//!   are analog, floating, until the timers take them). Set up, the outputs are enabled at their
//!   idle level (every switch off) with the main output enable (MOE) off: [`Bridges::enable`]
//!   turns it on. A comparator going high (through the break filter, against switching spikes)
//!   clears MOE of both timers in hardware, and it stays cleared (no automatic re-enable) until
//!   [`Bridges::clear_trip`] and [`Bridges::enable`]; a core lockup does the same (SYSCFG CLL).
//!   The dead time, break and idle settings are locked once set (LOCK level 1).
//! - **Sampling.** At the top of the count both low sides of a bridge conduct (a duty never
//!   reaches [`MAX_CCR`]): the winding's current circulates through them, through the shunt of
//!   leg 1. TIM8's OC4REF (CCR4 = [`PERIOD`] − [`SAMPLE_LEAD`], PWM mode 1) is its TRGO2, and
//!   its falling edge starts both ADCs' injected sequences: the currents first, their sampling
//!   window centred on the top, then the slower channels (bus voltage and analog input on ADC1,
//!   the NTC on ADC2). The sequences end in about 13 µs of the 50 µs period.
//!
//! embassy-stm32 0.6 sets up the timers (`ComplementaryPwm`: centre-aligned PWM, dead time, idle
//! state, break from the comparators, TRGO2, duties), the op-amps (`OpAmp::pga_int`, with its
//! offset calibration), the comparators (`Comp`), the DACs (`DacChannel::new_internal_blocking`)
//! and the ADCs (`Adc::new`, `setup_injected_conversions` on TIM8's TRGO2). The PAC does what it
//! lacks: the auto-reload (embassy counts a centre-aligned period as 2·(ARR+1), RM0440 as
//! 2·ARR), TIM8's trigger output and TIM1's trigger mode, the break flags, LOCK, SYSCFG's lockup
//! break, re-enabling an op-amp that `degrade_adc` disabled (its internal output's `Drop` runs
//! there), and reading the slow channels' results from another task.

use cortex_m::singleton;
use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, AnyAdcChannel, Exten, InjectedAdc, SampleTime};
use embassy_stm32::comp::{self, Comp, Hysteresis, InvertingInput};
use embassy_stm32::dac::{Ch1, Ch2, DacChannel, Value};
use embassy_stm32::gpio::OutputType;
use embassy_stm32::mode::Blocking;
use embassy_stm32::opamp::{OpAmp, OpAmpGain, OpAmpSpeed};
use embassy_stm32::pac;
use embassy_stm32::peripherals::{
    ADC1, ADC2, COMP2, COMP5, DAC3, DAC4, OPAMP1, OPAMP3, PA3, PA8, PA11, PB1, PB2, PB8, PB9, PB12, PB13, PB14, PC6,
    PC10, PC11, TIM1, TIM8,
};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::complementary_pwm::{
    BreakInputPolarity, ComplementaryPwm, ComplementaryPwmPin, FilterValue, Mms2, Ossi, Ossr,
};
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::{AdvancedInstance4Channel, Channel};
use embassy_stm32::{Peri, triggers};

use super::{Irqs, TIMER_HZ, VDDA_MV};

/// PWM frequency, Hz: above hearing, and the control tick's rate.
pub const PWM_HZ: u32 = 20_000;
/// The auto-reload value: half a PWM period in timer counts (centre-aligned, the counter runs up
/// to it and back), 4250 at 170 MHz. A leg's compare value is its high side's share of it.
pub const PERIOD: u16 = (TIMER_HZ / (2 * PWM_HZ)) as u16;
/// Timer counts in a microsecond.
const COUNTS_PER_US: u32 = TIMER_HZ / 1_000_000;
/// The dead time, ns: from one switch of a leg turning off to the other turning on (the gate
/// drivers' propagation skew and the MOSFETs' turn-off, with margin).
pub const DEAD_TIME_NS: u32 = 300;
/// The dead time in timer counts (5.9 ns each), rounded up.
const DEAD_TIME_COUNTS: u16 = (DEAD_TIME_NS * COUNTS_PER_US).div_ceil(1000) as u16;
// Under 128 counts the dead-time generator counts the timer's own clock (CKD = 1, DTG linear),
// and the break filter's clock (fDTS) stays 170 MHz.
const _: () = assert!(DEAD_TIME_COUNTS < 128);

/// The ADC clock: SYSCLK / 4, embassy-stm32's prescaler for 170 MHz under the ADC's 60 MHz.
const ADC_HZ: u32 = TIMER_HZ / 4;
/// The phase currents' sampling time: 12.5 ADC cycles (294 ns; the op-amps drive the ADC
/// inside the chip, at low impedance).
const CURRENT_SAMPLE: SampleTime = SampleTime::CYCLES12_5;
/// The slow channels' sampling time (5.8 µs): the dividers' and the NTC's source impedance.
const SLOW_SAMPLE: SampleTime = SampleTime::CYCLES247_5;
/// How far before the top the ADCs start (half of [`CURRENT_SAMPLE`] in timer counts), so that
/// the currents' sampling window is centred on the top of the count.
pub const SAMPLE_LEAD: u16 = (TIMER_HZ / ADC_HZ * 25 / 4) as u16;
/// The shortest time a leg's low side conducts around the top, ns: the dead time, the shunt
/// signal settling after the switch (ringing, the PGA) and the sample itself.
const MIN_LOW_SIDE_NS: u32 = 2_000;
/// The highest compare value a leg gets: its low side conducts 2·(PERIOD − CCR) counts around
/// the top, less the dead time, which must cover [`MIN_LOW_SIDE_NS`] (a duty of 95 %).
pub const MAX_CCR: u16 = PERIOD - (MIN_LOW_SIDE_NS * COUNTS_PER_US / 1000 + DEAD_TIME_COUNTS as u32).div_ceil(2) as u16;

/// The shunts, mΩ.
pub const SHUNT_MOHM: u32 = 20;
/// The op-amps' PGA gain.
const PGA_GAIN: u32 = 8;
/// The bias network at each op-amp's input: 15 kΩ from VDDA and 1 kΩ from the shunt, so that
/// VINP = VDDA/16 + 15/16 of the shunt's voltage; the PGA's output sits at VDDA/2 at zero
/// current and swings VDDA/2 either way for ±11 A.
const BIAS_DIV: u32 = 16;
/// mA a phase current's ADC code stands for, in 1/65536 (5.37 mA a code: ±11 A full scale).
const MA_PER_CODE_Q16: i32 = (((VDDA_MV as u64 * BIAS_DIV as u64 * 1000) << 16)
    / (4095 * PGA_GAIN as u64 * (BIAS_DIV as u64 - 1) * SHUNT_MOHM as u64)) as i32;
/// The hardware trip's margin over the drive's over-current setting (0x2133), percent: the
/// drive's own check on the sampled currents acts first, the comparator on what is faster.
const TRIP_PERCENT: u32 = 125;
/// How many PWM periods the currents' zero is averaged over at power-up (bridges off).
const ZERO_SAMPLES: u32 = 16;

/// The NTC's readings from -20 °C to 150 °C in steps of 10 °C: 10 kΩ at 25 °C, B 3435, to
/// ground, 10 kΩ to VDDA (ratiometric: code = 4095 · R / (R + 10 kΩ)).
const NTC_CODES: [u16; 18] =
    [3627, 3368, 3037, 2654, 2248, 1854, 1496, 1191, 940, 740, 584, 462, 368, 295, 238, 194, 159, 132];
/// Codes above this: the NTC is open (or not fitted); under [`NTC_SHORT`]: shorted.
const NTC_OPEN: u16 = 4000;
/// See [`NTC_OPEN`] (about 200 °C).
const NTC_SHORT: u16 = 60;

/// The peripherals and pins the power stage takes (`docs/board-g474.md`, `pins.rs`).
pub struct Parts {
    /// Phase A's legs and phase B's first.
    pub tim8: Peri<'static, TIM8>,
    /// Phase B's second leg.
    pub tim1: Peri<'static, TIM1>,
    /// TIM8_CH1.
    pub a1_high: Peri<'static, PC6>,
    /// TIM8_CH1N.
    pub a1_low: Peri<'static, PC10>,
    /// TIM8_CH2.
    pub a2_high: Peri<'static, PB8>,
    /// TIM8_CH2N.
    pub a2_low: Peri<'static, PC11>,
    /// TIM8_CH3.
    pub b1_high: Peri<'static, PB9>,
    /// TIM8_CH3N.
    pub b1_low: Peri<'static, PB1>,
    /// TIM1_CH1.
    pub b2_high: Peri<'static, PA8>,
    /// TIM1_CH1N.
    pub b2_low: Peri<'static, PA11>,
    /// Phase A's shunt: OPAMP1_VINP1 and COMP2_INP1.
    pub shunt_a: Peri<'static, PA3>,
    /// Phase B's shunt: OPAMP3_VINP1 and COMP5_INP0.
    pub shunt_b: Peri<'static, PB13>,
    /// Phase A's amplifier.
    pub opamp_a: Peri<'static, OPAMP1>,
    /// Phase B's amplifier.
    pub opamp_b: Peri<'static, OPAMP3>,
    /// Phase A's over-current comparator.
    pub comp_a: Peri<'static, COMP2>,
    /// Phase B's over-current comparator.
    pub comp_b: Peri<'static, COMP5>,
    /// COMP2's threshold (channel 2, the one COMP2's inverting input takes).
    pub dac_a: Peri<'static, DAC3>,
    /// COMP5's threshold (channel 1).
    pub dac_b: Peri<'static, DAC4>,
    /// Phase A's current, the bus voltage and the analog input.
    pub adc1: Peri<'static, ADC1>,
    /// Phase B's current and the NTC.
    pub adc2: Peri<'static, ADC2>,
    /// ADC1_IN11.
    pub bus_voltage: Peri<'static, PB12>,
    /// ADC2_IN12.
    pub ntc: Peri<'static, PB2>,
    /// ADC1_IN5.
    pub analog_in: Peri<'static, PB14>,
}

/// One PWM period's conversions, raw 12-bit codes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, defmt::Format)]
pub struct Samples {
    /// The phase currents' amplifiers, A and B (VDDA/2 at zero current).
    pub current: [u16; 2],
    /// The bus voltage divider.
    pub bus: u16,
    /// The analog input.
    pub analog_in: u16,
    /// The bridges' NTC.
    pub ntc: u16,
}

/// The two H-bridges with their sensing and over-current trip, set up.
pub struct Bridges {
    /// Legs A1, A2, B1.
    tim8: ComplementaryPwm<'static, TIM8>,
    /// Leg B2.
    tim1: ComplementaryPwm<'static, TIM1>,
    /// Phase A's current, the bus voltage, the analog input.
    adc1: InjectedAdc<'static, ADC1, 3>,
    /// Phase B's current, the NTC.
    adc2: InjectedAdc<'static, ADC2, 2>,
    /// The comparators' thresholds (DAC3 CH2 for COMP2, DAC4 CH1 for COMP5).
    thresholds: [DacChannel<'static, Blocking>; 2],
    /// Held so that they stay on (dropped, they would switch off).
    _comparators: (Comp<'static, COMP2>, Comp<'static, COMP5>),
    /// The currents' codes at zero current, measured at power-up with the bridges off.
    zero: [u16; 2],
    /// The comparators' trip, mA ([`TRIP_PERCENT`] of the drive's setting).
    trip_ma: i32,
}

impl Bridges {
    /// Sets the power stage up, the bridges off: PWM running with every switch off and MOE
    /// off, the break armed, the ADCs sampling every period; the comparators trip at
    /// [`TRIP_PERCENT`] of `over_current_ma` (the drive's 0x2133). Takes about 30 ms (the
    /// op-amps' offset calibration, then the currents' zero).
    pub fn new(parts: Parts, over_current_ma: u32) -> Self {
        let Parts {
            tim8,
            tim1,
            a1_high,
            a1_low,
            a2_high,
            a2_low,
            b1_high,
            b1_low,
            b2_high,
            b2_low,
            mut shunt_a,
            mut shunt_b,
            opamp_a,
            opamp_b,
            comp_a,
            comp_b,
            dac_a,
            dac_b,
            adc1,
            adc2,
            bus_voltage,
            ntc,
            analog_in,
        } = parts;
        let push_pull = OutputType::PushPull;
        // The pins go to their alternate function with the timers' outputs disabled (Hi-Z, the
        // board's pull-downs hold the gates off); `ComplementaryPwm::new` enables MOE with no
        // channel enabled (still Hi-Z), and `arm` turns MOE off before enabling any channel.
        let mut tim8 = ComplementaryPwm::new(
            tim8,
            Some(PwmPin::new(a1_high, push_pull)),
            Some(ComplementaryPwmPin::new(a1_low, push_pull)),
            Some(PwmPin::new(a2_high, push_pull)),
            Some(ComplementaryPwmPin::new(a2_low, push_pull)),
            Some(PwmPin::new(b1_high, push_pull)),
            Some(ComplementaryPwmPin::new(b1_low, push_pull)),
            None,
            None,
            Hertz(PWM_HZ),
            CountingMode::CenterAlignedBothInterrupts,
        );
        let mut tim1 = ComplementaryPwm::new(
            tim1,
            Some(PwmPin::new(b2_high, push_pull)),
            Some(ComplementaryPwmPin::new(b2_low, push_pull)),
            None,
            None,
            None,
            None,
            None,
            None,
            Hertz(PWM_HZ),
            CountingMode::CenterAlignedBothInterrupts,
        );
        arm(&mut tim8, &[Channel::Ch1, Channel::Ch2, Channel::Ch3]);
        arm(&mut tim1, &[Channel::Ch1]);
        // The ADCs' trigger: OC4REF falls when the counter passes CCR4 going up.
        tim8.set_mms2(Mms2::COMPARE_OC4);
        tim8.set_duty(Channel::Ch4, u32::from(PERIOD - SAMPLE_LEAD));
        stop_and_align();

        // The thresholds before the comparators, so that they never compare against 0 V.
        let mut thresholds = [
            DacChannel::new_internal_blocking::<DAC3, Ch2>(dac_a),
            DacChannel::new_internal_blocking::<DAC4, Ch1>(dac_b),
        ];
        set_thresholds(&mut thresholds, trip_ma(over_current_ma));
        let config = comp::Config {
            hysteresis: Hysteresis::Hyst10M,
            // INMSEL 100: DAC3 CH2 for COMP2, DAC4 CH1 for COMP5 (RM0440, the comparators'
            // inverting inputs).
            inverting_input: InvertingInput::Dac1,
            ..comp::Config::default()
        };
        let comparators =
            (Comp::new(comp_a, shunt_a.reborrow(), Irqs, config), Comp::new(comp_b, shunt_b.reborrow(), Irqs, config));

        // The amplifiers: offset calibration, then PGA x8 with the output inside the chip.
        let (Some(opamp_a), Some(opamp_b)) = (
            singleton!(: OpAmp<'static, OPAMP1> = OpAmp::new(opamp_a, OpAmpSpeed::HighSpeed)),
            singleton!(: OpAmp<'static, OPAMP3> = OpAmp::new(opamp_b, OpAmpSpeed::HighSpeed)),
        ) else {
            defmt::panic!("the power stage set up twice");
        };
        opamp_a.calibrate();
        opamp_b.calibrate();
        let current_a: AnyAdcChannel<'static, ADC1> =
            AdcChannel::<ADC1>::degrade_adc(opamp_a.pga_int(shunt_a, OpAmpGain::Mul8));
        let current_b: AnyAdcChannel<'static, ADC2> =
            AdcChannel::<ADC2>::degrade_adc(opamp_b.pga_int(shunt_b, OpAmpGain::Mul8));
        // `degrade_adc` drops the op-amp's output handle, whose `Drop` switches the op-amp off:
        // on again, as `pga_int` left it.
        pac::OPAMP1.csr().modify(|w| w.set_opampen(true));
        pac::OPAMP3.csr().modify(|w| w.set_opampen(true));

        let adc1 = Adc::new(adc1, AdcConfig::default()).setup_injected_conversions(
            [
                (current_a, CURRENT_SAMPLE),
                (AdcChannel::<ADC1>::degrade_adc(bus_voltage), SLOW_SAMPLE),
                (AdcChannel::<ADC1>::degrade_adc(analog_in), SLOW_SAMPLE),
            ],
            triggers::TIM8_TRGO2,
            Exten::FALLING_EDGE,
            false,
        );
        let adc2 = Adc::new(adc2, AdcConfig::default()).setup_injected_conversions(
            [(current_b, CURRENT_SAMPLE), (AdcChannel::<ADC2>::degrade_adc(ntc), SLOW_SAMPLE)],
            triggers::TIM8_TRGO2,
            Exten::FALLING_EDGE,
            false,
        );

        start_in_step();
        let mut bridges = Self {
            tim8,
            tim1,
            adc1,
            adc2,
            thresholds,
            _comparators: comparators,
            zero: [0; 2],
            trip_ma: trip_ma(over_current_ma),
        };
        bridges.zero = bridges.measure_zero();
        // A comparator may have flagged a break while its threshold and input settled.
        bridges.clear_trip();
        // A core lockup (a fault in the hard fault handler) breaks the timers too.
        pac::SYSCFG.cfgr2().modify(|w| w.set_cll(true));
        for t in [pac::TIM8, pac::TIM1] {
            t.bdtr().modify(|w| w.set_lock(pac::timer::vals::Lock::LEVEL1));
        }
        bridges
    }

    /// The currents' codes averaged over [`ZERO_SAMPLES`] periods, the bridges off. Halts if the
    /// ADCs are not triggered (TIM8's TRGO2 not reaching them).
    /// The currents' codes at zero current, measured at power-up with the bridges off
    /// (`drive_core::windings::sensing_ok` checks them).
    pub fn zero(&self) -> [u16; 2] {
        self.zero
    }

    fn measure_zero(&mut self) -> [u16; 2] {
        let mut sum = [0u32; 2];
        for _ in 0..ZERO_SAMPLES {
            // Clear the flag, then wait for the next sequence's end (ADC1's, the longer one).
            pac::ADC1.isr().write(|w| w.set_jeos(true));
            let mut spins = 0u32;
            while !pac::ADC1.isr().read().jeos() {
                spins += 1;
                if spins > TIMER_HZ / 1000 {
                    defmt::panic!("the ADCs are not triggered by TIM8 (TRGO2)");
                }
            }
            let s = self.samples();
            sum[0] += u32::from(s.current[0]);
            sum[1] += u32::from(s.current[1]);
        }
        [(sum[0] / ZERO_SAMPLES) as u16, (sum[1] / ZERO_SAMPLES) as u16]
    }

    /// Turns the bridges on (MOE of both timers) at the duties last set; false, and still off, if
    /// the over-current trip has acted ([`Self::clear_trip`] first) or a comparator is still high.
    pub fn enable(&mut self) -> bool {
        if tripped() {
            return false;
        }
        self.tim8.set_master_output_enable(true);
        self.tim1.set_master_output_enable(true);
        // MOE cannot be set while the break input is active.
        if self.tim8.get_master_output_enable() && self.tim1.get_master_output_enable() {
            true
        } else {
            self.disable();
            false
        }
    }

    /// Turns every switch off (MOE of both timers off: the outputs at their idle level).
    pub fn disable(&mut self) {
        self.tim8.set_master_output_enable(false);
        self.tim1.set_master_output_enable(false);
    }

    /// Whether the bridges are on.
    pub fn enabled(&self) -> bool {
        self.tim8.get_master_output_enable() || self.tim1.get_master_output_enable()
    }

    /// Forgets a trip, so that [`Self::enable`] may turn the bridges on again.
    pub fn clear_trip(&mut self) {
        for t in [pac::TIM8, pac::TIM1] {
            t.sr().modify(|w| w.set_bif(0, false));
        }
    }

    /// Sets the comparators' trip to [`TRIP_PERCENT`] of `setting_ma`, the drive's over-current
    /// setting (0x2133). A comparator sees the current flowing down through its leg's low side
    /// into the shunt: a short through that switch, or the winding's current beyond the trip in
    /// that direction (`docs/board-g474.md`, *The power stage*).
    pub fn set_over_current(&mut self, setting_ma: u32) {
        self.trip_ma = trip_ma(setting_ma);
        set_thresholds(&mut self.thresholds, self.trip_ma);
    }

    /// Sets the four half-bridges' duties, the share of the period each high side conducts in
    /// 1/65536 (0: the low side conducts throughout), in the order A1, A2, B1, B2; capped at
    /// [`MAX_CCR`]. The timers take them at the next top of the count (preloaded, one update a
    /// period).
    pub fn set_duties(&mut self, duties: [u16; 4]) {
        let ccr = |d: u16| ((u32::from(d) * u32::from(PERIOD)) >> 16).min(u32::from(MAX_CCR));
        self.tim8.set_duty(Channel::Ch1, ccr(duties[0]));
        self.tim8.set_duty(Channel::Ch2, ccr(duties[1]));
        self.tim8.set_duty(Channel::Ch3, ccr(duties[2]));
        self.tim1.set_duty(Channel::Ch1, ccr(duties[3]));
    }

    /// Sets the voltage across each phase's winding as a signed share of the bus voltage, in
    /// 1/32768 (32767: the bus voltage from leg 1 to leg 2, -32768: reversed), centred on half
    /// the bus: leg 1 at 1/2 + v/2, leg 2 at 1/2 − v/2. What the current loop calls every period.
    pub fn set_phase_voltages(&mut self, volts: [i16; 2]) {
        let leg = |v: i32| (32_768 + v).clamp(0, 65_535) as u16;
        let [a, b] = volts.map(i32::from);
        self.set_duties([leg(a), leg(-a), leg(b), leg(-b)]);
    }

    /// The last period's conversions (and the end-of-sequence flags cleared).
    pub fn samples(&mut self) -> Samples {
        let [current_a, bus, analog_in] = self.adc1.read_injected_samples();
        let [current_b, ntc] = self.adc2.read_injected_samples();
        Samples { current: [current_a, current_b], bus, analog_in, ntc }
    }

    /// The phase currents of `samples`, mA: positive out of leg 1 into the winding (the
    /// winding's current comes up through leg 1's low side and its shunt at the top).
    ///
    /// While the over-current trip holds the bridges off (their currents then decay to
    /// nothing), both phases read the trip's current, so that the drive's supervision latches
    /// the over-current (alarm 10) and turns its bridges off, which clears the trip
    /// ([`Self::clear_trip`]).
    pub fn phase_ma(&self, samples: &Samples) -> [i32; 2] {
        if tripped() {
            return [self.trip_ma; 2];
        }
        let ma = |zero: u16, code: u16| ((i32::from(zero) - i32::from(code)) * MA_PER_CODE_Q16) >> 16;
        [ma(self.zero[0], samples.current[0]), ma(self.zero[1], samples.current[1])]
    }
}

/// Sets `pwm` up with its outputs off: MOE off, the outputs at their idle level (low: every
/// switch off) while it is, the dead time, the break from COMP2 and COMP5 only (active high,
/// filtered, MOE left off after it), then `channels` and their complements enabled.
fn arm<T: AdvancedInstance4Channel>(pwm: &mut ComplementaryPwm<'static, T>, channels: &[Channel]) {
    pwm.set_master_output_enable(false);
    pwm.set_off_state_selection_idle(Ossi::IDLE_LEVEL);
    pwm.set_off_state_selection_run(Ossr::IDLE_LEVEL);
    pwm.set_dead_time(DEAD_TIME_COUNTS);
    // No break pin (TIMx_AF1 enables BKIN from reset): the comparators only.
    pwm.set_break_input_pin_enable(false);
    pwm.set_break_comparator_enable(1, true); // COMP2
    pwm.set_break_comparator_enable(4, true); // COMP5
    pwm.set_break_polarity(BreakInputPolarity::ACTIVE_HIGH);
    // 8 samples at 170 MHz / 8: a high level must last 376 ns, longer than the spike of a low
    // side switching on.
    pwm.set_break_filter(FilterValue::FDTS_DIV8_N8);
    pwm.set_automatic_output_enable(false);
    pwm.set_break_enable(true);
    for &channel in channels {
        pwm.set_duty(channel, 0);
        pwm.enable(channel);
    }
}

/// Stops both timers (`ComplementaryPwm::new` started them), sets the auto-reload to [`PERIOD`]
/// and loads the preloaded registers (counters at 0, counting up).
fn stop_and_align() {
    for t in [pac::TIM8, pac::TIM1] {
        t.cr1().modify(|w| w.set_cen(false));
        t.arr().write(|w| w.set_arr(PERIOD));
        // One update a period: with an odd repetition count written before the counter starts,
        // at the overflow (RM0440, the repetition counter), the top of the count, where the
        // currents are sampled: the voltages written in a period act over the whole of the next.
        t.rcr().write(|w| w.set_rep(1));
        t.egr().write(|w| w.set_ug(true));
    }
}

/// Starts TIM8, and TIM1 with it: TIM8's counter enable is its trigger output, TIM1 starts on
/// it (trigger mode on ITR5, TIM8_TRGO in RM0440's internal trigger table). Halts if TIM1 did
/// not start.
fn start_in_step() {
    use pac::timer::vals::{Mms, Sms, Ts};
    pac::TIM8.cr2().modify(|w| w.set_mms(Mms::ENABLE));
    // The trigger selected first, with the slave mode off (RM0440).
    pac::TIM1.smcr().modify(|w| w.set_ts(Ts::ITR5));
    pac::TIM1.smcr().modify(|w| w.set_sms(Sms::TRIGGER_MODE));
    pac::TIM8.cr1().modify(|w| w.set_cen(true));
    // TIM1 sets its own CEN a few clocks later (the trigger's resynchronisation).
    if !(0..100).any(|_| pac::TIM1.cr1().read().cen()) {
        defmt::panic!("TIM1 did not start with TIM8 (ITR5)");
    }
}

/// The comparators' DAC codes for a trip at `trip_ma` ([`trip_ma`]) through a shunt, at the
/// op-amps' inputs (VDDA/16 + 15/16 of the shunt's voltage).
fn set_thresholds(dacs: &mut [DacChannel<'static, Blocking>; 2], trip_ma: i32) {
    let trip_ma = u64::from(trip_ma.unsigned_abs());
    // mA · mΩ = µV.
    let bias_uv = u64::from(VDDA_MV) * 1000 / u64::from(BIAS_DIV);
    let uv = bias_uv + trip_ma * u64::from(SHUNT_MOHM) * u64::from(BIAS_DIV - 1) / u64::from(BIAS_DIV);
    let code = (uv * 4095 / (u64::from(VDDA_MV) * 1000)).min(4095) as u16;
    for dac in dacs {
        dac.set(Value::Bit12Right(code));
    }
}

/// Waits for the end of the ADCs' next sequence (a PWM period, 50 µs), its flag cleared first;
/// false if it does not come within a millisecond. For the power-up tune, before the tick takes
/// the ADCs' interrupt.
pub fn wait_for_sample() -> bool {
    pac::ADC1.isr().write(|w| w.set_jeos(true));
    (0..TIMER_HZ / 1000).any(|_| pac::ADC1.isr().read().jeos())
}

/// The comparators' trip for the drive's over-current setting `setting_ma`, mA.
fn trip_ma(setting_ma: u32) -> i32 {
    (u64::from(setting_ma) * u64::from(TRIP_PERCENT) / 100).min(i32::MAX as u64) as i32
}

/// Whether a break (the over-current trip, a core lockup) has acted on either timer since the
/// last [`Bridges::clear_trip`]: a status register read, from any task.
pub fn tripped() -> bool {
    pac::TIM8.sr().read().bif(0) || pac::TIM1.sr().read().bif(0)
}

/// The last bus voltage, NTC and analog input codes, converted every PWM period (0 before the
/// first): the injected data registers, read without taking the ADCs from the control tick.
pub fn slow_samples() -> (u16, u16, u16) {
    (pac::ADC1.jdr(1).read().jdata(), pac::ADC2.jdr(1).read().jdata(), pac::ADC1.jdr(2).read().jdata())
}

/// The bridges' temperature, °C, of an NTC reading (interpolated in [`NTC_CODES`], held at the
/// table's ends); `None` if the NTC is open or shorted (then the over-temperature alarm, 0x6000
/// bit 0, has nothing to act on).
pub fn bridge_temperature_c(code: u16) -> Option<i16> {
    if !(NTC_SHORT..=NTC_OPEN).contains(&code) {
        return None;
    }
    let Some(i) = NTC_CODES.windows(2).position(|w| code > w[1]) else {
        return Some(150);
    };
    let (hi, lo) = (i32::from(NTC_CODES[i]), i32::from(NTC_CODES[i + 1]));
    let step = (hi - i32::from(code)).max(0) * 10 / (hi - lo);
    Some((-20 + 10 * i as i32 + step) as i16)
}

/// Turns every switch off with raw register writes, whatever state the drivers are in (MOE off
/// on both timers): for the panic and fault handlers. Harmless before the timers are set up.
pub fn off() {
    for t in [pac::TIM8, pac::TIM1] {
        t.bdtr().modify(|w| w.set_moe(false));
    }
}
