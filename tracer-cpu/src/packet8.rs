//! Coherent packets of 8 rays (a 4 x 2 pixel block) through the wide BVH ([`crate::bvh8`]) with
//! AVX2 (compiled twice: for AVX2, and for AVX-512's registers where the CPU has them), the way
//! Embree's `rtcIntersect8` walks a coherent packet. The lanes are split by the signs
//! of their directions (one walk per octant; a lane with an axis-parallel direction goes alone).
//! Per walk a frustum bounds the lanes' origins and reciprocal directions; at a node one 8-wide
//! sequence tests all 8 children against the frustum (no child a lane enters fails it). Where the
//! lanes share an origin (primary rays), whose frustum is tight, every inner child it lets through
//! takes all the node's lanes along; otherwise one more sequence tests the children exactly against
//! the first live lane, and an inner child that lane enters takes all the node's lanes along. The
//! other children get only the lanes their exact per-lane test lets in, and a leaf block always
//! only those. Children are visited nearest first by the frustum's entry distance
//! (closest hit; any hit: last to first, as Embree), deferred ones on a stack of (node, lane bits,
//! distance). A leaf block is tested one triangle at a time against the lanes, or, where the lanes
//! do not share an origin and that takes fewer vector tests (by 1.25 times), one lane at a time
//! against all its triangles (the single-ray block test), or 2 or 4 lanes at a time against a block
//! of at most 4 or 2 triangles. Where all lanes share an origin (primary rays) the part of the
//! triangle test that does not depend on the direction is computed once per block, 8 triangles at a
//! time. A triangle test stops before its division where no lane is inside the triangle's edges
//! (most triangles of a block, for every lane) or, for lanes without a shared origin, where none
//! has the triangle's plane ahead (a shadow ray's own triangle). A subtree reached by at most
//! [`SPARSE`] live lanes is finished one ray at a time on the wide BVH's single-ray traversal.
//!
//! Every lane computes what the scalar path computes (the slab test and the triangle tests of
//! [`crate::packet`], operation by operation), so the hits are bit for bit the ordered traversal's
//! (`tests/hits.rs`). The whole-node lane masks are a superset of the exact ones, which changes
//! no hit: a lane reaches a triangle only through the exact test of the triangle's leaf box, and
//! a lane that passes a box passes every box around it (the rounded distances are monotonic in
//! the planes), so it passes every test the ordered traversal puts on its way.

use crate::bvh8::{Bvh8, Simd};
use crate::geometry::{MollerTrumbore, TriangleTest, Watertight};
use crate::lanes::TraceLanes;
use crate::packet::{Entry, Rays, Results};
use crate::traverse::Stack;
use render_spec::Intersect;

/// Live lanes at or below which a subtree is traced one ray at a time (2 measured as fast as or
/// faster than 0, 4 and 6 on the bunny, the dragon and the million-triangle scene).
pub const SPARSE: u32 = 2;

// `trace` stores the lanes' work counts into `Results::cost` as two 256-bit halves: that field
// must be exactly 64 bytes, eight `Cost`s of two `u32`s each.
const _: () = assert!(std::mem::size_of::<[crate::geometry::Cost; crate::packet::LANES]>() == 64);

/// Whether this CPU runs wide packets (AVX2, as [`crate::packet`], and the single-ray AVX2
/// traversal's POPCNT and FMA, which finish the sparse lanes).
pub fn available() -> bool {
    crate::packet::available() && Simd::Avx2.supported()
}

/// [`available`], detected once: the check guards every packet, and the feature tests it makes
/// were 2% of the bunny's packet instructions.
fn available_cached() -> bool {
    static AVAILABLE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *AVAILABLE.get_or_init(available)
}

/// Closest hits (`ANY == false`, `t_min` 0) or occlusion (`ANY == true`) of the valid lanes of
/// `rays` with the triangle test `T`: the packet's stack and one for the lanes finished alone.
/// Compiled for the BVH's instruction set ([`Bvh8::simd`]: AVX-512 where the CPU has it, else
/// AVX2). Only call when [`available`] is true.
#[inline]
pub fn trace<const ANY: bool, T: TriangleTest>(
    bvh: &Bvh8,
    rays: &Rays,
    stack: &mut Vec<Entry>,
    single: &mut Stack,
) -> Results {
    // The BVH's path is one this CPU runs (`Simd::detect`).
    trace_supported::<ANY, T>(bvh.simd(), bvh, rays, stack, single)
}

/// [`trace`] compiled for `simd` (the tests run every path this CPU has; a path the CPU lacks
/// runs the widest below it): AVX-512, or AVX2 for every narrower one. The same hits on every
/// path. Only call when [`available`] is true.
pub fn trace_on<const ANY: bool, T: TriangleTest>(
    simd: Simd,
    bvh: &Bvh8,
    rays: &Rays,
    stack: &mut Vec<Entry>,
    single: &mut Stack,
) -> Results {
    trace_supported::<ANY, T>(Simd::best_up_to(simd), bvh, rays, stack, single)
}

/// [`trace_on`] for a path `simd` this CPU supports.
#[inline]
fn trace_supported<const ANY: bool, T: TriangleTest>(
    simd: Simd,
    bvh: &Bvh8,
    rays: &Rays,
    stack: &mut Vec<Entry>,
    single: &mut Stack,
) -> Results {
    #[cfg(target_arch = "x86_64")]
    {
        assert!(available_cached(), "wide packets need AVX2; callers check `available()` first");
        if simd == Simd::Avx512 {
            // SAFETY: AVX-512 F, VL, DQ and BW are present (a supported path) with AVX2 and
            // POPCNT (checked above).
            return unsafe { avx512::trace::<ANY, T>(bvh, rays, stack, single) };
        }
        // SAFETY: AVX2 and POPCNT are present (checked above).
        unsafe { avx2::trace::<ANY, T>(bvh, rays, stack, single) }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = (simd, bvh, rays, stack, single);
        unreachable!("wide packets are only chosen where `available()` is true")
    }
}

/// The instruction sets [`trace_on`] compiles the packets for that this CPU runs, narrowest first.
pub fn paths() -> Vec<Simd> {
    if !available_cached() {
        return Vec::new();
    }
    [Simd::Avx2, Simd::Avx512].into_iter().filter(|s| s.supported()).collect()
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

/// Defines the module `$module`: the packet walk, its leaf tests and its lanes finished alone, every
/// function compiled with the target features `$features` (one `#[target_feature]` per function:
/// they are kept out of line by measurement, see [`avx2`]'s `leaf`).
#[cfg(target_arch = "x86_64")]
macro_rules! packet_walk_compiled_for {
    ($(#[$doc:meta])* $module:ident, $features:literal) => {
        $(#[$doc])*
        mod $module {
        use super::SPARSE;

        use crate::bvh8::avx2::{Lanes, cross, dot as dot3, edge_function, moller_trumbore, prefetch, watertight};
        use crate::bvh8::{Bvh8, LEAF, Simd, TriBlock, WIDTH, each3};
        use crate::geometry;
        use crate::geometry::Hit;
        use crate::geometry::{Cost, TriangleTest};
        use crate::packet::avx2::{
            Best, Packet, add, any, count, inside_edges, keep, may_hold, mul, packet_of, splat, sub, test,
        };
        use crate::packet::{Entry, LANES, Rays, Results};
        use crate::traverse::Stack;
        use render_spec::Intersect;
        use std::arch::x86_64::*;

        /// The box test of slot `slot` of `b` (a wide node's bounds) for all lanes whose inverse
        /// directions have, per axis, the sign that chose `near_plane` and `far_plane`: the
        /// single-ray AVX2 test's operations ([`crate::bvh8`]), lane by lane the scalar slab test's
        /// result, with fewer operations than `packet`'s slab test (which finds each lane's entered plane).
        /// Always inlined (without AVX2 of its own, as [`one_lane`]): with POPCNT enabled LLVM moved
        /// it out of the walk.
        #[inline(always)]
        fn slab_signed(
            b: &[[f32; WIDTH]; 6],
            slot: usize,
            pk: &Packet,
            near_plane: &[usize; 3],
            far_plane: &[usize; 3],
            t_best: __m256,
        ) -> (__m256, __m256) {
            // SAFETY: register arithmetic under the caller's AVX2.
            unsafe {
                // Written out, not in a closure: a closure does not inherit AVX2.
                let near = _mm256_max_ps(dist(b[near_plane[0]][slot], pk, 0), _mm256_setzero_ps());
                let near = _mm256_max_ps(dist(b[near_plane[1]][slot], pk, 1), near);
                let near = _mm256_max_ps(dist(b[near_plane[2]][slot], pk, 2), near);
                let far = _mm256_min_ps(dist(b[far_plane[0]][slot], pk, 0), t_best);
                let far = _mm256_min_ps(dist(b[far_plane[1]][slot], pk, 1), far);
                let far = _mm256_min_ps(dist(b[far_plane[2]][slot], pk, 2), far);
                (may_hold(near, far), near)
            }
        }

        /// `(plane - origin) * inverse direction` of axis `a`, per lane.
        #[inline(always)]
        fn dist(plane: f32, pk: &Packet, a: usize) -> __m256 {
            mul(sub(splat(plane), pk.o[a]), pk.inv[a])
        }

        /// `dot(d, c)` per lane, as [`crate::geometry::edge_function`] ends: `d.x c.x + d.y c.y + d.z c.z`.
        #[target_feature(enable = $features)]
        #[inline]
        fn dot(d: &[__m256; 3], c: [f32; 3]) -> __m256 {
            add(add(mul(d[0], splat(c[0])), mul(d[1], splat(c[1]))), mul(d[2], splat(c[2])))
        }

        /// What the edge-consistent test ([`crate::geometry::intersect`]) computes of the triangles
        /// of a leaf block for rays that all start at `o`, everything but the direction: the edge
        /// functions' cross products (`geometry::edge_function`'s, of the vertices relative to the
        /// origin), the plane normal ([`crate::geometry::plane_normal`]) and the plane's distance, each an array over
        /// the block's triangles, computed 8-wide with the scalar test's operations in its order.
        struct SharedOrigin {
            /// `cross[k][axis]`: the cross product of edge function `w_k`.
            cross: [[[f32; WIDTH]; 3]; 3],
            n: [[f32; WIDTH]; 3],
            dist: [f32; WIDTH],
        }

        /// The plane normals ([`crate::geometry::plane_normal`]) of a block's triangles, 8-wide with
        /// the scalar operations.
        #[target_feature(enable = $features)]
        #[inline]
        fn normals(block: &TriBlock) -> [__m256; 3] {
            let p = &block.p;
            let ld = |r: &[f32; WIDTH]| {
                // SAFETY: `r` holds 8 floats.
                unsafe { _mm256_loadu_ps(r.as_ptr()) }
            };
            let e1 = each3(|a| sub(ld(&p[1][a]), ld(&p[0][a])));
            let e2 = each3(|a| sub(ld(&p[2][a]), ld(&p[0][a])));
            [
                sub(mul(e1[1], e2[2]), mul(e1[2], e2[1])),
                sub(mul(e1[2], e2[0]), mul(e1[0], e2[2])),
                sub(mul(e1[0], e2[1]), mul(e1[1], e2[0])),
            ]
        }

        #[target_feature(enable = $features)]
        #[inline]
        fn shared_origin(block: &TriBlock, o: [f32; 3]) -> SharedOrigin {
            let p = &block.p;
            let ld = |r: &[f32; WIDTH]| {
                // SAFETY: `r` holds 8 floats.
                unsafe { _mm256_loadu_ps(r.as_ptr()) }
            };
            let rel = |k: usize| each3(|a| sub(ld(&p[k][a]), splat(o[a])));
            let (a0, a1, a2) = (rel(0), rel(1), rel(2));
            let cross = |a: [__m256; 3], b: [__m256; 3]| {
                let e = [sub(a[0], b[0]), sub(a[1], b[1]), sub(a[2], b[2])];
                let s = [add(a[0], b[0]), add(a[1], b[1]), add(a[2], b[2])];
                [
                    sub(mul(e[1], s[2]), mul(e[2], s[1])),
                    sub(mul(e[2], s[0]), mul(e[0], s[2])),
                    sub(mul(e[0], s[1]), mul(e[1], s[0])),
                ]
            };
            let n = normals(block);
            let dist = add(add(mul(n[0], a0[0]), mul(n[1], a0[1])), mul(n[2], a0[2]));
            SharedOrigin {
                cross: {
                    let c = [cross(a1, a2), cross(a2, a0), cross(a0, a1)];
                    each3(|k| each3(|a| store(c[k][a])))
                },
                n: each3(|a| store(n[a])),
                dist: store(dist),
            }
        }

        /// The edge-consistent test of triangle `l` of the block `s` was made from, for lanes that
        /// all start at its origin: only the dot products with the lanes' directions and the
        /// division run per lane. Returns what `packet`'s test returns, or `None` where no lane of
        /// `mv` is inside the triangle's edges (nothing further can hit).
        #[target_feature(enable = $features)]
        #[inline]
        fn intersect_shared_origin(
            s: &SharedOrigin,
            l: usize,
            d: &[__m256; 3],
            mv: __m256,
            t_max: __m256,
        ) -> Option<[__m256; 5]> {
            let c = |k: usize| [s.cross[k][0][l], s.cross[k][1][l], s.cross[k][2][l]];
            let w0 = dot(d, c(0));
            let w1 = dot(d, c(1));
            let w2 = dot(d, c(2));
            let zero = _mm256_setzero_ps();
            // Most triangles of a block are missed by every lane: those end before the division.
            let inside = _mm256_and_ps(inside_edges(w0, w1, w2), mv);
            if _mm256_movemask_ps(inside) == 0 {
                return None;
            }
            let sum = add(add(w0, w1), w2);
            let n = [s.n[0][l], s.n[1][l], s.n[2][l]];
            let den = add(add(mul(splat(n[0]), d[0]), mul(splat(n[1]), d[1])), mul(splat(n[2]), d[2]));
            let t = _mm256_div_ps(splat(s.dist[l]), den);
            let mut m = inside;
            m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_NEQ_OQ>(sum, zero));
            m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_NEQ_OQ>(den, zero));
            m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_GT_OQ>(t, zero));
            m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_LE_OQ>(t, t_max));
            Some([m, t, w1, w2, sum])
        }

        /// [`slab_signed`] for lanes that all start at `o`: `plane - origin` once, in scalar. Always
        /// inlined, as [`slab_signed`].
        #[inline(always)]
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
            // SAFETY: register arithmetic under the caller's AVX2.
            unsafe {
                let near = _mm256_max_ps(mul(splat(b[np[0]][slot] - o[0]), inv[0]), _mm256_setzero_ps());
                let near = _mm256_max_ps(mul(splat(b[np[1]][slot] - o[1]), inv[1]), near);
                let near = _mm256_max_ps(mul(splat(b[np[2]][slot] - o[2]), inv[2]), near);
                let far = _mm256_min_ps(mul(splat(b[fp[0]][slot] - o[0]), inv[0]), t_best);
                let far = _mm256_min_ps(mul(splat(b[fp[1]][slot] - o[1]), inv[1]), far);
                let far = _mm256_min_ps(mul(splat(b[fp[2]][slot] - o[2]), inv[2]), far);
                (may_hold(near, far), near)
            }
        }

        /// A deferred subtree: node, the lanes that go into it (bits), and the packet's lower bound
        /// on their entry distance (the frustum's).
        #[derive(Clone, Copy)]
        struct Item {
            node: u32,
            mask: u32,
            near: f32,
        }

        /// The packet's stack: a fixed array that covers the trees our builder makes, spilling into
        /// the caller's `Vec<Entry>` beyond (never on those trees).
        struct Items<'a> {
            inline: &'a mut [std::mem::MaybeUninit<Item>; INLINE],
            len: usize,
            spill: &'a mut Vec<Entry>,
        }
        const INLINE: usize = 256;

        impl<'a> Items<'a> {
            #[inline(always)]
            fn new(inline: &'a mut [std::mem::MaybeUninit<Item>; INLINE], spill: &'a mut Vec<Entry>) -> Self {
                spill.clear();
                Self { inline, len: 0, spill }
            }
            #[inline(always)]
            fn push(&mut self, e: Item) {
                if self.len < self.inline.len() {
                    self.inline[self.len] = std::mem::MaybeUninit::new(e);
                } else {
                    // SAFETY: register arithmetic; AVX2 is enabled in every caller.
                    let (mask, near) = unsafe { (_mm256_castsi256_ps(_mm256_set1_epi32(e.mask as i32)), splat(e.near)) };
                    self.spill.push(Entry { node: e.node, mask, near });
                }
                self.len += 1;
            }
            #[inline(always)]
            fn clear(&mut self) {
                self.len = 0;
                self.spill.clear();
            }
            #[inline(always)]
            fn pop(&mut self) -> Option<Item> {
                if self.len == 0 {
                    return None;
                }
                self.len -= 1;
                if self.len < self.inline.len() {
                    // SAFETY: slots below `len` were written by `push`.
                    Some(unsafe { self.inline[self.len].assume_init() })
                } else {
                    let e = self.spill.pop()?;
                    // SAFETY: as in `push`.
                    let (mask, near) =
                        unsafe { (_mm256_cvtsi256_si32(_mm256_castps_si256(e.mask)) as u32, _mm256_cvtss_f32(e.near)) };
                    Some(Item { node: e.node, mask, near })
                }
            }
        }

        /// The lanes in the bits of `m` as a mask vector.
        #[target_feature(enable = $features)]
        #[inline]
        fn mask_of(m: u32) -> __m256 {
            let bit = _mm256_setr_epi32(1, 2, 4, 8, 16, 32, 64, 128);
            _mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_and_si256(_mm256_set1_epi32(m as i32), bit), bit))
        }

        /// `v`'s lanes (inlined everywhere, unlike `packet`'s `to_array`).
        #[inline(always)]
        fn store(v: __m256) -> [f32; LANES] {
            let mut a = [0f32; LANES];
            // SAFETY: `a` has room for 8 floats; AVX is enabled in every caller.
            unsafe { _mm256_storeu_ps(a.as_mut_ptr(), v) };
            a
        }

        /// `v`'s lanes, as [`store`].
        #[inline(always)]
        fn store_i(v: __m256i) -> [i32; LANES] {
            let mut a = [0i32; LANES];
            // SAFETY: `a` has room for 8 ints; AVX is enabled in every caller.
            unsafe { _mm256_storeu_si256(a.as_mut_ptr().cast(), v) };
            a
        }

        /// The smallest lane of each of 4 vectors at once: that of `v[k]` in lane `SMALLEST4[k]`.
        #[inline(always)]
        fn smallest4(v: [__m256; 4]) -> __m256 {
            // SAFETY: register arithmetic under the callers' AVX2.
            unsafe {
                // Halves: lanes 0-3 hold v[0]'s 4 partial minima and 4-7 v[1]'s; likewise v[2], v[3].
                let x =
                    _mm256_min_ps(_mm256_permute2f128_ps::<0x20>(v[0], v[1]), _mm256_permute2f128_ps::<0x31>(v[0], v[1]));
                let y =
                    _mm256_min_ps(_mm256_permute2f128_ps::<0x20>(v[2], v[3]), _mm256_permute2f128_ps::<0x31>(v[2], v[3]));
                // Per half: two partials of x's vector, then two of y's.
                let z = _mm256_min_ps(_mm256_shuffle_ps::<0b01_00_01_00>(x, y), _mm256_shuffle_ps::<0b11_10_11_10>(x, y));
                _mm256_min_ps(z, _mm256_permute_ps::<0b10_11_00_01>(z))
            }
        }
        const SMALLEST4: [i32; 4] = [0, 4, 2, 6];

        /// The largest of `v`'s lanes in `mask` (-inf where none).
        #[target_feature(enable = $features)]
        #[inline]
        fn largest(v: __m256, mask: __m256) -> f32 {
            let v = _mm256_blendv_ps(splat(f32::NEG_INFINITY), v, mask);
            let v = _mm256_max_ps(v, _mm256_permute2f128_ps::<1>(v, v));
            let v = _mm256_max_ps(v, _mm256_permute_ps::<0b01_00_11_10>(v));
            let v = _mm256_max_ps(v, _mm256_permute_ps::<0b10_11_00_01>(v));
            _mm256_cvtss_f32(v)
        }

        /// Bounds on the rays of a group of lanes whose inverse directions are finite and have one
        /// sign per axis, for a test of all 8 children of a node at once that no child any of the
        /// lanes enters fails (Embree's coherent traversal's frustum test). Per axis the lanes'
        /// distance to a plane, `fl(fl(plane - o) * inv)`, is monotonic in `o` and in `inv` (rounding
        /// keeps order), so it lies between the products of the extreme origins and reciprocals.
        struct Frustum {
            near_plane: [usize; 3],
            far_plane: [usize; 3],
            /// Per axis the origin whose difference bounds the lanes' entry distances from below
            /// (the largest origin where the lanes go up the axis), and their exit distances from above.
            o_near: [__m256; 3],
            o_far: [__m256; 3],
            inv_lo: [__m256; 3],
            inv_hi: [__m256; 3],
        }

        impl Frustum {
            /// The frustum of the lanes in `group` (bits) of `pk`, from its shared origin if any.
            #[target_feature(enable = $features)]
            #[inline]
            fn new(pk: &Packet, shared: Option<[f32; 3]>, group: u32, negative: &[u32; 3]) -> Self {
                let m = mask_of(group);
                let (inf, neg) = (splat(f32::INFINITY), splat(-0.0));
                // The smallest of each vector's lanes in the group; the largest as the smallest
                // negated (negation is exact).
                let lo = |v: __m256| _mm256_blendv_ps(inf, v, m);
                let hi = |v: __m256| _mm256_blendv_ps(inf, _mm256_xor_ps(v, neg), m);
                let (o, inv) = (&pk.o, &pk.inv);
                let lane = |v: __m256, i: i32| _mm256_permutevar8x32_ps(v, _mm256_set1_epi32(i));
                let neg_lane = |v: __m256, i: i32| _mm256_xor_ps(lane(v, i), neg);
                // With a shared origin only the 6 bounds of the reciprocals are needed.
                let c = smallest4([lo(inv[1]), lo(inv[2]), hi(inv[1]), hi(inv[2])]);
                let (olo, ohi, a, b) = match shared {
                    Some(o) => {
                        let a = smallest4([lo(inv[0]), hi(inv[0]), lo(inv[0]), lo(inv[0])]);
                        (each3(|k| splat(o[k])), each3(|k| splat(o[k])), lane(a, SMALLEST4[0]), neg_lane(a, SMALLEST4[1]))
                    }
                    None => {
                        let a = smallest4([lo(o[0]), lo(o[1]), lo(o[2]), lo(inv[0])]);
                        let b = smallest4([hi(o[0]), hi(o[1]), hi(o[2]), hi(inv[0])]);
                        (
                            each3(|k| lane(a, SMALLEST4[k])),
                            each3(|k| neg_lane(b, SMALLEST4[k])),
                            lane(a, SMALLEST4[3]),
                            neg_lane(b, SMALLEST4[3]),
                        )
                    }
                };
                let inv_lo = [a, lane(c, SMALLEST4[0]), lane(c, SMALLEST4[1])];
                let inv_hi = [b, neg_lane(c, SMALLEST4[2]), neg_lane(c, SMALLEST4[3])];
                let up = each3(|a| negative[a] & group == 0);
                Frustum {
                    near_plane: each3(|a| if up[a] { a } else { 3 + a }),
                    far_plane: each3(|a| if up[a] { 3 + a } else { a }),
                    o_near: each3(|a| if up[a] { ohi[a] } else { olo[a] }),
                    o_far: each3(|a| if up[a] { olo[a] } else { ohi[a] }),
                    inv_lo,
                    inv_hi,
                }
            }

            /// Children of `b` that some lane may enter before `t_far` (the largest distance a lane
            /// still looks to), with the bound on their entry distances.
            #[target_feature(enable = $features)]
            #[inline]
            fn test(&self, b: &[[f32; WIDTH]; 6], t_far: f32) -> (u32, __m256) {
                let load = |r: &[f32; WIDTH]| {
                    // SAFETY: `r` holds 8 floats.
                    unsafe { _mm256_loadu_ps(r.as_ptr()) }
                };
                let mut near = _mm256_setzero_ps();
                let mut far = splat(t_far);
                for a in 0..3 {
                    let dn = sub(load(&b[self.near_plane[a]]), self.o_near[a]);
                    near = _mm256_max_ps(near, _mm256_min_ps(mul(dn, self.inv_lo[a]), mul(dn, self.inv_hi[a])));
                    let df = sub(load(&b[self.far_plane[a]]), self.o_far[a]);
                    far = _mm256_min_ps(far, _mm256_max_ps(mul(df, self.inv_lo[a]), mul(df, self.inv_hi[a])));
                }
                (_mm256_movemask_ps(may_hold(near, far)) as u32, near)
            }
        }

        /// The single-ray test of all 8 children of `b` ([`crate::bvh8`]'s AVX2 traversal's) for
        /// the lane `i` (in every lane of it): the children it enters.
        /// Always inlined (without AVX2 of its own, as [`smallest4`]): left to LLVM, the walk called it.
        #[inline(always)]
        fn one_lane(b: &[[f32; WIDTH]; 6], lane: &LaneSplat, f: &Frustum, t_best: __m256) -> u32 {
            // SAFETY: loads of 8 floats and register arithmetic under the caller's AVX2.
            unsafe {
                let (o, inv) = (&lane.o, &lane.inv);
                let (np, fp) = (&f.near_plane, &f.far_plane);
                let d0 = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(b[np[0]].as_ptr()), o[0]), inv[0]);
                let d1 = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(b[np[1]].as_ptr()), o[1]), inv[1]);
                let d2 = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(b[np[2]].as_ptr()), o[2]), inv[2]);
                let near = _mm256_max_ps(d2, _mm256_max_ps(d1, _mm256_max_ps(d0, _mm256_setzero_ps())));
                let e0 = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(b[fp[0]].as_ptr()), o[0]), inv[0]);
                let e1 = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(b[fp[1]].as_ptr()), o[1]), inv[1]);
                let e2 = _mm256_mul_ps(_mm256_sub_ps(_mm256_loadu_ps(b[fp[2]].as_ptr()), o[2]), inv[2]);
                let far = _mm256_min_ps(e2, _mm256_min_ps(e1, _mm256_min_ps(e0, t_best)));
                _mm256_movemask_ps(may_hold(near, far)) as u32
            }
        }

        /// One lane's origin and reciprocal direction in every lane, for [`one_lane`]: made again
        /// only where a node's first live lane is another than the last node's (rarely), not with 6
        /// lane permutations per node.
        struct LaneSplat {
            lane: u32,
            o: [__m256; 3],
            inv: [__m256; 3],
        }

        impl LaneSplat {
            /// Lane `lane` of `pk` (only packets whose lanes do not share an origin take it).
            #[target_feature(enable = $features)]
            #[inline]
            fn new(pk: &Packet, lane: u32) -> Self {
                let i = _mm256_set1_epi32(lane as i32);
                let at = |v: __m256| _mm256_permutevar8x32_ps(v, i);
                LaneSplat { lane, o: each3(|a| at(pk.o[a])), inv: each3(|a| at(pk.inv[a])) }
            }
        }

        /// What the walk of every group of lanes updates.
        struct State {
            best: Best,
            hit_any: __m256,
            alive: __m256,
            n_nodes: __m256i,
            n_tris: __m256i,
        }

        /// Lanes whose walk is finished one ray at a time, from `start` (the root or a subtree few
        /// lanes reach), on the wide BVH's single-ray traversal, each from its best hit so far.
        #[target_feature(enable = $features)]
        fn finish_alone<const ANY: bool, T: TriangleTest>(
            bvh: &Bvh8,
            rays: &Rays,
            start: u32,
            lanes: u32,
            st: &mut State,
            single: &mut Stack,
        ) {
            let load = |a: &[f32; LANES]| {
                // SAFETY: `a` holds 8 floats.
                unsafe { _mm256_loadu_ps(a.as_ptr()) }
            };
            let best = &st.best;
            let (mut t, mut tri) = (store(best.t), store_i(best.tri));
            let (mut w1, mut w2, mut sum, mut hit) = (store(best.w1), store(best.w2), store(best.sum), store(st.hit_any));
            let mut alive = store(st.alive);
            let (mut nodes, mut tris) = (store_i(st.n_nodes), store_i(st.n_tris));
            let mut m = lanes;
            while m != 0 {
                let i = m.trailing_zeros() as usize;
                m &= m - 1;
                let ray = rays.ray(i);
                let mut cost = Cost::default();
                let found = bvh.trace_from::<ANY, T>(
                    bvh.simd().max(Simd::Avx2),
                    start,
                    &ray,
                    0.0,
                    (t[i], tri[i] as u32),
                    single,
                    &mut cost,
                );
                nodes[i] += cost.nodes as i32;
                tris[i] += cost.tris as i32;
                if let Some(f) = found {
                    (t[i], tri[i], w1[i], w2[i], sum[i]) = (f.t, f.tri as i32, f.w1, f.w2, f.sum);
                    hit[i] = f32::from_bits(u32::MAX);
                    if ANY {
                        alive[i] = 0.0;
                    }
                }
            }
            st.best = Best {
                t: load(&t),
                // SAFETY: `tri` holds 8 ints.
                tri: unsafe { _mm256_loadu_si256(tri.as_ptr().cast()) },
                w1: load(&w1),
                w2: load(&w2),
                sum: load(&sum),
            };
            st.hit_any = load(&hit);
            st.alive = load(&alive);
            // SAFETY: `nodes` and `tris` hold 8 ints.
            (st.n_nodes, st.n_tris) =
                unsafe { (_mm256_loadu_si256(nodes.as_ptr().cast()), _mm256_loadu_si256(tris.as_ptr().cast())) };
        }

        /// Tests the triangles of `block` against the lanes in `lanes`, keeping their hits (and for
        /// `ANY` ending the lanes that found one); returns the lanes that found a hit. Its own
        /// function: inlined into [`walk`], LLVM kept the triangle test out of line instead.
        #[target_feature(enable = $features)]
        fn leaf<const ANY: bool, T: TriangleTest>(
            block: &TriBlock,
            pk: &Packet,
            shared: Option<[f32; 3]>,
            lanes: u32,
            st: &mut State,
        ) -> __m256 {
            // SAFETY: a load of 8 ints.
            let index = unsafe { _mm256_loadu_si256(block.index.as_ptr().cast()) };
            let full =
                !_mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(index, _mm256_set1_epi32(-1)))) as u32 & 0xff;
            // Shared-origin lanes keep the per-triangle test, whose scalar part is done once per
            // block (one lane at a time measured no faster for them). The others go one lane (or
            // lane group) at a time below 1.25 vector tests per triangle: the branch-free block test
            // beat the per-triangle one there (shadow rays on the VM: bunny +5%, dragon +12% against
            // "fewer lanes than triangles"; every lane alone, or below 0.5 or 0.625 per triangle,
            // measured slower; by instruction counts 0.5 to 2 and always are within 4% of 1.25).
            if shared.is_none() {
                let (n_lanes, n_tris) = (lanes.count_ones(), full.count_ones());
                if T::KIND == Intersect::Watertight {
                    // Vector tests of the block: lanes per test by the lanes the triangles fill.
                    let slot = if full < 1 << 2 {
                        2
                    } else if full < 1 << 4 {
                        4
                    } else {
                        8
                    };
                    if n_lanes.div_ceil(WIDTH as u32 / slot) * 4 < n_tris * 5 {
                        return match slot {
                            2 => leaf_grouped::<ANY, 2>(block, full, pk, lanes, st),
                            4 => leaf_grouped::<ANY, 4>(block, full, pk, lanes, st),
                            _ => leaf_grouped::<ANY, 8>(block, full, pk, lanes, st),
                        };
                    }
                } else if n_lanes * 4 < n_tris * 5 {
                    return leaf_by_lane::<ANY, T>(block, full, pk, lanes, st);
                }
            }
            let mut mv = mask_of(lanes);
            let mut won = _mm256_setzero_ps();
            // What every lane's test of a triangle shares, for the whole block at once. The normals
            // only where they are read: filled with zeros for nothing, in every leaf of a primary
            // packet, they were stored by 512-bit moves (see `avx512` below).
            let (pre, n) = match (T::KIND, shared) {
                (Intersect::Watertight, Some(o)) => (Some(shared_origin(block, o)), None),
                (Intersect::Watertight, None) => (None, Some({ let n = normals(block); each3(|a| store(n[a])) })),
                _ => (None, None),
            };
            if !ANY {
                // Every lane of `lanes` tests every triangle of the block.
                st.n_tris = _mm256_add_epi32(
                    st.n_tris,
                    _mm256_and_si256(_mm256_castps_si256(mv), _mm256_set1_epi32(full.count_ones() as i32)),
                );
            }
            let mut left = full;
            while left != 0 {
                let l = left.trailing_zeros() as usize;
                left &= left - 1;
                let i = block.index[l];
                if ANY {
                    st.n_tris = count(st.n_tris, mv);
                }
                let win = match (&pre, &n) {
                    (Some(s), _) => match intersect_shared_origin(s, l, &pk.d, mv, st.best.t) {
                        Some(found) => keep(found, i, mv, &mut st.best),
                        None => continue,
                    },
                    (None, Some(n)) => {
                        let v = |k: usize| [splat(block.p[k][0][l]), splat(block.p[k][1][l]), splat(block.p[k][2][l])];
                        let n = [splat(n[0][l]), splat(n[1][l]), splat(n[2][l])];
                        match watertight_in(&[v(0), v(1), v(2)], &n, &pk.o, &pk.d, _mm256_movemask_ps(mv) as u32, st.best.t)
                        {
                            Some((hit, [t, w1, w2, sum])) => keep([mask_of(hit), t, w1, w2, sum], i, mv, &mut st.best),
                            None => continue,
                        }
                    }
                    (None, None) => test::<T>(&block.triangle(l), i, pk, mv, &mut st.best),
                };
                won = _mm256_or_ps(won, win);
                if ANY {
                    st.alive = _mm256_andnot_ps(win, st.alive);
                    mv = _mm256_and_ps(mv, st.alive);
                    if !any(mv) {
                        break;
                    }
                }
            }
            st.hit_any = _mm256_or_ps(st.hit_any, won);
            won
        }

        /// [`leaf`] one lane at a time, each against all of the block's triangles (`full`, bits) at
        /// once, as the single-ray traversal tests a block: cheaper than one test per triangle where
        /// fewer than 1.25 times as many lanes as triangles reach the block. Möller-Trumbore only
        /// ([`leaf_grouped`] takes the edge-consistent test).
        #[target_feature(enable = $features)]
        fn leaf_by_lane<const ANY: bool, T: TriangleTest>(
            block: &TriBlock,
            full: u32,
            pk: &Packet,
            lanes: u32,
            st: &mut State,
        ) -> __m256 {
            let mut won = 0u32;
            let mut m = lanes;
            let n = _mm256_set1_epi32(full.count_ones() as i32);
            let (t_best, tri_best) = (store(st.best.t), store_i(st.best.tri));
            while m != 0 {
                let lane = m.trailing_zeros();
                m &= m - 1;
                let i = _mm256_set1_epi32(lane as i32);
                let at = |v: __m256| _mm256_permutevar8x32_ps(v, i);
                let r = Lanes { o: each3(|a| at(pk.o[a])), d: each3(|a| at(pk.d[a])), inv: each3(|a| at(pk.inv[a])) };
                let l = lane as usize;
                let [hit, t, w1, w2, sum] = match T::KIND {
                    Intersect::Watertight => watertight(block, &r, _mm256_setzero_ps(), splat(t_best[l])),
                    Intersect::MollerTrumbore => moller_trumbore(block, &r, _mm256_setzero_ps(), splat(t_best[l])),
                };
                let hit = _mm256_movemask_ps(hit) as u32 & full;
                if hit == 0 {
                    continue;
                }
                let ts = store(t);
                if let Some(k) = block_best::<ANY>(hit, |k| ts[k], &block.index, t_best[l], tri_best[l] as u32) {
                    won |= 1 << lane;
                    keep_lane(&mut st.best, lane, k, [t, w1, w2, sum], block.index[k]);
                }
            }
            settle::<ANY>(st, lanes, n, won)
        }

        /// Of the block's hits `hit` (bits of its triangles, distances `t(k)`), the one that beats the
        /// lane's best (`t_best`, `tri_best`): the nearest, ties to the lower index; with `ANY` the
        /// first that beats it.
        #[inline(always)]
        fn block_best<const ANY: bool>(
            mut hit: u32,
            t: impl Fn(usize) -> f32,
            index: &[u32; WIDTH],
            mut t_best: f32,
            mut tri_best: u32,
        ) -> Option<usize> {
            let mut k_best = None;
            while hit != 0 {
                let k = hit.trailing_zeros() as usize;
                hit &= hit - 1;
                if Hit::beats(t(k), index[k], t_best, tri_best) {
                    (t_best, tri_best) = (t(k), index[k]);
                    k_best = Some(k);
                    if ANY {
                        break;
                    }
                }
            }
            k_best
        }

        /// Packet lane `lane`'s best hit becomes vector lane `from` of the test's (t, w1, w2, sum),
        /// on triangle `tri`.
        #[target_feature(enable = $features)]
        #[inline]
        fn keep_lane(b: &mut Best, lane: u32, from: usize, [t, w1, w2, sum]: [__m256; 4], tri: u32) {
            let into = mask_of(1 << lane);
            let from = _mm256_set1_epi32(from as i32);
            let pick = |v: __m256| _mm256_permutevar8x32_ps(v, from);
            b.t = _mm256_blendv_ps(b.t, pick(t), into);
            b.w1 = _mm256_blendv_ps(b.w1, pick(w1), into);
            b.w2 = _mm256_blendv_ps(b.w2, pick(w2), into);
            b.sum = _mm256_blendv_ps(b.sum, pick(sum), into);
            b.tri = _mm256_castps_si256(_mm256_blendv_ps(
                _mm256_castsi256_ps(b.tri),
                _mm256_castsi256_ps(_mm256_set1_epi32(tri as i32)),
                into,
            ));
        }

        /// A block test's bookkeeping: `n` triangles counted for each lane of `lanes`, the lanes that
        /// `won` (bits) marked as hit and, for any hit, ended. Returns `won` as a mask.
        #[target_feature(enable = $features)]
        #[inline]
        fn settle<const ANY: bool>(st: &mut State, lanes: u32, n: __m256i, won: u32) -> __m256 {
            st.n_tris = _mm256_add_epi32(st.n_tris, _mm256_and_si256(_mm256_castps_si256(mask_of(lanes)), n));
            let won = mask_of(won);
            if ANY {
                st.alive = _mm256_andnot_ps(won, st.alive);
            }
            st.hit_any = _mm256_or_ps(st.hit_any, won);
            won
        }

        /// [`crate::geometry::intersect`] on 8 (ray, triangle) pairs, lane by lane its operations in
        /// its order (as `bvh8::avx2::watertight`): vertices `p[vertex][axis]`, the rays' origins `o`
        /// and directions `d`, each lane one pair. Returns the lanes of `live` (bits) that hit in
        /// `(0, t_max]` with (t, w1, w2, sum), or `None`, before the plane's distance, where no lane
        /// of `live` is inside the triangle's edges (most pairs), or, before the division, where none
        /// has the plane ahead.
        ///
        /// Inside is taken as `min(w) >= 0 || max(w) <= 0` (7 operations, not the scalar test's 11
        /// compares and logic): without a NaN the same, and a NaN edge function makes the sum NaN,
        /// which fails `sum != 0` in both forms, so the hits are the scalar test's bit for bit.
        /// Always inlined, without AVX2 of its own (as [`slab_signed`]).
        #[inline(always)]
        fn watertight_in(
            p: &[[__m256; 3]; 3],
            n: &[__m256; 3],
            o: &[__m256; 3],
            d: &[__m256; 3],
            live: u32,
            t_max: __m256,
        ) -> Option<(u32, [__m256; 4])> {
            // SAFETY: register arithmetic under the caller's AVX2.
            unsafe {
                let a0 = [sub(p[0][0], o[0]), sub(p[0][1], o[1]), sub(p[0][2], o[2])];
                let a1 = [sub(p[1][0], o[0]), sub(p[1][1], o[1]), sub(p[1][2], o[2])];
                let a2 = [sub(p[2][0], o[0]), sub(p[2][1], o[1]), sub(p[2][2], o[2])];
                let w2 = edge_function(&a0, &a1, d);
                let w0 = edge_function(&a1, &a2, d);
                let w1 = edge_function(&a2, &a0, d);
                let zero = _mm256_setzero_ps();
                let lo = _mm256_min_ps(_mm256_min_ps(w0, w1), w2);
                let hi = _mm256_max_ps(_mm256_max_ps(w0, w1), w2);
                let inside = _mm256_or_ps(_mm256_cmp_ps::<_CMP_GE_OQ>(lo, zero), _mm256_cmp_ps::<_CMP_LE_OQ>(hi, zero));
                if _mm256_movemask_ps(inside) as u32 & live == 0 {
                    return None;
                }
                let sum = add(add(w0, w1), w2);
                let (den, num) = (dot3(n, d), dot3(n, &a0));
                // `t = num / den` is above 0 only where num and den have one sign (a quotient's sign
                // is theirs, zeros and infinities included): the pairs inside the edges of a
                // triangle behind the origin (a shadow ray's own surface) end here, before the
                // division.
                if _mm256_movemask_ps(_mm256_andnot_ps(_mm256_xor_ps(num, den), inside)) as u32 & live == 0 {
                    return None;
                }
                let t = _mm256_div_ps(num, den);
                let mut m = inside;
                m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_NEQ_OQ>(sum, zero));
                m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_NEQ_OQ>(den, zero));
                m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_GT_OQ>(t, zero));
                m = _mm256_and_ps(m, _mm256_cmp_ps::<_CMP_LE_OQ>(t, t_max));
                Some((_mm256_movemask_ps(m) as u32 & live, [t, w1, w2, sum]))
            }
        }

        /// Row `r` of a leaf block (8 triangles' coordinate) as `SLOT`-lane groups: the whole row
        /// (`SLOT` 8), or its first 4 or 2 lanes repeated in every group.
        #[inline(always)]
        fn row<const SLOT: usize>(r: &[f32; WIDTH]) -> __m256 {
            // SAFETY: reads of 8, 4 or 2 floats of `r`; AVX under the caller's AVX2.
            unsafe {
                match SLOT {
                    8 => _mm256_loadu_ps(r.as_ptr()),
                    4 => _mm256_broadcast_ps(&*r.as_ptr().cast::<__m128>()),
                    _ => _mm256_castpd_ps(_mm256_broadcast_sd(&*r.as_ptr().cast::<f64>())),
                }
            }
        }

        /// [`leaf`] for lanes without a shared origin with the edge-consistent test, one lane per
        /// group of `SLOT` vector lanes against the block's triangles (all in its first `SLOT` lanes):
        /// one lane at a time against the whole block where `SLOT` is 8, as the single-ray traversal
        /// tests a block, and 2 or 4 lanes at a time against a block of at most 4 or 2 triangles, so
        /// that no vector lane is spent on an empty slot of a small block. Per lane the same hit as
        /// [`leaf_by_lane`] (the nearest of the block, ties to the lower index; for `ANY` the first
        /// that beats the lane's best).
        #[target_feature(enable = $features)]
        fn leaf_grouped<const ANY: bool, const SLOT: usize>(
            block: &TriBlock,
            full: u32,
            pk: &Packet,
            lanes: u32,
            st: &mut State,
        ) -> __m256 {
            let per = WIDTH / SLOT;
            let mut won = 0u32;
            let mut m = lanes;
            let n = _mm256_set1_epi32(full.count_ones() as i32);
            let (t_best, tri_best) = (store(st.best.t), store_i(st.best.tri));
            let p = [
                [row::<SLOT>(&block.p[0][0]), row::<SLOT>(&block.p[0][1]), row::<SLOT>(&block.p[0][2])],
                [row::<SLOT>(&block.p[1][0]), row::<SLOT>(&block.p[1][1]), row::<SLOT>(&block.p[1][2])],
                [row::<SLOT>(&block.p[2][0]), row::<SLOT>(&block.p[2][1]), row::<SLOT>(&block.p[2][2])],
            ];
            // The plane normals, as geometry::plane_normal computes them.
            let e1 = [sub(p[1][0], p[0][0]), sub(p[1][1], p[0][1]), sub(p[1][2], p[0][2])];
            let e2 = [sub(p[2][0], p[0][0]), sub(p[2][1], p[0][1]), sub(p[2][2], p[0][2])];
            let normal = cross(&e1, &e2);
            // One byte of 1 per vector lane of a group.
            let ones = (u64::MAX / 255) >> (64 - 8 * SLOT);
            while m != 0 {
                // The group's lanes, the last repeated where fewer are left.
                let mut ids = [0u32; WIDTH];
                let (mut bytes, mut live) = (0u64, 0u32);
                let mut g = 0;
                while g < per && m != 0 {
                    let lane = m.trailing_zeros();
                    m &= m - 1;
                    ids[g] = lane;
                    bytes |= (u64::from(lane) * ones) << (8 * SLOT * g);
                    live |= full << (SLOT * g);
                    g += 1;
                }
                let i = if SLOT == WIDTH {
                    _mm256_set1_epi32(ids[0] as i32)
                } else {
                    _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(bytes as i64))
                };
                let at = |v: __m256| _mm256_permutevar8x32_ps(v, i);
                let (o, d) = ([at(pk.o[0]), at(pk.o[1]), at(pk.o[2])], [at(pk.d[0]), at(pk.d[1]), at(pk.d[2])]);
                let Some((hit, [t, w1, w2, sum])) = watertight_in(&p, &normal, &o, &d, live, at(st.best.t)) else {
                    continue;
                };
                if hit == 0 {
                    continue;
                }
                let ts = store(t);
                for (j, &lane) in ids[..g].iter().enumerate() {
                    let l = lane as usize;
                    let h = hit >> (SLOT * j) & ((1 << SLOT) - 1);
                    if let Some(k) = block_best::<ANY>(h, |k| ts[SLOT * j + k], &block.index, t_best[l], tri_best[l] as u32)
                    {
                        won |= 1 << lane;
                        keep_lane(&mut st.best, lane, SLOT * j + k, [t, w1, w2, sum], block.index[k]);
                    }
                }
            }
            settle::<ANY>(st, lanes, n, won)
        }

        /// The walk of the lanes in `group` (finite inverse directions with one sign per axis):
        /// Embree's coherent packet traversal. At a node all 8 children are tested at once against
        /// the group's frustum and, unless the lanes share an origin, against its first live lane; an
        /// inner child the frustum lets through (shared origin) or the first lane enters takes all the
        /// node's lanes along (a superset of those that enter it: every lane is still tested exactly
        /// against the leaf blocks' boxes, and a lane that enters a box enters every box around it,
        /// so no triangle is tested by a lane the ordered traversal would not test it with), the
        /// others the lanes that enter them by the per-lane test.
        #[target_feature(enable = $features)]
        #[allow(clippy::too_many_arguments)]
        fn walk<const ANY: bool, T: TriangleTest>(
            bvh: &Bvh8,
            rays: &Rays,
            pk: &Packet,
            shared: Option<[f32; 3]>,
            group: u32,
            negative: &[u32; 3],
            st: &mut State,
            items: &mut Items<'_>,
            single: &mut Stack,
        ) {
            let f = Frustum::new(pk, shared, group, negative);
            let (np, fp) = (&f.near_plane, &f.far_plane);
            let group_v = mask_of(group);
            let mut t_far = largest(st.best.t, _mm256_and_ps(group_v, st.alive));
            let mut cur = bvh.root;
            let mut cur_mask = group & _mm256_movemask_ps(st.alive) as u32;
            // Made at the first node whose children the frustum lets through, and only for lanes
            // without a shared origin (shadow rays).
            let zero = _mm256_setzero_ps();
            let mut lane = LaneSplat { lane: u32::MAX, o: [zero; 3], inv: [zero; 3] };
            'walk: loop {
                if cur & LEAF == 0 {
                    if cur_mask.count_ones() <= SPARSE {
                        finish_alone::<ANY, T>(bvh, rays, cur, cur_mask, st, single);
                        if !ANY {
                            t_far = largest(st.best.t, _mm256_and_ps(group_v, st.alive));
                        }
                    } else {
                        let node = bvh.node(cur);
                        let b = &node.bounds;
                        let mv = mask_of(cur_mask);
                        st.n_nodes = _mm256_add_epi32(
                            st.n_nodes,
                            _mm256_and_si256(_mm256_castps_si256(mv), _mm256_set1_epi32(node.valid.count_ones() as i32)),
                        );
                        let (hit, near) = f.test(b, t_far);
                        let mut hit = hit & node.valid;
                        if hit != 0 {
                            // Inner children that take all the node's lanes along. A shared
                            // origin's frustum is tight enough to decide alone (the first lane's
                            // test cost primary packets 2-5% on the Xeon, stop 46); lanes from
                            // different points (shadow rays) need it: without it a loose frustum
                            // took them into every subtree it let through (dragon shadow packets
                            // ran at a tenth of their speed).
                            let first = if shared.is_some() {
                                u32::MAX
                            } else {
                                let l = cur_mask.trailing_zeros();
                                if l != lane.lane {
                                    lane = LaneSplat::new(pk, l);
                                }
                                let i = _mm256_set1_epi32(l as i32);
                                one_lane(b, &lane, &f, _mm256_permutevar8x32_ps(st.best.t, i))
                            };
                            let mut masks = [0u32; WIDTH];
                            let mut m = hit;
                            while m != 0 {
                                let slot = m.trailing_zeros() as usize;
                                m &= m - 1;
                                // The children some lane may enter start loading now, together.
                                prefetch(bvh, node.child[slot]);
                                if first >> slot & 1 != 0 && node.child[slot] & LEAF == 0 {
                                    masks[slot] = cur_mask;
                                    continue;
                                }
                                let (lanes, _) = match shared {
                                    Some(o) => slab_shared_origin(b, slot, o, pk, np, fp, st.best.t),
                                    None => slab_signed(b, slot, pk, np, fp, st.best.t),
                                };
                                let lanes = _mm256_movemask_ps(_mm256_and_ps(lanes, mv)) as u32;
                                masks[slot] = lanes;
                                if lanes == 0 {
                                    hit &= !(1 << slot);
                                }
                            }
                            if hit != 0 {
                                let near = store(near);
                                let first = hit.trailing_zeros() as usize;
                                let mut rest = hit & (hit - 1);
                                if rest == 0 {
                                    (cur, cur_mask) = (node.child[first], masks[first]);
                                    continue 'walk;
                                }
                                if ANY {
                                    // Any hit: the last child first, the others popped last to
                                    // first, as Embree's any-hit walk takes them (measured: 2.7%
                                    // fewer instructions per bunny shadow packet than first to
                                    // last, 1.3% on the dragon's primary and shadow packets
                                    // together; nearest first cost 1.3% more).
                                    let last = (31 - hit.leading_zeros()) as usize;
                                    let mut rest = hit & !(1 << last);
                                    while rest != 0 {
                                        let slot = rest.trailing_zeros() as usize;
                                        rest &= rest - 1;
                                        items.push(Item { node: node.child[slot], mask: masks[slot], near: near[slot] });
                                    }
                                    (cur, cur_mask) = (node.child[last], masks[last]);
                                    continue 'walk;
                                }
                                // Nearest first: the others go on the stack farthest first. Sorted
                                // as one integer each: the entry distance's bits (not negative, and
                                // -0 taken as +0, so they order as the distances do), then the lower
                                // slot first among equal distances; 8 bytes, not a 16-byte pair the
                                // compiler zeroed field by field per node.
                                let key =
                                    |slot: usize| (u64::from(near[slot].to_bits() & 0x7fff_ffff) << 3) | (7 - slot as u64);
                                let mut order = [0u64; WIDTH];
                                order[0] = key(first);
                                let mut n = 1;
                                while rest != 0 {
                                    let slot = rest.trailing_zeros() as usize;
                                    rest &= rest - 1;
                                    let e = key(slot);
                                    let mut k = n;
                                    while k > 0 && order[k - 1] < e {
                                        order[k] = order[k - 1];
                                        k -= 1;
                                    }
                                    order[k] = e;
                                    n += 1;
                                }
                                for &e in &order[..n - 1] {
                                    let slot = 7 - (e & 7) as usize;
                                    items.push(Item { node: node.child[slot], mask: masks[slot], near: near[slot] });
                                }
                                let slot = 7 - (order[n - 1] & 7) as usize;
                                (cur, cur_mask) = (node.child[slot], masks[slot]);
                                continue 'walk;
                            }
                        }
                    }
                } else {
                    let won = leaf::<ANY, T>(bvh.block(cur), pk, shared, cur_mask, st);
                    if !ANY && any(won) {
                        t_far = largest(st.best.t, _mm256_and_ps(group_v, st.alive));
                    }
                }
                let alive = _mm256_movemask_ps(st.alive) as u32;
                // A shadow packet whose lanes are all blocked ends here, not after popping every
                // deferred subtree.
                if ANY && alive & group == 0 {
                    items.clear();
                    return;
                }
                loop {
                    let Some(e) = items.pop() else { return };
                    let m = e.mask & alive;
                    if m != 0 && geometry::may_hold(e.near, t_far) {
                        (cur, cur_mask) = (e.node, m);
                        break;
                    }
                }
            }
        }

        #[target_feature(enable = $features)]
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
            let (pk, alive) = packet_of(rays);
            // Zero as a value LLVM cannot see: as a constant, the stores of two neighbouring zero
            // fields were merged into one 512-bit store (see `avx512` below).
            let zero = std::hint::black_box(_mm256_setzero_ps());
            let mut st = State {
                best: Best { t: load(&rays.t_max), tri: _mm256_set1_epi32(-1), w1: zero, w2: zero, sum: splat(1.0) },
                hit_any: zero,
                alive,
                n_nodes: _mm256_castps_si256(zero),
                n_tris: _mm256_castps_si256(zero),
            };
            let valid = _mm256_movemask_ps(alive) as u32;
            // The origin, where every valid lane starts at the same point (primary rays).
            let first = _mm256_set1_epi32(valid.trailing_zeros() as i32 & 7);
            let same = (0..3).fold(valid, |m, a| {
                let o = _mm256_castps_si256(pk.o[a]);
                let o0 = _mm256_permutevar8x32_epi32(o, first);
                m & _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_cmpeq_epi32(o, o0))) as u32
            });
            let shared =
                (same == valid).then(|| each3(|a| _mm256_cvtss_f32(_mm256_permutevar8x32_ps(pk.o[a], first))));
            // Lanes with an infinite reciprocal (a direction along a coordinate plane) go alone; the
            // others walk in groups of one octant, as Embree splits its packets.
            let abs = |v: __m256| _mm256_andnot_ps(splat(-0.0), v);
            let infinite = (0..3).fold(0, |m, a| {
                m | _mm256_movemask_ps(_mm256_cmp_ps::<_CMP_EQ_OQ>(abs(pk.inv[a]), splat(f32::INFINITY))) as u32
            }) & valid;
            let negative = each3(|a| _mm256_movemask_ps(pk.inv[a]) as u32);
            // Left uninitialised: only what `push` writes is read.
            let mut inline = std::mem::MaybeUninit::<[std::mem::MaybeUninit<Item>; INLINE]>::uninit();
            // SAFETY: an array of `MaybeUninit` needs no initialisation.
            let mut items = Items::new(unsafe { inline.assume_init_mut() }, stack);
            let mut left = valid & !infinite;
            while left != 0 {
                let i = left.trailing_zeros();
                let same = (0..3).fold(left, |m, a| m & !(negative[a] ^ (0u32.wrapping_sub(negative[a] >> i & 1))));
                left &= !same;
                walk::<ANY, T>(bvh, rays, &pk, shared, same, &negative, &mut st, &mut items, single);
            }
            if infinite != 0 {
                finish_alone::<ANY, T>(bvh, rays, bvh.root, infinite, &mut st, single);
            }

            let tri = store_i(st.best.tri);
            let inv = _mm256_div_ps(splat(1.0), st.best.sum);
            let (u, v) = (_mm256_mul_ps(st.best.w1, inv), _mm256_mul_ps(st.best.w2, inv));
            let hit = crate::wide::bools_of(st.hit_any);
            let mut out = Results { hit, t: store(st.best.t), u: store(u), v: store(v), ..Results::default() };
            // A loop, not `array::from_fn`: core's helper behind it may be put into another
            // codegen unit, out of the walk's inlining (see `bvh8::each3`).
            for i in 0..LANES {
                out.tri[i] = tri[i] as u32;
            }
            // The work counts as `Cost` pairs, lanes 0-3 and 4-7 in one 256-bit store each: left
            // to LLVM, the pairs were interleaved and stored in 512 bits (see `avx512` below).
            let (lo, hi) = (_mm256_unpacklo_epi32(st.n_nodes, st.n_tris), _mm256_unpackhi_epi32(st.n_nodes, st.n_tris));
            let cost = out.cost.as_mut_ptr().cast::<__m256i>();
            // SAFETY: `Cost` is two `u32`s in that order (`repr(C)`), so `out.cost` is 16 of them,
            // room for two unaligned 256-bit stores (its size is asserted at the top of the file).
            unsafe {
                _mm256_storeu_si256(cost, _mm256_permute2x128_si256::<0x20>(lo, hi));
                _mm256_storeu_si256(cost.add(1), _mm256_permute2x128_si256::<0x31>(lo, hi));
            }
            out
        }
        }
    };
}

#[cfg(target_arch = "x86_64")]
packet_walk_compiled_for!(
    /// Compiled for AVX2 and POPCNT (which `available` requires): AVX2 alone does not imply
    /// POPCNT, and every `count_ones` of the walk and the leaves was then a 15-instruction bit
    /// trick.
    avx2,
    "avx2,popcnt"
);

#[cfg(target_arch = "x86_64")]
packet_walk_compiled_for!(
    /// [`avx2`] compiled for AVX-512 (F, VL, DQ, BW) as well: the same 256-bit operations in the
    /// same order, so the same hits, with 32 vector registers and mask-register compares (as
    /// `bvh8::avx2::trace_evex` for single rays). No 512-bit register: where a function zeroes or
    /// copies 64 bytes or more, LLVM uses one for it here (the leaf's unused normals, the state's
    /// neighbouring zero fields, the work counts' pairs), and without those the 16-thread primary
    /// packets ran 1-4 points faster against Embree on the Xeon (docs/cpu-benchmark-log.md, stop
    /// 56). `.ci/run` checks the walks' disassembly for them.
    avx512,
    "avx2,popcnt,avx512f,avx512vl,avx512dq,avx512bw"
);
