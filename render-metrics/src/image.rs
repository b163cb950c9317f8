//! Errors of an 8-bit image against its reference.

use crate::{MetricsError, check_sizes};
use render_spec::Image;

/// How far an image is from its reference.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ImageErrors {
    /// Mean of FLIP's per-pixel error map (0: identical, 1: as different as can be), at FLIP's
    /// default viewing distance (67 pixels per degree).
    pub flip_mean: f64,
    /// The 99th percentile of the same map (nearest rank): how bad the worst 1% of pixels are.
    pub flip_p99: f64,
    /// Peak signal-to-noise ratio in dB over the 8-bit channels; +inf for identical images.
    pub psnr: f64,
    /// Share of pixels with a channel off by more than 1/255.
    pub off_1: f64,
    /// Share of pixels with a channel off by more than 8/255.
    pub off_8: f64,
}

/// Compares `test` with `reference` (same size; both sRGB-encoded 8-bit, as the tracers write).
pub fn compare_images(reference: &Image, test: &Image) -> Result<ImageErrors, MetricsError> {
    let n = check_sizes(reference, test)?;
    let (mut off_1, mut off_8, mut squares) = (0usize, 0usize, 0u64);
    for (a, b) in reference.rgb.iter().zip(&test.rgb) {
        let worst = (0..3).map(|c| a[c].abs_diff(b[c])).max().unwrap_or(0);
        off_1 += usize::from(worst > 1);
        off_8 += usize::from(worst > 8);
        squares += (0..3).map(|c| u64::from(a[c].abs_diff(b[c])).pow(2)).sum::<u64>();
    }
    let mse = squares as f64 / (3 * n) as f64;
    let psnr = if squares == 0 { f64::INFINITY } else { 10.0 * (255.0f64 * 255.0 / mse).log10() };
    let map = flip_map(reference, test);
    Ok(ImageErrors {
        flip_mean: map.iter().map(|&e| f64::from(e)).sum::<f64>() / n as f64,
        flip_p99: percentile(map, 0.99),
        psnr,
        off_1: off_1 as f64 / n as f64,
        off_8: off_8 as f64 / n as f64,
    })
}

/// FLIP's error map of `test` against `reference`, one value per pixel in [0, 1].
pub fn flip_map(reference: &Image, test: &Image) -> Vec<f32> {
    let flat = |i: &Image| nv_flip::FlipImageRgb8::with_data(i.width, i.height, i.rgb.as_flattened());
    nv_flip::flip(flat(reference), flat(test), nv_flip::DEFAULT_PIXELS_PER_DEGREE).to_vec()
}

/// The `q`-quantile (0..=1) of `values` by nearest rank: the smallest value with at least a share
/// `q` of the values at or below it.
fn percentile(mut values: Vec<f32>, q: f64) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_by(f32::total_cmp);
    let rank = ((q * values.len() as f64).ceil() as usize).clamp(1, values.len());
    f64::from(values[rank - 1])
}

#[cfg(test)]
mod tests {
    use super::*;
    use render_spec::RayCounts;

    /// A smooth gradient with some structure, so that FLIP sees edges and flat regions.
    fn image(w: u32, h: u32) -> Image {
        let rgb = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                [(x * 255 / w) as u8, (y * 255 / h) as u8, if (x / 4 + y / 4) % 2 == 0 { 40 } else { 200 }]
            })
            .collect();
        Image { width: w, height: h, rgb, aov: None, rays: RayCounts::default() }
    }

    #[test]
    fn identical_images_have_no_error() {
        let a = image(32, 24);
        let e = compare_images(&a, &a.clone()).unwrap();
        assert_eq!(e, ImageErrors { flip_mean: 0.0, flip_p99: 0.0, psnr: f64::INFINITY, off_1: 0.0, off_8: 0.0 });
    }

    #[test]
    fn one_changed_pixel_gives_the_exact_shares_and_psnr() {
        let a = image(32, 24);
        let n = 32.0 * 24.0;
        // One pixel's red channel off by 9: off by more than 1 and more than 8.
        let mut b = a.clone();
        b.rgb[100][0] = a.rgb[100][0].wrapping_add(9);
        let e = compare_images(&a, &b).unwrap();
        assert_eq!((e.off_1, e.off_8), (1.0 / n, 1.0 / n));
        let mse = 81.0 / (3.0 * n);
        assert!((e.psnr - 10.0 * (255.0f64 * 255.0 / mse).log10()).abs() < 1e-9, "{}", e.psnr);
        assert!(e.flip_mean > 0.0 && e.flip_mean < 0.01, "{}", e.flip_mean);
        // Off by exactly 8 (and by exactly 1) is within the thresholds.
        let mut c = a.clone();
        c.rgb[330][1] = a.rgb[330][1] - 8;
        c.rgb[331][2] = a.rgb[331][2] + 1;
        let e = compare_images(&a, &c).unwrap();
        assert_eq!((e.off_1, e.off_8), (1.0 / n, 0.0));
    }

    #[test]
    fn flip_grows_with_the_difference_and_reaches_the_99th_percentile() {
        let a = image(64, 48);
        let mut small = a.clone();
        let mut large = a.clone();
        // 5% of the pixels (every 20th) changed: the 99th percentile sees them, the mean less so.
        for i in (0..small.rgb.len()).step_by(20) {
            small.rgb[i] = small.rgb[i].map(|c| c.saturating_add(16));
            large.rgb[i] = [255 - a.rgb[i][0], 255 - a.rgb[i][1], 255 - a.rgb[i][2]];
        }
        let (s, l) = (compare_images(&a, &small).unwrap(), compare_images(&a, &large).unwrap());
        assert!(0.0 < s.flip_mean && s.flip_mean < l.flip_mean, "{s:?} {l:?}");
        assert!(s.flip_p99 > s.flip_mean && l.flip_p99 > 0.5, "{s:?} {l:?}");
        assert!(l.psnr < s.psnr);
    }

    #[test]
    fn percentiles_take_the_nearest_rank() {
        let v: Vec<f32> = (1..=100).map(|i| i as f32).collect();
        assert_eq!(percentile(v.clone(), 0.99), 99.0);
        assert_eq!(percentile(v.clone(), 1.0), 100.0);
        assert_eq!(percentile(v, 0.0), 1.0);
        assert_eq!(percentile(vec![3.0], 0.99), 3.0);
    }

    #[test]
    fn mismatched_images_are_refused() {
        let e = compare_images(&image(4, 4), &image(4, 3)).unwrap_err();
        assert_eq!(e.to_string(), "the test image is 4x3 but its reference is 4x4");
        assert_eq!(compare_images(&image(0, 4), &image(0, 4)).unwrap_err(), MetricsError::Empty);
    }
}
