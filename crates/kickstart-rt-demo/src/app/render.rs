//! `ksrt render`: the lit image and its channels, the GPU debug views (traced on the lit
//! render's own context, after its frames) and the CPU reference, written as images, with the
//! SDK's GPU timings.

use std::path::PathBuf;

use crate::app::debug_view::DebugView;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::{frame, scene};

use crate::app::{cpu_reference, defaults, frames_in_flight, gpu, lit, scenes, timings};

/// `ksrt render`'s options; `None`: the default for the adapter ([`crate::app::defaults`]).
pub struct RenderArgs {
    /// `--size WIDTHxHEIGHT`.
    pub size: Option<String>,
    /// `--out DIR`.
    pub out: PathBuf,
    /// `--debug-view`: only this view, and no CPU reference.
    pub debug_view: Option<DebugView>,
    /// `--scene`.
    pub scene: String,
    /// `--scenes DIR`.
    pub scenes: Option<PathBuf>,
    /// `--camera`.
    pub camera: Option<String>,
    /// `--frames N`.
    pub frames: Option<u32>,
    /// `--effects`.
    pub effects: String,
    /// `--seed`.
    pub seed: u32,
    /// `--hdr`.
    pub hdr: bool,
    /// `--no-reference`: the lit images only.
    pub no_reference: bool,
    /// `--json FILE`.
    pub json: Option<PathBuf>,
    /// `--memory-csv FILE`.
    pub memory_csv: Option<PathBuf>,
    /// `--frames-in-flight N`.
    pub frames_in_flight: u32,
    /// `--preset`.
    pub preset: kickstart_rt::Preset,
}

/// Runs `ksrt render` with an animated scene posed at `time` seconds (`--time`; the first
/// animation, looping): the frames, the debug views and the CPU reference all show that pose.
pub fn run_at(args: RenderArgs, time: f32) -> AnyResult<()> {
    if !time.is_finite() {
        return Err(format!("--time {time}: must be a finite number of seconds").into());
    }
    let effects = frame::Effects::parse(&args.effects)?;
    frames_in_flight::check_depth(args.frames_in_flight)?;
    let camera = args
        .camera
        .as_deref()
        .map(scene::parse_camera)
        .transpose()?;
    let adapter = gpu::adapter()?;
    let info = adapter.get_info();
    let mut picked = defaults::Resolver::new(defaults::is_software(&info));
    let size = picked.pick(args.size.as_deref(), defaults::VIEW_SIZE, "{v}", "--size");
    let (width, height) = crate::app::args::parse_size(size)?;
    let frames = picked.pick(
        args.frames,
        defaults::RENDER_FRAMES,
        "{v} frames",
        "--frames",
    );
    if frames == 0 {
        return Err("--frames 0: render at least one frame".into());
    }
    if let Some(notice) = picked.notice(&info) {
        eprintln!("{notice}");
    }
    let (device, queue) = gpu::device(&adapter)?;
    let mut scene = scenes::load_scene(&args.scene, args.scenes.clone())?;
    // The benchmark cameras of the issue frame the dragon and the apartment interior well.
    let camera = scene.prepare_view(camera.or_else(|| scene::benchmark_camera(&args.scene)));
    let views = match (args.no_reference, args.debug_view) {
        (true, _) => Vec::new(),
        (false, Some(v)) => vec![v],
        (false, None) => DebugView::ALL.to_vec(),
    };
    let start = std::time::Instant::now();
    let result = lit::render(
        &device,
        &queue,
        &scene,
        &camera,
        &lit::LitOptions {
            size: (width, height),
            frames,
            effects,
            seed: args.seed,
            preset: args.preset,
            progress: true,
            gpu_timing: true,
            frames_in_flight: args.frames_in_flight,
            debug_views: views,
            time,
        },
    )?;
    println!(
        "registered {} meshes, {} instances ({} triangles) with kickstart-rt; SDK memory {} bytes",
        scene.meshes.len(),
        scene.instances.len(),
        scene.triangle_count(),
        result.memory.total()
    );
    print!(
        "{}",
        result.memory.breakdown(
            u64::from(width) * u64::from(height),
            scene.triangle_count() as u64
        )
    );
    if let Some(path) = &args.memory_csv {
        result.memory.write_csv(path)?;
        println!("wrote {}", path.display());
    }
    println!(
        "traversal backend: {} ({})",
        result.backend.backend, result.backend.reason
    );
    let written = lit::write(&result, &args.out, args.hdr)?;
    println!(
        "wrote {} images to {} ({width}x{height}, {frames} frames, preset {}, in {:.2} s): {}",
        written.len(),
        args.out.display(),
        args.preset.name(),
        start.elapsed().as_secs_f64(),
        result
            .channels
            .iter()
            .map(|c| c.name)
            .collect::<Vec<_>>()
            .join(", ")
    );
    report(&result, &scene.name, (width, height), frames, &args)?;
    if args.no_reference {
        return Ok(());
    }
    if args.debug_view.is_none() {
        // The CPU reference traces the same pose: the same CPU skinning as the renderer's.
        let posed = (!scene.rigs.is_empty()).then(|| scene.posed(time));
        cpu_reference::render(
            posed.as_ref().unwrap_or(&scene),
            &cpu_reference::RenderOptions {
                width,
                height,
                out: args.out.clone(),
                camera,
            },
            true,
        )?;
    }
    for (view, texels) in &result.debug {
        let image = crate::app::debug_view::to_image(*view, &texels.data, width, height);
        let path = args.out.join(format!("debug-{}.png", view.name()));
        image
            .save(&path)
            .map_err(|e| format!("{}: {e}", path.display()))?;
        println!(
            "wrote {} ({width}x{height}, primary rays through kickstart-rt on the lit render's context)",
            path.display()
        );
    }
    Ok(())
}

/// Prints what the SDK refused, the GPU timings and the CPU cost per frame, and writes `--json`.
fn report(
    result: &lit::LitResult,
    scene_name: &str,
    size: (u32, u32),
    frames: u32,
    args: &RenderArgs,
) -> AnyResult<()> {
    if !result.refused.is_empty() {
        println!(
            "this kickstart-rt refuses {:?} as unsupported: not rendered",
            result.refused
        );
    }
    if !result.missing.is_empty() {
        println!(
            "not written (effect off or unsupported): {}",
            result.missing.join(", ")
        );
    }
    if result.timings.is_empty() {
        println!("no SDK GPU timings (no SDK pass ran, or the device has no timestamp queries)");
    } else {
        print!("{}", timings::timing_table(&result.timings));
    }
    // The first frames compile pipelines and fill the lighting cache: left out of the summary.
    let depth = args.frames_in_flight;
    let fif = frames_in_flight::summarise(depth, &result.frames, (frames / 4) as usize);
    print!(
        "CPU per frame, {depth} frame(s) in flight (medians of the last {} frames):\n{}",
        fif.frames,
        frames_in_flight::table(std::slice::from_ref(&fif))
    );
    if let Some(path) = &args.json {
        let mut value = timings::timing_json(scene_name, size, frames, &result.timings);
        value["frames_in_flight"] = serde_json::json!({"summary": fif, "frames": result.frames});
        value["preset"] = serde_json::json!(args.preset.name());
        value["traversal_backend"] = serde_json::json!(result.backend.backend.to_string());
        value["memory"] = result.memory.json();
        std::fs::write(path, serde_json::to_string_pretty(&value)?)
            .map_err(|e| format!("--json {}: {e}", path.display()))?;
        println!("wrote {}", path.display());
    }
    Ok(())
}
