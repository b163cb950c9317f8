//! Primary rays per second on the bunny at 640 x 480, one thread: ours one ray at a time and in
//! AVX2 packets, and (with `--features embree`) Embree's single rays and 8-ray packets on the same
//! rays and triangles. The whole matrix (three scenes, two resolutions, shadow and secondary rays,
//! all threads) is `examples/ray_report.rs`; this is its quick, statistically careful subset.
//!
//! `cargo bench -p tracer-cpu --features embree --bench rays`

mod rayset;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use rayset::{Engine, Kind, RaySet};
use render_spec::Intersect;
use std::time::Duration;
use tracer_cpu::{Method, Tracer, packet};

fn primary_rays(c: &mut Criterion) {
    let scene = rayset::load(&rayset::scenes_dir().join("bunny.toml")).expect("the bunny compiles");
    let [primary, ..]: [RaySet; 5] = rayset::generate(&scene, 640, 480).expect("the bunny has rays");
    assert_eq!(primary.kind, Kind::Primary);
    let tracer = Tracer::new(&scene);
    #[cfg(feature = "embree")]
    let embree = tracer_cpu::embree::Scene::new(&scene.leaf_triangles(), tracer_cpu::embree::Flags::Default)
        .expect("Embree builds the bunny");

    let mut engines = vec![(
        "ours-ordered",
        Engine::Scalar(tracer.walk(Method::Ordered).expect("the bunny has both layouts"), Intersect::Watertight),
    )];
    if packet::available() {
        engines.push(("ours-packet", Engine::Packet(&tracer)));
    }
    #[cfg(feature = "embree")]
    engines.extend([("embree-1", Engine::Embree1(&embree)), ("embree-8", Engine::Embree8(&embree))]);

    // One thread: the per-core comparison the report's ratios are about, and steady on a busy
    // machine where an all-threads run would measure the neighbours too.
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("a thread pool");
    let mut out = vec![rayset::NO_RAY; primary.rays.len()];
    let mut group = c.benchmark_group("bunny-640x480-primary-1thread");
    group.throughput(Throughput::Elements(primary.count as u64));
    group.sample_size(10).warm_up_time(Duration::from_secs(1)).measurement_time(Duration::from_secs(5));
    for (name, engine) in engines {
        group.bench_function(name, |b| b.iter(|| pool.install(|| rayset::trace(engine, &primary, &mut out))));
    }
    group.finish();
}

criterion_group!(benches, primary_rays);
criterion_main!(benches);
