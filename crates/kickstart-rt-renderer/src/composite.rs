//! The composite: the rasterised direct light plus the SDK's channels, tone mapped.
//!
//! `final = direct + sun × (shadow_rt − shadow_map) + diffuse_albedo × diffuse_gi × ao +
//! specular_radiance × EnvBRDF(F0, roughness, n·v)`, where the SDK's specular and diffuse
//! outputs are incoming radiance (the engine applies the BRDF, as the reference says): the
//! diffuse one is weighted by the Lambertian albedo, the specular one by the split-sum BRDF
//! integral in Karis's analytic fit ("Physically Based Shading on Mobile", 2014). Without diffuse
//! GI a constant ambient (3% of white) stands in, so shadows are not black. Tone mapping: a fixed
//! exposure of 1 and the ACES filmic fit of Narkowicz (2015), then sRGB.

use wgpu::util::DeviceExt;

use crate::frame::{Produced, SdkOutputs};
use crate::raster::ViewTargets;

/// Fixed exposure (a multiplier on linear radiance before tone mapping).
pub const EXPOSURE: f32 = 1.0;
/// Ambient radiance used when there is no diffuse GI.
pub const AMBIENT: f32 = 0.03;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Settings {
    enabled: [f32; 4],
    params: [f32; 4],
    view: [f32; 4],
}

/// What the composite shows.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Show {
    /// The composite.
    #[default]
    Final,
    /// The rasterised direct light only.
    Direct,
    /// The specular channel (denoised when it is).
    Specular,
    /// The diffuse channel.
    Diffuse,
    /// The AO channel.
    Ao,
    /// The shadow visibility.
    Shadow,
    /// The SDK debug view (`SdkOutputs::debug`).
    Debug,
}

impl Show {
    /// Every mode, in the viewer's cycling order.
    pub const ALL: [Show; 7] = [
        Show::Final,
        Show::Direct,
        Show::Specular,
        Show::Diffuse,
        Show::Ao,
        Show::Shadow,
        Show::Debug,
    ];
}

/// The composite pipeline for one display format.
pub struct Composite {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    settings: wgpu::Buffer,
    encode_srgb: bool,
}

impl Composite {
    /// A composite writing HDR (`Rgba16Float`) and display values in `ldr_format` (an sRGB format
    /// gets linear values and encodes on store; any other gets sRGB-encoded values).
    pub fn new(device: &wgpu::Device, ldr_format: wgpu::TextureFormat) -> Composite {
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("ksrt composite"),
            source: wgpu::ShaderSource::Wgsl(include_str!("../shaders/composite.wgsl").into()),
        });
        use crate::raster::gpu_scene_entries as e;
        let mut entries = vec![e::uniform(0), e::uniform(1)];
        entries.push(e::texture(2, wgpu::TextureSampleType::Depth));
        for b in 3..=12 {
            entries.push(e::texture(b, e::UNFILTERED));
        }
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ksrt composite"),
            entries: &entries,
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("ksrt composite"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("ksrt composite"),
            layout: Some(&pipeline_layout),
            vertex: wgpu::VertexState {
                module: &shader,
                entry_point: Some("vs_fullscreen"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &shader,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[
                    Some(wgpu::TextureFormat::Rgba16Float.into()),
                    Some(ldr_format.into()),
                ],
            }),
            multiview_mask: None,
            cache: None,
        });
        let settings = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("ksrt composite settings"),
            contents: bytemuck::bytes_of(&Settings {
                enabled: [0.0; 4],
                params: [0.0; 4],
                view: [0.0; 4],
            }),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        Composite {
            pipeline,
            layout,
            settings,
            encode_srgb: !ldr_format.is_srgb(),
        }
    }

    /// Records the composite of `main` and the SDK's `outputs` (the channels `produced` says
    /// exist, denoised where denoised) into `hdr` and `ldr`. Writes its settings with a queue
    /// write: call once per frame, before submitting.
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        &self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        main: &ViewTargets,
        outputs: &SdkOutputs,
        produced: Produced,
        show: Show,
        hdr: &wgpu::TextureView,
        ldr: &wgpu::TextureView,
    ) {
        let flag = |b: bool| if b { 1.0 } else { 0.0 };
        let pick = |(_, denoised): (bool, bool), raw: &wgpu::Texture, den: &wgpu::Texture| {
            if denoised { den } else { raw }.create_view(&Default::default())
        };
        let settings = Settings {
            enabled: [
                flag(produced.specular.0),
                flag(produced.diffuse.0),
                flag(produced.ao.0),
                flag(produced.shadow.0),
            ],
            params: [
                flag(!produced.shadow.1),
                flag(self.encode_srgb),
                EXPOSURE,
                AMBIENT,
            ],
            view: [show as u32 as f32, 0.0, 0.0, 0.0],
        };
        queue.write_buffer(&self.settings, 0, bytemuck::bytes_of(&settings));
        let views = [
            ViewTargets::view(&main.depth),
            ViewTargets::view(&main.normal),
            ViewTargets::view(&main.base_color),
            ViewTargets::view(&main.specular),
            ViewTargets::view(&main.direct),
            ViewTargets::view(&main.sun),
            pick(
                produced.specular,
                &outputs.specular,
                &outputs.specular_denoised,
            ),
            pick(
                produced.diffuse,
                &outputs.diffuse,
                &outputs.diffuse_denoised,
            ),
            pick(produced.ao, &outputs.ao, &outputs.ao_denoised),
            pick(produced.shadow, &outputs.shadow, &outputs.shadow_denoised),
            outputs.debug.create_view(&Default::default()),
        ];
        let mut entries = vec![
            wgpu::BindGroupEntry {
                binding: 0,
                resource: main.view_buffer().as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: self.settings.as_entire_binding(),
            },
        ];
        for (k, v) in views.iter().enumerate() {
            entries.push(wgpu::BindGroupEntry {
                binding: 2 + k as u32,
                resource: wgpu::BindingResource::TextureView(v),
            });
        }
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ksrt composite"),
            layout: &self.layout,
            entries: &entries,
        });
        let attach = |view| {
            Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                    store: wgpu::StoreOp::Store,
                },
            })
        };
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("ksrt composite"),
            color_attachments: &[attach(hdr), attach(ldr)],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.draw(0..3, 0..1);
    }
}
