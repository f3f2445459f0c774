//! The spatio-temporal filter every denoiser runs (SVGF-like, written here in WGSL; NRD is not
//! used), per frame of a context:
//! 1. **temporal** (`shaders/denoise/temporal.wgsl`): G-buffer decode into a compact guide,
//!    checkerboard resolve, reprojection (motion vectors of either type with their scale, or the
//!    previous matrices when there are none; camera jitter compensated), disocclusion from plane
//!    distance and normal, per-pixel history length, history clamping against ghosting,
//!    accumulation of the raw signal and of its luminance's second moment;
//! 2. **à-trous** (`shaders/denoise/atrous.wgsl`), 3 (Fast) or 5 (HighQuality) iterations of
//!    an edge-stopping wavelet filter guided by normal, plane distance and the estimated noise,
//!    with a radius that follows roughness, hit distance, the occluder distance of a shadow (its
//!    penumbra width) and the history length; one chain of dispatches per signal, whose last
//!    iteration writes the signal's output texture;
//! 3. in a block mode (one traced pixel per 2×2 or 4×4 block), the passes above work on one
//!    pixel per block and **upsample** (`shaders/denoise/upsample.wgsl`) writes every pixel of
//!    the output, guided by normals and depth.
//!
//! [`Shared`] holds what every denoiser binds the same way (layouts, placeholders); a
//! [`Filter`] is one denoiser's pipelines and histories.

use std::collections::HashMap;

use bytemuck::{Pod, Zeroable};

use super::guides::{GuideKey, GuideRequest, Guides};
use super::history::{self, Histories, History};
use super::scratch::Scratch;
use super::signal::{wgsl_format, Kind, SignalSet};
use crate::gpu::buffers::placeholder_texture;
use crate::gpu::reflect::{ReflectedLayout, ShaderReflection};
use crate::gpu::shader::compute_pipeline_with_layouts;
use crate::gpu::Recorder;
use crate::handles::DenoisingContextHandle;
use crate::tasks::{
    DenoiseMode, DenoiseTaskCommon, DenoisingContextInput, DenoisingMethod, HalfResolutionMode,
    MotionType, SignalType, TextureInput, Viewport,
};
use crate::trace::gbuffer::{
    resolve_viewport, CameraFrame, GBufferBinder, GBufferInputs, GBufferParams,
};

/// Invocations per workgroup side of every denoise pass (`@workgroup_size(8, 8)`).
const TILE: u32 = 8;

/// What one denoising method does.
#[derive(Debug, Clone, Copy)]
struct MethodSettings {
    /// Longest history, frames.
    max_history: f32,
    /// À-trous iterations (steps 1, 2, 4, …).
    iterations: u32,
    /// Radius of the spatial falloff before the signal-specific scaling, pixels.
    base_radius: f32,
}

fn method_settings(method: DenoisingMethod) -> MethodSettings {
    match method {
        DenoisingMethod::Fast => MethodSettings {
            max_history: 16.0,
            iterations: 3,
            base_radius: 8.0,
        },
        DenoisingMethod::HighQuality => MethodSettings {
            max_history: 32.0,
            iterations: 5,
            base_radius: 12.0,
        },
    }
}

/// The uniform of `shaders/denoise/common.wgsl` (`DenoiseParams`).
#[repr(C)]
#[derive(Pod, Zeroable, Clone, Copy, Debug)]
struct DenoiseParams {
    viewport: [u32; 4],
    eye: [f32; 4],
    forward: [f32; 4],
    prev_eye: [f32; 4],
    prev_forward: [f32; 4],
    jitter: [f32; 4],
    motion_scale: [f32; 4],
    kind0: u32,
    kind1: u32,
    signal_count: u32,
    motion_type: u32,
    max_history: f32,
    discard_history: u32,
    checkerboard: u32,
    base_radius: f32,
    grid: [u32; 4],
    lattice: [u32; 4],
    /// This and the previous frame's clip-to-world matrices (column-major): the guides' depths
    /// are unprojected with them.
    clip_to_world: [[f32; 4]; 4],
    prev_clip_to_world: [[f32; 4]; 4],
}

#[repr(C)]
#[derive(Pod, Zeroable, Clone, Copy, Debug)]
struct StepParams {
    value: u32,
    first: u32,
    pad: [u32; 2],
}

/// A denoise task's signals: inputs, outputs and kinds (one or two).
pub(super) struct Job<'a> {
    /// The signal type the task needs its context to have.
    pub signal_type: SignalType,
    pub common: &'a DenoiseTaskCommon,
    pub inputs: Vec<&'a TextureInput>,
    pub outputs: Vec<&'a TextureInput>,
    kinds: Vec<Kind>,
}

impl<'a> Job<'a> {
    /// A task of one signal.
    pub fn one(
        signal_type: SignalType,
        common: &'a DenoiseTaskCommon,
        input: &'a TextureInput,
        output: &'a TextureInput,
        kind: Kind,
    ) -> Self {
        Job {
            signal_type,
            common,
            inputs: vec![input],
            outputs: vec![output],
            kinds: vec![kind],
        }
    }

    /// A task of two signals.
    pub fn two(
        signal_type: SignalType,
        common: &'a DenoiseTaskCommon,
        inputs: [&'a TextureInput; 2],
        outputs: [&'a TextureInput; 2],
        kinds: [Kind; 2],
    ) -> Self {
        Job {
            signal_type,
            common,
            inputs: inputs.to_vec(),
            outputs: outputs.to_vec(),
            kinds: kinds.to_vec(),
        }
    }
}

/// What every denoiser binds the same way: the bind group layouts of the passes and the
/// placeholders bound where a pass has nothing (created on first use).
pub(super) struct Shared {
    gbuffer: GBufferBinder,
    /// Groups 1 and 2 of the temporal pass and 0 and 1 of the à-trous iterations, as the
    /// shaders declare them (the same for every signal set: a single-signal pass leaves its
    /// second signal's bindings unused).
    temporal_inputs: ReflectedLayout,
    temporal_buffers: ReflectedLayout,
    atrous_params: ReflectedLayout,
    atrous_buffers: ReflectedLayout,
    /// Group 1 of the upsample pass (block modes).
    upsample_inputs: ReflectedLayout,
    /// Bound where a pass has no texture (no motion vectors, one signal).
    placeholder_texture: wgpu::TextureView,
    /// Bound where a pass has no second signal: one to read, one to write (a dispatch may not
    /// use one buffer both ways).
    placeholder_buffers: [wgpu::Buffer; 2],
}

impl Shared {
    pub fn new(device: &wgpu::Device) -> Self {
        let gbuffer = GBufferBinder::new(device);
        // Any signal set declares the same bindings; a one-signal radiance set stands for all.
        let set = SignalSet::of(crate::tasks::SignalType::Diffuse);
        let temporal = ShaderReflection::new(&temporal_wgsl(set))
            .unwrap_or_else(|e| panic!("denoise temporal: composed WGSL is invalid: {e}"));
        let atrous = ShaderReflection::new(&atrous_wgsl(set, None))
            .unwrap_or_else(|e| panic!("denoise a-trous: composed WGSL is invalid: {e}"));
        let temporal_inputs =
            ReflectedLayout::new(device, "kickstart-rt denoise temporal inputs", &temporal, 1);
        let temporal_buffers = ReflectedLayout::new(
            device,
            "kickstart-rt denoise temporal buffers",
            &temporal,
            2,
        );
        let atrous_params =
            ReflectedLayout::new(device, "kickstart-rt denoise a-trous params", &atrous, 0);
        let atrous_buffers =
            ReflectedLayout::new(device, "kickstart-rt denoise a-trous buffers", &atrous, 1);
        let upsample = ShaderReflection::new(&upsample_wgsl(set, wgpu::TextureFormat::Rgba16Float))
            .unwrap_or_else(|e| panic!("denoise upsample: composed WGSL is invalid: {e}"));
        let upsample_inputs =
            ReflectedLayout::new(device, "kickstart-rt denoise upsample inputs", &upsample, 1);
        let placeholder_texture = placeholder_texture(device, "kickstart-rt denoise placeholder");
        let placeholder_buffer = || {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("kickstart-rt denoise placeholder"),
                size: history::RECORD_BYTES,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        };
        Shared {
            gbuffer,
            temporal_inputs,
            temporal_buffers,
            atrous_params,
            atrous_buffers,
            upsample_inputs,
            placeholder_texture,
            placeholder_buffers: [placeholder_buffer(), placeholder_buffer()],
        }
    }
}

/// Every signal type a denoising context can filter.
const SIGNAL_TYPES: [SignalType; 6] = [
    SignalType::Specular,
    SignalType::Diffuse,
    SignalType::SpecularAndDiffuse,
    SignalType::DiffuseOcclusion,
    SignalType::Shadow,
    SignalType::MultiShadow,
];

/// Which pass a shader variant is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Pass {
    Temporal,
    Atrous,
    Upsample,
}

/// The WGSL of every pipeline a context of `signal_type` can use, each once (label, source,
/// pass): the set's temporal pass, and per à-trous chain its iterations, its last iteration and
/// its upsample pass for every writable output format.
fn variants(signal_type: SignalType) -> Vec<(String, String, Pass)> {
    let set = SignalSet::of(signal_type);
    let mut out = vec![(
        format!("temporal {}", set.label()),
        temporal_wgsl(set),
        Pass::Temporal,
    )];
    for (_, chain) in set.atrous_chains() {
        out.push((
            format!("a-trous {}", chain.label()),
            atrous_wgsl(chain, None),
            Pass::Atrous,
        ));
        for f in crate::tasks::WRITABLE_OUTPUT_FORMATS {
            let label = format!("a-trous {} (last, {f:?})", chain.label());
            out.push((label, atrous_wgsl(chain, Some(f)), Pass::Atrous));
            let label = format!("upsample {} ({f:?})", chain.label());
            out.push((label, upsample_wgsl(chain, f), Pass::Upsample));
        }
    }
    out
}

/// The WGSL of every denoiser pass the SDK can create, each once, labelled.
pub(crate) fn shader_variants() -> Vec<(String, String)> {
    let mut seen = std::collections::BTreeSet::new();
    SIGNAL_TYPES
        .iter()
        .flat_map(|&st| variants(st))
        .filter(|(label, _, _)| seen.insert(label.clone()))
        .map(|(label, source, _)| (format!("denoise {label}"), source))
        .collect()
}

/// The WGSL of the temporal pass of `set` (the G-buffer module at group 0).
fn temporal_wgsl(set: SignalSet) -> String {
    set.compose(&["denoise/temporal"], None, &[("GBUFFER_GROUP", "0")])
}

/// The WGSL of an à-trous iteration of `set`; `output`: the last iteration's, writing a texture
/// of that format (see [`SignalSet::compose`]).
fn atrous_wgsl(set: SignalSet, output: Option<wgpu::TextureFormat>) -> String {
    set.compose(&["denoise/atrous"], output, &[])
}

/// The WGSL of the upsample pass of the one-signal chain `set` writing a texture of `format`
/// (the G-buffer module at group 0).
fn upsample_wgsl(set: SignalSet, format: wgpu::TextureFormat) -> String {
    set.compose(
        &["denoise/upsample"],
        Some(format),
        &[("GBUFFER_GROUP", "0")],
    )
}

/// The pipelines of one signal set, each created when first used: a two-signal set runs only its
/// temporal pass (its à-trous chains are single-signal sets), and a single-signal set that is a
/// chain of a two-signal one runs only its à-trous passes.
#[derive(Default)]
struct SetPipelines {
    temporal: Option<wgpu::ComputePipeline>,
    atrous: Option<wgpu::ComputePipeline>,
    /// The last à-trous iteration per output format: the output texture's layout (group 2) and
    /// the pipeline.
    last: Vec<(wgpu::TextureFormat, ReflectedLayout, wgpu::ComputePipeline)>,
    /// The upsample pass per output format (block modes; its group 2 is the last iteration's
    /// output layout of the same format).
    upsample: Vec<(wgpu::TextureFormat, wgpu::ComputePipeline)>,
}

/// The à-trous chain of one signal: its pipelines (a single-signal set; see
/// `SignalSet::atrous_chains`), the last iteration's output layout and pipeline.
struct Chain {
    signal: usize,
    atrous: wgpu::ComputePipeline,
    out_layout: ReflectedLayout,
    last: wgpu::ComputePipeline,
    upsample: wgpu::ComputePipeline,
}

/// The pipelines of the signal sets a denoiser has used (created on first use).
#[derive(Default)]
struct Pipelines {
    sets: HashMap<SignalSet, SetPipelines>,
}

impl Pipelines {
    /// The temporal pipeline of `set`.
    fn temporal(
        &mut self,
        device: &wgpu::Device,
        shared: &Shared,
        set: SignalSet,
    ) -> wgpu::ComputePipeline {
        let sp = self.sets.entry(set).or_default();
        sp.temporal
            .get_or_insert_with(|| {
                compute_pipeline_with_layouts(
                    device,
                    "kickstart-rt denoise temporal",
                    &temporal_wgsl(set),
                    "main",
                    &[
                        shared.gbuffer.layout(),
                        shared.temporal_inputs.layout(),
                        shared.temporal_buffers.layout(),
                    ],
                )
            })
            .clone()
    }

    /// The à-trous iteration (all but the last) of the one-signal chain `set`.
    fn atrous(
        &mut self,
        device: &wgpu::Device,
        shared: &Shared,
        set: SignalSet,
    ) -> wgpu::ComputePipeline {
        let sp = self.sets.entry(set).or_default();
        sp.atrous
            .get_or_insert_with(|| {
                compute_pipeline_with_layouts(
                    device,
                    "kickstart-rt denoise a-trous",
                    &atrous_wgsl(set, None),
                    "main",
                    &[
                        shared.atrous_params.layout(),
                        shared.atrous_buffers.layout(),
                    ],
                )
            })
            .clone()
    }

    /// The last à-trous iteration of the one-signal chain `set` writing a texture of `format`
    /// (one of the writable output formats): its output layout and pipeline.
    fn last(
        &mut self,
        device: &wgpu::Device,
        shared: &Shared,
        set: SignalSet,
        format: wgpu::TextureFormat,
    ) -> Option<(ReflectedLayout, wgpu::ComputePipeline)> {
        wgsl_format(format)?;
        let sp = self.sets.entry(set).or_default();
        if let Some((_, l, p)) = sp.last.iter().find(|(f, _, _)| *f == format) {
            return Some((l.clone(), p.clone()));
        }
        let source = atrous_wgsl(set, Some(format));
        let reflection = ShaderReflection::new(&source)
            .unwrap_or_else(|e| panic!("denoise a-trous (last): composed WGSL is invalid: {e}"));
        let out_layout =
            ReflectedLayout::new(device, "kickstart-rt denoise output", &reflection, 2);
        let pipeline = compute_pipeline_with_layouts(
            device,
            "kickstart-rt denoise a-trous (last, output)",
            &source,
            "main",
            &[
                shared.atrous_params.layout(),
                shared.atrous_buffers.layout(),
                out_layout.layout(),
            ],
        );
        sp.last.push((format, out_layout.clone(), pipeline.clone()));
        Some((out_layout, pipeline))
    }

    /// The upsample pass of the one-signal chain `set` writing a texture of `format` (one of
    /// the writable output formats), whose output layout is `out_layout`.
    fn upsample(
        &mut self,
        device: &wgpu::Device,
        shared: &Shared,
        set: SignalSet,
        format: wgpu::TextureFormat,
        out_layout: &ReflectedLayout,
    ) -> wgpu::ComputePipeline {
        let sp = self.sets.entry(set).or_default();
        if let Some((_, p)) = sp.upsample.iter().find(|(f, _)| *f == format) {
            return p.clone();
        }
        let pipeline = compute_pipeline_with_layouts(
            device,
            "kickstart-rt denoise upsample",
            &upsample_wgsl(set, format),
            "main",
            &[
                shared.gbuffer.layout(),
                shared.upsample_inputs.layout(),
                out_layout.layout(),
            ],
        );
        sp.upsample.push((format, pipeline.clone()));
        pipeline
    }

    /// The à-trous chain of each signal of `set` writing `job`'s outputs;
    /// `None` where an output format has no pipeline (validation admits writable formats only).
    fn chains(
        &mut self,
        device: &wgpu::Device,
        shared: &Shared,
        set: SignalSet,
        job: &Job<'_>,
    ) -> Option<Vec<Chain>> {
        let mut chains = Vec::new();
        for (s, chain_set) in set.atrous_chains() {
            let format = job.outputs[s].texture().format();
            let (out_layout, last) = self.last(device, shared, chain_set, format)?;
            let upsample = self.upsample(device, shared, chain_set, format, &out_layout);
            let atrous = self.atrous(device, shared, chain_set);
            chains.push(Chain {
                signal: s,
                atrous,
                out_layout,
                last,
                upsample,
            });
        }
        Some(chains)
    }
}

/// One denoiser: the pipelines of the signal sets it has used and the histories of the
/// contexts it serves.
pub(super) struct Filter {
    /// The signal types of the contexts it serves.
    signal_types: &'static [SignalType],
    pipelines: Pipelines,
    histories: Histories,
}

impl Filter {
    /// A denoiser of contexts of `signal_types`, with no pipelines and no history yet.
    pub fn new(signal_types: &'static [SignalType]) -> Self {
        Filter {
            signal_types,
            pipelines: Pipelines::default(),
            histories: Histories::default(),
        }
    }

    /// Follows the live contexts: creates the history of new ones it serves, retires destroyed
    /// ones.
    pub fn sync(&mut self, live: &[(DenoisingContextHandle, DenoisingContextInput)]) {
        let served = self.signal_types;
        let live = live
            .iter()
            .filter(move |(_, input)| served.contains(&input.signal_type));
        self.histories.sync(live);
    }

    /// Retires the histories of destroyed contexts (those not in `live`), creating nothing.
    pub fn retire_destroyed(&mut self, live: &[DenoisingContextHandle]) {
        self.histories.retire_destroyed(live.iter().copied());
    }

    /// Releases retired histories whose last task is older than `oldest_in_flight`.
    pub fn collect(&mut self, oldest_in_flight: u64) {
        self.histories.collect(oldest_in_flight);
    }

    /// GPU bytes of a live context it serves (see [`Histories::context_bytes`]).
    pub fn context_bytes(&self, context: &DenoisingContextHandle) -> Option<u64> {
        self.histories.context_bytes(context)
    }

    /// The guide pairs of the live contexts it serves.
    pub fn guides_held(&self) -> impl Iterator<Item = usize> + '_ {
        self.histories.guides_held()
    }

    /// Bytes of the largest signal buffer of a context it serves.
    pub fn largest_signal_buffer(&self) -> u64 {
        self.histories.largest_signal_buffer()
    }

    /// GPU bytes of its histories (live and not yet released).
    pub fn bytes(&self) -> u64 {
        self.histories.bytes()
    }

    /// Creates every pipeline of its signal types now, for every writable output format.
    pub fn prepare(&mut self, device: &wgpu::Device, shared: &Shared) {
        for &signal_type in self.signal_types {
            let set = SignalSet::of(signal_type);
            let _ = self.pipelines.temporal(device, shared, set);
            for (_, chain) in set.atrous_chains() {
                let _ = self.pipelines.atrous(device, shared, chain);
                for f in crate::tasks::WRITABLE_OUTPUT_FORMATS {
                    if let Some((out_layout, _)) = self.pipelines.last(device, shared, chain, f) {
                        let _ = self
                            .pipelines
                            .upsample(device, shared, chain, f, &out_layout);
                    }
                }
            }
        }
    }

    /// Records one frame of a validated denoise task of this denoiser (its context has a
    /// history after `sync`; a context without one records nothing).
    pub fn record(
        &mut self,
        rec: &mut Recorder<'_>,
        res: Resources<'_>,
        job: &Job<'_>,
        serial: u64,
    ) {
        let shared = res.shared;
        let Some(h) = self.histories.get_mut(&job.common.context) else {
            return;
        };
        let device = rec.device;
        let set = SignalSet::of(h.input.signal_type);
        let temporal = self.pipelines.temporal(device, shared, set);
        let Some(chains) = self.pipelines.chains(device, shared, set, job) else {
            return; // unreachable: validation admits writable formats only
        };
        let passes = Passes {
            temporal: &temporal,
            chains: &chains,
        };
        record_frame(rec, res, h, job, &passes, serial);
    }
}

/// What every denoiser's frames share: the layouts, the à-trous intermediate and the guides.
pub(super) struct Resources<'a> {
    pub shared: &'a Shared,
    pub scratch: &'a mut Scratch,
    pub guides: &'a mut Guides,
}

/// The pipelines of one frame of a context: its temporal pass and its signals' à-trous chains.
struct Passes<'a> {
    temporal: &'a wgpu::ComputePipeline,
    chains: &'a [Chain],
}

/// Records one frame of `job` on its context's history `h`: the temporal pass, then each
/// signal's à-trous chain; then advances the history.
fn record_frame(
    rec: &mut Recorder<'_>,
    res: Resources<'_>,
    h: &mut History,
    job: &Job<'_>,
    passes: &Passes<'_>,
    serial: u64,
) {
    let c = job.common;
    let settings = method_settings(h.input.method);
    let mut inputs = GBufferInputs::of_denoise(c, job.inputs[0]);
    inputs.viewport = resolve_viewport(c.viewport, job.inputs[0].texture().size());
    let vp = inputs.viewport;
    let (grid_w, grid_h) = grid_size(vp, c.half_resolution_mode);
    let pixels = u64::from(grid_w) * u64::from(grid_h);
    let signal_bytes = pixels * history::signal_record_bytes(h.input.signal_type);
    let (own, fresh) = h.buffers_for(rec.device, pixels);
    let history = own.history.clone();
    let discard = starts_over(h, job, vp, fresh);
    let gbuffer = inputs.params();
    let guides = res.guides.for_frame(
        rec.device,
        rec.encoder,
        &mut h.guide,
        GuideRequest {
            key: guide_key(job, &gbuffer, (grid_w, grid_h)),
            pixels,
            discard,
            serial,
        },
    );
    let buffers = BufferSet {
        guide_prev: guides.prev,
        guide_cur: guides.cur,
        history,
        scratch: res.scratch.get(rec.device, signal_bytes, serial),
    };
    let shared = res.shared;
    let (params, motion_texture) = frame_params(shared, h, job, (vp, discard), settings);
    let params = rec.uniform("kickstart-rt denoise params", &params);
    let gb_params = rec.uniform("kickstart-rt denoise g-buffer", &gbuffer);
    let frame = Frame {
        params: &params,
        groups: (grid_w.div_ceil(TILE), grid_h.div_ceil(TILE)),
        buffers: &buffers,
        history_bytes: signal_bytes,
    };

    let previous_scope = rec.scope;
    rec.scope = "denoise";
    // 1. Temporal accumulation.
    let temporal_inputs = TemporalInputs {
        gbuffer: &inputs,
        gbuffer_params: &gb_params,
        motion: &motion_texture,
    };
    record_temporal(rec, shared, job, &frame, &temporal_inputs, passes.temporal);
    // 2. À-trous iterations, per signal: history → scratch 0 → scratch 1 → … → the output
    // texture (the last iteration writes it; in a block mode the upsample pass does, from the
    // grid).
    let upsample = (c.half_resolution_mode.block_size() > 1).then(|| UpsampleInputs {
        gbuffer: &inputs,
        gbuffer_params: &gb_params,
        viewport_groups: (vp.width.div_ceil(TILE), vp.height.div_ceil(TILE)),
    });
    for chain in passes.chains {
        record_atrous(
            rec,
            shared,
            job,
            &frame,
            chain,
            settings.iterations,
            upsample.as_ref(),
        );
    }
    rec.scope = previous_scope;

    h.frame += 1;
    h.last_viewport = Some(vp);
    h.prev_jitter = c.view.jitter;
    h.prev_mode = c.half_resolution_mode;
    h.last_used = serial;
}

/// What every pass of one frame shares.
struct Frame<'a> {
    /// The frame's `DenoiseParams` uniform.
    params: &'a wgpu::Buffer,
    /// Workgroups of every dispatch.
    groups: (u32, u32),
    buffers: &'a BufferSet,
    /// Bytes of one signal's history.
    history_bytes: u64,
}

/// The buffers one frame of a context binds: its guides (maybe shared), its histories and the
/// shared à-trous scratch.
struct BufferSet {
    guide_prev: wgpu::Buffer,
    guide_cur: wgpu::Buffer,
    /// One per signal.
    history: Vec<wgpu::Buffer>,
    /// The temporal pass's output (a buffer per signal), then the à-trous ping-pong.
    scratch: [wgpu::Buffer; 2],
}

/// What the temporal pass reads besides the signal: the G-buffer and the motion vectors (or a
/// placeholder).
struct TemporalInputs<'a> {
    gbuffer: &'a GBufferInputs<'a>,
    gbuffer_params: &'a wgpu::Buffer,
    motion: &'a TextureInput,
}

/// The frame's `DenoiseParams` and the motion texture to bind (a placeholder without motion
/// vectors); `discard`: the frame starts the history over ([`starts_over`]).
fn frame_params(
    shared: &Shared,
    h: &History,
    job: &Job<'_>,
    (vp, discard): (Viewport, bool),
    settings: MethodSettings,
) -> (DenoiseParams, TextureInput) {
    let c = job.common;
    let mode = c.half_resolution_mode;
    let (grid_w, grid_h) = grid_size(vp, mode);
    let (x, y) = mode.traced_pixel();
    let (prev_x, prev_y) = h.prev_mode.traced_pixel();

    let cam = CameraFrame::new(c.view.world_to_view, c.view.view_to_clip);
    let prev = CameraFrame::new(c.view.prev_world_to_view, c.view.prev_view_to_clip);
    let v4 = |v: glam::DVec3, w: f32| v.as_vec3().extend(w).to_array();
    let (motion_type, motion_scale, motion_texture) = match &c.motion {
        None => (0, glam::Vec3::ZERO, shared.placeholder_texture.clone()),
        Some(m) => (
            match m.motion_type {
                MotionType::RgViewSpace => 1,
                MotionType::RgbWorldSpace => 2,
            },
            m.scale,
            m.texture.clone(),
        ),
    };
    let params = DenoiseParams {
        viewport: [vp.x, vp.y, vp.width, vp.height],
        eye: v4(cam.eye, if cam.perspective { 1.0 } else { 0.0 }),
        forward: v4(cam.forward, 0.0),
        prev_eye: v4(prev.eye, if prev.perspective { 1.0 } else { 0.0 }),
        prev_forward: v4(prev.forward, 0.0),
        jitter: [
            c.view.jitter.x,
            c.view.jitter.y,
            h.prev_jitter.x,
            h.prev_jitter.y,
        ],
        motion_scale: motion_scale.extend(0.0).to_array(),
        kind0: job.kinds[0] as u32,
        kind1: job.kinds.get(1).copied().unwrap_or(job.kinds[0]) as u32,
        signal_count: job.kinds.len() as u32,
        motion_type,
        max_history: settings.max_history,
        discard_history: discard as u32,
        checkerboard: checkerboard_code(mode),
        base_radius: settings.base_radius,
        grid: [grid_w, grid_h, mode.block_size(), 0],
        lattice: [x, y, prev_x, prev_y],
        clip_to_world: cam.clip_to_world.as_mat4().to_cols_array_2d(),
        prev_clip_to_world: prev.clip_to_world.as_mat4().to_cols_array_2d(),
    };
    (params, motion_texture)
}

/// Whether a frame of `job` on `h` starts the history over: on `DenoiseMode::DiscardHistory`, on
/// the context's first frame, when the viewport changes size or the grid its block size, and
/// when its buffers were just allocated (`fresh`).
fn starts_over(h: &History, job: &Job<'_>, vp: Viewport, fresh: bool) -> bool {
    let c = job.common;
    let resized = h
        .last_viewport
        .is_some_and(|l| l.width != vp.width || l.height != vp.height);
    let regridded = h.prev_mode.block_size() != c.half_resolution_mode.block_size();
    c.mode == DenoiseMode::DiscardHistory || h.frame == 0 || resized || regridded || fresh
}

/// What makes the guide of a frame of `job` with G-buffer uniform `gbuffer` on a grid of
/// `grid` pixels: two contexts' frames with equal keys in one task write the same guide.
fn guide_key(job: &Job<'_>, gbuffer: &GBufferParams, grid: (u32, u32)) -> GuideKey {
    let c = job.common;
    let mode = c.half_resolution_mode;
    let (x, y) = mode.traced_pixel();
    let checkerboard = checkerboard_code(mode);
    GuideKey::new(
        gbuffer,
        [
            Some(c.depth.texture.texture()),
            Some(c.normal.texture.texture()),
            c.roughness.texture.as_ref().map(|t| t.texture()),
        ],
        [grid.0, grid.1, mode.block_size(), x, y, checkerboard],
    )
}

/// `DenoiseParams::checkerboard` of `mode`: 0 off, 1 even cells traced, 2 odd ones.
fn checkerboard_code(mode: HalfResolutionMode) -> u32 {
    match mode {
        HalfResolutionMode::Checkerboard => 1,
        HalfResolutionMode::CheckerboardInverted => 2,
        _ => 0,
    }
}

/// The grid the passes work on (see `shaders/denoise/common.wgsl`): the viewport, or one pixel
/// per block in a block mode (the checkerboard modes fill their holes at full resolution).
fn grid_size(vp: Viewport, mode: HalfResolutionMode) -> (u32, u32) {
    let b = mode.block_size();
    (vp.width.div_ceil(b), vp.height.div_ceil(b))
}

/// The temporal pass: decodes the G-buffer into this frame's guide and accumulates each signal
/// into this frame's history from the previous frame's.
fn record_temporal(
    rec: &mut Recorder<'_>,
    shared: &Shared,
    job: &Job<'_>,
    frame: &Frame<'_>,
    inputs: &TemporalInputs<'_>,
    temporal: &wgpu::ComputePipeline,
) {
    let device = rec.device;
    // The second signal's buffer, or a placeholder (`written`: the one bound for writing).
    let second = |set: &Vec<wgpu::Buffer>, written: bool| -> wgpu::Buffer {
        set.get(1)
            .cloned()
            .unwrap_or_else(|| shared.placeholder_buffers[written as usize].clone())
    };
    let input1 = job
        .inputs
        .get(1)
        .map_or_else(|| shared.placeholder_texture.clone(), |t| (*t).clone());
    let g0 = shared
        .gbuffer
        .bind_group(device, inputs.gbuffer_params, inputs.gbuffer);
    let view = wgpu::BindingResource::TextureView;
    let g1 = shared.temporal_inputs.bind_group(
        device,
        &[
            ("dp", frame.params.as_entire_binding()),
            ("dn_motion", view(inputs.motion)),
            ("dn_input0", view(job.inputs[0])),
            ("dn_input1", view(&input1)),
        ],
    );
    let b = frame.buffers;
    let signals = b.history.len();
    let hist_prev1 = second(&b.history, false);
    let hist_cur1 = if signals > 1 {
        b.scratch[1].clone()
    } else {
        shared.placeholder_buffers[1].clone()
    };
    let g2 = shared.temporal_buffers.bind_group(
        device,
        &[
            ("guide_prev", b.guide_prev.as_entire_binding()),
            ("guide_cur", b.guide_cur.as_entire_binding()),
            ("hist_prev0", b.history[0].as_entire_binding()),
            ("hist_prev1", hist_prev1.as_entire_binding()),
            ("hist_cur0", b.scratch[0].as_entire_binding()),
            ("hist_cur1", hist_cur1.as_entire_binding()),
        ],
    );
    rec.dispatch_2d("denoise temporal", temporal, &[&g0, &g1, &g2], frame.groups);
    // This frame's accumulated signals become the history (the previous one is read: the
    // temporal pass could not write it in place).
    for (s, history) in b.history.iter().enumerate() {
        rec.encoder
            .copy_buffer_to_buffer(&b.scratch[s], 0, history, 0, frame.history_bytes);
    }
}

/// What the upsample pass of a block mode reads besides the filtered grid.
struct UpsampleInputs<'a> {
    gbuffer: &'a GBufferInputs<'a>,
    gbuffer_params: &'a wgpu::Buffer,
    /// Workgroups covering the viewport (the other passes cover the grid).
    viewport_groups: (u32, u32),
}

/// The à-trous chain of one signal: `iterations` dispatches from this frame's history through
/// the ping-pong buffers, the last writing the signal's output texture — or, with `upsample`
/// (a block mode), the upsample pass writing it from the last iteration's grid.
#[allow(clippy::too_many_arguments)]
fn record_atrous(
    rec: &mut Recorder<'_>,
    shared: &Shared,
    job: &Job<'_>,
    frame: &Frame<'_>,
    chain: &Chain,
    iterations: u32,
    upsample: Option<&UpsampleInputs<'_>>,
) {
    let device = rec.device;
    let s = chain.signal;
    let [read_placeholder, write_placeholder] = &shared.placeholder_buffers;
    let outputs = chain.out_layout.bind_group(
        device,
        &[(
            "dn_out0",
            wgpu::BindingResource::TextureView(job.outputs[s]),
        )],
    );
    let b = frame.buffers;
    // The scratch is free once the temporal pass's output is in the history.
    let ping_pong = b.scratch.clone();
    let mut src = b.history[s].clone();
    for it in 0..iterations {
        let dst = ping_pong[(it % 2) as usize].clone();
        let step = rec.uniform(
            "kickstart-rt denoise a-trous step",
            &StepParams {
                value: 1 << it,
                first: (it == 0) as u32,
                pad: [0; 2],
            },
        );
        let a0 = shared.atrous_params.bind_group(
            device,
            &[
                ("dp", frame.params.as_entire_binding()),
                ("ap", step.as_entire_binding()),
            ],
        );
        let a1 = shared.atrous_buffers.bind_group(
            device,
            &[
                ("guide", b.guide_cur.as_entire_binding()),
                ("src0", src.as_entire_binding()),
                ("src1", read_placeholder.as_entire_binding()),
                ("dst0", dst.as_entire_binding()),
                ("dst1", write_placeholder.as_entire_binding()),
            ],
        );
        if it + 1 == iterations && upsample.is_none() {
            rec.dispatch_2d(
                "denoise a-trous + output",
                &chain.last,
                &[&a0, &a1, &outputs],
                frame.groups,
            );
        } else {
            rec.dispatch_2d("denoise a-trous", &chain.atrous, &[&a0, &a1], frame.groups);
        }
        src = dst;
    }
    if let Some(up) = upsample {
        let g0 = shared
            .gbuffer
            .bind_group(device, up.gbuffer_params, up.gbuffer);
        let g1 = shared.upsample_inputs.bind_group(
            device,
            &[
                ("dp", frame.params.as_entire_binding()),
                ("guide", b.guide_cur.as_entire_binding()),
                ("src0", src.as_entire_binding()),
            ],
        );
        rec.dispatch_2d(
            "denoise upsample",
            &chain.upsample,
            &[&g0, &g1, &outputs],
            up.viewport_groups,
        );
    }
}

#[cfg(test)]
mod wgsl_tests;
