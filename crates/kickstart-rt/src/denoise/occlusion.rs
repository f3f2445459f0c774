//! The occlusion denoiser: ambient occlusion, one value per pixel (8-byte records).

use super::filter::{Filter, Job};
use super::signal::Kind;
use crate::tasks::{DenoiseDiffuseOcclusionTask, SignalType};

/// The signal types of the contexts it serves.
const SIGNAL_TYPES: &[SignalType] = &[SignalType::DiffuseOcclusion];

/// Its pipelines and the history of every occlusion context.
pub(super) fn new() -> Filter {
    Filter::new(SIGNAL_TYPES)
}

pub(super) fn diffuse_occlusion(t: &DenoiseDiffuseOcclusionTask) -> Job<'_> {
    Job::one(
        SignalType::DiffuseOcclusion,
        &t.common,
        &t.input,
        &t.output,
        Kind::Occlusion,
    )
}
