//! Rendering a scene file with the stream pipeline: upload once (only the layout the method
//! reads), specialise the kernels for the scene, then per frame dispatch the stages and read back
//! the image, the AOVs and the ray counts.
//!
//! A frame is rendered in tiles sized from the device's limits ([`crate::tiles`]), so any image
//! the host can hold renders. Per tile, the bounce passes are submitted in growing chunks and stop
//! once no path is alive. The kernels count what they did, and a count that does not add up (a
//! pixel whose stage never finished, a traversal that gave up on a ray) refuses the frame: a wrong
//! image is never returned in silence.

use crate::device::{Buffer, DeviceKind, Gpu, Pipeline};
use crate::error::VkError;
use crate::kernels::{self, Half, Method, Persistent, Specialisation, Split, Stage, Vertices, counters};
use crate::rt::RtTracer;
use crate::tiles::{self, Tile};
use bvh_format::{Light, SceneFile};
use bytemuck::{Pod, Zeroable};
use render_spec::{Accuracy, Aovs, BounceStop, Image, Intersect, Mode, Offset, RayCounts, RenderError, Settings};
use std::collections::HashMap;

/// The most invocations a workgroup may have on any device (Vulkan guarantees 128; every desktop
/// GPU and lavapipe allow 1024); a device's own lower limit is checked when a renderer is made.
pub const MAX_WORKGROUP_INVOCATIONS: u32 = 1024;

/// Whether the kernels take a `width` x `height` workgroup with at most `limit` invocations: both
/// sides powers of two (SST's vote reduction halves the workgroup), every shape of them tested.
pub fn workgroup_allowed(width: u32, height: u32, limit: u32) -> bool {
    width.is_power_of_two() && height.is_power_of_two() && width as u64 * height as u64 <= limit as u64
}

/// Every workgroup shape [`workgroup_allowed`] takes with `limit` invocations.
pub fn allowed_workgroups(limit: u32) -> Vec<(u32, u32)> {
    let sides = || (0..=limit.ilog2()).map(|k| 1u32 << k);
    sides().flat_map(|w| sides().map(move |h| (w, h))).filter(|&(w, h)| workgroup_allowed(w, h, limit)).collect()
}

/// rt-pipeline's passes are timed in three parts: the stage's first half (writing the rays), the
/// driver's traversal, and the stage's second half under the stage's own label. These label the
/// first two, summed over a frame's passes in [`Output::passes`].
pub const RT_RAY_HALVES: &str = "rt-pipeline ray halves";
pub const RT_TRAVERSAL: &str = "rt-pipeline traversal";

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
    pub image: Image,
    /// GPU time of the whole frame and of each pass, from timestamp queries.
    pub gpu_ms: f64,
    pub passes: Vec<(String, f64)>,
}

/// Why a frame cannot be rendered: the mistakes every tracer reports alike, or what only the
/// Vulkan tracer can run into.
#[derive(Debug, thiserror::Error)]
pub enum VkRenderError {
    #[error(transparent)]
    Settings(#[from] RenderError),
    #[error(transparent)]
    Vulkan(#[from] VkError),
    #[error("{0} lights are more than the kernels address")]
    TooManyLights(usize),
    #[error(
        "a {x} x {y} workgroup is not allowed: width and height must be powers of two with at most {limit} invocations in all on this device, such as 8x8 (the default), 16x16 or 32x4"
    )]
    Workgroup { x: u32, y: u32, limit: u64 },
    #[error(
        "{0} lacks the subgroup operations that the sst-subgroup traversal votes with and persistent kernels take their work with; use sst, or --persistent off"
    )]
    NoSubgroups(String),
    #[error("the {0} traversal does not run as persistent threads; use lst or stackless, or --persistent off")]
    NotPersistent(&'static str),
    #[error(
        "SST needs {needed} bytes of workgroup memory for its stack of a tree {depth} deep and a leaf cache of one triangle, more than the device's {limit}; use LST or stackless"
    )]
    SharedMemory { depth: u32, needed: u64, limit: u64 },
    #[error(
        "the scene's {what} need {bytes} bytes in one storage buffer, more than this device's {limit_name} of {limit} bytes; it takes scenes of up to {fits} {what}"
    )]
    SceneTooLarge { what: &'static str, bytes: u64, limit_name: &'static str, limit: u64, fits: u64 },
    #[error(
        "LST needs a stack of {depth} entries for this tree, more than the {limit} that {device} compiles in reasonable time (a deeper stack takes it minutes); use stackless"
    )]
    PrivateStack { depth: u32, limit: u32, device: String },
    #[error(
        "the scene's {what} need {bytes} bytes, more than {chunks} storage buffers of this device's {limit_name} of {limit} bytes each; it takes scenes of up to {fits} {what}"
    )]
    SplitTooLarge { what: &'static str, bytes: u64, chunks: u32, limit_name: &'static str, limit: u64, fits: u64 },
    #[error("a {width} x {height} image needs {bytes} bytes of host memory, which could not be allocated")]
    HostMemory { width: u32, height: u32, bytes: u64 },
    #[error(
        "the {method} kernels finished {done} of the {expected} {what} they were given, so no image was made: the device or its driver dropped work"
    )]
    LostWork { method: &'static str, what: &'static str, done: u64, expected: u64 },
    #[error("the {method} traversal {what}, so no image was made")]
    Fault { method: &'static str, what: String },
    #[error(
        "rt-pipeline traces the driver's own structures, not the file's triangles, so --vertices indexed does not apply to it; use lst, stackless, sst or sst-subgroup"
    )]
    IndexedRtPipeline,
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
    sample: [f32; 4],
    samples: [u32; 4],
    ao: [f32; 4],
}

/// The push constant of a pass (`Pass` in common.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct PassData {
    light: u32,
    depth: u32,
    work: u32,
    cap: u32,
}

impl PassData {
    fn bytes(light: u32, depth: u32, work: u32, cap: u32) -> [u8; kernels::PASS_BYTES as usize] {
        bytemuck::cast(PassData { light, depth, work, cap })
    }
}

/// Pixels per lane a subgroup of a persistent kernel takes at most on a CPU device (`cap` in
/// stages.wgsl: lavapipe ends an invocation's loops after 65535 iterations in all), with
/// enough workgroups launched that every pixel is taken. A GPU's subgroups take any number.
const CPU_PERSISTENT_CAP: u32 = 4;

/// Invocations the persistent kernels launch by default ([`Renderer::set_persistent`]): the most
/// an H100 SXM holds at once (132 multiprocessors of 2048). Fewer leave a larger GPU partly idle;
/// more cost a smaller one only workgroups that find the work taken and end at once.
pub const PERSISTENT_INVOCATIONS: u32 = 132 * 2048;

/// Per-pixel state of one tile, kept between frames and reused by every tile that fits.
struct Targets {
    pixels: u64,
    paths: Buffer,
    hits: Buffer,
    accum: Buffer,
    aovs: Buffer,
    image: Buffer,
    /// rt-pipeline: the ray and hit records the split stages exchange with the traversal.
    rt_records: Option<[Buffer; 2]>,
}

/// Who traces rt-pipeline's ray records.
enum RtTraversal {
    /// The driver: acceleration structures and a ray-tracing pipeline.
    Driver(Box<RtTracer>),
    /// LST in a compute kernel (made with the other kernels), for testing the split stages on a
    /// device without ray tracing.
    StandIn(Option<Pipeline>),
}

/// A scene on the GPU, ready to render frames with one traversal method.
pub struct Renderer<'g> {
    gpu: &'g Gpu,
    scene: &'g SceneFile,
    spec: Specialisation,
    /// The node and triangle arrays, one buffer per binding (`spec.split`).
    nodes: Vec<Buffer>,
    tris: Vec<Buffer>,
    normal_indices: Buffer,
    normals: Buffer,
    materials: Buffer,
    input_index: Buffer,
    pipelines: HashMap<Stage, Pipeline>,
    /// rt-pipeline: the first halves of the stages that trace (rt_pipeline.wgsl), and the driver's
    /// structures and pipeline.
    ray_halves: HashMap<Stage, Pipeline>,
    rt: Option<RtTraversal>,
    targets: Option<Targets>,
    /// A tile holds at most this many pixels (besides the device's own limits).
    tile_pixels: u64,
    /// Frames recorded back to back into each submission ([`Renderer::set_frames_per_submission`]).
    frames_per_submission: u32,
    /// [`Renderer::cast_rays`]: the rays of the frame being cast, one per pixel (origin, 1,
    /// direction, 1: `PathRay` of common.wgsl).
    ray_list: Option<Vec<[f32; 8]>>,
    /// Invocations a persistent kernel launches ([`Renderer::set_persistent`]).
    persistent_invocations: u32,
}

/// The kernels' storage buffers by binding number, as common.wgsl names them; `render_tile` binds
/// its buffers in this order (a test holds common.wgsl to it).
const BINDING_NAMES: [&str; 14] = [
    "frame",
    "nodes",
    "tris",
    "normal_indices",
    "normals",
    "materials",
    "lights",
    "input_index",
    "paths",
    "hits",
    "accum",
    "aovs",
    "image",
    "counters",
];

pub(crate) const BINDINGS: u32 = BINDING_NAMES.len() as u32;

/// Bytes per pixel of the per-pixel buffers: `PathRay`, `HitRec`, `Accum`, `Aov`
/// and the packed RGBA8 image of common.wgsl (a test holds them to naga's layout).
const PATH_BYTES: u64 = 32;
const HIT_BYTES: u64 = 16;
const ACCUM_BYTES: u64 = 48;
const AOV_BYTES: u64 = 32;
const IMAGE_BYTES: u64 = 4;

/// Where `Aov`'s fields lie in its eight 32-bit words (a test holds them to naga's layout).
mod aov_word {
    pub const NORMAL: usize = 0;
    pub const T: usize = 4;
    pub const PRIM: usize = 5;
    pub const NODES: usize = 6;
    pub const TRIS: usize = 7;
}

/// What one frame's passes gave, summed over tiles and submissions.
#[derive(Default)]
struct Tally {
    rays: RayCounts,
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
    fn new(width: u32, height: u32, image: bool, aovs: bool) -> Result<Self, VkRenderError> {
        let n = width as usize * height as usize;
        let bytes = n as u64 * (IMAGE_BYTES * image as u64 + AOV_BYTES * aovs as u64);
        let fail = |_| VkRenderError::HostMemory { width, height, bytes };
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
    pub fn new(
        gpu: &'g Gpu,
        scene: &'g SceneFile,
        method: Method,
        workgroup: (u32, u32),
    ) -> Result<Self, VkRenderError> {
        Self::with_binding_limit(gpu, scene, method, workgroup, u64::MAX)
    }

    /// [`Renderer::new`], with nodes and triangles split over bindings of at most `binding_bytes`
    /// (or the device's limit where that is lower): for tests, which thus split small scenes.
    pub fn with_binding_limit(
        gpu: &'g Gpu,
        scene: &'g SceneFile,
        method: Method,
        workgroup: (u32, u32),
        binding_bytes: u64,
    ) -> Result<Self, VkRenderError> {
        Self::make(gpu, scene, method, workgroup, false, binding_bytes)
    }

    /// rt-pipeline's stages, split around the trace as on a device with ray tracing, with LST's
    /// traversal in a compute kernel in place of the driver's (the scene needs its child-pair
    /// tree): tests the split stages and their records on any device. Its images are LST's.
    pub fn rt_stand_in(gpu: &'g Gpu, scene: &'g SceneFile, workgroup: (u32, u32)) -> Result<Self, VkRenderError> {
        Self::make(gpu, scene, Method::RtPipeline, workgroup, true, u64::MAX)
    }

    fn make(
        gpu: &'g Gpu,
        scene: &'g SceneFile,
        method: Method,
        workgroup: (u32, u32),
        stand_in: bool,
        binding_bytes: u64,
    ) -> Result<Self, VkRenderError> {
        // Refused before anything is uploaded, in one sentence naming what the device lacks.
        if method == Method::RtPipeline && !stand_in {
            crate::rt::properties(gpu)?;
        }
        // rt-pipeline reads no tree of the file; the binding gets one unused node.
        let placeholder = [bvh_format::Node::zeroed()];
        let binary = match method {
            // Refused in one sentence before any work when the file lacks the wide layout.
            Method::Cwbvh => {
                scene.wide.as_deref().ok_or(RenderError::MissingLayout { method: method.name(), layout: "wide" })?;
                &placeholder[..]
            }
            Method::RtPipeline if !stand_in => &placeholder[..],
            Method::RtPipeline => scene
                .child_pair
                .as_deref()
                .ok_or(RenderError::MissingLayout { method: "LST (rt-pipeline's stand-in)", layout: "child-pair" })?,
            Method::Lst | Method::Sst | Method::SstSubgroup => scene
                .child_pair
                .as_deref()
                .ok_or(RenderError::MissingLayout { method: method.name(), layout: "child-pair" })?,
            Method::Stackless => scene
                .escape
                .as_deref()
                .ok_or(RenderError::MissingLayout { method: method.name(), layout: "escape-pointer" })?,
        };
        let nodes = match (method, &scene.wide) {
            (Method::Cwbvh, Some(w)) => NodeArray::Wide(w),
            _ => NodeArray::Binary(binary),
        };
        let info = gpu.info();
        let node_what = match method {
            Method::Stackless => "escape-pointer nodes",
            Method::Cwbvh => "wide nodes",
            _ => "child-pair nodes",
        };
        let arrays = SceneArrays::new(scene);
        // rt-pipeline's ray and hit records take the binding numbers the split would use, so its
        // arrays must each fit one binding, as before the split.
        if method == Method::RtPipeline {
            fits(info, node_what, binary)?;
            fits(info, "triangles", &arrays.tris)?;
        }
        let (node_chunks, node_chunk) = match nodes {
            NodeArray::Binary(n) => chunking(info, binding_bytes, node_what, n)?,
            NodeArray::Wide(n) => chunking(info, binding_bytes, node_what, n)?,
        };
        let (tri_chunks, tri_chunk) = chunking(info, binding_bytes, "triangles", &arrays.tris)?;
        let split = Split { node_chunks, node_chunk, tri_chunks, tri_chunk };
        let stats = scene.stats();
        let mut spec = Specialisation {
            method,
            // cwbvh's node groups: one per level of the wide tree at most.
            stack_size: match nodes {
                NodeArray::Wide(w) => bvh_format::wide::depth(w).max(1),
                NodeArray::Binary(_) => stats.max_depth.max(1),
            },
            leaf_size: (stats.leaf_sizes.len().max(2) - 1) as u32,
            workgroup,
            reflection: scene.materials.iter().any(|m| m.kr > 0.0),
            refraction: scene.materials.iter().any(|m| m.kt > 0.0),
            smooth: !scene.normals.is_empty(),
            exact: false,
            intersect: Intersect::Watertight,
            fixed_offset: false,
            split,
            ray_list: false,
            vertices: Vertices::Expanded,
            first_vertex: 0,
            self_hits: false,
            persistent: Persistent::Off,
            refill: None,
        };
        let (wx, wy) = workgroup;
        let limit = info.max_workgroup_invocations.min(info.max_workgroup_size[0]).min(MAX_WORKGROUP_INVOCATIONS);
        if !workgroup_allowed(wx, wy, limit) {
            return Err(VkRenderError::Workgroup { x: wx, y: wy, limit: limit as u64 });
        }
        if method == Method::SstSubgroup && !info.supports_subgroup_ops {
            return Err(VkRenderError::NoSubgroups(info.name.clone()));
        }
        if matches!(method, Method::Lst | Method::Cwbvh)
            && info.kind == DeviceKind::Cpu
            && spec.stack_size > CPU_DEVICE_STACK_LIMIT
        {
            return Err(VkRenderError::PrivateStack {
                depth: spec.stack_size,
                limit: CPU_DEVICE_STACK_LIMIT,
                device: info.name.clone(),
            });
        }
        if matches!(method, Method::Sst | Method::SstSubgroup) {
            // The stack must fit whole; the leaf cache takes what is left, and a larger leaf is
            // loaded in chunks of it.
            let limit = info.max_shared_memory as u64;
            spec.leaf_size = kernels::sst_leaf_cache(&spec, limit).ok_or_else(|| VkRenderError::SharedMemory {
                depth: spec.stack_size,
                needed: kernels::sst_shared_bytes(&Specialisation { leaf_size: 1, ..spec }),
                limit,
            })?;
        }
        fits(info, "normal indices", &arrays.normal_indices)?;
        fits(info, "normals", &arrays.normals)?;
        fits(info, "materials", &scene.materials)?;
        fits(info, "input indices", &scene.input_index)?;
        let rt = match (method, stand_in) {
            (Method::RtPipeline, false) => Some(RtTraversal::Driver(Box::new(RtTracer::new(gpu, &arrays.tris)?))),
            (Method::RtPipeline, true) => Some(RtTraversal::StandIn(None)),
            _ => None,
        };
        Ok(Self {
            gpu,
            scene,
            spec,
            nodes: match nodes {
                NodeArray::Binary(n) => upload_chunks(gpu, n, node_chunk, "nodes")?,
                NodeArray::Wide(n) => upload_chunks(gpu, n, node_chunk, "nodes")?,
            },
            tris: upload_chunks(gpu, &arrays.tris, tri_chunk, "triangles")?,
            normal_indices: gpu.create_buffer_with(&arrays.normal_indices, "normal indices")?,
            normals: gpu.create_buffer_with(&arrays.normals, "normals")?,
            materials: gpu.create_buffer_with(&scene.materials, "materials")?,
            input_index: gpu.create_buffer_with(&scene.input_index, "input index")?,
            pipelines: HashMap::new(),
            ray_halves: HashMap::new(),
            rt,
            targets: None,
            tile_pixels: tiles::device_tile_pixels(info),
            frames_per_submission: 1,
            ray_list: None,
            persistent_invocations: PERSISTENT_INVOCATIONS,
        })
    }

    pub fn specialisation(&self) -> &Specialisation {
        &self.spec
    }

    /// rt-pipeline: what the driver's acceleration-structure build took.
    pub fn structure_build(&self) -> Option<crate::rt::accel::BuildReport> {
        match &self.rt {
            Some(RtTraversal::Driver(t)) => Some(t.build_report()),
            _ => None,
        }
    }

    /// Builds the kernels without contracting any float operations (`--exact`): on a GPU whose
    /// compiler fuses multiply-adds, the images then equal the CPU tracer's.
    pub fn set_exact(&mut self, exact: bool) {
        self.specialise(Specialisation { exact, ..self.spec });
    }

    /// Reads triangle corners in `form` from the next frame on (`--vertices`): uploads that form's
    /// triangle array in place of the other's, so a renderer holds one of them only, and builds
    /// the kernels that read it. Both forms give the same images bit for bit.
    pub fn set_vertices(&mut self, form: Vertices) -> Result<(), VkRenderError> {
        if form == self.spec.vertices {
            return Ok(());
        }
        if self.spec.method == Method::RtPipeline {
            return Err(VkRenderError::IndexedRtPipeline);
        }
        let info = self.gpu.info();
        // The new array is made before the old one goes, so a refusal leaves the renderer as it was.
        let (tris, split, first_vertex) = match form {
            Vertices::Expanded => {
                let arrays = SceneArrays::new(self.scene);
                let (tri_chunks, tri_chunk) = chunking(info, u64::MAX, "triangles", &arrays.tris)?;
                (
                    upload_chunks(self.gpu, &arrays.tris, tri_chunk, "triangles")?,
                    Split { tri_chunks, tri_chunk, ..self.spec.split },
                    0,
                )
            }
            Vertices::Indexed => {
                let records = indexed_records(self.scene);
                // One binding: the kernels find the vertices at a fixed record after the triangles.
                fits(info, "indexed triangles and vertices", &records)?;
                let buffer = self.gpu.create_buffer_with(&records, "indexed triangles and vertices")?;
                (
                    vec![buffer],
                    Split { tri_chunks: 1, tri_chunk: u32::MAX, ..self.spec.split },
                    self.scene.triangles.len() as u32,
                )
            }
        };
        self.tris = tris;
        self.specialise(Specialisation { vertices: form, first_vertex, split, ..self.spec });
        Ok(())
    }

    /// Counts the rays that the triangle they leave from meets (`--self-hits`, exact acne:
    /// [`render_spec::SelfHits`]) in the frames after this: a kernel variant with one more
    /// triangle test per such ray.
    pub fn set_self_hits(&mut self, on: bool) {
        self.specialise(Specialisation { self_hits: on, ..self.spec });
    }

    /// The closest hits of the given rays (origin, direction; the direction need not be unit),
    /// cast from 0 to f32::MAX as primary rays are, with `accuracy`'s triangle test: the AOVs
    /// of a ray-casting frame whose pixel `i` is ray `i` (`t`, `prim` and the rest; the ray
    /// counts in [`Image::rays`]). For tests that aim rays at chosen points (shared edges and
    /// vertices): the kernels read them from the `paths` buffer in place of the camera's.
    pub fn cast_rays(&mut self, rays: &[([f32; 3], [f32; 3])], accuracy: Accuracy) -> Result<Image, VkRenderError> {
        const WIDTH: usize = 1024;
        let n = rays.len().max(1);
        let (width, height) = (n.min(WIDTH), n.div_ceil(WIDTH));
        let first = rays.first().copied().unwrap_or(([0.0; 3], [0.0, 0.0, 1.0]));
        // The last row is filled up with copies of the first ray, whose results are dropped.
        let list = (0..width * height)
            .map(|i| {
                let (o, d) = rays.get(i).copied().unwrap_or(first);
                [o[0], o[1], o[2], 1.0, d[0], d[1], d[2], 1.0]
            })
            .collect();
        let settings = Settings {
            width: width as u32,
            height: height as u32,
            // Unused by the kernels but checked like any frame's.
            camera: render_spec::CameraSpec {
                eye: glam::Vec3::Z,
                at: glam::Vec3::ZERO,
                up: glam::Vec3::Y,
                fov_deg: 45.0,
            },
            mode: Mode::Cast,
            lights: Vec::new(),
            max_indirections: 0,
            aovs: true,
            accuracy,
        };
        self.ray_list = Some(list);
        let out = self.render(&settings);
        self.ray_list = None;
        let mut image = out?.image;
        image.rgb.truncate(rays.len());
        if let Some(a) = &mut image.aov {
            a.t.truncate(rays.len());
            a.normal.truncate(rays.len());
            a.prim.truncate(rays.len());
            a.nodes.truncate(rays.len());
            a.tris.truncate(rays.len());
        }
        image.rays.primary = rays.len() as u64;
        Ok(image)
    }

    /// The kernels of the frame's accuracy settings: the triangle test and the kind of origin
    /// offset are kernel variants, so the default kernels carry no code of the others.
    fn specialise_for(&mut self, a: &Accuracy) {
        let fixed_offset = matches!(a.offset, Offset::Fixed(_));
        let ray_list = self.ray_list.is_some();
        self.specialise(Specialisation { intersect: a.intersect, fixed_offset, ray_list, ..self.spec });
    }

    fn specialise(&mut self, spec: Specialisation) {
        if self.spec != spec {
            self.spec = spec;
            self.pipelines.clear();
            self.ray_halves.clear();
            if let Some(RtTraversal::StandIn(p)) = &mut self.rt {
                *p = None;
            }
        }
    }

    /// Runs the tracing stages that `mode` names as persistent threads (`--persistent`,
    /// [`Specialisation::persistent`]), launching about `invocations` invocations per dispatch
    /// (rounded up to whole workgroups; `None`: [`PERSISTENT_INVOCATIONS`]), with the setting's own
    /// refill threshold. [`Persistent::On`] is refused, in one sentence, for a method whose
    /// traversal does not walk in steps and on a device without the subgroup operations the kernels
    /// take their work with; [`Persistent::Auto`] is no request and gives such a method or device
    /// its plain kernels without a word. The images and ray counts are the plain kernels'.
    pub fn set_persistent(&mut self, mode: Persistent, invocations: Option<u32>) -> Result<(), VkRenderError> {
        self.set_persistent_with(mode, invocations, None)
    }

    /// [`Renderer::set_persistent`] with the lanes of every 32 that must be idle before a
    /// subgroup takes new pixels ([`Specialisation::refill`], 1 to 32; `None`: the setting's own).
    ///
    /// On a CPU device (lavapipe) auto chooses as on a GPU rather than plain: its persistent
    /// kernels are safe there because every subgroup takes at most [`CPU_PERSISTENT_CAP`] pixels
    /// per lane, so a lane's loops run the steps of a few walks, not of the thousands that pass
    /// gallivm's 65,535 iterations, and the counts check refuses, in one sentence, any frame whose
    /// work a loop limit cut short. The images are the plain kernels' bit for bit, so the tests on
    /// lavapipe run the very stage mix that a GPU runs by default.
    pub fn set_persistent_with(
        &mut self,
        mode: Persistent,
        invocations: Option<u32>,
        refill: Option<u32>,
    ) -> Result<(), VkRenderError> {
        let method = self.spec.method;
        let subgroups = self.gpu.info().supports_subgroup_ops;
        if mode == Persistent::On && !method.walks_in_steps() {
            return Err(VkRenderError::NotPersistent(method.name()));
        }
        if mode == Persistent::On && !subgroups {
            return Err(VkRenderError::NoSubgroups(self.gpu.info().name.clone()));
        }
        let mode =
            if mode == Persistent::Auto && !(method.walks_in_steps() && subgroups) { Persistent::Off } else { mode };
        self.persistent_invocations = invocations.unwrap_or(PERSISTENT_INVOCATIONS).max(1);
        self.specialise(Specialisation { persistent: mode, refill: refill.map(|r| r.clamp(1, 32)), ..self.spec });
        Ok(())
    }

    /// Renders in tiles of at most `pixels` pixels (at least one workgroup's), below what the
    /// device's limits allow: to bound the memory a frame takes, or to test tiling on small frames.
    pub fn limit_tile_pixels(&mut self, pixels: u64) {
        let wg = self.spec.workgroup.0 as u64 * self.spec.workgroup.1 as u64;
        self.tile_pixels = tiles::device_tile_pixels(self.gpu.info()).min(pixels.max(wg));
    }

    /// Holds at most `triangles` (at least one) in SST's leaf cache, so that larger leaves are
    /// tested in chunks as on a device with little workgroup memory: for tests.
    pub fn limit_leaf_cache(&mut self, triangles: u32) {
        self.specialise(Specialisation { leaf_size: self.spec.leaf_size.min(triangles.max(1)), ..self.spec });
    }

    /// Records `n` copies of each frame back to back into one submission, waited for once, and
    /// reports their mean: GPU time and rays per frame (issue 10 item 3: whether small frames fill
    /// the GPU when the gaps between submissions go). Every copy redoes the same work from the
    /// primary rays on, so the image is the single frame's. Frames of one sample per pixel only
    /// (a copy would add its sample to the sum again); all bounces go into the one submission.
    pub fn set_frames_per_submission(&mut self, n: u32) {
        self.frames_per_submission = n.max(1);
    }

    fn pipeline(&mut self, stage: Stage) -> Result<(), VkError> {
        let rt = self.rt.is_some();
        // rt-pipeline's kernels also bind the ray and hit records.
        let bindings = if rt { BINDINGS + 2 } else { BINDINGS };
        if let Some(RtTraversal::StandIn(p @ None)) = &mut self.rt {
            let spirv = kernels::compile_stand_in(&self.spec)?;
            *p = Some(self.gpu.pipeline(&spirv, bindings, kernels::PASS_BYTES, "rt-pipeline stand-in traversal")?);
        }
        let halves: &[Half] =
            if rt && stage != Stage::Convert { &[Half::Emit, Half::Collect] } else { &[Half::Collect] };
        for &half in halves {
            let map = if half == Half::Emit { &self.ray_halves } else { &self.pipelines };
            if map.contains_key(&stage) {
                continue;
            }
            let mut spirv = kernels::compile_half(stage, &self.spec, half)?;
            let label = match half {
                Half::Emit => format!("{} {stage:?} (ray half)", self.spec.method.name()),
                Half::Collect => format!("{} {stage:?}", self.spec.method.name()),
            };
            if self.spec.exact && self.gpu.info().denorm_preserve_f32 {
                spirv = crate::no_contraction::preserve_denormals(&spirv, &label)?;
            }
            let bindings = bindings + self.spec.split.extra_bindings();
            let p = self.gpu.pipeline(&spirv, bindings, kernels::PASS_BYTES, &label)?;
            match half {
                Half::Emit => self.ray_halves.insert(stage, p),
                Half::Collect => self.pipelines.insert(stage, p),
            };
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
            paths: g.create_buffer(pixels * PATH_BYTES, "paths")?,
            hits: g.create_buffer(pixels * HIT_BYTES, "hits")?,
            accum: g.create_buffer(pixels * ACCUM_BYTES, "accumulated colour")?,
            aovs: g.create_buffer(pixels * AOV_BYTES, "AOVs")?,
            image: g.create_buffer(pixels * IMAGE_BYTES, "image")?,
            rt_records: match &self.rt {
                None => None,
                Some(_) => Some([
                    g.create_buffer(pixels * crate::rt::spirv::RAY_BYTES as u64, "rt-pipeline ray records")?,
                    g.create_buffer(pixels * crate::rt::spirv::HIT_BYTES as u64, "rt-pipeline hit records")?,
                ]),
            },
        });
        if let (Some(RtTraversal::Driver(rt)), Some(t)) = (&self.rt, &self.targets)
            && let Some([rays, hits]) = &t.rt_records
        {
            rt.bind_records(rays, hits);
        }
        Ok(())
    }

    /// Renders one frame and reads back the image, and the AOVs when the settings ask for them.
    pub fn render(&mut self, s: &Settings) -> Result<Output, VkRenderError> {
        self.render_frame(s, true)
    }

    /// Renders one frame; without `readback` only the ray counts and GPU times come back (the
    /// image's pixels are empty and it has no AOVs), as benchmarks want.
    pub fn render_frame(&mut self, s: &Settings, readback: bool) -> Result<Output, VkRenderError> {
        self.render_with_progress(s, readback, &mut |_| {})
    }

    /// Renders one frame, calling `progress` after every tile. `readback` reads back the colours,
    /// and the per-pixel outputs when the settings ask for them; without it only the ray counts
    /// and GPU times come back.
    pub fn render_with_progress(
        &mut self,
        s: &Settings,
        readback: bool,
        progress: &mut dyn FnMut(Progress),
    ) -> Result<Output, VkRenderError> {
        let (image, aovs) = (readback, readback && s.aovs);
        let f = s.frame()?;
        if self.frames_per_submission > 1 && s.accuracy.spp > 1 {
            return Err(VkError::Usage(format!(
                "{} frames per submission take one sample per pixel, not {}",
                self.frames_per_submission, s.accuracy.spp
            ))
            .into());
        }
        self.specialise_for(&s.accuracy);
        if s.lights.len() > u32::MAX as usize / 2 {
            return Err(VkRenderError::TooManyLights(s.lights.len()));
        }
        // Bounces only in Whitted mode and where a material can spawn one: no scene pays for
        // what it lacks.
        let bounces = s.mode == Mode::Whitted && (self.spec.reflection || self.spec.refraction);
        let indirections = if bounces { s.max_indirections } else { 0 };
        let stages: &[Stage] = match s.mode {
            Mode::Cast => &[Stage::Cast],
            Mode::Whitted if indirections > 0 => &[Stage::Primary, Stage::Shade, Stage::Bounce, Stage::Convert],
            Mode::Whitted => &[Stage::Primary, Stage::Shade, Stage::Convert],
            Mode::Ao(_) => &[Stage::Primary, Stage::Ao, Stage::Convert],
            Mode::Diffuse => &[Stage::Primary, Stage::Diffuse, Stage::Convert],
        };
        let info = self.gpu.info();
        let groups = [info.max_workgroup_count[0], info.max_workgroup_count[1]];
        let mut host = HostFrame::new(s.width, s.height, image, aovs)?;
        for &st in stages {
            self.pipeline(st)?;
        }
        // Tiles sized from the device's limits may still not fit the memory other programs left:
        // halve them until they do, down to one workgroup.
        let plan = loop {
            let plan = tiles::plan(s.width, s.height, self.tile_pixels, self.spec.workgroup, groups)
                .ok_or_else(|| VkError::Usage(format!("no tile of {} pixels holds a workgroup", self.tile_pixels)))?;
            let wg = self.spec.workgroup.0 as u64 * self.spec.workgroup.1 as u64;
            match self.targets(plan.iter().map(Tile::pixels).max().unwrap_or(1)) {
                Err(VkError::OutOfDeviceMemory { .. }) if self.tile_pixels / 2 >= wg => self.tile_pixels /= 2,
                result => break result.map(|()| plan)?,
            }
        };

        let stop = BounceStop::new(self.scene, &s.lights).with_cutoff(s.accuracy.cutoff);
        let samples: Vec<(f32, f32)> = render_spec::accuracy::sample_positions(s.accuracy.spp).collect();
        let offset = match s.accuracy.offset {
            Offset::Fixed(d) => d,
            Offset::ScaleAware => 0.0,
        };
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
            stop: [stop.bound, stop.k_max, stop.cutoff, 0.0],
            tile: [0; 4],
            sample: [0.5, 0.5, 1.0 / samples.len() as f32, offset],
            samples: [0, samples.len() as u32, 0, 0],
            ao: [0.0; 4],
        };
        if let Mode::Ao(ao) = s.mode {
            let (lo, hi) = self.scene.bounds();
            frame.samples[2] = ao.samples;
            frame.ao = [ao.distance(lo, hi), ao.inverse(), 0.0, 0.0];
        }
        let g = self.gpu;
        let frame_buf = g.create_buffer(size_of::<FrameData>() as u64, "frame")?;
        // Storage buffers may not be empty: a scene without lights binds one unused entry.
        let lights = if s.lights.is_empty() { vec![Light::new([0.0; 3], [0.0; 3])] } else { s.lights.clone() };
        let lights_buf = g.create_buffer_with(&lights, "lights")?;
        // After the live-path words, one work word per pass of a submission for the persistent
        // kernels (`persistent` in stages.wgsl).
        let work_words = if self.spec.any_persistent() {
            passes_per_submission(s.mode, s.lights.len() as u32, indirections, self.frames_per_submission)
        } else {
            0
        };
        let counters =
            g.create_buffer(4 * (counters::LIVE as u64 + indirections.max(1) as u64 + work_words), "ray counters")?;

        let mut tally = Tally::default();
        let total = s.width as u64 * s.height as u64;
        let mut done = 0;
        for tile in &plan {
            frame.tile = [tile.x, tile.y, tile.width, tile.height];
            if let Some(list) = &self.ray_list {
                let t = self.targets.as_ref().expect("the targets were made above");
                let rows = (tile.y..tile.y + tile.height).map(|y| (y * s.width + tile.x) as usize);
                let rays: Vec<[f32; 8]> =
                    rows.flat_map(|at| list[at..at + tile.width as usize].iter().copied()).collect();
                g.upload_slice(&t.paths, &rays)?;
            }
            // Sample by sample (render_spec::accuracy::sample_positions): the kernels sum the
            // colours in this order and the last sample's conversion writes their mean.
            for (k, &(sx, sy)) in samples.iter().enumerate() {
                frame.sample[0] = sx;
                frame.sample[1] = sy;
                frame.samples[0] = k as u32;
                g.upload(&frame_buf, bytemuck::bytes_of(&frame))?;
                self.render_tile(
                    tile,
                    s.mode,
                    s.lights.len() as u32,
                    indirections,
                    &frame_buf,
                    &lights_buf,
                    &counters,
                    &mut tally,
                )?;
            }
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
        // The mean of the frames of each submission (identical work, so the counts divide).
        let n = self.frames_per_submission;
        if n > 1 {
            let r = &mut tally.rays;
            for c in [&mut r.primary, &mut r.shadow, &mut r.secondary, &mut r.ao, &mut r.diffuse] {
                *c /= u64::from(n);
            }
            tally.gpu_ms /= f64::from(n);
            tally.passes.iter_mut().for_each(|(_, ms)| *ms /= f64::from(n));
        }
        let f32_of = |u: u32| f32::from_bits(u);
        let a = &host.aovs;
        let aov = aovs.then(|| Aovs {
            normal: a.iter().map(|a| std::array::from_fn(|k| f32_of(a[aov_word::NORMAL + k]))).collect(),
            t: a.iter().map(|a| f32_of(a[aov_word::T])).collect(),
            prim: a.iter().map(|a| a[aov_word::PRIM]).collect(),
            nodes: a.iter().map(|a| a[aov_word::NODES]).collect(),
            tris: a.iter().map(|a| a[aov_word::TRIS]).collect(),
        });
        Ok(Output {
            image: Image {
                width: s.width,
                height: s.height,
                rgb: host.image.iter().map(|&p| [p as u8, (p >> 8) as u8, (p >> 16) as u8]).collect(),
                aov,
                rays: tally.rays,
            },
            gpu_ms: tally.gpu_ms,
            passes: tally.passes,
        })
    }

    /// Runs one tile's passes: the first submission traces the primary rays, shades (Whitted:
    /// once per light; the incoherent modes: their AO rays or diffuse bounce) and makes the
    /// first bounces; later ones (each as many bounces as all before it) run only while some
    /// path is alive. Every submission ends with the conversion to 8 bits, so whichever is last
    /// leaves the tile's image.
    #[allow(clippy::too_many_arguments)]
    fn render_tile(
        &self,
        tile: &Tile,
        mode: Mode,
        light_count: u32,
        indirections: u32,
        frame_buf: &Buffer,
        lights_buf: &Buffer,
        counters: &Buffer,
        tally: &mut Tally,
    ) -> Result<(), VkRenderError> {
        let g = self.gpu;
        let t = self.targets.as_ref().expect("the targets were made before the tiles");
        let (wx, wy) = self.spec.workgroup;
        let groups = [tile.width.div_ceil(wx), tile.height.div_ceil(wy), 1];
        // In the order of BINDING_NAMES, then the split bindings or rt-pipeline's records.
        let mut buffers: Vec<&Buffer> = vec![
            frame_buf,
            &self.nodes[0],
            &self.tris[0],
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
        // The split bindings, in the order of `kernels::Split::extra_bindings` (rt-pipeline never
        // splits: its records take those binding numbers).
        buffers.extend(self.nodes[1..].iter().chain(&self.tris[1..]));
        if let Some(records) = &t.rt_records {
            buffers.extend(records);
        }
        let p = &self.pipelines;
        let rays = &self.ray_halves;
        let rt = self.rt.as_ref();
        let shade_passes = light_count.max(1);
        let copies = self.frames_per_submission;
        let mut first = 0;
        loop {
            // Bounces [first, end) in this submission; copies of a frame make all in one.
            let end = match first {
                _ if copies > 1 => indirections,
                0 => indirections.min(FIRST_BOUNCES),
                _ => indirections.min(2 * first),
            };
            let mut dispatches = 0u64;
            let timings = g.run(|rec| {
                let mut pass = |rec: &mut crate::device::Recorder, stage: Stage, light: u32, depth: u32| {
                    // This pass's work word, after the live-path words (passes_per_submission).
                    let work = counters::LIVE as u64 + indirections.max(1) as u64 + dispatches;
                    dispatches += 1;
                    let cap = if g.info().kind == DeviceKind::Cpu { CPU_PERSISTENT_CAP } else { 0 };
                    let push = PassData::bytes(light, depth, work as u32, cap);
                    if self.spec.persistent_stage(stage) {
                        debug_assert!(work < counters.size() / 4, "the counters hold every pass's work word");
                        // With a cap, enough workgroups that their subgroups' caps cover the tile.
                        let all = groups[0] * groups[1];
                        let launch = self.persistent_invocations.div_ceil(wx * wy);
                        let launch = if cap > 0 { launch.max(all.div_ceil(cap)) } else { launch }.min(all);
                        return rec.dispatch(&p[&stage], &buffers, &push, [launch, 1, 1]);
                    }
                    // rt-pipeline: the stage's first half writes the rays, the driver traces them,
                    // the second half is the stage with their hits.
                    if let (Some(rt), Some(emit)) = (rt, rays.get(&stage)) {
                        rec.dispatch(emit, &buffers, &push, groups)?;
                        rec.mark(RT_RAY_HALVES);
                        match rt {
                            RtTraversal::Driver(t) => t.record_trace(rec, tile.width, tile.height),
                            RtTraversal::StandIn(p) => {
                                let p = p.as_ref().expect("the stand-in was made with the kernels");
                                rec.dispatch(p, &buffers, &push, groups)?;
                            }
                        }
                        rec.mark(RT_TRAVERSAL);
                    }
                    rec.dispatch(&p[&stage], &buffers, &push, groups)
                };
                rec.zero(counters);
                rec.mark("start");
                for _ in 0..copies {
                    if mode == Mode::Cast {
                        pass(rec, Stage::Cast, 0, 0)?;
                        rec.mark("cast");
                        continue;
                    }
                    if first == 0 {
                        pass(rec, Stage::Primary, 0, 0)?;
                        rec.mark("trace primary");
                        match mode {
                            Mode::Ao(ao) => {
                                // One pass per AO ray (the push constant's depth names it).
                                for k in 0..ao.samples {
                                    pass(rec, Stage::Ao, 0, k)?;
                                }
                                rec.mark("ambient occlusion");
                            }
                            Mode::Diffuse => {
                                pass(rec, Stage::Diffuse, 0, 0)?;
                                rec.mark("diffuse bounce");
                            }
                            _ => {
                                for l in 0..shade_passes {
                                    pass(rec, Stage::Shade, l, 0)?;
                                }
                                rec.mark("shade 0");
                            }
                        }
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
                }
                Ok(())
            })?;
            tally.add_timings(&timings);
            let words: Vec<u32> = g.download_as(counters)?;
            check_counts(&self.spec, &words, tile.pixels(), first == 0, copies, dispatches)?;
            let wide = |slot: usize| words[slot] as u64 | (words[slot + 1] as u64) << 32;
            tally.rays.primary += wide(counters::PRIMARY);
            tally.rays.shadow += wide(counters::SHADOW);
            tally.rays.secondary += wide(counters::SECONDARY);
            tally.rays.ao += wide(counters::AO);
            tally.rays.diffuse += wide(counters::DIFFUSE);
            tally.rays.self_hits.shadow += wide(counters::SELF_SHADOW);
            tally.rays.self_hits.secondary += wide(counters::SELF_SECONDARY);
            tally.rays.self_hits.ao += wide(counters::SELF_AO);
            tally.rays.self_hits.diffuse += wide(counters::SELF_DIFFUSE);
            if mode != Mode::Whitted || end >= indirections || words[counters::LIVE + end as usize - 1] == 0 {
                return Ok(());
            }
            first = end;
        }
    }
}

/// The most passes one submission of a tile records (`Renderer::render_tile`): per frame the
/// primary pass, the shade (one per light), AO (one per ray) or diffuse passes, every bounce with
/// its shade passes, and the conversion; a submission makes at most all the bounces.
fn passes_per_submission(mode: Mode, lights: u32, indirections: u32, copies: u32) -> u64 {
    let shade = u64::from(lights.max(1));
    let per_frame = match mode {
        Mode::Cast => 1,
        Mode::Ao(ao) => 2 + u64::from(ao.samples),
        Mode::Diffuse => 3,
        Mode::Whitted => 2 + shade + u64::from(indirections) * (1 + shade),
    };
    per_frame * u64::from(copies.max(1))
}

/// Refuses a submission whose counts do not add up: every dispatch must have finished every
/// pixel of the tile, the first must have traced one primary ray per pixel and frame (`copies`
/// frames per submission), and no traversal may have given up on a ray.
fn check_counts(
    spec: &Specialisation,
    words: &[u32],
    pixels: u64,
    first: bool,
    copies: u32,
    dispatches: u64,
) -> Result<(), VkRenderError> {
    let method = spec.method.name();
    let wide = |slot: usize| words[slot] as u64 | (words[slot + 1] as u64) << 32;
    let faults = words[counters::FAULTS];
    if faults & counters::FAULT_STACK != 0 {
        let what =
            format!("found its stack of {} entries full (the tree is deeper than its file says)", spec.stack_size);
        return Err(VkRenderError::Fault { method, what });
    }
    if faults & counters::FAULT_WALK != 0 {
        return Err(VkRenderError::Fault { method, what: "took more steps than the tree has nodes".to_owned() });
    }
    let primary = wide(counters::PRIMARY);
    let expected = pixels * u64::from(copies);
    if first && primary != expected {
        return Err(VkRenderError::LostWork { method, what: "primary rays", done: primary, expected });
    }
    let finished = wide(counters::FINISHED);
    let expected = dispatches * pixels;
    if finished != expected {
        return Err(VkRenderError::LostWork { method, what: "pixel passes", done: finished, expected });
    }
    Ok(())
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

/// The indexed form's triangle array (`Vertices::Indexed`, `tris` in common.wgsl): per triangle
/// its vertex indices and material, then the vertex positions padded to 16 bytes.
fn indexed_records(scene: &SceneFile) -> Vec<[u32; 4]> {
    let tris = scene.triangles.iter().map(|t| [t.vertices[0], t.vertices[1], t.vertices[2], t.material]);
    let vertices = scene.vertices.iter().map(|v| [v[0].to_bits(), v[1].to_bits(), v[2].to_bits(), 0]);
    tris.chain(vertices).collect()
}

/// The node array a renderer uploads: the binary nodes of one layout, or the wide layout's.
#[derive(Clone, Copy)]
enum NodeArray<'a> {
    Binary(&'a [bvh_format::Node]),
    Wide(&'a [bvh_format::WideNode]),
}

/// Bytes of scene data a renderer with `method` uploads (nodes of the one layout it reads,
/// triangles in the default expanded form, normals, materials, input indices), for `bvhc info`.
pub fn upload_bytes(scene: &SceneFile, method: Method) -> u64 {
    upload_bytes_with(scene, method, Vertices::Expanded)
}

/// [`upload_bytes`] with the triangles in `form` (`--vertices`).
pub fn upload_bytes_with(scene: &SceneFile, method: Method, form: Vertices) -> u64 {
    let nodes = match method {
        Method::Stackless => scene.escape.as_ref(),
        Method::RtPipeline | Method::Cwbvh => None,
        _ => scene.child_pair.as_ref(),
    };
    let wide = if method == Method::Cwbvh { scene.wide.as_deref().unwrap_or_default() } else { &[] };
    let a = SceneArrays::new(scene);
    let tris = match form {
        Vertices::Expanded => std::mem::size_of_val(&a.tris[..]),
        Vertices::Indexed => 16 * (scene.triangles.len() + scene.vertices.len()),
    };
    [
        std::mem::size_of_val(nodes.map_or(&[][..], |n| &n[..])) + std::mem::size_of_val(wide),
        tris,
        std::mem::size_of_val(&a.normal_indices[..]),
        std::mem::size_of_val(&a.normals[..]),
        std::mem::size_of_val(&scene.materials[..]),
        std::mem::size_of_val(&scene.input_index[..]),
    ]
    .iter()
    .sum::<usize>() as u64
}

/// The deepest LST stack a CPU Vulkan device (lavapipe) is asked to compile. LST keeps its stack
/// in two private arrays of the tree's depth, and lavapipe compiles a kernel at its first dispatch
/// (inside the submission, so a slow compile reads as a hang); the compile time grows steeply with
/// the stack. A Whitted frame's first submission of `tools::stress::scenes::chain` on this 2-core
/// VM's lavapipe at load 12: 500 deep 3.9 s, 1000 deep 21 s, 2000 deep 91 s (with naga's zero
/// initialisers of the arrays, which `shader.rs` now takes out: 500 deep 109 s, 1000 deep past the
/// 120 s timeout). Later frames take milliseconds; the H100 renders a 1000-deep chain at once.
pub const CPU_DEVICE_STACK_LIMIT: u32 = 1024;

/// `data` in buffers of `per_chunk` records each (at least one buffer, for an empty array too),
/// labelled with the array's name and, after the first, the chunk's number.
fn upload_chunks<T: bytemuck::Pod>(gpu: &Gpu, data: &[T], per_chunk: u32, what: &str) -> Result<Vec<Buffer>, VkError> {
    if data.is_empty() {
        return Ok(vec![gpu.create_buffer_with(data, what)?]);
    }
    let label = |i: usize| if i == 0 { what.to_string() } else { format!("{what} {i}") };
    data.chunks(per_chunk as usize).enumerate().map(|(i, c)| gpu.create_buffer_with(c, &label(i))).collect()
}

/// The most bytes one storage-buffer binding may hold, and the limit that sets it: the device's
/// range and allocation limits, and never more than 2 GiB. The H100 (driver 580.159.04) reported a
/// range of 4 GiB but rendered wrong images, silently, once the node array passed 2 GiB (75 M
/// nodes: stackless missed most hits, LST ran away; 60 M nodes rendered right), the classic sign
/// of signed 32-bit byte offsets; bindings of at most 2 GiB rendered right at every size measured
/// (docs/measurements/h100-2026-11-25-size). Splitting costs one comparison per read, only for
/// scenes that large.
pub fn binding_limit(info: &crate::device::DeviceInfo) -> (&'static str, u64) {
    const SIGNED_32_BIT_OFFSETS: u64 = 1 << 31;
    let (name, limit) = if info.max_storage_buffer_range <= info.max_memory_allocation {
        ("maxStorageBufferRange", info.max_storage_buffer_range)
    } else {
        ("maxMemoryAllocationSize", info.max_memory_allocation)
    };
    if limit > SIGNED_32_BIT_OFFSETS {
        ("2 GiB (signed 32-bit byte offsets)", SIGNED_32_BIT_OFFSETS)
    } else {
        (name, limit)
    }
}

/// How many bindings of at most `binding_bytes` (and the device's limits) the array `data` needs,
/// up to [`kernels::MAX_CHUNKS`], and the records per binding. An empty array still takes one.
fn chunking<T>(
    info: &crate::device::DeviceInfo,
    binding_bytes: u64,
    what: &'static str,
    data: &[T],
) -> Result<(u32, u32), VkRenderError> {
    let bytes = std::mem::size_of_val(data) as u64;
    let (limit_name, limit) = binding_limit(info);
    let limit = limit.min(binding_bytes);
    let per_chunk = (limit / size_of::<T>().max(1) as u64).clamp(1, u32::MAX as u64);
    let chunks = (data.len() as u64).div_ceil(per_chunk).max(1);
    if chunks > kernels::MAX_CHUNKS as u64 {
        let fits = per_chunk * kernels::MAX_CHUNKS as u64;
        return Err(VkRenderError::SplitTooLarge { what, bytes, chunks: kernels::MAX_CHUNKS, limit_name, limit, fits });
    }
    // One binding: no split, whatever the limit (the kernels then read the array as before).
    if chunks == 1 {
        return Ok((1, u32::MAX));
    }
    Ok((chunks as u32, per_chunk as u32))
}

/// Checks that a scene array fits one storage buffer binding and one allocation.
fn fits<T>(info: &crate::device::DeviceInfo, what: &'static str, data: &[T]) -> Result<(), VkRenderError> {
    let bytes = std::mem::size_of_val(data) as u64;
    let (limit_name, limit) = binding_limit(info);
    if bytes > limit {
        let fits = limit / size_of::<T>().max(1) as u64;
        return Err(VkRenderError::SceneTooLarge { what, bytes, limit_name, limit, fits });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec() -> Specialisation {
        Specialisation {
            stack_size: 12,
            leaf_size: 4,
            reflection: false,
            refraction: false,
            ..Specialisation::every_feature(Method::Sst)
        }
    }

    /// Counters as the kernels leave them after `dispatches` passes over `pixels` pixels.
    fn words(primary: u64, finished: u64, faults: u32) -> Vec<u32> {
        let mut w = vec![0u32; counters::LIVE + 1];
        w[counters::PRIMARY] = primary as u32;
        w[counters::PRIMARY + 1] = (primary >> 32) as u32;
        w[counters::FINISHED] = finished as u32;
        w[counters::FINISHED + 1] = (finished >> 32) as u32;
        w[counters::FAULTS] = faults;
        w
    }

    #[test]
    fn counts_that_add_up_pass() {
        check_counts(&spec(), &words(100, 400, 0), 100, true, 1, 4).unwrap();
        // Later submissions trace no primary rays.
        check_counts(&spec(), &words(0, 300, 0), 100, false, 1, 3).unwrap();
        // 64-bit counts: more than 2^32 pixel passes in one tile.
        let n = 1u64 << 31;
        check_counts(&spec(), &words(n, 3 * n, 0), n, true, 1, 3).unwrap();
        // Two frames per submission: twice the primary rays, every dispatch counted.
        check_counts(&spec(), &words(200, 800, 0), 100, true, 2, 8).unwrap();
        let short = check_counts(&spec(), &words(100, 800, 0), 100, true, 2, 8).unwrap_err().to_string();
        assert!(short.contains("finished 100 of the 200 primary rays"), "{short}");
    }

    #[test]
    fn lost_work_and_faults_refuse_the_frame_in_one_sentence() {
        let cases = [
            (words(99, 400, 0), true, "finished 99 of the 100 primary rays"),
            (words(100, 399, 0), true, "finished 399 of the 400 pixel passes"),
            (words(0, 400, 0), false, ""),
            (words(100, 400, counters::FAULT_STACK), true, "stack of 12 entries full"),
            (words(100, 400, counters::FAULT_WALK), true, "more steps than the tree has nodes"),
        ];
        for (w, first, says) in cases {
            let r = check_counts(&spec(), &w, 100, first, 1, 4);
            if says.is_empty() {
                assert!(r.is_ok(), "{r:?}");
                continue;
            }
            let msg = r.expect_err(says).to_string();
            assert!(msg.contains(says) && msg.contains("sst") && msg.contains("no image"), "{msg}");
            assert!(!msg.contains('\n'));
        }
    }
}

/// The layout contract between the Rust records and common.wgsl, read from naga's own layout of a
/// kernel module: every shared struct's size, array stride and field offsets, and the binding table.
#[cfg(test)]
mod layout_contract {
    use super::*;
    use bvh_format::{Material, Node, Triangle};
    use naga::proc::Layouter;
    use std::mem::{offset_of, size_of};

    /// A kernel with every feature present, so that every struct and binding is declared.
    fn module() -> naga::Module {
        let spec = Specialisation::every_feature(Method::Lst);
        naga::front::wgsl::parse_str(&kernels::source(Stage::Bounce, &spec)).expect("the kernel parses")
    }

    /// (size, array stride, alignment, [(field, offset)]) of the WGSL struct `name`.
    fn wgsl_struct(m: &naga::Module, l: &Layouter, name: &str) -> (u32, u32, u32, Vec<(String, u32)>) {
        let (h, ty) =
            m.types.iter().find(|(_, t)| t.name.as_deref() == Some(name)).unwrap_or_else(|| panic!("no {name}"));
        let naga::TypeInner::Struct { members, span } = &ty.inner else { panic!("{name} is not a struct") };
        let fields = members.iter().map(|f| (f.name.clone().unwrap_or_default(), f.offset)).collect();
        (*span, l[h].to_stride(), l[h].alignment.round_up(1), fields)
    }

    /// Asserts that the WGSL struct `name` is `size` bytes, strides by `size` in an array (so a
    /// Rust slice uploads as is) and has exactly `fields` at those byte offsets.
    fn check(m: &naga::Module, l: &Layouter, name: &str, size: usize, fields: &[(&str, usize)]) {
        let (span, stride, align, wgsl) = wgsl_struct(m, l, name);
        assert_eq!(span as usize, size, "{name}: {span} bytes in WGSL, {size} in Rust");
        assert_eq!(stride as usize, size, "{name}: array stride {stride} in WGSL (alignment {align}), {size} in Rust");
        let wgsl: Vec<(&str, usize)> = wgsl.iter().map(|(n, o)| (n.as_str(), *o as usize)).collect();
        assert_eq!(wgsl, fields, "{name}: fields and offsets (WGSL left, Rust right)");
    }

    #[test]
    fn every_record_shared_with_wgsl_has_the_rust_size_and_offsets() {
        let m = module();
        let mut l = Layouter::default();
        l.update(m.to_ctx()).expect("naga lays the module out");
        check(
            &m,
            &l,
            "Node",
            size_of::<Node>(),
            &[
                ("min", offset_of!(Node, min)),
                ("count", offset_of!(Node, count)),
                ("max", offset_of!(Node, max)),
                ("index", offset_of!(Node, index)),
            ],
        );
        check(
            &m,
            &l,
            "Tri",
            size_of::<Triangle>(),
            &[
                ("p0", offset_of!(Triangle, p0)),
                ("material", offset_of!(Triangle, material)),
                ("p1", offset_of!(Triangle, p1)),
                ("pad1", offset_of!(Triangle, _pad1)),
                ("p2", offset_of!(Triangle, p2)),
                ("pad2", offset_of!(Triangle, _pad2)),
            ],
        );
        check(
            &m,
            &l,
            "Material",
            size_of::<Material>(),
            &[
                ("kd_n", offset_of!(Material, kd)),
                ("ks_kr", offset_of!(Material, ks)),
                ("kt_ior", offset_of!(Material, kt)),
            ],
        );
        assert_eq!(offset_of!(Material, shininess), offset_of!(Material, kd) + 12, "shininess is kd_n.w");
        assert_eq!(offset_of!(Material, kr), offset_of!(Material, ks) + 12, "kr is ks_kr.w");
        assert_eq!(offset_of!(Material, ior), offset_of!(Material, kt) + 4, "ior is kt_ior.y");
        check(
            &m,
            &l,
            "Light",
            size_of::<Light>(),
            &[("position", offset_of!(Light, position)), ("colour", offset_of!(Light, colour))],
        );
        check(
            &m,
            &l,
            "Frame",
            size_of::<FrameData>(),
            &[
                ("eye", offset_of!(FrameData, eye)),
                ("top_left", offset_of!(FrameData, top_left)),
                ("h_step", offset_of!(FrameData, h_step)),
                ("v_step", offset_of!(FrameData, v_step)),
                ("ambient", offset_of!(FrameData, ambient)),
                ("background", offset_of!(FrameData, background)),
                ("size", offset_of!(FrameData, size)),
                ("stop", offset_of!(FrameData, stop)),
                ("tile", offset_of!(FrameData, tile)),
                ("sample", offset_of!(FrameData, sample)),
                ("samples", offset_of!(FrameData, samples)),
                ("ao", offset_of!(FrameData, ao)),
            ],
        );
        check(
            &m,
            &l,
            "Pass",
            size_of::<PassData>(),
            &[
                ("light", offset_of!(PassData, light)),
                ("depth", offset_of!(PassData, depth)),
                ("work", offset_of!(PassData, work)),
                ("cap", offset_of!(PassData, cap)),
            ],
        );
        assert_eq!(size_of::<PassData>(), kernels::PASS_BYTES as usize, "the push-constant range");
        // Per-pixel records the host only sizes and reads back as words.
        let size = |name: &str| wgsl_struct(&m, &l, name).1 as u64;
        assert_eq!(size("PathRay"), PATH_BYTES);
        assert_eq!(size("HitRec"), HIT_BYTES);
        assert_eq!(size("Aov"), AOV_BYTES);
        let w = |k: usize| 4 * k;
        check(
            &m,
            &l,
            "Aov",
            AOV_BYTES as usize,
            &[
                ("normal", w(aov_word::NORMAL)),
                ("t", w(aov_word::T)),
                ("prim", w(aov_word::PRIM)),
                ("nodes", w(aov_word::NODES)),
                ("tris", w(aov_word::TRIS)),
            ],
        );
    }

    #[test]
    fn the_binding_table_matches_the_rust_side() {
        let m = module();
        let mut l = Layouter::default();
        l.update(m.to_ctx()).expect("naga lays the module out");
        let mut bound: Vec<(u32, String, u32)> = m
            .global_variables
            .iter()
            .filter_map(|(_, g)| {
                let b = g.binding.as_ref()?;
                assert_eq!(b.group, 0, "{:?} is outside group 0", g.name);
                assert!(matches!(g.space, naga::AddressSpace::Storage { .. }), "{:?} is not a storage buffer", g.name);
                // The element stride of an array buffer, the size of a single record.
                let stride = match &m.types[g.ty].inner {
                    naga::TypeInner::Array { stride, .. } => *stride,
                    _ => l[g.ty].size,
                };
                Some((b.binding, g.name.clone().unwrap_or_default(), stride))
            })
            .collect();
        bound.sort();
        let names: Vec<&str> = bound.iter().map(|(_, n, _)| n.as_str()).collect();
        assert_eq!(names, BINDING_NAMES, "binding names in order (WGSL left)");
        let numbers: Vec<u32> = bound.iter().map(|(b, _, _)| *b).collect();
        assert_eq!(numbers, (0..BINDINGS).collect::<Vec<_>>(), "bindings are 0..{BINDINGS} without gaps");
        let stride = |name: &str| bound.iter().find(|(_, n, _)| n == name).expect("bound").2 as u64;
        assert_eq!(stride("frame"), size_of::<FrameData>() as u64);
        assert_eq!(stride("nodes"), size_of::<Node>() as u64);
        assert_eq!(stride("tris"), size_of::<Triangle>() as u64);
        // Three words per triangle and three floats per normal (SceneArrays uploads [u32; 3] and
        // [f32; 3]).
        assert_eq!(stride("normal_indices") * 3, size_of::<[u32; 3]>() as u64);
        assert_eq!(stride("normals") * 3, size_of::<[f32; 3]>() as u64);
        assert_eq!(stride("materials"), size_of::<Material>() as u64);
        assert_eq!(stride("lights"), size_of::<Light>() as u64);
        assert_eq!(stride("input_index"), 4);
        assert_eq!(stride("paths"), PATH_BYTES);
        assert_eq!(stride("hits"), HIT_BYTES);
        assert_eq!(stride("accum"), ACCUM_BYTES);
        assert_eq!(stride("aovs"), AOV_BYTES);
        assert_eq!(stride("image"), IMAGE_BYTES);
        assert_eq!(stride("counters"), 4);
    }
}
