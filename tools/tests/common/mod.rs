//! Running the real binaries in the tests: outputs, one-sentence errors, scratch folders.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};
pub use tests::Scratch;

pub fn bin(name: &str) -> &'static str {
    match name {
        "bvhc" => env!("CARGO_BIN_EXE_bvhc"),
        "trace-cpu" => env!("CARGO_BIN_EXE_trace-cpu"),
        "trace-vk" => env!("CARGO_BIN_EXE_trace-vk"),
        "stress" => env!("CARGO_BIN_EXE_stress"),
        _ => panic!("no binary {name}"),
    }
}

pub fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("tools/ sits in the workspace").to_path_buf()
}

pub fn scene(name: &str) -> PathBuf {
    repo().join("scenes").join(name)
}

/// A fresh, empty folder for one test, removed with its contents when the guard is dropped (a
/// run of the suite left some thirty folders in the temporary directory before).
pub fn scratch(name: &str) -> Scratch {
    Scratch::new(&format!("tools-{name}"))
}

/// Runs a program in `dir` with a time limit: a hang is a failure, not a stuck test.
pub fn run_in(dir: &Path, program: &str, args: &[&str], limit: Duration) -> Output {
    let mut child = Command::new(bin(program))
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary runs");
    let start = Instant::now();
    while child.try_wait().expect("wait works").is_none() {
        if start.elapsed() > limit {
            let _ = child.kill();
            panic!("{program} {args:?} ran past {limit:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    child.wait_with_output().expect("output is collected")
}

pub fn run(dir: &Path, program: &str, args: &[&str]) -> Output {
    run_in(dir, program, args, Duration::from_secs(120))
}

pub fn text(o: &Output) -> (String, String) {
    (String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned())
}

pub fn assert_ok(o: &Output, what: &str) -> String {
    let (out, err) = text(o);
    assert!(o.status.success(), "{what} failed: {err}");
    out
}

/// An error is one line on stderr starting with "error: ", the exit status is 1 or 2 (never a
/// panic's 101, an abort or a signal), and the line contains `must_contain`. Returns the line.
pub fn assert_one_sentence_error(o: &Output, must_contain: &str) -> String {
    let (_, err) = text(o);
    assert!(!o.status.success(), "expected failure, got success; stderr: {err}");
    assert!(matches!(o.status.code(), Some(1 | 2)), "exit status {:?} (panic, abort or signal): {err}", o.status);
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "expected one line of error, got: {err:?}");
    assert!(lines[0].starts_with("error: "), "{err}");
    assert!(!lines[0].contains("panicked"), "{err}");
    assert!(lines[0].contains(must_contain), "{err:?} should mention {must_contain:?}");
    lines[0].to_owned()
}

/// Every file in a folder with its bytes, to show that a failed run left them as they were.
pub fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut v: Vec<(PathBuf, Vec<u8>)> = std::fs::read_dir(dir)
        .expect("readable folder")
        .map(|e| e.expect("entry").path())
        .map(|p| {
            let bytes = if p.is_file() { std::fs::read(&p).expect("readable file") } else { Vec::new() };
            (p, bytes)
        })
        .collect();
    v.sort();
    v
}
