//! `--method auto` of `trace-vk render` and `trace-vk bench` (issue 10 item 5): the traversal is
//! picked per scene, mode and size from a calibration run (a few frames of every method the
//! device supports, the fastest median wins), cached beside the scene file so that later runs
//! read the pick instead of calibrating again. docs/vulkan-tracer.md says what it picks when.
//!
//! The cache is a text file `SCENE.methods` beside `SCENE`, one line per key. A key holds what can
//! change the pick: a hash of the compiled scene (so an edited scene, a re-compiled `.bvh` or a
//! changed mesh under a description invalidates it), the device and its driver, the mode with its
//! lights, indirections and AO settings, the size class (sizes within a power of four in pixels
//! share a pick) and the kernel settings (workgroup, exact kernels, triangle test, fixed offset,
//! persistent threads).
//! A damaged file is ignored with a warning and replaced; entries for another version of the scene
//! are stale: they are dropped, with a warning, when the file is next written.

use crate::output::write_atomically;
use bvh_format::SceneFile;
use render_spec::{Mode, Offset, Settings};
use std::io::Write as _;
use std::path::{Path, PathBuf};
use tracer_vk::Gpu;
use tracer_vk::kernels::{Method, Persistent};
use tracer_vk::render::Renderer;

/// The first line of a cache file (its format's version).
const MAGIC: &str = "trace-vk method calibration 1";
/// Untimed frames per candidate before its timed ones (the first compiles the kernels).
pub const CALIBRATION_WARMUP: usize = 1;
/// Timed frames per candidate; the median counts.
pub const CALIBRATION_FRAMES: usize = 3;

/// Whether `gpu` runs `method` at all (the scene may still refuse it, e.g. SST's workgroup memory):
/// `Err` with the reason in a phrase. The one list of GPU methods a device supports, for `auto`'s
/// candidates, `stress` and `trace-eval`.
pub fn support(gpu: &Gpu, method: Method) -> Result<(), String> {
    match method {
        Method::RtPipeline => tracer_vk::rt::properties(gpu).map(|_| ()).map_err(|e| e.to_string()),
        Method::SstSubgroup if !gpu.info().supports_subgroup_ops => {
            Err(format!("{} lacks the subgroup operations sst-subgroup votes with", gpu.info().name))
        }
        _ => Ok(()),
    }
}

/// Every GPU method ([`Method::ALL`]) with whether `gpu` supports it.
pub fn methods(gpu: &Gpu) -> Vec<(Method, Result<(), String>)> {
    Method::ALL.into_iter().map(|m| (m, support(gpu, m))).collect()
}

/// What decides a pick, as the cache stores it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Key {
    /// Hash of the compiled scene ([`crate::eval::reference::scene_hash`]), in hex.
    pub scene: String,
    /// Everything else, tab-free: device, driver, mode, size class, kernel settings.
    pub rest: String,
}

/// The key of a frame of `settings` on `gpu` with this workgroup and kernels (`persistent`: the
/// `--persistent` setting every candidate is timed with), picked among `candidates`.
pub fn key(
    scene_hash: u64,
    gpu: &Gpu,
    settings: &Settings,
    (workgroup, exact, persistent): ((u32, u32), bool, Persistent),
    candidates: &[Method],
) -> Key {
    let i = gpu.info();
    let mode = match settings.mode {
        Mode::Cast => "cast".to_owned(),
        Mode::Whitted => format!("whitted lights {} indirections {}", settings.lights.len(), settings.max_indirections),
        Mode::Ao(ao) => format!("ao {} x {}", ao.samples, ao.length),
        Mode::Diffuse => "diffuse".to_owned(),
    };
    let a = &settings.accuracy;
    let rest = format!(
        "device {} ({}, {:04x}:{:04x}); mode {mode}; pixels 4^{}; workgroup {}x{}; exact {exact}; intersect {:?}; offset {}; persistent {}; candidates {}",
        i.name,
        i.driver,
        i.vendor_id,
        i.device_id,
        size_class(settings.width, settings.height),
        workgroup.0,
        workgroup.1,
        a.intersect,
        match a.offset {
            Offset::ScaleAware => "scale-aware",
            Offset::Fixed(_) => "fixed",
        },
        persistent.name(),
        candidates.iter().map(|m| m.name()).collect::<Vec<_>>().join(",")
    );
    Key { scene: format!("{scene_hash:016x}"), rest: rest.replace(['\t', '\n', '\r'], " ") }
}

/// Sizes whose pixel counts round to the same power of four share a pick: 640x480 and 800x600
/// share 4^9, 1920x1440 is 4^11, 7680x4320 4^12.
pub fn size_class(width: u32, height: u32) -> u32 {
    let pixels = (u64::from(width) * u64::from(height)).max(1);
    pixels.ilog2().div_ceil(2)
}

/// The cache file of a scene: `NAME.methods` beside it.
pub fn cache_path(scene: &Path) -> PathBuf {
    let mut name = scene.file_name().unwrap_or_default().to_os_string();
    name.push(".methods");
    scene.with_file_name(name)
}

/// One cached pick.
#[derive(Clone, Debug, PartialEq)]
struct Entry {
    key: Key,
    method: Method,
    /// The calibration's median ms per candidate, for the reader of the file.
    note: String,
}

/// The cache's entries, or why the file cannot be used. A missing file is empty.
fn read(path: &Path) -> Result<Vec<Entry>, String> {
    let text = match std::fs::read(path) {
        Ok(bytes) => String::from_utf8(bytes).map_err(|_| "it is not text".to_owned())?,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Vec::new()),
        Err(e) => return Err(e.to_string()),
    };
    let mut lines = text.lines();
    if lines.next() != Some(MAGIC) {
        return Err(format!("its first line is not {MAGIC:?}"));
    }
    lines
        .enumerate()
        .map(|(n, line)| {
            let f: Vec<&str> = line.split('\t').collect();
            let [scene, rest, method, note] = f[..] else {
                return Err(format!("line {} has {} fields, not 4", n + 2, f.len()));
            };
            let method = Method::ALL
                .into_iter()
                .find(|m| m.name() == method)
                .ok_or_else(|| format!("line {} names no method this trace-vk has ({method:?})", n + 2))?;
            if scene.len() != 16 || !scene.bytes().all(|b| b.is_ascii_hexdigit()) {
                return Err(format!("line {} has no scene hash", n + 2));
            }
            Ok(Entry { key: Key { scene: scene.to_owned(), rest: rest.to_owned() }, method, note: note.to_owned() })
        })
        .collect()
}

fn write(path: &Path, entries: &[Entry]) -> Result<(), String> {
    write_atomically(path, |w| {
        let mut text = format!("{MAGIC}\n");
        for e in entries {
            text.push_str(&format!("{}\t{}\t{}\t{}\n", e.key.scene, e.key.rest, e.method.name(), e.note));
        }
        w.write_all(text.as_bytes()).map_err(|e| e.to_string())
    })
    .map_err(|e| e.to_string())
}

/// Every candidate's median ms, or why it was left out.
pub type Timings = Vec<(Method, Result<f64, String>)>;

/// How a pick was made.
#[derive(Clone, Debug, PartialEq)]
pub enum Source {
    /// Read from this cache file.
    Cached(PathBuf),
    /// Calibrated now: every candidate's median ms or why it was left out, and where the pick was
    /// written (`None`: the built-in scene, or the file could not be written, as warned).
    Calibrated { timings: Timings, written: Option<PathBuf> },
}

/// A pick of `--method auto`.
#[derive(Clone, Debug, PartialEq)]
pub struct Pick {
    pub method: Method,
    pub source: Source,
}

impl Pick {
    /// The report line: what was picked and how.
    pub fn line(&self) -> String {
        match &self.source {
            Source::Cached(p) => format!("auto: {} (calibration cached in {})", self.method.name(), p.display()),
            Source::Calibrated { timings, written } => {
                let each: Vec<String> = timings
                    .iter()
                    .map(|(m, t)| match t {
                        Ok(ms) => format!("{} {}", m.name(), crate::cli::duration(ms / 1e3)),
                        Err(why) => format!("{} left out ({why})", m.name()),
                    })
                    .collect();
                let cached = match written {
                    Some(p) => format!("cached in {}", p.display()),
                    None => "not cached".to_owned(),
                };
                format!("auto: {} after calibrating ({}; {cached})", self.method.name(), each.join(", "))
            }
        }
    }
}

/// What `auto` needs to pick for a scene.
pub struct Picker<'a> {
    pub gpu: &'a Gpu,
    pub scene: &'a SceneFile,
    /// The scene's file: the cache sits beside it (none for the built-in scene).
    pub path: Option<&'a Path>,
    pub workgroup: (u32, u32),
    pub exact: bool,
    /// Calibrate even where the cache has a pick (`--recalibrate`), and replace it.
    pub recalibrate: bool,
    /// The methods to pick among (`--candidates`): all the device supports, or these of them.
    pub candidates: Vec<Method>,
    /// The `--persistent` setting each candidate is timed with, and the pick renders with: the
    /// default auto times LST and stackless with persistent AO and diffuse stages.
    pub persistent: Persistent,
    /// The scene's hash, computed at the first pick.
    hash: std::cell::OnceCell<u64>,
}

impl<'a> Picker<'a> {
    pub fn new(
        gpu: &'a Gpu,
        scene: &'a SceneFile,
        path: Option<&'a Path>,
        workgroup: (u32, u32),
        exact: bool,
        recalibrate: bool,
    ) -> Self {
        let candidates = Method::ALL.to_vec();
        let persistent = Persistent::Auto;
        Picker {
            gpu,
            scene,
            path,
            workgroup,
            exact,
            recalibrate,
            candidates,
            persistent,
            hash: std::cell::OnceCell::new(),
        }
    }

    /// Times the candidates with persistent threads as `persistent` says (`--persistent`).
    pub fn with_persistent(self, persistent: Persistent) -> Self {
        Picker { persistent, ..self }
    }

    /// Picks among `methods` only (`--candidates`); none given: every method.
    pub fn among(self, methods: &[Method]) -> Self {
        if methods.is_empty() { self } else { Picker { candidates: methods.to_vec(), ..self } }
    }

    fn hash(&self) -> Result<u64, String> {
        if let Some(h) = self.hash.get() {
            return Ok(*h);
        }
        let h = crate::eval::reference::scene_hash(self.scene)?;
        Ok(*self.hash.get_or_init(|| h))
    }

    /// The method for frames of `settings`: the cached pick, else a calibration (cached).
    /// Warnings (a damaged or stale cache, one that cannot be written) go to standard error.
    pub fn pick(&self, settings: &Settings) -> Result<Pick, String> {
        let kernels = (self.workgroup, self.exact, self.persistent);
        let key = key(self.hash()?, self.gpu, settings, kernels, &self.candidates);
        let file = self.path.map(cache_path);
        let mut entries = match &file {
            None => Vec::new(),
            Some(f) => read(f).unwrap_or_else(|why| {
                warn(&format!("ignoring the method cache {} ({why}); it will be replaced", f.display()));
                Vec::new()
            }),
        };
        if let Some(f) = &file
            && !self.recalibrate
            && let Some(e) = entries.iter().find(|e| e.key == key)
        {
            return Ok(Pick { method: e.method, source: Source::Cached(f.clone()) });
        }
        let stale = entries.iter().filter(|e| e.key.scene != key.scene).count();
        if let Some(f) = &file
            && stale > 0
        {
            warn(&format!(
                "{stale} entries of the method cache {} were calibrated on another version of the scene; dropping them",
                f.display()
            ));
        }
        let timings = self.calibrate(settings)?;
        let best = timings
            .iter()
            .filter_map(|(m, t)| t.as_ref().ok().map(|ms| (*m, *ms)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(m, _)| m)
            .ok_or_else(|| {
                let why: Vec<String> = timings
                    .iter()
                    .filter_map(|(m, t)| t.as_ref().err().map(|e| format!("{}: {e}", m.name())))
                    .collect();
                format!("no method renders this scene on this device ({})", why.join("; "))
            })?;
        let note: Vec<String> = timings
            .iter()
            .map(|(m, t)| match t {
                Ok(ms) => format!("{} {ms:.4} ms", m.name()),
                Err(_) => format!("{} refused", m.name()),
            })
            .collect();
        let written = match &file {
            None => None,
            Some(f) => {
                entries.retain(|e| e.key.scene == key.scene && e.key != key);
                entries.push(Entry { key, method: best, note: note.join(", ") });
                match write(f, &entries) {
                    Ok(()) => Some(f.clone()),
                    Err(why) => {
                        warn(&format!("the calibration could not be cached: {why}"));
                        None
                    }
                }
            }
        };
        Ok(Pick { method: best, source: Source::Calibrated { timings, written } })
    }

    /// A few frames of every candidate: the median GPU time of each (wall time on a device
    /// without timestamps), or why it was left out.
    pub fn calibrate(&self, settings: &Settings) -> Result<Timings, String> {
        let mut out = Vec::new();
        for (method, supported) in methods(self.gpu).into_iter().filter(|(m, _)| self.candidates.contains(m)) {
            let timed = supported.and_then(|()| self.time(method, settings));
            out.push((method, timed));
        }
        Ok(out)
    }

    fn time(&self, method: Method, settings: &Settings) -> Result<f64, String> {
        let mut r = Renderer::new(self.gpu, self.scene, method, self.workgroup).map_err(|e| e.to_string())?;
        r.set_exact(self.exact);
        r.set_persistent(self.persistent, None).map_err(|e| e.to_string())?;
        let s = Settings { aovs: false, ..settings.clone() };
        let mut times = Vec::with_capacity(CALIBRATION_FRAMES);
        for k in 0..CALIBRATION_WARMUP + CALIBRATION_FRAMES {
            let t0 = std::time::Instant::now();
            let out = r.render_frame(&s, false).map_err(|e| e.to_string())?;
            let ms = if out.gpu_ms.is_finite() { out.gpu_ms } else { t0.elapsed().as_secs_f64() * 1e3 };
            if k >= CALIBRATION_WARMUP {
                times.push(ms);
            }
        }
        times.sort_by(f64::total_cmp);
        Ok(times[times.len() / 2])
    }
}

fn warn(s: &str) {
    eprintln!("warning: {s}");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_within_a_power_of_four_share_a_class() {
        assert_eq!(size_class(640, 480), size_class(800, 600));
        assert_eq!(size_class(1920, 1440), 11);
        assert_eq!(size_class(7680, 4320), 12);
        assert_ne!(size_class(640, 480), size_class(1920, 1440));
        assert_eq!(size_class(1, 1), 0);
    }

    #[test]
    fn the_cache_sits_beside_the_scene_and_damage_is_explained() {
        assert_eq!(cache_path(Path::new("a/dragon.bvh")), Path::new("a/dragon.bvh.methods"));
        let dir = std::env::temp_dir().join(format!("auto-cache-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("x.methods");
        let e = Entry {
            key: Key { scene: "00112233aabbccdd".into(), rest: "device d; mode cast".into() },
            method: Method::Stackless,
            note: "lst 1.0 ms".into(),
        };
        write(&f, std::slice::from_ref(&e)).unwrap();
        assert_eq!(read(&f).unwrap(), vec![e]);
        for (text, says) in [
            ("garbage", "first line"),
            (&*format!("{MAGIC}\nabc\tdef\n"), "2 fields"),
            (&*format!("{MAGIC}\n00112233aabbccdd\tk\tnot-a-method\tn\n"), "names no method"),
            (&*format!("{MAGIC}\nzz\tk\tlst\tn\n"), "no scene hash"),
        ] {
            std::fs::write(&f, text).unwrap();
            let why = read(&f).unwrap_err();
            assert!(why.contains(says), "{why}");
        }
        assert_eq!(read(&dir.join("missing.methods")).unwrap(), vec![]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
