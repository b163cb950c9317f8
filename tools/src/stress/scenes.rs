//! Generated stress scenes: every scene of the sweep is made here by code, so that a point of a
//! chart can be reproduced from its axis and size alone.
//!
//! Scenes with cameras and lights are scene descriptions (TOML text) read through the same
//! importer a user's file goes through, so that the far-from-origin axis tests the f64 import and
//! the rebasing too; the others are triangle lists built directly.

use bvh_build::Scene;
use bvh_format::{Camera, Light, Material, SceneSettings};
use glam::Vec3;
use std::path::Path;

/// Width of the [`mirror_room`] floor, the "size" the distance axis is measured in.
pub const MIRROR_ROOM_SIZE: f64 = 12.0;

/// A mirror and shadow scene 12 units wide, moved with its camera and light by `offset`: a
/// weakly reflective floor, a mirror wall behind a box and a sphere that cast shadows, one light.
/// Far from the origin, f32 coordinates lose the low bits that tell the objects apart and shadow
/// rays start below the surface they leave (acne stripes): the far-from-origin axis.
pub fn mirror_room(offset: [f64; 3]) -> String {
    let p = |v: [f64; 3]| format!("[{:?}, {:?}, {:?}]", v[0] + offset[0], v[1] + offset[1], v[2] + offset[2]);
    let t = format!("[{:?}, {:?}, {:?}]", offset[0], offset[1], offset[2]);
    format!(
        r#"indirections = 4
[material.floor]
kd = [0.6, 0.6, 0.55]
ks = [0.2, 0.2, 0.2]
shininess = 40
kr = 0.25
[material.mirror]
kd = [0.02, 0.02, 0.02]
ks = [0.5, 0.5, 0.5]
shininess = 200
kr = 0.85
[material.red]
kd = [0.7, 0.15, 0.1]
[material.blue]
kd = [0.2, 0.3, 0.8]
ks = [0.5, 0.5, 0.5]
shininess = 60
[[object]]
type = "quad"
size = [12.0, 12.0]
material = "floor"
translate = {t}
[[object]]
type = "quad"
centre = [0.0, 2.5, -4.0]
size = [10.0, 5.0]
normal = [0.0, 0.0, 1.0]
material = "mirror"
translate = {t}
[[object]]
type = "box"
centre = [-1.5, 0.75, -0.5]
size = [1.5, 1.5, 1.5]
rotate = [0.0, 25.0, 0.0]
material = "red"
translate = {t}
[[object]]
type = "sphere"
centre = [1.6, 1.0, 0.5]
radius = 1.0
material = "blue"
translate = {t}
[[camera]]
name = "view"
eye = {eye}
at = {at}
fov = 50
[[light]]
position = {light}
"#,
        eye = p([0.5, 3.5, 8.0]),
        at = p([0.0, 1.0, -1.0]),
        light = p([3.0, 7.0, 4.0]),
    )
}

/// Imports a scene description given as text (written to a temporary file, removed again).
pub fn import_description(text: &str) -> Result<Scene, String> {
    let dir = std::env::temp_dir().join(format!("bvh-stress-{}-{:?}", std::process::id(), std::thread::current().id()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let path = dir.join("scene.toml");
    std::fs::write(&path, text).map_err(|e| e.to_string())?;
    let scene = bvh_build::import::load(&path, &Default::default()).map_err(|e| e.to_string());
    let _ = std::fs::remove_dir_all(&dir);
    scene
}

/// A scene of bare triangles (one grey material, flat normals) seen by `camera` and lit by
/// `lights`.
pub fn triangles(positions: Vec<[Vec3; 3]>, camera: Camera, lights: Vec<Light>, materials: Vec<Material>) -> Scene {
    let normals = positions
        .iter()
        .map(|&[a, b, c]| {
            let n = (b - a).as_dvec3().cross((c - a).as_dvec3());
            let n = if n.length() > 0.0 && n.is_finite() { n.normalize().as_vec3() } else { Vec3::Z };
            [n; 3]
        })
        .collect();
    let n = positions.len();
    let material_count = materials.len().max(1);
    let materials = if materials.is_empty() { vec![Material::default()] } else { materials };
    Scene {
        positions,
        normals,
        material_ids: (0..n as u32).map(|i| i % material_count as u32).collect(),
        material_names: (0..material_count).map(|i| format!("m{i}")).collect(),
        materials,
        cameras: vec![camera],
        lights,
        settings: SceneSettings { max_indirections: 0, ..SceneSettings::default() },
        ..Scene::default()
    }
}

/// Imports a description file from disk (for the shipped-scene parts of the sweep).
pub fn import_file(path: &Path) -> Result<Scene, String> {
    bvh_build::import::load(path, &Default::default()).map_err(|e| e.to_string())
}
