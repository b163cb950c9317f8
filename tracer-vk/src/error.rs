//! The crate's one error type. Every `Display` is a single sentence for the person running the
//! program; details that do not fit (naga's full diagnostics) stay in the fields.

use ash::vk;

const INSTALL_HINT: &str = "install libvulkan1 and a Vulkan driver, e.g. `apt-get install mesa-vulkan-drivers \
                            libvulkan1` for the lavapipe CPU device";

#[derive(Debug, thiserror::Error)]
pub enum VkError {
    /// The loader library could not be opened; the field is the dynamic linker's reason.
    #[error("no Vulkan loader was found ({0}): {INSTALL_HINT}")]
    NoLoader(String),
    #[error("no Vulkan device with a compute queue was found: {INSTALL_HINT}")]
    NoDevice,
    #[error(
        "there is no Vulkan device number {index}: only {count} were found, numbered from 0 (`trace-vk devices` lists them)"
    )]
    DeviceIndex { index: usize, count: usize },
    #[error(
        "buffer `{label}` needs {bytes} bytes, more than this device's maxStorageBufferRange of {limit} bytes for one \
         storage buffer binding"
    )]
    BufferTooLarge { label: String, bytes: u64, limit: u64 },
    #[error("the GPU ran out of memory while allocating buffer `{label}` ({bytes} bytes)")]
    OutOfDeviceMemory { label: String, bytes: u64 },
    #[error(
        "the Vulkan device was lost (driver reset or crash, often a kernel that ran too long or read out of bounds)"
    )]
    DeviceLost,
    #[error("the GPU did not finish its work within {seconds} s, so the run was abandoned")]
    Timeout { seconds: u64 },
    /// `message` holds naga's full rendered diagnostic; only its first line is displayed.
    #[error("shader `{label}` did not compile: {}", first_line(message))]
    Shader { label: String, message: String },
    #[error("{0}")]
    Validation(String),
    /// A call into this crate's API that cannot be right (wrong binding count, data larger than its
    /// buffer, ...): a bug in the caller, reported instead of handed to the driver.
    #[error("{0}")]
    Usage(String),
    /// The device lacks what a method needs (rt-pipeline's extensions or limits): one sentence
    /// naming what is missing.
    #[error("{0}")]
    Unsupported(String),
    #[error("the Vulkan call {what} failed with {}", result_text(*result))]
    Vulkan { what: &'static str, result: i32 },
}

impl VkError {
    /// Maps a failed Vulkan call. Device loss gets its own variant because callers and users act on
    /// it differently (nothing on this device will work again).
    pub fn vk(what: &'static str, result: vk::Result) -> VkError {
        match result {
            vk::Result::ERROR_DEVICE_LOST => VkError::DeviceLost,
            _ => VkError::Vulkan { what, result: result.as_raw() },
        }
    }

    /// Like [`VkError::vk`], for calls that allocate on behalf of a named buffer.
    pub(crate) fn alloc(what: &'static str, result: vk::Result, label: &str, bytes: u64) -> VkError {
        match result {
            vk::Result::ERROR_OUT_OF_DEVICE_MEMORY | vk::Result::ERROR_OUT_OF_HOST_MEMORY => {
                VkError::OutOfDeviceMemory { label: label.to_string(), bytes }
            }
            _ => VkError::vk(what, result),
        }
    }
}

/// `ERROR_OUT_OF_DEVICE_MEMORY (a device memory allocation has failed)`: the name to search for and
/// ash's description.
fn result_text(raw: i32) -> String {
    let result = vk::Result::from_raw(raw);
    let description = result.to_string();
    let mut chars = description.chars();
    match chars.next() {
        Some(c) if description != format!("{result:?}") => {
            format!("{result:?} ({}{})", c.to_lowercase(), chars.as_str().trim_end_matches('.'))
        }
        _ => format!("{result:?}"),
    }
}

/// The first non-empty line, without naga's `error: ` prefix, so that `Display` stays one line.
fn first_line(message: &str) -> &str {
    let line = message.lines().map(str::trim).find(|l| !l.is_empty()).unwrap_or("unknown error");
    line.strip_prefix("error: ").unwrap_or(line)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_message_is_one_line() {
        let errors = [
            VkError::NoLoader("libvulkan.so.1: cannot open shared object file".into()),
            VkError::NoDevice,
            VkError::DeviceIndex { index: 3, count: 1 },
            VkError::BufferTooLarge { label: "nodes".into(), bytes: 1 << 30, limit: 1 << 27 },
            VkError::OutOfDeviceMemory { label: "nodes".into(), bytes: 1 << 30 },
            VkError::DeviceLost,
            VkError::Timeout { seconds: 120 },
            VkError::Unsupported(crate::rt::refusal("llvmpipe", "VK_KHR_acceleration_structure")),
            VkError::Shader { label: "k".into(), message: "error: expected `;`\n  ┌─ wgsl:1:1\n".into() },
            VkError::Vulkan { what: "vkCreateBuffer", result: vk::Result::ERROR_INITIALIZATION_FAILED.as_raw() },
        ];
        for e in errors {
            let s = e.to_string();
            assert!(!s.contains('\n'), "{s}");
            assert!(!s.ends_with('.'), "{s}");
        }
        let s = VkError::Shader { label: "k".into(), message: "error: expected `;`\nmore".into() }.to_string();
        assert_eq!(s, "shader `k` did not compile: expected `;`");
        let s = VkError::Vulkan { what: "vkCreateBuffer", result: -2 }.to_string();
        assert!(s.contains("ERROR_OUT_OF_DEVICE_MEMORY"), "{s}");
    }
}
