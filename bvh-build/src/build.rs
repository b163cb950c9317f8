//! The top-down build shared by both SAH builders: recursion, leaf decisions, fallbacks for
//! degenerate input, rayon parallelism, and the final child-pair layout. A [`Splitter`] (binned or
//! sweep) only decides where to split one node.

use bvh_format::Node;
use glam::Vec3A;

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

/// Per-triangle data every builder reads.
pub struct Primitives {
    pub bounds: Vec<Aabb>,
    /// Centre of each triangle's box: what the builders sort and bin by.
    pub centroids: Vec<Vec3A>,
}

impl Primitives {
    pub fn from_triangles(positions: &[[glam::Vec3; 3]]) -> Self {
        use rayon::prelude::*;
        let bounds: Vec<Aabb> = positions
            .par_iter()
            .map(|t| {
                let (a, b, c) = (Vec3A::from(t[0]), Vec3A::from(t[1]), Vec3A::from(t[2]));
                Aabb { min: a.min(b).min(c), max: a.max(b).max(c) }
            })
            .collect();
        let centroids = bounds.par_iter().map(|b| b.min * 0.5 + b.max * 0.5).collect();
        Primitives { bounds, centroids }
    }

    pub fn len(&self) -> usize {
        self.bounds.len()
    }

    pub fn is_empty(&self) -> bool {
        self.bounds.is_empty()
    }

    /// Box and centroid box of a set of primitives.
    pub fn bounds_of(&self, prims: &[u32]) -> NodeBounds {
        let mut nb = NodeBounds { aabb: Aabb::EMPTY, centroids: Aabb::EMPTY };
        for &p in prims {
            nb.aabb.grow(&self.bounds[p as usize]);
            nb.centroids.grow_point(self.centroids[p as usize]);
        }
        nb
    }
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
    /// Reorders `prims` and returns the split with the lowest SAH cost, or `None` when no split
    /// separates the primitives or, if `may_leaf`, when a leaf is cheaper than the best split.
    fn split(&self, prims: &mut [u32], bounds: &NodeBounds, may_leaf: bool) -> Option<Split>;
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
    prims: &'a Primitives,
    splitter: &'a S,
    costs: Costs,
}

/// Builds a tree over every primitive with the given splitter.
pub fn build<S: Splitter>(prims: &Primitives, splitter: &S, costs: Costs) -> BuiltTree {
    let n = prims.len();
    assert!(n > 0 && n < u32::MAX as usize / 2, "the compiler rejects empty and oversized scenes before building");
    let mut order: Vec<u32> = (0..n as u32).collect();
    let mut slots = vec![Slot::default(); 2 * n - 1];
    let root = prims_bounds_parallel(prims);
    let ctx = Ctx { prims, splitter, costs };
    build_node(&ctx, &mut order, 0, &mut slots, 0, root, 0);
    BuiltTree { nodes: flatten(&slots), order }
}

fn prims_bounds_parallel(prims: &Primitives) -> NodeBounds {
    use rayon::prelude::*;
    let empty = NodeBounds { aabb: Aabb::EMPTY, centroids: Aabb::EMPTY };
    (0..prims.len())
        .into_par_iter()
        .with_min_len(16384)
        .fold(
            || empty,
            |mut nb, i| {
                nb.aabb.grow(&prims.bounds[i]);
                nb.centroids.grow_point(prims.centroids[i]);
                nb
            },
        )
        .reduce(|| empty, |a, b| NodeBounds { aabb: a.aabb.union(&b.aabb), centroids: a.centroids.union(&b.centroids) })
}

fn build_node<S: Splitter>(
    ctx: &Ctx<'_, S>,
    prims: &mut [u32],
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
    } else if depth >= DEPTH_LIMIT {
        if may_leaf { None } else { Some(median_split(ctx.prims, prims, &bounds)) }
    } else {
        match ctx.splitter.split(prims, &bounds, may_leaf) {
            Some(s) => Some(s),
            None if may_leaf => None,
            None => Some(median_split(ctx.prims, prims, &bounds)),
        }
    };
    let here = &mut slots[0];
    here.min = bounds.aabb.min.into();
    here.max = bounds.aabb.max.into();
    let Some(split) = split else {
        here.count = n as u32;
        here.index = first as u32;
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
pub fn median_split(p: &Primitives, prims: &mut [u32], bounds: &NodeBounds) -> Split {
    let mid = prims.len() / 2;
    let ext = bounds.centroids.extent();
    if ext.max_element() > 0.0 {
        let axis = ext.max_position();
        prims.select_nth_unstable_by(mid, |&a, &b| {
            p.centroids[a as usize][axis].total_cmp(&p.centroids[b as usize][axis])
        });
    }
    Split { mid, left: p.bounds_of(&prims[..mid]), right: p.bounds_of(&prims[mid..]) }
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
