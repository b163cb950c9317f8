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
/// Names of the default cameras: the medium shot (the default view), then closest first.
pub const CAMERA_NAMES: [&str; 3] = ["medium", "close-up", "wide"];

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
        .zip([MEDIUM_FILL, CLOSE_UP_FILL, WIDE_FILL])
        .map(|(name, fill)| framing_camera(name, lo, hi, fill))
        .collect()
}

/// The default light of a scene without lights: one white light placed by [`lights_around`] the
/// camera the scene is seen from by default (its first).
pub fn light_for(camera: &Camera, lo: Vec3, hi: Vec3) -> Light {
    let p = lights_around(camera.eye.into(), camera.at.into(), camera.up.into(), lo, hi, 1);
    Light::new(p[0].into(), [1.0, 1.0, 1.0])
}

/// Positions of `n` lights that light what a camera at `eye` looking at `at` sees.
///
/// From outside the bounds: on a circle of half the bounding-sphere radius around a point one
/// radius above the eye, the first one to the camera's right (for the medium default camera,
/// beside and above its eye), so shading and shadows show. From inside the bounds (an interior,
/// such as a closed room): around the eye itself, no farther from it than 0.3 times its
/// distance to the nearest face of the bounds, so that every light stays inside and lights what
/// the camera sees instead of the outside of the walls.
pub fn lights_around(eye: Vec3, at: Vec3, up: Vec3, lo: Vec3, hi: Vec3, n: usize) -> Vec<Vec3> {
    let (eye, lo, hi) = (eye.as_dvec3(), lo.as_dvec3(), hi.as_dvec3());
    let forward = (at.as_dvec3() - eye).try_normalize().unwrap_or(DVec3::NEG_Z);
    let up = up.as_dvec3().try_normalize().unwrap_or(DVec3::Y);
    let right = forward.cross(up).try_normalize().unwrap_or(DVec3::X);
    let inside = eye.cmpgt(lo).all() && eye.cmplt(hi).all();
    let (centre, radius) = if inside {
        // Offsets of at most 0.15 room up and 0.15 room across: within 0.3 room of the eye.
        let room = (eye - lo).min(hi - eye).min_element();
        (eye + up * 0.15 * room, 0.15 * room)
    } else {
        let (_, r) = bounding_sphere(lo.as_vec3(), hi.as_vec3());
        (eye + up * r, 0.5 * r)
    };
    (0..n)
        .map(|k| {
            let a = std::f64::consts::TAU * k as f64 / n as f64;
            (centre + (right * a.cos() - forward * a.sin()) * radius).as_vec3()
        })
        .collect()
}

/// Checks that the default cameras and lights derived for bounds `lo`..`hi` are finite in f32
/// (coordinates near the limit of f32, such as 3e38, put them at infinity), naming the value.
pub fn check_finite(cameras: &[Camera], lights: &[Light], lo: Vec3, hi: Vec3) -> Result<(), String> {
    let bad_camera = cameras.iter().find(|c| !c.eye.iter().chain(&c.at).all(|x| x.is_finite()));
    let bad_light = lights.iter().find(|l| !l.position.iter().all(|x| x.is_finite()));
    if bad_camera.is_some() || bad_light.is_some() {
        let what = match bad_camera {
            Some(c) => format!("camera '{}' would stand at {}", c.name().unwrap_or("?"), sci(c.eye)),
            None => format!("the light would stand at {}", sci(bad_light.map_or([0.0; 3], |l| l.position))),
        };
        return Err(format!(
            "the scene reaches from {} to {}, too far to derive a default view in 32-bit floats: {what}; \
             scale the scene down or give cameras and lights",
            sci(lo.into()),
            sci(hi.into())
        ));
    }
    Ok(())
}

/// A point in scientific notation, readable for huge and tiny coordinates alike.
fn sci(p: [f32; 3]) -> String {
    format!("({:.3e}, {:.3e}, {:.3e})", p[0], p[1], p[2])
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
        for (cam, fill) in cams.iter().zip([MEDIUM_FILL, CLOSE_UP_FILL, WIDE_FILL]) {
            let (eye, at) = (Vec3::from(cam.eye), Vec3::from(cam.at));
            assert_eq!(at, Vec3::new(0.0, 1.0, 0.0));
            assert!(eye.z > 0.0 && eye.y > at.y, "front and above");
            let span = 2.0 * (r / eye.distance(at)).asin().to_degrees();
            assert!((span - FOV_DEG * fill as f32).abs() < 0.01, "{span}");
        }
        let l = light_for(&cams[0], lo, hi);
        assert!(l.position[1] > cams[0].eye[1] && l.position[0] > cams[0].eye[0], "beside and above the eye");
    }

    #[test]
    fn lights_of_an_interior_stay_inside_it() {
        // A closed room 4 x 3 x 4 seen from inside, near the front wall.
        let (lo, hi) = (Vec3::new(-2.0, 0.0, -2.0), Vec3::new(2.0, 3.0, 2.0));
        let (eye, at) = (Vec3::new(0.0, 1.5, 1.9), Vec3::new(0.0, 1.0, -1.0));
        for n in 1..=8 {
            for p in lights_around(eye, at, Vec3::Y, lo, hi, n) {
                assert!(p.cmpgt(lo).all() && p.cmplt(hi).all(), "{n} lights: {p} lies outside the room");
            }
        }
        let outside = lights_around(Vec3::new(0.0, 1.0, 9.0), Vec3::ZERO, Vec3::Y, lo, hi, 4);
        assert!(outside.iter().all(|p| p.y > 1.0), "from outside, above the eye");
    }

    #[test]
    fn degenerate_bounds_still_give_distinct_eye_and_target() {
        let p = Vec3::splat(5.0);
        for c in cameras(p, p) {
            assert!(Vec3::from(c.eye).distance(Vec3::from(c.at)) > 0.5);
        }
    }
}
