//! Which tile shape renders fastest: whole frames of `render_with` in each shape of
//! `render::Tiles`, interleaved round by round on one thread pool (median of the rounds), and how
//! evenly its bands would keep 16 workers busy (each band's cost measured on one thread, handed
//! out greedily in image order and with the costliest last: a machine with fewer cores can tell
//! what the end of a frame costs on more). Images do not depend on the shape; only the order in which blocks are traced
//! and the work per band do.
//!
//! ```text
//! cargo run --release -p tracer-cpu --example tiles -- SCENE.bvh [THREADS] [WxH] [CAMERA]
//! ```
//! (defaults: all threads, 1920x1440, medium; ray casting and Whitted with the scene's lights;
//! `--method auto`'s tracing as it picks it for the frame)

#[path = "../benches/rayset/mod.rs"]
mod rayset;

use render_spec::{CameraSpec, Mode, Settings};
use tracer_cpu::render::{Tiles, plan, render_with};
use tracer_cpu::{Method, Tracer};

/// Bands of two rows traced across the whole width (the packet path's first shape), and square
/// and wide tiles.
const SHAPES: [(usize, usize); 6] = [(2, usize::MAX), (4, 8), (8, 8), (8, 16), (16, 16), (4, 32)];

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let Some(path) = args.get(1) else {
        eprintln!("usage: tiles SCENE.bvh [THREADS] [WxH] [CAMERA]");
        std::process::exit(2)
    };
    let scene = bvh_format::read_file(std::path::Path::new(path)).unwrap_or_else(|e| {
        eprintln!("tiles: {e}");
        std::process::exit(1)
    });
    let threads = args.get(2).map_or(0, |t| t.parse().expect("a thread count"));
    let (w, h) = args.get(3).map_or((1920, 1440), |s| {
        let (w, h) = s.split_once('x').expect("a size like 1920x1440");
        (w.parse().expect("a width"), h.parse().expect("a height"))
    });
    let camera = args.get(4).map_or("medium", String::as_str);
    let tracer = Tracer::new(&scene);
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().expect("a thread pool");
    println!(
        "{path}, {w}x{h}, camera {camera}, {} threads, CPU {}, load {}",
        pool.current_num_threads(),
        rayset::cpu_model(),
        rayset::loadavg()
    );
    for mode in [Mode::Cast, Mode::Whitted] {
        let cam = CameraSpec::from(scene.camera(camera).expect("the scene has the camera"));
        let settings = Settings::of_scene(&scene, cam, mode, (w, h));
        // The renderer's own tracing for `--method auto`, as measured once here.
        let plan = pool.install(|| plan(&tracer, &settings, Method::Auto)).expect("the scene has a layout");
        // Each band's cost on one thread (the progress call ends a band) in CPU time of that
        // thread, so that waiting for a core on a shared machine does not count; the least of 5
        // frames.
        let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("a thread pool");
        let band_costs = |tiles: Tiles| {
            let mut least: Vec<f64> = Vec::new();
            for _ in 0..5 {
                let ends = std::sync::Mutex::new(Vec::new());
                let t0 = one.install(thread_cpu_seconds);
                one.install(|| {
                    render_with(&tracer, &settings, plan.method(), || plan.lanes(), tiles, &|_| {
                        ends.lock().expect("no panic").push(thread_cpu_seconds())
                    })
                })
                .expect("renders");
                let ends = ends.into_inner().expect("no panic");
                let costs = ends.iter().zip(std::iter::once(&t0).chain(&ends)).map(|(e, s)| e - s);
                least = if least.is_empty() {
                    costs.collect()
                } else {
                    least.iter().zip(costs).map(|(a, b)| a.min(b)).collect()
                };
            }
            least
        };
        let frame = |tiles: Tiles| {
            pool.install(|| render_with(&tracer, &settings, plan.method(), || plan.lanes(), tiles, &|_| {}))
                .expect("renders");
        };
        let mut passes: Vec<Box<dyn FnMut() + '_>> = SHAPES
            .iter()
            .map(|&(rows, columns)| Box::new(move || frame(Tiles { rows, columns })) as Box<dyn FnMut()>)
            .collect();
        let mut refs: Vec<&mut dyn FnMut()> = passes.iter_mut().map(|p| &mut **p as &mut dyn FnMut()).collect();
        let medians = rayset::interleaved_medians(7, 3.0, 15, &mut refs);
        let best = medians.iter().copied().fold(f64::INFINITY, f64::min);
        for (&(rows, columns), m) in SHAPES.iter().zip(medians) {
            let shape = if columns == usize::MAX { format!("{rows} x width") } else { format!("{rows} x {columns}") };
            let mut costs = band_costs(Tiles { rows, columns });
            let in_order = balance(&costs, 16);
            costs.sort_by(f64::total_cmp);
            let balance = [in_order, balance(&costs, 16)].map(|b| format!("{:.0}%", 100.0 * b));
            println!(
                "{mode:?} tiles {shape:>10}: {:7.1} ms ({:+.1}% of the fastest); balance on 16 workers, bands in image order and costliest last: {}",
                m * 1e3,
                100.0 * (m / best - 1.0),
                balance.join(", ")
            );
        }
    }
}

/// Seconds on a CPU of the calling thread (`CLOCK_THREAD_CPUTIME_ID`, exact to the nanosecond:
/// the thread's `schedstat` moves only at scheduler ticks).
fn thread_cpu_seconds() -> f64 {
    #[repr(C)]
    struct Timespec {
        sec: i64,
        nsec: i64,
    }
    unsafe extern "C" {
        fn clock_gettime(clock: i32, time: *mut Timespec) -> i32;
    }
    const CLOCK_THREAD_CPUTIME_ID: i32 = 3;
    let mut t = Timespec { sec: 0, nsec: 0 };
    // SAFETY: `t` is a valid timespec (two 64-bit fields on the 64-bit Linux this example runs on).
    if unsafe { clock_gettime(CLOCK_THREAD_CPUTIME_ID, &mut t) } != 0 {
        return f64::NAN;
    }
    t.sec as f64 + t.nsec as f64 * 1e-9
}

/// How well bands of these costs (seconds) keep `workers` busy: the mean load over the longest
/// when each band, in the order given, goes to the worker that is free first. In image order that
/// is about what work stealing does with whole bands; with the costliest bands last, the worst
/// it can do (rayon's splitting leaves whichever bands were stolen last to the end). 100% is a
/// frame with no worker waiting at its end.
fn balance(costs: &[f64], workers: usize) -> f64 {
    let mut load = vec![0.0f64; workers];
    for &c in costs {
        let first = load.iter_mut().min_by(|a, b| a.total_cmp(b)).expect("at least one worker");
        *first += c;
    }
    costs.iter().sum::<f64>() / workers as f64 / load.iter().copied().fold(0.0, f64::max)
}
