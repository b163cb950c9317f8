//! Wald's binned SAH split (Wald 2007): centroids are binned along each axis into K bins over the
//! node's centroid bounds, and the K - 1 planes between bins are evaluated with the SAH. Nodes of at
//! most K triangles are swept exactly instead. K is the configured bin count, raised for large
//! nodes to one bin per 16 primitives (at most 16 times the configured count): see
//! [`BinnedSah::bins_for`].
//!
//! One more candidate is evaluated with the same SAH: the triangles whose boxes are large
//! compared with the node (a quarter of its surface area or more) against the rest. Centroids
//! cannot separate a floor quad from the models standing on it (its centre lies among their feet),
//! and without this candidate the floor's two triangles sink deep into the tree, costing the
//! million-triangle scene 70% in SAH against the full sweep.
//!
//! Large nodes ([`crate::build::PARALLEL_NODE`]) are binned in fixed-size chunks by every thread,
//! and partitioned by every thread out of place, each chunk writing its primitives to where the
//! chunks before it leave off: the bins already counted how many of each chunk go left. That
//! partition is stable, so the children's order does not depend on the number of threads.

use crate::build::{Aabb, AreaScale, Costs, NodeBounds, PrimRef, Split, Splitter, centroid_bounds};
use glam::Vec3A;
use rayon::prelude::*;
use std::cell::RefCell;

/// Primitives per chunk of a large node's binning and partition (256 KiB of references): a size,
/// not a share of the threads, so that the chunks are the same on every machine.
const CHUNK: usize = 8192;

/// Bins of one node, boxes and counts apart (a bin's box is 32 bytes, two to a cache line): `3 K`
/// bins (K per axis), then the large bin, then (from [`TWO_SETS`] primitives) a second set of
/// `3 K` ([`BinnedSah::bin_into`]).
#[derive(Default)]
struct Bins {
    bounds: Vec<Aabb>,
    counts: Vec<u32>,
}

impl Bins {
    /// Empty bins, `len` of them.
    fn new(len: usize) -> Bins {
        Bins { bounds: vec![Aabb::EMPTY; len], counts: vec![0; len] }
    }

    /// Makes room for `len` bins and empties the first `clear` of them.
    fn reset(&mut self, len: usize, clear: usize) {
        if self.bounds.len() < len {
            self.bounds.resize(len, Aabb::EMPTY);
            self.counts.resize(len, 0);
        }
        self.bounds[..clear].fill(Aabb::EMPTY);
        self.counts[..clear].fill(0);
    }
}

thread_local! {
    /// Reused bin storage: a fresh allocation per node would cost more than the binning of the
    /// millions of small nodes near the leaves.
    static SCRATCH: RefCell<Bins> = RefCell::new(Bins::default());
}

pub struct BinnedSah {
    pub bins: usize,
    pub costs: Costs,
}

/// How one node's centroids map to bins, and which triangles count as large.
#[derive(Clone, Copy)]
struct Grid {
    lo: Vec3A,
    scale: Vec3A,
    /// The last bin's index, as a float.
    last: f32,
    /// Box half area from which a triangle joins the large-triangle candidate.
    big: f32,
}

impl Grid {
    /// `None` when all centroids coincide: no plane separates them.
    fn new(nb: &NodeBounds, bins: usize) -> Option<Grid> {
        let ext = nb.centroids.extent();
        if ext.max_element() <= 0.0 {
            return None;
        }
        // Axes without extent get scale 0: everything in bin 0, so they offer no plane.
        let scale = Vec3A::select(ext.cmpgt(Vec3A::ZERO), Vec3A::splat(bins as f32) / ext, Vec3A::ZERO);
        let big = (nb.aabb.half_area() * 0.25) as f32;
        Some(Grid { lo: nb.centroids.min, scale, last: (bins - 1) as f32, big })
    }

    /// The bin of centroid `c` on each axis. Clamped while still a float (`max` takes NaN, from
    /// an infinite scale times 0, to 0), the conversion is one truncation of all lanes at once
    /// (`cvttps2dq`): a saturating `as` per lane, `as_ivec3` included, compiles to a conversion, a
    /// range check and a NaN check per lane, with branches, which cost more than the rest of the
    /// binning. For the clamped values both truncate alike, so the bins are the same.
    #[inline(always)]
    fn bins_of(&self, c: Vec3A) -> [usize; 3] {
        let f = ((c - self.lo) * self.scale).max(Vec3A::ZERO).min(Vec3A::splat(self.last));
        #[cfg(target_arch = "x86_64")]
        {
            // SAFETY: SSE2 is part of every x86-64 target, so the instruction exists.
            let i: [i32; 4] = bytemuck::cast(unsafe { std::arch::x86_64::_mm_cvttps_epi32(f.into()) });
            [i[0] as usize, i[1] as usize, i[2] as usize]
        }
        #[cfg(not(target_arch = "x86_64"))]
        {
            let i = f.as_ivec3();
            [i.x as usize, i.y as usize, i.z as usize]
        }
    }

    /// Whether centroid `c` lies in a bin before `plane` on `axis`: the same arithmetic as
    /// [`Grid::bins_of`]'s lane, so that the partition sends every primitive where its bin was
    /// counted. For the clamped `f`, `trunc(f) < plane` exactly when `f < plane`, and the upper
    /// clamp never matters as `plane` is at most the last bin.
    #[inline(always)]
    fn left_of(&self, c: Vec3A, axis: usize, plane: f32) -> bool {
        ((c[axis] - self.lo[axis]) * self.scale[axis]).max(0.0) < plane
    }
}

/// The split chosen from the bins, before any primitive moves.
#[derive(Clone, Copy)]
enum Choice {
    /// Bins `..plane` on `axis` go left.
    Plane { axis: usize, plane: usize, left: Aabb, right: Aabb },
    /// The large triangles go left.
    Large { left: Aabb, right: Aabb },
}

impl Choice {
    #[inline(always)]
    fn goes_left(&self, grid: &Grid, p: &PrimRef, c: Vec3A) -> bool {
        match *self {
            Choice::Plane { axis, plane, .. } => grid.left_of(c, axis, plane as f32),
            Choice::Large { .. } => p.area >= grid.big,
        }
    }

    /// How many primitives of the chunk whose bin counts are `counts` go left.
    fn left_count(&self, counts: &[u32], k: usize) -> usize {
        match *self {
            Choice::Plane { axis, plane, .. } => counts[axis * k..axis * k + plane].iter().map(|&c| c as usize).sum(),
            Choice::Large { .. } => counts[3 * k] as usize,
        }
    }

    /// The children's bounds, their centroid boxes still empty (the partition grows them).
    fn children(&self) -> (NodeBounds, NodeBounds) {
        let (Choice::Plane { left, right, .. } | Choice::Large { left, right }) = *self;
        (NodeBounds { aabb: left, centroids: Aabb::EMPTY }, NodeBounds { aabb: right, centroids: Aabb::EMPTY })
    }
}

/// Adds one primitive to a set of `3 K` bins (`bounds`, `counts`) and, if it is large, to the
/// large bin.
#[inline(always)]
fn bin_one(bounds: &mut [Aabb], counts: &mut [u32], large: (&mut Aabb, &mut u32), k: usize, grid: &Grid, p: &PrimRef) {
    let pb = p.aabb();
    let b = grid.bins_of((pb.min + pb.max) * 0.5);
    for (axis, i) in b.into_iter().enumerate() {
        bounds[axis * k + i].grow(&pb);
        counts[axis * k + i] += 1;
    }
    // Large triangles are rare, hence a branch.
    if p.area >= grid.big {
        large.0.grow(&pb);
        *large.1 += 1;
    }
}

/// Large nodes get one bin per this many primitives ([`BinnedSah::bins_for`]). Uniform bins over
/// a node's centroid bounds waste resolution where the centroids cluster (small detailed models
/// far apart, or a thin ring around them): 16 bins left the forest 22 % above the full sweep's
/// SAH cost and the car 6 %; one bin per 16 primitives (so 256 from 4,096 primitives on) brings
/// every shipped scene but the room within 0.7 % of the sweep for about 3 % more build time
/// (docs/build-benchmark.md).
const PRIMS_PER_BIN: usize = 16;

/// Large nodes get at most this many times the configured bin count.
const ROOT_BINS_FACTOR: usize = 16;

/// Primitives from which [`BinnedSah::bin_into`] uses a second set of bins: below, clearing it
/// costs more than it saves.
const TWO_SETS: usize = 256;

/// Bins of one node: two sets of `3 K` and the large bin.
fn bin_len(k: usize) -> usize {
    6 * k + 1
}

impl BinnedSah {
    /// The bin count of a node of `n` primitives: the configured count, raised for large nodes
    /// to one bin per [`PRIMS_PER_BIN`] primitives, up to [`ROOT_BINS_FACTOR`] times the
    /// configured count (and [`crate::MAX_BINS`]).
    fn bins_for(&self, n: usize) -> usize {
        let most = (self.bins * ROOT_BINS_FACTOR).min(crate::MAX_BINS as usize);
        (n / PRIMS_PER_BIN).clamp(self.bins, most.max(self.bins))
    }

    /// Adds `prims` to `bins`: `3 K` bins (K per axis), then one gathering the large triangles,
    /// then (from [`TWO_SETS`] primitives) a second set of `3 K` bins for every other primitive.
    /// Neighbouring primitives tend to fall into the same bin, and with one set each would wait
    /// for the previous one's update of that bin to come back from memory; two sets halve those
    /// chains. The sets are summed into the first at the end (min, max and counts are exact in
    /// any order, so the bins do not depend on this). Always inlined, so that the callers'
    /// [`crate::isa::fastest`] compiles it for AVX2 too (likewise `choose` and `split_with`).
    #[inline(always)]
    fn bin_into(&self, prims: &[PrimRef], grid: &Grid, k: usize, bins: &mut Bins) {
        let (first_b, second_b) = bins.bounds.split_at_mut(3 * k + 1);
        let (first_c, second_c) = bins.counts.split_at_mut(3 * k + 1);
        let (axes_b, large_b) = first_b.split_at_mut(3 * k);
        let (axes_c, large_c) = first_c.split_at_mut(3 * k);
        let (large_b, large_c) = (&mut large_b[0], &mut large_c[0]);
        if prims.len() < TWO_SETS {
            for p in prims {
                bin_one(axes_b, axes_c, (large_b, large_c), k, grid, p);
            }
            return;
        }
        let (other_b, other_c) = (&mut second_b[..3 * k], &mut second_c[..3 * k]);
        other_b.fill(Aabb::EMPTY);
        other_c.fill(0);
        let mut pairs = prims.chunks_exact(2);
        for pair in &mut pairs {
            bin_one(axes_b, axes_c, (large_b, large_c), k, grid, &pair[0]);
            bin_one(other_b, other_c, (large_b, large_c), k, grid, &pair[1]);
        }
        for p in pairs.remainder() {
            bin_one(axes_b, axes_c, (large_b, large_c), k, grid, p);
        }
        for (a, b) in axes_b.iter_mut().zip(other_b.iter()) {
            a.grow(b);
        }
        for (a, b) in axes_c.iter_mut().zip(other_c.iter()) {
            *a += b;
        }
    }

    /// The cheapest split by the bins, or `None` when no plane separates the primitives or (if
    /// `may_leaf`) a leaf is cheaper. `rest` computes the box of the triangles that are not large,
    /// needed only when some but not all are.
    #[inline(always)]
    fn choose(
        &self,
        bins: &Bins,
        k: usize,
        n: usize,
        nb: &NodeBounds,
        may_leaf: bool,
        rest: impl FnOnce() -> Aabb,
    ) -> Option<Choice> {
        let scale = AreaScale::of(&nb.aabb);
        let parent_area = scale.half_area(&nb.aabb) as f64;
        // (area-weighted count of both children, axis, plane): within one node the SAH cost grows
        // with the weighted count, so only the chosen candidates' costs are computed in full.
        let (mut best_weighted, mut best_at) = (f32::INFINITY, 0);
        let mut right_area = [0f32; 256];
        let mut right_area_vec;
        let right_area: &mut [f32] = if k <= 256 {
            &mut right_area[..k]
        } else {
            right_area_vec = vec![0f32; k];
            &mut right_area_vec
        };
        for axis in 0..3 {
            let (ab, ac) = (&bins.bounds[axis * k..axis * k + k], &bins.counts[axis * k..axis * k + k]);
            let mut acc = Aabb::EMPTY;
            let mut right_n = 0u32;
            for i in (1..k).rev() {
                acc.grow(&ab[i]);
                right_n += ac[i];
                right_area[i] = scale.half_area(&acc) * right_n as f32;
            }
            let mut left = Aabb::EMPTY;
            let mut left_n = 0usize;
            for plane in 1..k {
                left.grow(&ab[plane - 1]);
                left_n += ac[plane - 1] as usize;
                // Selects, not branches: which plane beats the best so far is hard to predict.
                // A plane with an empty side is no candidate; every other weighted count is
                // finite (areas in node units times counts), so it beats the infinite start.
                let weighted = scale.half_area(&left) * left_n as f32 + right_area[plane];
                let weighted = if left_n == 0 || left_n == n { f32::INFINITY } else { weighted };
                let better = weighted < best_weighted;
                best_weighted = if better { weighted } else { best_weighted };
                best_at = if better { axis * k + plane } else { best_at };
            }
        }
        let best = (best_at != 0).then(|| (best_weighted, best_at / k, best_at % k));
        let beats_leaf = |cost: f64| !(may_leaf && cost >= self.costs.leaf_cost(n));

        let large = bins.bounds[3 * k];
        let large_n = bins.counts[3 * k] as usize;
        if large_n > 0 && large_n < n {
            let rest = rest();
            let weighted = scale.half_area(&large) * large_n as f32 + scale.half_area(&rest) * (n - large_n) as f32;
            if best.is_none_or(|(b, _, _)| weighted < b)
                && beats_leaf(self.costs.split_cost(parent_area, weighted as f64))
            {
                return Some(Choice::Large { left: large, right: rest });
            }
        }
        let (weighted, axis, plane) = best?;
        if !beats_leaf(self.costs.split_cost(parent_area, weighted as f64)) {
            return None;
        }
        let ab = &bins.bounds[axis * k..axis * k + k];
        let side = |bins: &[Aabb]| bins.iter().fold(Aabb::EMPTY, |a, b| a.union(b));
        Some(Choice::Plane { axis, plane, left: side(&ab[..plane]), right: side(&ab[plane..]) })
    }

    #[inline(always)]
    fn split_with(
        &self,
        prims: &mut [PrimRef],
        nb: &NodeBounds,
        may_leaf: bool,
        k: usize,
        bins: &mut Bins,
    ) -> Option<Split> {
        let grid = Grid::new(nb, k)?;
        // The second set is cleared by bin_into when used.
        bins.reset(bin_len(k), 3 * k + 1);
        self.bin_into(prims, &grid, k, bins);
        let choice = self.choose(bins, k, prims.len(), nb, may_leaf, || small_bounds(prims, grid.big))?;
        let (mut left, mut right) = choice.children();
        let mid = choice.left_count(&bins.counts, k);
        debug_assert!(mid > 0 && mid < prims.len());
        // One closure per kind of split, so that the partition's loop holds no match.
        let sides = match choice {
            Choice::Plane { axis, plane, .. } => partition(prims, mid, |_, c| grid.left_of(c, axis, plane as f32)),
            Choice::Large { .. } => partition(prims, mid, |p, _| p.area >= grid.big),
        };
        (left.centroids, right.centroids) = sides;
        Some(Split { mid, left, right, in_spare: false })
    }
}

/// The box of the triangles smaller than `big`.
fn small_bounds(prims: &[PrimRef], big: f32) -> Aabb {
    let mut rest = Aabb::EMPTY;
    for p in prims.iter().filter(|p| p.area < big) {
        rest.grow(&p.aabb());
    }
    rest
}

/// Primitives examined per block of [`partition`]'s scans.
const BLOCK: usize = 64;

/// Moves the primitives for which `goes_left(prim, centroid)` holds to the front, in place, given
/// how many do (`mid`, from the bins), and returns the centroid bounds of both sides. The pairs
/// swapped are Hoare's (the first primitive before `mid` that goes right with the last one from
/// `mid` on that goes left, and so on inwards), so the order is the one Hoare's partition leaves,
/// but found without a branch per primitive: the scans note the misplaced ones of a block of
/// [`BLOCK`] on each side (Edelkamp and Weiß's BlockQuicksort), then swap them. Where a primitive
/// goes is as good as random near the leaves, and a mispredicted branch cost more than the rest
/// of its test.
#[inline(always)]
fn partition(prims: &mut [PrimRef], mid: usize, goes_left: impl Fn(&PrimRef, Vec3A) -> bool) -> (Aabb, Aabb) {
    let n = prims.len();
    let sort = |p: &PrimRef| goes_left(p, p.centroid());
    // Misplaced primitives of the current blocks, `[start, end)` of each buffer: before `mid`
    // ascending, from `mid` on descending.
    let (mut lbuf, mut rbuf) = ([0u32; BLOCK], [0u32; BLOCK]);
    let (mut ls, mut le, mut rs, mut re) = (0, 0, 0, 0);
    // Next primitive to scan before `mid` (upwards), and one past the next from `mid` on (downwards).
    let (mut i, mut j) = (0, n);
    loop {
        let mut moved = false;
        if ls == le && i < mid {
            (ls, le) = (0, 0);
            let end = (i + BLOCK).min(mid);
            for (k, p) in (i..end).zip(&prims[i..end]) {
                lbuf[le] = k as u32;
                le += !sort(p) as usize;
            }
            (i, moved) = (end, true);
        }
        if rs == re && j > mid {
            (rs, re) = (0, 0);
            let end = j.saturating_sub(BLOCK).max(mid);
            for (k, p) in (end..j).zip(&prims[end..j]).rev() {
                rbuf[re] = k as u32;
                re += sort(p) as usize;
            }
            (j, moved) = (end, true);
        }
        let m = (le - ls).min(re - rs);
        for (&a, &b) in lbuf[ls..ls + m].iter().zip(&rbuf[rs..rs + m]) {
            prims.swap(a as usize, b as usize);
        }
        (ls, rs) = (ls + m, rs + m);
        // Done when both sides are scanned and their blocks swapped; a block left over on one
        // side only would mean the bins miscounted, which the assertions below report.
        if !moved && m == 0 {
            break;
        }
    }
    debug_assert!(prims[..mid].iter().all(|p| goes_left(p, p.centroid())), "the bins counted the left side");
    debug_assert!(prims[mid..].iter().all(|p| !goes_left(p, p.centroid())), "the bins counted the right side");
    // After the swaps, a pass over each side (still in the cache): growing the bounds of the
    // side each primitive goes to during the scans took a select per bound and cost the bunny's
    // build 5 % more (AMD EPYC, one thread).
    (centroid_bounds(&prims[..mid]), centroid_bounds(&prims[mid..]))
}

/// Copies `src` into `dst` partitioned, stably: each chunk of [`CHUNK`] primitives sends
/// `left_counts[chunk]` of them to the left part, after those of the chunks before it, and the
/// rest to the right part likewise. Returns the centroid bounds of both sides.
fn scatter(
    src: &[PrimRef],
    dst: &mut [PrimRef],
    left_counts: &[usize],
    goes_left: impl Fn(&PrimRef, Vec3A) -> bool + Sync,
) -> (Aabb, Aabb) {
    let mid: usize = left_counts.iter().sum();
    let (mut left_dst, mut right_dst) = dst.split_at_mut(mid);
    let mut jobs = Vec::with_capacity(left_counts.len());
    for (chunk, &l) in src.chunks(CHUNK).zip(left_counts) {
        let (l_out, rest) = std::mem::take(&mut left_dst).split_at_mut(l);
        left_dst = rest;
        let (r_out, rest) = std::mem::take(&mut right_dst).split_at_mut(chunk.len() - l);
        right_dst = rest;
        jobs.push((chunk, l_out, r_out));
    }
    jobs.into_par_iter()
        .map(|(chunk, l_out, r_out)| {
            crate::isa::fastest(
                #[inline(always)]
                || {
                    // Branch-free: where a primitive goes is as good as random, and a mispredicted
                    // branch per primitive cost more than the copy (the cursors select the place).
                    let (mut li, mut ri) = (0, 0);
                    let (ln, rn) = (l_out.len(), r_out.len());
                    let (lp, rp) = (l_out.as_mut_ptr(), r_out.as_mut_ptr());
                    for p in chunk {
                        let left = goes_left(p, p.centroid());
                        // A primitive without a place would mean the bins miscounted: a bug, never input.
                        assert!(if left { li < ln } else { ri < rn }, "the bins counted this chunk's sides");
                        let to = if left { lp.wrapping_add(li) } else { rp.wrapping_add(ri) };
                        // SAFETY: `to` is element `li` of `l_out` or `ri` of `r_out`, in bounds by the
                        // assertion, and the only reference to either slice is the pointer's.
                        unsafe { to.write(*p) };
                        li += left as usize;
                        ri += !left as usize;
                    }
                    assert!(li == ln && ri == rn, "the bins counted this chunk's sides");
                    (centroid_bounds(l_out), centroid_bounds(r_out))
                },
            )
        })
        .reduce(|| (Aabb::EMPTY, Aabb::EMPTY), |a, b| (a.0.union(&b.0), a.1.union(&b.1)))
}

impl Splitter for BinnedSah {
    fn sweeps_up_to(&self) -> usize {
        self.bins.min(crate::sweep::PRESORTED_MAX)
    }

    fn split(&self, prims: &mut [PrimRef], nb: &NodeBounds, may_leaf: bool) -> Option<Split> {
        // A node no larger than the bin count is swept exactly: sorting a handful of centroids
        // costs less than clearing and sweeping K bins per axis, and finds at least as good a plane.
        if prims.len() <= self.bins {
            return crate::sweep::sweep_split(&self.costs, prims, nb, may_leaf);
        }
        let k = self.bins_for(prims.len());
        SCRATCH.with(|s| {
            // A nested use (rayon may steal work while this thread waits) gets its own buffer.
            let mut own;
            let mut guard = s.try_borrow_mut();
            let bins: &mut Bins = match guard.as_deref_mut() {
                Ok(b) => b,
                Err(_) => {
                    own = Bins::default();
                    &mut own
                }
            };
            crate::isa::fastest(
                #[inline(always)]
                || self.split_with(prims, nb, may_leaf, k, bins),
            )
        })
    }

    fn split_parallel(
        &self,
        prims: &mut [PrimRef],
        spare: &mut [PrimRef],
        nb: &NodeBounds,
        may_leaf: bool,
    ) -> Option<Split> {
        if prims.len() <= self.bins {
            return self.split(prims, nb, may_leaf);
        }
        let k = self.bins_for(prims.len());
        let grid = Grid::new(nb, k)?;
        let chunks: Vec<Bins> = prims
            .par_chunks(CHUNK)
            .map(|chunk| {
                let mut bins = Bins::new(bin_len(k));
                crate::isa::fastest(
                    #[inline(always)]
                    || self.bin_into(chunk, &grid, k, &mut bins),
                );
                bins
            })
            .collect();
        let mut bins = Bins::new(3 * k + 1);
        for chunk in &chunks {
            for (b, c) in bins.bounds.iter_mut().zip(&chunk.bounds) {
                b.grow(c);
            }
            for (b, c) in bins.counts.iter_mut().zip(&chunk.counts) {
                *b += c;
            }
        }
        let rest =
            || prims.par_chunks(CHUNK).map(|c| small_bounds(c, grid.big)).reduce(|| Aabb::EMPTY, |a, b| a.union(&b));
        let choice = self.choose(&bins, k, prims.len(), nb, may_leaf, rest)?;
        let left_counts: Vec<usize> = chunks.iter().map(|c| choice.left_count(&c.counts, k)).collect();
        let (mut left, mut right) = choice.children();
        (left.centroids, right.centroids) = scatter(prims, spare, &left_counts, |p, c| choice.goes_left(&grid, p, c));
        let mid = left_counts.iter().sum();
        debug_assert!(mid > 0 && mid < prims.len());
        Some(Split { mid, left, right, in_spare: true })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hoare's partition as the builder had it: the reference for [`partition`]'s order.
    fn hoare(prims: &mut [PrimRef], goes_left: impl Fn(&PrimRef) -> bool) -> usize {
        let (mut i, mut j) = (0usize, prims.len());
        loop {
            while i < j && goes_left(&prims[i]) {
                i += 1;
            }
            while i < j && !goes_left(&prims[j - 1]) {
                j -= 1;
            }
            if i == j {
                return i;
            }
            prims.swap(i, j - 1);
            i += 1;
            j -= 1;
        }
    }

    #[test]
    fn the_block_partition_leaves_hoares_order() {
        let mut rng = ::tests::Rng(2024);
        for case in 0..3000 {
            // Sizes around the block's multiples, and shares of the left side from none to all.
            let n = 1 + case % (3 * BLOCK + 5);
            let share = rng.unit();
            let prims: Vec<PrimRef> = (0..n)
                .map(|i| {
                    let min = [rng.unit(), rng.unit(), rng.unit()];
                    let max = [min[0] + 0.1, min[1] + 0.2, min[2] + 0.3];
                    let area = if rng.unit() < share { 1.0 } else { 0.0 };
                    PrimRef { min, id: i as u32, max, area }
                })
                .collect();
            let goes_left = |p: &PrimRef| p.area > 0.5;
            let mut expected = prims.clone();
            let mid = hoare(&mut expected, goes_left);
            let mut got = prims.clone();
            let (l, r) = partition(&mut got, mid, |p, _| goes_left(p));
            let ids = |v: &[PrimRef]| v.iter().map(|p| p.id).collect::<Vec<_>>();
            assert_eq!(ids(&expected), ids(&got), "case {case}: n {n}, {mid} left");
            let centroids = |v: &[PrimRef]| {
                v.iter().fold(Aabb::EMPTY, |mut a, p| {
                    a.grow_point(p.centroid());
                    a
                })
            };
            assert_eq!((l, r), (centroids(&got[..mid]), centroids(&got[mid..])), "case {case}: centroid bounds");
        }
    }
}
