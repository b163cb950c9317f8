//! The whole CPU ray-throughput report: primary, shadow, secondary, AO and diffuse rays per second
//! on the bunny, the dragon and the million-triangle scene at 640 x 480 and 1920 x 1440, one
//! thread and all threads, ours (ordered, AVX2 packets, the wide BVH) against Embree (single rays,
//! default and robust scene flags, and 8-ray packets) tracing the same rays on the same triangles. Prints
//! the report as markdown to stdout, and writes it to the file `--out` names; progress goes to
//! stderr. (docs/cpu-benchmark.md is written by hand from such reports; the report never writes it.)
//!
//! ```text
//! cargo run --release -p tracer-cpu --features embree --example ray_report -- [options]
//!   --scene NAME=PATH   a scene to measure (repeatable; default bunny, dragon and million from
//!                       scenes/, or from the checkout's scenes/ when ./scenes does not exist)
//!   --out PATH          also write the markdown to this file (default: none; - for none), whole
//!                       or not at all
//!   --reps N            least timed rounds per measurement, the median is reported (default 5;
//!                       scenes over 500k triangles at 1920 x 1440 use half, at least 2; quick
//!                       cases run more rounds, up to 2 s)
//!   --threads LIST      thread counts, e.g. 1,16 (default 1 and all)
//!   --sizes LIST        e.g. 640x480,1920x1440 (the default)
//!   --clock wall|cpu    time passes by the wall clock (the default), or by the CPU time of the
//!                       process's threads (rays per CPU-second: for a machine shared with other
//!                       work, where waiting for a core would count as tracing)
//!   --kinds LIST        ray kinds to time, e.g. primary,shadow (default all five)
//!   --engines LIST      only these tracers, by their column names, comma-separated, e.g.
//!                       "ours bvh4,ours bvh8 packet,Embree 8,Embree 8 robust" [default: all];
//!                       Embree 1 always runs (the hit agreement's reference); the others read `-`
//! EMBREE_FTZ=1          in the environment: Embree's passes run with flush-to-zero and
//!                       denormals-are-zero set, as Embree asks of applications (ours never)
//! EMBREE_CONFIG=STRING  in the environment: Embree's device configuration (`rtcNewDevice`'s
//!                       string, e.g. "frequency_level=simd512" or "verbose=3")
//! ```
//!
//! Built once, the binary runs anywhere with the Embree 3 shared library (libembree3-3 and its
//! dependency libtbb12 on Debian and Ubuntu): copy it with `scenes/` and pass `--scene` paths.

#[path = "../benches/rayset/mod.rs"]
mod rayset;

use rayset::{Engine, Kind, RaySet};
use render_spec::Intersect;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;
use tracer_cpu::bvh8::{Simd, WideBvh};
use tracer_cpu::embree::{self, Flags};
use tracer_cpu::{Method, Tracer, packet, packet8};

/// The tracers of the table, in column order.
/// "ours ordered MT" is the ordered traversal with Möller-Trumbore (`--intersect mt`), the test
/// before issue 16, so the edge-consistent test's cost is measured beside Embree in one run.
/// "ours bvh8" is the wide BVH one ray at a time (`--method bvh8`), "ours bvh8 MT" the same with
/// Möller-Trumbore.
/// "ours bvh8" runs the path `trace-cpu` takes (the widest the CPU has: AVX-512 or AVX2), "ours
/// bvh8 AVX2" the AVX2 path forced (`-` on a CPU without it); "ours bvh8 packet" is `--method
/// bvh8-packet`, 8-ray packets on the wide BVH; "ours bvh4" the 4-wide BVH one ray at a time
/// (`--method bvh4`). "Embree 8 robust" is `rtcIntersect8` on the robust scene.
const ENGINES: [&str; 12] = [
    "ours ordered",
    "ours packet",
    "ours bvh8",
    "ours bvh8 AVX2",
    "ours bvh8 packet",
    "Embree 1",
    "Embree 1 robust",
    "Embree 8",
    "Embree 8 robust",
    "ours ordered MT",
    "ours bvh8 MT",
    "ours bvh4",
];
const PACKET: usize = 1;
const BVH8: usize = 2;
const AVX2: usize = 3;
const WIDE_PACKET: usize = 4;
const EMBREE1: usize = 5;
const ROBUST: usize = 6;
const EMBREE8: usize = 7;
const EMBREE8_ROBUST: usize = 8;
const BVH8_MT: usize = 10;
const BVH4: usize = 11;
/// Timed rounds go on at least this long per (ray set, thread count), so that the quick cases are
/// not a handful of 30 ms samples on a shared machine ...
const MIN_SECONDS: f64 = 2.0;
/// ... nor more than this many rounds.
const MAX_ROUNDS: usize = 25;

struct Options {
    scenes: Vec<(String, PathBuf)>,
    out: Option<PathBuf>,
    reps: usize,
    threads: Vec<usize>,
    sizes: Vec<(u32, u32)>,
    clock: rayset::Clock,
    kinds: Vec<Kind>,
    /// The tracers to run ([`ENGINES`] indices), all by default.
    engines: Vec<usize>,
}

fn parse_args() -> Result<Options, String> {
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    let dir = if Path::new("scenes").is_dir() { PathBuf::from("scenes") } else { rayset::scenes_dir() };
    let mut o = Options {
        scenes: Vec::new(),
        out: None,
        reps: 5,
        threads: if all > 1 { vec![1, all] } else { vec![1] },
        sizes: vec![(640, 480), (1920, 1440)],
        clock: rayset::Clock::Wall,
        kinds: Kind::ALL.to_vec(),
        engines: (0..ENGINES.len()).collect(),
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().ok_or_else(|| format!("{a} needs a value"));
        match a.as_str() {
            "--scene" => {
                let v = value()?;
                let (name, path) = v.split_once('=').ok_or("--scene takes NAME=PATH")?;
                o.scenes.push((name.to_owned(), PathBuf::from(path)));
            }
            "--out" => {
                let v = value()?;
                o.out = (v != "-").then(|| PathBuf::from(v));
            }
            "--reps" => o.reps = value()?.parse().map_err(|_| "--reps takes a number")?,
            "--threads" => {
                o.threads = value()?
                    .split(',')
                    .map(|t| t.trim().parse().map_err(|_| format!("bad thread count {t:?}")))
                    .collect::<Result<_, _>>()?
            }
            "--sizes" => {
                o.sizes = value()?
                    .split(',')
                    .map(|s| {
                        let (w, h) = s.split_once('x').ok_or(format!("bad size {s:?}"))?;
                        Ok((
                            w.parse().map_err(|_| format!("bad size {s:?}"))?,
                            h.parse().map_err(|_| format!("bad size {s:?}"))?,
                        ))
                    })
                    .collect::<Result<_, String>>()?
            }
            "--clock" => {
                o.clock = match value()?.as_str() {
                    "wall" => rayset::Clock::Wall,
                    "cpu" => rayset::Clock::Cpu,
                    c => return Err(format!("bad clock {c:?} (wall or cpu)")),
                }
            }
            "--kinds" => {
                o.kinds = value()?
                    .split(',')
                    .map(|k| {
                        Kind::ALL.into_iter().find(|x| x.name() == k.trim()).ok_or(format!("unknown ray kind {k:?}"))
                    })
                    .collect::<Result<_, _>>()?
            }
            "--engines" => {
                o.engines = value()?
                    .split(',')
                    .map(|e| {
                        ENGINES
                            .iter()
                            .position(|n| *n == e.trim())
                            .ok_or_else(|| format!("unknown engine {e:?} (one of {})", ENGINES.join(", ")))
                    })
                    .collect::<Result<_, _>>()?;
                o.engines.push(EMBREE1);
                o.engines.sort_unstable();
                o.engines.dedup();
            }
            "-h" | "--help" => {
                eprintln!("see the top of tracer-cpu/examples/ray_report.rs for the options");
                std::process::exit(0);
            }
            _ => return Err(format!("unknown argument {a:?}")),
        }
    }
    if o.scenes.is_empty() {
        o.scenes =
            ["bunny", "dragon", "million"].iter().map(|n| (n.to_string(), dir.join(format!("{n}.toml")))).collect();
    }
    Ok(o)
}

/// One measured (scene, size, kind, threads) line: Mrays/s per engine (None where it cannot run).
struct Row {
    scene: String,
    size: (u32, u32),
    kind: Kind,
    rays: usize,
    threads: usize,
    mrays: [Option<f64>; ENGINES.len()],
}

/// Hit agreement of each engine with Embree's default single-ray results, per ray set.
struct Agreement {
    scene: String,
    size: (u32, u32),
    kind: Kind,
    rays: usize,
    agree: [Option<(usize, usize)>; ENGINES.len()],
}

fn sh(cmd: &str, args: &[&str]) -> String {
    std::process::Command::new(cmd)
        .args(args)
        .output()
        .ok()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_owned())
        .unwrap_or_default()
}

fn main() {
    let opts = parse_args().unwrap_or_else(|e| {
        eprintln!("ray_report: {e}");
        std::process::exit(2)
    });
    let started = Instant::now();
    let load_before = rayset::loadavg();
    let pools: Vec<_> = opts
        .threads
        .iter()
        .map(|&n| (n, rayon::ThreadPoolBuilder::new().num_threads(n).build().expect("a thread pool")))
        .collect();
    let all_pool = &pools.last().expect("at least one thread count").1;
    let mut rows = Vec::new();
    let mut agreements = Vec::new();
    let mut scene_lines = Vec::new();

    for (name, path) in &opts.scenes {
        let t = Instant::now();
        let scene = rayset::load(path).unwrap_or_else(|e| {
            eprintln!("ray_report: {e}");
            std::process::exit(1)
        });
        let n_tris = scene.triangles.len();
        eprintln!("{name}: {n_tris} triangles, compiled in {:.1} s", t.elapsed().as_secs_f64());
        let t = Instant::now();
        let em = embree::Scene::new(&scene.leaf_triangles(), Flags::Default).expect("Embree builds the scene");
        let em_robust = embree::Scene::new(&scene.leaf_triangles(), Flags::Robust).expect("Embree builds the scene");
        eprintln!("{name}: Embree's two BVHs built in {:.1} s (not timed below)", t.elapsed().as_secs_f64());
        let tracer = Tracer::new(&scene);
        let wide = format!(
            "{}; Embree's BVH with its triangles {:.1} MB (robust mode {:.1} MB)",
            collapse_cost(&scene, &tracer),
            em.bvh_bytes() as f64 / 1e6,
            em_robust.bvh_bytes() as f64 / 1e6
        );
        eprintln!("{name}: {wide}");
        scene_lines.push(format!("{name} ({n_tris} triangles, {}; {wide})", path.display()));
        let mut engines: [Option<Engine>; ENGINES.len()] = [
            tracer.walk(Method::Ordered).ok().map(|w| Engine::Scalar(w, Intersect::Watertight)),
            packet::available().then_some(Engine::Packet(&tracer)),
            tracer.walk(Method::Bvh8).ok().map(|w| Engine::Scalar(w, Intersect::Watertight)),
            (tracer.bvh8().is_some() && Simd::Avx2.supported()).then_some(Engine::Bvh8(&tracer, Simd::Avx2)),
            (tracer.bvh8().is_some() && packet8::available()).then_some(Engine::WidePacket(&tracer)),
            Some(Engine::Embree1(&em)),
            Some(Engine::Embree1(&em_robust)),
            Some(Engine::Embree8(&em)),
            Some(Engine::Embree8(&em_robust)),
            tracer.walk(Method::Ordered).ok().map(|w| Engine::Scalar(w, Intersect::MollerTrumbore)),
            tracer.walk(Method::Bvh8).ok().map(|w| Engine::Scalar(w, Intersect::MollerTrumbore)),
            tracer.walk(Method::Bvh4).ok().map(|w| Engine::Scalar(w, Intersect::Watertight)),
        ];
        for (i, e) in engines.iter_mut().enumerate() {
            if !opts.engines.contains(&i) {
                *e = None;
            }
        }

        for &(w, h) in &opts.sizes {
            let t = Instant::now();
            let sets: [RaySet; 5] = all_pool.install(|| rayset::generate(&scene, w, h)).unwrap_or_else(|e| {
                eprintln!("ray_report: {name}: {e}");
                std::process::exit(1)
            });
            eprintln!("{name} {w}x{h}: ray sets generated in {:.1} s", t.elapsed().as_secs_f64());
            let reps = if n_tris > 500_000 && w * h > 1_000_000 { big_reps(opts.reps) } else { opts.reps };
            for set in sets.iter().filter(|s| opts.kinds.contains(&s.kind)) {
                // One untimed pass of every engine on all threads gives the outputs to compare.
                let outputs: Vec<Option<Vec<f32>>> = engines
                    .iter()
                    .map(|e| {
                        e.map(|e| {
                            let mut out = vec![rayset::NO_RAY; set.rays.len()];
                            all_pool.install(|| rayset::trace(e, set, &mut out));
                            out
                        })
                    })
                    .collect();
                let reference = outputs[EMBREE1].as_ref().expect("Embree always runs");
                agreements.push(Agreement {
                    scene: name.clone(),
                    size: (w, h),
                    kind: set.kind,
                    rays: set.count,
                    agree: std::array::from_fn(|i| outputs[i].as_ref().map(|o| rayset::agreement(o, reference))),
                });
                drop(outputs);
                let mut outs: Vec<Vec<f32>> = engines.iter().map(|_| vec![rayset::NO_RAY; set.rays.len()]).collect();
                for (threads, pool) in &pools {
                    let mut passes: Vec<(usize, Box<dyn FnMut() + '_>)> = Vec::new();
                    for ((i, e), out) in engines.iter().enumerate().zip(outs.iter_mut()) {
                        let Some(e) = *e else { continue };
                        passes.push((i, Box::new(move || pool.install(|| rayset::trace(e, set, out)))));
                    }
                    let mut refs: Vec<&mut dyn FnMut()> =
                        passes.iter_mut().map(|(_, p)| &mut **p as &mut dyn FnMut()).collect();
                    let medians = rayset::interleaved_medians_on(opts.clock, reps, MIN_SECONDS, MAX_ROUNDS, &mut refs);
                    let mut mrays = [None; ENGINES.len()];
                    for ((i, _), s) in passes.iter().zip(medians) {
                        mrays[*i] = Some(set.count as f64 / s / 1e6);
                    }
                    eprintln!(
                        "{name} {w}x{h} {:9} {threads:2} threads: {}",
                        set.kind.name(),
                        mrays.iter().map(|m| m.map_or("-".into(), |m| format!("{m:.2}"))).collect::<Vec<_>>().join(" ")
                    );
                    rows.push(Row {
                        scene: name.clone(),
                        size: (w, h),
                        kind: set.kind,
                        rays: set.count,
                        threads: *threads,
                        mrays,
                    });
                }
            }
        }
    }

    let md = markdown(&opts, &rows, &agreements, &scene_lines, &load_before, started.elapsed().as_secs_f64());
    print!("{md}");
    if let Some(out) = &opts.out {
        match rayset::write_report(out, &md) {
            Ok(()) => eprintln!("wrote {}", out.display()),
            Err(e) => {
                eprintln!("ray_report: {e}.");
                std::process::exit(1);
            }
        }
    }
}

/// What deriving the wide BVHs at load costs: the median of 5 collapses on one thread and on all
/// of them, and their sizes. (`tracer.bvh8()` and `tracer.bvh4()` keep one of their own, made
/// here before any timing.)
fn collapse_cost(scene: &bvh_format::SceneFile, tracer: &Tracer<'_>) -> String {
    let (Some(nodes), Some(bvh8), Some(bvh4)) = (scene.child_pair.as_deref(), tracer.bvh8(), tracer.bvh4()) else {
        return "no child-pair layout, no wide BVH".into();
    };
    format!("{}; {}", collapse_line(nodes, tracer, bvh8), collapse_line(nodes, tracer, bvh4))
}

fn collapse_line<const W: usize>(nodes: &[bvh_format::Node], tracer: &Tracer<'_>, bvh: &WideBvh<W>) -> String {
    let median = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a thread pool");
        let mut times: Vec<f64> = (0..5)
            .map(|_| {
                let t = Instant::now();
                std::hint::black_box(pool.install(|| WideBvh::<W>::from_source(nodes, &tracer.triangles())));
                t.elapsed().as_secs_f64()
            })
            .collect();
        times.sort_by(f64::total_cmp);
        times[2] * 1e3
    };
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    let ((n, b), bytes) = (bvh.len(), bvh.bytes());
    format!(
        "bvh{W} collapsed at load in {:.1} ms on one thread, {:.1} ms on {all} (medians of 5): {n} wide nodes, {b} leaf blocks, {:.1} MB",
        median(1),
        median(all),
        bytes as f64 / 1e6
    )
}

/// Rounds for the big dense cases, whose passes take seconds: fewer keep the whole run short.
fn big_reps(reps: usize) -> usize {
    reps.div_ceil(2).max(2)
}

/// What a reader of the generated file needs before the numbers; the machine sections follow.
const PREFACE: &str = "# CPU ray throughput: ours against Embree

Generated by `tracer-cpu/examples/ray_report.rs` (see its header for the options). Million rays per
second for primary rays (the scene's \"medium\" camera, one per pixel), shadow rays (from every
primary hit to the scene's first light, origin offset with `geometry::offset_origin` to the light's
side, `t_max` = distance to the light, any hit ends them), secondary rays (the mirror reflection
of every primary ray at its hit about the shading normal, offset origin), AO rays (one per primary
hit: `--mode ao`'s first ray, cosine-distributed about the geometric normal, 10% of the scene's
diagonal long, any hit ends them) and diffuse rays (the same directions, closest hit, no length
limit), generated once per scene and resolution and traced unchanged by every tracer on the scene
file's triangles:

- ours ordered: `Tracer::closest`/`occluded` with `Method::Ordered` (child-pair tree, stack), one
  ray at a time;
- ours packet: `packet::trace`, 8-wide AVX2 over the child-pair tree, 4 x 2 pixel blocks as the
  renderer forms them;
- ours bvh8: `Method::Bvh8`, the wide BVH (`tracer-cpu/src/bvh8.rs`: 8 children per node and up to
  8 triangles per leaf, structure of arrays, collapsed at load from the child-pair tree) one ray
  at a time, all children's boxes or all of a leaf's triangles in one sequence of 256-bit
  operations, compiled for AVX-512 (32 registers) where the CPU has it; ours bvh8 AVX2: the same
  compiled for AVX2 only (`TRACER_CPU_SIMD=avx2`); ours bvh8 packet:
  `Method::Bvh8Packet` (`tracer-cpu/src/packet8.rs`), 8-ray AVX2 packets of the same 4 x 2 blocks
  on the wide BVH; ours bvh4: `Method::Bvh4`, the 4-wide BVH collapsed the same way (4 children
  per node, up to 4 triangles per leaf) one ray at a time, one 128-bit sequence per node or leaf;
- Embree 1 / Embree 1 robust: Embree 3's `rtcIntersect1`/`rtcOccluded1` on a BVH Embree builds
  (default medium quality) over the same triangles (`v0`, `v0 + e1`, `v0 + e2`), default scene
  flags / `RTC_SCENE_FLAG_ROBUST`; Embree 8 / Embree 8 robust: `rtcIntersect8`/`rtcOccluded8` on
  the same 4 x 2 blocks (coherent context) of the two scenes; ours ordered MT and ours bvh8 MT: those two with Möller-Trumbore
  (`--intersect mt`) instead of the edge-consistent test. Only traversal is timed, never a build
  (the wide BVH's collapse, which a render pays once at load, is timed separately: Scenes line).

Threads: a rayon pool of the given size; the rays are handed out in chunks of two image rows.

";

fn ratio(a: Option<f64>, b: Option<f64>) -> String {
    match (a, b) {
        (Some(a), Some(b)) if b > 0.0 => format!("{:.0}%", 100.0 * a / b),
        _ => "-".into(),
    }
}

fn markdown(
    opts: &Options,
    rows: &[Row],
    agreements: &[Agreement],
    scenes: &[String],
    load_before: &str,
    seconds: f64,
) -> String {
    let mut s = String::new();
    let host = sh("hostname", &[]);
    let date = sh("date", &["-u", "+%Y-%m-%d %H:%M UTC"]);
    let nproc = std::thread::available_parallelism().map_or(0, |n| n.get());
    let command: Vec<String> = std::env::args().collect();
    s.push_str(PREFACE);
    let _ = writeln!(s, "## {} ({nproc} threads), {date}\n", rayset::cpu_model());
    let _ = writeln!(s, "- Machine: `{host}`, CPU `{}`, `nproc` = {nproc}, {}", rayset::cpu_model(), simd_flags());
    let _ = writeln!(s, "- Load average (1, 5, 15 min): {load_before} before, {} after", rayset::loadavg());
    let ftz = if rayset::embree_ftz() { "set for Embree's passes (`EMBREE_FTZ=1`)" } else { "not set (the default)" };
    let _ = writeln!(s, "- Flush-to-zero and denormals-are-zero (MXCSR): {ftz}; never for ours");
    let config = embree::config().map_or("Embree's defaults".to_string(), |c| format!("`{c}` (`EMBREE_CONFIG`)"));
    let _ = writeln!(s, "- Embree's device configuration: {config}");
    let _ = writeln!(s, "- Command: `{}` ({seconds:.0} s in all)", command.join(" "));
    let _ = writeln!(
        s,
        "- Each figure: rays traced / median {} of one pass over the whole ray set. Passes of the {} \
         tracers are interleaved round by round (so load changes hit all alike), after one untimed pass \
         of each on all threads, and each timed pass right after an untimed one of the same tracer (its \
         own data in the caches); at least {} rounds ({} for scenes over 500k triangles at 1920x1440) \
         and at least {MIN_SECONDS} s of timed passes per row, at most {MAX_ROUNDS} rounds",
        match opts.clock {
            rayset::Clock::Wall => "wall-clock time",
            rayset::Clock::Cpu => "CPU time of all threads (rays per CPU-second)",
        },
        opts.engines.len(),
        opts.reps,
        big_reps(opts.reps)
    );
    let _ = writeln!(s, "- Scenes: {}\n", scenes.join("; "));

    let _ = writeln!(
        s,
        "### Issue 11's targets: ours / Embree, same rays, same threads\n\nTargets: bvh8 >= 100% of Embree 1 \
         (default and robust) on every kind; packets >= 100% of Embree 8 (default and robust) on primary and \
         shadow rays. \
         bvh8: the path trace-cpu takes here ({}); bvh8 packet: 8-ray packets on the wide BVH. Like for \
         like: bvh8 (edge-consistent, watertight) against Embree's robust mode, bvh8 MT (Möller-Trumbore, \
         `--intersect mt`) against its default (Möller-Trumbore).\n",
        Simd::detect().name()
    );
    let _ = writeln!(
        s,
        "| scene | size | kind | threads | bvh8 / Embree 1 | bvh8 / Embree 1 robust | bvh8 AVX2 / Embree 1 | \
         bvh8 packet / Embree 8 | bvh8 packet / Embree 8 robust | packet / Embree 8 | bvh8 packet / Embree 1 | \
         bvh8 AVX2 / bvh8 | bvh4 / Embree 1 | bvh4 / Embree 1 robust | bvh4 / bvh8 | bvh8 MT / Embree 1 |"
    );
    let _ = writeln!(s, "|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    for r in rows {
        let _ = writeln!(
            s,
            "| {} | {}x{} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            r.scene,
            r.size.0,
            r.size.1,
            r.kind.name(),
            r.threads,
            ratio(r.mrays[BVH8], r.mrays[EMBREE1]),
            ratio(r.mrays[BVH8], r.mrays[ROBUST]),
            ratio(r.mrays[AVX2], r.mrays[EMBREE1]),
            ratio(r.mrays[WIDE_PACKET], r.mrays[EMBREE8]),
            ratio(r.mrays[WIDE_PACKET], r.mrays[EMBREE8_ROBUST]),
            ratio(r.mrays[PACKET], r.mrays[EMBREE8]),
            ratio(r.mrays[WIDE_PACKET], r.mrays[EMBREE1]),
            ratio(r.mrays[AVX2], r.mrays[BVH8]),
            ratio(r.mrays[BVH4], r.mrays[EMBREE1]),
            ratio(r.mrays[BVH4], r.mrays[ROBUST]),
            ratio(r.mrays[BVH4], r.mrays[BVH8]),
            ratio(r.mrays[BVH8_MT], r.mrays[EMBREE1]),
        );
    }

    let _ = writeln!(s, "\n### Throughput, million rays per second\n");
    let _ = writeln!(
        s,
        "| scene | size | rays | kind | threads | {} | bvh8 / Embree 1 | packet / Embree 1 |",
        ENGINES.join(" | ")
    );
    let _ = writeln!(s, "|---|---|---:|---|---:|{}---:|---:|", "---:|".repeat(ENGINES.len()));
    for r in rows {
        let cells: Vec<String> = r.mrays.iter().map(|m| m.map_or("-".into(), |m| format!("{m:.2}"))).collect();
        let _ = writeln!(
            s,
            "| {} | {}x{} | {} | {} | {} | {} | {} | {} |",
            r.scene,
            r.size.0,
            r.size.1,
            r.rays,
            r.kind.name(),
            r.threads,
            cells.join(" | "),
            ratio(r.mrays[BVH8], r.mrays[EMBREE1]),
            ratio(r.mrays[PACKET], r.mrays[EMBREE1]),
        );
    }

    let _ = writeln!(
        s,
        "\n### Hit agreement with Embree 1 (default flags)\n\nShare of rays with the same hit/miss \
         (for shadow rays: blocked/unblocked) and, for hits, `|t - t_embree| <= 1e-4 t_embree`.\n"
    );
    let others: Vec<usize> = (0..ENGINES.len()).filter(|&i| i != EMBREE1).collect();
    let _ = writeln!(
        s,
        "| scene | size | kind | rays | {} |",
        others.iter().map(|&i| ENGINES[i]).collect::<Vec<_>>().join(" | ")
    );
    let _ = writeln!(s, "|---|---|---|---:|{}", "---:|".repeat(others.len()));
    for a in agreements {
        let cells: Vec<String> =
            others.iter().map(|&i| a.agree[i].map_or("-".into(), |(same, n)| agree_cell(same, n))).collect();
        let _ = writeln!(
            s,
            "| {} | {}x{} | {} | {} | {} |",
            a.scene,
            a.size.0,
            a.size.1,
            a.kind.name(),
            a.rays,
            cells.join(" | ")
        );
    }
    s.push('\n');
    s
}

fn agree_cell(same: usize, n: usize) -> String {
    let pct = if n == 0 { 100.0 } else { 100.0 * same as f64 / n as f64 };
    format!("{pct:.3}% ({} differ)", n - same)
}

fn simd_flags() -> String {
    let cpuinfo = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let flags = cpuinfo.lines().find(|l| l.starts_with("flags")).unwrap_or("");
    let has = |f: &str| flags.split_whitespace().any(|x| x == f);
    let list: Vec<&str> = ["avx2", "fma", "avx512f"].into_iter().filter(|f| has(f)).collect();
    format!("SIMD: {}", if list.is_empty() { "none of avx2/fma/avx512f".into() } else { list.join(", ") })
}
