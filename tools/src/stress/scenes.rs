//! Generated stress scenes: every scene of the sweep is made here by code, so that a point of a
//! chart can be reproduced from its axis and size alone.
//!
//! Scenes with cameras and lights are scene descriptions (TOML text) read through the same
//! importer a user's file goes through, so that the far-from-origin axis tests the f64 import and
//! the rebasing too; the others are triangle lists built directly.

use bvh_build::Scene;
use bvh_format::{BuildParams, Camera, IndexedTriangle, Light, Material, Node, SceneFile, SceneSettings};
use glam::Vec3;

/// Width of the [`mirror_room`] floor, the "size" the distance axis is measured in.
pub const MIRROR_ROOM_SIZE: f64 = 12.0;

/// A mirror and shadow scene 12 units wide, moved with its camera and light by `offset`: a
/// weakly reflective floor, a mirror wall behind a box and a sphere that cast shadows, one light.
/// Far from the origin, f32 coordinates lose the low bits that tell the objects apart and shadow
/// rays start below the surface they leave (acne stripes): the far-from-origin axis.
pub fn mirror_room(offset: [f64; 3]) -> String {
    mirror_room_scaled(offset, 1.0)
}

/// [`mirror_room`] scaled by `scale` about its own origin, then moved by `offset`.
pub fn mirror_room_scaled(offset: [f64; 3], scale: f64) -> String {
    let p = |v: [f64; 3]| {
        format!("[{:?}, {:?}, {:?}]", v[0] * scale + offset[0], v[1] * scale + offset[1], v[2] * scale + offset[2])
    };
    let t = format!("[{:?}, {:?}, {:?}]\nscale = {scale:?}", offset[0], offset[1], offset[2]);
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

/// A scene of bare triangles with flat normals, material `i % materials.len()` for triangle `i`,
/// one camera and `lights`, not yet compiled.
pub fn triangles(positions: Vec<[Vec3; 3]>, camera: Camera, lights: Vec<Light>, materials: Vec<Material>) -> Scene {
    let normals = positions
        .iter()
        .map(|&[a, b, c]| {
            let n = (b - a).as_dvec3().cross((c - a).as_dvec3());
            let n = if n.length() > 0.0 && n.is_finite() { n.normalize().as_vec3() } else { Vec3::Z };
            [n; 3]
        })
        .collect();
    let materials = if materials.is_empty() { vec![Material::default()] } else { materials };
    let m = materials.len() as u32;
    Scene {
        material_ids: (0..positions.len() as u32).map(|i| i % m).collect(),
        material_names: (0..m).map(|i| format!("m{i}")).collect(),
        positions,
        normals,
        materials,
        cameras: vec![camera],
        lights,
        settings: SceneSettings::default(),
        ..Scene::default()
    }
}

/// The camera of the generated triangle scenes.
pub fn camera(eye: [f32; 3], at: [f32; 3], up: [f32; 3], fov: f32) -> Camera {
    Camera::new("view", eye, at, up, fov)
}

/// A grid of `n` x `n` unit squares in the plane z = 0, from (0, 0), two triangles each, so
/// that rays along the axes can be aimed exactly at its shared edges and vertices.
pub fn grid(n: u32) -> Vec<[Vec3; 3]> {
    let mut out = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let (x, y) = (i as f32, j as f32);
            let p = |dx: f32, dy: f32| Vec3::new(x + dx, y + dy, 0.0);
            out.push([p(0.0, 0.0), p(1.0, 0.0), p(1.0, 1.0)]);
            out.push([p(0.0, 0.0), p(1.0, 1.0), p(0.0, 1.0)]);
        }
    }
    out
}

/// A mirror tilted by `eps` about the y axis (the plane z = eps x, whose normal (-eps, 0, 1) has
/// a subnormal x component for a subnormal `eps`), seen by a camera in the plane x = 0 through a
/// frame one pixel wide, so that every primary ray has x = 0 and every reflected ray a subnormal
/// x component (2 eps d.z): its inverse is infinite in f32. The reflected rays run up a grid of
/// unit squares in the plane y = 6 whose shared edges lie on x = 0, exactly where they travel.
pub fn subnormal_mirror(eps: f32) -> Scene {
    let mut tris = vec![
        [Vec3::new(-2.0, -1.0, -2.0 * eps), Vec3::new(2.0, -1.0, 2.0 * eps), Vec3::new(2.0, 8.0, 2.0 * eps)],
        [Vec3::new(-2.0, -1.0, -2.0 * eps), Vec3::new(2.0, 8.0, 2.0 * eps), Vec3::new(-2.0, 8.0, -2.0 * eps)],
    ];
    // The wall: grid(4) in the plane y = 6, x in [-2, 2], z in [0, 16], facing -y.
    tris.extend(grid(4).into_iter().map(|t| {
        let [a, b, c] = t.map(|p| Vec3::new(p.x - 2.0, 6.0, 4.0 * p.y));
        [a, c, b]
    }));
    let mirror = Material { kd: [0.02; 3], ks: [0.0; 3], kr: 0.9, ..Material::default() };
    let wall = Material { kd: [0.9, 0.8, 0.3], ..Material::default() };
    let materials = (0..tris.len()).map(|i| if i < 2 { mirror } else { wall }).collect();
    let mut scene = triangles(
        tris,
        camera([0.0, 0.5, 1.0], [0.0, 4.0, 0.0], [0.0, 1.0, 0.0], 60.0),
        vec![Light::new([0.0, 3.0, 6.0], [1.0; 3])],
        materials,
    );
    scene.settings.max_indirections = 2;
    scene
}

/// A closed box of `n` x `n` squares per face around [0, n]^3, each face two triangles per square:
/// a watertight mesh that no ray from inside may leave.
pub fn closed_box(n: u32) -> Vec<[Vec3; 3]> {
    let s = n as f32;
    let mut out = Vec::new();
    // Each face as the grid mapped by (u, v) -> point, with the winding facing inward.
    type Face = fn(f32, f32, f32) -> Vec3;
    let faces: [(Face, bool); 6] = [
        (|u, v, _| Vec3::new(u, v, 0.0), false),
        (|u, v, s| Vec3::new(u, v, s), true),
        (|u, v, _| Vec3::new(0.0, u, v), false),
        (|u, v, s| Vec3::new(s, u, v), true),
        (|u, v, _| Vec3::new(v, 0.0, u), false),
        (|u, v, s| Vec3::new(v, s, u), true),
    ];
    for (f, flip) in faces {
        for [a, b, c] in grid(n) {
            let m = |p: Vec3| f(p.x, p.y, s);
            out.push(if flip { [m(a), m(c), m(b)] } else { [m(a), m(b), m(c)] });
        }
    }
    out
}

/// A fan of `n` triangles around the vertex (0, 0, 0) in the plane z = 0 (a disc of radius 1):
/// a vertex shared by `n` triangles.
pub fn fan(n: u32) -> Vec<[Vec3; 3]> {
    let at = |k: u32| {
        let a = std::f64::consts::TAU * f64::from(k % n) / f64::from(n);
        Vec3::new(a.cos() as f32, a.sin() as f32, 0.0)
    };
    (0..n).map(|k| [Vec3::ZERO, at(k), at(k + 1)]).collect()
}

/// The unit square cut into `count` strips of two needle triangles each (`count` times longer than
/// wide), side by side without gaps.
pub fn needles(count: u32) -> Vec<[Vec3; 3]> {
    let w = 1.0 / count as f64;
    let mut out = Vec::new();
    for i in 0..count {
        let (x0, x1) = ((i as f64 * w) as f32, (((i + 1) as f64) * w) as f32);
        out.push([Vec3::new(x0, 0.0, 0.0), Vec3::new(x1, 0.0, 0.0), Vec3::new(x1, 1.0, 0.0)]);
        out.push([Vec3::new(x0, 0.0, 0.0), Vec3::new(x1, 1.0, 0.0), Vec3::new(x0, 1.0, 0.0)]);
    }
    out
}

/// A hall of mirrors: a closed box whose six walls are mirrors (kr 1) around a diffuse sphere and
/// a light, seen from inside; every ray bounces until `max_indirections`.
pub fn hall_of_mirrors(indirections: u32) -> String {
    let mut s = format!(
        r#"indirections = {indirections}
[material.mirror]
kd = [0.05, 0.05, 0.05]
kr = 1.0
[material.ball]
kd = [0.8, 0.3, 0.2]
[[object]]
type = "sphere"
centre = [0.0, 0.0, 0.0]
radius = 0.6
material = "ball"
frame = false
"#
    );
    for (c, n) in [
        ([0.0, -2.0, 0.0], [0.0, 1.0, 0.0]),
        ([0.0, 2.0, 0.0], [0.0, -1.0, 0.0]),
        ([-2.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
        ([2.0, 0.0, 0.0], [-1.0, 0.0, 0.0]),
        ([0.0, 0.0, -2.0], [0.0, 0.0, 1.0]),
        ([0.0, 0.0, 2.0], [0.0, 0.0, -1.0]),
    ] {
        s += &format!(
            "[[object]]\ntype = \"quad\"\ncentre = {c:?}\nsize = [4.0, 4.0]\nnormal = {n:?}\nmaterial = \"mirror\"\n"
        );
    }
    s + r#"[[camera]]
name = "view"
eye = [1.5, 0.7, 1.6]
at = [0.0, 0.0, 0.0]
fov = 60
[[light]]
position = [-1.2, 1.5, 1.0]
"#
}

/// Glass inside glass: `nesting` concentric glass spheres (alternating indices of refraction)
/// over a checkered floor, seen from outside.
pub fn glass_in_glass(nesting: u32) -> String {
    let mut s = String::from(
        r#"indirections = 24
[material.floor]
kd = [0.7, 0.7, 0.6]
[material.glass_a]
kd = [0.02, 0.02, 0.02]
ks = [0.5, 0.5, 0.5]
shininess = 200
kt = 0.95
ior = 1.5
[material.glass_b]
kd = [0.02, 0.02, 0.02]
kt = 0.95
ior = 1.2
[[object]]
type = "quad"
centre = [0.0, -1.2, 0.0]
size = [8.0, 8.0]
material = "floor"
[[object]]
type = "box"
centre = [0.0, -0.2, -2.5]
size = [1.0, 2.0, 0.4]
material = "floor"
"#,
    );
    for k in 0..nesting {
        let r = 1.0 - 0.8 * k as f64 / nesting.max(1) as f64;
        let m = if k % 2 == 0 { "glass_a" } else { "glass_b" };
        s += &format!("[[object]]\ntype = \"sphere\"\nradius = {r:?}\nmaterial = \"{m}\"\n");
    }
    s + r#"[[camera]]
name = "view"
eye = [0.0, 0.6, 4.0]
at = [0.0, 0.0, 0.0]
fov = 45
[[light]]
position = [2.0, 4.0, 3.0]
"#
}

/// A compiled scene whose tree is a chain `n - 1` levels deep, assembled by hand (the compiler
/// caps the depth it builds, other tools need not): triangle `i` sits at x = i in a row; every
/// inner node holds one triangle's leaf and the rest of the row. The camera looks back along the
/// row, so the rest is always the nearer child and a stack holds every pending leaf.
pub fn chain(n: u32) -> SceneFile {
    let positions: Vec<[Vec3; 3]> = (0..n)
        .map(|i| {
            let x = i as f32;
            [Vec3::new(x, 0.0, 0.0), Vec3::new(x + 0.8, 0.0, 0.0), Vec3::new(x + 0.4, 1.0, 0.0)]
        })
        .collect();
    let cam = camera([n as f32 + 4.0, 0.5, 6.0], [n as f32 * 0.5, 0.5, 0.0], [0.0, 1.0, 0.0], 60.0);
    let mut nodes = Vec::new();
    let bounds = |range: std::ops::Range<usize>| {
        let pts = positions[range].iter().flatten();
        let lo = pts.clone().fold(Vec3::splat(f32::INFINITY), |a, &p| a.min(p));
        let hi = pts.fold(Vec3::splat(f32::NEG_INFINITY), |a, &p| a.max(p));
        (lo.to_array(), hi.to_array())
    };
    let n = n as usize;
    for i in 0..n {
        let (min, max) = bounds(i..n);
        if i + 1 == n {
            nodes.push(Node { min, max, count: 1, index: i as u32 });
        } else {
            nodes.push(Node { min, max, count: 0, index: nodes.len() as u32 + 1 });
            let (min, max) = bounds(i..i + 1);
            nodes.push(Node { min, max, count: 1, index: i as u32 });
        }
    }
    hand_built(positions, nodes, cam)
}

/// A compiled scene of `n` triangles in one leaf (the root): a grid of small triangles.
pub fn one_leaf(n: u32) -> SceneFile {
    let side = (n as f64).sqrt().ceil() as u32;
    let positions: Vec<[Vec3; 3]> = (0..n)
        .map(|k| {
            let (x, y) = ((k % side) as f32, (k / side) as f32);
            [Vec3::new(x, y, 0.0), Vec3::new(x + 0.9, y, 0.0), Vec3::new(x, y + 0.9, 0.0)]
        })
        .collect();
    let c = side as f32 * 0.5;
    let cam = camera([c, c, side as f32 * 1.3], [c, c, 0.0], [0.0, 1.0, 0.0], 50.0);
    let pts = positions.iter().flatten();
    let min = pts.clone().fold(Vec3::splat(f32::INFINITY), |a, &p| a.min(p)).to_array();
    let max = pts.fold(Vec3::splat(f32::NEG_INFINITY), |a, &p| a.max(p)).to_array();
    hand_built(positions, vec![Node { min, max, count: n, index: 0 }], cam)
}

/// A scene file with a child-pair tree given node by node (and its escape-pointer form).
fn hand_built(positions: Vec<[Vec3; 3]>, nodes: Vec<Node>, camera: Camera) -> SceneFile {
    let n = positions.len() as u32;
    let light = Light::new(camera.eye, [1.0; 3]);
    SceneFile {
        build: BuildParams { max_leaf_size: n, ..BuildParams::default() },
        settings: SceneSettings::default(),
        origin: [0.0; 3],
        scale_log2: 0,
        vertices: positions.iter().flatten().map(|p| p.to_array()).collect(),
        triangles: (0..n).map(|i| IndexedTriangle { vertices: [3 * i, 3 * i + 1, 3 * i + 2], material: 0 }).collect(),
        normals: Vec::new(),
        normal_indices: Vec::new(),
        materials: vec![Material::default()],
        material_names: vec!["default".to_owned()],
        input_index: (0..n).collect(),
        escape: Some(bvh_format::tree::escape_from_child_pair(&nodes)),
        child_pair: Some(nodes),
        wide: None,
        cameras: vec![camera],
        lights: vec![light],
    }
}

/// The side of the [`terrain`] whose triangle count (2 n^2) is nearest `triangles`.
pub fn terrain_side(triangles: u64) -> u32 {
    ((triangles as f64 / 2.0).sqrt().round() as u32).max(1)
}

/// The size axis's scene: a bumpy square 8 units wide of `n` x `n` quads (2 n^2 triangles, every
/// inner edge and vertex shared), its hills casting shadows, seen obliquely from above. One
/// surface however fine it is cut, so that frames of every triangle count look alike.
pub fn terrain(n: u32) -> Scene {
    let height = |x: f32, y: f32| 0.5 * (7.0 * x).sin() * (5.0 * y).cos() + 0.15 * (23.0 * (x + y)).sin();
    let vertex = |i: u32, j: u32| {
        let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
        Vec3::new(8.0 * x, 8.0 * y, height(x, y))
    };
    let mut tris = Vec::with_capacity(2 * n as usize * n as usize);
    for j in 0..n {
        for i in 0..n {
            let (a, b, c, d) = (vertex(i, j), vertex(i + 1, j), vertex(i + 1, j + 1), vertex(i, j + 1));
            tris.push([a, b, c]);
            tris.push([a, c, d]);
        }
    }
    let cam = camera([4.0, -2.0, 4.0], [4.0, 3.6, 0.0], [0.0, 0.0, 1.0], 55.0);
    // Low, from the side: the hills shade their back slopes and cast long shadows.
    triangles(tris, cam, vec![Light::new([-3.0, 5.0, 1.5], [1.0; 3])], Vec::new())
}
