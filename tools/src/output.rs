//! Writing what a tracer produced: the image as PNG, the traversal cost as a false-colour PNG, and
//! the AOVs as one OpenEXR file.

use std::path::Path;
use tracer_cpu::{Aovs, Image};

fn write_rgb(path: &Path, width: u32, height: u32, rgb: &[[u8; 3]]) -> Result<(), String> {
    // The pixels as they are, without a copy: at 16384 x 16384 a copy would be another 805 MB.
    image::save_buffer(path, rgb.as_flattened(), width, height, image::ExtendedColorType::Rgb8)
        .map_err(|e| format!("cannot write {}: {e}", path.display()))
}

/// An 8-bit RGB image from any tracer.
pub struct Frame<'a> {
    pub width: u32,
    pub height: u32,
    pub rgb: &'a [[u8; 3]],
}

pub fn write_frame_png(path: &Path, f: &Frame<'_>) -> Result<(), String> {
    write_rgb(path, f.width, f.height, f.rgb)
}

pub fn write_png(path: &Path, img: &Image) -> Result<(), String> {
    write_rgb(path, img.width, img.height, &img.rgb)
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

/// The nodes-visited AOV in false colour, scaled so that the image's maximum is red; returns that
/// maximum so that the caller can print the scale.
pub fn write_heatmap(path: &Path, width: u32, height: u32, aov: &Aovs) -> Result<u32, String> {
    let max = aov.nodes.iter().copied().max().unwrap_or(0).max(1);
    let rgb: Vec<[u8; 3]> = aov.nodes.iter().map(|&n| false_colour(n as f32 / max as f32)).collect();
    write_rgb(path, width, height, &rgb)?;
    Ok(max)
}

/// One OpenEXR file with the channels `t`, `N.X`, `N.Y`, `N.Z` (f32), `prim`, `nodes`, `tris` (u32).
pub fn write_aov(path: &Path, width: u32, height: u32, aov: &Aovs) -> Result<(), String> {
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
    Image::from_layer(layer).write().to_file(path).map_err(|e| format!("cannot write {}: {e}", path.display()))
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
