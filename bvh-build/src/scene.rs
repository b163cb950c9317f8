//! The in-memory scene that importers produce and the compiler consumes.

use bvh_format::{Camera, Light, Material, SceneSettings};
use glam::{DVec3, Vec3};

/// Triangles in input order (the order tracers report in their `prim` AOV), with everything the
/// file keeps about them.
#[derive(Clone, Debug, Default)]
pub struct Scene {
    /// World position of the local origin that positions, cameras and lights are relative to
    /// (see [`bvh_format::SceneFile::origin`]); zero unless an importer moved a scene far from
    /// the world origin to its centre.
    pub origin: DVec3,
    /// Vertex positions of each triangle, relative to `origin`.
    pub positions: Vec<[Vec3; 3]>,
    /// Shading normal at each vertex of each triangle, unit length, world space.
    pub normals: Vec<[Vec3; 3]>,
    /// Material of each triangle: an index into `materials`.
    pub material_ids: Vec<u32>,
    pub materials: Vec<Material>,
    /// One name per material.
    pub material_names: Vec<String>,
    pub cameras: Vec<Camera>,
    pub lights: Vec<Light>,
    pub settings: SceneSettings,
    /// What the importer skipped or changed, one sentence each, for the user to see.
    pub warnings: Vec<String>,
}

impl Scene {
    pub fn triangle_count(&self) -> usize {
        self.positions.len()
    }

    /// Bounds of all vertices; `None` for an empty scene.
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        crate::import::geometry::bounds(&self.positions)
    }

    /// Appends another scene's triangles and materials (cameras, lights and settings of `other`
    /// are ignored).
    pub fn append(&mut self, other: Scene) {
        let base = self.materials.len() as u32;
        self.positions.extend(other.positions);
        self.normals.extend(other.normals);
        self.material_ids.extend(other.material_ids.into_iter().map(|m| m + base));
        self.materials.extend(other.materials);
        self.material_names.extend(other.material_names);
        self.warnings.extend(other.warnings);
    }
}
