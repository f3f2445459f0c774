//! `ksrt`: the kickstart-rt demo, renderer and benchmark tool. It uses only the SDK's public API.

mod bench;
mod cmd_render;
mod composite;
mod debug_view;
mod defaults;
#[cfg(test)]
mod first_view_tests;
mod frame;
mod frames_in_flight;
#[cfg(test)]
mod golden;
mod gpu;
mod lit;
mod obvhs_peer;
mod progress;
mod quality;
mod raster;
mod readback;
mod render;
mod renderer;
mod rng;
mod scene;
mod sdk_glue;
mod shaders;
mod soak;
#[cfg(test)]
mod testing;
mod view;

use std::path::PathBuf;

use clap::{Parser, Subcommand};

/// Result of the `ksrt` commands: any error, printed by `main`.
pub type AnyResult<T> = Result<T, Box<dyn std::error::Error>>;

/// kickstart-rt's demo and tool.
#[derive(Parser)]
#[command(
    name = "ksrt",
    version,
    about = "kickstart-rt: ray-traced effects on wgpu — demo and tools"
)]
struct Cli {
    /// How the SDK traces rays: `auto` takes the GPU's ray-tracing hardware (wgpu ray queries)
    /// where the adapter has it, the SDK's own BVH traversal elsewhere.
    #[arg(long, global = true, value_enum, default_value_t = BackendArg::Auto)]
    backend: BackendArg,
    #[command(subcommand)]
    command: Command,
}

/// `--backend`: the SDK's `BackendChoice`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
enum BackendArg {
    /// Hardware ray queries when the adapter has them, else software.
    Auto,
    /// The SDK's own BVH and traversal, on every GPU.
    Software,
    /// Hardware ray queries (an error where the adapter has none).
    Hardware,
}

impl From<BackendArg> for kickstart_rt::BackendChoice {
    fn from(b: BackendArg) -> Self {
        match b {
            BackendArg::Auto => kickstart_rt::BackendChoice::Auto,
            BackendArg::Software => kickstart_rt::BackendChoice::Software,
            BackendArg::Hardware => kickstart_rt::BackendChoice::HardwareRayQuery,
        }
    }
}

#[derive(Subcommand)]
enum Command {
    /// Print the adapter, backend, and the features/limits the SDK needs or can use.
    Info,
    /// List every WGSL shader the SDK can create (each variant, as composed); with --dump, write
    /// each to DIR/<variant>.wgsl with an index.txt (no GPU needed).
    Shaders {
        /// Folder to write the shaders into.
        #[arg(long)]
        dump: Option<PathBuf>,
    },
    /// Render a scene with the rasteriser and the SDK's effects and write PNG images: `final.png`
    /// and each channel (`direct`, `specular`, `diffuse`, `ao`, `shadow`, raw and `-denoised`),
    /// then `cpu-reference.png` (traced on the CPU reference BVH) and the GPU debug views
    /// `debug-<view>.png` (only the one asked for with --debug-view). Prints the GPU time of each
    /// SDK pass.
    Render {
        /// Image size, WIDTHxHEIGHT [default: 1280x720; 640x360 on a CPU device].
        #[arg(long)]
        size: Option<String>,
        /// Output folder.
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// A GPU primary-ray debug view instead of the CPU reference image.
        #[arg(long, value_enum)]
        debug_view: Option<debug_view::DebugView>,
        /// Scene: default, cornell, window-room, town, crowd, dragon, apartment, bunny, cornell-obj,
        /// cornell-gltf, or a path to a .gltf/.glb/.obj file.
        #[arg(long, default_value = "default")]
        scene: String,
        /// Scenes folder [default: $KSRT_SCENES, else the repository's scenes/].
        #[arg(long)]
        scenes: Option<PathBuf>,
        /// Camera: eye_x,eye_y,eye_z,at_x,at_y,at_z,fov_deg (y up); default: the file's, else one
        /// framing the scene.
        #[arg(long, allow_hyphen_values = true)]
        camera: Option<String>,
        /// Frames to run before writing the images (the lighting cache and the denoisers settle
        /// over them) [default: 32; 3 on a CPU device].
        #[arg(long)]
        frames: Option<u32>,
        /// Effects, comma-separated, each NAME or NAME=on|off, applied in order to all on:
        /// specular, diffuse, ao, shadow, denoise, lidar, or all/none (e.g. `none,ao`).
        #[arg(long, default_value = "all")]
        effects: String,
        /// Seed of the SDK's ray noise.
        #[arg(long, default_value_t = 0)]
        seed: u32,
        /// Also write each image as linear OpenEXR (`<name>.exr`).
        #[arg(long)]
        hdr: bool,
        /// Only the lit images: no CPU reference image and no debug views (benchmark runs).
        #[arg(long)]
        no_reference: bool,
        /// Also write the SDK pass timings (medians of the last frames) as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Frames the CPU may record ahead of the GPU, 1..=3 (1: wait for each frame before
        /// recording the next). Each frame's CPU time of `build_gpu_task` and its wait for the
        /// frame N back are printed and in --json.
        #[arg(long, default_value_t = 1)]
        frames_in_flight: u32,
        /// Rays per pixel and denoiser: quality (every pixel, the high-quality denoiser),
        /// balanced (one ray per 2×2 pixels for every effect, the fast denoiser) or performance
        /// (one per 4×4 for reflections, GI and AO, per 2×2 for shadows; the fast denoiser).
        #[arg(long, default_value = "quality")]
        preset: kickstart_rt::Preset,
    },
    /// Open a window on a scene: fly with WASD/QE and the mouse (hold the left button), toggle
    /// effects with 1–6, cycle debug views with V; SDK timings in the title bar.
    View {
        /// Scene (as for `render`).
        #[arg(long, default_value = "default")]
        scene: String,
        /// Scenes folder [default: $KSRT_SCENES, else the repository's scenes/].
        #[arg(long)]
        scenes: Option<PathBuf>,
        /// Window size, WIDTHxHEIGHT [default: 1280x720; 640x360 on a CPU device].
        #[arg(long)]
        size: Option<String>,
        /// Effects at start (as for `render`).
        #[arg(long, default_value = "all")]
        effects: String,
        /// Start camera (as for `render`).
        #[arg(long, allow_hyphen_values = true)]
        camera: Option<String>,
        /// Close after this many frames, writing the last one to --screenshot (for tests and
        /// headless runs under Xvfb).
        #[arg(long)]
        frames: Option<u32>,
        /// Where to write the last frame when --frames ends the run.
        #[arg(long)]
        screenshot: Option<PathBuf>,
    },
    /// Measure the denoisers: along a slow pan, each frame's 1-spp diffuse, specular (roughness
    /// 0.3), AO and shadow traces, raw and denoised, against a converged reference of the same
    /// frame (the same traces through the frozen lighting cache, averaged over
    /// --reference-samples); prints PSNR and FLIP per frame on the tone-mapped 8-bit sRGB images
    /// (exposure 1, Reinhard, sRGB; AO and shadow visibility linear) and the energy ratio of the
    /// linear values, a summary (last frame, mean over frames 8..=last), then the flicker of
    /// --still-frames frames of a still camera against a reference's; writes noisy | denoised |
    /// reference strips.
    Quality {
        /// Scene (as for `render`).
        #[arg(long, default_value = "apartment")]
        scene: String,
        /// Scenes folder [default: $KSRT_SCENES, else the repository's scenes/].
        #[arg(long)]
        scenes: Option<PathBuf>,
        /// Image size, WIDTHxHEIGHT [default: 1920x1080; 320x180 on a CPU device].
        #[arg(long)]
        size: Option<String>,
        /// Start camera (as for `render`) [default: the for apartment and dragon, else
        /// the file's or one framing the scene].
        #[arg(long, allow_hyphen_values = true)]
        camera: Option<String>,
        /// Measured frames along the pan [default: 32; 4 on a CPU device].
        #[arg(long)]
        frames: Option<u32>,
        /// Frames warming the lighting cache before it is frozen [default: 64; 8 on a CPU
        /// device].
        #[arg(long)]
        warmup: Option<u32>,
        /// Samples per pixel of each frame's reference [default: 2048; 64 on a CPU device].
        #[arg(long)]
        reference_samples: Option<u32>,
        /// Yaw of the whole pan, degrees.
        #[arg(long, default_value_t = 8.0, allow_hyphen_values = true)]
        pan_degrees: f32,
        /// Frames held still at the pan's last camera after it, measuring the denoised output's
        /// flicker (0: none).
        #[arg(long, default_value_t = 8)]
        still_frames: u32,
        /// Rays per pixel and denoiser of the measured frames (as for `render`).
        #[arg(long, default_value = "quality")]
        preset: kickstart_rt::Preset,
        /// Seed of the measured frames' noise.
        #[arg(long, default_value_t = 0)]
        seed: u32,
        /// Output folder for the strips.
        #[arg(long, default_value = "out/quality")]
        out: PathBuf,
        /// Which frames' strips to write.
        #[arg(long, value_enum, default_value = "all")]
        images: quality::run::Images,
        /// Also write every frame's scores as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Render many frames of every effect while the scene churns (geometries and instances
    /// registered, updated and destroyed every few frames), fail on any SDK error, and check that
    /// the SDK's memory comes back once the churn is destroyed; prints what it did and the memory.
    Soak {
        /// Scene (as for `render`).
        #[arg(long, default_value = "default")]
        scene: String,
        /// Scenes folder [default: $KSRT_SCENES, else the repository's scenes/].
        #[arg(long)]
        scenes: Option<PathBuf>,
        /// Frames of churn.
        #[arg(long, default_value_t = 2000)]
        frames: u32,
        /// Image size, WIDTHxHEIGHT.
        #[arg(long, default_value = "160x90")]
        size: String,
        /// Seed of the churn.
        #[arg(long, default_value_t = 1)]
        seed: u64,
    },
    /// Benchmark BLAS/TLAS builds and refits, BVH quality and ray throughput on the GPU.
    Bench {
        /// Scenes folder [default: $KSRT_SCENES, else the repository's scenes/].
        #[arg(long)]
        scenes: Option<PathBuf>,
        /// Scenes to benchmark (repeatable) [default: dragon and apartment].
        #[arg(long)]
        scene: Vec<String>,
        /// Also write the results as JSON to this file.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Camera for every scene (eye_x,eye_y,eye_z,at_x,at_y,at_z,fov_deg) [default: the
        /// issue's for dragon and apartment, else the file's or one framing the scene].
        #[arg(long, allow_hyphen_values = true)]
        camera: Option<String>,
        /// Timed repetitions of each measurement, after one warm-up [default: 5; 1 on a CPU
        /// device].
        #[arg(long)]
        iterations: Option<u32>,
        /// Size of the ray batches' image, WIDTHxHEIGHT [default: 1920x1080; 320x180 on a CPU
        /// device].
        #[arg(long)]
        size: Option<String>,
        /// Only time the denoisers (every task and method, synthetic inputs at --size).
        #[arg(long)]
        denoisers: bool,
        /// CPU peers, scaling, frames in flight and charts (bench/extras/).
        #[command(flatten)]
        extras: bench::extras::ExtraArgs,
        /// Also measure a peer on the same meshes and rays and print ours, theirs and the
        /// ratio (skipped, with the reason, where this machine has no such peer).
        #[arg(long, value_enum)]
        peer: Option<bench::PeerKind>,
    },
}

/// Parses `--size WIDTHxHEIGHT`, each side in 1..=16384.
pub(crate) fn parse_size(size: &str) -> AnyResult<(u32, u32)> {
    let (w, h) = size
        .split_once('x')
        .and_then(|(w, h)| Some((w.trim().parse().ok()?, h.trim().parse().ok()?)))
        .ok_or_else(|| format!("--size {size:?}: expected WIDTHxHEIGHT, e.g. 1280x720"))?;
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("--size {w}x{h}: each side must be in 1..=16384").into());
    }
    Ok((w, h))
}

/// `ksrt quality`'s options; `None`: the default for the adapter ([`defaults`]).
struct QualityArgs {
    scene: String,
    scenes: Option<PathBuf>,
    size: Option<String>,
    camera: Option<String>,
    frames: Option<u32>,
    warmup: Option<u32>,
    reference_samples: Option<u32>,
    opts: quality::run::QualityOptions,
    json: Option<PathBuf>,
}

fn quality_command(args: QualityArgs) -> AnyResult<()> {
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
    let scene = cmd_render::load_scene(&args.scene, args.scenes)?;
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

/// `ksrt bench`'s options; `None`: the default for the adapter ([`defaults`]).
struct BenchArgs {
    scenes: Option<PathBuf>,
    names: Vec<String>,
    json: Option<PathBuf>,
    camera: Option<String>,
    iterations: Option<u32>,
    size: Option<String>,
    denoisers: bool,
    extras: bench::extras::ExtraArgs,
    peer: Option<bench::PeerKind>,
}

fn bench_command(args: BenchArgs) -> AnyResult<()> {
    if let (Some(dir), Some(json)) = (&args.extras.plots, &args.extras.plots_from) {
        // Charts of an earlier run: no GPU, no measurement.
        return bench::extras::plots_from_json(json, dir);
    }
    let info = gpu::adapter()?.get_info();
    let mut picked = defaults::Resolver::new(defaults::is_software(&info));
    let size = picked.pick(
        args.size.as_deref(),
        defaults::MEASURE_SIZE,
        "{v}",
        "--size",
    );
    let size = parse_size(size)?;
    let iterations = picked.pick(
        args.iterations,
        defaults::BENCH_ITERATIONS,
        "{v} iteration(s)",
        "--iterations",
    );
    if let Some(notice) = picked.notice(&info) {
        eprintln!("{notice}");
    }
    if args.denoisers {
        args.extras.check()?;
        return bench::denoise::run(
            size,
            iterations,
            args.extras.busy_gpu_ms,
            args.json.as_deref(),
        );
    }
    bench::run(bench::BenchOptions {
        scenes_dir: scene::scenes_dir(args.scenes),
        scenes: args.names,
        json: args.json,
        camera: args
            .camera
            .as_deref()
            .map(scene::parse_camera)
            .transpose()?,
        iterations,
        size,
        extras: args.extras,
        peer: args.peer,
    })
}

fn main() {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let cli = Cli::parse();
    gpu::set_backend_choice(cli.backend.into());
    let result = match cli.command {
        Command::Info => gpu::info(),
        Command::Shaders { dump } => shaders::run(dump.as_deref()),
        Command::Render {
            size,
            out,
            debug_view,
            scene,
            scenes,
            camera,
            frames,
            effects,
            seed,
            hdr,
            no_reference,
            json,
            frames_in_flight,
            preset,
        } => cmd_render::run(cmd_render::RenderArgs {
            size,
            out,
            debug_view,
            scene,
            scenes,
            camera,
            frames,
            effects,
            seed,
            hdr,
            no_reference,
            json,
            frames_in_flight,
            preset,
        }),
        Command::View {
            scene,
            scenes,
            size,
            effects,
            camera,
            frames,
            screenshot,
        } => view::run(view::ViewArgs {
            scene,
            scenes_dir: scene::scenes_dir(scenes),
            size,
            effects,
            camera,
            frames,
            screenshot,
        }),
        Command::Quality {
            scene,
            scenes,
            size,
            camera,
            frames,
            warmup,
            reference_samples,
            pan_degrees,
            still_frames,
            preset,
            seed,
            out,
            images,
            json,
        } => quality_command(QualityArgs {
            scene,
            scenes,
            size,
            camera,
            frames,
            warmup,
            reference_samples,
            opts: quality::run::QualityOptions {
                size: (0, 0),
                frames: 0,
                warmup: 0,
                reference_samples: 0,
                pan_degrees,
                still_frames,
                seed,
                out: Some(out),
                images,
                progress: true,
                preset,
            },
            json,
        }),
        Command::Soak {
            scene,
            scenes,
            frames,
            size,
            seed,
        } => soak::command(&scene, scenes, frames, &size, seed),
        Command::Bench {
            scenes,
            scene,
            json,
            camera,
            iterations,
            size,
            denoisers,
            extras,
            peer,
        } => bench_command(BenchArgs {
            scenes,
            names: scene,
            json,
            camera,
            iterations,
            size,
            denoisers,
            extras,
            peer,
        }),
    };
    if let Err(e) = result {
        eprintln!("ksrt: {e}");
        std::process::exit(1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn size_parsing() {
        assert_eq!(parse_size("320x180").ok(), Some((320, 180)));
        assert!(parse_size("320").is_err());
        assert!(parse_size("0x10").is_err());
        assert!(parse_size("axb").is_err());
    }

    #[test]
    fn cli_takes_the_bench_passes_and_frames_in_flight() {
        let cli = Cli::try_parse_from([
            "ksrt",
            "bench",
            "--skip-scenes",
            "--cpu-peers",
            "--scaling",
            "--frames-in-flight",
            "--plots",
            "out/plots",
        ])
        .expect("bench passes parse");
        match cli.command {
            Command::Bench { extras, .. } => {
                assert!(extras.skip_scenes && extras.cpu_peers && extras.scaling);
                assert!(extras.frames_in_flight && !extras.quick);
                assert_eq!(extras.fif_frames, 120);
                assert_eq!(extras.plots, Some(PathBuf::from("out/plots")));
            }
            _ => panic!("not bench"),
        }
        // Redrawing needs a folder to draw into.
        assert!(Cli::try_parse_from(["ksrt", "bench", "--plots-from", "r.json"]).is_err());
        // --backend is global: before or after the command, and only the three choices.
        for args in [
            &["ksrt", "--backend", "software", "render"][..],
            &["ksrt", "render", "--backend", "software"],
        ] {
            let cli = Cli::try_parse_from(args).expect("parses");
            assert_eq!(cli.backend, BackendArg::Software);
        }
        assert_eq!(
            Cli::try_parse_from(["ksrt", "info"]).unwrap().backend,
            BackendArg::Auto
        );
        assert!(Cli::try_parse_from(["ksrt", "render", "--backend", "rtx"]).is_err());
        match Cli::try_parse_from(["ksrt", "render", "--frames-in-flight", "2"]) {
            Ok(Cli {
                command:
                    Command::Render {
                        frames_in_flight, ..
                    },
                ..
            }) => assert_eq!(frames_in_flight, 2),
            _ => panic!("render --frames-in-flight 2 does not parse"),
        }
        let default = Cli::try_parse_from(["ksrt", "render"]).expect("render parses");
        assert!(matches!(
            default.command,
            Command::Render {
                frames_in_flight: 1,
                ..
            }
        ));
    }

    #[test]
    fn cli_accepts_negative_camera_values() {
        let cli = Cli::try_parse_from([
            "ksrt",
            "bench",
            "--camera",
            "-0.006,0.125,0.32,-0.006,0.125,-0.005,30",
            "--scene",
            "dragon",
        ]);
        assert!(cli.is_ok());
    }

    #[test]
    fn bench_accepts_the_vulkan_rt_peer() {
        let cli = Cli::try_parse_from(["ksrt", "bench", "--peer", "vulkan-rt"]);
        assert!(matches!(
            cli.map(|c| c.command),
            Ok(Command::Bench {
                peer: Some(bench::PeerKind::VulkanRt),
                ..
            })
        ));
        assert!(Cli::try_parse_from(["ksrt", "bench", "--peer", "optix"]).is_err());
    }

    #[test]
    fn bench_sections_select_measurements() {
        use bench::extras::Section;
        let sections = |args: &[&str]| match Cli::try_parse_from(args).map(|c| c.command) {
            Ok(Command::Bench { extras, .. }) => Ok(extras.sections),
            Ok(_) => panic!("not bench"),
            Err(e) => Err(e),
        };
        let some = sections(&["ksrt", "bench", "--sections", "rays,tasks"]).expect("parses");
        assert_eq!(some, vec![Section::Rays, Section::Tasks]);
        assert!(Section::Rays.runs_in(&some) && !Section::Builds.runs_in(&some));
        let all = sections(&["ksrt", "bench"]).expect("parses");
        assert!(Section::Tlas.runs_in(&all) && Section::Cache.runs_in(&all));
        assert!(sections(&["ksrt", "bench", "--sections", "rays,bvh"]).is_err());
    }
}
