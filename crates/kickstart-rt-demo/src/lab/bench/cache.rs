//! `ksrt bench`: the direct lighting cache. Per scene:
//! - **cache bytes** at the default tile settings: the surfels every instance got (16 bytes
//!   each, from the SDK's allocation read-back, after the pool has grown to hold them all at full
//!   resolution) and the whole `cache` kind of `resource_allocations()`;
//! - **injection time** of one `DirectLightingInjectionTask` at the bench size for strides 1, 2
//!   and 4 (the `injection` passes: inject and resolve);
//! - **cache error**: the mean relative difference `Σ|cache − E| / ΣE` over the primary hits,
//!   where `E = max(0, N·L)` is the exact direct lighting of a white directional light (no
//!   shadows) with the geometric normal, after 1, 8 and 64 injection tasks of that image (default
//!   stride 4 and average window 200), read with the DirectLightingCache debug view (bilinear).
//!
//! The injected image is made on the CPU from the primary hits of the bench's ray batch: world
//! positions (`RgbWorldSpace` depth) and `E`, so every pixel is exact.

use std::collections::HashMap;

use glam::Vec3;
use kickstart_rt as ksrt;
use wgpu::util::DeviceExt;

use super::harness::Bench;
use super::rays::surface;
pub use super::report::CacheReport;
use crate::app::gpu;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::scene::{Camera, Scene};
use kickstart_rt_renderer::sdk_glue as glue;
use kickstart_rt_renderer::upload::{self, UploadedMesh};

/// Direction towards the bench's directional light.
const LIGHT: Vec3 = Vec3::new(0.3, 1.0, 0.2);

fn texture(
    bench: &Bench,
    label: &str,
    (w, h): (u32, u32),
    format: wgpu::TextureFormat,
    usage: wgpu::TextureUsages,
    data: Option<&[f32]>,
) -> wgpu::Texture {
    let desc = wgpu::TextureDescriptor {
        label: Some(label),
        size: wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage,
        view_formats: &[],
    };
    match data {
        Some(d) => bench.device.create_texture_with_data(
            bench.queue,
            &desc,
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(d),
        ),
        None => bench.device.create_texture(&desc),
    }
}

/// Runs `tasks` empty tasks on `ctx`, each applying the last cache allocation read-back.
fn empty_tasks(bench: &Bench, ctx: &ksrt::ExecuteContext, tasks: u32) -> AnyResult<()> {
    for _ in 0..tasks {
        let task = upload::submit(
            ctx,
            bench.device,
            bench.queue,
            ctx.create_task_container(),
            |_| {},
        )?;
        gpu::complete(ctx, bench.device, task)?;
    }
    Ok(())
}

/// Lets the pool grow until every instance's cache is full (at most 8 tasks); returns the
/// instances still coarse.
fn grow_pool(
    bench: &Bench,
    ctx: &ksrt::ExecuteContext,
    instances: &[ksrt::InstanceHandle],
) -> AnyResult<usize> {
    let mut degraded = usize::MAX;
    for _ in 0..8 {
        empty_tasks(bench, ctx, 1)?;
        degraded = 0;
        for h in instances {
            match ctx.lighting_cache_allocation(*h)? {
                Some(a) if a.level == ksrt::CacheLevel::Full => {}
                _ => degraded += 1,
            }
        }
        if degraded == 0 {
            break;
        }
    }
    Ok(degraded)
}

/// The injected image of the bench's view: world positions and exact N·L at the primary hits,
/// as textures, the view, and the exact value of each pixel with a surface.
struct InjectedImage {
    positions: wgpu::Texture,
    lighting: wgpu::Texture,
    view: ksrt::ViewInfo,
    exact: HashMap<usize, f32>,
}

impl InjectedImage {
    fn new(
        bench: &Bench,
        ctx: &ksrt::ExecuteContext,
        slots: &HashMap<u32, usize>,
        (scene, camera): (&Scene, &Camera),
        (width, height): (u32, u32),
    ) -> AnyResult<InjectedImage> {
        let dirs: Vec<Vec3> = (0..height)
            .flat_map(|y| (0..width).map(move |x| (x, y)))
            .map(|(x, y)| camera.primary_dir(x, y, width, height))
            .collect();
        let primary: Vec<ksrt::GpuRay> = dirs
            .iter()
            .map(|d| ksrt::GpuRay {
                origin: camera.eye.to_array(),
                t_min: 0.0,
                dir: d.to_array(),
                t_max: f32::INFINITY,
            })
            .collect();
        let (_, hits) = bench.trace(ctx, &primary, glue::Query::Closest)?;
        let light = LIGHT.normalize();
        let mut positions = vec![f32::NAN; dirs.len() * 4];
        let mut lighting = vec![0.0f32; dirs.len() * 4];
        let mut exact: HashMap<usize, f32> = HashMap::new();
        for (i, (h, d)) in hits.iter().zip(&dirs).enumerate() {
            if !h.is_hit() {
                continue;
            }
            let Some(s) = surface(scene, slots, h, *d) else {
                continue;
            };
            let e = s.normal.dot(light).max(0.0);
            positions[4 * i..4 * i + 4].copy_from_slice(&s.point.extend(1.0).to_array());
            lighting[4 * i..4 * i + 4].copy_from_slice(&[e, e, e, 1.0]);
            exact.insert(i, e);
        }
        let usage = wgpu::TextureUsages::TEXTURE_BINDING;
        let f32x4 = wgpu::TextureFormat::Rgba32Float;
        let size = (width, height);
        let (world_to_view, view_to_clip) = camera.matrices(
            width as f32 / height as f32,
            scene.size() * 1e-4,
            scene.size() * 10.0,
        );
        Ok(InjectedImage {
            positions: texture(
                bench,
                "ksrt bench positions",
                size,
                f32x4,
                usage,
                Some(&positions),
            ),
            lighting: texture(
                bench,
                "ksrt bench lighting",
                size,
                f32x4,
                usage,
                Some(&lighting),
            ),
            view: ksrt::ViewInfo {
                world_to_view,
                view_to_clip,
                prev_world_to_view: world_to_view,
                prev_view_to_clip: view_to_clip,
                jitter: glam::Vec2::ZERO,
            },
            exact,
        })
    }

    /// A `DirectLightingInjectionTask` of this image at `stride`.
    fn injection(&self, stride: u32) -> ksrt::RenderTask {
        let mut t = ksrt::DirectLightingInjectionTask::new(
            ksrt::DepthInput {
                texture: self.positions.create_view(&Default::default()),
                depth_type: ksrt::DepthType::RgbWorldSpace,
            },
            self.lighting.create_view(&Default::default()),
            self.view,
        );
        t.injection_resolution_stride = stride;
        ksrt::RenderTask::DirectLightingInjection(t)
    }
}

/// Measures the cache on `scene` seen from `camera` at `size`.
pub fn cache_bench(
    bench: &Bench,
    scene: &Scene,
    uploads: &[UploadedMesh],
    camera: &Camera,
    size: (u32, u32),
) -> AnyResult<CacheReport> {
    let (ctx, handles) = bench.registered(scene, uploads, false, true)?;
    // Let the pool grow until every cache is full (each task applies the last read-back).
    let degraded = grow_pool(bench, &ctx, &handles.instances)?;
    let surfel_bytes = handles
        .instances
        .iter()
        .filter_map(|h| ctx.lighting_cache_allocation(*h).ok().flatten())
        .map(|a| a.surfels as u64 * 16)
        .sum();
    let slots = handles.instance_of_slot();
    let image = InjectedImage::new(bench, &ctx, &slots, (scene, camera), size)?;

    // Injection time (a fresh context per stride is not needed: the time does not depend on the
    // cache's contents).
    let mut times = Vec::new();
    for stride in [1, 2, 4] {
        let stats = bench.repeat(|_| {
            let mut c = ctx.create_task_container();
            c.schedule_render_task(image.injection(stride));
            bench.timed(&ctx, c, &["injection"], |_| {})
        })?;
        times.push((stride, stats));
    }

    // Cache error, on a fresh context (the timing runs above injected many times).
    let (ctx, _) = bench.registered(scene, uploads, false, true)?;
    empty_tasks(bench, &ctx, 8)?;
    let error = cache_error(bench, &ctx, scene.size(), &image, size)?;
    Ok(CacheReport {
        surfel_bytes,
        cache_bytes: ctx.resource_allocations().cache,
        degraded_instances: degraded,
        injection: times,
        error,
    })
}

/// The cache's mean relative error against the exact lighting after 1, 8 and 64 injections of
/// `image` on `ctx`, read through the DirectLightingCache debug view.
fn cache_error(
    bench: &Bench,
    ctx: &ksrt::ExecuteContext,
    scene_size: f32,
    image: &InjectedImage,
    (width, height): (u32, u32),
) -> AnyResult<Vec<(u32, f64)>> {
    let usage = wgpu::TextureUsages::TEXTURE_BINDING;
    let out = texture(
        bench,
        "ksrt bench cache view",
        (width, height),
        wgpu::TextureFormat::Rgba32Float,
        wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC,
        None,
    );
    let unused_depth = texture(
        bench,
        "ksrt unused depth",
        (width, height),
        wgpu::TextureFormat::R32Float,
        usage,
        None,
    );
    let unused_normal = texture(
        bench,
        "ksrt unused normals",
        (width, height),
        wgpu::TextureFormat::Rgba8Unorm,
        usage,
        None,
    );
    let row = (width as u64 * 16).div_ceil(256) * 256;
    let readback = gpu::readback_buffer(bench.device, row * height as u64);
    let mut error = Vec::new();
    let mut done = 0;
    for tasks in [1u32, 8, 64] {
        while done < tasks {
            let mut c = ctx.create_task_container();
            c.schedule_render_task(image.injection(4));
            let task = upload::submit(ctx, bench.device, bench.queue, c, |_| {})?;
            gpu::complete(ctx, bench.device, task)?;
            done += 1;
        }
        let mut common = ksrt::TraceTaskCommon::new(
            ksrt::DepthInput {
                texture: unused_depth.create_view(&Default::default()),
                depth_type: ksrt::DepthType::RClipSpace,
            },
            ksrt::NormalInput {
                texture: unused_normal.create_view(&Default::default()),
                normal_type: ksrt::NormalType::RgbNormalizedVector,
                normal_to_world: glam::Mat4::IDENTITY,
            },
        );
        common.view = image.view;
        common.debug_parameters.debug_output_type = ksrt::DebugOutputType::DirectLightingCache;
        let mut c = ctx.create_task_container();
        c.schedule_render_task(ksrt::RenderTask::TraceAmbientOcclusion(
            ksrt::TraceAmbientOcclusionTask {
                common,
                output: out.create_view(&Default::default()),
                ao_radius: scene_size,
            },
        ));
        let task = upload::submit(ctx, bench.device, bench.queue, c, |e| {
            e.copy_texture_to_buffer(
                out.as_image_copy(),
                wgpu::TexelCopyBufferInfo {
                    buffer: &readback,
                    layout: wgpu::TexelCopyBufferLayout {
                        offset: 0,
                        bytes_per_row: Some(row as u32),
                        rows_per_image: Some(height),
                    },
                },
                out.size(),
            );
        })?;
        gpu::complete(ctx, bench.device, task)?;
        let bytes = gpu::map_read(bench.device, &readback)?;
        error.push((tasks, relative_error(&image.exact, &bytes, (width, row))));
    }
    Ok(error)
}

/// `Σ|cache − E| / ΣE` over the pixels of `exact`, the cache read from the `Rgba32Float` rows
/// of `bytes` (`row` bytes apart) of an image `width` wide.
fn relative_error(exact: &HashMap<usize, f32>, bytes: &[u8], (width, row): (u32, u64)) -> f64 {
    let (mut diff, mut sum) = (0.0f64, 0.0f64);
    for (&i, &e) in exact {
        let (x, y) = (i as u64 % width as u64, i as u64 / width as u64);
        let at = (y * row + x * 16) as usize;
        let c: [f32; 4] = bytemuck::pod_read_unaligned(&bytes[at..at + 16]);
        let mean = (c[0] + c[1] + c[2]) as f64 / 3.0;
        diff += (mean - e as f64).abs();
        sum += e as f64;
    }
    if sum > 0.0 {
        diff / sum
    } else {
        0.0
    }
}
