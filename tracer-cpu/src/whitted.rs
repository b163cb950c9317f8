//! The Whitted driver (docs/shading.md): shades a block of up to 8 pixels (4 x 2) stage by stage,
//! as the thesis's pipeline runs a kernel per stage (code example 4.3): trace the primary rays,
//! shade once per light with that light's shadow rays traced together, then per indirection trace
//! the secondary rays of the paths still alive and shade their hits the same way. Ray casting is
//! the first stage alone, lit by a white light at the eye without shadow rays; ambient occlusion
//! and the diffuse bounce follow the first stage with their incoherent rays.
//!
//! Each lane computes exactly what its pixel traced on its own would, in the same order, so an
//! image does not depend on how its rays are grouped or traced ([`TraceLanes`]).

use crate::geometry::Cost;
use crate::lanes::{Stage, TraceLanes};
use crate::packet::{LANES, Rays, Results};
use crate::render::Tracer;
use crate::shade::{self, SurfaceOf};
use crate::vertices::{TriangleSource, Triangles};
use crate::wide::{Lanes, Mask, V3};
use bvh_format::{Light, Material, SceneFile, Triangle};
use glam::Vec3;
use render_spec::{Ao, BounceStop, Intersect, Mode, NO_TRIANGLE, Offset, RayCounts, Settings, sequence};

/// Per-frame constants of the pipeline.
pub struct Shading<'a> {
    scene: &'a SceneFile,
    /// The tracer's triangles: the hit triangle's corners and material are read here, in the
    /// expanded form from the cache lines the traversal has just read, in the indexed form
    /// through the file's index and vertex arrays (two more scattered reads per hit).
    triangles: Triangles<'a>,
    mode: Mode,
    /// The length of AO rays in scene units ([`Ao::distance`] of the scene's bounds).
    ao_distance: f32,
    lights: &'a [Light],
    max_indirections: u32,
    ambient: Vec3,
    background: Vec3,
    /// The adaptive bounce stop, computed once per frame.
    stop: BounceStop,
    /// The triangle test every ray is traced with.
    intersect: Intersect,
    /// How shadow and secondary rays leave the surface.
    offset: Offset,
    /// Whether to fill [`Block::t`], [`Block::normal`] and [`Block::prim`].
    aovs: bool,
    /// Whether to count the rays their own triangle meets ([`render_spec::SelfHits`]).
    self_hits: bool,
    /// Whether every triangle is flat (the file has no vertex normals): surfaces are then
    /// shaded with their geometric normals without reading or interpolating any.
    flat: bool,
    /// Whether a material has `kt > 0` (glass, unless `kr > 0` makes it a mirror): only then is
    /// refraction computed, in blocks with a glass hit.
    glass: bool,
}

/// What a block produced per lane, and the rays it traced.
#[derive(Clone, Copy, Debug)]
pub struct Block {
    /// Linear radiance, component by component.
    pub colour: [[f32; LANES]; 3],
    /// Primary hit distance (+inf on a miss), shading normal and input triangle (with AOVs only).
    pub t: [f32; LANES],
    pub normal: [[f32; LANES]; 3],
    pub prim: [u32; LANES],
    /// Work over all of the lane's rays (with AOVs only: the cost AOVs are its only reader).
    pub cost: [Cost; LANES],
    pub rays: RayCounts,
}

impl Default for Block {
    fn default() -> Self {
        Self {
            colour: [[0.0; LANES]; 3],
            t: [f32::INFINITY; LANES],
            normal: [[0.0; LANES]; 3],
            prim: [NO_TRIANGLE; LANES],
            cost: [Cost::default(); LANES],
            rays: RayCounts::default(),
        }
    }
}

/// The materials of the lanes' hit triangles (triangle 0's in lanes without a hit), read as
/// their three 16-byte rows: `kd, shininess`, `ks, kr`, `kt, ior` ([`Material`]'s layout), each
/// row for eight lanes in one gather and only where the mode uses it.
struct Materials<'a> {
    rows: [&'a [[f32; 4]; 3]; LANES],
}

impl<'a> Materials<'a> {
    #[inline(always)]
    fn of(materials: &'a [Material], index: &[usize; LANES]) -> Self {
        Self { rows: std::array::from_fn(|i| bytemuck::cast_ref(&materials[index[i]])) }
    }

    /// `kd` and the shininess.
    #[inline(always)]
    fn kd_shininess<L: Lanes>(&self) -> (V3<L>, L) {
        let [x, y, z, shininess] = L::gather4(std::array::from_fn(|i| &self.rows[i][0]));
        (V3::new(x, y, z), shininess)
    }

    /// `ks` and `kr`.
    #[inline(always)]
    fn ks_kr<L: Lanes>(&self) -> (V3<L>, L) {
        let [x, y, z, kr] = L::gather4(std::array::from_fn(|i| &self.rows[i][1]));
        (V3::new(x, y, z), kr)
    }

    /// `kt` and `ior`.
    #[inline(always)]
    fn kt_ior<L: Lanes>(&self) -> (L, L) {
        let [kt, ior, ..] = L::gather4(std::array::from_fn(|i| &self.rows[i][2]));
        (kt, ior)
    }
}

impl<'a> Shading<'a> {
    pub fn new(tracer: &'a Tracer<'a>, s: &'a Settings) -> Self {
        let scene = tracer.scene;
        Self {
            scene,
            triangles: tracer.triangles(),
            mode: s.mode,
            ao_distance: match s.mode {
                Mode::Ao(ao) => {
                    let (lo, hi) = scene.bounds();
                    ao.distance(lo, hi)
                }
                _ => 0.0,
            },
            lights: &s.lights,
            max_indirections: s.max_indirections,
            ambient: Vec3::from(scene.settings.ambient),
            background: Vec3::from(scene.settings.background),
            stop: BounceStop::new(scene, &s.lights).with_cutoff(s.accuracy.cutoff),
            intersect: s.accuracy.intersect,
            offset: s.accuracy.offset,
            aovs: s.aovs,
            self_hits: false,
            flat: scene.normal_indices.is_empty(),
            glass: scene.materials.iter().any(|m| m.kt > 0.0),
        }
    }

    /// Counts the rays leaving a surface that the triangle they leave from meets (exact acne,
    /// `--self-hits`): one more triangle test per such ray.
    pub fn with_self_hits(self, on: bool) -> Self {
        Self { self_hits: on, ..self }
    }

    /// Of the `valid` lanes of `rays`, leaving triangles `tri`, those that their own triangle
    /// meets in `(0, t_max]` with the frame's test; zero unless counting was asked for.
    #[inline(always)]
    fn count_self_hits(&self, rays: &Rays, tri: &[u32; LANES]) -> u64 {
        if !self.self_hits {
            return 0;
        }
        let test = match self.intersect {
            Intersect::Watertight => crate::geometry::intersect,
            Intersect::MollerTrumbore => crate::geometry::intersect_moller_trumbore,
        };
        (0..LANES)
            .filter(|&i| {
                rays.valid[i] && test(&self.triangles.triangle(tri[i]), &rays.ray(i), 0.0, rays.t_max[i]).is_some()
            })
            .count() as u64
    }

    /// Shades the valid lanes of `primary` (rays from the eye, `t_max` +inf) with lanes of type
    /// `L`, tracing every ray through `lanes`; `seeds` number the lanes' incoherent rays. Inlined into the renderer's loop, which is compiled
    /// for AVX2 where the CPU has it.
    #[inline(always)]
    pub(crate) fn block<L: Lanes, T: TraceLanes>(&self, primary: &Rays, seeds: &Seeds, lanes: &mut T) -> Block {
        let mut out = Block::default();
        out.colour = self.shade::<L, T>(primary, seeds, lanes, &mut out).to_arrays();
        out
    }

    /// Whether the mode reads [`Seeds`] (the incoherent modes' rays).
    pub(crate) fn seeded(&self) -> bool {
        matches!(self.mode, Mode::Ao(_) | Mode::Diffuse)
    }

    /// Whether the frame fills [`Block`]'s AOV fields (`t`, `normal`, `prim`, `cost`).
    pub(crate) fn aovs(&self) -> bool {
        self.aovs
    }

    /// [`Self::block`] into `out`, which the renderer keeps from block to block: adds the rays
    /// to `out.rays` and the costs to `out.cost`, sets `t`, `normal` and `prim` where a lane hits
    /// (all with AOVs only: else only `rays` is touched), and returns the colour in registers.
    /// A fresh [`Block`] per block was built, zeroed and copied out through memory (about 50
    /// instructions of a block's 1,450 outside the traversal in bunny Whitted frames).
    #[inline(always)]
    pub(crate) fn shade<L: Lanes, T: TraceLanes>(
        &self,
        primary: &Rays,
        seeds: &Seeds,
        lanes: &mut T,
        out: &mut Block,
    ) -> V3<L> {
        let scene = self.scene;
        let zero = L::splat(0.0);
        let background = V3::<L>::splat(self.background);
        let mut colour = V3::<L>::zero();
        // The stage's rays by reference: a copy of the caller's block (its arrays 8 bytes off the
        // 32 of the stores that wrote them) stalled on store forwarding, 5% of a Whitted frame.
        let mut secondary: Rays;
        let mut rays = primary;
        let mut hits = lanes.closest_in(Stage::Primary, rays, self.intersect);
        out.rays.primary += rays.count() as u64;
        let mut weight = L::splat(1.0);
        for depth in 0u32.. {
            // The surfaces hit; a miss adds the background and ends the path.
            let valid = L::mask(rays.valid);
            self.keep_cost(&mut out.cost, &rays.valid, &hits);
            let found = L::mask(hits.hit);
            let hit = valid & found;
            let miss = valid & !found;
            let behind = if depth == 0 { background } else { colour + background * weight };
            colour = V3::select(miss, behind, colour);
            if !hit.any() {
                break;
            }
            let hit_lanes = L::bools(hit);
            let (s, tri, material) = self.surfaces::<L>(rays, &hits, hit_lanes);
            let dir = V3::<L>::from_arrays(&rays.dir);
            if depth == 0 && self.aovs {
                out.t = L::select(hit, L::from_array(hits.t), L::from_array(out.t)).to_array();
                out.normal = V3::select(hit, s.shading, V3::zero()).to_arrays();
                for i in 0..LANES {
                    if hit_lanes[i] {
                        out.prim[i] = scene.input_index[tri[i] as usize];
                    }
                }
            }
            let m = Materials::of(&scene.materials, &material);
            let (kd, shininess) = m.kd_shininess::<L>();
            match self.mode {
                Mode::Cast => {
                    colour = V3::select(hit, shade::cast_of(kd, s.shading, dir), colour);
                    break;
                }
                Mode::Ao(ao) => {
                    let open = self.unoccluded::<L, T>(ao, &s, (hit_lanes, &tri), seeds, lanes, out);
                    colour = V3::select(hit, V3::new(open, open, open), colour);
                    break;
                }
                Mode::Diffuse => {
                    let light = self.diffuse_light::<L, T>(&s, (hit_lanes, &tri), seeds, lanes, out);
                    colour = V3::select(hit, kd.mul_each(light), colour);
                    break;
                }
                Mode::Whitted => {}
            }

            // Phong per light, each light's shadow rays traced together.
            let (ks, kr) = m.ks_kr::<L>();
            let mut local = V3::select(hit, V3::splat(self.ambient).mul_each(kd), V3::zero());
            for light in self.lights {
                let position = V3::<L>::splat(Vec3::from(light.position));
                let l = (position - s.point).normalize_or_zero();
                let term = shade::phong_of(kd, ks, shininess, s.shading, dir, l, hit);
                // A light behind the surface needs no shadow ray.
                let asks = hit & !term.is_zero();
                if !asks.any() {
                    continue;
                }
                // The shadow ray leaves from the side of the surface the light is on.
                let side = V3::select(s.geometric.dot(l).ge(zero), s.geometric, -s.geometric);
                let from = self.leave(s.point, side);
                let shadow = Rays {
                    origin: from.to_arrays(),
                    dir: l.to_arrays(),
                    t_max: (position - from).length().to_array(),
                    valid: L::bools(asks),
                };
                out.rays.shadow += L::count(asks) as u64;
                out.rays.self_hits.shadow += self.count_self_hits(&shadow, &tri);
                let blocked = lanes.occluded_in(Stage::Shadow, &shadow, self.intersect);
                self.keep_cost(&mut out.cost, &shadow.valid, &blocked);
                let lit = asks & !L::mask(blocked.hit);
                local = V3::select(lit, local + term.mul_each(V3::splat(Vec3::from(light.colour))), local);
            }
            colour = V3::select(hit, colour + local * weight, colour);

            // Secondary rays of the paths that can still change their pixel.
            let remaining = self.max_indirections - depth;
            if remaining == 0 {
                break;
            }
            // Refraction only where a hit lane is glass (in no block of a scene without glass).
            let sec = match self.glass.then(|| m.kt_ior::<L>()) {
                Some((kt, ior)) if (hit & !kr.gt(zero) & kt.gt(zero)).any() => {
                    shade::secondary_of(kr, kt, ior, s.shading, s.front, dir)
                }
                _ => shade::reflection_of(kr, s.shading, dir),
            };
            let go = hit & sec.exists & shade::worth_of(weight * sec.factor, &self.stop, self.stop.chain(remaining));
            if !go.any() {
                break;
            }
            weight = L::select(go, weight * sec.factor, weight);
            let side = V3::select(sec.same_side, s.geometric, -s.geometric);
            let from = self.leave(s.point, side);
            secondary = Rays {
                origin: from.to_arrays(),
                dir: sec.dir.to_arrays(),
                t_max: [f32::INFINITY; LANES],
                valid: L::bools(go),
            };
            rays = &secondary;
            out.rays.secondary += L::count(go) as u64;
            out.rays.self_hits.secondary += self.count_self_hits(rays, &tri);
            hits = lanes.closest_in(Stage::Secondary, rays, self.intersect);
        }
        colour
    }
}

/// What numbers the incoherent rays of a block's lanes (render_spec::sequence): each lane's pixel
/// (its row-major index in the image) and the pixel sample being traced.
#[derive(Clone, Copy, Debug, Default)]
pub struct Seeds {
    pub pixel: [u32; LANES],
    pub sample: u32,
}

impl Shading<'_> {
    /// The surfaces at the lanes' hits (`hit`: lanes that found one; the others hold whatever
    /// triangle 0 gives), the hit triangles and their materials' indices.
    #[inline(always)]
    fn surfaces<L: Lanes>(
        &self,
        rays: &Rays,
        hits: &Results,
        hit: [bool; LANES],
    ) -> (SurfaceOf<L>, [u32; LANES], [usize; LANES]) {
        let tri = L::keep_u32(L::mask(hit), &hits.tri);
        let (origin, dir) = (V3::<L>::from_arrays(&rays.origin), V3::<L>::from_arrays(&rays.dir));
        // The corners as stored, eight lanes per gather; the edges as `shade::edges` takes them.
        let ([p0, p1, p2], material) = match self.triangles {
            Triangles::Expanded(t) => corners::<L>(std::array::from_fn(|i| &t[tri[i] as usize])),
            Triangles::Indexed(t) => {
                let local: [Triangle; LANES] = std::array::from_fn(|i| t.triangle(tri[i]));
                corners::<L>(std::array::from_fn(|i| &local[i]))
            }
        };
        let (e1, e2) = (p1 - p0, p2 - p0);
        let t = L::from_array(hits.t);
        if self.flat {
            return (shade::flat_surface_of(e1, e2, origin, dir, t), tri, material);
        }
        // Vertex normals (zero for a flat triangle) padded to 16 bytes per lane.
        let scene = self.scene;
        let mut normals = [[[0.0f32; 4]; 3]; LANES];
        for i in 0..LANES {
            if let Some(n) = scene.vertex_normals(tri[i] as usize) {
                for (pad, n) in normals[i].iter_mut().zip(n) {
                    *pad = [n[0], n[1], n[2], 0.0];
                }
            }
        }
        let s = shade::surface_of(
            e1,
            e2,
            [
                L::gather3(std::array::from_fn(|i| &normals[i][0])),
                L::gather3(std::array::from_fn(|i| &normals[i][1])),
                L::gather3(std::array::from_fn(|i| &normals[i][2])),
            ],
            origin,
            dir,
            t,
            L::from_array(hits.u),
            L::from_array(hits.v),
        );
        (s, tri, material)
    }

    /// Adds the work of the `m` lanes of `r` to `cost`, where the frame keeps it (for the cost
    /// AOVs, its only reader).
    #[inline(always)]
    fn keep_cost(&self, cost: &mut [Cost; LANES], m: &[bool; LANES], r: &Results) {
        if self.aovs {
            add_cost(cost, m, r);
        }
    }

    /// The rays of the incoherent modes from the surfaces `s` of the `hit` lanes: origins moved
    /// off the surface to the side of the (turned) geometric normal, and cosine-distributed
    /// directions about that normal for sequence number `n` of each lane's pixel.
    #[inline(always)]
    fn incoherent_rays<L: Lanes>(
        &self,
        s: &SurfaceOf<L>,
        hit: [bool; LANES],
        seeds: &Seeds,
        t_max: f32,
        n: u32,
    ) -> Rays {
        let normal = s.geometric.to_arrays();
        let mut rays = Rays {
            origin: self.leave(s.point, s.geometric).to_arrays(),
            dir: [[0.0; LANES]; 3],
            t_max: [t_max; LANES],
            valid: hit,
        };
        for i in (0..LANES).filter(|&i| hit[i]) {
            let u = sequence::sample_2d(seeds.pixel[i], n);
            let d = sequence::cosine_direction([normal[0][i], normal[1][i], normal[2][i]], u);
            for (dir, d) in rays.dir.iter_mut().zip(d) {
                dir[i] = d;
            }
        }
        rays
    }

    /// Ambient occlusion (docs/shading.md): the fraction of the AO rays of each `hit` lane (on
    /// its triangle) that nothing blocks, `open * (1 / samples)`.
    #[inline(always)]
    fn unoccluded<L: Lanes, T: TraceLanes>(
        &self,
        ao: Ao,
        s: &SurfaceOf<L>,
        (hit, tri): ([bool; LANES], &[u32; LANES]),
        seeds: &Seeds,
        lanes: &mut T,
        out: &mut Block,
    ) -> L {
        let mut open = [0u32; LANES];
        for k in 0..ao.samples {
            let n = sequence::incoherent_sample(seeds.sample, ao.samples, k);
            let rays = self.incoherent_rays(s, hit, seeds, self.ao_distance, n);
            out.rays.ao += rays.count() as u64;
            out.rays.self_hits.ao += self.count_self_hits(&rays, tri);
            let blocked = lanes.occluded_in(Stage::Ao, &rays, self.intersect);
            self.keep_cost(&mut out.cost, &rays.valid, &blocked);
            for i in 0..LANES {
                open[i] += u32::from(hit[i] && !blocked.hit[i]);
            }
        }
        let inverse = ao.inverse();
        L::from_fn(|i| open[i] as f32 * inverse)
    }

    /// The light a diffuse bounce brings back to each `hit` lane (on its triangle;
    /// docs/shading.md): the bounce hit lit by a white light at the bounce's origin (ray
    /// casting's rule), or the background.
    #[inline(always)]
    fn diffuse_light<L: Lanes, T: TraceLanes>(
        &self,
        s: &SurfaceOf<L>,
        (hit, tri): ([bool; LANES], &[u32; LANES]),
        seeds: &Seeds,
        lanes: &mut T,
        out: &mut Block,
    ) -> V3<L> {
        let rays = self.incoherent_rays(s, hit, seeds, f32::INFINITY, seeds.sample);
        out.rays.diffuse += rays.count() as u64;
        out.rays.self_hits.diffuse += self.count_self_hits(&rays, tri);
        let hits = lanes.closest_in(Stage::Diffuse, &rays, self.intersect);
        self.keep_cost(&mut out.cost, &rays.valid, &hits);
        let found: [bool; LANES] = std::array::from_fn(|i| hit[i] && hits.hit[i]);
        let background = V3::<L>::splat(self.background);
        if !found.iter().any(|&f| f) {
            return background;
        }
        let (b, _, material) = self.surfaces::<L>(&rays, &hits, found);
        let (kd, _) = Materials::of(&self.scene.materials, &material).kd_shininess::<L>();
        let lit = shade::cast_of(kd, b.shading, V3::from_arrays(&rays.dir));
        V3::select(L::mask(found), lit, background)
    }

    /// The origins of rays leaving the surface at `p` into the side of the unit geometric normal
    /// `n`: [`crate::geometry::leave`] lane by lane.
    #[inline(always)]
    fn leave<L: Lanes>(&self, p: V3<L>, n: V3<L>) -> V3<L> {
        match self.offset {
            Offset::ScaleAware => L::offset_origin(p, n),
            Offset::Fixed(d) => p + n * L::splat(d),
        }
    }
}

/// The corners of eight triangles as stored (each padded to 16 bytes), eight lanes per gather,
/// and their materials' indices.
#[inline(always)]
fn corners<L: Lanes>(t: [&Triangle; LANES]) -> ([V3<L>; 3], [usize; LANES]) {
    let rows: [&[[f32; 4]; 3]; LANES] = std::array::from_fn(|i| bytemuck::cast_ref(t[i]));
    let p0 = L::gather3(std::array::from_fn(|i| &rows[i][0]));
    let p1 = L::gather3(std::array::from_fn(|i| &rows[i][1]));
    let p2 = L::gather3(std::array::from_fn(|i| &rows[i][2]));
    ([p0, p1, p2], std::array::from_fn(|i| t[i].material as usize))
}

#[inline(always)]
fn add_cost(cost: &mut [Cost; LANES], m: &[bool; LANES], r: &Results) {
    for i in 0..LANES {
        if m[i] {
            cost[i] += r.cost[i];
        }
    }
}
