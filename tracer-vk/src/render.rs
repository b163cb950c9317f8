//! Rendering a scene file with the stream pipeline: upload once (only the layout the method
//! reads), specialise the kernels for the scene, then per frame dispatch the stages and read back
//! the image, the AOVs and the ray counts.

use crate::device::{Buffer, Gpu, Pipeline};
use crate::error::VkError;
use crate::kernels::{self, Method, Specialisation, Stage};
use bvh_format::{Light, SceneFile};
use bytemuck::{Pod, Zeroable};
use render_spec::{Aovs, BounceStop, Image, Mode, RayCounts, RenderError, Settings};
use std::collections::HashMap;

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
    #[error("a {x} x {y} workgroup is empty or larger than the device's {limit} invocations")]
    Workgroup { x: u32, y: u32, limit: u64 },
    #[error("{0} lacks the subgroup operations the sst-subgroup traversal votes with; use sst")]
    NoSubgroups(String),
    #[error("SST needs a workgroup of a power-of-two size for its vote reduction, not {x} x {y}")]
    SstWorkgroup { x: u32, y: u32 },
    #[error(
        "SST needs {needed} bytes of workgroup memory for a tree {depth} deep with leaves of up to {leaf} triangles, more than the device's {limit}; use LST, or rebuild with a smaller --max-leaf-size"
    )]
    SharedMemory { depth: u32, leaf: u32, needed: u64, limit: u64 },
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
}

#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
struct PassData {
    light: u32,
    depth: u32,
    pad: [u32; 2],
}

/// Per-pixel state of one resolution, kept between frames.
struct Targets {
    width: u32,
    height: u32,
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
    normals: Buffer,
    material_ids: Buffer,
    materials: Buffer,
    input_index: Buffer,
    pipelines: HashMap<Stage, Pipeline>,
    targets: Option<Targets>,
}

const BINDINGS: u32 = 15;

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
        };
        let (wx, wy) = workgroup;
        let invocations = wx as u64 * wy as u64;
        let limit = gpu.info().max_workgroup_invocations as u64;
        if wx == 0 || wy == 0 || invocations > limit {
            return Err(VkRenderError::Workgroup { x: wx, y: wy, limit });
        }
        if method == Method::SstSubgroup && !gpu.info().supports_subgroup_ops {
            return Err(VkRenderError::NoSubgroups(gpu.info().name.clone()));
        }
        if matches!(method, Method::Sst | Method::SstSubgroup) {
            if !invocations.is_power_of_two() {
                return Err(VkRenderError::SstWorkgroup { x: wx, y: wy });
            }
            let needed = kernels::sst_shared_bytes(&spec);
            let limit = gpu.info().max_shared_memory as u64;
            if needed > limit {
                return Err(VkRenderError::SharedMemory {
                    depth: spec.stack_size,
                    leaf: spec.leaf_size,
                    needed,
                    limit,
                });
            }
        }
        Ok(Self {
            gpu,
            scene,
            spec,
            nodes: gpu.create_buffer_with(nodes, "nodes")?,
            tris: gpu.create_buffer_with(&scene.triangles, "triangles")?,
            normals: gpu.create_buffer_with(&scene.normals, "normals")?,
            material_ids: gpu.create_buffer_with(&scene.material_ids, "material ids")?,
            materials: gpu.create_buffer_with(&scene.materials, "materials")?,
            input_index: gpu.create_buffer_with(&scene.input_index, "input index")?,
            pipelines: HashMap::new(),
            targets: None,
        })
    }

    pub fn specialisation(&self) -> &Specialisation {
        &self.spec
    }

    fn pipeline(&mut self, stage: Stage) -> Result<(), VkError> {
        if !self.pipelines.contains_key(&stage) {
            let spirv = kernels::compile(stage, &self.spec)?;
            let label = format!("{} {stage:?}", self.spec.method.name());
            let p = self.gpu.pipeline(&spirv, BINDINGS, 0, &label)?;
            self.pipelines.insert(stage, p);
        }
        Ok(())
    }

    fn targets(&mut self, width: u32, height: u32) -> Result<(), VkError> {
        if self.targets.as_ref().is_some_and(|t| t.width == width && t.height == height) {
            return Ok(());
        }
        self.targets = None;
        let n = width as u64 * height as u64;
        let g = self.gpu;
        self.targets = Some(Targets {
            width,
            height,
            paths: g.create_buffer(n * 32, "paths")?,
            hits: g.create_buffer(n * 16, "hits")?,
            accum: g.create_buffer(n * 16, "accumulated colour")?,
            aovs: g.create_buffer(n * 32, "AOVs")?,
            image: g.create_buffer(n * 4, "image")?,
        });
        Ok(())
    }

    /// Renders one frame and reads back the image and the AOVs.
    pub fn render(&mut self, s: &Settings) -> Result<Output, VkRenderError> {
        self.render_frame(s, true)
    }

    /// Renders one frame; without `readback` only the ray counts and GPU times come back (the
    /// image's pixels are empty and it has no AOVs), as benchmarks want.
    pub fn render_frame(&mut self, s: &Settings, readback: bool) -> Result<Output, VkRenderError> {
        let f = s.frame()?;
        if s.lights.len() > u32::MAX as usize / 2 {
            return Err(VkRenderError::TooManyLights(s.lights.len()));
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
        for &st in stages {
            self.pipeline(st)?;
        }
        self.targets(s.width, s.height)?;

        let stop = BounceStop::new(self.scene, &s.lights);
        let v4 = |v: glam::Vec3| [v.x, v.y, v.z, 0.0];
        let a3 = |v: [f32; 3]| [v[0], v[1], v[2], 0.0];
        let frame = FrameData {
            eye: v4(f.eye),
            top_left: v4(f.top_left),
            h_step: v4(f.h_step),
            v_step: v4(f.v_step),
            ambient: a3(self.scene.settings.ambient),
            background: a3(self.scene.settings.background),
            size: [s.width, s.height, s.lights.len() as u32, indirections],
            stop: [stop.bound, stop.k_max, 0.0, 0.0],
        };
        let g = self.gpu;
        let frame_buf = g.create_buffer_with(std::slice::from_ref(&frame), "frame")?;
        // Storage buffers may not be empty: a scene without lights binds one unused entry.
        let lights = if s.lights.is_empty() { vec![Light::new([0.0; 3], [0.0; 3])] } else { s.lights.clone() };
        let lights_buf = g.create_buffer_with(&lights, "lights")?;
        let counters = g.create_buffer(16, "ray counters")?;
        let shade_passes = s.lights.len().max(1) as u32;
        let pass_data: Vec<PassData> =
            (0..shade_passes.max(indirections)).map(|i| PassData { light: i, depth: i, pad: [0; 2] }).collect();
        let pass_bufs: Vec<Buffer> = pass_data
            .iter()
            .map(|p| g.create_buffer_with(std::slice::from_ref(p), "pass"))
            .collect::<Result<_, _>>()?;

        let t = self.targets.as_ref().expect("targets were just created");
        let groups = [s.width.div_ceil(self.spec.workgroup.0), s.height.div_ceil(self.spec.workgroup.1), 1];
        let pipelines = &self.pipelines;
        let bind = |pass: usize| -> [&Buffer; BINDINGS as usize] {
            [
                &frame_buf,
                &self.nodes,
                &self.tris,
                &self.normals,
                &self.material_ids,
                &self.materials,
                &lights_buf,
                &self.input_index,
                &t.paths,
                &t.hits,
                &t.accum,
                &t.aovs,
                &t.image,
                &counters,
                &pass_bufs[pass],
            ]
        };
        let timings = g.run(|rec| {
            rec.zero(&counters);
            rec.mark("start");
            if !whitted {
                rec.dispatch(&pipelines[&Stage::Cast], &bind(0), &[], groups)?;
                rec.mark("cast");
                return Ok(());
            }
            rec.dispatch(&pipelines[&Stage::Primary], &bind(0), &[], groups)?;
            rec.mark("trace primary");
            for depth in 0..=indirections {
                for l in 0..shade_passes {
                    rec.dispatch(&pipelines[&Stage::Shade], &bind(l as usize), &[], groups)?;
                }
                rec.mark(&format!("shade {depth}"));
                if depth < indirections {
                    rec.dispatch(&pipelines[&Stage::Bounce], &bind(depth as usize), &[], groups)?;
                    rec.mark(&format!("trace secondary {}", depth + 1));
                }
            }
            rec.dispatch(&pipelines[&Stage::Convert], &bind(0), &[], groups)?;
            rec.mark("convert");
            Ok(())
        })?;

        let counts: Vec<u32> = g.download_as(&counters)?;
        let n = s.pixels() as usize;
        let rgb = if readback {
            let image: Vec<u32> = g.download_as(&t.image)?;
            image[..n].iter().map(|&p| [p as u8, (p >> 8) as u8, (p >> 16) as u8]).collect()
        } else {
            Vec::new()
        };
        let aov = if readback && s.aovs {
            let aovs: Vec<[u32; 8]> = g.download_as(&t.aovs)?;
            let f32_of = |u: u32| f32::from_bits(u);
            Some(Aovs {
                normal: aovs[..n].iter().map(|a| [f32_of(a[0]), f32_of(a[1]), f32_of(a[2])]).collect(),
                t: aovs[..n].iter().map(|a| f32_of(a[4])).collect(),
                prim: aovs[..n].iter().map(|a| a[5]).collect(),
                nodes: aovs[..n].iter().map(|a| a[6]).collect(),
                tris: aovs[..n].iter().map(|a| a[7]).collect(),
            })
        } else {
            None
        };
        let rays = RayCounts { primary: counts[0] as u64, shadow: counts[1] as u64, secondary: counts[2] as u64 };
        Ok(Output {
            image: Image { width: s.width, height: s.height, rgb, aov, rays },
            gpu_ms: timings.total_ms,
            passes: timings.intervals,
        })
    }
}
