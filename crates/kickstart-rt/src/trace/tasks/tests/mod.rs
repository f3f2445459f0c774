//! The trace passes against analytic answers: G-buffers of known surfaces (world-position depth,
//! vector normals), scenes packed by `TestScene`, outputs read back and compared with closed-form
//! AO, sphere shadows, penumbra widths and per-light visibility computed on the CPU, and the
//! radiance passes against a stand-in cache. One file per theme; the G-buffer, scene and
//! read-back helpers they share are here.

mod ao;
mod ggx;
mod passes;
mod radiance;
mod shadows;

use super::*;
use crate::gpu::testing;
use crate::trace::test_scene::{cube, TestScene, Tri};
use glam::{Mat4, Vec3};

/// A G-buffer texel: world position and unit normal, or `None` (nothing rendered).
type Texel = Option<(Vec3, Vec3)>;

/// `N × N` texels at random points of the cube of half-size `half` about the origin, each with a
/// random unit normal (drawn point then normal, texel by texel).
fn random_texels(rng: &mut testing::Rng, half: f32) -> Vec<Texel> {
    (0..N * N)
        .map(|_| {
            let p = Vec3::new(
                rng.range(-half, half),
                rng.range(-half, half),
                rng.range(-half, half),
            );
            let n = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            )
            .try_normalize()
            .unwrap_or(Vec3::Y);
            Some((p, n))
        })
        .collect()
}

/// The world-position depth and vector normal inputs of `w × h` texels from `f(x, y)`.
fn gbuffer(w: u32, h: u32, f: impl Fn(u32, u32) -> Texel) -> (DepthInput, NormalInput) {
    let mut pos = Vec::new();
    let mut nor = Vec::new();
    for y in 0..h {
        for x in 0..w {
            match f(x, y) {
                Some((p, n)) => {
                    pos.extend_from_slice(&[p.x, p.y, p.z, 1.0]);
                    nor.extend_from_slice(&[n.x, n.y, n.z, 0.0]);
                }
                None => {
                    pos.extend_from_slice(&[f32::NAN; 4]);
                    nor.extend_from_slice(&[0.0; 4]);
                }
            }
        }
    }
    let f = wgpu::TextureFormat::Rgba32Float;
    (
        DepthInput {
            texture: testing::texture_with(f, w, h, bytemuck::cast_slice(&pos)),
            depth_type: DepthType::RgbWorldSpace,
        },
        NormalInput {
            texture: testing::texture_with(f, w, h, bytemuck::cast_slice(&nor)),
            normal_type: NormalType::RgbVector,
            normal_to_world: Mat4::IDENTITY,
        },
    )
}

/// The common inputs of a G-buffer seen from `eye` (only the eye matters with world-position
/// depth: it gives the view distance).
fn common(g: (DepthInput, NormalInput), eye: Vec3) -> TraceTaskCommon {
    let mut c = TraceTaskCommon::new(g.0, g.1);
    let up = if eye.normalize().y.abs() > 0.9 {
        Vec3::NEG_Z
    } else {
        Vec3::Y
    };
    c.view.world_to_view = Mat4::look_at_rh(eye, Vec3::ZERO, up);
    assert!(c.view.world_to_view.is_finite());
    c.view.view_to_clip = Mat4::perspective_rh(1.0, 1.0, 0.1, 100.0);
    c.ray_offset.offset_type = RayOffsetType::WorldPosition;
    c
}

/// A `w × h` Rgba32Float output filled with `fill`.
fn output(w: u32, h: u32, fill: f32) -> TextureInput {
    let data = vec![fill; (w * h * 4) as usize];
    testing::texture_with(
        wgpu::TextureFormat::Rgba32Float,
        w,
        h,
        bytemuck::cast_slice(&data),
    )
}

/// Reads an Rgba32Float texture back.
fn read(t: &TextureInput) -> Vec<[f32; 4]> {
    let g = testing::gpu();
    let tex = t.texture();
    let (w, h) = (tex.width(), tex.height());
    let row = (w * 16).div_ceil(256) * 256;
    let buf = testing::buffer(row as u64 * h as u64);
    let mut enc = g.device.create_command_encoder(&Default::default());
    enc.copy_texture_to_buffer(
        tex.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buf,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: None,
            },
        },
        tex.size(),
    );
    g.queue.submit([enc.finish()]);
    let bytes = testing::read_back(&buf, 0, row as u64 * h as u64);
    let mut out = Vec::new();
    for y in 0..h {
        let start = (y * row) as usize;
        let floats: &[f32] = bytemuck::cast_slice(&bytes[start..start + (w * 16) as usize]);
        out.extend(floats.chunks(4).map(|c| [c[0], c[1], c[2], c[3]]));
    }
    out
}

/// Records `tasks` with one set of passes and waits, on the test pass's backend.
fn run(scene: &TestScene, tasks: &[RenderTask]) {
    assert_eq!(scene.buffers().backend(), testing::backend());
    let g = testing::gpu();
    let mut passes = TracePasses::new(&g.device, &g.queue, testing::backend());
    testing::run(|rec| {
        for t in tasks {
            let job = TracePasses::job(t).expect("a trace task");
            passes.record(rec, &scene.buffers(), &[], &job);
        }
    });
}

/// A square in the plane `axis = at` of half-size `s` (both windings are hit).
fn square(axis: usize, at: f32, s: f32) -> Vec<Tri> {
    let p = |a: f32, b: f32| {
        let mut v = [0.0; 3];
        v[axis] = at;
        v[(axis + 1) % 3] = a;
        v[(axis + 2) % 3] = b;
        Vec3::from(v)
    };
    vec![
        [p(-s, -s), p(s, -s), p(s, s)],
        [p(-s, -s), p(s, s), p(-s, s)],
    ]
}

/// A UV sphere (`rings` × 2·`rings` quads).
fn sphere(centre: Vec3, r: f32, rings: u32) -> Vec<Tri> {
    let seg = rings * 2;
    let p = |i: u32, j: u32| {
        let th = std::f32::consts::PI * i as f32 / rings as f32;
        let ph = std::f32::consts::TAU * j as f32 / seg as f32;
        centre + r * Vec3::new(th.sin() * ph.cos(), th.cos(), th.sin() * ph.sin())
    };
    let mut t = Vec::new();
    for i in 0..rings {
        for j in 0..seg {
            t.push([p(i, j), p(i + 1, j), p(i + 1, j + 1)]);
            t.push([p(i, j), p(i + 1, j + 1), p(i, j + 1)]);
        }
    }
    t
}

const N: u32 = 32;

/// Floor texels: y = 0, normal +y, x and z spanning [-2, 2] over the N×N grid.
fn floor(x: u32, y: u32) -> Texel {
    let f = |i: u32| -2.0 + 4.0 * (i as f32 + 0.5) / N as f32;
    Some((Vec3::new(f(x), 0.0, f(y)), Vec3::Y))
}
