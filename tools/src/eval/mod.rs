//! Speed against accuracy (issue 8, docs/accuracy.md): scenes x cameras x sizes x modes, each
//! rendered by the CPU tracer and the Vulkan tracer with every method and accuracy setting, timed
//! as `bench` times them ([`crate::bench::measure`]) and measured against a reference render
//! ([`reference`]) with [`render_metrics`]; written as CSV, Markdown and charts ([`report`],
//! [`chart`]).

pub mod chart;
pub mod reference;
pub mod report;

use crate::bench::{Bench, BenchMode, measure, parse_frames, parse_mode, parse_warmup};

/// A mode of the matrix that the exact reference renders (cast or whitted).
fn parse_reference_mode(s: &str) -> Result<BenchMode, String> {
    let m = parse_mode(s)?;
    match m.mode {
        render_spec::Mode::Cast | render_spec::Mode::Whitted => Ok(m),
        other => Err(format!(
            "{s:?}: the evaluation compares with the exact reference, which has no {} mode (cast, whitted1, whitted2, ...)",
            other.name()
        )),
    }
}
use crate::render_args::{
    self, IntersectArg, lights_n, parse_count, parse_offset, parse_res, parse_spp, stored_camera,
};
use bvh_format::SceneFile;
use clap::ValueEnum;
use reference::{Cache, Reference};
use render_spec::{Accuracy, Image, Intersect, Offset, Settings};
use report::Row;
use std::path::PathBuf;

/// The options of `trace-eval`.
#[derive(clap::Args, Debug, Clone)]
pub struct EvalArgs {
    /// Scenes: compiled .bvh files, meshes or scene descriptions [default: the built-in bunny].
    pub scenes: Vec<PathBuf>,
    /// Stored cameras to render from.
    #[arg(long, value_delimiter = ',', default_value = "medium", allow_hyphen_values = true)]
    pub cameras: Vec<String>,
    /// Image sizes.
    #[arg(long, value_delimiter = ',', value_parser = parse_res, default_value = "320x240", allow_hyphen_values = true)]
    pub res: Vec<(u32, u32)>,
    /// Modes: cast, or whitted with a light count (whitted1, whitted2, ...).
    #[arg(long, value_delimiter = ',', value_parser = parse_reference_mode, default_value = "whitted1", allow_hyphen_values = true)]
    pub modes: Vec<BenchMode>,
    /// CPU traversals (auto, packet, ordered, stackless, bvh8, bvh4, bvh8-packet), or none.
    #[arg(long, value_delimiter = ',', default_value = "auto")]
    pub cpu_methods: Vec<String>,
    /// GPU traversals (lst, stackless, sst, sst-subgroup, rt-pipeline), or none; one the device
    /// does not support is left out and named in eval.md with the reason.
    #[arg(long, value_delimiter = ',', default_value = "lst")]
    pub gpu_methods: Vec<String>,
    /// Triangle tests: watertight (the default test) and mt (Möller-Trumbore).
    #[arg(long, value_delimiter = ',', value_parser = parse_intersect, default_value = "watertight,mt")]
    pub intersect: Vec<Intersect>,
    /// Origin offsets of shadow and secondary rays: scale (scale-aware, the default) or a fixed
    /// distance in scene units.
    #[arg(long, value_delimiter = ',', value_parser = parse_offset, default_value = "scale,1e-4,1e-3,1e-2")]
    pub offset: Vec<Offset>,
    /// Samples per pixel (squares: 1, 4, 9, 16, ...).
    #[arg(long, value_delimiter = ',', value_parser = parse_spp, default_value = "1,4,16")]
    pub spp: Vec<u32>,
    /// Adaptive bounce stops: default (half an 8-bit step) or a contribution from 0 (every bounce).
    #[arg(long, value_delimiter = ',', value_parser = parse_cutoff, default_value = "default,0")]
    pub cutoff: Vec<f32>,
    /// Longest chains of secondary rays: scene (the file's) or a number, 0 to 64.
    #[arg(long, value_delimiter = ',', value_parser = parse_indirections, default_value = "scene")]
    pub indirections: Vec<Option<u32>>,
    /// GPU arithmetic without contracted multiply-adds: off, on (the CPU never contracts).
    #[arg(long, value_delimiter = ',', value_parser = parse_on_off, default_value = "off")]
    pub exact: Vec<bool>,
    /// Every combination of the values above; by default each value is tried alone, the other
    /// settings at their defaults.
    #[arg(long)]
    pub full: bool,
    /// Samples per pixel of the reference image (a square).
    #[arg(long, value_parser = parse_spp, default_value = "64")]
    pub reference_spp: u32,
    /// Timed frames per setting, 1 to 100000; the median is reported [default: 20 on the GPU, 5 on
    /// the CPU].
    #[arg(long, value_parser = parse_frames)]
    pub frames: Option<usize>,
    /// Untimed frames before the timed ones [default: 3 on the GPU, 2 on the CPU].
    #[arg(long, value_parser = parse_warmup)]
    pub warmup: Option<usize>,
    /// Folder for eval.csv, eval.md and the charts (created if missing).
    #[arg(long, default_value = "eval")]
    pub out: PathBuf,
    /// Folder of cached references [default: OUT/reference-cache].
    #[arg(long)]
    pub cache: Option<PathBuf>,
}

fn parse_intersect(s: &str) -> Result<Intersect, String> {
    IntersectArg::from_str(s.trim(), false)
        .map(IntersectArg::intersect)
        .map_err(|_| format!("{s:?} is not a triangle test (watertight, mt)"))
}

/// `default` (half an 8-bit step), or a cutoff as `--cutoff` takes it.
fn parse_cutoff(s: &str) -> Result<f32, String> {
    if s.trim() == "default" { Ok(Accuracy::default().cutoff) } else { render_args::parse_cutoff(s) }
}

fn parse_indirections(s: &str) -> Result<Option<u32>, String> {
    match s.trim() {
        "scene" => Ok(None),
        t => parse_count(t, 0, render_args::MAX_INDIRECTIONS, "the number of indirections").map(|n| Some(n as u32)),
    }
}

fn parse_on_off(s: &str) -> Result<bool, String> {
    match s.trim() {
        "off" => Ok(false),
        "on" => Ok(true),
        _ => Err(format!("{s:?} is neither on nor off")),
    }
}

/// One point of the settings axes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Variant {
    pub accuracy: Accuracy,
    /// `None`: the scene's.
    pub indirections: Option<u32>,
    /// GPU only: no contracted multiply-adds.
    pub exact: bool,
}

impl Variant {
    /// A short name of what differs from the defaults ("default", "mt", "offset 1e-3", "spp 4",
    /// "mt + spp 4", ...): the label of its marker in the charts.
    pub fn label(&self) -> String {
        let d = Accuracy::default();
        let a = &self.accuracy;
        let mut parts = Vec::new();
        if a.intersect != d.intersect {
            parts.push(intersect_name(a.intersect).to_owned());
        }
        if a.offset != d.offset {
            parts.push(format!("offset {}", offset_name(a.offset)));
        }
        if a.spp != d.spp {
            parts.push(format!("spp {}", a.spp));
        }
        if a.cutoff != d.cutoff {
            parts.push(format!("cutoff {}", a.cutoff));
        }
        if let Some(n) = self.indirections {
            parts.push(format!("ind {n}"));
        }
        if self.exact {
            parts.push("exact".to_owned());
        }
        if parts.is_empty() { "default".to_owned() } else { parts.join(" + ") }
    }
}

pub fn intersect_name(i: Intersect) -> &'static str {
    match i {
        Intersect::Watertight => "watertight",
        Intersect::MollerTrumbore => "mt",
    }
}

pub fn offset_name(o: Offset) -> String {
    match o {
        Offset::ScaleAware => "scale".to_owned(),
        Offset::Fixed(d) => format!("{d:e}"),
    }
}

/// The settings to try: each value of each axis alone with the others at their defaults (the
/// default setting once), or with `full` every combination.
pub fn variants(a: &EvalArgs) -> Vec<Variant> {
    let d = Variant::default();
    let mut out = vec![d];
    let mut push = |v: Variant| {
        if !out.contains(&v) {
            out.push(v);
        }
    };
    if a.full {
        for &intersect in &a.intersect {
            for &offset in &a.offset {
                for &spp in &a.spp {
                    for &cutoff in &a.cutoff {
                        for &indirections in &a.indirections {
                            for &exact in &a.exact {
                                let accuracy = Accuracy { intersect, offset, spp, cutoff };
                                push(Variant { accuracy, indirections, exact });
                            }
                        }
                    }
                }
            }
        }
    } else {
        let acc = d.accuracy;
        a.intersect.iter().for_each(|&intersect| push(Variant { accuracy: Accuracy { intersect, ..acc }, ..d }));
        a.offset.iter().for_each(|&offset| push(Variant { accuracy: Accuracy { offset, ..acc }, ..d }));
        a.spp.iter().for_each(|&spp| push(Variant { accuracy: Accuracy { spp, ..acc }, ..d }));
        a.cutoff.iter().for_each(|&cutoff| push(Variant { accuracy: Accuracy { cutoff, ..acc }, ..d }));
        a.indirections.iter().for_each(|&indirections| push(Variant { indirections, ..d }));
        a.exact.iter().for_each(|&exact| push(Variant { exact, ..d }));
    }
    out
}

/// A tracer to evaluate: a [`Bench`] and the method names it takes. `exact` names the method
/// string of an exact variant, or `None` where the tracer is always exact (the CPU).
pub struct Tracer<'b, B: Bench> {
    pub bench: &'b B,
    pub methods: Vec<String>,
    pub exact_method: fn(&str) -> Option<String>,
    pub frames: usize,
    pub warmup: usize,
}

impl<B: Bench> Tracer<'_, B> {
    /// The methods the device runs.
    fn runnable(&self) -> Vec<&String> {
        self.methods.iter().filter(|m| self.bench.unsupported(m).is_none()).collect()
    }

    /// The methods the device does not support, each with the reason (left out, and said so).
    fn unsupported(&self) -> Vec<String> {
        self.methods.iter().filter_map(|m| self.bench.unsupported(m).map(|why| format!("{m} ({why})"))).collect()
    }

    /// The settings of `variants` this tracer does not implement (left out, and said so).
    fn left_out(&self, variants: &[Variant]) -> Vec<String> {
        if self.methods.is_empty() {
            return Vec::new();
        }
        variants.iter().filter(|v| !self.bench.honours(&v.accuracy)).map(Variant::label).collect()
    }

    /// How many settings of `variants` this tracer measures per frame: exact variants only
    /// where it has an exact form.
    fn settings(&self, variants: &[Variant]) -> usize {
        let exact = |m: &String| {
            variants
                .iter()
                .filter(|v| (!v.exact || (self.exact_method)(m).is_some()) && self.bench.honours(&v.accuracy))
                .count()
        };
        self.runnable().into_iter().map(exact).sum()
    }
}

/// One frame of the matrix with its references.
struct Frame {
    camera: String,
    base: Settings,
    converged: Image,
    one_sample: Image,
}

/// Runs the evaluation and writes its tables and charts. Returns the rows.
pub fn run<C: Bench, G: Bench>(
    args: &EvalArgs,
    reference: &dyn Reference,
    cpu: &Tracer<'_, C>,
    gpu: &Tracer<'_, G>,
) -> Result<Vec<Row>, String> {
    let variants = variants(args);
    if args.cameras.is_empty() || args.res.is_empty() || args.modes.is_empty() {
        return Err("the evaluation is empty: give at least one camera, size and mode".to_owned());
    }
    if cpu.methods.is_empty() && gpu.methods.is_empty() {
        return Err("the evaluation is empty: give at least one CPU or GPU method".to_owned());
    }
    std::fs::create_dir_all(&args.out).map_err(|e| format!("cannot create {}: {e}", args.out.display()))?;
    let cache = Cache::new(&args.cache.clone().unwrap_or_else(|| args.out.join("reference-cache")))?;
    let scenes: Vec<Option<PathBuf>> =
        if args.scenes.is_empty() { vec![None] } else { args.scenes.iter().cloned().map(Some).collect() };
    let frames_per_scene = args.cameras.len() * args.res.len() * args.modes.len();
    let steps = scenes.len() * frames_per_scene * (2 + cpu.settings(&variants) + gpu.settings(&variants));
    let bar =
        crate::cli::Progress::new(steps as u64, "{bar:40} {pos}/{len} renders ({elapsed}, {eta} left) {msg}", false);
    let mut rows = Vec::new();
    for path in &scenes {
        let name = path
            .as_ref()
            .and_then(|p| p.file_stem())
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "bunny".to_owned());
        bar.set_message(format!("loading {name}"));
        let scene = crate::load_scene(path.as_deref())?.file;
        let hash = reference::scene_hash(&scene)?;
        let mut frames = Vec::with_capacity(frames_per_scene);
        for cam in &args.cameras {
            let camera = stored_camera(&scene, cam)?;
            for &(width, height) in &args.res {
                for mode in &args.modes {
                    let base = Settings {
                        width,
                        height,
                        camera,
                        mode: mode.mode,
                        lights: lights_n(&scene, mode.lights, &camera),
                        max_indirections: scene.settings.max_indirections,
                        aovs: false,
                        accuracy: Accuracy::default(),
                    };
                    bar.set_message(format!("reference of {name} {cam} {width}x{height} {}", mode.name()));
                    let conv = reference::converged(&base, &scene, args.reference_spp);
                    let (converged, _) = cache.get_or_render(reference, &scene, hash, &conv)?;
                    bar.inc(1);
                    let one = reference::one_sample(&base, &scene);
                    let (one_sample, _) = cache.get_or_render(reference, &scene, hash, &one)?;
                    bar.inc(1);
                    frames.push(Frame { camera: cam.clone(), base, converged, one_sample });
                }
            }
        }
        let context = Context { name: &name, scene: &scene, frames: &frames, variants: &variants, bar: &bar };
        rows.extend(evaluate(&context, cpu, false)?);
        rows.extend(evaluate(&context, gpu, true)?);
    }
    bar.finish();
    cpu.bench.finish()?;
    gpu.bench.finish()?;
    let devices = [
        (cpu.bench.tracer(), cpu.bench.device(), cpu.bench.timing(), cpu.frames, cpu.warmup),
        (gpu.bench.tracer(), gpu.bench.device(), gpu.bench.timing(), gpu.frames, gpu.warmup),
    ];
    let preface: Vec<String> = devices
        .iter()
        .map(|(t, d, timing, f, w)| {
            format!("`{t}`: {d}; the median of {f} timed frames per setting after at least {w} untimed frames, 1 s of them and more until their times settled; {timing}.")
        })
        .chain(
            [(cpu.bench.tracer(), cpu.left_out(&variants)), (gpu.bench.tracer(), gpu.left_out(&variants))]
                .into_iter()
                .filter(|(_, l)| !l.is_empty())
                .map(|(t, l)| {
                    format!("`{t}` does not implement these settings yet; they were left out: {}.", l.join(", "))
                }),
        )
        .chain(
            [(cpu.bench.tracer(), cpu.unsupported()), (gpu.bench.tracer(), gpu.unsupported())]
                .into_iter()
                .filter(|(_, l)| !l.is_empty())
                .map(|(t, l)| format!("`{t}`: not supported on this device, so no rows: {}.", l.join("; "))),
        )
        .chain([format!(
            "Reference: {}, {} samples per pixel, every bounce up to the scene's indirections (cutoff 0); hit errors \
             against its one-sample render.",
            reference.name(),
            args.reference_spp
        )])
        .collect();
    let written = report::write(&args.out, &preface, &rows)?;
    for w in written {
        crate::say!("-> {}", w.display());
    }
    Ok(rows)
}

struct Context<'a> {
    name: &'a str,
    scene: &'a SceneFile,
    frames: &'a [Frame],
    variants: &'a [Variant],
    bar: &'a crate::cli::Progress,
}

/// Every method and variant of one tracer on one scene's frames.
fn evaluate<B: Bench>(c: &Context<'_>, t: &Tracer<'_, B>, gpu: bool) -> Result<Vec<Row>, String> {
    let mut rows = Vec::new();
    for method in t.runnable() {
        for exact in [false, true] {
            let run_method = match (exact, (t.exact_method)(method)) {
                (false, _) => method.clone(),
                (true, Some(m)) => m,
                (true, None) => continue,
            };
            let chosen: Vec<&Variant> =
                c.variants.iter().filter(|v| v.exact == exact && t.bench.honours(&v.accuracy)).collect();
            if chosen.is_empty() {
                continue;
            }
            let mut renderer = t.bench.prepare(c.scene, &run_method)?;
            for f in c.frames {
                // One-sample renders with AOVs, shared by the variants of one test and offset.
                let mut hit_renders: Vec<((Intersect, Offset), Image)> = Vec::new();
                for v in &chosen {
                    c.bar.set_message(format!(
                        "{} {} {}x{} {} {method} {}",
                        c.name,
                        f.camera,
                        f.base.width,
                        f.base.height,
                        t.bench.tracer(),
                        v.label()
                    ));
                    let settings = Settings {
                        max_indirections: v.indirections.unwrap_or(f.base.max_indirections),
                        accuracy: crate::render_args::in_scene_unit(v.accuracy, c.scene),
                        ..f.base.clone()
                    };
                    let m = measure(t.bench, &mut renderer, &settings, t.warmup, t.frames)?;
                    let image = t.bench.image(&mut renderer, &settings)?;
                    // The hits and shadows of the variant's triangle test and offset, with the
                    // reference's one sample and bounces, so that only geometry differs.
                    let key = (v.accuracy.intersect, v.accuracy.offset);
                    let at = match hit_renders.iter().position(|(k, _)| *k == key) {
                        Some(at) => at,
                        None => {
                            let s = Settings {
                                aovs: true,
                                accuracy: crate::render_args::in_scene_unit(
                                    Accuracy { spp: 1, cutoff: 0.0, ..v.accuracy },
                                    c.scene,
                                ),
                                ..f.base.clone()
                            };
                            hit_renders.push((key, t.bench.image_with_self_hits(&mut renderer, &s)?));
                            hit_renders.len() - 1
                        }
                    };
                    let one = &hit_renders[at].1;
                    let img = render_metrics::compare_images(&f.converged, &image).map_err(|e| e.to_string())?;
                    let hits = render_metrics::compare_hits(&f.one_sample, one).map_err(|e| e.to_string())?;
                    let shifts = render_metrics::shading_shifts(&f.one_sample, one).map_err(|e| e.to_string())?;
                    rows.push(Row {
                        scene: c.name.to_owned(),
                        triangles: c.scene.triangles.len() as u64,
                        camera: f.camera.clone(),
                        width: f.base.width,
                        height: f.base.height,
                        mode: report::mode_name(&f.base),
                        tracer: t.bench.tracer().to_owned(),
                        gpu,
                        device: t.bench.device(),
                        method: method.clone(),
                        setting: v.label(),
                        variant: **v,
                        indirections: settings.max_indirections,
                        median_ms: m.median_ms,
                        min_ms: m.min_ms,
                        // The reference has no incoherent modes (parse_reference_mode): no
                        // AO or diffuse rays to lose.
                        rays: [m.rays[0], m.rays[1], m.rays[2]],
                        image: img,
                        hits,
                        shifts,
                        self_hits: one.rays.self_hits.total(),
                    });
                    c.bar.inc(1);
                }
            }
        }
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser)]
    struct Cli {
        #[command(flatten)]
        eval: EvalArgs,
    }

    fn args(extra: &[&str]) -> EvalArgs {
        Cli::try_parse_from(std::iter::once("eval").chain(extra.iter().copied())).unwrap().eval
    }

    #[test]
    fn each_value_is_tried_alone_unless_every_combination_is_asked_for() {
        let a =
            args(&["--intersect", "watertight,mt", "--offset", "scale,1e-3", "--spp", "1,4", "--cutoff", "default"]);
        let labels: Vec<String> = variants(&a).iter().map(Variant::label).collect();
        assert_eq!(labels, ["default", "mt", "offset 1e-3", "spp 4"]);
        let full = args(&["--intersect", "watertight,mt", "--offset", "scale,1e-3", "--spp", "1,4", "--full"]);
        assert_eq!(variants(&full).len(), 2 * 2 * 2 * 2);
        assert!(variants(&full).iter().any(|v| v.label() == "mt + offset 1e-3 + spp 4 + cutoff 0"));
    }

    #[test]
    fn axis_values_parse_or_explain() {
        assert_eq!(parse_offset("1e-4").unwrap(), Offset::Fixed(1e-4));
        assert!(parse_offset("-1").is_err() && parse_offset("nan").is_err());
        assert_eq!(parse_spp("16").unwrap(), 16);
        assert!(parse_spp("8").unwrap_err().contains("square"), "{}", parse_spp("8").unwrap_err());
        assert_eq!(parse_cutoff("0").unwrap(), 0.0);
        assert_eq!(parse_intersect("mt").unwrap(), Intersect::MollerTrumbore);
        assert_eq!(parse_indirections("scene").unwrap(), None);
        assert!(parse_on_off("maybe").is_err());
    }
}
