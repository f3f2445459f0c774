//! What a denoising context is created for: the signal it denoises and the denoiser.
//! These live beside the tasks (not in the context) because the denoisers and the validation
//! need them too, and imports point down the SDK's layers (see `lib.rs`).

/// Settings of a denoising context.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DenoisingContextInput {
    /// Largest width it will denoise, pixels (> 0).
    pub max_width: u32,
    /// Largest height it will denoise, pixels (> 0).
    pub max_height: u32,
    /// Which signal it denoises.
    pub signal_type: SignalType,
    /// Which denoiser.
    pub method: DenoisingMethod,
}

/// The signal a denoising context is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SignalType {
    /// Specular reflections.
    Specular,
    /// Diffuse GI.
    Diffuse,
    /// Both, in one pass.
    SpecularAndDiffuse,
    /// Ambient occlusion.
    DiffuseOcclusion,
    /// One shadow.
    Shadow,
    /// Up to 32 shadows.
    MultiShadow,
}

/// Which denoiser a context uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DenoisingMethod {
    /// The cheaper filter.
    Fast,
    /// The higher-quality filter.
    #[default]
    HighQuality,
}
