//! `ksrt bench`'s command: the options resolved for the adapter.

use std::path::PathBuf;

use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::scene;

use crate::app::args::parse_size;
use crate::app::{defaults, gpu, scenes};
use crate::lab::bench;

/// `ksrt bench`'s options; `None`: the default for the adapter ([`defaults`]).
pub struct BenchArgs {
    pub scenes: Option<PathBuf>,
    pub names: Vec<String>,
    pub json: Option<PathBuf>,
    pub camera: Option<String>,
    pub iterations: Option<u32>,
    pub size: Option<String>,
    pub denoisers: bool,
    pub extras: bench::extras::ExtraArgs,
    pub peer: Option<bench::PeerKind>,
}

/// `ksrt bench`: resolves the options for the adapter and runs the benchmark ([`bench::run`])
/// or, with `--denoisers`, the denoiser bench.
pub fn run(args: BenchArgs) -> AnyResult<()> {
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
        scenes_dir: scenes::scenes_dir(args.scenes),
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
