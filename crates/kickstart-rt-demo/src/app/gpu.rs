//! Adapter and device selection on this machine, the `--backend` choice, the `info` command, and
//! the blocking helpers every GPU command shares: waiting for a task and reading buffers back.
//! (Uploading and registering a scene is the renderer's `upload`.)

use kickstart_rt as ksrt;
use kickstart_rt_renderer::error::AnyResult;

/// The adapter `ksrt` runs on (the high-performance one of the primary backends, or what
/// `WGPU_BACKEND` selects).
pub fn adapter() -> AnyResult<wgpu::Adapter> {
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

/// The traversal backend every `ksrt` command asks the SDK for (`--backend`), set once by
/// `main` before any device is made.
static BACKEND: std::sync::OnceLock<ksrt::BackendChoice> = std::sync::OnceLock::new();

/// Sets the backend choice of this run (`--backend`); the first call wins.
pub fn set_backend_choice(choice: ksrt::BackendChoice) {
    let _ = BACKEND.set(choice);
}

/// The backend choice of this run (`Auto` unless `--backend` said otherwise).
pub fn backend_choice() -> ksrt::BackendChoice {
    BACKEND.get().copied().unwrap_or_default()
}

/// A device with the SDK's required features and every optional one the adapter has (which
/// includes `TIMESTAMP_QUERY`, the benchmark's GPU timing), less those named in
/// `KSRT_DISABLE_FEATURES` ([`disabled_features`]); with ray queries when the adapter has them
/// and `--backend` is not `software` (an explicit `hardware` on an adapter without them is an
/// error naming it).
pub fn device(adapter: &wgpu::Adapter) -> AnyResult<(wgpu::Device, wgpu::Queue)> {
    let optional = ksrt::optional_features_supported(adapter) - disabled_features()?;
    let mut features = ksrt::required_features() | optional;
    let mut limits = ksrt::required_limits().using_resolution(adapter.limits());
    let mut experimental_features = wgpu::ExperimentalFeatures::disabled();
    let choice = backend_choice();
    if choice != ksrt::BackendChoice::Software {
        match ksrt::hardware_ray_query_features(adapter) {
            Some(rq) => {
                features |= rq;
                limits = ksrt::hardware_ray_query_limits(adapter, limits);
                // SAFETY: `ksrt` accepts wgpu's experimental ray-query support (the SDK's
                // hardware backend is tested against the software one and the CPU oracle).
                experimental_features = unsafe { wgpu::ExperimentalFeatures::enabled() };
            }
            None if choice == ksrt::BackendChoice::HardwareRayQuery => {
                return Err(format!(
                    "--backend hardware: {} has no ray queries (Features::EXPERIMENTAL_RAY_QUERY)",
                    adapter.get_info().name
                )
                .into());
            }
            None => {}
        }
    }
    let desc = wgpu::DeviceDescriptor {
        label: Some("ksrt"),
        required_features: features,
        required_limits: limits,
        experimental_features,
        ..Default::default()
    };
    Ok(pollster::block_on(adapter.request_device(&desc))?)
}

/// `InitSettings` of this run's backend choice (and the other defaults).
pub fn init_settings() -> ksrt::InitSettings {
    ksrt::InitSettings {
        backend: backend_choice(),
        ..Default::default()
    }
}

/// [`init_settings`] with GPU timestamps on or off.
pub fn init_settings_timed(gpu_timing: bool) -> ksrt::InitSettings {
    ksrt::InitSettings {
        gpu_timing,
        ..init_settings()
    }
}

/// Optional SDK features named in the environment variable `KSRT_DISABLE_FEATURES`
/// (comma-separated wgpu names, e.g. `PASSTHROUGH_SHADERS,SUBGROUP`): the device is created
/// without them, so the SDK's fallback for each runs (and can be measured against the fast path
/// in one binary).
pub fn disabled_features() -> AnyResult<wgpu::Features> {
    let Ok(list) = std::env::var("KSRT_DISABLE_FEATURES") else {
        return Ok(wgpu::Features::empty());
    };
    parse_feature_list(&list)
}

/// The optional features named in `list` (comma-separated; blanks ignored).
fn parse_feature_list(list: &str) -> AnyResult<wgpu::Features> {
    let mut features = wgpu::Features::empty();
    for name in list.split(',').map(str::trim).filter(|n| !n.is_empty()) {
        let found = ksrt::optional_features()
            .iter_names()
            .find(|(n, _)| n.eq_ignore_ascii_case(name));
        match found {
            Some((_, f)) => features |= f,
            None => {
                let known: Vec<&str> = ksrt::optional_features()
                    .iter_names()
                    .map(|(n, _)| n)
                    .collect();
                return Err(format!(
                    "KSRT_DISABLE_FEATURES: `{name}` is not an optional SDK feature (known: {})",
                    known.join(", ")
                )
                .into());
            }
        }
    }
    Ok(features)
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
    let limits = adapter.limits();
    println!(
        "hardware ray queries: {}",
        match (
            ksrt::hardware_ray_query_features(&adapter),
            have.contains(wgpu::Features::EXPERIMENTAL_RAY_QUERY)
        ) {
            (Some(_), _) => format!(
                "yes (the hardware backend is available; BLAS vertices ≤ {}, TLAS instances ≤ {})",
                limits.max_blas_primitive_count, limits.max_tlas_instance_count
            ),
            (None, true) => "no: the adapter reports no acceleration-structure limits".to_string(),
            // wgpu's Vulkan backend offers ray queries where the device has VK_KHR_ray_query
            // with VK_KHR_acceleration_structure, VK_KHR_deferred_host_operations and
            // VK_KHR_buffer_device_address.
            (None, false) => "no: the adapter lacks Features::EXPERIMENTAL_RAY_QUERY (on Vulkan: \
                 VK_KHR_ray_query and VK_KHR_acceleration_structure); the software backend traces"
                .to_string(),
        }
    );
    let (device, queue) = device(&adapter)?;
    let ctx = ksrt::ExecuteContext::new(&device, &queue, init_settings())?;
    let backend = ctx.traversal_backend();
    println!("ExecuteContext: created ({ctx:?})");
    println!(
        "traversal backend: {} ({})",
        backend.backend, backend.reason
    );
    Ok(())
}

/// Waits for the GPU to finish everything submitted, then retires `task`.
pub fn complete(
    ctx: &ksrt::ExecuteContext,
    device: &wgpu::Device,
    task: ksrt::GpuTaskHandle,
) -> AnyResult<()> {
    device.poll(wgpu::PollType::wait_indefinitely())?;
    match ctx.mark_gpu_task_completed(task) {
        // Already retired (e.g. by a timing read-back that waited on it): nothing left to do.
        Ok(()) | Err(ksrt::Error::InvalidGpuTaskHandle(_)) => Ok(()),
        Err(e) => Err(e.into()),
    }
}

/// Maps a `MAP_READ` buffer after the GPU is done and returns its bytes.
pub fn map_read(device: &wgpu::Device, buffer: &wgpu::Buffer) -> AnyResult<Vec<u8>> {
    let slice = buffer.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    device.poll(wgpu::PollType::wait_indefinitely())?;
    rx.recv()
        .map_err(|_| "the buffer map callback never ran")??;
    let bytes = slice.get_mapped_range()?.to_vec();
    buffer.unmap();
    Ok(bytes)
}

/// A `MAP_READ | COPY_DST` buffer of `size` bytes to copy results into.
pub fn readback_buffer(device: &wgpu::Device, size: u64) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("ksrt read-back"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn feature_lists_name_optional_features_only() {
        let f = parse_feature_list(" passthrough_shaders, SUBGROUP ,").expect("valid list");
        assert_eq!(
            f,
            wgpu::Features::PASSTHROUGH_SHADERS | wgpu::Features::SUBGROUP
        );
        assert_eq!(
            parse_feature_list("").expect("empty"),
            wgpu::Features::empty()
        );
        let err = parse_feature_list("RAY_QUERY")
            .expect_err("not optional")
            .to_string();
        assert!(
            err.contains("RAY_QUERY") && err.contains("PASSTHROUGH_SHADERS"),
            "{err}"
        );
    }
}

/// What wgpu's own allocator holds on `device`: bytes and allocations live, read after waiting
/// for the device to go idle (so that resources freed by finished work are gone). It counts
/// every buffer, texture and acceleration structure wgpu allocated, the driver BLASes and
/// TLASes of the ray-query backend included, and nothing the SDK says about itself: the check
/// on the SDK's own accounting. `None` on backends without a report (Metal, GL, WebGPU).
pub fn wgpu_allocated(device: &wgpu::Device) -> AnyResult<Option<WgpuAllocated>> {
    device.poll(wgpu::PollType::wait_indefinitely())?;
    Ok(device.generate_allocator_report().map(|r| WgpuAllocated {
        bytes: r.total_allocated_bytes,
        allocations: r.allocations.len(),
    }))
}

/// Live memory in wgpu's allocator (see [`wgpu_allocated`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct WgpuAllocated {
    /// Bytes of all live allocations.
    pub bytes: u64,
    /// Live allocations.
    pub allocations: usize,
}
