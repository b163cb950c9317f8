//! The CPU tracer as a [`Bench`]: wall-clock time of whole frames on a thread pool. `trace-cpu
//! bench` times it, and `trace-eval` sets it beside the GPU.

use crate::bench::{Bench, Timed};
use bvh_format::SceneFile;
use render_spec::{Image, Settings};
use std::time::Instant;
use tracer_cpu::render::Canvas;
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

/// A scene prepared for one method, and the buffers of its last frame, which the next reuses.
pub struct CpuRenderer<'a> {
    tracer: Tracer<'a>,
    method: Method,
    buffers: Option<Canvas>,
}

pub struct CpuBench {
    pub pool: rayon::ThreadPool,
    /// Print each prepared method's bytes held ([`held_line`]; `trace-cpu bench --vertices`).
    pub report_held: bool,
}

impl Bench for CpuBench {
    type Renderer<'a> = CpuRenderer<'a>;

    fn tracer(&self) -> &'static str {
        "cpu"
    }

    fn device(&self) -> String {
        format!("{}, {} threads", crate::cpu_model(), self.pool.current_num_threads())
    }

    fn timing(&self) -> String {
        "a frame's time is the wall-clock time of `tracer_cpu::render`: primary rays, tracing and shading \
         into the 8-bit image, no AOVs (the measurement of `--method auto` included), into the buffers of the frame before; the \
         scene is loaded and prepared before"
            .to_owned()
    }

    /// `method` may end in [`crate::bench::INDEXED_SUFFIX`] for the indexed vertex form.
    fn prepare<'a>(&'a self, scene: &'a SceneFile, method: &str) -> Result<CpuRenderer<'a>, String> {
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
        Ok(CpuRenderer { tracer, method, buffers: None })
    }

    fn frame(&self, r: &mut CpuRenderer<'_>, s: &Settings) -> Result<Timed, String> {
        let s = Settings { aovs: false, ..s.clone() };
        // Into the last frame's buffers, as a renderer drawing frame after frame would: on the
        // H100 host's 16 threads, fresh buffers each frame (even paged in before the clock) held
        // the dragon's frames to 10.6-12.5x one thread, reused ones to 14.3-15.1x
        // (tools/scripts/h100-cpu-scaling.sh, 2026-11-26).
        let canvas = r.buffers.take().unwrap_or_else(|| {
            let mut fresh = Canvas::new(&s);
            self.pool.install(|| fresh.page_in());
            fresh
        });
        let (tracer, method) = (&r.tracer, r.method);
        let t0 = Instant::now();
        let image = self
            .pool
            .install(|| {
                let plan = tracer_cpu::render::plan(tracer, &s, method)?;
                tracer_cpu::render::render_into(tracer, &s, &plan, canvas, &|_| {})
            })
            .map_err(|e| e.to_string())?;
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        let rays = crate::bench::rays_of(&image.rays);
        r.buffers = Some(Canvas::reuse(image));
        Ok(Timed { ms, rays })
    }

    fn image(&self, r: &mut CpuRenderer<'_>, s: &Settings) -> Result<Image, String> {
        self.pool.install(|| tracer_cpu::render(&r.tracer, s, r.method)).map_err(|e| e.to_string())
    }

    fn image_with_self_hits(&self, r: &mut CpuRenderer<'_>, s: &Settings) -> Result<Image, String> {
        r.tracer.count_self_hits(true);
        let image = self.image(r, s);
        r.tracer.count_self_hits(false);
        image
    }
}
