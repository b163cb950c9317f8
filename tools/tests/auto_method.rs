//! `trace-vk --method auto` end to end on whatever Vulkan device is present (lavapipe in CI; it
//! fails, never skips, without one): the first run calibrates and caches its pick beside the
//! scene file, the next reads it without calibrating, a damaged cache is replaced, a changed scene
//! or `--recalibrate` calibrates again, and `bench --methods auto` reads the same cache. The
//! candidates are narrowed to LST and the stackless walk, whose kernels lavapipe compiles fast.

mod common;

use common::{assert_ok, run, scene, scratch, text};
use std::path::Path;

const MAGIC: &str = "trace-vk method calibration 1";

fn compile_room(dir: &Path, extra: &[&str]) {
    let room = scene("room.toml");
    let mut args = vec!["compile", room.to_str().unwrap(), "-o", "room.bvh", "--quiet"];
    args.extend(extra);
    assert_ok(&run(dir, "bvhc", &args), "compiling the room");
}

/// Renders with `--method auto` and returns (stdout, stderr).
fn render(dir: &Path, extra: &[&str]) -> (String, String) {
    let mut args = vec![
        "render",
        "room.bvh",
        "--method",
        "auto",
        "--candidates",
        "lst,stackless",
        "--res",
        "24x16",
        "-o",
        "a.png",
    ];
    args.extend(extra);
    let o = run(dir, "trace-vk", &args);
    assert_ok(&o, "trace-vk render --method auto");
    text(&o)
}

/// The method the render line says it rendered with.
fn rendered_with(out: &str) -> String {
    let line = out.lines().next().expect("a render line");
    let after = line.split(" with ").nth(1).expect("the render line names its method");
    after.split(' ').next().unwrap().to_owned()
}

fn calibrated(out: &str) -> bool {
    out.contains("auto: ") && out.contains(" after calibrating (")
}

fn read_cached(out: &str) -> bool {
    out.contains("(calibration cached in ")
}

#[test]
fn auto_calibrates_once_and_reads_its_cache_until_the_scene_changes() {
    let dir = scratch("auto");
    compile_room(&dir, &[]);
    let cache = dir.join("room.bvh.methods");

    let (out, _) = render(&dir, &[]);
    assert!(calibrated(&out) && out.contains("cached in room.bvh.methods"), "{out}");
    let picked = rendered_with(&out);
    assert!(["lst", "stackless"].contains(&picked.as_str()), "{out}");
    assert!(out.contains(&format!("auto: {picked} after calibrating")), "{out}");
    assert!(out.contains("lst ") && out.contains("stackless "), "both candidates are timed: {out}");
    let text1 = std::fs::read_to_string(&cache).expect("the pick is cached beside the scene");
    assert!(text1.starts_with(MAGIC) && text1.lines().count() == 2, "{text1}");
    assert_eq!(text1.lines().nth(1).unwrap().split('\t').nth(2), Some(picked.as_str()), "{text1}");
    let image1 = std::fs::read(dir.join("a.png")).unwrap();

    // The second run reads the pick, renders the same image and leaves the cache as it was.
    let (out, err) = render(&dir, &[]);
    assert!(read_cached(&out) && !calibrated(&out), "{out}");
    assert_eq!(rendered_with(&out), picked);
    assert!(!err.contains("warning"), "{err}");
    assert_eq!(std::fs::read(dir.join("a.png")).unwrap(), image1);
    assert_eq!(std::fs::read_to_string(&cache).unwrap(), text1);

    // Another mode is another key: calibrated and added beside the first.
    let (out, _) = render(&dir, &["--mode", "cast"]);
    assert!(calibrated(&out), "{out}");
    assert_eq!(std::fs::read_to_string(&cache).unwrap().lines().count(), 3);
    let (out, _) = render(&dir, &["--mode", "cast"]);
    assert!(read_cached(&out), "{out}");

    // --recalibrate calibrates again even with a pick cached.
    let (out, _) = render(&dir, &["--recalibrate"]);
    assert!(calibrated(&out), "{out}");

    // A damaged cache is ignored with a warning and replaced by a sound one.
    for damage in ["not a cache at all", &format!("{MAGIC}\nonly\ttwo fields\n")] {
        std::fs::write(&cache, damage).unwrap();
        let (out, err) = render(&dir, &[]);
        assert!(err.contains("warning: ignoring the method cache") && err.contains("replaced"), "{err}");
        assert!(calibrated(&out), "{out}");
        let (out, err) = render(&dir, &[]);
        assert!(read_cached(&out) && !err.contains("warning"), "the replaced cache is read: {out} {err}");
    }

    // A changed scene (compiled again with other leaves) invalidates the picks: its entries are
    // dropped with a warning and the new scene is calibrated.
    compile_room(&dir, &["--max-leaf-size", "2"]);
    let (out, err) = render(&dir, &[]);
    assert!(err.contains("another version of the scene"), "{err}");
    assert!(calibrated(&out), "{out}");
    assert_eq!(std::fs::read_to_string(&cache).unwrap().lines().count(), 2, "only the new scene's entry stays");
    let (out, _) = render(&dir, &[]);
    assert!(read_cached(&out), "{out}");

    // bench reads the same cache: its row names the pick, and no calibration runs.
    let o = run(
        &dir,
        "trace-vk",
        &[
            "bench",
            "room.bvh",
            "--methods",
            "auto",
            "--candidates",
            "lst,stackless",
            "--cameras",
            "medium",
            "--res",
            "24x16",
            "--modes",
            "whitted2",
            "--frames",
            "2",
            "--warmup",
            "0",
            "--csv",
            "b.csv",
        ],
    );
    let out = assert_ok(&o, "trace-vk bench --methods auto");
    assert!(read_cached(&out) && !calibrated(&out), "{out}");
    let csv = std::fs::read_to_string(dir.join("b.csv")).unwrap();
    assert!(csv.contains(&format!(",auto:{},", rendered_with(&render(&dir, &[]).0))), "{csv}");
}

/// The built-in scene has no file to cache beside: it is calibrated and says it is not cached.
#[test]
fn the_built_in_scene_is_calibrated_and_not_cached() {
    let dir = scratch("auto-builtin");
    let o = run(
        &dir,
        "trace-vk",
        &["render", "--method", "auto", "--candidates", "lst", "--res", "16x12", "--mode", "cast", "-o", "b.png"],
    );
    let out = assert_ok(&o, "trace-vk render --method auto on the built-in scene");
    assert!(out.contains("auto: lst after calibrating (lst ") && out.contains("not cached"), "{out}");
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1, "only the image is written");
}
