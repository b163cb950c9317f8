//! WGSL to SPIR-V inside the program (docs/vulkan-tracer.md, "Kernels").
//!
//! naga's SPIR-V writer has no specialization constants, so `override`s are resolved here, before
//! writing: every distinct set of override values is its own SPIR-V module (about a millisecond).

use naga::back::spv;
use naga::valid::{Capabilities, ValidationFlags, Validator};

use crate::error::VkError;

/// What every kernel may use: push constants, which naga 30 calls immediates (`var<immediate>
/// params: Params;` in WGSL; `var<push_constant>` is no longer accepted), bound by
/// [`crate::Gpu::pipeline`]'s `push_bytes`.
fn base_capabilities() -> Capabilities {
    Capabilities::default() | Capabilities::IMMEDIATES
}

/// WGSL -> validated naga module -> overrides resolved -> SPIR-V 1.3 words for entry point `main`.
/// Push constants are written `var<immediate> name: T;` (naga 30's spelling).
pub fn translate(source: &str, label: &str, overrides: &[(&str, f64)]) -> Result<Vec<u32>, VkError> {
    translate_with(source, label, overrides, base_capabilities())
}

/// As [`translate`], with subgroup builtins and operations allowed. naga 30 rejects the
/// `enable subgroups;` directive, so the source must use them without it; the device must report
/// `DeviceInfo::supports_subgroup_ops`.
pub fn translate_with_subgroups(source: &str, label: &str, overrides: &[(&str, f64)]) -> Result<Vec<u32>, VkError> {
    translate_with(
        source,
        label,
        overrides,
        base_capabilities() | Capabilities::SUBGROUP | Capabilities::SUBGROUP_BARRIER,
    )
}

fn translate_with(
    source: &str,
    label: &str,
    overrides: &[(&str, f64)],
    caps: Capabilities,
) -> Result<Vec<u32>, VkError> {
    let fail = |message: String| VkError::Shader { label: label.to_string(), message };
    let module = naga::front::wgsl::parse_str(source).map_err(|e| fail(e.emit_to_string(source)))?;
    let info = Validator::new(ValidationFlags::all(), caps)
        .validate(&module)
        .map_err(|e| fail(with_causes(e.emit_to_string(source), e.as_inner())))?;

    let mut constants = naga::back::PipelineConstants::default();
    for &(name, value) in overrides {
        constants.insert(name.to_string(), value);
    }
    let (module, info) = naga::back::pipeline_constants::process_overrides(
        &module,
        &info,
        Some((naga::ShaderStage::Compute, "main")),
        &constants,
    )
    .map_err(|e| {
        let text = match &e {
            naga::back::pipeline_constants::PipelineConstantError::ValidationError(v) => {
                with_causes(v.emit_to_string(source), v.as_inner())
            }
            other => with_causes(format!("error: {other}"), other),
        };
        fail(text)
    })?;

    // No zero-initialisation of workgroup memory: only SST's kernel has any, and it writes each
    // variable before reading it (tracer-vk/shaders/sst.wgsl). naga's polyfill stores every whole
    // array at the kernel's start, and lavapipe then compiled SST for minutes with a leaf cache of
    // 256 triangles (docs/stability.md, finding 8).
    let options = spv::Options {
        lang_version: (1, 3),
        zero_initialize_workgroup_memory: spv::ZeroInitializeWorkgroupMemoryMode::None,
        ..spv::Options::default()
    };
    let pipeline = spv::PipelineOptions { shader_stage: naga::ShaderStage::Compute, entry_point: "main".to_string() };
    spv::write_vec(&module, &info, &options, Some(&pipeline))
        .map(without_array_initialisers)
        .map_err(|e| fail(with_causes(format!("error: SPIR-V writer: {e}"), &e)))
}

/// The module with the zero initialisers of its function-local arrays taken out. naga gives every
/// local variable one, and lavapipe's compile time grows steeply with an initialised array's
/// length: LST's two stack arrays of a chain 500 deep made the first frame take 109 s, and 1000
/// deep more than 120 s; without the initialisers 3.9 s and 21 s (docs/stability.md, finding 5). The kernels' local arrays are the stacks of LST and cwbvh,
/// which are written before they are read (a pop follows its push), and SST's pair of children,
/// stored when declared.
fn without_array_initialisers(words: Vec<u32>) -> Vec<u32> {
    const OP_TYPE_ARRAY: u32 = 28;
    const OP_TYPE_POINTER: u32 = 32;
    const OP_VARIABLE: u32 = 59;
    const FUNCTION: u32 = 7;
    if words.len() < 5 {
        return words;
    }
    let mut arrays = std::collections::HashSet::new();
    let mut array_pointers = std::collections::HashSet::new();
    let mut out = words[..5].to_vec();
    let mut at = 5;
    while at < words.len() {
        let (count, op) = ((words[at] >> 16) as usize, words[at] & 0xffff);
        if count == 0 || at + count > words.len() {
            // Not a module naga would write: left as it is.
            return words;
        }
        let operands = &words[at + 1..at + count];
        match op {
            OP_TYPE_ARRAY => {
                arrays.insert(operands[0]);
            }
            OP_TYPE_POINTER if operands[1] == FUNCTION && arrays.contains(&operands[2]) => {
                array_pointers.insert(operands[0]);
            }
            OP_VARIABLE if count == 5 && operands[2] == FUNCTION && array_pointers.contains(&operands[0]) => {
                out.push((4 << 16) | OP_VARIABLE);
                out.extend_from_slice(&operands[..3]);
                at += count;
                continue;
            }
            _ => {}
        }
        out.extend_from_slice(&words[at..at + count]);
        at += count;
    }
    out
}

/// naga's validation errors nest ("Function [1] 'main' is invalid" <- "Expression [4] is invalid"
/// <- the actual reason), and the rendered diagnostic names only the outermost. The innermost is
/// the one a kernel author needs, so it is added to the first line (shown by `Display`), and causes
/// the diagnostic does not already show follow it.
fn with_causes(rendered: String, error: &dyn std::error::Error) -> String {
    let mut chain = Vec::new();
    let mut cause = error.source();
    while let Some(c) = cause {
        chain.push(c.to_string());
        cause = c.source();
    }
    let Some(root) = chain.last() else { return rendered };
    let (first, rest) = rendered.split_once('\n').unwrap_or((rendered.as_str(), ""));
    let mut out = format!("{first}: {root}\n{rest}");
    if !out.ends_with('\n') {
        out.push('\n');
    }
    for c in chain.iter().filter(|c| !rendered.contains(c.as_str())) {
        out.push_str("caused by: ");
        out.push_str(c);
        out.push('\n');
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const DOUBLE: &str = r#"
        override WG: u32 = 64u;
        @group(0) @binding(0) var<storage, read_write> data: array<u32>;
        @compute @workgroup_size(WG)
        fn main(@builtin(global_invocation_id) id: vec3<u32>) {
            if id.x < arrayLength(&data) { data[id.x] = data[id.x] * 2u; }
        }
    "#;

    #[test]
    fn translates_with_override() {
        let words = translate(DOUBLE, "double", &[("WG", 128.0)]).unwrap();
        assert_eq!(words[0], 0x0723_0203, "SPIR-V magic number");
        assert_eq!(words[1], 0x0001_0300, "SPIR-V 1.3");
    }

    #[test]
    fn errors_are_one_line_in_display() {
        let cases = [
            ("fn main( {", &[][..]),
            // Validation: u32 + f32 has no overload.
            ("@compute @workgroup_size(1) fn main() { let a = 1u + 2.0f; }", &[][..]),
            // An override the shader does not declare.
            (DOUBLE, &[("NOPE", 1.0)][..]),
            // A workgroup size of zero.
            (DOUBLE, &[("WG", 0.0)][..]),
        ];
        for (src, ov) in cases {
            let e = translate(src, "bad", ov).unwrap_err();
            let VkError::Shader { ref message, .. } = e else { panic!("{e:?}") };
            let shown = e.to_string();
            assert!(!shown.contains('\n'), "{shown}");
            assert!(shown.starts_with("shader `bad` did not compile: "), "{shown}");
            assert!(message.len() >= shown.len() - 30, "{message}");
            eprintln!("{shown}\n--- full:\n{message}");
        }
    }

    /// Local arrays and workgroup memory lose their zero initialisers (lavapipe compiled them for
    /// minutes); other local variables keep theirs, and the module still loads.
    #[test]
    fn arrays_and_workgroup_memory_are_not_zero_initialised() {
        let src = r#"
            @group(0) @binding(0) var<storage, read_write> data: array<u32>;
            var<workgroup> cache: array<u32, 64>;
            @compute @workgroup_size(64)
            fn main(@builtin(local_invocation_index) i: u32) {
                var stack: array<u32, 32>;
                var count: u32;
                stack[i % 32u] = data[i];
                cache[i] = stack[(i + 1u) % 32u];
                workgroupBarrier();
                count += cache[63u - i];
                data[i] = count;
            }
        "#;
        let words = translate(src, "init", &[]).unwrap();
        let module = rspirv::dr::load_words(&words).expect("a valid module");
        let function = module.functions.iter().flat_map(|f| f.blocks.iter()).flat_map(|b| b.instructions.iter());
        let variables: Vec<_> = module
            .types_global_values
            .iter()
            .chain(function)
            .filter(|i| i.class.opcode == rspirv::spirv::Op::Variable)
            .collect();
        let class = |i: &&rspirv::dr::Instruction| i.operands[0].unwrap_storage_class();
        let array_type = |i: &&rspirv::dr::Instruction| {
            let pointer = module.types_global_values.iter().find(|t| t.result_id == i.result_type).unwrap();
            let pointee = pointer.operands[1].unwrap_id_ref();
            module.types_global_values.iter().find(|t| t.result_id == Some(pointee)).unwrap().class.opcode
                == rspirv::spirv::Op::TypeArray
        };
        use rspirv::spirv::StorageClass;
        let local: Vec<_> = variables.iter().filter(|i| class(i) == StorageClass::Function).collect();
        let (arrays, others): (Vec<&&rspirv::dr::Instruction>, Vec<_>) = local.into_iter().partition(|i| array_type(i));
        assert!(!arrays.is_empty() && arrays.iter().all(|i| i.operands.len() == 1), "{arrays:?}");
        assert!(others.iter().any(|i| i.operands.len() == 2), "the scalar keeps its initialiser: {others:?}");
        let shared: Vec<_> = variables.iter().filter(|i| class(i) == StorageClass::Workgroup).collect();
        assert!(shared.len() == 1 && shared[0].operands.len() == 1, "{shared:?}");
    }

    #[test]
    fn subgroups_need_the_capability() {
        let src = r#"
            @group(0) @binding(0) var<storage, read_write> data: array<u32>;
            @compute @workgroup_size(64)
            fn main(@builtin(global_invocation_id) id: vec3<u32>) {
                data[id.x] = subgroupAdd(data[id.x]);
            }
        "#;
        assert!(translate(src, "sg", &[]).is_err());
        translate_with_subgroups(src, "sg", &[]).unwrap();
    }
}
