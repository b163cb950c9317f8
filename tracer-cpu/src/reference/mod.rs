//! The exact reference: the ground truth every other image and hit is measured against.
//!
//! Everything is f64, on the file's f32 data widened exactly (vertices, normals, boxes, materials,
//! lights, camera):
//!
//! - [`brute`]: the closest hit over every triangle, which tests trust ([`closest_hit`]).
//! - [`bvh`]: the same hits found through the file's tree ([`Bvh`]), fast enough for whole images
//!   of a million triangles, and tested to equal brute force.
//! - [`render`]: images by the shading definition of docs/shading.md in f64, with every bounce up
//!   to the indirection limit (no adaptive stop) and `n x n` samples per pixel ([`render()`]).
//!
//! What "exact" means here: each operation rounds to f64, about 2^29 times finer than f32, so the
//! reference's own error lies far below anything an 8-bit pixel or a metric can show. The shading
//! formulas, sample positions, tie rule and origin offset are the fast tracers' own, so that every
//! difference from a fast image is an error of f32 arithmetic or of a speed setting, not a
//! different model.

pub mod brute;
pub mod bvh;
pub mod render;

pub use brute::{RefHit, closest_hit, edge_distance, intersect64};
pub use bvh::Bvh;
pub use render::{ReferenceImage, render, render_with_progress};
