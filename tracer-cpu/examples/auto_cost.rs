//! What `--method auto`'s measurement costs a frame, and what it decides: for each scene, mode
//! and thread count, rounds of `plan` (the measurement) then `render_into` (the rest of the frame
//! `trace-cpu render` times) into the buffers of the round before, each timed by the wall clock
//! and by the CPU time of the process's threads. Prints the medians, the measurement's share of
//! the whole frame, the picks of every round (how often each came) and, per stage, the median
//! ratio of the single rays' time to the packets'.
//!
//! ```text
//! cargo run --release -p tracer-cpu --example auto_cost -- [options]
//!   --scene NAME=PATH   a scene (.bvh, or a mesh / description compiled with the default
//!                       settings); repeatable [default: bunny=scenes/bunny.toml]
//!   --size WxH          [default: 1920x1440]
//!   --threads LIST      e.g. 1,2 [default: 1 and all]
//!   --modes LIST        cast,whitted,ao,diffuse [default: cast,whitted]
//!   --reps N            rounds [default: 9]
//! ```

#[path = "../benches/rayset/mod.rs"]
mod rayset;

use bvh_format::SceneFile;
use render_spec::{CameraSpec, Mode, Settings};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use tracer_cpu::lanes::Stage;
use tracer_cpu::render::{Canvas, StageTimer, WallClock, plan, plan_with, render_into};
use tracer_cpu::{Method, Tracer};

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// The wall clock, noting every timing: (thread, stage, packets, seconds).
#[derive(Default)]
struct Log(Mutex<Vec<(std::thread::ThreadId, usize, bool, f64)>>);

impl StageTimer for Log {
    fn time(&self, stage: Stage, packets: bool, rays: u64, trace: &mut dyn FnMut()) -> f64 {
        let t = WallClock.time(stage, packets, rays, trace);
        self.0.lock().unwrap().push((std::thread::current().id(), stage.index(), packets, t));
        t
    }
}

/// Per stage: the ratio single / packets of the first round alone, summed over the workers.
fn first_rounds(log: Log) -> [f64; 5] {
    let log = log.0.into_inner().unwrap();
    let mut out = [0.0; 5];
    for i in 0..5 {
        let (mut s, mut p) = (0.0, 0.0);
        let mut seen: BTreeMap<String, usize> = BTreeMap::new();
        for &(t, st, packets, secs) in &log {
            if st != i {
                continue;
            }
            let k = seen.entry(format!("{t:?}{packets}")).or_default();
            if *k % ROUNDS == 0 {
                if packets { p += secs } else { s += secs }
            }
            *k += 1;
        }
        out[i] = if p > 0.0 { s / p } else { 0.0 };
    }
    out
}

const ROUNDS: usize = 3;

fn fail(msg: &str) -> ! {
    eprintln!("auto_cost: {msg}");
    std::process::exit(2)
}

fn main() {
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    let (mut scenes, mut size, mut threads, mut modes, mut reps) =
        (Vec::new(), (1920u32, 1440u32), vec![1, all], vec![Mode::Cast, Mode::Whitted], 9usize);
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let v = args.next().unwrap_or_else(|| fail(&format!("{a} needs a value")));
        let list = || v.split(',').map(str::trim).collect::<Vec<_>>();
        match a.as_str() {
            "--scene" => {
                let (n, p) = v.split_once('=').unwrap_or_else(|| fail("--scene takes NAME=PATH"));
                scenes.push((n.to_owned(), PathBuf::from(p)));
            }
            "--size" => {
                let (w, h) = v.split_once('x').unwrap_or_else(|| fail("--size takes WxH"));
                size =
                    (w.parse().unwrap_or_else(|_| fail("bad width")), h.parse().unwrap_or_else(|_| fail("bad height")));
            }
            "--threads" => {
                threads = list().iter().map(|t| t.parse().unwrap_or_else(|_| fail("bad --threads"))).collect()
            }
            "--modes" => {
                modes = list()
                    .iter()
                    .map(|m| match *m {
                        "cast" => Mode::Cast,
                        "whitted" => Mode::Whitted,
                        "ao" => Mode::Ao(Default::default()),
                        "diffuse" => Mode::Diffuse,
                        _ => fail("modes: cast, whitted, ao, diffuse"),
                    })
                    .collect()
            }
            "--reps" => reps = v.parse::<usize>().unwrap_or_else(|_| fail("bad --reps")).max(1),
            _ => fail(&format!("unknown option {a}")),
        }
    }
    if scenes.is_empty() {
        let dir = if Path::new("scenes").is_dir() { PathBuf::from("scenes") } else { rayset::scenes_dir() };
        scenes.push(("bunny".into(), dir.join("bunny.toml")));
    }
    println!("load average before: {}", rayset::loadavg());
    println!(
        "| scene | mode | threads | measure wall ms | frame wall ms | share wall | measure CPU ms | frame CPU ms | share CPU | picks (rounds) | single / packets per stage |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---|---|");
    for (name, path) in &scenes {
        let scene: SceneFile = if path.extension().is_some_and(|e| e == "bvh") {
            bvh_format::read_file(path).unwrap_or_else(|e| fail(&e.to_string()))
        } else {
            rayset::load(path).unwrap_or_else(|e| fail(&e))
        };
        let tracer = Tracer::new(&scene);
        let camera = CameraSpec::from(scene.camera("medium").unwrap_or_else(|| fail("no camera \"medium\"")));
        for &mode in &modes {
            let settings = Settings {
                width: size.0,
                height: size.1,
                camera,
                mode,
                lights: scene.lights.clone(),
                max_indirections: scene.settings.max_indirections,
                aovs: false,
                accuracy: render_spec::Accuracy::default(),
            };
            for &n in &threads {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build().expect("a thread pool");
                let (wall, cpu) = (rayset::Clock::Wall, rayset::Clock::Cpu);
                let mut canvas = None;
                let (mut mw, mut mc, mut fw, mut fc) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
                let mut picks: BTreeMap<String, usize> = BTreeMap::new();
                let mut ratios: [Vec<f64>; 5] = Default::default();
                let mut firsts: [Vec<f64>; 5] = Default::default();
                for round in 0..=reps {
                    pool.install(|| {
                        let (w0, c0) = (wall.now(), cpu.now());
                        let p = plan(&tracer, &settings, Method::Auto).unwrap_or_else(|e| fail(&e.to_string()));
                        let (w1, c1) = (wall.now(), cpu.now());
                        let c = canvas.take().unwrap_or_else(|| Canvas::new(&settings));
                        let image =
                            render_into(&tracer, &settings, &p, c, &|_| {}).unwrap_or_else(|e| fail(&e.to_string()));
                        let (w2, c2) = (wall.now(), cpu.now());
                        canvas = Some(Canvas::reuse(image));
                        if round > 0 && std::env::var_os("AUTO_COST_ROUNDS").is_some() {
                            let log = Log::default();
                            let t0 = wall.now();
                            let _ = plan_with(&tracer, &settings, Method::Auto, &log);
                            let t1 = wall.now();
                            let timed: f64 = log.0.lock().unwrap().iter().map(|r| r.3).sum();
                            let timings = log.0.lock().unwrap().len();
                            if std::env::var_os("AUTO_COST_ROUNDS").is_some_and(|v| v == "2") {
                                // Per stage and way: the sum over the workers of each round.
                                let mut sums: BTreeMap<(usize, bool, usize), f64> = BTreeMap::new();
                                // One thread: a chunk ends where the stage goes back (modes of 2 stages or more).
                                let mut seen: BTreeMap<(usize, bool), usize> = BTreeMap::new();
                                let mut prev = 0;
                                for &(_, st, p, secs) in log.0.lock().unwrap().iter() {
                                    if st < prev {
                                        seen.clear();
                                    }
                                    prev = st;
                                    let k = seen.entry((st, p)).or_default();
                                    *sums.entry((st, p, *k)).or_default() += secs;
                                    *k += 1;
                                }
                                eprintln!(
                                    "  {:?}",
                                    sums.iter()
                                        .map(|((st, p, k), v)| format!(
                                            "{st}{}{k} {:.1}",
                                            if *p { "p" } else { "s" },
                                            v * 1e6
                                        ))
                                        .collect::<Vec<_>>()
                                );
                            }
                            eprintln!(
                                "{name} {mode:?} {n}: plan {:.3} ms, of which {timings} timings {:.3} ms",
                                (t1 - t0) * 1e3,
                                timed * 1e3
                            );
                            for (i, r) in first_rounds(log).into_iter().enumerate() {
                                if r > 0.0 {
                                    firsts[i].push(r);
                                }
                            }
                        }
                        // The first round pages the canvas in and is not counted.
                        if round > 0 {
                            mw.push(w1 - w0);
                            mc.push(c1 - c0);
                            fw.push(w2 - w0);
                            fc.push(c2 - c0);
                            *picks.entry(p.describe()).or_default() += 1;
                            if let Some(m) = p.measured() {
                                for s in Stage::ALL {
                                    let i = s.index();
                                    if m.rays[i] > 0 && m.packets[i] > 0.0 {
                                        ratios[i].push(m.single[i] / m.packets[i]);
                                    }
                                }
                            }
                        }
                    });
                }
                let (mw, fw, mc, fc) = (median(mw), median(fw), median(mc), median(fc));
                let picks: Vec<String> = picks.iter().map(|(p, k)| format!("{p} ({k})")).collect();
                let ratios: Vec<String> = Stage::ALL
                    .into_iter()
                    .filter(|s| !ratios[s.index()].is_empty())
                    .map(|s| {
                        let f = &firsts[s.index()];
                        let (lo, hi) =
                            (f.iter().copied().fold(f64::INFINITY, f64::min), f.iter().copied().fold(0.0, f64::max));
                        let first =
                            if f.is_empty() { String::new() } else { format!(" (first rounds {lo:.2}-{hi:.2})") };
                        format!("{} {:.2}{first}", s.name(), median(ratios[s.index()].clone()))
                    })
                    .collect();
                println!(
                    "| {name} | {mode:?} | {n} | {:.3} | {:.2} | {:.2}% | {:.3} | {:.2} | {:.2}% | {} | {} |",
                    mw * 1e3,
                    fw * 1e3,
                    100.0 * mw / fw,
                    mc * 1e3,
                    fc * 1e3,
                    100.0 * mc / fc,
                    picks.join("; "),
                    ratios.join(", ")
                );
            }
        }
    }
    println!("load average after: {}", rayset::loadavg());
}
