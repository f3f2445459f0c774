//! `ksrt quality`: resolves the options for the adapter, runs the measurement ([`super::run`])
//! and prints (and writes) its scores.

use std::path::PathBuf;

use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::scene;

use crate::app::args::parse_size;
use crate::app::{defaults, gpu};
use crate::lab::quality;

/// `ksrt quality`'s options; `None`: the default for the adapter ([`defaults`]).
pub struct QualityArgs {
    pub scene: String,
    pub scenes: Option<PathBuf>,
    pub size: Option<String>,
    pub camera: Option<String>,
    pub frames: Option<u32>,
    pub warmup: Option<u32>,
    pub reference_samples: Option<u32>,
    pub opts: quality::run::QualityOptions,
    pub json: Option<PathBuf>,
}

/// `ksrt quality`.
pub fn run(args: QualityArgs) -> AnyResult<()> {
    let mut opts = args.opts;
    let camera = args
        .camera
        .as_deref()
        .map(scene::parse_camera)
        .transpose()?;
    let adapter = gpu::adapter()?;
    let info = adapter.get_info();
    let mut picked = defaults::Resolver::new(defaults::is_software(&info));
    let size = picked.pick(
        args.size.as_deref(),
        defaults::MEASURE_SIZE,
        "{v}",
        "--size",
    );
    opts.size = parse_size(size)?;
    opts.frames = picked.pick(
        args.frames,
        defaults::QUALITY_FRAMES,
        "{v} frames",
        "--frames",
    );
    opts.warmup = picked.pick(
        args.warmup,
        defaults::QUALITY_WARMUP,
        "{v} warm-up frames",
        "--warmup",
    );
    opts.reference_samples = picked.pick(
        args.reference_samples,
        defaults::QUALITY_SAMPLES,
        "{v} spp",
        "--reference-samples",
    );
    if let Some(notice) = picked.notice(&info) {
        eprintln!("{notice}");
    }
    let scene = crate::app::scenes::load_scene(&args.scene, args.scenes)?;
    let camera = scene.camera_or_default(camera.or_else(|| scene::benchmark_camera(&args.scene)));
    let (device, queue) = gpu::device(&adapter)?;
    println!(
        "ksrt quality: {} at {}x{}, preset {}, {} frames panning {}°, cache warmed {} frames then \
         frozen, reference {} spp; scores on 8-bit sRGB (exposure {}, Reinhard; AO and shadow \
         linear), energy ratios on the linear values",
        scene.name,
        opts.size.0,
        opts.size.1,
        opts.preset.name(),
        opts.frames,
        opts.pan_degrees,
        opts.warmup,
        opts.reference_samples,
        quality::metrics::EXPOSURE
    );
    let start = std::time::Instant::now();
    let mut header = false;
    let report = quality::run::run(&device, &queue, &scene, &camera, &opts, |f| {
        if !header {
            println!("{}", quality::report::table_header(&f.signals));
            header = true;
        }
        println!("{}", quality::report::table_row(f));
    })?;
    for line in quality::report::summary_lines(&report.summary) {
        println!("{line}");
    }
    if let Some(stability) = &report.stability {
        for line in quality::report::stability_lines(stability) {
            println!("{line}");
        }
    }
    println!(
        "{} frames ({} still) in {:.1} s; strips in {}",
        report.frames.len(),
        opts.still_frames,
        start.elapsed().as_secs_f64(),
        opts.out
            .as_deref()
            .unwrap_or(std::path::Path::new("-"))
            .display()
    );
    if let Some(path) = &args.json {
        let value = serde_json::json!({
            "scene": scene.name,
            "preset": opts.preset.name(),
            "size": [opts.size.0, opts.size.1],
            "frames": opts.frames,
            "warmup": opts.warmup,
            "reference_samples": opts.reference_samples,
            "pan_degrees": opts.pan_degrees,
            "still_frames": opts.still_frames,
            "specular_roughness": quality::run::SPECULAR_ROUGHNESS,
            "exposure": quality::metrics::EXPOSURE,
            "tone_map": "exposure, Reinhard c/(1+c), sRGB, 8 bit; \
                         AO and shadow visibility linear 8 bit",
            "energy_ratio": "mean linear value (radiance: Rec. 709 luminance) over the \
                             reference's, over the pixels with a surface; null where the \
                             reference is ~0",
            "flicker": "mean over surface pixels of |L_t - L_t-1| of the linear value, \
                        averaged over the still frames; reference: between two references",
            "scores": report.frames,
            "summary": report.summary,
            "stability": report.stability,
        });
        std::fs::write(path, serde_json::to_string_pretty(&value)?)
            .map_err(|e| format!("--json {}: {e}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
