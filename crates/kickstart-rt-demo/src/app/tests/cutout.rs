//! Cutouts end to end on the built-in grove. `ksrt render --scene grove` runs; and where a pixel
//! looks through a leaf card's transparent texel, the raster G-buffer, the SDK's primary-ray
//! debug view and an SDK ray batch all see the floor behind it (and the card where its texel is
//! opaque), while the sun's shadow map and the SDK's shadow trace let the sun through the same
//! holes onto the floor. The pixels are picked on the CPU ([`CutoutCaster`]), each away from
//! texel and pixel edges, so the micro-maps' resolution and the camera jitter cannot move them.

use glam::{Vec3, Vec4};
use kickstart_rt as ksrt;
use kickstart_rt::cpu::{Hit, Ray};
use kickstart_rt_renderer::scene::cutout::{texel_alpha, CutoutCaster};
use kickstart_rt_renderer::scene::{grove, Camera, Light, Scene};
use kickstart_rt_renderer::sdk_glue::{self as glue, GpuHit, GpuRay, Query};
use kickstart_rt_renderer::upload;
use wgpu::util::DeviceExt;

use crate::app::frames::RendererExt;
use crate::app::readback::read_texture;
use crate::app::{gpu, testing};

/// The size `ksrt render` is run at here, and the agreement test's view.
const SIZE: (u32, u32) = (160, 90);

/// `ksrt render --scene grove --size 160x90 --frames 2`, as the command line runs it: every
/// image is written.
#[test]
fn render_command_writes_every_image_of_the_grove() {
    let out = testing::temp_dir("grove-render");
    let args = crate::app::render::RenderArgs {
        size: Some("160x90".into()),
        out: out.clone(),
        debug_view: None,
        scene: "grove".into(),
        scenes: None,
        camera: None,
        frames: Some(2),
        effects: "all".into(),
        seed: 7,
        hdr: false,
        no_reference: false,
        json: None,
        memory_csv: None,
        frames_in_flight: 1,
        preset: ksrt::Preset::Quality,
    };
    crate::app::render::run_at(args, 0.0)
        .unwrap_or_else(|e| panic!("ksrt render --scene grove: {e}"));
    for name in [
        "final",
        "shadow",
        "cpu-reference",
        "debug-hit-t",
        "debug-mesh-color",
    ] {
        let img = image::open(out.join(format!("{name}.png")))
            .unwrap_or_else(|e| panic!("{name}.png: {e}"));
        assert_eq!((img.width(), img.height()), SIZE, "{name}.png");
    }
}

/// A pixel the CPU picked: where its centre's primary ray first meets a surface when cutouts are
/// ignored (`first`), and where it stops when they are not (`stop`).
#[derive(Debug, Clone, Copy)]
struct Pixel {
    x: u32,
    y: u32,
    first: f32,
    stop: f32,
}

/// The direction through point `(px, py)` of the image (pixels, from the top left corner).
fn dir_at(camera: &Camera, px: f32, py: f32) -> Vec3 {
    let (fwd, right, up, tan) = camera.basis();
    let aspect = SIZE.0 as f32 / SIZE.1 as f32;
    let u = (px / SIZE.0 as f32 * 2.0 - 1.0) * tan * aspect;
    let v = (1.0 - py / SIZE.1 as f32 * 2.0) * tan;
    (fwd + right * u + up * v).normalize()
}

fn ray(origin: Vec3, dir: Vec3) -> Ray {
    Ray {
        origin,
        dir,
        t_min: 0.0,
        t_max: f32::INFINITY,
    }
}

/// The name of the mesh `hit` is on.
fn mesh_of<'a>(scene: &'a Scene, caster: &CutoutCaster, hit: Option<Hit>) -> &'a str {
    hit.and_then(|h| caster.locate(h.primitive))
        .map_or("sky", |(instance, _)| {
            scene.meshes[scene.instances[instance].mesh].name.as_str()
        })
}

/// The alphas of the texture of `hit`'s mesh at the hit and half a texel away from it in the
/// eight directions.
fn texel_block(scene: &Scene, caster: &CutoutCaster, hit: &Hit) -> Vec<f32> {
    let Some((instance, triangle)) = caster.locate(hit.primitive) else {
        return Vec::new();
    };
    let mesh = &scene.meshes[scene.instances[instance].mesh];
    let Some(tex) = scene.mask_texture(mesh) else {
        return Vec::new();
    };
    let uv = mesh.uv_at(triangle, hit.u, hit.v);
    let (w, h) = tex.image.dimensions();
    let mut out = Vec::new();
    for dy in [-0.5, 0.0, 0.5] {
        for dx in [-0.5, 0.0, 0.5] {
            let at = [uv[0] + dx / w as f32, uv[1] + dy / h as f32];
            out.push(texel_alpha(&tex.image, at));
        }
    }
    out
}

/// The pixels whose centre and four points 0.45 pixel away (the jitter stays within half a
/// pixel) all look through a canopy card at the floor (`holes`), or all stop on a canopy card
/// (`leaves`); in both, the first card is transparent (or opaque) half a texel around the
/// centre's hit too: a margin for the micro-maps, whose micro-triangles are under a texel.
fn pick_pixels(scene: &Scene, caster: &CutoutCaster, camera: &Camera) -> (Vec<Pixel>, Vec<Pixel>) {
    let (mut holes, mut leaves) = (Vec::new(), Vec::new());
    let offsets = [
        (0.0, 0.0),
        (-0.45, 0.0),
        (0.45, 0.0),
        (0.0, -0.45),
        (0.0, 0.45),
    ];
    for y in 0..SIZE.1 {
        for x in 0..SIZE.0 {
            let (mut hole, mut leaf) = (true, true);
            for (dx, dy) in offsets {
                let r = ray(
                    camera.eye,
                    dir_at(camera, x as f32 + 0.5 + dx, y as f32 + 0.5 + dy),
                );
                let first = caster.bvh.closest_hit(&caster.triangles, &r);
                let stop = caster.closest_hit(&r);
                let (first, stop) = (mesh_of(scene, caster, first), mesh_of(scene, caster, stop));
                hole &= first == "canopy" && stop == "floor";
                leaf &= stop == "canopy";
            }
            let r = ray(camera.eye, dir_at(camera, x as f32 + 0.5, y as f32 + 0.5));
            let (Some(first), Some(stop)) = (
                caster.bvh.closest_hit(&caster.triangles, &r),
                caster.closest_hit(&r),
            ) else {
                continue;
            };
            let block = texel_block(scene, caster, &first);
            let p = Pixel {
                x,
                y,
                first: first.t,
                stop: stop.t,
            };
            if hole && !block.is_empty() && block.iter().all(|&a| a == 0.0) {
                holes.push(p);
            } else if leaf && !block.is_empty() && block.iter().all(|&a| a == 1.0) {
                leaves.push(p);
            }
        }
    }
    (holes, leaves)
}

/// Traces `rays` as one closest-hit ray batch on `ctx` and reads the hits back.
fn trace_batch(ctx: &ksrt::ExecuteContext, rays: &[GpuRay]) -> Vec<GpuHit> {
    let (device, queue) = testing::device();
    let bytes = std::mem::size_of_val(rays) as u64;
    let ray_buffer = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("grove rays"),
        contents: bytemuck::cast_slice(rays),
        usage: wgpu::BufferUsages::STORAGE,
    });
    let hit_buffer = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("grove hits"),
        size: bytes,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let readback = gpu::readback_buffer(device, bytes);
    let mut c = ctx.create_task_container();
    let task = glue::trace_rays_task(
        &ray_buffer,
        &hit_buffer,
        0,
        rays.len() as u32,
        Query::Closest,
    )
    .expect("ray batch task");
    c.schedule_render_task(task);
    let task = upload::submit(ctx, device, queue, c, |e| {
        e.copy_buffer_to_buffer(&hit_buffer, 0, &readback, 0, bytes)
    })
    .expect("ray batch");
    gpu::complete(ctx, device, task).expect("complete");
    gpu::map_read(device, &readback)
        .expect("read hits")
        .chunks_exact(std::mem::size_of::<GpuHit>())
        .map(bytemuck::pod_read_unaligned::<GpuHit>)
        .collect()
}

/// The world height of the G-buffer's surface at pixel `(x, y)` of `depth` (the unjittered
/// view: the jitter moves it by under half a pixel).
fn gbuffer_height(scene: &Scene, camera: &Camera, depth: f32, (x, y): (u32, u32)) -> f32 {
    let (near, far) = kickstart_rt_renderer::raster::clip_planes(camera, scene.size());
    let (view, proj) = camera.matrices(SIZE.0 as f32 / SIZE.1 as f32, near, far);
    let ndc = Vec4::new(
        (x as f32 + 0.5) / SIZE.0 as f32 * 2.0 - 1.0,
        1.0 - (y as f32 + 0.5) / SIZE.1 as f32 * 2.0,
        depth,
        1.0,
    );
    let world: Vec4 = (proj * view).inverse() * ndc;
    world.y / world.w
}

#[test]
fn grove_shows_the_floor_through_the_leaf_holes_in_the_gbuffer_and_the_traces() {
    let scene = grove::grove();
    let camera = scene.camera_or_default(None);
    let caster = CutoutCaster::new(&scene);
    let (holes, leaves) = pick_pixels(&scene, &caster, &camera);
    eprintln!("{} hole pixels, {} leaf pixels", holes.len(), leaves.len());
    assert!(
        holes.len() >= 10 && leaves.len() >= 20,
        "{} / {}",
        holes.len(),
        leaves.len()
    );
    let (device, queue) = testing::device();
    let opts = crate::app::frames::renderer_options(SIZE);
    let mut r = crate::app::frames::new_renderer(device, queue, &scene, &opts).expect("renderer");
    for _ in 0..2 {
        r.render_frame(device, queue, &camera, false)
            .expect("frame");
    }
    let depth = read_texture(device, queue, &r.main.depth).expect("depth");
    let hit_t = r
        .trace_debug_view(device, queue, ksrt::DebugOutputType::HitT)
        .expect("hit-t view");
    let rays: Vec<GpuRay> = holes
        .iter()
        .chain(&leaves)
        .map(|p| GpuRay {
            origin: camera.eye.to_array(),
            t_min: 0.0,
            dir: camera.primary_dir(p.x, p.y, SIZE.0, SIZE.1).to_array(),
            t_max: f32::INFINITY,
        })
        .collect();
    let hits = trace_batch(&r.sdk.ctx, &rays);
    let at = |p: &Pixel| (p.y * SIZE.0 + p.x) as usize;
    for (p, h) in holes.iter().zip(&hits) {
        // The floor is at y = 0; the lowest card edge is about a metre up.
        let y = gbuffer_height(&scene, &camera, depth.data[at(p)][0], (p.x, p.y));
        assert!(
            y.abs() < 0.1,
            "hole {p:?}: the G-buffer is at height {y}, not the floor"
        );
        let debug = hit_t.data[at(p)];
        assert!(
            debug[3] > 0.5 && (debug[0] - p.stop).abs() < 0.05 * p.stop,
            "hole {p:?}: the debug view hits at {debug:?}"
        );
        assert!(
            h.is_hit() && (h.t - p.stop).abs() <= 1e-3 * p.stop,
            "hole {p:?}: the ray batch hits at {h:?}"
        );
    }
    for (p, h) in leaves.iter().zip(&hits[holes.len()..]) {
        let y = gbuffer_height(&scene, &camera, depth.data[at(p)][0], (p.x, p.y));
        assert!(
            y > 0.5,
            "leaf {p:?}: the G-buffer is at height {y}, not on the card"
        );
        assert!(
            h.is_hit() && (h.t - p.first).abs() <= 1e-3 * p.first,
            "leaf {p:?}: the ray batch hits at {h:?}"
        );
    }
    check_sunlight_through_holes(&scene, &caster, &camera, &r);
}

/// Over the floor pixels whose sunlight the CPU finds the same at five points of the pixel, the
/// shadow map (in the direct light) and the SDK's raw shadow trace agree with the CPU on lit or
/// shadowed for at least 90% of them, and for 80% of those lit through a canopy card's holes
/// (which a shadow map or trace without cutouts would darken).
fn check_sunlight_through_holes(
    scene: &Scene,
    caster: &CutoutCaster,
    camera: &Camera,
    r: &kickstart_rt_renderer::renderer::Renderer,
) {
    let (device, queue) = testing::device();
    let Some(Light::Sun { direction, .. }) = scene.lights.first().copied() else {
        panic!("the grove has a sun");
    };
    let to_sun = -direction;
    assert!(r.sdk.produced().shadow.0, "the shadow trace ran");
    let direct = read_texture(device, queue, &r.main.direct).expect("direct");
    let shadow = read_texture(device, queue, &r.sdk.outputs.shadow).expect("shadow");
    // (pixel index, lit by the CPU, lit through a hole)
    let mut floor = Vec::new();
    let offsets = [
        (0.0, 0.0),
        (-0.45, 0.0),
        (0.45, 0.0),
        (0.0, -0.45),
        (0.0, 0.45),
    ];
    for y in 0..SIZE.1 {
        for x in 0..SIZE.0 {
            let mut lit = Vec::new();
            let mut blocked_opaque = true;
            for (dx, dy) in offsets {
                let d = dir_at(camera, x as f32 + 0.5 + dx, y as f32 + 0.5 + dy);
                let hit = caster.closest_hit(&ray(camera.eye, d));
                if mesh_of(scene, caster, hit) != "floor" {
                    break;
                }
                let p = camera.eye + d * hit.map_or(0.0, |h| h.t) + Vec3::Y * 1e-3;
                lit.push(!caster.any_hit(&ray(p, to_sun)));
                blocked_opaque &= caster.bvh.any_hit(&caster.triangles, &ray(p, to_sun));
            }
            if lit.len() == offsets.len() && lit.iter().all(|&l| l == lit[0]) {
                floor.push(((y * SIZE.0 + x) as usize, lit[0], lit[0] && blocked_opaque));
            }
        }
    }
    let brightest = floor
        .iter()
        .map(|f| direct.data[f.0][1])
        .fold(0.0f32, f32::max);
    let map_lit = |k: usize| direct.data[k][1] > 0.5 * brightest;
    // The raw trace: R < 0 where the light is visible.
    let sdk_lit = |k: usize| shadow.data[k][0] < 0.0;
    let share = |set: &[&(usize, bool, bool)], lit: &dyn Fn(usize) -> bool| {
        set.iter().filter(|f| lit(f.0) == f.1).count() as f32 / set.len().max(1) as f32
    };
    let all: Vec<_> = floor.iter().collect();
    let through: Vec<_> = floor.iter().filter(|f| f.2).collect();
    eprintln!(
        "{} floor pixels, {} lit through holes",
        all.len(),
        through.len()
    );
    assert!(
        through.len() >= 10,
        "only {} floor pixels lit through holes",
        through.len()
    );
    for (name, lit) in [
        ("shadow map", &map_lit as &dyn Fn(usize) -> bool),
        ("SDK shadow trace", &sdk_lit),
    ] {
        let (a, t) = (share(&all, lit), share(&through, lit));
        eprintln!("{name}: {a} of the floor, {t} of the lit-through-holes agree with the CPU");
        assert!(
            a >= 0.9 && t >= 0.8,
            "{name}: agreement {a}, through holes {t}"
        );
    }
}
