//! `ksrt render`: registers the default scene with the SDK and writes an image of it.
//!
//! Until the SDK's GPU tracer lands, the image is traced with the SDK's public CPU reference BVH
//! (`kickstart_rt::cpu`): primary rays, a sun with ray-traced hard shadows, each mesh its colour.
//! It is labelled as such in the file name and the output.

use glam::Vec3;
use kickstart_rt as ksrt;
use kickstart_rt::cpu::{CpuBvh, Ray};
use wgpu::util::DeviceExt;

use crate::scene::{default_scene, Mesh};

use crate::AnyResult;

/// Options of `ksrt render`.
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    pub out: std::path::PathBuf,
}

pub fn render(device: &wgpu::Device, queue: &wgpu::Queue, opts: &RenderOptions) -> AnyResult<()> {
    if opts.width == 0 || opts.height == 0 || opts.width > 16384 || opts.height > 16384 {
        return Err(format!(
            "--size {}x{}: each side must be in 1..=16384",
            opts.width, opts.height
        )
        .into());
    }
    let scene = default_scene();
    let ctx = ksrt::ExecuteContext::new(device, queue, ksrt::InitSettings::default())?;
    register(&ctx, device, &scene)?;
    device.poll(wgpu::PollType::wait_indefinitely())?;
    let triangles: usize = scene.iter().map(|m| m.indices.len() / 3).sum();
    println!(
        "registered {} meshes ({triangles} triangles) with kickstart-rt; SDK memory {} bytes",
        scene.len(),
        ctx.resource_allocations().total()
    );

    let start = std::time::Instant::now();
    let image = trace_cpu_reference(&scene, opts.width, opts.height);
    std::fs::create_dir_all(&opts.out)?;
    let path = opts.out.join("cpu-reference.png");
    image.save(&path)?;
    println!(
        "wrote {} ({}x{}, traced on the CPU reference BVH in {:.2} s; the GPU trace tasks are not implemented yet)",
        path.display(),
        opts.width,
        opts.height,
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

fn register(ctx: &ksrt::ExecuteContext, device: &wgpu::Device, scene: &[Mesh]) -> AnyResult<()> {
    let mut c = ctx.create_task_container();
    for m in scene {
        let vb = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(m.name),
            contents: bytemuck::cast_slice(&m.positions),
            usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::COPY_SRC,
        });
        let ib = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(m.name),
            contents: bytemuck::cast_slice(&m.indices),
            usage: wgpu::BufferUsages::INDEX | wgpu::BufferUsages::COPY_SRC,
        });
        let geometry = ctx.create_geometry_handle();
        c.schedule_bvh_task(ksrt::GeometryTask {
            operation: ksrt::TaskOperation::Register,
            handle: geometry,
            input: ksrt::GeometryInput {
                name: m.name.into(),
                components: vec![ksrt::GeometryComponent {
                    vertex_buffer: ksrt::VertexBufferInput {
                        buffer: vb,
                        offset: 0,
                        stride: 12,
                        count: m.positions.len() as u32,
                        format: ksrt::VertexFormat::Float32x3,
                    },
                    index_buffer: Some(ksrt::IndexBufferInput {
                        buffer: ib,
                        offset: 0,
                        count: m.indices.len() as u32,
                        format: ksrt::IndexFormat::Uint32,
                    }),
                    transform: None,
                    index_range: None,
                }],
                ..Default::default()
            },
        });
        c.schedule_bvh_task(ksrt::InstanceTask {
            operation: ksrt::TaskOperation::Register,
            handle: ctx.create_instance_handle(),
            input: ksrt::InstanceInput::new(geometry, m.transform),
        });
    }
    ctx.invoke_gpu_task(c)?;
    Ok(())
}

fn trace_cpu_reference(scene: &[Mesh], width: u32, height: u32) -> image::RgbImage {
    let mut tris = Vec::new();
    let mut owner = Vec::new();
    for (i, m) in scene.iter().enumerate() {
        for t in m.world_triangles() {
            tris.push(t);
            owner.push(i);
        }
    }
    let bvh = CpuBvh::build(&tris);
    let eye = Vec3::new(0.3, 2.4, 6.0);
    let at = Vec3::new(0.2, 0.8, 0.0);
    let fwd = (at - eye).normalize();
    let right = fwd.cross(Vec3::Y).normalize();
    let up = right.cross(fwd);
    let tan = (50f32.to_radians() / 2.0).tan();
    let aspect = width as f32 / height as f32;
    let sun = Vec3::new(0.5, 1.0, 0.4).normalize();
    let mut img = image::RgbImage::new(width, height);
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let rows: Vec<(u32, Vec<[u8; 3]>)> = std::thread::scope(|s| {
        let jobs: Vec<_> = (0..threads as u32)
            .map(|k| {
                let (bvh, tris, owner) = (&bvh, &tris, &owner);
                s.spawn(move || {
                    let mut out = Vec::new();
                    for y in (k..height).step_by(threads) {
                        let row = (0..width)
                            .map(|x| {
                                let u =
                                    ((x as f32 + 0.5) / width as f32 * 2.0 - 1.0) * tan * aspect;
                                let v = (1.0 - (y as f32 + 0.5) / height as f32 * 2.0) * tan;
                                let dir = (fwd + right * u + up * v).normalize();
                                let ray = Ray {
                                    origin: eye,
                                    dir,
                                    t_min: 0.0,
                                    t_max: f32::INFINITY,
                                };
                                let c = match bvh.closest_hit(tris, &ray) {
                                    None => Vec3::new(0.5, 0.6, 0.8),
                                    Some(h) => {
                                        let [a, b, c] = tris[h.primitive as usize];
                                        let mut n = (b - a).cross(c - a).normalize_or_zero();
                                        if n.dot(dir) > 0.0 {
                                            n = -n;
                                        }
                                        let p = eye + dir * h.t + n * 1e-3;
                                        let lit = n.dot(sun).max(0.0);
                                        let shadow = Ray {
                                            origin: p,
                                            dir: sun,
                                            t_min: 0.0,
                                            t_max: f32::INFINITY,
                                        };
                                        let vis = if lit > 0.0 && bvh.any_hit(tris, &shadow) {
                                            0.0
                                        } else {
                                            1.0
                                        };
                                        scene[owner[h.primitive as usize]].color
                                            * (0.2 + 0.8 * lit * vis)
                                    }
                                };
                                let srgb = |l: f32| {
                                    (l.clamp(0.0, 1.0).powf(1.0 / 2.2) * 255.0 + 0.5) as u8
                                };
                                [srgb(c.x), srgb(c.y), srgb(c.z)]
                            })
                            .collect();
                        out.push((y, row));
                    }
                    out
                })
            })
            .collect();
        jobs.into_iter()
            .flat_map(|j| j.join().unwrap_or_default())
            .collect()
    });
    for (y, row) in rows {
        for (x, p) in row.into_iter().enumerate() {
            img.put_pixel(x as u32, y, image::Rgb(p));
        }
    }
    img
}
