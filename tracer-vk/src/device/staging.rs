//! Moving bytes between the host and device-local buffers, through one host-visible staging
//! buffer per [`Gpu`] that is reused and grown as needed.

use ash::vk;

use super::commands::{RunState, barrier};
use super::gpu::Gpu;
use super::memory::{Buffer, BufferDesc};
use crate::error::VkError;

/// Uploads and downloads go through a host-visible buffer of at most this size, so that moving a
/// multi-GiB scene does not need as much host-visible memory again.
const STAGING_CHUNK: u64 = 64 << 20;

/// The staging buffer, mapped for its whole life.
pub(super) struct Staging {
    pub(super) buffer: vk::Buffer,
    pub(super) memory: vk::DeviceMemory,
    ptr: *mut u8,
    size: u64,
}

// SAFETY: the mapping is only touched while holding the Gpu's state mutex.
unsafe impl Send for Staging {}

impl Gpu {
    /// Copies `data` to the start of `buf` through a host-visible staging buffer.
    pub fn upload(&self, buf: &Buffer, data: &[u8]) -> Result<(), VkError> {
        self.check_buffer(buf)?;
        if data.len() as u64 > buf.size {
            return Err(VkError::Usage(format!(
                "{} bytes do not fit into buffer `{}` of {} bytes",
                data.len(),
                buf.label,
                buf.size
            )));
        }
        let mut guard = self.lock()?;
        let state = &mut *guard.state;
        for (i, chunk) in data.chunks(STAGING_CHUNK as usize).enumerate() {
            let staging = self.staging(state, chunk.len() as u64, &buf.label)?;
            // SAFETY: the staging buffer is mapped, at least chunk.len() long, and idle (the last
            // submission that used it was waited for).
            unsafe { std::ptr::copy_nonoverlapping(chunk.as_ptr(), staging.1, chunk.len()) };
            let region =
                vk::BufferCopy { src_offset: 0, dst_offset: i as u64 * STAGING_CHUNK, size: chunk.len() as u64 };
            // No host-to-transfer barrier: vkQueueSubmit makes host writes to coherent memory
            // visible to the commands it submits.
            self.execute(state, |_, cmd| {
                // SAFETY: recording into the state's command buffer.
                unsafe { self.inner.device.cmd_copy_buffer(cmd, staging.0, buf.buffer, &[region]) };
                Ok(())
            })?;
        }
        Ok(())
    }

    /// `data` into the start of `buf`.
    pub fn upload_slice<T: bytemuck::Pod>(&self, buf: &Buffer, data: &[T]) -> Result<(), VkError> {
        self.upload(buf, bytemuck::cast_slice(data))
    }

    /// The whole buffer's contents.
    pub fn download(&self, buf: &Buffer) -> Result<Vec<u8>, VkError> {
        self.download_prefix(buf, buf.size)
    }

    /// The first `bytes` of the buffer (a tile's pixels in a buffer sized for the largest tile).
    pub fn download_prefix(&self, buf: &Buffer, bytes: u64) -> Result<Vec<u8>, VkError> {
        self.check_buffer(buf)?;
        if bytes > buf.size {
            return Err(VkError::Usage(format!("buffer `{}` holds {} bytes, not {bytes}", buf.label, buf.size)));
        }
        let mut out = vec![0u8; bytes as usize];
        let mut guard = self.lock()?;
        let state = &mut *guard.state;
        for (i, chunk) in out.chunks_mut(STAGING_CHUNK as usize).enumerate() {
            let staging = self.staging(state, chunk.len() as u64, &buf.label)?;
            let region =
                vk::BufferCopy { src_offset: i as u64 * STAGING_CHUNK, dst_offset: 0, size: chunk.len() as u64 };
            self.execute(state, |_, cmd| {
                // SAFETY: recording into the state's command buffer. A fence wait does not make
                // device writes visible to the host; the HOST barrier does.
                unsafe {
                    self.inner.device.cmd_copy_buffer(cmd, buf.buffer, staging.0, &[region]);
                    barrier(
                        &self.inner.device,
                        cmd,
                        vk::PipelineStageFlags::TRANSFER,
                        vk::AccessFlags::TRANSFER_WRITE,
                        vk::PipelineStageFlags::HOST,
                        vk::AccessFlags::HOST_READ,
                    );
                }
                Ok(())
            })?;
            // SAFETY: the copy has finished and the memory is coherent.
            unsafe { std::ptr::copy_nonoverlapping(staging.1, chunk.as_mut_ptr(), chunk.len()) };
        }
        Ok(out)
    }

    /// The whole buffer as `T`s (its size is a multiple of 16, so of any `T` up to 16 bytes).
    pub fn download_as<T: bytemuck::Pod>(&self, buf: &Buffer) -> Result<Vec<T>, VkError> {
        let bytes = self.download(buf)?;
        let whole = bytes.len() - bytes.len() % size_of::<T>().max(1);
        Ok(bytemuck::pod_collect_to_vec(&bytes[..whole]))
    }

    /// The first `count` elements of the buffer as `T`s.
    pub fn download_prefix_as<T: bytemuck::Pod>(&self, buf: &Buffer, count: usize) -> Result<Vec<T>, VkError> {
        let bytes = self.download_prefix(buf, (count * size_of::<T>()) as u64)?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    }

    /// The staging buffer (grown to at least `bytes`) and its mapping.
    fn staging(&self, state: &mut RunState, bytes: u64, label: &str) -> Result<(vk::Buffer, *mut u8), VkError> {
        self.settle(state)?;
        if let Some(s) = &state.staging
            && s.size >= bytes
        {
            return Ok((s.buffer, s.ptr));
        }
        let device = &self.inner.device;
        if let Some(s) = state.staging.take() {
            // SAFETY: idle (settled above).
            unsafe {
                device.destroy_buffer(s.buffer, None);
                device.free_memory(s.memory, None);
            }
        }
        let staging_label = format!("staging for {label}");
        let desc = BufferDesc::staging(bytes, &staging_label);
        let (buffer, memory) = self.inner.raw_buffer(&desc)?;
        // SAFETY: host-visible memory, not mapped yet.
        let ptr = match unsafe { device.map_memory(memory, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty()) } {
            Ok(p) => p.cast::<u8>(),
            Err(e) => {
                unsafe {
                    device.destroy_buffer(buffer, None);
                    device.free_memory(memory, None);
                }
                return Err(VkError::alloc("vkMapMemory", e, label, desc.bytes));
            }
        };
        state.staging = Some(Staging { buffer, memory, ptr, size: desc.bytes });
        Ok((buffer, ptr))
    }
}
