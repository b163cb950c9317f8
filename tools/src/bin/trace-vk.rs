//! `trace-vk`: renders a scene file with the Vulkan compute tracer on any Vulkan device.

use clap::{Parser, Subcommand, ValueEnum};
use std::path::PathBuf;
use std::process::ExitCode;
use tools::render_args::{RenderArgs, lights_n, parse_res};
use tracer_vk::kernels::Method;
use tracer_vk::render::{Mode, Renderer, Settings};
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
    #[arg(long)]
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
        /// GPU traversal.
        #[arg(long, value_enum, default_value = "lst")]
        method: MethodArg,
        /// Workgroup shape (pixels): width and height powers of two, at most 1024 invocations.
        #[arg(long, value_parser = parse_workgroup, default_value = "8x8")]
        workgroup: (u32, u32),
        #[command(flatten)]
        device: DeviceArgs,
    },
}

#[derive(clap::Args)]
struct BenchArgs {
    /// Scenes: compiled .bvh files, meshes or scene descriptions [default: the built-in bunny].
    scenes: Vec<PathBuf>,
    /// Stored cameras to render from.
    #[arg(long, value_delimiter = ',', default_value = "close-up,medium,wide")]
    cameras: Vec<String>,
    /// Image sizes.
    #[arg(long, value_delimiter = ',', value_parser = parse_res, default_value = "640x480,1280x960,1920x1440")]
    res: Vec<(u32, u32)>,
    /// Modes: cast, or whitted with a light count (whitted1, whitted2, whitted4).
    #[arg(long, value_delimiter = ',', default_value = "cast,whitted1,whitted2")]
    modes: Vec<String>,
    /// Traversals.
    #[arg(long, value_delimiter = ',', value_enum, default_value = "lst,stackless,sst")]
    methods: Vec<MethodArg>,
    /// Timed frames per setting (the median is reported).
    #[arg(long, default_value_t = 50)]
    frames: usize,
    /// Untimed frames before the timed ones.
    #[arg(long, default_value_t = 3)]
    warmup: usize,
    /// Workgroup shape (pixels): width and height powers of two, at most 1024 invocations.
    #[arg(long, value_parser = parse_workgroup, default_value = "8x8")]
    workgroup: (u32, u32),
    /// Write the table as CSV here (and as Markdown next to it, .md).
    #[arg(long, default_value = "bench.csv")]
    csv: PathBuf,
    #[command(flatten)]
    device: DeviceArgs,
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
}

/// A workgroup shape the kernels take on every device that runs them: both sides powers of two,
/// at most 1024 invocations (a device with a lower limit says so when the renderer is made).
fn parse_workgroup(s: &str) -> Result<(u32, u32), String> {
    let bad = || {
        format!(
            "{s:?} is not a workgroup shape: width and height must be powers of two with at most {} invocations in all, such as 8x8 (the default), 16x16 or 32x4",
            tracer_vk::render::MAX_WORKGROUP_INVOCATIONS
        )
    };
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h) = (w.trim().parse::<u32>().map_err(|_| bad())?, h.trim().parse::<u32>().map_err(|_| bad())?);
    if !tracer_vk::render::workgroup_allowed(w, h, tracer_vk::render::MAX_WORKGROUP_INVOCATIONS) {
        return Err(bad());
    }
    Ok((w, h))
}

fn main() -> ExitCode {
    let result = match Cli::parse().command {
        Command::Devices => devices(),
        Command::Bench(b) => bench(&b),
        Command::Render { args, method, workgroup, device } => render(&args, method, workgroup, &device),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn devices() -> Result<(), String> {
    let list = list_devices().map_err(|e| e.to_string())?;
    for d in list {
        println!(
            "{}: {} ({:?}, Vulkan {}.{}.{}, {}), subgroup {}, shared memory {} KiB, storage buffer range {} MiB, device-local memory {} MiB",
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
            d.device_local_bytes >> 20
        );
    }
    Ok(())
}

fn open(device: &DeviceArgs) -> Result<Gpu, String> {
    Gpu::new(device.device, device.validate).map_err(|e| e.to_string())
}

fn check_validation(gpu: &Gpu) -> Result<(), String> {
    match gpu.validation_messages().first() {
        None => Ok(()),
        Some(m) => Err(format!("the validation layer reported a problem: {}", m.lines().next().unwrap_or(""))),
    }
}

fn render(args: &RenderArgs, method: MethodArg, workgroup: (u32, u32), device: &DeviceArgs) -> Result<(), String> {
    let scene = tools::load_scene(args.scene.as_deref())?;
    let settings = Settings {
        width: args.res.0,
        height: args.res.1,
        camera: args.camera(&scene)?,
        mode: match args.mode() {
            tracer_cpu::Mode::Cast => Mode::Cast,
            tracer_cpu::Mode::Whitted => Mode::Whitted,
        },
        lights: args.lights(&scene),
        max_indirections: args.indirections(&scene),
    };
    let method = method_of(method);
    let gpu = open(device)?;
    let mut renderer = Renderer::new(&gpu, &scene, method, workgroup).map_err(|e| e.to_string())?;
    let want_aovs = args.heatmap.is_some() || args.aov.is_some();
    let bar = LateBar::new();
    let out = renderer
        .render_with_progress(&settings, true, want_aovs, &mut |p| bar.update(p.pixels_done, p.pixels))
        .map_err(|e| e.to_string())?;
    bar.finish();
    check_validation(&gpu)?;
    let image = tools::output::Frame { width: out.width, height: out.height, rgb: &out.rgb };
    tools::output::write_frame_png(&args.output, &image)?;
    let [p, s, sec] = out.rays;
    println!(
        "{}x{} {:?} with {} on {}: {:.3} ms GPU, rays: {p} primary, {s} shadow, {sec} secondary ({:.1} Mrays/s) -> {}",
        out.width,
        out.height,
        settings.mode,
        method.name(),
        gpu.info().name,
        out.gpu_ms,
        (p + s + sec) as f64 / out.gpu_ms / 1e3,
        args.output.display()
    );
    let aov = tracer_cpu::Aovs { t: out.t, normal: out.normal, prim: out.prim, nodes: out.nodes, tris: out.tris };
    if let Some(path) = &args.heatmap {
        let max = tools::output::write_heatmap(path, out.width, out.height, &aov)?;
        println!("heatmap: nodes visited per pixel, 0 (blue) to {max} (red) -> {}", path.display());
    }
    if let Some(path) = &args.aov {
        tools::output::write_aov(path, out.width, out.height, &aov)?;
        println!("AOVs (t, N.X, N.Y, N.Z, prim, nodes, tris) -> {}", path.display());
    }
    Ok(())
}

/// A progress bar that shows itself only once the work has taken longer than a second.
struct LateBar {
    bar: indicatif::ProgressBar,
    start: std::time::Instant,
}

impl LateBar {
    fn new() -> Self {
        let bar = indicatif::ProgressBar::hidden().with_style(
            indicatif::ProgressStyle::with_template("{bar:40} {percent}% of the pixels, {elapsed} (eta {eta})")
                .expect("the template is valid"),
        );
        LateBar { bar, start: std::time::Instant::now() }
    }

    fn update(&self, done: u64, total: u64) {
        if self.bar.is_hidden() && self.start.elapsed() > std::time::Duration::from_secs(1) {
            self.bar.set_draw_target(indicatif::ProgressDrawTarget::stderr());
        }
        self.bar.set_length(total);
        self.bar.set_position(done);
    }

    fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

fn method_of(m: MethodArg) -> Method {
    match m {
        MethodArg::Lst => Method::Lst,
        MethodArg::Stackless => Method::Stackless,
        MethodArg::Sst => Method::Sst,
        MethodArg::SstSubgroup => Method::SstSubgroup,
    }
}

/// A mode of the bench matrix: ray casting, or Whitted with this many lights.
fn parse_mode(s: &str) -> Result<(Mode, usize), String> {
    match s {
        "cast" => Ok((Mode::Cast, 0)),
        _ => s
            .strip_prefix("whitted")
            .and_then(|n| n.parse::<usize>().ok())
            .map(|n| (Mode::Whitted, n))
            .ok_or_else(|| format!("{s:?} is not a mode (cast, whitted1, whitted2, ...)")),
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) }
}

fn bench(b: &BenchArgs) -> Result<(), String> {
    let modes: Vec<(Mode, usize)> = b.modes.iter().map(|m| parse_mode(m)).collect::<Result<_, _>>()?;
    if b.frames == 0 {
        return Err("--frames must be at least 1".to_owned());
    }
    let gpu = open(&b.device)?;
    let scenes: Vec<Option<PathBuf>> =
        if b.scenes.is_empty() { vec![None] } else { b.scenes.iter().cloned().map(Some).collect() };
    let total = scenes.len() * b.cameras.len() * b.res.len() * modes.len() * b.methods.len();
    let bar = indicatif::ProgressBar::new(total as u64).with_style(
        indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} {msg}").expect("the template is valid"),
    );
    let header =
        "scene,triangles,camera,width,height,mode,lights,method,median_ms,min_ms,primary,shadow,secondary,mrays_per_s";
    let mut csv = vec![header.to_owned()];
    let mut md = vec![
        format!(
            "Device: {} ({:?}, {}); {} frames per setting after {} warm-up frames, GPU time from timestamp queries.",
            gpu.info().name,
            gpu.info().kind,
            gpu.info().driver,
            b.frames,
            b.warmup
        ),
        String::new(),
        "| scene | camera | size | mode | method | median ms | Mrays/s | primary | shadow | secondary |".to_owned(),
        "|---|---|---|---|---|---:|---:|---:|---:|---:|".to_owned(),
    ];
    for path in &scenes {
        let name = path
            .as_ref()
            .and_then(|p| p.file_stem())
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "bunny (built-in)".to_owned());
        bar.set_message(format!("loading {name}"));
        let scene = tools::load_scene(path.as_deref())?;
        for &m in &b.methods {
            let method = method_of(m);
            let mut renderer = Renderer::new(&gpu, &scene, method, b.workgroup).map_err(|e| e.to_string())?;
            for cam in &b.cameras {
                let camera = tools::render_args::stored_camera(&scene, cam)?;
                for &(w, h) in &b.res {
                    for &(mode, nl) in &modes {
                        bar.set_message(format!(
                            "{name} {cam} {w}x{h} {mode:?}{} {}",
                            if nl > 0 { nl.to_string() } else { String::new() },
                            method.name()
                        ));
                        let settings = Settings {
                            width: w,
                            height: h,
                            camera,
                            mode,
                            lights: lights_n(&scene, nl),
                            max_indirections: scene.settings.max_indirections,
                        };
                        let mut times = Vec::with_capacity(b.frames);
                        let mut rays = [0u64; 3];
                        for i in 0..b.warmup + b.frames {
                            let out = renderer.render_frame(&settings, false).map_err(|e| e.to_string())?;
                            if i >= b.warmup {
                                times.push(out.gpu_ms);
                                rays = out.rays;
                            }
                        }
                        let min = times.iter().copied().fold(f64::INFINITY, f64::min);
                        let med = median(&mut times);
                        let mrays = (rays[0] + rays[1] + rays[2]) as f64 / med / 1e3;
                        let mode_name = match mode {
                            Mode::Cast => "cast".to_owned(),
                            Mode::Whitted => format!("whitted{nl}"),
                        };
                        csv.push(format!(
                            "{name},{},{cam},{w},{h},{mode_name},{nl},{},{med:.4},{min:.4},{},{},{},{mrays:.1}",
                            scene.triangles.len(),
                            method.name(),
                            rays[0],
                            rays[1],
                            rays[2]
                        ));
                        md.push(format!(
                            "| {name} | {cam} | {w}x{h} | {mode_name} | {} | {med:.3} | {mrays:.0} | {} | {} | {} |",
                            method.name(),
                            rays[0],
                            rays[1],
                            rays[2]
                        ));
                        bar.inc(1);
                    }
                }
            }
        }
    }
    bar.finish_and_clear();
    check_validation(&gpu)?;
    let write = |p: &std::path::Path, lines: &[String]| {
        std::fs::write(p, lines.join("\n") + "\n").map_err(|e| format!("cannot write {}: {e}", p.display()))
    };
    write(&b.csv, &csv)?;
    let md_path = b.csv.with_extension("md");
    write(&md_path, &md)?;
    println!("{}", md.join("\n"));
    println!("\n-> {} and {}", b.csv.display(), md_path.display());
    Ok(())
}
