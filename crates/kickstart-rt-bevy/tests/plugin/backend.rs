//! Which traversal backend the plugin takes on Bevy's device, and why: `RayTracingStatus` says
//! it. On a device with ray queries `Auto` takes the hardware backend; without them (CI's
//! lavapipe), the software one, naming the missing feature; `Software` always takes software;
//! `HardwareRayQuery` on a device without ray queries leaves ray-traced lighting off and says
//! how to get them.
//!
//! `KSRT_TEST_BACKEND=hardware` (as in the SDK's suites) makes the default test insist on the
//! hardware backend, for a run on a driver with ray queries (Mesa 25's lavapipe:
//! `.ci/lavapipe-rt`).

use crate::harness;

use bevy::prelude::*;
use bevy::render::renderer::RenderDevice;
use bevy::render::settings::{WgpuSettings, WgpuSettingsPriority};
use harness::{Harness, Setup};
use kickstart_rt_bevy::kickstart_rt::{BackendChoice, TraversalBackend};
use kickstart_rt_bevy::{
    KickstartRtPlugin, RayTracedLighting, RayTracingStatus, ray_query_wgpu_settings,
    with_ray_queries,
};

/// Starts an app with `plugin` (and renderer `settings`), and returns its status and whether
/// Bevy's device has ray queries.
fn start(plugin: KickstartRtPlugin, settings: WgpuSettings) -> (RayTracingStatus, bool) {
    let setup = Setup {
        plugin,
        render_creation: settings.into(),
        ..default()
    };
    let h = Harness::with(setup, RayTracedLighting::default(), || {}, false);
    let world = h.app.world();
    let features = world.resource::<RenderDevice>().features();
    let status = world
        .get_resource::<RayTracingStatus>()
        .cloned()
        .expect("the plugin reports its status once the renderer is up");
    (
        status,
        features.contains(wgpu::Features::EXPERIMENTAL_RAY_QUERY),
    )
}

#[test]
fn auto_takes_ray_queries_where_bevys_device_has_them_and_says_why() {
    let (status, ray_queries) = start(KickstartRtPlugin::default(), ray_query_wgpu_settings());
    println!("ray queries on Bevy's device: {ray_queries}; {status:?}");
    let RayTracingStatus::Running(report) = &status else {
        panic!("ray-traced lighting is off: {status:?}");
    };
    if ray_queries {
        assert_eq!(
            report.backend,
            TraversalBackend::HardwareRayQuery,
            "{report:?}"
        );
    } else {
        assert_eq!(report.backend, TraversalBackend::Software, "{report:?}");
        assert!(
            report.reason.contains("EXPERIMENTAL_RAY_QUERY"),
            "{report:?}"
        );
    }
    if std::env::var("KSRT_TEST_BACKEND").as_deref() == Ok("hardware") {
        assert_eq!(
            status.backend(),
            Some(TraversalBackend::HardwareRayQuery),
            "KSRT_TEST_BACKEND=hardware, yet {status:?}"
        );
    }
}

#[test]
fn software_is_taken_when_asked_for_or_when_the_settings_leave_ray_queries_out() {
    let software = KickstartRtPlugin {
        backend: BackendChoice::Software,
        ..default()
    };
    let (status, _) = start(software, ray_query_wgpu_settings());
    let RayTracingStatus::Running(report) = &status else {
        panic!("ray-traced lighting is off: {status:?}");
    };
    assert_eq!(report.backend, TraversalBackend::Software);
    assert!(report.reason.contains("Software"), "{report:?}");

    // Bevy's WebGPU priority asks for no adapter feature: no ray queries, whatever the GPU.
    let webgpu = WgpuSettings {
        priority: WgpuSettingsPriority::WebGPU,
        ..default()
    };
    let (status, ray_queries) = start(KickstartRtPlugin::default(), webgpu);
    assert!(!ray_queries);
    assert_eq!(
        status.backend(),
        Some(TraversalBackend::Software),
        "{status:?}"
    );
}

#[test]
fn hardware_insisted_on_without_ray_queries_leaves_lighting_off_and_says_how_to_get_them() {
    let hardware = KickstartRtPlugin {
        backend: BackendChoice::HardwareRayQuery,
        ..default()
    };
    let webgpu = WgpuSettings {
        priority: WgpuSettingsPriority::WebGPU,
        ..default()
    };
    let (status, _) = start(hardware, webgpu);
    println!("{status:?}");
    let RayTracingStatus::Off(why) = &status else {
        panic!("HardwareRayQuery ran without ray queries: {status:?}");
    };
    assert!(why.contains("EXPERIMENTAL_RAY_QUERY"), "{why}");
    assert!(why.contains("ray_query_wgpu_settings"), "{why}");
}

#[test]
fn with_ray_queries_frees_what_would_keep_them_out_and_keeps_the_rest() {
    let mine = WgpuSettings {
        priority: WgpuSettingsPriority::WebGPU,
        features: wgpu::Features::TIMESTAMP_QUERY,
        disabled_features: Some(wgpu::Features::EXPERIMENTAL_RAY_QUERY | wgpu::Features::SUBGROUP),
        constrained_limits: Some(wgpu::Limits::default()),
        ..default()
    };
    let settings = with_ray_queries(mine);
    assert!(matches!(
        settings.priority,
        WgpuSettingsPriority::Functionality
    ));
    assert_eq!(settings.features, wgpu::Features::TIMESTAMP_QUERY);
    assert_eq!(settings.disabled_features, Some(wgpu::Features::SUBGROUP));
    let limits = settings.constrained_limits.expect("still constrained");
    assert_eq!(limits.max_blas_primitive_count, u32::MAX);
    assert_eq!(limits.max_tlas_instance_count, u32::MAX);
    assert_eq!(
        limits.max_acceleration_structures_per_shader_stage,
        u32::MAX
    );
    // The other limits stay the caller's.
    assert_eq!(
        limits.max_storage_buffers_per_shader_stage,
        wgpu::Limits::default().max_storage_buffers_per_shader_stage
    );
}
