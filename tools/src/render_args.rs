//! The render options of `trace-cpu render` and `trace-vk render`: same names, same meaning.

use bvh_format::{Light, SceneFile};
use clap::{Args, ValueEnum};
use glam::Vec3;
use std::path::PathBuf;
use tracer_cpu::{CameraSpec, Mode};

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ModeArg {
    /// Ray casting: one white light at the eye, Lambert only.
    Cast,
    /// Whitted ray tracing: lights with shadows, Phong, reflection and refraction.
    Whitted,
}

#[derive(Args, Debug, Clone)]
pub struct RenderArgs {
    /// Scene: a compiled .bvh file, or a mesh / scene description compiled with default settings
    /// [default: the built-in bunny].
    pub scene: Option<PathBuf>,
    /// Shading mode.
    #[arg(long, value_enum, default_value = "whitted")]
    pub mode: ModeArg,
    /// A camera stored in the scene (close-up, medium, wide for the shipped scenes).
    #[arg(long, default_value = "medium", conflicts_with_all = ["eye", "at"])]
    pub camera: String,
    /// Eye position X,Y,Z (with --at; replaces --camera).
    #[arg(long, value_parser = parse_vec3, requires = "at")]
    pub eye: Option<Vec3>,
    /// Look-at point X,Y,Z.
    #[arg(long, value_parser = parse_vec3, requires = "eye")]
    pub at: Option<Vec3>,
    /// Up vector X,Y,Z.
    #[arg(long, value_parser = parse_vec3, default_value = "0,1,0")]
    pub up: Vec3,
    /// Vertical field of view in degrees (with --eye; a stored camera keeps its own unless given).
    #[arg(long)]
    pub fov: Option<f32>,
    /// Image size.
    #[arg(long, value_parser = parse_res, default_value = "640x480")]
    pub res: (u32, u32),
    /// A point light X,Y,Z or X,Y,Z,R,G,B (repeatable); replaces the scene's lights.
    #[arg(long = "light", value_parser = parse_light)]
    pub lights: Vec<Light>,
    /// Use this many lights: the scene's first ones, completed by lights placed evenly around the
    /// scene when it has fewer (the thesis's 1-, 2- and 4-light modes).
    #[arg(long = "lights", conflicts_with = "lights")]
    pub light_count: Option<usize>,
    /// Longest chain of secondary rays, at most 1024 (the passes stop early once every path has
    /// ended) [default: the scene's].
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=tracer_vk::render::MAX_INDIRECTIONS as i64))]
    pub indirections: Option<u32>,
    /// Output image (PNG).
    #[arg(short, long, default_value = "out.png")]
    pub output: PathBuf,
    /// Also write the traversal cost (nodes visited per pixel) as a false-colour PNG.
    #[arg(long)]
    pub heatmap: Option<PathBuf>,
    /// Also write per-pixel outputs as OpenEXR: t, N.X, N.Y, N.Z, prim, nodes, tris.
    #[arg(long)]
    pub aov: Option<PathBuf>,
}

fn parse_floats(s: &str, n: &[usize]) -> Result<Vec<f32>, String> {
    let v: Result<Vec<f32>, _> = s.split(',').map(|p| p.trim().parse::<f32>()).collect();
    let v = v.map_err(|_| format!("{s:?} is not a comma-separated list of numbers"))?;
    if !n.contains(&v.len()) || v.iter().any(|x| !x.is_finite()) {
        return Err(format!("{s:?} must be {} finite numbers separated by commas", n[0]));
    }
    Ok(v)
}

pub fn parse_vec3(s: &str) -> Result<Vec3, String> {
    let v = parse_floats(s, &[3])?;
    Ok(Vec3::new(v[0], v[1], v[2]))
}

pub fn parse_res(s: &str) -> Result<(u32, u32), String> {
    let bad = || format!("{s:?} is not a size like 640x480");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h) = (w.trim().parse::<u32>().map_err(|_| bad())?, h.trim().parse::<u32>().map_err(|_| bad())?);
    if w == 0 || h == 0 || (w as u64) * (h as u64) > 1 << 28 {
        return Err(format!("{s:?}: width and height must be positive and the image at most 2^28 pixels"));
    }
    Ok((w, h))
}

pub fn parse_light(s: &str) -> Result<Light, String> {
    let v = parse_floats(s, &[3, 6])?;
    let colour = if v.len() == 6 { [v[3], v[4], v[5]] } else { [1.0, 1.0, 1.0] };
    if colour.iter().any(|&c| c < 0.0) {
        return Err(format!("{s:?}: a light's colour must not be negative"));
    }
    Ok(Light::new([v[0], v[1], v[2]], colour))
}

impl RenderArgs {
    pub fn mode(&self) -> Mode {
        match self.mode {
            ModeArg::Cast => Mode::Cast,
            ModeArg::Whitted => Mode::Whitted,
        }
    }

    /// The camera: explicit eye/at, or a stored camera by name.
    pub fn camera(&self, scene: &SceneFile) -> Result<CameraSpec, String> {
        if let (Some(eye), Some(at)) = (self.eye, self.at) {
            return Ok(CameraSpec { eye, at, up: self.up, fov_deg: self.fov.unwrap_or(45.0) });
        }
        let mut spec = stored_camera(scene, &self.camera)?;
        if let Some(f) = self.fov {
            spec.fov_deg = f;
        }
        Ok(spec)
    }

    /// The lights: explicit ones, or the scene's, completed to `--lights N` when asked.
    pub fn lights(&self, scene: &SceneFile) -> Vec<Light> {
        if !self.lights.is_empty() {
            return self.lights.clone();
        }
        match self.light_count {
            Some(n) => lights_n(scene, n),
            None => scene.lights.clone(),
        }
    }

    pub fn indirections(&self, scene: &SceneFile) -> u32 {
        self.indirections.unwrap_or(scene.settings.max_indirections)
    }
}

/// A camera stored in the scene, by name.
pub fn stored_camera(scene: &SceneFile, name: &str) -> Result<CameraSpec, String> {
    let c = scene.camera(name).ok_or_else(|| {
        let names: Vec<&str> = scene.cameras.iter().filter_map(|c| c.name()).collect();
        format!("the scene has no camera named {name:?} (it has: {})", names.join(", "))
    })?;
    Ok(CameraSpec::from(c))
}

/// `n` lights: the scene's first ones, completed by lights evenly spaced on a circle above the
/// scene (dimmer as there are more of them) when it has fewer.
pub fn lights_n(scene: &SceneFile, n: usize) -> Vec<Light> {
    let mut lights = scene.lights.clone();
    lights.truncate(n);
    let (lo, hi) = scene.bounds();
    let (lo, hi) = (Vec3::from(lo), Vec3::from(hi));
    let centre = (lo + hi) * 0.5;
    let radius = ((hi - lo).length() * 0.5).max(f32::MIN_POSITIVE);
    let added = n.saturating_sub(lights.len());
    for k in 0..added {
        let a = std::f32::consts::TAU * (k as f32 + 0.25) / added as f32;
        let p = centre + Vec3::new(a.cos() * 2.0 * radius, 2.0 * radius, a.sin() * 2.0 * radius);
        let c = 1.0 / n as f32;
        lights.push(Light::new(p.to_array(), [c, c, c]));
    }
    lights
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn option_values_parse_or_explain() {
        assert_eq!(parse_vec3("1, 2,3").unwrap(), Vec3::new(1.0, 2.0, 3.0));
        assert!(parse_vec3("1,2").unwrap_err().contains("3 finite numbers"));
        assert!(parse_vec3("1,2,nan").is_err());
        assert_eq!(parse_res("640x480").unwrap(), (640, 480));
        assert!(parse_res("640").is_err() && parse_res("0x10").is_err() && parse_res("100000x100000").is_err());
        assert_eq!(parse_light("1,2,3").unwrap(), Light::new([1.0, 2.0, 3.0], [1.0; 3]));
        assert_eq!(parse_light("1,2,3,0.5,0.5,0").unwrap().colour, [0.5, 0.5, 0.0]);
        assert!(parse_light("1,2,3,-1,0,0").is_err());
    }
}
