//! Cameras and lights derived from scene bounds, for scenes that bring none.
//!
//! The three cameras look at the centre of the bounding sphere from the front (+z), raised by
//! [`ELEVATION_DEG`], with +y up and a vertical field of view of [`FOV_DEG`]. Their distances make
//! the bounding sphere span [`CLOSE_UP_FILL`], [`MEDIUM_FILL`] and [`WIDE_FILL`] times the vertical
//! field of view (a sphere of radius `r` seen from distance `d` spans `2 asin(r / d)`), so the
//! close-up cuts the model and the wide shot leaves room around it.

use bvh_format::{Camera, Light};
use glam::{DVec3, Vec3};

pub const FOV_DEG: f32 = 45.0;
/// How far above the horizontal the cameras look down onto the model.
pub const ELEVATION_DEG: f64 = 15.0;
pub const CLOSE_UP_FILL: f64 = 2.0;
pub const MEDIUM_FILL: f64 = 1.0;
pub const WIDE_FILL: f64 = 0.4;
/// Names of the default cameras, closest first.
pub const CAMERA_NAMES: [&str; 3] = ["close-up", "medium", "wide"];

/// Centre and radius of the sphere around a box; a degenerate box gets radius 1 so that the
/// cameras stay apart from the point they look at.
fn bounding_sphere(lo: Vec3, hi: Vec3) -> (DVec3, f64) {
    let (lo, hi) = (lo.as_dvec3(), hi.as_dvec3());
    let r = (hi - lo).length() * 0.5;
    ((lo + hi) * 0.5, if r > 0.0 && r.is_finite() { r } else { 1.0 })
}

/// Where a camera stands to see the bounds' sphere span `fill` times the vertical field of view.
pub fn framing_eye(lo: Vec3, hi: Vec3, fill: f64) -> Vec3 {
    let (c, r) = bounding_sphere(lo, hi);
    let half = (f64::from(FOV_DEG) * fill * 0.5).to_radians().min(std::f64::consts::FRAC_PI_2);
    let e = ELEVATION_DEG.to_radians();
    (c + DVec3::new(0.0, e.sin(), e.cos()) * (r / half.sin())).as_vec3()
}

/// One camera named `name` framing the bounds with `fill` (see the module notes).
pub fn framing_camera(name: &str, lo: Vec3, hi: Vec3, fill: f64) -> Camera {
    let (c, _) = bounding_sphere(lo, hi);
    Camera::new(name, framing_eye(lo, hi, fill).into(), c.as_vec3().into(), [0.0, 1.0, 0.0], FOV_DEG)
}

/// The "close-up", "medium" and "wide" cameras for scene bounds `lo`..`hi`.
pub fn cameras(lo: Vec3, hi: Vec3) -> Vec<Camera> {
    CAMERA_NAMES
        .iter()
        .zip([CLOSE_UP_FILL, MEDIUM_FILL, WIDE_FILL])
        .map(|(name, fill)| framing_camera(name, lo, hi, fill))
        .collect()
}

/// One white light beside and above the medium camera's eye (by one bounding-sphere radius
/// each way), so that shading and shadows are visible from every default camera.
pub fn lights(lo: Vec3, hi: Vec3) -> Vec<Light> {
    let (_, r) = bounding_sphere(lo, hi);
    let eye = framing_eye(lo, hi, MEDIUM_FILL).as_dvec3();
    let p = eye + DVec3::new(0.5 * r, r, 0.0);
    vec![Light::new(p.as_vec3().into(), [1.0, 1.0, 1.0])]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cameras_frame_the_bounds_as_documented() {
        let (lo, hi) = (Vec3::new(-1.0, 0.0, -1.0), Vec3::new(1.0, 2.0, 1.0));
        let cams = cameras(lo, hi);
        let names: Vec<_> = cams.iter().map(|c| c.name().unwrap()).collect();
        assert_eq!(names, CAMERA_NAMES);
        let r = 3f32.sqrt();
        for (cam, fill) in cams.iter().zip([CLOSE_UP_FILL, MEDIUM_FILL, WIDE_FILL]) {
            let (eye, at) = (Vec3::from(cam.eye), Vec3::from(cam.at));
            assert_eq!(at, Vec3::new(0.0, 1.0, 0.0));
            assert!(eye.z > 0.0 && eye.y > at.y, "front and above");
            let span = 2.0 * (r / eye.distance(at)).asin().to_degrees();
            assert!((span - FOV_DEG * fill as f32).abs() < 0.01, "{span}");
        }
        let l = lights(lo, hi);
        assert_eq!(l.len(), 1);
        assert!(Vec3::from(l[0].position).y > cams[1].eye[1]);
    }

    #[test]
    fn degenerate_bounds_still_give_distinct_eye_and_target() {
        let p = Vec3::splat(5.0);
        for c in cameras(p, p) {
            assert!(Vec3::from(c.eye).distance(Vec3::from(c.at)) > 0.5);
        }
    }
}
