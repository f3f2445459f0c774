//! A minimal deferred G-buffer pass: what an engine already renders, and what the SDK's trace
//! tasks and denoisers read. One raster pass writes depth, world normals, F0 + roughness,
//! motion vectors and the sun's direct light (unshadowed: the SDK's shadow trace supplies the
//! shadow in these examples).

use super::{Camera, Scene};
use bytemuck::Zeroable;
use glam::{Mat4, Vec3, Vec4};
use kickstart_rt as ksrt;
use wgpu::util::DeviceExt;

const SHADER: &str = r#"
struct Frame {
    view_proj: mat4x4<f32>,
    prev_view_proj: mat4x4<f32>,
    to_sun: vec4<f32>,
    sun_color: vec4<f32>,
    models: array<mat4x4<f32>, 16>,
    albedo: array<vec4<f32>, 16>,
}
@group(0) @binding(0) var<uniform> frame: Frame;

struct Varyings {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) @interpolate(flat) object: u32,
}

@vertex
fn vs_main(@location(0) p: vec3<f32>, @location(1) n: vec3<f32>,
           @builtin(instance_index) object: u32) -> Varyings {
    let model = frame.models[object];
    let world = (model * vec4(p, 1.0)).xyz;
    return Varyings(frame.view_proj * vec4(world, 1.0), world, (model * vec4(n, 0.0)).xyz, object);
}

struct Targets {
    @location(0) normal: vec4<f32>,
    @location(1) specular: vec4<f32>,
    @location(2) motion: vec2<f32>,
    @location(3) direct: vec4<f32>,
}

fn uv_of(clip: vec4<f32>) -> vec2<f32> {
    return clip.xy / clip.w * vec2(0.5, -0.5) + 0.5;
}

@fragment
fn fs_main(v: Varyings) -> Targets {
    let n = normalize(v.normal);
    let albedo = frame.albedo[v.object].rgb;
    let uv = uv_of(frame.view_proj * vec4(v.world, 1.0));
    let prev_uv = uv_of(frame.prev_view_proj * vec4(v.world, 1.0));
    let sun = albedo / 3.14159265 * frame.sun_color.rgb * max(dot(n, frame.to_sun.xyz), 0.0);
    // F0 of a dielectric (0.04) and roughness 0.4 in alpha, as the SDK's defaults read them.
    // The normal's alpha: which object (+1; 0 where nothing was drawn), for the composite.
    return Targets(vec4(n, f32(v.object + 1u)), vec4(0.04, 0.04, 0.04, 0.4),
                   prev_uv - uv, vec4(sun, 1.0));
}
"#;

/// The uniform block of `SHADER`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct FrameUniform {
    view_proj: Mat4,
    prev_view_proj: Mat4,
    to_sun: Vec4,
    sun_color: Vec4,
    models: [Mat4; MAX_OBJECTS],
    albedo: [Vec4; MAX_OBJECTS],
}

/// Objects the uniform block has room for.
pub const MAX_OBJECTS: usize = 16;

/// The G-buffer's textures (all `TEXTURE_BINDING`, which the SDK needs for its inputs).
pub struct GBuffer {
    /// `Depth32Float` hardware depth (the SDK's `DepthType::RClipSpace`).
    pub depth: wgpu::Texture,
    /// World-space normal in RGB (`NormalType::RgbVector`); alpha: the object's index + 1, 0
    /// where nothing was drawn (the composite looks its albedo up).
    pub normal: wgpu::Texture,
    /// F0 in RGB, roughness in A (the SDK's default roughness mask).
    pub specular: wgpu::Texture,
    /// previous_uv − uv (`MotionType::RgViewSpace`).
    pub motion: wgpu::Texture,
    /// HDR direct lighting (`Rgba16Float`).
    pub direct: wgpu::Texture,
    pipeline: wgpu::RenderPipeline,
    uniform: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

// Within the 32 bytes a pixel that WebGPU's default limits allow for colour targets (an RGBA8
// target counts 8), so there is no albedo target: the normal's alpha names the object instead.
const FORMATS: [wgpu::TextureFormat; 4] = [
    wgpu::TextureFormat::Rgba16Float, // normal
    wgpu::TextureFormat::Rgba8Unorm,  // specular
    wgpu::TextureFormat::Rg16Float,   // motion
    wgpu::TextureFormat::Rgba16Float, // direct
];

impl GBuffer {
    /// The G-buffer's textures and pipeline for `size` images.
    pub fn new(device: &wgpu::Device, (width, height): (u32, u32)) -> GBuffer {
        let texture = |label, format| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width,
                    height,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            })
        };
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("gbuffer"),
            source: wgpu::ShaderSource::Wgsl(SHADER.into()),
        });
        let targets = FORMATS.map(|f| Some(f.into()));
        let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("gbuffer"),
            layout: None,
            vertex: wgpu::VertexState {
                module: &module,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &[Some(wgpu::VertexBufferLayout {
                    array_stride: 24,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3],
                })],
            },
            primitive: wgpu::PrimitiveState {
                cull_mode: Some(wgpu::Face::Back),
                ..Default::default()
            },
            depth_stencil: Some(wgpu::DepthStencilState {
                format: wgpu::TextureFormat::Depth32Float,
                depth_write_enabled: Some(true),
                depth_compare: Some(wgpu::CompareFunction::Less),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &module,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &targets,
            }),
            multiview_mask: None,
            cache: None,
        });
        let uniform = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("gbuffer frame"),
            contents: bytemuck::bytes_of(&FrameUniform::zeroed()),
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("gbuffer"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: uniform.as_entire_binding(),
            }],
        });
        GBuffer {
            depth: texture("depth", wgpu::TextureFormat::Depth32Float),
            normal: texture("normal", FORMATS[0]),
            specular: texture("specular", FORMATS[1]),
            motion: texture("motion", FORMATS[2]),
            direct: texture("direct", FORMATS[3]),
            pipeline,
            uniform,
            bind_group,
        }
    }

    /// Records the G-buffer pass of `scene` seen by `camera` (last frame: `prev`), lit by a sun
    /// shining towards `sun_direction`.
    pub fn render(
        &self,
        queue: &wgpu::Queue,
        encoder: &mut wgpu::CommandEncoder,
        scene: &Scene,
        camera: &Camera,
        prev: &Camera,
        sun_direction: Vec3,
    ) {
        let mut u = FrameUniform::zeroed();
        u.view_proj = camera.projection() * camera.view();
        u.prev_view_proj = prev.projection() * prev.view();
        u.to_sun = (-sun_direction.normalize()).extend(0.0);
        u.sun_color = Vec4::new(3.0, 2.9, 2.7, 0.0);
        for (i, o) in scene.objects.iter().take(MAX_OBJECTS).enumerate() {
            u.models[i] = Mat4::from(o.transform);
            u.albedo[i] = o.albedo.extend(1.0);
        }
        queue.write_buffer(&self.uniform, 0, bytemuck::bytes_of(&u));
        let view = |t: &wgpu::Texture| t.create_view(&Default::default());
        let views = [&self.normal, &self.specular, &self.motion, &self.direct].map(view);
        let color = views.each_ref().map(|v| {
            Some(wgpu::RenderPassColorAttachment {
                view: v,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                    store: wgpu::StoreOp::Store,
                },
            })
        });
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("gbuffer"),
            color_attachments: &color,
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &view(&self.depth),
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            ..Default::default()
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &self.bind_group, &[]);
        for (i, o) in scene.objects.iter().take(MAX_OBJECTS).enumerate() {
            let mesh = &scene.meshes[o.shape as usize];
            pass.set_vertex_buffer(0, mesh.vertices.slice(..));
            pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
            // The instance index selects the object's transform and colour in the shader.
            pass.draw_indexed(0..mesh.index_count, 0, i as u32..i as u32 + 1);
        }
    }

    /// The inputs every trace task shares, read from this G-buffer.
    pub fn trace_common(&self, view: ksrt::ViewInfo, frame_index: u32) -> ksrt::TraceTaskCommon {
        let v = |t: &wgpu::Texture| t.create_view(&Default::default());
        let mut common = ksrt::TraceTaskCommon::new(self.depth_input(), self.normal_input());
        common.roughness.texture = Some(v(&self.specular));
        common.specular.texture = Some(v(&self.specular));
        common.direct_lighting = Some(v(&self.direct));
        common.view = view;
        // Pushes ray origins off the surface by an amount that grows with camera distance.
        common.ray_offset.offset_type = ksrt::RayOffsetType::CamDistance;
        // Each frame a new noise pattern, which the denoisers accumulate over time.
        common.debug_parameters.frame_index = frame_index;
        common
    }

    /// The inputs every denoise task shares, for the denoising context `context`.
    pub fn denoise_common(
        &self,
        context: ksrt::DenoisingContextHandle,
        view: ksrt::ViewInfo,
        first_frame: bool,
    ) -> ksrt::DenoiseTaskCommon {
        ksrt::DenoiseTaskCommon {
            context,
            viewport: None,
            depth: self.depth_input(),
            normal: self.normal_input(),
            roughness: ksrt::RoughnessInput {
                texture: Some(self.specular.create_view(&Default::default())),
                ..Default::default()
            },
            motion: Some(ksrt::MotionInput {
                texture: self.motion.create_view(&Default::default()),
                motion_type: ksrt::MotionType::RgViewSpace,
                scale: Vec3::ONE,
            }),
            view,
            half_resolution_mode: ksrt::HalfResolutionMode::Off,
            // There is no history to blend with on the first frame (or after a camera cut).
            mode: if first_frame {
                ksrt::DenoiseMode::DiscardHistory
            } else {
                ksrt::DenoiseMode::Continue
            },
        }
    }

    fn depth_input(&self) -> ksrt::DepthInput {
        ksrt::DepthInput {
            texture: self.depth.create_view(&Default::default()),
            depth_type: ksrt::DepthType::RClipSpace,
        }
    }

    fn normal_input(&self) -> ksrt::NormalInput {
        ksrt::NormalInput {
            texture: self.normal.create_view(&Default::default()),
            normal_type: ksrt::NormalType::RgbVector,
            normal_to_world: Mat4::IDENTITY,
        }
    }
}
