//! Rounding of `f32` to whole numbers through the FPU's 32-bit integer conversion (one
//! instruction each way on the Cortex-M4F) rather than libm's bit manipulation.
//!
//! ```
//! use drive_core::motion::whole::{ceil, floor};
//! assert_eq!((floor(-2.5), floor(2.5), floor(3.0)), (-3.0, 2.0, 3.0));
//! assert_eq!((ceil(-2.5), ceil(2.5), ceil(3.0)), (-2.0, 3.0, 3.0));
//! assert!(floor(f32::NAN).is_nan());
//! ```

/// 2^23: from here on every `f32` is whole.
const WHOLE: f32 = 8_388_608.0;

/// The largest whole number not above `x` (NaN and infinities as they are).
pub fn floor(x: f32) -> f32 {
    // NaN fails the comparison too.
    if x.is_nan() || libm::fabsf(x) >= WHOLE {
        return x;
    }
    let t = x as i32 as f32;
    if t > x { t - 1.0 } else { t }
}

/// The smallest whole number not below `x` (NaN and infinities as they are).
pub fn ceil(x: f32) -> f32 {
    -floor(-x)
}

#[cfg(test)]
mod tests {
    #[test]
    fn agrees_with_libm() {
        let xs = [0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 1e-30, -1e-30, 12345.678, -12345.678, 8.4e6, -8.4e6, 1e30, -3e9];
        for x in xs.into_iter().chain((0..2000).map(|i| (i as f32 - 1000.0) * 0.37)) {
            assert_eq!(super::floor(x), libm::floorf(x), "floor {x}");
            assert_eq!(super::ceil(x), libm::ceilf(x), "ceil {x}");
        }
    }
}
