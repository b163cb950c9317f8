//! The Vulkan device layer: picking a device, storage buffers, compute pipelines made from SPIR-V,
//! and one-shot command recording with GPU timestamps.
//!
//! Everything is synchronous on purpose: [`Gpu::run`] records, submits and waits, so a caller never
//! holds a command buffer or a fence, and a buffer or pipeline can be dropped as soon as `run`
//! returns. The tracer's kernels take milliseconds to seconds, so the lost overlap between
//! submissions does not show in its timings (which come from the timestamps, not the host clock).

use std::ffi::{CStr, CString, c_void};
use std::fmt;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::ThreadId;
use std::time::Duration;

use ash::vk;

use crate::error::VkError;

const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";
/// Uploads and downloads go through a host-visible buffer of at most this size, so that moving a
/// multi-GiB scene does not need as much host-visible memory again.
const STAGING_CHUNK: u64 = 64 << 20;
/// Timestamp queries per query pool; more pools are made when a run marks more often.
const QUERIES_PER_POOL: u32 = 64;
/// Descriptor sets per descriptor pool (and storage-buffer descriptors per set, on average).
const SETS_PER_POOL: u32 = 256;
const DESCRIPTORS_PER_SET: u32 = 8;

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
    /// Position in [`list_devices`], the number [`Gpu::new`] takes.
    pub index: usize,
    pub name: String,
    pub kind: DeviceKind,
    /// The version the device is used at: the lower of the device's and the loader's, at most 1.3.
    pub api_version: (u32, u32, u32),
    pub driver: String,
    pub subgroup_size: u32,
    pub max_shared_memory: u32,
    /// Largest range of one storage buffer binding, so also the largest [`Buffer`].
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
    /// Whether the compute queue writes timestamps; without them [`Timings`] holds NaN.
    pub timestamps: bool,
    pub vendor_id: u32,
    pub device_id: u32,
}

/// Every device that can run compute work, in the order [`Gpu::new`] numbers them.
pub fn list_devices() -> Result<Vec<DeviceInfo>, VkError> {
    let entry = load_entry()?;
    let api = instance_api(&entry)?;
    let instance = create_instance(&entry, api, None)?;
    let found = candidates(&instance, api);
    // SAFETY: nothing made from this instance outlives this function.
    unsafe { instance.destroy_instance(None) };
    Ok(found?.into_iter().map(|c| c.info).collect())
}

/// The validation messages of one [`Gpu`], readable after the `Gpu` (and its buffers) are gone,
/// which is when the layer reports leaked objects.
#[derive(Clone, Debug, Default)]
pub struct ValidationLog(Arc<Mutex<Vec<String>>>);

impl ValidationLog {
    pub fn messages(&self) -> Vec<String> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }
}

/// An open device with one compute queue.
pub struct Gpu {
    inner: Arc<Inner>,
    state: Mutex<RunState>,
    /// Which thread holds `state`, so that calling `upload` from inside `run`'s closure is an error
    /// instead of a deadlock.
    holder: Mutex<Option<ThreadId>>,
    /// How long [`Gpu::run`], [`Gpu::upload`] and [`Gpu::download`] wait for the GPU before giving
    /// up with [`VkError::Timeout`].
    pub timeout: Duration,
}

/// What buffers and pipelines need to free themselves: they hold an `Arc` to it, so the device
/// lives until the last of them is dropped, whatever order the caller drops things in.
struct Inner {
    // The loader library must stay loaded until the instance is destroyed (Drop below runs first).
    _entry: ash::Entry,
    instance: ash::Instance,
    messenger: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    names: Option<ash::ext::debug_utils::Device>,
    device: ash::Device,
    queue: vk::Queue,
    family: u32,
    memory: vk::PhysicalDeviceMemoryProperties,
    info: DeviceInfo,
    timestamp_mask: u64,
    log: ValidationLog,
    /// Objects dropped while a submission abandoned by a timeout may still use them.
    retired: Mutex<Retired>,
}

/// After a timeout the GPU may go on running the abandoned work (lavapipe's threads do), so a
/// buffer or pipeline dropped meanwhile is parked here and destroyed once the work is seen
/// finished. Destroying it at once freed memory a running kernel still used: `trace-vk render
/// --method sst --workgroup 1x1` aborted with "double free or corruption" that way.
#[derive(Default)]
struct Retired {
    /// A submission was abandoned and has not been seen finished.
    in_flight: bool,
    buffers: Vec<(vk::Buffer, vk::DeviceMemory)>,
    pipelines: Vec<(vk::Pipeline, vk::PipelineLayout, vk::DescriptorSetLayout)>,
}

impl Retired {
    /// SAFETY: no pending work may use the parked objects.
    unsafe fn destroy(&mut self, device: &ash::Device) {
        unsafe {
            for (buffer, memory) in self.buffers.drain(..) {
                device.destroy_buffer(buffer, None);
                device.free_memory(memory, None);
            }
            for (pipeline, layout, set_layout) in self.pipelines.drain(..) {
                device.destroy_pipeline(pipeline, None);
                device.destroy_pipeline_layout(layout, None);
                device.destroy_descriptor_set_layout(set_layout, None);
            }
        }
    }
}

impl Drop for Inner {
    fn drop(&mut self) {
        // SAFETY: every child object holds an Arc<Inner>, so all of them are destroyed by now.
        unsafe {
            let _ = self.device.device_wait_idle();
            self.retired.get_mut().unwrap_or_else(PoisonError::into_inner).destroy(&self.device);
            self.device.destroy_device(None);
            if let Some((utils, messenger)) = &self.messenger {
                utils.destroy_debug_utils_messenger(*messenger, None);
            }
            self.instance.destroy_instance(None);
        }
    }
}

impl Inner {
    /// Parks the objects when abandoned work may still run; otherwise hands them back to destroy.
    fn retire_buffer(&self, buffer: vk::Buffer, memory: vk::DeviceMemory) -> bool {
        let mut r = self.retired.lock().unwrap_or_else(PoisonError::into_inner);
        if r.in_flight {
            r.buffers.push((buffer, memory));
        }
        r.in_flight
    }

    fn retire_pipeline(&self, p: vk::Pipeline, layout: vk::PipelineLayout, set: vk::DescriptorSetLayout) -> bool {
        let mut r = self.retired.lock().unwrap_or_else(PoisonError::into_inner);
        if r.in_flight {
            r.pipelines.push((p, layout, set));
        }
        r.in_flight
    }

    /// Marks abandoned work as finished (or not) and destroys what waited for it.
    fn set_in_flight(&self, in_flight: bool) {
        let mut r = self.retired.lock().unwrap_or_else(PoisonError::into_inner);
        r.in_flight = in_flight;
        if !in_flight {
            // SAFETY: the caller saw the abandoned submission finish.
            unsafe { r.destroy(&self.device) };
        }
    }

    fn name<H: vk::Handle>(&self, handle: H, label: &str) {
        if let (Some(names), Ok(name)) = (&self.names, CString::new(label)) {
            let info = vk::DebugUtilsObjectNameInfoEXT::default().object_handle(handle).object_name(&name);
            // SAFETY: `handle` is a live object of this device. A failure only loses a debug name.
            let _ = unsafe { names.set_debug_utils_object_name(&info) };
        }
    }

    fn memory_type(&self, type_bits: u32, wanted: &[vk::MemoryPropertyFlags]) -> Option<u32> {
        let types = &self.memory.memory_types[..self.memory.memory_type_count as usize];
        wanted.iter().find_map(|&flags| {
            (0..types.len() as u32)
                .find(|&i| type_bits & (1 << i) != 0 && types[i as usize].property_flags.contains(flags))
        })
    }

    /// A buffer with its own memory. `bytes` is already rounded and checked against the limits.
    fn raw_buffer(
        &self,
        bytes: u64,
        usage: vk::BufferUsageFlags,
        wanted: &[vk::MemoryPropertyFlags],
        label: &str,
    ) -> Result<(vk::Buffer, vk::DeviceMemory), VkError> {
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
        let heap = self.memory.memory_heaps[self.memory.memory_types[type_index as usize].heap_index as usize];
        if req.size > self.info.max_memory_allocation || req.size > heap.size {
            free(vk::DeviceMemory::null());
            return Err(VkError::OutOfDeviceMemory { label: label.to_string(), bytes });
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
    inner: Arc<Inner>,
    buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    size: u64,
    label: String,
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

/// A compute pipeline with its layout, freed on drop.
pub struct Pipeline {
    inner: Arc<Inner>,
    pipeline: vk::Pipeline,
    layout: vk::PipelineLayout,
    set_layout: vk::DescriptorSetLayout,
    bindings: u32,
    push_bytes: u32,
    label: String,
}

impl Pipeline {
    pub fn label(&self) -> &str {
        &self.label
    }

    pub fn bindings(&self) -> u32 {
        self.bindings
    }

    pub fn push_bytes(&self) -> u32 {
        self.push_bytes
    }
}

impl fmt::Debug for Pipeline {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Pipeline")
            .field("label", &self.label)
            .field("bindings", &self.bindings)
            .field("push_bytes", &self.push_bytes)
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

/// GPU times between a run's [`Recorder::mark`]s.
#[derive(Clone, Debug, Default)]
pub struct Timings {
    /// (label of the later mark, milliseconds since the mark before it).
    pub intervals: Vec<(String, f64)>,
    /// First mark to last (0 with fewer than two marks); NaN where the device has no timestamps.
    pub total_ms: f64,
}

impl Timings {
    /// The interval that ends at the mark called `label`.
    pub fn get(&self, label: &str) -> Option<f64> {
        self.intervals.iter().find(|(l, _)| l == label).map(|&(_, ms)| ms)
    }
}

/// The per-Gpu objects that recording uses; behind a mutex because `Gpu`'s methods take `&self`.
struct RunState {
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    /// Submitted and not yet seen finished (only after a Timeout).
    pending: bool,
    descriptor_pools: Vec<vk::DescriptorPool>,
    /// The pool sets are taken from now; earlier ones are full.
    descriptor_pool: usize,
    query_pools: Vec<vk::QueryPool>,
    staging: Option<Staging>,
}

struct Staging {
    buffer: vk::Buffer,
    memory: vk::DeviceMemory,
    ptr: *mut u8,
    size: u64,
}

// SAFETY: the mapping is only touched while holding the Gpu's state mutex.
unsafe impl Send for Staging {}

impl RunState {
    fn empty() -> RunState {
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

    /// SAFETY: the device must be idle.
    unsafe fn destroy(&mut self, device: &ash::Device) {
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

struct StateGuard<'a> {
    state: MutexGuard<'a, RunState>,
    holder: &'a Mutex<Option<ThreadId>>,
}

impl Drop for StateGuard<'_> {
    fn drop(&mut self) {
        *self.holder.lock().unwrap_or_else(PoisonError::into_inner) = None;
    }
}

impl Drop for Gpu {
    fn drop(&mut self) {
        let device = &self.inner.device;
        let state = self.state.get_mut().unwrap_or_else(PoisonError::into_inner);
        // SAFETY: waiting first makes the device idle, so nothing below is in use.
        unsafe {
            if state.pending {
                let _ = device.wait_for_fences(&[state.fence], true, nanos(self.timeout));
            }
            let _ = device.device_wait_idle();
            state.destroy(device);
        }
        // The device is idle: whatever waited for abandoned work can go.
        self.inner.set_in_flight(false);
    }
}

impl Gpu {
    /// Opens device `choice` (an index into [`list_devices`]), or else the first discrete GPU, the
    /// first integrated one, or the first device of any kind. With `validation`, the Khronos
    /// validation layer is enabled and its errors and warnings are recorded (see
    /// [`Gpu::validation_messages`]).
    pub fn new(choice: Option<usize>, validation: bool) -> Result<Gpu, VkError> {
        let entry = load_entry()?;
        let api = instance_api(&entry)?;
        let log = ValidationLog::default();
        if validation {
            // SAFETY: plain query.
            let layers = unsafe { entry.enumerate_instance_layer_properties() }
                .map_err(|e| VkError::vk("vkEnumerateInstanceLayerProperties", e))?;
            if !layers.iter().any(|l| l.layer_name_as_c_str() == Ok(VALIDATION_LAYER)) {
                return Err(VkError::Validation(
                    "the Vulkan validation layer VK_LAYER_KHRONOS_validation is not installed (on Debian or Ubuntu: \
                     `apt-get install vulkan-validationlayers`)"
                        .to_string(),
                ));
            }
        }
        let instance = create_instance(&entry, api, validation.then_some(&log))?;
        let opened = (|| {
            let messenger = if validation {
                let utils = ash::ext::debug_utils::Instance::new(&entry, &instance);
                let info = messenger_info(&log);
                // SAFETY: `log` is kept alive by Inner until after the messenger is destroyed.
                let m = unsafe { utils.create_debug_utils_messenger(&info, None) }
                    .map_err(|e| VkError::vk("vkCreateDebugUtilsMessengerEXT", e))?;
                Some((utils, m))
            } else {
                None
            };
            let opened = open_device(&instance, api, choice);
            if let (Err(_), Some((utils, m))) = (&opened, &messenger) {
                // SAFETY: nothing else uses the messenger.
                unsafe { utils.destroy_debug_utils_messenger(*m, None) };
            }
            opened.map(|o| (o, messenger))
        })();
        let ((device, candidate), messenger) = match opened {
            Ok(x) => x,
            Err(e) => {
                // SAFETY: no children of the instance are left.
                unsafe { instance.destroy_instance(None) };
                return Err(e);
            }
        };
        // SAFETY: the family was created with one queue.
        let queue = unsafe { device.get_device_queue(candidate.family, 0) };
        let names = validation.then(|| ash::ext::debug_utils::Device::new(&instance, &device));
        let bits = candidate.timestamp_bits;
        let inner = Arc::new(Inner {
            _entry: entry,
            instance,
            messenger,
            names,
            device,
            queue,
            family: candidate.family,
            memory: candidate.memory,
            info: candidate.info,
            timestamp_mask: if bits >= 64 { u64::MAX } else { (1u64 << bits) - 1 },
            log,
            retired: Mutex::new(Retired::default()),
        });
        // From here on, a failure drops `gpu`, which destroys whatever was made (null handles are
        // valid arguments to vkDestroy*).
        let mut gpu = Gpu {
            inner,
            state: Mutex::new(RunState::empty()),
            holder: Mutex::new(None),
            timeout: Duration::from_secs(120),
        };
        let device = &gpu.inner.device;
        let state = gpu.state.get_mut().unwrap_or_else(PoisonError::into_inner);
        // SAFETY: valid create infos on a live device.
        unsafe {
            let info = vk::CommandPoolCreateInfo::default()
                .queue_family_index(gpu.inner.family)
                .flags(vk::CommandPoolCreateFlags::TRANSIENT);
            state.pool = device.create_command_pool(&info, None).map_err(|e| VkError::vk("vkCreateCommandPool", e))?;
            let info = vk::CommandBufferAllocateInfo::default()
                .command_pool(state.pool)
                .level(vk::CommandBufferLevel::PRIMARY)
                .command_buffer_count(1);
            state.cmd =
                device.allocate_command_buffers(&info).map_err(|e| VkError::vk("vkAllocateCommandBuffers", e))?[0];
            state.fence = device
                .create_fence(&vk::FenceCreateInfo::default(), None)
                .map_err(|e| VkError::vk("vkCreateFence", e))?;
        }
        Ok(gpu)
    }

    pub fn info(&self) -> &DeviceInfo {
        &self.inner.info
    }

    /// Validation errors and warnings recorded so far (empty without validation).
    pub fn validation_messages(&self) -> Vec<String> {
        self.inner.log.messages()
    }

    /// A handle on the same messages that stays readable after the Gpu is dropped.
    pub fn validation_log(&self) -> ValidationLog {
        self.inner.log.clone()
    }

    /// The ash device, for commands this API does not wrap (recorded through [`Recorder::raw`]).
    pub fn ash_device(&self) -> &ash::Device {
        &self.inner.device
    }

    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
    }

    /// A device-local storage buffer (also a transfer source and destination), its size rounded up
    /// to a multiple of 16 (at least 16). Its contents are undefined until written.
    pub fn create_buffer(&self, bytes: u64, label: &str) -> Result<Buffer, VkError> {
        let limit = self.inner.info.max_storage_buffer_range;
        if bytes > limit {
            return Err(VkError::BufferTooLarge { label: label.to_string(), bytes, limit });
        }
        let size = bytes.max(16).next_multiple_of(16);
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER
            | vk::BufferUsageFlags::TRANSFER_SRC
            | vk::BufferUsageFlags::TRANSFER_DST;
        let (buffer, memory) = self.inner.raw_buffer(
            size,
            usage,
            &[vk::MemoryPropertyFlags::DEVICE_LOCAL, vk::MemoryPropertyFlags::empty()],
            label,
        )?;
        Ok(Buffer { inner: self.inner.clone(), buffer, memory, size, label: label.to_string() })
    }

    /// A buffer holding `data` (cast to bytes).
    pub fn create_buffer_with<T: bytemuck::Pod>(&self, data: &[T], label: &str) -> Result<Buffer, VkError> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let buf = self.create_buffer(bytes.len() as u64, label)?;
        self.upload(&buf, bytes)?;
        Ok(buf)
    }

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

    /// A compute pipeline from SPIR-V words with entry point `main`, `bindings` storage buffers at
    /// set 0, bindings 0..bindings, and a push-constant block of `push_bytes` (0 for none).
    pub fn pipeline(&self, spirv: &[u32], bindings: u32, push_bytes: u32, label: &str) -> Result<Pipeline, VkError> {
        let info = &self.inner.info;
        if spirv.len() < 5 || spirv[0] != 0x0723_0203 {
            return Err(VkError::Usage(format!("pipeline `{label}` was given words that are not a SPIR-V module")));
        }
        if !push_bytes.is_multiple_of(4) || push_bytes > 128 || push_bytes > info.max_push_constants_size {
            return Err(VkError::Usage(format!(
                "pipeline `{label}` asks for {push_bytes} bytes of push constants, which must be a multiple of 4 and \
                 at most {}",
                info.max_push_constants_size.min(128)
            )));
        }
        if bindings > info.max_storage_buffers {
            return Err(VkError::Usage(format!(
                "pipeline `{label}` needs {bindings} storage buffers, more than this device's limit of {}",
                info.max_storage_buffers
            )));
        }
        let device = &self.inner.device;
        let mut p = Pipeline {
            inner: self.inner.clone(),
            pipeline: vk::Pipeline::null(),
            layout: vk::PipelineLayout::null(),
            set_layout: vk::DescriptorSetLayout::null(),
            bindings,
            push_bytes,
            label: label.to_string(),
        };
        let slots: Vec<_> = (0..bindings)
            .map(|b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        let ranges =
            [vk::PushConstantRange { stage_flags: vk::ShaderStageFlags::COMPUTE, offset: 0, size: push_bytes }];
        // SAFETY: valid create infos; a failure drops `p`, which destroys what was made.
        unsafe {
            p.set_layout = device
                .create_descriptor_set_layout(&vk::DescriptorSetLayoutCreateInfo::default().bindings(&slots), None)
                .map_err(|e| VkError::vk("vkCreateDescriptorSetLayout", e))?;
            let set_layouts = [p.set_layout];
            let mut layout_info = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
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
        self.inner.name(p.pipeline, label);
        Ok(p)
    }

    /// Records commands with `f`, submits them, waits for them (at most [`Gpu::timeout`]) and
    /// returns the GPU times between the recorder's marks. An error from `f` submits nothing.
    pub fn run(&self, f: impl FnOnce(&mut Recorder) -> Result<(), VkError>) -> Result<Timings, VkError> {
        let mut guard = self.lock()?;
        let state = &mut *guard.state;
        let marks = self.execute(state, |state, cmd| {
            for &pool in &state.descriptor_pools {
                // SAFETY: the previous submission finished (execute checked), so no set is in use.
                unsafe { self.inner.device.reset_descriptor_pool(pool, vk::DescriptorPoolResetFlags::empty()) }
                    .map_err(|e| VkError::vk("vkResetDescriptorPool", e))?;
            }
            state.descriptor_pool = 0;
            let mut rec = Recorder { inner: &self.inner, cmd, state, marks: Vec::new(), deferred: None };
            f(&mut rec)?;
            match rec.deferred {
                Some(e) => Err(e),
                None => Ok(rec.marks),
            }
        })?;
        self.timings(state, marks)
    }

    fn timings(&self, state: &RunState, marks: Vec<String>) -> Result<Timings, VkError> {
        if self.inner.timestamp_mask == 0 {
            let intervals = marks.into_iter().skip(1).map(|l| (l, f64::NAN)).collect();
            return Ok(Timings { intervals, total_ms: f64::NAN });
        }
        let mut stamps = vec![0u64; marks.len()];
        for (pool, chunk) in state.query_pools.iter().zip(stamps.chunks_mut(QUERIES_PER_POOL as usize)) {
            // SAFETY: these queries were reset and written by the finished submission.
            unsafe {
                self.inner.device.get_query_pool_results(
                    *pool,
                    0,
                    chunk,
                    vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
                )
            }
            .map_err(|e| VkError::vk("vkGetQueryPoolResults", e))?;
        }
        let mask = self.inner.timestamp_mask;
        let ms = |a: u64, b: u64| (b.wrapping_sub(a) & mask) as f64 * self.inner.info.timestamp_period_ns as f64 / 1e6;
        let intervals = marks.into_iter().skip(1).zip(stamps.windows(2)).map(|(l, w)| (l, ms(w[0], w[1]))).collect();
        let total_ms = match (stamps.first(), stamps.last()) {
            (Some(&a), Some(&b)) => ms(a, b),
            _ => 0.0,
        };
        Ok(Timings { intervals, total_ms })
    }

    fn check_buffer(&self, buf: &Buffer) -> Result<(), VkError> {
        if Arc::ptr_eq(&buf.inner, &self.inner) {
            Ok(())
        } else {
            Err(VkError::Usage(format!("buffer `{}` belongs to another Gpu", buf.label)))
        }
    }

    fn lock(&self) -> Result<StateGuard<'_>, VkError> {
        let me = std::thread::current().id();
        if *self.holder.lock().unwrap_or_else(PoisonError::into_inner) == Some(me) {
            return Err(VkError::Usage(
                "Gpu::run, upload and download cannot be called from inside a Gpu::run closure".to_string(),
            ));
        }
        let state = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        *self.holder.lock().unwrap_or_else(PoisonError::into_inner) = Some(me);
        Ok(StateGuard { state, holder: &self.holder })
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
        // At least 1 MiB, so that a run of small uploads does not reallocate each time.
        let size = bytes.max(1 << 20).next_multiple_of(16);
        let host = vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT;
        let (buffer, memory) = self.inner.raw_buffer(
            size,
            vk::BufferUsageFlags::TRANSFER_SRC | vk::BufferUsageFlags::TRANSFER_DST,
            // Cached memory makes the host's reads of downloads fast; writes do not suffer.
            &[host | vk::MemoryPropertyFlags::HOST_CACHED, host],
            &format!("staging for {label}"),
        )?;
        // SAFETY: host-visible memory, not mapped yet.
        let ptr = match unsafe { device.map_memory(memory, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty()) } {
            Ok(p) => p.cast::<u8>(),
            Err(e) => {
                unsafe {
                    device.destroy_buffer(buffer, None);
                    device.free_memory(memory, None);
                }
                return Err(VkError::alloc("vkMapMemory", e, label, size));
            }
        };
        state.staging = Some(Staging { buffer, memory, ptr, size });
        Ok((buffer, ptr))
    }

    /// Waits for a submission abandoned by an earlier timeout, so that its objects can be reused.
    fn settle(&self, state: &mut RunState) -> Result<(), VkError> {
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
    fn execute<R>(
        &self,
        state: &mut RunState,
        record: impl FnOnce(&mut RunState, vk::CommandBuffer) -> Result<R, VkError>,
    ) -> Result<R, VkError> {
        self.settle(state)?;
        let device = &self.inner.device;
        let cmd = state.cmd;
        // SAFETY: nothing from this pool is pending (settled), and the fence is signalled or new.
        unsafe {
            device
                .reset_command_pool(state.pool, vk::CommandPoolResetFlags::empty())
                .map_err(|e| VkError::vk("vkResetCommandPool", e))?;
            device.reset_fences(&[state.fence]).map_err(|e| VkError::vk("vkResetFences", e))?;
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

const READS_AND_WRITES: vk::AccessFlags = vk::AccessFlags::from_raw(
    vk::AccessFlags::SHADER_READ.as_raw()
        | vk::AccessFlags::SHADER_WRITE.as_raw()
        | vk::AccessFlags::TRANSFER_READ.as_raw()
        | vk::AccessFlags::TRANSFER_WRITE.as_raw(),
);

/// SAFETY: `cmd` is recording.
unsafe fn barrier(
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

fn nanos(d: Duration) -> u64 {
    u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
}

/// Records the commands of one [`Gpu::run`].
pub struct Recorder<'a> {
    inner: &'a Inner,
    cmd: vk::CommandBuffer,
    state: &'a mut RunState,
    marks: Vec<String>,
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
        if !std::ptr::eq(Arc::as_ptr(&p.inner), inner) {
            return Err(VkError::Usage(format!("pipeline `{}` belongs to another Gpu", p.label)));
        }
        if buffers.len() != p.bindings as usize {
            return Err(VkError::Usage(format!(
                "pipeline `{}` binds {} buffers but was given {}",
                p.label,
                p.bindings,
                buffers.len()
            )));
        }
        if push.len() != p.push_bytes as usize {
            return Err(VkError::Usage(format!(
                "pipeline `{}` takes {} bytes of push constants but was given {}",
                p.label,
                p.push_bytes,
                push.len()
            )));
        }
        if let Some(b) = buffers.iter().find(|b| !std::ptr::eq(Arc::as_ptr(&b.inner), inner)) {
            return Err(VkError::Usage(format!("buffer `{}` belongs to another Gpu", b.label)));
        }
        let max = inner.info.max_workgroup_count;
        if groups.iter().zip(max).any(|(&g, m)| g > m) {
            return Err(VkError::Usage(format!(
                "pipeline `{}` was dispatched with {groups:?} workgroups, more than this device's limit of {max:?}",
                p.label
            )));
        }
        let device = &inner.device;
        // SAFETY: `cmd` is recording; pipeline, layout and buffers are live objects of this device
        // and stay alive until `run` has waited for the GPU (they are borrowed by the caller).
        unsafe {
            device.cmd_bind_pipeline(self.cmd, vk::PipelineBindPoint::COMPUTE, p.pipeline);
            if p.bindings > 0 {
                let set = self.descriptor_set(p)?;
                let range_limit = inner.info.max_storage_buffer_range;
                let infos: Vec<_> = buffers
                    .iter()
                    .map(|b| vk::DescriptorBufferInfo { buffer: b.buffer, offset: 0, range: b.size.min(range_limit) })
                    .collect();
                let write = vk::WriteDescriptorSet::default()
                    .dst_set(set)
                    .dst_binding(0)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .buffer_info(&infos);
                device.update_descriptor_sets(&[write], &[]);
                device.cmd_bind_descriptor_sets(self.cmd, vk::PipelineBindPoint::COMPUTE, p.layout, 0, &[set], &[]);
            }
            if !push.is_empty() {
                device.cmd_push_constants(self.cmd, p.layout, vk::ShaderStageFlags::COMPUTE, 0, push);
            }
            device.cmd_dispatch(self.cmd, groups[0], groups[1], groups[2]);
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
        if !std::ptr::eq(Arc::as_ptr(&buf.inner), self.inner) {
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

    /// A timestamp taken when all earlier commands have finished. [`Timings`] reports the time
    /// between consecutive marks under the later mark's label.
    pub fn mark(&mut self, label: &str) {
        let n = self.marks.len() as u32;
        self.marks.push(label.to_string());
        if self.inner.timestamp_mask == 0 {
            return;
        }
        let (pool_index, query) = ((n / QUERIES_PER_POOL) as usize, n % QUERIES_PER_POOL);
        let device = &self.inner.device;
        if pool_index == self.state.query_pools.len() {
            let info =
                vk::QueryPoolCreateInfo::default().query_type(vk::QueryType::TIMESTAMP).query_count(QUERIES_PER_POOL);
            // SAFETY: valid create info.
            match unsafe { device.create_query_pool(&info, None) } {
                Ok(pool) => self.state.query_pools.push(pool),
                Err(e) => {
                    self.defer(VkError::vk("vkCreateQueryPool", e));
                    return;
                }
            }
        }
        let pool = self.state.query_pools[pool_index];
        // SAFETY: `cmd` is recording. Resetting each query just before writing it keeps pools that
        // are created mid-recording valid without a separate reset pass.
        unsafe {
            device.cmd_reset_query_pool(self.cmd, pool, query, 1);
            device.cmd_write_timestamp(self.cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, pool, query);
        }
    }

    /// The command buffer being recorded, for commands this API does not wrap.
    pub fn raw(&self) -> vk::CommandBuffer {
        self.cmd
    }

    fn defer(&mut self, e: VkError) {
        self.deferred.get_or_insert(e);
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
                    descriptor_count: (SETS_PER_POOL * DESCRIPTORS_PER_SET).max(p.bindings),
                }];
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

fn load_entry() -> Result<ash::Entry, VkError> {
    // SAFETY: loading the system's Vulkan loader runs its initialisers, which is what it is for.
    unsafe { ash::Entry::load() }.map_err(|e| VkError::NoLoader(e.to_string()))
}

/// The API version to request: the loader's, at most 1.3 (what the code is written against).
fn instance_api(entry: &ash::Entry) -> Result<u32, VkError> {
    // SAFETY: plain query.
    let loader = unsafe { entry.try_enumerate_instance_version() }
        .map_err(|e| VkError::vk("vkEnumerateInstanceVersion", e))?
        .unwrap_or(vk::API_VERSION_1_0);
    if loader < vk::API_VERSION_1_1 {
        // Subgroup properties and vkGetPhysicalDeviceProperties2 need 1.1.
        return Err(VkError::NoDevice);
    }
    Ok(loader.min(vk::API_VERSION_1_3))
}

fn messenger_info(log: &ValidationLog) -> vk::DebugUtilsMessengerCreateInfoEXT<'static> {
    vk::DebugUtilsMessengerCreateInfoEXT::default()
        .message_severity(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR | vk::DebugUtilsMessageSeverityFlagsEXT::WARNING)
        .message_type(
            vk::DebugUtilsMessageTypeFlagsEXT::GENERAL
                | vk::DebugUtilsMessageTypeFlagsEXT::VALIDATION
                | vk::DebugUtilsMessageTypeFlagsEXT::PERFORMANCE,
        )
        .pfn_user_callback(Some(on_message))
        .user_data(Arc::as_ptr(&log.0) as *mut c_void)
}

unsafe extern "system" fn on_message(
    severity: vk::DebugUtilsMessageSeverityFlagsEXT,
    _types: vk::DebugUtilsMessageTypeFlagsEXT,
    data: *const vk::DebugUtilsMessengerCallbackDataEXT<'_>,
    user: *mut c_void,
) -> vk::Bool32 {
    if data.is_null() || user.is_null() {
        return vk::FALSE;
    }
    // SAFETY: `user` is the Arc'd log, alive until the messenger and instance are destroyed;
    // `data` is valid for the duration of the call.
    let (log, text) = unsafe {
        let log = &*(user as *const Mutex<Vec<String>>);
        let text = (*data).message_as_c_str().map(|m| m.to_string_lossy().into_owned()).unwrap_or_default();
        (log, text)
    };
    let level = if severity.contains(vk::DebugUtilsMessageSeverityFlagsEXT::ERROR) { "error" } else { "warning" };
    log.lock().unwrap_or_else(PoisonError::into_inner).push(format!("{level}: {text}"));
    // FALSE: the call that triggered the message goes on, as the spec asks of applications.
    vk::FALSE
}

fn create_instance(entry: &ash::Entry, api: u32, validation: Option<&ValidationLog>) -> Result<ash::Instance, VkError> {
    let app = vk::ApplicationInfo::default().application_name(c"tracer-vk").engine_name(c"tracer-vk").api_version(api);
    let layers = [VALIDATION_LAYER.as_ptr()];
    let extensions = [ash::ext::debug_utils::NAME.as_ptr()];
    let mut info = vk::InstanceCreateInfo::default().application_info(&app);
    // Chained into the create info, the messenger also catches messages of vkCreateInstance and
    // vkDestroyInstance, which the separately created one cannot.
    let mut messenger = validation.map(messenger_info);
    if let Some(m) = messenger.as_mut() {
        info = info.enabled_layer_names(&layers).enabled_extension_names(&extensions).push_next(m);
    }
    // SAFETY: valid create info.
    unsafe { entry.create_instance(&info, None) }.map_err(|e| match e {
        vk::Result::ERROR_INCOMPATIBLE_DRIVER => VkError::NoDevice,
        e => VkError::vk("vkCreateInstance", e),
    })
}

struct Candidate {
    physical: vk::PhysicalDevice,
    family: u32,
    timestamp_bits: u32,
    memory: vk::PhysicalDeviceMemoryProperties,
    info: DeviceInfo,
}

/// The devices that can run the tracer: Vulkan 1.1 or later, with a compute queue.
fn candidates(instance: &ash::Instance, instance_api: u32) -> Result<Vec<Candidate>, VkError> {
    // SAFETY: plain queries on a live instance.
    let physicals = unsafe { instance.enumerate_physical_devices() }.or_else(|e| match e {
        vk::Result::ERROR_INITIALIZATION_FAILED => Ok(Vec::new()),
        e => Err(VkError::vk("vkEnumeratePhysicalDevices", e)),
    })?;
    let mut out = Vec::new();
    for physical in physicals {
        // SAFETY: as above.
        let base = unsafe { instance.get_physical_device_properties(physical) };
        // The device is used at the lower of the two versions; patch levels do not limit anything,
        // so the device's own is kept for display when its major.minor is the lower one.
        let minor = |v: u32| vk::make_api_version(0, vk::api_version_major(v), vk::api_version_minor(v), 0);
        let api = if minor(base.api_version) <= minor(instance_api) { base.api_version } else { instance_api };
        if api < vk::API_VERSION_1_1 {
            continue;
        }
        let families = unsafe { instance.get_physical_device_queue_family_properties(physical) };
        let compute = |f: &vk::QueueFamilyProperties| f.queue_flags.contains(vk::QueueFlags::COMPUTE);
        // A family that writes timestamps, else any compute family.
        let Some(family) = families
            .iter()
            .position(|f| compute(f) && f.timestamp_valid_bits > 0)
            .or_else(|| families.iter().position(compute))
        else {
            continue;
        };
        let mut subgroup = vk::PhysicalDeviceSubgroupProperties::default();
        let mut maintenance3 = vk::PhysicalDeviceMaintenance3Properties::default();
        let mut driver = vk::PhysicalDeviceDriverProperties::default();
        let mut float_controls = vk::PhysicalDeviceFloatControlsProperties::default();
        let mut props = vk::PhysicalDeviceProperties2::default().push_next(&mut subgroup).push_next(&mut maintenance3);
        if api >= vk::API_VERSION_1_2 {
            props = props.push_next(&mut driver).push_next(&mut float_controls);
        }
        unsafe { instance.get_physical_device_properties2(physical, &mut props) };
        let p = props.properties;
        let memory = unsafe { instance.get_physical_device_memory_properties(physical) };
        let device_local_bytes = memory.memory_heaps[..memory.memory_heap_count as usize]
            .iter()
            .filter(|h| h.flags.contains(vk::MemoryHeapFlags::DEVICE_LOCAL))
            .map(|h| h.size)
            .sum();
        let ops = vk::SubgroupFeatureFlags::BASIC
            | vk::SubgroupFeatureFlags::VOTE
            | vk::SubgroupFeatureFlags::BALLOT
            | vk::SubgroupFeatureFlags::ARITHMETIC;
        let cstr = |r: Result<&CStr, _>| r.map(|s: &CStr| s.to_string_lossy().into_owned()).unwrap_or_default();
        let driver = if api >= vk::API_VERSION_1_2 {
            let name = cstr(driver.driver_name_as_c_str());
            let detail = cstr(driver.driver_info_as_c_str());
            if detail.is_empty() { name } else { format!("{name} {detail}") }
        } else {
            format!("driver version {:#x}", p.driver_version)
        };
        let l = p.limits;
        let timestamp_bits = families[family].timestamp_valid_bits;
        out.push(Candidate {
            physical,
            family: family as u32,
            timestamp_bits,
            memory,
            info: DeviceInfo {
                index: out.len(),
                name: cstr(p.device_name_as_c_str()),
                kind: p.device_type.into(),
                api_version: (vk::api_version_major(api), vk::api_version_minor(api), vk::api_version_patch(api)),
                driver,
                subgroup_size: subgroup.subgroup_size,
                max_shared_memory: l.max_compute_shared_memory_size,
                max_storage_buffer_range: l.max_storage_buffer_range as u64,
                max_workgroup_invocations: l.max_compute_work_group_invocations,
                max_workgroup_size: l.max_compute_work_group_size,
                timestamp_period_ns: l.timestamp_period,
                device_local_bytes,
                denorm_preserve_f32: api >= vk::API_VERSION_1_2
                    && float_controls.shader_denorm_preserve_float32 == vk::TRUE,
                supports_subgroup_ops: subgroup.supported_stages.contains(vk::ShaderStageFlags::COMPUTE)
                    && subgroup.supported_operations.contains(ops),
                max_workgroup_count: l.max_compute_work_group_count,
                max_push_constants_size: l.max_push_constants_size,
                max_memory_allocation: maintenance3.max_memory_allocation_size,
                max_storage_buffers: l
                    .max_per_stage_descriptor_storage_buffers
                    .min(l.max_descriptor_set_storage_buffers),
                timestamps: timestamp_bits > 0,
                vendor_id: p.vendor_id,
                device_id: p.device_id,
            },
        });
    }
    Ok(out)
}

fn open_device(instance: &ash::Instance, api: u32, choice: Option<usize>) -> Result<(ash::Device, Candidate), VkError> {
    let mut found = candidates(instance, api)?;
    if found.is_empty() {
        return Err(VkError::NoDevice);
    }
    let index = match choice {
        Some(index) if index >= found.len() => return Err(VkError::DeviceIndex { index, count: found.len() }),
        Some(index) => index,
        None => [DeviceKind::Discrete, DeviceKind::Integrated]
            .iter()
            .find_map(|&k| found.iter().position(|c| c.info.kind == k))
            .unwrap_or(0),
    };
    let chosen = found.swap_remove(index);
    let priorities = [1.0f32];
    let queues = [vk::DeviceQueueCreateInfo::default().queue_family_index(chosen.family).queue_priorities(&priorities)];
    // Compute on storage buffers needs no optional features; none are enabled so that every
    // Vulkan 1.1 device qualifies.
    let info = vk::DeviceCreateInfo::default().queue_create_infos(&queues);
    // SAFETY: valid create info for a device of this instance.
    let device = unsafe { instance.create_device(chosen.physical, &info, None) }.map_err(|e| match e {
        vk::Result::ERROR_OUT_OF_DEVICE_MEMORY => VkError::OutOfDeviceMemory { label: "device".into(), bytes: 0 },
        e => VkError::vk("vkCreateDevice", e),
    })?;
    Ok((device, chosen))
}
