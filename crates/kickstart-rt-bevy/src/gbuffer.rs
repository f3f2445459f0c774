//! The compute pass that unpacks Bevy's deferred G-buffer into the SDK's input textures.

use bevy::prelude::*;
use bevy::render::renderer::RenderDevice;

use crate::view::ViewResources;

/// The unpack pipeline.
#[derive(Resource)]
pub(crate) struct Unpack {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl Unpack {
    /// Compiles the pass on Bevy's device.
    pub fn new(render_world: &World) -> Result<Unpack, String> {
        let device = render_world.resource::<RenderDevice>().wgpu_device();
        let storage = |binding| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format: wgpu::TextureFormat::Rgba16Float,
                view_dimension: wgpu::TextureViewDimension::D2,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("kickstart-rt unpack G-buffer"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Uint,
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                storage(1),
                storage(2),
                storage(3),
            ],
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("kickstart-rt unpack G-buffer"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shaders/unpack_gbuffer.wgsl").into()),
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("kickstart-rt unpack G-buffer"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("kickstart-rt unpack G-buffer"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("unpack"),
            compilation_options: Default::default(),
            cache: None,
        });
        Ok(Unpack { pipeline, layout })
    }

    /// Records the unpack of `deferred` (Bevy's `Rgba32Uint` G-buffer) into `view`'s textures.
    pub fn record(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        deferred: &wgpu::TextureView,
        view: &ViewResources,
    ) {
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("kickstart-rt unpack G-buffer"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(deferred),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&view.normal_roughness),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::TextureView(&view.specular),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: wgpu::BindingResource::TextureView(&view.diffuse_color),
                },
            ],
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("kickstart-rt unpack G-buffer"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(view.size.x.div_ceil(8), view.size.y.div_ceil(8), 1);
    }
}
