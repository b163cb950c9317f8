//! `bvhc`: compiles OBJ, glTF/GLB and scene descriptions into a validated BVH scene file, and
//! explains or verifies such a file.

use bvh_build::Layouts;
use bvh_build::import::{self, ImportOptions};
use bvh_format::{BuildParams, SceneFile, Strategy};
use clap::{Parser, Subcommand, ValueEnum};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;
use tools::cli::Progress;
use tools::output::{self, Kind};
use tools::render_args::parse_count;
use tools::say;

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
    /// Print what a scene holds: counts, tree depth and leaf statistics, SAH cost, sizes, and
    /// its cameras (the first is the tracers' default) and lights. A mesh or description is
    /// compiled on the fly with the default parameters first.
    Info {
        /// A compiled .bvh file, or an .obj, .gltf, .glb or scene description .toml.
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
    /// The 8-wide compressed layout for `trace-vk --method cwbvh`, beside a binary one (about 11
    /// bytes per triangle; it also stores the triangles in its leaves' order).
    Wide,
    /// Child-pair, escape-pointer and wide.
    All,
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
    /// Node layouts to store, comma-separated (`--layout both,wide`); `wide` needs a binary one beside it.
    #[arg(long, value_enum, value_delimiter = ',', default_value = "both")]
    layout: Vec<LayoutArg>,
    /// Builder.
    #[arg(long, value_enum, default_value = "binned")]
    strategy: StrategyArg,
    /// Bins per axis for the binned builder (2 to 1024); large nodes get one bin per 16 primitives,
    /// up to 16 times this count and 1024.
    #[arg(long, default_value_t = BuildParams::default().bins, value_parser = parse_bins, allow_hyphen_values = true)]
    bins: u32,
    /// SAH cost of traversing one inner node (relative to --intersection-cost; 0 or more).
    #[arg(long, default_value_t = BuildParams::default().traversal_cost, value_parser = parse_cost, allow_hyphen_values = true)]
    traversal_cost: f32,
    /// SAH cost of intersecting one triangle (above 0).
    #[arg(long, default_value_t = BuildParams::default().intersection_cost, value_parser = parse_cost, allow_hyphen_values = true)]
    intersection_cost: f32,
    /// Most triangles in one leaf (1 or more).
    #[arg(long, default_value_t = BuildParams::default().max_leaf_size, value_parser = parse_leaf_size, allow_hyphen_values = true)]
    max_leaf_size: u32,
    /// Interpolate vertex normals where the input has none (default: flat normals, as glTF asks).
    #[arg(long)]
    smooth_normals: bool,
    /// No progress bar and no summary.
    #[arg(short, long)]
    quiet: bool,
}

fn parse_bins(s: &str) -> Result<u32, String> {
    parse_count(s, 2, u64::from(bvh_build::MAX_BINS), "the bin count").map(|n| n as u32)
}

fn parse_leaf_size(s: &str) -> Result<u32, String> {
    parse_count(s, 1, u64::from(u32::MAX), "the maximum leaf size").map(|n| n as u32)
}

fn parse_cost(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(c) if c.is_finite() && c >= 0.0 => Ok(c),
        _ => Err(format!("{s:?}: a cost must be a finite number, 0 or more")),
    }
}

fn main() -> ExitCode {
    let cli: Cli = tools::cli::parse();
    tools::cli::run(|| match cli.command {
        Command::Compile(args) => compile(&args),
        Command::Info { file } => info(&file),
        Command::Verify { file } => verify(&file),
    })
}

fn compile(args: &CompileArgs) -> Result<(), String> {
    let output = args.output.clone().unwrap_or_else(|| args.input.with_extension("bvh"));
    let checked = output::check(&[("-o", &output, Kind::Scene)], &[&args.input]).map_err(|e| e.to_string())?;
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
    let mut layouts = Layouts { child_pair: false, escape: false, wide: false };
    for l in &args.layout {
        match l {
            LayoutArg::Both => (layouts.child_pair, layouts.escape) = (true, true),
            LayoutArg::ChildPair => layouts.child_pair = true,
            LayoutArg::Escape => layouts.escape = true,
            LayoutArg::Wide => layouts.wide = true,
            LayoutArg::All => layouts = Layouts::ALL,
        }
    }

    let t0 = Instant::now();
    let reading = Progress::new(0, "reading {msg} ({elapsed})", args.quiet);
    reading.set_message(args.input.display().to_string());
    let opts = ImportOptions { smooth_normals: args.smooth_normals };
    let scene = reading.around(|| import::load(&args.input, &opts), Progress::tick).map_err(|e| e.to_string())?;
    tools::print_warnings(&scene.warnings);
    let t_import = t0.elapsed();

    let n = scene.triangle_count();
    let t1 = Instant::now();
    let placed = AtomicUsize::new(0);
    let building = Progress::new(n as u64, "building {bar:40} {pos}/{len} triangles placed ({elapsed})", args.quiet);
    let file = building
        .around(
            || bvh_build::compile_for_writing(&scene, &params, layouts, Some(&placed)),
            |bar| bar.set_position(placed.load(Ordering::Relaxed) as u64),
        )
        .map_err(|e| e.to_string())?;
    let t_build = t1.elapsed();

    let t2 = Instant::now();
    let out = &checked[0];
    // Validated by the writer (compile_for_writing leaves that to it) before the first byte, and
    // streamed section by section into the file rather than assembled in memory first.
    let mut bytes = 0;
    output::write_atomically(&out.path, |w| {
        bytes = bvh_format::write_to(&file, w).map_err(|e| match e {
            bvh_format::WriteError::Invalid(e) => bvh_build::BuildError::Invalid(e).to_string(),
            bvh_format::WriteError::Io(e) => e.to_string(),
        })?;
        Ok(())
    })
    .map_err(|e| e.to_string())?;
    let t_write = t2.elapsed();
    if !args.quiet {
        let s = file.stats();
        say!(
            "{} -> {}: {} triangles, {} nodes, depth {}, SAH cost {:.3}, {}",
            args.input.display(),
            output.display(),
            n,
            s.node_count,
            s.max_depth,
            s.sah_cost,
            human_bytes(bytes)
        );
        say!(
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
    let bytes = bvh_format::read_input(file).map_err(|e| format!("cannot read {}: {e}", file.display()))?;
    bvh_format::read_with_sections(&bytes).map_err(|e| format!("{} is not a valid scene file: {e}", file.display()))
}

/// A compiled file as it is, or a mesh or description compiled with the default parameters (and
/// serialised, so that the section sizes are those of the file `bvhc compile` would write).
fn load_any(file: &Path) -> Result<(SceneFile, Vec<bvh_format::SectionInfo>, bool), String> {
    let ext = file.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if !matches!(ext.as_deref(), Some("obj" | "gltf" | "glb" | "toml")) {
        let (scene, sections) = load(file)?;
        return Ok((scene, sections, false));
    }
    let compiled = tools::compile_default(file)?;
    let bytes = bvh_format::write(&compiled).map_err(|e| e.to_string())?;
    let (scene, sections) = bvh_format::read_with_sections(&bytes).map_err(|e| e.to_string())?;
    Ok((scene, sections, true))
}

fn verify(file: &Path) -> Result<(), String> {
    let (scene, _) = load(file)?;
    let s = scene.stats();
    say!(
        "{}: valid ({} triangles, {} nodes, depth {}, layouts: {})",
        file.display(),
        scene.triangles.len(),
        s.node_count,
        s.max_depth,
        layout_names(&scene)
    );
    Ok(())
}

fn layout_names(scene: &SceneFile) -> String {
    let names = [
        (scene.child_pair.is_some(), "child-pair"),
        (scene.escape.is_some(), "escape-pointer"),
        (scene.wide.is_some(), "wide"),
    ];
    names.iter().filter(|(present, _)| *present).map(|(_, name)| *name).collect::<Vec<_>>().join(", ")
}

fn human_bytes(b: u64) -> String {
    match b {
        b if b >= 1 << 20 => format!("{:.1} MiB", b as f64 / (1u64 << 20) as f64),
        b if b >= 1 << 10 => format!("{:.1} KiB", b as f64 / 1024.0),
        b => format!("{b} B"),
    }
}

/// A world position with `digits` decimals, in scientific notation where fixed notation would
/// hide it (a scene 1e-7 wide, or 1e9).
fn point(p: [f64; 3], digits: usize) -> String {
    let wide = p.iter().any(|v| *v != 0.0 && !(1e-2..1e7).contains(&v.abs()));
    let c = |v: f64| if wide { format!("{v:.digits$e}") } else { format!("{v:.digits$}") };
    format!("({}, {}, {})", c(p[0]), c(p[1]), c(p[2]))
}

fn info(file: &Path) -> Result<(), String> {
    let (scene, sections, compiled) = load_any(file)?;
    let s = scene.stats();
    let (lo, hi) = scene.bounds();
    // Positions are shown in world coordinates; the file stores them relative to its origin.
    let (lo, hi) = (scene.world(lo), scene.world(hi));
    let b = &scene.build;
    say!("{}{}", file.display(), if compiled { " (compiled on the fly with the default parameters)" } else { "" });
    let smooth = scene.normal_indices.iter().filter(|n| **n != bvh_format::FLAT).count();
    say!("  triangles       {} ({} with vertex normals)", scene.triangles.len(), smooth);
    say!("  vertices        {} ({} normals)", scene.vertices.len(), scene.normals.len());
    say!("  materials       {}", scene.materials.len());
    say!("  bounds          {} .. {}", point(lo, 4), point(hi, 4));
    let o = scene.origin;
    say!(
        "  origin offset   ({}, {}, {}){}",
        o[0],
        o[1],
        o[2],
        if o == [0.0; 3] { "" } else { " (stored positions are relative to it; shown here in world coordinates)" }
    );
    if scene.scale_log2 != 0 {
        say!(
            "  stored unit     2^{} = {:e} world units (the scene is stored rescaled by a power of two so that the tracers' self-intersection offsets fit it; shown here in world units)",
            scene.scale_log2,
            scene.unit()
        );
    }
    say!("  layouts         {}", layout_names(&scene));
    say!(
        "  build           {}{}, traversal cost {}, intersection cost {}, max leaf size {}",
        b.strategy.name(),
        if b.strategy == Strategy::Binned { format!(" ({} bins)", b.bins) } else { String::new() },
        b.traversal_cost,
        b.intersection_cost,
        b.max_leaf_size
    );
    say!("  nodes           {} ({} inner, {} leaves)", s.node_count, s.node_count - s.leaf_count, s.leaf_count);
    say!("  depth           max {}, mean leaf depth {:.2}", s.max_depth, s.mean_leaf_depth);
    say!("  SAH cost        {:.4}", s.sah_cost);
    if let Some(w) = &scene.wide {
        let children: usize = w
            .iter()
            .map(|n| {
                (0..bvh_format::wide::WIDTH)
                    .filter(|&s| n.meta[s] != bvh_format::wide::EMPTY || n.inner_mask & (1 << s) != 0)
                    .count()
            })
            .sum();
        say!(
            "  wide layout     {} nodes, depth {}, {:.2} children per node, {:.1} bytes per triangle",
            w.len(),
            bvh_format::wide::depth(w),
            children as f64 / w.len().max(1) as f64,
            std::mem::size_of_val(&w[..]) as f64 / scene.triangles.len().max(1) as f64
        );
    }
    say!("  mean leaf size  {:.2}", scene.triangles.len() as f64 / s.leaf_count.max(1) as f64);
    say!("  leaf sizes");
    let widest = s.leaf_sizes.iter().copied().max().unwrap_or(1).max(1);
    for (size, &count) in s.leaf_sizes.iter().enumerate().filter(|(_, c)| **c > 0) {
        let bar = "#".repeat(((count as f64 / widest as f64) * 40.0).ceil() as usize);
        say!("    {size:>4} {count:>9}  {bar}");
    }
    say!("  sections");
    let total: u64 = sections.iter().map(|x| x.bytes).sum();
    for sec in &sections {
        say!("    {:<22} {:>10} entries {:>12}", sec.kind.name(), sec.count, human_bytes(sec.bytes));
    }
    say!("    {:<22} {:>10}         {:>12}", "total", "", human_bytes(total));
    let per_tri = |bytes: u64| bytes as f64 / scene.triangles.len().max(1) as f64;
    let vk = |m, v| per_tri(tracer_vk::render::upload_bytes_with(&scene, m, v));
    use tracer_vk::kernels::{Method as Vk, Vertices};
    say!(
        "  bytes/triangle  file {:.1}; trace-cpu holds {:.1}, with --vertices indexed {:.1} (bvh8, bvh4 and auto add their wide BVH); trace-vk uploads {:.1} (lst, sst), {:.1} (stackless), with --vertices indexed {:.1}, {:.1}{}",
        per_tri(total),
        per_tri(tracer_cpu::held_bytes(&scene, Vertices::Expanded)),
        per_tri(tracer_cpu::held_bytes(&scene, Vertices::Indexed)),
        vk(Vk::Lst, Vertices::Expanded),
        vk(Vk::Stackless, Vertices::Expanded),
        vk(Vk::Lst, Vertices::Indexed),
        vk(Vk::Stackless, Vertices::Indexed),
        if scene.wide.is_some() {
            format!(", {:.1} (cwbvh)", vk(Vk::Cwbvh, Vertices::Expanded))
        } else {
            String::new()
        }
    );
    say!(
        "  shading         ambient {:?}, background {:?}, up to {} indirections",
        scene.settings.ambient,
        scene.settings.background,
        scene.settings.max_indirections
    );
    say!("  cameras (the first is the tracers' default)");
    for c in &scene.cameras {
        let (eye, at) = (scene.world(c.eye), scene.world(c.at));
        say!(
            "    {:<16} eye {} at {} fov {}",
            format!("\"{}\"", c.name().unwrap_or("?")),
            point(eye, 3),
            point(at, 3),
            c.fov_deg
        );
    }
    say!("  lights");
    for (i, l) in scene.lights.iter().enumerate() {
        let p = scene.world(l.position);
        say!(
            "    light {:<10} at {} colour ({:.2}, {:.2}, {:.2})",
            i + 1,
            point(p, 3),
            l.colour[0],
            l.colour[1],
            l.colour[2]
        );
    }
    say!("  materials");
    for (i, (m, name)) in scene.materials.iter().zip(&scene.material_names).enumerate() {
        let kind = if m.kr > 0.0 {
            format!("mirror kr {}", m.kr)
        } else if m.kt > 0.0 {
            format!("glass kt {} ior {}", m.kt, m.ior)
        } else {
            "opaque".to_owned()
        };
        say!("    {i:>3} {:<20} kd {:?} ks {:?} n {} {kind}", name, m.kd, m.ks, m.shininess);
    }
    Ok(())
}
