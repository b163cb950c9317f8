//! A scene moved far from the origin together with its camera and light renders the image it
//! renders at the origin (issue 9): the importer places it in f64 and the compiler keeps it
//! relative to its own centre (the file's origin offset), so its f32 coordinates keep the
//! precision they have at the origin.

mod common;

use bvh_format::SceneFile;
use render_spec::{CameraSpec, Image, Mode, Settings};
use tools::stress::scenes::{import_description, mirror_room};
use tracer_cpu::{Method, Tracer};

/// The mirror room moved by `10^k` along a direction that is not axis-parallel.
fn moved(k: i32) -> SceneFile {
    let d = 10f64.powi(k);
    let scene = import_description(&mirror_room([d, 0.7 * d, -0.3 * d])).expect("the scene imports");
    bvh_build::compile(&scene, &Default::default(), Default::default()).expect("the scene compiles")
}

fn at_origin() -> SceneFile {
    let scene = import_description(&mirror_room([0.0; 3])).expect("the scene imports");
    bvh_build::compile(&scene, &Default::default(), Default::default()).expect("the scene compiles")
}

fn settings(scene: &SceneFile) -> Settings {
    Settings {
        aovs: true,
        accuracy: Default::default(),
        ..Settings::of_scene(scene, CameraSpec::from(&scene.cameras[0]), Mode::Whitted, (160, 120))
    }
}

fn cpu(scene: &SceneFile) -> Image {
    tracer_cpu::render(&Tracer::new(scene), &settings(scene), Method::Ordered).expect("the CPU renders")
}

fn flip(a: &Image, b: &Image) -> f32 {
    common::diff(a, b).flip_mean
}

#[test]
fn a_scene_moved_by_up_to_a_million_renders_the_image_it_renders_at_the_origin() {
    let origin = at_origin();
    assert_eq!(origin.origin, [0.0; 3], "a scene at the origin keeps its coordinates");
    let reference = cpu(&origin);
    for k in 0..=6 {
        let scene = moved(k);
        let d = 10f64.powi(k);
        // The offset lies within one scene size of the scene's centre, and the stored coordinates
        // are small: what the precision depends on.
        for (a, w) in [d, 0.7 * d, -0.3 * d].into_iter().enumerate() {
            assert!((scene.origin[a] - w).abs() <= 16.0, "10^{k}: origin {:?}", scene.origin);
        }
        let (lo, hi) = scene.bounds();
        assert!(lo.iter().chain(&hi).all(|v| v.abs() <= 32.0), "10^{k}: local bounds {lo:?} {hi:?}");
        let image = cpu(&scene);
        let f = flip(&reference, &image);
        println!("10^{k}: origin {:?}, FLIP against the origin {f:.5}", scene.origin);
        assert!(f < 0.005, "10^{k}: FLIP {f} against the image at the origin");
    }
}

#[test]
fn the_vulkan_tracer_renders_a_scene_a_million_units_away_like_the_cpu_at_the_origin() {
    let gpu = common::gpu();
    let reference = cpu(&at_origin());
    let scene = moved(6);
    for method in [tracer_vk::kernels::Method::Lst, tracer_vk::kernels::Method::Stackless] {
        let mut r = tracer_vk::render::Renderer::new(&gpu, &scene, method, (8, 8)).expect("the scene uploads");
        let image = r.render(&settings(&scene)).expect("the GPU renders").image;
        let f = flip(&reference, &image);
        println!("{} at 10^6: FLIP against the CPU at the origin {f:.5}", method.name());
        assert!(f < 0.005, "{} at 10^6: FLIP {f}", method.name());
    }
    assert!(gpu.validation_messages().is_empty());
}

#[test]
fn a_file_with_an_origin_offset_round_trips() {
    let scene = moved(6);
    assert_ne!(scene.origin, [0.0; 3]);
    let bytes = bvh_format::write(&scene).expect("the scene writes");
    let back = bvh_format::read(&bytes).expect("the file reads");
    assert_eq!(back, scene);
    // World positions come back through the offset: the camera stands where the description
    // put it, to f32 precision of its local coordinates.
    let eye = back.world(back.cameras[0].eye);
    let expected = [0.5 + 1e6, 3.5 + 0.7e6, 8.0 - 0.3e6];
    for a in 0..3 {
        assert!((eye[a] - expected[a]).abs() < 1e-5, "eye {eye:?}, expected {expected:?}");
    }
    assert_eq!(back.local(expected), back.cameras[0].eye);
}
