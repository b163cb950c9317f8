//! Whole images: primary rays per pixel, ray casting or Whitted shading, AOVs, rayon over rows.

use crate::Method;
use crate::geometry::{Cost, Hit, Ray, offset_origin};
use crate::shade::{self, Surface};
use crate::traverse::{self, Stack};
use bvh_format::{Light, Material, Node, SceneFile, Triangle};
use glam::Vec3;
use rayon::prelude::*;
use render_spec::{Aovs, BounceStop, Image, Mode, NO_TRIANGLE, RayCounts, RenderError, Settings};

/// The scene prepared for tracing: layouts, and the bounds behind the adaptive bounce stop.
pub struct Tracer<'a> {
    pub scene: &'a SceneFile,
    /// The triangles expanded to three vertices each, in leaf order (48 bytes per triangle).
    pub(crate) tris: Vec<Triangle>,
    child_pair: Option<&'a [Node]>,
    escape: Option<&'a [Node]>,
}

impl<'a> Tracer<'a> {
    pub fn new(scene: &'a SceneFile) -> Self {
        Self {
            scene,
            tris: scene.leaf_triangles(),
            child_pair: scene.child_pair.as_deref(),
            escape: scene.escape.as_deref(),
        }
    }

    /// The triangles as every path intersects them: three vertices each, in leaf order.
    pub fn triangles(&self) -> &[Triangle] {
        &self.tris
    }

    fn layout_for(&self, method: Method) -> Result<(), RenderError> {
        match method {
            Method::Stackless if self.escape.is_none() => {
                Err(RenderError::MissingLayout { method: method.name(), layout: "escape-pointer" })
            }
            Method::Ordered | Method::Packet if self.child_pair.is_none() => {
                Err(RenderError::MissingLayout { method: method.name(), layout: "child-pair" })
            }
            _ => Ok(()),
        }
    }

    /// Closest hit in `(t_min, t_max]`; adds the work done to `cost`.
    pub fn closest(
        &self,
        method: Method,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        stack: &mut Stack,
        cost: &mut Cost,
    ) -> Option<Hit> {
        self.trace::<false>(method, ray, t_min, t_max, stack, cost)
    }

    /// Whether anything lies in `(0, t_max]` along the ray.
    pub fn occluded(&self, method: Method, ray: &Ray, t_max: f32, stack: &mut Stack, cost: &mut Cost) -> bool {
        self.trace::<true>(method, ray, 0.0, t_max, stack, cost).is_some()
    }

    /// The scalar traversal `method` names, on the layout it reads (or whichever is present).
    fn trace<const ANY: bool>(
        &self,
        method: Method,
        ray: &Ray,
        t_min: f32,
        t_max: f32,
        stack: &mut Stack,
        cost: &mut Cost,
    ) -> Option<Hit> {
        let tris = &self.tris;
        match (method, self.child_pair, self.escape) {
            (Method::Stackless, _, Some(esc)) | (_, None, Some(esc)) => {
                traverse::escape::<ANY>(esc, tris, ray, t_min, t_max, cost)
            }
            (_, Some(cp), _) => traverse::child_pair::<ANY>(cp, tris, ray, t_min, t_max, stack, cost),
            (_, None, None) => None,
        }
    }

    fn surface(&self, ray: &Ray, hit: &Hit) -> Surface {
        let i = hit.tri as usize;
        shade::surface(&self.tris[i], self.scene.vertex_normals(i), ray.origin, ray.dir, hit.t, hit.u, hit.v)
    }
}

/// One pixel's result.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Sample {
    pub colour: Vec3,
    pub t: f32,
    pub normal: Vec3,
    pub prim: u32,
    pub cost: Cost,
    pub rays: RayCounts,
}

/// Per-frame constants of the Whitted pipeline.
pub(crate) struct Shading<'a> {
    pub mode: Mode,
    pub lights: &'a [Light],
    pub max_indirections: u32,
    pub ambient: Vec3,
    pub background: Vec3,
    pub stop: BounceStop,
    pub method: Method,
}

impl<'a> Shading<'a> {
    pub fn new(scene: &SceneFile, s: &'a Settings, method: Method) -> Self {
        let ambient = Vec3::from(scene.settings.ambient);
        let background = Vec3::from(scene.settings.background);
        Self {
            mode: s.mode,
            lights: &s.lights,
            max_indirections: s.max_indirections,
            ambient,
            background,
            stop: BounceStop::new(scene, &s.lights),
            // Secondary and shadow rays are incoherent: the SIMD packet path traces them one by one.
            method: if method == Method::Packet { Method::Ordered } else { method },
        }
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

/// [`light_query`] for a primary hit, for the packet path.
pub(crate) fn shadow_query(tracer: &Tracer<'_>, ray: &Ray, hit: &Hit, light: &Light) -> (Vec3, Option<(Ray, f32)>) {
    let scene = tracer.scene;
    let m = &scene.materials[scene.triangles[hit.tri as usize].material as usize];
    light_query(m, &tracer.surface(ray, hit), ray, light)
}

/// Shades one primary ray whose closest hit is already known (`primary`, found with `cost`), and
/// follows its shadow and secondary rays. `shadowed`, when given, holds the primary hit's shadow
/// test per light (a packet path traced those together).
pub(crate) fn shade_pixel(
    tracer: &Tracer<'_>,
    sh: &Shading<'_>,
    ray: Ray,
    primary: Option<Hit>,
    mut cost: Cost,
    shadowed: Option<&[bool]>,
    stack: &mut Stack,
) -> Sample {
    let scene = tracer.scene;
    let mut rays = RayCounts { primary: 1, ..RayCounts::default() };
    let Some(hit) = primary else {
        return Sample { colour: sh.background, t: f32::INFINITY, normal: Vec3::ZERO, prim: NO_TRIANGLE, cost, rays };
    };
    let surf = tracer.surface(&ray, &hit);
    let mut sample = Sample {
        colour: Vec3::ZERO,
        t: hit.t,
        normal: surf.shading,
        prim: scene.input_index[hit.tri as usize],
        cost,
        rays,
    };
    if sh.mode == Mode::Cast {
        let m = &scene.materials[scene.triangles[hit.tri as usize].material as usize];
        sample.colour = shade::cast(m, &surf, ray.dir);
        return sample;
    }

    let mut colour = Vec3::ZERO;
    let mut weight = 1.0f32;
    let mut ray = ray;
    let mut hit = hit;
    let mut surf = surf;
    let mut depth = 0u32;
    loop {
        let m = &scene.materials[scene.triangles[hit.tri as usize].material as usize];
        let mut local = sh.ambient * Vec3::from(m.kd);
        for (li, light) in sh.lights.iter().enumerate() {
            let (term, shadow) = light_query(m, &surf, &ray, light);
            let Some((sray, t_max)) = shadow else { continue };
            let blocked = match shadowed.filter(|_| depth == 0) {
                Some(s) => s[li],
                None => {
                    rays.shadow += 1;
                    tracer.occluded(sh.method, &sray, t_max, stack, &mut cost)
                }
            };
            if !blocked {
                local += Vec3::from(light.colour) * term;
            }
        }
        colour += weight * local;

        let Some(next) = shade::secondary(m, &surf, ray.dir) else { break };
        let remaining = sh.max_indirections - depth;
        if remaining == 0 || !sh.stop.worth_tracing(weight * next.factor, remaining) {
            break;
        }
        weight *= next.factor;
        depth += 1;
        let side = if next.same_side { surf.geometric } else { -surf.geometric };
        ray = Ray::new(offset_origin(surf.point, side), next.dir);
        rays.secondary += 1;
        match tracer.closest(sh.method, &ray, 0.0, f32::INFINITY, stack, &mut cost) {
            Some(h) => {
                surf = tracer.surface(&ray, &h);
                hit = h;
            }
            None => {
                colour += weight * sh.background;
                break;
            }
        }
    }
    sample.colour = colour;
    sample.cost = cost;
    sample.rays = rays;
    sample
}

/// Renders an image with `method`. Pixels are independent, so the result does not depend on the
/// thread count.
pub fn render(tracer: &Tracer<'_>, settings: &Settings, method: Method) -> Result<Image, RenderError> {
    let frame = settings.frame()?;
    let method = method.resolve(tracer.scene);
    tracer.layout_for(method)?;
    let (w, h) = (settings.width as usize, settings.height as usize);
    let sh = Shading::new(tracer.scene, settings, method);
    let mut samples = vec![Sample::default(); w * h];
    // Pairs of rows: the packet path traces 4 x 2 blocks.
    samples.par_chunks_mut(2 * w).enumerate().for_each_init(Stack::default, |stack, (pair, rows)| {
        let y0 = (pair * 2) as u32;
        if method == Method::Packet {
            crate::packet::render_rows(tracer, &sh, &frame, y0, rows, w, stack);
            return;
        }
        for (i, s) in rows.iter_mut().enumerate() {
            let (x, y) = ((i % w) as u32, y0 + (i / w) as u32);
            let ray = Ray::new(frame.eye, frame.direction(x, y));
            let mut cost = Cost::default();
            let hit = tracer.closest(method, &ray, 0.0, f32::INFINITY, stack, &mut cost);
            *s = shade_pixel(tracer, &sh, ray, hit, cost, None, stack);
        }
    });

    let rays = samples.par_iter().map(|s| s.rays).reduce(RayCounts::default, |a, b| a + b);
    let rgb = samples.iter().map(|s| shade::to_u8(s.colour)).collect();
    let aov = settings.aovs.then(|| Aovs {
        t: samples.iter().map(|s| s.t).collect(),
        normal: samples.iter().map(|s| s.normal.to_array()).collect(),
        prim: samples.iter().map(|s| s.prim).collect(),
        nodes: samples.iter().map(|s| s.cost.nodes).collect(),
        tris: samples.iter().map(|s| s.cost.tris).collect(),
    });
    Ok(Image { width: settings.width, height: settings.height, rgb, aov, rays })
}
