//! The exact reference against itself and the fast tracer: the f64 walk finds exactly brute
//! force's hits, and reference images agree with fast ones up to f32 rounding, closely enough
//! that a real shading bug would show.

mod common;

use bvh_format::SceneFile;
use common::Rng;
use glam::DVec3;
use rayon::prelude::*;
use render_spec::{Accuracy, CameraSpec, Image, Mode, Settings};
use tracer_cpu::reference::bvh::{Ray64, Stack};
use tracer_cpu::reference::{self, Bvh, closest_hit};
use tracer_cpu::{Cost, Method, Tracer};

/// Rays over a scene in f64: the shared random rays (widened), and rays from random points
/// outside aimed exactly (in f64) at stored vertices, at points on stored edges and at edge
/// midpoints, where neighbouring triangles tie and boxes are touched at their boundary.
fn rays(scene: &SceneFile, random: usize, aimed: usize, seed: u64) -> Vec<(DVec3, DVec3)> {
    let mut out: Vec<(DVec3, DVec3)> =
        common::random_rays(scene, random, seed).into_iter().map(|(o, d)| (o.as_dvec3(), d.as_dvec3())).collect();
    let (lo, hi) = scene.bounds();
    let (lo, hi) = (DVec3::from(lo.map(f64::from)), DVec3::from(hi.map(f64::from)));
    let (centre, radius) = ((lo + hi) * 0.5, (hi - lo).length() * 0.5);
    let mut rng = Rng(seed ^ 0x5851_f42d_4c95_7f2d);
    for i in 0..aimed {
        let k = rng.below(scene.triangles.len());
        let p = scene.positions(k).map(|v| DVec3::from(v.map(f64::from)));
        let j = rng.below(3);
        let (a, b) = (p[j], p[(j + 1) % 3]);
        let target = match i % 3 {
            0 => a,
            1 => (a + b) * 0.5,
            _ => a + (b - a) * f64::from(rng.unit()),
        };
        let origin = centre + glam::Vec3::from(rng.direction()).as_dvec3() * radius * (1.2 + f64::from(rng.unit()));
        out.push((origin, (target - origin).normalize()));
    }
    out
}

/// Brute force against both walks of the f64 traversal, closest hit and any hit, on every ray.
fn walks_equal_brute_force(name: &str, scene: &SceneFile, random: usize, aimed: usize) {
    let ordered = Bvh::new(scene).unwrap();
    let stackless = Bvh::escape_only(scene).expect("the test scenes hold both layouts");
    let tris = ordered.triangles();
    let rays = rays(scene, random, aimed, 0x2545_f491_4f6c_dd1d);
    let hits: usize = rays
        .par_iter()
        .map_init(Stack::new, |stack, &(o, d)| {
            let exact = closest_hit(tris, o, d, 0.0);
            let ray = Ray64::new(o, d);
            let mut cost = Cost::default();
            for (walk, bvh) in [("ordered", &ordered), ("stackless", &stackless)] {
                let got = bvh.closest(&ray, 0.0, stack, &mut cost);
                assert_eq!(got, exact, "{name}: the {walk} walk differs from brute force on origin {o:?} dir {d:?}");
                // Any hit: the closest hit blocks a ray ending exactly there, nothing a ray ending
                // just before it.
                if let Some(e) = exact {
                    assert!(bvh.occluded(&ray, 0.0, e.t, stack, &mut cost), "{name} {walk}: {o:?} {d:?}");
                    assert!(!bvh.occluded(&ray, 0.0, e.t * (1.0 - 1e-12), stack, &mut cost), "{name} {walk}");
                } else {
                    assert!(!bvh.occluded(&ray, 0.0, f64::INFINITY, stack, &mut cost), "{name} {walk}");
                }
            }
            usize::from(exact.is_some())
        })
        .sum();
    // The rays must mostly hit, or the comparison would prove little.
    assert!(hits * 2 > rays.len(), "{name}: only {hits} of {} rays hit", rays.len());
}

#[test]
fn the_f64_walk_finds_brute_forces_hits_on_the_bunny() {
    let scene = common::compile(&common::scenes_dir().join("bunny.toml"));
    walks_equal_brute_force("bunny", &scene, 1500, 1500);
}

#[test]
fn the_f64_walk_finds_brute_forces_hits_on_generated_meshes() {
    walks_equal_brute_force("sphere", &common::sphere_scene(), 6000, 12000);
    // A torus far from the origin, where the coordinates' units in the last place are coarse.
    let torus = common::compile_toml(
        "far-torus",
        "[[object]]\ntype = \"torus\"\ncentre = [3000.0, -2000.0, 500.0]\nmajor = 1.0\nminor = 0.3\n",
    );
    walks_equal_brute_force("far torus", &torus, 6000, 12000);
}

fn settings(scene: &SceneFile, width: u32, height: u32, mode: Mode) -> Settings {
    Settings::of_scene(scene, CameraSpec::from(&scene.cameras[0]), mode, (width, height))
}

/// Pixels whose largest channel differs by more than `by` 8-bit steps.
fn differing(a: &Image, b: &Image, by: u8) -> usize {
    a.rgb.iter().zip(&b.rgb).filter(|(p, q)| p.iter().zip(q.iter()).any(|(x, y)| x.abs_diff(*y) > by)).count()
}

/// Of the 19,200 pixels of a 160 x 120 image, how many may differ between the reference and a fast
/// render at all, and by more than one 8-bit step. Measured: at most 3 and 1 (the room's mirror
/// and glass, Whitted; a ray through an edge where f32 and f64 pick different triangles, and f32
/// rounding at a half step). A wrong Phong exponent (x 1.25) moves 378 pixels of the room, one
/// more unit of it 71; 2% more diffuse reflectance moves 13,703 in ray casting.
const ANY_DIFFERENCE: usize = 20;
const MORE_THAN_A_STEP: usize = 5;

#[test]
fn reference_images_agree_with_fast_ones_and_a_shading_change_shows() {
    for name in ["room.toml", "bunny.toml"] {
        let scene = common::compile(&common::scenes_dir().join(name));
        let tracer = Tracer::new(&scene);
        for mode in [Mode::Cast, Mode::Whitted] {
            let s = Settings { aovs: true, ..settings(&scene, 160, 120, mode) };
            let fast = tracer_cpu::render(&tracer, &s, Method::Ordered).unwrap();
            let exact = reference::render(&scene, &s).unwrap();
            let (any, step) = (differing(&fast, &exact.image, 0), differing(&fast, &exact.image, 1));
            eprintln!(
                "{name} {mode:?}: {any} of 19,200 pixels differ from the fast render, {step} by more than a step"
            );
            assert!(
                any <= ANY_DIFFERENCE && step <= MORE_THAN_A_STEP,
                "{name} {mode:?}: {any} pixels differ, {step} by more than a step"
            );
            // The image is the quantised linear colours.
            let quantised: Vec<[u8; 3]> =
                exact.linear.iter().map(|c| reference::render::to_u8(glam::Vec3::from(*c).as_dvec3())).collect();
            assert_eq!(quantised, exact.image.rgb, "{name} {mode:?}");
            // The primary hits: the same triangles but at a few edges, at the same distances.
            let (f, e) = (fast.aov.unwrap(), exact.image.aov.unwrap());
            let other = f.prim.iter().zip(&e.prim).filter(|(a, b)| a != b).count();
            assert!(other <= ANY_DIFFERENCE, "{name} {mode:?}: {other} primary hits on other triangles");
            for ((a, b), (pa, pb)) in f.t.iter().zip(&e.t).zip(f.prim.iter().zip(&e.prim)) {
                assert!(pa != pb || a == b || (a - b).abs() <= 1e-5 * b, "{name} {mode:?}: t {a} against {b}");
            }
            assert!(e.nodes.iter().all(|&n| n > 0), "every pixel tests the root");
        }
    }

    // The bounds can fail: a wrong Phong exponent, or a slightly brighter diffuse term, in the
    // reference alone exceeds them.
    let room = common::compile(&common::scenes_dir().join("room.toml"));
    let tracer = Tracer::new(&room);
    for (mode, change) in [(Mode::Whitted, 0), (Mode::Cast, 1)] {
        let s = settings(&room, 160, 120, mode);
        let fast = tracer_cpu::render(&tracer, &s, Method::Ordered).unwrap();
        let mut wrong = room.clone();
        for m in &mut wrong.materials {
            match change {
                0 => m.shininess *= 1.25,
                _ => m.kd = m.kd.map(|x| x * 1.02),
            }
        }
        let any = differing(&fast, &reference::render(&wrong, &s).unwrap().image, 0);
        assert!(any > ANY_DIFFERENCE * 3, "{mode:?}: a changed material moved only {any} pixels");
    }
}

/// `n x n` samples per pixel are the mean of the samples: the reference at `n W x n H` with one
/// sample per pixel shoots exactly the rays of `W x H` with `n x n` (for n a power of two every
/// sample position and camera step is exact, so the directions agree bit for bit), and averaging
/// its `n x n` blocks gives the supersampled image up to the f32 rounding of the linear colours.
#[test]
fn samples_per_pixel_average_the_sub_pixel_rays() {
    let room = common::compile(&common::scenes_dir().join("room.toml"));
    let (w, h) = (40u32, 30u32);
    let one = reference::render(&room, &settings(&room, w, h, Mode::Whitted)).unwrap();
    for n in [2u32, 4] {
        let spp = n * n;
        let s = Settings { accuracy: Accuracy { spp, ..Accuracy::default() }, ..settings(&room, w, h, Mode::Whitted) };
        let many = reference::render(&room, &s).unwrap();
        assert_eq!(many.image.rays.primary, u64::from(w * h * spp));
        let fine = reference::render(&room, &settings(&room, w * n, h * n, Mode::Whitted)).unwrap();
        let mut worst = 0.0f32;
        for y in 0..h {
            for x in 0..w {
                let mut sum = glam::Vec3::ZERO;
                for j in 0..n {
                    for i in 0..n {
                        sum += glam::Vec3::from(fine.linear[((y * n + j) * w * n + x * n + i) as usize]);
                    }
                }
                let got = glam::Vec3::from(many.linear[(y * w + x) as usize]);
                worst = worst.max((got - sum / spp as f32).abs().max_element());
            }
        }
        assert!(worst <= 1e-6, "{spp} samples: a pixel is {worst} away from the mean of its sub-pixel rays");
        // Supersampling changes the edges, not the flat regions: the check above is not trivial.
        let changed = differing(&one.image, &many.image, 1);
        let pixels = (w * h) as usize;
        assert!(changed > pixels / 50 && changed < pixels / 2, "{spp} samples changed {changed} of {pixels} pixels");
    }
    let bad = Settings { accuracy: Accuracy { spp: 3, ..Accuracy::default() }, ..settings(&room, w, h, Mode::Whitted) };
    assert!(matches!(reference::render(&room, &bad), Err(render_spec::RenderError::SamplesPerPixel(3))));
}
