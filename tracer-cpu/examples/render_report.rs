//! Whole images against their rays: how close `render` comes to the speed of the traversal alone.
//!
//! For each scene, mode and method, one frame is rendered with its ray tracing recorded (every
//! call the Whitted driver makes: each stage's rays of each 4 x 2 block); then, on each thread
//! count, rounds interleave (a) a whole frame as `trace-cpu render` times it (`plan`, then
//! `render_into`: auto's measurement, primary rays, tracing, shading, the 8-bit image, no AOVs)
//! into the buffers of the round before (`Canvas::reuse`: memory already paged in, as trace-cpu
//! pages its image in before its clock and as the ray report reuses its output), (b) the recorded calls replayed through the renderer's
//! tracing for the method (`Plan::lanes`, for auto with the pick that pool measured) on the same
//! pool, with nothing else, and (c) for ray casting from the "medium" camera, the ray report's
//! primary-ray pass (`examples/ray_report.rs`: the same rays, in chunks of two rows) with the
//! engine that traces the frame's primary rays (packets, or single rays of the method's
//! traversal). Each figure is rays / median time. Every method `trace-cpu --method` takes is
//! accepted (`Method::ALL`).
//!
//! ```text
//! cargo run --release -p tracer-cpu --example render_report -- [options]
//!   --scene NAME=PATH   a scene (.bvh, or a mesh / description compiled with the default
//!                       settings); repeatable [default: dragon=scenes/dragon.toml]
//!   --camera NAME       stored camera [default: medium]
//!   --size WxH          [default: 1920x1440]
//!   --threads LIST      e.g. 1,16 [default: 1 and all]
//!   --modes LIST        cast,whitted [default: both]
//!   --methods LIST      any of trace-cpu's: auto,packet,ordered,stackless,bvh8,bvh4,bvh8-packet [default: packet]
//!   --reps N            at least N interleaved rounds, and at least 2 s of them [default: 5]
//!   --clock wall|cpu    time passes by the wall clock, or by the CPU time of the process's
//!                       threads (rays per CPU-second; for a machine shared with other work,
//!                       where waiting for a core would otherwise count) [default: wall]
//!   --out PATH          also write the Markdown here (- for none, as the ray report)
//! ```

#[path = "../benches/rayset/mod.rs"]
mod rayset;

use rayon::prelude::*;
use render_spec::{CameraSpec, Intersect, Mode, Settings};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use tracer_cpu::lanes::{Stage, TraceLanes};
use tracer_cpu::packet::{Rays, Results};
use tracer_cpu::render::{Canvas, Tiles, plan, render_into, render_with};
use tracer_cpu::{Method, Tracer};

struct Options {
    scenes: Vec<(String, PathBuf)>,
    camera: String,
    size: (u32, u32),
    threads: Vec<usize>,
    modes: Vec<Mode>,
    methods: Vec<Method>,
    reps: usize,
    clock: rayset::Clock,
    out: Option<PathBuf>,
}

fn parse_args() -> Result<Options, String> {
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    let dir = if Path::new("scenes").is_dir() { PathBuf::from("scenes") } else { rayset::scenes_dir() };
    let mut o = Options {
        scenes: Vec::new(),
        camera: "medium".into(),
        size: (1920, 1440),
        threads: if all > 1 { vec![1, all] } else { vec![1] },
        modes: vec![Mode::Cast, Mode::Whitted],
        methods: vec![Method::Packet],
        reps: 5,
        clock: rayset::Clock::Wall,
        out: None,
    };
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().ok_or_else(|| format!("{a} needs a value"));
        let list = |v: String| v.split(',').map(|s| s.trim().to_owned()).collect::<Vec<_>>();
        match a.as_str() {
            "--scene" => {
                let v = value()?;
                let (name, path) = v.split_once('=').ok_or("--scene takes NAME=PATH")?;
                o.scenes.push((name.to_owned(), PathBuf::from(path)));
            }
            "--camera" => o.camera = value()?,
            "--size" => {
                let v = value()?;
                let (w, h) = v.split_once('x').ok_or(format!("bad size {v:?}"))?;
                o.size = (
                    w.parse().map_err(|_| format!("bad size {v:?}"))?,
                    h.parse().map_err(|_| format!("bad size {v:?}"))?,
                );
            }
            "--threads" => {
                o.threads = list(value()?)
                    .iter()
                    .map(|t| t.parse().map_err(|_| format!("bad thread count {t:?}")))
                    .collect::<Result<_, _>>()?
            }
            "--modes" => {
                o.modes = list(value()?)
                    .iter()
                    .map(|m| match m.as_str() {
                        "cast" => Ok(Mode::Cast),
                        "whitted" => Ok(Mode::Whitted),
                        _ => Err(format!("bad mode {m:?}")),
                    })
                    .collect::<Result<_, _>>()?
            }
            "--methods" => {
                o.methods = list(value()?)
                    .iter()
                    .map(|m| Method::named(m).ok_or_else(|| format!("bad method {m:?} (one of {})", Method::names())))
                    .collect::<Result<_, _>>()?
            }
            "--reps" => o.reps = value()?.parse().map_err(|_| "--reps takes a number")?,
            "--out" => {
                let v = value()?;
                o.out = (v != "-").then(|| PathBuf::from(v));
            }
            "--clock" => {
                o.clock = match value()?.as_str() {
                    "wall" => rayset::Clock::Wall,
                    "cpu" => rayset::Clock::Cpu,
                    c => return Err(format!("bad clock {c:?} (wall or cpu)")),
                }
            }
            "-h" | "--help" => {
                eprintln!("see the top of tracer-cpu/examples/render_report.rs for the options");
                std::process::exit(0);
            }
            _ => return Err(format!("unknown argument {a:?}")),
        }
    }
    if o.scenes.is_empty() {
        o.scenes.push(("dragon".into(), dir.join("dragon.toml")));
    }
    Ok(o)
}

/// One call of the driver: the rays of one stage of one block.
#[derive(Clone, Copy)]
struct Call {
    stage: Stage,
    any: bool,
    rays: Rays,
    test: Intersect,
}

/// Traces through `inner` and keeps every call; hands its calls to `sink` when dropped.
struct Recorder<'s, T> {
    inner: T,
    calls: Vec<Call>,
    sink: &'s Mutex<Vec<Call>>,
}

impl<T: TraceLanes> TraceLanes for Recorder<'_, T> {
    fn closest(&mut self, rays: &Rays, test: Intersect) -> Results {
        self.closest_in(Stage::Primary, rays, test)
    }
    fn occluded(&mut self, rays: &Rays, test: Intersect) -> Results {
        self.occluded_in(Stage::Shadow, rays, test)
    }
    fn closest_in(&mut self, stage: Stage, rays: &Rays, test: Intersect) -> Results {
        self.calls.push(Call { stage, any: false, rays: *rays, test });
        self.inner.closest_in(stage, rays, test)
    }
    fn occluded_in(&mut self, stage: Stage, rays: &Rays, test: Intersect) -> Results {
        self.calls.push(Call { stage, any: true, rays: *rays, test });
        self.inner.occluded_in(stage, rays, test)
    }
}

impl<T> Drop for Recorder<'_, T> {
    fn drop(&mut self) {
        self.sink.lock().expect("no recorder panicked").append(&mut self.calls);
    }
}

/// Replays recorded calls on the current pool, in order, in chunks of about a band's worth.
fn replay<T: TraceLanes>(lanes: impl Fn() -> T + Sync + Send, calls: &[Call]) {
    calls.par_chunks(256).for_each_init(lanes, |lanes, chunk| {
        for c in chunk {
            let r = if c.any {
                lanes.occluded_in(c.stage, &c.rays, c.test)
            } else {
                lanes.closest_in(c.stage, &c.rays, c.test)
            };
            std::hint::black_box(r);
        }
    });
}

struct Row {
    scene: String,
    mode: Mode,
    /// The method as the frame ran it (auto with its choice per kind of ray).
    method: String,
    threads: usize,
    rays: u64,
    render: f64,
    alone: f64,
    ray_report: Option<f64>,
}

impl Row {
    /// The method without auto's choice, which may differ between thread counts.
    fn method_name(&self) -> &str {
        self.method.split(" (").next().unwrap_or(&self.method)
    }
}

fn main() {
    let opts = parse_args().unwrap_or_else(|e| {
        eprintln!("render_report: {e}");
        std::process::exit(2)
    });
    let load_before = rayset::loadavg();
    let started = std::time::Instant::now();
    let pools: Vec<_> = opts
        .threads
        .iter()
        .map(|&n| (n, rayon::ThreadPoolBuilder::new().num_threads(n).build().expect("a thread pool")))
        .collect();
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("a thread pool");
    let mut rows = Vec::new();
    for (name, path) in &opts.scenes {
        let scene = rayset::open(path).unwrap_or_else(|e| fail(&e));
        let tracer = Tracer::new(&scene);
        let camera = CameraSpec::from(scene.camera(&opts.camera).unwrap_or_else(|| fail("no such camera")));
        let (w, h) = opts.size;
        for &mode in &opts.modes {
            for &method in &opts.methods {
                let settings = Settings::of_scene(&scene, camera, mode, (w, h));
                let sink = Mutex::new(Vec::new());
                let image = one
                    .install(|| {
                        let plan = plan(&tracer, &settings, method)?;
                        render_with(
                            &tracer,
                            &settings,
                            plan.method(),
                            || Recorder { inner: plan.lanes(), calls: Vec::new(), sink: &sink },
                            Tiles::default(),
                            &|_| {},
                        )
                    })
                    .unwrap_or_else(|e| fail(&e.to_string()));
                let calls = sink.into_inner().expect("no recorder panicked");
                let rays = image.rays.total();
                let recorded: u64 = calls.iter().map(|c| c.rays.count() as u64).sum();
                assert_eq!(recorded, rays, "the recorded calls hold every ray of the image");
                let primary_set = (mode == Mode::Cast && opts.camera == "medium").then(|| {
                    rayset::generate(&scene, w, h).unwrap_or_else(|e| fail(&e)).into_iter().next().expect("five sets")
                });
                for (threads, pool) in &pools {
                    // Auto's choice as this pool measures it, for the replay and the ray report's pass.
                    let plan =
                        pool.install(|| plan(&tracer, &settings, method)).unwrap_or_else(|e| fail(&e.to_string()));
                    let engine = match plan.method() {
                        Method::Packet => rayset::Engine::Packet(&tracer),
                        Method::Bvh8Packet => rayset::Engine::WidePacket(&tracer),
                        Method::Auto if plan.packet_stages()[Stage::Primary.index()] => {
                            rayset::Engine::WidePacket(&tracer)
                        }
                        m => rayset::Engine::Scalar(tracer.walk(m).expect("planned"), Intersect::Watertight),
                    };
                    let mut out = vec![rayset::NO_RAY; (w * h) as usize];
                    // The first (untimed) frame pages its buffers in; the timed ones reuse them.
                    let mut buffers = None;
                    let mut a = || {
                        let canvas = buffers.take().unwrap_or_else(|| Canvas::new(&settings));
                        let image = pool
                            .install(|| {
                                let frame = tracer_cpu::render::plan(&tracer, &settings, method)?;
                                render_into(&tracer, &settings, &frame, canvas, &|_| {})
                            })
                            .expect("renders");
                        buffers = Some(Canvas::reuse(image));
                    };
                    let mut b = || pool.install(|| replay(|| plan.lanes(), &calls));
                    let mut c = || {
                        if let Some(set) = &primary_set {
                            pool.install(|| rayset::trace(engine, set, &mut out));
                        }
                    };
                    a();
                    b();
                    c();
                    let t =
                        rayset::interleaved_medians_on(opts.clock, opts.reps, 2.0, 50, &mut [&mut a, &mut b, &mut c]);
                    let row = Row {
                        scene: name.clone(),
                        mode,
                        method: plan.describe(),
                        threads: *threads,
                        rays,
                        render: rays as f64 / t[0] / 1e6,
                        alone: rays as f64 / t[1] / 1e6,
                        ray_report: primary_set.as_ref().map(|s| s.count as f64 / t[2] / 1e6),
                    };
                    eprintln!(
                        "{name} {mode:?} {} {threads} threads: render {:.2}, traced alone {:.2}, ray report {} Mrays/s",
                        row.method,
                        row.render,
                        row.alone,
                        row.ray_report.map_or("-".into(), |r| format!("{r:.2}"))
                    );
                    rows.push(row);
                }
            }
        }
    }
    let md = markdown(&opts, &rows, &load_before, started.elapsed().as_secs_f64());
    print!("{md}");
    if let Some(p) = &opts.out {
        rayset::write_report(p, &md).unwrap_or_else(|e| fail(&format!("{e}.")));
    }
}

fn fail(msg: &str) -> ! {
    eprintln!("render_report: {msg}");
    std::process::exit(1)
}

fn markdown(opts: &Options, rows: &[Row], load_before: &str, seconds: f64) -> String {
    let mut s = String::new();
    let nproc = std::thread::available_parallelism().map_or(0, |n| n.get());
    let command: Vec<String> = std::env::args().collect();
    let _ = writeln!(s, "- Machine: CPU `{}`, `nproc` = {nproc}", rayset::cpu_model());
    let _ = writeln!(s, "- Load average (1, 5, 15 min): {load_before} before, {} after", rayset::loadavg());
    let _ = writeln!(s, "- Command: `{}` ({seconds:.0} s in all)", command.join(" "));
    let _ = writeln!(
        s,
        "- {} from camera `{}`, the scene's lights and indirections; Mrays/s = the frame's rays / median {} of \
         at least {} interleaved rounds and 2 s; render = what `trace-cpu render` times (auto's measurement, tracing, \
         shading into the 8-bit image already paged in)\n",
        format_args!("{}x{}", opts.size.0, opts.size.1),
        opts.camera,
        match opts.clock {
            rayset::Clock::Wall => "wall-clock time",
            rayset::Clock::Cpu => "CPU time of all threads (rays per CPU-second)",
        },
        opts.reps
    );
    s.push_str(
        "| scene | mode | method | threads | rays | render Mrays/s | traced alone | render / alone | ray report | render / ray report | render / 1 thread |\n",
    );
    s.push_str("|---|---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for r in rows {
        let single = rows
            .iter()
            .find(|o| o.threads == 1 && o.scene == r.scene && o.mode == r.mode && o.method_name() == r.method_name())
            .map_or("-".into(), |o| format!("{:.1}x", r.render / o.render));
        let _ = writeln!(
            s,
            "| {} | {:?} | {} | {} | {} | {:.2} | {:.2} | {:.0}% | {} | {} | {single} |",
            r.scene,
            r.mode,
            r.method,
            r.threads,
            r.rays,
            r.render,
            r.alone,
            100.0 * r.render / r.alone,
            r.ray_report.map_or("-".into(), |x| format!("{x:.2}")),
            r.ray_report.map_or("-".into(), |x| format!("{:.0}%", 100.0 * r.render / x)),
        );
    }
    s
}
