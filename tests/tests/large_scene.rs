//! Issue 9 item 4: a scene larger than one storage buffer binding renders. The stability sweep's
//! terrain of 2.9 million triangles (138 MB of triangles at 48 bytes, 92 MB of nodes: 230 MB,
//! past lavapipe's maxStorageBufferRange of 128 MiB) is rendered by LST and stackless with the
//! device's own limits, so its triangles are split over two bindings there, and must give the
//! CPU's image. Takes about a minute on 2 cores, most of it compiling the scene.
//! tools/scripts/h100-size.sh does the same past the H100's 4 GiB.

mod common;

use render_spec::Mode;
use tracer_cpu::{Method, Tracer};
use tracer_vk::kernels::Method as VkMethod;
use tracer_vk::render::Renderer;

#[test]
fn a_scene_past_lavapipes_binding_range_renders_like_the_cpu() {
    let gpu = common::gpu();
    let scene = tools::stress::scenes::terrain(1200);
    let scene = bvh_build::compile(&scene, &Default::default(), Default::default()).expect("the terrain compiles");
    let tri_bytes = scene.triangles.len() as u64 * 48;
    assert!(tri_bytes > 128 << 20, "{tri_bytes} bytes of triangles fit one lavapipe binding");
    let info = gpu.info();
    let range = info.max_storage_buffer_range.min(info.max_memory_allocation);
    let settings = common::frame_settings(&scene, "view", 64, 48, Mode::Whitted);
    let cpu = tracer_cpu::render(&Tracer::new(&scene), &settings, Method::Ordered).expect("the CPU renders");
    for method in [VkMethod::Lst, VkMethod::Stackless] {
        let nodes = if method == VkMethod::Stackless { &scene.escape } else { &scene.child_pair };
        let node_bytes = nodes.as_ref().expect("both layouts").len() as u64 * 32;
        let mut r = Renderer::new(&gpu, &scene, method, (8, 8)).expect("the scene uploads");
        let split = r.specialisation().split;
        // As many bindings as the device's range needs (two for the triangles on lavapipe).
        assert_eq!(split.tri_chunks as u64, tri_bytes.div_ceil(range), "{split:?}");
        assert_eq!(split.node_chunks as u64, node_bytes.div_ceil(range), "{split:?}");
        let out = r.render(&settings).expect("the GPU renders").image;
        common::assert_matches_cpu(&format!("terrain of {} triangles, {split:?}", scene.triangles.len()), &cpu, &out);
    }
    assert!(gpu.validation_messages().is_empty(), "{:?}", gpu.validation_messages());
}
