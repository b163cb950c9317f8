//! From an imported [`Scene`] to a [`SceneFile`]: build the tree, reorder the triangles into leaf
//! order, derive the requested layouts.

use crate::BuildError;
use crate::binned::BinnedSah;
use crate::build::{self, Costs};
use crate::scene::Scene;
use crate::sweep::SweepSah;
use bvh_format::{BuildParams, SceneFile, Strategy, Triangle, TriangleNormals};
use std::sync::atomic::AtomicUsize;

/// Which node layouts to store.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layouts {
    pub child_pair: bool,
    pub escape: bool,
}

impl Default for Layouts {
    fn default() -> Self {
        Self { child_pair: true, escape: true }
    }
}

/// Largest bin count accepted.
pub const MAX_BINS: u32 = 1024;

/// Checks build parameters; every message is one sentence for the user.
pub fn check_params(p: &BuildParams) -> Result<(), BuildError> {
    let bad = |m: &str| Err(BuildError::Params(m.to_owned()));
    if p.strategy == Strategy::Binned && !(2..=MAX_BINS).contains(&p.bins) {
        return bad(&format!("the bin count must lie between 2 and {MAX_BINS}, not {}", p.bins));
    }
    if !(p.traversal_cost.is_finite() && p.traversal_cost >= 0.0) {
        return bad("the traversal cost must be a finite, non-negative number");
    }
    if !(p.intersection_cost.is_finite() && p.intersection_cost > 0.0) {
        return bad("the intersection cost must be a finite, positive number");
    }
    if p.max_leaf_size == 0 {
        return bad("the maximum leaf size must be at least 1");
    }
    Ok(())
}

/// The tree alone (child-pair layout and leaf order), for benchmarks and tests.
pub fn build_tree(positions: &[[glam::Vec3; 3]], p: &BuildParams) -> Result<build::BuiltTree, BuildError> {
    build_tree_with_progress(positions, p, None)
}

/// [`build_tree`], counting the triangles placed in leaves into `progress` as it goes.
pub fn build_tree_with_progress(
    positions: &[[glam::Vec3; 3]],
    p: &BuildParams,
    progress: Option<&AtomicUsize>,
) -> Result<build::BuiltTree, BuildError> {
    tree_with(positions, p, progress, false)
}

fn tree_with(
    positions: &[[glam::Vec3; 3]],
    p: &BuildParams,
    progress: Option<&AtomicUsize>,
    escape: bool,
) -> Result<build::BuiltTree, BuildError> {
    use rayon::prelude::*;
    check_params(p)?;
    if positions.is_empty() {
        return Err(BuildError::Empty);
    }
    if positions.len() >= (u32::MAX / 2) as usize {
        return Err(BuildError::TooLarge(positions.len()));
    }
    if let Some(t) = positions.par_iter().position_first(|t| t.iter().any(|v| !v.is_finite())) {
        return Err(BuildError::NonFinite { triangle: t });
    }
    let mut refs = build::prim_refs(positions);
    let costs = Costs {
        traversal: p.traversal_cost as f64,
        intersection: p.intersection_cost as f64,
        max_leaf_size: p.max_leaf_size as usize,
        depth_limit: build::DEPTH_LIMIT,
    };
    Ok(match p.strategy {
        Strategy::Binned => {
            build::build(&mut refs, &BinnedSah { bins: p.bins as usize, costs }, costs, progress, escape)
        }
        Strategy::Sweep => build::build(&mut refs, &SweepSah { costs }, costs, progress, escape),
    })
}

/// Compiles a scene into the file's in-memory form (validated).
pub fn compile(scene: &Scene, params: &BuildParams, layouts: Layouts) -> Result<SceneFile, BuildError> {
    compile_with_progress(scene, params, layouts, None)
}

/// [`compile`], counting the triangles placed in leaves into `progress` as the tree is built.
pub fn compile_with_progress(
    scene: &Scene,
    params: &BuildParams,
    layouts: Layouts,
    progress: Option<&AtomicUsize>,
) -> Result<SceneFile, BuildError> {
    if !layouts.child_pair && !layouts.escape {
        return Err(BuildError::Params("at least one node layout must be chosen".to_owned()));
    }
    let n = scene.triangle_count();
    if scene.normals.len() != n || scene.material_ids.len() != n {
        return Err(BuildError::Params("the scene's normals or material ids do not match its triangles".to_owned()));
    }
    use rayon::prelude::*;
    let tree = tree_with(&scene.positions, params, progress, layouts.escape)?;
    let pad = |v: glam::Vec3| [v.x, v.y, v.z, 0.0];
    let order = &tree.order;
    let ((triangles, normals), material_ids) = rayon::join(
        || {
            rayon::join(
                || {
                    order
                        .par_iter()
                        .map(|&i| {
                            let [a, b, c] = scene.positions[i as usize];
                            Triangle::from_vertices(a.into(), b.into(), c.into())
                        })
                        .collect()
                },
                || {
                    order
                        .par_iter()
                        .map(|&i| {
                            let [a, b, c] = scene.normals[i as usize];
                            TriangleNormals { n: [pad(a), pad(b), pad(c)] }
                        })
                        .collect()
                },
            )
        },
        || order.par_iter().map(|&i| scene.material_ids[i as usize]).collect(),
    );
    let file = SceneFile {
        build: *params,
        settings: scene.settings,
        triangles,
        normals,
        material_ids,
        materials: scene.materials.clone(),
        material_names: scene.material_names.clone(),
        input_index: tree.order,
        child_pair: layouts.child_pair.then_some(tree.nodes),
        escape: tree.escape,
        cameras: scene.cameras.clone(),
        lights: scene.lights.clone(),
    };
    file.validate().map_err(BuildError::Invalid)?;
    Ok(file)
}
