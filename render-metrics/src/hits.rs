//! Errors of a set of primary rays against the reference's, from the per-pixel outputs (AOVs) of
//! two renders of the same frame with one sample per pixel: each pixel's `prim` (input triangle
//! index, [`NO_TRIANGLE`] on a miss) and `t` (distance) name one ray's closest hit.

use crate::{MetricsError, check_sizes};
use render_spec::{Aovs, Image, NO_TRIANGLE};

/// Relative difference of distances below which two different triangles count as the same hit:
/// a ray through an edge or vertex shared by both, where either answer is right.
pub const TIE: f32 = 1e-4;

/// How a set of closest hits differs from the reference's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct HitErrors {
    pub rays: u64,
    /// Rays whose closest hit is another triangle than the reference's, or a hit where the
    /// reference misses or the other way round, ties excluded. Includes the leaks.
    pub disagree: u64,
    /// Rays that hit another triangle than the reference at the same distance (within [`TIE`]):
    /// a shared edge or vertex, where either triangle is right.
    pub ties: u64,
    /// Rays that go past a surface the reference ray stops at: they miss where the reference hits,
    /// or hit another triangle farther away (through the gap of a shared edge into the back of a
    /// closed mesh, or past a silhouette the exact ray grazes).
    pub leaks: u64,
}

impl HitErrors {
    pub fn disagree_share(&self) -> f64 {
        self.disagree as f64 / self.rays.max(1) as f64
    }
}

/// Compares the closest hits of `test` with those of `reference` (same frame, same rays).
pub fn compare_hits(reference: &Image, test: &Image) -> Result<HitErrors, MetricsError> {
    let (r, t) = aovs(reference, test)?;
    let mut e = HitErrors { rays: r.prim.len() as u64, ..Default::default() };
    for i in 0..r.prim.len() {
        let (rp, tp) = (r.prim[i], t.prim[i]);
        if rp == tp {
            continue;
        }
        let (rt, tt) = (r.t[i], t.t[i]);
        let both_hit = rp != NO_TRIANGLE && tp != NO_TRIANGLE;
        if both_hit && (rt - tt).abs() <= TIE * rt.abs().max(tt.abs()) {
            e.ties += 1;
            continue;
        }
        e.disagree += 1;
        if rp != NO_TRIANGLE && (tp == NO_TRIANGLE || tt > rt) {
            e.leaks += 1;
        }
    }
    Ok(e)
}

/// Pixels whose primary ray hit the reference's triangle but whose shading moved by more than
/// 8/255: what wrong shadow rays do to an image (with one sample per pixel in Whitted mode).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ShadingShifts {
    /// Pixels whose primary hit agrees with the reference's.
    pub agreeing: u64,
    /// Of those, pixels darker than the reference by more than 8/255 in some channel and lighter
    /// in none by more than 1/255: a light the reference sees is blocked, as by acne (a shadow ray
    /// stopped by the surface it leaves).
    pub darker: u64,
    /// Pixels lighter by more than 8/255 and darker in none by more than 1/255: a shadow the
    /// reference casts is missed (a contact shadow skipped by too large an offset).
    pub lighter: u64,
}

impl ShadingShifts {
    pub fn darker_share(&self) -> f64 {
        self.darker as f64 / self.agreeing.max(1) as f64
    }
    pub fn lighter_share(&self) -> f64 {
        self.lighter as f64 / self.agreeing.max(1) as f64
    }
}

/// Counts [`ShadingShifts`] of `test` against `reference` (same frame, both with AOVs).
pub fn shading_shifts(reference: &Image, test: &Image) -> Result<ShadingShifts, MetricsError> {
    let (r, t) = aovs(reference, test)?;
    let mut s = ShadingShifts::default();
    for i in 0..r.prim.len() {
        if r.prim[i] != t.prim[i] || r.prim[i] == NO_TRIANGLE {
            continue;
        }
        s.agreeing += 1;
        let (a, b) = (reference.rgb[i], test.rgb[i]);
        let down = (0..3).map(|c| i32::from(a[c]) - i32::from(b[c])).max().unwrap_or(0);
        let up = (0..3).map(|c| i32::from(b[c]) - i32::from(a[c])).max().unwrap_or(0);
        s.darker += u64::from(down > 8 && up <= 1);
        s.lighter += u64::from(up > 8 && down <= 1);
    }
    Ok(s)
}

fn aovs<'a>(reference: &'a Image, test: &'a Image) -> Result<(&'a Aovs, &'a Aovs), MetricsError> {
    let n = check_sizes(reference, test)?;
    let r = reference.aov.as_ref().ok_or(MetricsError::NoAovs("reference"))?;
    let t = test.aov.as_ref().ok_or(MetricsError::NoAovs("test"))?;
    if [r.prim.len(), r.t.len(), t.prim.len(), t.t.len()].iter().any(|&l| l != n) {
        return Err(MetricsError::Inconsistent);
    }
    Ok((r, t))
}

#[cfg(test)]
mod tests {
    use super::*;
    use render_spec::RayCounts;

    fn frame(prim: &[u32], t: &[f32], rgb: &[[u8; 3]]) -> Image {
        let aov = Aovs { t: t.to_vec(), prim: prim.to_vec(), ..Default::default() };
        Image { width: prim.len() as u32, height: 1, rgb: rgb.to_vec(), aov: Some(aov), rays: RayCounts::default() }
    }

    const M: u32 = NO_TRIANGLE;
    const INF: f32 = f32::INFINITY;

    #[test]
    fn hits_are_sorted_into_agreement_ties_disagreement_and_leaks() {
        let grey = [[100u8; 3]; 7];
        // Pixels: same hit; a tie at a shared edge; a miss where the reference hits (leak); a
        // farther triangle (leak, through the surface); a nearer triangle (disagreement only); a
        // hit where the reference misses; both miss.
        let reference = frame(&[1, 2, 3, 4, 5, M, M], &[1.0, 2.0, 3.0, 4.0, 5.0, INF, INF], &grey);
        let test = frame(&[1, 7, M, 8, 9, 6, M], &[1.0, 2.00001, INF, 4.5, 4.0, 9.0, INF], &grey);
        let e = compare_hits(&reference, &test).unwrap();
        assert_eq!(e, HitErrors { rays: 7, disagree: 4, ties: 1, leaks: 2 });
        assert!((e.disagree_share() - 4.0 / 7.0).abs() < 1e-12);
        assert_eq!(compare_hits(&reference, &reference).unwrap(), HitErrors { rays: 7, ..Default::default() });
    }

    #[test]
    fn shading_shifts_count_darker_and_lighter_pixels_where_the_hit_agrees() {
        let prim = [1, 1, 1, 1, 2, M];
        let t = [1.0; 6];
        let reference = frame(&prim, &t, &[[100; 3]; 6]);
        // darker by 9 (acne); lighter by 9 (lost shadow); darker by exactly 8 (neither); mixed
        // (neither); a different triangle (not counted); a miss (not counted).
        let rgb = [[91, 100, 100], [100, 109, 100], [92, 92, 92], [80, 120, 100], [0, 0, 0], [0, 0, 0]];
        let mut test_prim = prim;
        test_prim[4] = 3;
        let test = frame(&test_prim, &t, &rgb);
        let s = shading_shifts(&reference, &test).unwrap();
        assert_eq!(s, ShadingShifts { agreeing: 4, darker: 1, lighter: 1 });
        assert_eq!((s.darker_share(), s.lighter_share()), (0.25, 0.25));
    }

    #[test]
    fn renders_without_aovs_are_refused() {
        let mut a = frame(&[1], &[1.0], &[[0; 3]]);
        let b = a.clone();
        a.aov = None;
        assert_eq!(compare_hits(&a, &b).unwrap_err(), MetricsError::NoAovs("reference"));
        assert_eq!(
            shading_shifts(&b, &a).unwrap_err().to_string(),
            "the test render has no per-pixel outputs (render it with AOVs)"
        );
    }
}
