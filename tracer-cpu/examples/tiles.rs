//! Which tile shape renders fastest: whole frames of `render_with` in each shape of
//! `render::Tiles`, interleaved round by round on one thread pool (median of the rounds). Images do
//! not depend on the shape; only the order in which blocks are traced and the work per band do.
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
const SHAPES: [(usize, usize); 8] = [(2, usize::MAX), (2, 16), (4, 8), (8, 8), (8, 16), (16, 16), (8, 32), (4, 32)];

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
        let settings = Settings {
            width: w,
            height: h,
            camera: CameraSpec::from(scene.camera(camera).expect("the scene has the camera")),
            mode,
            lights: scene.lights.clone(),
            max_indirections: scene.settings.max_indirections,
            aovs: false,
            accuracy: render_spec::Accuracy::default(),
        };
        // The renderer's own tracing for `--method auto`, as measured once here.
        let plan = pool.install(|| plan(&tracer, &settings, Method::Auto)).expect("the scene has a layout");
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
            println!(
                "{mode:?} tiles {shape:>10}: {:7.1} ms ({:+.1}% of the fastest)",
                m * 1e3,
                100.0 * (m / best - 1.0)
            );
        }
    }
}
