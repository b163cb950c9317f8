//! Two other Rust BVH builders, for the build benchmark (`--features compare`): the `bvh` crate
//! (top-down binned SAH, one triangle per leaf) and obvhs (PLOC, then reinsertion and leaf
//! collapse). Each peer is built from triangles in its own input type (prepared outside the timed
//! part, as ours start from `[[Vec3; 3]]`), and its tree is converted afterwards into our
//! child-pair layout plus a leaf order, so that [`bvh_format::tree::stats`] measures every tree's
//! SAH cost with the same code and constants.

use bvh::aabb::{Aabb as BvhAabb, Bounded};
use bvh::bounding_hierarchy::{BHShape, BoundingHierarchy};
use bvh::bvh::{Bvh, BvhNode};
use bvh_format::Node;
use glam::Vec3;
use nalgebra::Point3;
use obvhs::bvh2::Bvh2;
use std::time::Duration;

/// A peer's tree in our layout: child-pair nodes, and for each leaf-order slot the input triangle.
pub struct PeerTree {
    pub nodes: Vec<Node>,
    pub order: Vec<u32>,
}

/// A triangle as the `bvh` crate sees it. It asks every shape for its box repeatedly during the
/// build, so the box is computed from the vertices each time, as a user of the crate would.
pub struct BvhTriangle {
    pub vertices: [Point3<f32>; 3],
    node_index: usize,
}

impl Bounded<f32, 3> for BvhTriangle {
    fn aabb(&self) -> BvhAabb<f32, 3> {
        let [a, b, c] = &self.vertices;
        BvhAabb::with_bounds(a.inf(b).inf(c), a.sup(b).sup(c))
    }
}

impl BHShape<f32, 3> for BvhTriangle {
    fn set_bh_node_index(&mut self, index: usize) {
        self.node_index = index;
    }

    fn bh_node_index(&self) -> usize {
        self.node_index
    }
}

/// The `bvh` crate's input, one shape per triangle in input order.
pub fn bvh_input(triangles: &[[Vec3; 3]]) -> Vec<BvhTriangle> {
    let p = |v: Vec3| Point3::new(v.x, v.y, v.z);
    triangles.iter().map(|t| BvhTriangle { vertices: [p(t[0]), p(t[1]), p(t[2])], node_index: 0 }).collect()
}

/// The `bvh` crate's parallel (rayon) build. Only writes each shape's node index.
pub fn build_bvh(shapes: &mut [BvhTriangle]) -> Bvh<f32, 3> {
    Bvh::build_par(shapes)
}

fn from_bvh_aabb(b: &BvhAabb<f32, 3>) -> ([f32; 3], [f32; 3]) {
    ([b.min.x, b.min.y, b.min.z], [b.max.x, b.max.y, b.max.z])
}

/// Converts a `bvh` crate tree. Its inner nodes hold their children's boxes rather than their
/// own, so each box is handed down from the parent; the root's is the union of its children's.
pub fn bvh_to_tree(bvh: &Bvh<f32, 3>, shapes: &[BvhTriangle]) -> PeerTree {
    assert!(!bvh.nodes.is_empty(), "the benchmark never builds over an empty scene");
    let root_box = match &bvh.nodes[0] {
        BvhNode::Leaf { shape_index, .. } => from_bvh_aabb(&shapes[*shape_index].aabb()),
        BvhNode::Node { child_l_aabb, child_r_aabb, .. } => from_bvh_aabb(&child_l_aabb.join(child_r_aabb)),
    };
    let mut nodes = vec![Node::default()];
    let mut order = Vec::with_capacity(shapes.len());
    // (bvh crate node, our node, its box), left child popped first so leaves come out in order.
    let mut stack = vec![(0usize, 0usize, root_box)];
    while let Some((src, dst, (min, max))) = stack.pop() {
        let (count, index) = match &bvh.nodes[src] {
            BvhNode::Leaf { shape_index, .. } => {
                order.push(*shape_index as u32);
                (1, order.len() as u32 - 1)
            }
            BvhNode::Node { child_l_index, child_l_aabb, child_r_index, child_r_aabb, .. } => {
                let pair = nodes.len();
                nodes.extend([Node::default(); 2]);
                stack.push((*child_r_index, pair + 1, from_bvh_aabb(child_r_aabb)));
                stack.push((*child_l_index, pair, from_bvh_aabb(child_l_aabb)));
                (0, pair as u32)
            }
        };
        nodes[dst] = Node { min, count, max, index };
    }
    PeerTree { nodes, order }
}

/// obvhs's input: its own triangle type, in its glam version.
pub fn obvhs_input(triangles: &[[Vec3; 3]]) -> Vec<obvhs::triangle::Triangle> {
    let v = |v: Vec3| obvhs_glam::Vec3A::new(v.x, v.y, v.z);
    triangles.iter().map(|t| obvhs::triangle::Triangle { v0: v(t[0]), v1: v(t[1]), v2: v(t[2]) }).collect()
}

/// obvhs's build parameters: its `medium_build` preset (PLOC with search distance 6, reinsertion,
/// leaf collapse to at most 8 triangles, a second reinsertion pass; no pre-splitting, which would
/// reference triangles more than once), with the collapse deciding by our traversal-to-intersection
/// cost ratio instead of its default 3, so that it optimises the cost it is measured by.
pub fn obvhs_params(traversal_cost: f32, intersection_cost: f32) -> obvhs::BvhBuildParams {
    obvhs::BvhBuildParams {
        collapse_traversal_cost: traversal_cost / intersection_cost,
        ..obvhs::BvhBuildParams::medium_build()
    }
}

/// obvhs's build from triangles (boxes included), parallel with its `parallel` feature.
pub fn build_obvhs(triangles: &[obvhs::triangle::Triangle], params: obvhs::BvhBuildParams) -> Bvh2 {
    let mut core_time = Duration::ZERO;
    obvhs::bvh2::builder::build_bvh2_from_tris(triangles, params, &mut core_time)
}

/// Converts an obvhs tree. Its node 0 is the root, an inner node's children are adjacent at
/// `first_index`, and a leaf's triangles are `primitive_indices[first_index..][..prim_count]`,
/// which is the same shape as ours up to the leaf order.
pub fn obvhs_to_tree(bvh: &Bvh2) -> PeerTree {
    assert!(!bvh.nodes.is_empty(), "the benchmark never builds over an empty scene");
    let mut nodes = vec![Node::default()];
    let mut order = Vec::with_capacity(bvh.primitive_indices.len());
    let mut stack = vec![(0usize, 0usize)];
    while let Some((src, dst)) = stack.pop() {
        let n = &bvh.nodes[src];
        let (count, index) = if n.is_leaf() {
            let first = n.first_index as usize;
            let start = order.len() as u32;
            order.extend_from_slice(&bvh.primitive_indices[first..first + n.prim_count as usize]);
            (n.prim_count, start)
        } else {
            let pair = nodes.len();
            nodes.extend([Node::default(); 2]);
            let child = n.first_index as usize;
            stack.push((child + 1, pair + 1));
            stack.push((child, pair));
            (0, pair as u32)
        };
        nodes[dst] = Node { min: n.aabb().min.to_array(), count, max: n.aabb().max.to_array(), index };
    }
    PeerTree { nodes, order }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bvh_format::tree::{Tree, check_shape, stats};

    /// Small triangles scattered on a sphere-ish shell plus a few large ones, deterministic.
    fn triangles(n: usize) -> Vec<[Vec3; 3]> {
        let mut rng = ::tests::Rng(0x9e37_79b9);
        let mut r = move || rng.unit();
        (0..n)
            .map(|i| {
                let c = Vec3::new(r(), r(), r()) * 2.0 - 1.0;
                let size = if i % 97 == 0 { 0.5 } else { 0.02 };
                let e1 = Vec3::new(r(), r(), r()) * size;
                let e2 = Vec3::new(r(), r(), r()) * size;
                [c, c + e1, c + e2]
            })
            .collect()
    }

    /// Shape check, the leaf order a permutation, each leaf's box holding its triangles.
    fn check(tree: &PeerTree, tris: &[[Vec3; 3]]) {
        check_shape(Tree::child_pair(&tree.nodes), tris.len() as u32).unwrap();
        let mut seen = vec![false; tris.len()];
        for &t in &tree.order {
            assert!(!std::mem::replace(&mut seen[t as usize], true), "triangle {t} twice");
        }
        assert!(seen.iter().all(|&s| s));
        for n in tree.nodes.iter().filter(|n| n.is_leaf()) {
            for &t in &tree.order[n.index as usize..(n.index + n.count) as usize] {
                for v in tris[t as usize] {
                    for k in 0..3 {
                        assert!(n.min[k] <= v[k] && v[k] <= n.max[k], "triangle {t} outside its leaf");
                    }
                }
            }
        }
        let s = stats(Tree::child_pair(&tree.nodes), 1.0, 1.0);
        assert!(s.sah_cost.is_finite() && s.sah_cost >= 1.0, "SAH cost {}", s.sah_cost);
    }

    #[test]
    fn bvh_crate_trees_convert_to_valid_trees() {
        for n in [1, 2, 3, 100, 5000] {
            let tris = triangles(n);
            let mut shapes = bvh_input(&tris);
            let bvh = build_bvh(&mut shapes);
            let tree = bvh_to_tree(&bvh, &shapes);
            check(&tree, &tris);
            assert!(tree.nodes.iter().filter(|n| n.is_leaf()).all(|n| n.count == 1));
        }
    }

    #[test]
    fn obvhs_trees_convert_to_valid_trees() {
        for n in [1, 2, 3, 100, 5000] {
            let tris = triangles(n);
            let bvh = build_obvhs(&obvhs_input(&tris), obvhs_params(1.0, 1.0));
            let tree = obvhs_to_tree(&bvh);
            check(&tree, &tris);
            assert!(tree.nodes.iter().all(|n| n.count <= 8));
        }
    }
}
