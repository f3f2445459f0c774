//! `ksrt quality`'s options and the constants of its measurement.

use std::path::PathBuf;

/// The specular trace's roughness everywhere (the glossy case).
pub const SPECULAR_ROUGHNESS: f32 = 0.3;

/// Which strips to write.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Images {
    /// Every frame's.
    All,
    /// The last frame's.
    Last,
    /// None.
    None,
}

/// Options of `ksrt quality`.
#[derive(Debug, Clone)]
pub struct QualityOptions {
    /// Image size.
    pub size: (u32, u32),
    /// Measured frames along the pan.
    pub frames: u32,
    /// Frames of cache warm-up before the pan.
    pub warmup: u32,
    /// Samples per pixel of each frame's reference.
    pub reference_samples: u32,
    /// Yaw of the whole pan, degrees (turning left about the eye).
    pub pan_degrees: f32,
    /// Frames held still at the pan's last camera after it, for the flicker (0: none).
    pub still_frames: u32,
    /// Seed of the measured frames' noise.
    pub seed: u32,
    /// Where to write the strips (`None`: nowhere).
    pub out: Option<PathBuf>,
    /// Which strips to write.
    pub images: Images,
    /// Progress bars on stderr for the warm-up and the reference samples.
    pub progress: bool,
    /// Rays per pixel of the measured frames and the denoising method (the reference traces
    /// every pixel whatever the preset).
    pub preset: kickstart_rt::Preset,
}
