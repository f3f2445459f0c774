//! `ksrt bench --frames-in-flight`: `ksrt render`'s frame loop on the apartment at the bench
//! size with 1, 2 and 3 frames in flight; per depth the CPU time of `build_gpu_task`, of
//! recording and submitting a frame, how many frames found the frame N back still on the GPU and
//! how long the CPU waited, and the frame interval. GPU timestamps are off (their read-back
//! would wait for the GPU).

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::app::frames_in_flight::{self as fif, FifSummary, FrameRecord, LoopOptions};
use crate::lab::bench::attempt;
use crate::lab::bench::harness::Bench;
use kickstart_rt_renderer::scene::benchmark_camera;

/// The scene of the measurement.
pub const FIF_SCENE: &str = "apartment";
/// Depths measured.
pub const DEPTHS: [u32; 3] = [1, 2, 3];

/// The `--frames-in-flight` result.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct FifReport {
    /// Scene.
    pub scene: String,
    /// Frame width.
    pub width: u32,
    /// Frame height.
    pub height: u32,
    /// Frames per depth.
    pub frames: u32,
    /// Leading frames left out of the summaries.
    pub warmup: u32,
    /// CPU cores of the machine.
    pub cpu_threads: usize,
    /// One per depth.
    pub summaries: Vec<FifSummary>,
    /// Every frame of every depth, in the order of `summaries`.
    pub records: Vec<Vec<FrameRecord>>,
    /// Measurements that failed, and why.
    pub errors: Vec<String>,
}

/// Runs the loop `frames` frames for each of [`DEPTHS`].
pub(in crate::lab::bench) fn run(
    bench: &Bench,
    scenes_dir: &Path,
    size: (u32, u32),
    frames: u32,
    scene_name: &'static str,
) -> FifReport {
    let warmup = frames / 4;
    let mut report = FifReport {
        scene: scene_name.to_string(),
        width: size.0,
        height: size.1,
        frames,
        warmup,
        cpu_threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        ..Default::default()
    };
    let Some(scene) = attempt(&mut report.errors, &format!("load {scene_name}"), || {
        super::load(scene_name, scenes_dir)
    }) else {
        return report;
    };
    let camera = benchmark_camera(scene_name).unwrap_or_else(|| scene.camera_or_default(None));
    for depth in DEPTHS {
        let records = attempt(
            &mut report.errors,
            &format!("{depth} frames in flight"),
            || {
                let mut opts = crate::app::frames::renderer_options(size);
                opts.frames_in_flight = depth;
                let mut r =
                    crate::app::frames::new_renderer(bench.device, bench.queue, &scene, &opts)?;
                let looped = fif::run(
                    &mut r,
                    bench.device,
                    bench.queue,
                    &camera,
                    LoopOptions {
                        frames,
                        depth: fif::check_depth(depth)?,
                        timed_frames: 0,
                    },
                    || {},
                )?;
                Ok(looped.records)
            },
        );
        if let Some(records) = records {
            let s = fif::summarise(depth, &records, warmup as usize);
            println!(
                "  {depth} in flight: build_gpu_task {:.3} ms, GPU busy {}/{}, frame {:.3} ms",
                s.sdk_build_ms, s.frames_waited, s.frames, s.frame_ms
            );
            report.summaries.push(s);
            report.records.push(records);
        }
    }
    println!(
        "  {scene_name} {}x{}, {frames} frames each, medians after {warmup} warm-up frames:\n{}",
        size.0,
        size.1,
        fif::table(&report.summaries)
    );
    for e in &report.errors {
        println!("  failed: {e}");
    }
    report
}
