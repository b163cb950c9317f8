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
        n if n <= 4 => return sweep_small::<4>(costs, prims, nb, may_leaf),
        n if n <= 8 => return sweep_small::<8>(costs, prims, nb, may_leaf),
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

/// The comparators of Batcher's odd-even merge sort of `n` keys (a power of two), in order: `M` of
/// them, checked at compile time.
const fn batcher<const M: usize>(n: usize) -> [(u8, u8); M] {
    let mut out = [(0u8, 0u8); M];
    let mut m = 0;
    let mut p = 1;
    while p < n {
        let mut k = p;
        while k > 0 {
            let mut j = k % p;
            while j + k < n {
                let mut i = 0;
                while i < k && i < n - j - k {
                    if (i + j) / (2 * p) == (i + j + k) / (2 * p) {
                        out[m] = ((i + j) as u8, (i + j + k) as u8);
                        m += 1;
                    }
                    i += 1;
                }
                j += 2 * k;
            }
            k /= 2;
        }
        p *= 2;
    }
    assert!(m == M, "the comparator count of the network");
    out
}

// Batcher's construction (Knuth's merge exchange) sorts any count, not only powers of two: the
// sizes between save comparators on the many small nodes.
const NET2: [(u8, u8); 1] = batcher(2);
const NET4: [(u8, u8); 5] = batcher(4);
const NET6: [(u8, u8); 12] = batcher(6);
const NET8: [(u8, u8); 19] = batcher(8);
const NET12: [(u8, u8); 42] = batcher(12);
const NET16: [(u8, u8); 63] = batcher(16);

/// Sorts `keys` (padded with `u64::MAX` to the network's size) without a branch: a handful of
/// random keys costs an insertion sort a mispredicted branch per key.
#[inline(always)]
fn network_sort<const N: usize>(keys: &mut [u64; N], net: &[(u8, u8)]) {
    for &(a, b) in net {
        let (x, y) = (keys[a as usize], keys[b as usize]);
        keys[a as usize] = x.min(y);
        keys[b as usize] = x.max(y);
    }
}

/// The most primitives of a [`Presorted`] set: its orders hold places in a `u8`, and its arrays
/// live on the stack.
pub const PRESORTED_MAX: usize = 64;

/// A small set of primitives (at most `N`, at most [`PRESORTED_MAX`]) sorted once per axis. Each
/// primitive is known by its rank among the set's input ids (its "local" index): `boxes` and
/// `ids` by local index, `place[local]` its place in the slice it came from and `local[place]` the
/// inverse, and `orders[axis]` the local indices in the order of [`sweep_with`]'s keys on that
/// axis (centroid, then input id; the local index orders as the id does, so one integer
/// comparison sorts by both). A stable filter of a sorted order is sorted by the same keys, so the
/// orders of any subset (a child's, a grandchild's) are filtered from these without sorting again:
/// [`presorted_split`] on them sums the same boxes in the same order as a sweep that sorts, hence
/// chooses the same split.
pub(crate) struct Presorted<const N: usize> {
    pub(crate) boxes: [Aabb; N],
    pub(crate) ids: [u32; N],
    pub(crate) place: [u8; N],
    pub(crate) local: [u8; N],
    pub(crate) orders: [[u8; N]; 3],
}

/// Sorts the first `n` of `keys`, the rest being `u64::MAX` (they stay in place): by Batcher's
/// networks up to 16, the library sort beyond.
#[inline(always)]
fn sort_keys<const N: usize>(keys: &mut [u64; N], n: usize) {
    match n {
        0..=2 => network_sort(keys.first_chunk_mut::<2>().expect("N >= 2"), &NET2),
        3..=4 => network_sort(keys.first_chunk_mut::<4>().expect("N >= 4"), &NET4),
        5..=6 => network_sort(keys.first_chunk_mut::<6>().expect("N >= 6"), &NET6),
        7..=8 => network_sort(keys.first_chunk_mut::<8>().expect("N >= 8"), &NET8),
        9..=12 => network_sort(keys.first_chunk_mut::<12>().expect("N >= 12"), &NET12),
        13..=16 => network_sort(keys.first_chunk_mut::<16>().expect("N >= 16"), &NET16),
        _ => keys[..n].sort_unstable(),
    }
}

impl<const N: usize> Presorted<N> {
    /// Always inlined, so that `build_presorted`'s [`crate::isa::fastest`] compiles it for AVX2 too.
    #[inline(always)]
    pub(crate) fn new(prims: &[PrimRef]) -> Presorted<N> {
        let n = prims.len();
        debug_assert!(n <= N && N <= PRESORTED_MAX && N >= 2);
        // Local indices: the places sorted by input id (ids are distinct).
        let mut by_id = [u64::MAX; N];
        for (i, p) in prims.iter().enumerate() {
            by_id[i] = (p.id as u64) << 32 | i as u64;
        }
        sort_keys(&mut by_id, n);
        let mut set =
            Presorted { boxes: [Aabb::EMPTY; N], ids: [0; N], place: [0; N], local: [0; N], orders: [[0; N]; 3] };
        // Keys: the centroid's ordered bits (high half) and the local index (low half).
        let mut sorted = [[u64::MAX; N]; 3];
        for (k, &key) in by_id[..n].iter().enumerate() {
            let i = (key & 0xffff_ffff) as usize;
            let b = prims[i].aabb();
            (set.boxes[k], set.ids[k], set.place[k], set.local[i]) = (b, prims[i].id, i as u8, k as u8);
            let c = (b.min + b.max) * 0.5;
            for (axis, keys) in sorted.iter_mut().enumerate() {
                keys[k] = (ordered_bits(c[axis]) as u64) << 32 | k as u64;
            }
        }
        for (keys, order) in sorted.iter_mut().zip(&mut set.orders) {
            sort_keys(keys, n);
            for (o, &k) in order.iter_mut().zip(&keys[..n]) {
                *o = k as u8;
            }
        }
        set
    }
}

/// The full-sweep split of the primitives whose boxes are `boxes[i]` for `i` in `orders[axis]`,
/// given in [`Presorted`]'s order on each axis: `(axis, left count)`, the left side being
/// `orders[axis][..left count]`. `None` as [`sweep_split`] gives it (all centroids equal, or a
/// cheaper leaf when `may_leaf`).
#[inline(always)]
pub(crate) fn presorted_split<const N: usize>(
    costs: &Costs,
    boxes: &[Aabb],
    orders: [&[u8]; 3],
    nb: &NodeBounds,
    may_leaf: bool,
) -> Option<(usize, usize)> {
    if nb.centroids.extent().max_element() <= 0.0 {
        return None;
    }
    let n = orders[0].len();
    debug_assert!((2..=N).contains(&n));
    let scale = AreaScale::of(&nb.aabb);
    if n == 2 {
        // Two in five nodes swept: every axis offers the one split at the same cost (the sum of
        // the two areas in either order), so the first axis wins.
        let weighted = scale.half_area(&boxes[orders[0][0] as usize]) + scale.half_area(&boxes[orders[0][1] as usize]);
        let cost = costs.split_cost(scale.half_area(&nb.aabb) as f64, weighted as f64);
        return (!(may_leaf && cost >= costs.leaf_cost(n))).then_some((0, 1));
    }
    // The three axes side by side, each with its own best: three independent chains for the
    // processor and one loop exit to predict instead of three. Per axis the first of equal
    // weighted counts wins, and across axes the first axis: the order of a sweep of one axis
    // after the other. The first candidate always beats the infinite start: its weighted count
    // is finite (areas in node units times counts). Selects, not branches: which split beats the
    // best so far is hard to predict.
    let [o0, o1, o2] = orders;
    let (o1, o2) = (&o1[..n], &o2[..n]);
    let mut right_area = [[0f32; 3]; N];
    let mut acc = [Aabb::EMPTY; 3];
    for i in (1..n).rev() {
        let count = (n - i) as f32;
        for (a, &at) in [o0[i], o1[i], o2[i]].iter().enumerate() {
            acc[a].grow(&boxes[at as usize]);
            right_area[i][a] = scale.half_area(&acc[a]) * count;
        }
    }
    let mut left = [Aabb::EMPTY; 3];
    let (mut best, mut best_at) = ([f32::INFINITY; 3], [0usize; 3]);
    for i in 1..n {
        for (a, &at) in [o0[i - 1], o1[i - 1], o2[i - 1]].iter().enumerate() {
            left[a].grow(&boxes[at as usize]);
            let w = scale.half_area(&left[a]) * i as f32 + right_area[i][a];
            let better = w < best[a];
            best[a] = if better { w } else { best[a] };
            best_at[a] = if better { i } else { best_at[a] };
        }
    }
    let (mut weighted, mut axis, mut mid) = (best[0], 0, best_at[0]);
    for a in 1..3 {
        if best[a] < weighted {
            (weighted, axis, mid) = (best[a], a, best_at[a]);
        }
    }
    if mid == 0 {
        return None; // no finite weighted count: not from valid input, which is finite
    }
    let cost = costs.split_cost(scale.half_area(&nb.aabb) as f64, weighted as f64);
    if may_leaf && cost >= costs.leaf_cost(n) {
        return None;
    }
    Some((axis, mid))
}

/// The box and centroid box of the primitives `boxes[i]`, `i` in `of`.
#[inline(always)]
pub(crate) fn bounds_at(boxes: &[Aabb], of: &[u8]) -> NodeBounds {
    let mut nb = NodeBounds { aabb: Aabb::EMPTY, centroids: Aabb::EMPTY };
    for &i in of {
        let b = &boxes[i as usize];
        nb.aabb.grow(b);
        nb.centroids.grow_point((b.min + b.max) * 0.5);
    }
    nb
}

/// [`sweep_with`] for at most `N` primitives, with every buffer on the stack and the boxes loaded
/// once: [`Presorted`] sorts them, [`presorted_split`] sweeps.
fn sweep_small<const N: usize>(costs: &Costs, prims: &mut [PrimRef], nb: &NodeBounds, may_leaf: bool) -> Option<Split> {
    let n = prims.len();
    let set = Presorted::<N>::new(prims);
    let orders = set.orders.each_ref().map(|o| &o[..n]);
    let (axis, mid) = presorted_split::<N>(costs, &set.boxes, orders, nb, may_leaf)?;
    let mut copy = [PrimRef::zeroed(); N];
    copy[..n].copy_from_slice(prims);
    for (dst, &i) in prims.iter_mut().zip(orders[axis]) {
        *dst = copy[set.place[i as usize] as usize];
    }
    let (left, right) = orders[axis].split_at(mid);
    Some(Split { mid, left: bounds_at(&set.boxes, left), right: bounds_at(&set.boxes, right), in_spare: false })
}

impl Splitter for SweepSah {
    fn sweeps_up_to(&self) -> usize {
        PRESORTED_MAX
    }

    fn split(&self, prims: &mut [PrimRef], nb: &NodeBounds, may_leaf: bool) -> Option<Split> {
        sweep_split(&self.costs, prims, nb, may_leaf)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::bounds_of;

    fn sorts_every_zero_one_input<const N: usize>(net: &[(u8, u8)]) {
        // A comparator network that sorts every input of zeros and ones sorts every input.
        for bits in 0..1u32 << N {
            let mut keys = [0u64; N];
            for (i, k) in keys.iter_mut().enumerate() {
                *k = (bits >> i & 1) as u64;
            }
            network_sort(&mut keys, net);
            assert!(keys.windows(2).all(|w| w[0] <= w[1]), "{N} keys, input {bits:b}: {keys:?}");
        }
    }

    #[test]
    fn the_merge_networks_sort() {
        sorts_every_zero_one_input::<2>(&NET2);
        sorts_every_zero_one_input::<4>(&NET4);
        sorts_every_zero_one_input::<6>(&NET6);
        sorts_every_zero_one_input::<8>(&NET8);
        sorts_every_zero_one_input::<12>(&NET12);
        sorts_every_zero_one_input::<16>(&NET16);
    }

    #[test]
    fn small_nodes_split_as_the_general_sweep() {
        // Coordinates on a coarse grid, so that many centroids tie on some axis and the id order
        // decides; ids shuffled so that it differs from the order in the slice.
        let mut rng = ::tests::Rng(99);
        let costs = Costs { traversal: 1.0, intersection: 1.0, max_leaf_size: 8, depth_limit: 64 };
        for case in 0..4000 {
            let n = 2 + case % 63;
            let mut prims: Vec<PrimRef> = (0..n)
                .map(|i| {
                    let mut v = || (rng.unit() * 4.0).floor();
                    let min = [v(), v(), v()];
                    let max = [min[0] + v(), min[1] + v(), min[2] + v()];
                    let d = [max[0] - min[0], max[1] - min[1], max[2] - min[2]];
                    let id = ((i * 7919 + case) % 1000) as u32 + 1000 * i as u32;
                    PrimRef { min, id, max, area: d[0] * d[1] + d[1] * d[2] + d[2] * d[0] }
                })
                .collect();
            let nb = bounds_of(&prims);
            let may_leaf = case % 2 == 0;
            let mut general = prims.clone();
            let expected = (nb.centroids.extent().max_element() > 0.0)
                .then(|| sweep_with(&costs, &mut general, &nb, may_leaf, &mut Scratch::default()))
                .flatten();
            let got = sweep_split(&costs, &mut prims, &nb, may_leaf);
            match (expected, got) {
                (None, None) => {}
                (Some(e), Some(g)) => {
                    assert_eq!(e.mid, g.mid, "case {case}");
                    assert_eq!((e.left.aabb, e.right.aabb), (g.left.aabb, g.right.aabb), "case {case}");
                    assert_eq!((e.left.centroids, e.right.centroids), (g.left.centroids, g.right.centroids));
                    let ids = |p: &[PrimRef]| p.iter().map(|p| p.id).collect::<Vec<_>>();
                    assert_eq!(ids(&general), ids(&prims), "case {case}: the same order");
                }
                (e, g) => panic!("case {case}: general {:?}, small {:?}", e.map(|s| s.mid), g.map(|s| s.mid)),
            }
        }
    }
}
