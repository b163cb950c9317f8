//! Issue 9 item 5 end to end: `trace-vk render` on a device that fails mid-run (the device layer's
//! simulated faults, `TRACER_VK_FAULT`) ends with one sentence and exit status 1, and leaves every
//! output as it was: no partial image, AOV or heatmap file, no temporary file, and an image from
//! an earlier run untouched.

mod common;

use common::{assert_ok, assert_one_sentence_error, bin, run, scene, scratch, snapshot};
use std::process::{Command, Stdio};

#[test]
fn a_gpu_fault_leaves_no_output_file() {
    let dir = scratch("faults");
    let o = run(&dir, "bvhc", &["compile", scene("room.toml").to_str().unwrap(), "-o", "room.bvh", "--quiet"]);
    assert_ok(&o, "compiling the room");
    // An earlier run's image, which a failed run must leave as it was.
    std::fs::write(dir.join("old.png"), b"an earlier image").unwrap();
    let before = snapshot(&dir);
    for (fault, says) in [
        ("device-lost", "device was lost"),
        ("timeout", "did not finish its work"),
        ("out-of-memory:4096", "ran out of memory"),
        ("lost", "is not a fault"),
    ] {
        for outputs in [&["-o", "new.png", "--aov", "new.exr", "--heatmap", "heat.png"][..], &["-o", "old.png"]] {
            let mut args = vec!["render", "room.bvh", "--res", "64x48"];
            args.extend_from_slice(outputs);
            let o = Command::new(bin("trace-vk"))
                .args(&args)
                .current_dir(&dir)
                .env(tracer_vk::FAULT_VARIABLE, fault)
                .stdin(Stdio::null())
                .output()
                .expect("trace-vk runs");
            let line = assert_one_sentence_error(&o, says);
            assert_eq!(o.status.code(), Some(1), "{fault}: {line}");
            assert_eq!(snapshot(&dir), before, "{fault} {outputs:?}: the folder changed");
        }
    }
}
