//! Public API that the other suites leave alone: destroying every handle of a kind at once, the
//! log callback and its severity filter, `TlasUpdate::Auto`'s periodic rebuild, input buffers the
//! engine drops before its encoder is submitted, the injection task's viewport, and a denoiser
//! whose input and output are one texture.

use crate::common;

use common::cache as lc;
use common::denoise as dn;
use common::rt::{closest, compare, mesh_input, ray, schedule_mesh, Mesh, Rng};
use common::*;
use glam::{Affine3A, Vec3, Vec4};
use kickstart_rt::*;
use std::sync::{Arc, Mutex};

/// Rays straight down (−z) from `height` above a unit quad at each of `corners` (the quad's
/// lower-left corner, its plane z = corner.z), through (0.3, 0.6) of the quad: inside its second
/// triangle, away from the diagonal both triangles share, so no edge rule decides the hit.
fn rays_down(corners: &[Vec3], height: f32) -> Vec<GpuRay> {
    corners
        .iter()
        .map(|c| ray(*c + Vec3::new(0.3, 0.6, height), Vec3::NEG_Z, 0.0, 100.0))
        .collect()
}

/// A unit quad in the z = `z` plane (two triangles, shared corners).
fn quad_mesh(z: f32) -> Mesh {
    Mesh {
        positions: vec![
            Vec3::new(0.0, 0.0, z),
            Vec3::new(1.0, 0.0, z),
            Vec3::new(1.0, 1.0, z),
            Vec3::new(0.0, 1.0, z),
        ],
        indices: vec![0, 1, 2, 0, 2, 3],
    }
}

/// Asserts that `result` is the refusal of a stale handle of `kind` at slot `index`.
fn assert_stale<T: std::fmt::Debug>(result: Result<T>, kind: HandleKind, index: u32, what: &str) {
    match result {
        Err(Error::InvalidHandle {
            kind: k, index: i, ..
        }) if k == kind && i == index => {}
        other => {
            panic!("{what}: expected InvalidHandle {{ {kind:?}, index {index} }}, got {other:?}")
        }
    }
}

/// Asserts that every one of the destroyed handles is refused: by the destroy calls, the
/// queries, and a task naming one.
fn assert_all_refused(
    ctx: &ExecuteContext,
    geometries: &[GeometryHandle],
    instances: &[InstanceHandle],
    denoisers: &[DenoisingContextHandle],
) {
    for g in geometries {
        let (kind, index) = (HandleKind::Geometry, g.index());
        assert_stale(ctx.destroy_geometry_handle(*g), kind, index, "destroy");
        assert_stale(ctx.geometry_triangle_count(*g), kind, index, "triangles");
        assert_stale(ctx.geometry_is_built(*g), kind, index, "is built");
    }
    for i in instances {
        let (kind, index) = (HandleKind::Instance, i.index());
        assert_stale(ctx.destroy_instance_handle(*i), kind, index, "destroy");
        assert_stale(ctx.lighting_cache_allocation(*i), kind, index, "cache");
    }
    for d in denoisers {
        let (kind, index) = (HandleKind::DenoisingContext, d.index());
        assert_stale(
            ctx.destroy_denoising_context_handle(*d),
            kind,
            index,
            "destroy",
        );
    }
    // A task naming an old instance is refused as a whole.
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(InstanceTask {
        operation: TaskOperation::Update,
        handle: instances[0],
        input: InstanceInput::new(geometries[0], Affine3A::IDENTITY),
    });
    let mut e = encoder();
    assert_stale(
        ctx.build_gpu_task(c, &mut e),
        HandleKind::Instance,
        instances[0].index(),
        "task",
    );
    submit(e);
}

/// `destroy_all_geometry_handles`, `destroy_all_instance_handles` and
/// `destroy_all_denoising_context_handles`: every old handle is refused afterwards, by the
/// destroy calls and the queries alike; rays that hit the instances miss after the next BVH
/// build; once the tasks are complete and the resources released, the vertex copies, BLAS and
/// denoiser memory are back where they were before anything was registered; and handles created
/// afterwards (in the freed slots) register and trace as usual.
#[test]
fn destroying_every_handle_refuses_them_frees_their_memory_and_new_ones_work() {
    let ctx = context(4);
    assert_eq!(ctx.traversal_backend().backend, backend());
    let before = ctx.resource_allocations();
    let geometries = ctx.create_geometry_handles(3);
    let instances = ctx.create_instance_handles(3);
    let denoisers: Vec<DenoisingContextHandle> = (0..2)
        .map(|_| {
            ctx.create_denoising_context_handle(DenoisingContextInput {
                max_width: 32,
                max_height: 32,
                signal_type: SignalType::Diffuse,
                method: DenoisingMethod::Fast,
            })
            .unwrap_or_else(|e| panic!("denoising context: {e}"))
        })
        .collect();
    // Updatable geometry keeps its vertex copies while registered, so that memory is visible.
    let corners: Vec<Vec3> = (0..3)
        .map(|k| Vec3::new(2.0 * k as f32, 0.0, 0.0))
        .collect();
    let mut c = ctx.create_task_container();
    for ((g, i), at) in geometries.iter().zip(&instances).zip(&corners) {
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Register,
            handle: *g,
            input: mesh_input("quad", &quad_mesh(0.0), true),
        });
        register_instance(&mut c, *i, *g, Affine3A::from_translation(*at));
    }
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    let rays = rays_down(&corners, 5.0);
    for (k, h) in closest(&ctx, &rays).iter().enumerate() {
        assert_eq!(h.instance, instances[k].index(), "ray {k} before: {h:?}");
        assert_eq!(h.primitive, 1, "ray {k} before: {h:?}");
        assert!((h.t - 5.0).abs() < 1e-4, "ray {k} before: {h:?}");
    }
    let held = ctx.resource_allocations();
    assert_eq!(
        held.vertex_copies,
        3 * 2 * 48,
        "two triangles a quad: {held:?}"
    );
    assert!(held.blas > before.blas, "{held:?} vs {before:?}");
    assert_eq!(
        held.denoiser, before.denoiser,
        "a denoising context's memory comes with its first frame: {held:?}"
    );

    ctx.destroy_all_geometry_handles();
    ctx.destroy_all_instance_handles();
    ctx.destroy_all_denoising_context_handles();
    assert_all_refused(&ctx, &geometries, &instances, &denoisers);

    // The next BVH build drops them from the TLAS.
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    for (k, h) in closest(&ctx, &rays).iter().enumerate() {
        assert!(!h.is_hit() && h.t == -1.0, "ray {k} after destroy: {h:?}");
    }
    ctx.release_device_resources_immediately()
        .unwrap_or_else(|e| panic!("release: {e}"));
    let after = ctx.resource_allocations();
    assert_eq!(after.vertex_copies, before.vertex_copies, "{after:?}");
    assert_eq!(after.blas, before.blas, "{after:?}");
    assert_eq!(after.denoiser, before.denoiser, "{after:?}");

    // New handles take the freed slots (new generations: the old handles stay refused).
    let (g, i) = (ctx.create_geometry_handle(), ctx.create_instance_handle());
    assert_stale(
        ctx.destroy_geometry_handle(geometries[0]),
        HandleKind::Geometry,
        geometries[0].index(),
        "old handle after slot reuse",
    );
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g, 1.0);
    register_instance(&mut c, i, g, Affine3A::from_translation(corners[1]));
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    let hits = closest(&ctx, &rays);
    assert!(!hits[0].is_hit() && !hits[2].is_hit(), "{hits:?}");
    assert_eq!(hits[1].instance, i.index(), "{:?}", hits[1]);
    assert_eq!(hits[1].primitive, 1, "{:?}", hits[1]);
    assert!((hits[1].t - 5.0).abs() < 1e-4, "{:?}", hits[1]);
    assert_eq!(ctx.geometry_triangle_count(g), Ok(Some(2)));
}

type Log = Arc<Mutex<Vec<(Severity, String)>>>;

/// A log callback collecting every message it gets into a new [`Log`].
fn collector() -> (Log, LogCallback) {
    let log: Log = Arc::default();
    let sink = log.clone();
    let callback: LogCallback = Arc::new(move |s: Severity, m: &str| {
        sink.lock()
            .unwrap_or_else(|p| p.into_inner())
            .push((s, m.to_string()))
    });
    (log, callback)
}

fn messages(log: &Log) -> Vec<(Severity, String)> {
    log.lock().unwrap_or_else(|p| p.into_inner()).clone()
}

/// Registers `name`, a quad whose second triangle has an out-of-range index (99), waits until
/// its dropped-triangle counts are read back (which is when the SDK logs its warning) and
/// returns the warning the SDK documents for it.
fn register_bad_geometry(ctx: &ExecuteContext, name: &str) -> String {
    let g = ctx.create_geometry_handle();
    let mut m = quad_mesh(0.0);
    m.indices[5] = 99;
    let mut c = ctx.create_task_container();
    schedule_mesh(&mut c, g, name, &m);
    build_submit_complete(ctx, c);
    for _ in 0..1000 {
        let dropped = ctx
            .geometry_dropped_triangles(g)
            .unwrap_or_else(|e| panic!("dropped triangles of {name}: {e}"));
        if let Some(d) = dropped {
            assert_eq!(
                d,
                DroppedTriangles {
                    out_of_range_indices: 1,
                    non_finite_positions: 0
                }
            );
            return format!(
                "GeometryTask: geometry `{name}` ({g:?}): dropped 1 triangle(s) with out-of-range \
                 indices and 0 with NaN/infinite positions; they are never hit"
            );
        }
        gpu()
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .expect("poll");
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    panic!("the dropped-triangle counts of {name} were never read back");
}

/// `set_log_callback` and `set_min_log_severity` on a live context: the dropped-triangle warning
/// reaches the callback with its severity and text at the Warning minimum; an Error minimum
/// holds it back; `set_log_callback(None)` stops delivery; a new callback gets the next one.
#[test]
fn log_callback_and_minimum_severity_can_be_changed_on_a_live_context() {
    let ctx = context(2);
    assert_eq!(ctx.traversal_backend().backend, backend());
    let (first, callback) = collector();
    ctx.set_log_callback(Some(callback));
    ctx.set_min_log_severity(Severity::Warning);
    let warning = register_bad_geometry(&ctx, "bad-1");
    assert_eq!(messages(&first), vec![(Severity::Warning, warning)]);

    // Above the warning's severity: nothing arrives, though the counts are still reported.
    ctx.set_min_log_severity(Severity::Error);
    register_bad_geometry(&ctx, "bad-2");
    assert_eq!(messages(&first).len(), 1, "{:?}", messages(&first));

    // No callback: nothing arrives at the old one.
    ctx.set_min_log_severity(Severity::Warning);
    ctx.set_log_callback(None);
    register_bad_geometry(&ctx, "bad-3");
    assert_eq!(messages(&first).len(), 1, "{:?}", messages(&first));

    let (second, callback) = collector();
    ctx.set_log_callback(Some(callback));
    let warning = register_bad_geometry(&ctx, "bad-4");
    assert_eq!(messages(&second), vec![(Severity::Warning, warning)]);
    assert_eq!(messages(&first).len(), 1, "{:?}", messages(&first));
}

/// A context created with `settings` and a collecting callback; what it logged while created.
fn context_logging(settings: InitSettings) -> (ExecuteContext, Log) {
    let (log, callback) = collector();
    let g = gpu();
    let ctx = ExecuteContext::new(
        &g.device,
        &g.queue,
        InitSettings {
            log_callback: Some(callback),
            ..settings
        },
    )
    .unwrap_or_else(|e| panic!("context: {e}"));
    assert_eq!(ctx.traversal_backend().backend, backend());
    (ctx, log)
}

/// `InitSettings::log_callback` and `min_log_severity`: at the Info minimum the callback gets
/// the backend choice (Info) while the context is created; at the default Warning minimum only
/// the warning about another minor version arrives (not the Info), and later warnings too; at
/// the Error minimum neither.
#[test]
fn init_settings_callback_receives_what_its_minimum_severity_lets_through() {
    let other_minor = Version {
        minor: VERSION.minor + 1,
        ..VERSION
    };
    let (_ctx, info) = context_logging(InitSettings {
        min_log_severity: Severity::Info,
        ..Default::default()
    });
    let got = messages(&info);
    assert_eq!(got.len(), 1, "{got:?}");
    assert_eq!(got[0].0, Severity::Info);
    let prefix = format!("kickstart-rt traces with the {} backend (", backend());
    assert!(got[0].1.starts_with(&prefix), "{got:?}");

    let (ctx, warnings) = context_logging(InitSettings {
        version: other_minor,
        ..Default::default()
    });
    let version_warning =
        format!("application built against kickstart-rt {other_minor}, library is {VERSION}");
    assert_eq!(
        messages(&warnings),
        vec![(Severity::Warning, version_warning.clone())]
    );
    let dropped = register_bad_geometry(&ctx, "bad-init");
    assert_eq!(
        messages(&warnings),
        vec![
            (Severity::Warning, version_warning),
            (Severity::Warning, dropped)
        ]
    );

    let (ctx, errors) = context_logging(InitSettings {
        version: other_minor,
        min_log_severity: Severity::Error,
        ..Default::default()
    });
    register_bad_geometry(&ctx, "bad-quiet");
    assert_eq!(messages(&errors), vec![]);
}

/// A device of its own with timestamp queries (the shared one has none in the minimal-device
/// pass), otherwise as the shared device: its features and limits, ray queries included.
fn timing_device() -> (wgpu::Device, wgpu::Queue) {
    let g = gpu();
    assert!(
        g.adapter
            .features()
            .contains(wgpu::Features::TIMESTAMP_QUERY),
        "{:?} has no timestamp queries: the TLAS update test reads the passes' labels from GPU \
         timings",
        g.adapter.get_info().name
    );
    let experimental_features = if backend() == TraversalBackend::HardwareRayQuery {
        // SAFETY: the tests accept wgpu's experimental ray-query support (as the shared device).
        unsafe { wgpu::ExperimentalFeatures::enabled() }
    } else {
        wgpu::ExperimentalFeatures::disabled()
    };
    pollster::block_on(g.adapter.request_device(&wgpu::DeviceDescriptor {
        label: Some("kickstart-rt timing tests"),
        required_features: g.device.features() | wgpu::Features::TIMESTAMP_QUERY,
        required_limits: g.device.limits(),
        experimental_features,
        ..Default::default()
    }))
    .unwrap_or_else(|e| panic!("timing device: {e}"))
}

/// The software TLAS update a task's timings show: `tlas build` or `tlas refit` (the driver's
/// TLAS, on the hardware backend, is rebuilt in every task and not counted).
fn tlas_update(t: &GpuTimings) -> &'static str {
    let mut labels: Vec<&'static str> = t
        .passes
        .iter()
        .filter(|p| p.label.starts_with("tlas") && p.pass != "driver tlas build")
        .map(|p| p.label)
        .collect();
    labels.dedup();
    assert_eq!(labels.len(), 1, "one TLAS update a task: {t:?}");
    labels[0]
}

/// Where instance `j` of the moving scene is in frame `k`: the two drift apart (a refit's boxes
/// loosen), up and back.
fn placement(j: usize, k: u32) -> Affine3A {
    let side = j as f32 * 2.0 - 1.0;
    Affine3A::from_translation(Vec3::new(
        3.0 * j as f32 + 0.25 * k as f32 * side,
        0.1 * k as f32,
        -0.05 * k as f32 * j as f32,
    ))
}

/// One frame of the moving scene: moves every instance to frame `k`'s place and updates the TLAS
/// with `update`; checks that a ray down onto each instance hits it; returns the TLAS update the
/// task recorded.
fn move_frame(
    (device, queue): (&wgpu::Device, &wgpu::Queue),
    ctx: &ExecuteContext,
    (geometry, instances): (GeometryHandle, &[InstanceHandle]),
    k: u32,
    update: TlasUpdate,
) -> &'static str {
    let mut c = ctx.create_task_container();
    for (j, i) in instances.iter().enumerate() {
        c.schedule_bvh_task(InstanceTask {
            operation: TaskOperation::Update,
            handle: *i,
            input: InstanceInput::new(geometry, placement(j, k)),
        });
    }
    c.schedule_bvh_task(BvhBuildTask {
        tlas_update: update,
        ..Default::default()
    });
    let mut e = device.create_command_encoder(&Default::default());
    let t = ctx
        .build_gpu_task(c, &mut e)
        .unwrap_or_else(|e| panic!("frame {k}: {e}"));
    queue.submit([e.finish()]);
    let timings = ctx
        .wait_for_gpu_timings(t)
        .unwrap_or_else(|e| panic!("frame {k} timings: {e}"));
    ctx.mark_gpu_task_completed(t)
        .unwrap_or_else(|e| panic!("frame {k}: {e}"));
    let corners: Vec<Vec3> = (0..instances.len())
        .map(|j| placement(j, k).translation.into())
        .collect();
    let (hits, _) = trace_on(device, queue, ctx, &rays_down(&corners, 10.0));
    for (j, h) in hits.iter().enumerate() {
        assert_eq!(
            (h.instance, h.primitive),
            (instances[j].index(), 1),
            "frame {k}, ray {j}: {h:?}"
        );
        assert!((h.t - 10.0).abs() < 1e-4, "frame {k}, ray {j}: {h:?}");
    }
    tlas_update(&timings)
}

/// `TlasUpdate::Auto` refits the TLAS while only transforms change, and after
/// `AUTO_REBUILD_AFTER_REFITS` refits in a row rebuilds it: over 34 frames of moving instances
/// the tasks record 16 refits, a rebuild, 16 refits, a rebuild; `Refit` never rebuilds (and an
/// `Auto` task after that many refits rebuilds at once); `Rebuild` always does. Every frame's
/// rays hit the moved instances.
#[test]
fn auto_tlas_update_rebuilds_after_the_documented_number_of_refits() {
    let (device, queue) = timing_device();
    let dq = (&device, &queue);
    let ctx = ExecuteContext::new(
        &device,
        &queue,
        InitSettings {
            gpu_timing: true,
            ..Default::default()
        },
    )
    .unwrap_or_else(|e| panic!("context: {e}"));
    assert_eq!(ctx.traversal_backend().backend, backend());
    let geometry = ctx.create_geometry_handle();
    let instances = ctx.create_instance_handles(2);
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Register,
        handle: geometry,
        input: many_triangles(&device, 2),
    });
    for (j, i) in instances.iter().enumerate() {
        register_instance(&mut c, *i, geometry, placement(j, 0));
    }
    c.schedule_bvh_task(BvhBuildTask::default());
    let mut e = device.create_command_encoder(&Default::default());
    let t = ctx.build_gpu_task(c, &mut e).expect("registration");
    queue.submit([e.finish()]);
    let timings = ctx.wait_for_gpu_timings(t).expect("registration timings");
    ctx.mark_gpu_task_completed(t).expect("registration");
    assert_eq!(tlas_update(&timings), "tlas build");

    let n = TlasUpdate::AUTO_REBUILD_AFTER_REFITS;
    assert_eq!(n, 16, "the documented period");
    let scene = (geometry, instances.as_slice());
    let got: Vec<&str> = (1..=2 * (n + 1))
        .map(|k| move_frame(dq, &ctx, scene, k, TlasUpdate::Auto))
        .collect();
    let mut want = vec!["tlas refit"; n as usize];
    want.push("tlas build");
    want.extend(want.clone());
    assert_eq!(got, want);

    let refits: Vec<&str> = (0..n + 4)
        .map(|k| move_frame(dq, &ctx, scene, 100 + k, TlasUpdate::Refit))
        .collect();
    assert_eq!(refits, vec!["tlas refit"; n as usize + 4]);
    assert_eq!(
        move_frame(dq, &ctx, scene, 200, TlasUpdate::Auto),
        "tlas build"
    );
    let rebuilds: Vec<&str> = (0..3)
        .map(|k| move_frame(dq, &ctx, scene, 300 + k, TlasUpdate::Rebuild))
        .collect();
    assert_eq!(rebuilds, vec!["tlas build"; 3]);
}

/// Input buffers the engine drops right after `build_gpu_task`, before it submits the encoder:
/// the SDK keeps what it needs, and the geometry traces at the right distance. Covers a
/// registration built in the same task, an update refitted in the same task (the ingestion
/// fused into the refit), and an update whose refit runs in a later task.
#[test]
fn input_buffers_dropped_before_submission_still_build_the_geometry() {
    let ctx = context(4);
    assert_eq!(ctx.traversal_backend().backend, backend());
    let (g, i) = (ctx.create_geometry_handle(), ctx.create_instance_handle());
    // Runs `c` with the engine holding no input buffer once `build_gpu_task` returned (the
    // inputs moved into the container, which that call consumed), and a device poll (wgpu frees
    // what nothing holds) before the submission; then traces a ray down onto the quad.
    let run_then_trace = |c: TaskContainer| {
        let mut e = encoder();
        let t = ctx
            .build_gpu_task(c, &mut e)
            .unwrap_or_else(|e| panic!("build: {e}"));
        gpu().device.poll(wgpu::PollType::Poll).expect("poll");
        submit(e);
        ctx.mark_gpu_task_completed(t)
            .unwrap_or_else(|e| panic!("complete: {e}"));
        closest(&ctx, &rays_down(&[Vec3::ZERO], 3.0))[0]
    };
    let task = |op, z| GeometryTask {
        operation: op,
        handle: g,
        input: mesh_input("dropped by the engine", &quad_mesh(z), true),
    };

    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(task(TaskOperation::Register, 0.0));
    register_instance(&mut c, i, g, Affine3A::IDENTITY);
    c.schedule_bvh_task(BvhBuildTask::default());
    let h = run_then_trace(c);
    assert_eq!(
        (h.instance, h.primitive),
        (i.index(), 1),
        "registered: {h:?}"
    );
    assert!((h.t - 3.0).abs() < 1e-4, "registered: {h:?}");

    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(task(TaskOperation::Update, -1.0));
    c.schedule_bvh_task(BvhBuildTask::default());
    let h = run_then_trace(c);
    assert_eq!((h.instance, h.primitive), (i.index(), 1), "updated: {h:?}");
    assert!((h.t - 4.0).abs() < 1e-4, "updated: {h:?}");

    // No BvhBuildTask: the refit waits for the next task, long after the buffers are gone.
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(task(TaskOperation::Update, -2.0));
    let h = run_then_trace(c);
    assert!((h.t - 4.0).abs() < 1e-4, "refit still pending: {h:?}");
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(BvhBuildTask::default());
    let h = run_then_trace(c);
    assert_eq!(
        (h.instance, h.primitive),
        (i.index(), 1),
        "refitted later: {h:?}"
    );
    assert!((h.t - 5.0).abs() < 1e-4, "refitted later: {h:?}");
}

const MAGENTA: Vec4 = Vec4::new(1.0, 0.0, 1.0, 0.0);

/// A split-screen injection's textures, `2w × h`: the left half holds `left`'s view (clip depth)
/// lit `colours[0]`, the right half `right`'s lit `colours[1]`. Each camera must see only the
/// rectangle of its index in `rects`, at every pixel.
fn split_screen(
    rects: &[lc::Rect; 2],
    cameras: [&lc::Camera; 2],
    colours: [Vec3; 2],
) -> (wgpu::TextureView, wgpu::TextureView) {
    let (w, h) = (cameras[0].w, cameras[0].h);
    let mut depth = Vec::new();
    let mut light = Vec::new();
    for y in 0..h {
        for x in 0..2 * w {
            let side = (x / w) as usize;
            let cam = cameras[side];
            let (o, d) = cam.ray(x % w, y);
            let hit = lc::cast(rects, o, d);
            assert!(
                hit.is_some_and(|(_, r)| r == side),
                "camera {side} pixel ({}, {y}) must see rectangle {side}: {hit:?}",
                x % w
            );
            let (t, _) = hit.unwrap_or_default();
            depth.push(cam.project(o + d * t).1);
            light.extend(colours[side].extend(1.0).to_array());
        }
    }
    (
        lc::texture_with(wgpu::TextureFormat::R32Float, 2 * w, h, &depth),
        lc::texture_with(wgpu::TextureFormat::Rgba32Float, 2 * w, h, &light),
    )
}

/// The DirectLightingCache view (nearest) of the two triangles of each of `rects`, at their
/// centroids as `cam` sees them: `[rect][triangle]`.
fn cache_at_centroids(
    ctx: &ExecuteContext,
    cam: &lc::Camera,
    rects: &[lc::Rect; 2],
) -> [[Vec3; 2]; 2] {
    let img = lc::view(ctx, cam, DebugOutputType::DirectLightingCache, false);
    (*rects).map(|r| {
        // The triangles of `Rect::mesh(1, _)`: s ≥ t, and s ≤ t (a, b parameters).
        [(2.0, 1.0), (1.0, 2.0)].map(|(s, t)| {
            let p = r.origin + r.a * (s / 3.0) + r.b * (t / 3.0);
            let (px, _) = cam.project(p);
            let i = px.y as usize * cam.w as usize + px.x as usize;
            assert!(img[i].w > 0.0, "the view misses {p:?} at pixel {px:?}");
            img[i].truncate()
        })
    })
}

/// `DirectLightingInjectionTask::viewport`: on a split screen (two cameras side by side in one
/// pair of textures), an injection limited to the right half lights only what the right camera
/// sees — the rectangle only the left half shows keeps its initial colour, though its lit pixels
/// are in the same textures — and then one limited to the left half lights the other, each with
/// exactly its half's colour (the viewport's pixels map through its own camera).
#[test]
fn injection_viewport_limits_the_injection_to_its_region() {
    let ctx = context(4);
    assert_eq!(ctx.traversal_backend().backend, backend());
    let rect = |x: f32| lc::Rect {
        origin: Vec3::new(x, 0.0, -2.0),
        a: Vec3::new(0.0, 0.0, 4.0),
        b: Vec3::new(3.0, 0.0, 0.0),
    };
    let rects = [rect(-3.5), rect(0.5)];
    let camera = |x: f32| lc::Camera {
        eye: Vec3::new(x, 3.0, 1.5),
        target: Vec3::new(x, 0.0, 0.0),
        fov_y: 0.5,
        w: 32,
        h: 32,
    };
    let (left, right) = (camera(-2.0), camera(2.0));
    let overview = lc::Camera {
        eye: Vec3::new(0.0, 7.0, 5.0),
        target: Vec3::ZERO,
        fov_y: 1.0,
        w: 64,
        h: 64,
    };
    let edit = |g: &mut GeometryInput| {
        g.surfel_type = SurfelType::WarpedBarycentricStorage;
        g.force_direct_tile_mapping = true;
    };
    let (a, b) = (rects[0].mesh(1, false), rects[1].mesh(1, false));
    lc::scene(
        &ctx,
        &[(&a, &edit), (&b, &edit)],
        &[
            (0, Affine3A::IDENTITY, MAGENTA, InstanceInclusionMask::ALL),
            (1, Affine3A::IDENTITY, MAGENTA, InstanceInclusionMask::ALL),
        ],
    );
    let (red, green) = (Vec3::X, Vec3::Y);
    let (depth, light) = split_screen(&rects, [&left, &right], [red, green]);
    let inject = |cam: &lc::Camera, x: u32| {
        let mut t = DirectLightingInjectionTask::new(
            DepthInput {
                texture: depth.clone(),
                depth_type: DepthType::RClipSpace,
            },
            light.clone(),
            cam.view(),
        );
        t.viewport = Some(Viewport {
            x,
            y: 0,
            width: cam.w,
            height: cam.h,
        });
        t.injection_resolution_stride = 1;
        lc::run_tasks(&ctx, vec![RenderTask::DirectLightingInjection(t)]);
        cache_at_centroids(&ctx, &overview, &rects)
    };
    let close =
        |got: [Vec3; 2], want: Vec3| got.iter().all(|c| (*c - want).abs().max_element() < 1e-3);
    let initial = cache_at_centroids(&ctx, &overview, &rects);
    assert!(
        initial.iter().all(|r| close(*r, MAGENTA.truncate())),
        "{initial:?}"
    );

    let after_right = inject(&right, right.w);
    assert!(
        close(after_right[1], green),
        "right rectangle: {after_right:?}"
    );
    assert!(
        close(after_right[0], MAGENTA.truncate()),
        "left rectangle: {after_right:?}"
    );
    let after_left = inject(&left, 0);
    assert!(close(after_left[0], red), "left rectangle: {after_left:?}");
    assert!(
        close(after_left[1], green),
        "right rectangle: {after_left:?}"
    );
}

/// Uploads `g`'s clip depth and normals into the G-buffer textures of `common` (as the denoise
/// harness does for its own tasks).
fn upload_gbuffer(common: &DenoiseTaskCommon, g: &dn::GBuffer) {
    let clip = g.view.view_to_clip * g.view.world_to_view;
    let depth: Vec<f32> = g
        .surfaces
        .iter()
        .map(|s| s.map_or(1.0, |s| clip.project_point3(s.position).z))
        .collect();
    let tex = common.depth.texture.texture();
    gpu().queue.write_texture(
        tex.as_image_copy(),
        bytemuck::cast_slice(&depth),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(tex.width() * 4),
            rows_per_image: None,
        },
        tex.size(),
    );
    let normals: Vec<Vec4> = g
        .surfaces
        .iter()
        .map(|s| s.map_or(Vec4::ZERO, |s| s.normal.extend(0.0)))
        .collect();
    dn::write_texture(&common.normal.texture, &normals);
}

/// A denoise task whose input and output are the same texture (the denoisers' documented
/// promise: no pass reads the input and writes the output) gives, frame after frame, exactly
/// the output of the same task with separate textures, and that output is denoised (nearer the
/// reference than the noisy input).
#[test]
fn denoiser_with_one_texture_as_input_and_output_matches_separate_textures() {
    let eye = Vec3::new(0.3, 1.6, 2.6);
    let g = dn::gbuffer(eye, Vec3::ZERO, eye, Vec3::ZERO);
    let reference = dn::reference_image(&g, dn::reference);
    let separate = dn::Harness::new(SignalType::Diffuse, DenoisingMethod::HighQuality);
    let aliased = dn::Harness::new(SignalType::Diffuse, DenoisingMethod::HighQuality);
    assert_eq!(aliased.ctx.traversal_backend().backend, backend());
    let common = aliased.common(&g, dn::Motion::Matrices, DenoiseMode::Continue);
    upload_gbuffer(&common, &g);
    let usage = wgpu::TextureUsages::TEXTURE_BINDING
        | wgpu::TextureUsages::STORAGE_BINDING
        | wgpu::TextureUsages::COPY_DST
        | wgpu::TextureUsages::COPY_SRC;
    let both = texture(wgpu::TextureFormat::Rgba32Float, dn::SIZE, dn::SIZE, usage);
    let mut rng = Rng(7);
    // PSNR of each frame's noisy input and denoised output, checked once every frame matched.
    let mut quality = Vec::new();
    for frame in 0..4 {
        let input = dn::noisy(&reference, &mut rng);
        let want = separate
            .frame(
                &g,
                std::slice::from_ref(&input),
                dn::Motion::Matrices,
                DenoiseMode::Continue,
            )
            .remove(0);
        dn::write_texture(&both, &input);
        let mut c = aliased.ctx.create_task_container();
        c.schedule_render_task(RenderTask::DenoiseDiffuse(DenoiseDiffuseTask {
            common: common.clone(),
            input: both.clone(),
            output: both.clone(),
        }));
        build_submit_complete(&aliased.ctx, c);
        let got = dn::read_texture(&both);
        let worst = got
            .iter()
            .zip(&want)
            .map(|(a, b)| (*a - *b).abs().max_element())
            .fold(0.0f32, f32::max);
        assert!(
            worst <= 1e-6,
            "frame {frame}: aliased output differs by {worst}"
        );
        quality.push((
            dn::psnr(&g, &input, &reference),
            dn::psnr(&g, &got, &reference),
        ));
    }
    for (frame, (noisy, denoised)) in quality.iter().enumerate() {
        assert!(
            *denoised > noisy + 3.0,
            "frame {frame}: {denoised:.2} dB denoised, {noisy:.2} dB noisy"
        );
    }
}

/// A destroyed denoising context's history is released by `release_device_resources_immediately`
/// alone, as its documentation says, without a build in between (destroyed contexts used to be
/// retired only by the next build).
#[test]
fn releasing_right_after_destroying_a_denoiser_frees_its_history() {
    let h = dn::Harness::new(SignalType::Diffuse, DenoisingMethod::Fast);
    let ctx = &h.ctx;
    let before = ctx.resource_allocations();
    // The context's first frame creates its history.
    let eye = Vec3::new(0.0, 1.0, 4.0);
    let g = dn::gbuffer(eye, Vec3::ZERO, eye, Vec3::ZERO);
    let reference = dn::reference_image(&g, dn::reference);
    h.frame(
        &g,
        &[reference],
        dn::Motion::Matrices,
        DenoiseMode::Continue,
    );
    let held = ctx.resource_allocations();
    assert!(held.denoiser > before.denoiser, "{held:?} vs {before:?}");
    ctx.destroy_denoising_context_handle(h.handle)
        .unwrap_or_else(|e| panic!("destroy: {e}"));
    ctx.release_device_resources_immediately()
        .unwrap_or_else(|e| panic!("release: {e}"));
    let after = ctx.resource_allocations();
    assert_eq!(after.denoiser, before.denoiser, "{after:?}");
    // A context created since but not yet used by a frame gets no memory from the release.
    let _unused = ctx
        .create_denoising_context_handle(DenoisingContextInput {
            max_width: 32,
            max_height: 32,
            signal_type: SignalType::Diffuse,
            method: DenoisingMethod::Fast,
        })
        .unwrap_or_else(|e| panic!("denoising context: {e}"));
    ctx.release_device_resources_immediately()
        .unwrap_or_else(|e| panic!("release: {e}"));
    assert_eq!(ctx.resource_allocations().denoiser, before.denoiser);
}

/// Registers `n` quads on `device` in a row along x (each its own geometry and instance), builds
/// them and traces a ray down onto each; returns the handles.
fn quads_on(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    ctx: &ExecuteContext,
    n: usize,
) -> (Vec<GeometryHandle>, Vec<InstanceHandle>) {
    use wgpu::util::DeviceExt;
    let mesh = quad_mesh(0.0);
    let init = |contents: &[u8], usage| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents,
            usage: usage | wgpu::BufferUsages::COPY_SRC,
        })
    };
    let (geometries, instances) = (
        ctx.create_geometry_handles(n),
        ctx.create_instance_handles(n),
    );
    let mut c = ctx.create_task_container();
    for (k, (g, i)) in geometries.iter().zip(&instances).enumerate() {
        let vb = init(
            bytemuck::cast_slice(&mesh.positions),
            wgpu::BufferUsages::VERTEX,
        );
        let ib = init(
            bytemuck::cast_slice(&mesh.indices),
            wgpu::BufferUsages::INDEX,
        );
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Register,
            handle: *g,
            input: geometry_input(vb, Some(ib)),
        });
        let at = Affine3A::from_translation(Vec3::new(2.0 * k as f32, 0.0, 0.0));
        register_instance(&mut c, *i, *g, at);
    }
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: 64,
        ..Default::default()
    });
    build_submit_complete_on(device, queue, ctx, c);
    let corners: Vec<Vec3> = (0..n)
        .map(|k| Vec3::new(2.0 * k as f32, 0.0, 0.0))
        .collect();
    let (hits, _) = trace_on(device, queue, ctx, &rays_down(&corners, 5.0));
    for (k, h) in hits.iter().enumerate() {
        assert_eq!(h.instance, instances[k].index(), "ray {k}: {h:?}");
    }
    (geometries, instances)
}

/// wgpu's own allocator, on a device of the test's own, after each of two identical cycles of
/// registering 8 quads, tracing them, destroying everything and releasing: the same bytes and
/// allocations after both, and no more than while the quads were held. On the ray-query
/// backend the driver's BLASes (which the SDK's own count does not see) must be gone: fewer
/// bytes after the release than while held.
#[test]
fn wgpu_allocations_come_back_after_destroying_and_releasing_everything() {
    let (device, queue) = own_test_device(gpu().device.limits(), "kickstart-rt memory test");
    let settings = InitSettings {
        backend: pass_backend_choice(),
        ..InitSettings::default()
    };
    let ctx =
        ExecuteContext::new(&device, &queue, settings).unwrap_or_else(|e| panic!("context: {e}"));
    assert_pass_backend(&ctx);
    let cycle = || {
        let (geometries, instances) = quads_on(&device, &queue, &ctx, 8);
        let held = wgpu_allocated(&device).unwrap_or_else(|| panic!("no allocator report"));
        // The SDK counts the driver's structures, by the same report: only on the ray-query
        // backend.
        let driver = ctx.resource_allocations().driver_acceleration_structures;
        match backend() {
            TraversalBackend::HardwareRayQuery => {
                assert!(driver > 0, "driver structures uncounted")
            }
            TraversalBackend::Software => assert_eq!(driver, 0),
        }
        ctx.destroy_instance_handles(&instances)
            .unwrap_or_else(|e| panic!("{e}"));
        ctx.destroy_geometry_handles(&geometries)
            .unwrap_or_else(|e| panic!("{e}"));
        let mut c = ctx.create_task_container();
        c.schedule_bvh_task(BvhBuildTask::default());
        build_submit_complete_on(&device, &queue, &ctx, c);
        ctx.release_device_resources_immediately()
            .unwrap_or_else(|e| panic!("release: {e}"));
        let after = wgpu_allocated(&device).unwrap_or_else(|| panic!("no allocator report"));
        let left = ctx.resource_allocations().driver_acceleration_structures;
        assert!(
            left < driver || driver == 0,
            "{left} of {driver} driver bytes left"
        );
        (held, after)
    };
    let (held1, after1) = cycle();
    let (held2, after2) = cycle();
    assert_eq!(
        after2, after1,
        "the second cycle left more: held {held1:?} then {held2:?}"
    );
    assert!(after1.0 <= held1.0, "held {held1:?}, after {after1:?}");
    if backend() == TraversalBackend::HardwareRayQuery {
        // Each driver BLAS is an allocation of its own.
        assert!(
            after1.0 < held1.0 && after1.1 + 8 <= held1.1,
            "the driver's BLASes stayed: {held1:?} → {after1:?}"
        );
    }
}

/// wgpu's allocator report is the device's, yet each context counts only its own driver
/// structures: a second context on the same device keeps its count while the first builds a
/// scene, and the two counts add up to every driver structure the report holds.
#[test]
fn driver_structures_are_counted_for_their_own_context_only() {
    let (device, queue) = own_test_device(gpu().device.limits(), "kickstart-rt two contexts");
    let make = || {
        let settings = InitSettings {
            backend: pass_backend_choice(),
            ..InitSettings::default()
        };
        let ctx = ExecuteContext::new(&device, &queue, settings)
            .unwrap_or_else(|e| panic!("context: {e}"));
        assert_pass_backend(&ctx);
        ctx
    };
    let (scene, bystander) = (make(), make());
    let driver = |ctx: &ExecuteContext| ctx.resource_allocations().driver_acceleration_structures;
    let quiet = driver(&bystander);
    let _held = quads_on(&device, &queue, &scene, 8);
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("poll");
    assert_eq!(
        driver(&bystander),
        quiet,
        "the bystander counted the scene's BLASes"
    );
    let every = device.generate_allocator_report().map_or(0, |r| {
        r.allocations
            .iter()
            .filter(|a| a.name.starts_with("kickstart-rt driver"))
            .map(|a| a.size)
            .sum::<u64>()
    });
    assert_eq!(driver(&scene) + driver(&bystander), every);
    match backend() {
        TraversalBackend::HardwareRayQuery => assert!(
            driver(&scene) > quiet,
            "the scene's BLASes uncounted: {} against an empty context's {quiet}",
            driver(&scene)
        ),
        TraversalBackend::Software => assert_eq!((driver(&scene), every), (0, 0)),
    }
}

/// Once a scene's builds are done, the next GPU task gives back what only builds use: the
/// build scratch, the vertex copies' pool and the BLAS pools' free space (their ranges in use
/// moved into smaller buffers). Rays traced after hit exactly what they hit before, and agree
/// with the CPU oracle, on either backend.
#[test]
fn build_memory_is_given_back_once_builds_are_done_and_traces_stay_the_same() {
    let ctx = context(2);
    let mut rng = Rng(fuzz_seed("build memory", 0x5eed_b17d));
    let mut oracle = common::rt::Oracle::default();
    let mut c = ctx.create_task_container();
    let mut geometries = Vec::new();
    for k in 0..6 {
        let m = Mesh::soup(&mut rng, 400 + 150 * k, 3.0);
        let g = ctx.create_geometry_handle();
        geometries.push(g);
        schedule_mesh(&mut c, g, "soup", &m);
        oracle.geometry(g, &m);
        let i = ctx.create_instance_handle();
        let input = InstanceInput::new(
            g,
            Affine3A::from_translation(Vec3::new(4.0 * k as f32, 0.0, 0.0)),
        );
        oracle.instance(i, &input);
        c.schedule_bvh_task(InstanceTask {
            operation: TaskOperation::Register,
            handle: i,
            input,
        });
    }
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: 64,
        ..Default::default()
    });
    let rays: Vec<GpuRay> = (0..4000)
        .map(|_| {
            // From inside one of the soups.
            let k = rng.below(6) as f32;
            let o = Vec3::new(4.0 * k, 0.0, 0.0) + rng.v(0.0, 3.0);
            ray(o, rng.unit(), 0.0, 100.0)
        })
        .collect();
    // Traced in the building task: before anything is given back.
    let before_hits = common::rt::schedule_trace(
        &mut c,
        &rays,
        RayQuery::ClosestHit,
        InstanceInclusionMask::VISIBLE_IN_RT,
    );
    build_submit_complete(&ctx, c);
    let built = ctx.resource_allocations();
    let before: Vec<GpuHit> = bytemuck::pod_collect_to_vec(&read_buffer(&before_hits));
    // The static soups are fast-trace BLASes: once their compactions are read back, the next
    // quiet task gives back their unused nodes too (packing the node pool).
    let compacted: u64 = geometries
        .iter()
        .map(|&g| compacted_after_polls(&ctx, &gpu().device, g).node_bytes)
        .sum();

    let after = closest(&ctx, &rays);
    let quiet = ctx.resource_allocations();
    assert_eq!(quiet.vertex_copies, 0, "{quiet:?}");
    // The BLASes stay, their nodes compacted: 48 bytes a triangle, 64 a node, and the
    // geometry table, whose size the two counts share.
    let triangles: u64 = (0..6).map(|k| 400 + 150 * k).sum();
    let uncompacted = 48 * triangles + 64 * (triangles - 6);
    let compacted_blas = 48 * triangles + compacted;
    assert!(
        compacted < 64 * (triangles - 6),
        "compaction gave nothing back"
    );
    assert_eq!(
        built.blas - uncompacted,
        quiet.blas - compacted_blas,
        "BLAS bytes besides the geometry table: {quiet:?} vs {built:?}"
    );
    assert!(
        quiet.scratch * 4 < built.scratch,
        "build scratch kept: {quiet:?} vs {built:?}"
    );
    assert!(
        quiet.cache < built.cache,
        "the lighting cache's allocation scratch kept: {quiet:?} vs {built:?}"
    );
    // Only the last element's rounding is left of each pool (at most one 256-byte buffer or
    // the 16-element minimum each).
    assert!(
        quiet.pool_reserve <= 5 * 16 * 64,
        "pool space kept: {quiet:?} vs {built:?}"
    );
    let hit = before.iter().filter(|h| h.is_hit()).count();
    assert!(hit > 800, "{hit} of {} rays hit", rays.len());
    common::rt::assert_agrees(&compare(&oracle, &rays, &before, 0xff), "before the move");
    let differ: Vec<usize> = (0..rays.len()).filter(|&k| after[k] != before[k]).collect();
    if let Some(&k) = differ.first() {
        panic!(
            "{} of {} rays trace differently after the BLASes moved, e.g. ray {k}: {:?} then {:?}",
            differ.len(),
            rays.len(),
            before[k],
            after[k]
        );
    }
    common::rt::assert_agrees(&compare(&oracle, &rays, &after, 0xff), "after the move");

    // The next build allocates again and still traces right.
    let m = Mesh::soup(&mut rng, 300, 3.0);
    let g = ctx.create_geometry_handle();
    let i = ctx.create_instance_handle();
    let mut c = ctx.create_task_container();
    schedule_mesh(&mut c, g, "late soup", &m);
    let input = InstanceInput::new(g, Affine3A::from_translation(Vec3::new(0.0, 6.0, 0.0)));
    oracle.geometry(g, &m);
    oracle.instance(i, &input);
    c.schedule_bvh_task(InstanceTask {
        operation: TaskOperation::Register,
        handle: i,
        input,
    });
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    let rays: Vec<GpuRay> = (0..2000)
        .map(|_| ray(rng.v(0.0, 3.0) + Vec3::Y * 6.0, rng.unit(), 0.0, 100.0))
        .collect();
    let hits = closest(&ctx, &rays);
    common::rt::assert_agrees(&compare(&oracle, &rays, &hits, 0xff), "after a later build");
}
