//! The trace passes against analytic answers: G-buffers of known surfaces (world-position depth,
//! vector normals), scenes packed by `TestScene`, outputs read back and compared with closed-form
//! AO, sphere shadows, penumbra widths and per-light visibility computed on the CPU.

use super::*;
use crate::gpu::testing;
use crate::trace::test_scene::{cube, TestScene, Tri};
use glam::{Mat4, Vec3};

/// A G-buffer texel: world position and unit normal, or `None` (nothing rendered).
type Texel = Option<(Vec3, Vec3)>;

/// The world-position depth and vector normal inputs of `w × h` texels from `f(x, y)`.
fn gbuffer(w: u32, h: u32, f: impl Fn(u32, u32) -> Texel) -> (DepthInput, NormalInput) {
    let mut pos = Vec::new();
    let mut nor = Vec::new();
    for y in 0..h {
        for x in 0..w {
            match f(x, y) {
                Some((p, n)) => {
                    pos.extend_from_slice(&[p.x, p.y, p.z, 1.0]);
                    nor.extend_from_slice(&[n.x, n.y, n.z, 0.0]);
                }
                None => {
                    pos.extend_from_slice(&[f32::NAN; 4]);
                    nor.extend_from_slice(&[0.0; 4]);
                }
            }
        }
    }
    let f = wgpu::TextureFormat::Rgba32Float;
    (
        DepthInput {
            texture: testing::texture_with(f, w, h, bytemuck::cast_slice(&pos)),
            depth_type: DepthType::RgbWorldSpace,
        },
        NormalInput {
            texture: testing::texture_with(f, w, h, bytemuck::cast_slice(&nor)),
            normal_type: NormalType::RgbVector,
            normal_to_world: Mat4::IDENTITY,
        },
    )
}

/// The common inputs of a G-buffer seen from `eye` (only the eye matters with world-position
/// depth: it gives the view distance).
fn common(g: (DepthInput, NormalInput), eye: Vec3) -> TraceTaskCommon {
    let mut c = TraceTaskCommon::new(g.0, g.1);
    let up = if eye.normalize().y.abs() > 0.9 {
        Vec3::NEG_Z
    } else {
        Vec3::Y
    };
    c.view.world_to_view = Mat4::look_at_rh(eye, Vec3::ZERO, up);
    assert!(c.view.world_to_view.is_finite());
    c.view.view_to_clip = Mat4::perspective_rh(1.0, 1.0, 0.1, 100.0);
    c.ray_offset.offset_type = RayOffsetType::WorldPosition;
    c
}

/// A `w × h` Rgba32Float output filled with `fill`.
fn output(w: u32, h: u32, fill: f32) -> TextureInput {
    let data = vec![fill; (w * h * 4) as usize];
    testing::texture_with(
        wgpu::TextureFormat::Rgba32Float,
        w,
        h,
        bytemuck::cast_slice(&data),
    )
}

/// Reads an Rgba32Float texture back.
fn read(t: &TextureInput) -> Vec<[f32; 4]> {
    let g = testing::gpu();
    let tex = t.texture();
    let (w, h) = (tex.width(), tex.height());
    let row = (w * 16).div_ceil(256) * 256;
    let buf = testing::buffer(row as u64 * h as u64);
    let mut enc = g.device.create_command_encoder(&Default::default());
    enc.copy_texture_to_buffer(
        tex.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buf,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: None,
            },
        },
        tex.size(),
    );
    g.queue.submit([enc.finish()]);
    let bytes = testing::read_back(&buf, 0, row as u64 * h as u64);
    let mut out = Vec::new();
    for y in 0..h {
        let start = (y * row) as usize;
        let floats: &[f32] = bytemuck::cast_slice(&bytes[start..start + (w * 16) as usize]);
        out.extend(floats.chunks(4).map(|c| [c[0], c[1], c[2], c[3]]));
    }
    out
}

/// Records `tasks` with one set of passes and waits.
fn run(scene: &TestScene, tasks: &[RenderTask]) {
    let g = testing::gpu();
    let mut passes = TracePasses::new(&g.device, &g.queue);
    testing::run(|rec| {
        for t in tasks {
            passes.record(rec, &scene.buffers(), &[], t).unwrap();
        }
    });
}

/// A square in the plane `axis = at` of half-size `s` (both windings are hit).
fn square(axis: usize, at: f32, s: f32) -> Vec<Tri> {
    let p = |a: f32, b: f32| {
        let mut v = [0.0; 3];
        v[axis] = at;
        v[(axis + 1) % 3] = a;
        v[(axis + 2) % 3] = b;
        Vec3::from(v)
    };
    vec![
        [p(-s, -s), p(s, -s), p(s, s)],
        [p(-s, -s), p(s, s), p(-s, s)],
    ]
}

/// A UV sphere (`rings` × 2·`rings` quads).
fn sphere(centre: Vec3, r: f32, rings: u32) -> Vec<Tri> {
    let seg = rings * 2;
    let p = |i: u32, j: u32| {
        let th = std::f32::consts::PI * i as f32 / rings as f32;
        let ph = std::f32::consts::TAU * j as f32 / seg as f32;
        centre + r * Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin())
    };
    let mut t = Vec::new();
    for i in 0..rings {
        for j in 0..seg {
            t.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
            t.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
        }
    }
    t
}

fn ao(c: TraceTaskCommon, out: &TextureInput, radius: f32) -> RenderTask {
    RenderTask::TraceAmbientOcclusion(TraceAmbientOcclusionTask {
        common: c,
        output: out.clone(),
        ao_radius: radius,
    })
}

const N: u32 = 32;

/// Floor texels: y = 0, normal +y, x and z spanning [-2, 2] over the N×N grid.
fn floor(x: u32, y: u32) -> Texel {
    let f = |i: u32| -2.0 + 4.0 * (i as f32 + 0.5) / N as f32;
    Some((Vec3::new(f(x), 0.0, f(y)), Vec3::Y))
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

#[test]
fn ao_inside_a_closed_box_is_near_zero() {
    // A closed box of half-size 0.1; points inside it, random normals; radius 10: every ray hits
    // within the box's diagonal, so the output is at most 0.35 / 10.
    let box_tris: Vec<Tri> = cube(2).into_iter().map(|t| t.map(|v| v * 0.1)).collect();
    let scene = TestScene::single(box_tris);
    let mut rng = testing::Rng(7);
    let texels: Vec<Texel> = (0..N * N)
        .map(|_| {
            let p = Vec3::new(
                rng.range(-0.05, 0.05),
                rng.range(-0.05, 0.05),
                rng.range(-0.05, 0.05),
            );
            let n = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            )
            .try_normalize()
            .unwrap_or(Vec3::Y);
            Some((p, n))
        })
        .collect();
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
fn checkerboard_modes_write_exactly_their_pixels_and_the_mask_skips() {
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
                let parity = (x - vp.x.min(x) + y - vp.y.min(y)) % 2;
                let traced = inside
                    && x != 10
                    && match mode {
                        HalfResolutionMode::Off => true,
                        HalfResolutionMode::Checkerboard => parity == 0,
                        HalfResolutionMode::CheckerboardInverted => parity == 1,
                    };
                let want = if traced { 1.0 } else { -5.0 };
                assert_eq!(img[(y * N + x) as usize][0], want, "{mode:?} at {x},{y}");
            }
        }
    }
}

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

#[test]
fn every_pipeline_compiles_including_prepared_ones() {
    let g = testing::gpu();
    let mut passes = TracePasses::new(&g.device, &g.queue);
    passes.prepare(&g.device);
    assert_eq!(passes.pipelines.len(), 8);
    for f in crate::WRITABLE_OUTPUT_FORMATS {
        passes
            .pipeline(&g.device, TraceKind::AmbientOcclusion, (f, None))
            .unwrap();
    }
    assert!(passes
        .pipeline(
            &g.device,
            TraceKind::Shadow,
            (wgpu::TextureFormat::Rgba8Unorm, None)
        )
        .is_err());
    // Where the device takes our SPIR-V, every pass must come from it (a pass that silently fell
    // back to WGSL would zero-fill its stack per invocation again).
    let expected = crate::gpu::shader::spirv_accepted(&g.device);
    for p in &passes.pipelines {
        assert_eq!(p.own_spirv, expected, "{} {:?}", p.kind.label(), p.formats);
    }
}

// ---- specular and diffuse, against a stand-in cache ---------------------------------------------

/// A stand-in for the lighting cache's sampling module (same bindings and function): one colour
/// per (instance, primitive), so the radiance passes are checked independently of the cache.
const STUB_CACHE_WGSL: &str = r#"
@group(3) @binding(0) var<storage, read> stub_base: array<u32>;
@group(3) @binding(1) var<storage, read> stub_colour: array<vec4<f32>>;
fn cache_radiance(instance: u32, prim: u32, bary: vec2<f32>, bilinear: bool) -> vec3<f32> {
    return stub_colour[stub_base[instance] + prim].xyz;
}
"#;

/// Records `tasks` with the stand-in cache holding `colours[instance][primitive]`.
fn run_cached(scene: &TestScene, colours: &[Vec<Vec3>], tasks: &[RenderTask]) {
    let g = testing::gpu();
    let mut passes = TracePasses::new(&g.device, &g.queue);
    passes.cache_wgsl = STUB_CACHE_WGSL.to_string();
    let mut base = Vec::new();
    let mut flat: Vec<[f32; 4]> = Vec::new();
    for c in colours {
        base.push(flat.len() as u32);
        flat.extend(c.iter().map(|v| v.extend(0.0).to_array()));
    }
    let base = testing::buffer_with(bytemuck::cast_slice(&base));
    let flat = testing::buffer_with(bytemuck::cast_slice(&flat));
    let entries = [
        wgpu::BindGroupEntry {
            binding: 0,
            resource: base.as_entire_binding(),
        },
        wgpu::BindGroupEntry {
            binding: 1,
            resource: flat.as_entire_binding(),
        },
    ];
    testing::run(|rec| {
        for t in tasks {
            passes.record(rec, &scene.buffers(), &entries, t).unwrap();
        }
    });
}

fn specular(c: TraceTaskCommon, out: &TextureInput) -> RenderTask {
    RenderTask::TraceSpecular(TraceSpecularTask {
        common: c,
        output: out.clone(),
        demodulate_specular: false,
        demodulation_output: None,
    })
}

fn diffuse(c: TraceTaskCommon, out: &TextureInput, brdf: DiffuseBrdf) -> RenderTask {
    RenderTask::TraceDiffuse(TraceDiffuseTask {
        common: c,
        output: out.clone(),
        diffuse_brdf: brdf,
    })
}

/// A distinct colour per primitive.
fn prim_colour(p: usize) -> Vec3 {
    Vec3::new(p as f32, (p % 7) as f32 * 0.5, 1.0 + (p / 7) as f32)
}

/// A grid of `n × n` quads (2 triangles each) over [-s, s]² in the plane z = at; triangle 2k
/// below the diagonal of quad k (row-major from −s), 2k + 1 above.
fn grid_wall(n: usize, s: f32, at: f32) -> Vec<Tri> {
    let step = 2.0 * s / n as f32;
    let mut t = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let p = |a: usize, b: usize| Vec3::new(-s + a as f32 * step, -s + b as f32 * step, at);
            t.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
            t.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
        }
    }
    t
}

/// A mirror (roughness 0) in the plane z = 0 facing a wall of differently coloured triangles
/// at z = 3: each pixel returns the colour of the triangle its exact reflection hits, and the
/// hit distance.
#[test]
fn mirror_returns_the_colour_of_the_triangle_the_reflection_hits() {
    let (n, s, wall_z) = (8usize, 4.0f32, 3.0f32);
    let wall = grid_wall(n, s, wall_z);
    let colours: Vec<Vec3> = (0..wall.len()).map(prim_colour).collect();
    let scene = TestScene::single(wall);
    let eye = Vec3::new(0.3, 0.2, 1.5);
    let mirror = |x: u32, y: u32| {
        let f = |i: u32| -1.0 + 2.0 * (i as f32 + 0.5) / N as f32;
        Some((Vec3::new(f(x), f(y), 0.0), Vec3::Z))
    };
    for rng in [
        RandomNumberGenerator::BlueNoise,
        RandomNumberGenerator::Xorshift,
    ] {
        let out = output(N, N, -5.0);
        let mut c = common(gbuffer(N, N, mirror), eye);
        c.roughness.global_roughness = 0.0;
        c.debug_parameters.random_number_generator = rng;
        run_cached(&scene, std::slice::from_ref(&colours), &[specular(c, &out)]);
        let img = read(&out);
        let mut checked = 0;
        for y in 0..N {
            for x in 0..N {
                let (p, nrm) = mirror(x, y).unwrap();
                let v = (eye - p).normalize();
                let d = 2.0 * nrm.dot(v) * nrm - v;
                let t = (wall_z - p.z) / d.z;
                let q = p + d * t;
                let step = 2.0 * s / n as f32;
                let (gx, gy) = ((q.x + s) / step, (q.y + s) / step);
                let (fx, fy) = (gx.fract(), gy.fract());
                if fx.min(1.0 - fx) < 0.01 || fy.min(1.0 - fy) < 0.01 || (fx - fy).abs() < 0.01 {
                    continue; // on an edge: either triangle is right
                }
                let quad = gy as usize * n + gx as usize;
                let prim = 2 * quad + (fy > fx) as usize;
                let got = img[(y * N + x) as usize];
                assert_eq!(
                    Vec3::new(got[0], got[1], got[2]),
                    colours[prim],
                    "{rng:?} pixel {x},{y}: want triangle {prim}"
                );
                assert!(
                    (got[3] - t).abs() < 1e-3 * t,
                    "distance {} want {t}",
                    got[3]
                );
                checked += 1;
            }
        }
        assert!(checked > 800, "{checked}");
    }
}

/// Inside a closed sphere whose every triangle caches radiance L, every specular ray at every
/// roughness and every diffuse ray returns L (nothing escapes, nothing is NaN).
#[test]
fn furnace_with_a_uniform_stand_in_cache_gives_l_at_every_roughness() {
    let tris = sphere(Vec3::ZERO, 1.0, 12);
    let l = Vec3::new(0.25, 0.5, 2.0);
    let colours = vec![vec![l; tris.len()]];
    let scene = TestScene::single(tris);
    let mut rng = testing::Rng(11);
    let texels: Vec<Texel> = (0..N * N)
        .map(|_| {
            let p = Vec3::new(
                rng.range(-0.5, 0.5),
                rng.range(-0.5, 0.5),
                rng.range(-0.5, 0.5),
            );
            let n = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            )
            .try_normalize()
            .unwrap_or(Vec3::Y);
            Some((p, n))
        })
        .collect();
    let gb = |x: u32, y: u32| texels[(y * N + x) as usize];
    for roughness in [0.0, 0.1, 0.4, 0.8, 1.0] {
        let out = output(N, N, -5.0);
        let mut c = common(gbuffer(N, N, gb), Vec3::new(0.0, 0.9, 0.0));
        c.roughness.global_roughness = roughness;
        let d_out = output(N, N, -5.0);
        let dc = c.clone();
        run_cached(
            &scene,
            &colours,
            &[
                specular(c, &out),
                diffuse(dc, &d_out, DiffuseBrdf::Lambertian),
            ],
        );
        for (what, img) in [("specular", read(&out)), ("diffuse", read(&d_out))] {
            for (i, v) in img.iter().enumerate() {
                assert_eq!(
                    Vec3::new(v[0], v[1], v[2]),
                    l,
                    "{what} r {roughness} texel {i}"
                );
                assert!(v[3] > 0.0 && v[3] < 2.0, "{what}: distance {}", v[3]);
            }
        }
    }
}

/// Diffuse GI of a floor point in a corner of coloured walls against a CPU path-traced oracle
/// (same colours at hits, cosine-weighted rays through the CPU traversal, many samples).
#[test]
fn diffuse_matches_a_cpu_path_traced_oracle() {
    const M: u32 = 16;
    // Two coloured walls (x = 1 and z = -1) and a ceiling patch; the rest escapes (black).
    let mut tris = Vec::new();
    let mut colours = Vec::new();
    for (t, c) in [
        (square(0, 1.0, 1.5), Vec3::new(1.0, 0.2, 0.1)),
        (square(2, -1.0, 1.5), Vec3::new(0.1, 0.9, 0.3)),
        (
            square(1, 1.2, 0.7)
                .into_iter()
                .map(|t| t.map(|v| v + Vec3::new(-0.5, 0.0, 0.5)))
                .collect(),
            Vec3::new(0.2, 0.3, 2.0),
        ),
    ] {
        colours.extend(std::iter::repeat_n(c, t.len()));
        tris.extend(t);
    }
    let scene = TestScene::single(tris);
    let pos = |x: u32, y: u32| {
        Vec3::new(
            -0.8 + 1.6 * (x as f32 + 0.5) / M as f32,
            0.0,
            -0.8 + 1.6 * (y as f32 + 0.5) / M as f32,
        )
    };
    let frames = 32;
    let blocks = (M / 4) as usize;
    let mut gpu = vec![Vec3::ZERO; blocks * blocks];
    for frame in 0..frames {
        let out = output(M, M, -5.0);
        let mut c = common(
            gbuffer(M, M, |x, y| Some((pos(x, y), Vec3::Y))),
            Vec3::new(0.0, 2.0, 0.5),
        );
        c.debug_parameters.frame_index = frame;
        run_cached(
            &scene,
            std::slice::from_ref(&colours),
            &[diffuse(c, &out, DiffuseBrdf::Lambertian)],
        );
        for (i, v) in read(&out).iter().enumerate() {
            let (x, y) = (i as u32 % M, i as u32 / M);
            gpu[(y / 4) as usize * blocks + (x / 4) as usize] +=
                Vec3::new(v[0], v[1], v[2]) / (16 * frames) as f32;
        }
    }
    // CPU oracle: 2048 cosine-weighted rays per pixel of each block.
    let mut rng = testing::Rng(5);
    for by in 0..blocks {
        for bx in 0..blocks {
            let mut sum = glam::DVec3::ZERO;
            let mut count = 0.0;
            for py in 0..4 {
                for pxl in 0..4 {
                    let p = pos(bx as u32 * 4 + pxl, by as u32 * 4 + py);
                    for _ in 0..2048 {
                        let (u1, u2) = (rng.range(0.0, 1.0), rng.range(0.0, 1.0));
                        let r = u1.sqrt();
                        let phi = std::f32::consts::TAU * u2;
                        let d = Vec3::new(r * phi.cos(), (1.0 - u1).max(0.0).sqrt(), r * phi.sin());
                        let ray = crate::cpu::Ray {
                            origin: p,
                            dir: d,
                            t_min: 1e-4,
                            t_max: f32::INFINITY,
                        };
                        if let Some(h) = scene.closest_hit(&ray, 0xff) {
                            sum += colours[h.primitive as usize].as_dvec3();
                        }
                        count += 1.0;
                    }
                }
            }
            let want = (sum / count).as_vec3();
            let got = gpu[by * blocks + bx];
            // 512 GPU samples per block: standard error ≤ 0.5 · 2 / √512 ≈ 0.044 for the
            // brightest channel; 0.12 is about three of them.
            assert!(
                (got - want).abs().max_element() < 0.12,
                "block {bx},{by}: GPU {got}, oracle {want}"
            );
        }
    }
}

#[test]
fn environment_map_lights_misses_with_the_documented_lat_long_mapping() {
    // 8 × 2 texels: the top row red scaled by column, the bottom row blue.
    let mut env = Vec::new();
    for row in 0..2 {
        for col in 0..8 {
            let c = if row == 0 {
                [col as f32 + 1.0, 0.0, 0.0, 1.0]
            } else {
                [0.0, 0.0, 1.0, 1.0]
            };
            env.extend_from_slice(&c);
        }
    }
    let env = testing::texture_with(
        wgpu::TextureFormat::Rgba32Float,
        8,
        2,
        bytemuck::cast_slice(&env),
    );
    // No geometry on the way: a triangle far below.
    let scene = TestScene::single(square(1, -100.0, 1.0));
    // Mirror pixels whose reflection is straight up (eye straight above): the top row, which at
    // v = 0 is a mix of its own texels only; and a vertical mirror facing +x seen along the
    // normal: reflection +x, u = 0.75 → texel x = 5.5, v = 0.5 → halfway between the rows.
    let up = |_x: u32, _y: u32| Some((Vec3::ZERO, Vec3::Y));
    let out = output(4, 4, -5.0);
    let mut c = common(gbuffer(4, 4, up), Vec3::new(0.0, 3.0, 0.0));
    c.roughness.global_roughness = 0.0;
    c.environment_map = Some(env.clone());
    run_cached(&scene, &[vec![Vec3::ZERO; 2]], &[specular(c, &out)]);
    for v in read(&out) {
        // Straight up: v = 0 is clamped to the top row's centre line; u = 0.5 + atan2(0, -0)/2π
        // is undefined at the pole, so only the red channel's range and the others are checked.
        assert!(
            v[0] >= 1.0 && v[0] <= 8.0 && v[1] == 0.0 && v[2] == 0.0,
            "{v:?}"
        );
        assert_eq!(v[3], 65504.0);
    }
    let side = |_x: u32, _y: u32| Some((Vec3::ZERO, Vec3::X));
    let out = output(4, 4, -5.0);
    let mut c = common(gbuffer(4, 4, side), Vec3::new(3.0, 0.0, 0.0));
    c.roughness.global_roughness = 0.0;
    c.environment_map = Some(env);
    c.max_ray_length = 50.0;
    run_cached(&scene, &[vec![Vec3::ZERO; 2]], &[specular(c, &out)]);
    for v in read(&out) {
        let want = [(6.0 + 7.0) / 2.0 * 0.5, 0.0, 0.5];
        for k in 0..3 {
            assert!((v[k] - want[k]).abs() < 1e-3, "{v:?}, want {want:?}");
        }
        assert_eq!(v[3], 50.0, "a miss reads the ray's length");
    }
}

#[test]
fn demodulation_divides_by_the_specular_albedo_it_writes() {
    let scene = TestScene::single(square(1, 1.0, 50.0));
    let l = Vec3::new(0.5, 1.0, 1.5);
    let out = output(8, 8, -5.0);
    let demod = output(8, 8, -5.0);
    let g = |_x: u32, _y: u32| Some((Vec3::ZERO, Vec3::Y));
    let mut c = common(gbuffer(8, 8, g), Vec3::new(0.5, 0.8, 0.0));
    c.roughness.global_roughness = 0.5;
    c.specular.global_metalness = 0.6;
    run_cached(
        &scene,
        &[vec![l; 2]],
        &[RenderTask::TraceSpecular(TraceSpecularTask {
            common: c,
            output: out.clone(),
            demodulate_specular: true,
            demodulation_output: Some(demod.clone()),
        })],
    );
    let (img, dm) = (read(&out), read(&demod));
    for (o, d) in img.iter().zip(&dm) {
        // The albedo of F0 = 0.6 lies between F0·(1−ε) and 1, grey.
        assert!(
            d[0] > 0.4 && d[0] < 1.0 && d[0] == d[1] && d[1] == d[2],
            "{d:?}"
        );
        for k in 0..3 {
            assert!(
                (o[k] * d[k] - l[k]).abs() < 1e-4 * l[k].max(1.0),
                "{o:?} × {d:?}"
            );
        }
    }
}

/// A mirror floor under a camera that also sees the wall the floor reflects: reflections whose
/// hit is visible in the view read the engine's direct lighting texel there; those that leave
/// the view (or with no direct lighting bound) read the cache.
#[test]
fn direct_lighting_is_used_where_the_hit_is_visible_in_it() {
    const S: u32 = 32;
    let wall_z = -3.0f32;
    let wall = grid_wall(4, 4.0, wall_z);
    let colours: Vec<Vec3> = (0..wall.len()).map(prim_colour).collect();
    let scene = TestScene::single(wall);
    let eye = Vec3::new(0.0, 1.0, 2.0);
    let view = Mat4::look_at_rh(eye, Vec3::new(0.0, 0.6, wall_z), Vec3::Y);
    let proj = Mat4::perspective_rh(1.2, 1.0, 0.1, 100.0);
    let clip_to_world = (proj * view).inverse();
    let world_to_clip = proj * view;
    // CPU G-buffer: the first of floor (y = 0) and wall (z = wall_z) along each camera ray.
    let surface = |x: u32, y: u32| -> Texel {
        let ndc = glam::Vec2::new(
            (x as f32 + 0.5) / S as f32 * 2.0 - 1.0,
            1.0 - (y as f32 + 0.5) / S as f32 * 2.0,
        );
        let target = clip_to_world.project_point3(ndc.extend(0.5));
        let d = (target - eye).normalize();
        let t_floor = if d.y < 0.0 {
            -eye.y / d.y
        } else {
            f32::INFINITY
        };
        let t_wall = if d.z < 0.0 {
            (wall_z - eye.z) / d.z
        } else {
            f32::INFINITY
        };
        if t_floor < t_wall {
            Some((eye + d * t_floor, Vec3::Y))
        } else if t_wall.is_finite() {
            Some((eye + d * t_wall, Vec3::Z))
        } else {
            None
        }
    };
    let lighting: Vec<f32> = (0..S * S)
        .flat_map(|i| [(i % S) as f32, (i / S) as f32, 1000.0, 1.0])
        .collect();
    let lighting = testing::texture_with(
        wgpu::TextureFormat::Rgba32Float,
        S,
        S,
        bytemuck::cast_slice(&lighting),
    );
    let out = output(S, S, -5.0);
    let mut c = common(gbuffer(S, S, surface), eye);
    c.view.world_to_view = view;
    c.view.view_to_clip = proj;
    c.roughness.global_roughness = 0.0;
    c.direct_lighting = Some(lighting);
    run_cached(&scene, std::slice::from_ref(&colours), &[specular(c, &out)]);
    let img = read(&out);
    let (mut from_screen, mut from_cache) = (0, 0);
    for y in 0..S {
        for x in 0..S {
            let Some((p, n)) = surface(x, y) else {
                continue;
            };
            if n != Vec3::Y {
                continue; // wall pixels reflect away from the scene
            }
            let v = (eye - p).normalize();
            let r = 2.0 * n.dot(v) * n - v;
            if r.z >= 0.0 {
                continue;
            }
            let hit = p + r * ((wall_z - p.z) / r.z);
            let q = world_to_clip.project_point3(hit);
            let tx = (q.x + 1.0) * 0.5 * S as f32;
            let ty = (1.0 - q.y) * 0.5 * S as f32;
            let got = img[(y * S + x) as usize];
            let near_texel_edge = (tx - tx.round()).abs() < 0.02 || (ty - ty.round()).abs() < 0.02;
            let inside = (0.0..S as f32).contains(&tx) && (0.0..S as f32).contains(&ty);
            if inside && !near_texel_edge {
                // The wall is never occluded in this view: the texel there holds the hit.
                assert_eq!(
                    [got[0], got[1], got[2]],
                    [tx.floor(), ty.floor(), 1000.0],
                    "pixel {x},{y}: hit {hit} at texel {tx},{ty}"
                );
                from_screen += 1;
            } else if !inside
                && (tx < -0.5 || ty < -0.5 || tx > S as f32 + 0.5 || ty > S as f32 + 0.5)
            {
                assert!(
                    got[2] < 1000.0,
                    "pixel {x},{y}: off screen, from the cache: {got:?}"
                );
                from_cache += 1;
            }
        }
    }
    assert!(
        from_screen > 100 && from_cache > 5,
        "{from_screen} on screen, {from_cache} off"
    );
}

#[test]
fn a_dispatch_has_one_workgroup_per_tile_of_the_traced_grid() {
    // 21 × 13 pixels: 3 × 2 tiles of 8; checkerboard traces a grid of 11 × 13, 2 × 2 tiles.
    assert_eq!(traced_tiles(21, 13, false), Some(6));
    assert_eq!(traced_tiles(21, 13, true), Some(4));
    assert_eq!(traced_tiles(1920, 1080, false), Some(240 * 135));
    assert_eq!(traced_tiles(8, 8, false), Some(1));
    assert_eq!(traced_tiles(0, 8, false), Some(0));
    // 2^16 × 2^16 pixels need 2^32 invocations: more than the shader's u32 index holds.
    assert_eq!(traced_tiles(65_536, 65_536, false), None);
    assert_eq!(traced_tiles(65_536, 65_528, false), Some(8192 * 8191));
}
