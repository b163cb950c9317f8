//! Wavefront OBJ with MTL materials, through tobj.
//!
//! Triangle order: models (tobj splits at `o`, `g` and material changes) in file order, faces in
//! file order, a polygon of `k` corners as `k - 2` fan triangles. Points and lines are skipped.
//! A missing or malformed material library is an error; a `usemtl` naming no known material
//! gives the default material.

use super::geometry::{self, EmitError, Normals};
use super::{DEFAULT_MATERIAL_NAME, ImportError, ImportOptions, ReadFile, guarded, materials, read_file};
use crate::scene::Scene;
use glam::Vec3;
use std::cell::RefCell;
use std::io::Cursor;
use std::path::Path;

pub fn load(path: &Path, opts: &ImportOptions) -> Result<Scene, ImportError> {
    load_bytes(path, &read_file(path)?, opts, &bvh_format::read_input)
}

/// [`load`] of `bytes` read from `path`; `read` reads the material libraries it names.
pub fn load_bytes(path: &Path, bytes: &[u8], opts: &ImportOptions, read: ReadFile<'_>) -> Result<Scene, ImportError> {
    let err = |message: String| ImportError::Obj { path: path.to_owned(), message };
    let short_faces = check_lines(path, bytes)?;

    let dir = path.parent().unwrap_or(Path::new(""));
    // tobj's loader callback cannot return our error, so the reason is kept aside.
    let mtl_error: RefCell<Option<String>> = RefCell::new(None);
    // tobj's "merging" and "reordering" features add fields; another crate enabling them must
    // not break this build.
    #[allow(clippy::needless_update)]
    let load_opts = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
        ..Default::default()
    };
    let parsed = guarded(|| {
        tobj::load_obj_buf(&mut Cursor::new(bytes), &load_opts, |mtl_path| {
            let full = dir.join(mtl_path);
            let fail = |msg: String| {
                mtl_error.borrow_mut().get_or_insert(msg);
                tobj::LoadError::MaterialParseError
            };
            match read(&full) {
                Ok(text) => match normalize_mtl(&text) {
                    Ok(text) => tobj::load_mtl_buf(&mut Cursor::new(text))
                        .map_err(|e| fail(format!("its material library {} is malformed ({e})", full.display()))),
                    Err(line) => {
                        Err(fail(format!("its material library {} is malformed at line {line}", full.display())))
                    }
                },
                Err(e) => Err(fail(format!("its material library {} cannot be read ({e})", full.display()))),
            }
        })
    })
    .ok_or_else(|| err("the OBJ parser failed on this input".to_owned()))?;
    let (models, mtl_result) = parsed.map_err(|e| err(e.to_string()))?;
    if let Some(msg) = mtl_error.into_inner() {
        return Err(err(msg));
    }
    // With the callback above, tobj only reports a material error that the callback recorded,
    // or "no material library at all", which is fine.
    let mtls = mtl_result.unwrap_or_default();

    let mut scene = Scene {
        warnings: if short_faces > 0 {
            vec![format!(
                "{}: {short_faces} face{} with fewer than three corners skipped",
                path.display(),
                if short_faces == 1 { "" } else { "s" }
            )]
        } else {
            Vec::new()
        },
        materials: mtls.iter().map(materials::from_mtl).collect(),
        material_names: mtls.iter().map(|m| m.name.clone()).collect(),
        ..Scene::default()
    };
    let mut default_id = None;
    for model in &models {
        let mesh = &model.mesh;
        let material = match mesh.material_id.filter(|&id| id < mtls.len()) {
            Some(id) => id as u32,
            None => *default_id.get_or_insert_with(|| {
                scene.materials.push(super::default_material());
                scene.material_names.push(DEFAULT_MATERIAL_NAME.to_owned());
                scene.materials.len() as u32 - 1
            }),
        };
        let positions: Vec<Vec3> = mesh.positions.chunks_exact(3).map(Vec3::from_slice).collect();
        let triangles = triples(&mesh.indices);
        let normal_values: Vec<Vec3> = mesh.normals.chunks_exact(3).map(Vec3::from_slice).collect();
        let normal_tris = triples(&mesh.normal_indices);
        let normals = if normal_values.is_empty() || normal_tris.len() != triangles.len() {
            Normals::Missing
        } else {
            Normals::Indexed(&normal_values, &normal_tris)
        };
        let first = scene.triangle_count();
        geometry::emit(&mut scene, &positions, &triangles, normals, material, opts.smooth_normals).map_err(|e| {
            let name = &model.name;
            match e {
                EmitError::Index { triangle, value, limit, normal } => ImportError::IndexOutOfRange {
                    path: path.to_owned(),
                    what: format!(
                        "triangle {} (object '{name}') refers to {} {value}, but there are only {limit}",
                        first + triangle,
                        if normal { "normal" } else { "vertex" },
                    ),
                },
                EmitError::NonFinite { vertex } => ImportError::NonFinite {
                    path: path.to_owned(),
                    what: format!("vertex {vertex} of object '{name}'"),
                },
            }
        })?;
    }
    Ok(scene)
}

fn triples(v: &[u32]) -> Vec<[u32; 3]> {
    v.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect()
}

/// Checks, with line numbers, what tobj would reject without saying where or accept silently:
/// a `v` line needs three numbers, all finite (tobj takes "nan" and "inf"); each corner of an `f`
/// line must name a vertex defined before it (1-based, or negative counting back). Returns how
/// many faces have fewer than three corners: tobj drops them.
fn check_lines(path: &Path, bytes: &[u8]) -> Result<usize, ImportError> {
    let err = |line: usize, message: String| ImportError::Obj {
        path: path.to_owned(),
        message: format!("line {line}: {message}"),
    };
    let mut vertices = 0i64;
    let mut short_faces = 0;
    for (i, line) in bytes.split(|&b| b == b'\n').enumerate() {
        let Ok(line) = std::str::from_utf8(line) else { continue };
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                vertices += 1;
                // Only x, y, z: a fourth value (w) or vertex colours do not place the vertex.
                let xyz: Vec<&str> = words.take(3).collect();
                if xyz.len() < 3 {
                    return Err(err(i + 1, format!("vertex {vertices} has {} coordinates instead of 3", xyz.len())));
                }
                for w in xyz {
                    match w.parse::<f32>() {
                        Ok(x) if x.is_finite() => {}
                        Ok(_) => {
                            return Err(ImportError::NonFinite {
                                path: path.to_owned(),
                                what: format!("vertex {vertices} (line {}, {w:?})", i + 1),
                            });
                        }
                        Err(_) => {
                            return Err(err(i + 1, format!("vertex {vertices} has {w:?}, which is not a number")));
                        }
                    }
                }
            }
            Some("f") => {
                let corners: Vec<&str> = words.collect();
                for c in &corners {
                    let first = c.split('/').next().unwrap_or("");
                    let index = first
                        .parse::<i64>()
                        .map_err(|_| err(i + 1, format!("face corner {c:?} does not start with a vertex number")))?;
                    let resolved = if index < 0 { vertices + 1 + index } else { index };
                    if index == 0 || resolved < 1 || resolved > vertices {
                        return Err(err(
                            i + 1,
                            format!("a face refers to vertex {index}, but {vertices} vertices are defined before it"),
                        ));
                    }
                }
                if corners.len() < 3 {
                    short_faces += 1;
                }
            }
            _ => {}
        }
    }
    Ok(short_faces)
}

/// Makes an MTL file safe for tobj, which panics on a colour with fewer than three values: a
/// single value is widened to grey (as the MTL specification allows), anything else short is
/// reported by its line number.
fn normalize_mtl(text: &[u8]) -> Result<Vec<u8>, usize> {
    let text = String::from_utf8_lossy(text);
    let mut out = String::with_capacity(text.len() + 64);
    for (i, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        let key = words.next();
        if matches!(key, Some("Ka" | "Kd" | "Ks" | "Ke")) {
            let values: Vec<&str> = words.collect();
            match values.len() {
                1 => {
                    let v = values[0];
                    out.push_str(&format!("{} {v} {v} {v}\n", key.unwrap_or_default()));
                    continue;
                }
                n if n < 3 => return Err(i + 1),
                _ => {}
            }
        }
        out.push_str(line);
        out.push('\n');
    }
    Ok(out.into_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn obj_lines_are_checked_with_their_numbers() {
        let p = Path::new("t.obj");
        let msg = |text: &str| check_lines(p, text.as_bytes()).unwrap_err().to_string();
        assert_eq!(check_lines(p, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\nf 1 2 3\nf -3/1 -2//1 -1\n").unwrap(), 1);
        assert!(msg("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 x 3\n").contains("line 4: face corner \"x\""));
        assert!(msg("v 0 0 0\nf 1 2 3\n").contains("line 2: a face refers to vertex 2, but 1 vertices"));
        assert!(msg("v 0 0\n").contains("line 1: vertex 1 has 2 coordinates"));
        assert!(msg("v 0 0 0\nv 0 nan 0\n").contains("vertex 2 (line 2"));
        assert!(msg("v 0 0 0\nv 0 y 0\n").contains("line 2: vertex 2 has \"y\""));
    }

    #[test]
    fn short_mtl_colours_are_widened_or_rejected() {
        let t = normalize_mtl(b"newmtl a\nKd 0.5\nKs 1 1 1\n").unwrap();
        assert_eq!(String::from_utf8(t).unwrap(), "newmtl a\nKd 0.5 0.5 0.5\nKs 1 1 1\n");
        assert_eq!(normalize_mtl(b"newmtl a\nKd 0.5 0.2\n"), Err(2));
    }
}
