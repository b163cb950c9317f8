//! What both tracers mean identically, defined once: the render [`Settings`] with their [`Mode`]
//! and [`Accuracy`] ([`accuracy`]: triangle test, ray offset, samples per pixel, bounce cutoff),
//! the vertex form both read ([`Vertices`]), the [`RenderError`]s both report, the [`Image`] with its [`Aovs`] and [`RayCounts`], the
//! camera's primary rays ([`camera`]), the adaptive bounce stop ([`bounce`]), the Phong power ([`power`]), sample sequences
//! ([`sequence`]) and the numeric constants of the shading contract ([`constants`], with the WGSL
//! header the Vulkan kernels are prepended with).
//!
//! The shading definition itself is `docs/shading.md`. Dependency direction: the tracers depend on
//! this crate, this crate on `bvh-format` (for lights, materials and stored cameras).

pub mod accuracy;
pub mod bounce;
pub mod camera;
pub mod constants;
mod error;
mod image;
pub mod power;
pub mod sequence;
mod settings;

pub use accuracy::{Accuracy, Intersect, Offset};
pub use bounce::BounceStop;
pub use camera::{CameraSpec, Frame};
pub use constants::NO_TRIANGLE;
pub use error::RenderError;
pub use image::{Aovs, Image, PrimDiff, RayCounts, SelfHits};
pub use power::phong_pow;
pub use settings::{Ao, MAX_AO_SAMPLES, MAX_INDIRECTIONS, Mode, Settings, Vertices};
