//! The render effects the context owns, one module each (ray batches, debug views, the trace
//! tasks, the denoisers; the lighting cache owns its injection and transfer), and the one
//! `match` that sends a planned render task to its effect.

use crate::cache::DirectLightingCache;
use crate::denoise::{DenoiseJob, Denoisers};
use crate::device::TraversalBackend;
use crate::gpu::Recorder;
use crate::scene::traversal::{LeafTest, SceneBuffers};
use crate::tasks::*;
use crate::trace::debug_view::{DebugView, DebugViewPass};
use crate::trace::rays::RayTracer;
use crate::trace::tasks::{Job as TraceJob, TracePasses};

/// Where a render task is recorded: the effect that records it, with what the plan resolved,
/// so that recording it cannot fail.
pub(super) enum Route<'c> {
    /// A batch of rays from a buffer.
    RayBatch(&'c TraceRaysTask),
    /// Direct lighting injected into the lighting cache.
    Injection(&'c DirectLightingInjectionTask),
    /// The lighting cache copied from one instance to another.
    Transfer(&'c DirectLightTransferTask),
    /// A trace task writing its normal output: its pass and its viewport checked.
    Trace(TraceJob<'c>),
    /// A trace task writing a primary-ray debug view instead: the view and its viewport.
    DebugView {
        common: &'c TraceTaskCommon,
        output: &'c TextureInput,
        view: DebugView,
    },
    /// A denoise task, with its denoiser.
    Denoise(DenoiseJob<'c>),
}

/// The effects' pipelines and history. Pipelines are created on first use, so a context that
/// never traces never compiles the trace shaders.
pub(super) struct Effects {
    /// The traversal every tracing effect is composed with.
    backend: TraversalBackend,
    rays: Option<RayTracer>,
    debug_views: Option<DebugViewPass>,
    /// Created on first use: they generate the blue-noise tile.
    traces: Option<TracePasses>,
    /// The denoisers' history per denoising context, and their passes.
    pub(super) denoisers: Denoisers,
}

/// What a render task reads besides its own inputs.
pub(super) struct Inputs<'a> {
    /// The scene as the traversal binds it.
    pub scene: SceneBuffers<'a>,
    /// The direct lighting cache.
    pub cache: &'a mut DirectLightingCache,
    /// Triangles of a transfer's target geometry (0 for other tasks).
    pub transfer_triangles: u32,
    /// The task's serial number.
    pub serial: u64,
}

impl Effects {
    /// No pipelines yet; tracing effects will trace with `backend`.
    pub fn new(device: &wgpu::Device, backend: TraversalBackend) -> Self {
        Effects {
            backend,
            rays: None,
            debug_views: None,
            traces: None,
            denoisers: Denoisers::new(device),
        }
    }

    /// Creates every effect's pipelines now, tracing with the traversal build `leaf`.
    pub fn prepare_pipelines(
        &mut self,
        device: &wgpu::Device,
        queue: &wgpu::Queue,
        leaf: LeafTest,
    ) {
        let backend = self.backend;
        self.rays
            .get_or_insert_with(|| RayTracer::new(device, backend))
            .prepare(device, leaf);
        self.debug_views(device);
        self.traces(device, queue).prepare(device, leaf);
        self.denoisers.prepare_pipelines();
    }

    fn debug_views(&mut self, device: &wgpu::Device) -> &mut DebugViewPass {
        let backend = self.backend;
        self.debug_views.get_or_insert_with(|| {
            let mut p = DebugViewPass::new(backend);
            p.prepare(device);
            p
        })
    }

    fn traces(&mut self, device: &wgpu::Device, queue: &wgpu::Queue) -> &mut TracePasses {
        let backend = self.backend;
        self.traces
            .get_or_insert_with(|| TracePasses::new(device, queue, backend))
    }

    /// Records one render task on the effect its plan routed it to.
    pub fn record(
        &mut self,
        rec: &mut Recorder<'_>,
        queue: &wgpu::Queue,
        inputs: Inputs<'_>,
        route: &Route<'_>,
    ) {
        let device = rec.device;
        match route {
            Route::RayBatch(t) => {
                rec.scope = "trace rays";
                let backend = self.backend;
                let rays = self
                    .rays
                    .get_or_insert_with(|| RayTracer::new(device, backend));
                rays.record(
                    rec,
                    &inputs.scene,
                    (&t.rays, t.ray_offset),
                    (&t.hits, t.hit_offset),
                    t.ray_count,
                    t.query,
                    t.instance_mask.0,
                );
            }
            Route::Injection(t) => {
                let cache = inputs.cache;
                let meta = cache.meta_buffer().clone();
                let surfels = cache.surfel_buffer().clone();
                let capacity = cache.capacity();
                cache
                    .injector
                    .record(rec, &inputs.scene, (&meta, &surfels, capacity), t);
            }
            Route::Transfer(t) => {
                let triangles = inputs.transfer_triangles;
                let cache = inputs.cache;
                let meta = cache.meta_buffer().clone();
                let surfels = cache.surfel_buffer().clone();
                cache.transferer.record(
                    rec,
                    (&meta, &surfels),
                    t.source.index,
                    t.target.index,
                    triangles,
                );
            }
            Route::Trace(job) => {
                rec.scope = "trace";
                let cache = inputs.cache.sample_resources();
                self.traces(device, queue)
                    .record(rec, &inputs.scene, &cache, job);
            }
            Route::DebugView {
                common,
                output,
                view,
            } => {
                rec.scope = "debug view";
                self.debug_views(device).record(
                    rec,
                    &inputs.scene,
                    output,
                    output.texture().format(),
                    *view,
                    &common.view,
                    (inputs.cache, common.use_bilinear_sampling),
                );
            }
            Route::Denoise(job) => self.denoisers.record(rec, job, inputs.serial),
        }
    }
}
