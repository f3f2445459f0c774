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
//! - **Scene:** every entity with a [`Mesh3d`] (triangle lists, any vertex layout with
//!   `Float32x3` positions, `u16` or `u32` indices or none) is registered with the SDK, and kept
//!   in sync as it moves, spawns, despawns, hides or changes mesh. The SDK copies positions out
//!   of Bevy's own mesh buffers on the GPU (the plugin asks Bevy's mesh allocator for `COPY_SRC`
//!   and `STORAGE` on them). Meshes with compressed positions or a topology other than a
//!   triangle list are left out with a warning each.
//! - **Skinned and morphed meshes** (a [`SkinnedMesh`](bevy::mesh::skinning::SkinnedMesh), a
//!   [`MeshMorphWeights`](bevy::mesh::morph::MeshMorphWeights)) are traced at the pose Bevy
//!   draws: each frame the plugin computes every joint's matrix as Bevy's skinning does (the
//!   joint entity's `GlobalTransform` × its inverse bindpose) and reads the morph weights, and
//!   the SDK's [`SkinningTask`](kickstart_rt::SkinningTask) poses the rest positions in Bevy's
//!   vertex buffer (morph targets first, then up to four joints a vertex) into a positions
//!   buffer of the entity's own, from which the SDK refits the entity's BLAS. All of a frame's
//!   deformed meshes go into one SDK task: one compute dispatch and one refit each a frame.
//! - **Cutouts:** a mesh whose [`StandardMaterial`] has `AlphaMode::Mask(cutoff)` (or
//!   `AlphaToCoverage`, which is `Mask(0.5)` without MSAA) and a `base_color_texture` is traced as
//!   the SDK's cutout geometry: rays pass where `base_color.alpha() × texture alpha < cutoff`, as
//!   Bevy's raster discards, the texture read at the mesh's `ATTRIBUTE_UV_0` (or `_1`, per
//!   `base_color_channel`) in Bevy's own vertex buffer. The SDK bakes it into opacity micro-maps
//!   when the mesh is registered, so the plugin registers it again when the material's texture,
//!   factor, cutoff or alpha mode changes or the texture's texels do. A masked material without a
//!   texture is opaque or, below its cutoff, left out. Masks are traced opaque (with a warning)
//!   where the SDK cannot follow Bevy: a `uv_transform` other than identity, compressed UVs.
//!   `Blend`, `Premultiplied`, `Add` and `Multiply` have no ray-traced counterpart and are traced
//!   opaque; so are meshes of other material types. Vertex colours' alpha is not part of the traced
//!   test.
//! - **Rates:** [`RayTracedLighting::preset`] takes the SDK's [`Preset`]s (as `ksrt render
//!   --preset`): which pixels each effect traces a frame, the denoiser and the injection's
//!   stride.
//! - **Backend:** the SDK traces with hardware ray queries where Bevy's device has them, and in
//!   compute shaders otherwise; [`RayTracingStatus`] says which it took and why (also logged).
//!   Bevy's default renderer settings ask for ray queries wherever the adapter offers them:
//!   [`ray_query_wgpu_settings`] and [`with_ray_queries`] pin that.
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
mod cutout;
mod frame;
mod gbuffer;
mod scene;
mod sdk;
mod skin;
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
pub use kickstart_rt::Preset;
pub use sdk::{RayTracingStatus, SdkTimings, ray_query_wgpu_settings, with_ray_queries};

/// Adds ray-traced lighting to every camera with a [`RayTracedLighting`] component.
///
/// Once the renderer is up, the main world holds a [`RayTracingStatus`]: the traversal backend
/// the SDK took and why, or why ray-traced lighting is off.
#[derive(Clone, Debug)]
pub struct KickstartRtPlugin {
    /// Which traversal the SDK uses. `Auto` (the default) takes hardware ray queries when
    /// Bevy's device was created with them (Bevy's default settings ask for them where the
    /// adapter has them: see [`ray_query_wgpu_settings`]) and the portable compute traversal
    /// otherwise. `Software` always takes the compute traversal. `HardwareRayQuery` insists:
    /// on a device without ray queries ray-traced lighting stays off, with the reason logged
    /// and in [`RayTracingStatus::Off`].
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
///
/// [`RayTracedLighting::performance`], [`balanced`](RayTracedLighting::balanced) and
/// [`quality`](RayTracedLighting::quality) turn every effect on at one of the SDK's
/// [`Preset`]s; `default()` is the quality preset.
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
    /// How many pixels each effect traces a frame, which denoiser filters them and how densely
    /// Bevy's lit image is injected into the lighting cache: the SDK's [`Preset`], as
    /// `ksrt render --preset` applies it ([`Preset::Quality`], every pixel, by default).
    /// Changing it remakes the camera's denoisers (their history restarts).
    ///
    /// At a reduced rate the denoisers fill the pixels not traced this frame; with `denoise`
    /// off, each pixel shows its block's traced pixel (blocks of 2×2 or 4×4 pixels).
    // Not reflected: the SDK's type has no `Reflect`.
    #[reflect(ignore, clone, default = "quality_preset")]
    pub preset: Preset,
}

/// The default [`RayTracedLighting::preset`] (what reflection fills in).
fn quality_preset() -> Preset {
    Preset::Quality
}

impl RayTracedLighting {
    /// Every effect, denoised, at `preset`.
    pub fn with_preset(preset: Preset) -> Self {
        RayTracedLighting {
            preset,
            ..Default::default()
        }
    }

    /// Every effect at [`Preset::Performance`]: reflections, GI and AO trace one pixel in
    /// 4×4, shadows one in 2×2; the fast denoiser.
    pub fn performance() -> Self {
        Self::with_preset(Preset::Performance)
    }

    /// Every effect at [`Preset::Balanced`]: one pixel in 2×2 for every effect; the fast
    /// denoiser.
    pub fn balanced() -> Self {
        Self::with_preset(Preset::Balanced)
    }

    /// Every effect at [`Preset::Quality`] (the default): every pixel; the high-quality
    /// denoiser.
    pub fn quality() -> Self {
        Self::with_preset(Preset::Quality)
    }
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
            preset: quality_preset(),
        }
    }
}

impl Plugin for KickstartRtPlugin {
    fn build(&self, app: &mut App) {
        // The effects read material properties from Bevy's deferred G-buffer, which only
        // materials rendered by the deferred path write.
        app.register_type::<RayTracedLighting>()
            .insert_resource(DefaultOpaqueRendererMethod::deferred())
            .init_resource::<scene::ChangedMaterials>()
            // After the asset events of the update (PostUpdate), before extraction.
            .add_systems(Last, scene::collect_changed_materials)
            .add_plugins(ExtractComponentPlugin::<RayTracedLighting>::default());
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return;
        };
        // The SDK copies vertex and index data out of Bevy's mesh buffers, and its skinning
        // pass reads skinned meshes' rest positions, joints and weights there in place.
        render_app
            .world_mut()
            .resource_mut::<MeshAllocatorSettings>()
            .extra_buffer_usages |= BufferUsages::COPY_SRC | BufferUsages::STORAGE;
    }

    fn finish(&self, app: &mut App) {
        let status = match self.start(app) {
            Ok(report) => RayTracingStatus::Running(report),
            Err(e) => {
                error!("kickstart-rt: ray-traced lighting is off: {e}");
                RayTracingStatus::Off(e)
            }
        };
        app.insert_resource(status);
    }
}

impl KickstartRtPlugin {
    /// Creates the SDK on Bevy's device and adds the render-world systems; returns the backend
    /// the SDK took, or why ray-traced lighting cannot run.
    fn start(&self, app: &mut App) -> Result<kickstart_rt::BackendReport, String> {
        let Some(render_app) = app.get_sub_app_mut(RenderApp) else {
            return Err("the app has no render sub-app (is Bevy's RenderPlugin missing?)".into());
        };
        let context = sdk::SdkContext::new(render_app.world(), self)?;
        let report = context.ctx.traversal_backend().clone();
        let unpack = gbuffer::Unpack::new(render_app.world())?;
        let composite = composite::Composite::new(render_app.world())?;
        let timings = SdkTimings::default();
        render_app
            .insert_resource(context)
            .insert_resource(timings.clone())
            .insert_resource(unpack)
            .insert_resource(composite)
            .init_resource::<scene::ExtractedScene>()
            .init_resource::<scene::SceneSync>()
            .init_resource::<frame::FramesInFlight>()
            .add_systems(
                ExtractSchedule,
                (
                    scene::extract_mesh_instances,
                    scene::extract_lights,
                    skin::extract_poses,
                ),
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
        Ok(report)
    }
}
