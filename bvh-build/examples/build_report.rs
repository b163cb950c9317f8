//! Build time and SAH cost of our builders (binned SAH with 4 to 64 bins, full sweep) and of two
//! peers (the `bvh` crate, obvhs) on the same scenes; writes `docs/build-benchmark.md` (table) and
//! `docs/build-benchmark.svg` (SAH cost against build time), and prints the table.
//!
//! `cargo run --release -p bvh-build --features compare --example build_report -- [--runs N]
//! [--scenes bunny,dragon,million,PATH...] [--builders binned16,sweep,bvh,obvhs,...] [--out DIR]`
//!
//! A scene is one of the names (files in `scenes/`, or in `$BVH_SCENES_DIR`) or a path to any
//! scene file the importer reads, named in the table by its file name. The part of an existing
//! `build-benchmark.md` from the line [`HAND_WRITTEN`] on is kept: it holds what this report
//! cannot measure itself.
//!
//! Every tree's SAH cost is computed by `bvh_format::tree::stats` with our default constants, after
//! converting the peers' trees into our layout (not timed).

use bvh_build::import::{ImportOptions, load};
use bvh_build::peers::{self, PeerTree};
use bvh_format::tree::{Tree, TreeStats, check_shape, stats};
use bvh_format::{BuildParams, Node, Strategy};
use glam::Vec3;
use plotters::coord::Shift;
use plotters::prelude::*;
use std::fmt::Write as _;
use std::path::PathBuf;
use std::time::Instant;

const SCENES: [(&str, &str); 3] = [("bunny", "bunny.glb"), ("dragon", "dragon.glb"), ("million", "million.toml")];
const BINS: [u32; 5] = [4, 8, 16, 32, 64];

#[derive(Clone, Copy, PartialEq)]
enum Builder {
    Binned(u32),
    Sweep,
    BvhCrate,
    Obvhs,
}

impl Builder {
    fn all() -> Vec<Builder> {
        let mut v: Vec<Builder> = BINS.iter().map(|&b| Builder::Binned(b)).collect();
        v.extend([Builder::Sweep, Builder::BvhCrate, Builder::Obvhs]);
        v
    }

    /// The name `--builders` takes.
    fn key(self) -> String {
        match self {
            Builder::Binned(b) => format!("binned{b}"),
            Builder::Sweep => "sweep".to_owned(),
            Builder::BvhCrate => "bvh".to_owned(),
            Builder::Obvhs => "obvhs".to_owned(),
        }
    }

    fn label(self) -> String {
        match self {
            Builder::Binned(b) => format!("ours, binned {b}"),
            Builder::Sweep => "ours, sweep".to_owned(),
            Builder::BvhCrate => "bvh 0.13 (binned SAH)".to_owned(),
            Builder::Obvhs => "obvhs 0.4 (PLOC + reinsertion)".to_owned(),
        }
    }
}

struct Row {
    scene: String,
    triangles: usize,
    builder: Builder,
    times_ms: Vec<f64>,
    stats: TreeStats,
}

impl Row {
    fn median_ms(&self) -> f64 {
        let mut t = self.times_ms.clone();
        t.sort_by(f64::total_cmp);
        let n = t.len();
        if n % 2 == 1 { t[n / 2] } else { (t[n / 2 - 1] + t[n / 2]) / 2.0 }
    }

    fn mtris_per_s(&self) -> f64 {
        self.triangles as f64 / self.median_ms() / 1e3
    }
}

struct Args {
    runs: usize,
    scenes: Vec<String>,
    builders: Vec<Builder>,
    out: PathBuf,
}

fn parse_args() -> Result<Args, String> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut a = Args {
        runs: 5,
        scenes: SCENES.iter().map(|s| s.0.to_owned()).collect(),
        builders: Builder::all(),
        out: root.join("docs"),
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = || it.next().ok_or(format!("{flag} needs a value"));
        match flag.as_str() {
            "--runs" => a.runs = value()?.parse().map_err(|_| "--runs takes a positive number".to_owned())?,
            "--scenes" => a.scenes = value()?.split(',').map(str::to_owned).collect(),
            "--builders" => {
                a.builders = value()?
                    .split(',')
                    .map(|k| {
                        Builder::all().into_iter().find(|b| b.key() == k).ok_or_else(|| {
                            let known: Vec<String> = Builder::all().iter().map(|b| b.key()).collect();
                            format!("unknown builder {k} (expected some of {})", known.join(", "))
                        })
                    })
                    .collect::<Result<_, _>>()?
            }
            "--out" => a.out = PathBuf::from(value()?),
            _ => return Err(format!("unknown argument {flag} (expected --runs, --scenes, --builders, --out)")),
        }
    }
    if a.runs == 0 {
        return Err("--runs takes a positive number".to_owned());
    }
    if let Some(s) = a.scenes.iter().find(|s| !SCENES.iter().any(|k| k.0 == s.as_str()) && !PathBuf::from(s).is_file())
    {
        return Err(format!("unknown scene {s} (expected bunny, dragon, million or the path of a scene file)"));
    }
    Ok(a)
}

/// Milliseconds `build` takes; its result is freed after the clock stops.
fn time_ms<T>(build: impl FnOnce() -> T) -> f64 {
    let t = Instant::now();
    let tree = build();
    let ms = t.elapsed().as_secs_f64() * 1e3;
    drop(tree);
    ms
}

/// Builds once and returns the time taken in milliseconds.
type Run<'a> = Box<dyn FnMut() -> f64 + 'a>;

/// One builder, ready to run (its inputs converted), and the tree of an untimed warm-up build.
fn prepare(tris: &[[Vec3; 3]], builder: Builder) -> (Run<'_>, PeerTree) {
    let defaults = BuildParams::default();
    match builder {
        Builder::Binned(_) | Builder::Sweep => {
            let p = match builder {
                Builder::Binned(bins) => BuildParams { strategy: Strategy::Binned, bins, ..defaults },
                _ => BuildParams { strategy: Strategy::Sweep, ..defaults },
            };
            let build = move || bvh_build::build_tree(tris, &p).expect("the scenes are valid input");
            let tree = build();
            (Box::new(move || time_ms(build)), PeerTree { nodes: tree.nodes, order: tree.order })
        }
        Builder::BvhCrate => {
            let mut shapes = peers::bvh_input(tris);
            let tree = peers::bvh_to_tree(&peers::build_bvh(&mut shapes), &shapes);
            (Box::new(move || time_ms(|| peers::build_bvh(&mut shapes))), tree)
        }
        Builder::Obvhs => {
            let input = peers::obvhs_input(tris);
            let params = peers::obvhs_params(defaults.traversal_cost, defaults.intersection_cost);
            let tree = peers::obvhs_to_tree(&peers::build_obvhs(&input, params));
            (Box::new(move || time_ms(|| peers::build_obvhs(&input, params))), tree)
        }
    }
}

fn measure_stats(nodes: &[Node], triangles: usize) -> TreeStats {
    check_shape(Tree::child_pair(nodes), triangles as u32).expect("every builder's tree must be valid");
    let p = BuildParams::default();
    stats(Tree::child_pair(nodes), p.traversal_cost, p.intersection_cost)
}

fn sweep_cost(rows: &[Row], scene: &str) -> f64 {
    rows.iter().find(|r| r.scene == scene && r.builder == Builder::Sweep).map(|r| r.stats.sah_cost).unwrap_or(f64::NAN)
}

fn table(rows: &[Row]) -> String {
    let mut s = String::new();
    s.push_str("| scene | triangles | builder | median ms | min–max ms | Mtris/s | SAH cost | SAH / sweep | nodes | max depth |\n");
    s.push_str("|---|--:|---|--:|--:|--:|--:|--:|--:|--:|\n");
    for r in rows {
        let lo = r.times_ms.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = r.times_ms.iter().copied().fold(0.0, f64::max);
        // Without the sweep among the builders there is nothing to compare with.
        let sweep = sweep_cost(rows, &r.scene);
        let relative = if sweep.is_nan() { "–".to_owned() } else { format!("{:.4}", r.stats.sah_cost / sweep) };
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.1} | {:.1}–{:.1} | {:.2} | {:.3} | {} | {} | {} |",
            r.scene,
            thousands(r.triangles),
            r.builder.label(),
            r.median_ms(),
            lo,
            hi,
            r.mtris_per_s(),
            r.stats.sah_cost,
            relative,
            thousands(r.stats.node_count as usize),
            r.stats.max_depth,
        );
    }
    s
}

fn thousands(n: usize) -> String {
    let digits = n.to_string().into_bytes();
    let groups: Vec<&str> = digits.rchunks(3).rev().map(|g| std::str::from_utf8(g).expect("ASCII digits")).collect();
    groups.join(",")
}

/// The issue's three targets, checked against the measurements.
/// A scene's name in the table: the names as given, paths by their file name.
fn scene_name(scene: &str) -> String {
    match std::path::Path::new(scene).file_name() {
        Some(f) if !SCENES.iter().any(|k| k.0 == scene) => f.to_string_lossy().into_owned(),
        _ => scene.to_owned(),
    }
}

/// The line from which `build-benchmark.md` is written by hand and kept by this report.
const HAND_WRITTEN: &str = "<!-- Written by hand from here on: build_report keeps what follows. -->";

fn targets(rows: &[Row], scenes: &[String]) -> String {
    let mut s = String::new();
    let scenes: Vec<String> = scenes.iter().map(|s| scene_name(s)).collect();
    let find = |scene: &str, b: Builder| rows.iter().find(|r| r.scene == scene && r.builder == b);
    let yes = |ok: bool| if ok { "met" } else { "NOT met" };
    for scene in &scenes {
        let Some(b16) = find(scene, Builder::Binned(16)) else { continue };
        if let Some(sweep) = find(scene, Builder::Sweep) {
            let rel = b16.stats.sah_cost / sweep.stats.sah_cost - 1.0;
            let _ = writeln!(
                s,
                "- {scene}: 16 bins within 1.5 % of the sweep's SAH cost: {:+.2} %, {}.",
                rel * 100.0,
                yes(rel <= 0.015)
            );
        }
        if let Some(peer) = find(scene, Builder::BvhCrate) {
            let ratio = b16.mtris_per_s() / peer.mtris_per_s();
            let cheaper = b16.stats.sah_cost < peer.stats.sah_cost;
            let _ = writeln!(
                s,
                "- {scene}: 16 bins at least 1.5x the bvh crate's throughput with lower SAH cost: {:.2} vs {:.2} Mtris/s ({ratio:.2}x), SAH {:.3} vs {:.3}, {}.",
                b16.mtris_per_s(),
                peer.mtris_per_s(),
                b16.stats.sah_cost,
                peer.stats.sah_cost,
                yes(ratio >= 1.5 && cheaper)
            );
        }
        if b16.triangles >= 1_000_000 {
            // The issue's limits: 0.5 s on 2 cores, 0.15 s on the 16-core host.
            let threads = rayon::current_num_threads();
            let limit = if threads >= 16 { 150.0 } else { 500.0 };
            let ms = b16.median_ms();
            let _ = writeln!(
                s,
                "- {scene}: a million triangles in under {limit:.0} ms on {threads} threads (16 bins): {ms:.0} ms, {}.",
                yes(ms < limit)
            );
        }
    }
    s
}

/// Whether the binned builder's tree on `million` is far (over 10 %) from the sweep's.
fn million_gap(rows: &[Row]) -> bool {
    let cost = |b: Builder| rows.iter().find(|r| r.scene == "million" && r.builder == b).map(|r| r.stats.sah_cost);
    matches!((cost(Builder::Binned(16)), cost(Builder::Sweep)), (Some(b), Some(s)) if b > s * 1.1)
}

/// Why the binned trees on `million` cost so much more than the sweep's, found by walking the
/// 16-bin and sweep trees on 2026-11-21; kept with the table while the gap shows.
const MILLION_NOTE: &str = "\nWhy binning falls behind on `million`: the floor is two triangles whose \
boxes span the whole 2.4 × 2.4 quad, so their box centroids lie at the centre of the scene and at the \
lowest y of all centroids, among the dragon's and bunnies' feet. The sweep sorts by centroid and cuts \
the two floor triangles off at the root (a leaf at depth 1); no bin boundary separates them from the \
models' lowest triangles, so the binned builder peels the models off in pieces and the floor ends in a \
leaf at depth 4 below three near-root-sized inner nodes, which alone adds about 2.7 to the cost \
(SAH summed over depths 1–4: 4.6 binned against 1.9 for the sweep). More bins do not help (32 and 64 \
bins give the same cost).\n";

fn chart<DB: DrawingBackend>(
    rows: &[Row],
    scenes: &[String],
    root: DrawingArea<DB, Shift>,
) -> Result<(), Box<dyn std::error::Error>>
where
    DB::ErrorType: 'static,
{
    root.fill(&WHITE)?;
    let (title, body) = root.split_vertically(40);
    title.titled("SAH cost against build time (lower left is better)", ("sans-serif", 20).into_font())?;
    let panels = body.split_evenly((1, scenes.len()));
    let ours = RGBColor(31, 119, 180);
    let sweep_c = RGBColor(44, 160, 44);
    let bvh_c = RGBColor(214, 39, 40);
    let obvhs_c = RGBColor(148, 103, 189);
    for (panel, scene) in panels.iter().zip(scenes) {
        let rs: Vec<&Row> = rows.iter().filter(|r| &r.scene == scene).collect();
        let Some(first) = rs.first() else { continue };
        // Relative to the sweep when it ran; the plain cost otherwise (a NaN axis never ends
        // plotters' search for tick marks).
        let sweep = sweep_cost(rows, scene);
        let (base, y_desc) = if sweep.is_nan() { (1.0, "SAH cost") } else { (sweep, "SAH cost / sweep") };
        let pts: Vec<(Builder, f64, f64)> =
            rs.iter().map(|r| (r.builder, r.median_ms(), r.stats.sah_cost / base)).collect();
        let (tmin, tmax) = pts.iter().fold((f64::INFINITY, 0f64), |(a, b), p| (a.min(p.1), b.max(p.1)));
        let (ymin, ymax) = pts.iter().fold((f64::INFINITY, 0f64), |(a, b), p| (a.min(p.2), b.max(p.2)));
        let pad = ((ymax - ymin) * 0.12).max(0.005);
        // Headroom above the highest point keeps the legend clear of the markers.
        let top = ymax + pad + (ymax - ymin + pad) * 0.45;
        let mut c = ChartBuilder::on(panel)
            .caption(format!("{scene} ({} triangles)", thousands(first.triangles)), ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(
                (tmin / 1.5..tmax * 1.5).log_scale().with_key_points(log_ticks(tmin / 1.5, tmax * 1.5)),
                (ymin - pad)..top,
            )?;
        c.configure_mesh()
            .x_desc("median build time, ms (log scale)")
            .y_desc(y_desc)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.2}"))
            .light_line_style(WHITE.mix(0.0))
            .draw()?;
        let binned: Vec<(f64, f64, u32)> = pts
            .iter()
            .filter_map(|&(b, t, y)| match b {
                Builder::Binned(k) => Some((t, y, k)),
                _ => None,
            })
            .collect();
        c.draw_series(LineSeries::new(binned.iter().map(|p| (p.0, p.1)), ours.stroke_width(2)))?
            .label("ours, binned (4–64 bins)")
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, ours.filled()));
        c.draw_series(binned.iter().map(|&(t, y, k)| {
            EmptyElement::at((t, y))
                + Circle::new((0, 0), 4, ours.filled())
                + Text::new(k.to_string(), (6, -16), ("sans-serif", 13).into_font().color(&ours))
        }))?;
        let single = |b: Builder| pts.iter().filter(move |p| p.0 == b).map(|p| (p.1, p.2));
        c.draw_series(single(Builder::Sweep).map(|p| TriangleMarker::new(p, 7, sweep_c.filled())))?
            .label("ours, full sweep")
            .legend(move |(x, y)| TriangleMarker::new((x + 10, y), 6, sweep_c.filled()));
        c.draw_series(single(Builder::BvhCrate).map(|p| Cross::new(p, 6, bvh_c.stroke_width(3))))?
            .label("bvh 0.13 (binned SAH)")
            .legend(move |(x, y)| Cross::new((x + 10, y), 5, bvh_c.stroke_width(3)));
        c.draw_series(
            single(Builder::Obvhs).map(|p| EmptyElement::at(p) + Rectangle::new([(-5, -5), (5, 5)], obvhs_c.filled())),
        )?
        .label("obvhs 0.4 (PLOC + reinsertion)")
        .legend(move |(x, y)| Rectangle::new([(x + 5, y - 5), (x + 15, y + 5)], obvhs_c.filled()));
        c.configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK.mix(0.3))
            .label_font(("sans-serif", 13))
            .draw()?;
    }
    root.present()?;
    Ok(())
}

/// 1, 2, 5 times powers of ten inside `lo..hi`: plotters' own log axis labels too few of them.
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let mut ticks = Vec::new();
    let mut decade = 10f64.powf(lo.log10().floor());
    while decade <= hi {
        ticks.extend([1.0, 2.0, 5.0].iter().map(|m| m * decade).filter(|t| (lo..=hi).contains(t)));
        decade *= 10.0;
    }
    ticks
}

fn command_output(cmd: &str, args: &[&str]) -> Option<String> {
    let out = std::process::Command::new(cmd).args(args).output().ok()?;
    out.status.success().then(|| String::from_utf8_lossy(&out.stdout).trim().to_owned())
}

fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|m| m.trim().to_owned())
        })
        .unwrap_or_else(|| "unknown CPU".to_owned())
}

fn load_average() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unknown".to_owned())
}

fn main() {
    let args = parse_args().unwrap_or_else(|e| {
        eprintln!("build_report: {e}");
        std::process::exit(2);
    });
    let load_before = load_average();
    // BVH_SCENES_DIR lets a carried binary find the scenes on another machine.
    let scenes_dir = std::env::var_os("BVH_SCENES_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes"));
    let mut rows = Vec::new();
    for scene in &args.scenes {
        let path = match SCENES.iter().find(|s| s.0 == scene.as_str()) {
            Some(s) => scenes_dir.join(s.1),
            None => PathBuf::from(scene),
        };
        let scene = &scene_name(scene);
        let tris = load(&path, &ImportOptions::default())
            .unwrap_or_else(|e| {
                eprintln!("build_report: {e}");
                std::process::exit(1);
            })
            .positions;
        eprintln!("{scene}: {} triangles", thousands(tris.len()));
        // Warm-up builds first, then the timed builds in rounds over every builder, so that load
        // from other work on the machine falls on all builders alike rather than on whichever ran
        // during it.
        let mut runs = Vec::new();
        let mut scene_rows = Vec::new();
        for &builder in &args.builders {
            let (run, tree) = prepare(&tris, builder);
            let stats = measure_stats(&tree.nodes, tris.len());
            eprintln!("  {:32} warm-up done, SAH {:.3}", builder.label(), stats.sah_cost);
            scene_rows.push(Row { scene: scene.clone(), triangles: tris.len(), builder, times_ms: Vec::new(), stats });
            runs.push(run);
        }
        for round in 1..=args.runs {
            for (run, row) in runs.iter_mut().zip(&mut scene_rows) {
                row.times_ms.push(run());
            }
            eprintln!("  round {round}/{} done (load {})", args.runs, load_average());
        }
        drop(runs);
        for row in &scene_rows {
            eprintln!("  {:32} median {:8.1} ms", row.builder.label(), row.median_ms());
        }
        rows.extend(scene_rows);
    }
    let load_after = load_average();

    let threads = std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1);
    let nproc = command_output("nproc", &[]).unwrap_or_else(|| "?".to_owned());
    let date = command_output("date", &["-u", "+%Y-%m-%d %H:%M UTC"]).unwrap_or_else(|| "unknown date".to_owned());
    let rustc = command_output("rustc", &["-V"]).unwrap_or_else(|| "rustc ?".to_owned());
    let mut cmd = "cargo run --release -p bvh-build --features compare --example build_report".to_owned();
    let extra: Vec<String> = std::env::args().skip(1).collect();
    if !extra.is_empty() {
        cmd = format!("{cmd} -- {}", extra.join(" "));
    }
    let t = table(&rows);
    println!("{t}");
    let goals = targets(&rows, &args.scenes);
    println!("{goals}");

    let mut md = String::new();
    md.push_str("# Build benchmark\n\n");
    md.push_str(
        "Build time and SAH cost of our builders (Wald's binned SAH with 4 to 64 bins, full-sweep SAH) and \
         of two Rust peers on the same triangles in the same run: the `bvh` crate 0.13 (binned SAH, \
         one triangle per leaf, parallel build with rayon) and obvhs 0.4 (PLOC with reinsertion, its \
         `medium_build` preset with leaves of at most 8 triangles, its leaf collapse using our \
         traversal/intersection cost ratio; `parallel` feature on). Ours use the default parameters \
         (Ct = 1, Ci = 1, at most 8 triangles per leaf).\n\n\
         Build time: median of the timed builds, from triangles in memory to the finished tree, \
         after one warm-up build per builder; the timed builds run in rounds over all builders, so \
         that load from other work on the machine falls on all of them alike. It includes computing the triangle boxes (ours: `bvh_build::build_tree`; the peers from \
         their own triangle types, converted beforehand, untimed). SAH cost: every tree (the peers' \
         converted into our child-pair layout, untimed, and checked with `tree::check_shape`) measured \
         by `bvh_format::tree::stats` with Ct = 1, Ci = 1, normalised by the root's area \
         (`sum inner Ct·A/Aroot + sum leaves Ci·n·A/Aroot`). SAH / sweep is relative to our full sweep \
         on the same scene.\n\n",
    );
    md.push_str(&t);
    md.push_str("\n## Targets\n\n");
    md.push_str(&goals);
    if million_gap(&rows) {
        md.push_str(MILLION_NOTE);
    }
    md.push_str("\n![SAH cost against build time](build-benchmark.svg)\n\n");
    let _ = writeln!(md, "## How it was made\n\n```\n{cmd}\n```\n");
    let _ = writeln!(
        md,
        "Machine: {}, `nproc` {nproc} ({threads} rayon threads), {rustc}, release profile. \
         Load average (1, 5, 15 min) before the run: {load_before}; after: {load_after}. \
         {} timed builds per setting. Date: {date}.\n",
        cpu_model(),
        args.runs
    );
    md.push_str(
        "Time only, with criterion's statistics: `cargo bench -p bvh-build --features compare --bench build`.\n",
    );

    std::fs::create_dir_all(&args.out).expect("cannot create the output directory");
    let md_path = args.out.join("build-benchmark.md");
    if let Some(tail) =
        std::fs::read_to_string(&md_path).ok().and_then(|old| old.find(HAND_WRITTEN).map(|i| old[i..].to_owned()))
    {
        md.push('\n');
        md.push_str(&tail);
    }
    std::fs::write(&md_path, md).unwrap_or_else(|e| panic!("cannot write {}: {e}", md_path.display()));
    let svg_path = args.out.join("build-benchmark.svg");
    let size = (540 * args.scenes.len() as u32, 560);
    let names: Vec<String> = args.scenes.iter().map(|s| scene_name(s)).collect();
    if let Err(e) = chart(&rows, &names, SVGBackend::new(&svg_path, size).into_drawing_area()) {
        eprintln!("build_report: cannot draw {}: {e}", svg_path.display());
        std::process::exit(1);
    }
    eprintln!("wrote {} and {}", md_path.display(), svg_path.display());
}
