//! `trace-cpu render` and `trace-vk render` end to end: negative values, the default camera,
//! outputs checked before work and written whole, the same sentence from both tracers for the
//! same mistake, and a reader that stops early. trace-vk runs on whatever Vulkan device is present
//! (lavapipe in CI) and fails, never skips, without one.

mod common;

use common::{assert_ok, assert_one_sentence_error, run, scene, scratch, snapshot, text};
use std::path::Path;

/// A compiled room, small and with every material kind, for fast renders.
fn room(dir: &Path) -> String {
    let out = dir.join("room.bvh");
    let o = run(dir, "bvhc", &["compile", scene("room.toml").to_str().unwrap(), "-o", "room.bvh", "--quiet"]);
    assert_ok(&o, "compiling the room");
    out.to_str().unwrap().to_owned()
}

#[test]
fn negative_numbers_are_accepted_as_values_by_both_tracers() {
    let dir = scratch("negative");
    let room = room(&dir);
    for tracer in ["trace-cpu", "trace-vk"] {
        let o = run(
            &dir,
            tracer,
            &[
                "render",
                &room,
                "--eye",
                "-1.5,1,-1.5",
                "--at",
                "0,-0.5,0",
                "--up",
                "0,1,0",
                "--light",
                "-1,2.5,-1,0.5,0.5,0.5",
                "--res",
                "8x6",
                "-o",
                "neg.png",
            ],
        );
        assert_ok(&o, tracer);
        assert_eq!(image::image_dimensions(dir.join("neg.png")).unwrap(), (8, 6));
    }
}

/// A description with its own cameras and none called "medium" renders without --camera, from
/// its first camera, and `--help` says so.
#[test]
fn the_default_camera_is_the_files_first() {
    let dir = scratch("first-camera");
    std::fs::write(
        dir.join("two.toml"),
        "[[object]]\ntype = \"box\"\nsize = [1, 1, 1]\n\n[[camera]]\nname = \"north\"\neye = [0, 0.5, 3]\nat = [0, 0, 0]\n\n\
         [[camera]]\nname = \"south\"\neye = [0, 0.5, -3]\nat = [0.3, 0, 0]\n",
    )
    .unwrap();
    for tracer in ["trace-cpu", "trace-vk"] {
        assert_ok(&run(&dir, tracer, &["render", "two.toml", "--res", "16x12", "-o", "default.png"]), tracer);
        assert_ok(
            &run(&dir, tracer, &["render", "two.toml", "--res", "16x12", "-o", "north.png", "--camera", "north"]),
            tracer,
        );
        assert_ok(
            &run(&dir, tracer, &["render", "two.toml", "--res", "16x12", "-o", "south.png", "--camera", "south"]),
            tracer,
        );
        let read = |n: &str| image::open(dir.join(n)).unwrap().to_rgb8().into_raw();
        assert_eq!(read("default.png"), read("north.png"), "{tracer}");
        assert_ne!(read("default.png"), read("south.png"), "{tracer}: the two cameras see different images");
        let (help, _) = text(&run(&dir, tracer, &["render", "--help"]));
        assert!(help.contains("the scene's first camera"), "{tracer} --help: {help}");
    }
}

/// Every output is checked before any work, and a refused or failed run leaves existing files
/// as they were.
#[test]
fn outputs_are_checked_before_work_and_never_destroyed() {
    let dir = scratch("outputs");
    let room = room(&dir);
    for name in ["y.tiff", "y.png", "y.gif", "keep.exr"] {
        std::fs::write(dir.join(name), b"precious").unwrap();
    }
    let before = snapshot(&dir);
    for tracer in ["trace-cpu", "trace-vk"] {
        let cases: &[(&[&str], &str)] = &[
            (&["-o", "y.tiff"], ".png, .jpg, .bmp, .exr"),
            (&["-o", "y.gif"], "-o y.gif"),
            (&["-o", "y.png", "--heatmap", "y.tiff"], "--heatmap y.tiff"),
            (&["-o", "y.png", "--aov", "a.png"], "--aov a.png: the AOVs can be written as .exr"),
            (&["-o", "y.png", "--heatmap", "./y.png"], "-o and --heatmap both name ./y.png"),
            (&["-o", "keep.exr", "--aov", "keep.exr"], "-o and --aov both name keep.exr"),
            (&["-o", "no/such/folder/y.png"], "the folder no/such/folder does not exist"),
            (&["-o", "y.png", "--aov", "missing/a.exr"], "the folder missing does not exist"),
            (&["-o", "room.bvh"], "-o room.bvh"),
        ];
        for (args, needle) in cases {
            // The scene is missing too: the outputs are refused first, before anything is read.
            let mut all = vec!["render", "no-such-scene.bvh", "--res", "8x8"];
            all.extend_from_slice(args);
            assert_one_sentence_error(&run(&dir, tracer, &all), needle);
        }
        // A failure after the work (here: the validation layer cannot fail, so a scene that
        // cannot be read) also leaves everything in place.
        assert_one_sentence_error(&run(&dir, tracer, &["render", "missing.bvh", "-o", "y.png"]), "missing.bvh");
        assert_eq!(snapshot(&dir), before, "{tracer} changed a file it refused to write");
        let _ = &room;
    }
}

#[test]
fn colour_image_as_exr_and_heatmap_with_its_scale() {
    let dir = scratch("exr");
    let room = room(&dir);
    for tracer in ["trace-cpu", "trace-vk"] {
        let o = run(
            &dir,
            tracer,
            &[
                "render",
                &room,
                "--res",
                "20x10",
                "-o",
                "c.exr",
                "--heatmap",
                "h.png",
                "--heatmap-max",
                "3",
                "--aov",
                "a.exr",
            ],
        );
        let out = assert_ok(&o, tracer);
        assert!(out.contains("0 (blue) to 3 (red)") && out.contains("pixels above the scale"), "{out}");
        let rays = out.lines().next().unwrap();
        assert!(!rays.contains(" 0.0 ") && rays.contains("rays/s"), "{rays}");
        let (w, h) = image::image_dimensions(dir.join("h.png")).unwrap();
        assert!(w == 20 && h > 10, "the legend adds rows below the image: {w}x{h}");
        let exr = exr::prelude::read_all_flat_layers_from_file(dir.join("c.exr")).unwrap();
        let layer = &exr.layer_data[0];
        assert_eq!((layer.size.0, layer.size.1), (20, 10));
        let names: Vec<String> = layer.channel_data.list.iter().map(|c| c.name.to_string()).collect();
        assert_eq!(names, ["B", "G", "R"]);
        // Linear float: the same values as the 8-bit image, over 255.
        assert_ok(&run(&dir, tracer, &["render", &room, "--res", "20x10", "-o", "c.png"]), tracer);
        let png = image::open(dir.join("c.png")).unwrap().to_rgb8();
        let exr::prelude::FlatSamples::F32(r) = &layer.channel_data.list[2].sample_data else { panic!("R is f32") };
        for (i, p) in png.pixels().enumerate() {
            assert_eq!((r[i] * 255.0).round() as u8, p[0]);
        }
    }
}

/// The same mistake gets the same sentence from both tracers: their options are parsed and
/// checked once, in `tools::render_args`.
#[test]
fn both_tracers_explain_a_mistake_in_the_same_words() {
    let dir = scratch("same-words");
    let room = room(&dir);
    let cases: &[&[&str]] = &[
        &["--light", "0,1,1,1"],
        &["--eye", "1,2", "--at", "0,0,0"],
        &["--eye", "0,0,0", "--at", "0,0,0"],
        &["--fov", "-5"],
        &["--res", "0x0"],
        &["--lights", "-3"],
        &["--indirections", "-1"],
        &["--camera", "nope"],
        &["--eye", "3e38,0,0", "--at", "-3e38,0,0"],
        &["--heatmap-max", "0", "--heatmap", "h.png"],
        &["--intersect", "exact"],
        &["--offset", "-1e-4"],
        &["--offset", "tiny"],
        &["--offset", "inf"],
        &["--spp", "2"],
        &["--spp", "0"],
        &["--spp", "2048"],
        &["--cutoff", "-0.1"],
        &["--cutoff", "nan"],
    ];
    for args in cases {
        let mut all = vec!["render", room.as_str(), "--res", "8x8", "-o", "x.png"];
        all.extend_from_slice(args);
        let cpu = assert_one_sentence_error(&run(&dir, "trace-cpu", &all), "");
        let vk = assert_one_sentence_error(&run(&dir, "trace-vk", &all), "");
        assert_eq!(cpu, vk, "{args:?}");
        assert!(!cpu.contains("unexpected argument"), "{cpu}");
    }
    // A workgroup shape is not an image size.
    let line = assert_one_sentence_error(&run(&dir, "trace-vk", &["render", &room, "--workgroup", "0x0"]), "workgroup");
    assert!(!line.contains("image"), "{line}");
}

/// Each accuracy flag's refusal says what is wrong with the value in one sentence.
#[test]
fn accuracy_flags_explain_a_bad_value() {
    let dir = scratch("accuracy-words");
    let room = room(&dir);
    let cases: &[(&[&str], &str)] = &[
        (&["--spp", "8"], "not a square"),
        (&["--spp", "0"], "between 1 and 1024"),
        (&["--spp", "4096"], "between 1 and 1024"),
        (&["--cutoff", "-1"], "at least 0"),
        (&["--cutoff", "x"], "not a number"),
        (&["--offset", "-0.01"], "at least 0"),
        (&["--offset", "big"], "scale"),
        (&["--intersect", "fast"], "--intersect"),
    ];
    for (args, words) in cases {
        let mut all = vec!["render", room.as_str(), "--res", "8x8", "-o", "x.png"];
        all.extend_from_slice(args);
        assert_one_sentence_error(&run(&dir, "trace-cpu", &all), words);
    }
}

/// Both tracers render with every accuracy flag and name the non-default ones in their report
/// line, so that an image made with a setting cannot be taken for one made without it.
#[test]
fn accuracy_flags_are_honoured_and_named() {
    let dir = scratch("accuracy-flags");
    let room = room(&dir);
    let cases: &[(&[&str], &str)] = &[
        (&["--intersect", "mt"], "Möller-Trumbore"),
        (&["--offset", "1e-3"], "fixed offset"),
        (&["--spp", "4"], "4 samples per pixel"),
        (&["--cutoff", "0"], "no bounce cutoff"),
    ];
    for (args, named) in cases {
        let mut all = vec!["render", room.as_str(), "--res", "8x8", "-o", "x.png"];
        all.extend_from_slice(args);
        for tracer in ["trace-cpu", "trace-vk"] {
            let out = assert_ok(&run(&dir, tracer, &all), tracer);
            assert!(out.lines().next().unwrap_or("").contains(named), "{tracer}: the report names the setting: {out}");
        }
    }
    // The defaults spelled out are the defaults: both tracers render.
    let all = [
        "render",
        &room,
        "--res",
        "8x8",
        "-o",
        "d.png",
        "--intersect",
        "watertight",
        "--offset",
        "scale",
        "--spp",
        "1",
    ];
    for tracer in ["trace-cpu", "trace-vk"] {
        assert_ok(&run(&dir, tracer, &all), tracer);
    }
}

/// `--self-hits` (exact acne) prints the same line from both tracers where their arithmetic is the
/// same (`--exact`), with rays stopped by their own triangle under a tiny fixed offset; `--vertices
/// indexed` renders the expanded form's image and says what trace-vk uploaded and trace-cpu holds
/// (48 bytes per triangle less); the f64 reference refuses it.
#[test]
fn self_hits_and_the_vertex_form_are_reported() {
    let dir = scratch("self-hits");
    let room = room(&dir);
    let mut lines = Vec::new();
    for tracer in ["trace-cpu", "trace-vk"] {
        let args = ["render", &room, "--res", "32x24", "-o", "s.png", "--self-hits", "--exact", "--offset", "1e-9"];
        let out = assert_ok(&run(&dir, tracer, &args), tracer);
        let line = out.lines().find(|l| l.starts_with("self-hits")).unwrap_or_else(|| panic!("{tracer}: {out}"));
        lines.push(line.to_owned());
        let plain = assert_ok(&run(&dir, tracer, &["render", &room, "--res", "32x24", "-o", "p.png"]), tracer);
        assert!(!plain.contains("self-hits"), "{tracer} counted without being asked: {plain}");
    }
    assert_eq!(lines[0], lines[1], "the tracers count different self-hits");
    assert!(!lines[0].contains(": 0 of"), "a fixed offset of 1e-9 stopped no shadow ray on its surface: {}", lines[0]);
    let e = run(&dir, "trace-cpu", &["render", &room, "--res", "8x8", "-o", "r.png", "--self-hits", "--reference"]);
    assert_one_sentence_error(&e, "--self-hits");
    for (tracer, says) in [("trace-vk", "lst with {} vertices uploads "), ("trace-cpu", "auto with {} vertices holds ")]
    {
        let (mut images, mut bytes) = (Vec::new(), Vec::new());
        for v in ["expanded", "indexed"] {
            let name = format!("{tracer}-{v}.png");
            let out =
                assert_ok(&run(&dir, tracer, &["render", &room, "--res", "32x24", "-o", &name, "--vertices", v]), v);
            let says = says.replace("{}", v);
            let line = out.lines().find(|l| l.starts_with(&says)).unwrap_or_else(|| panic!("{tracer} {v}: {out}"));
            let n: u64 = line[says.len()..].split(' ').next().and_then(|n| n.parse().ok()).expect("a byte count");
            bytes.push(n);
            images.push(std::fs::read(dir.join(&name)).expect("the image was written"));
        }
        assert_eq!(images[0], images[1], "{tracer}: the indexed form's image differs from the expanded form's");
        assert!(bytes[1] < bytes[0], "{tracer}: the indexed form holds {} bytes, the expanded {}", bytes[1], bytes[0]);
        if tracer == "trace-cpu" {
            let scene = tools::load_scene(Some(std::path::Path::new(&room))).expect("the room loads").file;
            assert_eq!(bytes[0] - bytes[1], 48 * scene.triangles.len() as u64, "trace-cpu's expanded copy");
        }
    }
    let e = run(
        &dir,
        "trace-cpu",
        &["render", &room, "--res", "8x8", "-o", "r.png", "--vertices", "indexed", "--reference"],
    );
    assert!(!e.status.success() && String::from_utf8_lossy(&e.stderr).contains("--vertices"), "{e:?}");
}

/// `trace-cpu render ... | head -1`: the reader goes away, the program ends quietly.
#[test]
fn a_closed_pipe_ends_the_program_quietly() {
    let dir = scratch("pipe");
    let room = room(&dir);
    for tracer in ["trace-cpu", "trace-vk"] {
        let mut child = std::process::Command::new(common::bin(tracer))
            .args(["render", &room, "--res", "8x8", "-o", "p.png", "--heatmap", "h.png"])
            .current_dir(&dir)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take());
        let o = child.wait_with_output().unwrap();
        let (_, err) = text(&o);
        assert!(o.status.success(), "{tracer}: {:?} {err}", o.status);
        assert!(err.trim().is_empty(), "{tracer}: {err}");
        assert!(dir.join("p.png").exists() && dir.join("h.png").exists(), "every file was written first");
    }
}

/// trace-cpu's timing line says what its time covers: auto's measurement and its pick per kind of
/// ray, and apart from it the image's paging in; every method name is taken.
#[test]
fn the_cpu_timing_line_says_what_it_covers() {
    let dir = scratch("cpu-timing-line");
    let room = room(&dir);
    for method in tracer_cpu::Method::ALL {
        let args =
            ["render", room.as_str(), "--res", "32x24", "--mode", "whitted", "--method", method.name(), "-o", "x.png"];
        let out = assert_ok(&run(&dir, "trace-cpu", &args), method.name());
        let line = out.lines().next().unwrap_or("");
        assert!(line.contains("to page in the image (2304 bytes)"), "{line}");
        assert!(line.contains("trace and shade into the 8-bit image"), "{line}");
        let auto = method == tracer_cpu::Method::Auto;
        assert_eq!(line.contains("to measure auto's ways of tracing"), auto, "{line}");
        // The wide BVHs (bvh8's for bvh8, bvh8-packet and auto, bvh4's for bvh4) are collapsed at
        // load, apart from the render's time.
        use tracer_cpu::Method::{Bvh4, Bvh8, Bvh8Packet};
        let wide = matches!(method, Bvh4 | Bvh8 | Bvh8Packet) || auto;
        assert_eq!(line.contains("to collapse the wide BVH at load"), wide, "{line}");
        if auto && tracer_cpu::packet::available() {
            for stage in ["primary: ", "shadow: ", "secondary: "] {
                assert!(line.contains(stage), "auto names its pick for {stage}: {line}");
            }
        }
    }
}

/// `--method auto` on a file with only the escape-pointer layout takes the stackless walk.
#[test]
fn auto_method_on_an_escape_only_file_is_stackless() {
    let dir = scratch("escape-only");
    let o = run(
        &dir,
        "bvhc",
        &["compile", scene("room.toml").to_str().unwrap(), "-o", "e.bvh", "--layout", "escape", "--quiet"],
    );
    assert_ok(&o, "compile");
    let out = assert_ok(&run(&dir, "trace-cpu", &["render", "e.bvh", "--res", "8x8", "-o", "e.png"]), "auto");
    assert!(out.contains("with Stackless"), "{out}");
}

/// `--lights N` on a closed room places the added lights inside it, where they light the view.
#[test]
fn added_lights_stay_inside_a_closed_room() {
    let room = tools::compile_default(&scene("room.toml")).unwrap();
    let camera = tools::render_args::default_camera(&room).unwrap();
    let (lo, hi) = room.bounds();
    let lights = tools::render_args::lights_n(&room, 6, &camera);
    assert_eq!(lights.len(), 6);
    for l in &lights {
        let p = glam::Vec3::from(l.position);
        assert!(p.cmpgt(lo.into()).all() && p.cmplt(hi.into()).all(), "{p} lies outside the room");
    }
}

/// `bench --csv` of both tracers is checked before any scene is read or any frame is timed, and
/// an existing table survives a refused run.
#[test]
fn bench_checks_its_table_before_work() {
    let dir = scratch("bench-csv");
    std::fs::write(dir.join("old.csv"), b"kept").unwrap();
    let before = snapshot(&dir);
    for (tool, method) in [("trace-vk", "lst"), ("trace-cpu", "ordered")] {
        let bench =
            ["bench", "no-such-scene.bvh", "--res", "8x8", "--frames", "1", "--methods", method, "--modes", "cast"];
        for (csv, needle) in [("missing/b.csv", "the folder missing does not exist"), ("b.txt", "--csv b.txt")] {
            let args = [&bench[..], &["--csv", csv]].concat();
            assert_one_sentence_error(&run(&dir, tool, &args), needle);
        }
        assert_one_sentence_error(&run(&dir, tool, &[&bench[..], &["--csv", "old.csv"]].concat()), "no-such-scene.bvh");
    }
    assert_eq!(snapshot(&dir), before);
}

/// A scene stored in a unit of its own (2^-20 of the world here, see `bvh_build::unit`): the
/// camera, light and fixed offset given on the command line in world units, and the `t` AOV
/// written in world units, give the image and distances of the same scene at 2^3 (stored in the
/// same unit 2^3, so the two files differ only in their exponent): bit for bit.
#[test]
fn world_units_on_the_command_line_and_in_the_aov_go_through_the_stored_unit() {
    let dir = scratch("stored-unit");
    let mut t = Vec::new();
    let mut png = Vec::new();
    for (name, s) in [("big", 8.0f64), ("tiny", 2f64.powi(-20))] {
        let desc = dir.join(format!("{name}.toml"));
        std::fs::write(&desc, tools::stress::scenes::mirror_room_scaled([0.0; 3], s)).unwrap();
        let w = |v: [f64; 3]| format!("{:?},{:?},{:?}", v[0] * s, v[1] * s, v[2] * s);
        let light = format!("{},1,1,1", w([2.0, 6.0, 3.0]));
        let offset = format!("{:?}", 2f64.powi(-7) * s);
        let (eye, at) = (w([1.0, 3.0, 7.0]), w([0.0, 1.0, -1.0]));
        let args = [
            "render",
            desc.to_str().unwrap(),
            "--eye",
            &eye,
            "--at",
            &at,
            "--light",
            &light,
            "--offset",
            &offset,
            "--res",
            "24x16",
            "-o",
            &format!("{name}.png"),
            "--aov",
            &format!("{name}.exr"),
        ];
        let out = assert_ok(&run(&dir, "trace-cpu", &args), name);
        let given: f32 = offset.parse().unwrap();
        assert!(out.contains(&format!("fixed offset {given:e}")), "{name}: the report names the world offset: {out}");
        let (_, _, aov) = tools::output::read_aov(&dir.join(format!("{name}.exr"))).unwrap();
        t.push(aov.t.iter().map(|&v| f64::from(v) / s).collect::<Vec<_>>());
        png.push(std::fs::read(dir.join(format!("{name}.png"))).unwrap());
    }
    assert_eq!(png[0], png[1], "the images differ");
    assert!(t[0].iter().any(|v| v.is_finite()));
    assert_eq!(t[0], t[1], "the t AOV, divided by the scale, differs");
}

/// `trace-vk devices` says for every device whether rt-pipeline runs there, and `render --method
/// rt-pipeline` on device 0 agrees: refused before any output is written, in one sentence naming
/// what is missing (lavapipe), or rendered (a device with the ray-tracing extensions).
#[test]
fn devices_say_where_rt_pipeline_runs_and_render_agrees() {
    let dir = scratch("rt-pipeline");
    let out = assert_ok(&run(&dir, "trace-vk", &["devices"]), "trace-vk devices");
    let lines: Vec<&str> = out.lines().filter(|l| !l.trim().is_empty()).collect();
    assert!(!lines.is_empty());
    for l in &lines {
        assert!(l.ends_with("rt-pipeline: supported") || l.contains("rt-pipeline: no (lacks VK_KHR_"), "{l}");
    }
    if lines[0].contains("llvmpipe") {
        assert!(lines[0].contains("rt-pipeline: no (lacks VK_KHR_acceleration_structure"), "{}", lines[0]);
    }
    let room = room(&dir);
    let args = ["render", &room, "--device", "0", "--method", "rt-pipeline", "--res", "16x12", "-o", "rt.png"];
    let o = run(&dir, "trace-vk", &args);
    match lines[0].split_once("rt-pipeline: no (lacks ") {
        Some((_, missing)) => {
            let missing = missing.trim_end_matches(')');
            let line = assert_one_sentence_error(&o, missing);
            assert!(line.starts_with("error: --method rt-pipeline needs "), "{line}");
            assert!(!dir.join("rt.png").exists(), "a refused run wrote its image");
        }
        None => {
            let said = assert_ok(&o, "rt-pipeline on a device that supports it");
            assert!(said.contains("rt-pipeline: the driver built its structures in "), "{said}");
            assert_eq!(image::image_dimensions(dir.join("rt.png")).unwrap(), (16, 12));
        }
    }
}
