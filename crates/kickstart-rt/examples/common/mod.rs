//! What the examples share: a wgpu device set up for the SDK, a built-in scene (boxes on a
//! plane) registered with the SDK, a camera, and reading textures and buffers back.
//! The G-buffer rasteriser is in `gbuffer.rs`, the window example's composite in `composite.rs`.
//!
//! Each example includes this folder with `mod common;` (cargo builds only `examples/*.rs` as
//! examples, so this folder is not one).

#![allow(dead_code)] // each example uses a different part of this module

pub mod composite;
pub mod gbuffer;

use glam::{Affine3A, Mat4, Vec3};
use kickstart_rt as ksrt;
use wgpu::util::DeviceExt;

/// The examples' error type: any error, with its message printed by `main`.
pub type AnyResult<T> = Result<T, Box<dyn std::error::Error>>;

/// The message printed when wgpu finds no adapter: the usual cause on a machine without a GPU.
pub const NO_ADAPTER: &str = "no GPU adapter found. Install a GPU driver, or Mesa's software \
Vulkan (`apt-get install mesa-vulkan-drivers`) and run with WGPU_BACKEND=vulkan";

/// A wgpu instance for the primary backends (Vulkan, Metal, DX12), or what `WGPU_BACKEND` says.
/// `display` is the window system's display handle when the example opens a window.
pub fn instance(display: Option<Box<dyn wgpu::wgt::WgpuHasDisplayHandle>>) -> wgpu::Instance {
    let mut desc = match display {
        Some(d) => wgpu::InstanceDescriptor::new_with_display_handle_from_env(d),
        None => wgpu::InstanceDescriptor::new_without_display_handle_from_env(),
    };
    // Probing the GL backend on a headless machine only prints EGL errors.
    if std::env::var_os("WGPU_BACKEND").is_none() {
        desc.backends = wgpu::Backends::PRIMARY;
    }
    wgpu::Instance::new(desc)
}

/// An adapter (one that can present to `surface`, when given) and a device with what the SDK
/// needs: its required features and limits, plus every optional feature the adapter has.
pub fn device(
    instance: &wgpu::Instance,
    surface: Option<&wgpu::Surface<'_>>,
) -> AnyResult<(wgpu::Adapter, wgpu::Device, wgpu::Queue)> {
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        compatible_surface: surface,
        ..Default::default()
    }))
    .map_err(|e| format!("{NO_ADAPTER} ({e})"))?;
    println!("adapter: {}", adapter.get_info().name);
    let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("kickstart-rt example"),
        required_features: ksrt::required_features() | ksrt::optional_features_supported(&adapter),
        // The SDK's limits, raised to what the adapter allows for texture sizes.
        required_limits: ksrt::required_limits().using_resolution(adapter.limits()),
        ..Default::default()
    }))?;
    Ok((adapter, device, queue))
}

/// The two meshes of the built-in scenes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shape {
    /// A unit cube centred on the origin.
    Cube,
    /// A 20 × 20 square at y = 0, facing +y.
    Plane,
}

/// One placed object: its shape, transform (rotation, translation and uniform scale: the
/// rasteriser transforms normals with it) and colour.
pub struct Placement {
    /// Which mesh.
    pub shape: Shape,
    /// Object to world.
    pub transform: Affine3A,
    /// Linear albedo.
    pub albedo: Vec3,
}

/// A mesh in GPU buffers: interleaved position and normal (24 bytes a vertex), `u32` indices.
pub struct Mesh {
    /// Vertices: position (3 × f32) then normal (3 × f32).
    pub vertices: wgpu::Buffer,
    /// Triangle list indices.
    pub indices: wgpu::Buffer,
    /// Number of indices.
    pub index_count: u32,
}

/// A scene registered with the SDK: its meshes (for the rasteriser), its objects, and the SDK
/// handle of each object's instance.
pub struct Scene {
    /// `meshes[Shape as usize]`.
    pub meshes: Vec<Mesh>,
    /// The objects, in the order given.
    pub objects: Vec<Placement>,
    /// The SDK instance of each object (`GpuHit::instance` is its `index()`).
    pub instances: Vec<ksrt::InstanceHandle>,
}

/// The cube and plane as (position, normal) vertices and indices.
fn mesh_data(shape: Shape) -> (Vec<[f32; 6]>, Vec<u32>) {
    // Each face: its normal and two axes spanning it (so that a × b = n, counter-clockwise).
    let faces: &[([f32; 3], [f32; 3], [f32; 3])] = match shape {
        Shape::Cube => &[
            ([1., 0., 0.], [0., 0., -1.], [0., 1., 0.]),
            ([-1., 0., 0.], [0., 0., 1.], [0., 1., 0.]),
            ([0., 1., 0.], [1., 0., 0.], [0., 0., -1.]),
            ([0., -1., 0.], [1., 0., 0.], [0., 0., 1.]),
            ([0., 0., 1.], [1., 0., 0.], [0., 1., 0.]),
            ([0., 0., -1.], [-1., 0., 0.], [0., 1., 0.]),
        ],
        Shape::Plane => &[([0., 1., 0.], [1., 0., 0.], [0., 0., -1.])],
    };
    let (half, offset) = match shape {
        Shape::Cube => (0.5, 0.5),
        Shape::Plane => (10.0, 0.0),
    };
    let mut vertices = Vec::new();
    let mut indices = Vec::new();
    for (n, a, b) in faces {
        let (n, a, b) = (Vec3::from(*n), Vec3::from(*a), Vec3::from(*b));
        let base = vertices.len() as u32;
        for (sa, sb) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            let p = n * offset + (a * sa + b * sb) * half;
            vertices.push([p.x, p.y, p.z, n.x, n.y, n.z]);
        }
        indices.extend([0, 1, 2, 0, 2, 3].map(|i| base + i));
    }
    (vertices, indices)
}

/// Uploads the meshes, registers them and `objects` with the SDK, and builds the BVHs (submitted
/// now; the GPU runs it before any later submission).
pub fn register_scene(
    device: &wgpu::Device,
    ctx: &ksrt::ExecuteContext,
    objects: Vec<Placement>,
) -> AnyResult<Scene> {
    let mut container = ctx.create_task_container();
    let mut meshes = Vec::new();
    let mut geometries = Vec::new();
    for shape in [Shape::Cube, Shape::Plane] {
        let (vertices, indices) = mesh_data(shape);
        // VERTEX/INDEX for the rasteriser; COPY_SRC because the SDK copies what it reads.
        let buffer = |label, contents: &[u8], usage| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage: usage | wgpu::BufferUsages::COPY_SRC,
            })
        };
        let mesh = Mesh {
            vertices: buffer(
                "vertices",
                bytemuck::cast_slice(&vertices),
                wgpu::BufferUsages::VERTEX,
            ),
            indices: buffer(
                "indices",
                bytemuck::cast_slice(&indices),
                wgpu::BufferUsages::INDEX,
            ),
            index_count: indices.len() as u32,
        };
        let geometry = ctx.create_geometry_handle();
        container.schedule_bvh_task(ksrt::GeometryTask {
            operation: ksrt::TaskOperation::Register,
            handle: geometry,
            input: ksrt::GeometryInput {
                name: format!("{shape:?}"),
                components: vec![ksrt::GeometryComponent {
                    // The SDK reads the positions out of the interleaved vertices: stride 24.
                    vertex_buffer: ksrt::VertexBufferInput {
                        buffer: mesh.vertices.clone(),
                        offset: 0,
                        stride: 24,
                        count: vertices.len() as u32,
                        format: ksrt::VertexFormat::Float32x3,
                    },
                    index_buffer: Some(ksrt::IndexBufferInput {
                        buffer: mesh.indices.clone(),
                        offset: 0,
                        count: mesh.index_count,
                        format: ksrt::IndexFormat::Uint32,
                    }),
                    transform: None,
                    index_range: None,
                    opacity: None,
                }],
                ..Default::default()
            },
        });
        meshes.push(mesh);
        geometries.push(geometry);
    }
    let mut instances = Vec::new();
    for o in &objects {
        let handle = ctx.create_instance_handle();
        let mut input = ksrt::InstanceInput::new(geometries[o.shape as usize], o.transform);
        input.name = format!("{:?} {}", o.shape, instances.len());
        container.schedule_bvh_task(ksrt::InstanceTask {
            operation: ksrt::TaskOperation::Register,
            handle,
            input,
        });
        instances.push(handle);
    }
    // Build both BLASes in this task (the default builds at most 4 per task), then the TLAS.
    container.schedule_bvh_task(ksrt::BvhBuildTask {
        max_blas_build_count: 2,
        ..Default::default()
    });
    ctx.invoke_gpu_task(container)?;
    Ok(Scene {
        meshes,
        objects,
        instances,
    })
}

/// The examples' scene: a grey plane, a white cube resting on it at the origin (turned 30°), and
/// `extra` more placements.
pub fn box_on_plane(extra: impl IntoIterator<Item = Placement>) -> Vec<Placement> {
    let mut objects = vec![
        Placement {
            shape: Shape::Plane,
            transform: Affine3A::IDENTITY,
            albedo: Vec3::splat(0.6),
        },
        Placement {
            shape: Shape::Cube,
            transform: Affine3A::from_rotation_translation(
                glam::Quat::from_rotation_y(30f32.to_radians()),
                Vec3::new(0.0, 0.5, 0.0),
            ),
            albedo: Vec3::new(0.9, 0.9, 0.9),
        },
    ];
    objects.extend(extra);
    objects
}

/// A perspective camera (right-handed, depth 0 near to 1 far).
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    /// Eye position.
    pub eye: Vec3,
    /// The point looked at.
    pub target: Vec3,
    /// Vertical field of view, radians.
    pub fov_y: f32,
    /// Width / height.
    pub aspect: f32,
}

impl Camera {
    /// World to view.
    pub fn view(&self) -> Mat4 {
        Mat4::look_at_rh(self.eye, self.target, Vec3::Y)
    }

    /// View to clip.
    pub fn projection(&self) -> Mat4 {
        Mat4::perspective_rh(self.fov_y, self.aspect, 0.05, 100.0)
    }

    /// The SDK's view of this camera; `prev` is last frame's (the denoisers reproject with it).
    pub fn view_info(&self, prev: &Camera) -> ksrt::ViewInfo {
        ksrt::ViewInfo {
            world_to_view: self.view(),
            view_to_clip: self.projection(),
            prev_world_to_view: prev.view(),
            prev_view_to_clip: prev.projection(),
            jitter: glam::Vec2::ZERO,
        }
    }

    /// The pixel of a `width × height` image that shows world point `p`.
    pub fn pixel_of(&self, p: Vec3, width: u32, height: u32) -> (u32, u32) {
        let ndc = (self.projection() * self.view()).project_point3(p);
        let x = (ndc.x * 0.5 + 0.5) * width as f32;
        let y = (0.5 - ndc.y * 0.5) * height as f32;
        (x as u32, y as u32)
    }
}

/// A 2D texture the SDK can write into (and the example can copy out of).
pub fn output_texture(
    device: &wgpu::Device,
    label: &str,
    (width, height): (u32, u32),
) -> wgpu::Texture {
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
        format: wgpu::TextureFormat::Rgba16Float,
        // STORAGE_BINDING: the SDK writes it; TEXTURE_BINDING: a composite reads it.
        usage: wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC,
        view_formats: &[],
    })
}

/// Copies `size` bytes of `buffer` (which needs `COPY_SRC`) to the CPU, waiting for the GPU.
pub fn read_buffer(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
    size: u64,
) -> AnyResult<Vec<u8>> {
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("read back"),
        size,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, size);
    queue.submit([encoder.finish()]);
    staging.map_async(wgpu::MapMode::Read, .., |_| {});
    device.poll(wgpu::PollType::wait_indefinitely())?;
    let bytes = staging.get_mapped_range(..)?.to_vec();
    Ok(bytes)
}

/// Reads an `Rgba16Float` texture back as f32 RGBA texels, row by row from the top.
pub fn read_rgba16f(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    texture: &wgpu::Texture,
) -> AnyResult<Vec<[f32; 4]>> {
    let (width, height) = (texture.width(), texture.height());
    // Rows of a texture-to-buffer copy are padded to 256 bytes.
    let row = (width * 8).div_ceil(256) * 256;
    let buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("texture read back"),
        size: row as u64 * height as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        texture.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: None,
            },
        },
        texture.size(),
    );
    queue.submit([encoder.finish()]);
    let bytes = read_buffer(device, queue, &buffer, buffer.size())?;
    let mut texels = Vec::with_capacity((width * height) as usize);
    for y in 0..height as usize {
        let halves: &[u8] = &bytes[y * row as usize..][..width as usize * 8];
        for t in halves.chunks_exact(8) {
            let h = |k: usize| f16_to_f32(u16::from_le_bytes([t[2 * k], t[2 * k + 1]]));
            texels.push([h(0), h(1), h(2), h(3)]);
        }
    }
    Ok(texels)
}

/// An IEEE half-precision float to f32.
fn f16_to_f32(h: u16) -> f32 {
    let sign = if h & 0x8000 != 0 { -1.0 } else { 1.0 };
    let exp = i32::from((h >> 10) & 0x1f);
    let frac = f32::from(h & 0x3ff);
    sign * match exp {
        0 => frac * 2f32.powi(-24),
        31 if frac == 0.0 => f32::INFINITY,
        31 => f32::NAN,
        e => (1.0 + frac / 1024.0) * 2f32.powi(e - 15),
    }
}
