//! The Phong exponent `cos^n`, computed the same way on every backend.
//!
//! A driver's `pow` is an approximation of its own (lavapipe's differs from Rust's `powf` in the
//! last bits for one Phong term in twenty; an NVIDIA GPU uses its special-function unit), so the
//! tracers would round some pixels differently. This one uses only operations IEEE 754 rounds
//! exactly (add, multiply, compare, bit moves), in a fixed order that WGSL's `phong_pow` in
//! common.wgsl repeats line for line: with contraction forbidden (`--exact`) every device gets the
//! same bits. `x^n = 2^(n log2 x)`: the exponent of `x` plus a degree-8 polynomial for the log2 of
//! its mantissa (within 6e-8 absolute), and a degree-6 polynomial for `2^f`, `|f| <= 1/2` (within
//! 1e-7 relative), both fitted at Chebyshev nodes (coefficients in [`crate::constants`]). The
//! f64 reference renderer uses `powf`, so the approximation shows up in the accuracy figures.

use crate::constants::{POW_EXP2, POW_LOG2};

/// `x^n` for a clamped cosine `x` (0 where `x` is 0, negative or NaN) and an exponent `n > 0`.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub fn phong_pow(x: f32, n: f32) -> f32 {
    // Written so that NaN also gives 0.
    if x.is_nan() || x <= 0.0 {
        return 0.0;
    }
    let y = n * log2(x);
    if y == 0.0 {
        return 1.0;
    }
    exp2(y)
}

fn log2(x: f32) -> f32 {
    let mut x = x;
    let mut e = 0i32;
    if x < f32::MIN_POSITIVE {
        // A subnormal: scale into the normal range first (exact).
        x *= 18446744073709551616.0; // 2^64
        e = -64;
    }
    let bits = x.to_bits();
    e += (bits >> 23) as i32 - 127;
    let mut m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    if m > std::f32::consts::SQRT_2 {
        m *= 0.5;
        e += 1;
    }
    let t = m - 1.0;
    let mut p = POW_LOG2[8];
    for k in (0..8).rev() {
        p = p * t + POW_LOG2[k];
    }
    t * p + e as f32
}

fn exp2(y: f32) -> f32 {
    if y < -150.0 {
        return 0.0;
    }
    if y > 128.0 {
        return f32::INFINITY;
    }
    let i = (y + 0.5).floor();
    let f = y - i;
    let mut q = POW_EXP2[6];
    for k in (0..6).rev() {
        q = q * f + POW_EXP2[k];
    }
    // 2^i in two factors, so that results below the normal range come out subnormal.
    let i = i as i32;
    let (a, b) = if i < -126 { (i + 64, -64) } else { (i, 0) };
    q * f32::from_bits(((a + 127) as u32) << 23) * f32::from_bits(((b + 127) as u32) << 23)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_power_is_within_a_few_units_in_the_last_place_of_f64() {
        let mut worst = 0.0f64;
        for k in 1..=20_000 {
            let x = k as f32 / 20_000.0;
            for n in [0.5f32, 1.0, 2.0, 8.5, 32.0, 128.0] {
                let want = (x as f64).powf(n as f64);
                if want < 1e-30 {
                    continue;
                }
                let got = phong_pow(x, n) as f64;
                worst = worst.max((got - want).abs() / want);
            }
        }
        // The f32 product `y = n log2 x` alone is off by up to |y| * 6e-8, which moves `2^y` by
        // |y| * 4e-8 of itself: 6e-6 at y = -150, the smallest subnormal. Measured: 7.0e-6.
        assert!(worst < 1e-5, "worst relative error {worst:e}");
        assert_eq!(phong_pow(1.0, 37.0), 1.0);
        assert_eq!(phong_pow(0.0, 3.0), 0.0);
        assert_eq!(phong_pow(-0.2, 3.0), 0.0);
        assert_eq!(phong_pow(f32::NAN, 3.0), 0.0);
        assert!(phong_pow(1e-40, 0.5) > 0.0 && (phong_pow(1e-40, 0.5) as f64 - 1e-20).abs() < 1e-25);
        assert_eq!(phong_pow(0.5, 1000.0), 0.0, "below the smallest subnormal");
        assert!((phong_pow(0.5, 140.0) as f64 - 0.5f64.powi(140)).abs() < 1e-45, "a subnormal result");
    }
}
