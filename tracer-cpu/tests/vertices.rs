//! The two vertex forms (`--vertices`): a tracer that reads triangle corners through the file's
//! index and vertex arrays renders exactly what one holding its own expanded copy renders, on
//! every traversal, in every mode and with each triangle test, and holds 48 bytes per triangle
//! less.

mod common;

use bvh_format::SceneFile;
use render_spec::{Accuracy, Ao, CameraSpec, Image, Intersect, Mode, Settings, Vertices};
use tracer_cpu::vertices::{Indexed, TriangleSource};
use tracer_cpu::{Method, Tracer};

fn settings(scene: &SceneFile, camera: &str, mode: Mode, intersect: Intersect) -> Settings {
    Settings {
        aovs: true,
        accuracy: Accuracy { intersect, ..Accuracy::default() },
        ..Settings::of_scene(scene, CameraSpec::from(scene.camera(camera).expect("the camera exists")), mode, (64, 48))
    }
}

/// The image, every AOV (as bits) and the ray counts, self hits included; the traversal costs too
/// where `costs` (not for auto, whose costs are those of the way its timing picked for each kind
/// of ray, packets or the wide BVH, which two renders may pick differently: both ways' costs are
/// compared on their own rows).
fn assert_same(a: &Image, b: &Image, what: &str, costs: bool) {
    assert_eq!(a.rgb, b.rgb, "{what}: colours differ");
    let (x, y) = (a.aov.as_ref().expect("AOVs"), b.aov.as_ref().expect("AOVs"));
    let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&x.t), bits(&y.t), "{what}: distances differ");
    let nbits = |v: &[[f32; 3]]| v.iter().map(|n| n.map(f32::to_bits)).collect::<Vec<_>>();
    assert_eq!(nbits(&x.normal), nbits(&y.normal), "{what}: normals differ");
    assert_eq!(x.prim, y.prim, "{what}: triangle ids differ");
    if costs {
        assert_eq!((&x.nodes, &x.tris), (&y.nodes, &y.tris), "{what}: traversal costs differ");
    }
    assert_eq!(a.rays, b.rays, "{what}: ray counts differ");
}

#[test]
fn the_indexed_form_gives_every_triangle_bit_for_bit() {
    let scene = common::compile(&common::scenes_dir().join("bunny.toml"));
    let expanded = scene.leaf_triangles();
    let indexed = Indexed::new(&scene);
    assert_eq!(TriangleSource::len(&indexed), expanded.len());
    for (i, e) in expanded.iter().enumerate() {
        let t = indexed.triangle(i as u32);
        let bits = |t: &bvh_format::Triangle| (t.vertices().map(|v| v.map(f32::to_bits)), t.material);
        assert_eq!(bits(&t), bits(e), "triangle {i}");
    }
}

/// Every CPU method x both forms, on the bunny (mirror floor) and the room (mirror, glass, two
/// lights: every path kind of the Whitted model), in all four modes and with both triangle tests:
/// the same image, AOVs, traversal costs and ray counts (self hits counted, which read the
/// leaving triangle through the form).
#[test]
fn every_method_renders_the_same_image_from_both_forms() {
    let bunny = common::compile(&common::scenes_dir().join("bunny.toml"));
    let room = common::compile(&common::scenes_dir().join("room.toml"));
    let modes = [Mode::Cast, Mode::Whitted, Mode::Ao(Ao { samples: 2, length: 0.1 }), Mode::Diffuse];
    let methods = [Method::Ordered, Method::Stackless, Method::Packet, Method::Bvh8, Method::Auto];
    for (name, scene, camera) in [("bunny", &bunny, "medium"), ("room", &room, "medium"), ("room", &room, "close-up")] {
        let mut expanded = Tracer::with_vertices(scene, Vertices::Expanded);
        let mut indexed = Tracer::with_vertices(scene, Vertices::Indexed);
        expanded.count_self_hits(true);
        indexed.count_self_hits(true);
        assert_eq!(indexed.triangles().form(), Vertices::Indexed);
        let mut secondary = 0;
        for mode in modes {
            for intersect in [Intersect::Watertight, Intersect::MollerTrumbore] {
                let s = settings(scene, camera, mode, intersect);
                for method in methods {
                    let what = format!("{name} {camera} {mode:?} {intersect:?} {method:?}");
                    let a = tracer_cpu::render(&expanded, &s, method).expect("the expanded form renders");
                    let b = tracer_cpu::render(&indexed, &s, method).expect("the indexed form renders");
                    assert_same(&a, &b, &what, method != Method::Auto);
                    secondary += a.rays.secondary;
                }
            }
        }
        assert!(secondary > 0, "{name}: the Whitted renders should trace secondary rays");
    }
}

/// The indexed form holds no expanded copy: 48 bytes per triangle less, whether or not the wide
/// BVH was collapsed (which both forms hold alike).
#[test]
fn the_indexed_form_holds_48_bytes_per_triangle_less() {
    let scene = common::compile(&common::scenes_dir().join("bunny.toml"));
    let n = scene.triangles.len() as u64;
    let expanded = Tracer::with_vertices(&scene, Vertices::Expanded);
    let indexed = Tracer::with_vertices(&scene, Vertices::Indexed);
    assert_eq!(expanded.held_bytes() - indexed.held_bytes(), 48 * n);
    assert_eq!(expanded.held_bytes(), tracer_cpu::held_bytes(&scene, Vertices::Expanded));
    assert_eq!(indexed.held_bytes(), tracer_cpu::held_bytes(&scene, Vertices::Indexed));
    let wide = indexed.bvh8().expect("the child-pair layout").bytes() as u64;
    expanded.bvh8();
    assert_eq!(indexed.held_bytes(), tracer_cpu::held_bytes(&scene, Vertices::Indexed) + wide);
    assert_eq!(expanded.held_bytes() - indexed.held_bytes(), 48 * n);
}
