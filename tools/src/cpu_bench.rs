//! The CPU tracer as a [`Bench`]: wall-clock time of whole frames on a thread pool. `trace-cpu
//! bench` times it, and `trace-eval` sets it beside the GPU.

use crate::bench::{Bench, Timed};
use bvh_format::SceneFile;
use render_spec::{Image, Settings};
use std::time::Instant;
use tracer_cpu::{Method, Tracer};

/// A pool of `threads` workers [default: one per core].
pub fn thread_pool(threads: Option<usize>) -> Result<rayon::ThreadPool, String> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .build()
        .map_err(|e| format!("cannot start the worker threads: {e}"))
}

/// The names `trace-cpu --method` takes for the traversals a benchmark can time.
pub fn method_of(name: &str) -> Result<Method, String> {
    [Method::Auto, Method::Packet, Method::Ordered, Method::Stackless, Method::Bvh8, Method::Bvh8Packet]
        .into_iter()
        .find(|m| m.name() == name)
        .ok_or_else(|| format!("{name:?} is not a CPU method (auto, packet, ordered, stackless, bvh8, bvh8-packet)"))
}

pub struct CpuBench {
    pub pool: rayon::ThreadPool,
}

impl Bench for CpuBench {
    type Renderer<'a> = (Tracer<'a>, Method);

    fn tracer(&self) -> &'static str {
        "cpu"
    }

    fn device(&self) -> String {
        format!("{}, {} threads", crate::cpu_model(), self.pool.current_num_threads())
    }

    fn timing(&self) -> String {
        "a frame's time is the wall-clock time of `tracer_cpu::render`: primary rays, tracing and shading \
         into the 8-bit image, no AOVs; the scene is loaded and prepared before"
            .to_owned()
    }

    fn prepare<'a>(&'a self, scene: &'a SceneFile, method: &str) -> Result<(Tracer<'a>, Method), String> {
        let method = method_of(method)?;
        if method == Method::Packet && method.resolve(scene) != method {
            return Err("this CPU cannot run the packet method: it needs AVX2".to_owned());
        }
        Ok((Tracer::new(scene), method))
    }

    fn frame(&self, r: &mut (Tracer<'_>, Method), s: &Settings) -> Result<Timed, String> {
        let t0 = Instant::now();
        let image = self.image(r, &Settings { aovs: false, ..s.clone() })?;
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        Ok(Timed { ms, rays: crate::bench::rays_of(&image.rays) })
    }

    fn image(&self, (tracer, method): &mut (Tracer<'_>, Method), s: &Settings) -> Result<Image, String> {
        self.pool.install(|| tracer_cpu::render(tracer, s, *method)).map_err(|e| e.to_string())
    }

    fn image_with_self_hits(&self, r: &mut (Tracer<'_>, Method), s: &Settings) -> Result<Image, String> {
        r.0.count_self_hits(true);
        let image = self.image(r, s);
        r.0.count_self_hits(false);
        image
    }
}
