//! Scene descriptions (TOML): meshes placed with transforms, generated shapes, named materials
//! and material overrides, cameras, lights and settings. The format is documented, with an
//! example, in `docs/scene-description.md`.
//!
//! Triangle order: the `[[object]]` entries in file order, each contributing its triangles in
//! its own order (the mesh file's order, or the shape's order documented in [`super::shapes`]).

use super::geometry::{self, Affine};
use super::{DEFAULT_MATERIAL_NAME, ImportError, ImportOptions, Kind, ReadFile, defaults, load_mesh_file, shapes};
use crate::scene::Scene;
use bvh_format::{CAMERA_NAME_LEN, Camera, Light, Material, SceneSettings};
use glam::{DMat4, DQuat, DVec3, Vec3};
use rayon::prelude::*;
use serde::Deserialize;
use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Description {
    ambient: Option<[f32; 3]>,
    background: Option<[f32; 3]>,
    /// The file's `max_indirections`.
    indirections: Option<u32>,
    /// Default for every mesh that has no normals and no `smooth_normals` of its own.
    smooth_normals: Option<bool>,
    #[serde(default)]
    material: BTreeMap<String, MaterialDesc>,
    /// Read as tables first and each turned into an [`Object`] on its own: serde reads a tagged
    /// enum through a buffer that forgets positions, so an error could not say which object.
    #[serde(default)]
    object: Vec<toml::Spanned<toml::Table>>,
    #[serde(default)]
    camera: Vec<CameraDesc>,
    #[serde(default)]
    light: Vec<LightDesc>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MaterialDesc {
    kd: Option<[f32; 3]>,
    ks: Option<[f32; 3]>,
    shininess: Option<f32>,
    kr: Option<f32>,
    kt: Option<f32>,
    ior: Option<f32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraDesc {
    name: String,
    /// World coordinates, read in f64 so that a camera far from the origin keeps its place
    /// relative to the scene when both are moved to the scene's local origin.
    eye: [f64; 3],
    at: [f64; 3],
    up: Option<[f32; 3]>,
    fov: Option<f32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct LightDesc {
    position: [f64; 3],
    #[serde(alias = "color")]
    colour: Option<[f32; 3]>,
}

#[derive(Clone, Copy, Debug, Deserialize)]
#[serde(untagged)]
enum Scale {
    Uniform(f32),
    PerAxis([f32; 3]),
}

/// The placement every object accepts: scale, then rotate (`rotate` about x, y, z in that
/// order, then `axis`/`angle`), then translate.
#[derive(Clone, Copy, Debug, Default)]
struct Placement {
    translate: Option<[f64; 3]>,
    rotate: Option<[f32; 3]>,
    axis: Option<[f32; 3]>,
    angle: Option<f32>,
    scale: Option<Scale>,
}

/// Declares an object kind with the fields every kind shares (placement, material, framing);
/// serde cannot flatten them in while still denying unknown fields.
macro_rules! object_kind {
    ($(#[$doc:meta])* $name:ident { $($(#[$fa:meta])* $field:ident : $ty:ty,)* }) => {
        $(#[$doc])*
        #[derive(Debug, Deserialize)]
        #[serde(deny_unknown_fields)]
        struct $name {
            $($(#[$fa])* $field: $ty,)*
            translate: Option<[f64; 3]>,
            rotate: Option<[f32; 3]>,
            axis: Option<[f32; 3]>,
            angle: Option<f32>,
            scale: Option<Scale>,
            /// A description material for all triangles.
            material: Option<String>,
            /// Whether the default cameras and light frame this object (default true).
            frame: Option<bool>,
        }

        impl Common for $name {
            fn placement(&self) -> Placement {
                Placement {
                    translate: self.translate,
                    rotate: self.rotate,
                    axis: self.axis,
                    angle: self.angle,
                    scale: self.scale,
                }
            }
            fn material(&self) -> Option<&str> {
                self.material.as_deref()
            }
            fn frame(&self) -> bool {
                self.frame.unwrap_or(true)
            }
        }
    };
}

trait Common {
    fn placement(&self) -> Placement;
    fn material(&self) -> Option<&str>;
    fn frame(&self) -> bool;
}

object_kind!(MeshObj {
    file: PathBuf,
    /// Mesh material name -> description material name.
    #[serde(default)]
    overrides: BTreeMap<String, String>,
    smooth_normals: Option<bool>,
});
object_kind!(QuadObj {
    #[serde(alias = "center")]
    centre: Option<[f32; 3]>,
    size: [f32; 2],
    normal: Option<[f32; 3]>,
});
object_kind!(BoxObj {
    #[serde(alias = "center")]
    centre: Option<[f32; 3]>,
    size: [f32; 3],
});
object_kind!(SphereObj {
    #[serde(alias = "center")]
    centre: Option<[f32; 3]>,
    radius: f32,
    segments: Option<u32>,
    rings: Option<u32>,
});
object_kind!(TorusObj {
    #[serde(alias = "center")]
    centre: Option<[f32; 3]>,
    major: f32,
    minor: f32,
    segments: Option<u32>,
    sides: Option<u32>,
});

#[derive(Debug, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase")]
enum Object {
    Mesh(MeshObj),
    Quad(QuadObj),
    Box(BoxObj),
    Sphere(SphereObj),
    Torus(TorusObj),
}

impl Object {
    fn common(&self) -> &dyn Common {
        match self {
            Object::Mesh(o) => o,
            Object::Quad(o) => o,
            Object::Box(o) => o,
            Object::Sphere(o) => o,
            Object::Torus(o) => o,
        }
    }

    fn label(&self, k: usize) -> String {
        let kind = match self {
            Object::Mesh(m) => format!("mesh {}", m.file.display()),
            Object::Quad(_) => "quad".to_owned(),
            Object::Box(_) => "box".to_owned(),
            Object::Sphere(_) => "sphere".to_owned(),
            Object::Torus(_) => "torus".to_owned(),
        };
        format!("object {} ({kind})", k + 1)
    }
}

/// Default segment counts of the generated shapes.
pub const SPHERE_SEGMENTS: u32 = 32;
pub const SPHERE_RINGS: u32 = 16;
pub const TORUS_SEGMENTS: u32 = 48;
pub const TORUS_SIDES: u32 = 16;
/// Most triangles the generated shapes of one description may have together, so that a typo
/// (or a few dozen bytes of hostile input) cannot exhaust memory or take minutes.
pub const MAX_SHAPE_TRIANGLES: u64 = 1 << 22;

/// Reads a scene description and everything it references.
pub fn load(path: &Path, opts: &ImportOptions) -> Result<Scene, ImportError> {
    load_bytes(path, &super::read_file(path)?, opts, &bvh_format::read_input)
}

/// [`load`] of `bytes` read from `path`; `read` reads the mesh files it places.
pub fn load_bytes(path: &Path, bytes: &[u8], opts: &ImportOptions, read: ReadFile<'_>) -> Result<Scene, ImportError> {
    let text = std::str::from_utf8(bytes)
        .map_err(|_| ImportError::Description { path: path.to_owned(), message: "it is not UTF-8 text".to_owned() })?;
    let desc: Description = toml::from_str(text)
        .map_err(|e| ImportError::Description { path: path.to_owned(), message: toml_message(text, &e) })?;
    let objects = desc
        .object
        .iter()
        .enumerate()
        .map(|(k, table)| {
            toml::Value::Table(table.get_ref().clone()).try_into::<Object>().map_err(|e| {
                let message = object_message(text, k, table.span().start, &e);
                ImportError::Description { path: path.to_owned(), message }
            })
        })
        .collect::<Result<Vec<Object>, _>>()?;
    Builder::new(path, opts, read, &desc)?.build(&desc, &objects)
}

/// An error in object `k` (whose `[[object]]` header starts at `header`) as one line: the line
/// of the key it is about, when it names one, else the header's.
fn object_message(text: &str, k: usize, header: usize, e: &toml::de::Error) -> String {
    let msg = e.message().trim().replace('\n', " ");
    let at = key_in_object(text, k, &msg).unwrap_or(header);
    let line = text.get(..at).unwrap_or(text).matches('\n').count() + 1;
    format!("line {line}, object {}: {msg}", k + 1)
}

/// Where the key that a serde message names ("unknown field `x`", "invalid type ... for key `x`")
/// stands in object `k` of the parsed document.
fn key_in_object(text: &str, k: usize, msg: &str) -> Option<usize> {
    use toml::de::{DeTable, DeValue};
    let key = msg.split('`').nth(1)?;
    let doc = DeTable::parse(text).ok()?;
    let objects = doc.get_ref().iter().find(|(name, _)| name.get_ref() == "object")?.1;
    let DeValue::Array(items) = objects.get_ref() else { return None };
    let DeValue::Table(table) = items.get(k)?.get_ref() else { return None };
    table.iter().find(|(name, _)| name.get_ref() == key).map(|(name, _)| name.span().start)
}

/// A TOML error as one line: position and the parser's message.
fn toml_message(text: &str, e: &toml::de::Error) -> String {
    let msg = e.message().trim().replace('\n', " ");
    match e.span() {
        Some(span) => {
            let before = text.get(..span.start).unwrap_or(text);
            let line = before.matches('\n').count() + 1;
            let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
            format!("line {line}, column {column}: {msg}")
        }
        None => msg,
    }
}

struct Builder<'a> {
    path: &'a Path,
    dir: PathBuf,
    read: ReadFile<'a>,
    opts: ImportOptions,
    scene: Scene,
    /// Description materials, validated, by name.
    defined: BTreeMap<String, Material>,
    /// Scene id of each (name, material) pair already added, so that shared materials appear
    /// once.
    interned: HashMap<(String, [u32; 10]), u32>,
    /// Mesh files already read, with the smooth-normals choice they were read with.
    meshes: HashMap<(PathBuf, bool), Scene>,
    /// Each object's triangles (still in the object's own coordinates) with its placement and
    /// whether the default cameras frame it; placed in [`Builder::place`] once the scene's local
    /// origin is known.
    placed: Vec<Placed>,
    /// World bounds of all objects, in f64.
    world: Option<(DVec3, DVec3)>,
    /// Triangles of the generated shapes so far, against [`MAX_SHAPE_TRIANGLES`].
    generated: u64,
}

struct Placed {
    triangles: std::ops::Range<usize>,
    aff: Affine,
    frame: bool,
    label: String,
}

fn material_key(m: &Material) -> [u32; 10] {
    let v = [m.kd[0], m.kd[1], m.kd[2], m.shininess, m.ks[0], m.ks[1], m.ks[2], m.kr, m.kt, m.ior];
    v.map(f32::to_bits)
}

fn finite(v: &[f32]) -> bool {
    v.iter().all(|x| x.is_finite())
}

impl<'a> Builder<'a> {
    fn new(path: &'a Path, opts: &ImportOptions, read: ReadFile<'a>, desc: &Description) -> Result<Self, ImportError> {
        let mut b = Builder {
            path,
            dir: path.parent().unwrap_or(Path::new("")).to_owned(),
            read,
            opts: ImportOptions { smooth_normals: desc.smooth_normals.unwrap_or(opts.smooth_normals) },
            scene: Scene::default(),
            defined: BTreeMap::new(),
            interned: HashMap::new(),
            meshes: HashMap::new(),
            placed: Vec::new(),
            world: None,
            generated: 0,
        };
        for (name, m) in &desc.material {
            let mat = material(m).map_err(|msg| b.err(format!("material '{name}': {msg}")))?;
            b.defined.insert(name.clone(), mat);
        }
        Ok(b)
    }

    fn err(&self, message: String) -> ImportError {
        ImportError::Description { path: self.path.to_owned(), message }
    }

    fn intern(&mut self, name: &str, m: Material) -> u32 {
        let scene = &mut self.scene;
        *self.interned.entry((name.to_owned(), material_key(&m))).or_insert_with(|| {
            scene.materials.push(m);
            scene.material_names.push(name.to_owned());
            scene.materials.len() as u32 - 1
        })
    }

    /// The scene id of description material `name`.
    fn defined(&mut self, name: &str, label: &str) -> Result<u32, ImportError> {
        match self.defined.get(name) {
            Some(&m) => Ok(self.intern(name, m)),
            None => {
                let known: Vec<&str> = self.defined.keys().map(String::as_str).collect();
                Err(self.err(format!(
                    "{label} uses material '{name}', which is not defined (defined: {})",
                    if known.is_empty() { "none".to_owned() } else { known.join(", ") }
                )))
            }
        }
    }

    fn build(mut self, desc: &Description, objects: &[Object]) -> Result<Scene, ImportError> {
        for (k, obj) in objects.iter().enumerate() {
            self.object(k, obj)?;
        }
        let Some((wlo, whi)) = self.world else {
            return Err(ImportError::Empty { path: self.path.to_owned() });
        };
        let origin = geometry::local_origin(wlo, whi);
        let framed = self.place(origin)?;
        let Some((lo, hi)) = self.scene.bounds() else {
            return Err(ImportError::Empty { path: self.path.to_owned() });
        };
        let (flo, fhi) = framed.unwrap_or((lo, hi));
        let local = |p: [f64; 3]| (DVec3::from(p) - origin).as_vec3().to_array();

        let mut names = Vec::new();
        for c in &desc.camera {
            let cam = camera(c, origin).map_err(|m| self.err(format!("camera '{}': {m}", c.name)))?;
            if names.contains(&c.name) {
                return Err(self.err(format!("camera '{}' is defined twice", c.name)));
            }
            names.push(c.name.clone());
            self.scene.cameras.push(cam);
        }
        if self.scene.cameras.is_empty() {
            self.scene.cameras = defaults::cameras(flo, fhi);
        }
        for (k, l) in desc.light.iter().enumerate() {
            let colour = l.colour.unwrap_or([1.0; 3]);
            let position = local(l.position);
            if !finite(&position) || !finite(&colour) || colour.iter().any(|&c| c < 0.0) {
                return Err(
                    self.err(format!("light {} needs a finite position and a finite, non-negative colour", k + 1))
                );
            }
            self.scene.lights.push(Light::new(position, colour));
        }
        if self.scene.lights.is_empty() {
            self.scene.lights = vec![defaults::light_for(&self.scene.cameras[0], flo, fhi)];
        }
        if desc.camera.is_empty() || desc.light.is_empty() {
            defaults::check_finite(&self.scene.cameras, &self.scene.lights, flo, fhi)
                .map_err(|message| ImportError::Defaults { path: self.path.to_owned(), message })?;
        }

        let d = SceneSettings::default();
        let colour = |c: Option<[f32; 3]>, fallback: [f32; 3], what: &str| match c {
            Some(c) if !finite(&c) || c.iter().any(|&v| v < 0.0) => {
                Err(self.err(format!("the {what} colour must be finite and non-negative")))
            }
            c => Ok(c.unwrap_or(fallback)),
        };
        let settings = SceneSettings {
            ambient: colour(desc.ambient, d.ambient, "ambient")?,
            background: colour(desc.background, d.background, "background")?,
            max_indirections: desc.indirections.unwrap_or(d.max_indirections),
        };
        self.scene.settings = settings;
        self.scene.origin = origin;
        Ok(self.scene)
    }

    /// Places every object's triangles relative to the scene's local `origin` (world positions
    /// computed in f64, rounded to f32 once) and returns the bounds of the framed objects.
    fn place(&mut self, origin: DVec3) -> Result<Option<(Vec3, Vec3)>, ImportError> {
        let mut framed: Option<(Vec3, Vec3)> = None;
        for p in &self.placed {
            let positions = &mut self.scene.positions[p.triangles.clone()];
            let normals = &mut self.scene.normals[p.triangles.clone()];
            if let Err(t) = geometry::transform_triangles(positions, normals, &p.aff, origin) {
                return Err(ImportError::NonFinite {
                    path: self.path.to_owned(),
                    what: format!("triangle {} ({}) after its placement transform", p.triangles.start + t, p.label),
                });
            }
            if p.frame
                && let Some(b) = geometry::bounds(&self.scene.positions[p.triangles.clone()])
            {
                framed = Some(framed.map_or(b, |(lo, hi)| (lo.min(b.0), hi.max(b.1))));
            }
        }
        Ok(framed)
    }

    fn object(&mut self, k: usize, obj: &Object) -> Result<(), ImportError> {
        let label = obj.label(k);
        let common = obj.common();
        let aff = Affine::new(placement_matrix(&common.placement()).map_err(|m| self.err(format!("{label}: {m}")))?);
        let replace_all = match common.material() {
            Some(name) => Some(self.defined(name, &label)?),
            None => None,
        };
        let first = self.scene.triangle_count();
        match obj {
            Object::Mesh(m) => self.mesh(m, &label, replace_all)?,
            shape => {
                let mesh = self.shape(shape).map_err(|m| self.err(format!("{label}: {m}")))?;
                let id = match replace_all {
                    Some(id) => id,
                    None => self.intern(DEFAULT_MATERIAL_NAME, super::default_material()),
                };
                let n = mesh.triangle_count();
                self.generated += n as u64;
                self.scene.positions.extend(mesh.positions);
                self.scene.normals.extend(mesh.normals);
                self.scene.material_ids.extend(std::iter::repeat_n(id, n));
            }
        }
        let range = first..self.scene.triangle_count();
        // World bounds in f64, before anything is rounded: they choose the local origin.
        match geometry::world_bounds(&self.scene.positions[range.clone()], &aff) {
            Some((lo, hi)) => {
                if !range.is_empty() {
                    self.world = Some(self.world.map_or((lo, hi), |(a, b)| (a.min(lo), b.max(hi))));
                }
            }
            None => {
                return Err(ImportError::NonFinite {
                    path: self.path.to_owned(),
                    what: format!("a triangle of {label} after its placement transform"),
                });
            }
        }
        self.placed.push(Placed { triangles: range, aff, frame: common.frame(), label });
        Ok(())
    }

    fn mesh(&mut self, m: &MeshObj, label: &str, replace_all: Option<u32>) -> Result<(), ImportError> {
        let file = self.dir.join(&m.file);
        let kind = Kind::of(&file)?;
        if kind == Kind::Description {
            return Err(self.err(format!("{label}: a description cannot include another description")));
        }
        let smooth = m.smooth_normals.unwrap_or(self.opts.smooth_normals);
        let key = (file.clone(), smooth);
        if !self.meshes.contains_key(&key) {
            let bytes = (self.read)(&file).map_err(|source| ImportError::MissingMesh {
                path: self.path.to_owned(),
                mesh: file.clone(),
                source,
            })?;
            let opts = ImportOptions { smooth_normals: smooth };
            let (part, _cameras) = load_mesh_file(&file, &bytes, kind, &opts, self.read)?;
            self.scene.warnings.extend(part.warnings.iter().cloned());
            self.meshes.insert(key.clone(), part);
        }
        // Taken out while its triangles are copied, so that materials can be added meanwhile.
        let part = self.meshes.remove(&key).unwrap_or_default();
        let result = self.copy_mesh(m, label, replace_all, &part);
        self.meshes.insert(key, part);
        result
    }

    fn copy_mesh(
        &mut self,
        m: &MeshObj,
        label: &str,
        replace_all: Option<u32>,
        part: &Scene,
    ) -> Result<(), ImportError> {
        for name in m.overrides.keys() {
            if !part.material_names.contains(name) {
                return Err(self.err(format!(
                    "{label} has no material named '{name}' to override (its materials: {})",
                    part.material_names.join(", ")
                )));
            }
        }
        let mut ids: Vec<Option<u32>> = vec![None; part.materials.len()];
        let mut out_ids = Vec::with_capacity(part.material_ids.len());
        for &mid in &part.material_ids {
            let i = mid as usize;
            let id = match ids.get(i).copied().flatten() {
                Some(id) => id,
                None => {
                    let name = part.material_names.get(i).map_or(DEFAULT_MATERIAL_NAME, String::as_str);
                    let mat = part.materials.get(i).copied().unwrap_or_else(super::default_material);
                    let id = match (m.overrides.get(name), replace_all) {
                        (Some(over), _) => self.defined(over, label)?,
                        (None, Some(all)) => all,
                        (None, None) => self.intern(name, mat),
                    };
                    if let Some(slot) = ids.get_mut(i) {
                        *slot = Some(id);
                    }
                    id
                }
            };
            out_ids.push(id);
        }
        self.scene.positions.par_extend(part.positions.par_iter().copied());
        self.scene.normals.par_extend(part.normals.par_iter().copied());
        self.scene.material_ids.extend(out_ids);
        Ok(())
    }

    fn shape(&self, obj: &Object) -> Result<shapes::Mesh, String> {
        let centre = |c: Option<[f32; 3]>| -> Result<Vec3, String> {
            let c = c.unwrap_or([0.0; 3]);
            if finite(&c) { Ok(Vec3::from(c)) } else { Err("the centre must be finite".to_owned()) }
        };
        let positive = |v: &[f32], what: &str| -> Result<(), String> {
            if v.iter().all(|x| x.is_finite() && *x > 0.0) {
                Ok(())
            } else {
                Err(format!("the {what} must be positive and finite"))
            }
        };
        let count = |v: Option<u32>, default: u32, min: u32, what: &str| -> Result<u32, String> {
            let v = v.unwrap_or(default);
            if v < min { Err(format!("{what} must be at least {min}")) } else { Ok(v) }
        };
        // Saturating: u32 counts can multiply past u64 and wrap to a small number.
        let limit = |factors: [u32; 2]| -> Result<(), String> {
            let n = factors.iter().fold(2u64, |n, &f| n.saturating_mul(u64::from(f)));
            let left = MAX_SHAPE_TRIANGLES.saturating_sub(self.generated);
            if n > left {
                Err(format!(
                    "it would have {n} triangles, more than the {left} left of the {MAX_SHAPE_TRIANGLES} that the \
                     generated shapes of a description may have together"
                ))
            } else {
                Ok(())
            }
        };
        Ok(match obj {
            Object::Quad(q) => {
                positive(&q.size, "size")?;
                let n = Vec3::from(q.normal.unwrap_or([0.0, 1.0, 0.0]));
                if !(n.is_finite() && n.length() > 0.0) {
                    return Err("the normal must be a finite, non-zero vector".to_owned());
                }
                shapes::quad(centre(q.centre)?, q.size, n)
            }
            Object::Box(b) => {
                positive(&b.size, "size")?;
                shapes::cuboid(centre(b.centre)?, Vec3::from(b.size))
            }
            Object::Sphere(s) => {
                positive(&[s.radius], "radius")?;
                let segments = count(s.segments, SPHERE_SEGMENTS, 3, "segments")?;
                let rings = count(s.rings, SPHERE_RINGS, 2, "rings")?;
                limit([segments, rings - 1])?;
                shapes::sphere(centre(s.centre)?, s.radius, segments, rings)
            }
            Object::Torus(t) => {
                positive(&[t.major, t.minor], "radii")?;
                if t.minor >= t.major {
                    return Err("the minor radius must be smaller than the major radius".to_owned());
                }
                let segments = count(t.segments, TORUS_SEGMENTS, 3, "segments")?;
                let sides = count(t.sides, TORUS_SIDES, 3, "sides")?;
                limit([segments, sides])?;
                shapes::torus(centre(t.centre)?, t.major, t.minor, segments, sides)
            }
            Object::Mesh(_) => shapes::Mesh::default(),
        })
    }
}

fn material(m: &MaterialDesc) -> Result<Material, String> {
    let d = Material::default();
    let kt = m.kt.unwrap_or(0.0);
    let mat = Material {
        kd: m.kd.unwrap_or(d.kd),
        ks: m.ks.unwrap_or(d.ks),
        shininess: m.shininess.unwrap_or(d.shininess),
        kr: m.kr.unwrap_or(0.0),
        kt,
        ior: m.ior.unwrap_or(if kt > 0.0 { super::materials::DEFAULT_IOR } else { d.ior }),
        _pad: [0.0; 2],
    };
    let all = [&mat.kd[..], &mat.ks[..], &[mat.shininess, mat.kr, mat.kt, mat.ior]].concat();
    if !finite(&all) {
        return Err("every value must be a finite number".to_owned());
    }
    if mat.kd.iter().chain(&mat.ks).any(|&c| c < 0.0) || mat.shininess < 0.0 {
        return Err("colours and shininess must not be negative".to_owned());
    }
    if !(0.0..=1.0).contains(&mat.kr) || !(0.0..=1.0).contains(&mat.kt) {
        return Err("kr and kt must lie between 0 and 1".to_owned());
    }
    if mat.kr > 0.0 && mat.kt > 0.0 {
        return Err("a material is reflective (kr) or refractive (kt), not both".to_owned());
    }
    if mat.ior <= 0.0 {
        return Err("the index of refraction must be positive".to_owned());
    }
    Ok(mat)
}

/// Bounds of triangles; `None` for none.
/// A described camera, moved to the scene's local `origin`.
fn camera(c: &CameraDesc, origin: DVec3) -> Result<Camera, String> {
    if c.name.is_empty() || c.name.len() > CAMERA_NAME_LEN || c.name.contains('\0') {
        return Err(format!("a camera name must have 1 to {CAMERA_NAME_LEN} bytes and no NUL"));
    }
    let up = c.up.unwrap_or([0.0, 1.0, 0.0]);
    let fov = c.fov.unwrap_or(defaults::FOV_DEG);
    let (eye, at) = ((DVec3::from(c.eye) - origin).as_vec3(), (DVec3::from(c.at) - origin).as_vec3());
    if !finite(&[eye.to_array(), at.to_array(), up].concat()) {
        return Err("eye, at and up must be finite".to_owned());
    }
    if !(fov > 0.0 && fov < 180.0) {
        return Err("the field of view must lie strictly between 0 and 180 degrees".to_owned());
    }
    let f = (at - eye).as_dvec3();
    let u = Vec3::from(up).as_dvec3();
    if geometry::unit(f).is_none()
        || geometry::unit(u).is_none()
        || geometry::unit(f.normalize().cross(u.normalize())).is_none()
    {
        return Err("eye and at must differ, and up must not be parallel to the view direction".to_owned());
    }
    Ok(Camera::new(&c.name, eye.into(), at.into(), up, fov))
}

fn placement_matrix(p: &Placement) -> Result<DMat4, String> {
    let v3 = |v: [f32; 3]| DVec3::from(v.map(f64::from));
    let scale = match p.scale {
        None => DVec3::ONE,
        Some(Scale::Uniform(s)) => DVec3::splat(f64::from(s)),
        Some(Scale::PerAxis(s)) => v3(s),
    };
    if !scale.is_finite() || scale.x == 0.0 || scale.y == 0.0 || scale.z == 0.0 {
        return Err("the scale must be finite and non-zero".to_owned());
    }
    let mut rot = DQuat::IDENTITY;
    if let Some(r) = p.rotate {
        let r = v3(r);
        if !r.is_finite() {
            return Err("the rotation angles must be finite".to_owned());
        }
        rot = DQuat::from_rotation_z(r.z.to_radians())
            * DQuat::from_rotation_y(r.y.to_radians())
            * DQuat::from_rotation_x(r.x.to_radians());
    }
    match (p.axis, p.angle) {
        (None, None) => {}
        (Some(axis), Some(angle)) => {
            let axis = v3(axis).try_normalize().ok_or("the rotation axis must be a finite, non-zero vector")?;
            if !angle.is_finite() {
                return Err("the rotation angle must be finite".to_owned());
            }
            rot = DQuat::from_axis_angle(axis, f64::from(angle).to_radians()) * rot;
        }
        _ => return Err("axis and angle must be given together".to_owned()),
    }
    let t = DVec3::from(p.translate.unwrap_or([0.0; 3]));
    if !t.is_finite() {
        return Err("the translation must be finite".to_owned());
    }
    Ok(DMat4::from_scale_rotation_translation(scale, rot, t))
}
