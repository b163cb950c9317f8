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
    Method::named(name).ok_or_else(|| format!("{name:?} is not a CPU method ({})", Method::names()))
}

/// What a tracer made for `method` holds of its scene ([`Tracer::held_bytes`]: the file as read,
/// the expanded triangles in that form, the wide BVH where the method collapsed it), in all and
/// per triangle; the counterpart of trace-vk's bytes uploaded.
pub fn held_line(tracer: &Tracer<'_>, method: Method) -> String {
    let scene = tracer.scene;
    let bytes = tracer.held_bytes();
    let tris = scene.triangles.len();
    format!(
        "{} with {} vertices holds {} bytes of scene data, {:.1} per triangle ({tris} triangles, {} vertices{})",
        method.resolve(scene).name(),
        tracer.triangles().form().name(),
        bytes,
        bytes as f64 / tris.max(1) as f64,
        scene.vertices.len(),
        match tracer.wide_bytes() {
            Some(w) => format!("; the wide BVH {:.1} per triangle of it", w as f64 / tris.max(1) as f64),
            None => String::new(),
        }
    )
}

pub struct CpuBench {
    pub pool: rayon::ThreadPool,
    /// Print each prepared method's bytes held ([`held_line`]; `trace-cpu bench --vertices`).
    pub report_held: bool,
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

    /// `method` may end in [`crate::bench::INDEXED_SUFFIX`] for the indexed vertex form.
    fn prepare<'a>(&'a self, scene: &'a SceneFile, method: &str) -> Result<(Tracer<'a>, Method), String> {
        let (name, form) = crate::bench::split_form(method);
        let method = method_of(name)?;
        if method == Method::Packet && method.resolve(scene) != method {
            return Err("this CPU cannot run the packet method: it needs AVX2".to_owned());
        }
        let tracer = Tracer::with_vertices(scene, form);
        // Collapsed here, before the warm-up frames, so that the bytes held include it.
        tracer.collapse_for(method);
        if self.report_held {
            crate::say!("{}", held_line(&tracer, method));
        }
        Ok((tracer, method))
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
