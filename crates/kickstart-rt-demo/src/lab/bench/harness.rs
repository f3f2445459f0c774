//! The shared device state of one `ksrt bench` run and the timing every figure goes through:
//! the warm-up, the timed repetitions, the GPU span of the timed passes and its profile, and the
//! registrations and builds that the measurements start from.

use kickstart_rt as ksrt;
use wgpu::util::DeviceExt;

use super::options::{RayOrder, Section};
use super::profile::{self as prof, PassProfile};
use super::{busy, Stats};
use crate::app::gpu;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::scene::Scene;
use kickstart_rt_renderer::sdk_glue::{self as glue, GpuHit, GpuRay, Query, Tlas};
use kickstart_rt_renderer::upload::{self, UploadedMesh};

/// The shared device state of one benchmark run.
pub(super) struct Bench<'a> {
    pub(super) device: &'a wgpu::Device,
    pub(super) queue: &'a wgpu::Queue,
    pub(super) iterations: u32,
    /// Order of the primary rays of the ray batches (`--ray-order`).
    pub(super) ray_order: RayOrder,
    /// The passes of the last task `timed` measured, for the figure's profile.
    pub(super) last_passes: std::cell::RefCell<Vec<ksrt::PassTiming>>,
    /// Whether a measurement ran already (the first warms up longer, see [`Bench::repeat`]).
    pub(super) warmed: std::cell::Cell<bool>,
    /// Submitted before each timed task (`--busy-gpu-ms`).
    pub(super) busy: Option<busy::BusyGpu>,
    /// The measurements to run (`--sections`; empty: all).
    pub(super) sections: Vec<Section>,
    /// The traversal backend of the contexts [`Bench::context`] makes (`--backend`; the
    /// backend comparison switches it for its measurements).
    pub(super) backend: std::cell::Cell<ksrt::BackendChoice>,
}

impl<'a> Bench<'a> {
    /// A bench on `device`, timing `iterations` repetitions of each measurement.
    pub(super) fn new(device: &'a wgpu::Device, queue: &'a wgpu::Queue, iterations: u32) -> Self {
        Bench {
            device,
            queue,
            iterations,
            ray_order: RayOrder::Rows,
            last_passes: Default::default(),
            warmed: Default::default(),
            busy: None,
            sections: Vec::new(),
            backend: std::cell::Cell::new(gpu::backend_choice()),
        }
    }

    /// TLAS rebuild over `scene`'s instances, every transform updated (to the same values: the
    /// rebuild does the same work whatever they are), span `tlas build`.
    pub(super) fn tlas_rebuild(&self, scene: &Scene, uploads: &[UploadedMesh]) -> AnyResult<Stats> {
        let (ctx, h) = self.registered(scene, uploads, false, true)?;
        self.repeat(|_| {
            let mut c = ctx.create_task_container();
            for (inst, &handle) in scene.instances.iter().zip(&h.instances) {
                c.schedule_bvh_task(ksrt::InstanceTask {
                    operation: ksrt::TaskOperation::Update,
                    handle,
                    input: ksrt::InstanceInput::new(h.geometries[inst.mesh], inst.transform),
                });
            }
            c.schedule_bvh_task(glue::bvh_build_task(1, Some(Tlas::Rebuild)));
            self.timed(&ctx, c, &["tlas build"], |_| {})
        })
    }

    pub(super) fn context(&self) -> AnyResult<ksrt::ExecuteContext> {
        let settings = ksrt::InitSettings {
            backend: self.backend.get(),
            ..crate::app::gpu::init_settings_timed(true)
        };
        let ctx = ksrt::ExecuteContext::new(self.device, self.queue, settings)?;
        glue::prepare_pipelines(&ctx)?;
        Ok(ctx)
    }

    /// Submits `container`, waits, and returns the GPU time of the passes `span` names.
    pub(super) fn timed(
        &self,
        ctx: &ksrt::ExecuteContext,
        container: ksrt::TaskContainer,
        span: &[&str],
        after: impl FnOnce(&mut wgpu::CommandEncoder),
    ) -> AnyResult<f64> {
        if let Some(busy) = &self.busy {
            busy.submit(self.device, self.queue);
        }
        let task = upload::submit(ctx, self.device, self.queue, container, after)?;
        let timings = ctx.wait_for_gpu_timings(task);
        gpu::complete(ctx, self.device, task)?;
        let timings = timings?;
        let ms = glue::span_ms(&timings, span)?;
        *self.last_passes.borrow_mut() = prof::within(timings.passes, span);
        Ok(ms)
    }

    /// The profile of the last task `timed` measured.
    pub(super) fn last_profile(&self) -> Vec<PassProfile> {
        prof::profile(&self.last_passes.borrow())
    }

    /// Runs `one` untimed for at least half a second (warm-up: GPU clocks ramp up from idle,
    /// and one short run left them low enough to skew sub-millisecond passes 2–4× on the H100),
    /// then `iterations` times timed.
    ///
    /// The first measurement of a run warms up for 2 s instead: on a freshly started H100 the
    /// first figure (the dragon's BLAS build) measured 1.66 ms after 0.5 s, every pass about
    /// 1.8× slower than the same binary's 0.93 ms in another run, while later figures agreed.
    pub(super) fn repeat(&self, mut one: impl FnMut(bool) -> AnyResult<f64>) -> AnyResult<Stats> {
        let warm_up_ms = if self.warmed.replace(true) { 500 } else { 2000 };
        let start = std::time::Instant::now();
        one(false)?;
        while start.elapsed() < std::time::Duration::from_millis(warm_up_ms) {
            one(false)?;
        }
        let samples = (0..self.iterations)
            .map(|_| one(true))
            .collect::<AnyResult<Vec<f64>>>()?;
        Ok(Stats::new(samples))
    }

    /// Registers the scene's geometries (and instances) and builds every BVH, untimed.
    pub(super) fn registered(
        &self,
        scene: &Scene,
        uploads: &[UploadedMesh],
        allow_update: bool,
        instances: bool,
    ) -> AnyResult<(ksrt::ExecuteContext, upload::SceneHandles)> {
        let ctx = self.context()?;
        let mut c = ctx.create_task_container();
        let h = upload::schedule_scene(
            &ctx,
            &mut c,
            scene,
            uploads,
            allow_update,
            ksrt::BuildHint::Auto,
            instances,
        );
        c.schedule_bvh_task(glue::bvh_build_task(
            uploads.len() as u32,
            instances.then_some(Tlas::Auto),
        ));
        let task = upload::submit(&ctx, self.device, self.queue, c, |_| {})?;
        gpu::complete(&ctx, self.device, task)?;
        Ok((ctx, h))
    }

    /// (a) Every BLAS built in one task with `build_hint`, from newly registered geometry each
    /// time (the previous repetition's geometry destroyed first). Returns the context and the last
    /// handles for the SAH read-back.
    ///
    /// One context serves every repetition: with a fresh context per build, its set-up (pipelines,
    /// pools) left the GPU idle between builds, its clocks fell, and the same build measured
    /// 1.25 ms in one H100 run and 4.2 ms in another.
    pub(super) fn blas_build(
        &self,
        scene: &Scene,
        uploads: &[UploadedMesh],
        build_hint: ksrt::BuildHint,
    ) -> AnyResult<(Stats, ksrt::ExecuteContext, upload::SceneHandles)> {
        let ctx = self.context()?;
        let mut last: Option<upload::SceneHandles> = None;
        let stats = self.repeat(|_| {
            if let Some(old) = last.take() {
                ctx.destroy_geometry_handles(&old.geometries)?;
            }
            let mut c = ctx.create_task_container();
            let h = upload::schedule_scene(&ctx, &mut c, scene, uploads, false, build_hint, false);
            c.schedule_bvh_task(glue::bvh_build_task(uploads.len() as u32, None));
            let ms = self.timed(&ctx, c, &["ingest", "blas build"], |_| {})?;
            last = Some(h);
            Ok(ms)
        })?;
        let h = last.ok_or("no BLAS build ran")?;
        Ok((stats, ctx, h))
    }

    /// (b) Every BLAS refit after an update of all its vertices (the same positions again: the
    /// refit does the same work whatever they are).
    pub(super) fn blas_refit(&self, scene: &Scene, uploads: &[UploadedMesh]) -> AnyResult<Stats> {
        let (ctx, h) = self.registered(scene, uploads, true, false)?;
        self.repeat(|_| {
            let mut c = ctx.create_task_container();
            for (m, &handle) in uploads.iter().zip(&h.geometries) {
                c.schedule_bvh_task(ksrt::GeometryTask {
                    operation: ksrt::TaskOperation::Update,
                    handle,
                    input: upload::geometry_input(m, true),
                });
            }
            c.schedule_bvh_task(glue::bvh_build_task(uploads.len() as u32, None));
            self.timed(&ctx, c, &["ingest", "blas refit"], |_| {})
        })
    }

    /// Traces `rays` (`iterations` timed times after a warm-up) and returns the last hits.
    pub(super) fn trace(
        &self,
        ctx: &ksrt::ExecuteContext,
        rays: &[GpuRay],
        query: Query,
    ) -> AnyResult<(Stats, Vec<GpuHit>)> {
        if rays.is_empty() {
            return Ok((Stats::new(vec![0.0]), Vec::new()));
        }
        let limits = self.device.limits();
        let bytes = std::mem::size_of_val(rays) as u64;
        if bytes > limits.max_buffer_size {
            return Err(format!(
                "{} rays need {bytes} bytes, more than the device's largest buffer ({}); use a smaller --size",
                rays.len(),
                limits.max_buffer_size
            )
            .into());
        }
        // One task per chunk that fits a storage binding; chunk offsets keep the device's
        // storage offset alignment.
        let align_rays = (limits.min_storage_buffer_offset_alignment as u64 / 32).max(1);
        let chunk = (limits.max_storage_buffer_binding_size / 32) / align_rays * align_rays;
        let ray_buffer = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("ksrt bench rays"),
                contents: bytemuck::cast_slice(rays),
                usage: wgpu::BufferUsages::STORAGE,
            });
        let hit_buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ksrt bench hits"),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let readback = gpu::readback_buffer(self.device, bytes);
        let count = rays.len() as u64;
        let mut timed_runs = 0;
        let stats = self.repeat(|timed| {
            if timed {
                timed_runs += 1;
            }
            let mut c = ctx.create_task_container();
            let mut first = 0u64;
            while first < count {
                let n = chunk.min(count - first);
                c.schedule_render_task(glue::trace_rays_task(
                    &ray_buffer,
                    &hit_buffer,
                    first * 32,
                    n as u32,
                    query,
                )?);
                first += n;
            }
            // Only the last repetition's hits are read back; the copy is outside the timed passes.
            let read = timed && timed_runs == self.iterations;
            self.timed(ctx, c, &["trace rays"], |e| {
                if read {
                    e.copy_buffer_to_buffer(&hit_buffer, 0, &readback, 0, bytes);
                }
            })
        })?;
        let hits = gpu::map_read(self.device, &readback)?
            .chunks_exact(std::mem::size_of::<GpuHit>())
            .map(bytemuck::pod_read_unaligned::<GpuHit>)
            .collect();
        Ok((stats, hits))
    }
}
