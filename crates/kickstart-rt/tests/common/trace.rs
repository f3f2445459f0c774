//! Helpers of the trace-task tests: G-buffers of known surfaces (world-position depth, vector
//! normals) and reading Rgba32Float outputs back.

use glam::{Mat4, Vec3};
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
