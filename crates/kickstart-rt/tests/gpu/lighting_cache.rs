//! The direct lighting cache: injection from analytic images (CPU ray casts give depth and
//! lighting), read back through the DirectLightingCache / RandomTileColor debug views, sizes
//! against the documented formulas, allocation from a short pool, transfer, and exact
//! accumulation.

use crate::common;
use common::cache::*;
use common::rt::Mesh;
use common::*;
use glam::{Affine3A, Vec3, Vec4};
use kickstart_rt::*;

const MAGENTA: Vec4 = Vec4::new(1.0, 0.0, 1.0, 0.0);

/// A smooth function of the world position (positive everywhere in the test scenes).
fn gradient(p: Vec3) -> Vec3 {
    Vec3::new(0.5 + 0.2 * p.x, 0.5 + 0.2 * p.z, 0.3 + 0.2 * p.y)
}
/// Largest change of any channel of [`gradient`] per world unit.
const GRADIENT_SLOPE: f32 = 0.2;

/// The floor (x, z in [-2, 2] at y = 0) and the back wall (x in [-2, 2], y in [0, 2], z = -2).
fn room() -> [Rect; 2] {
    [
        Rect {
            origin: Vec3::new(-2.0, 0.0, -2.0),
            a: Vec3::new(0.0, 0.0, 4.0),
            b: Vec3::new(4.0, 0.0, 0.0),
        },
        Rect {
            origin: Vec3::new(-2.0, 0.0, -2.0),
            a: Vec3::new(4.0, 0.0, 0.0),
            b: Vec3::new(0.0, 2.0, 0.0),
        },
    ]
}

fn tile(unit: f32) -> impl Fn(&mut GeometryInput) {
    move |g: &mut GeometryInput| g.tile_unit_length = unit
}

/// Camera seeing the whole room.
fn overview() -> Camera {
    Camera {
        eye: Vec3::new(0.3, 4.0, 4.5),
        target: Vec3::new(0.0, 0.3, -0.8),
        fov_y: 1.1,
        w: 128,
        h: 128,
    }
}

/// A second camera, low and to the side.
fn side() -> Camera {
    Camera {
        eye: Vec3::new(-1.5, 1.2, 2.5),
        target: Vec3::new(0.5, 0.3, -1.0),
        fov_y: 1.0,
        w: 64,
        h: 64,
    }
}

/// Whether `cam` sees point `p` of the room (inside its image by `margin` pixels, unoccluded).
fn sees(cam: &Camera, rects: &[Rect], p: Vec3, margin: f32) -> bool {
    let (px, _) = cam.project(p);
    if px.x < margin
        || px.y < margin
        || px.x > cam.w as f32 - margin
        || px.y > cam.h as f32 - margin
    {
        return false;
    }
    let d = p - cam.eye;
    cast(rects, cam.eye, d.normalize()).is_some_and(|(t, _)| (t - d.length()).abs() < 1e-3)
}

#[test]
fn gradient_injected_from_one_camera_reads_back_from_another() {
    for (depth, surfel_type) in [
        (Depth::Clip, SurfelType::MeshColors),
        (Depth::World, SurfelType::WarpedBarycentricStorage),
    ] {
        inject_gradient_and_check(depth, surfel_type);
    }
}

/// Injects [`gradient`] into the room from the overview camera with depth stored as `depth`,
/// reads the cache back through the side camera's DirectLightingCache view (nearest, then
/// bilinear) and checks it against the gradient; returns both views.
fn inject_gradient_and_check(depth: Depth, surfel_type: SurfelType) -> [Vec<Vec4>; 2] {
    let mut views = Vec::new();
    let ctx = context(4);
    let rects = room();
    let floor = rects[0].mesh(4, false);
    let wall = rects[1].mesh(4, false);
    // A quad standing on the floor without DIRECT_LIGHT_INJECTION_TARGET: both cameras
    // see it, injection skips it (and the floor it hides from the overview).
    let hidden = Rect {
        origin: Vec3::new(0.2, 0.0, 0.0),
        a: Vec3::new(1.0, 0.0, 0.0),
        b: Vec3::new(0.0, 0.8, 0.0),
    };
    let unit = 0.4;
    let edit = move |g: &mut GeometryInput| {
        g.tile_unit_length = unit;
        g.surfel_type = surfel_type;
    };
    let hidden_mesh = hidden.mesh(1, false);
    let (_, inst) = scene(
        &ctx,
        &[(&floor, &edit), (&wall, &edit), (&hidden_mesh, &edit)],
        &[
            (
                0,
                Affine3A::IDENTITY,
                Vec4::ZERO,
                InstanceInclusionMask::ALL,
            ),
            (
                1,
                Affine3A::IDENTITY,
                Vec4::ZERO,
                InstanceInclusionMask::ALL,
            ),
            (
                2,
                Affine3A::IDENTITY,
                MAGENTA,
                InstanceInclusionMask::VISIBLE_IN_RT,
            ),
        ],
    );
    assert_eq!(inst.len(), 3);
    let all = [rects[0], rects[1], hidden];
    let a = overview();
    run_tasks(
        &ctx,
        vec![RenderTask::DirectLightingInjection(injection(
            &all,
            &a,
            depth,
            |p, _| gradient(p),
        ))],
    );
    let b = side();
    let hits = b.hits(&all);
    for bilinear in [false, true] {
        let img = view(&ctx, &b, DebugOutputType::DirectLightingCache, bilinear);
        let (mut n, mut sum, mut worst, mut hidden_px) = (0, 0.0, 0.0f32, 0);
        for (i, h) in hits.iter().enumerate() {
            let Some(p) = h else {
                assert_eq!(img[i].w, 0.0, "pixel {i} misses");
                continue;
            };
            if p.z.abs() < 1e-4 && p.y > 1e-3 {
                // The quad that is no injection target keeps its initial colour.
                {
                    assert!(
                        (img[i].truncate() - MAGENTA.truncate()).abs().max_element() < 1e-6,
                        "hidden quad pixel {i}: {:?}",
                        img[i]
                    );
                    hidden_px += 1;
                }
                continue;
            }
            // Surfels on a surface's border hold half cells, and the overview sees the foot of
            // the wall at a grazing angle: compare inside the surfaces.
            let inside = p.x.abs() < 2.0 - unit && p.z > -2.0 + unit && p.y < 2.0 - unit;
            // Interpolated reads mix the samples within a tile: all of them must have been seen.
            let (u, v) = if p.y.abs() < 1e-4 {
                (Vec3::X, Vec3::Z)
            } else {
                (Vec3::X, Vec3::Y)
            };
            let around = [u, -u, v, -v].map(|d| *p + d * unit);
            if !inside || !around.iter().chain([p]).all(|q| sees(&a, &all, *q, 2.0)) {
                continue;
            }
            let err = (img[i].truncate() - gradient(*p)).abs().max_element();
            sum += err;
            n += 1;
            worst = worst.max(err);
        }
        let mean = sum / n as f32;
        eprintln!("{depth:?} {surfel_type:?} bilinear {bilinear}: {n} px, mean {mean}, worst {worst}, hidden {hidden_px}");
        assert!(n > 1000, "too few pixels compared: {n}");
        assert!(
            hidden_px > 50,
            "the hidden quad must be in view: {hidden_px}"
        );
        // A tile spans `unit`; a surfel holds the average over its cell.
        assert!(worst < GRADIENT_SLOPE * unit * 1.5, "worst {worst}");
        assert!(mean < GRADIENT_SLOPE * unit * 0.35, "mean {mean}");
        views.push(img);
    }
    views.try_into().expect("two views")
}

/// An engine's own `Depth32Float` depth attachment as the injection depth (the other injection
/// tests store clip depth in `R32Float`): the gradient reads back as well as with `R32Float`
/// (the same analytic bounds), and the cache equals the one injected from an `R32Float` texture
/// holding the same depth values bit for bit (fresh contexts draw the same injection offsets, so
/// any difference is the depth-format path reading another depth).
#[test]
fn depth32float_depth_buffer_injects_like_r32float() {
    let started = std::time::Instant::now();
    let from_depth_buffer = inject_gradient_and_check(Depth::Depth32, SurfelType::MeshColors);
    let from_r32 = inject_gradient_and_check(Depth::Clip, SurfelType::MeshColors);
    for (k, (a, b)) in from_depth_buffer.iter().zip(&from_r32).enumerate() {
        for (i, (x, y)) in a.iter().zip(b).enumerate() {
            assert!(
                (*x - *y).abs().max_element() <= 1e-6,
                "view {k} pixel {i}: Depth32Float {x}, R32Float {y}"
            );
        }
    }
    eprintln!("took {:?}", started.elapsed());
}

#[test]
fn many_pixels_in_one_surfel_give_their_exact_average() {
    let ctx = context(4);
    // One triangle, one tile, filling the whole view.
    let big = Mesh {
        positions: vec![
            Vec3::new(-50.0, -50.0, 0.0),
            Vec3::new(50.0, -50.0, 0.0),
            Vec3::new(0.0, 50.0, 0.0),
        ],
        indices: vec![0, 1, 2],
    };
    let edit = |g: &mut GeometryInput| {
        g.surfel_type = SurfelType::WarpedBarycentricStorage;
        g.force_direct_tile_mapping = true;
    };
    scene(
        &ctx,
        &[(&big, &edit)],
        &[(
            0,
            Affine3A::IDENTITY,
            Vec4::ZERO,
            InstanceInclusionMask::ALL,
        )],
    );
    let rect = [Rect {
        origin: Vec3::new(-50.0, -50.0, 0.0),
        a: Vec3::new(100.0, 0.0, 0.0),
        b: Vec3::new(0.0, 100.0, 0.0),
    }];
    let cam = Camera {
        eye: Vec3::new(0.0, 0.0, 3.0),
        target: Vec3::ZERO,
        fov_y: 1.0,
        w: 64,
        h: 64,
    };
    // Pseudo-random HDR values per pixel.
    let value = |(x, y): (u32, u32)| {
        let h = x.wrapping_mul(73856093) ^ y.wrapping_mul(19349663);
        Vec3::new(
            (h % 1000) as f32 * 0.013,
            ((h / 1000) % 1000) as f32 * 0.0007,
            ((h / 7) % 997) as f32 * 0.11,
        )
    };
    let mut t = injection(&rect, &cam, Depth::Clip, |_, px| value(px));
    t.average_window = 1.0;
    run_tasks(&ctx, vec![RenderTask::DirectLightingInjection(t)]);
    let mut sum = glam::DVec3::ZERO;
    for y in 0..64 {
        for x in 0..64 {
            sum += value((x, y)).as_dvec3();
        }
    }
    let mean = (sum / 4096.0).as_vec3();
    let img = view(&ctx, &cam, DebugOutputType::DirectLightingCache, false);
    for p in &img {
        let err = (p.truncate() - mean).abs() / mean;
        assert!(err.max_element() < 1e-4, "{p:?} vs exact mean {mean:?}");
    }
}

#[test]
fn surfel_counts_follow_the_documented_formula() {
    let ctx = context(4);
    let mut rng = common::rt::Rng(7);
    let soup = Mesh::soup(&mut rng, 40, 3.0);
    let sphere = Mesh::icosphere(2);
    let sliver = Mesh {
        positions: vec![
            Vec3::ZERO,
            Vec3::new(9.3, 0.0, 0.0),
            Vec3::new(4.6, 1e-3, 0.0),
            Vec3::new(0.0, 1e-4, 0.0),
            Vec3::new(1e-4, 0.0, 1e-4),
            Vec3::new(500.0, 0.0, 0.0),
            Vec3::new(0.0, 0.0, 700.0),
        ],
        indices: vec![0, 1, 2, 0, 3, 4, 0, 5, 6],
    };
    let split = room()[0].mesh(3, true);
    let cases: Vec<(&Mesh, GeometryInput, Affine3A)> = [
        (SurfelType::MeshColors, 0.37, false),
        (SurfelType::WarpedBarycentricStorage, 0.37, false),
        (SurfelType::MeshColors, 0.37, true),
    ]
    .into_iter()
    .flat_map(|(surfel_type, unit, force)| {
        let input = GeometryInput {
            surfel_type,
            tile_unit_length: unit,
            tile_resolution_limit: 24,
            force_direct_tile_mapping: force,
            ..Default::default()
        };
        [
            (&soup, input.clone(), Affine3A::IDENTITY),
            (
                &sphere,
                input.clone(),
                Affine3A::from_scale(Vec3::splat(2.7)),
            ),
            (&sliver, input.clone(), Affine3A::IDENTITY),
            (&split, input.clone(), Affine3A::from_rotation_y(0.3)),
        ]
    })
    .collect();
    let mut c = ctx.create_task_container();
    let mut handles = Vec::new();
    for (m, input, xf) in &cases {
        let g = ctx.create_geometry_handle();
        let mut full = common::rt::mesh_input("sizing", m, false);
        full.surfel_type = input.surfel_type;
        full.tile_unit_length = input.tile_unit_length;
        full.tile_resolution_limit = input.tile_resolution_limit;
        full.force_direct_tile_mapping = input.force_direct_tile_mapping;
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Register,
            handle: g,
            input: full,
        });
        let i = ctx.create_instance_handle();
        register_instance(&mut c, i, g, *xf);
        handles.push(i);
    }
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: 100,
        ..Default::default()
    });
    build_submit_complete(&ctx, c);
    for ((m, input, xf), h) in cases.iter().zip(&handles) {
        let world: Vec<[Vec3; 3]> = m
            .triangles()
            .iter()
            .map(|t| t.map(|v| xf.transform_point3(v)))
            .collect();
        let a = allocation(&ctx, *h);
        assert_eq!(a.level, CacheLevel::Full);
        assert_eq!(
            a.surfels,
            expected_surfels(&world, input),
            "{:?} force {} of {} triangles",
            input.surfel_type,
            input.force_direct_tile_mapping,
            world.len()
        );
    }
    assert!(ctx.resource_allocations().cache > 0);
}

/// A floor of `n`×`n` quads (x, z in [-1, 1], y = 0) as a mesh.
fn small_floor() -> Rect {
    Rect {
        origin: Vec3::new(-1.0, 0.0, -1.0),
        a: Vec3::new(0.0, 0.0, 2.0),
        b: Vec3::new(2.0, 0.0, 0.0),
    }
}

fn above() -> Camera {
    Camera {
        eye: Vec3::new(0.1, 2.5, 1.2),
        target: Vec3::new(0.0, 0.0, 0.0),
        fov_y: 1.0,
        w: 64,
        h: 64,
    }
}

#[test]
fn injections_converge_as_the_average_window_says() {
    let ctx = context(4);
    let rect = small_floor();
    let mesh = rect.mesh(1, false);
    let edit = |g: &mut GeometryInput| {
        g.surfel_type = SurfelType::WarpedBarycentricStorage;
        g.force_direct_tile_mapping = true;
    };
    scene(
        &ctx,
        &[(&mesh, &edit)],
        &[(0, Affine3A::IDENTITY, MAGENTA, InstanceInclusionMask::ALL)],
    );
    let cam = above();
    let (a, b) = (Vec3::new(1.0, 0.5, 0.25), Vec3::new(0.0, 1.0, 2.0));
    let window = 4.0;
    let task = |c: Vec3| {
        let mut t = injection(&[rect], &cam, Depth::Clip, move |_, _| c);
        t.average_window = window;
        // Strided: every task still reaches both surfels.
        t.injection_resolution_stride = 4;
        RenderTask::DirectLightingInjection(t)
    };
    // The CPU form of the documented blend: the first task replaces, then
    // value += (average − value) / min(n + 1, window).
    let mut expected = MAGENTA.truncate();
    let mut n = 0.0f32;
    for (k, c) in [a, a, a, b, b, b, b, b].into_iter().enumerate() {
        // Two tasks in one container also count as two.
        let tasks = if k == 1 {
            vec![task(c), task(c)]
        } else {
            vec![task(c)]
        };
        for _ in 0..tasks.len() {
            expected = if n == 0.0 {
                c
            } else {
                expected + (c - expected) / (n + 1.0).min(window)
            };
            n += 1.0;
        }
        run_tasks(&ctx, tasks);
        let img = view(&ctx, &cam, DebugOutputType::DirectLightingCache, true);
        let centre = img[(32 * 64 + 32) as usize].truncate();
        assert!(
            (centre - expected).abs().max_element() < 1e-4,
            "after task {k}: {centre:?}, expected {expected:?}"
        );
    }
    // After 5 B tasks past n = 4 the formula gives B + (A − B)(3/4)^5.
    let closed = b + (a - b) * 0.75f32.powi(5);
    let img = view(&ctx, &cam, DebugOutputType::DirectLightingCache, true);
    assert!((img[32 * 64 + 32].truncate() - closed).abs().max_element() < 1e-4);
}

#[test]
fn two_cameras_in_one_container_fill_both_halves() {
    let ctx = context(4);
    let rects = [room()[0]];
    let mesh = rects[0].mesh(4, false);
    let unit = 0.4;
    let edit = tile(unit);
    scene(
        &ctx,
        &[(&mesh, &edit)],
        &[(0, Affine3A::IDENTITY, MAGENTA, InstanceInclusionMask::ALL)],
    );
    let cam = |x: f32| Camera {
        eye: Vec3::new(x, 2.0, 1.0),
        target: Vec3::new(x, 0.0, -0.5),
        fov_y: 0.9,
        w: 96,
        h: 96,
    };
    let (left, right) = (cam(-1.3), cam(1.3));
    let overview = overview();
    let hits = overview.hits(&rects);
    let seen_by = |c: &Camera, p: Vec3| {
        [Vec3::ZERO, Vec3::X, -Vec3::X, Vec3::Z, -Vec3::Z]
            .iter()
            .all(|d| sees(c, &rects, p + *d * unit, 1.0))
    };
    let unseen_by = |c: &Camera, p: Vec3| {
        [Vec3::ZERO, Vec3::X, -Vec3::X, Vec3::Z, -Vec3::Z]
            .iter()
            .all(|d| !sees(c, &rects, p + *d * unit, 0.0))
    };
    let check = |img: &[Vec4], cams: &[&Camera]| {
        let (mut lit, mut unlit) = (0, 0);
        for (i, h) in hits.iter().enumerate() {
            let Some(p) = h else { continue };
            let inside = p.x.abs() < 2.0 - unit && p.z.abs() < 2.0 - unit;
            if inside && cams.iter().any(|c| seen_by(c, *p)) {
                let err = (img[i].truncate() - gradient(*p)).abs().max_element();
                assert!(
                    err < GRADIENT_SLOPE * unit * 1.5,
                    "pixel {i} at {p:?}: {:?}",
                    img[i]
                );
                lit += 1;
            } else if cams.iter().all(|c| unseen_by(c, *p))
                && [&left, &right].iter().any(|c| seen_by(c, *p))
            {
                assert!((img[i].truncate() - MAGENTA.truncate()).abs().max_element() < 1e-6);
                unlit += 1;
            }
        }
        (lit, unlit)
    };
    run_tasks(
        &ctx,
        vec![RenderTask::DirectLightingInjection(injection(
            &rects,
            &left,
            Depth::Clip,
            |p, _| gradient(p),
        ))],
    );
    let (lit, unlit) = check(
        &view(&ctx, &overview, DebugOutputType::DirectLightingCache, true),
        &[&left],
    );
    assert!(
        lit > 200 && unlit > 200,
        "one camera: {lit} lit, {unlit} unlit pixels"
    );
    // Both cameras in one container (the second injects the same left half again).
    run_tasks(
        &ctx,
        vec![
            RenderTask::DirectLightingInjection(injection(&rects, &right, Depth::Clip, |p, _| {
                gradient(p)
            })),
            RenderTask::DirectLightingInjection(injection(&rects, &left, Depth::Clip, |p, _| {
                gradient(p)
            })),
        ],
    );
    let (lit2, unlit2) = check(
        &view(&ctx, &overview, DebugOutputType::DirectLightingCache, true),
        &[&left, &right],
    );
    assert!(
        lit2 > lit + 200 && unlit2 == 0,
        "two cameras: {lit2} lit, {unlit2} unlit pixels"
    );
}

/// Per-pixel noise in [0, 1].
fn noise((x, y): (u32, u32)) -> Vec3 {
    let h = |k: u32| {
        let s = (x.wrapping_mul(1973) ^ y.wrapping_mul(9277) ^ k.wrapping_mul(26699))
            .wrapping_mul(747796405);
        ((s >> 16) & 1023) as f32 / 1023.0
    };
    Vec3::new(h(1), h(2), h(3))
}

#[test]
fn interpolated_mesh_colors_are_continuous_across_shared_and_split_edges() {
    for split in [false, true] {
        let ctx = context(4);
        let rect = small_floor();
        // Two triangles sharing the diagonal s = t (split: with their own vertices).
        let mesh = rect.mesh(1, split);
        let edit = tile(0.5);
        scene(
            &ctx,
            &[(&mesh, &edit)],
            &[(
                0,
                Affine3A::IDENTITY,
                Vec4::ZERO,
                InstanceInclusionMask::ALL,
            )],
        );
        let inj = Camera {
            w: 128,
            h: 128,
            ..above()
        };
        run_tasks(
            &ctx,
            vec![RenderTask::DirectLightingInjection(injection(
                &[rect],
                &inj,
                Depth::Clip,
                |_, px| noise(px),
            ))],
        );
        let cam = Camera {
            w: 160,
            h: 160,
            ..above()
        };
        let img = view(&ctx, &cam, DebugOutputType::DirectLightingCache, true);
        let hits = cam.hits(&[rect]);
        // Which side of the diagonal a pixel's point is on (None near the mesh border).
        let side = |i: usize| {
            hits[i].and_then(|p| {
                let q = p - rect.origin;
                let (s, t) = (q.dot(rect.a) / 4.0, q.dot(rect.b) / 4.0);
                (s > 0.02 && s < 0.98 && t > 0.02 && t < 0.98).then_some(s > t)
            })
        };
        let (mut across, mut within) = (0.0f32, 0.0f32);
        let mut pairs = 0;
        for y in 0..cam.h as usize {
            for x in 0..cam.w as usize - 1 {
                let (i, j) = (y * cam.w as usize + x, y * cam.w as usize + x + 1);
                let (Some(a), Some(b)) = (side(i), side(j)) else {
                    continue;
                };
                let step = (img[i] - img[j]).truncate().abs().max_element();
                if a == b {
                    within = within.max(step);
                } else {
                    across = across.max(step);
                    pairs += 1;
                }
            }
        }
        eprintln!("split {split}: largest step across the edge {across}, within triangles {within} ({pairs} pairs)");
        assert!(pairs > 50);
        assert!(within > 0.0, "noise must make the cache vary");
        assert!(
            across <= within * 1.25,
            "a step across the shared edge: {across} vs {within} within"
        );
    }
}

#[test]
fn a_short_pool_gives_coarse_caches_at_once_and_grows_later() {
    let ctx = context_with(InitSettings {
        lighting_cache_pool_bytes: 64 * 16,
        ..Default::default()
    });
    let rect = small_floor();
    let mesh = rect.mesh(2, false);
    let unit = 0.3;
    let edit = tile(unit);
    let offsets = [
        Vec3::ZERO,
        Vec3::new(3.0, 0.0, 0.0),
        Vec3::new(-3.0, 0.0, 0.0),
    ];
    let cam = above();
    // The registering task injects and reads the caches at once: they must be valid.
    let c = Vec3::new(0.2, 0.4, 0.6);
    let (before, before_out) = view_task(&cam, DebugOutputType::DirectLightingCache, true);
    let (after, after_out) = view_task(&cam, DebugOutputType::DirectLightingCache, true);
    let inject =
        RenderTask::DirectLightingInjection(injection(&[rect], &cam, Depth::Clip, move |_, _| c));
    let (_, inst) = scene_with(
        &ctx,
        &[(&mesh, &edit)],
        &offsets.map(|o| {
            (
                0,
                Affine3A::from_translation(o),
                MAGENTA,
                InstanceInclusionMask::ALL,
            )
        }),
        vec![before, inject, after],
    );
    let centre = 32 * 64 + 32;
    assert!(
        (read_view(&before_out)[centre].truncate() - MAGENTA.truncate())
            .abs()
            .max_element()
            < 1e-6
    );
    assert!(
        (read_view(&after_out)[centre].truncate() - c)
            .abs()
            .max_element()
            < 1e-5
    );
    // Every instance got its coarse cache (9 vertex samples each: 27 of the 64 surfels).
    for h in &inst {
        let a = allocation(&ctx, *h);
        assert_eq!(
            a,
            CacheAllocation {
                surfels: 9,
                level: CacheLevel::Coarse
            }
        );
    }
    // The next task grows the pool and allocates full caches again.
    run_tasks(&ctx, vec![]);
    let world: Vec<[Vec3; 3]> = mesh.triangles();
    let mut input = GeometryInput::default();
    edit(&mut input);
    for h in &inst {
        let a = allocation(&ctx, *h);
        assert_eq!(a.level, CacheLevel::Full);
        assert_eq!(a.surfels, expected_surfels(&world, &input));
    }
    let img = view(&ctx, &cam, DebugOutputType::DirectLightingCache, true);
    assert!(
        (img[32 * 64 + 32].truncate() - MAGENTA.truncate())
            .abs()
            .max_element()
            < 1e-6,
        "{:?}",
        img[32 * 64 + 32]
    );
    run_tasks(
        &ctx,
        vec![RenderTask::DirectLightingInjection(injection(
            &[rect],
            &cam,
            Depth::Clip,
            |p, _| gradient(p),
        ))],
    );
    let hits = cam.hits(&[rect]);
    let img = view(&ctx, &cam, DebugOutputType::DirectLightingCache, true);
    for (i, h) in hits.iter().enumerate() {
        if let Some(p) = h.filter(|p| p.x.abs() < 0.7 && p.z.abs() < 0.7) {
            assert!(
                (img[i].truncate() - gradient(p)).abs().max_element() < GRADIENT_SLOPE * unit * 1.5
            );
        }
    }
}

/// Each transfer from `source` to a target of `refused` is refused as invalid input whose message
/// contains the paired word.
fn assert_transfers_refused(
    ctx: &ExecuteContext,
    source: InstanceHandle,
    refused: &[(InstanceHandle, &str)],
) {
    for &(target, why) in refused {
        let mut c = ctx.create_task_container();
        c.schedule_render_task(RenderTask::DirectLightTransfer(DirectLightTransferTask {
            source,
            target,
        }));
        let err = ctx
            .build_gpu_task(c, &mut encoder())
            .expect_err("bad transfer");
        assert!(
            matches!(err, Error::InvalidInput { .. }) && err.to_string().contains(why),
            "{err}"
        );
    }
}

#[test]
fn transfer_reproduces_the_source_lighting_on_the_target() {
    let ctx = context(4);
    let rect = small_floor();
    let mesh = rect.mesh(2, false);
    let unit = 0.3;
    let mc = |g: &mut GeometryInput| {
        g.tile_unit_length = 0.3;
        g.allow_light_transfer_target = true;
    };
    let wb = |g: &mut GeometryInput| {
        g.tile_unit_length = 0.3;
        g.surfel_type = SurfelType::WarpedBarycentricStorage;
        g.allow_light_transfer_target = true;
    };
    let other = Rect {
        origin: Vec3::ZERO,
        a: Vec3::X,
        b: Vec3::Z,
    }
    .mesh(1, false);
    let plain = |_: &mut GeometryInput| {};
    let shift = Vec3::new(10.0, 0.0, 0.0);
    // The source, then targets: same layout, warped-barycentric tiles, another triangle count,
    // and a geometry without allow_light_transfer_target.
    let placed: Vec<_> = [0, 0, 1, 2, 3]
        .into_iter()
        .enumerate()
        .map(|(k, geometry)| {
            let tint = if k == 0 { Vec4::ZERO } else { MAGENTA };
            let at = Affine3A::from_translation(shift * k as f32);
            (geometry, at, tint, InstanceInclusionMask::ALL)
        })
        .collect();
    let (_, inst) = scene(
        &ctx,
        &[(&mesh, &mc), (&mesh, &wb), (&other, &mc), (&mesh, &plain)],
        &placed,
    );
    let cam = above();
    run_tasks(
        &ctx,
        vec![RenderTask::DirectLightingInjection(injection(
            &[rect],
            &cam,
            Depth::Clip,
            |p, _| gradient(p),
        ))],
    );
    // Bad transfers are refused before anything is recorded.
    assert_transfers_refused(
        &ctx,
        inst[0],
        &[
            (inst[3], "triangles"),
            (inst[4], "allow_light_transfer_target"),
            (inst[0], "differ"),
        ],
    );
    run_tasks(
        &ctx,
        vec![
            RenderTask::DirectLightTransfer(DirectLightTransferTask {
                source: inst[0],
                target: inst[1],
            }),
            RenderTask::DirectLightTransfer(DirectLightTransferTask {
                source: inst[0],
                target: inst[2],
            }),
        ],
    );
    let moved = |k: f32| Camera {
        eye: cam.eye + shift * k,
        target: cam.target + shift * k,
        ..cam
    };
    let source = view(&ctx, &cam, DebugOutputType::DirectLightingCache, true);
    let same_layout = view(
        &ctx,
        &moved(1.0),
        DebugOutputType::DirectLightingCache,
        true,
    );
    let tiles = view(
        &ctx,
        &moved(2.0),
        DebugOutputType::DirectLightingCache,
        true,
    );
    let hits = cam.hits(&[rect]);
    let mut n = 0;
    for (i, h) in hits.iter().enumerate() {
        let Some(p) = h.filter(|p| p.x.abs() < 1.0 - unit && p.z.abs() < 1.0 - unit) else {
            continue;
        };
        assert!(
            (same_layout[i] - source[i]).abs().max_element() < 1e-4,
            "pixel {i}"
        );
        assert!(
            (tiles[i].truncate() - gradient(p)).abs().max_element() < GRADIENT_SLOPE * unit * 1.5,
            "pixel {i}"
        );
        n += 1;
    }
    assert!(n > 500);
}

#[test]
fn tile_view_shows_one_id_per_surfel() {
    let ctx = context(4);
    let rect = small_floor();
    let mesh = rect.mesh(1, false);
    let edit = |g: &mut GeometryInput| {
        g.surfel_type = SurfelType::WarpedBarycentricStorage;
        g.tile_unit_length = 0.3;
    };
    scene(
        &ctx,
        &[(&mesh, &edit)],
        &[(
            0,
            Affine3A::IDENTITY,
            Vec4::ZERO,
            InstanceInclusionMask::ALL,
        )],
    );
    let cam = Camera {
        w: 128,
        h: 128,
        ..above()
    };
    let img = view(&ctx, &cam, DebugOutputType::RandomTileColor, false);
    let colours: std::collections::HashSet<[u32; 3]> = img
        .iter()
        .filter(|p| p.w > 0.0)
        .map(|p| p.truncate().to_array().map(f32::to_bits))
        .collect();
    // Longest edge 2.83 / 0.3 → 10 tiles per edge, 100 tiles per triangle; most are in view.
    let mut input = GeometryInput::default();
    edit(&mut input);
    let expected = expected_surfels(&mesh.triangles(), &input) as usize;
    assert_eq!(expected, 200);
    assert!(
        colours.len() > 150 && colours.len() <= expected,
        "{} tile colours",
        colours.len()
    );
}

#[test]
fn a_destroyed_instance_frees_its_cache_for_the_next() {
    // Room for three caches of 17 surfels (the 2×2 quad at unit 1: 4 vertices, 4 edge samples,
    // 3 on the diagonal, 3 inside each triangle).
    let ctx = context_with(InitSettings {
        lighting_cache_pool_bytes: 64 * 16,
        ..Default::default()
    });
    let mesh = small_floor().mesh(1, false);
    let edit = tile(1.0);
    let (geoms, inst) = scene(
        &ctx,
        &[(&mesh, &edit)],
        &[0.0, 3.0, 6.0].map(|x| {
            (
                0,
                Affine3A::from_translation(Vec3::new(x, 0.0, 0.0)),
                MAGENTA,
                InstanceInclusionMask::ALL,
            )
        }),
    );
    for h in &inst {
        assert_eq!(
            allocation(&ctx, *h),
            CacheAllocation {
                surfels: 17,
                level: CacheLevel::Full
            }
        );
    }
    let bytes = ctx.resource_allocations().cache;
    ctx.destroy_instance_handle(inst[1]).expect("destroy");
    let fresh = ctx.create_instance_handle();
    let mut c = ctx.create_task_container();
    let mut input = InstanceInput::new(
        geoms[0],
        Affine3A::from_translation(Vec3::new(9.0, 0.0, 0.0)),
    );
    input.initial_tile_color = MAGENTA;
    c.schedule_bvh_task(InstanceTask {
        operation: TaskOperation::Register,
        handle: fresh,
        input,
    });
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    // The fourth cache fits only in the freed one's place: full, and the pool did not grow.
    assert_eq!(
        allocation(&ctx, fresh),
        CacheAllocation {
            surfels: 17,
            level: CacheLevel::Full
        }
    );
    run_tasks(&ctx, vec![]);
    // Nothing grew (the allocation scratch may have been given back since).
    let after = ctx.resource_allocations().cache;
    assert!(after <= bytes, "{after} bytes after, {bytes} before");
    let cam = Camera {
        eye: above().eye + Vec3::new(9.0, 0.0, 0.0),
        target: Vec3::new(9.0, 0.0, 0.0),
        ..above()
    };
    let img = view(&ctx, &cam, DebugOutputType::DirectLightingCache, true);
    assert!(
        (img[32 * 64 + 32] - MAGENTA.truncate().extend(1.0))
            .abs()
            .max_element()
            < 1e-6,
        "{:?}",
        img[32 * 64 + 32]
    );
}
