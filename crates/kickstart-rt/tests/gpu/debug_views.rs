//! Primary-ray debug views (HitT, Barycentrics, RandomMeshColor) through a trace task's debug
//! parameters, checked pixel by pixel against an analytic camera and the CPU triangle test.

use crate::common;
use common::rt::*;
use common::*;
use glam::{Affine3A, Mat4, Vec3, Vec4};
use kickstart_rt::*;
use wgpu::{TextureFormat as F, TextureUsages as U};

const W: u32 = 32;
const H: u32 = 24;

/// Two unit quads: instance A at z = 0 spanning x, y in [-1, 1]; instance B at z = -1, right of
/// A (x in [1.5, 3.5]).
fn scene() -> (ExecuteContext, InstanceHandle, InstanceHandle) {
    let ctx = context(4);
    let quad = Mesh {
        positions: vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        indices: vec![0, 1, 2, 0, 2, 3],
    };
    let g = ctx.create_geometry_handle();
    let (a, b) = (ctx.create_instance_handle(), ctx.create_instance_handle());
    let mut c = ctx.create_task_container();
    schedule_mesh(&mut c, g, "quad", &quad);
    register_instance(&mut c, a, g, Affine3A::IDENTITY);
    register_instance(
        &mut c,
        b,
        g,
        Affine3A::from_translation(Vec3::new(2.5, 0.0, -1.0)),
    );
    c.schedule_bvh_task(BvhBuildTask::default());
    build_submit_complete(&ctx, c);
    (ctx, a, b)
}

fn view(reverse_z: bool) -> ViewInfo {
    let eye = Vec3::new(0.5, 0.2, 3.0);
    let aspect = W as f32 / H as f32;
    ViewInfo {
        world_to_view: Mat4::look_at_rh(eye, Vec3::new(0.5, 0.2, 0.0), Vec3::Y),
        view_to_clip: if reverse_z {
            Mat4::perspective_infinite_reverse_rh(1.2, aspect, 0.1)
        } else {
            Mat4::perspective_rh(1.2, aspect, 0.1, 100.0)
        },
        ..Default::default()
    }
}

/// Renders `kind` into a W×H Rgba32Float texture (within `viewport`) and reads it back.
fn render(
    ctx: &ExecuteContext,
    v: ViewInfo,
    kind: DebugOutputType,
    viewport: Option<Viewport>,
) -> Vec<[f32; 4]> {
    let out_tex = gpu().device.create_texture(&wgpu::TextureDescriptor {
        label: None,
        size: wgpu::Extent3d {
            width: W,
            height: H,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: F::Rgba32Float,
        usage: U::STORAGE_BINDING | U::COPY_SRC,
        view_formats: &[],
    });
    let mut common = TraceTaskCommon::new(
        DepthInput {
            texture: texture(F::R32Float, W, H, U::TEXTURE_BINDING),
            depth_type: DepthType::RClipSpace,
        },
        NormalInput {
            texture: texture(F::Rgba8Unorm, W, H, U::TEXTURE_BINDING),
            normal_type: NormalType::RgbNormalizedVector,
            normal_to_world: Mat4::IDENTITY,
        },
    );
    common.view = v;
    common.viewport = viewport;
    common.debug_parameters.debug_output_type = kind;
    let mut c = ctx.create_task_container();
    c.schedule_render_task(RenderTask::TraceAmbientOcclusion(
        TraceAmbientOcclusionTask {
            common,
            output: out_tex.create_view(&Default::default()),
            ao_radius: 1.0,
        },
    ));
    build_submit_complete(ctx, c);
    let buf = gpu().device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: (W * 16 * H) as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let mut e = encoder();
    e.copy_texture_to_buffer(
        out_tex.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buf,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(W * 16),
                rows_per_image: Some(H),
            },
        },
        out_tex.size(),
    );
    submit(e);
    bytemuck::pod_collect_to_vec(&read_buffer(&buf))
}

/// The world-space ray of pixel (x, y): from the eye through the pixel centre.
fn pixel_ray(v: &ViewInfo, x: u32, y: u32) -> (Vec3, Vec3) {
    let inv = (v.view_to_clip * v.world_to_view).inverse();
    let ndc = glam::Vec2::new(
        (x as f32 + 0.5) / W as f32 * 2.0 - 1.0,
        1.0 - (y as f32 + 0.5) / H as f32 * 2.0,
    );
    let p = inv * Vec4::new(ndc.x, ndc.y, 0.5, 1.0);
    let p = p.truncate() / p.w;
    let eye = v.world_to_view.inverse().transform_point3(Vec3::ZERO);
    (eye, (p - eye).normalize())
}

/// The analytic hit of a pixel's ray: (instance, t, u, v) against the two quads.
fn expected(v: &ViewInfo, x: u32, y: u32, a: u32, b: u32) -> Option<(u32, f32, f32, f32)> {
    let (o, d) = pixel_ray(v, x, y);
    let quad = [
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
        Vec3::new(-1.0, 1.0, 0.0),
    ];
    let mut best: Option<(u32, f32, f32, f32)> = None;
    for (inst, off) in [(a, Vec3::ZERO), (b, Vec3::new(2.5, 0.0, -1.0))] {
        for tri in [[0, 1, 2], [0, 2, 3]] {
            let r = kickstart_rt::cpu::Ray {
                origin: o,
                dir: d,
                t_min: 0.0,
                t_max: f32::INFINITY,
            };
            if let Some(h) = kickstart_rt::cpu::intersect_triangle(
                &r,
                quad[tri[0]] + off,
                quad[tri[1]] + off,
                quad[tri[2]] + off,
            ) {
                if best.is_none_or(|bst| h.t < bst.1) {
                    best = Some((inst, h.t, h.u, h.v));
                }
            }
        }
    }
    best
}

#[test]
fn hit_t_is_the_distance_from_the_eye_with_normal_and_reverse_z() {
    let (ctx, a, b) = scene();
    for reverse in [false, true] {
        let v = view(reverse);
        let img = render(&ctx, v, DebugOutputType::HitT, None);
        let mut hits = 0;
        for y in 0..H {
            for x in 0..W {
                let px = img[(y * W + x) as usize];
                match expected(&v, x, y, a.index(), b.index()) {
                    Some((_, t, _, _)) => {
                        hits += 1;
                        assert!(
                            (px[0] - t).abs() <= 1e-3 * t,
                            "({x},{y}) reverse {reverse}: {px:?} vs t {t}"
                        );
                        assert_eq!((px[1], px[2], px[3]), (px[0], px[0], 1.0));
                    }
                    None => assert_eq!(px, [0.0; 4], "({x},{y}) reverse {reverse} must miss"),
                }
            }
        }
        assert!(
            hits > 100 && hits < (W * H) as usize,
            "both hits and misses in view: {hits}"
        );
    }
}

#[test]
fn barycentrics_and_mesh_colours_match_the_geometry() {
    let (ctx, a, b) = scene();
    let v = view(false);
    let bary = render(&ctx, v, DebugOutputType::Barycentrics, None);
    let mesh = render(&ctx, v, DebugOutputType::RandomMeshColor, None);
    let mut colour_of = std::collections::HashMap::new();
    for y in 0..H {
        for x in 0..W {
            let i = (y * W + x) as usize;
            match expected(&v, x, y, a.index(), b.index()) {
                Some((inst, _, u, w)) => {
                    let px = bary[i];
                    assert!(
                        (px[1] - u).abs() < 2e-3
                            && (px[2] - w).abs() < 2e-3
                            && (px[0] - (1.0 - u - w)).abs() < 2e-3,
                        "({x},{y}): {px:?} vs u {u} v {w}"
                    );
                    assert_eq!(px[3], 1.0);
                    let c = mesh[i];
                    assert_eq!(c[3], 1.0);
                    let prev = colour_of.entry(inst).or_insert(c);
                    assert_eq!(*prev, c, "one colour per instance");
                }
                None => {
                    assert_eq!(bary[i], [0.0; 4]);
                    assert_eq!(mesh[i][3], 0.0);
                }
            }
        }
    }
    let (ca, cb) = (colour_of[&a.index()], colour_of[&b.index()]);
    assert_ne!(ca, cb, "instances get different colours");
    assert!(ca[..3]
        .iter()
        .chain(&cb[..3])
        .all(|c| (0.0..=1.0).contains(c)));
}

#[test]
fn debug_views_write_only_the_viewport() {
    let (ctx, _, _) = scene();
    let v = view(false);
    let vp = Viewport {
        x: 8,
        y: 4,
        width: 12,
        height: 10,
    };
    let img = render(&ctx, v, DebugOutputType::HitT, Some(vp));
    // Inside, the camera covers the viewport: its pixel (x - vp.x, y - vp.y) of a
    // vp.width × vp.height image. The expected distances come from a ray batch.
    let inv = (v.view_to_clip * v.world_to_view).inverse();
    let eye = v.world_to_view.inverse().transform_point3(Vec3::ZERO);
    let mut rays = Vec::new();
    let mut pixels = Vec::new();
    for y in 0..H {
        for x in 0..W {
            let px = img[(y * W + x) as usize];
            let inside = x >= vp.x && x < vp.x + vp.width && y >= vp.y && y < vp.y + vp.height;
            if !inside {
                assert_eq!(px, [0.0; 4], "({x},{y}) outside the viewport was written");
                continue;
            }
            let (lx, ly) = (x - vp.x, y - vp.y);
            let ndc = glam::Vec2::new(
                (lx as f32 + 0.5) / vp.width as f32 * 2.0 - 1.0,
                1.0 - (ly as f32 + 0.5) / vp.height as f32 * 2.0,
            );
            let p = inv * Vec4::new(ndc.x, ndc.y, 0.5, 1.0);
            let d = (p.truncate() / p.w - eye).normalize();
            rays.push(GpuRay {
                origin: eye.to_array(),
                t_min: 0.0,
                dir: d.to_array(),
                t_max: f32::INFINITY,
            });
            pixels.push((x, y, px));
        }
    }
    let hits = closest(&ctx, &rays);
    let mut inside_hits = 0;
    for ((x, y, px), h) in pixels.iter().zip(&hits) {
        if h.is_hit() {
            inside_hits += 1;
            assert!(
                (px[0] - h.t).abs() <= 1e-3 * h.t,
                "({x},{y}): {px:?} vs {}",
                h.t
            );
        } else {
            assert_eq!(px[3], 0.0, "({x},{y})");
        }
    }
    assert!(inside_hits > 20);
}
