//! Brute force: the closest hit over every triangle, in f64. The f64 traversal ([`super::bvh`]) is
//! tested against it, and tests of the fast paths compare with it directly.
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

fn d3(v: [f32; 3]) -> DVec3 {
    DVec3::new(v[0] as f64, v[1] as f64, v[2] as f64)
}

/// The edge-consistent test of docs/shading.md in f64 on the stored vertices (widened exactly):
/// the same edge functions, sign rule and distance as the f32 paths, with far smaller rounding.
pub fn intersect64(tri: &Triangle, origin: DVec3, dir: DVec3, t_min: f64) -> Option<(f64, f64, f64)> {
    let [a0, a1, a2] = tri.vertices().map(|p| d3(p) - origin);
    let edge = |a: DVec3, b: DVec3| (a - b).cross(a + b).dot(dir);
    let (w2, w0, w1) = (edge(a0, a1), edge(a1, a2), edge(a2, a0));
    let inside = (w0 >= 0.0 && w1 >= 0.0 && w2 >= 0.0) || (w0 <= 0.0 && w1 <= 0.0 && w2 <= 0.0);
    let sum = w0 + w1 + w2;
    if !inside || sum == 0.0 {
        return None;
    }
    let [p0, p1, p2] = tri.vertices().map(d3);
    let n = (p1 - p0).cross(p2 - p0);
    let den = n.dot(dir);
    if den == 0.0 {
        return None;
    }
    let t = n.dot(a0) / den;
    (t > t_min).then_some((t, w1 / sum, w2 / sum))
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
