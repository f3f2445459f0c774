//! `ksrt quality`: how close the denoised 1-sample-per-pixel traces come to a converged
//! reference, frame by frame along a slow camera pan.
//!
//! 1. The lighting cache is warmed at the pan's first camera (`warmup` frames of injection from
//!    the main and the lidar views), then **frozen** (no more injection), so that every trace
//!    after it — the measured ones and the reference's — reads the same cache.
//! 2. Each pan frame renders as `ksrt render` does (G-buffer, specular at roughness
//!    [`SPECULAR_ROUGHNESS`] everywhere, diffuse GI, the main light's shadow, each at one ray per
//!    pixel, and their denoisers); the pan's first frame drops the denoisers' history, so the
//!    figures show them converging.
//! 3. Its reference: the same trace tasks on the same G-buffer, `reference_samples` times with
//!    white noise, averaged on the GPU.
//! 4. Noisy, denoised and reference are tone mapped to 8-bit sRGB ([`metrics::tone_map`]:
//!    exposure [`metrics::EXPOSURE`], Reinhard, sRGB; shadow visibility maps linearly to 0–255)
//!    and compared with PSNR and FLIP; each frame's noisy | denoised | reference strip is written
//!    as PNG.

use std::path::{Path, PathBuf};

use glam::{Quat, Vec3};

use super::accumulate::{Accumulator, SampleKind};
use super::metrics::{self, Srgb8};
use crate::frame::Effects;
use crate::progress;
use crate::readback::read_texture;
use crate::renderer::{Renderer, RendererOptions};
use crate::scene::{Camera, Scene};
use crate::AnyResult;

/// The specular trace's roughness everywhere (the glossy case).
pub const SPECULAR_ROUGHNESS: f32 = 0.3;

/// Reference samples traced per submission: each is a GPU task holding one of the context's
/// working sets until the submission completes, and `ksrt`'s context has the default four.
const SAMPLES_PER_SUBMIT: u32 = 3;

/// Which strips to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Images {
    /// Every frame's.
    All,
    /// The last frame's.
    Last,
    /// None.
    None,
}

/// Options of `ksrt quality`.
#[derive(Debug, Clone)]
pub struct QualityOptions {
    /// Image size.
    pub size: (u32, u32),
    /// Measured frames along the pan.
    pub frames: u32,
    /// Frames of cache warm-up before the pan.
    pub warmup: u32,
    /// Samples per pixel of each frame's reference.
    pub reference_samples: u32,
    /// Yaw of the whole pan, degrees (turning left about the eye).
    pub pan_degrees: f32,
    /// Seed of the measured frames' noise.
    pub seed: u32,
    /// Where to write the strips (`None`: nowhere).
    pub out: Option<PathBuf>,
    /// Which strips to write.
    pub images: Images,
    /// Progress bars on stderr for the warm-up and the reference samples.
    pub progress: bool,
}

/// One signal the yardstick measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Signal {
    /// Diffuse GI (incoming radiance).
    Diffuse,
    /// Reflections at roughness [`SPECULAR_ROUGHNESS`] (incoming radiance).
    Specular,
    /// The main light's shadow (visibility).
    Shadow,
}

impl Signal {
    /// Its name in the report and the file names.
    pub fn name(self) -> &'static str {
        match self {
            Signal::Diffuse => "diffuse",
            Signal::Specular => "specular",
            Signal::Shadow => "shadow",
        }
    }
}

/// PSNR (dB) and FLIP (mean, 0 = identical) of one image against the reference.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Score {
    /// PSNR, dB, of the 8-bit sRGB images (∞ when identical).
    pub psnr: f64,
    /// Mean FLIP error.
    pub flip: f64,
}

/// One signal's scores in one frame.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SignalScores {
    /// The signal's name.
    pub signal: &'static str,
    /// The 1-spp trace against the reference.
    pub noisy: Score,
    /// The denoised trace against the reference.
    pub denoised: Score,
}

/// One pan frame's scores.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FrameScores {
    /// Frame of the pan, from 0.
    pub frame: u32,
    /// Per signal the scene renders (the shadow needs a light).
    pub signals: Vec<SignalScores>,
}

/// The camera of pan frame `f` of `frames`: `camera` turned left about its eye by
/// `pan_degrees × f / (frames − 1)`.
pub fn pan_camera(camera: &Camera, f: u32, frames: u32, pan_degrees: f32) -> Camera {
    let t = if frames > 1 {
        f as f32 / (frames - 1) as f32
    } else {
        0.0
    };
    let turn = Quat::from_axis_angle(Vec3::Y, (pan_degrees * t).to_radians());
    Camera {
        at: camera.eye + turn * (camera.at - camera.eye),
        ..*camera
    }
}

/// An image of visibility (or any value in 0..=1) per pixel as 8-bit grey, linearly.
fn unit_image(width: u32, height: u32, values: &[[f32; 3]]) -> Srgb8 {
    Srgb8 {
        width,
        height,
        pixels: values
            .iter()
            .map(|v| [(v[0].clamp(0.0, 1.0) * 255.0).round() as u8; 3])
            .collect(),
    }
}

/// Noisy, denoised and reference images of one signal as linear RGB per pixel.
struct Triple {
    signal: Signal,
    noisy: Vec<[f32; 3]>,
    denoised: Vec<[f32; 3]>,
    reference: Vec<[f32; 3]>,
}

impl Triple {
    fn encode(&self, width: u32, height: u32, v: &[[f32; 3]]) -> Srgb8 {
        match self.signal {
            Signal::Shadow => unit_image(width, height, v),
            _ => metrics::tone_map(width, height, v),
        }
    }
}

// A `String` error, not `AnyResult`: it crosses threads.
fn score(test: &Srgb8, reference: &Srgb8) -> Result<Score, String> {
    Ok(Score {
        psnr: metrics::psnr(test, reference)?,
        flip: metrics::flip(test, reference)?,
    })
}

/// Writes `noisy | denoised | reference` side by side.
fn write_strip(path: &Path, images: [&Srgb8; 3]) -> AnyResult<()> {
    let (w, h) = (images[0].width, images[0].height);
    let mut strip = image::RgbImage::new(3 * w, h);
    for (k, img) in images.iter().enumerate() {
        for (i, p) in img.pixels.iter().enumerate() {
            let (x, y) = (i as u32 % w, i as u32 / w);
            strip.put_pixel(k as u32 * w + x, y, image::Rgb(*p));
        }
    }
    strip
        .save(path)
        .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    Ok(())
}

/// Scores every signal of one frame (FLIP is the costly part: one thread per image) and writes
/// the strips when `strips` is a folder.
fn score_frame(
    frame: u32,
    size: (u32, u32),
    triples: &[Triple],
    strips: Option<&Path>,
) -> AnyResult<FrameScores> {
    let (w, h) = size;
    let encoded: Vec<[Srgb8; 3]> = triples
        .iter()
        .map(|t| {
            [
                t.encode(w, h, &t.noisy),
                t.encode(w, h, &t.denoised),
                t.encode(w, h, &t.reference),
            ]
        })
        .collect();
    let scores: Vec<AnyResult<(Score, Score)>> = std::thread::scope(|s| {
        let jobs: Vec<_> = encoded
            .iter()
            .map(|[n, d, r]| (s.spawn(|| score(n, r)), s.spawn(|| score(d, r))))
            .collect();
        jobs.into_iter()
            .map(|(n, d)| {
                let n = n.join().map_err(|_| "the scoring thread panicked")?;
                let d = d.join().map_err(|_| "the scoring thread panicked")?;
                Ok((n?, d?))
            })
            .collect()
    });
    let mut signals = Vec::new();
    for ((t, imgs), sc) in triples.iter().zip(&encoded).zip(scores) {
        let (noisy, denoised) = sc?;
        signals.push(SignalScores {
            signal: t.signal.name(),
            noisy,
            denoised,
        });
        if let Some(dir) = strips {
            let path = dir.join(format!("{}-{frame:03}.png", t.signal.name()));
            write_strip(&path, [&imgs[0], &imgs[1], &imgs[2]])?;
        }
    }
    Ok(FrameScores { frame, signals })
}

fn rgb(texels: &[[f32; 4]]) -> Vec<[f32; 3]> {
    texels.iter().map(|t| [t[0], t[1], t[2]]).collect()
}

/// Runs the yardstick on `scene` from `camera`; `on_frame` sees each frame's scores as they come.
pub fn run(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    scene: &Scene,
    camera: &Camera,
    opts: &QualityOptions,
    mut on_frame: impl FnMut(&FrameScores),
) -> AnyResult<Vec<FrameScores>> {
    if opts.frames == 0 || opts.reference_samples == 0 {
        return Err(format!(
            "ksrt quality: --frames ({}) and --reference-samples ({}) must be at least 1",
            opts.frames, opts.reference_samples
        )
        .into());
    }
    let mut ropts = RendererOptions::new(opts.size);
    ropts.effects = Effects {
        ao: false,
        ..Effects::default()
    };
    ropts.seed = opts.seed;
    let mut r = Renderer::new(device, queue, scene, &ropts)?;
    r.sdk.roughness_override = Some(SPECULAR_ROUGHNESS);
    warm_up(device, queue, &mut r, camera, opts)?;
    let bar = progress::bar(
        opts.progress,
        u64::from(opts.frames) * u64::from(opts.reference_samples),
        "reference samples",
        "samples",
    );
    let o = &r.sdk.outputs;
    let has_shadow = r.sdk.produced().shadow.0;
    let mut sums = vec![
        (
            Signal::Diffuse,
            Accumulator::new(device, &o.diffuse, SampleKind::Radiance),
        ),
        (
            Signal::Specular,
            Accumulator::new(device, &o.specular, SampleKind::Radiance),
        ),
    ];
    if has_shadow {
        sums.push((
            Signal::Shadow,
            Accumulator::new(device, &o.shadow, SampleKind::ShadowHitDistance),
        ));
    }
    let mut all = Vec::new();
    for f in 0..opts.frames {
        let cam = pan_camera(camera, f, opts.frames, opts.pan_degrees);
        r.render_frame(device, queue, &cam, false)?;
        let produced = r.sdk.produced();
        if !(produced.diffuse.1 && produced.specular.1) {
            return Err(format!(
                "ksrt quality: this kickstart-rt did not trace and denoise diffuse and specular \
                 (refused: {:?})",
                r.sdk.refused
            )
            .into());
        }
        // The measured images, before the reference's traces overwrite the raw outputs.
        let o = &r.sdk.outputs;
        let read = |t: &wgpu::Texture| read_texture(device, queue, t).map(|t| t.data);
        let mut triples = vec![
            Triple {
                signal: Signal::Diffuse,
                noisy: rgb(&read(&o.diffuse)?),
                denoised: rgb(&read(&o.diffuse_denoised)?),
                reference: Vec::new(),
            },
            Triple {
                signal: Signal::Specular,
                noisy: rgb(&read(&o.specular)?),
                denoised: rgb(&read(&o.specular_denoised)?),
                reference: Vec::new(),
            },
        ];
        if has_shadow {
            let lit = |t: &[f32; 4]| {
                let v = if t[0] < 0.0 { 1.0 } else { 0.0 };
                [v; 3]
            };
            triples.push(Triple {
                signal: Signal::Shadow,
                noisy: read(&o.shadow)?.iter().map(lit).collect(),
                denoised: rgb(&read(&o.shadow_denoised)?),
                reference: Vec::new(),
            });
        }
        // The reference: the same traces on this frame's G-buffer, white noise per sample.
        accumulate_reference(
            device,
            queue,
            &mut r,
            (f, opts.reference_samples),
            &sums,
            &bar,
        )?;
        for ((signal, acc), t) in sums.iter().zip(triples.iter_mut()) {
            debug_assert_eq!(*signal, t.signal);
            t.reference = acc.mean(device, queue)?;
        }
        let strips = match (opts.images, &opts.out) {
            (Images::All, Some(dir)) => Some(dir.as_path()),
            (Images::Last, Some(dir)) if f + 1 == opts.frames => Some(dir.as_path()),
            _ => None,
        };
        let scores = score_frame(f, opts.size, &triples, strips)?;
        bar.suspend(|| on_frame(&scores));
        all.push(scores);
    }
    bar.finish_and_clear();
    Ok(all)
}

/// Warms the lighting cache where the pan starts (the denoisers' history of these frames is
/// dropped), freezes it and makes the strips' folder.
fn warm_up(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    r: &mut Renderer,
    camera: &Camera,
    opts: &QualityOptions,
) -> AnyResult<()> {
    let bar = progress::bar(
        opts.progress,
        opts.warmup.into(),
        "warming the cache",
        "frames",
    );
    for _ in 0..opts.warmup {
        r.render_frame(device, queue, camera, false)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    r.sdk.freeze_cache = true;
    r.cut();
    if let Some(dir) = &opts.out {
        std::fs::create_dir_all(dir)
            .map_err(|e| format!("--out {}: cannot create: {e}", dir.display()))?;
    }
    Ok(())
}

/// Traces frame `f`'s `samples` reference samples on the last frame's G-buffer into `sums`
/// (cleared first), submitting every [`SAMPLES_PER_SUBMIT`], and counts them on `bar`.
fn accumulate_reference(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    r: &mut Renderer,
    (f, samples): (u32, u32),
    sums: &[(Signal, Accumulator)],
    bar: &indicatif::ProgressBar,
) -> AnyResult<()> {
    let mut encoder = device.create_command_encoder(&Default::default());
    for (_, acc) in sums {
        acc.clear(&mut encoder);
    }
    let mut pending = Vec::new();
    for k in 0..samples {
        let sample = 0x8000_0000u32
            .wrapping_add(f.wrapping_mul(samples))
            .wrapping_add(k);
        pending.extend(r.record_traces(&mut encoder, sample)?);
        for (_, acc) in sums {
            acc.add(&mut encoder);
        }
        if (k + 1) % SAMPLES_PER_SUBMIT == 0 || k + 1 == samples {
            queue.submit([encoder.finish()]);
            r.finish(device, &pending, false)?;
            pending.clear();
            encoder = device.create_command_encoder(&Default::default());
            bar.set_position(u64::from(f) * u64::from(samples) + u64::from(k + 1));
        }
    }
    Ok(())
}

/// The report's table: one line per frame, noisy → denoised PSNR and FLIP per signal.
pub fn table_header(signals: &[SignalScores]) -> String {
    let mut s = String::from("frame");
    for sig in signals {
        s += &format!(
            " | {:>8} PSNR noisy→denoised   FLIP noisy→denoised",
            sig.signal
        );
    }
    s
}

/// One frame's line of the table.
pub fn table_row(frame: &FrameScores) -> String {
    let mut s = format!("{:>5}", frame.frame);
    for sig in &frame.signals {
        s += &format!(
            " | {:>8} {:>6.2} → {:>6.2} dB       {:.4} → {:.4}",
            "", sig.noisy.psnr, sig.denoised.psnr, sig.noisy.flip, sig.denoised.flip
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pan_turns_about_the_eye_by_the_whole_angle_over_the_frames() {
        let c = Camera {
            eye: Vec3::new(1.0, 2.0, 3.0),
            at: Vec3::new(1.0, 2.0, 2.0),
            up: Vec3::Y,
            fov_y_deg: 60.0,
        };
        let first = pan_camera(&c, 0, 5, 8.0);
        assert!((first.at - c.at).length() < 1e-6);
        let last = pan_camera(&c, 4, 5, 8.0);
        let d0 = (c.at - c.eye).normalize();
        let d1 = (last.at - last.eye).normalize();
        let angle = d0.dot(d1).clamp(-1.0, 1.0).acos().to_degrees();
        assert!((angle - 8.0).abs() < 1e-3, "{angle}");
        assert_eq!(last.eye, c.eye);
        // Turning left about +Y takes −Z towards −X.
        assert!(d1.x < 0.0);
    }

    #[test]
    fn zero_frames_or_samples_are_refused_by_name() {
        let (device, queue) = crate::testing::device();
        let scene = crate::scene::load("cornell", Path::new(".")).expect("built-in scene");
        let camera = scene.camera_or_default(None);
        let base = QualityOptions {
            size: (8, 8),
            frames: 1,
            warmup: 0,
            reference_samples: 1,
            pan_degrees: 0.0,
            seed: 0,
            out: None,
            images: Images::None,
            progress: false,
        };
        for (frames, samples) in [(0, 1), (1, 0)] {
            let opts = QualityOptions {
                frames,
                reference_samples: samples,
                ..base.clone()
            };
            let err = run(device, queue, &scene, &camera, &opts, |_| {})
                .expect_err("refused")
                .to_string();
            assert!(
                err.contains("--frames") && err.contains("--reference-samples"),
                "{err}"
            );
        }
    }

    /// The Cornell box at 48², 6 frames, 64 reference samples: the command runs end to end,
    /// scores every signal, writes the last frame's strips, and the denoisers beat the noisy
    /// input for diffuse and specular on the last frame (the shadow stays close to the
    /// reference).
    #[test]
    fn denoised_beats_noisy_against_the_reference_on_the_cornell_box() {
        let (device, queue) = crate::testing::device();
        let scene = crate::scene::load("cornell", Path::new(".")).expect("built-in scene");
        let camera = scene.camera_or_default(None);
        let dir = crate::testing::temp_dir("quality-cornell");
        let opts = QualityOptions {
            size: (48, 48),
            frames: 6,
            warmup: 16,
            reference_samples: 64,
            pan_degrees: 2.0,
            seed: 1,
            out: Some(dir.clone()),
            images: Images::Last,
            progress: false,
        };
        let frames = run(device, queue, &scene, &camera, &opts, |_| {}).expect("quality run");
        assert_eq!(frames.len(), 6);
        let last = frames.last().unwrap();
        let names: Vec<_> = last.signals.iter().map(|s| s.signal).collect();
        assert_eq!(names, ["diffuse", "specular", "shadow"]);
        for s in &last.signals {
            eprintln!("{s:?}");
            assert!(s.noisy.psnr.is_finite() && s.noisy.flip > 0.0, "{s:?}");
            if s.signal == "shadow" {
                // The Cornell light is small: one shadow ray per pixel is nearly exact already
                // (~28 dB), and at 48² the penumbra-guided filter's pixel of blur costs more than
                // the little noise it removes. What must hold is that it stays close.
                assert!(s.denoised.psnr > 20.0, "{s:?}");
                continue;
            }
            assert!(
                s.denoised.psnr > s.noisy.psnr + 3.0,
                "{}: denoised {:.2} dB is not well above noisy {:.2} dB",
                s.signal,
                s.denoised.psnr,
                s.noisy.psnr
            );
            assert!(s.denoised.flip < s.noisy.flip, "{s:?}");
        }
        for name in ["diffuse", "specular", "shadow"] {
            let img = image::open(dir.join(format!("{name}-005.png")))
                .expect("strip written")
                .to_rgb8();
            assert_eq!(img.dimensions(), (144, 48));
        }
        assert!(!dir.join("diffuse-004.png").exists());
    }
}
