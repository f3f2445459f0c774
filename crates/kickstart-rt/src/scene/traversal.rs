//! The traversal as the passes that trace rays see it: the scene's buffers bound at
//! `@group(0)`, the WGSL traversal module they import (`#import scene/traversal`, see
//! [`crate::gpu::compose`]), and the name of its stack. This is the one seam between the scene and
//! every tracing pass (ray batches, debug views, trace tasks, the lighting cache's injection), so
//! another traversal backend can stand in its place: a module of the same name and functions, and
//! the buffers it binds.

use std::sync::OnceLock;

use crate::gpu::layout::BoundLayout;
use crate::gpu::reflect::{named_entries, ReflectedShader, ShaderBinding};

/// The `@group(0)` bindings of the traversal module, as it declares them.
fn scene_bindings() -> &'static [ShaderBinding] {
    static BINDINGS: OnceLock<Vec<ShaderBinding>> = OnceLock::new();
    BINDINGS.get_or_init(|| {
        ReflectedShader::compose(&["scene/traversal"], &[])
            .reflection()
            .group_bindings(0)
    })
}

/// The scene as the traversal module binds it at `@group(0)` (layouts in
/// docs/ray-tracing-core.md).
#[derive(Clone, Copy)]
pub(crate) struct SceneBuffers<'a> {
    /// TLAS nodes (`rt_tlas_nodes`).
    pub tlas_nodes: &'a wgpu::Buffer,
    /// Instance table (`rt_instances`).
    pub instances: &'a wgpu::Buffer,
    /// Geometry table (`rt_geometries`).
    pub geometries: &'a wgpu::Buffer,
    /// BLAS node pool (`rt_blas_nodes`).
    pub blas_nodes: &'a wgpu::Buffer,
    /// Triangle pool (`rt_triangles`).
    pub triangles: &'a wgpu::Buffer,
}

impl SceneBuffers<'_> {
    /// The explicit layout of the `@group(0)` scene bindings, as the traversal module declares
    /// them, for pipelines built with explicit layouts.
    pub fn layout(device: &wgpu::Device) -> BoundLayout {
        let entries: Vec<_> = scene_bindings()
            .iter()
            .map(ShaderBinding::layout_entry)
            .collect();
        BoundLayout::new(device, "kickstart-rt scene", &entries)
    }

    /// The `@group(0)` bind group of a pipeline that imports the traversal module, each buffer
    /// at the binding the module declares for it.
    pub fn bind_group(
        &self,
        device: &wgpu::Device,
        pipeline: &wgpu::ComputePipeline,
    ) -> wgpu::BindGroup {
        let resources = [
            ("rt_tlas_nodes", self.tlas_nodes.as_entire_binding()),
            ("rt_instances", self.instances.as_entire_binding()),
            ("rt_geometries", self.geometries.as_entire_binding()),
            ("rt_blas_nodes", self.blas_nodes.as_entire_binding()),
            ("rt_triangles", self.triangles.as_entire_binding()),
        ];
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("kickstart-rt scene"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &named_entries("kickstart-rt scene", scene_bindings(), &resources),
        })
    }
}

/// The traversal module's stack (`var<private> rt_stack`): written before it is read, so the
/// passes that include the module may drop its zero fill ([`traversal_pipeline`]).
pub(crate) const TRAVERSAL_STACK: &str = "rt_stack";
