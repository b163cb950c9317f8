//! The chart of one frame: FLIP mean against milliseconds per frame, both on log scales, one
//! marker per tracer, method and setting (labelled with the setting), and the Pareto front as a
//! dashed line. Written as SVG and PNG.

use super::report::Row;
use crate::output;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// FLIP means below this (0 for an image equal to the reference) are drawn at it, so that they
/// stay on a log scale.
pub const FLIP_FLOOR: f64 = 1e-5;

const SIZE: (u32, u32) = (1000, 640);

const COLOURS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(148, 103, 189),
    RGBColor(255, 127, 14),
    RGBColor(23, 190, 207),
];

/// Draws the chart of `rows` into `dir/stem.svg` and `dir/stem.png`. Returns both paths.
pub fn draw(dir: &Path, stem: &str, title: &str, rows: &[&Row], front: &[&Row]) -> Result<Vec<PathBuf>, String> {
    let svg_path = dir.join(format!("{stem}.svg"));
    let png_path = dir.join(format!("{stem}.png"));
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, SIZE).into_drawing_area();
        plot(&root, title, rows, front)?;
        root.present().map_err(|e| format!("cannot draw the chart {stem}: {e}"))?;
    }
    let mut pixels = vec![0u8; (SIZE.0 * SIZE.1 * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, SIZE).into_drawing_area();
        plot(&root, title, rows, front)?;
        root.present().map_err(|e| format!("cannot draw the chart {stem}: {e}"))?;
    }
    output::write_chart(&svg_path, &svg, &png_path, SIZE, &pixels).map_err(|e| e.to_string())?;
    Ok(vec![svg_path, png_path])
}

fn flip(r: &Row) -> f64 {
    r.image.flip_mean.max(FLIP_FLOOR)
}

fn plot<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    title: &str,
    rows: &[&Row],
    front: &[&Row],
) -> Result<(), String> {
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| format!("cannot draw the chart {title}: {e}");
    root.fill(&WHITE).map_err(err)?;
    let (mut t0, mut t1, mut f0, mut f1) = (f64::INFINITY, 0.0f64, f64::INFINITY, 0.0f64);
    for r in rows {
        t0 = t0.min(r.median_ms);
        t1 = t1.max(r.median_ms);
        f0 = f0.min(flip(r));
        f1 = f1.max(flip(r));
    }
    if rows.is_empty() || !(t0 > 0.0 && t1.is_finite()) {
        return Err(format!("the chart {title} has no point with a time above 0"));
    }
    let mut chart = ChartBuilder::on(root)
        .caption(format!("{title}: error against time per frame"), ("sans-serif", 24))
        .margin(16)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d((t0 / 1.6..t1 * 1.6).log_scale(), (f0 / 2.0..f1 * 2.0).log_scale())
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_labels(8)
        .y_labels(8)
        .x_desc("milliseconds per frame (median, log scale)")
        .y_desc(format!("FLIP mean against the reference (log; 0 drawn at {FLIP_FLOOR:e})"))
        .x_label_formatter(&|x| crate::bench::significant(*x))
        .y_label_formatter(&|y| format!("{y:.0e}"))
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 17))
        .draw()
        .map_err(err)?;
    let mut series: Vec<(String, bool)> = rows.iter().map(|r| (r.series(), r.gpu)).collect();
    series.sort();
    series.dedup();
    for (k, (name, gpu)) in series.iter().enumerate() {
        let colour = COLOURS[k % COLOURS.len()];
        let mut points: Vec<(f64, f64, String)> =
            rows.iter().filter(|r| r.series() == *name).map(|r| (r.median_ms, flip(r), r.setting.clone())).collect();
        points.sort_by(|a, b| a.0.total_cmp(&b.0));
        let style = colour.filled();
        let drawn = if *gpu {
            chart.draw_series(points.iter().map(|(x, y, _)| TriangleMarker::new((*x, *y), 7, style)))
        } else {
            chart.draw_series(points.iter().map(|(x, y, _)| Circle::new((*x, *y), 6, style)))
        };
        drawn
            .map_err(err)?
            .label(name.clone())
            .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 10, y + 5)], colour.filled()));
        chart
            .draw_series(points.iter().enumerate().map(|(i, (x, y, label))| {
                // Beside the marker, up and to the right, staggered over three heights so that the
                // labels of neighbouring markers do not overwrite each other.
                let dy = -16 - 13 * (i as i32 % 3);
                EmptyElement::at((*x, *y))
                    + Text::new(label.clone(), (6, dy), ("sans-serif", 13).into_font().color(&colour.mix(0.95)))
            }))
            .map_err(err)?;
    }
    let line: Vec<(f64, f64)> = front.iter().map(|r| (r.median_ms, flip(r))).collect();
    chart
        .draw_series(DashedLineSeries::new(line, 6, 4, BLACK.mix(0.6).stroke_width(2)))
        .map_err(err)?
        .label("Pareto front")
        .legend(|(x, y)| PathElement::new([(x, y), (x + 14, y)], BLACK.mix(0.6).stroke_width(2)));
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK.mix(0.4))
        .label_font(("sans-serif", 15))
        .draw()
        .map_err(err)?;
    Ok(())
}
