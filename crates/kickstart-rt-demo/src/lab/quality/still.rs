//! Temporal stability: after the pan, the camera holds still at the pan's last camera for
//! `still_frames` more frames, the denoisers carrying on, and each signal's **flicker** — the
//! mean over the surface pixels of |L_t − L_{t−1}| of the denoised linear scalar
//! ([`super::linear::flicker`]) — is averaged over those frames (the first against the pan's last
//! frame).
//!
//! Each still frame is rendered as a game's next frame is: [`Renderer::render_frame`] advances
//! the frame counter, which is the SDK's noise frame index (so every still frame traces with new
//! noise) and the Halton jitter's index (so the G-buffer moves by sub-pixel offsets, and sharp
//! edges — geometry, hard shadows — change from frame to frame as they do before a game's
//! temporal anti-aliasing).
//!
//! Beside it, the **reference's flicker**: the same measure between two independent references
//! of that view, the last pan frame's and one more traced with other samples' noise on the last
//! still frame's G-buffer. It is the flicker that converged images of `reference_samples`
//! samples per pixel show between two frames of this view, their noise and the jitter's edges
//! together; a denoiser at or below it is as steady as such references.

use super::accumulate::Accumulator;
use super::capture::{accumulate_reference, read_denoised, surface_mask, Triple};
use super::linear;
use super::options::QualityOptions;
use super::signal::Signal;
use super::summary::mean_of_defined;
use crate::app::frames::RendererExt;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::renderer::Renderer;
use kickstart_rt_renderer::scene::Camera;

/// One signal's flicker.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SignalStability {
    /// The signal's name.
    pub signal: &'static str,
    /// Mean over the still frames of the denoised output's flicker; `None` when no pixel shows a
    /// surface.
    pub denoised_flicker: Option<f64>,
    /// Flicker between two independent references of the still view.
    pub reference_flicker: Option<f64>,
    /// Denoised over reference flicker; `None` where the reference's is ≈ 0
    /// ([`linear::MIN_REFERENCE`]).
    pub ratio: Option<f64>,
}

/// The flicker of every signal over the still frames.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Stability {
    /// Frames held still.
    pub still_frames: u32,
    /// Samples per pixel of each of the two references.
    pub reference_samples: u32,
    /// Per signal, in the pan's order.
    pub signals: Vec<SignalStability>,
}

/// Where the still frames start: the pan's last camera and that frame's images (with its
/// reference) and surface pixels.
pub(super) struct StillStart<'a> {
    /// The pan's last camera.
    pub(super) camera: &'a Camera,
    /// The last pan frame's images, one per signal, in the order of the accumulators.
    pub(super) triples: &'a [Triple],
    /// Its pixels with a surface.
    pub(super) mask: &'a [bool],
}

/// Renders `opts.still_frames` frames at `from.camera`, measuring each signal's flicker, then
/// traces the still view's second reference on the last one's G-buffer.
pub(super) fn hold(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    r: &mut Renderer,
    sums: &[(Signal, Accumulator)],
    from: &StillStart<'_>,
    opts: &QualityOptions,
    bar: &indicatif::ProgressBar,
) -> AnyResult<Stability> {
    let mut previous: Vec<Vec<f32>> = from
        .triples
        .iter()
        .map(|t| t.signal.scalars(&t.denoised))
        .collect();
    let mut previous_mask = from.mask.to_vec();
    let mut flickers = vec![Vec::new(); previous.len()];
    for _ in 0..opts.still_frames {
        r.render_frame(device, queue, from.camera, false)?;
        let mask = surface_mask(device, queue, r)?;
        let both = and(&mask, &previous_mask);
        for (k, t) in from.triples.iter().enumerate() {
            let now = t
                .signal
                .scalars(&read_denoised(device, queue, r, t.signal)?);
            flickers[k].push(linear::flicker(&now, &previous[k], &both));
            previous[k] = now;
        }
        previous_mask = mask;
    }
    // Reference index `frames`: past every pan frame's, so its samples' noise is new.
    accumulate_reference(
        device,
        queue,
        r,
        (opts.frames, opts.reference_samples),
        (sums, false),
        bar,
    )?;
    let both = and(&previous_mask, from.mask);
    let mut reference_flicker = Vec::new();
    for ((signal, acc), t) in sums.iter().zip(from.triples) {
        debug_assert_eq!(*signal, t.signal);
        let other = signal.scalars(&acc.mean(device, queue)?);
        reference_flicker.push(linear::flicker(
            &other,
            &signal.scalars(&t.reference),
            &both,
        ));
    }
    let signals = from
        .triples
        .iter()
        .zip(flickers)
        .zip(reference_flicker)
        .map(|((t, f), reference)| {
            let denoised = mean_of_defined(f);
            SignalStability {
                signal: t.signal.name(),
                denoised_flicker: denoised,
                reference_flicker: reference,
                ratio: denoised
                    .zip(reference)
                    .and_then(|(d, r)| linear::ratio(d, r)),
            }
        })
        .collect();
    Ok(Stability {
        still_frames: opts.still_frames,
        reference_samples: opts.reference_samples,
        signals,
    })
}

/// The pixels both masks keep.
fn and(a: &[bool], b: &[bool]) -> Vec<bool> {
    a.iter().zip(b).map(|(a, b)| *a && *b).collect()
}
