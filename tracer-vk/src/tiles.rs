//! Splitting a frame into tiles that fit the device: every per-pixel buffer of a tile must fit one
//! storage buffer binding (maxStorageBufferRange: 128 MiB on lavapipe, 4 GiB on an H100), one
//! allocation, a share of the device's memory, and its workgroups one dispatch.

use crate::device::DeviceInfo;

/// Bytes of the largest per-pixel buffer element (the colours: the path's, its hit's local term
/// and the sum over samples).
pub const LARGEST_PIXEL_RECORD: u64 = 48;
/// Bytes of all per-pixel state together: path 32, hit 16, colours 48, AOVs 32, image 4.
pub const PIXEL_BYTES: u64 = 132;
/// The per-pixel state of a tile takes at most this share of the device's memory, leaving the
/// rest to the scene and to other programs.
const MEMORY_SHARE: u64 = 4;

/// A rectangle of the image, rendered by one round of passes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tile {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

impl Tile {
    pub fn pixels(&self) -> u64 {
        self.width as u64 * self.height as u64
    }
}

/// The most pixels one tile may hold on this device.
pub fn device_tile_pixels(info: &DeviceInfo) -> u64 {
    let per_binding = info.max_storage_buffer_range.min(info.max_memory_allocation) / LARGEST_PIXEL_RECORD;
    let by_memory = info.device_local_bytes / MEMORY_SHARE / PIXEL_BYTES;
    // The kernels index pixels with 32-bit integers.
    per_binding.min(by_memory).min(u32::MAX as u64)
}

/// Splits a `width` x `height` image into tiles of at most `max_pixels` pixels: bands of whole
/// rows where a band of one workgroup's height fits, else bands cut into columns. Tiles start on
/// workgroup boundaries, so the blocks of pixels a workgroup traces do not depend on the split,
/// and no tile needs more than `max_groups` workgroups in x or y. `None` when not even one
/// workgroup's pixels fit.
pub fn plan(
    width: u32,
    height: u32,
    max_pixels: u64,
    workgroup: (u32, u32),
    max_groups: [u32; 2],
) -> Option<Vec<Tile>> {
    let (wx, wy) = (workgroup.0 as u64, workgroup.1 as u64);
    if width == 0 || height == 0 || wx * wy > max_pixels || max_groups[0] == 0 || max_groups[1] == 0 {
        return None;
    }
    let tile_w = (width as u64).min(max_groups[0] as u64 * wx).min(max_pixels / wy / wx * wx);
    let tile_h = (height as u64).min(max_groups[1] as u64 * wy).min(max_pixels / tile_w / wy * wy);
    let (tile_w, tile_h) = (tile_w as u32, tile_h as u32);
    let mut tiles = Vec::new();
    for y in (0..height).step_by(tile_h as usize) {
        for x in (0..width).step_by(tile_w as usize) {
            tiles.push(Tile { x, y, width: tile_w.min(width - x), height: tile_h.min(height - y) });
        }
    }
    Some(tiles)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn covers_once(tiles: &[Tile], w: u32, h: u32) {
        let mut seen = vec![0u8; (w * h) as usize];
        for t in tiles {
            for y in t.y..t.y + t.height {
                for x in t.x..t.x + t.width {
                    seen[(y * w + x) as usize] += 1;
                }
            }
        }
        assert!(seen.iter().all(|&n| n == 1), "the tiles must cover every pixel exactly once");
    }

    #[test]
    fn a_frame_within_the_limit_is_one_tile() {
        let t = plan(640, 480, 1 << 22, (8, 8), [65535; 2]).unwrap();
        assert_eq!(t, [Tile { x: 0, y: 0, width: 640, height: 480 }]);
    }

    #[test]
    fn tiles_respect_the_limits_and_cover_the_image() {
        for (w, h, max, wg, groups) in [
            (100, 37, 1000, (4, 2), [65535, 65535]),
            (1000, 10, 700, (8, 8), [65535, 65535]),
            (33, 65, 64, (8, 8), [65535, 65535]),
            (50, 50, 1 << 20, (1, 1), [7, 65535]),
            (16384, 16384, 1 << 22, (8, 8), [65535, 65535]),
        ] {
            let tiles = plan(w, h, max, wg, groups).unwrap();
            covers_once(&tiles, w, h);
            for t in &tiles {
                assert!(t.pixels() <= max, "{t:?} holds more than {max} pixels");
                assert_eq!(t.x % wg.0, 0, "{t:?} starts inside a workgroup");
                assert_eq!(t.y % wg.1, 0, "{t:?} starts inside a workgroup");
                assert!(t.width.div_ceil(wg.0) <= groups[0] && t.height.div_ceil(wg.1) <= groups[1]);
            }
        }
        assert_eq!(plan(16384, 16384, 1 << 22, (8, 8), [65535; 2]).unwrap().len(), 64);
    }

    #[test]
    fn a_limit_below_one_workgroup_is_refused() {
        assert_eq!(plan(64, 64, 63, (8, 8), [65535; 2]), None);
        assert_eq!(plan(0, 64, 1000, (8, 8), [65535; 2]), None);
    }
}
