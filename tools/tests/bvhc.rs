//! `bvhc` end to end: the real binary on the shipped bunny and on bad input.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bvhc(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_bvhc")).args(args).output().expect("the bvhc binary runs")
}

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("tools/ sits in the workspace").to_path_buf()
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("bvhc-test-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir is writable");
    dir
}

fn text(o: &Output) -> (String, String) {
    (String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned())
}

/// An error is one line on stderr starting with "error: ", and the exit status is non-zero.
fn assert_one_sentence_error(o: &Output, must_contain: &str) {
    let (_, err) = text(o);
    assert!(!o.status.success(), "expected failure, got success; stderr: {err}");
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "expected one line of error, got: {err:?}");
    assert!(lines[0].starts_with("error: "), "{err}");
    assert!(lines[0].contains(must_contain), "{err:?} should mention {must_contain:?}");
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
