//! The collapse of the file's binary tree into a [`WideBvh`] (the module docs of `bvh8` say
//! which slots become what): a plan made bottom-up by dynamic programming ([`Plan`]), then the
//! arena written top-down in its order (each node, its children's leaf blocks, its inner
//! children's subtrees in slot order).
//!
//! Both passes run in parallel over subtrees on rayon's current pool where the tree is large
//! ([`Parallel::auto`]): the plan over the binary subtrees some levels below the root, then the
//! levels above them; the arena sized first ([`Collapse::sized`]), so that each of the wide
//! subtrees a few levels below the root is written into its own slice of it, by the same loop that
//! writes a whole tree on one thread. Every subtree gets the lines the one-thread collapse would
//! give it, so the arena is the same line for line whatever the threads
//! (`a_parallel_collapse_writes_the_serial_arena`). On one thread this was 0.09-0.13 s of every
//! load of the dragon on the H100 machine's host, where its 16 threads render a frame in 10 ms.

use super::{LEAF, Line, Simd, TriBlock, WideBvh, WideNode};
use crate::vertices::TriangleSource;
use bvh_format::Node;
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicU8, Ordering::Relaxed};

/// The SAH costs the collapse weighs, per unit of a box's area (the probability that a ray
/// enters it): testing a wide node's boxes ([`NODE_COST`]) and a leaf block's triangles
/// ([`BLOCK_COST`]), each one SIMD sequence whatever the number of lanes in use. A block loads 5
/// cache lines to a node's 4 and runs about three times the operations; 2 and 3 traced alike on
/// the 2-core VM, 1 was slower (docs/cpu-benchmark-log.md, "Issue 11: the SAH collapse").
pub(super) const NODE_COST: f32 = 1.0;
pub(super) const BLOCK_COST: f32 = 2.0;

/// Binary trees of fewer nodes are collapsed on one thread. A quarter of the bunny's 138,901
/// nodes, whose collapse takes 8-9 ms on one thread and 2.8 ms on 16 of the H100 machine's host:
/// below it a collapse takes about 2 ms on one thread, little for tasks to save (a judgement,
/// not measured).
const MIN_PARALLEL: usize = 1 << 15;

/// Half the surface area of a box, the SAH's measure of how likely a ray enters it.
pub(super) fn half_area(n: &Node) -> f32 {
    let d = [n.max[0] - n.min[0], n.max[1] - n.min[1], n.max[2] - n.min[2]];
    d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
}

/// How the collapse splits its work into tasks.
#[derive(Clone, Copy, Debug)]
pub(super) struct Parallel {
    /// The plan's tasks: the binary subtrees this many levels below the root (and the leaves
    /// above them), each planned on its own; 0 plans the whole tree as one.
    pub plan_depth: usize,
    /// The writing's tasks: the wide subtrees this many wide levels below the root, each written
    /// into its own slice; 0 writes the whole tree in one loop.
    pub write_levels: usize,
}

impl Parallel {
    /// Everything on one thread (what the collapse was until stop 51).
    #[cfg(test)]
    pub const SERIAL: Parallel = Parallel { plan_depth: 0, write_levels: 0 };

    /// For a binary tree of `nodes` nodes: on one thread below [`MIN_PARALLEL`]; else up to 1024
    /// plan tasks and (8-wide) up to 512 writing tasks, (4-wide) 256, enough for rayon to even out
    /// subtrees of unequal size on 16 threads.
    pub fn auto<const W: usize>(nodes: usize) -> Parallel {
        match nodes < MIN_PARALLEL {
            true => Parallel { plan_depth: 0, write_levels: 0 },
            false => Parallel { plan_depth: 10, write_levels: if W >= 8 { 3 } else { 4 } },
        }
    }
}

/// Lines of a wide node and of a leaf block in the arena.
const fn node_lines<const W: usize>() -> usize {
    size_of::<WideNode<W>>() / 64
}

const fn block_lines<const W: usize>() -> usize {
    size_of::<TriBlock<W>>() / 64
}

/// Collapses the child-pair tree `nodes` over the triangles `tris` (leaf order), splitting the
/// work as `par` says.
pub(super) fn collapse<const W: usize>(
    nodes: &[Node],
    tris: &(impl TriangleSource + ?Sized),
    par: Parallel,
) -> WideBvh<W> {
    // `valid` holds a bit per slot; a binary node opens into at least 2.
    const { assert!(W >= 2 && W <= 32) };
    let mut out = WideBvh { lines: Vec::new(), counts: (0, 0), root: LEAF, simd: Simd::detect(), depth: 0 };
    if nodes.is_empty() {
        out.lines = vec![Line::UNWRITTEN; block_lines::<W>()];
        out.root = Cursor { out: &mut out.lines, base: 0, at: 0 }.block::<W>(tris, &[]);
        out.counts = (0, 1);
        return out;
    }
    let c = Collapse { nodes, tris, plan: Plan::<W>::new(nodes, par.plan_depth) };
    let sized = c.sized(Work::Binary(0), par.write_levels);
    let total = sized.lines;
    assert!(total < LEAF as usize, "a wide BVH of fewer than 2^31 lines");
    let mut lines = Vec::with_capacity(total);
    bvh_format::memory::advise_huge_pages(lines.spare_capacity_mut(), super::HUGE_TREE);
    // Nothing written here: the pages are first touched by the tasks that write them.
    lines.resize(total, Line::UNWRITTEN);
    out.root = c.write_par(Work::Binary(0), &sized, &mut lines, 0);
    out.lines = lines;
    (out.depth, out.counts) = out.measure();
    out
}

impl<const W: usize> WideBvh<W> {
    /// The most wide nodes on a path from the root to a leaf block, and the nodes and blocks.
    fn measure(&self) -> (usize, (usize, usize)) {
        let (mut most, mut counts, mut todo) = (0, (0, 0), vec![(self.root, 0)]);
        while let Some((r, depth)) = todo.pop() {
            if r & LEAF != 0 {
                (most, counts.1) = (most.max(depth), counts.1 + 1);
                continue;
            }
            counts.0 += 1;
            let node = self.node(r);
            todo.extend((0..W).filter(|&i| node.valid & (1 << i) != 0).map(|i| (node.child[i], depth + 1)));
        }
        (most, counts)
    }
}

/// What the collapse still has to make: the wide subtree of a binary node, or of a range of
/// triangles of one binary leaf larger than a block (boxes then computed from the triangles).
#[derive(Clone, Copy)]
enum Work {
    Binary(u32),
    Range(u32, u32),
}

/// The collapse of one tree: its plan, and the rules that size and write its wide subtrees.
struct Collapse<'a, const W: usize, S: ?Sized> {
    nodes: &'a [Node],
    tris: &'a S,
    plan: Plan<W>,
}

impl<const W: usize, S: TriangleSource + ?Sized> Collapse<'_, W, S> {
    /// What `w` becomes in one slot: a leaf block, a wide node over runs of a large binary
    /// leaf's triangles, or a wide node over the binary subtree.
    fn kind(&self, w: Work) -> Kind {
        match w {
            Work::Binary(b) if self.plan.is_block(b) => Kind::Block,
            Work::Binary(b) if self.nodes[b as usize].is_leaf() => {
                let n = &self.nodes[b as usize];
                Kind::Range(n.index, n.count)
            }
            Work::Binary(b) => Kind::Node(b),
            Work::Range(_, count) if count as usize <= W => Kind::Block,
            Work::Range(start, count) => Kind::Range(start, count),
        }
    }

    /// Lines of the arena the wide subtree of `w` takes.
    fn lines(&self, w: Work) -> usize {
        let (mut sum, mut todo, mut kids) = (0, vec![w], Vec::with_capacity(W));
        while let Some(w) = todo.pop() {
            sum += match self.kind(w) {
                Kind::Block => block_lines::<W>(),
                Kind::Range(_, count) => range_lines::<W>(count),
                Kind::Node(b) => {
                    self.plan.children(self.nodes, b, &mut kids);
                    todo.extend(kids.iter().map(|&k| Work::Binary(k)));
                    node_lines::<W>()
                }
            };
        }
        sum
    }

    /// [`Self::lines`] of the wide subtree of `w`, and through its `levels` top wide levels those
    /// of each inner child's subtree, each sized as a task of its own.
    fn sized(&self, w: Work, levels: usize) -> Sizes {
        match self.kind(w) {
            Kind::Node(b) if levels > 0 => {
                let mut kids = Vec::with_capacity(W);
                self.plan.children(self.nodes, b, &mut kids);
                let blocks = kids.iter().filter(|&&k| self.plan.is_block(k)).count() * block_lines::<W>();
                let inner: Vec<Sizes> = kids
                    .par_iter()
                    .filter(|&&k| !self.plan.is_block(k))
                    .map(|&k| self.sized(Work::Binary(k), levels - 1))
                    .collect();
                Sizes { lines: node_lines::<W>() + blocks + inner.iter().map(|s| s.lines).sum::<usize>(), inner }
            }
            _ => Sizes { lines: self.lines(w), inner: Vec::new() },
        }
    }

    /// Writes the wide subtree of `w` into `out` (exactly `sized.lines` of it, [`Self::sized`]),
    /// the arena's lines from `base` on, the inner subtrees that `sized` sized apart each a task
    /// of its own; returns the subtree's reference.
    fn write_par(&self, w: Work, sized: &Sizes, out: &mut [Line], base: u32) -> u32 {
        let b = match self.kind(w) {
            Kind::Node(b) if !sized.inner.is_empty() => b,
            _ => {
                let mut cursor = Cursor { out, base, at: 0 };
                let r = self.write(w, &mut cursor);
                // Every line written once: none is left for a walk to read unwritten.
                assert_eq!(cursor.at, cursor.out.len(), "the subtree fills the lines sized for it");
                return r;
            }
        };
        let mut kids = Vec::with_capacity(W);
        self.plan.children(self.nodes, b, &mut kids);
        let mut node = self.node(&kids);
        let blocks = kids.iter().filter(|&&k| self.plan.is_block(k)).count() * block_lines::<W>();
        let (head, rest) = out.split_at_mut(node_lines::<W>());
        let (leaves, mut rest) = rest.split_at_mut(blocks);
        // The leaf children's blocks follow the node, as `write` lays them out.
        let mut cursor = Cursor { out: leaves, base: base + node_lines::<W>() as u32, at: 0 };
        let (mut scratch, mut indices) = (Vec::new(), Vec::with_capacity(W));
        for (slot, &k) in kids.iter().enumerate().filter(|(_, k)| self.plan.is_block(**k)) {
            node.child[slot] = self.block(k, &mut cursor, &mut indices, &mut scratch);
        }
        let inner = kids.iter().enumerate().filter(|(_, k)| !self.plan.is_block(**k));
        let mut at = base + (node_lines::<W>() + blocks) as u32;
        let mut parts = Vec::with_capacity(W);
        for ((slot, &k), sized) in inner.zip(&sized.inner) {
            let (part, r) = std::mem::take(&mut rest).split_at_mut(sized.lines);
            parts.push((slot, k, sized, part, at));
            (rest, at) = (r, at + sized.lines as u32);
        }
        assert!(rest.is_empty(), "the subtrees fill the lines sized for them");
        let refs: Vec<(usize, u32)> = parts
            .into_par_iter()
            .map(|(slot, k, sized, part, at)| (slot, self.write_par(Work::Binary(k), sized, part, at)))
            .collect();
        for (slot, r) in refs {
            node.child[slot] = r;
        }
        Cursor { out: head, base, at: 0 }.push(node)
    }

    /// Writes the wide subtree of `w` on this thread, depth first: each node, then its leaf
    /// children's blocks (so that a node and the blocks a ray tests next to it lie together),
    /// then its inner children's subtrees in slot order. Returns the subtree's reference.
    fn write(&self, w: Work, out: &mut Cursor<'_>) -> u32 {
        let mut work: Vec<(Work, Option<(u32, usize)>)> = vec![(w, None)];
        let (mut indices, mut scratch, mut kids) = (Vec::with_capacity(W), Vec::new(), Vec::with_capacity(W));
        let mut root = LEAF;
        while let Some((w, parent)) = work.pop() {
            let r = match (w, self.kind(w)) {
                (Work::Binary(b), Kind::Block) => self.block(b, out, &mut indices, &mut scratch),
                (Work::Range(start, count), Kind::Block) => {
                    indices.clear();
                    indices.extend(start..start + count);
                    out.block::<W>(self.tris, &indices)
                }
                (_, Kind::Range(start, count)) => {
                    let runs = runs::<W>(start, count);
                    let mut node = WideNode::<W>::empty();
                    for (slot, &(s, n)) in runs.iter().enumerate() {
                        let (lo, hi) = self.range_box(s, n);
                        node.set(slot, lo, hi);
                    }
                    let id = out.push(node);
                    // Leaf children popped first, as below.
                    for leaves in [false, true] {
                        for (slot, &(s, n)) in runs.iter().enumerate().rev() {
                            if (n as usize <= W) == leaves {
                                work.push((Work::Range(s, n), Some((id, slot))));
                            }
                        }
                    }
                    id
                }
                (_, Kind::Node(b)) => {
                    self.plan.children(self.nodes, b, &mut kids);
                    let id = out.push(self.node(&kids));
                    // Leaf children popped first, so that their blocks follow the node.
                    for leaves in [false, true] {
                        for (slot, &k) in kids.iter().enumerate().rev() {
                            if self.plan.is_block(k) == leaves {
                                work.push((Work::Binary(k), Some((id, slot))));
                            }
                        }
                    }
                    id
                }
            };
            match parent {
                Some((p, slot)) => out.node_mut::<W>(p).child[slot] = r,
                None => root = r,
            }
        }
        root
    }

    /// A wide node over the binary nodes `kids`, their boxes in its slots (no children yet).
    fn node(&self, kids: &[u32]) -> WideNode<W> {
        let mut node = WideNode::empty();
        for (slot, &k) in kids.iter().enumerate() {
            let c = &self.nodes[k as usize];
            node.set(slot, c.min, c.max);
        }
        node
    }

    /// The leaf block of binary subtree `b`'s triangles, in index order.
    fn block(&self, b: u32, out: &mut Cursor<'_>, indices: &mut Vec<u32>, scratch: &mut Vec<u32>) -> u32 {
        indices.clear();
        leaf_indices(self.nodes, b, indices, scratch);
        indices.sort_unstable();
        out.block::<W>(self.tris, indices)
    }

    /// The box of the `count` triangles from `start`.
    fn range_box(&self, start: u32, count: u32) -> ([f32; 3], [f32; 3]) {
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for t in (start..start + count).map(|i| self.tris.triangle(i)) {
            for v in t.vertices() {
                for a in 0..3 {
                    lo[a] = lo[a].min(v[a]);
                    hi[a] = hi[a].max(v[a]);
                }
            }
        }
        (lo, hi)
    }
}

/// The lines of a wide subtree, and where it is written by tasks, those of its inner children's
/// subtrees in slot order ([`Collapse::sized`]).
struct Sizes {
    lines: usize,
    inner: Vec<Sizes>,
}

/// What one slot becomes ([`Collapse::kind`]).
enum Kind {
    Block,
    /// A wide node over up to `W` equal runs of the `count` triangles from `start` (a binary leaf
    /// of more than a block, or such a run), each boxed by its triangles' vertices.
    Range(u32, u32),
    /// A wide node over binary node `b`'s subtree, its slots as the plan spreads them.
    Node(u32),
}

/// The runs of a wide node over `count` (more than `W`) triangles from `start`: up to `W` of equal
/// length, the last shorter.
fn runs<const W: usize>(start: u32, count: u32) -> Vec<(u32, u32)> {
    let per = count.div_ceil(W as u32).max(W as u32);
    (start..start + count).step_by(per as usize).map(|s| (s, per.min(start + count - s))).collect()
}

/// Lines of the wide subtree over `count` triangles of a range.
fn range_lines<const W: usize>(count: u32) -> usize {
    if count as usize <= W {
        return block_lines::<W>();
    }
    node_lines::<W>() + runs::<W>(0, count).iter().map(|&(_, n)| range_lines::<W>(n)).sum::<usize>()
}

/// Where a subtree's lines go: `out`, the arena's lines from line `base` on, filled from the
/// front (`at`).
struct Cursor<'o> {
    out: &'o mut [Line],
    base: u32,
    at: usize,
}

impl Cursor<'_> {
    /// Writes `v` (a node or a block) at the next lines; returns its first line in the arena.
    fn push<T: Copy>(&mut self, v: T) -> u32 {
        const { assert!(size_of::<T>().is_multiple_of(64) && align_of::<T>() <= 64) };
        let lines = &mut self.out[self.at..self.at + size_of::<T>() / 64];
        // SAFETY: the lines (bounds-checked) hold `size_of::<T>()` bytes (a multiple of 64,
        // asserted above), aligned to 64 (at least `T`'s alignment).
        unsafe { lines.as_mut_ptr().cast::<T>().write(v) };
        let r = self.base + self.at as u32;
        self.at += size_of::<T>() / 64;
        r
    }

    /// The leaf block of triangles `indices`; returns its reference.
    fn block<const W: usize>(&mut self, tris: &(impl TriangleSource + ?Sized), indices: &[u32]) -> u32 {
        LEAF | self.push(TriBlock::<W>::new(tris, indices))
    }

    /// The node this cursor wrote at arena line `r`.
    fn node_mut<const W: usize>(&mut self, r: u32) -> &mut WideNode<W> {
        let at = (r - self.base) as usize;
        let lines = &mut self.out[at..at + node_lines::<W>()];
        // SAFETY: the slice (bounds-checked) holds a node's bytes, aligned to 64; a node is
        // floats and integers only, so any bytes are a valid one.
        unsafe { &mut *lines.as_mut_ptr().cast::<WideNode<W>>() }
    }
}

/// The collapse's choices, made bottom-up by dynamic programming over the binary tree (Ylitie,
/// Karras and Laine, "Efficient Incoherent Ray Traversal on GPUs Through Compressed Wide BVHs",
/// 2017): for each binary node and each budget of 1 to `W` slots, the least SAH cost of its
/// subtree spread over at most that many slots of a wide node, each slot a leaf block (a subtree
/// of at most `W` triangles) or a wide node of its own. Atomics, so that the tasks planning
/// disjoint subtrees write into the same arrays without `unsafe` (relaxed: plain moves on x86-64).
struct Plan<const W: usize> {
    /// Whether binary node `n`, given one slot, becomes a leaf block (else a wide node).
    leaf: Vec<AtomicBool>,
    /// At `n * W + k - 1`: how many of `k` slots the left subtree of `n` takes when `n` is
    /// spread over at most `k` (the rest go to the right one); 0 where `n` takes one slot itself.
    split: Vec<AtomicU8>,
    /// The slots of `n`'s left subtree when `n` becomes a wide node (its `W` slots spread over
    /// both subtrees).
    open: Vec<AtomicU8>,
}

/// A planned subtree: its triangles, and its least cost in at most 1 to `W` slots.
type Planned<const W: usize> = (u64, [f32; W]);

impl<const W: usize> Plan<W> {
    /// The plan of the tree `nodes`, its subtrees `depth` levels below the root (and the leaves
    /// above them) each planned as a task of its own, then the levels above them.
    fn new(nodes: &[Node], depth: usize) -> Self {
        let len = nodes.len();
        // Zeroed by the allocator (fresh pages from the kernel for large arrays), not entry by
        // entry: the dragon's `split` alone has 7.6 million.
        let plan = Plan {
            leaf: bytemuck::zeroed_vec(len),
            split: bytemuck::zeroed_vec(len * W),
            open: bytemuck::zeroed_vec(len),
        };
        let (mut frontier, mut stack) = (Vec::new(), vec![(0u32, 0usize)]);
        while let Some((n, d)) = stack.pop() {
            let node = &nodes[n as usize];
            match d == depth || node.is_leaf() {
                true => frontier.push(n),
                false => stack.extend([(node.index, d + 1), (node.index + 1, d + 1)]),
            }
        }
        let mut done: Vec<(u32, Planned<W>)> =
            frontier.par_iter().map(|&f| (f, plan.subtree(nodes, f, |_| None))).collect();
        done.sort_unstable_by_key(|d| d.0);
        plan.subtree(nodes, 0, |n| done.binary_search_by_key(&n, |d| d.0).ok().map(|i| done[i].1));
        plan
    }

    /// Plans the subtree of binary node `root`, taking those subtrees that `known` answers for as
    /// planned already; returns the root's.
    fn subtree(&self, nodes: &[Node], root: u32, known: impl Fn(u32) -> Option<Planned<W>>) -> Planned<W> {
        let mut order = Vec::new();
        let mut stack = vec![root];
        while let Some(n) = stack.pop() {
            order.push(n);
            let node = &nodes[n as usize];
            if !node.is_leaf() && known(n).is_none() {
                stack.extend([node.index, node.index + 1]);
            }
        }
        // The reverse of that order visits each node after both its subtrees, the left one
        // first: per subtree, its triangles and its least cost in at most 1 to `W` slots stay on
        // this stack until its parent takes them (as deep as the tree, not as long).
        let mut done: Vec<Planned<W>> = Vec::new();
        for &n in order.iter().rev() {
            if let Some(p) = known(n) {
                done.push(p);
                continue;
            }
            let n = n as usize;
            let node = &nodes[n];
            let area = half_area(node);
            if node.is_leaf() {
                let c = node.count as usize;
                self.leaf[n].store(c <= W, Relaxed);
                // A leaf of more than a block becomes a wide node over blocks (`range_lines`).
                let one = if c <= W { BLOCK_COST } else { NODE_COST + c.div_ceil(W) as f32 * BLOCK_COST };
                done.push((c as u64, [area * one; W]));
                continue;
            }
            let (Some((nr, right)), Some((nl, left))) = (done.pop(), done.pop()) else {
                unreachable!("both subtrees come before their node")
            };
            let count = nl + nr;
            // The cheapest spread of both subtrees over at most `j` slots, and the left's share
            // (at least 1, also where every cost is infinite: boxes of areas beyond f32).
            let spread = |j: usize| {
                (1..j)
                    .map(|k| (left[k - 1] + right[j - k - 1], k as u8))
                    .fold((f32::INFINITY, 1), |a, b| if b.0 < a.0 { b } else { a })
            };
            let (inner, k) = spread(W);
            self.open[n].store(k, Relaxed);
            let inner = area * NODE_COST + inner;
            let leaf = if count <= W as u64 { area * BLOCK_COST } else { f32::INFINITY };
            self.leaf[n].store(count <= W as u64 && leaf <= inner, Relaxed);
            let mut cost = [leaf.min(inner); W];
            let mut split = 0;
            for j in 2..=W {
                let (c, k) = spread(j);
                // More slots never cost more: keep the spread over fewer where it is as cheap.
                if c < cost[j - 2] {
                    (cost[j - 1], split) = (c, k);
                } else {
                    cost[j - 1] = cost[j - 2];
                }
                self.split[n * W + j - 1].store(split, Relaxed);
            }
            done.push((count, cost));
        }
        done.pop().expect("the root's plan")
    }

    /// Whether binary node `n`, given one slot, becomes a leaf block.
    fn is_block(&self, n: u32) -> bool {
        self.leaf[n as usize].load(Relaxed)
    }

    /// The binary nodes that become the children of internal binary node `b`'s wide node, left
    /// to right: its `W` slots spread over its subtrees as planned.
    fn children(&self, nodes: &[Node], b: u32, kids: &mut Vec<u32>) {
        kids.clear();
        // (binary node, slots): at most `W` pending, since each takes one slot or more of `W`.
        let mut todo = [(0u32, 0usize); W];
        let n = &nodes[b as usize];
        let k = self.open[b as usize].load(Relaxed) as usize;
        assert!((1..W).contains(&k), "the plan gives both subtrees of a wide node a slot");
        todo[0] = (n.index + 1, W - k);
        todo[1] = (n.index, k);
        let mut len = 2;
        while len > 0 {
            len -= 1;
            let (x, slots) = todo[len];
            let k = self.split[x as usize * W + slots - 1].load(Relaxed) as usize;
            if k == 0 {
                kids.push(x);
            } else {
                let c = nodes[x as usize].index;
                todo[len] = (c + 1, slots - k);
                todo[len + 1] = (c, k);
                len += 2;
            }
        }
    }
}

/// The triangles under binary node `b`, with `stack` as scratch.
fn leaf_indices(nodes: &[Node], b: u32, out: &mut Vec<u32>, stack: &mut Vec<u32>) {
    stack.clear();
    stack.push(b);
    while let Some(n) = stack.pop() {
        let node = &nodes[n as usize];
        if node.is_leaf() {
            out.extend(node.index..node.index + node.count);
        } else {
            stack.extend([node.index, node.index + 1]);
        }
    }
}
