//! SST on large leaves (docs/stability.md, finding 8). SST stages a leaf's triangles in workgroup
//! memory; with naga's zero-initialisation of that memory, lavapipe compiled the kernels for
//! minutes once the cache held 256 triangles (a Whitted frame's first submission: 10 s for 8,
//! 99 s for 128, past the 120 s submission timeout for 256), and the stability sweep counted a
//! hang. Now workgroup memory is not zero-initialised (SST writes it before reading), and a leaf
//! larger than the cache the device's workgroup memory holds is tested in chunks instead of
//! being refused. Each frame must come within the time bound, with every primary hit right
//! against the f64 reference.

mod common;

use std::sync::Arc;
use std::time::Duration;
use tools::stress::cases::{self, AXES, Extent};
use tools::stress::{Method, check, report};
use tracer_vk::kernels::Method as Gpu;

#[test]
fn sst_renders_large_leaves_in_bounded_time_with_every_hit_right() {
    // Lavapipe keeps compiled kernels on disk; a kernel that compiled for minutes would come from
    // that cache in a second run. Set before the device (and its cache) is created, in the only
    // test of this process.
    unsafe { std::env::set_var("MESA_SHADER_CACHE_DISABLE", "true") };
    let gpu = Arc::new(common::gpu());
    let leaves: Vec<_> = cases::all(Extent::Full, 1000, &|a| a == AXES[8])
        .into_iter()
        .filter(|c| c.label == "256" || c.label == "1000")
        .collect();
    assert_eq!(leaves.len(), 2);
    // The one point per method is given 60 s, the first frame's compile included (about 2 to 6 s
    // on this 2-core VM's lavapipe now; the leaf of 256 took over 120 s before).
    let methods = [Method::Gpu(Gpu::Sst), Method::Gpu(Gpu::SstSubgroup)];
    let rows = tools::stress::sweep(leaves.clone(), &methods, Some(gpu.clone()), Duration::from_secs(60), &|r| {
        println!("leaf {} {}: {}", r.label, r.line(), report::cell(&r.tally));
    });
    assert_eq!(rows.len(), 4);
    for r in &rows {
        let t = &r.tally;
        assert!(
            t.refusal.is_none() && !r.failed() && t.pixels > 0,
            "leaf {} {}: {} {:?}",
            r.label,
            r.line(),
            report::cell(t),
            t.refusal
        );
    }

    // A leaf larger than the cache, in chunks of 7 triangles (the last one partial), on any
    // device: the same hits.
    let case = &leaves[0];
    let shot = &case.shots[0];
    let reference = check::reference(&case.scene, shot, case.near);
    for m in [Gpu::Sst, Gpu::SstSubgroup] {
        let mut r = tracer_vk::render::Renderer::new(&gpu, &case.scene, m, (8, 8)).expect("SST takes the leaf");
        assert_eq!(r.specialisation().leaf_size, 256, "{m:?}: the whole leaf fits any Vulkan device's 16 KiB");
        r.limit_leaf_cache(7);
        assert_eq!(r.specialisation().leaf_size, 7);
        let image = r.render(shot).expect("renders").image;
        let mut tally = tools::stress::Tally::default();
        check::tally_image(case, &reference, shot, &image, None, &mut tally);
        assert!(tally.pixels > 0 && !tally.silent_failure(), "{m:?} in chunks of 7: {}", report::cell(&tally));
    }
    assert!(gpu.validation_messages().is_empty(), "{:?}", gpu.validation_messages());
}
