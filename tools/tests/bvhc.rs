//! `bvhc` end to end: the real binary on the shipped bunny and on bad input.

mod common;

use common::{assert_one_sentence_error, repo, scratch, text};
use std::path::Path;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn bvhc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_bvhc")).args(args).output().expect("the bvhc binary runs")
}

#[test]
fn compiles_verifies_and_describes_the_bunny() {
    let dir = scratch("bunny");
    let out = dir.join("bunny.bvh");
    let input = repo().join("scenes/bunny.glb");
    let o = bvhc(&["compile", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{:?}", text(&o));

    let o = bvhc(&["verify", out.to_str().unwrap()]);
    assert!(o.status.success(), "{:?}", text(&o));
    assert!(text(&o).0.contains("valid (69451 triangles"), "{:?}", text(&o));

    let o = bvhc(&["info", out.to_str().unwrap()]);
    assert!(o.status.success(), "{:?}", text(&o));
    let (info, _) = text(&o);
    for needle in [
        "triangles       69451",
        "bytes/triangle  file ",
        "\"medium\"",
        "light 1",
        "SAH cost",
        "leaf sizes",
        "child-pair nodes",
        "escape-pointer nodes",
        "binned (16 bins)",
    ] {
        assert!(info.contains(needle), "info lacks {needle:?}:\n{info}");
    }
    // The file agrees with the library's own reading of it.
    let scene = bvh_format::read_file(&out).expect("bvhc wrote a valid file");
    assert_eq!(scene.triangles.len(), 69451);
    assert!(info.contains(&format!("max {}", scene.stats().max_depth)));
}

#[test]
fn layout_and_strategy_options_reach_the_file() {
    let dir = scratch("options");
    let out = dir.join("sweep.bvh");
    let input = repo().join("scenes/bunny.glb");
    let o = bvhc(&[
        "compile",
        input.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--quiet",
        "--layout",
        "escape",
        "--strategy",
        "sweep",
        "--max-leaf-size",
        "4",
        "--traversal-cost",
        "2",
    ]);
    assert!(o.status.success(), "{:?}", text(&o));
    let scene = bvh_format::read_file(&out).unwrap();
    assert!(scene.child_pair.is_none() && scene.escape.is_some());
    assert_eq!(scene.build.strategy, bvh_format::Strategy::Sweep);
    assert_eq!(scene.build.max_leaf_size, 4);
    assert_eq!(scene.build.traversal_cost, 2.0);
    assert!(scene.stats().leaf_sizes.len() <= 5, "no leaf above 4 triangles");
}

/// `--layout` lists: `all` (or `both,wide`) adds the wide layout, which `info` and `verify` report;
/// the wide layout alone, without a binary one, is refused in one sentence.
#[test]
fn the_wide_layout_is_compiled_on_request_and_reported() {
    let dir = scratch("wide");
    let input = repo().join("scenes/bunny.glb");
    for (layout, file) in [("all", "all.bvh"), ("escape,wide", "escape-wide.bvh")] {
        let out = dir.join(file);
        let o = bvhc(&["compile", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "--quiet", "--layout", layout]);
        assert!(o.status.success(), "{layout}: {:?}", text(&o));
        let scene = bvh_format::read_file(&out).unwrap();
        let wide = scene.wide.as_deref().expect("the wide layout was asked for");
        assert_eq!(scene.child_pair.is_some(), layout == "all", "{layout}");
        let o = bvhc(&["info", out.to_str().unwrap()]);
        let (info, _) = text(&o);
        let line = format!("wide layout     {} nodes, depth {}", wide.len(), bvh_format::wide::depth(wide));
        assert!(info.contains(&line) && info.contains("wide nodes") && info.contains("(cwbvh)"), "{info}");
        let o = bvhc(&["verify", out.to_str().unwrap()]);
        assert!(o.status.success() && text(&o).0.contains("wide)"), "{:?}", text(&o));
    }
    let out = dir.join("never.bvh");
    let o = bvhc(&["compile", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "--layout", "wide"]);
    assert_one_sentence_error(&o, "binary one beside it");
    assert!(!out.exists());
}

#[test]
fn bad_input_gives_one_sentence_and_no_output() {
    let dir = scratch("bad");
    let out = dir.join("never.bvh");
    let o = bvhc(&["compile", dir.join("missing.obj").to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert_one_sentence_error(&o, "missing.obj");
    assert!(!out.exists());

    let input = repo().join("scenes/bunny.glb");
    let o = bvhc(&["compile", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "--bins", "1"]);
    assert_one_sentence_error(&o, "bin count");
    assert!(!out.exists());

    let obj = dir.join("nan.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n").unwrap();
    let o = bvhc(&["compile", obj.to_str().unwrap(), "-o", out.to_str().unwrap()]);
    assert_one_sentence_error(&o, "nan.obj");
    assert!(!out.exists());
}

/// A device given where a scene belongs (`/dev/zero` behind a scene's name, or as a file a
/// scene refers to) was read until memory ran out; it is refused at once, in one sentence.
#[cfg(unix)]
#[test]
fn a_device_given_as_a_scene_is_refused_not_read_until_memory_runs_out() {
    let dir = scratch("device");
    for name in ["zero.bvh", "zero.obj", "zero.glb", "zero.toml", "zero.mtl"] {
        std::os::unix::fs::symlink("/dev/zero", dir.join(name)).unwrap();
    }
    std::fs::write(dir.join("lib.obj"), "mtllib zero.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    std::fs::write(dir.join("refers.toml"), "[[object]]\ntype = \"mesh\"\nfile = \"zero.obj\"\n").unwrap();
    let limit = Duration::from_secs(30);
    for args in [
        &["info", "zero.bvh"][..],
        &["info", "/dev/zero"],
        &["compile", "zero.obj", "-o", "out.bvh"],
        &["compile", "zero.glb", "-o", "out.bvh"],
        &["compile", "zero.toml", "-o", "out.bvh"],
        &["compile", "lib.obj", "-o", "out.bvh"],
        &["compile", "refers.toml", "-o", "out.bvh"],
    ] {
        let o = common::run_in(&dir, "bvhc", args, limit);
        assert_one_sentence_error(&o, "is a device, not a file");
        assert!(!dir.join("out.bvh").exists(), "{args:?}");
    }
    let o = common::run_in(&dir, "trace-cpu", &["render", "zero.bvh", "--res", "8x8", "-o", "out.png"], limit);
    assert_one_sentence_error(&o, "is a device, not a file");
}

#[test]
fn damaged_files_fail_verification_with_one_sentence() {
    let dir = scratch("damaged");
    let good = dir.join("good.bvh");
    let input = repo().join("scenes/bunny.glb");
    assert!(bvhc(&["compile", input.to_str().unwrap(), "-o", good.to_str().unwrap(), "--quiet"]).status.success());
    let bytes = std::fs::read(&good).unwrap();

    let truncated = dir.join("truncated.bvh");
    std::fs::write(&truncated, &bytes[..bytes.len() / 2]).unwrap();
    assert_one_sentence_error(&bvhc(&["verify", truncated.to_str().unwrap()]), "truncated");

    let flipped = dir.join("flipped.bvh");
    let mut b = bytes.clone();
    let i = b.len() - 100;
    b[i] ^= 0x10;
    std::fs::write(&flipped, &b).unwrap();
    assert_one_sentence_error(&bvhc(&["verify", flipped.to_str().unwrap()]), "checksum");
    assert_one_sentence_error(&bvhc(&["info", flipped.to_str().unwrap()]), "checksum");

    let o = bvhc(&["verify", input.to_str().unwrap()]);
    assert_one_sentence_error(&o, "magic");
}

#[test]
fn negative_numbers_are_values_not_options() {
    let dir = scratch("negative");
    let out = dir.join("n.bvh");
    let input = repo().join("scenes/bunny.glb");
    for (option, value, needle) in
        [("--traversal-cost", "-1", "cost"), ("--bins", "-4", "bin count"), ("--max-leaf-size", "-2", "leaf size")]
    {
        let o = bvhc(&["compile", input.to_str().unwrap(), "-o", out.to_str().unwrap(), option, value]);
        let line = assert_one_sentence_error(&o, needle);
        assert!(!line.contains("unexpected argument"), "{option} {value}: {line}");
        assert!(line.contains(value), "the value is named: {line}");
    }
    assert!(!out.exists());
}

/// `bvhc info` lists the cameras (the default first) and the lights by name for every kind of
/// input: OBJ, glTF, GLB, a scene description and a compiled file.
#[test]
fn info_lists_cameras_and_lights_for_every_input_kind() {
    let dir = scratch("info-kinds");
    std::fs::write(dir.join("tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let compiled = dir.join("room.bvh");
    let room = repo().join("scenes/room.toml");
    assert!(bvhc(&["compile", room.to_str().unwrap(), "-o", compiled.to_str().unwrap(), "--quiet"]).status.success());
    let gltf = bvh_gltf(&dir);
    let inputs = [
        (dir.join("tri.obj"), "\"medium\"", 1, true),
        (gltf, "\"medium\"", 1, true),
        (repo().join("scenes/bunny.glb"), "\"medium\"", 1, true),
        (repo().join("scenes/forest.toml"), "\"medium\"", 2, true),
        (compiled, "\"medium\"", 2, false),
    ];
    for (input, first_camera, lights, on_the_fly) in inputs {
        let o = bvhc(&["info", input.to_str().unwrap()]);
        let (out, err) = text(&o);
        assert!(o.status.success(), "{}: {err}", input.display());
        assert_eq!(out.contains("compiled on the fly"), on_the_fly, "{out}");
        let cameras: Vec<&str> = out
            .lines()
            .skip_while(|l| !l.contains("cameras (the first"))
            .skip(1)
            .take_while(|l| !l.trim_start().starts_with("lights"))
            .collect();
        assert_eq!(cameras.len(), 3, "{}: {out}", input.display());
        assert!(cameras[0].trim_start().starts_with(first_camera), "{}: {cameras:?}", input.display());
        for k in 1..=lights {
            assert!(out.contains(&format!("light {k} ")), "{}: no light {k} in {out}", input.display());
        }
        assert!(!out.contains(&format!("light {} ", lights + 1)), "{out}");
    }
    // A text file is named as what it is, not as a truncated scene file.
    std::fs::write(dir.join("notes.txt"), "hello\n").unwrap();
    let line =
        assert_one_sentence_error(&bvhc(&["info", dir.join("notes.txt").to_str().unwrap()]), "not a BVH scene file");
    assert!(!line.contains("truncated"), "{line}");
}

/// A minimal glTF (one triangle, embedded buffer) written beside the other inputs.
fn bvh_gltf(dir: &Path) -> std::path::PathBuf {
    let floats: [f32; 9] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let bytes: Vec<u8> = floats.iter().flat_map(|f| f.to_le_bytes()).collect();
    const B64: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut b64 = String::new();
    for c in bytes.chunks(3) {
        let n =
            (u32::from(c[0]) << 16) | (u32::from(*c.get(1).unwrap_or(&0)) << 8) | u32::from(*c.get(2).unwrap_or(&0));
        for k in 0..4 {
            b64.push(if k <= c.len() { B64[(n >> (18 - 6 * k) & 63) as usize] as char } else { '=' });
        }
    }
    let json = format!(
        r#"{{"asset": {{"version": "2.0"}}, "scene": 0, "scenes": [{{"nodes": [0]}}], "nodes": [{{"mesh": 0}}],
        "meshes": [{{"primitives": [{{"attributes": {{"POSITION": 0}}}}]}}],
        "accessors": [{{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]}}],
        "bufferViews": [{{"buffer": 0, "byteLength": 36}}],
        "buffers": [{{"byteLength": 36, "uri": "data:application/octet-stream;base64,{b64}"}}]}}"#
    );
    let path = dir.join("tri.gltf");
    std::fs::write(&path, json).unwrap();
    path
}

/// Interrupting `bvhc compile` while it writes leaves neither a half-written file nor a damaged
/// output: the file that was there stays as it was.
#[test]
fn an_interrupted_compile_leaves_no_partial_file() {
    let dir = scratch("interrupt");
    let out = dir.join("dragon.bvh");
    std::fs::write(&out, b"the old file").unwrap();
    let input = repo().join("scenes/dragon.glb");
    let mut caught_writing = false;
    for _attempt in 0..3 {
        let mut child = Command::new(env!("CARGO_BIN_EXE_bvhc"))
            .args(["compile", input.to_str().unwrap(), "-o", out.to_str().unwrap(), "--quiet"])
            .spawn()
            .unwrap();
        let partial = dir.join(format!(".dragon.bvh.{}.partial", child.id()));
        let start = Instant::now();
        // Wait for the write to begin, then interrupt it.
        while child.try_wait().unwrap().is_none() && !partial.exists() && start.elapsed() < Duration::from_secs(300) {
            std::thread::sleep(Duration::from_micros(200));
        }
        let writing = partial.exists();
        let _ = Command::new("kill").args(["-TERM", &child.id().to_string()]).status();
        let status = child.wait().unwrap();
        if writing {
            caught_writing = true;
            assert_eq!(status.code(), Some(128 + 15), "{status:?}");
            assert_eq!(std::fs::read(&out).unwrap(), b"the old file");
            let left: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
            assert_eq!(left.len(), 1, "only the old output remains: {left:?}");
            break;
        }
        std::fs::write(&out, b"the old file").unwrap();
    }
    assert!(caught_writing, "the write was never seen in progress");
}

/// Faces with fewer than three corners are not dropped silently: bvhc compiles the rest and
/// warns with the count, on standard error, once.
#[test]
fn short_faces_are_counted_in_a_warning() {
    let dir = scratch("short-faces");
    let obj = dir.join("short.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\nf 2 3\n").unwrap();
    let out = dir.join("short.bvh");
    let o = bvhc(&["compile", obj.to_str().unwrap(), "-o", out.to_str().unwrap(), "--quiet"]);
    let (_, err) = text(&o);
    assert!(o.status.success(), "{err}");
    let warnings: Vec<&str> = err.lines().filter(|l| l.starts_with("warning: ")).collect();
    assert_eq!(warnings.len(), 1, "{err}");
    assert!(warnings[0].contains("2 faces with fewer than three corners skipped"), "{err}");
    assert!(out.exists());
}
