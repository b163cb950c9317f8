//! `stress`: the stability sweep of issue 9. Generated scenes along every axis of trouble
//! (distance from the origin, scale, axis-parallel and grazing rays, ray origins on surfaces,
//! degenerate geometry, tree depth, leaf size, secondary rays), rendered by every CPU and GPU
//! method, every primary hit checked against the exact f64 reference; writes docs/stability.md
//! with tables and a chart.

use clap::Parser;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tools::cli::Progress;
use tools::render_args::parse_count;
use tools::say;
use tools::stress::cases::{self, AXES, Extent};
use tools::stress::{METHODS, Method, report};

#[derive(Parser)]
#[command(
    name = "stress",
    version,
    about = "Sweep every method over the conditions where ray tracers fail and write the failure rates.",
    long_about = "Sweep every method (CPU ordered, stackless, packet, bvh8, bvh8-packet; GPU LST, stackless, SST, SST-subgroup, rt-pipeline \
where the device has it, else refused with the reason) over \
generated scenes along each axis of trouble: distance from the origin 10^0..10^7 scene sizes (with and without \
the compiler's rebasing), scale 10^-8..10^8, axis-parallel rays through faces, edges and vertices (+0 and -0 \
components), grazing rays down to 1e-6 degrees, ray origins on a surface, edge and vertex, zero-area and needle \
triangles, duplicates, coplanar overlaps, a vertex shared by 1000 triangles, trees 1000 deep, leaves of 1000 \
triangles, halls of mirrors up to 64 indirections, glass inside glass, triangle counts up to --max-triangles and \
frames up to 16384 x 16384. Where Möller-Trumbore (--intersect mt) can differ, every method runs with it too, as \
a line of its own.\n\nEvery pixel's primary hit is checked against the exact f64 brute-force reference; points \
that compare images (distance, scale, secondary rays, size) also count pixels whose colour differs. Each point \
and method is counted as wrong hits, leaks, NaN/infinite values, wrong pixels, crashes (panics), hangs (no frame \
within --timeout), device faults (a lost device, dropped work) or refusals (a typed error: a limit, not a silent \
failure). Writes a Markdown report and a chart (SVG and PNG); the exit status is 1 when anything failed \
in silence."
)]
struct Cli {
    /// Markdown report to write.
    #[arg(long, default_value = "docs/stability.md")]
    out: PathBuf,
    /// Chart to write, as STEM.svg and STEM.png.
    #[arg(long, default_value = "docs/stability/failure-rates")]
    chart: PathBuf,
    /// A cheap slice of every axis (smaller frames, fewer points), as the CI test runs it.
    #[arg(long)]
    quick: bool,
    /// CPU methods only (no Vulkan device needed).
    #[arg(long)]
    cpu_only: bool,
    /// Vulkan device index (see `trace-vk devices`) [default: the first discrete GPU, else any].
    #[arg(long, value_parser = parse_device)]
    device: Option<usize>,
    /// Seconds one method may take on one point before it counts as a hang (per 4 Mi pixels on
    /// the large frames).
    #[arg(long, default_value = "120", value_parser = parse_seconds)]
    timeout: u64,
    /// Run only the axes whose names contain this text (repeatable), e.g. `--axis distance`.
    #[arg(long)]
    axis: Vec<String>,
    /// Run only this method (repeatable), by its column name, e.g. `--method "GPU sst"`, so that a
    /// long sweep can be split over several runs (each writes its own report or section).
    #[arg(long)]
    method: Vec<String>,
    /// Describe the machine in the report as this (default: the CPU model and the device's name).
    #[arg(long)]
    machine: Option<String>,
    /// Leave out the frames of more pixels than this from the size axis (16384x16384 is 2^28),
    /// where a machine cannot render them within its session.
    #[arg(long, default_value_t = 1 << 28, value_parser = parse_pixels)]
    max_frame_pixels: u64,
    /// The report's section to write, "## TITLE" up to the next "## " heading (appended when the
    /// report has none), so that runs of different axes keep each other's tables.
    #[arg(long, default_value = "Results")]
    section: String,
    /// The size axis's largest scene: triangle counts 10^3, 10^4, ... up to this, and this.
    #[arg(long, default_value_t = cases::DEFAULT_MAX_TRIANGLES, value_parser = parse_triangles)]
    max_triangles: u64,
}

fn parse_triangles(s: &str) -> Result<u64, String> {
    parse_count(s, 1000, u32::MAX as u64, "the largest triangle count")
}

fn parse_pixels(s: &str) -> Result<u64, String> {
    parse_count(s, 1, 1 << 28, "the largest frame in pixels")
}

fn parse_device(s: &str) -> Result<usize, String> {
    parse_count(s, 0, 1 << 16, "the device index").map(|n| n as usize)
}

fn parse_seconds(s: &str) -> Result<u64, String> {
    parse_count(s, 1, 86_400, "the timeout in seconds")
}

fn cpu_model() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = info.lines().find_map(|l| l.strip_prefix("model name")).map(|l| l.trim_start_matches([' ', '\t', ':']));
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    format!("{}, {threads} threads", model.unwrap_or("unknown CPU"))
}

fn main() -> ExitCode {
    let cli = tools::cli::parse::<Cli>();
    tools::cli::run(|| sweep(&cli))
}

fn sweep(cli: &Cli) -> Result<(), String> {
    let started = Instant::now();
    let gpu = if cli.cpu_only {
        None
    } else {
        Some(Arc::new(tracer_vk::Gpu::new(cli.device, false).map_err(|e| format!("{e} (or run with --cpu-only)"))?))
    };
    if let Some(unknown) = cli.method.iter().find(|w| !METHODS.iter().any(|m| m.name().eq_ignore_ascii_case(w))) {
        let names: Vec<String> = METHODS.iter().map(|m| format!("{:?}", m.name())).collect();
        return Err(format!("--method {unknown:?} is none of the sweep's methods ({})", names.join(", ")));
    }
    let asked = |m: &Method| cli.method.is_empty() || cli.method.iter().any(|w| m.name().eq_ignore_ascii_case(w));
    let methods: Vec<Method> =
        METHODS.iter().copied().filter(|m| (gpu.is_some() || matches!(m, Method::Cpu(_))) && asked(m)).collect();
    let machine = cli.machine.clone().unwrap_or_else(|| {
        let device = gpu.as_ref().map_or("no Vulkan device".to_owned(), |g| g.info().name.clone());
        format!("{}; Vulkan: {device}", cpu_model())
    });
    say!("generating the scenes ...");
    let extent = if cli.quick { Extent::Quick } else { Extent::Full };
    let wanted = |axis: &str| cli.axis.is_empty() || cli.axis.iter().any(|a| axis.contains(a.as_str()));
    let mut cases = cases::all(extent, cli.max_triangles, &wanted);
    cases.retain(|c| c.axis != AXES[13] || c.pixels() <= cli.max_frame_pixels);
    let runs: usize = cases.iter().map(|c| if c.both_tests { 2 } else { 1 }).sum();
    let progress = Progress::new((runs * methods.len()) as u64, "{bar:40} {pos}/{len} {msg}", false);
    // Without a terminal (a log, a remote run) the bar is not drawn: a line per finished run
    // instead, so that a sweep cut short still shows how far it got.
    let lines = !std::io::IsTerminal::is_terminal(&std::io::stderr());
    let rows = tools::stress::sweep(cases, &methods, gpu, Duration::from_secs(cli.timeout), &|row| {
        progress.inc(1);
        progress.set_message(format!("{} {} {}", row.axis, row.label, row.line()));
        if lines {
            say!(
                "[{:.0} s] {} {} {}: {}",
                started.elapsed().as_secs_f64(),
                row.axis,
                row.label,
                row.line(),
                report::cell(&row.tally)
            );
        }
    });
    progress.finish();

    let silent: Vec<String> = rows
        .iter()
        // The f32-world axis shows what the compiler's rebasing prevents; it is not a method.
        .filter(|r| r.failed() && r.axis != AXES[1])
        .map(|r| format!("{} {}: {} {}", r.axis, r.label, r.line(), report::cell(&r.tally)))
        .collect();
    let axes: String = cli.axis.iter().map(|a| format!(" --axis {a:?}")).collect();
    let axes: String = axes + &cli.method.iter().map(|m| format!(" --method {m:?}")).collect::<String>();
    let frames = if cli.max_frame_pixels == 1 << 28 {
        String::new()
    } else {
        format!(" --max-frame-pixels {}", cli.max_frame_pixels)
    };
    let section = if cli.section == "Results" { String::new() } else { format!(" --section {:?}", cli.section) };
    let chart = if cli.chart == std::path::Path::new("docs/stability/failure-rates") {
        String::new()
    } else {
        format!(" --chart {}", cli.chart.display())
    };
    let command = format!(
        "cargo run --release -p tools --bin stress --{}{}{axes}{section}{chart}{frames} --timeout {} --max-triangles {}",
        if cli.quick { " --quick" } else { "" },
        if cli.cpu_only { " --cpu-only" } else { "" },
        cli.timeout,
        cli.max_triangles
    );
    let mut body = format!(
        "## {}\n\nMade by `{command}` on {machine} in {:.0} s. Chart: [{name}.svg]({name}.svg) \
         (failed pixels per point and method; a refused point has no marker).\n\n![failure rates]({name}.png)\n\n",
        cli.section,
        started.elapsed().as_secs_f64(),
        name = relative(&cli.chart, &cli.out),
    );
    body += &report::markdown(&rows, &AXES);
    let md = report::splice_section(&std::fs::read_to_string(&cli.out).unwrap_or_default(), &cli.section, &body);
    if let Some(dir) = cli.chart.parent() {
        std::fs::create_dir_all(dir).map_err(|e| format!("cannot create {}: {e}", dir.display()))?;
    }
    report::charts(&rows, &AXES, &cli.chart)?;
    tools::output::write_atomically(&cli.out, |w| {
        use std::io::Write;
        w.write_all(md.as_bytes()).map_err(|e| e.to_string())
    })
    .map_err(|e| e.to_string())?;
    say!("{} points x methods in {:.0} s -> {}", rows.len(), started.elapsed().as_secs_f64(), cli.out.display());
    if silent.is_empty() {
        say!("no silent failure");
        Ok(())
    } else {
        for s in &silent {
            say!("silent failure: {s}");
        }
        Err(format!("{} points failed in silence (listed above)", silent.len()))
    }
}

/// The chart's path as the report links it.
fn relative(chart: &std::path::Path, report: &std::path::Path) -> String {
    let base = report.parent().unwrap_or(std::path::Path::new(""));
    chart.strip_prefix(base).unwrap_or(chart).display().to_string()
}
