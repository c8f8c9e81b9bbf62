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
}
