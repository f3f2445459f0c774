//! How much of a score is the reference's own noise.
//!
//! A reference of `n` samples per pixel is itself noisy, so scored against it even a noise-free
//! image loses PSNR: a sparse signal (the Cornell box's diffuse, lit by rare rays that reach its
//! small light) keeps visible noise at 256 samples. The run keeps the mean `A` of a reference's
//! first `a` samples beside the mean `M` of all `n`; the last `b = n − a` samples' mean is then
//! `B = (n·M − a·A) / b`, and `A`, `B` are independent estimates of the converged image. With a
//! per-sample variance σ², `E|A − B|² = σ²·(1/a + 1/b)` and the reference's own error is
//! `E|M − converged|² = σ²/n`, so
//!
//! `MSE_ref = MSE(A, B) · a·b / n²`.
//!
//! The denoised image's error and the reference's are independent, so they add:
//! `MSE(denoised, reference) = MSE(denoised, converged) + MSE_ref`. Hence two figures: the
//! **ceiling**, the PSNR of `MSE_ref` (what a noise-free image scores against this reference),
//! and the denoised image's PSNR **against the converged signal**, the PSNR of the difference.
//! Both are taken on the 8-bit images the PSNR compares: at a converged reference's small noise
//! the tone curve is close to linear over the noise, so the halves' difference scales as the
//! linear one does. Where the noise is large the curve's bend also biases the tone-mapped
//! reference (a mean of noisy samples maps darker than the converged value), which the halves'
//! difference does not see: then the ceiling errs high and the score against the converged
//! signal errs low (the Cornell box's specular at 256 spp: 37.2 dB, against 40.0 dB from
//! 2048-spp references).

use super::metrics;
use super::signal::Signal;

/// The reference's first samples: the mean of the first `count` of its samples.
pub struct FirstSamples<'a> {
    /// Mean per pixel (linear RGB, row-major).
    pub mean: &'a [[f32; 3]],
    /// How many samples that mean holds.
    pub count: u32,
}

/// The reference's own mean squared error against the converged image (8-bit levels squared,
/// on `signal`'s encoding), from `full` (the mean of all `samples`) and `first` (the mean of
/// the first of them); `None` where one of the two halves holds no sample.
pub fn reference_noise_mse(
    signal: Signal,
    size: (u32, u32),
    full: &[[f32; 3]],
    first: &FirstSamples,
    samples: u32,
) -> Result<Option<f64>, String> {
    let (n, a) = (f64::from(samples), f64::from(first.count));
    let b = n - a;
    if first.count == 0 || b < 1.0 {
        return Ok(None);
    }
    if first.mean.len() != full.len() {
        return Err(format!(
            "the reference's first-samples mean holds {} pixels, its full mean {}",
            first.mean.len(),
            full.len()
        ));
    }
    let last: Vec<[f32; 3]> = full
        .iter()
        .zip(first.mean)
        .map(|(m, f)| {
            let mut r = [0.0f32; 3];
            for k in 0..3 {
                r[k] = ((n * f64::from(m[k]) - a * f64::from(f[k])) / b) as f32;
            }
            r
        })
        .collect();
    let (w, h) = size;
    let between = metrics::mse(
        &signal.encode(w, h, first.mean),
        &signal.encode(w, h, &last),
    )?;
    Ok(Some(between * a * b / (n * n)))
}

/// The PSNR (dB) a noise-free image scores against a reference whose own error is
/// `reference_mse`.
pub fn ceiling(reference_mse: f64) -> f64 {
    metrics::psnr_of_mse(reference_mse)
}

/// The PSNR (dB) of an image against the converged signal, from its PSNR `measured` against a
/// reference whose own error is `reference_mse`; `None` where the measured error exceeds the
/// reference's by less than 2 %, which the estimate cannot tell from none.
pub fn against_converged(measured: f64, reference_mse: f64) -> Option<f64> {
    let own = metrics::mse_of_psnr(measured) - reference_mse;
    (own > 0.02 * reference_mse).then(|| metrics::psnr_of_mse(own))
}

#[cfg(test)]
mod tests {
    use super::*;
    use kickstart_rt_renderer::rng::Rng;

    const SIZE: (u32, u32) = (96, 96);

    /// AO-like grey values in 0.2..0.8 (encoded linearly to 8 bits, so the error is analytic).
    fn converged() -> Vec<[f32; 3]> {
        (0..SIZE.0 * SIZE.1)
            .map(|i| {
                let v = 0.2 + 0.6 * ((i % SIZE.0) as f32 / SIZE.0 as f32);
                [v; 3]
            })
            .collect()
    }

    /// The means of the first `first` and of all `samples` noisy samples per pixel (each the
    /// converged value ± up to `amplitude`, uniform).
    fn reference(
        truth: &[[f32; 3]],
        samples: u32,
        first: u32,
        amplitude: f32,
        seed: u64,
    ) -> (Vec<[f32; 3]>, Vec<[f32; 3]>) {
        let mut rng = Rng(seed);
        let mut head = Vec::new();
        let mut all = Vec::new();
        for t in truth {
            let (mut sum, mut head_sum) = (0.0f32, 0.0f32);
            for k in 0..samples {
                sum += t[0] + amplitude * (2.0 * rng.f32() - 1.0);
                if k + 1 == first {
                    head_sum = sum;
                }
            }
            head.push([head_sum / first.max(1) as f32; 3]);
            all.push([sum / samples as f32; 3]);
        }
        (head, all)
    }

    fn encode(v: &[[f32; 3]]) -> metrics::Srgb8 {
        Signal::Ao.encode(SIZE.0, SIZE.1, v)
    }

    /// The AO reference error estimated from `all` (mean of `samples`) and `head` (mean of the
    /// first `count`).
    fn estimate(
        head: &[[f32; 3]],
        count: u32,
        all: &[[f32; 3]],
        samples: u32,
    ) -> Result<Option<f64>, String> {
        let first = FirstSamples { mean: head, count };
        reference_noise_mse(Signal::Ao, SIZE, all, &first, samples)
    }

    #[test]
    fn estimates_the_reference_error_from_halves_equal_or_not() {
        let truth = converged();
        for (samples, first) in [(64, 32), (64, 21), (16, 8)] {
            let (head, all) = reference(&truth, samples, first, 0.3, 7);
            let actual = metrics::mse(&encode(&all), &encode(&truth)).unwrap();
            let estimate = estimate(&head, first, &all, samples).unwrap().unwrap();
            let ratio = estimate / actual;
            assert!(
                (0.9..1.1).contains(&ratio),
                "{samples} samples, first {first}: estimated {estimate:.3}, actual {actual:.3}"
            );
        }
    }

    #[test]
    fn scores_an_image_against_the_converged_signal_through_a_noisy_reference() {
        let truth = converged();
        let (head, all) = reference(&truth, 16, 8, 0.4, 11);
        let reference_mse = estimate(&head, 8, &all, 16).unwrap().unwrap();
        // A "denoised" image with an error of its own, about as large as the reference's.
        let (_, denoised) = reference(&truth, 12, 12, 0.4, 23);
        let measured = metrics::psnr(&encode(&denoised), &encode(&all)).unwrap();
        let actual = metrics::psnr(&encode(&denoised), &encode(&truth)).unwrap();
        let estimate = against_converged(measured, reference_mse).unwrap();
        assert!(
            (estimate - actual).abs() < 0.3,
            "against the converged signal: estimated {estimate:.2} dB, actual {actual:.2} dB \
             (measured against the reference {measured:.2} dB)"
        );
        // The converged image itself scores the ceiling against the reference.
        let perfect = metrics::psnr(&encode(&truth), &encode(&all)).unwrap();
        assert!(
            (ceiling(reference_mse) - perfect).abs() < 0.3,
            "ceiling {:.2} dB, a noise-free image's score {perfect:.2} dB",
            ceiling(reference_mse)
        );
        // Its own error is the estimate's noise (a few % of the reference's on an image this
        // small): none, or far past the ceiling.
        let own = against_converged(perfect, reference_mse);
        assert!(
            own.is_none_or(|p| p > ceiling(reference_mse) + 10.0),
            "a noise-free image scored {own:?} against the converged signal"
        );
        assert_eq!(
            against_converged(ceiling(reference_mse), reference_mse),
            None
        );
    }

    #[test]
    fn a_reference_of_one_sample_or_mismatched_means_has_no_estimate() {
        let truth = converged();
        let (head, all) = reference(&truth, 1, 1, 0.3, 3);
        assert_eq!(estimate(&head, 1, &all, 1), Ok(None));
        assert!(estimate(&head[..10], 1, &all, 2).is_err());
    }
}
