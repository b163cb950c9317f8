//! `trace-vk`: renders a scene file with the Vulkan compute tracer on any Vulkan device.

use clap::{Parser, Subcommand, ValueEnum};
use render_spec::{Mode, RayCounts, Settings};
use std::path::PathBuf;
use std::process::ExitCode;
use tools::cli::{Progress, duration, rays_per_second};
use tools::output::{self, Kind};
use tools::render_args::{RenderArgs, lights_n, parse_count, parse_res, parse_workgroup};
use tools::say;
use tracer_vk::kernels::Method;
use tracer_vk::render::Renderer;
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
        /// GPU traversal.
        #[arg(long, value_enum, default_value = "lst")]
        method: MethodArg,
        /// Workgroup shape (pixels).
        #[arg(long, value_parser = parse_workgroup, default_value = "8x8", allow_hyphen_values = true)]
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
    #[arg(long, value_delimiter = ',', default_value = "close-up,medium,wide", allow_hyphen_values = true)]
    cameras: Vec<String>,
    /// Image sizes.
    #[arg(long, value_delimiter = ',', value_parser = parse_res, default_value = "640x480,1280x960,1920x1440", allow_hyphen_values = true)]
    res: Vec<(u32, u32)>,
    /// Modes: cast, or whitted with a light count (whitted1, whitted2, whitted4).
    #[arg(long, value_delimiter = ',', value_parser = parse_mode, default_value = "cast,whitted1,whitted2", allow_hyphen_values = true)]
    modes: Vec<(Mode, usize)>,
    /// Traversals.
    #[arg(long, value_delimiter = ',', value_enum, default_value = "lst,stackless,sst")]
    methods: Vec<MethodArg>,
    /// Timed frames per setting, 1 to 100000 (the median is reported).
    #[arg(long, default_value_t = 50, value_parser = parse_frames, allow_hyphen_values = true)]
    frames: usize,
    /// Untimed frames before the timed ones, 0 to 100000.
    #[arg(long, default_value_t = 3, value_parser = parse_warmup, allow_hyphen_values = true)]
    warmup: usize,
    /// Workgroup shape (pixels).
    #[arg(long, value_parser = parse_workgroup, default_value = "8x8", allow_hyphen_values = true)]
    workgroup: (u32, u32),
    /// Write the table as CSV here (and as Markdown next to it, .md).
    #[arg(long, default_value = "bench.csv", allow_hyphen_values = true)]
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

fn parse_device(s: &str) -> Result<usize, String> {
    parse_count(s, 0, 1 << 16, "the device index").map(|n| n as usize)
}

fn parse_frames(s: &str) -> Result<usize, String> {
    parse_count(s, 1, 100_000, "the number of frames").map(|n| n as usize)
}

fn parse_warmup(s: &str) -> Result<usize, String> {
    parse_count(s, 0, 100_000, "the number of warm-up frames").map(|n| n as usize)
}

fn main() -> ExitCode {
    let command = tools::cli::parse::<Cli>().command;
    tools::cli::run(|| match command {
        Command::Devices => devices(),
        Command::Bench(b) => bench(&b),
        Command::Render { args, method, workgroup, device } => render(&args, method, workgroup, &device),
    })
}

fn devices() -> Result<(), String> {
    let list = list_devices().map_err(|e| e.to_string())?;
    for d in list {
        say!(
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
    let outputs = args.check()?;
    let loaded = tools::load_scene(args.scene.as_deref())?;
    let scene = &loaded.file;
    let settings = args.settings(scene)?;
    let method = method_of(method);
    let gpu = open(device)?;
    let mut renderer = Renderer::new(&gpu, scene, method, workgroup).map_err(|e| e.to_string())?;
    let pixels = u64::from(settings.width) * u64::from(settings.height);
    let bar = Progress::new(pixels, "rendering {bar:40} {percent}% of the pixels ({elapsed}, {eta} left)", false);
    let out = bar
        .ticking(|| renderer.render_with_progress(&settings, true, &mut |p| bar.set_position(p.pixels_done)))
        .map_err(|e| e.to_string())?;
    check_validation(&gpu)?;

    // Every file first, the report after: a reader that stops early cannot cut the writing short.
    let image = &out.image;
    let written = outputs.write(image, args.heatmap_max)?;
    let r = image.rays;
    let lines = vec![format!(
        "{}x{} {:?} with {} on {}: {} GPU{}, rays: {} primary, {} shadow, {} secondary ({}) -> {}",
        image.width,
        image.height,
        settings.mode,
        method.name(),
        gpu.info().name,
        duration(out.gpu_ms / 1e3),
        loaded.timing_note(),
        r.primary,
        r.shadow,
        r.secondary,
        rays_per_second(r.total(), out.gpu_ms / 1e3),
        outputs.image.path.display()
    )];
    for line in lines.into_iter().chain(written) {
        say!("{line}");
    }
    Ok(())
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
        _ => match s.strip_prefix("whitted") {
            Some(n) => parse_count(n, 0, tools::render_args::MAX_LIGHTS as u64, "the light count after \"whitted\"")
                .map(|n| (Mode::Whitted, n as usize)),
            None => Err(format!("{s:?} is not a mode (cast, whitted1, whitted2, ...)")),
        },
    }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 { v[n / 2] } else { 0.5 * (v[n / 2 - 1] + v[n / 2]) }
}

fn bench(b: &BenchArgs) -> Result<(), String> {
    let md_path = b.csv.with_extension("md");
    let checked =
        output::check(&[("--csv", &b.csv, Kind::Table), ("--csv (its Markdown copy)", &md_path, Kind::Markdown)], &[])
            .map_err(|e| e.to_string())?;
    let modes = &b.modes;
    let gpu = open(&b.device)?;
    let scenes: Vec<Option<PathBuf>> =
        if b.scenes.is_empty() { vec![None] } else { b.scenes.iter().cloned().map(Some).collect() };
    let total = scenes.len() * b.cameras.len() * b.res.len() * modes.len() * b.methods.len();
    let bar = Progress::new(total as u64, "{bar:40} {pos}/{len} settings ({elapsed}, {eta} left) {msg}", false);
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
        "| scene | camera | size | mode | method | median ms | rays/s | primary | shadow | secondary |".to_owned(),
        "|---|---|---|---|---|---:|---:|---:|---:|---:|".to_owned(),
    ];
    for path in &scenes {
        let name = path
            .as_ref()
            .and_then(|p| p.file_stem())
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "bunny (built-in)".to_owned());
        bar.set_message(format!("loading {name}"));
        let scene = tools::load_scene(path.as_deref())?.file;
        for cam in &b.cameras {
            tools::render_args::stored_camera(&scene, cam)?;
        }
        for &m in &b.methods {
            let method = method_of(m);
            let mut renderer = Renderer::new(&gpu, &scene, method, b.workgroup).map_err(|e| e.to_string())?;
            for cam in &b.cameras {
                let camera = tools::render_args::stored_camera(&scene, cam)?;
                for &(w, h) in &b.res {
                    for &(mode, nl) in modes {
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
                            lights: lights_n(&scene, nl, &camera),
                            max_indirections: scene.settings.max_indirections,
                            aovs: false,
                        };
                        let mut times = Vec::with_capacity(b.frames);
                        let mut rays = RayCounts::default();
                        for i in 0..b.warmup + b.frames {
                            let out = renderer.render_frame(&settings, false).map_err(|e| e.to_string())?;
                            if i >= b.warmup {
                                times.push(out.gpu_ms);
                                rays = out.image.rays;
                            }
                        }
                        let min = times.iter().copied().fold(f64::INFINITY, f64::min);
                        let med = median(&mut times);
                        let all_rays = rays.total();
                        let mrays = all_rays as f64 / med / 1e3;
                        let mode_name = match mode {
                            Mode::Cast => "cast".to_owned(),
                            Mode::Whitted => format!("whitted{nl}"),
                        };
                        csv.push(format!(
                            "{name},{},{cam},{w},{h},{mode_name},{nl},{},{med:.4},{min:.4},{},{},{},{mrays:.4}",
                            scene.triangles.len(),
                            method.name(),
                            rays.primary,
                            rays.shadow,
                            rays.secondary
                        ));
                        md.push(format!(
                            "| {name} | {cam} | {w}x{h} | {mode_name} | {} | {med:.3} | {} | {} | {} | {} |",
                            method.name(),
                            rays_per_second(all_rays, med / 1e3),
                            rays.primary,
                            rays.shadow,
                            rays.secondary
                        ));
                        bar.inc(1);
                    }
                }
            }
        }
    }
    bar.finish();
    check_validation(&gpu)?;
    output::write_text(&checked[0], &(csv.join("\n") + "\n")).map_err(|e| e.to_string())?;
    output::write_text(&checked[1], &(md.join("\n") + "\n")).map_err(|e| e.to_string())?;
    say!("{}", md.join("\n"));
    say!("\n-> {} and {}", b.csv.display(), md_path.display());
    Ok(())
}
