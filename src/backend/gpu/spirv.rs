//! The f64 kernels as SPIR-V in which no floating-point operation may be
//! fused with another: every multiply, add, subtract, divide and negation
//! carries the `NoContraction` decoration.
//!
//! Why: WGSL cannot forbid contraction, and naga's SPIR-V writer (which wgpu
//! uses on Vulkan) leaves it allowed, so NVIDIA's compiler turns a·b + c into
//! one fma wherever it likes. Each such fma rounds once where the CPU path
//! rounds twice, and the finite-difference Jacobians amplify that rounding
//! by 1/δ: on an H100 and an H200 the GPU's exponents differed from the
//! CPU's by 2e-10 to 3e-8, where lavapipe (which does not contract in f64)
//! agrees with the CPU almost to the bit (docs/BENCHMARKS-GPU.md, "NVIDIA H100
//! and H200", "Why the f64 kernels forbid contraction"). So the kernels are compiled here as wgpu would,
//! decorated, and handed to the driver as they are (wgpu's passthrough
//! shaders, which Vulkan adapters offer). Explicit `fma` (the exact steps of
//! shaders/shared/math64.wgsl) is an instruction of its own and stays fused.

use naga::back::spv;

/// `OpDecorate`, and the `NoContraction` decoration.
const OP_DECORATE: u32 = 71;
const NO_CONTRACTION: u32 = 42;
/// The floating-point arithmetic a driver could fuse: OpFNegate, OpFAdd,
/// OpFSub, OpFMul, OpFDiv, OpFRem, OpFMod, OpVectorTimesScalar,
/// OpMatrixTimesScalar, OpVectorTimesMatrix, OpMatrixTimesVector,
/// OpMatrixTimesMatrix, OpDot. Each has its result id in word 2.
const ARITHMETIC: &[u32] = &[
    127, 129, 131, 133, 136, 140, 141, 142, 143, 144, 145, 146, 148,
];

/// What the module header and the sections before the annotations are made
/// of (capabilities, extensions, imports, the memory model, entry points,
/// execution modes, debug names and strings), and the annotations
/// themselves: the decorations go after the last of these.
const PREAMBLE: &[u32] = &[
    2, 3, 4, 5, 6, 7, 10, 11, 14, 15, 16, 17, 330, 331, // through the debug section
    71, 72, 73, 74, 75, 332, 5632, 5633, // annotations
];

/// Compiles WGSL `source`'s compute entry point `main` to SPIR-V with the
/// pipeline-overridable `constants` set, as wgpu's Vulkan backend does
/// (bounds checks restricted, loops bounded, group 0's `bindings` numbered
/// as its descriptors), and forbids contraction unless `fusing`.
pub fn compile(
    source: &str,
    bindings: &[u32],
    constants: &[(&str, f64)],
    fusing: bool,
) -> Result<Vec<u32>, String> {
    let module = naga::front::wgsl::parse_str(source).map_err(|e| e.emit_to_string(source))?;
    let info = naga::valid::Validator::new(
        naga::valid::ValidationFlags::all(),
        naga::valid::Capabilities::all(),
    )
    .validate(&module)
    .map_err(|e| e.emit_to_string(source))?;
    let constants: naga::back::PipelineConstants = constants
        .iter()
        .map(|&(name, value)| (name.to_owned(), value))
        .collect();
    let entry = (naga::ShaderStage::Compute, "main");
    let (module, info) =
        naga::back::pipeline_constants::process_overrides(&module, &info, Some(entry), &constants)
            .map_err(|e| e.to_string())?;
    let options = spv::Options {
        // SPIR-V 1.3: Vulkan 1.1, which every adapter with f64 storage has.
        lang_version: (1, 3),
        flags: spv::WriterFlags::empty(),
        fake_missing_bindings: false,
        binding_map: descriptors(bindings),
        bounds_check_policies: naga::proc::BoundsCheckPolicies {
            index: naga::proc::BoundsCheckPolicy::Restrict,
            buffer: naga::proc::BoundsCheckPolicy::Restrict,
            image_load: naga::proc::BoundsCheckPolicy::Restrict,
            binding_array: naga::proc::BoundsCheckPolicy::Unchecked,
        },
        ray_query_initialization_tracking: false,
        ..spv::Options::default()
    };
    let pipeline = spv::PipelineOptions {
        shader_stage: naga::ShaderStage::Compute,
        entry_point: "main".into(),
    };
    let words =
        spv::write_vec(&module, &info, &options, Some(&pipeline)).map_err(|e| e.to_string())?;
    Ok(if fusing {
        words
    } else {
        forbid_contraction(&words)
    })
}

/// Where group 0's `bindings` are in the descriptor set: wgpu's Vulkan
/// backend numbers a bind group layout's descriptors by their rank among
/// the layout's binding numbers (wgpu-hal's `create_bind_group_layout`;
/// wgpu-core sorts the entries), not by the numbers themselves, so a kernel
/// without bindings 5 and 6 finds binding 7 at descriptor 5.
fn descriptors(bindings: &[u32]) -> spv::BindingMap {
    let mut sorted = bindings.to_vec();
    sorted.sort_unstable();
    sorted
        .iter()
        .enumerate()
        .map(|(rank, &binding)| {
            let place = spv::BindingInfo {
                descriptor_set: 0,
                binding: rank as u32,
                binding_array_size: None,
            };
            (naga::ResourceBinding { group: 0, binding }, place)
        })
        .collect()
}

/// `words` with an `OpDecorate %r NoContraction` for the result `%r` of
/// every instruction in [`ARITHMETIC`], placed after the module's last
/// annotation (SPIR-V's logical layout wants all decorations before the
/// first type).
pub fn forbid_contraction(words: &[u32]) -> Vec<u32> {
    const HEADER: usize = 5;
    let mut results = Vec::new();
    let mut after_preamble = None;
    let mut at = HEADER;
    while at < words.len() {
        let (count, opcode) = ((words[at] >> 16) as usize, words[at] & 0xffff);
        assert!(
            count > 0 && at + count <= words.len(),
            "malformed SPIR-V at word {at}"
        );
        if after_preamble.is_none() && !PREAMBLE.contains(&opcode) {
            after_preamble = Some(at);
        }
        if ARITHMETIC.contains(&opcode) {
            results.push(words[at + 2]);
        }
        at += count;
    }
    let split = after_preamble.unwrap_or(words.len());
    let mut out = Vec::with_capacity(words.len() + 3 * results.len());
    out.extend_from_slice(&words[..split]);
    for id in results {
        out.extend_from_slice(&[(3 << 16) | OP_DECORATE, id, NO_CONTRACTION]);
    }
    out.extend_from_slice(&words[split..]);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every float multiply and add of a small kernel is decorated, nothing
    /// else is, and the decorations sit with the others, before the types.
    #[test]
    fn every_multiply_and_add_is_decorated_before_the_types() {
        let source = "
            @group(0) @binding(0) var<storage, read_write> x: array<f32>;
            override WORKGROUP_SIZE: u32 = 1u;
            @compute @workgroup_size(WORKGROUP_SIZE)
            fn main(@builtin(global_invocation_id) id: vec3<u32>) {
                let i = id.x + 1u;
                x[id.x] = x[id.x] * x[i] + x[i] - 2.0 * x[id.x];
            }";
        let words = compile(source, &[0], &[("WORKGROUP_SIZE", 64.0)], false).unwrap();
        let mut at = 5;
        let (mut decorated, mut arithmetic, mut first_type) = (Vec::new(), Vec::new(), None);
        while at < words.len() {
            let (count, opcode) = ((words[at] >> 16) as usize, words[at] & 0xffff);
            if opcode == OP_DECORATE && words[at + 2] == NO_CONTRACTION {
                assert!(first_type.is_none(), "a decoration after the types");
                decorated.push(words[at + 1]);
            }
            // OpTypeVoid .. OpTypeForwardPointer are 19..39.
            if (19..=39).contains(&opcode) && first_type.is_none() {
                first_type = Some(at);
            }
            if [129, 131, 133].contains(&opcode) {
                arithmetic.push(words[at + 2]);
            }
            at += count;
        }
        // One multiply, one add, one subtract, one multiply (the integer
        // add of the index is no float operation).
        assert_eq!(arithmetic.len(), 4, "{arithmetic:?}");
        assert_eq!(decorated, arithmetic);
    }
}
