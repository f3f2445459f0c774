//! Presets: how many rays each effect traces and how hard the denoisers work, in three steps
//! from cheapest to best looking. Every preset keeps all four effects and their denoisers.

use super::{DenoisingMethod, HalfResolutionMode};

/// One of the ray-traced effects, as a preset sets its rate.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Effect {
    /// Reflections ([`crate::TraceSpecularTask`]).
    Specular,
    /// Diffuse GI ([`crate::TraceDiffuseTask`]).
    Diffuse,
    /// Ambient occlusion ([`crate::TraceAmbientOcclusionTask`]).
    AmbientOcclusion,
    /// Shadows ([`crate::TraceShadowTask`], [`crate::TraceMultiShadowTask`]).
    Shadow,
}

/// A frame-cost preset.
///
/// ```
/// use kickstart_rt::{Effect, Preset};
/// let preset = Preset::Balanced;
/// let frame_index = 7;
/// // The same mode for the trace task and for the denoise task that reads its output.
/// let mode = preset.half_resolution_mode(Effect::Diffuse, frame_index);
/// assert_eq!(mode.block_size(), 2);
/// let method = preset.denoising_method(); // for DenoisingContextInput::method
/// # let _ = method;
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Preset {
    /// Reflections, GI and AO at one ray per 4×4 pixels, shadows per 2×2 (sharp shadow edges
    /// need more samples than smooth lighting); the fast denoiser; lighting injected from one
    /// pixel per 8×8.
    Performance,
    /// One ray per 2×2 pixels for every effect; the fast denoiser; lighting injected from one
    /// pixel per 8×8.
    Balanced,
    /// One ray per pixel for every effect (the reference's rate); the high-quality denoiser;
    /// lighting injected from one pixel per 4×4 (the reference's default).
    Quality,
}

impl Preset {
    /// Every preset, cheapest first.
    pub const ALL: [Preset; 3] = [Preset::Performance, Preset::Balanced, Preset::Quality];

    /// The traced-pixel mode of `effect` in frame `frame_index` (the block modes' phase follows
    /// the frame, so that every pixel is traced in turn). Give the trace task and its denoise
    /// task the same mode; the specular and diffuse signals of one
    /// [`crate::DenoiseSpecularAndDiffuseTask`] always get the same.
    pub fn half_resolution_mode(self, effect: Effect, frame_index: u32) -> HalfResolutionMode {
        let phase = frame_index;
        match (self, effect) {
            (Preset::Quality, _) => HalfResolutionMode::Off,
            (Preset::Performance, Effect::Shadow) | (Preset::Balanced, _) => {
                HalfResolutionMode::OnePer2x2 { phase }
            }
            (Preset::Performance, _) => HalfResolutionMode::OnePer4x4 { phase },
        }
    }

    /// The denoising method of every context.
    pub fn denoising_method(self) -> DenoisingMethod {
        match self {
            Preset::Quality => DenoisingMethod::HighQuality,
            Preset::Performance | Preset::Balanced => DenoisingMethod::Fast,
        }
    }

    /// The [`crate::DirectLightingInjectionTask::injection_resolution_stride`] of the main
    /// view: injection finds each injected pixel's surface with a ray, so its cost falls with
    /// the square of the stride; the lighting cache averages over many frames, so a sparser
    /// injection mostly makes it converge over more frames.
    pub fn injection_resolution_stride(self) -> u32 {
        match self {
            Preset::Quality => 4,
            Preset::Performance | Preset::Balanced => 8,
        }
    }

    /// The preset's name (`performance`, `balanced`, `quality`).
    pub fn name(self) -> &'static str {
        match self {
            Preset::Performance => "performance",
            Preset::Balanced => "balanced",
            Preset::Quality => "quality",
        }
    }
}

impl std::str::FromStr for Preset {
    type Err = String;

    /// Parses a preset's [`Preset::name`].
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Preset::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| format!("unknown preset {s:?} (performance, balanced or quality)"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_preset_traces_every_effect_at_its_rate_and_names_round_trip() {
        let effects = [
            Effect::Specular,
            Effect::Diffuse,
            Effect::AmbientOcclusion,
            Effect::Shadow,
        ];
        let blocks = |p: Preset| effects.map(|e| p.half_resolution_mode(e, 3).block_size());
        assert_eq!(blocks(Preset::Quality), [1, 1, 1, 1]);
        assert_eq!(blocks(Preset::Balanced), [2, 2, 2, 2]);
        assert_eq!(blocks(Preset::Performance), [4, 4, 4, 2]);
        // Specular and diffuse share a denoise task: always one mode.
        for p in Preset::ALL {
            for f in 0..20 {
                assert_eq!(
                    p.half_resolution_mode(Effect::Specular, f),
                    p.half_resolution_mode(Effect::Diffuse, f)
                );
            }
            assert_eq!(p.name().parse::<Preset>(), Ok(p));
        }
        // The phase follows the frame.
        assert_eq!(
            Preset::Balanced.half_resolution_mode(Effect::Diffuse, 5),
            HalfResolutionMode::OnePer2x2 { phase: 5 }
        );
        assert!("fast".parse::<Preset>().unwrap_err().contains("\"fast\""));
        assert_eq!(
            Preset::Quality.denoising_method(),
            DenoisingMethod::HighQuality
        );
        // Every stride is one the injection task accepts, the reference's default at quality.
        assert_eq!(Preset::Quality.injection_resolution_stride(), 4);
        for p in Preset::ALL {
            assert!((1..=8).contains(&p.injection_resolution_stride()));
        }
    }
}
