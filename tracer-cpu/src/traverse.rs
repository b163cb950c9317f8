//! Scalar traversals: ordered child-pair traversal with a stack (the CPU analogue of LST) and the
//! stackless walk of the escape-pointer layout. Both exist in a closest-hit and an any-hit form,
//! each compiled for one [`TriangleTest`].

use crate::geometry::{Cost, Hit, Ray, TriangleTest, may_hold, slab};
use crate::vertices::TriangleSource;
use bvh_format::Node;

/// A traversal stack of (node, entry distance) pairs: a fixed array that covers every tree our
/// builder makes (depth at most 64 + log2 n), spilling to the heap for deeper trees from elsewhere.
pub struct Stack {
    inline: [(u32, f32); 128],
    len: usize,
    /// The entries past the inline array's, or [`Stack::bounded`]'s slots where the array is too
    /// short (one walk at a time borrows the stack, and each starts by clearing or sizing it).
    heap: Vec<(u32, f32)>,
}

impl Default for Stack {
    fn default() -> Self {
        Self { inline: [(0, 0.0); 128], len: 0, heap: Vec::new() }
    }
}

impl Stack {
    #[inline(always)]
    pub fn clear(&mut self) {
        self.len = 0;
        self.heap.clear();
    }
    #[inline(always)]
    pub fn push(&mut self, e: (u32, f32)) {
        if self.len < self.inline.len() {
            self.inline[self.len] = e;
        } else {
            self.heap.push(e);
        }
        self.len += 1;
    }
    /// The stack for a walk that knows it holds at most `n` entries (the wide BVH's walks):
    /// room for them is made here, so that pushing never allocates.
    #[inline]
    pub fn bounded(&mut self, n: usize) -> Bounded<'_> {
        let slots: &mut [(u32, f32)] = if n <= self.inline.len() {
            &mut self.inline
        } else {
            if self.heap.len() < n {
                self.heap.resize(n, (0, 0.0));
            }
            &mut self.heap
        };
        Bounded { slots, len: 0 }
    }
    #[inline(always)]
    pub fn pop(&mut self) -> Option<(u32, f32)> {
        if self.len == 0 {
            return None;
        }
        self.len -= 1;
        if self.len < self.inline.len() { Some(self.inline[self.len]) } else { self.heap.pop() }
    }
}

/// A traversal stack of at most as many entries as it was made with ([`Stack::bounded`]). Its
/// push makes no call but the panic of an overflow, which a correct bound never reaches (and
/// which, never returning, leaves the caller's registers alone): a call that returns, even one
/// never made, clobbers every vector register, and the wide walk, which pushed onto a growable
/// stack, reloaded its ray from memory at every node for it (docs/cpu-benchmark-log.md, stop 42).
pub struct Bounded<'a> {
    slots: &'a mut [(u32, f32)],
    len: usize,
}

impl Bounded<'_> {
    #[inline(always)]
    pub fn push(&mut self, e: (u32, f32)) {
        self.slots[self.len] = e;
        self.len += 1;
    }
    #[inline(always)]
    pub fn pop(&mut self) -> Option<(u32, f32)> {
        self.len = self.len.checked_sub(1)?;
        Some(self.slots[self.len])
    }
}

/// Tests the leaf's triangles; returns true when `ANY` and something was hit.
#[inline(always)]
fn leaf<const ANY: bool, T: TriangleTest>(
    tris: &(impl TriangleSource + ?Sized),
    node: &Node,
    ray: &Ray,
    t_min: f32,
    best: &mut Hit,
    cost: &mut Cost,
) -> bool {
    for i in node.index..node.index + node.count {
        cost.tris += 1;
        if let Some((t, u, v)) = T::intersect(&tris.triangle(i), ray, t_min, best.t)
            && Hit::beats(t, i, best.t, best.tri)
        {
            *best = Hit { t, tri: i, u, v };
            if ANY {
                return true;
            }
        }
    }
    false
}

fn no_hit(t_max: f32) -> Hit {
    Hit { t: t_max, tri: u32::MAX, u: 0.0, v: 0.0 }
}

/// Ordered traversal of the child-pair layout: both children are tested, the nearer is entered
/// and the farther pushed with its entry distance, so that a pop can skip it once a nearer hit
/// was found.
pub fn child_pair<const ANY: bool, T: TriangleTest>(
    nodes: &[Node],
    tris: &(impl TriangleSource + ?Sized),
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    stack: &mut Stack,
    cost: &mut Cost,
) -> Option<Hit> {
    let mut best = no_hit(t_max);
    stack.clear();
    cost.nodes += 1;
    slab(&nodes[0], ray, best.t)?;
    let mut current = 0u32;
    loop {
        let node = &nodes[current as usize];
        if node.is_leaf() {
            if leaf::<ANY, T>(tris, node, ray, t_min, &mut best, cost) {
                return Some(best);
            }
        } else {
            let (l, r) = (node.index, node.index + 1);
            cost.nodes += 2;
            let tl = slab(&nodes[l as usize], ray, best.t);
            let tr = slab(&nodes[r as usize], ray, best.t);
            match (tl, tr) {
                (Some(a), Some(b)) => {
                    let (near, far, tfar) = if b < a { (r, l, a) } else { (l, r, b) };
                    stack.push((far, tfar));
                    current = near;
                    continue;
                }
                (Some(_), None) => {
                    current = l;
                    continue;
                }
                (None, Some(_)) => {
                    current = r;
                    continue;
                }
                (None, None) => {}
            }
        }
        loop {
            match stack.pop() {
                None => return (best.tri != u32::MAX).then_some(best),
                Some((n, t)) if may_hold(t, best.t) => {
                    current = n;
                    break;
                }
                Some(_) => {}
            }
        }
    }
}

/// Stackless traversal of the escape-pointer layout (Smits 1998; thesis 4.3.4): walk the array
/// front to back, jumping to the escape index past every inner node whose box is missed.
pub fn escape<const ANY: bool, T: TriangleTest>(
    nodes: &[Node],
    tris: &(impl TriangleSource + ?Sized),
    ray: &Ray,
    t_min: f32,
    t_max: f32,
    cost: &mut Cost,
) -> Option<Hit> {
    let mut best = no_hit(t_max);
    let mut i = 0usize;
    while i < nodes.len() {
        let node = &nodes[i];
        cost.nodes += 1;
        if slab(node, ray, best.t).is_some() {
            if node.is_leaf() && leaf::<ANY, T>(tris, node, ray, t_min, &mut best, cost) {
                return Some(best);
            }
            i += 1;
        } else {
            i = if node.is_leaf() { i + 1 } else { node.index as usize };
        }
    }
    (best.tri != u32::MAX).then_some(best)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::Watertight;
    use bvh_format::Triangle;
    use glam::Vec3;

    /// `n` triangles facing +x at x = 0..n, in a tree that is a chain: every inner node holds one
    /// triangle's leaf (left) and the rest of the row (right), so a ray down the row from +x
    /// enters the rest first and pushes every leaf it passes: `n - 1` entries, past the inline
    /// array's 128. Each triangle is half of the unit square of its box; a ray through the upper
    /// half (y + z > 1) misses all but triangle 0, the last entry popped.
    fn chain(n: u32) -> (Vec<Node>, Vec<Triangle>) {
        let tris: Vec<Triangle> = (0..n)
            .map(|i| {
                let x = i as f32;
                match i {
                    0 => Triangle::from_vertices([x, 1.0, 1.0], [x, 1.0, 0.0], [x, 0.0, 1.0]),
                    _ => Triangle::from_vertices([x, 0.0, 0.0], [x, 1.0, 0.0], [x, 0.0, 1.0]),
                }
            })
            .collect();
        let boxed = |lo: u32, hi: u32| ([lo as f32, 0.0, 0.0], [(hi - 1) as f32, 1.0, 1.0]);
        let mut nodes = Vec::new();
        for i in 0..n {
            let (min, max) = boxed(i, n);
            if i + 1 == n {
                nodes.push(Node { min, max, count: 1, index: i });
            } else {
                nodes.push(Node { min, max, count: 0, index: nodes.len() as u32 + 1 });
                let (min, max) = boxed(i, i + 1);
                nodes.push(Node { min, max, count: 1, index: i });
            }
        }
        (nodes, tris)
    }

    #[test]
    fn a_stack_deeper_than_its_inline_array_spills_and_serves_a_bounded_walk_after() {
        let n = 300;
        let (nodes, tris) = chain(n);
        let ray = Ray::new(Vec3::new(n as f32 + 4.0, 0.75, 0.75), Vec3::NEG_X);
        let mut stack = Stack::default();
        for round in 0..2 {
            let mut cost = Cost::default();
            let hit = child_pair::<false, Watertight>(&nodes, &tris, &ray, 0.0, f32::INFINITY, &mut stack, &mut cost)
                .expect("the ray runs down the row to triangle 0");
            assert_eq!((hit.tri, hit.t), (0, n as f32 + 4.0), "round {round}");
            // Down the whole chain, then every leaf popped back and tested once.
            assert_eq!((cost.nodes, cost.tris), (1 + 2 * (n - 1), n), "round {round}");
            let any = child_pair::<true, Watertight>(&nodes, &tris, &ray, 0.0, f32::INFINITY, &mut stack, &mut cost);
            assert!(any.is_some());
            // The same stack as a bounded one longer than its array, between the two rounds.
            let mut bounded = stack.bounded(n as usize);
            for i in 0..n {
                bounded.push((i, i as f32));
            }
            for i in (0..n).rev() {
                assert_eq!(bounded.pop(), Some((i, i as f32)));
            }
            assert_eq!(bounded.pop(), None);
        }
    }
}
