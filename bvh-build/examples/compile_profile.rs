//! Where the time of `bvhc compile` goes, phase by phase as bvhc runs them: import, tree build,
//! the rest of `compile_for_writing` (triangles reordered into leaf order and welded, layouts),
//! `bvh_format::write_to` into a buffered file (validation, CRCs, the file system write) and the
//! fsync; the validation alone is timed once more on its own. Prints the median and minimum of
//! `--runs N` (default 5) for each phase, in milliseconds.
//!
//! `cargo run --release -p bvh-build --example compile_profile -- SCENE [--runs N]`

use bvh_build::import::{ImportOptions, load};
use bvh_format::BuildParams;
use std::fs::File;
use std::io::BufWriter;
use std::time::Instant;

fn main() {
    let mut args = std::env::args().skip(1);
    let usage = "usage: compile_profile SCENE [--runs N]";
    let Some(scene) = args.next() else {
        eprintln!("{usage}");
        std::process::exit(2);
    };
    let mut runs = 5usize;
    while let Some(a) = args.next() {
        match (a.as_str(), args.next().and_then(|v| v.parse().ok())) {
            ("--runs", Some(n)) if n > 0 => runs = n,
            _ => {
                eprintln!("{usage}");
                std::process::exit(2);
            }
        }
    }
    let fail = |e: &dyn std::fmt::Display| -> ! {
        eprintln!("compile_profile: {e}");
        std::process::exit(1);
    };
    let names =
        ["import", "build_tree", "compile - build", "write_to (validates)", "  of it validate", "fsync", "total"];
    let mut t = vec![Vec::new(); names.len()];
    let out = std::env::temp_dir().join(format!("compile_profile_{}.bvh", std::process::id()));
    let params = BuildParams::default();
    let ms = |a: Instant| a.elapsed().as_secs_f64() * 1e3;
    for _ in 0..runs {
        let t0 = Instant::now();
        let s = load(std::path::Path::new(&scene), &ImportOptions::default()).unwrap_or_else(|e| fail(&e));
        let import = ms(t0);
        let t1 = Instant::now();
        drop(bvh_build::build_tree(&s.positions, &params).unwrap_or_else(|e| fail(&e)));
        let build = ms(t1);
        let t2 = Instant::now();
        let file = bvh_build::compile_for_writing(&s, &params, Default::default(), None).unwrap_or_else(|e| fail(&e));
        let compile = ms(t2);
        let t3 = Instant::now();
        file.validate().unwrap_or_else(|e| fail(&e));
        let validate = ms(t3);
        let t4 = Instant::now();
        let mut w = BufWriter::new(File::create(&out).unwrap_or_else(|e| fail(&e)));
        bvh_format::write_to(&file, &mut w).unwrap_or_else(|e| fail(&e));
        let f = w.into_inner().unwrap_or_else(|e| fail(&e.error().to_string()));
        let write = ms(t4);
        let t5 = Instant::now();
        f.sync_all().unwrap_or_else(|e| fail(&e));
        let sync = ms(t5);
        let rest = compile - build;
        for (v, x) in t.iter_mut().zip([import, build, rest, write, validate, sync, import + compile + write + sync]) {
            v.push(x);
        }
    }
    let _ = std::fs::remove_file(&out);
    println!("{scene}: {runs} runs, {} rayon threads", rayon::current_num_threads());
    for (n, v) in names.iter().zip(&mut t) {
        v.sort_by(f64::total_cmp);
        println!("{n:18} median {:8.1} ms  min {:8.1}", v[v.len() / 2], v[0]);
    }
}
