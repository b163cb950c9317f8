//! Walking, checking and measuring the two node layouts.
//!
//! Both layouts hold the same binary tree. In the child-pair layout the root is node 0 and an inner
//! node's children are `index` and `index + 1`. In the escape-pointer layout the nodes are in
//! depth-first order (left subtree first): an inner node's left child is the next node, and its
//! `index` is the first node after its subtree; after a leaf the next node is simply the next one.

use crate::error::{FormatError, LayoutKind};
use crate::types::Node;
use std::sync::atomic::AtomicBool;
use std::sync::atomic::Ordering::Relaxed;

/// A read-only view of one layout, enough to walk the tree top-down.
#[derive(Clone, Copy)]
pub struct Tree<'a> {
    pub nodes: &'a [Node],
    pub layout: LayoutKind,
}

impl<'a> Tree<'a> {
    pub fn child_pair(nodes: &'a [Node]) -> Self {
        Self { nodes, layout: LayoutKind::ChildPair }
    }
    pub fn escape(nodes: &'a [Node]) -> Self {
        Self { nodes, layout: LayoutKind::Escape }
    }

    /// The children of inner node `i`. Only meaningful on a validated tree.
    pub fn children(&self, i: usize) -> (usize, usize) {
        let n = &self.nodes[i];
        match self.layout {
            LayoutKind::ChildPair => (n.index as usize, n.index as usize + 1),
            LayoutKind::Escape => (i + 1, self.subtree_end(i + 1)),
        }
    }

    /// Escape layout only: the first node after the subtree rooted at `i`.
    fn subtree_end(&self, i: usize) -> usize {
        let n = &self.nodes[i];
        if n.is_leaf() { i + 1 } else { n.index as usize }
    }

    /// Visits every node depth-first, left child first, with its depth (the root has depth 0).
    /// Uses an explicit stack, so a deep tree cannot overflow the thread's stack.
    pub fn for_each_depth_first(&self, f: impl FnMut(usize, u32)) {
        if !self.nodes.is_empty() {
            self.for_each_depth_first_from(0, 0, f);
        }
    }

    /// [`Self::for_each_depth_first`] over the subtree of node `root`, which lies at `depth`.
    pub fn for_each_depth_first_from(&self, root: usize, depth: u32, mut f: impl FnMut(usize, u32)) {
        let mut stack = vec![(root, depth)];
        while let Some((i, depth)) = stack.pop() {
            f(i, depth);
            if !self.nodes[i].is_leaf() {
                let (l, r) = self.children(i);
                stack.push((r, depth + 1));
                stack.push((l, depth + 1));
            }
        }
    }
}

/// Measurements of a tree, as `bvhc info` prints them.
#[derive(Clone, Debug, PartialEq)]
pub struct TreeStats {
    pub node_count: u32,
    pub leaf_count: u32,
    /// Depth of the deepest node; the root has depth 0. A traversal stack that holds one entry per
    /// level below the root needs at most this many entries.
    pub max_depth: u32,
    pub mean_leaf_depth: f64,
    /// `leaf_sizes[k]` is the number of leaves with `k` triangles.
    pub leaf_sizes: Vec<u32>,
    /// The SAH cost of the finished tree, normalised by the root's surface area:
    /// `sum(inner) Ct * A(n) / A(root) + sum(leaves) Ci * count * A(l) / A(root)`.
    pub sah_cost: f64,
}

/// Half the surface area of a box, in f64 so that huge scenes do not overflow.
pub fn half_area(min: [f32; 3], max: [f32; 3]) -> f64 {
    let d = [
        (max[0] as f64 - min[0] as f64).max(0.0),
        (max[1] as f64 - min[1] as f64).max(0.0),
        (max[2] as f64 - min[2] as f64).max(0.0),
    ];
    d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
}

/// Depth, leaf statistics and SAH cost of a tree that has passed [`check_shape`]. The subtrees
/// below the top [`STATS_SPLIT`] levels are measured as tasks of their own on rayon's pool (the
/// reader runs this once per layout: for the dragon 12-16 ms each on one thread of the H100
/// machine's host, 1.4 ms on its 16, tracer-cpu's `examples/load_profile.rs`). The sums are the same whatever the threads: each task adds
/// up its subtree depth first, and a split node adds its own term, then its left subtree's sum,
/// then its right one's.
pub fn stats(tree: Tree<'_>, traversal_cost: f32, intersection_cost: f32) -> TreeStats {
    let root_area = tree.nodes.first().map(|r| half_area(r.min, r.max)).unwrap_or(0.0);
    // A flat or point-sized scene has zero area; then every node counts fully.
    let norm = if root_area > 0.0 && root_area.is_finite() { 1.0 / root_area } else { 0.0 };
    let costs = Costs { norm, traversal: traversal_cost as f64, intersection: intersection_cost as f64 };
    let sums = if tree.nodes.is_empty() { Sums::default() } else { sums(tree, &costs, 0, 0) };
    TreeStats {
        node_count: tree.nodes.len() as u32,
        leaf_count: sums.leaves,
        max_depth: sums.max_depth,
        mean_leaf_depth: if sums.leaves > 0 { sums.depth_sum as f64 / sums.leaves as f64 } else { 0.0 },
        leaf_sizes: sums.leaf_sizes,
        sah_cost: sums.cost,
    }
}

/// Tree levels whose nodes split [`stats`]'s walk into two tasks (up to 2^12 of them).
const STATS_SPLIT: u32 = 12;

/// The SAH's weights for [`stats`].
struct Costs {
    /// One over the root's half area (0 where it has none: every node then counts fully).
    norm: f64,
    traversal: f64,
    intersection: f64,
}

/// What [`stats`] adds up over a subtree.
#[derive(Default)]
struct Sums {
    leaves: u32,
    max_depth: u32,
    depth_sum: u64,
    leaf_sizes: Vec<u32>,
    cost: f64,
}

impl Sums {
    /// Node `n` at `depth`.
    fn add(&mut self, n: &Node, depth: u32, c: &Costs) {
        let rel = if c.norm > 0.0 { half_area(n.min, n.max) * c.norm } else { 1.0 };
        self.max_depth = self.max_depth.max(depth);
        if n.is_leaf() {
            self.leaves += 1;
            self.depth_sum += depth as u64;
            let k = n.count as usize;
            if self.leaf_sizes.len() <= k {
                self.leaf_sizes.resize(k + 1, 0);
            }
            self.leaf_sizes[k] += 1;
            self.cost += c.intersection * n.count as f64 * rel;
        } else {
            self.cost += c.traversal * rel;
        }
    }

    /// A subtree's sums after this one's.
    fn merge(&mut self, o: Sums) {
        self.leaves += o.leaves;
        self.max_depth = self.max_depth.max(o.max_depth);
        self.depth_sum += o.depth_sum;
        if self.leaf_sizes.len() < o.leaf_sizes.len() {
            self.leaf_sizes.resize(o.leaf_sizes.len(), 0);
        }
        for (a, b) in self.leaf_sizes.iter_mut().zip(o.leaf_sizes) {
            *a += b;
        }
        self.cost += o.cost;
    }
}

/// The sums of the subtree at node `i` (at `depth`): its root's two subtrees as tasks of their
/// own while it lies in the top [`STATS_SPLIT`] levels, else depth first on one thread.
fn sums(tree: Tree<'_>, c: &Costs, i: usize, depth: u32) -> Sums {
    let mut s = Sums::default();
    let n = &tree.nodes[i];
    if n.is_leaf() || depth >= STATS_SPLIT {
        tree.for_each_depth_first_from(i, depth, |j, d| s.add(&tree.nodes[j], d, c));
        return s;
    }
    s.add(n, depth, c);
    let (l, r) = tree.children(i);
    let (a, b) = rayon::join(|| sums(tree, c, l, depth + 1), || sums(tree, c, r, depth + 1));
    s.merge(a);
    s.merge(b);
    s
}

/// The escape-pointer layout of a child-pair tree: the same nodes in depth-first order.
pub fn escape_from_child_pair(nodes: &[Node]) -> Vec<Node> {
    let tree = Tree::child_pair(nodes);
    let mut out: Vec<Node> = Vec::with_capacity(nodes.len());
    // Indices into `out` of inner nodes whose subtree is still open, with the child-pair index of
    // their right child: when the walk reaches that child, the left subtree has ended.
    let mut open: Vec<usize> = Vec::new();
    tree.for_each_depth_first(|i, depth| {
        // Close every open subtree that is not an ancestor of `i`: with depth-first order the
        // ancestors are exactly the first `depth` entries of `open`.
        while open.len() > depth as usize {
            let j = open.pop().expect("open is longer than depth");
            out[j].index = out.len() as u32;
        }
        let mut n = nodes[i];
        if !n.is_leaf() {
            open.push(out.len());
            n.index = 0;
        }
        out.push(n);
    });
    while let Some(j) = open.pop() {
        out[j].index = out.len() as u32;
    }
    out
}

fn check_bounds(layout: LayoutKind, nodes: &[Node]) -> Result<(), FormatError> {
    for (i, n) in nodes.iter().enumerate() {
        if n.min.iter().chain(n.max.iter()).any(|v| !v.is_finite()) {
            let section = match layout {
                LayoutKind::ChildPair => crate::SectionKind::NodesChildPair,
                LayoutKind::Escape => crate::SectionKind::NodesEscape,
            };
            return Err(FormatError::NonFinite { section, index: i as u64 });
        }
        if (0..3).any(|k| n.min[k] > n.max[k]) {
            return Err(FormatError::InvertedBounds { layout, node: i as u32 });
        }
    }
    Ok(())
}

fn inside(child: &Node, parent: &Node) -> bool {
    (0..3).all(|k| child.min[k] >= parent.min[k] && child.max[k] <= parent.max[k])
}

/// Checks that `nodes` form one binary tree in the given layout whose leaves reference every one
/// of `triangle_count` triangles exactly once, with finite bounds that nest. Runs in linear time and
/// memory and never recurses, so a hostile file cannot exhaust the stack.
pub fn check_shape(tree: Tree<'_>, triangle_count: u32) -> Result<(), FormatError> {
    if shape_is_sound(tree, triangle_count) {
        return Ok(());
    }
    check_shape_serially(tree, triangle_count)
}

/// [`check_shape`] on one thread, rule by rule: the error it returns is the one reported.
fn check_shape_serially(tree: Tree<'_>, triangle_count: u32) -> Result<(), FormatError> {
    let nodes = tree.nodes;
    let layout = tree.layout;
    let len = nodes.len();
    if len == 0 {
        return Err(FormatError::TreeShape { layout, node: 0, reason: "the layout has no nodes" });
    }
    if len > u32::MAX as usize {
        return Err(FormatError::TreeShape { layout, node: 0, reason: "too many nodes" });
    }
    check_bounds(layout, nodes)?;
    let shape = |node: usize, reason| FormatError::TreeShape { layout, node: node as u32, reason };

    // Leaves first: ranges in bounds.
    for (i, n) in nodes.iter().enumerate() {
        if n.is_leaf() && (n.index as u64 + n.count as u64) > triangle_count as u64 {
            return Err(shape(i, "its triangle range reaches past the last triangle"));
        }
    }

    match layout {
        LayoutKind::ChildPair => {
            // Every node reached exactly once from the root; children come after their parent,
            // which rules out cycles.
            let mut seen = vec![false; len];
            let mut stack = vec![0usize];
            seen[0] = true;
            let mut reached = 1usize;
            while let Some(i) = stack.pop() {
                let n = &nodes[i];
                if n.is_leaf() {
                    continue;
                }
                let l = n.index as usize;
                if l <= i {
                    return Err(shape(i, "its children do not come after it"));
                }
                if l + 1 >= len {
                    return Err(shape(i, "its child index is past the last node"));
                }
                for c in [l, l + 1] {
                    if seen[c] {
                        return Err(shape(i, "a child is shared with another node"));
                    }
                    if !inside(&nodes[c], n) {
                        return Err(FormatError::ChildOutsideParent { layout, node: c as u32 });
                    }
                    seen[c] = true;
                    reached += 1;
                    stack.push(c);
                }
            }
            if reached != len {
                let orphan = seen.iter().position(|s| !s).unwrap_or(0);
                return Err(shape(orphan, "it cannot be reached from the root"));
            }
        }
        LayoutKind::Escape => {
            let end = |j: usize| {
                if nodes[j].is_leaf() { j + 1 } else { nodes[j].index as usize }
            };
            if let Some((i, n)) = nodes.iter().enumerate().find(|(i, n)| !n.is_leaf() && n.index as usize <= *i) {
                return Err(FormatError::EscapeBackwards { node: i as u32, escape: n.index });
            }
            for (i, n) in nodes.iter().enumerate() {
                if n.is_leaf() {
                    continue;
                }
                let e = n.index as usize;
                if e > len {
                    return Err(shape(i, "its escape index is past the end of the layout"));
                }
                if e < i + 3 {
                    return Err(shape(i, "its subtree is too small to hold two children"));
                }
                // The left child spans [i+1, r); the right child must span exactly [r, e).
                let r = end(i + 1);
                if r <= i + 1 || r >= e {
                    return Err(shape(i, "its left subtree does not end inside its own subtree"));
                }
                if end(r) != e {
                    return Err(shape(i, "its right subtree does not end at its escape index"));
                }
                for c in [i + 1, r] {
                    if !inside(&nodes[c], n) {
                        return Err(FormatError::ChildOutsideParent { layout, node: c as u32 });
                    }
                }
            }
            if end(0) != len {
                return Err(shape(0, "the root's subtree does not span the whole layout"));
            }
        }
    }

    // Coverage: with the shape known to be a tree, every leaf is reached exactly once.
    let mut covered = vec![0u8; triangle_count as usize];
    for n in nodes.iter().filter(|n| n.is_leaf()) {
        for t in n.index..n.index + n.count {
            let c = &mut covered[t as usize];
            *c = c.saturating_add(1);
            if *c > 1 {
                return Err(FormatError::LeafCoverage { layout, triangle: t, times: *c as u32 });
            }
        }
    }
    if let Some(t) = covered.iter().position(|&c| c == 0) {
        return Err(FormatError::LeafCoverage { layout, triangle: t as u32, times: 0 });
    }
    Ok(())
}

/// Whether [`check_shape`] accepts `tree`, decided on every thread: each rule holds per node, and
/// the serial check's walk from the root is replaced by counting each node's parents. True only
/// where the serial check passes (every rule here is at least as strict), so where it is false the
/// serial check runs and names the error, the same error whatever the number of threads.
fn shape_is_sound(tree: Tree<'_>, triangle_count: u32) -> bool {
    use crate::par;
    let nodes = tree.nodes;
    let len = nodes.len();
    if len == 0 || len > u32::MAX as usize {
        return false;
    }
    let each_node = par::all(nodes, |_, n| {
        n.min.iter().chain(&n.max).all(|v| v.is_finite())
            && (0..3).all(|k| n.min[k] <= n.max[k])
            && (!n.is_leaf() || n.index as u64 + n.count as u64 <= triangle_count as u64)
    });
    if !each_node {
        return false;
    }
    let linked = if tree.layout == LayoutKind::ChildPair {
        // Every node but the root is the child of exactly one node, and children come after their
        // parent: following parents from any node ends at the root, so the root reaches every
        // node exactly once.
        let claimed = flags(len);
        par::all(nodes, |i, n| {
            let l = n.index as usize;
            n.is_leaf()
                || (l > i
                    && l + 1 < len
                    && [l, l + 1].iter().all(|&c| inside(&nodes[c], n) && !claimed[c].swap(true, Relaxed)))
        }) && par::all(&claimed[1..], |_, c| c.load(Relaxed))
    } else if tree.layout == LayoutKind::Escape {
        let end = |j: usize| if nodes[j].is_leaf() { j + 1 } else { nodes[j].index as usize };
        par::all(nodes, |i, n| {
            let e = n.index as usize;
            n.is_leaf()
                || (e > i && e <= len && e >= i + 3 && {
                    let r = end(i + 1);
                    r > i + 1 && r < e && end(r) == e && inside(&nodes[i + 1], n) && inside(&nodes[r], n)
                })
        }) && end(0) == len
    } else {
        false
    };
    if !linked {
        return false;
    }
    // Leaf ranges are in bounds (above) and do not wrap around u32.
    let covered = flags(triangle_count as usize);
    par::all(nodes, |_, n| {
        !n.is_leaf() || (n.index..n.index + n.count).all(|t| !covered[t as usize].swap(true, Relaxed))
    }) && par::all(&covered, |_, c| c.load(Relaxed))
}

/// `n` flags, all false, for the parallel checks.
fn flags(n: usize) -> Vec<AtomicBool> {
    (0..n).map(|_| AtomicBool::new(false)).collect()
}

/// Checks that an escape-pointer layout is the depth-first order of a child-pair layout (both
/// already shape-checked).
pub fn check_same_tree(child_pair: &[Node], escape: &[Node]) -> Result<(), FormatError> {
    if same_tree_in_parallel(child_pair, escape) {
        return Ok(());
    }
    check_same_tree_serially(child_pair, escape)
}

fn check_same_tree_serially(child_pair: &[Node], escape: &[Node]) -> Result<(), FormatError> {
    if child_pair.len() != escape.len() {
        return Err(FormatError::LayoutsDiffer(0));
    }
    let mut k = 0usize;
    let mut diff = None;
    Tree::child_pair(child_pair).for_each_depth_first(|i, _| {
        if diff.is_none() {
            let a = &child_pair[i];
            let b = &escape[k];
            if a.min != b.min || a.max != b.max || a.count != b.count || (a.is_leaf() && a.index != b.index) {
                diff = Some(k as u32);
            }
        }
        k += 1;
    });
    match diff {
        Some(k) => Err(FormatError::LayoutsDiffer(k)),
        None => Ok(()),
    }
}

/// Whether [`check_same_tree`] accepts the pair (both shape-checked), decided on every thread:
/// both trees are walked together, subtree against subtree. With every node equal the two
/// depth-first orders coincide, so this is the serial check's comparison; false sends the caller
/// to the serial check for the error.
fn same_tree_in_parallel(cp: &[Node], esc: &[Node]) -> bool {
    fn same(a: &Node, b: &Node) -> bool {
        a.min == b.min && a.max == b.max && a.count == b.count && (!a.is_leaf() || a.index == b.index)
    }
    /// Compares the subtrees at child-pair node `i` and escape node `k`, splitting the work
    /// between threads while a subtree is large and the recursion shallow (a valid tree may be a
    /// chain as long as the scene); below that, an explicit stack.
    fn walk(cp: &[Node], esc: &[Node], i: usize, k: usize, depth: u32) -> bool {
        let mut stack = vec![(i, k)];
        while let Some((i, k)) = stack.pop() {
            let (Some(a), Some(b)) = (cp.get(i), esc.get(k)) else { return false };
            if !same(a, b) {
                return false;
            }
            if a.is_leaf() {
                continue;
            }
            let l = a.index as usize;
            let Some(r) = esc.get(k + 1).map(|n| if n.is_leaf() { k + 2 } else { n.index as usize }) else {
                return false;
            };
            if stack.is_empty() && depth < 20 && (b.index as usize).saturating_sub(k) > 1 << 14 {
                let (x, y) = rayon::join(|| walk(cp, esc, l, k + 1, depth + 1), || walk(cp, esc, l + 1, r, depth + 1));
                if !(x && y) {
                    return false;
                }
                continue;
            }
            stack.push((l + 1, r));
            stack.push((l, k + 1));
        }
        true
    }
    cp.len() == esc.len() && !cp.is_empty() && walk(cp, esc, 0, 0, 0)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn leaf(lo: f32, hi: f32, first: u32, count: u32) -> Node {
        Node { min: [lo, 0.0, 0.0], count, max: [hi, 1.0, 1.0], index: first }
    }
    fn inner(lo: f32, hi: f32, index: u32) -> Node {
        Node { min: [lo, 0.0, 0.0], count: 0, max: [hi, 1.0, 1.0], index }
    }

    /// root -> (A, B); A -> (t0, t1); B is a leaf with t2..t4.
    fn sample() -> Vec<Node> {
        vec![inner(0.0, 4.0, 1), inner(0.0, 2.0, 3), leaf(2.0, 4.0, 2, 3), leaf(0.0, 1.0, 0, 1), leaf(1.0, 2.0, 1, 1)]
    }

    #[test]
    fn escape_layout_is_depth_first_with_subtree_ends() {
        let cp = sample();
        check_shape(Tree::child_pair(&cp), 5).unwrap();
        let esc = escape_from_child_pair(&cp);
        let order: Vec<(u32, u32)> = esc.iter().map(|n| (n.count, n.index)).collect();
        assert_eq!(order, vec![(0, 5), (0, 4), (1, 0), (1, 1), (3, 2)]);
        check_shape(Tree::escape(&esc), 5).unwrap();
        check_same_tree(&cp, &esc).unwrap();
        let a = stats(Tree::child_pair(&cp), 1.0, 1.0);
        let b = stats(Tree::escape(&esc), 1.0, 1.0);
        assert_eq!(a, b);
        assert_eq!(a.max_depth, 2);
        assert_eq!(a.leaf_count, 3);
        assert_eq!(a.leaf_sizes, vec![0, 2, 0, 1]);
    }

    /// A child-pair tree of `leaves` leaves (one triangle each) split unevenly (a third to the
    /// left), so that its subtrees reach below [`STATS_SPLIT`] at different depths; boxes of
    /// varied shapes, so that the SAH terms differ.
    fn uneven(leaves: u32) -> Vec<Node> {
        let mut nodes = vec![Node::default()];
        let mut todo = vec![(0usize, 0u32, leaves)];
        while let Some((at, first, count)) = todo.pop() {
            // Nested boxes: x over the node's triangles, y growing with their number.
            let (min, max) = ([first as f32, 0.0, 0.0], [(first + count) as f32, 1.0 + (count as f32).sqrt(), 1.0]);
            if count == 1 {
                nodes[at] = Node { min, count: 1, max, index: first };
                continue;
            }
            let left = (count / 3).max(1);
            let index = nodes.len();
            nodes[at] = Node { min, count: 0, max, index: index as u32 };
            nodes.extend([Node::default(), Node::default()]);
            todo.push((index, first, left));
            todo.push((index + 1, first + left, count - left));
        }
        nodes
    }

    /// The statistics in parallel: the same on one thread and on four, in both layouts, and the
    /// serial walk's (every count exactly, the SAH cost to a summation order's rounding).
    #[test]
    fn parallel_stats_are_the_serial_walks() {
        let cp = uneven(20_000);
        check_shape(Tree::child_pair(&cp), 20_000).unwrap();
        let esc = escape_from_child_pair(&cp);
        let tree = Tree::child_pair(&cp);
        let (mut leaves, mut depth_sum, mut max_depth, mut cost) = (0u32, 0u64, 0u32, 0f64);
        let root = half_area(cp[0].min, cp[0].max);
        tree.for_each_depth_first(|i, depth| {
            let n = &cp[i];
            max_depth = max_depth.max(depth);
            let rel = half_area(n.min, n.max) / root;
            if n.is_leaf() {
                (leaves, depth_sum) = (leaves + 1, depth_sum + depth as u64);
                cost += 2.0 * rel;
            } else {
                cost += rel;
            }
        });
        assert!(max_depth > STATS_SPLIT + 4, "the test needs subtrees below the split ({max_depth})");
        let on = |threads: usize, t: Tree<'_>| {
            let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a pool");
            pool.install(|| stats(t, 1.0, 2.0))
        };
        let s = on(1, tree);
        assert_eq!((s.leaf_count, s.max_depth, s.leaf_sizes.clone()), (leaves, max_depth, vec![0, leaves]));
        assert_eq!(s.mean_leaf_depth, depth_sum as f64 / leaves as f64);
        assert!((s.sah_cost - cost).abs() <= 1e-12 * cost, "{} against {cost}", s.sah_cost);
        assert_eq!(on(4, tree), s);
        assert_eq!(on(4, Tree::escape(&esc)), s);
        assert_eq!(on(1, Tree::escape(&esc)), s);
    }

    #[test]
    fn sah_cost_matches_hand_computation() {
        let cp = sample();
        // Half areas: root 4*1+1+4 = 9; A 2+1+2 = 5; B 5; leaves of width 1: 3 each.
        let s = stats(Tree::child_pair(&cp), 1.0, 2.0);
        let expect = (9.0 + 5.0) / 9.0 + 2.0 * (3.0 * 5.0 + 1.0 * 3.0 + 1.0 * 3.0) / 9.0;
        assert!((s.sah_cost - expect).abs() < 1e-12, "{} vs {}", s.sah_cost, expect);
    }

    #[test]
    fn shape_errors_are_detected() {
        let mut cp = sample();
        cp[1].index = 0; // child before parent
        assert!(matches!(check_shape(Tree::child_pair(&cp), 5), Err(FormatError::TreeShape { .. })));
        let mut cp = sample();
        cp[2].count = 2; // triangle 4 uncovered
        assert!(matches!(check_shape(Tree::child_pair(&cp), 5), Err(FormatError::LeafCoverage { times: 0, .. })));
        let mut cp = sample();
        cp[4].index = 0; // triangle 0 twice
        assert!(matches!(check_shape(Tree::child_pair(&cp), 5), Err(FormatError::LeafCoverage { times: 2, .. })));
        let mut cp = sample();
        cp[3].max[0] = 9.0; // leaf sticks out of its parent
        assert!(matches!(check_shape(Tree::child_pair(&cp), 5), Err(FormatError::ChildOutsideParent { .. })));
        let mut esc = escape_from_child_pair(&sample());
        esc[1].index = 0;
        assert!(matches!(check_shape(Tree::escape(&esc), 5), Err(FormatError::EscapeBackwards { node: 1, .. })));
        let mut esc = escape_from_child_pair(&sample());
        esc[1].index = 5;
        assert!(check_shape(Tree::escape(&esc), 5).is_err());
        let mut esc = escape_from_child_pair(&sample());
        esc[2].min[1] = f32::NAN;
        assert!(matches!(check_shape(Tree::escape(&esc), 5), Err(FormatError::NonFinite { .. })));
    }

    /// A balanced child-pair tree over `tris` triangles, leaves of one or two, each node's box
    /// spanning its triangles' numbers on x.
    fn balanced(tris: u32) -> Vec<Node> {
        let mut nodes = vec![leaf(0.0, 0.0, 0, 0)];
        let mut todo = vec![(0usize, 0u32, tris)];
        while let Some((i, a, b)) = todo.pop() {
            if b - a <= 2 {
                nodes[i] = leaf(a as f32, b as f32, a, b - a);
                continue;
            }
            let l = nodes.len();
            nodes[i] = inner(a as f32, b as f32, l as u32);
            nodes.extend([leaf(0.0, 0.0, 0, 0); 2]);
            todo.extend([(l, a, (a + b) / 2), (l + 1, (a + b) / 2, b)]);
        }
        nodes
    }

    /// One field of node `at` set to `value`: 0-1 count, 2 index, 3-4 the box on x.
    fn damage(nodes: &mut [Node], at: usize, field: u8, value: u32) {
        let len = nodes.len();
        let n = &mut nodes[at % len];
        match field {
            0 => n.count = value % 4,
            1 => n.count = value,
            2 => n.index = value % (len as u32 + 4),
            3 => n.min[0] = if value.is_multiple_of(7) { f32::NAN } else { (value % 100) as f32 },
            _ => n.max[0] = (value % 100) as f32,
        }
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig { cases: 2000, failure_persistence: None, ..Default::default() })]

        /// The parallel checks accept exactly what the serial ones accept: a valid tree, and a
        /// damaged one only where the damage left it valid (then the serial check names the error).
        #[test]
        fn parallel_checks_agree_with_the_serial_ones(tris in 1u32..300, damaged in 0usize..3, at in 0usize..1000, field in 0u8..5, value in 0u32..1000, at2 in 0usize..1000, value2 in 0u32..1000) {
            let mut cp = balanced(tris);
            let mut esc = escape_from_child_pair(&cp);
            proptest::prop_assert!(shape_is_sound(Tree::child_pair(&cp), tris));
            proptest::prop_assert!(shape_is_sound(Tree::escape(&esc), tris));
            proptest::prop_assert!(same_tree_in_parallel(&cp, &esc));
            match damaged {
                0 => {
                    damage(&mut cp, at, field, value);
                    damage(&mut cp, at2, field, value2);
                }
                1 => {
                    damage(&mut esc, at, field, value);
                    damage(&mut esc, at2, field, value2);
                }
                _ => {}
            }
            for t in [Tree::child_pair(&cp), Tree::escape(&esc)] {
                let serial = check_shape_serially(t, tris);
                proptest::prop_assert_eq!(shape_is_sound(t, tris), serial.is_ok(), "{:?}", serial);
                proptest::prop_assert_eq!(check_shape(t, tris), serial);
            }
            if check_shape(Tree::child_pair(&cp), tris).is_ok() && check_shape(Tree::escape(&esc), tris).is_ok() {
                let serial = check_same_tree_serially(&cp, &esc);
                proptest::prop_assert_eq!(same_tree_in_parallel(&cp, &esc), serial.is_ok());
                proptest::prop_assert_eq!(check_same_tree(&cp, &esc), serial);
            }
        }
    }

    #[test]
    fn large_trees_pass_the_parallel_checks() {
        // Large enough that the subtree comparison splits between threads.
        let cp = balanced(200_000);
        let esc = escape_from_child_pair(&cp);
        assert!(shape_is_sound(Tree::child_pair(&cp), 200_000));
        assert!(shape_is_sound(Tree::escape(&esc), 200_000));
        assert!(same_tree_in_parallel(&cp, &esc));
        let mut other = esc.clone();
        let last_leaf = other.iter().rposition(Node::is_leaf).unwrap();
        other[last_leaf].max[1] = 0.5;
        assert!(!same_tree_in_parallel(&cp, &other));
        assert_eq!(check_same_tree(&cp, &other), Err(FormatError::LayoutsDiffer(last_leaf as u32)));
    }

    #[test]
    fn single_leaf_tree_is_valid() {
        let cp = vec![leaf(0.0, 1.0, 0, 3)];
        check_shape(Tree::child_pair(&cp), 3).unwrap();
        let esc = escape_from_child_pair(&cp);
        assert_eq!(esc, cp);
        check_shape(Tree::escape(&esc), 3).unwrap();
        assert_eq!(stats(Tree::escape(&esc), 1.0, 1.0).max_depth, 0);
    }
}
