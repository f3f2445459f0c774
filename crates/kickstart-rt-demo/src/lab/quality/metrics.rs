//! PSNR and FLIP between a test image and a reference, both computed on the **tone-mapped 8-bit
//! sRGB** images, so that noise in the dark and in highlights counts as a viewer sees it.
//!
//! Tone mapping (fixed, never adapted per image, so numbers compare across frames and runs):
//! linear HDR radiance × [`EXPOSURE`], then Reinhard per channel `c / (1 + c)`, then the sRGB
//! transfer function, rounded to 8 bits.
//!
//! FLIP follows Andersson et al. 2020, "FLIP: A Difference Evaluator for Alternating Images"
//! (our implementation from the paper): opponent colour space YCxCz, spatial filtering by the
//! contrast sensitivity functions (sums of Gaussians, at [`PIXELS_PER_DEGREE`]), Hunt-adjusted
//! L*a*b*, HyAB distance compressed and redistributed, and edge/point feature differences from
//! Gaussian derivative filters of the luminance. The result is the mean per-pixel error in
//! [0, 1]: 0 for identical images.

/// Exposure applied to linear radiance before tone mapping.
pub const EXPOSURE: f32 = 1.0;

/// Viewing condition of FLIP: 0.7 m from a 0.7 m wide 4K monitor (the paper's default, 67 ppd).
pub const PIXELS_PER_DEGREE: f32 = 67.0;

/// An 8-bit sRGB image, RGB, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Srgb8 {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// `width × height` RGB triplets.
    pub pixels: Vec<[u8; 3]>,
}

fn srgb_encode(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        12.92 * c
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

fn srgb_decode(c: f32) -> f32 {
    if c <= 0.040_45 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Tone maps linear HDR RGB (row-major, `width × height`) to 8-bit sRGB with the fixed exposure.
/// NaN and negative values map to black, +∞ to white.
pub fn tone_map(width: u32, height: u32, linear: &[[f32; 3]]) -> Srgb8 {
    let map = |c: f32| {
        let c = if c.is_nan() {
            0.0
        } else {
            (c * EXPOSURE).max(0.0)
        };
        let t = if c.is_infinite() { 1.0 } else { c / (1.0 + c) };
        (srgb_encode(t) * 255.0).round().clamp(0.0, 255.0) as u8
    };
    Srgb8 {
        width,
        height,
        pixels: linear.iter().map(|p| p.map(map)).collect(),
    }
}

fn check_sizes(a: &Srgb8, b: &Srgb8) -> Result<(), String> {
    if a.width != b.width || a.height != b.height || a.pixels.len() != b.pixels.len() {
        return Err(format!(
            "images differ in size: {}×{} and {}×{}",
            a.width, a.height, b.width, b.height
        ));
    }
    if a.pixels.len() != (a.width * a.height) as usize || a.pixels.is_empty() {
        return Err(format!(
            "{} pixels for a {}×{} image",
            a.pixels.len(),
            a.width,
            a.height
        ));
    }
    Ok(())
}

/// Mean squared error over the RGB channels, in 8-bit levels squared.
pub fn mse(test: &Srgb8, reference: &Srgb8) -> Result<f64, String> {
    check_sizes(test, reference)?;
    let mut sum = 0.0f64;
    for (a, b) in test.pixels.iter().zip(&reference.pixels) {
        for k in 0..3 {
            let d = a[k] as f64 - b[k] as f64;
            sum += d * d;
        }
    }
    Ok(sum / (test.pixels.len() * 3) as f64)
}

/// The PSNR in dB (peak 255) of a mean squared error `mse` in 8-bit levels squared;
/// `f64::INFINITY` for 0.
pub fn psnr_of_mse(mse: f64) -> f64 {
    if mse <= 0.0 {
        return f64::INFINITY;
    }
    10.0 * (255.0 * 255.0 / mse).log10()
}

/// The mean squared error (8-bit levels squared) of a PSNR `psnr` in dB (peak 255).
pub fn mse_of_psnr(psnr: f64) -> f64 {
    255.0 * 255.0 / 10f64.powf(psnr / 10.0)
}

/// PSNR in dB (peak 255) over the RGB channels; `f64::INFINITY` for identical images.
pub fn psnr(test: &Srgb8, reference: &Srgb8) -> Result<f64, String> {
    Ok(psnr_of_mse(mse(test, reference)?))
}

/// A float image of one channel.
struct Plane {
    w: usize,
    h: usize,
    v: Vec<f32>,
}

impl Plane {
    fn at(&self, x: isize, y: isize) -> f32 {
        // Clamp-to-edge sampling.
        let x = x.clamp(0, self.w as isize - 1) as usize;
        let y = y.clamp(0, self.h as isize - 1) as usize;
        self.v[y * self.w + x]
    }

    /// Separable convolution with `kx` along x and `ky` along y (both centred).
    fn convolve(&self, kx: &[f32], ky: &[f32]) -> Plane {
        let rx = (kx.len() / 2) as isize;
        let ry = (ky.len() / 2) as isize;
        let mut tmp = vec![0.0; self.v.len()];
        for y in 0..self.h {
            for x in 0..self.w {
                tmp[y * self.w + x] = kx
                    .iter()
                    .enumerate()
                    .map(|(i, k)| k * self.at(x as isize + i as isize - rx, y as isize))
                    .sum();
            }
        }
        let t = Plane {
            w: self.w,
            h: self.h,
            v: tmp,
        };
        let mut out = vec![0.0; self.v.len()];
        for y in 0..self.h {
            for x in 0..self.w {
                out[y * self.w + x] = ky
                    .iter()
                    .enumerate()
                    .map(|(i, k)| k * t.at(x as isize, y as isize + i as isize - ry))
                    .sum();
            }
        }
        Plane {
            w: self.w,
            h: self.h,
            v: out,
        }
    }
}

/// 1-D samples of exp(−π² x² / b) at pixel spacing (x in degrees), radius `r` pixels.
fn gaussian_1d(b: f32, r: isize) -> Vec<f32> {
    let pi2 = std::f32::consts::PI * std::f32::consts::PI;
    (-r..=r)
        .map(|i| {
            let x = i as f32 / PIXELS_PER_DEGREE;
            (-pi2 * x * x / b).exp()
        })
        .collect()
}

/// Filters a YCxCz channel with its contrast sensitivity function
/// a1·√(π/b1)·exp(−π²x²/b1) + a2·√(π/b2)·exp(−π²x²/b2), normalised to sum 1.
fn csf_filter(p: &Plane, (a1, b1, a2, b2): (f32, f32, f32, f32)) -> Plane {
    let pi = std::f32::consts::PI;
    let r = (3.0 * (b1.max(b2) / (2.0 * pi * pi)).sqrt() * PIXELS_PER_DEGREE).ceil() as isize;
    let mut parts = Vec::new();
    for (a, b) in [(a1, b1), (a2, b2)] {
        if a == 0.0 {
            continue;
        }
        let g = gaussian_1d(b, r);
        let s: f32 = g.iter().sum();
        parts.push((a * (pi / b).sqrt(), g, s * s));
    }
    let total: f32 = parts.iter().map(|(w, _, s2)| w * s2).sum();
    let mut out = vec![0.0; p.v.len()];
    for (w, g, _) in &parts {
        let f = p.convolve(g, g);
        for (o, v) in out.iter_mut().zip(f.v) {
            *o += w * v / total;
        }
    }
    Plane {
        w: p.w,
        h: p.h,
        v: out,
    }
}

fn linear_rgb_to_xyz(c: [f32; 3]) -> [f32; 3] {
    [
        0.412_456_4 * c[0] + 0.357_576_1 * c[1] + 0.180_437_5 * c[2],
        0.212_672_9 * c[0] + 0.715_152_2 * c[1] + 0.072_175 * c[2],
        0.019_333_9 * c[0] + 0.119_192 * c[1] + 0.950_304_1 * c[2],
    ]
}

fn xyz_to_linear_rgb(c: [f32; 3]) -> [f32; 3] {
    [
        3.240_454_2 * c[0] - 1.537_138_5 * c[1] - 0.498_531_4 * c[2],
        -0.969_266 * c[0] + 1.876_010_8 * c[1] + 0.041_556 * c[2],
        0.055_643_4 * c[0] - 0.204_025_9 * c[1] + 1.057_225_2 * c[2],
    ]
}

/// D65 white of `linear_rgb_to_xyz([1, 1, 1])`.
fn white() -> [f32; 3] {
    linear_rgb_to_xyz([1.0, 1.0, 1.0])
}

fn xyz_to_ycxcz(c: [f32; 3]) -> [f32; 3] {
    let w = white();
    let (x, y, z) = (c[0] / w[0], c[1] / w[1], c[2] / w[2]);
    [116.0 * y - 16.0, 500.0 * (x - y), 200.0 * (y - z)]
}

fn ycxcz_to_xyz(c: [f32; 3]) -> [f32; 3] {
    let w = white();
    let y = (c[0] + 16.0) / 116.0;
    let x = c[1] / 500.0 + y;
    let z = y - c[2] / 200.0;
    [x * w[0], y * w[1], z * w[2]]
}

fn xyz_to_lab(c: [f32; 3]) -> [f32; 3] {
    let w = white();
    let f = |t: f32| {
        let d = 6.0f32 / 29.0;
        if t > d * d * d {
            t.cbrt()
        } else {
            t / (3.0 * d * d) + 4.0 / 29.0
        }
    };
    let (fx, fy, fz) = (f(c[0] / w[0]), f(c[1] / w[1]), f(c[2] / w[2]));
    [116.0 * fy - 16.0, 500.0 * (fx - fy), 200.0 * (fy - fz)]
}

/// Hunt-adjusted L*a*b* of linear RGB in [0, 1].
fn hunt_lab(rgb: [f32; 3]) -> [f32; 3] {
    let l = xyz_to_lab(linear_rgb_to_xyz(rgb));
    [l[0], 0.01 * l[0] * l[1], 0.01 * l[0] * l[2]]
}

fn hyab(a: [f32; 3], b: [f32; 3]) -> f32 {
    (a[0] - b[0]).abs() + ((a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The image's CSF-filtered, Hunt-adjusted L*a*b* and its normalised luminance.
fn prepare(img: &Srgb8) -> (Vec<[f32; 3]>, Plane) {
    let (w, h) = (img.width as usize, img.height as usize);
    let ycc: Vec<[f32; 3]> = img
        .pixels
        .iter()
        .map(|p| xyz_to_ycxcz(linear_rgb_to_xyz(p.map(|c| srgb_decode(c as f32 / 255.0)))))
        .collect();
    let csf = [
        (1.0, 0.0047, 0.0, 1e-5),
        (1.0, 0.0053, 0.0, 1e-5),
        (34.1, 0.04, 13.5, 0.025),
    ];
    let filtered: Vec<Plane> = (0..3)
        .map(|k| {
            let p = Plane {
                w,
                h,
                v: ycc.iter().map(|c| c[k]).collect(),
            };
            csf_filter(&p, csf[k])
        })
        .collect();
    let lab = (0..w * h)
        .map(|i| {
            let c = [filtered[0].v[i], filtered[1].v[i], filtered[2].v[i]];
            let rgb = xyz_to_linear_rgb(ycxcz_to_xyz(c)).map(|v| v.clamp(0.0, 1.0));
            hunt_lab(rgb)
        })
        .collect();
    // Feature detection works on the luminance of YCxCz, normalised to [0, 1].
    let lum = Plane {
        w,
        h,
        v: ycc.iter().map(|c| (c[0] + 16.0) / 116.0).collect(),
    };
    (lab, lum)
}

/// Edge (first derivative) and point (second derivative) strength of the luminance, from
/// Gaussian derivative filters of standard deviation 0.5 × 0.082° (FLIP's feature width).
fn features(lum: &Plane) -> (Vec<f32>, Vec<f32>) {
    let sd = 0.5 * 0.082 * PIXELS_PER_DEGREE;
    let r = (3.0 * sd).ceil() as isize;
    let g: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f32 / (2.0 * sd * sd)).exp())
        .collect();
    let gsum: f32 = g.iter().sum();
    let g: Vec<f32> = g.iter().map(|v| v / gsum).collect();
    let d1: Vec<f32> = (-r..=r).zip(&g).map(|(i, v)| -(i as f32) * v).collect();
    let d2: Vec<f32> = (-r..=r)
        .zip(&g)
        .map(|(i, v)| ((i * i) as f32 / (sd * sd) - 1.0) * v)
        .collect();
    // Normalise the derivative kernels: positive parts sum to 1 (as FLIP does).
    let norm = |k: Vec<f32>| {
        let pos: f32 = k.iter().filter(|v| **v > 0.0).sum();
        let neg: f32 = -k.iter().filter(|v| **v < 0.0).sum::<f32>();
        k.into_iter()
            .map(|v| if v > 0.0 { v / pos } else { v / neg })
            .collect::<Vec<f32>>()
    };
    let (d1, d2) = (norm(d1), norm(d2));
    let ex = lum.convolve(&d1, &g);
    let ey = lum.convolve(&g, &d1);
    let px = lum.convolve(&d2, &g);
    let py = lum.convolve(&g, &d2);
    let edge = ex.v.iter().zip(&ey.v).map(|(a, b)| a.hypot(*b)).collect();
    let point = px.v.iter().zip(&py.v).map(|(a, b)| a.hypot(*b)).collect();
    (edge, point)
}

/// Mean FLIP error in [0, 1] of `test` against `reference` (0: identical).
pub fn flip(test: &Srgb8, reference: &Srgb8) -> Result<f64, String> {
    check_sizes(test, reference)?;
    let (qc, pc, pt, qf) = (0.7f32, 0.4f32, 0.95f32, 0.5f32);
    let (lab_t, lum_t) = prepare(test);
    let (lab_r, lum_r) = prepare(reference);
    let cmax = hyab(hunt_lab([0.0, 1.0, 0.0]), hunt_lab([0.0, 0.0, 1.0])).powf(qc);
    let (edge_t, point_t) = features(&lum_t);
    let (edge_r, point_r) = features(&lum_r);
    let mut sum = 0.0f64;
    for i in 0..lab_t.len() {
        let d = hyab(lab_t[i], lab_r[i]).powf(qc);
        let colour = if d < pc * cmax {
            d * pt / (pc * cmax)
        } else {
            pt + (d - pc * cmax) / (cmax - pc * cmax) * (1.0 - pt)
        };
        let feature = ((edge_t[i] - edge_r[i])
            .abs()
            .max((point_t[i] - point_r[i]).abs())
            / std::f32::consts::SQRT_2)
            .min(1.0)
            .powf(qf);
        sum += colour.clamp(0.0, 1.0).powf(1.0 - feature) as f64;
    }
    Ok(sum / lab_t.len() as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) -> Srgb8 {
        Srgb8 {
            width: w,
            height: h,
            pixels: (0..h)
                .flat_map(|y| (0..w).map(move |x| (x, y)))
                .map(|(x, y)| f(x, y))
                .collect(),
        }
    }

    #[test]
    fn identical_images_give_infinite_psnr_and_zero_flip() {
        let a = image(24, 16, |x, y| [(x * 10) as u8, (y * 15) as u8, 77]);
        assert_eq!(psnr(&a, &a), Ok(f64::INFINITY));
        assert_eq!(flip(&a, &a), Ok(0.0));
    }

    #[test]
    fn psnr_of_known_noise() {
        // Every channel off by ±8: MSE 64, PSNR = 10·log10(255² / 64) = 30.07 dB.
        let a = image(16, 16, |_, _| [128; 3]);
        let b = image(16, 16, |x, y| [if (x + y) % 2 == 0 { 136 } else { 120 }; 3]);
        let p = psnr(&b, &a).unwrap();
        assert!(
            (p - 10.0 * (255.0f64 * 255.0 / 64.0).log10()).abs() < 1e-9,
            "{p}"
        );
    }

    #[test]
    fn flip_grows_with_the_error_and_is_at_most_one() {
        let a = image(32, 32, |_, _| [100; 3]);
        let noisy = |amp: i32| {
            image(32, 32, |x, y| {
                let s = if (x * 7 + y * 13) % 3 == 0 { amp } else { -amp };
                [(100 + s).clamp(0, 255) as u8; 3]
            })
        };
        let small = flip(&noisy(5), &a).unwrap();
        let large = flip(&noisy(60), &a).unwrap();
        let black_white = flip(
            &image(32, 32, |_, _| [0; 3]),
            &image(32, 32, |_, _| [255; 3]),
        )
        .unwrap();
        assert!(0.0 < small && small < large, "{small} {large}");
        assert!(
            large < black_white && black_white <= 1.0,
            "{large} {black_white}"
        );
        assert!(black_white > 0.8, "black against white: {black_white}");
    }

    #[test]
    fn tone_map_is_fixed_and_handles_non_finite_values() {
        let img = tone_map(
            4,
            1,
            &[
                [0.0; 3],
                [1.0; 3],
                [f32::NAN, -1.0, f32::INFINITY],
                [1e9; 3],
            ],
        );
        assert_eq!(img.pixels[0], [0; 3]);
        // 1 → Reinhard 0.5 → sRGB 0.7354 → 188.
        assert_eq!(img.pixels[1], [188; 3]);
        assert_eq!(img.pixels[2], [0, 0, 255]);
        assert_eq!(img.pixels[3], [255; 3]);
    }

    #[test]
    fn size_mismatch_is_an_error() {
        let a = image(4, 4, |_, _| [0; 3]);
        let b = image(4, 5, |_, _| [0; 3]);
        assert!(psnr(&a, &b).is_err());
        assert!(flip(&a, &b).is_err());
    }
}
