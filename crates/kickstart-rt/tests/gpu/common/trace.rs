//! Helpers of the trace-task tests: G-buffers of known surfaces (world-position depth, vector
//! normals; or any depth and normal encoding of the SDK, written from analytic surfaces) and
//! reading Rgba32Float outputs back.

use glam::{DVec2, DVec3, DVec4, Mat4, Vec3};
use kickstart_rt::*;
use wgpu::{TextureFormat as F, TextureUsages as U};

/// A texture of `format` holding `data` (tightly packed), with `usage` + COPY_DST.
pub fn texture_with(format: F, w: u32, h: u32, usage: U, data: &[u8]) -> wgpu::TextureView {
    let g = super::gpu();
    let size = wgpu::Extent3d {
        width: w,
        height: h,
        depth_or_array_layers: 1,
    };
    let t = g.device.create_texture(&wgpu::TextureDescriptor {
        label: None,
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: usage | U::COPY_DST,
        view_formats: &[],
    });
    let bpp = format.block_copy_size(None).unwrap();
    g.queue.write_texture(
        t.as_image_copy(),
        data,
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(w * bpp),
            rows_per_image: Some(h),
        },
        size,
    );
    t.create_view(&Default::default())
}

/// The common inputs of a `w × h` G-buffer whose texel (x, y) is `f(x, y)` = (world position,
/// unit normal), or `None` for nothing rendered; seen from `eye`.
pub fn gbuffer_common(
    w: u32,
    h: u32,
    eye: Vec3,
    f: impl Fn(u32, u32) -> Option<(Vec3, Vec3)>,
) -> TraceTaskCommon {
    let mut pos = Vec::new();
    let mut nor = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let (p, n) = f(x, y).unwrap_or((Vec3::NAN, Vec3::ZERO));
            pos.extend_from_slice(&[p.x, p.y, p.z, 1.0]);
            nor.extend_from_slice(&[n.x, n.y, n.z, 0.0]);
        }
    }
    let depth = DepthInput {
        texture: texture_with(
            F::Rgba32Float,
            w,
            h,
            U::TEXTURE_BINDING,
            bytemuck::cast_slice(&pos),
        ),
        depth_type: DepthType::RgbWorldSpace,
    };
    let normal = NormalInput {
        texture: texture_with(
            F::Rgba32Float,
            w,
            h,
            U::TEXTURE_BINDING,
            bytemuck::cast_slice(&nor),
        ),
        normal_type: NormalType::RgbVector,
        normal_to_world: Mat4::IDENTITY,
    };
    let mut c = TraceTaskCommon::new(depth, normal);
    let up = if eye.normalize().y.abs() > 0.9 {
        Vec3::NEG_Z
    } else {
        Vec3::Y
    };
    c.view.world_to_view = Mat4::look_at_rh(eye, Vec3::ZERO, up);
    c.view.view_to_clip = Mat4::perspective_rh(1.0, w as f32 / h as f32, 0.05, 100.0);
    c.ray_offset.offset_type = RayOffsetType::WorldPosition;
    c
}

/// An Rgba32Float output (storage, copy source) of `w × h`.
pub fn output(w: u32, h: u32) -> wgpu::TextureView {
    super::texture(F::Rgba32Float, w, h, U::STORAGE_BINDING | U::COPY_SRC)
}

/// Reads an Rgba32Float texture back.
pub fn read_rgba32(t: &wgpu::TextureView) -> Vec<[f32; 4]> {
    let g = super::gpu();
    let tex = t.texture();
    let (w, h) = (tex.width(), tex.height());
    let row = (w * 16).div_ceil(256) * 256;
    let buf = g.device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: row as u64 * h as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut enc = super::encoder();
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
    super::submit(enc);
    buf.map_async(wgpu::MapMode::Read, .., |_| {});
    g.device
        .poll(wgpu::PollType::wait_indefinitely())
        .expect("poll");
    let bytes = buf.get_mapped_range(..).expect("mapped").to_vec();
    let mut out = Vec::new();
    for y in 0..h {
        let start = (y * row) as usize;
        let floats: &[f32] = bytemuck::cast_slice(&bytes[start..start + (w * 16) as usize]);
        out.extend(floats.chunks(4).map(|c| [c[0], c[1], c[2], c[3]]));
    }
    out
}

/// Runs render tasks in one GPU task and waits.
pub fn run_tasks(ctx: &ExecuteContext, tasks: Vec<RenderTask>) {
    let mut c = ctx.create_task_container();
    for t in tasks {
        c.schedule_render_task(t);
    }
    super::build_submit_complete(ctx, c);
}

/// The camera ray through the centre of pixel (x, y) of a `w × h` view, in f64: (eye, unit
/// direction). The pixel-to-NDC mapping is the documented one (x right, y down, centres at +0.5).
pub fn pixel_ray(view: &ViewInfo, w: u32, h: u32, x: u32, y: u32) -> (DVec3, DVec3) {
    let w2v = view.world_to_view.as_dmat4();
    let inv = (view.view_to_clip.as_dmat4() * w2v).inverse();
    let eye = w2v.inverse().transform_point3(DVec3::ZERO);
    let ndc = DVec2::new(
        (x as f64 + 0.5) / w as f64 * 2.0 - 1.0,
        1.0 - (y as f64 + 0.5) / h as f64 * 2.0,
    );
    let p = inv.project_point3(ndc.extend(0.5));
    (eye, (p - eye).normalize())
}

/// The NDC depth a projection gives "nothing rendered" (its far plane): 1 for normal Z, 0 for
/// reverse Z.
pub fn far_ndc(view_to_clip: Mat4) -> f32 {
    let c = view_to_clip.as_dmat4() * DVec4::new(0.0, 0.0, -1e30, 1.0);
    if (c.z / c.w).clamp(0.0, 1.0) >= 0.5 {
        1.0
    } else {
        0.0
    }
}

/// How a test G-buffer stores depth.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DepthEncoding {
    /// `RgbWorldSpace` in `Rgba32Float` (NaN where nothing was rendered).
    WorldPosition,
    /// `RClipSpace` in `R32Float` (the far plane's depth where nothing was rendered).
    ClipR32Float,
    /// `RClipSpace` in a `Depth32Float` depth buffer (written by a render pass).
    ClipDepth32Float,
}

/// The depth input of a `w × h` G-buffer whose texel i shows `positions[i]` (world space, `None`:
/// nothing rendered), seen with `view`; `depth_scale` multiplies each clip-space view distance
/// (1 for the true depth; tests use another value to make a wrong depth on purpose).
pub fn encode_depth(
    enc: DepthEncoding,
    w: u32,
    h: u32,
    view: &ViewInfo,
    positions: &[Option<DVec3>],
    depth_scale: f64,
) -> DepthInput {
    assert_eq!(positions.len(), (w * h) as usize);
    let w2v = view.world_to_view.as_dmat4();
    let world_to_clip = view.view_to_clip.as_dmat4() * w2v;
    let eye = w2v.inverse().transform_point3(DVec3::ZERO);
    let far = far_ndc(view.view_to_clip);
    let clip: Vec<f32> = positions
        .iter()
        .map(|p| match p {
            Some(p) => {
                let q = eye + (*p - eye) * depth_scale;
                world_to_clip.project_point3(q).z as f32
            }
            None => far,
        })
        .collect();
    match enc {
        DepthEncoding::WorldPosition => {
            let data: Vec<f32> = positions
                .iter()
                .flat_map(|p| match p {
                    Some(p) => {
                        let q = eye + (*p - eye) * depth_scale;
                        [q.x as f32, q.y as f32, q.z as f32, 1.0]
                    }
                    None => [f32::NAN; 4],
                })
                .collect();
            DepthInput {
                texture: texture_with(
                    F::Rgba32Float,
                    w,
                    h,
                    U::TEXTURE_BINDING,
                    bytemuck::cast_slice(&data),
                ),
                depth_type: DepthType::RgbWorldSpace,
            }
        }
        DepthEncoding::ClipR32Float => DepthInput {
            texture: texture_with(
                F::R32Float,
                w,
                h,
                U::TEXTURE_BINDING,
                bytemuck::cast_slice(&clip),
            ),
            depth_type: DepthType::RClipSpace,
        },
        DepthEncoding::ClipDepth32Float => DepthInput {
            texture: super::depth32float_texture(w, h, &clip),
            depth_type: DepthType::RClipSpace,
        },
    }
}

/// Octahedral encoding in [-1, 1]² of unit `n` (Cigolle et al. 2014; the inverse of the
/// documented decode).
pub fn oct_encode(n: DVec3) -> DVec2 {
    let p = n / (n.x.abs() + n.y.abs() + n.z.abs());
    if p.z >= 0.0 {
        p.truncate()
    } else {
        let s = DVec2::new(
            if p.x >= 0.0 { 1.0 } else { -1.0 },
            if p.y >= 0.0 { 1.0 } else { -1.0 },
        );
        (DVec2::ONE - DVec2::new(p.y.abs(), p.x.abs())) * s
    }
}

/// The texel of unit normal `n` in `ty`'s encoding (channels the type does not use hold filler).
pub fn encode_normal(ty: NormalType, n: DVec3) -> [f64; 4] {
    let o = oct_encode(n);
    let h = o * 0.5 + 0.5;
    match ty {
        NormalType::RgbVector => [n.x, n.y, n.z, 0.7],
        NormalType::RgbNormalizedVector => [n.x * 0.5 + 0.5, n.y * 0.5 + 0.5, n.z * 0.5 + 0.5, 0.7],
        NormalType::RgOctahedron => [o.x, o.y, 0.3, 0.9],
        NormalType::BaOctahedron => [0.3, 0.9, o.x, o.y],
        NormalType::RgNormalizedOctahedron => [h.x, h.y, 0.3, 0.9],
        NormalType::BaNormalizedOctahedron => [0.3, 0.9, h.x, h.y],
    }
}

/// The normal input of a `w × h` G-buffer whose texel i has the unit world normal `normals[i]`:
/// stored as `normalize(inverse(normal_to_world) · n)` in `ty`'s encoding, in `format`
/// (`Rgba32Float`, or the 8-bit `Rgba8Unorm` / `Rgba8Snorm`, rounded to nearest).
pub fn encode_normals(
    ty: NormalType,
    format: F,
    normal_to_world: Mat4,
    w: u32,
    h: u32,
    normals: &[DVec3],
) -> NormalInput {
    assert_eq!(normals.len(), (w * h) as usize);
    let inv = normal_to_world.as_dmat4().inverse();
    let texels: Vec<[f64; 4]> = normals
        .iter()
        .map(|n| encode_normal(ty, inv.transform_vector3(*n).normalize()))
        .collect();
    let bytes: Vec<u8> = match format {
        F::Rgba32Float => texels
            .iter()
            .flatten()
            .flat_map(|v| (*v as f32).to_ne_bytes())
            .collect(),
        F::Rgba8Unorm => texels
            .iter()
            .flatten()
            .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect(),
        F::Rgba8Snorm => texels
            .iter()
            .flatten()
            .map(|v| (v.clamp(-1.0, 1.0) * 127.0).round() as i8 as u8)
            .collect(),
        other => panic!("encode_normals: unsupported format {other:?}"),
    };
    NormalInput {
        texture: texture_with(format, w, h, U::TEXTURE_BINDING, &bytes),
        normal_type: ty,
        normal_to_world,
    }
}

/// Whether every pixel within `r` pixels (Chebyshev, clipped to the `w × h` image) of (x, y)
/// has the same label as (x, y): the pixel is away from the boundaries of its region.
pub fn away_from_boundaries<T: PartialEq>(
    labels: &[T],
    w: u32,
    h: u32,
    x: u32,
    y: u32,
    r: u32,
) -> bool {
    let l = &labels[(y * w + x) as usize];
    (y.saturating_sub(r)..(y + r + 1).min(h)).all(|yy| {
        (x.saturating_sub(r)..(x + r + 1).min(w)).all(|xx| labels[(yy * w + xx) as usize] == *l)
    })
}
