//! The scene on the GPU for rasterising: vertex streams, one uniform record per instance, a
//! material bind group per mesh (textures or 1×1 white), the lights, the sun's shadow map, and
//! the G-buffer, shadow and lighting pipelines.

use glam::{Mat4, Vec3};
use wgpu::util::DeviceExt;

use crate::scene::{Light, Scene};
use crate::upload::{upload_texture, CutoutSource, UploadedMesh};

/// Bytes between instance records in the draw buffer (the dynamic-offset alignment every device
/// accepts).
const DRAW_STRIDE: u64 = 256;
/// Lights the lighting pass takes; more are dropped with a warning.
pub const MAX_LIGHTS: usize = 8;
/// Side of the sun's shadow map, texels.
const SHADOW_MAP_SIZE: u32 = 2048;

/// The per-view uniform block of every pass (`View` in the shaders).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct ViewUniform {
    pub view_proj: [[f32; 4]; 4],
    pub inv_view_proj: [[f32; 4]; 4],
    pub unjittered_view_proj: [[f32; 4]; 4],
    pub prev_view_proj: [[f32; 4]; 4],
    pub eye: [f32; 4],
    pub size: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct DrawUniform {
    model: [[f32; 4]; 4],
    normal_matrix: [[f32; 4]; 4],
    base_color: [f32; 4],
    emissive: [f32; 4],
    /// Metallic, roughness, and the MASK test's factor and cutoff (1 and 0 for an opaque mesh:
    /// every texel passes).
    params: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LightRecord {
    kind: [f32; 4],
    position: [f32; 4],
    direction: [f32; 4],
    color: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LightsUniform {
    count: [u32; 4],
    shadow_view_proj: [[f32; 4]; 4],
    shadow_params: [f32; 4],
    sky: [f32; 4],
    items: [LightRecord; MAX_LIGHTS],
}

/// Linear radiance of the sky where nothing is drawn (and what the lighting cache never sees:
/// the SDK's rays that miss get black, there is no environment map).
pub const SKY: Vec3 = Vec3::new(0.35, 0.45, 0.6);

struct MeshBuffers {
    normals: wgpu::Buffer,
    uvs: wgpu::Buffer,
    material: wgpu::BindGroup,
}

/// Everything the rasteriser needs of a scene on the GPU, and its pipelines.
pub struct GpuScene {
    meshes: Vec<MeshBuffers>,
    /// Per instance: its mesh.
    draws: Vec<usize>,
    positions: Vec<(wgpu::Buffer, wgpu::Buffer, u32)>,
    draw_bind_group: wgpu::BindGroup,
    pub(crate) view_layout: wgpu::BindGroupLayout,
    pub(crate) lighting_layout: wgpu::BindGroupLayout,
    gbuffer_pipeline: wgpu::RenderPipeline,
    emission_pipeline: wgpu::RenderPipeline,
    /// Per instance: whether its material emits.
    emissive: Vec<bool>,
    /// Per instance: whether its mesh is a cutout (drawn into the shadow map with its texture).
    cutout: Vec<bool>,
    shadow_pipeline: wgpu::RenderPipeline,
    shadow_cutout_pipeline: wgpu::RenderPipeline,
    pub(crate) lighting_pipeline: wgpu::RenderPipeline,
    pub(crate) lights: wgpu::Buffer,
    pub(crate) shadow_view: wgpu::TextureView,
    pub(crate) shadow_sampler: wgpu::Sampler,
    shadow_bind_group: wgpu::BindGroup,
    /// Whether a sun has a shadow map (else the shadow pass is skipped).
    has_shadow: bool,
    /// The light whose shadow the SDK traces and the composite swaps in: the first sun, else the
    /// first light. The lighting pass writes its unshadowed radiance apart (`ViewTargets::sun`).
    pub shadow_light: Option<Light>,
    /// The scene's diameter, for clip planes and ray lengths.
    pub scene_size: f32,
}

/// G-buffer formats, in attachment order.
pub(crate) const GBUFFER_FORMATS: [wgpu::TextureFormat; 4] = [
    wgpu::TextureFormat::Rgba16Float,    // normal
    wgpu::TextureFormat::Rgba8UnormSrgb, // base colour, metalness in A
    wgpu::TextureFormat::Rgba8Unorm,     // specular colour F0, roughness in A
    wgpu::TextureFormat::Rg16Float,      // motion
];

pub(crate) fn uniform_entry(binding: u32, dynamic: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: dynamic,
            min_binding_size: None,
        },
        count: None,
    }
}

pub(crate) fn texture_entry(
    binding: u32,
    sample_type: wgpu::TextureSampleType,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::FRAGMENT,
        ty: wgpu::BindingType::Texture {
            sample_type,
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

pub(crate) const UNFILTERED: wgpu::TextureSampleType =
    wgpu::TextureSampleType::Float { filterable: false };

const fn attribute(location: u32, format: wgpu::VertexFormat) -> [wgpu::VertexAttribute; 1] {
    [wgpu::VertexAttribute {
        format,
        offset: 0,
        shader_location: location,
    }]
}
const POSITION_ATTR: [wgpu::VertexAttribute; 1] = attribute(0, wgpu::VertexFormat::Float32x3);
const NORMAL_ATTR: [wgpu::VertexAttribute; 1] = attribute(1, wgpu::VertexFormat::Float32x3);
const UV_ATTR: [wgpu::VertexAttribute; 1] = attribute(2, wgpu::VertexFormat::Float32x2);

fn mat(m: Mat4) -> [[f32; 4]; 4] {
    m.to_cols_array_2d()
}

/// The bind group layouts of the passes.
struct Layouts {
    view: wgpu::BindGroupLayout,
    draw: wgpu::BindGroupLayout,
    material: wgpu::BindGroupLayout,
    lighting: wgpu::BindGroupLayout,
}

impl Layouts {
    fn new(device: &wgpu::Device) -> Layouts {
        let view = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ksrt view"),
            entries: &[uniform_entry(0, false)],
        });
        let draw = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ksrt draw"),
            entries: &[uniform_entry(0, true)],
        });
        let filterable = wgpu::TextureSampleType::Float { filterable: true };
        let material = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ksrt material"),
            entries: &[
                texture_entry(0, filterable),
                texture_entry(1, filterable),
                texture_entry(2, filterable),
                wgpu::BindGroupLayoutEntry {
                    binding: 3,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
            ],
        });
        let mut lighting_entries = vec![uniform_entry(0, false), uniform_entry(1, false)];
        lighting_entries.push(texture_entry(2, wgpu::TextureSampleType::Depth));
        for b in [3, 5, 6] {
            lighting_entries.push(texture_entry(b, UNFILTERED));
        }
        lighting_entries.push(texture_entry(7, wgpu::TextureSampleType::Depth));
        lighting_entries.push(wgpu::BindGroupLayoutEntry {
            binding: 8,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Comparison),
            count: None,
        });
        let lighting = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ksrt lighting"),
            entries: &lighting_entries,
        });
        Layouts {
            view,
            draw,
            material,
            lighting,
        }
    }
}

/// The render pipelines of the passes.
struct Pipelines {
    gbuffer: wgpu::RenderPipeline,
    emission: wgpu::RenderPipeline,
    shadow: wgpu::RenderPipeline,
    shadow_cutout: wgpu::RenderPipeline,
    lighting: wgpu::RenderPipeline,
}

/// The vertex streams: position, normal, uv.
fn vertex_streams() -> [Option<wgpu::VertexBufferLayout<'static>>; 3] {
    let stream = |stride, attributes: &'static [wgpu::VertexAttribute]| {
        Some(wgpu::VertexBufferLayout {
            array_stride: stride,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes,
        })
    };
    [
        stream(12, &POSITION_ATTR),
        stream(12, &NORMAL_ATTR),
        stream(8, &UV_ATTR),
    ]
}

/// The shadow map's depth bias, against acne.
const SHADOW_BIAS: wgpu::DepthBiasState = wgpu::DepthBiasState {
    constant: 2,
    slope_scale: 2.0,
    clamp: 0.0,
};

/// A `Depth32Float` depth test (`Less`, writing) with `bias`.
fn depth_state(bias: wgpu::DepthBiasState) -> wgpu::DepthStencilState {
    wgpu::DepthStencilState {
        format: wgpu::TextureFormat::Depth32Float,
        depth_write_enabled: Some(true),
        depth_compare: Some(wgpu::CompareFunction::Less),
        stencil: Default::default(),
        bias,
    }
}

impl Pipelines {
    fn new(device: &wgpu::Device, layouts: &Layouts) -> Pipelines {
        let shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("ksrt gbuffer"),
            source: wgpu::ShaderSource::Wgsl(include_str!("../../shaders/gbuffer.wgsl").into()),
        });
        let (gbuffer, emission) = Self::gbuffer_and_emission(device, layouts, &shader);
        Pipelines {
            gbuffer,
            emission,
            shadow: Self::shadow(device, layouts, &shader),
            shadow_cutout: Self::shadow_cutout(device, layouts, &shader),
            lighting: Self::lighting(device, layouts),
        }
    }

    /// The G-buffer pipeline and the emission pipeline (drawing emissive instances again, at
    /// equal depth, into the direct light target).
    fn gbuffer_and_emission(
        device: &wgpu::Device,
        layouts: &Layouts,
        shader: &wgpu::ShaderModule,
    ) -> (wgpu::RenderPipeline, wgpu::RenderPipeline) {
        let streams = vertex_streams();
        let gbuffer_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("ksrt gbuffer"),
            bind_group_layouts: &[
                Some(&layouts.view),
                Some(&layouts.draw),
                Some(&layouts.material),
            ],
            immediate_size: 0,
        });
        let targets: Vec<Option<wgpu::ColorTargetState>> = GBUFFER_FORMATS
            .iter()
            .map(|&format| Some(format.into()))
            .collect();
        let gbuffer = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("ksrt gbuffer"),
            layout: Some(&gbuffer_layout),
            vertex: wgpu::VertexState {
                module: shader,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &streams,
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: Some(depth_state(Default::default())),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: shader,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &targets,
            }),
            multiview_mask: None,
            cache: None,
        });
        let emission = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("ksrt emission"),
            layout: Some(&gbuffer_layout),
            vertex: wgpu::VertexState {
                module: shader,
                entry_point: Some("vs_main"),
                compilation_options: Default::default(),
                buffers: &streams,
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: Some(wgpu::DepthStencilState {
                format: wgpu::TextureFormat::Depth32Float,
                depth_write_enabled: Some(false),
                depth_compare: Some(wgpu::CompareFunction::Equal),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: shader,
                entry_point: Some("fs_emission"),
                compilation_options: Default::default(),
                targets: &[Some(wgpu::TextureFormat::Rgba16Float.into())],
            }),
            multiview_mask: None,
            cache: None,
        });
        (gbuffer, emission)
    }

    /// The sun's shadow map pipeline: positions only, depth biased.
    fn shadow(
        device: &wgpu::Device,
        layouts: &Layouts,
        shader: &wgpu::ShaderModule,
    ) -> wgpu::RenderPipeline {
        let streams = vertex_streams();
        let shadow_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("ksrt shadow"),
            bind_group_layouts: &[Some(&layouts.view), Some(&layouts.draw)],
            immediate_size: 0,
        });
        device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("ksrt shadow map"),
            layout: Some(&shadow_layout),
            vertex: wgpu::VertexState {
                module: shader,
                entry_point: Some("vs_shadow"),
                compilation_options: Default::default(),
                buffers: &streams[..1],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: Some(depth_state(SHADOW_BIAS)),
            multisample: Default::default(),
            fragment: None,
            multiview_mask: None,
            cache: None,
        })
    }

    /// The shadow map pipeline of cutout meshes: the base colour texture's MASK test discards
    /// the fragments of transparent texels, so light passes through them as the SDK's shadow
    /// rays do. Apart from [`Self::shadow`] so that opaque meshes keep a depth-only pass.
    fn shadow_cutout(
        device: &wgpu::Device,
        layouts: &Layouts,
        shader: &wgpu::ShaderModule,
    ) -> wgpu::RenderPipeline {
        let streams = vertex_streams();
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("ksrt shadow cutout"),
            bind_group_layouts: &[
                Some(&layouts.view),
                Some(&layouts.draw),
                Some(&layouts.material),
            ],
            immediate_size: 0,
        });
        device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("ksrt shadow map cutout"),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module: shader,
                entry_point: Some("vs_shadow_cutout"),
                compilation_options: Default::default(),
                buffers: &streams,
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: Some(depth_state(SHADOW_BIAS)),
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: shader,
                entry_point: Some("fs_shadow_cutout"),
                compilation_options: Default::default(),
                targets: &[],
            }),
            multiview_mask: None,
            cache: None,
        })
    }

    /// The full-screen lighting pipeline: adds the lights to the emission in the direct target
    /// and writes the shadowed light's unshadowed radiance apart.
    fn lighting(device: &wgpu::Device, layouts: &Layouts) -> wgpu::RenderPipeline {
        let lighting_shader = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("ksrt lighting"),
            source: wgpu::ShaderSource::Wgsl(include_str!("../../shaders/lighting.wgsl").into()),
        });
        let lighting_pipeline_layout =
            device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("ksrt lighting"),
                bind_group_layouts: &[Some(&layouts.lighting)],
                immediate_size: 0,
            });
        device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some("ksrt lighting"),
            layout: Some(&lighting_pipeline_layout),
            vertex: wgpu::VertexState {
                module: &lighting_shader,
                entry_point: Some("vs_fullscreen"),
                compilation_options: Default::default(),
                buffers: &[],
            },
            primitive: wgpu::PrimitiveState::default(),
            depth_stencil: None,
            multisample: Default::default(),
            fragment: Some(wgpu::FragmentState {
                module: &lighting_shader,
                entry_point: Some("fs_main"),
                compilation_options: Default::default(),
                targets: &[
                    // Added to the emission already in the target.
                    Some(wgpu::ColorTargetState {
                        format: wgpu::TextureFormat::Rgba16Float,
                        blend: Some(wgpu::BlendState {
                            color: wgpu::BlendComponent {
                                src_factor: wgpu::BlendFactor::One,
                                dst_factor: wgpu::BlendFactor::One,
                                operation: wgpu::BlendOperation::Add,
                            },
                            alpha: wgpu::BlendComponent::REPLACE,
                        }),
                        write_mask: wgpu::ColorWrites::ALL,
                    }),
                    Some(wgpu::TextureFormat::Rgba16Float.into()),
                ],
            }),
            multiview_mask: None,
            cache: None,
        })
    }
}

/// The scene's textures on the GPU, a 1×1 white one for the slots without a texture, and the
/// two material samplers.
struct MaterialTextures {
    /// Per [`Scene::textures`] (`None`: an image without texels).
    textures: Vec<Option<wgpu::Texture>>,
    white: wgpu::Texture,
    linear: wgpu::Sampler,
    nearest: wgpu::Sampler,
}

impl MaterialTextures {
    /// Uploads the textures of `scene`, reusing those the cutouts of `uploads` already hold.
    fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
        uploads: &[UploadedMesh],
    ) -> MaterialTextures {
        let white = upload_texture(
            device,
            queue,
            &image::RgbaImage::from_pixel(1, 1, image::Rgba([255; 4])),
            "ksrt white",
        );
        let uploaded = |index: usize| {
            uploads
                .iter()
                .find_map(|u| match u.cutout.as_ref().map(|c| &c.source) {
                    Some(CutoutSource::Texture {
                        texture_index,
                        texture,
                        ..
                    }) if *texture_index == index => Some(texture.clone()),
                    _ => None,
                })
        };
        let textures = scene
            .textures
            .iter()
            .enumerate()
            .map(|(k, t)| {
                (t.image.width() > 0 && t.image.height() > 0).then(|| {
                    uploaded(k).unwrap_or_else(|| upload_texture(device, queue, &t.image, &t.name))
                })
            })
            .collect();
        let sampler_with = |filter| {
            device.create_sampler(&wgpu::SamplerDescriptor {
                label: Some("ksrt material"),
                address_mode_u: wgpu::AddressMode::Repeat,
                address_mode_v: wgpu::AddressMode::Repeat,
                mag_filter: filter,
                min_filter: wgpu::FilterMode::Linear,
                ..Default::default()
            })
        };
        MaterialTextures {
            textures,
            white,
            linear: sampler_with(wgpu::FilterMode::Linear),
            nearest: sampler_with(wgpu::FilterMode::Nearest),
        }
    }

    /// A view of texture `index` (white when there is none), as sRGB or linear.
    fn view_of(&self, index: Option<usize>, srgb: bool) -> wgpu::TextureView {
        let tex = index
            .and_then(|i| self.textures.get(i))
            .and_then(Option::as_ref)
            .unwrap_or(&self.white);
        tex.create_view(&wgpu::TextureViewDescriptor {
            format: Some(if srgb {
                wgpu::TextureFormat::Rgba8UnormSrgb
            } else {
                wgpu::TextureFormat::Rgba8Unorm
            }),
            ..Default::default()
        })
    }
}

/// Per mesh: its normal and uv streams and its material bind group. A cutout's coordinates are
/// the buffer the SDK bakes from (`uploads`), so both test the same values.
fn mesh_buffers(
    device: &wgpu::Device,
    scene: &Scene,
    uploads: &[UploadedMesh],
    textures: &MaterialTextures,
    material_layout: &wgpu::BindGroupLayout,
) -> Vec<MeshBuffers> {
    scene
        .meshes
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let uvs = match uploads
                .get(k)
                .and_then(|u| u.cutout.as_ref())
                .map(|c| &c.source)
            {
                Some(CutoutSource::Texture { uvs, .. }) => uvs.clone(),
                _ => crate::upload::uv_buffer(device, m),
            };
            // `COPY_DST`: a posed mesh's normals are written every frame (`write_normals`).
            let buffer = |bytes: &[u8]| {
                device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some(m.name.as_str()),
                    contents: bytes,
                    usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_DST,
                })
            };
            let material = &m.material;
            // One sampler per material: the base colour texture's filter.
            let sampler = match material
                .base_color_texture
                .and_then(|i| scene.textures.get(i))
            {
                Some(t) if t.nearest => &textures.nearest,
                _ => &textures.linear,
            };
            let views = [
                textures.view_of(material.base_color_texture, true),
                textures.view_of(material.metallic_roughness_texture, false),
                textures.view_of(material.emissive_texture, true),
            ];
            let view_entry = |binding: u32| wgpu::BindGroupEntry {
                binding,
                resource: wgpu::BindingResource::TextureView(&views[binding as usize]),
            };
            MeshBuffers {
                normals: buffer(bytemuck::cast_slice(&m.normals)),
                uvs,
                material: device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("ksrt material"),
                    layout: material_layout,
                    entries: &[
                        view_entry(0),
                        view_entry(1),
                        view_entry(2),
                        wgpu::BindGroupEntry {
                            binding: 3,
                            resource: wgpu::BindingResource::Sampler(sampler),
                        },
                    ],
                }),
            }
        })
        .collect()
}

/// The draw bind group: one [`DrawUniform`] per instance, at [`DRAW_STRIDE`].
fn draw_bind_group(
    device: &wgpu::Device,
    scene: &Scene,
    draw_layout: &wgpu::BindGroupLayout,
) -> wgpu::BindGroup {
    let mut draw_bytes = vec![0u8; (scene.instances.len().max(1) as u64 * DRAW_STRIDE) as usize];
    for (k, inst) in scene.instances.iter().enumerate() {
        let mesh = &scene.meshes[inst.mesh];
        let model = Mat4::from(inst.transform);
        let normal_matrix = Mat4::from_mat3(
            glam::Mat3::from(inst.transform.matrix3)
                .inverse()
                .transpose(),
        );
        let record = DrawUniform {
            model: mat(model),
            normal_matrix: mat(normal_matrix),
            base_color: mesh.color.extend(1.0).to_array(),
            emissive: mesh.material.emissive.extend(0.0).to_array(),
            params: {
                let (factor, cutoff) = mesh.mask().map_or((1.0, 0.0), |t| (t.factor, t.cutoff));
                [
                    mesh.material.metallic,
                    mesh.material.roughness,
                    factor,
                    cutoff,
                ]
            },
        };
        let at = k * DRAW_STRIDE as usize;
        draw_bytes[at..at + std::mem::size_of::<DrawUniform>()]
            .copy_from_slice(bytemuck::bytes_of(&record));
    }
    let draw_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("ksrt draws"),
        contents: &draw_bytes,
        usage: wgpu::BufferUsages::UNIFORM,
    });
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("ksrt draws"),
        layout: draw_layout,
        entries: &[wgpu::BindGroupEntry {
            binding: 0,
            resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: &draw_buffer,
                offset: 0,
                size: wgpu::BufferSize::new(std::mem::size_of::<DrawUniform>() as u64),
            }),
        }],
    })
}

/// The lights of a scene as the lighting pass reads them, and the shadowed one.
struct SceneLights {
    /// The uniform block.
    uniform: LightsUniform,
    /// The first sun's shadow map projection: an orthographic view of the scene's bounding
    /// sphere along the sun (`None`: no sun, no shadow map).
    shadow_view_proj: Option<Mat4>,
    /// The light whose shadow the SDK traces.
    shadow_light: Option<Light>,
}

/// The record of one light (a sun's carries no position).
fn light_record(light: &Light) -> LightRecord {
    match *light {
        Light::Sun {
            direction,
            irradiance,
            ..
        } => LightRecord {
            kind: [0.0, 0.0, 0.0, 0.0],
            position: [0.0; 4],
            direction: direction.extend(0.0).to_array(),
            color: irradiance.extend(0.0).to_array(),
        },
        Light::Point {
            position,
            intensity,
            range,
        } => LightRecord {
            kind: [1.0, range.max(1e-6), 0.0, 0.0],
            position: position.extend(1.0).to_array(),
            direction: [0.0, -1.0, 0.0, 0.0],
            color: intensity.extend(0.0).to_array(),
        },
        Light::Spot {
            position,
            direction,
            intensity,
            range,
            inner_angle,
            outer_angle,
        } => LightRecord {
            kind: [
                2.0,
                range.max(1e-6),
                inner_angle.cos(),
                outer_angle.cos().min(inner_angle.cos() - 1e-4),
            ],
            position: position.extend(1.0).to_array(),
            direction: direction.extend(0.0).to_array(),
            color: intensity.extend(0.0).to_array(),
        },
    }
}

impl SceneLights {
    /// The lights of `scene` (the first [`MAX_LIGHTS`]; a warning when there are more), and the
    /// shadow map of the first sun.
    fn new(scene: &Scene) -> SceneLights {
        let scene_lights = scene.lights_or_default();
        if scene_lights.len() > MAX_LIGHTS {
            log::warn!(
                "{}: {} lights, the rasteriser uses the first {MAX_LIGHTS}",
                scene.name,
                scene_lights.len()
            );
        }
        let (lo, hi) = scene.bounds();
        let centre = (lo + hi) * 0.5;
        let radius = ((hi - lo).length() * 0.5).max(1e-3);
        let mut lights = LightsUniform {
            count: [scene_lights.len().min(MAX_LIGHTS) as u32, u32::MAX, 0, 0],
            shadow_view_proj: mat(Mat4::IDENTITY),
            // Compare bias: two texels' worth of depth (the map's depth range is 3 radii); the
            // normal offset: three texels. Enough against acne on the built-in scenes without
            // visible peter-panning.
            shadow_params: [
                1.0 / SHADOW_MAP_SIZE as f32,
                2.0 * (2.0 * radius / SHADOW_MAP_SIZE as f32) / (3.0 * radius),
                3.0 * 2.0 * radius / SHADOW_MAP_SIZE as f32,
                0.0,
            ],
            sky: SKY.extend(1.0).to_array(),
            items: [LightRecord {
                kind: [0.0; 4],
                position: [0.0; 4],
                direction: [0.0; 4],
                color: [0.0; 4],
            }; MAX_LIGHTS],
        };
        let mut shadow_view_proj = None;
        let shadowed = scene_lights
            .iter()
            .take(MAX_LIGHTS)
            .position(|l| matches!(l, Light::Sun { .. }))
            .or((!scene_lights.is_empty()).then_some(0));
        lights.count[1] = shadowed.map_or(u32::MAX, |k| k as u32);
        for (k, light) in scene_lights.iter().take(MAX_LIGHTS).enumerate() {
            if let (Light::Sun { direction, .. }, true) = (light, shadowed == Some(k)) {
                let up = if direction.y.abs() > 0.99 {
                    Vec3::X
                } else {
                    Vec3::Y
                };
                let view = Mat4::look_to_rh(centre - *direction * radius * 2.0, *direction, up);
                let proj = Mat4::orthographic_rh(
                    -radius,
                    radius,
                    -radius,
                    radius,
                    radius * 0.5,
                    radius * 3.5,
                );
                shadow_view_proj = Some(proj * view);
                lights.count[2] = 1;
            }
            lights.items[k] = light_record(light);
        }
        if let Some(m) = shadow_view_proj {
            lights.shadow_view_proj = mat(m);
        }
        SceneLights {
            uniform: lights,
            shadow_view_proj,
            shadow_light: shadowed.and_then(|k| scene_lights.get(k).copied()),
        }
    }
}

/// The sun's shadow map: its view's bind group, the depth texture's view and the comparison
/// sampler the lighting pass reads it with.
struct ShadowMap {
    bind_group: wgpu::BindGroup,
    view: wgpu::TextureView,
    sampler: wgpu::Sampler,
}

impl ShadowMap {
    fn new(
        device: &wgpu::Device,
        view_layout: &wgpu::BindGroupLayout,
        view_proj: Option<Mat4>,
    ) -> ShadowMap {
        let shadow_view_uniform = ViewUniform {
            view_proj: mat(view_proj.unwrap_or(Mat4::IDENTITY)),
            inv_view_proj: mat(Mat4::IDENTITY),
            unjittered_view_proj: mat(Mat4::IDENTITY),
            prev_view_proj: mat(Mat4::IDENTITY),
            eye: [0.0; 4],
            size: [SHADOW_MAP_SIZE as f32; 4],
        };
        let shadow_view_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("ksrt shadow view"),
            contents: bytemuck::bytes_of(&shadow_view_uniform),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ksrt shadow view"),
            layout: view_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: shadow_view_buffer.as_entire_binding(),
            }],
        });
        let shadow_map = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("ksrt shadow map"),
            size: wgpu::Extent3d {
                width: SHADOW_MAP_SIZE,
                height: SHADOW_MAP_SIZE,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Depth32Float,
            usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            view_formats: &[],
        });
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("ksrt shadow"),
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            compare: Some(wgpu::CompareFunction::LessEqual),
            ..Default::default()
        });
        ShadowMap {
            bind_group,
            view: shadow_map.create_view(&Default::default()),
            sampler,
        }
    }
}

impl GpuScene {
    /// Uploads `scene` (whose positions and indices are `uploads`) and builds the pipelines.
    pub fn new(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
        uploads: &[UploadedMesh],
    ) -> GpuScene {
        let layouts = Layouts::new(device);
        let pipelines = Pipelines::new(device, &layouts);
        let textures = MaterialTextures::new(device, queue, scene, uploads);
        let meshes = mesh_buffers(device, scene, uploads, &textures, &layouts.material);
        let draw_bind_group = draw_bind_group(device, scene, &layouts.draw);
        let lights = SceneLights::new(scene);
        let lights_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("ksrt lights"),
            contents: bytemuck::bytes_of(&lights.uniform),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let shadow = ShadowMap::new(device, &layouts.view, lights.shadow_view_proj);
        GpuScene {
            meshes,
            draws: scene.instances.iter().map(|i| i.mesh).collect(),
            positions: uploads
                .iter()
                .map(|u| (u.vertices.clone(), u.indices.clone(), u.index_count))
                .collect(),
            draw_bind_group,
            view_layout: layouts.view,
            lighting_layout: layouts.lighting,
            gbuffer_pipeline: pipelines.gbuffer,
            emission_pipeline: pipelines.emission,
            emissive: scene
                .instances
                .iter()
                .map(|i| scene.meshes[i.mesh].material.emissive.max_element() > 0.0)
                .collect(),
            cutout: scene
                .instances
                .iter()
                .map(|i| scene.meshes[i.mesh].mask().is_some())
                .collect(),
            shadow_pipeline: pipelines.shadow,
            shadow_cutout_pipeline: pipelines.shadow_cutout,
            lighting_pipeline: pipelines.lighting,
            lights: lights_buffer,
            shadow_view: shadow.view,
            shadow_sampler: shadow.sampler,
            shadow_bind_group: shadow.bind_group,
            has_shadow: lights.shadow_view_proj.is_some(),
            shadow_light: lights.shadow_light,
            scene_size: scene.size(),
        }
    }

    /// Writes the normals of mesh `mesh` (one a vertex, as many as it was uploaded with) for
    /// the next submission: a posed mesh's, whose positions the caller wrote into the same
    /// mesh's vertex buffer. Ignored for a mesh out of range or a count that differs.
    pub fn write_normals(&self, queue: &wgpu::Queue, mesh: usize, normals: &[[f32; 3]]) {
        if let Some(m) = self.meshes.get(mesh) {
            let bytes: &[u8] = bytemuck::cast_slice(normals);
            if bytes.len() as u64 == m.normals.size() {
                queue.write_buffer(&m.normals, 0, bytes);
            }
        }
    }

    fn draw_all(&self, pass: &mut wgpu::RenderPass<'_>, with_material: bool) {
        self.draw(pass, with_material, |_| true)
    }

    fn draw(
        &self,
        pass: &mut wgpu::RenderPass<'_>,
        with_material: bool,
        which: impl Fn(usize) -> bool,
    ) {
        for (k, &mesh) in self.draws.iter().enumerate().filter(|(k, _)| which(*k)) {
            let (Some((positions, indices, count)), Some(m)) =
                (self.positions.get(mesh), self.meshes.get(mesh))
            else {
                continue;
            };
            pass.set_bind_group(1, &self.draw_bind_group, &[(k as u64 * DRAW_STRIDE) as u32]);
            pass.set_vertex_buffer(0, positions.slice(..));
            if with_material {
                pass.set_bind_group(2, &m.material, &[]);
                pass.set_vertex_buffer(1, m.normals.slice(..));
                pass.set_vertex_buffer(2, m.uvs.slice(..));
            }
            pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..*count, 0, 0..1);
        }
    }

    /// Records the sun's shadow map (once for a still scene; every frame the pose changes).
    pub fn record_shadow_map(&self, encoder: &mut wgpu::CommandEncoder) {
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("ksrt shadow map"),
            color_attachments: &[],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &self.shadow_view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        if !self.has_shadow {
            return;
        }
        pass.set_pipeline(&self.shadow_pipeline);
        pass.set_bind_group(0, &self.shadow_bind_group, &[]);
        self.draw(&mut pass, false, |k| !self.cutout[k]);
        if self.cutout.iter().any(|&c| c) {
            pass.set_pipeline(&self.shadow_cutout_pipeline);
            self.draw(&mut pass, true, |k| self.cutout[k]);
        }
    }

    /// Records the G-buffer and lighting passes of one view into `targets` (whose view uniform
    /// `ViewTargets::set_view` wrote).
    pub fn record_view(&self, encoder: &mut wgpu::CommandEncoder, targets: &ViewTargetsRef<'_>) {
        {
            let color: Vec<Option<wgpu::RenderPassColorAttachment>> = targets
                .gbuffer
                .iter()
                .map(|view| {
                    Some(wgpu::RenderPassColorAttachment {
                        view,
                        depth_slice: None,
                        resolve_target: None,
                        ops: wgpu::Operations {
                            load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                            store: wgpu::StoreOp::Store,
                        },
                    })
                })
                .collect();
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("ksrt gbuffer"),
                color_attachments: &color,
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: targets.depth,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.gbuffer_pipeline);
            pass.set_bind_group(0, targets.view_bind_group, &[]);
            self.draw_all(&mut pass, true);
        }
        let attach = |view, load| {
            Some(wgpu::RenderPassColorAttachment {
                view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load,
                    store: wgpu::StoreOp::Store,
                },
            })
        };
        let clear = wgpu::LoadOp::Clear(wgpu::Color::BLACK);
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("ksrt emission"),
                color_attachments: &[attach(targets.direct, clear)],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: targets.depth,
                    depth_ops: None,
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            if self.emissive.iter().any(|&e| e) {
                pass.set_pipeline(&self.emission_pipeline);
                pass.set_bind_group(0, targets.view_bind_group, &[]);
                self.draw(&mut pass, true, |k| self.emissive[k]);
            }
        }
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("ksrt lighting"),
            color_attachments: &[
                attach(targets.direct, wgpu::LoadOp::Load),
                attach(targets.sun, clear),
            ],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.lighting_pipeline);
        pass.set_bind_group(0, targets.lighting_bind_group, &[]);
        pass.draw(0..3, 0..1);
    }
}

/// The views of a [`ViewTargets`] that [`GpuScene::record_view`] draws into.
pub struct ViewTargetsRef<'a> {
    pub(crate) gbuffer: [&'a wgpu::TextureView; 4],
    pub(crate) depth: &'a wgpu::TextureView,
    pub(crate) direct: &'a wgpu::TextureView,
    pub(crate) sun: &'a wgpu::TextureView,
    pub(crate) view_bind_group: &'a wgpu::BindGroup,
    pub(crate) lighting_bind_group: &'a wgpu::BindGroup,
}

/// The view uniform of a camera view.
pub(crate) fn view_uniform(view: &super::FrameView, size: (u32, u32)) -> ViewUniform {
    let jittered = view.jittered_view_proj(size);
    ViewUniform {
        view_proj: mat(jittered),
        inv_view_proj: mat(jittered.inverse()),
        unjittered_view_proj: mat(view.view_to_clip * view.world_to_view),
        prev_view_proj: mat(view.prev_view_to_clip * view.prev_world_to_view),
        eye: view.eye.extend(1.0).to_array(),
        size: [
            size.0 as f32,
            size.1 as f32,
            1.0 / size.0 as f32,
            1.0 / size.1 as f32,
        ],
    }
}
