//! Memory beside speed for trace-vk's two vertex forms (`--vertices expanded|indexed`): from a
//! `trace-vk bench --vertices expanded,indexed` CSV and the scene files it timed, one point per
//! scene, setting and method and form at (bytes uploaded per triangle, Mrays/s), a line from each
//! expanded point to its indexed twin; and the same as a Markdown table on standard output.
//!
//! ```text
//! cargo run --release -p tools --example vertices_chart -- CSV SCENE.bvh... [-o chart.svg|chart.png]
//! ```
//!
//! A scene file matches the CSV's rows by its file stem (what `bench` names a scene).

use bvh_format::SceneFile;
use plotters::prelude::*;
use std::path::PathBuf;
use tools::bench::{Row, read_csv, significant};
use tools::vk_bench::{INDEXED_SUFFIX, method_of};
use tracer_vk::kernels::Vertices;

/// One measured point: the row, its method without the form, its form and bytes per triangle.
struct Point<'a> {
    row: &'a Row,
    method: String,
    form: Vertices,
    bytes_per_triangle: f64,
}

fn main() {
    let mut inputs = Vec::new();
    let mut out = PathBuf::from("vertices-chart.svg");
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "-o" | "--output" => out = args.next().map(PathBuf::from).unwrap_or_else(|| fail("-o needs a file name")),
            "-h" | "--help" => {
                println!(
                    "vertices_chart CSV SCENE.bvh... [-o chart.svg|chart.png]: memory beside speed per vertex form"
                );
                return;
            }
            _ => inputs.push(PathBuf::from(a)),
        }
    }
    let (csv, scenes) = inputs.split_first().unwrap_or_else(|| fail("give a trace-vk bench CSV and its scene files"));
    let rows = read_csv(csv).unwrap_or_else(|e| fail(&e));
    let files: Vec<(String, SceneFile)> = scenes
        .iter()
        .map(|p| {
            let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or_default().to_owned();
            (stem, bvh_format::read_file(p).unwrap_or_else(|e| fail(&format!("{}: {e}", p.display()))))
        })
        .collect();
    let points: Vec<Point<'_>> = rows
        .iter()
        .filter(|r| r.tracer == "vk")
        .filter_map(|row| {
            let (_, scene) = files.iter().find(|(stem, _)| *stem == row.scene)?;
            let (name, form) = match row.method.strip_suffix(INDEXED_SUFFIX) {
                Some(name) => (name, Vertices::Indexed),
                None => (row.method.as_str(), Vertices::Expanded),
            };
            let method = method_of(name).ok()?;
            let bytes = tracer_vk::render::upload_bytes_with(scene, method, form);
            Some(Point {
                row,
                method: name.to_owned(),
                form,
                bytes_per_triangle: bytes as f64 / scene.triangles.len().max(1) as f64,
            })
        })
        .collect();
    if points.is_empty() {
        fail("no row of the CSV belongs to a given scene file (matched by file stem)");
    }
    print_table(&points);
    let size = (900, 560);
    let drawn = match out.extension().and_then(|e| e.to_str()) {
        Some("svg") => draw(&points, SVGBackend::new(&out, size).into_drawing_area()),
        Some("png") => draw(&points, BitMapBackend::new(&out, size).into_drawing_area()),
        _ => fail("the chart can be written as .svg or .png; name the file accordingly"),
    };
    drawn.unwrap_or_else(|e| fail(&format!("cannot draw {}: {e}", out.display())));
    eprintln!("{} points of {} -> {}", points.len(), csv.display(), out.display());
}

fn fail(msg: &str) -> ! {
    eprintln!("error: {msg}");
    std::process::exit(1)
}

/// What a line joins: one scene, setting and method in both forms.
fn key(p: &Point<'_>) -> (String, String, String, String) {
    let r = p.row;
    (r.scene.clone(), format!("{} {}x{}", r.camera, r.width, r.height), r.mode.clone(), p.method.clone())
}

fn print_table(points: &[Point<'_>]) {
    println!(
        "| scene | setting | mode | method | expanded: B/tri, ms, Mrays/s | indexed: B/tri, ms, Mrays/s | memory | time |"
    );
    println!("|---|---|---|---|---|---|--:|--:|");
    let mut done = Vec::new();
    for p in points {
        let k = key(p);
        if done.contains(&k) {
            continue;
        }
        done.push(k.clone());
        let of = |form| points.iter().find(|q| key(q) == k && q.form == form);
        let cell = |q: Option<&Point<'_>>| {
            q.map_or("-".to_owned(), |q| {
                format!(
                    "{}, {}, {}",
                    significant(q.bytes_per_triangle),
                    significant(q.row.median_ms),
                    significant(q.row.mrays())
                )
            })
        };
        let (e, i) = (of(Vertices::Expanded), of(Vertices::Indexed));
        let ratio = |f: &dyn Fn(&Point<'_>) -> f64| match (e, i) {
            (Some(e), Some(i)) => format!("{:.3}", f(i) / f(e)),
            _ => "-".to_owned(),
        };
        println!(
            "| {} | {} | {} | {} | {} | {} | {} | {} |",
            k.0,
            k.1,
            k.2,
            k.3,
            cell(e),
            cell(i),
            ratio(&|p| p.bytes_per_triangle),
            ratio(&|p| p.row.median_ms)
        );
    }
    println!("\nmemory, time: indexed over expanded (bytes uploaded per triangle; median ms per frame).");
}

fn draw<DB: DrawingBackend>(points: &[Point<'_>], root: DrawingArea<DB, plotters::coord::Shift>) -> Result<(), String>
where
    DB::ErrorType: 'static,
{
    let err = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    root.fill(&WHITE).map_err(err)?;
    let xs = points.iter().map(|p| p.bytes_per_triangle);
    let ys: Vec<f64> = points.iter().map(|p| p.row.mrays()).filter(|y| y.is_finite() && *y > 0.0).collect();
    let (x_hi, y_lo, y_hi) = (
        xs.fold(0.0f64, f64::max) * 1.15,
        ys.iter().copied().fold(f64::INFINITY, f64::min) / 1.5,
        ys.iter().copied().fold(0.0f64, f64::max) * 3.0,
    );
    let (y_lo, y_hi) = if ys.is_empty() { (0.1, 10.0) } else { (y_lo, y_hi) };
    let mut chart = ChartBuilder::on(&root)
        .caption("trace-vk: memory beside speed, --vertices expanded and indexed", ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(70)
        .build_cartesian_2d(0.0..x_hi, (y_lo..y_hi).log_scale())
        .map_err(err)?;
    chart
        .configure_mesh()
        .x_desc("scene data uploaded, bytes per triangle")
        .y_desc("Mrays/s")
        .y_label_formatter(&|y| significant(*y))
        .draw()
        .map_err(err)?;
    let mut keys: Vec<(String, String, String, String)> = Vec::new();
    for p in points {
        if !keys.contains(&key(p)) {
            keys.push(key(p));
        }
    }
    for (i, k) in keys.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        let mut mine: Vec<&Point<'_>> = points.iter().filter(|p| key(p) == *k).collect();
        mine.sort_by(|a, b| a.bytes_per_triangle.total_cmp(&b.bytes_per_triangle));
        let line: Vec<(f64, f64)> = mine.iter().map(|p| (p.bytes_per_triangle, p.row.mrays())).collect();
        chart
            .draw_series(LineSeries::new(line, colour.stroke_width(2)))
            .map_err(err)?
            .label(format!("{} {} {} {}", k.0, k.1, k.2, k.3))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], colour.stroke_width(2)));
        // Filled: indexed; open: expanded.
        chart
            .draw_series(mine.iter().map(|p| {
                let style = if p.form == Vertices::Indexed { colour.filled() } else { colour.stroke_width(2) };
                Circle::new((p.bytes_per_triangle, p.row.mrays()), 5, style)
            }))
            .map_err(err)?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font(("sans-serif", 12))
        .draw()
        .map_err(err)?;
    root.present().map_err(err)?;
    Ok(())
}
