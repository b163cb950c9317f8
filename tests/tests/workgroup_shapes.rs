//! Every workgroup shape `trace-vk --workgroup` accepts, with every GPU traversal, renders the
//! CPU's image (issue 15, item 1). On main, SST lost rows of rays or looped for minutes with
//! workgroups narrower than 8 on lavapipe, and rendered wrong images with fewer than 4
//! invocations on an H100.
//!
//! Images stay small, because lavapipe resumes an SST workgroup at every barrier in chunks of 8
//! invocations and runs workgroups of fewer than 8 invocations a hundred times slower than 8:
//! shapes of up to 32 invocations render an image one pixel larger than the shape in each
//! direction (three workgroups where a side is 1), so full and partial workgroups meet; larger
//! shapes render exactly one full workgroup. Partial workgroups of 8 x 8 are also tested in
//! `frames.rs` and `cross_backend.rs`.

mod common;

use bvh_format::SceneFile;
use common::{assert_matches_cpu, compile, gpu};
use render_spec::{CameraSpec, Mode, Settings};
use tracer_cpu::{Method, Tracer};
use tracer_vk::kernels::Method as VkMethod;
use tracer_vk::render::{MAX_WORKGROUP_INVOCATIONS, Renderer, allowed_workgroups};

/// Room from its medium camera, Whitted with the scene's lights, AOVs on.
fn settings(scene: &SceneFile, width: u32, height: u32) -> Settings {
    Settings {
        aovs: true,
        ..Settings::of_scene(
            scene,
            CameraSpec::from(scene.camera("medium").expect("room has a medium camera")),
            Mode::Whitted,
            (width, height),
        )
    }
}

/// SST walks one path per workgroup with a barrier per step: lavapipe runs a 1024-invocation
/// workgroup on one core and needs minutes per shape there, so on the CPU driver the SST tests stop
/// at `SST_LAVAPIPE_MAX` invocations; `WORKGROUP_SHAPES_ALL=1` (used on the H100) takes every shape.
const SST_LAVAPIPE_MAX: u32 = 256;

fn render_all_shapes(methods: &[VkMethod], max_invocations: u32) {
    let gpu = gpu();
    let limit = gpu.info().max_workgroup_invocations.min(gpu.info().max_workgroup_size[0]);
    assert!(limit >= MAX_WORKGROUP_INVOCATIONS, "this device allows only {limit} invocations; the test wants all");
    let shapes = allowed_workgroups(MAX_WORKGROUP_INVOCATIONS);
    assert_eq!(shapes.len(), 66, "powers of two from 1 to 1024 with at most 1024 invocations");
    // Room: reflection, refraction, total internal reflection and shadows from two lights.
    let scene = compile("room.toml");
    let tracer = Tracer::new(&scene);
    let mut references = std::collections::HashMap::new();
    let max_invocations =
        if std::env::var_os("WORKGROUP_SHAPES_ALL").is_some() { MAX_WORKGROUP_INVOCATIONS } else { max_invocations };
    for &(wx, wy) in shapes.iter().filter(|(x, y)| x * y <= max_invocations) {
        let side = |n: u32| {
            if wx * wy > 32 {
                n
            } else if n == 1 {
                3
            } else {
                n + 1
            }
        };
        let (w, h) = (side(wx), side(wy));
        let start = std::time::Instant::now();
        let cpu = references.entry((w, h)).or_insert_with(|| {
            tracer_cpu::render(&tracer, &settings(&scene, w, h), Method::Ordered).expect("the CPU renders")
        });
        for &method in methods {
            let mut r = Renderer::new(&gpu, &scene, method, (wx, wy)).expect("an allowed shape is taken");
            let out =
                r.render(&settings(&scene, w, h)).unwrap_or_else(|e| panic!("{} {wx}x{wy}: {e}", method.name())).image;
            assert_matches_cpu(&format!("{} {wx}x{wy} at {w}x{h}", method.name()), cpu, &out);
        }
        println!("{wx}x{wy}: {:.1} s", start.elapsed().as_secs_f64());
    }
    let messages = gpu.validation_messages();
    assert!(messages.is_empty(), "the validation layer reported: {messages:#?}");
}

#[test]
fn every_allowed_shape_renders_the_cpu_image_with_lst_and_stackless() {
    render_all_shapes(&[VkMethod::Lst, VkMethod::Stackless], MAX_WORKGROUP_INVOCATIONS);
}

#[test]
fn every_allowed_shape_renders_the_cpu_image_with_sst() {
    render_all_shapes(&[VkMethod::Sst], SST_LAVAPIPE_MAX);
}

#[test]
fn every_allowed_shape_renders_the_cpu_image_with_sst_subgroup() {
    render_all_shapes(&[VkMethod::SstSubgroup], SST_LAVAPIPE_MAX);
}

#[test]
fn shapes_outside_the_allowed_set_are_refused_in_one_sentence() {
    let gpu = gpu();
    let scene = compile("room.toml");
    for shape in [(3, 4), (0, 8), (8, 0), (64, 32), (6, 1)] {
        for method in [VkMethod::Lst, VkMethod::Stackless, VkMethod::Sst, VkMethod::SstSubgroup] {
            let e = Renderer::new(&gpu, &scene, method, shape).err().expect("the shape is refused");
            let msg = e.to_string();
            assert!(msg.contains("powers of two") && msg.contains("8x8") && !msg.contains('\n'), "{msg}");
        }
    }
}
