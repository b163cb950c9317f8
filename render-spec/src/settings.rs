//! What to render: the settings both tracers take and check alike.

use crate::RenderError;
use crate::accuracy::Accuracy;
use crate::camera::{CameraError, CameraSpec, Frame};
use bvh_format::Light;

/// Ray casting or Whitted ray tracing (docs/shading.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Mode {
    /// One white light at the eye, Lambert only, no shadow or secondary rays.
    Cast,
    /// Coloured point lights with shadow rays, Phong, reflection and refraction.
    Whitted,
}

/// The most indirections a frame may ask for. Paths end earlier in every scene whose reflective
/// and refractive materials lose light; only perfect mirrors facing each other go on to the limit,
/// at a cost that grows with it.
pub const MAX_INDIRECTIONS: u32 = 1024;

/// What to render; how (the traversal method, the device) is each tracer's own choice.
#[derive(Clone, Debug, PartialEq)]
pub struct Settings {
    pub width: u32,
    pub height: u32,
    pub camera: CameraSpec,
    pub mode: Mode,
    /// Lights for Whitted mode (ray casting always uses one white light at the eye).
    pub lights: Vec<Light>,
    /// Longest chain of secondary rays, at most [`MAX_INDIRECTIONS`].
    pub max_indirections: u32,
    /// Return the per-pixel outputs ([`crate::Aovs`]) besides the colour.
    pub aovs: bool,
    /// What the frame trades between accuracy and speed; the default is docs/shading.md.
    pub accuracy: Accuracy,
}

impl Settings {
    /// Checks the image size, the indirections, the accuracy settings and the camera, and
    /// precomputes the camera for this image.
    pub fn frame(&self) -> Result<Frame, RenderError> {
        if self.width == 0 || self.height == 0 {
            return Err(RenderError::EmptyImage);
        }
        if self.max_indirections > MAX_INDIRECTIONS {
            return Err(RenderError::TooManyIndirections(self.max_indirections));
        }
        self.accuracy.check()?;
        self.camera.frame(self.width, self.height).map_err(|e| match e {
            CameraError::Degenerate => RenderError::DegenerateCamera,
            CameraError::FieldOfView => RenderError::FieldOfView(self.camera.fov_deg),
        })
    }

    /// Pixels of the image.
    pub fn pixels(&self) -> u64 {
        self.width as u64 * self.height as u64
    }
}
