//! What the SDK needs from a wgpu device, and the check `ExecuteContext::new` runs.

use crate::error::{Error, Result};

/// Features the SDK cannot work without. Request them when creating the device.
///
/// Empty: all ray tracing is plain compute, so any wgpu adapter qualifies.
pub fn required_features() -> wgpu::Features {
    wgpu::Features::empty()
}

/// Features the SDK uses when the device has them enabled, each with a fallback.
pub fn optional_features() -> wgpu::Features {
    wgpu::Features::SUBGROUP
        | wgpu::Features::SHADER_F16
        | wgpu::Features::TIMESTAMP_QUERY
        | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS
        | wgpu::Features::SHADER_INT64_ATOMIC_MIN_MAX
        | wgpu::Features::PIPELINE_CACHE
        | wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES
        // Vulkan: the traversal passes are created from our own SPIR-V, whose traversal stack
        // is not zero-filled per invocation (src/gpu/spirv.rs). Elsewhere it is not used.
        | wgpu::Features::PASSTHROUGH_SHADERS
}

/// Limits the SDK needs: WebGPU's defaults, which every desktop adapter exceeds.
pub fn required_limits() -> wgpu::Limits {
    wgpu::Limits::default()
}

/// The optional features `adapter` offers, for a device request:
/// `required_features() | optional_features_supported(&adapter)`.
pub fn optional_features_supported(adapter: &wgpu::Adapter) -> wgpu::Features {
    optional_features() & adapter.features()
}

/// Names every required feature and the first limit the device lacks.
pub(crate) fn check_device(device: &wgpu::Device) -> Result<()> {
    let missing = required_features() - device.features();
    if !missing.is_empty() {
        return Err(Error::MissingFeatures(format!("{missing:?}")));
    }
    let mut failure = None;
    required_limits().check_limits_with_fail_fn(
        &device.limits(),
        true,
        |name, required, actual| {
            failure = Some(Error::InsufficientLimit {
                name,
                actual,
                required,
            })
        },
    );
    match failure {
        Some(e) => Err(e),
        None => Ok(()),
    }
}
