//! docs/stability.md: a table per axis and one chart of failure rates, one line per method.

use super::{Method, Row, Tally, line_name};
use plotters::coord::Shift;
use plotters::prelude::*;
use render_spec::Intersect;
use std::fmt::Write;
use std::path::Path;

/// One table cell: "ok", the failure counts, or what stopped the method.
pub fn cell(t: &Tally) -> String {
    if let Some(c) = &t.crash {
        return format!("**CRASH** ({})", c.lines().next().unwrap_or(""));
    }
    if t.hang {
        return "**HANG**".to_owned();
    }
    if let Some(f) = &t.fault {
        return format!("**FAULT** ({f})");
    }
    if t.refusal.is_some() {
        return "refused".to_owned();
    }
    if t.failed == 0 {
        return "ok".to_owned();
    }
    let mut parts = Vec::new();
    for (n, what) in [(t.wrong, "wrong"), (t.leaks, "leak"), (t.non_finite, "NaN/inf"), (t.image, "image")] {
        if n > 0 {
            parts.push(format!("{n} {what}"));
        }
    }
    format!("**{:.2}%** ({})", 100.0 * t.failed as f64 / t.pixels.max(1) as f64, parts.join(", "))
}

/// The lines (method and triangle test) in the order they first ran.
fn lines(rows: &[Row]) -> Vec<(Method, Intersect)> {
    let mut m: Vec<(Method, Intersect)> = Vec::new();
    for r in rows {
        if !m.contains(&(r.method, r.intersect)) {
            m.push((r.method, r.intersect));
        }
    }
    m
}

fn row<'a>(rows: &'a [Row], axis: &str, label: &str, line: (Method, Intersect)) -> Option<&'a Row> {
    rows.iter().find(|r| r.axis == axis && r.label == label && (r.method, r.intersect) == line)
}

fn points<'a>(rows: &'a [Row], axis: &str) -> Vec<(f64, &'a str)> {
    let mut p: Vec<(f64, &str)> = Vec::new();
    for r in rows.iter().filter(|r| r.axis == axis) {
        if !p.iter().any(|q| q.1 == r.label) {
            p.push((r.x, &r.label));
        }
    }
    p
}

/// The tables and the list of refusals, as Markdown.
pub fn markdown(rows: &[Row], axes: &[&str]) -> String {
    let all = lines(rows);
    let mut s = String::new();
    for axis in axes {
        let pts = points(rows, axis);
        if pts.is_empty() {
            continue;
        }
        // The lines that ran on this axis (Möller-Trumbore only where it can differ).
        let ms: Vec<_> = all
            .iter()
            .copied()
            .filter(|l| rows.iter().any(|r| r.axis == *axis && (r.method, r.intersect) == *l))
            .collect();
        let _ = writeln!(s, "### {axis}\n");
        let _ = writeln!(s, "| point | {} |", ms.iter().map(|&(m, i)| line_name(m, i)).collect::<Vec<_>>().join(" | "));
        let _ = writeln!(s, "|---|{}", "---|".repeat(ms.len()));
        for (_, label) in &pts {
            let cells: Vec<String> =
                ms.iter().map(|&l| row(rows, axis, label, l).map_or("-".to_owned(), |r| cell(&r.tally))).collect();
            let _ = writeln!(s, "| {label} | {} |", cells.join(" | "));
        }
        s.push('\n');
    }
    let mut refusals: Vec<(String, String)> = Vec::new();
    for r in rows {
        if let Some(msg) = &r.tally.refusal {
            let key = (format!("{} {}", r.axis, r.label), msg.clone());
            if !refusals.iter().any(|(_, m)| m == msg) {
                refusals.push(key);
            }
        }
    }
    if !refusals.is_empty() {
        let _ = writeln!(s, "### Refusals (limits, each stated before the first frame)\n");
        for (at, msg) in refusals {
            let _ = writeln!(s, "- {at}: {msg}");
        }
        s.push('\n');
    }
    s
}

/// `text` with its section "## `title`" (up to the next "## " heading, or the end) replaced by
/// `body`, or `body` appended where there is none: everything else, hand-written or another run's
/// section, is kept.
pub fn splice_section(text: &str, title: &str, body: &str) -> String {
    let heading = format!("## {title}\n");
    let start = if text.starts_with(&heading) { Some(0) } else { text.find(&format!("\n{heading}")).map(|i| i + 1) };
    match start {
        Some(start) => {
            let end = text[start + 1..].find("\n## ").map_or(text.len(), |i| start + 1 + i + 1);
            format!("{}{body}{}", &text[..start], &text[end..])
        }
        None if text.is_empty() || text.ends_with("\n\n") => format!("{text}{body}"),
        None if text.ends_with('\n') => format!("{text}\n{body}"),
        None => format!("{text}\n\n{body}"),
    }
}

/// Writes the chart as `stem.svg` and `stem.png` (drawn in memory, each file replaced only when
/// complete).
pub fn charts(rows: &[Row], axes: &[&str], stem: &Path) -> Result<(), String> {
    let axes: Vec<&str> = axes.iter().copied().filter(|a| !points(rows, a).is_empty()).collect();
    let cols = 3;
    let size = (1500, 360 * axes.len().div_ceil(cols) as u32);
    let mut svg = String::new();
    draw(rows, &axes, cols, SVGBackend::with_string(&mut svg, size).into_drawing_area())?;
    let mut pixels = vec![0u8; (size.0 * size.1 * 3) as usize];
    draw(rows, &axes, cols, BitMapBackend::with_buffer(&mut pixels, size).into_drawing_area())?;
    crate::output::write_chart(&stem.with_extension("svg"), &svg, &stem.with_extension("png"), size, &pixels)
        .map_err(|e| e.to_string())
}

fn draw<DB: DrawingBackend>(
    rows: &[Row],
    axes: &[&str],
    cols: usize,
    root: DrawingArea<DB, Shift>,
) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let ms = lines(rows);
    let panels = root.split_evenly((axes.len().div_ceil(cols), cols));
    for (panel, axis) in panels.iter().zip(axes) {
        let pts = points(rows, axis);
        let n = pts.len();
        let mut chart = ChartBuilder::on(panel)
            .caption(*axis, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(28)
            .y_label_area_size(48)
            .build_cartesian_2d(-0.3f64..(n as f64 - 0.7), -2.0f64..102.0)
            .map_err(err)?;
        let labels: Vec<String> = pts.iter().map(|p| p.1.to_owned()).collect();
        chart
            .configure_mesh()
            .x_labels(n)
            .x_label_formatter(&|x| {
                let i = x.round();
                if (x - i).abs() < 1e-6 && i >= 0.0 {
                    labels.get(i as usize).cloned().unwrap_or_default()
                } else {
                    String::new()
                }
            })
            .y_desc("failed pixels %")
            .label_style(("sans-serif", 12))
            .draw()
            .map_err(err)?;
        for (k, &line) in ms.iter().enumerate() {
            let colour = Palette99::pick(k).to_rgba();
            let series: Vec<(f64, f64)> = pts
                .iter()
                .enumerate()
                .filter_map(|(i, p)| row(rows, axis, p.1, line)?.tally.failure_rate().map(|f| (i as f64, 100.0 * f)))
                .collect();
            if series.is_empty() {
                continue;
            }
            chart
                .draw_series(LineSeries::new(series.clone(), colour.stroke_width(2)))
                .map_err(err)?
                .label(line_name(line.0, line.1))
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2)));
            chart
                .draw_series(
                    series.iter().map(|&(x, y)| Circle::new((x, y), 3 + (ms.len() - k) as i32 / 2, colour.filled())),
                )
                .map_err(err)?;
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .label_font(("sans-serif", 11))
            .position(SeriesLabelPosition::UpperLeft)
            .draw()
            .map_err(err)?;
    }
    root.present().map_err(err)
}

#[cfg(test)]
mod tests {
    use super::splice_section;

    #[test]
    fn a_section_is_replaced_up_to_the_next_and_the_rest_kept() {
        let doc = "# Title\n\ntext\n\n## Results\n\nold\n\n### axis\n\n| a |\n\n## Results: size\n\nsize\n";
        let new = splice_section(doc, "Results", "## Results\n\nnew\n\n");
        assert_eq!(new, "# Title\n\ntext\n\n## Results\n\nnew\n\n## Results: size\n\nsize\n");
        let size = splice_section(&new, "Results: size", "## Results: size\n\nbig\n");
        assert_eq!(size, "# Title\n\ntext\n\n## Results\n\nnew\n\n## Results: size\n\nbig\n");
        // A heading that only starts like the title is another section.
        assert_eq!(
            splice_section("## Results: size\n\nx\n", "Results", "## Results\n"),
            "## Results: size\n\nx\n\n## Results\n"
        );
        assert_eq!(splice_section("", "Results", "## Results\n"), "## Results\n");
        assert_eq!(splice_section("## Results\nold", "Results", "## Results\nnew\n"), "## Results\nnew\n");
    }
}
