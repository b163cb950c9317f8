//! The incoherent modes (docs/shading.md, "Ambient occlusion" and "Diffuse bounce") on the CPU:
//! inside a closed box every AO ray of the box's diagonal is blocked and every AO ray of a tiny
//! length escapes; every traversal gives the same image and ray counts; a pixel of each mode is
//! the definition evaluated by hand, one scalar ray at a time.

mod common;

use glam::Vec3;
use render_spec::sequence::{cosine_direction, incoherent_sample, sample_2d};
use render_spec::{Accuracy, Ao, CameraSpec, Image, Mode, Settings};
use tracer_cpu::geometry::{Ray, leave};
use tracer_cpu::traverse::Stack;
use tracer_cpu::vertices::TriangleSource;
use tracer_cpu::{Cost, Method, Tracer, shade};

/// A closed box, 4 x 3 x 5, seen from inside, with a smaller box standing in it (compiled once:
/// the tests run in parallel and would share its temporary file).
fn box_scene() -> &'static bvh_format::SceneFile {
    static SCENE: std::sync::OnceLock<bvh_format::SceneFile> = std::sync::OnceLock::new();
    SCENE.get_or_init(|| common::compile_toml(
        "closed-box",
        "background = [0.2, 0.4, 0.6]\n\
         [material.grey]\nkd = [0.8, 0.7, 0.6]\n\
         [material.blue]\nkd = [0.1, 0.2, 0.9]\n\
         [[object]]\ntype = \"box\"\ncentre = [0.0, 1.5, 0.0]\nsize = [4.0, 3.0, 5.0]\nmaterial = \"grey\"\n\
         [[object]]\ntype = \"box\"\ncentre = [0.5, 0.4, -1.0]\nsize = [0.8, 0.8, 0.8]\nrotate = [0.0, 25.0, 0.0]\nmaterial = \"blue\"\n\
         [[camera]]\nname = \"inside\"\neye = [-1.2, 2.2, 2.0]\nat = [0.5, 0.4, -1.0]\nfov = 80.0\n",
    ))
}

fn settings(scene: &bvh_format::SceneFile, mode: Mode, spp: u32) -> Settings {
    Settings {
        width: 48,
        height: 36,
        camera: CameraSpec::from(scene.cameras.first().expect("a camera")),
        mode,
        lights: vec![],
        max_indirections: 0,
        aovs: true,
        accuracy: Accuracy { spp, ..Default::default() },
    }
}

/// Renders with every method and asserts that the images, AOVs and ray counts agree.
fn render_all(scene: &bvh_format::SceneFile, s: &Settings) -> Image {
    let tracer = Tracer::new(scene);
    let first = tracer_cpu::render(&tracer, s, Method::Ordered).expect("the CPU renders");
    for method in Method::ALL {
        let other = tracer_cpu::render(&tracer, s, method).expect("the CPU renders");
        assert_eq!(other.rgb, first.rgb, "{:?} {method:?}", s.mode);
        assert_eq!(other.rays, first.rays, "{:?} {method:?}", s.mode);
        assert_eq!(other.aov.as_ref().unwrap().prim, first.aov.as_ref().unwrap().prim);
    }
    first
}

#[test]
fn ao_in_a_closed_box_is_dark_with_the_diagonal_and_open_with_a_tiny_length() {
    let scene = box_scene();
    let pixels = 48 * 36;
    let closed = render_all(scene, &settings(scene, Mode::Ao(Ao { samples: 8, length: 1.0 }), 1));
    assert!(closed.rgb.iter().all(|&p| p == [0; 3]), "a ray of the diagonal must hit the box from anywhere inside");
    assert_eq!(closed.rays.primary, pixels);
    assert_eq!(closed.rays.ao, 8 * pixels, "8 AO rays per primary hit, and every primary ray hits");
    assert_eq!((closed.rays.shadow, closed.rays.secondary, closed.rays.diffuse), (0, 0, 0));

    let open = render_all(scene, &settings(scene, Mode::Ao(Ao { samples: 5, length: 1e-6 }), 1));
    assert!(open.rgb.iter().all(|&p| p == [255; 3]), "rays of a millionth of the diagonal escape everywhere");
    assert_eq!(open.rays.ao, 5 * pixels);

    // 10% of the diagonal: corners and the floor by the inner box are partly occluded, and more
    // rays (4 samples per pixel) give more distinct values than 8.
    let mid = render_all(scene, &settings(scene, Mode::Ao(Ao { samples: 8, length: 0.1 }), 1));
    let partial = mid.rgb.iter().filter(|p| p[0] > 0 && p[0] < 255).count();
    let full = mid.rgb.iter().filter(|p| p[0] == 255).count();
    assert!(partial > 20 && full > pixels as usize / 2, "partly occluded {partial}, open {full}");
    let levels = |i: &Image| i.rgb.iter().map(|p| p[0]).collect::<std::collections::BTreeSet<u8>>().len();
    assert!(levels(&mid) <= 9, "8 rays give at most 9 values");
    let more = render_all(scene, &settings(scene, Mode::Ao(Ao { samples: 8, length: 0.1 }), 4));
    assert_eq!(more.rays.ao, 4 * 8 * pixels);
    assert!(levels(&more) > levels(&mid), "4 samples of 8 rays give more values than one");
}

/// Pixel (x, y)'s primary hit, traced as one scalar ray.
fn primary_surface(scene: &bvh_format::SceneFile, s: &Settings, x: u32, y: u32) -> (shade::Surface, u32) {
    let tracer = Tracer::new(scene);
    let frame = s.frame().unwrap();
    let ray = Ray::new(frame.eye, frame.direction(x, y));
    let mut stack = Stack::default();
    let hit = tracer
        .walk(Method::Ordered)
        .expect("the file has the child-pair layout")
        .closest(&ray, 0.0, f32::INFINITY, &mut stack, &mut Cost::default())
        .expect("every primary ray hits the box");
    let tri = tracer.triangles().triangle(hit.tri);
    let normals = scene.vertex_normals(hit.tri as usize);
    (shade::surface(&tri, normals, ray.origin, ray.dir, hit.t, hit.u, hit.v), hit.tri)
}

/// One pixel of each mode evaluated from docs/shading.md with scalar rays: AO counts the rays
/// `offset_origin(p, ng) + t cosine_direction(ng, sample_2d(pixel, n))`, t in (0, length], that
/// hit nothing; the diffuse bounce is kd times the bounce hit's ray-casting colour.
#[test]
fn a_pixel_of_each_mode_is_the_definition_evaluated_by_hand() {
    let scene = box_scene();
    let tracer = Tracer::new(scene);
    let walk = tracer.walk(Method::Ordered).expect("the file has the child-pair layout");
    let ao = Ao { samples: 16, length: 0.3 };
    let s_ao = settings(scene, Mode::Ao(ao), 1);
    let s_diffuse = settings(scene, Mode::Diffuse, 1);
    let ao_image = render_all(scene, &s_ao);
    let diffuse_image = render_all(scene, &s_diffuse);
    let (lo, hi) = scene.bounds();
    let length = ao.distance(lo, hi);
    let mut stack = Stack::default();
    let mut partly = 0;
    for (x, y) in [(0, 0), (47, 35), (20, 30), (30, 28), (5, 33), (24, 18)] {
        let pixel = y * 48 + x;
        let (surface, tri) = primary_surface(scene, &s_ao, x, y);
        let from = leave(surface.point, surface.geometric, Default::default());
        let mut open = 0u32;
        for k in 0..ao.samples {
            let u = sample_2d(pixel, incoherent_sample(0, ao.samples, k));
            let d = Vec3::from(cosine_direction(surface.geometric.into(), u));
            open += u32::from(!walk.occluded(&Ray::new(from, d), length, &mut stack, &mut Cost::default()));
        }
        let v = shade::to_u8(Vec3::splat(open as f32 * ao.inverse()));
        assert_eq!(ao_image.rgb[pixel as usize], v, "AO pixel ({x}, {y}): {open} of {} open", ao.samples);
        partly += u32::from(open > 0 && open < ao.samples);

        let d = Vec3::from(cosine_direction(surface.geometric.into(), sample_2d(pixel, 0)));
        let bounce = Ray::new(from, d);
        let kd = Vec3::from(scene.materials[scene.triangles[tri as usize].material as usize].kd);
        let light = match walk.closest(&bounce, 0.0, f32::INFINITY, &mut stack, &mut Cost::default()) {
            Some(h) => {
                let t = tracer.triangles().triangle(h.tri);
                let b = shade::surface(&t, scene.vertex_normals(h.tri as usize), from, d, h.t, h.u, h.v);
                shade::cast(&scene.materials[scene.triangles[h.tri as usize].material as usize], &b, d)
            }
            None => Vec3::from(scene.settings.background),
        };
        assert_eq!(diffuse_image.rgb[pixel as usize], shade::to_u8(kd * light), "diffuse pixel ({x}, {y})");
    }
    assert!(partly > 0, "some chosen pixel must be partly occluded, or the test shows little");
    let pixels = 48 * 36;
    assert_eq!(diffuse_image.rays.diffuse, pixels, "one bounce per primary hit");
    assert_eq!(ao_image.rays.ao, 16 * pixels);
}
