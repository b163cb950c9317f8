//! The full-sweep SAH split: every boundary between centroid-sorted primitives on every axis is
//! evaluated. O(n log n) per node; the quality reference the binned builder is measured against,
//! and the binned builder's choice for nodes no larger than its bin count.

use crate::build::{Aabb, AreaScale, Costs, NodeBounds, PrimRef, Split, Splitter, bounds_of};
use bytemuck::Zeroable;
use std::cell::RefCell;

pub struct SweepSah {
    pub costs: Costs,
}

/// A primitive's sort key on one axis: its centroid component's bits made to order as integers
/// (high half) and its input id (low half, for ties), and its place in the node's slice. One
/// integer comparison per step of the sort.
#[derive(Clone, Copy)]
struct Key {
    key: u64,
    at: u32,
}

/// `f`'s bits as an integer of the same order as `f32::total_cmp`.
#[inline(always)]
fn ordered_bits(f: f32) -> u32 {
    let b = f.to_bits();
    if b >> 31 == 1 { !b } else { b | 1 << 31 }
}

#[derive(Default)]
struct Scratch {
    sorted: [Vec<Key>; 3],
    right_area: Vec<f32>,
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
    // Most nodes swept are the binned builder's smallest (up to 16 primitives by default, half a
    // million of them in a million-triangle tree): on the stack they skip the scratch buffers.
    match prims.len() {
        n if n <= 16 => return sweep_small::<16>(costs, prims, nb, may_leaf),
        n if n <= 64 => return sweep_small::<64>(costs, prims, nb, may_leaf),
        _ => {}
    }
    SCRATCH.with(|s| match s.try_borrow_mut() {
        Ok(mut s) => sweep_with(costs, prims, nb, may_leaf, &mut s),
        Err(_) => sweep_with(costs, prims, nb, may_leaf, &mut Scratch::default()),
    })
}

fn sweep_with(costs: &Costs, prims: &mut [PrimRef], nb: &NodeBounds, may_leaf: bool, s: &mut Scratch) -> Option<Split> {
    let n = prims.len();
    let scale = AreaScale::of(&nb.aabb);
    // (area-weighted count of both children, axis, left count): within one node the SAH cost
    // grows with the weighted count, so only the best split's cost is computed in full.
    let mut best: Option<(f32, usize, usize)> = None;
    s.right_area.resize(n, 0.0);
    for axis in 0..3 {
        let order = &mut s.sorted[axis];
        order.clear();
        // Ties broken by input index so that the result does not depend on the current order.
        order.extend(
            prims
                .iter()
                .enumerate()
                .map(|(i, p)| Key { key: (ordered_bits(p.centroid()[axis]) as u64) << 32 | p.id as u64, at: i as u32 }),
        );
        order.sort_unstable_by_key(|k| k.key);
        let mut acc = Aabb::EMPTY;
        for i in (1..n).rev() {
            acc.grow(&prims[order[i].at as usize].aabb());
            s.right_area[i] = scale.half_area(&acc) * (n - i) as f32;
        }
        let mut left = Aabb::EMPTY;
        for i in 1..n {
            left.grow(&prims[order[i - 1].at as usize].aabb());
            let weighted = scale.half_area(&left) * i as f32 + s.right_area[i];
            if best.is_none_or(|(b, _, _)| weighted < b) {
                best = Some((weighted, axis, i));
            }
        }
    }
    let (weighted, axis, mid) = best?;
    let cost = costs.split_cost(scale.half_area(&nb.aabb) as f64, weighted as f64);
    if may_leaf && cost >= costs.leaf_cost(n) {
        return None;
    }
    s.copy.clear();
    s.copy.extend_from_slice(prims);
    for (dst, k) in prims.iter_mut().zip(&s.sorted[axis]) {
        *dst = s.copy[k.at as usize];
    }
    Some(Split { mid, left: bounds_of(&prims[..mid]), right: bounds_of(&prims[mid..]), in_spare: false })
}

/// [`sweep_with`] for at most `N` primitives, with every buffer on the stack and the boxes loaded
/// once: the same keys, the same sums in the same order, hence the same split.
fn sweep_small<const N: usize>(costs: &Costs, prims: &mut [PrimRef], nb: &NodeBounds, may_leaf: bool) -> Option<Split> {
    let n = prims.len();
    debug_assert!(n <= N);
    let scale = AreaScale::of(&nb.aabb);
    let mut boxes = [Aabb::EMPTY; N];
    let mut sorted = [[Key { key: 0, at: 0 }; N]; 3];
    for (i, p) in prims.iter().enumerate() {
        let b = p.aabb();
        boxes[i] = b;
        let c = p.centroid();
        for (axis, keys) in sorted.iter_mut().enumerate() {
            keys[i] = Key { key: (ordered_bits(c[axis]) as u64) << 32 | p.id as u64, at: i as u32 };
        }
    }
    let mut best: Option<(f32, usize, usize)> = None;
    let mut right_area = [0f32; N];
    for (axis, keys) in sorted.iter_mut().enumerate() {
        let order = &mut keys[..n];
        order.sort_unstable_by_key(|k| k.key);
        let mut acc = Aabb::EMPTY;
        for i in (1..n).rev() {
            acc.grow(&boxes[order[i].at as usize]);
            right_area[i] = scale.half_area(&acc) * (n - i) as f32;
        }
        let mut left = Aabb::EMPTY;
        for i in 1..n {
            left.grow(&boxes[order[i - 1].at as usize]);
            let weighted = scale.half_area(&left) * i as f32 + right_area[i];
            if best.is_none_or(|(b, _, _)| weighted < b) {
                best = Some((weighted, axis, i));
            }
        }
    }
    let (weighted, axis, mid) = best?;
    let cost = costs.split_cost(scale.half_area(&nb.aabb) as f64, weighted as f64);
    if may_leaf && cost >= costs.leaf_cost(n) {
        return None;
    }
    let mut copy = [PrimRef::zeroed(); N];
    copy[..n].copy_from_slice(prims);
    let empty = NodeBounds { aabb: Aabb::EMPTY, centroids: Aabb::EMPTY };
    let (mut left, mut right) = (empty, empty);
    for (i, (dst, k)) in prims.iter_mut().zip(&sorted[axis][..n]).enumerate() {
        let p = &copy[k.at as usize];
        *dst = *p;
        let side = if i < mid { &mut left } else { &mut right };
        side.aabb.grow(&boxes[k.at as usize]);
        side.centroids.grow_point(p.centroid());
    }
    Some(Split { mid, left, right, in_spare: false })
}

impl Splitter for SweepSah {
    fn split(&self, prims: &mut [PrimRef], nb: &NodeBounds, may_leaf: bool) -> Option<Split> {
        sweep_split(&self.costs, prims, nb, may_leaf)
    }
}
