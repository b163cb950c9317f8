//! `trace-cpu`: renders a scene file on the CPU (the baseline tracer).

use clap::{Parser, Subcommand, ValueEnum};
use std::process::ExitCode;
use std::time::Instant;
use tools::cli::{duration, rays_per_second};
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
        args: RenderArgs,
        /// Traversal: SIMD packets where the CPU has AVX2 (else ordered), ordered child-pair
        /// traversal, or the stackless escape-pointer walk; auto takes the stackless walk for a
        /// file compiled with only the escape-pointer layout.
        #[arg(long, value_enum, default_value = "auto")]
        method: MethodArg,
        /// Worker threads, 1 to 1024 [default: all cores].
        #[arg(long, value_parser = parse_threads, allow_hyphen_values = true)]
        threads: Option<usize>,
    },
}

#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    Auto,
    Packet,
    Ordered,
    Stackless,
}

fn parse_threads(s: &str) -> Result<usize, String> {
    parse_count(s, 1, 1024, "the number of threads").map(|n| n as usize)
}

fn main() -> ExitCode {
    let Command::Render { args, method, threads } = tools::cli::parse::<Cli>().command;
    tools::cli::run(|| render(&args, method, threads))
}

fn render(args: &RenderArgs, method: MethodArg, threads: Option<usize>) -> Result<(), String> {
    let outputs = args.check()?;
    let loaded = tools::load_scene(args.scene.as_deref())?;
    let scene = &loaded.file;
    let settings = args.settings(scene)?;
    let method = match method {
        MethodArg::Auto => Method::Auto,
        MethodArg::Packet => Method::Packet,
        MethodArg::Ordered => Method::Ordered,
        MethodArg::Stackless => Method::Stackless,
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .build()
        .map_err(|e| format!("cannot start the worker threads: {e}"))?;
    let tracer = Tracer::new(scene);
    let t0 = Instant::now();
    let image = pool.install(|| tracer_cpu::render(&tracer, &settings, method)).map_err(|e| e.to_string())?;
    let seconds = t0.elapsed().as_secs_f64();

    // Every file first, the report after: a reader that stops early cannot cut the writing short.
    let written = outputs.write(&image, args.heatmap_max)?;
    let mut lines = Vec::new();
    let r = image.rays;
    lines.push(format!(
        "{}x{} {:?} with {:?} on {} threads: {}{}, rays: {} primary, {} shadow, {} secondary ({}) -> {}",
        image.width,
        image.height,
        settings.mode,
        method.resolve(scene),
        pool.current_num_threads(),
        duration(seconds),
        loaded.timing_note(),
        r.primary,
        r.shadow,
        r.secondary,
        rays_per_second(r.total(), seconds),
        outputs.image.path.display()
    ));
    for line in lines.into_iter().chain(written) {
        say!("{line}");
    }
    Ok(())
}
