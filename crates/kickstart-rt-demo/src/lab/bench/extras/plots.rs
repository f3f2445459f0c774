//! `ksrt bench --plots DIR`: PNG charts of the optional passes' results (plotters, bitmap
//! backend). Text is drawn with DejaVu Sans, committed beside the crate
//! (`assets/fonts/`, Bitstream Vera licence) and compiled in, so charts draw the same on a
//! machine without any system font. Log axes plot log10 of the values on a linear axis and
//! label the ticks with the values (1k, 10M, …).

use std::path::{Path, PathBuf};

use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint};
use plotters::prelude::*;

use super::ExtrasReport;
use kickstart_rt_renderer::error::AnyResult;

/// Chart size, pixels.
pub const CHART_SIZE: (u32, u32) = (960, 600);

/// DejaVu Sans (see `assets/fonts/DejaVuSans-LICENSE.txt`).
static FONT: &[u8] = include_bytes!("../../../../assets/fonts/DejaVuSans.ttf");

/// Registers the font under plotters' default family once per process.
fn register_font() -> AnyResult<()> {
    static DONE: std::sync::OnceLock<Result<(), String>> = std::sync::OnceLock::new();
    DONE.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, FONT)
            .map_err(|_| "the committed DejaVu Sans font does not parse".to_string())
    })
    .clone()
    .map_err(Into::into)
}

/// Series colours, distinct on white.
const COLOURS: [RGBColor; 6] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
];

/// One line of a chart.
#[derive(Debug, Clone)]
pub struct Series {
    /// Legend text.
    pub name: String,
    /// (x, y) points, drawn in x order.
    pub points: Vec<(f64, f64)>,
}

/// A chart to draw.
#[derive(Debug, Clone)]
pub struct Chart {
    /// File stem.
    pub file: &'static str,
    /// Title.
    pub title: String,
    /// X axis label.
    pub x_label: String,
    /// Y axis label.
    pub y_label: String,
    /// Logarithmic x.
    pub log_x: bool,
    /// Logarithmic y.
    pub log_y: bool,
    /// The lines.
    pub series: Vec<Series>,
}

/// `x` with a k/M/G suffix and at most three significant digits (tick labels).
pub fn human(x: f64) -> String {
    let (v, suffix) = match x.abs() {
        a if a >= 1e9 => (x / 1e9, "G"),
        a if a >= 1e6 => (x / 1e6, "M"),
        a if a >= 1e3 => (x / 1e3, "k"),
        _ => (x, ""),
    };
    let digits = match v.abs() {
        a if a >= 100.0 || a == 0.0 => 0,
        a if a >= 10.0 => 1,
        a if a >= 1.0 => 2,
        a => (2.0 - a.log10().floor()).clamp(2.0, 9.0) as usize,
    };
    let mut s = format!("{v:.digits$}");
    if s.contains('.') {
        s = s.trim_end_matches('0').trim_end_matches('.').to_string();
    }
    s + suffix
}

/// The value plotted for `v` on an axis (log10 on a log axis); `None` when it cannot be shown.
fn axis_value(v: f64, log: bool) -> Option<f64> {
    match log {
        true if v > 0.0 && v.is_finite() => Some(v.log10()),
        false if v.is_finite() => Some(v),
        _ => None,
    }
}

/// A padded range over `values` (a unit one around a single value).
fn range(values: impl Iterator<Item = f64>, log: bool, from_zero: bool) -> (f64, f64) {
    let (mut lo, mut hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    if from_zero && !log {
        lo = lo.min(0.0);
    }
    let pad = if hi > lo {
        (hi - lo) * 0.08
    } else if log {
        0.5
    } else {
        lo.abs().max(1.0) * 0.1
    };
    if !(from_zero && !log && lo == 0.0) {
        lo -= pad;
    }
    hi += pad;
    (lo, hi)
}

/// A linear f64 axis with given ticks (plotters' `WithKeyPoints` over f64 has no label
/// formatter, so `configure_mesh` refuses it; this one formats through our formatter).
struct Axis {
    lo: f64,
    hi: f64,
    /// Labelled ticks.
    bold: Vec<f64>,
    /// Minor grid lines.
    light: Vec<f64>,
}

impl Ranged for Axis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let t = (value - self.lo) / (self.hi - self.lo);
        limit.0 + (f64::from(limit.1 - limit.0) * t).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.light.clone()
        } else {
            self.bold.clone()
        }
    }

    fn range(&self) -> std::ops::Range<f64> {
        self.lo..self.hi
    }
}

/// Plotters' own tick positions over `lo..hi` (linear).
fn linear_ticks(lo: f64, hi: f64) -> Vec<f64> {
    plotters::coord::types::RangedCoordf64::from(lo..hi).key_points(10usize)
}

/// Positions (log10 of values) in `lo..hi` of the values m × 10^k for the mantissas `m`.
fn decade_ticks(lo: f64, hi: f64, mantissas: &[f64]) -> Vec<f64> {
    let mut out = Vec::new();
    for k in (lo.floor() as i32 - 1)..=(hi.ceil() as i32) {
        for m in mantissas {
            let v = f64::from(k) + m.log10();
            if (lo..=hi).contains(&v) {
                out.push(v);
            }
        }
    }
    out
}

/// Labelled ticks and minor grid lines of an axis over `lo..hi` (log10 values on a log axis):
/// on a log axis the powers of ten, or 1-2-5 steps, or every digit, whichever gives a handful;
/// on a span too short for those, linear steps of the values.
fn ticks(lo: f64, hi: f64, log: bool) -> (Vec<f64>, Vec<f64>) {
    if !log {
        return (linear_ticks(lo, hi), Vec::new());
    }
    let digits: Vec<f64> = (1..10).map(f64::from).collect();
    let minor = decade_ticks(lo, hi, &digits);
    for set in [&[1.0][..], &[1.0, 2.0, 5.0], &digits] {
        let t = decade_ticks(lo, hi, set);
        if t.len() >= 3 && t.len() <= 12 {
            return (t, minor);
        }
    }
    let t: Vec<f64> = linear_ticks(10f64.powf(lo), 10f64.powf(hi))
        .into_iter()
        .filter(|v| *v > 0.0)
        .map(f64::log10)
        .collect();
    (t, Vec::new())
}

/// Draws `chart` into `dir/<file>.png`; `None` when it has no point to show.
pub fn draw(chart: &Chart, dir: &Path) -> AnyResult<Option<PathBuf>> {
    register_font()?;
    let series: Vec<(String, Vec<(f64, f64)>)> = chart
        .series
        .iter()
        .map(|s| {
            let mut pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .filter_map(|&(x, y)| {
                    Some((axis_value(x, chart.log_x)?, axis_value(y, chart.log_y)?))
                })
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            (s.name.clone(), pts)
        })
        .filter(|(_, p)| !p.is_empty())
        .collect();
    if series.is_empty() {
        return Ok(None);
    }
    let all = || series.iter().flat_map(|(_, p)| p.iter().copied());
    let (x0, x1) = range(all().map(|p| p.0), chart.log_x, false);
    let (y0, y1) = range(all().map(|p| p.1), chart.log_y, true);
    let (xt, yt) = (ticks(x0, x1, chart.log_x), ticks(y0, y1, chart.log_y));
    let (w, h) = CHART_SIZE;
    let mut pixels = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let mut c = ChartBuilder::on(&root)
            .caption(&chart.title, ("sans-serif", 24))
            .margin(16)
            .x_label_area_size(52)
            .y_label_area_size(72)
            .build_cartesian_2d(
                Axis {
                    lo: x0,
                    hi: x1,
                    bold: xt.0,
                    light: xt.1,
                },
                Axis {
                    lo: y0,
                    hi: y1,
                    bold: yt.0,
                    light: yt.1,
                },
            )
            .map_err(|e| e.to_string())?;
        let (log_x, log_y) = (chart.log_x, chart.log_y);
        let fx = move |v: &f64| human(if log_x { 10f64.powf(*v) } else { *v });
        let fy = move |v: &f64| human(if log_y { 10f64.powf(*v) } else { *v });
        c.configure_mesh()
            .x_desc(chart.x_label.as_str())
            .y_desc(chart.y_label.as_str())
            .x_label_formatter(&fx)
            .y_label_formatter(&fy)
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 17))
            .draw()
            .map_err(|e| e.to_string())?;
        for (i, (name, pts)) in series.iter().enumerate() {
            let colour = COLOURS[i % COLOURS.len()];
            c.draw_series(LineSeries::new(pts.iter().copied(), colour.stroke_width(2)))
                .map_err(|e| e.to_string())?
                .label(name.as_str())
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 24, y)], colour.stroke_width(3))
                });
            c.draw_series(pts.iter().map(|&p| Circle::new(p, 4, colour.filled())))
                .map_err(|e| e.to_string())?;
        }
        c.configure_series_labels()
            .position(SeriesLabelPosition::UpperLeft)
            .label_font(("sans-serif", 15))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(|e| e.to_string())?;
        root.present().map_err(|e| e.to_string())?;
    }
    std::fs::create_dir_all(dir)
        .map_err(|e| format!("--plots {}: cannot create: {e}", dir.display()))?;
    let path = dir.join(format!("{}.png", chart.file));
    let image = image::RgbImage::from_raw(w, h, pixels).ok_or("chart buffer size mismatch")?;
    image
        .save(&path)
        .map_err(|e| format!("--plots {}: {e}", path.display()))?;
    Ok(Some(path))
}

/// A chart of `series`.
fn chart(
    file: &'static str,
    title: &str,
    (x, y): (&str, &str),
    log_x: bool,
    log_y: bool,
    series: Vec<Series>,
) -> Chart {
    Chart {
        file,
        title: title.to_string(),
        x_label: x.to_string(),
        y_label: y.to_string(),
        log_x,
        log_y,
        series,
    }
}

/// The charts of `report`'s passes (only those with data).
pub fn charts(report: &ExtrasReport) -> Vec<Chart> {
    let mut out = Vec::new();
    if let Some(s) = &report.scaling {
        scaling_size_charts(s, &mut out);
        scaling_frame_charts(s, &mut out);
    }
    if let Some(c) = &report.cpu_peers {
        cpu_peer_charts(c, &mut out);
    }
    if let Some(f) = &report.frames_in_flight {
        frames_in_flight_chart(f, &mut out);
    }
    out
}

/// `--scaling`: ray throughput and build times against the scene's size.
fn scaling_size_charts(s: &super::scaling::ScalingReport, out: &mut Vec<Chart>) {
    let rays = ["primary", "ao", "diffuse"]
        .iter()
        .map(|kind| Series {
            name: format!("{kind} rays"),
            points: s
                .triangles
                .iter()
                .filter_map(|p| {
                    let r = p.rays.iter().find(|r| r.kind == *kind)?;
                    Some((p.world_triangles as f64, r.mrays_per_s))
                })
                .collect(),
        })
        .collect();
    out.push(chart(
        "scaling-rays",
        &format!(
            "Ray throughput against scene size ({}x{} batches)",
            s.ray_size.0, s.ray_size.1
        ),
        (
            "triangles in the world (dragon copies counted each)",
            "Mrays/s",
        ),
        true,
        true,
        rays,
    ));
    let blas = Series {
        name: "BLAS build, all geometries".into(),
        points: s
            .triangles
            .iter()
            .filter_map(|p| {
                Some((
                    p.geometry_triangles as f64,
                    p.blas_build.as_ref()?.median_ms,
                ))
            })
            .collect(),
    };
    let tlas = Series {
        name: "TLAS build over dragon copies (x = copies)".into(),
        points: s
            .triangles
            .iter()
            .filter_map(|p| Some((p.copies as f64, p.tlas_build.as_ref()?.median_ms)))
            .collect(),
    };
    out.push(chart(
        "scaling-build",
        "GPU build time against size",
        ("BLAS: triangles; TLAS: instances", "ms (GPU)"),
        true,
        true,
        vec![blas, tlas],
    ));
}

/// `--scaling`: the SDK's frame time against resolution and lights, and the TLAS against
/// instances.
fn scaling_frame_charts(s: &super::scaling::ScalingReport, out: &mut Vec<Chart>) {
    let frame = |pts: &Vec<super::scaling::FramePoint>,
                 x: fn(&super::scaling::FramePoint) -> f64| {
        pts.iter().map(|p| (x(p), p.sdk_ms)).collect::<Vec<_>>()
    };
    out.push(chart(
        "scaling-resolution",
        &format!("SDK frame time against resolution ({})", s.frame_scene),
        ("megapixels", "ms (GPU, SDK passes)"),
        true,
        true,
        vec![Series {
            name: "SDK frame (inject, traces, denoisers)".into(),
            points: frame(&s.resolution, |p| f64::from(p.width * p.height) / 1e6),
        }],
    ));
    out.push(chart(
        "scaling-lights",
        &format!(
            "SDK frame time against lights ({}, {})",
            s.frame_scene,
            s.lights
                .first()
                .map_or("—".to_string(), |p| format!("{}x{}", p.width, p.height))
        ),
        ("lights in the multi-light shadow", "ms (GPU, SDK passes)"),
        true,
        false,
        vec![Series {
            name: "SDK frame".into(),
            points: frame(&s.lights, |p| f64::from(p.lights)),
        }],
    ));
    let tlas_series = |name: &str, f: fn(&super::scaling::TlasPoint) -> Option<f64>| Series {
        name: name.into(),
        points: s
            .tlas
            .iter()
            .filter_map(|p| Some((f64::from(p.instances), f(p)?)))
            .collect(),
    };
    out.push(chart(
        "scaling-tlas",
        "TLAS cost against instances",
        ("instances", "ms (GPU)"),
        true,
        true,
        vec![
            tlas_series("build", |p| p.build.as_ref().map(|s| s.median_ms)),
            tlas_series("refit", |p| p.refit.as_ref().map(|s| s.median_ms)),
        ],
    ));
}

/// `--cpu-peers`: build time and SAH cost of each builder against triangles.
fn cpu_peer_charts(c: &super::cpu_peers::CpuPeersReport, out: &mut Vec<Chart>) {
    let mut builders: Vec<String> = Vec::new();
    for b in c.meshes.iter().flat_map(|m| &m.builds) {
        if !builders.contains(&b.builder) {
            builders.push(b.builder.clone());
        }
    }
    let per_builder = |f: fn(&super::cpu_peers::PeerBuild) -> Option<f64>| {
        builders
            .iter()
            .map(|name| Series {
                name: name.clone(),
                points: c
                    .meshes
                    .iter()
                    .filter_map(|m| {
                        let b = m.builds.iter().find(|b| &b.builder == name)?;
                        Some((m.triangles as f64, f(b)?))
                    })
                    .collect(),
            })
            .collect::<Vec<_>>()
    };
    out.push(chart(
        "cpu-peers-build",
        &format!(
            "BVH build time: GPU against CPU builders ({} CPU threads)",
            c.cpu_threads
        ),
        ("triangles", "ms"),
        true,
        true,
        per_builder(|b| Some(b.time.median_ms)),
    ));
    out.push(chart(
        "cpu-peers-sah",
        "BVH quality: SAH cost / our CPU binned SAH's (lower is better)",
        ("triangles", "SAH ratio"),
        true,
        false,
        per_builder(|b| b.sah_vs_cpu_binned),
    ));
}

/// `--frames-in-flight`: the CPU's costs per frame against frames in flight.
fn frames_in_flight_chart(f: &super::fif::FifReport, out: &mut Vec<Chart>) {
    let col = |name: &str, g: fn(&crate::app::frames_in_flight::FifSummary) -> f64| Series {
        name: name.into(),
        points: f
            .summaries
            .iter()
            .map(|s| (f64::from(s.frames_in_flight), g(s)))
            .collect(),
    };
    out.push(chart(
        "frames-in-flight",
        &format!(
            "CPU per frame against frames in flight ({} {}x{})",
            f.scene, f.width, f.height
        ),
        ("frames in flight", "ms (CPU)"),
        false,
        false,
        vec![
            col("build_gpu_task", |s| s.sdk_build_ms),
            col("record frame", |s| s.record_ms),
            col("mean wait for GPU", |s| s.mean_wait_ms),
            col("frame interval", |s| s.frame_ms),
        ],
    ));
}

/// Draws every chart of `report` into `dir` and lists them.
pub fn draw_all(report: &ExtrasReport, dir: &Path) -> AnyResult<Vec<PathBuf>> {
    let mut written = Vec::new();
    for c in charts(report) {
        if let Some(p) = draw(&c, dir)? {
            println!("wrote {}", p.display());
            written.push(p);
        }
    }
    if written.is_empty() {
        println!(
            "--plots {}: nothing to draw (no --scaling, --cpu-peers or --frames-in-flight results)",
            dir.display()
        );
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::super::{cpu_peers, scaling};
    use super::*;
    use crate::lab::bench::Stats;

    #[test]
    fn human_labels() {
        assert_eq!(human(0.0), "0");
        assert_eq!(human(1.0), "1");
        assert_eq!(human(2.5), "2.5");
        assert_eq!(human(1000.0), "1k");
        assert_eq!(human(31_622.8), "31.6k");
        assert_eq!(human(871_414.0), "871k");
        assert_eq!(human(1e6), "1M");
        assert_eq!(human(2.26e9), "2.26G");
        assert_eq!(human(0.0123), "0.0123");
    }

    #[test]
    fn log_ticks_are_round_values() {
        let vals =
            |t: Vec<f64>| -> Vec<String> { t.iter().map(|v| human(10f64.powf(*v))).collect() };
        // Six decades: the powers of ten.
        assert_eq!(
            vals(ticks(0.0, 6.0, true).0),
            ["1", "10", "100", "1k", "10k", "100k", "1M"]
        );
        // One decade: 1-2-5.
        assert_eq!(vals(ticks(0.9, 2.1, true).0), ["10", "20", "50", "100"]);
        // Half a decade: every digit.
        assert_eq!(
            vals(ticks(1.2, 1.8, true).0),
            ["20", "30", "40", "50", "60"]
        );
        // A sliver: linear steps, still inside the range.
        let t = ticks(1.2, 1.21, true).0;
        assert!(!t.is_empty() && t.iter().all(|v| (1.2..=1.21).contains(v)));
        assert!(!ticks(0.0, 5.0, false).0.is_empty());
    }

    #[test]
    fn ranges_pad_and_log_axes_drop_non_positive_values() {
        assert_eq!(axis_value(100.0, true), Some(2.0));
        assert_eq!(axis_value(0.0, true), None);
        assert_eq!(axis_value(f64::NAN, false), None);
        let (lo, hi) = range([2.0, 2.0].into_iter(), true, false);
        assert!(lo < 2.0 && hi > 2.0);
        let (lo, hi) = range([1.0, 3.0].into_iter(), false, true);
        assert_eq!(lo, 0.0);
        assert!(hi > 3.0);
        assert_eq!(range(std::iter::empty(), false, false), (0.0, 1.0));
    }

    fn stats(ms: f64) -> Stats {
        Stats::new(vec![ms])
    }

    /// A small made-up report with every pass.
    fn report() -> ExtrasReport {
        let tri = |label: &str, n: usize, copies: u32, mrays: f64| scaling::TrianglePoint {
            label: label.into(),
            copies,
            geometry_triangles: n,
            world_triangles: n * copies.max(1) as usize,
            blas_build: (copies == 0).then(|| stats(n as f64 * 1e-6)),
            tlas_build: (copies > 0).then(|| stats(0.01 * f64::from(copies))),
            rays: ["primary", "ao", "diffuse"]
                .iter()
                .map(|k| scaling::RayPoint {
                    kind: k.to_string(),
                    rays: 1000,
                    misses: 10,
                    time: stats(1.0),
                    mrays_per_s: mrays,
                })
                .collect(),
        };
        let frame = |w: u32, h: u32, lights: u32, ms: f64| scaling::FramePoint {
            width: w,
            height: h,
            lights,
            sdk_ms: ms,
            tasks: vec![("trace".into(), ms / 2.0)],
            frames: 8,
        };
        let build = |name: &str, ms: f64, ratio: f64| cpu_peers::PeerBuild {
            builder: name.into(),
            device: "cpu".into(),
            threads: 2,
            time: stats(ms),
            mtri_per_s: 1.0,
            sah_cost: 50.0 * ratio,
            sah_vs_cpu_binned: Some(ratio),
        };
        ExtrasReport {
            scaling: Some(scaling::ScalingReport {
                quick: true,
                ray_size: (64, 36),
                triangles: vec![
                    tri("cornell", 36, 0, 900.0),
                    tri("dragon", 871_414, 0, 2000.0),
                    tri("dragon x10", 871_414, 10, 1500.0),
                ],
                frame_scene: "apartment".into(),
                resolution: vec![frame(1280, 720, 1, 2.0), frame(3840, 2160, 1, 12.0)],
                lights: vec![frame(1920, 1080, 1, 4.0), frame(1920, 1080, 16, 6.0)],
                tlas: vec![scaling::TlasPoint {
                    instances: 1000,
                    build: Some(stats(0.1)),
                    refit: None,
                    errors: vec!["refit: made up".into()],
                }],
                errors: vec![],
            }),
            cpu_peers: Some(cpu_peers::CpuPeersReport {
                cpu_threads: 2,
                cpu_model: "test".into(),
                meshes: vec![cpu_peers::PeerMesh {
                    scene: "bunny".into(),
                    mesh: "whole scene".into(),
                    triangles: 3674,
                    builds: vec![build("ours", 1.0, 1.0), build("obvhs", 2.0, 0.9)],
                }],
                errors: vec![],
            }),
            frames_in_flight: None,
        }
    }

    #[test]
    fn charts_are_drawn_as_readable_pngs() {
        let dir = crate::app::testing::temp_dir("plots");
        let written = draw_all(&report(), &dir).expect("draw");
        // Rays, build, resolution, lights, TLAS, CPU build, CPU SAH (no frames-in-flight).
        assert_eq!(written.len(), 7, "{written:?}");
        for path in &written {
            assert!(path.exists());
            let img = image::open(path)
                .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
                .to_rgb8();
            assert_eq!(img.dimensions(), CHART_SIZE, "{}", path.display());
            let first = *img.get_pixel(0, 0);
            assert!(
                img.pixels().any(|p| *p != first),
                "{} is one colour",
                path.display()
            );
            // Some series colour made it onto the chart (not only black text on white).
            assert!(
                img.pixels()
                    .any(|p| COLOURS.iter().any(|c| p.0 == [c.0, c.1, c.2])),
                "{} shows no series",
                path.display()
            );
        }
        // A report from JSON draws the same (what `--plots-from` reads).
        let json = serde_json::to_string(&report()).unwrap();
        let back: ExtrasReport = serde_json::from_str(&json).unwrap();
        assert_eq!(charts(&back).len(), charts(&report()).len());
    }

    #[test]
    fn a_chart_without_points_is_skipped() {
        let c = Chart {
            file: "empty",
            title: "t".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            log_x: true,
            log_y: true,
            series: vec![Series {
                name: "s".into(),
                points: vec![(0.0, 1.0), (-1.0, 2.0)],
            }],
        };
        let dir = crate::app::testing::temp_dir("plots-empty");
        assert!(draw(&c, &dir).unwrap().is_none());
        assert!(!dir.join("empty.png").exists());
    }
}
