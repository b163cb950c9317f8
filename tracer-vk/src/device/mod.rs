//! The Vulkan device layer: picking a device, storage buffers, compute pipelines made from SPIR-V,
//! and one-shot command recording with GPU timestamps.
//!
//! Everything is synchronous on purpose: [`Gpu::run`] records, submits and waits, so a caller never
//! holds a command buffer or a fence, and a buffer or pipeline can be dropped as soon as `run`
//! returns. The tracer's kernels take milliseconds to seconds, so the lost overlap between
//! submissions does not show in its timings (which come from the timestamps, not the host clock).
//!
//! One Vulkan concern per file. Plain descriptions ([`DeviceInfo`], [`BufferDesc`],
//! [`PipelineDesc`]: sizes, usages, bindings, no handles) are kept apart from the objects that own
//! handles and destroy them in `Drop` ([`Gpu`], [`Buffer`], [`Pipeline`]):
//!
//! | file | concern |
//! |---|---|
//! | `info.rs` | [`DeviceInfo`], [`DeviceKind`]: what a device reports |
//! | `instance.rs` | loader, instance, which physical devices qualify, opening one ([`list_devices`]) |
//! | `validation.rs` | the validation layer and the messenger into a [`ValidationLog`] |
//! | `gpu.rs` | [`Gpu`] and the shared core every buffer and pipeline holds; objects parked after a timeout |
//! | `memory.rs` | [`BufferDesc`], [`Buffer`]: memory types and allocation |
//! | `staging.rs` | uploads and downloads through the host-visible staging buffer |
//! | `pipeline.rs` | [`PipelineDesc`], [`Pipeline`]: shader modules, layouts, compute pipelines |
//! | `descriptors.rs` | descriptor pools and the per-dispatch descriptor sets |
//! | `commands.rs` | command pool, buffer and fence; [`Gpu::run`], [`Recorder`], barriers, timeouts |
//! | `timestamps.rs` | query pools, [`Recorder::mark`], [`Timings`] |
//! | `fault.rs` | [`Fault`]: device loss, out of memory and timeouts simulated for tests |
//!
//! A second kind of pipeline (ray tracing) and acceleration structures are meant to arrive as
//! files of their own beside these, on the same [`Gpu`] core.

mod commands;
mod descriptors;
mod fault;
mod gpu;
mod info;
mod instance;
mod memory;
mod pipeline;
mod staging;
mod timestamps;
mod validation;

pub use commands::Recorder;
pub use fault::{FAULT_VARIABLE, Fault};
pub use gpu::Gpu;
pub use info::{DeviceInfo, DeviceKind};
pub use instance::list_devices;
pub use memory::{Buffer, BufferDesc};
pub use pipeline::{Pipeline, PipelineDesc};
pub use timestamps::Timings;
pub use validation::ValidationLog;
