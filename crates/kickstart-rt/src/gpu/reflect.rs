//! Binding numbers read from the shader itself (naga reflection), so that no Rust table repeats
//! them: a pass names the buffers it binds by the names of the shader's globals, and
//! [`ReflectedPipeline::bind_group`] puts each at the binding the shader declares for it.
//!
//! The bindings of an entry point are the globals its call tree uses (naga's analysis), which are
//! exactly the entries of the automatic layout wgpu creates for it.

use naga::valid::{Capabilities, ValidationFlags, Validator};

/// What kind of resource a binding is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ResourceKind {
    /// `var<uniform>`.
    Uniform,
    /// `var<storage, read>` (`read_only`) or `var<storage, read_write>`.
    Storage {
        /// Declared `read` (no stores, no atomics).
        read_only: bool,
    },
    /// A texture, storage texture or sampler.
    Handle,
}

/// One resource an entry point uses.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct ShaderBinding {
    /// `@group`.
    pub group: u32,
    /// `@binding`.
    pub binding: u32,
    /// The global's name in the shader.
    pub name: String,
    /// Its kind.
    pub kind: ResourceKind,
}

/// A parsed and validated WGSL module, for reading its entry points' bindings.
pub(crate) struct ShaderReflection {
    module: naga::Module,
    info: naga::valid::ModuleInfo,
}

impl ShaderReflection {
    /// Parses and validates `source`; the error is naga's message.
    pub fn new(source: &str) -> Result<Self, String> {
        let module = naga::front::wgsl::parse_str(source).map_err(|e| e.emit_to_string(source))?;
        let info = Validator::new(ValidationFlags::all(), Capabilities::all())
            .validate(&module)
            .map_err(|e| e.emit_to_string(source))?;
        Ok(ShaderReflection { module, info })
    }

    /// The bindings `entry_point` uses (through any function it calls), sorted by group and
    /// binding; `None` when the module has no such entry point.
    pub fn entry_point_bindings(&self, entry_point: &str) -> Option<Vec<ShaderBinding>> {
        let index = self
            .module
            .entry_points
            .iter()
            .position(|ep| ep.name == entry_point)?;
        let uses = self.info.get_entry_point(index);
        let mut bindings: Vec<ShaderBinding> = self
            .module
            .global_variables
            .iter()
            .filter(|&(handle, _)| !uses[handle].is_empty())
            .filter_map(|(_, var)| {
                let rb = var.binding.as_ref()?;
                let kind = match var.space {
                    naga::AddressSpace::Uniform => ResourceKind::Uniform,
                    naga::AddressSpace::Storage { access } => ResourceKind::Storage {
                        read_only: !access.contains(naga::StorageAccess::STORE),
                    },
                    _ => ResourceKind::Handle,
                };
                Some(ShaderBinding {
                    group: rb.group,
                    binding: rb.binding,
                    name: var.name.clone().unwrap_or_default(),
                    kind,
                })
            })
            .collect();
        bindings.sort_by_key(|b| (b.group, b.binding));
        Some(bindings)
    }
}

/// A compute pipeline with an automatic layout, and the bindings its entry point uses as the
/// shader declares them.
pub(crate) struct ReflectedPipeline {
    /// The pipeline.
    pub pipeline: wgpu::ComputePipeline,
    /// Its label (named in the panic of a missing buffer).
    label: &'static str,
    /// The entry point's bindings, sorted by group and binding.
    bindings: Vec<ShaderBinding>,
}

impl ReflectedPipeline {
    /// The pipeline of `entry_point` of `source`, whose bindings `reflection` (of the same
    /// source) gives.
    ///
    /// # Panics
    ///
    /// When `reflection` has no such entry point (a programming error, as creating the pipeline
    /// would be).
    pub fn new(
        device: &wgpu::Device,
        label: &'static str,
        source: &str,
        reflection: &ShaderReflection,
        entry_point: &str,
    ) -> Self {
        let bindings = reflection
            .entry_point_bindings(entry_point)
            .unwrap_or_else(|| panic!("{label}: the shader has no entry point `{entry_point}`"));
        ReflectedPipeline {
            pipeline: super::shader::compute_pipeline(device, label, source, entry_point),
            label,
            bindings,
        }
    }

    /// A bind group of group `group` with every buffer binding the entry point uses taken from
    /// `buffers` by the shader's name for it (whole buffers). Names the entry point does not use
    /// are ignored, so one set of buffers can serve several passes of a module.
    ///
    /// # Panics
    ///
    /// When a binding of the group has no buffer of its name in `buffers` (a programming error:
    /// the pass's tests record it). Where a name is given twice, the later buffer is bound.
    pub fn bind_group(
        &self,
        device: &wgpu::Device,
        label: &str,
        group: u32,
        buffers: &[(&str, &wgpu::Buffer)],
    ) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry<'_>> = self
            .bindings
            .iter()
            .filter(|b| b.group == group)
            .map(|b| {
                let buffer = buffers
                    .iter()
                    .rev()
                    .find(|(name, _)| *name == b.name)
                    .map(|&(_, buffer)| buffer)
                    .unwrap_or_else(|| {
                        panic!(
                            "{}: no buffer given for `{}` (group {group}, binding {})",
                            self.label, b.name, b.binding
                        )
                    });
                wgpu::BindGroupEntry {
                    binding: b.binding,
                    resource: buffer.as_entire_binding(),
                }
            })
            .collect();
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &self.pipeline.get_bind_group_layout(group),
            entries: &entries,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const SOURCE: &str = "
struct Params { count: u32, pad: u32, pad2: u32, pad3: u32 }
@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> src: array<u32>;
@group(0) @binding(2) var<storage, read_write> dst: array<u32>;
@group(0) @binding(3) var<storage, read_write> unused: array<u32>;
@group(1) @binding(5) var<storage, read_write> counters: array<atomic<u32>>;

fn count_one() {
    atomicAdd(&counters[0], 1u);
}

@compute @workgroup_size(64)
fn copy(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < params.count {
        dst[id.x] = src[id.x];
    }
}

@compute @workgroup_size(64)
fn count(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < arrayLength(&src) {
        count_one();
    }
}
";

    fn binding(group: u32, binding: u32, name: &str, kind: ResourceKind) -> ShaderBinding {
        ShaderBinding {
            group,
            binding,
            name: name.into(),
            kind,
        }
    }

    #[test]
    fn an_entry_point_has_the_bindings_it_uses_with_their_kinds() {
        let r = ShaderReflection::new(SOURCE).expect("valid WGSL");
        assert_eq!(
            r.entry_point_bindings("copy").unwrap(),
            [
                binding(0, 0, "params", ResourceKind::Uniform),
                binding(0, 1, "src", ResourceKind::Storage { read_only: true }),
                binding(0, 2, "dst", ResourceKind::Storage { read_only: false }),
            ]
        );
    }

    #[test]
    fn bindings_used_through_a_called_function_count_and_unused_ones_do_not() {
        let r = ShaderReflection::new(SOURCE).expect("valid WGSL");
        // `arrayLength` queries `src`; `counters` is used by the function `count` calls; no
        // entry point uses `unused`.
        assert_eq!(
            r.entry_point_bindings("count").unwrap(),
            [
                binding(0, 1, "src", ResourceKind::Storage { read_only: true }),
                binding(1, 5, "counters", ResourceKind::Storage { read_only: false }),
            ]
        );
        assert!(r.entry_point_bindings("missing").is_none());
    }

    #[test]
    fn a_bind_group_puts_each_named_buffer_at_the_shader_s_binding() {
        use crate::gpu::testing::{buffer, buffer_with, gpu, read_back, run};
        let g = gpu();
        let r = ShaderReflection::new(SOURCE).expect("valid WGSL");
        let copy = ReflectedPipeline::new(&g.device, "reflect test", SOURCE, &r, "copy");
        let words: Vec<u32> = (0..100).map(|i| i * 7 + 1).collect();
        let src = buffer_with(bytemuck::cast_slice(&words));
        let dst = buffer(400);
        let decoy = buffer_with(&[0xff; 400]);
        run(|rec| {
            let params = rec.uniform("reflect test params", &[100u32, 0, 0, 0]);
            // Given in another order than the bindings', with a name `copy` does not use, and
            // `src` given twice: the later one wins.
            let bg = copy.bind_group(
                rec.device,
                "reflect test",
                0,
                &[
                    ("src", &decoy),
                    ("dst", &dst),
                    ("counters", &decoy),
                    ("params", &params),
                    ("src", &src),
                ],
            );
            rec.dispatch("reflect test", &copy.pipeline, &[&bg], 2);
        });
        let got: Vec<u32> = bytemuck::cast_slice(&read_back(&dst, 0, 400)).to_vec();
        assert_eq!(got, words);
    }

    #[test]
    #[should_panic(expected = "no buffer given for `dst` (group 0, binding 2)")]
    fn a_bind_group_missing_a_used_buffer_is_a_programming_error() {
        let g = crate::gpu::testing::gpu();
        let r = ShaderReflection::new(SOURCE).expect("valid WGSL");
        let copy = ReflectedPipeline::new(&g.device, "reflect test", SOURCE, &r, "copy");
        let b = crate::gpu::testing::buffer(400);
        let _ = copy.bind_group(&g.device, "reflect test", 0, &[("params", &b), ("src", &b)]);
    }

    #[test]
    fn invalid_wgsl_is_refused_with_naga_s_message() {
        let err = ShaderReflection::new("fn f() -> u32 { return 1.5; }")
            .err()
            .expect("a type error");
        assert!(err.contains("error"), "{err}");
    }
}
