// SST (thesis 4.3.3, code examples 4.9-4.13, after Günther et al. 2007): the whole workgroup (a
// block of pixels) walks ONE path through the child-pair tree. The children of the current node
// and a leaf's triangles are held in workgroup memory (a leaf's loaded cooperatively); every ray
// records whether it hit neither, the left, the right or both children in a shared hit code; when
// both are needed, each ray that hit both votes -1 (left first) or +1 (right first), a parallel
// reduction sums the votes (or, in the subgroup variant, subgroupAdd and one barrier), and the
// majority decides which child comes first. The other goes on a stack of whole nodes in workgroup
// memory. Rays that miss the child taken go inactive until the next pop, which re-activates all of
// them. STACK_SIZE is the file's max depth; LEAF_SIZE the triangles the leaf cache holds: the
// file's largest leaf, or fewer where the device's workgroup memory would not hold that many
// (larger leaves are then loaded and tested in chunks).
//
// Workgroup memory is not zero-initialised (tracer-vk/src/shader.rs): every variable below is
// written before it is read. naga's zero-initialisation stored each whole array at the kernel's
// start, and lavapipe's compile time grew steeply with the leaf cache (a Whitted frame's first
// submission: 10 s for a cache of 8 triangles, 99 s for 128, over 120 s for 256; 4 to 6 s for
// any size without it).
//
// Invocation 0 makes every decision and publishes it as one step (the node to visit and how the
// rays take part), read by all at the top of the next iteration: an inner node costs the barriers
// of that read and of the vote, a leaf those of the read, its load and one more. Every loop over
// the workgroup's invocations (loading, resetting, reducing) strides by WG_SIZE, so any workgroup
// from one invocation up works, whatever the device's subgroup size.

const WG_SIZE: u32 = WG_X * WG_Y;

//#if VOTE_SUBGROUP
// Set by the entry point: this invocation's lane in its subgroup, the subgroup's index in the
// workgroup, and the number of subgroups.
var<private> sg_lane: u32;
var<private> sg_id: u32;
var<private> sg_count: u32;
//#endif

// How the rays take part in a step's node.
const STEP_KEEP: u32 = 0u; // as in the last step (the root)
const STEP_LEFT: u32 = 1u; // the rays that hit the left child
const STEP_RIGHT: u32 = 2u; // the rays that hit the right child
const STEP_POP: u32 = 3u; // every ray still looking (the node came off the stack)
const STEP_DONE: u32 = 4u; // the walk is over

struct SstStep {
    node: Node,
    how: u32,
}

var<workgroup> sst_step: SstStep;
var<workgroup> sst_stack: array<Node, STACK_SIZE>;
// The children of the step's node, when it is an inner node.
var<workgroup> sst_children: array<Node, 2>;
var<workgroup> sst_tris: array<Tri, LEAF_SIZE>;
var<workgroup> sst_votes: array<i32, WG_SIZE>;
// Bit 1 << code for each hit code (1 left, 2 right, 3 both) some ray had.
var<workgroup> sst_hits: atomic<u32>;
// Whether some ray is still looking (any-hit rays stop at their first hit).
var<workgroup> sst_live: atomic<u32>;

// Invocation 0 only: publishes `node` as the next step, with its children when it is inner.
fn sst_publish(node: Node, how: u32) {
    sst_step = SstStep(node, how);
    if node.count == 0u && how != STEP_DONE {
        sst_children[0] = nodes[node.index];
        sst_children[1] = nodes[node.index + 1u];
    }
}

fn trace(r: Ray, t_min: f32, t_max: f32, any_hit: bool, enabled: bool) -> HitRec {
    var best = HitRec(t_max, NO_TRIANGLE, 0.0, 0.0);
    // `live`: still looking; `taking_part`: takes part in the current node; `code`: which children
    // of the last inner node this ray hit (bit 0 left, bit 1 right).
    var live = enabled;
    var taking_part = false;
    var code = 0u;
    // Invocation 0's stack pointer: only it pushes and pops.
    var sp = 0u;
    if lid == 0u {
        atomicStore(&sst_hits, 0u);
        atomicStore(&sst_live, 0u);
    }
    workgroupBarrier();
    if live {
        cost_nodes += 1u;
        taking_part = slab(nodes[0], r, best.t) >= 0.0;
        if taking_part {
            atomicOr(&sst_live, 1u);
        }
    }
    workgroupBarrier();
    if lid == 0u {
        sst_publish(nodes[0], select(STEP_DONE, STEP_KEEP, atomicLoad(&sst_live) != 0u));
        atomicStore(&sst_live, 0u);
    }
    // A walk visits each node at most once: more steps than nodes means it went wrong, and the
    // frame is refused instead of hanging (every invocation counts the same steps).
    let node_count = arrayLength(&nodes);
    var steps = 0u;
    loop {
        let step = workgroupUniformLoad(&sst_step);
        if step.how == STEP_DONE {
            break;
        }
        steps += 1u;
        if steps > node_count {
            if lid == 0u {
                fault(FAULT_WALK);
            }
            break;
        }
        if step.how == STEP_POP {
            taking_part = live;
        } else if step.how != STEP_KEEP {
            taking_part = taking_part && (code & step.how) != 0u;
        }
        let node = step.node;
        if node.count > 0u {
            // The leaf in chunks of LEAF_SIZE triangles: one chunk unless the leaf is larger than
            // the cache (the host shrinks the cache until the stack and it fit the device's
            // workgroup memory). `node` is uniform, so every invocation runs the same chunks and
            // reaches every barrier.
            for (var base = 0u; base < node.count; base += LEAF_SIZE) {
                let n = min(node.count - base, LEAF_SIZE);
                for (var i = lid; i < n; i += WG_SIZE) {
                    sst_tris[i] = fetch_tri(node.index + base + i);
                }
                workgroupBarrier();
                if taking_part && live {
                    for (var i = 0u; i < n; i++) {
                        cost_tris += 1u;
                        let idx = node.index + base + i;
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
                // The next chunk overwrites the cache only once every ray is done with this one.
                if base + LEAF_SIZE < node.count {
                    workgroupBarrier();
                }
            }
            if live {
                atomicOr(&sst_live, 1u);
            }
            workgroupBarrier();
            if lid == 0u {
                // Pop, unless no ray is looking any more.
                let any_live = atomicLoad(&sst_live) != 0u;
                atomicStore(&sst_live, 0u);
                if any_live && sp > 0u {
                    sp -= 1u;
                    sst_publish(sst_stack[sp], STEP_POP);
                } else {
                    sst_publish(node, STEP_DONE);
                }
            }
            continue;
        }
        code = 0u;
        var vote = 0;
        if taking_part {
            cost_nodes += 2u;
            let tl = slab(sst_children[0], r, best.t);
            let tr = slab(sst_children[1], r, best.t);
            code = select(0u, 1u, tl >= 0.0) | select(0u, 2u, tr >= 0.0);
            if code == 3u {
                vote = select(-1, 1, tr < tl);
            }
            if code != 0u {
                atomicOr(&sst_hits, 1u << code);
            }
        }
//#if VOTE_REDUCTION
        // Parallel reduction of the votes (WG_SIZE is a power of two). Invocation 0 adds the last
        // pair itself, so the last halving needs no barrier.
        sst_votes[lid] = vote;
        workgroupBarrier();
        for (var s = WG_SIZE / 2u; s > 1u; s >>= 1u) {
            if lid < s {
                sst_votes[lid] += sst_votes[lid + s];
            }
            workgroupBarrier();
        }
        var votes = sst_votes[0];
        if WG_SIZE > 1u {
            // (An index naga can bound when the workgroup has one invocation.)
            votes += sst_votes[min(1u, WG_SIZE - 1u)];
        }
//#endif
//#if VOTE_SUBGROUP
        // Each subgroup sums its votes in registers; one barrier, then invocation 0 adds the few
        // partial sums.
        let partial = subgroupAdd(vote);
        if sg_lane == 0u {
            sst_votes[sg_id] = partial;
        }
        workgroupBarrier();
        var votes = 0;
        if lid == 0u {
            for (var i = 0u; i < sg_count; i++) {
                votes += sst_votes[i];
            }
        }
//#endif
        if lid == 0u {
            let hits = atomicLoad(&sst_hits);
            atomicStore(&sst_hits, 0u);
            let both = (hits & 8u) != 0u;
            let left = both || (hits & 2u) != 0u;
            let right = both || (hits & 4u) != 0u;
            var children = array<Node, 2>(sst_children[0], sst_children[1]);
            if left && right {
                let right_first = votes > 0;
                // One push per level: a full stack means the tree is deeper than its file says.
                if sp == STACK_SIZE {
                    fault(FAULT_STACK);
                    sst_publish(node, STEP_DONE);
                } else {
                    sst_stack[sp] = children[select(1u, 0u, right_first)];
                    sp += 1u;
                    let first = select(0u, 1u, right_first);
                    sst_publish(children[first], STEP_LEFT << first);
                }
            } else if left {
                sst_publish(children[0], STEP_LEFT);
            } else if right {
                sst_publish(children[1], STEP_RIGHT);
            } else if sp > 0u {
                // A live ray got here (the last leaf said so), so popping finds work.
                sp -= 1u;
                sst_publish(sst_stack[sp], STEP_POP);
            } else {
                sst_publish(node, STEP_DONE);
            }
        }
    }
    return best;
}
