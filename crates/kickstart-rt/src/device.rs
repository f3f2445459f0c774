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

/// How rays find what they hit: the SDK's own BVH and compute-shader traversal, or the GPU's
/// ray-tracing hardware through wgpu's acceleration structures and WGSL ray queries. Both report
/// the same hits (instance index, primitive index, distance, barycentrics), except which of two
/// hits at exactly the same distance wins.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TraversalBackend {
    /// The SDK's BVH builders and WGSL traversal: runs on every wgpu device.
    Software,
    /// `Features::EXPERIMENTAL_RAY_QUERY`: acceleration structures built by the driver from the
    /// SDK's ingested triangles, traversed with WGSL `ray_query`.
    HardwareRayQuery,
}

impl std::fmt::Display for TraversalBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            TraversalBackend::Software => "software",
            TraversalBackend::HardwareRayQuery => "hardware ray query",
        })
    }
}

/// Which [`TraversalBackend`] a context should use ([`crate::InitSettings::backend`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum BackendChoice {
    /// Hardware ray queries when the device was created with them (see
    /// [`hardware_ray_query_features`]), the software traversal otherwise. The default.
    #[default]
    Auto,
    /// Always the software traversal, even on a device with ray queries.
    Software,
    /// Hardware ray queries; [`crate::ExecuteContext::new`] fails with
    /// [`Error::MissingFeatures`] when the device was created without them.
    HardwareRayQuery,
}

/// The backend a context uses and why (from [`crate::ExecuteContext::traversal_backend`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BackendReport {
    /// The backend every trace of the context uses.
    pub backend: TraversalBackend,
    /// Why it was chosen, in a sentence (the choice, and what the device offers).
    pub reason: String,
}

/// The features to request, beside [`required_features`] and [`optional_features`], for the
/// hardware ray-query backend: `Features::EXPERIMENTAL_RAY_QUERY`, or `None` when the adapter
/// lacks it.
///
/// wgpu treats ray queries as experimental: `Adapter::request_device` refuses the feature unless
/// the descriptor opts in with `experimental_features: unsafe { wgpu::ExperimentalFeatures::enabled() }`
/// (the engine accepts wgpu's caveats about experimental features by doing so), and the device
/// needs the adapter's acceleration-structure limits ([`hardware_ray_query_limits`]):
///
/// ```no_run
/// # fn device(adapter: &wgpu::Adapter) -> (wgpu::Device, wgpu::Queue) {
/// let mut features = kickstart_rt::required_features()
///     | kickstart_rt::optional_features_supported(adapter);
/// let mut limits = kickstart_rt::required_limits();
/// let mut experimental_features = wgpu::ExperimentalFeatures::disabled();
/// if let Some(rq) = kickstart_rt::hardware_ray_query_features(adapter) {
///     features |= rq;
///     limits = kickstart_rt::hardware_ray_query_limits(adapter, limits);
///     // SAFETY: the engine accepts wgpu's experimental ray-query support.
///     experimental_features = unsafe { wgpu::ExperimentalFeatures::enabled() };
/// }
/// pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
///     required_features: features,
///     required_limits: limits,
///     experimental_features,
///     ..Default::default()
/// }))
/// .unwrap()
/// # }
/// ```
pub fn hardware_ray_query_features(adapter: &wgpu::Adapter) -> Option<wgpu::Features> {
    let rq = wgpu::Features::EXPERIMENTAL_RAY_QUERY;
    let limits = adapter.limits();
    (adapter.features().contains(rq) && acceleration_structure_limits_usable(&limits)).then_some(rq)
}

/// `limits` raised to the adapter's own acceleration-structure limits (BLAS primitives and
/// geometries, TLAS instances, acceleration structures per stage), as the hardware ray-query
/// backend needs them. Use the adapter's rather than wgpu's minimum preset: software Vulkan
/// reports fewer BLAS primitives (2^24 − 1) than that preset asks for.
pub fn hardware_ray_query_limits(adapter: &wgpu::Adapter, limits: wgpu::Limits) -> wgpu::Limits {
    limits.using_acceleration_structure_values(adapter.limits())
}

/// Whether `limits` allow the hardware backend at all (wgpu's default limits give 0 of each).
fn acceleration_structure_limits_usable(limits: &wgpu::Limits) -> bool {
    limits.max_blas_primitive_count > 0
        && limits.max_blas_geometry_count > 0
        && limits.max_tlas_instance_count > 0
        && limits.max_acceleration_structures_per_shader_stage > 0
}

/// The backend `choice` gives on `device`, with the reason; an explicit hardware choice on a
/// device without ray queries (or without acceleration-structure limits) is an error.
pub(crate) fn choose_backend(
    device: &wgpu::Device,
    choice: BackendChoice,
) -> Result<BackendReport> {
    let has_feature = device
        .features()
        .contains(wgpu::Features::EXPERIMENTAL_RAY_QUERY);
    let limits = device.limits();
    let has_limits = acceleration_structure_limits_usable(&limits);
    let report = |backend, reason: String| Ok(BackendReport { backend, reason });
    match (choice, has_feature, has_limits) {
        (BackendChoice::Software, _, _) => report(
            TraversalBackend::Software,
            "InitSettings::backend is Software".into(),
        ),
        (_, true, true) => report(
            TraversalBackend::HardwareRayQuery,
            format!(
                "{}: the device has Features::EXPERIMENTAL_RAY_QUERY",
                if choice == BackendChoice::Auto {
                    "Auto"
                } else {
                    "HardwareRayQuery requested"
                }
            ),
        ),
        (BackendChoice::HardwareRayQuery, false, _) => Err(Error::MissingFeatures(
            "EXPERIMENTAL_RAY_QUERY (InitSettings::backend is HardwareRayQuery; see \
             kickstart_rt::hardware_ray_query_features)"
                .into(),
        )),
        (BackendChoice::HardwareRayQuery, true, false) => Err(Error::InsufficientLimit {
            name: "max_blas_primitive_count",
            actual: limits.max_blas_primitive_count as u64,
            required: 1,
        }),
        (BackendChoice::Auto, false, _) => report(
            TraversalBackend::Software,
            "Auto: the device was created without Features::EXPERIMENTAL_RAY_QUERY".into(),
        ),
        (BackendChoice::Auto, true, false) => report(
            TraversalBackend::Software,
            "Auto: the device has ray queries but no acceleration-structure limits \
             (see kickstart_rt::hardware_ray_query_limits)"
                .into(),
        ),
    }
}
