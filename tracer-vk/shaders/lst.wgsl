// LST (thesis 4.3.2, code example 4.8): one ray per invocation, ordered traversal of the
// child-pair layout with a stack in private memory. Both children are tested; when both are hit
// the farther one is pushed (with its entry distance, so a pop can skip it once a nearer hit was
// found) and the nearer one entered. STACK_SIZE is the file's max depth: the deepest path pushes
// at most one node per level, so the stack cannot overflow (if it would, the frame is refused).
//
// The walk is a state (`Walk`) advanced one node at a time (`walk_step`): `trace` steps it to the
// end, and the persistent kernels (stages.wgsl) step many walks and start a new one in a lane
// whose walk ended.

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

// Visits one node; false when the walk has ended (its hit is `best`).
fn walk_step(w: ptr<function, Walk>) -> bool {
    // Each node is entered at most once; more steps than nodes would be a walk gone wrong.
    (*w).steps += 1u;
    if (*w).steps > arrayLength(&nodes) {
        fault(FAULT_WALK);
        return false;
    }
    let r = (*w).r;
    let n = nodes[(*w).current];
    if n.count > 0u {
        // The leaf test updates a local copy (naga 30's SPIR-V writer fails on a pointer into
        // the walk's record).
        var best = (*w).best;
        let ended = intersect_leaf(n, r, (*w).t_min, &best, (*w).any_hit);
        (*w).best = best;
        if ended {
            return false;
        }
    } else {
        cost_nodes += 2u;
        let tl = slab(nodes[n.index], r, (*w).best.t);
        let tr = slab(nodes[n.index + 1u], r, (*w).best.t);
        if tl >= 0.0 && tr >= 0.0 {
            let right_first = tr < tl;
            let sp = (*w).sp;
            if sp == STACK_SIZE {
                fault(FAULT_STACK);
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
    }
    // Pop the next subtree that may still hold a nearer hit.
    while (*w).sp > 0u {
        (*w).sp -= 1u;
        if may_hold((*w).stack_near[(*w).sp], (*w).best.t) {
            (*w).current = (*w).stack_node[(*w).sp];
            return true;
        }
    }
    return false;
}

fn trace(r: Ray, t_min: f32, t_max: f32, any_hit: bool, enabled: bool) -> HitRec {
    var w: Walk;
    if walk_begin(&w, r, t_min, t_max, any_hit, enabled) {
        while walk_step(&w) {}
    }
    return w.best;
}
