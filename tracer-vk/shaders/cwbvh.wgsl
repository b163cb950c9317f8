// CWBVH (Ylitie, Karras and Laine, HPG 2017): one ray per invocation over the file's wide layout
// (bvh_format::wide): eight children per node with boxes quantised to 8 bits per axis relative to
// the node's grid. The kernels' `nodes` binding holds WideNode records for this method (kernels.rs
// swaps the declaration). A node's eight boxes are decoded exactly as the validator decodes them
// (origin + q * 2^e, the product exact, one rounding) and tested with the shared slab test; its
// hit leaves are gathered into one 32-bit mask of triangles after its triangle_base and tested,
// run by run, with the shared intersect_leaf; its hit inner children become a node group.
//
// Node groups (the paper's stack entries): x = the first inner child's index, y = the hit mask in
// bits 0-7 and the node's inner mask in bits 8-15. Slot s of a node is for rays of octant s (bit 0
// x, bit 1 y, bit 2 z negative); a ray of octant o keeps slot s's hit at bit s ^ o, so taking the
// lowest bit first visits slot o, then o ^ 1, ...: the near-to-far order the compiler chose the
// slots for. STACK_SIZE is the wide tree's depth: entering a node of depth d leaves at most one
// group per level above it on the stack (if it would overflow, the frame is refused).

struct WideNode {
    origin: vec3<f32>,
    // Biased exponents of the grid steps (bits 0-7 x, 8-15 y, 16-23 z), inner mask (bits 24-31).
    exp_imask: u32,
    child_base: u32,
    tri_base: u32,
    // The meta bytes, one per slot: 0 inner, 0xFF empty, else (count - 1) << 5 | offset of a leaf.
    slot_info: vec2<u32>,
    // Quantised low and high corners: words 2a and 2a + 1 hold axis a's bytes of slots 0-3 and 4-7.
    lo: array<u32, 6>,
    hi: array<u32, 6>,
}

fn octant(d: vec3<f32>) -> u32 {
    return select(0u, 1u, d.x < 0.0) | select(0u, 2u, d.y < 0.0) | select(0u, 4u, d.z < 0.0);
}

fn grid_step(e: u32) -> f32 {
    return bitcast<f32>((e & 0xFFu) << 23u);
}

fn trace(r: Ray, t_min: f32, t_max: f32, any_hit: bool, enabled: bool) -> HitRec {
    var best = HitRec(t_max, NO_TRIANGLE, 0.0, 0.0);
    if !enabled {
        return best;
    }
    let oct = octant(r.d);
    var stack: array<vec2<u32>, STACK_SIZE>;
    var sp = 0u;
    // The root as the only inner child (slot 0) of a node with its first child at 0.
    var group = vec2<u32>(0u, (1u << oct) | (1u << 8u));
    // Each node is entered at most once; more steps than nodes would be a walk gone wrong.
    let node_count = arrayLength(&nodes);
    var steps = 0u;
    loop {
        if (group.y & 0xFFu) == 0u {
            if sp == 0u {
                break;
            }
            sp -= 1u;
            group = stack[sp];
        }
        let bit = countTrailingZeros(group.y & 0xFFu);
        let slot = bit ^ oct;
        let index = group.x + countOneBits((group.y >> 8u) & ((1u << slot) - 1u));
        group.y &= ~(1u << bit);
        if (group.y & 0xFFu) != 0u {
            if sp == STACK_SIZE {
                fault(FAULT_STACK);
                return best;
            }
            stack[sp] = group;
            sp += 1u;
        }
        steps += 1u;
        if steps > node_count {
            fault(FAULT_WALK);
            return best;
        }

        var n = nodes[index];
        let step = vec3<f32>(grid_step(n.exp_imask), grid_step(n.exp_imask >> 8u), grid_step(n.exp_imask >> 16u));
        let imask = n.exp_imask >> 24u;
        var hits = 0u;
        var leaves = 0u;
        for (var s = 0u; s < 8u; s++) {
            let w = s >> 2u;
            let shift = (s & 3u) * 8u;
            let info = (n.slot_info[w] >> shift) & 0xFFu;
            let inner = ((imask >> s) & 1u) != 0u;
            if !inner && info == 0xFFu {
                continue;
            }
            let qlo = vec3<u32>(n.lo[w], n.lo[2u + w], n.lo[4u + w]) >> vec3<u32>(shift);
            let qhi = vec3<u32>(n.hi[w], n.hi[2u + w], n.hi[4u + w]) >> vec3<u32>(shift);
            let lo = n.origin + vec3<f32>(qlo & vec3<u32>(0xFFu)) * step;
            let hi = n.origin + vec3<f32>(qhi & vec3<u32>(0xFFu)) * step;
            cost_nodes += 1u;
            if slab(Node(lo, 0u, hi, 0u), r, best.t) >= 0.0 {
                if inner {
                    hits |= 1u << (s ^ oct);
                } else {
                    leaves |= ((1u << ((info >> 5u) + 1u)) - 1u) << (info & 31u);
                }
            }
        }
        group = vec2<u32>(n.child_base, hits | (imask << 8u));

        // The hit leaves' triangles, each run of consecutive ones as one leaf of the shared code.
        while leaves != 0u {
            let first = countTrailingZeros(leaves);
            let run = countTrailingZeros(~(leaves >> first));
            leaves &= ~((0xFFFFFFFFu >> (32u - run)) << first);
            if intersect_leaf(Node(vec3<f32>(0.0), run, vec3<f32>(0.0), n.tri_base + first), r, t_min, &best, any_hit) {
                return best;
            }
        }
    }
    return best;
}
