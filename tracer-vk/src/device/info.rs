//! What the tracer knows about a device: plain values read once when the device is listed or
//! opened, with no Vulkan handles, so they can be copied, printed and compared freely.

use std::fmt;

use ash::vk;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum DeviceKind {
    Discrete,
    Integrated,
    Virtual,
    Cpu,
    Other,
}

impl fmt::Display for DeviceKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            DeviceKind::Discrete => "discrete GPU",
            DeviceKind::Integrated => "integrated GPU",
            DeviceKind::Virtual => "virtual GPU",
            DeviceKind::Cpu => "CPU",
            DeviceKind::Other => "other",
        })
    }
}

impl From<vk::PhysicalDeviceType> for DeviceKind {
    fn from(t: vk::PhysicalDeviceType) -> Self {
        match t {
            vk::PhysicalDeviceType::DISCRETE_GPU => DeviceKind::Discrete,
            vk::PhysicalDeviceType::INTEGRATED_GPU => DeviceKind::Integrated,
            vk::PhysicalDeviceType::VIRTUAL_GPU => DeviceKind::Virtual,
            vk::PhysicalDeviceType::CPU => DeviceKind::Cpu,
            _ => DeviceKind::Other,
        }
    }
}

/// What the tracer needs to know about a device to size its kernels and buffers.
#[derive(Clone, Debug)]
pub struct DeviceInfo {
    /// Position in [`list_devices`](super::list_devices), the number [`Gpu::new`](super::Gpu::new)
    /// takes.
    pub index: usize,
    pub name: String,
    pub kind: DeviceKind,
    /// The version the device is used at: the lower of the device's and the loader's, at most 1.3.
    pub api_version: (u32, u32, u32),
    pub driver: String,
    pub subgroup_size: u32,
    pub max_shared_memory: u32,
    /// Largest range of one storage buffer binding, so also the largest [`Buffer`](super::Buffer).
    pub max_storage_buffer_range: u64,
    pub max_workgroup_invocations: u32,
    pub max_workgroup_size: [u32; 3],
    pub timestamp_period_ns: f32,
    /// Sum of the device-local memory heaps.
    pub device_local_bytes: u64,
    /// Basic, vote, ballot and arithmetic subgroup operations in compute shaders.
    pub supports_subgroup_ops: bool,
    /// Shaders may ask that 32-bit subnormals be kept, not flushed to zero
    /// (`shaderDenormPreserveFloat32`, Vulkan 1.2); `--exact` kernels do where this holds.
    pub denorm_preserve_f32: bool,
    pub max_workgroup_count: [u32; 3],
    pub max_push_constants_size: u32,
    /// Largest single memory allocation (maxMemoryAllocationSize).
    pub max_memory_allocation: u64,
    /// Storage buffers one compute pipeline may bind.
    pub max_storage_buffers: u32,
    /// Whether the compute queue writes timestamps; without them [`Timings`](super::Timings)
    /// holds NaN.
    pub timestamps: bool,
    pub vendor_id: u32,
    pub device_id: u32,
    /// Whether `--method rt-pipeline` runs here (the ray-tracing extensions and features, which
    /// the device is opened with whenever it has them: crate::rt explains why).
    pub rt_pipeline: crate::rt::Support,
}
