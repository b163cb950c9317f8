//! Simulated device faults, for tests of what a caller does when the driver fails: a device that
//! is lost, memory that runs out, work that does not finish in time. Real faults cannot be made on
//! demand (lavapipe never loses its device, and exhausting a shared machine's memory to get an
//! out-of-memory answer would hurt everything else on it), so the device layer can be told to
//! answer as the driver would, through [`Gpu::simulate`] or, for a whole program, the variable
//! [`FAULT_VARIABLE`].

use std::sync::PoisonError;

use super::gpu::Gpu;
use crate::error::VkError;

/// The environment variable a [`Gpu`] reads when it opens: `device-lost`, `timeout`, or
/// `out-of-memory:BYTES` (see [`Fault`]).
pub const FAULT_VARIABLE: &str = "TRACER_VK_FAULT";

/// A fault for the device layer to report as the driver would.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fault {
    /// Every [`Gpu::run`] from now on ends with `VK_ERROR_DEVICE_LOST` after its work was
    /// submitted, and so does every later submission (a lost device stays lost).
    DeviceLost,
    /// Every [`Gpu::run`] from now on ends as its wait timed out ([`VkError::Timeout`]), after the
    /// work has in fact finished.
    Timeout,
    /// Every buffer allocation of more than this many bytes fails with
    /// `VK_ERROR_OUT_OF_DEVICE_MEMORY`.
    OutOfMemory(u64),
}

impl Fault {
    /// The fault [`FAULT_VARIABLE`] names; `None` when it is unset or empty.
    pub fn from_env() -> Result<Option<Fault>, VkError> {
        match std::env::var(FAULT_VARIABLE) {
            Ok(v) if !v.is_empty() => Fault::parse(&v).map(Some),
            _ => Ok(None),
        }
    }

    pub fn parse(text: &str) -> Result<Fault, VkError> {
        let bad = || {
            VkError::Usage(format!(
                "{FAULT_VARIABLE}={text:?} is not a fault: use device-lost, timeout or out-of-memory:BYTES"
            ))
        };
        match text {
            "device-lost" => Ok(Fault::DeviceLost),
            "timeout" => Ok(Fault::Timeout),
            _ => {
                let bytes = text.strip_prefix("out-of-memory:").ok_or_else(bad)?;
                bytes.parse().map(Fault::OutOfMemory).map_err(|_| bad())
            }
        }
    }
}

impl Gpu {
    /// From now on, reports `fault` as the driver would (`None`: stops simulating; a device
    /// already reported lost stays lost).
    pub fn simulate(&self, fault: Option<Fault>) {
        *self.inner.fault.lock().unwrap_or_else(PoisonError::into_inner) = fault;
    }

    /// The simulated fault, if any.
    pub(super) fn fault(&self) -> Option<Fault> {
        *self.inner.fault.lock().unwrap_or_else(PoisonError::into_inner)
    }
}
