//! GPU memory the SDK holds, by kind.

/// Bytes of GPU memory held by an [`crate::ExecuteContext`], by kind. Memory of destroyed handles
/// counts until it is actually released (see [`crate::ExecuteContext::destroy_geometry_handle`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ResourceAllocations {
    /// Copies of the application's vertex and index data.
    pub vertex_copies: u64,
    /// Direct lighting cache.
    pub cache: u64,
    /// Bottom-level BVHs.
    pub blas: u64,
    /// Top-level BVH and the per-instance data table.
    pub tlas: u64,
    /// Build scratch.
    pub scratch: u64,
    /// Denoisers: every context's signal histories (per grid pixel and signal, a record of 16
    /// bytes for radiance, 8 for occlusion and shadows; see
    /// `ExecuteContext::denoising_context_bytes`), the guides (two of 8 bytes per pixel, one
    /// pair for the contexts denoised from the same inputs) and the two intermediates every
    /// context shares (a record per pixel of the largest context's grid each).
    pub denoiser: u64,
    /// Upload staging owned by working sets.
    pub staging: u64,
    /// Capacity of the shared pools (vertex copies, BLAS) not handed out yet.
    pub pool_reserve: u64,
    /// The driver's BLASes and TLAS of the hardware ray-query backend, as wgpu's allocator
    /// reports them (0 on the software backend, and where wgpu has no allocator report).
    pub driver_acceleration_structures: u64,
}

impl ResourceAllocations {
    /// Sum of every kind.
    pub fn total(&self) -> u64 {
        self.vertex_copies
            + self.cache
            + self.blas
            + self.tlas
            + self.scratch
            + self.denoiser
            + self.staging
            + self.pool_reserve
            + self.driver_acceleration_structures
    }
}
