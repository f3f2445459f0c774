//! Shared GPU test device and helpers. One device for the test binary (device creation is slow on
//! lavapipe). `KSRT_TEST_MINIMAL_DEVICE=1` creates it with `Features::empty()` and
//! `Limits::default()` (CI runs the suite both ways). A missing adapter fails the test: a GPU
//! test is never skipped. `KSRT_TEST_BACKEND=hardware` creates it with hardware ray queries
//! (contexts then take the hardware backend: `InitSettings::backend` is `Auto`), and a device
//! without them fails the test; `software` or unset leaves them out.

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

/// The traversal backend this test pass asks for (`KSRT_TEST_BACKEND`).
pub fn backend() -> kickstart_rt::TraversalBackend {
    match std::env::var("KSRT_TEST_BACKEND").as_deref() {
        Ok("hardware") => kickstart_rt::TraversalBackend::HardwareRayQuery,
        Ok("software") | Err(_) => kickstart_rt::TraversalBackend::Software,
        Ok(other) => panic!("KSRT_TEST_BACKEND={other}: expected `software` or `hardware`"),
    }
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
        let hardware = backend() == kickstart_rt::TraversalBackend::HardwareRayQuery;
        let (mut features, mut limits) = if minimal() {
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
        let mut experimental_features = wgpu::ExperimentalFeatures::disabled();
        if hardware {
            let rq = kickstart_rt::hardware_ray_query_features(&adapter).unwrap_or_else(|| {
                panic!(
                    "KSRT_TEST_BACKEND=hardware: {:?} has no ray queries",
                    adapter.get_info().name
                )
            });
            features |= rq;
            limits = kickstart_rt::hardware_ray_query_limits(&adapter, limits);
            // SAFETY: the tests accept wgpu's experimental ray-query support.
            experimental_features = unsafe { wgpu::ExperimentalFeatures::enabled() };
        }
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("kickstart-rt tests"),
            required_features: features,
            required_limits: limits,
            experimental_features,
            ..Default::default()
        }))
        .expect("request_device");
        eprintln!(
            "test device: {:?} (minimal: {}, backend: {})",
            adapter.get_info().name,
            minimal(),
            backend()
        );
        Gpu {
            adapter,
            device,
            queue,
        }
    })
}

/// A device of its own from the test adapter, with the shared test device's features (ray
/// queries on the hardware pass, nothing optional on the minimal one) and `limits`: for tests
/// that lose their device or need other limits, on the same backend as the rest of the pass.
pub fn own_test_device(limits: wgpu::Limits, label: &str) -> (wgpu::Device, wgpu::Queue) {
    let g = gpu();
    let hardware = backend() == kickstart_rt::TraversalBackend::HardwareRayQuery;
    pollster::block_on(g.adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some(label),
        required_features: g.device.features(),
        required_limits: limits,
        experimental_features: if hardware {
            // SAFETY: the tests accept wgpu's experimental ray-query support.
            unsafe { wgpu::ExperimentalFeatures::enabled() }
        } else {
            wgpu::ExperimentalFeatures::disabled()
        },
        ..Default::default()
    }))
    .expect("a device of the test adapter")
}

/// A context on the shared device, with the default settings but `working_sets`; fails the test
/// when it took another backend than the pass asks for (a silent fallback to software).
pub fn context(working_sets: u32) -> kickstart_rt::ExecuteContext {
    context_with(kickstart_rt::InitSettings {
        supported_working_sets: working_sets,
        ..Default::default()
    })
}

/// A context on the shared device with `settings`, checked as [`context`]'s is.
pub fn context_with(settings: kickstart_rt::InitSettings) -> kickstart_rt::ExecuteContext {
    let g = gpu();
    let ctx = kickstart_rt::ExecuteContext::new(&g.device, &g.queue, settings).expect("context");
    assert_pass_backend(&ctx);
    ctx
}

/// Waits until every task `ctx` invoked by itself is seen complete, or fails the test after
/// `limit`. A wait on the device is not enough by itself: on a device shared by tests running in
/// parallel, another thread's poll may take the queue's completion callbacks and run them just
/// after our wait returns, so the count is read until that callback has run.
pub fn settle_invoked_tasks(ctx: &kickstart_rt::ExecuteContext, limit: std::time::Duration) {
    let start = std::time::Instant::now();
    loop {
        gpu()
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .expect("poll");
        let left = ctx.in_flight_task_count();
        if left == 0 {
            return;
        }
        assert!(
            start.elapsed() < limit,
            "{left} invoked tasks still in flight {:?} after the device went idle",
            start.elapsed()
        );
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

/// Fails the test when `ctx` took another backend than the pass asks for (`KSRT_TEST_BACKEND`):
/// every test that makes a context of its own (another device, other settings) checks it too.
pub fn assert_pass_backend(ctx: &kickstart_rt::ExecuteContext) {
    let report = ctx.traversal_backend();
    assert_eq!(
        report.backend,
        backend(),
        "the context took another backend than KSRT_TEST_BACKEND asks for: {}",
        report.reason
    );
}

/// The explicit choice of the pass's backend, for contexts on devices of a test's own (which
/// may offer ray queries on a software pass).
pub fn pass_backend_choice() -> kickstart_rt::BackendChoice {
    match backend() {
        kickstart_rt::TraversalBackend::Software => kickstart_rt::BackendChoice::Software,
        kickstart_rt::TraversalBackend::HardwareRayQuery => {
            kickstart_rt::BackendChoice::HardwareRayQuery
        }
    }
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
            opacity: None,
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

/// [`build_submit_complete`] on a device of the test's own (`own_test_device`).
pub fn build_submit_complete_on(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    ctx: &kickstart_rt::ExecuteContext,
    c: kickstart_rt::TaskContainer,
) {
    let mut e = device.create_command_encoder(&Default::default());
    let t = ctx.build_gpu_task(c, &mut e).expect("build_gpu_task");
    queue.submit([e.finish()]);
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

/// A `Depth32Float` depth buffer (`TEXTURE_BINDING | RENDER_ATTACHMENT | COPY_SRC`) of `w × h` holding
/// `depth` (row-major, in [0, 1]). Depth formats cannot be copy destinations, so the values go
/// through an `R32Float` texture and a full-screen pass that writes them as `frag_depth`
/// (bit-exact for a 32-bit float depth buffer). Waits for the GPU.
pub fn depth32float_texture(w: u32, h: u32, depth: &[f32]) -> wgpu::TextureView {
    assert_eq!(depth.len(), (w * h) as usize);
    let g = gpu();
    let src = trace::texture_with(
        wgpu::TextureFormat::R32Float,
        w,
        h,
        wgpu::TextureUsages::TEXTURE_BINDING,
        bytemuck::cast_slice(depth),
    );
    let dst = texture(
        wgpu::TextureFormat::Depth32Float,
        w,
        h,
        wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::RENDER_ATTACHMENT
            | wgpu::TextureUsages::COPY_SRC,
    );
    let (pipeline, layout) = depth_copy_pipeline(&g.device);
    let bind = g.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: None,
        layout: &layout,
        entries: &[wgpu::BindGroupEntry {
            binding: 0,
            resource: wgpu::BindingResource::TextureView(&src),
        }],
    });
    let mut e = encoder();
    {
        let mut pass = e.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("depth copy"),
            color_attachments: &[],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &dst,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(0.5),
                    store: wgpu::StoreOp::Store,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        pass.draw(0..3, 0..1);
    }
    submit(e);
    assert_depth_holds(&dst, w, h, depth);
    dst
}

/// A full-screen pass writing an `R32Float` texture's values as `frag_depth`, and its bind group
/// layout.
fn depth_copy_pipeline(device: &wgpu::Device) -> (wgpu::RenderPipeline, wgpu::BindGroupLayout) {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some("depth copy"),
        source: wgpu::ShaderSource::Wgsl(
            r#"
@group(0) @binding(0) var src: texture_2d<f32>;
@vertex fn vs(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    let uv = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);
}
@fragment fn fs(@builtin(position) pos: vec4<f32>) -> @builtin(frag_depth) f32 {
    return textureLoad(src, vec2<u32>(pos.xy), 0).x;
}
"#
            .into(),
        ),
    });
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: None,
        entries: &[wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: false },
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            },
            count: None,
        }],
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: None,
        bind_group_layouts: &[Some(&layout)],
        immediate_size: 0,
    });
    let pipeline = device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("depth copy"),
        layout: Some(&pipeline_layout),
        vertex: wgpu::VertexState {
            module: &module,
            entry_point: Some("vs"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: Default::default(),
        depth_stencil: Some(wgpu::DepthStencilState {
            format: wgpu::TextureFormat::Depth32Float,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Always),
            stencil: Default::default(),
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module: &module,
            entry_point: Some("fs"),
            compilation_options: Default::default(),
            targets: &[],
        }),
        multiview_mask: None,
        cache: None,
    });
    (pipeline, layout)
}

/// Asserts that the depth buffer `dst` holds `depth` bit for bit.
fn assert_depth_holds(dst: &wgpu::TextureView, w: u32, h: u32, depth: &[f32]) {
    let g = gpu();
    // The depth buffer must hold the values exactly (a test input, not a result under test).
    let row = (w * 4).div_ceil(256) * 256;
    let buf = g.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: (row * h) as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let mut e = encoder();
    e.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture: dst.texture(),
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::DepthOnly,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &buf,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(h),
            },
        },
        dst.texture().size(),
    );
    submit(e);
    let bytes = read_buffer(&buf);
    for y in 0..h as usize {
        let line: &[f32] =
            bytemuck::cast_slice(&bytes[y * row as usize..y * row as usize + w as usize * 4]);
        for (x, v) in line.iter().enumerate() {
            let want = depth[y * w as usize + x];
            assert_eq!(v.to_bits(), want.to_bits(), "depth buffer texel ({x}, {y})");
        }
    }
}

// Tests on a device of their own (other limits than the shared one's).
use glam::Affine3A;
use kickstart_rt::{
    BvhBuildTask, ExecuteContext, GeometryComponent, GeometryHandle, GeometryInput, GeometryTask,
    GpuHit, GpuRay, IndexBufferInput, IndexFormat, InstanceHandle, RenderTask, TaskContainer,
    TaskOperation, TraceRaysTask, VertexBufferInput, VertexFormat,
};

/// A geometry of `triangles` triangles over the 4 corners of a unit quad (the indices cycle
/// through its two triangles), in buffers of `device`.
pub fn many_triangles(device: &wgpu::Device, triangles: u32) -> GeometryInput {
    let p: [[f32; 3]; 4] = [[0.0; 3], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
    let quad = [0u32, 1, 2, 0, 2, 3];
    let indices: Vec<u32> = (0..triangles as usize * 3).map(|i| quad[i % 6]).collect();
    let init = |contents: &[u8], usage| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents,
            usage: usage | wgpu::BufferUsages::COPY_SRC,
        })
    };
    let (vb, ib) = (
        init(bytemuck::cast_slice(&p), wgpu::BufferUsages::VERTEX),
        init(bytemuck::cast_slice(&indices), wgpu::BufferUsages::INDEX),
    );
    GeometryInput {
        name: format!("{triangles} triangles"),
        components: vec![GeometryComponent {
            vertex_buffer: VertexBufferInput {
                buffer: vb,
                offset: 0,
                stride: 12,
                count: 4,
                format: VertexFormat::Float32x3,
            },
            index_buffer: Some(IndexBufferInput {
                buffer: ib,
                offset: 0,
                count: triangles * 3,
                format: IndexFormat::Uint32,
            }),
            transform: None,
            index_range: None,
            opacity: None,
        }],
        ..Default::default()
    }
}

/// Traces `rays` (closest hit) through `ctx` on its own `device`; the hits and the task's serial.
pub fn trace_on(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    ctx: &ExecuteContext,
    rays: &[GpuRay],
) -> (Vec<GpuHit>, u64) {
    let rb = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("rays"),
        contents: bytemuck::cast_slice(rays),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let size = rays.len() as u64 * 32;
    let hb = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("hits"),
        size,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let read = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("hits read-back"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut c = ctx.create_task_container();
    c.schedule_render_task(RenderTask::TraceRays(TraceRaysTask::new(
        rb,
        rays.len() as u32,
        hb.clone(),
    )));
    let mut e = device.create_command_encoder(&Default::default());
    let t = ctx.build_gpu_task(c, &mut e).expect("trace task");
    e.copy_buffer_to_buffer(&hb, 0, &read, 0, size);
    queue.submit([e.finish()]);
    read.map_async(wgpu::MapMode::Read, .., |_| {});
    device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
    ctx.mark_gpu_task_completed(t).unwrap();
    let hits = bytemuck::pod_collect_to_vec(&read.get_mapped_range(..).expect("mapped"));
    (hits, t.serial())
}

/// A container registering `input` as `geometry`, an instance of it, and building both.
pub fn register_and_build(
    ctx: &ExecuteContext,
    handles: (GeometryHandle, InstanceHandle),
    input: GeometryInput,
) -> TaskContainer {
    register_and_build_at(ctx, handles, input, Affine3A::IDENTITY)
}

/// As [`register_and_build`], the instance placed by `transform`.
pub fn register_and_build_at(
    ctx: &ExecuteContext,
    (geometry, instance): (GeometryHandle, InstanceHandle),
    input: GeometryInput,
    transform: Affine3A,
) -> TaskContainer {
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Register,
        handle: geometry,
        input,
    });
    register_instance(&mut c, instance, geometry, transform);
    c.schedule_bvh_task(BvhBuildTask::default());
    c
}

/// The seed of every property test when `PROPTEST_RNG_SEED` is not set: a fixed one, so that a
/// run repeats the last one and a failure in CI replays here.
const PROPTEST_SEED: u64 = 0x6b73_7274_5f66_757a;

/// The seed of a fuzzed test named `what`: `PROPTEST_RNG_SEED` when set, else `default`;
/// printed, so a failure's output says how to replay it.
pub fn fuzz_seed(what: &str, default: u64) -> u64 {
    let seed = std::env::var("PROPTEST_RNG_SEED")
        .ok()
        .and_then(|s| s.trim().parse().ok())
        .unwrap_or(default);
    eprintln!("{what} seed {seed} (PROPTEST_RNG_SEED={seed} replays it)");
    seed
}

/// A property test's configuration: `cases` cases from a fixed seed (`PROPTEST_RNG_SEED`
/// overrides it; the seed used is printed, shown with a failure's output), and no failure
/// files written into the source tree.
pub fn proptest_config(cases: u32) -> proptest::test_runner::Config {
    let seed = fuzz_seed("property test", PROPTEST_SEED);
    proptest::test_runner::Config {
        cases,
        rng_seed: proptest::test_runner::RngSeed::Fixed(seed),
        failure_persistence: None,
        ..proptest::test_runner::Config::default()
    }
}

/// What wgpu's own allocator holds on `device` once it is idle: live bytes and allocations, or
/// `None` on backends without a report. It counts every buffer, texture and acceleration
/// structure wgpu allocated (the driver's BLASes and TLAS on the ray-query backend included),
/// and nothing the SDK says about itself: the check on `resource_allocations()`. Read it on a
/// device of the test's own (`own_test_device`): the shared one carries other tests' work.
pub fn wgpu_allocated(device: &wgpu::Device) -> Option<(u64, usize)> {
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("poll");
    device
        .generate_allocator_report()
        .map(|r| (r.total_allocated_bytes, r.allocations.len()))
}

/// Polls until the compaction of `h`'s BLAS is read back and applied (each call to the context
/// collects what arrived), or fails the test.
pub fn compacted_after_polls(
    ctx: &kickstart_rt::ExecuteContext,
    device: &wgpu::Device,
    h: kickstart_rt::GeometryHandle,
) -> kickstart_rt::BlasMemory {
    for _ in 0..1000 {
        let m = ctx.geometry_blas_memory(h).unwrap().expect("built");
        if m.compaction != kickstart_rt::BlasCompaction::Pending {
            return m;
        }
        device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    panic!("the compaction of {h:?} was not read back after 1000 polls");
}
