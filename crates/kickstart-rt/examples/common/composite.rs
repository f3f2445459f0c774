//! The window example's last pass: combines the G-buffer's direct light with the SDK's denoised
//! outputs and tone maps the result into the window's surface.
//!
//! The SDK's specular and diffuse outputs are incoming radiance, so the engine multiplies them by
//! its material terms: `direct × shadow + diffuse × albedo × AO + specular × F`, plus a sky
//! ambient term darkened by AO.

use super::gbuffer::{GBuffer, MAX_OBJECTS};
use super::Scene;
use glam::Vec4;
use wgpu::util::DeviceExt;

const SHADER: &str = r#"
@group(0) @binding(0) var normal_tex: texture_2d<f32>;
@group(0) @binding(1) var direct_tex: texture_2d<f32>;
@group(0) @binding(2) var specular_tex: texture_2d<f32>;
@group(0) @binding(3) var diffuse_tex: texture_2d<f32>;
@group(0) @binding(4) var ao_tex: texture_2d<f32>;
@group(0) @binding(5) var shadow_tex: texture_2d<f32>;
@group(0) @binding(6) var<uniform> albedo: array<vec4<f32>, 16>;

// Whether the surface stores linear values (encode sRGB here) or sRGB ones (the GPU encodes).
override ENCODE_SRGB: bool = false;

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4(uv * 2.0 - 1.0, 0.0, 1.0);
}

fn aces(x: vec3<f32>) -> vec3<f32> {
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), vec3(0.0), vec3(1.0));
}

@fragment
fn fs_main(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    let p = vec2<i32>(pos.xy);
    let object = i32(textureLoad(normal_tex, p, 0).a + 0.5) - 1;
    let sky = vec3(0.45, 0.6, 0.85);
    var color = sky;
    if object >= 0 {
        let a = albedo[object].rgb;
        let ao = textureLoad(ao_tex, p, 0).r;
        let shadow = textureLoad(shadow_tex, p, 0).r;
        color = textureLoad(direct_tex, p, 0).rgb * shadow
            + textureLoad(diffuse_tex, p, 0).rgb * a * ao
            + sky * 0.3 * a * ao
            // A dielectric's reflectance averaged over angles, standing in for the EnvBRDF term.
            + textureLoad(specular_tex, p, 0).rgb * 0.08;
    }
    var mapped = aces(color);
    if ENCODE_SRGB {
        mapped = pow(mapped, vec3(1.0 / 2.2));
    }
    return vec4(mapped, 1.0);
}
"#;

/// The SDK's denoised outputs the composite reads.
pub struct Lighting<'a> {
    /// Specular radiance.
    pub specular: &'a wgpu::Texture,
    /// Diffuse radiance.
    pub diffuse: &'a wgpu::Texture,
    /// Ambient occlusion (R: 1 open).
    pub ao: &'a wgpu::Texture,
    /// Sun visibility (R: 1 lit).
    pub shadow: &'a wgpu::Texture,
}

/// The composite pipeline and its bind group.
pub struct Composite {
    pipeline: wgpu::RenderPipeline,
    bind_group: wgpu::BindGroup,
}

impl Composite {
    /// A composite of `gbuffer` and `lighting` for `scene`'s objects, into `format` targets.
    pub fn new(
        device: &wgpu::Device,
        format: wgpu::TextureFormat,
        scene: &Scene,
        gbuffer: &GBuffer,
        lighting: &Lighting<'_>,
    ) -> Composite {
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("composite"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let encode = if format.is_srgb() { 0.0 } else { 1.0 };
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("composite"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: Default::default(),
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: wgpu::PipelineCompilationOptions {
                    constants: &[("ENCODE_SRGB", encode)],
                    ..Default::default()
                },
                targets: &[Some(format.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        let mut albedo = [Vec4::ZERO; MAX_OBJECTS];
        for (a, o) in albedo.iter_mut().zip(&scene.objects) {
            *a = o.albedo.extend(1.0);
        }
        let albedo = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("albedo"),
            contents: bytemuck::cast_slice(&albedo),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let views = [
            &gbuffer.normal,
            &gbuffer.direct,
            lighting.specular,
            lighting.diffuse,
            lighting.ao,
            lighting.shadow,
        ]
        .map(|t| t.create_view(&Default::default()));
        let mut entries: Vec<wgpu::BindGroupEntry> = views
            .iter()
            .enumerate()
            .map(|(i, v)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: wgpu::BindingResource::TextureView(v),
            })
            .collect();
        entries.push(wgpu::BindGroupEntry {
            binding: 6,
            resource: albedo.as_entire_binding(),
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("composite"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        Composite {
            pipeline,
            bind_group,
        }
    }

    /// Records the composite into `target`.
    pub fn render(&self, encoder: &mut wgpu::CommandEncoder, target: &wgpu::TextureView) {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("composite"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: target,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::BLACK),
                    store: wgpu::StoreOp::Store,
                },
            })],
            ..Default::default()
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        pass.draw(0..3, 0..1);
    }
}
