//! Helpers of the lighting cache tests: analytic scenes of axis-aligned quads, CPU ray casts
//! against them (the oracle for depth, lighting and what a camera sees), injection of images
//! made on the CPU, cache views read back, and an independent implementation of the documented
//! sizing formulas.
#![allow(dead_code)]

use super::rt::Mesh;
use super::*;
use glam::{Mat4, Vec2, Vec3, Vec4};
use kickstart_rt::*;
use wgpu::{TextureFormat as F, TextureUsages as U};

/// A rectangle `origin + s·a + t·b`, s, t in [0, 1] (a and b orthogonal).
#[derive(Clone, Copy, Debug)]
pub struct Rect {
    pub origin: Vec3,
    pub a: Vec3,
    pub b: Vec3,
}

impl Rect {
    /// Ray parameter of the hit with the rectangle, if any (both sides).
    pub fn hit(&self, o: Vec3, d: Vec3) -> Option<f32> {
        let n = self.a.cross(self.b);
        let den = n.dot(d);
        if den.abs() < 1e-12 {
            return None;
        }
        let t = n.dot(self.origin - o) / den;
        if t <= 0.0 {
            return None;
        }
        let p = o + d * t - self.origin;
        let s = p.dot(self.a) / self.a.length_squared();
        let u = p.dot(self.b) / self.b.length_squared();
        ((0.0..=1.0).contains(&s) && (0.0..=1.0).contains(&u)).then_some(t)
    }

    /// The rectangle as an n×n grid of quads, two triangles each. `split`: every triangle has
    /// its own three vertices (no shared indices).
    pub fn mesh(&self, n: u32, split: bool) -> Mesh {
        let mut m = Mesh::default();
        let p = |i: u32, j: u32| {
            self.origin + self.a * (i as f32 / n as f32) + self.b * (j as f32 / n as f32)
        };
        if split {
            for j in 0..n {
                for i in 0..n {
                    for v in [
                        (i, j),
                        (i + 1, j),
                        (i + 1, j + 1),
                        (i, j),
                        (i + 1, j + 1),
                        (i, j + 1),
                    ] {
                        m.indices.push(m.positions.len() as u32);
                        m.positions.push(p(v.0, v.1));
                    }
                }
            }
        } else {
            for j in 0..=n {
                for i in 0..=n {
                    m.positions.push(p(i, j));
                }
            }
            let id = |i: u32, j: u32| j * (n + 1) + i;
            for j in 0..n {
                for i in 0..n {
                    m.indices.extend([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                    m.indices.extend([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
                }
            }
        }
        m
    }
}

/// Closest hit of a ray with the scene's rectangles: (t, rect index).
pub fn cast(rects: &[Rect], o: Vec3, d: Vec3) -> Option<(f32, usize)> {
    rects
        .iter()
        .enumerate()
        .filter_map(|(i, r)| r.hit(o, d).map(|t| (t, i)))
        .min_by(|a, b| a.0.total_cmp(&b.0))
}

/// A perspective camera of a `w`×`h` image.
#[derive(Clone, Copy, Debug)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub fov_y: f32,
    pub w: u32,
    pub h: u32,
}

impl Camera {
    pub fn view(&self) -> ViewInfo {
        ViewInfo {
            world_to_view: Mat4::look_at_rh(self.eye, self.target, Vec3::Y),
            view_to_clip: Mat4::perspective_rh(
                self.fov_y,
                self.w as f32 / self.h as f32,
                0.05,
                100.0,
            ),
            ..Default::default()
        }
    }

    /// The ray through the centre of pixel (x, y): (eye, unit direction).
    pub fn ray(&self, x: u32, y: u32) -> (Vec3, Vec3) {
        let v = self.view();
        let inv = (v.view_to_clip * v.world_to_view).inverse();
        let ndc = Vec2::new(
            (x as f32 + 0.5) / self.w as f32 * 2.0 - 1.0,
            1.0 - (y as f32 + 0.5) / self.h as f32 * 2.0,
        );
        let p = inv.project_point3(ndc.extend(0.5));
        (self.eye, (p - self.eye).normalize())
    }

    /// The pixel (fractional) a world point projects to, and its NDC depth.
    pub fn project(&self, p: Vec3) -> (Vec2, f32) {
        let v = self.view();
        let c = (v.view_to_clip * v.world_to_view).project_point3(p);
        (
            Vec2::new(
                (c.x + 1.0) * 0.5 * self.w as f32,
                (1.0 - c.y) * 0.5 * self.h as f32,
            ),
            c.z,
        )
    }

    /// World hit point of every pixel (row-major), `None` where the ray misses.
    pub fn hits(&self, rects: &[Rect]) -> Vec<Option<Vec3>> {
        let mut out = Vec::new();
        for y in 0..self.h {
            for x in 0..self.w {
                let (o, d) = self.ray(x, y);
                out.push(cast(rects, o, d).map(|(t, _)| o + d * t));
            }
        }
        out
    }
}

/// A texture with `data` (4 floats per texel for Rgba32Float, 1 for R32Float).
pub fn texture_with(format: F, w: u32, h: u32, data: &[f32]) -> wgpu::TextureView {
    let g = gpu();
    let tex = g.device.create_texture(&wgpu::TextureDescriptor {
        label: None,
        size: wgpu::Extent3d {
            width: w,
            height: h,
            depth_or_array_layers: 1,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format,
        usage: U::TEXTURE_BINDING | U::COPY_DST,
        view_formats: &[],
    });
    let texel = format.block_copy_size(None).unwrap_or(4);
    g.queue.write_texture(
        tex.as_image_copy(),
        bytemuck::cast_slice(data),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(w * texel),
            rows_per_image: Some(h),
        },
        tex.size(),
    );
    tex.create_view(&Default::default())
}

/// How an injection image is made.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Depth {
    /// `RClipSpace` in an `R32Float` texture.
    Clip,
    /// `RgbWorldSpace` in an `Rgba32Float` texture.
    World,
    /// `RClipSpace` in a `Depth32Float` depth buffer (the engine's own depth attachment).
    Depth32,
}

/// An injection task of `cam`'s view of `rects`, lit by `light(point, pixel)`.
pub fn injection(
    rects: &[Rect],
    cam: &Camera,
    depth: Depth,
    light: impl Fn(Vec3, (u32, u32)) -> Vec3,
) -> DirectLightingInjectionTask {
    let hits = cam.hits(rects);
    let mut depth_data = Vec::new();
    let mut colour = Vec::new();
    for (i, h) in hits.iter().enumerate() {
        let px = (i as u32 % cam.w, i as u32 / cam.w);
        match (h, depth) {
            (Some(p), Depth::Clip | Depth::Depth32) => depth_data.push(cam.project(*p).1),
            (None, Depth::Clip | Depth::Depth32) => depth_data.push(1.0),
            (Some(p), Depth::World) => depth_data.extend([p.x, p.y, p.z, 1.0]),
            (None, Depth::World) => depth_data.extend([f32::NAN, f32::NAN, f32::NAN, 0.0]),
        }
        let c = h.map_or(Vec3::splat(100.0), |p| light(p, px));
        colour.extend(c.extend(1.0).to_array());
    }
    let (texture, depth_type) = match depth {
        Depth::Clip => (
            texture_with(F::R32Float, cam.w, cam.h, &depth_data),
            DepthType::RClipSpace,
        ),
        Depth::World => (
            texture_with(F::Rgba32Float, cam.w, cam.h, &depth_data),
            DepthType::RgbWorldSpace,
        ),
        Depth::Depth32 => (
            super::depth32float_texture(cam.w, cam.h, &depth_data),
            DepthType::RClipSpace,
        ),
    };
    let mut t = DirectLightingInjectionTask::new(
        DepthInput {
            texture,
            depth_type,
        },
        texture_with(F::Rgba32Float, cam.w, cam.h, &colour),
        cam.view(),
    );
    t.injection_resolution_stride = 1;
    t
}

/// Runs render tasks in one GPU task.
pub fn run_tasks(ctx: &ExecuteContext, tasks: Vec<RenderTask>) {
    let mut c = ctx.create_task_container();
    for t in tasks {
        c.schedule_render_task(t);
    }
    build_submit_complete(ctx, c);
}

/// The primary-ray debug view `kind` of `cam` (RGBA per pixel; alpha 0 on miss).
pub fn view(
    ctx: &ExecuteContext,
    cam: &Camera,
    kind: DebugOutputType,
    bilinear: bool,
) -> Vec<Vec4> {
    let (task, out) = view_task(cam, kind, bilinear);
    run_tasks(ctx, vec![task]);
    read_view(&out)
}

/// A trace task writing the debug view `kind` of `cam`, and its output texture.
pub fn view_task(
    cam: &Camera,
    kind: DebugOutputType,
    bilinear: bool,
) -> (RenderTask, wgpu::Texture) {
    let (w, h) = (cam.w, cam.h);
    let out = gpu().device.create_texture(&wgpu::TextureDescriptor {
        label: None,
        size: wgpu::Extent3d {
            width: w,
            height: h,
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
            texture: texture(F::R32Float, w, h, U::TEXTURE_BINDING),
            depth_type: DepthType::RClipSpace,
        },
        NormalInput {
            texture: texture(F::Rgba8Unorm, w, h, U::TEXTURE_BINDING),
            normal_type: NormalType::RgbNormalizedVector,
            normal_to_world: Mat4::IDENTITY,
        },
    );
    common.view = cam.view();
    common.use_bilinear_sampling = bilinear;
    common.debug_parameters.debug_output_type = kind;
    let task = RenderTask::TraceAmbientOcclusion(TraceAmbientOcclusionTask {
        common,
        output: out.create_view(&Default::default()),
        ao_radius: 1.0,
    });
    (task, out)
}

/// The texels of a debug view's output.
pub fn read_view(out: &wgpu::Texture) -> Vec<Vec4> {
    let (w, h) = (out.width(), out.height());
    let row = (w * 16).div_ceil(256) * 256;
    let buf = gpu().device.create_buffer(&wgpu::BufferDescriptor {
        label: None,
        size: (row * h) as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    });
    let mut e = encoder();
    e.copy_texture_to_buffer(
        out.as_image_copy(),
        wgpu::TexelCopyBufferInfo {
            buffer: &buf,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(row),
                rows_per_image: Some(h),
            },
        },
        out.size(),
    );
    submit(e);
    let bytes = read_buffer(&buf);
    let mut px = Vec::new();
    for y in 0..h {
        let line: &[f32] =
            bytemuck::cast_slice(&bytes[(y * row) as usize..(y * row + w * 16) as usize]);
        px.extend(line.chunks(4).map(|c| Vec4::new(c[0], c[1], c[2], c[3])));
    }
    px
}

/// A mesh and the changes to its default geometry input.
pub type MeshEdit<'a> = (&'a Mesh, &'a dyn Fn(&mut GeometryInput));

/// Registers `mesh` with `input` changes, one instance per transform, and builds everything.
pub fn scene(
    ctx: &ExecuteContext,
    meshes: &[MeshEdit<'_>],
    instances: &[(usize, glam::Affine3A, Vec4, InstanceInclusionMask)],
) -> (Vec<GeometryHandle>, Vec<InstanceHandle>) {
    scene_with(ctx, meshes, instances, vec![])
}

/// [`scene`], with render tasks in the same container (after the registrations).
pub fn scene_with(
    ctx: &ExecuteContext,
    meshes: &[MeshEdit<'_>],
    instances: &[(usize, glam::Affine3A, Vec4, InstanceInclusionMask)],
    render: Vec<RenderTask>,
) -> (Vec<GeometryHandle>, Vec<InstanceHandle>) {
    let mut c = ctx.create_task_container();
    for t in render {
        c.schedule_render_task(t);
    }
    let mut gs = Vec::new();
    for (m, edit) in meshes {
        let g = ctx.create_geometry_handle();
        let mut input = super::rt::mesh_input("cache test mesh", m, false);
        edit(&mut input);
        c.schedule_bvh_task(GeometryTask {
            operation: TaskOperation::Register,
            handle: g,
            input,
        });
        gs.push(g);
    }
    let mut is = Vec::new();
    for (g, xf, colour, mask) in instances {
        let h = ctx.create_instance_handle();
        let mut input = InstanceInput::new(gs[*g], *xf);
        input.initial_tile_color = *colour;
        input.inclusion_mask = *mask;
        c.schedule_bvh_task(InstanceTask {
            operation: TaskOperation::Register,
            handle: h,
            input,
        });
        is.push(h);
    }
    c.schedule_bvh_task(BvhBuildTask {
        max_blas_build_count: 1000,
        ..Default::default()
    });
    build_submit_complete(ctx, c);
    (gs, is)
}

/// The allocation of an instance once its read-back has arrived (polls a few times).
pub fn allocation(ctx: &ExecuteContext, h: InstanceHandle) -> CacheAllocation {
    for _ in 0..100 {
        if let Some(a) = ctx.lighting_cache_allocation(h).expect("valid handle") {
            return a;
        }
        gpu()
            .device
            .poll(wgpu::PollType::wait_indefinitely())
            .expect("poll");
    }
    panic!("the allocation read-back never arrived");
}

// --- The sizing formulas of the crate docs, written again from the docs ---------------------

/// `tiles(L) = clamp(ceil(L / unit), 1, limit)`.
fn tiles(len: f32, unit: f32, limit: u32) -> u32 {
    ((len / unit).ceil().max(1.0) as u32).min(limit)
}

/// Expected surfels of a mesh (world-space triangles) in the documented layouts.
pub fn expected_surfels(tris: &[[Vec3; 3]], input: &GeometryInput) -> u32 {
    let unit = input.tile_unit_length;
    let limit = input.tile_resolution_limit;
    match input.surfel_type {
        SurfelType::WarpedBarycentricStorage => tris
            .iter()
            .map(|[a, b, c]| {
                let area = 0.5 * (*b - *a).cross(*c - *a).length();
                let n = if input.force_direct_tile_mapping
                    || area < input.direct_tile_mapping_threshold * unit * unit
                {
                    1
                } else {
                    let l = (*b - *a)
                        .length()
                        .max((*c - *b).length())
                        .max((*a - *c).length());
                    tiles(l, unit, limit)
                };
                n * n
            })
            .sum(),
        SurfelType::MeshColors => {
            let mut pow2_limit = 1;
            while pow2_limit * 2 <= limit {
                pow2_limit *= 2;
            }
            let e = |l: f32| {
                if input.force_direct_tile_mapping {
                    1
                } else {
                    tiles(l, unit, limit).next_power_of_two().min(pow2_limit)
                }
            };
            let key = |v: Vec3| v.to_array().map(|x| (x + 0.0).to_bits());
            let mut verts = std::collections::HashSet::new();
            let mut edges = std::collections::HashSet::new();
            let mut n = 0;
            for t in tris {
                let mut r = 1;
                for k in 0..3 {
                    let (a, b) = (key(t[k]), key(t[(k + 1) % 3]));
                    verts.insert(a);
                    let ek = e((t[(k + 1) % 3] - t[k]).length());
                    r = r.max(ek);
                    if edges.insert(if a < b { (a, b) } else { (b, a) }) {
                        n += ek - 1;
                    }
                }
                if r > 2 {
                    n += (r - 1) * (r - 2) / 2;
                }
            }
            n + verts.len() as u32
        }
    }
}
