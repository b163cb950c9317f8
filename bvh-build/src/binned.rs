//! Wald's binned SAH split (Wald 2007): centroids are binned along each axis into K bins over the
//! node's centroid bounds, and the K - 1 planes between bins are evaluated with the SAH. Nodes of at
//! most K triangles are swept exactly instead.
//!
//! One more candidate is evaluated with the same SAH: the triangles whose boxes are large
//! compared with the node (a quarter of its surface area or more) against the rest. Centroids
//! cannot separate a floor quad from the models standing on it (its centre lies among their feet),
//! and without this candidate the floor's two triangles sink deep into the tree, costing the
//! million-triangle scene 70% in SAH against the full sweep.

use crate::build::{Aabb, Costs, NodeBounds, PrimRef, Split, Splitter};
use glam::Vec3A;
use std::cell::RefCell;

/// Nodes with more primitives than this bin in parallel chunks.
const PARALLEL_BINNING: usize = 1 << 16;

#[derive(Clone, Copy)]
struct Bin {
    bounds: Aabb,
    count: u32,
}

const EMPTY_BIN: Bin = Bin { bounds: Aabb::EMPTY, count: 0 };

thread_local! {
    /// Reused bin storage: a fresh allocation per node would cost more than the binning of the
    /// millions of small nodes near the leaves.
    static SCRATCH: RefCell<Vec<Bin>> = const { RefCell::new(Vec::new()) };
}

pub struct BinnedSah {
    pub bins: usize,
    pub costs: Costs,
}

/// The bin of centroid component `c`; the same arithmetic decides binning and partitioning, so the
/// children's boxes assembled from bins are exact.
#[inline(always)]
fn bin_index(c: Vec3A, lo: Vec3A, scale: Vec3A, last: usize) -> [usize; 3] {
    let f = ((c - lo) * scale).to_array();
    // `as` saturates: NaN and negatives land in bin 0.
    [(f[0] as usize).min(last), (f[1] as usize).min(last), (f[2] as usize).min(last)]
}

impl BinnedSah {
    fn bin_into(&self, prims: &[PrimRef], lo: Vec3A, scale: Vec3A, big: f32, bins: &mut [Bin]) {
        let k = self.bins;
        for p in prims {
            let b = bin_index(p.centroid(), lo, scale, k - 1);
            let pb = p.aabb();
            for axis in 0..3 {
                let bin = &mut bins[axis * k + b[axis]];
                bin.bounds.grow(&pb);
                bin.count += 1;
            }
            // The last slot gathers the large triangles (rare, hence a branch).
            if p.area >= big {
                let bin = &mut bins[3 * k];
                bin.bounds.grow(&pb);
                bin.count += 1;
            }
        }
    }

    fn bin_parallel(&self, prims: &[PrimRef], lo: Vec3A, scale: Vec3A, big: f32, bins: &mut [Bin]) {
        use rayon::prelude::*;
        let k = self.bins;
        let merged = prims
            .par_chunks(PARALLEL_BINNING / 4)
            .fold(
                || vec![EMPTY_BIN; 3 * k + 1],
                |mut acc, chunk| {
                    self.bin_into(chunk, lo, scale, big, &mut acc);
                    acc
                },
            )
            .reduce(
                || vec![EMPTY_BIN; 3 * k + 1],
                |mut a, b| {
                    for (x, y) in a.iter_mut().zip(&b) {
                        x.bounds.grow(&y.bounds);
                        x.count += y.count;
                    }
                    a
                },
            );
        bins.copy_from_slice(&merged);
    }

    fn split_with(&self, prims: &mut [PrimRef], nb: &NodeBounds, may_leaf: bool, bins: &mut [Bin]) -> Option<Split> {
        let n = prims.len();
        let k = self.bins;
        let lo = nb.centroids.min;
        let ext = nb.centroids.extent();
        if ext.max_element() <= 0.0 {
            return None;
        }
        // Axes without extent get scale 0: everything in bin 0, so they offer no plane.
        let scale = Vec3A::select(ext.cmpgt(Vec3A::ZERO), Vec3A::splat(k as f32) / ext, Vec3A::ZERO);
        bins.fill(EMPTY_BIN);
        let parent_area = nb.aabb.half_area();
        let big = (parent_area * 0.25) as f32;
        if n > PARALLEL_BINNING {
            self.bin_parallel(prims, lo, scale, big, bins);
        } else {
            self.bin_into(prims, lo, scale, big, bins);
        }

        let mut best: Option<(f64, usize, usize)> = None; // (cost, axis, plane)
        let mut right_area = [0f64; 256];
        let mut right_area_vec;
        let right_area: &mut [f64] = if k <= 256 {
            &mut right_area[..k]
        } else {
            right_area_vec = vec![0f64; k];
            &mut right_area_vec
        };
        for axis in 0..3 {
            let ab = &bins[axis * k..axis * k + k];
            let mut acc = Aabb::EMPTY;
            for i in (1..k).rev() {
                acc.grow(&ab[i].bounds);
                right_area[i] = acc.half_area();
            }
            let mut left = Aabb::EMPTY;
            let mut left_n = 0usize;
            for plane in 1..k {
                left.grow(&ab[plane - 1].bounds);
                left_n += ab[plane - 1].count as usize;
                let right_n = n - left_n;
                if left_n == 0 || right_n == 0 {
                    continue;
                }
                let cost = self.costs.split_cost(parent_area, left.half_area(), left_n, right_area[plane], right_n);
                if best.is_none_or(|(c, _, _)| cost < c) {
                    best = Some((cost, axis, plane));
                }
            }
        }
        let big_n = bins[3 * k].count as usize;
        if big_n > 0
            && big_n < n
            && let Some(split) = self.big_split(prims, nb, big, bins[3 * k].bounds, best.map(|b| b.0), may_leaf)
        {
            return Some(split);
        }
        let (cost, axis, plane) = best?;
        if may_leaf && cost >= self.costs.leaf_cost(n) {
            return None;
        }
        let ab = &bins[axis * k..axis * k + k];
        let mut left = NodeBounds { aabb: Aabb::EMPTY, centroids: Aabb::EMPTY };
        let mut right = left;
        for b in &ab[..plane] {
            left.aabb.grow(&b.bounds);
        }
        for b in &ab[plane..] {
            right.aabb.grow(&b.bounds);
        }

        // Only the split axis matters here; the scalar arithmetic equals `bin_index`'s lane.
        let (lo_a, scale_a) = (lo[axis], scale[axis]);
        let mid = partition(prims, &mut left, &mut right, |_, c| {
            ((((c[axis] - lo_a) * scale_a) as usize).min(k - 1)) < plane
        });
        debug_assert!(mid > 0 && mid < n);
        Some(Split { mid, left, right })
    }
}

/// Moves the primitives for which `goes_left(prim, centroid)` holds to the front, in place, and
/// grows each side's centroid bounds on the way; returns how many went left.
#[inline(always)]
fn partition(
    prims: &mut [PrimRef],
    left: &mut NodeBounds,
    right: &mut NodeBounds,
    goes_left: impl Fn(&PrimRef, Vec3A) -> bool,
) -> usize {
    let (mut i, mut j) = (0usize, prims.len());
    while i < j {
        let c = prims[i].centroid();
        if goes_left(&prims[i], c) {
            left.centroids.grow_point(c);
            i += 1;
        } else {
            j -= 1;
            right.centroids.grow_point(c);
            prims.swap(i, j);
        }
    }
    i
}

impl BinnedSah {
    /// The large triangles (box area at least `big`) against the rest, taken when the SAH prefers
    /// it to `best_cost` (and to a leaf, if one is allowed).
    fn big_split(
        &self,
        prims: &mut [PrimRef],
        nb: &NodeBounds,
        big: f32,
        big_bounds: Aabb,
        best_cost: Option<f64>,
        may_leaf: bool,
    ) -> Option<Split> {
        let n = prims.len();
        let mut rest = Aabb::EMPTY;
        let mut big_n = 0usize;
        for p in prims.iter() {
            if p.area >= big {
                big_n += 1;
            } else {
                rest.grow(&p.aabb());
            }
        }
        let cost =
            self.costs.split_cost(nb.aabb.half_area(), big_bounds.half_area(), big_n, rest.half_area(), n - big_n);
        if best_cost.is_some_and(|b| cost >= b) || (may_leaf && cost >= self.costs.leaf_cost(n)) {
            return None;
        }
        let mut left = NodeBounds { aabb: big_bounds, centroids: Aabb::EMPTY };
        let mut right = NodeBounds { aabb: rest, centroids: Aabb::EMPTY };
        let mid = partition(prims, &mut left, &mut right, |p, _| p.area >= big);
        Some(Split { mid, left, right })
    }
}

impl Splitter for BinnedSah {
    fn split(&self, prims: &mut [PrimRef], nb: &NodeBounds, may_leaf: bool) -> Option<Split> {
        // A node no larger than the bin count is swept exactly: sorting a handful of centroids
        // costs less than clearing and sweeping K bins per axis, and finds at least as good a plane.
        if prims.len() <= self.bins {
            return crate::sweep::sweep_split(&self.costs, prims, nb, may_leaf);
        }
        SCRATCH.with(|s| {
            // A nested use (rayon may steal work inside `bin_parallel`) gets its own buffer.
            let mut own;
            let mut guard = s.try_borrow_mut();
            let bins: &mut Vec<Bin> = match guard.as_deref_mut() {
                Ok(b) => b,
                Err(_) => {
                    own = Vec::new();
                    &mut own
                }
            };
            bins.resize(3 * self.bins + 1, EMPTY_BIN);
            self.split_with(prims, nb, may_leaf, &mut bins[..3 * self.bins + 1])
        })
    }
}
