//! `ksrt render`'s frame loop with N frames in flight (`--frames-in-flight N`): before recording
//! frame f the CPU waits for frame f − N (its fence: the submission index), so with N = 1 it
//! waits for the previous frame (what `ksrt render` always did: submit, then wait) and with 2 or
//! 3 it records ahead while the GPU runs earlier frames. Per frame it measures the CPU time of
//! building the SDK's GPU task (`build_gpu_task`, inside the frame's recording), of the whole
//! recording and of the submit, and whether the frame it had to retire was still running on the
//! GPU and how long the CPU waited for it (see
//! `reference/dx12-frames-in-flight-inline-rt-report.txt`).

use std::collections::VecDeque;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use kickstart_rt as ksrt;
use serde::{Deserialize, Serialize};

use crate::app::timings::median;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::renderer::Renderer;
use kickstart_rt_renderer::scene::Camera;

/// Most frames in flight `--frames-in-flight` accepts.
pub const MAX_FRAMES_IN_FLIGHT: u32 = 3;

/// Checks `--frames-in-flight N` (1..=3).
pub fn check_depth(n: u32) -> Result<usize, String> {
    if (1..=MAX_FRAMES_IN_FLIGHT).contains(&n) {
        Ok(n as usize)
    } else {
        Err(format!(
            "--frames-in-flight {n}: must be 1, 2 or 3 (frames the CPU may record ahead of the GPU)"
        ))
    }
}

/// The submitted frames not yet retired, oldest first, at most `depth` of them: the
/// bookkeeping of the loop, apart from the GPU so that it is tested on its own.
#[derive(Debug)]
pub struct InFlight<T> {
    depth: usize,
    frames: VecDeque<T>,
}

impl<T> InFlight<T> {
    /// An empty ring for `depth` (≥ 1) frames in flight.
    pub fn new(depth: usize) -> Self {
        InFlight {
            depth: depth.max(1),
            frames: VecDeque::new(),
        }
    }

    /// Whether the oldest frame must be retired (waited for) before another is recorded: a new
    /// frame would make more than `depth` in flight.
    pub fn must_retire(&self) -> bool {
        self.frames.len() >= self.depth
    }

    /// Removes the oldest frame (to wait for and retire).
    pub fn pop_oldest(&mut self) -> Option<T> {
        self.frames.pop_front()
    }

    /// Adds a submitted frame.
    pub fn push(&mut self, frame: T) {
        self.frames.push_back(frame);
    }

    /// Frames in flight now.
    #[cfg(test)]
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether none is in flight.
    #[cfg(test)]
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }
}

/// What one frame cost the CPU.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameRecord {
    /// Frame number.
    pub frame: u32,
    /// CPU time of the SDK's `build_gpu_task` calls of this frame (the frame's container and
    /// the debug view's), ms.
    pub sdk_build_ms: f64,
    /// CPU time of recording the whole frame (raster passes, SDK tasks, composite), ms.
    pub record_ms: f64,
    /// CPU time of `encoder.finish()` and `queue.submit`, ms.
    pub submit_ms: f64,
    /// The frame retired before this one was recorded (f − N), if any.
    pub waited_for: Option<u32>,
    /// Whether that frame was still running on the GPU when the CPU came to it (so the CPU
    /// blocked).
    pub gpu_busy: bool,
    /// CPU time blocked waiting for it, ms (0 when it had finished).
    pub wait_ms: f64,
    /// CPU time from this frame's start to the next one's (the frame interval; for the last
    /// frame, to the end of the final drain), ms.
    pub frame_ms: f64,
}

/// The per-frame records summarised (medians over the frames after `warmup`).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct FifSummary {
    /// Frames in flight.
    pub frames_in_flight: u32,
    /// Frames summarised.
    pub frames: u32,
    /// Median CPU time of `build_gpu_task` per frame, ms.
    pub sdk_build_ms: f64,
    /// Median CPU time of recording a frame, ms.
    pub record_ms: f64,
    /// Median CPU time of finishing and submitting, ms.
    pub submit_ms: f64,
    /// Frames whose CPU found the frame N back still running on the GPU.
    pub frames_waited: u32,
    /// Mean CPU time blocked on the GPU per frame, ms.
    pub mean_wait_ms: f64,
    /// Median frame interval on the CPU, ms.
    pub frame_ms: f64,
    /// 1000 / the mean frame interval.
    pub fps: f64,
}

/// Summarises `records` after dropping the first `warmup` frames (first frames compile
/// pipelines and fill the lighting cache).
pub fn summarise(depth: u32, records: &[FrameRecord], warmup: usize) -> FifSummary {
    let r = records.get(warmup..).unwrap_or(&[]);
    let n = r.len();
    let col = |f: fn(&FrameRecord) -> f64| median(r.iter().map(f).collect());
    let mean = |f: fn(&FrameRecord) -> f64| {
        if n == 0 {
            0.0
        } else {
            r.iter().map(f).sum::<f64>() / n as f64
        }
    };
    let mean_frame = mean(|x| x.frame_ms);
    FifSummary {
        frames_in_flight: depth,
        frames: n as u32,
        sdk_build_ms: col(|x| x.sdk_build_ms),
        record_ms: col(|x| x.record_ms),
        submit_ms: col(|x| x.submit_ms),
        frames_waited: r.iter().filter(|x| x.gpu_busy).count() as u32,
        mean_wait_ms: mean(|x| x.wait_ms),
        frame_ms: col(|x| x.frame_ms),
        fps: if mean_frame > 0.0 {
            1000.0 / mean_frame
        } else {
            0.0
        },
    }
}

/// The table of summaries (`ksrt bench --frames-in-flight`, `ksrt render`).
pub fn table(rows: &[FifSummary]) -> String {
    let mut s = String::from(
        "  in flight  frames  build_gpu_task  record    submit    GPU busy  mean wait  frame     fps\n",
    );
    for r in rows {
        s += &format!(
            "  {:>9}  {:>6}  {:>11.3} ms  {:>6.3} ms  {:>6.3} ms  {:>3}/{:<4}  {:>6.3} ms  {:>6.3} ms  {:>6.1}\n",
            r.frames_in_flight,
            r.frames,
            r.sdk_build_ms,
            r.record_ms,
            r.submit_ms,
            r.frames_waited,
            r.frames,
            r.mean_wait_ms,
            r.frame_ms,
            r.fps
        );
    }
    s
}

/// A submitted frame, until it is retired.
struct Pending {
    frame: u32,
    index: wgpu::SubmissionIndex,
    done: Arc<AtomicBool>,
    tasks: Vec<ksrt::GpuTaskHandle>,
}

/// How the wait for a retired frame went.
struct Retired {
    frame: u32,
    gpu_busy: bool,
    wait_ms: f64,
}

/// Waits for `p`'s submission (unless the GPU already reported it done) and marks its SDK tasks
/// complete.
fn retire(device: &wgpu::Device, ctx: &ksrt::ExecuteContext, p: Pending) -> AnyResult<Retired> {
    // A non-blocking poll runs the submitted-work-done callbacks of what has finished.
    device.poll(wgpu::PollType::Poll)?;
    let gpu_busy = !p.done.load(Ordering::Acquire);
    let mut wait_ms = 0.0;
    if gpu_busy {
        let start = Instant::now();
        device.poll(wgpu::PollType::Wait {
            submission_index: Some(p.index),
            timeout: None,
        })?;
        wait_ms = start.elapsed().as_secs_f64() * 1e3;
    }
    for task in p.tasks {
        match ctx.mark_gpu_task_completed(task) {
            Ok(()) | Err(ksrt::Error::InvalidGpuTaskHandle(_)) => {}
            Err(e) => return Err(e.into()),
        }
    }
    Ok(Retired {
        frame: p.frame,
        gpu_busy,
        wait_ms,
    })
}

/// What the loop produced.
pub struct LoopResult {
    /// Every frame's CPU record.
    pub records: Vec<FrameRecord>,
    /// GPU timings of the SDK's passes in each of the last `timed_frames` frames (when the
    /// renderer measures them), read after the final drain so that no read-back blocks the loop.
    pub timings: Vec<ksrt::GpuTimings>,
    /// The SDK's memory at its peak over the frames (sampled after each frame is recorded).
    pub memory: crate::app::memory::MemoryPeak,
}

/// How many frames the loop renders, and how.
#[derive(Debug, Clone, Copy)]
pub struct LoopOptions {
    /// Frames to render.
    pub frames: u32,
    /// Frames in flight (1..=3, see [`check_depth`]).
    pub depth: usize,
    /// Frames at the end whose GPU timings are read.
    pub timed_frames: u32,
}

/// Renders `opts.frames` frames of `camera` with `opts.depth` frames in flight, then waits for
/// all. `progress` runs after each frame's submit. The renderer's context must allow
/// `2 × depth` GPU tasks in flight (`RendererOptions::frames_in_flight`).
pub fn run(
    renderer: &mut Renderer,
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    camera: &Camera,
    opts: LoopOptions,
    mut progress: impl FnMut(),
) -> AnyResult<LoopResult> {
    let LoopOptions {
        frames,
        depth,
        timed_frames,
    } = opts;
    let mut ring = InFlight::new(depth);
    let mut records: Vec<FrameRecord> = Vec::with_capacity(frames as usize);
    let mut timed = Vec::new();
    let mut starts = Vec::with_capacity(frames as usize);
    let mut memory = crate::app::memory::MemoryPeak::default();
    for f in 0..frames {
        let start = Instant::now();
        starts.push(start);
        let mut rec = FrameRecord {
            frame: f,
            ..Default::default()
        };
        while ring.must_retire() {
            let Some(p) = ring.pop_oldest() else { break };
            let r = retire(device, &renderer.sdk.ctx, p)?;
            rec.waited_for = Some(r.frame);
            rec.gpu_busy |= r.gpu_busy;
            rec.wait_ms += r.wait_ms;
        }
        let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("ksrt frame"),
        });
        let t = Instant::now();
        let tasks = renderer.record_frame(device, queue, &mut encoder, camera)?;
        rec.record_ms = t.elapsed().as_secs_f64() * 1e3;
        rec.sdk_build_ms = renderer.last_sdk_build_ms;
        let t = Instant::now();
        let index = queue.submit([encoder.finish()]);
        let done = Arc::new(AtomicBool::new(false));
        let flag = done.clone();
        queue.on_submitted_work_done(move || flag.store(true, Ordering::Release));
        rec.submit_ms = t.elapsed().as_secs_f64() * 1e3;
        memory.sample(
            device,
            &renderer.sdk.ctx,
            &renderer.sdk.denoising_contexts(),
        );
        if f + timed_frames >= frames {
            if let Some(&first) = tasks.first() {
                timed.push(first);
            }
        }
        ring.push(Pending {
            frame: f,
            index,
            done,
            tasks,
        });
        records.push(rec);
        progress();
    }
    while let Some(p) = ring.pop_oldest() {
        retire(device, &renderer.sdk.ctx, p)?;
    }
    let end = Instant::now();
    for (k, rec) in records.iter_mut().enumerate() {
        let next = starts.get(k + 1).copied().unwrap_or(end);
        rec.frame_ms = (next - starts[k]).as_secs_f64() * 1e3;
    }
    let mut timings = Vec::new();
    for task in timed {
        match renderer.sdk.ctx.wait_for_gpu_timings(task) {
            Ok(t) => timings.push(t),
            // No timestamps on this device, or timing off: the loop's CPU figures stand alone.
            Err(e) => log::debug!("no GPU timings: {e}"),
        }
    }
    Ok(LoopResult {
        records,
        timings,
        memory,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn depth_is_checked_and_named() {
        assert_eq!(check_depth(1), Ok(1));
        assert_eq!(check_depth(3), Ok(3));
        for bad in [0, 4] {
            let e = check_depth(bad).unwrap_err();
            assert!(
                e.contains("--frames-in-flight") && e.contains(&bad.to_string()),
                "{e}"
            );
        }
    }

    /// Drives the ring as the loop does and returns, per frame, the frame it retired first.
    fn schedule(depth: usize, frames: u32) -> Vec<Option<u32>> {
        let mut ring = InFlight::new(depth);
        let mut waited = Vec::new();
        for f in 0..frames {
            let mut w = None;
            while ring.must_retire() {
                w = ring.pop_oldest();
            }
            waited.push(w);
            ring.push(f);
            assert!(ring.len() <= depth);
        }
        waited
    }

    #[test]
    fn each_frame_waits_for_the_frame_n_back() {
        // One in flight: every frame waits for the previous one (ksrt render's old loop).
        assert_eq!(schedule(1, 4), vec![None, Some(0), Some(1), Some(2)]);
        assert_eq!(schedule(2, 5), vec![None, None, Some(0), Some(1), Some(2)]);
        assert_eq!(
            schedule(3, 6),
            vec![None, None, None, Some(0), Some(1), Some(2)]
        );
        let mut ring = InFlight::new(0);
        ring.push(7);
        assert!(ring.must_retire(), "depth 0 means 1");
        assert_eq!(ring.pop_oldest(), Some(7));
        assert!(ring.is_empty());
    }

    /// Six frames of the Cornell box, every effect, 32² pixels, with `frames_in_flight` frames
    /// in flight (lavapipe: tiny).
    fn cornell_frames(frames_in_flight: u32) -> crate::app::lit::LitResult {
        let (device, queue) = crate::app::testing::device();
        let scene = kickstart_rt_renderer::scene::builtin::cornell_box();
        crate::app::lit::render(
            device,
            queue,
            &scene,
            &scene.camera_or_default(None),
            &crate::app::lit::LitOptions {
                preset: kickstart_rt::Preset::Quality,
                size: (32, 32),
                frames: 6,
                effects: kickstart_rt_renderer::frame::Effects::default(),
                seed: 0,
                progress: false,
                gpu_timing: false,
                frames_in_flight,
                debug_views: Vec::new(),
                time: 0.0,
            },
        )
        .unwrap_or_else(|e| panic!("{frames_in_flight} in flight: {e}"))
    }

    /// GPU (lavapipe: tiny): `ksrt render`'s loop with three frames in flight records every
    /// frame, waits for nothing before the fourth, and then always for the frame three back; and
    /// it renders the same images as one frame in flight: every channel of the last frame
    /// (final image, direct light, each SDK channel raw and denoised) equal texel for texel, no
    /// tolerance (frames in flight change when the CPU waits, not what the GPU computes or in
    /// which order; lavapipe gives identical texels run after run).
    #[test]
    fn render_loop_keeps_three_frames_in_flight() {
        let three = cornell_frames(3);
        let waited: Vec<Option<u32>> = three.frames.iter().map(|r| r.waited_for).collect();
        assert_eq!(waited, vec![None, None, None, Some(0), Some(1), Some(2)]);
        for r in &three.frames {
            // The build is timed (the renderer's clock is wired) within the recording, and each
            // frame's interval was filled in; no bound on either.
            assert!(
                r.record_ms >= r.sdk_build_ms && r.sdk_build_ms > 0.0 && r.frame_ms > 0.0,
                "{r:?}"
            );
            // Wait time is only counted for a frame the GPU was still running, and a frame that
            // retired none (the first three) neither found one busy nor waited.
            assert!(r.gpu_busy || r.wait_ms == 0.0, "{r:?}");
            assert!(r.waited_for.is_some() || !r.gpu_busy, "{r:?}");
        }
        let one = cornell_frames(1);
        let waited: Vec<Option<u32>> = one.frames.iter().map(|r| r.waited_for).collect();
        assert_eq!(
            waited,
            vec![None, Some(0), Some(1), Some(2), Some(3), Some(4)]
        );
        let names = |r: &crate::app::lit::LitResult| -> Vec<&str> {
            r.channels.iter().map(|c| c.name).collect()
        };
        assert_eq!(names(&three), names(&one));
        assert!(
            names(&one).contains(&"diffuse-denoised"),
            "{:?}",
            names(&one)
        );
        for (a, b) in three.channels.iter().zip(&one.channels) {
            let differ = a
                .texels
                .data
                .iter()
                .zip(&b.texels.data)
                .filter(|(x, y)| x != y)
                .count();
            let first = a
                .texels
                .data
                .iter()
                .zip(&b.texels.data)
                .position(|(x, y)| x != y);
            assert_eq!(
                differ,
                0,
                "channel {}: {differ} texels differ between 3 and 1 in flight (first: {:?})",
                a.name,
                first.map(|k| (k, a.texels.data[k], b.texels.data[k]))
            );
        }
    }

    /// A render asking for four frames in flight is refused with an error naming the option and
    /// the value, before it renders anything.
    #[test]
    fn more_than_three_frames_in_flight_are_refused_by_name() {
        let (device, queue) = crate::app::testing::device();
        let scene = kickstart_rt_renderer::scene::builtin::cornell_box();
        let bad = crate::app::lit::render(
            device,
            queue,
            &scene,
            &scene.camera_or_default(None),
            &crate::app::lit::LitOptions {
                preset: kickstart_rt::Preset::Quality,
                size: (8, 8),
                frames: 1,
                effects: Default::default(),
                seed: 0,
                progress: false,
                gpu_timing: false,
                frames_in_flight: 4,
                debug_views: Vec::new(),
                time: 0.0,
            },
        );
        assert!(bad
            .err()
            .is_some_and(|e| e.to_string().contains("--frames-in-flight 4")));
    }

    #[test]
    fn summary_drops_warmup_and_counts_waits() {
        let rec = |f: u32, build: f64, busy: bool, wait: f64, frame: f64| FrameRecord {
            frame: f,
            sdk_build_ms: build,
            record_ms: build * 2.0,
            submit_ms: 0.1,
            waited_for: f.checked_sub(1),
            gpu_busy: busy,
            wait_ms: wait,
            frame_ms: frame,
        };
        let records = vec![
            rec(0, 100.0, true, 50.0, 200.0),
            rec(1, 1.0, true, 3.0, 10.0),
            rec(2, 2.0, false, 0.0, 10.0),
            rec(3, 3.0, true, 1.0, 20.0),
        ];
        let s = summarise(2, &records, 1);
        assert_eq!(s.frames_in_flight, 2);
        assert_eq!(s.frames, 3);
        assert_eq!(s.sdk_build_ms, 2.0);
        assert_eq!(s.record_ms, 4.0);
        assert_eq!(s.frames_waited, 2);
        assert!((s.mean_wait_ms - 4.0 / 3.0).abs() < 1e-12);
        assert_eq!(s.frame_ms, 10.0);
        assert!((s.fps - 75.0).abs() < 1e-9);
        // More warm-up than frames: an empty summary, not a panic.
        assert_eq!(summarise(1, &records, 10).frames, 0);
        assert!(table(&[s]).contains("2/3"));
    }
}
