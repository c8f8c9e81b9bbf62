//! A winding of a two-phase stepper on one full H-bridge of the G474 board, for the current
//! loop's and the auto-tune's tests, independent of `hal-sim` (whose motor model is driven by
//! currents, not yet by bridge voltages): L·di/dt = v − R·i − e, integrated exactly between
//! sub-steps of the PWM period, with
//!
//! - the PWM's **one period of delay**: the voltage commanded at a sample acts over the whole of
//!   the next period (zero-order hold);
//! - the firmware's **quantisation** of that voltage (`Bridges::set_phase_voltages`: a share of
//!   the bus in 1/32768, each leg's compare value in counts of 4250, capped at `MAX_CCR`);
//! - the **dead time** (300 ns a switching, two legs): 2·t_dt·f_pwm·v_bus off the winding's mean
//!   voltage against its current, faded over the current ripple (20 mA) around zero;
//! - the **current sensing** (`power_stage.rs`: 20 mΩ shunt, bias 1/16, PGA ×8, 3.3 V, 12-bit:
//!   5.372 mA a code, ±11 A), with an offset of a few codes left after the zero's calibration and
//!   Gaussian noise of a few codes.
//!
//! The catalogue is `hal-sim/motors.toml`, read here.
#![allow(dead_code, missing_docs)]

/// The PWM rate, Hz (`power_stage::PWM_HZ`).
pub const PWM_HZ: f64 = 20_000.0;
/// The timers' half period in counts (`power_stage::PERIOD`).
const PERIOD_COUNTS: i32 = 4250;
/// The highest compare value (`power_stage::MAX_CCR`): 4250 − ⌈(340 + 51)/2⌉.
const MAX_CCR: i32 = 4054;
/// The dead time, s (`power_stage::DEAD_TIME_NS`).
pub const DEAD_TIME: f64 = 300e-9;
/// The current around zero over which the dead time's loss fades (the PWM's current ripple).
const DEAD_FADE_A: f64 = 0.02;
/// A phase current's ADC code, A: 3.3 V · 16 / (4095 · 8 · 15 · 20 mΩ).
pub const AMPS_PER_CODE: f64 = 3.3 * 16.0 / (4095.0 * 8.0 * 15.0 * 0.020);
/// Sub-steps a PWM period is integrated in.
const SUBSTEPS: u32 = 20;

/// A motor of the catalogue: its winding's R and L, its rated current.
#[derive(Clone, Debug)]
pub struct Motor {
    pub name: String,
    pub r: f64,
    pub l: f64,
    pub rated: f64,
    /// The torque constant, N·m/A: the back-EMF constant, V·s/rad.
    pub km: f64,
    /// Rotor teeth: electrical turns a mechanical turn.
    pub teeth: f64,
}

/// Every motor of `hal-sim/motors.toml`.
pub fn catalogue() -> Vec<Motor> {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../hal-sim/motors.toml");
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{path}: {e}"));
    let table: toml::Table = toml::from_str(&text).unwrap_or_else(|e| panic!("{path}: {e}"));
    let motors = table.get("motor").and_then(|m| m.as_array()).unwrap_or_else(|| panic!("{path}: no [[motor]]"));
    let motors: Vec<Motor> = motors
        .iter()
        .map(|m| {
            let num = |key: &str| {
                m.get(key)
                    .and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)))
                    .unwrap_or_else(|| panic!("{path}: {key} missing"))
            };
            Motor {
                name: m.get("name").and_then(|v| v.as_str()).unwrap_or("?").to_string(),
                r: num("r_ohm"),
                l: num("l_henry"),
                rated: num("rated_current_a"),
                km: num("km_nm_per_a"),
                teeth: num("steps_per_rev") / 4.0,
            }
        })
        .collect();
    assert!(!motors.is_empty(), "{path}: no motor");
    motors
}

/// xorshift64* with Box-Muller: repeatable noise without a dependency.
#[derive(Clone, Debug)]
pub struct Noise {
    state: u64,
    spare: Option<f64>,
}

impl Noise {
    pub fn new(seed: u64) -> Self {
        Self { state: seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1, spare: None }
    }

    fn uniform(&mut self) -> f64 {
        self.state ^= self.state >> 12;
        self.state ^= self.state << 25;
        self.state ^= self.state >> 27;
        let x = self.state.wrapping_mul(0x2545_F491_4F6C_DD1D);
        ((x >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    }

    /// A standard normal sample.
    pub fn gauss(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        let (u, v) = (self.uniform(), self.uniform());
        let r = (-2.0 * u.ln()).sqrt();
        let t = std::f64::consts::TAU * v;
        self.spare = Some(r * t.sin());
        r * t.cos()
    }
}

/// The current sensing of one phase: code = 2048 − i/LSB + offset + noise, rounded, within
/// 0..=4095; the drive reads it back with the zero it calibrated (2048).
#[derive(Clone, Debug)]
pub struct Sensing {
    /// The offset left after the zero's calibration, codes.
    pub offset: f64,
    /// The noise's standard deviation, codes (0: quantisation only).
    pub sigma: f64,
    pub noise: Noise,
}

impl Sensing {
    /// Exact: no quantisation, no noise.
    pub fn ideal() -> Option<Self> {
        None
    }

    pub fn new(offset: f64, sigma: f64, seed: u64) -> Self {
        Self { offset, sigma, noise: Noise::new(seed) }
    }

    /// The current the drive reads, A.
    pub fn read(&mut self, i: f64) -> f32 {
        let code = 2048.0 - i / AMPS_PER_CODE + self.offset + self.sigma * self.noise.gauss();
        let code = code.round().clamp(0.0, 4095.0);
        ((2048.0 - code) * AMPS_PER_CODE) as f32
    }
}

/// The winding's mean voltage over a period for a commanded `volts` as the firmware sets the
/// bridge: the share of the bus in 1/32768, the legs centred and quantised to timer counts.
pub fn bridge_volts(volts: f32, v_bus: f64) -> f64 {
    let [share, _] = drive_core::current::bridge_shares([volts, 0.0], v_bus as f32);
    let leg = |v: i32| (((32_768 + v).clamp(0, 65_535) * PERIOD_COUNTS) >> 16).min(MAX_CCR);
    let s = i32::from(share);
    f64::from(leg(s) - leg(-s)) / f64::from(PERIOD_COUNTS) * v_bus
}

/// One winding on its bridge.
#[derive(Clone, Debug)]
pub struct Winding {
    pub r: f64,
    pub l: f64,
    /// The current, A: positive out of leg 1.
    pub i: f64,
    /// The bus voltage, V.
    pub v_bus: f64,
    /// The back-EMF over the coming period, V (against the current).
    pub emf: f64,
    /// Whether the bridge has a dead time (else ideal switches).
    pub dead_time: bool,
    /// Whether the voltage is quantised as the firmware's timers do (else exact).
    pub quantised: bool,
    /// Whether a command acts half a period after its sample (timers updated at the bottom of
    /// the count as well as the top) instead of a whole one.
    pub half_delay: bool,
    /// The mean voltage over the current period, commanded a period ago.
    applied: f64,
}

impl Winding {
    pub fn new(motor: &Motor, v_bus: f64) -> Self {
        Self {
            r: motor.r,
            l: motor.l,
            i: 0.0,
            v_bus,
            emf: 0.0,
            dead_time: true,
            quantised: true,
            half_delay: false,
            applied: 0.0,
        }
    }

    /// Ideal switches and an exact voltage: the loop's own model.
    pub fn ideal(mut self) -> Self {
        self.dead_time = false;
        self.quantised = false;
        self
    }

    /// The dead time's loss at the bus voltage, V.
    pub fn dead_volts(&self) -> f64 {
        if self.dead_time { 2.0 * DEAD_TIME * PWM_HZ * self.v_bus } else { 0.0 }
    }

    /// Runs one PWM period with the voltage commanded a period ago, and takes `command` (the
    /// loop's output at the sample that starts this period) for the next one.
    pub fn period(&mut self, command: f32) {
        let h = 1.0 / PWM_HZ / f64::from(SUBSTEPS);
        let decay = (-self.r * h / self.l).exp();
        let next = if self.quantised {
            bridge_volts(command, self.v_bus)
        } else {
            f64::from(command).clamp(-self.v_bus, self.v_bus)
        };
        for n in 0..SUBSTEPS {
            if self.half_delay && n == SUBSTEPS / 2 {
                self.applied = next;
            }
            let loss = self.dead_volts() * (self.i / DEAD_FADE_A).clamp(-1.0, 1.0);
            let v = self.applied - self.emf - loss;
            self.i = self.i * decay + (1.0 - decay) * v / self.r;
        }
        self.applied = next;
    }
}
