//! The full-sweep SAH split: every boundary between centroid-sorted primitives on every axis is
//! evaluated. O(n log n) per node; the quality reference the binned builder is measured against,
//! and the binned builder's choice for nodes no larger than its bin count.

use crate::build::{Aabb, Costs, NodeBounds, PrimRef, Split, Splitter, bounds_of};
use std::cell::RefCell;

pub struct SweepSah {
    pub costs: Costs,
}

/// A primitive's sort key on one axis: centroid component, input id (for ties), and its place
/// in the node's slice. 12 bytes, so three sorts per node move little memory.
#[derive(Clone, Copy)]
struct Key {
    c: f32,
    id: u32,
    at: u32,
}

#[derive(Default)]
struct Scratch {
    sorted: [Vec<Key>; 3],
    right_area: Vec<f64>,
    copy: Vec<PrimRef>,
}

thread_local! {
    /// Reused buffers: four allocations per node would dominate the small nodes near the leaves.
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// The cheapest full-sweep split of `prims`, reordering them; see [`Splitter::split`].
pub fn sweep_split(costs: &Costs, prims: &mut [PrimRef], nb: &NodeBounds, may_leaf: bool) -> Option<Split> {
    if nb.centroids.extent().max_element() <= 0.0 {
        return None;
    }
    SCRATCH.with(|s| match s.try_borrow_mut() {
        Ok(mut s) => sweep_with(costs, prims, nb, may_leaf, &mut s),
        Err(_) => sweep_with(costs, prims, nb, may_leaf, &mut Scratch::default()),
    })
}

fn sweep_with(costs: &Costs, prims: &mut [PrimRef], nb: &NodeBounds, may_leaf: bool, s: &mut Scratch) -> Option<Split> {
    let n = prims.len();
    let parent_area = nb.aabb.half_area();
    let mut best: Option<(f64, usize, usize)> = None; // (cost, axis, left count)
    s.right_area.resize(n, 0.0);
    for axis in 0..3 {
        let order = &mut s.sorted[axis];
        order.clear();
        order.extend(prims.iter().enumerate().map(|(i, p)| Key { c: p.centroid()[axis], id: p.id, at: i as u32 }));
        // Ties broken by input index so that the result does not depend on the current order.
        order.sort_unstable_by(|a, b| a.c.total_cmp(&b.c).then(a.id.cmp(&b.id)));
        let mut acc = Aabb::EMPTY;
        for i in (1..n).rev() {
            acc.grow(&prims[order[i].at as usize].aabb());
            s.right_area[i] = acc.half_area();
        }
        let mut left = Aabb::EMPTY;
        for i in 1..n {
            left.grow(&prims[order[i - 1].at as usize].aabb());
            let cost = costs.split_cost(parent_area, left.half_area(), i, s.right_area[i], n - i);
            if best.is_none_or(|(b, _, _)| cost < b) {
                best = Some((cost, axis, i));
            }
        }
    }
    let (cost, axis, mid) = best?;
    if may_leaf && cost >= costs.leaf_cost(n) {
        return None;
    }
    s.copy.clear();
    s.copy.extend_from_slice(prims);
    for (dst, k) in prims.iter_mut().zip(&s.sorted[axis]) {
        *dst = s.copy[k.at as usize];
    }
    Some(Split { mid, left: bounds_of(&prims[..mid]), right: bounds_of(&prims[mid..]) })
}

impl Splitter for SweepSah {
    fn split(&self, prims: &mut [PrimRef], nb: &NodeBounds, may_leaf: bool) -> Option<Split> {
        sweep_split(&self.costs, prims, nb, may_leaf)
    }
}
