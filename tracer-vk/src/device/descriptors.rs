//! Descriptor sets: each dispatch gets a fresh set from the run's pools, which are all reset at
//! the start of the next run (sets are never freed one by one).

use ash::vk;

use super::commands::{Recorder, RunState};
use super::memory::Buffer;
use super::pipeline::Pipeline;
use crate::error::VkError;

/// Descriptor sets per descriptor pool (and storage-buffer descriptors per set, on average).
const SETS_PER_POOL: u32 = 256;
const DESCRIPTORS_PER_SET: u32 = 8;

impl RunState {
    /// Makes every set of the previous run free again.
    ///
    /// SAFETY: the previous submission has finished, so no set is in use.
    pub(super) unsafe fn reset_descriptor_pools(&mut self, device: &ash::Device) -> Result<(), VkError> {
        for &pool in &self.descriptor_pools {
            // SAFETY: the caller's promise.
            unsafe { device.reset_descriptor_pool(pool, vk::DescriptorPoolResetFlags::empty()) }
                .map_err(|e| VkError::vk("vkResetDescriptorPool", e))?;
        }
        self.descriptor_pool = 0;
        Ok(())
    }
}

impl Recorder<'_> {
    /// A set for `p`'s layout with `buffers` written to bindings 0.., each bound whole (up to the
    /// device's storage-buffer range).
    pub(super) fn bind_buffers(&mut self, p: &Pipeline, buffers: &[&Buffer]) -> Result<vk::DescriptorSet, VkError> {
        let set = self.descriptor_set(p)?;
        let range_limit = self.inner.info.max_storage_buffer_range;
        let infos: Vec<_> = buffers
            .iter()
            .map(|b| vk::DescriptorBufferInfo { buffer: b.buffer, offset: 0, range: b.size.min(range_limit) })
            .collect();
        let write = vk::WriteDescriptorSet::default()
            .dst_set(set)
            .dst_binding(0)
            .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
            .buffer_info(&infos);
        // SAFETY: the set is fresh (not bound by any recorded command yet) and the buffers live.
        unsafe { self.inner.device.update_descriptor_sets(&[write], &[]) };
        Ok(set)
    }

    /// A set for `p`'s layout from the run's descriptor pools, adding a pool when they are full.
    fn descriptor_set(&mut self, p: &Pipeline) -> Result<vk::DescriptorSet, VkError> {
        let device = &self.inner.device;
        let layouts = [p.set_layout];
        loop {
            let fresh = self.state.descriptor_pool == self.state.descriptor_pools.len();
            if fresh {
                let sizes = [vk::DescriptorPoolSize {
                    ty: vk::DescriptorType::STORAGE_BUFFER,
                    descriptor_count: (SETS_PER_POOL * DESCRIPTORS_PER_SET).max(p.desc.bindings),
                }];
                // No FREE_DESCRIPTOR_SET flag: sets go back all at once by resetting the pool.
                let info = vk::DescriptorPoolCreateInfo::default().max_sets(SETS_PER_POOL).pool_sizes(&sizes);
                // SAFETY: valid create info.
                let pool = unsafe { device.create_descriptor_pool(&info, None) }
                    .map_err(|e| VkError::vk("vkCreateDescriptorPool", e))?;
                self.state.descriptor_pools.push(pool);
            }
            let pool = self.state.descriptor_pools[self.state.descriptor_pool];
            let info = vk::DescriptorSetAllocateInfo::default().descriptor_pool(pool).set_layouts(&layouts);
            // SAFETY: valid allocate info.
            match unsafe { device.allocate_descriptor_sets(&info) } {
                Ok(sets) => return Ok(sets[0]),
                Err(vk::Result::ERROR_OUT_OF_POOL_MEMORY | vk::Result::ERROR_FRAGMENTED_POOL) if !fresh => {
                    self.state.descriptor_pool += 1;
                }
                Err(e) => return Err(VkError::vk("vkAllocateDescriptorSets", e)),
            }
        }
    }
}
