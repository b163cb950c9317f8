//! The ray-tracing stages of `--method rt-pipeline`, written as SPIR-V with rspirv: naga writes
//! no ray-generation, miss or hit stages. They do nothing but the vendor's traversal:
//!
//! - ray generation: reads the pixel's ray record ([`RAY_BYTES`], written by the WGSL stage
//!   kernel's first half, `rt_pipeline.wgsl`), traces it against the top-level structure and writes
//!   the pixel's hit record ([`HIT_BYTES`], the `HitRec` of common.wgsl) for the kernel's second half;
//! - closest hit: the hit record from the primitive index (the triangle's index in the file, which
//!   is the index the kernels read `tris` with), the hit distance and the barycentrics;
//! - miss: the record's triangle becomes `NO_TRIANGLE`.
//!
//! An occlusion ray (the shadow rays, [`FLAG_ANY_HIT`]) is traced with TerminateOnFirstHit and
//! SkipClosestHitShader: its record only says whether something blocks it (triangle 0 and t the
//! ray's t_max when blocked, `NO_TRIANGLE` when not), which is all the stage kernels read of it.

use rspirv::binary::Assemble;
use rspirv::dr::{Builder, Operand};
use rspirv::spirv::{
    AddressingModel, BuiltIn, Capability, Decoration, ExecutionModel, FunctionControl, MemoryModel, RayFlags,
    SelectionControl, StorageClass, Word,
};

use crate::error::VkError;

/// Bytes of a ray record: origin and t_min, direction and t_max, then the flags and three unused
/// words (`RtRay` in rt_pipeline.wgsl; a test holds the two to one layout).
pub const RAY_BYTES: u32 = 48;
/// Bytes of a hit record: t, triangle, u, v (`HitRec` in common.wgsl).
pub const HIT_BYTES: u32 = 16;
/// The record holds a ray to trace; without it the pixel traces nothing in this pass.
pub const FLAG_TRACE: u32 = 1;
/// Any hit answers the ray (an occlusion ray); else the closest one does.
pub const FLAG_ANY_HIT: u32 = 2;

/// Descriptor bindings of the ray-tracing pipeline (set 0).
pub const BINDING_TLAS: u32 = 0;
pub const BINDING_RAYS: u32 = 1;
pub const BINDING_HITS: u32 = 2;

/// The three stages, each its own module with entry point `main`.
#[derive(Clone, Debug)]
pub struct Stages {
    pub ray_gen: Vec<u32>,
    pub miss: Vec<u32>,
    pub closest_hit: Vec<u32>,
}

/// Writes the three modules.
pub fn stages() -> Result<Stages, VkError> {
    let fail = |e: rspirv::dr::Error| VkError::Shader {
        label: "rt-pipeline stages".into(),
        message: format!("error: rspirv could not build the module: {e}"),
    };
    Ok(Stages {
        ray_gen: ray_gen().map_err(fail)?,
        miss: miss().map_err(fail)?,
        closest_hit: closest_hit().map_err(fail)?,
    })
}

type Built = Result<Vec<u32>, rspirv::dr::Error>;

/// The types every module shares.
struct Common {
    void: Word,
    fn_void: Word,
    uint: Word,
    float: Word,
    /// The hit record as the payload (no explicit layout: the payload lives in the driver's memory).
    payload: Word,
}

/// SPIR-V 1.4 (Vulkan 1.2's), the ray-tracing capability, and the payload type.
fn begin() -> (Builder, Common) {
    let mut b = Builder::new();
    b.set_version(1, 4);
    b.capability(Capability::Shader);
    b.capability(Capability::RayTracingKHR);
    b.extension("SPV_KHR_ray_tracing");
    b.memory_model(AddressingModel::Logical, MemoryModel::GLSL450);
    let void = b.type_void();
    let fn_void = b.type_function(void, vec![]);
    let uint = b.type_int(32, 0);
    let float = b.type_float(32, None);
    // An id of its own: the buffer's HitRec has the same members but an explicit layout, and
    // rspirv would otherwise hand back that one type for both.
    let payload_id = b.id();
    let payload = b.type_struct_id(Some(payload_id), [float, uint, float, float]);
    b.name(payload, "Payload");
    (b, Common { void, fn_void, uint, float, payload })
}

fn ray_gen() -> Built {
    let (mut b, c) = begin();
    let Common { void, fn_void, uint, float, payload: payload_ty } = c;
    let bool_ty = b.type_bool();
    let v3u = b.type_vector(uint, 3);
    let v3f = b.type_vector(float, 3);
    let v4f = b.type_vector(float, 4);
    let v4u = b.type_vector(uint, 4);
    let accel = b.type_acceleration_structure_khr();

    // struct RtRay { vec4 origin_tmin; vec4 dir_tmax; uvec4 flags; } in a read-only buffer.
    let ray_id = b.id();
    let ray = b.type_struct_id(Some(ray_id), [v4f, v4f, v4u]);
    for (m, offset) in [(0, 0u32), (1, 16), (2, 32)] {
        b.member_decorate(ray, m, Decoration::Offset, [Operand::LiteralBit32(offset)]);
    }
    let rays_arr = b.type_runtime_array(ray);
    b.decorate(rays_arr, Decoration::ArrayStride, [Operand::LiteralBit32(RAY_BYTES)]);
    let rays_block = b.type_struct([rays_arr]);
    b.decorate(rays_block, Decoration::Block, []);
    b.member_decorate(rays_block, 0, Decoration::Offset, [Operand::LiteralBit32(0)]);
    b.member_decorate(rays_block, 0, Decoration::NonWritable, []);

    // struct HitRec { float t; uint tri; float u; float v; } in a write-only buffer.
    let hit_id = b.id();
    let hit = b.type_struct_id(Some(hit_id), [float, uint, float, float]);
    for (m, offset) in [(0, 0u32), (1, 4), (2, 8), (3, 12)] {
        b.member_decorate(hit, m, Decoration::Offset, [Operand::LiteralBit32(offset)]);
    }
    let hits_arr = b.type_runtime_array(hit);
    b.decorate(hits_arr, Decoration::ArrayStride, [Operand::LiteralBit32(HIT_BYTES)]);
    let hits_block_id = b.id();
    let hits_block = b.type_struct_id(Some(hits_block_id), [hits_arr]);
    b.decorate(hits_block, Decoration::Block, []);
    b.member_decorate(hits_block, 0, Decoration::Offset, [Operand::LiteralBit32(0)]);
    b.member_decorate(hits_block, 0, Decoration::NonReadable, []);

    let p_in_v3u = b.type_pointer(None, StorageClass::Input, v3u);
    let p_accel = b.type_pointer(None, StorageClass::UniformConstant, accel);
    let p_rays = b.type_pointer(None, StorageClass::StorageBuffer, rays_block);
    let p_hits = b.type_pointer(None, StorageClass::StorageBuffer, hits_block);
    let p_payload = b.type_pointer(None, StorageClass::RayPayloadKHR, payload_ty);
    let p_sb_v4f = b.type_pointer(None, StorageClass::StorageBuffer, v4f);
    let p_sb_v4u = b.type_pointer(None, StorageClass::StorageBuffer, v4u);
    let p_sb_float = b.type_pointer(None, StorageClass::StorageBuffer, float);
    let p_sb_uint = b.type_pointer(None, StorageClass::StorageBuffer, uint);

    let launch_id = b.variable(p_in_v3u, None, StorageClass::Input, None);
    b.decorate(launch_id, Decoration::BuiltIn, [Operand::BuiltIn(BuiltIn::LaunchIdKHR)]);
    let launch_size = b.variable(p_in_v3u, None, StorageClass::Input, None);
    b.decorate(launch_size, Decoration::BuiltIn, [Operand::BuiltIn(BuiltIn::LaunchSizeKHR)]);
    let tlas = b.variable(p_accel, None, StorageClass::UniformConstant, None);
    let rays = b.variable(p_rays, None, StorageClass::StorageBuffer, None);
    let hits = b.variable(p_hits, None, StorageClass::StorageBuffer, None);
    for (var, binding, name) in
        [(tlas, BINDING_TLAS, "tlas"), (rays, BINDING_RAYS, "rays"), (hits, BINDING_HITS, "hits")]
    {
        b.decorate(var, Decoration::DescriptorSet, [Operand::LiteralBit32(0)]);
        b.decorate(var, Decoration::Binding, [Operand::LiteralBit32(binding)]);
        b.name(var, name);
    }
    let payload = b.variable(p_payload, None, StorageClass::RayPayloadKHR, None);

    let u = |b: &mut Builder, v: u32| b.constant_bit32(uint, v);
    let (u0, u1, u2, u3) = (u(&mut b, 0), u(&mut b, 1), u(&mut b, 2), u(&mut b, 3));
    let no_triangle = u(&mut b, render_spec::NO_TRIANGLE);
    let cull_all = u(&mut b, 0xff);
    let flag_trace = u(&mut b, FLAG_TRACE);
    let flag_any = u(&mut b, FLAG_ANY_HIT);
    // Culling is off (no cull flag) and every triangle is opaque (the geometry's OPAQUE flag, and
    // the ray flag again), as our two-sided triangle test.
    let closest_flags = u(&mut b, RayFlags::OPAQUE_KHR.bits());
    let any_flags = u(
        &mut b,
        (RayFlags::OPAQUE_KHR | RayFlags::TERMINATE_ON_FIRST_HIT_KHR | RayFlags::SKIP_CLOSEST_HIT_SHADER_KHR).bits(),
    );
    let f0 = b.constant_bit32(float, 0f32.to_bits());

    let main = b.begin_function(void, None, FunctionControl::NONE, fn_void)?;
    b.name(main, "main");
    b.begin_block(None)?;
    // The launch is the tile (width x height) and the records are its pixels row by row.
    let id = b.load(v3u, None, launch_id, None, [])?;
    let size = b.load(v3u, None, launch_size, None, [])?;
    let x = b.composite_extract(uint, None, id, [0])?;
    let y = b.composite_extract(uint, None, id, [1])?;
    let width = b.composite_extract(uint, None, size, [0])?;
    let row = b.i_mul(uint, None, y, width)?;
    let index = b.i_add(uint, None, row, x)?;
    let at = b.access_chain(p_sb_v4f, None, rays, [u0, index, u0])?;
    let origin_tmin = b.load(v4f, None, at, None, [])?;
    let at = b.access_chain(p_sb_v4f, None, rays, [u0, index, u1])?;
    let dir_tmax = b.load(v4f, None, at, None, [])?;
    let at = b.access_chain(p_sb_v4u, None, rays, [u0, index, u2])?;
    let flag_words = b.load(v4u, None, at, None, [])?;
    let flags = b.composite_extract(uint, None, flag_words, [0])?;
    let trace_bit = b.bitwise_and(uint, None, flags, flag_trace)?;
    let wanted = b.i_not_equal(bool_ty, None, trace_bit, u0)?;
    let (trace_block, done) = (b.id(), b.id());
    b.selection_merge(done, SelectionControl::NONE)?;
    b.branch_conditional(wanted, trace_block, done, [])?;

    b.begin_block(Some(trace_block))?;
    let origin = b.vector_shuffle(v3f, None, origin_tmin, origin_tmin, [0, 1, 2])?;
    let t_min = b.composite_extract(float, None, origin_tmin, [3])?;
    let dir = b.vector_shuffle(v3f, None, dir_tmax, dir_tmax, [0, 1, 2])?;
    let t_max = b.composite_extract(float, None, dir_tmax, [3])?;
    let any_bit = b.bitwise_and(uint, None, flags, flag_any)?;
    let any_hit = b.i_not_equal(bool_ty, None, any_bit, u0)?;
    // Vulkan leaves a ray with t_max < t_min undefined; our traversals find nothing on it.
    let ordered = b.f_ord_less_than_equal(bool_ty, None, t_min, t_max)?;
    let blocked_unless_missed = b.logical_and(bool_ty, None, any_hit, ordered)?;
    // An occlusion ray starts out blocked (triangle 0) and the miss stage clears it; a closest-hit
    // ray starts out missed and the hit stage fills it in.
    let first_tri = b.select(uint, None, blocked_unless_missed, u0, no_triangle)?;
    let start = b.composite_construct(payload_ty, None, [t_max, first_tri, f0, f0])?;
    b.store(payload, start, None, [])?;
    let ray_flags = b.select(uint, None, any_hit, any_flags, closest_flags)?;
    let (cast_block, write_block) = (b.id(), b.id());
    b.selection_merge(write_block, SelectionControl::NONE)?;
    b.branch_conditional(ordered, cast_block, write_block, [])?;

    b.begin_block(Some(cast_block))?;
    let accel_value = b.load(accel, None, tlas, None, [])?;
    // SBT offset and stride 0: one hit group; miss index 0: one miss stage.
    b.trace_ray_khr(accel_value, ray_flags, cull_all, u0, u0, u0, origin, t_min, dir, t_max, payload)?;
    b.branch(write_block)?;

    b.begin_block(Some(write_block))?;
    let result = b.load(payload_ty, None, payload, None, [])?;
    for (member, ty, ptr) in
        [(0u32, float, p_sb_float), (1, uint, p_sb_uint), (2, float, p_sb_float), (3, float, p_sb_float)]
    {
        let value = b.composite_extract(ty, None, result, [member])?;
        let m = [u0, u1, u2, u3][member as usize];
        let at = b.access_chain(ptr, None, hits, [u0, index, m])?;
        b.store(at, value, None, [])?;
    }
    b.branch(done)?;

    b.begin_block(Some(done))?;
    b.ret()?;
    b.end_function()?;
    // SPIR-V 1.4: the interface names every global the entry point uses.
    b.entry_point(ExecutionModel::RayGenerationKHR, main, "main", [launch_id, launch_size, tlas, rays, hits, payload]);
    Ok(b.module().assemble())
}

fn closest_hit() -> Built {
    let (mut b, c) = begin();
    let Common { void, fn_void, uint, float, payload: payload_ty } = c;
    let v2f = b.type_vector(float, 2);
    let p_payload = b.type_pointer(None, StorageClass::IncomingRayPayloadKHR, payload_ty);
    let p_attr = b.type_pointer(None, StorageClass::HitAttributeKHR, v2f);
    let p_in_uint = b.type_pointer(None, StorageClass::Input, uint);
    let p_in_float = b.type_pointer(None, StorageClass::Input, float);
    let payload = b.variable(p_payload, None, StorageClass::IncomingRayPayloadKHR, None);
    // Built-in triangles: the weights of the second and third vertex, as HitRec's u and v.
    let barycentrics = b.variable(p_attr, None, StorageClass::HitAttributeKHR, None);
    let primitive = b.variable(p_in_uint, None, StorageClass::Input, None);
    b.decorate(primitive, Decoration::BuiltIn, [Operand::BuiltIn(BuiltIn::PrimitiveId)]);
    // In a closest-hit stage, t_max is the hit's distance.
    let t = b.variable(p_in_float, None, StorageClass::Input, None);
    b.decorate(t, Decoration::BuiltIn, [Operand::BuiltIn(BuiltIn::RayTmaxKHR)]);

    let main = b.begin_function(void, None, FunctionControl::NONE, fn_void)?;
    b.name(main, "main");
    b.begin_block(None)?;
    let tri = b.load(uint, None, primitive, None, [])?;
    let t_hit = b.load(float, None, t, None, [])?;
    let uv = b.load(v2f, None, barycentrics, None, [])?;
    let u = b.composite_extract(float, None, uv, [0])?;
    let v = b.composite_extract(float, None, uv, [1])?;
    let record = b.composite_construct(payload_ty, None, [t_hit, tri, u, v])?;
    b.store(payload, record, None, [])?;
    b.ret()?;
    b.end_function()?;
    b.entry_point(ExecutionModel::ClosestHitKHR, main, "main", [payload, barycentrics, primitive, t]);
    Ok(b.module().assemble())
}

fn miss() -> Built {
    let (mut b, c) = begin();
    let Common { void, fn_void, uint, payload: payload_ty, .. } = c;
    let p_payload = b.type_pointer(None, StorageClass::IncomingRayPayloadKHR, payload_ty);
    let p_tri = b.type_pointer(None, StorageClass::IncomingRayPayloadKHR, uint);
    let payload = b.variable(p_payload, None, StorageClass::IncomingRayPayloadKHR, None);
    let one = b.constant_bit32(uint, 1);
    let no_triangle = b.constant_bit32(uint, render_spec::NO_TRIANGLE);
    let main = b.begin_function(void, None, FunctionControl::NONE, fn_void)?;
    b.name(main, "main");
    b.begin_block(None)?;
    let tri = b.access_chain(p_tri, None, payload, [one])?;
    b.store(tri, no_triangle, None, [])?;
    b.ret()?;
    b.end_function()?;
    b.entry_point(ExecutionModel::MissKHR, main, "main", [payload]);
    Ok(b.module().assemble())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::{self, Half, Method, Specialisation, Stage};
    use rspirv::dr::{Instruction, Module};
    use rspirv::spirv::Op;

    fn load(words: &[u32]) -> Module {
        rspirv::dr::load_words(words).expect("the module parses")
    }

    fn constant(m: &Module, id: Word) -> u32 {
        let c = m.types_global_values.iter().find(|i| i.result_id == Some(id)).expect("a global");
        assert_eq!(c.class.opcode, Op::Constant, "{c:?}");
        match c.operands[0] {
            Operand::LiteralBit32(v) => v,
            ref o => panic!("{o:?}"),
        }
    }

    fn id(op: &Operand) -> Word {
        op.id_ref_any().expect("an id")
    }

    fn instructions(m: &Module) -> impl Iterator<Item = &Instruction> {
        m.functions.iter().flat_map(|f| f.blocks.iter()).flat_map(|b| b.instructions.iter())
    }

    fn decorations(m: &Module, target: Word) -> Vec<(Decoration, Vec<Operand>)> {
        m.annotations
            .iter()
            .filter(|a| a.class.opcode == Op::Decorate && a.operands[0] == Operand::IdRef(target))
            .map(|a| match a.operands[1] {
                Operand::Decoration(d) => (d, a.operands[2..].to_vec()),
                ref o => panic!("{o:?}"),
            })
            .collect()
    }

    fn builtin(m: &Module, var: Word) -> Option<BuiltIn> {
        decorations(m, var).into_iter().find_map(|(d, ops)| match (d, ops.first()) {
            (Decoration::BuiltIn, Some(Operand::BuiltIn(b))) => Some(*b),
            _ => None,
        })
    }

    /// (offsets, array stride) of the struct in the runtime array bound at `binding`.
    fn buffer_layout(m: &Module, binding: u32) -> (Vec<u32>, u32) {
        let var = m
            .types_global_values
            .iter()
            .filter(|i| i.class.opcode == Op::Variable)
            .find(|v| {
                decorations(m, v.result_id.unwrap())
                    .iter()
                    .any(|(d, ops)| *d == Decoration::Binding && ops == &[Operand::LiteralBit32(binding)])
            })
            .expect("a variable at the binding");
        let def = |id: Word| m.types_global_values.iter().find(|i| i.result_id == Some(id)).unwrap();
        let pointer = def(var.result_type.unwrap());
        let block = def(id(&pointer.operands[1]));
        let array = def(id(&block.operands[0]));
        let element = id(&array.operands[0]);
        let stride = decorations(m, array.result_id.unwrap())
            .into_iter()
            .find_map(|(d, ops)| (d == Decoration::ArrayStride).then(|| ops[0].unwrap_literal_bit32()))
            .expect("an array stride");
        let mut offsets: Vec<(u32, u32)> = m
            .annotations
            .iter()
            .filter(|a| a.class.opcode == Op::MemberDecorate && a.operands[0] == Operand::IdRef(element))
            .filter(|a| a.operands[2] == Operand::Decoration(Decoration::Offset))
            .map(|a| (a.operands[1].unwrap_literal_bit32(), a.operands[3].unwrap_literal_bit32()))
            .collect();
        offsets.sort();
        (offsets.into_iter().map(|(_, o)| o).collect(), stride)
    }

    /// (field offsets, stride) of a WGSL struct as naga lays out the rt-pipeline kernels.
    fn wgsl_layout(name: &str) -> (Vec<u32>, u32) {
        let spec = Specialisation { stack_size: 1, leaf_size: 1, ..Specialisation::every_feature(Method::RtPipeline) };
        let m = naga::front::wgsl::parse_str(&kernels::source_half(Stage::Shade, &spec, Half::Emit)).unwrap();
        let mut l = naga::proc::Layouter::default();
        l.update(m.to_ctx()).unwrap();
        let (h, ty) = m.types.iter().find(|(_, t)| t.name.as_deref() == Some(name)).unwrap();
        let naga::TypeInner::Struct { members, .. } = &ty.inner else { panic!("{name}") };
        (members.iter().map(|f| f.offset).collect(), l[h].to_stride())
    }

    #[test]
    fn the_stages_are_the_three_entry_points_of_spirv_1_4_ray_tracing() {
        let s = stages().unwrap();
        for (words, model) in [
            (&s.ray_gen, ExecutionModel::RayGenerationKHR),
            (&s.miss, ExecutionModel::MissKHR),
            (&s.closest_hit, ExecutionModel::ClosestHitKHR),
        ] {
            let m = load(words);
            assert_eq!(m.header.as_ref().unwrap().version(), (1, 4));
            let caps: Vec<_> = m.capabilities.iter().map(|c| c.operands[0].clone()).collect();
            assert!(caps.contains(&Operand::Capability(Capability::RayTracingKHR)), "{model:?}");
            assert_eq!(m.entry_points.len(), 1);
            let e = &m.entry_points[0];
            assert_eq!(e.operands[0], Operand::ExecutionModel(model));
            assert_eq!(e.operands[2], Operand::LiteralString("main".into()));
            // SPIR-V 1.4: every global the stage touches is in its interface.
            let interface: Vec<Word> = e.operands[3..].iter().map(id).collect();
            for v in m.types_global_values.iter().filter(|i| i.class.opcode == Op::Variable) {
                assert!(interface.contains(&v.result_id.unwrap()), "{model:?}: {v:?} is not in the interface");
            }
        }
    }

    /// The records the ray-generation stage reads and writes have exactly the layout the WGSL
    /// kernels write and read them with, as naga lays those out.
    #[test]
    fn the_records_have_the_kernels_layout() {
        let m = load(&stages().unwrap().ray_gen);
        let (ray_offsets, ray_stride) = buffer_layout(&m, BINDING_RAYS);
        let (wgsl_offsets, wgsl_stride) = wgsl_layout("RtRay");
        assert_eq!(ray_stride, RAY_BYTES);
        assert_eq!(wgsl_stride, RAY_BYTES, "RtRay in rt_pipeline.wgsl");
        // The SPIR-V reads (origin, t_min), (dir, t_max) and the flags as three 16-byte vectors.
        assert_eq!(ray_offsets, [0, 16, 32]);
        assert_eq!(wgsl_offsets, [0, 12, 16, 28, 32], "origin, t_min, dir, t_max, flags");
        let (hit_offsets, hit_stride) = buffer_layout(&m, BINDING_HITS);
        let (wgsl_offsets, wgsl_stride) = wgsl_layout("HitRec");
        assert_eq!((hit_offsets, hit_stride), (wgsl_offsets, wgsl_stride));
        assert_eq!(hit_stride, HIT_BYTES);
    }

    /// One trace, opaque with culling off; occlusion rays stop at the first hit and skip the
    /// closest-hit stage; one hit group and one miss stage.
    #[test]
    fn the_ray_generation_stage_traces_as_our_traversals_do() {
        let m = load(&stages().unwrap().ray_gen);
        let traces: Vec<_> = instructions(&m).filter(|i| i.class.opcode == Op::TraceRayKHR).collect();
        assert_eq!(traces.len(), 1);
        let ops = &traces[0].operands;
        assert_eq!(constant(&m, id(&ops[2])), 0xff, "cull mask");
        for (k, what) in [(3, "SBT offset"), (4, "SBT stride"), (5, "miss index")] {
            assert_eq!(constant(&m, id(&ops[k])), 0, "{what}");
        }
        let select = instructions(&m).find(|i| i.result_id == Some(id(&ops[1]))).expect("the flags");
        assert_eq!(select.class.opcode, Op::Select);
        let any = RayFlags::from_bits(constant(&m, id(&select.operands[1]))).unwrap();
        let closest = RayFlags::from_bits(constant(&m, id(&select.operands[2]))).unwrap();
        assert_eq!(closest, RayFlags::OPAQUE_KHR);
        assert_eq!(
            any,
            RayFlags::OPAQUE_KHR | RayFlags::TERMINATE_ON_FIRST_HIT_KHR | RayFlags::SKIP_CLOSEST_HIT_SHADER_KHR
        );
        // The payload is the ray-payload variable; t_min and t_max are the record's.
        let payload = m.types_global_values.iter().find(|i| i.result_id == Some(id(&ops[10]))).unwrap();
        assert_eq!(payload.operands[0], Operand::StorageClass(StorageClass::RayPayloadKHR));
        let extract = |k: usize| instructions(&m).find(|i| i.result_id == Some(id(&ops[k]))).unwrap().clone();
        for (k, lane) in [(7, 3), (9, 3)] {
            let e = extract(k);
            assert_eq!((e.class.opcode, e.operands[1].clone()), (Op::CompositeExtract, Operand::LiteralBit32(lane)));
        }
        let bindings = [BINDING_TLAS, BINDING_RAYS, BINDING_HITS];
        assert_eq!(bindings, [0, 1, 2]);
    }

    #[test]
    fn the_hit_stage_reports_the_primitive_the_distance_and_the_barycentrics() {
        let m = load(&stages().unwrap().closest_hit);
        let mut inputs: Vec<BuiltIn> = m
            .types_global_values
            .iter()
            .filter(|i| i.class.opcode == Op::Variable)
            .filter_map(|v| builtin(&m, v.result_id.unwrap()))
            .collect();
        inputs.sort_by_key(|b| *b as u32);
        assert_eq!(inputs, [BuiltIn::PrimitiveId, BuiltIn::RayTmaxKHR]);
        let attributes = m
            .types_global_values
            .iter()
            .filter(|i| i.class.opcode == Op::Variable)
            .filter(|v| v.operands[0] == Operand::StorageClass(StorageClass::HitAttributeKHR))
            .count();
        assert_eq!(attributes, 1);
        // The record is (t, primitive, u, v): the constructed payload's members in that order.
        let construct = instructions(&m).find(|i| i.class.opcode == Op::CompositeConstruct).unwrap();
        let loaded: Vec<Word> = construct.operands.iter().map(id).collect();
        let source_of = |w: Word| {
            let i = instructions(&m).find(|i| i.result_id == Some(w)).unwrap();
            match i.class.opcode {
                Op::Load => builtin(&m, id(&i.operands[0])).map(|b| format!("{b:?}")).unwrap_or("attributes".into()),
                Op::CompositeExtract => format!("barycentric {:?}", i.operands[1]),
                op => format!("{op:?}"),
            }
        };
        let names: Vec<String> = loaded.into_iter().map(source_of).collect();
        assert_eq!(names, ["RayTmaxKHR", "PrimitiveId", "barycentric LiteralBit32(0)", "barycentric LiteralBit32(1)"]);
    }

    #[test]
    fn the_miss_stage_clears_the_triangle() {
        let m = load(&stages().unwrap().miss);
        let stores: Vec<_> = instructions(&m).filter(|i| i.class.opcode == Op::Store).collect();
        assert_eq!(stores.len(), 1);
        assert_eq!(constant(&m, id(&stores[0].operands[1])), render_spec::NO_TRIANGLE);
        let chain = instructions(&m).find(|i| i.result_id == Some(id(&stores[0].operands[0]))).unwrap();
        assert_eq!(constant(&m, id(&chain.operands[1])), 1, "HitRec's second member, tri");
    }
}
