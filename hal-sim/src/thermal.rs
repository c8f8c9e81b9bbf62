//! The driver's (power stage's) temperature: a first-order thermal model heated by the bridge's
//! conduction losses.
//!
//! ```text
//! dT/dt = (P · R_th − (T − T_amb)) / τ,    P = R_ds · (i_a² + i_b²) + P_0
//! ```
//!
//! with the bridge currents the drive measures (a shorted output heats the stage as it should),
//! averaged over each control tick, and the exact exponential solution over the tick. The figures
//! ([`ThermalParams::SMALL_DRIVE`]) are chosen for a small integrated drive on a NEMA 17/23 flange;
//! they are plausible, not measured:
//!
//! - R_ds = 0.5 Ω a phase: the high- and low-side MOSFETs a phase current flows through
//!   (2 × 0.2 Ω, an integrated 40 V bridge) and its 0.1 Ω current-sense shunt;
//! - P_0 = 1 W standing: switching losses at 40 kHz, gate drive, regulator, MCU and transceiver;
//! - R_th = 4 K/W from the power stage to the air around the drive, through board and housing;
//! - τ = 60 s: board, heat spreader and housing.
//!
//! Microstepping keeps i_a² + i_b² at I² at every angle, so a hold at 2 A dissipates 3 W and
//! settles 12 K above the ambient; an output shorted at 8 A, 33 W and 132 K.

/// The constants of the thermal model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThermalParams {
    /// Conduction resistance of one phase's current path through the bridge, Ω.
    pub r_ds_ohm: f64,
    /// Losses that do not depend on the current, W.
    pub standing_w: f64,
    /// Thermal resistance from the power stage to the ambient, K/W.
    pub r_th_k_per_w: f64,
    /// Thermal time constant, s.
    pub tau_s: f64,
}

impl ThermalParams {
    /// The simulator's drive (see the module documentation).
    pub const SMALL_DRIVE: Self = Self { r_ds_ohm: 0.5, standing_w: 1.0, r_th_k_per_w: 4.0, tau_s: 60.0 };

    /// The power dissipated with the mean of i_a² + i_b² at `current_sq` (A²), W.
    pub fn power_w(&self, current_sq: f64) -> f64 {
        self.r_ds_ohm * current_sq + self.standing_w
    }

    /// Where the temperature settles above the ambient with the mean of i_a² + i_b² held at
    /// `current_sq` (A²), K.
    pub fn steady_rise_k(&self, current_sq: f64) -> f64 {
        self.power_w(current_sq) * self.r_th_k_per_w
    }
}

/// The driver's temperature.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Thermal {
    params: ThermalParams,
    ambient_c: f64,
    /// T − T_amb, K.
    rise_k: f64,
}

impl Thermal {
    /// At the ambient `ambient_c` (a drive that was off).
    pub fn new(params: ThermalParams, ambient_c: f64) -> Self {
        Self { params, ambient_c, rise_k: 0.0 }
    }

    /// The constants.
    pub fn params(&self) -> ThermalParams {
        self.params
    }

    /// The driver temperature, °C.
    pub fn temperature_c(&self) -> f64 {
        self.ambient_c + self.rise_k
    }

    /// The ambient temperature, °C.
    pub fn ambient_c(&self) -> f64 {
        self.ambient_c
    }

    /// Makes the driver read `c` now by stepping the ambient by the difference: the stage goes on
    /// heating or cooling from there as the model says.
    pub fn force(&mut self, c: f64) {
        self.ambient_c = c - self.rise_k;
    }

    /// `seconds` pass with the mean of i_a² + i_b² at `current_sq` (A²).
    pub fn advance(&mut self, current_sq: f64, seconds: f64) {
        let settle = self.params.steady_rise_k(current_sq);
        let keep = (-seconds.max(0.0) / self.params.tau_s).exp();
        self.rise_k = settle + (self.rise_k - settle) * keep;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_of_power_is_the_first_order_response() {
        let mut t = Thermal::new(ThermalParams::SMALL_DRIVE, 25.0);
        // 2 A: 3 W, 12 K. In 50 µs steps for one time constant: 1 − 1/e of the way.
        for _ in 0..1_200_000 {
            t.advance(4.0, 50e-6);
        }
        let want = 25.0 + 12.0 * (1.0 - (-1.0f64).exp());
        assert!((t.temperature_c() - want).abs() < 1e-6, "{} vs {want}", t.temperature_c());
        t.force(80.0);
        assert!((t.temperature_c() - 80.0).abs() < 1e-9);
        assert!((t.ambient_c() - (80.0 - 12.0 * (1.0 - (-1.0f64).exp()))).abs() < 1e-6);
        // No current: it cools towards the ambient plus the standing loss's 4 K.
        t.advance(0.0, 1e4);
        assert!((t.temperature_c() - (t.ambient_c() + 4.0)).abs() < 1e-9);
    }
}
