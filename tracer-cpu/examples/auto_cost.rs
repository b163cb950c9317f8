//! What `--method auto`'s measurement costs a frame, and what it decides: for each scene, mode
//! and thread count, rounds of `plan` (the measurement) then `render_into` (the rest of the frame
//! `trace-cpu render` times) into the buffers of the round before, each timed by the wall clock
//! (the process's CPU time, as `/proc` keeps it, moves in scheduler ticks: too coarse for a
//! millisecond). Prints the medians, the measurement's share of the whole frame, the picks of
//! every round (how often each came) and, per stage, the median ratio of the single rays' time
//! to the packets' (a lower bound where single rays were stopped once clearly behind).
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

use render_spec::{CameraSpec, Mode, Settings};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use tracer_cpu::lanes::Stage;
use tracer_cpu::render::{Canvas, plan, render_into};
use tracer_cpu::{Method, Tracer};

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
        "| scene | mode | threads | measure ms | frame ms | share | picks (rounds) | single / packets per stage |"
    );
    println!("|---|---|---:|---:|---:|---:|---|---|");
    for (name, path) in &scenes {
        let scene = rayset::open(path).unwrap_or_else(|e| fail(&e));
        let tracer = Tracer::new(&scene);
        let camera = CameraSpec::from(scene.camera("medium").unwrap_or_else(|| fail("no camera \"medium\"")));
        for &mode in &modes {
            let settings = Settings::of_scene(&scene, camera, mode, size);
            for &n in &threads {
                let pool = rayon::ThreadPoolBuilder::new().num_threads(n).build().expect("a thread pool");
                let wall = rayset::Clock::Wall;
                let mut canvas = None;
                let (mut mw, mut fw) = (Vec::new(), Vec::new());
                let mut picks: BTreeMap<String, usize> = BTreeMap::new();
                let mut ratios: [Vec<f64>; 5] = Default::default();
                for round in 0..=reps {
                    pool.install(|| {
                        let w0 = wall.now();
                        let p = plan(&tracer, &settings, Method::Auto).unwrap_or_else(|e| fail(&e.to_string()));
                        let w1 = wall.now();
                        let c = canvas.take().unwrap_or_else(|| Canvas::new(&settings));
                        let image =
                            render_into(&tracer, &settings, &p, c, &|_| {}).unwrap_or_else(|e| fail(&e.to_string()));
                        let w2 = wall.now();
                        canvas = Some(Canvas::reuse(image));
                        // The first round pages the canvas in and is not counted.
                        if round > 0 {
                            mw.push(w1 - w0);
                            fw.push(w2 - w0);
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
                let (mw, fw) = (rayset::median(mw), rayset::median(fw));
                let picks: Vec<String> = picks.iter().map(|(p, k)| format!("{p} ({k})")).collect();
                let ratios: Vec<String> = Stage::ALL
                    .into_iter()
                    .filter(|s| !ratios[s.index()].is_empty())
                    .map(|s| format!("{} {:.2}", s.name(), rayset::median(ratios[s.index()].clone())))
                    .collect();
                println!(
                    "| {name} | {mode:?} | {n} | {:.3} | {:.2} | {:.2}% | {} | {} |",
                    mw * 1e3,
                    fw * 1e3,
                    100.0 * mw / fw,
                    picks.join("; "),
                    ratios.join(", ")
                );
            }
        }
    }
    println!("load average after: {}", rayset::loadavg());
}
