//! Memory beside speed for the CPU tracer's two vertex forms (`trace-cpu --vertices`): per scene,
//! mode and method, whole frames of a tracer holding the expanded copy and of one reading the
//! file's indexed arrays, interleaved frame by frame (so that a change in the machine's load hits
//! both alike), as rays per median frame; the bytes each holds per triangle; and the images,
//! which must be the same. Markdown on standard output.
//!
//! ```text
//! cargo run --release -p tracer-cpu --example vertex_forms -- SCENE.bvh... [options]
//!   --size WxH        [default: 1280x960]
//!   --camera NAME     [default: medium]
//!   --modes LIST      cast,whitted [default: both]
//!   --methods LIST    packet,ordered,stackless,bvh8,auto [default: all]
//!   --reps N          at least N interleaved rounds [default: 7]
//!   --seconds S       and at least S seconds of them [default: 3]
//!   --clock wall|cpu  wall-clock time, or the CPU time of the process's threads (rays per
//!                     CPU-second: on a machine shared with other work) [default: wall]
//! ```
//!
//! Resident memory of a whole `trace-cpu render` process is measured apart (docs/cpu-benchmark.md,
//! "Vertex forms"): one process holds both tracers here.

#[path = "../benches/rayset/mod.rs"]
mod rayset;

use render_spec::{CameraSpec, Mode, Settings, Vertices};
use std::path::PathBuf;
use tracer_cpu::{Method, Tracer};

fn main() {
    let mut scenes = Vec::new();
    let (mut size, mut camera, mut reps, mut clock) = ((1280, 960), "medium".to_owned(), 7, rayset::Clock::Wall);
    let mut seconds = 3.0;
    let mut modes = vec![Mode::Cast, Mode::Whitted];
    let mut methods = vec![Method::Packet, Method::Ordered, Method::Stackless, Method::Bvh8, Method::Auto];
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        let mut value = || args.next().unwrap_or_else(|| fail(&format!("{a} needs a value")));
        match a.as_str() {
            "--size" => {
                let v = value();
                let (w, h) = v.split_once('x').unwrap_or_else(|| fail("--size is WxH"));
                size =
                    (w.parse().unwrap_or_else(|_| fail("bad width")), h.parse().unwrap_or_else(|_| fail("bad height")));
            }
            "--camera" => camera = value(),
            "--seconds" => seconds = value().parse().unwrap_or_else(|_| fail("--seconds is a number")),
            "--reps" => reps = value().parse().unwrap_or_else(|_| fail("--reps is a whole number")),
            "--clock" => {
                clock = match value().as_str() {
                    "wall" => rayset::Clock::Wall,
                    "cpu" => rayset::Clock::Cpu,
                    c => fail(&format!("bad clock {c:?} (wall or cpu)")),
                }
            }
            "--modes" => {
                modes = value()
                    .split(',')
                    .map(|m| match m {
                        "cast" => Mode::Cast,
                        "whitted" => Mode::Whitted,
                        m => fail(&format!("bad mode {m:?} (cast or whitted)")),
                    })
                    .collect()
            }
            "--methods" => {
                let all = [Method::Packet, Method::Ordered, Method::Stackless, Method::Bvh8, Method::Auto];
                methods = value()
                    .split(',')
                    .map(|m| *all.iter().find(|x| x.name() == m).unwrap_or_else(|| fail(&format!("bad method {m:?}"))))
                    .collect()
            }
            "-h" | "--help" => {
                println!("see the top of tracer-cpu/examples/vertex_forms.rs for the options");
                return;
            }
            _ => scenes.push(PathBuf::from(a)),
        }
    }
    if scenes.is_empty() {
        fail("give at least one compiled scene (.bvh)");
    }
    println!(
        "| scene | mode | method | bytes/triangle expanded | indexed | Mrays/s expanded | indexed | indexed/expanded | images |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for path in &scenes {
        let scene = bvh_format::read_file(path).unwrap_or_else(|e| fail(&format!("{}: {e}", path.display())));
        let name = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let cam = CameraSpec::from(scene.camera(&camera).unwrap_or_else(|| fail("no such camera")));
        let n = scene.triangles.len() as f64;
        for &mode in &modes {
            let s = Settings::of_scene(&scene, cam, mode, size);
            for &method in &methods {
                let tracers = [Vertices::Expanded, Vertices::Indexed].map(|v| Tracer::with_vertices(&scene, v));
                let images = tracers.each_ref().map(|t| tracer_cpu::render(t, &s, method).expect("the tracer renders"));
                let same = images[0].rgb == images[1].rgb && images[0].rays == images[1].rays;
                let rays = images[0].rays.total() as f64;
                let [a, b] = &tracers;
                let (mut pa, mut pb) = (
                    || drop(tracer_cpu::render(a, &s, method).expect("the tracer renders")),
                    || drop(tracer_cpu::render(b, &s, method).expect("the tracer renders")),
                );
                let t = rayset::interleaved_medians_on(clock, reps, seconds, 1000, &mut [&mut pa, &mut pb]);
                let mrays: Vec<f64> = t.iter().map(|t| rays / t / 1e6).collect();
                println!(
                    "| {name} | {} | {} | {:.1} | {:.1} | {:.2} | {:.2} | {:.2} | {} |",
                    mode.name(),
                    method.resolve(&scene).name(),
                    a.held_bytes() as f64 / n,
                    b.held_bytes() as f64 / n,
                    mrays[0],
                    mrays[1],
                    mrays[1] / mrays[0],
                    if same { "same" } else { "DIFFER" }
                );
            }
        }
    }
}

fn fail(msg: &str) -> ! {
    eprintln!("vertex_forms: {msg}");
    std::process::exit(2)
}
