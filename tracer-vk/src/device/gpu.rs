//! [`Gpu`], an open device with one compute queue, and the shared core ([`Inner`]) that every
//! buffer and pipeline holds so that the device outlives them.

use std::ffi::CString;
use std::sync::atomic::AtomicBool;
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::thread::ThreadId;
use std::time::Duration;

use ash::vk;

use super::Buffer;
use super::commands::{RunState, nanos};
use super::fault::Fault;
use super::info::DeviceInfo;
use super::instance::{create_instance, instance_api, load_entry, open_device};
use super::timestamps::timestamp_mask;
use super::validation::{ValidationLog, create_messenger, require_layer};
use crate::error::VkError;

/// An open device with one compute queue.
pub struct Gpu {
    pub(super) inner: Arc<Inner>,
    pub(super) state: Mutex<RunState>,
    /// Which thread holds `state`, so that calling `upload` from inside `run`'s closure is an error
    /// instead of a deadlock.
    holder: Mutex<Option<ThreadId>>,
    /// How long [`Gpu::run`], [`Gpu::upload`] and [`Gpu::download`] wait for the GPU before giving
    /// up with [`VkError::Timeout`].
    pub timeout: Duration,
}

/// What buffers and pipelines need to free themselves: they hold an `Arc` to it, so the device
/// lives until the last of them is dropped, whatever order the caller drops things in.
pub(super) struct Inner {
    // The loader library must stay loaded until the instance is destroyed (Drop below runs first).
    _entry: ash::Entry,
    instance: ash::Instance,
    messenger: Option<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT)>,
    names: Option<ash::ext::debug_utils::Device>,
    pub(super) device: ash::Device,
    pub(super) queue: vk::Queue,
    family: u32,
    pub(super) memory: vk::PhysicalDeviceMemoryProperties,
    pub(super) info: DeviceInfo,
    /// The valid bits of a timestamp; 0 where the queue writes none.
    pub(super) timestamp_mask: u64,
    log: ValidationLog,
    /// Objects dropped while a submission abandoned by a timeout may still use them.
    retired: Mutex<Retired>,
    /// The fault the layer simulates ([`Gpu::simulate`]).
    pub(super) fault: Mutex<Option<Fault>>,
    /// The device was reported lost (simulated): every later submission fails alike.
    pub(super) lost: AtomicBool,
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
    pub(super) fn retire_buffer(&self, buffer: vk::Buffer, memory: vk::DeviceMemory) -> bool {
        let mut r = self.retired.lock().unwrap_or_else(PoisonError::into_inner);
        if r.in_flight {
            r.buffers.push((buffer, memory));
        }
        r.in_flight
    }

    pub(super) fn retire_pipeline(
        &self,
        p: vk::Pipeline,
        layout: vk::PipelineLayout,
        set: vk::DescriptorSetLayout,
    ) -> bool {
        let mut r = self.retired.lock().unwrap_or_else(PoisonError::into_inner);
        if r.in_flight {
            r.pipelines.push((p, layout, set));
        }
        r.in_flight
    }

    /// Marks abandoned work as finished (or not) and destroys what waited for it.
    pub(super) fn set_in_flight(&self, in_flight: bool) {
        let mut r = self.retired.lock().unwrap_or_else(PoisonError::into_inner);
        r.in_flight = in_flight;
        if !in_flight {
            // SAFETY: the caller saw the abandoned submission finish.
            unsafe { r.destroy(&self.device) };
        }
    }

    /// Names `handle` for the validation layer's messages (only when validating).
    pub(super) fn name<H: vk::Handle>(&self, handle: H, label: &str) {
        if let (Some(names), Ok(name)) = (&self.names, CString::new(label)) {
            let info = vk::DebugUtilsObjectNameInfoEXT::default().object_handle(handle).object_name(&name);
            // SAFETY: `handle` is a live object of this device. A failure only loses a debug name.
            let _ = unsafe { names.set_debug_utils_object_name(&info) };
        }
    }

    /// Whether an object holding `inner` was made by this device.
    pub(super) fn owns(&self, inner: &Arc<Inner>) -> bool {
        std::ptr::eq(Arc::as_ptr(inner), self)
    }
}

/// The state lock, with the holder's thread recorded while it is held.
pub(super) struct StateGuard<'a> {
    pub(super) state: MutexGuard<'a, RunState>,
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
    /// Opens device `choice` (an index into [`list_devices`](super::list_devices)), or else the
    /// first discrete GPU, the first integrated one, or the first device of any kind. With
    /// `validation`, the Khronos validation layer is enabled and its errors and warnings are
    /// recorded (see [`Gpu::validation_messages`]).
    ///
    /// The variable [`FAULT_VARIABLE`](super::FAULT_VARIABLE) makes the device simulate a fault
    /// from the start (for tests of whole programs).
    pub fn new(choice: Option<usize>, validation: bool) -> Result<Gpu, VkError> {
        let fault = Fault::from_env()?;
        let entry = load_entry()?;
        let api = instance_api(&entry)?;
        let log = ValidationLog::default();
        if validation {
            require_layer(&entry)?;
        }
        let instance = create_instance(&entry, api, validation.then_some(&log))?;
        let opened = (|| {
            // `log` is kept alive by Inner until after the messenger is destroyed.
            let messenger = validation.then(|| create_messenger(&entry, &instance, &log)).transpose()?;
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
            timestamp_mask: timestamp_mask(candidate.timestamp_bits),
            log,
            retired: Mutex::new(Retired::default()),
            fault: Mutex::new(fault),
            lost: AtomicBool::new(false),
        });
        // From here on, a failure drops `gpu`, which destroys whatever was made (null handles are
        // valid arguments to vkDestroy*).
        let mut gpu = Gpu {
            inner,
            state: Mutex::new(RunState::empty()),
            holder: Mutex::new(None),
            timeout: Duration::from_secs(120),
        };
        let state = gpu.state.get_mut().unwrap_or_else(PoisonError::into_inner);
        state.create(&gpu.inner.device, gpu.inner.family)?;
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

    /// The ash device, for commands this API does not wrap (recorded through
    /// [`Recorder::raw`](super::Recorder::raw)).
    pub fn ash_device(&self) -> &ash::Device {
        &self.inner.device
    }

    /// The instance, for the extension function tables rt-pipeline loads.
    pub(crate) fn instance(&self) -> &ash::Instance {
        &self.inner.instance
    }

    /// The device's memory types, for the buffers rt-pipeline allocates itself.
    pub(crate) fn memory_properties(&self) -> &vk::PhysicalDeviceMemoryProperties {
        &self.inner.memory
    }

    pub fn set_timeout(&mut self, timeout: Duration) {
        self.timeout = timeout;
    }

    pub(super) fn check_buffer(&self, buf: &Buffer) -> Result<(), VkError> {
        if self.inner.owns(&buf.inner) {
            Ok(())
        } else {
            Err(VkError::Usage(format!("buffer `{}` belongs to another Gpu", buf.label)))
        }
    }

    /// The run state, refusing (instead of deadlocking) when this thread already holds it.
    pub(super) fn lock(&self) -> Result<StateGuard<'_>, VkError> {
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
}
