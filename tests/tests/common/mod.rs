//! What the GPU test files share: the shipped scenes compiled in memory, the Vulkan device, and
//! the comparison of a GPU image with the CPU's.

#![allow(dead_code)] // each test file uses its own part

use bvh_format::SceneFile;
use render_spec::{Image, Settings};
use std::path::Path;
use tracer_vk::Gpu;

/// A scene of `scenes/` (or of $SCENES_DIR, for a test binary run on another machine), compiled
/// with default settings.
pub fn compile(name: &str) -> SceneFile {
    compile_with(name, Default::default())
}

/// [`compile`] with the given node layouts (`Layouts::ALL` for the tests of `cwbvh`).
pub fn compile_with(name: &str, layouts: bvh_build::Layouts) -> SceneFile {
    compile_params(name, &Default::default(), layouts)
}

/// [`compile_with`] with the given build parameters.
pub fn compile_params(name: &str, params: &bvh_format::BuildParams, layouts: bvh_build::Layouts) -> SceneFile {
    let dir = std::env::var_os("SCENES_DIR")
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes"));
    let p = dir.join(name);
    let scene = bvh_build::import::load(&p, &Default::default()).expect("the scene imports");
    bvh_build::compile(&scene, params, layouts).expect("the scene compiles")
}

/// The first Vulkan device, with the validation layer on. Fails, never skips, without one.
pub fn gpu() -> Gpu {
    match Gpu::new(None, true) {
        Ok(g) => g,
        Err(e) => panic!("the GPU tests need a Vulkan device: {e}"),
    }
}

/// A frame of `scene` from its stored `camera` with the scene's lights and indirections, AOVs kept.
pub fn frame_settings(scene: &SceneFile, camera: &str, width: u32, height: u32, mode: render_spec::Mode) -> Settings {
    Settings {
        aovs: true,
        ..Settings::of_scene(
            scene,
            render_spec::CameraSpec::from(scene.camera(camera).expect("the camera exists")),
            mode,
            (width, height),
        )
    }
}

/// How a GPU image differs from the CPU's.
pub struct Diff {
    /// Share of pixels whose channels all lie within 1/255 of the CPU's.
    pub within_one: f64,
    pub flip_mean: f32,
    /// Pixels whose primary ray hit another triangle at another distance.
    pub prim_differs: usize,
    /// Pixels whose primary ray hit another triangle at the same distance (ties, shared edges).
    pub prim_ties: usize,
}

pub fn diff(cpu: &Image, gpu: &Image) -> Diff {
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
    let prims = aov.prim_diff(gpu);
    Diff { within_one: within as f64 / n as f64, flip_mean, prim_differs: prims.differs, prim_ties: prims.ties }
}

/// Asserts that a GPU frame (with AOVs) is the CPU's image: colours within 1/255 almost
/// everywhere, FLIP below 0.01, the same triangles but for ties, and the same rays of every kind.
pub fn assert_matches_cpu(what: &str, cpu: &Image, gpu: &Image) {
    assert_eq!((gpu.width, gpu.height), (cpu.width, cpu.height), "{what}: image size");
    let d = diff(cpu, gpu);
    println!(
        "{what}: {:.4}% of pixels within 1/255, FLIP mean {:.5}, triangle ids: {} differ at equal distance (ties), {} otherwise; rays GPU {:?} CPU {:?}",
        d.within_one * 100.0,
        d.flip_mean,
        d.prim_ties,
        d.prim_differs,
        gpu.rays,
        cpu.rays
    );
    assert!(d.within_one >= 0.999, "{what}: only {:.4}% of pixels within 1/255", d.within_one * 100.0);
    assert!(d.flip_mean < 0.01, "{what}: FLIP mean {}", d.flip_mean);
    assert_eq!(d.prim_differs, 0, "{what}: triangle ids differ beyond ties");
    assert!(d.prim_ties * 1000 <= cpu.rgb.len(), "{what}: {} ties is too many to be ties", d.prim_ties);
    assert_eq!(gpu.rays, cpu.rays, "{what}: primary, shadow and secondary rays");
}

/// An image's AOVs as bits (distances, normals, triangles, traversal costs), for comparisons that
/// must hold bit for bit (a NaN or a signed zero counts).
pub type AovBits = (Vec<u32>, Vec<[u32; 3]>, Vec<u32>, Vec<u32>, Vec<u32>);

/// [`AovBits`] of an image rendered with AOVs.
pub fn aov_bits(i: &Image) -> AovBits {
    let a = i.aov.as_ref().expect("AOVs were asked for");
    let t = a.t.iter().map(|x| x.to_bits()).collect();
    let n = a.normal.iter().map(|n| n.map(f32::to_bits)).collect();
    (t, n, a.prim.clone(), a.nodes.clone(), a.tris.clone())
}
