//! Scene import: OBJ (tobj), glTF/GLB (gltf) and scene descriptions (TOML) into a [`Scene`].
//!
//! [`load`] picks the reader from the file extension. Every reader produces triangles in a stable,
//! documented order, because the tracers report input triangle indices:
//!
//! - OBJ: models (objects and groups) in file order, faces in file order; polygons are split into
//!   fans, so a face with `k` corners becomes `k - 2` consecutive triangles.
//! - glTF: the default scene (or the first scene; without scenes, every root node) walked depth
//!   first, nodes in the order the scene and each node list them, primitives in mesh order.
//! - description: the `[[object]]` entries in file order, each contributing its triangles in the
//!   order above (generated shapes in the order documented in [`shapes`]).
//!
//! Shading normals: normals stored in the file are used (transformed with the inverse transpose
//! of the node or placement transform); where a file has none, flat normals are computed (the
//! glTF rule), or area-weighted smooth normals when [`ImportOptions::smooth_normals`] is set.
//!
//! Material mapping (MTL and glTF to the Whitted model) is described in `docs/materials.md`, the
//! description format in `docs/scene-description.md`.

pub mod defaults;
pub mod description;
pub(crate) mod geometry;
pub mod gltf;
pub mod materials;
pub mod obj;
pub mod shapes;

use crate::scene::Scene;
use bvh_format::{Camera, Material, SceneSettings};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// How to read a scene.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ImportOptions {
    /// Where a mesh has no normals, compute area-weighted smooth vertex normals instead of flat
    /// ones. A description can override this per mesh.
    pub smooth_normals: bool,
}

/// What can go wrong while reading a scene. Each message is one sentence naming the file.
#[derive(Debug, Error)]
pub enum ImportError {
    #[error("cannot read {}: {source}", path.display())]
    Read { path: PathBuf, source: std::io::Error },
    #[error("{} has an unsupported extension (expected .obj, .gltf, .glb or .toml)", path.display())]
    UnsupportedExtension { path: PathBuf },
    #[error("{} is not a valid OBJ file: {message}", path.display())]
    Obj { path: PathBuf, message: String },
    #[error("{} is not a valid glTF file: {message}", path.display())]
    Gltf { path: PathBuf, message: String },
    #[error("{} is not a valid scene description: {message}", path.display())]
    Description { path: PathBuf, message: String },
    #[error("{}: {what} has a coordinate that is not a finite number", path.display())]
    NonFinite { path: PathBuf, what: String },
    #[error("{}: {what}", path.display())]
    IndexOutOfRange { path: PathBuf, what: String },
    #[error("the mesh file {} named in {} cannot be read: {source}", mesh.display(), path.display())]
    MissingMesh { path: PathBuf, mesh: PathBuf, source: std::io::Error },
    #[error("{} holds no triangles", path.display())]
    Empty { path: PathBuf },
    #[error("{}: {message}", path.display())]
    Defaults { path: PathBuf, message: String },
    #[error("{}: the material name {name:?} holds a NUL byte, which a scene file cannot store", path.display())]
    MaterialName { path: PathBuf, name: String },
}

/// Reads a scene, choosing the reader by extension (`.obj`, `.gltf`, `.glb`, `.toml`; any case).
///
/// A mesh file (OBJ, glTF) gets the three default cameras of [`defaults::cameras`] (followed by
/// the glTF file's own perspective cameras, if any), the default light of [`defaults::light_for`]
/// and default settings, with `max_indirections` 2 when a material reflects or refracts and 0
/// otherwise. A description sets all of these itself (see `docs/scene-description.md`).
pub fn load(path: &Path, opts: &ImportOptions) -> Result<Scene, ImportError> {
    Kind::of(path)?;
    load_bytes(path, &read_file(path)?, opts, &bvh_format::read_input)
}

/// Reads a file that a scene refers to: an OBJ's material library, a glTF buffer, a mesh of a
/// description. [`load`] reads the file system.
pub type ReadFile<'a> = &'a dyn Fn(&Path) -> std::io::Result<Vec<u8>>;

/// [`load`] of a file already in memory: `path` names it (its extension picks the reader, its
/// folder is where the files it refers to lie) and `read` reads those files, so that a caller
/// can serve them from memory or refuse them (the fuzz targets in `bvh-build/fuzz` do).
pub fn load_bytes(path: &Path, bytes: &[u8], opts: &ImportOptions, read: ReadFile<'_>) -> Result<Scene, ImportError> {
    let scene = match Kind::of(path)? {
        Kind::Description => description::load_bytes(path, bytes, opts, read)?,
        kind => {
            let (mut scene, file_cameras) = load_mesh_file(path, bytes, kind, opts, read)?;
            let (lo, hi) = scene.bounds().ok_or_else(|| ImportError::Empty { path: path.to_owned() })?;
            scene.cameras = defaults::cameras(lo, hi);
            scene.cameras.extend(file_cameras);
            scene.lights = vec![defaults::light_for(&scene.cameras[0], lo, hi)];
            defaults::check_finite(&scene.cameras, &scene.lights, lo, hi)
                .map_err(|message| ImportError::Defaults { path: path.to_owned(), message })?;
            scene.settings = SceneSettings {
                max_indirections: if scene.materials.iter().any(|m| m.kr > 0.0 || m.kt > 0.0) { 2 } else { 0 },
                ..SceneSettings::default()
            };
            scene
        }
    };
    // The scene file separates material names by NUL bytes (MTL and glTF names may hold one).
    if let Some(name) = scene.material_names.iter().find(|n| n.contains('\0')) {
        return Err(ImportError::MaterialName { path: path.to_owned(), name: name.clone() });
    }
    Ok(scene)
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    Obj,
    Gltf,
    Description,
}

impl Kind {
    pub(crate) fn of(path: &Path) -> Result<Kind, ImportError> {
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("obj") => Ok(Kind::Obj),
            Some("gltf" | "glb") => Ok(Kind::Gltf),
            Some("toml") => Ok(Kind::Description),
            _ => Err(ImportError::UnsupportedExtension { path: path.to_owned() }),
        }
    }
}

/// Triangles and materials of one OBJ or glTF file, `bytes` read from `path` (no cameras, lights
/// or settings in the scene), plus the file's own cameras. Errs when the file holds no
/// triangles.
pub(crate) fn load_mesh_file(
    path: &Path,
    bytes: &[u8],
    kind: Kind,
    opts: &ImportOptions,
    read: ReadFile<'_>,
) -> Result<(Scene, Vec<Camera>), ImportError> {
    let (scene, cameras) = match kind {
        Kind::Obj => (obj::load_bytes(path, bytes, opts, read)?, Vec::new()),
        Kind::Gltf => gltf::load_bytes(path, bytes, opts, read)?,
        Kind::Description => {
            return Err(ImportError::Description {
                path: path.to_owned(),
                message: "a scene description cannot be loaded as a mesh".to_owned(),
            });
        }
    };
    if scene.triangle_count() == 0 {
        return Err(ImportError::Empty { path: path.to_owned() });
    }
    Ok((scene, cameras))
}

pub(crate) fn read_file(path: &Path) -> Result<Vec<u8>, ImportError> {
    bvh_format::read_input(path).map_err(|source| ImportError::Read { path: path.to_owned(), source })
}

/// The material of triangles that have none.
pub const DEFAULT_MATERIAL_NAME: &str = "default";

pub(crate) fn default_material() -> Material {
    Material::default()
}

/// Runs a third-party parser so that a panic inside it (a bug there, reached by malformed input)
/// becomes an error instead of taking the program down.
pub(crate) fn guarded<T>(f: impl FnOnce() -> T) -> Option<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).ok()
}
