//! `trace-cpu`: renders a scene file on the CPU (the baseline tracer).

use clap::{Parser, Subcommand, ValueEnum};
use std::process::ExitCode;
use std::time::Instant;
use tools::bench::{Defaults, MatrixArgs};
use tools::cli::{Progress, duration, rays_per_second};
use tools::cpu_bench::{CpuBench, thread_pool};
use tools::render_args::{RenderArgs, parse_count};
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
        /// Traversal: auto picks per kind of ray (incoherent rays one at a time on the wide BVH;
        /// primary and shadow rays as packets where a short measurement at the start finds them
        /// faster, else on the wide BVH too; the stackless walk for a file compiled with only the
        /// escape-pointer layout); packet: SIMD packets where the CPU has AVX2 (else ordered);
        /// ordered child-pair traversal; the stackless escape-pointer walk; bvh8: the wide BVH
        /// collapsed at load from the child-pair layout, one ray at a time.
        #[arg(long, value_enum, default_value = "auto")]
        method: MethodArg,
        /// Render the exact reference instead: f64 arithmetic throughout, every bounce up to the
        /// indirection limit (no adaptive stop), the edge-consistent test and an f64 offset; the
        /// ground truth other images are measured against, a few times slower than a fast render.
        /// Takes --spp; refuses --method, --intersect, --offset and --cutoff.
        #[arg(long, conflicts_with_all = ["method", "intersect", "offset", "cutoff"])]
        reference: bool,
        /// Worker threads, 1 to 1024 [default: all cores].
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

#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    Auto,
    Packet,
    Ordered,
    Stackless,
    Bvh8,
    Bvh8Packet,
}

impl MethodArg {
    fn method(self) -> Method {
        match self {
            MethodArg::Auto => Method::Auto,
            MethodArg::Packet => Method::Packet,
            MethodArg::Ordered => Method::Ordered,
            MethodArg::Stackless => Method::Stackless,
            MethodArg::Bvh8 => Method::Bvh8,
            MethodArg::Bvh8Packet => Method::Bvh8Packet,
        }
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
    let method = method.method();
    let pool = thread_pool(threads)?;
    // The scene prepared for tracing before the clock starts, as the file's reading is: the wide
    // BVH of bvh8 and auto is collapsed at load, and its time printed apart.
    let mut tracer = Tracer::new(scene);
    tracer.count_self_hits(args.self_hits);
    let collapse = (!reference && matches!(method.resolve(scene), Method::Bvh8 | Method::Bvh8Packet | Method::Auto))
        .then(|| {
            let t = Instant::now();
            tracer.bvh8();
            t.elapsed().as_secs_f64()
        });
    let bar = Progress::new(settings.height as u64, "{bar:40} {pos}/{len} rows ({elapsed}, {eta} left)", false);
    let t0 = Instant::now();
    let progress = |rows: u32| bar.inc(rows as u64);
    let (image, linear) = pool
        .install(|| {
            if reference {
                tracer_cpu::reference::render_with_progress(scene, &settings, &progress)
                    .map(|r| (r.image, Some(r.linear)))
            } else {
                tracer_cpu::render_with_progress(&tracer, &settings, method, &progress).map(|i| (i, None))
            }
        })
        .map_err(|e| e.to_string())?;
    let seconds = t0.elapsed().as_secs_f64();
    bar.finish();

    // Every file first, the report after: a reader that stops early cannot cut the writing short.
    let written = outputs.write(&image, linear.as_deref(), args.heatmap_max, scene)?;
    let mut lines = Vec::new();
    let r = image.rays;
    lines.push(format!(
        "{}x{} {}{} with {} on {} threads: {} to trace and shade into the 8-bit image{}{}{}, rays: {} ({}) -> {}",
        image.width,
        image.height,
        settings.mode.name(),
        tools::render_args::accuracy_note(&settings.accuracy, scene),
        if reference { "the f64 reference".to_owned() } else { format!("{:?}", method.resolve(scene)) },
        pool.current_num_threads(),
        duration(seconds),
        if settings.aovs { " and the AOVs" } else { "" },
        loaded.timing_note(),
        collapse.map_or(String::new(), |c| format!(" (not counting {} to collapse the wide BVH at load)", duration(c))),
        tools::render_args::rays_note(&r),
        rays_per_second(r.total(), seconds),
        outputs.image.path.display()
    ));
    if args.self_hits {
        lines.push(tools::render_args::self_hits_line(&r));
    }
    for line in lines.into_iter().chain(written) {
        say!("{line}");
    }
    Ok(())
}

fn bench(b: &BenchArgs) -> Result<(), String> {
    let names: Vec<String> = b
        .methods
        .iter()
        .map(|m| m.to_possible_value().expect("every method has a name").get_name().to_owned())
        .collect();
    let methods: Vec<&str> = names.iter().map(String::as_str).collect();
    let bench = CpuBench { pool: thread_pool(b.threads)? };
    tools::bench::run(&bench, &b.matrix, &methods, Defaults { frames: 10, warmup: 1 })?;
    Ok(())
}
