//! The top-down build shared by both SAH builders: recursion, leaf decisions, fallbacks for
//! degenerate input, rayon parallelism, and the final child-pair layout. A [`Splitter`] (binned or
//! sweep) only decides where to split one node.

use bvh_format::Node;
use glam::Vec3A;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Nodes deeper than this are split at the object median instead of by SAH, which bounds the
/// depth of any tree by `DEPTH_LIMIT + log2(triangles)`: SAH can peel one triangle at a time off
/// pathological input (nested shells, say) and build a tree as deep as the scene is large.
pub const DEPTH_LIMIT: u32 = 64;

/// Nodes with more triangles than this build their two subtrees in parallel.
const PARALLEL_THRESHOLD: usize = 4096;

/// An axis-aligned box.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: Vec3A,
    pub max: Vec3A,
}

impl Aabb {
    pub const EMPTY: Aabb = Aabb { min: Vec3A::splat(f32::INFINITY), max: Vec3A::splat(f32::NEG_INFINITY) };

    #[inline]
    pub fn grow(&mut self, other: &Aabb) {
        self.min = self.min.min(other.min);
        self.max = self.max.max(other.max);
    }

    #[inline]
    pub fn grow_point(&mut self, p: Vec3A) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    #[inline]
    pub fn union(mut self, other: &Aabb) -> Aabb {
        self.grow(other);
        self
    }

    /// Half the surface area in f64, zero for an empty box (f32 would overflow on huge scenes).
    #[inline]
    pub fn half_area(&self) -> f64 {
        if self.min.x > self.max.x {
            return 0.0;
        }
        bvh_format::tree::half_area(self.min.into(), self.max.into())
    }

    #[inline]
    pub fn extent(&self) -> Vec3A {
        (self.max - self.min).max(Vec3A::ZERO)
    }
}

/// One triangle as the builders see it: its box and its input index, 32 bytes. The builders
/// reorder these records themselves rather than an index array into them, so that binning and
/// partitioning stream through memory instead of gathering from it.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct PrimRef {
    pub min: [f32; 3],
    pub id: u32,
    pub max: [f32; 3],
    /// Half the surface area of the triangle's box (f32; only compared against node areas).
    pub area: f32,
}

impl PrimRef {
    #[inline(always)]
    pub fn aabb(&self) -> Aabb {
        Aabb { min: Vec3A::from(self.min), max: Vec3A::from(self.max) }
    }

    /// Centre of the triangle's box: what the builders sort and bin by.
    #[inline(always)]
    pub fn centroid(&self) -> Vec3A {
        (Vec3A::from(self.min) + Vec3A::from(self.max)) * 0.5
    }
}

/// The references of every triangle, in input order.
pub fn prim_refs(positions: &[[glam::Vec3; 3]]) -> Vec<PrimRef> {
    use rayon::prelude::*;
    positions
        .par_iter()
        .enumerate()
        .map(|(i, t)| {
            let (min, max) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
            let d = max - min;
            PrimRef { min: min.into(), id: i as u32, max: max.into(), area: d.x * d.y + d.y * d.z + d.z * d.x }
        })
        .collect()
}

/// Box and centroid box of a set of primitives.
pub fn bounds_of(refs: &[PrimRef]) -> NodeBounds {
    let mut nb = NodeBounds { aabb: Aabb::EMPTY, centroids: Aabb::EMPTY };
    for r in refs {
        nb.aabb.grow(&r.aabb());
        nb.centroids.grow_point(r.centroid());
    }
    nb
}

/// A node's box and the box of its primitives' centroids.
#[derive(Clone, Copy, Debug)]
pub struct NodeBounds {
    pub aabb: Aabb,
    pub centroids: Aabb,
}

/// The SAH constants and leaf limit the splitters decide with.
#[derive(Clone, Copy, Debug)]
pub struct Costs {
    pub traversal: f64,
    pub intersection: f64,
    pub max_leaf_size: usize,
    /// Depth below which nodes are split at the median; [`DEPTH_LIMIT`] outside tests.
    pub depth_limit: u32,
}

impl Costs {
    /// SAH cost of splitting a node of half area `parent_area` into the given children.
    #[inline]
    pub fn split_cost(&self, parent_area: f64, left_area: f64, left_n: usize, right_area: f64, right_n: usize) -> f64 {
        self.traversal + self.intersection * (left_area * left_n as f64 + right_area * right_n as f64) / parent_area
    }

    #[inline]
    pub fn leaf_cost(&self, n: usize) -> f64 {
        self.intersection * n as f64
    }
}

/// A split: `prims[..mid]` go left, the rest right.
pub struct Split {
    pub mid: usize,
    pub left: NodeBounds,
    pub right: NodeBounds,
}

/// Decides how one node is split.
pub trait Splitter: Sync {
    /// Reorders `refs` and returns the split with the lowest SAH cost, or `None` when no split
    /// separates the primitives or, if `may_leaf`, when a leaf is cheaper than the best split.
    fn split(&self, refs: &mut [PrimRef], bounds: &NodeBounds, may_leaf: bool) -> Option<Split>;
}

/// One node of the build, in a gapped depth-first array: a subtree of `c` primitives owns `2c - 1`
/// slots, its root first, its left subtree next, and its right subtree at `right`.
#[derive(Clone, Copy, Default)]
struct Slot {
    min: [f32; 3],
    max: [f32; 3],
    /// Triangle count for a leaf, 0 for an inner node.
    count: u32,
    /// First primitive (leaf) or slot of the right child (inner node).
    index: u32,
}

/// A finished tree: child-pair nodes, and for each leaf-order slot the input triangle it holds.
pub struct BuiltTree {
    pub nodes: Vec<Node>,
    pub order: Vec<u32>,
}

struct Ctx<'a, S: Splitter> {
    splitter: &'a S,
    costs: Costs,
    progress: Option<&'a AtomicUsize>,
}

/// Builds a tree over `refs` (reordering them into leaf order) with the given splitter.
/// `progress`, when given, counts the primitives already placed in leaves, for a progress bar.
pub fn build<S: Splitter>(
    refs: &mut [PrimRef],
    splitter: &S,
    costs: Costs,
    progress: Option<&AtomicUsize>,
) -> BuiltTree {
    let n = refs.len();
    assert!(n > 0 && n < u32::MAX as usize / 2, "the compiler rejects empty and oversized scenes before building");
    let mut slots = vec![Slot::default(); 2 * n - 1];
    let root = bounds_parallel(refs);
    let ctx = Ctx { splitter, costs, progress };
    build_node(&ctx, refs, 0, &mut slots, 0, root, 0);
    BuiltTree { nodes: flatten(&slots), order: refs.iter().map(|r| r.id).collect() }
}

fn bounds_parallel(refs: &[PrimRef]) -> NodeBounds {
    use rayon::prelude::*;
    let empty = NodeBounds { aabb: Aabb::EMPTY, centroids: Aabb::EMPTY };
    refs.par_chunks(16384)
        .map(bounds_of)
        .reduce(|| empty, |a, b| NodeBounds { aabb: a.aabb.union(&b.aabb), centroids: a.centroids.union(&b.centroids) })
}

fn build_node<S: Splitter>(
    ctx: &Ctx<'_, S>,
    prims: &mut [PrimRef],
    first: usize,
    slots: &mut [Slot],
    slot: usize,
    bounds: NodeBounds,
    depth: u32,
) {
    let n = prims.len();
    let may_leaf = n <= ctx.costs.max_leaf_size;
    let split = if n == 1 {
        None
    } else if depth >= ctx.costs.depth_limit {
        if may_leaf { None } else { Some(median_split(prims, &bounds)) }
    } else {
        match ctx.splitter.split(prims, &bounds, may_leaf) {
            Some(s) => Some(s),
            None if may_leaf => None,
            None => Some(median_split(prims, &bounds)),
        }
    };
    let here = &mut slots[0];
    here.min = bounds.aabb.min.into();
    here.max = bounds.aabb.max.into();
    let Some(split) = split else {
        here.count = n as u32;
        here.index = first as u32;
        if let Some(p) = ctx.progress {
            p.fetch_add(n, Ordering::Relaxed);
        }
        return;
    };
    let mid = split.mid;
    debug_assert!(mid > 0 && mid < n);
    let right_slot = slot + 2 * mid;
    here.count = 0;
    here.index = right_slot as u32;
    let (left_prims, right_prims) = prims.split_at_mut(mid);
    let (left_slots, right_slots) = slots[1..].split_at_mut(2 * mid - 1);
    let mut left = || build_node(ctx, left_prims, first, left_slots, slot + 1, split.left, depth + 1);
    let mut right = || build_node(ctx, right_prims, first + mid, right_slots, right_slot, split.right, depth + 1);
    if n > PARALLEL_THRESHOLD {
        rayon::join(left, right);
    } else {
        left();
        right();
    }
}

/// Splits at the object median along the widest centroid axis; with all centroids equal, simply
/// in the middle of the list. Always makes progress, so degenerate input terminates.
pub fn median_split(refs: &mut [PrimRef], bounds: &NodeBounds) -> Split {
    let mid = refs.len() / 2;
    let ext = bounds.centroids.extent();
    if ext.max_element() > 0.0 {
        let axis = ext.max_position();
        refs.select_nth_unstable_by(mid, |a, b| a.centroid()[axis].total_cmp(&b.centroid()[axis]));
    }
    Split { mid, left: bounds_of(&refs[..mid]), right: bounds_of(&refs[mid..]) }
}

/// Turns the gapped depth-first slots into the child-pair layout: root at 0, the two children of
/// each inner node allocated together when the walk (depth-first, left first) reaches it.
fn flatten(slots: &[Slot]) -> Vec<Node> {
    let mut nodes = Vec::with_capacity(slots.len());
    nodes.push(Node::default());
    let mut stack = vec![(0usize, 0usize)]; // (slot, node)
    while let Some((s, o)) = stack.pop() {
        let sl = &slots[s];
        let node = &mut nodes[o];
        node.min = sl.min;
        node.max = sl.max;
        node.count = sl.count;
        if sl.count > 0 {
            node.index = sl.index;
            continue;
        }
        let pair = nodes.len();
        nodes[o].index = pair as u32;
        nodes.push(Node::default());
        nodes.push(Node::default());
        stack.push((sl.index as usize, pair + 1));
        stack.push((s + 1, pair));
    }
    nodes
}

#[cfg(test)]
mod tests {
    use crate::build_tree;
    use bvh_format::tree::{check_shape, stats};
    use bvh_format::{BuildParams, Strategy, Tree};
    use glam::Vec3;

    fn params(strategy: Strategy, bins: u32, max_leaf_size: u32) -> BuildParams {
        BuildParams { strategy, bins, max_leaf_size, ..BuildParams::default() }
    }

    /// A deterministic pseudo-random soup of small triangles in a 10-unit cube.
    fn soup(n: usize) -> Vec<[Vec3; 3]> {
        let mut seed = 12345u32;
        let mut rnd = || {
            seed ^= seed << 13;
            seed ^= seed >> 17;
            seed ^= seed << 5;
            seed as f32 / u32::MAX as f32
        };
        (0..n)
            .map(|_| {
                let c = Vec3::new(rnd(), rnd(), rnd()) * 10.0;
                [c, c + Vec3::new(rnd(), rnd(), rnd()) * 0.3, c + Vec3::new(rnd(), rnd(), rnd()) * 0.3]
            })
            .collect()
    }

    fn check(tris: &[[Vec3; 3]], p: &BuildParams) -> bvh_format::TreeStats {
        let t = build_tree(tris, p).expect("builds");
        check_shape(Tree::child_pair(&t.nodes), tris.len() as u32).expect("valid tree");
        let mut order = t.order.clone();
        order.sort_unstable();
        assert!(order.iter().enumerate().all(|(i, &o)| i as u32 == o), "leaf order is a permutation");
        stats(Tree::child_pair(&t.nodes), p.traversal_cost, p.intersection_cost)
    }

    #[test]
    fn identical_triangles_end_in_leaves_no_larger_than_allowed() {
        let t = [Vec3::ZERO, Vec3::X, Vec3::Y];
        let tris = vec![t; 1000];
        for strategy in [Strategy::Binned, Strategy::Sweep] {
            let s = check(&tris, &params(strategy, 16, 4));
            assert!(s.leaf_sizes.len() <= 5, "{:?}", s.leaf_sizes);
            // Median splits of 1000 items: depth ceil(log2(1000 / 4)) = 8.
            assert!(s.max_depth <= 8, "{}", s.max_depth);
        }
    }

    #[test]
    fn below_the_depth_limit_splits_are_medians_and_depth_stays_bounded() {
        let tris = soup(4000);
        let free = check(&tris, &params(Strategy::Binned, 16, 1));
        let limit = 3;
        assert!(free.max_depth > limit, "the soup is meant to be deeper than the limit");
        let mut refs = super::prim_refs(&tris);
        let costs = super::Costs { traversal: 1.0, intersection: 1.0, max_leaf_size: 1, depth_limit: limit };
        let t = super::build(&mut refs, &crate::binned::BinnedSah { bins: 16, costs }, costs, None);
        check_shape(Tree::child_pair(&t.nodes), tris.len() as u32).expect("valid tree");
        let s = stats(Tree::child_pair(&t.nodes), 1.0, 1.0);
        // Median splits halve the count: at most ceil(log2(4000)) = 12 more levels, and a tree of
        // SAH splits this shallow would have to be perfectly balanced.
        assert!(s.max_depth <= limit + 12, "depth {}", s.max_depth);
        assert!(s.sah_cost > free.sah_cost, "median levels cost more than SAH ones");
        assert_eq!(s.leaf_count, 4000);
    }

    #[test]
    fn binning_with_more_bins_than_triangles_is_the_sweep() {
        let tris: Vec<[Vec3; 3]> = (0..40)
            .map(|i| {
                let x = ((i * 37) % 40) as f32;
                let y = ((i * 11) % 7) as f32;
                [Vec3::new(x, y, 0.0), Vec3::new(x + 1.5, y, 0.3), Vec3::new(x, y + 0.7, 1.0)]
            })
            .collect();
        let a = build_tree(&tris, &params(Strategy::Binned, 64, 4)).unwrap();
        let b = build_tree(&tris, &params(Strategy::Sweep, 16, 4)).unwrap();
        assert_eq!(a.nodes, b.nodes);
        assert_eq!(a.order, b.order);
    }

    #[test]
    fn a_floor_under_small_objects_is_split_off_as_the_sweep_does() {
        // Two floor triangles whose box centres lie among the objects' lowest centroids: no bin
        // plane separates them, the large-triangle candidate does.
        let mut tris = soup(4000);
        for t in &mut tris {
            for v in t.iter_mut() {
                *v = *v * 0.02 + Vec3::new(-0.1, 0.0, -0.1);
            }
        }
        let y = tris.iter().flatten().map(|v| v.y).fold(f32::INFINITY, f32::min);
        let (a, b, c, d) =
            (Vec3::new(-1.0, y, -1.0), Vec3::new(1.0, y, -1.0), Vec3::new(1.0, y, 1.0), Vec3::new(-1.0, y, 1.0));
        tris.push([a, b, c]);
        tris.push([a, c, d]);
        let sweep = check(&tris, &params(Strategy::Sweep, 16, 8)).sah_cost;
        let binned = check(&tris, &params(Strategy::Binned, 16, 8)).sah_cost;
        assert!(binned <= sweep * 1.02, "binned {binned} vs sweep {sweep}");
    }

    #[test]
    fn flat_huge_and_tiny_scenes_build() {
        for scale in [1e-30f32, 1.0, 1e30] {
            let tris: Vec<[Vec3; 3]> = (0..500)
                .map(|i| {
                    let x = (i % 25) as f32 * scale;
                    let y = (i / 25) as f32 * scale;
                    [Vec3::new(x, y, 0.0), Vec3::new(x + scale, y, 0.0), Vec3::new(x, y + scale, 0.0)]
                })
                .collect();
            for strategy in [Strategy::Binned, Strategy::Sweep] {
                let s = check(&tris, &params(strategy, 8, 4));
                assert!(s.sah_cost.is_finite(), "scale {scale}: SAH {}", s.sah_cost);
            }
        }
    }

    #[test]
    fn more_bins_do_not_make_a_random_scene_much_worse() {
        // The 16-bin tree must be within 5% of the sweep.
        let tris = soup(5000);
        let sweep = check(&tris, &params(Strategy::Sweep, 16, 8)).sah_cost;
        let binned = check(&tris, &params(Strategy::Binned, 16, 8)).sah_cost;
        assert!(binned <= sweep * 1.05, "binned {binned} vs sweep {sweep}");
        assert!(binned >= sweep * 0.95, "binned {binned} vs sweep {sweep}: sweep should be near-optimal");
    }
}
