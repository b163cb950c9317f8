//! What to render: the settings both tracers take and check alike.

use crate::RenderError;
use crate::accuracy::Accuracy;
use crate::camera::{CameraError, CameraSpec, Frame};
use bvh_format::{Light, SceneFile};

/// Ray casting, Whitted ray tracing, or one of the incoherent modes (docs/shading.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Mode {
    /// One white light at the eye, Lambert only, no shadow or secondary rays.
    Cast,
    /// Coloured point lights with shadow rays, Phong, reflection and refraction.
    Whitted,
    /// Ambient occlusion: the fraction of cosine-distributed rays of a fixed length that leave
    /// each primary hit unblocked.
    Ao(Ao),
    /// One cosine-distributed bounce of full length per primary hit.
    Diffuse,
}

impl Mode {
    /// The name `--mode` takes.
    pub fn name(self) -> &'static str {
        match self {
            Mode::Cast => "cast",
            Mode::Whitted => "whitted",
            Mode::Ao(_) => "ao",
            Mode::Diffuse => "diffuse",
        }
    }
}

/// How a tracer reads the corners of a triangle (`--vertices`), a trade of memory for reads: both
/// forms give the same bits, so the same images and hit counts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Vertices {
    /// Three vertices per triangle in leaf order, each padded to 16 bytes with the material in
    /// the first padding word: 48 bytes per triangle held (CPU) or uploaded (GPU) beside the
    /// file's indexed form, three 16-byte reads.
    #[default]
    Expanded,
    /// The file's indexed form: per triangle three vertex indices and the material, then every
    /// vertex once: one read more per triangle, through the index, and no copy of its own (the
    /// GPU uploads 16 bytes per triangle and per vertex; about half the memory of a closed mesh,
    /// where a vertex is shared by about six triangles).
    Indexed,
}

impl Vertices {
    /// The name `--vertices` takes.
    pub fn name(self) -> &'static str {
        match self {
            Vertices::Expanded => "expanded",
            Vertices::Indexed => "indexed",
        }
    }
}

/// The rays of ambient occlusion (`--ao-samples`, `--ao-length`).
#[derive(Clone, Copy, Debug)]
pub struct Ao {
    /// Rays per primary hit, 1 to [`MAX_AO_SAMPLES`].
    pub samples: u32,
    /// Their length as a fraction of the diagonal of the scene's bounding box (finite, above 0).
    pub length: f32,
}

/// The most AO rays per primary hit.
pub const MAX_AO_SAMPLES: u32 = 1024;

impl Default for Ao {
    /// 8 rays of 10% of the scene's diagonal, issue 10's setting.
    fn default() -> Self {
        Self { samples: 8, length: 0.1 }
    }
}

/// Equal when both fields have the same bits (a setting, not a number to compare).
impl PartialEq for Ao {
    fn eq(&self, o: &Self) -> bool {
        self.samples == o.samples && self.length.to_bits() == o.length.to_bits()
    }
}

impl Eq for Ao {}

impl std::hash::Hash for Ao {
    fn hash<H: std::hash::Hasher>(&self, h: &mut H) {
        (self.samples, self.length.to_bits()).hash(h)
    }
}

impl Ao {
    /// Checks the ray count and the length.
    pub fn check(&self) -> Result<(), RenderError> {
        if self.samples == 0 || self.samples > MAX_AO_SAMPLES {
            return Err(RenderError::AoSamples(self.samples));
        }
        if !(self.length.is_finite() && self.length > 0.0) {
            return Err(RenderError::AoLength(self.length));
        }
        Ok(())
    }

    /// The rays' length in scene units: [`Self::length`] times the diagonal of the box
    /// `lo..hi` (the scene's bounds), in f64, rounded once to f32 (the largest finite f32 where
    /// it would overflow). Both tracers take this value from here.
    pub fn distance(&self, lo: [f32; 3], hi: [f32; 3]) -> f32 {
        let diagonal = (0..3).map(|a| (hi[a] as f64 - lo[a] as f64).powi(2)).sum::<f64>().sqrt();
        ((self.length as f64 * diagonal) as f32).min(f32::MAX)
    }

    /// The f32 value of `1 / samples`, by which the open rays are multiplied (a GPU's division
    /// need not be correctly rounded, so the host computes it).
    pub fn inverse(&self) -> f32 {
        1.0 / self.samples.max(1) as f32
    }
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
    /// A `width` x `height` frame of `scene` from `camera` in `mode`, lit by the scene's lights
    /// and with its indirection count, without AOVs and at the default accuracy: what a frame is
    /// unless a caller says otherwise (`Settings { aovs: true, ..Settings::of_scene(..) }`).
    pub fn of_scene(scene: &SceneFile, camera: CameraSpec, mode: Mode, (width, height): (u32, u32)) -> Settings {
        Settings {
            width,
            height,
            camera,
            mode,
            lights: scene.lights.clone(),
            max_indirections: scene.settings.max_indirections,
            aovs: false,
            accuracy: Accuracy::default(),
        }
    }

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
        if let Mode::Ao(ao) = self.mode {
            ao.check()?;
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ao_settings_are_checked_and_measured_on_the_scene() {
        assert_eq!(Ao::default().check(), Ok(()));
        for samples in [0, MAX_AO_SAMPLES + 1, u32::MAX] {
            assert_eq!(Ao { samples, length: 0.1 }.check(), Err(RenderError::AoSamples(samples)));
        }
        for length in [0.0, -0.1, f32::NAN, f32::INFINITY] {
            assert!(matches!(Ao { samples: 1, length }.check(), Err(RenderError::AoLength(_))), "{length}");
        }
        let ao = Ao { samples: 4, length: 0.5 };
        assert_eq!(ao.distance([0.0; 3], [3.0, 4.0, 12.0]), 6.5);
        assert_eq!(ao.distance([1.0; 3], [1.0; 3]), 0.0);
        assert_eq!(Ao { samples: 1, length: 1e30 }.distance([-1e30; 3], [1e30; 3]), f32::MAX);
        assert_eq!(ao.inverse(), 0.25);
        assert_eq!(Mode::Ao(ao), Mode::Ao(Ao { samples: 4, length: 0.5 }));
        assert_ne!(Mode::Ao(ao), Mode::Ao(Ao { samples: 4, length: 0.25 }));
    }
}
