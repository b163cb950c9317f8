//! Settings that trade accuracy for speed (issue 8): which triangle test, which origin offset for
//! shadow and secondary rays, how many samples per pixel, and where the adaptive bounce stop
//! cuts. [`Accuracy::default`] is the shading contract of docs/shading.md; both tracers honour
//! every field identically.

use crate::RenderError;
use crate::constants::STOP_CONTRIBUTION;

/// The ray-triangle test.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Intersect {
    /// The edge-consistent test of docs/shading.md ("Intersection"): a ray through an edge shared
    /// by two triangles hits at least one of them.
    #[default]
    Watertight,
    /// Möller-Trumbore on vertex 0 and its two edges: each triangle decides a shared edge after
    /// its own roundings, so a ray aimed exactly at an edge can pass between both triangles.
    MollerTrumbore,
}

/// How far the origins of shadow and secondary rays are moved off the surface they leave.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Offset {
    /// A few units in the last place of each coordinate along the geometric normal (docs/shading.md,
    /// "Self-intersection"): free of the scene's scale.
    #[default]
    ScaleAware,
    /// The origin moved by this distance (in scene units) along the geometric normal: too small
    /// for the scene gives acne (rays stopped by their own surface), too large misses contact
    /// shadows.
    Fixed(f32),
}

/// The most samples per pixel a frame may take (32 x 32).
pub const MAX_SPP: u32 = 1024;

/// What a frame trades between accuracy and speed; the default is today's contract.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Accuracy {
    pub intersect: Intersect,
    pub offset: Offset,
    /// Samples per pixel, a square `n * n` (1, 4, 9, ...) up to [`MAX_SPP`], at the positions of
    /// [`sample_positions`]; the pixel is the mean of their linear colours, quantised once.
    pub spp: u32,
    /// The adaptive bounce stop (docs/shading.md, "Adaptive stop"): a secondary ray whose chain
    /// can add less than this to a channel is not traced. 0 traces every bounce up to the
    /// indirection limit.
    pub cutoff: f32,
}

impl Default for Accuracy {
    fn default() -> Self {
        Self { intersect: Intersect::Watertight, offset: Offset::ScaleAware, spp: 1, cutoff: STOP_CONTRIBUTION }
    }
}

impl Accuracy {
    /// Checks every field: a square spp from 1 to [`MAX_SPP`], a finite cutoff of at least 0, a
    /// finite fixed offset of at least 0.
    pub fn check(&self) -> Result<(), RenderError> {
        if self.spp == 0 || self.spp > MAX_SPP || side(self.spp) * side(self.spp) != self.spp {
            return Err(RenderError::SamplesPerPixel(self.spp));
        }
        if !(self.cutoff.is_finite() && self.cutoff >= 0.0) {
            return Err(RenderError::Cutoff(self.cutoff));
        }
        if let Offset::Fixed(d) = self.offset
            && !(d.is_finite() && d >= 0.0)
        {
            return Err(RenderError::Offset(d));
        }
        Ok(())
    }
}

/// The side `n` of an `n x n` sample grid: the integer square root of `spp`, rounded down.
pub fn side(spp: u32) -> u32 {
    let spp = u64::from(spp);
    let mut n = (spp as f64).sqrt() as u64;
    while n * n > spp {
        n -= 1;
    }
    while (n + 1) * (n + 1) <= spp {
        n += 1;
    }
    n as u32
}

/// The sub-pixel positions of `spp` samples, in `[0, 1)^2` from the pixel's top-left corner: the
/// centres of an `n x n` grid (`n` = [`side`] of `spp`), row by row from the top, each
/// `((i + 0.5) / n, (j + 0.5) / n)` rounded once to f32. One sample is `(0.5, 0.5)`, the pixel
/// centre of the primary ray of docs/shading.md. A GPU should get these values from the host
/// rather than divide itself (WGSL's division need not be correctly rounded).
pub fn sample_positions(spp: u32) -> impl Iterator<Item = (f32, f32)> {
    let n = side(spp).max(1);
    let at = move |i: u32| ((f64::from(i) + 0.5) / f64::from(n)) as f32;
    (0..n).flat_map(move |j| (0..n).map(move |i| (at(i), at(j))))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_sample_is_the_pixel_centre_and_grids_are_stratified() {
        assert_eq!(sample_positions(1).collect::<Vec<_>>(), vec![(0.5, 0.5)]);
        assert_eq!(
            sample_positions(4).collect::<Vec<_>>(),
            vec![(0.25, 0.25), (0.75, 0.25), (0.25, 0.75), (0.75, 0.75)]
        );
        for spp in [9, 16, 25, 1024] {
            let s: Vec<(f32, f32)> = sample_positions(spp).collect();
            let n = side(spp) as usize;
            assert_eq!(s.len(), spp as usize);
            // One sample per cell of the n x n grid, at its centre.
            for (k, &(x, y)) in s.iter().enumerate() {
                let (i, j) = (k % n, k / n);
                assert_eq!(((x * n as f32) as usize, (y * n as f32) as usize), (i, j), "{spp}: {x} {y}");
                assert!((x - (i as f32 + 0.5) / n as f32).abs() < 1e-6);
            }
            let mean = s.iter().fold((0.0, 0.0), |a, p| (a.0 + p.0, a.1 + p.1));
            assert!((mean.0 / spp as f32 - 0.5).abs() < 1e-5 && (mean.1 / spp as f32 - 0.5).abs() < 1e-5);
        }
    }

    #[test]
    fn the_default_is_the_contract_and_bad_values_are_refused() {
        let a = Accuracy::default();
        assert_eq!(a.check(), Ok(()));
        assert_eq!(
            (a.intersect, a.offset, a.spp, a.cutoff),
            (Intersect::Watertight, Offset::ScaleAware, 1, 0.5 / 255.0)
        );
        for spp in [0, 2, 3, 5, 8, 1025, 2048, u32::MAX] {
            assert_eq!(Accuracy { spp, ..a }.check(), Err(RenderError::SamplesPerPixel(spp)), "{spp}");
        }
        for spp in [1, 4, 9, 16, 25, 1024] {
            assert_eq!(Accuracy { spp, ..a }.check(), Ok(()));
        }
        for cutoff in [-1e-9, f32::NAN, f32::INFINITY] {
            assert!(matches!(Accuracy { cutoff, ..a }.check(), Err(RenderError::Cutoff(_))));
        }
        assert_eq!(Accuracy { cutoff: 0.0, ..a }.check(), Ok(()));
        for d in [-1e-4, f32::NAN, f32::NEG_INFINITY, f32::INFINITY] {
            assert!(matches!(Accuracy { offset: Offset::Fixed(d), ..a }.check(), Err(RenderError::Offset(_))));
        }
        assert_eq!(Accuracy { offset: Offset::Fixed(1e-4), ..a }.check(), Ok(()));
        assert_eq!(side(u32::MAX), 65535);
    }
}
