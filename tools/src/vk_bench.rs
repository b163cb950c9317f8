//! The Vulkan tracer as a [`Bench`]: GPU time of whole frames from timestamp queries. `trace-vk
//! bench` times it, and `trace-eval` sets it beside the CPU.

use crate::auto::Picker;
use crate::bench::{Bench, Timed};
use bvh_format::SceneFile;
use render_spec::{Image, Settings};
use std::path::Path;
use tracer_vk::Gpu;
use tracer_vk::kernels::{Method, Persistent, Vertices};
use tracer_vk::render::Renderer;

/// The method name that picks per setting ([`crate::auto`]).
pub const AUTO: &str = "auto";

/// Marks a method name for the exact kernels in [`VkBench::prepare`] (the evaluation's
/// `--exact on`).
pub const EXACT_SUFFIX: &str = "+exact";

/// Marks a method name for the indexed vertex form (`trace-vk bench --vertices indexed`).
pub use crate::bench::INDEXED_SUFFIX;

/// Marks a method name for its persistent kernels in every tracing stage (`trace-vk bench
/// --persistent on`).
pub const PERSISTENT_SUFFIX: &str = "+persistent";

/// Marks a method name for its plain kernels (`trace-vk bench --persistent off`) where the
/// default, `--persistent auto`, runs some stages persistently (LST and stackless).
pub const PLAIN_SUFFIX: &str = "+plain";

/// Marks a method name for persistent kernels refilling at this many idle lanes of 32 (`trace-vk
/// bench --persistent-refill N`): `lst+refill16`, `lst+persistent+refill8`.
pub const REFILL_SUFFIX: &str = "+refill";

/// The bench's name of `method` reading triangles in `form` with persistent threads as
/// `persistent` says, refilling at `refill` idle lanes (`None`: the setting's own). The method's
/// own name is its default: the expanded form and `--persistent auto`; [`INDEXED_SUFFIX`] names
/// the indexed form, then [`PLAIN_SUFFIX`] or [`PERSISTENT_SUFFIX`] the other settings, then
/// [`REFILL_SUFFIX`] a refill given (`lst+indexed+persistent+refill16`). For a method that cannot
/// run persistently, off and auto are the same plain kernels and share its own name.
pub fn method_name(method: Method, form: Vertices, persistent: Persistent, refill: Option<u32>) -> String {
    let name = crate::bench::with_form(method.name(), form);
    if !method.walks_in_steps() {
        return if persistent == Persistent::On { name + PERSISTENT_SUFFIX } else { name };
    }
    let name = match persistent {
        Persistent::Off => return name + PLAIN_SUFFIX,
        Persistent::On => name + PERSISTENT_SUFFIX,
        Persistent::Auto => name,
    };
    match refill {
        Some(r) => format!("{name}{REFILL_SUFFIX}{r}"),
        None => name,
    }
}

/// A bench method name ([`method_name`]) taken apart: the traversal's name with its form, the
/// persistent setting and the refill given.
pub fn split_persistent(name: &str) -> Result<(&str, Persistent, Option<u32>), String> {
    let (name, refill) = match name.rsplit_once(REFILL_SUFFIX) {
        Some((rest, n)) => {
            let n = n.parse::<u32>().ok().filter(|n| (1..=32).contains(n));
            (rest, Some(n.ok_or_else(|| format!("{name:?} names no refill threshold from 1 to 32"))?))
        }
        None => (name, None),
    };
    Ok(if let Some(rest) = name.strip_suffix(PERSISTENT_SUFFIX) {
        (rest, Persistent::On, refill)
    } else if let Some(rest) = name.strip_suffix(PLAIN_SUFFIX) {
        (rest, Persistent::Off, None)
    } else {
        (name, Persistent::Auto, refill)
    })
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
    /// `auto` calibrates even where the cache has a pick (`--recalibrate`).
    pub recalibrate: bool,
    /// `auto` picks among these (`--candidates`; empty: every method).
    pub candidates: Vec<Method>,
    /// Frames recorded into each submission, timed as their mean (`--in-flight`; 1: one).
    pub in_flight: u32,
    /// Tiles of at most this many pixels (`--tile-pixels`), below the device's own limit.
    pub tile_pixels: Option<u64>,
    /// Print each prepared method's bytes uploaded ([`upload_line`]; `trace-vk bench --vertices`).
    pub report_uploads: bool,
    /// Invocations a persistent kernel launches (`--persistent-invocations`; `None`: the
    /// renderer's default). The persistent setting and refill are the method name's
    /// ([`split_persistent`]).
    pub persistent_invocations: Option<u32>,
}

impl VkBench {
    /// A device's bench with one frame per submission and tiles as large as the device allows.
    pub fn new(gpu: Gpu, workgroup: (u32, u32), exact: bool) -> VkBench {
        VkBench {
            gpu,
            workgroup,
            exact,
            recalibrate: false,
            candidates: Vec::new(),
            in_flight: 1,
            tile_pixels: None,
            report_uploads: false,
            persistent_invocations: None,
        }
    }

    fn renderer<'a>(
        &'a self,
        scene: &'a SceneFile,
        method: Method,
        exact: bool,
        form: Vertices,
        (persistent, refill): (Persistent, Option<u32>),
    ) -> Result<Renderer<'a>, String> {
        let mut r = Renderer::new(&self.gpu, scene, method, self.workgroup).map_err(|e| e.to_string())?;
        r.set_exact(exact);
        r.set_vertices(form).map_err(|e| e.to_string())?;
        r.set_persistent_with(persistent, self.persistent_invocations, refill).map_err(|e| e.to_string())?;
        if self.report_uploads {
            crate::say!("{}", upload_line(scene, method, form));
        }
        r.set_frames_per_submission(self.in_flight);
        if let Some(p) = self.tile_pixels {
            r.limit_tile_pixels(p);
        }
        Ok(r)
    }
}

/// A renderer of one method, or `auto`'s: the method picked for the last settings and its
/// renderer, picked again when the settings change.
pub enum VkRenderer<'a> {
    Fixed(Box<Renderer<'a>>),
    Auto(Box<Auto<'a>>),
}

/// `auto`'s state: the pick of the last settings and its renderer.
pub struct Auto<'a> {
    bench: &'a VkBench,
    picker: Picker<'a>,
    current: Option<(Settings, Method, Renderer<'a>)>,
}

impl<'a> VkRenderer<'a> {
    fn for_settings(&mut self, s: &Settings) -> Result<&mut Renderer<'a>, String> {
        match self {
            VkRenderer::Fixed(r) => Ok(&mut **r),
            VkRenderer::Auto(auto) => {
                let Auto { bench, picker, current } = &mut **auto;
                // Settings that differ only in per-pixel outputs share a pick.
                let same = |c: &Settings| Settings { aovs: s.aovs, ..c.clone() } == *s;
                if !current.as_ref().is_some_and(|(c, _, _)| same(c)) {
                    let pick = picker.pick(s)?;
                    crate::say!("{}x{} {}: {}", s.width, s.height, s.mode.name(), pick.line());
                    let renderer = match current.take() {
                        Some((_, m, r)) if m == pick.method => r,
                        _ => bench.renderer(
                            picker.scene,
                            pick.method,
                            picker.exact,
                            Vertices::Expanded,
                            (picker.persistent, None),
                        )?,
                    };
                    *current = Some((s.clone(), pick.method, renderer));
                }
                Ok(&mut current.as_mut().expect("picked above").2)
            }
        }
    }
}

impl Bench for VkBench {
    type Renderer<'a> = VkRenderer<'a>;

    fn tracer(&self) -> &'static str {
        "vk"
    }

    fn device(&self) -> String {
        let i = self.gpu.info();
        format!("{} ({:?}, {})", i.name, i.kind, i.driver)
    }

    fn timing(&self) -> String {
        format!(
            "a frame's time is the GPU time of its passes from timestamp queries (workgroup {}x{}{}{}{}{})",
            self.workgroup.0,
            self.workgroup.1,
            if self.exact { ", exact kernels: no fused multiply-adds" } else { "" },
            if self.in_flight > 1 {
                format!(", {} frames recorded into each submission, their mean", self.in_flight)
            } else {
                String::new()
            },
            self.tile_pixels.map_or(String::new(), |p| format!(", tiles of at most {p} pixels")),
            self.persistent_invocations
                .map_or(String::new(), |n| format!(", persistent kernels launch {n} invocations"))
        )
    }

    /// `method` is a traversal's name, with [`EXACT_SUFFIX`] for its exact kernels and
    /// [`INDEXED_SUFFIX`] for the indexed vertex form (whose bytes uploaded it prints).
    fn prepare<'a>(&'a self, scene: &'a SceneFile, method: &str) -> Result<VkRenderer<'a>, String> {
        self.prepare_file(scene, None, method)
    }

    /// `auto` caches its picks beside `path`.
    fn prepare_file<'a>(
        &'a self,
        scene: &'a SceneFile,
        path: Option<&'a Path>,
        method: &str,
    ) -> Result<VkRenderer<'a>, String> {
        let (name, exact) = match method.strip_suffix(EXACT_SUFFIX) {
            Some(name) => (name, true),
            None => (method, self.exact),
        };
        if name == AUTO {
            let picker =
                Picker::new(&self.gpu, scene, path, self.workgroup, exact, self.recalibrate).among(&self.candidates);
            return Ok(VkRenderer::Auto(Box::new(Auto { bench: self, picker, current: None })));
        }
        let (name, persistent, refill) = split_persistent(name)?;
        let (name, form) = crate::bench::split_form(name);
        Ok(VkRenderer::Fixed(Box::new(self.renderer(scene, method_of(name)?, exact, form, (persistent, refill))?)))
    }

    fn unsupported(&self, method: &str) -> Option<String> {
        let name = method.strip_suffix(EXACT_SUFFIX).unwrap_or(method);
        let (name, persistent, _) = split_persistent(name).ok()?;
        let m = method_of(name.strip_suffix(INDEXED_SUFFIX).unwrap_or(name)).ok()?;
        if persistent == Persistent::On && !m.walks_in_steps() {
            return Some(format!("the {} traversal does not run as persistent threads", m.name()));
        }
        crate::auto::support(&self.gpu, m).err()
    }

    /// `auto:lst` for auto's pick of the last settings.
    fn method_label(&self, r: &VkRenderer<'_>, method: &str) -> String {
        match r {
            VkRenderer::Auto(a) => match &a.current {
                Some((_, m, _)) => format!("{method}:{}", m.name()),
                None => method.to_owned(),
            },
            VkRenderer::Fixed(_) => method.to_owned(),
        }
    }

    fn frame(&self, r: &mut VkRenderer<'_>, s: &Settings) -> Result<Timed, String> {
        let out = r.for_settings(s)?.render_frame(s, false).map_err(|e| e.to_string())?;
        Ok(Timed { ms: out.gpu_ms, rays: crate::bench::rays_of(&out.image.rays) })
    }

    fn image(&self, r: &mut VkRenderer<'_>, s: &Settings) -> Result<Image, String> {
        Ok(r.for_settings(s)?.render(s).map_err(|e| e.to_string())?.image)
    }

    fn image_with_self_hits(&self, r: &mut VkRenderer<'_>, s: &Settings) -> Result<Image, String> {
        let r = r.for_settings(s)?;
        r.set_self_hits(true);
        let image = r.render(s).map_err(|e| e.to_string()).map(|out| out.image);
        r.set_self_hits(false);
        image
    }

    fn finish(&self) -> Result<(), String> {
        check_validation(&self.gpu)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every bench name of a method, form, persistent setting and refill reads back as what made
    /// it; auto with the expanded form is the method's own name, and the methods that cannot run
    /// persistently share one name for off and auto.
    #[test]
    fn method_names_round_trip_and_the_default_is_the_bare_name() {
        let settings = [Persistent::Off, Persistent::On, Persistent::Auto];
        for method in Method::ALL {
            for form in [Vertices::Expanded, Vertices::Indexed] {
                for persistent in settings {
                    for refill in [None, Some(1), Some(16), Some(32)] {
                        let name = method_name(method, form, persistent, refill);
                        let (rest, p, r) = split_persistent(&name).unwrap();
                        let (base, f) = crate::bench::split_form(rest);
                        assert_eq!((method_of(base).unwrap(), f), (method, form), "{name}");
                        let walks = method.walks_in_steps();
                        let want = match persistent {
                            Persistent::Off if walks => (Persistent::Off, None),
                            Persistent::On if walks => (Persistent::On, refill),
                            Persistent::Auto if walks => (Persistent::Auto, refill),
                            Persistent::On => (Persistent::On, None),
                            _ => (Persistent::Auto, None),
                        };
                        assert_eq!((p, r), want, "{name}");
                    }
                }
            }
        }
        assert_eq!(method_name(Method::Lst, Vertices::Expanded, Persistent::Auto, None), "lst");
        assert_eq!(method_name(Method::Lst, Vertices::Expanded, Persistent::Off, Some(16)), "lst+plain");
        assert_eq!(
            method_name(Method::Stackless, Vertices::Indexed, Persistent::On, Some(8)),
            "stackless+indexed+persistent+refill8"
        );
        assert_eq!(method_name(Method::RtPipeline, Vertices::Expanded, Persistent::Off, None), "rt-pipeline");
        for bad in ["lst+refill0", "lst+refill33", "lst+refillx"] {
            assert!(split_persistent(bad).unwrap_err().contains("refill threshold"), "{bad}");
        }
    }
}
