//! `ksrt bench`: BLAS build, refit and skinned-refit times, BVH quality (SAH cost against the CPU
//! reference builder), TLAS build and refit times, and ray throughput, all timed on the GPU with
//! the SDK's timestamp queries, and the trace tasks (each alone at full and checkerboard
//! resolution, multi-light shadows against the light count, the four together). Ray generation
//! and other CPU work between batches is not timed.
//!
//! One job a file: this one holds the options, the statistics and [`run`]; `harness` the device
//! state and the timing every figure goes through; `scenes` each scene's BLAS, SAH, ray, cache
//! and trace-task figures and the TLAS figures; `skinned` the skinned refit (a rig generated
//! for every mesh, posed by the SDK's skinning tasks); `rays` the ray batches; `tasks` the SDK's
//! trace tasks; `report` the `--json` report's types and a scene's printed figures. The optional
//! passes are in `extras`, the driver peer in `peer`, the denoiser bench (`--denoisers`) in
//! `denoise`.

use std::path::PathBuf;

use kickstart_rt as ksrt;
use serde::{Deserialize, Serialize};

use crate::app::gpu;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::scene::{self, Camera, Scene};

mod backends;
mod busy;
mod cache;
pub mod command;
pub mod denoise;
pub mod extras;
mod harness;
mod options;
mod peer;
mod profile;
mod rays;
mod report;
mod scenes;
mod skinned;
mod tasks;
mod tree_work;

use harness::Bench;
pub use peer::PeerKind;
use profile as prof;
use report::{print_scene, SceneReport, TlasReport};
use scenes::{bench_scene, bench_tlas};

/// Scenes benchmarked when no `--scene` is given.
pub const DEFAULT_SCENES: [&str; 2] = ["statue", "apartment"];

/// Instance counts of the TLAS measurements.
pub const TLAS_INSTANCE_COUNTS: [u32; 3] = [1_000, 10_000, 100_000];

/// The whole `--json` report.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// kickstart-rt version.
    pub sdk_version: String,
    /// Adapter name.
    pub adapter: String,
    /// Driver name and version, as wgpu reports them.
    pub driver: String,
    /// The commit `ksrt` was built from (embedded at build time; `-dirty` with local changes).
    pub commit: String,
    /// wgpu backend.
    pub backend: String,
    /// Whether the device has timestamp queries (without them nothing is timed).
    pub timestamp_query: bool,
    /// Ray batch image width.
    pub width: u32,
    /// Ray batch image height.
    pub height: u32,
    /// Timed repetitions per measurement.
    pub iterations: u32,
    /// Order of the ray batches' primary rays.
    pub ray_order: extras::RayOrder,
    /// GPU work (milliseconds at full clocks) submitted untimed before each timed task
    /// (`--busy-gpu-ms`; 0: none).
    pub busy_gpu_ms: f64,
    /// Per scene.
    pub scenes: Vec<SceneReport>,
    /// Per instance count.
    pub tlas: Vec<TlasReport>,
    /// The optional passes' results (`cpu_peers`, `scaling`, `frames_in_flight`).
    #[serde(flatten)]
    pub extras: extras::ExtrasReport,
}

/// Options of `ksrt bench`.
pub struct BenchOptions {
    /// The scenes folder.
    pub scenes_dir: PathBuf,
    /// Scene names or paths.
    pub scenes: Vec<String>,
    /// Where to write the JSON report, if anywhere.
    pub json: Option<PathBuf>,
    /// Camera for every scene, overriding the and the files'.
    pub camera: Option<Camera>,
    /// Timed repetitions of each measurement (after one untimed warm-up).
    pub iterations: u32,
    /// Ray batch image size.
    pub size: (u32, u32),
    /// The optional passes (`extras`).
    pub extras: extras::ExtraArgs,
    /// A peer to compare with on the same rays (`--peer`), if any.
    pub peer: Option<PeerKind>,
}

/// Median, minimum and maximum of the timed repetitions, milliseconds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Stats {
    /// Median.
    pub median_ms: f64,
    /// Fastest.
    pub min_ms: f64,
    /// Slowest.
    pub max_ms: f64,
    /// Every repetition, in order.
    pub samples_ms: Vec<f64>,
}

impl Stats {
    /// Statistics of `samples` (at least one).
    pub fn new(samples: Vec<f64>) -> Stats {
        let mut sorted = samples.clone();
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len();
        let median = match n {
            0 => f64::NAN,
            _ if n % 2 == 1 => sorted[n / 2],
            _ => (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0,
        };
        Stats {
            median_ms: median,
            min_ms: sorted.first().copied().unwrap_or(f64::NAN),
            max_ms: sorted.last().copied().unwrap_or(f64::NAN),
            samples_ms: samples,
        }
    }

    fn show(&self) -> String {
        format!(
            "{:.3} ms ({:.3}..{:.3})",
            self.median_ms, self.min_ms, self.max_ms
        )
    }
}

/// Runs `f`, keeping its error as text in `errors` (labelled `what`) so that one failed
/// measurement does not hide the others.
fn attempt<T>(errors: &mut Vec<String>, what: &str, f: impl FnOnce() -> AnyResult<T>) -> Option<T> {
    match f() {
        Ok(v) => Some(v),
        Err(e) => {
            // Printed with the scene's results; the log gets it at once for long runs.
            log::debug!("{what}: {e}");
            errors.push(format!("{what}: {e}"));
            None
        }
    }
}

/// Builds and refits a TLAS over each of `counts` instances, printing each result (above
/// `bar`, which counts them).
fn tlas_sweep(bench: &Bench, counts: &[u32], bar: &indicatif::ProgressBar) -> Vec<TlasReport> {
    let mut out = Vec::with_capacity(counts.len());
    for &count in counts {
        bar.set_message(format!("bench TLAS {count}"));
        let t = bench_tlas(bench, count);
        bar.inc(1);
        bar.suspend(|| {
            let opt = |s: &Option<Stats>| s.as_ref().map_or("—".to_string(), Stats::show);
            println!(
                "  {:>7} instances  build {}  refit {}",
                count,
                opt(&t.build),
                opt(&t.refit)
            );
            for p in [&t.build_profile, &t.refit_profile] {
                if !p.is_empty() {
                    println!("    profile    {}", prof::show(p));
                }
            }
            for e in &t.errors {
                println!("    failed: {e}");
            }
        });
        out.push(t);
    }
    out
}

/// The scenes `ksrt bench` measures (none with `--skip-scenes`, the defaults when none is
/// named), each loaded (flattened with `--flatten`, made opaque with `--opaque`) before any GPU work, so that a wrong
/// name fails at once.
fn load_scenes(opts: &BenchOptions) -> AnyResult<(Vec<String>, Vec<Scene>)> {
    let names: Vec<String> = if opts.extras.skip_scenes {
        Vec::new()
    } else if opts.scenes.is_empty() {
        DEFAULT_SCENES.iter().map(|s| s.to_string()).collect()
    } else {
        opts.scenes.clone()
    };
    let mut scenes = Vec::new();
    for name in &names {
        let start = std::time::Instant::now();
        let loaded = crate::app::progress::with_spinner(true, format!("loading {name}"), || {
            crate::app::scenes::load(name, &opts.scenes_dir)
        })?;
        let mut loaded = if opts.extras.flatten {
            loaded.flattened()?
        } else {
            loaded
        };
        if opts.extras.opaque {
            for mesh in &mut loaded.meshes {
                mesh.material.alpha = kickstart_rt_renderer::scene::AlphaMode::Opaque;
            }
        }
        scenes.push(loaded);
        println!("loaded {name} in {:.2} s", start.elapsed().as_secs_f64());
    }
    Ok((names, scenes))
}

/// Measures each scene from its camera (`--camera`, else its benchmark camera, else its own),
/// printing each result above `bar`, which counts them.
fn scene_sweep(
    bench: &Bench,
    opts: &BenchOptions,
    names: &[String],
    scenes: &[Scene],
    mut peer: Option<&mut peer::PeerState>,
    bar: &indicatif::ProgressBar,
) -> Vec<SceneReport> {
    let mut out = Vec::with_capacity(scenes.len());
    for (name, scene) in names.iter().zip(scenes) {
        bar.set_message(format!("bench {name}"));
        let camera = opts
            .camera
            .or_else(|| scene::benchmark_camera(name))
            .unwrap_or_else(|| scene.camera_or_default(None));
        let r = bench_scene(
            bench,
            name,
            scene,
            camera,
            opts.size,
            peer.as_deref_mut(),
            opts.extras.tree_work,
        );
        bar.suspend(|| {
            print_scene(&r, opts.size);
            if let Some(b) = &r.backends {
                backends::print(b, &r);
            }
            if let Some(p) = &r.peer {
                peer::print(p);
            }
        });
        bar.inc(1);
        out.push(r);
    }
    out
}

/// How many measurements of `report` failed (each is listed with its scene or section).
fn failures(report: &Report) -> usize {
    report
        .scenes
        .iter()
        .map(|s| s.errors.len() + s.backends.as_ref().map_or(0, |b| b.errors.len()))
        .sum::<usize>()
        + report.tlas.iter().map(|t| t.errors.len()).sum::<usize>()
        + report.extras.failures()
}

/// `ksrt bench`.
pub fn run(opts: BenchOptions) -> AnyResult<()> {
    if opts.iterations == 0 {
        return Err("--iterations must be at least 1".into());
    }
    // Load every scene first: a wrong name fails before minutes of GPU work.
    opts.extras.check()?;
    if opts.peer.is_some() && opts.extras.ray_order != extras::RayOrder::Rows {
        // The driver peer launches the rays as a 2-D image of rows (its own tiling of the launch
        // then decides their grouping), so tiled rays would be compared in a scrambled order.
        return Err("--peer needs --ray-order rows (the peer's launch is row by row)".into());
    }
    let (names, scenes) = load_scenes(&opts)?;
    let adapter = gpu::adapter()?;
    let timestamp_query = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
    if !timestamp_query {
        log::warn!("the adapter has no TIMESTAMP_QUERY: GPU times cannot be measured");
    }
    let (device, queue) = gpu::device(&adapter)?;
    let info = adapter.get_info();
    println!(
        "kickstart-rt {} (commit {}) bench on {} ({:?}, driver {} {}), {} iterations after a warm-up",
        ksrt::VERSION,
        env!("KSRT_COMMIT"),
        info.name,
        info.backend,
        info.driver,
        info.driver_info,
        opts.iterations
    );
    let mut bench = Bench::new(&device, &queue, opts.iterations);
    bench.ray_order = opts.extras.ray_order;
    bench.sections = opts.extras.sections.clone();
    if opts.extras.busy_gpu_ms > 0.0 {
        bench.busy = Some(busy::BusyGpu::new(&device, opts.extras.busy_gpu_ms));
        println!(
            "each timed task follows ~{} ms of untimed GPU work (--busy-gpu-ms)",
            opts.extras.busy_gpu_ms
        );
    }
    let mut peer = opts.peer.map(|kind| peer::open(kind, &info));
    let mut report = Report {
        sdk_version: ksrt::VERSION.to_string(),
        adapter: info.name.clone(),
        driver: format!("{} {}", info.driver, info.driver_info),
        commit: env!("KSRT_COMMIT").to_string(),
        backend: format!("{:?}", info.backend),
        timestamp_query,
        width: opts.size.0,
        height: opts.size.1,
        iterations: opts.iterations,
        ray_order: opts.extras.ray_order,
        busy_gpu_ms: opts.extras.busy_gpu_ms,
        scenes: Vec::new(),
        tlas: Vec::new(),
        extras: Default::default(),
    };
    // One step per scene and per TLAS size: each takes seconds to minutes on software Vulkan.
    let bar = crate::app::progress::bar(
        true,
        (names.len() + TLAS_INSTANCE_COUNTS.len()) as u64,
        "bench",
        "steps",
    );
    report.scenes = scene_sweep(&bench, &opts, &names, &scenes, peer.as_mut(), &bar);
    let tlas_counts: &[u32] =
        if opts.extras.skip_scenes || !extras::Section::Tlas.runs_in(&opts.extras.sections) {
            &[]
        } else {
            bar.suspend(|| {
                println!("\nTLAS (instances of an 80-triangle sphere, random transforms):");
            });
            &TLAS_INSTANCE_COUNTS
        };
    bar.set_length((names.len() + tlas_counts.len()) as u64);
    report.tlas = tlas_sweep(&bench, tlas_counts, &bar);
    bar.finish_and_clear();
    extras::run(
        &bench,
        &opts.scenes_dir,
        opts.size,
        &opts.extras,
        &mut report.extras,
    )?;
    if let Some(path) = &opts.json {
        let text = serde_json::to_string_pretty(&report)?;
        std::fs::write(path, text)
            .map_err(|e| format!("--json {}: cannot write: {e}", path.display()))?;
        println!("wrote {}", path.display());
    }
    let failed = failures(&report);
    if failed > 0 {
        return Err(format!("{failed} measurements failed (listed above)").into());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_driver_peer_with_tiled_rays_is_refused_before_any_gpu_work() {
        let opts = BenchOptions {
            scenes_dir: PathBuf::from("/nonexistent"),
            scenes: vec!["dragon".into()],
            json: None,
            camera: None,
            iterations: 1,
            size: (16, 16),
            extras: extras::ExtraArgs {
                ray_order: extras::RayOrder::Tiles,
                ..Default::default()
            },
            peer: Some(PeerKind::VulkanRt),
        };
        let err = run(opts).expect_err("refused").to_string();
        assert!(
            err.contains("--peer") && err.contains("--ray-order rows"),
            "{err}"
        );
    }

    #[test]
    fn busy_gpu_ms_outside_0_to_1000_is_refused() {
        for bad in [-1.0, 1000.5, f64::NAN] {
            let args = extras::ExtraArgs {
                busy_gpu_ms: bad,
                ..Default::default()
            };
            let err = args.check().expect_err("refused").to_string();
            assert!(err.contains("--busy-gpu-ms"), "{err}");
        }
        let ok = extras::ExtraArgs {
            busy_gpu_ms: 2.0,
            ..Default::default()
        };
        assert!(ok.check().is_ok());
    }

    #[test]
    fn stats_median_min_max() {
        let s = Stats::new(vec![3.0, 1.0, 2.0, 10.0]);
        assert_eq!((s.median_ms, s.min_ms, s.max_ms), (2.5, 1.0, 10.0));
        assert_eq!(Stats::new(vec![4.0, 1.0, 2.0]).median_ms, 2.0);
    }

    #[test]
    fn benchmark_cameras_parse() {
        assert!(scene::benchmark_camera("dragon").is_some());
        assert!(scene::benchmark_camera("statue").is_some());
        assert!(scene::benchmark_camera("apartment").is_some());
        assert!(scene::benchmark_camera("bunny").is_none());
    }
}
