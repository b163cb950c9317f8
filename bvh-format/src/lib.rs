//! The BVH scene file: plain-data types, a writer, and a reader that validates everything before
//! a tracer may use it.
//!
//! The byte layout is documented in `FORMAT.md` beside this crate (included below). The reader
//! ([`read`], [`read_file`]) returns a [`SceneFile`] only after every check has passed; a damaged
//! file yields a typed [`FormatError`] and never panics.
#![doc = include_str!("../FORMAT.md")]

pub mod destination;
mod error;
pub mod layout;
pub mod memory;
mod par;
mod read;
pub mod tree;
mod types;
pub mod wide;
mod write;

pub use error::{FileError, FormatError, LayoutKind};
pub use layout::SectionKind;
pub use read::{SectionInfo, read, read_file, read_input, read_with_sections};
pub use tree::{Tree, TreeStats};
pub use types::{
    BuildParams, CAMERA_NAME_LEN, Camera, FLAT, IndexedTriangle, Light, Material, Node, SceneSettings, Strategy,
    Triangle,
};
pub use wide::WideNode;
pub use write::{WriteError, write, write_file, write_to};

/// Largest magnitude of [`SceneFile::scale_log2`] a file may hold: a rescaled f32 scene spans at
/// most 2^277 (subnormal to largest), so no compiler needs more.
pub const MAX_SCALE_LOG2: i32 = 300;

/// A whole scene as stored in one file: indexed geometry in BVH leaf order, shading data, the tree
/// in one or both layouts, and default cameras and lights.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneFile {
    pub build: BuildParams,
    pub settings: SceneSettings,
    /// World position of the scene's local origin. Every stored position (vertices, node boxes,
    /// cameras, lights) is relative to it: the compiler moves a scene far from the world origin
    /// to its own centre, so that its f32 coordinates keep the precision they have at the origin.
    /// Tracers work in these local coordinates throughout; only positions given in world
    /// coordinates (a command line's camera or lights) pass through [`SceneFile::local`].
    pub origin: [f64; 3],
    /// The stored unit is `2^scale_log2` world units: a world position is
    /// `origin + 2^scale_log2 * local`. The compiler stores a scene much smaller or larger than a
    /// few units rescaled by a power of two (exact in binary floating point), so that the
    /// tracers' self-intersection offsets, which are tuned to scenes of a few units, hold at any
    /// scale. Distances a user gives in world units (the fixed `--offset`) and distances the
    /// tracers report (the `t` AOV) pass through [`SceneFile::local_distance`] and
    /// [`SceneFile::world_distance`].
    pub scale_log2: i32,
    /// Vertex positions, shared by the triangles that meet at them.
    pub vertices: Vec<[f32; 3]>,
    /// Triangles in the order the leaves reference them: vertex indices and material.
    pub triangles: Vec<IndexedTriangle>,
    /// Unit shading normals, referenced by `normal_indices`; empty when every triangle is flat.
    pub normals: Vec<[f32; 3]>,
    /// Per triangle, the normal of each vertex, or [`FLAT`] for a triangle shaded with its
    /// geometric normal; empty (no triangle has normals) or parallel to `triangles`.
    pub normal_indices: Vec<[u32; 3]>,
    pub materials: Vec<Material>,
    /// One name per material (may be empty strings).
    pub material_names: Vec<String>,
    /// For each stored triangle, its index in the input scene (a permutation).
    pub input_index: Vec<u32>,
    pub child_pair: Option<Vec<Node>>,
    pub escape: Option<Vec<Node>>,
    /// The wide layout (8 children per node, quantised boxes): its own tree over the same
    /// triangles, collapsed from the binary one by the compiler ([`wide`]). Never alone: the
    /// header's tree statistics describe the binary tree.
    pub wide: Option<Vec<WideNode>>,
    pub cameras: Vec<Camera>,
    pub lights: Vec<Light>,
}

impl SceneFile {
    /// The three vertex positions of stored triangle `i`.
    pub fn positions(&self, i: usize) -> [[f32; 3]; 3] {
        self.triangles[i].vertices.map(|v| self.vertices[v as usize])
    }

    /// Stored triangle `i` in the tracers' intersection form.
    pub fn triangle(&self, i: usize) -> Triangle {
        let [a, b, c] = self.positions(i);
        Triangle { material: self.triangles[i].material, ..Triangle::from_vertices(a, b, c) }
    }

    /// Every triangle in the tracers' intersection form, in leaf order (48 bytes each), made on
    /// rayon's current pool: the dragon's 42 MB take 45 ms on one thread of the H100 machine's
    /// host, 6 ms on its 16 (tracer-cpu's `examples/load_profile.rs`).
    pub fn leaf_triangles(&self) -> Vec<Triangle> {
        use rayon::prelude::*;
        (0..self.triangles.len()).into_par_iter().map(|i| self.triangle(i)).collect()
    }

    /// The vertex normals of stored triangle `i`, or `None` for a flat triangle.
    pub fn vertex_normals(&self, i: usize) -> Option<[[f32; 3]; 3]> {
        let idx = *self.normal_indices.get(i)?;
        (idx != FLAT).then(|| idx.map(|n| self.normals[n as usize]))
    }

    /// The tree in whichever layout is present (child-pair preferred).
    pub fn tree(&self) -> Tree<'_> {
        match (&self.child_pair, &self.escape) {
            (Some(n), _) => Tree::child_pair(n),
            (None, Some(n)) => Tree::escape(n),
            (None, None) => Tree::child_pair(&[]),
        }
    }

    /// Depth, leaf statistics and SAH cost, computed with the stored build constants.
    pub fn stats(&self) -> TreeStats {
        tree::stats(self.tree(), self.build.traversal_cost, self.build.intersection_cost)
    }

    /// Bounds of the whole scene (the root node's box).
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        self.tree().nodes.first().map(|r| (r.min, r.max)).unwrap_or(([0.0; 3], [0.0; 3]))
    }

    /// A world position in the scene's local coordinates (rounded once, from f64).
    pub fn local(&self, world: [f64; 3]) -> [f32; 3] {
        let unit = self.unit();
        [0, 1, 2].map(|a| ((world[a] - self.origin[a]) / unit) as f32)
    }

    /// A local position in world coordinates.
    pub fn world(&self, local: [f32; 3]) -> [f64; 3] {
        let unit = self.unit();
        [0, 1, 2].map(|a| self.origin[a] + f64::from(local[a]) * unit)
    }

    /// The stored unit in world units, `2^scale_log2` (exact).
    pub fn unit(&self) -> f64 {
        2f64.powi(self.scale_log2)
    }

    /// A distance in world units as the tracers measure it (rounded once, from f64).
    pub fn local_distance(&self, world: f64) -> f32 {
        (world / self.unit()) as f32
    }

    /// A distance the tracers measured, in world units (exact).
    pub fn world_distance(&self, local: f32) -> f64 {
        f64::from(local) * self.unit()
    }

    /// A camera by name.
    pub fn camera(&self, name: &str) -> Option<&Camera> {
        self.cameras.iter().find(|c| c.name() == Some(name))
    }

    /// Checks the whole scene as the reader would, without writing it: a writer calls this so that
    /// it never produces a file the reader rejects.
    pub fn validate(&self) -> Result<(), FormatError> {
        read::validate_scene(self, None)
    }
}
