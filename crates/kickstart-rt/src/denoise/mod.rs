//! The denoisers: spatio-temporal filters for the specular, diffuse, occlusion and shadow
//! signals of the trace tasks, written here in WGSL (DESIGN.md, "Algorithms"; NRD is not used).
//!
//! One module per denoiser, each owning its pipelines and the history of the contexts it serves:
//! [`radiance`] (specular, diffuse, both), [`occlusion`] and [`shadow`] (one or many lights).
//! They run the same two passes ([`filter`]: temporal accumulation, then à-trous iterations),
//! compiled per [`signal::SignalSet`]. A denoise task is routed to its denoiser by one `match`
//! ([`route`]).
//!
//! History lives in SDK-owned storage buffers (16 or 8 bytes per pixel and buffer; see
//! [`history::History`]), created by a context's first frame for that frame's grid (a block
//! mode's grid holds a quarter or a sixteenth of the pixels), released lazily after destruction
//! once no in-flight task uses it, and counted as [`crate::ResourceAllocations::denoiser`]. The
//! filters' intermediate is one buffer every context shares ([`scratch`]), and contexts denoised
//! in one task from the same inputs share their guides ([`guides`]). A viewport of another size than the previous
//! frame's starts the history over, as does [`crate::DenoiseMode::DiscardHistory`].
//!
//! Input and output may be the same texture: no pass reads the input and writes the output.

mod filter;
mod guides;
pub(crate) use filter::shader_variants;
pub(crate) mod history;
mod occlusion;
mod radiance;
mod scratch;
mod shadow;
mod signal;

use crate::error::{Error, Result};
use crate::gpu::Recorder;
use crate::handles::DenoisingContextHandle;
use crate::tasks::{DenoisingContextInput, RenderTask};
use crate::trace::gbuffer::resolve_viewport;
use filter::{Filter, Job, Resources, Shared};
use guides::Guides;
use scratch::Scratch;

/// The denoisers.
#[derive(Debug, Clone, Copy)]
enum Denoiser {
    Radiance,
    Occlusion,
    Shadow,
}

/// A denoise task the plan resolved ([`route`]): its denoiser and its signals.
pub(crate) struct DenoiseJob<'a> {
    denoiser: Denoiser,
    job: Job<'a>,
}

/// The denoiser of a task and the task's signals; `None` for other tasks.
pub(crate) fn route(task: &RenderTask) -> Option<DenoiseJob<'_>> {
    let (denoiser, job) = match task {
        RenderTask::DenoiseSpecular(t) => (Denoiser::Radiance, radiance::specular(t)),
        RenderTask::DenoiseDiffuse(t) => (Denoiser::Radiance, radiance::diffuse(t)),
        RenderTask::DenoiseSpecularAndDiffuse(t) => {
            (Denoiser::Radiance, radiance::specular_and_diffuse(t))
        }
        RenderTask::DenoiseDiffuseOcclusion(t) => {
            (Denoiser::Occlusion, occlusion::diffuse_occlusion(t))
        }
        RenderTask::DenoiseShadow(t) => (Denoiser::Shadow, shadow::shadow(t)),
        RenderTask::DenoiseMultiShadow(t) => (Denoiser::Shadow, shadow::multi_shadow(t)),
        _ => return None,
    };
    Some(DenoiseJob { denoiser, job })
}

/// Checks a denoise task against its context (the task's own fields are checked by
/// `validate::render_task`): the context's signal type, and the viewport within its maximum
/// size.
pub(crate) fn check_task(
    task: &RenderTask,
    routed: &DenoiseJob<'_>,
    context: &DenoisingContextInput,
) -> Result<()> {
    let job = &routed.job;
    let needed = job.signal_type;
    let name = task.name();
    if context.signal_type != needed {
        return Err(Error::input(
            name,
            "common.context",
            context.signal_type,
            format!("the denoising context was created for another signal; {name} needs SignalType::{needed:?}"),
        ));
    }
    let vp = resolve_viewport(job.common.viewport, job.inputs[0].texture().size());
    if vp.width > context.max_width || vp.height > context.max_height {
        return Err(Error::input(
            name,
            "viewport",
            vp,
            format!(
                "larger than the denoising context's maximum {}×{}: create a context of that size",
                context.max_width, context.max_height
            ),
        ));
    }
    Ok(())
}

/// Checks a new context's size against the device's binding limits.
pub(crate) fn check_context(input: &DenoisingContextInput, limits: &wgpu::Limits) -> Result<()> {
    let bytes = history::buffer_bytes(input);
    let max = limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size);
    if bytes > max {
        return Err(Error::input(
            "DenoisingContextInput",
            "max_width/max_height",
            (input.max_width, input.max_height),
            format!(
                "needs {bytes}-byte buffers; the device binds at most {max} bytes ({} bytes per pixel)",
                history::RECORD_BYTES
            ),
        ));
    }
    Ok(())
}

/// Every denoiser, with the layouts they share.
pub(crate) struct Denoisers {
    device: wgpu::Device,
    /// Created on first use.
    shared: Option<Shared>,
    /// The à-trous intermediate every context shares.
    scratch: Scratch,
    /// The guides, shared by contexts denoised from the same inputs.
    guides: Guides,
    radiance: Filter,
    occlusion: Filter,
    shadow: Filter,
}

impl Denoisers {
    /// No contexts, no pipelines yet.
    pub fn new(device: &wgpu::Device) -> Self {
        Denoisers {
            device: device.clone(),
            shared: None,
            scratch: Scratch::default(),
            guides: Guides::default(),
            radiance: radiance::new(),
            occlusion: occlusion::new(),
            shadow: shadow::new(),
        }
    }

    fn all(&mut self) -> [&mut Filter; 3] {
        [&mut self.radiance, &mut self.occlusion, &mut self.shadow]
    }

    /// Creates every pipeline now.
    pub fn prepare_pipelines(&mut self) {
        let device = self.device.clone();
        let shared = self.shared.take().unwrap_or_else(|| Shared::new(&device));
        for denoiser in self.all() {
            denoiser.prepare(&device, &shared);
        }
        self.shared = Some(shared);
    }

    /// Follows the live contexts: starts the history of new ones (their memory comes with
    /// their first frame), retires destroyed ones.
    pub fn sync(&mut self, live: &[(DenoisingContextHandle, DenoisingContextInput)]) {
        for denoiser in self.all() {
            denoiser.sync(live);
        }
    }

    /// Retires the histories of destroyed contexts (those not in `live`), creating nothing:
    /// releasing memory must not allocate the histories of contexts no task has used yet.
    pub fn retire_destroyed(&mut self, live: &[DenoisingContextHandle]) {
        for denoiser in self.all() {
            denoiser.retire_destroyed(live);
        }
    }

    /// Releases retired histories whose last task is older than `oldest_in_flight`, and the
    /// shared intermediate when no live context needs it at its size.
    pub fn collect(&mut self, oldest_in_flight: u64) {
        for denoiser in self.all() {
            denoiser.collect(oldest_in_flight);
        }
        let needed = self.filters().map(Filter::largest_signal_buffer).max();
        self.scratch.collect(oldest_in_flight, needed.unwrap_or(0));
        let held: Vec<usize> = self.filters().flat_map(Filter::guides_held).collect();
        self.guides.collect(oldest_in_flight, &held);
    }

    fn filters(&self) -> impl Iterator<Item = &Filter> {
        [&self.radiance, &self.occlusion, &self.shadow].into_iter()
    }

    /// GPU bytes held (live and not yet released): [`Self::history_bytes`] and
    /// [`Self::intermediate_bytes`].
    pub fn bytes(&self) -> u64 {
        self.history_bytes() + self.intermediate_bytes()
    }

    /// GPU bytes of the contexts' histories and guides.
    pub fn history_bytes(&self) -> u64 {
        self.filters().map(Filter::bytes).sum::<u64>() + self.guides.bytes()
    }

    /// GPU bytes of one live context's histories (0 before its first frame, or for a context
    /// no `build_gpu_task` has seen yet); its guides may be shared and are not in it.
    pub fn context_bytes(&self, context: &DenoisingContextHandle) -> u64 {
        self.filters()
            .find_map(|f| f.context_bytes(context))
            .unwrap_or(0)
    }

    /// GPU bytes of the intermediate the contexts share.
    pub fn intermediate_bytes(&self) -> u64 {
        self.scratch.bytes()
    }

    /// Records a validated denoise task ([`route`]d, `check_task` passed; its context has a
    /// history after `sync`).
    pub fn record(&mut self, rec: &mut Recorder<'_>, routed: &DenoiseJob<'_>, serial: u64) {
        let (denoiser, job) = (routed.denoiser, &routed.job);
        let device = &self.device;
        let shared = self.shared.get_or_insert_with(|| Shared::new(device));
        let res = Resources {
            shared,
            scratch: &mut self.scratch,
            guides: &mut self.guides,
        };
        let denoiser = match denoiser {
            Denoiser::Radiance => &mut self.radiance,
            Denoiser::Occlusion => &mut self.occlusion,
            Denoiser::Shadow => &mut self.shadow,
        };
        denoiser.record(rec, res, job, serial);
    }
}
