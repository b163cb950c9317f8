//! Build time of one scene as wall time and as CPU time of every thread of the process (Linux:
//! `/proc/self/task/*/schedstat`), medians of `RUNS` builds after one warm-up, and a hash of the
//! tree (child-pair nodes and leaf order) to tell whether a change to the builder changed the tree.
//! CPU time is what to compare on a machine shared with other work: wall time there depends on
//! how much of the cores the process gets, CPU time much less.
//!
//! `cargo run --release -p bvh-build --example build_cpu -- SCENE [RUNS] [BINS]`

use bvh_build::import::{ImportOptions, load};
use bvh_format::BuildParams;
use std::time::Instant;

/// Nanoseconds every thread of this process has spent on a CPU so far.
fn cpu_ns() -> u64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else { return 0 };
    tasks
        .filter_map(|t| std::fs::read_to_string(t.ok()?.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let mut args = std::env::args().skip(1);
    let usage = "usage: build_cpu SCENE [RUNS] [BINS]";
    let fail = |e: &dyn std::fmt::Display| -> ! {
        eprintln!("build_cpu: {e}");
        std::process::exit(2);
    };
    let scene = args.next().unwrap_or_else(|| fail(&usage));
    let mut number = |default: usize| match args.next() {
        None => default,
        Some(a) => a.parse().ok().filter(|&n| n > 0).unwrap_or_else(|| fail(&usage)),
    };
    let (runs, bins) = (number(7), number(16) as u32);
    let s = load(std::path::Path::new(&scene), &ImportOptions::default()).unwrap_or_else(|e| fail(&e));
    let p = BuildParams { bins, ..BuildParams::default() };
    let tree = bvh_build::build_tree(&s.positions, &p).unwrap_or_else(|e| fail(&e));
    let (mut wall, mut cpu) = (Vec::new(), Vec::new());
    for _ in 0..runs {
        let (c0, t0) = (cpu_ns(), Instant::now());
        drop(bvh_build::build_tree(&s.positions, &p));
        wall.push(t0.elapsed().as_secs_f64() * 1e3);
        cpu.push((cpu_ns() - c0) as f64 / 1e6);
    }
    // FNV-1a over the nodes' bytes and the leaf order.
    let bytes = tree
        .nodes
        .iter()
        .flat_map(|n| bytemuck::bytes_of(n).iter().copied())
        .chain(tree.order.iter().flat_map(|o| o.to_le_bytes()));
    let hash = bytes.fold(0xcbf2_9ce4_8422_2325u64, |h, b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3));
    let sah = bvh_format::tree::stats(bvh_format::Tree::child_pair(&tree.nodes), p.traversal_cost, p.intersection_cost)
        .sah_cost;
    println!(
        "{scene}: {} triangles, {bins} bins, {} threads: wall median {:.1} ms, CPU median {:.1} ms ({runs} builds); SAH {sah:.4}, tree hash {hash:016x}",
        s.positions.len(),
        rayon::current_num_threads(),
        median(wall),
        median(cpu),
    );
}
