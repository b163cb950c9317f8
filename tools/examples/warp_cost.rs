//! How coherent a frame's primary rays are for a GPU's SIMT lanes, per image size (issue 10 item
//! 3: does a small frame trace fewer rays per second because it cannot fill the GPU, or because its
//! rays are less alike?). A warp of 32 invocations of the kernels' 8x8 workgroups is an 8x4 pixel
//! block (`li % 8`, `li / 8`), and it runs until its slowest lane is done; so its cost is about 32
//! times the largest work of its lanes, and the share `mean work / largest work` is the SIMT
//! efficiency. The work of a ray is the LST walk's (the CPU tracer's ordered child-pair walk: the
//! same order and the same nodes): nodes plus triangles tested. A sample of warps spread over the
//! image (every k-th) keeps large frames cheap.
//!
//! `cargo run --release -p tools --example warp_cost -- SCENE [--camera medium] [--res 1920x1440,7680x4320] [--warps 40000]`

use tracer_cpu::traverse::Stack;
use tracer_cpu::{Cost, Ray};

fn main() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let value = |name: &str, default: &str| {
        args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).cloned().unwrap_or_else(|| default.to_owned())
    };
    let scene_path = args.first().filter(|a| !a.starts_with("--")).ok_or("give a scene file")?;
    let loaded = tools::load_scene(Some(std::path::Path::new(scene_path)))?;
    let scene = &loaded.file;
    let camera = tools::render_args::stored_camera(scene, &value("--camera", "medium"))?;
    let sample: u64 = value("--warps", "40000").parse().map_err(|_| "--warps takes a number")?;
    let tracer = tracer_cpu::Tracer::new(scene);
    let walk = tracer.walk(tracer_cpu::Method::Ordered).map_err(|e| e.to_string())?;
    println!("| size | warps sampled | work per ray | largest lane's work per warp | SIMT efficiency |");
    println!("|---|--:|--:|--:|--:|");
    let mut first = None;
    for res in value("--res", "1920x1440,7680x4320").split(',') {
        let (w, h) = tools::render_args::parse_res(res)?;
        let frame = camera.frame(w, h).map_err(|e| format!("{e:?}"))?;
        let (bx, by) = (w.div_ceil(8), h.div_ceil(4));
        let warps = u64::from(bx) * u64::from(by);
        let step = (warps / sample).max(1);
        let (mut sum, mut max_sum, mut n, mut m) = (0u64, 0u64, 0u64, 0u64);
        let mut stack = Stack::default();
        for k in (0..warps).step_by(step as usize) {
            let (wx, wy) = ((k % u64::from(bx)) as u32 * 8, (k / u64::from(bx)) as u32 * 4);
            let mut largest = 0u64;
            for lane in 0..32 {
                let (x, y) = (wx + lane % 8, wy + lane / 8);
                if x >= w || y >= h {
                    continue;
                }
                let ray = Ray::new(frame.eye, frame.direction(x, y));
                let mut cost = Cost::default();
                walk.closest(&ray, 0.0, f32::MAX, &mut stack, &mut cost);
                let work = u64::from(cost.nodes) + u64::from(cost.tris);
                sum += work;
                largest = largest.max(work);
                n += 1;
            }
            max_sum += 32 * largest;
            m += 1;
        }
        let efficiency = sum as f64 / max_sum as f64;
        let base = *first.get_or_insert(efficiency);
        println!(
            "| {w}x{h} | {} | {:.1} | {:.1} | {:.1}% ({:.2}x the first size's) |",
            m,
            sum as f64 / n as f64,
            max_sum as f64 / 32.0 / m as f64,
            100.0 * efficiency,
            efficiency / base
        );
    }
    Ok(())
}
