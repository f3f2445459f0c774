//! Ray batches: rays from a buffer are traced through the scene (closest or any hit) and their
//! hits written to a buffer. Also holds the scene bindings every tracing pass shares.

use crate::device::TraversalBackend;
use crate::gpu::layout::BoundLayout;
use crate::gpu::reflect::{ReflectedLayout, ReflectedShader};
use crate::gpu::shader::traversal_pipeline;
use crate::gpu::Recorder;
use crate::scene::traversal::{self, LeafTest, PerLeafTest, SceneBuffers};
use bytemuck::{Pod, Zeroable};
use std::num::NonZeroU64;

/// Invocations per workgroup of the ray batch shader (its `@workgroup_size`): `RT_WORKGROUP_SIZE`
/// of `shaders/scene/traversal.wgsl`.
const WORKGROUP_SIZE: u32 = 64;

/// Size of one [`GpuRay`] / [`GpuHit`] record in bytes.
pub(crate) const RECORD_SIZE: u64 = 32;

#[allow(unused_imports)] // GpuHit and GpuRay are this module's tests' vocabulary
pub(crate) use crate::tasks::{GpuHit, GpuRay, RayQuery};

/// The ray batch pass's shader for `backend` with the leaf test `leaf`.
fn trace_rays_shader(backend: TraversalBackend, leaf: LeafTest) -> ReflectedShader {
    traversal::compose(backend, leaf, &["trace/rays"], &[])
}

/// The WGSL of the ray batch pass with `backend` (each traversal build), labelled.
pub(crate) fn shader_variants(backend: TraversalBackend) -> Vec<(String, String)> {
    LeafTest::all(backend)
        .iter()
        .map(|&leaf| {
            (
                format!("trace rays ({leaf:?})"),
                trace_rays_shader(backend, leaf).source().to_string(),
            )
        })
        .collect()
}

/// `size` bytes of a buffer from a byte offset, as a binding.
fn range((buffer, offset): (&wgpu::Buffer, u64), size: NonZeroU64) -> wgpu::BindingResource<'_> {
    wgpu::BindingResource::Buffer(wgpu::BufferBinding {
        buffer,
        offset,
        size: Some(size),
    })
}

/// Uniform parameters of the ray batch shader (`TraceParams`).
#[repr(C)]
#[derive(Pod, Zeroable, Clone, Copy)]
struct TraceParams {
    count: u32,
    query: u32,
    mask: u32,
    pad: u32,
}

/// One build of the ray batch pipeline.
struct RayPipeline {
    pipeline: wgpu::ComputePipeline,
    /// Whether the pipeline came from our own SPIR-V (no stack zero fill).
    #[cfg_attr(not(test), allow(dead_code))] // tests: a silent fallback to WGSL must fail them
    own_spirv: bool,
}

/// The ray batch pass (`trace rays`).
pub(crate) struct RayTracer {
    backend: TraversalBackend,
    scene_layout: BoundLayout,
    /// The layout of `@group(1)` (parameters, rays, hits) as the shader declares it.
    io_layout: ReflectedLayout,
    /// One pipeline per traversal build, created on first use (one for both queries: the query
    /// is a uniform, so one bind group layout serves every batch).
    pipelines: PerLeafTest<RayPipeline>,
}

impl RayTracer {
    /// Creates the layouts; the pipeline of each traversal build comes on first use.
    pub fn new(device: &wgpu::Device, backend: TraversalBackend) -> Self {
        let shader = trace_rays_shader(backend, LeafTest::WithCutouts);
        RayTracer {
            backend,
            scene_layout: SceneBuffers::layout(device, backend),
            io_layout: ReflectedLayout::new(
                device,
                "kickstart-rt trace rays io",
                shader.reflection(),
                1,
            ),
            pipelines: PerLeafTest::default(),
        }
    }

    /// Creates the pipeline of the traversal build `leaf` now.
    pub fn prepare(&self, device: &wgpu::Device, leaf: LeafTest) {
        self.pipeline(device, leaf);
    }

    /// The pipeline of build `leaf`, created on first use.
    fn pipeline(&self, device: &wgpu::Device, leaf: LeafTest) -> &RayPipeline {
        self.pipelines.get_or_init(leaf, || {
            let shader = trace_rays_shader(self.backend, leaf);
            let layouts = [self.scene_layout.group(), self.io_layout.group()];
            // SAFETY: the pass is bounded by construction, so naga's checks only cost time:
            // - the ray and hit bindings hold exactly `count` records and `main` returns for
            //   i >= count;
            // - the traversal's stack index is checked against RT_STACK_SIZE before every push
            //   and is > 0 before every pop; its loop stops after RT_MAX_VISITS node visits;
            // - every scene index comes from data the SDK built (node refs and leaf ranges from
            //   its BVH builders, the TLAS's ref table from its build, instance and geometry
            //   tables from validated handles), never from the user's buffers; a ref made for
            //   another build of its BLAS (a TLAS update deferred past a rebuild) is entered at
            //   the BLAS root, so it never indexes nodes of another build;
            // - the traversal has no other loop (a leaf's triangles are one per iteration);
            // - `rt_stack` is read only below the stack pointer, and every entry there was
            //   written first (a push stores, then raises the pointer), so it needs no zero fill.
            let (pipeline, own_spirv) = unsafe {
                traversal_pipeline(
                    device,
                    "kickstart-rt trace rays",
                    shader.source(),
                    "main",
                    &layouts,
                    wgpu::ShaderRuntimeChecks::unchecked(),
                    traversal::uninitialized(self.backend),
                )
            };
            RayPipeline {
                pipeline,
                own_spirv,
            }
        })
    }

    /// Records tracing `count` rays read from `rays` (buffer, byte offset) into `hits` (buffer,
    /// byte offset). The offsets must be multiples of the device's
    /// `min_storage_buffer_offset_alignment` and the buffers must hold `count` records from them
    /// (the caller validates). Only instances with `(instance.mask & mask) != 0` are traced.
    #[allow(clippy::too_many_arguments)] // mirrors the task's fields one to one
    pub fn record(
        &self,
        rec: &mut Recorder<'_>,
        scene: &SceneBuffers<'_>,
        rays: (&wgpu::Buffer, u64),
        hits: (&wgpu::Buffer, u64),
        count: u32,
        query: RayQuery,
        mask: u32,
    ) {
        let Some(size) = NonZeroU64::new(count as u64 * RECORD_SIZE) else {
            return;
        };
        let params = rec.uniform(
            "kickstart-rt trace rays params",
            &TraceParams {
                count,
                query: match query {
                    RayQuery::ClosestHit => 0,
                    RayQuery::AnyHit => 1,
                },
                mask,
                pad: 0,
            },
        );
        let pipeline = &self.pipeline(rec.device, scene.leaf_test()).pipeline;
        let scene_group = scene.bind_group(rec.device, pipeline);
        let io_group = self.io_layout.bind_group(
            rec.device,
            &[
                ("params", params.as_entire_binding()),
                ("rays", range(rays, size)),
                ("hits", range(hits, size)),
            ],
        );
        rec.dispatch(
            "trace rays",
            pipeline,
            &[&scene_group, &io_group],
            count.div_ceil(WORKGROUP_SIZE),
        );
    }
}

#[cfg(test)]
mod tests {
    //! GPU traversal against the CPU oracle (`test_scene::TestScene::closest_hit`), on the
    //! software traversal in every test pass: these are its exact rules (watertight shared
    //! edges, the tie rule, the inclusive `t` range), which the driver's triangle test does not
    //! promise. The hardware backend's agreement, with its tolerances, is tested through the
    //! context in `tests/gpu/ray_tracing.rs`.
    //!
    //! Agreement rule (GPUs may contract a*b+c into an FMA, so results can differ in the last
    //! ulp): a GPU hit agrees with the CPU when it reports the same (instance, primitive) with
    //! |Δt| ≤ 1e-4·max(1, t) (barycentrics within 1e-3), or when the CPU confirms that the GPU's
    //! (instance, primitive) is hit by the ray at a t within that tolerance of the CPU's closest
    //! t (a tie). A GPU miss with a CPU hit (or the reverse) is only accepted when the hit lies
    //! within 1e-5 of an edge in barycentric terms; those are counted and must be rare.
    use super::*;

    /// Barycentric distance from an edge within which GPU and CPU may legitimately disagree
    /// (docs/ray-tracing-core.md: f32 rounding, fused multiply-adds on NVIDIA). 1e-5 was too
    /// tight on the H100: one ray of the random soup hit there beyond it.
    const EDGE_TOLERANCE: f32 = 1e-4;
    use crate::cpu::Ray;
    use crate::trace::test_scene::{cube, gpu_ray, gpu_trace, Rng, TestInstance, TestScene, Tri};
    use glam::{Affine3A, Quat, Vec3};

    const MISS: u32 = u32::MAX;

    /// The pass's WGSL validated with naga without a device; the uniform and the ray and hit
    /// records (the public `GpuRay`, `GpuHit`) against its structs and buffer strides.
    #[test]
    fn the_wgsl_validates_and_matches_the_rust_layouts() {
        use crate::gpu::wgsl_check::{assert_wgsl_layout, storage_stride, validate};
        // Both traversal builds are valid; their layouts are the same module's.
        validate(
            "trace rays (OpaqueOnly)",
            trace_rays_shader(TraversalBackend::Software, LeafTest::OpaqueOnly).source(),
        );
        let module = validate(
            "trace rays",
            trace_rays_shader(TraversalBackend::Software, LeafTest::WithCutouts).source(),
        );
        assert!(module.entry_points.iter().any(|e| e.name == "main"));
        assert_wgsl_layout!(
            module,
            "TraceParams",
            TraceParams {
                count,
                query,
                mask,
                pad
            }
        );
        assert_wgsl_layout!(
            module,
            "RtRay",
            GpuRay {
                origin,
                t_min,
                dir,
                t_max
            }
        );
        assert_wgsl_layout!(
            module,
            "GpuHitOut",
            GpuHit {
                t,
                u,
                v,
                instance,
                primitive,
                _pad => "pad0",
            }
        );
        assert_eq!(storage_stride(&module, "rays") as u64, RECORD_SIZE);
        assert_eq!(storage_stride(&module, "hits") as u64, RECORD_SIZE);
    }

    #[test]
    fn the_pass_comes_from_own_spirv_where_the_device_takes_it() {
        // A pass that silently fell back to WGSL would zero-fill its stack per invocation again
        // (measured much slower on the H100; see docs/decisions/stack-zero-fill.md).
        let g = crate::gpu::testing::gpu();
        let tracer = RayTracer::new(&g.device, TraversalBackend::Software);
        // Expected from the test device's backend and features, not from the decision itself.
        let expected = crate::gpu::spirv::test_device_takes_own_spirv(&g.device);
        for &leaf in LeafTest::all(TraversalBackend::Software) {
            tracer.prepare(&g.device, leaf);
            let built = tracer.pipelines.get(leaf).map(|p| p.own_spirv);
            assert_eq!(built, Some(expected), "{leaf:?}");
        }
    }

    fn ray(origin: Vec3, dir: Vec3) -> Ray {
        Ray {
            origin,
            dir,
            t_min: 0.0,
            t_max: f32::INFINITY,
        }
    }

    fn edge_distance(u: f32, v: f32) -> f32 {
        u.min(v).min(1.0 - u - v)
    }

    /// Compares GPU closest and any hits with the oracle; returns the number of accepted
    /// near-edge hit/miss disagreements.
    fn check(scene: &TestScene, rays: &[Ray], mask: u32) -> usize {
        let gpu_rays: Vec<GpuRay> = rays.iter().map(gpu_ray).collect();
        let closest = gpu_trace(scene, &gpu_rays, RayQuery::ClosestHit, mask);
        let any = gpu_trace(scene, &gpu_rays, RayQuery::AnyHit, mask);
        let mut near_edge = 0;
        for (i, r) in rays.iter().enumerate() {
            let g = closest[i];
            let cpu = scene.closest_hit(r, mask);
            if g.instance != MISS {
                assert!(
                    scene.visible(g.instance as usize, mask),
                    "ray {i} {r:?}: hit invisible instance {}",
                    g.instance
                );
            }
            match (cpu, g.instance != MISS) {
                (Some(c), true) => {
                    let tol = 1e-4 * c.t.abs().max(1.0);
                    if (c.instance, c.primitive) == (g.instance, g.primitive) {
                        assert!(
                            (g.t - c.t).abs() <= tol
                                && (g.u - c.u).abs() <= 1e-3
                                && (g.v - c.v).abs() <= 1e-3,
                            "ray {i} {r:?}: gpu {g:?} cpu {c:?}"
                        );
                    } else {
                        let h = scene.hit_triangle(g.instance as usize, g.primitive, r);
                        let confirmed = h.is_some_and(|h| (h.t - c.t).abs() <= tol);
                        // Not confirmed: both hits must lie on edges of their triangles (the ray
                        // passes through a shared edge or vertex, and an ulp of difference in
                        // the object-space ray picks another triangle of the fan).
                        let on_edges = edge_distance(g.u, g.v) <= EDGE_TOLERANCE
                            && edge_distance(c.u, c.v) <= EDGE_TOLERANCE;
                        assert!(
                            (confirmed || on_edges) && (g.t - c.t).abs() <= tol,
                            "ray {i} {r:?}: gpu {g:?} (cpu says {h:?}) cpu {c:?}"
                        );
                        if !confirmed {
                            near_edge += 1;
                        }
                    }
                }
                (Some(c), false) => {
                    assert!(
                        edge_distance(c.u, c.v) <= EDGE_TOLERANCE,
                        "ray {i} {r:?}: gpu missed, cpu {c:?}"
                    );
                    near_edge += 1;
                }
                (None, true) => {
                    assert!(
                        edge_distance(g.u, g.v) <= EDGE_TOLERANCE,
                        "ray {i} {r:?}: cpu missed, gpu {g:?}"
                    );
                    near_edge += 1;
                }
                (None, false) => {}
            }
            let a = any[i];
            assert_eq!(
                a.instance != MISS,
                g.instance != MISS,
                "ray {i} {r:?}: any-hit {a:?} closest {g:?}"
            );
            if a.instance != MISS {
                // The occluder must be a real hit in range.
                let tol = 1e-4 * a.t.abs().max(1.0);
                let h = scene.hit_triangle(a.instance as usize, a.primitive, r);
                assert!(
                    h.is_some_and(|h| (h.t - a.t).abs() <= tol)
                        || edge_distance(a.u, a.v) <= EDGE_TOLERANCE,
                    "ray {i} {r:?}: any-hit occluder {a:?}, cpu says {h:?}"
                );
            } else {
                assert_eq!(a.t, -1.0);
            }
        }
        near_edge
    }

    /// `check` for random rays: near-edge disagreements must be rare (≤ 1 in 1000).
    fn check_random(scene: &TestScene, rays: &[Ray], mask: u32) -> usize {
        let near_edge = check(scene, rays, mask);
        assert!(
            near_edge * 1000 <= rays.len(),
            "{near_edge} near-edge disagreements in {} rays",
            rays.len()
        );
        near_edge
    }

    fn random_soup(rng: &mut Rng, n: usize, spread: f32, size: f32) -> Vec<Tri> {
        let mut tris: Vec<Tri> = (0..n)
            .map(|_| {
                let c = rng.v() * spread;
                [c + rng.v() * size, c + rng.v() * size, c + rng.v() * size]
            })
            .collect();
        // Duplicates (ties at equal t) and degenerates (never hit).
        tris.extend_from_within(0..n / 20);
        tris.push([Vec3::ONE; 3]);
        tris.push([Vec3::ZERO, Vec3::X, Vec3::X * 2.0]);
        tris
    }

    /// Random rays from a box of half-size `extent`; some aimed at points on triangles (so many
    /// hit), some axis-aligned (zero direction components), some with a limited t range.
    fn random_rays(rng: &mut Rng, n: usize, extent: f32, targets: &[Vec3]) -> Vec<Ray> {
        (0..n)
            .map(|i| {
                let origin = rng.v() * extent;
                let mut r = match i % 4 {
                    0 => ray(origin, rng.v()),
                    1 | 2 if !targets.is_empty() => {
                        let t = targets[rng.below(targets.len() as u32) as usize];
                        ray(origin, t - origin)
                    }
                    _ => {
                        let mut d = Vec3::ZERO;
                        d[rng.below(3) as usize] = if rng.f() < 0.5 { -1.0 } else { 1.0 };
                        if rng.f() < 0.3 {
                            d[rng.below(3) as usize] = rng.f() - 0.5;
                        }
                        ray(origin, d)
                    }
                };
                if i % 7 == 0 {
                    r.t_min = rng.f();
                    r.t_max = r.t_min + rng.f() * extent;
                }
                r
            })
            .collect()
    }

    /// Points inside triangles (random barycentrics).
    fn surface_points(rng: &mut Rng, tris: &[Tri], xf: &Affine3A, n: usize) -> Vec<Vec3> {
        (0..n)
            .map(|_| {
                let [a, b, c] = tris[rng.below(tris.len() as u32) as usize];
                let (mut u, mut v) = (rng.f(), rng.f());
                if u + v > 1.0 {
                    (u, v) = (1.0 - u, 1.0 - v);
                }
                xf.transform_point3(a + (b - a) * u + (c - a) * v)
            })
            .collect()
    }

    #[test]
    fn trace_rays_matches_cpu_on_random_soup_with_duplicates_and_degenerates() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let tris = random_soup(&mut rng, 600, 3.0, 0.4);
        let targets = surface_points(&mut rng, &tris, &Affine3A::IDENTITY, 500);
        let rays = random_rays(&mut rng, 2500, 5.0, &targets);
        let scene = TestScene::single_software(tris);
        let near_edge = check_random(&scene, &rays, 0xff);
        // Duplicates (600..630 copy 0..30) tie exactly with their originals: the lower
        // primitive index always wins.
        let hits = gpu_trace(
            &scene,
            &rays.iter().map(gpu_ray).collect::<Vec<_>>(),
            RayQuery::ClosestHit,
            0xff,
        );
        assert!(hits.iter().any(|h| h.primitive < 30));
        assert!(hits.iter().all(|h| !(600..630).contains(&h.primitive)));
        eprintln!(
            "random soup: {near_edge} near-edge disagreements in {}",
            rays.len()
        );
    }

    #[test]
    fn trace_rays_matches_cpu_with_transformed_and_masked_instances() {
        let mut rng = Rng(12345);
        let soup = random_soup(&mut rng, 200, 1.0, 0.3);
        let geometries = vec![soup, cube(2), Vec::new()];
        let rot = |axis: Vec3, a: f32| Quat::from_axis_angle(axis.normalize(), a);
        let mut instances = vec![
            TestInstance::new(0, Affine3A::from_translation(Vec3::new(-2.0, 0.0, 0.0))),
            TestInstance::new(
                1,
                Affine3A::from_scale_rotation_translation(
                    Vec3::splat(0.5),
                    rot(Vec3::new(1.0, 2.0, 3.0), 0.7),
                    Vec3::new(1.5, 1.0, 0.0),
                ),
            ),
            // Non-uniform scale.
            TestInstance::new(
                1,
                Affine3A::from_scale_rotation_translation(
                    Vec3::new(2.0, 0.3, 0.7),
                    rot(Vec3::new(-1.0, 0.5, 0.2), 1.9),
                    Vec3::new(0.5, -1.5, 1.0),
                ),
            ),
            // Mirror.
            TestInstance::new(
                0,
                Affine3A::from_scale_rotation_translation(
                    Vec3::new(-1.0, 1.0, 1.0),
                    rot(Vec3::Y, 0.3),
                    Vec3::new(1.0, 0.5, -1.5),
                ),
            ),
            // Excluded from mask 1 (overlaps instance 0).
            TestInstance::new(
                0,
                Affine3A::from_rotation_translation(rot(Vec3::Z, 0.5), Vec3::new(-1.8, 0.2, 0.1)),
            ),
            // Not participating (overlaps instance 1).
            TestInstance::new(1, Affine3A::from_translation(Vec3::new(1.5, 1.0, 0.0))),
            // Empty geometry.
            TestInstance::new(2, Affine3A::IDENTITY),
            // Identical copy of instance 1: ties go to the lower instance.
            TestInstance::new(
                1,
                Affine3A::from_scale_rotation_translation(
                    Vec3::splat(0.5),
                    rot(Vec3::new(1.0, 2.0, 3.0), 0.7),
                    Vec3::new(1.5, 1.0, 0.0),
                ),
            ),
        ];
        instances[4].mask = 0b10;
        instances[5].live = false;
        let mut targets = Vec::new();
        for inst in &instances {
            let g = &geometries[inst.geometry as usize];
            if !g.is_empty() {
                targets.extend(surface_points(&mut rng, g, &inst.transform, 100));
            }
        }
        let rays = random_rays(&mut rng, 2000, 4.0, &targets);
        let mut scene = TestScene::software(geometries, instances);
        let mut near_edge = 0;
        for (mask, n) in [(0b01, rays.len()), (0xff, rays.len()), (0b10, 500)] {
            near_edge += check_random(&scene, &rays[..n], mask);
        }
        // Refs of another BLAS build (a TLAS update deferred past a rebuild) are entered at the
        // root: the same hits, not just triangle 0 of each instance.
        scene.make_refs_stale();
        near_edge += check_random(&scene, &rays[..1000], 0xff);
        // The identical copy (instance 7) is never the closest hit: instance 1 wins every tie.
        let closest = gpu_trace(
            &scene,
            &rays.iter().map(gpu_ray).collect::<Vec<_>>(),
            RayQuery::ClosestHit,
            0xff,
        );
        assert!(closest.iter().all(|h| h.instance != 7 && h.instance != 5));
        assert!(closest.iter().any(|h| h.instance == 1));
        eprintln!(
            "instances: {near_edge} near-edge disagreements in {} rays",
            2 * rays.len() + 1500
        );
    }

    /// A closed mesh (a subdivided cube, and the same cube projected onto a sphere so vertices
    /// have arbitrary coordinates), transformed: rays from inside through every vertex, along
    /// every edge and in random directions never miss.
    #[test]
    fn closed_mesh_is_watertight_through_shared_edges_and_vertices() {
        let mut rng = Rng(777);
        let sphere: Vec<Tri> = cube(4).iter().map(|t| t.map(|v| v.normalize())).collect();
        for (tris, xf) in [
            (cube(3), Affine3A::IDENTITY),
            (
                sphere,
                Affine3A::from_scale_rotation_translation(
                    Vec3::new(1.0, 2.0, 0.5),
                    Quat::from_euler(glam::EulerRot::XYZ, 0.3, -0.7, 1.1),
                    Vec3::new(0.1, 0.2, -0.3),
                ),
            ),
        ] {
            let mut targets = Vec::new();
            for [a, b, c] in &tris {
                targets.extend([*a, *b, *c]);
                for s in [0.5f32, 0.25, rng.f()] {
                    targets.push(a.lerp(*b, s));
                    targets.push(b.lerp(*c, s));
                }
            }
            let mut rays = Vec::new();
            for o in [
                Vec3::ZERO,
                Vec3::new(0.1, -0.2, 0.3),
                Vec3::new(-0.3, 0.05, -0.1),
            ] {
                let origin = xf.transform_point3(o);
                for t in &targets {
                    rays.push(ray(origin, xf.transform_point3(*t) - origin));
                }
                for _ in 0..300 {
                    rays.push(ray(origin, rng.v()));
                }
            }
            let scene = TestScene::software(vec![tris], vec![TestInstance::new(0, xf)]);
            let hits = gpu_trace(
                &scene,
                &rays.iter().map(gpu_ray).collect::<Vec<_>>(),
                RayQuery::ClosestHit,
                0xff,
            );
            for (r, h) in rays.iter().zip(&hits) {
                assert!(h.instance == 0, "GPU missed from inside: {r:?}");
                assert!(scene.closest_hit(r, 0xff).is_some(), "CPU missed: {r:?}");
            }
            // Rays aimed at vertices and edges: disagreements on which triangle of a fan is
            // hit are expected here (not rare), misses are not.
            let near_edge = check(&scene, &rays, 0xff);
            eprintln!(
                "closed mesh: {near_edge} edge/vertex tie disagreements in {}",
                rays.len()
            );
        }
    }

    /// Axis-aligned rays (zero direction components, origins on slab planes) and rays lying in
    /// a face plane.
    #[test]
    fn axis_aligned_and_in_plane_rays_match_cpu() {
        let quad = vec![
            [
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, -1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
            ],
            [
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(-1.0, 1.0, 0.0),
            ],
        ];
        let scene = TestScene::software(
            vec![cube(2), quad],
            vec![
                TestInstance::new(0, Affine3A::IDENTITY),
                TestInstance::new(1, Affine3A::from_translation(Vec3::new(0.0, 0.0, 3.0))),
            ],
        );
        let mut rays = Vec::new();
        let coords = [-1.5f32, -1.0, -0.5, 0.0, 0.5, 1.0, 1.5];
        let dirs = [Vec3::X, -Vec3::X, Vec3::Y, -Vec3::Y, Vec3::Z, -Vec3::Z];
        for &x in &coords {
            for &y in &coords {
                for &z in &[-3.0f32, -1.0, 0.0, 1.0, 3.0] {
                    for d in dirs {
                        rays.push(ray(Vec3::new(x, y, z), d));
                        rays.push(ray(Vec3::new(y, z, x), d));
                    }
                    // In the plane z = const (the cube's faces at ±1, the quad at 3).
                    rays.push(ray(Vec3::new(x, y, z), Vec3::new(1.0, 0.5, 0.0)));
                    rays.push(ray(Vec3::new(x, y, z), Vec3::new(-0.3, 1.0, 0.0)));
                }
            }
        }
        let near_edge = check(&scene, &rays, 0xff);
        eprintln!(
            "axis-aligned: {near_edge} edge disagreements in {}",
            rays.len()
        );
    }

    #[test]
    fn t_range_is_inclusive_and_limits_both_queries() {
        let quad = vec![
            [
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, -1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
            ],
            [
                Vec3::new(-1.0, -1.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(-1.0, 1.0, 0.0),
            ],
        ];
        let scene = TestScene::single_software(quad);
        let o = Vec3::new(0.25, -0.5, 2.0);
        let with = |dir: Vec3, t_min: f32, t_max: f32| Ray {
            origin: o,
            dir,
            t_min,
            t_max,
        };
        let cases = [
            (with(-Vec3::Z, 0.0, 2.0), Some(2.0)),
            (with(-Vec3::Z, 0.0, 1.999), None),
            (with(-Vec3::Z, 2.0, 5.0), Some(2.0)),
            (with(-Vec3::Z, 2.001, 5.0), None),
            (with(-Vec3::Z, 0.0, f32::INFINITY), Some(2.0)),
            // Unnormalised direction: t in units of its length.
            (with(Vec3::new(0.0, 0.0, -4.0), 0.0, 1.0), Some(0.5)),
            (with(Vec3::Z, 0.0, f32::INFINITY), None),
            (with(-Vec3::Z, 3.0, 1.0), None),
            (with(-Vec3::Z, 0.0, f32::NAN), None),
        ];
        let rays: Vec<GpuRay> = cases.iter().map(|(r, _)| gpu_ray(r)).collect();
        for query in [RayQuery::ClosestHit, RayQuery::AnyHit] {
            let hits = gpu_trace(&scene, &rays, query, 0xff);
            for ((r, want), h) in cases.iter().zip(&hits) {
                match want {
                    Some(t) => assert!(h.instance == 0 && h.t == *t, "{query:?} {r:?}: {h:?}"),
                    None => assert!(
                        h.instance == MISS && h.primitive == MISS && h.t == -1.0,
                        "{query:?} {r:?}: {h:?}"
                    ),
                }
            }
        }
    }

    #[test]
    fn trace_rays_honours_buffer_offsets_and_empty_scenes() {
        let g = crate::gpu::testing::gpu();
        let align = g.device.limits().min_storage_buffer_offset_alignment as u64;
        let scene = TestScene::single_software(cube(1));
        let tracer = RayTracer::new(&g.device, TraversalBackend::Software);
        let n = 100usize;
        let rays: Vec<GpuRay> = (0..n)
            .map(|i| {
                let dir = if i % 2 == 0 {
                    Vec3::X
                } else {
                    Vec3::new(0.0, 1.0, 1.0)
                };
                gpu_ray(&ray(Vec3::new(0.0, 0.0, i as f32 * 0.01 - 0.5), dir))
            })
            .collect();
        let mut bytes = vec![0xABu8; align as usize];
        bytes.extend_from_slice(bytemuck::cast_slice(&rays));
        let ray_buf = crate::gpu::testing::buffer_with(&bytes);
        let hit_size = 2 * align + n as u64 * RECORD_SIZE;
        let hit_buf = crate::gpu::testing::buffer_with(&vec![0x55u8; hit_size as usize]);
        crate::gpu::testing::run(|rec| {
            tracer.record(
                rec,
                &scene.buffers(),
                (&ray_buf, align),
                (&hit_buf, 2 * align),
                n as u32,
                RayQuery::ClosestHit,
                0xff,
            );
            // A batch of no rays records nothing.
            tracer.record(
                rec,
                &scene.buffers(),
                (&ray_buf, 0),
                (&hit_buf, 0),
                0,
                RayQuery::AnyHit,
                0xff,
            );
        });
        let out = crate::gpu::testing::read_back(&hit_buf, 0, hit_size);
        assert!(out[..2 * align as usize].iter().all(|&b| b == 0x55));
        let hits: Vec<GpuHit> = bytemuck::pod_collect_to_vec(&out[2 * align as usize..]);
        for (i, h) in hits.iter().enumerate() {
            let z = i as f32 * 0.01 - 0.5;
            let want = if i % 2 == 0 { 1.0 } else { (1.0 - z).min(1.0) };
            assert!(h.instance == 0 && (h.t - want).abs() < 1e-5, "{i}: {h:?}");
        }
        // No instances at all: every ray misses.
        let empty = TestScene::software(vec![], vec![]);
        let hits = gpu_trace(&empty, &rays, RayQuery::ClosestHit, 0xff);
        assert!(hits.iter().all(|h| h.instance == MISS && h.t == -1.0));
    }
}
