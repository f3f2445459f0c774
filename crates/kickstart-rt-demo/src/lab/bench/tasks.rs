//! The SDK's trace tasks in `ksrt bench`, on a G-buffer made from the bench's primary hits.

use glam::Vec3;
use kickstart_rt as ksrt;
use wgpu::util::DeviceExt;

use super::harness::Bench;
use super::rays::{primary_rays, surface};
use super::report::{SceneReport, TraceTaskTime};
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::rng::Rng;
use kickstart_rt_renderer::scene::{Camera, Scene};
use kickstart_rt_renderer::sdk_glue::Query;
use kickstart_rt_renderer::upload::UploadedMesh;

/// Light counts of the multi-shadow measurement.
pub const SHADOW_LIGHT_COUNTS: [u32; 6] = [1, 2, 4, 8, 16, 32];

/// A G-buffer texture (Rgba32Float, sampled) holding `texels`.
fn gbuffer_texture(bench: &Bench, (w, h): (u32, u32), texels: &[[f32; 4]]) -> wgpu::TextureView {
    bench
        .device
        .create_texture_with_data(
            bench.queue,
            &wgpu::TextureDescriptor {
                label: Some("bench g-buffer"),
                size: wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba32Float,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(texels),
        )
        .create_view(&Default::default())
}

/// A trace output of `format` at the bench size.
fn trace_output(
    bench: &Bench,
    (w, h): (u32, u32),
    format: wgpu::TextureFormat,
) -> wgpu::TextureView {
    bench
        .device
        .create_texture(&wgpu::TextureDescriptor {
            label: Some("bench trace output"),
            size: wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::STORAGE_BINDING,
            view_formats: &[],
        })
        .create_view(&Default::default())
}

/// The G-buffer of the bench's view made from primary rays traced through the SDK on `ctx`
/// (world positions and geometric normals of the hits, computed on the CPU from the hit
/// records), as the trace tasks' common inputs.
fn hit_gbuffer(
    bench: &Bench,
    ctx: &ksrt::ExecuteContext,
    slots: &std::collections::HashMap<u32, usize>,
    (scene, camera): (&Scene, &Camera),
    (width, height): (u32, u32),
) -> AnyResult<ksrt::TraceTaskCommon> {
    let (dirs, primary) = primary_rays(camera, (width, height));
    let (_, hits) = bench.trace(ctx, &primary, Query::Closest)?;
    let mut positions = vec![[f32::NAN; 4]; hits.len()];
    let mut normals = vec![[0.0f32; 4]; hits.len()];
    for (i, (h, d)) in hits.iter().zip(&dirs).enumerate() {
        if let Some(s) = h.is_hit().then(|| surface(scene, slots, h, *d)).flatten() {
            positions[i] = s.point.extend(1.0).to_array();
            normals[i] = s.normal.extend(0.0).to_array();
        }
    }
    let size = (width, height);
    let depth = gbuffer_texture(bench, size, &positions);
    let normal = gbuffer_texture(bench, size, &normals);
    let extent = scene.size();
    let (world_to_view, view_to_clip) =
        camera.matrices(width as f32 / height as f32, extent * 1e-4, extent * 4.0);
    let mut common = ksrt::TraceTaskCommon::new(
        ksrt::DepthInput {
            texture: depth,
            depth_type: ksrt::DepthType::RgbWorldSpace,
        },
        ksrt::NormalInput {
            texture: normal,
            normal_type: ksrt::NormalType::RgbVector,
            normal_to_world: glam::Mat4::IDENTITY,
        },
    );
    common.view.world_to_view = world_to_view;
    common.view.view_to_clip = view_to_clip;
    common.view.prev_world_to_view = world_to_view;
    common.view.prev_view_to_clip = view_to_clip;
    common.ray_offset.offset_type = ksrt::RayOffsetType::WorldPosition;
    Ok(common)
}

/// The trace tasks the bench times: their outputs and lights.
struct TaskSet {
    radiance: wgpu::TextureView,
    radiance2: wgpu::TextureView,
    scalar: wgpu::TextureView,
    scalar2: wgpu::TextureView,
    packed: wgpu::TextureView,
    /// Point lights around the camera, for the multi-light shadow.
    lights: Vec<ksrt::LightInfo>,
    /// The single shadow's light.
    sun: ksrt::LightInfo,
    /// The scene's size.
    extent: f32,
}

impl TaskSet {
    fn new(bench: &Bench, scene: &Scene, camera: &Camera, size: (u32, u32)) -> TaskSet {
        let extent = scene.size();
        // Lights around the camera, at a tenth of the view distance, so every light matters.
        let reach = (camera.at - camera.eye).length().max(extent * 0.01);
        let mut rng = Rng(0x5348_4457);
        let lights: Vec<ksrt::LightInfo> = (0..32)
            .map(|_| {
                let d = Vec3::new(rng.f32() - 0.5, rng.f32() * 0.5, rng.f32() - 0.5);
                ksrt::LightInfo::Point {
                    position: camera.eye + d * reach * 0.5,
                    radius: reach * 0.01,
                    range: extent * 4.0,
                }
            })
            .collect();
        TaskSet {
            radiance: trace_output(bench, size, wgpu::TextureFormat::Rgba16Float),
            radiance2: trace_output(bench, size, wgpu::TextureFormat::Rgba16Float),
            scalar: trace_output(bench, size, wgpu::TextureFormat::R32Float),
            scalar2: trace_output(bench, size, wgpu::TextureFormat::R32Float),
            packed: trace_output(bench, size, wgpu::TextureFormat::Rgba16Float),
            lights,
            sun: ksrt::LightInfo::Directional {
                direction: Vec3::new(0.3, -1.0, 0.2).normalize(),
                angular_extent: 0.0093,
            },
            extent,
        }
    }

    /// Specular, diffuse, AO and one shadow on `c`: (name, lights, task).
    fn tasks(&self, c: &ksrt::TraceTaskCommon) -> Vec<(&'static str, u32, ksrt::RenderTask)> {
        vec![
            (
                "specular",
                0,
                ksrt::RenderTask::TraceSpecular(ksrt::TraceSpecularTask {
                    common: c.clone(),
                    output: self.radiance.clone(),
                    demodulate_specular: false,
                    demodulation_output: None,
                }),
            ),
            (
                "diffuse",
                0,
                ksrt::RenderTask::TraceDiffuse(ksrt::TraceDiffuseTask {
                    common: c.clone(),
                    output: self.radiance2.clone(),
                    diffuse_brdf: ksrt::DiffuseBrdf::Lambertian,
                    ambient_occlusion: None,
                }),
            ),
            (
                "ao",
                0,
                ksrt::RenderTask::TraceAmbientOcclusion(ksrt::TraceAmbientOcclusionTask {
                    common: c.clone(),
                    output: self.scalar.clone(),
                    ao_radius: self.extent * 0.05,
                }),
            ),
            (
                "shadow",
                1,
                ksrt::RenderTask::TraceShadow(ksrt::TraceShadowTask {
                    common: c.clone(),
                    output: self.scalar2.clone(),
                    light: self.sun,
                    enable_first_hit_and_end_search: true,
                }),
            ),
        ]
    }

    /// The multi-light shadow of the first `n` lights on `c`.
    fn multi(&self, c: &ksrt::TraceTaskCommon, n: u32) -> ksrt::RenderTask {
        ksrt::RenderTask::TraceMultiShadow(ksrt::TraceMultiShadowTask {
            common: c.clone(),
            output0: self.packed.clone(),
            output1: self.radiance2.clone(),
            lights: self.lights[..n as usize].to_vec(),
            enable_first_hit_and_end_search: true,
        })
    }
}

/// (f) The trace tasks on a G-buffer made from primary rays traced through the SDK (no
/// rasteriser involved, see [`hit_gbuffer`]). Each task alone at full and checkerboard
/// resolution, multi-light shadows against the light count, and specular + diffuse + AO + one
/// shadow together.
pub(super) fn trace_tasks(
    bench: &Bench,
    scene: &Scene,
    uploads: &[UploadedMesh],
    camera: &Camera,
    size: (u32, u32),
    report: &mut SceneReport,
) -> AnyResult<()> {
    let (ctx, handles) = bench.registered(scene, uploads, false, true)?;
    let slots = handles.instance_of_slot();
    let common = hit_gbuffer(bench, &ctx, &slots, (scene, camera), size)?;
    let set = TaskSet::new(bench, scene, camera, size);
    let time_one = |task: &ksrt::RenderTask| {
        bench.repeat(|_| {
            let mut c = ctx.create_task_container();
            c.schedule_render_task(task.clone());
            // The trace tasks' passes are timed under the scope "trace" (their pass names say
            // which task); these containers hold no ray batches ("trace rays").
            bench.timed(&ctx, c, &["trace"], |_| {})
        })
    };
    for checkerboard in [false, true] {
        let mut c = common.clone();
        if checkerboard {
            c.half_resolution_mode = ksrt::HalfResolutionMode::Checkerboard;
        }
        for (name, lights, task) in set.tasks(&c) {
            report.trace_tasks.push(TraceTaskTime {
                task: name,
                checkerboard,
                lights,
                time: time_one(&task)?,
            });
        }
        report.trace_tasks.push(TraceTaskTime {
            task: "multi_shadow",
            checkerboard,
            lights: 4,
            time: time_one(&set.multi(&c, 4))?,
        });
    }
    for n in SHADOW_LIGHT_COUNTS {
        report.trace_tasks.push(TraceTaskTime {
            task: "multi_shadow",
            checkerboard: false,
            lights: n,
            time: time_one(&set.multi(&common, n))?,
        });
    }
    report.trace_combined = Some(bench.repeat(|_| {
        let mut c = ctx.create_task_container();
        for (_, _, t) in set.tasks(&common) {
            c.schedule_render_task(t);
        }
        bench.timed(&ctx, c, &["trace"], |_| {})
    })?);
    Ok(())
}
