//! Whole images: bands of rows in parallel (rayon), 4 x 2 pixel blocks shaded by the Whitted
//! driver and written straight into the 8-bit image and, when asked for, the AOVs.

use crate::Method;
use crate::bvh8::Bvh8;
use crate::geometry::{Cost, Hit, MollerTrumbore, Ray, TriangleTest, Watertight};
use crate::lanes::{Mixed, OneByOne, Packets, TraceLanes};
use crate::packet::{LANES, Rays};
use crate::shade;
use crate::traverse::{self, Stack};
use crate::whitted::{Seeds, Shading};
use crate::wide::{F8, Lanes, V3};
use bvh_format::{Node, SceneFile, Triangle};
use rayon::prelude::*;
use render_spec::{Aovs, Frame, Image, Intersect, RayCounts, RenderError, Settings};

/// The scene prepared for tracing: layouts, and the bounds behind the adaptive bounce stop.
pub struct Tracer<'a> {
    pub scene: &'a SceneFile,
    /// The triangles expanded to three vertices each, in leaf order (48 bytes per triangle).
    pub(crate) tris: Vec<Triangle>,
    child_pair: Option<&'a [Node]>,
    escape: Option<&'a [Node]>,
    /// Count the rays their own triangle meets ([`render_spec::SelfHits`], `--self-hits`).
    self_hits: bool,
    /// The wide BVH, collapsed from the child-pair layout on first use.
    wide: std::sync::OnceLock<Bvh8>,
}

impl<'a> Tracer<'a> {
    pub fn new(scene: &'a SceneFile) -> Self {
        Self {
            scene,
            tris: scene.leaf_triangles(),
            child_pair: scene.child_pair.as_deref(),
            escape: scene.escape.as_deref(),
            self_hits: false,
            wide: std::sync::OnceLock::new(),
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
        Some(self.wide.get_or_init(|| Bvh8::new(nodes, &self.tris)))
    }

    /// The triangles as every path intersects them: three vertices each, in leaf order.
    pub fn triangles(&self) -> &[Triangle] {
        &self.tris
    }

    /// The scalar traversal `method` names, bound to the layout it reads: the child-pair layout
    /// for [`Method::Ordered`] and [`Method::Packet`], the escape-pointer layout for
    /// [`Method::Stackless`], the wide BVH collapsed from the child-pair layout for
    /// [`Method::Bvh8`] and the single rays of [`Method::Auto`], and for [`Method::Auto`] on a
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
    /// [`Method::Stackless`] on the escape-pointer layout or [`Method::Bvh8`] on the wide BVH.
    pub fn method(&self) -> Method {
        match self.layout {
            Layout::ChildPair(_) => Method::Ordered,
            Layout::Escape(_) => Method::Stackless,
            Layout::Wide(_) => Method::Bvh8,
        }
    }

    /// The child-pair nodes, where this walk reads them (what packets trace).
    pub(crate) fn child_pair(&self) -> Option<&'t [Node]> {
        match self.layout {
            Layout::ChildPair(nodes) => Some(nodes),
            Layout::Escape(_) | Layout::Wide(_) => None,
        }
    }

    /// Closest hit in `(t_min, t_max]` with the default (watertight) triangle test; adds the work
    /// done to `cost`.
    pub fn closest(&self, ray: &Ray, t_min: f32, t_max: f32, stack: &mut Stack, cost: &mut Cost) -> Option<Hit> {
        self.closest_with(Intersect::Watertight, ray, t_min, t_max, stack, cost)
    }

    /// [`Self::closest`] with the triangle test `test`.
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
    pub fn occluded(&self, ray: &Ray, t_max: f32, stack: &mut Stack, cost: &mut Cost) -> bool {
        self.occluded_with(Intersect::Watertight, ray, t_max, stack, cost)
    }

    /// [`Self::occluded`] with the triangle test `test`.
    pub fn occluded_with(&self, test: Intersect, ray: &Ray, t_max: f32, stack: &mut Stack, cost: &mut Cost) -> bool {
        match test {
            Intersect::Watertight => self.trace::<true, Watertight>(ray, 0.0, t_max, stack, cost),
            Intersect::MollerTrumbore => self.trace::<true, MollerTrumbore>(ray, 0.0, t_max, stack, cost),
        }
        .is_some()
    }

    /// This walk's traversal with the triangle test `T`.
    pub(crate) fn trace<const ANY: bool, T: TriangleTest>(
        &self,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        stack: &mut Stack,
        cost: &mut Cost,
    ) -> Option<Hit> {
        let tris = &self.tracer.tris;
        match self.layout {
            Layout::Escape(nodes) => traverse::escape::<ANY, T>(nodes, tris, ray, t_min, t_max, cost),
            Layout::ChildPair(nodes) => traverse::child_pair::<ANY, T>(nodes, tris, ray, t_min, t_max, stack, cost),
            Layout::Wide(bvh) => bvh.trace::<ANY, T>(ray, t_min, t_max, stack, cost),
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
    /// 8 x 8: as fast as any shape measured on the dragon and the bunny (tiles of 2 x the width,
    /// 4 x 8 to 16 x 16 and 8 x 32 lie within 5% of each other; `examples/tiles.rs`), and enough
    /// bands (180 at 1920 x 1440) to keep 16 workers busy to the end.
    fn default() -> Self {
        Self { rows: 8, columns: 8 }
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
/// done (from any worker thread).
pub fn render_with_progress(
    tracer: &Tracer<'_>,
    settings: &Settings,
    method: Method,
    progress: &(dyn Fn(u32) + Sync),
) -> Result<Image, RenderError> {
    let tiles = Tiles::default();
    let walk = tracer.walk(method)?;
    match method.resolve(tracer.scene) {
        Method::Packet => render_with(tracer, settings, Method::Packet, || Packets::new(walk), tiles, progress),
        Method::Bvh8Packet => {
            let bvh = tracer.bvh8().expect("the walk is on the wide BVH");
            render_with(tracer, settings, Method::Bvh8Packet, || crate::packet8::Lanes::new(bvh), tiles, progress)
        }
        Method::Auto => {
            let pairs = if packets_pay(tracer, settings, walk)? { Some(tracer.walk(Method::Ordered)?) } else { None };
            render_with(tracer, settings, Method::Auto, || Mixed::new(walk, pairs), tiles, progress)
        }
        m => render_with(tracer, settings, m, || OneByOne::new(walk), tiles, progress),
    }
}

/// `--method auto`'s measurement: whether AVX2 packets over the child-pair tree trace this frame's
/// primary rays faster than the wide BVH one ray at a time (`wide`), timed on up to 256 of its
/// 4 x 2 pixel blocks spread evenly over the image (the fastest of 3 alternating rounds; about a
/// millisecond). Its answer goes for the shadow rays too, the other coherent kind. Images do not
/// depend on it: every method finds the same hits.
pub fn packets_pay(tracer: &Tracer<'_>, settings: &Settings, wide: Walk<'_>) -> Result<bool, RenderError> {
    if !crate::packet::available() || tracer.child_pair.is_none() {
        return Ok(false);
    }
    let frame = settings.frame()?;
    let (w, h) = (settings.width, settings.height);
    const GRID: u32 = 16;
    let mut blocks = Vec::with_capacity((GRID * GRID) as usize);
    for gy in 0..GRID.min(h.div_ceil(2)) {
        for gx in 0..GRID.min(w.div_ceil(4)) {
            let (bx, by) = ((gx * w / GRID) & !3, (gy * h / GRID) & !1);
            let mut rays = Rays::default();
            for i in 0..LANES as u32 {
                let (x, y) = (bx + i % 4, by + i / 4);
                if x < w && y < h {
                    rays.set(i as usize, &Ray::new(frame.eye, frame.direction(x, y)), f32::INFINITY);
                }
            }
            blocks.push(rays);
        }
    }
    let test = settings.accuracy.intersect;
    let mut single = OneByOne::new(wide);
    let mut packets = Packets::new(tracer.walk(Method::Ordered)?);
    let (mut t_single, mut t_packets) = (f64::INFINITY, f64::INFINITY);
    for _ in 0..3 {
        let t = std::time::Instant::now();
        for b in &blocks {
            std::hint::black_box(single.closest(b, test));
        }
        t_single = t_single.min(t.elapsed().as_secs_f64());
        let t = std::time::Instant::now();
        for b in &blocks {
            std::hint::black_box(packets.closest(b, test));
        }
        t_packets = t_packets.min(t.elapsed().as_secs_f64());
    }
    Ok(t_packets < t_single)
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

/// [`render_with_progress`] with the rays of every stage traced by a [`TraceLanes`] made once per
/// worker by `lanes` (benchmarks wrap the renderer's own to see what it traces), in `tiles`.
/// `method` is the one `lanes` traces with: the layout it reads must be in the file.
pub fn render_with<T: TraceLanes>(
    tracer: &Tracer<'_>,
    settings: &Settings,
    method: Method,
    lanes: impl Fn() -> T + Sync,
    tiles: Tiles,
    progress: &(dyn Fn(u32) + Sync),
) -> Result<Image, RenderError> {
    render_in(tracer, settings, method, lanes, tiles, progress, crate::packet::available())
}

/// [`render_with`], with AVX lanes for the shading or (`avx` false, or no AVX2) plain arrays.
fn render_in<T: TraceLanes>(
    tracer: &Tracer<'_>,
    settings: &Settings,
    method: Method,
    lanes: impl Fn() -> T + Sync,
    tiles: Tiles,
    progress: &(dyn Fn(u32) + Sync),
    avx: bool,
) -> Result<Image, RenderError> {
    let tiles = tiles.blocks();
    let frame = settings.frame()?;
    tracer.walk(method)?;
    let (w, h) = (settings.width as usize, settings.height as usize);
    let sh = Shading::new(tracer, settings).with_self_hits(tracer.self_hits);
    let samples: Vec<(f32, f32)> = render_spec::accuracy::sample_positions(settings.accuracy.spp).collect();
    let mut rgb = vec![[0u8; 3]; w * h];
    let mut aov = settings.aovs.then(|| Aovs {
        t: vec![0.0; w * h],
        normal: vec![[0.0; 3]; w * h],
        prim: vec![0; w * h],
        nodes: vec![0; w * h],
        tris: vec![0; w * h],
    });
    let rays = bands(w, tiles.rows, &mut rgb, aov.as_mut())
        .into_par_iter()
        .map_init(&lanes, |lanes, mut band| {
            let rays = render_band(&sh, &frame, &samples, lanes, &mut band, w, tiles.columns, avx);
            progress((band.rgb.len() / w) as u32);
            rays
        })
        .reduce(RayCounts::default, |a, b| a + b);
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
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { render_band_avx2(sh, frame, samples, lanes, band, w, columns) };
    }
    render_band_in::<F8, T>(sh, frame, samples, lanes, band, w, columns)
}

/// [`render_band`] compiled for AVX2, so that every lane operation of the shading is one
/// instruction.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
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
    let mut rays = RayCounts::default();
    for x0 in (0..w).step_by(columns) {
        for dy in (0..rows).step_by(2) {
            for bx in (x0..(x0 + columns).min(w)).step_by(4) {
                rays = rays + block::<L, T>(sh, frame, samples, lanes, band, w, rows, bx, dy);
            }
        }
    }
    rays
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

/// Traces and shades the 4 x 2 block whose top-left pixel is (`bx`, `dy`) in the band at every
/// sample position, writing its pixels: the colour is the sum of the samples' linear colours in
/// their order times the f32 reciprocal of their number (a GPU multiplies exactly, where its
/// division may be off by ulps), then quantised; the distance, normal and triangle AOVs
/// are the first sample's, the cost AOVs the sum over all. Returns its rays.
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
) -> RayCounts {
    let lane_xy = |i: usize| (bx + i % 4, dy + i / 4);
    let mut primary = Rays::default();
    for i in 0..LANES {
        let (x, y) = lane_xy(i);
        primary.valid[i] = x < w && y < rows;
    }
    primary.origin = V3::<L>::splat(frame.eye).to_arrays();
    let (x, y) = (L::from_fn(|i| lane_xy(i).0 as f32), L::from_fn(|i| (band.y0 + lane_xy(i).1) as f32));
    primary.t_max = [f32::INFINITY; LANES];
    primary.dir = directions(frame, x, y, samples[0]).to_arrays();
    // Row-major pixel indices in the image (at most 2^28 pixels: no overflow).
    let mut seeds =
        Seeds { pixel: std::array::from_fn(|i| ((band.y0 + lane_xy(i).1) * w + lane_xy(i).0) as u32), sample: 0 };
    let mut out = sh.block::<L, T>(&primary, &seeds, lanes);
    let mut colour = V3::<L>::from_arrays(&out.colour);
    for (k, &sample) in samples.iter().enumerate().skip(1) {
        primary.dir = directions(frame, x, y, sample).to_arrays();
        seeds.sample = k as u32;
        let more = sh.block::<L, T>(&primary, &seeds, lanes);
        colour = colour + V3::from_arrays(&more.colour);
        for i in 0..LANES {
            out.cost[i] += more.cost[i];
        }
        out.rays = out.rays + more.rays;
    }
    if samples.len() > 1 {
        colour = colour * (L::splat(1.0) / L::splat(samples.len() as f32));
    }
    let rgb = shade::to_u8_lanes(colour);
    for i in 0..LANES {
        if !primary.valid[i] {
            continue;
        }
        let (x, y) = lane_xy(i);
        let p = y * w + x;
        band.rgb[p] = rgb[i];
        if let Some(a) = &mut band.aov {
            let n = out.normal;
            a.t[p] = out.t[i];
            a.normal[p] = [n[0][i], n[1][i], n[2][i]];
            a.prim[p] = out.prim[i];
            a.nodes[p] = out.cost[i].nodes;
            a.tris[p] = out.cost[i].tris;
        }
    }
    out.rays
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use render_spec::{CameraSpec, Mode};

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
                    let x = L::from_fn(|i| (bx + i as u32 % 4) as f32);
                    let y = L::from_fn(|i| (by + i as u32 / 4) as f32);
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
                    width: 61,
                    height: 37,
                    camera: CameraSpec::from(scene.camera("medium").unwrap()),
                    mode,
                    lights: scene.lights.clone(),
                    max_indirections: scene.settings.max_indirections,
                    aovs: true,
                    accuracy: render_spec::Accuracy::default(),
                };
                let tiles = Tiles { rows: 6, columns: 12 };
                let walk = tracer.walk(method).unwrap();
                let image = |avx| match method.resolve(&scene) {
                    Method::Packet => {
                        render_in(&tracer, &settings, Method::Packet, || Packets::new(walk), tiles, &|_| {}, avx)
                    }
                    m => render_in(&tracer, &settings, m, || OneByOne::new(walk), tiles, &|_| {}, avx),
                };
                let (a, b) = (image(true).unwrap(), image(false).unwrap());
                assert_eq!(a.rgb, b.rgb, "{mode:?} {method:?}");
                for tiles in [Tiles { rows: 2, columns: usize::MAX }, Tiles { rows: usize::MAX, columns: 1 }] {
                    let other =
                        render_in(&tracer, &settings, Method::Packet, || Packets::new(walk), tiles, &|_| {}, true);
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
                width: w,
                height: h,
                camera: CameraSpec::from(scene.camera("medium").unwrap()),
                mode: Mode::Whitted,
                lights: scene.lights.clone(),
                max_indirections: scene.settings.max_indirections,
                aovs: true,
                accuracy: render_spec::Accuracy { spp, ..Default::default() },
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
                    let image = match method.resolve(&scene) {
                        Method::Packet => render_in(
                            &tracer,
                            &settings,
                            Method::Packet,
                            || Packets::new(walk),
                            Tiles::default(),
                            &|_| {},
                            avx,
                        ),
                        m => render_in(&tracer, &settings, m, || OneByOne::new(walk), Tiles::default(), &|_| {}, avx),
                    }
                    .unwrap();
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
