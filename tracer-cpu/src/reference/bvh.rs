//! The f64 traversal: the hits of brute force ([`super::closest_hit`]), found through the file's
//! tree so that a whole image of a million triangles takes minutes, not days.
//!
//! The boxes are the file's, widened exactly from f32, so they bound the widened triangles just as
//! they bound the stored ones. The slab test rounds in f64, as does the triangle test's distance,
//! so a triangle touching its box's boundary can come out a little nearer than the box; every
//! comparison of a box's distance with a hit's therefore has a relative slack ([`SLACK`]). A
//! slack only makes the walk visit more boxes, never skip a hit, and the tie rule is brute
//! force's (nearest, then lowest stored index), so the walk returns exactly brute force's
//! triangle, distance and barycentrics (tested in `tests/reference.rs` on rays aimed at vertices
//! and edges).

use super::brute::{RefHit, intersect64};
use crate::geometry::Cost;
use bvh_format::{Node, SceneFile, Triangle};
use glam::DVec3;
use render_spec::RenderError;

/// Relative slack of every box-against-hit comparison: the f32 paths' [`T_SLACK`], 2^-20. The
/// rounding it covers is a few f64 units in the last place (2^-52) of the distance, or more for a
/// ray grazing a triangle's plane, whose distance rounds worse; the wide margin costs almost
/// nothing, since a box entered that close behind the best hit is rare.
///
/// [`T_SLACK`]: render_spec::constants::T_SLACK
pub const SLACK: f64 = render_spec::constants::T_SLACK as f64;

/// A ray in f64 with its inverse direction (components may be infinite).
#[derive(Clone, Copy, Debug)]
pub struct Ray64 {
    pub origin: DVec3,
    pub dir: DVec3,
    pub inv_dir: DVec3,
}

impl Ray64 {
    pub fn new(origin: DVec3, dir: DVec3) -> Self {
        Self { origin, dir, inv_dir: dir.recip() }
    }
}

/// Whether a box entered at `near` may still hold a hit at `t` or nearer.
#[inline(always)]
fn may_hold(near: f64, t: f64) -> bool {
    near <= t + t.abs() * SLACK
}

/// Entry distance of the ray into the node's box if it enters within `[0, t_max]` (with
/// [`SLACK`]). An axis where `(bound - origin) / d` is NaN (the origin in the face's plane, the
/// direction parallel to it) is left out, as in the f32 slab test: the ray lies in the face.
#[inline(always)]
fn slab(node: &Node, ray: &Ray64, t_max: f64) -> Option<f64> {
    let lo = (DVec3::from(node.min.map(f64::from)) - ray.origin) * ray.inv_dir;
    let hi = (DVec3::from(node.max.map(f64::from)) - ray.origin) * ray.inv_dir;
    let mut near = 0.0f64;
    let mut far = t_max;
    for a in 0..3 {
        let (t0, t1) = (lo[a], hi[a]);
        if t0.is_nan() || t1.is_nan() {
            continue;
        }
        near = near.max(t0.min(t1));
        far = far.min(t0.max(t1));
    }
    may_hold(near, far).then_some(near)
}

/// The tree the walk reads: the child-pair layout (ordered, with a stack) where the file has it,
/// else the escape-pointer layout (stackless). Both find the same hits.
#[derive(Clone, Copy, Debug)]
enum Layout<'a> {
    ChildPair(&'a [Node]),
    Escape(&'a [Node]),
}

/// The scene prepared for f64 traversal: its tree and its triangles in leaf order.
pub struct Bvh<'a> {
    pub scene: &'a SceneFile,
    tris: Vec<Triangle>,
    layout: Layout<'a>,
}

/// A traversal stack of (node, entry distance), kept by the caller to reuse its memory.
pub type Stack = Vec<(u32, f64)>;

impl<'a> Bvh<'a> {
    /// Prepares `scene`; an error when the file holds no tree (a reader-validated file always
    /// holds one).
    pub fn new(scene: &'a SceneFile) -> Result<Self, RenderError> {
        let layout = match (&scene.child_pair, &scene.escape) {
            (Some(n), _) => Layout::ChildPair(n),
            (None, Some(n)) => Layout::Escape(n),
            (None, None) => return Err(RenderError::MissingLayout { method: "reference", layout: "child-pair" }),
        };
        Ok(Self { scene, tris: scene.leaf_triangles(), layout })
    }

    /// Prepares `scene` to walk its escape-pointer layout even where it also has the child-pair
    /// one (for tests of both walks); `None` without that layout.
    pub fn escape_only(scene: &'a SceneFile) -> Option<Self> {
        let nodes = scene.escape.as_deref()?;
        Some(Self { scene, tris: scene.leaf_triangles(), layout: Layout::Escape(nodes) })
    }

    /// The triangles as the walk intersects them, in leaf order (the file's stored order).
    pub fn triangles(&self) -> &[Triangle] {
        &self.tris
    }

    /// The closest hit beyond `t_min` (brute force's [`super::closest_hit`], exactly); adds the
    /// work done to `cost`.
    pub fn closest(&self, ray: &Ray64, t_min: f64, stack: &mut Stack, cost: &mut Cost) -> Option<RefHit> {
        self.walk::<false>(ray, t_min, f64::INFINITY, stack, cost)
    }

    /// Whether anything lies in `(t_min, t_max]` along the ray.
    pub fn occluded(&self, ray: &Ray64, t_min: f64, t_max: f64, stack: &mut Stack, cost: &mut Cost) -> bool {
        self.walk::<true>(ray, t_min, t_max, stack, cost).is_some()
    }

    fn walk<const ANY: bool>(
        &self,
        ray: &Ray64,
        t_min: f64,
        t_max: f64,
        stack: &mut Stack,
        cost: &mut Cost,
    ) -> Option<RefHit> {
        let mut best = Best { hit: None, t: t_max };
        match self.layout {
            Layout::ChildPair(nodes) => self.child_pair::<ANY>(nodes, ray, t_min, &mut best, stack, cost),
            Layout::Escape(nodes) => self.escape::<ANY>(nodes, ray, t_min, &mut best, cost),
        }
        best.hit
    }

    /// Tests a leaf's triangles; true when `ANY` and something was hit.
    #[inline(always)]
    fn leaf<const ANY: bool>(&self, node: &Node, ray: &Ray64, t_min: f64, best: &mut Best, cost: &mut Cost) -> bool {
        for i in node.index..node.index + node.count {
            cost.tris += 1;
            if let Some((t, u, v)) = intersect64(&self.tris[i as usize], ray.origin, ray.dir, t_min)
                && best.takes(t, i)
            {
                best.hit = Some(RefHit { t, tri: i, u, v });
                best.t = t;
                if ANY {
                    return true;
                }
            }
        }
        false
    }

    /// Ordered walk of the child-pair layout: both children are tested and pushed, the farther
    /// first, so the nearer is taken next; a popped box entered beyond the best hit is skipped.
    fn child_pair<const ANY: bool>(
        &self,
        nodes: &[Node],
        ray: &Ray64,
        t_min: f64,
        best: &mut Best,
        stack: &mut Stack,
        cost: &mut Cost,
    ) {
        stack.clear();
        cost.nodes += 1;
        stack.extend(slab(&nodes[0], ray, best.t).map(|near| (0, near)));
        while let Some((n, near)) = stack.pop() {
            if !may_hold(near, best.t) {
                continue;
            }
            let node = &nodes[n as usize];
            if node.is_leaf() {
                if self.leaf::<ANY>(node, ray, t_min, best, cost) {
                    return;
                }
                continue;
            }
            cost.nodes += 2;
            let children = [node.index, node.index + 1].map(|c| slab(&nodes[c as usize], ray, best.t).map(|t| (c, t)));
            let [a, b] = match children {
                [Some(l), Some(r)] if r.1 < l.1 => [Some(l), Some(r)],
                [l, r] => [r, l],
            };
            stack.extend(a);
            stack.extend(b);
        }
    }

    fn escape<const ANY: bool>(&self, nodes: &[Node], ray: &Ray64, t_min: f64, best: &mut Best, cost: &mut Cost) {
        let mut i = 0usize;
        while i < nodes.len() {
            let node = &nodes[i];
            cost.nodes += 1;
            if slab(node, ray, best.t).is_some() {
                if node.is_leaf() && self.leaf::<ANY>(node, ray, t_min, best, cost) {
                    return;
                }
                i += 1;
            } else {
                i = if node.is_leaf() { i + 1 } else { node.index as usize };
            }
        }
    }
}

/// The best hit so far and the distance boxes are compared with (the hit's, else the ray's end).
struct Best {
    hit: Option<RefHit>,
    t: f64,
}

impl Best {
    /// Brute force's rule: a hit within the ray's end that is nearer, or as near with a lower
    /// stored index.
    #[inline(always)]
    fn takes(&self, t: f64, tri: u32) -> bool {
        match self.hit {
            None => t <= self.t,
            Some(b) => t < b.t || (t == b.t && tri < b.tri),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn slab_skips_nan_axes_and_keeps_flat_boxes() {
        let node = Node { min: [0.0, 0.0, 0.0], count: 1, max: [1.0, 1.0, 1.0], index: 0 };
        let ray = |o: [f64; 3], d: [f64; 3]| Ray64::new(DVec3::from(o), DVec3::from(d));
        assert_eq!(slab(&node, &ray([0.5, 0.5, -1.0], [0.0, 0.0, 1.0]), f64::INFINITY), Some(1.0));
        assert_eq!(slab(&node, &ray([2.0, 0.5, -1.0], [0.0, 0.0, 1.0]), f64::INFINITY), None);
        // Origin in a face's plane, parallel to it: inside, for either sign of zero.
        assert_eq!(slab(&node, &ray([0.0, 0.5, -1.0], [0.0, 0.0, 1.0]), f64::INFINITY), Some(1.0));
        assert_eq!(slab(&node, &ray([1.0, 1.0, 0.5], [-0.0, -0.0, 1.0]), f64::INFINITY), Some(0.0));
        assert_eq!(slab(&node, &ray([0.5, 0.5, -1.0], [0.0, 0.0, 1.0]), 0.5), None, "beyond t_max");
        let flat = Node { min: [0.0, 0.0, 0.0], count: 1, max: [1.0, 0.0, 1.0], index: 0 };
        assert!(slab(&flat, &ray([0.5, 1.0, 0.5], [0.0, -1.0, 0.0]), f64::INFINITY).is_some());
        // The slack: a box entered a hair behind the best hit is still entered.
        assert!(slab(&node, &ray([0.5, 0.5, -1.0], [0.0, 0.0, 1.0]), 1.0 - 1e-9).is_some());
        assert!(slab(&node, &ray([0.5, 0.5, -1.0], [0.0, 0.0, 1.0]), 1.0 - 1e-5).is_none());
    }
}
