//! Figures on the **linear** values, before tone mapping: the energy ratio (does a trace keep the
//! reference's brightness?) and the flicker (how much a still image changes from frame to frame).
//!
//! Both read one scalar per pixel (luminance of radiance, the value of AO and shadow visibility;
//! [`super::signal::Signal::scalar`]) and only the pixels with a surface (the mask: the G-buffer's
//! depth is not the far plane), so that background pixels, which every trace leaves at a fixed
//! value, neither dilute nor inflate them. Non-finite values count as 0, as the reference's
//! accumulation counts them ([`super::accumulate`]).

/// Rec. 709 luminance weights of linear RGB.
pub const LUMINANCE: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// A reference figure (a mean, a flicker) at or below this is taken as none at all: a ratio to it
/// is then undefined (`None`), not a division by (almost) zero.
pub const MIN_REFERENCE: f64 = 1e-6;

/// Luminance of linear RGB.
pub fn luminance(rgb: [f32; 3]) -> f32 {
    LUMINANCE[0] * rgb[0] + LUMINANCE[1] * rgb[1] + LUMINANCE[2] * rgb[2]
}

fn finite_or_zero(v: f32) -> f64 {
    if v.is_finite() {
        f64::from(v)
    } else {
        0.0
    }
}

/// The mean of `values` over the pixels `mask` keeps; `None` when it keeps none.
pub fn masked_mean(values: &[f32], mask: &[bool]) -> Option<f64> {
    debug_assert_eq!(values.len(), mask.len());
    let (sum, n) = values
        .iter()
        .zip(mask)
        .filter(|(_, &m)| m)
        .fold((0.0f64, 0usize), |(s, n), (&v, _)| {
            (s + finite_or_zero(v), n + 1)
        });
    (n > 0).then(|| sum / n as f64)
}

/// `numerator / denominator`, or `None` when the denominator is at most
/// [`MIN_REFERENCE`] (or either is not finite).
pub fn ratio(numerator: f64, denominator: f64) -> Option<f64> {
    (numerator.is_finite() && denominator.is_finite() && denominator > MIN_REFERENCE)
        .then(|| numerator / denominator)
}

/// Energy ratio of `test` against `reference` (per-pixel scalars) over the masked pixels: mean
/// of `test` over mean of `reference`. 1 keeps the reference's energy, below 1 loses some.
/// `None` when no pixel is masked in or the reference's mean is ≈ 0 ([`MIN_REFERENCE`]).
pub fn energy_ratio(test: &[f32], reference: &[f32], mask: &[bool]) -> Option<f64> {
    debug_assert_eq!(test.len(), reference.len());
    ratio(masked_mean(test, mask)?, masked_mean(reference, mask)?)
}

/// Flicker between two frames of a still view: the mean over the masked pixels of
/// |current − previous| (per-pixel scalars). `None` when no pixel is masked in.
pub fn flicker(current: &[f32], previous: &[f32], mask: &[bool]) -> Option<f64> {
    debug_assert_eq!(current.len(), previous.len());
    debug_assert_eq!(current.len(), mask.len());
    let (sum, n) = current
        .iter()
        .zip(previous)
        .zip(mask)
        .filter(|(_, &m)| m)
        .fold((0.0f64, 0usize), |(s, n), ((&a, &b), _)| {
            (s + (finite_or_zero(a) - finite_or_zero(b)).abs(), n + 1)
        });
    (n > 0).then(|| sum / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn luminance_weights_sum_to_one() {
        assert!((luminance([1.0; 3]) - 1.0).abs() < 1e-6);
        assert!((luminance([0.0, 0.0, 2.0]) - 0.1444).abs() < 1e-6);
    }

    #[test]
    fn energy_ratio_is_the_ratio_of_the_means_over_the_surface_pixels() {
        let reference = [1.0, 2.0, 3.0, 100.0];
        let test = [0.5, 1.0, 1.5, 0.0];
        // The last pixel is background: left out, so the ratio is (3 / 3) / (6 / 3).
        let mask = [true, true, true, false];
        let r = energy_ratio(&test, &reference, &mask).unwrap();
        assert!((r - 0.5).abs() < 1e-12, "{r}");
        // A sparse test image with the same total keeps the energy.
        let sparse = [0.0, 0.0, 6.0, 7.0];
        let r = energy_ratio(&sparse, &reference, &mask).unwrap();
        assert!((r - 1.0).abs() < 1e-12, "{r}");
        // Over every pixel the background counts.
        let r = energy_ratio(&test, &reference, &[true; 4]).unwrap();
        assert!((r - 3.0 / 106.0).abs() < 1e-12, "{r}");
    }

    #[test]
    fn energy_ratio_is_undefined_without_reference_energy_or_pixels() {
        assert_eq!(energy_ratio(&[0.3, 0.1], &[0.0, 0.0], &[true; 2]), None);
        assert_eq!(energy_ratio(&[0.3, 0.1], &[1e-9, 0.0], &[true; 2]), None);
        assert_eq!(energy_ratio(&[0.3, 0.1], &[1.0, 1.0], &[false; 2]), None);
        // Non-finite test values count as 0, as in the reference's accumulation.
        let r = energy_ratio(&[f32::NAN, 2.0], &[1.0, 1.0], &[true; 2]).unwrap();
        assert!((r - 1.0).abs() < 1e-12, "{r}");
    }

    #[test]
    fn flicker_is_the_mean_absolute_change_over_the_surface_pixels() {
        let previous = [0.5, 0.5, 0.5, 0.0];
        let current = [0.7, 0.3, 0.5, 9.0];
        let mask = [true, true, true, false];
        let f = flicker(&current, &previous, &mask).unwrap();
        assert!((f - 0.4 / 3.0).abs() < 1e-7, "{f}");
        assert_eq!(flicker(&current, &current, &mask), Some(0.0));
        assert_eq!(flicker(&current, &previous, &[false; 4]), None);
    }

    #[test]
    fn ratio_refuses_a_zero_denominator() {
        assert_eq!(ratio(1.0, 0.0), None);
        assert_eq!(ratio(1.0, f64::NAN), None);
        assert_eq!(ratio(3.0, 2.0), Some(1.5));
    }
}
