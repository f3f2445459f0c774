//! The text report of `ksrt quality`: the per-frame table, the summary after it and the still
//! camera's flicker.

use super::run::{FrameScores, ReferenceNoise, Score, SignalScores};
use super::still::Stability;
use super::summary::{Summary, SUMMARY_FROM_FRAME};

/// An optional figure with `decimals`, or `n/a` (a ratio to a reference of ≈ 0).
fn figure(v: Option<f64>, decimals: usize) -> String {
    match v {
        Some(v) => format!("{v:.decimals$}"),
        None => "n/a".into(),
    }
}

/// The headings of the score columns; each column is as wide as its heading.
const SCORE_COLUMNS: [&str; 3] = [
    "PSNR noisy→denoised",
    "FLIP noisy→denoised",
    "energy noisy→denoised",
];

/// `cells` right-aligned in the score columns.
fn columns(cells: [&str; 3]) -> String {
    let mut s = String::new();
    for (k, (cell, heading)) in cells.iter().zip(SCORE_COLUMNS).enumerate() {
        if k > 0 {
            s += "   ";
        }
        s += &format!("{cell:>width$}", width = heading.chars().count());
    }
    s
}

/// `noisy → denoised` PSNR, FLIP and energy ratio, in the score columns.
fn scores(noisy: &Score, denoised: &Score) -> String {
    columns([
        &format!("{:.2} → {:.2} dB", noisy.psnr, denoised.psnr),
        &format!("{:.4} → {:.4}", noisy.flip, denoised.flip),
        &format!(
            "{} → {}",
            figure(noisy.energy_ratio, 3),
            figure(denoised.energy_ratio, 3)
        ),
    ])
}

/// The per-frame table's header: noisy → denoised PSNR, FLIP and energy ratio per signal.
pub fn table_header(signals: &[SignalScores]) -> String {
    let mut s = String::from("frame");
    for sig in signals {
        s += &format!(" | {:>8} {}", sig.signal, columns(SCORE_COLUMNS));
    }
    s
}

/// One frame's line of the table.
pub fn table_row(frame: &FrameScores) -> String {
    let mut s = format!("{:>5}", frame.frame);
    for sig in &frame.signals {
        s += &format!(" | {:>8} {}", "", scores(&sig.noisy, &sig.denoised));
    }
    s
}

/// The summary's lines: a heading naming the frames the means cover, then per signal the last
/// frame's line and the mean's.
pub fn summary_lines(summary: &Summary) -> Vec<String> {
    let [first, last] = summary.mean_frames;
    let covers = if first == SUMMARY_FROM_FRAME {
        format!("frames {first}..={last}, after the denoisers' first {SUMMARY_FROM_FRAME}")
    } else {
        format!(
            "all frames {first}..={last} (the pan has no more than {SUMMARY_FROM_FRAME} frames)"
        )
    };
    let mut lines = vec![
        format!(
            "summary: the last frame ({}) and the mean over {covers}",
            summary.last_frame
        ),
        format!("  signal   {:<12} {}", "", columns(SCORE_COLUMNS)),
    ];
    let mean_label = format!("mean {first}..={last}");
    for s in &summary.signals {
        lines.push(format!(
            "  {:<8} {:<12} {}",
            s.signal,
            format!("last ({})", summary.last_frame),
            scores(&s.last.noisy, &s.last.denoised)
        ));
        lines.push(format!(
            "  {:<8} {:<12} {}",
            "",
            mean_label,
            scores(&s.mean.noisy, &s.mean.denoised)
        ));
        if let Some(noise) = &s.mean.reference_noise {
            lines.push(format!("  {:<8} {:<12} {}", "", "", reference_noise(noise)));
        }
    }
    lines
}

/// The reference-noise line under a signal's mean: the ceiling its references leave any image,
/// and the denoised trace's score with their noise taken out.
fn reference_noise(noise: &ReferenceNoise) -> String {
    let converged = match noise.denoised_against_converged {
        Some(p) => format!("{p:.2} dB"),
        None => "at the ceiling".into(),
    };
    format!(
        "the references' own noise: a noise-free image scores {:.2} dB; the denoised, \
         against the converged signal: {converged}",
        noise.ceiling
    )
}

/// The flicker's lines: denoised and reference flicker and their ratio per signal.
pub fn stability_lines(stability: &Stability) -> Vec<String> {
    let mut lines = vec![
        format!(
            "temporal stability: {} still frames at the last camera; flicker = mean |L_t − L_t−1| \
             of the linear values, reference: between two {}-spp references",
            stability.still_frames, stability.reference_samples
        ),
        "  signal   denoised flicker   reference flicker   denoised / reference".into(),
    ];
    for s in &stability.signals {
        lines.push(format!(
            "  {:<8} {:>16}   {:>17}   {:>21}",
            s.signal,
            figure(s.denoised_flicker, 5),
            figure(s.reference_flicker, 5),
            figure(s.ratio, 2)
        ));
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::super::still::SignalStability;
    use super::super::summary::{NoisyDenoised, SignalSummary};
    use super::*;

    fn score(psnr: f64, energy_ratio: Option<f64>) -> Score {
        Score {
            psnr,
            flip: 0.25,
            energy_ratio,
        }
    }

    #[test]
    fn rows_line_up_with_the_header_and_show_undefined_ratios_as_na() {
        let frame = FrameScores {
            frame: 3,
            signals: vec![SignalScores {
                signal: "diffuse",
                noisy: score(21.5, Some(0.98765)),
                denoised: score(30.25, None),
                reference_noise: None,
            }],
        };
        let header = table_header(&frame.signals);
        let row = table_row(&frame);
        assert_eq!(
            header.chars().count(),
            row.chars().count(),
            "{header}\n{row}"
        );
        assert!(row.contains("21.50 → 30.25 dB"), "{row}");
        assert!(row.ends_with("0.988 → n/a"), "{row}");
    }

    #[test]
    fn summary_heading_names_the_frames_of_the_mean() {
        let pair = NoisyDenoised {
            noisy: score(20.0, Some(1.0)),
            denoised: score(25.0, Some(0.5)),
            reference_noise: Some(ReferenceNoise {
                ceiling: 30.5,
                denoised_against_converged: Some(43.25),
            }),
        };
        let mut summary = Summary {
            last_frame: 31,
            mean_frames: [8, 31],
            signals: vec![SignalSummary {
                signal: "ao",
                last: pair,
                mean: pair,
            }],
        };
        let lines = summary_lines(&summary);
        assert!(lines[0].contains("frames 8..=31"), "{}", lines[0]);
        assert!(lines[2].contains("last (31)") && lines[3].contains("mean 8..=31"));
        assert!(
            lines[4].contains("scores 30.50 dB") && lines[4].ends_with("signal: 43.25 dB"),
            "{}",
            lines[4]
        );
        summary.mean_frames = [0, 5];
        summary.last_frame = 5;
        let lines = summary_lines(&summary);
        assert!(lines[0].contains("all frames 0..=5"), "{}", lines[0]);
    }

    #[test]
    fn stability_lines_show_both_flickers_and_their_ratio() {
        let lines = stability_lines(&Stability {
            still_frames: 8,
            reference_samples: 64,
            signals: vec![SignalStability {
                signal: "shadow",
                denoised_flicker: Some(0.012),
                reference_flicker: Some(0.004),
                ratio: Some(3.0),
            }],
        });
        assert!(lines[0].contains("8 still frames") && lines[0].contains("64-spp"));
        assert!(
            lines[2].contains("0.01200") && lines[2].contains("0.00400"),
            "{}",
            lines[2]
        );
        assert!(lines[2].ends_with("3.00"), "{}", lines[2]);
    }
}
