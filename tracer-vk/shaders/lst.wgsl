// LST (thesis 4.3.2, code example 4.8): one ray per invocation, ordered traversal of the
// child-pair layout with a stack in private memory. Both children are tested; when both are hit
// the farther one is pushed (with its entry distance, so a pop can skip it once a nearer hit was
// found) and the nearer one entered. STACK_SIZE is the file's max depth: the deepest path pushes
// at most one node per level, so the stack cannot overflow (if it would, the frame is refused).

fn trace(r: Ray, t_min: f32, t_max: f32, any_hit: bool, enabled: bool) -> HitRec {
    var best = HitRec(t_max, NO_TRIANGLE, 0.0, 0.0);
    if !enabled {
        return best;
    }
    var stack_node: array<u32, STACK_SIZE>;
    var stack_near: array<f32, STACK_SIZE>;
    var sp = 0u;
    cost_nodes += 1u;
    if slab(nodes[0], r, best.t) < 0.0 {
        return best;
    }
    var current = 0u;
    // Each node is entered at most once; more steps than nodes would be a walk gone wrong.
    let node_count = arrayLength(&nodes);
    var steps = 0u;
    loop {
        steps += 1u;
        if steps > node_count {
            fault(FAULT_WALK);
            return best;
        }
        let n = nodes[current];
        if n.count > 0u {
            if intersect_leaf(n, r, t_min, &best, any_hit) {
                return best;
            }
        } else {
            cost_nodes += 2u;
            let tl = slab(nodes[n.index], r, best.t);
            let tr = slab(nodes[n.index + 1u], r, best.t);
            if tl >= 0.0 && tr >= 0.0 {
                let right_first = tr < tl;
                if sp == STACK_SIZE {
                    fault(FAULT_STACK);
                    return best;
                }
                stack_node[sp] = select(n.index + 1u, n.index, right_first);
                stack_near[sp] = select(tr, tl, right_first);
                sp += 1u;
                current = select(n.index, n.index + 1u, right_first);
                continue;
            }
            if tl >= 0.0 {
                current = n.index;
                continue;
            }
            if tr >= 0.0 {
                current = n.index + 1u;
                continue;
            }
        }
        // Pop the next subtree that may still hold a nearer hit.
        var found = false;
        while sp > 0u {
            sp -= 1u;
            if may_hold(stack_near[sp], best.t) {
                current = stack_node[sp];
                found = true;
                break;
            }
        }
        if !found {
            return best;
        }
    }
    return best;
}
