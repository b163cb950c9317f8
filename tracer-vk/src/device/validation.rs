//! The Khronos validation layer: checking that it is installed, and the messenger that records
//! its errors and warnings into a [`ValidationLog`].

use std::ffi::{CStr, c_void};
use std::sync::{Arc, Mutex, PoisonError};

use ash::vk;

use crate::error::VkError;

pub(super) const VALIDATION_LAYER: &CStr = c"VK_LAYER_KHRONOS_validation";

/// The validation messages of one [`Gpu`](super::Gpu), readable after the `Gpu` (and its buffers)
/// are gone, which is when the layer reports leaked objects.
#[derive(Clone, Debug, Default)]
pub struct ValidationLog(Arc<Mutex<Vec<String>>>);

impl ValidationLog {
    pub fn messages(&self) -> Vec<String> {
        self.0.lock().unwrap_or_else(PoisonError::into_inner).clone()
    }
}

/// Refuses with the install command when the layer is missing, instead of the loader's bare
/// ERROR_LAYER_NOT_PRESENT from vkCreateInstance.
pub(super) fn require_layer(entry: &ash::Entry) -> Result<(), VkError> {
    // SAFETY: plain query.
    let layers = unsafe { entry.enumerate_instance_layer_properties() }
        .map_err(|e| VkError::vk("vkEnumerateInstanceLayerProperties", e))?;
    if layers.iter().any(|l| l.layer_name_as_c_str() == Ok(VALIDATION_LAYER)) {
        return Ok(());
    }
    Err(VkError::Validation(
        "the Vulkan validation layer VK_LAYER_KHRONOS_validation is not installed (on Debian or Ubuntu: \
         `apt-get install vulkan-validationlayers`)"
            .to_string(),
    ))
}

/// The messenger that appends to `log`. Errors and warnings only: the layer's info and verbose
/// output would bury them. Performance warnings are kept because they name real costs.
pub(super) fn messenger_info(log: &ValidationLog) -> vk::DebugUtilsMessengerCreateInfoEXT<'static> {
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

/// A messenger of its own on `instance`: the one chained into vkCreateInstance only reports during
/// vkCreateInstance and vkDestroyInstance. The caller keeps `log` alive until the messenger is destroyed.
pub(super) fn create_messenger(
    entry: &ash::Entry,
    instance: &ash::Instance,
    log: &ValidationLog,
) -> Result<(ash::ext::debug_utils::Instance, vk::DebugUtilsMessengerEXT), VkError> {
    let utils = ash::ext::debug_utils::Instance::new(entry, instance);
    let info = messenger_info(log);
    // SAFETY: valid create info; `log` outlives the messenger (the caller's duty).
    let m = unsafe { utils.create_debug_utils_messenger(&info, None) }
        .map_err(|e| VkError::vk("vkCreateDebugUtilsMessengerEXT", e))?;
    Ok((utils, m))
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
