//! Specular and diffuse against a stand-in cache: mirror reflections hit the predicted
//! triangles, a furnace returns its radiance at every roughness, diffuse GI matches a CPU
//! path-traced oracle, environment-map misses, demodulation, and the engine's direct lighting
//! read where the hit is visible in it.

use super::*;

/// A stand-in for the lighting cache's sampling module (same bindings and function): one colour
/// per (instance, primitive), so the radiance passes are checked independently of the cache.
const STUB_CACHE_WGSL: &str = r#"
#param CACHE_GROUP
#param SURFEL_ACCESS
@group({{CACHE_GROUP}}) @binding(0) var<storage, read> cache_meta: array<u32>;
@group({{CACHE_GROUP}}) @binding(1) var<storage, {{SURFEL_ACCESS}}> cache_surfels: array<vec4<f32>>;
fn cache_radiance(instance: u32, prim: u32, bary: vec2<f32>, bilinear: bool) -> vec3<f32> {
    return cache_surfels[cache_meta[instance] + prim].xyz;
}
"#;

/// Records `tasks` with the stand-in cache holding `colours[instance][primitive]`.
pub(super) fn run_cached(scene: &TestScene, colours: &[Vec<Vec3>], tasks: &[RenderTask]) {
    assert_eq!(scene.buffers().backend(), testing::backend());
    let g = testing::gpu();
    let mut passes = TracePasses::new(&g.device, &g.queue, testing::backend());
    passes.library.replace("cache/sample", STUB_CACHE_WGSL);
    let mut base = Vec::new();
    let mut flat: Vec<[f32; 4]> = Vec::new();
    for c in colours {
        base.push(flat.len() as u32);
        flat.extend(c.iter().map(|v| v.extend(0.0).to_array()));
    }
    let base = testing::buffer_with(bytemuck::cast_slice(&base));
    let flat = testing::buffer_with(bytemuck::cast_slice(&flat));
    let entries = [
        ("cache_meta", base.as_entire_binding()),
        ("cache_surfels", flat.as_entire_binding()),
    ];
    testing::run(|rec| {
        for t in tasks {
            let job = TracePasses::job(t).expect("a trace task");
            passes.record(rec, &scene.buffers(), &entries, &job);
        }
    });
}

pub(super) fn specular(c: TraceTaskCommon, out: &TextureInput) -> RenderTask {
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
        ambient_occlusion: None,
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
    let texels = random_texels(&mut rng, 0.5);
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

/// Ambient occlusion written by the diffuse pass from its own rays: in front of a wall at
/// distance d (radius R, c = d / R) it matches the AO task's closed form (mean 2c − c²,
/// occluded fraction 1 − c²; see the AO tests), and every pixel's AO is the diffuse output's own
/// hit distance over the radius (1 beyond it): the same rays.
#[test]
fn diffuse_writes_ambient_occlusion_from_its_own_rays() {
    let (d, radius) = (0.3f32, 1.0f32);
    let wall = square(2, -d, 20.0);
    let colours = vec![vec![Vec3::ONE; wall.len()]];
    let scene = TestScene::single(wall);
    let g = |x: u32, y: u32| {
        let f = |i: u32| -0.5 + (i as f32 + 0.5) / N as f32;
        Some((Vec3::new(f(x), f(y), 0.0), Vec3::NEG_Z))
    };
    let c = d / radius;
    let (mut sum, mut occluded, mut n) = (0.0f64, 0usize, 0usize);
    for frame in 0..12 {
        let (out, ao) = (output(N, N, -5.0), output(N, N, -5.0));
        let mut cm = common(gbuffer(N, N, g), Vec3::new(0.0, 0.0, 2.0));
        cm.debug_parameters.frame_index = frame;
        let task = RenderTask::TraceDiffuse(TraceDiffuseTask {
            ambient_occlusion: Some(DiffuseAmbientOcclusion {
                output: ao.clone(),
                ao_radius: radius,
            }),
            ..TraceDiffuseTask::new(cm, out.clone())
        });
        run_cached(&scene, &colours, &[task]);
        let (radiance, ao) = (read(&out), read(&ao));
        for (i, (r, a)) in radiance.iter().zip(&ao).enumerate() {
            let t = r[3];
            let want = if t <= radius { t / radius } else { 1.0 };
            assert!(
                (a[0] - want).abs() < 1e-5,
                "frame {frame} texel {i}: AO {} for a hit at {t}",
                a[0]
            );
            sum += a[0] as f64;
            occluded += (a[0] < 1.0) as usize;
            n += 1;
        }
    }
    let mean = sum / n as f64;
    let frac = occluded as f64 / n as f64;
    let want = (2.0 * c - c * c) as f64;
    assert!(
        (mean - want).abs() < 0.01,
        "mean {mean}, closed form {want}"
    );
    assert!(
        (frac - (1.0 - c * c) as f64).abs() < 0.01,
        "occluded fraction {frac}"
    );
}
