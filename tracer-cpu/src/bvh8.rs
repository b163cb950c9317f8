//! The wide BVHs for single rays, Embree's way: the file's binary SAH tree collapsed at load into
//! nodes of up to `W` children whose boxes lie component by component (structure of arrays), so
//! one SIMD sequence tests a ray against all of them; leaves of up to `W` triangles, also
//! structure of arrays, so one sequence tests the ray against all of a leaf's triangles with the
//! frame's triangle test. Two widths share every line of it ([`WideBvh`]): [`Bvh8`] (8 children,
//! one 256-bit AVX2 sequence per node or leaf) and [`Bvh4`] (4 children, one 128-bit sequence).
//! Three paths ([`Simd`]): AVX-512 and AVX2 (the same walk compiled for each; the widest the CPU
//! has is the default) and a portable one; `crate::packet8` traces coherent packets of 8 rays
//! through the 8-wide tree.
//!
//! The collapse (Ylitie, Karras and Laine, "Efficient Incoherent Ray Traversal on GPUs Through
//! Compressed Wide BVHs", 2017): every child slot of a wide node is a node of the binary tree,
//! made either a leaf block (a subtree of at most `W` triangles, whatever its binary shape: testing
//! `W` triangles costs one sequence, like testing one) or a wide node of its own, and a wide node's
//! `W` slots are spread over its binary subtree. Which, is decided bottom-up by dynamic programming
//! for the least SAH cost (a slot's box area times the cost of testing a node's boxes or a block's
//! triangles, `collapse`'s `NODE_COST` and `BLOCK_COST`), not greedily as Embree's BVH8 collapse does
//! (open the child of the largest area until the node is full; every subtree of at most `W`
//! triangles a block), which this replaced: the greedy collapse leaves many nodes of 2 children
//! (30% of the dragon's) and boxes a block's far-apart triangles together. Per ray the SAH
//! collapse enters 1-3% fewer nodes and tests 6-10% fewer triangles, and on one thread of the
//! 2-core VM gained on 12 of the ray report's 15 rows against Embree (the million-triangle
//! scene's 6-16 points; docs/cpu-benchmark-log.md, "Issue 11: the SAH collapse"). The boxes are the file's own, so every box a wide traversal tests is one the
//! ordered traversal tests too, entered wherever the ordered traversal enters it (and within a
//! rounding of the exit beyond: `geometry::may_hold_wide`, `geometry::exit_bound` for any-hit
//! rays), and the triangle test is the scalar
//! one, lane by lane, in the same operations: both find exactly the same hits (closest hit: the nearest, ties to the lower
//! triangle index, whatever the order of the tests; `tests/hits.rs` holds every path to that).
//!
//! Derived at load from the child-pair layout ([`WideBvh::new`], in parallel on rayon's pool:
//! `collapse`; on the H100 machine's 16-core host 2.8 ms for the bunny, 16 ms for the dragon and
//! 18 ms for the million-triangle scene on 16 threads, 9, 129 and 145 ms on one;
//! `examples/load_profile.rs` and `examples/ray_report.rs` print it), not stored in the file.
//! Arrays of 32 MiB or more ask for transparent huge pages, as Embree's allocator does (see
//! `HUGE_TREE`).

mod collapse;

use crate::geometry::{self, Cost, Hit, Ray, TriangleTest, may_hold};
use crate::traverse::Stack;
use crate::vertices::TriangleSource;
use bvh_format::{Node, Triangle};
#[cfg(test)]
use collapse::{BLOCK_COST, NODE_COST, half_area};

/// Children of a node of the 8-wide BVH, and triangles of its leaf blocks.
pub const WIDTH: usize = 8;

/// A child reference: a wide node's index, or with this bit a leaf block's index.
pub(crate) const LEAF: u32 = 1 << 31;

/// `[f(0), f(1), f(2)]`, for the walks instead of `array::map` and `array::from_fn`. Those run
/// through core's generic helpers, which rustc may put into another codegen unit than the walk
/// that calls them, out of reach of its inlining until link time: where it did, the packet walk
/// compiled with 12% more instructions per primary packet (1.7 times the stack moves), from an
/// unrelated change elsewhere in the crate (docs/cpu-benchmark-log.md, stop 49). Always inlined,
/// so a copy sits beside every caller.
#[inline(always)]
pub(crate) fn each3<T>(mut f: impl FnMut(usize) -> T) -> [T; 3] {
    [f(0), f(1), f(2)]
}

/// A wide node: the boxes of up to `W` children, component by component.
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug)]
pub struct WideNode<const W: usize = WIDTH> {
    /// Per child: min x, min y, min z, max x, max y, max z. Empty slots hold an inverted
    /// infinite box and are masked out by `valid` as well.
    pub bounds: [[f32; W]; 6],
    /// Per child: a wide node's index, or [`LEAF`] | a leaf block's index.
    pub child: [u32; W],
    /// Bit `i` set where slot `i` holds a child.
    pub valid: u32,
}

impl<const W: usize> WideNode<W> {
    fn empty() -> Self {
        let mut bounds = [[f32::INFINITY; W]; 6];
        bounds[3..].iter_mut().for_each(|b| *b = [f32::NEG_INFINITY; W]);
        Self { bounds, child: [u32::MAX; W], valid: 0 }
    }

    fn set(&mut self, slot: usize, min: [f32; 3], max: [f32; 3]) {
        for a in 0..3 {
            self.bounds[a][slot] = min[a];
            self.bounds[3 + a][slot] = max[a];
        }
        self.valid |= 1 << slot;
    }
}

/// Up to `W` triangles of a leaf, component by component: the vertices exactly as stored and the
/// triangle's index in leaf order. Empty lanes hold NaN vertices (which no test hits) and index
/// `u32::MAX`. The plane normal ([`geometry::plane_normal`]) is computed in the lanes where a test
/// needs it: stored, it made a block 7 cache lines instead of 5 (8b9ede9).
#[repr(C, align(64))]
#[derive(Clone, Copy, Debug)]
pub struct TriBlock<const W: usize = WIDTH> {
    /// `p[vertex][axis][lane]`.
    pub p: [[[f32; W]; 3]; 3],
    pub index: [u32; W],
}

impl<const W: usize> TriBlock<W> {
    fn new(tris: &(impl TriangleSource + ?Sized), indices: &[u32]) -> Self {
        let mut b = Self { p: [[[f32::NAN; W]; 3]; 3], index: [u32::MAX; W] };
        for (lane, &i) in indices.iter().enumerate() {
            let t = tris.triangle(i);
            for a in 0..3 {
                b.p[0][a][lane] = t.p0[a];
                b.p[1][a][lane] = t.p1[a];
                b.p[2][a][lane] = t.p2[a];
            }
            b.index[lane] = i;
        }
        b
    }

    /// The triangle in `lane`, as the scalar tests take it.
    pub(crate) fn triangle(&self, lane: usize) -> Triangle {
        let v = |k: usize| [self.p[k][0][lane], self.p[k][1][lane], self.p[k][2][lane]];
        Triangle::from_vertices(v(0), v(1), v(2))
    }

    /// Lanes holding a triangle.
    fn count(&self) -> u32 {
        self.index.iter().filter(|&&i| i != u32::MAX).count() as u32
    }
}

/// One cache line of a [`WideBvh`]'s arena.
#[repr(C, align(64))]
#[derive(Clone, Copy)]
pub(crate) struct Line(std::mem::MaybeUninit<[u8; 64]>);

impl Line {
    /// A line not written yet: the collapse writes every line of the arena once, and its nodes'
    /// padding never, so the bytes of a line need not be initialised.
    pub(crate) const UNWRITTEN: Line = Line(std::mem::MaybeUninit::uninit());
}

/// A wide BVH of a scene, `W` children per node and up to `W` triangles per leaf block, nodes and
/// blocks in one arena of cache lines: each node followed by its children's leaf blocks, then its
/// inner children's subtrees in slot order, so that a node and the blocks a ray tests next to it
/// lie together. Against nodes and blocks in two arrays (each depth first) the single rays gained
/// 0 to 3 points against Embree on every row of the H100 host's report and 1 to 2 on the VM
/// (docs/cpu-benchmark-log.md, stop 35).
pub struct WideBvh<const W: usize> {
    /// Nodes ([`WideNode`], 4 lines for the 8-wide BVH) and blocks ([`TriBlock`], 5 lines); a
    /// reference is the line a node or (with [`LEAF`]) a block starts at.
    lines: Vec<Line>,
    /// Nodes and blocks in the arena.
    counts: (usize, usize),
    /// The root's reference (a leaf for a scene of at most `W` triangles).
    pub(crate) root: u32,
    /// The instruction set the traversal runs with here ([`Simd::detect`]).
    simd: Simd,
    /// The most wide nodes on a path from the root to a leaf block.
    depth: usize,
}

/// The 8-wide BVH: one AVX2 sequence (256-bit) tests a ray against a node's 8 boxes or a leaf's
/// 8 triangles; the one `--method bvh8`, `bvh8-packet` and auto's single rays walk.
pub type Bvh8 = WideBvh<WIDTH>;

/// The 4-wide BVH: one 128-bit sequence tests a ray against a node's 4 boxes or a leaf's 4
/// triangles (`--method bvh4`): shallower than the binary tree, narrower than [`Bvh8`], fewer
/// boxes and triangles tested per ray than the 8-wide BVH in exchange for more steps.
pub type Bvh4 = WideBvh<4>;

/// The instruction sets the single-ray traversal is written for. Every one finds bit for bit
/// the same hits (the box and triangle tests are the scalar ones, operation by operation); they
/// differ in speed only.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Simd {
    /// One lane at a time: any CPU.
    Portable,
    /// A node's boxes or a leaf's triangles per sequence of AVX2-encoded instructions: 256-bit
    /// for the 8-wide BVH, 128-bit for the 4-wide one (and POPCNT for the work counts).
    Avx2,
    /// The AVX2 path compiled for AVX-512 (F, VL, DQ, BW): the same operations on the same
    /// registers' widths, with 32 of them instead of 16 and mask registers for the compares.
    /// The default where the CPU has it (a few points faster on both machines measured,
    /// docs/cpu-benchmark-log.md, stop 34).
    Avx512,
}

impl Simd {
    /// Every path, slowest first.
    pub const ALL: [Simd; 3] = [Simd::Portable, Simd::Avx2, Simd::Avx512];

    /// The name `TRACER_CPU_SIMD` takes.
    pub fn name(self) -> &'static str {
        match self {
            Simd::Portable => "portable",
            Simd::Avx2 => "avx2",
            Simd::Avx512 => "avx512",
        }
    }

    /// Whether this CPU runs the path.
    pub fn supported(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::is_x86_feature_detected as has;
            match self {
                Simd::Portable => true,
                // POPCNT and FMA come with AVX2 on every CPU that has it (Intel since Haswell,
                // AMD since Excavator); checked all the same, since the traversal is compiled
                // with them.
                Simd::Avx2 => has!("avx2") && has!("popcnt") && has!("fma"),
                Simd::Avx512 => {
                    Simd::Avx2.supported()
                        && has!("avx512f")
                        && has!("avx512vl")
                        && has!("avx512dq")
                        && has!("avx512bw")
                }
            }
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            self == Simd::Portable
        }
    }

    /// The paths this CPU runs, slowest first (what the tests check against each other).
    pub fn available() -> Vec<Simd> {
        Simd::ALL.into_iter().filter(|s| s.supported()).collect()
    }

    /// The path [`WideBvh::trace`] takes: the widest this CPU has; the environment variable
    /// `TRACER_CPU_SIMD` (`portable`, `avx2` or `avx512`) asks for a narrower one (a wider one
    /// than the CPU runs gets the widest it runs; a name it does not know is ignored).
    pub fn detect() -> Simd {
        let asked = std::env::var("TRACER_CPU_SIMD").ok().and_then(|v| Simd::parse(&v));
        Simd::best_up_to(asked.unwrap_or(Simd::Avx512))
    }

    /// The path `name` names (case and surrounding blanks ignored).
    pub fn parse(name: &str) -> Option<Simd> {
        Simd::ALL.into_iter().find(|s| s.name().eq_ignore_ascii_case(name.trim()))
    }

    /// The fastest path this CPU runs that is no wider than `cap`.
    pub fn best_up_to(cap: Simd) -> Simd {
        Simd::ALL.into_iter().rev().find(|s| *s <= cap && s.supported()).unwrap_or(Simd::Portable)
    }
}

/// A hit before its barycentrics are divided out, as the traversals keep it: `u = w1 * (1 / sum)`
/// and `v = w2 * (1 / sum)` (the portable traversal keeps `u`, `v` and 1, which gives the same
/// bits).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Found {
    pub t: f32,
    pub tri: u32,
    pub w1: f32,
    pub w2: f32,
    pub sum: f32,
}

impl Found {
    #[inline(always)]
    pub fn hit(self) -> Hit {
        let inv = 1.0 / self.sum;
        Hit { t: self.t, tri: self.tri, u: self.w1 * inv, v: self.w2 * inv }
    }
}

/// Wide BVHs of at least this many bytes ask for transparent huge pages
/// ([`bvh_format::memory::advise_huge_pages`]) where the kernel grants them on request (`madvise`):
/// an incoherent walk of a tree of tens of MB takes a TLB miss on most nodes and blocks with
/// 4 KiB pages (Zen 4's L2 TLB covers 12 MB of them), a page walk before the cache miss. A tree
/// the TLB covers gains nothing (the bunny's 5 MB traced AO and diffuse rays about 10 points
/// slower with them on the VM, docs/cpu-benchmark-log.md, branch sr11).
const HUGE_TREE: usize = 32 << 20;

impl<const W: usize> WideBvh<W> {
    /// Collapses the child-pair tree `nodes` over the triangles `tris` (leaf order, as
    /// [`bvh_format::SceneFile::leaf_triangles`] gives them).
    pub fn new(nodes: &[Node], tris: &[Triangle]) -> Self {
        Self::from_source(nodes, tris)
    }

    /// [`Self::new`] over the triangles of either vertex form: the leaf blocks are this BVH's
    /// own copy of the vertices, in the layout its SIMD test loads, whatever form they came from.
    pub fn from_source(nodes: &[Node], tris: &(impl TriangleSource + ?Sized)) -> Self {
        collapse::collapse(nodes, tris, collapse::Parallel::auto::<W>(nodes.len()))
    }

    /// The most entries a walk's stack holds: what is on it are children of the wide nodes on the
    /// path from where the walk started to the node it is at, at most `W - 1` of each.
    #[inline(always)]
    pub(crate) fn stack_bound(&self) -> usize {
        (W - 1) * self.depth.max(1)
    }

    /// The node `r` refers to.
    #[inline(always)]
    pub(crate) fn node(&self, r: u32) -> &WideNode<W> {
        let lines = &self.lines[r as usize..r as usize + size_of::<WideNode<W>>() / 64];
        // SAFETY: the slice (bounds-checked) holds a node's bytes, aligned to 64; a node is
        // floats and integers only, so any bytes are a valid one (a wrong `r` reads garbage,
        // never undefined behaviour).
        unsafe { &*lines.as_ptr().cast::<WideNode<W>>() }
    }

    /// The node `r` refers to, unchecked.
    ///
    /// # Safety
    /// `r` is a node reference of this BVH.
    #[inline(always)]
    pub(crate) unsafe fn node_unchecked(&self, r: u32) -> &WideNode<W> {
        debug_assert!(r as usize + size_of::<WideNode<W>>() / 64 <= self.lines.len());
        // SAFETY: the caller's promise.
        unsafe { &*self.lines.as_ptr().add(r as usize).cast::<WideNode<W>>() }
    }

    /// The leaf block `r` (with [`LEAF`]) refers to.
    #[inline(always)]
    pub(crate) fn block(&self, r: u32) -> &TriBlock<W> {
        let at = (r & !LEAF) as usize;
        let lines = &self.lines[at..at + size_of::<TriBlock<W>>() / 64];
        // SAFETY: as in `node`.
        unsafe { &*lines.as_ptr().cast::<TriBlock<W>>() }
    }

    /// The leaf block `r` refers to, unchecked.
    ///
    /// # Safety
    /// `r` is a block reference of this BVH.
    #[inline(always)]
    pub(crate) unsafe fn block_unchecked(&self, r: u32) -> &TriBlock<W> {
        debug_assert!(((r & !LEAF) as usize) + size_of::<TriBlock<W>>() / 64 <= self.lines.len());
        // SAFETY: the caller's promise.
        unsafe { &*self.lines.as_ptr().add((r & !LEAF) as usize).cast::<TriBlock<W>>() }
    }

    /// The start of the arena, for prefetches.
    #[inline(always)]
    pub(crate) fn lines_ptr(&self) -> *const i8 {
        self.lines.as_ptr().cast()
    }

    /// Wide nodes and leaf blocks.
    pub fn len(&self) -> (usize, usize) {
        self.counts
    }

    /// Whether the tree holds no node (a scene of at most `W` triangles is one leaf block).
    pub fn is_empty(&self) -> bool {
        self.counts.0 == 0
    }

    /// Bytes of nodes and blocks.
    pub fn bytes(&self) -> usize {
        std::mem::size_of_val(&self.lines[..])
    }

    /// The path [`Self::trace`] runs.
    pub fn simd(&self) -> Simd {
        self.simd
    }

    /// Closest hit in `(t_min, t_max]` (`ANY` false) or any hit there (`ANY` true) with the
    /// triangle test `T`, adding the boxes and triangles tested to `cost`: with the fastest
    /// instruction set this CPU has ([`Simd::detect`]).
    #[inline]
    pub fn trace<const ANY: bool, T: TriangleTest>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        stack: &mut Stack,
        cost: &mut Cost,
    ) -> Option<Hit> {
        self.trace_from::<ANY, T>(self.simd, self.root, ray, t_min, (t_max, u32::MAX), stack, cost).map(Found::hit)
    }

    /// [`Self::trace`] on the path `simd` (the tests run every path this CPU has); a path the CPU
    /// lacks ([`Simd::supported`]) runs the fastest one below it that it has.
    #[inline]
    pub fn trace_on<const ANY: bool, T: TriangleTest>(
        &self,
        simd: Simd,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        stack: &mut Stack,
        cost: &mut Cost,
    ) -> Option<Hit> {
        let simd = Simd::best_up_to(simd);
        self.trace_from::<ANY, T>(simd, self.root, ray, t_min, (t_max, u32::MAX), stack, cost).map(Found::hit)
    }

    /// The subtree `start`'s hits that beat `best` (distance, triangle; [`Hit::beats`]), the
    /// packets' way to finish a lane alone, on the path `simd`, which this CPU must support.
    #[inline]
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn trace_from<const ANY: bool, T: TriangleTest>(
        &self,
        simd: Simd,
        start: u32,
        ray: &Ray,
        t_min: f32,
        best: (f32, u32),
        stack: &mut Stack,
        cost: &mut Cost,
    ) -> Option<Found> {
        #[cfg(target_arch = "x86_64")]
        {
            use std::arch::x86_64::{__m128, __m256};
            // SAFETY (all four): the callers pass a supported path (AVX2, or AVX-512 F, VL, DQ
            // and BW with AVX2). The register holds `W` lanes.
            if simd == Simd::Avx512 {
                if W == 8 {
                    return unsafe {
                        avx2::trace_evex::<ANY, T, __m256, W>(self, start, ray, t_min, best, stack, cost)
                    };
                }
                if W == 4 {
                    return unsafe {
                        avx2::trace_evex::<ANY, T, __m128, W>(self, start, ray, t_min, best, stack, cost)
                    };
                }
            }
            if simd >= Simd::Avx2 {
                if W == 8 {
                    return unsafe { avx2::trace::<ANY, T, __m256, W>(self, start, ray, t_min, best, stack, cost) };
                }
                if W == 4 {
                    return unsafe { avx2::trace::<ANY, T, __m128, W>(self, start, ray, t_min, best, stack, cost) };
                }
            }
        }
        let _ = simd;
        self.portable::<ANY, T>(start, ray, t_min, best, stack, cost)
    }

    /// [`Self::trace`] without SIMD, for CPUs without AVX2 and as the tests' second opinion.
    pub fn trace_portable<const ANY: bool, T: TriangleTest>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        stack: &mut Stack,
        cost: &mut Cost,
    ) -> Option<Hit> {
        self.trace_on::<ANY, T>(Simd::Portable, ray, t_min, t_max, stack, cost)
    }

    fn portable<const ANY: bool, T: TriangleTest>(
        &self,
        start: u32,
        ray: &Ray,
        t_min: f32,
        (t_max, tri): (f32, u32),
        stack: &mut Stack,
        cost: &mut Cost,
    ) -> Option<Found> {
        let mut best = Hit { t: t_max, tri, u: 0.0, v: 0.0 };
        let mut found = false;
        let inv_far = ray.inv_dir.to_array().map(geometry::inv_far);
        let mut stack = stack.bounded(self.stack_bound());
        let mut cur = start;
        loop {
            if cur & LEAF == 0 {
                let node = self.node(cur);
                let mut hits: [(f32, u32); W] = [(0.0, 0); W];
                let mut n = 0;
                for slot in (0..W).filter(|&s| node.valid & (1 << s) != 0) {
                    cost.nodes += 1;
                    let lane = |k: usize| [node.bounds[k][slot], node.bounds[k + 1][slot], node.bounds[k + 2][slot]];
                    let child = Node { min: lane(0), count: 0, max: lane(3), index: 0 };
                    // The entry as the binary traversals compute it, the exits as the SIMD walk
                    // compares them (for any hit `geometry::before_exit`, see `avx2::trace`).
                    let (near, far) = geometry::slab_range(&child, ray, best.t);
                    let leaves_after = |a: usize| {
                        let plane = if ray.inv_dir[a].is_sign_negative() { child.min[a] } else { child.max[a] };
                        geometry::before_exit(near, plane, ray.origin[a], inv_far[a])
                    };
                    let enters = if ANY {
                        leaves_after(0) && leaves_after(1) && leaves_after(2) && geometry::may_hold_wide(near, best.t)
                    } else {
                        geometry::may_hold_wide(near, far)
                    };
                    if enters {
                        hits[n] = (near, node.child[slot]);
                        n += 1;
                    }
                }
                if ANY && n > 0 {
                    // As the SIMD walk: no order, the lowest slot entered, the others pushed.
                    for &(near, r) in &hits[1..n] {
                        stack.push((r, near));
                    }
                    cur = hits[0].1;
                    continue;
                }
                hits[..n].sort_by(|a, b| b.0.total_cmp(&a.0));
                if n > 0 {
                    for &(near, r) in &hits[..n - 1] {
                        stack.push((r, near));
                    }
                    cur = hits[n - 1].1;
                    continue;
                }
            } else {
                let block = self.block(cur);
                cost.tris += block.count();
                for lane in (0..W).filter(|&l| block.index[l] != u32::MAX) {
                    let i = block.index[lane];
                    if let Some((t, u, v)) = T::intersect(&block.triangle(lane), ray, t_min, best.t)
                        && Hit::beats(t, i, best.t, best.tri)
                    {
                        best = Hit { t, tri: i, u, v };
                        found = true;
                        if ANY {
                            break;
                        }
                    }
                }
                if ANY && found {
                    break;
                }
            }
            loop {
                match stack.pop() {
                    None => {
                        return found.then_some(Found { t: best.t, tri: best.tri, w1: best.u, w2: best.v, sum: 1.0 });
                    }
                    Some((r, near)) if may_hold(near, best.t) => {
                        cur = r;
                        break;
                    }
                    Some(_) => {}
                }
            }
        }
        Some(Found { t: best.t, tri: best.tri, w1: best.u, w2: best.v, sum: 1.0 })
    }
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod avx2 {
    use super::{Found, LEAF, TriBlock, WideBvh, WideNode};
    use crate::geometry::{self, Cost, EXIT_SCALE, Hit, Ray, TriangleTest, may_hold};
    use crate::traverse::Stack;
    use render_spec::Intersect;
    use std::arch::x86_64::*;

    /// One register of lanes: `__m128` (4, the 4-wide BVH's nodes and blocks) or `__m256` (8, the
    /// 8-wide BVH's), so that one traversal and one leaf test serve both widths. Each operation is
    /// the one instruction of its name, lane by lane the `f32` operation. Only for code compiled
    /// with AVX2 and entered where the CPU has it (the methods are inlined into it; as in
    /// `crate::wide`, no lane operation is written inside a closure).
    pub(crate) trait Vector: Copy {
        /// Lanes.
        const N: usize;
        fn splat(v: f32) -> Self;
        fn zero() -> Self;
        /// The `W` floats of `a`; `W` must be [`Self::N`].
        fn load<const W: usize>(a: &[f32; W]) -> Self;
        fn store<const W: usize>(self) -> [f32; W];
        /// Bit `i` set where lane `i` of `index` is `u32::MAX` (an empty lane of a leaf block).
        fn unset<const W: usize>(index: &[u32; W]) -> u32;
        fn add(self, o: Self) -> Self;
        fn sub(self, o: Self) -> Self;
        fn mul(self, o: Self) -> Self;
        fn div(self, o: Self) -> Self;
        fn and(self, o: Self) -> Self;
        fn or(self, o: Self) -> Self;
        fn cmp<const P: i32>(self, o: Self) -> Self;
        /// The lanes' sign bits.
        fn bits(self) -> u32;
        /// Lane by lane the larger of the lanes' bits read as signed integers: for floats of clear
        /// sign bit the larger float, in one cycle where the float `max` takes four.
        fn imax(self, o: Self) -> Self;
        /// `self * b + c`, rounded once.
        fn fmadd(self, b: Self, c: Self) -> Self;
    }

    // SAFETY (every `unsafe` block in the impls): AVX2 register arithmetic, which the callers
    // guarantee (see `Vector`); loads and stores of `N` lanes, `W` = `N` asserted first (a
    // constant comparison, which the compiler removes).
    macro_rules! vector {
        ($v:ty, $n:literal, $vi:ty, $set1:ident, $setzero:ident, $loadu:ident, $storeu:ident,
         $loadu_si:ident, $set1_epi32:ident, $cmpeq_epi32:ident, $castsi_ps:ident,
         $add:ident, $sub:ident, $mul:ident, $div:ident, $and:ident,
         $or:ident, $cmp:ident, $movemask:ident, $imax:ident, $castps_si:ident, $fmadd:ident) => {
            impl Vector for $v {
                const N: usize = $n;
                #[inline(always)]
                fn splat(v: f32) -> Self {
                    unsafe { $set1(v) }
                }
                #[inline(always)]
                fn zero() -> Self {
                    unsafe { $setzero() }
                }
                #[inline(always)]
                fn load<const W: usize>(a: &[f32; W]) -> Self {
                    assert!(W == Self::N);
                    unsafe { $loadu(a.as_ptr()) }
                }
                #[inline(always)]
                fn store<const W: usize>(self) -> [f32; W] {
                    assert!(W == Self::N);
                    let mut a = [0f32; W];
                    unsafe { $storeu(a.as_mut_ptr(), self) };
                    a
                }
                #[inline(always)]
                fn unset<const W: usize>(index: &[u32; W]) -> u32 {
                    assert!(W == Self::N);
                    unsafe {
                        let i = $loadu_si(index.as_ptr().cast::<$vi>());
                        $movemask($castsi_ps($cmpeq_epi32(i, $set1_epi32(-1)))) as u32
                    }
                }
                #[inline(always)]
                fn add(self, o: Self) -> Self {
                    unsafe { $add(self, o) }
                }
                #[inline(always)]
                fn sub(self, o: Self) -> Self {
                    unsafe { $sub(self, o) }
                }
                #[inline(always)]
                fn mul(self, o: Self) -> Self {
                    unsafe { $mul(self, o) }
                }
                #[inline(always)]
                fn div(self, o: Self) -> Self {
                    unsafe { $div(self, o) }
                }
                #[inline(always)]
                fn and(self, o: Self) -> Self {
                    unsafe { $and(self, o) }
                }
                #[inline(always)]
                fn or(self, o: Self) -> Self {
                    unsafe { $or(self, o) }
                }
                #[inline(always)]
                fn cmp<const P: i32>(self, o: Self) -> Self {
                    unsafe { $cmp::<P>(self, o) }
                }
                #[inline(always)]
                fn bits(self) -> u32 {
                    unsafe { $movemask(self) as u32 }
                }
                #[inline(always)]
                fn imax(self, o: Self) -> Self {
                    unsafe { $castsi_ps($imax($castps_si(self), $castps_si(o))) }
                }
                #[inline(always)]
                fn fmadd(self, b: Self, c: Self) -> Self {
                    unsafe { $fmadd(self, b, c) }
                }
            }
        };
    }
    vector! {
        __m128, 4, __m128i, _mm_set1_ps, _mm_setzero_ps, _mm_loadu_ps, _mm_storeu_ps, _mm_loadu_si128, _mm_set1_epi32,
        _mm_cmpeq_epi32, _mm_castsi128_ps, _mm_add_ps, _mm_sub_ps, _mm_mul_ps, _mm_div_ps,
        _mm_and_ps, _mm_or_ps, _mm_cmp_ps, _mm_movemask_ps, _mm_max_epi32, _mm_castps_si128, _mm_fmadd_ps
    }
    vector! {
        __m256, 8, __m256i, _mm256_set1_ps, _mm256_setzero_ps, _mm256_loadu_ps, _mm256_storeu_ps, _mm256_loadu_si256,
        _mm256_set1_epi32, _mm256_cmpeq_epi32, _mm256_castsi256_ps, _mm256_add_ps, _mm256_sub_ps, _mm256_mul_ps,
        _mm256_div_ps, _mm256_and_ps, _mm256_or_ps, _mm256_cmp_ps,
        _mm256_movemask_ps, _mm256_max_epi32, _mm256_castps_si256, _mm256_fmadd_ps
    }

    /// The ray, splatted.
    pub(crate) struct Lanes<V> {
        pub o: [V; 3],
        pub d: [V; 3],
        pub inv: [V; 3],
    }

    /// `x`, read as one 4-byte load ([`read_ray`]).
    #[inline(always)]
    fn read_f32(x: &f32) -> f32 {
        // SAFETY: `x` is a reference, valid for reads.
        unsafe { std::ptr::read_volatile(x) }
    }

    /// The ray's nine floats, each read with a load of its own 4 bytes. A caller that has just
    /// made the ray (`Ray::new` right before the trace) leaves its fields in the store buffer,
    /// written 4 or 8 bytes at a time, and the compiler, left to itself, read them back 8 bytes at
    /// a time across two of those stores (`origin.z` with `dir.x`, `dir.x` with `dir.y`): such a
    /// load is not forwarded from the store buffer and waits for the stores to reach the cache, at
    /// the start of every ray's chain of dependent loads. The ray report, which makes each ray's
    /// inverse direction just before the trace as `rtcIntersect1` does, lost a fifth of the
    /// bunny's primary-ray speed to it on the VM (docs/cpu-benchmark-log.md, stop 33); the renderer,
    /// which makes its rays a stage ahead, measured the same with and without. A load of exactly
    /// one stored field is always forwarded; volatile keeps the compiler from merging the nine.
    #[inline(always)]
    pub(crate) fn read_ray(ray: &Ray) -> Ray {
        let v = |v: &glam::Vec3| glam::Vec3::new(read_f32(&v.x), read_f32(&v.y), read_f32(&v.z));
        Ray { origin: v(&ray.origin), dir: v(&ray.dir), inv_dir: v(&ray.inv_dir) }
    }

    impl<V: Vector> Lanes<V> {
        #[inline(always)]
        pub fn new(ray: &Ray) -> Self {
            let s = |v: glam::Vec3| [V::splat(v.x), V::splat(v.y), V::splat(v.z)];
            Self { o: s(ray.origin), d: s(ray.dir), inv: s(ray.inv_dir) }
        }
    }

    /// `p - o` per axis.
    #[inline(always)]
    fn sub3<V: Vector, const W: usize>(p: &[[f32; W]; 3], o: &[V; 3]) -> [V; 3] {
        [V::load(&p[0]).sub(o[0]), V::load(&p[1]).sub(o[1]), V::load(&p[2]).sub(o[2])]
    }

    /// The distances to the planes `b`, component `a` of the ray.
    #[inline(always)]
    fn dist<V: Vector, const W: usize>(b: &[f32; W], r: &Lanes<V>, a: usize) -> V {
        V::load(b).sub(r.o[a]).mul(r.inv[a])
    }

    /// `y * z' - z * y'` and so on: the cross product, in the scalar tests' order.
    #[inline(always)]
    pub(crate) fn cross<V: Vector>(a: &[V; 3], b: &[V; 3]) -> [V; 3] {
        [a[1].mul(b[2]).sub(a[2].mul(b[1])), a[2].mul(b[0]).sub(a[0].mul(b[2])), a[0].mul(b[1]).sub(a[1].mul(b[0]))]
    }

    /// [`crate::geometry::edge_function`], operation by operation.
    #[inline(always)]
    pub(crate) fn edge_function<V: Vector>(a: &[V; 3], b: &[V; 3], d: &[V; 3]) -> V {
        let e = [a[0].sub(b[0]), a[1].sub(b[1]), a[2].sub(b[2])];
        let s = [a[0].add(b[0]), a[1].add(b[1]), a[2].add(b[2])];
        dot(d, &cross(&e, &s))
    }

    /// `x[0] * y[0] + x[1] * y[1] + x[2] * y[2]`, in that order.
    #[inline(always)]
    pub(crate) fn dot<V: Vector>(x: &[V; 3], y: &[V; 3]) -> V {
        x[0].mul(y[0]).add(x[1].mul(y[1])).add(x[2].mul(y[2]))
    }

    /// `p[k] - p[0]` per axis: a triangle edge from its first vertex.
    #[inline(always)]
    fn edge<V: Vector, const W: usize>(p: &[[[f32; W]; 3]; 3], k: usize) -> [V; 3] {
        sub3(&p[k], &[V::load(&p[0][0]), V::load(&p[0][1]), V::load(&p[0][2])])
    }

    /// [`crate::geometry::intersect`] on the block's triangles, operation by operation; returns
    /// (hit mask, t, w1, w2, sum) (`u = w1 * (1 / sum)`, computed for the closest hit only).
    #[inline(always)]
    pub(crate) fn watertight<V: Vector, const W: usize>(b: &TriBlock<W>, r: &Lanes<V>, t_min: V, t_max: V) -> [V; 5] {
        let (o, d) = (&r.o, &r.d);
        let (a0, a1, a2) = (sub3(&b.p[0], o), sub3(&b.p[1], o), sub3(&b.p[2], o));
        let w2 = edge_function(&a0, &a1, d);
        let w0 = edge_function(&a1, &a2, d);
        let w1 = edge_function(&a2, &a0, d);
        let zero = V::zero();
        let positive = w0.cmp::<_CMP_GE_OQ>(zero).and(w1.cmp::<_CMP_GE_OQ>(zero)).and(w2.cmp::<_CMP_GE_OQ>(zero));
        let negative = w0.cmp::<_CMP_LE_OQ>(zero).and(w1.cmp::<_CMP_LE_OQ>(zero)).and(w2.cmp::<_CMP_LE_OQ>(zero));
        let inside = positive.or(negative);
        // Most blocks a ray enters hold no triangle it passes through: those skip the plane
        // normal, the distance and its division (a third of the test's work).
        if inside.bits() == 0 {
            return [zero; 5];
        }
        let sum = w0.add(w1).add(w2);
        // The plane normal, as geometry::plane_normal computes it.
        let n = cross(&edge(&b.p, 1), &edge(&b.p, 2));
        let den = dot(&n, d);
        let t = dot(&n, &a0).div(den);
        let mut m = inside.and(sum.cmp::<_CMP_NEQ_OQ>(zero));
        m = m.and(den.cmp::<_CMP_NEQ_OQ>(zero));
        m = m.and(t.cmp::<_CMP_GT_OQ>(t_min));
        m = m.and(t.cmp::<_CMP_LE_OQ>(t_max));
        [m, t, w1, w2, sum]
    }

    /// [`crate::geometry::intersect_moller_trumbore`] on the block's triangles, operation by
    /// operation; returns (hit mask, t, u, v, 1).
    #[inline(always)]
    pub(crate) fn moller_trumbore<V: Vector, const W: usize>(
        b: &TriBlock<W>,
        r: &Lanes<V>,
        t_min: V,
        t_max: V,
    ) -> [V; 5] {
        let (o, d) = (&r.o, &r.d);
        let v0 = [V::load(&b.p[0][0]), V::load(&b.p[0][1]), V::load(&b.p[0][2])];
        let (e1, e2) = (edge(&b.p, 1), edge(&b.p, 2));
        // The scalar test's cross products (a product's operand order changes no bit).
        let p = cross(d, &e2);
        let det = dot(&e1, &p);
        let one = V::splat(1.0);
        let inv = one.div(det);
        let s = [o[0].sub(v0[0]), o[1].sub(v0[1]), o[2].sub(v0[2])];
        let u = dot(&s, &p).mul(inv);
        let q = cross(&s, &e1);
        let v = dot(d, &q).mul(inv);
        let t = dot(&e2, &q).mul(inv);
        let zero = V::zero();
        // The scalar conditions exactly, NaN included (see packet.rs).
        let mut m = det.cmp::<_CMP_NEQ_UQ>(zero);
        m = m.and(u.cmp::<_CMP_GE_OQ>(zero));
        m = m.and(u.cmp::<_CMP_LE_OQ>(one));
        m = m.and(v.cmp::<_CMP_NLT_UQ>(zero));
        m = m.and(u.add(v).cmp::<_CMP_NGT_UQ>(one));
        m = m.and(t.cmp::<_CMP_GT_OQ>(t_min));
        m = m.and(t.cmp::<_CMP_LE_OQ>(t_max));
        [m, t, u, v, one]
    }

    /// Tests the block's triangles against the ray, updating `best`; true where one beat it.
    /// `#[inline(always)]` without target features, so that it is inlined into both traversals
    /// (a `#[target_feature]` function cannot be `#[inline(always)]`, and LLVM kept one out of
    /// line, at a cost of 10%).
    #[inline(always)]
    pub(super) fn leaf<const ANY: bool, T: TriangleTest, V: Vector, const W: usize>(
        block: &TriBlock<W>,
        r: &Lanes<V>,
        t_min: V,
        best: &mut Found,
        cost: &mut Cost,
    ) -> bool {
        cost.tris += W as u32 - V::unset(&block.index).count_ones();
        let [m, t, w1, w2, sum] = match T::KIND {
            Intersect::Watertight => watertight(block, r, t_min, V::splat(best.t)),
            Intersect::MollerTrumbore => moller_trumbore(block, r, t_min, V::splat(best.t)),
        };
        let mut hit = m.bits();
        let mut found = false;
        if hit != 0 {
            let (t, w1, w2, sum) = (t.store::<W>(), w1.store::<W>(), w2.store::<W>(), sum.store::<W>());
            while hit != 0 {
                let i = hit.trailing_zeros() as usize;
                hit &= hit - 1;
                if Hit::beats(t[i], block.index[i], best.t, best.tri) {
                    *best = Found { t: t[i], tri: block.index[i], w1: w1[i], w2: w2[i], sum: sum[i] };
                    found = true;
                    if ANY {
                        break;
                    }
                }
            }
        }
        found
    }

    /// Asks for the cache lines of the node or leaf block `r`.
    #[inline(always)]
    pub(crate) fn prefetch<const W: usize>(bvh: &WideBvh<W>, r: u32) {
        let lines = if r & LEAF == 0 { size_of::<WideNode<W>>() } else { size_of::<TriBlock<W>>() } / 64;
        let ptr = bvh.lines_ptr().wrapping_add(64 * (r & !LEAF) as usize);
        for l in 0..lines.min(PREFETCH_LINES) {
            // SAFETY: a prefetch never faults, whatever the address.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(ptr.wrapping_add(64 * l)) };
        }
    }
    const PREFETCH_LINES: usize = 8;

    /// Defines an entry to [`walk`] compiled with the target features `$features`.
    macro_rules! walk_compiled_for {
        ($(#[$doc:meta])* $name:ident, $features:literal) => {
            $(#[$doc])*
            #[target_feature(enable = $features)]
            pub fn $name<const ANY: bool, T: TriangleTest, V: Vector, const W: usize>(
                bvh: &WideBvh<W>,
                start: u32,
                ray: &Ray,
                t_min: f32,
                best: (f32, u32),
                stack: &mut Stack,
                cost: &mut Cost,
            ) -> Option<Found> {
                walk::<ANY, T, V, W>(bvh, start, ray, t_min, best, stack, cost)
            }
        };
    }

    walk_compiled_for!(
        /// [`WideBvh::trace`] with AVX2: the `W` children's boxes or a leaf's `W` triangles in
        /// registers `V` of `W` lanes (256-bit for the 8-wide BVH, 128-bit for the 4-wide one).
        ///
        /// The box test decides as the scalar slab test with [`crate::geometry::may_hold_wide`]: per
        /// axis the entry and exit distances are `(plane - origin) * inverse direction`; which plane
        /// is entered is known from the sign of the inverse direction (for a finite one the rounding
        /// is monotonic, so it is the smaller distance, as the scalar `min` finds). A NaN distance
        /// (`0 * inf`: the origin on the plane of an axis the ray is parallel to) leaves its axis out,
        /// as the scalar test does. The distances are then reduced as Embree's node test does, not in
        /// a chain of float `max` and `min` (four cycles each; the walk waits on that chain at every
        /// node), child for child with the chain's decision:
        /// - entry: the largest distance by the integer order of the floats' bits, from the integer
        ///   0 (the float +0) up, in one-cycle `vpmaxsd`s. For a float of clear sign bit that order
        ///   is the float order; a negative or -0 distance is below 0 in both, and so is a NaN made
        ///   by `0 * inf` (the x86 default NaN, sign bit set), which the chain leaves out too. The
        ///   entry distances are the chain's, bit for bit but a zero's sign.
        /// - exit: rounding being monotonic, `entry <= min(exits, best) * EXIT_SCALE` holds exactly
        ///   when `entry <= exit * EXIT_SCALE` holds for each exit and for the best hit's distance:
        ///   four compares side by side instead of a chain; a NaN exit distance passes
        ///   (`!(entry > NaN)`), as the chain's `min` drops it. For any-hit rays (`ANY`) each exit
        ///   is compared as [`crate::geometry::exit_bound`] instead, which accepts whatever
        ///   `exit * EXIT_SCALE` accepts in one multiply-add (the scale folded into the inverse
        ///   direction, `geometry::inv_far`); the portable walk compares the same numbers.
        ///
        /// A ray with a NaN direction hits nothing whichever way. On the H100 host's 16 threads this
        /// gained 1-6 points against Embree on every row of the ray report, side by side with the
        /// float chain (docs/cpu-benchmark-log.md, "the integer node test"), and the folded exit
        /// 1-4 more on shadow and AO rays ("the exit scale folded into the inverse"); the walk's
        /// hits and work counts are the portable walk's, ray by ray (the tests below, with rays
        /// from vertices, where exit distances are zeros, and along the axes, where they are NaN).
        trace,
        "avx2,popcnt,fma"
    );

    walk_compiled_for!(
        /// [`trace`] compiled for AVX-512 (F, VL, DQ, BW): the same 256-bit (or 128-bit)
        /// operations in the same order, so the same hits bit for bit, but with 32 vector
        /// registers instead of 16 and compares straight into mask registers. (Both builds keep
        /// the ray's lanes in registers across the node loop since its stack stopped calling the
        /// allocator there, [`crate::traverse::Bounded`]; per node the AVX2 build reloads four of
        /// the six planes' offsets, this one two: objdump, stop 42.) On the H100 host's Xeon 0-5
        /// points more of Embree on every row of the ray report, side by side in three runs
        /// (docs/cpu-benchmark-log.md, "AVX-512's registers and the walk's entry"); a walk
        /// written for 16-lane registers traced 3-20% fewer rays than this one there and was
        /// removed.
        trace_evex,
        "avx2,popcnt,fma,avx512f,avx512vl,avx512dq,avx512bw"
    );

    /// The body of [`trace`] and [`trace_evex`]: always inlined, without target features of its
    /// own, so each compiles it with its own (as [`leaf`]).
    #[inline(always)]
    fn walk<const ANY: bool, T: TriangleTest, V: Vector, const W: usize>(
        bvh: &WideBvh<W>,
        start: u32,
        ray: &Ray,
        t_min: f32,
        (t_max, tri): (f32, u32),
        stack: &mut Stack,
        cost: &mut Cost,
    ) -> Option<Found> {
        let ray = &read_ray(ray);
        let r = Lanes::<V>::new(ray);
        let near_plane = super::each3(|a| if ray.inv_dir[a].is_sign_negative() { 3 + a } else { a });
        let far_plane = super::each3(|a| if ray.inv_dir[a].is_sign_negative() { a } else { 3 + a });
        let zero = V::zero();
        // Splatted one by one, not by `map`, for the reason of `each3`.
        let inv_far = [
            V::splat(geometry::inv_far(ray.inv_dir[0])),
            V::splat(geometry::inv_far(ray.inv_dir[1])),
            V::splat(geometry::inv_far(ray.inv_dir[2])),
        ];
        let tiny = V::splat(f32::MIN_POSITIVE);
        let exit_scale = V::splat(EXIT_SCALE);
        let t_min_v = V::splat(t_min);
        let mut best = Found { t: t_max, tri, w1: 0.0, w2: 0.0, sum: 1.0 };
        let mut found = false;
        // Counted here and added to `cost` once per ray: a local stays in a register.
        let mut work = Cost::default();
        // No allocating call in the loop: a call, even one never made, clobbers every vector
        // register, and the compiler then reloaded the ray from memory at every node.
        let mut stack = stack.bounded(bvh.stack_bound());
        let mut cur = start;
        loop {
            if cur & LEAF == 0 {
                // SAFETY: the collapse refers only to nodes it made.
                let node = unsafe { bvh.node_unchecked(cur) };
                let b = &node.bounds;
                // `geometry::may_hold_wide` of the entry and exit distances, in a short chain (see
                // the doc comment).
                let n = |a: usize| dist(&b[near_plane[a]], &r, a);
                let near = n(0).imax(zero).imax(n(1).imax(n(2)));
                let before = |a: usize| {
                    let exit = if ANY {
                        V::load(&b[far_plane[a]]).sub(r.o[a]).fmadd(inv_far[a], tiny)
                    } else {
                        dist(&b[far_plane[a]], &r, a).mul(exit_scale)
                    };
                    near.cmp::<_CMP_NGT_UQ>(exit)
                };
                let ok =
                    before(0).and(before(1)).and(before(2).and(near.cmp::<_CMP_LE_OQ>(V::splat(best.t * EXIT_SCALE))));
                let mut mask = ok.bits() & node.valid;
                work.nodes += node.valid.count_ones();
                if mask != 0 {
                    let first = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    if mask == 0 {
                        cur = node.child[first];
                        continue;
                    }
                    let near = near.store::<W>();
                    // The children still to visit start loading now, together.
                    let mut all = mask | (1 << first);
                    while all != 0 {
                        let i = all.trailing_zeros() as usize;
                        prefetch(bvh, node.child[i]);
                        all &= all - 1;
                    }
                    if ANY {
                        // Any hit ends the ray: no order needed.
                        while mask != 0 {
                            let i = mask.trailing_zeros() as usize;
                            stack.push((node.child[i], near[i]));
                            mask &= mask - 1;
                        }
                        cur = node.child[first];
                        continue;
                    }
                    let second = mask.trailing_zeros() as usize;
                    if mask & (mask - 1) == 0 {
                        // Two children: the insertion sort's order below without its array (the
                        // farther pushed, on a tie the lower slot).
                        let (push, enter) = if near[first] < near[second] { (second, first) } else { (first, second) };
                        stack.push((node.child[push], near[push]));
                        cur = node.child[enter];
                        continue;
                    }
                    // Nearest first: the others go on the stack farthest first.
                    let mut hits = [(0f32, 0u32); W];
                    hits[0] = (near[first], node.child[first]);
                    let mut n = 1;
                    while mask != 0 {
                        let i = mask.trailing_zeros() as usize;
                        let e = (near[i], node.child[i]);
                        let mut k = n;
                        while k > 0 && hits[k - 1].0 < e.0 {
                            hits[k] = hits[k - 1];
                            k -= 1;
                        }
                        hits[k] = e;
                        n += 1;
                        mask &= mask - 1;
                    }
                    for &(d, c) in &hits[..n - 1] {
                        stack.push((c, d));
                    }
                    cur = hits[n - 1].1;
                    continue;
                }
            } else {
                // SAFETY: the collapse refers only to blocks it made.
                let block = unsafe { bvh.block_unchecked(cur) };
                if leaf::<ANY, T, V, W>(block, &r, t_min_v, &mut best, &mut work) {
                    found = true;
                    if ANY {
                        *cost += work;
                        return Some(best);
                    }
                }
            }
            loop {
                match stack.pop() {
                    None => {
                        *cost += work;
                        return found.then_some(best);
                    }
                    Some((c, near)) if may_hold(near, best.t) => {
                        cur = c;
                        break;
                    }
                    Some(_) => {}
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::{MollerTrumbore, Watertight};
    use glam::Vec3;

    /// A binary tree over `tris` made by halving index ranges down to leaves of `leaf` triangles,
    /// with boxes from the vertices (what the collapse reads; the builder's trees are tested
    /// through `tests/hits.rs`).
    fn halving_tree(tris: &[Triangle], leaf: u32) -> Vec<Node> {
        fn bounds(tris: &[Triangle]) -> ([f32; 3], [f32; 3]) {
            let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
            for v in tris.iter().flat_map(|t| t.vertices()) {
                for a in 0..3 {
                    lo[a] = lo[a].min(v[a]);
                    hi[a] = hi[a].max(v[a]);
                }
            }
            (lo, hi)
        }
        let mut nodes = vec![Node { min: [0.0; 3], count: 0, max: [0.0; 3], index: 0 }];
        let mut work = vec![(0usize, 0u32, tris.len() as u32)];
        while let Some((i, start, n)) = work.pop() {
            let (min, max) = bounds(&tris[start as usize..(start + n) as usize]);
            if n <= leaf {
                nodes[i] = Node { min, count: n, max, index: start };
            } else {
                let c = nodes.len();
                nodes[i] = Node { min, count: 0, max, index: c as u32 };
                nodes.extend([Node { min: [0.0; 3], count: 0, max: [0.0; 3], index: 0 }; 2]);
                work.push((c, start, n / 2));
                work.push((c + 1, start + n / 2, n - n / 2));
            }
        }
        nodes
    }

    /// `n` small triangles scattered in the unit cube.
    fn scattered(n: usize, seed: u64) -> Vec<Triangle> {
        let mut rng = ::tests::Rng(seed);
        (0..n)
            .map(|_| {
                let c = Vec3::new(rng.unit(), rng.unit(), rng.unit());
                let mut v = || (c + Vec3::new(rng.signed(), rng.signed(), rng.signed()) * 0.05).to_array();
                Triangle::from_vertices(v(), v(), v())
            })
            .collect()
    }

    /// Every triangle sits in exactly one leaf block, inside every box on its way from the root,
    /// and the blocks' empty lanes hit nothing.
    fn check_structure<const W: usize>(bvh: &WideBvh<W>, tris: &[Triangle]) {
        let mut seen = vec![0u32; tris.len()];
        let mut work = vec![(bvh.root, [f32::NEG_INFINITY; 3], [f32::INFINITY; 3])];
        while let Some((r, lo, hi)) = work.pop() {
            if r & LEAF != 0 {
                let b = bvh.block(r);
                for lane in 0..W {
                    let i = b.index[lane];
                    if i == u32::MAX {
                        assert!(b.p.iter().all(|v| v.iter().all(|a| a[lane].is_nan())), "empty lanes hold NaN");
                        continue;
                    }
                    seen[i as usize] += 1;
                    assert_eq!(b.triangle(lane).vertices(), tris[i as usize].vertices(), "the vertices as stored");
                    for v in tris[i as usize].vertices() {
                        assert!((0..3).all(|a| lo[a] <= v[a] && v[a] <= hi[a]), "triangle {i} outside its box");
                    }
                }
                continue;
            }
            let node = bvh.node(r);
            assert!(node.valid.count_ones() >= 2 && node.valid < 1 << W, "a node has 2 to {W} children");
            for slot in (0..W).filter(|&s| node.valid & (1 << s) != 0) {
                let clo = [node.bounds[0][slot], node.bounds[1][slot], node.bounds[2][slot]];
                let chi = [node.bounds[3][slot], node.bounds[4][slot], node.bounds[5][slot]];
                work.push((node.child[slot], clo, chi));
            }
        }
        assert!(seen.iter().all(|&n| n == 1), "every triangle in exactly one block");
    }

    impl<const W: usize> WideBvh<W> {
        /// Every node and block reference, from the root down.
        fn refs(&self) -> Vec<u32> {
            let (mut out, mut work) = (Vec::new(), vec![self.root]);
            while let Some(r) = work.pop() {
                out.push(r);
                if r & LEAF == 0 {
                    let node = self.node(r);
                    work.extend((0..W).filter(|&s| node.valid & (1 << s) != 0).map(|s| node.child[s]));
                }
            }
            out
        }
    }

    fn collapse_keeps_every_triangle_once<const W: usize>() {
        for (n, leaf) in [(1, 1), (4, 2), (5, 1), (8, 2), (9, 1), (1000, 1), (1000, 3), (777, 8)] {
            let tris = scattered(n, n as u64);
            let bvh = WideBvh::<W>::new(&halving_tree(&tris, leaf), &tris);
            check_structure(&bvh, &tris);
            // More triangles than a block holds need a node; fewer may get one too, where their
            // blocks' boxes are that much smaller than the whole.
            assert!(n <= W || !bvh.is_empty(), "{n} triangles, width {W}");
            let blocks = bvh.refs().into_iter().filter(|r| r & LEAF != 0).map(|r| bvh.block(r).count() as usize);
            assert!(blocks.clone().all(|c| c > 0) && blocks.sum::<usize>() == n, "no empty block");
        }
    }

    /// The SAH cost of a wide tree as the collapse weighs it, from its own boxes (`root`: the
    /// binary root, whose box the wide tree does not keep).
    fn wide_cost<const W: usize>(bvh: &WideBvh<W>, root: &Node) -> f64 {
        let weight = |r: u32| if r & LEAF != 0 { BLOCK_COST } else { NODE_COST } as f64;
        let mut sum = half_area(root) as f64 * weight(bvh.root);
        for node in bvh.refs().into_iter().filter(|r| r & LEAF == 0).map(|r| bvh.node(r)) {
            for slot in (0..W).filter(|&s| node.valid & (1 << s) != 0) {
                let lane = |k: usize| [node.bounds[k][slot], node.bounds[k + 1][slot], node.bounds[k + 2][slot]];
                let b = Node { min: lane(0), count: 0, max: lane(3), index: 0 };
                sum += half_area(&b) as f64 * weight(node.child[slot]);
            }
        }
        sum
    }

    /// The same cost for the greedy collapse the SAH collapse replaced (Embree's: open the child
    /// of the largest area until the node is full; any subtree of at most `W` triangles a block).
    fn greedy_cost<const W: usize>(nodes: &[Node], b: usize) -> f64 {
        fn count(nodes: &[Node], b: usize) -> usize {
            let n = &nodes[b];
            if n.is_leaf() {
                n.count as usize
            } else {
                count(nodes, n.index as usize) + count(nodes, n.index as usize + 1)
            }
        }
        let area = half_area(&nodes[b]) as f64;
        if count(nodes, b) <= W {
            return area * BLOCK_COST as f64;
        }
        let mut kids = vec![nodes[b].index as usize, nodes[b].index as usize + 1];
        while kids.len() < W {
            let open = (0..kids.len())
                .filter(|&k| !nodes[kids[k]].is_leaf() && count(nodes, kids[k]) > W)
                .max_by(|&x, &y| half_area(&nodes[kids[x]]).total_cmp(&half_area(&nodes[kids[y]])));
            let Some(k) = open else { break };
            let c = nodes[kids[k]].index as usize;
            kids[k] = c;
            kids.push(c + 1);
        }
        area * NODE_COST as f64 + kids.iter().map(|&k| greedy_cost::<W>(nodes, k)).sum::<f64>()
    }

    /// The collapse is optimal for its cost model: never costlier than the greedy collapse, and
    /// cheaper on scattered triangles, whose small subtrees' boxes leave much empty space.
    #[test]
    fn the_sah_collapse_costs_no_more_than_the_greedy_one() {
        sah_beats_greedy::<8>();
        sah_beats_greedy::<4>();
    }

    fn sah_beats_greedy<const W: usize>() {
        let mut cheaper = 0;
        for (n, leaf) in [(5, 1), (9, 1), (100, 2), (1000, 1), (1000, 3), (777, 4)] {
            let tris = scattered(n, 3 * n as u64);
            let nodes = halving_tree(&tris, leaf);
            let (sah, greedy) = (wide_cost(&WideBvh::<W>::new(&nodes, &tris), &nodes[0]), greedy_cost::<W>(&nodes, 0));
            assert!(sah <= greedy * (1.0 + 1e-5), "{n} triangles, width {W}: {sah} against {greedy}");
            cheaper += usize::from(sah < greedy * 0.99);
        }
        assert!(cheaper >= 3, "width {W}: cheaper on {cheaper} of 6 trees");
    }

    /// The collapse split into tasks (the plan's subtrees, the arena's slices) writes the arena
    /// the one-thread collapse writes, line for line, on a pool of several threads: with tasks
    /// from the root's children down to the leaves, and with large leaves (wide nodes over runs
    /// of triangles) inside and at the foot of the parallel levels.
    #[test]
    fn a_parallel_collapse_writes_the_serial_arena() {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(4).build().expect("a pool of 4 threads");
        pool.install(|| {
            parallel_matches_serial::<8>();
            parallel_matches_serial::<4>();
        });
    }

    fn parallel_matches_serial<const W: usize>() {
        use collapse::{Parallel, collapse};
        for (n, leaf) in [(1, 1), (9, 1), (100, 2), (1000, 1), (3000, 3), (2000, 20), (700, 700)] {
            let tris = scattered(n, 11 * n as u64 + leaf as u64);
            let nodes = halving_tree(&tris, leaf);
            let serial = collapse::<W>(&nodes, &tris[..], Parallel::SERIAL);
            check_structure(&serial, &tris);
            for (plan_depth, write_levels) in [(1, 1), (3, 2), (10, 3), (40, 40)] {
                let par = collapse::<W>(&nodes, &tris[..], Parallel { plan_depth, write_levels });
                let what = format!("{n} triangles, leaves of {leaf}, width {W}, {plan_depth}/{write_levels}");
                assert_eq!((par.root, par.counts, par.depth), (serial.root, serial.counts, serial.depth), "{what}");
                assert_eq!(par.lines.len(), serial.lines.len(), "{what}");
                // Node by node and block by block (a node's padding bytes are not written).
                let refs = serial.refs();
                assert_eq!(par.refs(), refs, "{what}: the same layout");
                for r in refs {
                    let same = match r & LEAF {
                        0 => {
                            let (a, b) = (par.node(r), serial.node(r));
                            a.bounds
                                .as_flattened()
                                .iter()
                                .zip(b.bounds.as_flattened())
                                .all(|(x, y)| x.to_bits() == y.to_bits())
                                && (a.child, a.valid) == (b.child, b.valid)
                        }
                        _ => {
                            let (a, b) = (par.block(r), serial.block(r));
                            let bits = |t: &TriBlock<W>| {
                                t.p.as_flattened().as_flattened().iter().map(|x| x.to_bits()).collect::<Vec<_>>()
                            };
                            bits(a) == bits(b) && a.index == b.index
                        }
                    };
                    assert!(same, "{what}: the same contents at line {r:#x}");
                }
            }
        }
    }

    #[test]
    fn the_collapse_keeps_every_triangle_once_inside_its_boxes() {
        collapse_keeps_every_triangle_once::<8>();
        collapse_keeps_every_triangle_once::<4>();
    }

    /// Boxes so large that their areas overflow to infinity (every SAH cost infinite): the
    /// collapse still spreads each node's slots and keeps every triangle once.
    #[test]
    fn boxes_of_infinite_area_are_collapsed_too() {
        for n in [3, 20, 300] {
            let tris: Vec<Triangle> = scattered(n, 5)
                .iter()
                .map(|t| {
                    let [a, b, c] = t.vertices().map(|v| v.map(|x| x * 1e25));
                    Triangle::from_vertices(a, b, c)
                })
                .collect();
            let nodes = halving_tree(&tris, 2);
            assert!(half_area(&nodes[0]).is_infinite(), "the test needs an infinite area");
            check_structure(&WideBvh::<8>::new(&nodes, &tris), &tris);
            check_structure(&WideBvh::<4>::new(&nodes, &tris), &tris);
        }
    }

    /// A leaf of more triangles than a block (a file from another builder) becomes wide nodes
    /// over runs of `W`, boxed by their triangles, and the hits stay the scalar traversal's.
    #[test]
    fn large_leaves_are_split_into_blocks_and_hit_the_same() {
        large_leaves_hit_the_same::<8>();
        large_leaves_hit_the_same::<4>();
    }

    fn large_leaves_hit_the_same<const W: usize>() {
        for n in [5, 9, 64, 65, 700] {
            let tris = scattered(n, 7 + n as u64);
            let nodes = halving_tree(&tris, n as u32);
            assert_eq!(nodes.len(), 1, "one leaf");
            let bvh = WideBvh::<W>::new(&nodes, &tris);
            check_structure(&bvh, &tris);
            let mut rng = ::tests::Rng(n as u64);
            let (mut stack, mut cost) = (Stack::default(), Cost::default());
            let mut hits = 0;
            for _ in 0..2000 {
                let o = Vec3::new(rng.signed(), rng.signed(), rng.signed()) * 2.0;
                // Aimed at a triangle's centroid, so that most rays hit something.
                let t = &tris[rng.below(n)];
                let centroid = (Vec3::from(t.p0) + Vec3::from(t.p1) + Vec3::from(t.p2)) / 3.0;
                let d = (centroid - o).normalize();
                let ray = Ray::new(o, d);
                let want = crate::traverse::child_pair::<false, Watertight>(
                    &nodes,
                    &tris,
                    &ray,
                    0.0,
                    f32::INFINITY,
                    &mut stack,
                    &mut cost,
                );
                for simd in Simd::available() {
                    let got = bvh.trace_on::<false, Watertight>(simd, &ray, 0.0, f32::INFINITY, &mut stack, &mut cost);
                    assert_eq!(got, want, "{simd:?}, width {W}");
                }
                let mt = crate::traverse::child_pair::<false, MollerTrumbore>(
                    &nodes,
                    &tris,
                    &ray,
                    0.0,
                    f32::INFINITY,
                    &mut stack,
                    &mut cost,
                );
                for simd in Simd::available() {
                    let got =
                        bvh.trace_on::<false, MollerTrumbore>(simd, &ray, 0.0, f32::INFINITY, &mut stack, &mut cost);
                    assert_eq!(got, mt, "{simd:?}, width {W}");
                }
                hits += usize::from(want.is_some());
            }
            assert!(hits > 1000, "{n} triangles: only {hits} rays hit");
        }
    }

    /// The traversal's work counts: one box per child of each node entered, one triangle per
    /// occupied lane of each block tested.
    #[test]
    fn costs_count_boxes_and_triangles_tested() {
        costs_count::<8>();
        costs_count::<4>();
    }

    fn costs_count<const W: usize>() {
        let tris = scattered(300, 3);
        let bvh = WideBvh::<W>::new(&halving_tree(&tris, 2), &tris);
        let mut stack = Stack::default();
        let ray = Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z);
        let mut a = Cost::default();
        let hit = bvh.trace_portable::<false, Watertight>(&ray, 0.0, f32::INFINITY, &mut stack, &mut a);
        assert!(a.nodes >= bvh.node(bvh.root).valid.count_ones() && a.tris > 0, "{a:?}");
        for simd in Simd::available() {
            let mut b = Cost::default();
            let same = bvh.trace_on::<false, Watertight>(simd, &ray, 0.0, f32::INFINITY, &mut stack, &mut b);
            assert_eq!(hit, same, "{simd:?}, width {W}");
            assert_eq!(a, b, "{simd:?}, width {W}, visits the nodes and blocks the portable traversal visits");
        }
    }

    /// Every path the CPU has, against the portable one: closest hits and costs on rays from
    /// everywhere (many aimed at the cloud, some along axes and through box planes, where the
    /// slab test's NaN rules decide), any hits up to and short of the closest hit.
    #[test]
    fn every_simd_path_finds_the_portable_hits_at_the_same_cost() {
        every_simd_path::<8>();
        every_simd_path::<4>();
    }

    fn every_simd_path<const W: usize>() {
        let tris = scattered(2000, 11);
        let bvh = WideBvh::<W>::new(&halving_tree(&tris, 3), &tris);
        let mut rng = ::tests::Rng(5);
        let mut stack = Stack::default();
        let paths = Simd::available();
        println!("paths on this CPU: {paths:?}");
        let mut hits = 0;
        for k in 0..20_000 {
            let o = Vec3::new(rng.signed(), rng.signed(), rng.signed()) * 2.0;
            let d = match k % 4 {
                // Along an axis: two inverse direction components are infinite.
                0 => [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::X, -Vec3::Y, -Vec3::Z][rng.below(6)],
                // From a vertex's coordinate plane: origins on box planes.
                1 => {
                    let v = tris[rng.below(tris.len())].p1;
                    let o2 = Vec3::new(v[0], o.y, o.z);
                    let d = Vec3::new(0.0, -o2.y + 0.5, -o2.z + 0.5).normalize();
                    let ray = Ray::new(o2, d);
                    check(&bvh, &ray, &paths, &mut stack, &mut hits);
                    continue;
                }
                // From a vertex, in any direction: an origin on the planes of every box the vertex
                // bounds, whose exit distances there are zeros of either sign.
                2 if k % 8 == 2 => {
                    let t = &tris[rng.below(tris.len())];
                    let v = [t.p0, t.p1, t.p2][rng.below(3)];
                    let d = Vec3::new(rng.signed(), rng.signed(), rng.signed()).normalize();
                    check(&bvh, &Ray::new(Vec3::from(v), d), &paths, &mut stack, &mut hits);
                    continue;
                }
                _ => (Vec3::splat(0.5) + Vec3::new(rng.signed(), rng.signed(), rng.signed()) * 0.4 - o).normalize(),
            };
            check(&bvh, &Ray::new(o, d), &paths, &mut stack, &mut hits);
        }
        assert!(hits > 4000, "only {hits} rays hit");

        fn check<const W: usize>(bvh: &WideBvh<W>, ray: &Ray, paths: &[Simd], stack: &mut Stack, hits: &mut usize) {
            let mut want_cost = Cost::default();
            let want = bvh.trace_portable::<false, Watertight>(ray, 0.0, f32::INFINITY, stack, &mut want_cost);
            let want_mt = bvh.trace_on::<false, MollerTrumbore>(
                Simd::Portable,
                ray,
                0.0,
                f32::INFINITY,
                stack,
                &mut Cost::default(),
            );
            *hits += usize::from(want.is_some());
            for &simd in paths {
                let mut cost = Cost::default();
                let got = bvh.trace_on::<false, Watertight>(simd, ray, 0.0, f32::INFINITY, stack, &mut cost);
                assert_eq!(got, want, "{simd:?}, width {W}, on {ray:?}");
                assert_eq!(cost, want_cost, "{simd:?}, width {W}, on {ray:?}");
                let mt = bvh.trace_on::<false, MollerTrumbore>(simd, ray, 0.0, f32::INFINITY, stack, &mut cost);
                assert_eq!(mt, want_mt, "{simd:?}, width {W} (Möller-Trumbore) on {ray:?}");
                let limits = want.map_or(vec![1.0, f32::INFINITY], |h| vec![h.t, h.t * (1.0 - 1e-3), f32::INFINITY]);
                for t_max in limits {
                    let mut any_cost = Cost::default();
                    let any = bvh.trace_on::<true, Watertight>(simd, ray, 0.0, t_max, stack, &mut any_cost);
                    let expected = want.is_some_and(|h| h.t <= t_max);
                    assert_eq!(any.is_some(), expected, "{simd:?}, width {W}: any hit to {t_max} on {ray:?}");
                    // Any-hit rays compare their exits in another form (`geometry::exit_bound`) and
                    // visit children unordered: the portable walk's hit and work, ray by ray.
                    let mut want_any_cost = Cost::default();
                    let want_any =
                        bvh.trace_on::<true, Watertight>(Simd::Portable, ray, 0.0, t_max, stack, &mut want_any_cost);
                    assert_eq!(any, want_any, "{simd:?}, width {W}: any hit to {t_max} on {ray:?}");
                    assert_eq!(any_cost, want_any_cost, "{simd:?}, width {W}: any hit to {t_max} on {ray:?}");
                }
            }
        }
    }

    /// The walks' stacks hold what the deepest walk leaves on them ([`WideBvh::stack_bound`]; a
    /// push beyond it would panic): coincident triangles under a binary tree as deep as it can be,
    /// so that every ray through them enters every box and leaves all but one child of each
    /// node on the stack, deeper than the stack's inline array.
    #[test]
    fn the_walks_stack_holds_the_deepest_walk() {
        deepest_walk::<8>();
        deepest_walk::<4>();
    }

    fn deepest_walk<const W: usize>() {
        let n = 400u32;
        let tris = vec![Triangle::from_vertices([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]); n as usize];
        // Node 2k: a leaf of triangle k (the last: two triangles); node 2k + 1: the rest.
        let leaf = |k: u32, count: u32| Node { min: [0.0; 3], count, max: [1.0, 1.0, 0.0], index: k };
        let mut nodes = vec![Node { min: [0.0; 3], count: 0, max: [1.0, 1.0, 0.0], index: 1 }];
        for k in 0..n - 2 {
            nodes.push(leaf(k, 1));
            nodes.push(Node { min: [0.0; 3], count: 0, max: [1.0, 1.0, 0.0], index: nodes.len() as u32 + 1 });
        }
        nodes.push(leaf(n - 2, 1));
        nodes.push(leaf(n - 1, 1));
        let bvh = WideBvh::<W>::new(&nodes, &tris);
        assert!(bvh.stack_bound() > 128, "width {W}: {} entries fit the inline array", bvh.stack_bound());
        let mut stack = Stack::default();
        for o in [Vec3::new(0.25, 0.25, 1.0), Vec3::new(0.25, 0.25, -1.0)] {
            let ray = Ray::new(o, Vec3::new(0.0, 0.0, -o.z.signum()));
            for simd in Simd::available() {
                let mut cost = Cost::default();
                let hit = bvh.trace_on::<false, Watertight>(simd, &ray, 0.0, f32::INFINITY, &mut stack, &mut cost);
                assert_eq!(hit.map(|h| (h.t, h.tri)), Some((1.0, 0)), "{simd:?}, width {W}");
                assert_eq!(cost.tris, n, "{simd:?}, width {W}: every triangle tested");
                let any = bvh.trace_on::<true, Watertight>(simd, &ray, 0.0, f32::INFINITY, &mut stack, &mut cost);
                assert!(any.is_some(), "{simd:?}, width {W}");
            }
        }
    }

    #[test]
    fn paths_are_named_and_capped_by_what_the_cpu_runs() {
        assert_eq!(Simd::parse(" AVX2 "), Some(Simd::Avx2));
        assert_eq!(Simd::parse("avx512"), Some(Simd::Avx512));
        assert_eq!(Simd::parse("sse"), None);
        let avx2 = if Simd::Avx2.supported() { Simd::Avx2 } else { Simd::Portable };
        assert_eq!(Simd::best_up_to(Simd::Portable), Simd::Portable);
        assert_eq!(Simd::best_up_to(Simd::Avx2), avx2);
        assert_eq!(Simd::best_up_to(Simd::Avx512), *Simd::available().last().unwrap());
    }
}
