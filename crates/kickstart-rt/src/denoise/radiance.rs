//! The radiance denoiser: specular reflections and diffuse GI, alone or together (one task, two
//! signals). A radiance signal keeps rgb and the hit distance (16-byte records); the filter's
//! radius follows roughness and hit distance. SpecularAndDiffuse accumulates both signals in one
//! temporal pass and filters each in its own à-trous chain (see `SignalSet::atrous_chains`).

use super::filter::{Filter, Job};
use super::signal::Kind;
use crate::tasks::{
    DenoiseDiffuseTask, DenoiseSpecularAndDiffuseTask, DenoiseSpecularTask, SignalType,
};

/// The signal types of the contexts it serves.
const SIGNAL_TYPES: &[SignalType] = &[
    SignalType::Specular,
    SignalType::Diffuse,
    SignalType::SpecularAndDiffuse,
];

/// Its pipelines and the history of every radiance context.
pub(super) fn new() -> Filter {
    Filter::new(SIGNAL_TYPES)
}

pub(super) fn specular(t: &DenoiseSpecularTask) -> Job<'_> {
    Job::one(
        SignalType::Specular,
        &t.common,
        &t.input,
        &t.output,
        Kind::Specular,
    )
}

pub(super) fn diffuse(t: &DenoiseDiffuseTask) -> Job<'_> {
    Job::one(
        SignalType::Diffuse,
        &t.common,
        &t.input,
        &t.output,
        Kind::Diffuse,
    )
}

pub(super) fn specular_and_diffuse(t: &DenoiseSpecularAndDiffuseTask) -> Job<'_> {
    Job::two(
        SignalType::SpecularAndDiffuse,
        &t.common,
        [&t.input_specular, &t.input_diffuse],
        [&t.output_specular, &t.output_diffuse],
        [Kind::Specular, Kind::Diffuse],
    )
}
