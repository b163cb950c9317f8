//! Where the time of `bvhc compile` goes: import, tree build, the rest of `compile()` (reorder,
//! escape layout, validation), serialisation, file write. Prints medians of `--runs N`.
//!
//! `cargo run --release -p bvh-build --example compile_profile -- SCENE [--runs N]`

use bvh_build::import::{ImportOptions, load};
use bvh_format::BuildParams;
use std::time::Instant;

fn main() {
    let mut args = std::env::args().skip(1);
    let scene = args.next().expect("a scene path");
    let mut runs = 5;
    while let Some(a) = args.next() {
        if a == "--runs" {
            runs = args.next().and_then(|v| v.parse().ok()).expect("--runs N");
        }
    }
    let mut t = vec![Vec::new(); 6];
    let out = std::env::temp_dir().join("compile_profile.bvh");
    for _ in 0..runs {
        let t0 = Instant::now();
        let s = load(std::path::Path::new(&scene), &ImportOptions::default()).expect("loads");
        let t1 = Instant::now();
        let tree = bvh_build::build_tree(&s.positions, &BuildParams::default()).unwrap();
        let t2 = Instant::now();
        drop(tree);
        let t3 = Instant::now();
        let file = bvh_build::compile(&s, &BuildParams::default(), Default::default()).unwrap();
        let t4 = Instant::now();
        let bytes = bvh_format::write(&file).unwrap();
        let t5 = Instant::now();
        std::fs::write(&out, &bytes).unwrap();
        let t6 = Instant::now();
        let ms = |a: Instant, b: Instant| (b - a).as_secs_f64() * 1e3;
        t[0].push(ms(t0, t1));
        t[1].push(ms(t1, t2));
        t[2].push(ms(t3, t4) - ms(t1, t2));
        t[3].push(ms(t4, t5));
        t[4].push(ms(t5, t6));
        t[5].push(ms(t0, t2) + ms(t3, t6) - ms(t1, t2));
    }
    let _ = std::fs::remove_file(&out);
    let names = ["import", "build_tree", "compile rest", "serialise", "fs write", "total"];
    for (n, v) in names.iter().zip(&mut t) {
        v.sort_by(f64::total_cmp);
        println!("{n:14} median {:8.1} ms  min {:8.1}", v[v.len() / 2], v[0]);
    }
}
