//! Every file the programs write goes through here. The format of an output is decided from its
//! name, and all output paths are checked (known format, existing folder, no two outputs on one
//! file, none on an input) by [`check`] before any work; each file is then written under a
//! temporary name in its own folder and renamed only when complete ([`write_atomically`]), so that
//! a failure or an interrupt (Ctrl-C, SIGTERM, SIGHUP) leaves what was there before untouched.

use render_spec::Aovs;
use std::fs::File;
use std::io::{BufWriter, Seek, Write};
use std::path::{Path, PathBuf};
use thiserror::Error;

/// A file format, known from the file name's extension (any case).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    Png,
    Jpeg,
    Bmp,
    /// OpenEXR: the colour image as linear float RGB, or the AOVs.
    Exr,
    Csv,
    Markdown,
    Bvh,
}

impl Format {
    pub fn of(path: &Path) -> Option<Format> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "png" => Format::Png,
            "jpg" | "jpeg" => Format::Jpeg,
            "bmp" => Format::Bmp,
            "exr" => Format::Exr,
            "csv" => Format::Csv,
            "md" => Format::Markdown,
            "bvh" => Format::Bvh,
            _ => return None,
        })
    }

    pub fn extension(self) -> &'static str {
        match self {
            Format::Png => ".png",
            Format::Jpeg => ".jpg",
            Format::Bmp => ".bmp",
            Format::Exr => ".exr",
            Format::Csv => ".csv",
            Format::Markdown => ".md",
            Format::Bvh => ".bvh",
        }
    }
}

/// What an output holds, which decides the formats it may have.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    /// The rendered colour image: PNG, JPEG, BMP (8-bit) or OpenEXR (linear float).
    Image,
    /// The traversal cost in false colour: PNG, JPEG or BMP.
    Heatmap,
    /// Per-pixel outputs: OpenEXR only.
    Aov,
    /// A benchmark table: CSV (a Markdown copy is written beside it).
    Table,
    /// A Markdown table.
    Markdown,
    /// A compiled scene.
    Scene,
}

impl Kind {
    pub fn formats(self) -> &'static [Format] {
        match self {
            Kind::Image => &[Format::Png, Format::Jpeg, Format::Bmp, Format::Exr],
            Kind::Heatmap => &[Format::Png, Format::Jpeg, Format::Bmp],
            Kind::Aov => &[Format::Exr],
            Kind::Table => &[Format::Csv],
            Kind::Markdown => &[Format::Markdown],
            Kind::Scene => &[Format::Bvh],
        }
    }

    fn what(self) -> &'static str {
        match self {
            Kind::Image => "the image",
            Kind::Heatmap => "the heatmap",
            Kind::Aov => "the AOVs",
            Kind::Table => "the table",
            Kind::Markdown => "the Markdown table",
            Kind::Scene => "a scene file",
        }
    }
}

/// An output that passed [`check`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Output {
    pub path: PathBuf,
    pub format: Format,
}

/// Why an output cannot be written. One sentence each, naming the option and the file.
#[derive(Debug, Error)]
pub enum OutputError {
    #[error("{option} {}: {what} can be written as {allowed}; name the file accordingly", path.display())]
    Format { option: &'static str, path: PathBuf, what: &'static str, allowed: String },
    #[error("{option} {}: the folder {} does not exist", path.display(), folder.display())]
    NoFolder { option: &'static str, path: PathBuf, folder: PathBuf },
    #[error("{option} {} is a folder; give a file name", path.display())]
    IsFolder { option: &'static str, path: PathBuf },
    #[error("{first} and {second} both name {}; each output needs a file of its own", path.display())]
    Same { first: &'static str, second: &'static str, path: PathBuf },
    #[error("{option} {} would overwrite the input {}", path.display(), input.display())]
    OverwritesInput { option: &'static str, path: PathBuf, input: PathBuf },
    #[error("cannot write {}: {message}", path.display())]
    Write { path: PathBuf, message: String },
}

/// The folder and name a path refers to, with the folder resolved, so that two spellings of one
/// file compare equal. `None` when the folder does not exist.
fn identity(path: &Path) -> Option<(PathBuf, std::ffi::OsString)> {
    let folder = folder_of(path);
    Some((folder.canonicalize().ok()?, path.file_name()?.to_owned()))
}

fn folder_of(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// Checks every output before any work: each name has a format that its kind allows, each
/// folder exists, no two outputs name the same file and none names an input. `outputs` are
/// (option, path, kind); `inputs` the files the program reads.
pub fn check(outputs: &[(&'static str, &Path, Kind)], inputs: &[&Path]) -> Result<Vec<Output>, OutputError> {
    let mut checked = Vec::with_capacity(outputs.len());
    let mut seen: Vec<(&'static str, (PathBuf, std::ffi::OsString))> = Vec::new();
    for &(option, path, kind) in outputs {
        let format = Format::of(path).filter(|f| kind.formats().contains(f)).ok_or_else(|| {
            let names: Vec<&str> = kind.formats().iter().map(|f| f.extension()).collect();
            OutputError::Format { option, path: path.to_owned(), what: kind.what(), allowed: names.join(", ") }
        })?;
        if path.is_dir() || path.file_name().is_none() {
            return Err(OutputError::IsFolder { option, path: path.to_owned() });
        }
        let folder = folder_of(path);
        if !folder.is_dir() {
            return Err(OutputError::NoFolder { option, path: path.to_owned(), folder: folder.to_owned() });
        }
        let id = identity(path).ok_or_else(|| OutputError::NoFolder {
            option,
            path: path.to_owned(),
            folder: folder.to_owned(),
        })?;
        if let Some((first, _)) = seen.iter().find(|(_, other)| *other == id) {
            return Err(OutputError::Same { first, second: option, path: path.to_owned() });
        }
        if let Some(input) = inputs.iter().find(|i| identity(i).is_some_and(|i| i == id)) {
            return Err(OutputError::OverwritesInput { option, path: path.to_owned(), input: input.to_path_buf() });
        }
        seen.push((option, id));
        checked.push(Output { path: path.to_owned(), format });
    }
    Ok(checked)
}

/// Writes `path` through `write` by the workspace's one rule for outputs
/// ([`bvh_format::destination::write_replacing`]): a file is replaced only when its new version is
/// complete and on disk, and left as it was on any failure or interrupt; a link is followed to its
/// file; a device or a pipe (`/dev/null`) is written in place, never renamed over.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut BufWriter<File>) -> Result<(), String>,
) -> Result<(), OutputError> {
    bvh_format::destination::write_replacing(path, |w| write(w).map_err(std::io::Error::other))
        .map_err(|e| OutputError::Write { path: path.to_owned(), message: e.to_string() })
}

/// On Ctrl-C, SIGTERM or SIGHUP: removes every temporary file being written and exits with
/// 128 + the signal's number, as a shell reports a process the signal ended.
pub fn remove_partial_outputs_on_interrupt() {
    #[cfg(unix)]
    {
        use signal_hook::consts::{SIGHUP, SIGINT, SIGTERM};
        static INSTALLED: std::sync::Once = std::sync::Once::new();
        INSTALLED.call_once(|| {
            let Ok(mut signals) = signal_hook::iterator::Signals::new([SIGINT, SIGTERM, SIGHUP]) else { return };
            std::thread::spawn(move || {
                if let Some(signal) = signals.forever().next() {
                    bvh_format::destination::remove_temporaries();
                    let _ = writeln!(std::io::stderr(), "\ninterrupted; no output was left half-written");
                    std::process::exit(128 + signal);
                }
            });
        });
    }
}

/// An 8-bit RGB image from any tracer, row-major from the top-left pixel.
pub struct Frame<'a> {
    pub width: u32,
    pub height: u32,
    pub rgb: &'a [[u8; 3]],
    /// The same pixels unquantised, where the tracer keeps them (the f64 reference's mean of its
    /// samples): an EXR then holds these, not the 8-bit values, so an error metric against the
    /// reference measures the render and not the reference's rounding.
    pub linear: Option<&'a [[f32; 3]]>,
}

fn encode_rgb<W: Write + Seek>(w: &mut W, format: Format, f: &Frame<'_>) -> Result<(), String> {
    use image::ImageEncoder;
    let bytes: &[u8] = f.rgb.as_flattened();
    let colour = image::ExtendedColorType::Rgb8;
    let result = match format {
        Format::Png => image::codecs::png::PngEncoder::new(w).write_image(bytes, f.width, f.height, colour),
        Format::Jpeg => {
            image::codecs::jpeg::JpegEncoder::new_with_quality(w, 95).write_image(bytes, f.width, f.height, colour)
        }
        Format::Bmp => image::codecs::bmp::BmpEncoder::new(w).write_image(bytes, f.width, f.height, colour),
        Format::Exr => return encode_exr_rgb(w, f),
        other => return Err(format!("{} is not an image format", other.extension())),
    };
    result.map_err(|e| e.to_string())
}

/// The colour image as OpenEXR: linear float R, G, B. The tracers' colour is linear (no
/// gamma, docs/shading.md), so this is the 8-bit value over 255, or the unquantised value where
/// the frame has it.
fn encode_exr_rgb<W: Write + Seek>(w: &mut W, f: &Frame<'_>) -> Result<(), String> {
    use exr::prelude::*;
    let channel = |k: usize| {
        FlatSamples::F32(match f.linear {
            Some(linear) => linear.iter().map(|p| p[k]).collect(),
            None => f.rgb.iter().map(|p| f32::from(p[k]) / 255.0).collect(),
        })
    };
    let channels =
        vec![AnyChannel::new("R", channel(0)), AnyChannel::new("G", channel(1)), AnyChannel::new("B", channel(2))];
    let layer = Layer::new(
        (f.width as usize, f.height as usize),
        LayerAttributes::default(),
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(channels.into()),
    );
    Image::from_layer(layer).write().to_buffered(w).map_err(|e| e.to_string())
}

/// Writes the colour image in the format its name gave.
pub fn write_image(out: &Output, f: &Frame<'_>) -> Result<(), OutputError> {
    write_atomically(&out.path, |w| encode_rgb(w, out.format, f))
}

/// Writes text (CSV, Markdown) to a checked output.
pub fn write_text(out: &Output, text: &str) -> Result<(), OutputError> {
    write_atomically(&out.path, |w| w.write_all(text.as_bytes()).map_err(|e| e.to_string()))
}

/// Writes a chart drawn in memory (plotters' `SVGBackend::with_string` and
/// `BitMapBackend::with_buffer`, RGB8 rows) as `svg_path` and `png_path`, each replaced only
/// when complete, so that a failed run leaves the previous charts as they were.
pub fn write_chart(
    svg_path: &Path,
    svg: &str,
    png_path: &Path,
    size: (u32, u32),
    pixels: &[u8],
) -> Result<(), OutputError> {
    write_atomically(svg_path, |w| w.write_all(svg.as_bytes()).map_err(|e| e.to_string()))?;
    let rgb: Vec<[u8; 3]> = pixels.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect();
    let out = Output { path: png_path.to_owned(), format: Format::Png };
    write_image(&out, &Frame { width: size.0, height: size.1, rgb: &rgb, linear: None })
}

/// A false-colour ramp from dark blue (0) through cyan, green and yellow to red (1).
pub fn false_colour(x: f32) -> [u8; 3] {
    const STOPS: [[f32; 3]; 6] =
        [[0.05, 0.03, 0.25], [0.1, 0.35, 0.9], [0.1, 0.8, 0.8], [0.3, 0.85, 0.2], [0.95, 0.85, 0.1], [0.85, 0.1, 0.05]];
    let x = if x.is_finite() { x.clamp(0.0, 1.0) } else { 0.0 } * (STOPS.len() - 1) as f32;
    let i = (x as usize).min(STOPS.len() - 2);
    let f = x - i as f32;
    let c = |k: usize| ((STOPS[i][k] * (1.0 - f) + STOPS[i + 1][k] * f) * 255.0 + 0.5) as u8;
    [c(0), c(1), c(2)]
}

/// Digits 0-9 in a 3 x 5 pixel font, one bit per pixel, rows top down, 3 bits per row.
const DIGITS: [u16; 10] = [
    0b111_101_101_101_111,
    0b010_110_010_010_111,
    0b111_001_111_100_111,
    0b111_001_111_001_111,
    0b101_101_111_001_001,
    0b111_100_111_001_111,
    0b111_100_111_101_111,
    0b111_001_001_001_001,
    0b111_101_111_101_111,
    0b111_101_111_001_111,
];

/// A false-colour image of the nodes visited per pixel, with its legend: a colour bar below the
/// image from 0 (left) to `max` (right), both numbers written under it.
pub struct Heatmap {
    pub width: u32,
    /// The image's height plus the legend's.
    pub height: u32,
    pub rgb: Vec<[u8; 3]>,
    /// The value shown as red: the image's maximum, or the fixed scale asked for.
    pub max: u32,
    /// Pixels above a fixed scale (drawn red).
    pub clipped: usize,
}

impl Heatmap {
    /// `fixed`: a scale to use instead of the image's maximum, so that two heatmaps compare.
    pub fn new(width: u32, height: u32, nodes: &[u32], fixed: Option<u32>) -> Heatmap {
        let max = fixed.unwrap_or_else(|| nodes.iter().copied().max().unwrap_or(0)).max(1);
        let mut rgb: Vec<[u8; 3]> = nodes.iter().map(|&n| false_colour(n as f32 / max as f32)).collect();
        let clipped = nodes.iter().filter(|&&n| n > max).count();
        let w = width as usize;
        let scale = if w >= 96 { 2 } else { 1 };
        let (gap, bar, text) = (2 * scale, 4 * scale, 5 * scale);
        let band = gap + bar + 1 + text + gap;
        rgb.resize(w * (height as usize + band), [0, 0, 0]);
        let top = height as usize * w;
        for y in gap..gap + bar {
            for x in 0..w {
                rgb[top + y * w + x] = false_colour(x as f32 / (w.max(2) - 1) as f32);
            }
        }
        let label = max.to_string();
        let glyph_w = 4 * scale;
        if w >= (label.len() + 2) * glyph_w {
            let y0 = gap + bar + 1;
            let mut put = |x0: usize, digit: usize| {
                for row in 0..5 {
                    for col in 0..3 {
                        if DIGITS[digit] >> (14 - (row * 3 + col)) & 1 == 1 {
                            for dy in 0..scale {
                                for dx in 0..scale {
                                    rgb[top + (y0 + row * scale + dy) * w + x0 + col * scale + dx] = [255; 3];
                                }
                            }
                        }
                    }
                }
            };
            put(0, 0);
            let x0 = w - label.len() * glyph_w + scale;
            for (i, d) in label.bytes().enumerate() {
                put(x0 + i * glyph_w - scale, usize::from(d - b'0'));
            }
        }
        Heatmap { width, height: height + band as u32, rgb, max, clipped }
    }
}

/// Writes a heatmap (with its legend) in the format its name gave.
pub fn write_heatmap(out: &Output, h: &Heatmap) -> Result<(), OutputError> {
    write_image(out, &Frame { width: h.width, height: h.height, rgb: &h.rgb, linear: None })
}

/// One OpenEXR file with the channels `t`, `N.X`, `N.Y`, `N.Z` (f32), `prim`, `nodes`, `tris` (u32).
pub fn write_aov(out: &Output, width: u32, height: u32, aov: &Aovs) -> Result<(), OutputError> {
    use exr::prelude::*;
    let f32s = |v: Vec<f32>| FlatSamples::F32(v);
    let channels = vec![
        AnyChannel::new("t", f32s(aov.t.clone())),
        AnyChannel::new("N.X", f32s(aov.normal.iter().map(|n| n[0]).collect())),
        AnyChannel::new("N.Y", f32s(aov.normal.iter().map(|n| n[1]).collect())),
        AnyChannel::new("N.Z", f32s(aov.normal.iter().map(|n| n[2]).collect())),
        AnyChannel::new("prim", FlatSamples::U32(aov.prim.clone())),
        AnyChannel::new("nodes", FlatSamples::U32(aov.nodes.clone())),
        AnyChannel::new("tris", FlatSamples::U32(aov.tris.clone())),
    ];
    let layer = Layer::new(
        (width as usize, height as usize),
        LayerAttributes::named("aov"),
        Encoding::FAST_LOSSLESS,
        AnyChannels::sort(channels.into()),
    );
    write_atomically(&out.path, |w| Image::from_layer(layer).write().to_buffered(w).map_err(|e| e.to_string()))
}

/// Reads back an AOV file written by [`write_aov`] (for tests and tools that compare backends).
pub fn read_aov(path: &Path) -> Result<(u32, u32, Aovs), String> {
    use exr::prelude::*;
    let err = |e: exr::error::Error| format!("cannot read {}: {e}", path.display());
    let image = read_all_flat_layers_from_file(path).map_err(err)?;
    let layer = image.layer_data.first().ok_or_else(|| format!("{} holds no layer", path.display()))?;
    let size = layer.size;
    let find = |name: &str| {
        layer
            .channel_data
            .list
            .iter()
            .find(|c| c.name.eq(name))
            .ok_or_else(|| format!("{} has no channel {name}", path.display()))
    };
    let f = |name: &str| -> std::result::Result<Vec<f32>, String> {
        match &find(name)?.sample_data {
            FlatSamples::F32(v) => Ok(v.clone()),
            _ => Err(format!("channel {name} of {} is not f32", path.display())),
        }
    };
    let u = |name: &str| -> std::result::Result<Vec<u32>, String> {
        match &find(name)?.sample_data {
            FlatSamples::U32(v) => Ok(v.clone()),
            _ => Err(format!("channel {name} of {} is not u32", path.display())),
        }
    };
    let (nx, ny, nz) = (f("N.X")?, f("N.Y")?, f("N.Z")?);
    let aov = Aovs {
        t: f("t")?,
        normal: nx.iter().zip(&ny).zip(&nz).map(|((x, y), z)| [*x, *y, *z]).collect(),
        prim: u("prim")?,
        nodes: u("nodes")?,
        tris: u("tris")?,
    };
    Ok((size.0 as u32, size.1 as u32, aov))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("tools-output-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn outputs_are_checked_by_name_folder_and_identity() {
        let d = scratch("check");
        let img = d.join("a.png");
        let ok = check(&[("-o", &img, Kind::Image), ("--aov", &d.join("a.exr"), Kind::Aov)], &[]).unwrap();
        assert_eq!(ok[0].format, Format::Png);
        assert_eq!(ok[1].format, Format::Exr);
        assert_eq!(check(&[("-o", &d.join("x.JPEG"), Kind::Image)], &[]).unwrap()[0].format, Format::Jpeg);
        let e = check(&[("--aov", &d.join("a.png"), Kind::Aov)], &[]).unwrap_err().to_string();
        assert!(e.contains("--aov") && e.contains(".exr"), "{e}");
        let e = check(&[("-o", &d.join("y.tiff"), Kind::Image)], &[]).unwrap_err().to_string();
        assert!(e.contains(".png, .jpg, .bmp, .exr"), "{e}");
        let e = check(&[("-o", &d.join("missing/a.png"), Kind::Image)], &[]).unwrap_err().to_string();
        assert!(e.contains("does not exist"), "{e}");
        let other = d.join(".").join("a.png");
        let e = check(&[("-o", &img, Kind::Image), ("--heatmap", &other, Kind::Heatmap)], &[]).unwrap_err();
        assert!(matches!(e, OutputError::Same { first: "-o", second: "--heatmap", .. }), "{e}");
        let e = check(&[("-o", &img, Kind::Image)], &[&img]).unwrap_err();
        assert!(matches!(e, OutputError::OverwritesInput { .. }), "{e}");
    }

    #[test]
    fn a_failed_write_leaves_the_old_file_and_no_temporary() {
        let d = scratch("atomic");
        let p = d.join("keep.png");
        std::fs::write(&p, b"old").unwrap();
        let e = write_atomically(&p, |w| {
            w.write_all(b"half").map_err(|e| e.to_string())?;
            Err("the encoder failed".to_owned())
        });
        assert!(e.unwrap_err().to_string().contains("the encoder failed"));
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
        assert!(!bvh_format::destination::temporary_name(&p).exists());
        write_atomically(&p, |w| w.write_all(b"new").map_err(|e| e.to_string())).unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new");
        assert_eq!(std::fs::read_dir(&d).unwrap().count(), 1, "only the output remains");
    }

    /// Renamed over, `/dev/null` became an empty regular file for the whole machine (as root), and
    /// a link became a file beside the one it named. Through a link to `/dev/null`, so that a
    /// regression replaces the test's link, not the device.
    #[cfg(unix)]
    #[test]
    fn a_link_is_written_through_and_a_device_in_place() {
        use std::os::unix::fs::FileTypeExt;
        let d = scratch("links");
        let target = d.join("target.png");
        std::fs::write(&target, b"old").unwrap();
        let link = d.join("link.png");
        let _ = std::fs::remove_file(&link);
        std::os::unix::fs::symlink(&target, &link).unwrap();
        write_atomically(&link, |w| w.write_all(b"new").map_err(|e| e.to_string())).unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(), "the link stays a link");
        assert_eq!(std::fs::read(&target).unwrap(), b"new", "the file it names is replaced");
        let null = d.join("null.png");
        let _ = std::fs::remove_file(&null);
        std::os::unix::fs::symlink("/dev/null", &null).unwrap();
        write_atomically(&null, |w| w.write_all(b"discarded").map_err(|e| e.to_string())).unwrap();
        assert!(std::fs::symlink_metadata(&null).unwrap().file_type().is_symlink());
        assert!(std::fs::metadata("/dev/null").unwrap().file_type().is_char_device());
        let names: Vec<_> = std::fs::read_dir(&d).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(names.len(), 3, "no temporary file left: {names:?}");
    }

    #[test]
    fn heatmap_carries_its_scale() {
        let nodes: Vec<u32> = (0..128 * 4).map(|i| i % 128).collect();
        let h = Heatmap::new(128, 4, &nodes, None);
        assert_eq!(h.max, 127);
        assert!(h.height > 4, "a legend below the image");
        assert_eq!(h.rgb.len(), (128 * h.height) as usize);
        assert!(h.rgb[(4 * 128)..].contains(&[255; 3]), "numbers drawn in the legend");
        let fixed = Heatmap::new(128, 4, &nodes, Some(63));
        assert_eq!(fixed.max, 63);
        assert_eq!(fixed.clipped, 4 * 64);
        assert_eq!(fixed.rgb[127], false_colour(1.0));
        assert_eq!(fixed.rgb[63], h.rgb[127], "63 at a fixed scale of 63 is as red as 127 at 127");
    }
}
