//! Per-camera textures and denoising contexts, remade when the camera's size changes.

use bevy::prelude::*;
use bevy::render::camera::ExtractedCamera;
use bevy::render::renderer::RenderDevice;
use kickstart_rt as ksrt;

use crate::RayTracedLighting;
use crate::sdk::SdkContext;

/// What one camera's ray-traced lighting needs from frame to frame.
#[derive(Component)]
pub(crate) struct ViewResources {
    /// Pixel size of the camera's target.
    pub size: UVec2,
    /// Unpacked G-buffer: world normal (RGB), perceptual roughness (A).
    pub normal_roughness: wgpu::TextureView,
    /// F0 (RGB), metallic (A).
    pub specular: wgpu::TextureView,
    /// Diffuse colour (RGB).
    pub diffuse_color: wgpu::TextureView,
    /// Traced signals, raw: reflections, GI, AO, shadow.
    pub traced: [wgpu::TextureView; 4],
    /// The same, denoised.
    pub denoised: [wgpu::TextureView; 4],
    /// Denoising contexts: reflections, GI, AO, shadow.
    pub denoisers: [ksrt::DenoisingContextHandle; 4],
    /// Their method (the camera's preset's): another preset's remakes them.
    pub method: ksrt::DenoisingMethod,
    /// Frames traced so far (the noise pattern's index; 0 discards denoiser history).
    pub frame: u32,
    /// The effects of the last frame: a toggled effect restarts its denoiser's history.
    pub last_settings: Option<RayTracedLighting>,
    /// Last frame's world-to-view and view-to-clip matrices.
    pub previous: Option<(Mat4, Mat4)>,
    /// Whether the camera's MSAA was reported (it keeps the camera from being traced).
    pub warned_msaa: bool,
}

impl ViewResources {
    fn new(
        device: &wgpu::Device,
        ctx: &ksrt::ExecuteContext,
        size: UVec2,
        method: ksrt::DenoisingMethod,
    ) -> ksrt::Result<Self> {
        let texture = |label: &str| {
            device
                .create_texture(&wgpu::TextureDescriptor {
                    label: Some(label),
                    size: wgpu::Extent3d {
                        width: size.x,
                        height: size.y,
                        depth_or_array_layers: 1,
                    },
                    mip_level_count: 1,
                    sample_count: 1,
                    dimension: wgpu::TextureDimension::D2,
                    format: wgpu::TextureFormat::Rgba16Float,
                    usage: wgpu::TextureUsages::STORAGE_BINDING
                        | wgpu::TextureUsages::TEXTURE_BINDING
                        | wgpu::TextureUsages::COPY_SRC,
                    view_formats: &[],
                })
                .create_view(&Default::default())
        };
        let signals = ["reflections", "gi", "ao", "shadow"];
        let denoiser = |signal_type| {
            ctx.create_denoising_context_handle(ksrt::DenoisingContextInput {
                max_width: size.x,
                max_height: size.y,
                signal_type,
                method,
            })
        };
        let denoisers = [
            denoiser(ksrt::SignalType::Specular)?,
            denoiser(ksrt::SignalType::Diffuse)?,
            denoiser(ksrt::SignalType::DiffuseOcclusion)?,
            denoiser(ksrt::SignalType::Shadow)?,
        ];
        Ok(ViewResources {
            size,
            normal_roughness: texture("kickstart-rt normal roughness"),
            specular: texture("kickstart-rt specular"),
            diffuse_color: texture("kickstart-rt diffuse colour"),
            traced: signals.map(|s| texture(&format!("kickstart-rt {s}"))),
            denoised: signals.map(|s| texture(&format!("kickstart-rt {s} denoised"))),
            denoisers,
            method,
            frame: 0,
            last_settings: None,
            previous: None,
            warned_msaa: false,
        })
    }

    /// Hands the denoising contexts back to the SDK.
    fn release(&self, ctx: &ksrt::ExecuteContext) {
        if let Err(e) = ctx.destroy_denoising_context_handles(&self.denoisers) {
            warn!("kickstart-rt: releasing a camera's denoisers: {e}");
        }
    }
}

/// Hands back the resources of cameras that no longer have [`RayTracedLighting`].
pub(crate) fn release_view_resources(
    mut commands: Commands,
    sdk: Res<SdkContext>,
    views: Query<(Entity, &ViewResources), Without<RayTracedLighting>>,
) {
    for (entity, resources) in &views {
        resources.release(&sdk.ctx);
        commands.entity(entity).remove::<ViewResources>();
    }
}

/// Creates each ray-traced camera's resources, and remakes them when its size or its preset's
/// denoising method changes (a denoising context keeps the method it was made with).
pub(crate) fn prepare_view_resources(
    mut commands: Commands,
    sdk: Res<SdkContext>,
    device: Res<RenderDevice>,
    views: Query<(
        Entity,
        &ExtractedCamera,
        &RayTracedLighting,
        Option<&ViewResources>,
    )>,
) {
    for (entity, camera, settings, existing) in &views {
        let Some(size) = camera.physical_target_size.filter(|s| s.x > 0 && s.y > 0) else {
            continue;
        };
        let method = settings.preset.denoising_method();
        if existing.is_some_and(|r| r.size == size && r.method == method) {
            continue;
        }
        if let Some(old) = existing {
            old.release(&sdk.ctx);
        }
        match ViewResources::new(device.wgpu_device(), &sdk.ctx, size, method) {
            Ok(resources) => {
                commands.entity(entity).insert(resources);
            }
            Err(e) => error!("kickstart-rt: camera {entity}: {e}"),
        }
    }
}
