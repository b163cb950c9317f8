//! The wide layout of the file ([`bvh_format::wide`]): the binary SAH tree collapsed into nodes of
//! up to eight children, the triangles put in the order the wide leaves need, and the child boxes
//! quantised to 8 bits per axis.
//!
//! Collapse: greedy, top-down. A wide node starts with its binary node's two children and
//! repeatedly opens the inner child of largest surface area (replacing it by its two children)
//! while it has fewer than eight children and its leaf children keep within the 32-triangle
//! window. A binary subtree of at most [`MERGE`] triangles is one wide leaf (its binary leaves
//! stored one after another), as Ylitie et al.'s leaves of up to 3 triangles: without it the
//! bottom levels of the wide tree are nodes of two or three tiny leaves (the dragon's wide layout:
//! 13.3 bytes per triangle without merging, 10.8 with it; 4.2 children per node). Ylitie, Karras and Laine
//! choose the cut by an SAH dynamic programme over the binary tree; the greedy cut by area is the
//! one Embree and most wide-BVH builders use, costs one pass, and opens first the children a ray
//! is most likely to enter, which is what the programme optimises.
//!
//! Triangle order: a node's leaf children must lie in a window of 32 triangles from its
//! `triangle_base`, so the compiler stores the triangles wide node by wide node (each node's
//! leaves in slot order) when the wide layout is asked for. The binary layouts' leaves are
//! renumbered to match (their leaves are the same ranges), so no index array is needed: the file
//! holds one triangle order for every layout, and a triangle's number means the same in all.
//!
//! Child slots follow the ray octant (Ylitie et al., section 3.1): slot `s` is for rays whose
//! direction has the signs of `s` (bit 0 x, bit 1 y, bit 2 z negative), and gets the child nearest
//! to the node's entry for such rays (smallest projection of its centre on the octant's diagonal),
//! assigned greedily by that cost; a ray of octant `o` then visits slot `s` in the order `s ^ o`.

use crate::BuildError;
use bvh_format::Node;
use bvh_format::tree::half_area;
use bvh_format::wide::{EMPTY, MAX_LEAF, TRIANGLE_WINDOW, WIDTH, WideNode};
use std::collections::VecDeque;

/// A binary subtree of at most this many triangles becomes one wide leaf (Ylitie et al.'s largest
/// leaf); larger binary leaves (up to [`MAX_LEAF`]) stay leaves as they are.
pub const MERGE: u32 = 3;

/// The wide tree before quantisation, in binary node indices.
pub struct Plan {
    shapes: Vec<Shape>,
    /// For each binary leaf and each binary subtree that is one wide leaf (by index in the
    /// child-pair layout), its first triangle in the wide order; `u32::MAX` elsewhere.
    new_start: Vec<u32>,
}

struct Shape {
    /// The binary node this wide node stands for (its box is the quantisation frame).
    binary: u32,
    /// Per slot, the binary node of the child, and whether it is a leaf of the wide tree (a binary
    /// leaf or a merged subtree).
    slots: [Option<(u32, bool)>; WIDTH],
    child_base: u32,
    triangle_base: u32,
}

/// Collapses a child-pair tree (validated) into the wide tree's shape. Refuses leaves of more than
/// [`MAX_LEAF`] triangles, which a wide leaf cannot hold.
pub fn collapse(cp: &[Node]) -> Result<Plan, BuildError> {
    if let Some(big) = cp.iter().filter(|n| n.is_leaf()).map(|n| n.count).find(|&c| c > MAX_LEAF) {
        return Err(BuildError::Params(format!(
            "the wide layout holds leaves of at most {MAX_LEAF} triangles, and this tree has one of {big}; compile it with --max-leaf-size {MAX_LEAF} or less"
        )));
    }
    // Triangles beneath each binary node (children come after their parents).
    let mut below = vec![0u32; cp.len()];
    for i in (0..cp.len()).rev() {
        let n = &cp[i];
        below[i] = if n.is_leaf() { n.count } else { below[n.index as usize] + below[n.index as usize + 1] };
    }
    let is_leaf = |c: u32| cp[c as usize].is_leaf() || below[c as usize] <= MERGE;
    let leaf_tris = |c: u32| if is_leaf(c) { below[c as usize] } else { 0 };
    let area = |c: u32| half_area(cp[c as usize].min, cp[c as usize].max);
    let mut shapes = Vec::new();
    let mut new_start = vec![u32::MAX; cp.len()];
    let mut queue = VecDeque::from([0u32]);
    let mut next_node = 1u32;
    let mut next_tri = 0u32;
    while let Some(b) = queue.pop_front() {
        let root = &cp[b as usize];
        let mut kids = if is_leaf(b) { vec![b] } else { vec![root.index, root.index + 1] };
        let mut tris: u32 = kids.iter().map(|&c| leaf_tris(c)).sum();
        while kids.len() < WIDTH {
            let open = kids
                .iter()
                .enumerate()
                .filter(|&(_, &c)| {
                    let n = &cp[c as usize];
                    !is_leaf(c) && tris + leaf_tris(n.index) + leaf_tris(n.index + 1) <= TRIANGLE_WINDOW
                })
                .max_by(|a, b| area(*a.1).total_cmp(&area(*b.1)).then(b.0.cmp(&a.0)))
                .map(|(k, _)| k);
            let Some(k) = open else { break };
            let n = &cp[kids[k] as usize];
            tris += leaf_tris(n.index) + leaf_tris(n.index + 1);
            kids[k] = n.index;
            kids.push(n.index + 1);
        }
        let slots = assign_slots(cp, b, &kids).map(|c| c.map(|c| (c, is_leaf(c))));
        let mut shape = Shape { binary: b, slots, child_base: next_node, triangle_base: next_tri };
        for (c, leaf) in slots.into_iter().flatten() {
            if leaf {
                // The binary leaves beneath, one after another, in depth-first order.
                new_start[c as usize] = next_tri;
                let mut stack = vec![c];
                while let Some(i) = stack.pop() {
                    let n = &cp[i as usize];
                    if n.is_leaf() {
                        new_start[i as usize] = next_tri;
                        next_tri += n.count;
                    } else {
                        stack.extend([n.index + 1, n.index]);
                    }
                }
            } else {
                queue.push_back(c);
                next_node += 1;
            }
        }
        if next_node == shape.child_base {
            shape.child_base = 0;
        }
        shapes.push(shape);
    }
    Ok(Plan { shapes, new_start })
}

/// Slot of each child: greedily, the (child, octant) pair of least cost first, the cost being the
/// projection of the child's centre (relative to the node's) on the octant's diagonal.
fn assign_slots(cp: &[Node], parent: u32, kids: &[u32]) -> [Option<u32>; WIDTH] {
    let centre = |i: u32| {
        let n = &cp[i as usize];
        [0, 1, 2].map(|a| (f64::from(n.min[a]) + f64::from(n.max[a])) * 0.5)
    };
    let p = centre(parent);
    let mut costs = Vec::with_capacity(kids.len() * WIDTH);
    for (k, &c) in kids.iter().enumerate() {
        let q = centre(c);
        for s in 0..WIDTH {
            let dir = [0, 1, 2].map(|a| if s & (1 << a) != 0 { -1.0 } else { 1.0 });
            let cost: f64 = (0..3).map(|a| (q[a] - p[a]) * dir[a]).sum();
            costs.push((cost, k, s));
        }
    }
    costs.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let mut slots = [None; WIDTH];
    let mut placed = [false; WIDTH];
    for (_, k, s) in costs {
        if slots[s].is_none() && !placed[k] {
            slots[s] = Some(kids[k]);
            placed[k] = true;
        }
    }
    slots
}

impl Plan {
    /// Puts the triangles in the wide order: `order` (input triangle per stored triangle, in the
    /// binary leaf order) is permuted, and the leaves of the child-pair and (when given) escape
    /// layouts renumbered, so that both keep pointing at their triangles.
    pub fn reorder(&self, cp: &mut [Node], escape: Option<&mut [Node]>, order: &mut Vec<u32>) {
        let mut new_order = vec![0u32; order.len()];
        // Old first triangle of each leaf -> new one (leaves are disjoint, so starts are unique).
        let mut moved = vec![u32::MAX; order.len()];
        for (n, &start) in cp.iter_mut().zip(&self.new_start).filter(|(n, _)| n.is_leaf()) {
            let (old, count) = (n.index as usize, n.count as usize);
            new_order[start as usize..start as usize + count].copy_from_slice(&order[old..old + count]);
            moved[old] = start;
            n.index = start;
        }
        for n in escape.into_iter().flatten().filter(|n| n.is_leaf()) {
            n.index = moved[n.index as usize];
        }
        *order = new_order;
    }

    /// The wide nodes, their boxes quantised around the child-pair layout's boxes `cp` (the ones
    /// of the file, after [`crate::unit::rescale`]; leaves already renumbered by [`Plan::reorder`]).
    pub fn quantise(&self, cp: &[Node]) -> Result<Vec<WideNode>, BuildError> {
        self.shapes.iter().map(|s| quantise_node(cp, s, &self.new_start)).collect()
    }
}

/// Triangles beneath binary node `c`.
fn triangles_below(cp: &[Node], c: u32) -> u32 {
    let mut stack = vec![c];
    let mut count = 0;
    while let Some(i) = stack.pop() {
        let n = &cp[i as usize];
        if n.is_leaf() {
            count += n.count;
        } else {
            stack.extend([n.index, n.index + 1]);
        }
    }
    count
}

fn quantise_node(cp: &[Node], shape: &Shape, new_start: &[u32]) -> Result<WideNode, BuildError> {
    let frame = &cp[shape.binary as usize];
    let mut node = WideNode {
        origin: frame.min,
        child_base: shape.child_base,
        triangle_base: shape.triangle_base,
        meta: [EMPTY; WIDTH],
        ..WideNode::default()
    };
    for (s, c) in shape.slots.iter().enumerate() {
        let Some((c, leaf)) = *c else { continue };
        if leaf {
            let first = new_start[c as usize];
            node.meta[s] = WideNode::leaf_meta(first - shape.triangle_base, triangles_below(cp, c));
        } else {
            node.inner_mask |= 1 << s;
            node.meta[s] = 0;
        }
    }
    for a in 0..3 {
        let children: Vec<(usize, f32, f32)> = shape
            .slots
            .iter()
            .enumerate()
            .filter_map(|(s, c)| c.map(|(c, _)| (s, cp[c as usize].min[a], cp[c as usize].max[a])))
            .collect();
        let (e, lo, hi) = quantise_axis(frame.min[a], frame.max[a], &children)?;
        node.exponents[a] = e;
        node.lo[a] = lo;
        node.hi[a] = hi;
    }
    Ok(node)
}

/// One axis of a node: the smallest grid step `2^k` (k >= -126) for which every child's interval
/// `[cmin, cmax]` (inside `[p, top]`) gets 8-bit corners whose decoded f32 values (`p + q * step`,
/// rounded once as the traversal computes them) enclose it. Returns the biased exponent and the
/// corners per slot (zero for empty slots).
fn quantise_axis(
    p: f32,
    top: f32,
    children: &[(usize, f32, f32)],
) -> Result<(u8, [u8; WIDTH], [u8; WIDTH]), BuildError> {
    let extent = f64::from(top) - f64::from(p);
    let mut k = if extent > 0.0 { ((extent / 255.0).log2().ceil() as i32).max(-126) } else { -126 };
    'step: while k <= 127 {
        let step = f32::from_bits(((k + 127) as u32) << 23);
        let dec = |q: u8| p + f32::from(q) * step;
        let guess = |v: f32| ((f64::from(v) - f64::from(p)) / f64::from(step)).clamp(0.0, 255.0);
        let (mut lo, mut hi) = ([0u8; WIDTH], [0u8; WIDTH]);
        for &(s, cmin, cmax) in children {
            let mut l = guess(cmin).floor() as u8;
            while l > 0 && dec(l) > cmin {
                l -= 1;
            }
            while l < 255 && dec(l + 1) <= cmin {
                l += 1;
            }
            let mut h = guess(cmax).ceil() as u8;
            while h < 255 && dec(h) < cmax {
                h += 1;
            }
            while h > 0 && dec(h - 1) >= cmax {
                h -= 1;
            }
            if dec(h) < cmax || !dec(h).is_finite() {
                k += 1;
                continue 'step;
            }
            // Equal decoded values (a step below the origin's ulp) can put the last q at or below
            // cmin above the first at or above cmax; both then decode to cmin = cmax.
            lo[s] = l.min(h);
            hi[s] = h;
        }
        return Ok(((k + 127) as u8, lo, hi));
    }
    Err(BuildError::Params("a node of the scene is too large for the wide layout's 8-bit grid".to_owned()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_quantisation_encloses_every_child_and_uses_the_smallest_step() {
        // (origin, top, children's intervals)
        type Case<'a> = (f32, f32, &'a [(f32, f32)]);
        let cases: &[Case] = &[
            (0.0, 1.0, &[(0.0, 1.0), (0.3, 0.30001), (0.999, 1.0)]),
            (-3.5, 7.25, &[(-3.5, -3.4), (0.1, 0.2), (7.0, 7.25)]),
            (5.0, 5.0, &[(5.0, 5.0)]),
            (1.0e6, 1.0e6 + 0.5, &[(1.0e6, 1.0e6 + 0.125)]),
            (-1e-30, 4.0, &[(-1e-30, 1e-30), (3.9, 4.0)]),
        ];
        for &(p, top, kids) in cases {
            let children: Vec<_> = kids.iter().enumerate().map(|(s, &(a, b))| (s, a, b)).collect();
            let (e, lo, hi) = quantise_axis(p, top, &children).unwrap();
            let step = f32::from_bits(u32::from(e) << 23);
            for &(s, cmin, cmax) in &children {
                assert!(p + f32::from(lo[s]) * step <= cmin, "{p} {top}: slot {s} low");
                assert!(p + f32::from(hi[s]) * step >= cmax, "{p} {top}: slot {s} high");
                assert!(lo[s] <= hi[s]);
            }
            // Half the step would not reach the top (or the step is the smallest there is).
            assert!(e == 1 || f64::from(p) + 255.0 * f64::from(step) / 2.0 < f64::from(top), "{p} {top}: step {step}");
        }
    }
}
