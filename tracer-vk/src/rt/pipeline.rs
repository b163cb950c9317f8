//! The ray-tracing pipeline of rt-pipeline: the three stages of [`super::spirv`] in three shader
//! groups (ray generation, miss, a triangle hit group with the closest-hit stage), their shader
//! binding table, and the descriptor set with the top-level structure and the ray and hit records.

use ash::vk;

use super::spirv::{self, BINDING_HITS, BINDING_RAYS, BINDING_TLAS};
use super::{HOST_WRITTEN, Properties, RawBuffer, barrier};
use crate::device::{Buffer, Gpu, Recorder};
use crate::error::VkError;

/// Where the three shader groups' records lie in the shader binding table.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SbtLayout {
    /// Bytes between records: the handle size rounded up to the handle alignment.
    pub stride: u64,
    /// Offsets of the ray-generation, miss and hit-group records, each a multiple of the base
    /// alignment.
    pub offsets: [u64; 3],
    pub bytes: u64,
}

impl SbtLayout {
    /// The layout Vulkan's rules ask for: every region starts at a multiple of
    /// shaderGroupBaseAlignment, its stride is a multiple of shaderGroupHandleAlignment and at most
    /// maxShaderGroupStride, and the ray-generation region's size equals its stride.
    pub fn new(p: &Properties) -> Result<SbtLayout, VkError> {
        let handle_align = p.shader_group_handle_alignment.max(1) as u64;
        let base = p.shader_group_base_alignment.max(1) as u64;
        let stride = (p.shader_group_handle_size as u64).next_multiple_of(handle_align);
        if stride > p.max_shader_group_stride as u64 {
            return Err(VkError::Unsupported(format!(
                "a shader group handle of {} bytes is more than the device's maxShaderGroupStride of {}",
                p.shader_group_handle_size, p.max_shader_group_stride
            )));
        }
        let region = stride.next_multiple_of(base);
        Ok(SbtLayout { stride, offsets: [0, region, 2 * region], bytes: 3 * region })
    }
}

/// The pipeline and everything it binds. Freed on drop.
pub struct RtPipeline {
    device: ash::Device,
    loader: ash::khr::ray_tracing_pipeline::Device,
    pipeline: vk::Pipeline,
    layout: vk::PipelineLayout,
    set_layout: vk::DescriptorSetLayout,
    pool: vk::DescriptorPool,
    set: vk::DescriptorSet,
    top: vk::AccelerationStructureKHR,
    _sbt: RawBuffer,
    /// Ray generation, miss, hit, callable (none).
    regions: [vk::StridedDeviceAddressRegionKHR; 4],
}

impl RtPipeline {
    /// The pipeline over the top-level structure `top` (which must outlive it).
    pub fn new(gpu: &Gpu, props: &Properties, top: vk::AccelerationStructureKHR) -> Result<RtPipeline, VkError> {
        if props.max_ray_recursion_depth < 1 {
            return Err(VkError::Unsupported(format!("{} traces no rays (maxRayRecursionDepth 0)", gpu.info().name)));
        }
        let device = gpu.ash_device().clone();
        let loader = ash::khr::ray_tracing_pipeline::Device::new(gpu.instance(), gpu.ash_device());
        let layout_sbt = SbtLayout::new(props)?;
        // The table's start aligned to the base alignment (the buffer's own alignment need not be).
        let base = props.shader_group_base_alignment.max(1) as u64;
        let sbt = RawBuffer::new(
            gpu,
            layout_sbt.bytes + base,
            vk::BufferUsageFlags::SHADER_BINDING_TABLE_KHR | vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            &HOST_WRITTEN,
            "rt shader binding table",
        )?;
        // Null handles until made: a failure drops `p`, which destroys what was made.
        let mut p = RtPipeline {
            device,
            loader,
            pipeline: vk::Pipeline::null(),
            layout: vk::PipelineLayout::null(),
            set_layout: vk::DescriptorSetLayout::null(),
            pool: vk::DescriptorPool::null(),
            set: vk::DescriptorSet::null(),
            top,
            _sbt: sbt,
            regions: [vk::StridedDeviceAddressRegionKHR::default(); 4],
        };
        let stage = vk::ShaderStageFlags::RAYGEN_KHR;
        let bindings = [
            vk::DescriptorSetLayoutBinding::default()
                .binding(BINDING_TLAS)
                .descriptor_type(vk::DescriptorType::ACCELERATION_STRUCTURE_KHR)
                .descriptor_count(1)
                .stage_flags(stage),
            vk::DescriptorSetLayoutBinding::default()
                .binding(BINDING_RAYS)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .descriptor_count(1)
                .stage_flags(stage),
            vk::DescriptorSetLayoutBinding::default()
                .binding(BINDING_HITS)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .descriptor_count(1)
                .stage_flags(stage),
        ];
        let stages = spirv::stages()?;
        let d = &p.device;
        // SAFETY: valid create infos on a live device.
        unsafe {
            p.set_layout = d
                .create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings), None)
                .map_err(|e| VkError::vk("vkCreateDescriptorSetLayout", e))?;
            let set_layouts = [p.set_layout];
            p.layout = d
                .create_pipeline_layout(&vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts), None)
                .map_err(|e| VkError::vk("vkCreatePipelineLayout", e))?;
            let sizes = [
                vk::DescriptorPoolSize { ty: vk::DescriptorType::ACCELERATION_STRUCTURE_KHR, descriptor_count: 1 },
                vk::DescriptorPoolSize { ty: vk::DescriptorType::STORAGE_BUFFER, descriptor_count: 2 },
            ];
            p.pool = d
                .create_descriptor_pool(&vk::DescriptorPoolCreateInfo::default().max_sets(1).pool_sizes(&sizes), None)
                .map_err(|e| VkError::vk("vkCreateDescriptorPool", e))?;
            p.set = d
                .allocate_descriptor_sets(
                    &vk::DescriptorSetAllocateInfo::default().descriptor_pool(p.pool).set_layouts(&set_layouts),
                )
                .map_err(|e| VkError::vk("vkAllocateDescriptorSets", e))?[0];

            let mut modules = Vec::new();
            let made = (|| {
                for words in [&stages.ray_gen, &stages.miss, &stages.closest_hit] {
                    let m = d
                        .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(words), None)
                        .map_err(|e| VkError::vk("vkCreateShaderModule", e))?;
                    modules.push(m);
                }
                let stage_infos = [
                    (vk::ShaderStageFlags::RAYGEN_KHR, modules[0]),
                    (vk::ShaderStageFlags::MISS_KHR, modules[1]),
                    (vk::ShaderStageFlags::CLOSEST_HIT_KHR, modules[2]),
                ]
                .map(|(s, m)| vk::PipelineShaderStageCreateInfo::default().stage(s).module(m).name(c"main"));
                let general = |i: u32| {
                    vk::RayTracingShaderGroupCreateInfoKHR::default()
                        .ty(vk::RayTracingShaderGroupTypeKHR::GENERAL)
                        .general_shader(i)
                        .closest_hit_shader(vk::SHADER_UNUSED_KHR)
                        .any_hit_shader(vk::SHADER_UNUSED_KHR)
                        .intersection_shader(vk::SHADER_UNUSED_KHR)
                };
                let groups = [
                    general(0),
                    general(1),
                    vk::RayTracingShaderGroupCreateInfoKHR::default()
                        .ty(vk::RayTracingShaderGroupTypeKHR::TRIANGLES_HIT_GROUP)
                        .general_shader(vk::SHADER_UNUSED_KHR)
                        .closest_hit_shader(2)
                        .any_hit_shader(vk::SHADER_UNUSED_KHR)
                        .intersection_shader(vk::SHADER_UNUSED_KHR),
                ];
                // Primary and secondary rays are traced from ray generation alone: depth 1.
                let info = vk::RayTracingPipelineCreateInfoKHR::default()
                    .stages(&stage_infos)
                    .groups(&groups)
                    .max_pipeline_ray_recursion_depth(1)
                    .layout(p.layout);
                match p.loader.create_ray_tracing_pipelines(
                    vk::DeferredOperationKHR::null(),
                    vk::PipelineCache::null(),
                    &[info],
                    None,
                ) {
                    Ok(v) => Ok(v[0]),
                    Err((v, e)) => {
                        for pl in v {
                            d.destroy_pipeline(pl, None);
                        }
                        Err(VkError::vk("vkCreateRayTracingPipelinesKHR", e))
                    }
                }
            })();
            for m in modules {
                d.destroy_shader_module(m, None);
            }
            p.pipeline = made?;

            let handle = props.shader_group_handle_size as usize;
            let handles = p
                .loader
                .get_ray_tracing_shader_group_handles(p.pipeline, 0, 3, 3 * handle)
                .map_err(|e| VkError::vk("vkGetRayTracingShaderGroupHandlesKHR", e))?;
            let start = (p._sbt.address.next_multiple_of(base) - p._sbt.address) as usize;
            let mut table = vec![0u8; start + layout_sbt.bytes as usize];
            for (g, &offset) in layout_sbt.offsets.iter().enumerate() {
                let at = start + offset as usize;
                table[at..at + handle].copy_from_slice(&handles[g * handle..(g + 1) * handle]);
            }
            p._sbt.write(&table)?;
        }
        let at = |k: usize| p._sbt.address.next_multiple_of(base) + layout_sbt.offsets[k];
        let stride = layout_sbt.stride;
        p.regions = [
            vk::StridedDeviceAddressRegionKHR { device_address: at(0), stride, size: stride },
            vk::StridedDeviceAddressRegionKHR { device_address: at(1), stride, size: stride },
            vk::StridedDeviceAddressRegionKHR { device_address: at(2), stride, size: stride },
            vk::StridedDeviceAddressRegionKHR::default(),
        ];
        Ok(p)
    }

    /// Points the descriptor set at the ray and hit records. Not while a run uses the set.
    pub fn bind_records(&self, rays: &Buffer, hits: &Buffer) {
        let tops = [self.top];
        let mut accel = vk::WriteDescriptorSetAccelerationStructureKHR::default().acceleration_structures(&tops);
        let ray_info = [vk::DescriptorBufferInfo { buffer: rays.raw(), offset: 0, range: vk::WHOLE_SIZE }];
        let hit_info = [vk::DescriptorBufferInfo { buffer: hits.raw(), offset: 0, range: vk::WHOLE_SIZE }];
        let mut tlas_write = vk::WriteDescriptorSet::default()
            .dst_set(self.set)
            .dst_binding(BINDING_TLAS)
            .descriptor_type(vk::DescriptorType::ACCELERATION_STRUCTURE_KHR)
            .push_next(&mut accel);
        // The count comes from the chained structure, which the builder does not see.
        tlas_write.descriptor_count = 1;
        let writes = [
            tlas_write,
            vk::WriteDescriptorSet::default()
                .dst_set(self.set)
                .dst_binding(BINDING_RAYS)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .buffer_info(&ray_info),
            vk::WriteDescriptorSet::default()
                .dst_set(self.set)
                .dst_binding(BINDING_HITS)
                .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                .buffer_info(&hit_info),
        ];
        // SAFETY: live objects; Gpu::run is synchronous, so no pending work uses the set.
        unsafe { self.device.update_descriptor_sets(&writes, &[]) };
    }

    /// Records one trace of a `width` x `height` launch: the compute writes of the ray records
    /// become visible to ray generation, and its hit records to the compute kernels and transfers
    /// after it.
    pub fn record_trace(&self, rec: &mut Recorder, width: u32, height: u32) {
        let cmd = rec.raw();
        let d = &self.device;
        let rt_stage = vk::PipelineStageFlags::RAY_TRACING_SHADER_KHR;
        let rw = vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE;
        // SAFETY: `cmd` is recording; the pipeline, set and tables outlive the run, which waits.
        unsafe {
            barrier(d, cmd, (vk::PipelineStageFlags::COMPUTE_SHADER, vk::AccessFlags::SHADER_WRITE), (rt_stage, rw));
            d.cmd_bind_pipeline(cmd, vk::PipelineBindPoint::RAY_TRACING_KHR, self.pipeline);
            d.cmd_bind_descriptor_sets(cmd, vk::PipelineBindPoint::RAY_TRACING_KHR, self.layout, 0, &[self.set], &[]);
            let [rgen, miss, hit, callable] = &self.regions;
            self.loader.cmd_trace_rays(cmd, rgen, miss, hit, callable, width, height, 1);
            barrier(
                d,
                cmd,
                (rt_stage, vk::AccessFlags::SHADER_WRITE),
                (
                    vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                    rw | vk::AccessFlags::TRANSFER_READ,
                ),
            );
        }
    }
}

impl Drop for RtPipeline {
    fn drop(&mut self) {
        // SAFETY: the runs that used these were waited for; null handles are ignored.
        unsafe {
            self.device.destroy_pipeline(self.pipeline, None);
            self.device.destroy_pipeline_layout(self.layout, None);
            self.device.destroy_descriptor_pool(self.pool, None);
            self.device.destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn props(size: u32, align: u32, base: u32) -> Properties {
        Properties {
            shader_group_handle_size: size,
            shader_group_handle_alignment: align,
            shader_group_base_alignment: base,
            max_shader_group_stride: 4096,
            max_ray_recursion_depth: 31,
            min_scratch_offset_alignment: 128,
            max_primitive_count: 1 << 29,
        }
    }

    #[test]
    fn the_binding_table_follows_the_alignment_rules() {
        // NVIDIA's values, and made-up ones where every rule bites.
        for (p, stride, region) in
            [(props(32, 32, 64), 32, 64), (props(20, 16, 48), 32, 48), (props(64, 64, 32), 64, 64)]
        {
            let l = SbtLayout::new(&p).unwrap();
            assert_eq!(l.stride, stride, "{p:?}");
            assert_eq!(l.offsets, [0, region, 2 * region], "{p:?}");
            for o in l.offsets {
                assert_eq!(o % p.shader_group_base_alignment as u64, 0, "{p:?}");
                assert!(o + p.shader_group_handle_size as u64 <= l.bytes);
            }
            assert_eq!(l.stride % p.shader_group_handle_alignment as u64, 0);
            assert!(l.stride >= p.shader_group_handle_size as u64);
        }
        let too_wide = Properties { max_shader_group_stride: 16, ..props(32, 32, 64) };
        assert!(SbtLayout::new(&too_wide).is_err());
    }
}
