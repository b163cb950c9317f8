//! Scene import and the SAH builders.
//!
//! - [`import`]: OBJ (tobj) and glTF/GLB (gltf) into a [`Scene`], and scene descriptions (TOML)
//!   that place several meshes, generated shapes, cameras and lights.
//! - [`build`]: the top-down builder shared by [`binned`] (Wald's binned SAH) and [`sweep`]
//!   (full-sweep SAH, the quality reference), and the reinsertion in the top of the finished
//!   tree that both get (`top`).
//! - [`compile()`]: a [`Scene`] into a validated [`bvh_format::SceneFile`].

pub mod binned;
pub mod build;
mod compile;
pub mod import;
mod isa;
#[cfg(feature = "compare")]
pub mod peers;
pub mod scene;
pub mod sweep;
mod top;
pub mod unit;
mod weld;
pub mod wide;

pub use compile::{
    Layouts, MAX_BINS, build_tree, build_tree_with_progress, check_params, compile, compile_for_writing,
    compile_with_progress,
};
pub use import::{ImportError, ImportOptions};
pub use scene::Scene;

use thiserror::Error;

/// What can go wrong between reading a scene and holding a valid file. One sentence each.
#[derive(Debug, Error)]
pub enum BuildError {
    #[error("the scene has no triangles")]
    Empty,
    #[error("the scene has {0} triangles, more than the format can hold")]
    TooLarge(usize),
    #[error("triangle {triangle} has a coordinate that is not a finite number")]
    NonFinite { triangle: usize },
    #[error("invalid build parameters: {0}")]
    Params(String),
    #[error("the compiled scene failed validation: {0}")]
    Invalid(bvh_format::FormatError),
    #[error(
        "the scene's largest coordinate is {largest:e}, below the smallest normal f32 (1.2e-38), so its coordinates have already lost precision; scale the scene up"
    )]
    Unrepresentable { largest: f32 },
    #[error(
        "{what} lies {distance:e} units from the scene's origin, beyond f32's range once the scene (largest coordinate {largest:e}) is stored in units of 2^{scale_log2}; move it nearer"
    )]
    BeyondRange { what: String, distance: f32, largest: f32, scale_log2: i32 },
}
