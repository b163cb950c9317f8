//! Build time of one scene as wall time and as CPU time of every thread of the process (Linux:
//! `/proc/self/task/*/schedstat`), medians of `RUNS` builds after one warm-up (and the least CPU
//! time: on a machine shared with other work, the build least disturbed by it), and a hash of the
//! tree (child-pair nodes and leaf order) to tell whether a change to the builder changed the tree.
//! CPU time is what to compare on a machine shared with other work: wall time there depends on
//! how much of the cores the process gets, CPU time much less.
//!
//! With `--phases`, also the median wall time of each phase of the build ([`bvh_build::build::Phases`]):
//! where the time goes that more threads do not shorten.
//!
//! `cargo run --release -p bvh-build --example build_cpu -- SCENE [RUNS] [BINS] [--phases]`

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
    let all: Vec<String> = std::env::args().skip(1).collect();
    let phases = all.iter().any(|a| a == "--phases");
    let mut args = all.into_iter().filter(|a| a != "--phases");
    let usage = "usage: build_cpu SCENE [RUNS] [BINS] [--phases]";
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
    let (mut wall, mut cpu, mut parts) = (Vec::new(), Vec::new(), Vec::new());
    for _ in 0..runs {
        let (c0, t0) = (cpu_ns(), Instant::now());
        let built = bvh_build::build_tree(&s.positions, &p);
        let ph = built.as_ref().map(|t| t.phases).unwrap_or_default();
        drop(built);
        wall.push(t0.elapsed().as_secs_f64() * 1e3);
        cpu.push((cpu_ns() - c0) as f64 / 1e6);
        parts.push(ph);
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
        "{scene}: {} triangles, {bins} bins, {} threads: wall median {:.1} ms, CPU median {:.1} ms (min {:.1}) ({runs} builds); SAH {sah:.4}, tree hash {hash:016x}",
        s.positions.len(),
        rayon::current_num_threads(),
        median(wall),
        median(cpu.clone()),
        cpu.iter().copied().fold(f64::INFINITY, f64::min),
    );
    if phases {
        let m = |f: fn(&bvh_build::build::Phases) -> f64| median(parts.iter().map(f).collect());
        println!(
            "  phases, medians (ms): setup {:.2}, tree {:.2} (parallel splits: {} nodes, {:.2} summed, the last done at {:.2}), top {:.2}, layouts {:.2}, release {:.2}",
            m(|p| p.setup),
            m(|p| p.tree),
            parts[0].parallel_split_count,
            m(|p| p.parallel_splits),
            m(|p| p.parallel_until),
            m(|p| p.top),
            m(|p| p.layouts),
            m(|p| p.release),
        );
    }
}
