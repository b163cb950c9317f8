//! The Vulkan tracer as a [`Bench`]: GPU time of whole frames from timestamp queries. `trace-vk
//! bench` times it, and `trace-eval` sets it beside the CPU.

use crate::bench::{Bench, Timed};
use bvh_format::SceneFile;
use render_spec::{Image, Settings};
use tracer_vk::Gpu;
use tracer_vk::kernels::{Method, Vertices};
use tracer_vk::render::Renderer;

/// Marks a method name for the exact kernels in [`VkBench::prepare`] (the evaluation's
/// `--exact on`).
pub const EXACT_SUFFIX: &str = "+exact";

/// Marks a method name for the indexed vertex form (`trace-vk bench --vertices indexed`).
pub const INDEXED_SUFFIX: &str = "+indexed";

/// The bench's name of `method` reading triangles in `form`: the method's own for the default
/// expanded form, with [`INDEXED_SUFFIX`] for the indexed one.
pub fn method_name(method: Method, form: Vertices) -> String {
    match form {
        Vertices::Expanded => method.name().to_owned(),
        Vertices::Indexed => format!("{}{INDEXED_SUFFIX}", method.name()),
    }
}

/// What `method` with triangles in `form` uploads of `scene` (nodes of its layout, triangles,
/// normals, materials, input indices), in all and per triangle.
pub fn upload_line(scene: &SceneFile, method: Method, form: Vertices) -> String {
    let bytes = tracer_vk::render::upload_bytes_with(scene, method, form);
    let tris = scene.triangles.len();
    format!(
        "{} with {} vertices uploads {} bytes of scene data, {:.1} per triangle ({tris} triangles, {} vertices)",
        method.name(),
        form.name(),
        bytes,
        bytes as f64 / tris.max(1) as f64,
        scene.vertices.len()
    )
}

/// A traversal by the name `trace-vk --method` takes.
pub fn method_of(name: &str) -> Result<Method, String> {
    Method::ALL.into_iter().find(|m| m.name() == name).ok_or_else(|| {
        let names: Vec<&str> = Method::ALL.iter().map(|m| m.name()).collect();
        format!("{name:?} is not a GPU method ({})", names.join(", "))
    })
}

/// Fails when the validation layer reported anything.
pub fn check_validation(gpu: &Gpu) -> Result<(), String> {
    match gpu.validation_messages().first() {
        None => Ok(()),
        Some(m) => Err(format!("the validation layer reported a problem: {}", m.lines().next().unwrap_or(""))),
    }
}

pub struct VkBench {
    pub gpu: Gpu,
    pub workgroup: (u32, u32),
    /// Exact kernels for every method (`trace-vk bench --exact`).
    pub exact: bool,
    /// Print each prepared method's bytes uploaded ([`upload_line`]; `trace-vk bench --vertices`).
    pub report_uploads: bool,
}

impl Bench for VkBench {
    type Renderer<'a> = Renderer<'a>;

    fn tracer(&self) -> &'static str {
        "vk"
    }

    fn device(&self) -> String {
        let i = self.gpu.info();
        format!("{} ({:?}, {})", i.name, i.kind, i.driver)
    }

    fn timing(&self) -> String {
        format!(
            "a frame's time is the GPU time of its passes from timestamp queries (workgroup {}x{}{})",
            self.workgroup.0,
            self.workgroup.1,
            if self.exact { ", exact kernels: no fused multiply-adds" } else { "" }
        )
    }

    /// `method` is a traversal's name, with [`EXACT_SUFFIX`] for its exact kernels and
    /// [`INDEXED_SUFFIX`] for the indexed vertex form (whose bytes uploaded it prints).
    fn prepare<'a>(&'a self, scene: &'a SceneFile, method: &str) -> Result<Renderer<'a>, String> {
        let (name, exact) = match method.strip_suffix(EXACT_SUFFIX) {
            Some(name) => (name, true),
            None => (method, self.exact),
        };
        let (name, form) = match name.strip_suffix(INDEXED_SUFFIX) {
            Some(name) => (name, Vertices::Indexed),
            None => (name, Vertices::Expanded),
        };
        let m = method_of(name)?;
        let mut r = Renderer::new(&self.gpu, scene, m, self.workgroup).map_err(|e| e.to_string())?;
        r.set_exact(exact);
        r.set_vertices(form).map_err(|e| e.to_string())?;
        if self.report_uploads {
            crate::say!("{}", upload_line(scene, m, form));
        }
        Ok(r)
    }

    fn frame(&self, r: &mut Renderer<'_>, s: &Settings) -> Result<Timed, String> {
        let out = r.render_frame(s, false).map_err(|e| e.to_string())?;
        Ok(Timed { ms: out.gpu_ms, rays: crate::bench::rays_of(&out.image.rays) })
    }

    fn image(&self, r: &mut Renderer<'_>, s: &Settings) -> Result<Image, String> {
        Ok(r.render(s).map_err(|e| e.to_string())?.image)
    }

    fn image_with_self_hits(&self, r: &mut Renderer<'_>, s: &Settings) -> Result<Image, String> {
        r.set_self_hits(true);
        let image = self.image(r, s);
        r.set_self_hits(false);
        image
    }

    fn finish(&self) -> Result<(), String> {
        check_validation(&self.gpu)
    }
}
