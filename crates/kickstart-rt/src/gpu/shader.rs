//! WGSL assembly and compute pipeline creation. WGSL has no `#include`: shared snippets (the
//! traversal module, packing helpers) are concatenated in front of a pass's source.

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

/// A compute pipeline like [`compute_pipeline`], compiled without naga's runtime checks
/// (`ShaderRuntimeChecks::unchecked()`: no index clamps, no forced loop bounding).
///
/// Only for shaders whose every index and loop is bounded by construction; the caller names the
/// argument. Measured on the H100 for the ray batch pass: +3–4 % rays/s (BENCHMARKS.md).
///
/// # Safety
///
/// Every array index in `source` must be in bounds and every loop must terminate for all data
/// the SDK can bind to it.
pub(crate) unsafe fn compute_pipeline_unchecked(
    device: &wgpu::Device,
    label: &str,
    source: &str,
    entry_point: &str,
) -> wgpu::ComputePipeline {
    // SAFETY: the caller guarantees the shader is in bounds and terminates (see above).
    let module = unsafe {
        device.create_shader_module_trusted(
            wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            },
            wgpu::ShaderRuntimeChecks::unchecked(),
        )
    };
    pipeline_with_auto_layout(device, label, &module, entry_point)
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
    let groups: Vec<Option<&wgpu::BindGroupLayout>> = layouts.iter().copied().map(Some).collect();
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &groups,
        immediate_size: 0,
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&layout),
        module: &module,
        entry_point: Some(entry_point),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// Concatenates WGSL sources (shared modules first).
pub(crate) fn assemble(parts: &[&str]) -> String {
    parts.join("\n")
}
