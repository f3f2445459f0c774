//! Shared GPU test device and helpers. One device per test binary (device creation is slow on
//! lavapipe). `KSRT_TEST_MINIMAL_DEVICE=1` creates it with `Features::empty()` and
//! `Limits::default()` (CI runs the suite both ways). A missing adapter fails the test: a GPU
//! test is never skipped.

#![allow(dead_code)]

pub mod cache;
pub mod denoise;
pub mod rt;
pub mod trace;

use std::sync::OnceLock;
use wgpu::util::DeviceExt;

pub struct Gpu {
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
}

pub fn minimal() -> bool {
    std::env::var("KSRT_TEST_MINIMAL_DEVICE").is_ok_and(|v| v == "1")
}

pub fn gpu() -> &'static Gpu {
    static GPU: OnceLock<Gpu> = OnceLock::new();
    GPU.get_or_init(|| {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
        if std::env::var("WGPU_BACKEND").is_err() {
            desc.backends = wgpu::Backends::PRIMARY;
        }
        let instance = wgpu::Instance::new(desc);
        let adapter = pollster::block_on(instance.request_adapter(&Default::default()))
            .unwrap_or_else(|e| {
                panic!("GPU tests need an adapter (install mesa-vulkan-drivers): {e}")
            });
        let (features, limits) = if minimal() {
            (wgpu::Features::empty(), wgpu::Limits::default())
        } else {
            (
                // What the SDK can use, not every adapter feature: wgpu refuses experimental
                // ones (NVIDIA lists mesh shaders and ray-tracing pipelines) unless opted in.
                kickstart_rt::required_features()
                    | kickstart_rt::optional_features_supported(&adapter),
                adapter.limits(),
            )
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("kickstart-rt tests"),
            required_features: features,
            required_limits: limits,
            ..Default::default()
        }))
        .expect("request_device");
        eprintln!(
            "test device: {:?} (minimal: {})",
            adapter.get_info().name,
            minimal()
        );
        Gpu {
            adapter,
            device,
            queue,
        }
    })
}

pub fn context(working_sets: u32) -> kickstart_rt::ExecuteContext {
    let g = gpu();
    kickstart_rt::ExecuteContext::new(
        &g.device,
        &g.queue,
        kickstart_rt::InitSettings {
            supported_working_sets: working_sets,
            ..Default::default()
        },
    )
    .expect("context")
}

pub fn buffer(bytes: &[u8], usage: wgpu::BufferUsages) -> wgpu::Buffer {
    gpu()
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents: bytes,
            usage,
        })
}

/// A unit quad (2 triangles) as f32x3 vertices and u32 indices, with COPY_SRC.
pub fn quad(scale: f32) -> (wgpu::Buffer, wgpu::Buffer) {
    let p: [[f32; 3]; 4] = [
        [0.0, 0.0, 0.0],
        [scale, 0.0, 0.0],
        [scale, scale, 0.0],
        [0.0, scale, 0.0],
    ];
    let i: [u32; 6] = [0, 1, 2, 0, 2, 3];
    let u = wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_SRC;
    (
        buffer(bytemuck::cast_slice(&p), u),
        buffer(
            bytemuck::cast_slice(&i),
            wgpu::BufferUsages::INDEX | wgpu::BufferUsages::COPY_SRC,
        ),
    )
}

pub fn geometry_input(vb: wgpu::Buffer, ib: Option<wgpu::Buffer>) -> kickstart_rt::GeometryInput {
    use kickstart_rt::*;
    GeometryInput {
        name: "quad".into(),
        components: vec![GeometryComponent {
            vertex_buffer: VertexBufferInput {
                buffer: vb,
                offset: 0,
                stride: 12,
                count: 4,
                format: VertexFormat::Float32x3,
            },
            index_buffer: ib.map(|b| IndexBufferInput {
                buffer: b,
                offset: 0,
                count: 6,
                format: IndexFormat::Uint32,
            }),
            transform: None,
            index_range: None,
        }],
        ..Default::default()
    }
}

pub fn register_geometry(
    c: &mut kickstart_rt::TaskContainer,
    h: kickstart_rt::GeometryHandle,
    scale: f32,
) {
    let (vb, ib) = quad(scale);
    c.schedule_bvh_task(kickstart_rt::GeometryTask {
        operation: kickstart_rt::TaskOperation::Register,
        handle: h,
        input: geometry_input(vb, Some(ib)),
    });
}

pub fn encoder() -> wgpu::CommandEncoder {
    gpu().device.create_command_encoder(&Default::default())
}

/// Submits and waits (tests only: the SDK itself never waits).
pub fn submit(e: wgpu::CommandEncoder) {
    let g = gpu();
    g.queue.submit([e.finish()]);
    g.device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("poll");
}

pub fn read_buffer(src: &wgpu::Buffer) -> Vec<u8> {
    let g = gpu();
    let dst = g.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: src.size(),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut e = encoder();
    e.copy_buffer_to_buffer(src, 0, &dst, 0, src.size());
    submit(e);
    dst.map_async(wgpu::MapMode::Read, .., |_| {});
    g.device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("poll");
    dst.get_mapped_range(..).expect("mapped").to_vec()
}

pub fn texture(
    format: wgpu::TextureFormat,
    w: u32,
    h: u32,
    usage: wgpu::TextureUsages,
) -> wgpu::TextureView {
    gpu()
        .device
        .create_texture(&wgpu::TextureDescriptor {
            label: None,
            size: wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage,
            view_formats: &[],
        })
        .create_view(&Default::default())
}

/// Builds `c`, submits it, waits for the GPU and marks the task completed.
pub fn build_submit_complete(ctx: &kickstart_rt::ExecuteContext, c: kickstart_rt::TaskContainer) {
    let mut e = encoder();
    let t = ctx.build_gpu_task(c, &mut e).expect("build_gpu_task");
    submit(e);
    ctx.mark_gpu_task_completed(t)
        .expect("mark_gpu_task_completed");
}

/// Schedules the registration of instance `handle` of `geometry` at `transform`.
pub fn register_instance(
    c: &mut kickstart_rt::TaskContainer,
    handle: kickstart_rt::InstanceHandle,
    geometry: kickstart_rt::GeometryHandle,
    transform: glam::Affine3A,
) {
    c.schedule_bvh_task(kickstart_rt::InstanceTask {
        operation: kickstart_rt::TaskOperation::Register,
        handle,
        input: kickstart_rt::InstanceInput::new(geometry, transform),
    });
}
