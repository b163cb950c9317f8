//! The driver's acceleration structures for rt-pipeline: one bottom-level structure over the file's
//! triangles, in the file's order (so the primitive index a hit reports is the file's triangle
//! index, the one the stage kernels read `tris`, `normal_indices` and `input_index` with), and one
//! instance of it, untransformed, in a top-level structure.
//!
//! The build is timed with GPU timestamps, bottom and top level apart, to stand beside bvhc's build
//! time. The vertices are copied to device-local memory before the first timestamp, so the times are
//! the driver's builders alone. No compaction: it saves memory, not tracing time, and would add a
//! second build-like pass to the measured time.

use ash::vk;
use bvh_format::Triangle;

use super::{DEVICE_LOCAL, HOST_WRITTEN, Properties, RawBuffer, barrier};
use crate::device::Gpu;
use crate::error::VkError;

/// Bytes of one vertex as `bvh_format::Triangle` stores it (a vec3 and a padding word): the
/// vertex stride of the geometry, read straight from the kernels' triangle array.
const VERTEX_STRIDE: u64 = 16;
/// Bytes of a VkAccelerationStructureInstanceKHR.
const INSTANCE_BYTES: usize = 64;

/// What the build took, from GPU timestamps (NaN where the queue has none), and the sizes the
/// driver asked for.
#[derive(Clone, Copy, Debug)]
pub struct BuildReport {
    pub bottom_ms: f64,
    pub top_ms: f64,
    pub bottom_bytes: u64,
    pub top_bytes: u64,
    pub scratch_bytes: u64,
}

/// The two structures and the memory they live in. Freed on drop.
pub struct Accel {
    loader: ash::khr::acceleration_structure::Device,
    bottom: vk::AccelerationStructureKHR,
    top: vk::AccelerationStructureKHR,
    _bottom_memory: RawBuffer,
    _top_memory: RawBuffer,
    pub report: BuildReport,
}

impl Accel {
    /// Builds both structures over `tris` (the kernels' triangle array) and waits for the build.
    pub fn build(gpu: &Gpu, props: &Properties, tris: &[Triangle]) -> Result<Accel, VkError> {
        let count = tris.len() as u64;
        if count > props.max_primitive_count || count > u32::MAX as u64 / 3 {
            return Err(VkError::Unsupported(format!(
                "the scene's {count} triangles are more than the {} one acceleration structure of {} may hold",
                props.max_primitive_count,
                gpu.info().name
            )));
        }
        let loader = ash::khr::acceleration_structure::Device::new(gpu.instance(), gpu.ash_device());
        let input = vk::BufferUsageFlags::ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_KHR
            | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS
            | vk::BufferUsageFlags::TRANSFER_DST;
        let vertex_bytes: &[u8] = bytemuck::cast_slice(tris);
        let vertices = RawBuffer::new(gpu, vertex_bytes.len() as u64, input, &DEVICE_LOCAL, "rt vertices")?;
        let instances = RawBuffer::new(gpu, INSTANCE_BYTES as u64, input, &DEVICE_LOCAL, "rt instance")?;
        let staging = RawBuffer::new(
            gpu,
            (vertex_bytes.len() + INSTANCE_BYTES) as u64,
            vk::BufferUsageFlags::TRANSFER_SRC,
            &HOST_WRITTEN[1..],
            "rt staging",
        )?;

        // Bottom level: triangles, opaque (no any-hit stage runs), no index buffer.
        let triangles = vk::AccelerationStructureGeometryTrianglesDataKHR::default()
            .vertex_format(vk::Format::R32G32B32_SFLOAT)
            .vertex_data(vk::DeviceOrHostAddressConstKHR { device_address: vertices.address })
            .vertex_stride(VERTEX_STRIDE)
            .max_vertex((3 * count).saturating_sub(1) as u32)
            .index_type(vk::IndexType::NONE_KHR);
        let bottom_geometry = [vk::AccelerationStructureGeometryKHR::default()
            .geometry_type(vk::GeometryTypeKHR::TRIANGLES)
            .geometry(vk::AccelerationStructureGeometryDataKHR { triangles })
            .flags(vk::GeometryFlagsKHR::OPAQUE)];
        let mut bottom_info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
            .ty(vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL)
            .flags(vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE)
            .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
            .geometries(&bottom_geometry);
        let bottom_sizes = sizes(&loader, &bottom_info, count as u32);

        let instance_data = vk::AccelerationStructureGeometryInstancesDataKHR::default()
            .array_of_pointers(false)
            .data(vk::DeviceOrHostAddressConstKHR { device_address: instances.address });
        let top_geometry = [vk::AccelerationStructureGeometryKHR::default()
            .geometry_type(vk::GeometryTypeKHR::INSTANCES)
            .geometry(vk::AccelerationStructureGeometryDataKHR { instances: instance_data })
            .flags(vk::GeometryFlagsKHR::OPAQUE)];
        let mut top_info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
            .ty(vk::AccelerationStructureTypeKHR::TOP_LEVEL)
            .flags(vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE)
            .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
            .geometries(&top_geometry);
        let top_sizes = sizes(&loader, &top_info, 1);

        let storage =
            vk::BufferUsageFlags::ACCELERATION_STRUCTURE_STORAGE_KHR | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS;
        let bottom_memory =
            RawBuffer::new(gpu, bottom_sizes.acceleration_structure_size, storage, &DEVICE_LOCAL, "rt bottom level")?;
        let top_memory =
            RawBuffer::new(gpu, top_sizes.acceleration_structure_size, storage, &DEVICE_LOCAL, "rt top level")?;
        // Null handles until created: a failure drops `accel`, which destroys what was made.
        let mut accel = Accel {
            loader,
            bottom: vk::AccelerationStructureKHR::null(),
            top: vk::AccelerationStructureKHR::null(),
            _bottom_memory: bottom_memory,
            _top_memory: top_memory,
            report: BuildReport { bottom_ms: 0.0, top_ms: 0.0, bottom_bytes: 0, top_bytes: 0, scratch_bytes: 0 },
        };
        accel.bottom = accel.create(&accel._bottom_memory, bottom_sizes.acceleration_structure_size, true)?;
        accel.top = accel.create(&accel._top_memory, top_sizes.acceleration_structure_size, false)?;

        // One scratch buffer serves both builds (a barrier separates them), its address aligned
        // as the device asks.
        let align = props.min_scratch_offset_alignment.max(1) as u64;
        let scratch_bytes = bottom_sizes.build_scratch_size.max(top_sizes.build_scratch_size);
        let scratch = RawBuffer::new(
            gpu,
            scratch_bytes + align,
            vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            &DEVICE_LOCAL,
            "rt scratch",
        )?;
        let scratch_address = scratch.address.next_multiple_of(align);
        bottom_info = bottom_info
            .dst_acceleration_structure(accel.bottom)
            .scratch_data(vk::DeviceOrHostAddressKHR { device_address: scratch_address });
        top_info = top_info
            .dst_acceleration_structure(accel.top)
            .scratch_data(vk::DeviceOrHostAddressKHR { device_address: scratch_address });

        // SAFETY: a live structure of this device.
        let bottom_address = unsafe {
            accel.loader.get_acceleration_structure_device_address(
                &vk::AccelerationStructureDeviceAddressInfoKHR::default().acceleration_structure(accel.bottom),
            )
        };
        let mut upload = Vec::with_capacity(vertex_bytes.len() + INSTANCE_BYTES);
        upload.extend_from_slice(vertex_bytes);
        upload.extend_from_slice(&instance_record(bottom_address));
        staging.write(&upload)?;

        let device = gpu.ash_device();
        let loader = &accel.loader;
        let bottom_range = [vk::AccelerationStructureBuildRangeInfoKHR::default().primitive_count(count as u32)];
        let top_range = [vk::AccelerationStructureBuildRangeInfoKHR::default().primitive_count(1)];
        let build = vk::PipelineStageFlags::ACCELERATION_STRUCTURE_BUILD_KHR;
        let as_rw =
            vk::AccessFlags::ACCELERATION_STRUCTURE_READ_KHR | vk::AccessFlags::ACCELERATION_STRUCTURE_WRITE_KHR;
        let timings = gpu.run(|rec| {
            let cmd = rec.raw();
            // SAFETY: `cmd` is recording; every buffer and structure outlives the run, which waits.
            unsafe {
                device.cmd_copy_buffer(
                    cmd,
                    staging.buffer,
                    vertices.buffer,
                    &[vk::BufferCopy { src_offset: 0, dst_offset: 0, size: vertex_bytes.len().max(1) as u64 }],
                );
                device.cmd_copy_buffer(
                    cmd,
                    staging.buffer,
                    instances.buffer,
                    &[vk::BufferCopy {
                        src_offset: vertex_bytes.len() as u64,
                        dst_offset: 0,
                        size: INSTANCE_BYTES as u64,
                    }],
                );
                barrier(
                    device,
                    cmd,
                    (vk::PipelineStageFlags::TRANSFER, vk::AccessFlags::TRANSFER_WRITE),
                    (build, vk::AccessFlags::SHADER_READ | as_rw),
                );
            }
            rec.mark("start");
            // SAFETY: as above; the build infos point at live geometry arrays.
            unsafe {
                loader.cmd_build_acceleration_structures(cmd, &[bottom_info], &[&bottom_range[..]]);
                // The top level reads the bottom one, and the builds share the scratch buffer.
                barrier(device, cmd, (build, as_rw), (build, as_rw));
            }
            rec.mark("bottom level");
            // SAFETY: as above.
            unsafe {
                loader.cmd_build_acceleration_structures(cmd, &[top_info], &[&top_range[..]]);
                barrier(
                    device,
                    cmd,
                    (build, as_rw),
                    (vk::PipelineStageFlags::RAY_TRACING_SHADER_KHR, vk::AccessFlags::ACCELERATION_STRUCTURE_READ_KHR),
                );
            }
            rec.mark("top level");
            Ok(())
        })?;
        accel.report = BuildReport {
            bottom_ms: timings.get("bottom level").unwrap_or(f64::NAN),
            top_ms: timings.get("top level").unwrap_or(f64::NAN),
            bottom_bytes: bottom_sizes.acceleration_structure_size,
            top_bytes: top_sizes.acceleration_structure_size,
            scratch_bytes,
        };
        Ok(accel)
    }

    pub fn top(&self) -> vk::AccelerationStructureKHR {
        self.top
    }

    fn create(&self, memory: &RawBuffer, size: u64, bottom: bool) -> Result<vk::AccelerationStructureKHR, VkError> {
        let ty = if bottom {
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL
        } else {
            vk::AccelerationStructureTypeKHR::TOP_LEVEL
        };
        let info = vk::AccelerationStructureCreateInfoKHR::default().buffer(memory.buffer).size(size).ty(ty);
        // SAFETY: `memory` has acceleration-structure storage usage and at least `size` bytes.
        unsafe { self.loader.create_acceleration_structure(&info, None) }
            .map_err(|e| VkError::vk("vkCreateAccelerationStructureKHR", e))
    }
}

impl Drop for Accel {
    fn drop(&mut self) {
        // SAFETY: the runs that used the structures were waited for; null handles are ignored.
        unsafe {
            self.loader.destroy_acceleration_structure(self.top, None);
            self.loader.destroy_acceleration_structure(self.bottom, None);
        }
    }
}

/// The memory a build of `info` over `primitives` primitives needs.
fn sizes(
    loader: &ash::khr::acceleration_structure::Device,
    info: &vk::AccelerationStructureBuildGeometryInfoKHR<'_>,
    primitives: u32,
) -> vk::AccelerationStructureBuildSizesInfoKHR<'static> {
    let mut sizes = vk::AccelerationStructureBuildSizesInfoKHR::default();
    // SAFETY: a valid build info with one geometry.
    unsafe {
        loader.get_acceleration_structure_build_sizes(
            vk::AccelerationStructureBuildTypeKHR::DEVICE,
            info,
            &[primitives],
            &mut sizes,
        )
    };
    sizes
}

/// The one instance (VkAccelerationStructureInstanceKHR): the identity transform, custom index 0,
/// mask 0xff, hit group 0, culling off (our triangle test is two-sided) and forced opaque.
fn instance_record(bottom_address: vk::DeviceAddress) -> [u8; INSTANCE_BYTES] {
    let mut words = [0u32; 16];
    // The 3 x 4 row-major transform's diagonal.
    for w in [0, 5, 10] {
        words[w] = 1f32.to_bits();
    }
    words[12] = 0xff << 24;
    let flags = vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE | vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE;
    words[13] = (flags.as_raw() & 0xff) << 24;
    words[14] = bottom_address as u32;
    words[15] = (bottom_address >> 32) as u32;
    let mut out = [0u8; INSTANCE_BYTES];
    for (chunk, w) in out.chunks_exact_mut(4).zip(words) {
        chunk.copy_from_slice(&w.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The instance record against ash's own struct, field by field.
    #[test]
    fn the_instance_record_has_vulkans_layout() {
        assert_eq!(size_of::<vk::AccelerationStructureInstanceKHR>(), INSTANCE_BYTES);
        let address = 0x1234_5678_9abc_def0u64;
        let bytes = instance_record(address);
        let word = |k: usize| u32::from_le_bytes(bytes[4 * k..4 * k + 4].try_into().unwrap());
        let f = |k: usize| f32::from_bits(word(k));
        let transform: Vec<f32> = (0..12).map(f).collect();
        assert_eq!(transform, [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
        assert_eq!(word(12), vk::Packed24_8::new(0, 0xff).low_24() | (0xff << 24));
        let flags =
            vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE | vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE;
        let packed = vk::Packed24_8::new(0, flags.as_raw() as u8);
        assert_eq!(packed.high_8() as u32, word(13) >> 24);
        assert_eq!(word(13) & 0xff_ffff, 0, "hit group record 0");
        assert_eq!(word(14) as u64 | (word(15) as u64) << 32, address);
        // The reference field sits at byte 56, as ash lays the struct out.
        assert_eq!(std::mem::offset_of!(vk::AccelerationStructureInstanceKHR, acceleration_structure_reference), 56);
    }

    #[test]
    fn the_vertex_stride_reads_the_kernels_triangles() {
        assert_eq!(std::mem::offset_of!(Triangle, p1) as u64, VERTEX_STRIDE);
        assert_eq!(std::mem::offset_of!(Triangle, p2) as u64, 2 * VERTEX_STRIDE);
        assert_eq!(size_of::<Triangle>() as u64, 3 * VERTEX_STRIDE);
    }
}
