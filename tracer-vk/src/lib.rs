//! The Vulkan compute tracer: LST, SST and stackless traversal (docs/vulkan-tracer.md).
//!
//! - [`device`]: the Vulkan device layer (ash), one concern per file: instance and device choice,
//!   validation, memory and staging, compute pipelines, descriptors, command recording and GPU
//!   timestamps.
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
pub use device::{
    Buffer, BufferDesc, DeviceInfo, DeviceKind, FAULT_VARIABLE, Fault, Gpu, Pipeline, PipelineDesc, Recorder, Timings,
    ValidationLog, list_devices,
};
pub use error::VkError;
pub use shader::{translate, translate_with_subgroups};
