//! `--exact`: SPIR-V in which no float operation may be fused with another.
//!
//! A GPU compiler may contract `a * b + c` into one fused multiply-add, which rounds once where the
//! CPU rounds twice; WGSL has no way to forbid it, SPIR-V has: the `NoContraction` decoration on an
//! arithmetic instruction's result. This pass decorates every float arithmetic result of a module
//! naga wrote. It refuses instructions whose internal arithmetic the driver defines (a dot product
//! sums in an order of its choosing, `cross` and `normalize` contract inside), because no
//! decoration makes those equal to the CPU: the kernels spell such operations out in the CPU's
//! operation order (`dot3`, `cross3`, `length3` in common.wgsl). Division and `sqrt`, which Vulkan
//! lets a device round inexactly, are correctly rounded by the exact kernels' `div_rn` and
//! `sqrt_rn` (built on `fma`, which this pass therefore allows); powers are adds and multiplies
//! (`phong_pow`). [`preserve_denormals`] keeps subnormal results where the device can.

use rspirv::binary::Assemble;
use rspirv::dr::{Instruction, Operand};
use rspirv::spirv::{Capability, Decoration, ExecutionMode, GlslStd450Op, Op, Word};
use std::collections::HashSet;

use crate::error::VkError;

/// Float arithmetic whose result is rounded once: each gets `NoContraction`.
const DECORATED: [Op; 9] = [
    Op::FNegate,
    Op::FAdd,
    Op::FSub,
    Op::FMul,
    Op::FDiv,
    Op::FRem,
    Op::FMod,
    Op::VectorTimesScalar,
    Op::MatrixTimesScalar,
];

/// Instructions made of several roundings in an order the driver picks.
const COMPOUND: [Op; 5] =
    [Op::Dot, Op::VectorTimesMatrix, Op::MatrixTimesVector, Op::MatrixTimesMatrix, Op::OuterProduct];

/// GLSL.std.450 instructions made of several roundings. `Fma` is not among them: it rounds once
/// by definition (the exact product plus the addend), which is what the correctly rounded division
/// and square root of an exact kernel (`div_rn`, `sqrt_rn` in common.wgsl) are built on; the CPU
/// model of those uses `f32::mul_add`.
const COMPOUND_GL: [GlslStd450Op; 11] = [
    GlslStd450Op::FMix,
    GlslStd450Op::SmoothStep,
    GlslStd450Op::Length,
    GlslStd450Op::Distance,
    GlslStd450Op::Cross,
    GlslStd450Op::Normalize,
    GlslStd450Op::FaceForward,
    GlslStd450Op::Reflect,
    GlslStd450Op::Refract,
    GlslStd450Op::Determinant,
    GlslStd450Op::MatrixInverse,
];

/// Whether `op` is float arithmetic this pass decorates.
pub fn is_decorated_arithmetic(op: Op) -> bool {
    DECORATED.contains(&op)
}

/// Returns `spirv` with `NoContraction` on the result of every float arithmetic instruction, or
/// the shader error naming the first instruction whose rounding the driver would define.
pub fn forbid_contraction(spirv: &[u32], label: &str) -> Result<Vec<u32>, VkError> {
    let fail = |message: String| VkError::Shader { label: label.to_string(), message };
    let mut module =
        rspirv::dr::load_words(spirv).map_err(|e| fail(format!("error: the SPIR-V does not parse: {e}")))?;
    let floats = float_types(&module.types_global_values);
    let glsl: HashSet<Word> = module
        .ext_inst_imports
        .iter()
        .filter(|i| matches!(i.operands.first(), Some(Operand::LiteralString(s)) if s == "GLSL.std.450"))
        .filter_map(|i| i.result_id)
        .collect();
    let mut done: HashSet<Word> = module
        .annotations
        .iter()
        .filter(|i| {
            i.class.opcode == Op::Decorate && i.operands.get(1) == Some(&Operand::Decoration(Decoration::NoContraction))
        })
        .filter_map(|i| i.operands.first().and_then(Operand::id_ref_any))
        .collect();
    let mut added = Vec::new();
    for inst in module.functions.iter().flat_map(|f| f.blocks.iter()).flat_map(|b| b.instructions.iter()) {
        let op = inst.class.opcode;
        let float = inst.result_type.is_some_and(|t| floats.contains(&t));
        if float && COMPOUND.contains(&op) {
            return Err(fail(format!(
                "error: Op{:?} (%{}) rounds in an order the driver chooses, so --exact cannot hold it to the CPU's; spell it out in common.wgsl's helpers",
                op,
                inst.result_id.unwrap_or(0)
            )));
        }
        if float
            && op == Op::ExtInst
            && let Some(gl) = compound_gl(inst, &glsl)
        {
            return Err(fail(format!(
                "error: GLSL.std.450 {gl:?} (%{}) rounds inside the driver, so --exact cannot hold it to the CPU's; spell it out in common.wgsl's helpers",
                inst.result_id.unwrap_or(0)
            )));
        }
        if float
            && is_decorated_arithmetic(op)
            && let Some(id) = inst.result_id
            && done.insert(id)
        {
            added.push(Instruction::new(
                Op::Decorate,
                None,
                None,
                vec![Operand::IdRef(id), Operand::Decoration(Decoration::NoContraction)],
            ));
        }
    }
    module.annotations.extend(added);
    Ok(module.assemble())
}

/// Returns `spirv` with the execution mode `DenormPreserve` for 32-bit floats on every entry point
/// (SPV_KHR_float_controls): the device may not flush subnormal operands or results to zero, as
/// the CPU does not. Only for a device that reports `shaderDenormPreserveFloat32`
/// ([`crate::DeviceInfo::denorm_preserve_f32`]); elsewhere the mode is not allowed.
pub fn preserve_denormals(spirv: &[u32], label: &str) -> Result<Vec<u32>, VkError> {
    let mut module = rspirv::dr::load_words(spirv).map_err(|e| VkError::Shader {
        label: label.to_string(),
        message: format!("error: the SPIR-V does not parse: {e}"),
    })?;
    module.capabilities.push(Instruction::new(
        Op::Capability,
        None,
        None,
        vec![Operand::Capability(Capability::DenormPreserve)],
    ));
    module.extensions.push(Instruction::new(
        Op::Extension,
        None,
        None,
        vec![Operand::LiteralString("SPV_KHR_float_controls".to_string())],
    ));
    let entries: Vec<Operand> = module.entry_points.iter().filter_map(|e| e.operands.get(1).cloned()).collect();
    for entry in entries {
        module.execution_modes.push(Instruction::new(
            Op::ExecutionMode,
            None,
            None,
            vec![entry, Operand::ExecutionMode(ExecutionMode::DenormPreserve), Operand::LiteralBit32(32)],
        ));
    }
    Ok(module.assemble())
}

/// The ids of float scalar, vector and matrix types.
fn float_types(globals: &[Instruction]) -> HashSet<Word> {
    let mut floats = HashSet::new();
    // Types are declared before use, so one pass in order sees a vector's component first.
    for i in globals {
        let Some(id) = i.result_id else { continue };
        let component = i.operands.first().and_then(Operand::id_ref_any);
        let is_float = match i.class.opcode {
            Op::TypeFloat => true,
            Op::TypeVector | Op::TypeMatrix => component.is_some_and(|c| floats.contains(&c)),
            _ => false,
        };
        if is_float {
            floats.insert(id);
        }
    }
    floats
}

/// The GLSL.std.450 instruction of an `OpExtInst`, where it is one made of several roundings.
fn compound_gl(inst: &Instruction, glsl: &HashSet<Word>) -> Option<GlslStd450Op> {
    let (Some(Operand::IdRef(set)), Some(Operand::LiteralExtInstInteger(n))) =
        (inst.operands.first(), inst.operands.get(1))
    else {
        return None;
    };
    if !glsl.contains(set) {
        return None;
    }
    COMPOUND_GL.iter().copied().find(|&g| g as u32 == *n)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::{self, Method, Specialisation, Stage};

    /// Every float arithmetic result of `words` and whether it carries `NoContraction`.
    fn arithmetic(words: &[u32]) -> Vec<(Op, Word, bool)> {
        let m = rspirv::dr::load_words(words).expect("the output parses");
        let floats = float_types(&m.types_global_values);
        let decorated: HashSet<Word> = m
            .annotations
            .iter()
            .filter(|i| i.operands.get(1) == Some(&Operand::Decoration(Decoration::NoContraction)))
            .filter_map(|i| i.operands.first().and_then(Operand::id_ref_any))
            .collect();
        m.functions
            .iter()
            .flat_map(|f| f.blocks.iter())
            .flat_map(|b| b.instructions.iter())
            .filter(|i| is_decorated_arithmetic(i.class.opcode) && i.result_type.is_some_and(|t| floats.contains(&t)))
            .map(|i| {
                let id = i.result_id.expect("arithmetic has a result");
                (i.class.opcode, id, decorated.contains(&id))
            })
            .collect()
    }

    /// The Khronos validation layer (which runs spirv-val on every shader module) takes the
    /// decorated module as a compute pipeline.
    fn validates(gpu: &crate::Gpu, words: &[u32], label: &str) {
        gpu.pipeline(words, crate::render::BINDINGS, kernels::PASS_BYTES, label).expect("the pipeline is made");
        let messages = gpu.validation_messages();
        assert!(messages.is_empty(), "{label}: the validation layer reported {messages:#?}");
    }

    fn gpu() -> crate::Gpu {
        crate::Gpu::new(None, true).unwrap_or_else(|e| panic!("this test needs a Vulkan device: {e}"))
    }

    #[test]
    fn every_float_result_of_every_kernel_is_decorated() {
        let gpu = gpu();
        for method in [Method::Lst, Method::Stackless, Method::Sst, Method::SstSubgroup, Method::Cwbvh] {
            for stage in [Stage::Cast, Stage::Primary, Stage::Shade, Stage::Bounce, Stage::Convert] {
                let spec = Specialisation { exact: true, ..Specialisation::every_feature(method) };
                // The exact kernel's text as naga writes it, then with the pass.
                let source = kernels::source(stage, &spec);
                let plain = if method == Method::SstSubgroup {
                    crate::shader::translate_with_subgroups(&source, "t", &[])
                } else {
                    crate::shader::translate(&source, "t", &[])
                }
                .expect("the kernel compiles");
                let before = arithmetic(&plain);
                assert!(before.iter().all(|&(_, _, d)| !d), "{method:?} {stage:?}: naga decorates nothing itself");
                let exact = kernels::compile(stage, &spec).expect("exact compiles");
                let after = arithmetic(&exact);
                assert_eq!(before.len(), after.len(), "{method:?} {stage:?}: the pass adds no arithmetic");
                assert!(after.len() > 10, "{method:?} {stage:?}: a kernel has float arithmetic to decorate");
                let kinds: HashSet<Op> = after.iter().map(|a| a.0).collect();
                assert!(kinds.contains(&Op::FMul) && kinds.contains(&Op::FAdd), "{method:?} {stage:?}: {kinds:?}");
                for (op, id, decorated) in after {
                    assert!(decorated, "{method:?} {stage:?}: Op{op:?} %{id} lacks NoContraction");
                }
                validates(&gpu, &exact, &format!("exact {method:?} {stage:?}"));
            }
        }
    }

    #[test]
    fn compound_operations_are_refused_in_one_sentence() {
        let src = |body: &str| {
            format!(
                "@group(0) @binding(0) var<storage, read_write> v: array<vec4<f32>>;\n\
                 @compute @workgroup_size(1) fn main() {{ let a = v[0].xyz; let b = v[1].xyz; {body} }}"
            )
        };
        for (body, what) in [
            ("v[2].x = dot(a, b);", "OpDot"),
            ("v[2] = vec4<f32>(cross(a, b), 0.0);", "Cross"),
            ("v[2] = vec4<f32>(normalize(a), 0.0);", "Normalize"),
            ("v[2].x = length(a);", "Length"),
        ] {
            let words = crate::shader::translate(&src(body), "t", &[]).expect("translates");
            let e = forbid_contraction(&words, "t").expect_err(body).to_string();
            assert!(e.contains(what) && e.contains("--exact") && !e.contains('\n'), "{body}: {e}");
        }
        // Plain arithmetic passes, decorated, and so does fma (one rounding by definition).
        let words =
            crate::shader::translate(&src("v[2] = vec4<f32>(a * b.x + b - a / b, fma(-a.x, b.y, a.z));"), "t", &[])
                .unwrap();
        let out = forbid_contraction(&words, "t").unwrap();
        let found = arithmetic(&out);
        assert!(found.len() >= 5 && found.iter().all(|a| a.2), "{found:?}");
        let gpu = gpu();
        gpu.pipeline(&out, 1, kernels::PASS_BYTES, "plain").expect("the pipeline is made");
        assert!(gpu.validation_messages().is_empty(), "{:#?}", gpu.validation_messages());
    }

    /// The capability, the extension and the execution mode on the entry point (the device here,
    /// lavapipe, does not report shaderDenormPreserveFloat32, so no pipeline is made of it).
    #[test]
    fn denormals_are_preserved_by_execution_mode() {
        let spec = Specialisation { exact: true, ..Specialisation::every_feature(Method::Lst) };
        let words = kernels::compile(Stage::Bounce, &spec).expect("the kernel compiles");
        let out = rspirv::dr::load_words(preserve_denormals(&words, "t").unwrap()).unwrap();
        assert!(out.capabilities.iter().any(|i| i.operands == [Operand::Capability(Capability::DenormPreserve)]));
        assert!(out.extensions.iter().any(|i| i.operands == [Operand::LiteralString("SPV_KHR_float_controls".into())]));
        let main = out.entry_points[0].operands[1].clone();
        let mode = [main, Operand::ExecutionMode(ExecutionMode::DenormPreserve), Operand::LiteralBit32(32)];
        assert!(out.execution_modes.iter().any(|i| i.operands == mode), "{:?}", out.execution_modes);
    }

    /// On the device: `a * b + c` of the exact kernel equals the CPU's two roundings on every
    /// input, including those where a fused multiply-add rounds differently.
    #[test]
    fn the_device_rounds_the_exact_kernel_as_the_cpu() {
        const N: usize = 4096;
        let src = "@group(0) @binding(0) var<storage, read_write> v: array<vec4<f32>>;\n\
                   @compute @workgroup_size(64) fn main(@builtin(global_invocation_id) id: vec3<u32>) {\n\
                   let x = v[id.x]; v[id.x].w = x.x * x.y + x.z; }";
        // Products that need more than 24 bits, offset by about their own size: where a fused
        // multiply-add keeps the low bits the product's rounding drops.
        let mut rng = ::tests::Rng(0x9e37_79b9);
        let mut next = || 1.0 + rng.unit();
        let input: Vec<[f32; 4]> = (0..N)
            .map(|_| {
                let (a, b) = (next(), next());
                [a, b, -(a * b) * next().fract().max(0.5), 0.0]
            })
            .collect();
        let fused = input.iter().filter(|x| x[0].mul_add(x[1], x[2]) != x[0] * x[1] + x[2]).count();
        assert!(fused > N / 4, "the inputs must tell fused from unfused ({fused} of {N} do)");
        let gpu = gpu();
        let words = crate::shader::translate(src, "mad", &[]).unwrap();
        let mut differ = [0; 2];
        for (k, exact) in [false, true].into_iter().enumerate() {
            let words = if exact { forbid_contraction(&words, "mad").unwrap() } else { words.clone() };
            let p = gpu.pipeline(&words, 1, kernels::PASS_BYTES, "mad").unwrap();
            let buf = gpu.create_buffer_with(&input, "mad").unwrap();
            gpu.run(|rec| rec.dispatch(&p, &[&buf], &[0; kernels::PASS_BYTES as usize], [(N / 64) as u32, 1, 1]))
                .unwrap();
            let out: Vec<[f32; 4]> = gpu.download_as(&buf).unwrap();
            differ[k] =
                out.iter().zip(&input).filter(|(o, x)| o[3].to_bits() != (x[0] * x[1] + x[2]).to_bits()).count();
        }
        println!(
            "{}: a * b + c differs from the CPU's on {} of {N} inputs without NoContraction, {} with (a fused multiply-add would differ on {fused})",
            gpu.info().name,
            differ[0],
            differ[1]
        );
        assert_eq!(differ[1], 0, "the exact kernel rounds as the CPU does");
        assert!(gpu.validation_messages().is_empty(), "{:#?}", gpu.validation_messages());
    }
}
