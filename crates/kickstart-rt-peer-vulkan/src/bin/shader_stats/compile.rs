//! WGSL → SPIR-V the way wgpu 30 does it for a Vulkan compute pipeline, and the pipeline layout
//! wgpu's automatic layout (`layout: None`, what the SDK uses) would derive. Needs no GPU.
//!
//! What is mirrored, and where it comes from:
//! - parsing and validation: `wgpu-core` `Device::create_shader_module` (WGSL front end and
//!   validator with the capabilities of the SDK's features, [`validation_capabilities`],
//!   `ValidationFlags::all()`);
//! - one module per entry point: wgpu-hal's Vulkan backend always sets its
//!   `SEPARATE_ENTRY_POINTS` workaround, so `compile_stage` calls
//!   `naga::back::pipeline_constants::process_overrides` for the entry point (which compacts the
//!   module to what it reaches where there are several entry points or overrides) and writes
//!   SPIR-V for that entry point only (naga leaves out the globals it does not use);
//! - `naga::back::spv::Options`: wgpu-hal `vulkan/adapter.rs` (`naga_options`), adjusted as
//!   `vulkan/device.rs` `compile_stage` does for `ShaderRuntimeChecks::checked()` (the default)
//!   or `unchecked()` ([`spv_options`]);
//! - the binding map: wgpu-hal numbers each group's Vulkan bindings 0, 1, 2… in the order of the
//!   bind group layout's entries, which wgpu-core sorts by WGSL binding ([`derive_layout`]).

use std::fmt;

use naga::back::spv;
use naga::proc::{BoundsCheckPolicies, BoundsCheckPolicy};
use naga::valid::{Capabilities, ModuleInfo, ValidationFlags, Validator};

/// The WGSL files of one pass, concatenated with `"\n"` (as the SDK's `assemble` does), with
/// where each file starts so that error locations can name the file and its line.
pub struct Source {
    /// The concatenated text.
    pub text: String,
    /// `(path, first line in `text`, 1-based)` of each file, in order.
    files: Vec<(String, u32)>,
}

impl Source {
    /// Concatenates `(path, text)` parts with `"\n"`.
    pub fn concat(parts: &[(String, String)]) -> Source {
        let mut files = Vec::with_capacity(parts.len());
        let mut line = 1u32;
        let mut texts = Vec::with_capacity(parts.len());
        for (path, text) in parts {
            files.push((path.clone(), line));
            // This file's lines, plus the one the joining "\n" ends.
            line += text.bytes().filter(|&b| b == b'\n').count() as u32 + 1;
            texts.push(text.as_str());
        }
        Source {
            text: texts.join("\n"),
            files,
        }
    }

    /// The file and 1-based line within it of 1-based line `line` of the concatenation.
    pub fn locate(&self, line: u32) -> (&str, u32) {
        let k = self
            .files
            .iter()
            .rposition(|&(_, first)| first <= line)
            .unwrap_or(0);
        match self.files.get(k) {
            Some((path, first)) => (path.as_str(), line + 1 - first),
            None => ("<no input>", line),
        }
    }

    /// `" at path:line:column"` of the first defined span of an error (some labels carry an
    /// undefined span), or nothing.
    fn at(&self, mut spans: impl Iterator<Item = naga::Span>) -> String {
        match spans
            .find(|s| s.is_defined() && s.to_range().is_some_and(|r| r.end <= self.text.len()))
        {
            Some(span) => {
                let loc = span.location(&self.text);
                let (path, line) = self.locate(loc.line_number);
                format!(" at {path}:{line}:{}", loc.line_position)
            }
            None => String::new(),
        }
    }

    /// A label for the concatenation in naga's diagnostics (line numbers there count from the
    /// first file's first line).
    fn label(&self) -> String {
        let names: Vec<&str> = self.files.iter().map(|(p, _)| p.as_str()).collect();
        if names.len() == 1 {
            names[0].to_string()
        } else {
            format!("<{} concatenated>", names.join(" + "))
        }
    }
}

/// A parsing, validation or SPIR-V generation failure, with naga's text.
#[derive(Debug)]
pub struct CompileError(pub String);

impl fmt::Display for CompileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// The validator capabilities wgpu-core gives a device with every optional feature the SDK
/// requests (`kickstart_rt::optional_features()`: `SUBGROUP`, `SHADER_F16`,
/// `SHADER_INT64_ATOMIC_MIN_MAX`, …) and desktop downlevel flags (cube arrays, multisampled
/// shading, f16 in f32), as on an H100 (`wgpu_naga_bridge::features_to_naga_capabilities`);
/// plus `IMMEDIATES` (`var<immediate>`, bound as push constants), which the SDK does not use.
pub fn validation_capabilities() -> Capabilities {
    Capabilities::IMMEDIATES
        | Capabilities::SUBGROUP
        | Capabilities::SHADER_FLOAT16
        | Capabilities::SHADER_FLOAT16_IN_FLOAT32
        | Capabilities::SHADER_INT64_ATOMIC_MIN_MAX
        | Capabilities::CUBE_ARRAY_TEXTURES
        | Capabilities::MULTISAMPLED_SHADING
}

/// Parses and validates the concatenated WGSL as wgpu-core does.
pub fn parse_and_validate(src: &Source) -> Result<(naga::Module, ModuleInfo), CompileError> {
    let mut options = naga::front::wgsl::Options::new();
    options.capabilities = validation_capabilities();
    let mut frontend = naga::front::wgsl::Frontend::new_with_options(options);
    let module = frontend.parse(&src.text).map_err(|e| {
        let at = src.at(e.labels().map(|(span, _)| span));
        CompileError(format!(
            "WGSL parse error{at}:\n{}",
            e.emit_to_string_with_path(&src.text, &src.label())
        ))
    })?;
    let info = Validator::new(ValidationFlags::all(), validation_capabilities())
        .validate(&module)
        .map_err(|e| {
            let at = src.at(e.spans().map(|&(span, _)| span));
            CompileError(format!(
                "WGSL validation error{at}:\n{}",
                e.emit_to_string_with_path(&src.text, &src.label())
            ))
        })?;
    Ok((module, info))
}

/// The compute entry points of `module`, in declaration order.
pub fn compute_entry_points(module: &naga::Module) -> Vec<String> {
    module
        .entry_points
        .iter()
        .filter(|ep| ep.stage == naga::ShaderStage::Compute)
        .map(|ep| ep.name.clone())
        .collect()
}

/// What a descriptor binding is, as a Vulkan descriptor type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum DescriptorKind {
    /// `var<uniform>`: `VK_DESCRIPTOR_TYPE_UNIFORM_BUFFER`.
    UniformBuffer,
    /// `var<storage, read>` (`read_only`) or `var<storage, read_write>`:
    /// `VK_DESCRIPTOR_TYPE_STORAGE_BUFFER`.
    StorageBuffer {
        /// `read` access only.
        read_only: bool,
    },
    /// A sampled or depth texture: `VK_DESCRIPTOR_TYPE_SAMPLED_IMAGE`.
    SampledImage,
    /// A storage texture: `VK_DESCRIPTOR_TYPE_STORAGE_IMAGE`.
    StorageImage,
    /// A sampler (comparison or not): `VK_DESCRIPTOR_TYPE_SAMPLER`.
    Sampler,
}

impl fmt::Display for DescriptorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            DescriptorKind::UniformBuffer => "uniform",
            DescriptorKind::StorageBuffer { read_only: true } => "storage(read)",
            DescriptorKind::StorageBuffer { read_only: false } => "storage(read_write)",
            DescriptorKind::SampledImage => "sampled-image",
            DescriptorKind::StorageImage => "storage-image",
            DescriptorKind::Sampler => "sampler",
        })
    }
}

/// One descriptor binding an entry point uses.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Binding {
    /// `@group` (the Vulkan descriptor set).
    pub group: u32,
    /// `@binding` in the WGSL.
    pub binding: u32,
    /// The Vulkan binding wgpu gives it: its rank among the group's bindings that the entry
    /// point uses.
    pub vk_binding: u32,
    /// Descriptor type.
    pub kind: DescriptorKind,
    /// Descriptor count (binding arrays; 1 otherwise).
    pub count: u32,
    /// The global's name in the WGSL.
    pub name: String,
}

/// The pipeline layout of one entry point.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Layout {
    /// Sorted by (group, binding).
    pub bindings: Vec<Binding>,
    /// Bytes of `var<immediate>` (push constants); 0 without.
    pub push_constant_size: u32,
}

impl Layout {
    /// Number of descriptor sets (highest group + 1; the groups between get empty layouts).
    pub fn set_count(&self) -> u32 {
        self.bindings.iter().map(|b| b.group + 1).max().unwrap_or(0)
    }

    /// wgpu-hal's `BindingMap` for this layout.
    fn binding_map(&self) -> spv::BindingMap {
        self.bindings
            .iter()
            .map(|b| {
                (
                    naga::ResourceBinding {
                        group: b.group,
                        binding: b.binding,
                    },
                    spv::BindingInfo {
                        descriptor_set: b.group,
                        binding: b.vk_binding,
                        binding_array_size: None,
                    },
                )
            })
            .collect()
    }
}

/// Derives the layout of entry point `ep` (an index into `module.entry_points`): the globals
/// with a binding that it uses (wgpu's automatic layout; naga's SPIR-V writer leaves the others
/// out of the entry point's module).
pub fn derive_layout(
    module: &naga::Module,
    info: &ModuleInfo,
    ep: usize,
) -> Result<Layout, CompileError> {
    let mut layout = Layout::default();
    let uses = info.get_entry_point(ep);
    for (handle, var) in module.global_variables.iter() {
        if uses[handle].is_empty() {
            continue;
        }
        let name = var.name.clone().unwrap_or_else(|| "<unnamed>".to_string());
        if var.space == naga::AddressSpace::Immediate {
            layout.push_constant_size = module.types[var.ty].inner.size(module.to_ctx());
            continue;
        }
        let Some(rb) = var.binding else { continue };
        let (inner, count) = match module.types[var.ty].inner {
            naga::TypeInner::BindingArray { base, size } => {
                let count = match size {
                    naga::ArraySize::Constant(n) => n.get(),
                    _ => {
                        return Err(CompileError(format!(
                            "binding array `{name}` (@group({}) @binding({})) has no fixed size; \
                             not supported by this tool",
                            rb.group, rb.binding
                        )))
                    }
                };
                (&module.types[base].inner, count)
            }
            ref other => (other, 1),
        };
        let kind = match var.space {
            naga::AddressSpace::Uniform => DescriptorKind::UniformBuffer,
            naga::AddressSpace::Storage { access } => DescriptorKind::StorageBuffer {
                read_only: !access.contains(naga::StorageAccess::STORE),
            },
            naga::AddressSpace::Handle => match *inner {
                naga::TypeInner::Image { class, .. } => match class {
                    naga::ImageClass::Sampled { .. } | naga::ImageClass::Depth { .. } => {
                        DescriptorKind::SampledImage
                    }
                    naga::ImageClass::Storage { .. } => DescriptorKind::StorageImage,
                    naga::ImageClass::External => {
                        return Err(CompileError(format!(
                            "`{name}` is an external texture; not supported by this tool"
                        )))
                    }
                },
                naga::TypeInner::Sampler { .. } => DescriptorKind::Sampler,
                _ => {
                    return Err(CompileError(format!(
                        "`{name}` (@group({}) @binding({})) is a resource this tool does not \
                         bind (acceleration structure?)",
                        rb.group, rb.binding
                    )))
                }
            },
            other => {
                return Err(CompileError(format!(
                    "`{name}` has a binding in address space {other:?}; not supported"
                )))
            }
        };
        layout.bindings.push(Binding {
            group: rb.group,
            binding: rb.binding,
            vk_binding: 0,
            kind,
            count,
            name,
        });
    }
    layout.bindings.sort_by_key(|b| (b.group, b.binding));
    let mut k = 0;
    for i in 0..layout.bindings.len() {
        if i > 0 && layout.bindings[i - 1].group != layout.bindings[i].group {
            k = 0;
        }
        layout.bindings[i].vk_binding = k;
        k += 1;
    }
    Ok(layout)
}

/// What of the Vulkan device changes wgpu's SPIR-V options.
#[derive(Debug, Clone, Copy)]
pub struct Target {
    /// `VkPhysicalDeviceProperties::apiVersion` (picks the SPIR-V version).
    pub api_version: u32,
    /// `robustBufferAccess2` enabled: buffer bounds checks are left to the driver.
    pub robust_buffer_access2: bool,
    /// `robustImageAccess2` or `robustImageAccess` enabled: image loads are left to the driver.
    pub robust_image_access: bool,
    /// `shaderZeroInitializeWorkgroupMemory` enabled: native zero-initialisation.
    pub zero_initialize_workgroup_memory: bool,
    /// PCI vendor id (Qualcomm gets no `LABEL_VARYINGS`).
    pub vendor_id: u32,
}

impl Target {
    /// A Vulkan 1.3 device with robustness2 and native zero-initialisation, as an H100 is.
    #[cfg(test)]
    pub fn h100_like() -> Target {
        Target {
            api_version: ash_api_version(1, 3),
            robust_buffer_access2: true,
            robust_image_access: true,
            zero_initialize_workgroup_memory: true,
            vendor_id: 0x10de,
        }
    }
}

#[cfg(test)]
const fn ash_api_version(major: u32, minor: u32) -> u32 {
    (major << 22) | (minor << 12)
}

/// The SPIR-V version wgpu-hal writes for a device API version.
pub fn spirv_version(api_version: u32) -> (u8, u8) {
    let (major, minor) = (api_version >> 22 & 0x7f, api_version >> 12 & 0x3ff);
    match (major, minor) {
        (1, 0) | (0, _) => (1, 0),
        (1, 1) => (1, 3),
        (1, 2) => (1, 5),
        _ => (1, 6),
    }
}

/// wgpu-hal's `naga_options` for `target`, with `compile_stage`'s per-pipeline changes for
/// `ShaderRuntimeChecks::checked()` (`checked`) or `::unchecked()`. `capabilities` is left
/// `None`: wgpu's list only restricts what a module may use; the words written are the same.
pub fn spv_options(target: &Target, checked: bool, layout: &Layout) -> spv::Options<'static> {
    const QUALCOMM: u32 = 0x5143;
    let mut flags = spv::WriterFlags::empty();
    flags.set(
        spv::WriterFlags::LABEL_VARYINGS,
        target.vendor_id != QUALCOMM,
    );
    flags.set(spv::WriterFlags::FORCE_POINT_SIZE, true);
    let bounds_check_policies = if checked {
        BoundsCheckPolicies {
            index: BoundsCheckPolicy::Restrict,
            buffer: if target.robust_buffer_access2 {
                BoundsCheckPolicy::Unchecked
            } else {
                BoundsCheckPolicy::Restrict
            },
            image_load: if target.robust_image_access {
                BoundsCheckPolicy::Unchecked
            } else {
                BoundsCheckPolicy::Restrict
            },
            binding_array: BoundsCheckPolicy::Unchecked,
        }
    } else {
        BoundsCheckPolicies {
            index: BoundsCheckPolicy::Unchecked,
            buffer: BoundsCheckPolicy::Unchecked,
            image_load: BoundsCheckPolicy::Unchecked,
            binding_array: BoundsCheckPolicy::Unchecked,
        }
    };
    spv::Options {
        lang_version: spirv_version(target.api_version),
        flags,
        fake_missing_bindings: false,
        binding_map: layout.binding_map(),
        capabilities: None,
        bounds_check_policies,
        // The default `PipelineCompilationOptions::zero_initialize_workgroup_memory` is true.
        zero_initialize_workgroup_memory: if target.zero_initialize_workgroup_memory {
            spv::ZeroInitializeWorkgroupMemoryMode::Native
        } else {
            spv::ZeroInitializeWorkgroupMemoryMode::Polyfill
        },
        force_loop_bounding: checked,
        ray_query_initialization_tracking: checked,
        trace_ray_argument_validation: true,
        use_storage_input_output_16: false,
        debug_info: None,
        task_dispatch_limits: None,
        mesh_shader_primitive_indices_clamp: checked,
        emit_int_div_checks: checked,
    }
}

/// One entry point ready for the driver.
#[derive(Debug, Clone)]
pub struct EntryModule {
    /// Entry point name.
    pub name: String,
    /// `@workgroup_size`.
    pub workgroup_size: [u32; 3],
    /// Its pipeline layout.
    pub layout: Layout,
    /// Bytes of `var<workgroup>` memory it reaches.
    pub workgroup_bytes: u32,
}

/// Prepares compute entry point `name` as wgpu-hal's `compile_stage` does (`process_overrides`
/// for it, which compacts the module where there are several entry points or overrides) and
/// derives its layout.
pub fn prepare_entry(
    module: &naga::Module,
    info: &ModuleInfo,
    name: &str,
) -> Result<(EntryModule, naga::Module, ModuleInfo), CompileError> {
    let constants = naga::back::PipelineConstants::default();
    let (m, i) = naga::back::pipeline_constants::process_overrides(
        module,
        info,
        Some((naga::ShaderStage::Compute, name)),
        &constants,
    )
    .map_err(|e| CompileError(format!("entry point `{name}`: overrides: {e}")))?;
    let (m, i) = (m.into_owned(), i.into_owned());
    let index = m
        .entry_points
        .iter()
        .position(|ep| ep.name == name && ep.stage == naga::ShaderStage::Compute)
        .ok_or_else(|| CompileError(format!("no compute entry point `{name}`")))?;
    let workgroup_size = m.entry_points[index].workgroup_size;
    let layout = derive_layout(&m, &i, index)
        .map_err(|e| CompileError(format!("entry point `{name}`: {e}")))?;
    let uses = i.get_entry_point(index);
    let workgroup_bytes = m
        .global_variables
        .iter()
        .filter(|&(h, v)| v.space == naga::AddressSpace::WorkGroup && !uses[h].is_empty())
        .map(|(_, v)| m.types[v.ty].inner.size(m.to_ctx()))
        .sum();
    Ok((
        EntryModule {
            name: name.to_string(),
            workgroup_size,
            layout,
            workgroup_bytes,
        },
        m,
        i,
    ))
}

/// Writes the SPIR-V of a module prepared by [`prepare_entry`].
pub fn write_spirv(
    entry: &EntryModule,
    module: &naga::Module,
    info: &ModuleInfo,
    target: &Target,
    checked: bool,
) -> Result<Vec<u32>, CompileError> {
    let options = spv_options(target, checked, &entry.layout);
    let pipeline = spv::PipelineOptions {
        shader_stage: naga::ShaderStage::Compute,
        entry_point: entry.name.clone(),
    };
    spv::write_vec(module, info, &options, Some(&pipeline))
        .map_err(|e| CompileError(format!("entry point `{}`: SPIR-V: {e}", entry.name)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The LBVH module as the SDK composes it (with the digit counting, centroid bounds,
    /// triangle boxes and vertex decoding it imports).
    fn lbvh() -> Source {
        let text = kickstart_rt::compose_shader(&["scene/lbvh/lbvh"], &[]).expect("composes");
        Source::concat(&[("scene/lbvh/lbvh".to_string(), text)])
    }

    /// `(group, WGSL binding, Vulkan binding, kind)` of entry point `ep`, and its workgroup
    /// memory bytes; checks that its SPIR-V is written with that binding map.
    fn layout_of(
        module: &naga::Module,
        info: &ModuleInfo,
        ep: &str,
    ) -> (Vec<(u32, u32, u32, DescriptorKind)>, u32) {
        let (entry, m, i) = prepare_entry(module, info, ep).expect("prepares");
        // The SPIR-V must be writable with the layout's binding map (no missing binding).
        let words = write_spirv(&entry, &m, &i, &Target::h100_like(), true).expect("SPIR-V");
        assert_eq!(words[0], 0x0723_0203, "SPIR-V magic");
        assert_eq!(words[1], 0x0001_0600, "SPIR-V 1.6 for a Vulkan 1.3 device");
        assert_eq!(
            entry.workgroup_size,
            [256, 1, 1],
            "WG = 256u in scene/lbvh/common.wgsl"
        );
        assert_eq!(entry.layout.push_constant_size, 0);
        assert_eq!(entry.layout.set_count(), 1);
        let got = entry
            .layout
            .bindings
            .iter()
            .map(|b| (b.group, b.binding, b.vk_binding, b.kind))
            .collect();
        (got, entry.workgroup_bytes)
    }

    /// The LBVH module, parsed and validated.
    fn lbvh_module() -> (naga::Module, ModuleInfo) {
        parse_and_validate(&lbvh()).expect("scene/lbvh/lbvh is valid")
    }

    use DescriptorKind::UniformBuffer as U;
    const R: DescriptorKind = DescriptorKind::StorageBuffer { read_only: true };
    const RW: DescriptorKind = DescriptorKind::StorageBuffer { read_only: false };

    /// The LBVH's passes, in the order the composed module holds them.
    #[test]
    fn lbvh_entry_points() {
        let (module, _) = lbvh_module();
        assert_eq!(
            compute_entry_points(&module),
            [
                "lbvh_bounds",
                "lbvh_morton",
                "lbvh_morton_histogram",
                "lbvh_segment_keys",
                "lbvh_rekey",
                "lbvh_gather",
                "lbvh_hierarchy",
                "lbvh_climb",
                "lbvh_refit_gather",
                "lbvh_refit_ingest",
                "lbvh_range_refit",
                "lbvh_compact_mark",
                "lbvh_compact_count",
                "lbvh_compact_scan",
                "lbvh_compact_assign",
                "lbvh_compact_scatter"
            ]
        );
    }

    /// scene/lbvh/common.wgsl declares, in @group(0): 0 `params` uniform, 1 `aabbs` storage read, 2 `work`
    /// (atomics), 3 `keys`, 4 `values`, 5 `order`, 6 `topology`, 7 `nodes`, 8 `bounds_out`,
    /// all storage read_write. Each entry point's layout holds what it reaches, as read in the
    /// source:
    /// - `lbvh_bounds`: `aabbs` (`prim_box`), `work` (`atomicMax`), 18 `segs` (storage read:
    ///   the batch's per-build params; the build passes read theirs there, not `params`);
    ///   workgroup memory `wg_bounds: array<atomic<u32>, 6>` = 24 bytes;
    /// - `lbvh_morton` and `lbvh_rekey`: `params` (the batch's position count), `aabbs`,
    ///   `work` (the scene bounds), `keys`, `values`, `segs`;
    /// - `lbvh_morton_histogram`: those and 10 `sort_hist` (the radix sort's histogram);
    ///   workgroup memory `wg_digit_bins: array<atomic<u32>, 2048>` = 8192 bytes;
    /// - `lbvh_segment_keys`: `params`, `keys`, `values`, `segs`;
    /// - `lbvh_gather`: `params`, `order`, `refit_src`, `refit_dst`, `segs`;
    /// - `lbvh_hierarchy`: `keys` (`delta`), `values`, `order`, `topology`, `segs`;
    /// - `lbvh_climb`: `params`, `aabbs` (`leaf_box`), `work`, `order`, `topology`, `nodes`
    ///   (`write_node`), `bounds_out` (`write_bounds`). (Its workgroup memory is left out: it
    ///   changes whenever the climb is tuned.)
    /// - `lbvh_refit_gather`: `params`, `work` (the straddling nodes' lists, the pyramid's
    ///   upper levels), `order`, `topology`, `nodes`, `bounds_out`, 11 `pyramid`, 12
    ///   `refit_src` (storage read) and 13 `refit_dst`; workgroup memory `wg_pyramid_lo`,
    ///   `wg_pyramid_hi: array<vec3<f32>, 511>` = 2 × 8176 bytes, plus `wg_straddlers`, 4 bytes;
    /// - `lbvh_refit_ingest`: as `lbvh_refit_gather` without `bounds_out` and `refit_src`,
    ///   with 14 `raw` (storage read), 15 `ingest_rows` (a uniform) and 16 `ingest_counters`:
    ///   eight storage buffers, the default limit;
    /// - `lbvh_range_refit`: `params`, `order` (`out_ref`), `topology`, `nodes`, `bounds_out`,
    ///   `pyramid`, `refit_dst` (leaf boxes from the triangles) and 17 `work_read` (the list
    ///   and the upper levels, read-only: not binding 2's atomics).
    ///
    /// Vulkan bindings are the ranks within the group (wgpu-hal's numbering). The build's
    /// passes here, the range refit's in [`lbvh_refit_bindings`].
    #[test]
    fn lbvh_build_bindings() {
        let (module, info) = lbvh_module();
        let got = |ep| layout_of(&module, &info, ep);
        assert_eq!(
            got("lbvh_bounds"),
            (vec![(0, 1, 0, R), (0, 2, 1, RW), (0, 18, 2, R)], 24)
        );
        let morton = vec![
            (0, 0, 0, U),
            (0, 1, 1, R),
            (0, 2, 2, RW),
            (0, 3, 3, RW),
            (0, 4, 4, RW),
            (0, 18, 5, R),
        ];
        assert_eq!(got("lbvh_morton"), (morton.clone(), 0));
        assert_eq!(got("lbvh_rekey"), (morton, 0));
        assert_eq!(
            got("lbvh_segment_keys"),
            (
                vec![(0, 0, 0, U), (0, 3, 1, RW), (0, 4, 2, RW), (0, 18, 3, R)],
                0
            )
        );
        assert_eq!(
            got("lbvh_gather"),
            (
                vec![
                    (0, 0, 0, U),
                    (0, 5, 1, RW),
                    (0, 12, 2, R),
                    (0, 13, 3, RW),
                    (0, 18, 4, R)
                ],
                0
            )
        );
        assert_eq!(
            got("lbvh_morton_histogram"),
            (
                vec![
                    (0, 0, 0, U),
                    (0, 1, 1, R),
                    (0, 2, 2, RW),
                    (0, 3, 3, RW),
                    (0, 4, 4, RW),
                    (0, 10, 5, RW),
                    (0, 18, 6, R)
                ],
                8192
            )
        );
        assert_eq!(
            got("lbvh_hierarchy"),
            (
                vec![
                    (0, 3, 0, RW),
                    (0, 4, 1, RW),
                    (0, 5, 2, RW),
                    (0, 6, 3, RW),
                    (0, 18, 4, R)
                ],
                0
            )
        );
        assert_eq!(
            got("lbvh_climb").0,
            [
                (0, 0, 0, U),
                (0, 1, 1, R),
                (0, 2, 2, RW),
                (0, 5, 3, RW),
                (0, 6, 4, RW),
                (0, 7, 5, RW),
                (0, 8, 6, RW),
            ]
        );
    }

    /// The range refit's passes' bindings, as documented at [`lbvh_build_bindings`].
    #[test]
    fn lbvh_refit_bindings() {
        let (module, info) = lbvh_module();
        let got = |ep| layout_of(&module, &info, ep);
        assert_eq!(
            got("lbvh_refit_gather"),
            (
                vec![
                    (0, 0, 0, U),
                    (0, 2, 1, RW),
                    (0, 5, 2, RW),
                    (0, 6, 3, RW),
                    (0, 7, 4, RW),
                    (0, 8, 5, RW),
                    (0, 11, 6, RW),
                    (0, 12, 7, R),
                    (0, 13, 8, RW),
                    (0, 19, 9, U)
                ],
                16356
            )
        );
        assert_eq!(
            got("lbvh_refit_ingest"),
            (
                vec![
                    (0, 0, 0, U),
                    (0, 2, 1, RW),
                    (0, 5, 2, RW),
                    (0, 6, 3, RW),
                    (0, 7, 4, RW),
                    (0, 11, 5, RW),
                    (0, 13, 6, RW),
                    (0, 14, 7, R),
                    (0, 15, 8, U),
                    (0, 16, 9, RW),
                    (0, 19, 10, U)
                ],
                16356
            )
        );
        assert_eq!(
            got("lbvh_range_refit"),
            (
                vec![
                    (0, 0, 0, U),
                    (0, 5, 1, RW),
                    (0, 6, 2, RW),
                    (0, 7, 3, RW),
                    (0, 8, 4, RW),
                    (0, 11, 5, RW),
                    (0, 13, 6, RW),
                    (0, 17, 7, R),
                    (0, 19, 8, U)
                ],
                0
            )
        );
    }

    #[test]
    fn vulkan_bindings_are_ranks_within_each_group() {
        let text = "
            @group(0) @binding(3) var<storage, read_write> a: array<u32>;
            @group(0) @binding(7) var<uniform> b: vec4<u32>;
            @group(2) @binding(5) var<storage, read> c: array<u32>;
            @group(2) @binding(1) var<storage, read> unused: array<u32>;
            var<immediate> pc: vec4<u32>;
            @compute @workgroup_size(8, 4)
            fn main(@builtin(global_invocation_id) id: vec3<u32>) {
                a[id.x] = b.x + c[id.y] + pc.z;
            }";
        let src = Source::concat(&[("t.wgsl".to_string(), text.to_string())]);
        let (module, info) = parse_and_validate(&src).expect("valid");
        let (entry, m, i) = prepare_entry(&module, &info, "main").expect("prepares");
        let got: Vec<_> = entry
            .layout
            .bindings
            .iter()
            .map(|b| (b.group, b.binding, b.vk_binding, b.kind))
            .collect();
        assert_eq!(
            got,
            [
                (0, 3, 0, DescriptorKind::StorageBuffer { read_only: false }),
                (0, 7, 1, DescriptorKind::UniformBuffer),
                (2, 5, 0, DescriptorKind::StorageBuffer { read_only: true }),
            ]
        );
        assert_eq!(entry.layout.set_count(), 3);
        assert_eq!(entry.layout.push_constant_size, 16);
        assert_eq!(entry.workgroup_size, [8, 4, 1]);
        write_spirv(&entry, &m, &i, &Target::h100_like(), false).expect("SPIR-V");
    }

    #[test]
    fn errors_name_the_file_and_line() {
        let parts = [
            ("a.wgsl".to_string(), "const A: u32 = 1u;\n".to_string()),
            (
                "b.wgsl".to_string(),
                "fn f() -> u32 {\n  return B;\n}".to_string(),
            ),
        ];
        let src = Source::concat(&parts);
        assert_eq!(src.locate(1), ("a.wgsl", 1));
        assert_eq!(src.locate(3), ("b.wgsl", 1));
        assert_eq!(src.locate(4), ("b.wgsl", 2));
        let err = parse_and_validate(&src).expect_err("B is undefined");
        assert!(err.0.contains("at b.wgsl:2:"), "{err}");
        // An error whose first label has no span (the conversion's destination) is placed by
        // the next one.
        let parts = [
            ("a.wgsl".to_string(), "const A: u32 = 1u;".to_string()),
            (
                "b.wgsl".to_string(),
                "fn f() -> u32 { return 1.5; }".to_string(),
            ),
        ];
        let err = parse_and_validate(&Source::concat(&parts)).expect_err("1.5 is no u32");
        assert!(err.0.contains("at b.wgsl:1:24"), "{err}");
    }

    #[test]
    fn spirv_versions_follow_the_device_api() {
        assert_eq!(spirv_version(ash_api_version(1, 0)), (1, 0));
        assert_eq!(spirv_version(ash_api_version(1, 1)), (1, 3));
        assert_eq!(spirv_version(ash_api_version(1, 2)), (1, 5));
        assert_eq!(spirv_version(ash_api_version(1, 3)), (1, 6));
        assert_eq!(spirv_version(ash_api_version(1, 4) | 305), (1, 6));
    }
}
