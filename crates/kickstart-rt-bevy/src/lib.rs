//! Ray-traced reflections, diffuse GI, ambient occlusion and sun shadows for Bevy 0.20, on any
//! GPU Bevy runs on: [kickstart-rt](kickstart_rt) traces in compute shaders, so no ray-tracing
//! hardware is needed.
//!
//! ```no_run
//! use bevy::prelude::*;
//! use kickstart_rt_bevy::{KickstartRtPlugin, RayTracedLighting};
//!
//! App::new()
//!     .add_plugins((DefaultPlugins, KickstartRtPlugin::default()))
//!     .add_systems(Startup, |mut commands: Commands| {
//!         commands.spawn((Camera3d::default(), RayTracedLighting::default()));
//!     })
//!     .run();
//! ```
//!
//! # What the plugin does
//! - **Scene:** every entity with a [`Mesh3d`](bevy::prelude::Mesh3d) (triangle lists, any
//!   vertex layout with `Float32x3` positions, `u16` or `u32` indices or none) is registered with
//!   the SDK, and kept in sync as it moves, spawns, despawns, hides or changes mesh. The SDK
//!   copies positions out of Bevy's own mesh buffers on the GPU (the plugin asks Bevy's mesh
//!   allocator for `COPY_SRC` on them). Skinned and morphed meshes are left out, with a warning
//!   logged once: Bevy deforms them in its vertex shader, out of the SDK's reach (a compute
//!   skinning pass feeding the SDK's refit would bring them in). Meshes with compressed
//!   positions or a topology other than a triangle list are left out with a warning each.
//! - **Each frame, for each camera with [`RayTracedLighting`]**, after Bevy's deferred lighting
//!   pass: the deferred G-buffer is unpacked into the SDK's inputs (normal, roughness, F0); Bevy's
//!   lit image, which at that point holds only Bevy's own (direct) light, is injected into the
//!   SDK's lighting cache; the enabled effects are traced and denoised; and a composite adds
//!   them into the view: diffuse GI × albedo (× AO), reflections × the split-sum specular term,
//!   and ray-traced shadows take the first directional light's diffuse light away where it is
//!   blocked.
//! - **On Bevy's device and encoder**: the SDK records into the same command encoder as Bevy's
//!   passes; nothing waits for the GPU.
//!
//! # What the camera needs
//! [`RayTracedLighting`] requires the deferred prepass, depth and motion-vector prepasses and
//! HDR; add `Msaa::Off` to the camera (Bevy's deferred renderer has no MSAA). For GI, set
//! Bevy's `GlobalAmbientLight` to zero brightness (the plugin's GI replaces it; it warns once
//! otherwise), and for ray-traced shadows turn Bevy's shadow maps off on the directional light
//! (`shadow_maps_enabled: false`, Bevy's default), or the shadow is applied twice.

mod composite;
mod frame;
mod gbuffer;
mod scene;
mod sdk;
mod view;

use bevy::camera::Hdr;
use bevy::core_pipeline::prepass::{DeferredPrepass, DepthPrepass, MotionVectorPrepass};
use bevy::core_pipeline::schedule::{Core3d, Core3dSystems};
use bevy::pbr::DefaultOpaqueRendererMethod;
use bevy::prelude::*;
use bevy::render::extract_component::{ExtractComponent, ExtractComponentPlugin};
use bevy::render::mesh::allocator::MeshAllocatorSettings;
use bevy::render::render_resource::BufferUsages;
use bevy::render::{ExtractSchedule, Render, RenderApp, RenderSystems};

pub use kickstart_rt;
pub use sdk::SdkTimings;

/// Adds ray-traced lighting to every camera with a [`RayTracedLighting`] component.
#[derive(Clone, Debug)]
pub struct KickstartRtPlugin {
    /// Which traversal the SDK uses (hardware ray queries when the device has them, by
    /// default; the portable compute traversal otherwise).
    pub backend: kickstart_rt::BackendChoice,
    /// Collect GPU timestamps of the SDK's passes into [`SdkTimings`] (needs the device's
    /// `TIMESTAMP_QUERY` features; ignored without them).
    pub gpu_timing: bool,
}

impl Default for KickstartRtPlugin {
    fn default() -> Self {
        KickstartRtPlugin {
            backend: kickstart_rt::BackendChoice::Auto,
            gpu_timing: false,
        }
    }
}

/// The ray-traced effects of one camera. Each is traced and (with `denoise`) denoised only
/// when on; toggling any of them at run time is free.
#[derive(Component, Clone, Debug, PartialEq, ExtractComponent, Reflect)]
#[reflect(Component, Default, Clone)]
#[extract_app(RenderApp)]
#[require(Hdr, DeferredPrepass, DepthPrepass, MotionVectorPrepass)]
pub struct RayTracedLighting {
    /// Glossy and mirror reflections, weighted by each surface's F0 and roughness.
    pub reflections: bool,
    /// One bounce of diffuse light, read from the SDK's lighting cache where rays hit.
    pub gi: bool,
    /// Ambient occlusion: multiplies the GI (or, without GI, the whole lit image).
    pub ao: bool,
    /// Ray-traced shadows of the first directional light.
    pub shadows: bool,
    /// Denoise each effect (temporal accumulation and an edge-aware spatial filter); off shows
    /// the raw one-sample-per-pixel traces.
    pub denoise: bool,
    /// Distance within which geometry occludes for AO, in world units.
    pub ao_radius: f32,
    /// Angular diameter of the sun for soft shadows, radians.
    pub sun_angular_diameter: f32,
}

impl Default for RayTracedLighting {
    fn default() -> Self {
        RayTracedLighting {
            reflections: true,
            gi: true,
            ao: true,
            shadows: true,
            denoise: true,
            ao_radius: 1.0,
            sun_angular_diameter: 0.5f32.to_radians(),
        }
    }
}

impl Plugin for KickstartRtPlugin {
    fn build(&self, app: &mut App) {
        // The effects read material properties from Bevy's deferred G-buffer, which only
        // materials rendered by the deferred path write.
        app.register_type::<RayTracedLighting>()
            .insert_resource(DefaultOpaqueRendererMethod::deferred())
            .add_plugins(ExtractComponentPlugin::<RayTracedLighting>::default());
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        // The SDK copies vertex and index data out of Bevy's mesh buffers.
        render_app
            .world_mut()
            .resource_mut::<MeshAllocatorSettings>()
            .extra_buffer_usages |= BufferUsages::COPY_SRC;
    }

    fn finish(&self, app: &mut App) {
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        let context = match sdk::SdkContext::new(render_app.world(), self) {
            Ok(context) => context,
            Err(e) => {
                error!("kickstart-rt: ray-traced lighting is off: {e}");
                return;
            }
        };
        let passes = match (
            gbuffer::Unpack::new(render_app.world()),
            composite::Composite::new(render_app.world()),
        ) {
            (Ok(unpack), Ok(composite)) => (unpack, composite),
            (Err(e), _) | (_, Err(e)) => {
                error!("kickstart-rt: ray-traced lighting is off: {e}");
                return;
            }
        };
        let timings = SdkTimings::default();
        render_app
            .insert_resource(context)
            .insert_resource(timings.clone())
            .insert_resource(passes.0)
            .insert_resource(passes.1)
            .init_resource::<scene::ExtractedScene>()
            .init_resource::<scene::SceneSync>()
            .init_resource::<frame::FramesInFlight>()
            .add_systems(
                ExtractSchedule,
                (scene::extract_mesh_instances, scene::extract_lights),
            )
            .add_systems(
                Render,
                (
                    frame::retire_finished_frames,
                    scene::sync_scene,
                    view::release_view_resources,
                    view::prepare_view_resources,
                )
                    .chain()
                    .in_set(RenderSystems::PrepareResources),
            )
            .add_systems(
                Render,
                frame::track_submitted_frames.in_set(RenderSystems::Cleanup),
            )
            .add_systems(
                Core3d,
                frame::ray_traced_lighting
                    .after(bevy::pbr::deferred::deferred_lighting)
                    .before(bevy::core_pipeline::core_3d::main_opaque_pass_3d)
                    .in_set(Core3dSystems::MainPass),
            );
        // The render world writes the timings; the main world reads the same shared value.
        app.insert_resource(timings);
    }
}
