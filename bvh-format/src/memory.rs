//! Hints to the kernel about how to back large buffers.

/// Asks Linux to back `buf` with transparent huge pages (2 MiB) where its memory has not been
/// touched yet. A build of a million triangles writes about 170 MB of fresh memory (the
/// references, the spare buffer, the slots and the layouts; glibc maps every buffer above 32 MiB
/// afresh and unmaps it when freed), and with 4 KiB pages the kernel's fault handling took about
/// a sixth of its CPU time; a huge page is one fault per 512 of them.
/// Embree advises its large allocations the same way. Only a hint: where huge pages are off
/// (`/sys/kernel/mm/transparent_hugepage/enabled` set to `never`) or the call fails, nothing
/// changes but the speed. The contents are not touched, so the buffer's state does not change.
/// Buffers under `smallest` bytes are left alone. Here, below all of its users (bvh-build's
/// buffers, the reader's file buffer, tracer-cpu's wide BVHs), so that the one `unsafe` call to the
/// C library is written once.
pub fn advise_huge_pages<T>(buf: &mut [std::mem::MaybeUninit<T>], smallest: usize) {
    #[cfg(target_os = "linux")]
    {
        const HUGE: usize = 2 << 20;
        const PAGE: usize = 4096;
        /// `MADV_HUGEPAGE` of Linux's `<asm-generic/mman-common.h>` (the same on every architecture).
        const MADV_HUGEPAGE: std::ffi::c_int = 14;
        unsafe extern "C" {
            // The C library's, which the standard library links on Linux.
            fn madvise(addr: *mut std::ffi::c_void, len: usize, advice: std::ffi::c_int) -> std::ffi::c_int;
        }
        let (start, bytes) = (buf.as_mut_ptr() as usize, std::mem::size_of_val(buf));
        if bytes < smallest.max(HUGE) {
            return;
        }
        let (lo, hi) = (start.next_multiple_of(PAGE), (start + bytes) / PAGE * PAGE);
        // SAFETY: `[lo, hi)` lies within `buf`, memory this process owns; MADV_HUGEPAGE changes
        // how the kernel backs it, never its contents. The result is ignored: a hint.
        unsafe { madvise(lo as *mut std::ffi::c_void, hi - lo, MADV_HUGEPAGE) };
    }
    #[cfg(not(target_os = "linux"))]
    let _ = (buf, smallest);
}
