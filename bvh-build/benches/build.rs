//! Build time of our builders (binned SAH with 4 to 64 bins, full sweep) and of two peers (the
//! `bvh` crate, obvhs) on the same triangles. SAH costs and the table in `docs/` come from
//! `examples/build_report.rs`; this measures time only, with criterion's statistics.
//!
//! `cargo bench -p bvh-build --features compare --bench build`

use bvh_build::import::{ImportOptions, load};
use bvh_build::peers;
use bvh_format::{BuildParams, Strategy};
use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use std::path::PathBuf;
use std::time::Duration;

const SCENES: [(&str, &str); 3] = [("bunny", "bunny.glb"), ("dragon", "dragon.glb"), ("million", "million.toml")];
const BINS: [u32; 5] = [4, 8, 16, 32, 64];

fn builds(c: &mut Criterion) {
    let scenes = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../scenes");
    for (name, file) in SCENES {
        let path = scenes.join(file);
        let tris = load(&path, &ImportOptions::default())
            .unwrap_or_else(|e| panic!("cannot load {}: {e}", path.display()))
            .positions;
        let mut group = c.benchmark_group(name);
        // Sweep builds of a million triangles take seconds on two cores: ten samples and a short
        // target time keep the whole run to minutes (criterion extends the time as needed).
        group.sample_size(10);
        group.warm_up_time(Duration::from_secs(1));
        group.measurement_time(Duration::from_secs(3));
        group.throughput(Throughput::Elements(tris.len() as u64));

        let defaults = BuildParams::default();
        for bins in BINS {
            let p = BuildParams { strategy: Strategy::Binned, bins, ..defaults };
            group.bench_function(format!("binned-{bins}"), |b| {
                b.iter_with_large_drop(|| bvh_build::build_tree(&tris, &p).unwrap())
            });
        }
        let p = BuildParams { strategy: Strategy::Sweep, ..defaults };
        group.bench_function("sweep", |b| b.iter_with_large_drop(|| bvh_build::build_tree(&tris, &p).unwrap()));

        // The peers' inputs are converted to their own types outside the timed part, as ours are
        // already `[[Vec3; 3]]`; each still computes its triangle boxes inside its build.
        let mut shapes = peers::bvh_input(&tris);
        group.bench_function("bvh-crate", |b| b.iter_with_large_drop(|| peers::build_bvh(&mut shapes)));
        let obvhs_tris = peers::obvhs_input(&tris);
        let params = peers::obvhs_params(defaults.traversal_cost, defaults.intersection_cost);
        group.bench_function("obvhs", |b| b.iter_with_large_drop(|| peers::build_obvhs(&obvhs_tris, params)));
        group.finish();
    }
}

criterion_group!(benches, builds);
criterion_main!(benches);
