//! `trace-vk`: renders a scene file with the Vulkan compute tracer on any Vulkan device.

use clap::{Parser, Subcommand, ValueEnum};
use std::process::ExitCode;
use tools::render_args::{RenderArgs, parse_res};
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
    /// Render one image (and optionally a cost heatmap and AOVs).
    Render {
        #[command(flatten)]
        args: Box<RenderArgs>,
        /// GPU traversal.
        #[arg(long, value_enum, default_value = "lst")]
        method: MethodArg,
        /// Workgroup shape (pixels).
        #[arg(long, value_parser = parse_res, default_value = "8x8")]
        workgroup: (u32, u32),
        #[command(flatten)]
        device: DeviceArgs,
    },
}

#[derive(Clone, Copy, ValueEnum)]
enum MethodArg {
    /// Local-memory stack, one ray per invocation (thesis 4.3.2).
    Lst,
    /// Escape-pointer walk without a stack (thesis 4.3.4).
    Stackless,
}

fn main() -> ExitCode {
    let result = match Cli::parse().command {
        Command::Devices => devices(),
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
    let method = match method {
        MethodArg::Lst => Method::Lst,
        MethodArg::Stackless => Method::Stackless,
    };
    let gpu = open(device)?;
    let mut renderer = Renderer::new(&gpu, &scene, method, workgroup).map_err(|e| e.to_string())?;
    let out = renderer.render(&settings).map_err(|e| e.to_string())?;
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
