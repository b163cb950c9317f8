//! The render options of `trace-cpu render` and `trace-vk render`: same names, same meaning, and
//! the same sentence for the same mistake, because both parse and check them here. Every value
//! may start with `-` (`--eye -15,-11,0`): a negative number is a value, never an option.

use crate::output::{self, Kind, Output};
use bvh_format::{Light, SceneFile};
use clap::{Args, ValueEnum};
use glam::{DVec3, Vec3};
use render_spec::{Accuracy, Ao, CameraSpec, Image, Intersect, Mode, Offset, Settings, Vertices};
use std::path::PathBuf;
use tracer_vk::kernels::Persistent;

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// Ray casting: one white light at the eye, Lambert only.
    Cast,
    /// Whitted ray tracing: lights with shadows, Phong, reflection and refraction.
    Whitted,
    /// Ambient occlusion: the fraction of --ao-samples cosine-distributed rays of --ao-length
    /// that leave each primary hit unblocked (grey; a miss shows the background).
    Ao,
    /// One cosine-distributed bounce of full length per primary hit: the hit's colour times what
    /// the bounce sees (lit from the hit, as ray casting lights) or the background.
    Diffuse,
}

/// The triangle test (`--intersect`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum IntersectArg {
    /// The watertight test: docs/shading.md's edge-consistent test, where two triangles sharing
    /// an edge compute it with exactly opposite signs, so no ray passes between them.
    Watertight,
    /// Möller-Trumbore: fewer operations, but each triangle rounds a shared edge its own way, so
    /// a ray aimed exactly at one can pass between both triangles (a leak).
    Mt,
}

impl IntersectArg {
    pub fn intersect(self) -> Intersect {
        match self {
            IntersectArg::Watertight => Intersect::Watertight,
            IntersectArg::Mt => Intersect::MollerTrumbore,
        }
    }
}

/// How a tracer reads triangle corners (`--vertices`, `bench --vertices`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum VerticesArg {
    /// Three vertices per triangle in leaf order, 48 bytes, one contiguous read.
    Expanded,
    /// The file's indexed form: vertex indices per triangle and every vertex once, one read more
    /// per triangle through the index.
    Indexed,
}

impl VerticesArg {
    pub fn vertices(self) -> Vertices {
        match self {
            VerticesArg::Expanded => Vertices::Expanded,
            VerticesArg::Indexed => Vertices::Indexed,
        }
    }
}

/// Which of the Vulkan tracer's tracing stages run as persistent threads (`trace-vk render
/// --persistent`, `trace-vk bench --persistent off,on,auto`; `Renderer::set_persistent`): as many
/// workgroups as the device holds at once, each subgroup taking pixels from a counter and giving
/// lanes whose ray ended a new pixel (Aila and Laine 2009). LST and stackless; the images are the
/// plain kernels'. Which stage runs how is `tracer_vk::kernels::Specialisation::persistent_stage`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PersistentArg {
    /// One invocation per pixel, as many workgroups as the tile has.
    Off,
    /// Persistent threads in every tracing stage (refill at 8 idle lanes of 32).
    On,
    /// Persistent threads where they win on the H100: the AO and diffuse stages (incoherent rays,
    /// refill at 16 idle lanes), plain kernels for primary, shadow and mirror rays; plain
    /// everywhere for the methods that cannot run persistently.
    Auto,
}

impl PersistentArg {
    pub fn persistent(self) -> Persistent {
        match self {
            PersistentArg::Off => Persistent::Off,
            PersistentArg::On => Persistent::On,
            PersistentArg::Auto => Persistent::Auto,
        }
    }
}

/// How persistent kernels run (`trace-vk render`, with `--persistent on` or `auto`).
#[derive(Args, Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct PersistentTuning {
    /// Invocations a persistent kernel launches [default: 270336, an H100 SXM full].
    #[arg(long, value_parser = parse_persistent_invocations)]
    pub persistent_invocations: Option<u32>,
    /// Lanes of every 32 that must be idle before a persistent subgroup gives them new pixels (1:
    /// as soon as one is; 32: only when all are, no replacement) [default: 8 with --persistent on,
    /// 16 in auto's AO and diffuse stages].
    #[arg(long, value_parser = parse_persistent_refill)]
    pub persistent_refill: Option<u32>,
}

/// [`PersistentTuning`] of `trace-vk bench`: refill thresholds side by side.
#[derive(Args, Debug, Clone, PartialEq, Eq, Default)]
pub struct BenchPersistentTuning {
    /// Invocations a persistent kernel launches [default: 270336, an H100 SXM full].
    #[arg(long, value_parser = parse_persistent_invocations)]
    pub persistent_invocations: Option<u32>,
    /// Time the persistent rows (--persistent on, auto) with each of these refill thresholds, idle
    /// lanes of 32 before a refill, side by side: rows named METHOD+refillN or
    /// METHOD+persistent+refillN [default: each setting's own, 8 for on, 16 for auto].
    #[arg(long, value_delimiter = ',', value_parser = parse_persistent_refill)]
    pub persistent_refill: Vec<u32>,
}

fn parse_persistent_invocations(s: &str) -> Result<u32, String> {
    parse_count(s, 1, 1 << 24, "the invocations a persistent kernel launches").map(|n| n as u32)
}

fn parse_persistent_refill(s: &str) -> Result<u32, String> {
    parse_count(s, 1, 32, "the idle lanes of 32 before a refill").map(|n| n as u32)
}

/// The most lights a render takes (`--light` repeated, or `--lights N`).
pub const MAX_LIGHTS: usize = 256;

#[derive(Args, Debug, Clone)]
pub struct RenderArgs {
    /// Scene: a compiled .bvh file, or a mesh / scene description compiled with default settings
    /// [default: the built-in bunny].
    pub scene: Option<PathBuf>,
    /// Shading mode.
    #[arg(long, value_enum, default_value = "whitted")]
    pub mode: ModeArg,
    /// A camera stored in the scene [default: the scene's first camera; the shipped scenes and
    /// meshes have "medium" first, then "close-up" and "wide"; `bvhc info` lists them].
    #[arg(long, conflicts_with_all = ["eye", "at"])]
    pub camera: Option<String>,
    /// Eye position X,Y,Z in world coordinates (with --at; replaces --camera). Negative numbers
    /// need no `=`.
    #[arg(long, value_parser = parse_point, requires = "at", allow_hyphen_values = true)]
    pub eye: Option<DVec3>,
    /// Look-at point X,Y,Z in world coordinates.
    #[arg(long, value_parser = parse_point, requires = "eye", allow_hyphen_values = true)]
    pub at: Option<DVec3>,
    /// Up vector X,Y,Z [default: with --eye 0,1,0; a stored camera keeps its own unless given].
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub up: Option<Vec3>,
    /// Vertical field of view in degrees, between 0 and 180 (with --eye: default 45; a stored
    /// camera keeps its own unless given).
    #[arg(long, value_parser = parse_fov, allow_hyphen_values = true)]
    pub fov: Option<f32>,
    /// Image size, at most 2^28 pixels.
    #[arg(long, value_parser = parse_res, default_value = "640x480", allow_hyphen_values = true)]
    pub res: (u32, u32),
    /// A point light X,Y,Z or X,Y,Z,R,G,B in world coordinates (repeatable, up to 256); replaces
    /// the scene's lights.
    #[arg(long = "light", value_parser = parse_light, allow_hyphen_values = true)]
    pub lights: Vec<WorldLight>,
    /// Use this many lights: the scene's first ones, completed by lights placed around the
    /// camera so that what it sees is lit (the thesis's 1-, 2- and 4-light modes); 0 to 256.
    #[arg(long = "lights", conflicts_with = "lights", value_parser = parse_light_count, allow_hyphen_values = true)]
    pub light_count: Option<usize>,
    /// Longest chain of secondary rays, 0 to 64; rendering stops early once no path is alive
    /// [default: the scene's].
    #[arg(long, value_parser = parse_indirections, allow_hyphen_values = true)]
    pub indirections: Option<u32>,
    /// Output image: .png, .jpg/.jpeg (quality 95), .bmp (8-bit), or .exr (linear float RGB).
    #[arg(short, long, default_value = "out.png", allow_hyphen_values = true)]
    pub output: PathBuf,
    /// Also write the traversal cost (nodes visited per pixel) as a false-colour image (.png,
    /// .jpg, .bmp) with its scale drawn below it.
    #[arg(long, allow_hyphen_values = true)]
    pub heatmap: Option<PathBuf>,
    /// The node count shown as red in the heatmap [default: the image's maximum]; a fixed scale
    /// makes two heatmaps comparable.
    #[arg(long, value_parser = parse_positive, requires = "heatmap", allow_hyphen_values = true)]
    pub heatmap_max: Option<u32>,
    /// Also write per-pixel outputs as OpenEXR (.exr): t, N.X, N.Y, N.Z, prim, nodes, tris (with
    /// --spp above 1: t, N and prim of each pixel's first sample, nodes and tris over all).
    #[arg(long, allow_hyphen_values = true)]
    pub aov: Option<PathBuf>,
    /// Ambient-occlusion rays per primary hit (--mode ao), 1 to 1024.
    #[arg(long, value_parser = parse_ao_samples, default_value = "8", allow_hyphen_values = true)]
    pub ao_samples: u32,
    /// Length of the ambient-occlusion rays (--mode ao) as a fraction of the diagonal of the
    /// scene's bounding box, above 0 (0.1: a tenth of the scene).
    #[arg(long, value_parser = parse_ao_length, default_value = "0.1", allow_hyphen_values = true)]
    pub ao_length: f32,
    /// Triangle test: watertight (no ray passes between two triangles sharing an edge) or mt
    /// (Möller-Trumbore: fewer operations, but leaks at shared edges).
    #[arg(long, value_enum, default_value = "watertight", help_heading = "Accuracy")]
    pub intersect: IntersectArg,
    /// How far shadow and secondary rays start from the surface they leave: `scale` (a few units
    /// in the last place of the coordinates, right for any scene size) or a fixed distance in
    /// scene units along the normal, such as 1e-4, 1e-3 or 1e-2 (too small gives shadow acne, too
    /// large loses contact shadows).
    #[arg(long, value_parser = parse_offset, default_value = "scale", allow_hyphen_values = true, help_heading = "Accuracy")]
    pub offset: Offset,
    /// Samples per pixel: a square, 1, 4, 9, 16, ... up to 1024, on the centres of an n x n grid
    /// in each pixel; the pixel is their mean linear colour, quantised once.
    #[arg(long, value_parser = parse_spp, default_value = "1", allow_hyphen_values = true, help_heading = "Accuracy")]
    pub spp: u32,
    /// The adaptive bounce stop: a secondary ray whose whole chain could add less than this to a
    /// colour channel (1 = white) is not traced; 0 traces every bounce up to --indirections
    /// [default: half an 8-bit step, 1/510, which cannot change an 8-bit pixel].
    #[arg(long, value_parser = parse_cutoff, allow_hyphen_values = true, help_heading = "Accuracy")]
    pub cutoff: Option<f32>,
    /// Bit-exact arithmetic: trace-vk builds kernels whose float operations the GPU's compiler
    /// may not fuse into multiply-adds, whose divisions and square roots are correctly rounded,
    /// and which keep subnormals where the device allows it (shaderDenormPreserveFloat32), so
    /// that its images equal trace-cpu's bit for bit (at some cost in speed). The CPU tracer never
    /// fuses them, so trace-cpu is always exact.
    #[arg(long, help_heading = "Accuracy")]
    pub exact: bool,
    /// How the tracer reads triangle corners, a trade of memory for reads with the same images:
    /// expanded (a copy of 48 bytes per triangle: trace-cpu holds it beside the file, trace-vk
    /// uploads it) or indexed (the file's own arrays: trace-cpu reads them in place, trace-vk
    /// uploads 16 bytes per triangle and per vertex; one read more per triangle). trace-cpu's
    /// bvh8, bvh4 and auto test the leaf blocks of their wide BVH, a copy of their own in either form.
    /// Given, the report says the bytes held (trace-cpu) or uploaded (trace-vk) per triangle
    /// [default: expanded].
    #[arg(long, value_enum)]
    pub vertices: Option<VerticesArg>,
    /// Count exact acne: the shadow, secondary, AO and diffuse rays that the triangle they leave
    /// from meets (one more triangle test per such ray), reported on a line of their own.
    #[arg(long, help_heading = "Accuracy")]
    pub self_hits: bool,
}

/// The checked outputs of a render.
pub struct RenderOutputs {
    pub image: Output,
    pub heatmap: Option<Output>,
    pub aov: Option<Output>,
}

impl RenderOutputs {
    /// Writes every output of a rendered image (the colour image, then the heatmap and the AOVs
    /// where asked for) and returns the report lines of the heatmap and the AOVs, so that a caller
    /// prints only after every file is complete.
    /// Writes every output of `image`; `linear` is its unquantised colour where the tracer has it
    /// (written to an EXR colour image instead of the 8-bit values). The `t` AOV is written in
    /// world units (the tracers measure in the scene's stored unit, see
    /// [`SceneFile::scale_log2`]).
    pub fn write(
        &self,
        image: &Image,
        linear: Option<&[[f32; 3]]>,
        heatmap_max: Option<u32>,
        scene: &SceneFile,
    ) -> Result<Vec<String>, String> {
        let frame = output::Frame { width: image.width, height: image.height, rgb: &image.rgb, linear };
        output::write_image(&self.image, &frame).map_err(|e| e.to_string())?;
        let mut lines = Vec::new();
        if let Some(aov) = &image.aov {
            if let Some(out) = &self.heatmap {
                let h = output::Heatmap::new(image.width, image.height, &aov.nodes, heatmap_max);
                output::write_heatmap(out, &h).map_err(|e| e.to_string())?;
                lines.push(heatmap_line(&h, out));
            }
            if let Some(out) = &self.aov {
                let world;
                let aov = if scene.scale_log2 == 0 {
                    aov
                } else {
                    let t = aov.t.iter().map(|&t| scene.world_distance(t) as f32).collect();
                    world = render_spec::Aovs { t, ..aov.clone() };
                    &world
                };
                output::write_aov(out, image.width, image.height, aov).map_err(|e| e.to_string())?;
                lines.push(format!("AOVs (t, N.X, N.Y, N.Z, prim, nodes, tris) -> {}", out.path.display()));
            }
        }
        Ok(lines)
    }
}

/// A light given on the command line: its position in world coordinates (f64, so that a light
/// far from the origin keeps its place relative to the scene, see [`SceneFile::local`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorldLight {
    pub position: DVec3,
    pub colour: [f32; 3],
}

fn parse_floats(s: &str, counts: &[usize], what: &str) -> Result<Vec<f32>, String> {
    Ok(parse_f64s(s, counts, what)?.into_iter().map(|x| x as f32).collect())
}

/// Numbers that are finite as f32 too, kept in f64.
fn parse_f64s(s: &str, counts: &[usize], what: &str) -> Result<Vec<f64>, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if !counts.contains(&parts.len()) {
        return Err(format!("{s:?} has {} values; {what}", parts.len()));
    }
    parts
        .iter()
        .map(|p| match p.parse::<f64>() {
            Ok(x) if (x as f32).is_finite() => Ok(x),
            Ok(_) => Err(format!("{p:?} is not a finite number (finite f32 values lie within ±3.4e38)")),
            Err(_) => Err(format!("{p:?} is not a number; {what}")),
        })
        .collect()
}

/// A point in world coordinates, X,Y,Z.
pub fn parse_point(s: &str) -> Result<DVec3, String> {
    let v = parse_f64s(s, &[3], "give 3 numbers X,Y,Z")?;
    Ok(DVec3::new(v[0], v[1], v[2]))
}

pub fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let v = parse_floats(s, &[3], "give 3 numbers X,Y,Z")?;
    Ok(Vec3::new(v[0], v[1], v[2]))
}

/// A size `WxH`, such as an image size or a workgroup shape, each side at least 1 and the
/// product at most `max` (named `what` in the message).
fn parse_size(s: &str, what: &str, max: u64) -> Result<(u32, u32), String> {
    let bad = || format!("{s:?} is not {what} like 640x480 (two whole numbers joined by x)");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let side = |v: &str| v.trim().parse::<i64>().map_err(|_| bad());
    let (w, h) = (side(w)?, side(h)?);
    if w < 1 || h < 1 {
        return Err(format!("{s:?}: the width and height of {what} must be at least 1"));
    }
    if (w as u64).saturating_mul(h as u64) > max || w > u32::MAX as i64 || h > u32::MAX as i64 {
        return Err(format!("{s:?}: {what} may have at most {max} pixels"));
    }
    Ok((w as u32, h as u32))
}

/// Most pixels of an image: 2^28 (16384 x 16384).
pub const MAX_PIXELS: u64 = 1 << 28;

pub fn parse_res(s: &str) -> Result<(u32, u32), String> {
    parse_size(s, "an image size", MAX_PIXELS)
}

/// A workgroup shape the GPU kernels take on every device that offers enough invocations (see
/// [`tracer_vk::render::workgroup_allowed`]; a device's own lower limit is checked when the
/// kernels are built).
pub fn parse_workgroup(s: &str) -> Result<(u32, u32), String> {
    let max = tracer_vk::render::MAX_WORKGROUP_INVOCATIONS;
    let (w, h) = parse_size(s, "a workgroup shape", max as u64)?;
    if !tracer_vk::render::workgroup_allowed(w, h, max) {
        return Err(format!(
            "{s:?}: a workgroup's width and height must be powers of two (1, 2, 4, ... with at most {max} invocations in all), such as 8x8 (the default), 16x16 or 32x4"
        ));
    }
    Ok((w, h))
}

pub fn parse_fov(s: &str) -> Result<f32, String> {
    match s.trim().parse::<f32>() {
        Ok(f) if f > 0.0 && f < 180.0 => Ok(f),
        _ => Err(format!("{s:?}: the field of view is in degrees and must lie strictly between 0 and 180")),
    }
}

/// A whole number of at least `min` and at most `max`, explained as `what`.
pub fn parse_count(s: &str, min: u64, max: u64, what: &str) -> Result<u64, String> {
    match s.trim().parse::<i128>() {
        Ok(n) if n >= i128::from(min) && n <= i128::from(max) => Ok(n as u64),
        Ok(_) => Err(format!("{s:?}: {what} must lie between {min} and {max}")),
        Err(_) => Err(format!("{s:?} is not a whole number; {what} must lie between {min} and {max}")),
    }
}

pub fn parse_positive(s: &str) -> Result<u32, String> {
    parse_count(s, 1, u64::from(u32::MAX), "the value").map(|n| n as u32)
}

fn parse_light_count(s: &str) -> Result<usize, String> {
    parse_count(s, 0, MAX_LIGHTS as u64, "the number of lights").map(|n| n as usize)
}

/// The largest `--indirections` taken: bounce passes stop once no path is alive, so a large
/// value costs nothing beyond what the scene needs.
pub const MAX_INDIRECTIONS: u64 = 64;
const _: () = assert!(MAX_INDIRECTIONS <= render_spec::MAX_INDIRECTIONS as u64, "both tracers must take every value");

fn parse_indirections(s: &str) -> Result<u32, String> {
    parse_count(s, 0, MAX_INDIRECTIONS, "the number of indirections").map(|n| n as u32)
}

/// `--offset`: `scale`, or a finite distance of at least 0.
pub fn parse_offset(s: &str) -> Result<Offset, String> {
    let s = s.trim();
    if s.eq_ignore_ascii_case("scale") {
        return Ok(Offset::ScaleAware);
    }
    let d: f32 = s.parse().map_err(|_| format!("{s:?} is not an offset: give `scale` or a distance such as 1e-4"))?;
    let offset = Offset::Fixed(d);
    Accuracy { offset, ..Accuracy::default() }.check().map_err(|e| e.to_string())?;
    Ok(offset)
}

/// `--spp`: a square from 1 to [`render_spec::accuracy::MAX_SPP`], refused with the renderer's
/// sentence.
pub fn parse_spp(s: &str) -> Result<u32, String> {
    let max = render_spec::accuracy::MAX_SPP;
    let n = parse_count(s, 1, u64::from(max), "the samples per pixel")? as u32;
    Accuracy { spp: n, ..Accuracy::default() }.check().map_err(|e| e.to_string())?;
    Ok(n)
}

/// `--cutoff`: a finite number of at least 0, refused with the renderer's sentence.
pub fn parse_cutoff(s: &str) -> Result<f32, String> {
    let cutoff: f32 =
        s.trim().parse().map_err(|_| format!("{s:?} is not a number; the bounce cutoff is one, such as 0.002 or 0"))?;
    Accuracy { cutoff, ..Accuracy::default() }.check().map_err(|e| e.to_string())?;
    Ok(cutoff)
}

/// `--ao-samples`: a whole number from 1 to [`render_spec::MAX_AO_SAMPLES`].
pub fn parse_ao_samples(s: &str) -> Result<u32, String> {
    let max = render_spec::MAX_AO_SAMPLES;
    parse_count(s, 1, u64::from(max), "the ambient-occlusion rays per hit").map(|n| n as u32)
}

/// `--ao-length`: a finite fraction above 0, refused with the renderer's sentence.
pub fn parse_ao_length(s: &str) -> Result<f32, String> {
    let length: f32 = s.trim().parse().map_err(|_| {
        format!(
            "{s:?} is not a number; the ambient-occlusion length is a fraction of the scene's diagonal, such as 0.1"
        )
    })?;
    Ao { samples: 1, length }.check().map_err(|e| e.to_string())?;
    Ok(length)
}

pub fn parse_light(s: &str) -> Result<WorldLight, String> {
    let v = parse_f64s(s, &[3, 6], "a light is X,Y,Z (3 numbers) or X,Y,Z,R,G,B (6 numbers)")?;
    let colour = if v.len() == 6 { [v[3], v[4], v[5]].map(|c| c as f32) } else { [1.0, 1.0, 1.0] };
    if colour.iter().any(|&c| c < 0.0) {
        return Err(format!("{s:?}: a light's colour must not be negative"));
    }
    Ok(WorldLight { position: DVec3::new(v[0], v[1], v[2]), colour })
}

impl RenderArgs {
    /// The settings both tracers take; AOVs are kept when an AOV file or a heatmap is asked for.
    pub fn settings(&self, scene: &SceneFile) -> Result<Settings, String> {
        let camera = self.camera(scene)?;
        Ok(Settings {
            width: self.res.0,
            height: self.res.1,
            camera,
            mode: self.mode(),
            lights: self.lights(scene, &camera),
            max_indirections: self.indirections(scene),
            aovs: self.aov.is_some() || self.heatmap.is_some(),
            accuracy: self.accuracy(scene),
        })
    }

    /// The accuracy settings; what is not given is today's contract ([`Accuracy::default`]). A
    /// fixed offset is given in world units and handed to the tracers in the scene's stored unit.
    pub fn accuracy(&self, scene: &SceneFile) -> Accuracy {
        let default = Accuracy::default();
        let given = Accuracy {
            intersect: self.intersect.intersect(),
            offset: self.offset,
            spp: self.spp,
            cutoff: self.cutoff.unwrap_or(default.cutoff),
        };
        in_scene_unit(given, scene)
    }

    pub fn mode(&self) -> Mode {
        match self.mode {
            ModeArg::Cast => Mode::Cast,
            ModeArg::Whitted => Mode::Whitted,
            ModeArg::Ao => Mode::Ao(Ao { samples: self.ao_samples, length: self.ao_length }),
            ModeArg::Diffuse => Mode::Diffuse,
        }
    }

    /// Checks, before any work, what clap cannot check alone: every output path (see
    /// [`crate::output::check`]) and the number of lights.
    pub fn check(&self) -> Result<RenderOutputs, String> {
        let mut list = vec![("-o", self.output.as_path(), Kind::Image)];
        list.extend(self.heatmap.as_deref().map(|p| ("--heatmap", p, Kind::Heatmap)));
        list.extend(self.aov.as_deref().map(|p| ("--aov", p, Kind::Aov)));
        let inputs: Vec<&std::path::Path> = self.scene.as_deref().into_iter().collect();
        let mut checked = output::check(&list, &inputs).map_err(|e| e.to_string())?.into_iter();
        let image = checked.next().ok_or("no output image")?;
        let heatmap = if self.heatmap.is_some() { checked.next() } else { None };
        let aov = if self.aov.is_some() { checked.next() } else { None };
        if self.lights.len() > MAX_LIGHTS {
            return Err(format!("{} lights given; at most {MAX_LIGHTS} are taken", self.lights.len()));
        }
        Ok(RenderOutputs { image, heatmap, aov })
    }

    /// The camera: explicit eye/at, a stored camera by name, or the scene's first camera. It is
    /// checked here, so that both tracers refuse a bad camera with the same sentence.
    pub fn camera(&self, scene: &SceneFile) -> Result<CameraSpec, String> {
        let spec = if let (Some(eye), Some(at)) = (self.eye, self.at) {
            let (eye, at) = (scene.local(eye.to_array()).into(), scene.local(at.to_array()).into());
            CameraSpec { eye, at, up: self.up.unwrap_or(Vec3::Y), fov_deg: self.fov.unwrap_or(45.0) }
        } else {
            let mut spec = match &self.camera {
                Some(name) => stored_camera(scene, name)?,
                None => default_camera(scene)?,
            };
            if let Some(f) = self.fov {
                spec.fov_deg = f;
            }
            if let Some(up) = self.up {
                spec.up = up;
            }
            spec
        };
        check_camera(&spec, self.res)?;
        Ok(spec)
    }

    /// The lights: explicit ones, or the scene's, completed to `--lights N` when asked.
    pub fn lights(&self, scene: &SceneFile, camera: &CameraSpec) -> Vec<Light> {
        if !self.lights.is_empty() {
            return self.lights.iter().map(|l| Light::new(scene.local(l.position.to_array()), l.colour)).collect();
        }
        match self.light_count {
            Some(n) => lights_n(scene, n, camera),
            None => scene.lights.clone(),
        }
    }

    pub fn indirections(&self, scene: &SceneFile) -> u32 {
        self.indirections.unwrap_or(scene.settings.max_indirections)
    }
}

/// Why a camera cannot be used, in the words both tracers print.
pub fn check_camera(spec: &CameraSpec, res: (u32, u32)) -> Result<(), String> {
    if !(spec.at - spec.eye).is_finite() {
        return Err(format!(
            "the eye {} and look-at point {} are too far apart to compute a view direction in f32",
            spec.eye, spec.at
        ));
    }
    spec.frame(res.0, res.1).map(|_| ()).map_err(|e| match e {
        render_spec::camera::CameraError::Degenerate => format!(
            "the camera is degenerate: the eye {} is on the look-at point {} or the up vector {} is zero or parallel to the view",
            spec.eye, spec.at, spec.up
        ),
        render_spec::camera::CameraError::FieldOfView => {
            format!("the field of view must lie strictly between 0 and 180 degrees, not {}", spec.fov_deg)
        }
    })
}

/// The scene's first camera: what a render uses without `--camera` or `--eye`.
pub fn default_camera(scene: &SceneFile) -> Result<CameraSpec, String> {
    scene
        .cameras
        .first()
        .map(CameraSpec::from)
        .ok_or_else(|| "the scene has no camera; give one with --eye X,Y,Z --at X,Y,Z".to_owned())
}

/// A camera stored in the scene, by name.
pub fn stored_camera(scene: &SceneFile, name: &str) -> Result<CameraSpec, String> {
    let c = scene.camera(name).ok_or_else(|| {
        let names: Vec<&str> = scene.cameras.iter().filter_map(|c| c.name()).collect();
        format!("the scene has no camera named {name:?} (it has: {})", names.join(", "))
    })?;
    Ok(CameraSpec::from(c))
}

/// `n` lights: the scene's first ones, completed when it has fewer by lights placed around
/// `camera` as the compiler places a scene's default light (inside the scene when the camera
/// stands inside it), each of brightness 1/n.
pub fn lights_n(scene: &SceneFile, n: usize, camera: &CameraSpec) -> Vec<Light> {
    let mut lights = scene.lights.clone();
    lights.truncate(n);
    let (lo, hi) = scene.bounds();
    let added = n.saturating_sub(lights.len());
    let c = 1.0 / n.max(1) as f32;
    let placed =
        bvh_build::import::defaults::lights_around(camera.eye, camera.at, camera.up, lo.into(), hi.into(), added);
    lights.extend(placed.into_iter().map(|p| Light::new(p.to_array(), [c, c, c])));
    lights
}

/// Accuracy settings given in world units (a fixed `--offset` distance) in the scene's stored unit
/// ([`SceneFile::scale_log2`]), as the tracers take them.
pub fn in_scene_unit(a: Accuracy, scene: &SceneFile) -> Accuracy {
    match a.offset {
        Offset::Fixed(d) => Accuracy { offset: Offset::Fixed(scene.local_distance(f64::from(d))), ..a },
        Offset::ScaleAware => a,
    }
}

/// The accuracy settings that differ from the default, for the report line both tracers print
/// (empty for the default).
pub fn accuracy_note(a: &Accuracy, scene: &SceneFile) -> String {
    let d = Accuracy::default();
    let mut parts = Vec::new();
    if a.intersect != d.intersect {
        parts.push("Möller-Trumbore triangle test".to_owned());
    }
    if let Offset::Fixed(x) = a.offset {
        parts.push(format!("fixed offset {:e}", scene.world_distance(x) as f32));
    }
    if a.spp != d.spp {
        parts.push(format!("{} samples per pixel", a.spp));
    }
    if a.cutoff != d.cutoff {
        parts.push(if a.cutoff == 0.0 { "no bounce cutoff".to_owned() } else { format!("bounce cutoff {}", a.cutoff) });
    }
    if parts.is_empty() { String::new() } else { format!(" ({})", parts.join(", ")) }
}

/// The rays of a frame as both tracers report them: primary, shadow and secondary, and AO and
/// diffuse rays where there are any.
pub fn rays_note(r: &render_spec::RayCounts) -> String {
    let mut s = format!("{} primary, {} shadow, {} secondary", r.primary, r.shadow, r.secondary);
    if r.ao > 0 {
        s.push_str(&format!(", {} AO", r.ao));
    }
    if r.diffuse > 0 {
        s.push_str(&format!(", {} diffuse", r.diffuse));
    }
    s
}

/// The line both tracers print with `--self-hits`: of each kind of ray that leaves a surface, how
/// many the triangle it leaves from meets (render_spec::SelfHits).
pub fn self_hits_line(r: &render_spec::RayCounts) -> String {
    let h = r.self_hits;
    let mut parts =
        vec![format!("{} of {} shadow", h.shadow, r.shadow), format!("{} of {} secondary", h.secondary, r.secondary)];
    if r.ao > 0 {
        parts.push(format!("{} of {} AO", h.ao, r.ao));
    }
    if r.diffuse > 0 {
        parts.push(format!("{} of {} diffuse", h.diffuse, r.diffuse));
    }
    format!("self-hits (rays stopped by the triangle they leave, exact acne): {}", parts.join(", "))
}

/// The line both tracers print for a heatmap: its scale, and how many pixels lie above a fixed one.
pub fn heatmap_line(h: &output::Heatmap, out: &Output) -> String {
    let clipped =
        if h.clipped > 0 { format!(", {} pixels above the scale drawn red", h.clipped) } else { String::new() };
    format!(
        "heatmap: nodes visited per pixel, 0 (blue) to {} (red), scale drawn below the image{clipped} -> {}",
        h.max,
        out.path.display()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn option_values_parse_or_explain() {
        assert_eq!(parse_vec3("1, 2,3").unwrap(), Vec3::new(1.0, 2.0, 3.0));
        assert_eq!(parse_vec3("-15,-11,0").unwrap(), Vec3::new(-15.0, -11.0, 0.0));
        assert!(parse_vec3("1,2").unwrap_err().contains("3 numbers"));
        assert!(parse_vec3("1,2,nan").unwrap_err().contains("\"nan\" is not a finite number"));
        assert!(parse_vec3("1,2,4e38").unwrap_err().contains("not a finite number"));
        assert_eq!(parse_res("640x480").unwrap(), (640, 480));
        assert!(parse_res("640").is_err() && parse_res("0x10").is_err() && parse_res("100000x100000").is_err());
        assert!(parse_res("-4x4").unwrap_err().contains("at least 1"));
        assert_eq!(parse_light("1,2,3").unwrap(), WorldLight { position: DVec3::new(1.0, 2.0, 3.0), colour: [1.0; 3] });
        assert_eq!(parse_point("1e6,2.25,-1000000.125").unwrap(), DVec3::new(1e6, 2.25, -1000000.125));
        assert_eq!(parse_light("1,2,3,0.5,0.5,0").unwrap().colour, [0.5, 0.5, 0.0]);
        assert!(parse_light("1,2,3,-1,0,0").is_err());
        let e = parse_light("0,1,1,1").unwrap_err();
        assert!(e.contains("has 4 values") && e.contains("3 numbers") && e.contains("6 numbers"), "{e}");
        let e = parse_workgroup("0x0").unwrap_err();
        assert!(e.contains("workgroup") && !e.contains("image"), "{e}");
        assert!(parse_workgroup("64x64").unwrap_err().contains("1024"));
        assert!(parse_fov("-5").is_err() && parse_fov("180").is_err() && parse_fov("nan").is_err());
        assert!(parse_count("-1", 1, 10, "x").unwrap_err().contains("between 1 and 10"));
    }
}
