//! The importer fuzz targets' inputs in the normal test suite: every seed (cut from `scenes/`)
//! must import and pass the fuzz targets' checks, and every input that once crashed a target
//! (`bvh-build/fuzz/regressions/<target>/`) must now give a scene that passes them or a
//! one-sentence error, through the same readers and checks as the fuzz targets.

#[path = "../fuzz/src/lib.rs"]
mod fuzz;

use bvh_build::Scene;
use bvh_build::import::{ImportError, ImportOptions};
use std::path::{Path, PathBuf};

type Import = fn(&[u8], &ImportOptions) -> Result<Scene, ImportError>;

const TARGETS: [(&str, Import); 3] =
    [("obj", fuzz::import_obj), ("gltf", fuzz::import_gltf), ("description", fuzz::import_description)];

fn files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = match std::fs::read_dir(dir) {
        Ok(entries) => entries.map(|e| e.unwrap().path()).filter(|p| p.is_file()).collect(),
        Err(_) => Vec::new(),
    };
    v.sort();
    v
}

fn fuzz_dir(what: &str, target: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz").join(what).join(target)
}

#[test]
fn every_seed_imports_and_passes_the_fuzz_checks() {
    for (target, import) in TARGETS {
        let seeds = files(&fuzz_dir("seeds", target));
        assert!(seeds.len() >= 4, "{target}: only {} seeds", seeds.len());
        for seed in seeds {
            let data = std::fs::read(&seed).unwrap();
            for smooth in [false, true] {
                let result = import(&data, &ImportOptions { smooth_normals: smooth });
                if let Err(e) = &result {
                    panic!("{}: {e}", seed.display());
                }
                fuzz::check(&result);
            }
        }
    }
}

#[test]
fn every_saved_crash_input_passes_the_fuzz_checks() {
    for (target, import) in TARGETS {
        for input in files(&fuzz_dir("regressions", target)) {
            let data = std::fs::read(&input).unwrap();
            let result = std::panic::catch_unwind(|| fuzz::check(&import(&data, &fuzz::options(&data))));
            assert!(result.is_ok(), "{} fails the checks of fuzz target {target}", input.display());
        }
    }
}

/// The first crash the fuzzing found (`obj`, a `newmtl` name with NUL bytes): the scene file
/// separates material names by NUL, so such a name failed the compiled file's validation. Each
/// format can spell one (MTL bytes, a JSON `\u0000`, a quoted TOML key).
#[test]
fn material_names_with_a_nul_byte_are_refused_in_every_format() {
    for ((target, import), ext) in TARGETS.into_iter().zip(["obj", "gltf", "toml"]) {
        let file = fuzz_dir("regressions", target).join(format!("material-name-with-nul.{ext}"));
        let data = std::fs::read(&file).unwrap();
        match import(&data, &ImportOptions::default()) {
            Ok(_) => panic!("{} was accepted", file.display()),
            Err(e) => {
                let msg = e.to_string();
                assert!(msg.contains("holds a NUL byte, which a scene file cannot store"), "{target}: {msg}");
                assert!(msg.contains("fuzz."), "{target}: the file is named: {msg}");
            }
        }
    }
}
