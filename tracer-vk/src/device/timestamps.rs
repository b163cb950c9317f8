//! GPU timestamps: query pools written by [`Recorder::mark`] and read back as [`Timings`].

use ash::vk;

use super::commands::{Recorder, RunState};
use super::gpu::Gpu;
use crate::error::VkError;

/// Timestamp queries per query pool; more pools are made when a run marks more often.
const QUERIES_PER_POOL: u32 = 64;

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

/// The mask of a queue's valid timestamp bits: counters of fewer than 64 bits wrap, so
/// differences are taken modulo the mask. 0 where the queue writes no timestamps.
pub(super) fn timestamp_mask(valid_bits: u32) -> u64 {
    if valid_bits >= 64 { u64::MAX } else { (1u64 << valid_bits) - 1 }
}

impl Recorder<'_> {
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
        // are created mid-recording valid without a separate reset pass. BOTTOM_OF_PIPE: the
        // stamp is written once everything recorded before it has finished.
        unsafe {
            device.cmd_reset_query_pool(self.cmd, pool, query, 1);
            device.cmd_write_timestamp(self.cmd, vk::PipelineStageFlags::BOTTOM_OF_PIPE, pool, query);
        }
    }
}

impl Gpu {
    /// The intervals between `marks`, read from the query pools of the finished run.
    pub(super) fn timings(&self, state: &RunState, marks: Vec<String>) -> Result<Timings, VkError> {
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
}
