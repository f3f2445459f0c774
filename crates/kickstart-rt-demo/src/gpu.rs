//! Adapter selection and the `info` / `render` commands.

use kickstart_rt as ksrt;

use crate::AnyResult;

fn adapter() -> AnyResult<wgpu::Adapter> {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
    // Vulkan/Metal/DX12 unless WGPU_BACKEND says otherwise: probing GL on a headless machine only
    // prints EGL errors.
    if std::env::var_os("WGPU_BACKEND").is_none() {
        desc.backends = wgpu::Backends::PRIMARY;
    }
    let instance = wgpu::Instance::new(desc);
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

/// `ksrt render`.
pub fn render(size: &str, out: std::path::PathBuf) -> AnyResult<()> {
    let (w, h) = size
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
        .ok_or_else(|| format!("--size {size:?}: expected WIDTHxHEIGHT, e.g. 1280x720"))?;
    let adapter = adapter()?;
    let (device, queue) = device(&adapter)?;
    crate::render::render(
        &device,
        &queue,
        &crate::render::RenderOptions {
            width: w,
            height: h,
            out,
        },
    )
}
