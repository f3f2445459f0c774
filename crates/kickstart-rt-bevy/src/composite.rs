//! The full-screen pass that adds the SDK's results to Bevy's lit image.

use std::collections::HashMap;
use std::sync::Mutex;

use bevy::prelude::*;
use bevy::render::renderer::RenderDevice;
use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

use crate::view::ViewResources;

/// The composite's uniforms (see `shaders/composite.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Pod, Zeroable)]
pub(crate) struct CompositeParams {
    pub world_from_clip: [[f32; 4]; 4],
    pub camera: [f32; 4],
    pub to_sun: [f32; 4],
    pub sun: [f32; 4],
    pub effects: [u32; 4],
    /// Per signal, where the composite reads it in each pixel's block (see `traced_pixel` in
    /// `shaders/composite.wgsl`).
    pub traced_pixels: [u32; 4],
}

/// The composite's pipelines, one per target format.
#[derive(Resource)]
pub(crate) struct Composite {
    module: wgpu::ShaderModule,
    layout: wgpu::BindGroupLayout,
    pipeline_layout: wgpu::PipelineLayout,
    pipelines: Mutex<HashMap<wgpu::TextureFormat, wgpu::RenderPipeline>>,
}

/// The textures one composite reads.
pub(crate) struct CompositeInputs<'a> {
    /// Bevy's lit image.
    pub lit: &'a wgpu::TextureView,
    /// Bevy's depth (prepass copy).
    pub depth: &'a wgpu::TextureView,
    /// Reflections, GI, AO, shadow: denoised or raw.
    pub signals: &'a [wgpu::TextureView; 4],
}

impl Composite {
    /// Compiles the shader on Bevy's device; pipelines are made per target format on first use.
    pub fn new(render_world: &World) -> Result<Composite, String> {
        let device = render_world.resource::<RenderDevice>().wgpu_device();
        let texture = |binding, sample_type| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Texture {
                sample_type,
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        };
        let float = wgpu::TextureSampleType::Float { filterable: false };
        let mut entries = vec![
            texture(0, float),
            texture(1, wgpu::TextureSampleType::Depth),
        ];
        entries.extend((2..9).map(|b| texture(b, float)));
        entries.push(wgpu::BindGroupLayoutEntry {
            binding: 9,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        });
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("kickstart-rt composite"),
            entries: &entries,
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("kickstart-rt composite"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("kickstart-rt composite"),
            source: wgpu::ShaderSource::Wgsl(include_str!("shaders/composite.wgsl").into()),
        });
        Ok(Composite {
            module,
            layout,
            pipeline_layout,
            pipelines: Mutex::new(HashMap::new()),
        })
    }

    fn pipeline(&self, device: &wgpu::Device, format: wgpu::TextureFormat) -> wgpu::RenderPipeline {
        let mut pipelines = self.pipelines.lock().unwrap_or_else(|e| e.into_inner());
        pipelines
            .entry(format)
            .or_insert_with(|| {
                device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some("kickstart-rt composite"),
                    layout: Some(&self.pipeline_layout),
                    vertex: wgpu::VertexState {
                        module: &self.module,
                        entry_point: Some("fullscreen"),
                        compilation_options: Default::default(),
                        buffers: &[],
                    },
                    primitive: Default::default(),
                    depth_stencil: None,
                    multisample: Default::default(),
                    fragment: Some(wgpu::FragmentState {
                        module: &self.module,
                        entry_point: Some("composite"),
                        compilation_options: Default::default(),
                        targets: &[Some(format.into())],
                    }),
                    multiview_mask: None,
                    cache: None,
                })
            })
            .clone()
    }

    /// Records the composite of `inputs` and `view`'s G-buffer into `target` (of `format`).
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        inputs: CompositeInputs,
        view: &ViewResources,
        params: &CompositeParams,
        target: &wgpu::TextureView,
        format: wgpu::TextureFormat,
    ) {
        let pipeline = self.pipeline(device, format);
        let uniforms = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("kickstart-rt composite"),
            contents: bytemuck::bytes_of(params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let views = [
            inputs.lit,
            inputs.depth,
            &view.normal_roughness,
            &view.specular,
            &view.diffuse_color,
            &inputs.signals[0],
            &inputs.signals[1],
            &inputs.signals[2],
            &inputs.signals[3],
        ];
        let mut entries: Vec<wgpu::BindGroupEntry> = views
            .iter()
            .enumerate()
            .map(|(i, v)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: wgpu::BindingResource::TextureView(v),
            })
            .collect();
        entries.push(wgpu::BindGroupEntry {
            binding: 9,
            resource: uniforms.as_entire_binding(),
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("kickstart-rt composite"),
            layout: &self.layout,
            entries: &entries,
        });
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("kickstart-rt composite"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Load,
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.draw(0..3, 0..1);
    }
}
