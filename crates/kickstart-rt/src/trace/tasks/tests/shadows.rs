//! Shadows against analytic answers: a sphere over a plane (point and directional lights), the
//! penumbra width of an edge under a sphere light, and the packed per-light visibility of the
//! multi-shadow pass.

use super::*;

/// Distance along the unit ray (o, d) to the sphere (c, r), if it is hit ahead.
fn ray_sphere(o: Vec3, d: Vec3, c: Vec3, r: f32) -> Option<f32> {
    let oc = o - c;
    let b = oc.dot(d);
    let disc = b * b - (oc.length_squared() - r * r);
    if disc < 0.0 {
        return None;
    }
    let t = -b - disc.sqrt();
    (t > 0.0).then_some(t)
}

/// Sphere-over-floor shadows: for each floor texel, the shadow ray towards `light` (a point
/// light at `to_light` or a direction) against the analytic sphere, with a margin for the
/// tessellation.
fn check_sphere_shadow(light: LightInfo, first_hit: bool) {
    let (centre, r) = (Vec3::new(0.3, 1.0, 0.1), 0.6);
    let scene = TestScene::single(sphere(centre, r, 24));
    let out = output(N, N, -5.0);
    let c = common(gbuffer(N, N, floor), Vec3::new(0.0, 5.0, 0.0));
    run(
        &scene,
        &[RenderTask::TraceShadow(TraceShadowTask {
            common: c,
            output: out.clone(),
            light,
            enable_first_hit_and_end_search: first_hit,
        })],
    );
    let img = read(&out);
    let (mut lit, mut shadowed) = (0, 0);
    for y in 0..N {
        for x in 0..N {
            let (p, _) = floor(x, y).unwrap();
            let (dir, t_max) = match light {
                LightInfo::Directional { direction, .. } => (-direction, f32::MAX),
                LightInfo::Point { position, .. } => {
                    ((position - p).normalize(), (position - p).length())
                }
                _ => unreachable!(),
            };
            // Distance of the ray's line from the centre decides, with a tessellation margin.
            let oc = centre - p;
            let miss_by = (oc - dir * oc.dot(dir)).length() - r;
            let v = img[(y * N + x) as usize][0];
            if miss_by > 0.02 || oc.dot(dir) < 0.0 {
                lit += 1;
                assert_eq!(v, -1.0, "{light:?}: lit at {x},{y}");
            } else if miss_by < -0.02 {
                shadowed += 1;
                let t = ray_sphere(p, dir, centre, r).unwrap();
                assert!(t < t_max);
                assert!(v >= 0.0, "{light:?}: shadowed at {x},{y}: {v}");
                if !first_hit {
                    assert!((v - t).abs() < 0.02, "{light:?}: hit at {v}, sphere at {t}");
                }
            }
        }
    }
    assert!(lit > 100 && shadowed > 50, "{lit} lit, {shadowed} shadowed");
}

#[test]
fn sphere_over_a_plane_shadows_the_predicted_disc_point_light() {
    let light = LightInfo::Point {
        position: Vec3::new(-0.2, 3.0, -0.1),
        radius: 0.0,
        range: 100.0,
    };
    check_sphere_shadow(light, false);
    check_sphere_shadow(light, true);
}

#[test]
fn sphere_over_a_plane_shadows_the_predicted_disc_directional_light() {
    let light = LightInfo::Directional {
        direction: Vec3::new(0.3, -1.0, 0.2).normalize(),
        angular_extent: 0.0,
    };
    check_sphere_shadow(light, false);
    check_sphere_shadow(light, true);
}

/// Fraction of a unit disc with coordinate > s (s in [-1, 1]).
fn disc_fraction_above(s: f64) -> f64 {
    let s = s.clamp(-1.0, 1.0);
    (s.acos() - s * (1.0 - s * s).sqrt()) / std::f64::consts::PI
}

/// A sphere light of radius a at height H over a half-plane occluder edge at height h: the
/// penumbra on the floor is 2a·h/(H − h) wide (similar triangles), and the visible fraction at x
/// is the fraction of the light's disc beyond the edge's projection.
#[test]
fn penumbra_width_matches_similar_triangles() {
    let (a, big_h, h) = (0.5f32, 4.0f32, 2.0f32);
    // Occluder: x in [-10, 0] at height h.
    let occluder: Vec<Tri> = square(1, h, 5.0)
        .into_iter()
        .map(|t| t.map(|v| v + Vec3::new(-5.0, 0.0, 0.0)))
        .collect();
    let scene = TestScene::single(occluder);
    const W: u32 = 64;
    const ROWS: u32 = 8;
    let px = |x: u32| -2.0 + 4.0 * (x as f32 + 0.5) / W as f32;
    let light = LightInfo::Point {
        position: Vec3::new(0.0, big_h, 0.0),
        radius: a,
        range: 100.0,
    };
    let mut vis = vec![0.0f64; W as usize];
    let frames = 24;
    for frame in 0..frames {
        let out = output(W, ROWS, -5.0);
        let mut c = common(
            gbuffer(W, ROWS, |x, y| {
                Some((Vec3::new(px(x), 0.0, (y as f32 - 4.0) * 0.05), Vec3::Y))
            }),
            Vec3::new(0.0, 5.0, 0.0),
        );
        c.debug_parameters.frame_index = frame;
        run(
            &scene,
            &[RenderTask::TraceShadow(TraceShadowTask {
                common: c,
                output: out.clone(),
                light,
                enable_first_hit_and_end_search: true,
            })],
        );
        for (i, v) in read(&out).iter().enumerate() {
            vis[i % W as usize] += (v[0] < 0.0) as u32 as f64 / (frames * ROWS) as f64;
        }
    }
    let width = 2.0 * a * h / (big_h - h);
    let pixel = 4.0 / W as f32;
    for (x, v) in vis.iter().enumerate() {
        // The edge projects to q = -x·h/(H-h) on the light's disc (here h = H - h).
        let want = disc_fraction_above(-(px(x as u32) * h / (big_h - h) / a) as f64);
        assert!(
            (v - want).abs() < 0.08,
            "x {}: visible {v}, want {want}",
            px(x as u32)
        );
    }
    // Width between the first texel above 0 and the first at 1, against 2a·h/(H−h).
    let first_lit = vis.iter().position(|v| *v > 0.0).unwrap() as f32;
    let first_full = vis.iter().position(|v| *v >= 1.0).unwrap() as f32;
    let measured = (first_full - first_lit) * pixel;
    assert!(
        (measured - width).abs() <= 2.0 * pixel,
        "penumbra {measured}, similar triangles {width}"
    );
}

#[test]
fn multi_shadow_packs_each_lights_visibility() {
    let (centre, r) = (Vec3::new(0.0, 1.0, 0.0), 0.5);
    let scene = TestScene::single(sphere(centre, r, 24));
    let mut rng = testing::Rng(3);
    let lights: Vec<LightInfo> = (0..20)
        .map(|_| LightInfo::Point {
            position: Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(2.0, 4.0),
                rng.range(-1.0, 1.0),
            ),
            radius: 0.0,
            range: 100.0,
        })
        .collect();
    let out0 = output(N, N, -5.0);
    let out1 = output(N, N, -5.0);
    let c = common(gbuffer(N, N, floor), Vec3::new(0.0, 5.0, 0.0));
    run(
        &scene,
        &[RenderTask::TraceMultiShadow(TraceMultiShadowTask {
            common: c,
            output0: out0.clone(),
            output1: out1.clone(),
            lights: lights.clone(),
            enable_first_hit_and_end_search: true,
        })],
    );
    let (img0, img1) = (read(&out0), read(&out1));
    let mut checked = 0;
    let mut partial = 0;
    'pixels: for y in 0..N {
        for x in 0..N {
            let (p, _) = floor(x, y).unwrap();
            let mut want = [0u32; 4];
            let mut visible = 0;
            for (i, l) in lights.iter().enumerate() {
                let LightInfo::Point { position, .. } = l else {
                    unreachable!()
                };
                let dir = (*position - p).normalize();
                let oc = centre - p;
                let miss_by = (oc - dir * oc.dot(dir)).length() - r;
                if miss_by.abs() < 0.02 {
                    continue 'pixels;
                }
                if miss_by > 0.0 {
                    want[i / 8] |= 1 << (i % 8);
                    visible += 1;
                }
            }
            let i = (y * N + x) as usize;
            let got = img1[i].map(|v| v as u32);
            assert_eq!(got, want, "bits at {x},{y}");
            // A GPU division may be off by an ulp (WGSL allows 2.5); one light is 0.05.
            let fraction = visible as f32 / 20.0;
            assert!(
                (img0[i][0] - fraction).abs() <= 1e-6,
                "visible fraction at {x},{y}: {} for {visible} of 20",
                img0[i][0]
            );
            assert_eq!(img0[i][3], 20.0);
            if visible > 0 && visible < 20 {
                partial += 1;
                assert!(img0[i][1] > 0.0 && img0[i][2] >= img0[i][1]);
            } else if visible == 20 {
                assert_eq!((img0[i][1], img0[i][2]), (-1.0, -1.0));
            }
            checked += 1;
        }
    }
    assert!(
        checked > 150 && partial > 50,
        "{checked} checked, {partial} partial"
    );
}
