//! Reading a measured frame back (its raw and denoised outputs, the pixels with a surface) and
//! accumulating its converged reference: what the pan (`run`) and the still frames (`still`)
//! both do.

use crate::app::frames::RendererExt;
use crate::app::readback::read_texture;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::renderer::Renderer;

use super::accumulate::Accumulator;
use super::signal::Signal;

/// Reference samples traced per submission: each is a GPU task holding one of the context's
/// working sets until the submission completes, and `ksrt`'s context has the default four.
const SAMPLES_PER_SUBMIT: u32 = 3;

/// Noisy, denoised and reference images of one signal as linear RGB per pixel.
pub struct Triple {
    pub signal: Signal,
    pub noisy: Vec<[f32; 3]>,
    pub denoised: Vec<[f32; 3]>,
    pub reference: Vec<[f32; 3]>,
    /// The mean of the reference's first half of samples (empty for a reference of one sample).
    pub reference_first_half: Vec<[f32; 3]>,
}

/// How many of a reference's `samples` make its first half ([`super::ceiling`]).
pub fn first_half(samples: u32) -> u32 {
    samples / 2
}

/// `signal`'s denoised output of the last frame, as linear RGB.
pub fn read_denoised(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    r: &Renderer,
    signal: Signal,
) -> AnyResult<Vec<[f32; 3]>> {
    let (_, denoised) = signal.outputs(&r.sdk.outputs);
    let texels = read_texture(device, queue, denoised)?.data;
    Ok(texels.iter().map(|&t| signal.denoised_texel(t)).collect())
}

/// `signal`'s raw and denoised outputs of the last frame (the reference still to come).
pub fn read_measured(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    r: &Renderer,
    signal: Signal,
) -> AnyResult<Triple> {
    let (raw, _) = signal.outputs(&r.sdk.outputs);
    let raw = read_texture(device, queue, raw)?.data;
    Ok(Triple {
        signal,
        noisy: raw.iter().map(|&t| signal.raw_texel(t)).collect(),
        denoised: read_denoised(device, queue, r, signal)?,
        reference: Vec::new(),
        reference_first_half: Vec::new(),
    })
}

/// The pixels of the last frame that show a surface (depth short of the far plane).
pub fn surface_mask(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    r: &Renderer,
) -> AnyResult<Vec<bool>> {
    let depth = read_texture(device, queue, &r.main.depth)?;
    Ok(depth.data.iter().map(|d| d[0] < 1.0).collect())
}

/// Traces reference `f`'s `samples` samples on the last frame's G-buffer into `sums` (cleared
/// first), submitting every [`SAMPLES_PER_SUBMIT`], and counts them on `bar`. Each reference `f`
/// draws its own samples' noise indices, so references of different `f` are independent. With
/// `halves`, returns per signal of `sums` the mean of the first half of the samples
/// ([`first_half`]); nothing without, or for a reference of one sample.
pub fn accumulate_reference(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    r: &mut Renderer,
    (f, samples): (u32, u32),
    (sums, halves): (&[(Signal, Accumulator)], bool),
    bar: &indicatif::ProgressBar,
) -> AnyResult<Vec<Vec<[f32; 3]>>> {
    let mut encoder = device.create_command_encoder(&Default::default());
    for (_, acc) in sums {
        acc.clear(&mut encoder);
    }
    let half = if halves { first_half(samples) } else { 0 };
    let mut first_halves = Vec::new();
    let mut pending = Vec::new();
    for k in 0..samples {
        let sample = 0x8000_0000u32
            .wrapping_add(f.wrapping_mul(samples))
            .wrapping_add(k);
        pending.extend(r.record_traces(&mut encoder, sample)?);
        for (_, acc) in sums {
            acc.add(&mut encoder);
        }
        let at_half = half > 0 && k + 1 == half;
        if (k + 1) % SAMPLES_PER_SUBMIT == 0 || k + 1 == samples || at_half {
            queue.submit([encoder.finish()]);
            r.finish(device, &pending, false)?;
            pending.clear();
            encoder = device.create_command_encoder(&Default::default());
            bar.set_position(u64::from(f) * u64::from(samples) + u64::from(k + 1));
        }
        if at_half {
            first_halves = sums
                .iter()
                .map(|(_, acc)| acc.mean(device, queue))
                .collect::<AnyResult<_>>()?;
        }
    }
    Ok(first_halves)
}
