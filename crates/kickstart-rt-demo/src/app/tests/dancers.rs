//! The built-in dancers played: the renderer's vertex buffers hold the CPU skinning of the pose
//! asked for, and the sun's shadow on the floor moves when the time does — in the SDK's trace,
//! which agrees on the floor with a CPU trace of the same pose (so the BVHs were refitted), and
//! in the rasteriser's shadow-mapped direct light.

use glam::Vec3;
use kickstart_rt::cpu::Ray;
use kickstart_rt_renderer::frame::Effects;
use kickstart_rt_renderer::scene::cutout::CutoutCaster;
use kickstart_rt_renderer::scene::{character, Light, Scene};

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
            size: SIZE,
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

/// The size of the renders.
const SIZE: (u32, u32) = (160, 90);

/// Per pixel, traced on the CPU through the scene posed at `time`: `None` where the pixel's
/// centre does not see the floor, else whether the floor point there is in the sun's shadow.
fn cpu_floor_shadow(scene: &Scene, time: f32) -> Vec<Option<bool>> {
    let posed = scene.posed(time);
    let caster = CutoutCaster::new(&posed);
    let floor = posed
        .instances
        .iter()
        .position(|i| posed.meshes[i.mesh].deform.is_rigid())
        .unwrap_or_else(|| panic!("no floor"));
    let Some(Light::Sun { direction, .. }) = posed.lights.first().copied() else {
        panic!("the dancers have a sun");
    };
    let camera = scene.camera_or_default(None);
    let (fwd, right, up, tan) = camera.basis();
    let aspect = SIZE.0 as f32 / SIZE.1 as f32;
    let ray = |origin: Vec3, dir: Vec3| Ray {
        origin,
        dir,
        t_min: 0.0,
        t_max: f32::INFINITY,
    };
    (0..SIZE.0 * SIZE.1)
        .map(|k| {
            let (x, y) = ((k % SIZE.0) as f32 + 0.5, (k / SIZE.0) as f32 + 0.5);
            let u = (x / SIZE.0 as f32 * 2.0 - 1.0) * tan * aspect;
            let v = (1.0 - y / SIZE.1 as f32 * 2.0) * tan;
            let dir = (fwd + right * u + up * v).normalize();
            let hit = caster
                .bvh
                .closest_hit(&caster.triangles, &ray(camera.eye, dir))?;
            let (instance, _) = caster.locate(hit.primitive)?;
            if instance != floor {
                return None;
            }
            let at = camera.eye + dir * hit.t + Vec3::Y * 1e-3;
            let sun = ray(at, -direction.normalize());
            Some(caster.bvh.closest_hit(&caster.triangles, &sun).is_some())
        })
        .collect()
}

#[test]
fn the_shadows_on_the_floor_follow_the_dance() {
    let scene = dancers();
    let times = [0.0, character::PERIOD * 0.3];
    let mut floor_shadows = Vec::new();
    let mut directs = Vec::new();
    for t in times {
        let (sdk, direct) = shadow_at(&scene, t);
        let cpu = cpu_floor_shadow(&scene, t);
        // On the floor, the SDK's traced shadow (the refitted BVHs) agrees with the CPU's
        // trace of the same pose, but for pixels at a shadow's edge (camera jitter).
        let floor: Vec<(bool, bool)> = cpu
            .iter()
            .zip(&sdk)
            .filter_map(|(c, s)| c.map(|c| (c, *s)))
            .collect();
        let shadowed = floor.iter().filter(|(c, _)| *c).count();
        let disagree = floor.iter().filter(|(c, s)| c != s).count();
        assert!(shadowed > 40, "t = {t}: {shadowed} floor pixels in shadow");
        assert!(
            disagree * 5 < shadowed,
            "t = {t}: the SDK and the CPU disagree at {disagree} of {} floor pixels ({shadowed} in shadow)",
            floor.len()
        );
        floor_shadows.push(cpu);
        directs.push(direct);
    }
    // The floor's shadow moved between the two times...
    let moved = floor_shadows[0]
        .iter()
        .zip(&floor_shadows[1])
        .filter(|(a, b)| matches!((a, b), (Some(x), Some(y)) if x != y))
        .count();
    assert!(
        moved > 20,
        "the shadow on the floor moved at {moved} pixels only"
    );
    // ...and the shadow-mapped direct light with it.
    let changed = directs[0]
        .iter()
        .zip(&directs[1])
        .filter(|(x, y)| (x[0] - y[0]).abs() > 0.05)
        .count();
    assert!(
        changed > 20,
        "the rasterised light changed at {changed} pixels only"
    );
}
