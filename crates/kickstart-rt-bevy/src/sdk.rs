//! The SDK's context on Bevy's device and queue, and the GPU timings it reports.

use std::sync::{Arc, Mutex};

use bevy::prelude::*;
use bevy::render::renderer::{RenderDevice, RenderQueue};
use bevy::render::settings::{WgpuSettings, WgpuSettingsPriority};
use kickstart_rt as ksrt;

use crate::KickstartRtPlugin;

/// GPU tasks the SDK may have recorded and not yet seen finish: Bevy keeps up to a few frames
/// in flight, plus the scene-update task of each.
const WORKING_SETS: u32 = 8;

/// The SDK instance, living in the render world.
#[derive(Resource)]
pub(crate) struct SdkContext {
    pub ctx: ksrt::ExecuteContext,
    /// Whether GPU tasks carry timestamps ([`KickstartRtPlugin::gpu_timing`] and the features).
    pub timing: bool,
}

impl SdkContext {
    /// Creates the SDK on Bevy's render device; the error says why it cannot run there.
    pub fn new(render_world: &World, plugin: &KickstartRtPlugin) -> Result<SdkContext, String> {
        let device = render_world
            .resource::<RenderDevice>()
            .wgpu_device()
            .clone();
        let queue: &wgpu::Queue = render_world.resource::<RenderQueue>();
        let timing = plugin.gpu_timing
            && device.features().contains(
                wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS,
            );
        let settings = ksrt::InitSettings {
            supported_working_sets: WORKING_SETS,
            backend: plugin.backend,
            gpu_timing: timing,
            ..Default::default()
        };
        let ctx = ksrt::ExecuteContext::new(&device, queue, settings).map_err(|e| {
            let rq = wgpu::Features::EXPERIMENTAL_RAY_QUERY;
            if plugin.backend == ksrt::BackendChoice::HardwareRayQuery
                && !device.features().contains(rq)
            {
                // The usual cause: an adapter without ray queries, or settings that left them
                // out of the device.
                format!(
                    "{e}; KickstartRtPlugin::backend is HardwareRayQuery and Bevy's device has no \
                     ray queries (the adapter lacks them, or the RenderPlugin's WgpuSettings \
                     left them out: see kickstart_rt_bevy::ray_query_wgpu_settings)"
                )
            } else {
                e.to_string()
            }
        })?;
        let report = ctx.traversal_backend();
        info!(
            "kickstart-rt: {} traversal ({})",
            report.backend, report.reason
        );
        Ok(SdkContext { ctx, timing })
    }
}

/// Whether ray-traced lighting runs, and on which traversal backend: a main-world resource the
/// plugin inserts once Bevy's renderer is up (absent before, and in an app without a renderer
/// that never finishes its plugins).
#[derive(Resource, Clone, Debug, PartialEq, Eq)]
pub enum RayTracingStatus {
    /// The SDK runs on Bevy's device, with this backend (and the reason it was chosen).
    Running(ksrt::BackendReport),
    /// Ray-traced lighting is off for the app's lifetime: why (also logged as an error).
    Off(String),
}

impl RayTracingStatus {
    /// The backend the SDK traces with, when it runs.
    pub fn backend(&self) -> Option<ksrt::TraversalBackend> {
        match self {
            RayTracingStatus::Running(report) => Some(report.backend),
            RayTracingStatus::Off(_) => None,
        }
    }
}

/// Bevy renderer settings under which the device gets ray queries wherever the adapter offers
/// them, for the SDK's hardware backend: `RenderPlugin { render_creation:
/// ray_query_wgpu_settings().into(), .. }`.
///
/// The features cannot be named before Bevy picks the adapter (asking for one the adapter lacks
/// fails device creation), so this relies on Bevy's own mechanism:
/// [`WgpuSettingsPriority::Functionality`] requests every feature and limit the adapter offers,
/// and Bevy always opts into wgpu's experimental features, which ray queries are. That is Bevy's
/// default priority, so a default app already gets them; these settings pin it against a
/// `WGPU_SETTINGS_PRIO` environment variable. [`with_ray_queries`] does the same to settings of
/// your own.
pub fn ray_query_wgpu_settings() -> WgpuSettings {
    with_ray_queries(WgpuSettings::default())
}

/// `settings` changed so that the device gets ray queries where the adapter has them: the
/// `Functionality` priority, `EXPERIMENTAL_RAY_QUERY` taken out of `disabled_features`, and the
/// acceleration-structure limits freed from `constrained_limits` (the adapter's own apply).
/// Everything else is kept, features you request included; under the `WebGPU` priority Bevy
/// would ask for no adapter feature at all, hence the priority change.
pub fn with_ray_queries(mut settings: WgpuSettings) -> WgpuSettings {
    settings.priority = WgpuSettingsPriority::Functionality;
    if let Some(disabled) = &mut settings.disabled_features {
        disabled.remove(wgpu::Features::EXPERIMENTAL_RAY_QUERY);
    }
    if let Some(constrained) = settings.constrained_limits.take() {
        // Bevy takes the lower of the adapter's and these: unbounded, the adapter's stand.
        let unbounded = wgpu::Limits {
            max_blas_geometry_count: u32::MAX,
            max_tlas_instance_count: u32::MAX,
            max_blas_primitive_count: u32::MAX,
            max_acceleration_structures_per_shader_stage: u32::MAX,
            max_buffers_and_acceleration_structures_per_shader_stage: u32::MAX,
            ..constrained.clone()
        };
        settings.constrained_limits =
            Some(constrained.using_acceleration_structure_values(unbounded));
    }
    settings
}

/// GPU time of the SDK's passes in the last frame whose timings were read, per pass
/// (`"group: pass"`, e.g. `"trace: trace diffuse"`), in milliseconds (only with [`KickstartRtPlugin::gpu_timing`]). The same value is a resource of
/// the main world and the render world.
#[derive(Resource, Clone, Default)]
pub struct SdkTimings(pub Arc<Mutex<Vec<(String, f64)>>>);

impl SdkTimings {
    /// The last frame's passes: (label, milliseconds), in recording order.
    pub fn passes(&self) -> Vec<(String, f64)> {
        self.0.lock().map(|p| p.clone()).unwrap_or_default()
    }

    /// Sum of the last frame's passes, milliseconds.
    pub fn total_ms(&self) -> f64 {
        self.passes().iter().map(|(_, ms)| ms).sum()
    }

    pub(crate) fn set(&self, timings: &ksrt::GpuTimings) {
        if let Ok(mut passes) = self.0.lock() {
            *passes = timings
                .passes
                .iter()
                .map(|p| (format!("{}: {}", p.label, p.pass), p.ms))
                .collect();
        }
    }
}
