//! The plain-data records of the file. Every type here is `#[repr(C)]`, has no padding that
//! bytemuck would reject, and a size that is a multiple of 16 (or 4 for the index arrays, 12 for
//! positions and normals), so a
//! section can be uploaded to a GPU storage buffer or mapped without conversion.

use bytemuck::{Pod, Zeroable};

/// A BVH node, 32 bytes: two 16-byte rows so that a GPU reads it with two vector loads.
///
/// `count > 0` marks a leaf whose triangles are `[index, index + count)`. For an inner node
/// (`count == 0`) the meaning of `index` depends on the layout: the left child in the child-pair
/// layout (the right child is `index + 1`), the escape index in the escape-pointer layout.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Node {
    pub min: [f32; 3],
    pub count: u32,
    pub max: [f32; 3],
    pub index: u32,
}

impl Node {
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }
}

/// A triangle as the file stores it: three indices into the vertex positions and its material.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct IndexedTriangle {
    pub vertices: [u32; 3],
    pub material: u32,
}

/// Marks a triangle without vertex normals in [`SceneFile::normal_indices`](crate::SceneFile):
/// it is shaded with its geometric normal.
pub const FLAT: [u32; 3] = [u32::MAX; 3];

/// A triangle as the tracers intersect it: its three vertices, each padded to 16 bytes, with the
/// material in the first padding word, 48 bytes. The tracers expand the file's indexed form into
/// this one at load ([`SceneFile::leaf_triangles`](crate::SceneFile::leaf_triangles)), in leaf
/// order, so that a leaf's triangles are one contiguous read (thesis 4.2.2: 16-byte aligned
/// vectors) and the edge test reads each vertex exactly as stored.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Triangle {
    pub p0: [f32; 3],
    pub material: u32,
    pub p1: [f32; 3],
    pub _pad1: u32,
    pub p2: [f32; 3],
    pub _pad2: u32,
}

impl Triangle {
    /// The triangle with vertices `a`, `b`, `c` and material 0.
    pub fn from_vertices(a: [f32; 3], b: [f32; 3], c: [f32; 3]) -> Self {
        Self { p0: a, material: 0, p1: b, _pad1: 0, p2: c, _pad2: 0 }
    }

    /// The three vertices, exactly as stored.
    pub fn vertices(&self) -> [[f32; 3]; 3] {
        [self.p0, self.p1, self.p2]
    }
}

/// A material of the Whitted model (docs/materials.md, docs/shading.md). A material is reflective (`kr > 0`) or
/// refractive (`kt > 0`), never both.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Material {
    pub kd: [f32; 3],
    pub shininess: f32,
    pub ks: [f32; 3],
    pub kr: f32,
    pub kt: f32,
    pub ior: f32,
    pub _pad: [f32; 2],
}

impl Default for Material {
    fn default() -> Self {
        Self { kd: [0.8, 0.8, 0.8], shininess: 32.0, ks: [0.0, 0.0, 0.0], kr: 0.0, kt: 0.0, ior: 1.0, _pad: [0.0; 2] }
    }
}

/// Longest camera name, in bytes of UTF-8.
pub const CAMERA_NAME_LEN: usize = 16;

/// A pinhole camera in the convention of docs/shading.md ("Camera").
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Camera {
    pub eye: [f32; 3],
    /// Vertical field of view in degrees.
    pub fov_deg: f32,
    pub at: [f32; 3],
    pub _pad0: f32,
    pub up: [f32; 3],
    pub _pad1: f32,
    /// UTF-8, padded with zero bytes.
    pub name: [u8; CAMERA_NAME_LEN],
}

impl Camera {
    /// A camera named `name`; names longer than [`CAMERA_NAME_LEN`] bytes are cut at a character
    /// boundary.
    pub fn new(name: &str, eye: [f32; 3], at: [f32; 3], up: [f32; 3], fov_deg: f32) -> Self {
        let mut bytes = [0u8; CAMERA_NAME_LEN];
        let mut end = name.len().min(CAMERA_NAME_LEN);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        bytes[..end].copy_from_slice(&name.as_bytes()[..end]);
        Self { eye, fov_deg, at, _pad0: 0.0, up, _pad1: 0.0, name: bytes }
    }

    /// The name, or `None` when the stored bytes are not UTF-8.
    pub fn name(&self) -> Option<&str> {
        let end = self.name.iter().position(|&b| b == 0).unwrap_or(CAMERA_NAME_LEN);
        std::str::from_utf8(&self.name[..end]).ok()
    }
}

/// A coloured point light.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct Light {
    pub position: [f32; 3],
    pub _pad0: f32,
    pub colour: [f32; 3],
    pub _pad1: f32,
}

impl Light {
    pub fn new(position: [f32; 3], colour: [f32; 3]) -> Self {
        Self { position, _pad0: 0.0, colour, _pad1: 0.0 }
    }
}

/// Which builder made the tree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Strategy {
    /// Wald's binned SAH.
    Binned,
    /// SAH evaluated at every centroid (the quality reference).
    Sweep,
}

impl Strategy {
    pub(crate) fn to_u32(self) -> u32 {
        match self {
            Strategy::Binned => 0,
            Strategy::Sweep => 1,
        }
    }
    pub(crate) fn from_u32(v: u32) -> Option<Self> {
        match v {
            0 => Some(Strategy::Binned),
            1 => Some(Strategy::Sweep),
            _ => None,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Strategy::Binned => "binned",
            Strategy::Sweep => "sweep",
        }
    }
}

/// The parameters the tree was built with, kept in the header so that `bvhc info` can explain a
/// file and the SAH cost can be recomputed with the same constants.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BuildParams {
    pub strategy: Strategy,
    /// Bin count (ignored by the sweep builder, stored as given).
    pub bins: u32,
    pub traversal_cost: f32,
    pub intersection_cost: f32,
    pub max_leaf_size: u32,
}

impl Default for BuildParams {
    fn default() -> Self {
        Self { strategy: Strategy::Binned, bins: 16, traversal_cost: 1.0, intersection_cost: 1.0, max_leaf_size: 8 }
    }
}

/// Scene-wide shading settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneSettings {
    /// The ambient term `Ia` of the Phong sum.
    pub ambient: [f32; 3],
    /// Colour of rays that leave the scene.
    pub background: [f32; 3],
    /// Most secondary rays a primary ray may spawn in a chain (the thesis's "indirections").
    pub max_indirections: u32,
}

impl Default for SceneSettings {
    fn default() -> Self {
        Self { ambient: [0.05, 0.05, 0.05], background: [0.0, 0.0, 0.0], max_indirections: 0 }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn records_have_gpu_friendly_sizes() {
        assert_eq!(std::mem::size_of::<Node>(), 32);
        assert_eq!(std::mem::size_of::<Triangle>(), 48);
        assert_eq!(std::mem::size_of::<IndexedTriangle>(), 16);
        assert_eq!(std::mem::size_of::<Material>(), 48);
        assert_eq!(std::mem::size_of::<Camera>(), 64);
        assert_eq!(std::mem::size_of::<Light>(), 32);
    }

    #[test]
    fn camera_names_are_cut_at_char_boundaries() {
        let c = Camera::new("ääääääääää", [0.0; 3], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 45.0);
        assert_eq!(c.name(), Some("ääääääää"));
        let c = Camera::new("wide", [0.0; 3], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0], 45.0);
        assert_eq!(c.name(), Some("wide"));
    }
}
