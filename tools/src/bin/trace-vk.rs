//! `trace-vk`: renders a scene file with the Vulkan compute tracer on any Vulkan device.

use clap::{Parser, Subcommand, ValueEnum};
use std::process::ExitCode;
use tools::auto::Picker;
use tools::bench::{Defaults, MatrixArgs};
use tools::cli::{Progress, duration, rays_per_second};
use tools::render_args::{
    BenchPersistentTuning, PersistentArg, PersistentTuning, RenderArgs, VerticesArg, parse_count, parse_workgroup,
};
use tools::say;
use tools::vk_bench::{AUTO, VkBench, check_validation};
use tracer_vk::kernels::{Method, Persistent, Specialisation, Stage};
use tracer_vk::render::RT_TRAVERSAL;
use tracer_vk::render::Renderer;
use tracer_vk::rt::Support;
use tracer_vk::{Gpu, list_devices};

#[derive(Parser)]
#[command(name = "trace-vk", version, about = "Ray cast or Whitted ray trace a BVH scene file with Vulkan compute.")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Args, Clone)]
struct DeviceArgs {
    /// Vulkan device index (see `trace-vk devices`) [default: the first discrete GPU, else any].
    #[arg(long, value_parser = parse_device, allow_hyphen_values = true)]
    device: Option<usize>,
    /// Enable the Khronos validation layer and fail on any message it reports.
    #[arg(long)]
    validate: bool,
}

#[derive(Subcommand)]
enum Command {
    /// List the Vulkan devices.
    Devices,
    /// Time the thesis's evaluation matrix: scenes x cameras x sizes x modes x methods, GPU time
    /// per frame from timestamp queries (median of --frames), written as CSV and Markdown.
    Bench(Box<BenchArgs>),
    /// Render one image (and optionally a cost heatmap and AOVs).
    Render {
        #[command(flatten)]
        args: Box<RenderArgs>,
        /// GPU traversal; auto picks the fastest for the scene, mode and size from a calibration
        /// run, cached beside the scene file (docs/vulkan-tracer.md, "--method auto").
        #[arg(long, value_enum, default_value = "lst")]
        method: MethodArg,
        /// With --method auto: calibrate again even where the cache has a pick, and replace it.
        #[arg(long)]
        recalibrate: bool,
        /// With --method auto: pick among these methods only [default: every method the device
        /// supports].
        #[arg(long, value_delimiter = ',', value_enum)]
        candidates: Vec<MethodArg>,
        /// Workgroup shape (pixels): width and height powers of two, at most 1024 invocations.
        #[arg(long, value_parser = parse_workgroup, default_value = "8x8", allow_hyphen_values = true)]
        workgroup: (u32, u32),
        /// Run tracing stages as persistent threads (lst and stackless; the same image): on for
        /// every one, auto for the AO and diffuse stages only (where they win on the H100).
        #[arg(long, value_enum, default_value = "auto")]
        persistent: PersistentArg,
        #[command(flatten)]
        tuning: PersistentTuning,
        #[command(flatten)]
        device: DeviceArgs,
    },
}

#[derive(clap::Args)]
struct BenchArgs {
    #[command(flatten)]
    matrix: MatrixArgs,
    /// Traversals.
    #[arg(long, value_delimiter = ',', value_enum, default_value = "lst,stackless,sst")]
    methods: Vec<MethodArg>,
    /// Workgroup shape (pixels): width and height powers of two, at most 1024 invocations.
    #[arg(long, value_parser = parse_workgroup, default_value = "8x8", allow_hyphen_values = true)]
    workgroup: (u32, u32),
    /// Time the bit-exact kernels (`render --exact`: no fused multiply-adds).
    #[arg(long)]
    exact: bool,
    /// With the method auto: calibrate again even where the cache has a pick, and replace it.
    #[arg(long)]
    recalibrate: bool,
    /// With the method auto: pick among these methods only [default: every method the device
    /// supports].
    #[arg(long, value_delimiter = ',', value_enum)]
    candidates: Vec<MethodArg>,
    /// Record N frames back to back into each submission, waited for once, and time their mean
    /// (1 to 64; one sample per pixel): whether small frames fill the GPU without the gaps
    /// between submissions (tools/scripts/h100-fill.sh). The images are those of one frame.
    #[arg(long, value_parser = parse_in_flight, default_value = "1")]
    in_flight: u32,
    /// Render in tiles of at most N pixels (at least one workgroup's), below the device's limit:
    /// a large frame cut into small frames' dispatches, rays as coherent as the large frame's.
    #[arg(long, value_parser = parse_tile_pixels)]
    tile_pixels: Option<u64>,
    /// Time each method with plain kernels (rows METHOD+plain), persistent threads in every
    /// tracing stage (METHOD+persistent) or auto's choice (`render --persistent`; rows METHOD),
    /// side by side. Only lst and stackless run persistently: the other methods' off and auto
    /// are one row, METHOD, and on (which they refuse) adds none beside them.
    #[arg(long, value_delimiter = ',', value_enum, default_value = "auto")]
    persistent: Vec<PersistentArg>,
    #[command(flatten)]
    tuning: BenchPersistentTuning,
    #[command(flatten)]
    device: DeviceArgs,
}

fn parse_in_flight(s: &str) -> Result<u32, String> {
    parse_count(s, 1, 64, "the frames per submission").map(|n| n as u32)
}

fn parse_tile_pixels(s: &str) -> Result<u64, String> {
    parse_count(s, 1, 1 << 32, "the pixels per tile")
}

#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    /// Local-memory stack, one ray per invocation (thesis 4.3.2).
    Lst,
    /// Escape-pointer walk without a stack (thesis 4.3.4).
    Stackless,
    /// Workgroup-shared stack: each workgroup walks one path for all its rays (thesis 4.3.3).
    Sst,
    /// SST whose majority vote uses subgroup operations instead of a workgroup-memory reduction.
    SstSubgroup,
    /// The GPU vendor's traversal (VK_KHR_ray_tracing_pipeline on the driver's own acceleration
    /// structures) with the same shading; where `trace-vk devices` says the device supports it.
    RtPipeline,
    /// Compressed 8-wide BVH (Ylitie, Karras and Laine 2017): quantised boxes, children in the
    /// ray octant's order; needs the wide layout (`bvhc compile --layout all`), which a mesh or
    /// description compiled on the fly gets.
    Cwbvh,
    /// The fastest of the methods above that the device supports, for this scene, mode and size:
    /// picked by timing a few frames of each, cached beside the scene file (`SCENE.methods`).
    Auto,
}

fn parse_device(s: &str) -> Result<usize, String> {
    parse_count(s, 0, 1 << 16, "the device index").map(|n| n as usize)
}

fn main() -> ExitCode {
    let command = tools::cli::parse::<Cli>().command;
    tools::cli::run(|| match command {
        Command::Devices => devices(),
        Command::Bench(b) => bench(&b),
        Command::Render { args, method, recalibrate, candidates, workgroup, persistent, tuning, device } => {
            render(&args, method, Auto { recalibrate, candidates }, workgroup, (persistent, tuning), &device)
        }
    })
}

fn devices() -> Result<(), String> {
    let list = list_devices().map_err(|e| e.to_string())?;
    for d in list {
        say!(
            "{}: {} ({:?}, Vulkan {}.{}.{}, {}), subgroup {}, shared memory {} KiB, storage buffer range {} MiB, device-local memory {} MiB, rt-pipeline: {}",
            d.index,
            d.name,
            d.kind,
            d.api_version.0,
            d.api_version.1,
            d.api_version.2,
            d.driver,
            d.subgroup_size,
            d.max_shared_memory / 1024,
            d.max_storage_buffer_range >> 20,
            d.device_local_bytes >> 20,
            match &d.rt_pipeline {
                Support::Supported(_) => "supported".to_string(),
                Support::Missing(what) => format!("no (lacks {what})"),
            }
        );
    }
    Ok(())
}

fn open(device: &DeviceArgs) -> Result<Gpu, String> {
    Gpu::new(device.device, device.validate).map_err(|e| e.to_string())
}

/// The device, refused at once when `methods` include one it cannot run (rt-pipeline).
fn open_for(device: &DeviceArgs, methods: &[Method]) -> Result<Gpu, String> {
    let gpu = open(device)?;
    if methods.contains(&Method::RtPipeline) {
        tracer_vk::rt::properties(&gpu).map_err(|e| e.to_string())?;
    }
    Ok(gpu)
}

/// What `--method auto` takes besides the scene.
struct Auto {
    recalibrate: bool,
    candidates: Vec<MethodArg>,
}

impl Auto {
    /// The candidates as methods; auto itself is not one.
    fn candidates(&self) -> Result<Vec<Method>, String> {
        self.candidates
            .iter()
            .map(|&m| method_of(m).ok_or_else(|| "auto is not a candidate of auto".to_owned()))
            .collect()
    }
}

fn render(
    args: &RenderArgs,
    method: MethodArg,
    auto: Auto,
    workgroup: (u32, u32),
    (persistent, tuning): (PersistentArg, PersistentTuning),
    device: &DeviceArgs,
) -> Result<(), String> {
    let vertices = args.vertices;
    let candidates = auto.candidates()?;
    let outputs = args.check()?;
    let chosen = method_of(method);
    // A device without rt-pipeline refuses it before the scene is read.
    let early = if chosen == Some(Method::RtPipeline) { Some(open_for(device, &[Method::RtPipeline])?) } else { None };
    let loaded =
        tools::load_scene_with(args.scene.as_deref(), tools::layouts_for(&[chosen.map_or(AUTO, Method::name)]))?;
    let scene = &loaded.file;
    let settings = args.settings(scene)?;
    let gpu = match early {
        Some(gpu) => gpu,
        None => open(device)?,
    };
    let (method, pick) = match chosen {
        Some(m) => (m, None),
        None => {
            let picker = Picker::new(&gpu, scene, args.scene.as_deref(), workgroup, args.exact, auto.recalibrate)
                .among(&candidates)
                .with_persistent(persistent.persistent());
            let pick = picker.pick(&settings)?;
            (pick.method, Some(pick))
        }
    };
    let mut renderer = Renderer::new(&gpu, scene, method, workgroup).map_err(|e| e.to_string())?;
    renderer.set_exact(args.exact);
    renderer.set_self_hits(args.self_hits);
    if let Some(v) = vertices {
        renderer.set_vertices(v.vertices()).map_err(|e| e.to_string())?;
    }
    renderer
        .set_persistent_with(persistent.persistent(), tuning.persistent_invocations, tuning.persistent_refill)
        .map_err(|e| e.to_string())?;
    let pixels = u64::from(settings.width) * u64::from(settings.height);
    let bar = Progress::new(pixels, "rendering {bar:40} {percent}% of the pixels ({elapsed}, {eta} left)", false);
    let out = bar
        .ticking(|| renderer.render_with_progress(&settings, true, &mut |p| bar.set_position(p.pixels_done)))
        .map_err(|e| e.to_string())?;
    check_validation(&gpu)?;

    // Every file first, the report after: a reader that stops early cannot cut the writing short.
    let image = &out.image;
    let written = outputs.write(image, None, args.heatmap_max, scene)?;
    let r = image.rays;
    let mut lines = vec![format!(
        "{}x{} {}{} with {}{}{} on {}: {} GPU{}, rays: {} ({}) -> {}",
        image.width,
        image.height,
        settings.mode.name(),
        tools::render_args::accuracy_note(&settings.accuracy, scene),
        method.name(),
        if args.exact { " (exact)" } else { "" },
        persistent_note(renderer.specialisation(), &settings.mode),
        gpu.info().name,
        duration(out.gpu_ms / 1e3),
        loaded.timing_note(),
        tools::render_args::rays_note(&r),
        rays_per_second(r.total(), out.gpu_ms / 1e3),
        outputs.image.path.display()
    )];
    let split = renderer.specialisation().split;
    if split.node_chunks > 1 || split.tri_chunks > 1 {
        lines.push(format!(
            "the scene is split over storage buffer bindings of at most {} MiB: nodes {}, triangles {}",
            tracer_vk::render::binding_limit(gpu.info()).1 >> 20,
            split.node_chunks,
            split.tri_chunks
        ));
    }
    if args.self_hits {
        lines.push(tools::render_args::self_hits_line(&r));
    }
    if let Some(v) = vertices {
        lines.push(tools::vk_bench::upload_line(scene, method, v.vertices()));
    }
    if let Some(b) = renderer.structure_build() {
        let traversal: f64 = out.passes.iter().filter(|(l, _)| l == RT_TRAVERSAL).map(|(_, ms)| ms).sum();
        lines.push(format!(
            "rt-pipeline: the driver built its structures in {} (bottom level {}, top level {}) into {} MiB with {} MiB of scratch; its traversal took {} of the frame's {}",
            duration((b.bottom_ms + b.top_ms) / 1e3),
            duration(b.bottom_ms / 1e3),
            duration(b.top_ms / 1e3),
            (b.bottom_bytes + b.top_bytes) >> 20,
            b.scratch_bytes >> 20,
            duration(traversal / 1e3),
            duration(out.gpu_ms / 1e3)
        ));
    }
    lines.extend(pick.map(|p| p.line()));
    for line in lines.into_iter().chain(written) {
        say!("{line}");
    }
    Ok(())
}

/// The report's note of the stages of a `mode` frame that ran as persistent threads, if any.
fn persistent_note(spec: &Specialisation, mode: &render_spec::Mode) -> String {
    let stages: Vec<&str> =
        Stage::tracing(mode).iter().filter(|&&s| spec.persistent_stage(s)).map(|s| s.name()).collect();
    match stages.len() {
        0 => String::new(),
        n if n == Stage::tracing(mode).len() => " (persistent threads)".to_owned(),
        _ => format!(" (persistent threads: {} stage, refill {})", stages.join(" and "), spec.refill_idle()),
    }
}

/// The method, or `None` for auto.
fn method_of(m: MethodArg) -> Option<Method> {
    Some(match m {
        MethodArg::Lst => Method::Lst,
        MethodArg::Stackless => Method::Stackless,
        MethodArg::Sst => Method::Sst,
        MethodArg::SstSubgroup => Method::SstSubgroup,
        MethodArg::RtPipeline => Method::RtPipeline,
        MethodArg::Cwbvh => Method::Cwbvh,
        MethodArg::Auto => return None,
    })
}

fn bench(b: &BenchArgs) -> Result<(), String> {
    let mut names: Vec<String> = Vec::new();
    // The persistent rows once per refill given (off has none).
    let refills: Vec<Option<u32>> = match b.tuning.persistent_refill.as_slice() {
        [] => vec![None],
        list => list.iter().map(|&r| Some(r)).collect(),
    };
    let only_on = b.persistent.iter().all(|p| p.persistent() == Persistent::On);
    for &m in &b.methods {
        for &v in &b.matrix.vertices {
            for &p in &b.persistent {
                for &refill in &refills {
                    let p = p.persistent();
                    let refill = if p == Persistent::Off { None } else { refill };
                    let name = match method_of(m) {
                        // `on` refuses such a method; beside off or auto, its plain row is all it has.
                        Some(m) if p == Persistent::On && !m.walks_in_steps() && !only_on => continue,
                        Some(m) => tools::vk_bench::method_name(m, v.vertices(), p, refill),
                        None => AUTO.to_owned(),
                    };
                    if !names.contains(&name) {
                        names.push(name);
                    }
                }
            }
        }
    }
    let methods: Vec<&str> = names.iter().map(String::as_str).collect();
    let all: Vec<Method> = b.methods.iter().filter_map(|&m| method_of(m)).collect();
    let auto = Auto { recalibrate: b.recalibrate, candidates: b.candidates.clone() };
    let bench = VkBench {
        recalibrate: b.recalibrate,
        candidates: auto.candidates()?,
        in_flight: b.in_flight,
        tile_pixels: b.tile_pixels,
        report_uploads: b.matrix.vertices.iter().any(|&v| v != VerticesArg::Expanded),
        persistent_invocations: b.tuning.persistent_invocations,
        ..VkBench::new(open_for(&b.device, &all)?, b.workgroup, b.exact)
    };
    tools::bench::run(&bench, &b.matrix, &methods, Defaults { frames: 50, warmup: 3 })?;
    Ok(())
}
