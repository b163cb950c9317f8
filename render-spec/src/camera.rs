//! Primary rays from a camera: the convention of docs/shading.md ("Camera"), shared by every tracer
//! and tool so that all of them shoot exactly the same primary rays.

use glam::{DVec3, Vec3};

/// A pinhole camera: eye, look-at point, up vector, vertical field of view in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraSpec {
    pub eye: Vec3,
    pub at: Vec3,
    pub up: Vec3,
    pub fov_deg: f32,
}

impl From<&bvh_format::Camera> for CameraSpec {
    fn from(c: &bvh_format::Camera) -> Self {
        Self { eye: c.eye.into(), at: c.at.into(), up: c.up.into(), fov_deg: c.fov_deg }
    }
}

/// Per-frame precomputation (thesis code example 4.4): the direction to the top-left image corner
/// and the steps from one pixel to the next.
#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub eye: Vec3,
    pub top_left: Vec3,
    pub h_step: Vec3,
    pub v_step: Vec3,
}

/// Why a camera cannot be used.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CameraError {
    /// Eye and look-at point coincide, or up is parallel to the view direction.
    Degenerate,
    /// Field of view outside (0, 180) degrees.
    FieldOfView,
}

impl CameraSpec {
    pub fn frame(&self, width: u32, height: u32) -> Result<Frame, CameraError> {
        if !(self.fov_deg > 0.0 && self.fov_deg < 180.0) {
            return Err(CameraError::FieldOfView);
        }
        let [f, r, u] = self.basis()?;
        let t = (self.fov_deg.to_radians() * 0.5).tan();
        let a = width as f32 / height as f32;
        Ok(Frame {
            eye: self.eye,
            top_left: f - t * a * r + t * u,
            h_step: 2.0 * t * a * r / width as f32,
            v_step: -2.0 * t * u / height as f32,
        })
    }

    /// The camera's unit vectors `[forward, right, up]` (right-handed: `up = right x forward`),
    /// from which [`Self::frame`] spans the image.
    pub fn basis(&self) -> Result<[Vec3; 3], CameraError> {
        let f = unit(self.at - self.eye, self.at.as_dvec3() - self.eye.as_dvec3());
        let r = unit(f.cross(self.up), f.as_dvec3().cross(self.up.as_dvec3()));
        if f == Vec3::ZERO || r == Vec3::ZERO || !f.is_finite() || !r.is_finite() {
            return Err(CameraError::Degenerate);
        }
        Ok([f, r, r.cross(f)])
    }
}

/// `v` (computed in f32) as a unit vector; zero where it is zero or its inputs are not finite.
/// Where `v` or its squared length over- or underflows f32 (an eye 1e20 from the look-at point or
/// 1e-20, eye and look-at point on either side of 2e38, an up vector of length 1e30), `v64`, the
/// same vector computed in f64, where none of these does. Elsewhere f32's own normalisation, so
/// that every ordinary camera keeps the bits of its rays.
fn unit(v: Vec3, v64: DVec3) -> Vec3 {
    let n = v.normalize_or_zero();
    if n != Vec3::ZERO || !v64.is_finite() {
        return n;
    }
    v64.normalize_or_zero().as_vec3()
}

impl Frame {
    /// Unit direction of the primary ray through pixel (x, y), x right and y down from the
    /// top-left corner.
    #[inline(always)]
    pub fn direction(&self, x: u32, y: u32) -> Vec3 {
        self.sample_direction(x, y, (0.5, 0.5))
    }

    /// Unit direction through the point `(sx, sy)` of pixel (x, y), from its top-left corner in
    /// pixels ([`crate::accuracy::sample_positions`]); `(0.5, 0.5)` is [`Self::direction`].
    #[inline(always)]
    pub fn sample_direction(&self, x: u32, y: u32, (sx, sy): (f32, f32)) -> Vec3 {
        (self.top_left + (x as f32 + sx) * self.h_step + (y as f32 + sy) * self.v_step).normalize()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn centre_pixel_looks_at_the_target_and_corners_span_the_fov() {
        let cam = CameraSpec { eye: Vec3::new(0.0, 0.0, 5.0), at: Vec3::ZERO, up: Vec3::Y, fov_deg: 90.0 };
        let f = cam.frame(2, 2).unwrap();
        // With an even size the image centre lies between pixels: average the four.
        let c = (f.direction(0, 0) + f.direction(1, 0) + f.direction(0, 1) + f.direction(1, 1)).normalize();
        assert!((c - Vec3::NEG_Z).length() < 1e-6);
        // Top-left pixel points up and to the left.
        let tl = f.direction(0, 0);
        assert!(tl.x < 0.0 && tl.y > 0.0 && tl.z < 0.0);
        // A 1x1 image's only pixel looks straight ahead; the vertical edge of a 90 degree view is at 45.
        let f1 = cam.frame(1, 1).unwrap();
        assert!((f1.direction(0, 0) - Vec3::NEG_Z).length() < 1e-6);
        let top = f1.top_left + 0.5 * f1.h_step;
        assert!((top.normalize().y - (45f32).to_radians().sin()).abs() < 1e-6);
    }

    #[test]
    fn cameras_far_near_or_with_a_long_up_vector_are_not_degenerate() {
        let plain = CameraSpec { eye: Vec3::new(0.0, 0.0, 5.0), at: Vec3::ZERO, up: Vec3::Y, fov_deg: 60.0 };
        let want = plain.frame(4, 3).unwrap();
        // The view direction's and the right vector's squared lengths overflow or underflow f32.
        for cam in [
            CameraSpec { eye: Vec3::new(0.0, 0.0, 1e30), ..plain },
            CameraSpec { eye: Vec3::new(0.0, 0.0, 3e38), at: Vec3::new(0.0, 0.0, -3e38), ..plain },
            CameraSpec { eye: Vec3::new(0.0, 0.0, 1e-30), ..plain },
            CameraSpec { up: Vec3::new(0.0, 1e30, 0.0), ..plain },
            CameraSpec { up: Vec3::new(0.0, 1e-30, 0.0), ..plain },
        ] {
            let f = cam.frame(4, 3).unwrap_or_else(|e| panic!("{cam:?}: {e:?}"));
            for (x, y) in [(0, 0), (3, 0), (1, 2)] {
                let (a, b) = (f.direction(x, y), want.direction(x, y));
                assert!((a - b).length() < 1e-6, "{cam:?} pixel ({x}, {y}): {a} against {b}");
            }
        }
        // Where f32 normalises, the rays keep their bits: a power-of-two longer up vector.
        let f = CameraSpec { up: Vec3::new(0.0, 4.0, 0.0), ..plain }.frame(4, 3).unwrap();
        assert_eq!(f.direction(3, 2), want.direction(3, 2));
    }

    #[test]
    fn degenerate_cameras_are_rejected() {
        let bad = CameraSpec { eye: Vec3::ZERO, at: Vec3::ZERO, up: Vec3::Y, fov_deg: 45.0 };
        assert_eq!(bad.frame(4, 4).unwrap_err(), CameraError::Degenerate);
        let bad = CameraSpec { eye: Vec3::ZERO, at: Vec3::Y, up: Vec3::Y, fov_deg: 45.0 };
        assert_eq!(bad.frame(4, 4).unwrap_err(), CameraError::Degenerate);
        let bad = CameraSpec { eye: Vec3::ZERO, at: Vec3::Z, up: Vec3::ZERO, fov_deg: 45.0 };
        assert_eq!(bad.frame(4, 4).unwrap_err(), CameraError::Degenerate);
        let bad = CameraSpec { eye: Vec3::ZERO, at: Vec3::new(0.0, 0.0, f32::INFINITY), up: Vec3::Y, fov_deg: 45.0 };
        assert_eq!(bad.frame(4, 4).unwrap_err(), CameraError::Degenerate);
        let bad = CameraSpec { eye: Vec3::ZERO, at: Vec3::Z, up: Vec3::Y, fov_deg: 180.0 };
        assert_eq!(bad.frame(4, 4).unwrap_err(), CameraError::FieldOfView);
    }
}
