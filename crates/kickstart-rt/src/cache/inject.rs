//! `DirectLightingInjectionTask`: the engine's direct lighting blended into the cache.
//!
//! Per strided pixel (one per `stride × stride` block, at an offset inside the block drawn anew
//! for every injection task), the surface the pixel shows is found by tracing from the camera
//! towards the position the depth gives (RClipSpace: unprojected with the task's matrices;
//! RgbWorldSpace: read directly) and accepting a hit on an instance with
//! `DIRECT_LIGHT_INJECTION_TARGET` within 0.2 % of that distance. The pixel's radiance (NaN/∞ as
//! 0, clamped to [0, 65504]) is summed exactly into its nearest surfel's slot (64-bit fixed-point
//! sums with 16 fractional bits, and a count); a resolve pass then blends each slot's average
//! into the surfel: the first injection replaces the initial colour, the n-th after it moves the
//! value by `(average − value) / min(n + 1, average_window)`.

use bytemuck::{Pod, Zeroable};

use crate::device::TraversalBackend;
use crate::error::{Error, Result};
use crate::gpu::buffers::storage;
use crate::gpu::reflect::{ReflectedLayout, ReflectedPipeline, ReflectedShader};
use crate::gpu::shader::traversal_pipeline;
use crate::gpu::Recorder;
use crate::scene::traversal::{self, LeafTest, PerLeafTest, SceneBuffers};
use crate::tasks::{DepthType, DirectLightingInjectionTask, Viewport};

const TASK: &str = "DirectLightingInjectionTask";
/// Relative distance within which a traced hit counts as the surface the depth shows.
const DEPTH_TOLERANCE: f32 = 2e-3;

#[repr(C)]
#[derive(Pod, Zeroable, Clone, Copy)]
struct InjectParams {
    clip_to_world: [[f32; 4]; 4],
    eye: [f32; 4],
    viewport: [u32; 4],
    grid: [u32; 4],
    offset: [u32; 4],
    f: [f32; 4],
    /// `ViewInfo::jitter` in xy (pixels), zw unused.
    jitter: [f32; 4],
}

#[repr(C)]
#[derive(Pod, Zeroable, Clone, Copy)]
struct ResolveParams {
    slots: u32,
    map_words: u32,
    window: f32,
    pad: u32,
}

struct InjectPipeline {
    /// Group 1: the cache's meta and the accumulation, as the entry point uses them.
    cache: ReflectedLayout,
    /// Group 2: the task's parameters and textures.
    io: ReflectedLayout,
    pipeline: wgpu::ComputePipeline,
}

/// The injection passes and their accumulation buffer.
pub(crate) struct Injector {
    /// The traversal the visibility rays use.
    backend: TraversalBackend,
    /// Index 0: a depth-format depth texture; 1: a float texture; each per traversal build.
    inject: [PerLeafTest<InjectPipeline>; 2],
    resolve: Option<ReflectedPipeline>,
    /// Surfel → slot map (one word per surfel of the pool), then 8 words per slot.
    accum: Option<(wgpu::Buffer, u32, u32)>,
    tasks: u32,
}

/// The WGSL of the injection pass reading depth of a depth format (`depth_format`) or a float
/// texture, with the traversal's leaf test `leaf`.
fn inject_shader(backend: TraversalBackend, leaf: LeafTest, depth_format: bool) -> ReflectedShader {
    let depth = if depth_format {
        "cache/inject_depth/depth_format"
    } else {
        "cache/inject_depth/float_format"
    };
    traversal::compose(
        backend,
        leaf,
        &["cache/inject", depth],
        &super::sample_params(1, false),
    )
}

/// The WGSL of the injection passes (both depth inputs, each traversal build) tracing with
/// `backend`, labelled.
pub(crate) fn shader_variants(backend: TraversalBackend) -> Vec<(String, String)> {
    let mut out = Vec::new();
    for &leaf in LeafTest::all(backend) {
        for depth_format in [true, false] {
            out.push((
                format!("injection (depth format: {depth_format}, {leaf:?})"),
                inject_shader(backend, leaf, depth_format)
                    .source()
                    .to_string(),
            ));
        }
    }
    out
}

/// The WGSL of the injection's resolve pass (it traces nothing), labelled.
pub(crate) fn resolve_shader_variants() -> Vec<(String, String)> {
    vec![(
        "injection resolve".into(),
        resolve_shader().source().to_string(),
    )]
}

/// The resolve pass's shader.
fn resolve_shader() -> ReflectedShader {
    ReflectedShader::compose(&["cache/resolve"], &[])
}

fn inject_pipeline(
    device: &wgpu::Device,
    backend: TraversalBackend,
    leaf: LeafTest,
    depth_format: bool,
) -> InjectPipeline {
    let shader = inject_shader(backend, leaf, depth_format);
    let scene = SceneBuffers::layout(device, backend);
    let layout = |label, group| {
        ReflectedLayout::of_entry_point(device, label, shader.reflection(), "inject", group)
    };
    let cache = layout("kickstart-rt injection cache", 1);
    let io = layout("kickstart-rt injection inputs", 2);
    let groups = [scene.group(), cache.group(), io.group()];
    // SAFETY: with naga's checks on, only the dropped zero fill needs an argument: the
    // traversal reads `rt_stack` only below its stack pointer, where it wrote first.
    let (pipeline, _) = unsafe {
        traversal_pipeline(
            device,
            "kickstart-rt injection",
            shader.source(),
            "inject",
            &groups,
            wgpu::ShaderRuntimeChecks::checked(),
            traversal::uninitialized(backend),
        )
    };
    InjectPipeline {
        cache,
        io,
        pipeline,
    }
}

/// Whether a texture format reads as floats in WGSL (`Some(true)` for depth formats).
pub(crate) fn float_kind(format: wgpu::TextureFormat) -> Option<bool> {
    if format.has_depth_aspect() {
        return (!format.has_stencil_aspect()).then_some(true);
    }
    match format.sample_type(None, None) {
        Some(wgpu::TextureSampleType::Float { .. }) => Some(false),
        _ => None,
    }
}

/// The injection's viewport, its stride, and the number of injected grid slots.
fn grid(task: &DirectLightingInjectionTask) -> (Viewport, u32, u64) {
    let size = task.direct_lighting.texture().size();
    let vp = task.viewport.unwrap_or(Viewport {
        x: 0,
        y: 0,
        width: size.width,
        height: size.height,
    });
    let stride = task.injection_resolution_stride.clamp(1, 8);
    let slots = vp.width.div_ceil(stride) as u64 * vp.height.div_ceil(stride) as u64;
    (vp, stride, slots)
}

/// A PCG hash (per-task block offsets).
fn hash(x: u32) -> u32 {
    let state = x.wrapping_mul(747796405).wrapping_add(2891336453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277803737);
    (word >> 22) ^ word
}

impl Injector {
    /// No pipelines yet; visibility rays traced with `backend`.
    pub fn new(backend: TraversalBackend) -> Self {
        Injector {
            backend,
            inject: Default::default(),
            resolve: None,
            accum: None,
            tasks: 0,
        }
    }

    /// Creates the pipelines now, tracing with the traversal build `leaf`.
    pub fn prepare(&mut self, device: &wgpu::Device, leaf: LeafTest) {
        let backend = self.backend;
        for (i, p) in self.inject.iter().enumerate() {
            p.get_or_init(leaf, || inject_pipeline(device, backend, leaf, i == 0));
        }
        self.resolve(device);
    }

    fn resolve(&mut self, device: &wgpu::Device) -> &ReflectedPipeline {
        self.resolve.get_or_insert_with(|| {
            resolve_shader().pipeline(device, "kickstart-rt injection resolve", "resolve")
        })
    }

    /// Bytes of the accumulation buffer.
    pub fn bytes(&self) -> u64 {
        self.accum.as_ref().map_or(0, |a| a.0.size())
    }

    /// Refuses an injection whose accumulation would not fit one storage binding beside a cache
    /// of `capacity` surfels (the capacity the cache will have when the task records).
    pub fn check_fits(
        task: &DirectLightingInjectionTask,
        capacity: u32,
        limits: &wgpu::Limits,
    ) -> Result<()> {
        let (_, stride, slots) = grid(task);
        if (capacity as u64 + 8 * slots) * 4 > limits.max_storage_buffer_binding_size {
            return Err(Error::input(
                TASK,
                "injection_resolution_stride",
                stride,
                "too many injected pixels for one storage binding with this cache size: raise the stride",
            ));
        }
        Ok(())
    }

    /// Records one injection task, planned and checked with [`Self::check_fits`]. `meta`/`surfels`
    /// are the cache's buffers, `capacity` its surfel count.
    pub fn record(
        &mut self,
        rec: &mut Recorder<'_>,
        scene: &SceneBuffers<'_>,
        (meta, surfels, capacity): (&wgpu::Buffer, &wgpu::Buffer, u32),
        task: &DirectLightingInjectionTask,
    ) {
        let device = rec.device;
        // The formats were checked when the task was planned (`context::validate`).
        let depth_is_depth = float_kind(task.depth.texture.texture().format()) == Some(true);
        let (vp, stride, slots) = grid(task);
        let (gw, gh) = (vp.width.div_ceil(stride), vp.height.div_ceil(stride));
        if slots == 0 {
            return;
        }
        let slots = slots as u32;
        let fits = matches!(&self.accum, Some((_, c, s)) if *c == capacity && *s >= slots);
        if !fits {
            let keep = self.accum.as_ref().map_or(0, |a| a.2).max(slots);
            let buffer = storage(
                device,
                "kickstart-rt injection accumulation",
                (capacity as u64 + 8 * keep as u64) * 4,
            );
            self.accum = Some((buffer, capacity, keep));
        }
        let Some((accum, _, _)) = self.accum.clone() else {
            return;
        };
        self.tasks = self.tasks.wrapping_add(1);
        let seed = hash(self.tasks);
        let (clip_to_world, eye, ortho, z_origin, _) = crate::camera::camera(&task.view);
        let params = rec.uniform(
            "kickstart-rt injection params",
            &InjectParams {
                clip_to_world,
                eye,
                viewport: [vp.x, vp.y, vp.width, vp.height],
                grid: [gw, gh, stride, ortho],
                offset: [
                    seed % stride,
                    hash(seed) % stride,
                    (task.depth.depth_type == DepthType::RgbWorldSpace) as u32,
                    capacity,
                ],
                f: [z_origin, DEPTH_TOLERANCE, task.average_window, 0.0],
                jitter: [task.view.jitter.x, task.view.jitter.y, 0.0, 0.0],
            },
        );
        let index = if depth_is_depth { 0 } else { 1 };
        let backend = self.backend;
        let leaf = scene.leaf_test();
        let p = self.inject[index].get_or_init(leaf, || {
            inject_pipeline(device, backend, leaf, depth_is_depth)
        });
        let [scene_group, cache_group, io_group] =
            inject_groups(device, p, scene, (meta, &accum), &params, task);
        let pipeline = p.pipeline.clone();
        rec.scope = "injection";
        rec.dispatch(
            "cache inject",
            &pipeline,
            &[&scene_group, &cache_group, &io_group],
            slots.div_ceil(64),
        );
        self.record_resolve(rec, (surfels, &accum), slots, capacity, task.average_window);
    }

    /// Records the resolve pass: the accumulated injections averaged into the surfels.
    fn record_resolve(
        &mut self,
        rec: &mut Recorder<'_>,
        (surfels, accum): (&wgpu::Buffer, &wgpu::Buffer),
        slots: u32,
        capacity: u32,
        window: f32,
    ) {
        let device = rec.device;
        let resolve = self.resolve(device);
        let rparams = rec.uniform(
            "kickstart-rt injection resolve params",
            &ResolveParams {
                slots,
                map_words: capacity,
                window,
                pad: 0,
            },
        );
        let group = resolve.bind_group(
            device,
            "kickstart-rt injection resolve",
            0,
            &[("surfels", surfels), ("accum", accum), ("params", &rparams)],
        );
        rec.dispatch(
            "cache resolve",
            &resolve.pipeline,
            &[&group],
            slots.div_ceil(64),
        );
    }
}

/// The injection pass's three bind groups: the scene, the cache (meta, accumulation) and the
/// task's inputs.
fn inject_groups(
    device: &wgpu::Device,
    p: &InjectPipeline,
    scene: &SceneBuffers<'_>,
    (meta, accum): (&wgpu::Buffer, &wgpu::Buffer),
    params: &wgpu::Buffer,
    task: &DirectLightingInjectionTask,
) -> [wgpu::BindGroup; 3] {
    let cache = [
        ("cache_meta", meta.as_entire_binding()),
        ("accum", accum.as_entire_binding()),
    ];
    let io = [
        ("params", params.as_entire_binding()),
        (
            "depth_tex",
            wgpu::BindingResource::TextureView(&task.depth.texture),
        ),
        (
            "light_tex",
            wgpu::BindingResource::TextureView(&task.direct_lighting),
        ),
    ];
    [
        scene.bind_group(device, &p.pipeline),
        p.cache.bind_group(device, &cache),
        p.io.bind_group(device, &io),
    ]
}

#[cfg(test)]
mod wgsl_tests {
    //! The injection and resolve passes' WGSL validated with naga without a device, and their
    //! uniforms against it.
    use super::*;
    use crate::cache::alloc::SURFEL_BYTES;
    use crate::gpu::wgsl_check::{assert_wgsl_layout, storage_stride, validate};

    #[test]
    fn both_injection_variants_validate_and_match_the_rust_layout() {
        for depth_format in [true, false] {
            let label = format!("injection (depth format: {depth_format})");
            validate(
                &label,
                inject_shader(
                    TraversalBackend::Software,
                    LeafTest::OpaqueOnly,
                    depth_format,
                )
                .source(),
            );
            let module = validate(
                &label,
                inject_shader(
                    TraversalBackend::Software,
                    LeafTest::WithCutouts,
                    depth_format,
                )
                .source(),
            );
            assert!(module.entry_points.iter().any(|e| e.name == "inject"));
            assert_wgsl_layout!(
                module,
                "InjectParams",
                InjectParams {
                    clip_to_world,
                    eye,
                    viewport,
                    grid,
                    offset,
                    f,
                    jitter,
                }
            );
            assert_eq!(
                storage_stride(&module, "cache_surfels") as u64,
                SURFEL_BYTES
            );
        }
    }

    #[test]
    fn the_resolve_pass_validates_and_matches_the_rust_layout() {
        let module = validate("injection resolve", resolve_shader().source());
        assert!(module.entry_points.iter().any(|e| e.name == "resolve"));
        assert_wgsl_layout!(
            module,
            "ResolveParams",
            ResolveParams {
                slots,
                map_words,
                window,
                pad,
            }
        );
        assert_eq!(storage_stride(&module, "surfels") as u64, SURFEL_BYTES);
    }
}
