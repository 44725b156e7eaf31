//! The kernels as SPIR-V in which no floating-point operation may be fused
//! with another: every multiply, add, subtract, divide and negation carries
//! the `NoContraction` decoration.
//!
//! Why: WGSL cannot forbid contraction, and naga's SPIR-V writer (which wgpu
//! uses on Vulkan) leaves it allowed, so NVIDIA's compiler turns a·b + c into
//! one fma wherever it likes. Each such fma rounds once where the CPU path
//! rounds twice, and the finite-difference Jacobians amplify that rounding
//! by 1/δ: on an H100 and an H200 the GPU's exponents differed from the
//! CPU's by 2e-10 to 3e-8, where lavapipe (which does not contract) agrees
//! with the CPU almost to the bit (docs/BENCHMARKS.md, "What the H100 found
//! wrong"). So the kernels are compiled here as wgpu would compile them,
//! decorated, and handed to the driver as they are (wgpu's passthrough
//! shaders, which Vulkan adapters offer). Explicit `fma` (the exact steps of
//! shaders/shared/math64.wgsl) is an instruction of its own and stays fused.

use naga::back::spv;

/// `OpDecorate`, and the `NoContraction` decoration.
const OP_DECORATE: u32 = 71;
const NO_CONTRACTION: u32 = 42;
/// `OpCapability`, `OpExtension`, `OpEntryPoint`, `OpExecutionMode`, and
/// the capability and execution mode `SignedZeroInfNanPreserve`.
const OP_CAPABILITY: u32 = 17;
const OP_EXTENSION: u32 = 10;
const OP_ENTRY_POINT: u32 = 15;
const OP_EXECUTION_MODE: u32 = 16;
const INF_NAN_CAPABILITY: u32 = 4466;
const INF_NAN_MODE: u32 = 4461;

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
/// as its descriptors), and forbids contraction.
pub fn compile(
    source: &str,
    bindings: &[u32],
    constants: &[(&str, f64)],
    inf_nan_widths: &[u32],
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
    Ok(keep_inf_nan(&forbid_contraction(&words), inf_nan_widths))
}

/// The float widths (32, 64) whose infinities and NaN `adapter`'s Vulkan
/// driver can be told to keep (`shaderSignedZeroInfNanPreserveFloat32/64`).
/// Why it matters: SPIR-V (as WGSL) lets a driver assume that no operand is
/// infinite or NaN, and the kernels test for both (`abs(x) <= MAX_REAL`
/// fails for them alone) and make them on purpose (-∞ for a collapsed
/// direction); under that assumption a driver may fold such a test to
/// true.
pub fn inf_nan_widths(adapter: &wgpu::Adapter) -> Vec<u32> {
    use ash::vk;
    // SAFETY: the instance and physical device are the adapter's own,
    // alive while it is; the query writes only the structures passed.
    unsafe {
        let Some(hal) = adapter.as_hal::<wgpu::hal::api::Vulkan>() else {
            return Vec::new();
        };
        let instance = hal.shared_instance().raw_instance();
        let mut controls = vk::PhysicalDeviceFloatControlsProperties::default();
        let mut properties = vk::PhysicalDeviceProperties2::default().push_next(&mut controls);
        instance.get_physical_device_properties2(hal.raw_physical_device(), &mut properties);
        [
            (32, controls.shader_signed_zero_inf_nan_preserve_float32),
            (64, controls.shader_signed_zero_inf_nan_preserve_float64),
        ]
        .into_iter()
        .filter(|&(_, kept)| kept == vk::TRUE)
        .map(|(width, _)| width)
        .collect()
    }
}

/// `words` declaring that the entry points keep signed zeros, infinities
/// and NaN of the float `widths` (SPV_KHR_float_controls, core from SPIR-V
/// 1.4): the capability after the module's capabilities, the extension
/// after them, an execution mode per width after each entry point's.
pub fn keep_inf_nan(words: &[u32], widths: &[u32]) -> Vec<u32> {
    const HEADER: usize = 5;
    if widths.is_empty() {
        return words.to_vec();
    }
    let extension = string_words("SPV_KHR_float_controls");
    let mut out = Vec::with_capacity(words.len() + 8 + 4 * widths.len());
    out.extend_from_slice(&words[..HEADER]);
    let mut at = HEADER;
    let (mut capability_added, mut entries) = (false, Vec::new());
    while at < words.len() {
        let (count, opcode) = ((words[at] >> 16) as usize, words[at] & 0xffff);
        if !capability_added && opcode != OP_CAPABILITY {
            out.extend_from_slice(&[(2 << 16) | OP_CAPABILITY, INF_NAN_CAPABILITY]);
            out.push(((1 + extension.len() as u32) << 16) | OP_EXTENSION);
            out.extend_from_slice(&extension);
            capability_added = true;
        }
        if opcode == OP_ENTRY_POINT {
            entries.push(words[at + 2]);
        }
        // The modes go after the last entry point, with the other modes.
        if !entries.is_empty() && opcode != OP_ENTRY_POINT && opcode != OP_EXECUTION_MODE {
            for &entry in &entries {
                for &width in widths {
                    out.extend_from_slice(&[
                        (4 << 16) | OP_EXECUTION_MODE,
                        entry,
                        INF_NAN_MODE,
                        width,
                    ]);
                }
            }
            entries.clear();
        }
        out.extend_from_slice(&words[at..at + count]);
        at += count;
    }
    out
}

/// A SPIR-V literal string: UTF-8, nul-terminated, in little-endian words.
fn string_words(text: &str) -> Vec<u32> {
    let mut bytes = text.as_bytes().to_vec();
    bytes.push(0);
    bytes.resize(bytes.len().div_ceil(4) * 4, 0);
    bytes
        .chunks(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect()
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
        let words = compile(source, &[0], &[("WORKGROUP_SIZE", 64.0)], &[]).unwrap();
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

    /// The declaration that infinities and NaN are kept: the capability
    /// with the others, the extension after them, a mode per width with the
    /// entry point's, and nothing else changed.
    #[test]
    fn inf_and_nan_are_declared_kept_where_spir_v_wants_them() {
        let source = "
            @group(0) @binding(3) var<storage, read_write> x: array<f32>;
            @compute @workgroup_size(64)
            fn main(@builtin(global_invocation_id) id: vec3<u32>) {
                x[id.x] = -1.0 / x[id.x];
            }";
        let plain = compile(source, &[3], &[], &[]).unwrap();
        let kept = compile(source, &[3], &[], &[32, 64]).unwrap();
        let instructions = |words: &[u32]| {
            let mut list = Vec::new();
            let mut at = 5;
            while at < words.len() {
                let count = (words[at] >> 16) as usize;
                list.push(words[at..at + count].to_vec());
                at += count;
            }
            list
        };
        let (plain, kept) = (instructions(&plain), instructions(&kept));
        let opcodes: Vec<u32> = kept.iter().map(|i| i[0] & 0xffff).collect();
        let last_capability = opcodes.iter().rposition(|&o| o == OP_CAPABILITY).unwrap();
        assert_eq!(kept[last_capability][1], INF_NAN_CAPABILITY);
        assert_eq!(opcodes[last_capability + 1], OP_EXTENSION);
        assert_eq!(
            kept[last_capability + 1][1..],
            string_words("SPV_KHR_float_controls")
        );
        let modes: Vec<&Vec<u32>> = kept
            .iter()
            .filter(|i| i[0] & 0xffff == OP_EXECUTION_MODE && i[2] == INF_NAN_MODE)
            .collect();
        assert_eq!(modes.iter().map(|m| m[3]).collect::<Vec<_>>(), [32, 64]);
        let last_mode = opcodes
            .iter()
            .rposition(|&o| o == OP_EXECUTION_MODE)
            .unwrap();
        assert_eq!(kept[last_mode][2], INF_NAN_MODE);
        assert!(opcodes[..last_mode].contains(&OP_ENTRY_POINT));
        // Binding 3, the layout's only one, is at descriptor 0 (decoration
        // Binding is 33).
        assert!(kept
            .iter()
            .any(|i| i[0] & 0xffff == OP_DECORATE && i[2..] == [33, 0]));
        let added = |i: &Vec<u32>| {
            (i[0] & 0xffff == OP_CAPABILITY && i[1] == INF_NAN_CAPABILITY)
                || i[0] & 0xffff == OP_EXTENSION
                || (i[0] & 0xffff == OP_EXECUTION_MODE && i[2] == INF_NAN_MODE)
        };
        let rest: Vec<&Vec<u32>> = kept.iter().filter(|i| !added(i)).collect();
        assert_eq!(rest, plain.iter().collect::<Vec<_>>());
    }
}
