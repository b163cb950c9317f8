//! `trace-cpu`: renders a scene file on the CPU (the baseline tracer).

use clap::{Parser, Subcommand, ValueEnum};
use std::process::ExitCode;
use std::time::Instant;
use tools::render_args::RenderArgs;
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
        /// Traversal: SIMD packets where the CPU has AVX2, ordered child-pair traversal, or the
        /// stackless escape-pointer walk.
        #[arg(long, value_enum, default_value = "auto")]
        method: MethodArg,
        /// Worker threads [default: all cores].
        #[arg(long)]
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

fn main() -> ExitCode {
    let Command::Render { args, method, threads } = Cli::parse().command;
    match render(&args, method, threads) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn render(args: &RenderArgs, method: MethodArg, threads: Option<usize>) -> Result<(), String> {
    let scene = tools::load_scene(args.scene.as_deref())?;
    let settings = args.settings(&scene)?;
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
    let tracer = Tracer::new(&scene);
    let t0 = Instant::now();
    let image = pool.install(|| tracer_cpu::render(&tracer, &settings, method)).map_err(|e| e.to_string())?;
    let ms = t0.elapsed().as_secs_f64() * 1e3;
    tools::output::write_png(&args.output, &image)?;
    let r = image.rays;
    let total = r.total();
    println!(
        "{}x{} {:?} with {:?} on {} threads: {:.1} ms, rays: {} primary, {} shadow, {} secondary ({:.2} Mrays/s) -> {}",
        image.width,
        image.height,
        settings.mode,
        method.resolve(),
        pool.current_num_threads(),
        ms,
        r.primary,
        r.shadow,
        r.secondary,
        total as f64 / ms / 1e3,
        args.output.display()
    );
    if let Some(aov) = &image.aov {
        if let Some(p) = &args.heatmap {
            let max = tools::output::write_heatmap(p, image.width, image.height, aov)?;
            println!("heatmap: nodes visited per pixel, 0 (blue) to {max} (red) -> {}", p.display());
        }
        if let Some(p) = &args.aov {
            tools::output::write_aov(p, image.width, image.height, aov)?;
            println!("AOVs (t, N.X, N.Y, N.Z, prim, nodes, tris) -> {}", p.display());
        }
    }
    Ok(())
}
