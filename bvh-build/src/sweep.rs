//! The full-sweep SAH split: every boundary between centroid-sorted primitives on every axis is
//! evaluated. O(n log n) per node; the quality reference the binned builder is measured against.

use crate::build::{Aabb, Costs, NodeBounds, Primitives, Split, Splitter};

pub struct SweepSah<'a> {
    pub prims: &'a Primitives,
    pub costs: Costs,
}

impl Splitter for SweepSah<'_> {
    fn split(&self, prims: &mut [u32], nb: &NodeBounds, may_leaf: bool) -> Option<Split> {
        let n = prims.len();
        if nb.centroids.extent().max_element() <= 0.0 {
            return None;
        }
        let parent_area = nb.aabb.half_area();
        let mut best: Option<(f64, usize, usize)> = None; // (cost, axis, left count)
        let mut sorted: [Vec<u32>; 3] = Default::default();
        let mut right_area = vec![0f64; n];
        for (axis, order) in sorted.iter_mut().enumerate() {
            *order = prims.to_vec();
            let c = &self.prims.centroids;
            // Ties broken by index so that the result does not depend on the input order.
            order.sort_unstable_by(|&a, &b| c[a as usize][axis].total_cmp(&c[b as usize][axis]).then(a.cmp(&b)));
            let mut acc = Aabb::EMPTY;
            for i in (1..n).rev() {
                acc.grow(&self.prims.bounds[order[i] as usize]);
                right_area[i] = acc.half_area();
            }
            let mut left = Aabb::EMPTY;
            for i in 1..n {
                left.grow(&self.prims.bounds[order[i - 1] as usize]);
                let cost = self.costs.split_cost(parent_area, left.half_area(), i, right_area[i], n - i);
                if best.is_none_or(|(b, _, _)| cost < b) {
                    best = Some((cost, axis, i));
                }
            }
        }
        let (cost, axis, mid) = best?;
        if may_leaf && cost >= self.costs.leaf_cost(n) {
            return None;
        }
        prims.copy_from_slice(&sorted[axis]);
        Some(Split { mid, left: self.prims.bounds_of(&prims[..mid]), right: self.prims.bounds_of(&prims[mid..]) })
    }
}
