//! The direct lighting cache: the engine's rasterised direct lighting stored on the surfaces, in
//! world space, one cache per instance. Trace tasks read it at their hits instead of shading.
//!
//! # Sampling contract (for trace shaders)
//!
//! `cache/sample` is a WGSL module a trace shader imports (`#import cache/sample`, see
//! [`crate::gpu::compose`]). It declares two storage buffers at `@group(CACHE_GROUP)` bindings 0
//! (`meta`) and 1 (`surfels`); the importer gives the group number and the surfels' access with
//! [`sample_params`] and binds [`DirectLightingCache::sample_resources`] there by name (its
//! layout comes from the module itself). It defines
//!
//! - `fn cache_radiance(instance: u32, prim: u32, bary: vec2<f32>, bilinear: bool) -> vec3<f32>`:
//!   the cached linear radiance at that surface point; the instance's `initial_tile_color` where
//!   nothing was injected yet, `vec3(0.0)` for an instance slot without a cache;
//! - `fn cache_tile_id(instance: u32, prim: u32, bary: vec2<f32>) -> u32`: an id unique per
//!   surfel of the whole cache (`0xffffffff` without a cache), for `RandomTileColor`.
//!
//! `instance` is the instance slot (`InstanceHandle::index`, as `GpuHit::instance`), `prim` the
//! primitive index (`GpuHit::primitive`), `bary = (u, v)` with point = (1−u−v)·v0 + u·v1 + v·v2.
//! Both bindings are valid before any instance exists (small placeholder buffers).
//!
//! # Layouts and sizing (world space, after the instance transform)
//!
//! Let `L` be a length in world units, `unit = tile_unit_length`, `limit =
//! tile_resolution_limit`, and `tiles(L) = clamp(ceil(L / unit), 1, limit)`.
//!
//! - **WarpedBarycentricStorage**: each triangle gets an `n × n` grid of sub-triangles (tiles;
//!   `n²` surfels), `n = tiles(longest edge)`. *Direct mapping* (`n = 1`, one tile for the whole
//!   triangle) when `force_direct_tile_mapping` is set or the triangle's area is below
//!   `direct_tile_mapping_threshold × unit²` (it would not fill that fraction of one tile's square).
//!   Always read nearest (no interpolation across tiles). Coarse fallback: one tile per triangle.
//! - **MeshColors** (Yuksel et al. 2010, the default): samples at the points `(i0·v0 + i1·v1 +
//!   i2·v2) / R` with `i0 + i1 + i2 = R`. Each **edge** has its own resolution `E(L) =
//!   min(pow2ceil(tiles(L)), pow2floor(limit))` (1 with `force_direct_tile_mapping`) and stores
//!   `E − 1` samples, shared by every triangle with the same two endpoint **positions** (split
//!   vertices share too); each **vertex position** stores one sample, shared the same way; each
//!   triangle's resolution is `R = max(E0, E1, E2)` and it stores `(R − 1)(R − 2) / 2` interior
//!   samples. A grid point on an edge that the edge does not store (`E < R`, `E` divides `R`) is
//!   the linear interpolation of the edge's samples, so both triangles of an edge evaluate the
//!   same piecewise-linear function on it: interpolated reads are continuous across edges. A
//!   triangle's cost is `3 vertex + 3 edge shares + interior`; `direct_tile_mapping_threshold` does
//!   not apply (a tiny triangle costs only its shared vertex samples). Coarse fallback: the vertex
//!   samples only (`R = E = 1`).
//!
//! Surfels are 16 bytes (`vec4<f32>`: linear RGB, and the number of injection tasks merged,
//! saturating). Per triangle the cache keeps an 8-word record (32 bytes), per instance slot an
//! 8-word header.
//!
//! # Allocation
//!
//! On the GPU, in the `build_gpu_task` that registers the instance (or the first one after its
//! geometry's BLAS is built): shared vertices and edges are found with hash tables keyed by
//! position bits, counted, and placed in one SDK-owned surfel pool (free blocks of destroyed
//! caches first, then the pool's top). If the full cache does not fit, the instance gets its
//! coarse cache at once, and if that does not fit either, no cache (reads give 0) — nothing is
//! written out of bounds. The allocation log is read back asynchronously when the task is
//! marked complete; a shortfall grows the pool in a later task and re-allocates the degraded
//! caches at full resolution (their lighting restarts from `initial_tile_color`).
//!
//! A cache is sized at registration: a later `Update` that only moves the instance keeps it; one
//! that changes the geometry allocates a new one.

pub(crate) mod alloc;
pub(crate) mod inject;
#[cfg_attr(not(test), allow(dead_code))] // the formulas' CPU form: tests and tools
pub(crate) mod sizing;
pub(crate) mod transfer;

pub(crate) use alloc::{AllocJob, DirectLightingCache};

use crate::tasks::{GeometryInput, SurfelType};

/// How much of its lighting cache an instance got.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CacheLevel {
    /// The full resolution of the documented sizing formulas.
    Full,
    /// The pool was short: MeshColors vertex samples only / one tile per triangle, until the pool
    /// has grown (a later task re-allocates it at full resolution).
    Coarse,
    /// The pool could not hold even the coarse cache: reads give 0 until it has grown.
    None,
}

/// An instance's lighting cache as the GPU allocated it (read back asynchronously).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CacheAllocation {
    /// Surfels (16 bytes each) in the pool.
    pub surfels: u32,
    /// Full or degraded.
    pub level: CacheLevel,
}

/// The parameters of the sampling module `cache/sample` (see the module docs) bound at
/// `@group(group)`, its surfels writable or read-only.
///
/// # Panics
///
/// When `group` is over 3 (WebGPU has four bind groups; the SDK's passes pass constants).
pub(crate) fn sample_params(
    group: u32,
    surfels_writable: bool,
) -> [(&'static str, &'static str); 2] {
    let group = ["0", "1", "2", "3"][group as usize];
    let access = if surfels_writable {
        "read_write"
    } else {
        "read"
    };
    [("CACHE_GROUP", group), ("SURFEL_ACCESS", access)]
}

/// Cache layout settings of a geometry (from its `GeometryInput`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct CacheParams {
    pub mesh_colors: bool,
    pub tile_unit_length: f32,
    pub tile_resolution_limit: u32,
    pub direct_tile_mapping_threshold: f32,
    pub force_direct_tile_mapping: bool,
}

impl CacheParams {
    /// The settings of `input`.
    pub fn of(input: &GeometryInput) -> Self {
        CacheParams {
            mesh_colors: input.surfel_type == SurfelType::MeshColors,
            tile_unit_length: input.tile_unit_length,
            tile_resolution_limit: input.tile_resolution_limit.max(1),
            direct_tile_mapping_threshold: input.direct_tile_mapping_threshold,
            force_direct_tile_mapping: input.force_direct_tile_mapping,
        }
    }
}
