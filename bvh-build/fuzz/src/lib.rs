//! What the importer fuzz targets share: the file readers they hand the importers (no target
//! touches the file system) and the checks on every scene an importer accepts.
//!
//! `bvh-build/tests/fuzz_regressions.rs` includes this file, so that the saved crash inputs and
//! the seeds run through the same readers and checks in `cargo test`.

use bvh_build::Scene;
use bvh_build::import::{ImportError, ImportOptions, load_bytes};
use bvh_format::BuildParams;
use std::io;
use std::path::Path;

/// A two-triangle OBJ served for every `.obj` a scene description places; its materials are named
/// like the shipped car's, so that `overrides` in the seeds find them.
pub const MESH_OBJ: &str = "mtllib stub.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nvn 0 0 1\n\
usemtl Glass\nf 1//1 2//1 3//1\nusemtl ToyCar\nf 3 2 4\n";

/// The material library of [`MESH_OBJ`].
pub const MESH_MTL: &str =
    "newmtl Glass\nKd 0.3 0.8 0.3\nd 0.5\nNi 1.5\nnewmtl ToyCar\nKd 0.8 0.1 0.1\nKs 0.5 0.5 0.5\nNs 100\n";

/// A two-triangle glTF (its buffer a `data:` URI) served for every `.gltf` and `.glb` a scene
/// description places, materials named as in [`MESH_OBJ`].
pub const MESH_GLTF: &str = r#"{"asset": {"version": "2.0"},
"buffers": [{"byteLength": 60, "uri": "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAACAPwAAgD8AAAAAAAABAAIAAgABAAMA"}],
"bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 48}, {"buffer": 0, "byteOffset": 48, "byteLength": 12}],
"accessors": [
 {"bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
 {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"},
 {"bufferView": 1, "byteOffset": 6, "componentType": 5123, "count": 3, "type": "SCALAR"}],
"materials": [
 {"name": "Glass", "pbrMetallicRoughness": {"baseColorFactor": [0.3, 0.8, 0.3, 1], "roughnessFactor": 0, "metallicFactor": 0},
  "extensions": {"KHR_materials_transmission": {"transmissionFactor": 1}}},
 {"name": "ToyCar", "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.1, 0.1, 1], "metallicFactor": 0.2}}],
"extensionsUsed": ["KHR_materials_transmission"],
"meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "material": 0},
 {"attributes": {"POSITION": 0}, "indices": 2, "material": 1}]}],
"nodes": [{"mesh": 0}], "scenes": [{"nodes": [0]}], "scene": 0}"#;

/// Scenes up to this many triangles are also compiled (cheap); larger ones are only checked.
pub const MAX_COMPILED_TRIANGLES: usize = 1024;

/// Where a fuzz input stops being the OBJ file and starts being its material library (served
/// for every `mtllib` it names).
pub const MTL_SEPARATOR: u8 = 0;

fn refused(path: &Path) -> io::Error {
    io::Error::new(io::ErrorKind::PermissionDenied, format!("the fuzz target reads no files ({})", path.display()))
}

/// Refuses every file: glTF external buffers.
pub fn no_files(path: &Path) -> io::Result<Vec<u8>> {
    Err(refused(path))
}

/// The stub meshes of a scene description, by extension; anything else is refused.
pub fn stub_meshes(path: &Path) -> io::Result<Vec<u8>> {
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    match ext.as_deref() {
        Some("obj") => Ok(MESH_OBJ.as_bytes().to_vec()),
        Some("mtl") => Ok(MESH_MTL.as_bytes().to_vec()),
        Some("gltf" | "glb") => Ok(MESH_GLTF.as_bytes().to_vec()),
        _ => Err(refused(path)),
    }
}

/// Imports an OBJ fuzz input: the bytes before the first [`MTL_SEPARATOR`] are the OBJ file,
/// those after it the material library that any `mtllib` gets (without a separator, every
/// library is refused).
pub fn import_obj(data: &[u8], opts: &ImportOptions) -> Result<Scene, ImportError> {
    let (obj, mtl) = match data.iter().position(|&b| b == MTL_SEPARATOR) {
        Some(at) => (&data[..at], Some(&data[at + 1..])),
        None => (data, None),
    };
    let read = |path: &Path| mtl.map(<[u8]>::to_vec).ok_or_else(|| refused(path));
    load_bytes(Path::new("fuzz.obj"), obj, opts, &read)
}

/// Imports a glTF or GLB fuzz input (the parser tells them apart by the GLB magic), external
/// buffers refused.
pub fn import_gltf(data: &[u8], opts: &ImportOptions) -> Result<Scene, ImportError> {
    load_bytes(Path::new("fuzz.glb"), data, opts, &no_files)
}

/// Imports a scene-description fuzz input, its meshes served by [`stub_meshes`].
pub fn import_description(data: &[u8], opts: &ImportOptions) -> Result<Scene, ImportError> {
    load_bytes(Path::new("fuzz.toml"), data, opts, &stub_meshes)
}

/// The options each input is imported with: flat normals (as given), and for the first byte's
/// low bit set also smooth normals, so that both paths are fuzzed without a second import.
pub fn options(data: &[u8]) -> ImportOptions {
    ImportOptions { smooth_normals: data.first().is_some_and(|b| b & 1 == 1) }
}

/// The checks on an import's outcome. An error must be one sentence (no line break, ending in
/// neither a colon nor a comma). An accepted scene must be what the compiler and the tracers
/// expect: finite positions, unit shading normals, material ids in range, at least one camera
/// and one light, all finite; a small one must then compile into a file that validates, writes
/// and reads back equal. Panics (a fuzz crash) when any check fails.
pub fn check(result: &Result<Scene, ImportError>) {
    let scene = match result {
        Err(e) => {
            let msg = e.to_string();
            assert!(!msg.trim().is_empty() && !msg.contains('\n'), "an error must be one line: {msg:?}");
            assert!(!msg.ends_with(':') && !msg.ends_with(','), "an error must be a whole sentence: {msg:?}");
            return;
        }
        Ok(scene) => scene,
    };
    let n = scene.triangle_count();
    assert!(n > 0, "an accepted scene must have triangles");
    assert_eq!(scene.normals.len(), n, "one normal triple per triangle");
    assert_eq!(scene.material_ids.len(), n, "one material id per triangle");
    assert_eq!(scene.materials.len(), scene.material_names.len(), "one name per material");
    for (t, (p, ns)) in scene.positions.iter().zip(&scene.normals).enumerate() {
        assert!(p.iter().all(|v| v.is_finite()), "triangle {t} has a non-finite position {p:?}");
        for v in ns {
            assert!(v.is_finite() && (v.length() - 1.0).abs() < 1e-3, "triangle {t} has a non-unit normal {v}");
        }
    }
    if let Some(&m) = scene.material_ids.iter().find(|&&m| m as usize >= scene.materials.len()) {
        panic!("material id {m} of {} materials", scene.materials.len());
    }
    for m in &scene.materials {
        let values = [&m.kd[..], &m.ks[..], &[m.shininess, m.kr, m.kt, m.ior]].concat();
        assert!(values.iter().all(|v| v.is_finite()), "material with a non-finite value: {m:?}");
    }
    assert!(!scene.cameras.is_empty() && !scene.lights.is_empty(), "a scene needs a camera and a light");
    for c in &scene.cameras {
        let all = c.eye.iter().chain(&c.at).chain(&c.up).chain(std::iter::once(&c.fov_deg));
        assert!(all.copied().all(f32::is_finite), "camera with a non-finite value: {c:?}");
    }
    for l in &scene.lights {
        assert!(l.position.iter().chain(&l.colour).all(|v| v.is_finite()), "light with a non-finite value: {l:?}");
    }
    assert!(scene.origin.is_finite(), "non-finite origin {}", scene.origin);
    if n <= MAX_COMPILED_TRIANGLES {
        let file = bvh_build::compile(scene, &BuildParams::default(), bvh_build::Layouts::default())
            .unwrap_or_else(|e| panic!("an accepted scene must compile: {e}"));
        let bytes = bvh_format::write(&file).unwrap_or_else(|e| panic!("a compiled scene must write: {e}"));
        let back = bvh_format::read(&bytes).unwrap_or_else(|e| panic!("a written scene must read back: {e}"));
        assert!(back == file, "the compiled scene changed in a write/read round trip");
    }
}
