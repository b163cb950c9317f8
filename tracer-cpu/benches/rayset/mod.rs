//! The ray sets and tracer runners shared by `benches/rays.rs` and `examples/ray_report.rs`, so
//! that the criterion bench and the whole-run report measure exactly the same thing.
//!
//! A ray set is generated once per (scene, resolution) and then traced unchanged by every tracer:
//! one slot per pixel (row-major), empty where the pixel has no ray of that kind, so that packet
//! tracers can group the same 4 x 2 pixel blocks the renderer groups.
#![allow(dead_code)]

use bvh_format::SceneFile;
use glam::Vec3;
use rayon::prelude::*;
use render_spec::{CameraSpec, Intersect, sequence};
use std::path::Path;
use std::time::Instant;
use tracer_cpu::bvh8::Simd;
use tracer_cpu::geometry::{Cost, Hit, Ray, Watertight, offset_origin};
use tracer_cpu::packet::{self, LANES, Rays};
use tracer_cpu::packet8;
use tracer_cpu::traverse::Stack;
use tracer_cpu::{Method, Tracer, Walk, shade};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// From the "medium" camera, one per pixel.
    Primary,
    /// From each primary hit to the scene's first light, any hit ends it.
    Shadow,
    /// The mirror reflection of each primary ray at its hit.
    Secondary,
    /// An ambient-occlusion ray from each primary hit (`--mode ao`'s first: cosine-distributed
    /// about the geometric normal, the default length), any hit ends it.
    Ao,
    /// A diffuse bounce from each primary hit (`--mode diffuse`'s: the same direction as the AO
    /// ray, no length limit), closest hit.
    Diffuse,
}

impl Kind {
    pub const ALL: [Kind; 5] = [Kind::Primary, Kind::Shadow, Kind::Secondary, Kind::Ao, Kind::Diffuse];
    pub fn name(self) -> &'static str {
        match self {
            Kind::Primary => "primary",
            Kind::Shadow => "shadow",
            Kind::Secondary => "secondary",
            Kind::Ao => "ao",
            Kind::Diffuse => "diffuse",
        }
    }

    /// Whether any hit ends the ray (occlusion), rather than the closest hit being wanted.
    pub fn any_hit(self) -> bool {
        matches!(self, Kind::Shadow | Kind::Ao)
    }
}

/// One ray per pixel slot (with its `t_max`), or none.
pub struct RaySet {
    pub kind: Kind,
    pub width: usize,
    pub height: usize,
    pub rays: Vec<Option<(Ray, f32)>>,
    /// Rays present.
    pub count: usize,
}

impl RaySet {
    fn new(kind: Kind, width: usize, height: usize, rays: Vec<Option<(Ray, f32)>>) -> Self {
        let count = rays.iter().filter(|r| r.is_some()).count();
        Self { kind, width, height, rays, count }
    }
}

/// Imports and compiles a scene with both node layouts and the default build parameters (what
/// `tools::compile_default` does, without depending on the tools crate).
pub fn load(path: &Path) -> Result<SceneFile, String> {
    let scene = bvh_build::import::load(path, &Default::default()).map_err(|e| format!("{}: {e}", path.display()))?;
    bvh_build::compile(&scene, &Default::default(), Default::default()).map_err(|e| format!("{}: {e}", path.display()))
}

/// A compiled scene file (`.bvh`) as it is, anything else through [`load`].
pub fn open(path: &Path) -> Result<SceneFile, String> {
    if path.extension().is_some_and(|e| e == "bvh") {
        bvh_format::read_file(path).map_err(|e| format!("{}: {e}", path.display()))
    } else {
        load(path)
    }
}

/// The ray sets of a scene at `width` x `height`, one of each [`Kind`] in [`Kind::ALL`]'s order.
/// Primary hits are found with our ordered traversal; the other rays' origins are offset and
/// their directions drawn exactly as the renderer does it.
pub fn generate(scene: &SceneFile, width: u32, height: u32) -> Result<[RaySet; 5], String> {
    let cam = scene.camera("medium").ok_or("the scene has no camera named \"medium\"")?;
    let frame = CameraSpec::from(cam).frame(width, height).map_err(|e| format!("camera: {e:?}"))?;
    let light = Vec3::from(scene.lights.first().ok_or("the scene has no light")?.position);
    let tracer = Tracer::new(scene);
    let walk = tracer.walk(Method::Ordered).map_err(|e| e.to_string())?;
    let (lo, hi) = scene.bounds();
    let ao_length = render_spec::Ao::default().distance(lo, hi);
    let (w, h) = (width as usize, height as usize);
    let per_pixel: Vec<_> = (0..w * h)
        .into_par_iter()
        .map_init(Stack::default, |stack, i| {
            let ray = Ray::new(frame.eye, frame.direction((i % w) as u32, (i / w) as u32));
            let hit = walk.closest(&ray, 0.0, f32::INFINITY, stack, &mut Cost::default());
            let Some(hit) = hit else { return [Some((ray, f32::INFINITY)), None, None, None, None] };
            let k = hit.tri as usize;
            let surf =
                shade::surface(&scene.triangle(k), scene.vertex_normals(k), ray.origin, ray.dir, hit.t, hit.u, hit.v);
            let to = light - surf.point;
            let shadow = (to != Vec3::ZERO).then(|| {
                let l = to.normalize();
                let side = if surf.geometric.dot(l) >= 0.0 { surf.geometric } else { -surf.geometric };
                let o = offset_origin(surf.point, side);
                (Ray::new(o, l), (light - o).length())
            });
            let mirror = shade::reflect(ray.dir, surf.shading);
            let off = offset_origin(surf.point, surf.geometric);
            let secondary = (Ray::new(off, mirror), f32::INFINITY);
            let bounce = sequence::cosine_direction(surf.geometric.into(), sequence::sample_2d(i as u32, 0));
            let bounce = Ray::new(off, Vec3::from(bounce));
            [
                Some((ray, f32::INFINITY)),
                shadow,
                Some(secondary),
                Some((bounce, ao_length)),
                Some((bounce, f32::INFINITY)),
            ]
        })
        .collect();
    let mut sets: [Vec<Option<(Ray, f32)>>; 5] = std::array::from_fn(|_| Vec::with_capacity(w * h));
    for pixel in per_pixel {
        for (set, r) in sets.iter_mut().zip(pixel) {
            set.push(r);
        }
    }
    let mut sets = sets.into_iter();
    Ok(Kind::ALL.map(|kind| RaySet::new(kind, w, h, sets.next().expect("one set per kind"))))
}

/// A way of tracing a ray set.
#[derive(Clone, Copy)]
pub enum Engine<'a> {
    /// Ours, one ray at a time (an ordered, stackless or bvh8 walk) with a triangle test.
    Scalar(Walk<'a>, Intersect),
    /// Ours, 8-wide AVX2 packets of 4 x 2 pixel blocks.
    Packet(&'a Tracer<'a>),
    /// Ours, the wide BVH one ray at a time on a chosen instruction set (the edge-consistent test).
    Bvh8(&'a Tracer<'a>, Simd),
    /// Ours, 8-wide AVX2 packets of 4 x 2 pixel blocks over the wide BVH (`packet8`).
    WidePacket(&'a Tracer<'a>),
    /// Embree, `rtcIntersect1` / `rtcOccluded1`.
    #[cfg(feature = "embree")]
    Embree1(&'a tracer_cpu::embree::Scene),
    /// Embree, `rtcIntersect8` / `rtcOccluded8` over the same 4 x 2 blocks.
    #[cfg(feature = "embree")]
    Embree8(&'a tracer_cpu::embree::Scene),
}

/// What a traced slot holds: the hit distance (closest hit) or 0 (occluded); +inf for a miss or
/// an unblocked shadow ray; NaN where the slot has no ray.
pub const NO_RAY: f32 = f32::NAN;

/// Traces every ray of `set` into `out` on the current rayon pool, in chunks of two rows (one row
/// of 4 x 2 blocks).
pub fn trace(engine: Engine<'_>, set: &RaySet, out: &mut [f32]) {
    let w = set.width;
    let any = set.kind.any_hit();
    set.rays.par_chunks(2 * w).zip(out.par_chunks_mut(2 * w)).for_each_init(
        || (Stack::default(), Vec::with_capacity(128)),
        |(stack, pstack), (rays, out)| match engine {
            Engine::Scalar(walk, test) => {
                let mut cost = Cost::default();
                for (r, o) in rays.iter().zip(out.iter_mut()) {
                    let Some((ray, t_max)) = r else { continue };
                    let ray = &like_embree(ray);
                    *o = if any {
                        if walk.occluded_with(test, ray, *t_max, stack, &mut cost) { 0.0 } else { f32::INFINITY }
                    } else {
                        walk.closest_with(test, ray, 0.0, *t_max, stack, &mut cost).map_or(f32::INFINITY, hit_t)
                    };
                }
            }
            Engine::Bvh8(tracer, simd) => {
                let bvh = tracer.bvh8().expect("the scene has the child-pair layout");
                let mut cost = Cost::default();
                for (r, o) in rays.iter().zip(out.iter_mut()) {
                    let Some((ray, t_max)) = r else { continue };
                    let ray = &like_embree(ray);
                    *o = if any {
                        let hit = bvh.trace_on::<true, Watertight>(simd, ray, 0.0, *t_max, stack, &mut cost);
                        if hit.is_some() { 0.0 } else { f32::INFINITY }
                    } else {
                        bvh.trace_on::<false, Watertight>(simd, ray, 0.0, *t_max, stack, &mut cost)
                            .map_or(f32::INFINITY, hit_t)
                    };
                }
            }
            Engine::WidePacket(tracer) => {
                let bvh = tracer.bvh8().expect("the scene has the child-pair layout");
                blocks(rays, out, w, |p| {
                    let res = if any {
                        packet8::trace::<true, Watertight>(bvh, p, pstack, stack)
                    } else {
                        packet8::trace::<false, Watertight>(bvh, p, pstack, stack)
                    };
                    std::array::from_fn(|i| match res.get(i) {
                        Some(_) if any => 0.0,
                        Some(h) => h.t,
                        None => f32::INFINITY,
                    })
                });
            }
            Engine::Packet(tracer) => {
                let nodes = tracer.scene.child_pair.as_deref().expect("the scene has the child-pair layout");
                let tris = tracer.triangles().expanded().expect("Tracer::new expands the triangles");
                blocks(rays, out, w, |p| {
                    let res = if any {
                        packet::trace::<true, Watertight>(nodes, tris, p, pstack)
                    } else {
                        packet::trace::<false, Watertight>(nodes, tris, p, pstack)
                    };
                    std::array::from_fn(|i| match res.get(i) {
                        Some(_) if any => 0.0,
                        Some(h) => h.t,
                        None => f32::INFINITY,
                    })
                });
            }
            #[cfg(feature = "embree")]
            Engine::Embree1(scene) => {
                let _mxcsr = FlushToZero::for_embree();
                for (r, o) in rays.iter().zip(out.iter_mut()) {
                    let Some((ray, t_max)) = r else { continue };
                    *o = if any {
                        if scene.occluded1(ray, *t_max) { 0.0 } else { f32::INFINITY }
                    } else {
                        scene.intersect1(ray, 0.0, *t_max).map_or(f32::INFINITY, |h| h.0)
                    };
                }
            }
            #[cfg(feature = "embree")]
            Engine::Embree8(scene) => {
                let _mxcsr = FlushToZero::for_embree();
                blocks(rays, out, w, |p| {
                    if any {
                        scene.occluded8(p).map(|b| if b { 0.0 } else { f32::INFINITY })
                    } else {
                        scene.intersect8(p).map(|h| h.map_or(f32::INFINITY, |h| h.0))
                    }
                })
            }
        },
    );
}

/// Flush-to-zero and denormals-are-zero set in this thread's MXCSR for as long as it lives, then
/// the old MXCSR back. Embree asks applications to set both (its device warns without them, "a
/// severe performance impact"); ours need neither and never run with them, since they would
/// change the results of our exact tests. Only with `EMBREE_FTZ=1` in the environment, for
/// measuring what they change (nothing above the noise on a Zen 4 or on the H200 host's Xeon:
/// docs/cpu-benchmark.md, Notes).
struct FlushToZero(Option<u32>);

/// Whether `EMBREE_FTZ=1` asks for [`FlushToZero`] in Embree's passes.
pub fn embree_ftz() -> bool {
    static ON: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *ON.get_or_init(|| std::env::var("EMBREE_FTZ").is_ok_and(|v| v == "1"))
}

impl FlushToZero {
    fn for_embree() -> Self {
        if !embree_ftz() {
            return Self(None);
        }
        #[cfg(target_arch = "x86_64")]
        {
            let mut old = 0u32;
            // SAFETY: stmxcsr stores the 32-bit MXCSR at the address given, a local of that size;
            // ldmxcsr loads a value that differs from the current one only in the FTZ (bit 15)
            // and DAZ (bit 6) flags, which every SSE-capable x86-64 CPU has.
            unsafe {
                std::arch::asm!("stmxcsr [{}]", in(reg) &raw mut old, options(nostack));
                let new = old | 1 << 15 | 1 << 6;
                std::arch::asm!("ldmxcsr [{}]", in(reg) &raw const new, options(nostack));
            }
            Self(Some(old))
        }
        #[cfg(not(target_arch = "x86_64"))]
        Self(None)
    }
}

impl Drop for FlushToZero {
    fn drop(&mut self) {
        #[cfg(target_arch = "x86_64")]
        if let Some(old) = self.0 {
            // SAFETY: loads the MXCSR `for_embree` found in this thread.
            unsafe { std::arch::asm!("ldmxcsr [{}]", in(reg) &raw const old, options(nostack)) };
        }
    }
}

/// The ray as our single-ray walks get it from an origin and a direction, its inverse direction
/// computed inside the timed loop: Embree's `rtcIntersect1` is handed only the origin and the
/// direction and computes its inverse per call, so ours pays for it too (the packets compute
/// theirs inside `trace` already).
#[inline(always)]
fn like_embree(ray: &Ray) -> Ray {
    Ray::new(ray.origin, ray.dir)
}

/// The distance of a closest hit, its barycentrics computed all the same: `rtcIntersect1` writes
/// them into every hit it returns, and the renderer reads them; inlined into the loop, ours
/// would otherwise be left out as unused.
fn hit_t(h: Hit) -> f32 {
    std::hint::black_box(h).t
}

/// Groups the slots of (up to) two rows into 4 x 2 packets as the renderer does, skipping
/// packets with no ray.
fn blocks(rays: &[Option<(Ray, f32)>], out: &mut [f32], w: usize, mut f: impl FnMut(&Rays) -> [f32; LANES]) {
    let h = rays.len() / w;
    for x0 in (0..w).step_by(4) {
        let mut p = Rays::default();
        for i in 0..LANES {
            let (x, dy) = (x0 + i % 4, i / 4);
            if x < w
                && dy < h
                && let Some((r, t)) = rays[dy * w + x]
            {
                p.set(i, &r, t);
            }
        }
        if !p.valid.contains(&true) {
            continue;
        }
        let res = f(&p);
        for i in 0..LANES {
            if p.valid[i] {
                out[(i / 4) * w + x0 + i % 4] = res[i];
            }
        }
    }
}

/// On how many of the rays two traced outputs agree (both miss or both unblocked, or both hit with
/// `|t - t_ref| <= 1e-4 t_ref`), and how many rays there are.
pub fn agreement(a: &[f32], reference: &[f32]) -> (usize, usize) {
    let (mut n, mut same) = (0usize, 0usize);
    for (&x, &r) in a.iter().zip(reference) {
        if r.is_nan() {
            continue;
        }
        n += 1;
        if (x.is_infinite() && r.is_infinite()) || (x - r).abs() <= 1e-4 * r.abs() {
            same += 1;
        }
    }
    (same, n)
}

/// What a pass is timed by.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Clock {
    /// Wall-clock time.
    Wall,
    /// CPU time of all the process's threads: on a machine shared with other work, time spent
    /// waiting for a core does not count (the figures are then rays per CPU-second).
    Cpu,
}

impl Clock {
    /// Seconds on this clock since some fixed start.
    pub fn now(self) -> f64 {
        match self {
            Clock::Wall => {
                static START: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
                START.get_or_init(Instant::now).elapsed().as_secs_f64()
            }
            Clock::Cpu => cpu_seconds(),
        }
    }
}

/// Nanoseconds on a CPU summed over the process's threads (Linux: the first field of each
/// thread's `schedstat`).
fn cpu_seconds() -> f64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else { return f64::NAN };
    let ns: u64 = tasks
        .filter_map(|t| std::fs::read_to_string(t.ok()?.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum();
    ns as f64 * 1e-9
}

/// Times passes of several tracers interleaved (one pass of each per round), so that a change in
/// the machine's load during the measurement hits all of them alike: at least `reps` rounds and
/// enough to fill `min_seconds` of timed passes, at most `max_rounds`. Returns each one's median
/// pass in seconds of wall-clock time. The caller warms up first.
///
/// Each timed pass comes right after an untimed pass of the same tracer, so that every tracer is
/// timed with its own data in the caches, as when it renders alone. Without it each was timed
/// after another's pass, and the one that followed a tracer of the same scene data (ours after
/// ours) read up to 9% faster on incoherent rays than in another place (docs/cpu-benchmark-log.md,
/// stop 34).
pub fn interleaved_medians(
    reps: usize,
    min_seconds: f64,
    max_rounds: usize,
    passes: &mut [&mut dyn FnMut()],
) -> Vec<f64> {
    interleaved_medians_on(Clock::Wall, reps, min_seconds, max_rounds, passes)
}

/// [`interleaved_medians`] on `clock`.
pub fn interleaved_medians_on(
    clock: Clock,
    reps: usize,
    min_seconds: f64,
    max_rounds: usize,
    passes: &mut [&mut dyn FnMut()],
) -> Vec<f64> {
    let mut samples = vec![Vec::new(); passes.len()];
    let mut round = 0usize;
    let mut elapsed = 0.0;
    loop {
        for (p, s) in passes.iter_mut().zip(samples.iter_mut()) {
            p();
            let start = clock.now();
            p();
            let t = clock.now() - start;
            elapsed += t;
            s.push(t);
        }
        round += 1;
        if round >= max_rounds.max(1) || (round >= reps.max(1) && elapsed >= min_seconds) {
            break;
        }
    }
    samples.into_iter().map(median).collect()
}

/// The median (the mean of the middle two for an even count).
pub fn median(mut t: Vec<f64>) -> f64 {
    t.sort_by(f64::total_cmp);
    let m = t.len() / 2;
    if t.len() % 2 == 1 { t[m] } else { 0.5 * (t[m - 1] + t[m]) }
}

/// The scenes directory of this checkout.
pub fn scenes_dir() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenes")
}

/// The load average over 1, 5 and 15 minutes, as /proc/loadavg gives it.
pub fn loadavg() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map_or("?".into(), |s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
}

/// The CPU's model name.
pub fn cpu_model() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| {
            s.lines().find(|l| l.starts_with("model name")).map(|l| l.split(':').nth(1).unwrap_or("").trim().to_owned())
        })
        .unwrap_or_else(|| "?".into())
}

/// Writes a report to `path` whole: under a temporary name beside it, renamed over `path` only
/// once complete, so that a failed or interrupted write leaves what was there before; a link is
/// followed to its file, a device or a pipe (`--out /dev/null`) written in place
/// ([`bvh_format::destination`]). The reports are written only where `--out` names a file: the
/// hand-written docs beside them are not theirs.
pub fn write_report(path: &Path, text: &str) -> Result<(), String> {
    let dir = path.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
    std::fs::create_dir_all(dir).map_err(|e| format!("cannot create the folder {}: {e}", dir.display()))?;
    bvh_format::destination::write_replacing(path, |w| std::io::Write::write_all(w, text.as_bytes()))
        .map_err(|e| format!("cannot write {}: {e}", path.display()))
}
