//! Recording and submitting work: the one command buffer and fence of a [`Gpu`], [`Gpu::run`],
//! the [`Recorder`] that dispatches, and the barriers between commands.
//!
//! Every submission is waited for before the call returns, so the objects here are reused from one
//! submission to the next instead of being made per call.

use std::sync::atomic::Ordering;
use std::time::Duration;

use ash::vk;

use super::fault::Fault;
use super::gpu::{Gpu, Inner};
use super::memory::Buffer;
use super::pipeline::Pipeline;
use super::staging::Staging;
use super::timestamps::Timings;
use crate::error::VkError;

/// The per-Gpu objects that recording uses; behind a mutex because `Gpu`'s methods take `&self`.
pub(super) struct RunState {
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    pub(super) fence: vk::Fence,
    /// Submitted and not yet seen finished (only after a Timeout).
    pub(super) pending: bool,
    pub(super) descriptor_pools: Vec<vk::DescriptorPool>,
    /// The pool sets are taken from now; earlier ones are full.
    pub(super) descriptor_pool: usize,
    pub(super) query_pools: Vec<vk::QueryPool>,
    pub(super) staging: Option<Staging>,
}

impl RunState {
    /// Null handles, so that destroying a half-made state is valid.
    pub(super) fn empty() -> RunState {
        RunState {
            pool: vk::CommandPool::null(),
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            pending: false,
            descriptor_pools: Vec::new(),
            descriptor_pool: 0,
            query_pools: Vec::new(),
            staging: None,
        }
    }

    /// The command pool, its one command buffer and the fence. On failure what was made stays in
    /// `self` for [`RunState::destroy`].
    pub(super) fn create(&mut self, device: &ash::Device, family: u32) -> Result<(), VkError> {
        // SAFETY: valid create infos on a live device.
        unsafe {
            // TRANSIENT: the buffer is re-recorded for every submission (the pool is reset each
            // time), which lets the driver pick an allocator for short-lived command memory.
            let info = vk::CommandPoolCreateInfo::default()
                .queue_family_index(family)
                .flags(vk::CommandPoolCreateFlags::TRANSIENT);
            self.pool = device.create_command_pool(&info, None).map_err(|e| VkError::vk("vkCreateCommandPool", e))?;
            let info = vk::CommandBufferAllocateInfo::default()
                .command_pool(self.pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(1);
            self.cmd =
                device.allocate_command_buffers(&info).map_err(|e| VkError::vk("vkAllocateCommandBuffers", e))?[0];
            // Unsignalled: `execute` resets it before each submission anyway.
            self.fence = device
                .create_fence(&vk::FenceCreateInfo::default(), None)
                .map_err(|e| VkError::vk("vkCreateFence", e))?;
        }
        Ok(())
    }

    /// SAFETY: the device must be idle.
    pub(super) unsafe fn destroy(&mut self, device: &ash::Device) {
        unsafe {
            if let Some(s) = self.staging.take() {
                device.destroy_buffer(s.buffer, None);
                device.free_memory(s.memory, None);
            }
            for p in self.query_pools.drain(..) {
                device.destroy_query_pool(p, None);
            }
            for p in self.descriptor_pools.drain(..) {
                device.destroy_descriptor_pool(p, None);
            }
            device.destroy_fence(self.fence, None);
            device.destroy_command_pool(self.pool, None);
        }
    }
}

impl Gpu {
    /// Records commands with `f`, submits them, waits for them (at most [`Gpu::timeout`]) and
    /// returns the GPU times between the recorder's marks. An error from `f` submits nothing.
    pub fn run(&self, f: impl FnOnce(&mut Recorder) -> Result<(), VkError>) -> Result<Timings, VkError> {
        let mut guard = self.lock()?;
        let state = &mut *guard.state;
        let marks = self.execute(state, |state, cmd| {
            // SAFETY: the previous submission finished (execute settled it).
            unsafe { state.reset_descriptor_pools(&self.inner.device)? };
            let mut rec = Recorder { inner: &self.inner, cmd, state, marks: Vec::new(), deferred: None };
            f(&mut rec)?;
            match rec.deferred {
                Some(e) => Err(e),
                None => Ok(rec.marks),
            }
        })?;
        match self.fault() {
            Some(Fault::DeviceLost) => {
                self.inner.lost.store(true, Ordering::Relaxed);
                return Err(VkError::DeviceLost);
            }
            Some(Fault::Timeout) => return Err(VkError::Timeout { seconds: self.timeout.as_secs_f64().ceil() as u64 }),
            _ => {}
        }
        self.timings(state, marks)
    }

    /// Waits for a submission abandoned by an earlier timeout, so that its objects can be reused.
    pub(super) fn settle(&self, state: &mut RunState) -> Result<(), VkError> {
        if !state.pending {
            return Ok(());
        }
        self.wait(state)
    }

    fn wait(&self, state: &mut RunState) -> Result<(), VkError> {
        // SAFETY: the fence is live.
        match unsafe { self.inner.device.wait_for_fences(&[state.fence], true, nanos(self.timeout)) } {
            Ok(()) => {
                state.pending = false;
                self.inner.set_in_flight(false);
                Ok(())
            }
            Err(vk::Result::TIMEOUT) => {
                self.inner.set_in_flight(true);
                Err(VkError::Timeout { seconds: self.timeout.as_secs_f64().ceil() as u64 })
            }
            Err(e) => Err(VkError::vk("vkWaitForFences", e)),
        }
    }

    /// Records with `record` into the one command buffer, submits it and waits for it.
    pub(super) fn execute<R>(
        &self,
        state: &mut RunState,
        record: impl FnOnce(&mut RunState, vk::CommandBuffer) -> Result<R, VkError>,
    ) -> Result<R, VkError> {
        self.settle(state)?;
        if self.inner.lost.load(Ordering::Relaxed) {
            return Err(VkError::DeviceLost);
        }
        let device = &self.inner.device;
        let cmd = state.cmd;
        // SAFETY: nothing from this pool is pending (settled), and the fence is signalled or new.
        unsafe {
            device
                .reset_command_pool(state.pool, vk::CommandPoolResetFlags::empty())
                .map_err(|e| VkError::vk("vkResetCommandPool", e))?;
            device.reset_fences(&[state.fence]).map_err(|e| VkError::vk("vkResetFences", e))?;
            // ONE_TIME_SUBMIT: recorded anew for each submission, never replayed.
            let begin = vk::CommandBufferBeginInfo::default().flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
            device.begin_command_buffer(cmd, &begin).map_err(|e| VkError::vk("vkBeginCommandBuffer", e))?;
            // Waiting for a fence orders submissions but makes no device writes visible to later
            // ones: this barrier does, for whatever the previous submission wrote.
            barrier(
                device,
                cmd,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                READS_AND_WRITES,
            );
        }
        let out = record(state, cmd)?;
        // SAFETY: `cmd` is recorded; the queue is only used while holding the state lock.
        unsafe {
            device.end_command_buffer(cmd).map_err(|e| VkError::vk("vkEndCommandBuffer", e))?;
            let cmds = [cmd];
            let submit = vk::SubmitInfo::default().command_buffers(&cmds);
            device
                .queue_submit(self.inner.queue, &[submit], state.fence)
                .map_err(|e| VkError::vk("vkQueueSubmit", e))?;
        }
        state.pending = true;
        self.wait(state)?;
        Ok(out)
    }
}

/// Everything a later dispatch or transfer may do to a buffer: the destination of the barriers,
/// so that neither a read after a write nor a write after a write races.
const READS_AND_WRITES: vk::AccessFlags = vk::AccessFlags::from_raw(
    vk::AccessFlags::SHADER_READ.as_raw()
        | vk::AccessFlags::SHADER_WRITE.as_raw()
        | vk::AccessFlags::TRANSFER_READ.as_raw()
        | vk::AccessFlags::TRANSFER_WRITE.as_raw(),
);

/// A global memory barrier: buffers are few and mostly whole-buffer, so per-buffer barriers would
/// add bookkeeping for no gain.
///
/// SAFETY: `cmd` is recording.
pub(super) unsafe fn barrier(
    device: &ash::Device,
    cmd: vk::CommandBuffer,
    src_stage: vk::PipelineStageFlags,
    src_access: vk::AccessFlags,
    dst_stage: vk::PipelineStageFlags,
    dst_access: vk::AccessFlags,
) {
    let mb = vk::MemoryBarrier::default().src_access_mask(src_access).dst_access_mask(dst_access);
    unsafe { device.cmd_pipeline_barrier(cmd, src_stage, dst_stage, vk::DependencyFlags::empty(), &[mb], &[], &[]) };
}

/// A fence timeout in nanoseconds, saturating.
pub(super) fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

/// Records the commands of one [`Gpu::run`].
pub struct Recorder<'a> {
    pub(super) inner: &'a Inner,
    pub(super) cmd: vk::CommandBuffer,
    pub(super) state: &'a mut RunState,
    pub(super) marks: Vec<String>,
    /// An error from a method that returns nothing (`mark`, `zero`), reported by `run`.
    deferred: Option<VkError>,
}

impl Recorder<'_> {
    /// Binds `buffers` to bindings 0.. of set 0, pushes `push`, dispatches `groups` workgroups,
    /// then makes the results visible to later dispatches and transfers.
    pub fn dispatch(
        &mut self,
        p: &Pipeline,
        buffers: &[&Buffer],
        push: &[u8],
        groups: [u32; 3],
    ) -> Result<(), VkError> {
        let inner = self.inner;
        let label = &p.desc.label;
        if !inner.owns(&p.inner) {
            return Err(VkError::Usage(format!("pipeline `{label}` belongs to another Gpu")));
        }
        if buffers.len() != p.desc.bindings as usize {
            return Err(VkError::Usage(format!(
                "pipeline `{label}` binds {} buffers but was given {}",
                p.desc.bindings,
                buffers.len()
            )));
        }
        if push.len() != p.desc.push_bytes as usize {
            return Err(VkError::Usage(format!(
                "pipeline `{label}` takes {} bytes of push constants but was given {}",
                p.desc.push_bytes,
                push.len()
            )));
        }
        if let Some(b) = buffers.iter().find(|b| !inner.owns(&b.inner)) {
            return Err(VkError::Usage(format!("buffer `{}` belongs to another Gpu", b.label)));
        }
        let max = inner.info.max_workgroup_count;
        if groups.iter().zip(max).any(|(&g, m)| g > m) {
            return Err(VkError::Usage(format!(
                "pipeline `{label}` was dispatched with {groups:?} workgroups, more than this device's limit of {max:?}"
            )));
        }
        let device = &inner.device;
        // SAFETY: `cmd` is recording; pipeline, layout and buffers are live objects of this device
        // and stay alive until `run` has waited for the GPU (they are borrowed by the caller).
        unsafe {
            device.cmd_bind_pipeline(self.cmd, vk::PipelineBindPoint::COMPUTE, p.pipeline);
            if p.desc.bindings > 0 {
                let set = self.bind_buffers(p, buffers)?;
                device.cmd_bind_descriptor_sets(self.cmd, vk::PipelineBindPoint::COMPUTE, p.layout, 0, &[set], &[]);
            }
            if !push.is_empty() {
                device.cmd_push_constants(self.cmd, p.layout, vk::ShaderStageFlags::COMPUTE, 0, push);
            }
            device.cmd_dispatch(self.cmd, groups[0], groups[1], groups[2]);
            // The next dispatch may read what this one wrote, a download may copy it, and a later
            // upload or zero may overwrite what this one still reads.
            barrier(
                device,
                self.cmd,
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::AccessFlags::SHADER_WRITE,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                READS_AND_WRITES,
            );
        }
        Ok(())
    }

    /// Fills `buf` with zeros, visible to the following dispatches and transfers.
    pub fn zero(&mut self, buf: &Buffer) {
        if !self.inner.owns(&buf.inner) {
            self.defer(VkError::Usage(format!("buffer `{}` belongs to another Gpu", buf.label)));
            return;
        }
        let device = &self.inner.device;
        // SAFETY: `cmd` is recording; the buffer's size is a multiple of 4.
        unsafe {
            device.cmd_fill_buffer(self.cmd, buf.buffer, 0, vk::WHOLE_SIZE, 0);
            barrier(
                device,
                self.cmd,
                vk::PipelineStageFlags::TRANSFER,
                vk::AccessFlags::TRANSFER_WRITE,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                READS_AND_WRITES,
            );
        }
    }

    /// The command buffer being recorded, for commands this API does not wrap.
    pub fn raw(&self) -> vk::CommandBuffer {
        self.cmd
    }

    pub(super) fn defer(&mut self, e: VkError) {
        self.deferred.get_or_insert(e);
    }
}
