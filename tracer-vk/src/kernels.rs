//! Assembling and specialising the WGSL kernels: the common file, one traversal file and the
//! pipeline stages, with the shading contract's constants (generated from `render_spec::constants`)
//! and per-scene constants prepended and unneeded shading features stripped.
//!
//! Specialisation is by generated constants, not naga's pipeline overrides: the per-invocation
//! stack of LST is a function-scope array, which WGSL only lets a `const` size (naga rejects an
//! `override`-sized one), and features left out of the text are truly absent from the SPIR-V.

use crate::error::VkError;
use crate::shader;
use render_spec::Intersect;

const COMMON: &str = include_str!("../shaders/common.wgsl");
const LST: &str = include_str!("../shaders/lst.wgsl");
const STACKLESS: &str = include_str!("../shaders/stackless.wgsl");
const SST: &str = include_str!("../shaders/sst.wgsl");
const CWBVH: &str = include_str!("../shaders/cwbvh.wgsl");
const RT_PIPELINE: &str = include_str!("../shaders/rt_pipeline.wgsl");
const STAGES: &str = include_str!("../shaders/stages.wgsl");

/// GPU traversal methods (thesis 4.3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Method {
    /// Per-invocation stack over the child-pair layout (thesis 4.3.2).
    Lst,
    /// Escape-pointer walk, no stack (thesis 4.3.4).
    Stackless,
    /// Workgroup-shared stack, one path per workgroup (thesis 4.3.3).
    Sst,
    /// SST voting with subgroup operations instead of a workgroup-memory reduction.
    SstSubgroup,
    /// The vendor's traversal: VK_KHR_ray_tracing_pipeline on the driver's acceleration structures
    /// ([`crate::rt`]), the stages' shading unchanged (rt_pipeline.wgsl).
    RtPipeline,
    /// Ylitie, Karras and Laine's compressed wide BVH: 8 quantised children per node, a stack of
    /// node groups, children visited in the order of the ray's octant (cwbvh.wgsl); reads the
    /// file's wide layout.
    Cwbvh,
}

impl Method {
    /// Every method, in the order `trace-vk` lists them.
    pub const ALL: [Method; 6] =
        [Method::Lst, Method::Stackless, Method::Sst, Method::SstSubgroup, Method::RtPipeline, Method::Cwbvh];

    pub fn name(self) -> &'static str {
        match self {
            Method::Lst => "lst",
            Method::Stackless => "stackless",
            Method::Sst => "sst",
            Method::SstSubgroup => "sst-subgroup",
            Method::RtPipeline => "rt-pipeline",
            Method::Cwbvh => "cwbvh",
        }
    }

    /// Whether the method walks one of the file's trees (rt-pipeline builds the driver's own).
    pub fn reads_file_tree(self) -> bool {
        self != Method::RtPipeline
    }

    /// Whether the method's kernels can run as persistent threads ([`Specialisation::persistent`]):
    /// its traversal file walks one node per step (`walk_begin`, `walk_step`). SST walks with the
    /// whole workgroup and rt-pipeline with the driver.
    pub fn walks_in_steps(self) -> bool {
        matches!(self, Method::Lst | Method::Stackless)
    }
}

/// Which half of a stage an rt-pipeline kernel is (rt_pipeline.wgsl): the one that writes the
/// pixel's ray before the driver traces it, or the one that reads its hit and shades. The other
/// methods' kernels are whole stages, [`Half::Collect`] by convention.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Half {
    Emit,
    Collect,
}

/// The kernels of the stream pipeline.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Stage {
    /// Ray casting: trace and shade in one kernel.
    Cast,
    /// Whitted: trace the primary rays.
    Primary,
    /// Whitted: one light (and the ambient term) at every live path's hit, shadow ray included.
    Shade,
    /// Whitted: trace one secondary ray per live path.
    Bounce,
    /// Whitted and the incoherent modes: accumulated radiance to 8 bits.
    Convert,
    /// Ambient occlusion: one AO ray of every primary hit (any hit); after the last, their
    /// fraction.
    Ao,
    /// The diffuse bounce of every primary hit (closest hit), shaded.
    Diffuse,
}

impl Stage {
    /// Whether the stage traces rays (every one but the conversion).
    pub fn traces(self) -> bool {
        self != Stage::Convert
    }

    /// Whether the stage traces incoherent rays: cosine-distributed AO and diffuse rays, whose
    /// neighbours in a warp go different ways and end at different times. The H100 measured
    /// persistent threads faster for these (AO frames 1.13-1.34x the plain kernels') and slower
    /// for coherent ones (cast frames 0.75-0.89x), docs/gpu-benchmark.md. Whitted's shadow and
    /// mirror rays stay with the coherent ones: they leave neighbouring hits towards one light or
    /// in nearly one direction, and no measurement has shown a gain for them.
    pub fn incoherent(self) -> bool {
        matches!(self, Stage::Ao | Stage::Diffuse)
    }

    /// The tracing stages a frame of `mode` runs (the conversion aside).
    pub fn tracing(mode: &render_spec::Mode) -> &'static [Stage] {
        match mode {
            render_spec::Mode::Cast => &[Stage::Cast],
            render_spec::Mode::Whitted => &[Stage::Primary, Stage::Shade, Stage::Bounce],
            render_spec::Mode::Ao(_) => &[Stage::Primary, Stage::Ao],
            render_spec::Mode::Diffuse => &[Stage::Primary, Stage::Diffuse],
        }
    }

    /// The stage's name in stages.wgsl (`stage_{name}`).
    pub fn name(self) -> &'static str {
        self.parts().0
    }

    /// The stage's parts in stages.wgsl: `{prefix}_begin`, `{prefix}_end` and `{Prefix}Job`.
    fn parts(self) -> (&'static str, &'static str) {
        match self {
            Stage::Cast => ("cast", "CastJob"),
            Stage::Primary => ("primary", "PrimaryJob"),
            Stage::Shade => ("shade", "ShadeJob"),
            Stage::Bounce => ("bounce", "BounceJob"),
            Stage::Ao => ("ao", "AoJob"),
            Stage::Diffuse => ("diffuse", "DiffuseJob"),
            Stage::Convert => ("convert", ""),
        }
    }

    fn entry(self) -> &'static str {
        match self {
            Stage::Cast => "stage_cast",
            Stage::Primary => "stage_primary",
            Stage::Shade => "stage_shade",
            Stage::Bounce => "stage_bounce",
            Stage::Convert => "stage_convert",
            Stage::Ao => "stage_ao",
            Stage::Diffuse => "stage_diffuse",
        }
    }
}

/// What a scene needs from its kernels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Specialisation {
    pub method: Method,
    /// Entries of LST's and SST's stacks: the file's max depth (at least 1).
    pub stack_size: u32,
    /// Triangles SST's leaf cache (in workgroup memory) holds: the file's largest leaf, or fewer
    /// where the device's workgroup memory would not hold it ([`sst_leaf_cache`]); a larger leaf
    /// is then tested in chunks.
    pub leaf_size: u32,
    pub workgroup: (u32, u32),
    /// Some material reflects (kr > 0).
    pub reflection: bool,
    /// Some material refracts (kt > 0).
    pub refraction: bool,
    /// Some triangle has vertex normals (the others are shaded with their geometric normal).
    pub smooth: bool,
    /// No float operation may be contracted with another (`--exact`, [`crate::no_contraction`]).
    pub exact: bool,
    /// The triangle test (`--intersect`): each its own kernel, so the default one is unchanged.
    pub intersect: Intersect,
    /// Origins move by the frame's fixed distance (`--offset D`) instead of the scale-aware offset.
    pub fixed_offset: bool,
    /// How the node and triangle arrays are spread over storage-buffer bindings.
    pub split: Split,
    /// Ray casting traces the host's rays, one per pixel, from the `paths` buffer instead of the
    /// camera's ([`crate::render::Renderer::cast_rays`]: tests that aim rays at chosen points).
    pub ray_list: bool,
    /// How the kernels read triangle corners (`--vertices`; `fetch_tri` in common.wgsl).
    pub vertices: Vertices,
    /// [`Vertices::Indexed`]: the record where the vertex positions start (the triangle count).
    pub first_vertex: u32,
    /// Count the shadow, secondary, AO and diffuse rays that the triangle they leave from meets
    /// (`--self-hits`; [`counters::SELF_SHADOW`] and after): a variant, so the default kernels
    /// carry no such test.
    pub self_hits: bool,
    /// Which tracing stages run as persistent threads (`--persistent`; `persistent` in
    /// stages.wgsl): as many workgroups as the device holds at once, each subgroup taking pixels
    /// from a counter and refilling its lanes whose rays ended. Methods that
    /// [`Method::walks_in_steps`] only; the images are the plain kernels'.
    /// [`Specialisation::persistent_stage`] is the choice per stage.
    pub persistent: Persistent,
    /// Persistent kernels: a subgroup's finished lanes take new pixels once this many of every 32
    /// lanes are idle (1: as soon as one is; 32: only when all are, no replacement); `None`: the
    /// setting's own ([`Specialisation::refill_idle`]).
    pub refill: Option<u32>,
}

/// Which tracing stages run as persistent threads ([`Specialisation::persistent`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Persistent {
    /// Plain kernels, one invocation per pixel (`--persistent off`).
    Off,
    /// Every tracing stage, refilling once [`DEFAULT_REFILL`] lanes of 32 are idle (`--persistent
    /// on`).
    On,
    /// The stages that trace incoherent rays ([`Stage::incoherent`]: AO and diffuse), refilling
    /// once [`INCOHERENT_REFILL`] lanes of 32 are idle; plain kernels for the others
    /// (`--persistent auto`, the default of `trace-vk render` and `bench`). Where the method or
    /// the device cannot run persistent kernels, the plain ones, unasked
    /// ([`crate::render::Renderer::set_persistent`]).
    Auto,
}

impl Persistent {
    /// The name `--persistent` takes.
    pub fn name(self) -> &'static str {
        match self {
            Persistent::Off => "off",
            Persistent::On => "on",
            Persistent::Auto => "auto",
        }
    }
}

/// [`Specialisation::refill`] of `--persistent on`: a quarter of the lanes idle.
pub const DEFAULT_REFILL: u32 = 8;

/// [`Specialisation::refill`] of `--persistent auto`'s incoherent stages: half of the lanes idle,
/// 4-5% faster than [`DEFAULT_REFILL`] for AO frames on the H100 (docs/gpu-benchmark.md, the
/// refill sweep of tools/scripts/h100-persistent.sh).
pub const INCOHERENT_REFILL: u32 = 16;

/// How the kernels read the corners of a triangle (`--vertices`): defined with the settings both
/// tracers share.
pub use render_spec::Vertices;

/// The most bindings one scene array (nodes or triangles) is spread over.
pub const MAX_CHUNKS: u32 = 4;

/// Storage-buffer ranges are a limit of one binding (maxStorageBufferRange: 128 MiB on lavapipe,
/// 4 GiB on the H100), not of the device: an array larger than one binding is cut into up to
/// [`MAX_CHUNKS`] bindings of `*_chunk` records each, and the kernels pick the binding by index
/// range. With one chunk each (every scene that fits one binding) the kernel text is exactly the
/// unsplit one, so the hot path is unchanged.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Split {
    /// Bindings of the node array (1 to [`MAX_CHUNKS`]) and nodes per binding.
    pub node_chunks: u32,
    pub node_chunk: u32,
    /// Bindings of the triangle array and triangles per binding.
    pub tri_chunks: u32,
    pub tri_chunk: u32,
}

impl Split {
    /// One binding per array.
    pub const NONE: Split = Split { node_chunks: 1, node_chunk: u32::MAX, tri_chunks: 1, tri_chunk: u32::MAX };

    /// Bindings after the unsplit table (`render::BINDINGS`): the node chunks after the first, then
    /// the triangle chunks after the first.
    pub fn extra_bindings(&self) -> u32 {
        self.node_chunks.max(1) - 1 + self.tri_chunks.max(1) - 1
    }
}

impl Specialisation {
    /// `method`'s kernels with every feature kept (reflection, refraction, smooth normals; the
    /// default triangle test and offset; one binding per array; a 23-entry stack, 8-triangle
    /// leaves, 8x8 workgroups): what tests that inspect the kernels start from, so a new field
    /// gets one default here rather than one in each of them.
    pub fn every_feature(method: Method) -> Specialisation {
        Specialisation {
            method,
            stack_size: 23,
            leaf_size: 8,
            workgroup: (8, 8),
            reflection: true,
            refraction: true,
            smooth: true,
            exact: false,
            intersect: Intersect::Watertight,
            fixed_offset: false,
            split: Split::NONE,
            ray_list: false,
            vertices: Vertices::Expanded,
            first_vertex: 0,
            self_hits: false,
            persistent: Persistent::Off,
            refill: None,
        }
    }

    /// Whether `stage`'s kernel is a persistent one (and so takes subgroup operations): the one
    /// place that decides it per stage.
    pub fn persistent_stage(&self, stage: Stage) -> bool {
        self.method.walks_in_steps()
            && stage.traces()
            && match self.persistent {
                Persistent::Off => false,
                Persistent::On => true,
                Persistent::Auto => stage.incoherent(),
            }
    }

    /// Whether any stage runs persistently (the frame then holds a work word per pass).
    pub fn any_persistent(&self) -> bool {
        self.method.walks_in_steps() && self.persistent != Persistent::Off
    }

    /// Idle lanes of 32 before a persistent subgroup refills: [`Specialisation::refill`] where
    /// given, else [`INCOHERENT_REFILL`] under [`Persistent::Auto`] (whose persistent stages are
    /// all incoherent) and [`DEFAULT_REFILL`] under [`Persistent::On`].
    pub fn refill_idle(&self) -> u32 {
        let own = if self.persistent == Persistent::Auto { INCOHERENT_REFILL } else { DEFAULT_REFILL };
        self.refill.unwrap_or(own).clamp(1, 32)
    }

    /// The `//#if` blocks of the kernel files this specialisation keeps.
    fn features(&self) -> Vec<&'static str> {
        let mut features = Vec::new();
        if self.reflection {
            features.push("REFLECTION");
        }
        if self.refraction {
            features.push("REFRACTION");
        }
        if self.smooth {
            features.push("SMOOTH");
        }
        features.push(if self.method == Method::SstSubgroup { "VOTE_SUBGROUP" } else { "VOTE_REDUCTION" });
        features.push(match self.intersect {
            Intersect::Watertight => "WATERTIGHT",
            Intersect::MollerTrumbore => "MOLLER_TRUMBORE",
        });
        features.push(if self.fixed_offset { "FIXED_OFFSET" } else { "SCALE_AWARE_OFFSET" });
        if self.exact {
            features.push("EXACT");
        }
        features.push(if self.ray_list { "RAY_LIST" } else { "CAMERA_RAYS" });
        features.push(match self.vertices {
            Vertices::Expanded => "EXPANDED_VERTICES",
            Vertices::Indexed => "INDEXED_VERTICES",
        });
        if self.self_hits {
            features.push("SELF_HITS");
        }
        features
    }
}

/// Drops the lines between `//#if NAME` and `//#endif` when NAME is not enabled (no nesting).
pub fn strip_features(src: &str, enabled: &[&str]) -> String {
    let mut out = String::with_capacity(src.len());
    let mut keep = true;
    for line in src.lines() {
        let t = line.trim();
        if let Some(name) = t.strip_prefix("//#if ") {
            keep = enabled.contains(&name.trim());
            continue;
        }
        if t == "//#endif" {
            keep = true;
            continue;
        }
        if keep {
            out.push_str(line);
            out.push('\n');
        }
    }
    out
}

/// The kernel text as the device's operators round: each `div_rn(a, b)`, `div3_rn(a, b)` and
/// `sqrt_rn(x)` of the shared code (correctly rounded in an `--exact` kernel, common.wgsl) written
/// as `a / b` and `sqrt(x)`, so that the other kernels are the SPIR-V they were before `--exact`.
/// Calls are on one line; comments are left as they are.
pub fn with_device_rounding(src: &str) -> String {
    let mut out = String::with_capacity(src.len());
    for line in src.lines() {
        let (code, comment) = line.split_at(line.find("//").unwrap_or(line.len()));
        out.push_str(&rewrite_calls(code));
        out.push_str(comment);
        out.push('\n');
    }
    out
}

fn rewrite_calls(code: &str) -> String {
    let mut out = String::with_capacity(code.len());
    let mut rest = code;
    while let Some((i, name)) = ["div_rn(", "div3_rn(", "sqrt_rn("]
        .iter()
        .filter_map(|name| rest.find(name).map(|i| (i, *name)))
        .filter(|&(i, _)| !rest[..i].ends_with(|c: char| c.is_alphanumeric() || c == '_'))
        .min()
    {
        out.push_str(&rest[..i]);
        let args_start = i + name.len();
        let (args, len) = call_arguments(&rest[args_start..]);
        match (name, args.as_slice()) {
            ("sqrt_rn(", [x]) => out.push_str(&format!("sqrt({})", x.trim())),
            (_, [a, b]) if name != "sqrt_rn(" => {
                let operand = |a: &str| {
                    let a = a.trim();
                    if a.chars().all(|c| c.is_alphanumeric() || c == '_' || c == '.') {
                        a.to_string()
                    } else {
                        format!("({a})")
                    }
                };
                out.push_str(&format!("({} / {})", operand(a), operand(b)));
            }
            _ => panic!("the kernel calls {name}) with {} arguments: {code}", args.len()),
        }
        rest = &rest[args_start + len..];
    }
    out.push_str(rest);
    out
}

/// The comma-separated arguments of a call whose opening parenthesis came just before `src`, and
/// the length of the text up to and including the closing parenthesis.
fn call_arguments(src: &str) -> (Vec<&str>, usize) {
    let mut depth = 0;
    let mut args = Vec::new();
    let mut start = 0;
    for (i, c) in src.char_indices() {
        match c {
            '(' => depth += 1,
            ')' if depth == 0 => {
                args.push(&src[start..i]);
                return (args, i + 1);
            }
            ')' => depth -= 1,
            ',' if depth == 0 => {
                args.push(&src[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    panic!("a call in the kernel text is not closed: {src}")
}

/// The counters buffer the kernels count into, in u32 words; the kernels get these as constants.
pub mod counters {
    /// 64-bit counters (low word, high word): primary, shadow, secondary, AO and diffuse rays,
    /// and invocations that finished a stage for a pixel of the tile.
    pub const PRIMARY: usize = 0;
    pub const SHADOW: usize = 2;
    pub const SECONDARY: usize = 4;
    pub const AO: usize = 6;
    pub const DIFFUSE: usize = 8;
    pub const FINISHED: usize = 10;
    /// FAULT_* bits: a traversal gave up on a ray.
    pub const FAULTS: usize = 12;
    /// 64-bit counters of the `self_hits` variant: shadow, secondary, AO and diffuse rays that
    /// the triangle they leave from meets (render_spec::SelfHits).
    pub const SELF_SHADOW: usize = 13;
    pub const SELF_SECONDARY: usize = 15;
    pub const SELF_AO: usize = 17;
    pub const SELF_DIFFUSE: usize = 19;
    /// Then one word per bounce: paths still alive after it.
    pub const LIVE: usize = 21;
    /// A stack push found the stack full (the tree is deeper than the file's depth).
    pub const FAULT_STACK: u32 = 1;
    /// A walk took more steps than the tree has nodes.
    pub const FAULT_WALK: u32 = 2;

    pub(crate) const WGSL: [(&str, u32); 14] = [
        ("SLOT_PRIMARY", PRIMARY as u32),
        ("SLOT_SHADOW", SHADOW as u32),
        ("SLOT_SECONDARY", SECONDARY as u32),
        ("SLOT_AO", AO as u32),
        ("SLOT_DIFFUSE", DIFFUSE as u32),
        ("SLOT_FINISHED", FINISHED as u32),
        ("SLOT_FAULTS", FAULTS as u32),
        ("SLOT_SELF_SHADOW", SELF_SHADOW as u32),
        ("SLOT_SELF_SECONDARY", SELF_SECONDARY as u32),
        ("SLOT_SELF_AO", SELF_AO as u32),
        ("SLOT_SELF_DIFFUSE", SELF_DIFFUSE as u32),
        ("SLOT_LIVE", LIVE as u32),
        ("FAULT_STACK", FAULT_STACK),
        ("FAULT_WALK", FAULT_WALK),
    ];
}

/// Bytes of the push constant every kernel takes: which light a shade pass handles and which
/// bounce a bounce pass is (`Pass` in common.wgsl).
pub const PASS_BYTES: u32 = 16;

/// The complete WGSL source of one kernel.
pub fn source(stage: Stage, spec: &Specialisation) -> String {
    source_half(stage, spec, Half::Collect)
}

/// The complete WGSL source of one kernel; `half` matters for rt-pipeline only.
pub fn source_half(stage: Stage, spec: &Specialisation, half: Half) -> String {
    let mut features = spec.features();
    let traversal = match spec.method {
        Method::Lst => LST,
        Method::Stackless => STACKLESS,
        Method::Sst | Method::SstSubgroup => SST,
        Method::Cwbvh => CWBVH,
        Method::RtPipeline => {
            features.push(if half == Half::Emit { "RT_EMIT" } else { "RT_COLLECT" });
            RT_PIPELINE
        }
    };
    // Every kernel runs its WG_X x WG_Y pixel block as a line of WG_X * WG_Y invocations. naga
    // accepts the subgroup builtins only in one-dimensional workgroups, and lavapipe (whose
    // subgroups are 8 wide) loses whole rows of SST's workgroups when a two-dimensional one is
    // narrower than 8: `--workgroup 4x4` traced a quarter of its rays.
    let (params, subgroup_setup) = if spec.method == Method::SstSubgroup {
        (
            ",\n        @builtin(subgroup_invocation_id) sgl: u32, @builtin(subgroup_id) sgi: u32, @builtin(num_subgroups) sgn: u32",
            "    sg_lane = sgl;\n    sg_id = sgi;\n    sg_count = sgn;\n",
        )
    } else {
        ("", "")
    };
    let call = if spec.method == Method::RtPipeline {
        // The pixel's ray and hit records; none outside the tile, where pixel_index would name
        // another pixel's.
        format!(
            "let valid = x < frame.tile.x + frame.tile.z && y < frame.tile.y + frame.tile.w;\n    \
             rt_slot = select(RT_NO_SLOT, pixel_index(x, y), valid);\n    {}(x, y, valid);",
            stage.entry()
        )
    } else {
        format!("{}(x, y, x < frame.tile.x + frame.tile.z && y < frame.tile.y + frame.tile.w);", stage.entry())
    };
    let entry = if spec.persistent_stage(stage) {
        features.push("PERSISTENT");
        // The persistent driver (stages.wgsl) runs this stage's parts.
        let (prefix, job) = stage.parts();
        format!(
            "const REFILL_IDLE: u32 = {}u;\n\
             alias StageJob = {job};\n\
             fn stage_begin(x: u32, y: u32, valid: bool) -> StageJob {{\n    return {prefix}_begin(x, y, valid);\n}}\n\
             fn stage_end(j: StageJob, h: HitRec) {{\n    {prefix}_end(j, h);\n}}\n\
             @compute @workgroup_size(WG_X * WG_Y)\n\
             fn main(@builtin(local_invocation_index) li: u32) {{\n\
             \x20   lid = li;\n    persistent();\n}}\n",
            spec.refill_idle()
        )
    } else {
        format!(
            "@compute @workgroup_size(WG_X * WG_Y)\n\
             fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) li: u32{params}) {{\n\
             \x20   lid = li;\n{subgroup_setup}\
             \x20   let x = frame.tile.x + wg.x * WG_X + li % WG_X;\n    let y = frame.tile.y + wg.y * WG_Y + li / WG_X;\n\
             \x20   {call}\n}}\n"
        )
    };
    let text = format!(
        "{}\n{}\n{}\n{}",
        prelude(spec),
        strip_features(traversal, &features),
        strip_features(STAGES, &features),
        entry
    );
    let text = if spec.method == Method::Cwbvh { text.replacen(BINARY_NODES, WIDE_NODES, 1) } else { text };
    let text = split_arrays(&text, &spec.split, node_record(spec.method));
    if spec.exact { text } else { with_device_rounding(&text) }
}

/// common.wgsl's declaration of the node array, and the one cwbvh's kernels have instead: the
/// binding holds the wide layout's records (cwbvh.wgsl's `WideNode`) for that method.
const BINARY_NODES: &str = "var<storage, read> nodes: array<Node>;";
const WIDE_NODES: &str = "var<storage, read> nodes: array<WideNode>;";

/// The record of the node array a method's kernels read.
fn node_record(method: Method) -> &'static str {
    if method == Method::Cwbvh { "WideNode" } else { "Node" }
}

/// rt-pipeline's traversal done by LST in a compute kernel, one invocation per pixel's ray record
/// (`stand_in` in rt_pipeline.wgsl): for testing the split stages on a device without ray
/// tracing. `spec` is the renderer's (any method); the kernel walks the child-pair tree.
pub fn stand_in_source(spec: &Specialisation) -> String {
    let spec = Specialisation { method: Method::Lst, ..*spec };
    let mut features = spec.features();
    features.push("RT_STAND_IN");
    let text = format!(
        "{}\n{}\n{}\n\
         @compute @workgroup_size(WG_X * WG_Y)\n\
         fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) li: u32) {{\n\
         \x20   lid = li;\n\
         \x20   let x = frame.tile.x + wg.x * WG_X + li % WG_X;\n    let y = frame.tile.y + wg.y * WG_Y + li / WG_X;\n\
         \x20   if x < frame.tile.x + frame.tile.z && y < frame.tile.y + frame.tile.w {{\n\
         \x20       stand_in((y - frame.tile.y) * frame.tile.z + (x - frame.tile.x));\n    }}\n}}\n",
        prelude(&spec),
        strip_features(LST, &features),
        strip_features(RT_PIPELINE, &features),
    );
    if spec.exact { text } else { with_device_rounding(&text) }
}

/// Translates [`stand_in_source`].
pub fn compile_stand_in(spec: &Specialisation) -> Result<Vec<u32>, VkError> {
    let words = shader::translate(&stand_in_source(spec), "rt-pipeline stand-in traversal", &[])?;
    if spec.exact {
        crate::no_contraction::forbid_contraction(&words, "rt-pipeline stand-in traversal")
    } else {
        Ok(words)
    }
}

/// What every kernel starts with: the contract's constants, the counter slots, the per-scene
/// constants, then common.wgsl (records, bindings, intersection and shading functions). Public so
/// that a test can append its own entry point and call one shared function at a time.
pub fn prelude(spec: &Specialisation) -> String {
    let counters: String = counters::WGSL.iter().map(|(name, v)| format!("const {name}: u32 = {v}u;\n")).collect();
    // Only the indexed form's kernels name it, so the default kernels' text is unchanged.
    let counters = match spec.vertices {
        Vertices::Indexed => format!("{counters}const FIRST_VERTEX: u32 = {}u;\n", spec.first_vertex),
        Vertices::Expanded => counters,
    };
    let text = format!(
        "{}{counters}const STACK_SIZE: u32 = {}u;\nconst LEAF_SIZE: u32 = {}u;\nconst WG_X: u32 = {}u;\nconst WG_Y: u32 = {}u;\n\n{}",
        render_spec::constants::wgsl_header(),
        spec.stack_size.max(1),
        spec.leaf_size.max(1),
        spec.workgroup.0,
        spec.workgroup.1,
        strip_features(COMMON, &spec.features()),
    );
    if spec.exact { text } else { with_device_rounding(&text) }
}

/// Binding number of the first of the split bindings (after common.wgsl's fixed table).
const FIRST_SPLIT_BINDING: u32 = 14;

/// With one chunk per array, `text` unchanged. Otherwise every read `nodes[i]` / `tris[i]` becomes
/// `node_at(i)` / `tri_at(i)`, which picks the binding by index range, and the extra bindings and
/// the two functions are declared.
fn split_arrays(text: &str, split: &Split, node_record: &str) -> String {
    let mut text = text.to_string();
    let mut binding = FIRST_SPLIT_BINDING;
    let mut decls = String::new();
    for (array, record, accessor, chunks, chunk) in [
        ("nodes", node_record, "node_at", split.node_chunks, split.node_chunk),
        ("tris", "Tri", "tri_at", split.tri_chunks, split.tri_chunk),
    ] {
        if chunks <= 1 {
            continue;
        }
        let chunk_const = format!("{}_CHUNK", array.to_uppercase());
        text = rewrite_indexing(&text, array, accessor);
        // The traversals bound their indices by the array's length: the whole array's, over all chunks.
        let last = chunks - 1;
        text = text.replace(
            &format!("arrayLength(&{array})"),
            &format!("({last}u * {chunk_const} + arrayLength(&{array}{last}))"),
        );
        decls += &format!(
            "const {chunk_const}: u32 = {chunk}u;
"
        );
        let mut body = String::new();
        for c in 1..chunks {
            decls += &format!(
                "@group(0) @binding({binding}) var<storage, read> {array}{c}: array<{record}>;
"
            );
            binding += 1;
        }
        // A chain of range tests: a read pays one comparison per chunk boundary below its index,
        // so a scene split in two pays one comparison more per read than the unsplit kernel.
        for c in 0..chunks - 1 {
            let name = if c == 0 { array.to_string() } else { format!("{array}{c}") };
            body += &format!(
                "    if i < {}u * {chunk_const} {{ return {name}[i - {c}u * {chunk_const}]; }}
",
                c + 1
            );
        }
        body += &format!(
            "    return {array}{last}[i - {last}u * {chunk_const}];
"
        );
        decls += &format!(
            "fn {accessor}(i: u32) -> {record} {{
{body}}}
"
        );
    }
    if decls.is_empty() {
        text
    } else {
        format!(
            "{text}
{decls}"
        )
    }
}

/// `array[expr]` (with `array` a whole word) as `accessor(expr)`, brackets matched.
fn rewrite_indexing(text: &str, array: &str, accessor: &str) -> String {
    let pattern = format!("{array}[");
    let mut out = String::with_capacity(text.len());
    let mut rest = text;
    while let Some(at) = rest.find(&pattern) {
        let word_start = at == 0 || !rest[..at].ends_with(|c: char| c.is_alphanumeric() || c == '_');
        out += &rest[..at];
        if !word_start {
            out += &pattern;
            rest = &rest[at + pattern.len()..];
            continue;
        }
        let inner = &rest[at + pattern.len()..];
        let mut depth = 1;
        let end = inner
            .char_indices()
            .find(|&(_, c)| {
                depth += match c {
                    '[' => 1,
                    ']' => -1,
                    _ => 0,
                };
                depth == 0
            })
            .map(|(i, _)| i)
            .expect("brackets in the kernel source match");
        out += &format!("{accessor}({})", rewrite_indexing(&inner[..end], array, accessor));
        rest = &inner[end + 1..];
    }
    out + rest
}

/// common.wgsl's correctly rounded division and square root (`div_rn`, `div3_rn`, `sqrt_rn` and
/// their helpers, the `EXACT` block) alone: for testing them on a device without the rest.
pub fn exact_rounding_wgsl() -> &'static str {
    let start = COMMON.find("//#if EXACT\n").expect("common.wgsl has an EXACT block");
    let len = COMMON[start..].find("//#endif").expect("the EXACT block ends");
    &COMMON[start..start + len]
}

/// Workgroup memory an SST kernel needs: the stack of whole nodes, the step (a node and a word,
/// padded to 48 bytes), the two children, the leaf cache, the votes and two flag words.
pub fn sst_shared_bytes(spec: &Specialisation) -> u64 {
    let wg = spec.workgroup.0 as u64 * spec.workgroup.1 as u64;
    32 * spec.stack_size.max(1) as u64 + 48 + 2 * 32 + 48 * spec.leaf_size.max(1) as u64 + 4 * wg + 2 * 4
}

/// The largest leaf cache, up to `spec.leaf_size` triangles, with which SST's workgroup memory
/// fits in `limit` bytes; `None` when not even one triangle fits beside the stack.
pub fn sst_leaf_cache(spec: &Specialisation, limit: u64) -> Option<u32> {
    let one = sst_shared_bytes(&Specialisation { leaf_size: 1, ..*spec });
    let more = limit.checked_sub(one)? / 48;
    Some(spec.leaf_size.max(1).min(1 + more.min(u32::MAX as u64 - 1) as u32))
}

/// Translates one kernel to SPIR-V.
pub fn compile(stage: Stage, spec: &Specialisation) -> Result<Vec<u32>, VkError> {
    compile_half(stage, spec, Half::Collect)
}

/// Translates one kernel to SPIR-V; `half` matters for rt-pipeline only.
pub fn compile_half(stage: Stage, spec: &Specialisation, half: Half) -> Result<Vec<u32>, VkError> {
    let label = match (spec.method, half) {
        (Method::RtPipeline, Half::Emit) => format!("{} {:?} kernel (ray half)", spec.method.name(), stage),
        _ => format!("{} {:?} kernel", spec.method.name(), stage),
    };
    let text = source_half(stage, spec, half);
    let words = if spec.method == Method::SstSubgroup || spec.persistent_stage(stage) {
        shader::translate_with_subgroups(&text, &label, &[])?
    } else {
        shader::translate(&text, &label, &[])?
    };
    if spec.exact { crate::no_contraction::forbid_contraction(&words, &label) } else { Ok(words) }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(method: Method, reflection: bool, refraction: bool) -> Specialisation {
        // Smooth normals with reflection, so that both settings of each feature translate.
        let smooth = reflection;
        Specialisation { reflection, refraction, smooth, ..Specialisation::every_feature(method) }
    }

    #[test]
    fn every_kernel_translates_for_every_specialisation() {
        for method in Method::ALL {
            for (r, t) in [(false, false), (true, false), (false, true), (true, true)] {
                for stage in [
                    Stage::Cast,
                    Stage::Primary,
                    Stage::Shade,
                    Stage::Bounce,
                    Stage::Convert,
                    Stage::Ao,
                    Stage::Diffuse,
                ] {
                    let s = spec(method, r, t);
                    if let Err(e) = compile(stage, &s) {
                        panic!("{method:?} {stage:?} reflection {r} refraction {t}: {e:?}");
                    }
                    if method == Method::RtPipeline
                        && let Err(e) = compile_half(stage, &s, Half::Emit)
                    {
                        panic!("{method:?} {stage:?} ray half, reflection {r} refraction {t}: {e:?}");
                    }
                }
            }
            // The accuracy variants, exact or not.
            for (intersect, fixed_offset, exact) in [
                (Intersect::MollerTrumbore, false, false),
                (Intersect::Watertight, true, false),
                (Intersect::MollerTrumbore, true, true),
            ] {
                for stage in [Stage::Cast, Stage::Bounce] {
                    let s = Specialisation { intersect, fixed_offset, exact, ..spec(method, true, true) };
                    if let Err(e) = compile(stage, &s) {
                        panic!("{method:?} {stage:?} {intersect:?} fixed offset {fixed_offset} exact {exact}: {e:?}");
                    }
                }
            }
        }
    }

    /// The ray-list, self-hit and indexed-vertex variants translate for every method and stage;
    /// the default kernels carry none of their code; and every read of a triangle goes through
    /// `fetch_tri`, the one place that knows the vertex form.
    #[test]
    fn the_test_and_memory_variants_translate_and_the_default_has_none_of_their_code() {
        const STAGES_ALL: [Stage; 7] =
            [Stage::Cast, Stage::Primary, Stage::Shade, Stage::Bounce, Stage::Convert, Stage::Ao, Stage::Diffuse];
        for method in Method::ALL {
            for stage in STAGES_ALL {
                for (ray_list, self_hits, vertices) in [
                    (true, false, Vertices::Expanded),
                    (false, true, Vertices::Expanded),
                    (false, false, Vertices::Indexed),
                    (true, true, Vertices::Indexed),
                ] {
                    let s = Specialisation {
                        ray_list,
                        self_hits,
                        vertices,
                        first_vertex: 1000,
                        ..spec(method, true, true)
                    };
                    if let Err(e) = compile(stage, &s) {
                        panic!("{method:?} {stage:?} ray list {ray_list} self-hits {self_hits} {vertices:?}: {e:?}");
                    }
                    let text = source(stage, &s);
                    let body = &text[text.find("fn fetch_tri(").expect("fetch_tri")..];
                    let body_end = body.find("\n}\n").expect("fetch_tri ends");
                    let outside = text.replace(&body[..body_end], "");
                    let bypass = outside
                        .match_indices("tris[")
                        .any(|(at, _)| !outside[..at].ends_with(|c: char| c.is_alphanumeric() || c == '_'));
                    assert!(!bypass, "{method:?} {stage:?}: a triangle read bypasses fetch_tri");
                }
                let plain = source(stage, &spec(method, true, true));
                assert!(!plain.contains("SLOT_SELF_") || !plain.contains("count(SLOT_SELF_"), "{method:?} {stage:?}");
                assert!(!plain.contains("given.origin") && !plain.contains("FIRST_VERTEX"), "{method:?} {stage:?}");
                assert!(
                    plain.contains("fn fetch_tri(i: u32) -> Tri {\n    return tris[i];\n}"),
                    "{method:?} {stage:?}"
                );
            }
        }
        let indexed = source(
            Stage::Cast,
            &Specialisation { vertices: Vertices::Indexed, first_vertex: 77, ..spec(Method::Lst, false, false) },
        );
        assert!(indexed.contains("const FIRST_VERTEX: u32 = 77u;") && indexed.contains("tris: array<vec4<u32>>"));
    }

    #[test]
    fn the_default_kernel_has_no_code_of_the_other_accuracy_variants() {
        let plain = source(Stage::Bounce, &spec(Method::Lst, true, true));
        assert!(plain.contains("fn intersect_watertight") && !plain.contains("fn intersect_moller_trumbore"));
        assert!(plain.contains("return offset_origin(p, n);") && !plain.contains("frame.sample.w;"));
        let s = Specialisation {
            intersect: Intersect::MollerTrumbore,
            fixed_offset: true,
            ..spec(Method::Lst, true, true)
        };
        let variant = source(Stage::Bounce, &s);
        assert!(
            variant.contains("return intersect_moller_trumbore(") && !variant.contains("return intersect_watertight(")
        );
        assert!(variant.contains("return p + n * frame.sample.w;") && !variant.contains("return offset_origin(p, n);"));
    }

    #[test]
    fn sst_leaf_cache_takes_the_workgroup_memory_the_stack_leaves() {
        let spec = Specialisation { stack_size: 1, leaf_size: 1000, ..Specialisation::every_feature(Method::Sst) };
        // 32 (stack) + 48 (step) + 64 (children) + 256 (votes of 8x8) + 8 (flags) + 48 per triangle.
        assert_eq!(sst_shared_bytes(&Specialisation { leaf_size: 1, ..spec }), 456);
        assert_eq!(sst_leaf_cache(&spec, 48 * 1024), Some(1000), "the whole leaf in 48 KiB");
        assert_eq!(sst_leaf_cache(&spec, 32 * 1024), Some(1 + (32768 - 456) / 48));
        let deep = Specialisation { stack_size: 1010, ..spec };
        assert_eq!(sst_shared_bytes(&Specialisation { leaf_size: 1, ..deep }), 32 * 1010 + 424);
        // The stack and one triangle take 32744 bytes; the 24 left hold no second triangle.
        assert_eq!(sst_leaf_cache(&deep, 32 * 1024), Some(1));
        assert_eq!(sst_leaf_cache(&Specialisation { stack_size: 1011, ..spec }, 32 * 1024), None);
        assert_eq!(sst_leaf_cache(&Specialisation { leaf_size: 3, ..spec }, 32 * 1024), Some(3));
    }

    #[test]
    fn features_and_stack_size_follow_the_scene() {
        let s = source(Stage::Bounce, &spec(Method::Lst, true, false));
        assert!(s.contains("const STACK_SIZE: u32 = 23u;"));
        assert!(s.contains("reflect_dir(r.d, s.shading)") && !s.contains("1.0 / m.kt_ior.y"));
        let s = source(Stage::Bounce, &spec(Method::Lst, false, true));
        assert!(s.contains("1.0 / m.kt_ior.y") && !s.contains("factor = m.ks_kr.w"));
        let s = source(Stage::Bounce, &spec(Method::Lst, false, false));
        assert!(!s.contains("1.0 / m.kt_ior.y") && !s.contains("factor = m.ks_kr.w"));
        assert!(source(Stage::Primary, &spec(Method::Stackless, false, false)).contains("arrayLength(&nodes)"));
    }

    /// Every shared constant reaches the kernels with exactly the Rust value, as naga reads it.
    #[test]
    fn the_contract_constants_reach_the_kernels_bit_for_bit() {
        use render_spec::constants::{SHARED, Value};
        let src = source(Stage::Bounce, &spec(Method::Lst, true, true));
        let module = naga::front::wgsl::parse_str(&src).expect("the kernel parses");
        for (name, value) in SHARED {
            let c = module.constants.iter().find(|(_, c)| c.name.as_deref() == Some(*name));
            let (_, c) = c.unwrap_or_else(|| panic!("the kernel lacks {name}"));
            match (&module.global_expressions[c.init], value) {
                (naga::Expression::Literal(naga::Literal::F32(k)), Value::F32(v)) => {
                    assert_eq!(k.to_bits(), v.to_bits(), "{name}: {k} in the kernel, {v} in Rust")
                }
                (naga::Expression::Literal(naga::Literal::U32(k)), Value::U32(v)) => assert_eq!(k, v, "{name}"),
                (e, _) => panic!("{name} is {e:?} in the kernel"),
            }
        }
        // No kernel file spells a shared value itself.
        for (file, text) in [
            ("common", COMMON),
            ("lst", LST),
            ("stackless", STACKLESS),
            ("sst", SST),
            ("stages", STAGES),
            ("cwbvh", CWBVH),
        ] {
            for (name, _) in SHARED {
                assert!(!text.contains(&format!("const {name}")), "{file}.wgsl declares {name} again");
            }
        }
    }

    /// The default kernels' division and sqrt are the operators they were (the rewritten kernels
    /// were checked byte for byte against the SPIR-V from before div_rn/sqrt_rn, 160 kernels).
    #[test]
    fn the_default_kernels_divide_with_the_operators() {
        let src = "    return v * div_rn(1.0, length3(v)); // div_rn(a, b) in a comment\n\
                   let r = Ray(o, d, div3_rn(vec3<f32>(1.0), d));\n\
                   let t = div_rn(n.x * a.x + n.y, den) + sqrt_rn(dot3(v, v)) + div_rn(1.0, m.kt_ior.y);\n";
        assert_eq!(
            with_device_rounding(src),
            "    return v * (1.0 / (length3(v))); // div_rn(a, b) in a comment\n\
             let r = Ray(o, d, ((vec3<f32>(1.0)) / d));\n\
             let t = ((n.x * a.x + n.y) / den) + sqrt(dot3(v, v)) + (1.0 / m.kt_ior.y);\n"
        );
        for method in [Method::Lst, Method::Stackless, Method::Sst, Method::SstSubgroup, Method::Cwbvh] {
            let plain = source(Stage::Bounce, &spec(method, true, true));
            let code = plain.lines().map(|l| l.split("//").next().unwrap_or_default());
            assert!(code.clone().all(|l| !l.contains("_rn(")) && code.clone().any(|l| l.contains(" / ")), "{method:?}");
            assert!(!plain.contains("fn split"), "{method:?}");
            let exact = source(Stage::Bounce, &Specialisation { exact: true, ..spec(method, true, true) });
            assert!(exact.contains("fn div_rn(") && exact.contains("div_rn(1.0, length3(v))"), "{method:?}");
        }
    }

    /// rt-pipeline's first half of a stage writes the ray and stops there; its second half reads
    /// the hit; the other methods' kernels have neither.
    #[test]
    fn the_rt_pipeline_halves_split_every_tracing_stage_at_its_trace() {
        let s = spec(Method::RtPipeline, true, true);
        for stage in [Stage::Cast, Stage::Primary, Stage::Shade, Stage::Bounce, Stage::Ao, Stage::Diffuse] {
            let emit = source_half(stage, &s, Half::Emit);
            let collect = source_half(stage, &s, Half::Collect);
            assert!(emit.contains("rt_rays[rt_slot] = RtRay(") && !emit.contains("return rt_hits[rt_slot];"));
            assert!(collect.contains("return rt_hits[rt_slot];") && !collect.contains("rt_rays[rt_slot] ="));
            // The stage function of the emit half returns right after its trace() call.
            let body = &emit[emit.find(&format!("fn {}(", stage.entry())).expect("the stage")..];
            let after = &body[body.find("= trace_query(").expect("the stage traces")..];
            let next = after.lines().nth(1).expect("a line after the trace").trim();
            assert!(next.starts_with("return;"), "{stage:?}: `{next}` follows the trace in the ray half");
            assert!(!collect.contains("this half only writes the ray"));
            assert!(emit.contains("rt_slot = select(RT_NO_SLOT, pixel_index(x, y), valid);"));
        }
        for method in [Method::Lst, Method::Stackless, Method::Sst, Method::SstSubgroup, Method::Cwbvh] {
            let text = source(Stage::Bounce, &spec(method, true, true));
            assert!(!text.contains("rt_slot") && !text.contains("this half only writes the ray"), "{method:?}");
        }
    }

    /// cwbvh's kernels read the node binding as wide records, every other method's as binary
    /// nodes; the triangle test and leaf loop are the shared ones (no copy in cwbvh.wgsl).
    #[test]
    fn cwbvh_reads_wide_nodes_through_the_shared_leaf_code() {
        assert_eq!(COMMON.matches(BINARY_NODES).count(), 1, "common.wgsl declares the node array once");
        let wide = source(Stage::Bounce, &spec(Method::Cwbvh, true, true));
        assert!(wide.contains(WIDE_NODES) && !wide.contains(BINARY_NODES));
        assert!(wide.contains("const STACK_SIZE: u32 = 23u;"));
        for method in [Method::Lst, Method::Stackless, Method::Sst, Method::SstSubgroup] {
            let text = source(Stage::Bounce, &spec(method, true, true));
            assert!(text.contains(BINARY_NODES) && !text.contains("WideNode"), "{method:?}");
        }
        for shared in ["fn intersect", "fn slab", "fn edge_function", "tris["] {
            assert!(!CWBVH.contains(shared), "cwbvh.wgsl has its own `{shared}`");
        }
        assert!(CWBVH.contains("intersect_leaf(") && CWBVH.contains("slab("));
    }

    /// The persistent kernels translate for every tracing stage of the methods that walk in
    /// steps, with every variant that changes the stages' text, split bindings included; the plain
    /// kernels have none of the persistent driver, and a method that cannot walk in steps keeps its
    /// plain kernels whatever the setting.
    #[test]
    fn persistent_kernels_translate_and_the_plain_ones_have_none_of_their_code() {
        let split = Split { node_chunks: 2, node_chunk: 1000, tri_chunks: 2, tri_chunk: 700 };
        for method in [Method::Lst, Method::Stackless] {
            for stage in [Stage::Cast, Stage::Primary, Stage::Shade, Stage::Bounce, Stage::Ao, Stage::Diffuse] {
                for (ray_list, self_hits, split) in [(false, false, Split::NONE), (true, true, split)] {
                    let s = Specialisation {
                        persistent: Persistent::On,
                        ray_list,
                        self_hits,
                        split,
                        ..spec(method, true, true)
                    };
                    assert!(s.persistent_stage(stage));
                    let text = source(stage, &s);
                    assert!(
                        text.contains("fn persistent()") && text.contains("    persistent();"),
                        "{method:?} {stage:?}"
                    );
                    compile(stage, &s).unwrap_or_else(|e| panic!("{method:?} {stage:?} ray list {ray_list}: {e}"));
                }
                let plain = source(stage, &spec(method, true, true));
                assert!(!plain.contains("fn persistent(") && !plain.contains("subgroupAdd("), "{method:?} {stage:?}");
            }
            let convert = Specialisation { persistent: Persistent::On, ..spec(method, true, true) };
            assert!(!convert.persistent_stage(Stage::Convert));
            assert!(!source(Stage::Convert, &convert).contains("fn persistent("));
        }
        for method in [Method::Sst, Method::SstSubgroup, Method::RtPipeline, Method::Cwbvh] {
            let s = Specialisation { persistent: Persistent::On, ..spec(method, true, true) };
            assert!(!s.persistent_stage(Stage::Cast));
            assert!(!source(Stage::Cast, &s).contains("fn persistent("), "{method:?}");
        }
    }

    /// `--persistent auto` runs the AO and diffuse stages persistently with 16 idle lanes before
    /// a refill and every other stage plain; `on` runs every tracing stage with 8, `off` none;
    /// an explicit refill overrides either; the methods that do not walk in steps stay plain.
    #[test]
    fn auto_runs_the_incoherent_stages_persistently_and_the_coherent_ones_plain() {
        let tracing = [Stage::Cast, Stage::Primary, Stage::Shade, Stage::Bounce, Stage::Ao, Stage::Diffuse];
        for method in Method::ALL {
            let with = |persistent, refill| Specialisation { persistent, refill, ..spec(method, true, true) };
            let walks = matches!(method, Method::Lst | Method::Stackless);
            for stage in tracing.into_iter().chain([Stage::Convert]) {
                let incoherent = matches!(stage, Stage::Ao | Stage::Diffuse);
                assert!(!with(Persistent::Off, None).persistent_stage(stage), "{method:?} {stage:?} off");
                assert_eq!(
                    with(Persistent::On, None).persistent_stage(stage),
                    walks && stage != Stage::Convert,
                    "{method:?} {stage:?} on"
                );
                assert_eq!(
                    with(Persistent::Auto, Some(3)).persistent_stage(stage),
                    walks && incoherent,
                    "{method:?} {stage:?} auto"
                );
                let source = source(stage, &with(Persistent::Auto, None));
                assert_eq!(source.contains("fn persistent("), walks && incoherent, "{method:?} {stage:?}");
                if walks && incoherent {
                    assert!(source.contains("const REFILL_IDLE: u32 = 16u;"), "{method:?} {stage:?}");
                }
            }
            assert!(with(Persistent::Auto, None).any_persistent() == walks);
            assert!(!with(Persistent::Off, Some(16)).any_persistent());
        }
        let lst = |persistent, refill| Specialisation { persistent, refill, ..spec(Method::Lst, true, true) };
        assert_eq!(lst(Persistent::On, None).refill_idle(), DEFAULT_REFILL);
        assert_eq!(lst(Persistent::Auto, None).refill_idle(), INCOHERENT_REFILL);
        assert_eq!((DEFAULT_REFILL, INCOHERENT_REFILL), (8, 16), "the H100's measured thresholds");
        assert_eq!(lst(Persistent::On, Some(16)).refill_idle(), 16);
        assert_eq!(lst(Persistent::Auto, Some(8)).refill_idle(), 8);
        assert!(source(Stage::Ao, &lst(Persistent::Auto, Some(4))).contains("const REFILL_IDLE: u32 = 4u;"));
        assert!(source(Stage::Ao, &lst(Persistent::On, None)).contains("const REFILL_IDLE: u32 = 8u;"));
    }

    #[test]
    fn stripping_keeps_everything_outside_blocks() {
        let src = "a\n//#if X\nb\n//#endif\nc\n//#if Y\nd\n//#endif\n";
        assert_eq!(strip_features(src, &["Y"]), "a\nc\nd\n");
        assert_eq!(strip_features(src, &[]), "a\nc\n");
    }

    /// A split kernel reads nodes and triangles only through the accessors, declares one binding
    /// per extra chunk, and translates for every traversal and stage; an unsplit one is the text
    /// of the file unchanged (so the hot path of scenes that fit one binding is the same code).
    #[test]
    fn split_kernels_translate_and_unsplit_ones_are_unchanged() {
        let split = Split { node_chunks: 3, node_chunk: 1000, tri_chunks: 2, tri_chunk: 700 };
        for method in [Method::Lst, Method::Stackless, Method::Sst, Method::SstSubgroup, Method::Cwbvh] {
            for stage in [Stage::Cast, Stage::Primary, Stage::Shade, Stage::Bounce] {
                let plain = spec(method, true, true);
                let unsplit = source(stage, &plain);
                assert!(!unsplit.contains("node_at") && !unsplit.contains("tri_at"));
                let s = Specialisation { split, ..plain };
                let text = source(stage, &s);
                for read in ["nodes[", "tris[", "arrayLength(&nodes)"] {
                    let stray = text.match_indices(read).any(|(at, _)| {
                        !text[..at].ends_with(|c: char| c.is_alphanumeric() || c == '_')
                            && !text[at..].starts_with("nodes[i - ")
                            && !text[at..].starts_with("tris[i - ")
                    });
                    assert!(!stray, "{method:?} {stage:?}: a read `{read}` bypasses the accessors");
                }
                for binding in 14..14 + split.extra_bindings() {
                    assert!(text.contains(&format!("@binding({binding})")), "binding {binding}");
                }
                compile(stage, &s).unwrap_or_else(|e| panic!("{method:?} {stage:?}: {e}"));
            }
        }
        assert_eq!(split.extra_bindings(), 3);
        assert_eq!(Split::NONE.extra_bindings(), 0);
    }
}
