// Stackless traversal (Smits 1998; thesis 4.3.4, code example 4.14): walk the escape-pointer
// layout front to back. A missed inner node jumps to its escape index (the first node after its
// subtree); otherwise the walk goes on with the next node. No stack, fixed child order.
//
// The walk is a state (`Walk`) advanced one node at a time (`walk_step`) by the persistent kernels
// (stages.wgsl), which step many walks and start a new one in a lane whose walk ended. `trace`
// walks the same nodes in the same order "while-while" (Aila and Laine, HPG 2009): an inner loop
// tests boxes until the lane stands on a leaf whose box is hit, and only then tests its triangles,
// so the lanes of a subgroup testing boxes and those testing triangles do not take turns every node.

struct Walk {
    r: Ray,
    t_min: f32,
    any_hit: bool,
    best: HitRec,
    i: u32,
}

// Starts a walk; false when it ends at once (not enabled).
fn walk_begin(w: ptr<function, Walk>, r: Ray, t_min: f32, t_max: f32, any_hit: bool, enabled: bool) -> bool {
    (*w).best = HitRec(t_max, NO_TRIANGLE, 0.0, 0.0);
    (*w).r = r;
    (*w).t_min = t_min;
    (*w).any_hit = any_hit;
    (*w).i = 0u;
    return enabled && arrayLength(&nodes) > 0u;
}

// Tests the box of node n (the walk's `i`) and moves `i` on to the node after it: the next one,
// or past n's subtree where an inner node's box is missed. True when n is a leaf whose box is hit
// (its triangles are to be tested).
fn walk_box(w: ptr<function, Walk>, n: Node) -> bool {
    let i = (*w).i;
    cost_nodes += 1u;
    let hit = slab(n, (*w).r, (*w).best.t) >= 0.0;
    (*w).i = select(n.index, i + 1u, hit || n.count > 0u);
    return hit && n.count > 0u;
}

// Tests the leaf n's triangles; true when the walk ends (an any-hit walk found one).
fn walk_leaf(w: ptr<function, Walk>, n: Node) -> bool {
    // A local copy (naga 30's SPIR-V writer fails on a pointer into the walk's record).
    var best = (*w).best;
    let ended = intersect_leaf(n, (*w).r, (*w).t_min, &best, (*w).any_hit);
    (*w).best = best;
    return ended;
}

// Visits one node; false when the walk has ended (its hit is `best`).
fn walk_step(w: ptr<function, Walk>) -> bool {
    let n = nodes[(*w).i];
    if walk_box(w, n) && walk_leaf(w, n) {
        return false;
    }
    return (*w).i < arrayLength(&nodes);
}

fn trace(r: Ray, t_min: f32, t_max: f32, any_hit: bool, enabled: bool) -> HitRec {
    var w: Walk;
    if !walk_begin(&w, r, t_min, t_max, any_hit, enabled) {
        return w.best;
    }
    // Declared out of the loops, so that no iteration stores a zeroed node into it.
    var n: Node;
    loop {
        // Boxes until a leaf's is hit.
        loop {
            n = nodes[w.i];
            if walk_box(&w, n) {
                break;
            }
            if w.i >= arrayLength(&nodes) {
                return w.best;
            }
        }
        if walk_leaf(&w, n) || w.i >= arrayLength(&nodes) {
            return w.best;
        }
    }
    return w.best;
}
