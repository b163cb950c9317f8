//! The builder's hot loops compiled for AVX2 where the processor has it.
//!
//! The crate is compiled for the x86-64 baseline (SSE2), so that the compiler runs anywhere; its
//! binning, partition and small-subtree sweeps are compiled a second time for x86-64-v3 (AVX2,
//! BMI, FMA) and that copy runs where the processor supports it: the three-operand and blend
//! instructions cut a binned build's CPU time by about 3 % (the bunny, AMD EPYC, one thread; the
//! whole crate compiled for x86-64-v3, 6 %: docs/build-benchmark.md).
//! The arithmetic is the same instructions' (no multiply-add is formed without being asked
//! for), so both copies build the same tree: `build::tests::both_copies_build_the_same_tree`.

use std::sync::atomic::{AtomicBool, Ordering};

/// Runs `f` compiled for AVX2 where the processor has it, else as compiled for the baseline.
/// `f` and what it inlines take on the features; what it calls without inlining does not, so
/// the hot functions it reaches are `#[inline(always)]`.
#[inline(always)]
pub(crate) fn fastest<R>(f: impl FnOnce() -> R) -> R {
    #[cfg(target_arch = "x86_64")]
    if avx2() {
        // SAFETY: the processor supports every feature `on_avx2` is compiled for.
        return unsafe { on_avx2(f) };
    }
    f()
}

/// Set by tests to run the baseline copy on a processor with AVX2 too.
static BASELINE_ONLY: AtomicBool = AtomicBool::new(false);

/// Makes [`fastest`] run the baseline copy (`true`) or the fastest one again (`false`). Both build
/// the same tree, so builds running meanwhile on other threads are not disturbed.
#[cfg(test)]
pub(crate) fn baseline_only(on: bool) {
    BASELINE_ONLY.store(on, Ordering::Relaxed);
}

/// Whether the AVX2 copies run: the processor has x86-64-v3's features and no test asked for the
/// baseline.
#[cfg(target_arch = "x86_64")]
pub(crate) fn avx2() -> bool {
    !BASELINE_ONLY.load(Ordering::Relaxed) && detected()
}

/// Whether the processor has the features the AVX2 copies are compiled for, detected once (the
/// check guards every split).
#[cfg(target_arch = "x86_64")]
pub(crate) fn detected() -> bool {
    static DETECTED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *DETECTED.get_or_init(|| {
        is_x86_feature_detected!("avx2")
            && is_x86_feature_detected!("fma")
            && is_x86_feature_detected!("bmi1")
            && is_x86_feature_detected!("bmi2")
            && is_x86_feature_detected!("lzcnt")
            && is_x86_feature_detected!("popcnt")
    })
}

/// # Safety
/// The processor must support every feature named here ([`avx2`]). The same list as
/// `build::Subtree::node_avx2`'s (an attribute takes no constant).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx,avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
unsafe fn on_avx2<R>(f: impl FnOnce() -> R) -> R {
    f()
}
