//! Shadows against analytic answers: a sphere over a plane (point and directional lights), the
//! penumbra width of an edge under a sphere light and under a directional light's angular
//! extent, a spot light's cone, and the packed per-light visibility of the multi-shadow pass.

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
                assert_eq!(v, -LIT_MIN, "{light:?}: lit at {x},{y}");
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

/// A lit pixel's value for a light without size: minus 2^-14, the smallest normal f16, where
/// a sized light writes minus the tangent of its angular radius.
const LIT_MIN: f32 = 6.103_515_6e-5;

/// The value the shadow trace writes where `light` is visible from `p`: minus the tangent of its
/// angular radius seen from there, at least [`LIT_MIN`].
fn lit_value(light: LightInfo, p: Vec3) -> f32 {
    let tan = match light {
        LightInfo::Directional { angular_extent, .. } => (angular_extent * 0.5).tan(),
        LightInfo::Point {
            position, radius, ..
        }
        | LightInfo::Spot {
            position, radius, ..
        } => radius / (position - p).length(),
    };
    -tan.max(LIT_MIN)
}

/// Fraction of a unit disc with coordinate > s (s in [-1, 1]).
fn disc_fraction_above(s: f64) -> f64 {
    let s = s.clamp(-1.0, 1.0);
    (s.acos() - s * (1.0 - s * s).sqrt()) / std::f64::consts::PI
}

/// A sphere light of radius a at height H over a half-plane occluder edge at height h: the
/// penumbra on the floor is 2a·h/(H − h) wide (similar triangles), and the visible fraction at x
/// is the fraction of the light's disc beyond the edge's projection.
/// Columns and rows of the penumbra tests' floor images.
const COLUMNS: u32 = 64;
const ROWS: u32 = 8;

/// An occluding half-plane: x in [-10, 0] at height `h`, over the floor at y = 0.
fn half_plane_occluder(h: f32) -> TestScene {
    let occluder: Vec<Tri> = square(1, h, 5.0)
        .into_iter()
        .map(|t| t.map(|v| v + Vec3::new(-5.0, 0.0, 0.0)))
        .collect();
    TestScene::single(occluder)
}

/// The share of texels `light` lights in each column of the floor y = 0 (column x at
/// `px(x)`, [`ROWS`] rows 0.05 apart in z), over `frames` frames of the shadow pass's noise.
/// Every lit texel holds [`lit_value`].
fn lit_fraction_per_column(
    scene: &TestScene,
    light: LightInfo,
    px: impl Fn(u32) -> f32,
    frames: u32,
) -> Vec<f64> {
    let mut vis = vec![0.0f64; COLUMNS as usize];
    for frame in 0..frames {
        let out = output(COLUMNS, ROWS, -5.0);
        let mut c = common(
            gbuffer(COLUMNS, ROWS, |x, y| {
                Some((Vec3::new(px(x), 0.0, (y as f32 - 4.0) * 0.05), Vec3::Y))
            }),
            Vec3::new(0.0, 5.0, 0.0),
        );
        c.debug_parameters.frame_index = frame;
        run(
            scene,
            &[RenderTask::TraceShadow(TraceShadowTask {
                common: c,
                output: out.clone(),
                light,
                enable_first_hit_and_end_search: true,
            })],
        );
        for (i, v) in read(&out).iter().enumerate() {
            let (x, y) = (i as u32 % COLUMNS, i as u32 / COLUMNS);
            if v[0] < 0.0 {
                let p = Vec3::new(px(x), 0.0, (y as f32 - 4.0) * 0.05);
                let want = lit_value(light, p);
                assert!(
                    (v[0] - want).abs() <= 1e-4 * want.abs(),
                    "{light:?}: lit texel {x},{y} holds {}, want {want}",
                    v[0]
                );
            }
            vis[x as usize] += (v[0] < 0.0) as u32 as f64 / (frames * ROWS) as f64;
        }
    }
    vis
}

#[test]
fn penumbra_width_matches_similar_triangles() {
    let (a, big_h, h) = (0.5f32, 4.0f32, 2.0f32);
    let scene = half_plane_occluder(h);
    let px = |x: u32| -2.0 + 4.0 * (x as f32 + 0.5) / COLUMNS as f32;
    let light = LightInfo::Point {
        position: Vec3::new(0.0, big_h, 0.0),
        radius: a,
        range: 100.0,
    };
    let vis = lit_fraction_per_column(&scene, light, px, 24);
    let width = 2.0 * a * h / (big_h - h);
    let pixel = 4.0 / COLUMNS as f32;
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

/// A spot light 2 above the floor under a ceiling that covers everything at height 1: the floor
/// texels inside the cone (angle to the axis below `apex_angle`, the half-angle) are traced and
/// find the ceiling halfway to the light; those outside are not traced and read as lit,
/// though the ceiling is in the way. Straight down, the cone meets the floor in the circle of
/// radius 2·tan(apex); tilted, in an ellipse (the angle decides).
#[test]
fn spot_light_traces_inside_its_cone_only() {
    let scene = TestScene::single(square(1, 1.0, 5.0));
    let position = Vec3::new(0.0, 2.0, 0.0);
    let apex = 30f32.to_radians();
    for direction in [Vec3::NEG_Y, Vec3::new(0.4, -1.0, 0.2).normalize()] {
        let out = output(N, N, -5.0);
        let c = common(gbuffer(N, N, floor), Vec3::new(0.0, 5.0, 0.0));
        let light = LightInfo::Spot {
            position,
            direction,
            radius: 0.0,
            range: 100.0,
            apex_angle: apex,
        };
        run(
            &scene,
            &[RenderTask::TraceShadow(TraceShadowTask {
                common: c,
                output: out.clone(),
                light,
                enable_first_hit_and_end_search: false,
            })],
        );
        let img = read(&out);
        let (mut inside, mut outside) = (0, 0);
        for y in 0..N {
            for x in 0..N {
                let (p, _) = floor(x, y).unwrap();
                let to_p = p - position;
                let angle = to_p.normalize().dot(direction).clamp(-1.0, 1.0).acos();
                if direction == Vec3::NEG_Y {
                    // The same edge from the circle's radius, independently of the angle.
                    let radius = 2.0 * apex.tan();
                    let r = Vec3::new(p.x, 0.0, p.z).length();
                    assert_eq!(r < radius, angle < apex, "texel {x},{y}");
                }
                let v = img[(y * N + x) as usize][0];
                // 0.01 rad either side of the edge: about 0.03 world units on the floor.
                if angle < apex - 0.01 {
                    inside += 1;
                    let want = to_p.length() / 2.0;
                    assert!(
                        (v - want).abs() < 1e-3 * want,
                        "{direction}: texel {x},{y} inside the cone ({angle} rad): {v}, the \
                         ceiling at {want}"
                    );
                } else if angle > apex + 0.01 {
                    outside += 1;
                    assert_eq!(
                        v, -LIT_MIN,
                        "{direction}: texel {x},{y} outside the cone ({angle} rad) was traced"
                    );
                }
            }
        }
        assert!(
            inside > 100 && outside > 100,
            "{direction}: {inside} texels inside the cone, {outside} outside"
        );
    }
}

/// A directional light straight down over an occluder edge at height h (x < 0 covered): with
/// angular extent θ (full angle) its rays are aimed through a disc of radius tan(θ/2) at unit
/// distance, so the visible fraction at x is the part of that disc beyond −x / (h·tan(θ/2)) and
/// the penumbra is 2h·tan(θ/2) wide; with extent 0 the edge is hard (x > 0 lit, x < 0 not).
#[test]
fn directional_light_penumbra_width_follows_its_angular_extent() {
    let h = 1.0f32;
    let scene = half_plane_occluder(h);
    let px = |x: u32| -1.0 + 2.0 * (x as f32 + 0.5) / COLUMNS as f32;
    let pixel = 2.0 / COLUMNS as f32;
    let visibility = |extent: f32, frames: u32| {
        let light = LightInfo::Directional {
            direction: Vec3::NEG_Y,
            angular_extent: extent,
        };
        lit_fraction_per_column(&scene, light, px, frames)
    };

    // Hard: every texel exactly lit or shadowed by the side of the edge it is on.
    for (x, v) in visibility(0.0, 1).iter().enumerate() {
        let want = if px(x as u32) > 0.0 { 1.0 } else { 0.0 };
        assert_eq!(*v, want, "extent 0: x {} visible {v}", px(x as u32));
    }

    let extent = 0.4f32;
    let spread = h * (extent / 2.0).tan();
    let width = 2.0 * spread;
    let vis = visibility(extent, 24);
    for (x, v) in vis.iter().enumerate() {
        let want = disc_fraction_above(-(px(x as u32) / spread) as f64);
        assert!(
            (v - want).abs() < 0.08,
            "extent {extent}: x {}: visible {v}, want {want}",
            px(x as u32)
        );
    }
    // Width between the first texel above 0 and the first at 1, against 2h·tan(θ/2).
    let first_lit = vis.iter().position(|v| *v > 0.0).unwrap() as f32;
    let first_full = vis.iter().position(|v| *v >= 1.0).unwrap() as f32;
    let measured = (first_full - first_lit) * pixel;
    eprintln!(
        "penumbra {measured}, analytic {width} ({} texels)",
        width / pixel
    );
    assert!(
        (measured - width).abs() <= 2.0 * pixel,
        "extent {extent}: penumbra {measured}, analytic 2h·tan(θ/2) = {width}"
    );
}
