//! The Vulkan compute tracer: LST, SST and stackless traversal (docs/vulkan-tracer.md).
//!
//! - [`device`]: the Vulkan device layer (ash): devices, buffers, compute pipelines, recording
//!   dispatches and reading back GPU timestamps.
//! - [`shader`]: WGSL kernels to SPIR-V with naga, overrides resolved in the program.
//! - [`no_contraction`]: the `--exact` pass, SPIR-V whose float operations may not be fused.
//! - [`error`]: [`VkError`], one sentence per failure.
//!
//! The kernels and the traversals are built on top of these.

pub mod device;
pub mod error;
pub mod kernels;
pub mod no_contraction;
pub mod render;
pub mod rt;
pub mod shader;
pub mod tiles;

/// The ash version the raw handles ([`Gpu::ash_device`], [`Recorder::raw`]) come from.
pub use ash;
pub use device::{Buffer, DeviceInfo, DeviceKind, Gpu, Pipeline, Recorder, Timings, ValidationLog, list_devices};
pub use error::VkError;
pub use shader::{translate, translate_with_subgroups};
