// SST (thesis 4.3.3, code examples 4.9-4.13, after Günther et al. 2007): the whole workgroup (a
// block of pixels) walks ONE path through the child-pair tree. The children of the current node
// and a leaf's triangles are loaded cooperatively into workgroup memory; every ray records in a
// 4-entry hit code whether it hit neither, the left, the right or both children; when both are
// needed, each ray that hit both votes -1 (left first) or +1 (right first), a parallel reduction
// sums the votes (or, in the subgroup variant, subgroupAdd and one barrier), and the majority
// decides which child comes first. The other goes on a stack of
// whole nodes in workgroup memory. Rays that miss the child taken go inactive until the next pop,
// which re-activates all of them. STACK_SIZE is the file's max depth; LEAF_SIZE its largest leaf.

const WG_SIZE: u32 = WG_X * WG_Y;

//#if VOTE_SUBGROUP
// Set by the entry point: this invocation's lane in its subgroup, the subgroup's index in the
// workgroup, and the number of subgroups.
var<private> sg_lane: u32;
var<private> sg_id: u32;
var<private> sg_count: u32;
//#endif

var<workgroup> sst_stack: array<Node, STACK_SIZE>;
var<workgroup> sst_children: array<Node, 2>;
var<workgroup> sst_tris: array<Tri, LEAF_SIZE>;
var<workgroup> sst_votes: array<i32, WG_SIZE>;
var<workgroup> sst_hitcode: array<atomic<u32>, 4>;
var<workgroup> sst_live: atomic<u32>;
var<workgroup> sst_node: Node;
var<workgroup> sst_sp: u32;
// 0: continue with sst_node, 1: the walk is over
var<workgroup> sst_done: u32;
// Which child the workgroup enters: 0 left, 1 right, 2 none (pop)
var<workgroup> sst_next: u32;

fn trace(r: Ray, t_min: f32, t_max: f32, any_hit: bool, enabled: bool) -> HitRec {
    var best = HitRec(t_max, NO_TRIANGLE, 0.0, 0.0);
    // `live`: still looking (an any-hit ray stops at its first hit); `taking_part`: takes part in the
    // current node.
    var live = enabled;
    if lid == 0u {
        sst_node = nodes[0];
        sst_sp = 0u;
        sst_done = 0u;
        atomicStore(&sst_live, 0u);
    }
    workgroupBarrier();
    var taking_part = false;
    if live {
        cost_nodes += 1u;
        taking_part = slab(sst_node, r, best.t) >= 0.0;
        atomicOr(&sst_live, u32(taking_part));
    }
    workgroupBarrier();
    if lid == 0u && atomicLoad(&sst_live) == 0u {
        sst_done = 1u;
    }
    // A walk enters each node at most once: more steps than nodes means the walk went wrong, and
    // the frame is refused instead of hanging (every invocation counts the same steps).
    let node_count = arrayLength(&nodes);
    var steps = 0u;
    loop {
        if workgroupUniformLoad(&sst_done) != 0u {
            break;
        }
        steps += 1u;
        if steps > node_count {
            if lid == 0u {
                fault(FAULT_WALK);
            }
            break;
        }
        let node = workgroupUniformLoad(&sst_node);
        var pop = false;
        if node.count > 0u {
            for (var i = lid; i < node.count; i += WG_SIZE) {
                sst_tris[i] = tris[node.index + i];
            }
            workgroupBarrier();
            if taking_part {
                for (var i = 0u; i < node.count; i++) {
                    cost_tris += 1u;
                    let idx = node.index + i;
                    let h = intersect(sst_tris[i], r, t_min, best.t);
                    if h.x >= 0.0 && (h.x < best.t || (h.x == best.t && idx < best.tri)) {
                        best = HitRec(h.x, idx, h.y, h.z);
                        if any_hit {
                            live = false;
                            break;
                        }
                    }
                }
            }
            pop = true;
        } else {
            // Loops, not `lid < 2u`: a workgroup may have fewer invocations than entries.
            for (var i = lid; i < 2u; i += WG_SIZE) {
                sst_children[i] = nodes[node.index + i];
            }
            for (var i = lid; i < 4u; i += WG_SIZE) {
                atomicStore(&sst_hitcode[i], 0u);
            }
            workgroupBarrier();
            var code = 0u;
            var vote = 0;
            if taking_part {
                cost_nodes += 2u;
                let tl = slab(sst_children[0], r, best.t);
                let tr = slab(sst_children[1], r, best.t);
                code = select(0u, 1u, tl >= 0.0) | select(0u, 2u, tr >= 0.0);
                if code == 3u {
                    vote = select(-1, 1, tr < tl);
                }
                atomicStore(&sst_hitcode[code], 1u);
            }
//#if VOTE_REDUCTION
            sst_votes[lid] = vote;
            workgroupBarrier();
            // Parallel reduction of the votes (WG_SIZE is a power of two).
            for (var s = WG_SIZE / 2u; s > 0u; s >>= 1u) {
                if lid < s {
                    sst_votes[lid] += sst_votes[lid + s];
                }
                workgroupBarrier();
            }
//#endif
//#if VOTE_SUBGROUP
            // Each subgroup sums its votes in registers; one barrier, then lid 0 adds the few
            // partial sums.
            let partial = subgroupAdd(vote);
            if sg_lane == 0u {
                sst_votes[sg_id] = partial;
            }
            workgroupBarrier();
            if lid == 0u {
                for (var i = 1u; i < sg_count; i++) {
                    sst_votes[0] += sst_votes[i];
                }
            }
//#endif
            if lid == 0u {
                let both = atomicLoad(&sst_hitcode[3]) != 0u;
                let left = both || atomicLoad(&sst_hitcode[1]) != 0u;
                let right = both || atomicLoad(&sst_hitcode[2]) != 0u;
                if left && right {
                    let right_first = sst_votes[0] > 0;
                    // One push per level: a full stack means the tree is deeper than the file says.
                    if sst_sp == STACK_SIZE {
                        fault(FAULT_STACK);
                        sst_done = 1u;
                    } else {
                        sst_stack[sst_sp] = sst_children[select(1u, 0u, right_first)];
                        sst_sp += 1u;
                    }
                    sst_next = select(0u, 1u, right_first);
                } else if left {
                    sst_next = 0u;
                } else if right {
                    sst_next = 1u;
                } else {
                    sst_next = 2u;
                }
            }
            let next = workgroupUniformLoad(&sst_next);
            if next == 2u {
                pop = true;
            } else {
                taking_part = taking_part && (code & (1u << next)) != 0u;
                if lid == 0u {
                    sst_node = sst_children[next];
                }
            }
        }
        if pop {
            workgroupBarrier();
            if lid == 0u {
                if sst_sp == 0u {
                    sst_done = 1u;
                } else {
                    sst_sp -= 1u;
                    sst_node = sst_stack[sst_sp];
                }
                atomicStore(&sst_live, 0u);
            }
            workgroupBarrier();
            // The pop re-activates every ray that is still looking.
            taking_part = live;
            atomicOr(&sst_live, u32(live));
            workgroupBarrier();
            if lid == 0u && atomicLoad(&sst_live) == 0u {
                sst_done = 1u;
            }
        }
        workgroupBarrier();
    }
    return best;
}
