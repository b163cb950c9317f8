//! What the command-line programs share: command-line handling ([`cli`]), loading scenes (the
//! built-in bunny included), the render options every tracer takes ([`render_args`]), writing
//! every output safely ([`output`]), `trace-vk --method auto` ([`auto`]), the benchmark matrix ([`bench`], with the CPU tracer in
//! [`cpu_bench`], the Vulkan tracer in [`vk_bench`]) and the evaluation of speed against accuracy ([`eval`]).

pub mod auto;
pub mod bench;
pub mod cli;
pub mod cpu_bench;
pub mod eval;
pub mod output;
pub mod render_args;
pub mod stress;
pub mod vk_bench;

use bvh_format::SceneFile;
use std::path::Path;
use std::time::Instant;

/// A scene for a tracer, and whether it was compiled on the fly.
pub struct LoadedScene {
    pub file: SceneFile,
    /// Seconds spent importing and compiling a mesh, description or the built-in scene; `None`
    /// for a compiled `.bvh` read as it is.
    pub compile_seconds: Option<f64>,
}

impl LoadedScene {
    /// How a printed render time relates to loading: it never includes it, and says so when
    /// the scene was compiled on the fly.
    pub fn timing_note(&self) -> String {
        match self.compile_seconds {
            Some(s) => format!(" (not counting {s:.2} s to compile the scene on the fly)"),
            None => String::new(),
        }
    }
}

/// The built-in default scene: `scenes/bunny.toml` and `scenes/bunny.glb`, embedded in the binary
/// and compiled at start-up (a fraction of a second), so that a tracer needs no file to run.
pub fn builtin_scene() -> Result<SceneFile, String> {
    builtin_scene_with(bvh_build::Layouts::default())
}

/// [`builtin_scene`] with the given node layouts.
pub fn builtin_scene_with(layouts: bvh_build::Layouts) -> Result<SceneFile, String> {
    const TOML: &str = include_str!("../../scenes/bunny.toml");
    const GLB: &[u8] = include_bytes!("../../scenes/bunny.glb");
    let dir = std::env::temp_dir().join(format!("bvh-builtin-{}", std::process::id()));
    let result = (|| {
        std::fs::create_dir_all(&dir).map_err(|e| format!("cannot unpack the built-in scene: {e}"))?;
        std::fs::write(dir.join("bunny.toml"), TOML).map_err(|e| format!("cannot unpack the built-in scene: {e}"))?;
        std::fs::write(dir.join("bunny.glb"), GLB).map_err(|e| format!("cannot unpack the built-in scene: {e}"))?;
        compile_with(&dir.join("bunny.toml"), layouts)
    })();
    let _ = std::fs::remove_dir_all(&dir);
    result
}

/// Imports a mesh or scene description and compiles it with the default build parameters; what
/// the importer skipped is printed as warnings.
pub fn compile_default(path: &Path) -> Result<SceneFile, String> {
    compile_with(path, bvh_build::Layouts::default())
}

/// [`compile_default`] with the given node layouts.
pub fn compile_with(path: &Path, layouts: bvh_build::Layouts) -> Result<SceneFile, String> {
    let scene = bvh_build::import::load(path, &Default::default()).map_err(|e| e.to_string())?;
    print_warnings(&scene.warnings);
    bvh_build::compile(&scene, &Default::default(), layouts).map_err(|e| e.to_string())
}

/// The layouts a scene compiled on the fly gets for GPU methods by these names: the wide one too
/// where `cwbvh` is among them (it costs memory and compile time the others do not need).
pub fn layouts_for(methods: &[&str]) -> bvh_build::Layouts {
    // auto takes cwbvh among its candidates, so it gets the wide layout too.
    let wide = methods.iter().any(|m| {
        let name = m.split('+').next();
        name == Some(tracer_vk::kernels::Method::Cwbvh.name()) || name == Some(crate::vk_bench::AUTO)
    });
    bvh_build::Layouts { wide, ..bvh_build::Layouts::default() }
}

/// Import warnings, one line each on standard error.
pub fn print_warnings(warnings: &[String]) {
    for w in warnings {
        eprintln!("warning: {w}");
    }
}

/// Whether a path names a compiled scene file (by its extension, any case).
pub fn is_compiled(path: &Path) -> bool {
    path.extension().is_some_and(|e| e.eq_ignore_ascii_case("bvh"))
}

/// A scene for a tracer: a compiled `.bvh` file as it is, a mesh or description compiled on the
/// fly with default parameters, or the built-in bunny when no path is given.
pub fn load_scene(path: Option<&Path>) -> Result<LoadedScene, String> {
    load_scene_with(path, bvh_build::Layouts::default())
}

/// [`load_scene`], compiling a mesh or description (or the built-in bunny) with `layouts`.
pub fn load_scene_with(path: Option<&Path>, layouts: bvh_build::Layouts) -> Result<LoadedScene, String> {
    let t0 = Instant::now();
    let (file, compiled) = match path {
        None => (builtin_scene_with(layouts)?, true),
        Some(p) if is_compiled(p) => (bvh_format::read_file(p).map_err(|e| e.to_string())?, false),
        Some(p) => (compile_with(p, layouts)?, true),
    };
    Ok(LoadedScene { file, compile_seconds: compiled.then(|| t0.elapsed().as_secs_f64()) })
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
