//! The calls the renderer and `ksrt` make into the SDK's ray tracing API
//! (docs/ray-tracing-core.md, "Public API added with the ray tracing core"), in one place: ray
//! batches, GPU timings, BVH build options and BLAS read-back.

use kickstart_rt as ksrt;

use crate::error::AnyResult;

pub use ksrt::{GpuHit, GpuRay};

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

/// A `BvhBuildTask` building up to `max_blas_build_count` BLASes, and the TLAS when `tlas` is
/// `Some`.
pub fn bvh_build_task(max_blas_build_count: u32, tlas: Option<Tlas>) -> ksrt::BvhBuildTask {
    ksrt::BvhBuildTask {
        max_blas_build_count: max_blas_build_count.max(1),
        build_tlas: tlas.is_some(),
        tlas_update: match tlas {
            Some(Tlas::Auto) | None => ksrt::TlasUpdate::Auto,
            Some(Tlas::Rebuild) => ksrt::TlasUpdate::Rebuild,
            Some(Tlas::Refit) => ksrt::TlasUpdate::Refit,
        },
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
    Ok(ksrt::RenderTask::TraceRays(ksrt::TraceRaysTask {
        rays: rays.clone(),
        ray_offset: offset,
        ray_count: count,
        hits: hits.clone(),
        hit_offset: offset,
        query: match query {
            Query::Closest => ksrt::RayQuery::ClosestHit,
            Query::Any => ksrt::RayQuery::AnyHit,
        },
        instance_mask: ksrt::InstanceInclusionMask::VISIBLE_IN_RT,
    }))
}

/// The span of `timings` over the passes whose labels start with any of `prefixes`, in
/// milliseconds; an error listing the task's passes when none matches.
pub fn span_ms(timings: &ksrt::GpuTimings, prefixes: &[&str]) -> AnyResult<f64> {
    timings.span_ms(prefixes).ok_or_else(|| {
        format!(
            "no GPU pass labelled {prefixes:?} in this task (passes: {:?})",
            timings.passes.iter().map(|p| p.label).collect::<Vec<_>>()
        )
        .into()
    })
}

/// The SAH cost of a built geometry's BLAS, comparable to `kickstart_rt::cpu::CpuBvh::sah_cost`.
pub fn blas_sah_cost(ctx: &ksrt::ExecuteContext, geometry: ksrt::GeometryHandle) -> AnyResult<f64> {
    Ok(ctx.read_back_blas(geometry)?.sah_cost as f64)
}

/// Creates every SDK pipeline now, so no timed task pays for shader compilation.
pub fn prepare_pipelines(ctx: &ksrt::ExecuteContext) -> AnyResult<()> {
    ctx.prepare_pipelines();
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
