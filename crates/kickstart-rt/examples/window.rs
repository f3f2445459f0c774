//! A winit window with every effect: reflections, diffuse GI (through the direct lighting
//! cache), ambient occlusion and sun shadow, each denoised, composited on screen while the
//! camera circles the scene.
//!
//! ```sh
//! cargo run -p kickstart-rt --example window                 # until the window is closed
//! xvfb-run -a cargo run -p kickstart-rt --example window -- --frames 3   # CI: exits after 3
//! ```
//!
//! Each frame is one task container, in the order the integration guide gives: inject the
//! frame's direct light into the lighting cache, trace, denoise. The SDK records into the
//! frame's encoder and never waits; the example tells it when the GPU finished a frame
//! (`mark_gpu_task_completed`), with up to two frames in flight.

mod common;

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use common::composite::{Composite, Lighting};
use common::{gbuffer::GBuffer, AnyResult, Camera, Placement, Shape};
use glam::{Affine3A, Vec3};
use kickstart_rt as ksrt;
use winit::application::ApplicationHandler;
use winit::event::WindowEvent;
use winit::event_loop::{ActiveEventLoop, EventLoop};
use winit::window::{Window, WindowId};

/// Direction the sunlight travels.
const SUN: Vec3 = Vec3::new(0.8, -1.0, -0.5);
const FRAMES_IN_FLIGHT: usize = 2;

fn main() {
    if let Err(e) = run() {
        eprintln!("window: {e}");
        std::process::exit(1);
    }
}

fn run() -> AnyResult<()> {
    let mut args = std::env::args().skip(1);
    let mut frames = None;
    while let Some(arg) = args.next() {
        match (arg.as_str(), args.next().map(|n| n.parse::<u32>())) {
            ("--frames", Some(Ok(n))) => frames = Some(n),
            _ => return Err("usage: window [--frames N]".into()),
        }
    }
    let event_loop = EventLoop::new()
        .map_err(|e| format!("cannot open a window ({e}); is there a display (or Xvfb)?"))?;
    let mut app = App {
        frames,
        gpu: None,
        error: None,
    };
    event_loop.run_app(&mut app)?;
    app.error.map_or(Ok(()), |e| Err(e.into()))
}

struct App {
    /// Exit after this many frames (`--frames N`).
    frames: Option<u32>,
    gpu: Option<Gpu>,
    error: Option<String>,
}

/// Everything that lives as long as the window.
struct Gpu {
    window: Arc<Window>,
    surface: wgpu::Surface<'static>,
    device: wgpu::Device,
    queue: wgpu::Queue,
    ctx: ksrt::ExecuteContext,
    scene: common::Scene,
    gbuffer: GBuffer,
    outputs: Outputs,
    /// Denoising contexts: specular + diffuse, AO, shadow.
    denoisers: [ksrt::DenoisingContextHandle; 3],
    composite: Composite,
    frame: u32,
    prev_camera: Camera,
    /// Submitted GPU tasks, and whether the GPU has finished each.
    in_flight: VecDeque<(ksrt::GpuTaskHandle, Arc<AtomicBool>)>,
}

/// The SDK's output textures: raw traces and denoised.
struct Outputs {
    specular: wgpu::Texture,
    diffuse: wgpu::Texture,
    ao: wgpu::Texture,
    shadow: wgpu::Texture,
    specular_denoised: wgpu::Texture,
    diffuse_denoised: wgpu::Texture,
    ao_denoised: wgpu::Texture,
    shadow_denoised: wgpu::Texture,
}

impl Gpu {
    fn new(event_loop: &ActiveEventLoop) -> AnyResult<Gpu> {
        let attributes = Window::default_attributes()
            .with_title("kickstart-rt window example")
            .with_inner_size(winit::dpi::PhysicalSize::new(640, 360))
            // A fixed size keeps the example short: the G-buffer and outputs are made once.
            .with_resizable(false);
        let window = Arc::new(event_loop.create_window(attributes)?);
        let instance = common::instance(Some(Box::new(event_loop.owned_display_handle())));
        let surface = instance.create_surface(window.clone())?;
        let (adapter, device, queue) = common::device(&instance, Some(&surface))?;
        let size = window.inner_size();
        let size = (size.width.max(1), size.height.max(1));
        let caps = surface.get_capabilities(&adapter);
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| f.is_srgb())
            .or(caps.formats.first().copied())
            .ok_or("the window's surface offers no format")?;
        let mut config = surface
            .get_default_config(&adapter, size.0, size.1)
            .ok_or("the adapter cannot present to this window")?;
        config.format = format;
        surface.configure(&device, &config);

        // One GPU task per frame, FRAMES_IN_FLIGHT of them outstanding at most.
        let settings = ksrt::InitSettings {
            supported_working_sets: FRAMES_IN_FLIGHT as u32,
            ..Default::default()
        };
        let ctx = ksrt::ExecuteContext::new(&device, &queue, settings)?;
        let scene = common::register_scene(&device, &ctx, scene())?;
        let gbuffer = GBuffer::new(&device, size);
        let texture = |label| common::output_texture(&device, label, size);
        let outputs = Outputs {
            specular: texture("specular"),
            diffuse: texture("diffuse"),
            ao: texture("ao"),
            shadow: texture("shadow"),
            specular_denoised: texture("specular denoised"),
            diffuse_denoised: texture("diffuse denoised"),
            ao_denoised: texture("ao denoised"),
            shadow_denoised: texture("shadow denoised"),
        };
        let denoiser = |signal_type| {
            ctx.create_denoising_context_handle(ksrt::DenoisingContextInput {
                max_width: size.0,
                max_height: size.1,
                signal_type,
                method: Default::default(),
            })
        };
        let denoisers = [
            denoiser(ksrt::SignalType::SpecularAndDiffuse)?,
            denoiser(ksrt::SignalType::DiffuseOcclusion)?,
            denoiser(ksrt::SignalType::Shadow)?,
        ];
        let lighting = Lighting {
            specular: &outputs.specular_denoised,
            diffuse: &outputs.diffuse_denoised,
            ao: &outputs.ao_denoised,
            shadow: &outputs.shadow_denoised,
        };
        let composite = Composite::new(&device, format, &scene, &gbuffer, &lighting);
        Ok(Gpu {
            prev_camera: camera(0, size),
            window,
            surface,
            device,
            queue,
            ctx,
            scene,
            gbuffer,
            outputs,
            denoisers,
            composite,
            frame: 0,
            in_flight: VecDeque::new(),
        })
    }

    /// Renders and presents one frame.
    fn redraw(&mut self) -> AnyResult<()> {
        // Wait for the oldest frame when FRAMES_IN_FLIGHT are outstanding, then tell the SDK
        // which finished, so it can reuse their memory.
        self.retire(self.in_flight.len() >= FRAMES_IN_FLIGHT)?;
        let surface_texture = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(t)
            | wgpu::CurrentSurfaceTexture::Suboptimal(t) => t,
            other => return Err(format!("no surface texture: {other:?}").into()),
        };
        let size = (self.gbuffer.depth.width(), self.gbuffer.depth.height());
        let camera = camera(self.frame, size);
        let mut encoder = self.device.create_command_encoder(&Default::default());
        self.gbuffer.render(
            &self.queue,
            &mut encoder,
            &self.scene,
            &camera,
            &self.prev_camera,
            SUN,
        );
        let tasks = self.tasks(camera.view_info(&self.prev_camera));
        let task = self.ctx.build_gpu_task(tasks, &mut encoder)?;
        let target = surface_texture.texture.create_view(&Default::default());
        self.composite.render(&mut encoder, &target);
        self.queue.submit([encoder.finish()]);
        let done = Arc::new(AtomicBool::new(false));
        let flag = done.clone();
        self.queue
            .on_submitted_work_done(move || flag.store(true, Ordering::Release));
        self.in_flight.push_back((task, done));
        self.window.pre_present_notify();
        self.queue.present(surface_texture);
        self.prev_camera = camera;
        self.frame += 1;
        Ok(())
    }

    /// This frame's SDK work: injection, the four traces, their denoisers.
    fn tasks(&self, view: ksrt::ViewInfo) -> ksrt::TaskContainer {
        let v = |t: &wgpu::Texture| t.create_view(&Default::default());
        let (g, o) = (&self.gbuffer, &self.outputs);
        let mut c = self.ctx.create_task_container();
        // The cache learns the lighting of what the camera sees; reflection and GI rays read it
        // where they hit. (This G-buffer's direct light has no shadow, so the cache's has none.)
        let depth = ksrt::DepthInput {
            texture: v(&g.depth),
            depth_type: ksrt::DepthType::RClipSpace,
        };
        c.schedule_render_task(ksrt::RenderTask::DirectLightingInjection(
            ksrt::DirectLightingInjectionTask::new(depth, v(&g.direct), view),
        ));
        let common = g.trace_common(view, self.frame);
        c.schedule_render_task(ksrt::RenderTask::TraceSpecular(ksrt::TraceSpecularTask {
            common: common.clone(),
            output: v(&o.specular),
            demodulate_specular: false,
            demodulation_output: None,
        }));
        c.schedule_render_task(ksrt::RenderTask::TraceDiffuse(ksrt::TraceDiffuseTask {
            common: common.clone(),
            output: v(&o.diffuse),
            diffuse_brdf: ksrt::DiffuseBrdf::Lambertian,
            ambient_occlusion: None,
        }));
        c.schedule_render_task(ksrt::RenderTask::TraceAmbientOcclusion(
            ksrt::TraceAmbientOcclusionTask {
                common: common.clone(),
                output: v(&o.ao),
                ao_radius: 1.0,
            },
        ));
        c.schedule_render_task(ksrt::RenderTask::TraceShadow(ksrt::TraceShadowTask {
            common,
            output: v(&o.shadow),
            light: ksrt::LightInfo::Directional {
                direction: SUN.normalize(),
                angular_extent: 2f32.to_radians(),
            },
            enable_first_hit_and_end_search: true,
        }));
        let first = self.frame == 0;
        let [spec_diff, ao, shadow] = self.denoisers;
        c.schedule_render_task(ksrt::RenderTask::DenoiseSpecularAndDiffuse(
            ksrt::DenoiseSpecularAndDiffuseTask {
                common: g.denoise_common(spec_diff, view, first),
                input_specular: v(&o.specular),
                input_diffuse: v(&o.diffuse),
                output_specular: v(&o.specular_denoised),
                output_diffuse: v(&o.diffuse_denoised),
            },
        ));
        c.schedule_render_task(ksrt::RenderTask::DenoiseDiffuseOcclusion(
            ksrt::DenoiseDiffuseOcclusionTask {
                common: g.denoise_common(ao, view, first),
                input: v(&o.ao),
                output: v(&o.ao_denoised),
            },
        ));
        c.schedule_render_task(ksrt::RenderTask::DenoiseShadow(ksrt::DenoiseShadowTask {
            common: g.denoise_common(shadow, view, first),
            input: v(&o.shadow),
            output: v(&o.shadow_denoised),
        }));
        c
    }

    /// Marks the GPU tasks the GPU has finished complete; `wait`: waits for all first.
    fn retire(&mut self, wait: bool) -> AnyResult<()> {
        // Polling runs wgpu's callbacks, which set the `done` flags.
        let poll = if wait {
            wgpu::PollType::wait_indefinitely()
        } else {
            wgpu::PollType::Poll
        };
        self.device.poll(poll)?;
        while let Some((task, done)) = self.in_flight.front() {
            if !done.load(Ordering::Acquire) {
                break;
            }
            self.ctx.mark_gpu_task_completed(*task)?;
            self.in_flight.pop_front();
        }
        Ok(())
    }
}

/// The box on the floor, with a red and a blue crate that tint the GI and reflections.
fn scene() -> Vec<Placement> {
    let crate_at = |x, z, albedo| Placement {
        shape: Shape::Cube,
        transform: Affine3A::from_translation(Vec3::new(x, 0.5, z)),
        albedo,
    };
    common::box_on_plane([
        crate_at(-1.6, 0.4, Vec3::new(0.8, 0.1, 0.1)),
        crate_at(1.2, -1.5, Vec3::new(0.1, 0.2, 0.8)),
    ])
}

/// The camera of frame `frame`: circling the scene.
fn camera(frame: u32, (width, height): (u32, u32)) -> Camera {
    let angle = 0.6 + frame as f32 * 0.02;
    Camera {
        eye: Vec3::new(6.0 * angle.sin(), 3.0, 6.0 * angle.cos()),
        target: Vec3::new(0.0, 0.4, 0.0),
        fov_y: 50f32.to_radians(),
        aspect: width as f32 / height as f32,
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.gpu.is_none() {
            match Gpu::new(event_loop) {
                Ok(gpu) => self.gpu = Some(gpu),
                Err(e) => self.fail(event_loop, e),
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _: WindowId, event: WindowEvent) {
        match event {
            WindowEvent::CloseRequested => self.exit(event_loop),
            WindowEvent::RedrawRequested => {
                let Some(gpu) = self.gpu.as_mut() else { return };
                if let Err(e) = gpu.redraw() {
                    return self.fail(event_loop, e);
                }
                if self.frames.is_some_and(|n| gpu.frame >= n) {
                    self.exit(event_loop);
                }
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, _: &ActiveEventLoop) {
        // Render continuously.
        if let Some(gpu) = &self.gpu {
            gpu.window.request_redraw();
        }
    }
}

impl App {
    fn exit(&mut self, event_loop: &ActiveEventLoop) {
        if let Some(gpu) = self.gpu.as_mut() {
            if let Err(e) = gpu.retire(true) {
                self.error = Some(e.to_string());
            }
            println!("rendered {} frames", gpu.frame);
        }
        event_loop.exit();
    }

    fn fail(&mut self, event_loop: &ActiveEventLoop, e: impl std::fmt::Display) {
        self.error = Some(e.to_string());
        event_loop.exit();
    }
}
