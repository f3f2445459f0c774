//! The optional passes of `ksrt bench` (apart from the driver peer): CPU BVH peers
//! (`--cpu-peers`), scaling (`--scaling`), frames in flight (`--frames-in-flight`), and the PNG
//! charts of their results (`--plots DIR`, also from an earlier run's JSON with
//! `--plots-from`). Each pass is off unless asked for; `--skip-scenes` leaves out the default
//! per-scene measurements and TLAS table so that a pass can run alone.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::harness::Bench;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::scene::Scene;

pub mod cpu_peers;
pub mod fif;
pub mod plots;
pub mod scaling;

pub use super::options::{RayOrder, Section};

/// The command-line options of the optional passes (flattened into `ksrt bench`).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ExtraArgs {
    /// Also compare BVH build time and SAH cost with CPU builders (obvhs, and our CPU
    /// binned-SAH builder) on bunny, Cornell box, apartment and dragon.
    #[arg(long)]
    pub cpu_peers: bool,
    /// Also measure scaling: rays/s and BLAS build time against triangles (with the dragon
    /// instanced 1–1000×), SDK frame time against resolution and light count, TLAS cost against
    /// instances (1k–1M). About a minute on an H100.
    #[arg(long)]
    pub scaling: bool,
    /// Also run `ksrt render`'s frame loop with 1, 2 and 3 frames in flight and print the CPU
    /// time of `build_gpu_task` and the waits for the GPU.
    #[arg(long)]
    pub frames_in_flight: bool,
    /// Frames of each frames-in-flight run (the first quarter is left out as warm-up).
    #[arg(long, default_value_t = 120)]
    pub fif_frames: u32,
    /// Tiny series on the small scenes for the passes above (a smoke test on software Vulkan;
    /// not the figures).
    #[arg(long)]
    pub quick: bool,
    /// Also trace each one-instance scene's sampled rays (on the CPU, as the GPU traverses)
    /// through trees of our CPU binned-SAH builder and obvhs's PLOC presets laid out as our
    /// BVH2: the traversal work a better builder would save. Seconds of CPU per scene.
    #[arg(long)]
    pub tree_work: bool,
    /// Bake every scene into one mesh in world space under one instance before measuring (as a
    /// renderer with a single BVH over its whole scene would trace it). The one mesh has one
    /// colour and is opaque: materials, textures and cutouts are dropped.
    #[arg(long)]
    pub flatten: bool,
    /// Trace every mesh opaque: cutout (`MASK`) materials lose their alpha test, so that a
    /// scene's figures with and without it come from one binary and one call (the alpha
    /// test's cost is their ratio).
    #[arg(long)]
    pub opaque: bool,
    /// Order of the primary rays in the ray batches (the secondary rays follow their primary
    /// hits): `rows`, row by row over the image; `tiles`, 8×8-pixel tiles row by row, pixels row
    /// by row inside a tile (the order a screen-space dispatch of 8×8 workgroups issues them, as
    /// the SDK's trace tasks and the software peer do). The batch shader takes 64
    /// consecutive rays a workgroup either way.
    #[arg(long, value_enum, default_value_t = RayOrder::Rows)]
    pub ray_order: RayOrder,
    /// Before each timed task, keep the GPU busy for about this many milliseconds (a spin
    /// kernel submitted just before it, not timed), as a frame's other work would: short tasks
    /// (refits, TLAS builds, the `--denoisers` tasks) then run at the clocks of a busy GPU, not
    /// the lower ones it drops to while the CPU prepares the next repetition. 0 (default): no
    /// such work, as every earlier figure was measured.
    #[arg(long, default_value_t = 0.0)]
    pub busy_gpu_ms: f64,
    /// Leave out the default per-scene measurements and the TLAS table (run only the passes
    /// asked for).
    #[arg(long)]
    pub skip_scenes: bool,
    /// The default measurements to run (comma-separated; all when not given): `builds` (BLAS
    /// build, fast-build, refit, SAH), `rays` (the ray batches and the peer workload), `cache`
    /// (lighting cache), `tasks` (the SDK's trace tasks), `tlas` (the TLAS table). A shorter
    /// run for experiments on one part.
    #[arg(long, value_enum, value_delimiter = ',')]
    pub sections: Vec<Section>,
    /// Draw the results of the passes run as PNG charts into this folder.
    #[arg(long)]
    pub plots: Option<PathBuf>,
    /// With --plots: draw from this earlier `ksrt bench --json` file instead of measuring
    /// (no GPU needed).
    #[arg(long, requires = "plots")]
    pub plots_from: Option<PathBuf>,
}

impl ExtraArgs {
    /// Checks the values (before any GPU work).
    pub fn check(&self) -> AnyResult<()> {
        if !(0.0..=1000.0).contains(&self.busy_gpu_ms) {
            return Err(format!(
                "--busy-gpu-ms {}: from 0 to 1000 milliseconds",
                self.busy_gpu_ms
            )
            .into());
        }
        if self.frames_in_flight && self.fif_frames < 8 {
            return Err(format!(
                "--fif-frames {}: at least 8 frames (a quarter are warm-up)",
                self.fif_frames
            )
            .into());
        }
        Ok(())
    }
}

/// What the optional passes measured (flattened into the bench's JSON report; a pass not run
/// leaves its key out).
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct ExtrasReport {
    /// `--cpu-peers`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cpu_peers: Option<cpu_peers::CpuPeersReport>,
    /// `--scaling`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scaling: Option<scaling::ScalingReport>,
    /// `--frames-in-flight`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frames_in_flight: Option<fif::FifReport>,
}

impl ExtrasReport {
    /// Measurements that failed in the passes.
    pub fn failures(&self) -> usize {
        self.cpu_peers.as_ref().map_or(0, |r| r.errors.len())
            + self.scaling.as_ref().map_or(0, |r| r.errors.len())
            + self.frames_in_flight.as_ref().map_or(0, |r| r.errors.len())
    }
}

/// Loads a scene by name, saying how long it took (the big ones take seconds).
fn load(name: &str, scenes_dir: &Path) -> AnyResult<Scene> {
    let start = std::time::Instant::now();
    let s = crate::app::scenes::load(name, scenes_dir)?;
    println!(
        "  loaded {name} ({} triangles) in {:.2} s",
        s.triangle_count(),
        start.elapsed().as_secs_f64()
    );
    Ok(s)
}

/// Runs the passes `args` asks for into `report`, then draws the charts.
pub(super) fn run(
    bench: &Bench,
    scenes_dir: &Path,
    size: (u32, u32),
    args: &ExtraArgs,
    report: &mut ExtrasReport,
) -> AnyResult<()> {
    if args.cpu_peers {
        println!("\nCPU peers: BVH build time and SAH cost, same meshes");
        let start = std::time::Instant::now();
        let scenes: &[&str] = if args.quick {
            &cpu_peers::QUICK_SCENES
        } else {
            &cpu_peers::CPU_PEER_SCENES
        };
        report.cpu_peers = Some(cpu_peers::run(bench, scenes_dir, scenes));
        println!("CPU peers done in {:.1} s", start.elapsed().as_secs_f64());
    }
    if args.scaling {
        println!("\nScaling");
        let start = std::time::Instant::now();
        let plan = if args.quick {
            scaling::Plan::quick()
        } else {
            scaling::Plan::full()
        };
        report.scaling = Some(scaling::run(bench, scenes_dir, size, &plan, args.quick));
        println!("scaling done in {:.1} s", start.elapsed().as_secs_f64());
    }
    if args.frames_in_flight {
        println!("\nFrames in flight");
        let scene = if args.quick {
            "cornell-obj"
        } else {
            fif::FIF_SCENE
        };
        report.frames_in_flight = Some(fif::run(bench, scenes_dir, size, args.fif_frames, scene));
    }
    if let Some(dir) = &args.plots {
        plots::draw_all(report, dir)?;
    }
    Ok(())
}

/// `ksrt bench --plots DIR --plots-from FILE`: the charts of an earlier run's JSON.
pub fn plots_from_json(json: &Path, dir: &Path) -> AnyResult<()> {
    let text = std::fs::read_to_string(json)
        .map_err(|e| format!("--plots-from {}: cannot read: {e}", json.display()))?;
    let report: ExtrasReport = serde_json::from_str(&text).map_err(|e| {
        format!(
            "--plots-from {}: not a ksrt bench report: {e}",
            json.display()
        )
    })?;
    if report.cpu_peers.is_none() && report.scaling.is_none() && report.frames_in_flight.is_none() {
        return Err(format!(
            "--plots-from {}: holds no --cpu-peers, --scaling or --frames-in-flight results",
            json.display()
        )
        .into());
    }
    plots::draw_all(&report, dir)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_ray_orders_cover_each_pixel_once_and_tiles_are_8_by_8() {
        for size in [(20, 11), (16, 8), (1, 1), (9, 17)] {
            let mut rows = RayOrder::Rows.pixels(size);
            let tiles = RayOrder::Tiles.pixels(size);
            assert_eq!(rows.len(), (size.0 * size.1) as usize, "{size:?}");
            assert_eq!(rows[1.min(rows.len() - 1)], (1.min(size.0 - 1), 0));
            let mut sorted = tiles.clone();
            sorted.sort_by_key(|&(x, y)| (y, x));
            rows.sort_by_key(|&(x, y)| (y, x));
            assert_eq!(sorted, rows, "{size:?}: every pixel once");
        }
        // 20 × 11: the first tile's 64 pixels, then the second tile (x 8..16) from its top row.
        let t = RayOrder::Tiles.pixels((20, 11));
        assert_eq!(&t[..3], &[(0, 0), (1, 0), (2, 0)]);
        assert_eq!(t[8], (0, 1));
        assert_eq!(t[63], (7, 7));
        assert_eq!(t[64], (8, 0));
        // The third tile of the first row is 4 pixels wide (x 16..20), 8 high.
        assert_eq!(t[128..132], [(16, 0), (17, 0), (18, 0), (19, 0)]);
        assert_eq!(t[132], (16, 1));
        // The second row of tiles is 3 high (y 8..11) and starts after 3 tiles (64 + 64 + 32).
        assert_eq!(t[160], (0, 8));
    }

    #[test]
    fn too_few_frames_in_flight_frames_are_refused_by_name() {
        let args = ExtraArgs {
            frames_in_flight: true,
            fif_frames: 7,
            ..Default::default()
        };
        let err = args.check().expect_err("7 frames refused").to_string();
        assert!(err.contains("--fif-frames 7"), "{err}");
        // The count only matters when the pass runs.
        let off = ExtraArgs {
            fif_frames: 0,
            ..Default::default()
        };
        assert!(off.check().is_ok());
    }

    #[test]
    fn plots_from_refuses_a_missing_file_another_json_and_a_report_without_extras() {
        let dir = crate::app::testing::temp_dir("plots-from-bad-input");
        let missing = dir.join("missing.json");
        let err = plots_from_json(&missing, &dir)
            .expect_err("missing")
            .to_string();
        assert!(
            err.contains("--plots-from") && err.contains("cannot read"),
            "{err}"
        );
        let other = dir.join("other.json");
        std::fs::write(&other, "[1, 2, 3]").expect("write");
        let err = plots_from_json(&other, &dir)
            .expect_err("not a report")
            .to_string();
        assert!(err.contains("not a ksrt bench report"), "{err}");
        let empty = dir.join("empty.json");
        std::fs::write(&empty, "{}").expect("write");
        let err = plots_from_json(&empty, &dir)
            .expect_err("no extras")
            .to_string();
        assert!(err.contains("holds no --cpu-peers"), "{err}");
        assert!(
            std::fs::read_dir(&dir)
                .expect("dir")
                .filter_map(Result::ok)
                .all(|e| e.path().extension().is_none_or(|x| x != "png")),
            "no chart is drawn from bad input"
        );
    }
}
