//! The current loop: each winding's voltage, once a PWM period, from its current's reference and
//! measurement (issue 39, item 2; `docs/current-loop.md`).
//!
//! A two-phase hybrid stepper has two windings, each on its own full H-bridge. Per winding, in
//! its own stationary axis (phase A is α, phase B is β):
//!
//! - **the plant** is L·di/dt = v − R·i − e, with e the back-EMF; sampled with a zero-order hold
//!   at the PWM period T, `i[k+1] = a·i[k] + b·(v[k] − e[k])` with a = e^(−R·T/L) and
//!   b = (1 − a)/R;
//! - **one period of delay**: the currents are sampled at the centre of a period and the voltage
//!   computed from them is applied over the whole of the next one (the timers take their
//!   preloaded compare values at the next update), so the voltage that follows from `i[k]` first
//!   shows in `i[k+2]`;
//! - **a predictor** undoes that delay: the voltage applied over the current period is known (it
//!   is the last output), so `i[k+1]` is predicted from `i[k]` and it, and the PI acts on the error of
//!   that prediction. What the model misses (a back-EMF not fed forward, R or L off) shows as
//!   the difference between the current measured and the one predicted for now; that difference,
//!   low-passed ([`CORRECTION_GAIN`]), corrects the prediction (a Smith predictor with a
//!   disturbance observer), so that the loop has no steady error whatever the model misses: an
//!   uncorrected prediction leaves one of b·Δe, 16 mA a volt of back-EMF on the NEMA 17.
//!   Without a predictor no PI reaches 90 % of a step in three periods with under 5 %
//!   overshoot: with the delay left in the loop, the first two samples after a step show only the
//!   proportional action, and a gain that brings the third to 90 % overshoots by 15 % and more;
//!   `docs/current-loop.md` has the figures;
//! - **a PI** on the predicted error, u = kp·ε + Σ ki·ε, whose zero cancels the winding's pole:
//!   kp = a·(1 − p)/b, ki = R·(1 − p) a period, with p = e^(−ωc·T) the closed loop's pole.
//!   As T → 0 these are kp = L·ωc and ki·(1/T) = R·ωc, the continuous design's. The
//!   predicted current then follows its reference as a first-order lag with pole p, the measured
//!   one a period later;
//! - **feed-forward** of the back-EMF (the caller's estimate of e over the coming period) and of
//!   the bridge's **dead time**: while a leg's two switches are both off the current flows
//!   through a diode, which takes t_dt·f_pwm·v_bus off the winding's mean voltage at each of its
//!   two legs, against the current: the loop adds 2·t_dt·f_pwm·v_bus in the direction of the
//!   reference current (its sign, faded linearly across a band around zero, where the current's
//!   own sign is noise);
//! - **the supply's limit**: each winding has its own full H-bridge, so the limit is per phase,
//!   |v| ≤ [`MAX_MODULATION`]·v_bus, a square and not the circle v_bus/√2 of a three-phase
//!   inverter whose phases share a star point; **anti-windup**: the integral stops while the
//!   output is clamped in the direction of the error, and is itself kept within the limit.
//!
//! The settings are validated once into an immutable [`CurrentLoopSettings`] (gains worked out
//! there, off the control tick), the loop's memory is a [`CurrentLoopState`], and
//! [`CurrentLoopSettings::step`] runs a period: `idsp`'s `process(&self, &mut state, x)`
//! shape. Our own code rather than `idsp` 0.23's `BiquadClamp` (its clamp limits and offset are
//! in the configuration while ours move every period with the bus voltage and the
//! feed-forward, its offset is one the integrator accumulates, and the predictor is not a
//! biquad on the error) or the `foc` 0.3 crate (`I16F16` fixed point only, a PI with no limit
//! nor anti-windup, a three-phase Clarke transform and modulation): `docs/current-loop.md`.
//!
//! For field-oriented control (an encoder gives the rotor's electrical angle θe) the references
//! come from d/q: [`inverse_park`] of (i_d = 0, i_q) at the angle the rotor will have when the
//! voltage acts; a two-phase motor needs no Clarke transform (its windings are α and β
//! already). Open loop, the reference is `inverse_park([I, 0], θe)` = (I·cos θe, I·sin θe) at the
//! commanded microstep angle.
//!
//! ```
//! use drive_core::current::{CurrentLoopSettings, CurrentLoopState, MAX_MODULATION, recommended_bandwidth};
//! // A NEMA 17 (1.4 Ω, 3 mH) on 24 V at 20 kHz.
//! let settings = CurrentLoopSettings::new(1.4, 3.0e-3, 24.0, 20_000.0, recommended_bandwidth(20_000.0)).unwrap();
//! let mut state = CurrentLoopState::default();
//! // From rest, 0.2 A asked of phase A: the first period's voltage is the proportional step.
//! let v = settings.step(&mut state, [0.2, 0.0], [0.0, 0.0], [0.0, 0.0], 24.0);
//! assert!((v[0] - 9.71).abs() < 0.01 && v[1] == 0.0, "{v:?}");
//! // 1 A asked at once would need more than the bridge has: 0.9 × 24 V.
//! let mut state = CurrentLoopState::default();
//! let v = settings.step(&mut state, [1.0, -1.0], [0.0, 0.0], [0.0, 0.0], 24.0);
//! assert_eq!(v, [MAX_MODULATION * 24.0, -MAX_MODULATION * 24.0]);
//! ```

/// The largest voltage across a winding as a share of the bus voltage. The firmware centres
/// each bridge's legs on half the bus (leg 1 at ½ + v/2, leg 2 at ½ − v/2) and caps a leg's
/// high-side share at 95.4 % (`MAX_CCR`: the low sides conduct at least 2 µs around the centre,
/// where the currents are sampled), so a winding gets at most 90.8 % of the bus: 0.9 with a margin.
pub const MAX_MODULATION: f32 = 0.9;

/// The share of the last prediction's error that goes into the correction of the next, each
/// period: the correction settles in about four periods, fast beside a back-EMF's change, and
/// passes a quarter of the currents' noise on.
pub const CORRECTION_GAIN: f32 = 0.25;

/// The closed loop's pole (per PWM period) that [`recommended_bandwidth`] places: the predicted
/// current covers 80 % of the rest of a step each period, the measured one a period later, so a
/// step is 96 % made in three periods with the motor's R and L exact and at least 91 % with
/// either 5 % off (the auto-tune's tolerance), overshooting by at most 3 %
/// (`drive-core/tests/current_step.rs`).
pub const RECOMMENDED_POLE: f32 = 0.2;

/// The bandwidth, rad/s, that puts the loop's pole at [`RECOMMENDED_POLE`] at `pwm_hz`:
/// ln 5 · f_pwm, 32 189 rad/s (5.1 kHz) at 20 kHz. The winding's R and L set the gains
/// ([`CurrentLoopSettings::new`]), not the bandwidth: it is bounded by the period and its delay.
///
/// ```
/// let w = drive_core::current::recommended_bandwidth(20_000.0);
/// assert!((w - 32_189.0).abs() < 1.0);
/// ```
pub fn recommended_bandwidth(pwm_hz: f32) -> f32 {
    -libm::logf(RECOMMENDED_POLE) * pwm_hz
}

/// Why settings were refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Error {
    /// The winding's resistance is not within [`R_RANGE`].
    Resistance,
    /// The winding's inductance is not within [`L_RANGE`].
    Inductance,
    /// The bus voltage is not within [`V_BUS_RANGE`].
    Supply,
    /// The PWM rate is not within [`PWM_RANGE`].
    PwmRate,
    /// The bandwidth is not positive, or puts the pole under 0.01 (ωc·T over ln 100): beyond
    /// that the loop only amplifies the currents' noise.
    Bandwidth,
    /// The dead time is negative or a tenth of the period or more, or its band not positive.
    DeadTime,
    /// A gain set by hand is not a positive number.
    Gains,
}

/// Resistances the loop accepts, Ω.
pub const R_RANGE: (f32, f32) = (0.01, 100.0);
/// Inductances the loop accepts, H.
pub const L_RANGE: (f32, f32) = (1.0e-5, 1.0);
/// Bus voltages the loop accepts, V.
pub const V_BUS_RANGE: (f32, f32) = (1.0, 100.0);
/// PWM rates the loop accepts, Hz.
pub const PWM_RANGE: (f32, f32) = (1_000.0, 200_000.0);

/// Whether `x` is finite and within `range`.
fn within(x: f32, range: (f32, f32)) -> bool {
    x.is_finite() && x >= range.0 && x <= range.1
}

/// The current loop's settings, validated, with its gains.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurrentLoopSettings {
    r: f32,
    l: f32,
    v_bus: f32,
    period: f32,
    bandwidth: f32,
    /// The winding's current a period later with no voltage: e^(−R·T/L).
    a: f32,
    /// The current a volt held over a period adds, A/V: (1 − a)/R.
    b: f32,
    /// The proportional gain, V/A.
    kp: f32,
    /// The integral's gain, V/A a period.
    ki: f32,
    /// The dead time's loss as a share of the bus: 2·t_dt·f_pwm.
    dead_share: f32,
    /// The reference current over which the dead-time compensation is whole, A.
    dead_band: f32,
    /// Its reciprocal, 1/A (the share is worked out each period, a multiplication).
    per_band: f32,
}

impl CurrentLoopSettings {
    /// Settings for a winding of `r` Ω and `l` H, on a bus of nominally `v_bus` V (checked here;
    /// [`Self::step`] takes the measured one), at `pwm_hz`, with the closed loop's bandwidth
    /// `bandwidth` rad/s (its pole p = e^(−bandwidth/pwm_hz) a period). No dead-time
    /// compensation: [`Self::with_dead_time`].
    ///
    /// ```
    /// use drive_core::current::{CurrentLoopSettings, Error};
    /// let s = CurrentLoopSettings::new(1.13, 4.8e-3, 24.0, 20_000.0, 32_189.0).unwrap();
    /// // kp = a·(1 − p)/b ≈ L·(1 − p)/T, ki = R·(1 − p) a period; p = 0.2.
    /// assert!((s.kp() - 76.35).abs() < 0.01 && (s.ki() - 0.904).abs() < 0.001, "{} {}", s.kp(), s.ki());
    /// assert_eq!(CurrentLoopSettings::new(1.13, 0.0, 24.0, 20_000.0, 32_189.0), Err(Error::Inductance));
    /// ```
    pub fn new(r: f32, l: f32, v_bus: f32, pwm_hz: f32, bandwidth: f32) -> Result<Self, Error> {
        if !within(r, R_RANGE) {
            return Err(Error::Resistance);
        }
        if !within(l, L_RANGE) {
            return Err(Error::Inductance);
        }
        if !within(v_bus, V_BUS_RANGE) {
            return Err(Error::Supply);
        }
        if !within(pwm_hz, PWM_RANGE) {
            return Err(Error::PwmRate);
        }
        let period = 1.0 / pwm_hz;
        let pole_exponent = bandwidth * period;
        if !(pole_exponent.is_finite() && pole_exponent > 0.0 && pole_exponent <= libm::logf(100.0)) {
            return Err(Error::Bandwidth);
        }
        let x = r * period / l;
        // 1 − a without the cancellation of 1 − e^(−x) for a small x.
        let one_minus_a = -libm::expm1f(-x);
        let a = 1.0 - one_minus_a;
        let b = one_minus_a / r;
        let one_minus_p = -libm::expm1f(-pole_exponent);
        Ok(Self {
            r,
            l,
            v_bus,
            period,
            bandwidth,
            a,
            b,
            kp: a * one_minus_p / b,
            ki: r * one_minus_p,
            dead_share: 0.0,
            dead_band: 1.0,
            per_band: 1.0,
        })
    }

    /// The same settings with the bridges' dead time compensated: `dead_time` s each switching
    /// of each leg, the compensation faded linearly over reference currents under `band` A
    /// (a few ADC codes of current: the current's sign is unsure there).
    ///
    /// ```
    /// use drive_core::current::CurrentLoopSettings;
    /// let s = CurrentLoopSettings::new(1.4, 3.0e-3, 24.0, 20_000.0, 32_189.0).unwrap();
    /// let s = s.with_dead_time(300e-9, 0.05).unwrap();
    /// // 2 × 300 ns × 20 kHz = 1.2 % of the bus: 0.288 V at 24 V.
    /// assert!((s.dead_time_volts(24.0) - 0.288).abs() < 1e-6);
    /// assert!(s.with_dead_time(5e-6, 0.05).is_err());
    /// ```
    pub fn with_dead_time(self, dead_time: f32, band: f32) -> Result<Self, Error> {
        let fine = dead_time.is_finite() && dead_time >= 0.0 && dead_time < 0.1 * self.period;
        if !(fine && band.is_finite() && band > 0.0) {
            return Err(Error::DeadTime);
        }
        Ok(Self { dead_share: 2.0 * dead_time / self.period, dead_band: band, per_band: 1.0 / band, ..self })
    }

    /// The same settings with the PI's gains set rather than worked out from R, L and the
    /// bandwidth: `kp` V/A and `ki` V/A a period (positive); the predictor keeps its model of
    /// the winding.
    ///
    /// ```
    /// use drive_core::current::{CurrentLoopSettings, Error};
    /// let s = CurrentLoopSettings::new(1.4, 3.0e-3, 24.0, 20_000.0, 32_189.0).unwrap();
    /// let s = s.with_gains(30.0, 0.3).unwrap();
    /// assert_eq!((s.kp(), s.ki()), (30.0, 0.3));
    /// assert_eq!(s.with_gains(0.0, 0.3), Err(Error::Gains));
    /// ```
    pub fn with_gains(self, kp: f32, ki: f32) -> Result<Self, Error> {
        let fine = |g: f32| g.is_finite() && g > 0.0;
        if !(fine(kp) && fine(ki)) {
            return Err(Error::Gains);
        }
        Ok(Self { kp, ki, ..self })
    }

    /// The winding's resistance, Ω.
    pub fn resistance(&self) -> f32 {
        self.r
    }

    /// The winding's inductance, H.
    pub fn inductance(&self) -> f32 {
        self.l
    }

    /// The bus voltage the settings were checked for, V.
    pub fn nominal_bus(&self) -> f32 {
        self.v_bus
    }

    /// The PWM period, s.
    pub fn period(&self) -> f32 {
        self.period
    }

    /// The closed loop's bandwidth, rad/s.
    pub fn bandwidth(&self) -> f32 {
        self.bandwidth
    }

    /// The closed loop's pole a period: e^(−bandwidth·T).
    pub fn pole(&self) -> f32 {
        1.0 - self.ki / self.r
    }

    /// The current a volt held across the winding over a period adds to it, A/V: (1 − a)/R.
    pub fn volt_gain(&self) -> f32 {
        self.b
    }

    /// The proportional gain, V/A.
    pub fn kp(&self) -> f32 {
        self.kp
    }

    /// The integral's gain, V/A a period.
    pub fn ki(&self) -> f32 {
        self.ki
    }

    /// The voltage the dead time takes off a winding at `v_bus`, V.
    pub fn dead_time_volts(&self, v_bus: f32) -> f32 {
        self.dead_share * v_bus
    }

    /// The share of the dead time's voltage the loop adds for a reference of `i_ref` A: its
    /// sign, faded linearly across the band around zero.
    fn dead_time_share(&self, i_ref: f32) -> f32 {
        (i_ref * self.per_band).clamp(-1.0, 1.0)
    }

    /// The part of a winding's voltage asked for `i_ref` A at `v_bus` that the dead time takes
    /// back before it reaches the winding, V: what the loop adds for it.
    pub fn dead_time_feed_forward(&self, i_ref: f32, v_bus: f32) -> f32 {
        self.dead_time_share(i_ref) * self.dead_time_volts(v_bus)
    }

    /// The largest voltage across a winding at `v_bus`: [`MAX_MODULATION`]·v_bus, 0 for a bus
    /// voltage that is not a positive number.
    pub fn limit(v_bus: f32) -> f32 {
        if v_bus.is_finite() && v_bus > 0.0 { MAX_MODULATION * v_bus } else { 0.0 }
    }

    /// The winding's current the loop expects at the next sample, A, and the correction it
    /// includes: from `measured` now, the voltage that acts on the winding's R and L over the
    /// current period (the last output less its feed-forward), and the correction, which moves
    /// [`CORRECTION_GAIN`] of the way to the last prediction's error.
    fn predict_phase(&self, st: &PhaseState, measured: f32) -> (f32, f32, f32) {
        let model = self.a * measured + self.b * st.applied;
        let correction = st.correction + CORRECTION_GAIN * (measured - st.predicted - st.correction);
        (model + correction, model, correction)
    }

    /// The windings' currents the loop expects at the next sample from those `measured` now, A:
    /// what [`Self::step`] regulates.
    pub fn predict(&self, state: &CurrentLoopState, measured: [f32; 2]) -> [f32; 2] {
        let [a, b] = &state.phases;
        [self.predict_phase(a, measured[0]).0, self.predict_phase(b, measured[1]).0]
    }

    /// One PWM period: the voltage to put across each winding over the next period, V, within
    /// ±[`MAX_MODULATION`]·`v_bus`, from each winding's reference current `i_ref` (A, the current
    /// wanted at the end of that period), its current `i_meas` sampled now (A), the back-EMF it
    /// will meet over that period (V, in the direction that opposes the current) and the bus
    /// voltage measured now (V). A winding whose arithmetic is not finite (a NaN measurement)
    /// gets 0 V and its state is cleared; a bus that is not a positive number gives 0 V.
    ///
    /// ```
    /// use drive_core::current::{CurrentLoopSettings, CurrentLoopState, PhaseState};
    /// let s = CurrentLoopSettings::new(1.4, 3.0e-3, 24.0, 20_000.0, 32_189.0).unwrap();
    /// // Standing at 1 A in phase A with R·i = 1.4 V applied: the prediction is the reference,
    /// // nothing changes.
    /// let standing = PhaseState { integral: 1.4, applied: 1.4, predicted: 1.0, correction: 0.0 };
    /// let mut state = CurrentLoopState { phases: [standing, PhaseState::default()] };
    /// let v = s.step(&mut state, [1.0, 0.0], [1.0, 0.0], [0.0, 0.0], 24.0);
    /// assert!((v[0] - 1.4).abs() < 1e-5 && (state.phases[0].integral - 1.4).abs() < 1e-5);
    /// // A back-EMF of 5 V is fed forward whole.
    /// let v = s.step(&mut state, [1.0, 0.0], [1.0, 0.0], [5.0, 0.0], 24.0);
    /// assert!((v[0] - 6.4).abs() < 1e-5, "{v:?}");
    /// // A NaN measurement: 0 V and that winding's memory cleared.
    /// let v = s.step(&mut state, [1.0, 0.0], [f32::NAN, 0.0], [0.0, 0.0], 24.0);
    /// assert_eq!((v[0], state.phases[0]), (0.0, PhaseState::default()));
    /// ```
    pub fn step(
        &self,
        state: &mut CurrentLoopState,
        i_ref: [f32; 2],
        i_meas: [f32; 2],
        back_emf: [f32; 2],
        v_bus: f32,
    ) -> [f32; 2] {
        let limit = Self::limit(v_bus);
        let dead = if limit > 0.0 { self.dead_time_volts(v_bus) } else { 0.0 };
        let [pa, pb] = &mut state.phases;
        [
            self.phase(pa, i_ref[0], i_meas[0], back_emf[0], limit, dead),
            self.phase(pb, i_ref[1], i_meas[1], back_emf[1], limit, dead),
        ]
    }

    /// One winding's period: see [`Self::step`].
    fn phase(&self, st: &mut PhaseState, i_ref: f32, i_meas: f32, emf: f32, limit: f32, dead: f32) -> f32 {
        let (predicted, model, correction) = self.predict_phase(st, i_meas);
        let error = i_ref - predicted;
        let feed_forward = emf + self.dead_time_share(i_ref) * dead;
        let integral = st.integral + self.ki * error;
        let wanted = feed_forward + self.kp * error + integral;
        if !(wanted.is_finite() && feed_forward.is_finite()) {
            *st = PhaseState::default();
            return 0.0;
        }
        let out = wanted.max(-limit).min(limit);
        // Anti-windup: no integration while clamped in the error's direction; and the integral,
        // which carries R·i and what the model misses, stays within what the bridge can give.
        if (wanted - out) * error <= 0.0 {
            st.integral = integral;
        }
        st.integral = st.integral.max(-limit).min(limit);
        st.applied = out - feed_forward;
        (st.predicted, st.correction) = (model, correction);
        out
    }
}

/// One winding's memory.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhaseState {
    /// The PI's integral, V.
    pub integral: f32,
    /// The voltage acting on the winding's R and L over the current period (the last output
    /// less its feed-forward), V: the predictor's input.
    pub applied: f32,
    /// The model's prediction of the current at the next sample, A (without the correction).
    pub predicted: f32,
    /// What the model misses, A: the last predictions' errors, low-passed.
    pub correction: f32,
}

/// The current loop's memory, both windings: zero when the bridges turn on.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CurrentLoopState {
    /// Phase A's and phase B's.
    pub phases: [PhaseState; 2],
}

/// An angle's cosine and sine, worked out once for both transforms of a period.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CosSin {
    /// cos θ.
    pub cos: f32,
    /// sin θ.
    pub sin: f32,
}

impl Default for CosSin {
    /// The angle 0.
    fn default() -> Self {
        Self { cos: 1.0, sin: 0.0 }
    }
}

impl CosSin {
    /// The cosine and sine of `angle` rad, in `f32` throughout (libm's `sincosf` works in `f64`,
    /// which the Cortex-M4's FPU does not have): the angle brought within ±π/4 of a multiple of
    /// π/2 (π/2 in two parts, so that the reduction loses nothing for angles of a few turns),
    /// then Taylor polynomials of the 9th and 8th degree; within 3e-7 of the exact values over
    /// ±100 rad (`cos_sin_agrees_with_libm`). NaN for an angle that is not finite.
    ///
    /// ```
    /// use drive_core::current::CosSin;
    /// let at = CosSin::of(core::f32::consts::FRAC_PI_3);
    /// assert!((at.cos - 0.5).abs() < 2e-7 && (at.sin - 0.866_025_4).abs() < 2e-7);
    /// ```
    pub fn of(angle: f32) -> Self {
        if !angle.is_finite() {
            return Self { cos: f32::NAN, sin: f32::NAN };
        }
        // π/2 = HI + LO, HI with its low seven bits zero: k·HI is exact for |k| < 128.
        const HI: f32 = 1.570_785_5;
        const LO: f32 = 1.080_433e-5;
        // Rounded to the nearest quarter turn by the FPU's conversion (a saturating truncation).
        let quarter = (angle * core::f32::consts::FRAC_2_PI + 0.5f32.copysign(angle)) as i32;
        let k = quarter as f32;
        let r = (angle - k * HI) - k * LO;
        let r2 = r * r;
        // Multiplications by the factorials' reciprocals: a division is 14 cycles of the FPU.
        let sin = r
            * (1.0
                - r2 * (1.0 / 6.0) * (1.0 - r2 * (1.0 / 20.0) * (1.0 - r2 * (1.0 / 42.0) * (1.0 - r2 * (1.0 / 72.0)))));
        let cos = 1.0 - r2 * 0.5 * (1.0 - r2 * (1.0 / 12.0) * (1.0 - r2 * (1.0 / 30.0) * (1.0 - r2 * (1.0 / 56.0))));
        match quarter & 3 {
            0 => Self { cos, sin },
            1 => Self { cos: -sin, sin: cos },
            2 => Self { cos: -cos, sin: -sin },
            _ => Self { cos: sin, sin: -cos },
        }
    }
}

/// The Park transform: the windings' currents (or voltages) α, β to d (along the electrical
/// angle θ) and q (90° ahead of it). The motor's torque is K_m·i_q with θ the rotor's electrical
/// angle. A two-phase motor needs no Clarke transform: its windings are α and β.
///
/// ```
/// use drive_core::current::{CosSin, park, inverse_park};
/// let at = CosSin::of(core::f32::consts::FRAC_PI_6); // 30°
/// let dq = park([1.0, 0.0], at);
/// assert!((dq[0] - 0.866).abs() < 1e-3 && (dq[1] + 0.5).abs() < 1e-3);
/// let ab = inverse_park(dq, at);
/// assert!((ab[0] - 1.0).abs() < 1e-6 && ab[1].abs() < 1e-6);
/// // The open-loop reference: I·cos θe, I·sin θe.
/// assert_eq!(inverse_park([2.0, 0.0], CosSin { cos: 0.6, sin: 0.8 }), [1.2, 1.6]);
/// ```
pub fn park(ab: [f32; 2], at: CosSin) -> [f32; 2] {
    let [alpha, beta] = ab;
    [at.cos * alpha + at.sin * beta, at.cos * beta - at.sin * alpha]
}

/// The inverse Park transform: d, q at the angle θ to the windings' α, β.
pub fn inverse_park(dq: [f32; 2], at: CosSin) -> [f32; 2] {
    let [d, q] = dq;
    [at.cos * d - at.sin * q, at.sin * d + at.cos * q]
}

/// The windings' voltages as the firmware's `Bridges::set_phase_voltages` takes them: shares of
/// the measured bus in 1/32768, rounded, within the i16's range (0 for a bus that is not a
/// positive number).
///
/// ```
/// use drive_core::current::bridge_shares;
/// assert_eq!(bridge_shares([12.0, -21.6], 24.0), [16384, -29491]);
/// assert_eq!(bridge_shares([30.0, 0.0], 24.0), [32767, 0]);
/// assert_eq!(bridge_shares([1.0, 1.0], 0.0), [0, 0]);
/// ```
pub fn bridge_shares(volts: [f32; 2], v_bus: f32) -> [i16; 2] {
    let scale = if v_bus.is_finite() && v_bus > 0.0 { 32_768.0 / v_bus } else { 0.0 };
    // Rounded half away from zero; `as` saturates at the i16's bounds, and a NaN gives 0.
    volts.map(|v| {
        let x = v * scale;
        (x + 0.5f32.copysign(x)) as i16
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn cos_sin_agrees_with_libm(angle in -100.0f64..100.0) {
            let at = CosSin::of(angle as f32);
            let exact = (angle as f32) as f64;
            prop_assert!((f64::from(at.cos) - exact.cos()).abs() < 3e-7, "{} {}", at.cos, exact.cos());
            prop_assert!((f64::from(at.sin) - exact.sin()).abs() < 3e-7, "{} {}", at.sin, exact.sin());
        }
    }

    /// Settings over the ranges a drive meets: 0.1..20 Ω, 0.1..50 mH, 10..60 V, 10..40 kHz, the
    /// pole anywhere from 0.01 to 0.99, with or without the dead time's compensation.
    fn settings() -> impl Strategy<Value = CurrentLoopSettings> {
        (0.1f32..20.0, 1.0e-4f32..5.0e-2, 10.0f32..60.0, 10_000.0f32..40_000.0, 0.01f32..0.99, any::<bool>()).prop_map(
            |(r, l, v, f, p, dead)| {
                let s = CurrentLoopSettings::new(r, l, v, f, -libm::logf(p) * f);
                let s = s.and_then(|s| if dead { s.with_dead_time(300e-9, 0.05) } else { Ok(s) });
                s.unwrap_or_else(|e| unreachable!("{e:?} for {r} {l} {v} {f} {p}"))
            },
        )
    }

    fn pair(range: f32) -> impl Strategy<Value = [f32; 2]> {
        [-range..range, -range..range]
    }

    fn phase_state(range: f32) -> impl Strategy<Value = PhaseState> {
        (-range..range, -range..range, -range / 10.0..range / 10.0, -1.0f32..1.0).prop_map(
            |(integral, applied, predicted, correction)| PhaseState { integral, applied, predicted, correction },
        )
    }

    proptest! {
        /// Whatever comes in, each winding's voltage is within ±0.9·v_bus and the integral
        /// within the same limit, over a run of periods whose bus voltage moves too.
        #[test]
        fn the_output_and_the_integral_stay_within_the_supply(
            s in settings(),
            start in [phase_state(100.0), phase_state(100.0)],
            periods in proptest::collection::vec((pair(30.0), pair(30.0), pair(80.0), -5.0f32..70.0), 1..40),
        ) {
            let mut state = CurrentLoopState { phases: start };
            for (i_ref, i_meas, emf, v_bus) in periods {
                let v = s.step(&mut state, i_ref, i_meas, emf, v_bus);
                let limit = CurrentLoopSettings::limit(v_bus);
                for (volts, phase) in v.iter().zip(&state.phases) {
                    prop_assert!(volts.abs() <= limit, "{volts} V beyond {limit}");
                    prop_assert!(phase.integral.abs() <= limit, "integral {} beyond {limit}", phase.integral);
                }
            }
        }

        /// With no error against the prediction the integral does not move and the output is
        /// the integral and the feed-forward.
        #[test]
        fn zero_error_changes_nothing(
            s in settings(),
            start in [phase_state(10.0), phase_state(10.0)],
            i_meas in pair(5.0),
            emf in pair(5.0),
        ) {
            let mut state = CurrentLoopState { phases: start };
            let i_ref = s.predict(&state, i_meas);
            // No dead-time term: the same reference, at rest, with the compensation off.
            let plain = CurrentLoopSettings { dead_share: 0.0, ..s };
            let v = plain.step(&mut state, i_ref, i_meas, emf, 48.0);
            for (((start, after), emf), v) in start.iter().zip(&state.phases).zip(emf).zip(v) {
                let clamped = start.integral.clamp(-43.2, 43.2);
                prop_assert_eq!(after.integral, clamped);
                let want = (emf + clamped).clamp(-43.2, 43.2);
                prop_assert!((v - want).abs() <= 1e-5 * (1.0 + want.abs()), "{} {}", v, want);
            }
        }

        /// Standing at a current with the voltage it needs (R·i applied, the integral holding
        /// it): the loop keeps that voltage.
        #[test]
        fn a_winding_at_rest_stays_at_rest(s in settings(), i in -3.0f32..3.0) {
            prop_assume!((s.resistance() * i).abs() < 50.0);
            let rest = PhaseState { integral: s.resistance() * i, applied: s.resistance() * i, predicted: i, correction: 0.0 };
            let mut state = CurrentLoopState { phases: [rest, rest] };
            let plain = CurrentLoopSettings { dead_share: 0.0, ..s };
            // The prediction's rounding (a few ulps of the current) comes out times kp: 1 500 V/A
            // for a slow winding on a fast loop.
            let rounding = s.kp() * 1e-6 * (1.0 + i.abs());
            for _ in 0..5 {
                let v = plain.step(&mut state, [i, i], [i, i], [0.0, 0.0], 60.0);
                let want = s.resistance() * i;
                prop_assert!((v[0] - want).abs() <= 1e-4 * (1.0 + want.abs()) + rounding, "{} {}", v[0], want);
            }
        }

        /// Park then inverse Park is the identity, and keeps the vector's length.
        #[test]
        fn park_round_trips(ab in pair(10.0), angle in -10.0f32..10.0) {
            let at = CosSin::of(angle);
            let dq = park(ab, at);
            let back = inverse_park(dq, at);
            prop_assert!((back[0] - ab[0]).abs() < 1e-5 && (back[1] - ab[1]).abs() < 1e-5);
            let len = |v: [f32; 2]| libm::sqrtf(v[0] * v[0] + v[1] * v[1]);
            prop_assert!((len(dq) - len(ab)).abs() < 1e-5);
        }
    }

    #[test]
    fn settings_out_of_range_are_refused() {
        let ok = (1.4, 3e-3, 24.0, 20_000.0, 32_189.0);
        let new = |(r, l, v, f, w): (f32, f32, f32, f32, f32)| CurrentLoopSettings::new(r, l, v, f, w);
        assert!(new(ok).is_ok());
        assert_eq!(new((f32::NAN, 3e-3, 24.0, 20_000.0, 1e4)), Err(Error::Resistance));
        assert_eq!(new((1.4, 2.0, 24.0, 20_000.0, 1e4)), Err(Error::Inductance));
        assert_eq!(new((1.4, 3e-3, 0.5, 20_000.0, 1e4)), Err(Error::Supply));
        assert_eq!(new((1.4, 3e-3, 24.0, 1e6, 1e4)), Err(Error::PwmRate));
        assert_eq!(new((1.4, 3e-3, 24.0, 20_000.0, 0.0)), Err(Error::Bandwidth));
        // ωc·T over ln 100: a pole under 0.01.
        assert_eq!(new((1.4, 3e-3, 24.0, 20_000.0, 4.7 * 20_000.0)), Err(Error::Bandwidth));
        let s = new(ok).unwrap_or_else(|e| unreachable!("{e:?}"));
        assert!((s.pole() - RECOMMENDED_POLE).abs() < 1e-4);
        assert_eq!(s.with_dead_time(-1e-9, 0.05), Err(Error::DeadTime));
        assert_eq!(s.with_dead_time(300e-9, 0.0), Err(Error::DeadTime));
    }

    #[test]
    fn the_dead_time_is_compensated_in_the_reference_direction() {
        let s = CurrentLoopSettings::new(1.4, 3e-3, 24.0, 20_000.0, 32_189.0)
            .and_then(|s| s.with_dead_time(300e-9, 0.05))
            .unwrap_or_else(|e| unreachable!("{e:?}"));
        // At rest at ±1 A, the loop adds 0.288 V in the current's direction; at 25 mA half of it.
        for (i, extra) in [(1.0f32, 0.288f32), (-1.0, -0.288), (0.025, 0.144), (0.0, 0.0)] {
            let rest = PhaseState { integral: 1.4 * i, applied: 1.4 * i, predicted: i, correction: 0.0 };
            let mut state = CurrentLoopState { phases: [rest, rest] };
            let v = s.step(&mut state, [i, i], [i, i], [0.0, 0.0], 24.0);
            assert!((v[0] - 1.4 * i - extra).abs() < 1e-4, "{i} A: {v:?}");
        }
    }

    #[test]
    fn a_bus_that_is_not_a_voltage_gives_no_voltage() {
        let s = CurrentLoopSettings::new(1.4, 3e-3, 24.0, 20_000.0, 32_189.0).unwrap_or_else(|e| unreachable!("{e:?}"));
        for bus in [0.0, -24.0, f32::NAN, f32::INFINITY] {
            let mut state = CurrentLoopState::default();
            assert_eq!(s.step(&mut state, [1.0, -1.0], [0.0, 0.0], [3.0, 3.0], bus), [0.0, 0.0], "{bus}");
            assert_eq!(state.phases[0].integral, 0.0);
        }
    }
}
