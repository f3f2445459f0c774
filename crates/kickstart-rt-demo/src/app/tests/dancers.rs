//! The built-in dancers played: the renderer's vertex buffers hold the CPU skinning of the pose
//! asked for, and the sun's shadow on the floor — in the SDK's trace (refitted BVHs) and in the
//! rasteriser's shadow-mapped direct light — moves when the time does.

use kickstart_rt_renderer::frame::Effects;
use kickstart_rt_renderer::scene::{character, Scene};

use crate::app::frames::RendererExt;
use crate::app::lit::{self, LitOptions};
use crate::app::{frames, scenes, testing};

fn dancers() -> Scene {
    scenes::dancers().unwrap_or_else(|e| panic!("{e}"))
}

/// The `f32` triples of `buffer`, read back.
fn read_positions(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    buffer: &wgpu::Buffer,
) -> Vec<[f32; 3]> {
    let staging = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("vertices read back"),
        size: buffer.size(),
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    let mut encoder = device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(buffer, 0, &staging, 0, buffer.size());
    queue.submit([encoder.finish()]);
    staging.slice(..).map_async(wgpu::MapMode::Read, |r| {
        r.unwrap_or_else(|e| panic!("map: {e}"))
    });
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .unwrap_or_else(|e| panic!("{e}"));
    let bytes = staging
        .slice(..)
        .get_mapped_range()
        .unwrap_or_else(|e| panic!("{e:?}"))
        .to_vec();
    bytemuck::cast_slice(&bytes).to_vec()
}

#[test]
fn the_vertex_buffers_hold_the_cpu_skinning_of_each_time() {
    let (device, queue) = testing::device();
    let scene = dancers();
    let mut opts = frames::renderer_options((32, 18));
    opts.effects = Effects::parse("none").unwrap_or_else(|e| panic!("{e}"));
    opts.prepare_pipelines = false;
    let mut r =
        frames::new_renderer(device, queue, &scene, &opts).unwrap_or_else(|e| panic!("{e}"));
    assert!(r.is_animated());
    let camera = scene.camera_or_default(None);
    let mesh = scene.instances[scene.rigs[1].instance].mesh;
    let mut seen = Vec::new();
    for t in [0.0, 0.45] {
        r.set_time(t);
        r.render_frame(device, queue, &camera, false)
            .unwrap_or_else(|e| panic!("{e}"));
        let buffer = r.vertex_buffer(mesh).unwrap_or_else(|| panic!("no buffer"));
        let gpu = read_positions(device, queue, buffer);
        assert_eq!(gpu, scene.posed(t).meshes[mesh].positions, "t = {t}");
        seen.push(gpu);
    }
    assert_ne!(seen[0], seen[1]);
}

/// Pixels whose raw SDK shadow says "in shadow" (a hit distance > 0) at `time`, and the
/// rasteriser's direct light, of a small render of the dancers.
fn shadow_at(scene: &Scene, time: f32) -> (Vec<bool>, Vec<[f32; 4]>) {
    let (device, queue) = testing::device();
    let result = lit::render(
        device,
        queue,
        scene,
        &scene.camera_or_default(None),
        &LitOptions {
            size: (160, 90),
            frames: 1,
            effects: Effects::parse("none,shadow").unwrap_or_else(|e| panic!("{e}")),
            seed: 3,
            preset: kickstart_rt::Preset::Quality,
            progress: false,
            gpu_timing: false,
            frames_in_flight: 1,
            debug_views: Vec::new(),
            time,
        },
    )
    .unwrap_or_else(|e| panic!("render at {time} s: {e}"));
    let channel = |name: &str| {
        result
            .channel(name)
            .unwrap_or_else(|| panic!("no {name} channel"))
            .texels
            .data
            .clone()
    };
    let shadowed = channel("shadow").iter().map(|t| t[0] > 0.0).collect();
    (shadowed, channel("direct"))
}

#[test]
fn the_shadows_on_the_floor_follow_the_dance() {
    let scene = dancers();
    let (a, direct_a) = shadow_at(&scene, 0.0);
    let (b, direct_b) = shadow_at(&scene, character::PERIOD * 0.3);
    let shadowed = a.iter().filter(|&&s| s).count();
    assert!(shadowed > 50, "only {shadowed} shadowed pixels at t = 0");
    let moved = a.iter().zip(&b).filter(|(x, y)| x != y).count();
    assert!(moved > 20, "the traced shadow moved at {moved} pixels only");
    let changed = direct_a
        .iter()
        .zip(&direct_b)
        .filter(|(x, y)| (x[0] - y[0]).abs() > 0.05)
        .count();
    assert!(
        changed > 20,
        "the rasterised light changed at {changed} pixels only"
    );
}
