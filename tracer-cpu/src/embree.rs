//! Embree 3 over the very triangles a scene file stores, for the ray benchmark's comparison
//! (`--features embree`, needs libembree-dev). Nothing in rendering uses it.
//!
//! Built on the `embree` crate's raw `sys` bindings (bindgen output for Embree 3, with layout
//! tests) rather than its safe wrappers: those tie the committed scene to borrows of the scene and
//! the device, which cannot live in one struct, and do not wrap `rtcIntersect8`/`rtcOccluded8`.

use crate::geometry::Ray;
use crate::packet::{LANES, Rays};
use bvh_format::Triangle;
use embree::sys::*;
use std::ptr;
use std::sync::atomic::{AtomicIsize, Ordering};

/// Embree's scene flags that matter for the comparison.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flags {
    /// Embree's defaults: medium build quality, no flags.
    Default,
    /// `RTC_SCENE_FLAG_ROBUST`: no optimisations that lose accuracy (our traversal is
    /// conservative too, so this is the like-for-like setting).
    Robust,
}

/// A committed Embree scene of one triangle mesh, triangle `i` of the input being `primID` `i`.
pub struct Scene {
    device: RTCDevice,
    scene: RTCScene,
    /// Bytes Embree holds, as its memory monitor reports them (the monitor's user pointer).
    held: Box<AtomicIsize>,
    /// What the commit added to `held`: Embree's BVH and its copies of the triangles.
    bvh_bytes: isize,
}

/// Embree's memory monitor: keeps the running total of what the device holds.
unsafe extern "C" fn monitor(user: *mut std::os::raw::c_void, bytes: ssize_t, _post: bool) -> bool {
    // SAFETY: the user pointer is the scene's `held`, which outlives the device.
    unsafe { &*user.cast::<AtomicIsize>() }.fetch_add(bytes, Ordering::Relaxed);
    true
}

// SAFETY: Embree allows any number of threads to trace a committed scene at once; nothing here
// changes the scene after `new`, and the handles are released only in `drop`.
unsafe impl Send for Scene {}
unsafe impl Sync for Scene {}

// The valid masks of rtcIntersect8/rtcOccluded8 must be 32-byte aligned.
#[repr(C, align(32))]
struct Valid([i32; LANES]);

fn context(flags: RTCIntersectContextFlags) -> RTCIntersectContext {
    // What the header's inline rtcInitIntersectContext does, with the flags chosen.
    RTCIntersectContext { flags, filter: None, instID: [u32::MAX] }
}

/// Writes the ray into `dst` in Embree's layout as three whole 16-byte stores: Embree reads
/// `org`/`tnear`, `dir`/`time` and `tfar`/`mask`/`id`/`flags` as 16-byte vectors right after the
/// call, and a vector load of what several narrower stores have just written cannot be forwarded
/// from the store buffer: it waits for them to reach the cache. Built field by field, the
/// compiler stored `org_x, org_y` as 8 bytes and `org_z`, `tnear` as 4 bytes each, and
/// `rtcIntersect1` on the bunny's primary rays ran at 71-72% of the speed the same library
/// reaches with the ray stored whole (docs/cpu-benchmark-log.md, stop 33): the benchmark handicapped Embree.
/// The stores are volatile only so that the compiler keeps each one whole instead of splitting it
/// back into the fields it sees.
#[inline(always)]
fn write_ray(dst: *mut RTCRay, ray: &Ray, t_min: f32, t_max: f32) {
    let (o, d) = (ray.origin, ray.dir);
    let rows = [[o.x, o.y, o.z, t_min], [d.x, d.y, d.z, 0.0], [t_max, f32::from_bits(u32::MAX), 0.0, 0.0]];
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{__m128, _mm_loadu_ps};
        // RTCRay is 12 4-byte fields in this order, 48 bytes aligned to 16 (bindgen's layout
        // tests), as three `__m128` are; every bit pattern is a valid value of each field (floats
        // and u32s: mask all ones, id and flags 0).
        let p = dst.cast::<__m128>();
        for (k, r) in rows.iter().enumerate() {
            // SAFETY: `dst` is valid for writes of a whole, 16-byte aligned RTCRay (the caller's),
            // row `k` is its `k`-th 16 bytes; SSE is part of every x86-64 target.
            unsafe { std::ptr::write_volatile(p.add(k), _mm_loadu_ps(r.as_ptr())) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let [[org_x, org_y, org_z, tnear], [dir_x, dir_y, dir_z, time], [tfar, ..]] = rows;
        let r = RTCRay { org_x, org_y, org_z, tnear, dir_x, dir_y, dir_z, time, tfar, mask: u32::MAX, id: 0, flags: 0 };
        // SAFETY: `dst` is valid for writes (the caller's).
        unsafe { dst.write(r) };
    }
}

/// The device configuration `EMBREE_CONFIG` asks for (Embree's `rtcNewDevice` syntax), if any.
/// Embree 3 limits its code by what it calls the CPU's frequency level: on a CPU it does not know
/// it sets `simd256`, no optimization that would lower the clock below that of 256-bit code
/// (`verbose=3` prints the level and the kernels it picks; `frequency_level=simd512` lifts it).
pub fn config() -> Option<String> {
    std::env::var("EMBREE_CONFIG").ok().filter(|c| !c.is_empty())
}

/// An RTCHit that says "no hit yet".
fn no_hit() -> RTCHit {
    RTCHit { Ng_x: 0.0, Ng_y: 0.0, Ng_z: 0.0, u: 0.0, v: 0.0, primID: u32::MAX, geomID: u32::MAX, instID: [u32::MAX] }
}

impl Scene {
    /// Builds Embree's BVH over `tris` (each triangle's three vertices, unshared but bit-identical
    /// where triangles meet).
    ///
    /// The device gets the configuration string in `EMBREE_CONFIG`, if set (for measuring
    /// Embree's own settings, e.g. `frequency_level=simd512`; see [`config`]), else Embree's
    /// defaults.
    pub fn new(tris: &[Triangle], flags: Flags) -> Result<Self, String> {
        let n = tris.len();
        let config = config().map(std::ffi::CString::new).transpose().map_err(|_| "EMBREE_CONFIG holds a NUL byte")?;
        // SAFETY: every handle is checked before use; the buffers Embree allocates are written
        // within the sizes requested; `config` outlives the call that reads it.
        unsafe {
            let device = rtcNewDevice(config.as_ref().map_or(ptr::null(), |c| c.as_ptr()));
            if device.is_null() {
                return Err(format!("Embree: rtcNewDevice failed ({:?})", rtcGetDeviceError(ptr::null_mut())));
            }
            let held = Box::new(AtomicIsize::new(0));
            rtcSetDeviceMemoryMonitorFunction(device, Some(monitor), ptr::from_ref(&*held).cast_mut().cast());
            let scene = rtcNewScene(device);
            let mut this = Self { device, scene, held, bvh_bytes: 0 };
            if flags == Flags::Robust {
                rtcSetSceneFlags(scene, RTCSceneFlags::ROBUST);
            }
            let geom = rtcNewGeometry(device, RTCGeometryType::TRIANGLE);
            // A 16-byte stride keeps every vertex readable as a whole SIMD word, as Embree prefers.
            let verts = rtcSetNewGeometryBuffer(geom, RTCBufferType::VERTEX, 0, RTCFormat::FLOAT3, 16, 3 * n)
                .cast::<[f32; 4]>();
            let index =
                rtcSetNewGeometryBuffer(geom, RTCBufferType::INDEX, 0, RTCFormat::UINT3, 12, n).cast::<[u32; 3]>();
            if verts.is_null() || index.is_null() {
                rtcReleaseGeometry(geom);
                return Err(format!("Embree: cannot allocate buffers for {n} triangles"));
            }
            let verts = std::slice::from_raw_parts_mut(verts, 3 * n);
            let index = std::slice::from_raw_parts_mut(index, n);
            for (i, t) in tris.iter().enumerate() {
                for (k, v) in t.vertices().into_iter().enumerate() {
                    verts[3 * i + k] = [v[0], v[1], v[2], 0.0];
                }
                let b = 3 * i as u32;
                index[i] = [b, b + 1, b + 2];
            }
            rtcCommitGeometry(geom);
            rtcAttachGeometry(scene, geom);
            rtcReleaseGeometry(geom);
            let before = this.held.load(Ordering::Relaxed);
            rtcCommitScene(scene);
            this.bvh_bytes = this.held.load(Ordering::Relaxed) - before;
            match rtcGetDeviceError(device) {
                RTCError::NONE => Ok(this),
                e => Err(format!("Embree: building the scene failed ({e:?})")),
            }
        }
    }

    /// Bytes the commit left allocated (Embree's memory monitor): its BVH with its own copy of
    /// the triangles, the counterpart of [`crate::bvh8::WideBvh::bytes`].
    pub fn bvh_bytes(&self) -> usize {
        self.bvh_bytes.max(0) as usize
    }

    /// Closest hit in `[t_min, t_max]`: distance and triangle index.
    #[inline]
    pub fn intersect1(&self, ray: &Ray, t_min: f32, t_max: f32) -> Option<(f32, u32)> {
        let mut ctx = context(RTCIntersectContextFlags::INCOHERENT);
        let mut rh = std::mem::MaybeUninit::<RTCRayHit>::uninit();
        let p = rh.as_mut_ptr();
        // SAFETY: `p` points to an RTCRayHit; `write_ray` writes all of its ray, this its hit.
        let rh = unsafe {
            write_ray(&raw mut (*p).ray, ray, t_min, t_max);
            (&raw mut (*p).hit).write(no_hit());
            rh.assume_init_mut()
        };
        // SAFETY: the scene is committed; `ctx` and `rh` are valid and aligned for the call.
        unsafe { rtcIntersect1(self.scene, &mut ctx, rh) };
        (rh.hit.geomID != u32::MAX).then_some((rh.ray.tfar, rh.hit.primID))
    }

    /// Whether anything lies in `[0, t_max]`.
    #[inline]
    pub fn occluded1(&self, ray: &Ray, t_max: f32) -> bool {
        let mut ctx = context(RTCIntersectContextFlags::INCOHERENT);
        let mut r = std::mem::MaybeUninit::<RTCRay>::uninit();
        write_ray(r.as_mut_ptr(), ray, 0.0, t_max);
        // SAFETY: `write_ray` wrote every field.
        let r = unsafe { r.assume_init_mut() };
        // SAFETY: as in `intersect1`.
        unsafe { rtcOccluded1(self.scene, &mut ctx, r) };
        r.tfar == f32::NEG_INFINITY
    }

    /// Writes the packet into `ray` in Embree's 8-ray layout, in place, and returns the valid
    /// mask. In place rather than returned: a returned `RTCRay8` (384 bytes) was built on the
    /// stack and copied into the call's argument, work a caller that fills its packet where
    /// Embree reads it does not do.
    #[inline(always)]
    fn fill(rays: &Rays, ray: *mut RTCRay8) -> Valid {
        // SAFETY: `ray` is valid for writes of a whole RTCRay8 (the caller's); each field is
        // written once, every field is written.
        unsafe {
            (&raw mut (*ray).org_x).write(rays.origin[0]);
            (&raw mut (*ray).org_y).write(rays.origin[1]);
            (&raw mut (*ray).org_z).write(rays.origin[2]);
            (&raw mut (*ray).tnear).write([0.0; LANES]);
            (&raw mut (*ray).dir_x).write(rays.dir[0]);
            (&raw mut (*ray).dir_y).write(rays.dir[1]);
            (&raw mut (*ray).dir_z).write(rays.dir[2]);
            (&raw mut (*ray).time).write([0.0; LANES]);
            (&raw mut (*ray).tfar).write(rays.t_max);
            (&raw mut (*ray).mask).write([u32::MAX; LANES]);
            (&raw mut (*ray).id).write([0; LANES]);
            (&raw mut (*ray).flags).write([0; LANES]);
        }
        Valid(std::array::from_fn(|i| if rays.valid[i] { -1 } else { 0 }))
    }

    /// Closest hits of a packet (`t_min` 0, like [`crate::packet::trace`]), coherent context.
    #[inline]
    pub fn intersect8(&self, rays: &Rays) -> [Option<(f32, u32)>; LANES] {
        let mut ctx = context(RTCIntersectContextFlags::COHERENT);
        let mut rh = std::mem::MaybeUninit::<RTCRayHit8>::uninit();
        let p = rh.as_mut_ptr();
        let no_hit = RTCHit8 {
            Ng_x: [0.0; LANES],
            Ng_y: [0.0; LANES],
            Ng_z: [0.0; LANES],
            u: [0.0; LANES],
            v: [0.0; LANES],
            primID: [u32::MAX; LANES],
            geomID: [u32::MAX; LANES],
            instID: [[u32::MAX; LANES]],
        };
        // SAFETY: `p` points to an RTCRayHit8; `fill` writes all of its ray, this its hit.
        let (valid, rh) = unsafe {
            let valid = Self::fill(rays, &raw mut (*p).ray);
            (&raw mut (*p).hit).write(no_hit);
            (valid, rh.assume_init_mut())
        };
        // SAFETY: the scene is committed; `valid` and `rh` have the alignment Embree needs.
        unsafe { rtcIntersect8(valid.0.as_ptr(), self.scene, &mut ctx, rh) };
        std::array::from_fn(|i| {
            (rays.valid[i] && rh.hit.geomID[i] != u32::MAX).then_some((rh.ray.tfar[i], rh.hit.primID[i]))
        })
    }

    /// Occlusion of a packet in `[0, t_max]` per lane, coherent context.
    #[inline]
    pub fn occluded8(&self, rays: &Rays) -> [bool; LANES] {
        let mut ctx = context(RTCIntersectContextFlags::COHERENT);
        let mut ray = std::mem::MaybeUninit::<RTCRay8>::uninit();
        let valid = Self::fill(rays, ray.as_mut_ptr());
        // SAFETY: `fill` wrote every field.
        let ray = unsafe { ray.assume_init_mut() };
        // SAFETY: as in `intersect8`.
        unsafe { rtcOccluded8(valid.0.as_ptr(), self.scene, &mut ctx, ray) };
        std::array::from_fn(|i| rays.valid[i] && ray.tfar[i] == f32::NEG_INFINITY)
    }
}

impl Drop for Scene {
    fn drop(&mut self) {
        // SAFETY: both handles came from Embree in `new` and are released once.
        unsafe {
            rtcReleaseScene(self.scene);
            rtcReleaseDevice(self.device);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    #[test]
    fn the_ray_written_whole_has_every_field() {
        let ray = Ray::new(Vec3::new(1.0, -2.0, 3.5), Vec3::new(0.0, -0.6, 0.8));
        let mut r = std::mem::MaybeUninit::<RTCRay>::uninit();
        write_ray(r.as_mut_ptr(), &ray, 0.25, 7.0);
        // SAFETY: write_ray wrote every field.
        let r = unsafe { r.assume_init() };
        let got = [r.org_x, r.org_y, r.org_z, r.tnear, r.dir_x, r.dir_y, r.dir_z, r.time, r.tfar].map(f32::to_bits);
        let want = [1.0, -2.0, 3.5, 0.25, ray.dir.x, ray.dir.y, ray.dir.z, 0.0, 7.0].map(f32::to_bits);
        assert_eq!(got, want);
        assert_eq!((r.mask, r.id, r.flags), (u32::MAX, 0, 0));
    }

    #[test]
    fn embree_finds_the_same_triangle_and_distance() {
        let tris = [
            Triangle::from_vertices([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
            Triangle::from_vertices([0.0, 0.0, -1.0], [1.0, 0.0, -1.0], [0.0, 1.0, -1.0]),
        ];
        for flags in [Flags::Default, Flags::Robust] {
            let s = Scene::new(&tris, flags).unwrap();
            let down = Ray::new(Vec3::new(0.25, 0.25, 1.0), Vec3::NEG_Z);
            assert_eq!(s.intersect1(&down, 0.0, f32::INFINITY), Some((1.0, 0)));
            assert_eq!(s.intersect1(&down, 1.5, f32::INFINITY), Some((2.0, 1)));
            assert_eq!(s.intersect1(&Ray::new(Vec3::new(2.0, 2.0, 1.0), Vec3::NEG_Z), 0.0, f32::INFINITY), None);
            assert!(s.occluded1(&down, 1.5));
            assert!(!s.occluded1(&down, 0.5));
            let mut p = Rays::default();
            for i in 0..LANES {
                p.set(i, &down, f32::INFINITY);
            }
            p.valid[3] = false;
            p.t_max[5] = 0.5;
            let hits = s.intersect8(&p);
            let occ = s.occluded8(&p);
            for i in 0..LANES {
                let want = p.valid[i] && i != 5;
                assert_eq!(hits[i], want.then_some((1.0, 0)), "lane {i}");
                assert_eq!(occ[i], want, "lane {i}");
            }
        }
    }
}
