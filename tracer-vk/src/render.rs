//! Rendering a scene file with the stream pipeline: upload once (only the layout the method
//! reads), specialise the kernels for the scene, then per frame dispatch the stages and read back
//! the image, the AOVs and the ray counts.
//!
//! A frame is rendered in tiles sized from the device's limits ([`crate::tiles`]), so any image
//! the host can hold renders. Per tile, the bounce passes are submitted in growing chunks and stop
//! once no path is alive. The kernels count what they did, and a count that does not add up (a
//! pixel whose stage never finished, a traversal that gave up on a ray) refuses the frame: a wrong
//! image is never returned in silence.

use crate::device::{Buffer, Gpu, Pipeline};
use crate::error::VkError;
use crate::kernels::{self, Method, Specialisation, Stage, counters};
use crate::tiles::{self, Tile};
use bvh_format::camera::CameraSpec;
use bvh_format::{Light, SceneFile};
use bytemuck::{Pod, Zeroable};
use std::collections::HashMap;

/// Ray casting or Whitted ray tracing.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    Cast,
    Whitted,
}

/// What to render.
#[derive(Clone, Debug)]
pub struct Settings {
    pub width: u32,
    pub height: u32,
    pub camera: CameraSpec,
    pub mode: Mode,
    pub lights: Vec<Light>,
    pub max_indirections: u32,
}

/// The most indirections a frame may ask for. Paths end earlier in every scene whose reflective
/// and refractive materials lose light (the passes stop when none is alive); only perfect mirrors
/// facing each other go on to the limit, at a cost that grows with it.
pub const MAX_INDIRECTIONS: u32 = 1024;

/// Bounces in the first submission of a tile (every shipped scene needs at most 5); each later
/// submission doubles the bounces done so far. Between submissions the live paths are counted.
const FIRST_BOUNCES: u32 = 8;

/// How far a frame has come: pixels of finished tiles, out of all.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Progress {
    pub pixels_done: u64,
    pub pixels: u64,
}

/// A rendered frame.
#[derive(Clone, Debug)]
pub struct Output {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<[u8; 3]>,
    /// Per pixel: primary hit distance (+inf on a miss), shading normal, input triangle
    /// (`NO_TRIANGLE` on a miss), nodes and triangles tested over all of the pixel's rays.
    pub t: Vec<f32>,
    pub normal: Vec<[f32; 3]>,
    pub prim: Vec<u32>,
    pub nodes: Vec<u32>,
    pub tris: Vec<u32>,
    /// Primary, shadow and secondary rays traced.
    pub rays: [u64; 3],
    /// GPU time of the whole frame and of each pass, from timestamp queries.
    pub gpu_ms: f64,
    pub passes: Vec<(String, f64)>,
}

/// Why a frame cannot be rendered.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    #[error(transparent)]
    Vulkan(#[from] VkError),
    #[error("the image must be at least 1 x 1 pixels")]
    EmptyImage,
    #[error("the camera is degenerate or its field of view is outside 0 to 180 degrees")]
    Camera,
    #[error("the {method} traversal needs the {layout} layout, which the scene file does not contain")]
    MissingLayout { method: &'static str, layout: &'static str },
    #[error("{0} lights are more than the kernels address")]
    TooManyLights(usize),
    #[error("{0} indirections are more than the {MAX_INDIRECTIONS} a frame may trace")]
    TooManyIndirections(u32),
    #[error(
        "a {x} x {y} workgroup is not allowed: width and height must be powers of two with at most {limit} invocations in all on this device, such as 8x8 (the default), 16x16 or 32x4"
    )]
    Workgroup { x: u32, y: u32, limit: u64 },
    #[error("{0} lacks the subgroup operations the sst-subgroup traversal votes with; use sst")]
    NoSubgroups(String),
    #[error(
        "SST needs {needed} bytes of workgroup memory for a tree {depth} deep with leaves of up to {leaf} triangles, more than the device's {limit}; use LST, or rebuild with a smaller --max-leaf-size"
    )]
    SharedMemory { depth: u32, leaf: u32, needed: u64, limit: u64 },
    #[error(
        "the scene's {what} need {bytes} bytes in one storage buffer, more than this device's {limit_name} of {limit} bytes; it takes scenes of up to {fits} {what}"
    )]
    SceneTooLarge { what: &'static str, bytes: u64, limit_name: &'static str, limit: u64, fits: u64 },
    #[error("a {width} x {height} image needs {bytes} bytes of host memory, which could not be allocated")]
    HostMemory { width: u32, height: u32, bytes: u64 },
    #[error(
        "the {method} kernels finished {done} of the {expected} {what} they were given, so no image was made: the device or its driver dropped work"
    )]
    LostWork { method: &'static str, what: &'static str, done: u64, expected: u64 },
    #[error("the {method} traversal {what}, so no image was made")]
    Fault { method: &'static str, what: String },
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct FrameData {
    eye: [f32; 4],
    top_left: [f32; 4],
    h_step: [f32; 4],
    v_step: [f32; 4],
    ambient: [f32; 4],
    background: [f32; 4],
    size: [u32; 4],
    stop: [f32; 4],
    tile: [u32; 4],
}

/// The push constant of a pass (`Pass` in common.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct PassData {
    light: u32,
    depth: u32,
    pad: [u32; 2],
}

impl PassData {
    fn bytes(light: u32, depth: u32) -> [u8; kernels::PASS_BYTES as usize] {
        bytemuck::cast(PassData { light, depth, pad: [0; 2] })
    }
}

/// Per-pixel state of one tile, kept between frames and reused by every tile that fits.
struct Targets {
    pixels: u64,
    paths: Buffer,
    hits: Buffer,
    accum: Buffer,
    aovs: Buffer,
    image: Buffer,
}

/// A scene on the GPU, ready to render frames with one traversal method.
pub struct Renderer<'g> {
    gpu: &'g Gpu,
    scene: &'g SceneFile,
    spec: Specialisation,
    nodes: Buffer,
    tris: Buffer,
    normal_indices: Buffer,
    normals: Buffer,
    materials: Buffer,
    input_index: Buffer,
    pipelines: HashMap<Stage, Pipeline>,
    targets: Option<Targets>,
    /// A tile holds at most this many pixels (besides the device's own limits).
    tile_pixels: u64,
}

const BINDINGS: u32 = 14;

/// What one frame's passes gave, summed over tiles and submissions.
#[derive(Default)]
struct Tally {
    rays: [u64; 3],
    gpu_ms: f64,
    passes: Vec<(String, f64)>,
}

impl Tally {
    fn add_timings(&mut self, t: &crate::device::Timings) {
        self.gpu_ms += t.total_ms;
        for (label, ms) in &t.intervals {
            match self.passes.iter_mut().find(|(l, _)| l == label) {
                Some((_, sum)) => *sum += ms,
                None => self.passes.push((label.clone(), *ms)),
            }
        }
    }
}

/// The per-pixel results of a frame on the host, filled tile by tile.
struct HostFrame {
    width: u32,
    image: Vec<u32>,
    aovs: Vec<[u32; 8]>,
}

impl HostFrame {
    fn new(width: u32, height: u32, image: bool, aovs: bool) -> Result<Self, RenderError> {
        let n = width as usize * height as usize;
        let bytes = n as u64 * (4 * image as u64 + 32 * aovs as u64);
        let fail = |_| RenderError::HostMemory { width, height, bytes };
        let mut f = HostFrame { width, image: Vec::new(), aovs: Vec::new() };
        if image {
            f.image.try_reserve_exact(n).map_err(fail)?;
        }
        if aovs {
            f.aovs.try_reserve_exact(n).map_err(fail)?;
        }
        f.image.resize(if image { n } else { 0 }, 0);
        f.aovs.resize(if aovs { n } else { 0 }, [0; 8]);
        Ok(f)
    }

    /// Copies a tile's rows (`src` holds them one after another) into the frame.
    fn place<T: Copy>(width: u32, dst: &mut [T], src: &[T], tile: &Tile) {
        let tw = tile.width as usize;
        for (r, row) in src.chunks_exact(tw).take(tile.height as usize).enumerate() {
            let at = (tile.y as usize + r) * width as usize + tile.x as usize;
            dst[at..at + tw].copy_from_slice(row);
        }
    }
}

impl<'g> Renderer<'g> {
    /// Uploads the scene (only the node layout `method` reads) and specialises the kernels:
    /// LST's and SST's stacks hold exactly the file's max depth, SST's leaf cache its largest
    /// leaf; reflection and refraction code is present only when some material needs it.
    pub fn new(gpu: &'g Gpu, scene: &'g SceneFile, method: Method, workgroup: (u32, u32)) -> Result<Self, RenderError> {
        let nodes = match method {
            Method::Lst | Method::Sst | Method::SstSubgroup => scene
                .child_pair
                .as_deref()
                .ok_or(RenderError::MissingLayout { method: method.name(), layout: "child-pair" })?,
            Method::Stackless => scene
                .escape
                .as_deref()
                .ok_or(RenderError::MissingLayout { method: "stackless", layout: "escape-pointer" })?,
        };
        let stats = scene.stats();
        let spec = Specialisation {
            method,
            stack_size: stats.max_depth.max(1),
            leaf_size: (stats.leaf_sizes.len().max(2) - 1) as u32,
            workgroup,
            reflection: scene.materials.iter().any(|m| m.kr > 0.0),
            refraction: scene.materials.iter().any(|m| m.kt > 0.0),
            smooth: !scene.normals.is_empty(),
        };
        let info = gpu.info();
        let (wx, wy) = workgroup;
        let limit = (info.max_workgroup_invocations as u64).min(info.max_workgroup_size[0] as u64);
        if !wx.is_power_of_two() || !wy.is_power_of_two() || wx as u64 * wy as u64 > limit {
            return Err(RenderError::Workgroup { x: wx, y: wy, limit });
        }
        if method == Method::SstSubgroup && !info.supports_subgroup_ops {
            return Err(RenderError::NoSubgroups(info.name.clone()));
        }
        if matches!(method, Method::Sst | Method::SstSubgroup) {
            let needed = kernels::sst_shared_bytes(&spec);
            let limit = info.max_shared_memory as u64;
            if needed > limit {
                return Err(RenderError::SharedMemory { depth: spec.stack_size, leaf: spec.leaf_size, needed, limit });
            }
        }
        let node_what = if method == Method::Stackless { "escape-pointer nodes" } else { "child-pair nodes" };
        fits(info, node_what, nodes)?;
        let arrays = SceneArrays::new(scene);
        fits(info, "triangles", &arrays.tris)?;
        fits(info, "normal indices", &arrays.normal_indices)?;
        fits(info, "normals", &arrays.normals)?;
        fits(info, "materials", &scene.materials)?;
        fits(info, "input indices", &scene.input_index)?;
        Ok(Self {
            gpu,
            scene,
            spec,
            nodes: gpu.create_buffer_with(nodes, "nodes")?,
            tris: gpu.create_buffer_with(&arrays.tris, "triangles")?,
            normal_indices: gpu.create_buffer_with(&arrays.normal_indices, "normal indices")?,
            normals: gpu.create_buffer_with(&arrays.normals, "normals")?,
            materials: gpu.create_buffer_with(&scene.materials, "materials")?,
            input_index: gpu.create_buffer_with(&scene.input_index, "input index")?,
            pipelines: HashMap::new(),
            targets: None,
            tile_pixels: tiles::device_tile_pixels(info),
        })
    }

    pub fn specialisation(&self) -> &Specialisation {
        &self.spec
    }

    /// Renders in tiles of at most `pixels` pixels (at least one workgroup's), below what the
    /// device's limits allow: to bound the memory a frame takes, or to test tiling on small frames.
    pub fn limit_tile_pixels(&mut self, pixels: u64) {
        let wg = self.spec.workgroup.0 as u64 * self.spec.workgroup.1 as u64;
        self.tile_pixels = tiles::device_tile_pixels(self.gpu.info()).min(pixels.max(wg));
    }

    fn pipeline(&mut self, stage: Stage) -> Result<(), VkError> {
        if !self.pipelines.contains_key(&stage) {
            let spirv = kernels::compile(stage, &self.spec)?;
            let label = format!("{} {stage:?}", self.spec.method.name());
            let p = self.gpu.pipeline(&spirv, BINDINGS, kernels::PASS_BYTES, &label)?;
            self.pipelines.insert(stage, p);
        }
        Ok(())
    }

    /// Per-pixel buffers for tiles of up to `pixels` pixels.
    fn targets(&mut self, pixels: u64) -> Result<(), VkError> {
        if self.targets.as_ref().is_some_and(|t| t.pixels >= pixels) {
            return Ok(());
        }
        self.targets = None;
        let g = self.gpu;
        self.targets = Some(Targets {
            pixels,
            paths: g.create_buffer(pixels * 32, "paths")?,
            hits: g.create_buffer(pixels * 16, "hits")?,
            accum: g.create_buffer(pixels * 16, "accumulated colour")?,
            aovs: g.create_buffer(pixels * 32, "AOVs")?,
            image: g.create_buffer(pixels * 4, "image")?,
        });
        Ok(())
    }

    /// Renders one frame and reads back the image and the AOVs.
    pub fn render(&mut self, s: &Settings) -> Result<Output, RenderError> {
        self.render_frame(s, true)
    }

    /// Renders one frame; without `readback` only the ray counts and GPU times come back (the
    /// per-pixel vectors of the output are empty), as benchmarks want.
    pub fn render_frame(&mut self, s: &Settings, readback: bool) -> Result<Output, RenderError> {
        self.render_with_progress(s, readback, readback, &mut |_| {})
    }

    /// Renders one frame, calling `progress` after every tile. `image` reads back the colours,
    /// `aovs` the per-pixel outputs; without either only the ray counts and GPU times come back.
    pub fn render_with_progress(
        &mut self,
        s: &Settings,
        image: bool,
        aovs: bool,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Output, RenderError> {
        if s.width == 0 || s.height == 0 {
            return Err(RenderError::EmptyImage);
        }
        let f = s.camera.frame(s.width, s.height).map_err(|_| RenderError::Camera)?;
        if s.lights.len() > u32::MAX as usize / 2 {
            return Err(RenderError::TooManyLights(s.lights.len()));
        }
        if s.max_indirections > MAX_INDIRECTIONS {
            return Err(RenderError::TooManyIndirections(s.max_indirections));
        }
        let whitted = s.mode == Mode::Whitted;
        // Bounces only where a material can spawn one: no scene pays for what it lacks.
        let indirections = if self.spec.reflection || self.spec.refraction { s.max_indirections } else { 0 };
        let stages: &[Stage] = if whitted {
            if indirections > 0 {
                &[Stage::Primary, Stage::Shade, Stage::Bounce, Stage::Convert]
            } else {
                &[Stage::Primary, Stage::Shade, Stage::Convert]
            }
        } else {
            &[Stage::Cast]
        };
        let info = self.gpu.info();
        let groups = [info.max_workgroup_count[0], info.max_workgroup_count[1]];
        let plan = tiles::plan(s.width, s.height, self.tile_pixels, self.spec.workgroup, groups)
            .ok_or_else(|| VkError::Usage(format!("no tile of {} pixels holds a workgroup", self.tile_pixels)))?;
        let mut host = HostFrame::new(s.width, s.height, image, aovs)?;
        for &st in stages {
            self.pipeline(st)?;
        }
        self.targets(plan.iter().map(Tile::pixels).max().unwrap_or(1))?;

        let colours: Vec<[f32; 3]> = s.lights.iter().map(|l| l.colour).collect();
        let (bound, k_max) = self.scene.bounce_bound(&colours);
        let v4 = |v: glam::Vec3| [v.x, v.y, v.z, 0.0];
        let a3 = |v: [f32; 3]| [v[0], v[1], v[2], 0.0];
        let mut frame = FrameData {
            eye: v4(f.eye),
            top_left: v4(f.top_left),
            h_step: v4(f.h_step),
            v_step: v4(f.v_step),
            ambient: a3(self.scene.settings.ambient),
            background: a3(self.scene.settings.background),
            size: [s.width, s.height, s.lights.len() as u32, indirections],
            stop: [bound, k_max, 0.0, 0.0],
            tile: [0; 4],
        };
        let g = self.gpu;
        let frame_buf = g.create_buffer(size_of::<FrameData>() as u64, "frame")?;
        // Storage buffers may not be empty: a scene without lights binds one unused entry.
        let lights = if s.lights.is_empty() { vec![Light::new([0.0; 3], [0.0; 3])] } else { s.lights.clone() };
        let lights_buf = g.create_buffer_with(&lights, "lights")?;
        let counters = g.create_buffer(4 * (counters::LIVE as u64 + indirections.max(1) as u64), "ray counters")?;

        let mut tally = Tally::default();
        let total = s.width as u64 * s.height as u64;
        let mut done = 0;
        for tile in &plan {
            frame.tile = [tile.x, tile.y, tile.width, tile.height];
            g.upload(&frame_buf, bytemuck::bytes_of(&frame))?;
            self.render_tile(
                tile,
                whitted,
                s.lights.len() as u32,
                indirections,
                &frame_buf,
                &lights_buf,
                &counters,
                &mut tally,
            )?;
            let t = self.targets.as_ref().expect("the targets were made above");
            let n = tile.pixels() as usize;
            if image {
                let px: Vec<u32> = g.download_prefix_as(&t.image, n)?;
                HostFrame::place(s.width, &mut host.image, &px, tile);
            }
            if aovs {
                let a: Vec<[u32; 8]> = g.download_prefix_as(&t.aovs, n)?;
                HostFrame::place(s.width, &mut host.aovs, &a, tile);
            }
            done += tile.pixels();
            progress(Progress { pixels_done: done, pixels: total });
        }
        debug_assert_eq!(host.width, s.width);
        let f32_of = |u: u32| f32::from_bits(u);
        let a = &host.aovs;
        Ok(Output {
            width: s.width,
            height: s.height,
            rgb: host.image.iter().map(|&p| [p as u8, (p >> 8) as u8, (p >> 16) as u8]).collect(),
            normal: a.iter().map(|a| [f32_of(a[0]), f32_of(a[1]), f32_of(a[2])]).collect(),
            t: a.iter().map(|a| f32_of(a[4])).collect(),
            prim: a.iter().map(|a| a[5]).collect(),
            nodes: a.iter().map(|a| a[6]).collect(),
            tris: a.iter().map(|a| a[7]).collect(),
            rays: tally.rays,
            gpu_ms: tally.gpu_ms,
            passes: tally.passes,
        })
    }

    /// Runs one tile's passes: the first submission traces the primary rays, shades and makes
    /// the first bounces; later ones (each as many bounces as all before it) run only while some
    /// path is alive. Every submission ends with the conversion to 8 bits, so whichever is last
    /// leaves the tile's image.
    #[allow(clippy::too_many_arguments)]
    fn render_tile(
        &self,
        tile: &Tile,
        whitted: bool,
        light_count: u32,
        indirections: u32,
        frame_buf: &Buffer,
        lights_buf: &Buffer,
        counters: &Buffer,
        tally: &mut Tally,
    ) -> Result<(), RenderError> {
        let g = self.gpu;
        let t = self.targets.as_ref().expect("the targets were made before the tiles");
        let (wx, wy) = self.spec.workgroup;
        let groups = [tile.width.div_ceil(wx), tile.height.div_ceil(wy), 1];
        let buffers: [&Buffer; BINDINGS as usize] = [
            frame_buf,
            &self.nodes,
            &self.tris,
            &self.normal_indices,
            &self.normals,
            &self.materials,
            lights_buf,
            &self.input_index,
            &t.paths,
            &t.hits,
            &t.accum,
            &t.aovs,
            &t.image,
            counters,
        ];
        let p = &self.pipelines;
        let shade_passes = light_count.max(1);
        let mut first = 0;
        loop {
            // Bounces [first, end) in this submission.
            let end = if first == 0 { indirections.min(FIRST_BOUNCES) } else { indirections.min(2 * first) };
            let mut dispatches = 0u64;
            let timings = g.run(|rec| {
                let mut pass = |rec: &mut crate::device::Recorder, stage: Stage, light: u32, depth: u32| {
                    dispatches += 1;
                    rec.dispatch(&p[&stage], &buffers, &PassData::bytes(light, depth), groups)
                };
                rec.zero(counters);
                rec.mark("start");
                if !whitted {
                    pass(rec, Stage::Cast, 0, 0)?;
                    rec.mark("cast");
                    return Ok(());
                }
                if first == 0 {
                    pass(rec, Stage::Primary, 0, 0)?;
                    rec.mark("trace primary");
                    for l in 0..shade_passes {
                        pass(rec, Stage::Shade, l, 0)?;
                    }
                    rec.mark("shade 0");
                }
                for depth in first..end {
                    pass(rec, Stage::Bounce, 0, depth)?;
                    rec.mark(&format!("trace secondary {}", depth + 1));
                    for l in 0..shade_passes {
                        pass(rec, Stage::Shade, l, depth + 1)?;
                    }
                    rec.mark(&format!("shade {}", depth + 1));
                }
                pass(rec, Stage::Convert, 0, 0)?;
                rec.mark("convert");
                Ok(())
            })?;
            tally.add_timings(&timings);
            let words: Vec<u32> = g.download_as(counters)?;
            self.check_counts(&words, tile, first == 0, dispatches)?;
            let wide = |slot: usize| words[slot] as u64 | (words[slot + 1] as u64) << 32;
            tally.rays[0] += wide(counters::PRIMARY);
            tally.rays[1] += wide(counters::SHADOW);
            tally.rays[2] += wide(counters::SECONDARY);
            if !whitted || end >= indirections || words[counters::LIVE + end as usize - 1] == 0 {
                return Ok(());
            }
            first = end;
        }
    }

    /// Refuses a submission whose counts do not add up: every dispatch must have finished every
    /// pixel of the tile, the first must have traced one primary ray per pixel, and no traversal
    /// may have given up on a ray.
    fn check_counts(&self, words: &[u32], tile: &Tile, first: bool, dispatches: u64) -> Result<(), RenderError> {
        let method = self.spec.method.name();
        let wide = |slot: usize| words[slot] as u64 | (words[slot + 1] as u64) << 32;
        let faults = words[counters::FAULTS];
        if faults & counters::FAULT_STACK != 0 {
            let what = format!(
                "found its stack of {} entries full (the tree is deeper than its file says)",
                self.spec.stack_size
            );
            return Err(RenderError::Fault { method, what });
        }
        if faults & counters::FAULT_WALK != 0 {
            return Err(RenderError::Fault { method, what: "took more steps than the tree has nodes".to_owned() });
        }
        let primary = wide(counters::PRIMARY);
        if first && primary != tile.pixels() {
            return Err(RenderError::LostWork { method, what: "primary rays", done: primary, expected: tile.pixels() });
        }
        let finished = wide(counters::FINISHED);
        let expected = dispatches * tile.pixels();
        if finished != expected {
            return Err(RenderError::LostWork { method, what: "pixel passes", done: finished, expected });
        }
        Ok(())
    }
}

/// The triangle arrays as the kernels read them: three vertices per triangle in leaf order (one
/// contiguous 48-byte read per triangle, as the thesis's 16-byte aligned data), and the file's
/// normal indices and normals, or one-entry placeholders for a scene without smooth triangles
/// (whose kernels never read them).
struct SceneArrays {
    tris: Vec<bvh_format::Triangle>,
    normal_indices: Vec<[u32; 3]>,
    normals: Vec<[f32; 3]>,
}

impl SceneArrays {
    fn new(scene: &SceneFile) -> Self {
        let smooth = !scene.normals.is_empty();
        Self {
            tris: scene.leaf_triangles(),
            normal_indices: if smooth { scene.normal_indices.clone() } else { vec![bvh_format::FLAT] },
            normals: if smooth { scene.normals.clone() } else { vec![[0.0; 3]] },
        }
    }
}

/// Bytes of scene data a renderer with `method` uploads (nodes of the one layout it reads,
/// triangles, normals, materials, input indices), for `bvhc info`.
pub fn upload_bytes(scene: &SceneFile, method: Method) -> u64 {
    let nodes = match method {
        Method::Stackless => scene.escape.as_ref(),
        _ => scene.child_pair.as_ref(),
    };
    let a = SceneArrays::new(scene);
    [
        std::mem::size_of_val(nodes.map_or(&[][..], |n| &n[..])),
        std::mem::size_of_val(&a.tris[..]),
        std::mem::size_of_val(&a.normal_indices[..]),
        std::mem::size_of_val(&a.normals[..]),
        std::mem::size_of_val(&scene.materials[..]),
        std::mem::size_of_val(&scene.input_index[..]),
    ]
    .iter()
    .sum::<usize>() as u64
}

/// Checks that a scene array fits one storage buffer binding and one allocation.
fn fits<T>(info: &crate::device::DeviceInfo, what: &'static str, data: &[T]) -> Result<(), RenderError> {
    let bytes = std::mem::size_of_val(data) as u64;
    let (limit_name, limit) = if info.max_storage_buffer_range <= info.max_memory_allocation {
        ("maxStorageBufferRange", info.max_storage_buffer_range)
    } else {
        ("maxMemoryAllocationSize", info.max_memory_allocation)
    };
    if bytes > limit {
        let fits = limit / size_of::<T>().max(1) as u64;
        return Err(RenderError::SceneTooLarge { what, bytes, limit_name, limit, fits });
    }
    Ok(())
}
