//! The SDK's part of a `ksrt` frame, as the reference's integration guide describes it: one task
//! container per frame holding
//!
//! 1. `DirectLightingInjectionTask` of the main view (its depth and rasterised direct lighting),
//!    and of a low-resolution secondary "lidar" view that turns around the camera every frame, so
//!    that the cache learns surfaces the main camera has not seen yet;
//! 2. `TraceSpecularTask`, `TraceDiffuseTask`, `TraceAmbientOcclusionTask` and `TraceShadowTask`
//!    (the shadow of the scene's main light), reading the main G-buffer;
//! 3. their denoisers: `DenoiseSpecularAndDiffuseTask` (or the single one when only one of the
//!    two is on), `DenoiseDiffuseOcclusionTask`, `DenoiseShadowTask`,
//!
//! all writing into textures this module owns ([`SdkOutputs`]).
//!
//! A task the SDK version at hand does not implement makes `build_gpu_task` refuse the whole
//! container with `Error::Unsupported { task }` (recording nothing). `ksrt` then logs one warning
//! naming the task, drops that part for the rest of the run and builds the container again, so
//! everything else still renders.

use std::collections::BTreeSet;

use glam::Vec3;
use kickstart_rt as ksrt;

use crate::raster::{FrameView, ViewTargets};
use crate::scene::Light;

/// The effects `--effects` switches (all on by default).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Effects {
    /// Ray-traced reflections.
    pub specular: bool,
    /// Ray-traced diffuse GI.
    pub diffuse: bool,
    /// Ray-traced ambient occlusion.
    pub ao: bool,
    /// Ray-traced shadow of the main light (replacing its shadow map).
    pub shadow: bool,
    /// The SDK's denoisers on the four traces (off: the composite uses the raw traces).
    pub denoise: bool,
    /// The secondary low-resolution "lidar" view warming the lighting cache.
    pub lidar: bool,
}

impl Default for Effects {
    fn default() -> Self {
        Effects {
            specular: true,
            diffuse: true,
            ao: true,
            shadow: true,
            denoise: true,
            lidar: true,
        }
    }
}

/// The names `--effects` accepts.
pub const EFFECT_NAMES: [&str; 6] = ["specular", "diffuse", "ao", "shadow", "denoise", "lidar"];

impl Effects {
    /// Parses `--effects`: comma-separated names of [`EFFECT_NAMES`], each optionally `=on` or
    /// `=off`, applied in order to all effects on; `all` and `none` set every effect.
    /// Example: `none,ao=on` (AO only), `denoise=off`.
    pub fn parse(s: &str) -> Result<Effects, String> {
        let mut e = Effects::default();
        for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            let (name, on) = match item.split_once('=') {
                Some((n, "on")) => (n.trim(), true),
                Some((n, "off")) => (n.trim(), false),
                Some((_, v)) => {
                    return Err(format!(
                        "--effects {s:?}: {item:?}: the value must be on or off, not {v:?}"
                    ))
                }
                None => (item, true),
            };
            match name {
                "all" | "none" => e.set_all(name == "all" && on),
                _ => {
                    *e.flag(name).ok_or_else(|| {
                        format!(
                            "--effects {s:?}: unknown effect {name:?} (known: all, none, {})",
                            EFFECT_NAMES.join(", ")
                        )
                    })? = on
                }
            }
        }
        Ok(e)
    }

    fn set_all(&mut self, on: bool) {
        for n in EFFECT_NAMES {
            if let Some(f) = self.flag(n) {
                *f = on;
            }
        }
    }

    /// The flag of effect `name`.
    pub fn flag(&mut self, name: &str) -> Option<&mut bool> {
        Some(match name {
            "specular" => &mut self.specular,
            "diffuse" => &mut self.diffuse,
            "ao" => &mut self.ao,
            "shadow" => &mut self.shadow,
            "denoise" => &mut self.denoise,
            "lidar" => &mut self.lidar,
            _ => return None,
        })
    }
}

/// A part of the frame that can be dropped when the SDK refuses its task.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Part {
    /// Both injection tasks (scheduled while specular or diffuse is on, or the cache's debug
    /// view is shown).
    Injection,
    /// The specular trace.
    Specular,
    /// The diffuse trace.
    Diffuse,
    /// The AO trace.
    Ao,
    /// The shadow trace.
    Shadow,
    /// The specular/diffuse denoisers.
    DenoiseSpecularDiffuse,
    /// The AO denoiser.
    DenoiseAo,
    /// The shadow denoiser.
    DenoiseShadow,
}

impl Part {
    /// The part a task type (as `RenderTask::name` and `Error::Unsupported` name it) belongs to.
    pub fn of_task(task: &str) -> Option<Part> {
        Some(match task {
            "DirectLightingInjectionTask" => Part::Injection,
            "TraceSpecularTask" => Part::Specular,
            "TraceDiffuseTask" => Part::Diffuse,
            "TraceAmbientOcclusionTask" => Part::Ao,
            "TraceShadowTask" | "TraceMultiShadowTask" => Part::Shadow,
            "DenoiseSpecularAndDiffuseTask" | "DenoiseSpecularTask" | "DenoiseDiffuseTask" => {
                Part::DenoiseSpecularDiffuse
            }
            "DenoiseDiffuseOcclusionTask" => Part::DenoiseAo,
            "DenoiseShadowTask" | "DenoiseMultiShadowTask" => Part::DenoiseShadow,
            _ => return None,
        })
    }
}

/// The textures the SDK writes (all `Rgba16Float`, full resolution): each trace's raw output and
/// its denoised output.
pub struct SdkOutputs {
    /// Specular radiance (RGB) and hit distance (A), raw.
    pub specular: wgpu::Texture,
    /// Specular, denoised.
    pub specular_denoised: wgpu::Texture,
    /// Diffuse radiance (RGB) and hit distance (A), raw.
    pub diffuse: wgpu::Texture,
    /// Diffuse, denoised.
    pub diffuse_denoised: wgpu::Texture,
    /// AO: hit distance / radius, 1 unoccluded (R), raw.
    pub ao: wgpu::Texture,
    /// AO, denoised (R: 1 unoccluded).
    pub ao_denoised: wgpu::Texture,
    /// Shadow: closest hit distance, negative where the light is visible (R), raw.
    pub shadow: wgpu::Texture,
    /// Shadow, denoised visibility (R: 1 lit).
    pub shadow_denoised: wgpu::Texture,
    /// The SDK debug view asked for ([`SdkFrame::debug_view`]).
    pub debug: wgpu::Texture,
}

impl SdkOutputs {
    fn new(device: &wgpu::Device, size: (u32, u32)) -> SdkOutputs {
        let t = |label: &str| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d {
                    width: size.0,
                    height: size.1,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba16Float,
                usage: wgpu::TextureUsages::STORAGE_BINDING
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
                view_formats: &[],
            })
        };
        SdkOutputs {
            specular: t("ksrt specular"),
            specular_denoised: t("ksrt specular denoised"),
            diffuse: t("ksrt diffuse"),
            diffuse_denoised: t("ksrt diffuse denoised"),
            ao: t("ksrt ao"),
            ao_denoised: t("ksrt ao denoised"),
            shadow: t("ksrt shadow"),
            shadow_denoised: t("ksrt shadow denoised"),
            debug: t("ksrt debug view"),
        }
    }
}

/// Which channel the composite should read for each effect this frame, and whether it is there.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Produced {
    /// Specular was traced; `.1`: and denoised.
    pub specular: (bool, bool),
    /// Diffuse was traced; and denoised.
    pub diffuse: (bool, bool),
    /// AO was traced; and denoised.
    pub ao: (bool, bool),
    /// The shadow was traced; and denoised.
    pub shadow: (bool, bool),
}

/// The inputs of one frame's SDK work.
pub struct FrameInputs<'a> {
    /// The main view's targets.
    pub main: &'a ViewTargets,
    /// The main view's camera.
    pub view: &'a FrameView,
    /// The lidar view's targets and camera, when it was rendered this frame.
    pub lidar: Option<(&'a ViewTargets, &'a FrameView)>,
    /// Frame number (noise).
    pub frame: u32,
    /// Whether history must be dropped (first frame, camera cut).
    pub discard_history: bool,
}

/// The SDK side of `ksrt`'s frames: the context, the denoising contexts, the output textures and
/// the parts the SDK refused.
pub struct SdkFrame {
    /// The SDK context (the scene is registered into it by the caller).
    pub ctx: ksrt::ExecuteContext,
    /// The effects asked for.
    pub effects: Effects,
    /// Parts dropped because the SDK refused their task.
    pub refused: BTreeSet<Part>,
    /// The output textures.
    pub outputs: SdkOutputs,
    /// An SDK debug view to trace into `outputs.debug` each frame (through an AO task with that
    /// debug output type), or `None`.
    pub debug_view: Option<ksrt::DebugOutputType>,
    size: (u32, u32),
    denoisers: std::collections::HashMap<u8, (ksrt::SignalType, ksrt::DenoisingContextHandle)>,
    shadow_light: Option<ksrt::LightInfo>,
    /// The trace inputs of the last frame, for the debug view's task.
    debug_common: Option<ksrt::TraceTaskCommon>,
    scene_size: f32,
    seed: u32,
    /// No injection: the lighting cache keeps what it holds (`ksrt quality` measures against a
    /// reference traced through the same, frozen, cache).
    pub freeze_cache: bool,
    /// One roughness for every pixel instead of the G-buffer's (`ksrt quality`'s specular at
    /// roughness 0.3), for the traces and the denoisers.
    pub roughness_override: Option<f32>,
    /// Set while [`Self::record_traces`] builds: the trace tasks only, white noise of this index.
    traces_only: Option<u32>,
    /// When set, the shadow is traced for several lights ([`Self::set_multi_shadow`]).
    multi_shadow: Option<MultiShadow>,
    /// Rays per pixel of each effect and the denoising method (set before the first frame: the
    /// denoising contexts are made with its method).
    pub preset: ksrt::Preset,
}

/// The multi-light shadow of [`SdkFrame::set_multi_shadow`]: its extra lights and the packed
/// outputs of `TraceMultiShadowTask`.
struct MultiShadow {
    lights: Vec<ksrt::LightInfo>,
    output0: wgpu::Texture,
    output1: wgpu::Texture,
}

/// The SDK's description of a scene light, for its shadow task. Point and spot lights get an
/// emitter radius of 1% of the scene (a soft, but not blurry, penumbra).
pub fn light_info(light: &Light, scene_size: f32) -> ksrt::LightInfo {
    match *light {
        Light::Sun {
            direction,
            angular_diameter,
            ..
        } => ksrt::LightInfo::Directional {
            direction: direction.normalize_or(Vec3::NEG_Y),
            angular_extent: angular_diameter.clamp(0.0, std::f32::consts::PI),
        },
        Light::Point {
            position, range, ..
        } => ksrt::LightInfo::Point {
            position,
            radius: scene_size * 0.01,
            range: range.max(1e-6),
        },
        Light::Spot {
            position,
            direction,
            range,
            outer_angle,
            ..
        } => ksrt::LightInfo::Spot {
            position,
            direction: direction.normalize_or(Vec3::NEG_Y),
            radius: scene_size * 0.01,
            range: range.max(1e-6),
            apex_angle: outer_angle.clamp(1e-3, std::f32::consts::FRAC_PI_2),
        },
    }
}

/// A default view of `t`.
fn view(t: &wgpu::Texture) -> wgpu::TextureView {
    t.create_view(&Default::default())
}

/// The depth input of a view's targets (wgpu's 0..1 clip depth).
fn depth_input(targets: &ViewTargets) -> ksrt::DepthInput {
    ksrt::DepthInput {
        texture: view(&targets.depth),
        depth_type: ksrt::DepthType::RClipSpace,
    }
}

/// The normal input of the main view (world-space, unencoded).
fn normal_input(main: &ViewTargets) -> ksrt::NormalInput {
    ksrt::NormalInput {
        texture: view(&main.normal),
        normal_type: ksrt::NormalType::RgbVector,
        normal_to_world: glam::Mat4::IDENTITY,
    }
}

impl SdkFrame {
    /// The SDK side for `size` images of a scene of diameter `scene_size` whose main light is
    /// `shadow_light`.
    pub fn new(
        device: &wgpu::Device,
        ctx: ksrt::ExecuteContext,
        size: (u32, u32),
        effects: Effects,
        shadow_light: Option<&Light>,
        scene_size: f32,
        seed: u32,
    ) -> SdkFrame {
        SdkFrame {
            ctx,
            effects,
            refused: BTreeSet::new(),
            debug_view: None,
            outputs: SdkOutputs::new(device, size),
            size,
            denoisers: Default::default(),
            shadow_light: shadow_light.map(|l| light_info(l, scene_size)),
            debug_common: None,
            scene_size,
            seed,
            freeze_cache: false,
            roughness_override: None,
            traces_only: None,
            multi_shadow: None,
            preset: ksrt::Preset::Quality,
        }
    }

    /// Traces the shadow of the main light and `extra_lights` in one `TraceMultiShadowTask`
    /// (denoised by `DenoiseMultiShadowTask` into the shadow's denoised output) instead of the
    /// main light's `TraceShadowTask`; `ksrt bench --scaling` times the frame against the light
    /// count with it. `None`: back to the single light's task. At most 31 extra lights (the
    /// task takes 32); more are dropped. The raw `shadow` output is then not written.
    pub fn set_multi_shadow(
        &mut self,
        device: &wgpu::Device,
        extra_lights: Option<&[ksrt::LightInfo]>,
    ) {
        let Some(extra_lights) = extra_lights else {
            self.multi_shadow = None;
            return;
        };
        let keep = extra_lights.len().min(ksrt::MAX_MULTI_SHADOW_LIGHTS - 1);
        let packed = SdkOutputs::new(device, self.size);
        self.multi_shadow = Some(MultiShadow {
            lights: extra_lights[..keep].to_vec(),
            output0: packed.shadow,
            output1: packed.shadow_denoised,
        });
    }

    fn on(&self, part: Part) -> bool {
        let e = &self.effects;
        let denoise_part = matches!(
            part,
            Part::DenoiseSpecularDiffuse | Part::DenoiseAo | Part::DenoiseShadow
        );
        if self.traces_only.is_some() && (part == Part::Injection || denoise_part) {
            return false;
        }
        !self.refused.contains(&part)
            && match part {
                // Only reflections, GI and the cache's debug view read the lighting cache.
                Part::Injection => {
                    !self.freeze_cache
                        && (e.specular
                            || e.diffuse
                            || self.debug_view == Some(ksrt::DebugOutputType::DirectLightingCache))
                }
                Part::Specular => e.specular,
                Part::Diffuse => e.diffuse,
                Part::Ao => e.ao,
                Part::Shadow => e.shadow && self.shadow_light.is_some(),
                Part::DenoiseSpecularDiffuse => {
                    e.denoise && (self.on(Part::Specular) || self.on(Part::Diffuse))
                }
                Part::DenoiseAo => e.denoise && self.on(Part::Ao),
                Part::DenoiseShadow => e.denoise && self.on(Part::Shadow),
            }
    }

    /// What the last built frame produced (the parts on and not refused).
    pub fn produced(&self) -> Produced {
        let pair = |trace, denoise| (self.on(trace), self.on(trace) && self.on(denoise));
        Produced {
            specular: pair(Part::Specular, Part::DenoiseSpecularDiffuse),
            diffuse: pair(Part::Diffuse, Part::DenoiseSpecularDiffuse),
            ao: pair(Part::Ao, Part::DenoiseAo),
            shadow: pair(Part::Shadow, Part::DenoiseShadow),
        }
    }

    /// The denoising contexts created so far (one per signal type the frames denoised), by
    /// signal type.
    pub fn denoising_contexts(&self) -> Vec<(ksrt::SignalType, ksrt::DenoisingContextHandle)> {
        let mut all: Vec<_> = self.denoisers.values().copied().collect();
        all.sort_by_key(|(signal, _)| *signal as u8);
        all
    }

    fn denoiser(&mut self, signal: ksrt::SignalType) -> ksrt::Result<ksrt::DenoisingContextHandle> {
        let key = signal as u8;
        if let Some(&(_, h)) = self.denoisers.get(&key) {
            return Ok(h);
        }
        let h = self
            .ctx
            .create_denoising_context_handle(ksrt::DenoisingContextInput {
                max_width: self.size.0,
                max_height: self.size.1,
                signal_type: signal,
                method: self.preset.denoising_method(),
            })?;
        self.denoisers.insert(key, (signal, h));
        Ok(h)
    }

    /// Schedules this frame's tasks and records them into `encoder`: the frame's container,
    /// then the debug view's (its own container, so that a refused debug view is told apart from
    /// a refused effect). Returns the GPU tasks built (none when every part is off or refused).
    /// Parts the SDK refuses as unsupported are dropped (one warning each) and the container is
    /// built again without them.
    pub fn record(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &FrameInputs<'_>,
    ) -> ksrt::Result<Vec<ksrt::GpuTaskHandle>> {
        let mut handles: Vec<ksrt::GpuTaskHandle> =
            self.record_frame(encoder, inputs)?.into_iter().collect();
        if let Some(debug) = self.debug_view {
            match self.record_debug_view(encoder, debug) {
                Ok(h) => handles.extend(h),
                Err(ksrt::Error::Unsupported { .. }) => {
                    log::warn!("kickstart-rt does not support the debug view {debug:?} yet: off");
                    self.debug_view = None;
                }
                Err(e) => return Err(e),
            }
        }
        Ok(handles)
    }

    /// Records the debug view `debug` alone, traced into `outputs.debug` on this context with the
    /// last recorded frame's view: the lighting cache it reads is the one this context's frames
    /// injected (a fresh context's cache holds only the instances' initial tile colour, black).
    /// `Ok(None)` before any frame was recorded.
    pub fn record_debug_view(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        debug: ksrt::DebugOutputType,
    ) -> ksrt::Result<Option<ksrt::GpuTaskHandle>> {
        let Some(mut common) = self.debug_common.clone() else {
            return Ok(None);
        };
        common.debug_parameters.debug_output_type = debug;
        let mut c = self.ctx.create_task_container();
        c.schedule_render_task(ksrt::RenderTask::TraceAmbientOcclusion(
            ksrt::TraceAmbientOcclusionTask {
                common,
                output: self.outputs.debug.create_view(&Default::default()),
                ao_radius: self.ao_radius(),
            },
        ));
        self.ctx.build_gpu_task(c, encoder).map(Some)
    }

    /// Records the trace tasks of `inputs` alone (no injection, no denoisers, no debug view)
    /// with per-pixel white noise of index `sample` — one sample of a converged reference,
    /// accumulated by the caller from the raw outputs. Returns the GPU task, if any trace is on.
    pub fn record_traces(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &FrameInputs<'_>,
        sample: u32,
    ) -> ksrt::Result<Option<ksrt::GpuTaskHandle>> {
        self.traces_only = Some(sample);
        let result = self.record_frame(encoder, inputs);
        self.traces_only = None;
        result
    }

    fn record_frame(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &FrameInputs<'_>,
    ) -> ksrt::Result<Option<ksrt::GpuTaskHandle>> {
        loop {
            let tasks = self.tasks(inputs)?;
            if tasks.is_empty() {
                return Ok(None);
            }
            let mut container = self.ctx.create_task_container();
            for t in tasks {
                container.schedule_render_task(t);
            }
            match self.ctx.build_gpu_task(container, encoder) {
                Ok(handle) => return Ok(Some(handle)),
                Err(ksrt::Error::Unsupported { task }) => match Part::of_task(task) {
                    Some(part) if !self.refused.contains(&part) => {
                        log::warn!(
                            "kickstart-rt does not support {task} yet: {part:?} is off for the rest of this run"
                        );
                        self.refused.insert(part);
                    }
                    _ => return Err(ksrt::Error::Unsupported { task }),
                },
                Err(e) => return Err(e),
            }
        }
    }

    /// The render tasks of one frame, in the integration guide's order.
    pub fn tasks(&mut self, inputs: &FrameInputs<'_>) -> ksrt::Result<Vec<ksrt::RenderTask>> {
        let mut tasks = self.injection_tasks(inputs);
        let common = self.trace_common(inputs);
        self.trace_tasks(&common, inputs.frame, &mut tasks);
        self.denoise_specular_diffuse_tasks(inputs, &mut tasks)?;
        if self.on(Part::DenoiseAo) {
            let context = self.denoiser(ksrt::SignalType::DiffuseOcclusion)?;
            let c = self.denoise_common(inputs, context, ksrt::Effect::AmbientOcclusion);
            tasks.push(ksrt::RenderTask::DenoiseDiffuseOcclusion(
                ksrt::DenoiseDiffuseOcclusionTask {
                    common: c,
                    input: view(&self.outputs.ao),
                    output: view(&self.outputs.ao_denoised),
                },
            ));
        }
        self.denoise_shadow_tasks(inputs, &mut tasks)?;
        Ok(tasks)
    }

    /// The roughness input: the specular target's alpha, or [`Self::roughness_override`].
    fn roughness_input(&self, main: &ViewTargets) -> ksrt::RoughnessInput {
        // The specular target holds F0 in RGB and roughness in A: the roughness mask stays the
        // default (alpha), and the same texture is the specular input.
        match self.roughness_override {
            Some(r) => ksrt::RoughnessInput {
                texture: None,
                global_roughness: r,
                ..Default::default()
            },
            None => ksrt::RoughnessInput {
                texture: Some(view(&main.specular)),
                ..Default::default()
            },
        }
    }

    /// The rate `effect` is traced (and denoised) at on `frame`: the preset's, but every pixel
    /// for the debug view and the reference's samples.
    fn rate(&self, effect: ksrt::Effect, frame: u32) -> ksrt::HalfResolutionMode {
        match self.traces_only {
            Some(_) => ksrt::HalfResolutionMode::Off,
            None => self.preset.half_resolution_mode(effect, frame),
        }
    }

    /// The injection tasks of the main view and, when on, of the lidar view.
    fn injection_tasks(&self, inputs: &FrameInputs<'_>) -> Vec<ksrt::RenderTask> {
        let mut tasks = Vec::new();
        if !self.on(Part::Injection) {
            return tasks;
        }
        let main = inputs.main;
        let mut t = ksrt::DirectLightingInjectionTask::new(
            depth_input(main),
            view(&main.direct),
            inputs.view.sdk_view(),
        );
        t.injection_resolution_stride = self.preset.injection_resolution_stride();
        tasks.push(ksrt::RenderTask::DirectLightingInjection(t));
        if let (true, Some((lidar, lidar_view))) = (self.effects.lidar, inputs.lidar) {
            let mut t = ksrt::DirectLightingInjectionTask::new(
                depth_input(lidar),
                view(&lidar.direct),
                lidar_view.sdk_view(),
            );
            // The lidar image is small already: inject every pixel.
            t.injection_resolution_stride = 1;
            tasks.push(ksrt::RenderTask::DirectLightingInjection(t));
        }
        tasks
    }

    /// The trace tasks' common inputs (every pixel), kept for the debug view's task.
    fn trace_common(&mut self, inputs: &FrameInputs<'_>) -> ksrt::TraceTaskCommon {
        let main = inputs.main;
        let mut common = ksrt::TraceTaskCommon::new(depth_input(main), normal_input(main));
        common.roughness = self.roughness_input(main);
        common.specular = ksrt::SpecularInput {
            texture: Some(view(&main.specular)),
            ..Default::default()
        };
        common.direct_lighting = Some(view(&main.direct));
        common.view = inputs.view.sdk_view();
        common.ray_offset.offset_type = ksrt::RayOffsetType::CamDistance;
        common.debug_parameters.frame_index =
            self.seed.wrapping_mul(7919).wrapping_add(inputs.frame);
        if let Some(sample) = self.traces_only {
            // A reference accumulates thousands of samples: white noise, not a blue-noise
            // sequence that repeats.
            common.debug_parameters.random_number_generator = ksrt::RandomNumberGenerator::Xorshift;
            common.debug_parameters.frame_index = sample;
        }
        // The debug view and the reference's samples trace every pixel; the frame's effects at
        // the preset's rates (the same mode for each trace and its denoiser).
        self.debug_common = Some(common.clone());
        common
    }

    /// The trace tasks of the effects on, each at its rate on `frame`.
    fn trace_tasks(
        &self,
        common: &ksrt::TraceTaskCommon,
        frame: u32,
        tasks: &mut Vec<ksrt::RenderTask>,
    ) {
        let at_rate = |effect| {
            let mut c = common.clone();
            c.half_resolution_mode = self.rate(effect, frame);
            c
        };
        let o = &self.outputs;
        if self.on(Part::Specular) {
            tasks.push(ksrt::RenderTask::TraceSpecular(ksrt::TraceSpecularTask {
                common: at_rate(ksrt::Effect::Specular),
                output: view(&o.specular),
                demodulate_specular: false,
                demodulation_output: None,
            }));
        }
        // With GI on, AO comes from the diffuse rays (one traversal for both) where both
        // trace the same pixels.
        let ao_from_diffuse = self.on(Part::Ao)
            && self.on(Part::Diffuse)
            && self.rate(ksrt::Effect::AmbientOcclusion, frame)
                == self.rate(ksrt::Effect::Diffuse, frame);
        if self.on(Part::Diffuse) {
            tasks.push(ksrt::RenderTask::TraceDiffuse(ksrt::TraceDiffuseTask {
                common: at_rate(ksrt::Effect::Diffuse),
                output: view(&o.diffuse),
                diffuse_brdf: ksrt::DiffuseBrdf::Lambertian,
                ambient_occlusion: ao_from_diffuse.then(|| ksrt::DiffuseAmbientOcclusion {
                    output: view(&o.ao),
                    ao_radius: self.ao_radius(),
                }),
            }));
        }
        if self.on(Part::Ao) && !ao_from_diffuse {
            tasks.push(ksrt::RenderTask::TraceAmbientOcclusion(
                ksrt::TraceAmbientOcclusionTask {
                    common: at_rate(ksrt::Effect::AmbientOcclusion),
                    output: view(&o.ao),
                    ao_radius: self.ao_radius(),
                },
            ));
        }
        if let (true, Some(light)) = (self.on(Part::Shadow), self.shadow_light) {
            match &self.multi_shadow {
                Some(m) => tasks.push(ksrt::RenderTask::TraceMultiShadow(
                    ksrt::TraceMultiShadowTask {
                        common: at_rate(ksrt::Effect::Shadow),
                        output0: view(&m.output0),
                        output1: view(&m.output1),
                        lights: std::iter::once(light)
                            .chain(m.lights.iter().copied())
                            .collect(),
                        enable_first_hit_and_end_search: true,
                    },
                )),
                None => tasks.push(ksrt::RenderTask::TraceShadow(ksrt::TraceShadowTask {
                    common: at_rate(ksrt::Effect::Shadow),
                    output: view(&o.shadow),
                    light,
                    enable_first_hit_and_end_search: true,
                })),
            }
        }
    }

    /// The inputs every denoiser of the frame shares, for `context` denoising `effect`.
    fn denoise_common(
        &self,
        inputs: &FrameInputs<'_>,
        context: ksrt::DenoisingContextHandle,
        effect: ksrt::Effect,
    ) -> ksrt::DenoiseTaskCommon {
        let main = inputs.main;
        ksrt::DenoiseTaskCommon {
            context,
            viewport: None,
            depth: depth_input(main),
            normal: normal_input(main),
            roughness: self.roughness_input(main),
            motion: Some(ksrt::MotionInput {
                texture: view(&main.motion),
                motion_type: ksrt::MotionType::RgViewSpace,
                scale: Vec3::ONE,
            }),
            view: inputs.view.sdk_view(),
            half_resolution_mode: self.rate(effect, inputs.frame),
            mode: if inputs.discard_history {
                ksrt::DenoiseMode::DiscardHistory
            } else {
                ksrt::DenoiseMode::Continue
            },
        }
    }

    /// The specular and diffuse denoiser: one task for both when both are traced.
    fn denoise_specular_diffuse_tasks(
        &mut self,
        inputs: &FrameInputs<'_>,
        tasks: &mut Vec<ksrt::RenderTask>,
    ) -> ksrt::Result<()> {
        if !self.on(Part::DenoiseSpecularDiffuse) {
            return Ok(());
        }
        let (spec, diff) = (self.on(Part::Specular), self.on(Part::Diffuse));
        let o = &self.outputs;
        let (is, id, os, od) = (
            view(&o.specular),
            view(&o.diffuse),
            view(&o.specular_denoised),
            view(&o.diffuse_denoised),
        );
        if spec && diff {
            let context = self.denoiser(ksrt::SignalType::SpecularAndDiffuse)?;
            let c = self.denoise_common(inputs, context, ksrt::Effect::Diffuse);
            tasks.push(ksrt::RenderTask::DenoiseSpecularAndDiffuse(
                ksrt::DenoiseSpecularAndDiffuseTask {
                    common: c,
                    input_specular: is,
                    input_diffuse: id,
                    output_specular: os,
                    output_diffuse: od,
                },
            ));
        } else if spec {
            let context = self.denoiser(ksrt::SignalType::Specular)?;
            let c = self.denoise_common(inputs, context, ksrt::Effect::Specular);
            tasks.push(ksrt::RenderTask::DenoiseSpecular(
                ksrt::DenoiseSpecularTask {
                    common: c,
                    input: is,
                    output: os,
                },
            ));
        } else {
            let context = self.denoiser(ksrt::SignalType::Diffuse)?;
            let c = self.denoise_common(inputs, context, ksrt::Effect::Diffuse);
            tasks.push(ksrt::RenderTask::DenoiseDiffuse(ksrt::DenoiseDiffuseTask {
                common: c,
                input: id,
                output: od,
            }));
        }
        Ok(())
    }

    /// The shadow's denoiser: of the multi-light shadow when it is traced, else of the main
    /// light's.
    fn denoise_shadow_tasks(
        &mut self,
        inputs: &FrameInputs<'_>,
        tasks: &mut Vec<ksrt::RenderTask>,
    ) -> ksrt::Result<()> {
        if !self.on(Part::DenoiseShadow) {
            return Ok(());
        }
        if self.multi_shadow.is_some() {
            let context = self.denoiser(ksrt::SignalType::MultiShadow)?;
            let c = self.denoise_common(inputs, context, ksrt::Effect::Shadow);
            if let Some(m) = &self.multi_shadow {
                tasks.push(ksrt::RenderTask::DenoiseMultiShadow(
                    ksrt::DenoiseMultiShadowTask {
                        common: c,
                        input0: view(&m.output0),
                        input1: view(&m.output1),
                        output: view(&self.outputs.shadow_denoised),
                    },
                ));
            }
        } else {
            let context = self.denoiser(ksrt::SignalType::Shadow)?;
            let c = self.denoise_common(inputs, context, ksrt::Effect::Shadow);
            tasks.push(ksrt::RenderTask::DenoiseShadow(ksrt::DenoiseShadowTask {
                common: c,
                input: view(&self.outputs.shadow),
                output: view(&self.outputs.shadow_denoised),
            }));
        }
        Ok(())
    }

    /// AO radius: 5% of the scene's diameter (contact shadows, not a second sky occlusion).
    pub fn ao_radius(&self) -> f32 {
        (self.scene_size * 0.05).max(1e-4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn effects_parse_names_values_all_and_none() {
        assert_eq!(Effects::parse("").unwrap(), Effects::default());
        let e = Effects::parse("none,ao").unwrap();
        assert!(e.ao && !e.specular && !e.diffuse && !e.shadow && !e.denoise && !e.lidar);
        let e = Effects::parse("all=off,lidar=on").unwrap();
        assert!(e.lidar && !e.ao && !e.specular);
        let e = Effects::parse("denoise=off, specular=off").unwrap();
        assert!(!e.denoise && !e.specular && e.diffuse && e.ao);
        let err = Effects::parse("reflections").unwrap_err();
        assert!(err.contains("unknown effect \"reflections\""), "{err}");
        let err = Effects::parse("ao=maybe").unwrap_err();
        assert!(err.contains("on or off"), "{err}");
    }

    #[test]
    fn every_refusable_task_maps_to_a_part() {
        for task in [
            "DirectLightingInjectionTask",
            "TraceSpecularTask",
            "TraceDiffuseTask",
            "TraceAmbientOcclusionTask",
            "TraceShadowTask",
            "DenoiseSpecularAndDiffuseTask",
            "DenoiseSpecularTask",
            "DenoiseDiffuseTask",
            "DenoiseDiffuseOcclusionTask",
            "DenoiseShadowTask",
            "TraceMultiShadowTask",
            "DenoiseMultiShadowTask",
        ] {
            assert!(Part::of_task(task).is_some(), "{task}");
        }
        assert_eq!(Part::of_task("TraceRaysTask"), None);
    }
}
