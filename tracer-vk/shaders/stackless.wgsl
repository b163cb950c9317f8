// Stackless traversal (Smits 1998; thesis 4.3.4, code example 4.14): walk the escape-pointer
// layout front to back. A missed inner node jumps to its escape index (the first node after its
// subtree); otherwise the walk goes on with the next node. No stack, fixed child order.

fn trace(r: Ray, t_min: f32, t_max: f32, any_hit: bool, enabled: bool) -> HitRec {
    var best = HitRec(t_max, NO_TRIANGLE, 0.0, 0.0);
    if !enabled {
        return best;
    }
    let count = arrayLength(&nodes);
    var i = 0u;
    while i < count {
        let n = nodes[i];
        cost_nodes += 1u;
        if slab(n, r, best.t) >= 0.0 {
            if n.count > 0u && intersect_leaf(n, r, t_min, &best, any_hit) {
                return best;
            }
            i += 1u;
        } else {
            i = select(n.index, i + 1u, n.count > 0u);
        }
    }
    return best;
}
