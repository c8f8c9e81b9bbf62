//! `f32` arithmetic the Cortex-M4's FPU does in a few instructions, where the library routine
//! would be a software one.

/// The square root of `x` (0 for zero, negative numbers and NaN), within an ulp: three Newton
/// steps from an estimate of the exponent's half, each a division the FPU makes in 14 cycles,
/// where `libm::sqrtf` rounds correctly in software (518 bytes of code and table).
///
/// ```
/// use drive_core::math::sqrt;
/// assert_eq!(sqrt(16.0), 4.0);
/// assert!((sqrt(2.0) - core::f32::consts::SQRT_2).abs() <= f32::EPSILON);
/// assert_eq!((sqrt(0.0), sqrt(-1.0)), (0.0, 0.0));
/// ```
pub fn sqrt(x: f32) -> f32 {
    if x.is_nan() || x <= 0.0 {
        return 0.0;
    }
    if x == f32::INFINITY {
        return x;
    }
    // Half the exponent: within 4 % of the root.
    let mut r = f32::from_bits((x.to_bits() >> 1) + 0x1FBD_1DF5);
    for _ in 0..3 {
        r = 0.5 * (r + x / r);
    }
    r
}

/// The cosine of `x` rad for `x` in `[0, π]`, within 1e-6: `-sin(x - π/2)` by its Taylor
/// series to the eleventh power, a few multiplications where `libm::cosf` reduces its argument in
/// software.
///
/// ```
/// use drive_core::math::cos;
/// assert!((cos(0.0) - 1.0).abs() < 1e-6);
/// assert!(cos(core::f32::consts::FRAC_PI_2).abs() < 1e-6);
/// assert!((cos(core::f32::consts::PI) + 1.0).abs() < 1e-6);
/// ```
pub fn cos(x: f32) -> f32 {
    let u = x - core::f32::consts::FRAC_PI_2;
    let u2 = u * u;
    let sin = u * (1.0 - u2 / 6.0 * (1.0 - u2 / 20.0 * (1.0 - u2 / 42.0 * (1.0 - u2 / 72.0 * (1.0 - u2 / 110.0)))));
    -sin
}

#[cfg(test)]
mod tests {
    #[test]
    fn within_an_ulp_of_the_correctly_rounded_root() {
        let mut x = 1e-30f32;
        while x < 1e30 {
            for k in 0..7 {
                let v = x * (1.0 + k as f32 * 0.37);
                let (got, want) = (super::sqrt(v), libm::sqrtf(v));
                assert!((got - want).abs() <= want * f32::EPSILON, "sqrt({v}) = {got}, not {want}");
            }
            x *= 1.7;
        }
        for v in [1.0f32, 4.0, 9.0, 1e6, 2.5e11] {
            assert_eq!(super::sqrt(v), libm::sqrtf(v), "{v}: exact squares");
        }
    }

    #[test]
    fn the_cosine_is_within_a_millionth_over_half_a_turn() {
        for k in 0..=10_000 {
            let x = core::f32::consts::PI * k as f32 / 10_000.0;
            let (got, want) = (super::cos(x), libm::cosf(x));
            assert!((got - want).abs() < 1e-6, "cos({x}) = {got}, not {want}");
        }
    }
}
