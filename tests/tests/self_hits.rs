//! Exact acne (issue 8, `--self-hits`): both tracers count the rays leaving a surface that the
//! triangle they leave from meets (render_spec::SelfHits). A fixed origin offset too small for the
//! scene gives such rays where the scale-aware offset gives none, and the Vulkan kernels count
//! exactly what the CPU tracer counts, ray kind by ray kind, on every traversal of each.

mod common;

use bvh_format::SceneFile;
use render_spec::{Accuracy, Ao, CameraSpec, Image, Mode, Offset, SelfHits, Settings};
use tracer_cpu::{Method, Tracer};
use tracer_vk::kernels::Method as VkMethod;
use tracer_vk::render::Renderer;

/// A smooth sphere and a mirror floor under it, one light: every kind of ray that leaves a surface
/// (shadow, mirror, AO, diffuse) leaves one. The compiler stores the scene in a unit that makes it
/// a few units across, where the hit points are rounded to about 1e-7: a fixed offset of 1e-9
/// (in the stored unit, as Settings take it) leaves many of them below their surface.
fn scene() -> SceneFile {
    let text = "indirections = 4\nambient = [0.1, 0.1, 0.1]\n\
         [material.grey]\nkd = [0.8, 0.8, 0.8]\n\
         [material.mirror]\nkd = [0.2, 0.2, 0.2]\nkr = 0.6\n\
         [[object]]\ntype = \"sphere\"\nradius = 100.0\nsegments = 48\nrings = 24\nmaterial = \"grey\"\n\
         [[object]]\ntype = \"quad\"\ncentre = [0.0, -100.0, 0.0]\nsize = [600.0, 600.0]\nnormal = [0.0, 1.0, 0.0]\nmaterial = \"mirror\"\n\
         [[camera]]\nname = \"view\"\neye = [120.0, 160.0, 340.0]\nat = [0.0, -20.0, 0.0]\nfov = 50.0\n\
         [[light]]\nposition = [260.0, 150.0, 300.0]\n";
    let no_files = |p: &std::path::Path| -> std::io::Result<Vec<u8>> {
        Err(std::io::Error::other(format!("no file {} here", p.display())))
    };
    let s = bvh_build::import::load_bytes(
        std::path::Path::new("self_hits.toml"),
        text.as_bytes(),
        &Default::default(),
        &no_files,
    )
    .expect("the description imports");
    bvh_build::compile(&s, &Default::default(), Default::default()).expect("the scene compiles")
}

fn settings(scene: &SceneFile, mode: Mode, offset: Offset) -> Settings {
    Settings {
        accuracy: Accuracy { offset, ..Default::default() },
        ..Settings::of_scene(scene, CameraSpec::from(scene.camera("view").expect("the camera")), mode, (96, 72))
    }
}

fn cpu(scene: &SceneFile, s: &Settings, method: Method) -> Image {
    let mut tracer = Tracer::new(scene);
    tracer.count_self_hits(true);
    tracer_cpu::render(&tracer, s, method).expect("the CPU renders")
}

#[test]
fn both_tracers_count_the_same_rays_stopped_by_their_own_triangle() {
    let scene = scene();
    println!("the scene is stored in units of 2^{} (bounds {:?})", scene.scale_log2, scene.bounds());
    let gpu = common::gpu();
    let modes = [Mode::Whitted, Mode::Ao(Ao { samples: 4, length: 0.1 }), Mode::Diffuse];
    println!("mode | offset | CPU self-hits (shadow, secondary, AO, diffuse) of rays | GPU");
    let mut tiny = SelfHits::default();
    for mode in modes {
        for offset in [Offset::ScaleAware, Offset::Fixed(1e-9), Offset::Fixed(1e-2)] {
            let s = settings(&scene, mode, offset);
            let reference = cpu(&scene, &s, Method::Ordered);
            for method in [Method::Stackless, Method::Packet] {
                let other = cpu(&scene, &s, method).rays;
                assert_eq!(other, reference.rays, "{mode:?} {offset:?}: CPU {method:?} counts otherwise");
            }
            // Without counting, no count: the default renders stay as they were.
            let plain = tracer_cpu::render(&Tracer::new(&scene), &s, Method::Ordered).expect("the CPU renders");
            assert_eq!(plain.rays.self_hits, SelfHits::default(), "counted without --self-hits");
            assert_eq!(plain.rgb, reference.rgb, "counting changed the image");
            for method in [VkMethod::Lst, VkMethod::Stackless] {
                let name = method.name();
                let mut r = Renderer::new(&gpu, &scene, method, (8, 8)).expect("the scene uploads");
                // Exact kernels (`--exact`) round as the CPU does, so they must count what it counts;
                // the default kernels' contracted multiply-adds may move a hit point by an ulp, which
                // decides a ray that grazes its own triangle.
                r.set_exact(true);
                let plain = r.render(&s).expect("the GPU renders").image;
                assert_eq!(plain.rays.self_hits, SelfHits::default(), "{name}: counted without asking");
                r.set_self_hits(true);
                let counted = r.render(&s).expect("the GPU renders with the count").image;
                assert_eq!(counted.rgb, plain.rgb, "{name}: counting changed the image");
                r.set_exact(false);
                let fast = r.render(&s).expect("the default kernels render with the count").image;
                println!(
                    "{} | {offset:?} | {:?} of {} | {name}: exact {:?}, default kernels {:?}",
                    mode.name(),
                    reference.rays.self_hits,
                    reference.rays.total(),
                    counted.rays.self_hits,
                    fast.rays.self_hits
                );
                assert_eq!(counted.rays, reference.rays, "{mode:?} {offset:?}: {name} --exact counts otherwise");
                assert_eq!(
                    fast.rays.self_hits == SelfHits::default(),
                    reference.rays.self_hits == SelfHits::default(),
                    "{mode:?} {offset:?}: {name}'s default kernels count self-hits where the CPU has none or the other way round"
                );
            }
            match offset {
                Offset::ScaleAware => {
                    assert_eq!(reference.rays.self_hits, SelfHits::default(), "{mode:?}: the scale-aware offset")
                }
                Offset::Fixed(d) if d < 1e-3 => tiny = tiny + reference.rays.self_hits,
                // Far enough off the surface for any rounding: no ray meets its own triangle.
                Offset::Fixed(_) => assert_eq!(reference.rays.self_hits, SelfHits::default(), "{mode:?}: 1e-2"),
            }
        }
    }
    // The tiny offset stops rays of every kind on their own triangle.
    for (what, n) in
        [("shadow", tiny.shadow), ("secondary", tiny.secondary), ("AO", tiny.ao), ("diffuse", tiny.diffuse)]
    {
        assert!(n > 50, "a fixed offset of 1e-9 gave only {n} {what} self-hits");
    }
    let messages = gpu.validation_messages();
    assert!(messages.is_empty(), "the validation layer reported: {messages:#?}");
}
