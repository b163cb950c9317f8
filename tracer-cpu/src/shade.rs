//! The shading definition (docs/shading.md), as pure functions. The Vulkan kernels implement the
//! same formulas; the cross-backend tests hold them to it.

use bvh_format::{Material, Triangle};
use glam::Vec3;

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
    let point = origin + t * dir;
    let p0 = Vec3::from(tri.p0);
    let raw = (Vec3::from(tri.p1) - p0).cross(Vec3::from(tri.p2) - p0);
    // A degenerate (zero-area) triangle has no normal of its own: face the ray.
    let ng = raw.try_normalize().unwrap_or(-dir);
    let front = dir.dot(ng) < 0.0;
    let geometric = if front { ng } else { -ng };
    let Some(n) = normals else {
        return Surface { point, geometric, shading: geometric, front };
    };
    let interp = (1.0 - u - v) * Vec3::from(n[0]) + u * Vec3::from(n[1]) + v * Vec3::from(n[2]);
    let shading = match interp.try_normalize() {
        Some(s) if s.dot(geometric) < 0.0 => -s,
        Some(s) => s,
        None => geometric,
    };
    Surface { point, geometric, shading, front }
}

/// Ray casting: a white point light at the eye, Lambert only.
#[inline]
pub fn cast(m: &Material, s: &Surface, dir: Vec3) -> Vec3 {
    Vec3::from(m.kd) * s.shading.dot(-dir).max(0.0)
}

/// Mirror direction of `dir` about the unit normal `n`.
#[inline]
pub fn reflect(dir: Vec3, n: Vec3) -> Vec3 {
    dir - 2.0 * dir.dot(n) * n
}

/// Refraction of the unit `dir` through a surface with unit normal `n` facing the incoming ray,
/// for the ratio `eta` = (index on the incoming side) / (index on the far side); `None` on total
/// internal reflection.
#[inline]
pub fn refract(dir: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    let cos_i = -dir.dot(n);
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    (k >= 0.0).then(|| (eta * dir + (eta * cos_i - k.sqrt()) * n).normalize())
}

/// The diffuse and specular terms of one unshadowed light, before its colour:
/// `kd cos(theta) + ks cos(phi)^n`, with phi between the light's mirror direction and the viewer.
/// Zero when the light is behind the shading normal.
#[inline]
pub fn phong(m: &Material, s: &Surface, dir: Vec3, to_light: Vec3) -> Vec3 {
    let cos_t = s.shading.dot(to_light);
    if cos_t <= 0.0 {
        return Vec3::ZERO;
    }
    let r = reflect(-to_light, s.shading);
    let cos_p = r.dot(-dir).max(0.0);
    let spec = if m.shininess > 0.0 { cos_p.powf(m.shininess) } else { 1.0 };
    Vec3::from(m.kd) * cos_t + Vec3::from(m.ks) * spec
}

/// The secondary ray a hit spawns: direction, which side of the surface it leaves into
/// (`true`: the incoming side), and the factor its weight is multiplied by.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Secondary {
    pub dir: Vec3,
    pub same_side: bool,
    pub factor: f32,
}

/// A material's secondary ray: reflection for `kr > 0`; refraction for `kt > 0`, entering when
/// the front was hit (eta = 1 / ior) and leaving otherwise (eta = ior), with total internal
/// reflection sending the ray back as a mirror would, still weighted by `kt`.
pub fn secondary(m: &Material, s: &Surface, dir: Vec3) -> Option<Secondary> {
    if m.kr > 0.0 {
        return Some(Secondary { dir: reflect(dir, s.shading), same_side: true, factor: m.kr });
    }
    if m.kt > 0.0 {
        let eta = if s.front { 1.0 / m.ior } else { m.ior };
        return Some(match refract(dir, s.shading, eta) {
            Some(t) => Secondary { dir: t, same_side: false, factor: m.kt },
            None => Secondary { dir: reflect(dir, s.shading), same_side: true, factor: m.kt },
        });
    }
    None
}

/// Linear radiance to 8 bits: clamp to [0, 1], scale by 255, round to nearest.
#[inline]
pub fn to_u8(c: Vec3) -> [u8; 3] {
    let q = |x: f32| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    [q(c.x), q(c.y), q(c.z)]
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
