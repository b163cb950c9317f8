//! TEMPORARY (measurement only): packet8.rs as it was before the pkt8 branch, so the ray report
//! times before and after in one run. Removed before merge.

//! Coherent packets of 8 rays (a 4 x 2 pixel block) through the wide BVH ([`crate::bvh8`]) with
//! AVX2, Embree's `rtcIntersect8` way: one walk for the packet; at a node each child's box is
//! tested against the 8 rays at once, the children some ray enters are visited nearest first (by
//! the smallest entry distance among their rays) with the lanes that enter them; a leaf block's
//! triangles are tested one by one against the 8 rays. Where a subtree is reached by at most
//! [`SPARSE`] live lanes, those lanes finish it one ray at a time on the wide BVH's single-ray
//! traversal, which then costs less than dragging a mostly empty packet along.
//!
//! Every lane computes what the scalar path computes (the slab test and the triangle tests of
//! [`crate::packet`], operation by operation), and a subtree is left out only where no lane can
//! find a hit in it, so the hits are bit for bit the ordered traversal's (`tests/hits.rs`).

use crate::bvh8::Bvh8;
use crate::geometry::{MollerTrumbore, TriangleTest, Watertight};
use crate::lanes::TraceLanes;
use crate::packet::{Entry, Rays, Results};
use crate::traverse::Stack;
use render_spec::Intersect;

/// Live lanes at or below which a subtree is traced one ray at a time.
pub const SPARSE: u32 = 4;

/// Whether this CPU runs wide packets (AVX2, as [`crate::packet`]).
pub fn available() -> bool {
    crate::packet::available()
}

/// Closest hits (`ANY == false`, `t_min` 0) or occlusion (`ANY == true`) of the valid lanes of
/// `rays` with the triangle test `T`: the packet's stack and one for the lanes finished alone.
/// Only call when [`available`] is true.
pub fn trace<const ANY: bool, T: TriangleTest>(
    bvh: &Bvh8,
    rays: &Rays,
    stack: &mut Vec<Entry>,
    single: &mut Stack,
) -> Results {
    #[cfg(target_arch = "x86_64")]
    {
        assert!(available(), "wide packets need AVX2; callers check `available()` first");
        // SAFETY: AVX2 is present (checked above).
        unsafe { avx2::trace::<ANY, T>(bvh, rays, stack, single) }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = (bvh, rays, stack, single);
        unreachable!("wide packets are only chosen where `available()` is true")
    }
}

/// `--method bvh8-packet`'s way of tracing the stages of a block: every stage as one wide packet.
pub struct Lanes<'a> {
    bvh: &'a Bvh8,
    stack: Vec<Entry>,
    single: Stack,
}

impl<'a> Lanes<'a> {
    /// Wide packets on `bvh`; only where [`available`].
    pub fn new(bvh: &'a Bvh8) -> Self {
        Self { bvh, stack: Vec::with_capacity(128), single: Stack::default() }
    }

    fn trace<const ANY: bool>(&mut self, rays: &Rays, test: Intersect) -> Results {
        match test {
            Intersect::Watertight => trace::<ANY, Watertight>(self.bvh, rays, &mut self.stack, &mut self.single),
            Intersect::MollerTrumbore => {
                trace::<ANY, MollerTrumbore>(self.bvh, rays, &mut self.stack, &mut self.single)
            }
        }
    }
}

impl TraceLanes for Lanes<'_> {
    fn closest(&mut self, rays: &Rays, test: Intersect) -> Results {
        self.trace::<false>(rays, test)
    }
    fn occluded(&mut self, rays: &Rays, test: Intersect) -> Results {
        self.trace::<true>(rays, test)
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::SPARSE;
    use crate::bvh8::{Bvh8, LEAF, Simd, WIDTH};
    use crate::geometry::plane_normal;
    use crate::geometry::{Cost, TriangleTest};
    use crate::packet::avx2::{
        Best, Packet, add, any, count, keep, may_hold, mul, packet_of, slab, splat, test, to_array, to_array_i,
    };
    use crate::packet::{Entry, LANES, Rays, Results};
    use crate::traverse::Stack;
    use bvh_format::Node;
    use bvh_format::Triangle;
    use render_spec::Intersect;
    use std::arch::x86_64::*;

    /// The smallest entry distance among the lanes in `mask`.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn nearest(near: __m256, mask: __m256) -> f32 {
        let v = _mm256_blendv_ps(splat(f32::INFINITY), near, mask);
        let v = _mm256_min_ps(v, _mm256_permute2f128_ps::<1>(v, v));
        let v = _mm256_min_ps(v, _mm256_permute_ps::<0b01_00_11_10>(v));
        let v = _mm256_min_ps(v, _mm256_permute_ps::<0b10_11_00_01>(v));
        _mm256_cvtss_f32(v)
    }

    /// The box test of slot `slot` of `b` (a wide node's bounds) for all lanes whose inverse
    /// directions have, per axis, the sign that chose `near_plane` and `far_plane`: the
    /// single-ray AVX2 test's operations ([`crate::bvh8`]), lane by lane the scalar slab test's
    /// result, with fewer operations than [`slab`] (which must find each lane's entered plane).
    #[target_feature(enable = "avx2")]
    #[inline]
    fn slab_signed(
        b: &[[f32; WIDTH]; 6],
        slot: usize,
        pk: &Packet,
        near_plane: &[usize; 3],
        far_plane: &[usize; 3],
        t_best: __m256,
    ) -> (__m256, __m256) {
        // Written out, not in a closure: a closure does not inherit AVX2.
        let near = _mm256_max_ps(dist(b[near_plane[0]][slot], pk, 0), _mm256_setzero_ps());
        let near = _mm256_max_ps(dist(b[near_plane[1]][slot], pk, 1), near);
        let near = _mm256_max_ps(dist(b[near_plane[2]][slot], pk, 2), near);
        let far = _mm256_min_ps(dist(b[far_plane[0]][slot], pk, 0), t_best);
        let far = _mm256_min_ps(dist(b[far_plane[1]][slot], pk, 1), far);
        let far = _mm256_min_ps(dist(b[far_plane[2]][slot], pk, 2), far);
        (may_hold(near, far), near)
    }

    /// `(plane - origin) * inverse direction` of axis `a`, per lane.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn dist(plane: f32, pk: &Packet, a: usize) -> __m256 {
        _mm256_mul_ps(_mm256_sub_ps(splat(plane), pk.o[a]), pk.inv[a])
    }

    /// `dot(d, c)` per lane, as [`crate::geometry::edge_function`] ends: `d.x c.x + d.y c.y + d.z c.z`.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn dot(d: &[__m256; 3], c: [f32; 3]) -> __m256 {
        add(add(mul(d[0], splat(c[0])), mul(d[1], splat(c[1]))), mul(d[2], splat(c[2])))
    }

    /// The edge-consistent test ([`crate::geometry::intersect`]) of `tri` for lanes that all start
    /// at `o`: everything but the direction is the same in every lane (the vertices relative to
    /// the origin, the edge functions' cross products, the plane's distance), so it is computed
    /// once, in scalar, with the same operations; the lanes compute only the dot products with
    /// their directions and the division. Returns what `packet`'s test returns.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn intersect_shared_origin(tri: &Triangle, o: [f32; 3], d: &[__m256; 3], t_max: __m256) -> [__m256; 5] {
        let rel = |p: [f32; 3]| [p[0] - o[0], p[1] - o[1], p[2] - o[2]];
        let (a0, a1, a2) = (rel(tri.p0), rel(tri.p1), rel(tri.p2));
        // The cross product of geometry::edge_function, operation by operation.
        let cross = |a: [f32; 3], b: [f32; 3]| {
            let e = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
            let s = [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
            [e[1] * s[2] - e[2] * s[1], e[2] * s[0] - e[0] * s[2], e[0] * s[1] - e[1] * s[0]]
        };
        let w2 = dot(d, cross(a0, a1));
        let w0 = dot(d, cross(a1, a2));
        let w1 = dot(d, cross(a2, a0));
        let zero = _mm256_setzero_ps();
        let positive = _mm256_and_ps(
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(w0, zero), _mm256_cmp_ps::<_CMP_GE_OQ>(w1, zero)),
            _mm256_cmp_ps::<_CMP_GE_OQ>(w2, zero),
        );
        let negative = _mm256_and_ps(
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(w0, zero), _mm256_cmp_ps::<_CMP_LE_OQ>(w1, zero)),
            _mm256_cmp_ps::<_CMP_LE_OQ>(w2, zero),
        );
        let sum = add(add(w0, w1), w2);
        let n = plane_normal(tri);
        let den = add(add(mul(splat(n[0]), d[0]), mul(splat(n[1]), d[1])), mul(splat(n[2]), d[2]));
        let t = _mm256_div_ps(splat(n[0] * a0[0] + n[1] * a0[1] + n[2] * a0[2]), den);
        let mut m = _mm256_or_ps(positive, negative);
        m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_NEQ_OQ>(sum, zero));
        m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_NEQ_OQ>(den, zero));
        m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_GT_OQ>(t, zero));
        m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_LE_OQ>(t, t_max));
        [m, t, w1, w2, sum]
    }

    /// [`slab_signed`] for lanes that all start at `o`: `plane - origin` once, in scalar.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn slab_shared_origin(
        b: &[[f32; WIDTH]; 6],
        slot: usize,
        o: [f32; 3],
        pk: &Packet,
        near_plane: &[usize; 3],
        far_plane: &[usize; 3],
        t_best: __m256,
    ) -> (__m256, __m256) {
        let (np, fp, inv) = (near_plane, far_plane, &pk.inv);
        let near = _mm256_max_ps(mul(splat(b[np[0]][slot] - o[0]), inv[0]), _mm256_setzero_ps());
        let near = _mm256_max_ps(mul(splat(b[np[1]][slot] - o[1]), inv[1]), near);
        let near = _mm256_max_ps(mul(splat(b[np[2]][slot] - o[2]), inv[2]), near);
        let far = _mm256_min_ps(mul(splat(b[fp[0]][slot] - o[0]), inv[0]), t_best);
        let far = _mm256_min_ps(mul(splat(b[fp[1]][slot] - o[1]), inv[1]), far);
        let far = _mm256_min_ps(mul(splat(b[fp[2]][slot] - o[2]), inv[2]), far);
        (may_hold(near, far), near)
    }

    #[target_feature(enable = "avx2")]
    pub fn trace<const ANY: bool, T: TriangleTest>(
        bvh: &Bvh8,
        rays: &Rays,
        stack: &mut Vec<Entry>,
        single: &mut Stack,
    ) -> Results {
        let load = |a: &[f32; LANES]| {
            // SAFETY: `a` holds 8 floats.
            unsafe { _mm256_loadu_ps(a.as_ptr()) }
        };
        // Lanes still looking: valid ones, minus (for any-hit) those already blocked.
        let (pk, mut alive) = packet_of(rays);
        let mut best = Best {
            t: load(&rays.t_max),
            tri: _mm256_set1_epi32(-1),
            w1: _mm256_setzero_ps(),
            w2: _mm256_setzero_ps(),
            sum: splat(1.0),
        };
        let mut hit_any = _mm256_setzero_ps();
        let mut n_nodes = _mm256_setzero_si256();
        let mut n_tris = _mm256_setzero_si256();
        // Whether every valid lane's inverse direction has one sign per axis (as a coherent
        // packet's have), and if so which planes the rays enter.
        let valid = _mm256_movemask_ps(alive);
        let negative: [i32; 3] = std::array::from_fn(|a| _mm256_movemask_ps(pk.inv[a]) & valid);
        let signed = negative.iter().all(|&n| n == 0 || n == valid);
        let near_plane: [usize; 3] = std::array::from_fn(|a| if negative[a] != 0 { 3 + a } else { a });
        let far_plane: [usize; 3] = std::array::from_fn(|a| if negative[a] != 0 { a } else { 3 + a });
        // The origin, where every valid lane starts at the same point (primary rays).
        let first = rays.valid.iter().position(|&v| v).unwrap_or(0);
        let o0 = [rays.origin[0][first], rays.origin[1][first], rays.origin[2][first]];
        let shared = (0..LANES)
            .all(|i| !rays.valid[i] || (0..3).all(|a| rays.origin[a][i].to_bits() == o0[a].to_bits()))
            .then_some(o0);
        // Work of the lanes finished alone.
        let mut alone = [Cost::default(); LANES];
        stack.clear();

        let mut cur = bvh.root;
        let mut cur_mask = alive;
        let mut live = any(cur_mask);
        while live {
            let lanes_in = _mm256_movemask_ps(cur_mask) as u32;
            if cur & LEAF == 0 && lanes_in.count_ones() <= SPARSE {
                // Few lanes: each finishes this subtree alone, from its best so far.
                let (mut t, mut tri) = (to_array(best.t), to_array_i(best.tri));
                let (mut w1, mut w2, mut sum, mut hit) =
                    (to_array(best.w1), to_array(best.w2), to_array(best.sum), to_array(hit_any));
                let mut alive_a = to_array(alive);
                let mut m = lanes_in;
                while m != 0 {
                    let i = m.trailing_zeros() as usize;
                    m &= m - 1;
                    let ray = rays.ray(i);
                    let found = bvh.trace_from::<ANY, T>(
                        Simd::Avx2,
                        cur,
                        &ray,
                        0.0,
                        (t[i], tri[i] as u32),
                        single,
                        &mut alone[i],
                    );
                    if let Some(f) = found {
                        (t[i], tri[i], w1[i], w2[i], sum[i]) = (f.t, f.tri as i32, f.w1, f.w2, f.sum);
                        hit[i] = f32::from_bits(u32::MAX);
                        if ANY {
                            alive_a[i] = 0.0;
                        }
                    }
                }
                best = Best {
                    t: load(&t),
                    // SAFETY: `tri` holds 8 ints.
                    tri: unsafe { _mm256_loadu_si256(tri.as_ptr().cast()) },
                    w1: load(&w1),
                    w2: load(&w2),
                    sum: load(&sum),
                };
                hit_any = load(&hit);
                alive = load(&alive_a);
            } else if cur & LEAF == 0 {
                let node = &bvh.nodes[cur as usize];
                // Per child entered: the lanes that enter it and their entry distances; and
                // (the nearest lane's entry distance, slot) to order them by.
                let mut masks = [_mm256_setzero_ps(); WIDTH];
                let mut nears = [_mm256_setzero_ps(); WIDTH];
                let mut order = [(0f32, 0usize); WIDTH];
                let mut n = 0;
                let mut valid = node.valid;
                while valid != 0 {
                    let slot = valid.trailing_zeros() as usize;
                    valid &= valid - 1;
                    n_nodes = count(n_nodes, cur_mask);
                    let b = &node.bounds;
                    let (m, near) = if let (true, Some(o)) = (signed, shared) {
                        slab_shared_origin(b, slot, o, &pk, &near_plane, &far_plane, best.t)
                    } else if signed {
                        slab_signed(b, slot, &pk, &near_plane, &far_plane, best.t)
                    } else {
                        let child = Node {
                            min: [b[0][slot], b[1][slot], b[2][slot]],
                            count: 0,
                            max: [b[3][slot], b[4][slot], b[5][slot]],
                            index: 0,
                        };
                        slab(&child, &pk, best.t)
                    };
                    let m = _mm256_and_ps(m, cur_mask);
                    if any(m) {
                        masks[slot] = m;
                        nears[slot] = near;
                        order[n] = (nearest(near, m), slot);
                        n += 1;
                    }
                }
                if n > 0 {
                    // Farthest first onto the stack (ties in slot order), the nearest entered.
                    for j in 1..n {
                        let e = order[j];
                        let mut k = j;
                        while k > 0 && order[k - 1].0 < e.0 {
                            order[k] = order[k - 1];
                            k -= 1;
                        }
                        order[k] = e;
                    }
                    for &(_, slot) in &order[..n - 1] {
                        stack.push(Entry { node: node.child[slot], mask: masks[slot], near: nears[slot] });
                    }
                    let slot = order[n - 1].1;
                    (cur, cur_mask) = (node.child[slot], masks[slot]);
                    continue;
                }
            } else {
                let block = &bvh.blocks[(cur & !LEAF) as usize];
                for lane in 0..WIDTH {
                    let i = block.index[lane];
                    if i == u32::MAX {
                        continue;
                    }
                    n_tris = count(n_tris, cur_mask);
                    let tri = block.triangle(lane);
                    let win = match (T::KIND, shared) {
                        (Intersect::Watertight, Some(o)) => {
                            keep(intersect_shared_origin(&tri, o, &pk.d, best.t), i, cur_mask, &mut best)
                        }
                        _ => test::<T>(&tri, i, &pk, cur_mask, &mut best),
                    };
                    hit_any = _mm256_or_ps(hit_any, win);
                    if ANY {
                        alive = _mm256_andnot_ps(win, alive);
                        cur_mask = _mm256_and_ps(cur_mask, alive);
                        if !any(cur_mask) {
                            break;
                        }
                    }
                }
            }
            live = false;
            while let Some(e) = stack.pop() {
                let m = _mm256_and_ps(_mm256_and_ps(e.mask, alive), may_hold(e.near, best.t));
                if any(m) {
                    cur = e.node;
                    cur_mask = m;
                    live = true;
                    break;
                }
            }
        }

        let (hit, tri) = (to_array(hit_any), to_array_i(best.tri));
        let (nn, nt) = (to_array_i(n_nodes), to_array_i(n_tris));
        let inv = _mm256_div_ps(splat(1.0), best.sum);
        let (u, v) = (_mm256_mul_ps(best.w1, inv), _mm256_mul_ps(best.w2, inv));
        let mut out = Results { t: to_array(best.t), u: to_array(u), v: to_array(v), ..Results::default() };
        // A loop, not `array::from_fn`: its closure would not be compiled for AVX2 nor inlined.
        for i in 0..LANES {
            out.hit[i] = hit[i].to_bits() != 0;
            out.tri[i] = tri[i] as u32;
            out.cost[i] = Cost { nodes: nn[i] as u32 + alone[i].nodes, tris: nt[i] as u32 + alone[i].tris };
        }
        out
    }
}
