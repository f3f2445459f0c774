//! The ray tracing core through the public API: geometry ingestion, GPU BLAS/TLAS builds and
//! refits, and traversal, checked ray by ray against the CPU oracle (`kickstart_rt::cpu`).

use crate::common;
use common::rt::*;
use common::*;
use glam::{Affine3A, Quat, Vec3};
use kickstart_rt::*;
use proptest::prelude::{any, prop_assert, prop_assert_eq, proptest};
use proptest::test_runner::TestCaseError;
use std::sync::{Arc, Mutex};

const VISIBLE: u32 = InstanceInclusionMask::VISIBLE_IN_RT.0;

/// The context traces with the backend the test pass asks for (`KSRT_TEST_BACKEND`), and says
/// why; an explicit choice the device cannot honour is refused by name.
#[test]
fn the_context_reports_the_backend_of_the_test_pass() {
    let ctx = context(1);
    let report = ctx.traversal_backend();
    assert_eq!(report.backend, backend(), "{}", report.reason);
    assert!(report.reason.contains("Auto"), "{}", report.reason);
    let g = gpu();
    let forced = |backend| {
        ExecuteContext::new(
            &g.device,
            &g.queue,
            InitSettings {
                backend,
                ..Default::default()
            },
        )
    };
    let software = forced(BackendChoice::Software).expect("software is always available");
    assert_eq!(
        software.traversal_backend().backend,
        TraversalBackend::Software
    );
    match (backend(), forced(BackendChoice::HardwareRayQuery)) {
        (TraversalBackend::HardwareRayQuery, Ok(c)) => {
            assert_eq!(
                c.traversal_backend().backend,
                TraversalBackend::HardwareRayQuery
            )
        }
        (TraversalBackend::Software, Err(Error::MissingFeatures(what))) => {
            assert!(what.contains("EXPERIMENTAL_RAY_QUERY"), "{what}")
        }
        (b, r) => panic!("test pass {b}: HardwareRayQuery gave {:?}", r.map(|_| ())),
    }
}

/// Whether triangle `v` is no sliver: its area is not tiny against its longest edge. Whether a
/// ray aimed at a sliver's centroid hits it is a matter of rounding (FMA on a GPU, the driver's
/// triangle test on the hardware backend), so tests aim at well-shaped triangles only.
fn well_shaped(v: &[Vec3; 3]) -> bool {
    let longest = (v[1] - v[0])
        .length_squared()
        .max((v[2] - v[1]).length_squared())
        .max((v[0] - v[2]).length_squared());
    (v[1] - v[0]).cross(v[2] - v[0]).length() > 0.05 * longest
}

/// The centroids of `mesh`'s [`well_shaped`] triangles, moved by `shift`.
fn well_shaped_centroids(mesh: &Mesh, shift: Vec3) -> Vec<Vec3> {
    mesh.triangles()
        .iter()
        .filter(|v| well_shaped(v))
        .map(|v| (v[0] + v[1] + v[2]) / 3.0 + shift)
        .collect()
}

/// A random transform: rotation, non-uniform scale (sometimes mirrored), translation.
fn random_transform(rng: &mut Rng, spread: f32) -> Affine3A {
    let axis = rng.unit();
    let mut scale = Vec3::new(
        rng.range(0.5, 2.0),
        rng.range(0.5, 2.0),
        rng.range(0.5, 2.0),
    );
    if rng.below(4) == 0 {
        scale.x = -scale.x;
    }
    Affine3A::from_scale_rotation_translation(
        scale,
        Quat::from_axis_angle(axis, rng.range(0.0, std::f32::consts::TAU)),
        rng.v(-spread, spread),
    )
}

/// Rays between random points of the scene's region, some with a finite range, some starting
/// beyond their origin (t_min > 0), a few axis-aligned.
fn random_rays(rng: &mut Rng, n: usize, extent: f32) -> Vec<GpuRay> {
    (0..n)
        .map(|k| {
            let o = rng.v(-extent, extent);
            let mut d = rng.v(-extent, extent) - o;
            if k % 23 == 0 {
                // Axis-aligned: two zero components (0 × ∞ in the slab test).
                let axis = rng.below(3) as usize;
                let mut a = Vec3::ZERO;
                a[axis] = if rng.below(2) == 0 { 1.0 } else { -1.0 };
                d = a;
            }
            let t_max = if k % 5 == 0 {
                rng.range(0.1, 2.0)
            } else {
                f32::INFINITY
            };
            let t_min = if k % 7 == 0 { rng.range(0.0, 0.3) } else { 0.0 };
            ray(o, d, t_min, t_max)
        })
        .collect()
}

struct Scene {
    ctx: ExecuteContext,
    oracle: Oracle,
    instances: Vec<(InstanceHandle, InstanceInput)>,
}

/// Geometries (random soups of ≥ `tris` triangles, with duplicates and degenerates) and
/// `instances` instances of them, some masked out and some not participating.
fn random_scene(seed: u64, tris: u32, instances: u32) -> Scene {
    let mut rng = Rng(seed);
    let ctx = context(4);
    let mut oracle = Oracle::default();
    let mut c = ctx.create_task_container();
    let geometries: Vec<GeometryHandle> = (0..3)
        .map(|k| {
            let h = ctx.create_geometry_handle();
            let m = Mesh::soup(&mut rng, tris + k * 101, 1.0);
            schedule_mesh(&mut c, h, &format!("soup {k}"), &m);
            oracle.geometry(h, &m);
            h
        })
        .collect();
    let mut list = Vec::new();
    for k in 0..instances {
        let h = ctx.create_instance_handle();
        let mut input = InstanceInput::new(
            geometries[k as usize % geometries.len()],
            random_transform(&mut rng, 4.0),
        );
        if k % 11 == 3 {
            input.inclusion_mask = InstanceInclusionMask::DIRECT_LIGHT_INJECTION_TARGET;
        }
        if k % 13 == 7 {
            input.participating_in_tlas = false;
        }
        c.schedule_bvh_task(InstanceTask {
            operation: TaskOperation::Register,
            handle: h,
            input: input.clone(),
        });
        oracle.instance(h, &input);
        list.push((h, input));
    }
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: 100,
        ..Default::default()
    });
    build_submit_complete(&ctx, c);
    Scene {
        ctx,
        oracle,
        instances: list,
    }
}

proptest! {
    #![proptest_config(common::proptest_config(3))]

    /// ≥ 10k-triangle meshes, ≥ 100 instances: GPU closest hits equal the CPU oracle's, masks
    /// and participation are honoured, and any-hit agrees with closest-hit on occlusion.
    #[test]
    fn gpu_hits_equal_the_cpu_oracle(seed in any::<u64>(), tris in 10_000u32..10_500, instances in 100u32..130) {
        let s = random_scene(seed, tris, instances);
        let mut rng = Rng(seed ^ 0x5eed);
        let rays = random_rays(&mut rng, 3000, 6.0);
        let hits = closest(&s.ctx, &rays);
        let a = compare(&s.oracle, &rays, &hits, VISIBLE);
        assert_agrees(&a, "closest hit");
        prop_assert!(a.hits > 300, "the rays must actually hit things: {}", a.hits);
        for h in hits.iter().filter(|h| h.is_hit()) {
            let (_, input) = &s.instances[s.instances.iter().position(|(i, _)| i.index() == h.instance).unwrap()];
            prop_assert!(input.participating_in_tlas && input.inclusion_mask.contains(InstanceInclusionMask::VISIBLE_IN_RT));
        }
        let any = trace(&s.ctx, &rays, RayQuery::AnyHit, InstanceInclusionMask::VISIBLE_IN_RT);
        let mut disagree = 0;
        for (k, (h, c)) in any.iter().zip(&hits).enumerate() {
            if h.is_hit() != c.is_hit() {
                // Only an edge graze may flip between two traversals.
                let (inst, prim) = if h.is_hit() { (h.instance, h.primitive) } else { (c.instance, c.primitive) };
                prop_assert!(s.oracle.edge_distance(&rays[k], inst, prim) < 1e-4, "ray {k}: any {h:?} closest {c:?}");
                disagree += 1;
            }
            if h.is_hit() {
                prop_assert!(h.t >= rays[k].t_min && h.t <= rays[k].t_max);
            }
        }
        prop_assert!(disagree * 500 <= rays.len());
        // The injection-only mask sees exactly the other instances.
        let inj = trace(&s.ctx, &rays, RayQuery::ClosestHit, InstanceInclusionMask::DIRECT_LIGHT_INJECTION_TARGET);
        assert_agrees(&compare(&s.oracle, &rays, &inj, InstanceInclusionMask::DIRECT_LIGHT_INJECTION_TARGET.0), "injection mask");
    }
}

/// A mesh of `tris` triangles over `verts` vertices in the unit cube, with bad data mixed in
/// at random: vertices with a NaN or ±∞ coordinate, vertices far out (finite, 1e6), indices past
/// the last vertex (just past it and `u32::MAX`), and degenerate triangles (a repeated index).
fn hostile_mesh(rng: &mut Rng, tris: u32, verts: u32) -> Mesh {
    let positions = (0..verts)
        .map(|_| match rng.below(24) {
            0 => Vec3::new(f32::NAN, rng.f(), rng.f()),
            1 => Vec3::new(rng.f(), f32::INFINITY, rng.f()),
            2 => Vec3::new(rng.f(), rng.f(), f32::NEG_INFINITY),
            3 => rng.v(-1.0e6, 1.0e6),
            _ => rng.v(-1.0, 1.0),
        })
        .collect();
    let mut indices = Vec::new();
    for _ in 0..tris {
        let mut t = [rng.below(verts), rng.below(verts), rng.below(verts)];
        match rng.below(16) {
            0 => t[rng.below(3) as usize] = verts + rng.below(3),
            1 => t[rng.below(3) as usize] = u32::MAX,
            2 => t[2] = t[0],
            _ => {}
        }
        indices.extend(t);
    }
    Mesh { positions, indices }
}

/// What ingestion must make of `m`: the triangles it drops (an out-of-range index first, else a
/// non-finite vertex), and the mesh the CPU oracle traces — `m` with each dropped triangle
/// turned into a point far away (never hit; the other triangles keep their indices).
fn expected_ingestion(m: &Mesh) -> (DroppedTriangles, Mesh) {
    let mut dropped = DroppedTriangles::default();
    let mut oracle = m.clone();
    let point = oracle.positions.len() as u32;
    oracle.positions.push(Vec3::splat(1.0e7));
    for t in oracle.indices.chunks_mut(3) {
        if t.iter().any(|&i| i as usize >= m.positions.len()) {
            dropped.out_of_range_indices += 1;
        } else if t.iter().any(|&i| !m.positions[i as usize].is_finite()) {
            dropped.non_finite_positions += 1;
        } else {
            continue;
        }
        t.copy_from_slice(&[point; 3]);
    }
    (dropped, oracle)
}

proptest! {
    #![proptest_config(common::proptest_config(12))]

    /// Fuzzed ingestion: meshes with NaN, ∞ and far-out vertices, out-of-range indices and
    /// degenerate triangles, placed by ordinary, singular (flattened to a plane or a line) and
    /// enormous transforms. Nothing panics or hangs; each geometry reports exactly the triangles
    /// it drops, and every ray hits what the CPU oracle says of the rest.
    #[test]
    fn fuzzed_geometry_drops_exactly_the_bad_triangles_and_traces_the_rest(seed in any::<u64>()) {
        fuzzed_geometry_case(seed)?;
    }
}

/// Fuzzed ingestion in bulk: 2,000 hostile meshes (NaN, ∞ and far-out vertices, indices out of
/// range, degenerate triangles) registered in 4 tasks of 500, each geometry instanced at a
/// random place; one build of every BLAS. Each geometry reports exactly the triangles it
/// drops, and rays through the crowd hit what the CPU oracle says of the rest.
#[test]
fn thousands_of_fuzzed_meshes_in_a_few_tasks_drop_exactly_the_bad_triangles() {
    const MESHES: usize = 2000;
    const PER_TASK: usize = 500;
    let mut rng = Rng(fuzz_seed("batched ingestion fuzz", 0x6b73_7274_6261_7463));
    let ctx = context(4);
    let mut oracle = Oracle::default();
    let mut expected = Vec::with_capacity(MESHES);
    for task in 0..MESHES / PER_TASK {
        let mut c = ctx.create_task_container();
        for k in 0..PER_TASK {
            let (tris, verts) = (4 + rng.below(40), 4 + rng.below(24));
            let m = hostile_mesh(&mut rng, tris, verts);
            let (dropped, traced) = expected_ingestion(&m);
            let h = ctx.create_geometry_handle();
            schedule_mesh(&mut c, h, &format!("hostile {task}.{k}"), &m);
            oracle.geometry(h, &traced);
            expected.push((h, dropped));
            let i = ctx.create_instance_handle();
            let input = InstanceInput::new(h, random_transform(&mut rng, 12.0));
            c.schedule_bvh_task(InstanceTask {
                operation: TaskOperation::Register,
                handle: i,
                input: input.clone(),
            });
            oracle.instance(i, &input);
        }
        build_submit_complete(&ctx, c);
    }
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: MESHES as u32,
        ..Default::default()
    });
    build_submit_complete(&ctx, c);
    let device = gpu().device.clone();
    let wrong: Vec<String> = expected
        .iter()
        .filter_map(|(h, want)| {
            let got = dropped_after_polls(&ctx, &device, *h);
            (got != *want).then(|| format!("{h:?}: dropped {got:?}, expected {want:?}"))
        })
        .collect();
    assert!(
        wrong.is_empty(),
        "{} of {MESHES} geometries: {wrong:#?}",
        wrong.len()
    );
    let rays = random_rays(&mut rng, 2000, 14.0);
    let hits = closest(&ctx, &rays);
    let a = compare(&oracle, &rays, &hits, VISIBLE);
    assert!(a.hits > 200, "too few hits to mean anything: {a:?}");
    assert_agrees(&a, "closest hit over 2,000 fuzzed meshes");
}

/// Seeds on which the fuzzed-geometry property once failed, replayed on every run.
#[test]
fn fuzzed_geometry_regression_seeds() {
    for seed in [14_492_952_624_186_624_813_u64, 17_099_713_997_685_529_562] {
        if let Err(e) = fuzzed_geometry_case(seed) {
            panic!("seed {seed}: {e}");
        }
    }
}

/// The disagreement CI's lavapipe once produced on a fuzzed scene: a ray whose origin lies
/// 4e-9 (in object space, a thousandth of the world's) before the plane of a triangle of an
/// instance scaled 1000×. The GPU hit that triangle at t ≈ 1e-5, the oracle (and lavapipe on
/// another CPU) passed it by and hit another at t = 35: which is right is below `f32`
/// precision, and the comparison counts it as a start on the plane. A miss for a ray starting
/// further back is a real mismatch.
#[test]
fn a_hit_where_the_ray_starts_on_the_plane_is_ill_conditioned_not_a_mismatch() {
    let ctx = context(4);
    let mut oracle = Oracle::default();
    let near = Mesh {
        positions: vec![
            Vec3::new(-0.283_332_23, -0.836_442_2, 0.561_648_4),
            Vec3::new(-0.811_429_3, 0.996_348_5, -0.807_716_5),
            Vec3::new(0.593_669_8, 0.463_323_6, -0.262_382_5),
        ],
        indices: vec![0, 1, 2],
    };
    let g = ctx.create_geometry_handle();
    oracle.geometry(g, &near);
    let i = ctx.create_instance_handle();
    oracle.instance(
        i,
        &InstanceInput::new(g, Affine3A::from_scale(Vec3::splat(1.0e3))),
    );
    let dir = Vec3::new(0.248_215_68, -1.644_748_7, 1.873_196_6);
    let on_plane = ray(
        Vec3::new(2.277_333_3, 1.963_726_5, -2.806_230_5),
        dir,
        0.0,
        f32::INFINITY,
    );
    let off_plane = ray(
        Vec3::new(2.277_333_3, 1.963_726_5, -2.806_230_5) - dir * 0.1,
        dir,
        0.0,
        f32::INFINITY,
    );
    let gpu = |t: f32| GpuHit {
        t,
        u: 0.158_716_5,
        v: 0.421_238_8,
        instance: i.index(),
        primitive: 0,
        _pad: [0; 3],
    };
    let miss = GpuHit {
        t: -1.0,
        instance: GpuHit::MISS,
        ..GpuHit::default()
    };
    // Whichever side calls it a hit, the start on the plane is tolerated, once.
    let cpu_hits = oracle.closest(&on_plane, VISIBLE).is_some();
    let gpu_answer = if cpu_hits { miss } else { gpu(1.1e-5) };
    let a = compare(&oracle, &[on_plane], &[gpu_answer], VISIBLE);
    assert_eq!((a.plane_starts, a.mismatches.len()), (1, 0), "{a:?}");
    // Started a tenth of the direction back, 5e-5 off the plane in object space, the oracle hits
    // the triangle at t ≈ 0.1: a GPU miss is a real error.
    let a = compare(&oracle, &[off_plane], &[miss], VISIBLE);
    assert_eq!((a.plane_starts, a.mismatches.len()), (0, 1), "{a:?}");
}

/// Hostile meshes put vertices at ±1e6 beside ones in the unit cube: an edge between two such
/// vertices crosses the cube where `f32` can place it only to about 0.1, and a hit/miss
/// disagreement that close to it is rounding, not counted against the edge-graze rate. The same
/// distance from a unit triangle's edge is a graze that counts, and further in, a mismatch.
#[test]
fn a_graze_within_the_rounding_of_far_out_vertices_is_not_rate_limited() {
    let ctx = context(4);
    let one_triangle = |positions: [Vec3; 3]| {
        let mut oracle = Oracle::default();
        let g = ctx.create_geometry_handle();
        let mesh = Mesh {
            positions: positions.to_vec(),
            indices: vec![0, 1, 2],
        };
        oracle.geometry(g, &mesh);
        let i = ctx.create_instance_handle();
        oracle.instance(i, &InstanceInput::new(g, Affine3A::IDENTITY));
        (oracle, i.index())
    };
    let down = |x: f32, y: f32| ray(Vec3::new(x, y, 1.0), Vec3::NEG_Z, 0.0, f32::INFINITY);
    let miss = GpuHit {
        t: -1.0,
        instance: GpuHit::MISS,
        ..GpuHit::default()
    };
    let (wide, _) = one_triangle([
        Vec3::new(-1.0e6, 0.0, 0.0),
        Vec3::new(1.0e6, 0.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
    ]);
    let a = compare(&wide, &[down(0.3, 1.0e-5)], &[miss], VISIBLE);
    assert_eq!(
        (a.rounding_grazes, a.edge_grazes, a.mismatches.len()),
        (1, 0, 0),
        "{a:?}"
    );
    let (unit, unit_index) = one_triangle([Vec3::X * -1.0, Vec3::X, Vec3::Y]);
    let rays = [down(0.3, 1.0e-5), down(0.3, 0.01)];
    let a = compare(&unit, &rays, &[miss, miss], VISIBLE);
    assert_eq!(
        (a.rounding_grazes, a.edge_grazes, a.mismatches.len()),
        (0, 1, 1),
        "{a:?}"
    );
    // The same triangle hit half a unit further along: within the rounding of a plane through
    // vertices 1e6 out, met at a grazing angle 1000 units away; a mismatch on a unit triangle
    // met head-on 10 units away.
    let hit = |t: f32, instance: u32| GpuHit {
        t,
        instance,
        ..GpuHit::default()
    };
    let (far, far_index) = one_triangle([
        Vec3::new(-1.0e6, 0.0, 0.0),
        Vec3::new(1.0e6, 0.0, 0.0),
        Vec3::new(0.0, 1.0e6, 0.0),
    ]);
    let grazing = ray(
        Vec3::new(0.0, 0.5, 10.0),
        Vec3::new(0.0, 1.0, -0.01),
        0.0,
        f32::INFINITY,
    );
    let a = compare(&far, &[grazing], &[hit(1000.5, far_index)], VISIBLE);
    assert_eq!(
        (a.rounding_grazes, a.edge_grazes, a.mismatches.len()),
        (1, 0, 0),
        "{a:?}"
    );
    let a = compare(&unit, &[down(0.3, 0.3)], &[hit(1.5, unit_index)], VISIBLE);
    assert_eq!(
        (a.rounding_grazes, a.edge_grazes, a.mismatches.len()),
        (0, 0, 1),
        "{a:?}"
    );
}

/// One fuzzed-ingestion case (see the property above), generated from `seed`.
fn fuzzed_geometry_case(seed: u64) -> Result<(), TestCaseError> {
    let mut rng = Rng(seed);
    let ctx = context(4);
    let mut oracle = Oracle::default();
    let mut c = ctx.create_task_container();
    let mut expected = Vec::new();
    for k in 0..3 {
        let (tris, verts) = (20 + rng.below(60), 8 + rng.below(40));
        let m = hostile_mesh(&mut rng, tris, verts);
        let (dropped, traced) = expected_ingestion(&m);
        let h = ctx.create_geometry_handle();
        schedule_mesh(&mut c, h, &format!("hostile {k}"), &m);
        oracle.geometry(h, &traced);
        expected.push((h, dropped));
        for j in 0..2 {
            // The first instance of each geometry is an ordinary one, so that rays hit.
            let transform = match if j == 0 { 4 } else { rng.below(5) } {
                0 => Affine3A::from_scale(Vec3::new(1.0, 1.0, 0.0)),
                1 => Affine3A::from_scale(Vec3::new(0.0, 2.0, 0.0)),
                2 => Affine3A::from_scale(Vec3::splat(1.0e3)),
                _ => random_transform(&mut rng, 2.0),
            };
            let i = ctx.create_instance_handle();
            let input = InstanceInput::new(h, transform);
            c.schedule_bvh_task(InstanceTask {
                operation: TaskOperation::Register,
                handle: i,
                input: input.clone(),
            });
            oracle.instance(i, &input);
        }
    }
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: 3,
        ..Default::default()
    });
    build_submit_complete(&ctx, c);
    let device = gpu().device.clone();
    for (h, dropped) in &expected {
        prop_assert_eq!(dropped_after_polls(&ctx, &device, *h), *dropped);
    }
    let rays = random_rays(&mut rng, 600, 3.0);
    let hits = closest(&ctx, &rays);
    let a = compare(&oracle, &rays, &hits, VISIBLE);
    assert_agrees(&a, "closest hit over fuzzed geometry");
    Ok(())
}

/// A TLAS over thousands of instances (above the one-workgroup sort, so the radix sort of the
/// TLAS's coarse 24-bit keys runs): a dense cluster whose instances share key cells, coincident
/// instances (equal keys and equal hits: the lowest instance wins), instances spread wide, a few
/// far away stretching the bounds, and empty slots (not participating, destroyed). Hits equal
/// the CPU oracle's after the build and after a TLAS refit that moves some of them.
#[test]
fn thousands_of_clustered_and_coincident_instances_equal_the_cpu_oracle() {
    let mut rng = Rng(2024);
    let ctx = context(4);
    let mut oracle = Oracle::default();
    let mut c = ctx.create_task_container();
    let meshes = [Mesh::icosphere(1), Mesh::soup(&mut rng, 60, 1.0)];
    let geometries: Vec<GeometryHandle> = meshes
        .iter()
        .enumerate()
        .map(|(k, m)| {
            let h = ctx.create_geometry_handle();
            schedule_mesh(&mut c, h, &format!("small mesh {k}"), m);
            oracle.geometry(h, m);
            h
        })
        .collect();
    let n = 2000usize;
    let handles = ctx.create_instance_handles(n);
    let mut inputs: Vec<InstanceInput> = Vec::with_capacity(n);
    let small = |rng: &mut Rng, at: Vec3| {
        Affine3A::from_scale_rotation_translation(
            Vec3::splat(rng.range(0.02, 0.1)),
            Quat::from_axis_angle(rng.unit(), rng.range(0.0, std::f32::consts::TAU)),
            at,
        )
    };
    for k in 0..n {
        let geometry = geometries[k % 2];
        let mut input = match k % 10 {
            // Coincident with the instance before it: same geometry, same transform, so equal
            // keys and hits at equal t (the lower instance index must win).
            0 if k > 0 => InstanceInput::new(inputs[k - 1].geometry, inputs[k - 1].transform),
            // The dense cluster: 0.5 across in a scene thousands across.
            1..=4 => {
                let at = rng.v(-0.25, 0.25);
                InstanceInput::new(geometry, small(&mut rng, at))
            }
            9 if k % 100 == 9 => InstanceInput::new(geometry, random_transform(&mut rng, 4000.0)),
            _ => InstanceInput::new(geometry, random_transform(&mut rng, 40.0)),
        };
        if k % 13 == 7 {
            input.participating_in_tlas = false;
        }
        c.schedule_bvh_task(InstanceTask {
            operation: TaskOperation::Register,
            handle: handles[k],
            input: input.clone(),
        });
        oracle.instance(handles[k], &input);
        inputs.push(input);
    }
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    // Destroyed instances leave empty slots in the rebuilt TLAS (the slot count stays).
    for k in (5..n).step_by(97) {
        ctx.destroy_instance_handle(handles[k]).unwrap();
        oracle.remove_instance(handles[k]);
    }
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(BvhBuildTask {
        tlas_update: TlasUpdate::Rebuild,
        ..Default::default()
    });
    build_submit_complete(&ctx, c);

    // Rays into the cluster from nearby, and rays across the spread instances.
    let rays_now = |rng: &mut Rng| -> Vec<GpuRay> {
        let mut rays: Vec<GpuRay> = (0..200)
            .map(|_| {
                let o = rng.v(-1.0, 1.0);
                ray(o, rng.v(-0.25, 0.25) - o, 0.0, f32::INFINITY)
            })
            .collect();
        rays.extend(random_rays(rng, 200, 45.0));
        rays
    };
    let rays = rays_now(&mut rng);
    let hits = closest(&ctx, &rays);
    let a = compare(&oracle, &rays, &hits, VISIBLE);
    assert_agrees(&a, "clustered instances, rebuilt TLAS");
    assert!(a.hits > 200, "the rays must hit things: {}", a.hits);

    // Move every third live instance (a refit keeps the tree of the old keys).
    let mut c = ctx.create_task_container();
    for k in (0..n).step_by(3).filter(|k| (k + 92) % 97 != 0) {
        let mut input = inputs[k].clone();
        input.transform = Affine3A::from_translation(Vec3::new(0.1, -0.05, 0.2)) * input.transform;
        c.schedule_bvh_task(InstanceTask {
            operation: TaskOperation::Update,
            handle: handles[k],
            input: input.clone(),
        });
        oracle.instance(handles[k], &input);
    }
    c.schedule_bvh_task(BvhBuildTask {
        tlas_update: TlasUpdate::Refit,
        ..Default::default()
    });
    build_submit_complete(&ctx, c);
    let hits = closest(&ctx, &rays);
    assert_agrees(
        &compare(&oracle, &rays, &hits, VISIBLE),
        "clustered instances, refitted TLAS",
    );
}

/// Rays from inside closed meshes, and rays through their shared edges and vertices (from inside
/// and outside), never miss; rays lying in face planes and axis-aligned rays agree with the CPU.
#[test]
fn closed_meshes_have_no_gaps() {
    let ctx = context(4);
    let mut oracle = Oracle::default();
    let sphere = Mesh::icosphere(3);
    let cube = Mesh::cuboid(Vec3::splat(-1.0), Vec3::splat(1.0));
    let gs = ctx.create_geometry_handle();
    let gc = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    schedule_mesh(&mut c, gs, "icosphere", &sphere);
    schedule_mesh(&mut c, gc, "cube", &cube);
    oracle.geometry(gs, &sphere);
    oracle.geometry(gc, &cube);
    let placements = [
        (gs, Affine3A::IDENTITY),
        (
            gs,
            Affine3A::from_scale_rotation_translation(
                Vec3::new(2.0, 0.5, 1.0),
                Quat::from_rotation_y(0.7),
                Vec3::new(6.0, 0.0, 0.0),
            ),
        ),
        (gc, Affine3A::from_translation(Vec3::new(0.0, 6.0, 0.0))),
        (
            gc,
            Affine3A::from_rotation_translation(
                Quat::from_rotation_z(0.3),
                Vec3::new(0.0, 0.0, 6.0),
            ),
        ),
    ];
    let mut inst = Vec::new();
    for (g, t) in placements {
        let h = ctx.create_instance_handle();
        let input = InstanceInput::new(g, t);
        c.schedule_bvh_task(InstanceTask {
            operation: TaskOperation::Register,
            handle: h,
            input: input.clone(),
        });
        oracle.instance(h, &input);
        inst.push((h, g, t));
    }
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);

    let mut rng = Rng(7);
    let mut must_hit = Vec::new();
    for &(_, g, t) in &inst {
        let m = if g == gs { &sphere } else { &cube };
        let centre = t.transform_point3(Vec3::ZERO);
        // Every vertex and every edge midpoint, from the centre and from random inside points.
        let mut targets: Vec<Vec3> = m.positions.iter().map(|p| t.transform_point3(*p)).collect();
        for tri in m.indices.chunks(3) {
            for k in 0..3 {
                let (a, b) = (
                    m.positions[tri[k] as usize],
                    m.positions[tri[(k + 1) % 3] as usize],
                );
                targets.push(t.transform_point3((a + b) * 0.5));
            }
        }
        for p in &targets {
            must_hit.push(ray(centre, *p - centre, 0.0, f32::INFINITY));
            let inside = t.transform_point3(rng.v(-0.3, 0.3));
            must_hit.push(ray(inside, *p - inside, 0.0, f32::INFINITY));
            // From outside, aimed exactly at the vertex or edge point.
            let outside = centre + (*p - centre) * 3.0 + rng.v(-0.5, 0.5);
            must_hit.push(ray(outside, *p - outside, 0.0, f32::INFINITY));
        }
        for _ in 0..200 {
            let inside = t.transform_point3(rng.v(-0.5, 0.5));
            must_hit.push(ray(inside, rng.unit(), 0.0, f32::INFINITY));
        }
    }
    let hits = closest(&ctx, &must_hit);
    let missed: Vec<_> = must_hit
        .iter()
        .zip(&hits)
        .filter(|(_, h)| !h.is_hit())
        .collect();
    // Our traversal is watertight by construction: not one ray may slip through. The hardware
    // backend's triangle test is the driver's: Vulkan asks for watertightness, but Mesa 25's
    // lavapipe lets about 1 in 2,500 of these rays (aimed exactly at shared edges and vertices)
    // through, so that pass allows 1 in 1,000 and no more.
    let allowed = match backend() {
        TraversalBackend::Software => 0,
        TraversalBackend::HardwareRayQuery => must_hit.len() / 1000,
    };
    assert!(
        missed.len() <= allowed,
        "{} of {} rays through closed meshes missed ({allowed} allowed on this backend), e.g. {:?}",
        missed.len(),
        must_hit.len(),
        missed.first()
    );
    assert_agrees(
        &compare(&oracle, &must_hit, &hits, VISIBLE),
        "closed meshes",
    );

    rays_in_face_planes_agree(&ctx, &oracle, &mut rng);
}

/// Rays in the face planes and along the edges of the cube at (0, 6, 0) of
/// [`closed_meshes_have_no_gaps`], and axis-aligned rays, against the CPU.
fn rays_in_face_planes_agree(ctx: &ExecuteContext, oracle: &Oracle, rng: &mut Rng) {
    // Rays in the cube's face planes and along its edges, and axis-aligned rays.
    let cube_at = Vec3::new(0.0, 6.0, 0.0);
    let mut planar = Vec::new();
    for k in 0..400 {
        let u = rng.range(-1.5, 1.5);
        let v = rng.range(-1.5, 1.5);
        let o = cube_at
            + match k % 4 {
                0 => Vec3::new(-3.0, 1.0, u), // in the plane y = 1 (top face), along x
                1 => Vec3::new(u, -3.0, 1.0), // in the plane z = 1, along y
                2 => Vec3::new(1.0, v, -3.0), // in the plane x = 1, along z
                _ => Vec3::new(-3.0, u, v),
            };
        let d = match k % 4 {
            0 => Vec3::X,
            1 => Vec3::Y,
            2 => Vec3::Z,
            _ => Vec3::X,
        };
        planar.push(ray(o, d, 0.0, f32::INFINITY));
    }
    let hits = closest(ctx, &planar);
    let in_planes = compare(oracle, &planar, &hits, VISIBLE);
    // Every ray here starts on a plane: a disagreement excused as such would hide a real one.
    assert_eq!(in_planes.plane_starts, 0, "rays in face planes");
    // A ray lying in a triangle's plane grazes it everywhere: our traversal decides each the
    // way the oracle does; the driver (hardware backend) may call any of them a miss, so there
    // only real mismatches count.
    if backend() == TraversalBackend::HardwareRayQuery {
        assert!(
            in_planes.mismatches.is_empty(),
            "rays in face planes: {:?}",
            &in_planes.mismatches[..in_planes.mismatches.len().min(3)]
        );
    }
    assert_agrees(
        &Agreement {
            edge_grazes: match backend() {
                TraversalBackend::Software => in_planes.edge_grazes,
                TraversalBackend::HardwareRayQuery => 0,
            },
            ..in_planes
        },
        "rays in face planes",
    );
    // Our traversal also hits the faces that in-plane rays meet at their edges; the axis-aligned
    // quarter (about 44 rays inside the face x = -1) hits on either backend.
    let least = match backend() {
        TraversalBackend::Software => 50,
        TraversalBackend::HardwareRayQuery => 30,
    };
    assert!(hits.iter().filter(|h| h.is_hit()).count() > least);
}

/// A geometry of three components in three vertex formats, with offsets, strides, transforms
/// and an index range: component 0 Float16x4 at byte offset 8 with stride 12, u16 indices at
/// offset 2; component 1 Snorm16x4, non-indexed, translated by x = 2, its first triangle skipped
/// by its index range; component 2 Float32x4 with u32 indices, translated by x = 4.
fn mixed_components() -> GeometryInput {
    // Component 0: Float16x4 at byte offset 8 with stride 12, u16 indices at offset 2;
    // 2 triangles (a quad at z = 0 spanning x 0..1).
    let quad = [
        [0.0f32, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
    ];
    let mut vbytes = vec![0u8; 8];
    for p in quad {
        for c in [p[0], p[1], p[2], 1.0] {
            vbytes.extend_from_slice(&half_bits(c).to_le_bytes());
        }
        vbytes.extend_from_slice(&[0xee; 4]); // stride padding
    }
    vbytes.resize(vbytes.len().div_ceil(4) * 4, 0);
    let mut ibytes = vec![0u8; 2];
    for i in [0u16, 1, 2, 0, 2, 3] {
        ibytes.extend_from_slice(&i.to_le_bytes());
    }
    ibytes.resize(ibytes.len().div_ceil(4) * 4, 0);
    // Component 1: Snorm16x4, non-indexed, translated by x = 2 with its transform; the index
    // range skips its first triangle.
    let mut sbytes = Vec::new();
    for p in [
        [0.0f32, 0.0, 0.0],
        [0.5, 0.0, 0.0],
        [0.5, 0.5, 0.0],
        [0.0, 0.0, 0.0],
        [0.5, 0.5, 0.0],
        [0.0, 0.5, 0.0],
    ] {
        for c in [p[0], p[1], p[2], 0.0] {
            sbytes.extend_from_slice(&((c * 32767.0).round() as i16).to_le_bytes());
        }
    }
    // Component 2: Float32x4, u32 indices, translated by x = 4.
    let f4: Vec<f32> = quad.iter().flat_map(|p| [p[0], p[1], p[2], 7.0]).collect();
    let i4 = [0u32, 1, 2, 0, 2, 3];
    let src = wgpu::BufferUsages::COPY_SRC;
    GeometryInput {
        name: "mixed".into(),
        components: vec![
            GeometryComponent {
                vertex_buffer: VertexBufferInput {
                    buffer: buffer(&vbytes, src),
                    offset: 8,
                    stride: 12,
                    count: 4,
                    format: VertexFormat::Float16x4,
                },
                index_buffer: Some(IndexBufferInput {
                    buffer: buffer(&ibytes, src),
                    offset: 2,
                    count: 6,
                    format: IndexFormat::Uint16,
                }),
                transform: None,
                index_range: None,
                opacity: None,
            },
            GeometryComponent {
                vertex_buffer: VertexBufferInput {
                    buffer: buffer(&sbytes, src),
                    offset: 0,
                    stride: 8,
                    count: 6,
                    format: VertexFormat::Snorm16x4,
                },
                index_buffer: None,
                transform: Some(Affine3A::from_translation(Vec3::new(2.0, 0.0, 0.0))),
                index_range: Some((3, 3)),
                opacity: None,
            },
            GeometryComponent {
                vertex_buffer: VertexBufferInput {
                    buffer: buffer(bytemuck::cast_slice(&f4), src),
                    offset: 0,
                    stride: 16,
                    count: 4,
                    format: VertexFormat::Float32x4,
                },
                index_buffer: Some(IndexBufferInput {
                    buffer: buffer(bytemuck::cast_slice(&i4), src),
                    offset: 0,
                    count: 6,
                    format: IndexFormat::Uint32,
                }),
                transform: Some(Affine3A::from_translation(Vec3::new(4.0, 0.0, 0.0))),
                index_range: None,
                opacity: None,
            },
        ],
        ..Default::default()
    }
}

/// Per-component formats, strides, offsets, transforms and index ranges: each hit reports the
/// documented primitive index (earlier components' triangles first).
#[test]
fn ingestion_formats_and_components_hit_the_documented_primitives() {
    let ctx = context(4);
    let g = ctx.create_geometry_handle();
    let input = mixed_components();
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Register,
        handle: g,
        input,
    });
    let i = ctx.create_instance_handle();
    register_instance(&mut c, i, g, Affine3A::IDENTITY);
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    assert_eq!(ctx.geometry_triangle_count(g).unwrap(), Some(5));

    // (x, y) aimed at, expected primitive.
    let cases = [
        ((0.75, 0.25), 0),      // component 0, triangle (0,1,2)
        ((0.25, 0.75), 1),      // component 0, triangle (0,2,3)
        ((2.1, 0.4), 2),        // component 1's second triangle (the first is skipped by the range)
        ((2.4, 0.1), u32::MAX), // the skipped first triangle: nothing there
        ((4.75, 0.25), 3),
        ((4.25, 0.75), 4),
    ];
    let rays: Vec<GpuRay> = cases
        .iter()
        .map(|((x, y), _)| ray(Vec3::new(*x, *y, 1.0), -Vec3::Z, 0.0, 10.0))
        .collect();
    let hits = closest(&ctx, &rays);
    for (((x, y), prim), h) in cases.iter().zip(&hits) {
        if *prim == u32::MAX {
            assert!(!h.is_hit(), "({x}, {y}) must miss: {h:?}");
        } else {
            assert!(h.is_hit(), "({x}, {y}) must hit primitive {prim}");
            assert_eq!(h.primitive, *prim, "({x}, {y})");
            assert_eq!(h.instance, i.index());
            assert!((h.t - 1.0).abs() < 1e-3, "t {}", h.t);
        }
    }
}

/// f32 → IEEE half bits (round to nearest; test values are exactly representable).
fn half_bits(v: f32) -> u16 {
    let b = v.to_bits();
    let sign = ((b >> 16) & 0x8000) as u16;
    let exp = ((b >> 23) & 0xff) as i32;
    if exp == 0 {
        return sign;
    }
    let e = exp - 127 + 15;
    sign | ((e as u16) << 10) | ((b >> 13) & 0x3ff) as u16
}

/// A context of the test device that times its passes.
fn timing_context() -> ExecuteContext {
    context_with(InitSettings {
        gpu_timing: true,
        ..Default::default()
    })
}

/// Passes of `t` named `pass` under `label`.
fn pass_count(t: &GpuTimings, label: &str, pass: &str) -> usize {
    t.passes
        .iter()
        .filter(|p| p.label == label && p.pass == pass)
        .count()
}

/// Builds, submits and completes `c`'s task; its GPU timings where the device has timestamp
/// queries.
fn run_timed(ctx: &ExecuteContext, c: TaskContainer) -> Option<GpuTimings> {
    let mut e = encoder();
    let task = ctx.build_gpu_task(c, &mut e).unwrap();
    submit(e);
    ctx.mark_gpu_task_completed(task).unwrap();
    gpu()
        .device
        .features()
        .contains(wgpu::Features::TIMESTAMP_QUERY)
        .then(|| ctx.wait_for_gpu_timings(task).unwrap())
}

/// An `allow_update` geometry whose vertices move, refitted, traces exactly like a fresh build
/// of the moved vertices; TLAS refit after moving instances equals a TLAS rebuild. Both BLAS
/// kinds are refit: the LBVH (`Auto` with `allow_update`) and the clustered fast-trace tree
/// (`PreferFastTrace`), whose refit climbs a topology without block structure. The fresh build
/// is a clustered fast-trace tree either way.
#[test]
fn refits_equal_rebuilds() {
    refit_equals_rebuild(BuildHint::Auto);
    refit_equals_rebuild(BuildHint::PreferFastTrace);
}

fn refit_equals_rebuild(hint: BuildHint) {
    let dynamic = |m: &Mesh| {
        let mut input = mesh_input("dyn", m, true);
        input.build_hint = hint;
        input
    };
    let mut rng = Rng(99);
    let before = Mesh::soup(&mut rng, 3000, 1.0);
    let mut after = before.clone();
    for p in &mut after.positions {
        *p += Vec3::new(p.y * 0.3, (p.x * 5.0).sin() * 0.1, 0.05);
    }
    let transforms: Vec<Affine3A> = (0..40).map(|_| random_transform(&mut rng, 3.0)).collect();
    let moved: Vec<Affine3A> = transforms
        .iter()
        .map(|t| Affine3A::from_translation(Vec3::new(0.3, -0.2, 0.1)) * *t)
        .collect();

    // A: register `before`, build; update to `after` (refit); move instances with a TLAS refit.
    let a = context(4);
    let ga = a.create_geometry_handle();
    let mut c = a.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Register,
        handle: ga,
        input: dynamic(&before),
    });
    let ia: Vec<InstanceHandle> = a.create_instance_handles(transforms.len());
    for (h, t) in ia.iter().zip(&transforms) {
        register_instance(&mut c, *h, ga, *t);
    }
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&a, c);
    let mut c = a.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Update,
        handle: ga,
        input: dynamic(&after),
    });
    for (h, t) in ia.iter().zip(&moved) {
        c.schedule_bvh_task(InstanceTask {
            operation: TaskOperation::Update,
            handle: *h,
            input: InstanceInput::new(ga, *t),
        });
    }
    c.schedule_bvh_task(BvhBuildTask {
        tlas_update: TlasUpdate::Refit,
        ..Default::default()
    });
    let mut e = encoder();
    let task = a.build_gpu_task(c, &mut e).unwrap();
    submit(e);
    a.mark_gpu_task_completed(task).unwrap();
    assert!(a.geometry_is_built(ga).unwrap());

    // B: `after` and `moved` built from scratch.
    let b = context(4);
    let gb = b.create_geometry_handle();
    let mut c = b.create_task_container();
    schedule_mesh(&mut c, gb, "static", &after);
    let ib: Vec<InstanceHandle> = b.create_instance_handles(moved.len());
    for (h, t) in ib.iter().zip(&moved) {
        register_instance(&mut c, *h, gb, *t);
    }
    c.schedule_bvh_task(BvhBuildTask {
        tlas_update: TlasUpdate::Rebuild,
        ..Default::default()
    });
    build_submit_complete(&b, c);

    let rays = random_rays(&mut rng, 3000, 5.0);
    let ha = closest(&a, &rays);
    let hb = closest(&b, &rays);
    let mut oracle = Oracle::default();
    oracle.geometry(gb, &after);
    for (h, t) in ib.iter().zip(&moved) {
        oracle.instance(*h, &InstanceInput::new(gb, *t));
    }
    assert_agrees(&compare(&oracle, &rays, &hb, VISIBLE), "rebuild");
    assert_agrees(
        &compare(&oracle, &rays, &ha, VISIBLE),
        &format!("{hint:?} refit"),
    );
    // The triangle data and instance transforms are bit-identical in both contexts, and the tie
    // rule makes the reported hit independent of the tree: refit and rebuild must agree exactly.
    // The driver has no tie rule: between coincident triangles its refitted and rebuilt
    // structures may report either, so on that backend a differing hit must be a tie the oracle
    // confirms (both triangles hit at that distance), with the same distance.
    for (k, (x, y)) in ha.iter().zip(&hb).enumerate() {
        if backend() == TraversalBackend::HardwareRayQuery
            && (x.instance, x.primitive) != (y.instance, y.primitive)
        {
            assert!(
                x.is_hit()
                    && y.is_hit()
                    && close(x.t, y.t)
                    && oracle.hits_at(&rays[k], x.instance, x.primitive, x.t)
                    && oracle.hits_at(&rays[k], y.instance, y.primitive, y.t),
                "{hint:?}: ray {k} {:?}: refit {x:?}, rebuild {y:?} (not a tie)",
                rays[k]
            );
            continue;
        }
        assert_eq!(
            (
                x.instance,
                x.primitive,
                x.t.to_bits(),
                x.u.to_bits(),
                x.v.to_bits()
            ),
            (
                y.instance,
                y.primitive,
                y.t.to_bits(),
                y.u.to_bits(),
                y.v.to_bits()
            ),
            "{hint:?}: ray {k} {:?}: refit {x:?}, rebuild {y:?}",
            rays[k]
        );
    }
}

/// A fast-build BLAS (`PreferFastBuild`, or `Auto` with `allow_update`) gets its nodes from the
/// range refit's passes right after the hierarchy: one block of 256 triangles or less, exactly
/// one, one and a bit, several; each geometry under one instance, traced against the CPU oracle.
/// The builds of one task are two batches, one chain of passes each: those that keep their sort
/// order and topology for refits (`allow_update`) and those that do not.
#[test]
fn fast_build_blases_of_every_size_trace_as_the_oracle_says() {
    let ctx = timing_context();
    let mut rng = Rng(77);
    let counts = [2u32, 3, 17, 255, 256, 257, 513, 2000];
    let mut c = ctx.create_task_container();
    let mut oracle = Oracle::default();
    let geometries = ctx.create_geometry_handles(2 * counts.len());
    let instances = ctx.create_instance_handles(geometries.len());
    let mut centroids: Vec<Vec<Vec3>> = Vec::new();
    for (k, ((&g, &i), allow_update)) in geometries
        .iter()
        .zip(&instances)
        .zip([false, true].into_iter().cycle())
        .enumerate()
    {
        let mesh = Mesh::soup(&mut rng, counts[k / 2], 1.0);
        let mut input = mesh_input("fast-build", &mesh, allow_update);
        input.build_hint = if allow_update {
            BuildHint::Auto
        } else {
            BuildHint::PreferFastBuild
        };
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Register,
            handle: g,
            input,
        });
        // Side by side along x, so rays cross several geometries.
        let t = Affine3A::from_translation(Vec3::new(3.0 * k as f32, 0.0, 0.0));
        register_instance(&mut c, i, g, t);
        oracle.geometry(g, &mesh);
        oracle.instance(i, &InstanceInput::new(g, t));
        // Not the soup's slivers and degenerate triangles, whose hit or miss at the centroid
        // is a matter of rounding (FMA on the H100 and not on the CPU: 3 of 4000 rays).
        let shift = Vec3::from(t.translation);
        centroids.push(well_shaped_centroids(&mesh, shift));
    }
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: geometries.len() as u32,
        ..Default::default()
    });
    if let Some(t) = run_timed(&ctx, c) {
        let passes = |name: &str| pass_count(&t, "blas build", name);
        assert_eq!(
            (
                passes("lbvh hierarchy"),
                passes("lbvh refit gather"),
                passes("lbvh range refit")
            ),
            (2, 2, 2),
            "two batches for {} fast-build builds: {:?}",
            geometries.len(),
            t.passes.iter().map(|p| p.pass).collect::<Vec<_>>()
        );
        assert_eq!(passes("blas build: triangle aabbs"), 0);
    }
    // Random rays (misses, bounded and axis-aligned ones), then rays at every geometry's
    // well-shaped triangles from around it.
    let mut rays = random_rays(&mut rng, 2000, 2.0);
    for (k, r) in rays.iter_mut().enumerate() {
        r.origin[0] += 3.0 * (k % geometries.len()) as f32;
    }
    let random = rays.len();
    // (A tiny soup may have no well-shaped triangle: its rays are left out.)
    let targets: Vec<&Vec<Vec3>> = centroids.iter().filter(|c| !c.is_empty()).collect();
    assert!(
        targets.len() >= centroids.len() - 4,
        "too few geometries to aim at"
    );
    for k in 0..2000 {
        let of = targets[k % targets.len()];
        let at = of[rng.below(of.len() as u32) as usize];
        let o = at + rng.v(-2.0, 2.0);
        rays.push(ray(o, at - o, 0.0, f32::INFINITY));
    }
    let hits = closest(&ctx, &rays);
    assert_agrees(
        &compare(&oracle, &rays, &hits, VISIBLE),
        "fast-build BLASes",
    );
    let aimed_hits = hits[random..].iter().filter(|h| h.t >= 0.0).count();
    assert!(
        aimed_hits > 1900,
        "{aimed_hits} of 2000 rays aimed at triangles hit"
    );
}

/// An update refit in the task that ingests it decodes the application's bytes itself (the
/// ingestion fused into the refit); one that `max_blas_build_count` leaves to a later task is
/// ingested as usual and refit then. Both trace as the CPU oracle says, and the dropped
/// triangles of a fused refit are counted and reported.
#[test]
fn update_refits_in_their_task_and_later_trace_and_report_drops() {
    let g = gpu();
    let ctx = context(4);
    let mut rng = Rng(123);
    // Two fast-build geometries of more than one block of 256 triangles.
    let before = [
        Mesh::soup(&mut rng, 700, 1.0),
        Mesh::soup(&mut rng, 900, 1.0),
    ];
    let mut after = before.clone();
    for m in &mut after {
        for p in &mut m.positions {
            *p += Vec3::new(p.y * 0.3, (p.x * 5.0).sin() * 0.1, 0.05);
        }
    }
    // The first's last triangle references a vertex past the end: dropped by the fused refit.
    let last = after[0].indices.len() - 1;
    after[0].indices[last] = 99_999;
    let geoms = ctx.create_geometry_handles(2);
    let insts = ctx.create_instance_handles(2);
    let place = |k: usize| Affine3A::from_translation(Vec3::new(3.0 * k as f32 - 3.0, -1.5, -1.5));
    let mut c = ctx.create_task_container();
    for (k, (geom, inst)) in geoms.iter().zip(&insts).enumerate() {
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Register,
            handle: *geom,
            input: mesh_input(&format!("dyn{k}"), &before[k], true),
        });
        register_instance(&mut c, *inst, *geom, place(k));
    }
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);

    // Both updated, one refit allowed: the first is refit now, the second waits.
    let mut c = ctx.create_task_container();
    for (k, geom) in geoms.iter().enumerate() {
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Update,
            handle: *geom,
            input: mesh_input(&format!("dyn{k}"), &after[k], true),
        });
    }
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: 1,
        ..Default::default()
    });
    build_submit_complete(&ctx, c);
    assert_eq!(
        dropped_after_polls(&ctx, &g.device, geoms[0]),
        DroppedTriangles {
            out_of_range_indices: 1,
            non_finite_positions: 0
        }
    );
    assert_eq!(
        dropped_after_polls(&ctx, &g.device, geoms[1]),
        DroppedTriangles::default()
    );
    // The oracle's copy of the dropped triangle is a point: never hit, and no index shifts.
    let mut seen = after.clone();
    seen[0].indices[last] = 0;
    seen[0].indices[last - 1] = 0;
    seen[0].indices[last - 2] = 0;
    // Rays at the updated triangles' centroids (from random points around them); not at the
    // soup's slivers (its collinear triangles, bent a little by the update), whose hit or miss
    // at the centroid is a matter of rounding (FMA on the H100 and not on the CPU).
    let rays: Vec<GpuRay> = (0..3000)
        .map(|k| {
            let m = &seen[k % 2];
            let corners = loop {
                let t = rng.below(m.indices.len() as u32 / 3) as usize;
                let v: [Vec3; 3] =
                    std::array::from_fn(|i| m.positions[m.indices[3 * t + i] as usize]);
                if well_shaped(&v) {
                    break v;
                }
            };
            let c = place(k % 2).transform_point3((corners[0] + corners[1] + corners[2]) / 3.0);
            let o = c + rng.v(-2.0, 2.0);
            ray(o, c - o, 0.0, f32::INFINITY)
        })
        .collect();
    let agree = |meshes: [&Mesh; 2], what: &str| {
        let mut oracle = Oracle::default();
        for (k, (geom, inst)) in geoms.iter().zip(&insts).enumerate() {
            oracle.geometry(*geom, meshes[k]);
            oracle.instance(*inst, &InstanceInput::new(*geom, place(k)));
        }
        let hits = closest(&ctx, &rays);
        let a = compare(&oracle, &rays, &hits, VISIBLE);
        assert!(a.hits > 1000, "{what}: {} hits", a.hits);
        assert_agrees(&a, what);
    };
    agree([&seen[0], &before[1]], "first refit, second waiting");
    // A task with no geometry work refits the second from its staged triangles.
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    agree([&seen[0], &seen[1]], "both refit");
}

/// Update refits of fast-build geometries of very different sizes in one task are recorded as
/// one batch: one `lbvh refit ingest` for every refit that decodes the application's bytes
/// (more than one block of 256 triangles), whose one `lbvh range refit` follows, and one `lbvh
/// refit gather` for those refit from staged triangles (one block or less: no range pass); and
/// every moved geometry traces as the CPU oracle says.
#[test]
fn a_batch_of_refits_of_every_size_traces_as_the_oracle_says() {
    let ctx = timing_context();
    let mut rng = Rng(61);
    let counts = [2u32, 3, 100, 256, 257, 513, 2000, 20_000];
    let before: Vec<Mesh> = counts
        .iter()
        .map(|&n| Mesh::soup(&mut rng, n, 1.0))
        .collect();
    // Every mesh bent and shifted: each box changes.
    let after: Vec<Mesh> = before
        .iter()
        .map(|m| {
            let mut m = m.clone();
            for p in &mut m.positions {
                *p += Vec3::new(p.y * 0.3, (p.x * 5.0).sin() * 0.1, 0.05);
            }
            m
        })
        .collect();
    let geoms = ctx.create_geometry_handles(counts.len());
    let insts = ctx.create_instance_handles(counts.len());
    let place = |k: usize| Affine3A::from_translation(Vec3::new(3.0 * k as f32, 0.0, 0.0));
    let schedule = |c: &mut TaskContainer, op, meshes: &[Mesh]| {
        for (k, geom) in geoms.iter().enumerate() {
            c.schedule_bvh_task(GeometryTask {
                operation: op,
                handle: *geom,
                // `Auto` with `allow_update`: the fast-build tree, refit by its leaf ranges.
                input: mesh_input(&format!("{} triangles", counts[k]), &meshes[k], true),
            });
        }
        c.schedule_bvh_task(BvhBuildTask {
            max_blas_build_count: counts.len() as u32,
            ..Default::default()
        });
    };
    let mut c = ctx.create_task_container();
    schedule(&mut c, TaskOperation::Register, &before);
    for (k, (geom, inst)) in geoms.iter().zip(&insts).enumerate() {
        register_instance(&mut c, *inst, *geom, place(k));
    }
    build_submit_complete(&ctx, c);
    let mut c = ctx.create_task_container();
    schedule(&mut c, TaskOperation::Update, &after);
    if let Some(t) = run_timed(&ctx, c) {
        let passes = |name: &str| pass_count(&t, "blas refit", name);
        assert_eq!(
            (
                passes("lbvh refit ingest"),
                passes("lbvh refit gather"),
                passes("lbvh range refit")
            ),
            // The staged refits are of one block: all their nodes are the gather's.
            (1, 1, 1),
            "one batch for all {} refits: {:?}",
            counts.len(),
            t.passes
                .iter()
                .map(|p| (p.label, p.pass))
                .collect::<Vec<_>>()
        );
    }
    let mut oracle = Oracle::default();
    let mut rays = random_rays(&mut rng, 1000, 2.0);
    for (k, r) in rays.iter_mut().enumerate() {
        r.origin[0] += 3.0 * (k % counts.len()) as f32;
    }
    let mut aimed = 0;
    for (k, (geom, inst)) in geoms.iter().zip(&insts).enumerate() {
        oracle.geometry(*geom, &after[k]);
        oracle.instance(*inst, &InstanceInput::new(*geom, place(k)));
        let centres = well_shaped_centroids(&after[k], Vec3::from(place(k).translation));
        aimed += usize::from(!centres.is_empty());
        for j in 0..centres.len().min(200) {
            let at = centres[(j * 7919) % centres.len()];
            let o = at + rng.v(-2.0, 2.0);
            rays.push(ray(o, at - o, 0.0, f32::INFINITY));
        }
    }
    assert!(aimed >= counts.len() - 2, "too few geometries to aim at");
    let hits = closest(&ctx, &rays);
    let a = compare(&oracle, &rays, &hits, VISIBLE);
    assert!(a.hits > 1000, "{} hits", a.hits);
    assert_agrees(&a, "a batch of refits of every size");
}

/// The instance a hit reports is the index of that instance's data, with instances registered
/// out of order, destroyed, and their slots reused.
#[test]
fn hit_instance_is_the_instance_data_index() {
    let ctx = context(4);
    let g = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    let quad = Mesh {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
        indices: vec![0, 1, 2, 0, 2, 3],
    };
    schedule_mesh(&mut c, g, "quad", &quad);
    build_submit_complete(&ctx, c);
    let handles = ctx.create_instance_handles(120);
    // Register in reverse order, each quad at x = 2·index.
    let mut c = ctx.create_task_container();
    for h in handles.iter().rev() {
        register_instance(
            &mut c,
            *h,
            g,
            Affine3A::from_translation(Vec3::new(2.0 * h.index() as f32, 0.0, 0.0)),
        );
    }
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    // Destroy every third; re-create (slots reused lowest first) and place them at x = -2·(k+1).
    let dead: Vec<InstanceHandle> = handles.iter().step_by(3).copied().collect();
    ctx.destroy_instance_handles(&dead).unwrap();
    let again = ctx.create_instance_handles(dead.len() + 5);
    let mut c = ctx.create_task_container();
    for (k, h) in again.iter().enumerate().rev() {
        register_instance(
            &mut c,
            *h,
            g,
            Affine3A::from_translation(Vec3::new(-2.0 * (k as f32 + 1.0), 0.0, 0.0)),
        );
    }
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);

    let mut rays = Vec::new();
    let mut expect = Vec::new();
    for h in handles.iter().filter(|h| !dead.contains(h)) {
        rays.push(ray(
            Vec3::new(2.0 * h.index() as f32 + 0.5, 0.5, 1.0),
            -Vec3::Z,
            0.0,
            5.0,
        ));
        expect.push(Some(h.index()));
    }
    for (k, h) in again.iter().enumerate() {
        rays.push(ray(
            Vec3::new(-2.0 * (k as f32 + 1.0) + 0.5, 0.5, 1.0),
            -Vec3::Z,
            0.0,
            5.0,
        ));
        expect.push(Some(h.index()));
    }
    // Where destroyed instances were, unless a re-created one took the same place: nothing.
    for h in &dead {
        rays.push(ray(
            Vec3::new(2.0 * h.index() as f32 + 0.5, 0.5, 1.0),
            -Vec3::Z,
            0.0,
            5.0,
        ));
        expect.push(None);
    }
    let hits = closest(&ctx, &rays);
    for (k, (h, e)) in hits.iter().zip(&expect).enumerate() {
        match e {
            Some(i) => assert_eq!(h.instance, *i, "ray {k}"),
            None => assert!(!h.is_hit(), "ray {k} hit destroyed instance's place: {h:?}"),
        }
    }
}

/// `max_blas_build_count` throttles: builds happen over later tasks, in registration order, and
/// instances of unbuilt geometry are invisible until their BLAS exists.
#[test]
fn throttled_builds_complete_in_queue_order() {
    let ctx = context(4);
    let quad = Mesh {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
        indices: vec![0, 1, 2, 0, 2, 3],
    };
    let geoms = ctx.create_geometry_handles(5);
    let insts = ctx.create_instance_handles(5);
    let mut c = ctx.create_task_container();
    for (k, (g, i)) in geoms.iter().zip(&insts).enumerate() {
        schedule_mesh(&mut c, *g, &format!("g{k}"), &quad);
        register_instance(
            &mut c,
            *i,
            *g,
            Affine3A::from_translation(Vec3::new(2.0 * k as f32, 0.0, 0.0)),
        );
    }
    let rays: Vec<GpuRay> = (0..5)
        .map(|k| {
            ray(
                Vec3::new(2.0 * k as f32 + 0.5, 0.5, 1.0),
                -Vec3::Z,
                0.0,
                5.0,
            )
        })
        .collect();
    let throttle = BvhBuildTask {
        max_blas_build_count: 2,
        ..Default::default()
    };
    c.schedule_bvh_task(throttle);
    build_submit_complete(&ctx, c);
    let built = |ctx: &ExecuteContext| {
        geoms
            .iter()
            .map(|g| ctx.geometry_is_built(*g).unwrap())
            .collect::<Vec<_>>()
    };
    assert_eq!(built(&ctx), [true, true, false, false, false]);
    let visible = |ctx: &ExecuteContext| {
        closest(ctx, &rays)
            .iter()
            .map(|h| h.is_hit())
            .collect::<Vec<_>>()
    };
    assert_eq!(visible(&ctx), [true, true, false, false, false]);
    // A container without a BvhBuildTask builds nothing.
    build_submit_complete(&ctx, ctx.create_task_container());
    assert_eq!(built(&ctx), [true, true, false, false, false]);
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(throttle);
    build_submit_complete(&ctx, c);
    assert_eq!(built(&ctx), [true, true, true, true, false]);
    assert_eq!(visible(&ctx), [true, true, true, true, false]);
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(throttle);
    build_submit_complete(&ctx, c);
    assert_eq!(visible(&ctx), [true; 5]);
}

/// Geometry `h`'s dropped-triangle counts, polling the device until they are read back (the
/// documented contract: a later call after a device poll picks them up). One poll was not always
/// enough: once in 35 runs on the H100 the counts were still missing after it. wgpu runs a
/// mapping's callback in whichever thread's poll finds it ready, and the tests share one device
/// across threads, so another test's poll taking the mapping is the likely cause.
fn dropped_after_polls(
    ctx: &ExecuteContext,
    device: &wgpu::Device,
    h: GeometryHandle,
) -> DroppedTriangles {
    for _ in 0..1000 {
        if let Some(d) = ctx.geometry_dropped_triangles(h).unwrap() {
            return d;
        }
        device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    panic!("the dropped-triangle counts of {h:?} were not read back after 1000 polls");
}

/// Out-of-range indices and NaN/∞ positions: those triangles are dropped and reported (a
/// warning naming the geometry, and counts); every other triangle, of that geometry and of the
/// others, still traces correctly.
#[test]
fn bad_geometry_is_reported_and_the_rest_traces() {
    let log: Arc<Mutex<Vec<String>>> = Arc::default();
    let sink = log.clone();
    let ctx = context_with(InitSettings {
        log_callback: Some(Arc::new(move |_, m: &str| {
            sink.lock().unwrap().push(m.to_string())
        })),
        ..Default::default()
    });
    // Three quads in a row at x = 0, 2, 4 (z = 0): "bad-index" has triangle 1 referencing
    // vertex 99; "bad-nan" has a NaN in vertex 3 (used by triangle 1 only); "bad-inf" an ∞ in vertex 3.
    let positions = |x: f32, v3: Vec3| {
        vec![
            Vec3::new(x, 0.0, 0.0),
            Vec3::new(x + 1.0, 0.0, 0.0),
            Vec3::new(x + 1.0, 1.0, 0.0),
            v3,
        ]
    };
    let meshes = [
        (
            "bad-index",
            Mesh {
                positions: positions(0.0, Vec3::new(0.0, 1.0, 0.0)),
                indices: vec![0, 1, 2, 0, 2, 99],
            },
        ),
        (
            "bad-nan",
            Mesh {
                positions: positions(2.0, Vec3::new(f32::NAN, 1.0, 0.0)),
                indices: vec![0, 1, 2, 0, 2, 3],
            },
        ),
        (
            "bad-inf",
            Mesh {
                positions: positions(4.0, Vec3::new(4.0, f32::INFINITY, 0.0)),
                indices: vec![0, 1, 2, 0, 2, 3],
            },
        ),
        (
            "good",
            Mesh {
                positions: positions(6.0, Vec3::new(6.0, 1.0, 0.0)),
                indices: vec![0, 1, 2, 0, 2, 3],
            },
        ),
    ];
    let mut c = ctx.create_task_container();
    let mut handles = Vec::new();
    for (name, m) in &meshes {
        let h = ctx.create_geometry_handle();
        schedule_mesh(&mut c, h, name, m);
        let i = ctx.create_instance_handle();
        register_instance(&mut c, i, h, Affine3A::IDENTITY);
        handles.push(h);
    }
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    let dropped: Vec<DroppedTriangles> = handles
        .iter()
        .map(|h| dropped_after_polls(&ctx, &gpu().device, *h))
        .collect();
    assert_eq!(
        dropped[0],
        DroppedTriangles {
            out_of_range_indices: 1,
            non_finite_positions: 0
        }
    );
    assert_eq!(
        dropped[1],
        DroppedTriangles {
            out_of_range_indices: 0,
            non_finite_positions: 1
        }
    );
    assert_eq!(
        dropped[2],
        DroppedTriangles {
            out_of_range_indices: 0,
            non_finite_positions: 1
        }
    );
    assert_eq!(dropped[3], DroppedTriangles::default());
    let messages = log.lock().unwrap().clone();
    for name in ["bad-index", "bad-nan", "bad-inf"] {
        assert!(
            messages
                .iter()
                .any(|m| m.contains(&format!("`{name}`")) && m.contains("dropped")),
            "no warning names {name}: {messages:?}"
        );
    }
    assert!(!messages.iter().any(|m| m.contains("`good`")));
    // Triangle 0 of every quad (lower right half) hits; triangle 1 (upper left) only on "good".
    for (k, (name, _)) in meshes.iter().enumerate() {
        let x = 2.0 * k as f32;
        let rays = [
            ray(Vec3::new(x + 0.75, 0.25, 1.0), -Vec3::Z, 0.0, 5.0),
            ray(Vec3::new(x + 0.25, 0.75, 1.0), -Vec3::Z, 0.0, 5.0),
        ];
        let hits = closest(&ctx, &rays);
        assert!(
            hits[0].is_hit() && hits[0].primitive == 0,
            "{name}: {:?}",
            hits[0]
        );
        assert!((hits[0].t - 1.0).abs() < 1e-4);
        assert_eq!(hits[1].is_hit(), k == 3, "{name}: {:?}", hits[1]);
    }
}

/// TraceRaysTask inputs are validated before anything is recorded.
#[test]
fn trace_rays_task_inputs_are_validated() {
    let ctx = context(2);
    let storage = wgpu::BufferUsages::STORAGE;
    let rays = buffer(&[0u8; 64], storage);
    let hits = buffer(&[0u8; 64], storage | wgpu::BufferUsages::COPY_SRC);
    let copy_only = buffer(&[0u8; 64], wgpu::BufferUsages::COPY_SRC);
    let cases: Vec<(TraceRaysTask, &str)> = vec![
        (
            TraceRaysTask::new(copy_only.clone(), 2, hits.clone()),
            "rays",
        ),
        (TraceRaysTask::new(rays.clone(), 2, copy_only), "hits"),
        (
            TraceRaysTask::new(rays.clone(), 3, hits.clone()),
            "rays_offset",
        ),
        (
            TraceRaysTask {
                ray_offset: 4,
                ..TraceRaysTask::new(rays.clone(), 1, hits.clone())
            },
            "rays_offset",
        ),
        (
            TraceRaysTask {
                instance_mask: InstanceInclusionMask(8),
                ..TraceRaysTask::new(rays.clone(), 1, hits.clone())
            },
            "instance_mask",
        ),
    ];
    for (task, field) in cases {
        let mut c = ctx.create_task_container();
        c.schedule_render_task(RenderTask::TraceRays(task));
        let mut e = encoder();
        match ctx.build_gpu_task(c, &mut e) {
            Err(Error::InvalidInput { task, field: f, .. }) => {
                assert_eq!(task, "TraceRaysTask");
                assert_eq!(f, field);
            }
            other => panic!("expected an error on {field}, got {other:?}"),
        }
        submit(e);
    }
    // Before any BVH exists, a valid batch simply misses.
    let r = [ray(Vec3::ZERO, Vec3::X, 0.0, f32::INFINITY)];
    let h = closest(&ctx, &r);
    assert!(!h[0].is_hit() && h[0].t == -1.0);
}

/// The TLAS follows instance changes in every task, with or without a `BvhBuildTask`, unless a
/// `BvhBuildTask` defers it with `build_tlas: false`; `TlasUpdate::Auto` refits moves.
#[test]
fn tlas_follows_instance_changes_unless_deferred() {
    let ctx = context(4);
    let quad = Mesh {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
        indices: vec![0, 1, 2, 0, 2, 3],
    };
    let g = ctx.create_geometry_handle();
    let i = ctx.create_instance_handle();
    let mut c = ctx.create_task_container();
    schedule_mesh(&mut c, g, "quad", &quad);
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    let at = |x: f32| ray(Vec3::new(x + 0.5, 0.5, 1.0), -Vec3::Z, 0.0, 5.0);
    let probe = |ctx: &ExecuteContext| {
        closest(ctx, &[at(0.0), at(3.0)])
            .iter()
            .map(|h| h.is_hit())
            .collect::<Vec<_>>()
    };
    // Registered in a container without a BvhBuildTask: visible at once.
    let mut c = ctx.create_task_container();
    register_instance(&mut c, i, g, Affine3A::IDENTITY);
    build_submit_complete(&ctx, c);
    assert_eq!(probe(&ctx), [true, false]);
    // Moved with build_tlas: false: rays of that task still see the old place...
    let moved = InstanceInput::new(g, Affine3A::from_translation(Vec3::new(3.0, 0.0, 0.0)));
    let rays = [at(0.0), at(3.0)];
    let rb = buffer(bytemuck::cast_slice(&rays), wgpu::BufferUsages::STORAGE);
    let hb = buffer(
        &[0u8; 64],
        wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
    );
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(InstanceTask {
        operation: TaskOperation::Update,
        handle: i,
        input: moved,
    });
    c.schedule_bvh_task(BvhBuildTask {
        build_tlas: false,
        ..Default::default()
    });
    c.schedule_render_task(RenderTask::TraceRays(TraceRaysTask::new(rb, 2, hb.clone())));
    build_submit_complete(&ctx, c);
    let hits: Vec<GpuHit> = bytemuck::pod_collect_to_vec(&read_buffer(&hb));
    assert_eq!([hits[0].is_hit(), hits[1].is_hit()], [true, false]);
    // ...and the next task that does not defer brings the move in (a refit).
    assert_eq!(probe(&ctx), [false, true]);
    // Destroyed: gone from the TLAS in the next task.
    ctx.destroy_instance_handle(i).unwrap();
    build_submit_complete(&ctx, ctx.create_task_container());
    assert_eq!(probe(&ctx), [false, false]);
}

/// An `Update` is a refit: another triangle count is refused naming the field, nothing is
/// recorded, and the geometry keeps tracing as before.
#[test]
fn update_with_another_triangle_count_is_refused() {
    let ctx = context(4);
    let quad = Mesh {
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
        indices: vec![0, 1, 2, 0, 2, 3],
    };
    let g = ctx.create_geometry_handle();
    let i = ctx.create_instance_handle();
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Register,
        handle: g,
        input: mesh_input("dyn", &quad, true),
    });
    register_instance(&mut c, i, g, Affine3A::IDENTITY);
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    let one = Mesh {
        indices: vec![0, 1, 2],
        ..quad.clone()
    };
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Update,
        handle: g,
        input: mesh_input("dyn", &one, true),
    });
    let mut e = encoder();
    match ctx.build_gpu_task(c, &mut e) {
        Err(Error::InvalidInput { task, field, .. }) => {
            assert_eq!((task, field.as_str()), ("GeometryTask", "input.components"));
        }
        other => panic!("expected InvalidInput, got {other:?}"),
    }
    submit(e);
    let hits = closest(&ctx, &[ray(Vec3::new(0.25, 0.75, 1.0), -Vec3::Z, 0.0, 5.0)]);
    assert!(hits[0].is_hit() && hits[0].primitive == 1, "{:?}", hits[0]);
}

/// GPU timings: with timestamp queries every SDK pass is timed under its label; without them
/// (the minimal device) a warning says so and asking for timings is an error, not a panic.
#[test]
fn gpu_timings_label_the_passes_or_say_why_not() {
    let log: Arc<Mutex<Vec<String>>> = Arc::default();
    let sink = log.clone();
    let ctx = context_with(InitSettings {
        gpu_timing: true,
        log_callback: Some(Arc::new(move |_, m: &str| {
            sink.lock().unwrap().push(m.to_string())
        })),
        ..Default::default()
    });
    let geometry = ctx.create_geometry_handle();
    let instance = ctx.create_instance_handle();
    let mut c = ctx.create_task_container();
    schedule_mesh(&mut c, geometry, "sphere", &Mesh::icosphere(2));
    register_instance(&mut c, instance, geometry, Affine3A::IDENTITY);
    c.schedule_bvh_task(BvhBuildTask::default());
    let rays = [ray(Vec3::new(0.0, 0.0, 3.0), -Vec3::Z, 0.0, 10.0)];
    c.schedule_render_task(RenderTask::TraceRays(TraceRaysTask::new(
        buffer(bytemuck::cast_slice(&rays), wgpu::BufferUsages::STORAGE),
        1,
        buffer(&[0u8; 32], wgpu::BufferUsages::STORAGE),
    )));
    let mut e = encoder();
    let task = ctx.build_gpu_task(c, &mut e).unwrap();
    submit(e);
    let timed = gpu()
        .device
        .features()
        .contains(wgpu::Features::TIMESTAMP_QUERY);
    match ctx.wait_for_gpu_timings(task) {
        Ok(t) => {
            assert!(timed);
            for label in ["ingest", "blas build", "tlas build", "trace rays"] {
                assert!(t.passes.iter().any(|p| p.label == label), "{label}: {t:?}");
                // Durations are not bounded (no performance test here), and the conversion
                // saturates, so they cannot be negative; but each label must have a span, and a
                // finite one: a NaN or infinite timestamp period (ticks to ms) makes it NaN.
                let span = t.span_ms(&[label]);
                assert!(
                    span.is_some_and(f64::is_finite),
                    "{label}: span {span:?} in {t:?}"
                );
            }
            assert!(t.span_ms(&["ingest", "blas build"]).unwrap() >= t.sum_ms(&["blas build"]));
            assert!(t.span_ms(&["no such pass"]).is_none());
            // Each task's timings are read once.
            assert!(matches!(
                ctx.wait_for_gpu_timings(task),
                Err(Error::ReadBack(_))
            ));
        }
        Err(Error::ReadBack(_)) => {
            assert!(!timed);
            assert!(log
                .lock()
                .unwrap()
                .iter()
                .any(|m| m.contains("TIMESTAMP_QUERY")));
        }
        Err(other) => panic!("{other:?}"),
    }
    ctx.mark_gpu_task_completed(task).unwrap();
}

/// Tool queries on geometry: stale handles are `InvalidHandle`, an unbuilt BLAS cannot be read
/// back, and a built one reads back with every triangle once and a sane SAH cost.
#[test]
fn blas_read_back_and_geometry_queries_check_their_handles() {
    let ctx = context(4);
    let sphere = Mesh::icosphere(2);
    let g = ctx.create_geometry_handle();
    assert!(matches!(ctx.read_back_blas(g), Err(Error::ReadBack(_))));
    let mut c = ctx.create_task_container();
    schedule_mesh(&mut c, g, "sphere", &sphere);
    build_submit_complete(&ctx, c);
    assert!(!ctx.geometry_is_built(g).unwrap());
    assert!(matches!(ctx.read_back_blas(g), Err(Error::ReadBack(_))));
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    let b = ctx.read_back_blas(g).unwrap();
    let mut prims = b.primitive_indices.clone();
    prims.sort_unstable();
    assert_eq!(
        prims,
        (0..sphere.indices.len() as u32 / 3).collect::<Vec<_>>()
    );
    let cpu = kickstart_rt::cpu::CpuBvh::build(&sphere.triangles()).sah_cost();
    assert!(
        b.sah_cost >= 1.0 && b.sah_cost < 3.0 * cpu,
        "{} vs {cpu}",
        b.sah_cost
    );
    ctx.destroy_geometry_handle(g).unwrap();
    assert!(matches!(
        ctx.read_back_blas(g),
        Err(Error::InvalidHandle { .. })
    ));
    assert!(matches!(
        ctx.geometry_is_built(g),
        Err(Error::InvalidHandle { .. })
    ));
    assert!(matches!(
        ctx.geometry_dropped_triangles(g),
        Err(Error::InvalidHandle { .. })
    ));
}

/// `build_hint`: fast-trace collapses subtrees into leaves of up to
/// `BuildHint::FAST_TRACE_MAX_LEAF` triangles by SAH (a lower SAH cost); fast-build, and `Auto`
/// with `allow_update`, keep one triangle per leaf; `Auto` on static geometry is fast-trace.
#[test]
fn build_hints_choose_the_leaf_size() {
    let ctx = context(4);
    let sphere = Mesh::icosphere(3);
    let cases = [
        (BuildHint::PreferFastTrace, false, true),
        (BuildHint::PreferFastTrace, true, true),
        (BuildHint::Auto, false, true),
        (BuildHint::PreferFastBuild, false, false),
        (BuildHint::Auto, true, false),
    ];
    let handles = ctx.create_geometry_handles(cases.len());
    let mut c = ctx.create_task_container();
    for (&(hint, allow_update, _), &h) in cases.iter().zip(&handles) {
        let mut input = mesh_input("sphere", &sphere, allow_update);
        input.build_hint = hint;
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Register,
            handle: h,
            input,
        });
    }
    build_submit_complete(&ctx, c);
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: cases.len() as u32,
        ..Default::default()
    });
    build_submit_complete(&ctx, c);
    let one_per_leaf = ctx.read_back_blas(handles[3]).unwrap().sah_cost;
    // Rays from around the sphere (radius 1) towards and past it, for the read-back traversal.
    let mut rng = Rng(31);
    let rays: Vec<kickstart_rt::cpu::Ray> = random_rays(&mut rng, 2000, 1.5)
        .iter()
        .map(|r| kickstart_rt::cpu::Ray {
            origin: Vec3::from(r.origin),
            dir: Vec3::from(r.dir),
            t_min: r.t_min,
            t_max: r.t_max,
        })
        .collect();
    let tris = sphere.triangles();
    let oracle = kickstart_rt::cpu::CpuBvh::build(&tris);
    let mut node_visits = Vec::new();
    for (&(hint, allow_update, collapsed), &h) in cases.iter().zip(&handles) {
        let b = ctx.read_back_blas(h).unwrap();
        // The read-back tree traced on the CPU finds the oracle's hits; count its work.
        let mut work = kickstart_rt::cpu::TraversalCounts::default();
        for r in &rays {
            let (hit, counts) = b.trace(r, false);
            work += counts;
            let want = oracle.closest_hit(&tris, r);
            assert_eq!(
                hit.map(|h| (h.t, h.primitive)),
                want.map(|h| (h.t, h.primitive)),
                "{hint:?}: {r:?}"
            );
        }
        node_visits.push((collapsed, work.nodes));
        // Leaf sizes reachable from the root (collapsed subtrees' nodes stay in the buffer).
        let mut leaves = Vec::new();
        let mut stack = vec![0u32];
        while let Some(i) = stack.pop() {
            for c in b.nodes[i as usize].iter().filter(|c| !c.is_empty()) {
                if c.is_leaf() {
                    leaves.push(c.leaf_range().1);
                } else {
                    stack.push(c.reference);
                }
            }
        }
        let largest = leaves.iter().copied().max().unwrap_or(0);
        let what = format!("{hint:?}, allow_update {allow_update}");
        if collapsed {
            assert!(
                largest > 1 && largest <= BuildHint::FAST_TRACE_MAX_LEAF,
                "{what}: largest leaf {largest}"
            );
            assert!(
                b.sah_cost < one_per_leaf,
                "{what}: SAH {} vs {one_per_leaf} with one triangle per leaf",
                b.sah_cost
            );
        } else {
            assert_eq!(largest, 1, "{what}");
        }
        // Reachable leaves hold every triangle exactly once.
        let triangles: u32 = leaves.iter().sum();
        assert_eq!(triangles as usize, sphere.indices.len() / 3, "{what}");
    }
    // Fuller leaves: fewer inner nodes fetched for the same rays.
    let most_collapsed = node_visits.iter().filter(|v| v.0).map(|v| v.1).max();
    let fewest_single = node_visits.iter().filter(|v| !v.0).map(|v| v.1).min();
    assert!(
        most_collapsed < fewest_single,
        "node visits (collapsed, count): {node_visits:?}"
    );
}

/// A geometry of more triangles than the device's `max_blas_primitive_count` cannot become one
/// driver BLAS: the hardware backend refuses its task by name before recording, the context is
/// unchanged, and a geometry within the limit then traces. The software backend has no such
/// limit: the same geometry traces there (a device without ray queries reports 0 for it).
#[test]
fn a_geometry_past_the_drivers_blas_limit_is_refused_only_by_the_hardware_backend() {
    let g = gpu();
    let hardware = backend() == TraversalBackend::HardwareRayQuery;
    let mut limits = g.device.limits();
    if hardware {
        // wgpu checks a BLAS's vertex count against the limit: 16 triangles of 3 vertices fit.
        limits.max_blas_primitive_count = 48;
    }
    let (device, queue) = device_with_limits(limits, "kickstart-rt small BLAS limit");
    let ctx = ExecuteContext::new(&device, &queue, InitSettings::default()).expect("context");
    assert_pass_backend(&ctx);
    assert_eq!(ctx.traversal_backend().backend, backend());
    let submit = |e: wgpu::CommandEncoder| {
        queue.submit([e.finish()]);
        device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
    };
    let big = (ctx.create_geometry_handle(), ctx.create_instance_handle());
    let mut e = device.create_command_encoder(&Default::default());
    let result = ctx.build_gpu_task(
        register_and_build(&ctx, big, many_triangles(&device, 17)),
        &mut e,
    );
    let down = [ray(
        Vec3::new(0.25, 0.75, 1.0),
        -Vec3::Z,
        0.0,
        f32::INFINITY,
    )];
    if !hardware {
        let t = result.expect("the software backend has no BLAS limit");
        submit(e);
        ctx.mark_gpu_task_completed(t).unwrap();
        let (hits, _) = trace_on(&device, &queue, &ctx, &down);
        assert_eq!((hits[0].t, hits[0].instance), (1.0, big.1.index()));
        return;
    }
    match result {
        Err(Error::InvalidInput {
            task,
            field,
            value,
            reason,
        }) => {
            assert_eq!((task, field.as_str()), ("GeometryTask", "input.components"));
            assert_eq!(value, "\"17 triangles\"");
            assert!(
                reason.contains("max_blas_primitive_count is 48"),
                "{reason}"
            );
        }
        other => panic!(
            "17 triangles past a limit of 48 vertices: {:?}",
            other.map(|t| t.serial())
        ),
    }
    assert_eq!(
        ctx.recorded_task_counts().geometry_tasks,
        0,
        "refused before recording"
    );
    submit(e);
    let fits = (ctx.create_geometry_handle(), ctx.create_instance_handle());
    let mut e = device.create_command_encoder(&Default::default());
    let t = ctx
        .build_gpu_task(
            register_and_build(&ctx, fits, many_triangles(&device, 16)),
            &mut e,
        )
        .expect("16 triangles fit");
    submit(e);
    ctx.mark_gpu_task_completed(t).unwrap();
    let (hits, _) = trace_on(&device, &queue, &ctx, &down);
    assert_eq!((hits[0].t, hits[0].instance), (1.0, fits.1.index()));
}

/// A device of the test adapter with the test device's features and `limits` (wgpu's
/// experimental ray queries accepted on the hardware pass, as the test device does).
fn device_with_limits(limits: wgpu::Limits, label: &str) -> (wgpu::Device, wgpu::Queue) {
    own_test_device(limits, label)
}

/// An instance slot past the device's `max_tlas_instance_count` cannot enter the driver's TLAS:
/// the hardware backend refuses its task by name before recording, the context is unchanged,
/// and the instances within the limit still trace. The software backend has no such limit: the
/// same instance traces there.
#[test]
fn an_instance_past_the_drivers_tlas_limit_is_refused_only_by_the_hardware_backend() {
    let g = gpu();
    let hardware = backend() == TraversalBackend::HardwareRayQuery;
    let mut limits = g.device.limits();
    if hardware {
        limits.max_tlas_instance_count = 4;
    }
    let (device, queue) = device_with_limits(limits, "kickstart-rt small TLAS limit");
    let ctx = ExecuteContext::new(&device, &queue, InitSettings::default()).expect("context");
    assert_pass_backend(&ctx);
    assert_eq!(ctx.traversal_backend().backend, backend());
    let submit = |e: wgpu::CommandEncoder| {
        queue.submit([e.finish()]);
        device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
    };
    let geometry = ctx.create_geometry_handle();
    let instances = ctx.create_instance_handles(5);
    assert_eq!(instances[4].index(), 4, "a fresh context's fifth slot");
    let at = |k: usize| Affine3A::from_translation(Vec3::new(2.0 * k as f32, 0.0, 0.0));
    // A quad under each of four instances, side by side.
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Register,
        handle: geometry,
        input: many_triangles(&device, 2),
    });
    for (k, &h) in instances[..4].iter().enumerate() {
        register_instance(&mut c, h, geometry, at(k));
    }
    c.schedule_bvh_task(BvhBuildTask::default());
    let mut e = device.create_command_encoder(&Default::default());
    let t = ctx.build_gpu_task(c, &mut e).expect("four instances fit");
    submit(e);
    ctx.mark_gpu_task_completed(t).unwrap();
    let recorded = ctx.recorded_task_counts().instance_tasks;
    // The fifth, in slot 4.
    let mut c = ctx.create_task_container();
    register_instance(&mut c, instances[4], geometry, at(4));
    c.schedule_bvh_task(BvhBuildTask::default());
    let mut e = device.create_command_encoder(&Default::default());
    let result = ctx.build_gpu_task(c, &mut e);
    let down: Vec<GpuRay> = (0..5)
        .map(|k| {
            ray(
                Vec3::new(2.0 * k as f32 + 0.25, 0.75, 1.0),
                -Vec3::Z,
                0.0,
                f32::INFINITY,
            )
        })
        .collect();
    let hit_instances = |ctx: &ExecuteContext| -> Vec<Option<u32>> {
        let (hits, _) = trace_on(&device, &queue, ctx, &down);
        hits.iter()
            .map(|h| h.is_hit().then_some(h.instance))
            .collect()
    };
    if !hardware {
        let t = result.expect("the software backend has no TLAS instance limit");
        submit(e);
        ctx.mark_gpu_task_completed(t).unwrap();
        assert_eq!(hit_instances(&ctx), (0..5).map(Some).collect::<Vec<_>>());
        return;
    }
    match result {
        Err(Error::InvalidInput {
            task,
            field,
            value,
            reason,
        }) => {
            assert_eq!(
                (task, field.as_str(), value.as_str()),
                ("InstanceTask", "handle", "4")
            );
            assert!(reason.contains("max_tlas_instance_count (4)"), "{reason}");
        }
        other => panic!(
            "instance slot 4 past a limit of 4: {:?}",
            other.map(|t| t.serial())
        ),
    }
    assert_eq!(
        ctx.recorded_task_counts().instance_tasks,
        recorded,
        "refused before recording"
    );
    submit(e);
    assert_eq!(
        hit_instances(&ctx),
        [Some(0), Some(1), Some(2), Some(3), None],
        "the four instances within the limit trace; the refused one is not there"
    );
}

/// Fast-trace builds of very different sizes registered in one task are ingested in one pass and
/// built as one batch (one hierarchy pass, one clustered climb and one gather for all of them,
/// no per-build box pass), and every geometry traces as the CPU oracle says: builds of 1, 2 and 3 triangles,
/// around the batch's 256-position blocks, and one of 100,000.
#[test]
fn a_batch_of_builds_of_every_size_traces_as_the_oracle_says() {
    let mut rng = Rng(34);
    let ctx = timing_context();
    let counts = [1u32, 2, 3, 100, 255, 256, 257, 1000, 4097, 100_000];
    let geometries = ctx.create_geometry_handles(counts.len());
    let instances = ctx.create_instance_handles(counts.len());
    let mut oracle = Oracle::default();
    let mut c = ctx.create_task_container();
    let mut centres = Vec::new();
    for (k, (&gh, &ih)) in geometries.iter().zip(&instances).enumerate() {
        let mesh = Mesh::soup(&mut rng, counts[k], 1.0);
        schedule_mesh(&mut c, gh, &format!("{} triangles", counts[k]), &mesh);
        let t = Affine3A::from_translation(Vec3::new(3.0 * k as f32, 0.0, 0.0));
        register_instance(&mut c, ih, gh, t);
        oracle.geometry(gh, &mesh);
        oracle.instance(ih, &InstanceInput::new(gh, t));
        // The centroids of well-shaped triangles: a sliver's centroid is hit or missed as
        // rounding goes (the driver's triangle test on the hardware backend, FMA on a GPU).
        let shift = Vec3::from(t.translation);
        centres.push(well_shaped_centroids(&mesh, shift));
    }
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: counts.len() as u32,
        ..Default::default()
    });
    if let Some(t) = run_timed(&ctx, c) {
        let passes = |name: &str| pass_count(&t, "blas build", name);
        assert_eq!(
            (
                passes("lbvh hierarchy"),
                passes("hploc climb"),
                passes("lbvh gather")
            ),
            (1, 1, 1),
            "one batch for all {} builds: {:?}",
            counts.len(),
            t.passes.iter().map(|p| p.pass).collect::<Vec<_>>()
        );
        assert_eq!(passes("blas build: triangle aabbs"), 0);
        // And one ingestion pass decodes all ten geometries.
        assert_eq!(t.passes.iter().filter(|p| p.label == "ingest").count(), 1);
    }
    // Rays at triangles of every geometry (the small ones all of theirs), and random ones.
    let mut rays = random_rays(&mut rng, 1000, 2.0);
    for (k, r) in rays.iter_mut().enumerate() {
        r.origin[0] += 3.0 * (k % counts.len()) as f32;
    }
    for of in &centres {
        // The small builds' every triangle; 300 of the big ones'.
        for j in 0..of.len().min(300) {
            let at = match of.len() <= 300 {
                true => of[j],
                false => of[rng.below(of.len() as u32) as usize],
            };
            let o = at + rng.v(-2.0, 2.0);
            rays.push(ray(o, at - o, 0.0, f32::INFINITY));
        }
    }
    let hits = closest(&ctx, &rays);
    let a = compare(&oracle, &rays, &hits, VISIBLE);
    assert_agrees(&a, "a batch of builds of every size");
    // Every geometry aimed at is hit somewhere (none was left unbuilt or built into another's
    // nodes); a tiny soup may have no well-shaped triangle to aim at.
    assert!(centres.iter().filter(|c| !c.is_empty()).count() >= counts.len() - 2);
    for (&ih, _) in instances
        .iter()
        .zip(&centres)
        .filter(|(_, c)| !c.is_empty())
    {
        assert!(
            hits.iter().any(|h| h.is_hit() && h.instance == ih.index()),
            "instance {} never hit",
            ih.index()
        );
    }
}

/// A child as the compaction test compares it: its box, and its leaf ref (`None`: an inner
/// child, whose index compaction renumbers).
type ComparedChild = (Vec3, Vec3, Option<u32>);

/// The inner nodes reachable from the root of a read-back BLAS, in depth-first order (left
/// child first), each with its two children as (box, leaf ref or `None` for an inner child).
fn reachable_nodes(b: &kickstart_rt::cpu::BlasReadback) -> Vec<(u32, Vec<ComparedChild>)> {
    let mut out = Vec::new();
    let mut stack = vec![0u32];
    while let Some(i) = stack.pop() {
        let node = &b.nodes[i as usize];
        out.push((
            i,
            node.iter()
                .map(|c| (c.min, c.max, c.is_leaf().then_some(c.reference)))
                .collect(),
        ));
        for c in node.iter().rev().filter(|c| !c.is_empty() && !c.is_leaf()) {
            stack.push(c.reference);
        }
    }
    out
}

/// A fast-trace BLAS of static geometry is compacted: its build moves the nodes its collapsed
/// leaves left unreferenced out of the way, the node count read back gives the rest of its
/// range back, and the next quiet task packs the node pool, moving BLASes. The compacted tree is
/// the tree a fast-trace build kept for refits makes (never compacted): the same nodes in the
/// same order, numbered 0.. without gaps, in a batch of builds and alone; node bytes are 64 a
/// reachable node; and rays traced before and after the moves hit exactly the same, as the CPU
/// oracle does.
#[test]
fn fast_trace_compaction_keeps_the_tree_and_gives_nodes_back() {
    let ctx = context(2);
    let device = gpu().device.clone();
    let sphere = Mesh::icosphere(4);
    let n = sphere.indices.len() as u64 / 3;
    let mut rng = Rng(fuzz_seed("compaction", 0xc0_4ac7));
    let soup = Mesh::soup(&mut rng, 3000, 2.0);
    let [batched, soup_h, kept, single] = [(); 4].map(|()| ctx.create_geometry_handle());
    let mut oracle = Oracle::default();
    let mut c = ctx.create_task_container();
    let mut place = |c: &mut TaskContainer, g: GeometryHandle, m: &Mesh, x: f32| {
        oracle.geometry(g, m);
        let i = ctx.create_instance_handle();
        let input = InstanceInput::new(g, Affine3A::from_translation(Vec3::new(x, 0.0, 0.0)));
        oracle.instance(i, &input);
        c.schedule_bvh_task(InstanceTask {
            operation: TaskOperation::Register,
            handle: i,
            input,
        });
        i
    };
    // One task: the sphere and the soup as a batch of fast-trace builds, and the sphere kept
    // for refits (far from the rays: it is destroyed below); then the sphere again, built alone.
    let mut kept_instance = None;
    for (g, m, update, x) in [
        (batched, &sphere, false, 0.0),
        (soup_h, &soup, false, 4.0),
        (kept, &sphere, true, 100.0),
    ] {
        let mut input = mesh_input("compaction", m, update);
        input.build_hint = BuildHint::PreferFastTrace;
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Register,
            handle: g,
            input,
        });
        let i = place(&mut c, g, m, x);
        kept_instance = Some(i).filter(|_| update);
    }
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: 8,
        ..Default::default()
    });
    build_submit_complete(&ctx, c);
    let mut c = ctx.create_task_container();
    schedule_mesh(&mut c, single, "compaction alone", &sphere);
    place(&mut c, single, &sphere, 12.0);
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    let rays: Vec<GpuRay> = (0..3000)
        .map(|k| {
            // Towards the sphere, the soup or the sphere built alone, from around it.
            let centre = Vec3::new([0.0, 4.0, 12.0][k % 3], 0.0, 0.0);
            let o = centre + rng.v(-2.5, 2.5);
            let d = (centre + rng.v(-0.8, 0.8) - o).normalize_or(Vec3::X);
            ray(o, d, 0.0, 100.0)
        })
        .collect();
    let before = closest(&ctx, &rays);

    let kept_memory = ctx.geometry_blas_memory(kept).unwrap().expect("built");
    assert_eq!(kept_memory.compaction, BlasCompaction::NotApplicable);
    assert_eq!(kept_memory.node_bytes, 64 * (n - 1));
    let reference = reachable_nodes(&ctx.read_back_blas(kept).unwrap());
    let reachable = reference.len() as u64;
    assert!(
        reachable * 4 < (n - 1) * 3,
        "{reachable} of {} nodes reachable: too few collapsed to tell",
        n - 1
    );
    for g in [batched, single] {
        let m = compacted_after_polls(&ctx, &device, g);
        assert_eq!(m.compaction, BlasCompaction::Done, "{g:?}");
        assert_eq!(m.node_bytes, 64 * reachable, "{g:?}: {m:?}");
        assert_eq!(m.triangle_bytes, 48 * n, "{g:?}");
        assert_eq!(m.refit_bytes, 0, "{g:?}");
    }
    assert_eq!(
        compacted_after_polls(&ctx, &device, soup_h).compaction,
        BlasCompaction::Done
    );
    // With the kept sphere gone (its vertex copy too), a quiet task packs the node pool (the
    // geometry headers follow the moves). What the pools keep besides the last element's
    // rounding (one 256-byte buffer or 16 elements each) is the kept sphere's triangles
    // between the others' (triangles never move: the driver's BLASes read them in place).
    ctx.destroy_instance_handle(kept_instance.expect("the kept sphere's instance"))
        .unwrap();
    ctx.destroy_geometry_handle(kept).unwrap();
    let after = closest(&ctx, &rays);
    let quiet = ctx.resource_allocations();
    assert!(
        quiet.pool_reserve <= 48 * n + 5 * 16 * 64,
        "pool space kept: {quiet:?}"
    );
    for g in [batched, single] {
        let b = ctx.read_back_blas(g).unwrap();
        assert_eq!(b.nodes.len() as u64, reachable, "{g:?}");
        let got = reachable_nodes(&b);
        // The reference's nodes, in their order, renumbered 0.. without gaps.
        let mut order: Vec<u32> = reference.iter().map(|r| r.0).collect();
        order.sort_unstable();
        for (r, c) in reference.iter().zip(&got) {
            let rank = order.binary_search(&r.0).unwrap() as u32;
            assert_eq!(c.0, rank, "{g:?}: node {} of the kept tree", r.0);
            assert_eq!(c.1, r.1, "{g:?}: node {} of the kept tree", r.0);
        }
        assert_eq!(got.len(), reference.len(), "{g:?}");
    }
    assert_agrees(&compare(&oracle, &rays, &before, 0xff), "before compaction");
    let differ = (0..rays.len()).filter(|&k| after[k] != before[k]).count();
    assert_eq!(
        differ, 0,
        "rays that trace differently once compacted and moved"
    );
    assert!(
        before.iter().filter(|h| h.is_hit()).count() > 1000,
        "too few hits to tell"
    );
}

/// Bytes wgpu's allocator holds for buffers labelled `label` on `device` (after a wait).
fn allocated_with_label(device: &wgpu::Device, label: &str) -> u64 {
    device.poll(wgpu::PollType::wait_indefinitely()).unwrap();
    let report = device
        .generate_allocator_report()
        .expect("an allocator report");
    report
        .allocations
        .iter()
        .filter(|a| a.name == label)
        .map(|a| a.size)
        .sum()
}

/// The node memory a compaction gives back returns to the driver, by wgpu's own allocator
/// report: the node pool's buffer holds the uncompacted nodes after the build, and exactly the
/// compacted ones once the next quiet task packed it.
#[test]
fn compacted_nodes_go_back_to_the_driver() {
    let (device, queue) = own_test_device(gpu().device.limits(), "kickstart-rt compaction test");
    let settings = InitSettings {
        backend: pass_backend_choice(),
        ..InitSettings::default()
    };
    let ctx = ExecuteContext::new(&device, &queue, settings).unwrap_or_else(|e| panic!("{e}"));
    assert_pass_backend(&ctx);
    let triangles = 6000u64;
    let g = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Register,
        handle: g,
        input: many_triangles(&device, triangles as u32),
    });
    register_instance(&mut c, ctx.create_instance_handle(), g, Affine3A::IDENTITY);
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete_on(&device, &queue, &ctx, c);
    const NODES: &str = "kickstart-rt BLAS nodes";
    let built = allocated_with_label(&device, NODES);
    assert!(
        built >= 64 * (triangles - 1),
        "{built} bytes of nodes after the build"
    );
    let m = compacted_after_polls(&ctx, &device, g);
    assert_eq!(m.compaction, BlasCompaction::Done);
    assert!(m.node_bytes < built / 2, "{m:?}: {built} bytes before");
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete_on(&device, &queue, &ctx, c);
    let packed = allocated_with_label(&device, NODES);
    // The allocator may round an allocation up to its placement alignment.
    assert!(
        packed >= m.node_bytes && packed <= m.node_bytes + 1024,
        "{packed} bytes of nodes held for {} compacted",
        m.node_bytes
    );
    assert_eq!(
        ctx.read_back_blas(g).unwrap().nodes.len() as u64 * 64,
        m.node_bytes
    );
}

/// Cards of the cutout test: the checkerboard with 32-bit, 16-bit float and 16-bit unorm
/// coordinates (0, 3, 4), per-triangle flags (1), opaque (2).
const CARDS: u32 = 5;

/// Points on the cutout tests' cards (card 0..3, point on the unit square) away from texel
/// edges (the micro-maps resolve a texel in 32 × 32 micro-triangles' worth; a texel edge crossing
/// one is where the two may differ) and from the cards' diagonal.
fn cutout_points() -> Vec<(u32, glam::Vec2)> {
    let mut rng = Rng(fuzz_seed("cutout cards", 0xc0_7ca7));
    let mut points = Vec::new();
    while points.len() < 1500 {
        let p = glam::Vec2::new(rng.f(), rng.f());
        let texel = p * CHECKER as f32;
        let edge = (texel - texel.round()).abs().min_element();
        if edge > 0.08 && (p.x - p.y).abs() > 0.02 {
            points.push((rng.below(CARDS), p));
        }
    }
    points
}

/// Cutout geometry: rays through a checkerboard-alpha card (glTF MASK: texture alpha × factor
/// against the cutoff) stop only on its opaque texels, for closest-hit and any-hit rays, as the
/// CPU oracle applying the same test says (exactly, away from texel edges); a card of
/// per-triangle flags lets rays through its transparent triangle only; an opaque copy of the
/// card stops every ray. Behind the cards, a floor catches what passes.
#[test]
fn cutout_cards_let_rays_through_where_they_are_transparent() {
    let ctx = context(2);
    let (card_mesh, uvs) = card();
    let flags = buffer(
        bytemuck::cast_slice(&[7u32, 0]),
        wgpu::BufferUsages::COPY_SRC,
    );
    let floor = Mesh::cuboid(Vec3::new(-1.0, -1.0, -1.2), Vec3::new(10.0, 2.0, -1.0));
    let textured = |format| checker_card(&card_mesh, &uvs, format);
    let mut flagged = mesh_input("flagged card", &card_mesh, false);
    flagged.components[0].opacity = Some(ComponentOpacity::per_triangle(flags, 0));
    let opaque = mesh_input("opaque card", &card_mesh, false);
    let mut c = ctx.create_task_container();
    let mut instances = Vec::new();
    for (k, input) in [
        textured(UvFormat::Float32x2),
        flagged,
        opaque,
        textured(UvFormat::Float16x2),
        textured(UvFormat::Unorm16x2),
        mesh_input("floor", &floor, false),
    ]
    .into_iter()
    .enumerate()
    {
        let g = ctx.create_geometry_handle();
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Register,
            handle: g,
            input,
        });
        let i = ctx.create_instance_handle();
        // Cards side by side along x (2 apart), the floor under all of them.
        let x = if k < CARDS as usize {
            2.0 * k as f32
        } else {
            0.0
        };
        register_instance(
            &mut c,
            i,
            g,
            Affine3A::from_translation(Vec3::new(x, 0.0, 0.0)),
        );
        instances.push(i.index());
    }
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: 8,
        ..Default::default()
    });
    build_submit_complete(&ctx, c);
    let points = cutout_points();
    let rays: Vec<GpuRay> = points
        .iter()
        .map(|&(card, p)| {
            let o = Vec3::new(2.0 * card as f32 + p.x, p.y, 1.0);
            ray(o, Vec3::NEG_Z, 0.0, 10.0)
        })
        .collect();
    let closest_hits = closest(&ctx, &rays);
    let shadow_rays: Vec<GpuRay> = rays.iter().map(|r| GpuRay { t_max: 1.5, ..*r }).collect();
    let any_hits = trace(
        &ctx,
        &shadow_rays,
        RayQuery::AnyHit,
        InstanceInclusionMask::VISIBLE_IN_RT,
    );
    let mut wrong = Vec::new();
    for (k, &(card, p)) in points.iter().enumerate() {
        // Triangle 0 is (0,0), (1,0), (1,1): below the diagonal.
        let stops = match card {
            1 => p.x > p.y,
            2 => true,
            _ => checker_opaque(p),
        };
        let h = closest_hits[k];
        let want = if stops {
            (instances[card as usize], 1.0)
        } else {
            (instances[CARDS as usize], 2.0)
        };
        if h.instance != want.0 || (h.t - want.1).abs() > 1e-5 {
            wrong.push(format!("card {card} at {p}: hit {h:?}, expected {want:?}"));
        }
        if any_hits[k].is_hit() != stops {
            wrong.push(format!(
                "card {card} at {p}: any hit {:?}, expected {stops}",
                any_hits[k]
            ));
        }
    }
    assert!(
        wrong.is_empty(),
        "{} of {} wrong, e.g. {:#?}",
        wrong.len(),
        2 * points.len(),
        &wrong[..wrong.len().min(6)]
    );
    let through = points
        .iter()
        .filter(|(c, p)| matches!(c, 0 | 3 | 4) && !checker_opaque(*p))
        .count();
    assert!(
        through > 300,
        "too few rays through the checkerboard's holes: {through}"
    );
}

/// Points on the unit card away from its diagonal, where its triangle 0 (below the diagonal)
/// meets triangle 1.
fn flag_card_points() -> Vec<glam::Vec2> {
    let mut rng = Rng(fuzz_seed("opacity build", 0x0b_5e7));
    std::iter::repeat_with(|| glam::Vec2::new(rng.f(), rng.f()))
        .filter(|p| (p.x - p.y).abs() > 0.02)
        .take(200)
        .collect()
}

/// Rays straight down onto `points` of the card (at z = 0, the floor at z = -1).
fn flag_card_rays(points: &[glam::Vec2]) -> Vec<GpuRay> {
    points
        .iter()
        .map(|p| ray(Vec3::new(p.x, p.y, 1.0), Vec3::NEG_Z, 0.0, 10.0))
        .collect()
}

/// Traces rays onto `points` of the card of per-triangle flags (opaque triangle 0, transparent
/// triangle 1) over the floor, registered with its flags (`cutout`) or without: each must stop
/// on the card, or on the floor through the transparent triangle; and the trace must take the
/// software traversal's build without the opacity test exactly when the scene has no cutouts.
fn assert_flag_card_traced(ctx: &ExecuteContext, points: &[glam::Vec2], step: &str, cutout: bool) {
    let before = ctx.recorded_task_counts().opaque_only_traces;
    let hits = closest(ctx, &flag_card_rays(points));
    let opaque_only = ctx.recorded_task_counts().opaque_only_traces - before;
    let software = backend() == TraversalBackend::Software;
    assert_eq!(
        opaque_only,
        u64::from(software && !cutout),
        "{step}: builds"
    );
    let want_t = |p: glam::Vec2| if !cutout || p.x > p.y { 1.0 } else { 2.0 };
    assert_card_hits(points, &hits, want_t, step);
}

/// Each of `hits`, of rays down onto `points` of the card, is a hit at `want_t(point)`.
fn assert_card_hits(
    points: &[glam::Vec2],
    hits: &[GpuHit],
    want_t: impl Fn(glam::Vec2) -> f32,
    step: &str,
) {
    let wrong: Vec<String> = points
        .iter()
        .zip(hits)
        .filter(|(p, h)| !h.is_hit() || (h.t - want_t(**p)).abs() > 1e-5)
        .map(|(p, h)| format!("at {p}: {h:?}"))
        .collect();
    assert!(
        wrong.is_empty(),
        "{step}: {} of {} rays wrong, e.g. {:?}",
        wrong.len(),
        points.len(),
        &wrong[..wrong.len().min(4)]
    );
}

/// The software traversal drops its opacity test while the scene holds no cutout geometry (so
/// opaque scenes pay nothing for cutouts), and takes it again as soon as it holds some: through
/// every change of a scene's cutout geometry, a card of per-triangle flags lets rays through its
/// transparent triangle exactly while it is registered with them, and the context reports which
/// build traced (`RecordedTaskCounts::opaque_only_traces`; the hardware backend has one build).
/// Destroying opaque geometry, or updating the card with the same flags, must not make the scene
/// look opaque.
#[test]
fn the_opacity_test_follows_the_scenes_cutout_geometry() {
    let ctx = context(2);
    let software = backend() == TraversalBackend::Software;
    let (card_mesh, _) = card();
    let flags = buffer(
        bytemuck::cast_slice(&[7u32, 0]),
        wgpu::BufferUsages::COPY_SRC,
    );
    let card_input = |cutout: bool| {
        let mut input = mesh_input("flagged card", &card_mesh, true);
        if cutout {
            input.components[0].opacity = Some(ComponentOpacity::per_triangle(flags.clone(), 0));
        }
        input
    };
    let floor = Mesh::cuboid(Vec3::new(-1.0, -1.0, -1.2), Vec3::new(4.0, 2.0, -1.0));
    let far_box = Mesh::cuboid(Vec3::new(20.0, 0.0, 0.0), Vec3::new(21.0, 1.0, 1.0));
    let points = flag_card_points();
    let schedule = |c: &mut TaskContainer, operation, g: GeometryHandle, input| {
        c.schedule_bvh_task(GeometryTask {
            operation,
            handle: g,
            input,
        });
    };
    let register = |c: &mut TaskContainer, g, input| schedule(c, TaskOperation::Register, g, input);
    let update = |c: &mut TaskContainer, g, input| schedule(c, TaskOperation::Update, g, input);
    let build = |mut c: TaskContainer| {
        c.schedule_bvh_task(BvhBuildTask {
            max_blas_build_count: 8,
            ..Default::default()
        });
        build_submit_complete(&ctx, c);
    };
    let check = |step: &str, cutout: bool| assert_flag_card_traced(&ctx, &points, step, cutout);
    let (card_g, floor_g, box_g) = (
        ctx.create_geometry_handle(),
        ctx.create_geometry_handle(),
        ctx.create_geometry_handle(),
    );
    let box_i = ctx.create_instance_handle();
    let mut c = ctx.create_task_container();
    register(&mut c, floor_g, mesh_input("floor", &floor, false));
    register(&mut c, box_g, mesh_input("far box", &far_box, false));
    register_instance(
        &mut c,
        ctx.create_instance_handle(),
        floor_g,
        Affine3A::IDENTITY,
    );
    register_instance(&mut c, box_i, box_g, Affine3A::IDENTITY);
    register(&mut c, card_g, card_input(false));
    let card_i = ctx.create_instance_handle();
    register_instance(&mut c, card_i, card_g, Affine3A::IDENTITY);
    build(c);
    check("an opaque scene", false);
    let mut c = ctx.create_task_container();
    update(&mut c, card_g, card_input(true));
    build(c);
    check("the card updated with its flags", true);
    ctx.destroy_instance_handle(box_i).unwrap();
    ctx.destroy_geometry_handle(box_g).unwrap();
    build(ctx.create_task_container());
    check("opaque geometry destroyed", true);
    let mut c = ctx.create_task_container();
    update(&mut c, card_g, card_input(true));
    build(c);
    check("the card updated again with the same flags", true);
    let mut c = ctx.create_task_container();
    update(&mut c, card_g, card_input(false));
    build(c);
    check("the card updated without flags", false);
    let mut c = ctx.create_task_container();
    update(&mut c, card_g, card_input(true));
    build(c);
    check("the card updated with its flags again", true);
    // The last cutout geometry destroyed: the opaque build again, and only the floor left.
    ctx.destroy_instance_handle(card_i).unwrap();
    ctx.destroy_geometry_handle(card_g).unwrap();
    build(ctx.create_task_container());
    let before = ctx.recorded_task_counts().opaque_only_traces;
    let hits = closest(&ctx, &flag_card_rays(&points));
    let opaque_only = ctx.recorded_task_counts().opaque_only_traces - before;
    assert_eq!(
        opaque_only,
        u64::from(software),
        "the card destroyed: builds"
    );
    assert!(
        hits.iter().all(|h| h.is_hit() && (h.t - 2.0).abs() <= 1e-5),
        "the card destroyed: {:?}",
        hits.iter()
            .find(|h| !h.is_hit() || (h.t - 2.0).abs() > 1e-5)
    );
}

/// A cutout geometry deformed by updates (a skinned or morphed character's alpha-tested parts):
/// each refit keeps the opacity of every triangle where the triangle went. The card of
/// per-triangle flags, `allow_update`, is mirrored (x ↦ 1 − x) and lifted to z = 0.25 with the
/// same flags: its transparent triangle now covers x + y > 1, where rays reach the floor, and
/// the rest stop on the card at its new height; then it goes back.
#[test]
fn a_deformed_cutout_geometry_keeps_its_holes_on_its_triangles() {
    let ctx = context(2);
    let (card_mesh, _) = card();
    let flags = buffer(
        bytemuck::cast_slice(&[7u32, 0]),
        wgpu::BufferUsages::COPY_SRC,
    );
    let card_input = |mesh: &Mesh| {
        let mut input = mesh_input("deformed card", mesh, true);
        input.components[0].opacity = Some(ComponentOpacity::per_triangle(flags.clone(), 0));
        input
    };
    let deformed = Mesh {
        positions: card_mesh
            .positions
            .iter()
            .map(|p| Vec3::new(1.0 - p.x, p.y, 0.25))
            .collect(),
        indices: card_mesh.indices.clone(),
    };
    let floor = Mesh::cuboid(Vec3::new(-1.0, -1.0, -1.2), Vec3::new(4.0, 2.0, -1.0));
    let (card_g, floor_g) = (ctx.create_geometry_handle(), ctx.create_geometry_handle());
    let mut c = ctx.create_task_container();
    for (g, input) in [
        (floor_g, mesh_input("floor", &floor, false)),
        (card_g, card_input(&card_mesh)),
    ] {
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Register,
            handle: g,
            input,
        });
    }
    for g in [floor_g, card_g] {
        register_instance(&mut c, ctx.create_instance_handle(), g, Affine3A::IDENTITY);
    }
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    let points: Vec<glam::Vec2> = flag_card_points()
        .into_iter()
        .filter(|p| (p.x + p.y - 1.0).abs() > 0.02)
        .collect();
    // Where a ray down onto `p` stops: the card at `card_t`, or the floor (t = 2) through the
    // transparent triangle.
    let check = |step: &str, transparent: &dyn Fn(glam::Vec2) -> bool, card_t: f32| {
        let hits = closest(&ctx, &flag_card_rays(&points));
        let want_t = |p| if transparent(p) { 2.0 } else { card_t };
        assert_card_hits(&points, &hits, want_t, step);
    };
    check("as built", &|p| p.x < p.y, 1.0);
    for (step, mesh, transparent, card_t) in [
        (
            "mirrored and lifted",
            &deformed,
            &(|p: glam::Vec2| p.x + p.y > 1.0) as &dyn Fn(glam::Vec2) -> bool,
            0.75,
        ),
        ("back", &card_mesh, &|p: glam::Vec2| p.x < p.y, 1.0),
    ] {
        let mut c = ctx.create_task_container();
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Update,
            handle: card_g,
            input: card_input(mesh),
        });
        c.schedule_bvh_task(BvhBuildTask::default());
        build_submit_complete(&ctx, c);
        check(step, transparent, card_t);
    }
}
