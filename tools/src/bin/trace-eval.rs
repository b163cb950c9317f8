//! `trace-eval`: speed against accuracy (docs/accuracy.md). Its own program, so that the charts'
//! font libraries (fontconfig, FreeType) and FLIP's C++ runtime are linked into it alone, not into
//! the tracers.

use clap::Parser;
use std::process::ExitCode;
use tools::cpu_bench::{CpuBench, thread_pool};
use tools::eval::EvalArgs;
use tools::eval::reference::F64Reference;
use tools::render_args::{parse_count, parse_workgroup};
use tools::vk_bench::{EXACT_SUFFIX, VkBench};
use tracer_vk::Gpu;

/// Chart speed against accuracy: scenes x cameras x sizes x modes, each rendered by the CPU tracer
/// and on the Vulkan device with every method and accuracy setting, timed (medians) and compared
/// with the f64 reference render (FLIP, PSNR, pixels off, hit errors); writes eval.csv, eval.md
/// and a chart per frame (SVG and PNG) with its Pareto front.
#[derive(Parser)]
#[command(name = "trace-eval", version)]
struct Cli {
    #[command(flatten)]
    eval: EvalArgs,
    /// Worker threads of the CPU tracer and the reference, 1 to 1024 [default: all cores].
    #[arg(long, value_parser = parse_threads)]
    threads: Option<usize>,
    /// GPU workgroup shape (pixels): width and height powers of two, at most 1024 invocations.
    #[arg(long, value_parser = parse_workgroup, default_value = "8x8", allow_hyphen_values = true)]
    workgroup: (u32, u32),
    /// Vulkan device index (see `trace-vk devices`) [default: the first discrete GPU, else any].
    #[arg(long, value_parser = parse_device)]
    device: Option<usize>,
    /// Enable the Khronos validation layer and fail on any message it reports.
    #[arg(long)]
    validate: bool,
}

fn parse_threads(s: &str) -> Result<usize, String> {
    parse_count(s, 1, 1024, "the number of threads").map(|n| n as usize)
}

fn parse_device(s: &str) -> Result<usize, String> {
    parse_count(s, 0, 1 << 16, "the device index").map(|n| n as usize)
}

/// Method names as the evaluation lists them; "none" leaves the tracer out.
fn method_list(names: &[String]) -> Vec<String> {
    names.iter().filter(|m| m.as_str() != "none").cloned().collect()
}

fn main() -> ExitCode {
    let cli = tools::cli::parse::<Cli>();
    tools::cli::run(|| {
        let a = &cli.eval;
        let cpu = CpuBench { pool: thread_pool(cli.threads)?, report_held: false };
        let gpu = Gpu::new(cli.device, cli.validate).map_err(|e| e.to_string())?;
        let gpu = VkBench::new(gpu, cli.workgroup, false);
        let reference = F64Reference { pool: thread_pool(cli.threads)? };
        let cpu = tools::eval::Tracer {
            bench: &cpu,
            methods: method_list(&a.cpu_methods),
            exact_method: |_| None,
            frames: a.frames.unwrap_or(5),
            warmup: a.warmup.unwrap_or(2),
        };
        let gpu = tools::eval::Tracer {
            bench: &gpu,
            methods: method_list(&a.gpu_methods),
            exact_method: |m| Some(format!("{m}{EXACT_SUFFIX}")),
            frames: a.frames.unwrap_or(20),
            warmup: a.warmup.unwrap_or(3),
        };
        tools::eval::run(a, &reference, &cpu, &gpu)?;
        Ok(())
    })
}
