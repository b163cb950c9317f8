// LST (thesis 4.3.2, code example 4.8): one ray per invocation, ordered traversal of the
// child-pair layout with a stack in private memory. Both children are tested; when both are hit
// the farther one is pushed (with its entry distance, so a pop can skip it once a nearer hit was
// found) and the nearer one entered. STACK_SIZE is the file's max depth: the deepest path pushes
// at most one node per level, so the stack cannot overflow (if it would, the frame is refused).
//
// The walk is a state (`Walk`) advanced one node at a time (`walk_step`) by the persistent kernels
// (stages.wgsl), which step many walks and start a new one in a lane whose walk ended. `trace`
// walks the same nodes in the same order "while-while" (Aila and Laine, HPG 2009): an inner loop
// descends (and pops) through inner nodes until the lane stands on a leaf, and only then tests it,
// so the lanes of a subgroup that are at inner nodes and those at leaves do not take turns every
// node as they would stepping one node at a time. That `trace` walks in order (IN_ORDER, the
// default); SPECULATIVE's, below, lets a lane walk on past a leaf while others in its subgroup
// still look for one.

struct Walk {
    r: Ray,
    t_min: f32,
    any_hit: bool,
    best: HitRec,
    stack_node: array<u32, STACK_SIZE>,
    stack_near: array<f32, STACK_SIZE>,
    sp: u32,
    current: u32,
    steps: u32,
}

// Starts a walk; false when it ends at once (not enabled, or the root is missed).
fn walk_begin(w: ptr<function, Walk>, r: Ray, t_min: f32, t_max: f32, any_hit: bool, enabled: bool) -> bool {
    (*w).best = HitRec(t_max, NO_TRIANGLE, 0.0, 0.0);
    if !enabled {
        return false;
    }
    (*w).r = r;
    (*w).t_min = t_min;
    (*w).any_hit = any_hit;
    (*w).sp = 0u;
    (*w).current = 0u;
    (*w).steps = 0u;
    cost_nodes += 1u;
    return slab(nodes[0], r, t_max) >= 0.0;
}

// The node the walk enters next; false (and a fault) when the walk has entered more nodes than
// the tree has: each node is entered at most once, so that would be a walk gone wrong.
fn walk_enter(w: ptr<function, Walk>) -> bool {
    (*w).steps += 1u;
    if (*w).steps > arrayLength(&nodes) {
        fault(FAULT_WALK);
        return false;
    }
    return true;
}

// Tests the children of the inner node n; true when the walk descends into one (`current`), false
// when both are missed (or the stack is full: a fault, and the stack is emptied so the walk ends).
fn walk_inner(w: ptr<function, Walk>, n: Node) -> bool {
    cost_nodes += 2u;
    let tl = slab(nodes[n.index], (*w).r, (*w).best.t);
    let tr = slab(nodes[n.index + 1u], (*w).r, (*w).best.t);
    if tl >= 0.0 && tr >= 0.0 {
        let right_first = tr < tl;
        let sp = (*w).sp;
        if sp == STACK_SIZE {
            fault(FAULT_STACK);
            (*w).sp = 0u;
            return false;
        }
        (*w).stack_node[sp] = select(n.index + 1u, n.index, right_first);
        (*w).stack_near[sp] = select(tr, tl, right_first);
        (*w).sp = sp + 1u;
        (*w).current = select(n.index, n.index + 1u, right_first);
        return true;
    }
    if tl >= 0.0 {
        (*w).current = n.index;
        return true;
    }
    if tr >= 0.0 {
        (*w).current = n.index + 1u;
        return true;
    }
    return false;
}

// Tests the leaf n's triangles; true when the walk ends (an any-hit walk found one).
fn walk_leaf(w: ptr<function, Walk>, n: Node) -> bool {
    // A local copy (naga 30's SPIR-V writer fails on a pointer into the walk's record).
    var best = (*w).best;
    let ended = intersect_leaf(n, (*w).r, (*w).t_min, &best, (*w).any_hit);
    (*w).best = best;
    return ended;
}

// Pops the next subtree that may still hold a nearer hit into `current`; false when none is left.
fn walk_pop(w: ptr<function, Walk>) -> bool {
    while (*w).sp > 0u {
        (*w).sp -= 1u;
        if may_hold((*w).stack_near[(*w).sp], (*w).best.t) {
            (*w).current = (*w).stack_node[(*w).sp];
            return true;
        }
    }
    return false;
}

// Visits one node; false when the walk has ended (its hit is `best`).
fn walk_step(w: ptr<function, Walk>) -> bool {
    if !walk_enter(w) {
        return false;
    }
    let n = nodes[(*w).current];
    if n.count > 0u {
        if walk_leaf(w, n) {
            return false;
        }
    } else if walk_inner(w, n) {
        return true;
    }
    return walk_pop(w);
}

//#if IN_ORDER
fn trace(r: Ray, t_min: f32, t_max: f32, any_hit: bool, enabled: bool) -> HitRec {
    var w: Walk;
    if !walk_begin(&w, r, t_min, t_max, any_hit, enabled) {
        return w.best;
    }
    // Declared out of the loops, so that no iteration stores a zeroed node into it.
    var n: Node;
    loop {
        // Inner nodes until the walk stands on a leaf (best.t cannot change meanwhile, so popping
        // here skips exactly the subtrees walk_step's pops would).
        loop {
            if !walk_enter(&w) {
                return w.best;
            }
            n = nodes[w.current];
            if n.count > 0u {
                break;
            }
            if !walk_inner(&w, n) && !walk_pop(&w) {
                return w.best;
            }
        }
        if walk_leaf(&w, n) || !walk_pop(&w) {
            return w.best;
        }
    }
    return w.best;
}
//#endif

//#if SPECULATIVE
// Speculative while-while (Aila and Laine 2009, "speculative traversal";
// `Renderer::set_speculative`, off by default): a lane that reaches a leaf postpones its test and
// walks on through inner nodes (popping with the distance bound before that test) until it stands
// on a second leaf, its walk runs out, or every active lane of the subgroup holds a leaf; then the
// lanes test their leaves together. Leaves are still tested in the walk's order, each at most
// once, but the walk past a postponed leaf does not know that leaf's hits, so it may enter
// subtrees (and test leaves) that the in-order walk skips: per ray, the nodes and triangles tested
// are at least the in-order walk's, and the closest hit is the same. An any-hit ray tests the
// same triangles (its bound does not change before the hit that ends it) and at most a few more
// nodes.
fn trace(r: Ray, t_min: f32, t_max: f32, any_hit: bool, enabled: bool) -> HitRec {
    var w: Walk;
    if !walk_begin(&w, r, t_min, t_max, any_hit, enabled) {
        return w.best;
    }
    // `going`: the walk has a node to enter (`current`); `at`: `n` is that node, entered already
    // (a second leaf found while one was postponed: the next leaf to test).
    var going = true;
    var at = false;
    var n: Node;
    // The postponed leaf, where `postponed`.
    var leaf: Node;
    loop {
        var postponed = false;
        loop {
            if subgroupAll(postponed) {
                break;
            }
            if !at {
                if !going {
                    break;
                }
                if !walk_enter(&w) {
                    return w.best;
                }
                n = nodes[w.current];
            }
            at = false;
            if n.count > 0u {
                if postponed {
                    at = true;
                    break;
                }
                leaf = n;
                postponed = true;
                going = walk_pop(&w);
            } else {
                going = walk_inner(&w, n) || walk_pop(&w);
            }
        }
        if postponed && walk_leaf(&w, leaf) {
            return w.best;
        }
        if !going && !at {
            return w.best;
        }
    }
    return w.best;
}
//#endif
