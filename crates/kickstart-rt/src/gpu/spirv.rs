//! Our own WGSL → SPIR-V compilation for the traversal passes on Vulkan, so that the traversal
//! stack is not zero-filled at the start of every invocation.
//!
//! WGSL zero-initialises every variable, and naga writes that rule into SPIR-V as a null
//! initializer on each `var<private>` and function `var`. For scalars that costs nothing (they
//! live in registers), but the traversal stack (`rt_stack` in `shaders/scene/traversal.wgsl`) is a
//! dynamically indexed array of 64 × 8 bytes, which the driver places in local memory: the null
//! initializer becomes 512 bytes of stores per invocation before the first ray step, whether the
//! ray needs two stack entries or forty. The traversal never reads an entry it has not written
//! (a pop only reads below the stack pointer, a push writes before it raises it), so the
//! initializer is dead work that no WGSL spelling can remove.
//!
//! Where the device accepts SPIR-V directly (Vulkan with `Features::PASSTHROUGH_SHADERS`), this
//! module compiles the pass's WGSL with the naga version wgpu uses, with the options wgpu-hal
//! would use, and drops the initializer of the variables the caller names (nothing else
//! changes). Everywhere else the pass is created from WGSL as before.

use naga::back::spv;
use naga::valid::{Capabilities, ValidationFlags, Validator};
use std::collections::HashMap;

/// SPIR-V opcodes this module reads.
const OP_NAME: u32 = 5;
const OP_VARIABLE: u32 = 59;
/// `StorageClass::Private`.
const STORAGE_PRIVATE: u32 = 6;
/// Words of an `OpVariable` with an initializer (opcode, type, id, storage class, initializer).
const VARIABLE_WITH_INIT_WORDS: usize = 5;
/// The SPIR-V header's length in words.
const HEADER_WORDS: usize = 5;

/// What [`compile_without_zero_init`] needs besides the source.
pub(crate) struct SpirvRequest<'a> {
    /// The compute entry point.
    pub entry_point: &'a str,
    /// The binding numbers of each bind group layout the pipeline is created with
    /// (`layout_bindings[g]` for group g, any order): wgpu-hal numbers a layout's Vulkan bindings
    /// by their position among the layout's entries sorted by binding number, so the shader must
    /// use the same numbers.
    pub layout_bindings: &'a [&'a [u32]],
    /// naga's runtime checks, as wgpu-hal applies them to a module from WGSL.
    pub checks: wgpu::ShaderRuntimeChecks,
    /// `var<private>` variables whose zero initializer is dropped. Each must exist in the module
    /// (a rename would otherwise silently bring the cost back), and the caller guarantees the
    /// shader never reads an element of one before writing it.
    pub uninitialized: &'a [&'a str],
}

/// A compiled module: its SPIR-V words and the entry point's workgroup size.
pub(crate) struct CompiledSpirv {
    /// The SPIR-V module.
    pub words: Vec<u32>,
    /// `@workgroup_size` of the entry point.
    pub workgroup_size: [u32; 3],
}

/// Compiles `source` for `request` (see the module comment). The error names what failed; the
/// caller falls back to creating the pass from WGSL.
pub(crate) fn compile_without_zero_init(
    source: &str,
    request: &SpirvRequest<'_>,
) -> Result<CompiledSpirv, String> {
    let module = naga::front::wgsl::parse_str(source).map_err(|e| e.emit_to_string(source))?;
    let info = Validator::new(ValidationFlags::all(), Capabilities::all())
        .validate(&module)
        .map_err(|e| e.emit_to_string(source))?;
    // As wgpu-hal does: the module reduced to the entry point (and overrides resolved).
    let (module, info) = naga::back::pipeline_constants::process_overrides(
        &module,
        &info,
        Some((naga::ShaderStage::Compute, request.entry_point)),
        &naga::back::PipelineConstants::default(),
    )
    .map_err(|e| format!("overrides: {e}"))?;
    let entry = module
        .entry_points
        .iter()
        .find(|ep| ep.name == request.entry_point && ep.stage == naga::ShaderStage::Compute)
        .ok_or_else(|| format!("no compute entry point `{}`", request.entry_point))?;
    let workgroup_size = entry.workgroup_size;
    let options = spv_options(request);
    let pipeline = spv::PipelineOptions {
        shader_stage: naga::ShaderStage::Compute,
        entry_point: request.entry_point.to_string(),
    };
    let mut words =
        spv::write_vec(&module, &info, &options, Some(&pipeline)).map_err(|e| e.to_string())?;
    drop_initializers(&mut words, request.uninitialized)?;
    Ok(CompiledSpirv {
        words,
        workgroup_size,
    })
}

/// wgpu-hal's SPIR-V options for a compute pipeline, with `request`'s checks and bindings.
fn spv_options(request: &SpirvRequest<'_>) -> spv::Options<'static> {
    let mut binding_map = spv::BindingMap::default();
    for (group, bindings) in request.layout_bindings.iter().enumerate() {
        let mut sorted = bindings.to_vec();
        sorted.sort_unstable();
        for (vulkan_binding, &binding) in sorted.iter().enumerate() {
            binding_map.insert(
                naga::ResourceBinding {
                    group: group as u32,
                    binding,
                },
                spv::BindingInfo {
                    descriptor_set: group as u32,
                    binding: vulkan_binding as u32,
                    binding_array_size: None,
                },
            );
        }
    }
    let checks = &request.checks;
    let policy = if checks.bounds_checks {
        naga::proc::BoundsCheckPolicy::Restrict
    } else {
        naga::proc::BoundsCheckPolicy::Unchecked
    };
    spv::Options {
        // SPIR-V 1.0: what every Vulkan driver accepts, as wgpu-hal writes for a Vulkan 1.0
        // device (it writes the newest the device's API version allows; the traversal passes use
        // nothing newer, and the driver's code is the same). wgpu does not tell us the device's
        // API version, and a newer version would fail on a Vulkan 1.0 device.
        lang_version: (1, 0),
        // Names only (no source or line info): they find the variables to change.
        flags: spv::WriterFlags::DEBUG,
        // An unmapped binding is an error: the layouts must name every binding the shader uses.
        fake_missing_bindings: false,
        binding_map,
        capabilities: None,
        bounds_check_policies: naga::proc::BoundsCheckPolicies {
            index: policy,
            // Buffers unchecked either way, as wgpu-hal writes them on every device with
            // robustBufferAccess2 (desktop drivers): the device's robust buffer access already
            // keeps every access inside its binding (robustBufferAccess, which every Vulkan
            // device has and wgpu-hal enables, is memory-safe too). Clamping them here as well
            // measured slower on the H100 (docs/decisions/buffer-bounds-checks.md).
            buffer: naga::proc::BoundsCheckPolicy::Unchecked,
            image_load: policy,
            binding_array: naga::proc::BoundsCheckPolicy::Unchecked,
        },
        zero_initialize_workgroup_memory: spv::ZeroInitializeWorkgroupMemoryMode::Polyfill,
        force_loop_bounding: checks.force_loop_bounding,
        ray_query_initialization_tracking: checks.ray_query_initialization_tracking,
        trace_ray_argument_validation: true,
        use_storage_input_output_16: false,
        debug_info: None,
        task_dispatch_limits: None,
        mesh_shader_primitive_indices_clamp: checks.mesh_shader_primitive_indices_clamp,
        emit_int_div_checks: checks.int_div_checks,
    }
}

/// Removes the initializer operand of each `OpVariable` in the Private storage class whose
/// `OpName` is in `names`. Every name must be found, with an initializer.
fn drop_initializers(words: &mut Vec<u32>, names: &[&str]) -> Result<(), String> {
    let instructions = instructions(words)?;
    let mut ids: HashMap<u32, &str> = HashMap::new();
    for &(start, count) in &instructions {
        if words[start] & 0xffff == OP_NAME && count >= 3 {
            let name = literal_string(&words[start + 2..start + count]);
            if let Some(&wanted) = names.iter().find(|&&n| n == name) {
                ids.insert(words[start + 1], wanted);
            }
        }
    }
    let mut dropped = Vec::new();
    let mut out = Vec::with_capacity(words.len());
    out.extend_from_slice(&words[..HEADER_WORDS]);
    for &(start, count) in &instructions {
        let inst = &words[start..start + count];
        let is_target = inst[0] & 0xffff == OP_VARIABLE
            && count == VARIABLE_WITH_INIT_WORDS
            && inst[3] == STORAGE_PRIVATE
            && ids.contains_key(&inst[2]);
        if is_target {
            out.push(((count as u32 - 1) << 16) | OP_VARIABLE);
            out.extend_from_slice(&inst[1..count - 1]);
            dropped.push(ids[&inst[2]]);
        } else {
            out.extend_from_slice(inst);
        }
    }
    if let Some(missing) = names.iter().find(|n| !dropped.contains(n)) {
        return Err(format!(
            "no zero-initialised `var<private> {missing}` in the module"
        ));
    }
    *words = out;
    Ok(())
}

/// (first word, word count) of every instruction after the header.
fn instructions(words: &[u32]) -> Result<Vec<(usize, usize)>, String> {
    if words.len() < HEADER_WORDS || words[0] != 0x0723_0203 {
        return Err("not a SPIR-V module".into());
    }
    let mut out = Vec::new();
    let mut at = HEADER_WORDS;
    while at < words.len() {
        let count = (words[at] >> 16) as usize;
        if count == 0 || at + count > words.len() {
            return Err(format!("malformed instruction at word {at}"));
        }
        out.push((at, count));
        at += count;
    }
    Ok(out)
}

/// A SPIR-V literal string (UTF-8, nul-terminated, packed little-endian into words).
fn literal_string(words: &[u32]) -> String {
    let bytes: Vec<u8> = words.iter().flat_map(|w| w.to_le_bytes()).collect();
    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
    String::from_utf8_lossy(&bytes[..end]).into_owned()
}

/// Whether the unit tests' device ([`crate::gpu::testing::gpu`]) must get the traversal passes
/// from our own SPIR-V, stated from how that device is made rather than by
/// [`crate::gpu::shader::spirv_accepted`] (the decision under test): it asks for every optional
/// feature the adapter has unless `KSRT_TEST_MINIMAL_DEVICE=1` (then for none), and wgpu-hal's
/// Vulkan adapters all offer `PASSTHROUGH_SHADERS`, other backends never take SPIR-V. So: on
/// Vulkan, yes, unless the device is the minimal one.
#[cfg(test)]
pub(crate) fn test_device_takes_own_spirv(device: &wgpu::Device) -> bool {
    let minimal = std::env::var("KSRT_TEST_MINIMAL_DEVICE").is_ok_and(|v| v == "1");
    device.adapter_info().backend == wgpu::Backend::Vulkan && !minimal
}

#[cfg(test)]
mod tests {
    use super::*;

    const SHADER: &str = "
        var<private> stack: array<u32, 16>;
        var<private> other: array<u32, 4>;
        @group(0) @binding(3) var<storage, read_write> out: array<u32>;
        @compute @workgroup_size(8, 2, 1)
        fn main(@builtin(global_invocation_id) id: vec3<u32>) {
            stack[id.x % 16u] = id.x;
            other[0] = 1u;
            out[id.x] = stack[id.x % 16u] + other[id.x % 4u];
        }
    ";

    /// (storage class, has initializer) of each `OpVariable` named `name`.
    fn variable(words: &[u32], name: &str) -> Option<(u32, bool)> {
        let insts = instructions(words).ok()?;
        let id = insts.iter().find_map(|&(s, c)| {
            (words[s] & 0xffff == OP_NAME && literal_string(&words[s + 2..s + c]) == name)
                .then_some(words[s + 1])
        })?;
        insts.iter().find_map(|&(s, c)| {
            (words[s] & 0xffff == OP_VARIABLE && words[s + 2] == id)
                .then_some((words[s + 3], c == VARIABLE_WITH_INIT_WORDS))
        })
    }

    fn request<'a>(uninitialized: &'a [&'a str], bindings: &'a [&'a [u32]]) -> SpirvRequest<'a> {
        SpirvRequest {
            entry_point: "main",
            layout_bindings: bindings,
            checks: wgpu::ShaderRuntimeChecks::unchecked(),
            uninitialized,
        }
    }

    #[test]
    fn drops_only_the_named_initializer() {
        let compiled =
            compile_without_zero_init(SHADER, &request(&["stack"], &[&[3]])).expect("compiles");
        assert_eq!(compiled.workgroup_size, [8, 2, 1]);
        assert_eq!(
            variable(&compiled.words, "stack"),
            Some((STORAGE_PRIVATE, false))
        );
        // naga's own output keeps WGSL's zero initializer on every other private variable.
        assert_eq!(
            variable(&compiled.words, "other"),
            Some((STORAGE_PRIVATE, true))
        );
        // The instruction stream still parses word for word.
        assert!(instructions(&compiled.words).is_ok());
    }

    #[test]
    fn a_missing_name_is_an_error() {
        let err = compile_without_zero_init(SHADER, &request(&["stak"], &[&[3]]))
            .err()
            .expect("a misspelt variable must fail");
        assert!(err.contains("stak"), "{err}");
    }

    #[test]
    fn bindings_are_numbered_as_wgpu_hal_numbers_them() {
        // Layout entries 1, 3, 7 in group 0: the shader's binding 3 is Vulkan binding 1.
        let compiled = compile_without_zero_init(SHADER, &request(&["stack"], &[&[7, 3, 1]]))
            .expect("compiles");
        const OP_DECORATE: u32 = 71;
        const DECORATION_BINDING: u32 = 33;
        let bindings: Vec<u32> = instructions(&compiled.words)
            .expect("parses")
            .iter()
            .filter(|&&(s, c)| {
                compiled.words[s] & 0xffff == OP_DECORATE
                    && c == 4
                    && compiled.words[s + 2] == DECORATION_BINDING
            })
            .map(|&(s, _)| compiled.words[s + 3])
            .collect();
        assert_eq!(bindings, vec![1]);
    }

    #[test]
    fn an_unmapped_binding_is_an_error() {
        assert!(compile_without_zero_init(SHADER, &request(&["stack"], &[&[0, 1]])).is_err());
    }
}
