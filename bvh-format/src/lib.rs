//! The BVH scene file: plain-data types, a writer, and a reader that validates everything before
//! a tracer may use it.
//!
//! The byte layout is documented in `FORMAT.md` beside this crate (included below). The reader
//! ([`read`], [`read_file`]) returns a [`SceneFile`] only after every check has passed; a damaged
//! file yields a typed [`FormatError`] and never panics.
#![doc = include_str!("../FORMAT.md")]

mod error;
pub mod layout;
mod read;
pub mod tree;
mod types;
mod write;

pub use error::{FileError, FormatError, LayoutKind};
pub use layout::SectionKind;
pub use read::{SectionInfo, read, read_file, read_with_sections};
pub use tree::{Tree, TreeStats};
pub use types::{
    BuildParams, CAMERA_NAME_LEN, Camera, Light, Material, Node, SceneSettings, Strategy, Triangle, TriangleNormals,
};
pub use write::{write, write_file};

/// A whole scene as stored in one file: geometry in BVH leaf order, shading data, the tree in one
/// or both layouts, and default cameras and lights.
#[derive(Clone, Debug, PartialEq)]
pub struct SceneFile {
    pub build: BuildParams,
    pub settings: SceneSettings,
    /// Triangles in the order the leaves reference them.
    pub triangles: Vec<Triangle>,
    /// Shading normals, parallel to `triangles`.
    pub normals: Vec<TriangleNormals>,
    /// Material of each triangle, parallel to `triangles`.
    pub material_ids: Vec<u32>,
    pub materials: Vec<Material>,
    /// One name per material (may be empty strings).
    pub material_names: Vec<String>,
    /// For each stored triangle, its index in the input scene (a permutation).
    pub input_index: Vec<u32>,
    pub child_pair: Option<Vec<Node>>,
    pub escape: Option<Vec<Node>>,
    pub cameras: Vec<Camera>,
    pub lights: Vec<Light>,
}

impl SceneFile {
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
