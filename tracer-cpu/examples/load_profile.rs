//! Where loading a scene file for the CPU tracer goes, step by step, each the median of 5 runs
//! on rayon's global pool (`RAYON_NUM_THREADS` sets its threads): reading the file's bytes,
//! reading and checking the scene from them (of which one tree's statistics pass, which the checks
//! run once per layout), both at once as the tracers load a file (`bvh_format::read_file`: each
//! section read from the file straight into its array), the triangles' expanded copy, the wide
//! BVH's collapse, and freeing it.
//!
//! Usage: `load_profile FILE.bvh...` (one Markdown table row per file).

use std::path::Path;
use std::time::Instant;
use tracer_cpu::bvh8::Bvh8;

/// The median of 5 timings of `f`, in ms.
fn median(mut f: impl FnMut() -> f64) -> f64 {
    let mut t: Vec<f64> = (0..5).map(|_| f()).collect();
    t.sort_by(f64::total_cmp);
    t[2] * 1e3
}

/// The seconds `f` takes.
fn timed<T>(f: impl FnOnce() -> T) -> f64 {
    let t = Instant::now();
    std::hint::black_box(f());
    t.elapsed().as_secs_f64()
}

fn main() -> Result<(), String> {
    let files: Vec<String> = std::env::args().skip(1).collect();
    if files.is_empty() {
        return Err("name one or more .bvh files".into());
    }
    println!("rayon threads: {}", rayon::current_num_threads());
    println!();
    println!(
        "| file | MB | read bytes | read and check | read_file | one stats pass | expanded triangles | collapse | free the wide BVH |"
    );
    println!("|---|--:|--:|--:|--:|--:|--:|--:|--:|");
    for f in files {
        let path = Path::new(&f);
        let bytes = bvh_format::read_input(path).map_err(|e| format!("{f}: {e}"))?;
        let scene = bvh_format::read(&bytes).map_err(|e| format!("{f}: {e}"))?;
        let nodes = scene.child_pair.as_deref().ok_or(format!("{f}: no child-pair layout"))?;
        let tris = scene.leaf_triangles();
        let read = median(|| timed(|| bvh_format::read_input(path)));
        let check = median(|| timed(|| bvh_format::read(&bytes)));
        let file = median(|| timed(|| bvh_format::read_file(path)));
        let stats = median(|| timed(|| bvh_format::tree::stats(scene.tree(), 1.0, 1.0)));
        let expand = median(|| timed(|| scene.leaf_triangles()));
        let collapse = median(|| timed(|| Bvh8::new(nodes, &tris)));
        let free = median(|| {
            let bvh = Bvh8::new(nodes, &tris);
            timed(|| drop(bvh))
        });
        println!(
            "| {f} | {:.1} | {read:.1} | {check:.1} | {file:.1} | {stats:.1} | {expand:.1} | {collapse:.1} | {free:.1} |",
            bytes.len() as f64 / 1e6
        );
    }
    Ok(())
}
