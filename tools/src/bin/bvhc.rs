//! `bvhc`: compiles OBJ, glTF/GLB and scene descriptions into a validated BVH scene file, and
//! explains or verifies such a file.

use bvh_build::Layouts;
use bvh_build::import::{self, ImportOptions};
use bvh_format::{BuildParams, SceneFile, Strategy};
use clap::{Parser, Subcommand, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

#[derive(Parser)]
#[command(name = "bvhc", version, about = "Compile triangle scenes into SAH BVH files, and explain or verify them.")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Compile an OBJ, glTF/GLB or scene description (.toml) into a BVH scene file.
    Compile(CompileArgs),
    /// Print what a scene file holds: counts, tree depth and leaf statistics, SAH cost, sizes.
    Info {
        /// The scene file.
        file: PathBuf,
    },
    /// Run the full validation of a scene file; exit status 0 when it passes.
    Verify {
        /// The scene file.
        file: PathBuf,
    },
}

#[derive(Clone, Copy, ValueEnum)]
enum LayoutArg {
    /// Both layouts (child-pair for LST and SST, escape-pointer for the stackless traversal).
    Both,
    ChildPair,
    Escape,
}

#[derive(Clone, Copy, ValueEnum)]
enum StrategyArg {
    /// Wald's binned SAH (fast; the default).
    Binned,
    /// SAH evaluated at every centroid (slow; the quality reference).
    Sweep,
}

#[derive(clap::Args)]
struct CompileArgs {
    /// Input scene: .obj (with its .mtl), .gltf, .glb, or a scene description .toml that places
    /// meshes and shapes and adds cameras, lights and material overrides.
    input: PathBuf,
    /// Output file [default: the input's name with the extension .bvh].
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Node layouts to store.
    #[arg(long, value_enum, default_value = "both")]
    layout: LayoutArg,
    /// Builder.
    #[arg(long, value_enum, default_value = "binned")]
    strategy: StrategyArg,
    /// Bins per axis for the binned builder.
    #[arg(long, default_value_t = BuildParams::default().bins)]
    bins: u32,
    /// SAH cost of traversing one inner node (relative to --intersection-cost).
    #[arg(long, default_value_t = BuildParams::default().traversal_cost)]
    traversal_cost: f32,
    /// SAH cost of intersecting one triangle.
    #[arg(long, default_value_t = BuildParams::default().intersection_cost)]
    intersection_cost: f32,
    /// Most triangles in one leaf.
    #[arg(long, default_value_t = BuildParams::default().max_leaf_size)]
    max_leaf_size: u32,
    /// Interpolate vertex normals where the input has none (default: flat normals, as glTF asks).
    #[arg(long)]
    smooth_normals: bool,
    /// No progress bar and no summary.
    #[arg(short, long)]
    quiet: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Compile(args) => compile(&args),
        Command::Info { file } => info(&file),
        Command::Verify { file } => verify(&file),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(message) => {
            eprintln!("error: {message}");
            ExitCode::FAILURE
        }
    }
}

fn compile(args: &CompileArgs) -> Result<(), String> {
    let output = args.output.clone().unwrap_or_else(|| args.input.with_extension("bvh"));
    if output == args.input {
        return Err(format!("the output {} would overwrite the input; choose another with -o", output.display()));
    }
    let params = BuildParams {
        strategy: match args.strategy {
            StrategyArg::Binned => Strategy::Binned,
            StrategyArg::Sweep => Strategy::Sweep,
        },
        bins: args.bins,
        traversal_cost: args.traversal_cost,
        intersection_cost: args.intersection_cost,
        max_leaf_size: args.max_leaf_size,
    };
    bvh_build::check_params(&params).map_err(|e| e.to_string())?;
    let layouts = match args.layout {
        LayoutArg::Both => Layouts { child_pair: true, escape: true },
        LayoutArg::ChildPair => Layouts { child_pair: true, escape: false },
        LayoutArg::Escape => Layouts { child_pair: false, escape: true },
    };

    let spinner = |msg: &str| {
        let pb = if args.quiet { ProgressBar::hidden() } else { ProgressBar::new_spinner() };
        pb.set_message(msg.to_owned());
        pb.enable_steady_tick(Duration::from_millis(100));
        pb
    };
    let t0 = Instant::now();
    let pb = spinner(&format!("reading {}", args.input.display()));
    let opts = ImportOptions { smooth_normals: args.smooth_normals };
    let scene = import::load(&args.input, &opts).map_err(|e| e.to_string())?;
    pb.finish_and_clear();
    let t_import = t0.elapsed();

    let n = scene.triangle_count();
    let t1 = Instant::now();
    let placed = AtomicUsize::new(0);
    let file = if args.quiet {
        bvh_build::compile(&scene, &params, layouts).map_err(|e| e.to_string())?
    } else {
        let pb = ProgressBar::new(n as u64).with_style(
            ProgressStyle::with_template("building {bar:40} {pos}/{len} triangles placed ({elapsed})")
                .expect("the template is valid"),
        );
        std::thread::scope(|s| {
            let worker = s.spawn(|| bvh_build::compile_with_progress(&scene, &params, layouts, Some(&placed)));
            while !worker.is_finished() {
                pb.set_position(placed.load(Ordering::Relaxed) as u64);
                std::thread::sleep(Duration::from_millis(50));
            }
            pb.finish_and_clear();
            worker.join().unwrap_or_else(|p| std::panic::resume_unwind(p))
        })
        .map_err(|e| e.to_string())?
    };
    let t_build = t1.elapsed();

    let t2 = Instant::now();
    bvh_format::write_file(&file, &output).map_err(|e| e.to_string())?;
    let t_write = t2.elapsed();
    if !args.quiet {
        let s = file.stats();
        let bytes = std::fs::metadata(&output).map(|m| m.len()).unwrap_or(0);
        println!(
            "{} -> {}: {} triangles, {} nodes, depth {}, SAH cost {:.3}, {}",
            args.input.display(),
            output.display(),
            n,
            s.node_count,
            s.max_depth,
            s.sah_cost,
            human_bytes(bytes)
        );
        println!(
            "  import {:.2} s, build {:.2} s ({} {}), write {:.2} s",
            t_import.as_secs_f64(),
            t_build.as_secs_f64(),
            params.strategy.name(),
            if params.strategy == Strategy::Binned { format!("{} bins", params.bins) } else { String::new() },
            t_write.as_secs_f64()
        );
    }
    Ok(())
}

fn load(file: &Path) -> Result<(SceneFile, Vec<bvh_format::SectionInfo>), String> {
    let bytes = std::fs::read(file).map_err(|e| format!("cannot read {}: {e}", file.display()))?;
    bvh_format::read_with_sections(&bytes).map_err(|e| format!("{} is not a valid scene file: {e}", file.display()))
}

fn verify(file: &Path) -> Result<(), String> {
    let (scene, _) = load(file)?;
    let s = scene.stats();
    println!(
        "{}: valid ({} triangles, {} nodes, depth {}, layouts: {})",
        file.display(),
        scene.triangles.len(),
        s.node_count,
        s.max_depth,
        layout_names(&scene)
    );
    Ok(())
}

fn layout_names(scene: &SceneFile) -> &'static str {
    match (scene.child_pair.is_some(), scene.escape.is_some()) {
        (true, true) => "child-pair, escape-pointer",
        (true, false) => "child-pair",
        _ => "escape-pointer",
    }
}

fn human_bytes(b: u64) -> String {
    match b {
        b if b >= 1 << 20 => format!("{:.1} MiB", b as f64 / (1u64 << 20) as f64),
        b if b >= 1 << 10 => format!("{:.1} KiB", b as f64 / 1024.0),
        b => format!("{b} B"),
    }
}

fn info(file: &Path) -> Result<(), String> {
    let (scene, sections) = load(file)?;
    let s = scene.stats();
    let (lo, hi) = scene.bounds();
    let b = &scene.build;
    println!("{}", file.display());
    println!("  triangles       {}", scene.triangles.len());
    println!("  materials       {}", scene.materials.len());
    println!(
        "  bounds          ({:.4}, {:.4}, {:.4}) .. ({:.4}, {:.4}, {:.4})",
        lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]
    );
    println!("  layouts         {}", layout_names(&scene));
    println!(
        "  build           {}{}, traversal cost {}, intersection cost {}, max leaf size {}",
        b.strategy.name(),
        if b.strategy == Strategy::Binned { format!(" ({} bins)", b.bins) } else { String::new() },
        b.traversal_cost,
        b.intersection_cost,
        b.max_leaf_size
    );
    println!("  nodes           {} ({} inner, {} leaves)", s.node_count, s.node_count - s.leaf_count, s.leaf_count);
    println!("  depth           max {}, mean leaf depth {:.2}", s.max_depth, s.mean_leaf_depth);
    println!("  SAH cost        {:.4}", s.sah_cost);
    println!("  mean leaf size  {:.2}", scene.triangles.len() as f64 / s.leaf_count.max(1) as f64);
    println!("  leaf sizes");
    let widest = s.leaf_sizes.iter().copied().max().unwrap_or(1).max(1);
    for (size, &count) in s.leaf_sizes.iter().enumerate().filter(|(_, c)| **c > 0) {
        let bar = "#".repeat(((count as f64 / widest as f64) * 40.0).ceil() as usize);
        println!("    {size:>4} {count:>9}  {bar}");
    }
    println!("  sections");
    let total: u64 = sections.iter().map(|x| x.bytes).sum();
    for sec in &sections {
        println!("    {:<22} {:>10} entries {:>12}", sec.kind.name(), sec.count, human_bytes(sec.bytes));
    }
    println!("    {:<22} {:>10}         {:>12}", "total", "", human_bytes(total));
    println!(
        "  shading         ambient {:?}, background {:?}, up to {} indirections",
        scene.settings.ambient, scene.settings.background, scene.settings.max_indirections
    );
    println!("  cameras");
    for c in &scene.cameras {
        println!(
            "    {:<16} eye ({:.3}, {:.3}, {:.3}) at ({:.3}, {:.3}, {:.3}) fov {}",
            c.name().unwrap_or("?"),
            c.eye[0],
            c.eye[1],
            c.eye[2],
            c.at[0],
            c.at[1],
            c.at[2],
            c.fov_deg
        );
    }
    println!("  lights");
    for l in &scene.lights {
        println!(
            "    at ({:.3}, {:.3}, {:.3}) colour ({:.2}, {:.2}, {:.2})",
            l.position[0], l.position[1], l.position[2], l.colour[0], l.colour[1], l.colour[2]
        );
    }
    println!("  materials");
    for (i, (m, name)) in scene.materials.iter().zip(&scene.material_names).enumerate() {
        let kind = if m.kr > 0.0 {
            format!("mirror kr {}", m.kr)
        } else if m.kt > 0.0 {
            format!("glass kt {} ior {}", m.kt, m.ior)
        } else {
            "opaque".to_owned()
        };
        println!("    {i:>3} {:<20} kd {:?} ks {:?} n {} {kind}", name, m.kd, m.ks, m.shininess);
    }
    Ok(())
}
