//! `--method rt-pipeline`: the GPU vendor's own traversal as a peer of LST, SST and stackless.
//!
//! The driver builds its acceleration structures from the file's triangles ([`accel`]: one
//! bottom-level structure whose primitive `i` is the file's triangle `i`, one instance of it in a
//! top-level structure) and traces them in a VK_KHR_ray_tracing_pipeline ([`pipeline`]) whose three
//! stages ([`spirv`], written with rspirv, as naga writes no ray-tracing stages) do nothing but read
//! a ray record and write a hit record. Ray generation and shading stay in the WGSL stage kernels,
//! split around the trace (rt_pipeline.wgsl), so what differs from the other methods is the
//! traversal and nothing else.
//!
//! The method needs VK_KHR_acceleration_structure, VK_KHR_ray_tracing_pipeline (and
//! VK_KHR_deferred_host_operations, which the first requires) and the bufferDeviceAddress feature of
//! Vulkan 1.2. Devices are opened with them whenever they have them ([`Support`]): one device then
//! serves every method of a `trace-vk bench` run under the same settings, and enabling them changes
//! nothing for the compute kernels.

pub mod accel;
pub mod pipeline;
pub mod spirv;

use std::ffi::CStr;

use ash::vk;

use crate::device::Gpu;
use crate::error::VkError;

/// The device extensions rt-pipeline needs.
pub const EXTENSIONS: [&CStr; 3] = [
    ash::khr::acceleration_structure::NAME,
    ash::khr::ray_tracing_pipeline::NAME,
    ash::khr::deferred_host_operations::NAME,
];

/// Whether a device can run rt-pipeline, and the limits its shader binding table follows.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Support {
    Supported(Properties),
    /// What the device lacks, as a phrase: "VK_KHR_acceleration_structure and
    /// VK_KHR_ray_tracing_pipeline".
    Missing(String),
}

impl Support {
    pub fn is_supported(&self) -> bool {
        matches!(self, Support::Supported(_))
    }
}

/// The device's ray-tracing limits that the structures and the shader binding table depend on.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Properties {
    pub shader_group_handle_size: u32,
    pub shader_group_handle_alignment: u32,
    pub shader_group_base_alignment: u32,
    pub max_shader_group_stride: u32,
    pub max_ray_recursion_depth: u32,
    pub min_scratch_offset_alignment: u32,
    pub max_primitive_count: u64,
}

/// The features rt-pipeline enables, chained into the device's create info.
pub(crate) struct Features {
    pub v12: vk::PhysicalDeviceVulkan12Features<'static>,
    pub accel: vk::PhysicalDeviceAccelerationStructureFeaturesKHR<'static>,
    pub pipeline: vk::PhysicalDeviceRayTracingPipelineFeaturesKHR<'static>,
}

impl Features {
    /// Exactly what the method uses: device addresses, acceleration structures, the pipeline.
    pub fn wanted() -> Self {
        Features {
            v12: vk::PhysicalDeviceVulkan12Features::default().buffer_device_address(true),
            accel: vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default().acceleration_structure(true),
            pipeline: vk::PhysicalDeviceRayTracingPipelineFeaturesKHR::default().ray_tracing_pipeline(true),
        }
    }
}

/// Asks a physical device whether it can run rt-pipeline. `api` is the version it is used at.
///
/// SAFETY: `physical` belongs to `instance`.
pub(crate) unsafe fn query_support(instance: &ash::Instance, physical: vk::PhysicalDevice, api: u32) -> Support {
    // SAFETY: plain queries on a live physical device.
    let available = unsafe { instance.enumerate_device_extension_properties(physical) }.unwrap_or_default();
    let has = |name: &CStr| available.iter().any(|e| e.extension_name_as_c_str() == Ok(name));
    let mut missing: Vec<String> =
        EXTENSIONS.iter().filter(|e| !has(e)).map(|e| e.to_string_lossy().into_owned()).collect();
    if api < vk::API_VERSION_1_2 {
        missing.insert(0, "Vulkan 1.2".to_string());
    }
    if !missing.is_empty() {
        return Support::Missing(join(&missing));
    }
    let mut v12 = vk::PhysicalDeviceVulkan12Features::default();
    let mut accel = vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default();
    let mut rt = vk::PhysicalDeviceRayTracingPipelineFeaturesKHR::default();
    let mut features =
        vk::PhysicalDeviceFeatures2::default().push_next(&mut v12).push_next(&mut accel).push_next(&mut rt);
    // SAFETY: the structures chained are known to a Vulkan 1.2 device with these extensions.
    unsafe { instance.get_physical_device_features2(physical, &mut features) };
    for (present, name) in [
        (v12.buffer_device_address, "the bufferDeviceAddress feature"),
        (accel.acceleration_structure, "the accelerationStructure feature"),
        (rt.ray_tracing_pipeline, "the rayTracingPipeline feature"),
    ] {
        if present != vk::TRUE {
            missing.push(name.to_string());
        }
    }
    if !missing.is_empty() {
        return Support::Missing(join(&missing));
    }
    let mut rt_props = vk::PhysicalDeviceRayTracingPipelinePropertiesKHR::default();
    let mut accel_props = vk::PhysicalDeviceAccelerationStructurePropertiesKHR::default();
    let mut props = vk::PhysicalDeviceProperties2::default().push_next(&mut rt_props).push_next(&mut accel_props);
    // SAFETY: as above.
    unsafe { instance.get_physical_device_properties2(physical, &mut props) };
    Support::Supported(Properties {
        shader_group_handle_size: rt_props.shader_group_handle_size,
        shader_group_handle_alignment: rt_props.shader_group_handle_alignment,
        shader_group_base_alignment: rt_props.shader_group_base_alignment,
        max_shader_group_stride: rt_props.max_shader_group_stride,
        max_ray_recursion_depth: rt_props.max_ray_recursion_depth,
        min_scratch_offset_alignment: accel_props.min_acceleration_structure_scratch_offset_alignment,
        max_primitive_count: accel_props.max_primitive_count,
    })
}

/// "a", "a and b", "a, b and c".
fn join(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [rest @ .., last] => format!("{} and {last}", rest.join(", ")),
    }
}

/// The sentence that refuses rt-pipeline on a device without it.
pub fn refusal(device: &str, missing: &str) -> String {
    format!(
        "--method rt-pipeline needs {missing}, which {device} does not offer (`trace-vk devices` says which devices \
         support it)"
    )
}

/// The properties of a device that supports rt-pipeline, else the refusal.
pub fn properties(gpu: &Gpu) -> Result<Properties, VkError> {
    match &gpu.info().rt_pipeline {
        Support::Supported(p) => Ok(*p),
        Support::Missing(m) => Err(VkError::Unsupported(refusal(&gpu.info().name, m))),
    }
}

/// rt-pipeline's part of a renderer: the structures, the pipeline and the per-pixel ray and hit
/// records the split stage kernels exchange with it.
pub struct RtTracer {
    // Before `accel`: the pipeline's descriptor set names the top-level structure.
    pipeline: pipeline::RtPipeline,
    accel: accel::Accel,
}

impl RtTracer {
    /// Builds the structures over `tris` (the kernels' triangle array, in the file's order) and the
    /// pipeline; refuses a device without rt-pipeline in one sentence.
    pub fn new(gpu: &Gpu, tris: &[bvh_format::Triangle]) -> Result<RtTracer, VkError> {
        let props = properties(gpu)?;
        let accel = accel::Accel::build(gpu, &props, tris)?;
        let pipeline = pipeline::RtPipeline::new(gpu, &props, accel.top())?;
        Ok(RtTracer { pipeline, accel })
    }

    /// What the driver's build took.
    pub fn build_report(&self) -> accel::BuildReport {
        self.accel.report
    }

    /// Traces the ray records in `rays` into the hit records in `hits` from now on (the
    /// per-pixel buffers of the split kernels, bindings 14 and 15). Not while a run is recorded.
    pub fn bind_records(&self, rays: &crate::device::Buffer, hits: &crate::device::Buffer) {
        self.pipeline.bind_records(rays, hits);
    }

    /// Records the trace of a tile's ray records into its hit records.
    pub fn record_trace(&self, rec: &mut crate::device::Recorder, width: u32, height: u32) {
        self.pipeline.record_trace(rec, width, height);
    }
}

/// A buffer of the rt-pipeline's own (device addresses, acceleration-structure storage, the shader
/// binding table), which [`crate::device::Buffer`] does not make. Freed on drop.
pub(crate) struct RawBuffer {
    device: ash::Device,
    pub buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    pub size: u64,
    /// The buffer's device address (0 without SHADER_DEVICE_ADDRESS usage).
    pub address: vk::DeviceAddress,
    /// The host mapping of a host-visible buffer.
    mapped: Option<*mut u8>,
}

impl RawBuffer {
    /// A buffer of `size` bytes in memory with the first of `wanted` property sets the device has.
    pub fn new(
        gpu: &Gpu,
        size: u64,
        usage: vk::BufferUsageFlags,
        wanted: &[vk::MemoryPropertyFlags],
        label: &str,
    ) -> Result<RawBuffer, VkError> {
        let device = gpu.ash_device().clone();
        let size = size.max(16);
        let info = vk::BufferCreateInfo::default().size(size).usage(usage).sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid create info; `b` is dropped (destroying what was made) on every failure.
        let buffer = unsafe { device.create_buffer(&info, None) }
            .map_err(|e| VkError::alloc("vkCreateBuffer", e, label, size))?;
        let mut b = RawBuffer { device, buffer, memory: vk::DeviceMemory::null(), size, address: 0, mapped: None };
        // SAFETY: `buffer` is live.
        let req = unsafe { b.device.get_buffer_memory_requirements(buffer) };
        let memory = gpu.memory_properties();
        let types = &memory.memory_types[..memory.memory_type_count as usize];
        let type_index = wanted
            .iter()
            .find_map(|&flags| {
                (0..types.len() as u32)
                    .find(|&i| req.memory_type_bits & (1 << i) != 0 && types[i as usize].property_flags.contains(flags))
            })
            .ok_or_else(|| VkError::OutOfDeviceMemory { label: label.to_string(), bytes: size })?;
        let addressed = usage.contains(vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS);
        let mut flags = vk::MemoryAllocateFlagsInfo::default().flags(vk::MemoryAllocateFlags::DEVICE_ADDRESS);
        let mut alloc = vk::MemoryAllocateInfo::default().allocation_size(req.size).memory_type_index(type_index);
        if addressed {
            alloc = alloc.push_next(&mut flags);
        }
        // SAFETY: valid allocate info; bound once to a fresh buffer.
        unsafe {
            b.memory = b
                .device
                .allocate_memory(&alloc, None)
                .map_err(|e| VkError::alloc("vkAllocateMemory", e, label, size))?;
            b.device
                .bind_buffer_memory(buffer, b.memory, 0)
                .map_err(|e| VkError::alloc("vkBindBufferMemory", e, label, size))?;
            if addressed {
                b.address = b.device.get_buffer_device_address(&vk::BufferDeviceAddressInfo::default().buffer(buffer));
            }
            if types[type_index as usize].property_flags.contains(vk::MemoryPropertyFlags::HOST_VISIBLE) {
                let ptr = b
                    .device
                    .map_memory(b.memory, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
                    .map_err(|e| VkError::alloc("vkMapMemory", e, label, size))?;
                b.mapped = Some(ptr.cast());
            }
        }
        Ok(b)
    }

    /// Copies `data` to the start of a host-visible, host-coherent buffer.
    pub fn write(&self, data: &[u8]) -> Result<(), VkError> {
        match self.mapped {
            Some(ptr) if data.len() as u64 <= self.size => {
                // SAFETY: the mapping covers `size` bytes and no GPU work uses the buffer now.
                unsafe { std::ptr::copy_nonoverlapping(data.as_ptr(), ptr, data.len()) };
                Ok(())
            }
            _ => Err(VkError::Usage(format!(
                "{} bytes cannot be written into a {}-byte buffer that is not host-visible or too small",
                data.len(),
                self.size
            ))),
        }
    }
}

impl Drop for RawBuffer {
    fn drop(&mut self) {
        // SAFETY: every submission that used the buffer was waited for (Gpu::run is synchronous).
        unsafe {
            self.device.destroy_buffer(self.buffer, None);
            if self.memory != vk::DeviceMemory::null() {
                self.device.free_memory(self.memory, None);
            }
        }
    }
}

/// The memory a buffer the GPU alone uses should live in, best first.
pub(crate) const DEVICE_LOCAL: [vk::MemoryPropertyFlags; 2] =
    [vk::MemoryPropertyFlags::DEVICE_LOCAL, vk::MemoryPropertyFlags::empty()];

/// Host-written memory, device-local where the device maps some.
pub(crate) const HOST_WRITTEN: [vk::MemoryPropertyFlags; 2] = [
    vk::MemoryPropertyFlags::from_raw(
        vk::MemoryPropertyFlags::DEVICE_LOCAL.as_raw()
            | vk::MemoryPropertyFlags::HOST_VISIBLE.as_raw()
            | vk::MemoryPropertyFlags::HOST_COHERENT.as_raw(),
    ),
    vk::MemoryPropertyFlags::from_raw(
        vk::MemoryPropertyFlags::HOST_VISIBLE.as_raw() | vk::MemoryPropertyFlags::HOST_COHERENT.as_raw(),
    ),
];

/// A barrier between two pipeline stages, the way the device layer orders its dispatches.
///
/// SAFETY: `cmd` is recording.
pub(crate) unsafe fn barrier(
    device: &ash::Device,
    cmd: vk::CommandBuffer,
    src: (vk::PipelineStageFlags, vk::AccessFlags),
    dst: (vk::PipelineStageFlags, vk::AccessFlags),
) {
    let mb = vk::MemoryBarrier::default().src_access_mask(src.1).dst_access_mask(dst.1);
    unsafe { device.cmd_pipeline_barrier(cmd, src.0, dst.0, vk::DependencyFlags::empty(), &[mb], &[], &[]) };
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_refusal_is_one_sentence_naming_what_is_missing() {
        let s =
            refusal("llvmpipe", &join(&["VK_KHR_acceleration_structure".into(), "VK_KHR_ray_tracing_pipeline".into()]));
        assert_eq!(
            s,
            "--method rt-pipeline needs VK_KHR_acceleration_structure and VK_KHR_ray_tracing_pipeline, which llvmpipe \
             does not offer (`trace-vk devices` says which devices support it)"
        );
        assert!(!s.contains('\n') && !s.ends_with('.'));
        assert_eq!(join(&["a".into(), "b".into(), "c".into()]), "a, b and c");
    }
}
