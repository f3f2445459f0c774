//! The execution model: handles, working sets, lazy destruction, threading, GPU data.

use crate::common;
use common::*;
use glam::{Affine3A, Vec3};
use kickstart_rt::*;

fn field_of(e: &Error) -> String {
    match e {
        Error::InvalidInput { field, .. } => field.clone(),
        other => panic!("expected InvalidInput, got {other:?}"),
    }
}

#[test]
fn static_geometry_copies_are_held_until_built_then_released() {
    let ctx = context(2);
    let g = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g, 2.0);
    build_submit_complete(&ctx, c);
    assert_eq!(ctx.geometry_triangle_count(g).unwrap(), Some(2));
    // No BvhBuildTask yet: the ingested triangles (48 bytes each) wait in the shared pool.
    assert_eq!(ctx.resource_allocations().vertex_copies, 2 * 48);
    assert!(!ctx.geometry_is_built(g).unwrap());
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    assert!(ctx.geometry_is_built(g).unwrap());
    let a = ctx.resource_allocations();
    assert!(a.blas >= 2 * 48 + 64, "BLAS triangles and a node: {a:?}");
    // Released in the first build after the building task completed.
    build_submit_complete(&ctx, ctx.create_task_container());
    assert_eq!(ctx.resource_allocations().vertex_copies, 0);
}

#[test]
fn stale_handles_of_every_kind_are_errors_and_context_keeps_working() {
    let ctx = context(2);
    let g = ctx.create_geometry_handle();
    let i = ctx.create_instance_handle();
    let d = ctx
        .create_denoising_context_handle(DenoisingContextInput {
            max_width: 64,
            max_height: 64,
            signal_type: SignalType::Diffuse,
            method: DenoisingMethod::Fast,
        })
        .unwrap();
    ctx.destroy_geometry_handle(g).unwrap();
    ctx.destroy_instance_handle(i).unwrap();
    ctx.destroy_denoising_context_handle(d).unwrap();
    assert!(matches!(
        ctx.destroy_geometry_handle(g),
        Err(Error::InvalidHandle {
            kind: HandleKind::Geometry,
            ..
        })
    ));
    assert!(matches!(
        ctx.destroy_instance_handle(i),
        Err(Error::InvalidHandle {
            kind: HandleKind::Instance,
            ..
        })
    ));
    assert!(matches!(
        ctx.destroy_denoising_context_handle(d),
        Err(Error::InvalidHandle {
            kind: HandleKind::DenoisingContext,
            ..
        })
    ));

    // The slot is reused with a new generation: the old handle stays invalid.
    let g2 = ctx.create_geometry_handle();
    assert_eq!(g2.index(), g.index());
    assert_ne!(g2, g);
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g, 1.0);
    let mut e = encoder();
    assert!(matches!(
        ctx.build_gpu_task(c, &mut e),
        Err(Error::InvalidHandle {
            kind: HandleKind::Geometry,
            ..
        })
    ));
    submit(e); // nothing recorded: finishing the encoder must not fail

    // A stale instance handle in a task.
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g2, 1.0);
    register_instance(&mut c, i, g2, Affine3A::IDENTITY);
    let mut e = encoder();
    assert!(matches!(
        ctx.build_gpu_task(c, &mut e),
        Err(Error::InvalidHandle {
            kind: HandleKind::Instance,
            ..
        })
    ));
    submit(e);

    // The context still works, and the failed container registered nothing.
    let i2 = ctx.create_instance_handle();
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g2, 1.0);
    register_instance(&mut c, i2, g2, Affine3A::IDENTITY);
    build_submit_complete(&ctx, c);
    assert_eq!(ctx.recorded_task_counts().geometry_tasks, 1);

    // Handles from another context are foreign.
    let other = context(1);
    assert!(matches!(
        other.destroy_geometry_handle(g2),
        Err(Error::InvalidHandle { .. })
    ));
}

#[test]
fn gpu_task_handles_unknown_or_completed_are_errors() {
    let ctx = context(2);
    let mut e = encoder();
    let t = ctx
        .build_gpu_task(ctx.create_task_container(), &mut e)
        .unwrap();
    submit(e);
    ctx.mark_gpu_task_completed(t).unwrap();
    assert_eq!(
        ctx.mark_gpu_task_completed(t),
        Err(Error::InvalidGpuTaskHandle(t.serial()))
    );
    // A handle this context never issued (serial 2 exists only in `other`).
    let other = context(2);
    let mut e = encoder();
    let _u1 = other
        .build_gpu_task(other.create_task_container(), &mut e)
        .unwrap();
    let u2 = other
        .build_gpu_task(other.create_task_container(), &mut e)
        .unwrap();
    submit(e);
    assert_eq!(u2.serial(), 2);
    assert_eq!(
        ctx.mark_gpu_task_completed(u2),
        Err(Error::InvalidGpuTaskHandle(2))
    );
}

#[test]
fn building_past_supported_working_sets_errors_without_blocking() {
    let ctx = context(2);
    let mut e = encoder();
    let a = ctx
        .build_gpu_task(ctx.create_task_container(), &mut e)
        .unwrap();
    let _b = ctx
        .build_gpu_task(ctx.create_task_container(), &mut e)
        .unwrap();
    let start = std::time::Instant::now();
    // Not submitted yet: the GPU can't finish, so a blocking build would hang here.
    assert_eq!(
        ctx.build_gpu_task(ctx.create_task_container(), &mut e),
        Err(Error::WorkingSetsExhausted { supported: 2 })
    );
    assert!(start.elapsed().as_secs() < 10, "build blocked");
    submit(e);
    ctx.mark_gpu_task_completed(a).unwrap();
    let mut e = encoder();
    assert!(ctx
        .build_gpu_task(ctx.create_task_container(), &mut e)
        .is_ok());
    submit(e);
}

#[test]
fn destroyed_geometry_keeps_memory_until_first_build_after_completion() {
    let ctx = context(4);
    let g = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g, 1.0);
    let mut e = encoder();
    let t = ctx.build_gpu_task(c, &mut e).unwrap();
    let bytes = ctx.resource_allocations().vertex_copies;
    assert_eq!(bytes, 2 * 48, "two ingested triangles");
    ctx.destroy_geometry_handle(g).unwrap();
    // In flight: kept, even across another build.
    let mut e2 = encoder();
    let t2 = ctx
        .build_gpu_task(ctx.create_task_container(), &mut e2)
        .unwrap();
    assert_eq!(ctx.resource_allocations().vertex_copies, bytes);
    submit(e);
    submit(e2);
    ctx.mark_gpu_task_completed(t).unwrap();
    // Completed, but not released before the next build.
    assert_eq!(ctx.resource_allocations().vertex_copies, bytes);
    ctx.mark_gpu_task_completed(t2).unwrap();
    let mut e = encoder();
    let t3 = ctx
        .build_gpu_task(ctx.create_task_container(), &mut e)
        .unwrap();
    assert_eq!(ctx.resource_allocations().vertex_copies, 0);
    submit(e);
    ctx.mark_gpu_task_completed(t3).unwrap();
}

#[test]
fn release_immediately_refuses_while_in_flight() {
    let ctx = context(2);
    let g = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g, 1.0);
    let mut e = encoder();
    let t = ctx.build_gpu_task(c, &mut e).unwrap();
    ctx.destroy_geometry_handle(g).unwrap();
    assert_eq!(
        ctx.release_device_resources_immediately(),
        Err(Error::TasksInFlight {
            operation: "release_device_resources_immediately",
            in_flight: 1
        })
    );
    submit(e);
    ctx.mark_gpu_task_completed(t).unwrap();
    ctx.release_device_resources_immediately().unwrap();
    assert_eq!(ctx.resource_allocations().vertex_copies, 0);
    assert_eq!(ctx.resource_allocations().staging, 0);
}

/// Where thread `k` places its geometry `j` (a quad of side `1 + j` in z = 0): its corner at
/// (10k, 10j) in x and y, and at a depth of its own, so that a ray tells every thread's every
/// instance apart by its hit distance as well as by its instance index.
fn thread_slot(k: usize, j: usize) -> Vec3 {
    Vec3::new(10.0 * k as f32, 10.0 * j as f32, -0.25 * (5 * k + j) as f32)
}

/// Eight threads fill one container each (five geometries of their own sizes and an instance of
/// each at a place of their own), then several threads build them, each container into exactly
/// one GPU task; rays then find every thread's every instance where that thread put it, with its
/// size: hit at the expected distance inside the quad, missed just outside it.
#[test]
fn eight_threads_fill_containers_then_several_build_each_task_once() {
    let ctx = context(16);
    let handles = ctx.create_geometry_handles(8 * 5);
    let filled: Vec<(TaskContainer, Vec<InstanceHandle>)> = std::thread::scope(|s| {
        let jobs: Vec<_> = handles
            .chunks(5)
            .enumerate()
            .map(|(k, chunk)| {
                let ctx = &ctx;
                s.spawn(move || {
                    let mut c = ctx.create_task_container();
                    let instances = ctx.create_instance_handles(chunk.len());
                    for (j, (h, i)) in chunk.iter().zip(&instances).enumerate() {
                        register_geometry(&mut c, *h, 1.0 + j as f32);
                        let at = Affine3A::from_translation(thread_slot(k, j));
                        register_instance(&mut c, *i, *h, at);
                    }
                    (c, instances)
                })
            })
            .collect();
        jobs.into_iter().map(|j| j.join().unwrap()).collect()
    });
    let (containers, instances): (Vec<TaskContainer>, Vec<Vec<InstanceHandle>>) =
        filled.into_iter().unzip();
    let mut built: Vec<(GpuTaskHandle, wgpu::CommandBuffer)> = std::thread::scope(|s| {
        let mut rest = containers;
        let mut jobs = Vec::new();
        while !rest.is_empty() {
            let batch: Vec<TaskContainer> = rest.drain(..rest.len().min(2)).collect();
            let ctx = &ctx;
            jobs.push(s.spawn(move || {
                batch
                    .into_iter()
                    .map(|c| {
                        let mut e = encoder();
                        let t = ctx.build_gpu_task(c, &mut e).unwrap();
                        (t, e.finish())
                    })
                    .collect::<Vec<_>>()
            }));
        }
        jobs.into_iter().flat_map(|j| j.join().unwrap()).collect()
    });
    // GPU tasks must execute in the order they were built (each one's uploads and builds follow
    // the previous one's): the threads only record, and the command buffers go to the queue in
    // serial order. Submitted as each thread finished instead, a later task can run before an
    // earlier one, and rays miss the earlier task's instances.
    built.sort_by_key(|(t, _)| t.serial());
    let serials: Vec<u64> = built.iter().map(|(t, _)| t.serial()).collect();
    assert!(
        serials.windows(2).all(|w| w[0] < w[1]) && serials.len() == 8,
        "one task per container, each its own serial: {serials:?}"
    );
    let (built, buffers): (Vec<GpuTaskHandle>, Vec<wgpu::CommandBuffer>) =
        built.into_iter().unzip();
    gpu().queue.submit(buffers);
    gpu()
        .device
        .poll(wgpu::PollType::wait_indefinitely())
        .unwrap();
    assert_eq!(
        ctx.recorded_task_counts(),
        RecordedTaskCounts {
            geometry_tasks: 40,
            instance_tasks: 40,
            gpu_tasks: 8,
            opaque_only_traces: 0,
        }
    );
    for h in &handles {
        assert_eq!(ctx.geometry_triangle_count(*h).unwrap(), Some(2));
    }
    for t in built {
        ctx.mark_gpu_task_completed(t).unwrap();
    }
    assert_threads_instances_traced(&ctx, &instances);
}

/// Builds every BLAS and the TLAS, then traces three rays down at each of thread `k`'s
/// instances `j` (see [`thread_slot`]): 0.25 inside its near and far corners (hit at its
/// depth), 0.25 past its far corner (miss: the quad has the size that thread gave it).
fn assert_threads_instances_traced(ctx: &ExecuteContext, instances: &[Vec<InstanceHandle>]) {
    rt::build_all(ctx);
    let mut rays = Vec::new();
    let mut want = Vec::new();
    for (k, thread) in instances.iter().enumerate() {
        for (j, i) in thread.iter().enumerate() {
            let corner = thread_slot(k, j);
            let side = 1.0 + j as f32;
            let origin_z = 10.0;
            for (offset, hit) in [(0.25, true), (side - 0.25, true), (side + 0.25, false)] {
                let o = Vec3::new(corner.x + offset, corner.y + offset, origin_z);
                rays.push(rt::ray(o, -Vec3::Z, 0.0, 100.0));
                want.push(hit.then_some((i.index(), origin_z - corner.z)));
            }
        }
    }
    let hits = rt::closest(ctx, &rays);
    for (k, (hit, want)) in hits.iter().zip(&want).enumerate() {
        let thread = k / 15;
        match want {
            Some((instance, t)) => assert!(
                hit.instance == *instance && (hit.t - t).abs() < 1e-4,
                "thread {thread}, ray {k}: want instance {instance} at {t}, got {hit:?}"
            ),
            None => assert!(!hit.is_hit(), "thread {thread}, ray {k}: {hit:?}"),
        }
    }
}

/// The instance-id bug report's invariant: instance data lives at the handle's index, with
/// out-of-order registration, destruction and re-registration, and a table that grows.
#[test]
fn instance_data_is_at_the_instance_index() {
    let ctx = context(4);
    let g = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g, 1.0);
    build_submit_complete(&ctx, c);

    let mut live: Vec<(InstanceHandle, f32)> = Vec::new();
    let handles = ctx.create_instance_handles(100);
    // Register in reverse order, in two containers.
    for (n, chunk) in handles
        .iter()
        .rev()
        .collect::<Vec<_>>()
        .chunks(50)
        .enumerate()
    {
        let mut c = ctx.create_task_container();
        for h in chunk {
            let x = h.index() as f32 * 10.0 + n as f32;
            register_instance(
                &mut c,
                **h,
                g,
                Affine3A::from_translation(Vec3::new(x, 1.0, 2.0)),
            );
            live.push((**h, x));
        }
        build_submit_complete(&ctx, c);
    }
    // Destroy every third, re-create (slots reused) and register with new data.
    for k in (0..100).step_by(3) {
        ctx.destroy_instance_handle(handles[k]).unwrap();
        live.retain(|(h, _)| *h != handles[k]);
    }
    let again = ctx.create_instance_handles(40); // 34 reused slots, 6 new (table grows past 64? no: 106)
    let mut c = ctx.create_task_container();
    for h in &again {
        let x = -(h.index() as f32) - 0.5;
        register_instance(
            &mut c,
            *h,
            g,
            Affine3A::from_translation(Vec3::new(x, 1.0, 2.0)),
        );
        live.push((*h, x));
    }
    build_submit_complete(&ctx, c);

    let table = read_buffer(&ctx.instance_table().unwrap());
    let words: &[f32] = bytemuck::cast_slice(&table);
    let stride = (INSTANCE_RECORD_SIZE / 4) as usize;
    assert!(
        table.len() as u64 >= 106 * INSTANCE_RECORD_SIZE,
        "table grew to hold index 105"
    );
    for (h, x) in live {
        let rec = &words[h.index() as usize * stride..][..stride];
        // Row-major 3x4: translation in column 3 of each row.
        assert_eq!(
            (rec[3], rec[7], rec[11]),
            (x, 1.0, 2.0),
            "instance {}",
            h.index()
        );
        // Then the inverse's rows: the translation is negated.
        assert_eq!(
            (rec[15], rec[19], rec[23]),
            (-x, -1.0, -2.0),
            "instance {}",
            h.index()
        );
        assert_eq!(rec[24].to_bits(), g.index());
        assert_eq!(rec[25].to_bits(), 3, "default inclusion mask");
        assert_eq!(rec[26].to_bits(), 1, "participating");
    }
}

#[test]
fn invoke_gpu_task_completes_by_itself() {
    let ctx = context(1);
    let g = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g, 1.0);
    ctx.invoke_gpu_task(c).unwrap();
    settle_invoked_tasks(&ctx, std::time::Duration::from_secs(10));
    // With one working set, a second invoke only works if the first was marked complete.
    ctx.invoke_gpu_task(ctx.create_task_container()).unwrap();
}

#[test]
fn input_buffer_without_copy_src_gets_our_error_not_a_wgpu_panic() {
    let ctx = context(2);
    let g = ctx.create_geometry_handle();
    let vb = buffer(&[0u8; 48], wgpu::BufferUsages::VERTEX);
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Register,
        handle: g,
        input: geometry_input(vb, None),
    });
    let mut e = encoder();
    let err = ctx.build_gpu_task(c, &mut e).unwrap_err();
    assert_eq!(field_of(&err), "input.components[0].vertex_buffer.buffer");
    submit(e); // finish() must succeed: nothing invalid was recorded
}

#[test]
fn refused_containers_apply_nothing() {
    let ctx = context(2);
    let [a, b] = [ctx.create_instance_handle(), ctx.create_instance_handle()];
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(BvhBuildTask::default());
    // A transfer between instances that were never registered.
    c.schedule_render_task(RenderTask::DirectLightTransfer(DirectLightTransferTask {
        source: a,
        target: b,
    }));
    let mut e = encoder();
    let err = ctx.build_gpu_task(c, &mut e).unwrap_err();
    assert_eq!(field_of(&err), "source");
    submit(e);
    // Nothing of the refused container was applied: the context still builds.
    build_submit_complete(&ctx, ctx.create_task_container());
}

#[test]
fn version_and_settings_checks() {
    let g = gpu();
    let bad_major = InitSettings {
        version: Version {
            major: VERSION.major + 1,
            ..VERSION
        },
        ..Default::default()
    };
    assert!(matches!(
        ExecuteContext::new(&g.device, &g.queue, bad_major),
        Err(Error::IncompatibleVersion { .. })
    ));
    let warned = std::sync::Arc::new(std::sync::Mutex::new(Vec::<String>::new()));
    let w = warned.clone();
    let minor = InitSettings {
        version: Version {
            minor: VERSION.minor + 1,
            ..VERSION
        },
        log_callback: Some(std::sync::Arc::new(move |s, m: &str| {
            if s == Severity::Warning {
                w.lock().unwrap().push(m.to_string());
            }
        })),
        ..Default::default()
    };
    assert!(ExecuteContext::new(&g.device, &g.queue, minor).is_ok());
    assert_eq!(warned.lock().unwrap().len(), 1);
    let zero = InitSettings {
        supported_working_sets: 0,
        ..Default::default()
    };
    assert_eq!(
        field_of(&ExecuteContext::new(&g.device, &g.queue, zero).unwrap_err()),
        "supported_working_sets"
    );
}

#[test]
fn device_below_required_limits_is_named() {
    let g = gpu();
    let (device, queue) = pollster::block_on(g.adapter.request_device(&wgpu::DeviceDescriptor {
        required_limits: wgpu::Limits::downlevel_webgl2_defaults(),
        ..Default::default()
    }))
    .unwrap();
    match ExecuteContext::new(&device, &queue, InitSettings::default()) {
        Err(Error::InsufficientLimit {
            name,
            actual,
            required,
        }) => {
            assert!(!name.is_empty());
            assert!(actual < required);
        }
        other => panic!("expected InsufficientLimit, got {other:?}"),
    }
}

/// Per-task upload staging returns to the pool on completion and is reused, so memory stays
/// bounded over many frames; data written in each frame reaches GPU memory.
#[test]
fn staging_is_recycled_and_every_frame_reaches_the_gpu() {
    let ctx = context(2);
    let g = ctx.create_geometry_handle();
    // The moving instance is not the first: a record read at the wrong stride would then land
    // in another record (the first one's, which stays at the origin).
    let still = ctx.create_instance_handle();
    let i = ctx.create_instance_handle();
    assert_ne!(i.index(), 0);
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g, 1.0);
    register_instance(&mut c, still, g, Affine3A::IDENTITY);
    register_instance(&mut c, i, g, Affine3A::IDENTITY);
    build_submit_complete(&ctx, c);
    let mut peak = 0;
    let mut base = 0;
    for frame in 0..30 {
        let mut c = ctx.create_task_container();
        let x = frame as f32;
        c.schedule_bvh_task(InstanceTask {
            operation: TaskOperation::Update,
            handle: i,
            input: InstanceInput::new(g, Affine3A::from_translation(Vec3::new(x, 0.0, 0.0))),
        });
        build_submit_complete(&ctx, c);
        // The first frames also carry one-off uploads (the lighting cache's initial state);
        // from then on only the instance record is uploaded.
        if frame == 1 {
            base = ctx.resource_allocations().staging;
        }
        peak = peak.max(ctx.resource_allocations().staging);
        let table = read_buffer(&ctx.instance_table().unwrap());
        let words: &[f32] = bytemuck::cast_slice(&table);
        // Row 0 of the 3×4 object-to-world matrix ends with the x translation.
        let record = (INSTANCE_RECORD_SIZE / 4) as usize;
        assert_eq!(words[i.index() as usize * record + 3], x, "frame {frame}");
        assert_eq!(
            words[still.index() as usize * record + 3],
            0.0,
            "frame {frame}"
        );
    }
    // Each frame needs one 256-byte buffer; a leak would reach 30 of them.
    assert!(
        peak <= base + 3 * 256,
        "staging grew from {base} to {peak} bytes"
    );
}

/// One engine frame of the bounded-memory tests: instance `i` of `g` moved to `x` (an upload
/// through the working set's staging), the TLAS refit over it, and an AO trace of a small
/// G-buffer (per-task uniforms and bind groups).
fn moving_frame(
    ctx: &ExecuteContext,
    (g, i): (GeometryHandle, InstanceHandle),
    x: f32,
    ao: &TraceAmbientOcclusionTask,
) -> TaskContainer {
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(InstanceTask {
        operation: TaskOperation::Update,
        handle: i,
        input: InstanceInput::new(g, Affine3A::from_translation(Vec3::new(x, 0.0, 0.0))),
    });
    c.schedule_bvh_task(BvhBuildTask::default());
    c.schedule_render_task(RenderTask::TraceAmbientOcclusion(ao.clone()));
    c
}

/// A context of `working_sets` with one registered, built quad instance, and the AO task the
/// frames trace (8×8 pixels looking at the quad).
fn moving_scene(
    working_sets: u32,
) -> (
    ExecuteContext,
    (GeometryHandle, InstanceHandle),
    TraceAmbientOcclusionTask,
) {
    let ctx = context(working_sets);
    let g = ctx.create_geometry_handle();
    let i = ctx.create_instance_handle();
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g, 1.0);
    register_instance(&mut c, i, g, Affine3A::IDENTITY);
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    let common = trace::gbuffer_common(8, 8, Vec3::new(0.0, 0.0, 3.0), |x, y| {
        Some((Vec3::new(x as f32 / 8.0, y as f32 / 8.0, 0.0), Vec3::Z))
    });
    let ao = TraceAmbientOcclusionTask {
        common,
        output: trace::output(8, 8),
        ao_radius: 1.0,
    };
    (ctx, (g, i), ao)
}

/// An engine that submits frame after frame but never polls the device nor marks a task
/// complete (a GPU that fell behind, or a lost fence): the SDK accepts as many GPU tasks as it
/// has working sets, then refuses every further one with `WorkingSetsExhausted` at once (no
/// stall), and nothing it holds grows: allocations, tasks in flight and recorded work stay what
/// they were when the working sets filled up. A refused frame applies nothing (its instance
/// move is not in the table once the GPU catches up), and the context then carries on.
#[test]
fn tasks_ahead_of_a_gpu_never_polled_are_refused_and_memory_stays_bounded() {
    const WORKING_SETS: u32 = 3;
    const FRAMES: u32 = 200;
    let (ctx, scene, ao) = moving_scene(WORKING_SETS);
    let base_tasks = ctx.recorded_task_counts().gpu_tasks;
    let g = gpu();
    let mut accepted = Vec::new();
    let mut full = None;
    let start = std::time::Instant::now();
    for frame in 0..FRAMES {
        let mut e = encoder();
        match ctx.build_gpu_task(moving_frame(&ctx, scene, frame as f32, &ao), &mut e) {
            Ok(t) => accepted.push((t, frame)),
            Err(Error::WorkingSetsExhausted { supported }) => {
                assert_eq!(supported, WORKING_SETS);
                // What the SDK held when its working sets filled up: nothing may grow after
                // (the driver's structures, read from wgpu's allocator, may shrink as finished
                // work frees old ones, or move by their placement's padding).
                let a = ctx.resource_allocations();
                let driver = a.driver_acceleration_structures;
                let now = (
                    ResourceAllocations {
                        driver_acceleration_structures: 0,
                        ..a
                    },
                    ctx.in_flight_task_count(),
                );
                let (first, first_driver) = *full.get_or_insert((now, driver));
                assert_eq!(first, now, "frame {frame}");
                assert!(
                    driver <= first_driver + DRIVER_PLACEMENT_PADDING,
                    "frame {frame}: the driver's structures grew: {first_driver} → {driver}"
                );
            }
            Err(other) => panic!("frame {frame}: {other:?}"),
        }
        // Submitted, never polled: `queue.submit` does not wait.
        g.queue.submit([e.finish()]);
    }
    assert!(
        start.elapsed().as_secs() < 60,
        "{FRAMES} builds took {:?}: a build waited for the GPU",
        start.elapsed()
    );
    let frames: Vec<u32> = accepted.iter().map(|(_, f)| *f).collect();
    assert_eq!(
        frames,
        [0, 1, 2],
        "the first working sets' worth, then refusals"
    );
    assert_eq!(
        ctx.recorded_task_counts().gpu_tasks,
        base_tasks + u64::from(WORKING_SETS)
    );
    let ((held, in_flight), _) = full.expect("the working sets filled up");
    assert_eq!(in_flight, WORKING_SETS as usize);
    assert!(held.staging > 0, "each task in flight holds its upload");
    // The GPU catches up: only the accepted frames reached it.
    g.device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("poll");
    for (t, _) in &accepted {
        ctx.mark_gpu_task_completed(*t).unwrap();
    }
    let table = read_buffer(&ctx.instance_table().unwrap());
    let words: &[f32] = bytemuck::cast_slice(&table);
    let record = (INSTANCE_RECORD_SIZE / 4) as usize;
    assert_eq!(words[scene.1.index() as usize * record + 3], 2.0);
    // And the context carries on.
    build_submit_complete(&ctx, moving_frame(&ctx, scene, 7.0, &ao));
    let table = read_buffer(&ctx.instance_table().unwrap());
    let words: &[f32] = bytemuck::cast_slice(&table);
    assert_eq!(words[scene.1.index() as usize * record + 3], 7.0);
}

/// An engine that keeps the SDK's working sets full for many frames, waiting for the oldest
/// frame before it builds the next (what `ksrt`'s loops and a frames-in-flight renderer do):
/// after the first frames, the memory the SDK holds stops growing; recycled staging is reused,
/// not added to.
#[test]
fn a_full_pipeline_of_frames_runs_in_bounded_memory() {
    const WORKING_SETS: u32 = 3;
    const FRAMES: u32 = 150;
    let (ctx, scene, ao) = moving_scene(WORKING_SETS);
    let g = gpu();
    let mut in_flight = std::collections::VecDeque::new();
    let mut warm = ResourceAllocations::default();
    let mut peak = ResourceAllocations::default();
    for frame in 0..FRAMES {
        if in_flight.len() == WORKING_SETS as usize {
            g.device
                .poll(wgpu::PollType::wait_indefinitely())
                .expect("poll");
            ctx.mark_gpu_task_completed(in_flight.pop_front().unwrap())
                .unwrap();
        }
        let mut e = encoder();
        let t = ctx
            .build_gpu_task(moving_frame(&ctx, scene, frame as f32, &ao), &mut e)
            .unwrap_or_else(|err| panic!("frame {frame}: {err}"));
        g.queue.submit([e.finish()]);
        in_flight.push_back(t);
        let now = ctx.resource_allocations();
        let target = if frame < 20 { &mut warm } else { &mut peak };
        target.staging = target.staging.max(now.staging);
        target.scratch = target.scratch.max(now.scratch);
        *target = ResourceAllocations {
            staging: target.staging,
            scratch: target.scratch,
            ..now
        };
    }
    eprintln!("first 20 frames: {warm:?}\nframes 20..{FRAMES}: {peak:?}");
    assert!(
        peak.staging <= warm.staging && peak.scratch <= warm.scratch,
        "grew after the first frames: {warm:?} → {peak:?}"
    );
    // The driver's structures (hardware backend) are wgpu's allocator's sizes, with the padding
    // of where each landed: the TLAS rebuilt each frame moves by a few bytes, not more.
    let driver = (
        warm.driver_acceleration_structures,
        peak.driver_acceleration_structures,
    );
    assert!(
        driver.1 <= driver.0 + DRIVER_PLACEMENT_PADDING,
        "the driver's structures grew: {driver:?}"
    );
    let own = |a: ResourceAllocations| ResourceAllocations {
        staging: 0,
        scratch: 0,
        driver_acceleration_structures: 0,
        ..a
    };
    assert_eq!(own(peak), own(warm), "the scene's own memory changed");
}

/// Bytes a driver structure's reported size may move by between two placements in wgpu's
/// allocator (its alignment padding).
const DRIVER_PLACEMENT_PADDING: u64 = 1024;

/// `invoke_gpu_task` called in a loop by an application that never polls the device itself:
/// every call returns at once, each either accepted or refused by name, and no more tasks than
/// working sets are ever in flight.
#[test]
fn invoke_without_polling_never_stalls_nor_exceeds_the_working_sets() {
    const WORKING_SETS: u32 = 2;
    let (ctx, scene, ao) = moving_scene(WORKING_SETS);
    let start = std::time::Instant::now();
    let (mut accepted, mut refused) = (0, 0);
    for frame in 0..100 {
        match ctx.invoke_gpu_task(moving_frame(&ctx, scene, frame as f32, &ao)) {
            Ok(()) => accepted += 1,
            Err(Error::WorkingSetsExhausted { supported: 2 }) => refused += 1,
            Err(other) => panic!("frame {frame}: {other:?}"),
        }
        assert!(ctx.in_flight_task_count() <= WORKING_SETS as usize);
    }
    assert!(start.elapsed().as_secs() < 60, "{:?}", start.elapsed());
    assert!(
        accepted >= WORKING_SETS,
        "{accepted} accepted, {refused} refused"
    );
    settle_invoked_tasks(&ctx, std::time::Duration::from_secs(10));
}
