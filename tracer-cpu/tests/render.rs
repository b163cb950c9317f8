//! Whole images: every traversal renders the same image, thread counts do not matter, shadow
//! rays end at the light, and the adaptive bounce stop traces only what can change a pixel.

mod common;

use bvh_format::{Light, SceneFile};
use glam::Vec3;
use render_spec::{CameraSpec, Image, Mode, NO_TRIANGLE, Settings};
use tracer_cpu::lanes::Stage;
use tracer_cpu::render::{Canvas, StageTimer, plan, plan_with, render_into};
use tracer_cpu::traverse::Stack;
use tracer_cpu::{Cost, Method, Ray, Tracer};

/// Renders with `settings.1` as the method.
fn render(tracer: &Tracer<'_>, settings: &(Settings, Method)) -> Result<Image, render_spec::RenderError> {
    tracer_cpu::render(tracer, &settings.0, settings.1)
}

fn settings(scene: &SceneFile, camera: &str, mode: Mode, method: Method, w: u32, h: u32) -> (Settings, Method) {
    let settings = Settings {
        aovs: true,
        ..Settings::of_scene(scene, CameraSpec::from(scene.camera(camera).expect("camera exists")), mode, (w, h))
    };
    (settings, method)
}

fn same_image(a: &Image, b: &Image, what: &str) {
    assert_eq!(a.rgb, b.rgb, "{what}: colours differ");
    let (x, y) = (a.aov.as_ref().unwrap(), b.aov.as_ref().unwrap());
    assert_eq!(x.prim, y.prim, "{what}: triangle ids differ");
    assert_eq!(x.t, y.t, "{what}: distances differ");
    assert_eq!(x.normal, y.normal, "{what}: normals differ");
    assert_eq!(a.rays, b.rays, "{what}: ray counts differ");
}

#[test]
fn every_method_renders_the_same_image() {
    let room = common::compile(&common::scenes_dir().join("room.toml"));
    let bunny = common::compile(&common::scenes_dir().join("bunny.toml"));
    for (name, scene, camera) in [("room", &room, "medium"), ("room", &room, "close-up"), ("bunny", &bunny, "medium")] {
        let tracer = Tracer::new(scene);
        for mode in [Mode::Cast, Mode::Whitted] {
            let base = render(&tracer, &settings(scene, camera, mode, Method::Ordered, 97, 61)).unwrap();
            for method in Method::ALL {
                let img = render(&tracer, &settings(scene, camera, mode, method, 97, 61)).unwrap();
                same_image(&base, &img, &format!("{name} {camera} {mode:?} {method:?}"));
            }
            let hits = base.aov.as_ref().unwrap().prim.iter().filter(|&&p| p != NO_TRIANGLE).count();
            assert!(hits > 97 * 61 / 4, "{name} {camera}: the camera should see the scene ({hits} hits)");
        }
    }
}

#[test]
fn whitted_images_do_not_depend_on_the_thread_count() {
    let room = common::compile(&common::scenes_dir().join("room.toml"));
    let tracer = Tracer::new(&room);
    let s = settings(&room, "medium", Mode::Whitted, Method::Auto, 160, 120);
    let images: Vec<Image> = [1, 2, 3]
        .iter()
        .map(|&n| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build().unwrap();
            pool.install(|| render(&tracer, &s).unwrap())
        })
        .collect();
    same_image(&images[0], &images[1], "1 vs 2 threads");
    same_image(&images[0], &images[2], "1 vs 3 threads");
    assert!(images[0].rays.secondary > 0 && images[0].rays.shadow > 0);
}

/// A floor (y = 0) under a roof (y = 2), both 10 x 10 quads.
fn floor_and_roof() -> SceneFile {
    common::compile_toml(
        "roof",
        r#"
[[object]]
type = "quad"
size = [10.0, 10.0]

[[object]]
type = "quad"
centre = [0.0, 2.0, 0.0]
size = [10.0, 10.0]
normal = [0.0, -1.0, 0.0]

[[camera]]
name = "down"
eye = [0.0, 1.0, 0.5]
at = [0.0, 0.0, 0.0]

[[light]]
position = [0.0, 1.5, 0.0]
"#,
    )
}

#[test]
fn shadow_rays_end_at_the_light() {
    let scene = floor_and_roof();
    let tracer = Tracer::new(&scene);
    let mut stack = Stack::default();
    let mut cost = Cost::default();
    let from = Vec3::new(0.0, 1e-3, 0.0);
    let up = Ray::new(from, Vec3::Y);
    for method in [Method::Ordered, Method::Stackless] {
        let walk = tracer.walk(method).unwrap();
        // The roof is 2 away: a light at 1.5 is not blocked, one at 2.5 is.
        assert!(!walk.occluded(&up, 1.5, &mut stack, &mut cost), "{method:?}");
        assert!(walk.occluded(&up, 2.5, &mut stack, &mut cost), "{method:?}");
    }
    // In an image: the floor under a light below the roof is lit; above the roof it is dark.
    let lit = {
        let mut s = settings(&scene, "down", Mode::Whitted, Method::Auto, 8, 8);
        s.0.lights = vec![Light::new([0.0, 1.5, 0.0], [1.0; 3])];
        render(&tracer, &s).unwrap()
    };
    let shadowed = {
        let mut s = settings(&scene, "down", Mode::Whitted, Method::Auto, 8, 8);
        s.0.lights = vec![Light::new([0.0, 2.5, 0.0], [1.0; 3])];
        render(&tracer, &s).unwrap()
    };
    let brightness = |img: &Image| img.rgb.iter().map(|p| p[0] as u32).sum::<u32>();
    assert!(brightness(&lit) > 4 * brightness(&shadowed), "{} vs {}", brightness(&lit), brightness(&shadowed));
    assert_eq!(lit.rays.shadow, 64);
}

fn mirror_floor(kr: f32) -> SceneFile {
    common::compile_toml(
        &format!("mirror{}", (kr * 1000.0) as u32),
        &format!(
            r#"
indirections = 3
[material.m]
kd = [0.3, 0.3, 0.3]
kr = {kr}

[[object]]
type = "quad"
size = [10.0, 10.0]
material = "m"

[[object]]
type = "sphere"
centre = [0.0, 0.5, 0.0]
radius = 0.5

[[camera]]
name = "view"
eye = [0.0, 1.0, 3.0]
at = [0.0, 0.3, 0.0]

[[light]]
position = [1.0, 3.0, 2.0]
"#
        ),
    )
}

#[test]
fn the_bounce_stop_skips_only_rays_that_cannot_change_a_pixel() {
    // kr = 0.001: a reflection adds at most 0.001 * (bound) < half an 8-bit step, so none is traced.
    let faint = mirror_floor(0.001);
    let s = settings(&faint, "view", Mode::Whitted, Method::Auto, 64, 48);
    let img = render(&Tracer::new(&faint), &s).unwrap();
    assert_eq!(img.rays.secondary, 0);
    // Skipping them changes nothing: the image equals that of a floor that does not reflect.
    let none = mirror_floor(0.0);
    let base = render(&Tracer::new(&none), &settings(&none, "view", Mode::Whitted, Method::Auto, 64, 48)).unwrap();
    assert_eq!(img.rgb, base.rgb);
    // kr = 0.5 reflects, and at most `indirections` deep.
    let strong = mirror_floor(0.5);
    let img = render(&Tracer::new(&strong), &settings(&strong, "view", Mode::Whitted, Method::Auto, 64, 48)).unwrap();
    assert!(img.rays.secondary > 0 && img.rays.secondary <= 3 * img.rays.primary);
    let mut one = settings(&strong, "view", Mode::Whitted, Method::Auto, 64, 48);
    one.0.max_indirections = 1;
    let once = render(&Tracer::new(&strong), &one).unwrap();
    assert!(once.rays.secondary <= once.rays.primary && once.rays.secondary < img.rays.secondary + 1);
}

#[test]
fn bad_settings_are_errors() {
    let scene = floor_and_roof();
    let tracer = Tracer::new(&scene);
    let mut s = settings(&scene, "down", Mode::Cast, Method::Auto, 0, 8);
    assert!(render(&tracer, &s).is_err());
    s.0.width = 8;
    s.0.camera.at = s.0.camera.eye;
    assert!(render(&tracer, &s).unwrap_err().to_string().contains("degenerate"));
    let mut only_escape = scene.clone();
    only_escape.child_pair = None;
    let s = settings(&scene, "down", Mode::Cast, Method::Ordered, 8, 8);
    assert!(render(&Tracer::new(&only_escape), &s).unwrap_err().to_string().contains("child-pair"));
}

/// A traversal is bound to its layout when it is chosen: asking for one whose layout the file
/// lacks is a typed refusal, never a silent walk of the other layout; `Auto` is the documented
/// choice that takes whichever layout is there.
#[test]
fn a_walk_on_a_missing_layout_is_refused() {
    use render_spec::RenderError;
    let scene = floor_and_roof();
    let mut only_escape = scene.clone();
    only_escape.child_pair = None;
    let mut only_child_pair = scene.clone();
    only_child_pair.escape = None;
    let (escape, child_pair) = (Tracer::new(&only_escape), Tracer::new(&only_child_pair));
    for method in [Method::Ordered, Method::Packet] {
        let e = escape.walk(method).err().expect("no child-pair layout to walk");
        assert!(matches!(e, RenderError::MissingLayout { layout: "child-pair", .. }), "{method:?}: {e:?}");
    }
    let e = child_pair.walk(Method::Stackless).err().expect("no escape layout to walk");
    assert!(matches!(e, RenderError::MissingLayout { method: "stackless", layout: "escape-pointer" }), "{e:?}");
    let mut neither = scene.clone();
    (neither.child_pair, neither.escape) = (None, None);
    assert!(Tracer::new(&neither).walk(Method::Auto).is_err());
    // What each walk does traverse, and that it finds the roof 2 above the floor.
    assert_eq!(escape.walk(Method::Auto).unwrap().method(), Method::Stackless);
    assert_eq!(escape.walk(Method::Stackless).unwrap().method(), Method::Stackless);
    assert_eq!(child_pair.walk(Method::Auto).unwrap().method(), Method::Bvh8);
    assert_eq!(child_pair.walk(Method::Bvh8).unwrap().method(), Method::Bvh8);
    assert_eq!(child_pair.walk(Method::Bvh4).unwrap().method(), Method::Bvh4);
    for method in [Method::Bvh8, Method::Bvh4] {
        let e = escape.walk(method).err().expect("the wide BVHs are collapsed from the child-pair layout");
        assert!(matches!(e, RenderError::MissingLayout { layout: "child-pair", .. }), "{method:?}: {e:?}");
    }
    let up = Ray::new(Vec3::new(0.0, 1e-3, 0.0), Vec3::Y);
    let walks = [Method::Ordered, Method::Bvh8, Method::Bvh4].map(|m| child_pair.walk(m).unwrap());
    for walk in [escape.walk(Method::Auto).unwrap()].into_iter().chain(walks) {
        let hit = walk.closest(&up, 0.0, f32::INFINITY, &mut Stack::default(), &mut Cost::default());
        assert!(hit.is_some_and(|h| (h.t - (2.0 - 1e-3)).abs() < 1e-4), "{:?}: {hit:?}", walk.method());
    }
}

#[test]
fn progress_reports_every_row_once_and_the_image_is_unchanged() {
    let room = common::compile(&common::scenes_dir().join("room.toml"));
    let tracer = Tracer::new(&room);
    // 203 rows: bands of 2 and a last band of 1.
    let s = settings(&room, "medium", Mode::Whitted, Method::Auto, 65, 203);
    let rows = std::sync::atomic::AtomicU64::new(0);
    let calls = std::sync::atomic::AtomicU64::new(0);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(3).build().unwrap();
    let img = pool
        .install(|| {
            tracer_cpu::render_with_progress(&tracer, &s.0, s.1, &|n| {
                rows.fetch_add(n as u64, std::sync::atomic::Ordering::Relaxed);
                calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            })
        })
        .unwrap();
    assert_eq!(rows.into_inner(), 203);
    assert!(calls.into_inner() > 1, "progress comes band by band, not once at the end");
    same_image(&img, &render(&tracer, &s).unwrap(), "with and without progress");
}

/// A [`StageTimer`] that reads the cost from a table (seconds per ray, one by one and as packets,
/// per stage) instead of a clock, and notes which stages it was asked about.
struct Table {
    per_ray: [(f64, f64); 5],
    asked: std::sync::Mutex<std::collections::BTreeSet<usize>>,
    /// Per stage: the rays timed one by one and as packets, over all rounds and workers.
    timed: std::sync::Mutex<[[u64; 2]; 5]>,
}

impl Table {
    fn new(per_ray: [(f64, f64); 5]) -> Self {
        Self { per_ray, asked: Default::default(), timed: Default::default() }
    }
}

impl StageTimer for Table {
    fn time(&self, stage: Stage, packets: bool, rays: u64, trace: &mut dyn FnMut()) -> f64 {
        trace();
        self.asked.lock().unwrap().insert(stage.index());
        self.timed.lock().unwrap()[stage.index()][packets as usize] += rays;
        let (single, packet) = self.per_ray[stage.index()];
        rays as f64 * if packets { packet } else { single }
    }
}

/// `--method auto` picks each stage's way by its measurement: a cost table handed in as the
/// timer decides every stage the frame has rays of (primary, shadow and secondary in the room's
/// Whitted frame; AO and diffuse rays in their modes), either way round, and the images are those
/// of the fixed methods whatever it picks.
#[test]
fn auto_picks_each_kind_of_ray_by_its_measurement() {
    let room = common::compile(&common::scenes_dir().join("room.toml"));
    let tracer = Tracer::new(&room);
    let (p, s) = (1e-9, 2e-9);
    // Packets cheaper for primary and secondary rays, single rays for shadow, AO and diffuse ...
    let a = [(s, p), (p, s), (s, p), (p, s), (p, s)];
    // ... and the other way round.
    let b = a.map(|(x, y)| (y, x));
    for (mode, stages) in [
        (Mode::Cast, vec![Stage::Primary]),
        (Mode::Whitted, vec![Stage::Primary, Stage::Shadow, Stage::Secondary]),
        (Mode::Ao(Default::default()), vec![Stage::Primary, Stage::Ao]),
        (Mode::Diffuse, vec![Stage::Primary, Stage::Diffuse]),
    ] {
        let (s, _) = settings(&room, "medium", mode, Method::Auto, 64, 48);
        let base = tracer_cpu::render(&tracer, &s, Method::Ordered).unwrap();
        for table in [a, b] {
            let timer = Table::new(table);
            let plan = plan_with(&tracer, &s, Method::Auto, &timer).unwrap();
            let want: Vec<usize> = stages.iter().map(|s| s.index()).collect();
            if !tracer_cpu::packet8::available() {
                assert!(plan.measured().is_none() && plan.packet_stages() == [false; 5], "no AVX2: no packets");
                continue;
            }
            assert_eq!(timer.asked.into_inner().unwrap().into_iter().collect::<Vec<_>>(), want, "{mode:?}");
            let m = plan.measured().expect("auto measures where packets run");
            // Every sampled block is whole at 64 x 48: 16 x 16 blocks of 8 primary rays.
            assert_eq!(m.rays[Stage::Primary.index()], 256 * 8, "{mode:?}");
            for stage in Stage::ALL {
                let i = stage.index();
                let packets = stages.contains(&stage) && table[i].1 < table[i].0;
                assert_eq!(plan.packet_stages()[i], packets, "{mode:?} {stage:?}: {m:?}");
                assert_eq!(m.rays[i] > 0, stages.contains(&stage), "{mode:?} {stage:?}: {m:?}");
            }
            let image = render_into(&tracer, &s, &plan, Canvas::new(&s), &|_| {}).unwrap();
            same_image(&base, &image, &format!("{mode:?} auto {}", plan.describe()));
        }
    }
}

/// Auto's two ways are the wide BVH's: where its measurement sends every stage as packets, each
/// pixel's work (the node and triangle AOVs) is `--method bvh8-packet`'s, and where it sends none,
/// `--method bvh8`'s; the binary tree's packets (`--method packet`) would test other nodes.
#[test]
fn auto_traces_the_wide_bvh_both_ways() {
    let bunny = common::compile(&common::scenes_dir().join("bunny.toml"));
    let tracer = Tracer::new(&bunny);
    for mode in [Mode::Cast, Mode::Whitted, Mode::Ao(Default::default()), Mode::Diffuse] {
        let (s, _) = settings(&bunny, "medium", mode, Method::Auto, 64, 48);
        let work = |image: &Image| {
            let aov = image.aov.as_ref().expect("AOVs asked for");
            (aov.nodes.clone(), aov.tris.clone())
        };
        let binary = work(&tracer_cpu::render(&tracer, &s, Method::Packet).unwrap());
        for (per_ray, fixed) in [((2e-9, 1e-9), Method::Bvh8Packet), ((1e-9, 2e-9), Method::Bvh8)] {
            let plan = plan_with(&tracer, &s, Method::Auto, &Table::new([per_ray; 5])).unwrap();
            let image = render_into(&tracer, &s, &plan, Canvas::new(&s), &|_| {}).unwrap();
            let want = tracer_cpu::render(&tracer, &s, fixed.resolve(&bunny)).unwrap();
            same_image(&want, &image, &format!("{mode:?} auto {}", plan.describe()));
            assert!(work(&image) == work(&want), "{mode:?}: auto's work is not {fixed:?}'s");
            if fixed == Method::Bvh8Packet && tracer_cpu::packet8::available() {
                assert!(work(&image) != binary, "{mode:?}: the binary tree's packets do the same work");
            }
        }
    }
}

/// Auto's measurement stops timing single rays once one way is clearly ahead: with packets 4
/// times faster, single rays get less than one round (stopped at twice the packets' time) and
/// count as 1.1 times the packets; with single rays 4 times faster, they get two rounds; where
/// the ways are 10% apart, three. Packets always get 3 (the first a warm-up). Every pick follows
/// the table.
#[test]
fn auto_stops_timing_the_way_clearly_behind() {
    let room = common::compile(&common::scenes_dir().join("room.toml"));
    let tracer = Tracer::new(&room);
    let (s, _) = settings(&room, "medium", Mode::Whitted, Method::Auto, 64, 48);
    let stages = [Stage::Primary, Stage::Shadow, Stage::Secondary];
    // (single, packets) seconds per ray; rounds timed (single, packets) per sampled ray.
    for ((single, packets), rounds) in
        [((4e-9, 1e-9), (None, 3)), ((1e-9, 4e-9), (Some(2), 3)), ((1.1e-9, 1e-9), (Some(3), 3))]
    {
        let timer = Table::new([(single, packets); 5]);
        let plan = plan_with(&tracer, &s, Method::Auto, &timer).unwrap();
        if !tracer_cpu::packet8::available() {
            assert!(
                plan.measured().is_none() && timer.timed.into_inner().unwrap() == [[0; 2]; 5],
                "no AVX2: no timing"
            );
            continue;
        }
        let m = plan.measured().expect("auto measures where packets run");
        let timed = timer.timed.into_inner().unwrap();
        for stage in stages {
            let i = stage.index();
            let what = format!("{stage:?}, {single} / {packets} s per ray: {m:?}, timed {timed:?}");
            assert!(m.rays[i] > 0, "{what}");
            assert_eq!(plan.packet_stages()[i], packets < single, "{what}");
            assert_eq!(timed[i][1], rounds.1 * m.rays[i], "{what}");
            let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b;
            assert!(close(m.packets[i], packets * m.rays[i] as f64), "{what}");
            match rounds.0 {
                Some(n) => {
                    assert_eq!(timed[i][0], n * m.rays[i], "{what}");
                    assert!(close(m.single[i], single * m.rays[i] as f64), "{what}");
                }
                None => {
                    assert!(timed[i][0] <= m.rays[i], "{what}");
                    assert!(close(m.single[i], 1.1 * m.packets[i]), "{what}");
                }
            }
        }
        // 16 calls of 8 primary rays per worker, timed in 8 slices: stopped once past twice the
        // packets' time, at 5 of the 8 (single rays 4 times slower).
        assert!(timed[0][0] == m.rays[0] * 5 / 8 || rounds.0.is_some(), "{m:?}, timed {timed:?}");
    }
}

/// The measured plan picks what its measurement says, and names it.
#[test]
fn auto_by_the_clock_follows_its_measurement() {
    let room = common::compile(&common::scenes_dir().join("room.toml"));
    let tracer = Tracer::new(&room);
    let (s, _) = settings(&room, "medium", Mode::Whitted, Method::Auto, 96, 64);
    let plan = plan(&tracer, &s, Method::Auto).unwrap();
    match plan.measured() {
        Some(m) => {
            assert_eq!(plan.packet_stages(), m.packet_stages());
            for stage in [Stage::Primary, Stage::Shadow, Stage::Secondary] {
                let i = stage.index();
                assert!(m.rays[i] > 0 && m.single[i] > 0.0 && m.packets[i] > 0.0, "{stage:?}: {m:?}");
                assert_eq!(m.packet_stages()[i], m.packets[i] < m.single[i]);
                assert!(plan.describe().contains(stage.name()), "{}", plan.describe());
            }
        }
        None => assert!(!tracer_cpu::packet8::available()),
    }
}

/// A canvas paged in before the frame, or one made for other settings, changes nothing.
#[test]
fn the_canvas_does_not_change_the_image() {
    let room = common::compile(&common::scenes_dir().join("room.toml"));
    let tracer = Tracer::new(&room);
    let (s, method) = settings(&room, "medium", Mode::Whitted, Method::Packet, 45, 31);
    let want = tracer_cpu::render(&tracer, &s, method).unwrap();
    let plan = plan(&tracer, &s, method).unwrap();
    let mut paged = Canvas::new(&s);
    paged.page_in();
    assert_eq!(paged.bytes(), 45 * 31 * (3 + 4 + 12 + 4 + 4 + 4));
    same_image(&want, &render_into(&tracer, &s, &plan, paged, &|_| {}).unwrap(), "paged in");
    let (other, _) = settings(&room, "medium", Mode::Whitted, Method::Packet, 31, 45);
    let other = Canvas::new(&Settings { aovs: false, ..other });
    same_image(&want, &render_into(&tracer, &s, &plan, other, &|_| {}).unwrap(), "a canvas of another size");
    // The buffers of another frame of the same size (other pixels, other AOVs) are overwritten.
    let (cast, _) = settings(&room, "wide", Mode::Cast, Method::Packet, 45, 31);
    let before = tracer_cpu::render(&tracer, &cast, method).unwrap();
    assert_ne!(before.rgb, want.rgb);
    let reused = Canvas::reuse(before);
    same_image(&want, &render_into(&tracer, &s, &plan, reused, &|_| {}).unwrap(), "another frame's buffers");
}
