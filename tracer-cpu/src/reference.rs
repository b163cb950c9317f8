//! The exact reference: brute-force closest hit over every triangle in f64. Tests trust it.
//!
//! Ties: the nearest hit wins; at exactly equal f64 distance (a ray through an edge or vertex
//! shared by triangles) the lower stored triangle index wins, the same rule as every fast path
//! ([`crate::Hit::beats`]). Edges and vertices count as inside a triangle.

use bvh_format::Triangle;
use glam::DVec3;

/// A hit found by the reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefHit {
    pub t: f64,
    pub tri: u32,
    pub u: f64,
    pub v: f64,
}

fn d3(v: [f32; 4]) -> DVec3 {
    DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64)
}

/// Möller-Trumbore in f64 on the stored triangle (vertex and edges widened exactly).
pub fn intersect64(tri: &Triangle, origin: DVec3, dir: DVec3, t_min: f64) -> Option<(f64, f64, f64)> {
    let (v0, e1, e2) = (d3(tri.v0), d3(tri.e1), d3(tri.e2));
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det == 0.0 {
        return None;
    }
    let inv = 1.0 / det;
    let s = origin - v0;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = dir.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(q) * inv;
    (t > t_min).then_some((t, u, v))
}

/// The closest hit beyond `t_min` over all triangles, or `None`.
pub fn closest_hit(tris: &[Triangle], origin: DVec3, dir: DVec3, t_min: f64) -> Option<RefHit> {
    let mut best: Option<RefHit> = None;
    for (i, tri) in tris.iter().enumerate() {
        if let Some((t, u, v)) = intersect64(tri, origin, dir, t_min)
            && best.is_none_or(|b| t < b.t)
        {
            best = Some(RefHit { t, tri: i as u32, u, v });
        }
    }
    best
}

/// How close (in barycentric terms) a reference hit lies to its triangle's boundary: the smallest
/// of `u`, `v` and `1 - u - v`. Tests treat disagreements with f32 paths within a tiny margin of
/// an edge as edge ambiguities, not errors.
pub fn edge_distance(h: &RefHit) -> f64 {
    h.u.min(h.v).min(1.0 - h.u - h.v)
}
