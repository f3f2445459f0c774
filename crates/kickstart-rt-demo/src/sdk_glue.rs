//! Every call `ksrt` makes into the SDK API that arrives with the ray tracing core
//! (docs/ray-tracing-core.md, "Public API added with the ray tracing core"), in one place.
//!
//! That API is not in the SDK yet. Each item below keeps the signature the rest of `ksrt` uses,
//! and its body is marked `TODO(rt-core)`: until the SDK has it, functions that cannot work
//! return an error that says so, and the rest fall back to today's API. Finishing the port means
//! replacing these bodies only (the intended code is in each comment).

use bytemuck::{Pod, Zeroable};
use kickstart_rt as ksrt;

use crate::AnyResult;

/// Error message of the calls whose SDK part does not exist yet.
fn not_yet(what: &str) -> Box<dyn std::error::Error> {
    format!(
        "{what} needs the SDK's ray tracing core API (docs/ray-tracing-core.md), which this build \
         of kickstart-rt does not have yet"
    )
    .into()
}

/// One ray of a `TraceRaysTask` batch: the layout of the SDK's `GpuRay` (32 bytes).
// TODO(rt-core): use `ksrt::GpuRay` and drop this copy of its layout.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuRay {
    /// Start point.
    pub origin: [f32; 3],
    /// Smallest accepted `t`.
    pub t_min: f32,
    /// Direction (need not be unit; `t` is in its units).
    pub dir: [f32; 3],
    /// Largest accepted `t` (∞ allowed).
    pub t_max: f32,
}

/// One result of a `TraceRaysTask` batch: the layout of the SDK's `GpuHit` (32 bytes).
// TODO(rt-core): use `ksrt::GpuHit` and drop this copy of its layout.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Pod, Zeroable)]
pub struct GpuHit {
    /// Ray parameter of the hit; −1 on a miss.
    pub t: f32,
    /// Barycentric weight of the triangle's second vertex.
    pub u: f32,
    /// Barycentric weight of the third vertex.
    pub v: f32,
    /// Instance slot index (`InstanceHandle::index`); `u32::MAX` on a miss.
    pub instance: u32,
    /// Triangle index within the instance's geometry.
    pub primitive: u32,
    /// Padding to 32 bytes.
    pub pad: [u32; 3],
}

impl GpuHit {
    /// Whether the ray hit anything.
    pub fn is_hit(&self) -> bool {
        self.instance != u32::MAX
    }
}

/// Which hit a ray batch asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Query {
    /// The closest hit (`RayQuery::ClosestHit`).
    Closest,
    /// Any hit, the first found (`RayQuery::AnyHit`): occlusion.
    Any,
}

/// How a `BvhBuildTask` treats the TLAS (`TlasUpdate`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Tlas {
    /// Refit when only transforms changed, rebuild otherwise.
    Auto,
    /// Always rebuild.
    Rebuild,
    /// Refit (the SDK rebuilds when the instance set changed).
    Refit,
}

/// `InitSettings` with GPU timestamps on or off.
pub fn init_settings(gpu_timing: bool) -> ksrt::InitSettings {
    // TODO(rt-core): `ksrt::InitSettings { gpu_timing, ..Default::default() }`.
    static WARNED: std::sync::Once = std::sync::Once::new();
    if gpu_timing {
        // Once per run, not once per context: the benchmark makes many.
        WARNED.call_once(|| {
            log::warn!(
                "GPU timing requested, but this SDK build has no InitSettings::gpu_timing yet"
            )
        });
    }
    ksrt::InitSettings::default()
}

/// A `BvhBuildTask` building up to `max_blas_build_count` BLASes, and the TLAS when `tlas` is
/// `Some`.
pub fn bvh_build_task(max_blas_build_count: u32, tlas: Option<Tlas>) -> ksrt::BvhBuildTask {
    // TODO(rt-core): add `tlas_update: match tlas { Some(Tlas::Auto) | None =>
    // ksrt::TlasUpdate::Auto, Some(Tlas::Rebuild) => ksrt::TlasUpdate::Rebuild,
    // Some(Tlas::Refit) => ksrt::TlasUpdate::Refit }`.
    ksrt::BvhBuildTask {
        max_blas_build_count: max_blas_build_count.max(1),
        build_tlas: tlas.is_some(),
    }
}

/// A `RenderTask::TraceRays` over `count` [`GpuRay`]s at byte `offset` of `rays`, writing as
/// many [`GpuHit`]s at the same byte offset of `hits`.
pub fn trace_rays_task(
    rays: &wgpu::Buffer,
    hits: &wgpu::Buffer,
    offset: u64,
    count: u32,
    query: Query,
) -> AnyResult<ksrt::RenderTask> {
    // TODO(rt-core):
    // Ok(ksrt::RenderTask::TraceRays(ksrt::TraceRaysTask {
    //     rays: rays.clone(), ray_offset: offset, ray_count: count,
    //     hits: hits.clone(), hit_offset: offset,
    //     query: match query { Query::Closest => ksrt::RayQuery::ClosestHit,
    //                          Query::Any => ksrt::RayQuery::AnyHit },
    //     instance_mask: ksrt::InstanceInclusionMask::VISIBLE_IN_RT,
    // }))
    let _ = (rays, hits, offset, count, query);
    Err(not_yet("RenderTask::TraceRays"))
}

/// Waits for the GPU timings of a submitted task and returns the span over the passes whose
/// labels start with any of `prefixes` (e.g. `["ingest", "blas build"]`), in milliseconds.
pub fn wait_span_ms(
    ctx: &ksrt::ExecuteContext,
    task: ksrt::GpuTaskHandle,
    prefixes: &[&str],
) -> AnyResult<f64> {
    // TODO(rt-core):
    // let timings = ctx.wait_for_gpu_timings(task)?;
    // timings.span_ms(prefixes).ok_or_else(|| format!(
    //     "no GPU pass labelled {prefixes:?} in this task (passes: {:?})",
    //     timings.passes.iter().map(|p| p.label).collect::<Vec<_>>()).into())
    let _ = (ctx, task, prefixes);
    Err(not_yet("GPU timing (ExecuteContext::wait_for_gpu_timings)"))
}

/// The SAH cost of a built geometry's BLAS, comparable to `kickstart_rt::cpu::CpuBvh::sah_cost`.
pub fn blas_sah_cost(ctx: &ksrt::ExecuteContext, geometry: ksrt::GeometryHandle) -> AnyResult<f64> {
    // TODO(rt-core): `Ok(ctx.read_back_blas(geometry)?.sah_cost as f64)`.
    let _ = (ctx, geometry);
    Err(not_yet("BLAS read-back (ExecuteContext::read_back_blas)"))
}

/// Creates every SDK pipeline now, so no timed task pays for shader compilation.
pub fn prepare_pipelines(ctx: &ksrt::ExecuteContext) -> AnyResult<()> {
    // TODO(rt-core): `ctx.prepare_pipelines()?; Ok(())` (when it returns a Result; else call it).
    let _ = ctx;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_and_hit_records_are_32_bytes() {
        // The SDK's GpuRay/GpuHit layouts (docs/ray-tracing-core.md): the batches are raw bytes.
        assert_eq!(std::mem::size_of::<GpuRay>(), 32);
        assert_eq!(std::mem::size_of::<GpuHit>(), 32);
    }
}
