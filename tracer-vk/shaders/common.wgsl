// Shared by every kernel: the scene's data, the frame's state, and the intersection and shading
// arithmetic of docs/shading.md. The host prepends the shading contract's constants (T_SLACK,
// OFFSET_*, STOP_*, NO_TRIANGLE, FLAT_NORMAL, F32_MAX, generated from render_spec::constants,
// where each is defined and explained) and the per-scene constants STACK_SIZE, LEAF_SIZE, WG_X and WG_Y, and
// strips the blocks between `//#if FEATURE` and `//#endif` for features the scene lacks.

struct Node {
    min: vec3<f32>,
    count: u32,
    max: vec3<f32>,
    index: u32,
}

// A triangle as the tracers intersect it (bvh_format::Triangle): three vertices, the material in
// the first padding word.
struct Tri {
    p0: vec3<f32>,
    material: u32,
    p1: vec3<f32>,
    pad1: u32,
    p2: vec3<f32>,
    pad2: u32,
}

// Material as the file stores it: (kd, shininess), (ks, kr), (kt, ior, -, -).
struct Material {
    kd_n: vec4<f32>,
    ks_kr: vec4<f32>,
    kt_ior: vec4<f32>,
}

struct Light {
    position: vec4<f32>,
    colour: vec4<f32>,
}

struct Frame {
    eye: vec4<f32>,
    top_left: vec4<f32>,
    h_step: vec4<f32>,
    v_step: vec4<f32>,
    ambient: vec4<f32>,
    background: vec4<f32>,
    // width, height, light count, max indirections
    size: vec4<u32>,
    // bounce-stop bound B, largest kr/kt, the cutoff (Accuracy::cutoff), -
    stop: vec4<f32>,
    // The tile this dispatch renders: first column, first row, width, height. The per-pixel
    // buffers hold the tile's pixels only, row by row.
    tile: vec4<u32>,
    // This sample's point in the pixel (x, y from the top-left corner, render_spec's
    // sample_positions), 1 / samples per pixel (from the host: WGSL's division need not be
    // correctly rounded), the fixed origin offset (feature FIXED_OFFSET).
    sample: vec4<f32>,
    // This sample's index, samples per pixel, AO rays per hit (Mode::Ao), -.
    samples: vec4<u32>,
    // The AO rays' length in scene units (render_spec::Ao::distance) and the host's f32 of
    // 1 / (AO rays per hit), -, -.
    ao: vec4<f32>,
}

// The current ray of a pixel: origin (w: path weight), direction (w: 1 while the path is alive).
struct PathRay {
    origin: vec4<f32>,
    dir: vec4<f32>,
}

struct HitRec {
    t: f32,
    tri: u32,
    u: f32,
    v: f32,
}

// A pixel's colour so far, the local term of its current hit summed over the lights shaded so far
// (added to the colour, times the path weight, after the last light, as the CPU does; in AO mode
// local.x counts the AO rays not blocked so far), and the sum of the colours of the pixel's
// finished samples.
struct Accum {
    colour: vec4<f32>,
    local: vec4<f32>,
    sum: vec4<f32>,
}

struct Aov {
    normal: vec4<f32>,
    t: f32,
    prim: u32,
    nodes: u32,
    tris: u32,
}

// Which light a shade pass handles, and which bounce a bounce pass (or which ray an AO pass) is
// (a push constant); `work`: the counters word the persistent kernels take their work from
// (stages.wgsl), one per pass of a submission, and `cap`: the most pixels per lane a subgroup of
// them takes (0: no limit).
struct Pass {
    light: u32,
    depth: u32,
    work: u32,
    cap: u32,
}

@group(0) @binding(0) var<storage, read> frame: Frame;
@group(0) @binding(1) var<storage, read> nodes: array<Node>;
//#if EXPANDED_VERTICES
@group(0) @binding(2) var<storage, read> tris: array<Tri>;
//#endif
//#if INDEXED_VERTICES
// The file's indexed form (`--vertices indexed`): per triangle in leaf order its three vertex
// indices and material, then from FIRST_VERTEX on the vertex positions (w unused), 16 bytes each.
@group(0) @binding(2) var<storage, read> tris: array<vec4<u32>>;
//#endif
// Three normal indices per triangle (all FLAT_NORMAL for a flat one) and three floats per normal; read
// only when the scene has smooth triangles (feature SMOOTH), else one-entry placeholders.
@group(0) @binding(3) var<storage, read> normal_indices: array<u32>;
@group(0) @binding(4) var<storage, read> normals: array<f32>;
@group(0) @binding(5) var<storage, read> materials: array<Material>;
@group(0) @binding(6) var<storage, read> lights: array<Light>;
@group(0) @binding(7) var<storage, read> input_index: array<u32>;
@group(0) @binding(8) var<storage, read_write> paths: array<PathRay>;
@group(0) @binding(9) var<storage, read_write> hits: array<HitRec>;
@group(0) @binding(10) var<storage, read_write> accum: array<Accum>;
@group(0) @binding(11) var<storage, read_write> aovs: array<Aov>;
@group(0) @binding(12) var<storage, read_write> image: array<u32>;
// Ray counts, finished invocations, faults and live paths per bounce, at the SLOT_* words the
// host prepends (kernels.rs); see count() and fault().
@group(0) @binding(13) var<storage, read_write> counters: array<atomic<u32>>;
var<immediate> pass_info: Pass;

// This invocation's index in its workgroup (set by the entry point; SST needs it).
var<private> lid: u32;

// Adds n to the 64-bit counter at words `slot` (low) and `slot + 1` (high): a tile's shadow
// rays can pass 2^32. The invocation whose addition wraps the low word carries.
fn count_n(slot: u32, n: u32) {
    let old = atomicAdd(&counters[slot], n);
    if old + n < old {
        atomicAdd(&counters[slot + 1u], 1u);
    }
}

fn count(slot: u32) {
    count_n(slot, 1u);
}

// Records that a traversal gave up on a ray (a FAULT_* bit); the host refuses the frame.
fn fault(bit: u32) {
    atomicOr(&counters[SLOT_FAULTS], bit);
}

// Work done by the current invocation's rays, for the cost AOV.
var<private> cost_nodes: u32;
var<private> cost_tris: u32;

// Division and square root as the CPU rounds them (IEEE 754: correctly rounded, subnormals kept).
// Vulkan lets a device's division and sqrt() be off by 2.5 ulp (NVIDIA's are) and its fma() be
// unfused (lavapipe's is), so an --exact kernel spells them div_rn() and sqrt_rn(): the device's
// float operations only estimate the result's significand, integer arithmetic on the significands
// (products of up to 50 bits in two words) decides which side of each midpoint the exact result
// lies, and subnormal operands and results are handled with integers too, so a device that
// flushes denormals still gets them right. The other kernels have no such functions: kernels.rs
// writes each call as the plain operator there. The Rust model and its exhaustive tests are
// tracer-vk/tests/exact_rounding.rs.
//#if EXACT
struct Split {
    // The significand as a float in [1, 2) and the exponent of a finite nonzero |x|.
    m: f32,
    e: i32,
}

fn split(magnitude: u32) -> Split {
    let field = magnitude & 0x7fffffu;
    let biased = magnitude >> 23u;
    if biased != 0u {
        return Split(bitcast<f32>(field | 0x3f800000u), i32(biased) - 127i);
    }
    let top = 31u - countLeadingZeros(field);
    return Split(bitcast<f32>(((field << (23u - top)) & 0x7fffffu) | 0x3f800000u), i32(top) - 149i);
}

// The significand of a float in [1, 2) as an integer in [2^23, 2^24).
fn significand(m: f32) -> u32 {
    return (bitcast<u32>(m) & 0x7fffffu) | 0x800000u;
}

// a b for a, b < 2^26, as (high word, low word).
fn mul_wide(a: u32, b: u32) -> vec2<u32> {
    let a0 = a & 0xffffu;
    let b0 = b & 0xffffu;
    let low = a0 * b0;
    let mid = (a >> 16u) * b0 + a0 * (b >> 16u);
    let lo = low + (mid << 16u);
    return vec2<u32>((a >> 16u) * (b >> 16u) + (mid >> 16u) + select(0u, 1u, lo < low), lo);
}

// x 2^k for x < 2^26 and 7 <= k <= 31, as (high word, low word).
fn shl_wide(x: u32, k: u32) -> vec2<u32> {
    return vec2<u32>(x >> (32u - k), x << k);
}

fn wide_less(a: vec2<u32>, b: vec2<u32>) -> bool {
    return a.x < b.x || (a.x == b.x && a.y < b.y);
}

fn div_rn(a: f32, b: f32) -> f32 {
    let sign = (bitcast<u32>(a) ^ bitcast<u32>(b)) & 0x80000000u;
    let ma = bitcast<u32>(a) & 0x7fffffffu;
    let mb = bitcast<u32>(b) & 0x7fffffffu;
    let inf = 0x7f800000u;
    if ma > inf || mb > inf || (ma == inf && mb == inf) || (ma == 0u && mb == 0u) {
        return a / b; // NaN
    }
    if ma == inf || mb == 0u {
        return bitcast<f32>(sign | inf);
    }
    if ma == 0u || mb == inf {
        return bitcast<f32>(sign);
    }
    let x = split(ma);
    let y = split(mb);
    // With significands X and Y the quotient's is n = RN(X 2^k / Y), k = 23 where X >= Y (a
    // quotient in [1, 2)), else 24. A Newton step on the device's reciprocal and one on the
    // quotient estimate it to about an ulp (with a fused or an unfused fma).
    let big_x = significand(x.m);
    let big_y = significand(y.m);
    let k = select(24u, 23u, big_x >= big_y);
    var r = 1.0 / y.m;
    r = fma(fma(-y.m, r, 1.0), r, r);
    var q = x.m * r;
    q = fma(fma(-q, y.m, x.m), r, q);
    var n = u32(q * bitcast<f32>((127u + k) << 23u));
    // The quotient lies above the midpoint (2n + 1) / 2^(k + 1) where X 2^(k + 1) > (2n + 1) Y;
    // never on it (an odd multiple of Y is no power-of-two multiple of X this small).
    let scaled = shl_wide(big_x, k + 1u);
    for (var i = 0; i < 2; i++) {
        if wide_less(mul_wide(2u * n + 1u, big_y), scaled) {
            n += 1u;
        }
        if wide_less(scaled, mul_wide(2u * n - 1u, big_y)) {
            n -= 1u;
        }
    }
    // Which side of n the quotient lies on, for rounding a subnormal one.
    let exact = shl_wide(big_x, k);
    let product = mul_wide(n, big_y);
    let above = wide_less(product, exact);
    let below = wide_less(exact, product);
    var e = x.e - y.e + 23i - i32(k); // a / b = n 2^(e - 23)
    if n == 0x1000000u {
        n = 0x800000u;
        e += 1i;
    }
    if e > 127i {
        return bitcast<f32>(sign | inf);
    }
    if e >= -126i {
        return bitcast<f32>(sign | (u32(e + 127i) << 23u) | (n & 0x7fffffu));
    }
    // A subnormal quotient keeps the top 24 - s bits of n, rounded to nearest even with the
    // dropped bits and, at exactly half, the side of n the quotient lies on.
    let s = u32(min(-126i - e, 25i));
    let kept = n >> s;
    let dropped = n & ((1u << s) - 1u);
    let half = 1u << (s - 1u);
    let up = dropped > half || (dropped == half && (above || (!below && (kept & 1u) == 1u)));
    return bitcast<f32>(sign | (kept + select(0u, 1u, up)));
}

fn div3_rn(a: vec3<f32>, b: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(div_rn(a.x, b.x), div_rn(a.y, b.y), div_rn(a.z, b.z));
}

fn sqrt_rn(x: f32) -> f32 {
    let bits = bitcast<u32>(x);
    if bits == 0u || bits == 0x80000000u || bits == 0x7f800000u {
        return x; // +-0 and +inf
    }
    if bits > 0x7f800000u {
        return sqrt(x); // negative or NaN: NaN
    }
    // x = m 2^e with m = W 2^-23 in [1, 4) and e even: sqrt(m) in [1, 2), never subnormal; its
    // significand n = RN(sqrt(m) 2^23), estimated by the device's sqrt and a Newton step.
    let v = split(bits);
    let odd = (v.e & 1i) != 0i;
    let m = select(v.m, 2.0 * v.m, odd);
    let e = select(v.e, v.e - 1i, odd);
    let w = significand(v.m) << select(0u, 1u, odd);
    var s = sqrt(m);
    s = fma(fma(-s, s, m), 0.5 / s, s);
    var n = u32(s * 8388608.0);
    // sqrt(m) lies above the midpoint (2n + 1) 2^-24 where W 2^25 > (2n + 1)^2 (never equal:
    // an odd square is not even).
    let scaled = shl_wide(w, 25u);
    for (var i = 0; i < 2; i++) {
        if wide_less(mul_wide(2u * n + 1u, 2u * n + 1u), scaled) {
            n += 1u;
        }
        if wide_less(scaled, mul_wide(2u * n - 1u, 2u * n - 1u)) {
            n -= 1u;
        }
    }
    return bitcast<f32>(bitcast<u32>(f32(n) * bitcast<f32>(0x34000000u)) + (bitcast<u32>(e / 2i) << 23u));
}
//#endif

// Vector arithmetic in tracer-cpu's operation order (wide.rs `V3`): the builtins dot(), cross(),
// length() and normalize() (see unit()) leave the order and the rounding to the driver, so an --exact kernel
// (no_contraction.rs refuses them) could not round as the CPU does.
fn dot3(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

fn cross3(a: vec3<f32>, b: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(a.y * b.z - b.y * a.z, a.z * b.x - b.z * a.x, a.x * b.y - b.x * a.y);
}

fn length3(v: vec3<f32>) -> f32 {
    return sqrt_rn(dot3(v, v));
}

// tracer-cpu's V3::normalize: one division, then three products (lavapipe's normalize() differs in
// the last bit for a third of the inputs: tests/tests/wgsl_functions.rs).
fn unit(v: vec3<f32>) -> vec3<f32> {
    return v * div_rn(1.0, length3(v));
}

fn is_finite(x: f32) -> bool {
    return (bitcast<u32>(x) & 0x7f800000u) != 0x7f800000u;
}

// glam's try_normalize: the unit vector where the inverse length is finite and positive, else
// `fallback`.
fn normalize_or(v: vec3<f32>, fallback: vec3<f32>) -> vec3<f32> {
    let rcp = div_rn(1.0, length3(v));
    return select(fallback, v * rcp, is_finite(rcp) && rcp > 0.0);
}

struct Ray {
    o: vec3<f32>,
    d: vec3<f32>,
    inv: vec3<f32>,
    // Origin, direction and reciprocal all finite: no slab distance of this ray can be NaN
    // (node bounds are finite, the reader checks), so `slab` may use plain min/max.
    nan_free: bool,
}

fn make_ray(o: vec3<f32>, d: vec3<f32>) -> Ray {
    let inv = div3_rn(vec3<f32>(1.0), d);
    let finite = is_finite(o.x) && is_finite(o.y) && is_finite(o.z) && is_finite(d.x) && is_finite(d.y)
        && is_finite(d.z) && is_finite(inv.x) && is_finite(inv.y) && is_finite(inv.z);
    return Ray(o, d, inv, finite);
}

fn is_nan(x: f32) -> bool {
    // Bit test: comparisons with themselves may be folded away by a driver's compiler.
    return (bitcast<u32>(x) & 0x7fffffffu) > 0x7f800000u;
}

fn may_hold(near: f32, t: f32) -> bool {
    return near <= t + abs(t) * T_SLACK;
}

// Slab test; returns the entry distance, or -1 for a miss. An axis with a NaN distance (origin in
// the face's plane, direction parallel to it) is skipped, as on the CPU.
//
// A distance is NaN only where a bound minus the origin is 0 and the reciprocal infinite (or an
// input is not finite), so for a `nan_free` ray the per-axis NaN tests are skipped: min/max give
// the same entry and exit as the selects below (up to the sign of a zero entry, which no caller
// can tell apart), at less than half their instructions, and box tests are most of a walk's work.
fn slab(n: Node, r: Ray, t_max: f32) -> f32 {
    let lo = (n.min - r.o) * r.inv;
    let hi = (n.max - r.o) * r.inv;
    if r.nan_free {
        let enter = min(lo, hi);
        let exit = max(lo, hi);
        let near = max(max(enter.x, enter.y), max(enter.z, 0.0));
        // t_max by select, as below, so that a NaN t_max misses here too.
        let e = min(min(exit.x, exit.y), exit.z);
        let far = select(t_max, e, e < t_max);
        return select(-1.0, near, may_hold(near, far));
    }
    var near = 0.0;
    var far = t_max;
    for (var a = 0u; a < 3u; a++) {
        let t0 = lo[a];
        let t1 = hi[a];
        if is_nan(t0) || is_nan(t1) {
            continue;
        }
        let enter = select(t0, t1, t1 < t0);
        let exit = select(t1, t0, t0 > t1);
        near = select(near, enter, enter > near);
        far = select(far, exit, exit < far);
    }
    return select(-1.0, near, may_hold(near, far));
}

// The edge function of the edge from a to b (vertices relative to the ray origin), in the CPU's
// operation order (tracer-cpu geometry::edge_function): dot(cross(a - b, a + b), d), twice
// dot(cross(a, b), d). The triangle on the other side of the edge meets it as (b, a): a - b
// changes sign exactly and a + b not at all, so it gets exactly the negated number, also where a
// driver contracts multiply-adds (fma(-x, y, -z) = -fma(x, y, z)).
fn edge_function(a: vec3<f32>, b: vec3<f32>, d: vec3<f32>) -> f32 {
    let e = a - b;
    let s = a + b;
    let c = vec3<f32>(e.y * s.z - e.z * s.y, e.z * s.x - e.x * s.z, e.x * s.y - e.y * s.x);
    return d.x * c.x + d.y * c.y + d.z * c.z;
}

// The frame's triangle test (render_spec::Intersect): the edge-consistent test by default,
// Möller-Trumbore with feature MOLLER_TRUMBORE. Returns (t, u, v) or t = -1 for a miss.
fn intersect(tri: Tri, r: Ray, t_min: f32, t_max: f32) -> vec3<f32> {
//#if WATERTIGHT
    return intersect_watertight(tri, r, t_min, t_max);
//#endif
//#if MOLLER_TRUMBORE
    return intersect_moller_trumbore(tri, r, t_min, t_max);
//#endif
}

//#if MOLLER_TRUMBORE
// Möller-Trumbore on vertex 0 and its two edges, in the operation order of tracer-cpu's
// geometry::intersect_moller_trumbore: each triangle decides a shared edge after its own
// roundings, so a ray aimed exactly at the edge can pass between both.
fn intersect_moller_trumbore(tri: Tri, r: Ray, t_min: f32, t_max: f32) -> vec3<f32> {
    let d = r.d;
    let e1 = tri.p1 - tri.p0;
    let e2 = tri.p2 - tri.p0;
    let p = vec3<f32>(d.y * e2.z - e2.y * d.z, d.z * e2.x - e2.z * d.x, d.x * e2.y - e2.x * d.y);
    let det = e1.x * p.x + e1.y * p.y + e1.z * p.z;
    if det == 0.0 {
        return vec3<f32>(-1.0, 0.0, 0.0);
    }
    let inv = div_rn(1.0, det);
    let s = r.o - tri.p0;
    let u = (s.x * p.x + s.y * p.y + s.z * p.z) * inv;
    if !(u >= 0.0 && u <= 1.0) {
        return vec3<f32>(-1.0, 0.0, 0.0);
    }
    let q = vec3<f32>(s.y * e1.z - e1.y * s.z, s.z * e1.x - e1.z * s.x, s.x * e1.y - e1.x * s.y);
    let v = (d.x * q.x + d.y * q.y + d.z * q.z) * inv;
    if v < 0.0 || u + v > 1.0 {
        return vec3<f32>(-1.0, 0.0, 0.0);
    }
    let t = (e2.x * q.x + e2.y * q.y + e2.z * q.z) * inv;
    if t > t_min && t <= t_max {
        return vec3<f32>(t, u, v);
    }
    return vec3<f32>(-1.0, 0.0, 0.0);
}
//#endif

// The edge-consistent triangle test of docs/shading.md.
fn intersect_watertight(tri: Tri, r: Ray, t_min: f32, t_max: f32) -> vec3<f32> {
    let d = r.d;
    let a0 = tri.p0 - r.o;
    let a1 = tri.p1 - r.o;
    let a2 = tri.p2 - r.o;
    let w2 = edge_function(a0, a1, d);
    let w0 = edge_function(a1, a2, d);
    let w1 = edge_function(a2, a0, d);
    let inside = (w0 >= 0.0 && w1 >= 0.0 && w2 >= 0.0) || (w0 <= 0.0 && w1 <= 0.0 && w2 <= 0.0);
    let sum = w0 + w1 + w2;
    if !inside || sum == 0.0 {
        return vec3<f32>(-1.0, 0.0, 0.0);
    }
    let e1 = tri.p1 - tri.p0;
    let e2 = tri.p2 - tri.p0;
    let n = vec3<f32>(e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z, e1.x * e2.y - e1.y * e2.x);
    let den = n.x * d.x + n.y * d.y + n.z * d.z;
    if den == 0.0 {
        return vec3<f32>(-1.0, 0.0, 0.0);
    }
    let t = div_rn(n.x * a0.x + n.y * a0.y + n.z * a0.z, den);
    if t > t_min && t <= t_max {
        let inv = div_rn(1.0, sum);
        return vec3<f32>(t, w1 * inv, w2 * inv);
    }
    return vec3<f32>(-1.0, 0.0, 0.0);
}

// Triangle i (leaf order) with its corners and material: every read of a triangle, by the
// traversals and by shading, goes through this function, so the vertex form the host uploaded
// (render.rs `Vertices`) is decided here alone. Both forms give the same bits.
fn fetch_tri(i: u32) -> Tri {
//#if EXPANDED_VERTICES
    return tris[i];
//#endif
//#if INDEXED_VERTICES
    let t = tris[i];
    let p0 = bitcast<vec3<f32>>(tris[FIRST_VERTEX + t.x].xyz);
    let p1 = bitcast<vec3<f32>>(tris[FIRST_VERTEX + t.y].xyz);
    let p2 = bitcast<vec3<f32>>(tris[FIRST_VERTEX + t.z].xyz);
    return Tri(p0, t.w, p1, 0u, p2, 0u);
//#endif
}

// Tests a leaf's triangles against the best hit so far (nearer wins, then the lower index).
fn intersect_leaf(n: Node, r: Ray, t_min: f32, best: ptr<function, HitRec>, any_hit: bool) -> bool {
    for (var i = n.index; i < n.index + n.count; i++) {
        cost_tris += 1u;
        let h = intersect(fetch_tri(i), r, t_min, (*best).t);
        if h.x >= 0.0 && (h.x < (*best).t || (h.x == (*best).t && i < (*best).tri)) {
            *best = HitRec(h.x, i, h.y, h.z);
            if any_hit {
                return true;
            }
        }
    }
    return false;
}

// The origin of a ray leaving the surface at p into the side the unit geometric normal n points
// to, moved as the frame's render_spec::Offset says: p + n * d with feature FIXED_OFFSET, else
// offset_origin().
fn leave(p: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
//#if FIXED_OFFSET
    return p + n * frame.sample.w;
//#endif
//#if SCALE_AWARE_OFFSET
    return offset_origin(p, n);
//#endif
}

// Moves a point off a surface along the unit normal n (Wächter and Binder 2019).
fn offset_origin(p: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    let of_i = vec3<i32>(n * OFFSET_INT_SCALE);
    var p_i: vec3<f32>;
    for (var a = 0u; a < 3u; a++) {
        let bits = bitcast<i32>(p[a]);
        p_i[a] = bitcast<f32>(select(bits + of_i[a], bits - of_i[a], p[a] < 0.0));
    }
    var out: vec3<f32>;
    for (var a = 0u; a < 3u; a++) {
        out[a] = select(p_i[a], p[a] + OFFSET_FLOAT_SCALE * n[a], abs(p[a]) < OFFSET_ORIGIN);
    }
    return out;
}

struct Surface {
    point: vec3<f32>,
    geometric: vec3<f32>,
    shading: vec3<f32>,
    front: bool,
}

//#if SMOOTH
fn vertex_normal(i: u32) -> vec3<f32> {
    return vec3<f32>(normals[3u * i], normals[3u * i + 1u], normals[3u * i + 2u]);
}
//#endif

fn surface_at(r: Ray, h: HitRec) -> Surface {
    let tri = fetch_tri(h.tri);
    let point = r.o + h.t * r.d;
    // A degenerate (zero-area) triangle has no normal of its own: face the ray.
    let ng = normalize_or(cross3(tri.p1 - tri.p0, tri.p2 - tri.p0), -r.d);
    let front = dot3(r.d, ng) < 0.0;
    let geometric = select(-ng, ng, front);
    var shading = geometric;
//#if SMOOTH
    let ni = 3u * h.tri;
    if normal_indices[ni] != FLAT_NORMAL {
        let n0 = vertex_normal(normal_indices[ni]);
        let n1 = vertex_normal(normal_indices[ni + 1u]);
        let n2 = vertex_normal(normal_indices[ni + 2u]);
        let interp = n0 * (1.0 - h.u - h.v) + n1 * h.u + n2 * h.v;
        let s = normalize_or(interp, vec3<f32>(0.0));
        if any(s != vec3<f32>(0.0)) {
            shading = select(s, -s, dot3(s, geometric) < 0.0);
        }
    }
//#endif
    return Surface(point, geometric, shading, front);
}

fn material_of(tri: u32) -> Material {
    return materials[fetch_tri(tri).material];
}

fn reflect_dir(d: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    return d - n * (2.0 * dot3(d, n));
}

// Refraction of the unit d through a surface with unit normal n facing the incoming ray, for the
// ratio eta of the indices (incoming side over far side); w = 0 on total internal reflection.
fn refract_dir(d: vec3<f32>, n: vec3<f32>, eta: f32) -> vec4<f32> {
    let cos_i = -dot3(d, n);
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if k < 0.0 {
        return vec4<f32>(0.0);
    }
    return vec4<f32>(unit(eta * d + (eta * cos_i - sqrt_rn(k)) * n), 1.0);
}

// render_spec::power::phong_pow, operation for operation (see there why pow() is not used).
fn phong_pow(x_in: f32, n: f32) -> f32 {
    if !(x_in > 0.0) {
        return 0.0;
    }
    var x = x_in;
    var e = 0i;
    if x < 1.17549435e-38f {
        x *= 18446744073709551616.0f;
        e = -64i;
    }
    let bits = bitcast<u32>(x);
    e += i32(bits >> 23u) - 127i;
    var m = bitcast<f32>((bits & 0x007fffffu) | 0x3f800000u);
    if m > 1.4142135f {
        m *= 0.5;
        e += 1i;
    }
    let t = m - 1.0;
    var p = POW_LOG2_8;
    p = p * t + POW_LOG2_7;
    p = p * t + POW_LOG2_6;
    p = p * t + POW_LOG2_5;
    p = p * t + POW_LOG2_4;
    p = p * t + POW_LOG2_3;
    p = p * t + POW_LOG2_2;
    p = p * t + POW_LOG2_1;
    p = p * t + POW_LOG2_0;
    let y = n * (t * p + f32(e));
    if y == 0.0 {
        return 1.0;
    }
    if y < -150.0 {
        return 0.0;
    }
    if y > 128.0 {
        return bitcast<f32>(0x7f800000u);
    }
    let fi = floor(y + 0.5);
    let f = y - fi;
    var q = POW_EXP2_6;
    q = q * f + POW_EXP2_5;
    q = q * f + POW_EXP2_4;
    q = q * f + POW_EXP2_3;
    q = q * f + POW_EXP2_2;
    q = q * f + POW_EXP2_1;
    q = q * f + POW_EXP2_0;
    var a = i32(fi);
    var b = 0i;
    if a < -126i {
        a += 64i;
        b = -64i;
    }
    return q * bitcast<f32>(u32(a + 127i) << 23u) * bitcast<f32>(u32(b + 127i) << 23u);
}

// kd cos(theta) + ks cos(phi)^n for a light in direction l; zero when the light is behind.
fn phong(m: Material, s: Surface, d: vec3<f32>, l: vec3<f32>) -> vec3<f32> {
    let cos_t = dot3(s.shading, l);
    if cos_t <= 0.0 {
        return vec3<f32>(0.0);
    }
    let r = reflect_dir(-l, s.shading);
    let cos_p = max(dot3(r, -d), 0.0);
    var spec = 1.0;
    if m.kd_n.w > 0.0 {
        spec = phong_pow(cos_p, m.kd_n.w);
    }
    return m.kd_n.xyz * cos_t + m.ks_kr.xyz * spec;
}

fn worth_tracing(w: f32, remaining: u32) -> bool {
    var chain = 0.0;
    var f = 1.0;
    for (var i = 0u; i < remaining; i++) {
        chain += f;
        f *= frame.stop.y;
        if f < STOP_CHAIN_TERM {
            break;
        }
    }
    // No indirection left stops the chain also at a cutoff of 0 (BounceStop::worth_tracing).
    return remaining > 0u && w * frame.stop.x * chain >= frame.stop.z;
}

fn to_rgba8(c: vec3<f32>) -> u32 {
    let q = vec3<u32>(clamp(c, vec3<f32>(0.0), vec3<f32>(1.0)) * 255.0 + 0.5);
    return q.x | (q.y << 8u) | (q.z << 16u) | (255u << 24u);
}

fn primary_dir(x: u32, y: u32) -> vec3<f32> {
    return unit(frame.top_left.xyz + (f32(x) + frame.sample.x) * frame.h_step.xyz + (f32(y) + frame.sample.y) * frame.v_step.xyz);
}

// render_spec::sequence, step for step: the R2 sequence of a pixel and the cosine-distributed
// directions of the incoherent modes (tests/tests/wgsl_functions.rs holds them to the Rust bits).
fn seq_hash(x_in: u32) -> u32 {
    var x = x_in;
    x ^= x >> 16u;
    x *= 0x7feb352du;
    x ^= x >> 15u;
    x *= 0x846ca68bu;
    x ^= x >> 16u;
    return x;
}

fn seq_unit(x: u32) -> f32 {
    return f32(x >> 8u) * (1.0 / 16777216.0);
}

fn sample_2d(pixel: u32, n: u32) -> vec2<f32> {
    let sx = seq_hash(pixel);
    let sy = seq_hash(sx ^ 0x9e3779b9u);
    return vec2<f32>(seq_unit(sx + n * R2_STEP_X), seq_unit(sy + n * R2_STEP_Y));
}

fn incoherent_sample(sample: u32, rays: u32, ray: u32) -> u32 {
    return sample * rays + ray;
}

// sin(pi/2 x), cos(pi/2 x) for x in [0, 1).
fn quarter_turn(x: f32) -> vec2<f32> {
    let x2 = x * x;
    var s = QUARTER_SIN_6;
    s = s * x2 + QUARTER_SIN_5;
    s = s * x2 + QUARTER_SIN_4;
    s = s * x2 + QUARTER_SIN_3;
    s = s * x2 + QUARTER_SIN_2;
    s = s * x2 + QUARTER_SIN_1;
    s = s * x2 + QUARTER_SIN_0;
    var c = QUARTER_COS_7;
    c = c * x2 + QUARTER_COS_6;
    c = c * x2 + QUARTER_COS_5;
    c = c * x2 + QUARTER_COS_4;
    c = c * x2 + QUARTER_COS_3;
    c = c * x2 + QUARTER_COS_2;
    c = c * x2 + QUARTER_COS_1;
    c = c * x2 + QUARTER_COS_0;
    return vec2<f32>(x * s, c);
}

fn cosine_direction(n: vec3<f32>, u: vec2<f32>) -> vec3<f32> {
    let q4 = u.y * 4.0;
    let q = floor(q4);
    let sc = quarter_turn(q4 - q);
    var phi = vec2<f32>(sc.y, sc.x);
    if q >= 3.0 {
        phi = vec2<f32>(sc.x, -sc.y);
    } else if q >= 2.0 {
        phi = vec2<f32>(-sc.y, -sc.x);
    } else if q >= 1.0 {
        phi = vec2<f32>(-sc.x, sc.y);
    }
    let r = sqrt_rn(u.x);
    let z = sqrt_rn(1.0 - u.x);
    let a = r * phi.x;
    let b = r * phi.y;
    let sign = select(1.0, -1.0, n.z < 0.0);
    let k = div_rn(-1.0, sign + n.z);
    let m = n.x * n.y * k;
    let t1 = vec3<f32>(1.0 + sign * n.x * n.x * k, sign * m, -(sign * n.x));
    let t2 = vec3<f32>(m, sign + n.y * n.y * k, -n.y);
    return unit(t1 * a + t2 * b + n * z);
}
