//! Adapter selection and the `info` / `render` commands.

use kickstart_rt as ksrt;
use wgpu::util::DeviceExt;

type AnyResult<T> = Result<T, Box<dyn std::error::Error>>;

fn adapter() -> AnyResult<wgpu::Adapter> {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        ..Default::default()
    }))
    .map_err(|e| {
        format!("no GPU adapter found ({e}); install a GPU driver or mesa-vulkan-drivers")
    })?;
    Ok(adapter)
}

fn device(adapter: &wgpu::Adapter) -> AnyResult<(wgpu::Device, wgpu::Queue)> {
    let desc = wgpu::DeviceDescriptor {
        label: Some("ksrt"),
        required_features: ksrt::required_features() | ksrt::optional_features_supported(adapter),
        required_limits: ksrt::required_limits().using_resolution(adapter.limits()),
        ..Default::default()
    };
    Ok(pollster::block_on(adapter.request_device(&desc))?)
}

/// `ksrt info`.
pub fn info() -> AnyResult<()> {
    let adapter = adapter()?;
    let i = adapter.get_info();
    println!("kickstart-rt {}", ksrt::VERSION);
    println!(
        "adapter:  {} ({:?}, {:?})",
        i.name, i.device_type, i.backend
    );
    println!("driver:   {} {}", i.driver, i.driver_info);
    let have = adapter.features();
    let required = ksrt::required_features();
    println!(
        "required features: {}",
        if required.is_empty() {
            "none".to_string()
        } else {
            format!("{required:?}")
        }
    );
    for (name, f) in ksrt::required_features().iter_names() {
        println!(
            "  {name:<44} {}",
            if have.contains(f) { "yes" } else { "MISSING" }
        );
    }
    println!("optional features (used when present):");
    for (name, f) in ksrt::optional_features().iter_names() {
        println!(
            "  {name:<44} {}",
            if have.contains(f) { "yes" } else { "no" }
        );
    }
    println!("required limits (WebGPU defaults):");
    let limits = adapter.limits();
    let mut ok = true;
    ksrt::required_limits().check_limits_with_fail_fn(&limits, false, |name, req, got| {
        ok = false;
        println!("  {name:<44} needs {req}, adapter has {got}");
    });
    if ok {
        println!("  all met");
    }
    println!(
        "  max_storage_buffer_binding_size: {} MiB, max_storage_buffers_per_shader_stage: {}",
        limits.max_storage_buffer_binding_size / (1 << 20),
        limits.max_storage_buffers_per_shader_stage
    );
    let (device, queue) = device(&adapter)?;
    let ctx = ksrt::ExecuteContext::new(&device, &queue, ksrt::InitSettings::default())?;
    println!("ExecuteContext: created ({ctx:?})");
    Ok(())
}

/// `ksrt render`: for now registers the default scene's meshes and prints what the SDK holds.
pub fn render() -> AnyResult<()> {
    let adapter = adapter()?;
    let (device, queue) = device(&adapter)?;
    let ctx = ksrt::ExecuteContext::new(&device, &queue, ksrt::InitSettings::default())?;
    // A floor quad: the first mesh of the default scene.
    let positions: [[f32; 3]; 4] = [
        [-5.0, 0.0, -5.0],
        [5.0, 0.0, -5.0],
        [5.0, 0.0, 5.0],
        [-5.0, 0.0, 5.0],
    ];
    let indices: [u32; 6] = [0, 2, 1, 0, 3, 2];
    let vb = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("floor vertices"),
        contents: bytemuck::cast_slice(&positions),
        usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_SRC,
    });
    let ib = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("floor indices"),
        contents: bytemuck::cast_slice(&indices),
        usage: wgpu::BufferUsages::INDEX | wgpu::BufferUsages::COPY_SRC,
    });
    let geometry = ctx.create_geometry_handle();
    let instance = ctx.create_instance_handle();
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(ksrt::GeometryTask {
        operation: ksrt::TaskOperation::Register,
        handle: geometry,
        input: ksrt::GeometryInput {
            name: "floor".into(),
            components: vec![ksrt::GeometryComponent {
                vertex_buffer: ksrt::VertexBufferInput {
                    buffer: vb,
                    offset: 0,
                    stride: 12,
                    count: 4,
                    format: ksrt::VertexFormat::Float32x3,
                },
                index_buffer: Some(ksrt::IndexBufferInput {
                    buffer: ib,
                    offset: 0,
                    count: 6,
                    format: ksrt::IndexFormat::Uint32,
                }),
                transform: None,
                index_range: None,
            }],
            ..Default::default()
        },
    });
    c.schedule_bvh_task(ksrt::InstanceTask {
        operation: ksrt::TaskOperation::Register,
        handle: instance,
        input: ksrt::InstanceInput::new(geometry, glam::Affine3A::IDENTITY),
    });
    ctx.invoke_gpu_task(c)?;
    device.poll(wgpu::PollType::wait_indefinitely())?;
    println!(
        "registered 1 geometry, 1 instance; SDK memory: {:?}",
        ctx.resource_allocations()
    );
    println!(
        "note: images need the ray tracing core (BVH build and trace tasks), not in this version"
    );
    Ok(())
}
