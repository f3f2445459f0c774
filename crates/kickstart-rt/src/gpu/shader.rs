//! Compute pipeline creation from composed WGSL (see [`super::compose`]).

use super::layout::GroupLayout;

/// A compute pipeline from WGSL `source` with an automatic layout (groups as the shader declares).
pub(crate) fn compute_pipeline(
    device: &wgpu::Device,
    label: &str,
    source: &str,
    entry_point: &str,
) -> wgpu::ComputePipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    pipeline_with_auto_layout(device, label, &module, entry_point)
}

/// The compute pipeline of `module`'s `entry_point` with an automatic layout.
fn pipeline_with_auto_layout(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    entry_point: &str,
) -> wgpu::ComputePipeline {
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: None,
        module,
        entry_point: Some(entry_point),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// A compute pipeline from WGSL `source` with explicit bind group layouts (`layouts[i]` is group
/// `i`): needed where a shared module declares bindings a pass may not use (the G-buffer), since
/// an automatic layout would drop them.
pub(crate) fn compute_pipeline_with_layouts(
    device: &wgpu::Device,
    label: &str,
    source: &str,
    entry_point: &str,
    layouts: &[&wgpu::BindGroupLayout],
) -> wgpu::ComputePipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    pipeline_with_layouts(device, label, &module, entry_point, layouts)
}

/// A traversal pass's compute pipeline (explicit layouts, `layouts[i]` is group `i`) whose
/// `uninitialized` private arrays are not zero-filled at the start of each invocation, where the
/// device allows it (Vulkan with `Features::PASSTHROUGH_SHADERS`: see [`super::spirv`]); otherwise,
/// or if that compilation fails, the same pipeline from WGSL; `checks` applies to either. Also
/// returns whether the pipeline came from our own SPIR-V (see [`spirv_accepted`]). With no
/// `uninitialized` array (the hardware backend's passes have no stack) there is nothing to drop:
/// the pipeline is made from WGSL.
///
/// # Safety
///
/// As for `Device::create_shader_module_trusted` with `checks`: without bounds checks every array
/// index in `source` must be in bounds, without loop bounding every loop must terminate, for all
/// data the SDK can bind to it. Either way, the shader must never read an element of an
/// `uninitialized` variable before writing it.
pub(crate) unsafe fn traversal_pipeline(
    device: &wgpu::Device,
    label: &str,
    source: &str,
    entry_point: &str,
    layouts: &[GroupLayout<'_>],
    checks: wgpu::ShaderRuntimeChecks,
    uninitialized: &[&str],
) -> (wgpu::ComputePipeline, bool) {
    let groups: Vec<&wgpu::BindGroupLayout> = layouts.iter().map(|g| g.layout).collect();
    if spirv_accepted(device) && !uninitialized.is_empty() {
        let bindings: Vec<&[u32]> = layouts.iter().map(|g| g.bindings).collect();
        let request = super::spirv::SpirvRequest {
            entry_point,
            layout_bindings: &bindings,
            checks,
            uninitialized,
        };
        match super::spirv::compile_without_zero_init(source, &request) {
            Ok(compiled) => {
                let [x, y, z] = compiled.workgroup_size;
                let entry_points = [wgpu::PassthroughShaderEntryPoint {
                    name: entry_point.into(),
                    workgroup_size: (x, y, z),
                }];
                // SAFETY: the words are naga's own SPIR-V for the validated module, written with
                // the options wgpu-hal uses and the pipeline's own binding numbers; the only
                // change is the dropped initializers, which the caller guarantees are never read.
                let module = unsafe {
                    device.create_shader_module_passthrough(
                        wgpu::ShaderModuleDescriptorPassthrough {
                            label: Some(label),
                            entry_points: entry_points[..].into(),
                            spirv: Some(compiled.words.into()),
                            ..Default::default()
                        },
                    )
                };
                log::debug!(
                    "{label}: created from own SPIR-V (zero fill dropped: {uninitialized:?})"
                );
                let pipeline = pipeline_with_layouts(device, label, &module, entry_point, &groups);
                return (pipeline, true);
            }
            Err(e) => log::warn!("{label}: own SPIR-V failed ({e}); created from WGSL instead"),
        }
    }
    let descriptor = wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    };
    // SAFETY: the caller guarantees what `checks` leaves out (see above).
    let module = unsafe { device.create_shader_module_trusted(descriptor, checks) };
    let pipeline = pipeline_with_layouts(device, label, &module, entry_point, &groups);
    (pipeline, false)
}

/// Whether [`traversal_pipeline`] may give `device` our own SPIR-V: a Vulkan device with
/// `Features::PASSTHROUGH_SHADERS` enabled.
pub(crate) fn spirv_accepted(device: &wgpu::Device) -> bool {
    device
        .features()
        .contains(wgpu::Features::PASSTHROUGH_SHADERS)
        && device.adapter_info().backend == wgpu::Backend::Vulkan
}

/// The compute pipeline of `module`'s `entry_point` with explicit layouts (`layouts[i]` is group
/// `i`).
fn pipeline_with_layouts(
    device: &wgpu::Device,
    label: &str,
    module: &wgpu::ShaderModule,
    entry_point: &str,
    layouts: &[&wgpu::BindGroupLayout],
) -> wgpu::ComputePipeline {
    let groups: Vec<Option<&wgpu::BindGroupLayout>> = layouts.iter().copied().map(Some).collect();
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &groups,
        immediate_size: 0,
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&layout),
        module,
        entry_point: Some(entry_point),
        compilation_options: Default::default(),
        cache: None,
    })
}
