//! Compute pipelines: [`PipelineDesc`] says what a pipeline binds (storage buffers, push
//! constants) and is checked against the device's limits; [`Pipeline`] owns the shader's pipeline
//! with its layouts and frees them on drop.

use std::fmt;
use std::sync::Arc;

use ash::vk;

use super::gpu::{Gpu, Inner};
use super::info::DeviceInfo;
use crate::error::VkError;

/// The interface of a compute pipeline: `bindings` storage buffers at set 0, bindings
/// 0..bindings, and a push-constant block of `push_bytes` (0 for none).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PipelineDesc {
    pub label: String,
    pub bindings: u32,
    pub push_bytes: u32,
}

/// The push-constant size every Vulkan device supports; more is refused even where the device
/// allows it, so that a kernel that runs on one device runs on all.
const PORTABLE_PUSH_BYTES: u32 = 128;

impl PipelineDesc {
    /// Refuses, with a sentence naming the limit, what the device (or any device) cannot build.
    pub fn check(&self, info: &DeviceInfo) -> Result<(), VkError> {
        let (label, push_bytes, bindings) = (&self.label, self.push_bytes, self.bindings);
        if !push_bytes.is_multiple_of(4)
            || push_bytes > PORTABLE_PUSH_BYTES
            || push_bytes > info.max_push_constants_size
        {
            return Err(VkError::Usage(format!(
                "pipeline `{label}` asks for {push_bytes} bytes of push constants, which must be a multiple of 4 and \
                 at most {}",
                info.max_push_constants_size.min(PORTABLE_PUSH_BYTES)
            )));
        }
        if bindings > info.max_storage_buffers {
            return Err(VkError::Usage(format!(
                "pipeline `{label}` needs {bindings} storage buffers, more than this device's limit of {}",
                info.max_storage_buffers
            )));
        }
        Ok(())
    }

    /// One storage buffer per binding, seen by the compute stage only (the only stage there is).
    fn set_layout_bindings(&self) -> Vec<vk::DescriptorSetLayoutBinding<'static>> {
        (0..self.bindings)
            .map(|b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect()
    }

    fn push_range(&self) -> vk::PushConstantRange {
        vk::PushConstantRange { stage_flags: vk::ShaderStageFlags::COMPUTE, offset: 0, size: self.push_bytes }
    }
}

/// A compute pipeline with its layout, freed on drop.
pub struct Pipeline {
    pub(super) inner: Arc<Inner>,
    pub(super) pipeline: vk::Pipeline,
    pub(super) layout: vk::PipelineLayout,
    pub(super) set_layout: vk::DescriptorSetLayout,
    pub(super) desc: PipelineDesc,
}

impl Pipeline {
    pub fn label(&self) -> &str {
        &self.desc.label
    }

    pub fn bindings(&self) -> u32 {
        self.desc.bindings
    }

    pub fn push_bytes(&self) -> u32 {
        self.desc.push_bytes
    }

    pub fn desc(&self) -> &PipelineDesc {
        &self.desc
    }
}

impl fmt::Debug for Pipeline {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Pipeline")
            .field("label", &self.desc.label)
            .field("bindings", &self.desc.bindings)
            .field("push_bytes", &self.desc.push_bytes)
            .finish()
    }
}

impl Drop for Pipeline {
    fn drop(&mut self) {
        if self.inner.retire_pipeline(self.pipeline, self.layout, self.set_layout) {
            return;
        }
        // SAFETY: as for Buffer: no pending work uses it.
        unsafe {
            self.inner.device.destroy_pipeline(self.pipeline, None);
            self.inner.device.destroy_pipeline_layout(self.layout, None);
            self.inner.device.destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

impl Gpu {
    /// A compute pipeline from SPIR-V words with entry point `main`, `bindings` storage buffers at
    /// set 0, bindings 0..bindings, and a push-constant block of `push_bytes` (0 for none).
    pub fn pipeline(&self, spirv: &[u32], bindings: u32, push_bytes: u32, label: &str) -> Result<Pipeline, VkError> {
        self.pipeline_from(spirv, PipelineDesc { label: label.to_string(), bindings, push_bytes })
    }

    /// A compute pipeline from SPIR-V words with entry point `main` and the interface `desc`.
    pub fn pipeline_from(&self, spirv: &[u32], desc: PipelineDesc) -> Result<Pipeline, VkError> {
        // The SPIR-V magic number: anything else is a caller's bug that some drivers crash on.
        if spirv.len() < 5 || spirv[0] != 0x0723_0203 {
            return Err(VkError::Usage(format!(
                "pipeline `{}` was given words that are not a SPIR-V module",
                desc.label
            )));
        }
        desc.check(&self.inner.info)?;
        let device = &self.inner.device;
        let slots = desc.set_layout_bindings();
        let ranges = [desc.push_range()];
        let push_bytes = desc.push_bytes;
        let mut p = Pipeline {
            inner: self.inner.clone(),
            pipeline: vk::Pipeline::null(),
            layout: vk::PipelineLayout::null(),
            set_layout: vk::DescriptorSetLayout::null(),
            desc,
        };
        // SAFETY: valid create infos; a failure drops `p`, which destroys what was made.
        unsafe {
            p.set_layout = device
                .create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&slots), None)
                .map_err(|e| VkError::vk("vkCreateDescriptorSetLayout", e))?;
            let set_layouts = [p.set_layout];
            let mut layout_info = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
            // A zero-sized push-constant range is invalid, so none is declared without push bytes.
            if push_bytes > 0 {
                layout_info = layout_info.push_constant_ranges(&ranges);
            }
            p.layout = device
                .create_pipeline_layout(&layout_info, None)
                .map_err(|e| VkError::vk("vkCreatePipelineLayout", e))?;
            let module = device
                .create_shader_module(&vk::ShaderModuleCreateInfo::default().code(spirv), None)
                .map_err(|e| VkError::vk("vkCreateShaderModule", e))?;
            let stage = vk::PipelineShaderStageCreateInfo::default()
                .stage(vk::ShaderStageFlags::COMPUTE)
                .module(module)
                .name(c"main");
            let info = vk::ComputePipelineCreateInfo::default().stage(stage).layout(p.layout);
            let made = device.create_compute_pipelines(vk::PipelineCache::null(), &[info], None);
            // The pipeline keeps what it needs of the module; the module itself is not needed again.
            device.destroy_shader_module(module, None);
            p.pipeline = match made {
                Ok(v) => v[0],
                Err((v, e)) => {
                    for pl in v {
                        device.destroy_pipeline(pl, None);
                    }
                    return Err(VkError::vk("vkCreateComputePipelines", e));
                }
            };
        }
        self.inner.name(p.pipeline, &p.desc.label);
        Ok(p)
    }
}
