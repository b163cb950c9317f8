//! `trace-cpu`: renders a scene file on the CPU (the baseline tracer).

use clap::{Parser, Subcommand, ValueEnum};
use std::process::ExitCode;
use std::time::Instant;
use tools::bench::{Defaults, MatrixArgs};
use tools::cli::{Progress, duration, rays_per_second};
use tools::cpu_bench::{CpuBench, held_line, thread_pool};
use tools::render_args::{RenderArgs, VerticesArg, parse_count};
use tools::say;
use tracer_cpu::{Method, Tracer};

#[derive(Parser)]
#[command(name = "trace-cpu", version, about = "Ray cast or Whitted ray trace a BVH scene file on the CPU.")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render one image (and optionally a cost heatmap and AOVs).
    Render {
        #[command(flatten)]
        args: Box<RenderArgs>,
        /// Traversal: auto picks per kind of ray (primary, shadow, secondary, AO, diffuse) between
        /// the wide BVH's 8-ray packets and its rays one at a time (bvh8-packet and bvh8),
        /// whichever a short measurement of the frame's own rays at the start finds faster (the
        /// stackless walk for a file compiled with only the escape-pointer layout); packet: SIMD
        /// packets on the binary tree where the CPU has AVX2 (else ordered); ordered child-pair
        /// traversal; the stackless escape-pointer walk; bvh8: the wide BVH (8 children per node)
        /// collapsed at load from the child-pair layout, one ray at a time; bvh4: the same with 4
        /// children per node; bvh8-packet: 8-ray packets on the wide BVH.
        #[arg(long, value_enum, default_value = "auto")]
        method: MethodArg,
        /// Render the exact reference instead: f64 arithmetic throughout, every bounce up to the
        /// indirection limit (no adaptive stop), the edge-consistent test and an f64 offset; the
        /// ground truth other images are measured against, a few times slower than a fast render.
        /// Takes --spp; refuses --method, --intersect, --offset, --cutoff and --vertices.
        #[arg(long, conflicts_with_all = ["method", "intersect", "offset", "cutoff", "vertices"])]
        reference: bool,
        /// Worker threads of the render, 1 to 1024 [default: all cores]. Loading the scene
        /// (reading and checking the file, or compiling it, and collapsing the wide BVH) uses
        /// every core whatever this says.
        #[arg(long, value_parser = parse_threads, allow_hyphen_values = true)]
        threads: Option<usize>,
    },
    /// Time the thesis's evaluation matrix: scenes x cameras x sizes x modes x methods, wall-clock
    /// time per frame (median of --frames), written as CSV and Markdown with the columns of
    /// `trace-vk bench`.
    Bench(Box<BenchArgs>),
}

#[derive(clap::Args)]
struct BenchArgs {
    #[command(flatten)]
    matrix: MatrixArgs,
    /// Traversals.
    #[arg(long, value_delimiter = ',', value_enum, default_value = "packet,ordered,stackless")]
    methods: Vec<MethodArg>,
    /// Worker threads, 1 to 1024 [default: all cores].
    #[arg(long, value_parser = parse_threads, allow_hyphen_values = true)]
    threads: Option<usize>,
}

/// A CPU method as clap takes it: the names of [`Method::ALL`].
#[derive(Clone, Copy)]
struct MethodArg(Method);

impl ValueEnum for MethodArg {
    fn value_variants<'a>() -> &'a [Self] {
        const ALL: [MethodArg; Method::ALL.len()] = {
            let mut all = [MethodArg(Method::Auto); Method::ALL.len()];
            let mut i = 0;
            while i < all.len() {
                all[i] = MethodArg(Method::ALL[i]);
                i += 1;
            }
            all
        };
        &ALL
    }

    fn to_possible_value(&self) -> Option<clap::builder::PossibleValue> {
        Some(clap::builder::PossibleValue::new(self.0.name()))
    }
}

fn parse_threads(s: &str) -> Result<usize, String> {
    parse_count(s, 1, 1024, "the number of threads").map(|n| n as usize)
}

fn main() -> ExitCode {
    let command = tools::cli::parse::<Cli>().command;
    tools::cli::run(|| match command {
        Command::Render { args, method, reference, threads } => render(&args, method, reference, threads),
        Command::Bench(b) => bench(&b),
    })
}

fn render(args: &RenderArgs, method: MethodArg, reference: bool, threads: Option<usize>) -> Result<(), String> {
    let outputs = args.check()?;
    if reference && args.self_hits {
        return Err("--self-hits counts the fast tracer's rays, not the f64 reference's; leave out one of them".into());
    }
    let loaded = tools::load_scene(args.scene.as_deref())?;
    let scene = &loaded.file;
    let settings = args.settings(scene)?;
    let method = method.0;
    let pool = thread_pool(threads)?;
    // The scene prepared for tracing before the clock starts, as the file's reading is: the wide
    // BVH of bvh8, bvh4 and auto is collapsed at load, on every core as the loading is (outside
    // `pool`), and its time printed apart.
    let form = args.vertices.map_or(Default::default(), VerticesArg::vertices);
    let mut tracer = Tracer::with_vertices(scene, form);
    tracer.count_self_hits(args.self_hits);
    let collapse = (!reference)
        .then(|| {
            let t = Instant::now();
            tracer.collapse_for(method).then(|| t.elapsed().as_secs_f64())
        })
        .flatten();
    // The image's buffers paged in before the clock starts, as the ray report's output is: the
    // first writes to fresh memory cost a page fault each (a few microseconds in a VM).
    let paged = Instant::now();
    let mut canvas = tracer_cpu::render::Canvas::new(&settings);
    if !reference {
        pool.install(|| canvas.page_in());
    }
    let (paged, canvas_bytes) = (paged.elapsed().as_secs_f64(), canvas.bytes());
    let bar = Progress::new(settings.height as u64, "{bar:40} {pos}/{len} rows ({elapsed}, {eta} left)", false);
    let t0 = Instant::now();
    let progress = |rows: u32| bar.inc(rows as u64);
    let (image, linear, plan) = pool
        .install(|| {
            if reference {
                tracer_cpu::reference::render_with_progress(scene, &settings, &progress)
                    .map(|r| (r.image, Some(r.linear), "the f64 reference".to_owned()))
            } else {
                let plan = tracer_cpu::render::plan(&tracer, &settings, method)?;
                tracer_cpu::render::render_into(&tracer, &settings, &plan, canvas, &progress)
                    .map(|i| (i, None, plan.describe()))
            }
        })
        .map_err(|e| e.to_string())?;
    let seconds = t0.elapsed().as_secs_f64();
    bar.finish();

    // Every file first, the report after: a reader that stops early cannot cut the writing short.
    let written = outputs.write(&image, linear.as_deref(), args.heatmap_max, scene)?;
    let mut lines = Vec::new();
    let r = image.rays;
    let mut not_counted = Vec::new();
    if !reference {
        let size = match canvas_bytes {
            b if b < 10_000 => format!("{b} bytes"),
            b if b < 10_000_000 => format!("{:.0} kB", b as f64 / 1e3),
            b => format!("{:.0} MB", b as f64 / 1e6),
        };
        not_counted.push(format!("{} to page in the image ({size})", duration(paged)));
    }
    if let Some(c) = collapse {
        not_counted.push(format!("{} to collapse the wide BVH at load", duration(c)));
    }
    lines.push(format!(
        "{}x{} {}{} with {} on {} threads: {} to {}trace and shade into the 8-bit image{}{}{}, rays: {} ({}) -> {}",
        image.width,
        image.height,
        settings.mode.name(),
        tools::render_args::accuracy_note(&settings.accuracy, scene),
        plan,
        pool.current_num_threads(),
        duration(seconds),
        if method == Method::Auto && !reference { "measure auto's ways of tracing, " } else { "" },
        if settings.aovs { " and the AOVs" } else { "" },
        loaded.timing_note(),
        if not_counted.is_empty() { String::new() } else { format!(" (not counting {})", not_counted.join(", nor ")) },
        tools::render_args::rays_note(&r),
        rays_per_second(r.total(), seconds),
        outputs.image.path.display()
    ));
    if args.self_hits {
        lines.push(tools::render_args::self_hits_line(&r));
    }
    if args.vertices.is_some() {
        lines.push(held_line(&tracer, method));
    }
    for line in lines.into_iter().chain(written) {
        say!("{line}");
    }
    Ok(())
}

fn bench(b: &BenchArgs) -> Result<(), String> {
    let mut names: Vec<String> = Vec::new();
    for m in &b.methods {
        for &v in &b.matrix.vertices {
            let name = tools::bench::with_form(m.0.name(), v.vertices());
            if !names.contains(&name) {
                names.push(name);
            }
        }
    }
    let methods: Vec<&str> = names.iter().map(String::as_str).collect();
    let report_held = b.matrix.vertices.iter().any(|&v| v != VerticesArg::Expanded);
    let bench = CpuBench { pool: thread_pool(b.threads)?, report_held };
    tools::bench::run(&bench, &b.matrix, &methods, Defaults { frames: 10, warmup: 1 })?;
    Ok(())
}
