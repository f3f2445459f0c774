//! The shadow denoiser: one shadow, or the packed visibility of up to 32 lights, one value per
//! pixel (8-byte records).
//!
//! Shadows use the same passes with the visibility as the signal. That makes the filter
//! penumbra-guided: a hard shadow's visibility is deterministic, so once a few frames are
//! accumulated its noise variance is zero and the luminance stop keeps its edge sharp, while a
//! large light's penumbra is noisy and is smoothed over a radius that grows with the occluder
//! distance.

use super::filter::{Filter, Job};
use super::signal::Kind;
use crate::tasks::{DenoiseMultiShadowTask, DenoiseShadowTask, SignalType};

/// The signal types of the contexts it serves.
const SIGNAL_TYPES: &[SignalType] = &[SignalType::Shadow, SignalType::MultiShadow];

/// Its pipelines and the history of every shadow context.
pub(super) fn new() -> Filter {
    Filter::new(SIGNAL_TYPES)
}

pub(super) fn shadow(t: &DenoiseShadowTask) -> Job<'_> {
    Job::one(
        SignalType::Shadow,
        &t.common,
        &t.input,
        &t.output,
        Kind::Shadow,
    )
}

/// The multi-shadow task's job: its `input0` (`input1` is not bound by any pass).
pub(super) fn multi_shadow(t: &DenoiseMultiShadowTask) -> Job<'_> {
    Job::one(
        SignalType::MultiShadow,
        &t.common,
        &t.input0,
        &t.output,
        Kind::MultiShadow,
    )
}
