//! Every option of bvhc, trace-cpu and trace-vk given a bad value (empty, negative, zero, huge,
//! NaN, a wrong count, a missing or unreadable file) ends with one sentence and exit status 1 or 2:
//! never a panic, an abort or a hang, and every file that was there stays as it was.

mod common;

use common::{assert_one_sentence_error, run_in, scene, scratch, snapshot};
use std::time::Duration;

/// Bad values of each numeric kind.
const BAD_COUNT: &[&str] = &["", "-1", "0", "99999999999999999999", "nan", "1.5", "x"];
const BAD_FLOAT: &[&str] = &["", "-1", "nan", "inf", "1e39", "x"];
const BAD_VEC3: &[&str] = &["", "1,2", "1,2,3,4", "nan,0,0", "1e39,0,0", "a,b,c", "-"];
const BAD_SIZE: &[&str] = &["", "0x0", "-4x4", "8x-8", "100000x100000", "8", "x", "nanxnan"];
const BAD_PATH_OUT: &[&str] = &["", "missing/out.png", "out.tiff", "folder"];

#[test]
fn every_option_refuses_bad_values_in_one_sentence_and_touches_nothing() {
    let dir = scratch("robust");
    let o = run_in(
        &dir,
        "bvhc",
        &["compile", scene("room.toml").to_str().unwrap(), "-o", "room.bvh", "--quiet"],
        Duration::from_secs(60),
    );
    assert!(o.status.success());
    std::fs::write(dir.join("tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    std::fs::write(dir.join("out.png"), b"an image the user keeps").unwrap();
    std::fs::write(dir.join("out.tiff"), b"another").unwrap();
    std::fs::write(dir.join("bench.csv"), b"a table").unwrap();
    std::fs::write(dir.join("empty.bvh"), b"").unwrap();
    std::fs::write(dir.join("text.bvh"), b"not a scene\n").unwrap();
    std::fs::write(dir.join("empty.obj"), b"").unwrap();
    std::fs::create_dir(dir.join("folder")).unwrap();
    std::fs::create_dir(dir.join("folder.bvh")).unwrap();
    let before = snapshot(&dir);

    let mut cases: Vec<(&str, Vec<String>)> = Vec::new();
    // `tool base.. option value` for each value; an empty option puts the value in the base's place.
    fn add(
        cases: &mut Vec<(&'static str, Vec<String>)>,
        tool: &'static str,
        base: &[&str],
        option: &str,
        values: &[&str],
    ) {
        for v in values {
            let mut args: Vec<String> = base.iter().map(|s| s.to_string()).collect();
            if !option.is_empty() {
                args.push(option.to_owned());
            }
            args.push(v.to_string());
            cases.push((tool, args));
        }
    }
    let c = &mut cases;

    // bvhc
    let compile = ["compile", "tri.obj", "-o", "tri.bvh"];
    add(c, "bvhc", &["compile"], "", &["", "missing.obj", "empty.obj", "folder", "text.bvh", "out.png"]);
    add(c, "bvhc", &["compile", "tri.obj"], "-o", &["", "missing/x.bvh", "x.png", "folder", "tri.obj"]);
    add(c, "bvhc", &compile, "--layout", &["", "none", "-1"]);
    add(c, "bvhc", &compile, "--strategy", &["", "best"]);
    add(c, "bvhc", &compile, "--bins", &[BAD_COUNT, &["1", "100000"]].concat());
    add(c, "bvhc", &compile, "--traversal-cost", BAD_FLOAT);
    add(c, "bvhc", &compile, "--intersection-cost", &[BAD_FLOAT, &["0"]].concat());
    add(c, "bvhc", &compile, "--max-leaf-size", BAD_COUNT);
    for sub in ["info", "verify"] {
        add(c, "bvhc", &[sub], "", &["", "missing.bvh", "empty.bvh", "text.bvh", "folder.bvh"]);
    }

    // Both tracers' render options, then trace-vk's own.
    for tracer in ["trace-cpu", "trace-vk"] {
        let render = ["render", "room.bvh", "--res", "8x8", "-o", "out.png"];
        add(c, tracer, &["render"], "", &["missing.bvh", "empty.bvh", "text.bvh", "folder.bvh", "empty.obj"]);
        add(c, tracer, &render, "--mode", &["", "fast"]);
        let ao = [&render[..], &["--mode", "ao"]].concat();
        add(c, tracer, &ao, "--ao-samples", &[BAD_COUNT, &["1025", "99999999999"]].concat());
        add(c, tracer, &ao, "--ao-length", &[BAD_FLOAT, &["0", "-0.1"]].concat());
        add(c, tracer, &render, "--camera", &["", "nope", "-1"]);
        add(c, tracer, &[&render[..], &["--at", "0,1,0"]].concat(), "--eye", BAD_VEC3);
        add(c, tracer, &[&render[..], &["--eye", "0,0,3"]].concat(), "--at", BAD_VEC3);
        add(c, tracer, &render, "--up", &[BAD_VEC3, &["0,0,0"]].concat());
        add(c, tracer, &[&render[..], &["--eye", "0,0,3", "--at", "0,0,0"]].concat(), "--up", &["0,0,-1", "0,0,0"]);
        add(c, tracer, &render, "--fov", &[BAD_FLOAT, &["0", "180"]].concat());
        add(c, tracer, &["render", "room.bvh", "-o", "out.png"], "--res", BAD_SIZE);
        add(c, tracer, &render, "--light", &[BAD_VEC3, &["1,2,3,-1,0,0", "1,2,3,nan,0,0"]].concat());
        add(c, tracer, &render, "--lights", &["", "-1", "99999999999", "nan", "1000"]);
        add(c, tracer, &render, "--indirections", &["", "-1", "99999999999", "nan", "100000"]);
        add(c, tracer, &["render", "room.bvh", "--res", "8x8"], "-o", BAD_PATH_OUT);
        add(c, tracer, &render, "--heatmap", &["", "missing/h.png", "h.exr", "out.png", "folder"]);
        add(c, tracer, &[&render[..], &["--heatmap", "h.png"]].concat(), "--heatmap-max", BAD_COUNT);
        add(c, tracer, &render, "--heatmap-max", &["5"]);
        add(c, tracer, &render, "--aov", &["", "missing/a.exr", "a.png", "out.png", "folder"]);
        add(c, tracer, &render, "--method", &["", "fastest"]);
    }
    let cpu = ["render", "room.bvh", "--res", "8x8", "-o", "out.png"];
    add(c, "trace-cpu", &cpu, "--threads", &["", "-1", "0", "99999999999", "nan", "100000"]);
    let vk = ["render", "room.bvh", "--res", "8x8", "-o", "out.png"];
    add(c, "trace-vk", &vk, "--workgroup", &[BAD_SIZE, &["64x64"]].concat());
    add(c, "trace-vk", &vk, "--device", &["", "-1", "nan", "99999999999", "999"]);
    add(c, "trace-vk", &vk, "--persistent", &["", "maybe", "off,on"]);
    add(c, "trace-vk", &vk, "--persistent-refill", &["", "0", "33", "-1", "nan", "8,16"]);
    add(c, "trace-vk", &vk, "--persistent-invocations", &["", "0", "-1", "99999999999"]);
    add(c, "trace-vk", &[&vk[..], &["--method", "sst"]].concat(), "--persistent", &["on"]);
    let auto = ["render", "room.bvh", "--res", "8x8", "-o", "out.png", "--method", "auto"];
    add(c, "trace-vk", &auto, "--candidates", &["", "fastest", "auto"]);
    let bench =
        ["bench", "room.bvh", "--res", "8x8", "--frames", "1", "--warmup", "0", "--methods", "lst", "--modes", "cast"];
    add(c, "trace-vk", &bench, "--cameras", &["", "nope", "-1"]);
    add(c, "trace-vk", &bench, "--res", BAD_SIZE);
    add(
        c,
        "trace-vk",
        &bench,
        "--modes",
        &["", "fast", "whitted-1", "whitted99999", "whitted", "ao", "ao0", "ao1025", "ao8:0", "ao8:nan", "ao8:", "aox"],
    );
    add(c, "trace-vk", &bench, "--methods", &["", "fastest"]);
    add(c, "trace-vk", &bench, "--frames", &["", "-1", "0", "99999999999", "nan"]);
    add(c, "trace-vk", &bench, "--warmup", &["", "-1", "99999999999", "nan"]);
    add(c, "trace-vk", &bench, "--workgroup", &["", "0x0", "64x64"]);
    add(c, "trace-vk", &bench, "--csv", &["", "missing/b.csv", "b.txt", "folder"]);
    add(c, "trace-vk", &bench, "--device", &["-1", "999"]);
    add(c, "trace-vk", &bench, "--intersect", &["", "moller"]);
    add(c, "trace-vk", &bench, "--in-flight", &["", "0", "-1", "65", "nan"]);
    add(c, "trace-vk", &bench, "--tile-pixels", &["", "0", "-1", "nan"]);
    add(c, "trace-vk", &bench, "--candidates", &["fastest", "auto"]);
    add(c, "trace-vk", &bench, "--persistent", &["", "maybe", "off,maybe"]);
    add(c, "trace-vk", &bench, "--persistent-refill", &["", "0", "8,33", "8,nan"]);
    add(c, "trace-vk", &["bench"], "", &["missing.bvh", "empty.bvh", "text.bvh", "folder.bvh"]);

    assert!(cases.len() > 250, "{} cases", cases.len());
    // Every case runs, and the failures are listed together: one fix often mends several.
    let mut failures = Vec::new();
    for (tool, args) in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let o = run_in(&dir, tool, &args, Duration::from_secs(60));
        if let Err(why) = std::panic::catch_unwind(|| assert_one_sentence_error(&o, "")) {
            let why = why.downcast_ref::<String>().cloned().unwrap_or_default();
            failures.push(format!("{tool} {}: {why}", args.join(" ")));
        }
        if snapshot(&dir) != before {
            failures.push(format!("{tool} {}: changed the folder", args.join(" ")));
            restore(&dir, &before);
        }
    }
    assert!(failures.is_empty(), "{} of {} cases:\n{}", failures.len(), cases.len(), failures.join("\n"));
}

/// Puts the folder back as `before` had it, so that one failing case does not fail the next.
fn restore(dir: &std::path::Path, before: &[(std::path::PathBuf, Vec<u8>)]) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let p = entry.unwrap().path();
        if !before.iter().any(|(q, _)| *q == p) {
            let _ = if p.is_dir() { std::fs::remove_dir_all(&p) } else { std::fs::remove_file(&p) };
        }
    }
    for (p, bytes) in before {
        if p.is_file() {
            std::fs::write(p, bytes).unwrap();
        }
    }
}

/// `stress --method` runs only the methods it names (so that a long sweep can be split over
/// several runs) and refuses a name that is none of them, writing nothing.
#[test]
fn stress_runs_only_the_methods_asked_for() {
    let dir = scratch("stress-method");
    let args = |method: &'static str| {
        ["--cpu-only", "--quick", "--axis", "distance", "--method", method, "--out", "r.md", "--chart", "c"]
    };
    let o = run_in(&dir, "stress", &args("GPU nope"), Duration::from_secs(60));
    assert_one_sentence_error(&o, "none of the sweep's methods");
    assert!(!dir.join("r.md").exists(), "a refused run wrote its report");
    let o = run_in(&dir, "stress", &args("cpu ordered"), Duration::from_secs(120));
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let report = std::fs::read_to_string(dir.join("r.md")).expect("the report is written");
    assert!(report.contains("| point | CPU ordered |"), "{report}");
    assert!(!report.contains("CPU stackless") && !report.contains("CPU packet"), "{report}");
    assert!(report.contains("--method \"cpu ordered\""), "the report names its command: {report}");
}
