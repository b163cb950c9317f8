//! Buffers and their memory: [`BufferDesc`] says what a buffer is for (size, usage, the memory it
//! prefers) without owning anything; [`Buffer`] owns the Vulkan buffer and memory and frees them
//! on drop.

use std::fmt;
use std::sync::Arc;

use ash::vk;

use super::gpu::{Gpu, Inner};
use crate::error::VkError;

/// A buffer before it exists: what the allocator needs, and nothing that must be destroyed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BufferDesc<'a> {
    pub label: &'a str,
    /// Already rounded and checked against the device's limits by the constructor that made it.
    pub bytes: u64,
    pub usage: vk::BufferUsageFlags,
    /// Memory property sets in order of preference: the first one some memory type of the device
    /// has (and the buffer accepts) is taken.
    pub memory: &'a [vk::MemoryPropertyFlags],
}

impl<'a> BufferDesc<'a> {
    /// A storage buffer the kernels read and write, its size rounded up to a multiple of 16 (at
    /// least 16).
    pub fn storage(bytes: u64, label: &'a str) -> BufferDesc<'a> {
        BufferDesc {
            label,
            // A multiple of 16, so that a whole download casts to any record of at most 16
            // bytes (`Gpu::download_as`).
            bytes: bytes.max(16).next_multiple_of(16),
            // STORAGE_BUFFER: bound by the kernels. TRANSFER_DST: written by uploads and by
            // vkCmdFillBuffer (`Recorder::zero`). TRANSFER_SRC: read back by downloads.
            usage: vk::BufferUsageFlags::STORAGE_BUFFER
                | vk::BufferUsageFlags::TRANSFER_SRC
                | vk::BufferUsageFlags::TRANSFER_DST,
            // Device-local where the device has it, because the kernels read these buffers many
            // times for each upload; any memory type otherwise, so that a device whose only
            // memory type is not marked device-local still works.
            memory: const { &[vk::MemoryPropertyFlags::DEVICE_LOCAL, vk::MemoryPropertyFlags::empty()] },
        }
    }

    /// The host-visible buffer that uploads and downloads pass through, at least 1 MiB so that a
    /// run of small uploads does not reallocate it each time.
    pub fn staging(bytes: u64, label: &'a str) -> BufferDesc<'a> {
        const HOST: vk::MemoryPropertyFlags = vk::MemoryPropertyFlags::from_raw(
            // Mapped by the host; coherent, so no flush or invalidate calls are needed around
            // the copies.
            vk::MemoryPropertyFlags::HOST_VISIBLE.as_raw() | vk::MemoryPropertyFlags::HOST_COHERENT.as_raw(),
        );
        const CACHED: vk::MemoryPropertyFlags =
            vk::MemoryPropertyFlags::from_raw(HOST.as_raw() | vk::MemoryPropertyFlags::HOST_CACHED.as_raw());
        BufferDesc {
            label,
            bytes: bytes.max(1 << 20).next_multiple_of(16),
            // Only ever the other end of a copy.
            usage: vk::BufferUsageFlags::TRANSFER_SRC | vk::BufferUsageFlags::TRANSFER_DST,
            // Cached memory makes the host's reads of downloads fast; writes do not suffer.
            memory: &[CACHED, HOST],
        }
    }
}

impl Inner {
    /// The first memory type allowed by `type_bits` that has one of the `wanted` property sets,
    /// trying the sets in order.
    fn memory_type(&self, type_bits: u32, wanted: &[vk::MemoryPropertyFlags]) -> Option<u32> {
        let types = &self.memory.memory_types[..self.memory.memory_type_count as usize];
        wanted.iter().find_map(|&flags| {
            (0..types.len() as u32)
                .find(|&i| type_bits & (1 << i) != 0 && types[i as usize].property_flags.contains(flags))
        })
    }

    /// A buffer with its own memory, as `desc` describes it.
    pub(super) fn raw_buffer(&self, desc: &BufferDesc<'_>) -> Result<(vk::Buffer, vk::DeviceMemory), VkError> {
        let BufferDesc { label, bytes, usage, memory: wanted } = *desc;
        // EXCLUSIVE: one queue family ever touches it.
        let info = vk::BufferCreateInfo::default().size(bytes).usage(usage).sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid create info; the buffer is destroyed below on every failure path.
        let buffer = unsafe { self.device.create_buffer(&info, None) }
            .map_err(|e| VkError::alloc("vkCreateBuffer", e, label, bytes))?;
        let free = |memory: vk::DeviceMemory| unsafe {
            self.device.destroy_buffer(buffer, None);
            self.device.free_memory(memory, None);
        };
        // SAFETY: `buffer` is live.
        let req = unsafe { self.device.get_buffer_memory_requirements(buffer) };
        let Some(type_index) = self.memory_type(req.memory_type_bits, wanted) else {
            free(vk::DeviceMemory::null());
            return Err(VkError::OutOfDeviceMemory { label: label.to_string(), bytes });
        };
        // Refused here with a sentence, because drivers answer an allocation past these limits
        // with anything from an error code to a crash.
        let heap = self.memory.memory_heaps[self.memory.memory_types[type_index as usize].heap_index as usize];
        if req.size > self.info.max_memory_allocation || req.size > heap.size {
            free(vk::DeviceMemory::null());
            return Err(VkError::OutOfDeviceMemory { label: label.to_string(), bytes });
        }
        let simulated = *self.fault.lock().unwrap_or_else(std::sync::PoisonError::into_inner);
        if matches!(simulated, Some(super::Fault::OutOfMemory(most)) if req.size > most) {
            free(vk::DeviceMemory::null());
            return Err(VkError::alloc("vkAllocateMemory", vk::Result::ERROR_OUT_OF_DEVICE_MEMORY, label, bytes));
        }
        let alloc = vk::MemoryAllocateInfo::default().allocation_size(req.size).memory_type_index(type_index);
        // SAFETY: valid allocate info.
        let memory = match unsafe { self.device.allocate_memory(&alloc, None) } {
            Ok(m) => m,
            Err(e) => {
                free(vk::DeviceMemory::null());
                return Err(VkError::alloc("vkAllocateMemory", e, label, bytes));
            }
        };
        // SAFETY: fresh buffer and memory of the required size and type.
        if let Err(e) = unsafe { self.device.bind_buffer_memory(buffer, memory, 0) } {
            free(memory);
            return Err(VkError::alloc("vkBindBufferMemory", e, label, bytes));
        }
        self.name(buffer, label);
        Ok((buffer, memory))
    }
}

/// A device-local storage buffer, freed on drop.
pub struct Buffer {
    pub(super) inner: Arc<Inner>,
    pub(super) buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    pub(super) size: u64,
    pub(super) label: String,
}

impl Buffer {
    /// Size in bytes: the requested size rounded up to a multiple of 16.
    pub fn size(&self) -> u64 {
        self.size
    }

    pub fn label(&self) -> &str {
        &self.label
    }

    pub fn raw(&self) -> vk::Buffer {
        self.buffer
    }
}

impl fmt::Debug for Buffer {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Buffer").field("label", &self.label).field("size", &self.size).finish()
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        if self.inner.retire_buffer(self.buffer, self.memory) {
            return;
        }
        // SAFETY: `run`/`upload`/`download` wait for the GPU, so no pending work uses the buffer
        // (after a Timeout it was parked above instead).
        unsafe {
            self.inner.device.destroy_buffer(self.buffer, None);
            self.inner.device.free_memory(self.memory, None);
        }
    }
}

impl Gpu {
    /// A device-local storage buffer (also a transfer source and destination), its size rounded up
    /// to a multiple of 16 (at least 16). Its contents are undefined until written.
    pub fn create_buffer(&self, bytes: u64, label: &str) -> Result<Buffer, VkError> {
        let limit = self.inner.info.max_storage_buffer_range;
        if bytes > limit {
            return Err(VkError::BufferTooLarge { label: label.to_string(), bytes, limit });
        }
        let desc = BufferDesc::storage(bytes, label);
        let (buffer, memory) = self.inner.raw_buffer(&desc)?;
        Ok(Buffer { inner: self.inner.clone(), buffer, memory, size: desc.bytes, label: label.to_string() })
    }

    /// A buffer holding `data` (cast to bytes).
    pub fn create_buffer_with<T: bytemuck::Pod>(&self, data: &[T], label: &str) -> Result<Buffer, VkError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let buf = self.create_buffer(bytes.len() as u64, label)?;
        self.upload(&buf, bytes)?;
        Ok(buf)
    }
}
