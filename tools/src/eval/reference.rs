//! The renders every setting is measured against, and their cache on disk.
//!
//! A reference is rendered once per scene, camera, size, mode and lights, in two forms: the
//! converged image (many samples per pixel, every bounce) that image errors are measured against,
//! and one sample per pixel with the per-pixel outputs, whose closest hits the hit errors compare
//! with. Both are kept under a key made of a hash of the scene file's bytes, the settings and the
//! reference renderer's name, so that a changed scene or setting never reuses a stale image.

use crate::output::write_atomically;
use bvh_format::SceneFile;
use render_spec::{Accuracy, Aovs, Image, RayCounts, Settings};
use std::io::Write as _;
use std::path::{Path, PathBuf};

/// A renderer whose images count as the truth.
pub trait Reference {
    /// Names the renderer in tables and in the cache key; it must change when its images would.
    fn name(&self) -> String;
    fn render(&self, scene: &SceneFile, settings: &Settings) -> Result<Image, String>;
}

/// The exact reference of issue 8.1 (`tracer_cpu::reference`): docs/shading.md in f64 through
/// an f64 BVH walk, every bounce up to the indirection limit, the settings' samples per pixel.
pub struct F64Reference {
    pub pool: rayon::ThreadPool,
}

impl Reference for F64Reference {
    fn name(&self) -> String {
        "the f64 reference (trace-cpu render --reference)".to_owned()
    }

    fn render(&self, scene: &SceneFile, settings: &Settings) -> Result<Image, String> {
        self.pool.install(|| tracer_cpu::reference::render(scene, settings)).map(|r| r.image).map_err(|e| e.to_string())
    }
}

/// The settings of the converged reference of `frame`: `spp` samples per pixel, the scene's
/// indirections, no bounce cutoff, no per-pixel outputs.
pub fn converged(frame: &Settings, scene: &SceneFile, spp: u32) -> Settings {
    Settings {
        max_indirections: scene.settings.max_indirections,
        aovs: false,
        accuracy: Accuracy { spp, cutoff: 0.0, ..Accuracy::default() },
        ..frame.clone()
    }
}

/// The settings of the one-sample reference of `frame`, with per-pixel outputs.
pub fn one_sample(frame: &Settings, scene: &SceneFile) -> Settings {
    Settings { aovs: true, ..converged(frame, scene, 1) }
}

/// 64-bit FNV-1a: a stable hash (the standard library's may change between Rust versions).
pub fn fnv1a(bytes: &[u8], mut h: u64) -> u64 {
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x100_0000_01b3);
    }
    h
}

pub const FNV_OFFSET: u64 = 0xcbf2_9ce4_8422_2325;

/// A hash of a scene's content: the bytes of its file.
pub fn scene_hash(scene: &SceneFile) -> Result<u64, String> {
    let bytes = bvh_format::write(scene).map_err(|e| format!("cannot hash the scene: {e}"))?;
    Ok(fnv1a(&bytes, FNV_OFFSET))
}

/// Reference images on disk, one file per key.
pub struct Cache {
    pub dir: PathBuf,
}

const MAGIC: &[u8; 8] = b"EVALREF1";

impl Cache {
    /// The cache in `dir`, created if missing.
    pub fn new(dir: &Path) -> Result<Cache, String> {
        std::fs::create_dir_all(dir)
            .map_err(|e| format!("cannot create the reference cache {}: {e}", dir.display()))?;
        Ok(Cache { dir: dir.to_owned() })
    }

    /// The file of a reference of `scene` (by hash) under `settings`, rendered by `name`.
    pub fn path(&self, scene_hash: u64, settings: &Settings, name: &str) -> PathBuf {
        // Debug prints floats exactly (shortest round trip), so equal settings give equal keys.
        let key = fnv1a(format!("{settings:?}|{name}").as_bytes(), scene_hash);
        self.dir.join(format!("{scene_hash:016x}-{key:016x}.ref"))
    }

    /// The cached reference, or a new render stored for next time. The flag says whether it
    /// was rendered now.
    pub fn get_or_render(
        &self,
        reference: &dyn Reference,
        scene: &SceneFile,
        scene_hash: u64,
        settings: &Settings,
    ) -> Result<(Image, bool), String> {
        let path = self.path(scene_hash, settings, &reference.name());
        if let Ok(bytes) = std::fs::read(&path)
            && let Some(image) = decode(&bytes, settings)
        {
            return Ok((image, false));
        }
        let image = reference.render(scene, settings)?;
        write_atomically(&path, |w| w.write_all(&encode(&image)).map_err(|e| e.to_string()))
            .map_err(|e| e.to_string())?;
        Ok((image, true))
    }
}

/// The cache file: magic, width, height, whether AOVs follow, the 8-bit pixels, then the `prim`
/// and `t` outputs (little-endian), the only ones the metrics read.
fn encode(image: &Image) -> Vec<u8> {
    let mut b = MAGIC.to_vec();
    b.extend(image.width.to_le_bytes());
    b.extend(image.height.to_le_bytes());
    b.push(u8::from(image.aov.is_some()));
    b.extend(image.rgb.as_flattened());
    if let Some(aov) = &image.aov {
        b.extend(aov.prim.iter().flat_map(|p| p.to_le_bytes()));
        b.extend(aov.t.iter().flat_map(|t| t.to_le_bytes()));
    }
    b
}

/// Reads a cache file back; `None` when it is damaged or does not fit `settings` (then it is
/// rendered again).
fn decode(b: &[u8], settings: &Settings) -> Option<Image> {
    let rest = b.strip_prefix(MAGIC)?;
    let word = |at: usize| Some(u32::from_le_bytes(rest.get(at..at + 4)?.try_into().ok()?));
    let (width, height) = (word(0)?, word(4)?);
    let has_aov = *rest.get(8)? == 1;
    if (width, height) != (settings.width, settings.height) || has_aov != settings.aovs {
        return None;
    }
    let n = width as usize * height as usize;
    let body = &rest[9..];
    let expected = 3 * n + if has_aov { 8 * n } else { 0 };
    if body.len() != expected {
        return None;
    }
    let rgb = body[..3 * n].chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let aov = has_aov.then(|| {
        let words = |at: usize| body[at..at + 4 * n].chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]);
        Aovs {
            prim: words(3 * n).map(u32::from_le_bytes).collect(),
            t: words(7 * n).map(f32::from_le_bytes).collect(),
            ..Default::default()
        }
    });
    Some(Image { width, height, rgb, aov, rays: RayCounts::default() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use render_spec::{CameraSpec, Mode};

    fn settings(aovs: bool) -> Settings {
        Settings {
            width: 3,
            height: 2,
            camera: CameraSpec { eye: glam::Vec3::Z, at: glam::Vec3::ZERO, up: glam::Vec3::Y, fov_deg: 45.0 },
            mode: Mode::Whitted,
            lights: Vec::new(),
            max_indirections: 1,
            aovs,
            accuracy: Accuracy::default(),
        }
    }

    #[test]
    fn cache_files_round_trip_and_damaged_ones_are_refused() {
        let aov = Aovs {
            prim: vec![1, 2, 3, 4, 5, u32::MAX],
            t: vec![0.5, 1.0, 2.0, 3.0, 4.0, f32::INFINITY],
            ..Default::default()
        };
        let image = Image {
            width: 3,
            height: 2,
            rgb: (0..6).map(|i| [i, 2 * i, 3 * i]).collect(),
            aov: Some(aov),
            rays: RayCounts::default(),
        };
        let bytes = encode(&image);
        let back = decode(&bytes, &settings(true)).unwrap();
        assert_eq!((back.rgb, back.aov), (image.rgb.clone(), image.aov.clone()));
        assert!(decode(&bytes, &settings(false)).is_none(), "the AOVs asked for must be there");
        assert!(decode(&bytes[..bytes.len() - 1], &settings(true)).is_none());
        assert!(decode(b"EVALREF0", &settings(true)).is_none());
    }

    #[test]
    fn keys_change_with_the_scene_the_settings_and_the_renderer() {
        let cache = Cache { dir: PathBuf::from("c") };
        let a = cache.path(1, &settings(false), "r");
        assert_eq!(a, cache.path(1, &settings(false), "r"));
        assert_ne!(a, cache.path(2, &settings(false), "r"));
        assert_ne!(a, cache.path(1, &settings(true), "r"));
        assert_ne!(a, cache.path(1, &settings(false), "s"));
        let mut s = settings(false);
        s.accuracy.spp = 4;
        assert_ne!(a, cache.path(1, &s, "r"));
        assert_eq!(fnv1a(b"a", FNV_OFFSET), 0xaf63dc4c8601ec8c);
    }
}
