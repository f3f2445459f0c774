//! The denoisers: spatio-temporal filters for the specular, diffuse, occlusion and shadow
//! signals of the trace tasks, written here in WGSL (DESIGN.md, "Algorithms"; NRD is not used).
//!
//! Each denoise task runs, per [`crate::DenoisingContextHandle`]:
//! 1. **temporal** (`shaders/denoise_temporal.wgsl`): G-buffer decode into a compact guide,
//!    checkerboard resolve, reprojection (motion vectors of either type with their scale, or the
//!    previous matrices when there are none; camera jitter compensated), disocclusion from plane
//!    distance and normal, per-pixel history length, history clamping against ghosting, firefly
//!    clamping, accumulation of the raw signal and of its luminance's second moment;
//! 2. **à-trous** (`shaders/denoise_atrous.wgsl`), 3 (Fast) or 5 (HighQuality) iterations of
//!    an edge-stopping wavelet filter guided by normal, plane distance and the estimated noise
//!    (SVGF), with a radius that follows roughness, hit distance, the occluder distance of a
//!    shadow (its penumbra width) and the history length; one chain of dispatches per signal,
//!    whose last iteration writes the signal's output texture.
//!
//! Every pass is compiled per [`SignalSet`] (constant signal loops, folded kind switches, the
//! record layout: 16 bytes for radiance, 8 for occlusion and shadows).
//!
//! Shadows use the same passes with the visibility as the signal. That makes the filter
//! penumbra-guided: a hard shadow's visibility is deterministic, so once a few frames are
//! accumulated its noise variance is zero and the luminance stop keeps its edge sharp, while a
//! large light's penumbra is noisy and is smoothed over a radius that grows with the occluder
//! distance.
//!
//! History lives in SDK-owned storage buffers (16 or 8 bytes per pixel and buffer; see
//! [`history::History`]), created in the first `build_gpu_task` after the handle is created,
//! released lazily after destruction once no in-flight task uses it, and counted as
//! [`crate::ResourceAllocations::denoiser`]. A viewport of another size than the previous
//! frame's starts the history over, as does [`crate::DenoiseMode::DiscardHistory`].
//!
//! Input and output may be the same texture: no pass reads the input and writes the output.

pub(crate) mod history;

use std::collections::HashMap;

use bytemuck::{Pod, Zeroable};

use crate::context::{DenoisingContextInput, DenoisingMethod, SignalType};
use crate::error::{Error, Result};
use crate::gpu::layout::{float_texture_entry, storage_entry, uniform_entry};
use crate::gpu::shader::{assemble, compute_pipeline_with_layouts};
use crate::gpu::Recorder;
use crate::handles::DenoisingContextHandle;
use crate::tasks::{
    DenoiseMode, DenoiseTaskCommon, HalfResolutionMode, MotionType, RenderTask, TextureInput,
};
use crate::trace::gbuffer::{
    gbuffer_wgsl, resolve_viewport, CameraFrame, GBufferBinder, GBufferInputs,
};
use history::History;

const COMMON_WGSL: &str = include_str!("../../shaders/denoise_common.wgsl");
const TEMPORAL_WGSL: &str = include_str!("../../shaders/denoise_temporal.wgsl");
const ATROUS_WGSL: &str = include_str!("../../shaders/denoise_atrous.wgsl");
const RECORD_RGBA_WGSL: &str = include_str!("../../shaders/denoise_record_rgba.wgsl");
const RECORD_SCALAR_WGSL: &str = include_str!("../../shaders/denoise_record_scalar.wgsl");

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

/// Signal kinds of the shaders (`DN_KIND_*`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Kind {
    Specular = 0,
    Diffuse = 1,
    Occlusion = 2,
    Shadow = 3,
    MultiShadow = 4,
}

impl Kind {
    /// One value per pixel (stored in the 8-byte scalar record).
    fn scalar(self) -> bool {
        matches!(self, Kind::Occlusion | Kind::Shadow | Kind::MultiShadow)
    }
}

/// The signals a context filters together; every pass is compiled per signal set (constant loop
/// bounds, folded kind switches, the record layout).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
struct SignalSet {
    kinds: [Kind; 2],
    count: usize,
}

impl SignalSet {
    fn of(signal_type: SignalType) -> Self {
        let one = |k| SignalSet {
            kinds: [k, k],
            count: 1,
        };
        match signal_type {
            SignalType::Specular => one(Kind::Specular),
            SignalType::Diffuse => one(Kind::Diffuse),
            SignalType::SpecularAndDiffuse => SignalSet {
                kinds: [Kind::Specular, Kind::Diffuse],
                count: 2,
            },
            SignalType::DiffuseOcclusion => one(Kind::Occlusion),
            SignalType::Shadow => one(Kind::Shadow),
            SignalType::MultiShadow => one(Kind::MultiShadow),
        }
    }

    fn scalar(self) -> bool {
        self.kinds[..self.count].iter().all(|k| k.scalar())
    }

    /// The à-trous passes of this set: one chain per signal, each with a single-signal set.
    /// SpecularAndDiffuse filters its signals in separate dispatches: measured on an H100, one
    /// dispatch for both (18 live values per signal across the taps) ran 0.39 ms per iteration
    /// at 1080p, two single-signal dispatches 2 × 0.14 ms, although they read the guide twice.
    fn atrous_chains(self) -> Vec<(usize, SignalSet)> {
        (0..self.count)
            .map(|s| {
                (
                    s,
                    SignalSet {
                        kinds: [self.kinds[s]; 2],
                        count: 1,
                    },
                )
            })
            .collect()
    }

    /// The WGSL in front of a pass of this set: constants, the record layout and (`outputs`:
    /// the last à-trous iteration) the output textures of group 2.
    fn prelude(self, outputs: Option<&[wgpu::TextureFormat]>) -> String {
        let mut s = format!(
            "const DN_SIGNALS: u32 = {}u;\nconst DN_KIND0: u32 = {}u;\nconst DN_KIND1: u32 = {}u;\n",
            self.count, self.kinds[0] as u32, self.kinds[1] as u32
        );
        s += if self.scalar() {
            RECORD_SCALAR_WGSL
        } else {
            RECORD_RGBA_WGSL
        };
        match outputs {
            None => {
                s += "\nconst DN_LAST: bool = false;\n\
                      fn dn_write_output(s: u32, texel: vec2<u32>, v: vec4<f32>) {}\n";
            }
            Some(formats) => {
                s += "\nconst DN_LAST: bool = true;\n";
                for (k, f) in formats.iter().enumerate() {
                    let name = wgsl_format(*f).unwrap_or("rgba16float");
                    s += &format!(
                        "@group(2) @binding({k}) var dn_out{k}: texture_storage_2d<{name}, write>;\n"
                    );
                }
                // Radiance: rgb and the filtered hit distance; occlusion and shadows: the value
                // in every channel.
                s += "fn dn_write_output(s: u32, texel: vec2<u32>, v: vec4<f32>) {\n\
                      var out = v;\n\
                      if dn_kind(s) != DN_KIND_SPECULAR && dn_kind(s) != DN_KIND_DIFFUSE {\n\
                      out = vec4<f32>(v.x);\n\
                      }\n\
                      if s == 0u {\n\
                      textureStore(dn_out0, texel, out);\n\
                      }\n";
                if formats.len() > 1 {
                    s += "if s == 1u {\ntextureStore(dn_out1, texel, out);\n}\n";
                }
                s += "}\n";
            }
        }
        s
    }
}

/// The uniform of `shaders/denoise_common.wgsl` (`DenoiseParams`).
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
}

#[repr(C)]
#[derive(Pod, Zeroable, Clone, Copy, Debug)]
struct StepParams {
    value: u32,
    first: u32,
    pad: [u32; 2],
}

/// A denoise task's signals: inputs, outputs and kinds (one or two).
struct Job<'a> {
    common: &'a DenoiseTaskCommon,
    inputs: Vec<&'a TextureInput>,
    outputs: Vec<&'a TextureInput>,
    kinds: Vec<Kind>,
}

fn job(task: &RenderTask) -> Option<Job<'_>> {
    let one = |common, input, output, kind| {
        Some(Job {
            common,
            inputs: vec![input],
            outputs: vec![output],
            kinds: vec![kind],
        })
    };
    match task {
        RenderTask::DenoiseSpecular(t) => one(&t.common, &t.input, &t.output, Kind::Specular),
        RenderTask::DenoiseDiffuse(t) => one(&t.common, &t.input, &t.output, Kind::Diffuse),
        RenderTask::DenoiseSpecularAndDiffuse(t) => Some(Job {
            common: &t.common,
            inputs: vec![&t.input_specular, &t.input_diffuse],
            outputs: vec![&t.output_specular, &t.output_diffuse],
            kinds: vec![Kind::Specular, Kind::Diffuse],
        }),
        RenderTask::DenoiseDiffuseOcclusion(t) => {
            one(&t.common, &t.input, &t.output, Kind::Occlusion)
        }
        RenderTask::DenoiseShadow(t) => one(&t.common, &t.input, &t.output, Kind::Shadow),
        RenderTask::DenoiseMultiShadow(t) => {
            one(&t.common, &t.input0, &t.output, Kind::MultiShadow)
        }
        _ => None,
    }
}

/// The signal type a denoise task needs its context to have.
fn signal_type_of(task: &RenderTask) -> Option<SignalType> {
    Some(match task {
        RenderTask::DenoiseSpecular(_) => SignalType::Specular,
        RenderTask::DenoiseDiffuse(_) => SignalType::Diffuse,
        RenderTask::DenoiseSpecularAndDiffuse(_) => SignalType::SpecularAndDiffuse,
        RenderTask::DenoiseDiffuseOcclusion(_) => SignalType::DiffuseOcclusion,
        RenderTask::DenoiseShadow(_) => SignalType::Shadow,
        RenderTask::DenoiseMultiShadow(_) => SignalType::MultiShadow,
        _ => return None,
    })
}

/// Checks a denoise task against its context (the task's own fields are checked by
/// `validate::render_task`): the context's signal type, and the viewport within its maximum
/// size.
pub(crate) fn check_task(task: &RenderTask, context: &DenoisingContextInput) -> Result<()> {
    let (Some(needed), Some(job)) = (signal_type_of(task), job(task)) else {
        return Ok(());
    };
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

fn wgsl_format(format: wgpu::TextureFormat) -> Option<&'static str> {
    match format {
        wgpu::TextureFormat::Rgba16Float => Some("rgba16float"),
        wgpu::TextureFormat::Rgba32Float => Some("rgba32float"),
        wgpu::TextureFormat::R32Float => Some("r32float"),
        wgpu::TextureFormat::Rg32Float => Some("rg32float"),
        _ => None,
    }
}

fn layout(
    device: &wgpu::Device,
    label: &str,
    entries: &[wgpu::BindGroupLayoutEntry],
) -> wgpu::BindGroupLayout {
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some(label),
        entries,
    })
}

fn bind(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    resources: &[wgpu::BindingResource<'_>],
) -> wgpu::BindGroup {
    let entries: Vec<wgpu::BindGroupEntry<'_>> = resources
        .iter()
        .enumerate()
        .map(|(i, r)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: r.clone(),
        })
        .collect();
    device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some(label),
        layout,
        entries: &entries,
    })
}

/// The pipelines of one signal set.
struct SetPipelines {
    temporal: wgpu::ComputePipeline,
    atrous: wgpu::ComputePipeline,
    /// The last à-trous iteration per output formats (one per signal): the output textures'
    /// layout (group 2) and the pipeline.
    last: Vec<(
        Vec<wgpu::TextureFormat>,
        wgpu::BindGroupLayout,
        wgpu::ComputePipeline,
    )>,
}

/// Bind group layouts and pipelines of the denoise passes (created on first use).
struct Pipelines {
    gbuffer: GBufferBinder,
    temporal_inputs: wgpu::BindGroupLayout,
    temporal_buffers: wgpu::BindGroupLayout,
    atrous_params: wgpu::BindGroupLayout,
    atrous_buffers: wgpu::BindGroupLayout,
    sets: HashMap<SignalSet, SetPipelines>,
    /// Bound where a pass has no texture (no motion vectors, one signal).
    placeholder_texture: wgpu::TextureView,
    /// Bound where a pass has no second signal: one to read, one to write (a dispatch may not
    /// use one buffer both ways).
    placeholder_buffers: [wgpu::Buffer; 2],
}

impl Pipelines {
    fn new(device: &wgpu::Device) -> Self {
        let gbuffer = GBufferBinder::new(device);
        let temporal_inputs = layout(
            device,
            "kickstart-rt denoise temporal inputs",
            &[
                uniform_entry(0),
                float_texture_entry(1),
                float_texture_entry(2),
                float_texture_entry(3),
            ],
        );
        let temporal_buffers = layout(
            device,
            "kickstart-rt denoise temporal buffers",
            &[
                storage_entry(0, true),
                storage_entry(1, false),
                storage_entry(2, true),
                storage_entry(3, true),
                storage_entry(4, false),
                storage_entry(5, false),
            ],
        );
        let atrous_params = layout(
            device,
            "kickstart-rt denoise a-trous params",
            &[uniform_entry(0), uniform_entry(1)],
        );
        let atrous_buffers = layout(
            device,
            "kickstart-rt denoise a-trous buffers",
            &[
                storage_entry(0, true),
                storage_entry(1, true),
                storage_entry(2, true),
                storage_entry(3, false),
                storage_entry(4, false),
            ],
        );
        let placeholder_texture = device
            .create_texture(&wgpu::TextureDescriptor {
                label: Some("kickstart-rt denoise placeholder"),
                size: wgpu::Extent3d {
                    width: 1,
                    height: 1,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba8Unorm,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            })
            .create_view(&Default::default());
        let placeholder_buffer = || {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("kickstart-rt denoise placeholder"),
                size: history::RECORD_BYTES,
                usage: wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        };
        Pipelines {
            gbuffer,
            temporal_inputs,
            temporal_buffers,
            atrous_params,
            atrous_buffers,
            sets: HashMap::new(),
            placeholder_texture,
            placeholder_buffers: [placeholder_buffer(), placeholder_buffer()],
        }
    }

    /// The temporal and à-trous pipelines of `set`.
    fn set(&mut self, device: &wgpu::Device, set: SignalSet) -> &mut SetPipelines {
        let (gbuffer, inputs, buffers, params, atrous_buffers) = (
            &self.gbuffer,
            &self.temporal_inputs,
            &self.temporal_buffers,
            &self.atrous_params,
            &self.atrous_buffers,
        );
        self.sets.entry(set).or_insert_with(|| {
            let prelude = set.prelude(None);
            SetPipelines {
                temporal: compute_pipeline_with_layouts(
                    device,
                    "kickstart-rt denoise temporal",
                    &assemble(&[&gbuffer_wgsl(0), &prelude, COMMON_WGSL, TEMPORAL_WGSL]),
                    "main",
                    &[gbuffer.layout(), inputs, buffers],
                ),
                atrous: compute_pipeline_with_layouts(
                    device,
                    "kickstart-rt denoise a-trous",
                    &assemble(&[&prelude, COMMON_WGSL, ATROUS_WGSL]),
                    "main",
                    &[params, atrous_buffers],
                ),
                last: Vec::new(),
            }
        })
    }

    /// The last à-trous iteration of `set` writing textures of `formats` (one per signal; each
    /// one of the writable output formats): its output layout and pipeline.
    fn last(
        &mut self,
        device: &wgpu::Device,
        set: SignalSet,
        formats: &[wgpu::TextureFormat],
    ) -> Option<(wgpu::BindGroupLayout, wgpu::ComputePipeline)> {
        if formats.iter().any(|f| wgsl_format(*f).is_none()) {
            return None;
        }
        let params = self.atrous_params.clone();
        let buffers = self.atrous_buffers.clone();
        let sp = self.set(device, set);
        if let Some((_, l, p)) = sp.last.iter().find(|(f, _, _)| f == formats) {
            return Some((l.clone(), p.clone()));
        }
        let entries: Vec<wgpu::BindGroupLayoutEntry> = formats
            .iter()
            .enumerate()
            .map(|(k, format)| wgpu::BindGroupLayoutEntry {
                binding: k as u32,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::StorageTexture {
                    access: wgpu::StorageTextureAccess::WriteOnly,
                    format: *format,
                    view_dimension: wgpu::TextureViewDimension::D2,
                },
                count: None,
            })
            .collect();
        let out_layout = layout(device, "kickstart-rt denoise output", &entries);
        let pipeline = compute_pipeline_with_layouts(
            device,
            "kickstart-rt denoise a-trous (last, output)",
            &assemble(&[&set.prelude(Some(formats)), COMMON_WGSL, ATROUS_WGSL]),
            "main",
            &[&params, &buffers, &out_layout],
        );
        sp.last
            .push((formats.to_vec(), out_layout.clone(), pipeline.clone()));
        Some((out_layout, pipeline))
    }
}

/// Every denoising context's history, and the denoise passes.
pub(crate) struct Denoisers {
    device: wgpu::Device,
    pipelines: Option<Pipelines>,
    histories: HashMap<DenoisingContextHandle, History>,
    /// Histories of destroyed contexts, released once no in-flight task can use them.
    retired: Vec<History>,
}

impl Denoisers {
    /// No contexts, no pipelines yet.
    pub fn new(device: &wgpu::Device) -> Self {
        Denoisers {
            device: device.clone(),
            pipelines: None,
            histories: HashMap::new(),
            retired: Vec::new(),
        }
    }

    fn pipelines(&mut self) -> &mut Pipelines {
        let device = &self.device;
        self.pipelines.get_or_insert_with(|| Pipelines::new(device))
    }

    /// Creates every pipeline now.
    pub fn prepare_pipelines(&mut self) {
        let device = self.device.clone();
        let p = self.pipelines();
        let formats = crate::WRITABLE_OUTPUT_FORMATS;
        for signal_type in [
            SignalType::Specular,
            SignalType::Diffuse,
            SignalType::SpecularAndDiffuse,
            SignalType::DiffuseOcclusion,
            SignalType::Shadow,
            SignalType::MultiShadow,
        ] {
            let set = SignalSet::of(signal_type);
            let _ = p.set(&device, set);
            for (_, chain) in set.atrous_chains() {
                for f in formats {
                    let _ = p.last(&device, chain, &[f]);
                }
            }
        }
    }

    /// Follows the live contexts: creates the history of new ones, retires destroyed ones.
    pub fn sync(&mut self, live: &[(DenoisingContextHandle, DenoisingContextInput)]) {
        let dead: Vec<DenoisingContextHandle> = self
            .histories
            .keys()
            .filter(|h| !live.iter().any(|(l, _)| l == *h))
            .copied()
            .collect();
        for h in dead {
            if let Some(history) = self.histories.remove(&h) {
                self.retired.push(history);
            }
        }
        for (h, input) in live {
            if !self.histories.contains_key(h) {
                self.histories
                    .insert(*h, History::new(&self.device, *input));
            }
        }
    }

    /// Releases retired histories whose last task is older than `oldest_in_flight`.
    pub fn collect(&mut self, oldest_in_flight: u64) {
        self.retired.retain(|h| h.last_used >= oldest_in_flight);
    }

    /// GPU bytes held (live and not yet released).
    pub fn bytes(&self) -> u64 {
        self.histories
            .values()
            .chain(self.retired.iter())
            .map(History::bytes)
            .sum()
    }

    /// Records a validated denoise task (`check_task` passed; its context has a history after
    /// `sync`). Other tasks are ignored.
    pub fn record(&mut self, rec: &mut Recorder<'_>, task: &RenderTask, serial: u64) {
        let Some(job) = job(task) else {
            return;
        };
        let device = self.device.clone();
        let mut pipelines = self
            .pipelines
            .take()
            .unwrap_or_else(|| Pipelines::new(&device));
        if let Some(history) = self.histories.get_mut(&job.common.context) {
            record_job(rec, &mut pipelines, history, &job, serial);
        }
        self.pipelines = Some(pipelines);
    }
}

fn record_job(
    rec: &mut Recorder<'_>,
    p: &mut Pipelines,
    h: &mut History,
    job: &Job<'_>,
    serial: u64,
) {
    let device = rec.device;
    let c = job.common;
    let settings = method_settings(h.input.method);
    let set = SignalSet::of(h.input.signal_type);
    let temporal = p.set(device, set).temporal.clone();
    // The à-trous chain of each signal: its pipelines (single-signal sets; see `SignalSet::
    // atrous_chains`), the last iteration's output layout and pipeline.
    let mut chains = Vec::new();
    for (s, chain_set) in set.atrous_chains() {
        let format = job.outputs[s].texture().format();
        let Some((out_layout, last)) = p.last(device, chain_set, &[format]) else {
            return; // unreachable: validation admits writable formats only
        };
        let atrous = p.set(device, chain_set).atrous.clone();
        chains.push((s, atrous, out_layout, last));
    }
    let mut inputs = GBufferInputs::of_denoise(c, job.inputs[0]);
    inputs.viewport = resolve_viewport(c.viewport, job.inputs[0].texture().size());
    let vp = inputs.viewport;
    let resized = h
        .last_viewport
        .is_some_and(|l| l.width != vp.width || l.height != vp.height);
    let discard = c.mode == DenoiseMode::DiscardHistory || h.frame == 0 || resized;

    let cam = CameraFrame::new(c.view.world_to_view, c.view.view_to_clip);
    let prev = CameraFrame::new(c.view.prev_world_to_view, c.view.prev_view_to_clip);
    let v4 = |v: glam::DVec3, w: f32| v.as_vec3().extend(w).to_array();
    let (motion_type, motion_scale, motion_texture) = match &c.motion {
        None => (0, glam::Vec3::ZERO, p.placeholder_texture.clone()),
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
        checkerboard: match c.half_resolution_mode {
            HalfResolutionMode::Off => 0,
            HalfResolutionMode::Checkerboard => 1,
            HalfResolutionMode::CheckerboardInverted => 2,
        },
        base_radius: settings.base_radius,
    };
    let params = rec.uniform("kickstart-rt denoise params", &params);
    let gb_params = rec.uniform("kickstart-rt denoise g-buffer", &inputs.params());

    let cur = (h.frame % 2) as usize;
    let prv = 1 - cur;
    // The second signal's buffer, or a placeholder (`written`: the one bound for writing).
    let second = |set: &Vec<wgpu::Buffer>, written: bool| -> wgpu::Buffer {
        set.get(1)
            .cloned()
            .unwrap_or_else(|| p.placeholder_buffers[written as usize].clone())
    };
    let input1 = job
        .inputs
        .get(1)
        .map_or_else(|| p.placeholder_texture.clone(), |t| (*t).clone());

    let groups = (vp.width.div_ceil(TILE), vp.height.div_ceil(TILE));
    let previous_scope = rec.scope;
    rec.scope = "denoise";

    // 1. Temporal accumulation.
    let g0 = p.gbuffer.bind_group(device, &gb_params, &inputs);
    let g1 = bind(
        device,
        "kickstart-rt denoise temporal inputs",
        &p.temporal_inputs,
        &[
            params.as_entire_binding(),
            wgpu::BindingResource::TextureView(&motion_texture),
            wgpu::BindingResource::TextureView(job.inputs[0]),
            wgpu::BindingResource::TextureView(&input1),
        ],
    );
    let hist_prev1 = second(&h.history[prv], false);
    let hist_cur1 = second(&h.history[cur], true);
    let g2 = bind(
        device,
        "kickstart-rt denoise temporal buffers",
        &p.temporal_buffers,
        &[
            h.guides[prv].as_entire_binding(),
            h.guides[cur].as_entire_binding(),
            h.history[prv][0].as_entire_binding(),
            hist_prev1.as_entire_binding(),
            h.history[cur][0].as_entire_binding(),
            hist_cur1.as_entire_binding(),
        ],
    );
    rec.dispatch_2d("denoise temporal", &temporal, &[&g0, &g1, &g2], groups);

    // 2. À-trous iterations, per signal: history → temp[0] → temp[1] → … → the output texture
    // (the last iteration writes it).
    let [read_placeholder, write_placeholder] = p.placeholder_buffers.clone();
    for (s, atrous, out_layout, last) in &chains {
        let s = *s;
        let outputs = bind(
            device,
            "kickstart-rt denoise output",
            out_layout,
            &[wgpu::BindingResource::TextureView(job.outputs[s])],
        );
        let mut src = h.history[cur][s].clone();
        for it in 0..settings.iterations {
            let dst = h.temp[(it % 2) as usize][s].clone();
            let step = rec.uniform(
                "kickstart-rt denoise a-trous step",
                &StepParams {
                    value: 1 << it,
                    first: (it == 0) as u32,
                    pad: [0; 2],
                },
            );
            let a0 = bind(
                device,
                "kickstart-rt denoise a-trous params",
                &p.atrous_params,
                &[params.as_entire_binding(), step.as_entire_binding()],
            );
            let a1 = bind(
                device,
                "kickstart-rt denoise a-trous buffers",
                &p.atrous_buffers,
                &[
                    h.guides[cur].as_entire_binding(),
                    src.as_entire_binding(),
                    read_placeholder.as_entire_binding(),
                    dst.as_entire_binding(),
                    write_placeholder.as_entire_binding(),
                ],
            );
            if it + 1 == settings.iterations {
                rec.dispatch_2d(
                    "denoise a-trous + output",
                    last,
                    &[&a0, &a1, &outputs],
                    groups,
                );
            } else {
                rec.dispatch_2d("denoise a-trous", atrous, &[&a0, &a1], groups);
            }
            src = dst;
        }
    }
    rec.scope = previous_scope;

    h.frame += 1;
    h.last_viewport = Some(vp);
    h.prev_jitter = c.view.jitter;
    h.last_used = serial;
}
