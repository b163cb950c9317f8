// rt-pipeline: the vendor's traversal (VK_KHR_ray_tracing_pipeline, tracer-vk/src/rt) in place of
// ours, with the shading of stages.wgsl unchanged. A compute kernel cannot call into a ray-tracing
// pipeline, so every stage that traces runs as two kernels around one vkCmdTraceRaysKHR:
//
// - RT_EMIT: the stage up to its trace() call, which writes the pixel's ray record (rt_rays) and
//   returns; the stage returns right after it (the `//#if RT_EMIT` lines of stages.wgsl), so this
//   half writes nothing else and counts nothing;
// - the ray-generation stage (rt/spirv.rs) traces each record and writes the pixel's hit record
//   (rt_hits);
// - RT_COLLECT: the whole stage again, whose trace() returns the pixel's hit record instead of
//   walking a tree. Everything before the call is recomputed from the same inputs, so the ray is
//   the one the first half wrote.
//
// - RT_STAND_IN (tests only): LST in place of the driver, one kernel between the two halves.
//
// One trace() per stage and pixel, as in every stage of stages.wgsl. The cost AOVs (nodes, triangles)
// stay 0: the driver's traversal does not tell.

// A ray record (rt::spirv::RAY_BYTES): origin and t_min, direction and t_max, flags.
struct RtRay {
    origin: vec3<f32>,
    t_min: f32,
    dir: vec3<f32>,
    t_max: f32,
    // RT_FLAG_* in x; y, z, w unused.
    flags: vec4<u32>,
}

@group(0) @binding(14) var<storage, read_write> rt_rays: array<RtRay>;
@group(0) @binding(15) var<storage, read_write> rt_hits: array<HitRec>;

// rt::spirv::FLAG_TRACE and FLAG_ANY_HIT.
const RT_FLAG_TRACE: u32 = 1u;
const RT_FLAG_ANY_HIT: u32 = 2u;
const RT_NO_SLOT: u32 = 0xffffffffu;

// The record of this invocation's pixel, RT_NO_SLOT outside the tile (set by the entry point).
var<private> rt_slot: u32;

//#if RT_EMIT
fn trace(r: Ray, t_min: f32, t_max: f32, any_hit: bool, enabled: bool) -> HitRec {
    if rt_slot != RT_NO_SLOT {
        // Our tests take t > t_min, Vulkan's t >= t_min: the record's t_min is the next float up.
        // t_max is taken as it is on both sides (t <= t_max).
        let flags = select(0u, RT_FLAG_TRACE, enabled) | select(0u, RT_FLAG_ANY_HIT, any_hit);
        let t_above = bitcast<f32>(bitcast<u32>(max(t_min, 0.0)) + 1u);
        rt_rays[rt_slot] = RtRay(r.o, t_above, r.d, t_max, vec4<u32>(flags, 0u, 0u, 0u));
    }
    return HitRec(t_max, NO_TRIANGLE, 0.0, 0.0);
}
//#endif

//#if RT_COLLECT
fn trace(r: Ray, t_min: f32, t_max: f32, any_hit: bool, enabled: bool) -> HitRec {
    if !enabled {
        return HitRec(t_max, NO_TRIANGLE, 0.0, 0.0);
    }
    return rt_hits[rt_slot];
}
//#endif

//#if RT_STAND_IN
// The driver's traversal as LST does it (the LST file is part of this kernel), for testing the
// split stages on a device without ray tracing (Renderer::rt_stand_in): one invocation per ray
// record, with the records' Vulkan semantics (t_min inclusive, an occlusion record that only says
// whether something blocks) and the cost AOVs of the driver (none).
fn stand_in(slot: u32) {
    let q = rt_rays[slot];
    if (q.flags.x & RT_FLAG_TRACE) == 0u {
        return;
    }
    let any_hit = (q.flags.x & RT_FLAG_ANY_HIT) != 0u;
    let t_min = bitcast<f32>(bitcast<u32>(q.t_min) - 1u);
    var h = HitRec(q.t_max, NO_TRIANGLE, 0.0, 0.0);
    if q.t_min <= q.t_max {
        h = trace(make_ray(q.origin, q.dir), t_min, q.t_max, any_hit, true);
    }
    if any_hit && h.tri != NO_TRIANGLE {
        h = HitRec(q.t_max, 0u, 0.0, 0.0);
    }
    rt_hits[slot] = h;
}
//#endif
