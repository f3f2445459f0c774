//! Each frame's SDK work for a camera, recorded into Bevy's encoder, and the bookkeeping that
//! tells the SDK when the GPU finished it.

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use bevy::core_pipeline::prepass::ViewPrepassTextures;
use bevy::prelude::*;
use bevy::render::camera::ExtractedCamera;
use bevy::render::renderer::{RenderContext, RenderDevice, RenderQueue, ViewQuery};
use bevy::render::view::{ExtractedView, ViewTarget};
use kickstart_rt as ksrt;

use crate::RayTracedLighting;
use crate::composite::{Composite, CompositeInputs, CompositeParams};
use crate::gbuffer::Unpack;
use crate::scene::{ExtractedScene, Sun};
use crate::sdk::{SdkContext, SdkTimings};
use crate::view::ViewResources;

/// Frames Bevy may have submitted and the GPU not finished before the plugin waits.
const MAX_FRAMES_IN_FLIGHT: usize = 3;

/// SDK tasks recorded and not yet known finished.
#[derive(Resource, Default)]
pub(crate) struct FramesInFlight {
    /// Recorded this frame (submitted by Bevy at the end of its render systems).
    recorded: Vec<ksrt::GpuTaskHandle>,
    /// Submitted: each frame's tasks, and a flag the queue sets once that frame's work is done.
    submitted: VecDeque<(Vec<ksrt::GpuTaskHandle>, Arc<AtomicBool>)>,
}

/// After Bevy submitted the frame: asks the queue to report when its work is done.
pub(crate) fn track_submitted_frames(mut frames: ResMut<FramesInFlight>, queue: Res<RenderQueue>) {
    if frames.recorded.is_empty() {
        return;
    }
    let tasks = std::mem::take(&mut frames.recorded);
    let done = Arc::new(AtomicBool::new(false));
    let flag = done.clone();
    queue.on_submitted_work_done(move || flag.store(true, Ordering::Release));
    frames.submitted.push_back((tasks, done));
}

/// Tells the SDK which frames the GPU finished (so it can reuse their memory), reading their
/// GPU timings when asked to; waits when too many are outstanding.
pub(crate) fn retire_finished_frames(
    mut frames: ResMut<FramesInFlight>,
    sdk: Res<SdkContext>,
    device: Res<RenderDevice>,
    timings: Res<SdkTimings>,
) {
    let wait = frames.submitted.len() >= MAX_FRAMES_IN_FLIGHT;
    let poll = if wait {
        wgpu::PollType::wait_indefinitely()
    } else {
        wgpu::PollType::Poll
    };
    if let Err(e) = device.wgpu_device().poll(poll) {
        warn!("kickstart-rt: polling the device: {e}");
    }
    while let Some((tasks, done)) = frames.submitted.front() {
        if !done.load(Ordering::Acquire) {
            break;
        }
        for task in tasks {
            if sdk.timing {
                match sdk.ctx.wait_for_gpu_timings(*task) {
                    Ok(t) => timings.set(&t),
                    Err(e) => warn!("kickstart-rt: GPU timings: {e}"),
                }
            }
            if let Err(e) = sdk.ctx.mark_gpu_task_completed(*task) {
                warn!("kickstart-rt: {e}");
            }
        }
        frames.submitted.pop_front();
    }
}

type LightingView = (
    &'static ExtractedView,
    &'static ExtractedCamera,
    &'static ViewTarget,
    &'static ViewPrepassTextures,
    &'static RayTracedLighting,
    &'static mut ViewResources,
    &'static Msaa,
);

/// The Core3d system: after Bevy's deferred lighting, unpack the G-buffer, inject Bevy's lit
/// image into the lighting cache, trace and denoise the camera's effects, and composite them
/// into the view target.
#[allow(clippy::too_many_arguments)]
pub(crate) fn ray_traced_lighting(
    view: ViewQuery<LightingView>,
    sdk: Res<SdkContext>,
    unpack: Res<Unpack>,
    composite: Res<Composite>,
    scene: Res<ExtractedScene>,
    mut frames: ResMut<FramesInFlight>,
    device: Res<RenderDevice>,
    mut ctx: RenderContext,
) {
    let (extracted, camera, target, prepass, settings, mut resources, msaa) = view.into_inner();
    if *msaa != Msaa::Off {
        if !resources.warned_msaa {
            error!(
                "kickstart-rt: a RayTracedLighting camera has {msaa:?}; Bevy's deferred renderer \
                 needs Msaa::Off on the camera, so this camera is not ray traced"
            );
            resources.warned_msaa = true;
        }
        return;
    }
    let (Some(deferred), Some(depth), Some(motion)) = (
        prepass.deferred_view(),
        prepass.depth_only_view(),
        prepass.motion_vectors_view(),
    ) else {
        debug!("kickstart-rt: a prepass texture is missing; skipping the view");
        return;
    };
    let device = device.wgpu_device();
    let resources = &mut *resources;
    debug!(
        "kickstart-rt: frame {} of a {} view",
        resources.frame, resources.size
    );
    if target.main_texture().size() != size_of(resources.size) {
        // Resized this frame; the resources follow next frame.
        return;
    }

    let world_to_view = extracted.world_from_view.to_matrix().inverse();
    let view_to_clip = extracted.clip_from_view;
    let (prev_world_to_view, prev_view_to_clip) =
        resources.previous.unwrap_or((world_to_view, view_to_clip));
    let view_info = ksrt::ViewInfo {
        world_to_view: to_sdk(world_to_view),
        view_to_clip: to_sdk(view_to_clip),
        prev_world_to_view: to_sdk(prev_world_to_view),
        prev_view_to_clip: to_sdk(prev_view_to_clip),
        jitter: glam::Vec2::ZERO,
    };
    // History is dropped on the first frame and for an effect toggled on.
    let restart = |on: bool, was: Option<bool>| resources.frame == 0 || (on && was != Some(true));
    let last = resources.last_settings.clone();
    let fresh = [
        restart(settings.reflections, last.as_ref().map(|l| l.reflections)),
        restart(settings.gi, last.as_ref().map(|l| l.gi)),
        restart(settings.ao, last.as_ref().map(|l| l.ao)),
        restart(settings.shadows, last.as_ref().map(|l| l.shadows)),
    ];

    let encoder = ctx.command_encoder();
    unpack.record(device, encoder, deferred, resources);

    let post = target.post_process_write();
    let inputs = SdkInputs {
        depth,
        motion,
        lit: post.source,
        view: view_info,
    };
    let container = tasks(&sdk.ctx, settings, scene.sun, resources, &inputs, fresh);
    match sdk.ctx.build_gpu_task(container, encoder) {
        Ok(task) => frames.recorded.push(task),
        Err(e) => {
            error!("kickstart-rt: this frame's ray-traced lighting was not recorded: {e}");
        }
    }

    let params = composite_params(extracted, camera, settings, scene.sun, resources.frame);
    let signals = if settings.denoise {
        &resources.denoised
    } else {
        &resources.traced
    };
    composite.record(
        device,
        encoder,
        CompositeInputs {
            lit: post.source,
            depth,
            signals,
        },
        resources,
        &params,
        post.destination,
        target.main_texture_format(),
    );

    resources.previous = Some((world_to_view, view_to_clip));
    resources.last_settings = Some(settings.clone());
    resources.frame = resources.frame.wrapping_add(1).max(1);
}

/// Bevy's views of this frame that the SDK's tasks read.
struct SdkInputs<'a> {
    depth: &'a wgpu::TextureView,
    motion: &'a wgpu::TextureView,
    lit: &'a wgpu::TextureView,
    view: ksrt::ViewInfo,
}

/// The traced-pixel mode of each effect this frame (reflections, GI, AO, shadow): the camera's
/// preset's, its phase following the frame; the same for a trace and its denoiser.
pub(crate) fn rates(settings: &RayTracedLighting, frame: u32) -> [ksrt::HalfResolutionMode; 4] {
    [
        ksrt::Effect::Specular,
        ksrt::Effect::Diffuse,
        ksrt::Effect::AmbientOcclusion,
        ksrt::Effect::Shadow,
    ]
    .map(|effect| settings.preset.half_resolution_mode(effect, frame))
}

/// The camera's SDK tasks: injection, then each enabled effect's trace and denoiser.
fn tasks(
    ctx: &ksrt::ExecuteContext,
    settings: &RayTracedLighting,
    sun: Option<Sun>,
    r: &ViewResources,
    inputs: &SdkInputs,
    fresh: [bool; 4],
) -> ksrt::TaskContainer {
    let depth = || ksrt::DepthInput {
        texture: inputs.depth.clone(),
        depth_type: ksrt::DepthType::RClipSpace,
    };
    let normal = || ksrt::NormalInput {
        texture: r.normal_roughness.clone(),
        normal_type: ksrt::NormalType::RgbVector,
        normal_to_world: glam::Mat4::IDENTITY,
    };
    let mut c = ctx.create_task_container();
    // Bevy's lit image at this point holds Bevy's own light only (the composite comes after).
    let mut injection =
        ksrt::DirectLightingInjectionTask::new(depth(), inputs.lit.clone(), inputs.view);
    injection.injection_resolution_stride = settings.preset.injection_resolution_stride();
    c.schedule_render_task(ksrt::RenderTask::DirectLightingInjection(injection));
    let mut common = ksrt::TraceTaskCommon::new(depth(), normal());
    common.roughness.texture = Some(r.normal_roughness.clone());
    common.specular.texture = Some(r.specular.clone());
    common.direct_lighting = Some(inputs.lit.clone());
    common.view = inputs.view;
    common.ray_offset.offset_type = ksrt::RayOffsetType::CamDistance;
    common.debug_parameters.frame_index = r.frame;
    let rates = rates(settings, r.frame);
    let denoise = |i: usize| ksrt::DenoiseTaskCommon {
        context: r.denoisers[i],
        viewport: None,
        depth: depth(),
        normal: normal(),
        roughness: ksrt::RoughnessInput {
            texture: Some(r.normal_roughness.clone()),
            ..Default::default()
        },
        // Bevy's motion vectors are current UV − previous UV.
        motion: Some(ksrt::MotionInput {
            texture: inputs.motion.clone(),
            motion_type: ksrt::MotionType::RgViewSpace,
            scale: glam::Vec3::new(-1.0, -1.0, 0.0),
        }),
        view: inputs.view,
        half_resolution_mode: rates[i],
        mode: if fresh[i] {
            ksrt::DenoiseMode::DiscardHistory
        } else {
            ksrt::DenoiseMode::Continue
        },
    };
    let at_rate = |i: usize| ksrt::TraceTaskCommon {
        half_resolution_mode: rates[i],
        ..common.clone()
    };
    for trace in trace_tasks(settings, sun, r, at_rate).into_iter().flatten() {
        c.schedule_render_task(trace);
    }
    if settings.denoise {
        let on = [
            settings.reflections,
            settings.gi,
            settings.ao,
            settings.shadows && sun.is_some(),
        ];
        for i in (0..4).filter(|i| on[*i]) {
            c.schedule_render_task(denoise_task(i, denoise(i), r));
        }
    }
    c
}

/// The denoise task of effect `i` (reflections, GI, AO, shadow): its raw trace into its
/// denoised texture.
fn denoise_task(i: usize, common: ksrt::DenoiseTaskCommon, r: &ViewResources) -> ksrt::RenderTask {
    let (input, output) = (r.traced[i].clone(), r.denoised[i].clone());
    match i {
        0 => ksrt::RenderTask::DenoiseSpecular(ksrt::DenoiseSpecularTask {
            common,
            input,
            output,
        }),
        1 => ksrt::RenderTask::DenoiseDiffuse(ksrt::DenoiseDiffuseTask {
            common,
            input,
            output,
        }),
        2 => ksrt::RenderTask::DenoiseDiffuseOcclusion(ksrt::DenoiseDiffuseOcclusionTask {
            common,
            input,
            output,
        }),
        _ => ksrt::RenderTask::DenoiseShadow(ksrt::DenoiseShadowTask {
            common,
            input,
            output,
        }),
    }
}

/// The trace task of each effect on (reflections, GI, AO, shadow), `at_rate(i)` its inputs.
/// With GI and AO both on at one rate, the AO comes from the diffuse rays (one traversal for
/// both, as `ksrt` does): the AO slot is then empty, and the GI task writes the AO output.
fn trace_tasks(
    settings: &RayTracedLighting,
    sun: Option<Sun>,
    r: &ViewResources,
    at_rate: impl Fn(usize) -> ksrt::TraceTaskCommon,
) -> [Option<ksrt::RenderTask>; 4] {
    let out = |i: usize| r.traced[i].clone();
    let ao_from_diffuse = settings.ao
        && settings.gi
        && at_rate(1).half_resolution_mode == at_rate(2).half_resolution_mode;
    let reflections = settings.reflections.then(|| {
        ksrt::RenderTask::TraceSpecular(ksrt::TraceSpecularTask {
            common: at_rate(0),
            output: out(0),
            demodulate_specular: false,
            demodulation_output: None,
        })
    });
    let gi = settings.gi.then(|| {
        ksrt::RenderTask::TraceDiffuse(ksrt::TraceDiffuseTask {
            common: at_rate(1),
            output: out(1),
            diffuse_brdf: ksrt::DiffuseBrdf::Lambertian,
            ambient_occlusion: ao_from_diffuse.then(|| ksrt::DiffuseAmbientOcclusion {
                output: out(2),
                ao_radius: settings.ao_radius,
            }),
        })
    });
    let ao = (settings.ao && !ao_from_diffuse).then(|| {
        ksrt::RenderTask::TraceAmbientOcclusion(ksrt::TraceAmbientOcclusionTask {
            common: at_rate(2),
            output: out(2),
            ao_radius: settings.ao_radius,
        })
    });
    let shadow = match (settings.shadows, sun) {
        (true, Some(sun)) => Some(ksrt::RenderTask::TraceShadow(ksrt::TraceShadowTask {
            common: at_rate(3),
            output: out(3),
            light: ksrt::LightInfo::Directional {
                direction: -glam::Vec3::from_array(sun.to_light.to_array()),
                angular_extent: settings.sun_angular_diameter,
            },
            enable_first_hit_and_end_search: true,
        })),
        _ => None,
    };
    [reflections, gi, ao, shadow]
}
/// The composite's uniforms for this view.
fn composite_params(
    view: &ExtractedView,
    camera: &ExtractedCamera,
    settings: &RayTracedLighting,
    sun: Option<Sun>,
    frame: u32,
) -> CompositeParams {
    let clip_from_world = view.clip_from_view * view.world_from_view.to_matrix().inverse();
    let (to_sun, sun_radiance) = match sun {
        Some(s) => (
            s.to_light.extend(1.0),
            (s.illuminance * camera.exposure).extend(0.0),
        ),
        None => (Vec4::ZERO, Vec4::ZERO),
    };
    CompositeParams {
        world_from_clip: clip_from_world.inverse().to_cols_array_2d(),
        camera: view.world_from_view.translation().extend(1.0).to_array(),
        to_sun: to_sun.to_array(),
        sun: sun_radiance.to_array(),
        effects: [
            u32::from(settings.reflections),
            u32::from(settings.gi),
            u32::from(settings.ao),
            // 2: denoising is off and the shadow texture holds the raw trace (the occluder's
            // distance, negative where the sun is visible), not visibility.
            match (settings.shadows && sun.is_some(), settings.denoise) {
                (false, _) => 0,
                (true, true) => 1,
                (true, false) => 2,
            },
        ],
        // The denoisers fill every pixel; a raw trace at a reduced rate holds this frame's
        // values only in each block's traced pixel (the rest are older frames').
        traced_pixels: if settings.denoise {
            [traced_pixel_code(ksrt::HalfResolutionMode::Off); 4]
        } else {
            rates(settings, frame).map(traced_pixel_code)
        },
    }
}

/// `mode`'s block as the composite reads it: the block's side (bits 0–7), and its traced
/// pixel's x (8–15) and y (16–23).
fn traced_pixel_code(mode: ksrt::HalfResolutionMode) -> u32 {
    let (x, y) = mode.traced_pixel();
    mode.block_size() | (x << 8) | (y << 16)
}

fn size_of(size: UVec2) -> wgpu::Extent3d {
    wgpu::Extent3d {
        width: size.x,
        height: size.y,
        depth_or_array_layers: 1,
    }
}

/// Bevy's and the SDK's glam may be different versions: convert through arrays.
fn to_sdk(m: Mat4) -> glam::Mat4 {
    glam::Mat4::from_cols_array(&m.to_cols_array())
}
