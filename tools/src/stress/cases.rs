//! The points of every axis: a generated scene and the frames to render of it.

use super::scenes::{self, camera};
use super::{Case, Expect};
use bvh_build::Scene;
use bvh_format::SceneFile;
use glam::{DVec3, Vec3};
use render_spec::{CameraSpec, Image, Mode, Settings};

/// How much of each axis to run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Extent {
    /// Every point (docs/stability.md).
    Full,
    /// A cheap slice of every axis (the CI test).
    Quick,
}

/// The largest triangle count of the size axis unless the caller sets one (`stress
/// --max-triangles`): cheap enough for the CI slice.
pub const DEFAULT_MAX_TRIANGLES: u64 = 100_000;

/// Frames of more pixels than this have no AOVs (at 16384 x 16384 they would take 8 GiB): only
/// their colours are compared, with the CPU ordered walk's image.
pub const MAX_AOV_PIXELS: u64 = 1 << 20;

/// The axes, in the order of the report.
pub const AXES: [&str; 14] = [
    "distance",
    "distance, f32 world coordinates (no rebasing)",
    "scale",
    "axis-parallel rays",
    "grazing rays",
    "ray origin on the surface",
    "degenerate geometry",
    "tree depth",
    "leaf size",
    "indirections (hall of mirrors)",
    "glass in glass",
    "subnormal ray directions",
    "size: triangles",
    "size: frame",
];

fn compile(scene: &Scene) -> SceneFile {
    bvh_build::compile(scene, &Default::default(), Default::default()).expect("a generated scene compiles")
}

fn description(text: &str) -> SceneFile {
    compile(&scenes::import_description(text).expect("a generated description imports"))
}

/// A frame of `scene` from `cam` (Whitted, the scene's lights and indirections, with AOVs).
pub fn shot(scene: &SceneFile, cam: CameraSpec, w: u32, h: u32) -> Settings {
    Settings { aovs: true, ..Settings::of_scene(scene, cam, Mode::Whitted, (w, h)) }
}

fn first_camera(scene: &SceneFile) -> CameraSpec {
    CameraSpec::from(&scene.cameras[0])
}

fn cpu_images(scene: &SceneFile, shots: &[Settings]) -> Vec<Image> {
    let tracer = tracer_cpu::Tracer::new(scene);
    shots
        .iter()
        .map(|s| tracer_cpu::render(&tracer, s, tracer_cpu::Method::Ordered).expect("the CPU renders"))
        .collect()
}

fn case(axis: &'static str, x: f64, label: String, scene: SceneFile, shots: Vec<Settings>) -> Case {
    // Möller-Trumbore differs from the edge-consistent test at edges and vertices, where far from
    // the origin and at extreme scales its roundings grow: those axes run it as lines of their own.
    let both_tests = [AXES[0], AXES[2], AXES[3], AXES[4], AXES[5], AXES[6], AXES[11]].contains(&axis);
    Case { axis, x, label, scene, shots, expect: Expect::Hits, near: 0.0, both_tests }
}

/// The size axis's triangle counts: 10^3, 10^4, ... up to `max`, and `max` itself.
pub fn triangle_counts(max: u64) -> Vec<u64> {
    let mut counts: Vec<u64> = (3..=10).map(|k| 10u64.pow(k)).filter(|&n| n <= max).collect();
    if counts.last() != Some(&max) && max >= 1000 {
        counts.push(max);
    }
    counts
}

/// The scene as it would be without rebasing: world coordinates rounded to f32, origin zero.
fn unrebased(mut s: Scene) -> Scene {
    let o = s.origin;
    let w = |p: Vec3| (p.as_dvec3() + o).as_vec3();
    for t in &mut s.positions {
        *t = t.map(w);
    }
    for c in &mut s.cameras {
        c.eye = w(c.eye.into()).into();
        c.at = w(c.at.into()).into();
    }
    for l in &mut s.lights {
        l.position = w(l.position.into()).into();
    }
    s.origin = DVec3::ZERO;
    s
}

/// Every point of every axis (in [`AXES`] order), of the axes `wanted` accepts (only those are
/// generated); the size axis up to `max_triangles`.
pub fn all(extent: Extent, max_triangles: u64, wanted: &dyn Fn(&str) -> bool) -> Vec<Case> {
    let quick = extent == Extent::Quick;
    let (w, h) = if quick { (32, 24) } else { (64, 48) };
    let mut out = Vec::new();

    // Distance: the mirror room moved by 10^k of its own size, with camera and light.
    let origin_image = || {
        let at_origin = description(&scenes::mirror_room([0.0; 3]));
        let origin_shot = shot(&at_origin, first_camera(&at_origin), w, h);
        cpu_images(&at_origin, std::slice::from_ref(&origin_shot))
    };
    let ks: Vec<i32> = if quick { vec![0, 3, 6] } else { (0..=7).collect() };
    if wanted(AXES[0]) || wanted(AXES[1]) {
        let origin_image = origin_image();
        for &k in &ks {
            let d = 10f64.powi(k) * scenes::MIRROR_ROOM_SIZE;
            let text = scenes::mirror_room([d, 0.7 * d, -0.3 * d]);
            let imported = scenes::import_description(&text).expect("the mirror room imports");
            for axis in [AXES[0], AXES[1]].into_iter().filter(|a| wanted(a)) {
                let scene = if axis == AXES[0] { compile(&imported) } else { compile(&unrebased(imported.clone())) };
                let s = shot(&scene, first_camera(&scene), w, h);
                let mut c = case(axis, 10f64.powi(k), format!("10^{k}"), scene, vec![s]);
                c.expect = Expect::Images(origin_image.clone());
                out.push(c);
            }
        }
    }

    // Scale: the mirror room scaled by 10^k about the origin.
    let ks: Vec<i32> = if quick { vec![-8, -5, 0, 7, 8] } else { (-8..=8).collect() };
    if wanted(AXES[2]) {
        let origin_image = origin_image();
        for k in ks {
            let scene = description(&scenes::mirror_room_scaled([0.0; 3], 10f64.powi(k)));
            let s = shot(&scene, first_camera(&scene), w, h);
            let mut c = case(AXES[2], 10f64.powi(k), format!("10^{k}"), scene, vec![s]);
            c.expect = Expect::Images(origin_image.clone());
            out.push(c);
        }
    }

    // Axis-parallel rays along +z and -z (1 x 1 frames, whose one ray is exactly the view
    // direction, with +0 and -0 components) through faces, edges and vertices of a grid.
    let grid = compile(&scenes::triangles(
        scenes::grid(6),
        camera([3.0, 3.0, 4.0], [3.0, 3.0, 0.0], [0.0, 1.0, 0.0], 45.0),
        vec![bvh_format::Light::new([2.0, 1.0, 5.0], [1.0; 3])],
        Vec::new(),
    ));
    let eyes = if quick { 2 } else { 4 };
    for (x, label, dx, dy) in [
        (1.0, "faces", 0.3, 0.6),
        (2.0, "edges", 0.5, 0.0),
        (3.0, "diagonal edges", 0.5, 0.5),
        (4.0, "vertices", 0.0, 0.0),
    ] {
        let mut shots = Vec::new();
        for j in 1..=eyes {
            for i in 1..=eyes {
                let (px, py) = (i as f32 + dx, j as f32 + dy);
                for z in [3.0f32, -3.0] {
                    let cam = CameraSpec {
                        eye: Vec3::new(px, py, z),
                        at: Vec3::new(px, py, 0.0),
                        up: Vec3::Y,
                        fov_deg: 30.0,
                    };
                    shots.push(shot(&grid, cam, 1, 1));
                }
            }
        }
        out.push(case(AXES[3], x, label.to_owned(), grid.clone(), shots));
    }

    // Grazing rays: a 16 x 16 grid seen at 10^-k degrees, down to 1e-6.
    let floor = compile(&scenes::triangles(
        scenes::grid(16),
        camera([8.0, -4.0, 6.0], [8.0, 8.0, 0.0], [0.0, 0.0, 1.0], 45.0),
        vec![bvh_format::Light::new([8.0, 8.0, 10.0], [1.0; 3])],
        Vec::new(),
    ));
    let ks: Vec<i32> = if quick { vec![0, 3, 6] } else { (0..=6).collect() };
    for k in ks {
        let theta = 10f64.powi(-k).to_radians();
        let (dist, y0) = (8.0, 0.1);
        let eye = DVec3::new(8.3, y0, dist * theta.tan());
        let at = eye + DVec3::new(0.0, theta.cos(), -theta.sin()) * dist;
        let fov = (10f64.powi(-k) * 0.5) as f32;
        let cam = CameraSpec { eye: eye.as_vec3(), at: at.as_vec3(), up: Vec3::Z, fov_deg: fov };
        let s = shot(&floor, cam, w / 2, w / 2);
        out.push(case(AXES[4], 10f64.powi(-k), format!("1e-{k} deg"), floor.clone(), vec![s]));
    }

    // Ray origins on a closed box's surface, edges and vertices, looking inside: every ray must
    // hit the box (a miss is a leak).
    let boxed = compile(&scenes::triangles(
        scenes::closed_box(4),
        camera([2.0, 2.0, 2.0], [0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 45.0),
        vec![bvh_format::Light::new([2.0, 3.5, 2.0], [1.0; 3])],
        Vec::new(),
    ));
    for (x, label, eye) in [
        (1.0, "on a face", [2.3, 1.7, 0.0]),
        (2.0, "on an edge", [2.0, 1.5, 0.0]),
        (3.0, "on a vertex", [2.0, 2.0, 0.0]),
        (4.0, "on the box's corner", [0.0, 0.0, 0.0]),
    ] {
        let cam = CameraSpec { eye: Vec3::from(eye), at: Vec3::splat(2.0), up: Vec3::Y, fov_deg: 90.0 };
        let s = shot(&boxed, cam, w / 2, w / 2);
        let mut c = case(AXES[5], x, label.to_owned(), boxed.clone(), vec![s]);
        c.near = 1e-4;
        out.push(c);
    }

    // Degenerate geometry.
    let down = |c: [f32; 3], r: f32| camera([c[0], c[1], c[2] + r], c, [0.0, 1.0, 0.0], 50.0);
    let light = vec![bvh_format::Light::new([0.3, 0.2, 5.0], [1.0; 3])];
    let mut zero_area = scenes::grid(6);
    for (k, t) in zero_area.iter_mut().enumerate() {
        match k % 3 {
            0 => t[2] = t[1],    // a line
            1 => *t = [t[0]; 3], // a point
            _ => {}
        }
    }
    zero_area.extend(scenes::grid(6).into_iter().map(|t| t.map(|p| p - Vec3::Z)));
    let mut duplicates = Vec::new();
    for t in scenes::grid(4) {
        duplicates.extend(std::iter::repeat_n(t, 8));
    }
    let mut coplanar = scenes::grid(4);
    coplanar.extend(scenes::grid(4).into_iter().map(|t| t.map(|p| p + Vec3::new(0.5, 0.25, 0.0))));
    let needle_counts: &[u32] = if quick { &[1000] } else { &[1000, 10000] };
    // Name, triangles, the point the camera looks down at, and its height above it.
    type Shape = (String, Vec<[Vec3; 3]>, [f32; 3], f32);
    let mut geometry: Vec<Shape> = vec![
        ("zero-area triangles".to_owned(), zero_area, [3.0, 3.0, 0.0], 6.0),
        ("duplicates x8".to_owned(), duplicates, [2.0, 2.0, 0.0], 4.0),
        ("coplanar overlap".to_owned(), coplanar, [2.2, 2.1, 0.0], 4.0),
        ("fan of 1000 at one vertex".to_owned(), scenes::fan(1000), [0.0, 0.0, 0.0], 1.5),
    ];
    for &n in needle_counts {
        geometry.push((format!("needles 1:{n}"), scenes::needles(n), [0.5, 0.5, 0.0], 1.0));
    }
    for (k, (label, tris, centre, r)) in geometry.into_iter().enumerate() {
        let scene = compile(&scenes::triangles(tris, down(centre, r), light.clone(), Vec::new()));
        let mut shots = vec![shot(&scene, first_camera(&scene), w / 2, w / 2)];
        // One ray exactly through the centre (the fan's shared vertex).
        shots.push(shot(&scene, first_camera(&scene), 1, 1));
        out.push(case(AXES[6], (k + 1) as f64, label, scene, shots));
    }

    // Subnormal ray direction components: reflections off a mirror tilted by a subnormal angle
    // (a camera's own rays never have them: its right and up vectors fill the other components),
    // running along the shared edges of a wall. Compared with the f64 reference's image, so that
    // a leak or a wrong reflection on every method is seen. At the smallest subnormal tilt the
    // reflection's x component rounds to zero (2 eps d.z is below half of it).
    let tilts: &[(f32, &str)] = if quick {
        &[(1e-39, "1e-39"), (1e-44, "1e-44")]
    } else {
        &[(1e-39, "1e-39"), (-1e-39, "-1e-39"), (1e-44, "1e-44"), (f32::from_bits(1), "1.4e-45")]
    };
    for &(eps, label) in tilts {
        let scene = compile(&scenes::subnormal_mirror(eps));
        let s = shot(&scene, first_camera(&scene), 1, if quick { 16 } else { 48 });
        let expected = tracer_cpu::reference::render(&scene, &s).expect("the reference renders").image;
        let mut c = case(AXES[11], f64::from(eps.abs()), label.to_owned(), scene, vec![s]);
        c.expect = Expect::Images(vec![expected]);
        out.push(c);
    }

    // Tree depth: hand-assembled chains (the compiler caps the depth it builds). Run last: a
    // device that hangs on the deepest chain is not used again.
    let mut deep = Vec::new();
    let depths: &[u32] = if quick { &[8, 100] } else { &[8, 32, 128, 512, 1000] };
    for &d in depths {
        let scene = scenes::chain(d + 1);
        let s = shot(&scene, first_camera(&scene), w, w / 4);
        deep.push(case(AXES[7], d as f64, format!("{d}"), scene, vec![s]));
    }

    // Leaf size: every triangle in one leaf.
    let leaves: &[u32] = if quick { &[8, 1000] } else { &[8, 64, 256, 1000] };
    for &n in leaves {
        let scene = scenes::one_leaf(n);
        let s = shot(&scene, first_camera(&scene), w / 2, w / 2);
        out.push(case(AXES[8], n as f64, format!("{n}"), scene, vec![s]));
    }

    // Secondary rays: compared with the CPU's ordered traversal, the trusted path.
    let bounces: &[u32] = if quick { &[4, 64] } else { &[1, 4, 16, 64] };
    for &n in bounces {
        let scene = description(&scenes::hall_of_mirrors(n));
        let s = shot(&scene, first_camera(&scene), w / 2, w / 2);
        let mut c = case(AXES[9], n as f64, format!("{n}"), scene, vec![s]);
        c.expect = Expect::Images(cpu_images(&c.scene, &c.shots));
        out.push(c);
    }
    let nests: &[u32] = if quick { &[3] } else { &[1, 2, 3, 4] };
    for &n in nests {
        let scene = description(&scenes::glass_in_glass(n));
        let s = shot(&scene, first_camera(&scene), w / 2, w / 2);
        let mut c = case(AXES[10], n as f64, format!("{n}"), scene, vec![s]);
        c.expect = Expect::Images(cpu_images(&c.scene, &c.shots));
        out.push(c);
    }

    // Size: the bumpy terrain of growing triangle counts in a small frame (every hit checked), and
    // frames up to 16384 x 16384 of the terrain of 10^4 triangles (the GPU renders them in
    // tiles), compared with the CPU ordered walk's image.
    if wanted(AXES[12]) {
        let counts = triangle_counts(max_triangles);
        let counts: Vec<u64> = if quick && counts.len() > 2 {
            vec![counts[0], *counts.last().expect("two counts or more")]
        } else {
            counts
        };
        for n in counts {
            let scene = compile(&scenes::terrain(scenes::terrain_side(n)));
            let tris = scene.triangles.len() as f64;
            let s = shot(&scene, first_camera(&scene), w, h);
            let mut c = case(AXES[12], tris, format!("{tris:.0}"), scene, vec![s]);
            c.expect = Expect::CpuOrdered;
            out.push(c);
        }
    }
    if wanted(AXES[13]) {
        let scene = compile(&scenes::terrain(scenes::terrain_side(10_000)));
        // Sizes that are no multiple of the workgroup's, the widest and tallest frames, and (in
        // the full sweep) frames the GPU splits into tiles, up to the largest allowed.
        let frames: &[(u32, u32)] = if quick {
            &[(500, 375), (16384, 2), (2, 16384)]
        } else {
            &[(256, 256), (500, 375), (16384, 2), (2, 16384), (4096, 4096), (16384, 16384)]
        };
        for &(fw, fh) in frames {
            let mut s = shot(&scene, first_camera(&scene), fw, fh);
            s.aovs = fw as u64 * fh as u64 <= MAX_AOV_PIXELS;
            let mut c = case(AXES[13], fw as f64 * fh as f64, format!("{fw}x{fh}"), scene.clone(), vec![s]);
            c.expect = Expect::CpuOrdered;
            out.push(c);
        }
    }
    out.extend(deep);
    out.retain(|c| wanted(c.axis));
    out
}
