//! Reinsertion in the top of the finished tree (Bittner, Hapala and Havran 2013, "Fast
//! insertion-based optimization of bounding volume hierarchies", restricted to a treelet).
//!
//! Top-down SAH decides each split alone, by the children's boxes and counts, and cannot see how
//! the children will be split in turn. Where a few large triangles meet many small ones this goes
//! wrong near the root: in `scenes/room.toml` the large-triangle candidate sends the floor, the
//! ceiling and the four walls one way and the objects and the mirror the other (the cheaper split
//! by the SAH), after which the mirror widens every box of the objects' side and the floor costs
//! the walls' side one more room-sized node. No bin count or resolution changes that choice
//! (docs/build-benchmark.md). Moving such a subtree afterwards is cheap: the top of the tree is
//! cut into [`top_units`] subtrees (the largest boxes opened first), and each node of that treelet is
//! taken out and put back as the sibling of whichever treelet node makes the sum of the inner
//! nodes' areas smallest, while that sum falls. The units' own subtrees do not change, so this
//! sum is the whole SAH cost of the tree up to a constant: no move ever raises the cost.
//!
//! Everything here is serial and on at most 511 nodes (half a millisecond); it depends only on
//! the built tree, not on the number of threads. Only the reinsertion's search is pruned (from
//! the cost of putting the node back), not its choice: the result is that of trying every place.

use crate::build::{Aabb, SlotId, Slots};
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Subtrees the top of a tree over `n` primitives is cut into for the reinsertion: one per 1,024
/// primitives, at least 64 (the room's walls, mirror and objects need a few dozen) and at most
/// 256. A pass costs about a microsecond per unit (AMD EPYC, one thread), serial, so the treelet
/// grows with the build it rides on: 256 units made the generated city 14.44 (128: 15.16, 512:
/// 13.89), about 0.5 ms, where the build of a million triangles takes 600 ms of CPU time.
pub(crate) fn top_units(n: usize) -> usize {
    (n / 1024).clamp(64, 256)
}

/// Passes over the treelet's nodes at most; each pass that moves nothing ends the search.
const ROUNDS: usize = 4;

const NONE: u32 = u32::MAX;

#[derive(Clone, Copy)]
struct TNode {
    bbox: Aabb,
    area: f64,
    parent: u32,
    /// Children of an inner treelet node; `NONE` for a unit.
    kids: [u32; 2],
    /// A unit's slot, first primitive (in the build's leaf order) and primitive count.
    slot: SlotId,
    first: u32,
    count: u32,
    /// Height of the whole tree below this node (a leaf's is 0).
    height: u32,
}

impl TNode {
    fn is_unit(&self) -> bool {
        self.kids[0] == NONE
    }
}

/// The top of a built tree as a treelet over units (subtrees of the gapped slot array).
pub(crate) struct Top {
    nodes: Vec<TNode>,
    root: u32,
    /// The tree's depth as built: no move may make it deeper (the build's depth bound, and the
    /// GPU's stacks, sized by the depth, hold).
    limit: u32,
    /// Per treelet node after [`Top::prepare`]: the nodes of its subtree in the finished tree.
    subtree: Vec<u32>,
    /// Per unit after [`Top::prepare`]: how far its leaves' triangle ranges move in the new leaf
    /// order (wrapping).
    shift: Vec<u32>,
}

/// A unit waiting to be opened, largest box first, earliest node on ties.
struct Open(f64, u32);

impl PartialEq for Open {
    fn eq(&self, o: &Open) -> bool {
        self.cmp(o) == Ordering::Equal
    }
}
impl Eq for Open {}
impl PartialOrd for Open {
    fn partial_cmp(&self, o: &Open) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Open {
    fn cmp(&self, o: &Open) -> Ordering {
        self.0.total_cmp(&o.0).then(o.1.cmp(&self.1))
    }
}

/// A node of the finished tree while the layouts are written: a slot, with the shift of its
/// leaves' triangle ranges (nonzero below a reshaped top), or an inner node of the reshaped top.
#[derive(Clone, Copy)]
pub(crate) enum At {
    Slot(SlotId, u32),
    Top(u32),
}

impl Top {
    /// Cuts the tree in `slots` (over `n` primitives) into at most `units` subtrees, opening the
    /// inner node with the largest box first.
    pub(crate) fn extract(slots: &Slots, n: usize, units: usize) -> Top {
        let unit = |s: SlotId, first: usize, count: usize, parent: u32| {
            let sl = slots.get(s);
            let bbox = Aabb { min: sl.min.into(), max: sl.max.into() };
            // An inner slot keeps its height where a leaf keeps its count.
            let height = if sl.nodes == 1 { 0 } else { sl.count };
            TNode {
                bbox,
                area: bbox.half_area(),
                parent,
                kids: [NONE; 2],
                slot: s,
                first: first as u32,
                count: count as u32,
                height,
            }
        };
        let mut nodes = vec![unit(SlotId::ROOT, 0, n, NONE)];
        let mut open = BinaryHeap::new();
        if slots.children(SlotId::ROOT).is_some() {
            open.push(Open(nodes[0].area, 0));
        }
        let mut count = 1;
        while count < units {
            let Some(Open(_, id)) = open.pop() else { break };
            let t = nodes[id as usize];
            let (l, r) = slots.children(t.slot).expect("only inner nodes are opened");
            // The right subtree's primitives follow the left one's in the leaf order.
            let (first, total) = (t.first as usize, t.count as usize);
            let mid = slots.first_primitive(r) as usize - first;
            for (slot, f, c) in [(l, first, mid), (r, first + mid, total - mid)] {
                let k = nodes.len() as u32;
                nodes.push(unit(slot, f, c, id));
                if slots.children(slot).is_some() {
                    open.push(Open(nodes[k as usize].area, k));
                }
            }
            let k = nodes.len() as u32;
            nodes[id as usize].kids = [k - 2, k - 1];
            count += 1;
        }
        let limit = nodes[0].height;
        Top { nodes, root: 0, limit, subtree: Vec::new(), shift: Vec::new() }
    }

    /// Reinserts treelet nodes while that lowers the sum of the inner nodes' areas; whether any
    /// moved.
    pub(crate) fn optimise(&mut self) -> bool {
        // Moves must gain more than rounding: the sums run over a few hundred areas.
        let tol = self.nodes[self.root as usize].area * 1e-9;
        let mut moved = false;
        for _ in 0..ROUNDS {
            let mut any = false;
            for x in 0..self.nodes.len() as u32 {
                if x != self.root {
                    any |= self.reinsert(x, tol);
                }
            }
            moved |= any;
            if !any {
                break;
            }
        }
        moved
    }

    /// Takes `x` out (its sibling takes its parent's place) and puts it back where it costs the
    /// least; true if that is somewhere else and cheaper by more than `tol`.
    fn reinsert(&mut self, x: u32, tol: f64) -> bool {
        let p = self.nodes[x as usize].parent;
        let kids = self.nodes[p as usize].kids;
        let side = usize::from(kids[1] == x);
        let sibling = kids[1 - side];
        let g = self.nodes[p as usize].parent;
        self.replace(g, p, sibling);
        let gain = self.nodes[p as usize].area + self.refit(g);
        // Only places cheaper than putting x back count: that bound prunes most of the search.
        let (_, y) = self.best_sibling(x, gain - tol, self.limit);
        let better = y != NONE;
        let (at, pair) = if better {
            (y, [y, x])
        } else {
            let mut pair = [sibling; 2];
            pair[side] = x;
            (sibling, pair)
        };
        let gy = self.nodes[at as usize].parent;
        self.replace(gy, at, p);
        self.nodes[p as usize].parent = gy;
        self.nodes[p as usize].kids = pair;
        self.nodes[at as usize].parent = p;
        self.nodes[x as usize].parent = p;
        // p's stored box is from its old place: set it, then grow its ancestors as needed.
        let bbox = self.nodes[at as usize].bbox.union(&self.nodes[x as usize].bbox);
        let height = 1 + self.nodes[at as usize].height.max(self.nodes[x as usize].height);
        let n = &mut self.nodes[p as usize];
        (n.bbox, n.area, n.height) = (bbox, bbox.half_area(), height);
        self.refit(gy);
        better
    }

    /// Puts `new` where `old` was among `parent`'s children (or at the root).
    fn replace(&mut self, parent: u32, old: u32, new: u32) {
        if parent == NONE {
            self.root = new;
        } else {
            let k = &mut self.nodes[parent as usize].kids;
            let i = usize::from(k[1] == old);
            k[i] = new;
        }
        self.nodes[new as usize].parent = parent;
    }

    /// Recomputes the boxes and heights from `from` up, after one of its children changed, until
    /// one comes out as it was (the ones above it then hold already); returns how much their areas
    /// shrank.
    fn refit(&mut self, mut from: u32) -> f64 {
        let mut shrunk = 0.0;
        while from != NONE {
            let [a, b] = self.nodes[from as usize].kids;
            let bbox = self.nodes[a as usize].bbox.union(&self.nodes[b as usize].bbox);
            let height = 1 + self.nodes[a as usize].height.max(self.nodes[b as usize].height);
            let n = &mut self.nodes[from as usize];
            if bbox == n.bbox && height == n.height {
                break;
            }
            n.height = height;
            let area = bbox.half_area();
            shrunk += n.area - area;
            n.bbox = bbox;
            n.area = area;
            from = n.parent;
        }
        shrunk
    }

    /// The node whose new sibling `x` (out of the tree) adds the least area, the new parent's area
    /// plus the growth of every ancestor, and that area (branch and bound from the root); `NONE`
    /// if no place adds less than `bound`. Places where the tree would grow deeper than `limit`
    /// are not taken.
    fn best_sibling(&self, x: u32, bound: f64, limit: u32) -> (f64, u32) {
        let xb = self.nodes[x as usize].bbox;
        let (x_area, x_height) = (self.nodes[x as usize].area, self.nodes[x as usize].height);
        let mut best = (bound, NONE);
        let mut stack = vec![(self.root, 0.0f64, 0u32)];
        while let Some((y, above, depth)) = stack.pop() {
            let n = &self.nodes[y as usize];
            let joined = n.bbox.union(&xb).half_area();
            // The new parent takes y's place: y and x go one level down.
            if above + joined < best.0 && depth + 1 + n.height.max(x_height) <= limit {
                best = (above + joined, y);
            }
            let below = above + joined - n.area;
            if !n.is_unit() && below + x_area < best.0 {
                stack.push((n.kids[1], below, depth + 1));
                stack.push((n.kids[0], below, depth + 1));
            }
        }
        best
    }

    /// Counts each treelet node's subtree in the finished tree and gives each unit its place in
    /// the new leaf order (units depth-first, left first); returns the units' ranges of the
    /// build's leaf order `(first, count)` in the new order, which the caller copies.
    pub(crate) fn prepare(&mut self, slots: &Slots) -> Vec<(u32, u32)> {
        self.subtree = vec![0; self.nodes.len()];
        self.shift = vec![0; self.nodes.len()];
        let mut ranges = Vec::new();
        let mut next = 0u32;
        // Post-order by an explicit stack: (node, children done).
        let mut stack = vec![(self.root, false)];
        while let Some((t, done)) = stack.pop() {
            let n = self.nodes[t as usize];
            if n.is_unit() {
                self.subtree[t as usize] = slots.get(n.slot).nodes;
                self.shift[t as usize] = next.wrapping_sub(n.first);
                ranges.push((n.first, n.count));
                next += n.count;
            } else if done {
                self.subtree[t as usize] = 1 + self.subtree[n.kids[0] as usize] + self.subtree[n.kids[1] as usize];
            } else {
                stack.push((t, true));
                stack.push((n.kids[1], false));
                stack.push((n.kids[0], false));
            }
        }
        ranges
    }

    pub(crate) fn root(&self) -> At {
        self.child(self.root)
    }

    fn child(&self, t: u32) -> At {
        let n = &self.nodes[t as usize];
        if n.is_unit() { At::Slot(n.slot, self.shift[t as usize]) } else { At::Top(t) }
    }

    /// An inner treelet node's box, subtree size (after [`Top::prepare`]) and children.
    pub(crate) fn inner(&self, t: u32) -> (Aabb, u32, At, At) {
        let n = &self.nodes[t as usize];
        (n.bbox, self.subtree[t as usize], self.child(n.kids[0]), self.child(n.kids[1]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3A;

    /// A treelet over `units` random boxes, joined in random pairs (so of random shape).
    fn random_top(rng: &mut ::tests::Rng, units: usize) -> Top {
        let mut nodes = Vec::new();
        let mut free: Vec<u32> = Vec::new();
        for i in 0..units {
            let c = Vec3A::new(rng.unit(), rng.unit(), rng.unit()) * 10.0;
            // Some large boxes among many small ones, as where the reinsertion matters.
            let size = if i % 7 == 0 { 8.0 } else { 0.5 };
            let e = Vec3A::new(rng.unit(), rng.unit(), rng.unit()) * size;
            let bbox = Aabb { min: c - e, max: c + e };
            // Units of different heights, so that the depth limit binds somewhere.
            let height = (rng.unit() * 4.0) as u32;
            let n = TNode {
                bbox,
                area: bbox.half_area(),
                parent: NONE,
                kids: [NONE; 2],
                slot: SlotId::ROOT,
                first: 0,
                count: 1,
                height,
            };
            nodes.push(n);
            free.push(i as u32);
        }
        while free.len() > 1 {
            let a = free.swap_remove((rng.unit() * free.len() as f32) as usize % free.len());
            let b = free.swap_remove((rng.unit() * free.len() as f32) as usize % free.len());
            let bbox = nodes[a as usize].bbox.union(&nodes[b as usize].bbox);
            let k = nodes.len() as u32;
            let height = 1 + nodes[a as usize].height.max(nodes[b as usize].height);
            nodes.push(TNode {
                bbox,
                area: bbox.half_area(),
                parent: NONE,
                kids: [a, b],
                slot: SlotId::ROOT,
                first: 0,
                count: 0,
                height,
            });
            nodes[a as usize].parent = k;
            nodes[b as usize].parent = k;
            free.push(k);
        }
        let limit = nodes[free[0] as usize].height;
        Top { root: free[0], nodes, limit, subtree: Vec::new(), shift: Vec::new() }
    }

    /// The sum of the inner nodes' areas, recomputed from the units' boxes; checks the links and
    /// that the stored boxes and heights are those of the children; returns the units reached
    /// and the tree's height too.
    fn cost(t: &Top) -> (f64, Vec<u32>, u32) {
        let mut units = Vec::new();
        let mut sum = 0.0;
        fn walk(t: &Top, at: u32, sum: &mut f64, units: &mut Vec<u32>) -> (Aabb, u32) {
            let n = &t.nodes[at as usize];
            if n.is_unit() {
                units.push(at);
                return (n.bbox, n.height);
            }
            for k in n.kids {
                assert_eq!(t.nodes[k as usize].parent, at, "child {k} of {at} points back");
            }
            let (a, ah) = walk(t, n.kids[0], sum, units);
            let (b, bh) = walk(t, n.kids[1], sum, units);
            let (b, h) = (a.union(&b), 1 + ah.max(bh));
            assert_eq!(b, n.bbox, "node {at} holds the union of its children");
            assert_eq!(h, n.height, "node {at} holds its height");
            *sum += b.half_area();
            (b, h)
        }
        assert_eq!(t.nodes[t.root as usize].parent, NONE);
        let (_, height) = walk(t, t.root, &mut sum, &mut units);
        units.sort_unstable();
        (sum, units, height)
    }

    fn copy(t: &Top) -> Top {
        Top { nodes: t.nodes.clone(), root: t.root, limit: t.limit, subtree: Vec::new(), shift: Vec::new() }
    }

    #[test]
    fn the_best_sibling_is_the_cheapest_place_tried_one_by_one() {
        let mut rng = ::tests::Rng(99);
        for trial in 0..40 {
            let top = random_top(&mut rng, 3 + trial % 30);
            for x in 0..top.nodes.len() as u32 {
                if x == top.root {
                    continue;
                }
                // Take x out as `reinsert` does.
                let mut out = copy(&top);
                let p = out.nodes[x as usize].parent;
                let kids = out.nodes[p as usize].kids;
                let sibling = if kids[0] == x { kids[1] } else { kids[0] };
                let g = out.nodes[p as usize].parent;
                out.replace(g, p, sibling);
                out.refit(g);
                let (without, ..) = cost(&out);
                // Brute force: every place, the whole cost recomputed.
                let mut places = Vec::new();
                let mut stack = vec![out.root];
                while let Some(y) = stack.pop() {
                    places.push(y);
                    if !out.nodes[y as usize].is_unit() {
                        stack.extend(out.nodes[y as usize].kids);
                    }
                }
                let tried: Vec<(f64, u32)> = places
                    .iter()
                    .map(|&y| {
                        let mut t = copy(&out);
                        let gy = t.nodes[y as usize].parent;
                        t.replace(gy, y, p);
                        t.nodes[p as usize].kids = [y, x];
                        t.nodes[y as usize].parent = p;
                        t.nodes[x as usize].parent = p;
                        let bbox = t.nodes[y as usize].bbox.union(&t.nodes[x as usize].bbox);
                        t.nodes[p as usize].bbox = bbox;
                        t.nodes[p as usize].area = bbox.half_area();
                        t.nodes[p as usize].height = 1 + t.nodes[y as usize].height.max(t.nodes[x as usize].height);
                        t.refit(gy);
                        let (c, _, h) = cost(&t);
                        (c, h)
                    })
                    .collect();
                // The brute force counts x's own inner nodes, which stay as they are.
                let inside = {
                    let mut sum = 0.0;
                    let mut stack = vec![x];
                    while let Some(y) = stack.pop() {
                        let n = &top.nodes[y as usize];
                        if !n.is_unit() {
                            sum += n.area;
                            stack.extend(n.kids);
                        }
                    }
                    sum
                };
                let scale = cost(&top).0;
                // With the tree's depth as the limit (putting x back always meets it) and without.
                for limit in [top.limit, u32::MAX] {
                    let (found, y) = out.best_sibling(x, f64::INFINITY, limit);
                    assert_ne!(y, NONE);
                    let brute = tried.iter().filter(|t| t.1 <= limit).map(|t| t.0).fold(f64::INFINITY, f64::min);
                    assert!(
                        (without + inside + found - brute).abs() <= 1e-9 * scale,
                        "trial {trial}, node {x}, limit {limit}: found {} against {brute}",
                        without + inside + found
                    );
                }
            }
        }
    }

    #[test]
    fn reinsertion_lowers_the_cost_and_keeps_every_unit() {
        let mut rng = ::tests::Rng(7);
        let mut lowered = 0;
        for trial in 0..60 {
            let mut top = random_top(&mut rng, 2 + trial % 50);
            let (before, units, height) = cost(&top);
            let moved = top.optimise();
            let (after, units_after, height_after) = cost(&top);
            assert_eq!(units, units_after, "trial {trial}");
            assert!(height_after <= height, "trial {trial}: the tree grew from {height} to {height_after} levels");
            assert!(after <= before * (1.0 + 1e-12), "trial {trial}: {after} > {before}");
            assert_eq!(moved, after < before, "trial {trial}: moved {moved}, {before} -> {after}");
            lowered += usize::from(moved);
        }
        assert!(lowered > 40, "random treelets are far from optimal: only {lowered} of 60 improved");
    }
}
