//! The specular pass's ray distribution against the analytic GGX one: the reflected directions
//! of many pixels, read back as hit distances to a ceiling (cos θ of the ray = height / t), are
//! binned and compared with the distribution of `reflect(−v, h)` for half-vectors drawn from the
//! visible normals of GGX (Heitz 2018: D_v(h) = G1(v) · max(0, v·h) · D(h) / v.z, so
//! p(l) = D_v(h) / (4 v·h)), with the documented fallback of rays below the surface to the
//! mirror direction. A chi-square bound over equiprobable bins rejects a wrong lobe (α for α², α
//! squared again) by thousands.

use super::radiance::{run_cached, specular};
use super::*;
use std::f64::consts::PI;

/// Side of the image; every pixel is the same surface point, so each traces one sample.
const SIDE: u32 = 64;
/// Frames (frame indices) per configuration: `SIDE² × FRAMES` samples.
const FRAMES: u32 = 16;
/// Height of the ceiling above the surface point.
const CEILING: f32 = 1.0;
/// Cells of cos θ over [0, 1] on which the oracle is integrated.
const CELLS: usize = 2000;
/// Equiprobable bins of the chi-square statistic.
const BINS: usize = 32;

/// GGX normal distribution of a half-vector with cos θ_h = `hz`.
fn ggx_d(hz: f64, a: f64) -> f64 {
    let a2 = a * a;
    let k = hz * hz * (a2 - 1.0) + 1.0;
    a2 / (PI * k * k)
}

/// Smith's masking of GGX for a direction with cos θ = `z`.
fn ggx_g1(z: f64, a: f64) -> f64 {
    2.0 * z / (z + (a * a + (1.0 - a * a) * z * z).sqrt())
}

/// The probability of each cell of cos θ_l (cells of width 1 / CELLS over [0, 1]) for the
/// reflection about a GGX visible normal of the view `v` (tangent frame, z up), roughness² = `a`;
/// the directions below the surface go to the mirror direction's cell. Midpoint rule over
/// (cos θ_l, φ_l); the pdf is symmetric in φ about v's plane.
fn oracle(v: glam::DVec3, a: f64) -> Vec<f64> {
    const PHI: usize = 720;
    let dphi = PI / PHI as f64;
    let dz = 1.0 / CELLS as f64;
    let mut cells = vec![0.0; CELLS];
    for (i, cell) in cells.iter_mut().enumerate() {
        let z = (i as f64 + 0.5) * dz;
        let s = (1.0 - z * z).sqrt();
        let mut sum = 0.0;
        for j in 0..PHI {
            let phi = (j as f64 + 0.5) * dphi;
            let l = glam::DVec3::new(s * phi.cos(), s * phi.sin(), z);
            let h = (v + l).normalize();
            let vh = v.dot(h);
            if h.z <= 0.0 || vh <= 0.0 {
                continue;
            }
            let dv = ggx_g1(v.z, a) * vh * ggx_d(h.z, a) / v.z;
            sum += dv / (4.0 * vh);
        }
        *cell = 2.0 * sum * dphi * dz;
    }
    let above: f64 = cells.iter().sum();
    assert!(
        above < 1.01,
        "the oracle integrates to {above} over the upper hemisphere"
    );
    let mirror = ((v.z * CELLS as f64) as usize).min(CELLS - 1);
    cells[mirror] += (1.0 - above).max(0.0);
    cells
}

/// The cells at which about `BINS` equiprobable bins of `cells` end (exclusive), the last at
/// CELLS; a cell holding several bins' probability (the mirror direction's) is one bin.
fn bin_ends(cells: &[f64]) -> Vec<usize> {
    let mut ends = Vec::new();
    let mut acc = 0.0;
    let mut next = 1;
    for (i, p) in cells.iter().enumerate() {
        acc += p;
        if next < BINS && acc >= next as f64 / BINS as f64 {
            ends.push(i + 1);
            while next < BINS && acc >= next as f64 / BINS as f64 {
                next += 1;
            }
        }
    }
    if ends.last() != Some(&CELLS) {
        ends.push(CELLS);
    }
    ends
}

/// Each bin's observed and expected counts, from the sample cells' counts and the
/// probabilities `cells`, over `ends`' bins.
fn bins(counts: &[u32], cells: &[f64], ends: &[usize]) -> Vec<(f64, f64)> {
    let n: u32 = counts.iter().sum();
    let mut start = 0;
    let mut out = Vec::new();
    for &end in ends {
        let observed: u32 = counts[start..end].iter().sum();
        let expected = n as f64 * cells[start..end].iter().sum::<f64>();
        assert!(expected >= 5.0, "bin {start}..{end}: {expected} expected");
        out.push((observed as f64, expected));
        start = end;
    }
    out
}

/// Pearson's chi-square of the bins.
fn chi_square(bins: &[(f64, f64)]) -> f64 {
    bins.iter().map(|(o, e)| (o - e).powi(2) / e).sum()
}

/// The largest error of a bin's count, relative to the count of an equiprobable bin (the bin
/// of the mirror direction, which holds the rays below the surface too, may be larger).
fn worst_bin(bins: &[(f64, f64)]) -> f64 {
    let full = bins.iter().map(|(_, e)| e).sum::<f64>() / BINS as f64;
    bins.iter()
        .map(|(o, e)| (o - e).abs() / full)
        .fold(0.0, f64::max)
}

/// The cells of cos θ of the specular pass's rays: a surface point at the origin facing +y,
/// seen at `view_angle` from its normal, roughness `roughness`, a ceiling at y = CEILING.
fn sampled_cells(roughness: f32, view_angle: f32, rng: RandomNumberGenerator) -> Vec<u32> {
    let scene = TestScene::single(square(1, CEILING, 1000.0));
    let eye = 3.0 * Vec3::new(view_angle.sin(), view_angle.cos(), 0.0);
    let mut counts = vec![0u32; CELLS];
    for frame in 0..FRAMES {
        let out = output(SIDE, SIDE, -5.0);
        let mut c = common(gbuffer(SIDE, SIDE, |_, _| Some((Vec3::ZERO, Vec3::Y))), eye);
        // The origin stays on the surface point: cos θ = CEILING / t exactly.
        c.ray_offset.offset_type = RayOffsetType::Disabled;
        c.roughness.global_roughness = roughness;
        c.debug_parameters.random_number_generator = rng;
        c.debug_parameters.frame_index = frame;
        run_cached(&scene, &[vec![Vec3::ZERO; 2]], &[specular(c, &out)]);
        for v in read(&out) {
            let t = v[3];
            assert!(t >= CEILING * 0.999, "a ray hit at {t}, below the ceiling");
            let cos = (CEILING / t).min(1.0);
            counts[((cos * CELLS as f32) as usize).min(CELLS - 1)] += 1;
        }
    }
    counts
}

/// Xorshift draws independent samples: Pearson's chi-square applies. Blue noise (the default)
/// does not (each frame is one tile's pairs of numbers, translated): its bins must each be within
/// a few percent of the expected count instead.
#[test]
fn specular_rays_follow_the_ggx_visible_normal_distribution() {
    // At most 31 degrees of freedom: the chi-square exceeds 80 with probability about 3e-6.
    const CHI_BOUND: f64 = 80.0;
    // About 2000 samples a bin: an independent sample's bins are within 2.2 % (one standard
    // deviation); 15 % is about seven.
    const BIN_BOUND: f64 = 0.15;
    for rng in [
        RandomNumberGenerator::Xorshift,
        RandomNumberGenerator::BlueNoise,
    ] {
        for (roughness, degrees) in [(0.3f32, 0.0f32), (0.3, 60.0), (0.6, 30.0), (0.9, 70.0)] {
            let angle = degrees.to_radians();
            let counts = sampled_cells(roughness, angle, rng);
            let v = glam::DVec3::new(angle.sin() as f64, 0.0, angle.cos() as f64);
            let alpha = (roughness * roughness) as f64;
            let want = oracle(v, alpha);
            let ends = bin_ends(&want);
            let got = bins(&counts, &want, &ends);
            // The same samples against the lobes of the usual mistakes: the test can tell them.
            let as_alpha = bins(&counts, &oracle(v, roughness as f64), &ends);
            let squared_twice = bins(&counts, &oracle(v, alpha * alpha), &ends);
            let what = format!("{rng:?} roughness {roughness}, view {degrees}°");
            eprintln!(
                "{what}: chi-square {:.1}, worst bin {:.3} over {} bins (roughness as α: {:.0}, \
                 {:.3}; α²: {:.0}, {:.3})",
                chi_square(&got),
                worst_bin(&got),
                ends.len(),
                chi_square(&as_alpha),
                worst_bin(&as_alpha),
                chi_square(&squared_twice),
                worst_bin(&squared_twice),
            );
            if rng == RandomNumberGenerator::Xorshift {
                let chi = chi_square(&got);
                assert!(
                    chi < CHI_BOUND,
                    "{what}: the specular rays' cos θ is not GGX's (chi-square {chi:.1} over {} \
                     bins)",
                    ends.len()
                );
                for wrong in [&as_alpha, &squared_twice] {
                    assert!(
                        chi_square(wrong) > 3.0 * CHI_BOUND,
                        "{what}: a wrong lobe would pass ({:.1})",
                        chi_square(wrong)
                    );
                }
            } else {
                let worst = worst_bin(&got);
                assert!(
                    worst < BIN_BOUND,
                    "{what}: the specular rays' cos θ is not GGX's (a bin off by {worst:.3})"
                );
                for wrong in [&as_alpha, &squared_twice] {
                    assert!(
                        worst_bin(wrong) > 2.0 * BIN_BOUND,
                        "{what}: a wrong lobe would pass ({:.3})",
                        worst_bin(wrong)
                    );
                }
            }
        }
    }
}
