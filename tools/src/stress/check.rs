//! Every pixel's primary hit against the exact f64 reference (`tracer_cpu::reference`), with the
//! ambiguities that no f32 tracer can decide taken out: a ray within a hair of a triangle's edge
//! (silhouettes, where hitting or missing are both right), two triangles at the same distance
//! (ties, duplicates, coplanar overlaps) and hits at the ray's origin (a ray leaving a surface).

use super::{Case, Tally};
use bvh_format::{SceneFile, Triangle};
use glam::DVec3;
use render_spec::{Image, NO_TRIANGLE, Settings};
use tracer_cpu::reference::{Bvh, bvh::Ray64, intersect64};

/// Barycentric margin within which a ray counts as passing through an edge or vertex.
pub const EDGE: f64 = 1e-5;
/// Relative distance within which two hits are a tie.
pub const TIE: f64 = 1e-4;
/// Largest colour difference (of 255) from the expected image that is not a wrong pixel.
pub const COLOUR_TOLERANCE: u8 = 24;

/// The reference's answer for one pixel's primary ray.
#[derive(Clone, Copy, Debug)]
pub struct RefPixel {
    origin: DVec3,
    dir: DVec3,
    /// Closest hit: distance, stored triangle, distance to the triangle's boundary.
    hit: Option<(f64, u32, f64)>,
    /// Another triangle lies at the same distance (a shared edge or vertex, a duplicate): a miss
    /// there is a leak even on the boundary.
    shared: bool,
}

/// The plane hit and the smallest barycentric coordinate of triangle `tri` (negative outside),
/// in f64 on the stored vertices.
fn plane_hit(tri: &Triangle, o: DVec3, d: DVec3) -> Option<(f64, f64)> {
    let [a, b, c] = tri.vertices().map(|p| DVec3::from(p.map(f64::from)));
    let n = (b - a).cross(c - a);
    let den = n.dot(d);
    if den == 0.0 || n.length_squared() == 0.0 {
        return None;
    }
    let t = n.dot(a - o) / den;
    let p = o + d * t;
    let area = n.length_squared();
    let w = [(c - b).cross(p - b), (a - c).cross(p - c), (b - a).cross(p - a)].map(|e| e.dot(n) / area);
    Some((t, w[0].min(w[1]).min(w[2])))
}

/// The reference answers for every pixel of one frame; none for a frame without AOVs (too large
/// to hold its hits: only its colours are compared).
///
/// The closest hit is brute force's, found by the f64 walk of the file's tree
/// (`tracer_cpu::reference::Bvh`, tested equal to brute force), so that scenes of millions of
/// triangles are checked too. Whether another triangle lies at the same distance only matters
/// for a hit on its triangle's boundary, and only there is every triangle tried.
pub fn reference(scene: &SceneFile, shot: &Settings, near: f64) -> Vec<RefPixel> {
    use rayon::prelude::*;
    if !shot.aovs {
        return Vec::new();
    }
    let bvh = Bvh::new(scene).expect("the sweep's scenes hold a tree");
    let tris = bvh.triangles();
    let frame = shot.frame().expect("the sweep's cameras are valid");
    let o = frame.eye.as_dvec3();
    (0..shot.height * shot.width)
        .into_par_iter()
        .map_init(Vec::new, |stack, i| {
            let d = frame.direction(i % shot.width, i / shot.width).as_dvec3();
            let best = bvh.closest(&Ray64::new(o, d), near, stack, &mut Default::default());
            let hit = best.map(|h| (h.t, h.tri, plane_hit(&tris[h.tri as usize], o, d).map_or(0.0, |p| p.1)));
            let shared = hit.is_some_and(|(t, k, edge)| {
                edge <= EDGE
                    && tris.iter().enumerate().any(|(j, tri)| {
                        j as u32 != k
                            && intersect64(tri, o, d, 0.0).is_some_and(|(tj, _, _)| (tj - t).abs() <= TIE * t.abs())
                    })
            });
            RefPixel { origin: o, dir: d, hit, shared }
        })
        .collect()
}

/// Adds one rendered frame's pixels to `tally`.
pub fn tally_image(
    case: &Case,
    reference: &[RefPixel],
    shot: &Settings,
    image: &Image,
    expected: Option<&Image>,
    tally: &mut Tally,
) {
    let tris = case.scene.leaf_triangles();
    let mut stored = vec![0u32; case.scene.input_index.len()];
    for (s, &i) in case.scene.input_index.iter().enumerate() {
        stored[i as usize] = s as u32;
    }
    if !shot.aovs {
        // Colours only (a frame too large to hold its hits).
        if let Some(e) = expected {
            let off: Vec<usize> =
                (0..e.rgb.len().min(image.rgb.len())).filter(|&i| off_colour(&e.rgb[i], &image.rgb[i])).collect();
            // Without hits to compare, a pixel whose ray meets a triangle's boundary is a tie
            // either tracer may break its own way (a GPU that fuses multiply-adds breaks some
            // differently, and a bumpy surface's two sides of an edge differ in colour), as it is
            // for the pixels with AOVs below; every other differing pixel is wrong.
            let off = off.len() as u64 - on_boundary(case, shot, &off) as u64;
            tally.image += off;
            tally.failed += off;
        }
        if image.rgb.len() as u64 != shot.width as u64 * shot.height as u64 {
            tally.crash = Some(format!("the frame came back with {} pixels", image.rgb.len()));
        }
        tally.pixels += shot.width as u64 * shot.height as u64;
        return;
    }
    let Some(aov) = image.aov.as_ref() else {
        tally.crash = Some("the frame came back without AOVs".to_owned());
        return;
    };
    for (i, r) in reference.iter().enumerate() {
        let prim = aov.prim[i];
        let got = (prim != NO_TRIANGLE).then(|| stored.get(prim as usize).copied());
        let t = aov.t[i];
        let non_finite = got.is_some() && (!t.is_finite() || aov.normal[i].iter().any(|v| !v.is_finite()));
        let (mut wrong, mut leak) = (false, false);
        match (r.hit, got) {
            (_, Some(None)) => wrong = true,
            (None, None) => {}
            (Some((_, k, _)), Some(Some(g))) if k == g => {}
            (Some((rt, _, edge)), None) => leak = rt > case.near && (edge > EDGE || r.shared),
            (None, Some(Some(g))) => {
                wrong = plane_hit(&tris[g as usize], r.origin, r.dir).is_none_or(|(gt, m)| m < -EDGE && gt > case.near)
            }
            (Some((rt, _, edge)), Some(Some(g))) => {
                let tie = (f64::from(t) - rt).abs() <= TIE * rt.abs().max(f64::from(t).abs());
                let ambiguous = edge <= EDGE
                    || plane_hit(&tris[g as usize], r.origin, r.dir).is_some_and(|(_, m)| m.abs() <= EDGE)
                    || rt <= case.near
                    || f64::from(t) <= case.near;
                wrong = !tie && !ambiguous;
            }
        }
        let off_colour = expected.is_some_and(|e| off_colour(&e.rgb[i], &image.rgb[i]));
        tally.wrong += wrong as u64;
        tally.leaks += leak as u64;
        tally.non_finite += non_finite as u64;
        tally.image += off_colour as u64;
        tally.failed += (wrong || leak || non_finite || off_colour) as u64;
    }
    tally.pixels += (shot.width * shot.height) as u64;
}

/// How many of `pixels` of `shot` have a primary ray that the f64 walk finds within [`EDGE`] of
/// its closest triangle's boundary (or at a hit closer than the case's `near`).
fn on_boundary(case: &Case, shot: &Settings, pixels: &[usize]) -> usize {
    if pixels.is_empty() {
        return 0;
    }
    let (Ok(bvh), Ok(frame)) = (Bvh::new(&case.scene), shot.frame()) else {
        return 0;
    };
    let tris = bvh.triangles();
    let o = frame.eye.as_dvec3();
    let mut stack = Vec::new();
    pixels
        .iter()
        .filter(|&&i| {
            let d = frame.direction(i as u32 % shot.width, i as u32 / shot.width).as_dvec3();
            bvh.closest(&Ray64::new(o, d), case.near, &mut stack, &mut Default::default()).is_some_and(|h| {
                h.t <= case.near || plane_hit(&tris[h.tri as usize], o, d).is_some_and(|(_, m)| m <= EDGE)
            })
        })
        .count()
}

/// Whether two pixels differ by more than [`COLOUR_TOLERANCE`] in a channel.
fn off_colour(a: &[u8; 3], b: &[u8; 3]) -> bool {
    a.iter().zip(b).any(|(a, b)| a.abs_diff(*b) > COLOUR_TOLERANCE)
}
