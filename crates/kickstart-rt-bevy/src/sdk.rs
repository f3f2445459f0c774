//! The SDK's context on Bevy's device and queue, and the GPU timings it reports.

use std::sync::{Arc, Mutex};

use bevy::prelude::*;
use bevy::render::renderer::{RenderDevice, RenderQueue};
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
    /// Creates the SDK on Bevy's render device.
    pub fn new(render_world: &World, plugin: &KickstartRtPlugin) -> ksrt::Result<SdkContext> {
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
        let ctx = ksrt::ExecuteContext::new(&device, queue, settings)?;
        info!(
            "kickstart-rt: {:?} traversal ({})",
            ctx.traversal_backend().backend,
            ctx.traversal_backend().reason
        );
        Ok(SdkContext { ctx, timing })
    }
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
