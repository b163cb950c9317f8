//! The top-down build shared by both SAH builders: recursion, leaf decisions, fallbacks for
//! degenerate input, rayon parallelism, and the final child-pair layout. A [`Splitter`] (binned or
//! sweep) only decides where to split one node.

use crate::sweep::{PRESORTED_MAX, Presorted, bounds_at, presorted_split};
use crate::top::{At, Top, top_units};
use bvh_format::Node;
use bvh_format::memory::advise_huge_pages;
use glam::Vec3A;
use std::mem::MaybeUninit;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::time::Instant;

/// Nodes deeper than this are split at the object median instead of by SAH, which bounds the
/// depth of any tree by `DEPTH_LIMIT + log2(triangles)`: SAH can peel one triangle at a time off
/// pathological input (nested shells, say) and build a tree as deep as the scene is large.
pub const DEPTH_LIMIT: u32 = 64;

/// Nodes with more triangles than this build their two subtrees in parallel.
const PARALLEL_SUBTREES: usize = 1024;

/// Wall time of the phases of one build, in milliseconds (`build_cpu --phases`): where the time
/// goes that more threads cannot share. Measured on every build (a dozen clock reads).
#[derive(Clone, Copy, Debug, Default)]
pub struct Phases {
    /// Checks of the input, primitive references, buffers and the root's bounds.
    pub setup: f64,
    /// The recursion, from the root's split to the last leaf.
    pub tree: f64,
    /// Of [`Phases::tree`]: the splits of nodes above [`PARALLEL_NODE`] (every thread bins and
    /// partitions them), their wall times summed: near the root they run one at a time, further
    /// down a few side by side.
    pub parallel_splits: f64,
    /// How many nodes were split so.
    pub parallel_split_count: u32,
    /// Of [`Phases::tree`]: when the last of those splits ended, from the start of the recursion;
    /// after it only subtrees of at most [`PARALLEL_NODE`] primitives are left.
    pub parallel_until: f64,
    /// The reinsertion in the top ([`crate::top`]), the leaf order renumbered included.
    pub top: f64,
    /// Writing the node layouts.
    pub layouts: f64,
    /// Freeing the build's buffers (the kernel unmaps the large ones, on the calling thread).
    pub release: f64,
}

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

/// Half areas of the boxes inside one node, in f32 and in units of the node's largest extent, so
/// that none exceeds 3 and no coordinate of a huge scene overflows: the SAH compares only ratios
/// of areas within a node, and f32 lets the splitters evaluate them without conversions.
#[derive(Clone, Copy)]
pub struct AreaScale(f32);

impl AreaScale {
    pub fn of(node: &Aabb) -> AreaScale {
        // The extent in f64: in f32 it overflows for coordinates beyond half of f32::MAX.
        let e = (0..3).map(|k| node.max[k] as f64 - node.min[k] as f64).fold(0.0, f64::max);
        let s = (1.0 / e) as f32;
        // A point-sized node has no area to compare: any finite scale does.
        AreaScale(if s.is_finite() && s > 0.0 { s } else { 1.0 })
    }

    /// Half the surface area of `b` in this node's units; 0 for an empty box.
    #[inline(always)]
    pub fn half_area(self, b: &Aabb) -> f32 {
        let d = (b.max * self.0 - b.min * self.0).max(Vec3A::ZERO);
        d.x * d.y + d.y * d.z + d.z * d.x
    }
}

/// One triangle as the builders see it: its box and its input index, 32 bytes. The builders
/// reorder these records themselves rather than an index array into them, so that binning and
/// partitioning stream through memory instead of gathering from it.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Zeroable)]
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

/// The reference of triangle `t`, number `i`.
#[inline(always)]
fn prim_ref(t: &[glam::Vec3; 3], i: usize) -> PrimRef {
    let (min, max) = (t[0].min(t[1]).min(t[2]), t[0].max(t[1]).max(t[2]));
    let d = max - min;
    PrimRef { min: min.into(), id: i as u32, max: max.into(), area: d.x * d.y + d.y * d.z + d.z * d.x }
}

/// The references of every triangle, in input order.
pub fn prim_refs(positions: &[[glam::Vec3; 3]]) -> Vec<PrimRef> {
    use rayon::prelude::*;
    positions.par_iter().enumerate().map(|(i, t)| prim_ref(t, i)).collect()
}

/// [`prim_refs`] and their bounds (the root's), in one pass by every thread that also checks
/// every coordinate: `Err` with the first triangle that has one that is not finite.
pub fn prim_refs_checked(positions: &[[glam::Vec3; 3]]) -> Result<(Vec<PrimRef>, NodeBounds), usize> {
    use rayon::prelude::*;
    const CHUNK: usize = 1 << 14;
    let empty = NodeBounds { aabb: Aabb::EMPTY, centroids: Aabb::EMPTY };
    let fill = |out: &mut [MaybeUninit<PrimRef>]| {
        out.par_chunks_mut(CHUNK)
            .zip(positions.par_chunks(CHUNK))
            .enumerate()
            .map(|(c, (out, tris))| {
                assert_eq!(out.len(), tris.len(), "a chunk of references per chunk of triangles");
                let (mut nb, mut finite) = (empty, true);
                for (k, (o, t)) in out.iter_mut().zip(tris).enumerate() {
                    // x * 0 is 0 for every finite x, NaN for infinities and NaN.
                    finite &= t[0] * 0.0 + t[1] * 0.0 + t[2] * 0.0 == glam::Vec3::ZERO;
                    let r = o.write(prim_ref(t, c * CHUNK + k));
                    nb.aabb.grow(&r.aabb());
                    nb.centroids.grow_point(r.centroid());
                }
                (nb, finite)
            })
            .reduce(
                || (empty, true),
                |a, b| {
                    let nb =
                        NodeBounds { aabb: a.0.aabb.union(&b.0.aabb), centroids: a.0.centroids.union(&b.0.centroids) };
                    (nb, a.1 && b.1)
                },
            )
    };
    // SAFETY: `fill` pairs each chunk of the references with the chunk of triangles of the same
    // length (asserted) and writes one reference per triangle.
    let (refs, (root, finite)) = unsafe { written(positions.len(), fill) };
    if !finite {
        let t = positions.par_iter().position_first(|t| t.iter().any(|v| !v.is_finite()));
        return Err(t.expect("a coordinate is not finite"));
    }
    Ok((refs, root))
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

/// The box of a set of primitives' centroids, the same as [`bounds_of`]'s. Two boxes grow side by
/// side (the min and max chains are the loop's latency), and the halving of the box's corner
/// sums waits until the end: halving is exact and monotonic, so it commutes with min and max.
pub(crate) fn centroid_bounds(refs: &[PrimRef]) -> Aabb {
    let sum = |r: &PrimRef| Vec3A::from(r.min) + Vec3A::from(r.max);
    let (mut a, mut b) = (Aabb::EMPTY, Aabb::EMPTY);
    let mut pairs = refs.chunks_exact(2);
    for pair in &mut pairs {
        a.grow_point(sum(&pair[0]));
        b.grow_point(sum(&pair[1]));
    }
    for r in pairs.remainder() {
        a.grow_point(sum(r));
    }
    let both = a.union(&b);
    if refs.is_empty() { both } else { Aabb { min: both.min * 0.5, max: both.max * 0.5 } }
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
    /// SAH cost of splitting a node of half area `parent_area` into children whose half areas
    /// times their primitive counts sum to `weighted`.
    #[inline]
    pub fn split_cost(&self, parent_area: f64, weighted: f64) -> f64 {
        self.traversal + self.intersection * weighted / parent_area
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
    /// The split primitives lie in the spare buffer ([`Splitter::split_parallel`] only).
    pub in_spare: bool,
}

/// Decides how one node is split.
pub trait Splitter: Sync {
    /// Reorders `refs` in place and returns the split with the lowest SAH cost, or `None` when no
    /// split separates the primitives or, if `may_leaf`, when a leaf is cheaper than the best split.
    fn split(&self, refs: &mut [PrimRef], bounds: &NodeBounds, may_leaf: bool) -> Option<Split>;

    /// [`Splitter::split`] for a node of more than [`PARALLEL_NODE`] primitives, using every
    /// thread. It may leave the split primitives in `spare` (as long as `refs`) instead of
    /// `refs`, which [`Split::in_spare`] then says. It must choose the same split as `split`, and
    /// order the children's primitives independently of the number of threads.
    fn split_parallel(
        &self,
        refs: &mut [PrimRef],
        spare: &mut [PrimRef],
        bounds: &NodeBounds,
        may_leaf: bool,
    ) -> Option<Split> {
        let _ = spare;
        self.split(refs, bounds, may_leaf)
    }

    /// The largest node that [`Splitter::split`] splits by the full sweep ([`crate::sweep`]), and
    /// whose subtree, all of it swept too, the build may therefore build from one sorted order
    /// per axis ([`build_presorted`]); 0 for none.
    fn sweeps_up_to(&self) -> usize {
        0
    }
}

/// Nodes with more primitives than this are split by [`Splitter::split_parallel`]: every thread
/// bins and partitions them, since near the root there are too few subtrees to keep the threads
/// busy. It is a size, not a count of threads, so that the tree does not depend on the machine.
pub const PARALLEL_NODE: usize = 1 << 15;

/// One node of the build, in the slots of [`Slots`].
#[repr(C)]
#[derive(Clone, Copy)]
pub(crate) struct Slot {
    pub(crate) min: [f32; 3],
    pub(crate) max: [f32; 3],
    /// Triangle count for a leaf; for an inner node the height of its subtree (a leaf's is 0),
    /// which the reinsertion in the top needs to keep the tree's depth ([`crate::top`]). A leaf
    /// is the slot whose subtree is one node.
    pub(crate) count: u32,
    /// First primitive (leaf) or slot of the right child (inner node).
    pub(crate) index: u32,
    /// Nodes in the subtree rooted here (1 for a leaf): where each layout puts the right child.
    pub(crate) nodes: u32,
}

/// The built tree, one slot per node. A subtree of `c` primitives owns `2c - 1` slots from its
/// root's on (as many as it can have nodes), its left subtree's next. Above
/// [`PARALLEL_SUBTREES`] primitives the right subtree's start after all the slots the left one
/// owns, so that both are built at once; below, a subtree's nodes are packed depth-first at the
/// start of its slots (the right subtree right after the left one's nodes) and the rest are
/// never written. A leaf takes one slot of the `2c - 1`
/// its `c` primitives own, so about half the slots stay unwritten: they are never faulted in
/// either (a million triangles: 72 MB of slots, about 40 of them nodes), and the layouts read
/// the nodes packed.
pub(crate) struct Slots(Box<[MaybeUninit<Slot>]>);

/// A written slot of one [`Slots`]: made only as [`SlotId::ROOT`] and by [`Slots::children`],
/// which is what lets [`Slots::get`] read it. (Every `SlotId` of a build lives in its `build_with` call,
/// beside the one `Slots` it came from.)
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct SlotId(u32);

impl SlotId {
    /// The root's slot: the first.
    pub(crate) const ROOT: SlotId = SlotId(0);
}

impl Slots {
    /// The slot's node.
    #[inline(always)]
    pub(crate) fn get(&self, s: SlotId) -> &Slot {
        // SAFETY: `build_node` writes the root's slot (a tree has a root) and, for every inner
        // node it writes, the slots of both children (the left at the next slot, the right at
        // `index`) before its own; a `SlotId` is the root or a child of a written inner slot.
        unsafe { self.0[s.0 as usize].assume_init_ref() }
    }

    /// An inner node's children, `None` for a leaf.
    #[inline(always)]
    pub(crate) fn children(&self, s: SlotId) -> Option<(SlotId, SlotId)> {
        let sl = self.get(s);
        (sl.nodes > 1).then_some((SlotId(s.0 + 1), SlotId(sl.index)))
    }

    /// The first primitive (in the build's leaf order) of the subtree at `s`.
    pub(crate) fn first_primitive(&self, mut s: SlotId) -> u32 {
        while let Some((left, _)) = self.children(s) {
            s = left;
        }
        self.get(s).index
    }
}

/// A finished tree: child-pair nodes, the escape-pointer layout when asked for, and for each
/// leaf-order slot the input triangle it holds.
pub struct BuiltTree {
    pub nodes: Vec<Node>,
    pub escape: Option<Vec<Node>>,
    pub order: Vec<u32>,
    pub phases: Phases,
}

struct Ctx<'a, S: Splitter> {
    splitter: &'a S,
    costs: Costs,
    progress: Option<&'a AtomicUsize>,
    /// [`PARALLEL_NODE`] outside tests.
    parallel_node: usize,
    /// [`PARALLEL_SUBTREES`] outside tests, which compare the packed placement below it with
    /// the gapped one above ([`Slots`]).
    parallel_subtrees: usize,
    /// Whether subtrees are reinserted in the top of the finished tree ([`crate::top`]); always
    /// outside tests.
    reshape_top: bool,
    /// Whether small swept subtrees are built from one sorted order per axis
    /// ([`build_presorted`]); always outside tests, which compare it with a sort per node.
    presorted: bool,
    /// The parallel splits' wall time summed, and when the last ended ([`Phases`]), in ns from
    /// `started`.
    parallel_ns: AtomicU64,
    parallel_count: AtomicUsize,
    parallel_until: AtomicU64,
    started: Instant,
}

/// A vector of `len` elements, each written by `fill` instead of zeroed first: `vec![x; n]` or a
/// zeroed allocation writes every byte on the calling thread (`calloc` clears memory the
/// allocator recycles, most buffers of a build below glibc's 32 MiB mmap threshold), a serial
/// part the other threads wait for, where the build's own threads write each element anyway.
///
/// # Safety
/// `fill` must write every element of the slice it is given, or panic.
unsafe fn written<T, R>(len: usize, fill: impl FnOnce(&mut [MaybeUninit<T>]) -> R) -> (Vec<T>, R) {
    let mut v = Vec::with_capacity(len);
    advise_huge_pages(&mut v.spare_capacity_mut()[..len], HUGE_BUFFER);
    let r = fill(&mut v.spare_capacity_mut()[..len]);
    // SAFETY: the caller's contract: `fill` returned, so it wrote all `len` elements.
    unsafe { v.set_len(len) };
    (v, r)
}

/// The build's buffers worth huge pages: the smaller ones (the bunny's, a million triangles' leaf
/// order) mostly come from the heap that glibc recycles, already backed.
const HUGE_BUFFER: usize = 16 << 20;

/// Builds a tree over `refs` (used as scratch space: their order afterwards means nothing) with
/// the given splitter; `escape` asks for the escape-pointer layout too. `progress`, when given,
/// counts the primitives already placed in leaves, for a progress bar.
pub fn build<S: Splitter>(
    refs: &mut [PrimRef],
    splitter: &S,
    costs: Costs,
    progress: Option<&AtomicUsize>,
    escape: bool,
) -> BuiltTree {
    let root = bounds_parallel(refs);
    build_bounded(refs, root, splitter, costs, progress, escape)
}

/// [`build`] given the bounds of `refs` ([`prim_refs_checked`]).
pub fn build_bounded<S: Splitter>(
    refs: &mut [PrimRef],
    root: NodeBounds,
    splitter: &S,
    costs: Costs,
    progress: Option<&AtomicUsize>,
    escape: bool,
) -> BuiltTree {
    build_with(refs, root, Ctx::new(splitter, costs, progress, PARALLEL_NODE), escape)
}

impl<'a, S: Splitter> Ctx<'a, S> {
    fn new(splitter: &'a S, costs: Costs, progress: Option<&'a AtomicUsize>, parallel_node: usize) -> Self {
        Ctx {
            splitter,
            costs,
            progress,
            parallel_node,
            parallel_subtrees: PARALLEL_SUBTREES,
            reshape_top: true,
            presorted: true,
            parallel_ns: AtomicU64::new(0),
            parallel_count: AtomicUsize::new(0),
            parallel_until: AtomicU64::new(0),
            started: Instant::now(),
        }
    }
}

fn ms(from: Instant) -> f64 {
    from.elapsed().as_secs_f64() * 1e3
}

fn build_with<S: Splitter>(refs: &mut [PrimRef], root: NodeBounds, mut ctx: Ctx<'_, S>, escape: bool) -> BuiltTree {
    use rayon::prelude::*;
    let n = refs.len();
    assert!(n > 0 && n < u32::MAX as usize / 2, "the compiler rejects empty and oversized scenes before building");
    let mut phases = Phases::default();
    let t = Instant::now();
    // The second buffer that large nodes are partitioned into (small trees never need it), in
    // safe code an initialised one: zeroed by every thread ([`written`] says why not `calloc`).
    let mut spare: Vec<PrimRef> = if n > ctx.parallel_node {
        let zero = |s: &mut [MaybeUninit<PrimRef>]| {
            s.par_chunks_mut(1 << 14).for_each(|c| c.iter_mut().for_each(|r| _ = r.write(bytemuck::Zeroable::zeroed())))
        };
        // SAFETY: `zero` writes every element.
        unsafe { written(n, zero).0 }
    } else {
        Vec::new()
    };
    phases.setup = ms(t);
    ctx.started = Instant::now();
    let mut slots = Slots(Box::new_uninit_slice(2 * n - 1));
    // The slots too, though about half of them are never written (huge pages clear those with
    // the rest): million's CPU time fell by 10 % with only the other buffers advised, by 17 %
    // with the slots as well (docs/build-benchmark.md).
    advise_huge_pages(&mut slots.0, HUGE_BUFFER);
    // SAFETY: `build_node` writes every element of its part of the leaf order (its leaves'
    // primitives; the children's parts split at `mid`).
    let mut order = unsafe {
        written(n, |order| build_node(&ctx, Prims { refs, spare: &mut spare, order }, 0, &mut slots.0, 0, root, 0)).0
    };
    phases.tree = ms(ctx.started);
    phases.parallel_splits = ctx.parallel_ns.load(Ordering::Relaxed) as f64 * 1e-6;
    phases.parallel_split_count = ctx.parallel_count.load(Ordering::Relaxed) as u32;
    phases.parallel_until = ctx.parallel_until.load(Ordering::Relaxed) as f64 * 1e-6;
    let t = Instant::now();
    drop(spare);
    phases.release = ms(t);
    let t = Instant::now();
    let mut top = None;
    if ctx.reshape_top {
        let mut t = Top::extract(&slots, n, top_units(n));
        if t.optimise() {
            order = renumber(&t.prepare(&slots), &order);
            top = Some(t);
        }
    }
    phases.top = ms(t);
    let t = Instant::now();
    let shape = Shape { slots: &slots, top: top.as_ref() };
    let (nodes, escape) = rayon::join(|| child_pair(&shape), || escape.then(|| depth_first(&shape)));
    phases.layouts = ms(t);
    debug_assert!(order.par_iter().all(|&i| (i as usize) < n));
    let t = Instant::now();
    drop((slots, top));
    phases.release += ms(t);
    BuiltTree { nodes, escape, order, phases }
}

/// The leaf order after the reinsertion: `order`'s ranges `(first, count)` of `units` one after
/// the other, copied by every thread.
fn renumber(units: &[(u32, u32)], order: &[u32]) -> Vec<u32> {
    use rayon::prelude::*;
    let copy = |out: &mut [MaybeUninit<u32>]| {
        let mut parts = Vec::with_capacity(units.len());
        let mut rest = out;
        for &(first, count) in units {
            let (part, r) = rest.split_at_mut(count as usize);
            parts.push((part, &order[first as usize..(first + count) as usize]));
            rest = r;
        }
        assert!(rest.is_empty(), "the units hold every primitive");
        parts.into_par_iter().for_each(|(to, from)| {
            for (t, &f) in to.iter_mut().zip(from) {
                t.write(f);
            }
        });
    };
    // SAFETY: `copy` splits the buffer into one part per unit, as long as the unit's range of
    // `order` (which `zip` then copies whole), and asserts that nothing is left over.
    unsafe { written(order.len(), copy).0 }
}

fn bounds_parallel(refs: &[PrimRef]) -> NodeBounds {
    use rayon::prelude::*;
    let empty = NodeBounds { aabb: Aabb::EMPTY, centroids: Aabb::EMPTY };
    refs.par_chunks(16384)
        .map(bounds_of)
        .reduce(|| empty, |a, b| NodeBounds { aabb: a.aabb.union(&b.aabb), centroids: a.centroids.union(&b.centroids) })
}

/// A node's primitives, the same range of the spare buffer (empty below [`Ctx::parallel_node`]),
/// and the same range of the leaf order.
struct Prims<'a> {
    refs: &'a mut [PrimRef],
    spare: &'a mut [PrimRef],
    order: &'a mut [MaybeUninit<u32>],
}

impl<'a> Prims<'a> {
    fn split_at(self, mid: usize) -> (Prims<'a>, Prims<'a>) {
        let (a, b) = self.refs.split_at_mut(mid);
        let (c, d) = if self.spare.is_empty() { (&mut [][..], &mut [][..]) } else { self.spare.split_at_mut(mid) };
        let (e, f) = self.order.split_at_mut(mid);
        (Prims { refs: a, spare: c, order: e }, Prims { refs: b, spare: d, order: f })
    }
}

/// Builds the subtree of `p.refs` into `slots` (its own part of the gapped array, starting at
/// absolute slot `slot`); `first` is the index of its first primitive. Returns its node count and
/// height.
fn build_node<S: Splitter>(
    ctx: &Ctx<'_, S>,
    mut p: Prims<'_>,
    first: usize,
    slots: &mut [MaybeUninit<Slot>],
    slot: usize,
    bounds: NodeBounds,
    depth: u32,
) -> (u32, u32) {
    let n = p.refs.len();
    // A subtree that the depth limit cannot reach (each level takes at least one primitive off).
    if ctx.presorted
        && n >= 2
        && n <= ctx.splitter.sweeps_up_to()
        && depth as usize + n <= ctx.costs.depth_limit as usize
    {
        return if n <= 16 {
            build_presorted::<S, 16>(ctx, p.refs, p.order, first, slots, slot, bounds)
        } else {
            build_presorted::<S, { PRESORTED_MAX }>(ctx, p.refs, p.order, first, slots, slot, bounds)
        };
    }
    let may_leaf = n <= ctx.costs.max_leaf_size;
    let split = if n == 1 {
        None
    } else if depth >= ctx.costs.depth_limit {
        if may_leaf { None } else { Some(median_split(p.refs, &bounds)) }
    } else {
        let s = if n > ctx.parallel_node {
            let t = Instant::now();
            let s = ctx.splitter.split_parallel(p.refs, p.spare, &bounds, may_leaf);
            ctx.parallel_ns.fetch_add(t.elapsed().as_nanos() as u64, Ordering::Relaxed);
            ctx.parallel_count.fetch_add(1, Ordering::Relaxed);
            ctx.parallel_until.fetch_max(ctx.started.elapsed().as_nanos() as u64, Ordering::Relaxed);
            s
        } else {
            ctx.splitter.split(p.refs, &bounds, may_leaf)
        };
        match s {
            Some(s) => Some(s),
            None if may_leaf => None,
            None => Some(median_split(p.refs, &bounds)),
        }
    };
    let (here, below) = slots.split_first_mut().expect("a subtree owns at least one slot");
    let (min, max) = (bounds.aabb.min.into(), bounds.aabb.max.into());
    let Some(split) = split else {
        leaf(ctx, here, Slot { min, max, count: n as u32, index: first as u32, nodes: 1 });
        assert_eq!(p.order.len(), n, "a node's part of the leaf order holds its primitives");
        for (o, r) in p.order.iter_mut().zip(p.refs.iter()) {
            o.write(r.id);
        }
        return (1, 0);
    };
    let mid = split.mid;
    debug_assert!(mid > 0 && mid < n);
    if split.in_spare {
        std::mem::swap(&mut p.refs, &mut p.spare);
    }
    let (left_p, right_p) = p.split_at(mid);
    let ((l, lh), (r, rh), right_slot) = if n > ctx.parallel_subtrees {
        let right_slot = slot + 2 * mid;
        let (left_slots, right_slots) = below.split_at_mut(2 * mid - 1);
        let left = || build_node(ctx, left_p, first, left_slots, slot + 1, split.left, depth + 1);
        let right = || build_node(ctx, right_p, first + mid, right_slots, right_slot, split.right, depth + 1);
        let (l, r) = rayon::join(left, right);
        (l, r, right_slot)
    } else {
        // Packed: the right subtree right after the left one's nodes ([`Slots`]).
        let l = build_node(ctx, left_p, first, &mut below[..2 * mid - 1], slot + 1, split.left, depth + 1);
        let right_slot = slot + 1 + l.0 as usize;
        let r = build_node(ctx, right_p, first + mid, &mut below[l.0 as usize..], right_slot, split.right, depth + 1);
        (l, r, right_slot)
    };
    let (nodes, height) = (1 + l + r, 1 + lh.max(rh));
    here.write(Slot { min, max, count: height, index: right_slot as u32, nodes });
    (nodes, height)
}

/// Writes a leaf's slot and counts its primitives as placed.
fn leaf<S: Splitter>(ctx: &Ctx<'_, S>, here: &mut MaybeUninit<Slot>, slot: Slot) {
    here.write(slot);
    if let Some(pr) = ctx.progress {
        pr.fetch_add(slot.count as usize, Ordering::Relaxed);
    }
}

/// [`build_node`] for a subtree of at most `N` primitives that the splitter sweeps all of
/// ([`Splitter::sweeps_up_to`]), out of the depth limit's reach: the primitives are sorted once
/// per axis ([`Presorted`]) and each child's orders are filtered from its parent's, where the
/// per-node sweep sorts every node's primitives again (a fifth of a binned build's time went to
/// sweeping these nodes). The same splits as [`build_node`], hence the same tree and leaf order:
/// `tests::presorted_subtrees_build_the_tree_of_a_sort_per_node`.
fn build_presorted<S: Splitter, const N: usize>(
    ctx: &Ctx<'_, S>,
    refs: &[PrimRef],
    order: &mut [MaybeUninit<u32>],
    first: usize,
    slots: &mut [MaybeUninit<Slot>],
    slot: usize,
    bounds: NodeBounds,
) -> (u32, u32) {
    crate::isa::fastest(
        #[inline(always)]
        || {
            let n = refs.len();
            let set = Presorted::<N>::new(refs);
            let sub = Subtree { ctx, ids: &set.ids, boxes: &set.boxes };
            let root = Part {
                orders: set.orders.each_ref().map(|o| &o[..n]),
                slice: &set.local[..n],
                order,
                first,
                slots,
                slot,
            };
            #[cfg(target_arch = "x86_64")]
            if crate::isa::avx2() {
                // SAFETY: the processor has the features `node_avx2` is compiled for.
                return unsafe { sub.node_avx2::<N>(root, bounds) };
            }
            sub.node::<N>(root, bounds)
        },
    )
}

/// One node of a [`build_presorted`] subtree: its primitives (local indices) in the order of each
/// axis, and in the order the per-node build would hold them in its slice (`slice`: the parent's
/// chosen axis order; the slice's own order at the subtree's root), which the leaves keep; its
/// part of the leaf order, and its slots (the first at absolute slot `slot`).
struct Part<'a> {
    orders: [&'a [u8]; 3],
    slice: &'a [u8],
    order: &'a mut [MaybeUninit<u32>],
    first: usize,
    slots: &'a mut [MaybeUninit<Slot>],
    slot: usize,
}

/// What every node of a [`build_presorted`] subtree shares: its primitives' input ids and boxes,
/// by local index ([`Presorted`]).
struct Subtree<'a, 'c, S: Splitter> {
    ctx: &'a Ctx<'c, S>,
    ids: &'a [u32],
    boxes: &'a [Aabb],
}

impl<S: Splitter> Subtree<'_, '_, S> {
    /// The subtree of `part`, compiled for the baseline.
    fn node<const N: usize>(&self, part: Part<'_>, bounds: NodeBounds) -> (u32, u32) {
        self.node_with::<N>(part, bounds, &|s, p, b| s.node::<N>(p, b))
    }

    /// [`Subtree::node`] compiled for AVX2 ([`crate::isa`]).
    ///
    /// # Safety
    /// The processor must have the features named here ([`crate::isa::avx2`]).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx,avx2,fma,bmi1,bmi2,lzcnt,popcnt")]
    unsafe fn node_avx2<const N: usize>(&self, part: Part<'_>, bounds: NodeBounds) -> (u32, u32) {
        // SAFETY: the caller's contract, passed on to the children.
        self.node_with::<N>(part, bounds, &|s, p, b| unsafe { s.node_avx2::<N>(p, b) })
    }

    /// One node, its children built by `child` (the copy compiled for the same features).
    #[inline(always)]
    fn node_with<const N: usize>(
        &self,
        part: Part<'_>,
        bounds: NodeBounds,
        child: &impl Fn(&Self, Part<'_>, NodeBounds) -> (u32, u32),
    ) -> (u32, u32) {
        let Part { orders, slice, order, first, slots, slot } = part;
        let ctx = self.ctx;
        let n = slice.len();
        let may_leaf = n <= ctx.costs.max_leaf_size;
        let split = if n == 1 { None } else { presorted_split::<N>(&ctx.costs, self.boxes, orders, &bounds, may_leaf) };
        let (here, below) = slots.split_first_mut().expect("a subtree owns at least one slot");
        let (min, max) = (bounds.aabb.min.into(), bounds.aabb.max.into());
        // No split: a leaf, or, for a node too large for one whose centroids all coincide, the
        // middle of its slice (as `median_split` does without a centroid extent).
        let (mid, side_of) = match split {
            Some((axis, mid)) => (mid, orders[axis]),
            None if may_leaf || n == 1 => {
                leaf(ctx, here, Slot { min, max, count: n as u32, index: first as u32, nodes: 1 });
                assert_eq!(order.len(), n, "a node's part of the leaf order holds its primitives");
                for (o, &i) in order.iter_mut().zip(slice) {
                    o.write(self.ids[i as usize]);
                }
                return (1, 0);
            }
            None => (n / 2, slice),
        };
        // Each axis's order split stably by side, the three side by side.
        let (left_slice, right_slice) = side_of.split_at(mid);
        let mut left_side = [false; N];
        for &i in left_slice {
            left_side[i as usize] = true;
        }
        let (left_nb, right_nb) = (bounds_at(self.boxes, left_slice), bounds_at(self.boxes, right_slice));
        let (mut lefts, mut rights) = ([[0u8; N]; 3], [[0u8; N]; 3]);
        let [o0, o1, o2] = orders;
        let (o1, o2) = (&o1[..n], &o2[..n]);
        let (mut l, mut r) = ([0usize; 3], [0usize; 3]);
        // Children of one primitive are leaves, which need no orders (two in five nodes here).
        for k in 0..if n > 2 { n } else { 0 } {
            for (a, &i) in [o0[k], o1[k], o2[k]].iter().enumerate() {
                // Branch-free: written to both sides, kept on the one whose cursor moves on (the
                // other's next write overwrites it; neither cursor passes its side's count).
                let left = left_side[i as usize];
                lefts[a][l[a]] = i;
                rights[a][r[a]] = i;
                l[a] += left as usize;
                r[a] += !left as usize;
            }
        }
        let (left_order, right_order) = order.split_at_mut(mid);
        let left_orders = lefts.each_ref().map(|o| &o[..mid]);
        let right_orders = rights.each_ref().map(|o| &o[..n - mid]);
        let left_slots = &mut below[..2 * mid - 1];
        let left = Part {
            orders: left_orders,
            slice: left_slice,
            order: left_order,
            first,
            slots: left_slots,
            slot: slot + 1,
        };
        let (l, lh) = child(self, left, left_nb);
        // Packed, as [`build_node`] below [`PARALLEL_SUBTREES`].
        let right_slot = slot + 1 + l as usize;
        let right = Part {
            orders: right_orders,
            slice: right_slice,
            order: right_order,
            first: first + mid,
            slots: &mut below[l as usize..],
            slot: right_slot,
        };
        let (r, rh) = child(self, right, right_nb);
        let (nodes, height) = (1 + l + r, 1 + lh.max(rh));
        here.write(Slot { min, max, count: height, index: right_slot as u32, nodes });
        (nodes, height)
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
    Split { mid, left: bounds_of(&refs[..mid]), right: bounds_of(&refs[mid..]), in_spare: false }
}

/// Subtrees of more nodes than this are written out in parallel.
const PARALLEL_EMIT: u32 = 1 << 14;

/// The finished tree: the slots, below the reshaped top when there is one.
struct Shape<'a> {
    slots: &'a Slots,
    top: Option<&'a Top>,
}

impl Shape<'_> {
    fn root(&self) -> At {
        self.top.map_or(At::Slot(SlotId::ROOT, 0), Top::root)
    }

    /// The node at `at` (`children`: where an inner node's pair lies, child-pair layout, or its
    /// escape index, escape layout), its subtree's node count and its children.
    #[inline(always)]
    fn node(&self, at: At, children: usize) -> (Node, u32, Option<(At, At)>) {
        match at {
            At::Slot(s, shift) => {
                let sl = self.slots.get(s);
                match self.slots.children(s) {
                    None => {
                        let index = sl.index.wrapping_add(shift);
                        (Node { min: sl.min, count: sl.count, max: sl.max, index }, 1, None)
                    }
                    Some((l, r)) => {
                        let node = Node { min: sl.min, count: 0, max: sl.max, index: children as u32 };
                        (node, sl.nodes, Some((At::Slot(l, shift), At::Slot(r, shift))))
                    }
                }
            }
            At::Top(t) => {
                let (bbox, nodes, l, r) = self.top.expect("a top node comes from a top").inner(t);
                let node = Node { min: bbox.min.into(), count: 0, max: bbox.max.into(), index: children as u32 };
                (node, nodes, Some((l, r)))
            }
        }
    }

    fn nodes(&self, at: At) -> u32 {
        self.node(at, 0).1
    }
}

/// The child-pair layout: root at 0, the two children of each inner node side by side, pairs in
/// the depth-first (left first) order of their parents. The pairs below a node are therefore
/// contiguous, which lets subtrees be written in parallel into their own parts of the array.
fn child_pair(shape: &Shape<'_>) -> Vec<Node> {
    let root = shape.root();
    let count = shape.nodes(root);
    let write = |nodes: &mut [MaybeUninit<Node>]| {
        let (first, below) = nodes.split_first_mut().expect("a tree has a root");
        let (node, _, kids) = shape.node(root, 1);
        first.write(node);
        match kids {
            Some(kids) => pairs(shape, kids, count, below, 1),
            None => assert!(below.is_empty(), "a leaf has no nodes below it"),
        }
    };
    // SAFETY: `pairs` writes every node of the part it is given ([`pairs`] asserts the sizes).
    unsafe { written(count as usize, write).0 }
}

/// Writes the nodes below an inner node of `count` nodes whose children are `kids` into `out`,
/// which starts at node `base`: its pair, then everything below its left child, then everything
/// below its right child. Writes every node of `out`: its length must be `count - 1`, and the
/// part below a leaf child empty (asserted; [`written`] relies on it).
fn pairs(shape: &Shape<'_>, (l, r): (At, At), count: u32, out: &mut [MaybeUninit<Node>], base: usize) {
    assert_eq!(out.len() + 1, count as usize, "a subtree's part holds its nodes");
    // The left child's pair comes right after this one, whatever its size.
    let left_base = base + 2;
    let (ln, left_count, lk) = shape.node(l, left_base);
    let left_below = left_count as usize - 1;
    let (pair, below) = out.split_at_mut(2);
    let (left_node, right_node) = pair.split_at_mut(1);
    let (left_out, right_out) = below.split_at_mut(left_below);
    let right_base = left_base + left_below;
    left_node[0].write(ln);
    let mut left = || match lk {
        Some(k) => pairs(shape, k, left_count, left_out, left_base),
        None => assert!(left_out.is_empty(), "a leaf has no nodes below it"),
    };
    // The right child's slot is read after the left subtree is written: a packed subtree's slots
    // lie depth-first, so it then comes next in memory, where read at once it was a cache miss
    // (two thirds of this function's time on the bunny).
    let mut right = || {
        let (rn, right_count, rk) = shape.node(r, right_base);
        right_node[0].write(rn);
        match rk {
            Some(k) => pairs(shape, k, right_count, right_out, right_base),
            None => assert!(right_out.is_empty(), "a leaf has no nodes below it"),
        }
    };
    if count > PARALLEL_EMIT {
        rayon::join(left, right);
    } else {
        left();
        right();
    }
}

/// The escape-pointer layout: nodes in depth-first order (left first), an inner node pointing
/// past its subtree.
fn depth_first(shape: &Shape<'_>) -> Vec<Node> {
    let root = shape.root();
    // SAFETY: `preorder` writes every node of the part it is given (it asserts the sizes).
    unsafe { written(shape.nodes(root) as usize, |nodes| preorder(shape, root, nodes, 0)).0 }
}

/// Writes the subtree at `at` into `out`, every node of it: its length must be the subtree's
/// node count (asserted; [`written`] relies on it).
fn preorder(shape: &Shape<'_>, at: At, out: &mut [MaybeUninit<Node>], base: usize) {
    let count = shape.nodes(at);
    assert_eq!(out.len(), count as usize, "a subtree's part holds its nodes");
    let (node, _, kids) = shape.node(at, base + count as usize);
    out[0].write(node);
    let Some((l, r)) = kids else { return };
    let left_n = shape.nodes(l) as usize;
    let (left_out, right_out) = out[1..].split_at_mut(left_n);
    let mut left = || preorder(shape, l, left_out, base + 1);
    let mut right = || preorder(shape, r, right_out, base + 1 + left_n);
    if count > PARALLEL_EMIT {
        rayon::join(left, right);
    } else {
        left();
        right();
    }
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
        let mut rng = ::tests::Rng(12345);
        let mut rnd = || rng.unit();
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
        let t = super::build(&mut refs, &crate::binned::BinnedSah { bins: 16, costs }, costs, None, false);
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

    /// Builds with large nodes split in parallel from `parallel_node` primitives up, on a rayon
    /// pool of `threads`.
    fn build_parallel(tris: &[[Vec3; 3]], parallel_node: usize, threads: usize) -> super::BuiltTree {
        build_ctx(tris, parallel_node, threads, true)
    }

    fn build_refs<S: super::Splitter>(tris: &[[Vec3; 3]], ctx: super::Ctx<'_, S>) -> super::BuiltTree {
        let (mut refs, root) = super::prim_refs_checked(tris).expect("finite triangles");
        super::build_with(&mut refs, root, ctx, true)
    }

    fn build_ctx(tris: &[[Vec3; 3]], parallel_node: usize, threads: usize, reshape_top: bool) -> super::BuiltTree {
        let costs =
            super::Costs { traversal: 1.0, intersection: 1.0, max_leaf_size: 8, depth_limit: super::DEPTH_LIMIT };
        let splitter = crate::binned::BinnedSah { bins: 16, costs };
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a thread pool");
        pool.install(|| {
            let ctx = super::Ctx { reshape_top, ..super::Ctx::new(&splitter, costs, None, parallel_node) };
            build_refs(tris, ctx)
        })
    }

    /// Triangles on a coarse grid (many centroids tie on some axis, so the input-id order
    /// decides), clusters of identical triangles (no plane separates them: the middle split) and
    /// a soup.
    fn ties_and_duplicates(n: usize) -> Vec<[Vec3; 3]> {
        let mut rng = ::tests::Rng(7);
        let mut tris: Vec<[Vec3; 3]> = (0..n)
            .map(|_| {
                let mut v = || (rng.unit() * 6.0).floor();
                let c = Vec3::new(v(), v(), v());
                [c, c + Vec3::new(v() + 1.0, 0.0, 0.0), c + Vec3::new(0.0, v() + 1.0, v())]
            })
            .collect();
        for k in 0..40 {
            let t = [
                Vec3::splat(k as f32 * 3.0),
                Vec3::splat(k as f32 * 3.0) + Vec3::X,
                Vec3::splat(k as f32 * 3.0) + Vec3::Y,
            ];
            tris.extend(std::iter::repeat_n(t, 1 + k % 23));
        }
        tris.extend(soup(n));
        tris
    }

    #[test]
    #[cfg(target_arch = "x86_64")]
    fn both_copies_build_the_same_tree() {
        assert!(crate::isa::detected(), "this processor lacks AVX2, so the two copies cannot be compared here");
        // 100,000 triangles: the parallel splits and their scatter too.
        for tris in [soup(100_000), ties_and_duplicates(3000), soup_on_floor(5000), soup_in_a_room(2000)] {
            for p in [params(Strategy::Binned, 16, 8), params(Strategy::Binned, 4, 1), params(Strategy::Sweep, 16, 8)] {
                let build = |baseline| {
                    crate::isa::baseline_only(baseline);
                    let t = crate::compile::tree_with(&tris, &p, None, true).expect("builds");
                    crate::isa::baseline_only(false);
                    t
                };
                let (baseline, avx2) = (build(true), build(false));
                check_shape(Tree::child_pair(&avx2.nodes), tris.len() as u32).expect("valid tree");
                let what = format!("{} triangles, {:?} {} bins", tris.len(), p.strategy, p.bins);
                assert_eq!(baseline.nodes, avx2.nodes, "{what}: the same nodes");
                assert_eq!(baseline.order, avx2.order, "{what}: the same leaf order");
                assert_eq!(baseline.escape, avx2.escape, "{what}: the same escape layout");
            }
        }
    }

    #[test]
    fn presorted_subtrees_build_the_tree_of_a_sort_per_node() {
        use crate::binned::BinnedSah;
        use crate::sweep::SweepSah;
        fn both<S: super::Splitter>(tris: &[[Vec3; 3]], splitter: &S, costs: super::Costs, what: &str) {
            let build = |presorted| {
                let ctx = super::Ctx { presorted, ..super::Ctx::new(splitter, costs, None, super::PARALLEL_NODE) };
                build_refs(tris, ctx)
            };
            let (sorting, presorted) = (build(false), build(true));
            check_shape(Tree::child_pair(&presorted.nodes), tris.len() as u32).expect("valid tree");
            assert_eq!(sorting.nodes, presorted.nodes, "{what}: the same nodes");
            assert_eq!(sorting.order, presorted.order, "{what}: the same leaf order");
            assert_eq!(sorting.escape, presorted.escape, "{what}: the same escape layout");
        }
        let costs =
            super::Costs { traversal: 1.0, intersection: 1.0, max_leaf_size: 8, depth_limit: super::DEPTH_LIMIT };
        for tris in [ties_and_duplicates(3000), soup_on_floor(5000), soup_in_a_room(2000)] {
            for bins in [4, 16, 33, 64] {
                both(&tris, &BinnedSah { bins, costs }, costs, &format!("{bins} bins"));
            }
            both(&tris, &SweepSah { costs }, costs, "sweep");
            // Leaves of one and of four: more levels swept, the middle split of duplicates above
            // the leaf size, and (limit 10) subtrees near the depth limit left to the per-node path.
            for (max_leaf_size, depth_limit) in [(1, super::DEPTH_LIMIT), (4, super::DEPTH_LIMIT), (1, 10)] {
                let costs = super::Costs { max_leaf_size, depth_limit, ..costs };
                both(
                    &tris,
                    &BinnedSah { bins: 16, costs },
                    costs,
                    &format!("leaves of {max_leaf_size}, limit {depth_limit}"),
                );
            }
        }
    }

    /// The leaf order with each leaf's triangles sorted: the serial partition is in place and
    /// unstable, the parallel one stable, so only the order inside a leaf may differ.
    fn leaf_sets(t: &super::BuiltTree) -> Vec<u32> {
        let mut order = t.order.clone();
        for n in t.nodes.iter().filter(|n| n.count > 0) {
            order[n.index as usize..(n.index + n.count) as usize].sort_unstable();
        }
        order
    }

    /// A soup with a large floor under it, so that the large-triangle candidate wins some nodes.
    fn soup_on_floor(n: usize) -> Vec<[Vec3; 3]> {
        let mut tris = soup(n);
        let (a, b, c, d) = (
            Vec3::new(-1.0, -0.5, -1.0),
            Vec3::new(11.0, -0.5, -1.0),
            Vec3::new(11.0, -0.5, 11.0),
            Vec3::new(-1.0, -0.5, 11.0),
        );
        tris.push([a, b, c]);
        tris.push([a, c, d]);
        tris
    }

    #[test]
    fn parallel_splits_of_large_nodes_build_the_serial_tree() {
        for tris in [soup(40_000), soup_on_floor(40_000)] {
            // 64: nearly every inner node above the sweep's size takes the parallel path, across
            // many chunks of its binning and partition.
            let serial = build_parallel(&tris, usize::MAX, 1);
            let parallel = build_parallel(&tris, 64, 3);
            for t in [&serial, &parallel] {
                check_shape(Tree::child_pair(&t.nodes), tris.len() as u32).expect("valid tree");
                let mut order = t.order.clone();
                order.sort_unstable();
                assert!(order.iter().enumerate().all(|(i, &o)| i as u32 == o), "leaf order is a permutation");
            }
            // The same splits, hence the same boxes and SAH cost, bit for bit.
            assert_eq!(serial.nodes, parallel.nodes);
            assert_eq!(leaf_sets(&serial), leaf_sets(&parallel));
            let (a, b) =
                (stats(Tree::child_pair(&serial.nodes), 1.0, 1.0), stats(Tree::child_pair(&parallel.nodes), 1.0, 1.0));
            assert_eq!(a.sah_cost, b.sah_cost);
            assert!(a.node_count > 2 * super::PARALLEL_EMIT, "big enough to write the layouts in parallel");
        }
    }

    #[test]
    fn the_parallel_build_does_not_depend_on_the_number_of_threads() {
        let tris = soup_on_floor(40_000);
        let one = build_parallel(&tris, 64, 1);
        for threads in [2, 5] {
            let many = build_parallel(&tris, 64, threads);
            assert_eq!(one.nodes, many.nodes, "{threads} threads");
            assert_eq!(one.order, many.order, "{threads} threads");
            assert_eq!(one.escape, many.escape, "{threads} threads");
        }
    }

    #[test]
    fn packed_and_gapped_subtrees_give_the_same_tree() {
        // Every subtree gapped (built in parallel from two primitives on), packed below the
        // default size, and packed throughout: the same nodes, leaf order and escape layout,
        // with and without the reinsertion in the top (which reads the slots too).
        let costs =
            super::Costs { traversal: 1.0, intersection: 1.0, max_leaf_size: 8, depth_limit: super::DEPTH_LIMIT };
        let splitter = crate::binned::BinnedSah { bins: 16, costs };
        for (what, tris) in [("soup on a floor", soup_on_floor(40_000)), ("room", soup_in_a_room(5_000))] {
            for reshape_top in [false, true] {
                let build = |parallel_subtrees| {
                    let ctx = super::Ctx {
                        parallel_subtrees,
                        reshape_top,
                        ..super::Ctx::new(&splitter, costs, None, super::PARALLEL_NODE)
                    };
                    build_refs(&tris, ctx)
                };
                let gapped = build(1);
                check_shape(Tree::child_pair(&gapped.nodes), tris.len() as u32).expect("valid tree");
                for parallel_subtrees in [super::PARALLEL_SUBTREES, usize::MAX] {
                    let packed = build(parallel_subtrees);
                    let case = format!("{what}, packed below {parallel_subtrees}, top {reshape_top}");
                    assert_eq!(gapped.nodes, packed.nodes, "{case}");
                    assert_eq!(gapped.order, packed.order, "{case}");
                    assert_eq!(gapped.escape, packed.escape, "{case}");
                }
            }
        }
    }

    #[test]
    fn the_checked_references_are_the_references_and_their_bounds() {
        let mut tris = soup_on_floor(50_000);
        // Finite extremes pass the check.
        tris[17][1] = Vec3::splat(f32::MAX);
        tris[18][2] = Vec3::new(f32::MIN, 0.0, -0.0);
        let (refs, root) = super::prim_refs_checked(&tris).expect("finite");
        let plain = super::prim_refs(&tris);
        let bits = |p: &super::PrimRef| (p.min.map(f32::to_bits), p.id, p.max.map(f32::to_bits), p.area.to_bits());
        assert!(refs.len() == plain.len() && refs.iter().zip(&plain).all(|(a, b)| bits(a) == bits(b)));
        let nb = super::bounds_of(&plain);
        assert_eq!((root.aabb, root.centroids), (nb.aabb, nb.centroids));
        // The first triangle with a coordinate that is not finite, wherever it lies.
        for (at, bad) in [(0, f32::NAN), (16_383, f32::INFINITY), (16_384, f32::NEG_INFINITY), (49_999, f32::NAN)] {
            for corner in 0..3 {
                let mut t = tris.clone();
                t[at][corner][corner] = bad;
                t[49_999][0].x = f32::INFINITY;
                assert_eq!(super::prim_refs_checked(&t).err(), Some(at), "{bad} at {at}, corner {corner}");
            }
        }
    }

    #[test]
    fn the_escape_layout_from_the_build_is_the_child_pair_tree_depth_first() {
        let tris = soup_on_floor(40_000);
        let t = build_parallel(&tris, 64, 3);
        let escape = t.escape.expect("asked for");
        assert_eq!(escape, bvh_format::tree::escape_from_child_pair(&t.nodes));
        check_shape(Tree::escape(&escape), tris.len() as u32).expect("valid escape tree");
    }

    /// The leaves as (box, sorted triangles), sorted: what the reinsertion must keep.
    fn leaves(t: &super::BuiltTree) -> Vec<([u32; 6], Vec<u32>)> {
        let mut v: Vec<([u32; 6], Vec<u32>)> = t
            .nodes
            .iter()
            .filter(|n| n.count > 0)
            .map(|n| {
                let mut tris = t.order[n.index as usize..(n.index + n.count) as usize].to_vec();
                tris.sort_unstable();
                let b = [n.min[0], n.min[1], n.min[2], n.max[0], n.max[1], n.max[2]].map(f32::to_bits);
                (b, tris)
            })
            .collect();
        v.sort_unstable();
        v
    }

    /// A room of six two-triangle walls around a soup of small triangles, with a mirror-like quad
    /// in front of one wall: the large-triangle candidate sends the walls one way and the rest the
    /// other, which the reinsertion in the top then improves on (crate::top).
    fn soup_in_a_room(n: usize) -> Vec<[Vec3; 3]> {
        // The soup fills a tenth of the room's width, as the objects of scenes/room.toml do.
        let mut tris: Vec<[Vec3; 3]> = soup(n).iter().map(|t| t.map(|v| v * 0.14 + Vec3::splat(2.0))).collect();
        let quad = |c: [Vec3; 4]| [[c[0], c[1], c[2]], [c[0], c[2], c[3]]];
        let (lo, hi) = (-2.0f32, 12.0f32);
        let v = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        for (axis, at) in [(0, lo), (0, hi), (1, lo), (1, hi), (2, lo), (2, hi)] {
            let p = |a: f32, b: f32| match axis {
                0 => v(at, a, b),
                1 => v(a, at, b),
                _ => v(a, b, at),
            };
            tris.extend(quad([p(lo, lo), p(hi, lo), p(hi, hi), p(lo, hi)]));
        }
        tris.extend(quad([
            v(1.0, 4.0, lo + 0.05),
            v(8.0, 4.0, lo + 0.05),
            v(8.0, 9.0, lo + 0.05),
            v(1.0, 9.0, lo + 0.05),
        ]));
        tris
    }

    #[test]
    fn reinsertion_in_the_top_lowers_the_cost_and_keeps_every_leaf() {
        for tris in [soup_in_a_room(20_000), soup_on_floor(20_000), soup(3000)] {
            let plain = build_ctx(&tris, super::PARALLEL_NODE, 2, false);
            let reshaped = build_ctx(&tris, super::PARALLEL_NODE, 2, true);
            for t in [&plain, &reshaped] {
                check_shape(Tree::child_pair(&t.nodes), tris.len() as u32).expect("valid tree");
                let escape = t.escape.as_ref().expect("asked for");
                assert_eq!(*escape, bvh_format::tree::escape_from_child_pair(&t.nodes));
                let mut order = t.order.clone();
                order.sort_unstable();
                assert!(order.iter().enumerate().all(|(i, &o)| i as u32 == o), "leaf order is a permutation");
            }
            assert_eq!(leaves(&plain), leaves(&reshaped), "the same leaves, boxes and triangles");
            let (a, b) =
                (stats(Tree::child_pair(&plain.nodes), 1.0, 1.0), stats(Tree::child_pair(&reshaped.nodes), 1.0, 1.0));
            assert!(b.sah_cost <= a.sah_cost, "SAH {} after reinsertion, {} before", b.sah_cost, a.sah_cost);
            assert!(b.max_depth <= a.max_depth, "{} levels after reinsertion, {} before", b.max_depth, a.max_depth);
            assert_eq!(a.node_count, b.node_count);
        }
        // In the room the top is far from the best: the reinsertion must find something.
        let tris = soup_in_a_room(20_000);
        let (a, b) =
            (build_ctx(&tris, super::PARALLEL_NODE, 1, false), build_ctx(&tris, super::PARALLEL_NODE, 1, true));
        let (a, b) = (
            stats(Tree::child_pair(&a.nodes), 1.0, 1.0).sah_cost,
            stats(Tree::child_pair(&b.nodes), 1.0, 1.0).sah_cost,
        );
        assert!(b < a * 0.99, "room: SAH {b} after reinsertion, {a} before");
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
