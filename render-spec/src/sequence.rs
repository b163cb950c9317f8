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
//!
//! The incoherent modes (docs/shading.md, "Ambient occlusion" and "Diffuse bounce") draw their
//! directions here: [`incoherent_sample`] numbers a pixel's samples, [`cosine_direction`] maps one to
//! the hemisphere. `common.wgsl` repeats both operation for operation, and
//! `tests/tests/wgsl_functions.rs` holds the two to equal bits.

use crate::constants::{QUARTER_COS, QUARTER_SIN, R2_STEP_X, R2_STEP_Y};

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

/// The sequence number of incoherent ray `ray` of pixel sample `sample` (the `--spp` sample's index)
/// when each sample casts `rays` of them: the samples' rays follow one another in one run of the
/// sequence (`sample * rays + ray`, wrapping), so the whole pixel covers the square evenly.
#[inline]
pub fn incoherent_sample(sample: u32, rays: u32, ray: u32) -> u32 {
    sample.wrapping_mul(rays).wrapping_add(ray)
}

/// `sin(pi/2 x)` and `cos(pi/2 x)` for `x` in `[0, 1)`, by the polynomials of
/// [`QUARTER_SIN`] and [`QUARTER_COS`] (Horner's rule in `x^2`).
#[inline]
fn quarter_turn(x: f32) -> (f32, f32) {
    let x2 = x * x;
    let mut s = QUARTER_SIN[6];
    for k in (0..6).rev() {
        s = s * x2 + QUARTER_SIN[k];
    }
    let mut c = QUARTER_COS[7];
    for k in (0..7).rev() {
        c = c * x2 + QUARTER_COS[k];
    }
    (x * s, c)
}

/// A cosine-distributed unit direction about the unit normal `n` for the sample `u` in `[0, 1)^2`
/// (Malley's method): the point `(sqrt(u0) cos(2 pi u1), sqrt(u0) sin(2 pi u1))` of the unit disk
/// lifted to the hemisphere (`z = sqrt(1 - u0)`) in the tangent frame of Duff et al. 2017
/// ("Building an Orthonormal Basis, Revisited"), then normalised as the tracers normalise
/// (`v * (1 / length(v))`). Additions, multiplications, one division and square roots only, so a
/// kernel repeating the steps gets the same bits; the azimuth is a quarter turn `floor(4 u1)`
/// (exact) plus a polynomial sine and cosine of the rest.
#[allow(clippy::neg_cmp_op_on_partial_ord)]
pub fn cosine_direction(n: [f32; 3], u: [f32; 2]) -> [f32; 3] {
    let q4 = u[1] * 4.0;
    let q = q4.floor();
    let (s, c) = quarter_turn(q4 - q);
    let (cos_phi, sin_phi) = if q < 1.0 {
        (c, s)
    } else if q < 2.0 {
        (-s, c)
    } else if q < 3.0 {
        (-c, -s)
    } else {
        (s, -c)
    };
    let r = u[0].sqrt();
    // u0 is a multiple of 2^-24 below 1: 1 - u0 is exact and positive.
    let z = (1.0 - u[0]).sqrt();
    let (a, b) = (r * cos_phi, r * sin_phi);
    let sign = if n[2] < 0.0 { -1.0f32 } else { 1.0 };
    let k = -1.0 / (sign + n[2]);
    let m = n[0] * n[1] * k;
    let t1 = [1.0 + sign * n[0] * n[0] * k, sign * m, -(sign * n[0])];
    let t2 = [m, sign + n[1] * n[1] * k, -n[1]];
    let d: [f32; 3] = std::array::from_fn(|i| t1[i] * a + t2[i] * b + n[i] * z);
    let inv = 1.0 / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    [d[0] * inv, d[1] * inv, d[2] * inv]
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

    #[test]
    fn the_quarter_turn_is_sine_and_cosine() {
        for i in 0..=4096 {
            let x = i as f32 / 4096.0;
            let (s, c) = quarter_turn(x);
            let a = std::f64::consts::FRAC_PI_2 * x as f64;
            assert!((s as f64 - a.sin()).abs() < 2e-7 && (c as f64 - a.cos()).abs() < 2e-7, "{x}: {s} {c}");
        }
    }

    /// Directions are unit vectors in the normal's hemisphere, and cosine-distributed: over many
    /// samples the mean of `cos` is 2/3 and of `cos^2` is 1/2 (uniform directions give 1/2 and
    /// 1/3), and the azimuth is uniform (the mean direction lies along the normal). For normals
    /// along the axes (both signs, the frame's branch) and oblique ones.
    #[test]
    fn cosine_directions_are_unit_cosine_distributed_and_about_the_normal() {
        let normals =
            [[0.0, 0.0, 1.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.6, 0.0, -0.8], [0.48, 0.6, 0.64]];
        for n in normals {
            let count = 4096;
            let (mut cos, mut cos2, mut mean) = (0.0f64, 0.0f64, [0.0f64; 3]);
            for k in 0..count {
                let d = cosine_direction(n, sample_2d(77, k));
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                assert!((len - 1.0).abs() < 1e-6, "{n:?} {k}: length {len}");
                let c = (d[0] * n[0] + d[1] * n[1] + d[2] * n[2]) as f64;
                assert!(c >= -1e-6, "{n:?} {k}: {d:?} is below the surface");
                cos += c;
                cos2 += c * c;
                for i in 0..3 {
                    mean[i] += d[i] as f64;
                }
            }
            let count = count as f64;
            assert!((cos / count - 2.0 / 3.0).abs() < 0.01, "{n:?}: mean cos {}", cos / count);
            assert!((cos2 / count - 0.5).abs() < 0.01, "{n:?}: mean cos^2 {}", cos2 / count);
            for i in 0..3 {
                assert!((mean[i] / count - 2.0 / 3.0 * n[i] as f64).abs() < 0.01, "{n:?}: mean {mean:?}");
            }
        }
    }

    #[test]
    fn samples_of_a_pixel_follow_one_another() {
        assert_eq!(incoherent_sample(0, 8, 3), 3);
        assert_eq!(incoherent_sample(2, 8, 3), 19);
        assert_eq!(incoherent_sample(u32::MAX, 2, 1), u32::MAX);
    }
}
