//! The accuracy settings (issue 8) reach every path of the CPU renderer: a fixed origin offset
//! too small for the scene gives shadow acne where the scale-aware offset gives none, and the
//! bounce cutoff trades secondary rays for at most one 8-bit step. (Samples per pixel: the unit
//! test in `src/render.rs`; the triangle test: `tests/tests/leaks.rs` and `tests/hits.rs`.)

mod common;

use glam::Vec3;
use render_spec::{Accuracy, CameraSpec, Image, Mode, NO_TRIANGLE, Offset, Settings};
use tracer_cpu::{Method, Tracer};

/// A smooth sphere of radius 100 at the origin, one light beside the camera, no mirrors or glass:
/// convex, so no shadow ray of a point that faces the light can be blocked, except by the surface
/// it leaves (acne). The primary hit points, 300 units from the eye, are off the surface by up to
/// a few ulps of 400 (3e-5).
fn sphere_scene() -> bvh_format::SceneFile {
    common::compile_toml(
        "acne",
        "ambient = [0.1, 0.1, 0.1]\n\
         [material.grey]\nkd = [0.8, 0.8, 0.8]\n\
         [[object]]\ntype = \"sphere\"\nradius = 100.0\nsegments = 96\nrings = 48\nmaterial = \"grey\"\n\
         [[camera]]\nname = \"view\"\neye = [120.0, 160.0, 340.0]\nat = [0.0, 0.0, 0.0]\nfov = 45.0\n\
         [[light]]\nposition = [260.0, 150.0, 300.0]\n",
    )
}

fn whitted(scene: &bvh_format::SceneFile, w: u32, h: u32, accuracy: Accuracy) -> Settings {
    Settings {
        aovs: true,
        accuracy,
        ..Settings::of_scene(
            scene,
            CameraSpec::from(scene.camera("view").or(scene.cameras.first()).expect("a camera")),
            Mode::Whitted,
            (w, h),
        )
    }
}

/// Acne pixels of a render of [`sphere_scene`]: the primary ray hit, the light lies clearly in
/// front of the surface (cosine above 0.2 with the shading normal), and yet the pixel has the
/// ambient colour alone, so its shadow ray was blocked. Returns (acne pixels, lit pixels).
fn acne(scene: &bvh_format::SceneFile, s: &Settings, image: &Image) -> (usize, usize) {
    let aov = image.aov.as_ref().expect("AOVs were asked for");
    let frame = s.frame().unwrap();
    let light = Vec3::from(s.lights[0].position);
    let kd = Vec3::from(scene.materials[0].kd);
    let ambient = tracer_cpu::shade::to_u8(Vec3::from(scene.settings.ambient) * kd);
    let (mut acne, mut lit) = (0, 0);
    for i in 0..image.rgb.len() {
        if aov.prim[i] == NO_TRIANGLE {
            continue;
        }
        let (x, y) = (i as u32 % s.width, i as u32 / s.width);
        let p = frame.eye + frame.direction(x, y) * aov.t[i];
        if Vec3::from(aov.normal[i]).dot((light - p).normalize()) > 0.2 {
            lit += 1;
            acne += usize::from(image.rgb[i] == ambient);
        }
    }
    (acne, lit)
}

#[test]
fn a_fixed_offset_too_small_for_the_scene_gives_acne_where_the_scale_aware_one_does_not() {
    let scene = sphere_scene();
    let tracer = Tracer::new(&scene);
    println!("offset | method | acne pixels | lit pixels");
    for method in Method::ALL {
        let mut counts = Vec::new();
        for offset in [Offset::ScaleAware, Offset::Fixed(1e-6), Offset::Fixed(1e-2)] {
            let s = whitted(&scene, 160, 120, Accuracy { offset, ..Default::default() });
            let image = tracer_cpu::render(&tracer, &s, method).unwrap();
            let (acne, lit) = acne(&scene, &s, &image);
            println!("{offset:?} | {method:?} | {acne} | {lit}");
            assert!(lit > 160 * 120 / 5, "the light should light much of the sphere ({lit} pixels)");
            counts.push(acne);
        }
        assert_eq!(counts[0], 0, "{method:?}: the scale-aware offset gave {} acne pixels", counts[0]);
        assert!(counts[1] > 100, "{method:?}: a fixed offset of 1e-6 should give acne at 300 units");
        assert_eq!(counts[2], 0, "{method:?}: a fixed offset of 1e-2 should leave the surface");
    }
}

/// Two facing mirrors that lose 20% per bounce, a sphere between them, and a camera looking at
/// one at a slant: paths bounce long enough for the cutoff to decide where they end.
fn mirrors_scene() -> bvh_format::SceneFile {
    common::compile_toml(
        "mirrors",
        r#"
indirections = 64
ambient = [0.1, 0.1, 0.1]
[material.mirror]
kd = [0.1, 0.1, 0.1]
kr = 0.8
[material.red]
kd = [0.8, 0.2, 0.1]
[[object]]
type = "quad"
centre = [0.0, 0.0, -1.0]
size = [30.0, 30.0]
normal = [0.0, 0.0, 1.0]
material = "mirror"
[[object]]
type = "quad"
centre = [0.0, 0.0, 1.0]
size = [30.0, 30.0]
normal = [0.0, 0.0, -1.0]
material = "mirror"
[[object]]
type = "sphere"
radius = 0.4
material = "red"
[[camera]]
name = "view"
eye = [-0.5, 0.2, 0.9]
at = [0.4, 0.1, -1.0]
fov = 60.0
[[light]]
position = [0.0, 0.7, 0.0]
"#,
    )
}

#[test]
fn the_bounce_cutoff_trades_secondary_rays_for_at_most_one_step() {
    let scene = mirrors_scene();
    let tracer = Tracer::new(&scene);
    let at = |cutoff: f32, method: Method| {
        let s = whitted(&scene, 80, 60, Accuracy { cutoff, ..Default::default() });
        tracer_cpu::render(&tracer, &s, method).unwrap()
    };
    for method in Method::ALL {
        let default = at(Accuracy::default().cutoff, method);
        let every = at(0.0, method);
        let coarse = at(0.1, method);
        let none = at(1e6, method);
        println!(
            "{method:?}: secondary rays with cutoff 0: {}, 1/510: {}, 0.1: {}, 1e6: {}",
            every.rays.secondary, default.rays.secondary, coarse.rays.secondary, none.rays.secondary
        );
        assert!(every.rays.secondary > default.rays.secondary, "{method:?}: a cutoff of 0 traces more");
        assert!(default.rays.secondary > coarse.rays.secondary && coarse.rays.secondary > 0, "{method:?}");
        assert_eq!(none.rays.secondary, 0, "{method:?}: nothing can add a million");
        let most = |a: &Image, b: &Image| {
            a.rgb.iter().zip(&b.rgb).flat_map(|(p, q)| (0..3).map(|c| p[c].abs_diff(q[c]))).max().unwrap()
        };
        // What the default stop leaves out could not move a pixel by a full step.
        assert!(most(&every, &default) <= 1, "{method:?}: {}", most(&every, &default));
        assert!(most(&every, &coarse) > 1, "{method:?}: a cutoff of 0.1 should show");
    }
}
