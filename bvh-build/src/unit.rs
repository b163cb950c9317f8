//! The stored unit of a compiled scene: a scene much smaller or larger than a few units is stored
//! rescaled by a power of two ([`bvh_format::SceneFile::scale_log2`]).
//!
//! Why: the tracers' self-intersection offset (Wächter and Binder; docs/shading.md) moves a
//! secondary ray's origin by an absolute step near zero (1/65536 below 1/32) and by ulps
//! elsewhere. Both hold for scenes of a few units only: a scene 1e-7 wide is pushed off itself by
//! the absolute step, and in a scene 1e9 wide the error of a computed hit point (ulps of the
//! camera's distance) dwarfs both steps, so shadow rays start inside surfaces (the stress sweep's
//! scale axis measured ~10% wrong pixels at 10^-8 and 1-23% at 10^7..10^8). Multiplying by a power
//! of two is exact in binary floating point, so the rescaled scene is the same scene: its image
//! equals the image of every other power-of-two rescaling of it bit for bit, and only values
//! that underflow change. Scaling the constants by the scene's extent instead would have to be
//! done identically in every tracer, kernel and the f64 reference, for every constant.

use crate::BuildError;
use bvh_format::SceneFile;

/// Scenes whose largest local coordinate (in magnitude) lies in `[KEPT_MIN, KEPT_MAX)` are stored
/// as they are: the stress sweep's mirror room (largest coordinate 6) renders every pixel right
/// from 0.06 to 60, so this keeps a margin of two at both ends.
pub const KEPT_MIN: f32 = 0.125;
/// See [`KEPT_MIN`].
pub const KEPT_MAX: f32 = 32.0;
/// A rescaled scene's largest coordinate lies in `[2^TARGET_LOG2, 2^(TARGET_LOG2 + 1))`, [4, 8).
pub const TARGET_LOG2: i32 = 2;

/// The scene's largest coordinate in magnitude (of its root box).
fn largest(file: &SceneFile) -> f32 {
    let (lo, hi) = file.bounds();
    lo.iter().chain(&hi).fold(0.0f32, |m, v| m.max(v.abs()))
}

/// The power of two that brings a scene whose largest coordinate is `m` into the stored range:
/// 0 inside `[KEPT_MIN, KEPT_MAX)` (and for a scene that is all zero), else the exponent that
/// brings `m` into `[4, 8)`.
pub fn scale_log2(m: f32) -> Result<i32, BuildError> {
    if m == 0.0 || (KEPT_MIN..KEPT_MAX).contains(&m) {
        return Ok(0);
    }
    if !m.is_normal() {
        // Subnormal (or non-finite, which the builder refuses earlier): the coordinates have
        // already lost bits to underflow when they were rounded to f32.
        return Err(BuildError::Unrepresentable { largest: m });
    }
    let exponent = ((m.to_bits() >> 23) & 0xff) as i32 - 127;
    Ok(exponent - TARGET_LOG2)
}

/// Rescales a compiled scene (vertices, node boxes, cameras, lights) to its stored unit and
/// records the exponent. A camera or light that would lie beyond f32's range in the new unit is
/// refused, with the numbers.
pub fn rescale(file: &mut SceneFile) -> Result<(), BuildError> {
    let m = largest(file);
    let e = scale_log2(m)?;
    if e == 0 {
        return Ok(());
    }
    // In f64: 2^-e may not be an f32 (e = -128), and a product of an f32 and a power of two is
    // exact in f64, so the only rounding is the one to f32 (which changes only what underflows).
    let f = 2f64.powi(-e);
    let s = |v: [f32; 3]| v.map(|x| (f64::from(x) * f) as f32);
    use rayon::prelude::*;
    file.vertices.par_iter_mut().for_each(|v| *v = s(*v));
    for nodes in file.child_pair.iter_mut().chain(file.escape.iter_mut()) {
        nodes.par_iter_mut().for_each(|n| (n.min, n.max) = (s(n.min), s(n.max)));
    }
    let beyond = |what: String, p: [f32; 3]| BuildError::BeyondRange {
        what,
        distance: p.iter().fold(0.0f32, |a, v| a.max(v.abs())),
        largest: m,
        scale_log2: e,
    };
    for c in &mut file.cameras {
        let (eye, at) = (s(c.eye), s(c.at));
        let name = c.name().unwrap_or_default().to_owned();
        for (p, q) in [(c.eye, eye), (c.at, at)] {
            if !q.iter().all(|v| v.is_finite()) {
                return Err(beyond(format!("camera '{name}'"), p));
            }
        }
        (c.eye, c.at) = (eye, at);
    }
    for (k, l) in file.lights.iter_mut().enumerate() {
        let p = s(l.position);
        if !p.iter().all(|v| v.is_finite()) {
            return Err(beyond(format!("light {}", k + 1), l.position));
        }
        l.position = p;
    }
    file.scale_log2 = e;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_exponent_brings_the_largest_coordinate_into_four_to_eight() {
        for m in [1e-30f32, 1.2e-7, 0.1, 0.124, 32.0, 1e4, 1.2e9, 3e38, f32::MIN_POSITIVE] {
            let e = scale_log2(m).unwrap();
            let stored = f64::from(m) * 2f64.powi(-e);
            assert!((4.0..8.0).contains(&stored), "{m}: 2^{e} gives {stored}");
        }
        for m in [0.0f32, 0.125, 1.0, 6.0, 31.99] {
            assert_eq!(scale_log2(m).unwrap(), 0, "{m}");
        }
        for m in [1e-40f32, f32::MIN_POSITIVE / 2.0] {
            let e = scale_log2(m).unwrap_err().to_string();
            assert!(e.contains("smallest normal"), "{e}");
        }
    }
}
