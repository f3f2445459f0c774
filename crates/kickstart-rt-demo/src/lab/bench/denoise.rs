//! `ksrt bench --denoisers`: the GPU time of every denoise task at `--size` (1920×1080 by
//! default) on synthetic inputs — a floor and a back wall seen by a perspective camera, noisy
//! radiance, occlusion and shadow inputs — with a history already accumulated (the steady
//! state of a frame). Each measurement is the span of the task's `denoise …` passes (GPU
//! timestamps). The targets on the H100: SpecularAndDiffuse ≤ 0.6 ms, Shadow ≤ 0.15 ms.

use crate::app::gpu;
use crate::lab::bench::busy::BusyGpu;
use crate::lab::bench::Stats;
use glam::{Mat4, Vec3};
use kickstart_rt as ksrt;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::sdk_glue as glue;
use kickstart_rt_renderer::upload;
use serde::Serialize;
use std::path::Path;

/// One denoiser's measurement.
#[derive(Debug, Clone, Serialize)]
pub struct DenoiserTime {
    /// The task (`DenoiseSpecularAndDiffuseTask`, …).
    pub task: String,
    /// `Fast` or `HighQuality`.
    pub method: String,
    /// GPU time of the task's passes.
    pub time: Stats,
    /// The task's time target on the H100, where it has one.
    pub target_ms: Option<f64>,
    /// Each of the task's passes in recording order: its label and median GPU time (the
    /// profile behind `time`, whose span also counts the gaps between passes).
    pub passes: Vec<PassTime>,
}

/// The median GPU time of one pass of a denoise task.
#[derive(Debug, Clone, Serialize)]
pub struct PassTime {
    /// The pass's label (`denoise temporal`, `denoise a-trous`, …).
    pub pass: String,
    /// Median over the timed frames, ms.
    pub median_ms: f64,
}

/// The `--json` report of `ksrt bench --denoisers`.
#[derive(Debug, Clone, Serialize)]
pub struct DenoiserReport {
    /// Adapter name.
    pub adapter: String,
    /// The commit `ksrt` was built from.
    pub commit: String,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Untimed GPU work before each timed task, ms (`--busy-gpu-ms`; 0: none).
    pub busy_gpu_ms: f64,
    /// Every task × method.
    pub denoisers: Vec<DenoiserTime>,
}

/// The synthetic G-buffer and signal textures.
struct Inputs {
    view: ksrt::ViewInfo,
    depth: wgpu::TextureView,
    normal: wgpu::TextureView,
    motion: wgpu::TextureView,
    signal: [wgpu::TextureView; 2],
    outputs: [wgpu::TextureView; 2],
}

fn texture(
    device: &wgpu::Device,
    format: wgpu::TextureFormat,
    (w, h): (u32, u32),
    usage: wgpu::TextureUsages,
) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("ksrt bench denoiser input"),
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
    })
}

fn upload(queue: &wgpu::Queue, t: &wgpu::Texture, bytes: &[u8], texel: u32) {
    queue.write_texture(
        t.as_image_copy(),
        bytes,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(t.width() * texel),
            rows_per_image: None,
        },
        t.size(),
    );
}

impl Inputs {
    fn new(device: &wgpu::Device, queue: &wgpu::Queue, (w, h): (u32, u32)) -> Self {
        let eye = Vec3::new(0.0, 1.6, 3.0);
        let world_to_view = Mat4::look_at_rh(eye, Vec3::new(0.0, 0.5, -1.0), Vec3::Y);
        let view_to_clip =
            Mat4::perspective_rh(60f32.to_radians(), w as f32 / h as f32, 0.1, 100.0);
        let clip = view_to_clip * world_to_view;
        let inv = clip.inverse();
        let n = (w * h) as usize;
        let mut depth = Vec::with_capacity(n);
        let mut normal = Vec::with_capacity(n * 4);
        let mut signal = Vec::with_capacity(n * 4);
        let mut rng = 0x1234_5678u32;
        let mut rand = || {
            rng ^= rng << 13;
            rng ^= rng >> 17;
            rng ^= rng << 5;
            rng as f32 / u32::MAX as f32
        };
        for y in 0..h {
            for x in 0..w {
                let ndc = glam::Vec2::new(
                    (x as f32 + 0.5) / w as f32 * 2.0 - 1.0,
                    1.0 - (y as f32 + 0.5) / h as f32 * 2.0,
                );
                let a = inv.project_point3(ndc.extend(0.0));
                let b = inv.project_point3(ndc.extend(0.5));
                let d = (b - a).normalize();
                // Floor y = 0 and wall z = −4.
                let t_floor = if d.y < 0.0 { -a.y / d.y } else { f32::INFINITY };
                let t_wall = if d.z < 0.0 {
                    (-4.0 - a.z) / d.z
                } else {
                    f32::INFINITY
                };
                let (t, nrm) = if t_floor < t_wall {
                    (t_floor, Vec3::Y)
                } else {
                    (t_wall, Vec3::Z)
                };
                if t.is_finite() {
                    depth.push(clip.project_point3(a + d * t).z);
                    normal.extend_from_slice(&[nrm.x, nrm.y, nrm.z, 0.0]);
                } else {
                    depth.push(1.0);
                    normal.extend_from_slice(&[0.0; 4]);
                }
                let k = 2.0 * rand();
                // Radiance × noise; alpha: a hit distance (shadow inputs read .r: negative is
                // lit, so about half the pixels are in shadow).
                signal.extend_from_slice(&[0.5 * k - 0.5, 0.4 * k, 0.3 * k, 1.0 + rand()]);
            }
        }
        let read = wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST;
        let depth_t = texture(device, wgpu::TextureFormat::R32Float, (w, h), read);
        upload(queue, &depth_t, bytemuck::cast_slice(&depth), 4);
        let normal_t = texture(device, wgpu::TextureFormat::Rgba32Float, (w, h), read);
        upload(queue, &normal_t, bytemuck::cast_slice(&normal), 16);
        let motion_t = texture(device, wgpu::TextureFormat::Rg32Float, (w, h), read);
        upload(queue, &motion_t, &vec![0u8; n * 8], 8);
        let signal_t = texture(device, wgpu::TextureFormat::Rgba32Float, (w, h), read);
        upload(queue, &signal_t, bytemuck::cast_slice(&signal), 16);
        let out = || {
            texture(
                device,
                wgpu::TextureFormat::Rgba16Float,
                (w, h),
                wgpu::TextureUsages::STORAGE_BINDING,
            )
            .create_view(&Default::default())
        };
        let view = |t: &wgpu::Texture| t.create_view(&Default::default());
        Inputs {
            view: ksrt::ViewInfo {
                world_to_view,
                view_to_clip,
                prev_world_to_view: world_to_view,
                prev_view_to_clip: view_to_clip,
                jitter: glam::Vec2::ZERO,
            },
            depth: view(&depth_t),
            normal: view(&normal_t),
            motion: view(&motion_t),
            signal: [view(&signal_t), view(&signal_t)],
            outputs: [out(), out()],
        }
    }

    fn task(
        &self,
        context: ksrt::DenoisingContextHandle,
        signal: ksrt::SignalType,
    ) -> ksrt::RenderTask {
        use ksrt::RenderTask as R;
        let common = ksrt::DenoiseTaskCommon {
            context,
            viewport: None,
            depth: ksrt::DepthInput {
                texture: self.depth.clone(),
                depth_type: ksrt::DepthType::RClipSpace,
            },
            normal: ksrt::NormalInput {
                texture: self.normal.clone(),
                normal_type: ksrt::NormalType::RgbVector,
                normal_to_world: Mat4::IDENTITY,
            },
            roughness: ksrt::RoughnessInput::default(),
            motion: Some(ksrt::MotionInput {
                texture: self.motion.clone(),
                motion_type: ksrt::MotionType::RgViewSpace,
                scale: Vec3::ONE,
            }),
            view: self.view,
            half_resolution_mode: ksrt::HalfResolutionMode::Off,
            mode: ksrt::DenoiseMode::Continue,
        };
        let (input, output) = (self.signal[0].clone(), self.outputs[0].clone());
        match signal {
            ksrt::SignalType::Specular => R::DenoiseSpecular(ksrt::DenoiseSpecularTask {
                common,
                input,
                output,
            }),
            ksrt::SignalType::Diffuse => R::DenoiseDiffuse(ksrt::DenoiseDiffuseTask {
                common,
                input,
                output,
            }),
            ksrt::SignalType::SpecularAndDiffuse => {
                R::DenoiseSpecularAndDiffuse(ksrt::DenoiseSpecularAndDiffuseTask {
                    common,
                    input_specular: input,
                    input_diffuse: self.signal[1].clone(),
                    output_specular: output,
                    output_diffuse: self.outputs[1].clone(),
                })
            }
            ksrt::SignalType::DiffuseOcclusion => {
                R::DenoiseDiffuseOcclusion(ksrt::DenoiseDiffuseOcclusionTask {
                    common,
                    input,
                    output,
                })
            }
            ksrt::SignalType::Shadow => R::DenoiseShadow(ksrt::DenoiseShadowTask {
                common,
                input,
                output,
            }),
            ksrt::SignalType::MultiShadow => R::DenoiseMultiShadow(ksrt::DenoiseMultiShadowTask {
                common,
                input0: input.clone(),
                input1: input,
                output,
            }),
        }
    }
}

const SIGNALS: [(ksrt::SignalType, Option<f64>); 6] = [
    (ksrt::SignalType::SpecularAndDiffuse, Some(0.6)),
    (ksrt::SignalType::Specular, None),
    (ksrt::SignalType::Diffuse, None),
    (ksrt::SignalType::DiffuseOcclusion, None),
    (ksrt::SignalType::Shadow, Some(0.15)),
    (ksrt::SignalType::MultiShadow, None),
];

/// Runs the denoiser benchmark; `busy_gpu_ms` > 0 submits that much untimed GPU work before
/// each timed task (`--busy-gpu-ms`: in a frame the denoisers follow the traces, so they run at
/// a busy GPU's clocks, not the lower ones an idle GPU drops to between repetitions).
pub fn run(
    size: (u32, u32),
    iterations: u32,
    busy_gpu_ms: f64,
    json: Option<&Path>,
) -> AnyResult<()> {
    let adapter = gpu::adapter()?;
    if !adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY) {
        return Err("the adapter has no TIMESTAMP_QUERY: GPU times cannot be measured".into());
    }
    let (device, queue) = gpu::device(&adapter)?;
    let ctx =
        ksrt::ExecuteContext::new(&device, &queue, crate::app::gpu::init_settings_timed(true))?;
    glue::prepare_pipelines(&ctx)?;
    let inputs = Inputs::new(&device, &queue, size);
    let busy = (busy_gpu_ms > 0.0).then(|| BusyGpu::new(&device, busy_gpu_ms));
    let info = adapter.get_info();
    println!(
        "kickstart-rt {} (commit {}) denoisers at {}x{} on {}, {iterations} iterations after a warm-up",
        ksrt::VERSION,
        env!("KSRT_COMMIT"),
        size.0,
        size.1,
        info.name
    );
    if busy.is_some() {
        println!("each timed task follows ~{busy_gpu_ms} ms of untimed GPU work (--busy-gpu-ms)");
    }
    let mut report = DenoiserReport {
        adapter: info.name.clone(),
        commit: env!("KSRT_COMMIT").to_string(),
        width: size.0,
        height: size.1,
        busy_gpu_ms,
        denoisers: Vec::new(),
    };
    for method in [
        ksrt::DenoisingMethod::Fast,
        ksrt::DenoisingMethod::HighQuality,
    ] {
        for (signal, target_ms) in SIGNALS {
            let handle = ctx.create_denoising_context_handle(ksrt::DenoisingContextInput {
                max_width: size.0,
                max_height: size.1,
                signal_type: signal,
                method,
            })?;
            let task = inputs.task(handle, signal);
            let name = task.name().to_string();
            let one = || -> AnyResult<(f64, Vec<(&'static str, f64)>)> {
                let mut c = ctx.create_task_container();
                c.schedule_render_task(task.clone());
                if let Some(busy) = &busy {
                    busy.submit(&device, &queue);
                }
                let t = upload::submit(&ctx, &device, &queue, c, |_| {})?;
                let timings = ctx.wait_for_gpu_timings(t);
                gpu::complete(&ctx, &device, t)?;
                let timings = timings?;
                let span = glue::span_ms(&timings, &["denoise"])?;
                let passes = timings
                    .passes
                    .iter()
                    .filter(|p| p.label.starts_with("denoise"))
                    .map(|p| (p.pass, p.ms))
                    .collect();
                Ok((span, passes))
            };
            // Warm-up (clocks up, history accumulated), then the timed frames.
            let start = std::time::Instant::now();
            while start.elapsed() < std::time::Duration::from_millis(500) {
                one()?;
            }
            let runs = (0..iterations)
                .map(|_| one())
                .collect::<AnyResult<Vec<_>>>()?;
            let passes = pass_medians(runs.iter().map(|(_, p)| p.as_slice()));
            let time = Stats::new(runs.into_iter().map(|(ms, _)| ms).collect());
            println!(
                "  {name:<32} {method:<12?} median {:.3} ms (min {:.3}, max {:.3}){}",
                time.median_ms,
                time.min_ms,
                time.max_ms,
                target_ms.map_or(String::new(), |t| format!("  target ≤ {t} ms"))
            );
            let profile: Vec<String> = passes
                .iter()
                .map(|p| {
                    format!(
                        "{} {:.3}",
                        p.pass.trim_start_matches("denoise "),
                        p.median_ms
                    )
                })
                .collect();
            println!("      passes: {}", profile.join(" | "));
            report.denoisers.push(DenoiserTime {
                task: name,
                method: format!("{method:?}"),
                time,
                target_ms,
                passes,
            });
            ctx.destroy_denoising_context_handle(handle)?;
        }
    }
    if let Some(path) = json {
        std::fs::write(path, serde_json::to_string_pretty(&report)?)
            .map_err(|e| format!("--json {}: cannot write: {e}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}

/// Per pass (by position in recording order), the median of its time over `runs` (every run
/// records the same passes).
fn pass_medians<'a>(runs: impl Iterator<Item = &'a [(&'static str, f64)]>) -> Vec<PassTime> {
    let runs: Vec<_> = runs.collect();
    let Some(first) = runs.first() else {
        return Vec::new();
    };
    (0..first.len())
        .map(|i| {
            let mut ms: Vec<f64> = runs.iter().filter_map(|r| r.get(i).map(|p| p.1)).collect();
            ms.sort_by(f64::total_cmp);
            PassTime {
                pass: first[i].0.to_string(),
                median_ms: ms[ms.len() / 2],
            }
        })
        .collect()
}
