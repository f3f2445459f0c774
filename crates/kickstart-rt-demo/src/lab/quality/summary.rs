//! The summary after the per-frame table: per signal the last frame's scores and their mean over
//! the frames after the denoisers' first [`SUMMARY_FROM_FRAME`] (their history starts empty at
//! the pan's first frame, so the early frames measure convergence rather than the steady state).

use std::ops::RangeInclusive;

use super::scores::{FrameScores, ReferenceNoise, Score};

/// The first frame the summary's mean covers, when the pan is longer than this many frames.
pub const SUMMARY_FROM_FRAME: u32 = 8;

/// The frames the summary's mean covers for a pan of `count` frames: `8..=count − 1`, or every
/// frame when the pan has at most 8. `None` for no frames.
pub fn summary_frames(count: u32) -> Option<RangeInclusive<u32>> {
    let last = count.checked_sub(1)?;
    let first = if count > SUMMARY_FROM_FRAME {
        SUMMARY_FROM_FRAME
    } else {
        0
    };
    Some(first..=last)
}

/// The mean of the defined values; `None` when none is.
pub fn mean_of_defined(values: impl IntoIterator<Item = Option<f64>>) -> Option<f64> {
    let (sum, n) = values
        .into_iter()
        .flatten()
        .fold((0.0, 0usize), |(s, n), v| (s + v, n + 1));
    (n > 0).then(|| sum / n as f64)
}

/// The mean of `scores`, field by field (PSNR in dB, so an ∞ of identical images makes it ∞);
/// the energy ratio over the frames where it is defined. `None` for no scores.
pub fn mean_score(scores: &[Score]) -> Option<Score> {
    let n = scores.len();
    (n > 0).then(|| Score {
        psnr: scores.iter().map(|s| s.psnr).sum::<f64>() / n as f64,
        flip: scores.iter().map(|s| s.flip).sum::<f64>() / n as f64,
        energy_ratio: mean_of_defined(scores.iter().map(|s| s.energy_ratio)),
    })
}

/// The mean of `noises`' ceilings (`None` for none) and of their defined denoised scores
/// against the converged signal.
pub fn mean_reference_noise(noises: &[ReferenceNoise]) -> Option<ReferenceNoise> {
    let ceiling = mean_of_defined(noises.iter().map(|n| Some(n.ceiling)))?;
    Some(ReferenceNoise {
        ceiling,
        denoised_against_converged: mean_of_defined(
            noises.iter().map(|n| n.denoised_against_converged),
        ),
    })
}

/// A signal's noisy and denoised scores.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct NoisyDenoised {
    /// The 1-spp trace against the reference.
    pub noisy: Score,
    /// The denoised trace against the reference.
    pub denoised: Score,
    /// How much of those scores is the reference's own noise (means: over the frames that have
    /// an estimate).
    pub reference_noise: Option<ReferenceNoise>,
}

/// One signal's summary.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SignalSummary {
    /// The signal's name.
    pub signal: &'static str,
    /// The last frame's scores.
    pub last: NoisyDenoised,
    /// The mean over [`Summary::mean_frames`].
    pub mean: NoisyDenoised,
}

/// The summary of a pan.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Summary {
    /// The last frame.
    pub last_frame: u32,
    /// First and last frame (inclusive) of the means.
    pub mean_frames: [u32; 2],
    /// Per signal of the first frame, in its order.
    pub signals: Vec<SignalSummary>,
}

/// The summary of the pan's `frames` (numbered from 0, in order); `None` for no frames. A signal
/// missing from some frames is averaged over the frames that have it.
pub fn summarize(frames: &[FrameScores]) -> Option<Summary> {
    let last = frames.last()?;
    let range = summary_frames(u32::try_from(frames.len()).ok()?)?;
    let in_range: Vec<&FrameScores> = frames.iter().filter(|f| range.contains(&f.frame)).collect();
    let mut signals = Vec::new();
    for s in &last.signals {
        let of_signal = |pick: fn(&super::scores::SignalScores) -> Score| -> Vec<Score> {
            in_range
                .iter()
                .flat_map(|f| f.signals.iter().filter(|x| x.signal == s.signal))
                .map(pick)
                .collect()
        };
        let (Some(noisy), Some(denoised)) = (
            mean_score(&of_signal(|x| x.noisy)),
            mean_score(&of_signal(|x| x.denoised)),
        ) else {
            continue;
        };
        let noises: Vec<ReferenceNoise> = in_range
            .iter()
            .flat_map(|f| f.signals.iter().filter(|x| x.signal == s.signal))
            .filter_map(|x| x.reference_noise)
            .collect();
        signals.push(SignalSummary {
            signal: s.signal,
            last: NoisyDenoised {
                noisy: s.noisy,
                denoised: s.denoised,
                reference_noise: s.reference_noise,
            },
            mean: NoisyDenoised {
                noisy,
                denoised,
                reference_noise: mean_reference_noise(&noises),
            },
        });
    }
    Some(Summary {
        last_frame: last.frame,
        mean_frames: [*range.start(), *range.end()],
        signals,
    })
}

#[cfg(test)]
mod tests {
    use super::super::scores::SignalScores;
    use super::*;

    fn score(psnr: f64, flip: f64, energy_ratio: Option<f64>) -> Score {
        Score {
            psnr,
            flip,
            energy_ratio,
        }
    }

    #[test]
    fn the_mean_covers_frames_8_to_last_or_every_frame_of_a_short_pan() {
        assert_eq!(summary_frames(0), None);
        assert_eq!(summary_frames(1), Some(0..=0));
        assert_eq!(summary_frames(8), Some(0..=7));
        assert_eq!(summary_frames(9), Some(8..=8));
        assert_eq!(summary_frames(32), Some(8..=31));
    }

    #[test]
    fn mean_score_averages_each_field_and_skips_undefined_ratios() {
        let m = mean_score(&[
            score(20.0, 0.5, Some(0.8)),
            score(30.0, 0.1, None),
            score(40.0, 0.3, Some(1.2)),
        ])
        .unwrap();
        assert_eq!(m, score(30.0, 0.3, Some(1.0)));
        assert_eq!(
            mean_score(&[score(1.0, 0.0, None)]).unwrap().energy_ratio,
            None
        );
        assert_eq!(mean_score(&[]), None);
    }

    /// Frame `f` of a pan scores PSNR `f`, FLIP `f / 100` and an energy ratio of `f / 10`
    /// (noisy) and twice those (denoised).
    fn frames(count: u32) -> Vec<FrameScores> {
        (0..count)
            .map(|f| {
                let v = f as f64;
                FrameScores {
                    frame: f,
                    signals: vec![SignalScores {
                        signal: "ao",
                        noisy: score(v, v / 100.0, Some(v / 10.0)),
                        denoised: score(2.0 * v, v / 50.0, Some(v / 5.0)),
                        // Ceiling 40 + f; against the converged signal only on even frames.
                        reference_noise: Some(ReferenceNoise {
                            ceiling: 40.0 + v,
                            denoised_against_converged: (f % 2 == 0).then_some(3.0 * v),
                        }),
                    }],
                }
            })
            .collect()
    }

    #[test]
    fn summary_of_a_long_pan_is_the_last_frame_and_the_mean_from_frame_8() {
        let s = summarize(&frames(12)).unwrap();
        assert_eq!(s.last_frame, 11);
        assert_eq!(s.mean_frames, [8, 11]);
        let ao = &s.signals[0];
        assert_eq!(ao.signal, "ao");
        assert_eq!(ao.last.noisy.psnr, 11.0);
        assert_eq!(ao.last.denoised.psnr, 22.0);
        // Frames 8..=11: mean 9.5.
        assert!((ao.mean.noisy.psnr - 9.5).abs() < 1e-12);
        assert!((ao.mean.denoised.psnr - 19.0).abs() < 1e-12);
        assert!((ao.mean.noisy.flip - 0.095).abs() < 1e-12);
        assert!((ao.mean.denoised.energy_ratio.unwrap() - 1.9).abs() < 1e-12);
        let last_noise = ao.last.reference_noise.unwrap();
        assert_eq!(last_noise.ceiling, 51.0);
        assert_eq!(last_noise.denoised_against_converged, None);
        // Ceilings of frames 8..=11, the converged scores of frames 8 and 10 (24, 30).
        let mean_noise = ao.mean.reference_noise.unwrap();
        assert!((mean_noise.ceiling - 49.5).abs() < 1e-12);
        assert_eq!(mean_noise.denoised_against_converged, Some(27.0));
        assert_eq!(mean_reference_noise(&[]), None);
    }

    #[test]
    fn summary_of_a_short_pan_covers_every_frame() {
        let s = summarize(&frames(6)).unwrap();
        assert_eq!(s.mean_frames, [0, 5]);
        // Frames 0..=5: mean 2.5.
        assert!((s.signals[0].mean.noisy.psnr - 2.5).abs() < 1e-12);
        assert!(summarize(&[]).is_none());
    }
}
