//! `ksrt render`'s lit image: `frames` frames of the full pipeline (so the lighting cache and the
//! denoisers settle), then the final image and every channel read back and written, and the GPU
//! time of each SDK pass of the last frame.

use crate::app::frames::RendererExt;
use std::path::Path;

use kickstart_rt as ksrt;

use crate::app::debug_view::DebugView;
use crate::app::readback::{read_texture, to_hdr, to_png, Encoding, Texels};
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::frame::Effects;
use kickstart_rt_renderer::renderer::Renderer;
use kickstart_rt_renderer::scene::{Camera, Scene};

/// Frames at the end of a render whose SDK passes are timed (the earlier ones warm up).
pub const TIMED_FRAMES: u32 = 8;

/// Options of the lit render.
#[derive(Debug, Clone)]
pub struct LitOptions {
    /// Image size.
    pub size: (u32, u32),
    /// Frames to run (≥ 1); the images are of the last one.
    pub frames: u32,
    /// Effects on.
    pub effects: Effects,
    /// Noise seed.
    pub seed: u32,
    /// Rays per pixel of each effect and the denoising method.
    pub preset: kickstart_rt::Preset,
    /// Show a progress bar.
    pub progress: bool,
    /// Measure the SDK's passes on the last frame.
    pub gpu_timing: bool,
    /// Frames the CPU may record ahead of the GPU (1..=3; 1 waits for each frame before the
    /// next), see [`crate::app::frames_in_flight`].
    pub frames_in_flight: u32,
    /// SDK debug views traced after the last frame on the same context (so the lighting
    /// cache's view shows what the frames injected), into [`LitResult::debug`].
    pub debug_views: Vec<DebugView>,
    /// Scene time, seconds, of every frame: an animated scene's pose (`ksrt render --time`).
    pub time: f32,
}

/// One image of the render: its file stem, texels and how to display them.
pub struct Channel {
    /// File stem (`final`, `direct`, `specular-denoised`, …).
    pub name: &'static str,
    /// Linear texels (display values for `final`).
    pub texels: Texels,
    /// How the texels become an image.
    pub encoding: Encoding,
}

/// What a lit render produced.
pub struct LitResult {
    /// The final image first, then the direct light and each SDK channel produced.
    pub channels: Vec<Channel>,
    /// Channels not written because their effect was off or the SDK refused its task.
    pub missing: Vec<&'static str>,
    /// SDK tasks refused as unsupported.
    pub refused: Vec<kickstart_rt_renderer::frame::Part>,
    /// GPU time of the SDK's passes in each of the last [`TIMED_FRAMES`] frames, when measured
    /// (empty otherwise).
    pub timings: Vec<ksrt::GpuTimings>,
    /// Every frame's CPU costs: `build_gpu_task`, recording, submit, waits for the GPU.
    pub frames: Vec<crate::app::frames_in_flight::FrameRecord>,
    /// Each of [`LitOptions::debug_views`] with its texels, in the order asked.
    pub debug: Vec<(DebugView, Texels)>,
    /// The SDK's GPU memory at its peak over the frames.
    pub memory: crate::app::memory::MemoryPeak,
    /// The traversal backend the SDK traced with, and why.
    pub backend: kickstart_rt::BackendReport,
}

impl LitResult {
    /// The channel named `name` (the tests look channels up; `ksrt render` writes them all).
    #[cfg(test)]
    pub fn channel(&self, name: &str) -> Option<&Channel> {
        self.channels.iter().find(|c| c.name == name)
    }
}

/// Renders `opts.frames` frames of `scene` from `camera` and reads every image back.
pub fn render(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    scene: &Scene,
    camera: &Camera,
    opts: &LitOptions,
) -> AnyResult<LitResult> {
    let mut ropts = crate::app::frames::renderer_options(opts.size);
    ropts.effects = opts.effects;
    ropts.seed = opts.seed;
    ropts.preset = opts.preset;
    ropts.gpu_timing = opts.gpu_timing;
    let depth = crate::app::frames_in_flight::check_depth(opts.frames_in_flight)?;
    ropts.frames_in_flight = opts.frames_in_flight;
    // A batch render waits for its frames anyway: only the pipelines its effects use.
    ropts.prepare_pipelines = false;
    let mut renderer = crate::app::frames::new_renderer(device, queue, scene, &ropts)?;
    renderer.set_time(opts.time);
    let frames = opts.frames.max(1);
    let bar = crate::app::progress::bar(
        opts.progress,
        frames as u64,
        format!("rendering {}", scene.name),
        "frames",
    );
    let looped = crate::app::frames_in_flight::run(
        &mut renderer,
        device,
        queue,
        camera,
        crate::app::frames_in_flight::LoopOptions {
            frames,
            depth,
            timed_frames: if opts.gpu_timing { TIMED_FRAMES } else { 0 },
        },
        || bar.inc(1),
    )?;
    bar.finish_and_clear();
    let (channels, missing) = read_channels(device, queue, &renderer)?;
    let debug = trace_debug_views(
        device,
        queue,
        &mut renderer,
        (&opts.debug_views, opts.progress),
    )?;
    Ok(LitResult {
        channels,
        missing,
        refused: renderer.sdk.refused.iter().copied().collect(),
        timings: looped.timings,
        frames: looped.records,
        debug,
        memory: looped.memory,
        backend: renderer.sdk.ctx.traversal_backend().clone(),
    })
}

/// Traces each of `views` on `renderer`'s context from its last frame, one GPU task each, with a
/// progress bar (several seconds each on software Vulkan).
fn trace_debug_views(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    renderer: &mut Renderer,
    (views, show): (&[DebugView], bool),
) -> AnyResult<Vec<(DebugView, Texels)>> {
    let bar = crate::app::progress::bar(show, views.len() as u64, "debug views", "views");
    let mut out = Vec::with_capacity(views.len());
    for &view in views {
        bar.set_message(format!("debug view {}", view.name()));
        out.push((
            view,
            renderer.trace_debug_view(device, queue, view.output_type())?,
        ));
        bar.inc(1);
    }
    bar.finish_and_clear();
    Ok(out)
}

/// The final image, the direct light and every SDK channel the last frame produced, read back;
/// and the names of the channels it did not produce.
fn read_channels(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    renderer: &Renderer,
) -> AnyResult<(Vec<Channel>, Vec<&'static str>)> {
    let read = |t: &wgpu::Texture| read_texture(device, queue, t);
    let mut channels = vec![
        Channel {
            name: "final",
            texels: read(&renderer.ldr)?,
            encoding: Encoding::Display,
        },
        Channel {
            name: "direct",
            texels: read(&renderer.main.direct)?,
            encoding: Encoding::Radiance,
        },
    ];
    let produced = renderer.sdk.produced();
    let o = &renderer.sdk.outputs;
    // (raw name, denoised name, produced, raw texture, denoised texture, raw and denoised
    // encodings)
    struct SdkChannel<'a> {
        raw: &'static str,
        denoised: &'static str,
        produced: (bool, bool),
        textures: (&'a wgpu::Texture, &'a wgpu::Texture),
        encodings: (Encoding, Encoding),
    }
    let sdk_channels = [
        SdkChannel {
            raw: "specular",
            denoised: "specular-denoised",
            produced: produced.specular,
            textures: (&o.specular, &o.specular_denoised),
            encodings: (Encoding::Radiance, Encoding::Radiance),
        },
        SdkChannel {
            raw: "diffuse",
            denoised: "diffuse-denoised",
            produced: produced.diffuse,
            textures: (&o.diffuse, &o.diffuse_denoised),
            encodings: (Encoding::Radiance, Encoding::Radiance),
        },
        SdkChannel {
            raw: "ao",
            denoised: "ao-denoised",
            produced: produced.ao,
            textures: (&o.ao, &o.ao_denoised),
            encodings: (Encoding::Unit, Encoding::Unit),
        },
        SdkChannel {
            raw: "shadow",
            denoised: "shadow-denoised",
            produced: produced.shadow,
            textures: (&o.shadow, &o.shadow_denoised),
            encodings: (Encoding::ShadowHitDistance, Encoding::Unit),
        },
    ];
    let mut missing = Vec::new();
    for c in sdk_channels {
        let (raw, den, (traced, denoised)) = (c.raw, c.denoised, c.produced);
        let ((traw, tden), (eraw, eden)) = (c.textures, c.encodings);
        if traced {
            channels.push(Channel {
                name: raw,
                texels: read(traw)?,
                encoding: eraw,
            });
        } else {
            missing.push(raw);
        }
        if denoised {
            channels.push(Channel {
                name: den,
                texels: read(tden)?,
                encoding: eden,
            });
        } else {
            missing.push(den);
        }
    }
    Ok((channels, missing))
}

/// Writes every channel of `result` into `out` as `<name>.png`, and `<name>.exr` (linear) when
/// `hdr`; returns the paths written.
pub fn write(result: &LitResult, out: &Path, hdr: bool) -> AnyResult<Vec<std::path::PathBuf>> {
    std::fs::create_dir_all(out)
        .map_err(|e| format!("--out {}: cannot create: {e}", out.display()))?;
    let mut written = Vec::new();
    for c in &result.channels {
        let path = out.join(format!("{}.png", c.name));
        to_png(&c.texels, c.encoding)
            .save(&path)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        written.push(path);
        if hdr {
            let path = out.join(format!("{}.exr", c.name));
            to_hdr(&c.texels, c.encoding)
                .save(&path)
                .map_err(|e| format!("{}: {e}", path.display()))?;
            written.push(path);
        }
    }
    Ok(written)
}
