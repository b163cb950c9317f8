// Stackless traversal (Smits 1998; thesis 4.3.4, code example 4.14): walk the escape-pointer
// layout front to back. A missed inner node jumps to its escape index (the first node after its
// subtree); otherwise the walk goes on with the next node. No stack, fixed child order.
//
// The walk is a state (`Walk`) advanced one node at a time (`walk_step`): `trace` steps it to the
// end, and the persistent kernels (stages.wgsl) step many walks and start a new one in a lane
// whose walk ended.

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

// Visits one node; false when the walk has ended (its hit is `best`).
fn walk_step(w: ptr<function, Walk>) -> bool {
    let i = (*w).i;
    let n = nodes[i];
    cost_nodes += 1u;
    if slab(n, (*w).r, (*w).best.t) >= 0.0 {
        if n.count > 0u {
            // The leaf test updates a local copy (naga 30's SPIR-V writer fails on a pointer
            // into the walk's record).
            var best = (*w).best;
            let ended = intersect_leaf(n, (*w).r, (*w).t_min, &best, (*w).any_hit);
            (*w).best = best;
            if ended {
                return false;
            }
        }
        (*w).i = i + 1u;
    } else {
        (*w).i = select(n.index, i + 1u, n.count > 0u);
    }
    return (*w).i < arrayLength(&nodes);
}

fn trace(r: Ray, t_min: f32, t_max: f32, any_hit: bool, enabled: bool) -> HitRec {
    var w: Walk;
    if walk_begin(&w, r, t_min, t_max, any_hit, enabled) {
        while walk_step(&w) {}
    }
    return w.best;
}
