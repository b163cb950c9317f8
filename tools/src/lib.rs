//! What the command-line programs share: loading scenes (the built-in bunny included), the render
//! options every tracer takes, and writing images, heatmaps and AOV files.

pub mod bench;
pub mod output;
pub mod progress;
pub mod render_args;

use bvh_format::SceneFile;
use std::path::Path;

/// The built-in default scene: `scenes/bunny.toml` and `scenes/bunny.glb`, embedded in the binary
/// and compiled at start-up (a fraction of a second), so that a tracer needs no file to run.
pub fn builtin_scene() -> Result<SceneFile, String> {
    const TOML: &str = include_str!("../../scenes/bunny.toml");
    const GLB: &[u8] = include_bytes!("../../scenes/bunny.glb");
    let dir = std::env::temp_dir().join(format!("bvh-builtin-{}", std::process::id()));
    let result = (|| {
        std::fs::create_dir_all(&dir).map_err(|e| format!("cannot unpack the built-in scene: {e}"))?;
        std::fs::write(dir.join("bunny.toml"), TOML).map_err(|e| format!("cannot unpack the built-in scene: {e}"))?;
        std::fs::write(dir.join("bunny.glb"), GLB).map_err(|e| format!("cannot unpack the built-in scene: {e}"))?;
        compile_default(&dir.join("bunny.toml"))
    })();
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// Imports a mesh or scene description and compiles it with the default build parameters.
pub fn compile_default(path: &Path) -> Result<SceneFile, String> {
    let scene = bvh_build::import::load(path, &Default::default()).map_err(|e| e.to_string())?;
    bvh_build::compile(&scene, &Default::default(), Default::default()).map_err(|e| e.to_string())
}

/// A scene for a tracer: a compiled `.bvh` file as it is, a mesh or description compiled on the
/// fly with default parameters, or the built-in bunny when no path is given.
pub fn load_scene(path: Option<&Path>) -> Result<SceneFile, String> {
    match path {
        None => builtin_scene(),
        Some(p) if p.extension().is_some_and(|e| e.eq_ignore_ascii_case("bvh")) => {
            bvh_format::read_file(p).map_err(|e| e.to_string())
        }
        Some(p) => compile_default(p),
    }
}

/// The CPU's model name, for benchmark tables ("?" where the system does not say).
pub fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            let line = s.lines().find(|l| l.starts_with("model name"))?;
            Some(line.split_once(':')?.1.trim().to_owned())
        })
        .unwrap_or_else(|| "?".to_owned())
}
