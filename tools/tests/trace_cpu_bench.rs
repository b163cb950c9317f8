//! `trace-cpu bench` end to end on a tiny matrix: the CSV has one row per setting with the shared
//! columns, and every row's ray counts are those of the image the tracer renders for it.

use render_spec::{Mode, Settings};
use std::process::Command;
use tools::bench::{CSV_HEADER, read_csv};
use tracer_cpu::{Method, Tracer};

mod common;
use common::repo;

#[test]
fn a_small_matrix_writes_one_row_per_setting_with_the_rays_of_its_image() {
    let dir = common::scratch("cpu-bench");
    let csv = dir.join("cpu.csv");
    let room = repo().join("scenes/room.toml");
    let o = Command::new(env!("CARGO_BIN_EXE_trace-cpu"))
        .args(["bench", room.to_str().unwrap(), "--cameras", "medium,wide", "--res", "32x24,21x15"])
        .args(["--modes", "cast,whitted1,whitted2,ao4,diffuse", "--methods", "ordered,stackless", "--frames", "3"])
        .args(["--warmup", "0", "--threads", "2", "--csv", csv.to_str().unwrap()])
        .output()
        .expect("trace-cpu runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let text = std::fs::read_to_string(&csv).unwrap();
    assert_eq!(text.lines().next(), Some(CSV_HEADER));
    let rows = read_csv(&csv).unwrap();
    assert_eq!(rows.len(), 2 * 2 * 2 * 5, "cameras x sizes x methods x modes");

    let scene = tools::load_scene(Some(&room)).unwrap().file;
    let tracer = Tracer::new(&scene);
    for (i, r) in rows.iter().enumerate() {
        // Scene, then method, then camera, size and mode: the order of the loops.
        let method = ["ordered", "stackless"][i / 20];
        let camera = ["medium", "wide"][i / 10 % 2];
        let size = [(32, 24), (21, 15)][i / 5 % 2];
        let (name, lights, mode) = [
            ("cast", 0, Mode::Cast),
            ("whitted1", 1, Mode::Whitted),
            ("whitted2", 2, Mode::Whitted),
            ("ao4", 0, Mode::Ao(render_spec::Ao { samples: 4, length: 0.1 })),
            ("diffuse", 0, Mode::Diffuse),
        ][i % 5];
        assert_eq!(
            (r.scene.as_str(), r.method.as_str(), r.camera.as_str(), (r.width, r.height), r.mode.as_str(), r.lights),
            ("room", method, camera, size, name, lights),
            "row {i}"
        );
        assert_eq!(
            (r.tracer.as_str(), r.triangles, r.intersect.as_str()),
            ("cpu", scene.triangles.len() as u64, "watertight")
        );
        assert!(r.device.ends_with("2 threads"), "{}", r.device);
        assert!(r.min_ms > 0.0 && r.min_ms <= r.median_ms, "row {i}: {} > {}", r.min_ms, r.median_ms);

        let cam = tools::render_args::stored_camera(&scene, camera).unwrap();
        let image = tracer_cpu::render(
            &tracer,
            &Settings {
                width: r.width,
                height: r.height,
                camera: cam,
                mode,
                lights: tools::render_args::lights_n(&scene, lights, &cam),
                max_indirections: scene.settings.max_indirections,
                aovs: false,
                accuracy: render_spec::Accuracy::default(),
            },
            Method::Ordered,
        )
        .unwrap();
        let rays = image.rays;
        assert_eq!(r.rays, [rays.primary, rays.shadow, rays.secondary, rays.ao, rays.diffuse], "row {i}");
        assert_eq!(r.rays[0], (r.width * r.height) as u64);
        // The room is closed: every primary ray hits, and casts 4 AO rays or one diffuse bounce.
        match mode {
            Mode::Cast => assert_eq!(r.rays[1..], [0, 0, 0, 0], "row {i}: ray casting traces primary rays only"),
            Mode::Whitted => {
                assert!(r.rays[1] > 0 && r.rays[2] > 0, "row {i}: the room has lights, a mirror and glass")
            }
            Mode::Ao(_) => assert_eq!(r.rays[1..], [0, 0, 4 * r.rays[0], 0], "row {i}"),
            Mode::Diffuse => assert_eq!(r.rays[1..], [0, 0, 0, r.rays[0]], "row {i}"),
        }
    }
    let md = std::fs::read_to_string(csv.with_extension("md")).unwrap();
    assert_eq!(md.lines().filter(|l| l.starts_with("| room |")).count(), rows.len());
}

/// `--vertices expanded,indexed` times each method in both forms side by side (rows METHOD and
/// METHOD+indexed, the same rays), and prints each prepared tracer's bytes held, the indexed form's
/// 48 bytes per triangle fewer.
#[test]
fn both_vertex_forms_are_timed_side_by_side() {
    let dir = common::scratch("cpu-bench-forms");
    let csv = dir.join("cpu.csv");
    let room = repo().join("scenes/room.toml");
    let o = Command::new(env!("CARGO_BIN_EXE_trace-cpu"))
        .args(["bench", room.to_str().unwrap(), "--cameras", "medium", "--res", "24x16", "--modes", "whitted1"])
        .args(["--methods", "ordered,bvh8,bvh4", "--vertices", "expanded,indexed", "--frames", "1", "--warmup", "0"])
        .args(["--threads", "2", "--csv", csv.to_str().unwrap()])
        .output()
        .expect("trace-cpu runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows = read_csv(&csv).unwrap();
    let methods: Vec<&str> = rows.iter().map(|r| r.method.as_str()).collect();
    assert_eq!(methods, ["ordered", "ordered+indexed", "bvh8", "bvh8+indexed", "bvh4", "bvh4+indexed"]);
    assert!(rows.iter().all(|r| r.rays == rows[0].rays), "the forms or methods trace different rays");
    let out = String::from_utf8_lossy(&o.stdout);
    let held = |method: &str, form: &str| -> u64 {
        let says = format!("{method} with {form} vertices holds ");
        let line = out.lines().find(|l| l.starts_with(&says)).unwrap_or_else(|| panic!("no {says:?} in {out}"));
        line[says.len()..].split(' ').next().and_then(|n| n.parse().ok()).expect("a byte count")
    };
    let scene = tools::load_scene(Some(&room)).unwrap().file;
    let copy = 48 * scene.triangles.len() as u64;
    assert_eq!(held("ordered", "expanded") - held("ordered", "indexed"), copy);
    assert_eq!(held("bvh8", "expanded") - held("bvh8", "indexed"), copy);
    assert!(held("bvh8", "indexed") > held("ordered", "indexed"), "bvh8 holds its wide BVH besides");
    assert_eq!(held("bvh4", "expanded") - held("bvh4", "indexed"), copy);
    assert!(held("bvh4", "indexed") > held("ordered", "indexed"), "bvh4 holds its 4-wide BVH besides");
}
