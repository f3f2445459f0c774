//! Ray queries as gameplay code uses them: picking (which object is under the cursor?) and
//! visibility (can this guard see the player?), traced in batches on the GPU.
//!
//! ```sh
//! cargo run -p kickstart-rt --example ray_queries
//! ```
//!
//! A `TraceRaysTask` reads `GpuRay` records from a storage buffer and writes one `GpuHit` per
//! ray. Picking wants the closest hit (`RayQuery::ClosestHit`); visibility only needs to know
//! whether anything blocks the segment (`RayQuery::AnyHit` with `t_max` = the distance, which
//! stops at the first hit found). The example knows each answer and exits with an error on a
//! wrong one.

mod common;

use common::{AnyResult, Placement, Shape};
use glam::{Affine3A, Vec3};
use kickstart_rt as ksrt;
use wgpu::util::DeviceExt;

fn main() {
    if let Err(e) = run() {
        eprintln!("ray_queries: {e}");
        std::process::exit(1);
    }
}

/// A cube of `size` metres standing on the floor at (x, z).
fn crate_at(x: f32, z: f32, size: f32) -> Placement {
    Placement {
        shape: Shape::Cube,
        transform: Affine3A::from_scale_rotation_translation(
            Vec3::splat(size),
            glam::Quat::IDENTITY,
            Vec3::new(x, size / 2.0, z),
        ),
        albedo: Vec3::splat(0.5),
    }
}

fn run() -> AnyResult<()> {
    let (_adapter, device, queue) = common::device(&common::instance(None), None)?;
    let ctx = ksrt::ExecuteContext::new(&device, &queue, ksrt::InitSettings::default())?;
    // Objects 0 (floor) and 1 (a box at the origin), then two crates.
    let objects = common::box_on_plane([crate_at(-3.0, -1.0, 1.0), crate_at(3.0, -2.0, 2.0)]);
    let scene = common::register_scene(&device, &ctx, objects)?;
    let names = ["floor", "box", "small crate", "big crate"];
    // `GpuHit::instance` is the instance handle's index: map it back to our objects.
    let object_of = |hit: &ksrt::GpuHit| {
        scene
            .instances
            .iter()
            .position(|h| hit.is_hit() && hit.instance == h.index())
            .map_or("nothing", |i| names[i])
    };

    // Picking: rays from the camera through what the cursor points at, and what each must hit.
    let camera = Vec3::new(0.0, 4.0, 8.0);
    let picks = [
        (Vec3::new(0.0, 0.5, 0.0), "box"),
        (Vec3::new(-3.0, 0.5, -1.0), "small crate"),
        (Vec3::new(3.0, 1.0, -2.0), "big crate"),
        (Vec3::new(1.5, 0.0, 3.0), "floor"),
        (Vec3::new(0.0, 8.0, 0.0), "nothing"), // the sky
    ];
    let pick_rays: Vec<ksrt::GpuRay> = picks
        .iter()
        .map(|(at, _)| ray(camera, (*at - camera).normalize(), f32::INFINITY))
        .collect();

    // Visibility: can the guard at `from` see the player at `to`? Blocked or not, as expected.
    let checks = [
        (Vec3::new(0.0, 0.5, 4.0), Vec3::new(0.0, 0.5, -4.0), false), // through the box
        (Vec3::new(0.0, 2.5, 4.0), Vec3::new(0.0, 2.5, -4.0), true),  // over everything
        (Vec3::new(-6.0, 0.5, -1.0), Vec3::new(0.0, 0.5, -1.0), false), // through the crate
        (Vec3::new(-6.0, 1.5, -1.0), Vec3::new(0.0, 1.5, -1.0), true), // over the small crate
    ];
    let sight_rays: Vec<ksrt::GpuRay> = checks
        .iter()
        .map(|(from, to, _)| ray(*from, (*to - *from).normalize(), from.distance(*to)))
        .collect();

    // One buffer of rays in and one of hits out per batch; both batches in one GPU task.
    let rays_in = |rays: &[ksrt::GpuRay]| {
        device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("rays"),
            contents: bytemuck::cast_slice(rays),
            usage: wgpu::BufferUsages::STORAGE,
        })
    };
    let hits_out = |count: usize| {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("hits"),
            size: (count * std::mem::size_of::<ksrt::GpuHit>()) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        })
    };
    let (pick_hits, sight_hits) = (hits_out(picks.len()), hits_out(checks.len()));
    let mut tasks = ctx.create_task_container();
    let pick = ksrt::TraceRaysTask::new(rays_in(&pick_rays), picks.len() as u32, pick_hits.clone());
    tasks.schedule_render_task(ksrt::RenderTask::TraceRays(pick));
    let mut sight = ksrt::TraceRaysTask::new(
        rays_in(&sight_rays),
        checks.len() as u32,
        sight_hits.clone(),
    );
    sight.query = ksrt::RayQuery::AnyHit;
    tasks.schedule_render_task(ksrt::RenderTask::TraceRays(sight));
    let mut encoder = device.create_command_encoder(&Default::default());
    let task = ctx.build_gpu_task(tasks, &mut encoder)?;
    queue.submit([encoder.finish()]);

    let read_hits = |buffer: &wgpu::Buffer| -> AnyResult<Vec<ksrt::GpuHit>> {
        let bytes = common::read_buffer(&device, &queue, buffer, buffer.size())?;
        Ok(bytemuck::pod_collect_to_vec(&bytes))
    };
    let (pick_hits, sight_hits) = (read_hits(&pick_hits)?, read_hits(&sight_hits)?);
    ctx.mark_gpu_task_completed(task)?;

    let mut wrong = 0;
    for ((at, expected), hit) in picks.iter().zip(&pick_hits) {
        let got = object_of(hit);
        let verdict = if got == *expected {
            String::new()
        } else {
            wrong += 1;
            format!("  <-- WRONG, expected {expected}")
        };
        let detail = if hit.is_hit() {
            format!(" (t = {:.2}, triangle {})", hit.t, hit.primitive)
        } else {
            String::new()
        };
        println!("pick towards {at}: {got}{detail}{verdict}");
    }
    for ((from, to, expected), hit) in checks.iter().zip(&sight_hits) {
        let visible = !hit.is_hit();
        let ok = visible == *expected;
        wrong += usize::from(!ok);
        let seen = if visible { "visible" } else { "blocked" };
        println!(
            "{from} sees {to}: {seen}{}",
            if ok { "" } else { "  <-- WRONG" }
        );
    }
    if wrong > 0 {
        return Err(format!("{wrong} wrong answers").into());
    }
    println!(
        "all {} queries answered as expected",
        picks.len() + checks.len()
    );
    Ok(())
}

/// A ray from `origin` along unit `dir`, accepting hits up to `t_max`.
fn ray(origin: Vec3, dir: Vec3, t_max: f32) -> ksrt::GpuRay {
    ksrt::GpuRay {
        origin: origin.into(),
        t_min: 0.0,
        dir: dir.into(),
        t_max,
    }
}
