//! Rays, the slab test, the edge-consistent and Möller-Trumbore triangle tests and the origin
//! offsets, in f32: the arithmetic every fast path shares.

use bvh_format::{Node, Triangle};
use glam::Vec3;
use render_spec::constants::{OFFSET_FLOAT_SCALE, OFFSET_INT_SCALE, OFFSET_ORIGIN, T_SLACK};
use render_spec::{Intersect, Offset};

/// A ray with its precomputed inverse direction (components may be infinite).
#[derive(Clone, Copy, Debug)]
pub struct Ray {
    pub origin: Vec3,
    pub dir: Vec3,
    pub inv_dir: Vec3,
}

impl Ray {
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self { origin, dir, inv_dir: dir.recip() }
    }
}

/// A ray-triangle hit. `tri` is the triangle's index in the file's (leaf) order; `u` and `v` are
/// the barycentric weights of vertices 1 and 2.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub tri: u32,
    pub u: f32,
    pub v: f32,
}

impl Hit {
    /// Ordering of candidate hits: nearer wins; at exactly equal distance the lower triangle index
    /// wins, so that every traversal order picks the same triangle.
    #[inline(always)]
    pub fn beats(t: f32, tri: u32, best_t: f32, best_tri: u32) -> bool {
        t < best_t || (t == best_t && tri < best_tri)
    }
}

/// Work done for one ray, the traversal-cost AOV: node boxes tested and triangles tested.
/// `repr(C)`: the wide packets store lanes of them as pairs of `u32` (`packet8`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[repr(C)]
pub struct Cost {
    pub nodes: u32,
    pub tris: u32,
}

impl std::ops::AddAssign for Cost {
    fn add_assign(&mut self, o: Cost) {
        self.nodes += o.nodes;
        self.tris += o.tris;
    }
}

/// Whether a box entered at `near` may still hold a hit at `t` or nearer ([`T_SLACK`] says why
/// with a slack).
#[inline(always)]
pub fn may_hold(near: f32, t: f32) -> bool {
    near <= t + t.abs() * T_SLACK
}

/// Entry distance of the ray into the node's box if it enters within `[0, t_max]` (with
/// [`T_SLACK`]).
///
/// A zero direction component has an infinite inverse, and an origin exactly on that slab's plane
/// makes `0 * inf = NaN`, in the entry or the exit distance depending on the sign of the zero.
/// Such an axis is left out of the interval altogether: the ray lies in the face's plane, inside
/// the slab's closed range, so it counts as inside. That errs towards a hit, which costs a little
/// work and never a missed triangle. The SIMD path and the GPU kernels make the same comparisons
/// in the same order.
#[inline(always)]
pub fn slab(node: &Node, ray: &Ray, t_max: f32) -> Option<f32> {
    let (near, far) = slab_range(node, ray, t_max);
    may_hold(near, far).then_some(near)
}

/// The entry and exit distances [`slab`] compares: the interval of `[0, t_max]` inside the box,
/// empty where `near > far`, before the slack.
#[inline(always)]
pub fn slab_range(node: &Node, ray: &Ray, t_max: f32) -> (f32, f32) {
    let lo = (Vec3::from(node.min) - ray.origin) * ray.inv_dir;
    let hi = (Vec3::from(node.max) - ray.origin) * ray.inv_dir;
    let mut near = 0.0f32;
    let mut far = t_max;
    for a in 0..3 {
        let (t0, t1) = (lo[a], hi[a]);
        if t0.is_nan() || t1.is_nan() {
            continue;
        }
        let enter = if t1 < t0 { t1 } else { t0 };
        let exit = if t0 > t1 { t0 } else { t1 };
        near = if enter > near { enter } else { near };
        far = if exit < far { exit } else { far };
    }
    (near, far)
}

/// The wide traversals' form of [`may_hold`] on a box's exit distance (`bvh8`: one multiply
/// instead of a multiply and an add on the path from a node's boxes to the next node's address;
/// on the exit planes the walk folds even that multiply into the inverse, [`exit_bound`]).
/// It accepts every box [`may_hold`] accepts, so that they find every hit the binary traversals
/// find: for `far` of 0 or more, the exact `far * (1 + 2 T_SLACK)` is at least the exact
/// `far + round(far * T_SLACK)` (the product's rounding error is at most the product, subnormals
/// included), `1 + 2 T_SLACK` is a float, and rounding to nearest is monotonic; a negative or
/// negative-zero `far` gives the same answer in both forms, since `near` is never below 0. A box
/// is entered where `near` lies within a rounding above `may_hold`'s bound: extra work, no other
/// hit.
#[inline(always)]
pub fn may_hold_wide(near: f32, far: f32) -> bool {
    near <= far * EXIT_SCALE
}

/// `1 + 2 T_SLACK`, exactly ([`may_hold_wide`]).
pub const EXIT_SCALE: f32 = 1.0 + 2.0 * T_SLACK;

/// The single-ray wide walks' exit test on one axis for any-hit rays (`bvh8`): whether a box
/// entered at `near` may hold a hit before the ray leaves the slab whose far plane is `plane`,
/// given `inv_far =` [`inv_far`]`(inverse direction)`. One multiply-add from the plane to the
/// compared number, where [`may_hold_wide`] on the exit distance takes a subtract and two
/// multiplies, a multiply's latency less on the walk's critical path: on the H100 host's Xeon 1-4
/// points more shadow and AO rays per second. Closest-hit rays keep `may_hold_wide`: there it
/// gained nothing on the Xeon and cost 3-11 points on the 2-core VM's Zen 4, in three pairs of
/// builds (docs/cpu-benchmark-log.md, "the exit scale folded into the inverse"); on two Xeons
/// again in stop 55, within a point or two, as much as the untouched any-hit rays moved ("the
/// folded exit for closest-hit rays too").
///
/// It accepts whatever [`may_hold_wide`]`(near, exit)` accepts for the exit distance
/// `exit = (plane - origin) * inv`, so that the walk still finds every hit the binary traversals
/// find (it may enter a box more, never fewer). With `x = plane - origin` (the same float in both),
/// `y = x * inv` exact and `u = 2^-24`, for an inverse direction whose components are 0, infinite
/// or at least `2^-126` in magnitude (every direction component below `2^126`):
/// - `may_hold_wide` compares with `round(round(y) * EXIT_SCALE)`, at most
///   `y * EXIT_SCALE * (1 + u)^2 + 2^-149` (relative rounding, or half a subnormal step);
/// - this compares with `round(x * round(inv * K) + 2^-126)` (`K` = [`EXIT_SCALE_FOLDED`], one
///   rounding of the fused multiply-add), at least `round(y * K * (1 - u) + 2^-126)` for `y > 0`;
///   `K * (1 - u) >= EXIT_SCALE * (1 + u)^2` (`K` is `EXIT_SCALE` plus 4 ulps of 1, 8u) and
///   `2^-126` covers the subnormal term, so by monotonic rounding it is never the smaller;
/// - for `y <= 0` `may_hold_wide` accepts only `near = 0`, and only where `round(y)` is a zero
///   (`|y|` at most `2^-150`); there `x * round(inv * K)` is below `2^-148` in magnitude and the
///   `2^-126` makes this number positive;
/// - a NaN (`0 * inf`: the origin on the plane of an axis the ray is parallel to) passes in both
///   (`!(near > NaN)`); an infinite `inv_far` from a finite `inv` gives `+inf` or NaN where the
///   other's number is positive or zero, `-inf` only where it is negative.
///
/// `geometry::tests::the_folded_exit_test_accepts_what_may_hold_wide_accepts` checks it on
/// ordinary, extreme and special numbers.
#[inline(always)]
pub fn exit_bound(plane: f32, origin: f32, inv_far: f32) -> f32 {
    (plane - origin).mul_add(inv_far, f32::MIN_POSITIVE)
}

/// Whether `near` passes [`exit_bound`]: not above it, a NaN bound passing (the axis left out).
#[inline(always)]
pub fn before_exit(near: f32, plane: f32, origin: f32, inv_far: f32) -> bool {
    // Not `<=`: a NaN bound must pass.
    exit_bound(plane, origin, inv_far).partial_cmp(&near) != Some(std::cmp::Ordering::Less)
}

/// The inverse direction component [`exit_bound`] multiplies by: `inv` scaled by
/// [`EXIT_SCALE_FOLDED`].
#[inline(always)]
pub fn inv_far(inv: f32) -> f32 {
    inv * EXIT_SCALE_FOLDED
}

/// [`EXIT_SCALE`] plus 4 ulps of 1 (`2^-21`): the rounding of `inv * K` and of the multiply-add
/// in [`exit_bound`] kept on the accepting side of [`may_hold_wide`]'s two roundings.
pub const EXIT_SCALE_FOLDED: f32 = EXIT_SCALE + 4.0 * f32::EPSILON;

/// The edge function of the edge from `a` to `b` (vertices relative to the ray origin) for the
/// direction `d`: `dot(cross(a - b, a + b), d)`, which is twice `dot(cross(a, b), d)`, the signed
/// volume that says on which side of the edge the ray passes.
///
/// The triangle on the other side of the edge meets it as `(b, a)`: `a - b` then changes sign
/// exactly and `a + b` not at all, so that triangle computes exactly the negated number, and a ray
/// can never be outside both. That holds also where a GPU compiler contracts multiply-adds, since
/// `fma(-x, y, -z) = -fma(x, y, z)`; a plain `cross(a, b)` would lose it there (`a.y * b.z` kept
/// exact on one side of the edge is `b.z * a.y` rounded on the other). The packet path and the
/// kernels (`common.wgsl`) make exactly these operations in this order.
#[inline(always)]
pub fn edge_function(a: [f32; 3], b: [f32; 3], d: Vec3) -> f32 {
    let e = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    let s = [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
    let c = [e[1] * s[2] - e[2] * s[1], e[2] * s[0] - e[0] * s[2], e[0] * s[1] - e[1] * s[0]];
    d.x * c[0] + d.y * c[1] + d.z * c[2]
}

/// The edge-consistent triangle test (docs/shading.md): the distance and barycentrics of a hit in
/// `(t_min, t_max]` (closed above so that a hit at exactly the best distance so far can still win
/// a tie). The ray hits when the three [`edge_function`]s have one sign, zeros counting as inside
/// on both sides, so a ray through a shared edge hits both triangles and [`Hit::beats`] decides;
/// a ray parallel to the plane (`det == 0`) misses. `u` and `v`, the weights of vertices 1 and 2,
/// are their edge functions over the sum of all three.
#[inline(always)]
pub fn intersect(tri: &Triangle, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)> {
    let (o, d) = (ray.origin, ray.dir);
    let rel = |p: [f32; 3]| [p[0] - o.x, p[1] - o.y, p[2] - o.z];
    let (a0, a1, a2) = (rel(tri.p0), rel(tri.p1), rel(tri.p2));
    let w2 = edge_function(a0, a1, d);
    let w0 = edge_function(a1, a2, d);
    let w1 = edge_function(a2, a0, d);
    let inside = (w0 >= 0.0 && w1 >= 0.0 && w2 >= 0.0) || (w0 <= 0.0 && w1 <= 0.0 && w2 <= 0.0);
    let sum = w0 + w1 + w2;
    if !inside || sum == 0.0 {
        return None;
    }
    // The distance from the plane, not from the edge functions: their sum cancels for an origin
    // far from a small triangle.
    let n = plane_normal(tri);
    let den = n[0] * d.x + n[1] * d.y + n[2] * d.z;
    if den == 0.0 {
        return None;
    }
    let t = (n[0] * a0[0] + n[1] * a0[1] + n[2] * a0[2]) / den;
    if !(t > t_min && t <= t_max) {
        return None;
    }
    let inv = 1.0 / sum;
    Some((t, w1 * inv, w2 * inv))
}

/// The (unnormalised) normal of the triangle's plane that [`intersect`] measures distances with:
/// `cross(p1 - p0, p2 - p0)`, operation by operation. A triangle's alone: the wide BVH's leaf
/// test computes it in its lanes (`bvh8`), the packet path once per triangle, in this order.
#[inline(always)]
pub fn plane_normal(tri: &Triangle) -> [f32; 3] {
    let (p0, p1, p2) = (tri.p0, tri.p1, tri.p2);
    let e1 = [p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]];
    let e2 = [p2[0] - p0[0], p2[1] - p0[1], p2[2] - p0[2]];
    [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]]
}

/// Möller-Trumbore (thesis 4.2.4) on vertex 0 and the two edges from it, as every path tested
/// before format version 2, and `--intersect mt` now: each triangle decides a shared edge after
/// its own roundings, so a ray aimed exactly at the edge can pass between both (tests count
/// those leaks). Fewer operations than [`intersect`]. Same contract as [`intersect`]; the packet
/// path repeats its operations in the same order.
#[inline(always)]
pub fn intersect_moller_trumbore(tri: &Triangle, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)> {
    let (o, d) = (ray.origin, ray.dir);
    let v0 = tri.p0;
    let e1 = [tri.p1[0] - v0[0], tri.p1[1] - v0[1], tri.p1[2] - v0[2]];
    let e2 = [tri.p2[0] - v0[0], tri.p2[1] - v0[1], tri.p2[2] - v0[2]];
    let p = [d.y * e2[2] - e2[1] * d.z, d.z * e2[0] - e2[2] * d.x, d.x * e2[1] - e2[0] * d.y];
    let det = e1[0] * p[0] + e1[1] * p[1] + e1[2] * p[2];
    if det == 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let s = [o.x - v0[0], o.y - v0[1], o.z - v0[2]];
    let u = (s[0] * p[0] + s[1] * p[1] + s[2] * p[2]) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = [s[1] * e1[2] - e1[1] * s[2], s[2] * e1[0] - e1[2] * s[0], s[0] * e1[1] - e1[0] * s[1]];
    let v = (d.x * q[0] + d.y * q[1] + d.z * q[2]) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = (e2[0] * q[0] + e2[1] * q[1] + e2[2] * q[2]) * inv;
    (t > t_min && t <= t_max).then_some((t, u, v))
}

/// A triangle test as a type, so that a traversal is compiled for one test (chosen once per frame
/// or per call, never per triangle).
pub trait TriangleTest {
    /// The setting this test implements.
    const KIND: Intersect;
    fn intersect(tri: &Triangle, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)>;
}

/// [`intersect`], the default.
pub struct Watertight;
/// [`intersect_moller_trumbore`].
pub struct MollerTrumbore;

impl TriangleTest for Watertight {
    const KIND: Intersect = Intersect::Watertight;
    #[inline(always)]
    fn intersect(tri: &Triangle, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)> {
        intersect(tri, ray, t_min, t_max)
    }
}

impl TriangleTest for MollerTrumbore {
    const KIND: Intersect = Intersect::MollerTrumbore;
    #[inline(always)]
    fn intersect(tri: &Triangle, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, f32, f32)> {
        intersect_moller_trumbore(tri, ray, t_min, t_max)
    }
}

/// Moves a ray origin off the surface it lies on, along the geometric normal `n` (pointing to the
/// side the new ray leaves into), by a few units in the last place of the coordinates: scale-free,
/// so it works for the tiny Stanford models and for huge scenes alike. After Wächter and Binder,
/// "A Fast and Robust Method for Avoiding Self-Intersection" (Ray Tracing Gems, 2019).
#[inline]
pub fn offset_origin(p: Vec3, n: Vec3) -> Vec3 {
    let of_i = (n * OFFSET_INT_SCALE).as_ivec3();
    let step = |p: f32, o: i32| {
        let bits = p.to_bits() as i32;
        // Wrapping: the integer step is computed for every component, also for those near zero
        // (where `pick` then takes the float step instead), whose bits can sit at `i32::MIN`.
        f32::from_bits((if p < 0.0 { bits.wrapping_sub(o) } else { bits.wrapping_add(o) }) as u32)
    };
    let p_i = Vec3::new(step(p.x, of_i.x), step(p.y, of_i.y), step(p.z, of_i.z));
    let pick = |p: f32, n: f32, pi: f32| if p.abs() < OFFSET_ORIGIN { p + OFFSET_FLOAT_SCALE * n } else { pi };
    Vec3::new(pick(p.x, n.x, p_i.x), pick(p.y, n.y, p_i.y), pick(p.z, n.z, p_i.z))
}

/// Moves a ray origin by the distance `d` along the unit normal `n` (`--offset D`): `p + n * d`,
/// a multiply and an add per coordinate, each rounded (the kernels must not fuse them).
#[inline(always)]
pub fn offset_fixed(p: Vec3, n: Vec3, d: f32) -> Vec3 {
    p + n * d
}

/// The origin of a ray leaving the surface at `p` into the side the unit geometric normal `n`
/// points to, moved as the frame's [`Offset`] says.
#[inline]
pub fn leave(p: Vec3, n: Vec3, offset: Offset) -> Vec3 {
    match offset {
        Offset::ScaleAware => offset_origin(p, n),
        Offset::Fixed(d) => offset_fixed(p, n, d),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit_tri() -> Triangle {
        Triangle::from_vertices([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    }

    #[test]
    fn triangle_test_hits_inside_and_on_edges_and_misses_outside() {
        let t = unit_tri();
        let down = Vec3::new(0.0, 0.0, -1.0);
        let hit = intersect(&t, &Ray::new(Vec3::new(0.25, 0.25, 1.0), down), 0.0, f32::INFINITY).unwrap();
        assert_eq!(hit, (1.0, 0.25, 0.25));
        assert!(intersect(&t, &Ray::new(Vec3::new(0.5, 0.5, 1.0), down), 0.0, f32::INFINITY).is_some(), "hypotenuse");
        assert!(intersect(&t, &Ray::new(Vec3::new(0.0, 0.0, 1.0), down), 0.0, f32::INFINITY).is_some(), "vertex");
        assert!(intersect(&t, &Ray::new(Vec3::new(0.6, 0.6, 1.0), down), 0.0, f32::INFINITY).is_none());
        // Behind the origin, and beyond t_max.
        assert!(intersect(&t, &Ray::new(Vec3::new(0.2, 0.2, -1.0), down), 0.0, f32::INFINITY).is_none());
        assert!(intersect(&t, &Ray::new(Vec3::new(0.2, 0.2, 1.0), down), 0.0, 0.5).is_none());
        assert!(intersect(&t, &Ray::new(Vec3::new(0.2, 0.2, 1.0), down), 0.0, 1.0).is_some(), "t_max is inclusive");
        // Parallel to the plane, in it and above it.
        let side = Vec3::new(1.0, 0.0, 0.0);
        assert!(intersect(&t, &Ray::new(Vec3::new(-1.0, 0.2, 0.0), side), 0.0, f32::INFINITY).is_none());
        assert!(intersect(&t, &Ray::new(Vec3::new(-1.0, 0.2, 0.5), side), 0.0, f32::INFINITY).is_none());
        // Back faces are hit too.
        let up = Vec3::new(0.0, 0.0, 1.0);
        assert!(intersect(&t, &Ray::new(Vec3::new(0.2, 0.2, -1.0), up), 0.0, f32::INFINITY).is_some());
    }

    /// Deterministic test inputs in `[-1, 1)`.
    fn randoms(seed: u64) -> impl FnMut() -> f32 {
        let mut rng = ::tests::Rng(seed);
        move || rng.signed()
    }

    #[test]
    fn edge_function_is_antisymmetric_also_with_contracted_multiply_adds() {
        // A GPU compiler may contract `x * y - z * w` into `fma(x, y, -(z * w))` and a dot product
        // into a chain of fmas; emulated here with mul_add.
        fn dot_fma(d: Vec3, c: [f32; 3]) -> f32 {
            d.x.mul_add(c[0], d.y.mul_add(c[1], d.z * c[2]))
        }
        fn cross_fma(x: [f32; 3], y: [f32; 3]) -> [f32; 3] {
            [x[1].mul_add(y[2], -(x[2] * y[1])), x[2].mul_add(y[0], -(x[0] * y[2])), x[0].mul_add(y[1], -(x[1] * y[0]))]
        }
        let ours = |a: [f32; 3], b: [f32; 3], d: Vec3| {
            let e = [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
            let s = [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
            dot_fma(d, cross_fma(e, s))
        };
        let plain = |a: [f32; 3], b: [f32; 3], d: Vec3| dot_fma(d, cross_fma(a, b));
        let mut r = randoms(0x9e3779b97f4a7c15);
        let (mut ours_broken, mut plain_broken) = (0, 0);
        for _ in 0..100_000 {
            let scale = 10f32.powi((r() * 4.0) as i32);
            let mut p = || [r() * scale, r() * scale, r() * scale];
            let (a, b) = (p(), p());
            let d = Vec3::new(r(), r(), r());
            assert_eq!(edge_function(a, b, d).to_bits(), (-edge_function(b, a, d)).to_bits(), "{a:?} {b:?} {d}");
            ours_broken += usize::from(ours(a, b, d).to_bits() != (-ours(b, a, d)).to_bits());
            plain_broken += usize::from(plain(a, b, d).to_bits() != (-plain(b, a, d)).to_bits());
        }
        assert_eq!(ours_broken, 0, "contracted edge functions lost their antisymmetry");
        // The check can fail: the plain cross product loses it under contraction.
        assert!(plain_broken > 1000, "only {plain_broken} plain cross products broke");
    }

    /// The sum-and-difference form is the accurate one where a short edge is seen from afar (a
    /// mesh's edges, from the camera): `a - b` is the short edge vector, nearly exact, where the
    /// plain `cross(a, b)` of two long, nearly parallel vectors cancels. Relative errors against
    /// f64 on the same f32 inputs; the plain form was tried for speed (docs/cpu-benchmark-log.md,
    /// stop 33).
    #[test]
    fn edge_function_is_more_accurate_than_the_plain_cross_product_at_distant_edges() {
        let plain = |a: [f32; 3], b: [f32; 3], d: Vec3| {
            let c = [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
            d.x * c[0] + d.y * c[1] + d.z * c[2]
        };
        let exact = |a: [f32; 3], b: [f32; 3], d: Vec3| {
            let (a, b, d) = (Vec3::from(a).as_dvec3(), Vec3::from(b).as_dvec3(), d.as_dvec3());
            d.dot(a.cross(b))
        };
        let mut rng = ::tests::Rng(0x5eed_ed9e);
        for distance in [0.2f32, 10.0, 1000.0] {
            let (mut ours_err, mut plain_err) = (Vec::new(), Vec::new());
            for _ in 0..20_000 {
                // An edge 1/200 of its distance long, the ray aimed near it.
                let mid = Vec3::from(rng.direction()) * distance;
                let half = Vec3::from(rng.signed3()) * distance * 0.0025;
                let (a, b) = ((mid + half).to_array(), (mid - half).to_array());
                let d = (mid + Vec3::from(rng.signed3()) * distance * 0.001).normalize();
                let e = exact(a, b, d);
                if e == 0.0 {
                    continue;
                }
                // Ours is twice the edge function.
                ours_err.push(((edge_function(a, b, d) as f64 * 0.5 - e) / e).abs());
                plain_err.push(((plain(a, b, d) as f64 - e) / e).abs());
            }
            let median = |v: &mut Vec<f64>| {
                v.sort_by(f64::total_cmp);
                v[v.len() / 2]
            };
            let (ours, plain) = (median(&mut ours_err), median(&mut plain_err));
            println!(
                "edge {distance} away: median relative error {ours:.2e} (ours), {plain:.2e} (plain cross product)"
            );
            assert!(
                ours * 10.0 < plain,
                "at {distance}: median relative error {ours:e} (ours) against {plain:e} (plain)"
            );
        }
    }

    /// Every exit distance's largest accepted entry under [`may_hold`] is accepted by
    /// [`may_hold_wide`] too: exit distances over the whole float range (every 509th bit pattern
    /// of the positive floats, subnormals, zeros and infinity included, and their negations).
    #[test]
    fn the_wide_box_test_accepts_every_box_the_scalar_test_accepts() {
        let mut fars: Vec<f32> = (0..0x7f80_0000u32).step_by(509).map(f32::from_bits).collect();
        fars.extend([0.0, -0.0, f32::MIN_POSITIVE, f32::MAX, f32::INFINITY, 1.0, 3.0e-41]);
        let negated: Vec<f32> = fars.iter().map(|f| -f).collect();
        fars.extend(negated);
        let mut checked = 0;
        for far in fars {
            // `near` is 0 or more in both traversals: the largest `may_hold` accepts, if any (none
            // for a negative `far`, whose bound is negative or, for -inf, NaN).
            let bound = far + far.abs() * T_SLACK;
            if bound.is_nan() || bound < 0.0 {
                assert!(!may_hold(0.0, far), "{far:e}");
                assert!(!may_hold_wide(0.0, far), "{far:e}");
                continue;
            }
            assert!(may_hold(bound, far), "{far:e}");
            assert!(may_hold_wide(bound, far), "{far:e}: {bound:e} accepted by the scalar test only");
            checked += 1;
        }
        assert!(checked > 4_000_000, "{checked}");
        // It accepts more where it must not matter: within a few roundings above the bound.
        let far = 1.0f32;
        let above = f32::from_bits((far + far * T_SLACK).to_bits() + 1);
        assert!(!may_hold(above, far) && may_hold_wide(above, far));
    }

    #[test]
    fn slab_handles_axis_parallel_rays_and_origins_on_faces() {
        let node = Node { min: [0.0, 0.0, 0.0], count: 1, max: [1.0, 1.0, 1.0], index: 0 };
        // Axis-parallel rays: zero components give infinite inverses.
        assert_eq!(slab(&node, &Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z), f32::INFINITY), Some(1.0));
        assert_eq!(slab(&node, &Ray::new(Vec3::new(2.0, 0.5, -1.0), Vec3::Z), f32::INFINITY), None);
        // Origin exactly on a face plane while parallel to it: 0 * inf = NaN must not reject, on
        // the min face or the max face, for either sign of zero.
        assert_eq!(slab(&node, &Ray::new(Vec3::new(0.0, 0.5, -1.0), Vec3::Z), f32::INFINITY), Some(1.0));
        assert_eq!(slab(&node, &Ray::new(Vec3::new(0.5, 1.0, -1.0), Vec3::Z), f32::INFINITY), Some(1.0));
        let neg_zero = Vec3::new(-0.0, -0.0, 1.0);
        assert_eq!(slab(&node, &Ray::new(Vec3::new(1.0, 0.0, -1.0), neg_zero), f32::INFINITY), Some(1.0));
        assert_eq!(slab(&node, &Ray::new(Vec3::new(1.0, 1.0, 0.5), neg_zero), f32::INFINITY), Some(0.0));
        // Inside: enters at 0.
        assert_eq!(slab(&node, &Ray::new(Vec3::splat(0.5), Vec3::X), f32::INFINITY), Some(0.0));
        // Box behind the ray, and beyond t_max.
        assert_eq!(slab(&node, &Ray::new(Vec3::new(0.5, 0.5, 2.0), Vec3::Z), f32::INFINITY), None);
        assert_eq!(slab(&node, &Ray::new(Vec3::new(0.5, 0.5, -1.0), Vec3::Z), 0.5), None);
        // A flat box (a quad's bounds) is still hit.
        let flat = Node { min: [0.0, 0.0, 0.0], count: 1, max: [1.0, 0.0, 1.0], index: 0 };
        assert!(slab(&flat, &Ray::new(Vec3::new(0.5, 1.0, 0.5), Vec3::NEG_Y), f32::INFINITY).is_some());
        // ... and a ray lying in the flat box's plane.
        assert!(slab(&flat, &Ray::new(Vec3::new(-1.0, 0.0, 0.5), Vec3::X), f32::INFINITY).is_some());
    }

    #[test]
    fn the_folded_exit_test_accepts_what_may_hold_wide_accepts() {
        // Floats of every sign and exponent (random bits), the specials, and planes, origins and
        // inverses near one another so that `plane - origin` cancels to tiny or zero differences.
        let mut rng = ::tests::Rng(0x2545f4914f6cdd1d);
        let specials =
            [0.0, -0.0, 1.0, -1.0, f32::MIN_POSITIVE, 1e-45, -1e-45, f32::MAX, f32::INFINITY, -f32::INFINITY];
        let any = |rng: &mut ::tests::Rng| match rng.below(4) {
            0 => specials[rng.below(specials.len())],
            1 => f32::from_bits(rng.next_u64() as u32),
            _ => rng.signed() * 2f32.powi(rng.below(40) as i32 - 20),
        };
        let (mut checked, mut nan) = (0, 0);
        for _ in 0..2_000_000 {
            let origin = any(&mut rng);
            let plane = if rng.below(2) == 0 { any(&mut rng) } else { origin + origin * rng.signed() * 1e-6 };
            let inv = any(&mut rng);
            // The stated domain: inverse components of 0, infinite, or normal (and not NaN).
            if inv.is_nan() || plane.is_nan() || origin.is_nan() || (inv != 0.0 && inv.abs() < f32::MIN_POSITIVE) {
                continue;
            }
            let exit = (plane - origin) * inv;
            let bound = exit_bound(plane, origin, inv_far(inv));
            if exit.is_nan() {
                assert!(bound.is_nan(), "{plane} {origin} {inv}: NaN exit, bound {bound}");
                nan += 1;
                continue;
            }
            // `may_hold_wide` accepts `near` from 0 up to `exit * EXIT_SCALE` (0 only, at -0);
            // the largest such `near` must pass the folded test too.
            if may_hold_wide(0.0, exit) {
                let near = (exit * EXIT_SCALE).max(0.0);
                assert!(may_hold_wide(near, exit));
                let passes = before_exit(near, plane, origin, inv_far(inv));
                assert!(passes, "{plane} - {origin} times {inv}: exit {exit}, bound {bound}");
                checked += 1;
            }
        }
        assert!(checked > 300_000 && nan > 1000, "too few cases: {checked} accepted, {nan} NaN");
    }

    #[test]
    fn offset_origin_leaves_the_surface_at_every_scale() {
        for scale in [1e-6f32, 1e-3, 1.0, 1e3, 1e6] {
            let tri = Triangle::from_vertices([0.0, 0.0, 0.0], [scale, 0.0, 0.0], [0.0, scale, 0.0]);
            for &(x, y) in &[(0.25f32, 0.25f32), (0.1, 0.7), (0.5, 0.01)] {
                let p = Vec3::new(x * scale + 7.0 * scale, y * scale, 0.0) - Vec3::new(7.0 * scale, 0.0, 0.0);
                let o = offset_origin(p, Vec3::Z);
                assert!(o.z > 0.0, "scale {scale}: origin not above the plane");
                // A ray leaving along the surface normal must not hit its own triangle.
                assert!(intersect(&tri, &Ray::new(o, Vec3::new(0.3, 0.2, 1.0)), 0.0, f32::INFINITY).is_none());
            }
        }
    }
}
