//! From an imported [`Scene`] to a [`SceneFile`]: build the tree, reorder the triangles into leaf
//! order, derive the requested layouts.

use crate::BuildError;
use crate::binned::BinnedSah;
use crate::build::{self, Costs};
use crate::scene::Scene;
use crate::sweep::SweepSah;
use crate::weld::weld;
use bvh_format::{BuildParams, FLAT, IndexedTriangle, SceneFile, Strategy};
use glam::Vec3;
use std::sync::atomic::AtomicUsize;

/// Which node layouts to store.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layouts {
    pub child_pair: bool,
    pub escape: bool,
    /// The wide layout ([`crate::wide`]), beside at least one of the binary ones; it also puts the
    /// triangles in the order its leaves need.
    pub wide: bool,
}

impl Layouts {
    /// The two binary layouts (the default).
    pub const BINARY: Layouts = Layouts { child_pair: true, escape: true, wide: false };
    /// Every layout.
    pub const ALL: Layouts = Layouts { child_pair: true, escape: true, wide: true };
}

impl Default for Layouts {
    /// The binary layouts: the wide one costs about 11 bytes per triangle more, which only a scene
    /// traced with `cwbvh` needs.
    fn default() -> Self {
        Self::BINARY
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

pub(crate) fn tree_with(
    positions: &[[glam::Vec3; 3]],
    p: &BuildParams,
    progress: Option<&AtomicUsize>,
    escape: bool,
) -> Result<build::BuiltTree, BuildError> {
    let started = std::time::Instant::now();
    check_params(p)?;
    if positions.is_empty() {
        return Err(BuildError::Empty);
    }
    if positions.len() >= (u32::MAX / 2) as usize {
        return Err(BuildError::TooLarge(positions.len()));
    }
    let (mut refs, root) = build::prim_refs_checked(positions).map_err(|t| BuildError::NonFinite { triangle: t })?;
    let costs = Costs {
        traversal: p.traversal_cost as f64,
        intersection: p.intersection_cost as f64,
        max_leaf_size: p.max_leaf_size as usize,
        depth_limit: build::DEPTH_LIMIT,
    };
    let checked = started.elapsed().as_secs_f64() * 1e3;
    let mut tree = match p.strategy {
        Strategy::Binned => {
            build::build_bounded(&mut refs, root, &BinnedSah { bins: p.bins as usize, costs }, costs, progress, escape)
        }
        Strategy::Sweep => build::build_bounded(&mut refs, root, &SweepSah { costs }, costs, progress, escape),
    };
    // The checks and the primitive references are set-up too.
    tree.phases.setup += checked;
    let t = std::time::Instant::now();
    drop(refs);
    tree.phases.release += t.elapsed().as_secs_f64() * 1e3;
    Ok(tree)
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
    let file = compile_for_writing(scene, params, layouts, progress)?;
    file.validate().map_err(BuildError::Invalid)?;
    Ok(file)
}

/// [`compile_with_progress`] without its validation, for a caller that hands the file straight to
/// `bvh_format::write_to` (or `write`), which validates it before writing a byte: one validation
/// on the way to disk instead of two (about 130 ms for a million triangles on the H100 host).
pub fn compile_for_writing(
    scene: &Scene,
    params: &BuildParams,
    layouts: Layouts,
    progress: Option<&AtomicUsize>,
) -> Result<SceneFile, BuildError> {
    if !layouts.child_pair && !layouts.escape {
        let msg = if layouts.wide {
            "the wide layout needs a binary one beside it (child-pair or escape)"
        } else {
            "at least one node layout must be chosen"
        };
        return Err(BuildError::Params(msg.to_owned()));
    }
    let n = scene.triangle_count();
    if scene.normals.len() != n || scene.material_ids.len() != n {
        return Err(BuildError::Params("the scene's normals or material ids do not match its triangles".to_owned()));
    }
    let mut tree = tree_with(&scene.positions, params, progress, layouts.escape)?;
    let plan = if layouts.wide {
        let plan = crate::wide::collapse(&tree.nodes)?;
        plan.reorder(&mut tree.nodes, tree.escape.as_deref_mut(), &mut tree.order);
        Some(plan)
    } else {
        None
    };
    let geometry = index_geometry(scene, &tree.order);
    let mut file = SceneFile {
        build: *params,
        settings: scene.settings,
        origin: scene.origin.to_array(),
        scale_log2: 0,
        vertices: geometry.vertices,
        triangles: geometry.triangles,
        normals: geometry.normals,
        normal_indices: geometry.normal_indices,
        materials: scene.materials.clone(),
        material_names: scene.material_names.clone(),
        input_index: tree.order,
        // Kept until the wide layout is quantised around its (rescaled) boxes.
        child_pair: Some(tree.nodes),
        escape: tree.escape,
        wide: None,
        cameras: scene.cameras.clone(),
        lights: scene.lights.clone(),
    };
    // After the build: a power of two changes no SAH decision, and this way no copy is made.
    crate::unit::rescale(&mut file)?;
    if let (Some(plan), Some(cp)) = (&plan, &file.child_pair) {
        file.wide = Some(plan.quantise(cp)?);
    }
    if !layouts.child_pair {
        file.child_pair = None;
    }
    Ok(file)
}

/// The indexed geometry of the file, in leaf order.
struct IndexedGeometry {
    vertices: Vec<[f32; 3]>,
    triangles: Vec<IndexedTriangle>,
    normals: Vec<[f32; 3]>,
    normal_indices: Vec<[u32; 3]>,
}

/// Welds equal positions (and equal normals) into shared vertices, numbered in order of first use
/// so that a leaf's vertices lie close together. Welding is what makes the tracers' edge test
/// consistent: the two triangles of an edge read the same two stored vertices. Triangles whose
/// vertex normals all equal their geometric normal are stored flat (no normals); a scene of only
/// flat triangles stores none. Parallel, with the result of a serial pass ([`crate::weld`]).
fn index_geometry(scene: &Scene, order: &[u32]) -> IndexedGeometry {
    use rayon::prelude::*;
    let corners: Vec<Vec3> = order.par_iter().flat_map_iter(|&i| scene.positions[i as usize]).collect();
    let welded = weld(&corners);
    drop(corners);
    let triangles = order
        .par_iter()
        .zip(welded.indices.par_chunks_exact(3))
        .map(|(&i, v)| IndexedTriangle { vertices: [v[0], v[1], v[2]], material: scene.material_ids[i as usize] })
        .collect();
    let flat: Vec<bool> =
        order.par_iter().map(|&i| is_flat(scene.positions[i as usize], scene.normals[i as usize])).collect();
    let shaded: Vec<Vec3> =
        order.par_iter().zip(&flat).filter(|&(_, &f)| !f).flat_map_iter(|(&i, _)| scene.normals[i as usize]).collect();
    let welded_normals = weld(&shaded);
    drop(shaded);
    let normal_indices = if welded_normals.vertices.is_empty() {
        Vec::new()
    } else {
        // The k-th shaded triangle's normals are the k-th triple of the welded indices.
        let mut triples = welded_normals.indices.chunks_exact(3);
        flat.iter()
            .map(|&f| {
                if f {
                    FLAT
                } else {
                    triples.next().map(|t| [t[0], t[1], t[2]]).expect("one triple per shaded triangle")
                }
            })
            .collect()
    };
    IndexedGeometry { vertices: welded.vertices, triangles, normals: welded_normals.vertices, normal_indices }
}

/// Whether all three vertex normals are the triangle's own geometric normal (to rounding), so that
/// shading with the geometric normal gives the same picture.
fn is_flat([a, b, c]: [Vec3; 3], normals: [Vec3; 3]) -> bool {
    let ng = crate::import::geometry::face_normal(a, b, c);
    normals.iter().all(|&n| (n - ng).abs().max_element() <= 1e-6)
}
