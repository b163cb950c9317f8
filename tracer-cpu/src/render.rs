//! Whole images: bands of rows in parallel (rayon), 4 x 2 pixel blocks shaded by the Whitted
//! driver and written straight into the 8-bit image and, when asked for, the AOVs.

use crate::Method;
use crate::bvh8::{Bvh4, Bvh8};
use crate::geometry::{Cost, Hit, MollerTrumbore, Ray, TriangleTest, Watertight};
use crate::lanes::{Mixed, OneByOne, Packets, Stage, TraceLanes};
use crate::packet::{LANES, Rays, Results};
use crate::shade;
use crate::traverse::{self, Stack};
use crate::vertices::{Indexed, Triangles};
use crate::whitted::{Block, Seeds, Shading};
use crate::wide::{F8, Lanes, V3};
use bvh_format::{Node, SceneFile, Triangle};
use rayon::prelude::*;
use render_spec::{Aovs, Frame, Image, Intersect, RayCounts, RenderError, Settings, Vertices};

/// The scene prepared for tracing: layouts, and the bounds behind the adaptive bounce stop.
pub struct Tracer<'a> {
    pub scene: &'a SceneFile,
    /// The triangles expanded to three vertices each, in leaf order (48 bytes per triangle);
    /// empty in the indexed form, which reads the file's arrays instead.
    tris: Vec<Triangle>,
    vertices: Vertices,
    child_pair: Option<&'a [Node]>,
    escape: Option<&'a [Node]>,
    /// Count the rays their own triangle meets ([`render_spec::SelfHits`], `--self-hits`).
    self_hits: bool,
    /// The wide BVH, collapsed from the child-pair layout on first use.
    wide: std::sync::OnceLock<Bvh8>,
    /// The 4-wide BVH (`--method bvh4`), likewise.
    wide4: std::sync::OnceLock<Bvh4>,
}

impl<'a> Tracer<'a> {
    /// The scene with the triangles in the expanded form ([`Vertices::Expanded`]).
    pub fn new(scene: &'a SceneFile) -> Self {
        Self::with_vertices(scene, Vertices::Expanded)
    }

    /// The scene with the triangles read in the form `vertices`: the expanded form copies them
    /// (48 bytes per triangle), the indexed form reads the file's index and vertex arrays in
    /// place. Both give the same images.
    pub fn with_vertices(scene: &'a SceneFile, vertices: Vertices) -> Self {
        Self {
            scene,
            tris: match vertices {
                Vertices::Expanded => scene.leaf_triangles(),
                Vertices::Indexed => Vec::new(),
            },
            vertices,
            child_pair: scene.child_pair.as_deref(),
            escape: scene.escape.as_deref(),
            self_hits: false,
            wide: std::sync::OnceLock::new(),
            wide4: std::sync::OnceLock::new(),
        }
    }

    /// Counts, in the images rendered after this, the shadow, secondary, AO and diffuse rays that
    /// the triangle they leave from meets (exact acne, [`render_spec::SelfHits`] in
    /// [`Image::rays`]): one more triangle test per such ray, so off by default.
    pub fn count_self_hits(&mut self, on: bool) {
        self.self_hits = on;
    }

    /// The wide BVH of the child-pair layout, collapsed on the first call (once, whichever thread
    /// asks); None for a file without that layout.
    pub fn bvh8(&self) -> Option<&Bvh8> {
        let nodes = self.child_pair?;
        Some(self.wide.get_or_init(|| Bvh8::from_source(nodes, &self.triangles())))
    }

    /// The wide BVH where [`Self::bvh8`] has collapsed it already.
    pub fn bvh8_if_made(&self) -> Option<&Bvh8> {
        self.wide.get()
    }

    /// The 4-wide BVH of the child-pair layout, collapsed on the first call; None for a file
    /// without that layout.
    pub fn bvh4(&self) -> Option<&Bvh4> {
        let nodes = self.child_pair?;
        Some(self.wide4.get_or_init(|| Bvh4::from_source(nodes, &self.triangles())))
    }

    /// Collapses the wide BVH that `method` walks on this file, where it walks one ([`Self::bvh8`]
    /// or [`Self::bvh4`]): what a render does on its first ray, done at load so that the render's
    /// time leaves it out. Returns whether one was made (or was there already).
    pub fn collapse_for(&self, method: Method) -> bool {
        match method.resolve(self.scene) {
            Method::Bvh8 | Method::Bvh8Packet | Method::Auto => self.bvh8().is_some(),
            Method::Bvh4 => self.bvh4().is_some(),
            Method::Ordered | Method::Stackless | Method::Packet => false,
        }
    }

    /// Bytes of the wide BVHs collapsed so far.
    pub fn wide_bytes(&self) -> Option<usize> {
        let sizes = [self.wide.get().map(Bvh8::bytes), self.wide4.get().map(Bvh4::bytes)];
        sizes.into_iter().flatten().reduce(|a, b| a + b)
    }

    /// The triangles as every path intersects them, in leaf order, in the form this tracer
    /// was made with.
    pub fn triangles(&self) -> Triangles<'_> {
        match self.vertices {
            Vertices::Expanded => Triangles::Expanded(&self.tris),
            Vertices::Indexed => Triangles::Indexed(Indexed::new(self.scene)),
        }
    }

    /// Bytes of scene data this tracer holds: the file as read ([`crate::file_bytes`]), the
    /// expanded triangles where it made them, and the wide BVHs where they were collapsed.
    pub fn held_bytes(&self) -> u64 {
        crate::file_bytes(self.scene)
            + std::mem::size_of_val(&self.tris[..]) as u64
            + self.wide_bytes().unwrap_or(0) as u64
    }

    /// The scalar traversal `method` names, bound to the layout it reads: the child-pair layout
    /// for [`Method::Ordered`] and [`Method::Packet`], the escape-pointer layout for
    /// [`Method::Stackless`], the wide BVH collapsed from the child-pair layout for
    /// [`Method::Bvh8`] and the single rays of [`Method::Auto`], the 4-wide one for
    /// [`Method::Bvh4`], and for [`Method::Auto`] on a
    /// file with only the escape-pointer layout, the stackless walk. A method
    /// whose layout the file lacks is refused here ([`RenderError::MissingLayout`]), never walked
    /// on the other layout: the caller decides, once, which traversal its rays take.
    pub fn walk(&self, method: Method) -> Result<Walk<'_>, RenderError> {
        let resolved = method.resolve(self.scene);
        let missing = |layout| RenderError::MissingLayout { method: resolved.name(), layout };
        let layout = match resolved {
            Method::Stackless => Layout::Escape(self.escape.ok_or_else(|| missing("escape-pointer"))?),
            // Auto's rays one at a time: the wide BVH.
            Method::Bvh8 | Method::Bvh8Packet | Method::Auto => {
                Layout::Wide(self.bvh8().ok_or_else(|| missing("child-pair"))?)
            }
            Method::Bvh4 => Layout::Wide4(self.bvh4().ok_or_else(|| missing("child-pair"))?),
            Method::Ordered | Method::Packet => {
                Layout::ChildPair(self.child_pair.ok_or_else(|| missing("child-pair"))?)
            }
        };
        Ok(Walk { tracer: self, layout })
    }
}

/// The node layout a [`Walk`] reads.
#[derive(Clone, Copy)]
enum Layout<'a> {
    ChildPair(&'a [Node]),
    Escape(&'a [Node]),
    Wide(&'a Bvh8),
    Wide4(&'a Bvh4),
}

/// A scalar traversal bound to its tracer and to the layout it walks, made by [`Tracer::walk`]
/// (which refuses a method whose layout the file lacks).
#[derive(Clone, Copy)]
pub struct Walk<'t> {
    tracer: &'t Tracer<'t>,
    layout: Layout<'t>,
}

impl<'t> Walk<'t> {
    pub fn tracer(&self) -> &'t Tracer<'t> {
        self.tracer
    }

    /// The traversal this walk runs: [`Method::Ordered`] on the child-pair layout,
    /// [`Method::Stackless`] on the escape-pointer layout, [`Method::Bvh8`] on the wide BVH or
    /// [`Method::Bvh4`] on the 4-wide one.
    pub fn method(&self) -> Method {
        match self.layout {
            Layout::ChildPair(_) => Method::Ordered,
            Layout::Escape(_) => Method::Stackless,
            Layout::Wide(_) => Method::Bvh8,
            Layout::Wide4(_) => Method::Bvh4,
        }
    }

    /// The wide BVH, where this walk reads it and this CPU runs packets on it
    /// ([`crate::packet8::available`]): what `--method bvh8-packet` and auto's packets trace.
    pub(crate) fn packet_bvh8(&self) -> Option<&'t Bvh8> {
        match self.layout {
            Layout::Wide(bvh) if crate::packet8::available() => Some(bvh),
            Layout::Wide(_) | Layout::ChildPair(_) | Layout::Escape(_) | Layout::Wide4(_) => None,
        }
    }

    /// The child-pair nodes, where this walk reads them (what packets trace).
    pub(crate) fn child_pair(&self) -> Option<&'t [Node]> {
        match self.layout {
            Layout::ChildPair(nodes) => Some(nodes),
            Layout::Escape(_) | Layout::Wide(_) | Layout::Wide4(_) => None,
        }
    }

    /// Closest hit in `(t_min, t_max]` with the default (watertight) triangle test; adds the work
    /// done to `cost`.
    #[inline]
    pub fn closest(&self, ray: &Ray, t_min: f32, t_max: f32, stack: &mut Stack, cost: &mut Cost) -> Option<Hit> {
        self.closest_with(Intersect::Watertight, ray, t_min, t_max, stack, cost)
    }

    /// [`Self::closest`] with the triangle test `test`.
    #[inline]
    pub fn closest_with(
        &self,
        test: Intersect,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        stack: &mut Stack,
        cost: &mut Cost,
    ) -> Option<Hit> {
        match test {
            Intersect::Watertight => self.trace::<false, Watertight>(ray, t_min, t_max, stack, cost),
            Intersect::MollerTrumbore => self.trace::<false, MollerTrumbore>(ray, t_min, t_max, stack, cost),
        }
    }

    /// Whether anything lies in `(0, t_max]` along the ray, with the default (watertight) test.
    #[inline]
    pub fn occluded(&self, ray: &Ray, t_max: f32, stack: &mut Stack, cost: &mut Cost) -> bool {
        self.occluded_with(Intersect::Watertight, ray, t_max, stack, cost)
    }

    /// [`Self::occluded`] with the triangle test `test`.
    #[inline]
    pub fn occluded_with(&self, test: Intersect, ray: &Ray, t_max: f32, stack: &mut Stack, cost: &mut Cost) -> bool {
        match test {
            Intersect::Watertight => self.trace::<true, Watertight>(ray, 0.0, t_max, stack, cost),
            Intersect::MollerTrumbore => self.trace::<true, MollerTrumbore>(ray, 0.0, t_max, stack, cost),
        }
        .is_some()
    }

    /// This walk's traversal with the triangle test `T`.
    #[inline]
    pub(crate) fn trace<const ANY: bool, T: TriangleTest>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        stack: &mut Stack,
        cost: &mut Cost,
    ) -> Option<Hit> {
        // One branch per ray on the form; each form's traversal is compiled on its own.
        match (self.layout, self.tracer.triangles()) {
            (Layout::Escape(nodes), Triangles::Expanded(tris)) => {
                traverse::escape::<ANY, T>(nodes, tris, ray, t_min, t_max, cost)
            }
            (Layout::Escape(nodes), Triangles::Indexed(tris)) => {
                traverse::escape::<ANY, T>(nodes, &tris, ray, t_min, t_max, cost)
            }
            (Layout::ChildPair(nodes), Triangles::Expanded(tris)) => {
                traverse::child_pair::<ANY, T>(nodes, tris, ray, t_min, t_max, stack, cost)
            }
            (Layout::ChildPair(nodes), Triangles::Indexed(tris)) => {
                traverse::child_pair::<ANY, T>(nodes, &tris, ray, t_min, t_max, stack, cost)
            }
            // The wide BVH tests its own leaf blocks, whatever the form.
            (Layout::Wide(bvh), _) => bvh.trace::<ANY, T>(ray, t_min, t_max, stack, cost),
            (Layout::Wide4(bvh), _) => bvh.trace::<ANY, T>(ray, t_min, t_max, stack, cost),
        }
    }
}

/// How the image is cut up for the workers: bands of `rows` rows are the unit of parallel work,
/// of progress and of the output slices a worker writes into; a band is traced in tiles of
/// `rows` x `columns` pixels, 4 x 2 blocks in each, so that neighbouring blocks find the same
/// nodes in the cache. Images do not depend on it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tiles {
    pub rows: usize,
    pub columns: usize,
}

impl Default for Tiles {
    /// Bands of 2 rows (one row of blocks) across the whole width, the ray report's unit of work:
    /// on one thread within a few percent of 8 x 8 tiles (`examples/tiles.rs`, dragon and bunny),
    /// and small enough that the last bands leave no core idle. Bands of 8 rows cost about twice
    /// the mean where the dragon fills the frame: from their one-thread costs, 16 workers would
    /// reach 89-98% of perfect balance with them, 98-99% with bands of 2 rows (issue 17).
    fn default() -> Self {
        Self { rows: 2, columns: usize::MAX }
    }
}

impl Tiles {
    /// Whole blocks: an even number of rows and a multiple of 4 columns, at least one block. Sizes
    /// beyond any image (`usize::MAX` for "the whole width") are cut first, so that rounding up to
    /// whole blocks cannot wrap to zero.
    fn blocks(self) -> Self {
        const BEYOND_ANY_IMAGE: usize = 1 << 30;
        let whole = |n: usize, block: usize| n.clamp(block, BEYOND_ANY_IMAGE).next_multiple_of(block);
        Self { rows: whole(self.rows, 2), columns: whole(self.columns, 4) }
    }
}

/// Renders an image with `method`. Pixels are independent, so the result does not depend on the
/// thread count.
pub fn render(tracer: &Tracer<'_>, settings: &Settings, method: Method) -> Result<Image, RenderError> {
    render_with_progress(tracer, settings, method, &|_| {})
}

/// [`render`], calling `progress` with the number of rows finished each time a band of rows is
/// done (from any worker thread): [`plan`], then [`render_into`] a fresh [`Canvas`].
pub fn render_with_progress(
    tracer: &Tracer<'_>,
    settings: &Settings,
    method: Method,
    progress: &(dyn Fn(u32) + Sync),
) -> Result<Image, RenderError> {
    let plan = plan(tracer, settings, method)?;
    render_into(tracer, settings, &plan, Canvas::new(settings), progress)
}

/// The buffers a frame is written into: the 8-bit image and, when the settings ask for them, the
/// AOVs. Made before the frame, so that a caller can page them in before its clock starts
/// ([`Canvas::page_in`]), as the ray report's output is before its passes.
pub struct Canvas {
    width: u32,
    height: u32,
    rgb: Vec<[u8; 3]>,
    aov: Option<Aovs>,
}

impl Canvas {
    /// Zeroed buffers for a frame of `settings` (the pages are mapped when first written).
    pub fn new(settings: &Settings) -> Self {
        let n = settings.width as usize * settings.height as usize;
        Canvas {
            width: settings.width,
            height: settings.height,
            rgb: vec![[0; 3]; n],
            aov: settings.aovs.then(|| Aovs {
                t: vec![0.0; n],
                normal: vec![[0.0; 3]; n],
                prim: vec![0; n],
                nodes: vec![0; n],
                tris: vec![0; n],
            }),
        }
    }

    /// Bytes of the buffers.
    pub fn bytes(&self) -> usize {
        let aov = self.aov.as_ref().map_or(0, |a| {
            std::mem::size_of_val(&a.t[..])
                + std::mem::size_of_val(&a.normal[..])
                + std::mem::size_of_val(&a.prim[..])
                + std::mem::size_of_val(&a.nodes[..])
                + std::mem::size_of_val(&a.tris[..])
        });
        std::mem::size_of_val(&self.rgb[..]) + aov
    }

    /// Writes every page of the buffers on the current thread pool, so that the frame does not
    /// take the page faults of fresh memory (a few microseconds each in a VM: 2000 of them for a
    /// 1920 x 1440 image, 12 000 at 4096 x 4096).
    pub fn page_in(&mut self) {
        fn touch<T: Copy + Default + Send>(v: &mut [T]) {
            const PAGE: usize = 4096;
            let step = (PAGE / std::mem::size_of::<T>().max(1)).max(1);
            v.par_chunks_mut(step * 64).for_each(|chunk| {
                for x in chunk.iter_mut().step_by(step) {
                    // Through black_box: a store of zero into memory known to be zeroed could
                    // otherwise be dropped.
                    *std::hint::black_box(x) = T::default();
                }
            });
        }
        touch(&mut self.rgb);
        if let Some(a) = &mut self.aov {
            touch(&mut a.t);
            touch(&mut a.normal);
            touch(&mut a.prim);
            touch(&mut a.nodes);
            touch(&mut a.tris);
        }
    }

    /// The buffers of a frame rendered before, to render the next frame into without fresh
    /// memory (a benchmark's repeated frames, as the ray report reuses its output): every pixel
    /// of the image and of the AOVs is written again, so what they held does not show.
    pub fn reuse(image: Image) -> Self {
        Canvas { width: image.width, height: image.height, rgb: image.rgb, aov: image.aov }
    }

    /// Whether these buffers are a frame of `settings`.
    fn fits(&self, settings: &Settings) -> bool {
        (self.width, self.height, self.aov.is_some()) == (settings.width, settings.height, settings.aovs)
    }
}

/// How a frame's rays are traced, fixed before its first pixel: the method as resolved for the
/// scene and, for [`Method::Auto`], the stages its measurement sends as packets.
#[derive(Clone, Copy)]
pub struct Plan<'t> {
    method: Method,
    walk: Walk<'t>,
    packet_stages: [bool; Stage::ALL.len()],
    measured: Option<Measurement>,
}

impl<'t> Plan<'t> {
    /// The method the frame runs ([`Method::resolve`]d for the scene).
    pub fn method(&self) -> Method {
        self.method
    }

    /// Per stage ([`Stage::index`]): whether auto sends its rays as packets.
    pub fn packet_stages(&self) -> [bool; Stage::ALL.len()] {
        self.packet_stages
    }

    /// Auto's measurement, where it took one.
    pub fn measured(&self) -> Option<&Measurement> {
        self.measured.as_ref()
    }

    /// The tracing of one worker, as the renderer makes it for this plan.
    pub fn lanes(&self) -> FrameLanes<'t> {
        match self.method {
            Method::Packet => FrameLanes::Packets(Packets::new(self.walk)),
            Method::Bvh8Packet => match self.walk.packet_bvh8() {
                Some(bvh) => FrameLanes::WidePackets(crate::packet8::Lanes::new(bvh)),
                None => FrameLanes::Single(OneByOne::new(self.walk)),
            },
            Method::Auto => FrameLanes::Mixed(Mixed::new(self.walk, self.packet_stages)),
            _ => FrameLanes::Single(OneByOne::new(self.walk)),
        }
    }

    /// The method in words, with auto's pick per measured kind of ray ("Auto (primary: packets,
    /// shadow: packets, secondary: bvh8)").
    pub fn describe(&self) -> String {
        let name = format!("{:?}", self.method);
        let Some(m) = &self.measured else { return name };
        let picks: Vec<String> = Stage::ALL
            .into_iter()
            .filter(|s| m.rays[s.index()] > 0)
            .map(|s| format!("{}: {}", s.name(), if self.packet_stages[s.index()] { "packets" } else { "bvh8" }))
            .collect();
        format!("{name} ({})", picks.join(", "))
    }
}

/// A worker's tracing for a [`Plan`] ([`Plan::lanes`]).
// Made once per worker and kept on its stack: a box would cost an indirection on every call.
#[allow(clippy::large_enum_variant)]
pub enum FrameLanes<'t> {
    Packets(Packets<'t>),
    WidePackets(crate::packet8::Lanes<'t>),
    Single(OneByOne<'t>),
    Mixed(Mixed<'t>),
}

impl TraceLanes for FrameLanes<'_> {
    fn closest(&mut self, rays: &Rays, test: Intersect) -> Results {
        match self {
            FrameLanes::Packets(l) => l.closest(rays, test),
            FrameLanes::WidePackets(l) => l.closest(rays, test),
            FrameLanes::Single(l) => l.closest(rays, test),
            FrameLanes::Mixed(l) => l.closest(rays, test),
        }
    }
    fn occluded(&mut self, rays: &Rays, test: Intersect) -> Results {
        match self {
            FrameLanes::Packets(l) => l.occluded(rays, test),
            FrameLanes::WidePackets(l) => l.occluded(rays, test),
            FrameLanes::Single(l) => l.occluded(rays, test),
            FrameLanes::Mixed(l) => l.occluded(rays, test),
        }
    }
    fn closest_in(&mut self, stage: Stage, rays: &Rays, test: Intersect) -> Results {
        match self {
            FrameLanes::Packets(l) => l.closest_in(stage, rays, test),
            FrameLanes::WidePackets(l) => l.closest_in(stage, rays, test),
            FrameLanes::Single(l) => l.closest_in(stage, rays, test),
            FrameLanes::Mixed(l) => l.closest_in(stage, rays, test),
        }
    }
    fn occluded_in(&mut self, stage: Stage, rays: &Rays, test: Intersect) -> Results {
        match self {
            FrameLanes::Packets(l) => l.occluded_in(stage, rays, test),
            FrameLanes::WidePackets(l) => l.occluded_in(stage, rays, test),
            FrameLanes::Single(l) => l.occluded_in(stage, rays, test),
            FrameLanes::Mixed(l) => l.occluded_in(stage, rays, test),
        }
    }
}

/// What `--method auto`'s measurement found, per stage ([`Stage::index`]): the sampled rays, and
/// the seconds they took one by one on the wide BVH and as packets (summed over the workers,
/// each the fastest of its rounds; for single rays that a worker stopped after their first round,
/// twice as slow as the packets' first two rounds, 1.1 times those: less than they would have
/// taken).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Measurement {
    pub rays: [u64; Stage::ALL.len()],
    pub single: [f64; Stage::ALL.len()],
    pub packets: [f64; Stage::ALL.len()],
}

impl Measurement {
    /// Packets for the stages where they took less time than single rays; single rays where
    /// nothing was sampled.
    pub fn packet_stages(&self) -> [bool; Stage::ALL.len()] {
        std::array::from_fn(|i| self.rays[i] > 0 && self.packets[i] < self.single[i])
    }

    fn add(mut self, o: Self) -> Self {
        for i in 0..Stage::ALL.len() {
            self.rays[i] += o.rays[i];
            self.single[i] += o.single[i];
            self.packets[i] += o.packets[i];
        }
        self
    }
}

/// How auto's measurement times one way of tracing one stage's sampled rays. The renderer's is
/// [`WallClock`]; tests hand in a table of costs to see that the measurement decides.
pub trait StageTimer: Sync {
    /// Runs `trace` (the `rays` sampled rays of `stage`, as packets or one by one on the wide
    /// BVH) and returns the seconds it took.
    fn time(&self, stage: Stage, packets: bool, rays: u64, trace: &mut dyn FnMut()) -> f64;
}

/// [`StageTimer`] by the wall clock.
pub struct WallClock;

impl StageTimer for WallClock {
    fn time(&self, _: Stage, _: bool, _: u64, trace: &mut dyn FnMut()) -> f64 {
        let t = std::time::Instant::now();
        trace();
        t.elapsed().as_secs_f64()
    }
}

/// Fixes how the frame's rays are traced: the method resolved for the scene (refused here when
/// the file lacks its layout), and for [`Method::Auto`] a short measurement on the current thread
/// pool ([`plan_with`] by the wall clock).
pub fn plan<'t>(tracer: &'t Tracer<'t>, settings: &Settings, method: Method) -> Result<Plan<'t>, RenderError> {
    plan_with(tracer, settings, method, &WallClock)
}

/// [`plan`] with `timer` timing auto's measurement: the frame's own rays at up to 256 of its
/// 4 x 2 pixel blocks spread evenly over the image are shaded once as the renderer shades them,
/// every call of each stage (primary, shadow, secondary, AO or diffuse rays) recorded; then the
/// workers (16 chunks, each every 16th block) time each stage's calls one by one on the wide BVH
/// and as packets on it ([`crate::packet8`]; the binary tree's packets, `--method packet`, are
/// slower on nearly every kind of ray, docs/cpu-benchmark.md): packets 3 rounds (the first warms
/// them up; the recording pass has warmed the single rays), single rays up to 3 until one way has
/// taken more than 1.3 times the other's time, but only one where it took twice the packets' first
/// two, stopped there and counted as 1.1 times them (about half a millisecond of work on one
/// thread, spread over the pool). Each way's time is the fastest of its rounds, and each stage
/// goes the way that took less time summed over the workers. Images do not depend on it: every
/// way finds the same hits.
pub fn plan_with<'t>(
    tracer: &'t Tracer<'t>,
    settings: &Settings,
    method: Method,
    timer: &dyn StageTimer,
) -> Result<Plan<'t>, RenderError> {
    let resolved = method.resolve(tracer.scene);
    let walk = tracer.walk(resolved)?;
    let mut plan = Plan { method: resolved, walk, packet_stages: [false; 5], measured: None };
    if resolved == Method::Auto && walk.packet_bvh8().is_some() {
        let m = measure(tracer, settings, walk, timer)?;
        plan.packet_stages = m.packet_stages();
        plan.measured = Some(m);
    }
    Ok(plan)
}

/// Auto's measurement ([`plan_with`]).
fn measure(
    tracer: &Tracer<'_>,
    settings: &Settings,
    wide: Walk<'_>,
    timer: &dyn StageTimer,
) -> Result<Measurement, RenderError> {
    let frame = settings.frame()?;
    let sh = Shading::new(tracer, settings).with_self_hits(false);
    let sample = render_spec::accuracy::sample_positions(settings.accuracy.spp).next().unwrap_or((0.5, 0.5));
    let (w, h) = (settings.width as usize, settings.height as usize);
    const GRID: usize = 16;
    let mut blocks = Vec::with_capacity(GRID * GRID);
    for gy in 0..GRID.min(h.div_ceil(2)) {
        for gx in 0..GRID.min(w.div_ceil(4)) {
            blocks.push(((gx * w / GRID) & !3, (gy * h / GRID) & !1));
        }
    }
    let test = settings.accuracy.intersect;
    // Chunk c takes every CHUNKS-th block from the c-th: each chunk a sample of the whole image, so
    // that chunks cost about the same (a row of the grid, the sky's or the object's, did not) and
    // the measurement's wall time on as many workers is about one chunk's share.
    const CHUNKS: usize = 16;
    let chunks = CHUNKS.min(blocks.len());
    Ok((0..chunks)
        .into_par_iter()
        .map(|c| {
            let mut record = Recorder { inner: OneByOne::new(wide), calls: Vec::new() };
            for &(x0, y0) in blocks.iter().skip(c).step_by(chunks) {
                let (rays, seeds, ..) = primary_block::<F8>(&frame, w, h, x0, y0, sample, sh.seeded());
                sh.block::<F8, _>(&rays, &seeds, &mut record);
            }
            let mut single = Mixed::new(wide, [false; 5]);
            let mut packets = Mixed::new(wide, [true; 5]);
            let mut m = Measurement::default();
            for stage in Stage::ALL {
                let calls: Vec<&Call> = record.calls.iter().filter(|c| c.stage == stage).collect();
                let rays: u64 = calls.iter().map(|c| c.rays.count() as u64).sum();
                if rays == 0 {
                    continue;
                }
                let run = |lanes: &mut Mixed<'_>, calls: &[&Call]| {
                    for c in calls {
                        std::hint::black_box(if c.any {
                            lanes.occluded_in(stage, &c.rays, test)
                        } else {
                            lanes.closest_in(stage, &c.rays, test)
                        });
                    }
                };
                let mut packet_round = || timer.time(stage, true, rays, &mut || run(&mut packets, &calls));
                // Single rays in slices; None once they pass `limit`.
                let mut single_round = |limit: f64| {
                    let mut t = 0.0;
                    for part in calls.chunks(calls.len().div_ceil(SLICES)) {
                        let rays = part.iter().map(|c| c.rays.count() as u64).sum();
                        t += timer.time(stage, false, rays, &mut || run(&mut single, part));
                        if t > limit {
                            return None;
                        }
                    }
                    Some(t)
                };
                // Packets' first round runs cold, 2-4 times slower than the next (the recording
                // traced single rays on the wide BVH; the other stages have been through the
                // caches since): it warms up, and packets get 3 rounds, so that one preempted
                // round does not count. Single rays, 2-4 times slower than packets on most
                // stages, run only until they have taken STOP times the packets' two rounds.
                // Their first round, after the packets', can itself run cold (AO and diffuse
                // rays: a third slower on average, more on some workers) or be preempted, so
                // single rays stopped there count as just BEHIND the packets. Otherwise they get
                // up to 3 rounds, until one way is clearly ahead.
                let two = packet_round().min(packet_round());
                let first = single_round(STOP * two);
                let t_packets = two.min(packet_round());
                let behind = first.is_none_or(|t| t > STOP * t_packets);
                let mut t_single = match first {
                    Some(t) if !behind => t,
                    _ => BEHIND * two,
                };
                // The way ahead by a clear margin needs one round beside the first to trust it.
                for round in 1..3 {
                    if behind || clearly_apart(t_single, t_packets) && (round > 1 || t_single > t_packets) {
                        break;
                    }
                    t_single = t_single.min(single_round(f64::INFINITY).unwrap_or(f64::INFINITY));
                }
                let i = stage.index();
                (m.rays[i], m.single[i], m.packets[i]) = (rays, t_single, t_packets);
            }
            m
        })
        .reduce(Measurement::default, Measurement::add))
}

/// The slices a round of single rays is timed in, so that it can stop once clearly behind.
const SLICES: usize = 8;

/// How many times the other's time one way must take to be clearly behind: more than the spread
/// of repeated warm timings of the same way, so that more rounds would not change auto's pick.
const APART: f64 = 1.3;

/// How many times the packets' time single rays' first round must take to stop there.
const STOP: f64 = 2.0;

/// How many times the packets' time single rays stopped after their first round count as: a
/// lower bound where that round ran cold, up to STOP / BEHIND times slower than the next.
const BEHIND: f64 = 1.1;

fn clearly_apart(a: f64, b: f64) -> bool {
    a.max(b) > APART * a.min(b)
}

/// One call of the Whitted driver, as auto's measurement records it.
struct Call {
    stage: Stage,
    any: bool,
    rays: Rays,
}

/// Traces through `inner` and keeps every call.
struct Recorder<T> {
    inner: T,
    calls: Vec<Call>,
}

impl<T: TraceLanes> TraceLanes for Recorder<T> {
    fn closest(&mut self, rays: &Rays, test: Intersect) -> Results {
        self.closest_in(Stage::Primary, rays, test)
    }
    fn occluded(&mut self, rays: &Rays, test: Intersect) -> Results {
        self.occluded_in(Stage::Shadow, rays, test)
    }
    fn closest_in(&mut self, stage: Stage, rays: &Rays, test: Intersect) -> Results {
        self.calls.push(Call { stage, any: false, rays: *rays });
        self.inner.closest_in(stage, rays, test)
    }
    fn occluded_in(&mut self, stage: Stage, rays: &Rays, test: Intersect) -> Results {
        self.calls.push(Call { stage, any: true, rays: *rays });
        self.inner.occluded_in(stage, rays, test)
    }
}

/// Renders a frame of `settings` the way `plan` (from [`plan`]) says into `canvas` (one made
/// for other settings is replaced by a fresh one).
pub fn render_into(
    tracer: &Tracer<'_>,
    settings: &Settings,
    plan: &Plan<'_>,
    canvas: Canvas,
    progress: &(dyn Fn(u32) + Sync),
) -> Result<Image, RenderError> {
    let tiles = Tiles::default();
    let avx = crate::packet::available();
    let (walk, method) = (plan.walk, plan.method);
    // Each way of tracing compiled into the loop of its own (what [`Plan::lanes`] makes).
    match method {
        Method::Packet => render_in(tracer, settings, method, || Packets::new(walk), tiles, progress, avx, canvas),
        Method::Bvh8Packet => match walk.packet_bvh8() {
            Some(bvh) => {
                render_in(tracer, settings, method, || crate::packet8::Lanes::new(bvh), tiles, progress, avx, canvas)
            }
            None => render_in(tracer, settings, method, || OneByOne::new(walk), tiles, progress, avx, canvas),
        },
        Method::Auto => {
            let stages = plan.packet_stages;
            render_in(tracer, settings, method, || Mixed::new(walk, stages), tiles, progress, avx, canvas)
        }
        _ => render_in(tracer, settings, method, || OneByOne::new(walk), tiles, progress, avx, canvas),
    }
}

/// One band of rows and the part of every output it covers.
struct Band<'a> {
    y0: usize,
    rgb: &'a mut [[u8; 3]],
    aov: Option<AovRows<'a>>,
}

struct AovRows<'a> {
    t: &'a mut [f32],
    normal: &'a mut [[f32; 3]],
    prim: &'a mut [u32],
    nodes: &'a mut [u32],
    tris: &'a mut [u32],
}

/// Splits the outputs into bands of `rows` rows of `w` pixels.
fn bands<'a>(w: usize, rows: usize, rgb: &'a mut [[u8; 3]], aov: Option<&'a mut Aovs>) -> Vec<Band<'a>> {
    let n = rows * w;
    let mut aovs: Vec<Option<AovRows<'a>>> = match aov {
        Some(a) => {
            a.t.chunks_mut(n)
                .zip(a.normal.chunks_mut(n))
                .zip(a.prim.chunks_mut(n))
                .zip(a.nodes.chunks_mut(n))
                .zip(a.tris.chunks_mut(n))
                .map(|((((t, normal), prim), nodes), tris)| Some(AovRows { t, normal, prim, nodes, tris }))
                .collect()
        }
        None => Vec::new(),
    };
    aovs.resize_with(rgb.len().div_ceil(n), || None);
    rgb.chunks_mut(n).zip(aovs).enumerate().map(|(i, (rgb, aov))| Band { y0: i * rows, rgb, aov }).collect()
}

/// A frame with the rays of every stage traced by a [`TraceLanes`] made once per worker by
/// `lanes` (benchmarks wrap the renderer's own to see what it traces), in `tiles`. `method` is
/// the one `lanes` traces with: the layout it reads must be in the file.
pub fn render_with<T: TraceLanes>(
    tracer: &Tracer<'_>,
    settings: &Settings,
    method: Method,
    lanes: impl Fn() -> T + Sync,
    tiles: Tiles,
    progress: &(dyn Fn(u32) + Sync),
) -> Result<Image, RenderError> {
    let avx = crate::packet::available();
    render_in(tracer, settings, method, lanes, tiles, progress, avx, Canvas::new(settings))
}

/// [`render_with`] into `canvas`, with AVX lanes for the shading or (`avx` false, or no AVX2)
/// plain arrays.
#[allow(clippy::too_many_arguments)]
fn render_in<T: TraceLanes>(
    tracer: &Tracer<'_>,
    settings: &Settings,
    method: Method,
    lanes: impl Fn() -> T + Sync,
    tiles: Tiles,
    progress: &(dyn Fn(u32) + Sync),
    avx: bool,
    canvas: Canvas,
) -> Result<Image, RenderError> {
    let tiles = tiles.blocks();
    let frame = settings.frame()?;
    tracer.walk(method)?;
    let (w, h) = (settings.width as usize, settings.height as usize);
    let sh = Shading::new(tracer, settings).with_self_hits(tracer.self_hits);
    let samples: Vec<(f32, f32)> = render_spec::accuracy::sample_positions(settings.accuracy.spp).collect();
    let Canvas { mut rgb, mut aov, .. } = if canvas.fits(settings) { canvas } else { Canvas::new(settings) };
    let rays = bands(w, tiles.rows, &mut rgb, aov.as_mut())
        .into_par_iter()
        .map_init(&lanes, |lanes, mut band| {
            let rays = render_band(&sh, &frame, &samples, lanes, &mut band, w, tiles.columns, avx);
            progress((band.rgb.len() / w) as u32);
            rays
        })
        .reduce(RayCounts::default, |a, b| a + b);
    debug_assert_eq!(rgb.len(), w * h);
    Ok(Image { width: settings.width, height: settings.height, rgb, aov, rays })
}

/// Renders a band: with AVX lanes when asked and the CPU has AVX2, else with plain arrays.
#[allow(clippy::too_many_arguments)]
fn render_band<T: TraceLanes>(
    sh: &Shading<'_>,
    frame: &Frame,
    samples: &[(f32, f32)],
    lanes: &mut T,
    band: &mut Band<'_>,
    w: usize,
    columns: usize,
    avx: bool,
) -> RayCounts {
    #[cfg(target_arch = "x86_64")]
    if avx && crate::packet::available() {
        // SAFETY: the CPU has AVX2 and POPCNT (checked just above).
        return unsafe { render_band_avx2(sh, frame, samples, lanes, band, w, columns) };
    }
    render_band_in::<F8, T>(sh, frame, samples, lanes, band, w, columns)
}

/// [`render_band`] compiled for AVX2, so that every lane operation of the shading is one
/// instruction, and with POPCNT, which every CPU with AVX2 has (`packet::available` checks
/// both): without it a count of lanes took a dozen instructions, about 10 per pixel.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt")]
fn render_band_avx2<T: TraceLanes>(
    sh: &Shading<'_>,
    frame: &Frame,
    samples: &[(f32, f32)],
    lanes: &mut T,
    band: &mut Band<'_>,
    w: usize,
    columns: usize,
) -> RayCounts {
    render_band_in::<crate::wide::Avx8, T>(sh, frame, samples, lanes, band, w, columns)
}

/// The band tile by tile, and each tile in 4 x 2 blocks.
#[inline(always)]
fn render_band_in<L: Lanes, T: TraceLanes>(
    sh: &Shading<'_>,
    frame: &Frame,
    samples: &[(f32, f32)],
    lanes: &mut T,
    band: &mut Band<'_>,
    w: usize,
    columns: usize,
) -> RayCounts {
    let rows = band.rgb.len() / w;
    // The blocks' rays are added up in here, and their AOVs kept (see `Shading::shade`).
    let mut out = Block::default();
    let (y0, h) = (band.y0, band.y0 + rows);
    let seeded = sh.seeded();
    // Each block's primary rays are made before the block ahead of it is traced: their square
    // roots and divisions then run beside that block's work instead of holding up its own first
    // traversal step (a tenth of the shading's samples in bunny Whitted frames where they were not).
    // They are made into the slot the block after next will not need, and the two slots trade
    // places by reference: moved from one to the other, they were copied (about 22 instructions
    // per block).
    let mut a = primary_block::<L>(frame, w, h, 0, y0, samples[0], seeded);
    let mut b = a;
    let (mut this, mut ahead) = (&mut a, &mut b);
    let mut at = (0, 0, 0);
    loop {
        let next = next_block(at, w, rows, columns);
        if let Some((nx, ny, _)) = next {
            next_primary::<L>(ahead, frame, w, h, nx, y0 + ny, samples[0], seeded);
        }
        block::<L, T>(sh, frame, samples, lanes, band, w, rows, at.0, at.1, this, &mut out);
        std::mem::swap(&mut this, &mut ahead);
        match next {
            Some(n) => at = n,
            None => break,
        }
    }
    out.rays
}

/// The block after the one at (`bx`, `dy`) of the tile whose first column is `x0`, in a band of
/// `rows` rows of `w` pixels: the next to the right in its tile of `columns` columns, else the
/// first of the tile's next row of blocks, else the first of the next tile, each with its tile's
/// first column (carried along: found again from `bx`, it took a division per block); `None`
/// after the last.
#[inline(always)]
fn next_block(
    (bx, dy, x0): (usize, usize, usize),
    w: usize,
    rows: usize,
    columns: usize,
) -> Option<(usize, usize, usize)> {
    if bx + 4 < (x0 + columns).min(w) {
        Some((bx + 4, dy, x0))
    } else if dy + 2 < rows {
        Some((x0, dy + 2, x0))
    } else if x0 + columns < w {
        Some((x0 + columns, 0, x0 + columns))
    } else {
        None
    }
}

/// `Frame::sample_direction` for the pixels (`x`, `y`) of the lanes at the sub-pixel point
/// `(sx, sy)`, operation by operation.
#[inline(always)]
fn directions<L: Lanes>(frame: &Frame, x: L, y: L, (sx, sy): (f32, f32)) -> V3<L> {
    (V3::splat(frame.top_left)
        + V3::splat(frame.h_step) * (x + L::splat(sx))
        + V3::splat(frame.v_step) * (y + L::splat(sy)))
    .normalize()
}

/// The primary rays at the sub-pixel point `sample` of the 4 x 2 block whose top-left pixel is
/// (`x0`, `y0`) in an image `w` pixels wide, whose rows end at `h` (lanes past either edge are not
/// valid), with the block's seeds (zero unless `seeded`: only the incoherent modes read them)
/// and its lanes' pixel coordinates.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn primary_block<L: Lanes>(
    frame: &Frame,
    w: usize,
    h: usize,
    x0: usize,
    y0: usize,
    sample: (f32, f32),
    seeded: bool,
) -> (Rays, Seeds, L, L) {
    let rays = Rays { origin: V3::<L>::splat(frame.eye).to_arrays(), t_max: [f32::INFINITY; LANES], ..Rays::default() };
    let mut block = (rays, Seeds::default(), L::splat(0.0), L::splat(0.0));
    next_primary(&mut block, frame, w, h, x0, y0, sample, seeded);
    block
}

/// [`primary_block`] of the block at (`x0`, `y0`) into `block`, a block of the same frame made by
/// it: the origins (the eye) and `t_max` (+inf), which every block shares, are left as they are,
/// and the rest is written in place (made apart and moved in, the whole block was copied).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn next_primary<L: Lanes>(
    block: &mut (Rays, Seeds, L, L),
    frame: &Frame,
    w: usize,
    h: usize,
    x0: usize,
    y0: usize,
    sample: (f32, f32),
    seeded: bool,
) {
    // Most blocks lie inside the image: all lanes valid without working them out.
    block.0.valid = if x0 + 4 <= w && y0 + 2 <= h { [true; LANES] } else { inside(x0, y0, w, h) };
    // At most 2^28 pixels: coordinates below 2^31.
    let (x, y) = L::block_xy(x0 as u32, y0 as u32);
    block.0.dir = directions(frame, x, y, sample).to_arrays();
    // Row-major pixel indices in the image (at most 2^28 pixels: no overflow).
    if seeded {
        let lane_xy = |i: usize| (x0 + i % 4, y0 + i / 4);
        block.1 = Seeds { pixel: std::array::from_fn(|i| (lane_xy(i).1 * w + lane_xy(i).0) as u32), sample: 0 };
    }
    (block.2, block.3) = (x, y);
}

/// The lanes of the 4 x 2 block at (`x0`, `y0`) inside an image `w` pixels wide whose rows end at
/// `h`, made in a register: stored byte by byte, the first 8-byte read of them (the packet's live
/// lanes) waited for the bytes to reach the cache instead of being forwarded from the stores.
#[inline(always)]
fn inside(x0: usize, y0: usize, w: usize, h: usize) -> [bool; LANES] {
    // One byte of 1 per column inside the image, in both rows; then the rows inside it.
    let columns = 0x0101_0101u64 >> (8 * (x0 + 4).saturating_sub(w).min(4));
    let row = |dy: usize| if y0 + dy < h { columns << (32 * dy) } else { 0 };
    // SAFETY: every byte is 0 or 1, a valid bool; lane i is byte i (little-endian x86-64 and
    // others alike: `to_le_bytes` orders them).
    unsafe { std::mem::transmute::<[u8; LANES], [bool; LANES]>((row(0) | row(1)).to_le_bytes()) }
}

/// Traces and shades the 4 x 2 block whose top-left pixel is (`bx`, `dy`) in the band at every
/// sample position, writing its pixels: the colour is the sum of the samples' linear colours in
/// their order times the f32 reciprocal of their number (a GPU multiplies exactly, where its
/// division may be off by ulps), then quantised; the distance, normal and triangle AOVs
/// are the first sample's, the cost AOVs the sum over all. `primary` is [`primary_block`]'s
/// for the block's first sample. Adds its rays to `out.rays`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn block<L: Lanes, T: TraceLanes>(
    sh: &Shading<'_>,
    frame: &Frame,
    samples: &[(f32, f32)],
    lanes: &mut T,
    band: &mut Band<'_>,
    w: usize,
    rows: usize,
    bx: usize,
    dy: usize,
    (primary, seeds, x, y): &mut (Rays, Seeds, L, L),
    out: &mut Block,
) {
    let (x, y) = (*x, *y);
    let lane_xy = |i: usize| (bx + i % 4, dy + i / 4);
    if sh.aovs() {
        let rays = out.rays;
        *out = Block { rays, ..Block::default() };
    }
    let mut colour = sh.shade::<L, T>(primary, seeds, lanes, out);
    for (k, &sample) in samples.iter().enumerate().skip(1) {
        primary.dir = directions(frame, x, y, sample).to_arrays();
        seeds.sample = k as u32;
        let more = sh.block::<L, T>(primary, seeds, lanes);
        colour = colour + V3::from_arrays(&more.colour);
        for i in 0..LANES {
            out.cost[i] += more.cost[i];
        }
        out.rays = out.rays + more.rays;
    }
    if samples.len() > 1 {
        colour = colour * (L::splat(1.0) / L::splat(samples.len() as f32));
    }
    let rgb = shade::to_rgb_rows(colour);
    if band.aov.is_none() && bx + 4 <= w && dy + 2 <= rows {
        // The whole block inside the image: two runs of 12 bytes.
        for (r, row) in rgb.iter().enumerate() {
            let p = (dy + r) * w + bx;
            band.rgb[p..p + 4].as_flattened_mut().copy_from_slice(&row[..12]);
        }
        return;
    }
    for i in 0..LANES {
        if !primary.valid[i] {
            continue;
        }
        let (x, y) = lane_xy(i);
        let p = y * w + x;
        let at = 3 * (i % 4);
        band.rgb[p] = [rgb[i / 4][at], rgb[i / 4][at + 1], rgb[i / 4][at + 2]];
        if let Some(a) = &mut band.aov {
            let n = out.normal;
            a.t[p] = out.t[i];
            a.normal[p] = [n[0][i], n[1][i], n[2][i]];
            a.prim[p] = out.prim[i];
            a.nodes[p] = out.cost[i].nodes;
            a.tris[p] = out.cost[i].tris;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use render_spec::{CameraSpec, Mode};

    /// A frame through `render_in` with `tiles` and `avx` as given: packets for `Method::Packet`,
    /// one ray at a time for the other (resolved) methods.
    fn traced_frame(
        tracer: &Tracer<'_>,
        settings: &Settings,
        method: Method,
        walk: Walk<'_>,
        tiles: Tiles,
        avx: bool,
    ) -> Result<Image, RenderError> {
        let canvas = Canvas::new(settings);
        match method {
            Method::Packet => render_in(tracer, settings, method, || Packets::new(walk), tiles, &|_| {}, avx, canvas),
            m => render_in(tracer, settings, m, || OneByOne::new(walk), tiles, &|_| {}, avx, canvas),
        }
    }

    fn same_directions<L: Lanes>() {
        let cams = [
            CameraSpec { eye: Vec3::new(0.0, 0.1, 0.3), at: Vec3::new(0.01, 0.1, 0.0), up: Vec3::Y, fov_deg: 45.0 },
            CameraSpec { eye: Vec3::new(-3e4, 2e3, 7.0), at: Vec3::ZERO, up: Vec3::new(0.1, 1.0, 0.3), fov_deg: 170.0 },
            CameraSpec { eye: Vec3::new(1.0, 2.0, 3.0), at: Vec3::new(1.0, 2.0, 2.0), up: Vec3::X, fov_deg: 0.01 },
        ];
        for cam in cams {
            for (w, h) in [(1, 1), (97, 61), (16384, 3), (3, 70000)] {
                let frame = cam.frame(w, h).unwrap();
                for (bx, by) in [(0, 0), (w.saturating_sub(4), h.saturating_sub(2)), (w / 2, h / 3)] {
                    let (x, y) = L::block_xy(bx, by);
                    for sample in render_spec::accuracy::sample_positions(9).chain([(0.5, 0.5)]) {
                        let d = directions(&frame, x, y, sample).to_arrays();
                        let got: [[f32; 3]; LANES] = std::array::from_fn(|i| [d[0][i], d[1][i], d[2][i]]);
                        for (i, got) in got.iter().enumerate() {
                            let (px, py) = (bx + i as u32 % 4, by + i as u32 / 4);
                            let want = frame.sample_direction(px, py, sample);
                            assert_eq!(got.map(f32::to_bits), want.to_array().map(f32::to_bits));
                            if sample == (0.5, 0.5) {
                                assert_eq!(got.map(f32::to_bits), frame.direction(px, py).to_array().map(f32::to_bits));
                            }
                        }
                    }
                }
            }
        }
    }

    /// `block_xy` converts as `as f32` does, beyond 2^24 too, where floats skip integers.
    fn block_coordinates<L: Lanes>() {
        for (x0, y0) in
            [(0, 0), (5, 7), ((1 << 24) - 2, (1 << 24) + 1), ((1 << 28) - 4, 3), ((1 << 31) - 8, (1 << 30) + 5)]
        {
            let (x, y) = L::block_xy(x0, y0);
            for i in 0..LANES as u32 {
                let want = ((x0 + i % 4) as usize as f32, (y0 + i / 4) as usize as f32);
                assert_eq!((x.to_array()[i as usize], y.to_array()[i as usize]), want, "{x0}, {y0}, lane {i}");
            }
        }
    }

    #[test]
    fn block_coordinates_are_the_pixels_as_floats() {
        block_coordinates::<F8>();
        #[cfg(target_arch = "x86_64")]
        if crate::packet::available() {
            block_coordinates::<crate::wide::Avx8>();
        }
    }

    #[test]
    fn lanes_inside_the_image_are_the_pixels_inside_it() {
        for (w, h) in [(1, 1), (3, 2), (4, 1), (5, 3), (8, 4), (13, 7)] {
            for x0 in 0..w + 2 {
                for y0 in 0..h + 2 {
                    let want: [bool; LANES] = std::array::from_fn(|i| x0 + i % 4 < w && y0 + i / 4 < h);
                    assert_eq!(inside(x0, y0, w, h), want, "block ({x0}, {y0}) of {w} x {h}");
                }
            }
        }
    }

    #[test]
    fn next_block_visits_the_blocks_of_a_band_in_tile_order() {
        for (w, rows) in [(1, 1), (3, 2), (4, 2), (61, 6), (64, 8), (1922, 2), (13, 7)] {
            for columns in [4, 8, 12, 1 << 30] {
                let mut want = Vec::new();
                for x0 in (0..w).step_by(columns) {
                    for dy in (0..rows).step_by(2) {
                        want.extend((x0..(x0 + columns).min(w)).step_by(4).map(|bx| (bx, dy)));
                    }
                }
                let mut got = vec![(0, 0, 0)];
                while let Some(n) = next_block(*got.last().unwrap(), w, rows, columns) {
                    got.push(n);
                }
                assert!(got.iter().all(|&(bx, _, x0)| x0 == bx / columns * columns), "{w} x {rows}: tile starts");
                let got: Vec<(usize, usize)> = got.into_iter().map(|(bx, dy, _)| (bx, dy)).collect();
                assert_eq!(got, want, "{w} x {rows} in tiles {columns} wide");
            }
        }
    }

    /// The image with AVX lanes is the image with plain arrays (the path of CPUs without AVX2),
    /// for every way of tracing the rays, and does not depend on the tiles.
    #[test]
    fn both_lane_types_render_the_same_image() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/room.toml");
        let scene = bvh_build::import::load(&path, &Default::default()).unwrap();
        let scene = bvh_build::compile(&scene, &Default::default(), Default::default()).unwrap();
        let tracer = Tracer::new(&scene);
        for mode in [Mode::Cast, Mode::Whitted] {
            for method in [Method::Packet, Method::Ordered, Method::Stackless, Method::Bvh8] {
                let settings = Settings {
                    aovs: true,
                    ..Settings::of_scene(&scene, CameraSpec::from(scene.camera("medium").unwrap()), mode, (61, 37))
                };
                let tiles = Tiles { rows: 6, columns: 12 };
                let walk = tracer.walk(method).unwrap();
                let image = |avx| traced_frame(&tracer, &settings, method.resolve(&scene), walk, tiles, avx);
                let (a, b) = (image(true).unwrap(), image(false).unwrap());
                assert_eq!(a.rgb, b.rgb, "{mode:?} {method:?}");
                for tiles in [Tiles { rows: 2, columns: usize::MAX }, Tiles { rows: usize::MAX, columns: 1 }] {
                    let other = traced_frame(&tracer, &settings, Method::Packet, walk, tiles, true);
                    assert_eq!(a.rgb, other.unwrap().rgb, "{mode:?} {method:?}: {tiles:?}");
                }
                assert_eq!(a.rgb, render(&tracer, &settings, method).unwrap().rgb, "{mode:?} {method:?}: other tiles");
                assert_eq!(a.rays, b.rays, "{mode:?} {method:?}");
                let (x, y) = (a.aov.unwrap(), b.aov.unwrap());
                assert_eq!(
                    x.t.iter().map(|t| t.to_bits()).collect::<Vec<_>>(),
                    y.t.iter().map(|t| t.to_bits()).collect::<Vec<_>>()
                );
                assert_eq!(
                    (x.normal, x.prim, x.nodes, x.tris),
                    (y.normal, y.prim, y.nodes, y.tris),
                    "{mode:?} {method:?}"
                );
                assert!(a.rays.secondary > 0 || mode == Mode::Cast, "the room has a mirror and glass");
            }
        }
    }

    #[test]
    fn block_directions_are_the_cameras_bit_for_bit() {
        same_directions::<F8>();
        #[cfg(target_arch = "x86_64")]
        same_directions::<crate::wide::Avx8>();
    }

    /// A pixel of an image with several samples per pixel is its samples' mean linear colour
    /// quantised once: each sample traced on its own (one ray, scalar lanes, the camera's own
    /// `sample_direction`), summed in order, times 1 / spp. Every method, both lane types, and
    /// whole images that differ from one sample per pixel.
    #[test]
    fn several_samples_per_pixel_are_the_mean_of_single_samples() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/room.toml");
        let scene = bvh_build::import::load(&path, &Default::default()).unwrap();
        let scene = bvh_build::compile(&scene, &Default::default(), Default::default()).unwrap();
        let tracer = Tracer::new(&scene);
        let (w, h) = (23, 14);
        for spp in [4, 9] {
            let settings = Settings {
                aovs: true,
                accuracy: render_spec::Accuracy { spp, ..Default::default() },
                ..Settings::of_scene(&scene, CameraSpec::from(scene.camera("medium").unwrap()), Mode::Whitted, (w, h))
            };
            let one = Settings { accuracy: Default::default(), ..settings.clone() };
            let frame = settings.frame().unwrap();
            let sh = Shading::new(&tracer, &settings);
            let mut lanes = OneByOne::new(tracer.walk(Method::Ordered).unwrap());
            let mut want = Vec::new();
            for y in 0..h {
                for x in 0..w {
                    let mut sum = Vec3::ZERO;
                    for sample in render_spec::accuracy::sample_positions(spp) {
                        let mut rays = Rays::default();
                        rays.set(0, &Ray::new(frame.eye, frame.sample_direction(x, y, sample)), f32::INFINITY);
                        let c = sh.block::<F8, _>(&rays, &Default::default(), &mut lanes).colour;
                        sum += Vec3::new(c[0][0], c[1][0], c[2][0]);
                    }
                    want.push(shade::to_u8(sum * (1.0 / spp as f32)));
                }
            }
            for method in [Method::Packet, Method::Ordered, Method::Stackless, Method::Bvh8] {
                let walk = tracer.walk(method).unwrap();
                for avx in [true, false] {
                    let image =
                        traced_frame(&tracer, &settings, method.resolve(&scene), walk, Tiles::default(), avx).unwrap();
                    assert_eq!(image.rgb, want, "{spp} spp, {method:?}, avx {avx}");
                    let single = render(&tracer, &one, method).unwrap();
                    assert_eq!(image.rays.primary, single.rays.primary * spp as u64);
                    let differ = image.rgb.iter().zip(&single.rgb).filter(|(a, b)| a != b).count();
                    assert!(differ > (w * h) as usize / 10, "{spp} spp: only {differ} pixels differ from 1 spp");
                    // The first sample's distance, and the cost of all samples.
                    let (a, b) = (image.aov.unwrap(), single.aov.unwrap());
                    let first =
                        frame.sample_direction(0, 0, render_spec::accuracy::sample_positions(spp).next().unwrap());
                    let mut stack = Stack::default();
                    let hit =
                        walk.closest(&Ray::new(frame.eye, first), 0.0, f32::INFINITY, &mut stack, &mut Cost::default());
                    assert_eq!(a.t[0], hit.map_or(f32::INFINITY, |h| h.t));
                    assert!(a.nodes.iter().sum::<u32>() > b.nodes.iter().sum::<u32>() * (spp - 1));
                }
            }
        }
    }
}
