//! The same scenes rendered by the Vulkan tracer and the CPU tracer, diffed pixel by pixel.
//!
//! Runs on whatever Vulkan device is present (lavapipe in CI) with the Khronos validation layer
//! on. Without a Vulkan loader or device these tests fail with the sentence that says what to
//! install: a skipped GPU test must never pass.

use bvh_format::SceneFile;
use render_spec::{CameraSpec, Image, Mode, NO_TRIANGLE, Settings};
use std::path::Path;
use tracer_cpu::{Method, Tracer};
use tracer_vk::Gpu;
use tracer_vk::kernels::Method as VkMethod;
use tracer_vk::render::Renderer;

fn compile(name: &str) -> SceneFile {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes").join(name);
    let scene = bvh_build::import::load(&p, &Default::default()).expect("the scene imports");
    bvh_build::compile(&scene, &Default::default(), Default::default()).expect("the scene compiles")
}

fn gpu() -> Gpu {
    match Gpu::new(None, true) {
        Ok(g) => g,
        Err(e) => panic!("the cross-backend tests need a Vulkan device: {e}"),
    }
}

struct Diff {
    within_one: f64,
    flip_mean: f32,
    prim_differs: usize,
    prim_ties: usize,
}

fn diff(cpu: &Image, gpu: &Image) -> Diff {
    let n = cpu.rgb.len();
    let within =
        cpu.rgb.iter().zip(&gpu.rgb).filter(|(a, b)| a.iter().zip(b.iter()).all(|(x, y)| x.abs_diff(*y) <= 1)).count();
    let flat = |rgb: &[[u8; 3]]| rgb.iter().flatten().copied().collect::<Vec<u8>>();
    let reference = nv_flip::FlipImageRgb8::with_data(cpu.width, cpu.height, &flat(&cpu.rgb));
    let test = nv_flip::FlipImageRgb8::with_data(gpu.width, gpu.height, &flat(&gpu.rgb));
    let error = nv_flip::flip(reference, test, nv_flip::DEFAULT_PIXELS_PER_DEGREE);
    let flip_mean = nv_flip::FlipPool::from_image(&error).mean();

    // Triangle ids: a different triangle at the same distance is an exact tie or a shared edge
    // (both backends round differently there); anything else is a real disagreement.
    let aov = cpu.aov.as_ref().expect("the CPU render keeps AOVs");
    let gpu = gpu.aov.as_ref().expect("the GPU render keeps AOVs");
    let (mut differs, mut ties) = (0, 0);
    for i in 0..n {
        if aov.prim[i] == gpu.prim[i] {
            continue;
        }
        let (a, b) = (aov.t[i], gpu.t[i]);
        let both_hit = aov.prim[i] != NO_TRIANGLE && gpu.prim[i] != NO_TRIANGLE;
        if both_hit && (a - b).abs() <= 1e-4 * a.abs().max(b.abs()) {
            ties += 1;
        } else {
            differs += 1;
        }
    }
    Diff { within_one: within as f64 / n as f64, flip_mean, prim_differs: differs, prim_ties: ties }
}

fn compare(scene_name: &str, scene: &SceneFile, camera: &str, gpu: &Gpu, w: u32, h: u32) {
    let cam = CameraSpec::from(scene.camera(camera).expect("the camera exists"));
    let tracer = Tracer::new(scene);
    for mode in [Mode::Cast, Mode::Whitted] {
        let settings = Settings {
            width: w,
            height: h,
            camera: cam,
            mode,
            lights: scene.lights.clone(),
            max_indirections: scene.settings.max_indirections,
            aovs: true,
        };
        let cpu = tracer_cpu::render(&tracer, &settings, Method::Ordered).expect("the CPU renders");
        for method in [VkMethod::Lst, VkMethod::Stackless, VkMethod::Sst, VkMethod::SstSubgroup] {
            let mut r = Renderer::new(gpu, scene, method, (8, 8)).expect("the scene uploads");
            let out = r.render(&settings).expect("the GPU renders").image;
            let d = diff(&cpu, &out);
            let what = format!("{scene_name} {camera} {mode:?} {}", method.name());
            println!(
                "{what}: {:.4}% of pixels within 1/255, FLIP mean {:.5}, triangle ids: {} differ at equal distance (ties), {} otherwise; rays GPU {:?} CPU {:?}",
                d.within_one * 100.0,
                d.flip_mean,
                d.prim_ties,
                d.prim_differs,
                out.rays,
                cpu.rays
            );
            assert!(d.within_one >= 0.999, "{what}: only {:.4}% of pixels within 1/255", d.within_one * 100.0);
            assert!(d.flip_mean < 0.01, "{what}: FLIP mean {}", d.flip_mean);
            assert_eq!(d.prim_differs, 0, "{what}: triangle ids differ beyond ties");
            assert!(d.prim_ties * 1000 <= (w * h) as usize, "{what}: {} ties is too many to be ties", d.prim_ties);
            assert_eq!(out.rays, cpu.rays, "{what}: primary, shadow and secondary rays");
        }
    }
    let messages = gpu.validation_messages();
    assert!(messages.is_empty(), "the validation layer reported: {messages:#?}");
}

#[test]
fn bunny_on_a_mirror_floor_matches_the_cpu() {
    let gpu = gpu();
    let scene = compile("bunny.toml");
    compare("bunny", &scene, "medium", &gpu, 160, 120);
}

#[test]
fn room_with_mirror_and_glass_matches_the_cpu() {
    let gpu = gpu();
    let scene = compile("room.toml");
    compare("room", &scene, "medium", &gpu, 160, 120);
    compare("room", &scene, "close-up", &gpu, 120, 90);
}

/// A scene whose tree is deeper than a fixed 32-entry stack could hold: pairs of triangles at
/// distances 8^-k from the origin, k = 0..40. The SAH peels them off one level at a time.
fn deep_scene() -> SceneFile {
    let mut scene = bvh_build::Scene::default();
    for k in 0..40 {
        let d = 8f32.powi(-k);
        let s = 0.3 * d;
        for sx in [1.0f32, -1.0] {
            let c = glam::Vec3::new(sx * d, 0.0, 0.0);
            let t = [c, c + glam::Vec3::new(s, 0.0, 0.0), c + glam::Vec3::new(0.0, s, 0.5 * s)];
            let n = (t[1] - t[0]).cross(t[2] - t[0]).normalize_or(glam::Vec3::Z);
            scene.positions.push(t);
            scene.normals.push([n; 3]);
            scene.material_ids.push(0);
        }
    }
    scene.materials.push(bvh_format::Material::default());
    scene.material_names.push("default".to_owned());
    // At the origin, where the chain of ever smaller pairs ends: every primary ray starts inside
    // all the nested boxes and walks the whole depth of the tree.
    scene.cameras.push(bvh_format::Camera::new("medium", [0.0; 3], [0.2, 0.1, 1.0], [0.0, 1.0, 0.0], 100.0));
    scene.lights.push(bvh_format::Light::new([0.5, 1.0, 2.0], [1.0; 3]));
    let params = bvh_format::BuildParams { max_leaf_size: 1, ..Default::default() };
    bvh_build::compile(&scene, &params, Default::default()).expect("the deep scene compiles")
}

#[test]
fn a_tree_deeper_than_32_levels_renders_with_stacks_sized_from_the_file() {
    let scene = deep_scene();
    let depth = scene.stats().max_depth;
    assert!(depth > 32, "the scene is meant to be deeper than 32 levels, it is {depth}");
    let gpu = gpu();
    let mut r = Renderer::new(&gpu, &scene, VkMethod::Lst, (8, 8)).unwrap();
    assert_eq!(r.specialisation().stack_size, depth, "the stacks hold exactly the file's depth");
    let cam = CameraSpec::from(&scene.cameras[0]);
    let out = r
        .render(&Settings {
            width: 96,
            height: 64,
            camera: cam,
            mode: Mode::Cast,
            lights: vec![],
            max_indirections: 0,
            aovs: true,
        })
        .unwrap();
    let deepest = out.image.aov.expect("AOVs were asked for").nodes.iter().copied().max().unwrap_or(0);
    assert!(deepest > 2 * 33, "some ray must walk below level 32 (most nodes tested by one ray: {deepest})");
    println!("deep scene: {} triangles, depth {depth}", scene.triangles.len());
    compare("deep", &scene, "medium", &gpu, 96, 64);
}

#[test]
fn an_sst_stack_or_leaf_beyond_shared_memory_is_a_clear_error() {
    // One leaf of 1,000 identical triangles: SST's leaf cache alone would need 48,000 bytes of
    // workgroup memory, more than lavapipe's 32 KiB or an H100's 48 KiB.
    let mut scene = bvh_build::Scene::default();
    let t = [glam::Vec3::ZERO, glam::Vec3::X, glam::Vec3::Y];
    scene.positions = vec![t; 1000];
    scene.normals = vec![[glam::Vec3::Z; 3]; 1000];
    scene.material_ids = vec![0; 1000];
    scene.materials.push(bvh_format::Material::default());
    scene.material_names.push("default".to_owned());
    let params = bvh_format::BuildParams { max_leaf_size: 1000, ..Default::default() };
    let file = bvh_build::compile(&scene, &params, Default::default()).unwrap();
    let gpu = gpu();
    let e = Renderer::new(&gpu, &file, VkMethod::Sst, (8, 8)).err().expect("SST must refuse this scene");
    let msg = e.to_string();
    assert!(msg.contains("workgroup memory") && msg.contains("use LST"), "{msg}");
    assert!(!msg.contains('\n'));
    // LST renders it.
    assert!(Renderer::new(&gpu, &file, VkMethod::Lst, (8, 8)).is_ok());
}

/// The per-pixel buffers of a frame this large exceed one storage buffer binding: the renderer
/// splits it into tiles, and every pixel still gets its primary ray.
#[test]
fn a_frame_beyond_the_storage_buffer_range_renders_in_tiles() {
    let gpu = gpu();
    let limit = gpu.info().max_storage_buffer_range;
    let scene = compile("room.toml");
    let mut r = Renderer::new(&gpu, &scene, VkMethod::Lst, (8, 8)).unwrap();
    // 32 bytes of path state per pixel: a square image just past the limit.
    let side = ((limit / 32) as f64).sqrt() as u32 + 2;
    let cam = CameraSpec::from(scene.camera("medium").unwrap());
    let s = Settings {
        width: side,
        height: side,
        camera: cam,
        mode: Mode::Cast,
        lights: vec![],
        max_indirections: 0,
        aovs: false,
    };
    let out = r.render(&s).expect("the frame renders in tiles").image;
    assert_eq!(out.rays.primary, side as u64 * side as u64);
    assert_eq!(out.rgb.len(), side as usize * side as usize);
    assert!(out.aov.is_none(), "AOVs were not asked for");
}
