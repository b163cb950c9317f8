//! The wide layout: an 8-wide tree with child boxes quantised to 8 bits per axis relative to their
//! parent (Ylitie, Karras and Laine, "Efficient Incoherent Ray Traversal on GPUs Through
//! Compressed Wide BVHs", HPG 2017), its own tree over the file's triangles beside the binary one,
//! and its validation. Kept apart from the binary layouts' checks (`tree.rs`), which it does not
//! share: its nodes are not [`crate::Node`]s.

use crate::error::FormatError;
use crate::types::IndexedTriangle;
use bytemuck::{Pod, Zeroable};

/// Children per wide node.
pub const WIDTH: usize = 8;
/// A leaf child holds at most this many triangles (3 bits of its meta byte).
pub const MAX_LEAF: u32 = 8;
/// A node's leaf children lie within this many triangles from its `triangle_base` (the 32-bit
/// triangle hit mask of the traversal).
pub const TRIANGLE_WINDOW: u32 = 32;
/// The meta byte of an empty slot.
pub const EMPTY: u8 = 0xFF;

/// One node of the wide layout, 80 bytes (five 16-byte rows). Every bit:
///
/// - `origin` (bytes 0..12, `f32[3]`): the corner of the node's quantisation grid, in the file's
///   local coordinates; finite.
/// - `exponents` (bytes 12..15, `u8[3]`): per axis the biased exponent `e` of the grid step
///   `2^(e - 127)` (the bit pattern of that f32 is `e << 23`); each in 1..=254, so the step is a
///   normal f32 and a quantised coordinate times it is exact.
/// - `inner_mask` (byte 15): bit `s` set when slot `s` holds an inner child.
/// - `child_base` (bytes 16..20): the index of the first inner child. The inner children are
///   consecutive nodes, in slot order: slot `s` holds node `child_base + popcount(inner_mask &
///   ((1 << s) - 1))`. Children come after their parent (`child_base` > the node's index).
/// - `triangle_base` (bytes 20..24): the first triangle of the node's leaf children.
/// - `meta` (bytes 24..32, `u8[8]`): per slot, 0 for an inner child; [`EMPTY`] (0xFF) for an
///   empty slot; for a leaf child `(count - 1) << 5 | offset`: the triangles `[triangle_base +
///   offset, triangle_base + offset + count)`, with `count` 1..=8 and `offset + count <= 32` (so
///   0xFF, count 8 at offset 31, is no leaf).
/// - `lo`, `hi` (bytes 32..56 and 56..80, `u8[3][8]`): per axis, then per slot, the quantised
///   corners of the child's box. The box's coordinate on axis `a` is the f32 sum
///   `origin[a] + q * 2^(exponents[a] - 127)` (the product is exact, the sum rounded to nearest
///   once, as a GPU computes it with or without a fused multiply-add); `lo <= hi`, and all six
///   are zero in an empty slot. The decoded box contains every vertex of every triangle beneath
///   the child (conservative: the compiler rounds outwards).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct WideNode {
    pub origin: [f32; 3],
    pub exponents: [u8; 3],
    pub inner_mask: u8,
    pub child_base: u32,
    pub triangle_base: u32,
    pub meta: [u8; WIDTH],
    pub lo: [[u8; WIDTH]; 3],
    pub hi: [[u8; WIDTH]; 3],
}

/// What occupies one slot of a wide node.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    Empty,
    /// Node index of an inner child.
    Inner(u32),
    /// A leaf child: its first triangle and triangle count.
    Leaf {
        first: u32,
        count: u32,
    },
}

impl WideNode {
    /// The grid step of axis `a`.
    pub fn step(&self, a: usize) -> f32 {
        f32::from_bits(u32::from(self.exponents[a]) << 23)
    }

    /// The meta byte of a leaf of `count` triangles at `offset`.
    pub fn leaf_meta(offset: u32, count: u32) -> u8 {
        debug_assert!((1..=MAX_LEAF).contains(&count) && offset + count <= TRIANGLE_WINDOW);
        (((count - 1) << 5) | offset) as u8
    }

    /// What slot `s` holds, read from the bits as a traversal reads them (not validated).
    pub fn slot(&self, s: usize) -> Slot {
        if self.inner_mask & (1 << s) != 0 {
            let rank = (self.inner_mask & ((1u16 << s) - 1) as u8).count_ones();
            return Slot::Inner(self.child_base.wrapping_add(rank));
        }
        match self.meta[s] {
            EMPTY => Slot::Empty,
            m => Slot::Leaf { first: self.triangle_base.wrapping_add(u32::from(m & 31)), count: u32::from(m >> 5) + 1 },
        }
    }

    /// The decoded box of slot `s`: `(min, max)` in f32, as the traversal computes it.
    pub fn child_box(&self, s: usize) -> ([f32; 3], [f32; 3]) {
        let o = self.origin;
        let decode = |a: usize, q: u8| o[a] + f32::from(q) * self.step(a);
        ([0, 1, 2].map(|a| decode(a, self.lo[a][s])), [0, 1, 2].map(|a| decode(a, self.hi[a][s])))
    }
}

/// Depth of the deepest node of a validated wide tree (the root has depth 0): the traversal's
/// stack holds at most one node group per level below the root.
pub fn depth(nodes: &[WideNode]) -> u32 {
    let mut depth = vec![0u32; nodes.len()];
    let mut deepest = 0;
    for i in 0..nodes.len() {
        let d = depth[i];
        deepest = deepest.max(d);
        for s in 0..WIDTH {
            if let Slot::Inner(c) = nodes[i].slot(s) {
                depth[c as usize] = d + 1;
            }
        }
    }
    deepest
}

/// Checks that `nodes` form one wide tree over the file's triangles: every node reached once
/// from the root (children after their parent, so no cycles), every field within what the
/// layout allows, leaf ranges inside the triangle array, every triangle in exactly one leaf, and
/// every decoded child box containing every vertex of every triangle beneath the child. Linear
/// in the nodes and triangles, no recursion.
pub fn validate(nodes: &[WideNode], triangles: &[IndexedTriangle], vertices: &[[f32; 3]]) -> Result<(), FormatError> {
    let bad = |node: usize, reason: &'static str| FormatError::WideShape { node: node as u32, reason };
    let len = nodes.len();
    if len == 0 {
        return Err(bad(0, "the layout has no nodes"));
    }
    if len > u32::MAX as usize {
        return Err(bad(0, "the layout has too many nodes"));
    }
    let n_tris = triangles.len() as u64;
    // Shape: fields, children after their parent, each node the child of exactly one slot.
    let mut parent_seen = vec![false; len];
    let mut covered = vec![false; triangles.len()];
    for (i, n) in nodes.iter().enumerate() {
        if n.origin.iter().any(|v| !v.is_finite()) {
            return Err(bad(i, "its grid origin is not finite"));
        }
        if n.exponents.iter().any(|&e| e == 0 || e == 255) {
            return Err(bad(i, "a grid exponent is outside 1 to 254"));
        }
        let inner = n.inner_mask.count_ones();
        if inner > 0 {
            let base = n.child_base as u64;
            if base <= i as u64 {
                return Err(bad(i, "its children do not come after it"));
            }
            if base + inner as u64 > len as u64 {
                return Err(bad(i, "its child index is past the last node"));
            }
        }
        let mut children = 0;
        for s in 0..WIDTH {
            let slot = n.slot(s);
            let (lo, hi) = ([0, 1, 2].map(|a| n.lo[a][s]), [0, 1, 2].map(|a| n.hi[a][s]));
            match slot {
                Slot::Empty => {
                    if lo != [0; 3] || hi != [0; 3] {
                        return Err(bad(i, "an empty slot has a box"));
                    }
                    continue;
                }
                Slot::Inner(c) => {
                    if n.meta[s] != 0 {
                        return Err(bad(i, "an inner child's meta byte is not zero"));
                    }
                    if std::mem::replace(&mut parent_seen[c as usize], true) {
                        return Err(bad(i, "a child is shared with another node"));
                    }
                }
                Slot::Leaf { first, count } => {
                    if u32::from(n.meta[s] & 31) + count > TRIANGLE_WINDOW {
                        return Err(bad(i, "a leaf reaches past the node's 32-triangle window"));
                    }
                    if n.triangle_base as u64 + u64::from(n.meta[s] & 31) + count as u64 > n_tris {
                        return Err(bad(i, "a leaf's triangle range reaches past the last triangle"));
                    }
                    for t in first..first + count {
                        if std::mem::replace(&mut covered[t as usize], true) {
                            return Err(FormatError::WideCoverage { triangle: t, times: 2 });
                        }
                    }
                }
            }
            children += 1;
            if (0..3).any(|a| lo[a] > hi[a]) {
                return Err(bad(i, "a child box has its low corner above its high corner"));
            }
            let (bmin, bmax) = n.child_box(s);
            if bmin.iter().chain(&bmax).any(|v| !v.is_finite()) {
                return Err(bad(i, "a child box decodes to a number that is not finite"));
            }
        }
        if children == 0 {
            return Err(bad(i, "it has no children"));
        }
    }
    if parent_seen[0] {
        return Err(bad(0, "the root is the child of another node"));
    }
    if let Some(orphan) = parent_seen.iter().skip(1).position(|s| !s) {
        return Err(bad(orphan + 1, "it cannot be reached from the root"));
    }
    if let Some(t) = covered.iter().position(|c| !c) {
        return Err(FormatError::WideCoverage { triangle: t as u32, times: 0 });
    }
    check_boxes(nodes, triangles, vertices)
}

/// Bounds of the triangles `[first, first + count)` (all valid indices).
fn triangle_bounds(first: u32, count: u32, triangles: &[IndexedTriangle], vertices: &[[f32; 3]]) -> [[f32; 3]; 2] {
    let mut b = [[f32::INFINITY; 3], [f32::NEG_INFINITY; 3]];
    for t in &triangles[first as usize..(first + count) as usize] {
        for &v in &t.vertices {
            let p = vertices[v as usize];
            for a in 0..3 {
                b[0][a] = b[0][a].min(p[a]);
                b[1][a] = b[1][a].max(p[a]);
            }
        }
    }
    b
}

/// Bottom-up (children come after their parents): the exact bounds of each node's triangles, and
/// each slot's decoded box around its child's.
fn check_boxes(nodes: &[WideNode], triangles: &[IndexedTriangle], vertices: &[[f32; 3]]) -> Result<(), FormatError> {
    let mut bounds = vec![[[f32::INFINITY; 3], [f32::NEG_INFINITY; 3]]; nodes.len()];
    for i in (0..nodes.len()).rev() {
        let n = &nodes[i];
        let mut all = [[f32::INFINITY; 3], [f32::NEG_INFINITY; 3]];
        for s in 0..WIDTH {
            let inside = match n.slot(s) {
                Slot::Empty => continue,
                Slot::Inner(c) => bounds[c as usize],
                Slot::Leaf { first, count } => triangle_bounds(first, count, triangles, vertices),
            };
            let (bmin, bmax) = n.child_box(s);
            if (0..3).any(|a| bmin[a] > inside[0][a] || bmax[a] < inside[1][a]) {
                return Err(FormatError::WideBoxTooSmall { node: i as u32, slot: s as u32 });
            }
            for a in 0..3 {
                all[0][a] = all[0][a].min(inside[0][a]);
                all[1][a] = all[1][a].max(inside[1][a]);
            }
        }
        bounds[i] = all;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_node_is_80_bytes_with_the_documented_offsets() {
        assert_eq!(std::mem::size_of::<WideNode>(), 80);
        let n = WideNode { inner_mask: 0xAB, child_base: 7, triangle_base: 9, ..WideNode::zeroed() };
        let b = bytemuck::bytes_of(&n);
        assert_eq!(b[15], 0xAB);
        assert_eq!(u32::from_le_bytes(b[16..20].try_into().unwrap()), 7);
        assert_eq!(u32::from_le_bytes(b[20..24].try_into().unwrap()), 9);
        let mut n = WideNode::zeroed();
        n.lo[1][3] = 1;
        n.hi[2][7] = 2;
        n.meta[5] = 3;
        let b = bytemuck::bytes_of(&n);
        assert_eq!((b[24 + 5], b[32 + 8 + 3], b[56 + 16 + 7]), (3, 1, 2));
    }

    #[test]
    fn slots_decode_as_documented() {
        let mut n = WideNode { inner_mask: 0b1010_0100, child_base: 10, triangle_base: 100, ..WideNode::zeroed() };
        n.meta = [EMPTY, WideNode::leaf_meta(0, 3), 0, WideNode::leaf_meta(3, 8), EMPTY, 0, EMPTY, 0];
        assert_eq!(n.slot(0), Slot::Empty);
        assert_eq!(n.slot(1), Slot::Leaf { first: 100, count: 3 });
        assert_eq!(n.slot(2), Slot::Inner(10));
        assert_eq!(n.slot(3), Slot::Leaf { first: 103, count: 8 });
        assert_eq!(n.slot(5), Slot::Inner(11));
        assert_eq!(n.slot(7), Slot::Inner(12));
        assert_eq!(WideNode::leaf_meta(24, 8), 0xF8);
        n.exponents = [127, 126, 130];
        n.origin = [1.0, -2.0, 0.5];
        n.lo[0][2] = 3;
        n.hi[2][2] = 255;
        let (lo, hi) = n.child_box(2);
        assert_eq!(lo, [4.0, -2.0, 0.5]);
        assert_eq!(hi, [1.0, -2.0, 0.5 + 255.0 * 8.0]);
    }
}
