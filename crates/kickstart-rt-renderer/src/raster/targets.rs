//! The textures one view renders into: its G-buffer, its direct lighting and its view uniform.

use super::gpu_scene::{view_uniform, ViewTargetsRef, GBUFFER_FORMATS};
use super::{FrameView, GpuScene};

/// One view's render targets (the main camera's, or the lidar camera's).
pub struct ViewTargets {
    /// Width and height, pixels.
    pub size: (u32, u32),
    /// Depth, `Depth32Float` (1 = far).
    pub depth: wgpu::Texture,
    /// World normals (`Rgba16Float`, RGB unencoded).
    pub normal: wgpu::Texture,
    /// Base colour, metalness in A (`Rgba8UnormSrgb`).
    pub base_color: wgpu::Texture,
    /// Specular colour F0, roughness in A (`Rgba8Unorm`).
    pub specular: wgpu::Texture,
    /// Motion, previous_uv − uv (`Rg16Float`).
    pub motion: wgpu::Texture,
    /// Direct lighting (`Rgba16Float`): what the SDK injects and the composite starts from.
    pub direct: wgpu::Texture,
    /// The shadow-mapped sun's unshadowed radiance (RGB) and shadow-map visibility (A).
    pub sun: wgpu::Texture,
    views: Vec<wgpu::TextureView>,
    view_buffer: wgpu::Buffer,
    view_bind_group: wgpu::BindGroup,
    lighting_bind_group: wgpu::BindGroup,
}

fn target(
    device: &wgpu::Device,
    label: &str,
    size: (u32, u32),
    format: wgpu::TextureFormat,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: size.0,
            height: size.1,
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
}

impl ViewTargets {
    /// Targets of `size` (each side ≥ 1) for views of `scene`.
    pub fn new(device: &wgpu::Device, scene: &GpuScene, size: (u32, u32)) -> ViewTargets {
        let size = (size.0.max(1), size.1.max(1));
        let names = ["normal", "base colour", "specular", "motion"];
        let mut g: Vec<wgpu::Texture> = GBUFFER_FORMATS
            .iter()
            .zip(names)
            .map(|(&f, n)| target(device, &format!("ksrt gbuffer {n}"), size, f))
            .collect();
        let depth = target(
            device,
            "ksrt depth",
            size,
            wgpu::TextureFormat::Depth32Float,
        );
        let direct = target(
            device,
            "ksrt direct lighting",
            size,
            wgpu::TextureFormat::Rgba16Float,
        );
        let sun = target(device, "ksrt sun", size, wgpu::TextureFormat::Rgba16Float);
        let motion = g.remove(3);
        let specular = g.remove(2);
        let base_color = g.remove(1);
        let normal = g.remove(0);
        let views: Vec<wgpu::TextureView> = [
            &normal,
            &base_color,
            &specular,
            &motion,
            &depth,
            &direct,
            &sun,
        ]
        .iter()
        .map(|t| t.create_view(&Default::default()))
        .collect();
        let view_buffer = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ksrt view"),
            size: std::mem::size_of::<super::gpu_scene::ViewUniform>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let view_bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ksrt view"),
            layout: &scene.view_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: view_buffer.as_entire_binding(),
            }],
        });
        let tex = |binding, view| wgpu::BindGroupEntry {
            binding,
            resource: wgpu::BindingResource::TextureView(view),
        };
        let lighting_bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ksrt lighting"),
            layout: &scene.lighting_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: view_buffer.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: scene.lights.as_entire_binding(),
                },
                tex(2, &views[4]),
                tex(3, &views[0]),
                tex(5, &views[1]),
                tex(6, &views[2]),
                tex(7, &scene.shadow_view),
                wgpu::BindGroupEntry {
                    binding: 8,
                    resource: wgpu::BindingResource::Sampler(&scene.shadow_sampler),
                },
            ],
        });
        ViewTargets {
            size,
            depth,
            normal,
            base_color,
            specular,
            motion,
            direct,
            sun,
            views,
            view_buffer,
            view_bind_group,
            lighting_bind_group,
        }
    }

    /// Writes this frame's view uniform (a queue write: it lands before the next submission, so
    /// call it once per view and frame, before submitting the frame that draws with it).
    pub fn set_view(&self, queue: &wgpu::Queue, view: &FrameView) {
        queue.write_buffer(
            &self.view_buffer,
            0,
            bytemuck::bytes_of(&view_uniform(view, self.size)),
        );
    }

    /// The view uniform buffer (the composite reads it too).
    pub fn view_buffer(&self) -> &wgpu::Buffer {
        &self.view_buffer
    }

    /// The views [`GpuScene::record_view`] draws into.
    pub fn as_ref(&self) -> ViewTargetsRef<'_> {
        let v = &self.views;
        ViewTargetsRef {
            gbuffer: [&v[0], &v[1], &v[2], &v[3]],
            depth: &v[4],
            direct: &v[5],
            sun: &v[6],
            view_bind_group: &self.view_bind_group,
            lighting_bind_group: &self.lighting_bind_group,
        }
    }

    /// A view of a target texture.
    pub fn view(texture: &wgpu::Texture) -> wgpu::TextureView {
        texture.create_view(&Default::default())
    }
}
