//! The scores of `ksrt quality`: per signal and frame, and how much of them is the reference's
//! own noise.

/// PSNR (dB), FLIP (mean, 0 = identical) and energy ratio of one image against the reference.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Score {
    /// PSNR, dB, of the 8-bit sRGB images (∞ when identical).
    pub psnr: f64,
    /// Mean FLIP error.
    pub flip: f64,
    /// Mean of the linear values over the reference's, over the pixels with a surface
    /// ([`super::linear::energy_ratio`]); `None` where the reference is ≈ 0.
    pub energy_ratio: Option<f64>,
}

/// One signal's scores in one frame.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SignalScores {
    /// The signal's name.
    pub signal: &'static str,
    /// The 1-spp trace against the reference.
    pub noisy: Score,
    /// The denoised trace against the reference.
    pub denoised: Score,
    /// How much of those scores is the reference's own noise (`None` for a reference of one
    /// sample).
    pub reference_noise: Option<ReferenceNoise>,
}

/// How much of a score is its reference's own noise ([`super::ceiling`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ReferenceNoise {
    /// The PSNR (dB) a noise-free image scores against the reference, which no denoiser can
    /// exceed (an estimate from the reference's two halves; see [`super::ceiling`] for where it
    /// errs).
    pub ceiling: f64,
    /// The denoised trace's PSNR (dB) against the converged signal, the reference's noise taken
    /// out; `None` where the denoised error is within the estimate of the reference's.
    pub denoised_against_converged: Option<f64>,
}

/// One pan frame's scores.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FrameScores {
    /// Frame of the pan, from 0.
    pub frame: u32,
    /// Per signal the scene renders (the shadow needs a light).
    pub signals: Vec<SignalScores>,
}
