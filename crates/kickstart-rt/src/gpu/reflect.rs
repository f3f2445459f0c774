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
    /// Its type as a bind group layout entry declares it (see [`binding_type`]).
    pub ty: wgpu::BindingType,
}

impl ShaderBinding {
    /// The bind group layout entry of this binding (compute stage).
    pub fn layout_entry(&self) -> wgpu::BindGroupLayoutEntry {
        wgpu::BindGroupLayoutEntry {
            binding: self.binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: self.ty,
            count: None,
        }
    }
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
            .filter_map(|(_, var)| self.binding(var))
            .collect();
        bindings.sort_by_key(|b| (b.group, b.binding));
        Some(bindings)
    }

    /// Every binding the module declares in `group`, whether an entry point uses it or not
    /// (what an explicit layout shared by several passes needs), sorted by binding.
    pub fn group_bindings(&self, group: u32) -> Vec<ShaderBinding> {
        let mut bindings: Vec<ShaderBinding> = self
            .module
            .global_variables
            .iter()
            .filter_map(|(_, var)| self.binding(var))
            .filter(|b| b.group == group)
            .collect();
        bindings.sort_by_key(|b| b.binding);
        bindings
    }

    /// The binding of the global `var`, `None` when it has no `@group`/`@binding`.
    fn binding(&self, var: &naga::GlobalVariable) -> Option<ShaderBinding> {
        let rb = var.binding.as_ref()?;
        let name = var.name.clone().unwrap_or_default();
        let kind = match var.space {
            naga::AddressSpace::Uniform => ResourceKind::Uniform,
            naga::AddressSpace::Storage { access } => ResourceKind::Storage {
                read_only: !access.contains(naga::StorageAccess::STORE),
            },
            _ => ResourceKind::Handle,
        };
        let ty = binding_type(kind, &self.module.types[var.ty].inner)
            .unwrap_or_else(|| panic!("binding `{name}`: a resource type the SDK never binds"));
        Some(ShaderBinding {
            group: rb.group,
            binding: rb.binding,
            name,
            kind,
            ty,
        })
    }
}

/// The layout type of a binding of `kind` and naga type `inner`: buffers as declared; 2-D float
/// textures as unfilterable (every pass reads them with `textureLoad`, so `R32Float` and depth
/// formats bind too); depth textures; write, read or read-write storage textures of the declared
/// format. `None` for what the SDK's shaders never declare (arrays, cubes, samplers, …).
fn binding_type(kind: ResourceKind, inner: &naga::TypeInner) -> Option<wgpu::BindingType> {
    use naga::{ImageClass, ImageDimension, ScalarKind, TypeInner};
    let buffer = |ty| wgpu::BindingType::Buffer {
        ty,
        has_dynamic_offset: false,
        min_binding_size: None,
    };
    let texture = |sample_type| wgpu::BindingType::Texture {
        sample_type,
        view_dimension: wgpu::TextureViewDimension::D2,
        multisampled: false,
    };
    match (kind, inner) {
        (ResourceKind::Uniform, _) => Some(buffer(wgpu::BufferBindingType::Uniform)),
        (ResourceKind::Storage { read_only }, _) => {
            Some(buffer(wgpu::BufferBindingType::Storage { read_only }))
        }
        (ResourceKind::Handle, &TypeInner::AccelerationStructure { vertex_return }) => {
            Some(wgpu::BindingType::AccelerationStructure { vertex_return })
        }
        (
            ResourceKind::Handle,
            &TypeInner::Image {
                dim: ImageDimension::D2,
                arrayed: false,
                class,
            },
        ) => match class {
            ImageClass::Sampled {
                kind: ScalarKind::Float,
                multi: false,
            } => Some(texture(wgpu::TextureSampleType::Float {
                filterable: false,
            })),
            ImageClass::Depth { multi: false } => Some(texture(wgpu::TextureSampleType::Depth)),
            ImageClass::Storage { format, access } => {
                let access = match (
                    access.contains(naga::StorageAccess::LOAD),
                    access.contains(naga::StorageAccess::STORE),
                ) {
                    (true, true) => wgpu::StorageTextureAccess::ReadWrite,
                    (true, false) => wgpu::StorageTextureAccess::ReadOnly,
                    _ => wgpu::StorageTextureAccess::WriteOnly,
                };
                Some(wgpu::BindingType::StorageTexture {
                    access,
                    format: storage_format(format)?,
                    view_dimension: wgpu::TextureViewDimension::D2,
                })
            }
            _ => None,
        },
        _ => None,
    }
}

/// The texture format of a WGSL storage format the SDK writes (`WRITABLE_OUTPUT_FORMATS`).
fn storage_format(format: naga::StorageFormat) -> Option<wgpu::TextureFormat> {
    use naga::StorageFormat as S;
    use wgpu::TextureFormat as F;
    Some(match format {
        S::Rgba16Float => F::Rgba16Float,
        S::Rgba32Float => F::Rgba32Float,
        S::R32Float => F::R32Float,
        S::Rg32Float => F::Rg32Float,
        S::Rgba8Unorm => F::Rgba8Unorm,
        _ => return None,
    })
}

/// The entries of a bind group over `bindings` (one group's), each resource taken from
/// `resources` by the shader's name for it.
///
/// # Panics
///
/// When a binding has no resource of its name (a programming error: the pass's tests record
/// it); `label` names the pass.
pub(crate) fn named_entries<'a, 'b>(
    label: &str,
    bindings: impl IntoIterator<Item = &'b ShaderBinding>,
    resources: &[(&str, wgpu::BindingResource<'a>)],
) -> Vec<wgpu::BindGroupEntry<'a>> {
    bindings
        .into_iter()
        .map(|b| {
            let resource = resources
                .iter()
                .rev()
                .find(|(name, _)| *name == b.name)
                .map(|(_, r)| r.clone())
                .unwrap_or_else(|| {
                    panic!(
                        "{label}: no resource given for `{}` (group {}, binding {})",
                        b.name, b.group, b.binding
                    )
                });
            wgpu::BindGroupEntry {
                binding: b.binding,
                resource,
            }
        })
        .collect()
}

/// An explicit bind group layout made from the bindings a shader declares in one group, and
/// bind groups for it by the shader's names: for passes whose layouts are shared or explicit
/// (the traversal's own SPIR-V needs them), so no Rust table repeats the shader's bindings.
#[derive(Clone)]
pub(crate) struct ReflectedLayout {
    /// The layout and its binding numbers.
    pub layout: super::layout::BoundLayout,
    bindings: Vec<ShaderBinding>,
    label: &'static str,
}

impl ReflectedLayout {
    /// The layout of every binding `reflection` declares in `group`.
    pub fn new(
        device: &wgpu::Device,
        label: &'static str,
        reflection: &ShaderReflection,
        group: u32,
    ) -> Self {
        Self::from_bindings(device, label, reflection.group_bindings(group))
    }

    /// The layout of the bindings `entry_point` of `reflection` uses in `group` (a pass whose
    /// shared modules declare bindings it does not read, such as the cache's surfels).
    ///
    /// # Panics
    ///
    /// When the module has no such entry point (a programming error).
    pub fn of_entry_point(
        device: &wgpu::Device,
        label: &'static str,
        reflection: &ShaderReflection,
        entry_point: &str,
        group: u32,
    ) -> Self {
        let bindings: Vec<ShaderBinding> = reflection
            .entry_point_bindings(entry_point)
            .unwrap_or_else(|| panic!("{label}: the shader has no entry point `{entry_point}`"))
            .into_iter()
            .filter(|b| b.group == group)
            .collect();
        Self::from_bindings(device, label, bindings)
    }

    fn from_bindings(
        device: &wgpu::Device,
        label: &'static str,
        bindings: Vec<ShaderBinding>,
    ) -> Self {
        let entries: Vec<_> = bindings.iter().map(ShaderBinding::layout_entry).collect();
        ReflectedLayout {
            layout: super::layout::BoundLayout::new(device, label, &entries),
            bindings,
            label,
        }
    }

    /// The bind group layout.
    pub fn layout(&self) -> &wgpu::BindGroupLayout {
        &self.layout.layout
    }

    /// This layout as a pipeline's group.
    pub fn group(&self) -> super::layout::GroupLayout<'_> {
        self.layout.group()
    }

    /// A bind group with each binding's resource taken from `resources` by the shader's name
    /// (see [`named_entries`]).
    pub fn bind_group(
        &self,
        device: &wgpu::Device,
        resources: &[(&str, wgpu::BindingResource<'_>)],
    ) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(self.label),
            layout: &self.layout.layout,
            entries: &named_entries(self.label, &self.bindings, resources),
        })
    }
}

/// A composed shader (see [`super::compose`]) and its reflection, from which a pass makes the
/// pipelines of its entry points.
pub(crate) struct ReflectedShader {
    source: String,
    reflection: ShaderReflection,
}

impl ReflectedShader {
    /// The SDK's modules `roots` composed with `params`, parsed and validated.
    ///
    /// # Panics
    ///
    /// When the composition or naga's validation fails: the roots and parameters are the SDK's
    /// own per variant, and a CPU-only test of each pass validates every variant it creates.
    pub fn compose(roots: &[&str], params: &[(&str, &str)]) -> Self {
        Self::compose_in(&super::compose::ShaderLibrary::builtin(), roots, params)
    }

    /// As [`ReflectedShader::compose`], from the modules of `library` (the SDK's, with a
    /// backend's module substituted: see the scene's traversal module).
    pub fn compose_in(
        library: &super::compose::ShaderLibrary,
        roots: &[&str],
        params: &[(&str, &str)],
    ) -> Self {
        let source = library
            .compose(roots, params)
            .unwrap_or_else(|e| panic!("composing {roots:?}: {e}"));
        let reflection = ShaderReflection::new(&source)
            .unwrap_or_else(|e| panic!("composed shader {roots:?} is not valid WGSL: {e}"));
        ReflectedShader { source, reflection }
    }

    /// The composed WGSL.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Its reflection.
    pub fn reflection(&self) -> &ShaderReflection {
        &self.reflection
    }

    /// The pipeline of `entry_point`, with an automatic layout and the bindings it uses.
    pub fn pipeline(
        &self,
        device: &wgpu::Device,
        label: &'static str,
        entry_point: &str,
    ) -> ReflectedPipeline {
        ReflectedPipeline::new(device, label, &self.source, &self.reflection, entry_point)
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
        let resources: Vec<(&str, wgpu::BindingResource<'_>)> = buffers
            .iter()
            .map(|&(name, buffer)| (name, buffer.as_entire_binding()))
            .collect();
        self.bind_resources(device, label, group, &resources)
    }
}

impl ReflectedPipeline {
    /// As [`Self::bind_group`], with any resources (texture views, buffer ranges) by name.
    pub fn bind_resources(
        &self,
        device: &wgpu::Device,
        label: &str,
        group: u32,
        resources: &[(&str, wgpu::BindingResource<'_>)],
    ) -> wgpu::BindGroup {
        // Called per dispatch: the group's bindings are filtered in place, not copied.
        let group_bindings = self.bindings.iter().filter(|b| b.group == group);
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &self.pipeline.get_bind_group_layout(group),
            entries: &named_entries(self.label, group_bindings, resources),
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
        let ty = match kind {
            ResourceKind::Uniform => wgpu::BufferBindingType::Uniform,
            ResourceKind::Storage { read_only } => wgpu::BufferBindingType::Storage { read_only },
            ResourceKind::Handle => unreachable!("buffers only"),
        };
        ShaderBinding {
            group,
            binding,
            name: name.into(),
            kind,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
        }
    }

    #[test]
    fn a_group_s_layout_comes_from_every_binding_the_module_declares() {
        let source = "
@group(2) @binding(0) var<uniform> p: vec4<u32>;
@group(2) @binding(1) var colour: texture_2d<f32>;
@group(2) @binding(3) var depth: texture_depth_2d;
@group(2) @binding(4) var out0: texture_storage_2d<rgba16float, write>;
@group(2) @binding(5) var out1: texture_storage_2d<r32float, write>;
@group(1) @binding(0) var<storage, read> other: array<u32>;
@compute @workgroup_size(1)
fn main() {
    textureStore(out0, vec2<u32>(0u), textureLoad(colour, vec2<u32>(p.xy), 0));
}
";
        let r = ShaderReflection::new(source).expect("valid WGSL");
        let entries: Vec<_> = r
            .group_bindings(2)
            .iter()
            .map(|b| (b.name.clone(), b.layout_entry()))
            .collect();
        let texture = |sample_type| wgpu::BindingType::Texture {
            sample_type,
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        };
        let storage = |format| wgpu::BindingType::StorageTexture {
            access: wgpu::StorageTextureAccess::WriteOnly,
            format,
            view_dimension: wgpu::TextureViewDimension::D2,
        };
        let expected = [
            ("p", 0, binding(2, 0, "p", ResourceKind::Uniform).ty),
            (
                "colour",
                1,
                texture(wgpu::TextureSampleType::Float { filterable: false }),
            ),
            ("depth", 3, texture(wgpu::TextureSampleType::Depth)),
            ("out0", 4, storage(wgpu::TextureFormat::Rgba16Float)),
            // Declared but unused by `main`: still in the group's layout.
            ("out1", 5, storage(wgpu::TextureFormat::R32Float)),
        ];
        assert_eq!(entries.len(), expected.len());
        for ((name, entry), (want_name, want_binding, want_ty)) in entries.iter().zip(expected) {
            assert_eq!(
                (name.as_str(), entry.binding, entry.ty),
                (want_name, want_binding, want_ty)
            );
            assert_eq!(entry.visibility, wgpu::ShaderStages::COMPUTE);
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
    #[should_panic(expected = "no resource given for `dst` (group 0, binding 2)")]
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
