//! Faults the engine must be able to act on: a device lost (here destroyed with
//! `Device::destroy`, which wgpu reports like a removed or reset device) while a context has work
//! registered and in flight.

use crate::common;
use common::*;
use glam::{Affine3A, Vec3};
use kickstart_rt::*;
use wgpu::util::DeviceExt;

/// A device of the test adapter with what the SDK uses, apart from the shared one (this test
/// destroys it).
fn own_device() -> (wgpu::Device, wgpu::Queue) {
    own_test_device(gpu().device.limits(), "kickstart-rt faults test")
}

/// A unit quad's vertex and index buffers on `device`.
fn quad_on(device: &wgpu::Device) -> (wgpu::Buffer, wgpu::Buffer) {
    let p: [f32; 12] = [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 1.0, 1.0, 0.0, 0.0, 1.0, 0.0];
    let i: [u32; 6] = [0, 1, 2, 0, 2, 3];
    let init = |contents: &[u8], usage| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: None,
            contents,
            usage: usage | wgpu::BufferUsages::COPY_SRC,
        })
    };
    (
        init(bytemuck::cast_slice(&p), wgpu::BufferUsages::VERTEX),
        init(bytemuck::cast_slice(&i), wgpu::BufferUsages::INDEX),
    )
}

/// The device is lost with a task in flight and another queued: every later task is refused
/// with `Error::Device` (never a panic, which wgpu's default error handler or its buffer helpers
/// would raise), the context's other calls keep working and it drops cleanly; a new context on
/// a new device then traces correctly.
#[test]
fn a_lost_device_is_reported_by_every_later_task_and_nothing_panics() {
    let (device, queue) = own_device();
    let settings = InitSettings {
        backend: pass_backend_choice(),
        ..InitSettings::default()
    };
    let ctx = ExecuteContext::new(&device, &queue, settings).unwrap();
    assert_pass_backend(&ctx);
    let (vb, ib) = quad_on(&device);
    let first = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Register,
        handle: first,
        input: geometry_input(vb, Some(ib)),
    });
    let instance = ctx.create_instance_handle();
    c.schedule_bvh_task(InstanceTask {
        operation: TaskOperation::Register,
        handle: instance,
        input: InstanceInput::new(first, Affine3A::IDENTITY),
    });
    c.schedule_bvh_task(BvhBuildTask::default());
    let mut e = device.create_command_encoder(&Default::default());
    let in_flight = ctx.build_gpu_task(c, &mut e).unwrap();
    queue.submit([e.finish()]);
    // The engine's next frame, prepared before the loss.
    let (vb, ib) = quad_on(&device);
    let second = ctx.create_geometry_handle();

    device.destroy();

    let mut c = ctx.create_task_container();
    c.schedule_bvh_task(GeometryTask {
        operation: TaskOperation::Register,
        handle: second,
        input: geometry_input(vb, Some(ib)),
    });
    c.schedule_bvh_task(BvhBuildTask::default());
    let mut e = device.create_command_encoder(&Default::default());
    match ctx.build_gpu_task(c, &mut e) {
        Err(Error::Device { operation, message }) => {
            assert_eq!(operation, "build_gpu_task");
            assert!(!message.is_empty());
        }
        other => panic!("expected Error::Device after the loss, got {other:?}"),
    }
    // Every later task too, even an empty one (which records nothing the device could refuse).
    let mut e = device.create_command_encoder(&Default::default());
    assert!(matches!(
        ctx.build_gpu_task(ctx.create_task_container(), &mut e),
        Err(Error::Device { .. })
    ));
    // The rest of the API still answers, and the context drops without a panic.
    ctx.mark_gpu_task_completed(in_flight).unwrap();
    let _ = ctx.resource_allocations();
    ctx.destroy_instance_handle(instance).unwrap();
    ctx.destroy_geometry_handle(first).unwrap();
    drop(ctx);

    // What the engine does next: a new device and context, the scene registered again.
    let ctx = context(2);
    let g = ctx.create_geometry_handle();
    let mut c = ctx.create_task_container();
    register_geometry(&mut c, g, 1.0);
    register_instance(&mut c, ctx.create_instance_handle(), g, Affine3A::IDENTITY);
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    let hits = common::rt::closest(
        &ctx,
        &[common::rt::ray(
            Vec3::new(0.25, 0.25, 1.0),
            -Vec3::Z,
            0.0,
            10.0,
        )],
    );
    assert!(
        hits[0].is_hit() && (hits[0].t - 1.0).abs() < 1e-5,
        "{:?}",
        hits[0]
    );
}
