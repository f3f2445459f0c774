//! The native side of the renderer's frames: making a [`Renderer`] with this run's backend and
//! a clock, waiting for its BVH builds, and the blocking calls a command-line program makes on
//! it (render a frame and wait, read the SDK's GPU timings, trace a debug view and read it back).
//! The renderer itself never waits: it must also run where nothing may block (a browser).

use std::sync::OnceLock;
use std::time::Instant;

use kickstart_rt as ksrt;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::renderer::{Renderer, RendererOptions};
use kickstart_rt_renderer::scene::{Camera, Scene};

use crate::app::gpu;
use crate::app::readback::{self, Texels};

/// Milliseconds since the first call: the renderer's clock.
pub fn now_ms() -> f64 {
    static START: OnceLock<Instant> = OnceLock::new();
    START.get_or_init(Instant::now).elapsed().as_secs_f64() * 1e3
}

/// [`RendererOptions::new`] with this run's `--backend` and the clock that times the SDK's
/// `build_gpu_task` calls.
pub fn renderer_options(size: (u32, u32)) -> RendererOptions {
    RendererOptions {
        backend: gpu::backend_choice(),
        clock: Some(now_ms),
        ..RendererOptions::new(size)
    }
}

/// A renderer of `scene`: registers it, waits for the GPU to build its BVHs, then makes the
/// pipelines and targets.
pub fn new_renderer(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    scene: &Scene,
    opts: &RendererOptions,
) -> AnyResult<Renderer> {
    let (ctx, registered) = Renderer::register(device, queue, scene, opts)?;
    device.poll(wgpu::PollType::wait_indefinitely())?;
    Ok(Renderer::from_registered(
        device, queue, scene, opts, ctx, registered,
    ))
}

/// The blocking calls on a [`Renderer`].
pub trait RendererExt {
    /// Traces the SDK debug view `debug` from the last frame's camera on this renderer's context
    /// (whose lighting cache the frames filled), waits for it and reads `sdk.outputs.debug` back.
    /// The composite and the other outputs keep the last frame.
    fn trace_debug_view(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        debug: ksrt::DebugOutputType,
    ) -> AnyResult<Texels>;

    /// Records, submits and waits for one frame, then marks its SDK task complete; returns the
    /// GPU timings of the SDK's passes when `timing` (and the device can measure them).
    fn render_frame(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        camera: &Camera,
        timing: bool,
    ) -> AnyResult<Option<ksrt::GpuTimings>>;

    /// After the frame of `tasks` was submitted: reads the first task's GPU timings when
    /// `timing` (blocking), waits for the GPU and marks every task complete.
    fn finish(
        &self,
        device: &wgpu::Device,
        tasks: &[ksrt::GpuTaskHandle],
        timing: bool,
    ) -> AnyResult<Option<ksrt::GpuTimings>>;
}

impl RendererExt for Renderer {
    fn trace_debug_view(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        debug: ksrt::DebugOutputType,
    ) -> AnyResult<Texels> {
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("ksrt debug view"),
        });
        let task = self
            .sdk
            .record_debug_view(&mut encoder, debug)?
            .ok_or("trace_debug_view: no frame has been rendered yet")?;
        queue.submit([encoder.finish()]);
        self.finish(device, &[task], false)?;
        readback::read_texture(device, queue, &self.sdk.outputs.debug)
    }

    fn render_frame(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        camera: &Camera,
        timing: bool,
    ) -> AnyResult<Option<ksrt::GpuTimings>> {
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("ksrt frame"),
        });
        let tasks = self.record_frame(device, queue, &mut encoder, camera)?;
        queue.submit([encoder.finish()]);
        self.finish(device, &tasks, timing)
    }

    fn finish(
        &self,
        device: &wgpu::Device,
        tasks: &[ksrt::GpuTaskHandle],
        timing: bool,
    ) -> AnyResult<Option<ksrt::GpuTimings>> {
        let timings = match tasks.first() {
            Some(&task) if timing => match self.sdk.ctx.wait_for_gpu_timings(task) {
                Ok(t) => Some(t),
                Err(e) => {
                    log::debug!("no GPU timings: {e}");
                    None
                }
            },
            _ => None,
        };
        device.poll(wgpu::PollType::wait_indefinitely())?;
        for &task in tasks {
            gpu::complete(&self.sdk.ctx, device, task)?;
        }
        Ok(timings)
    }
}
