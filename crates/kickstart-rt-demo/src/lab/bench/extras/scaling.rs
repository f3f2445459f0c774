//! `ksrt bench --scaling`: how the SDK's costs grow with the work.
//!
//! - **Triangles**: rays/s of the bench's primary, AO and diffuse batches and the BLAS build time
//!   on bunny, Cornell box, apartment and dragon, and on the dragon instanced 1, 10, 100 and
//!   1000 times through SDK instances (one BLAS, a TLAS over the copies; its build time instead of
//!   the BLAS's). No CPU oracle here: 1000 dragons are 871 M triangles.
//! - **Resolution**: GPU time of the SDK's passes in `ksrt render`'s frame (injection, the four
//!   traces, the denoisers) at 720p, 1080p and 4K.
//! - **Lights**: the same frame at 1080p with the shadow traced by `TraceMultiShadowTask` over 1,
//!   4 and 16 lights (the scene's main light and point lights around the camera), denoised by
//!   `DenoiseMultiShadowTask`.
//! - **TLAS**: build and refit over 1k, 10k, 100k and 1M instances (the bench's TLAS
//!   measurement).

use std::path::Path;

use glam::{Affine3A, Vec3};
use kickstart_rt as ksrt;
use serde::{Deserialize, Serialize};

use crate::lab::bench::harness::Bench;
use crate::lab::bench::rays::{batch, primary_rays, secondary_rays, surface};
use crate::lab::bench::scenes::bench_tlas;
use crate::lab::bench::{attempt, Stats};
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::rng::Rng;
use kickstart_rt_renderer::scene::benchmark_camera;
use kickstart_rt_renderer::scene::{Camera, Instance, Scene};
use kickstart_rt_renderer::sdk_glue::{self as glue, GpuRay, Query};
use kickstart_rt_renderer::upload::{self, UploadedMesh};

/// Scenes of the triangle series.
pub const SCALING_SCENES: [&str; 4] = ["cornell-obj", "cornell-gltf", "apartment", "statue"];
/// The instanced scene.
pub const INSTANCED_SCENE: &str = "statue";
/// Copies of the instanced dragon.
pub const DRAGON_COPIES: [u32; 4] = [1, 10, 100, 1000];
/// Frame sizes of the resolution series.
pub const RESOLUTIONS: [(u32, u32); 3] = [(1280, 720), (1920, 1080), (3840, 2160)];
/// Light counts of the light series.
pub const LIGHT_COUNTS: [u32; 3] = [1, 4, 16];
/// Instance counts of the TLAS series.
pub const TLAS_COUNTS: [u32; 4] = [1_000, 10_000, 100_000, 1_000_000];
/// The scene of the frame series (what `ksrt render` is benchmarked on).
pub const FRAME_SCENE: &str = "apartment";
/// Frames before the timed ones (pipelines, lighting cache, denoiser history settle).
const WARMUP_FRAMES: u32 = 16;
/// Timed frames of each frame measurement (median).
const TIMED_FRAMES: u32 = 8;

/// What the pass measures: the issue's series, or tiny ones for a smoke test on software Vulkan
/// (`--quick`).
#[derive(Debug, Clone)]
pub struct Plan {
    /// Scenes of the triangle series.
    pub scenes: Vec<&'static str>,
    /// The scene whose largest mesh is instanced (must be in `scenes`).
    pub instanced: &'static str,
    /// Its copies.
    pub copies: Vec<u32>,
    /// Frame sizes.
    pub resolutions: Vec<(u32, u32)>,
    /// Frame size of the light series.
    pub light_size: (u32, u32),
    /// Light counts.
    pub lights: Vec<u32>,
    /// TLAS instance counts.
    pub tlas: Vec<u32>,
    /// The frame series' scene (must be in `scenes`).
    pub frame_scene: &'static str,
}

impl Plan {
    /// The issue's series.
    pub fn full() -> Plan {
        Plan {
            scenes: SCALING_SCENES.to_vec(),
            instanced: INSTANCED_SCENE,
            copies: DRAGON_COPIES.to_vec(),
            resolutions: RESOLUTIONS.to_vec(),
            light_size: (1920, 1080),
            lights: LIGHT_COUNTS.to_vec(),
            tlas: TLAS_COUNTS.to_vec(),
            frame_scene: FRAME_SCENE,
        }
    }

    /// Tiny series on the small scenes (seconds on lavapipe).
    pub fn quick() -> Plan {
        Plan {
            scenes: vec!["cornell-obj", "cornell-gltf"],
            instanced: "cornell-obj",
            copies: vec![1, 4],
            resolutions: vec![(64, 36), (128, 72)],
            light_size: (64, 36),
            lights: vec![1, 4],
            tlas: vec![100, 1000],
            frame_scene: "cornell-obj",
        }
    }
}

/// The whole `--scaling` result.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct ScalingReport {
    /// `--quick`: tiny smoke-test series, not the issue's.
    #[serde(default)]
    pub quick: bool,
    /// Ray batch image size.
    pub ray_size: (u32, u32),
    /// Triangle series, in the order measured.
    pub triangles: Vec<TrianglePoint>,
    /// The scene of the frame series.
    pub frame_scene: String,
    /// Frame time against resolution (single-light shadow, as `ksrt render`).
    pub resolution: Vec<FramePoint>,
    /// Frame time against light count (at 1920×1080).
    pub lights: Vec<FramePoint>,
    /// TLAS build and refit against instance count.
    pub tlas: Vec<TlasPoint>,
    /// Measurements that failed, and why.
    pub errors: Vec<String>,
}

/// One point of the triangle series.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct TrianglePoint {
    /// `dragon`, `dragon x100`, …
    pub label: String,
    /// Instances of the dragon (0: a scene as loaded).
    pub copies: u32,
    /// Triangles the BLAS builds process (each geometry once).
    pub geometry_triangles: usize,
    /// Triangles in the world (instances counted each).
    pub world_triangles: usize,
    /// Every BLAS of the scene built in one task (`ingest` + `blas build`); scenes only.
    pub blas_build: Option<Stats>,
    /// TLAS rebuild over the copies (`tlas build`); instanced points only.
    pub tlas_build: Option<Stats>,
    /// Primary, AO and diffuse batches.
    pub rays: Vec<RayPoint>,
}

/// One ray batch.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct RayPoint {
    /// `primary`, `ao` or `diffuse`.
    pub kind: String,
    /// Rays.
    pub rays: u64,
    /// Rays that hit nothing.
    pub misses: u64,
    /// GPU time of the batch.
    pub time: Stats,
    /// Millions of rays per second at the median time.
    pub mrays_per_s: f64,
}

/// One SDK frame measurement.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct FramePoint {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Lights of the shadow trace.
    pub lights: u32,
    /// Median GPU time of all the SDK's passes of a frame, ms.
    pub sdk_ms: f64,
    /// Median GPU time per task label (`inject`, `trace`, `denoise`, …), ms.
    pub tasks: Vec<(String, f64)>,
    /// Frames timed.
    pub frames: u32,
}

/// One point of the TLAS series.
#[derive(Debug, Clone, Default, Serialize, Deserialize)]
pub struct TlasPoint {
    /// Instances.
    pub instances: u32,
    /// Rebuild (`tlas build`).
    pub build: Option<Stats>,
    /// Refit (`tlas refit`).
    pub refit: Option<Stats>,
    /// Why a measurement failed (e.g. a device limit).
    pub errors: Vec<String>,
}

/// `copies` instances of the scene's (the dragon's) largest mesh on a square grid in the xz
/// plane, 1.25 mesh widths apart, each with the file's own transform of that mesh; named
/// `<name> x<copies>`.
pub fn instanced(dragon: &Scene, name: &str, copies: u32) -> AnyResult<Scene> {
    let (k, mesh) = dragon
        .meshes
        .iter()
        .enumerate()
        .max_by_key(|(_, m)| m.triangle_count())
        .ok_or_else(|| format!("{name}: the scene has no mesh"))?;
    let base = dragon
        .instances
        .iter()
        .find(|i| i.mesh == k)
        .map_or(Affine3A::IDENTITY, |i| i.transform);
    let (mut lo, mut hi) = (Vec3::INFINITY, Vec3::NEG_INFINITY);
    for p in &mesh.positions {
        let w = base.transform_point3(Vec3::from(*p));
        lo = lo.min(w);
        hi = hi.max(w);
    }
    let size = (hi - lo).max(Vec3::splat(1e-6));
    let step = size.x.max(size.z) * 1.25;
    let cols = (f64::from(copies).sqrt().ceil() as u32).max(1);
    let instances = (0..copies)
        .map(|i| Instance {
            mesh: 0,
            transform: Affine3A::from_translation(Vec3::new(
                (i % cols) as f32 * step,
                0.0,
                (i / cols) as f32 * step,
            )) * base,
        })
        .collect();
    Ok(Scene {
        name: format!("{name} x{copies}"),
        meshes: vec![mesh.clone()],
        instances,
        ..Default::default()
    })
}

/// The bench's primary, AO and diffuse batches (the definitions of `ksrt bench`'s rays:
/// cosine-weighted secondary rays from the primary hits, AO any-hit within 1 unit), without
/// the CPU oracle.
fn trace_kinds(
    bench: &Bench,
    scene: &Scene,
    uploads: &[UploadedMesh],
    camera: &Camera,
    (width, height): (u32, u32),
) -> AnyResult<Vec<RayPoint>> {
    let (ctx, handles) = bench.registered(scene, uploads, false, true)?;
    let slots = handles.instance_of_slot();
    let (dirs, primary) = primary_rays(camera, (width, height));
    let point = |kind: &'static str, rays: &[GpuRay], time: Stats, hits: &[glue::GpuHit]| {
        let b = batch(kind, rays.len(), hits, time);
        RayPoint {
            kind: kind.to_string(),
            rays: b.rays,
            misses: b.misses,
            time: b.time,
            mrays_per_s: b.mrays_per_s,
        }
    };
    let mut out = Vec::new();
    let (t, hits) = bench.trace(&ctx, &primary, Query::Closest)?;
    out.push(point("primary", &primary, t, &hits));
    let offset = 1e-4 * scene.size();
    let surfaces: Vec<_> = hits
        .iter()
        .zip(&dirs)
        .filter(|(h, _)| h.is_hit())
        .filter_map(|(h, d)| surface(scene, &slots, h, *d))
        .collect();
    let mut rng = Rng(0x6b73_7274);
    let ao = secondary_rays(&surfaces, offset, &mut rng, 1.0);
    let (t, hits) = bench.trace(&ctx, &ao, Query::Any)?;
    out.push(point("ao", &ao, t, &hits));
    let diffuse = secondary_rays(&surfaces, offset, &mut rng, f32::INFINITY);
    let (t, hits) = bench.trace(&ctx, &diffuse, Query::Closest)?;
    out.push(point("diffuse", &diffuse, t, &hits));
    Ok(out)
}

/// The triangle series point of `scene` (copies 0: a loaded scene, with its BLAS build).
fn triangle_point(
    bench: &Bench,
    label: &str,
    scene: &Scene,
    copies: u32,
    camera: &Camera,
    size: (u32, u32),
    errors: &mut Vec<String>,
) -> TrianglePoint {
    let uploads = upload::upload_scene(bench.device, bench.queue, scene);
    let mut p = TrianglePoint {
        label: label.to_string(),
        copies,
        geometry_triangles: scene.meshes.iter().map(|m| m.triangle_count()).sum(),
        world_triangles: scene.triangle_count(),
        ..Default::default()
    };
    if copies == 0 {
        p.blas_build = attempt(errors, &format!("{label}: BLAS build"), || {
            Ok(bench.blas_build(scene, &uploads, ksrt::BuildHint::Auto)?.0)
        });
    } else {
        p.tlas_build = attempt(errors, &format!("{label}: TLAS build"), || {
            bench.tlas_rebuild(scene, &uploads)
        });
    }
    p.rays = attempt(errors, &format!("{label}: rays"), || {
        trace_kinds(bench, scene, &uploads, camera, size)
    })
    .unwrap_or_default();
    let build = p
        .blas_build
        .as_ref()
        .map(|s| format!("BLAS build {}", s.show()))
        .or_else(|| {
            p.tlas_build
                .as_ref()
                .map(|s| format!("TLAS build {}", s.show()))
        })
        .unwrap_or_else(|| "build —".into());
    let rays: Vec<String> = p
        .rays
        .iter()
        .map(|r| format!("{} {:.0}", r.kind, r.mrays_per_s))
        .collect();
    println!(
        "  {:<14} {:>11} triangles ({:>9} in BLASes)  {}  Mrays/s: {}",
        label,
        p.world_triangles,
        p.geometry_triangles,
        build,
        rays.join(", ")
    );
    p
}

/// Point lights around `camera` (as the bench's multi-shadow measurement places them).
fn extra_lights(camera: &Camera, extent: f32, n: usize) -> Vec<ksrt::LightInfo> {
    let reach = (camera.at - camera.eye).length().max(extent * 0.01);
    let mut rng = Rng(0x5348_4457);
    (0..n)
        .map(|_| {
            let d = Vec3::new(rng.f32() - 0.5, rng.f32() * 0.5, rng.f32() - 0.5);
            ksrt::LightInfo::Point {
                position: camera.eye + d * reach * 0.5,
                radius: reach * 0.01,
                range: extent * 4.0,
            }
        })
        .collect()
}

/// GPU time of the SDK's passes in `ksrt render`'s frame of `scene` at `size`; with `lights`,
/// the shadow over that many lights through the multi-light task.
fn frame_point(
    bench: &Bench,
    scene: &Scene,
    camera: &Camera,
    size: (u32, u32),
    lights: Option<u32>,
) -> AnyResult<FramePoint> {
    let mut opts = crate::app::frames::renderer_options(size);
    opts.gpu_timing = true;
    let mut r = crate::app::frames::new_renderer(bench.device, bench.queue, scene, &opts)?;
    if let Some(n) = lights {
        let extra = extra_lights(camera, scene.size(), n.saturating_sub(1) as usize);
        r.sdk.set_multi_shadow(bench.device, Some(&extra));
    }
    let looped = crate::app::frames_in_flight::run(
        &mut r,
        bench.device,
        bench.queue,
        camera,
        crate::app::frames_in_flight::LoopOptions {
            frames: WARMUP_FRAMES + TIMED_FRAMES,
            depth: 1,
            timed_frames: TIMED_FRAMES,
        },
        || {},
    )?;
    if looped.timings.is_empty() {
        return Err("no GPU timings (the device has no timestamp queries?)".into());
    }
    let rows = crate::app::timings::timing_medians(&looped.timings);
    let sdk_ms = rows
        .iter()
        .find(|(l, _, _)| *l == "total")
        .map_or(0.0, |r| r.2);
    Ok(FramePoint {
        width: size.0,
        height: size.1,
        lights: lights.unwrap_or(1),
        sdk_ms,
        tasks: rows
            .iter()
            .filter(|(l, p, _)| p.is_empty() && *l != "total")
            .map(|(l, _, ms)| (l.to_string(), *ms))
            .collect(),
        frames: looped.timings.len() as u32,
    })
}

fn print_frame(what: &str, p: &FramePoint) {
    let tasks: Vec<String> = p
        .tasks
        .iter()
        .map(|(l, ms)| format!("{l} {ms:.2}"))
        .collect();
    println!(
        "  {what:<22} SDK {:>8.3} ms  ({})",
        p.sdk_ms,
        tasks.join(", ")
    );
}

/// `--scaling`. Failures are kept in the report; the other points still run.
pub(in crate::lab::bench) fn run(
    bench: &Bench,
    scenes_dir: &Path,
    size: (u32, u32),
    plan: &Plan,
    quick: bool,
) -> ScalingReport {
    let mut report = ScalingReport {
        quick,
        ray_size: size,
        frame_scene: plan.frame_scene.to_string(),
        ..Default::default()
    };
    let errors = &mut report.errors;
    println!(
        "  rays/s and build time against triangles ({}x{} ray batches):",
        size.0, size.1
    );
    let mut dragon = None;
    let mut frame_scene = None;
    for &name in &plan.scenes {
        let Some(scene) = attempt(errors, &format!("load {name}"), || {
            super::load(name, scenes_dir)
        }) else {
            continue;
        };
        let camera = benchmark_camera(name).unwrap_or_else(|| scene.camera_or_default(None));
        let p = triangle_point(bench, name, &scene, 0, &camera, size, errors);
        report.triangles.push(p);
        if name == plan.frame_scene {
            frame_scene = Some(scene.clone());
        }
        if name == plan.instanced {
            dragon = Some(scene);
        }
    }
    if let Some(dragon) = &dragon {
        for &copies in &plan.copies {
            let label = format!("{} x{copies}", plan.instanced);
            if let Some(scene) =
                attempt(errors, &label, || instanced(dragon, plan.instanced, copies))
            {
                let camera = scene.default_camera();
                let p = triangle_point(bench, &label, &scene, copies, &camera, size, errors);
                report.triangles.push(p);
            }
        }
    }
    if let Some(scene) = &frame_scene {
        let camera =
            benchmark_camera(plan.frame_scene).unwrap_or_else(|| scene.camera_or_default(None));
        println!(
            "  SDK frame time of `ksrt render` ({}) against resolution:",
            plan.frame_scene
        );
        for &res in &plan.resolutions {
            let what = format!("{}x{}", res.0, res.1);
            if let Some(p) = attempt(errors, &format!("frame {what}"), || {
                frame_point(bench, scene, &camera, res, None)
            }) {
                print_frame(&what, &p);
                report.resolution.push(p);
            }
        }
        let (lw, lh) = plan.light_size;
        println!("  … against the light count (multi-light shadow, {lw}x{lh}):");
        for &n in &plan.lights {
            let what = format!("{n} lights");
            if let Some(p) = attempt(errors, &format!("frame {what}"), || {
                frame_point(bench, scene, &camera, plan.light_size, Some(n))
            }) {
                print_frame(&what, &p);
                report.lights.push(p);
            }
        }
    }
    println!("  TLAS against instances (80-triangle spheres, random transforms):");
    for &count in &plan.tlas {
        let t = bench_tlas(bench, count);
        let opt = |s: &Option<Stats>| s.as_ref().map_or("—".to_string(), Stats::show);
        println!(
            "  {:>9} instances  build {}  refit {}",
            count,
            opt(&t.build),
            opt(&t.refit)
        );
        for e in &t.errors {
            println!("    failed: {e}");
        }
        errors.extend(t.errors.iter().cloned());
        report.tlas.push(TlasPoint {
            instances: count,
            build: t.build,
            refit: t.refit,
            errors: t.errors,
        });
    }
    report
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::gpu;
    use kickstart_rt_renderer::scene::Mesh;
    use kickstart_rt_renderer::sdk_glue::Tlas;

    fn dragon() -> Scene {
        let mesh = Mesh::new(
            "d",
            vec![[0.0, 0.0, 0.0], [2.0, 0.0, 0.0], [0.0, 1.0, 1.0]],
            vec![0, 1, 2],
            Vec3::ONE,
        )
        .unwrap();
        Scene {
            meshes: vec![mesh],
            instances: vec![Instance {
                mesh: 0,
                transform: Affine3A::from_scale(Vec3::splat(0.5)),
            }],
            ..Default::default()
        }
    }

    #[test]
    fn instanced_copies_sit_on_a_grid_without_overlap() {
        for copies in [1, 10, 100] {
            let s = instanced(&dragon(), "dragon", copies).unwrap();
            assert_eq!(s.instances.len(), copies as usize);
            assert_eq!(s.meshes.len(), 1);
            assert_eq!(s.triangle_count(), copies as usize);
            assert_eq!(s.name, format!("dragon x{copies}"));
            // The file's transform is kept (scale 0.5: the mesh is 1 wide), copies 1.25 apart.
            let boxes: Vec<(Vec3, Vec3)> = s
                .instances
                .iter()
                .map(|i| {
                    let t: Vec<Vec3> = s.meshes[0].triangles(i.transform).next().unwrap().into();
                    let lo = t.iter().fold(Vec3::INFINITY, |a, b| a.min(*b));
                    let hi = t.iter().fold(Vec3::NEG_INFINITY, |a, b| a.max(*b));
                    (lo, hi)
                })
                .collect();
            assert!((boxes[0].1.x - boxes[0].0.x - 1.0).abs() < 1e-6);
            for (a, (alo, ahi)) in boxes.iter().enumerate() {
                for (blo, bhi) in boxes.iter().skip(a + 1) {
                    let overlap = alo.x < bhi.x && blo.x < ahi.x && alo.z < bhi.z && blo.z < ahi.z;
                    assert!(!overlap, "copies {copies}: {a} overlaps");
                }
            }
        }
        // 10 copies: a 4-wide grid, the 10th in the third row.
        let s = instanced(&dragon(), "dragon", 10).unwrap();
        let t = s.instances[9].transform.translation;
        assert!((t.x - 1.25).abs() < 1e-6 && (t.z - 2.5).abs() < 1e-6, "{t}");
        assert!(instanced(&Scene::default(), "dragon", 4).is_err());
    }

    /// GPU, slow on lavapipe: the TLAS series' largest point fits a device with wgpu's default
    /// limits (the instance table, 128 bytes an instance, is the tightest: 1 048 576 instances
    /// fill its 128 MiB binding). One registration and build, untimed.
    #[test]
    #[ignore = "minutes on lavapipe in a debug build; run with --ignored"]
    fn tlas_of_a_million_instances_fits_a_default_device() {
        let (device, queue) = crate::app::testing::device();
        let ctx =
            ksrt::ExecuteContext::new(device, queue, crate::app::gpu::init_settings_timed(false))
                .expect("context");
        let (p, i) = kickstart_rt_renderer::scene::builtin::icosphere(0);
        let upload = upload::upload(device, &Mesh::new("s", p, i, Vec3::ONE).unwrap());
        let geometry = ctx.create_geometry_handle();
        let mut c = ctx.create_task_container();
        c.schedule_bvh_task(ksrt::GeometryTask {
            operation: ksrt::TaskOperation::Register,
            handle: geometry,
            input: upload::geometry_input(&upload, false),
        });
        let count = TLAS_COUNTS[TLAS_COUNTS.len() - 1];
        for (k, h) in ctx
            .create_instance_handles(count as usize)
            .into_iter()
            .enumerate()
        {
            let at = Vec3::new((k % 1000) as f32, 0.0, (k / 1000) as f32) * 3.0;
            c.schedule_bvh_task(ksrt::InstanceTask {
                operation: ksrt::TaskOperation::Register,
                handle: h,
                input: ksrt::InstanceInput::new(geometry, Affine3A::from_translation(at)),
            });
        }
        c.schedule_bvh_task(glue::bvh_build_task(1, Some(Tlas::Rebuild)));
        let task = upload::submit(&ctx, device, queue, c, |_| {}).expect("a million instances");
        gpu::complete(&ctx, device, task).expect("built");
    }

    #[test]
    fn extra_lights_are_points_near_the_camera() {
        let cam = Camera {
            eye: Vec3::ZERO,
            at: Vec3::new(0.0, 0.0, -4.0),
            up: Vec3::Y,
            fov_y_deg: 60.0,
        };
        let l = extra_lights(&cam, 10.0, 15);
        assert_eq!(l.len(), 15);
        for light in l {
            match light {
                ksrt::LightInfo::Point { position, .. } => assert!(position.length() <= 2.0),
                other => panic!("{other:?}"),
            }
        }
    }

    #[test]
    fn series_are_the_issues() {
        for plan in [Plan::full(), Plan::quick()] {
            assert!(plan.scenes.contains(&plan.instanced));
            assert!(plan.scenes.contains(&plan.frame_scene));
        }
        assert_eq!(DRAGON_COPIES, [1, 10, 100, 1000]);
        assert_eq!(TLAS_COUNTS.last(), Some(&1_000_000));
        assert_eq!(RESOLUTIONS[2], (3840, 2160));
        assert!(LIGHT_COUNTS
            .iter()
            .all(|&n| n as usize <= ksrt::MAX_MULTI_SHADOW_LIGHTS));
    }
}
