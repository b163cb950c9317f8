//! A tilted grid of quads whose vertices lie on a camera's pixel rays, so that every primary ray
//! meets a shared edge at its midpoint, or a shared vertex, to within the rounding of the vertex
//! positions: where a triangle test that is not edge-consistent lets rays slip between two
//! triangles (issue 16). tests/tests/leaks.rs asserts on it; tools/examples/leak_table.rs counts
//! the leaks of our tests and Embree's on the same rays.

use bvh_build::Scene;
use bvh_format::{Camera, Material, SceneFile};
use glam::Vec3;
use render_spec::{CameraSpec, Mode, Settings};

/// Compiles triangles (flat normals, one default material) with the default build settings.
pub fn scene_of(tris: Vec<[Vec3; 3]>, camera: Option<Camera>) -> Result<SceneFile, String> {
    let n = tris.len();
    let scene = Scene {
        normals: tris.iter().map(|_| [Vec3::Z; 3]).collect(),
        positions: tris,
        material_ids: vec![0; n],
        materials: vec![Material::default()],
        material_names: vec![String::new()],
        cameras: camera.into_iter().collect(),
        ..Default::default()
    };
    bvh_build::compile(&scene, &Default::default(), Default::default()).map_err(|e| e.to_string())
}

/// Which pixel rays a camera grid aims at.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Aim {
    /// The midpoint of a shared (horizontal) edge.
    Edges,
    /// A shared vertex.
    Vertices,
}

/// A camera at distance `distance` from the origin looking at it, and an `n` x `n` image whose
/// every pixel ray meets the grid at a shared edge's midpoint or at a shared vertex.
///
/// Vertex (i, j) lies at `eye + s_j D(x, y)` on the unnormalised camera ray `D` of image point
/// (x, y) (pixel centres at +0.5), with the depth `s_j` of a plane through the origin tilted 35
/// degrees about the camera's horizontal axis: constant along a row, so the midpoint of two
/// neighbours in a row lies on the ray between them. For edges the vertices sit at pixel corners
/// in x, so the midpoint of each horizontal edge is a pixel centre; for vertices at pixel centres.
/// One extra row and column around the image keeps every aimed-at edge and vertex interior.
/// Returns also, per pixel, the vertices its ray is aimed at (both ends of its edge, or its vertex).
pub fn camera_grid(n: u32, distance: f32, aim: Aim) -> Result<(SceneFile, CameraSpec, Vec<Vec<Vec3>>), String> {
    let eye = Vec3::new(0.48, 0.6, 0.64) * distance;
    let fov = 2.0 * (0.4 / distance).atan().to_degrees();
    let cam = CameraSpec { eye, at: Vec3::ZERO, up: Vec3::Y, fov_deg: fov };
    let frame = cam.frame(n, n).map_err(|e| format!("{e:?}"))?;
    let [f, _, u] = cam.basis().map_err(|e| format!("{e:?}"))?;
    let tilt = 35f32.to_radians();
    let plane = -f * tilt.cos() + u * tilt.sin();
    let ray = |x: f32, y: f32| frame.top_left + x * frame.h_step + y * frame.v_step;
    let (x0, cols) = match aim {
        Aim::Edges => (0.0, n + 1),
        Aim::Vertices => (-0.5, n + 2),
    };
    let rows = n + 2;
    let vertex = |i: u32, j: u32| {
        let (x, y) = (x0 + i as f32, j as f32 - 0.5);
        let s = plane.dot(cam.at - eye) / plane.dot(ray(0.0, y));
        eye + s * ray(x, y)
    };
    let v: Vec<Vec<Vec3>> = (0..rows).map(|j| (0..cols).map(|i| vertex(i, j)).collect()).collect();
    let mut tris = Vec::new();
    for j in 0..rows as usize - 1 {
        for i in 0..cols as usize - 1 {
            let (a, b, c, d) = (v[j][i], v[j][i + 1], v[j + 1][i + 1], v[j + 1][i]);
            if (i + j) % 2 == 0 {
                tris.extend([[a, b, c], [a, c, d]]);
            } else {
                tris.extend([[a, b, d], [b, c, d]]);
            }
        }
    }
    let aimed = (0..n as usize)
        .flat_map(|y| (0..n as usize).map(move |x| (x, y)))
        .map(|(x, y)| match aim {
            Aim::Edges => vec![v[y + 1][x], v[y + 1][x + 1]],
            Aim::Vertices => vec![v[y + 1][x + 1]],
        })
        .collect();
    let camera = Camera::new("grid", cam.eye.into(), cam.at.into(), cam.up.into(), cam.fov_deg);
    Ok((scene_of(tris, Some(camera))?, cam, aimed))
}

/// Ray casting of an `n` x `n` image from `cam` with the primary hits' AOVs: a pixel whose `prim`
/// is `NO_TRIANGLE` is a ray that slipped through the grid.
pub fn cast_settings(cam: CameraSpec, n: u32) -> Settings {
    Settings {
        width: n,
        height: n,
        camera: cam,
        mode: Mode::Cast,
        lights: Vec::new(),
        max_indirections: 0,
        aovs: true,
        accuracy: Default::default(),
    }
}
