//! A chart of rays per second from `trace-cpu bench` and `trace-vk bench` CSV files: one panel per
//! scene, one group of bars per setting (mode, and camera and size where a scene has several), one
//! bar per tracer and method (and thread count or device, where one tracer ran on several), on a
//! logarithmic axis so that CPU and GPU rates share it.
//!
//! With `--ray-types` a bar is one kind of ray instead of one mode: a mode's frame minus the cast
//! frame of the same scene, shot, size and method leaves the time of its extra rays, so the cast row
//! gives the primary rate and, say, the ao8 row the rate of its AO rays alone (rays beyond the
//! primary ones over the time beyond the cast frame). Modes without a cast row beside them are left
//! out with a warning.
//!
//! A Markdown file written by the ray report (`tracer-cpu/examples/ray_report.rs`) is read as well:
//! its throughput table becomes one group of bars per kind of ray and one bar per tracer (ours
//! and Embree's), at the thread count `--threads` names (by default the largest in the file).
//!
//! Files that repeat one measurement (the rounds of `tools/scripts/h100-ray-ab.sh`, say) make one
//! bar per setting at the median run's rate, with a whisker from the slowest run to the fastest,
//! and the panels name the number of runs. Rows are runs of one measurement when they agree in
//! every column but the times; files with different triangle tests (the CSV's `intersect`) get
//! bars of their own.
//!
//! ```text
//! cargo run --release -p tools --example bench_chart -- CSV|ray-report.md... [--ray-types] [--threads N]
//!     [-o chart.svg|chart.png]
//! ```

use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::PathBuf;
use tools::bench::{Repeated, Row, merge_repeats, read_csv, read_ray_report, significant};

fn main() {
    let mut csvs = Vec::new();
    let mut out = PathBuf::from("bench-chart.svg");
    let mut ray_types = false;
    let mut threads = None;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "-o" | "--output" => out = args.next().map(PathBuf::from).unwrap_or_else(|| fail("-o needs a file name")),
            "--ray-types" => ray_types = true,
            "--threads" => {
                threads = Some(
                    args.next()
                        .and_then(|n| n.parse::<u32>().ok())
                        .unwrap_or_else(|| fail("--threads needs a whole number")),
                )
            }
            "-h" | "--help" => {
                println!(
                    "bench_chart CSV|ray-report.md... [--ray-types] [--threads N] [-o chart.svg|chart.png]: Mrays/s \
                     per scene, setting (or kind of ray), tracer and method"
                );
                return;
            }
            _ => csvs.push(PathBuf::from(a)),
        }
    }
    if csvs.is_empty() {
        fail("give at least one CSV written by trace-cpu bench or trace-vk bench, or a ray report's .md");
    }
    let mut rows = Vec::new();
    for c in &csvs {
        let read = if c.extension().is_some_and(|e| e == "md") { read_ray_report(c, threads) } else { read_csv(c) };
        rows.extend(read.unwrap_or_else(|e| fail(&e)));
    }
    // Runs with different triangle tests (`bench --intersect`) are different measurements: where
    // the files hold several, each method's bars name theirs.
    if distinct(rows.iter().map(|r| r.intersect.clone())).len() > 1 {
        for r in rows.iter_mut().filter(|r| !r.intersect.is_empty()) {
            r.method = format!("{} ({})", r.method, r.intersect);
        }
    }
    let mut rows = merge_repeats(&rows);
    if ray_types {
        // The kinds of ray from the runs' medians; their spread is not carried over.
        let medians: Vec<Row> = rows.into_iter().map(|m| m.row).collect();
        rows = by_ray_type(&medians)
            .into_iter()
            .map(|row| Repeated { runs: 1, slowest: row.mrays(), fastest: row.mrays(), row })
            .collect();
    }
    if rows.is_empty() {
        fail("the CSV files hold no rows");
    }
    let scenes = distinct(rows.iter().map(|r| r.row.scene.clone()));
    let size = (1100, 380 * scenes.len() as u32);
    let drawn = match out.extension().and_then(|e| e.to_str()) {
        Some("svg") => draw(&rows, &scenes, SVGBackend::new(&out, size).into_drawing_area()),
        Some("png") => draw(&rows, &scenes, BitMapBackend::new(&out, size).into_drawing_area()),
        _ => fail("the chart can be written as .svg or .png; name the file accordingly"),
    };
    drawn.unwrap_or_else(|e| fail(&format!("cannot draw {}: {e}", out.display())));
    println!("{} rows of {} -> {}", rows.len(), names(&csvs), out.display());
}

fn fail(msg: &str) -> ! {
    eprintln!("error: {msg}");
    std::process::exit(1)
}

/// One row per kind of ray: the cast row as "primary", every other mode as the rays it adds to the
/// cast frame of the same scene, shot, size, tracer, method and device over the time it adds.
fn by_ray_type(rows: &[Row]) -> Vec<Row> {
    const KINDS: [&str; 5] = ["primary", "shadow", "secondary", "AO", "diffuse"];
    let key = |r: &Row| {
        (r.scene.clone(), r.camera.clone(), r.width, r.height, r.tracer.clone(), r.method.clone(), r.device.clone())
    };
    let mut out = Vec::new();
    for r in rows {
        let Some(cast) = rows.iter().find(|c| c.mode == "cast" && key(c) == key(r)) else {
            eprintln!("warning: no cast row beside {} {} {} {}: left out", r.scene, r.mode, r.tracer, r.method);
            continue;
        };
        if r.mode == "cast" {
            out.push(Row { mode: "primary".into(), ..r.clone() });
            continue;
        }
        let extra: Vec<u64> = r.rays.iter().zip(&cast.rays).map(|(a, b)| a.saturating_sub(*b)).collect();
        let kinds: Vec<&str> = KINDS.iter().zip(&extra).filter(|(_, n)| **n > 0).map(|(k, _)| *k).collect();
        let ms = r.median_ms - cast.median_ms;
        if kinds.is_empty() || ms <= 0.0 {
            eprintln!(
                "warning: {} {} {} {} adds no rays or no time to the cast frame: left out",
                r.scene, r.mode, r.tracer, r.method
            );
            continue;
        }
        let mut rays = [0; 5];
        rays.copy_from_slice(&extra);
        out.push(Row {
            mode: if kinds.join("+").eq_ignore_ascii_case(&r.mode) {
                r.mode.clone()
            } else {
                format!("{} ({})", kinds.join("+"), r.mode)
            },
            median_ms: ms,
            min_ms: r.min_ms - cast.min_ms,
            rays,
            ..r.clone()
        });
    }
    out
}

fn names(paths: &[PathBuf]) -> String {
    paths.iter().map(|p| p.display().to_string()).collect::<Vec<_>>().join(", ")
}

/// The values in order of first appearance, once each.
fn distinct(items: impl Iterator<Item = String>) -> Vec<String> {
    let mut v: Vec<String> = Vec::new();
    for i in items {
        if !v.contains(&i) {
            v.push(i);
        }
    }
    v
}

/// What a bar stands for: tracer and method, and the device's last words ("16 threads", the GPU's
/// name) where one tracer's rows come from several devices. Ordered by tracer, then method, so
/// that one method's bars on several devices stand side by side.
fn series_of(rows: &[Row]) -> Vec<(String, String, String)> {
    let tracers = distinct(rows.iter().map(|r| r.tracer.clone()));
    let methods = distinct(rows.iter().map(|r| r.method.clone()));
    let mut series: Vec<(String, String, String)> = Vec::new();
    for r in rows {
        let s = (r.tracer.clone(), r.method.clone(), r.device.clone());
        if !series.contains(&s) {
            series.push(s);
        }
    }
    let rank =
        |s: &(String, String, String)| (tracers.iter().position(|t| *t == s.0), methods.iter().position(|m| *m == s.1));
    series.sort_by_key(rank);
    series
}

fn label(series: &[(String, String, String)], s: &(String, String, String)) -> String {
    let devices = distinct(series.iter().filter(|o| o.0 == s.0).map(|o| o.2.clone()));
    if devices.len() > 1 {
        let short = s.2.rsplit(';').next().unwrap_or(&s.2).trim();
        format!("{} {}, {short}", s.0, s.1)
    } else {
        format!("{} {}", s.0, s.1)
    }
}

fn setting(r: &Row, several: bool) -> String {
    if several { format!("{} {}x{} {}", r.camera, r.width, r.height, r.mode) } else { r.mode.clone() }
}

fn draw<DB: DrawingBackend>(rows: &[Repeated], scenes: &[String], root: DrawingArea<DB, Shift>) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let series = series_of(&rows.iter().map(|r| r.row.clone()).collect::<Vec<_>>());
    let colour = |i: usize| Palette99::pick(i).to_rgba();
    for (panel, scene) in root.split_evenly((scenes.len(), 1)).iter().zip(scenes) {
        let repeated: Vec<&Repeated> = rows.iter().filter(|r| &r.row.scene == scene).collect();
        let mine: Vec<&Row> = repeated.iter().map(|r| &r.row).collect();
        let (fewest, runs) = repeated.iter().fold((usize::MAX, 1), |(lo, hi), r| (lo.min(r.runs), hi.max(r.runs)));
        let runs_said = if fewest < runs { format!("{fewest} to {runs}") } else { runs.to_string() };
        let several = distinct(mine.iter().map(|r| format!("{} {}x{}", r.camera, r.width, r.height))).len() > 1;
        let settings = distinct(mine.iter().map(|r| setting(r, several)));
        let present: Vec<usize> = (0..series.len())
            .filter(|&i| {
                mine.iter().any(|r| (&r.tracer, &r.method, &r.device) == (&series[i].0, &series[i].1, &series[i].2))
            })
            .collect();
        // Each bar is a segment of its own; a setting's group is followed by one empty segment.
        let slots = present.len() + 1;
        let n = settings.len() * slots;
        let rates: Vec<f64> =
            repeated.iter().flat_map(|r| [r.slowest, r.fastest]).filter(|x| x.is_finite() && *x > 0.0).collect();
        let (lo, hi) = rates.iter().fold((f64::INFINITY, 0.0f64), |(l, h), &x| (l.min(x), h.max(x)));
        // Headroom above the tallest bar for the legend: on the logarithmic axis a third of the
        // panel, whether the rates span 2x (one tracer's methods) or 1000x (CPU beside GPU).
        let (lo, hi) = if rates.is_empty() {
            (0.1, 10.0)
        } else {
            let lo = lo / 1.5;
            (lo, hi * (hi / lo).sqrt().max(2.0))
        };
        let triangles = mine.first().map_or(0, |r| r.triangles);
        let mut chart = ChartBuilder::on(panel)
            .caption(
                if runs > 1 {
                    format!("{scene} ({triangles} triangles): median of {runs_said} runs, whiskers slowest to fastest")
                } else {
                    format!("{scene} ({triangles} triangles)")
                },
                ("sans-serif", 20),
            )
            .margin(10)
            .x_label_area_size(30)
            .y_label_area_size(60)
            .build_cartesian_2d((0..n).into_segmented(), (lo..hi).log_scale())
            .map_err(err)?;
        let middle = present.len() / 2;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_label_style(("sans-serif", 14))
            .x_labels(n + 1)
            .x_label_formatter(&|v| match v {
                SegmentValue::CenterOf(i) if i % slots == middle => settings[i / slots].clone(),
                _ => String::new(),
            })
            .y_desc("Mrays/s")
            .y_label_formatter(&|y| significant(*y))
            .draw()
            .map_err(err)?;
        for (slot, &si) in present.iter().enumerate() {
            let s = &series[si];
            let bars: Vec<Rectangle<(SegmentValue<usize>, f64)>> = mine
                .iter()
                .filter(|r| (&r.tracer, &r.method, &r.device) == (&s.0, &s.1, &s.2) && r.mrays() > 0.0)
                .filter_map(|r| {
                    let g = settings.iter().position(|x| *x == setting(r, several))?;
                    let x = g * slots + slot;
                    Some(Rectangle::new(
                        [(SegmentValue::Exact(x), lo), (SegmentValue::Exact(x + 1), r.mrays())],
                        colour(si).filled(),
                    ))
                })
                .collect();
            chart
                .draw_series(bars)
                .map_err(err)?
                .label(label(&series, s))
                .legend(move |(x, y)| Rectangle::new([(x, y - 5), (x + 10, y + 5)], colour(si).filled()));
            let whiskers: Vec<PathElement<(SegmentValue<usize>, f64)>> = repeated
                .iter()
                .filter(|r| {
                    r.runs > 1 && r.slowest > 0.0 && (&r.row.tracer, &r.row.method, &r.row.device) == (&s.0, &s.1, &s.2)
                })
                .filter_map(|r| {
                    let g = settings.iter().position(|x| *x == setting(&r.row, several))?;
                    let x = SegmentValue::CenterOf(g * slots + slot);
                    Some(PathElement::new(vec![(x.clone(), r.slowest), (x, r.fastest)], BLACK.stroke_width(2)))
                })
                .collect();
            chart.draw_series(whiskers).map_err(err)?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()
            .map_err(err)?;
    }
    root.present().map_err(err)?;
    Ok(())
}
