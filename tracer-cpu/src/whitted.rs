//! The Whitted driver (docs/shading.md): shades a block of up to 8 pixels (4 x 2) stage by stage,
//! as the thesis's pipeline runs a kernel per stage (code example 4.3): trace the primary rays,
//! shade once per light with that light's shadow rays traced together, then per indirection trace
//! the secondary rays of the paths still alive and shade their hits the same way. Ray casting is
//! the first stage alone, lit by a white light at the eye without shadow rays.
//!
//! Each lane computes exactly what its pixel traced on its own would, in the same order, so an
//! image does not depend on how its rays are grouped or traced ([`TraceLanes`]).

use crate::geometry::{Cost, Ray, offset_origin};
use crate::lanes::TraceLanes;
use crate::packet::{LANES, Rays};
use crate::render::{Mode, RayCounts, RenderSettings};
use crate::shade::{self, Surface};
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
    pub colour: [Vec3; LANES],
    /// Primary hit distance (+inf on a miss), shading normal and input triangle (with AOVs only).
    pub t: [f32; LANES],
    pub normal: [Vec3; LANES],
    pub prim: [u32; LANES],
    /// Work over all of the lane's rays.
    pub cost: [Cost; LANES],
    pub rays: RayCounts,
}

impl Default for Block {
    fn default() -> Self {
        Self {
            colour: [Vec3::ZERO; LANES],
            t: [f32::INFINITY; LANES],
            normal: [Vec3::ZERO; LANES],
            prim: [NO_TRIANGLE; LANES],
            cost: [Cost::default(); LANES],
            rays: RayCounts::default(),
        }
    }
}

fn count(valid: &[bool; LANES]) -> u64 {
    valid.iter().filter(|&&v| v).count() as u64
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
        let scene = self.scene;
        let mut out = Block::default();
        let mut rays = *primary;
        let mut hits = lanes.closest(&rays);
        out.rays.primary = count(&rays.valid);
        let mut weight = [1.0f32; LANES];
        for depth in 0u32.. {
            // The surfaces hit; a miss adds the background and ends the path.
            let mut surf: [Option<(Surface, &Material)>; LANES] = [None; LANES];
            for i in 0..LANES {
                if !rays.valid[i] {
                    continue;
                }
                out.cost[i] += hits.cost[i];
                let Some(hit) = hits.hits[i] else {
                    out.colour[i] =
                        if depth == 0 { self.background } else { out.colour[i] + weight[i] * self.background };
                    continue;
                };
                let k = hit.tri as usize;
                let ray = &rays.rays[i];
                let s =
                    shade::surface(&scene.triangles[k], &scene.normals[k], ray.origin, ray.dir, hit.t, hit.u, hit.v);
                if depth == 0 && self.aovs {
                    (out.t[i], out.normal[i], out.prim[i]) = (hit.t, s.shading, scene.input_index[k]);
                }
                surf[i] = Some((s, &scene.materials[scene.material_ids[k] as usize]));
            }
            if self.mode == Mode::Cast {
                for i in 0..LANES {
                    if let Some((s, m)) = &surf[i] {
                        out.colour[i] = shade::cast(m, s, rays.rays[i].dir);
                    }
                }
                return out;
            }

            // Phong per light, each light's shadow rays traced together.
            let mut local = [Vec3::ZERO; LANES];
            for i in 0..LANES {
                if let Some((_, m)) = &surf[i] {
                    local[i] = self.ambient * Vec3::from(m.kd);
                }
            }
            for light in self.lights {
                let mut shadow = Rays { rays: rays.rays, valid: [false; LANES], t_max: [0.0; LANES] };
                let mut terms = [Vec3::ZERO; LANES];
                for i in 0..LANES {
                    let Some((s, m)) = &surf[i] else { continue };
                    if let (term, Some((ray, t_max))) = light_query(m, s, &rays.rays[i], light) {
                        (terms[i], shadow.rays[i], shadow.t_max[i], shadow.valid[i]) = (term, ray, t_max, true);
                    }
                }
                if !shadow.valid.contains(&true) {
                    continue;
                }
                out.rays.shadow += count(&shadow.valid);
                let blocked = lanes.occluded(&shadow);
                for i in 0..LANES {
                    if shadow.valid[i] {
                        out.cost[i] += blocked.cost[i];
                        if blocked.hits[i].is_none() {
                            local[i] += Vec3::from(light.colour) * terms[i];
                        }
                    }
                }
            }

            // Secondary rays of the paths that can still change their pixel.
            let mut next = Rays { rays: rays.rays, valid: [false; LANES], t_max: [f32::INFINITY; LANES] };
            for i in 0..LANES {
                let Some((s, m)) = &surf[i] else { continue };
                out.colour[i] += weight[i] * local[i];
                let Some(sec) = shade::secondary(m, s, rays.rays[i].dir) else { continue };
                let remaining = self.max_indirections - depth;
                if remaining == 0 || !shade::worth_tracing(weight[i] * sec.factor, remaining, self.bound, self.k_max) {
                    continue;
                }
                weight[i] *= sec.factor;
                let side = if sec.same_side { s.geometric } else { -s.geometric };
                (next.rays[i], next.valid[i]) = (Ray::new(offset_origin(s.point, side), sec.dir), true);
            }
            if !next.valid.contains(&true) {
                break;
            }
            out.rays.secondary += count(&next.valid);
            rays = next;
            hits = lanes.closest(&rays);
        }
        out
    }
}

/// One light's unshadowed Phong term at a hit, and the shadow ray that decides whether it counts
/// (none when the term is zero: a light behind the surface needs no shadow ray). The shadow ray
/// leaves from the side of the surface the light is on and ends at the light.
fn light_query(m: &Material, surf: &Surface, ray: &Ray, light: &Light) -> (Vec3, Option<(Ray, f32)>) {
    let to = Vec3::from(light.position) - surf.point;
    let l = to.normalize_or_zero();
    let term = shade::phong(m, surf, ray.dir, l);
    if term == Vec3::ZERO {
        return (term, None);
    }
    let side = if surf.geometric.dot(l) >= 0.0 { surf.geometric } else { -surf.geometric };
    let o = offset_origin(surf.point, side);
    (term, Some((Ray::new(o, l), (Vec3::from(light.position) - o).length())))
}
