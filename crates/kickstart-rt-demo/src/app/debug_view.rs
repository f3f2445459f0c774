//! `ksrt render --debug-view`: the SDK's primary-ray debug views (hit distance, barycentrics, a
//! colour per instance), traced on the GPU by a trace task and written as PNG.

use kickstart_rt as ksrt;

/// A debug view `--debug-view` names.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DebugView {
    /// Distance from the eye, grey: near white, far dark, misses black.
    HitT,
    /// `(1 − u − v, u, v)` as RGB.
    Barycentrics,
    /// A colour hashed from the instance index.
    MeshColor,
    /// The SDK's direct lighting cache at the primary hits (interpolated): what was injected,
    /// else each instance's initial tile colour.
    Cache,
    /// A colour hashed from the lighting cache's surfel (tile) id.
    Tiles,
}

impl DebugView {
    /// Every view, in the order `ksrt render` writes them.
    pub const ALL: [DebugView; 5] = [
        DebugView::MeshColor,
        DebugView::HitT,
        DebugView::Barycentrics,
        DebugView::Cache,
        DebugView::Tiles,
    ];

    /// The name in the output file (`debug-<name>.png`).
    pub fn name(self) -> &'static str {
        match self {
            DebugView::HitT => "hit-t",
            DebugView::Barycentrics => "barycentrics",
            DebugView::MeshColor => "mesh-color",
            DebugView::Cache => "cache",
            DebugView::Tiles => "tiles",
        }
    }

    /// The SDK's debug output type of this view.
    pub fn output_type(self) -> ksrt::DebugOutputType {
        match self {
            DebugView::HitT => ksrt::DebugOutputType::HitT,
            DebugView::Barycentrics => ksrt::DebugOutputType::Barycentrics,
            DebugView::MeshColor => ksrt::DebugOutputType::RandomMeshColor,
            DebugView::Cache => ksrt::DebugOutputType::DirectLightingCache,
            DebugView::Tiles => ksrt::DebugOutputType::RandomTileColor,
        }
    }
}

/// Turns the task's output into an 8-bit image. Hit-t is normalised to the range of distances in
/// the image itself (no legend to read): the nearest hit white, the farthest dark grey (not black,
/// so it stays apart from misses), misses black. The other views are colours already.
pub fn to_image(view: DebugView, texels: &[[f32; 4]], width: u32, height: u32) -> image::RgbImage {
    let hit = |t: &[f32; 4]| t[3] > 0.5;
    let (near, far) = texels
        .iter()
        .filter(|t| hit(t) && t[0].is_finite())
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), t| {
            (lo.min(t[0]), hi.max(t[0]))
        });
    let byte = |v: f32| (v.clamp(0.0, 1.0) * 255.0 + 0.5) as u8;
    let mut img = image::RgbImage::new(width, height);
    for (p, t) in img.pixels_mut().zip(texels) {
        *p = match view {
            _ if !hit(t) => image::Rgb([0, 0, 0]),
            DebugView::HitT => {
                let s = if far > near {
                    (t[0] - near) / (far - near)
                } else {
                    0.0
                };
                let g = byte(1.0 - 0.85 * s);
                image::Rgb([g, g, g])
            }
            DebugView::Barycentrics
            | DebugView::MeshColor
            | DebugView::Cache
            | DebugView::Tiles => image::Rgb([byte(t[0]), byte(t[1]), byte(t[2])]),
        };
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::gpu;
    use kickstart_rt_renderer::error::AnyResult;
    use kickstart_rt_renderer::scene::{Camera, Scene};
    use kickstart_rt_renderer::upload;

    /// Registers `scene` with a new context, builds its BVHs and traces `view` from `camera` into a
    /// `width`×`height` image, returned as RGBA `f32` texels, rows top to bottom. The context never
    /// injects, so the lighting cache's view shows each instance's initial tile colour (black):
    /// `ksrt render` traces its views on the lit render's context instead ([`crate::app::lit`]).
    pub fn trace(
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        scene: &Scene,
        camera: &Camera,
        view: DebugView,
        (width, height): (u32, u32),
    ) -> AnyResult<Vec<[f32; 4]>> {
        let ctx = ksrt::ExecuteContext::new(device, queue, crate::app::gpu::init_settings())?;
        let uploads = upload::upload_scene(device, queue, scene);
        let mut c = ctx.create_task_container();
        upload::schedule_static_scene(&ctx, &mut c, scene, &uploads);
        // Every BLAS in this one task, so the trace below sees the whole scene.
        c.schedule_bvh_task(ksrt::BvhBuildTask {
            max_blas_build_count: (uploads.len() as u32).max(1),
            build_tlas: true,
            ..Default::default()
        });

        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let texture = |label, format, usage| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage,
                view_formats: &[],
            })
        };
        let output = texture(
            "ksrt debug view",
            wgpu::TextureFormat::Rgba32Float,
            wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
        );
        // The debug views trace primary rays from the view and read no G-buffer, but the task needs
        // depth and normal inputs, of the output's size (the viewport must fit every texture).
        let depth = texture(
            "ksrt unused depth",
            wgpu::TextureFormat::R32Float,
            wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let normal = texture(
            "ksrt unused normals",
            wgpu::TextureFormat::Rgba8Unorm,
            wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let scene_size = scene.size();
        let (world_to_view, view_to_clip) = camera.matrices(
            width as f32 / height as f32,
            scene_size * 1e-4,
            scene_size * 10.0,
        );
        let mut common = ksrt::TraceTaskCommon::new(
            ksrt::DepthInput {
                texture: depth.create_view(&Default::default()),
                depth_type: ksrt::DepthType::RClipSpace,
            },
            ksrt::NormalInput {
                texture: normal.create_view(&Default::default()),
                normal_type: ksrt::NormalType::RgbNormalizedVector,
                normal_to_world: glam::Mat4::IDENTITY,
            },
        );
        common.view = ksrt::ViewInfo {
            world_to_view,
            view_to_clip,
            prev_world_to_view: world_to_view,
            prev_view_to_clip: view_to_clip,
            jitter: glam::Vec2::ZERO,
        };
        common.debug_parameters.debug_output_type = view.output_type();
        c.schedule_render_task(ksrt::RenderTask::TraceAmbientOcclusion(
            ksrt::TraceAmbientOcclusionTask {
                common,
                output: output.create_view(&Default::default()),
                ao_radius: scene_size,
            },
        ));

        // Rows of a texture copy are padded to 256 bytes.
        let row = width as u64 * 16;
        let padded = row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as u64)
            * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as u64;
        let readback = gpu::readback_buffer(device, padded * height as u64);
        let task = upload::submit(&ctx, device, queue, c, |encoder| {
            encoder.copy_texture_to_buffer(
                output.as_image_copy(),
                wgpu::TexelCopyBufferInfo {
                    buffer: &readback,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(padded as u32),
                        rows_per_image: None,
                    },
                },
                size,
            );
        })?;
        gpu::complete(&ctx, device, task)?;
        let bytes = gpu::map_read(device, &readback)?;
        let mut texels = Vec::with_capacity(width as usize * height as usize);
        for y in 0..height as usize {
            let start = y * padded as usize;
            // The mapped copy has no alignment guarantee for f32: read texels unaligned.
            texels.extend(
                bytes[start..start + row as usize]
                    .chunks_exact(16)
                    .map(bytemuck::pod_read_unaligned::<[f32; 4]>),
            );
        }
        Ok(texels)
    }

    #[test]
    fn hit_t_maps_near_to_white_far_to_dark_and_misses_to_black() {
        let texels = [
            [1.0, 1.0, 1.0, 1.0],
            [3.0, 3.0, 3.0, 1.0],
            [0.0, 0.0, 0.0, 0.0],
        ];
        let img = to_image(DebugView::HitT, &texels, 3, 1);
        assert_eq!(img.get_pixel(0, 0).0, [255, 255, 255]);
        assert!(img.get_pixel(1, 0).0[0] > 0 && img.get_pixel(1, 0).0[0] < 64);
        assert_eq!(img.get_pixel(2, 0).0, [0, 0, 0]);
    }

    /// `ksrt render --debug-view` on the built-in scenes and every scene of the repository:
    /// each is registered, built on the GPU and traced, and shows geometry (hits with finite
    /// distances, at least two instance colours where it has several instances) and sky.
    #[test]
    fn debug_views_render_every_scene() {
        let dir = crate::app::scenes::repository_scenes_dir();
        let adapter =
            crate::app::gpu::adapter().expect("GPU tests need an adapter (mesa-vulkan-drivers)");
        let (device, queue) = crate::app::gpu::device(&adapter).expect("device");
        let names = [
            "default",
            "cornell",
            "cornell-obj",
            "cornell-gltf",
            "apartment",
            "statue",
            "grove",
        ];
        for name in names {
            let scene =
                crate::app::scenes::load(name, &dir).unwrap_or_else(|e| panic!("{name}: {e}"));
            let camera =
                scene.camera_or_default(kickstart_rt_renderer::scene::benchmark_camera(name));
            let (w, h) = (48, 27);
            let t = trace(&device, &queue, &scene, &camera, DebugView::HitT, (w, h))
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            let hits: Vec<&[f32; 4]> = t.iter().filter(|p| p[3] == 1.0).collect();
            assert!(
                hits.len() > 40,
                "{name}: {} of {} pixels hit",
                hits.len(),
                t.len()
            );
            assert!(
                hits.iter().all(|p| p[0].is_finite() && p[0] > 0.0),
                "{name}"
            );
            let m = trace(
                &device,
                &queue,
                &scene,
                &camera,
                DebugView::MeshColor,
                (w, h),
            )
            .unwrap_or_else(|e| panic!("{name}: {e}"));
            let mut colours: Vec<[u32; 3]> = m
                .iter()
                .filter(|p| p[3] == 1.0)
                .map(|p| [p[0].to_bits(), p[1].to_bits(), p[2].to_bits()])
                .collect();
            colours.sort();
            colours.dedup();
            let want = if scene.instances.len() > 1 { 2 } else { 1 };
            assert!(
                colours.len() >= want,
                "{name}: {} instance colours",
                colours.len()
            );
            // The same pixels hit in both views.
            for (a, b) in t.iter().zip(&m) {
                assert_eq!(a[3], b[3], "{name}");
            }
        }
    }
}
