//! `trace-cpu`: renders a scene file on the CPU (the baseline tracer).

use bvh_format::SceneFile;
use clap::{Parser, Subcommand, ValueEnum};
use std::process::ExitCode;
use std::time::Instant;
use tools::bench::{Bench, Defaults, FrameSpec, MatrixArgs, Timed, significant};
use tools::progress::LateBar;
use tools::render_args::RenderArgs;
use tracer_cpu::{Method, RenderSettings, Tracer};

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
    /// Worker threads [default: all cores].
    #[arg(long)]
    threads: Option<usize>,
}

#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    Auto,
    Packet,
    Ordered,
    Stackless,
}

impl MethodArg {
    fn method(self) -> Method {
        match self {
            MethodArg::Auto => Method::Auto,
            MethodArg::Packet => Method::Packet,
            MethodArg::Ordered => Method::Ordered,
            MethodArg::Stackless => Method::Stackless,
        }
    }
}

fn main() -> ExitCode {
    let result = match Cli::parse().command {
        Command::Render { args, method, threads } => render(&args, method, threads),
        Command::Bench(b) => bench(&b),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn render(args: &RenderArgs, method: MethodArg, threads: Option<usize>) -> Result<(), String> {
    let loading = Instant::now();
    let scene = tools::load_scene(args.scene.as_deref())?;
    let load_s = loading.elapsed().as_secs_f64();
    let settings = RenderSettings {
        width: args.res.0,
        height: args.res.1,
        camera: args.camera(&scene)?,
        mode: args.mode(),
        lights: args.lights(&scene),
        max_indirections: args.indirections(&scene),
        method: method.method(),
        aovs: args.aov.is_some() || args.heatmap.is_some(),
    };
    let pool = pool(threads)?;
    let tracer = Tracer::new(&scene);
    let bar = LateBar::new(settings.height as u64, "rows");
    let t0 = Instant::now();
    let image = pool
        .install(|| tracer_cpu::render_with_progress(&tracer, &settings, &|rows| bar.inc(rows as u64)))
        .map_err(|e| e.to_string())?;
    let ms = t0.elapsed().as_secs_f64() * 1e3;
    bar.finish();
    tools::output::write_png(&args.output, &image)?;
    let r = image.rays;
    let total = r.primary + r.shadow + r.secondary;
    println!(
        "{}x{} {:?} with {:?} on {} threads: {} ms to trace and shade into the 8-bit image{} (not the {:.2} s to load \
         the scene, nor writing files), rays: {} primary, {} shadow, {} secondary ({} Mrays/s) -> {}",
        image.width,
        image.height,
        settings.mode,
        settings.method.resolve(),
        pool.current_num_threads(),
        significant(ms),
        if settings.aovs { " and the AOVs" } else { "" },
        load_s,
        r.primary,
        r.shadow,
        r.secondary,
        significant(total as f64 / ms / 1e3),
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

fn pool(threads: Option<usize>) -> Result<rayon::ThreadPool, String> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .build()
        .map_err(|e| format!("cannot start the worker threads: {e}"))
}

/// The CPU side of the benchmark matrix: wall-clock time of whole frames on a thread pool.
struct CpuBench {
    pool: rayon::ThreadPool,
}

impl Bench for CpuBench {
    type Renderer<'a> = (Tracer<'a>, Method);

    fn tracer(&self) -> &'static str {
        "cpu"
    }

    fn device(&self) -> String {
        format!("{}, {} threads", tools::cpu_model(), self.pool.current_num_threads())
    }

    fn timing(&self) -> String {
        "a frame's time is the wall-clock time of `tracer_cpu::render`: primary rays, tracing and shading \
         into the 8-bit image, no AOVs; the scene is loaded and prepared before"
            .to_owned()
    }

    fn prepare<'a>(&'a self, scene: &'a SceneFile, method: &str) -> Result<(Tracer<'a>, Method), String> {
        let method = MethodArg::from_str(method, false).map_err(|e| format!("{method:?}: {e}"))?.method();
        if method == Method::Packet && method.resolve() != method {
            return Err("this CPU cannot run the packet method: it needs AVX2".to_owned());
        }
        Ok((Tracer::new(scene), method))
    }

    fn frame(&self, (tracer, method): &mut (Tracer<'_>, Method), f: &FrameSpec) -> Result<Timed, String> {
        let settings = RenderSettings {
            width: f.width,
            height: f.height,
            camera: f.camera,
            mode: f.mode,
            lights: f.lights.clone(),
            max_indirections: f.max_indirections,
            method: *method,
            aovs: false,
        };
        let t0 = Instant::now();
        let image = self.pool.install(|| tracer_cpu::render(tracer, &settings)).map_err(|e| e.to_string())?;
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        let r = image.rays;
        Ok(Timed { ms, rays: [r.primary, r.shadow, r.secondary] })
    }
}

fn bench(b: &BenchArgs) -> Result<(), String> {
    let names: Vec<String> = b
        .methods
        .iter()
        .map(|m| m.to_possible_value().expect("every method has a name").get_name().to_owned())
        .collect();
    let methods: Vec<&str> = names.iter().map(String::as_str).collect();
    let bench = CpuBench { pool: pool(b.threads)? };
    tools::bench::run(&bench, &b.matrix, &methods, Defaults { frames: 10, warmup: 1 })?;
    Ok(())
}
