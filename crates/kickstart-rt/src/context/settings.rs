//! The context's own public types: its settings and what it reports.

use crate::logging::{LogCallback, Severity};
use crate::scene::gpu_scene::INSTANCE_RECORD_BYTES;
use crate::version::Version;

/// Bytes of one instance's record in the instance data table. The table is indexed by the
/// instance handle's slot index, which is the instance index a ray hit reports. Layout (32-bit
/// words): 0–11 object-to-world 3×4 (three rows), 12–23 world-to-object 3×4 (rows), 24 geometry
/// slot index, 25 inclusion mask, 26 flags (bit 0: live and participating in the TLAS).
pub const INSTANCE_RECORD_SIZE: u64 = INSTANCE_RECORD_BYTES;

/// Settings of [`ExecuteContext::new`](crate::ExecuteContext::new).
#[derive(Clone)]
pub struct InitSettings {
    /// GPU tasks that may be built and not yet marked complete at once (the reference's
    /// `supportedWorkingsets`): typically tasks per frame × frames in flight. Building one more
    /// returns [`Error::WorkingSetsExhausted`](crate::Error::WorkingSetsExhausted) at once. ≥ 1; default 4.
    pub supported_working_sets: u32,
    /// The SDK version the application was built against; leave at the default.
    pub version: Version,
    /// Receives SDK messages at or above `min_log_severity` (they also go to the `log` crate).
    pub log_callback: Option<LogCallback>,
    /// Least severe message delivered.
    pub min_log_severity: Severity,
    /// Measure every SDK pass with GPU timestamp queries (read them with
    /// [`ExecuteContext::wait_for_gpu_timings`](crate::ExecuteContext::wait_for_gpu_timings)). Needs `Features::TIMESTAMP_QUERY` on the
    /// device; without it a warning is logged and timing stays off. Default off.
    pub gpu_timing: bool,
    /// Initial size of the direct lighting cache's surfel pool, bytes (16 per surfel; default
    /// 4 MiB). The pool grows by itself when instances need more (their caches are coarse until
    /// then); a size near the scene's need avoids that first coarse frame.
    pub lighting_cache_pool_bytes: u64,
    /// How rays traverse the scene: the software BVH everywhere, or the GPU's ray-tracing
    /// hardware where the device was created with ray queries. Default
    /// [`BackendChoice::Auto`](crate::BackendChoice::Auto); the choice and its reason:
    /// [`ExecuteContext::traversal_backend`](crate::ExecuteContext::traversal_backend).
    pub backend: crate::device::BackendChoice,
}

impl Default for InitSettings {
    fn default() -> Self {
        InitSettings {
            supported_working_sets: 4,
            version: crate::version::VERSION,
            log_callback: None,
            min_log_severity: Severity::Warning,
            gpu_timing: false,
            lighting_cache_pool_bytes: crate::cache::alloc::DEFAULT_INITIAL_SURFELS as u64 * 16,
            backend: crate::device::BackendChoice::Auto,
        }
    }
}

impl std::fmt::Debug for InitSettings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("InitSettings")
            .field("supported_working_sets", &self.supported_working_sets)
            .field("version", &self.version)
            .field("log_callback", &self.log_callback.is_some())
            .field("min_log_severity", &self.min_log_severity)
            .field("gpu_timing", &self.gpu_timing)
            .field("lighting_cache_pool_bytes", &self.lighting_cache_pool_bytes)
            .field("backend", &self.backend)
            .finish()
    }
}

/// Triangles ingestion dropped from a geometry (they are never hit); also logged as a warning
/// naming the geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DroppedTriangles {
    /// Triangles with an index ≥ the component's vertex count.
    pub out_of_range_indices: u32,
    /// Triangles with a NaN or infinite position (as given, or after the component transform).
    pub non_finite_positions: u32,
}

/// Counts of what `build_gpu_task` has recorded, since the context was created.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RecordedTaskCounts {
    /// Geometry registrations and updates recorded.
    pub geometry_tasks: u64,
    /// Instance registrations and updates recorded.
    pub instance_tasks: u64,
    /// GPU tasks built.
    pub gpu_tasks: u64,
    /// Tracing passes (ray batches, trace tasks, lighting-cache injections) recorded with the
    /// software traversal built without the opacity test: the build taken while the scene holds
    /// no cutout geometry, so that opaque scenes pay nothing for cutouts. Debug views always
    /// trace with the test; the hardware backend has one build.
    pub opaque_only_traces: u64,
}
