//! The Whitted driver (docs/shading.md): shades a block of up to 8 pixels (4 x 2) stage by stage,
//! as the thesis's pipeline runs a kernel per stage (code example 4.3): trace the primary rays,
//! shade once per light with that light's shadow rays traced together, then per indirection trace
//! the secondary rays of the paths still alive and shade their hits the same way. Ray casting is
//! the first stage alone, lit by a white light at the eye without shadow rays.
//!
//! Each lane computes exactly what its pixel traced on its own would, in the same order, so an
//! image does not depend on how its rays are grouped or traced ([`TraceLanes`]).

use crate::geometry::{Cost, offset_origin};
use crate::lanes::TraceLanes;
use crate::packet::{LANES, Rays, Results};
use crate::render::{Mode, RayCounts, RenderSettings};
use crate::shade;
use crate::wide::{F8, M8, Mask, Real, V8};
use bvh_format::{Light, Material, NO_TRIANGLE, SceneFile};
use glam::Vec3;

/// Per-frame constants of the pipeline.
pub struct Shading<'a> {
    scene: &'a SceneFile,
    mode: Mode,
    lights: &'a [Light],
    max_indirections: u32,
    ambient: Vec3,
    background: Vec3,
    /// The adaptive bounce stop's bound on what a path can still add, and the largest kr or kt.
    bound: f32,
    k_max: f32,
    /// Whether to fill [`Block::t`], [`Block::normal`] and [`Block::prim`].
    aovs: bool,
}

/// What a block produced per lane, and the rays it traced.
#[derive(Clone, Copy, Debug)]
pub struct Block {
    /// Linear radiance.
    pub colour: V8,
    /// Primary hit distance (+inf on a miss), shading normal and input triangle (with AOVs only).
    pub t: F8,
    pub normal: V8,
    pub prim: [u32; LANES],
    /// Work over all of the lane's rays.
    pub cost: [Cost; LANES],
    pub rays: RayCounts,
}

impl Default for Block {
    fn default() -> Self {
        Self {
            colour: V8::zero(),
            t: F8::splat(f32::INFINITY),
            normal: V8::zero(),
            prim: [NO_TRIANGLE; LANES],
            cost: [Cost::default(); LANES],
            rays: RayCounts::default(),
        }
    }
}

/// The materials of the lanes that hit something (a default material elsewhere).
struct Materials {
    kd: V8,
    ks: V8,
    shininess: F8,
    kr: F8,
    kt: F8,
    ior: F8,
}

impl Materials {
    #[inline(always)]
    fn gather(m: &[&Material; LANES]) -> Self {
        let f = |g: fn(&Material) -> f32| F8::from_fn(|i| g(m[i]));
        Self {
            kd: V8::from_lanes(|i| Vec3::from(m[i].kd)),
            ks: V8::from_lanes(|i| Vec3::from(m[i].ks)),
            shininess: f(|m| m.shininess),
            kr: f(|m| m.kr),
            kt: f(|m| m.kt),
            ior: f(|m| m.ior),
        }
    }
}

/// `offset_origin` lane by lane (bit arithmetic on the coordinates).
#[inline(always)]
fn offset(p: V8, n: V8) -> V8 {
    let o: [Vec3; LANES] = std::array::from_fn(|i| offset_origin(p.lane(i), n.lane(i)));
    V8::from_lanes(|i| o[i])
}

impl<'a> Shading<'a> {
    pub fn new(scene: &'a SceneFile, s: &'a RenderSettings) -> Self {
        let colours: Vec<[f32; 3]> = s.lights.iter().map(|l| l.colour).collect();
        let (bound, k_max) = scene.bounce_bound(&colours);
        Self {
            scene,
            mode: s.mode,
            lights: &s.lights,
            max_indirections: s.max_indirections,
            ambient: Vec3::from(scene.settings.ambient),
            background: Vec3::from(scene.settings.background),
            bound,
            k_max,
            aovs: s.aovs,
        }
    }

    /// Shades the valid lanes of `primary` (rays from the eye, `t_max` +inf), tracing every ray
    /// through `lanes`.
    pub fn block<T: TraceLanes>(&self, primary: &Rays, lanes: &mut T) -> Block {
        #[cfg(target_arch = "x86_64")]
        if crate::packet::available() {
            // SAFETY: the CPU has AVX2 (checked just above).
            return unsafe { self.block_avx2(primary, lanes) };
        }
        self.block_lanes(primary, lanes)
    }

    /// [`Shading::block`] compiled for AVX2, so that each lane operation is one instruction.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn block_avx2<T: TraceLanes>(&self, primary: &Rays, lanes: &mut T) -> Block {
        self.block_lanes(primary, lanes)
    }

    #[inline(always)]
    fn block_lanes<T: TraceLanes>(&self, primary: &Rays, lanes: &mut T) -> Block {
        let scene = self.scene;
        let zero = F8::splat(0.0);
        let background = V8::splat(self.background);
        let mut out = Block::default();
        let mut rays = *primary;
        let mut hits = lanes.closest(&rays);
        out.rays.primary = M8(rays.valid).count() as u64;
        let mut weight = F8::splat(1.0);
        for depth in 0u32.. {
            // The surfaces hit; a miss adds the background and ends the path.
            let valid = M8(rays.valid);
            add_cost(&mut out.cost, valid, &hits);
            let hit = valid & M8(hits.hit);
            let miss = valid & !hit;
            let behind = if depth == 0 { background } else { out.colour + background * weight };
            out.colour = V8::select(miss, behind, out.colour);
            if !hit.any() {
                break;
            }
            let tri: [usize; LANES] = std::array::from_fn(|i| if hit.0[i] { hits.tri[i] as usize } else { 0 });
            let (t, n) = (&scene.triangles, &scene.normals);
            let normal = |k: usize| V8::from_lanes(|i| Vec3::from_slice(&n[tri[i]].n[k][..3]));
            let (origin, dir) = (V8::from_arrays(&rays.origin), V8::from_arrays(&rays.dir));
            let s = shade::surface_of(
                V8::from_lanes(|i| Vec3::from_slice(&t[tri[i]].e1[..3])),
                V8::from_lanes(|i| Vec3::from_slice(&t[tri[i]].e2[..3])),
                [normal(0), normal(1), normal(2)],
                origin,
                dir,
                F8(hits.t),
                F8(hits.u),
                F8(hits.v),
            );
            if depth == 0 && self.aovs {
                out.t = F8::select(hit, F8(hits.t), out.t);
                out.normal = V8::select(hit, s.shading, out.normal);
                for i in 0..LANES {
                    if hit.0[i] {
                        out.prim[i] = scene.input_index[tri[i]];
                    }
                }
            }
            let m = Materials::gather(&std::array::from_fn(|i| &scene.materials[scene.material_ids[tri[i]] as usize]));
            if self.mode == Mode::Cast {
                out.colour = V8::select(hit, shade::cast_of(m.kd, s.shading, dir), out.colour);
                break;
            }

            // Phong per light, each light's shadow rays traced together.
            let mut local = V8::select(hit, V8::splat(self.ambient).mul(m.kd), V8::zero());
            for light in self.lights {
                let position = V8::splat(Vec3::from(light.position));
                let l = (position - s.point).normalize_or_zero();
                let term = shade::phong_of(m.kd, m.ks, m.shininess, s.shading, dir, l, hit);
                // A light behind the surface needs no shadow ray.
                let asks = hit & !term.is_zero();
                if !asks.any() {
                    continue;
                }
                // The shadow ray leaves from the side of the surface the light is on.
                let side = V8::select(s.geometric.dot(l).ge(zero), s.geometric, -s.geometric);
                let from = offset(s.point, side);
                let shadow =
                    Rays { origin: from.to_arrays(), dir: l.to_arrays(), t_max: (position - from).length().0, valid: asks.0 };
                out.rays.shadow += asks.count() as u64;
                let blocked = lanes.occluded(&shadow);
                add_cost(&mut out.cost, asks, &blocked);
                let lit = asks & !M8(blocked.hit);
                local = V8::select(lit, local + term.mul(V8::splat(Vec3::from(light.colour))), local);
            }
            out.colour = V8::select(hit, out.colour + local * weight, out.colour);

            // Secondary rays of the paths that can still change their pixel.
            let remaining = self.max_indirections - depth;
            if remaining == 0 {
                break;
            }
            let sec = shade::secondary_of(m.kr, m.kt, m.ior, s.shading, s.front, dir);
            let go = hit & sec.exists & shade::worth_of(weight * sec.factor, self.bound, shade::chain(remaining, self.k_max));
            if !go.any() {
                break;
            }
            weight = F8::select(go, weight * sec.factor, weight);
            let side = V8::select(sec.same_side, s.geometric, -s.geometric);
            let from = offset(s.point, side);
            rays = Rays { origin: from.to_arrays(), dir: sec.dir.to_arrays(), t_max: [f32::INFINITY; LANES], valid: go.0 };
            out.rays.secondary += go.count() as u64;
            hits = lanes.closest(&rays);
        }
        out
    }
}

#[inline(always)]
fn add_cost(cost: &mut [Cost; LANES], m: M8, r: &Results) {
    for i in 0..LANES {
        if m.0[i] {
            cost[i] += r.cost[i];
        }
    }
}
