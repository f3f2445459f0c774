//! `ksrt`: the kickstart-rt demo, renderer and benchmark tool. It uses only the SDK's public API.

mod app;
mod lab;

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};
use kickstart_rt_renderer::error::AnyResult;

use app::debug_view::DebugView;
use lab::{bench, quality};

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
    Shaders(ShadersCli),
    /// Render a scene with the rasteriser and the SDK's effects and write PNG images: `final.png`
    /// and each channel (`direct`, `specular`, `diffuse`, `ao`, `shadow`, raw and `-denoised`),
    /// then `cpu-reference.png` (traced on the CPU reference BVH) and the GPU debug views
    /// `debug-<view>.png` (only the one asked for with --debug-view). Prints the GPU time of each
    /// SDK pass.
    Render(RenderCli),
    /// Open a window on a scene: fly with WASD/QE and the mouse (hold the left button), toggle
    /// effects with 1–6, cycle debug views with V; SDK timings in the title bar.
    View(ViewCli),
    /// Measure the denoisers: along a slow pan, each frame's 1-spp diffuse, specular (roughness
    /// 0.3), AO and shadow traces, raw and denoised, against a converged reference of the same
    /// frame (the same traces through the frozen lighting cache, averaged over
    /// --reference-samples); prints PSNR and FLIP per frame on the tone-mapped 8-bit sRGB images
    /// (exposure 1, Reinhard, sRGB; AO and shadow visibility linear) and the energy ratio of the
    /// linear values, a summary (last frame, mean over frames 8..=last), then the flicker of
    /// --still-frames frames of a still camera against a reference's; writes noisy | denoised |
    /// reference strips.
    Quality(QualityCli),
    /// Render many frames of every effect while the scene churns (geometries and instances
    /// registered, updated and destroyed every few frames), fail on any SDK error, and check that
    /// the SDK's memory comes back once the churn is destroyed; prints what it did and the memory.
    Soak(SoakCli),
    /// Benchmark BLAS/TLAS builds and refits, BVH quality and ray throughput on the GPU.
    Bench(BenchCli),
    /// Compare two `ksrt render` output folders: the PSNR of every PNG image both hold (8-bit,
    /// peak 255); fails when one is below --min-db.
    Compare(CompareCli),
}

// `ksrt compare`'s options (no doc comment: the variant's is the help text).
#[derive(Args)]
struct CompareCli {
    /// The folder compared.
    a: PathBuf,
    /// The folder it is compared against.
    b: PathBuf,
    /// Least PSNR every image must have, dB.
    #[arg(long, default_value_t = 40.0)]
    min_db: f64,
}

// `ksrt shaders`'s options (no doc comment: the variant's is the help text).
#[derive(Args)]
struct ShadersCli {
    /// Folder to write the shaders into.
    #[arg(long)]
    dump: Option<PathBuf>,
}

// `ksrt render`'s options (no doc comment: the variant's is the help text).
#[derive(Args)]
struct RenderCli {
    /// Image size, WIDTHxHEIGHT [default: 1280x720; 640x360 on a CPU device].
    #[arg(long)]
    size: Option<String>,
    /// Output folder.
    #[arg(long, default_value = "out")]
    out: PathBuf,
    /// A GPU primary-ray debug view instead of the CPU reference image.
    #[arg(long, value_enum)]
    debug_view: Option<DebugView>,
    /// Scene: default, cornell, window-room, grove, dancers, town, crowd, statue, dragon,
    /// apartment, bunny, cornell-obj, cornell-gltf, or a path to a .gltf/.glb/.obj file.
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
    /// Also write the SDK pass timings (medians of the last frames) and its memory peak as JSON
    /// to this file.
    #[arg(long)]
    json: Option<PathBuf>,
    /// Also write the SDK's memory at its peak over the frames, by kind and by denoising
    /// context, as CSV (`kind,bytes`) to this file.
    #[arg(long)]
    memory_csv: Option<PathBuf>,
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
    /// Scene time, seconds, of an animated scene's pose (its first animation, looping).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    time: f32,
}

// `ksrt view`'s options (no doc comment: the variant's is the help text).
#[derive(Args)]
struct ViewCli {
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
}

// `ksrt quality`'s options (no doc comment: the variant's is the help text).
#[derive(Args)]
struct QualityCli {
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
    #[arg(long, default_value_t = 8.0, allow_hyphen_values = true, value_parser = app::args::parse_degrees)]
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
}

// `ksrt soak`'s options (no doc comment: the variant's is the help text).
#[derive(Args)]
struct SoakCli {
    /// Scene (as for `render`).
    #[arg(long, default_value = "default")]
    scene: String,
    /// Scenes folder [default: $KSRT_SCENES, else the repository's scenes/].
    #[arg(long)]
    scenes: Option<PathBuf>,
    /// Frames of churn, in two rounds (at least 2: one a round).
    #[arg(long, default_value_t = 2000, value_parser = clap::value_parser!(u32).range(2..))]
    frames: u32,
    /// Image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "160x90")]
    size: String,
    /// Seed of the churn.
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

// `ksrt bench`'s options (no doc comment: the variant's is the help text).
#[derive(Args)]
struct BenchCli {
    /// Scenes folder [default: $KSRT_SCENES, else the repository's scenes/].
    #[arg(long)]
    scenes: Option<PathBuf>,
    /// Scenes to benchmark (repeatable): any scene `render` takes (the built-in default, cornell,
    /// window-room, grove (cutouts), dancers (skinned), town, crowd, statue; dragon, apartment,
    /// bunny, cornell-obj, cornell-gltf; or a file) [default: statue and apartment].
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
}

fn main() {
    env_logger::Builder::from_env(env_logger::Env::default().default_filter_or("warn")).init();
    let cli = Cli::parse();
    app::gpu::set_backend_choice(cli.backend.into());
    if let Err(e) = run(cli.command) {
        eprintln!("ksrt: {e}");
        std::process::exit(1);
    }
}

/// Runs one command.
fn run(command: Command) -> AnyResult<()> {
    match command {
        Command::Info => app::gpu::info(),
        Command::Shaders(c) => app::shaders::run(c.dump.as_deref()),
        Command::Render(c) => app::render::run_at(
            app::render::RenderArgs {
                size: c.size,
                out: c.out,
                debug_view: c.debug_view,
                scene: c.scene,
                scenes: c.scenes,
                camera: c.camera,
                frames: c.frames,
                effects: c.effects,
                seed: c.seed,
                hdr: c.hdr,
                no_reference: c.no_reference,
                json: c.json,
                memory_csv: c.memory_csv,
                frames_in_flight: c.frames_in_flight,
                preset: c.preset,
            },
            c.time,
        ),
        Command::View(c) => app::view::run(app::view::ViewArgs {
            scene: c.scene,
            scenes_dir: app::scenes::scenes_dir(c.scenes),
            size: c.size,
            effects: c.effects,
            camera: c.camera,
            frames: c.frames,
            screenshot: c.screenshot,
        }),
        Command::Quality(c) => quality::command::run(quality_args(c)),
        Command::Soak(c) => lab::soak::command(&c.scene, c.scenes, c.frames, &c.size, c.seed),
        Command::Compare(c) => lab::compare::command(&c.a, &c.b, c.min_db),
        Command::Bench(c) => bench::command::run(bench::command::BenchArgs {
            scenes: c.scenes,
            names: c.scene,
            json: c.json,
            camera: c.camera,
            iterations: c.iterations,
            size: c.size,
            denoisers: c.denoisers,
            extras: c.extras,
            peer: c.peer,
        }),
    }
}

/// `ksrt quality`'s options for the lab (the adapter's defaults resolved there).
fn quality_args(c: QualityCli) -> quality::command::QualityArgs {
    quality::command::QualityArgs {
        scene: c.scene,
        scenes: c.scenes,
        size: c.size,
        camera: c.camera,
        frames: c.frames,
        warmup: c.warmup,
        reference_samples: c.reference_samples,
        opts: quality::run::QualityOptions {
            size: (0, 0),
            frames: 0,
            warmup: 0,
            reference_samples: 0,
            pan_degrees: c.pan_degrees,
            still_frames: c.still_frames,
            seed: c.seed,
            out: Some(c.out),
            images: c.images,
            progress: true,
            preset: c.preset,
        },
        json: c.json,
    }
}

/// The layers of this crate, lowest first: the application's modules, then the lab; `main.rs`
/// stands above them all and nothing imports it.
#[cfg(test)]
const LAYERS: &[&[&str]] = &[
    &[
        "app",
        "app::args",
        "app::defaults",
        "app::progress",
        "app::timings",
        "app::gpu",
        "app::memory",
    ],
    &["app::readback", "app::scenes", "app::frames"],
    &["app::frames_in_flight", "app::debug_view"],
    &["app::lit", "app::cpu_reference", "app::shaders"],
    &["app::render", "app::view"],
    &["lab"],
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn imports_point_down_the_layers_without_loops() {
        let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
        if let Err(problems) = kickstart_rt_layering::check(&src, LAYERS) {
            panic!("layering of kickstart-rt-demo:\n{}", problems.join("\n"));
        }
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
            Command::Bench(BenchCli { extras, .. }) => {
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
                    Command::Render(RenderCli {
                        frames_in_flight, ..
                    }),
                ..
            }) => assert_eq!(frames_in_flight, 2),
            _ => panic!("render --frames-in-flight 2 does not parse"),
        }
        let default = Cli::try_parse_from(["ksrt", "render"]).expect("render parses");
        assert!(matches!(
            default.command,
            Command::Render(RenderCli {
                frames_in_flight: 1,
                ..
            })
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
    fn quality_pan_and_soak_frames_refuse_values_that_do_nothing() {
        for pan in ["NaN", "inf", "1e9"] {
            let args = ["ksrt", "quality", "--pan-degrees", pan];
            assert!(Cli::try_parse_from(args).is_err(), "--pan-degrees {pan}");
        }
        let pan = Cli::try_parse_from(["ksrt", "quality", "--pan-degrees", "-12"]);
        assert!(matches!(
            pan.map(|c| c.command),
            Ok(Command::Quality(QualityCli { pan_degrees, .. })) if pan_degrees == -12.0
        ));
        for frames in ["0", "1"] {
            let args = ["ksrt", "soak", "--frames", frames];
            assert!(Cli::try_parse_from(args).is_err(), "--frames {frames}");
        }
        let soak = Cli::try_parse_from(["ksrt", "soak", "--frames", "2"]);
        assert!(matches!(
            soak.map(|c| c.command),
            Ok(Command::Soak(SoakCli { frames: 2, .. }))
        ));
    }

    #[test]
    fn render_takes_the_pose_time() {
        let time = |args: &[&str]| match Cli::try_parse_from(args).map(|c| c.command) {
            Ok(Command::Render(c)) => Ok(c.time),
            Ok(_) => Err("not render".to_string()),
            Err(e) => Err(e.to_string()),
        };
        assert_eq!(time(&["ksrt", "render"]), Ok(0.0));
        assert_eq!(time(&["ksrt", "render", "--time", "1.25"]), Ok(1.25));
        assert_eq!(time(&["ksrt", "render", "--time", "-0.5"]), Ok(-0.5));
        assert!(time(&["ksrt", "render", "--time", "soon"]).is_err());
    }

    #[test]
    fn bench_accepts_the_vulkan_rt_peer() {
        let cli = Cli::try_parse_from(["ksrt", "bench", "--peer", "vulkan-rt"]);
        assert!(matches!(
            cli.map(|c| c.command),
            Ok(Command::Bench(BenchCli {
                peer: Some(bench::PeerKind::VulkanRt),
                ..
            }))
        ));
        assert!(Cli::try_parse_from(["ksrt", "bench", "--peer", "optix"]).is_err());
    }

    #[test]
    fn bench_sections_select_measurements() {
        use bench::extras::Section;
        let sections = |args: &[&str]| match Cli::try_parse_from(args).map(|c| c.command) {
            Ok(Command::Bench(BenchCli { extras, .. })) => Ok(extras.sections),
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
