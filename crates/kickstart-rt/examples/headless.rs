//! One frame of ray-traced ambient occlusion and sun shadow, without a window, written to a PNG.
//!
//! ```sh
//! cargo run -p kickstart-rt --example headless -- [OUT.png]   # default: headless.png
//! ```
//!
//! The steps an engine takes, in order: a device with the SDK's features, an `ExecuteContext`,
//! the scene registered (meshes → BLASes, instances → TLAS), a G-buffer rendered as usual, then
//! one task container with the trace tasks and their denoisers recorded into the frame's
//! encoder. The example then checks its own image (darker AO where the box meets the floor, the
//! box's shadow on the floor) and exits with an error when it is wrong, so CI catches a
//! regression.

mod common;

use common::{gbuffer::GBuffer, AnyResult, Camera};
use glam::Vec3;
use kickstart_rt as ksrt;

const SIZE: (u32, u32) = (320, 240);
/// Direction the sunlight travels: from the upper left, casting the shadow back and right.
const SUN: Vec3 = Vec3::new(0.8, -1.0, -0.5);

fn main() {
    if let Err(e) = run() {
        eprintln!("headless: {e}");
        std::process::exit(1);
    }
}

fn run() -> AnyResult<()> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "headless.png".into());
    let (_adapter, device, queue) = common::device(&common::instance(None), None)?;
    let ctx = ksrt::ExecuteContext::new(&device, &queue, ksrt::InitSettings::default())?;
    let scene = common::register_scene(&device, &ctx, common::box_on_plane([]))?;

    // The engine's own G-buffer pass, recorded into the frame's encoder.
    let camera = Camera {
        eye: Vec3::new(3.0, 2.5, 4.0),
        target: Vec3::new(0.0, 0.3, 0.0),
        fov_y: 50f32.to_radians(),
        aspect: SIZE.0 as f32 / SIZE.1 as f32,
    };
    let gbuffer = GBuffer::new(&device, SIZE);
    let mut encoder = device.create_command_encoder(&Default::default());
    gbuffer.render(&queue, &mut encoder, &scene, &camera, &camera, SUN);

    // Where the SDK writes: the raw traces and the denoised ones.
    let texture = |label| common::output_texture(&device, label, SIZE);
    let (ao, ao_denoised) = (texture("ao"), texture("ao denoised"));
    let (shadow, shadow_denoised) = (texture("shadow"), texture("shadow denoised"));
    let v = |t: &wgpu::Texture| t.create_view(&Default::default());
    // A denoising context per signal holds its history between frames.
    let denoiser = |signal_type| {
        ctx.create_denoising_context_handle(ksrt::DenoisingContextInput {
            max_width: SIZE.0,
            max_height: SIZE.1,
            signal_type,
            method: Default::default(),
        })
    };
    let ao_context = denoiser(ksrt::SignalType::DiffuseOcclusion)?;
    let shadow_context = denoiser(ksrt::SignalType::Shadow)?;

    // One container: the traces, then their denoisers (which read the traces' outputs).
    let view = camera.view_info(&camera);
    let common = gbuffer.trace_common(view, 0);
    let mut tasks = ctx.create_task_container();
    tasks.schedule_render_task(ksrt::RenderTask::TraceAmbientOcclusion(
        ksrt::TraceAmbientOcclusionTask {
            common: common.clone(),
            output: v(&ao),
            ao_radius: 1.0,
        },
    ));
    tasks.schedule_render_task(ksrt::RenderTask::TraceShadow(ksrt::TraceShadowTask {
        common,
        output: v(&shadow),
        light: ksrt::LightInfo::Directional {
            direction: SUN.normalize(),
            angular_extent: 2f32.to_radians(),
        },
        enable_first_hit_and_end_search: true,
    }));
    tasks.schedule_render_task(ksrt::RenderTask::DenoiseDiffuseOcclusion(
        ksrt::DenoiseDiffuseOcclusionTask {
            common: gbuffer.denoise_common(ao_context, view, true),
            input: v(&ao),
            output: v(&ao_denoised),
        },
    ));
    tasks.schedule_render_task(ksrt::RenderTask::DenoiseShadow(ksrt::DenoiseShadowTask {
        common: gbuffer.denoise_common(shadow_context, view, true),
        input: v(&shadow),
        output: v(&shadow_denoised),
    }));
    // Records into our encoder; the SDK never submits or waits by itself.
    let task = ctx.build_gpu_task(tasks, &mut encoder)?;
    queue.submit([encoder.finish()]);

    // Reading back waits for the GPU; then the SDK may recycle the task's memory.
    let ao = common::read_rgba16f(&device, &queue, &ao_denoised)?;
    let shadow = common::read_rgba16f(&device, &queue, &shadow_denoised)?;
    let normal = common::read_rgba16f(&device, &queue, &gbuffer.normal)?;
    ctx.mark_gpu_task_completed(task)?;

    write_png(&out, &ao, &shadow, &normal)?;
    println!("wrote {out}");
    check(&camera, &ao, &shadow, &normal)
}

/// A simple composite on the CPU: sky where nothing was drawn, else
/// AO × (ambient + visible sun × n·l), gamma-encoded.
fn write_png(
    out: &str,
    ao: &[[f32; 4]],
    shadow: &[[f32; 4]],
    normal: &[[f32; 4]],
) -> AnyResult<()> {
    let to_sun = -SUN.normalize();
    let mut img = image::RgbImage::new(SIZE.0, SIZE.1);
    for (i, px) in img.pixels_mut().enumerate() {
        let n = normal[i];
        let rgb = if n[3] == 0.0 {
            Vec3::new(0.45, 0.6, 0.85)
        } else {
            let n_dot_l = Vec3::new(n[0], n[1], n[2]).dot(to_sun).max(0.0);
            Vec3::splat(ao[i][0] * (0.25 + 0.75 * shadow[i][0] * n_dot_l))
        };
        let encode = |c: f32| (c.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0).round() as u8;
        *px = image::Rgb([encode(rgb.x), encode(rgb.y), encode(rgb.z)]);
    }
    img.save(out).map_err(|e| format!("writing {out}: {e}"))?;
    Ok(())
}

/// Checks the image where the answer is known: AO is darker where the box's front face meets
/// the floor than on open floor, and the floor behind the box (away from the sun) is in shadow
/// while open floor is lit.
fn check(
    camera: &Camera,
    ao: &[[f32; 4]],
    shadow: &[[f32; 4]],
    normal: &[[f32; 4]],
) -> AnyResult<()> {
    // The mean of channel R over 5 × 5 pixels around the pixel showing `p`.
    let mean = |img: &[[f32; 4]], p: Vec3| -> AnyResult<f32> {
        let (x, y) = camera.pixel_of(p, SIZE.0, SIZE.1);
        let mut sum = 0.0;
        for yy in y.saturating_sub(2)..=y + 2 {
            for xx in x.saturating_sub(2)..=x + 2 {
                let i = (yy.min(SIZE.1 - 1) * SIZE.0 + xx.min(SIZE.0 - 1)) as usize;
                if normal[i][3] == 0.0 {
                    return Err(format!("no surface drawn at pixel ({xx}, {yy}) of {p}").into());
                }
                sum += img[i][0];
            }
        }
        Ok(sum / 25.0)
    };
    // The box is turned 30° about y: its +z face looks along (sin 30°, 0, cos 30°).
    let front = Vec3::new(0.5, 0.0, 0.866);
    let contact = front * 0.56; // on the floor, 6 cm in front of that face
    let open = Vec3::new(-1.0, 0.0, 2.0); // open floor, lit, 2 m from the box
    let shadowed = Vec3::new(0.72, 0.0, -0.45); // where the box's centre casts its shadow
    let (ao_contact, ao_open) = (mean(ao, contact)?, mean(ao, open)?);
    let (lit, dark) = (mean(shadow, open)?, mean(shadow, shadowed)?);
    println!("AO: {ao_contact:.2} at the box's foot, {ao_open:.2} on open floor (1 = open)");
    println!("sun visibility: {lit:.2} on open floor, {dark:.2} behind the box (1 = lit)");
    if ao_contact > ao_open - 0.1 {
        return Err("wrong image: AO at the box's foot is not darker than on open floor".into());
    }
    if lit < 0.8 || dark > 0.2 {
        return Err("wrong image: the box's shadow is not where the sun casts it".into());
    }
    Ok(())
}
