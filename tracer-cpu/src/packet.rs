//! Coherent packets of 8 rays (a 4 x 2 pixel block) traced together with AVX2: one walk through
//! the child-pair tree for all 8, each node's box and each leaf's triangles tested 8-wide. The
//! renderer traces every stage of a block this way (`lanes::Packets`); this module is the kernel
//! alone.
//!
//! Every lane computes exactly what the scalar path computes, in the same order and without fused
//! multiply-adds, so a packet finds bit-identical hits (a test holds it to that).

use crate::geometry::{Cost, Hit, Ray, TriangleTest};
use crate::vertices::TriangleSource;
use bvh_format::Node;
use glam::Vec3;

/// Lanes of a packet.
pub use crate::wide::LANES;

/// Whether this CPU runs the packet path (and the renderer's AVX2 shading, which also counts
/// lanes with POPCNT: every CPU with AVX2 has it).
pub fn available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("popcnt")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Up to 8 rays, component by component across the lanes (as the kernel and the block shading
/// read them); lanes with `valid[i] == false` take no part. The inverse directions are computed
/// where they are needed (8-wide in the kernel, by [`Ray::new`] for one ray at a time).
// In this order, each array at a multiple of 32 bytes from the start, `valid` last: a copy of
// the block then moves each array as the 32-byte store that wrote it, which the CPU forwards.
// Rust's own layout put `valid` first, every array 8 bytes off, and each 32-byte load of a
// copy spanned two stores and waited for both to reach the cache (a tenth of the shading's time
// in bunny Whitted frames).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct Rays {
    pub origin: [[f32; LANES]; 3],
    pub dir: [[f32; LANES]; 3],
    pub t_max: [f32; LANES],
    pub valid: [bool; LANES],
}

impl Rays {
    /// Puts `ray` with `t_max` into lane `i` and marks it valid.
    pub fn set(&mut self, i: usize, ray: &Ray, t_max: f32) {
        for a in 0..3 {
            self.origin[a][i] = ray.origin[a];
            self.dir[a][i] = ray.dir[a];
        }
        self.t_max[i] = t_max;
        self.valid[i] = true;
    }

    /// The ray of lane `i`.
    pub fn ray(&self, i: usize) -> Ray {
        let v = |a: &[[f32; LANES]; 3]| Vec3::new(a[0][i], a[1][i], a[2][i]);
        Ray::new(v(&self.origin), v(&self.dir))
    }

    /// Valid lanes: the sum of the eight bytes (each 0 or 1) read as one word, which the
    /// multiplication adds up in its top byte (no byte's sum passes 8: nothing carries). One
    /// 8-byte read, which the single store of [`crate::wide::bools_of`] forwards; and two
    /// instructions where `count_ones` without POPCNT took a dozen.
    #[inline]
    pub fn count(&self) -> usize {
        (u64::from_le_bytes(self.valid.map(u8::from)).wrapping_mul(0x0101_0101_0101_0101) >> 56) as usize
    }
}

/// The result for each lane, component by component: whether it hit (for any-hit: is blocked),
/// the closest (or, for any-hit, some) hit's distance, triangle and barycentrics, and its work.
#[derive(Clone, Copy, Debug)]
pub struct Results {
    pub hit: [bool; LANES],
    pub t: [f32; LANES],
    pub tri: [u32; LANES],
    pub u: [f32; LANES],
    pub v: [f32; LANES],
    pub cost: [Cost; LANES],
}

impl Default for Results {
    fn default() -> Self {
        Self {
            hit: [false; LANES],
            t: [f32::INFINITY; LANES],
            tri: [u32::MAX; LANES],
            u: [0.0; LANES],
            v: [0.0; LANES],
            cost: [Cost::default(); LANES],
        }
    }
}

impl Results {
    /// Lane `i`'s hit.
    pub fn get(&self, i: usize) -> Option<Hit> {
        self.hit[i].then(|| Hit { t: self.t[i], tri: self.tri[i], u: self.u[i], v: self.v[i] })
    }

    /// Sets lane `i`'s hit.
    pub fn set(&mut self, i: usize, hit: Option<Hit>) {
        if let Some(h) = hit {
            (self.hit[i], self.t[i], self.tri[i], self.u[i], self.v[i]) = (true, h.t, h.tri, h.u, h.v);
        }
    }
}

/// Closest hits (`ANY == false`, `t_min` 0) or occlusion (`ANY == true`) for a packet, with the
/// triangle test `T` in every lane. Only call when [`available`] is true.
pub fn trace<const ANY: bool, T: TriangleTest>(
    nodes: &[Node],
    tris: &(impl TriangleSource + ?Sized),
    rays: &Rays,
    stack: &mut Vec<Entry>,
) -> Results {
    #[cfg(target_arch = "x86_64")]
    {
        assert!(available(), "the packet path needs AVX2; callers check `available()` first");
        // SAFETY: AVX2 is present (checked above).
        unsafe { avx2::trace::<ANY, T>(nodes, tris, rays, stack) }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = (nodes, tris, rays, stack);
        unreachable!("the packet path is only chosen where `available()` is true")
    }
}

/// A deferred subtree on the packet's stack: node, lane mask and per-lane entry distances.
#[derive(Clone, Copy)]
pub struct Entry {
    pub(crate) node: u32,
    #[cfg(target_arch = "x86_64")]
    pub(crate) mask: std::arch::x86_64::__m256,
    #[cfg(target_arch = "x86_64")]
    pub(crate) near: std::arch::x86_64::__m256,
}

#[cfg(target_arch = "x86_64")]
pub(crate) mod avx2 {
    use super::{Entry, LANES, Rays, Results};
    use crate::geometry::{Cost, TriangleTest};
    use crate::vertices::TriangleSource;
    use bvh_format::{Node, Triangle};
    use render_spec::Intersect;
    use render_spec::constants::T_SLACK;
    use std::arch::x86_64::*;

    pub(crate) struct Packet {
        pub o: [__m256; 3],
        pub d: [__m256; 3],
        pub inv: [__m256; 3],
    }

    #[inline(always)]
    pub(crate) fn splat(v: f32) -> __m256 {
        // SAFETY: plain register arithmetic; AVX is enabled for every caller of this module.
        unsafe { _mm256_set1_ps(v) }
    }

    /// The packet of `rays` splatted, with `Ray::new`'s reciprocal 8-wide (the same correctly
    /// rounded division), and the lanes still looking: the valid ones.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(crate) fn packet_of(rays: &Rays) -> (Packet, __m256) {
        let load = |a: &[f32; LANES]| {
            // SAFETY: `a` holds 8 floats.
            unsafe { _mm256_loadu_ps(a.as_ptr()) }
        };
        let o = [load(&rays.origin[0]), load(&rays.origin[1]), load(&rays.origin[2])];
        let d = [load(&rays.dir[0]), load(&rays.dir[1]), load(&rays.dir[2])];
        let one = splat(1.0);
        let inv = [_mm256_div_ps(one, d[0]), _mm256_div_ps(one, d[1]), _mm256_div_ps(one, d[2])];
        // The 8 `bool`s (bytes 0 or 1) widened to ints, then all bits set where 1.
        // SAFETY: `valid` holds 8 bytes.
        let valid = _mm256_cvtepu8_epi32(unsafe { _mm_loadl_epi64(rays.valid.as_ptr().cast()) });
        let alive = _mm256_castsi256_ps(_mm256_cmpgt_epi32(valid, _mm256_setzero_si256()));
        (Packet { o, d, inv }, alive)
    }

    #[target_feature(enable = "avx2")]
    pub(crate) fn to_array(v: __m256) -> [f32; LANES] {
        let mut a = [0f32; LANES];
        // SAFETY: `a` has room for 8 floats.
        unsafe { _mm256_storeu_ps(a.as_mut_ptr(), v) };
        a
    }

    #[target_feature(enable = "avx2")]
    pub(crate) fn to_array_i(v: __m256i) -> [i32; LANES] {
        let mut a = [0i32; LANES];
        // SAFETY: `a` has room for 8 ints.
        unsafe { _mm256_storeu_si256(a.as_mut_ptr().cast(), v) };
        a
    }

    /// The scalar slab test's comparisons, 8-wide; `_mm256_min_ps(a, b)` is `a < b ? a : b` and
    /// `_mm256_max_ps(a, b)` is `a > b ? a : b`, exactly the scalar `if`s. An axis with a NaN
    /// distance becomes NaN in both, which the last two comparisons then ignore, as the scalar
    /// path skips it.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(crate) fn slab(node: &Node, p: &Packet, t_max: __m256) -> (__m256, __m256) {
        let mut near = _mm256_setzero_ps();
        let mut far = t_max;
        for a in 0..3 {
            let t0 = _mm256_mul_ps(_mm256_sub_ps(splat(node.min[a]), p.o[a]), p.inv[a]);
            let t1 = _mm256_mul_ps(_mm256_sub_ps(splat(node.max[a]), p.o[a]), p.inv[a]);
            let unordered = _mm256_cmp_ps::<_CMP_UNORD_Q>(t0, t1);
            let enter = _mm256_or_ps(_mm256_min_ps(t1, t0), unordered);
            let exit = _mm256_or_ps(_mm256_max_ps(t0, t1), unordered);
            near = _mm256_max_ps(enter, near);
            far = _mm256_min_ps(exit, far);
        }
        (may_hold(near, far), near)
    }

    /// [`crate::geometry::may_hold`], 8-wide: `near <= t + |t| * T_SLACK`.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(crate) fn may_hold(near: __m256, t: __m256) -> __m256 {
        let abs = _mm256_andnot_ps(splat(-0.0), t);
        _mm256_cmp_ps::<_CMP_LE_OQ>(near, add(t, mul(abs, splat(T_SLACK))))
    }

    #[inline(always)]
    pub(crate) fn mul(a: __m256, b: __m256) -> __m256 {
        // SAFETY: register arithmetic under the callers' AVX2.
        unsafe { _mm256_mul_ps(a, b) }
    }
    #[inline(always)]
    pub(crate) fn sub(a: __m256, b: __m256) -> __m256 {
        // SAFETY: as above.
        unsafe { _mm256_sub_ps(a, b) }
    }
    #[inline(always)]
    pub(crate) fn add(a: __m256, b: __m256) -> __m256 {
        // SAFETY: as above.
        unsafe { _mm256_add_ps(a, b) }
    }

    /// [`geometry::edge_function`](crate::geometry::edge_function) on 8 lanes, same operations.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn edge_function(a: &[__m256; 3], b: &[__m256; 3], d: &[__m256; 3]) -> __m256 {
        let e = [sub(a[0], b[0]), sub(a[1], b[1]), sub(a[2], b[2])];
        let s = [add(a[0], b[0]), add(a[1], b[1]), add(a[2], b[2])];
        let c = [
            sub(mul(e[1], s[2]), mul(e[2], s[1])),
            sub(mul(e[2], s[0]), mul(e[0], s[2])),
            sub(mul(e[0], s[1]), mul(e[1], s[0])),
        ];
        add(add(mul(d[0], c[0]), mul(d[1], c[1])), mul(d[2], c[2]))
    }

    /// The edge-consistent test with the scalar path's operations
    /// ([`geometry::intersect`](crate::geometry::intersect)); returns (hit mask, t, w1, w2, sum):
    /// the barycentrics `u = w1 * (1 / sum)`, `v = w2 * (1 / sum)` are computed once, for the
    /// closest hit only, which saves a division per triangle and gives the same bits.
    #[target_feature(enable = "avx2")]
    #[inline]
    fn intersect(tri: &Triangle, pk: &Packet, t_min: __m256, t_max: __m256) -> [__m256; 5] {
        // The plane's normal is the triangle's alone: computed once, in scalar, as the scalar
        // path computes it.
        intersect_with_normal(tri, crate::geometry::plane_normal(tri), pk, t_min, t_max)
    }

    /// [`intersect`] with the triangle's [`plane_normal`](crate::geometry::plane_normal) given
    /// (the wide packets compute a leaf block's 8 normals at once).
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(crate) fn intersect_with_normal(
        tri: &Triangle,
        n: [f32; 3],
        pk: &Packet,
        t_min: __m256,
        t_max: __m256,
    ) -> [__m256; 5] {
        let all = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
        intersect_in(tri, n, pk, all, t_min, t_max).unwrap_or([_mm256_setzero_ps(); 5])
    }

    /// Lanes where the three edge functions agree in sign, a zero counting as either: the ray
    /// passes inside the triangle's edges or on one (the scalar test's condition; NaN lanes fail).
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(crate) fn inside_edges(w0: __m256, w1: __m256, w2: __m256) -> __m256 {
        let zero = _mm256_setzero_ps();
        let positive = _mm256_and_ps(
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(w0, zero), _mm256_cmp_ps::<_CMP_GE_OQ>(w1, zero)),
            _mm256_cmp_ps::<_CMP_GE_OQ>(w2, zero),
        );
        let negative = _mm256_and_ps(
            _mm256_and_ps(_mm256_cmp_ps::<_CMP_LE_OQ>(w0, zero), _mm256_cmp_ps::<_CMP_LE_OQ>(w1, zero)),
            _mm256_cmp_ps::<_CMP_LE_OQ>(w2, zero),
        );
        _mm256_or_ps(positive, negative)
    }

    /// [`intersect_with_normal`] for the lanes of `mv`: `None`, before the division, where none
    /// of them is inside the triangle's edges (the other lanes' results are not used).
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(crate) fn intersect_in(
        tri: &Triangle,
        n: [f32; 3],
        pk: &Packet,
        mv: __m256,
        t_min: __m256,
        t_max: __m256,
    ) -> Option<[__m256; 5]> {
        let (o, d) = (&pk.o, &pk.d);
        // Written out, not in closures: a closure does not inherit AVX2, so its lane operations
        // would not inline.
        let (p0, p1, p2) = (tri.p0, tri.p1, tri.p2);
        let a0 = [sub(splat(p0[0]), o[0]), sub(splat(p0[1]), o[1]), sub(splat(p0[2]), o[2])];
        let a1 = [sub(splat(p1[0]), o[0]), sub(splat(p1[1]), o[1]), sub(splat(p1[2]), o[2])];
        let a2 = [sub(splat(p2[0]), o[0]), sub(splat(p2[1]), o[1]), sub(splat(p2[2]), o[2])];
        let w2 = edge_function(&a0, &a1, d);
        let w0 = edge_function(&a1, &a2, d);
        let w1 = edge_function(&a2, &a0, d);
        let zero = _mm256_setzero_ps();
        let inside = _mm256_and_ps(inside_edges(w0, w1, w2), mv);
        if _mm256_movemask_ps(inside) == 0 {
            return None;
        }
        let sum = add(add(w0, w1), w2);
        let n = [splat(n[0]), splat(n[1]), splat(n[2])];
        let den = add(add(mul(n[0], d[0]), mul(n[1], d[1])), mul(n[2], d[2]));
        let t = _mm256_div_ps(add(add(mul(n[0], a0[0]), mul(n[1], a0[1])), mul(n[2], a0[2])), den);
        let mut m = inside;
        m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_NEQ_OQ>(sum, zero));
        m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_NEQ_OQ>(den, zero));
        m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_GT_OQ>(t, t_min));
        m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_LE_OQ>(t, t_max));
        Some([m, t, w1, w2, sum])
    }

    /// [`geometry::intersect_moller_trumbore`](crate::geometry::intersect_moller_trumbore) with
    /// the scalar path's operations; returns (hit mask, t, u, v, 1) in the form of [`intersect`]
    /// (`u * (1 / 1)` is `u`, bit for bit).
    #[target_feature(enable = "avx2")]
    #[inline]
    fn intersect_moller_trumbore(tri: &Triangle, pk: &Packet, t_min: __m256, t_max: __m256) -> [__m256; 5] {
        let (o, d) = (&pk.o, &pk.d);
        let v0 = tri.p0;
        // The edges are the triangle's alone: scalar, as the scalar path computes them.
        let e1 = [tri.p1[0] - v0[0], tri.p1[1] - v0[1], tri.p1[2] - v0[2]];
        let e2 = [tri.p2[0] - v0[0], tri.p2[1] - v0[1], tri.p2[2] - v0[2]];
        let (e1, e2) = ([splat(e1[0]), splat(e1[1]), splat(e1[2])], [splat(e2[0]), splat(e2[1]), splat(e2[2])]);
        let p = [
            sub(mul(d[1], e2[2]), mul(e2[1], d[2])),
            sub(mul(d[2], e2[0]), mul(e2[2], d[0])),
            sub(mul(d[0], e2[1]), mul(e2[0], d[1])),
        ];
        let det = add(add(mul(e1[0], p[0]), mul(e1[1], p[1])), mul(e1[2], p[2]));
        let one = splat(1.0);
        let inv = _mm256_div_ps(one, det);
        let s = [sub(o[0], splat(v0[0])), sub(o[1], splat(v0[1])), sub(o[2], splat(v0[2]))];
        let u = mul(add(add(mul(s[0], p[0]), mul(s[1], p[1])), mul(s[2], p[2])), inv);
        let q = [
            sub(mul(s[1], e1[2]), mul(e1[1], s[2])),
            sub(mul(s[2], e1[0]), mul(e1[2], s[0])),
            sub(mul(s[0], e1[1]), mul(e1[0], s[1])),
        ];
        let v = mul(add(add(mul(d[0], q[0]), mul(d[1], q[1])), mul(d[2], q[2])), inv);
        let t = mul(add(add(mul(e2[0], q[0]), mul(e2[1], q[1])), mul(e2[2], q[2])), inv);
        let zero = _mm256_setzero_ps();
        // The scalar conditions exactly, NaN included: `det != 0`, `0 <= u <= 1` (ordered),
        // `!(v < 0)` and `!(u + v > 1)` (unordered: a NaN passes them, as in the scalar test),
        // then `t_min < t <= t_max`.
        let mut m = _mm256_cmp_ps::<_CMP_NEQ_UQ>(det, zero);
        m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_GE_OQ>(u, zero));
        m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_LE_OQ>(u, one));
        m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_NLT_UQ>(v, zero));
        m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_NGT_UQ>(add(u, v), one));
        m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_GT_OQ>(t, t_min));
        m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_LE_OQ>(t, t_max));
        [m, t, u, v, one]
    }

    /// Adds 1 to the counters of the lanes in `mask`.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(crate) fn count(acc: __m256i, mask: __m256) -> __m256i {
        // An all-ones lane is -1.
        _mm256_sub_epi32(acc, _mm256_castps_si256(mask))
    }

    #[target_feature(enable = "avx2")]
    #[inline]
    pub(crate) fn any(mask: __m256) -> bool {
        _mm256_movemask_ps(mask) != 0
    }

    /// The lanes' closest hits so far: distance, triangle, and the edge functions w1, w2 and
    /// their sum (Möller-Trumbore: u, v and 1).
    pub(crate) struct Best {
        pub t: __m256,
        pub tri: __m256i,
        pub w1: __m256,
        pub w2: __m256,
        pub sum: __m256,
    }

    /// Tests triangle `tri` (index `i`) against the lanes in `mask` with the test `T` and keeps
    /// each lane's hit where it beats the lane's best ([`Hit::beats`](crate::Hit::beats)); returns
    /// the lanes it won.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(crate) fn test<T: TriangleTest>(tri: &Triangle, i: u32, pk: &Packet, mask: __m256, best: &mut Best) -> __m256 {
        // A constant per instance: the other test is compiled out.
        let found = match T::KIND {
            Intersect::Watertight => intersect(tri, pk, _mm256_setzero_ps(), best.t),
            Intersect::MollerTrumbore => intersect_moller_trumbore(tri, pk, _mm256_setzero_ps(), best.t),
        };
        keep(found, i, mask, best)
    }

    /// Keeps the hits `[hit mask, t, w1, w2, sum]` of triangle `i` in the lanes of `mask` where
    /// they beat the lane's best; returns the lanes it won.
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(crate) fn keep([m, t, w1, w2, sum]: [__m256; 5], i: u32, mask: __m256, best: &mut Best) -> __m256 {
        // Hit::beats: nearer, or equally near with a lower index (unsigned compare through a
        // sign flip).
        let bias = _mm256_set1_epi32(i32::MIN);
        let idx = _mm256_set1_epi32(i as i32);
        let lower =
            _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_xor_si256(best.tri, bias), _mm256_xor_si256(idx, bias)));
        let nearer = _mm256_cmp_ps::<_CMP_LT_OQ>(t, best.t);
        let tie = _mm256_and_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(t, best.t), lower);
        let win = _mm256_and_ps(_mm256_and_ps(m, mask), _mm256_or_ps(nearer, tie));
        best.t = _mm256_blendv_ps(best.t, t, win);
        best.w1 = _mm256_blendv_ps(best.w1, w1, win);
        best.w2 = _mm256_blendv_ps(best.w2, w2, win);
        best.sum = _mm256_blendv_ps(best.sum, sum, win);
        best.tri = _mm256_castps_si256(_mm256_blendv_ps(_mm256_castsi256_ps(best.tri), _mm256_castsi256_ps(idx), win));
        win
    }

    #[target_feature(enable = "avx2")]
    pub fn trace<const ANY: bool, T: TriangleTest>(
        nodes: &[Node],
        tris: &(impl TriangleSource + ?Sized),
        rays: &Rays,
        stack: &mut Vec<Entry>,
    ) -> Results {
        let load = |a: &[f32; LANES]| {
            // SAFETY: `a` holds 8 floats.
            unsafe { _mm256_loadu_ps(a.as_ptr()) }
        };
        // Lanes still looking: valid ones, minus (for any-hit) those already blocked.
        let (pk, mut alive) = packet_of(rays);
        let mut best_t = load(&rays.t_max);
        let mut best_tri = _mm256_set1_epi32(-1);
        // The closest hit's edge functions w1, w2 and their sum (one for lanes without a hit;
        // Möller-Trumbore's u, v and 1).
        let mut best_w1 = _mm256_setzero_ps();
        let mut best_w2 = _mm256_setzero_ps();
        let mut best_sum = splat(1.0);
        let mut hit_any = _mm256_setzero_ps();
        let mut n_nodes = _mm256_setzero_si256();
        let mut n_tris = _mm256_setzero_si256();
        stack.clear();

        n_nodes = count(n_nodes, alive);
        let (m, _) = slab(&nodes[0], &pk, best_t);
        let mut cur_mask = _mm256_and_ps(m, alive);
        let mut current = 0usize;
        let mut live = any(cur_mask);
        while live {
            let node = &nodes[current];
            let mut descend = false;
            if node.is_leaf() {
                for i in node.index..node.index + node.count {
                    n_tris = count(n_tris, cur_mask);
                    let mut b = Best { t: best_t, tri: best_tri, w1: best_w1, w2: best_w2, sum: best_sum };
                    let win = test::<T>(&tris.triangle(i), i, &pk, cur_mask, &mut b);
                    Best { t: best_t, tri: best_tri, w1: best_w1, w2: best_w2, sum: best_sum } = b;
                    hit_any = _mm256_or_ps(hit_any, win);
                    if ANY {
                        alive = _mm256_andnot_ps(win, alive);
                        cur_mask = _mm256_and_ps(cur_mask, alive);
                        if !any(alive) {
                            break;
                        }
                    }
                }
            } else {
                let (l, r) = (node.index as usize, node.index as usize + 1);
                n_nodes = count(n_nodes, cur_mask);
                n_nodes = count(n_nodes, cur_mask);
                let (ml, nl) = slab(&nodes[l], &pk, best_t);
                let (mr, nr) = slab(&nodes[r], &pk, best_t);
                let ml = _mm256_and_ps(ml, cur_mask);
                let mr = _mm256_and_ps(mr, cur_mask);
                match (any(ml), any(mr)) {
                    (true, true) => {
                        // The majority of the lanes that hit both decides which goes first.
                        let both = _mm256_and_ps(ml, mr);
                        let right_first = _mm256_and_ps(both, _mm256_cmp_ps::<_CMP_LT_OQ>(nr, nl));
                        let votes_right = _mm256_movemask_ps(right_first).count_ones();
                        let votes_left = _mm256_movemask_ps(both).count_ones() - votes_right;
                        let (near, nm, far, fm, fnear) =
                            if votes_right > votes_left { (r, mr, l, ml, nl) } else { (l, ml, r, mr, nr) };
                        stack.push(Entry { node: far as u32, mask: fm, near: fnear });
                        current = near;
                        cur_mask = nm;
                        descend = true;
                    }
                    (true, false) => {
                        current = l;
                        cur_mask = ml;
                        descend = true;
                    }
                    (false, true) => {
                        current = r;
                        cur_mask = mr;
                        descend = true;
                    }
                    (false, false) => {}
                }
            }
            if descend {
                continue;
            }
            live = false;
            while let Some(e) = stack.pop() {
                let m = _mm256_and_ps(_mm256_and_ps(e.mask, alive), may_hold(e.near, best_t));
                if any(m) {
                    current = e.node as usize;
                    cur_mask = m;
                    live = true;
                    break;
                }
            }
        }

        let tri = to_array_i(best_tri);
        let (nn, nt) = (to_array_i(n_nodes), to_array_i(n_tris));
        let inv = _mm256_div_ps(splat(1.0), best_sum);
        let (best_u, best_v) = (mul(best_w1, inv), mul(best_w2, inv));
        let hit = crate::wide::bools_of(hit_any);
        let mut out =
            Results { hit, t: to_array(best_t), u: to_array(best_u), v: to_array(best_v), ..Results::default() };
        // A loop, not `array::from_fn`: its closure would not be compiled for AVX2 nor inlined.
        for i in 0..LANES {
            out.tri[i] = tri[i] as u32;
            out.cost[i] = Cost { nodes: nn[i] as u32, tris: nt[i] as u32 };
        }
        out
    }
}
