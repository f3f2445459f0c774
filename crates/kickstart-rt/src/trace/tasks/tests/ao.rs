//! Ambient occlusion against closed forms (open plane, closed box, a wall over frames), and
//! what every trace pass shares, checked through AO: the noise per frame index and the
//! checkerboard modes with the input mask.

use super::*;

fn ao(c: TraceTaskCommon, out: &TextureInput, radius: f32) -> RenderTask {
    RenderTask::TraceAmbientOcclusion(TraceAmbientOcclusionTask {
        common: c,
        output: out.clone(),
        ao_radius: radius,
    })
}

#[test]
fn ao_of_an_open_plane_is_one_with_every_offset_and_generator() {
    let scene = TestScene::single(square(1, 0.0, 50.0));
    for offset in [
        RayOffsetType::Disabled,
        RayOffsetType::WorldPosition,
        RayOffsetType::CamDistance,
    ] {
        for rng in [
            RandomNumberGenerator::BlueNoise,
            RandomNumberGenerator::Xorshift,
        ] {
            let out = output(N, N, -5.0);
            let mut c = common(gbuffer(N, N, floor), Vec3::new(0.0, 3.0, 0.0));
            c.ray_offset.offset_type = offset;
            c.debug_parameters.random_number_generator = rng;
            run(&scene, &[ao(c, &out, 2.0)]);
            for (i, v) in read(&out).iter().enumerate() {
                assert_eq!(v[0], 1.0, "{offset:?} {rng:?} texel {i}");
            }
        }
    }
}

/// What the ray offsets are for: a G-buffer whose positions sit 1 mm below the surface they
/// show (reconstruction error, here far from the origin: the plane is at y = 1000, where a float
/// step is 61 µm). Without an offset every ray starts under the plane and hits it at once (AO
/// ≈ 0: the hit lies past the 0.3 mm t_min); the world-position offset (256 float steps, 16
/// mm here) and the camera-distance one (about 2.5 mm at 3 m) lift the origin above it, and
/// the open plane is unoccluded again. The open-plane test above cannot see this: with exact
/// positions every offset gives 1.
#[test]
fn ray_offsets_lift_origins_from_below_the_surface() {
    const H: f32 = 1000.0;
    let scene = TestScene::single(square(1, H, 50.0));
    let below = |x, y| floor(x, y).map(|(p, n)| (p + Vec3::new(0.0, H - 1e-3, 0.0), n));
    for offset in [
        RayOffsetType::Disabled,
        RayOffsetType::WorldPosition,
        RayOffsetType::CamDistance,
    ] {
        let out = output(N, N, -5.0);
        let mut c = common(gbuffer(N, N, below), Vec3::new(0.0, H + 3.0, 0.0));
        c.ray_offset.offset_type = offset;
        run(&scene, &[ao(c, &out, 2.0)]);
        let values: Vec<f32> = read(&out).iter().map(|v| v[0]).collect();
        if offset == RayOffsetType::Disabled {
            // Hit at 1 mm / cos θ: a fraction of the 2 m radius, up to grazing rays.
            let mean = values.iter().sum::<f32>() / values.len() as f32;
            assert!(mean < 0.02, "{offset:?}: mean AO {mean}");
        } else {
            for (i, v) in values.iter().enumerate() {
                assert_eq!(*v, 1.0, "{offset:?} texel {i}");
            }
        }
    }
}

#[test]
fn ao_inside_a_closed_box_is_near_zero() {
    // A closed box of half-size 0.1; points inside it, random normals; radius 10: every ray hits
    // within the box's diagonal, so the output is at most 0.35 / 10.
    let box_tris: Vec<Tri> = cube(2).into_iter().map(|t| t.map(|v| v * 0.1)).collect();
    let scene = TestScene::single(box_tris);
    let mut rng = testing::Rng(7);
    let texels = random_texels(&mut rng, 0.05);
    let out = output(N, N, -5.0);
    let c = common(
        gbuffer(N, N, |x, y| texels[(y * N + x) as usize]),
        Vec3::new(0.0, 0.05, 0.0),
    );
    run(&scene, &[ao(c, &out, 10.0)]);
    for (i, v) in read(&out).iter().enumerate() {
        assert!(v[0] > 0.0 && v[0] <= 0.0347, "texel {i}: {}", v[0]);
    }
}

/// A point at distance d facing an infinite wall: a cosine-weighted ray at angle θ to the normal
/// hits at d / cos θ, so with c = d / R the occluded fraction is 1 − c² and the mean output
/// E[min(d / (R cos θ), 1)] = 2c − c² (closed form; pdf of cos θ is 2 cos θ).
#[test]
fn ao_in_front_of_a_wall_matches_the_closed_form_over_frames() {
    let (d, radius) = (0.3f32, 1.0f32);
    let scene = TestScene::single(square(2, -d, 20.0));
    let g = |x: u32, y: u32| {
        let f = |i: u32| -0.5 + (i as f32 + 0.5) / N as f32;
        Some((Vec3::new(f(x), f(y), 0.0), Vec3::NEG_Z))
    };
    let c = d / radius;
    for rng in [
        RandomNumberGenerator::BlueNoise,
        RandomNumberGenerator::Xorshift,
    ] {
        let (mut sum, mut occluded, mut n) = (0.0f64, 0usize, 0usize);
        let mut frames = Vec::new();
        for frame in 0..12 {
            let out = output(N, N, -5.0);
            let mut cm = common(gbuffer(N, N, g), Vec3::new(0.0, 0.0, 2.0));
            cm.debug_parameters.random_number_generator = rng;
            cm.debug_parameters.frame_index = frame;
            run(&scene, &[ao(cm, &out, radius)]);
            let img = read(&out);
            for v in &img {
                sum += v[0] as f64;
                occluded += (v[0] < 1.0) as usize;
                n += 1;
            }
            frames.push(img);
        }
        let mean = sum / n as f64;
        let frac = occluded as f64 / n as f64;
        let want = (2.0 * c - c * c) as f64;
        assert!(
            (mean - want).abs() < 0.01,
            "{rng:?}: mean {mean}, closed form {want}"
        );
        assert!(
            (frac - (1.0 - c * c) as f64).abs() < 0.01,
            "{rng:?}: occluded fraction {frac}"
        );
        // Noise changes every frame.
        assert_ne!(frames[0], frames[1], "{rng:?}");
    }
}

#[test]
fn noise_is_reproducible_for_a_frame_index() {
    let scene = TestScene::single(square(2, -0.3, 20.0));
    let g = |x: u32, y: u32| {
        Some((
            Vec3::new(x as f32 * 0.01, y as f32 * 0.01, 0.0),
            Vec3::NEG_Z,
        ))
    };
    for rng in [
        RandomNumberGenerator::BlueNoise,
        RandomNumberGenerator::Xorshift,
    ] {
        let img = |frame| {
            let out = output(16, 16, -5.0);
            let mut cm = common(gbuffer(16, 16, g), Vec3::new(0.0, 0.0, 2.0));
            cm.debug_parameters.random_number_generator = rng;
            cm.debug_parameters.frame_index = frame;
            run(&scene, &[ao(cm, &out, 1.0)]);
            read(&out)
        };
        let a = img(5);
        assert_eq!(a, img(5), "{rng:?}");
        assert_ne!(a, img(6), "{rng:?}");
    }
}

#[test]
fn reduced_rate_modes_write_exactly_their_pixels_and_the_mask_skips() {
    let scene = TestScene::single(square(1, 0.0, 50.0));
    // Viewport at an odd x offset: the pattern is viewport-relative.
    let vp = Viewport {
        x: 3,
        y: 2,
        width: 21,
        height: 13,
    };
    for mode in [
        HalfResolutionMode::Off,
        HalfResolutionMode::Checkerboard,
        HalfResolutionMode::CheckerboardInverted,
        HalfResolutionMode::OnePer2x2 { phase: 0 },
        HalfResolutionMode::OnePer2x2 { phase: 1 },
        HalfResolutionMode::OnePer2x2 { phase: 6 },
        HalfResolutionMode::OnePer4x4 { phase: 1 },
        // (3, 3) in each 4×4 block: the last block column and row (x, y = 20 of 21 × 13 → 12)
        // have no traced pixel inside the viewport.
        HalfResolutionMode::OnePer4x4 { phase: 5 },
    ] {
        let out = output(N, N, -5.0);
        let mut c = common(gbuffer(N, N, floor), Vec3::new(0.0, 3.0, 0.0));
        c.viewport = Some(vp);
        c.half_resolution_mode = mode;
        // Mask: column 10 of the texture skipped.
        let mask: Vec<f32> = (0..N * N)
            .flat_map(|i| {
                let v = if i % N == 10 { 0.0 } else { 1.0 };
                [v, v, v, v]
            })
            .collect();
        c.input_mask = Some(testing::texture_with(
            wgpu::TextureFormat::Rgba32Float,
            N,
            N,
            bytemuck::cast_slice(&mask),
        ));
        run(&scene, &[ao(c, &out, 1.0)]);
        let img = read(&out);
        for y in 0..N {
            for x in 0..N {
                let inside =
                    (vp.x..vp.x + vp.width).contains(&x) && (vp.y..vp.y + vp.height).contains(&y);
                let (rx, ry) = (x - vp.x.min(x), y - vp.y.min(y));
                let parity = (rx + ry) % 2;
                // The documented sequences: 2×2 (0,0) (1,1) (1,0) (0,1); 4×4 phase 1 is (2,2),
                // phase 5 (3,3).
                let traced = inside
                    && x != 10
                    && match mode {
                        HalfResolutionMode::Off => true,
                        HalfResolutionMode::Checkerboard => parity == 0,
                        HalfResolutionMode::CheckerboardInverted => parity == 1,
                        HalfResolutionMode::OnePer2x2 { phase: 0 } => (rx % 2, ry % 2) == (0, 0),
                        HalfResolutionMode::OnePer2x2 { phase: 1 } => (rx % 2, ry % 2) == (1, 1),
                        HalfResolutionMode::OnePer2x2 { phase: 6 } => (rx % 2, ry % 2) == (1, 0),
                        HalfResolutionMode::OnePer4x4 { phase: 1 } => (rx % 4, ry % 4) == (2, 2),
                        HalfResolutionMode::OnePer4x4 { phase: 5 } => (rx % 4, ry % 4) == (3, 3),
                        _ => unreachable!(),
                    };
                let want = if traced { 1.0 } else { -5.0 };
                assert_eq!(img[(y * N + x) as usize][0], want, "{mode:?} at {x},{y}");
            }
        }
    }
}
