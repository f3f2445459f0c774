//! The SDK's GPU pass timings of `ksrt render` summarised: medians per task label and pass over
//! the timed frames, as a table and as JSON.

use kickstart_rt as ksrt;

/// Median of `v` (0 when empty): the per-frame summaries of `ksrt render` and its
/// frames-in-flight loop.
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => 0.0,
        n if n % 2 == 1 => v[n / 2],
        n => (v[n / 2 - 1] + v[n / 2]) / 2.0,
    }
}

/// Median GPU milliseconds over `frames` of each (label, pass) in first-seen order, each label's
/// summed passes, and the frame's total: `(label, pass or "" for the label's sum, ms)`.
pub fn timing_medians(frames: &[ksrt::GpuTimings]) -> Vec<(&'static str, &'static str, f64)> {
    let mut keys: Vec<(&'static str, &'static str)> = Vec::new();
    for t in frames {
        for p in &t.passes {
            if !keys.contains(&(p.label, p.pass)) {
                keys.push((p.label, p.pass));
            }
        }
    }
    let mut out = Vec::new();
    let mut labels: Vec<&'static str> = Vec::new();
    for (l, _) in &keys {
        if !labels.contains(l) {
            labels.push(l);
        }
    }
    for label in labels {
        out.push((
            label,
            "",
            median(frames.iter().map(|t| t.sum_ms(&[label])).collect()),
        ));
        for &(l, pass) in keys.iter().filter(|(l, _)| *l == label) {
            out.push((
                l,
                pass,
                median(
                    frames
                        .iter()
                        .map(|t| {
                            t.passes
                                .iter()
                                .filter(|p| p.label == l && p.pass == pass)
                                .map(|p| p.ms)
                                .sum()
                        })
                        .collect(),
                ),
            ));
        }
    }
    out.push((
        "total",
        "",
        median(
            frames
                .iter()
                .map(|t| t.passes.iter().map(|p| p.ms).sum())
                .collect(),
        ),
    ));
    out
}

/// A table of the SDK's GPU passes: per label (task) the summed time, then each pass; medians
/// over the timed frames.
pub fn timing_table(frames: &[ksrt::GpuTimings]) -> String {
    let mut out = format!(
        "GPU time per SDK pass (median of the last {} frames):\n",
        frames.len()
    );
    for (label, pass, ms) in timing_medians(frames) {
        if pass.is_empty() {
            out += &format!("  {label:<28} {ms:>9.3} ms\n");
        } else {
            out += &format!("    {pass:<26} {ms:>9.3} ms\n");
        }
    }
    out
}

/// The timing medians as JSON (`ksrt render --json`): scene, size, frames and one record per
/// row of [`timing_table`].
pub fn timing_json(
    scene: &str,
    size: (u32, u32),
    frames: u32,
    timed: &[ksrt::GpuTimings],
) -> serde_json::Value {
    serde_json::json!({
        "scene": scene,
        "width": size.0,
        "height": size.1,
        "frames": frames,
        "timed_frames": timed.len(),
        "passes": timing_medians(timed)
            .into_iter()
            .map(|(label, pass, ms)| serde_json::json!({"label": label, "pass": pass, "median_ms": ms}))
            .collect::<Vec<_>>(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn medians_per_label_and_pass() {
        let frame = |a: f64, b: f64| ksrt::GpuTimings {
            passes: vec![
                ksrt::PassTiming {
                    label: "trace",
                    pass: "specular",
                    start_ms: 0.0,
                    ms: a,
                },
                ksrt::PassTiming {
                    label: "trace",
                    pass: "diffuse",
                    start_ms: a,
                    ms: b,
                },
                ksrt::PassTiming {
                    label: "denoise",
                    pass: "spatial",
                    start_ms: a + b,
                    ms: 1.0,
                },
            ],
        };
        let rows = timing_medians(&[frame(1.0, 2.0), frame(3.0, 4.0), frame(2.0, 9.0)]);
        assert_eq!(rows[0], ("trace", "", 7.0));
        assert_eq!(rows[1], ("trace", "specular", 2.0));
        assert_eq!(rows[2], ("trace", "diffuse", 4.0));
        assert_eq!(rows[3], ("denoise", "", 1.0));
        assert_eq!(rows.last(), Some(&("total", "", 8.0)));
        assert!(timing_table(&[]).contains("last 0 frames"));
    }
}
