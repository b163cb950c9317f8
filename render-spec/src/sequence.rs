//! Sample sequences: where the n-th sample of a pixel lies in the unit square, so that both tracers
//! take the same samples (sub-pixel positions for several samples per pixel, ambient-occlusion and
//! diffuse directions).
//!
//! The sequence is R2 (Roberts 2018, "The unreasonable effectiveness of quasirandom sequences"):
//! `x_n = frac(s + n / phi2)`, `y_n = frac(s' + n / phi2^2)` with `phi2 = 1.32471...` the plastic
//! number, the 2D analogue of the golden-ratio sequence: any run of consecutive samples covers the
//! square evenly, with no rejection and no table. Each pixel starts at its own offset `(s, s')`
//! (a Cranley-Patterson rotation by a hash of the pixel index), so that neighbouring pixels do
//! not repeat one pattern.
//!
//! Everything is integer arithmetic in 0.32 fixed point and one exact conversion to f32 (the top 24
//! bits), so a kernel computes bit-identical samples with the same steps
//! ([`crate::constants::R2_STEP_X`], [`crate::constants::R2_STEP_Y`]).

use crate::constants::{R2_STEP_X, R2_STEP_Y};

/// A 32-bit integer hash with good avalanche (Wellons' "lowbias32"): the per-pixel offsets.
#[inline]
pub fn hash(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// A 0.32 fixed-point fraction as an f32 in `[0, 1)`: its top 24 bits, which an f32 holds exactly.
#[inline]
pub fn unit_f32(x: u32) -> f32 {
    (x >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// The `n`-th sample of pixel `pixel` (its row-major index), in `[0, 1)^2`.
#[inline]
pub fn sample_2d(pixel: u32, n: u32) -> [f32; 2] {
    let sx = hash(pixel);
    let sy = hash(sx ^ 0x9e37_79b9);
    [unit_f32(sx.wrapping_add(n.wrapping_mul(R2_STEP_X))), unit_f32(sy.wrapping_add(n.wrapping_mul(R2_STEP_Y)))]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_steps_are_the_inverse_powers_of_the_plastic_number() {
        // phi2 is the real root of x^3 = x + 1.
        let mut p = 1.3f64;
        for _ in 0..50 {
            p -= (p * p * p - p - 1.0) / (3.0 * p * p - 1.0);
        }
        assert_eq!(R2_STEP_X, ((1.0 / p) * 4294967296.0).round() as u32);
        assert_eq!(R2_STEP_Y, ((1.0 / (p * p)) * 4294967296.0).round() as u32);
    }

    #[test]
    fn samples_lie_in_the_unit_square_and_are_reproducible() {
        for pixel in [0u32, 1, 77, u32::MAX] {
            for n in [0u32, 1, 2, 1000, u32::MAX] {
                let s = sample_2d(pixel, n);
                assert!(s.iter().all(|&v| (0.0..1.0).contains(&v)), "{pixel} {n}: {s:?}");
                assert_eq!(s, sample_2d(pixel, n));
            }
        }
        assert_eq!(unit_f32(u32::MAX), 1.0 - 1.0 / (1u32 << 24) as f32, "the largest value stays below 1");
    }

    /// Any run of 64 consecutive samples of a pixel puts between 2 and 6 in each of the 16 cells of
    /// a 4 x 4 grid (4 expected); independent uniform samples break that bound in most runs.
    #[test]
    fn consecutive_samples_cover_the_square_evenly() {
        let cells = |pts: &[[f32; 2]]| {
            let mut c = [0u32; 16];
            for p in pts {
                c[(p[0] * 4.0) as usize + 4 * (p[1] * 4.0) as usize] += 1;
            }
            c
        };
        for pixel in [0u32, 5, 123_456] {
            for start in [0u32, 1, 1000, 65_536] {
                let pts: Vec<[f32; 2]> = (start..start + 64).map(|n| sample_2d(pixel, n)).collect();
                let c = cells(&pts);
                assert!(c.iter().all(|&k| (2..=6).contains(&k)), "pixel {pixel} from {start}: {c:?}");
            }
        }
        // The same test on hashed (independent-looking) samples fails: the bound means something.
        let mut failures = 0;
        for run in 0..20u32 {
            let pts: Vec<[f32; 2]> =
                (0..64).map(|n| [unit_f32(hash(run * 1000 + 2 * n)), unit_f32(hash(run * 1000 + 2 * n + 1))]).collect();
            failures += u32::from(!cells(&pts).iter().all(|&k| (2..=6).contains(&k)));
        }
        assert!(failures >= 10, "uniform random samples passed {} of 20 runs", 20 - failures);
    }

    #[test]
    fn pixels_start_at_different_offsets() {
        let firsts: Vec<[f32; 2]> = (0..4096).map(|p| sample_2d(p, 0)).collect();
        let mean = firsts.iter().fold([0.0f64; 2], |a, s| [a[0] + s[0] as f64, a[1] + s[1] as f64]);
        for m in mean {
            assert!((m / 4096.0 - 0.5).abs() < 0.02, "first samples are not spread: mean {}", m / 4096.0);
        }
        let distinct: std::collections::HashSet<[u32; 2]> =
            firsts.iter().map(|s| [s[0].to_bits(), s[1].to_bits()]).collect();
        assert_eq!(distinct.len(), 4096);
    }
}
