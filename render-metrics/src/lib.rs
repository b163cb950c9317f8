//! How far a render is from a reference render of the same scene, camera and size (issue 8,
//! docs/accuracy.md):
//!
//! - [`image`]: per image, the perceptual error FLIP (mean and 99th percentile of NVIDIA's error
//!   map), PSNR, and the shares of pixels off by more than 1/255 and by more than 8/255.
//! - [`hits`]: per set of primary rays, from the per-pixel outputs (`prim`, `t`): closest hits that
//!   disagree with the reference's, leaks (rays that go past a surface the reference ray stops
//!   at), and shading shifts where the hit agrees: darker pixels (acne, a shadow ray stopped by
//!   its own surface) and lighter ones (a contact shadow missed).
//!
//! Every figure is a plain count or share, so that two settings compare by their numbers alone.

pub mod hits;
pub mod image;

pub use hits::{HitErrors, ShadingShifts, compare_hits, shading_shifts};
pub use image::{ImageErrors, compare_images};

/// Why two renders cannot be compared.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum MetricsError {
    #[error("the test image is {test_w}x{test_h} but its reference is {ref_w}x{ref_h}")]
    SizeMismatch { ref_w: u32, ref_h: u32, test_w: u32, test_h: u32 },
    #[error("the images hold no pixels")]
    Empty,
    #[error("the {0} render has no per-pixel outputs (render it with AOVs)")]
    NoAovs(&'static str),
    #[error("an image's pixel or output count does not match its size")]
    Inconsistent,
}

fn check_sizes(reference: &render_spec::Image, test: &render_spec::Image) -> Result<usize, MetricsError> {
    if (reference.width, reference.height) != (test.width, test.height) {
        return Err(MetricsError::SizeMismatch {
            ref_w: reference.width,
            ref_h: reference.height,
            test_w: test.width,
            test_h: test.height,
        });
    }
    let n = reference.width as usize * reference.height as usize;
    if n == 0 {
        return Err(MetricsError::Empty);
    }
    if reference.rgb.len() != n || test.rgb.len() != n {
        return Err(MetricsError::Inconsistent);
    }
    Ok(n)
}
