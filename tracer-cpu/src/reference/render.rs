//! Reference images: docs/shading.md evaluated in f64 for every sample of every pixel.
//!
//! The same model as the fast tracers, with f64 arithmetic and without their shortcuts:
//!
//! - Primary rays: the camera of docs/shading.md computed in f64 from the settings' camera (its f32
//!   values widened), through the sub-pixel positions every tracer takes
//!   ([`sample_offsets`]).
//! - Hits: the f64 walk of [`super::Bvh`], equal to brute force; shadow rays any-hit.
//! - Shading: Lambert, Phong and ambient, reflection and refraction directions, all in f64.
//! - Origins of shadow and secondary rays: the scale-aware offset of Wächter and Binder in f64
//!   units in the last place ([`offset_origin`]).
//! - Every secondary ray up to the indirection limit is traced: no adaptive stop.
//! - Of the settings' [`render_spec::Accuracy`], only the samples per pixel count: the reference
//!   always takes the edge-consistent triangle test, its own offset and no cutoff.
//! - A pixel's colour is the mean of its samples' linear colours; the 8-bit image quantises that
//!   mean as the fast tracers do (clamp to [0, 1], scale by 255, round to nearest).

use super::brute::RefHit;
use super::bvh::{Bvh, Ray64, Stack};
use crate::geometry::Cost;
use bvh_format::{Material, SceneFile};
use glam::DVec3;
use rayon::prelude::*;
use render_spec::accuracy::sample_positions;
use render_spec::{Aovs, Image, Mode, NO_TRIANGLE, RayCounts, RenderError, Settings};

/// A reference render: the 8-bit image every tracer writes, and the linear colours it was
/// quantised from, for metrics.
#[derive(Clone, Debug)]
pub struct ReferenceImage {
    /// The 8-bit image (with AOVs when the settings ask for them: `t`, `N`, `prim` of the first
    /// sample, `nodes` and `tris` summed over all samples of the pixel), and the rays traced.
    pub image: Image,
    /// Linear RGB per pixel, row-major from the top-left: the mean of the samples' f64 colours,
    /// rounded once to f32 (not clamped).
    pub linear: Vec<[f32; 3]>,
}

/// Renders the reference image of `scene` with `settings` (docs/shading.md in f64; the module
/// documentation lists what differs from a fast render). Pixels are independent, so the result
/// does not depend on the thread count. The errors are those of a fast render: a bad camera, size
/// or sample count, or a file without a tree.
pub fn render(scene: &SceneFile, settings: &Settings) -> Result<ReferenceImage, RenderError> {
    render_with_progress(scene, settings, &|_| {})
}

/// [`render`], calling `progress` with the number of rows finished each time one is done (from any
/// worker thread).
pub fn render_with_progress(
    scene: &SceneFile,
    settings: &Settings,
    progress: &(dyn Fn(u32) + Sync),
) -> Result<ReferenceImage, RenderError> {
    // Bands of rows in parallel, each written out before the next: the pixels' records (about 100
    // bytes each) are held for one band, not for a whole image of up to 2^28 pixels.
    let band_rows = (BAND_PIXELS / settings.width.max(1) as usize).max(16);
    render_in_bands(scene, settings, progress, band_rows)
}

/// [`render_with_progress`] in bands of `band_rows` rows.
fn render_in_bands(
    scene: &SceneFile,
    settings: &Settings,
    progress: &(dyn Fn(u32) + Sync),
    band_rows: usize,
) -> Result<ReferenceImage, RenderError> {
    let shading = Shading::new(scene, settings)?;
    let (w, h) = (settings.width as usize, settings.height as usize);
    let mut rgb = Vec::with_capacity(w * h);
    let mut linear = Vec::with_capacity(w * h);
    let mut aov = settings.aovs.then(|| Aovs {
        t: Vec::with_capacity(w * h),
        normal: Vec::with_capacity(w * h),
        prim: Vec::with_capacity(w * h),
        nodes: Vec::with_capacity(w * h),
        tris: Vec::with_capacity(w * h),
    });
    let mut rays = RayCounts::default();
    for y0 in (0..h).step_by(band_rows) {
        let rows: Vec<Vec<Pixel>> = (y0..(y0 + band_rows).min(h))
            .into_par_iter()
            .map_init(Stack::new, |stack, y| {
                let row = (0..settings.width).map(|x| shading.pixel(x, y as u32, stack)).collect();
                progress(1);
                row
            })
            .collect();
        for p in rows.iter().flatten() {
            rgb.push(to_u8(p.colour));
            linear.push(p.colour.as_vec3().to_array());
            rays = rays + p.rays;
            if let Some(a) = &mut aov {
                a.t.push(p.t as f32);
                a.normal.push(p.normal.as_vec3().to_array());
                a.prim.push(p.prim);
                a.nodes.push(p.cost.nodes);
                a.tris.push(p.cost.tris);
            }
        }
    }
    Ok(ReferenceImage { image: Image { width: settings.width, height: settings.height, rgb, aov, rays }, linear })
}

/// Pixels of one band of rows rendered in parallel (a 640-pixel-wide image is one band).
const BAND_PIXELS: usize = 1 << 18;

/// The sub-pixel positions of a pixel's samples in `[0, 1)^2`, in the order they are summed: the
/// positions both fast tracers take ([`render_spec::accuracy::sample_positions`] of the settings'
/// samples per pixel), widened to f64.
pub fn sample_offsets(settings: &Settings) -> Vec<(f64, f64)> {
    sample_positions(settings.accuracy.spp).map(|(x, y)| (f64::from(x), f64::from(y))).collect()
}

/// Linear radiance to 8 bits as the fast tracers quantise it: clamp to [0, 1], scale by 255, round
/// to nearest (a NaN gives 0).
pub fn to_u8(c: DVec3) -> [u8; 3] {
    let q = |x: f64| (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    [q(c.x), q(c.y), q(c.z)]
}

/// The camera of docs/shading.md in f64.
#[derive(Clone, Copy, Debug)]
pub struct Frame64 {
    pub eye: DVec3,
    pub top_left: DVec3,
    pub h_step: DVec3,
    pub v_step: DVec3,
}

impl Frame64 {
    /// The settings' camera for their image size; the errors of [`Settings::frame`].
    pub fn new(settings: &Settings) -> Result<Self, RenderError> {
        settings.frame()?;
        let c = &settings.camera;
        let (eye, at, up) = (c.eye.as_dvec3(), c.at.as_dvec3(), c.up.as_dvec3());
        let f = (at - eye).normalize_or_zero();
        let r = f.cross(up).normalize_or_zero();
        if f == DVec3::ZERO || r == DVec3::ZERO {
            return Err(RenderError::DegenerateCamera);
        }
        let u = r.cross(f);
        let t = (f64::from(c.fov_deg).to_radians() * 0.5).tan();
        let (w, h) = (f64::from(settings.width), f64::from(settings.height));
        let a = w / h;
        Ok(Self { eye, top_left: f - t * a * r + t * u, h_step: 2.0 * t * a * r / w, v_step: -2.0 * t * u / h })
    }

    /// The unit direction through the image point (`x`, `y`), in pixels from the top-left corner
    /// (pixel (i, j)'s centre is (i + 0.5, j + 0.5)).
    pub fn direction(&self, x: f64, y: f64) -> DVec3 {
        (self.top_left + x * self.h_step + y * self.v_step).normalize()
    }
}

/// Origin offset in f64, the analogue of the f32 one ([`crate::geometry::offset_origin`]): 256
/// units in the last place per unit of the normal's component, and near zero (below 1/32, as in
/// f32) an absolute step. That step keeps the f32 constants' ratio to the integer step at the
/// threshold (2^-16 against 256 f32 ulps of 1/32, 2^-20): 16 x 256 f64 ulps of 1/32, 2^-45.
pub const OFFSET_ORIGIN: f64 = 1.0 / 32.0;
/// See [`OFFSET_ORIGIN`].
pub const OFFSET_FLOAT_SCALE: f64 = 1.0 / (1u64 << 45) as f64;
/// See [`OFFSET_ORIGIN`].
pub const OFFSET_INT_SCALE: f64 = 256.0;

/// Moves a ray origin off the surface along the unit normal `n` (pointing to the side the new ray
/// leaves into) by a few f64 units in the last place of its coordinates: the scale-aware offset
/// of the fast tracers (Wächter and Binder 2019), about 2^29 times smaller.
pub fn offset_origin(p: DVec3, n: DVec3) -> DVec3 {
    let step = |p: f64, n: f64| {
        if p.abs() < OFFSET_ORIGIN {
            return p + OFFSET_FLOAT_SCALE * n;
        }
        let o = (n * OFFSET_INT_SCALE) as i64;
        let bits = p.to_bits() as i64;
        f64::from_bits((if p < 0.0 { bits.wrapping_sub(o) } else { bits.wrapping_add(o) }) as u64)
    };
    DVec3::new(step(p.x, n.x), step(p.y, n.y), step(p.z, n.z))
}

/// A hit's surface (docs/shading.md, "Surfaces") in f64.
#[derive(Clone, Copy, Debug)]
struct Surface {
    point: DVec3,
    /// Unit geometric normal facing the incoming ray.
    geometric: DVec3,
    /// Unit shading normal on the geometric normal's side.
    shading: DVec3,
    /// Whether the ray hit the front (the side `cross(p1 - p0, p2 - p0)` points to).
    front: bool,
}

fn d3(v: [f32; 3]) -> DVec3 {
    DVec3::from(v.map(f64::from))
}

fn surface(bvh: &Bvh<'_>, ray: &Ray64, hit: &RefHit) -> Surface {
    let [p0, p1, p2] = bvh.triangles()[hit.tri as usize].vertices().map(d3);
    let point = ray.origin + ray.dir * hit.t;
    // A degenerate (zero-area) triangle has no normal of its own: face the ray.
    let ng = (p1 - p0).cross(p2 - p0).try_normalize().unwrap_or(-ray.dir);
    let front = ray.dir.dot(ng) < 0.0;
    let geometric = if front { ng } else { -ng };
    let shading = match bvh.scene.vertex_normals(hit.tri as usize) {
        None => geometric,
        Some([n0, n1, n2]) => {
            let interp = d3(n0) * (1.0 - hit.u - hit.v) + d3(n1) * hit.u + d3(n2) * hit.v;
            match interp.try_normalize() {
                Some(s) if s.dot(geometric) < 0.0 => -s,
                Some(s) => s,
                None => geometric,
            }
        }
    };
    Surface { point, geometric, shading, front }
}

fn reflect(dir: DVec3, n: DVec3) -> DVec3 {
    dir - n * (2.0 * dir.dot(n))
}

/// Snell's law for the unit `dir` through a surface with unit normal `n` facing it, `eta` the
/// ratio of the indices (incoming over far side); `None` on total internal reflection.
fn refract(dir: DVec3, n: DVec3, eta: f64) -> Option<DVec3> {
    let cos_i = -dir.dot(n);
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    (k >= 0.0).then(|| (dir * eta + n * (eta * cos_i - k.sqrt())).normalize())
}

/// `kd cos(theta) + ks cos(phi)^n` of one unshadowed light, zero when it is behind the shading
/// normal.
fn phong(m: &Material, s: &Surface, dir: DVec3, to_light: DVec3) -> DVec3 {
    let cos_t = s.shading.dot(to_light);
    if cos_t <= 0.0 {
        return DVec3::ZERO;
    }
    let cos_p = reflect(-to_light, s.shading).dot(-dir).max(0.0);
    let n = f64::from(m.shininess);
    let spec = if n > 0.0 { cos_p.powf(n) } else { 1.0 };
    d3(m.kd) * cos_t + d3(m.ks) * spec
}

/// A material's secondary ray: its direction, whether it leaves into the incoming side, and the
/// factor of its weight (docs/shading.md, "Secondary ray").
fn secondary(m: &Material, s: &Surface, dir: DVec3) -> Option<(DVec3, bool, f64)> {
    if m.kr > 0.0 {
        return Some((reflect(dir, s.shading), true, f64::from(m.kr)));
    }
    if m.kt > 0.0 {
        let ior = f64::from(m.ior);
        let eta = if s.front { 1.0 / ior } else { ior };
        return Some(match refract(dir, s.shading, eta) {
            Some(t) => (t, false, f64::from(m.kt)),
            None => (reflect(dir, s.shading), true, f64::from(m.kt)),
        });
    }
    None
}

/// One pixel's result: the mean colour of its samples, the first sample's primary hit, and the
/// work and rays of all samples.
struct Pixel {
    colour: DVec3,
    t: f64,
    normal: DVec3,
    prim: u32,
    cost: Cost,
    rays: RayCounts,
}

/// Per-frame constants.
struct Shading<'a> {
    bvh: Bvh<'a>,
    frame: Frame64,
    offsets: Vec<(f64, f64)>,
    mode: Mode,
    /// Position and colour of each light.
    lights: Vec<(DVec3, DVec3)>,
    ambient: DVec3,
    background: DVec3,
    max_indirections: u32,
}

impl<'a> Shading<'a> {
    fn new(scene: &'a SceneFile, settings: &Settings) -> Result<Self, RenderError> {
        if !matches!(settings.mode, Mode::Cast | Mode::Whitted) {
            return Err(RenderError::ModeUnsupported { renderer: "the exact reference", mode: settings.mode.name() });
        }
        Ok(Self {
            frame: Frame64::new(settings)?,
            bvh: Bvh::new(scene)?,
            offsets: sample_offsets(settings),
            mode: settings.mode,
            lights: settings.lights.iter().map(|l| (d3(l.position), d3(l.colour))).collect(),
            ambient: d3(scene.settings.ambient),
            background: d3(scene.settings.background),
            max_indirections: settings.max_indirections,
        })
    }

    fn pixel(&self, x: u32, y: u32, stack: &mut Stack) -> Pixel {
        let mut p = Pixel {
            colour: DVec3::ZERO,
            t: f64::INFINITY,
            normal: DVec3::ZERO,
            prim: NO_TRIANGLE,
            cost: Cost::default(),
            rays: RayCounts::default(),
        };
        for (i, &(sx, sy)) in self.offsets.iter().enumerate() {
            let dir = self.frame.direction(f64::from(x) + sx, f64::from(y) + sy);
            let c = self.radiance(Ray64::new(self.frame.eye, dir), &mut p, i == 0, stack);
            p.colour += c;
        }
        p.colour /= self.offsets.len() as f64;
        p
    }

    /// The linear colour of one primary ray, following its secondary rays to the end; records the
    /// primary hit into `p` when `first`, and the work and rays always.
    fn radiance(&self, mut ray: Ray64, p: &mut Pixel, first: bool, stack: &mut Stack) -> DVec3 {
        let scene = self.bvh.scene;
        let mut colour = DVec3::ZERO;
        let mut weight = 1.0f64;
        p.rays.primary += 1;
        let mut depth = 0u32;
        loop {
            let Some(hit) = self.bvh.closest(&ray, 0.0, stack, &mut p.cost) else {
                return colour + self.background * weight;
            };
            let s = surface(&self.bvh, &ray, &hit);
            if depth == 0 && first {
                p.t = hit.t;
                p.normal = s.shading;
                p.prim = scene.input_index[hit.tri as usize];
            }
            let m = &scene.materials[scene.triangles[hit.tri as usize].material as usize];
            if self.mode == Mode::Cast {
                return d3(m.kd) * s.shading.dot(-ray.dir).max(0.0);
            }
            let mut local = self.ambient * d3(m.kd);
            for &(position, light) in &self.lights {
                let l = (position - s.point).normalize_or_zero();
                let term = phong(m, &s, ray.dir, l);
                if term == DVec3::ZERO {
                    continue;
                }
                let side = if s.geometric.dot(l) >= 0.0 { s.geometric } else { -s.geometric };
                let from = offset_origin(s.point, side);
                p.rays.shadow += 1;
                if !self.bvh.occluded(&Ray64::new(from, l), 0.0, (position - from).length(), stack, &mut p.cost) {
                    local += term * light;
                }
            }
            colour += local * weight;
            if depth == self.max_indirections {
                return colour;
            }
            let Some((dir, same_side, factor)) = secondary(m, &s, ray.dir) else {
                return colour;
            };
            weight *= factor;
            let from = offset_origin(s.point, if same_side { s.geometric } else { -s.geometric });
            ray = Ray64::new(from, dir);
            p.rays.secondary += 1;
            depth += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offset_origin_moves_every_coordinate_to_the_normals_side() {
        for p in [0.0, 1e-300, 1e-3, 0.03125, 1.0, 7.5e3, 1e12] {
            for sign in [1.0, -1.0] {
                let q = DVec3::splat(p * sign);
                let n = DVec3::new(1.0, -1.0, 0.5).normalize();
                let o = offset_origin(q, n);
                for a in 0..3 {
                    assert!((o[a] - q[a]) * n[a] > 0.0, "{q:?} along {n:?} gave {o:?}");
                    // Tiny: at most 256 ulps or the absolute step near zero.
                    let bound = (q[a].abs() * 256.0 * f64::EPSILON).max(OFFSET_FLOAT_SCALE);
                    assert!((o[a] - q[a]).abs() <= bound, "{q:?}: moved by {}", o[a] - q[a]);
                }
            }
        }
    }

    #[test]
    fn bands_do_not_change_the_image() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes/room.toml");
        let scene = bvh_build::import::load(&path, &Default::default()).unwrap();
        let scene = bvh_build::compile(&scene, &Default::default(), Default::default()).unwrap();
        let settings = Settings {
            aovs: true,
            accuracy: render_spec::Accuracy { spp: 4, ..Default::default() },
            ..Settings::of_scene(&scene, render_spec::CameraSpec::from(&scene.cameras[0]), Mode::Whitted, (23, 17))
        };
        let rows = std::sync::atomic::AtomicU32::new(0);
        let count = |n: u32| {
            rows.fetch_add(n, std::sync::atomic::Ordering::Relaxed);
        };
        let one = render_in_bands(&scene, &settings, &count, 1000).unwrap();
        let many = render_in_bands(&scene, &settings, &count, 5).unwrap();
        assert_eq!(rows.into_inner(), 2 * 17, "progress counts every row once");
        assert_eq!((&one.image.rgb, &one.linear, &one.image.aov), (&many.image.rgb, &many.linear, &many.image.aov));
        assert_eq!(one.image.rays, many.image.rays);
        assert_eq!(one.image.rays.primary, 23 * 17 * 4);
    }

    #[test]
    fn quantisation_matches_the_fast_tracers() {
        for x in [-1.0f32, 0.0, 0.5 / 255.0, 0.3, 0.5, 127.5 / 255.0, 0.999, 1.0, 2.0] {
            let fast = crate::shade::to_u8(glam::Vec3::splat(x));
            assert_eq!(to_u8(DVec3::splat(f64::from(x))), fast, "{x}");
        }
    }
}
