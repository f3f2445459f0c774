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

/// Where a BLAS's node range stands with compaction (see [`BlasMemory`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BlasCompaction {
    /// The tree has no unreferenced node to drop: a fast-build tree (one triangle a leaf), a
    /// fast-trace tree kept for refits (`allow_update`: a refit decides its collapsed leaves
    /// again, so it keeps every node), or one of fewer than two triangles.
    NotApplicable,
    /// A fast-trace tree, compacted by its build; its unused nodes are given back once the
    /// build's node count is read back, a task or two after it completed.
    Pending,
    /// A fast-trace tree whose node range holds only its reachable nodes.
    Done,
}

/// GPU memory of one geometry's BLAS ([`crate::ExecuteContext::geometry_blas_memory`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BlasMemory {
    /// Its triangles in leaf order: 48 bytes a triangle.
    pub triangle_bytes: u64,
    /// Its BVH2 nodes: 64 bytes a node (`n - 1` nodes for `n` triangles, fewer once compacted).
    pub node_bytes: u64,
    /// Sort order and refit topology kept for refits (`allow_update` only): 4 and 20 bytes a
    /// triangle (less 16 bytes).
    pub refit_bytes: u64,
    /// Whether the node range was compacted.
    pub compaction: BlasCompaction,
}

impl BlasMemory {
    /// Sum of every part.
    pub fn total(&self) -> u64 {
        self.triangle_bytes + self.node_bytes + self.refit_bytes
    }
}
