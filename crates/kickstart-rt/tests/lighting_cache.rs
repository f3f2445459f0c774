//! The direct lighting cache: injection from analytic images (CPU ray casts give depth and
//! lighting), read back through the DirectLightingCache / RandomTileColor debug views, sizes
//! against the documented formulas, allocation from a short pool, transfer, and exact
//! accumulation.

mod common;
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
    if px.x < margin || px.y < margin || px.x > cam.w as f32 - margin || px.y > cam.h as f32 - margin
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
                (0, Affine3A::IDENTITY, Vec4::ZERO, InstanceInclusionMask::ALL),
                (1, Affine3A::IDENTITY, Vec4::ZERO, InstanceInclusionMask::ALL),
                (2, Affine3A::IDENTITY, MAGENTA, InstanceInclusionMask::VISIBLE_IN_RT),
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
            assert!(hidden_px > 50, "the hidden quad must be in view: {hidden_px}");
            // A tile spans `unit`; a surfel holds the average over its cell.
            assert!(worst < GRADIENT_SLOPE * unit * 1.5, "worst {worst}");
            assert!(mean < GRADIENT_SLOPE * unit * 0.35, "mean {mean}");
        }
    }
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
    scene(&ctx, &[(&big, &edit)], &[(0, Affine3A::IDENTITY, Vec4::ZERO, InstanceInclusionMask::ALL)]);
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
            (&sphere, input.clone(), Affine3A::from_scale(Vec3::splat(2.7))),
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
