// The stream pipeline of thesis code examples 4.2 and 4.3, one pixel per invocation: ray casting
// is a single trace-and-shade kernel; Whitted ray tracing traces the primary rays, shades once per
// light, then per indirection traces the secondary rays and shades again, and finally converts to
// 8 bits. The incoherent modes trace the primary rays, then cast their AO rays (any hit) or their
// diffuse bounce (closest hit) from every primary hit and shade, then convert. Each pass reads
// and writes per-pixel state (paths, hits, accum, aovs) in storage buffers.
//
// Every invocation of a workgroup calls `trace` exactly once per stage, with `active` false when
// its pixel lies outside the image or has nothing to trace: SST walks the tree with the whole
// workgroup and needs every invocation at its barriers.

// Index of image pixel (x, y) in the per-pixel buffers, which hold the current tile.
fn pixel_index(x: u32, y: u32) -> u32 {
    return (y - frame.tile.y) * frame.tile.z + (x - frame.tile.x);
}

fn record_primary(p: u32, r: Ray, h: HitRec) -> bool {
    // Later samples add their cost; the distance, normal and triangle are the first sample's.
    if frame.samples.x > 0u {
        aovs[p].nodes += cost_nodes;
        aovs[p].tris += cost_tris;
        return h.tri != NO_TRIANGLE;
    }
    var a: Aov;
    a.nodes = cost_nodes;
    a.tris = cost_tris;
    if h.tri == NO_TRIANGLE {
        a.t = bitcast<f32>(0x7f800000u);
        a.prim = NO_TRIANGLE;
        a.normal = vec4<f32>(0.0);
        aovs[p] = a;
        return false;
    }
    a.t = h.t;
    a.prim = input_index[h.tri];
    a.normal = vec4<f32>(surface_at(r, h).shading, 0.0);
    aovs[p] = a;
    return true;
}

// The pixel's colour over its samples so far, this one's colour c included: the CPU's sum in
// sample order (the first sample alone is c).
fn with_earlier_samples(p: u32, c: vec3<f32>) -> vec3<f32> {
    return select(accum[p].sum.xyz + c, c, frame.samples.x == 0u);
}

// The pixel's 8-bit colour from the sum of all its samples' colours: their mean, as the CPU
// computes it (times the host's f32 1 / spp), quantised once.
fn samples_to_rgba8(total: vec3<f32>) -> u32 {
    return to_rgba8(select(total, total * frame.sample.z, frame.samples.y > 1u));
}

// A tracing stage is three parts: `X_begin` reads the pixel's state and makes its ray (a `Query`
// and what the stage keeps until the hit is known, an `XJob`), `trace` finds the hit, `X_end`
// shades and writes. `stage_X` runs them in a row for one pixel; the persistent kernels
// (`persistent` below) run the begin and end parts of many pixels around the traversals' walks.
struct Query {
    r: Ray,
    t_min: f32,
    t_max: f32,
    any_hit: bool,
    enabled: bool,
}

fn trace_query(q: Query) -> HitRec {
    return trace(q.r, q.t_min, q.t_max, q.any_hit, q.enabled);
}

struct CastJob {
    q: Query,
    p: u32,
    valid: bool,
}

fn cast_begin(x: u32, y: u32, valid: bool) -> CastJob {
    let p = pixel_index(x, y);
//#if CAMERA_RAYS
    let r = make_ray(frame.eye.xyz, primary_dir(x, y));
//#endif
//#if RAY_LIST
    // The host's ray for this pixel (Renderer::cast_rays), in the paths buffer, which ray casting
    // does not use otherwise.
    let given = paths[select(0u, p, valid)];
    let r = make_ray(given.origin.xyz, given.dir.xyz);
//#endif
    return CastJob(Query(r, 0.0, F32_MAX, false, valid), p, valid);
}

fn cast_end(j: CastJob, h: HitRec) {
    if !j.valid {
        return;
    }
    let p = j.p;
    let r = j.q.r;
    count(SLOT_PRIMARY);
    var c = frame.background.xyz;
    if record_primary(p, r, h) {
        let s = surface_at(r, h);
        c = material_of(h.tri).kd_n.xyz * max(dot3(s.shading, -r.d), 0.0);
    }
    let total = with_earlier_samples(p, c);
    if frame.samples.x + 1u < frame.samples.y {
        accum[p].sum = vec4<f32>(total, 0.0);
    } else {
        image[p] = samples_to_rgba8(total);
    }
    count(SLOT_FINISHED);
}

fn stage_cast(x: u32, y: u32, valid: bool) {
    let j = cast_begin(x, y, valid);
    let h = trace_query(j.q);
//#if RT_EMIT
    return; // rt_pipeline.wgsl: this half only writes the ray
//#endif
    cast_end(j, h);
}

struct PrimaryJob {
    q: Query,
    p: u32,
    valid: bool,
}

fn primary_begin(x: u32, y: u32, valid: bool) -> PrimaryJob {
    let p = pixel_index(x, y);
    let r = make_ray(frame.eye.xyz, primary_dir(x, y));
    return PrimaryJob(Query(r, 0.0, F32_MAX, false, valid), p, valid);
}

fn primary_end(j: PrimaryJob, h: HitRec) {
    if !j.valid {
        return;
    }
    let p = j.p;
    let r = j.q.r;
    count(SLOT_PRIMARY);
    if frame.samples.x > 0u {
        // The previous sample is complete: its colour joins the sum before this one starts.
        accum[p].sum = vec4<f32>(select(accum[p].sum.xyz + accum[p].colour.xyz, accum[p].colour.xyz, frame.samples.x == 1u), 0.0);
    }
    hits[p] = h;
    let alive = record_primary(p, r, h);
    paths[p] = PathRay(vec4<f32>(r.o, 1.0), vec4<f32>(r.d, select(0.0, 1.0, alive)));
    accum[p].colour = select(vec4<f32>(frame.background.xyz, 0.0), vec4<f32>(0.0), alive);
    count(SLOT_FINISHED);
}

fn stage_primary(x: u32, y: u32, valid: bool) {
    let j = primary_begin(x, y, valid);
    let h = trace_query(j.q);
//#if RT_EMIT
    return; // rt_pipeline.wgsl: this half only writes the ray
//#endif
    primary_end(j, h);
}

// One light (pass_info.light) at the current hit of every live path; the first pass also adds the
// ambient term. The shadow ray is traced here.
struct ShadeJob {
    q: Query,
    p: u32,
    valid: bool,
    live: bool,
    // The path's weight (its origin's w), the hit's triangle, the light's colour and Phong term,
    // and what the pass adds without the light.
    weight: f32,
    tri: u32,
    colour: vec3<f32>,
    term: vec3<f32>,
    add: vec3<f32>,
}

fn shade_begin(x: u32, y: u32, valid: bool) -> ShadeJob {
    // Out-of-image invocations read pixel 0 and write nothing.
    let p = select(0u, pixel_index(x, y), valid);
    let path = paths[p];
    let live = valid && path.dir.w != 0.0;
    let r = make_ray(path.origin.xyz, path.dir.xyz);
    let h = hits[p];
    var add = vec3<f32>(0.0);
    var shadow = make_ray(vec3<f32>(0.0), vec3<f32>(0.0, 0.0, 1.0));
    var shadow_t = 0.0;
    var wants_shadow = false;
    var term = vec3<f32>(0.0);
    var colour = vec3<f32>(0.0);
    if live {
        let s = surface_at(r, h);
        let m = material_of(h.tri);
        if pass_info.light == 0u {
            add = frame.ambient.xyz * m.kd_n.xyz;
        } else {
            add = accum[p].local.xyz;
        }
        if pass_info.light < frame.size.z {
            let light = lights[pass_info.light];
            colour = light.colour.xyz;
            let l = normalize_or(light.position.xyz - s.point, vec3<f32>(0.0));
            term = phong(m, s, r.d, l);
            if any(term != vec3<f32>(0.0)) {
                let side = select(-s.geometric, s.geometric, dot3(s.geometric, l) >= 0.0);
                let o = leave(s.point, side);
                shadow = make_ray(o, l);
                shadow_t = length3(light.position.xyz - o);
                wants_shadow = true;
            }
        }
    }
    return ShadeJob(Query(shadow, 0.0, shadow_t, true, wants_shadow), p, valid, live, path.origin.w, h.tri, colour, term, add);
}

fn shade_end(j: ShadeJob, hit: HitRec) {
    let p = j.p;
    let blocked = hit.tri != NO_TRIANGLE;
    if j.valid {
        count(SLOT_FINISHED);
    }
    if !j.live {
        return;
    }
    var add = j.add;
    if j.q.enabled {
        count(SLOT_SHADOW);
//#if SELF_HITS
        if intersect(fetch_tri(j.tri), j.q.r, 0.0, j.q.t_max).x >= 0.0 {
            count(SLOT_SELF_SHADOW);
        }
//#endif
        if !blocked {
            add += j.colour * j.term;
        }
    }
    // The hit's local term is complete after the last light (one pass when there is none).
    if pass_info.light + 1u >= max(frame.size.z, 1u) {
        accum[p].colour += vec4<f32>(add * j.weight, 0.0);
    } else {
        accum[p].local = vec4<f32>(add, 0.0);
    }
    aovs[p].nodes += cost_nodes;
    aovs[p].tris += cost_tris;
}

fn stage_shade(x: u32, y: u32, valid: bool) {
    let j = shade_begin(x, y, valid);
    let h = trace_query(j.q);
//#if RT_EMIT
    return; // rt_pipeline.wgsl: this half only writes the ray
//#endif
    shade_end(j, h);
}

// The secondary ray of every live path whose material reflects or refracts (pass_info.depth rays
// already traced), if it can still change the pixel; its closest hit replaces the path's hit.
struct BounceJob {
    q: Query,
    p: u32,
    valid: bool,
    live: bool,
    // The bounce's weight and the hit's triangle.
    w: f32,
    tri: u32,
}

fn bounce_begin(x: u32, y: u32, valid: bool) -> BounceJob {
    let p = select(0u, pixel_index(x, y), valid);
    let path = paths[p];
    let live = valid && path.dir.w != 0.0;
    let r = make_ray(path.origin.xyz, path.dir.xyz);
    let h = hits[p];
    var dir = vec3<f32>(0.0, 0.0, 1.0);
    var o = vec3<f32>(0.0);
    var w = 0.0;
    var go = false;
    if live {
        let s = surface_at(r, h);
        let m = material_of(h.tri);
        var same_side = true;
        var factor = 0.0;
//#if REFLECTION
        if m.ks_kr.w > 0.0 {
            dir = reflect_dir(r.d, s.shading);
            factor = m.ks_kr.w;
        }
//#endif
//#if REFRACTION
        if m.kt_ior.x > 0.0 {
            let eta = select(m.kt_ior.y, div_rn(1.0, m.kt_ior.y), s.front);
            let refracted = refract_dir(r.d, s.shading, eta);
            if refracted.w != 0.0 {
                dir = refracted.xyz;
                same_side = false;
            } else {
                // Total internal reflection.
                dir = reflect_dir(r.d, s.shading);
            }
            factor = m.kt_ior.x;
        }
//#endif
        let remaining = frame.size.w - pass_info.depth;
        w = path.origin.w * factor;
        go = factor > 0.0 && remaining > 0u && worth_tracing(w, remaining);
        o = leave(s.point, select(-s.geometric, s.geometric, same_side));
    }
    return BounceJob(Query(make_ray(o, dir), 0.0, F32_MAX, false, go), p, valid, live, w, h.tri);
}

fn bounce_end(j: BounceJob, nh: HitRec) {
    let p = j.p;
    if j.valid {
        count(SLOT_FINISHED);
    }
    if !j.live {
        return;
    }
    if !j.q.enabled {
        paths[p].dir.w = 0.0;
        return;
    }
    count(SLOT_SECONDARY);
//#if SELF_HITS
    if intersect(fetch_tri(j.tri), j.q.r, 0.0, F32_MAX).x >= 0.0 {
        count(SLOT_SELF_SECONDARY);
    }
//#endif
    aovs[p].nodes += cost_nodes;
    aovs[p].tris += cost_tris;
    if nh.tri == NO_TRIANGLE {
        accum[p].colour += vec4<f32>(frame.background.xyz * j.w, 0.0);
        paths[p].dir.w = 0.0;
        return;
    }
    hits[p] = nh;
    paths[p] = PathRay(vec4<f32>(j.q.r.o, j.w), vec4<f32>(j.q.r.d, 1.0));
    // Paths still alive after this bounce: the host stops the passes once none is.
    atomicAdd(&counters[SLOT_LIVE + pass_info.depth], 1u);
}

fn stage_bounce(x: u32, y: u32, valid: bool) {
    let j = bounce_begin(x, y, valid);
    let h = trace_query(j.q);
//#if RT_EMIT
    return; // rt_pipeline.wgsl: this half only writes the ray
//#endif
    bounce_end(j, h);
}

// The image-wide index of pixel (x, y): the seed of its incoherent rays (render_spec::sequence),
// the same whichever tile holds it.
fn image_pixel(x: u32, y: u32) -> u32 {
    return y * frame.size.x + x;
}

// Where the incoherent rays of a live path's primary hit leave from, and the turned geometric
// normal they are distributed about.
struct Leaving {
    origin: vec3<f32>,
    normal: vec3<f32>,
    kd: vec3<f32>,
}

fn leaving(live: bool, p: u32) -> Leaving {
    var l = Leaving(vec3<f32>(0.0), vec3<f32>(0.0, 0.0, 1.0), vec3<f32>(0.0));
    if live {
        let path = paths[p];
        let h = hits[p];
        let s = surface_at(make_ray(path.origin.xyz, path.dir.xyz), h);
        l = Leaving(leave(s.point, s.geometric), s.geometric, material_of(h.tri).kd_n.xyz);
    }
    return l;
}

// Ambient occlusion (docs/shading.md): AO ray pass_info.depth of frame.samples.z, of length
// frame.ao.x, from every primary hit through the any-hit traversal; one pass per ray, the rays
// not blocked so far counted in accum.local.x (an f32 holds the count exactly). The last pass
// writes the fraction. (One pass per ray rather than a loop around `trace`: lavapipe dropped
// workgroups of the subgroup-voting SST whose any-hit walk ran inside a loop.)
struct AoJob {
    q: Query,
    p: u32,
    valid: bool,
}

fn ao_begin(x: u32, y: u32, valid: bool) -> AoJob {
    let p = select(0u, pixel_index(x, y), valid);
    let live = valid && paths[p].dir.w != 0.0;
    let start = leaving(live, p);
    let k = pass_info.depth;
    let u = sample_2d(image_pixel(x, y), incoherent_sample(frame.samples.x, frame.samples.z, k));
    let r = make_ray(start.origin, cosine_direction(start.normal, u));
    return AoJob(Query(r, 0.0, frame.ao.x, true, live), p, valid);
}

fn ao_end(j: AoJob, hit: HitRec) {
    let p = j.p;
    let k = pass_info.depth;
    let blocked = hit.tri != NO_TRIANGLE;
    if j.valid {
        count(SLOT_FINISHED);
    }
    // Live: the query is enabled.
    if !j.q.enabled {
        return;
    }
//#if SELF_HITS
    if intersect(fetch_tri(hits[p].tri), j.q.r, 0.0, frame.ao.x).x >= 0.0 {
        count(SLOT_SELF_AO);
    }
//#endif
    let open = select(accum[p].local.x, 0.0, k == 0u) + select(1.0, 0.0, blocked);
    accum[p].local.x = open;
    if k + 1u == frame.samples.z {
        count_n(SLOT_AO, frame.samples.z);
        accum[p].colour = vec4<f32>(vec3<f32>(open * frame.ao.y), 0.0);
    }
    aovs[p].nodes += cost_nodes;
    aovs[p].tris += cost_tris;
}

fn stage_ao(x: u32, y: u32, valid: bool) {
    let j = ao_begin(x, y, valid);
    let h = trace_query(j.q);
//#if RT_EMIT
    return; // rt_pipeline.wgsl: this half only writes the ray
//#endif
    ao_end(j, h);
}

// The diffuse bounce (docs/shading.md): one ray from every primary hit through the closest-hit
// traversal; the colour is the primary hit's kd times the bounce hit lit by a white light at the
// bounce's origin, or times the background.
struct DiffuseJob {
    q: Query,
    p: u32,
    valid: bool,
    kd: vec3<f32>,
}

fn diffuse_begin(x: u32, y: u32, valid: bool) -> DiffuseJob {
    let p = select(0u, pixel_index(x, y), valid);
    let live = valid && paths[p].dir.w != 0.0;
    let start = leaving(live, p);
    let u = sample_2d(image_pixel(x, y), frame.samples.x);
    let r = make_ray(start.origin, cosine_direction(start.normal, u));
    return DiffuseJob(Query(r, 0.0, F32_MAX, false, live), p, valid, start.kd);
}

fn diffuse_end(j: DiffuseJob, h: HitRec) {
    let p = j.p;
    let r = j.q.r;
    if j.valid {
        count(SLOT_FINISHED);
    }
    // Live: the query is enabled.
    if !j.q.enabled {
        return;
    }
    count(SLOT_DIFFUSE);
//#if SELF_HITS
    if intersect(fetch_tri(hits[p].tri), r, 0.0, F32_MAX).x >= 0.0 {
        count(SLOT_SELF_DIFFUSE);
    }
//#endif
    var light = frame.background.xyz;
    if h.tri != NO_TRIANGLE {
        let s = surface_at(r, h);
        light = material_of(h.tri).kd_n.xyz * max(dot3(s.shading, -r.d), 0.0);
    }
    accum[p].colour = vec4<f32>(j.kd * light, 0.0);
    aovs[p].nodes += cost_nodes;
    aovs[p].tris += cost_tris;
}

fn stage_diffuse(x: u32, y: u32, valid: bool) {
    let j = diffuse_begin(x, y, valid);
    let h = trace_query(j.q);
//#if RT_EMIT
    return; // rt_pipeline.wgsl: this half only writes the ray
//#endif
    diffuse_end(j, h);
}

fn stage_convert(x: u32, y: u32, valid: bool) {
    if !valid {
        return;
    }
    let p = pixel_index(x, y);
    image[p] = samples_to_rgba8(with_earlier_samples(p, accum[p].colour.xyz));
    count(SLOT_FINISHED);
}

//#if PERSISTENT
// Persistent threads (Aila and Laine, "Understanding the efficiency of ray traversal on GPUs",
// HPG 2009): the host launches only as many workgroups as the device holds at once, and each
// subgroup takes its pixels from a counter (the pass's `work` word) until none is left, so the
// dispatch ends with the device full instead of with its last, half-empty waves. The lanes walk
// their rays one node per step (the traversal's `walk_step`); once enough of a subgroup's lanes
// (a quarter by default) have finished theirs, those shade their pixels together and take new ones
// ("while-while" with replacement), so a few long rays do not hold the others' lanes idle.
//
// A subgroup takes at most `pass_info.cap` pixels per lane where that is not 0 (the host then
// launches enough invocations for all): lavapipe ends every loop of an invocation silently once
// they have run 65535 iterations together (gallivm's LP_MAX_TGSI_LOOP_ITERATIONS), which a
// subgroup walking thousands of rays passes.
//
// Items number the pixels as the plain dispatch orders its invocations: workgroup-sized blocks
// of the tile in row order, each block's pixels in its invocations' order. A subgroup's lanes take
// consecutive items, so they trace neighbouring pixels, as the plain kernel's do. The work done
// for a pixel is exactly the plain kernel's (the same begin, walk and end), so are the images.
fn persistent() {
    let blocks_x = (frame.tile.z + WG_X - 1u) / WG_X;
    let items = blocks_x * ((frame.tile.w + WG_Y - 1u) / WG_Y) * WG_X * WG_Y;
    // The subgroup's lanes (fewer than its size in a workgroup smaller than a subgroup); refill
    // once REFILL_IDLE of every 32 are idle (the host's `--persistent-refill`, by default 8).
    let lanes = subgroupAdd(1u);
    let refill = max(lanes * REFILL_IDLE / 32u, 1u);
    var job: StageJob;
    var walk: Walk;
    // `busy`: the lane holds a pixel (walking, or walked and waiting to shade it); `walking`: its
    // walk goes on. `exhausted` is the subgroup's: every item is taken, or it took its cap.
    var busy = false;
    var walking = false;
    var exhausted = false;
    var taken = 0u;
    loop {
        if busy && !walking {
            stage_end(job, walk.best);
            busy = false;
        }
        if !exhausted {
            let want = select(0u, 1u, !busy);
            let n = subgroupAdd(want);
            let rank = subgroupExclusiveAdd(want);
            var base = 0u;
            if subgroupExclusiveAdd(1u) == 0u {
                base = atomicAdd(&counters[pass_info.work], n);
            }
            base = subgroupBroadcastFirst(base);
            taken += n;
            exhausted = base + n >= items || (pass_info.cap != 0u && taken >= pass_info.cap * lanes);
            let item = base + rank;
            if !busy && item < items {
                let block = item / (WG_X * WG_Y);
                let li = item % (WG_X * WG_Y);
                let x = frame.tile.x + (block % blocks_x) * WG_X + li % WG_X;
                let y = frame.tile.y + (block / blocks_x) * WG_Y + li / WG_X;
                job = stage_begin(x, y, x < frame.tile.x + frame.tile.z && y < frame.tile.y + frame.tile.w);
                cost_nodes = 0u;
                cost_tris = 0u;
                walking = walk_begin(&walk, job.q.r, job.q.t_min, job.q.t_max, job.q.any_hit, job.q.enabled);
                busy = true;
            }
        }
        if subgroupAll(!busy) {
            break;
        }
        // With nothing left to take, the lanes walk until all are done. (Counted by the lanes
        // still walking, so that a device that ran part of a subgroup apart would still leave
        // the loop once that part is done.)
        loop {
            if walking {
                walking = walk_step(&walk);
            }
            let working = subgroupAdd(select(0u, 1u, walking));
            if working == 0u || (!exhausted && working + refill <= lanes) {
                break;
            }
        }
    }
}
//#endif
