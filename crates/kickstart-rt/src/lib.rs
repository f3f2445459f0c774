#![doc = include_str!("../README.md")]
//!
//! ## Execution model
//!
//! 1. [`ExecuteContext::new`] on the engine's device and queue (request
//!    [`required_features`] and [`required_limits`], plus any of [`optional_features`]).
//! 2. Each frame, fill one or more [`TaskContainer`]s (on any threads) with BVH tasks
//!    ([`GeometryTask`], [`InstanceTask`], [`BvhBuildTask`]) and render tasks ([`RenderTask`]).
//! 3. [`ExecuteContext::build_gpu_task`] validates the whole container and records compute passes
//!    and copies into the engine's `CommandEncoder`. It never submits and never waits.
//! 4. After the GPU has run the submission, [`ExecuteContext::mark_gpu_task_completed`].
//!    [`InitSettings::supported_working_sets`] bounds how many built tasks may be outstanding.
//!
//! ## Status of this version
//!
//! Working: the API, handles, working sets, lazy destruction, validation, and the **ray tracing
//! core** — geometry ingestion on the GPU (vertex pulling of every supported format into shared,
//! sub-allocated pools), GPU BLAS builds (LBVH) and refits, the TLAS (rebuild or refit), ray
//! batches ([`TraceRaysTask`]) and the primary-ray debug views (`HitT`, `Barycentrics`,
//! `RandomMeshColor`, plus `DirectLightingCache` and `RandomTileColor`) of the trace tasks, the
//! **direct lighting cache** (GPU allocation, injection, transfer, sampling;
//! `docs/lighting-cache.md`), the **trace tasks** (specular, diffuse, AO, shadow, multi-shadow;
//! `docs/trace-tasks.md`) and the **denoisers** (every denoise task; `docs/denoisers.md`). Not
//! implemented yet: the `Normal`, `Roughness` and `WorldPosition` debug views: such a task is
//! fully validated and then refused with [`Error::Unsupported`] naming it — never a silent no-op.
//!
//! ## Ray tracing: how geometry becomes rays
//!
//! - A [`GeometryTask`] (`Register` or `Update`) copies the application's bytes inside its encoder
//!   and decodes them on the GPU into the shared staged-triangle pool. Triangles with an
//!   out-of-range index or a NaN/∞ position are dropped (never hit) and reported: a warning
//!   naming the geometry through the log, and [`ExecuteContext::geometry_dropped_triangles`].
//! - BLASes are built only by a [`BvhBuildTask`], at most `max_blas_build_count` per GPU task, in
//!   the order their geometry was scheduled; the rest wait for later tasks (the reference's
//!   throttling). An instance of a geometry whose BLAS is not built yet is invisible to rays.
//!   Static geometry's staged copy is released once its BLAS is built; `allow_update` geometry
//!   keeps it, and its `Update` (same triangle count) re-ingests the vertices and refits.
//! - The TLAS covers every instance slot. Every GPU task that changed an instance or built a BLAS
//!   rebuilds it when instances were added or removed or a BLAS was built, and otherwise refits
//!   it when transforms moved ([`TlasUpdate`]); a [`BvhBuildTask`] with `build_tlas: false`
//!   defers that.
//! - A hit reports the instance's handle index ([`InstanceHandle::index`], the index of its data
//!   in the instance table) and the primitive index within its geometry: earlier components'
//!   triangles first, then this component's, counted after its `index_range`.
//! - Traversal is watertight: a ray through a shared edge or vertex hits (no gaps); among hits at
//!   equal `t`, the lowest instance index, then the lowest primitive index wins. Layouts and the
//!   traversal contract: `docs/ray-tracing-core.md`.
//!
//! ## Validation rules
//!
//! `build_gpu_task` checks every rule before recording anything; a failure returns
//! [`Error::InvalidInput`] naming the task, the field and the value, and the context is unchanged.
//!
//! | task | field | valid | error when |
//! | --- | --- | --- | --- |
//! | `InitSettings` | `supported_working_sets` | ≥ 1 | 0 |
//! | `TaskContainer` | `context` | made by this context | made by another context |
//! | `GeometryTask` | `handle` | live handle of this context | destroyed/foreign: [`Error::InvalidHandle`] |
//! | `GeometryTask` | `operation` | `Register` once; `Update` only after it, with `allow_update` | re-register, update of unregistered or non-updatable |
//! | `GeometryTask` | `input.components` | ≥ 1 | empty |
//! | `GeometryTask` | `input.tile_unit_length` | finite, > 0 | ≤ 0, NaN, ∞ |
//! | `GeometryTask` | `input.tile_resolution_limit` | ≥ 1 | 0 |
//! | `GeometryTask` | `input.direct_tile_mapping_threshold` | [0, 1] | outside |
//! | `GeometryTask` | `…vertex_buffer.buffer` | has `COPY_SRC` | lacks it (wgpu would panic at `finish()`) |
//! | `GeometryTask` | `…vertex_buffer.stride` | ≥ format size | smaller |
//! | `GeometryTask` | `…vertex_buffer.count` | ≥ 1; multiple of 3 when non-indexed | 0; not a multiple |
//! | `GeometryTask` | `…vertex_buffer.offset` | range inside the buffer | past its end |
//! | `GeometryTask` | `…transform` | finite | NaN/∞ |
//! | `GeometryTask` | `…index_buffer.buffer` | has `COPY_SRC` | lacks it |
//! | `GeometryTask` | `…index_buffer.offset` | multiple of the index size, range inside the buffer | misaligned, past the end |
//! | `GeometryTask` | `…index_buffer.count` | non-zero multiple of 3 | otherwise |
//! | `GeometryTask` | `…index_range` | multiples of 3 inside the component | otherwise |
//! | `GeometryTask` | `…opacity.micromap_level` | ≤ 6 (`ComponentOpacity::MAX_MICROMAP_LEVEL`) with a texture source | larger |
//! | `GeometryTask` | `…opacity.source.channel` | 0..=3 | larger |
//! | `GeometryTask` | `…opacity.source.factor` | finite, ≥ 0 | negative, NaN/∞ |
//! | `GeometryTask` | `…opacity.source.cutoff` | [0, 1] | outside, NaN |
//! | `GeometryTask` | `…opacity.source.texture` | `TEXTURE_BINDING`, 2D, 1 sample, float sample type | missing usage; other dimension; multisampled; depth, stencil or integer format |
//! | `GeometryTask` | `…opacity.source.uvs.stride` | ≥ format size | smaller |
//! | `GeometryTask` | `…opacity.source.uvs.buffer` | has `COPY_SRC`, holds `vertex_buffer.count` coordinates | lacks it; too short |
//! | `GeometryTask` | `…opacity.source.uvs.offset` | range inside the buffer | past its end |
//! | `GeometryTask` | `…opacity.source.buffer` (per triangle) | has `COPY_SRC`, holds a `u32` per triangle (after `index_range`) | lacks it; too short |
//! | `GeometryTask` | `…opacity.source.offset` (per triangle) | multiple of 4, range inside the buffer | misaligned, past the end |
//! | `InstanceTask` | `handle`, `input.geometry` | live handles; geometry registered | stale: [`Error::InvalidHandle`]; unregistered |
//! | `InstanceTask` | `operation` | `Register` once; `Update` only after it | re-register, update of unregistered |
//! | `InstanceTask` | `input.transform` | finite | NaN/∞ |
//! | `InstanceTask` | `input.inclusion_mask` | bits 0–1 | other bits |
//! | `InstanceTask` | `input.initial_tile_color` | finite, ≥ 0 | otherwise |
//! | `GeometryTask` | `input.components` (Update) | the registered triangle count | another count (the BVH is refitted) |
//! | `BvhBuildTask` | `max_blas_build_count` | ≥ 1 | 0 |
//! | `SkinningTask` | `vertex_count` | ≤ 64 × `max_compute_workgroups_per_dimension` | more (split the mesh) |
//! | `SkinningTask` | `rest_positions.format` | `Float32x3`, `Float32x4` | other formats |
//! | `SkinningTask` | `*.offset`, `*.stride` of every attribute and the output | multiples of 4; stride ≥ the value's size; every value inside the buffer | misaligned; smaller; past the end |
//! | `SkinningTask` | `*.buffer` | `STORAGE` usage; a window ≤ `max_storage_buffer_binding_size` | missing; larger ([`Error::OutOfDeviceMemory`]) |
//! | `SkinningTask` | `output.buffer` | none of the task's input buffers | the same buffer |
//! | `SkinningTask` | `joint_matrices` | finite; ≤ `MAX_JOINTS`; one at least when `influences` is set | NaN/∞; more; none |
//! | `SkinningTask` | `morph_weights`, `morph_targets.count` | one finite weight a target; ≤ `MAX_MORPH_TARGETS` targets | another count; NaN/∞; more |
//! | `TraceRaysTask` | `rays`, `hits` | `STORAGE` usage | missing |
//! | `TraceRaysTask` | `rays_offset`, `hits_offset` | multiples of `min_storage_buffer_offset_alignment`; `ray_count` × 32 bytes fit | misaligned; past the end |
//! | `TraceRaysTask` | `instance_mask` | bits 0–1 | other bits |
//! | trace tasks | `output` | `STORAGE_BINDING`, a format of [`WRITABLE_OUTPUT_FORMATS`] | otherwise |
//! | trace tasks | `common.depth.texture`, `common.normal.texture`, optional inputs | `TEXTURE_BINDING`; depth formats allowed | missing usage; combined depth-stencil format |
//! | trace tasks | `common.roughness.*` | global/min/max in [0, 1], min ≤ max, finite multiplier | otherwise |
//! | trace tasks | `common.specular.global_metalness` | [0, 1] | outside |
//! | trace tasks | `common.view.*` | finite, invertible matrices | otherwise |
//! | trace tasks | `common.max_ray_length` | > 0 (∞ allowed) | ≤ 0, NaN |
//! | trace tasks | `common.ray_offset.*` | finite | NaN/∞ |
//! | trace/denoise/injection | `viewport` | non-empty, inside every texture it addresses | otherwise |
//! | `TraceSpecularTask` | `demodulation_output` | present when `demodulate_specular` | missing |
//! | `TraceAmbientOcclusionTask` | `ao_radius` | finite, > 0 | otherwise |
//! | shadow tasks | `light.*` | unit directions, finite positions, radius ≥ 0, range > 0, apex in (0, π/2], extent in [0, π] | otherwise |
//! | `TraceMultiShadowTask` | `lights` | 1..=32 | 0 or > 32 |
//! | `TraceMultiShadowTask` | `output0`, `output1` | `Rgba16Float` or `Rgba32Float` (the packed format of docs/trace-tasks.md) | other formats |
//! | `TraceSpecularTask` | `demodulation_output`, `common.direct_lighting` | cover the viewport | smaller |
//! | `DirectLightingInjectionTask` | `average_window` | finite, ≥ 1 | otherwise |
//! | `DirectLightingInjectionTask` | `injection_resolution_stride` | 1..=8 | otherwise |
//! | `DirectLightTransferTask` | `source`, `target` | live, different instances registered by an earlier task; the target's geometry has `allow_light_transfer_target` and as many triangles as the source's | same, stale, unregistered; no flag; another triangle count |
//! | `DirectLightingInjectionTask` | `depth.texture`, `direct_lighting` | float colour or depth format (depth: `RClipSpace` only) | integer formats |
//! | denoise tasks | `common.context` | live denoising context | stale: [`Error::InvalidHandle`] |
//! | denoise tasks | `common.motion.scale` | finite | NaN/∞ |
//! | `DenoisingContextInput` | `max_width/max_height` | 1..=16384, 16 B × pixels within the device's storage binding size | otherwise |
//! | denoise tasks | `common.context` | created for the task's `SignalType` | another signal type |
//! | denoise tasks | `viewport` | within the context's `max_width × max_height` | larger |

#![warn(missing_docs)]

// The SDK's layers, lowest first; a module imports only from its own layer and those before it,
// no two files or folders import each other, and every import names the module that owns the
// item, never the crate root's re-export (checked by `tests/layering.rs`):
//
// 1. foundation: `error`, `version`, `handles`, `tasks` (every public task and input type),
//    `logging`, `allocations`, `container`, `camera`
// 2. GPU helpers: `gpu` (layouts, recorder, buffers, shaders), `staging`, `timing`, `device`
// 3. `cpu`: the CPU reference BVH (the tests' oracle)
// 4. `scene`: geometry ingestion, pools, BLAS/TLAS builds, and `scene::traversal`, the one
//    seam every tracing pass binds
// 5. `cache`: the direct lighting cache (allocation, injection, transfer, sampling)
// 6. `trace`: ray batches, debug views, the trace tasks
// 7. `denoise`: the denoisers and their history
// 8. `context`: the public calls; plans a container (every check) and records it
//
// docs/architecture.md is the map of these modules and of one task's data flow.

mod allocations;
mod cache;
mod camera;
mod container;
mod context;
pub mod cpu;
mod denoise;
mod device;
mod error;
mod gpu;
mod handles;
mod logging;
mod scene;
mod staging;
mod tasks;
mod timing;
mod trace;
mod version;

pub use allocations::{BlasCompaction, BlasMemory, ResourceAllocations};
pub use cache::{CacheAllocation, CacheLevel};
pub use container::TaskContainer;
pub use context::{
    shader_variants, DroppedTriangles, ExecuteContext, InitSettings, RecordedTaskCounts,
    ShaderVariant, INSTANCE_RECORD_SIZE,
};
pub use device::{
    hardware_ray_query_features, hardware_ray_query_limits, optional_features,
    optional_features_supported, required_features, required_limits, BackendChoice, BackendReport,
    TraversalBackend,
};
pub use error::{Error, HandleKind, Result};
pub use gpu::compose::{compose_shader, shader_modules, ComposeError};
pub use handles::{DenoisingContextHandle, GeometryHandle, GpuTaskHandle, InstanceHandle};
pub use logging::{LogCallback, Severity};
pub use tasks::*;
pub use timing::{GpuTimings, PassTiming};
pub use version::{Version, VERSION};
