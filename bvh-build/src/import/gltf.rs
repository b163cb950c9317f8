//! glTF 2.0 (`.gltf` with external or `data:` buffers, and `.glb`), through the gltf crate.
//!
//! The default scene (else the first scene; else every root node) is walked depth first, nodes
//! in the order the scene and each node list them, and each mesh's primitives in order; node
//! transforms (matrix or TRS) are composed down the tree in f64. Triangle lists, strips and fans
//! become triangles; points and lines are skipped. Positions and normals must be float VEC3,
//! indices unsigned byte, short or int; sparse accessors and quantized attributes are reported
//! as unsupported. Textures are never loaded. Perspective camera nodes become named cameras.
//!
//! The accessors are read here rather than through the crate's reader, which trusts the file's
//! types and sizes (and asserts on them); every offset is checked so that no input can panic.

use super::geometry::{self, Affine, EmitError, Normals};
use super::materials::{self, PbrParams};
use super::{DEFAULT_MATERIAL_NAME, ImportError, ImportOptions, ReadFile, guarded, read_file};
use crate::scene::Scene;
use ::gltf::accessor::{DataType, Dimensions};
use ::gltf::mesh::{Mode, Semantic};
use ::gltf::{Accessor, Document, Node, buffer};
use bvh_format::Camera;
use glam::{DMat4, DQuat, DVec3, Mat4, Vec3};
use rayon::prelude::*;
use std::path::Path;

pub fn load(path: &Path, opts: &ImportOptions) -> Result<(Scene, Vec<Camera>), ImportError> {
    load_bytes(path, &read_file(path)?, opts, &bvh_format::read_input)
}

/// [`load`] of `bytes` read from `path` (a `.gltf` or `.glb`); `read` reads the external
/// buffers it refers to.
pub fn load_bytes(
    path: &Path,
    bytes: &[u8],
    opts: &ImportOptions,
    read: ReadFile<'_>,
) -> Result<(Scene, Vec<Camera>), ImportError> {
    let err = |message: String| ImportError::Gltf { path: path.to_owned(), message };
    let parser_failed = || err("the glTF parser failed on this input".to_owned());
    let ::gltf::Gltf { document, blob } = guarded(|| ::gltf::Gltf::from_slice_without_validation(bytes))
        .ok_or_else(parser_failed)?
        .map_err(|e| err(e.to_string()))?;
    guarded(|| validate(&document)).ok_or_else(parser_failed)?.map_err(err)?;
    let base = path.parent().unwrap_or(Path::new(""));
    let buffers = load_buffers(&document, blob, base, read).map_err(err)?;

    let mut reader = Reader {
        path,
        buffers: &buffers,
        smooth: opts.smooth_normals,
        scene: Scene::default(),
        material_ids: vec![None; document.materials().len()],
        default_material: None,
    };
    let mut camera_nodes = Vec::new();
    let mut visited = vec![false; document.nodes().len()];
    let mut stack: Vec<(Node<'_>, DMat4)> = roots(&document).into_iter().rev().map(|n| (n, DMat4::IDENTITY)).collect();
    while let Some((node, parent)) = stack.pop() {
        let seen = visited.get_mut(node.index()).ok_or_else(|| err(format!("node {} does not exist", node.index())))?;
        if std::mem::replace(seen, true) {
            return Err(err(format!("node {} is reached twice in the node hierarchy", node.index())));
        }
        let world = parent * local_transform(&node);
        if !world.is_finite() {
            return Err(ImportError::NonFinite {
                path: path.to_owned(),
                what: format!("the composed transform of node {}", node.index()),
            });
        }
        if let Some(mesh) = node.mesh() {
            reader.mesh(&mesh, &node, &Affine::new(world))?;
        }
        if node.camera().is_some() {
            camera_nodes.push((node.clone(), world));
        }
        let children: Vec<Node<'_>> = node.children().collect();
        stack.extend(children.into_iter().rev().map(|c| (c, world)));
    }
    let scene = reader.scene;
    let centre = scene.bounds().map(|(lo, hi)| ((lo + hi) * 0.5).as_dvec3());
    let cameras = camera_nodes.iter().filter_map(|(node, world)| camera(node, world, centre)).collect();
    Ok((scene, cameras))
}

/// The data of every buffer: the GLB binary chunk, a `data:` URI, or a file beside the glTF file
/// read through `read` (the crate's own loader panics on a percent escape that is not UTF-8 and
/// reads the file system itself).
fn load_buffers(
    document: &Document,
    mut blob: Option<Vec<u8>>,
    base: &Path,
    read: ReadFile<'_>,
) -> Result<Vec<buffer::Data>, String> {
    let mut out = Vec::new();
    for buffer in document.buffers() {
        let i = buffer.index();
        let data = match buffer.source() {
            buffer::Source::Bin => {
                blob.take().ok_or_else(|| format!("buffer {i} refers to a binary chunk that the file does not have"))?
            }
            source @ buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                guarded(|| buffer::Data::from_source(source, None))
                    .ok_or_else(|| format!("the data URI of buffer {i} cannot be decoded"))?
                    .map_err(|e| format!("the data URI of buffer {i} cannot be decoded ({e})"))?
                    .0
            }
            buffer::Source::Uri(uri) => {
                let file = base.join(percent_decode(uri));
                read(&file)
                    .map_err(|e| format!("buffer {i} refers to {}, which cannot be read ({e})", file.display()))?
            }
        };
        if data.len() < buffer.length() {
            return Err(format!(
                "buffer {i} holds {} bytes, fewer than the {} it declares",
                data.len(),
                buffer.length()
            ));
        }
        out.push(buffer::Data(data));
    }
    Ok(out)
}

/// The crate's validation (every reference in range, every enum known), less one rule: the
/// specification requires `min` and `max` on POSITION accessors, which this reader does not use
/// and which some exporters leave out.
fn validate(doc: &Document) -> Result<(), String> {
    use ::gltf::json::validation::{Error, Validate};
    let root = doc.as_json();
    // The crate's validation itself indexes the accessor of each POSITION attribute unchecked.
    for (m, mesh) in root.meshes.iter().enumerate() {
        for (p, prim) in mesh.primitives.iter().enumerate() {
            for (semantic, index) in &prim.attributes {
                if index.value() >= root.accessors.len() {
                    let name = match semantic {
                        ::gltf::json::validation::Checked::Valid(s) => s.to_string(),
                        ::gltf::json::validation::Checked::Invalid => "an unknown attribute".to_owned(),
                    };
                    return Err(format!(
                        "mesh {m} primitive {p}: {name} refers to accessor {}, which does not exist",
                        index.value()
                    ));
                }
            }
        }
    }
    let mut errors = Vec::new();
    root.validate(root, ::gltf::json::Path::new, &mut |path, e| {
        let path = path();
        let bounds = path.as_str().ends_with(".min") || path.as_str().ends_with(".max");
        if !(bounds && matches!(e, Error::Missing)) {
            errors.push(format!("{path}: {e}"));
        }
    });
    match errors.len() {
        0 => Ok(()),
        n if n > 3 => Err(format!("{} (and {} more problems)", errors[..3].join("; "), n - 3)),
        _ => Err(errors.join("; ")),
    }
}

/// The nodes to walk: the default scene's, else the first scene's, else every node that is no
/// other node's child.
fn roots(doc: &Document) -> Vec<Node<'_>> {
    if let Some(scene) = doc.default_scene().or_else(|| doc.scenes().next()) {
        return scene.nodes().collect();
    }
    let mut is_child = vec![false; doc.nodes().len()];
    for n in doc.nodes() {
        for c in n.children() {
            if let Some(f) = is_child.get_mut(c.index()) {
                *f = true;
            }
        }
    }
    doc.nodes().filter(|n| !is_child.get(n.index()).copied().unwrap_or(true)).collect()
}

fn local_transform(node: &Node<'_>) -> DMat4 {
    match node.transform() {
        ::gltf::scene::Transform::Matrix { matrix } => Mat4::from_cols_array_2d(&matrix).as_dmat4(),
        ::gltf::scene::Transform::Decomposed { translation, rotation, scale } => {
            let [x, y, z, w] = rotation.map(f64::from);
            // The specification asks for unit quaternions; exporters round, so normalize.
            let q = DQuat::from_xyzw(x, y, z, w);
            let q = if q.length() > 0.0 { q.normalize() } else { DQuat::from_xyzw(f64::NAN, 0.0, 0.0, 0.0) };
            DMat4::from_scale_rotation_translation(
                DVec3::from(scale.map(f64::from)),
                q,
                DVec3::from(translation.map(f64::from)),
            )
        }
    }
}

/// A perspective camera node as a named camera looking down its local -z with +y up. The
/// look-at point lies as far ahead as the scene's centre, so that tools that measure the
/// distance to it get a sensible scale.
fn camera(node: &Node<'_>, world: &DMat4, centre: Option<DVec3>) -> Option<Camera> {
    let cam = node.camera()?;
    let ::gltf::camera::Projection::Perspective(p) = cam.projection() else { return None };
    let fov = p.yfov().to_degrees();
    let eye = world.transform_point3(DVec3::ZERO);
    let fwd = world.transform_vector3(DVec3::NEG_Z).try_normalize()?;
    let up = world.transform_vector3(DVec3::Y).try_normalize()?;
    let dist = centre.map(|c| c.distance(eye)).filter(|d| *d > 0.0 && d.is_finite()).unwrap_or(1.0);
    let at = eye + fwd * dist;
    let name = node.name().or(cam.name()).map_or_else(|| format!("camera{}", cam.index()), str::to_owned);
    let c = Camera::new(&name, eye.as_vec3().into(), at.as_vec3().into(), up.as_vec3().into(), fov);
    let finite = [c.eye, c.at, c.up].iter().flatten().all(|v| v.is_finite());
    (finite && fov > 0.0 && fov < 180.0 && c.eye != c.at).then_some(c)
}

/// A URI's `%XX` escapes decoded (glTF buffer URIs are URI references; a space is `%20`).
fn percent_decode(uri: &str) -> String {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = bytes
            .get(i + 1..i + 3)
            .and_then(|h| std::str::from_utf8(h).ok())
            .and_then(|h| u8::from_str_radix(h, 16).ok());
        match (bytes[i], hex) {
            (b'%', Some(v)) => {
                out.push(v);
                i += 3;
            }
            (b, _) => {
                out.push(b);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Most elements of an accessor without a buffer view (all zeros).
const MAX_ZERO_ELEMENTS: usize = 1 << 24;

struct Reader<'a> {
    path: &'a Path,
    buffers: &'a [buffer::Data],
    smooth: bool,
    scene: Scene,
    /// Scene material id of each glTF material, assigned on first use.
    material_ids: Vec<Option<u32>>,
    default_material: Option<u32>,
}

impl Reader<'_> {
    fn err(&self, message: String) -> ImportError {
        ImportError::Gltf { path: self.path.to_owned(), message }
    }

    fn mesh(&mut self, mesh: &::gltf::Mesh<'_>, node: &Node<'_>, aff: &Affine) -> Result<(), ImportError> {
        for prim in mesh.primitives() {
            let label = match mesh.name() {
                Some(name) => format!("mesh {} ('{name}') primitive {}", mesh.index(), prim.index()),
                None => format!("mesh {} primitive {}", mesh.index(), prim.index()),
            };
            let mode = prim.mode();
            if !matches!(mode, Mode::Triangles | Mode::TriangleStrip | Mode::TriangleFan) {
                continue;
            }
            let positions_acc =
                prim.get(&Semantic::Positions).ok_or_else(|| self.err(format!("{label} has no POSITION attribute")))?;
            let raw = self.read_vec3(&positions_acc, "POSITION").map_err(|m| self.err(format!("{label}: {m}")))?;
            if let Some(i) = raw.par_iter().position_first(|p| !p.is_finite()) {
                return Err(ImportError::NonFinite {
                    path: self.path.to_owned(),
                    what: format!("vertex {i} of {label}"),
                });
            }
            let positions: Vec<Vec3> = raw.par_iter().map(|&p| aff.point(p)).collect();
            if let Some(i) = positions.par_iter().position_first(|p| !p.is_finite()) {
                return Err(ImportError::NonFinite {
                    path: self.path.to_owned(),
                    what: format!("vertex {i} of {label} after the transform of node {}", node.index()),
                });
            }
            let normals = match prim.get(&Semantic::Normals) {
                Some(acc) => {
                    let n = self.read_vec3(&acc, "NORMAL").map_err(|m| self.err(format!("{label}: {m}")))?;
                    if n.len() != raw.len() {
                        return Err(self.err(format!("{label} has {} normals for {} positions", n.len(), raw.len())));
                    }
                    // A normal the transform collapses becomes zero, which emit replaces by the
                    // triangle's flat normal.
                    Some(n.par_iter().map(|&n| aff.normal(n).unwrap_or(Vec3::ZERO)).collect::<Vec<_>>())
                }
                None => None,
            };
            let indices = match prim.indices() {
                Some(acc) => self.read_indices(&acc).map_err(|m| self.err(format!("{label}: {m}")))?,
                None => (0..raw.len() as u32).collect(),
            };
            let mut triangles = assemble(mode, &indices);
            if aff.flips {
                triangles.par_iter_mut().for_each(|t| t.swap(1, 2));
            }
            let material = self.material(&prim.material());
            let normals = normals.as_deref().map_or(Normals::Missing, Normals::PerVertex);
            let first = self.scene.triangle_count();
            geometry::emit(&mut self.scene, &positions, &triangles, normals, material, self.smooth).map_err(
                |e| match e {
                    EmitError::Index { triangle, value, limit, .. } => ImportError::IndexOutOfRange {
                        path: self.path.to_owned(),
                        what: format!(
                            "triangle {} ({label}) refers to vertex {value}, but the primitive has only {limit}",
                            first + triangle
                        ),
                    },
                    EmitError::NonFinite { vertex } => ImportError::NonFinite {
                        path: self.path.to_owned(),
                        what: format!("vertex {vertex} of {label}"),
                    },
                },
            )?;
        }
        Ok(())
    }

    fn material(&mut self, m: &::gltf::Material<'_>) -> u32 {
        let scene = &mut self.scene;
        let mut add = |name: String, mat| {
            scene.materials.push(mat);
            scene.material_names.push(name);
            scene.materials.len() as u32 - 1
        };
        match m.index() {
            Some(i) => match self.material_ids.get(i).copied().flatten() {
                Some(id) => id,
                None => {
                    let name = m.name().map_or_else(|| format!("material{i}"), str::to_owned);
                    let id = add(name, materials::from_gltf(&PbrParams::of(m)));
                    if let Some(slot) = self.material_ids.get_mut(i) {
                        *slot = Some(id);
                    }
                    id
                }
            },
            None => *self
                .default_material
                .get_or_insert_with(|| add(DEFAULT_MATERIAL_NAME.to_owned(), super::default_material())),
        }
    }

    /// The bytes of an accessor's elements and their stride, every range checked; `None` for an
    /// accessor without a buffer view (all zeros, by the specification).
    fn accessor_bytes(&self, acc: &Accessor<'_>, elem: usize) -> Result<Option<(&[u8], usize)>, String> {
        let i = acc.index();
        if acc.sparse().is_some() {
            return Err(format!("accessor {i} is sparse, which is not supported"));
        }
        let Some(view) = acc.view() else {
            // Nothing bounds the count of an accessor without data but the JSON, so a typo could
            // ask for terabytes of zeros.
            if acc.count() > MAX_ZERO_ELEMENTS {
                return Err(format!("accessor {i} has no data but {} elements", acc.count()));
            }
            return Ok(None);
        };
        let stride = view.stride().unwrap_or(elem);
        if stride < elem {
            return Err(format!("accessor {i} has a byte stride of {stride}, less than its element size {elem}"));
        }
        let data: &[u8] = self
            .buffers
            .get(view.buffer().index())
            .ok_or_else(|| format!("buffer {} does not exist", view.buffer().index()))?;
        let view_bytes = view
            .offset()
            .checked_add(view.length())
            .and_then(|end| data.get(view.offset()..end))
            .ok_or_else(|| format!("buffer view {} lies outside its buffer", view.index()))?;
        if acc.count() == 0 {
            return Ok(Some((&[], stride)));
        }
        let end = (acc.count() - 1)
            .checked_mul(stride)
            .and_then(|n| n.checked_add(elem))
            .and_then(|n| n.checked_add(acc.offset()));
        let bytes = end
            .and_then(|end| view_bytes.get(acc.offset()..end))
            .ok_or_else(|| format!("accessor {i} reaches past the end of buffer view {}", view.index()))?;
        Ok(Some((bytes, stride)))
    }

    fn read_vec3(&self, acc: &Accessor<'_>, what: &str) -> Result<Vec<Vec3>, String> {
        if acc.dimensions() != Dimensions::Vec3 || acc.data_type() != DataType::F32 {
            return Err(format!(
                "accessor {} for {what} holds {:?} {:?} values, but only float VEC3 is supported",
                acc.index(),
                acc.data_type(),
                acc.dimensions()
            ));
        }
        let Some((bytes, stride)) = self.accessor_bytes(acc, 12)? else {
            return Ok(vec![Vec3::ZERO; acc.count()]);
        };
        let f = |b: &[u8], k: usize| {
            b.get(4 * k..4 * k + 4).and_then(|s| s.try_into().ok()).map_or(f32::NAN, f32::from_le_bytes)
        };
        Ok((0..acc.count())
            .into_par_iter()
            .map(|e| {
                let b = bytes.get(e * stride..).unwrap_or(&[]);
                Vec3::new(f(b, 0), f(b, 1), f(b, 2))
            })
            .collect())
    }

    fn read_indices(&self, acc: &Accessor<'_>) -> Result<Vec<u32>, String> {
        let size = match acc.data_type() {
            DataType::U8 => 1,
            DataType::U16 => 2,
            DataType::U32 => 4,
            t => return Err(format!("index accessor {} holds {t:?} values", acc.index())),
        };
        if acc.dimensions() != Dimensions::Scalar {
            return Err(format!("index accessor {} is not SCALAR", acc.index()));
        }
        let Some((bytes, stride)) = self.accessor_bytes(acc, size)? else {
            return Ok(vec![0; acc.count()]);
        };
        Ok((0..acc.count())
            .into_par_iter()
            .map(|e| {
                let b = bytes.get(e * stride..).unwrap_or(&[]);
                match size {
                    1 => b.first().map_or(u32::MAX, |&v| u32::from(v)),
                    2 => b
                        .get(..2)
                        .and_then(|s| s.try_into().ok())
                        .map_or(u32::MAX, |s| u32::from(u16::from_le_bytes(s))),
                    _ => b.get(..4).and_then(|s| s.try_into().ok()).map_or(u32::MAX, u32::from_le_bytes),
                }
            })
            .collect())
    }
}

/// Triangles of a primitive's vertex sequence, in the order the glTF specification numbers them
/// (a trailing incomplete triangle of a list is dropped).
fn assemble(mode: Mode, v: &[u32]) -> Vec<[u32; 3]> {
    let n = v.len();
    match mode {
        Mode::Triangles => v.par_chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        Mode::TriangleStrip => (0..n.saturating_sub(2))
            .map(|i| if i % 2 == 0 { [v[i], v[i + 1], v[i + 2]] } else { [v[i], v[i + 2], v[i + 1]] })
            .collect(),
        Mode::TriangleFan => (0..n.saturating_sub(2)).map(|i| [v[i + 1], v[i + 2], v[0]]).collect(),
        _ => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strips_and_fans_keep_their_winding() {
        let v = [0, 1, 2, 3, 4];
        assert_eq!(assemble(Mode::TriangleStrip, &v), vec![[0, 1, 2], [1, 3, 2], [2, 3, 4]]);
        assert_eq!(assemble(Mode::TriangleFan, &v), vec![[1, 2, 0], [2, 3, 0], [3, 4, 0]]);
        assert_eq!(assemble(Mode::Triangles, &v), vec![[0, 1, 2]]);
        assert!(assemble(Mode::TriangleStrip, &v[..2]).is_empty());
    }
}
