//! The traversal as the passes that trace rays see it: the scene's buffers bound at
//! `@group(0)`, the WGSL traversal module they include, and the name of its stack. This is the
//! one seam between the scene and every tracing pass (ray batches, debug views, trace tasks,
//! the lighting cache's injection), so another traversal backend can stand in its place.

use crate::gpu::layout::{storage_entry, BoundLayout};
use crate::gpu::Recorder;

/// The traversal module (`shaders/traverse.wgsl`) that every tracing pass prepends.
pub(crate) const TRAVERSE_WGSL: &str = concat!(
    include_str!("../../shaders/scene_types.wgsl"),
    include_str!("../../shaders/traverse.wgsl")
);
/// The scene as the traversal module binds it at `@group(0)` (layouts in
/// docs/ray-tracing-core.md).
#[derive(Clone, Copy)]
pub(crate) struct SceneBuffers<'a> {
    /// TLAS nodes (binding 0).
    pub tlas_nodes: &'a wgpu::Buffer,
    /// Instance table (binding 1).
    pub instances: &'a wgpu::Buffer,
    /// Geometry table (binding 2).
    pub geometries: &'a wgpu::Buffer,
    /// BLAS node pool (binding 3).
    pub blas_nodes: &'a wgpu::Buffer,
    /// Triangle pool (binding 4).
    pub triangles: &'a wgpu::Buffer,
}

impl SceneBuffers<'_> {
    /// The explicit layout of the `@group(0)` scene bindings (five read-only storage buffers,
    /// bindings 0–4), for pipelines built with explicit layouts.
    pub fn layout(device: &wgpu::Device) -> BoundLayout {
        let entries = [0, 1, 2, 3, 4].map(|b| storage_entry(b, true));
        BoundLayout::new(device, "kickstart-rt scene", &entries)
    }

    /// The `@group(0)` bind group of a pipeline that includes the traversal module.
    pub fn bind_group(
        &self,
        rec: &Recorder<'_>,
        pipeline: &wgpu::ComputePipeline,
    ) -> wgpu::BindGroup {
        rec.bind_buffers(
            "kickstart-rt scene",
            pipeline,
            0,
            &[
                self.tlas_nodes.as_entire_binding(),
                self.instances.as_entire_binding(),
                self.geometries.as_entire_binding(),
                self.blas_nodes.as_entire_binding(),
                self.triangles.as_entire_binding(),
            ],
        )
    }
}

/// The traversal module's stack (`var<private> rt_stack`): written before it is read, so the
/// passes that include the module may drop its zero fill ([`traversal_pipeline`]).
pub(crate) const TRAVERSAL_STACK: &str = "rt_stack";
