//! Scenes and random rays shared by the tracer's integration tests.
#![allow(dead_code)]

use bvh_format::SceneFile;
use glam::Vec3;
use std::path::{Path, PathBuf};

pub fn scenes_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}

/// Imports and compiles a scene with both layouts and the default build parameters.
pub fn compile(path: &Path) -> SceneFile {
    let scene = bvh_build::import::load(path, &Default::default()).expect("the scene imports");
    bvh_build::compile(&scene, &Default::default(), Default::default()).expect("the scene compiles")
}

/// Compiles a scene description given as text.
pub fn compile_toml(name: &str, text: &str) -> SceneFile {
    // One folder per call: tests run on several threads of one process, and two may compile the
    // same scene at once (one would delete the other's file).
    static CALLS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let call = CALLS.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("tracer-cpu-test-{}-{call}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(format!("{name}.toml"));
    std::fs::write(&p, text).unwrap();
    let f = compile(&p);
    let _ = std::fs::remove_dir_all(&dir);
    f
}

/// A UV sphere of radius 1 (4,032 triangles), to probe shared edges and vertices everywhere.
pub fn sphere_scene() -> SceneFile {
    compile_toml("sphere", "[[object]]\ntype = \"sphere\"\nradius = 1.0\nsegments = 64\nrings = 32\n")
}

pub use tests::Rng;

/// Random rays over a scene: from outside aimed at random points of the bounds, from inside in
/// random directions, and axis-parallel rays (one or two zero direction components, including
/// negative zeros), which stress the slab test.
pub fn random_rays(scene: &SceneFile, n: usize, seed: u64) -> Vec<(Vec3, Vec3)> {
    let (lo, hi) = scene.bounds();
    let (lo, hi) = (Vec3::from(lo), Vec3::from(hi));
    let centre = (lo + hi) * 0.5;
    let radius = (hi - lo).length() * 0.5;
    let mut rng = Rng(seed);
    let inside = |rng: &mut Rng| lo + (hi - lo) * Vec3::new(rng.unit(), rng.unit(), rng.unit());
    (0..n)
        .map(|i| match i % 5 {
            0 | 1 => {
                let o = centre + Vec3::from(rng.direction()) * radius * 2.0;
                let target = inside(&mut rng);
                (o, (target - o).normalize())
            }
            2 => (inside(&mut rng), Vec3::from(rng.direction())),
            3 => {
                let o = inside(&mut rng);
                let axis = rng.below(3);
                let mut d = Vec3::splat(-0.0);
                d[axis] = if rng.unit() < 0.5 { 1.0 } else { -1.0 };
                (o - d * radius * 2.0, d)
            }
            _ => {
                let o = centre + Vec3::from(rng.direction()) * radius * 1.5;
                let mut d = (inside(&mut rng) - o).normalize();
                d[rng.below(3)] = 0.0;
                (o, d.normalize_or(Vec3::X))
            }
        })
        .collect()
}
