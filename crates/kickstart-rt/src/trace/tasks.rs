//! The trace tasks' passes: specular, diffuse, ambient occlusion, shadows and multi-light
//! shadows. One compute dispatch per task over the viewport (or its
//! checkerboard half), one ray (per light) per pixel. Semantics of every output:
//! docs/trace-tasks.md.
//!
//! Bind groups: 0 the scene (traversal), 1 the G-buffer ([`GBufferBinder`]), 2 the task's
//! parameters, blue noise, environment map, direct lighting and outputs, 3 (specular and diffuse)
//! the lighting cache's sampling bindings. Pipelines are created
//! per (task kind, output formats) on first use, with explicit layouts (the shared WGSL modules
//! declare bindings some passes do not use).

use super::gbuffer::{GBufferBinder, GBufferInputs};
use super::lights::{pack_lights, GpuLight};
use super::sampling::blue_noise_texture;
use crate::device::TraversalBackend;
use crate::error::{Error, Result};
use crate::gpu::compose::ShaderLibrary;
use crate::gpu::layout::BoundLayout;
use crate::gpu::reflect::{ReflectedLayout, ReflectedShader, ShaderReflection};
use crate::gpu::shader::traversal_pipeline;
use crate::gpu::Recorder;
use crate::scene::traversal::{self, LeafTest, SceneBuffers};
use crate::tasks::InstanceInclusionMask;
use crate::tasks::*;
use bytemuck::{Pod, Zeroable};

/// Invocations per workgroup (`RT_WORKGROUP_SIZE` of the traversal module): one workgroup traces
/// one `TILE` × `TILE` tile of pixels (`tr_pixel` in `shaders/trace/common.wgsl`).
const WORKGROUP_SIZE: u32 = 64;

/// Side of the square pixel tile one workgroup traces (`TR_TILE` of `trace/common.wgsl`).
const TILE: u32 = 8;

/// Workgroups a trace dispatch needs: one per tile of the traced grid (the viewport, its
/// half-width in a checkerboard mode, a pixel per block in a block mode). `None` when the
/// tiles' invocations would not fit a u32 (the shader indexes them with one).
fn traced_tiles(width: u32, height: u32, mode: HalfResolutionMode) -> Option<u32> {
    let (grid_w, grid_h) = mode.traced_grid(width, height);
    let tiles = u64::from(grid_w.div_ceil(TILE)) * u64::from(grid_h.div_ceil(TILE));
    u32::try_from(tiles * u64::from(WORKGROUP_SIZE))
        .ok()
        .map(|_| tiles as u32)
}

/// Secondary rays start past `T_MIN_PER_VIEW_DISTANCE × view distance` (with or without a ray
/// offset): depth-reconstructed positions carry an error that grows with the view distance.
pub const T_MIN_PER_VIEW_DISTANCE: f32 = 1e-4;

/// Which pass a trace task runs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum TraceKind {
    AmbientOcclusion,
    Shadow,
    MultiShadow,
    Specular,
    Diffuse,
}

impl TraceKind {
    /// The pass's label and timing name.
    fn label(self) -> &'static str {
        match self {
            TraceKind::AmbientOcclusion => "trace ambient occlusion",
            TraceKind::Shadow => "trace shadow",
            TraceKind::MultiShadow => "trace multi shadow",
            TraceKind::Specular => "trace specular",
            TraceKind::Diffuse => "trace diffuse",
        }
    }

    /// Decorrelates the noise of tasks traced in the same frame.
    fn salt(self) -> u32 {
        match self {
            TraceKind::AmbientOcclusion => 1,
            TraceKind::Shadow => 2,
            TraceKind::MultiShadow => 3,
            TraceKind::Specular => 4,
            TraceKind::Diffuse => 5,
        }
    }

    /// Whether the pass reads the lighting cache (bind group 3).
    fn reads_cache(self) -> bool {
        matches!(self, TraceKind::Specular | TraceKind::Diffuse)
    }
}

/// The uniform of `shaders/trace/common.wgsl` (`TraceParams`).
#[repr(C)]
#[derive(Pod, Zeroable, Clone, Copy)]
struct TraceParams {
    mode: [u32; 4],
    lengths: [f32; 4],
    misc: [u32; 4],
    offset_wp: [f32; 4],
    offset_cd: [f32; 4],
    lights: [GpuLight; MAX_MULTI_SHADOW_LIGHTS],
}

const FLAG_ENV: u32 = 1;
const FLAG_DIRECT_LIGHTING: u32 = 2;
const FLAG_BILINEAR: u32 = 4;
const FLAG_DEMODULATE: u32 = 8;
const FLAG_FIRST_HIT: u32 = 16;
const FLAG_DISNEY: u32 = 32;
const FLAG_AO: u32 = 64;

/// The WGSL storage format name of a writable output format.
fn wgsl_format(format: wgpu::TextureFormat) -> Option<&'static str> {
    match format {
        wgpu::TextureFormat::Rgba16Float => Some("rgba16float"),
        wgpu::TextureFormat::Rgba32Float => Some("rgba32float"),
        wgpu::TextureFormat::R32Float => Some("r32float"),
        wgpu::TextureFormat::Rg32Float => Some("rg32float"),
        _ => None,
    }
}

/// One cached pipeline.
struct Pipeline {
    kind: TraceKind,
    formats: (wgpu::TextureFormat, Option<wgpu::TextureFormat>),
    /// The traversal build it traces with.
    leaf: LeafTest,
    pipeline: wgpu::ComputePipeline,
    /// Group 2 (parameters, textures, outputs) as the entry point uses it.
    io_layout: ReflectedLayout,
    /// Whether the pipeline came from our own SPIR-V (no stack zero fill).
    #[cfg_attr(not(test), allow(dead_code))] // tests: a silent fallback to WGSL must fail them
    own_spirv: bool,
}

/// What one trace task asks of its pass.
#[derive(Clone, Copy)]
pub(crate) struct Job<'a> {
    kind: TraceKind,
    common: &'a TraceTaskCommon,
    out0: &'a TextureInput,
    out1: Option<&'a TextureInput>,
    ao_radius: f32,
    lights: &'a [LightInfo],
    first_hit: bool,
    demodulate: bool,
    disney: bool,
    /// The diffuse pass writes ambient occlusion (`out1`) from its own rays.
    ambient_occlusion: bool,
}

/// The trace-task passes of one context.
pub(crate) struct TracePasses {
    scene_layout: BoundLayout,
    gbuffer: GBufferBinder,
    blue_noise: wgpu::TextureView,
    placeholder: wgpu::TextureView,
    /// Group 3 of the radiance passes: the lighting cache's sampling bindings.
    cache_layout: ReflectedLayout,
    /// The shader modules (unit tests stand a simple module in for the lighting cache's
    /// `cache/sample`).
    library: ShaderLibrary,
    /// The traversal the passes are composed with.
    backend: TraversalBackend,
    pipelines: Vec<Pipeline>,
}

impl TracePasses {
    /// Creates the layouts and the blue-noise tile (pipelines come on first use).
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, backend: TraversalBackend) -> Self {
        let gbuffer = GBufferBinder::new(device);
        // Absent optional textures bind the G-buffer's 1×1 placeholder.
        let placeholder = gbuffer.placeholder().clone();
        TracePasses {
            scene_layout: SceneBuffers::layout(device, backend),
            gbuffer,
            blue_noise: blue_noise_texture(device, queue),
            placeholder,
            cache_layout: ReflectedLayout::new(
                device,
                "kickstart-rt trace cache",
                ReflectedShader::compose(&["cache/sample"], &crate::cache::sample_params(3, false))
                    .reflection(),
                3,
            ),
            library: traversal::library(backend),
            backend,
            pipelines: Vec::new(),
        }
    }

    /// Creates the pipelines of every kind for the common output formats (Rgba16Float, and
    /// R32Float for the single-channel outputs) with the traversal build `leaf`, so the first
    /// frame does not stall.
    pub fn prepare(&mut self, device: &wgpu::Device, leaf: LeafTest) {
        use wgpu::TextureFormat as F;
        for (kind, f0, f1) in [
            (TraceKind::AmbientOcclusion, F::Rgba16Float, None),
            (TraceKind::AmbientOcclusion, F::R32Float, None),
            (TraceKind::Shadow, F::Rgba16Float, None),
            (TraceKind::Shadow, F::R32Float, None),
            (TraceKind::MultiShadow, F::Rgba16Float, Some(F::Rgba16Float)),
            (TraceKind::Specular, F::Rgba16Float, None),
            (TraceKind::Specular, F::Rgba16Float, Some(F::Rgba16Float)),
            (TraceKind::Diffuse, F::Rgba16Float, None),
            (TraceKind::Diffuse, F::Rgba16Float, Some(F::Rgba16Float)),
            (TraceKind::Diffuse, F::Rgba16Float, Some(F::R32Float)),
        ] {
            // Every format listed has a WGSL name, so this cannot fail.
            let _ = self.pipeline(device, kind, (f0, f1), leaf);
        }
    }

    /// The pipeline of `kind` writing `formats` with the traversal build `leaf`, created on
    /// first use.
    fn pipeline(
        &mut self,
        device: &wgpu::Device,
        kind: TraceKind,
        formats: (wgpu::TextureFormat, Option<wgpu::TextureFormat>),
        leaf: LeafTest,
    ) -> Result<usize> {
        if let Some(i) = self
            .pipelines
            .iter()
            .position(|p| p.kind == kind && p.formats == formats && p.leaf == leaf)
        {
            return Ok(i);
        }
        let mut library = self.library.clone();
        leaf.apply(&mut library);
        let (source, entry) = trace_wgsl(&library, kind, formats)?;
        let reflection = ShaderReflection::new(&source)
            .unwrap_or_else(|e| panic!("{}: composed WGSL is invalid: {e}", kind.label()));
        // Group 2 as the entry point uses it (a shadow pass declares output1 it may not write).
        let io =
            ReflectedLayout::of_entry_point(device, "kickstart-rt trace io", &reflection, entry, 2);
        let mut layouts = vec![self.scene_layout.group(), self.gbuffer.group(), io.group()];
        if kind.reads_cache() {
            layouts.push(self.cache_layout.group());
        }
        // SAFETY: with naga's checks on, only the dropped zero fill needs an argument: the
        // traversal reads `rt_stack` only below its stack pointer, where it wrote first.
        let (pipeline, own_spirv) = unsafe {
            traversal_pipeline(
                device,
                kind.label(),
                &source,
                entry,
                &layouts,
                wgpu::ShaderRuntimeChecks::checked(),
                traversal::uninitialized(self.backend),
            )
        };
        self.pipelines.push(Pipeline {
            kind,
            formats,
            leaf,
            pipeline,
            io_layout: io,
            own_spirv,
        });
        Ok(self.pipelines.len() - 1)
    }

    /// Records a trace task the plan resolved ([`Self::job`], [`Self::check`]). `cache` are the
    /// lighting cache's sampling bindings by name (`DirectLightingCache::sample_resources`).
    pub fn record(
        &mut self,
        rec: &mut Recorder<'_>,
        scene: &SceneBuffers<'_>,
        cache: &[(&str, wgpu::BindingResource<'_>)],
        job: &Job<'_>,
    ) {
        self.record_job(rec, scene, cache, job)
    }

    /// The job of `task`: which pass records it, with what; `None` for a task this module does
    /// not record with its default output (debug views go elsewhere).
    pub fn job(task: &RenderTask) -> Option<Job<'_>> {
        Some(match task {
            RenderTask::TraceSpecular(t) => Job {
                kind: TraceKind::Specular,
                common: &t.common,
                out0: &t.output,
                out1: t
                    .demodulation_output
                    .as_ref()
                    .filter(|_| t.demodulate_specular),
                ao_radius: 0.0,
                lights: &[],
                first_hit: false,
                demodulate: t.demodulate_specular,
                disney: false,
                ambient_occlusion: false,
            },
            RenderTask::TraceDiffuse(t) => Job {
                kind: TraceKind::Diffuse,
                common: &t.common,
                out0: &t.output,
                out1: t.ambient_occlusion.as_ref().map(|a| &a.output),
                ao_radius: t.ambient_occlusion.as_ref().map_or(0.0, |a| a.ao_radius),
                lights: &[],
                first_hit: false,
                demodulate: false,
                disney: t.diffuse_brdf == DiffuseBrdf::NormalizedDisney,
                ambient_occlusion: t.ambient_occlusion.is_some(),
            },
            RenderTask::TraceAmbientOcclusion(t) => Job {
                kind: TraceKind::AmbientOcclusion,
                common: &t.common,
                out0: &t.output,
                out1: None,
                ao_radius: t.ao_radius,
                lights: &[],
                first_hit: false,
                demodulate: false,
                disney: false,
                ambient_occlusion: false,
            },
            RenderTask::TraceShadow(t) => Job {
                kind: TraceKind::Shadow,
                common: &t.common,
                out0: &t.output,
                out1: None,
                ao_radius: 0.0,
                lights: std::slice::from_ref(&t.light),
                first_hit: t.enable_first_hit_and_end_search,
                demodulate: false,
                disney: false,
                ambient_occlusion: false,
            },
            RenderTask::TraceMultiShadow(t) => Job {
                kind: TraceKind::MultiShadow,
                common: &t.common,
                out0: &t.output0,
                out1: Some(&t.output1),
                ao_radius: 0.0,
                lights: &t.lights,
                first_hit: t.enable_first_hit_and_end_search,
                demodulate: false,
                disney: false,
                ambient_occlusion: false,
            },
            _ => return None,
        })
    }

    /// Refuses a job whose viewport has more tiles than one dispatch can run (the plan's
    /// check, so that recording it cannot fail).
    pub fn check(job: &Job<'_>) -> Result<()> {
        let vp = GBufferInputs::of_trace(job.common, job.out0).viewport;
        match traced_tiles(vp.width, vp.height, job.common.half_resolution_mode) {
            Some(_) => Ok(()),
            None => Err(Error::input(
                job.kind.label(),
                "common.viewport",
                vp,
                "too many pixels",
            )),
        }
    }

    fn record_job(
        &mut self,
        rec: &mut Recorder<'_>,
        scene: &SceneBuffers<'_>,
        cache: &[(&str, wgpu::BindingResource<'_>)],
        job: &Job<'_>,
    ) {
        let c = job.common;
        let formats = (
            job.out0.texture().format(),
            job.out1.map(|t| t.texture().format()),
        );
        // validate::render_task admits only WRITABLE_OUTPUT_FORMATS, which all have WGSL names.
        let index = self
            .pipeline(rec.device, job.kind, formats, scene.leaf_test())
            .expect("a validated output format has a pipeline");
        let inputs = GBufferInputs::of_trace(c, job.out0);
        let vp = inputs.viewport;
        let tiles = traced_tiles(vp.width, vp.height, c.half_resolution_mode)
            .expect("the plan checked the viewport's tiles (TracePasses::check)");
        let params = trace_params(job);
        let gb_params = rec.uniform("kickstart-rt g-buffer params", &inputs.params());
        let tp = rec.uniform("kickstart-rt trace params", &params);
        let device = rec.device;
        let gb_group = self.gbuffer.bind_group(device, &gb_params, &inputs);
        let p = &self.pipelines[index];
        let scene_group = scene.bind_group(rec.device, &p.pipeline);
        let env = c.environment_map.as_ref().unwrap_or(&self.placeholder);
        let direct = c.direct_lighting.as_ref().unwrap_or(&self.placeholder);
        let view = wgpu::BindingResource::TextureView;
        let mut io = vec![
            ("tp", tp.as_entire_binding()),
            ("tr_blue_noise", view(&self.blue_noise)),
            ("tr_env", view(env)),
            ("tr_direct_lighting", view(direct)),
            ("out0", view(job.out0)),
        ];
        io.extend(job.out1.map(|o| ("out1", view(o))));
        let io_group = p.io_layout.bind_group(device, &io);
        let mut groups = vec![&scene_group, &gb_group, &io_group];
        let cache_group;
        if job.kind.reads_cache() {
            cache_group = self.cache_layout.bind_group(device, cache);
            groups.push(&cache_group);
        }
        rec.dispatch(job.kind.label(), &p.pipeline, &groups, tiles);
    }
}

/// The WGSL of the pass of `kind` writing `formats`, composed from `library`, and its entry
/// point. Specular and diffuse read the lighting cache's sampling module at group 3. An output
/// format without a WGSL name is refused.
fn trace_wgsl(
    library: &ShaderLibrary,
    kind: TraceKind,
    formats: (wgpu::TextureFormat, Option<wgpu::TextureFormat>),
) -> Result<(String, &'static str)> {
    let name = |f: wgpu::TextureFormat, field: &str| {
        wgsl_format(f).ok_or_else(|| {
            Error::input(
                kind.label(),
                field.to_string(),
                f,
                "must be one of WRITABLE_OUTPUT_FORMATS",
            )
        })
    };
    let f0 = name(formats.0, "output")?;
    let f1 = formats.1.map(|f| name(f, "output1")).transpose()?;
    let mut params = vec![("GBUFFER_GROUP", "1"), ("OUTPUT0_FORMAT", f0)];
    let (roots, entry): (&[&str], _) = match kind {
        TraceKind::AmbientOcclusion => (&["trace/ao"], "main"),
        TraceKind::Shadow | TraceKind::MultiShadow => {
            // The single-light pass never writes output1; its declaration needs a format.
            params.push(("OUTPUT1_FORMAT", f1.unwrap_or("r32float")));
            let entry = if kind == TraceKind::Shadow {
                "shadow"
            } else {
                "multi_shadow"
            };
            (&["trace/shadow"], entry)
        }
        TraceKind::Specular | TraceKind::Diffuse => {
            params.extend(crate::cache::sample_params(3, false));
            let roots: &[&str] = match f1 {
                Some(f) => {
                    params.push(("OUTPUT1_FORMAT", f));
                    &["trace/radiance", "trace/second_output/texture"]
                }
                None => &["trace/radiance", "trace/second_output/none"],
            };
            let entry = if kind == TraceKind::Specular {
                "specular"
            } else {
                "diffuse"
            };
            (roots, entry)
        }
    };
    let source = library
        .compose(roots, &params)
        .unwrap_or_else(|e| panic!("{}: {e}", kind.label()));
    Ok((source, entry))
}

/// The pass uniform of `job`.
fn trace_params(job: &Job<'_>) -> TraceParams {
    let c = job.common;
    let mut flags = 0;
    if c.environment_map.is_some() {
        flags |= FLAG_ENV;
    }
    if c.direct_lighting.is_some() {
        flags |= FLAG_DIRECT_LIGHTING;
    }
    if c.use_bilinear_sampling {
        flags |= FLAG_BILINEAR;
    }
    if job.first_hit {
        flags |= FLAG_FIRST_HIT;
    }
    if job.demodulate {
        flags |= FLAG_DEMODULATE;
    }
    if job.disney {
        flags |= FLAG_DISNEY;
    }
    if job.ambient_occlusion {
        flags |= FLAG_AO;
    }
    let o = &c.ray_offset;
    TraceParams {
        mode: [
            c.half_resolution_mode.shader_code(),
            match c.debug_parameters.random_number_generator {
                RandomNumberGenerator::BlueNoise => 0,
                RandomNumberGenerator::Xorshift => 1,
            },
            c.debug_parameters.frame_index,
            flags,
        ],
        lengths: [
            c.max_ray_length.min(f32::MAX),
            job.ao_radius,
            T_MIN_PER_VIEW_DISTANCE,
            0.0,
        ],
        misc: [
            match o.offset_type {
                RayOffsetType::Disabled => 0,
                RayOffsetType::WorldPosition => 1,
                RayOffsetType::CamDistance => 2,
            },
            job.lights.len() as u32,
            InstanceInclusionMask::VISIBLE_IN_RT.0,
            job.kind.salt(),
        ],
        offset_wp: [
            o.world_position_threshold,
            o.world_position_float_scale,
            o.world_position_int_scale,
            0.0,
        ],
        offset_cd: [
            o.cam_distance_constant,
            o.cam_distance_linear,
            o.cam_distance_quadratic,
            0.0,
        ],
        lights: pack_lights(job.lights),
    }
}

#[cfg(test)]
mod tests;

/// Every trace pass kind.
const KINDS: [TraceKind; 5] = [
    TraceKind::AmbientOcclusion,
    TraceKind::Shadow,
    TraceKind::MultiShadow,
    TraceKind::Specular,
    TraceKind::Diffuse,
];

/// The second outputs a pass of `kind` can write (`TracePasses::record`): the specular's
/// demodulation output (when demodulating), the diffuse's ambient occlusion, the multi-shadow's
/// `output1`.
fn second_outputs(kind: TraceKind) -> Vec<Option<wgpu::TextureFormat>> {
    let writable = WRITABLE_OUTPUT_FORMATS.map(Some);
    match kind {
        TraceKind::AmbientOcclusion | TraceKind::Shadow => vec![None],
        TraceKind::MultiShadow => writable.to_vec(),
        TraceKind::Specular | TraceKind::Diffuse => [None].into_iter().chain(writable).collect(),
    }
}

/// The WGSL of every trace pass the SDK can create with `backend` (kind × output formats ×
/// traversal build), labelled.
pub(crate) fn shader_variants(backend: TraversalBackend) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for &leaf in LeafTest::all(backend) {
        let mut library = traversal::library(backend);
        leaf.apply(&mut library);
        for kind in KINDS {
            for f0 in WRITABLE_OUTPUT_FORMATS {
                for f1 in second_outputs(kind) {
                    // Every writable format has a WGSL name, so this cannot fail.
                    if let Ok((source, _)) = trace_wgsl(&library, kind, (f0, f1)) {
                        let label = format!("{} ({f0:?}, {f1:?}, {leaf:?})", kind.label());
                        out.push((label, source));
                    }
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod wgsl_tests {
    //! Every pass variant `TracePasses` can create, validated with naga without a device, and
    //! the uniform against the WGSL.
    use super::*;
    use crate::gpu::wgsl_check::{assert_wgsl_layout, validate};
    use wgpu::TextureFormat as F;

    #[test]
    fn every_trace_task_variant_validates_and_matches_the_rust_layouts() {
        let library = ShaderLibrary::builtin();
        let mut variants = 0;
        for kind in KINDS {
            for f0 in WRITABLE_OUTPUT_FORMATS {
                for f1 in second_outputs(kind) {
                    let (source, entry) = trace_wgsl(&library, kind, (f0, f1)).unwrap();
                    let label = format!("{} ({f0:?}, {f1:?})", kind.label());
                    let module = validate(&label, &source);
                    assert!(
                        module.entry_points.iter().any(|e| e.name == entry),
                        "{label}: no entry point {entry}"
                    );
                    assert_wgsl_layout!(
                        module,
                        "TraceParams",
                        TraceParams {
                            mode,
                            lengths,
                            misc,
                            offset_wp,
                            offset_cd,
                            lights,
                        }
                    );
                    super::super::lights::assert_wgsl_layout(&module);
                    super::super::gbuffer::assert_wgsl_layout(&module);
                    variants += 1;
                }
            }
        }
        // 4 formats × (AO, shadow: 1; multi-shadow: 4; specular, diffuse: 5 second outputs).
        assert_eq!(variants, 64);
        // A format without a WGSL name is refused before any WGSL is made.
        for formats in [(F::Rgba8Unorm, None), (F::R32Float, Some(F::Rgba8Unorm))] {
            assert!(trace_wgsl(&library, TraceKind::MultiShadow, formats).is_err());
        }
    }
}
