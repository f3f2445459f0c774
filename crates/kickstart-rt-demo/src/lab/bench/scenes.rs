//! The default measurements of `ksrt bench`: per scene, the BLAS build (fast-trace and
//! fast-build), refit, skinned refit and SAH cost against the CPU reference builder, then the ray batches, the
//! peer, the lighting cache and the trace tasks; and the TLAS build and refit over random
//! instances.

use glam::{Affine3A, Quat, Vec3};
use kickstart_rt as ksrt;
use kickstart_rt_renderer::upload;

use super::harness::Bench;
use super::rays::rays;
use super::report::{BlasMemoryReport, SahReport, SceneReport, TlasReport, WorkPerRay};
use super::tasks::trace_tasks;
use super::{attempt, backends, cache, options, peer, tree_work, Stats};
use crate::app::gpu;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::rng::Rng;
use kickstart_rt_renderer::scene::{Camera, Scene};
use kickstart_rt_renderer::sdk_glue::{self as glue, GpuRay, Query, Tlas};

/// Benchmarks one scene.
pub(super) fn bench_scene(
    bench: &Bench,
    name: &str,
    scene: &Scene,
    camera: Camera,
    size: (u32, u32),
    peer: Option<&mut peer::PeerState>,
    measure_tree_work: bool,
) -> SceneReport {
    let mut r = SceneReport::new(name, scene, &camera);
    r.traversal_backend = backends::backend_of(bench, bench.backend.get()).map(|b| b.to_string());
    let uploads = upload::upload_scene(bench.device, bench.queue, scene);
    let mut errors = Vec::new();
    let runs = |s: options::Section| s.runs_in(&bench.sections);
    let builds = runs(options::Section::Builds);
    if let Some((stats, ctx, h)) = builds
        .then(|| {
            attempt(&mut errors, "BLAS build", || {
                bench.blas_build(scene, &uploads, ksrt::BuildHint::Auto)
            })
        })
        .flatten()
    {
        r.blas_build_profile = bench.last_profile();
        r.blas_build_mtri_per_s = Some(r.geometry_triangles as f64 / (stats.median_ms * 1e3));
        r.blas_build = Some(stats);
        r.sah = attempt(&mut errors, "SAH cost", || {
            let (k, mesh) = scene
                .meshes
                .iter()
                .enumerate()
                .max_by_key(|(_, m)| m.triangle_count())
                .ok_or("the scene has no geometry")?;
            let gpu_sah_cost = glue::blas_sah_cost(&ctx, h.geometries[k])?;
            let tris: Vec<[Vec3; 3]> = mesh.triangles(Affine3A::IDENTITY).collect();
            let cpu = ksrt::cpu::CpuBvh::build(&tris);
            if cpu.nodes.is_empty() {
                return Err(
                    format!("{}: no finite triangle to build a CPU BVH over", mesh.name).into(),
                );
            }
            let cpu_sah_cost = cpu.sah_cost() as f64;
            Ok(SahReport {
                geometry: mesh.name.clone(),
                triangles: tris.len(),
                gpu_sah_cost,
                cpu_sah_cost,
                ratio: gpu_sah_cost / cpu_sah_cost,
            })
        });
        r.blas_memory = attempt(&mut errors, "BLAS memory", || {
            blas_memory(bench.device, &ctx, &h.geometries, r.geometry_triangles)
        });
    }
    if builds {
        r.blas_build_fast_build = attempt(&mut errors, "BLAS build (fast-build)", || {
            Ok(bench
                .blas_build(scene, &uploads, ksrt::BuildHint::PreferFastBuild)?
                .0)
        });
        if r.blas_build_fast_build.is_some() {
            r.blas_build_fast_build_profile = bench.last_profile();
        }
        r.blas_refit = attempt(&mut errors, "BLAS refit", || {
            bench.blas_refit(scene, &uploads)
        });
        if r.blas_refit.is_some() {
            r.blas_refit_profile = bench.last_profile();
        }
        r.skinned_refit = attempt(&mut errors, "skinned refit", || {
            bench.skinned_refit(scene, &uploads)
        });
        r.tlas_build = attempt(&mut errors, "TLAS build", || {
            bench.tlas_rebuild(scene, &uploads)
        });
        if r.tlas_build.is_some() {
            r.tlas_build_profile = bench.last_profile();
        }
    }
    let batches = runs(options::Section::Rays)
        .then(|| {
            attempt(&mut errors, "rays", || {
                rays(bench, scene, &uploads, &camera, size, &mut r)
            })
        })
        .flatten();
    if let (true, Some(b)) = (measure_tree_work, &batches) {
        let rays: Vec<(&'static str, bool, &[GpuRay])> = b
            .batches
            .iter()
            .map(|(kind, query, rays, _)| (*kind, matches!(query, Query::Any), rays.as_slice()))
            .collect();
        if let Some(trees) = attempt(&mut errors, "tree work", || {
            tree_work::measure(scene, &rays, b.blas.as_ref())
        }) {
            let gpu: Vec<(String, Option<WorkPerRay>)> = r
                .rays
                .iter()
                .map(|b| (b.kind.to_string(), b.work))
                .collect();
            tree_work::print(&gpu, &trees);
            r.tree_work = trees;
        }
    }
    if let Some(b) = &batches {
        r.backends = backends::compare(bench, scene, &uploads, b, &r);
    }
    if let Some(p) = peer {
        r.peer = Some(peer::compare(
            bench,
            p,
            scene,
            &uploads,
            batches.as_ref(),
            &r,
        ));
    }
    if runs(options::Section::Cache) {
        r.cache = attempt(&mut errors, "lighting cache", || {
            cache::cache_bench(bench, scene, &uploads, &camera, size)
        });
    }
    if runs(options::Section::Tasks) {
        attempt(&mut errors, "trace tasks", || {
            trace_tasks(bench, scene, &uploads, &camera, size, &mut r)
        });
    }
    r.errors = errors;
    r
}

/// (d) TLAS build and refit over `count` random instances of a small sphere.
pub(super) fn bench_tlas(bench: &Bench, count: u32) -> TlasReport {
    let mut errors = Vec::new();
    let sphere = {
        let (p, i) = kickstart_rt_renderer::scene::builtin::icosphere(1);
        kickstart_rt_renderer::scene::Mesh::new("tlas sphere", p, i, Vec3::ONE)
    };
    let run = |tlas: Tlas, span: &'static str| -> AnyResult<Stats> {
        let mesh = sphere.clone()?;
        let upload = upload::upload(bench.device, &mesh);
        let ctx = bench.context()?;
        let geometry = ctx.create_geometry_handle();
        let instances = ctx.create_instance_handles(count as usize);
        let mut rng = Rng(u64::from(count));
        // Spread the instances through a cube that holds them about 3 radii apart.
        let extent = (count as f32).cbrt() * 3.0;
        let mut random = move || {
            let axis = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5)
                .try_normalize()
                .unwrap_or(Vec3::Y);
            Affine3A::from_scale_rotation_translation(
                Vec3::splat(0.5 + rng.f32()),
                Quat::from_axis_angle(axis, rng.f32() * std::f32::consts::TAU),
                (Vec3::new(rng.f32(), rng.f32(), rng.f32()) - 0.5) * extent,
            )
        };
        let mut c = ctx.create_task_container();
        c.schedule_bvh_task(ksrt::GeometryTask {
            operation: ksrt::TaskOperation::Register,
            handle: geometry,
            input: upload::geometry_input(&upload, false),
        });
        for &h in &instances {
            c.schedule_bvh_task(ksrt::InstanceTask {
                operation: ksrt::TaskOperation::Register,
                handle: h,
                input: ksrt::InstanceInput::new(geometry, random()),
            });
        }
        c.schedule_bvh_task(glue::bvh_build_task(1, Some(Tlas::Rebuild)));
        let task = upload::submit(&ctx, bench.device, bench.queue, c, |_| {})?;
        gpu::complete(&ctx, bench.device, task)?;
        // Each repetition moves every instance, so the SDK has a TLAS to rebuild or refit.
        bench.repeat(|_| {
            let mut c = ctx.create_task_container();
            for &h in &instances {
                c.schedule_bvh_task(ksrt::InstanceTask {
                    operation: ksrt::TaskOperation::Update,
                    handle: h,
                    input: ksrt::InstanceInput::new(geometry, random()),
                });
            }
            c.schedule_bvh_task(glue::bvh_build_task(1, Some(tlas)));
            bench.timed(&ctx, c, &[span], |_| {})
        })
    };
    let build = attempt(
        &mut errors,
        &format!("TLAS build, {count} instances"),
        || run(Tlas::Rebuild, "tlas build"),
    );
    let build_profile = build.as_ref().map_or(Vec::new(), |_| bench.last_profile());
    let refit = attempt(
        &mut errors,
        &format!("TLAS refit, {count} instances"),
        || run(Tlas::Refit, "tlas refit"),
    );
    let refit_profile = refit.as_ref().map_or(Vec::new(), |_| bench.last_profile());
    TlasReport {
        instances: count,
        build,
        build_profile,
        refit,
        refit_profile,
        errors,
    }
}

/// Our BLASes' memory once every geometry's compaction is read back (each call to the context
/// collects what arrived; a fast-build or refittable BLAS is never compacted).
fn blas_memory(
    device: &wgpu::Device,
    ctx: &ksrt::ExecuteContext,
    geometries: &[ksrt::GeometryHandle],
    triangles: usize,
) -> AnyResult<BlasMemoryReport> {
    let mut report = BlasMemoryReport {
        triangles,
        triangle_bytes: 0,
        built_node_bytes: 0,
        node_bytes: 0,
    };
    for &g in geometries {
        let mut polls = 0;
        let m = loop {
            let m = ctx
                .geometry_blas_memory(g)?
                .ok_or_else(|| format!("{g:?}: its BLAS is not built"))?;
            if m.compaction != ksrt::BlasCompaction::Pending {
                break m;
            }
            polls += 1;
            if polls > 1000 {
                return Err(format!("{g:?}: no compaction read back after 1000 polls").into());
            }
            device.poll(wgpu::PollType::wait_indefinitely())?;
        };
        report.triangle_bytes += m.triangle_bytes;
        report.node_bytes += m.node_bytes;
        // As built: 64 bytes for each of n - 1 inner nodes (at least the root).
        report.built_node_bytes += (m.triangle_bytes / 48).saturating_sub(1).max(1) * 64;
    }
    Ok(report)
}
