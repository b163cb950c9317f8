//! The Vulkan instance and the choice of a physical device: which devices qualify, what they
//! report ([`DeviceInfo`]), and opening the chosen one with its compute queue.

use std::ffi::CStr;

use ash::vk;

use super::info::{DeviceInfo, DeviceKind};
use super::validation::{VALIDATION_LAYER, ValidationLog, messenger_info};
use crate::error::VkError;

/// Every device that can run compute work, in the order [`Gpu::new`](super::Gpu::new) numbers
/// them.
pub fn list_devices() -> Result<Vec<DeviceInfo>, VkError> {
    let entry = load_entry()?;
    let api = instance_api(&entry)?;
    let instance = create_instance(&entry, api, None)?;
    let found = candidates(&instance, api);
    // SAFETY: nothing made from this instance outlives this function.
    unsafe { instance.destroy_instance(None) };
    Ok(found?.into_iter().map(|c| c.info).collect())
}

pub(super) fn load_entry() -> Result<ash::Entry, VkError> {
    // SAFETY: loading the system's Vulkan loader runs its initialisers, which is what it is for.
    unsafe { ash::Entry::load() }.map_err(|e| VkError::NoLoader(e.to_string()))
}

/// The API version to request: the loader's, at most 1.3 (what the code is written against).
pub(super) fn instance_api(entry: &ash::Entry) -> Result<u32, VkError> {
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

/// An instance, with the validation layer and a messenger into `validation` when given.
pub(super) fn create_instance(
    entry: &ash::Entry,
    api: u32,
    validation: Option<&ValidationLog>,
) -> Result<ash::Instance, VkError> {
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

/// A physical device that qualifies, with what opening it needs.
pub(super) struct Candidate {
    pub(super) physical: vk::PhysicalDevice,
    /// The compute queue family used.
    pub(super) family: u32,
    pub(super) timestamp_bits: u32,
    pub(super) memory: vk::PhysicalDeviceMemoryProperties,
    pub(super) info: DeviceInfo,
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
        // Driver and float-control properties are core in 1.2; chaining them on a 1.1 device is
        // invalid usage.
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
        // The subgroup operations the SST-subgroup kernel may use (its vote sum is a subgroupAdd).
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
                // SAFETY: `physical` belongs to `instance`.
                rt_pipeline: unsafe { crate::rt::query_support(instance, physical, api) },
            },
        });
    }
    Ok(out)
}

/// Opens device `choice`, or else the first discrete GPU, the first integrated one, or the first
/// device of any kind.
pub(super) fn open_device(
    instance: &ash::Instance,
    api: u32,
    choice: Option<usize>,
) -> Result<(ash::Device, Candidate), VkError> {
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
    // Vulkan 1.1 device qualifies. rt-pipeline's are, where the device has them (crate::rt).
    let mut info = vk::DeviceCreateInfo::default().queue_create_infos(&queues);
    let rt_extensions = crate::rt::EXTENSIONS.map(|e| e.as_ptr());
    let mut rt = crate::rt::Features::wanted();
    if chosen.info.rt_pipeline.is_supported() {
        info = info
            .enabled_extension_names(&rt_extensions)
            .push_next(&mut rt.v12)
            .push_next(&mut rt.accel)
            .push_next(&mut rt.pipeline);
    }
    // SAFETY: valid create info for a device of this instance.
    let device = unsafe { instance.create_device(chosen.physical, &info, None) }.map_err(|e| match e {
        vk::Result::ERROR_OUT_OF_DEVICE_MEMORY => VkError::OutOfDeviceMemory { label: "device".into(), bytes: 0 },
        e => VkError::vk("vkCreateDevice", e),
    })?;
    Ok((device, chosen))
}
