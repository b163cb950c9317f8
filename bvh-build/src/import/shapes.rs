//! Generated geometry for scene descriptions: quads, boxes, UV spheres and tori, each with
//! outward unit normals and counter-clockwise winding seen from outside.
//!
//! Triangle order (the input order tracers report):
//! - quad: 2 triangles;
//! - box: the faces +x, -x, +y, -y, +z, -z, two triangles each (12);
//! - sphere: band by band from the +y pole to the -y pole, around each band in the direction of
//!   increasing longitude (x towards z); `2 * segments * (rings - 1)` triangles;
//! - torus: around the major circle (x towards z), for each step around the tube (outside, up,
//!   inside, down); `2 * segments * sides` triangles.
//!
//! The generators trust their parameters (the description checks them), but never panic:
//! counts below the minimum are raised to it.

use glam::Vec3;
use std::f32::consts::{PI, TAU};

/// Triangles with per-vertex normals, in local space.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<[Vec3; 3]>,
    pub normals: Vec<[Vec3; 3]>,
}

impl Mesh {
    fn push(&mut self, p: [Vec3; 3], n: [Vec3; 3]) {
        self.positions.push(p);
        self.normals.push(n);
    }

    pub fn triangle_count(&self) -> usize {
        self.positions.len()
    }
}

/// The in-plane axes of a rectangle facing `normal`: `(u, v)` with `u x v = normal`. A floor or
/// ceiling (normal along +-y) has `u` along +x; any other rectangle has `u` horizontal and `v`
/// pointing as far up (+y) as the normal allows, so walls and mirrors stand upright.
pub fn quad_axes(normal: Vec3) -> (Vec3, Vec3) {
    let n = normal.try_normalize().unwrap_or(Vec3::Y);
    let reference = if n.y.abs() > 0.999 { Vec3::NEG_Z } else { Vec3::Y };
    let u = reference.cross(n).normalize();
    (u, n.cross(u))
}

/// A rectangle centred on `centre`, facing `normal`, `size[0]` wide along `u` and `size[1]` high
/// along `v` of [`quad_axes`].
pub fn quad(centre: Vec3, size: [f32; 2], normal: Vec3) -> Mesh {
    let (u, v) = quad_axes(normal);
    let n = u.cross(v);
    let (hu, hv) = (u * size[0] * 0.5, v * size[1] * 0.5);
    let [a, b, c, d] = [centre - hu - hv, centre + hu - hv, centre + hu + hv, centre - hu + hv];
    let mut m = Mesh::default();
    m.push([a, b, c], [n; 3]);
    m.push([a, c, d], [n; 3]);
    m
}

/// An axis-aligned box centred on `centre` with edge lengths `size`, flat-shaded.
pub fn cuboid(centre: Vec3, size: Vec3) -> Mesh {
    let h = size * 0.5;
    let faces = [
        (Vec3::X, [size.z, size.y], h.x),
        (Vec3::NEG_X, [size.z, size.y], h.x),
        (Vec3::Y, [size.x, size.z], h.y),
        (Vec3::NEG_Y, [size.x, size.z], h.y),
        (Vec3::Z, [size.x, size.y], h.z),
        (Vec3::NEG_Z, [size.x, size.y], h.z),
    ];
    let mut m = Mesh::default();
    for (n, s, d) in faces {
        let q = quad(centre + n * d, s, n);
        m.positions.extend(q.positions);
        m.normals.extend(q.normals);
    }
    m
}

/// A UV sphere with `segments` steps of longitude (at least 3) and `rings` bands of latitude
/// (at least 2), smooth normals. The poles lie on the y axis.
pub fn sphere(centre: Vec3, radius: f32, segments: u32, rings: u32) -> Mesh {
    let (segments, rings) = (segments.max(3), rings.max(2));
    let dir = |j: u32, i: u32| {
        if j == 0 {
            return Vec3::Y;
        }
        if j == rings {
            return Vec3::NEG_Y;
        }
        let theta = PI * j as f32 / rings as f32;
        let phi = TAU * (i % segments) as f32 / segments as f32;
        Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin())
    };
    let mut m = Mesh::default();
    let mut tri = |d: [Vec3; 3]| m.push(d.map(|d| centre + d * radius), d);
    for j in 0..rings {
        for i in 0..segments {
            let (a, b, c, d) = (dir(j, i), dir(j, i + 1), dir(j + 1, i), dir(j + 1, i + 1));
            if j > 0 {
                tri([a, b, c]);
            }
            if j + 1 < rings {
                tri([b, d, c]);
            }
        }
    }
    m
}

/// A torus around the y axis through `centre`: the tube's centre line is a circle of radius
/// `major` in the xz plane, the tube has radius `minor`; `segments` steps around the major
/// circle and `sides` around the tube (at least 3 each), smooth normals.
pub fn torus(centre: Vec3, major: f32, minor: f32, segments: u32, sides: u32) -> Mesh {
    let (segments, sides) = (segments.max(3), sides.max(3));
    let at = |i: u32, k: u32| {
        let u = TAU * (i % segments) as f32 / segments as f32;
        let v = TAU * (k % sides) as f32 / sides as f32;
        let n = Vec3::new(v.cos() * u.cos(), v.sin(), v.cos() * u.sin());
        let ring = Vec3::new(u.cos(), 0.0, u.sin()) * major;
        (centre + ring + n * minor, n)
    };
    let mut m = Mesh::default();
    for i in 0..segments {
        for k in 0..sides {
            let (a, b, c, d) = (at(i, k), at(i, k + 1), at(i + 1, k), at(i + 1, k + 1));
            m.push([a.0, b.0, c.0], [a.1, b.1, c.1]);
            m.push([b.0, d.0, c.0], [b.1, d.1, c.1]);
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::import::geometry::face_normal;

    fn check_closed_outward(m: &Mesh, inside: Vec3) {
        for (t, (p, n)) in m.positions.iter().zip(&m.normals).enumerate() {
            for v in n {
                assert!(v.is_finite() && (v.length() - 1.0).abs() < 1e-5, "triangle {t}: normal {v}");
            }
            let centroid = (p[0] + p[1] + p[2]) / 3.0;
            let f = face_normal(p[0], p[1], p[2]);
            assert!(f.dot(centroid - inside) > 0.0, "triangle {t} faces inwards");
            assert!(f.dot(n[0]) > 0.0, "triangle {t}: shading normal against winding");
        }
        // Closed: every directed edge is matched by its reverse.
        let key = |v: Vec3| (v * 1e4).round().to_array().map(|x| x as i64);
        let mut edges = std::collections::HashMap::new();
        for p in &m.positions {
            for k in 0..3 {
                *edges.entry((key(p[k]), key(p[(k + 1) % 3]))).or_insert(0i32) += 1;
            }
        }
        for (&(a, b), &c) in &edges {
            assert_eq!(edges.get(&(b, a)).copied(), Some(c), "open edge {a:?} -> {b:?}");
        }
    }

    fn bounds(m: &Mesh) -> (Vec3, Vec3) {
        m.positions.iter().flatten().fold((Vec3::MAX, Vec3::MIN), |(lo, hi), &p| (lo.min(p), hi.max(p)))
    }

    #[test]
    fn quad_faces_its_normal() {
        for n in [Vec3::Y, Vec3::NEG_Y, Vec3::X, Vec3::new(1.0, 1.0, -2.0)] {
            let q = quad(Vec3::ONE, [2.0, 4.0], n);
            assert_eq!(q.triangle_count(), 2);
            for p in &q.positions {
                assert!((face_normal(p[0], p[1], p[2]) - n.normalize()).length() < 1e-5);
            }
            let area: f32 = q.positions.iter().map(|p| (p[1] - p[0]).cross(p[2] - p[0]).length() / 2.0).sum();
            assert!((area - 8.0).abs() < 1e-4);
        }
        let (u, v) = quad_axes(Vec3::Y);
        assert_eq!((u, v), (Vec3::X, Vec3::NEG_Z));
        let (u, v) = quad_axes(Vec3::Z);
        assert_eq!((u, v), (Vec3::X, Vec3::Y));
    }

    #[test]
    fn box_is_closed_with_the_right_bounds() {
        let c = Vec3::new(1.0, 2.0, 3.0);
        let m = cuboid(c, Vec3::new(2.0, 4.0, 6.0));
        assert_eq!(m.triangle_count(), 12);
        check_closed_outward(&m, c);
        let (lo, hi) = bounds(&m);
        assert!((lo - Vec3::new(0.0, 0.0, 0.0)).length() < 1e-5 && (hi - Vec3::new(2.0, 4.0, 6.0)).length() < 1e-5);
    }

    #[test]
    fn sphere_is_closed_with_the_right_bounds() {
        let c = Vec3::new(-1.0, 0.5, 2.0);
        let m = sphere(c, 2.0, 16, 8);
        assert_eq!(m.triangle_count(), 2 * 16 * 7);
        check_closed_outward(&m, c);
        let (lo, hi) = bounds(&m);
        assert!((hi.y - 2.5).abs() < 1e-5 && (lo.y + 1.5).abs() < 1e-5);
        assert!((hi.x - 1.0).abs() < 1e-5 && lo.x >= -3.0 - 1e-5 && hi.z <= 4.0 + 1e-5);
        assert_eq!(sphere(c, 1.0, 0, 0).triangle_count(), 2 * 3);
    }

    #[test]
    fn torus_is_closed_with_outward_normals() {
        let c = Vec3::new(0.0, 1.0, 0.0);
        let m = torus(c, 3.0, 0.5, 24, 12);
        assert_eq!(m.triangle_count(), 2 * 24 * 12);
        check_closed_outward_torus(&m, c, 3.0);
        let (lo, hi) = bounds(&m);
        assert!((hi.x - 3.5).abs() < 1e-4 && (hi.y - 1.5).abs() < 1e-4 && (lo.y - 0.5).abs() < 1e-4);
    }

    fn check_closed_outward_torus(m: &Mesh, c: Vec3, major: f32) {
        // "Outward" for a torus: away from the nearest point of the centre circle.
        for p in &m.positions {
            let centroid = (p[0] + p[1] + p[2]) / 3.0 - c;
            let ring = Vec3::new(centroid.x, 0.0, centroid.z).normalize() * major;
            let f = face_normal(p[0], p[1], p[2]);
            assert!(f.dot(centroid - ring) > 0.0);
        }
        check_closed_outward(&Mesh::default(), c);
        let key = |v: Vec3| (v * 1e4).round().to_array().map(|x| x as i64);
        let mut edges = std::collections::HashSet::new();
        for p in &m.positions {
            for k in 0..3 {
                edges.insert((key(p[k]), key(p[(k + 1) % 3])));
            }
        }
        assert!(edges.iter().all(|&(a, b)| edges.contains(&(b, a))));
        for n in m.normals.iter().flatten() {
            assert!(n.is_finite() && (n.length() - 1.0).abs() < 1e-5);
        }
    }
}
