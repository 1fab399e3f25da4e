//! exp, sigmoid and tanh for f32 without branches or library calls, so that loops over them
//! vectorise (libm's `expf`/`tanhf` are one call per element: 10-20 % of a PPO step was
//! spent in them, mostly in the GRU gates).
//!
//! Cephes' single-precision polynomials (range reduction by ln 2 in two parts, degree-6
//! polynomial, exponent by integer add). Only `+ - * /`, min/max and an f32 -> i32
//! conversion are used, so the result is the same on every instruction set level (see
//! `simd`). Accuracy against f64, tested below: exp within 2 ulp (relative 2.4e-7) on
//! [-87, 88]; tanh within 3e-7 absolute and 1e-6 relative; sigmoid within 3e-7 absolute.
//! Arguments below -87 give exp(-87) ~ 1.6e-38 instead of a denormal or 0, above 88 give
//! exp(88); NaN stays NaN for tanh and sigmoid inputs in range.

const LOG2E: f32 = std::f32::consts::LOG2_E;
/// 1.5 * 2^23: adding and subtracting it rounds to the nearest integer.
const ROUND: f32 = 12_582_912.0;

/// e^x (see the module doc for range and accuracy).
#[inline(always)]
pub fn exp(x: f32) -> f32 {
    let x = x.clamp(-87.0, 88.0);
    let n = (x * LOG2E + ROUND) - ROUND;
    let r = x - n * 0.693_359_4;
    let r = r - n * -2.121_944_4e-4;
    let mut y = 1.987_569_1e-4;
    y = y * r + 1.398_199_9e-3;
    y = y * r + 8.333_452e-3;
    y = y * r + 4.166_579_6e-2;
    y = y * r + 0.166_666_65;
    y = y * r + 0.5;
    y = y * (r * r) + r + 1.0;
    // SAFETY: n is an integer in [-126, 127] (x was clamped; NaN becomes 0 through the
    // clamp-free path below only if x is NaN, handled first). `as i32` would be a
    // saturating conversion whose NaN/range checks keep the loop from vectorising.
    let n = if n.is_nan() { 0.0 } else { n };
    let ni: i32 = unsafe { n.to_int_unchecked() };
    f32::from_bits(y.to_bits().wrapping_add((ni << 23) as u32))
}

/// 1 / (1 + e^-x).
#[inline(always)]
pub fn sigmoid(x: f32) -> f32 {
    1.0 / (1.0 + exp(-x))
}

#[allow(clippy::excessive_precision)] // Cephes constants as published
/// tanh x: an odd polynomial below |x| 0.625 (where 1 - e^-2|x| would cancel), else
/// (1 - e^-2|x|) / (1 + e^-2|x|) with x's sign.
#[inline(always)]
pub fn tanh(x: f32) -> f32 {
    let ax = x.abs();
    let z = x * x;
    let small =
        ((((-5.704_988_7e-3 * z + 2.063_908_9e-2) * z - 5.373_971_6e-2) * z + 0.133_314_42) * z
            - 0.333_332_82)
            * z
            * x
            + x;
    let e = exp(-2.0 * ax);
    let large = ((1.0 - e) / (1.0 + e)).copysign(x);
    if ax < 0.625 {
        small.copysign(x)
    } else {
        large
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid() -> impl Iterator<Item = f32> {
        (-197_000..=200_000).map(|i| i as f32 * 4.4e-4)
    }

    #[test]
    fn exp_within_two_ulp() {
        for x in grid().chain([-87.0, 88.0, 0.0, -0.0, 1e-8, -1e-8]) {
            let want = (x as f64).exp();
            let got = exp(x) as f64;
            assert!(
                ((got - want) / want).abs() <= 2.4e-7,
                "exp({x}) = {got}, want {want}"
            );
        }
        assert!(exp(-1000.0) < 2e-38 && exp(-1000.0) >= 0.0);
        assert!(exp(1000.0).is_finite());
    }

    #[test]
    fn tanh_and_sigmoid_close_to_f64() {
        for x in grid().chain([0.0, 1e-6, -1e-6, 0.6249, 0.625, 50.0, -50.0]) {
            let t = (x as f64).tanh();
            let got = tanh(x) as f64;
            assert!((got - t).abs() <= 3e-7, "tanh({x}) = {got}, want {t}");
            if t.abs() > 1e-30 {
                assert!(((got - t) / t).abs() <= 1e-6, "tanh({x}) relative");
            }
            let s = 1.0 / (1.0 + (-x as f64).exp());
            assert!((sigmoid(x) as f64 - s).abs() <= 3e-7, "sigmoid({x})");
        }
        assert_eq!(tanh(0.0), 0.0);
        assert!(tanh(-0.0).is_sign_negative());
    }
}
