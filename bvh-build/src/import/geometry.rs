//! Shared geometry for the readers: emitting indexed meshes as triangles with unit shading
//! normals, and affine transforms of points and normals.
//!
//! Normal arithmetic runs in f64: cross products of tiny (or huge) f32 edges underflow (or
//! overflow) in f32, and a triangle must still get a finite unit normal.

use crate::scene::Scene;
use glam::{DMat3, DMat4, DVec3, Vec3};
use rayon::prelude::*;

/// The normal of a triangle that has none (zero area): +z, so that every normal stays unit.
pub(crate) const FALLBACK_NORMAL: Vec3 = Vec3::Z;

/// `v` scaled to unit length, or `None` when that is not possible.
pub(crate) fn unit(v: DVec3) -> Option<Vec3> {
    let len = v.length();
    if !(len > 0.0 && len.is_finite()) {
        return None;
    }
    let u = (v / len).as_vec3();
    // f32 rounding can still leave a vector far from unit for denormal inputs; reject those.
    (u.is_finite() && (u.length() - 1.0).abs() < 1e-3).then_some(u)
}

/// Twice the area-weighted normal of a triangle (its edge cross product), in f64.
pub(crate) fn area_normal(a: Vec3, b: Vec3, c: Vec3) -> DVec3 {
    let (a, b, c) = (a.as_dvec3(), b.as_dvec3(), c.as_dvec3());
    (b - a).cross(c - a)
}

/// The unit geometric normal by the right-hand rule, or [`FALLBACK_NORMAL`] for a zero-area
/// triangle.
pub(crate) fn face_normal(a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    unit(area_normal(a, b, c)).unwrap_or(FALLBACK_NORMAL)
}

/// Where the shading normals of a mesh come from.
pub(crate) enum Normals<'a> {
    /// None in the file: flat or smooth normals are computed.
    Missing,
    /// One normal per position, indexed like the positions (glTF).
    PerVertex(&'a [Vec3]),
    /// A separate normal array with its own index triangles, parallel to the position triangles
    /// (OBJ).
    Indexed(&'a [Vec3], &'a [[u32; 3]]),
}

/// Why an indexed mesh could not be emitted; the reader adds the file and the mesh's name.
#[derive(Debug)]
pub(crate) enum EmitError {
    /// Triangle `triangle` refers to `value` in an array of `limit` entries.
    Index { triangle: usize, value: u32, limit: usize, normal: bool },
    /// Position `vertex` is not finite.
    NonFinite { vertex: usize },
}

/// Appends an indexed mesh (positions already in world space) to `scene` with material
/// `material`. Triangles keep their order.
pub(crate) fn emit(
    scene: &mut Scene,
    positions: &[Vec3],
    triangles: &[[u32; 3]],
    normals: Normals<'_>,
    material: u32,
    smooth: bool,
) -> Result<(), EmitError> {
    // Each check finds its first offending triangle on every thread, then its first offending
    // corner: the error a serial pass would report.
    let out_of = |tri: &[u32; 3], len: usize| tri.iter().copied().find(|&i| i as usize >= len);
    if let Some(t) = triangles.par_iter().position_first(|tri| out_of(tri, positions.len()).is_some()) {
        let value = out_of(&triangles[t], positions.len()).unwrap_or_default();
        return Err(EmitError::Index { triangle: t, value, limit: positions.len(), normal: false });
    }
    // Only referenced vertices matter: an unused NaN vertex harms nothing.
    let non_finite = |tri: &[u32; 3]| tri.iter().copied().find(|&i| !positions[i as usize].is_finite());
    if let Some(t) = triangles.par_iter().position_first(|tri| non_finite(tri).is_some()) {
        return Err(EmitError::NonFinite { vertex: non_finite(&triangles[t]).unwrap_or_default() as usize });
    }
    match normals {
        Normals::PerVertex(n) if n.len() != positions.len() => {
            return Err(EmitError::Index { triangle: 0, value: n.len() as u32, limit: positions.len(), normal: true });
        }
        Normals::Indexed(n, idx) => {
            if idx.len() != triangles.len() {
                return Err(EmitError::Index {
                    triangle: 0,
                    value: idx.len() as u32,
                    limit: triangles.len(),
                    normal: true,
                });
            }
            if let Some(t) = idx.par_iter().position_first(|tri| out_of(tri, n.len()).is_some()) {
                let value = out_of(&idx[t], n.len()).unwrap_or_default();
                return Err(EmitError::Index { triangle: t, value, limit: n.len(), normal: true });
            }
        }
        _ => {}
    }

    let smoothed = match normals {
        Normals::Missing if smooth => Some(smooth_normals(positions, triangles)),
        _ => None,
    };
    // Every triangle on its own, so in parallel, straight into the scene's new tail (rayon writes
    // an indexed iterator's items in place: no serial pass fills the tail first).
    scene.positions.par_extend(triangles.par_iter().map(|tri| tri.map(|i| positions[i as usize])));
    scene.normals.par_extend(triangles.par_iter().enumerate().map(|(t, tri)| {
        // The flat normal only where a vertex has none: it costs a square root in f64.
        let flat = || {
            let p = tri.map(|i| positions[i as usize]);
            face_normal(p[0], p[1], p[2])
        };
        let fix = |n: Vec3| unit(n.as_dvec3()).unwrap_or_else(flat);
        match (&normals, &smoothed) {
            (_, Some(s)) => tri.map(|i| s[i as usize].unwrap_or_else(flat)),
            (Normals::PerVertex(n), None) => tri.map(|i| fix(n[i as usize])),
            (Normals::Indexed(n, idx), None) => idx[t].map(|i| fix(n[i as usize])),
            (Normals::Missing, None) => [flat(); 3],
        }
    }));
    scene.material_ids.resize(scene.positions.len(), material);
    Ok(())
}

/// Area-weighted vertex normals: each vertex gets the sum of its triangles' edge cross products
/// (twice their area times their normal), normalized; `None` where that sum vanishes.
pub(crate) fn smooth_normals(positions: &[Vec3], triangles: &[[u32; 3]]) -> Vec<Option<Vec3>> {
    let mut sum = vec![DVec3::ZERO; positions.len()];
    for tri in triangles {
        let [a, b, c] = tri.map(|i| positions.get(i as usize).copied().unwrap_or(Vec3::ZERO));
        let n = area_normal(a, b, c);
        for &i in tri {
            if let Some(s) = sum.get_mut(i as usize) {
                *s += n;
            }
        }
    }
    sum.into_par_iter().map(unit).collect()
}

/// Triangles per piece of the parallel bounds: a size, so that the pieces, and the order in
/// which their bounds are combined, do not depend on the number of threads.
const BOUNDS_PIECE: usize = 1 << 14;

/// Bounds of all vertices, or `None` without any: pieces bounded on every thread, then combined
/// in order. `Vec3::min` is exact, so this is the serial fold's box.
pub(crate) fn bounds(positions: &[[Vec3; 3]]) -> Option<(Vec3, Vec3)> {
    let pieces: Vec<Option<(Vec3, Vec3)>> = positions
        .par_chunks(BOUNDS_PIECE)
        .map(|piece| {
            let mut it = piece.iter().flatten();
            let first = *it.next()?;
            Some(it.fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p))))
        })
        .collect();
    pieces.into_iter().flatten().reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
}

/// World bounds in f64 of the vertices under `aff`, or `None` when a transformed vertex is not
/// finite; pieces as in [`bounds`]. An empty slice gives the empty box (infinite bounds).
pub(crate) fn world_bounds(positions: &[[Vec3; 3]], aff: &Affine) -> Option<(DVec3, DVec3)> {
    let empty = (DVec3::INFINITY, DVec3::NEG_INFINITY);
    let pieces: Vec<Option<(DVec3, DVec3)>> = positions
        .par_chunks(BOUNDS_PIECE)
        .map(|piece| {
            piece.iter().flatten().try_fold(empty, |(lo, hi), &p| {
                let w = aff.m.transform_point3(p.as_dvec3());
                w.is_finite().then(|| (lo.min(w), hi.max(w)))
            })
        })
        .collect();
    pieces.into_iter().try_fold(empty, |(lo, hi), b| b.map(|(c, d)| (lo.min(c), hi.max(d))))
}

/// An affine transform of points, with its normal transform.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Affine {
    pub m: DMat4,
    /// The inverse transpose of the linear part, up to a positive factor: the cofactor matrix
    /// times the sign of the determinant. Unlike the inverse it exists for singular matrices too,
    /// where it still maps normals onto the normal of the flattened surface.
    normal: DMat3,
    /// The transform mirrors (negative determinant), so triangles must swap two vertices to keep
    /// their winding consistent with their normals.
    pub flips: bool,
}

impl Affine {
    pub fn new(m: DMat4) -> Self {
        let l = DMat3::from_mat4(m);
        let det = l.determinant();
        let cof = DMat3::from_cols(l.y_axis.cross(l.z_axis), l.z_axis.cross(l.x_axis), l.x_axis.cross(l.y_axis));
        let flips = det < 0.0;
        Self { m, normal: if flips { -cof } else { cof }, flips }
    }

    pub fn is_identity(&self) -> bool {
        self.m == DMat4::IDENTITY
    }

    pub fn point(&self, p: Vec3) -> Vec3 {
        self.m.transform_point3(p.as_dvec3()).as_vec3()
    }

    /// The transformed point relative to `origin`, computed in f64 and rounded once.
    pub fn point_from(&self, p: Vec3, origin: DVec3) -> Vec3 {
        (self.m.transform_point3(p.as_dvec3()) - origin).as_vec3()
    }

    /// The transformed unit normal, or `None` where the transform collapses it.
    pub fn normal(&self, n: Vec3) -> Option<Vec3> {
        unit(self.normal * n.as_dvec3())
    }
}

/// The local origin of a scene whose world bounds are `lo..hi`: its centre, rounded to a
/// multiple of the smallest power of two `g` not below its extent. Local coordinates then lie
/// within `g` of zero, so they keep the relative precision they would have at the world origin
/// whatever the distance; a scene whose centre lies within `g / 2` of the world origin keeps
/// origin zero (and its coordinates exactly as given).
pub fn local_origin(lo: DVec3, hi: DVec3) -> DVec3 {
    let extent = (hi - lo).max_element().max(f64::MIN_POSITIVE);
    let grid = extent.log2().ceil().exp2();
    let origin = ((lo + hi) * 0.5 / grid).round() * grid;
    // `+ 0.0` turns -0 into +0, so that a scene at the origin has an all-zero offset.
    if origin.is_finite() { origin + DVec3::ZERO } else { DVec3::ZERO }
}

/// Applies `aff` to triangles with their normals, in place, giving positions relative to
/// `origin`. Returns the index of the first triangle whose transformed position is not finite.
pub(crate) fn transform_triangles(
    positions: &mut [[Vec3; 3]],
    normals: &mut [[Vec3; 3]],
    aff: &Affine,
    origin: DVec3,
) -> Result<(), usize> {
    if aff.is_identity() && origin == DVec3::ZERO {
        return Ok(());
    }
    // In parallel; the first triangle (by index) that fails is reported, and what the others
    // became does not matter then, since the caller gives up the scene.
    let failed = positions.par_iter_mut().zip(normals.par_iter_mut()).position_first(|(p, n)| {
        let mut q = p.map(|v| aff.point_from(v, origin));
        if !q.iter().all(|v| v.is_finite()) {
            return true;
        }
        let flat = || face_normal(q[0], q[1], q[2]);
        let mut m = n.map(|v| aff.normal(v).unwrap_or_else(flat));
        if aff.flips {
            q.swap(1, 2);
            m.swap(1, 2);
        }
        *p = q;
        *n = m;
        false
    });
    failed.map_or(Ok(()), Err)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degenerate_triangles_get_a_unit_normal() {
        let p = Vec3::new(1.0, 2.0, 3.0);
        assert_eq!(face_normal(p, p, p), FALLBACK_NORMAL);
        let tiny = face_normal(Vec3::ZERO, Vec3::new(1e-30, 0.0, 0.0), Vec3::new(0.0, 1e-30, 0.0));
        assert!((tiny - Vec3::Z).length() < 1e-6);
        let huge = face_normal(Vec3::ZERO, Vec3::new(3e38, 0.0, 0.0), Vec3::new(0.0, 3e38, 0.0));
        assert!((huge - Vec3::Z).length() < 1e-6);
    }

    #[test]
    fn mirroring_keeps_normals_outward_and_flips_winding() {
        let aff = Affine::new(DMat4::from_scale(DVec3::new(-1.0, 1.0, 1.0)));
        let mut p = [[Vec3::ZERO, Vec3::X, Vec3::Y]];
        let mut n = [[Vec3::Z; 3]];
        transform_triangles(&mut p, &mut n, &aff, DVec3::ZERO).unwrap();
        assert_eq!(n[0], [Vec3::Z; 3]);
        assert_eq!(face_normal(p[0][0], p[0][1], p[0][2]), Vec3::Z);
    }

    #[test]
    fn non_uniform_scale_uses_the_inverse_transpose() {
        let aff = Affine::new(DMat4::from_scale(DVec3::new(1.0, 4.0, 1.0)));
        let n = aff.normal(Vec3::new(1.0, 1.0, 0.0).normalize()).unwrap();
        // A 45-degree slope stretched along y gets steeper, so its normal tilts towards x.
        assert!(n.x > 0.9 && n.y > 0.0 && (n.length() - 1.0).abs() < 1e-6);
    }
}
