//! The shading definition (docs/shading.md), as pure functions. The Vulkan kernels implement the
//! same formulas; the cross-backend tests hold them to it.

use crate::wide::{LANES, Lanes, Real, V3};
use bvh_format::{Material, Triangle};
use glam::Vec3;
use render_spec::BounceStop;

/// Everything shading needs to know about a hit.
#[derive(Clone, Copy, Debug)]
pub struct Surface {
    pub point: Vec3,
    /// Unit geometric normal, turned to face the incoming ray.
    pub geometric: Vec3,
    /// Unit interpolated shading normal, turned to the same side as `geometric`.
    pub shading: Vec3,
    /// Whether the ray hit the triangle's front (the side `cross(p1 - p0, p2 - p0)` points to).
    pub front: bool,
}

/// [`Surface`] for any lanes ([`crate::wide`]).
#[derive(Clone, Copy, Debug)]
pub struct SurfaceOf<R: Real> {
    pub point: V3<R>,
    pub geometric: V3<R>,
    pub shading: V3<R>,
    pub front: R::Mask,
}

/// The edges `p1 - p0` and `p2 - p0` of a triangle, whose cross product is its geometric normal
/// (the kernels compute them the same way).
pub fn edges(tri: &Triangle) -> (Vec3, Vec3) {
    let p0 = Vec3::from(tri.p0);
    (Vec3::from(tri.p1) - p0, Vec3::from(tri.p2) - p0)
}

/// The vertex normals shading interpolates: a flat triangle's are zero, which the interpolation
/// turns into its geometric normal (the kernels take that normal directly).
pub fn shading_normals(normals: Option<[[f32; 3]; 3]>) -> [[f32; 3]; 3] {
    normals.unwrap_or([[0.0; 3]; 3])
}

/// The surface at a hit `t` along `origin + t * dir` with barycentrics `(u, v)`; `normals` are the
/// triangle's vertex normals, `None` for a flat triangle (shaded with its geometric normal).
pub fn surface(
    tri: &Triangle,
    normals: Option<[[f32; 3]; 3]>,
    origin: Vec3,
    dir: Vec3,
    t: f32,
    u: f32,
    v: f32,
) -> Surface {
    let n = shading_normals(normals).map(|n| Vec3::from(n).into());
    let (e1, e2) = edges(tri);
    let s = surface_of(e1.into(), e2.into(), n, origin.into(), dir.into(), t, u, v);
    Surface { point: s.point.into(), geometric: s.geometric.into(), shading: s.shading.into(), front: s.front }
}

/// [`surface`] of a triangle given by its edges `e1`, `e2` and vertex normals `n` (zero for a
/// flat triangle).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn surface_of<R: Real>(
    e1: V3<R>,
    e2: V3<R>,
    n: [V3<R>; 3],
    origin: V3<R>,
    dir: V3<R>,
    t: R,
    u: R,
    v: R,
) -> SurfaceOf<R> {
    let zero = R::splat(0.0);
    let flat = flat_surface_of(e1, e2, origin, dir, t);
    let interp = n[0] * (R::splat(1.0) - u - v) + n[1] * u + n[2] * v;
    let (s, ok) = interp.try_normalize();
    let s = V3::select(s.dot(flat.geometric).lt(zero), -s, s);
    SurfaceOf { shading: V3::select(ok, s, flat.geometric), ..flat }
}

/// [`surface_of`] of a flat triangle (zero vertex normals), which is shaded with its geometric
/// normal: the interpolated normal is zero (or NaN), never normalisable, so `surface_of` ends in
/// the same surface; without the interpolation, for scenes whose triangles are all flat.
#[inline(always)]
pub fn flat_surface_of<R: Real>(e1: V3<R>, e2: V3<R>, origin: V3<R>, dir: V3<R>, t: R) -> SurfaceOf<R> {
    let point = origin + dir * t;
    // A degenerate (zero-area) triangle has no normal of its own: face the ray.
    let (ng, ok) = e1.cross(e2).try_normalize();
    let ng = V3::select(ok, ng, -dir);
    let front = dir.dot(ng).lt(R::splat(0.0));
    let geometric = V3::select(front, ng, -ng);
    SurfaceOf { point, geometric, shading: geometric, front }
}

/// Ray casting: a white point light at the eye, Lambert only.
#[inline]
pub fn cast(m: &Material, s: &Surface, dir: Vec3) -> Vec3 {
    cast_of(Vec3::from(m.kd).into(), s.shading.into(), dir.into()).into()
}

/// [`cast`] with the material's `kd`.
#[inline(always)]
pub fn cast_of<R: Real>(kd: V3<R>, shading: V3<R>, dir: V3<R>) -> V3<R> {
    kd * shading.dot(-dir).max(R::splat(0.0))
}

/// Mirror direction of `dir` about the unit normal `n`.
#[inline]
pub fn reflect(dir: Vec3, n: Vec3) -> Vec3 {
    reflect_of(dir.into(), n.into()).into()
}

/// [`reflect`] for any lanes.
#[inline(always)]
pub fn reflect_of<R: Real>(dir: V3<R>, n: V3<R>) -> V3<R> {
    dir - n * (R::splat(2.0) * dir.dot(n))
}

/// Refraction of the unit `dir` through a surface with unit normal `n` facing the incoming ray,
/// for the ratio `eta` = (index on the incoming side) / (index on the far side); `None` on total
/// internal reflection.
#[inline]
pub fn refract(dir: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    let (t, ok) = refract_of(dir.into(), n.into(), eta);
    ok.then(|| t.into())
}

/// [`refract`] for any lanes: the direction, and where it exists (elsewhere total internal
/// reflection).
#[inline(always)]
pub fn refract_of<R: Real>(dir: V3<R>, n: V3<R>, eta: R) -> (V3<R>, R::Mask) {
    let one = R::splat(1.0);
    let cos_i = -dir.dot(n);
    let k = one - eta * eta * (one - cos_i * cos_i);
    ((dir * eta + n * (eta * cos_i - k.sqrt())).normalize(), k.ge(R::splat(0.0)))
}

/// The diffuse and specular terms of one unshadowed light, before its colour:
/// `kd cos(theta) + ks cos(phi)^n`, with phi between the light's mirror direction and the viewer.
/// Zero when the light is behind the shading normal.
#[inline]
pub fn phong(m: &Material, s: &Surface, dir: Vec3, to_light: Vec3) -> Vec3 {
    let (kd, ks) = (Vec3::from(m.kd).into(), Vec3::from(m.ks).into());
    phong_of(kd, ks, m.shininess, s.shading.into(), dir.into(), to_light.into(), true).into()
}

/// [`phong`] with the material's `kd`, `ks` and shininess; `live` marks the lanes whose result
/// is used (the others skip the power).
#[inline(always)]
pub fn phong_of<R: Real>(
    kd: V3<R>,
    ks: V3<R>,
    shininess: R,
    shading: V3<R>,
    dir: V3<R>,
    to_light: V3<R>,
    live: R::Mask,
) -> V3<R> {
    let zero = R::splat(0.0);
    let cos_t = shading.dot(to_light);
    let lit = !cos_t.le(zero);
    let r = reflect_of(-to_light, shading);
    let cos_p = r.dot(-dir).max(zero);
    let glossy = shininess.gt(zero);
    let spec = R::select(glossy, cos_p.powf_in(shininess, glossy & lit & live), R::splat(1.0));
    V3::select(lit, kd * cos_t + ks * spec, V3::zero())
}

/// The secondary ray a hit spawns: direction, which side of the surface it leaves into
/// (`true`: the incoming side), and the factor its weight is multiplied by.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Secondary {
    pub dir: Vec3,
    pub same_side: bool,
    pub factor: f32,
}

/// [`Secondary`] for any lanes, with where one exists.
#[derive(Clone, Copy, Debug)]
pub struct SecondaryOf<R: Real> {
    pub dir: V3<R>,
    pub same_side: R::Mask,
    pub factor: R,
    pub exists: R::Mask,
}

/// A material's secondary ray: reflection for `kr > 0`; refraction for `kt > 0`, entering when
/// the front was hit (eta = 1 / ior) and leaving otherwise (eta = ior), with total internal
/// reflection sending the ray back as a mirror would, still weighted by `kt`.
pub fn secondary(m: &Material, s: &Surface, dir: Vec3) -> Option<Secondary> {
    let sec = secondary_of(m.kr, m.kt, m.ior, s.shading.into(), s.front, dir.into());
    sec.exists.then(|| Secondary { dir: sec.dir.into(), same_side: sec.same_side, factor: sec.factor })
}

/// [`secondary`] with the material's `kr`, `kt` and `ior`, and the surface's shading normal and
/// side.
#[inline(always)]
pub fn secondary_of<R: Real>(kr: R, kt: R, ior: R, shading: V3<R>, front: R::Mask, dir: V3<R>) -> SecondaryOf<R> {
    let zero = R::splat(0.0);
    let mirror = kr.gt(zero);
    let glass = !mirror & kt.gt(zero);
    let reflected = reflect_of(dir, shading);
    let eta = R::select(front, R::splat(1.0) / ior, ior);
    let (refracted, ok) = refract_of(dir, shading, eta);
    SecondaryOf {
        dir: V3::select(mirror, reflected, V3::select(ok, refracted, reflected)),
        same_side: mirror | !ok,
        factor: R::select(mirror, kr, kt),
        exists: mirror | glass,
    }
}

/// [`secondary_of`] for lanes none of which is glass (`kt > 0` without `kr > 0`): in every
/// lane the same `exists`, and where a ray exists (the mirrors) the same direction, side and
/// factor, without the refraction (a division and two square roots) that no lane takes.
#[inline(always)]
pub fn reflection_of<R: Real>(kr: R, shading: V3<R>, dir: V3<R>) -> SecondaryOf<R> {
    let mirror = kr.gt(R::splat(0.0));
    SecondaryOf { dir: reflect_of(dir, shading), same_side: mirror, factor: kr, exists: mirror }
}

/// [`BounceStop::worth_tracing`] for any lanes, given the stop's [`BounceStop::chain`] at their
/// (common) depth: computed once per depth, not once per lane.
#[inline(always)]
pub fn worth_of<R: Real>(w: R, stop: &BounceStop, chain: f32) -> R::Mask {
    (w * R::splat(stop.bound) * R::splat(chain)).ge(R::splat(stop.cutoff))
}

/// Linear radiance to 8 bits: clamp to [0, 1], scale by 255, round to nearest.
#[inline]
pub fn to_u8(c: Vec3) -> [u8; 3] {
    let q = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    [q(c.x), q(c.y), q(c.z)]
}

/// [`to_u8`] for eight lanes: the same clamp (`f32::clamp` keeps a NaN, which `as u8` turns into
/// 0), scale and offset; then every value lies in [0.5, 255.5], where `as u8` is truncation.
#[inline(always)]
pub fn to_u8_lanes<L: Lanes>(c: V3<L>) -> [[u8; 3]; LANES] {
    let (r, g, b) = (quantize(c.x), quantize(c.y), quantize(c.z));
    std::array::from_fn(|i| [r[i] as u8, g[i] as u8, b[i] as u8])
}

/// [`to_u8_lanes`] laid out as the block's two rows of four pixels: RGB bytes 0..12 of each row
/// ([`Lanes::rgb_rows`]), ready to be copied into the image.
#[inline(always)]
pub fn to_rgb_rows<L: Lanes>(c: V3<L>) -> [[u8; 16]; 2] {
    L::rgb_rows(scaled(c.x), scaled(c.y), scaled(c.z))
}

#[inline(always)]
fn quantize<L: Lanes>(x: L) -> [i32; LANES] {
    scaled(x).trunc()
}

/// Clamped, scaled and offset into [0.5, 255.5], NaN as 0: what `as u8` truncates to
/// [`to_u8`]'s bytes (which turns NaN into 0). `max(x, 0)` (`x > 0 ? x : 0`) sends NaN to 0 and
/// `min(x, 1)` clamps the rest: two instructions per channel where two comparisons and selects,
/// and a third pair for NaN, took six.
#[inline(always)]
fn scaled<L: Lanes>(x: L) -> L {
    x.max(L::splat(0.0)).min(L::splat(1.0)) * L::splat(255.0) + L::splat(0.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat_surface(front: bool) -> Surface {
        Surface { point: Vec3::ZERO, geometric: Vec3::Y, shading: Vec3::Y, front }
    }

    #[test]
    fn reflection_mirrors_about_the_normal() {
        let d = Vec3::new(1.0, -1.0, 0.0).normalize();
        let r = reflect(d, Vec3::Y);
        assert!((r - Vec3::new(1.0, 1.0, 0.0).normalize()).length() < 1e-6);
        assert!((r.length() - 1.0).abs() < 1e-6);
    }

    #[test]
    fn refraction_follows_snell_and_total_internal_reflection() {
        let theta = 30f32.to_radians();
        let d = Vec3::new(theta.sin(), -theta.cos(), 0.0);
        let t = refract(d, Vec3::Y, 1.0 / 1.5).unwrap();
        // n1 sin(t1) = n2 sin(t2)
        assert!((theta.sin() - 1.5 * t.x).abs() < 1e-6, "{t:?}");
        assert!(t.y < 0.0);
        // Head-on: straight through.
        let t = refract(Vec3::NEG_Y, Vec3::Y, 1.0 / 1.5).unwrap();
        assert!((t - Vec3::NEG_Y).length() < 1e-6);
        // Leaving glass at 60 degrees exceeds the critical angle asin(1/1.5) = 41.8 degrees.
        let theta = 60f32.to_radians();
        let d = Vec3::new(theta.sin(), -theta.cos(), 0.0);
        assert!(refract(d, Vec3::Y, 1.5).is_none());
        let m = Material { kt: 0.9, ior: 1.5, ..Material::default() };
        let s = secondary(&m, &flat_surface(false), d).unwrap();
        assert!(s.same_side, "total internal reflection stays on the incoming side");
        assert_eq!(s.factor, 0.9);
        assert!((s.dir - reflect(d, Vec3::Y)).length() < 1e-6);
        // Entering at the same angle refracts.
        let s = secondary(&m, &flat_surface(true), d).unwrap();
        assert!(!s.same_side && s.dir.y < 0.0);
    }

    #[test]
    fn mirrors_reflect_and_opaque_materials_stop() {
        let d = Vec3::new(0.0, -1.0, 0.0);
        let mirror = Material { kr: 0.8, ..Material::default() };
        let s = secondary(&mirror, &flat_surface(true), d).unwrap();
        assert_eq!(s, Secondary { dir: Vec3::Y, same_side: true, factor: 0.8 });
        assert!(secondary(&Material::default(), &flat_surface(true), d).is_none());
    }

    #[test]
    fn phong_is_zero_behind_and_peaks_on_the_mirror_direction() {
        let m = Material { kd: [0.5; 3], ks: [0.25; 3], shininess: 10.0, ..Material::default() };
        let s = flat_surface(true);
        assert_eq!(phong(&m, &s, Vec3::NEG_Y, Vec3::NEG_Y), Vec3::ZERO);
        let c = phong(&m, &s, Vec3::NEG_Y, Vec3::Y);
        assert!((c - Vec3::splat(0.75)).length() < 1e-6, "{c:?}");
        let l = Vec3::new(1.0, 1.0, 0.0).normalize();
        let c = phong(&m, &s, Vec3::NEG_Y, l);
        let expect = 0.5 * l.y + 0.25 * l.y.powf(10.0);
        assert!((c.x - expect).abs() < 1e-6);
    }

    #[test]
    fn surfaces_face_the_ray_and_fall_back_for_degenerate_triangles() {
        let tri = Triangle::from_vertices([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]);
        let n = Some([[0.0, 1.0, 0.0]; 3]);
        let down = surface(&tri, n, Vec3::new(0.2, 1.0, -0.2), Vec3::NEG_Y, 1.0, 0.2, 0.2);
        assert!(down.front && down.geometric == Vec3::Y && down.shading == Vec3::Y);
        let up = surface(&tri, n, Vec3::new(0.2, -1.0, -0.2), Vec3::Y, 1.0, 0.2, 0.2);
        assert!(!up.front && up.geometric == Vec3::NEG_Y && up.shading == Vec3::NEG_Y);
        let sliver = Triangle::from_vertices([0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]);
        let s = surface(&sliver, Some([[0.0; 3]; 3]), Vec3::ZERO, Vec3::X, 0.5, 0.3, 0.3);
        assert_eq!(s.geometric, Vec3::NEG_X);
        assert!(s.shading.is_finite());
        // A flat triangle is shaded with its geometric normal.
        let flat = surface(&tri, None, Vec3::new(0.2, -1.0, -0.2), Vec3::Y, 1.0, 0.2, 0.2);
        assert_eq!(flat.shading, flat.geometric);
    }

    #[test]
    fn radiance_rounds_to_the_nearest_8_bit_value() {
        assert_eq!(to_u8(Vec3::new(-1.0, 0.5, 2.0)), [0, 128, 255]);
    }
}
