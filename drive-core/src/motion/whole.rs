//! Rounding of `f64` to whole numbers through the integer conversions the planner links
//! anyway: libm's `floor` and `ceil` are 350 bytes of software floating point on the Cortex-M4,
//! whose FPU has no `f64`.
//!
//! ```
//! use drive_core::motion::whole::{ceil, floor};
//! assert_eq!((floor(-2.5), floor(2.5), floor(3.0)), (-3.0, 2.0, 3.0));
//! assert_eq!((ceil(-2.5), ceil(2.5), ceil(3.0)), (-2.0, 3.0, 3.0));
//! assert!(floor(f64::NAN).is_nan());
//! ```

/// 2^52: from here on every `f64` is whole.
const WHOLE: f64 = 4_503_599_627_370_496.0;

/// The largest whole number not above `x` (NaN and infinities as they are).
pub fn floor(x: f64) -> f64 {
    // NaN fails the comparison too.
    if x.is_nan() || libm::fabs(x) >= WHOLE {
        return x;
    }
    let t = x as i64 as f64;
    if t > x { t - 1.0 } else { t }
}

/// The smallest whole number not below `x` (NaN and infinities as they are).
pub fn ceil(x: f64) -> f64 {
    -floor(-x)
}

#[cfg(test)]
mod tests {
    #[test]
    fn agrees_with_libm() {
        let xs = [0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 1e-300, -1e-300, 123456.789, -123456.789, 4.5e15, -4.5e15, 1e300];
        for x in xs.into_iter().chain((0..2000).map(|i| (f64::from(i) - 1000.0) * 0.37)) {
            assert_eq!(super::floor(x), libm::floor(x), "floor {x}");
            assert_eq!(super::ceil(x), libm::ceil(x), "ceil {x}");
        }
    }
}
