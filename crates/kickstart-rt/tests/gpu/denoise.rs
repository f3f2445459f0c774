//! The denoisers on synthetic inputs: an analytic scene's G-buffer, a converged reference signal
//! and noisy inputs (reference × per-pixel noise of mean 1, new every frame). What the denoisers
//! must do: converge, keep edges, smooth flat walls, restart at camera cuts, follow moving
//! objects, keep hard and soft shadows, take checkerboard input; plus the contexts' memory and
//! validation.

use crate::common;

use common::denoise::*;
use common::rt::Rng;
use common::*;
use glam::{Vec3, Vec4};
use kickstart_rt::*;

const EYE: Vec3 = Vec3::new(0.3, 1.6, 2.6);

/// A 4-sample sub-pixel jitter pattern (pixels), as TAA cycles through.
const JITTER: [glam::Vec2; 4] = [
    glam::Vec2::new(0.25, -0.25),
    glam::Vec2::new(-0.25, 0.25),
    glam::Vec2::new(-0.25, -0.25),
    glam::Vec2::new(0.25, 0.25),
];

fn static_gbuffer() -> GBuffer {
    gbuffer(EYE, Vec3::ZERO, EYE, Vec3::ZERO)
}

/// PSNR per signal per frame, the last frame's outputs, and the last noisy inputs' PSNR.
struct StaticRun {
    psnrs: Vec<Vec<f64>>,
    last: Vec<Vec<Vec4>>,
    noisy: Vec<f64>,
}

fn run_static(
    signal: SignalType,
    method: DenoisingMethod,
    frames: u32,
    refs: &[Vec<Vec4>],
    seed: u64,
) -> StaticRun {
    let g = static_gbuffer();
    let h = Harness::new(signal, method);
    let mut rng = Rng(seed);
    let mut psnrs = vec![Vec::new(); refs.len()];
    let mut noisy_psnr = vec![0.0; refs.len()];
    let mut last = Vec::new();
    for _ in 0..frames {
        let inputs: Vec<Vec<Vec4>> = refs.iter().map(|r| noisy(r, &mut rng)).collect();
        for (k, r) in refs.iter().enumerate() {
            noisy_psnr[k] = psnr(&g, &inputs[k], r);
        }
        last = h.frame(&g, &inputs, Motion::Matrices, DenoiseMode::Continue);
        for (k, r) in refs.iter().enumerate() {
            psnrs[k].push(psnr(&g, &last[k], r));
        }
    }
    StaticRun {
        psnrs,
        last,
        noisy: noisy_psnr,
    }
}

fn assert_converges(name: &str, psnrs: &[f64], noisy: f64) {
    eprintln!("{name}: noisy {noisy:.2} dB, denoised {psnrs:.2?}");
    for k in 1..psnrs.len() {
        assert!(
            psnrs[k] >= psnrs[k - 1] - 0.3,
            "{name}: error rose from frame {} to {}: {psnrs:.2?}",
            k - 1,
            k
        );
    }
    let last = psnrs[psnrs.len() - 1];
    assert!(
        last >= noisy + 10.0,
        "{name}: {last:.2} dB after {} frames, noisy input {noisy:.2} dB",
        psnrs.len()
    );
}

#[test]
fn static_camera_error_falls_and_ends_10db_better() {
    let g = static_gbuffer();
    let diffuse = reference_image(&g, reference);
    let StaticRun { psnrs, noisy, .. } = run_static(
        SignalType::Diffuse,
        DenoisingMethod::HighQuality,
        16,
        std::slice::from_ref(&diffuse),
        1,
    );
    assert_converges("diffuse (high quality)", &psnrs[0], noisy[0]);
}

/// A sparse 1-spp signal — most samples 0, one in ten 10× the mean (diffuse GI lit by rare
/// bright hits) — keeps most of its energy: clamping the rare samples (as fireflies, or the
/// history to a 3×3 neighbourhood that is all zeros) darkens it frame after frame.
#[test]
fn sparse_signal_keeps_its_energy() {
    let g = static_gbuffer();
    let r = reference_image(&g, reference);
    let h = Harness::new(SignalType::Diffuse, DenoisingMethod::HighQuality);
    let mut rng = Rng(21);
    let mut out = Vec::new();
    let mut noisy_psnr = 0.0;
    for _ in 0..32 {
        let input: Vec<Vec4> = r
            .iter()
            .map(|v| {
                let k = if rng.f() < 0.1 { 10.0 } else { 0.0 };
                (v.truncate() * k).extend(v.w)
            })
            .collect();
        noisy_psnr = psnr(&g, &input, &r);
        out = h
            .frame(&g, &[input], Motion::Matrices, DenoiseMode::Continue)
            .remove(0);
    }
    let (mut sum_out, mut sum_ref) = (0.0f64, 0.0f64);
    for (i, s) in g.surfaces.iter().enumerate() {
        if s.is_some() {
            sum_out += out[i].truncate().element_sum() as f64;
            sum_ref += r[i].truncate().element_sum() as f64;
        }
    }
    let ratio = sum_out / sum_ref;
    let p = psnr(&g, &out, &r);
    eprintln!("sparse: denoised/reference energy {ratio:.3}, {p:.2} dB (noisy {noisy_psnr:.2} dB)");
    // The temporal pass clamps no sample as a firefly and the à-trous luminance weight is
    // symmetric: the rare samples' energy is spread, not dropped (0.78 with the centre's noise
    // alone in the weight).
    assert!(
        (0.9..=1.1).contains(&ratio),
        "the denoised sparse signal holds {ratio:.3} of the reference's energy"
    );
    assert!(p > noisy_psnr + 10.0, "{p:.2} dB, noisy {noisy_psnr:.2} dB");
}

/// Bounce light through a small window: 1 sample in 100 carries the whole signal (× 100), the
/// others are 0. Every frame from the 8th keeps the reference's energy within 15 % (the input's
/// own sampling noise is a few %), the last within 10 %: no pass may treat the rare samples as
/// outliers (with a firefly clamp and a one-sided luminance weight the output kept 6 %).
#[test]
fn very_sparse_signal_keeps_its_energy_every_frame() {
    let g = static_gbuffer();
    let r = reference_image(&g, reference);
    let energy = |img: &[Vec4]| -> f64 {
        let mut sum = 0.0f64;
        for (i, s) in g.surfaces.iter().enumerate() {
            if s.is_some() {
                sum += img[i].truncate().element_sum() as f64;
            }
        }
        sum
    };
    let want = energy(&r);
    for method in [DenoisingMethod::HighQuality, DenoisingMethod::Fast] {
        let h = Harness::new(SignalType::Diffuse, method);
        let mut rng = Rng(21);
        let mut ratios = Vec::new();
        for _ in 0..32 {
            let input: Vec<Vec4> = r
                .iter()
                .map(|v| {
                    let k = if rng.f() < 0.01 { 100.0 } else { 0.0 };
                    (v.truncate() * k).extend(v.w)
                })
                .collect();
            let out = h
                .frame(&g, &[input], Motion::Matrices, DenoiseMode::Continue)
                .remove(0);
            ratios.push(energy(&out) / want);
        }
        eprintln!("{method:?}: energy ratio per frame {ratios:.3?}");
        for (f, q) in ratios.iter().enumerate().skip(7) {
            assert!(
                (0.85..=1.15).contains(q),
                "{method:?} frame {f}: the denoised signal holds {q:.3} of the energy"
            );
        }
        let last = ratios[31];
        assert!(
            (0.9..=1.1).contains(&last),
            "{method:?}: last frame {last:.3}"
        );
    }
}

#[test]
fn jittered_camera_converges() {
    // A static camera whose projection is jittered by a 4-sample pattern (as for TAA); the
    // G-buffer is rendered jittered, and the denoiser compensates with ViewInfo::jitter.
    let h = Harness::new(SignalType::Diffuse, DenoisingMethod::HighQuality);
    let mut rng = Rng(13);
    let mut psnrs = Vec::new();
    let mut noisy_psnr = 0.0;
    for f in 0..16 {
        let g = gbuffer_jittered(EYE, Vec3::ZERO, EYE, Vec3::ZERO, JITTER[f % 4]);
        let r = reference_image(&g, reference);
        let input = noisy(&r, &mut rng);
        noisy_psnr = psnr(&g, &input, &r);
        let out = h.frame(&g, &[input], Motion::Matrices, DenoiseMode::Continue);
        psnrs.push(psnr(&g, &out[0], &r));
    }
    eprintln!("jittered: noisy {noisy_psnr:.2} dB, denoised {psnrs:.2?}");
    // Compensated, the history keeps accumulating (~26 dB better here); with the jitter applied
    // the wrong way round it stalls ~17 dB better, as the edges' history keeps being rejected.
    let last = psnrs[15];
    assert!(
        last >= noisy_psnr + 20.0,
        "{last:.2} dB, noisy {noisy_psnr:.2} dB"
    );
}

#[test]
fn fast_method_also_converges() {
    let g = static_gbuffer();
    let diffuse = reference_image(&g, reference);
    let StaticRun { psnrs, noisy, .. } = run_static(
        SignalType::Diffuse,
        DenoisingMethod::Fast,
        16,
        std::slice::from_ref(&diffuse),
        2,
    );
    assert_converges("diffuse (fast)", &psnrs[0], noisy[0]);
}

#[test]
fn specular_and_diffuse_denoise_both_signals_in_one_task() {
    let g = static_gbuffer();
    let diffuse = reference_image(&g, reference);
    // A second, different signal: the specular one is brighter on the wall and darker on the box.
    let specular = reference_image(&g, |s| {
        let r = reference(s);
        if s.object == 1 {
            Vec3::new(1.2, 1.0, 0.8) * (0.8 + 0.2 * s.position.x.cos())
        } else {
            Vec3::new(r.z, r.y, r.x) * 0.5
        }
    });
    let StaticRun { psnrs, noisy, .. } = run_static(
        SignalType::SpecularAndDiffuse,
        DenoisingMethod::HighQuality,
        16,
        &[specular, diffuse],
        3,
    );
    assert_converges("specular of SpecularAndDiffuse", &psnrs[0], noisy[0]);
    assert_converges("diffuse of SpecularAndDiffuse", &psnrs[1], noisy[1]);
}

/// SpecularAndDiffuse filters both signals in shared dispatches (one guide read for both): each
/// of its outputs must be what the one-signal task makes of the same input, frame after frame
/// (a dispatch that mixed up the two signals' records or weights would differ).
#[test]
fn specular_and_diffuse_task_matches_each_signal_alone() {
    let g = static_gbuffer();
    let diffuse = reference_image(&g, reference);
    let specular = reference_image(&g, |s| {
        let r = reference(s);
        Vec3::new(0.3 * r.y, 0.9 * r.z, 1.4 * r.x)
    });
    for method in [DenoisingMethod::Fast, DenoisingMethod::HighQuality] {
        let both = Harness::new(SignalType::SpecularAndDiffuse, method);
        let alone = [
            Harness::new(SignalType::Specular, method),
            Harness::new(SignalType::Diffuse, method),
        ];
        let mut rng = Rng(11);
        for frame in 0..4 {
            let inputs = [noisy(&specular, &mut rng), noisy(&diffuse, &mut rng)];
            let out = both.frame(&g, &inputs, Motion::Matrices, DenoiseMode::Continue);
            for (k, h) in alone.iter().enumerate() {
                let one = h.frame(&g, &inputs[k..=k], Motion::Matrices, DenoiseMode::Continue);
                let worst = out[k]
                    .iter()
                    .zip(&one[0])
                    .map(|(a, b)| (*a - *b).abs().max_element())
                    .fold(0.0f32, f32::max);
                assert!(
                    worst <= 1e-3,
                    "{method:?} frame {frame}: signal {k} of SpecularAndDiffuse differs from the \
                     one-signal task by {worst}"
                );
            }
            // The two signals differ, so equal outputs above are not one signal twice.
            let apart = out[0]
                .iter()
                .zip(&out[1])
                .map(|(a, b)| (*a - *b).abs().max_element())
                .fold(0.0f32, f32::max);
            assert!(
                apart > 0.1,
                "{method:?} frame {frame}: the outputs are alike ({apart})"
            );
        }
    }
}

#[test]
fn occlusion_converges() {
    let g = static_gbuffer();
    // Normalised hit distance: darker near the box's foot and the wall's corner.
    let ao = reference_image(&g, |s| {
        let to_box = (s.position.x.abs().max(s.position.z.abs()) - 0.5).max(0.0);
        let v = (0.4 + to_box).min(1.0) * (0.5 + 0.5 * (s.position.z + 2.0).min(1.0));
        Vec3::splat(v)
    });
    // Occlusion samples stay in [0, 1]: the reference ± uniform noise as wide as it can be.
    let h = Harness::new(SignalType::DiffuseOcclusion, DenoisingMethod::HighQuality);
    let mut rng = Rng(4);
    let mut psnrs = Vec::new();
    let mut noisy_psnr = 0.0;
    for _ in 0..16 {
        let input: Vec<Vec4> = ao
            .iter()
            .map(|r| {
                let a = r.x.min(1.0 - r.x);
                Vec4::splat(r.x + rng.range(-a, a))
            })
            .collect();
        noisy_psnr = psnr(&g, &input, &ao);
        let out = h.frame(&g, &[input], Motion::Matrices, DenoiseMode::Continue);
        psnrs.push(psnr(&g, &out[0], &ao));
    }
    assert_converges("occlusion", &psnrs, noisy_psnr);
}

/// Pixels whose 4-neighbourhood in `reference` changes by more than `step` (a depth or normal
/// discontinuity of the scene), with their neighbours.
fn edge_pixels(g: &GBuffer, reference: &[Vec4], step: f32) -> Vec<usize> {
    let s = SIZE as usize;
    let mut out = Vec::new();
    for y in 1..s - 1 {
        for x in 1..s - 1 {
            let i = y * s + x;
            if g.surfaces[i].is_none() {
                continue;
            }
            let c = reference[i].truncate();
            let jump = [i - 1, i + 1, i - s, i + s]
                .iter()
                .filter(|&&j| g.surfaces[j].is_some())
                .map(|&j| (reference[j].truncate() - c).abs().max_element())
                .fold(0.0f32, f32::max);
            if jump > step {
                out.push(i);
            }
        }
    }
    out
}

#[test]
fn edges_survive_depth_and_normal_discontinuities() {
    let g = static_gbuffer();
    let r = reference_image(&g, reference);
    let StaticRun { last, .. } = run_static(
        SignalType::Diffuse,
        DenoisingMethod::HighQuality,
        16,
        std::slice::from_ref(&r),
        5,
    );
    let out = &last[0];
    let edges = edge_pixels(&g, &r, 0.25);
    assert!(
        edges.len() > 40,
        "the scene has box edges and a wall corner: {}",
        edges.len()
    );
    // Across each edge the denoised image keeps the reference's step: the error of an edge pixel
    // stays a small part of the step (a blur across it would halve the step).
    let mut err = 0.0;
    for &i in &edges {
        err += (out[i].truncate() - r[i].truncate()).abs().max_element();
    }
    let mean_err = err / edges.len() as f32;
    eprintln!("edge pixels {}, mean error {mean_err:.4}", edges.len());
    assert!(
        mean_err < 0.08,
        "edges blurred: mean error {mean_err:.4} at {} edge pixels",
        edges.len()
    );
    // And the step itself: for each edge pixel pair of different objects or faces, the denoised
    // difference has the reference's sign and at least 70 % of its size.
    let s = SIZE as usize;
    let mut pairs = 0;
    let mut kept = 0;
    for &i in &edges {
        let j = i + 1;
        if g.surfaces[j].is_none() {
            continue;
        }
        let dr = r[j].truncate() - r[i].truncate();
        let k = dr.abs().max_position();
        if dr[k].abs() < 0.25 {
            continue;
        }
        pairs += 1;
        let dd = out[j][k] - out[i][k];
        if dd * dr[k].signum() >= 0.7 * dr[k].abs() {
            kept += 1;
        }
        let _ = s;
    }
    assert!(pairs > 10, "horizontal edge pairs: {pairs}");
    assert!(
        kept as f32 >= 0.9 * pairs as f32,
        "steps kept at {kept} of {pairs} horizontal edge pairs"
    );
}

#[test]
fn flat_uniform_wall_stays_flat() {
    let g = static_gbuffer();
    let flat = reference_image(&g, |_| Vec3::splat(0.5));
    let StaticRun { last, .. } = run_static(
        SignalType::Diffuse,
        DenoisingMethod::HighQuality,
        16,
        std::slice::from_ref(&flat),
        6,
    );
    let vals: Vec<f32> = g
        .surfaces
        .iter()
        .enumerate()
        .filter(|(_, s)| s.is_some())
        .map(|(i, _)| last[0][i].x)
        .collect();
    let mean = vals.iter().sum::<f32>() / vals.len() as f32;
    let sd = (vals.iter().map(|v| (v - mean) * (v - mean)).sum::<f32>() / vals.len() as f32).sqrt();
    let worst = vals.iter().map(|v| (v - 0.5).abs()).fold(0.0f32, f32::max);
    let worst_pixel = (0..last[0].len())
        .filter(|&i| g.surfaces[i].is_some())
        .max_by(|&a, &b| {
            (last[0][a].x - 0.5)
                .abs()
                .total_cmp(&(last[0][b].x - 0.5).abs())
        });
    eprintln!(
        "worst pixel {worst_pixel:?}: {:?}",
        worst_pixel.map(|i| g.surfaces[i])
    );
    eprintln!("flat: mean {mean:.4}, sd {sd:.4}, worst {worst:.4}");
    // The noisy input's standard deviation is 0.5/√3 ≈ 0.29.
    assert!((mean - 0.5).abs() < 0.01, "mean {mean}");
    assert!(sd < 0.02, "not flat: standard deviation {sd}");
    assert!(worst < 0.1, "a blotch of {worst}");
}

#[test]
fn discard_history_keeps_nothing_of_the_old_view() {
    let g = static_gbuffer();
    let h = Harness::new(SignalType::Diffuse, DenoisingMethod::HighQuality);
    let mut rng = Rng(7);
    let red = reference_image(&g, |_| Vec3::new(1.0, 0.0, 0.0));
    for _ in 0..8 {
        h.frame(
            &g,
            &[noisy(&red, &mut rng)],
            Motion::Matrices,
            DenoiseMode::Continue,
        );
    }
    // Camera cut to a view of the same geometry with another colour: green.
    let green = reference_image(&g, |_| Vec3::new(0.0, 1.0, 0.0));
    let out = h.frame(
        &g,
        &[noisy(&green, &mut rng)],
        Motion::Matrices,
        DenoiseMode::DiscardHistory,
    );
    let worst_red = out[0].iter().map(|v| v.x).fold(0.0f32, f32::max);
    assert_eq!(
        worst_red, 0.0,
        "a pixel kept the old view's red: {worst_red}"
    );
    // Without the discard, the history carries red into the frame (the test can fail).
    let h2 = Harness::new(SignalType::Diffuse, DenoisingMethod::HighQuality);
    let orange = reference_image(&g, |_| Vec3::new(1.0, 0.5, 0.0));
    for _ in 0..8 {
        h2.frame(
            &g,
            &[noisy(&red, &mut rng)],
            Motion::Matrices,
            DenoiseMode::Continue,
        );
    }
    let out = h2.frame(
        &g,
        &[noisy(&orange, &mut rng)],
        Motion::Matrices,
        DenoiseMode::Continue,
    );
    let mean_green = out[0].iter().map(|v| v.y).sum::<f32>() / out[0].len() as f32;
    assert!(
        mean_green < 0.45,
        "history was not used: mean green {mean_green}"
    );
}

/// The worst errors of a moving box's denoised image after 12 frames.
struct Trail {
    /// Over the floor and wall farther than 3 pixels from the box's silhouette: where the box
    /// was, the history must be dropped (disocclusion).
    off_box: f32,
    /// Over the box's own pixels farther than 3 pixels from the step between its halves and
    /// from its silhouette: the history must follow the box's surface, or the halves smear.
    on_box: f32,
}

/// The colour of the moving box at `s` with the box at `box_at`: bright on the half of lower x
/// (in the box's own frame), dark on the other, so that reusing the history of the screen pixel
/// instead of the surface point (motion vectors missing or zero) reads the other half.
fn two_tone_box(s: &common::denoise::Surface, box_at: Vec3) -> Vec3 {
    if s.object != 2 {
        return Vec3::splat(0.1);
    }
    if s.position.x < box_at.x {
        Vec3::splat(1.0)
    } else {
        Vec3::splat(0.2)
    }
}

/// Runs the two-tone box moving along +x by 0.08 world units (about 1.5 pixels) a frame over a
/// dark floor, noise-free, with the motion input `motion`; `zero_motion` writes zero motion
/// vectors instead of the true ones (the box then looks static to the denoiser).
fn trail_error(motion: Motion, zero_motion: bool) -> Trail {
    let h = Harness::new(SignalType::Diffuse, DenoisingMethod::HighQuality);
    let speed = 0.08;
    let mut prev_box = Vec3::new(-1.0, 0.0, 0.0);
    let mut last = (static_gbuffer(), Vec::new());
    for f in 0..12 {
        let box_at = Vec3::new(-1.0 + speed * f as f32, 0.0, 0.0);
        let mut g = gbuffer(EYE, box_at, EYE, prev_box);
        if zero_motion {
            g.world_motion.fill(Vec3::ZERO);
            g.uv_motion.fill(glam::Vec2::ZERO);
        }
        let r = reference_image(&g, |s| two_tone_box(s, box_at));
        let out = h.frame(&g, std::slice::from_ref(&r), motion, DenoiseMode::Continue);
        prev_box = box_at;
        last = (g, vec![r, out[0].clone()]);
    }
    let (g, imgs) = last;
    let (r, out) = (&imgs[0], &imgs[1]);
    let s = SIZE as i32;
    let at = |x: i32, y: i32| (x >= 0 && y >= 0 && x < s && y < s).then(|| (y * s + x) as usize);
    let is_box =
        |x: i32, y: i32| at(x, y).is_some_and(|i| g.surfaces[i].is_some_and(|q| q.object == 2));
    let mut trail = Trail {
        off_box: 0.0,
        on_box: 0.0,
    };
    let mut on_box_pixels = 0;
    for y in 0..s {
        for x in 0..s {
            let i = (y * s + x) as usize;
            let Some(surface) = g.surfaces[i] else {
                continue;
            };
            let err = (out[i] - r[i]).truncate().abs().max_element();
            if surface.object == 2 {
                // Away from the halves' step and the silhouette: resampling the history
                // bilinearly at a sub-pixel offset blends the two sides, and the history clamp
                // lets that blur reach 2 to 3 pixels past a moving step (up to 0.15 there).
                let flat = (-3..=3).all(|dy| {
                    (-3..=3).all(|dx| {
                        is_box(x + dx, y + dy) && at(x + dx, y + dy).is_some_and(|j| r[j] == r[i])
                    })
                });
                if flat {
                    on_box_pixels += 1;
                    trail.on_box = trail.on_box.max(err);
                }
                continue;
            }
            let near_box = (-3..=3).any(|dy| (-3..=3).any(|dx| is_box(x + dx, y + dy)));
            if !near_box {
                trail.off_box = trail.off_box.max(err);
            }
        }
    }
    assert!(
        on_box_pixels > 50,
        "the box shows {on_box_pixels} pixels inside its halves"
    );
    trail
}

/// A moving box leaves no trail on the floor behind it, and its own halves stay sharp: the
/// history follows the motion vectors. The same run with the motion vectors zeroed (or with
/// none, reprojecting with the matrices alone) must smear the halves, which shows the check can
/// see a trail.
#[test]
fn moving_object_leaves_no_trail() {
    for motion in [Motion::WorldSpace, Motion::ViewSpace] {
        let t = trail_error(motion, false);
        eprintln!(
            "{motion:?}: worst error off the box {:.4}, on its halves {:.4}",
            t.off_box, t.on_box
        );
        assert!(
            t.off_box < 0.05,
            "{motion:?}: a trail of {} behind the box (box 1.0 / 0.2 on floor 0.1)",
            t.off_box
        );
        assert!(
            t.on_box < 0.05,
            "{motion:?}: the box's halves smeared by {} (halves 1.0 / 0.2)",
            t.on_box
        );
        let zeroed = trail_error(motion, true);
        eprintln!(
            "{motion:?} with zero motion vectors: off the box {:.4}, on its halves {:.4}",
            zeroed.off_box, zeroed.on_box
        );
        assert!(
            zeroed.on_box > 0.3,
            "{motion:?}: zero motion vectors left the halves sharp ({}): the motion input \
             was not what kept them sharp",
            zeroed.on_box
        );
    }
    // Without motion vectors the matrices cannot tell that the box moved: its halves smear,
    // but the history where the box was is still dropped.
    let t = trail_error(Motion::Matrices, false);
    eprintln!(
        "Matrices: worst error off the box {:.4}, on its halves {:.4}",
        t.off_box, t.on_box
    );
    assert!(t.off_box < 0.05, "Matrices: a trail of {}", t.off_box);
    assert!(t.on_box > 0.3, "Matrices: halves sharp ({})", t.on_box);
}

/// Shadow trace output on the static scene for a light whose penumbra spans `width` world
/// units across x = 0.2 on the floor: negative (visible) or a hit distance of 0.5.
fn shadow_input(g: &GBuffer, width: f32, rng: &mut Rng) -> Vec<Vec4> {
    g.surfaces
        .iter()
        .map(|s| match s {
            None => Vec4::splat(-1.0),
            Some(s) => {
                let p = visibility(s.position.x, width);
                let v = if rng.f() < p { -1.0 } else { 0.5 };
                Vec4::new(v, 0.0, 0.0, 0.0)
            }
        })
        .collect()
}

fn visibility(x: f32, width: f32) -> f32 {
    if width == 0.0 {
        return if x < 0.2 { 1.0 } else { 0.0 };
    }
    ((0.2 + width / 2.0 - x) / width).clamp(0.0, 1.0)
}

fn run_shadow(width: f32, seed: u64) -> (GBuffer, Vec<Vec4>) {
    let g = static_gbuffer();
    let h = Harness::new(SignalType::Shadow, DenoisingMethod::HighQuality);
    let mut rng = Rng(seed);
    let mut out = Vec::new();
    for _ in 0..16 {
        out = h.frame(
            &g,
            &[shadow_input(&g, width, &mut rng)],
            Motion::Matrices,
            DenoiseMode::Continue,
        );
    }
    (g, out.remove(0))
}

#[test]
fn small_light_shadow_stays_hard() {
    let (g, out) = run_shadow(0.0, 8);
    let mut checked = 0;
    for (i, s) in g.surfaces.iter().enumerate() {
        let Some(s) = s else { continue };
        let want = visibility(s.position.x, 0.0);
        // Every pixel whose footprint does not straddle the edge keeps its exact visibility.
        let x = i % SIZE as usize;
        let straddles = [x.saturating_sub(1), (x + 1).min(SIZE as usize - 1)]
            .iter()
            .any(|&xx| {
                g.surfaces[i - x + xx].is_some_and(|q| visibility(q.position.x, 0.0) != want)
            });
        if straddles {
            continue;
        }
        checked += 1;
        assert!(
            (out[i].x - want).abs() < 0.05,
            "hard shadow softened at pixel {i}: {} instead of {want}",
            out[i].x
        );
    }
    assert!(checked > 1000);
}

/// How far a denoised shadow is from the visibility `want` gives each surface (by its x): the
/// mean absolute error, the pixels off by more than 0.25, and the surfaces counted.
fn visibility_error(g: &GBuffer, out: &[Vec4], want: impl Fn(f32) -> f32) -> (f32, usize, usize) {
    let (mut err, mut wrong, mut n) = (0.0f32, 0, 0);
    for (i, s) in g.surfaces.iter().enumerate() {
        let Some(s) = s else { continue };
        let e = (out[i].x - want(s.position.x)).abs();
        err += e;
        wrong += (e > 0.25) as usize;
        n += 1;
    }
    (err / n as f32, wrong, n)
}

/// A small light's shadow is exact at one sample per pixel: along a jittered, moving camera the
/// denoised shadow must stay as exact as its raw input (the reference of each frame is that
/// frame's visibility). Resampling the history across the edge, or blurring by the edge's
/// spatial spread as if it were noise, softens it (frame 0 alone lost 10 dB that way).
#[test]
fn hard_shadow_stays_as_exact_as_its_input_along_a_jittered_pan() {
    let eye = |f: usize| EYE + Vec3::new(0.01 * f as f32, 0.0, 0.0);
    let h = Harness::new(SignalType::Shadow, DenoisingMethod::HighQuality);
    let mut rng = Rng(31);
    for f in 0..12 {
        let g = gbuffer_jittered(
            eye(f),
            Vec3::ZERO,
            eye(f.saturating_sub(1)),
            Vec3::ZERO,
            JITTER[f % 4],
        );
        let out = h
            .frame(
                &g,
                &[shadow_input(&g, 0.0, &mut rng)],
                Motion::Matrices,
                DenoiseMode::Continue,
            )
            .remove(0);
        let (mean, wrong, n) = visibility_error(&g, &out, |x| visibility(x, 0.0));
        eprintln!("frame {f}: mean error {mean:.4}, {wrong} of {n} pixels off by 0.25");
        assert!(mean < 0.01, "frame {f}: mean error {mean:.4}");
        assert!(
            wrong * 200 < n,
            "frame {f}: {wrong} of {n} pixels off by 0.25"
        );
    }
}

/// The sun's shadow as the shadow trace writes it: where the light is visible, minus the tangent
/// of its angular radius (about 0.27°); where not, the occluder's distance (0.5). The penumbra,
/// 2 × 0.5 × 0.0047, is a tenth of a pixel here.
const SUN_TAN: f32 = 0.0047;

/// Denoises a shadow along a long (24-frame), jittered pan: `input` writes each frame's raw
/// shadow trace from its G-buffer, `check` sees each frame's G-buffer and denoised output.
fn denoise_shadow_along_a_pan(
    mut input: impl FnMut(&GBuffer) -> Vec<Vec4>,
    mut check: impl FnMut(usize, &GBuffer, &[Vec4]),
) {
    let eye = |f: usize| EYE + Vec3::new(0.017 * f as f32, 0.0, 0.0);
    let h = Harness::new(SignalType::Shadow, DenoisingMethod::HighQuality);
    for f in 0..24 {
        let g = gbuffer_jittered(
            eye(f),
            Vec3::ZERO,
            eye(f.saturating_sub(1)),
            Vec3::ZERO,
            JITTER[f % 4],
        );
        let out = h
            .frame(&g, &[input(&g)], Motion::Matrices, DenoiseMode::Continue)
            .remove(0);
        check(f, &g, &out);
    }
}

/// A thin shadow of the sun (a line about 1.5 pixels wide) along a long, jittered pan: the
/// denoised shadow must stay as exact as its raw samples every frame. History resampled across
/// the line at a sub-pixel offset, frame after frame, blurs it away (the default scene at
/// 320×180 lost 6 dB to its raw input over a 16-frame pan that way).
#[test]
fn thin_sun_shadow_stays_exact_along_a_long_pan() {
    let lit = |x: f32| (x - 0.2).abs() >= 0.04;
    let input = |g: &GBuffer| -> Vec<Vec4> {
        g.surfaces
            .iter()
            .map(|s| match s {
                None => Vec4::splat(-1.0),
                Some(s) if lit(s.position.x) => Vec4::new(-SUN_TAN, 0.0, 0.0, 0.0),
                Some(_) => Vec4::new(0.5, 0.0, 0.0, 0.0),
            })
            .collect()
    };
    denoise_shadow_along_a_pan(input, |f, g, out| {
        let (mean, wrong, n) = visibility_error(g, out, |x| if lit(x) { 1.0 } else { 0.0 });
        eprintln!("frame {f}: mean error {mean:.4}, {wrong} of {n} pixels off by 0.25");
        assert!(mean < 0.005, "frame {f}: mean error {mean:.4}");
        assert!(
            wrong * 400 < n,
            "frame {f}: {wrong} of {n} pixels off by 0.25"
        );
    });
}

/// A light whose penumbra is about 2 pixels wide here (tan 0.1, occluder 0.5 away: 0.1 wide),
/// sampled at one ray a pixel along a long pan: its samples are noise, so the history is kept,
/// and each frame resamples it. Scored near the edge (within 0.15 of its centre) against the
/// exact visibility ramp, as the mean absolute error over frames 8-23 and at the last frame:
/// the bilinear history, which blurs the edge by its sub-pixel offset every frame, scored 0.084
/// and 0.109 (growing every frame); the Catmull-Rom history 0.051 and 0.055 (flat).
#[test]
fn two_pixel_penumbra_stays_sharp_along_a_long_pan() {
    const WIDTH: f32 = 0.1;
    let mut rng = Rng(77);
    let input = |g: &GBuffer| -> Vec<Vec4> {
        g.surfaces
            .iter()
            .map(|s| match s {
                None => Vec4::splat(-1.0),
                Some(s) if rng.f() < visibility(s.position.x, WIDTH) => {
                    Vec4::new(-WIDTH, 0.0, 0.0, 0.0)
                }
                Some(_) => Vec4::new(0.5, 0.0, 0.0, 0.0),
            })
            .collect()
    };
    let (mut err, mut n, mut last) = (0.0f32, 0usize, 0.0f32);
    denoise_shadow_along_a_pan(input, |f, g, out| {
        let (mut e, mut m) = (0.0f32, 0usize);
        for (i, s) in g.surfaces.iter().enumerate() {
            let Some(s) = s else { continue };
            if (s.position.x - 0.2).abs() < 0.15 {
                e += (out[i].x - visibility(s.position.x, WIDTH)).abs();
                m += 1;
            }
        }
        last = e / m as f32;
        eprintln!("frame {f}: mean error {last:.4} over {m} pixels near the edge");
        if f >= 8 {
            err += e;
            n += m;
        }
    });
    let mean = err / n as f32;
    eprintln!("frames 8-23: mean error {mean:.4} near the edge");
    assert!(n > 2000, "{n} pixels near the edge");
    assert!(
        mean < 0.065,
        "frames 8-23: mean error near the edge {mean:.4}"
    );
    assert!(
        last < 0.07,
        "last frame: mean error near the edge {last:.4}"
    );
}

#[test]
fn large_light_penumbra_is_smooth() {
    let width = 1.0;
    let (g, out) = run_shadow(width, 9);
    let s = SIZE as usize;
    let mut err = 0.0;
    let mut n = 0;
    let mut rough_out = 0.0f32;
    let mut rough_in = 0.0f32;
    let mut rng = Rng(10);
    let noisy = shadow_input(&g, width, &mut rng);
    let vis = |v: f32| if v < 0.0 { 1.0f32 } else { 0.0 };
    for y in 0..s {
        for x in 1..s - 1 {
            let i = y * s + x;
            let (Some(a), Some(b), Some(c)) = (g.surfaces[i - 1], g.surfaces[i], g.surfaces[i + 1])
            else {
                continue;
            };
            if a.object != 0 || b.object != 0 || c.object != 0 {
                continue;
            }
            let want = visibility(b.position.x, width);
            if want <= 0.0 || want >= 1.0 {
                continue;
            }
            err += (out[i].x - want).abs();
            rough_out += (out[i - 1].x - 2.0 * out[i].x + out[i + 1].x).abs();
            rough_in += (vis(noisy[i - 1].x) - 2.0 * vis(noisy[i].x) + vis(noisy[i + 1].x)).abs();
            n += 1;
        }
    }
    assert!(n > 200, "penumbra pixels {n}");
    let mean_err = err / n as f32;
    eprintln!(
        "penumbra: {n} pixels, mean error {mean_err:.4}, roughness {:.4} (noisy {:.4})",
        rough_out / n as f32,
        rough_in / n as f32
    );
    assert!(
        mean_err < 0.08,
        "penumbra off the expected ramp by {mean_err}"
    );
    let roughness = rough_out / n as f32;
    assert!(roughness < 0.05, "penumbra not smooth: {roughness}");
}

#[test]
fn checkerboard_input_is_resolved_to_every_pixel() {
    // The viewport offset by one column checks that the traced cells are found by the
    // viewport-relative parity the trace tasks write (trace_common.wgsl), not the texel's.
    for (mode, x0) in [
        (HalfResolutionMode::Checkerboard, 0),
        (HalfResolutionMode::CheckerboardInverted, 0),
        (HalfResolutionMode::Checkerboard, 1),
    ] {
        let g = static_gbuffer();
        let mut h = Harness::new(SignalType::Diffuse, DenoisingMethod::HighQuality);
        h.half_resolution_mode = mode;
        h.viewport = Some(Viewport {
            x: x0,
            y: 0,
            width: SIZE - x0,
            height: SIZE,
        });
        let r = reference_image(&g, reference);
        let traced_parity = if mode == HalfResolutionMode::Checkerboard {
            0
        } else {
            1
        };
        // Pixels left of the viewport are not the task's: scored as the reference.
        let inside = |img: &[Vec4]| -> Vec<Vec4> {
            img.iter()
                .enumerate()
                .map(|(i, v)| if (i as u32 % SIZE) < x0 { r[i] } else { *v })
                .collect()
        };
        let mut rng = Rng(11);
        let mut out = Vec::new();
        let mut noisy_psnr = 0.0;
        for _ in 0..16 {
            // Untraced cells hold garbage the denoiser must never show.
            let mut input = noisy(&r, &mut rng);
            noisy_psnr = psnr(&g, &inside(&input), &r);
            for (i, v) in input.iter_mut().enumerate() {
                let (x, y) = (i as u32 % SIZE, i as u32 / SIZE);
                if (x + y + x0) % 2 != traced_parity {
                    *v = Vec4::new(1000.0, -50.0, f32::NAN, 3.0);
                }
            }
            out = h
                .frame(&g, &[input], Motion::Matrices, DenoiseMode::Continue)
                .remove(0);
        }
        let p = psnr(&g, &inside(&out), &r);
        eprintln!("{mode:?} at x {x0}: {p:.2} dB (noisy full-resolution input {noisy_psnr:.2} dB)");
        // An untraced pixel none of whose 4-neighbours is on its surface (a box corner) has no
        // sample of its own colour at all: it is not checked.
        let s_ = SIZE as usize;
        let same = |a: &common::denoise::Surface, j: usize| {
            g.surfaces[j].is_some_and(|b| b.object == a.object && b.normal == a.normal)
        };
        let mut unknowable = 0;
        for (i, s) in g.surfaces.iter().enumerate() {
            if let Some(a) = s {
                let (x, y) = (i % s_, i / s_);
                if x < x0 as usize {
                    continue;
                }
                let traced = (x + y + x0 as usize) % 2 == traced_parity as usize;
                let neighbours = [
                    (x > 0).then(|| i - 1),
                    (x + 1 < s_).then(|| i + 1),
                    (y > 0).then(|| i - s_),
                    (y + 1 < s_).then(|| i + s_),
                ];
                if !traced && !neighbours.iter().flatten().any(|&j| same(a, j)) {
                    unknowable += 1;
                    continue;
                }
                let e = (out[i] - r[i]).truncate().abs().max_element();
                assert!(
                    e < 0.25,
                    "{mode:?}: pixel {i} ({s:?}) is {} for {}",
                    out[i],
                    r[i]
                );
            }
        }
        assert!(
            unknowable < 10,
            "{mode:?}: {unknowable} pixels without a sample"
        );
        assert!(p > noisy_psnr + 8.0, "{mode:?}: {p:.2} dB");
    }
}

/// The traced pixel of each block in frame `phase` of a block mode, as documented on
/// `HalfResolutionMode` (written out here, not taken from the SDK).
fn block_traced_pixel(block: u32, phase: u32) -> (u32, u32) {
    const TWO: [(u32, u32); 4] = [(0, 0), (1, 1), (1, 0), (0, 1)];
    // The 4×4 Bayer matrix's pixel of value k.
    const BAYER: [[u32; 4]; 4] = [[0, 8, 2, 10], [12, 4, 14, 6], [3, 11, 1, 9], [15, 7, 13, 5]];
    if block == 2 {
        return TWO[(phase % 4) as usize];
    }
    let k = phase % 16;
    for (y, row) in BAYER.iter().enumerate() {
        for (x, &v) in row.iter().enumerate() {
            if v == k {
                return (x as u32, y as u32);
            }
        }
    }
    unreachable!()
}

fn block_mode(block: u32, phase: u32) -> HalfResolutionMode {
    if block == 2 {
        HalfResolutionMode::OnePer2x2 { phase }
    } else {
        HalfResolutionMode::OnePer4x4 { phase }
    }
}

/// `img` with every pixel a block mode does not trace in `phase` replaced by garbage (which
/// the denoiser must never read).
fn keep_traced(img: &[Vec4], block: u32, phase: u32) -> Vec<Vec4> {
    let t = block_traced_pixel(block, phase);
    img.iter()
        .enumerate()
        .map(|(i, v)| {
            let (x, y) = (i as u32 % SIZE, i as u32 / SIZE);
            if (x % block, y % block) == t {
                *v
            } else {
                Vec4::new(1000.0, -50.0, f32::NAN, 3.0)
            }
        })
        .collect()
}

#[test]
fn block_modes_reconstruct_a_uniform_signal_exactly_at_every_pixel() {
    // A noiseless uniform signal traced at one pixel per block: the filtered grid is uniform,
    // and the upsample must give that value to every pixel with a surface, from the first frame
    // on (no untraced pixel left unwritten, no garbage read), whatever the phase.
    let g = static_gbuffer();
    let flat = reference_image(&g, |_| Vec3::new(0.5, 0.25, 0.125));
    for block in [2, 4] {
        let mut h = Harness::new(SignalType::Diffuse, DenoisingMethod::Fast);
        for phase in 0..6 {
            h.half_resolution_mode = block_mode(block, phase);
            let input = keep_traced(&flat, block, phase);
            let out = h
                .frame(&g, &[input], Motion::Matrices, DenoiseMode::Continue)
                .remove(0);
            for (i, s) in g.surfaces.iter().enumerate() {
                if s.is_none() {
                    continue;
                }
                let e = (out[i] - flat[i]).truncate().abs().max_element();
                assert!(
                    e < 2e-3,
                    "{block}×{block} phase {phase}: pixel {i} is {} for {}",
                    out[i],
                    flat[i]
                );
            }
        }
    }
}

#[test]
fn block_modes_upsample_a_horizontal_ramp_exactly() {
    // A noiseless signal linear in the pixel column, traced at one pixel per block: the
    // edge-stopping filter keeps it (on one plane its weights are symmetric in the column
    // offset, whichever rows an edge takes away), and the upsample's bilinear weights between
    // the four grid pixels around a pixel rebuild it exactly. Checked on the back wall's rows
    // above the box (one plane from side to side), away from the image's sides. A tap given another tap's record or weight
    // is off by the ramp's step between them.
    let g = static_gbuffer();
    let ramp = |i: usize| {
        let x = (i as u32 % SIZE) as f32;
        Vec3::new(1.0 + 0.02 * x, 0.5 + 0.01 * x, 0.8 - 0.005 * x)
    };
    let r: Vec<Vec4> = (0..g.surfaces.len())
        .map(|i| g.surfaces[i].map_or(Vec4::ZERO, |_| ramp(i).extend(1.0)))
        .collect();
    // 2×2 only: the same upsample code serves 4×4, whose filter reaches 28 pixels, across
    // most of this 64-pixel image, so that the image's sides (taps dropped on one side) bias
    // every pixel by more than the tolerance.
    let block = 2u32;
    let mut h = Harness::new(SignalType::Diffuse, DenoisingMethod::Fast);
    let mut out = Vec::new();
    for phase in 0..8 {
        h.half_resolution_mode = block_mode(block, phase);
        out = h
            .frame(
                &g,
                &[keep_traced(&r, block, phase)],
                Motion::Matrices,
                DenoiseMode::Continue,
            )
            .remove(0);
    }
    let side = 2 * block;
    let mut checked = 0;
    let mut worst = 0.0f32;
    for (i, v) in out.iter().enumerate() {
        let (x, y) = (i as u32 % SIZE, i as u32 / SIZE);
        // Rows that are wall from side to side (above the box).
        let wall_row =
            (0..SIZE).all(|x| g.surfaces[(y * SIZE + x) as usize].is_some_and(|s| s.object == 1));
        if !wall_row || x < side || x >= SIZE - side {
            continue;
        }
        checked += 1;
        let e = (v.truncate() - ramp(i)).abs().max_element();
        worst = worst.max(e);
    }
    eprintln!("{block}×{block}: {checked} wall pixels, worst error {worst:.5}");
    assert!(
        checked >= 500,
        "{block}×{block}: only {checked} wall pixels"
    );
    // f16 records and the filter's rounding leave 0.008 at worst; a tap given a neighbour's
    // record or bilinear weight is off by 0.027.
    assert!(
        worst < 0.015,
        "{block}×{block}: the ramp is off by {worst:.5}"
    );
}

#[test]
fn block_modes_are_reconstructed_to_every_pixel_with_edges_kept() {
    let g = static_gbuffer();
    let r = reference_image(&g, reference);
    for (block, min_gain) in [(2, 15.0), (4, 11.0)] {
        let mut h = Harness::new(SignalType::Diffuse, DenoisingMethod::HighQuality);
        let mut rng = Rng(23);
        let mut out = Vec::new();
        let mut noisy_psnr = 0.0;
        // 16 frames: every pixel of a 4×4 block traced once.
        for phase in 0..16 {
            h.half_resolution_mode = block_mode(block, phase);
            let input = noisy(&r, &mut rng);
            noisy_psnr = psnr(&g, &input, &r);
            out = h
                .frame(
                    &g,
                    &[keep_traced(&input, block, phase)],
                    Motion::Matrices,
                    DenoiseMode::Continue,
                )
                .remove(0);
        }
        let p = psnr(&g, &out, &r);
        let edges = edge_pixels(&g, &r, 0.25);
        let edge_err = edges
            .iter()
            .map(|&i| (out[i].truncate() - r[i].truncate()).abs().max_element())
            .sum::<f32>()
            / edges.len() as f32;
        let surfaces: Vec<usize> = (0..out.len())
            .filter(|&i| g.surfaces[i].is_some())
            .collect();
        let far = surfaces
            .iter()
            .filter(|&&i| (out[i] - r[i]).truncate().abs().max_element() >= 0.25)
            .count();
        eprintln!(
            "{block}×{block}: {p:.2} dB (noisy full-rate input {noisy_psnr:.2} dB), edge error \
             {edge_err:.4}, {far} of {} pixels off by 0.25",
            surfaces.len()
        );
        assert!(
            out.iter().all(|v| v.is_finite()),
            "{block}×{block}: garbage read"
        );
        assert!(p > noisy_psnr + min_gain, "{block}×{block}: {p:.2} dB");
        // Guided by the G-buffer, the upsample keeps the steps across depth and normal edges
        // (a plain bilinear upsample of a 4×4 grid smears them over 4 pixels).
        assert!(
            edge_err < 0.1,
            "{block}×{block}: edges blurred, mean error {edge_err:.4}"
        );
        assert!(
            far * 100 < surfaces.len(),
            "{block}×{block}: {far} pixels off by 0.25"
        );
    }
}

#[test]
fn multi_shadow_denoises_the_packed_visibility() {
    // The multi-shadow format read by the denoiser: R = visibility in [0, 1], G = hit distance.
    let g = static_gbuffer();
    let h = Harness::new(SignalType::MultiShadow, DenoisingMethod::HighQuality);
    let mut rng = Rng(12);
    let want = |s: &common::denoise::Surface| 0.25 + 0.5 * visibility(s.position.x, 1.0);
    let mut out = Vec::new();
    for _ in 0..16 {
        let input: Vec<Vec4> = g
            .surfaces
            .iter()
            .map(|s| match s {
                None => Vec4::new(1.0, 0.0, 0.0, 0.0),
                Some(s) => {
                    // Two lights: one always visible at weight 0.25 … a noisy estimate.
                    let v = (want(s) + rng.range(-0.25, 0.25)).clamp(0.0, 1.0);
                    Vec4::new(v, 0.5, 0.0, 0.0)
                }
            })
            .collect();
        out = h
            .frame(&g, &[input], Motion::Matrices, DenoiseMode::Continue)
            .remove(0);
    }
    let mut err = 0.0;
    let mut n = 0;
    for (i, s) in g.surfaces.iter().enumerate() {
        if let Some(s) = s {
            err += (out[i].x - want(s)).abs();
            n += 1;
        }
    }
    let mean = err / n as f32;
    assert!(mean < 0.03, "multi-shadow mean error {mean}");
}

/// Builds an empty container on `ctx` and submits it (a `build_gpu_task` collects released
/// memory).
fn build_empty(ctx: &ExecuteContext) -> GpuTaskHandle {
    let mut e = encoder();
    let t = ctx
        .build_gpu_task(ctx.create_task_container(), &mut e)
        .unwrap();
    submit(e);
    t
}

/// A denoising context's memory, by the documented formula: its own, per grid pixel and signal
/// one record (16 bytes for radiance, 8 for occlusion and shadows); and what it may share with
/// other contexts: two 8-byte guides and the two intermediates (a record each) per pixel.
fn expected_denoiser_bytes(signal: SignalType, grid_pixels: u64) -> (u64, u64) {
    let (signals, record) = match signal {
        SignalType::SpecularAndDiffuse => (2, 16),
        SignalType::Specular | SignalType::Diffuse => (1, 16),
        _ => (1, 8),
    };
    (
        grid_pixels * signals * record,
        grid_pixels * (2 * 8 + 2 * record),
    )
}

/// A context holds no memory before its first frame; then its histories and guides for the
/// frame's grid (a block mode's is a quarter of the pixels, and the larger buffers go once no
/// task uses them) and the shared intermediate; all of it is released after destruction once
/// the tasks that used it are complete.
#[test]
fn history_memory_follows_its_grid_and_is_released_after_destroy() {
    let g = static_gbuffer();
    for signal in [SignalType::SpecularAndDiffuse, SignalType::Shadow] {
        let mut h = Harness::new(signal, DenoisingMethod::Fast);
        let t = build_empty(&h.ctx);
        assert_eq!(h.ctx.resource_allocations().denoiser, 0, "created lazily");
        assert_eq!(h.ctx.denoising_context_bytes(h.handle), Ok(0));
        h.ctx.mark_gpu_task_completed(t).unwrap();
        let r = reference_image(&g, reference);
        let inputs = vec![r; h.outputs.len()];
        let full = u64::from(SIZE * SIZE);
        h.frame(&g, &inputs, Motion::Matrices, DenoiseMode::Continue);
        let (own, shared) = expected_denoiser_bytes(signal, full);
        assert_eq!(
            h.ctx.denoising_context_bytes(h.handle),
            Ok(own),
            "{signal:?}"
        );
        assert_eq!(h.ctx.resource_allocations().denoiser, own + shared);

        // One traced pixel per 2×2: a quarter of the grid.
        h.half_resolution_mode = HalfResolutionMode::OnePer2x2 { phase: 0 };
        let used = h.submit_frame(&g, &inputs, Motion::Matrices, DenoiseMode::Continue);
        let (quarter, quarter_shared) = expected_denoiser_bytes(signal, full / 4);
        assert_eq!(h.ctx.denoising_context_bytes(h.handle), Ok(own + quarter));
        h.ctx.mark_gpu_task_completed(used).unwrap();
        h.frame(&g, &inputs, Motion::Matrices, DenoiseMode::Continue);
        assert_eq!(h.ctx.denoising_context_bytes(h.handle), Ok(quarter));
        assert_eq!(
            h.ctx.resource_allocations().denoiser,
            quarter + quarter_shared,
            "{signal:?}: the full-size buffers are released"
        );

        let used = h.submit_frame(&g, &inputs, Motion::Matrices, DenoiseMode::Continue);
        h.ctx.destroy_denoising_context_handle(h.handle).unwrap();
        // A destroyed context's bytes are asked of a stale handle: an error naming it.
        match h.ctx.denoising_context_bytes(h.handle) {
            Err(Error::InvalidHandle {
                kind: HandleKind::DenoisingContext,
                index,
                ..
            }) => assert_eq!(index, h.handle.index()),
            other => panic!("{signal:?}: stale handle gave {other:?}"),
        }
        // The task that used it is still in flight: the memory stays.
        let t2 = build_empty(&h.ctx);
        assert_eq!(
            h.ctx.resource_allocations().denoiser,
            quarter + quarter_shared
        );
        h.ctx.mark_gpu_task_completed(used).unwrap();
        h.ctx.mark_gpu_task_completed(t2).unwrap();
        let t3 = build_empty(&h.ctx);
        assert_eq!(h.ctx.resource_allocations().denoiser, 0, "{signal:?}");
        h.ctx.mark_gpu_task_completed(t3).unwrap();
    }
}

#[test]
fn denoise_task_refuses_a_context_of_another_signal_or_size() {
    let g = static_gbuffer();
    let h = Harness::new(SignalType::Shadow, DenoisingMethod::Fast);
    let other = h
        .ctx
        .create_denoising_context_handle(DenoisingContextInput {
            max_width: 16,
            max_height: 16,
            signal_type: SignalType::Diffuse,
            method: DenoisingMethod::Fast,
        })
        .unwrap();
    // A Diffuse context used by a shadow task.
    let mut common = h.common(&g, Motion::Matrices, DenoiseMode::Continue);
    common.context = other;
    let task = |common| {
        RenderTask::DenoiseShadow(DenoiseShadowTask {
            common,
            input: texture(
                wgpu::TextureFormat::R32Float,
                SIZE,
                SIZE,
                wgpu::TextureUsages::TEXTURE_BINDING,
            ),
            output: h.outputs[0].clone(),
        })
    };
    let mut c = h.ctx.create_task_container();
    c.schedule_render_task(task(common));
    let mut e = encoder();
    match h.ctx.build_gpu_task(c, &mut e) {
        Err(Error::InvalidInput { task, field, .. }) => {
            assert_eq!(
                (task, field.as_str()),
                ("DenoiseShadowTask", "common.context")
            )
        }
        other => panic!("expected an InvalidInput error, got {other:?}"),
    }
    // A Diffuse context of 16×16 used for 64×64.
    let d = Harness::new(SignalType::Diffuse, DenoisingMethod::Fast);
    let mut common = d.common(&g, Motion::Matrices, DenoiseMode::Continue);
    common.context = d
        .ctx
        .create_denoising_context_handle(DenoisingContextInput {
            max_width: 16,
            max_height: 16,
            signal_type: SignalType::Diffuse,
            method: DenoisingMethod::Fast,
        })
        .unwrap();
    let mut c = d.ctx.create_task_container();
    c.schedule_render_task(RenderTask::DenoiseDiffuse(DenoiseDiffuseTask {
        common,
        input: texture(
            wgpu::TextureFormat::Rgba32Float,
            SIZE,
            SIZE,
            wgpu::TextureUsages::TEXTURE_BINDING,
        ),
        output: d.outputs[0].clone(),
    }));
    match d.ctx.build_gpu_task(c, &mut e) {
        Err(Error::InvalidInput { field, .. }) if field == "viewport" => {}
        other => panic!("expected a viewport error, got {other:?}"),
    }
    submit(e);
}

/// Two contexts denoised in one task from the same G-buffer share one pair of guides, and each
/// gives, frame by frame, exactly what it gives alone; a frame where one context's inputs differ
/// (another roughness) gives it a pair of its own without losing its history, and it shares
/// again once its inputs match its partner's for a second frame.
#[test]
fn contexts_with_the_same_inputs_share_their_guides_and_give_what_each_gives_alone() {
    let method = DenoisingMethod::HighQuality;
    let shared = Harness::new(SignalType::Diffuse, method);
    let partner = shared
        .ctx
        .create_denoising_context_handle(DenoisingContextInput {
            max_width: SIZE,
            max_height: SIZE,
            signal_type: SignalType::Diffuse,
            method,
        })
        .unwrap();
    let read = wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST;
    let write = wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::COPY_SRC;
    let partner_in = [make_texture(wgpu::TextureFormat::Rgba32Float, read)];
    let partner_out = [make_texture(wgpu::TextureFormat::Rgba32Float, write)];
    let (alone_a, alone_b) = (
        Harness::new(SignalType::Diffuse, method),
        Harness::new(SignalType::Diffuse, method),
    );
    let mut rng = Rng(77);
    let pixels = u64::from(SIZE * SIZE);
    let (own, guides_and_scratch) = expected_denoiser_bytes(SignalType::Diffuse, pixels);
    for frame in 0..7 {
        let eye = EYE + Vec3::new(0.04 * frame as f32, 0.0, 0.0);
        let prev_eye = EYE + Vec3::new(0.04 * frame.max(1) as f32 - 0.04, 0.0, 0.0);
        let g = gbuffer(eye, Vec3::ZERO, prev_eye, Vec3::ZERO);
        let r = reference_image(&g, reference);
        let (a, b) = (noisy(&r, &mut rng), noisy(&r, &mut rng));
        // Frame 3: the partner reads another roughness, so its guide differs.
        let partner_common = |h: &Harness| {
            let mut c = h.common(&g, Motion::Matrices, DenoiseMode::Continue);
            if frame == 3 {
                c.roughness.global_roughness = 0.8;
            }
            c
        };
        shared.upload(&g, std::slice::from_ref(&a), Motion::Matrices);
        write_texture(&partner_in[0], &b);
        let mut c = shared.ctx.create_task_container();
        c.schedule_render_task(shared.task(shared.common(
            &g,
            Motion::Matrices,
            DenoiseMode::Continue,
        )));
        let mut pc = partner_common(&shared);
        pc.context = partner;
        c.schedule_render_task(denoise_task(
            SignalType::Diffuse,
            pc,
            &partner_in,
            &partner_out,
        ));
        build_submit_complete(&shared.ctx, c);

        let want_a = alone_a.frame(
            &g,
            std::slice::from_ref(&a),
            Motion::Matrices,
            DenoiseMode::Continue,
        );
        alone_b.upload(&g, std::slice::from_ref(&b), Motion::Matrices);
        let mut c = alone_b.ctx.create_task_container();
        c.schedule_render_task(alone_b.task(partner_common(&alone_b)));
        build_submit_complete(&alone_b.ctx, c);
        let want_b = read_texture(&alone_b.outputs[0]);
        assert!(
            read_texture(&shared.outputs[0]) == want_a[0],
            "frame {frame}: first context"
        );
        assert!(
            read_texture(&partner_out[0]) == want_b,
            "frame {frame}: partner"
        );

        let total = shared.ctx.resource_allocations().denoiser;
        // The partner's own pair from frame 3 until it rejoins (frame 5), released by the next
        // task.
        let pairs = if (3..=5).contains(&frame) { 2 } else { 1 };
        assert_eq!(
            total,
            2 * own + guides_and_scratch + (pairs - 1) * 2 * 8 * pixels,
            "frame {frame}: {pairs} pair(s) of guides"
        );
    }
}
