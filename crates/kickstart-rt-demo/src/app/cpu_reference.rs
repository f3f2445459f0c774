//! The CPU reference image of `ksrt render`: the view traced with the SDK's public CPU reference
//! BVH (`kickstart_rt::cpu`): primary rays, a sun with
//! ray-traced hard shadows, each mesh its colour. Both kinds of ray pass through the
//! transparent texels of cutouts, as the SDK's do ([`CutoutCaster`]). It stands beside the GPU debug views until the
//! lighting cache and the trace tasks make lit GPU images; it is labelled as such in the file name
//! and the output.

use glam::Vec3;
use kickstart_rt::cpu::Ray;

use kickstart_rt_renderer::scene::cutout::CutoutCaster;
use kickstart_rt_renderer::scene::{Camera, Scene};

use kickstart_rt_renderer::error::AnyResult;

/// Options of `ksrt render`.
pub struct RenderOptions {
    /// Image width, pixels.
    pub width: u32,
    /// Image height, pixels.
    pub height: u32,
    /// Output folder.
    pub out: std::path::PathBuf,
    /// The camera.
    pub camera: Camera,
}

/// Writes `cpu-reference.png`: `scene` traced on the CPU from `opts.camera`, a progress bar
/// counting rows when `progress` (the reference takes seconds to minutes on two cores).
pub fn render(scene: &Scene, opts: &RenderOptions, progress: bool) -> AnyResult<()> {
    let start = std::time::Instant::now();
    let bar = crate::app::progress::bar(progress, u64::from(opts.height), "CPU reference", "rows");
    let image = trace_cpu_reference(scene, &opts.camera, (opts.width, opts.height), &bar);
    bar.finish_and_clear();
    std::fs::create_dir_all(&opts.out)
        .map_err(|e| format!("--out {}: cannot create: {e}", opts.out.display()))?;
    let path = opts.out.join("cpu-reference.png");
    image
        .save(&path)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    println!(
        "wrote {} ({}x{}, traced on the CPU reference BVH in {:.2} s: direct sunlight without the SDK, to compare the lit images with)",
        path.display(),
        opts.width,
        opts.height,
        start.elapsed().as_secs_f64()
    );
    Ok(())
}

fn trace_cpu_reference(
    scene: &Scene,
    camera: &Camera,
    (width, height): (u32, u32),
    bar: &indicatif::ProgressBar,
) -> image::RgbImage {
    let caster = CutoutCaster::new(scene);
    let tris = &caster.triangles;
    let eye = camera.eye;
    // Shadow rays start this far off the surface: relative to the scene so that tiny scenes
    // (the dragon is 0.3 units across) don't shadow themselves and big ones don't leak.
    let offset = scene.size() * 2e-4;
    let sun = Vec3::new(0.5, 1.0, 0.4).normalize();
    let shading_normal = |prim: u32, u: f32, v: f32| -> Option<Vec3> {
        let (instance, triangle) = caster.locate(prim)?;
        let inst = scene.instances.get(instance)?;
        let mesh = &scene.meshes[inst.mesh];
        let first = triangle * 3;
        let idx = mesh.indices.get(first..first + 3)?;
        let n = |k: usize| Vec3::from(mesh.normals[idx[k] as usize]);
        let local = n(0) * (1.0 - u - v) + n(1) * u + n(2) * v;
        // Normals transform by the inverse transpose (non-uniform scales).
        (inst.transform.matrix3.inverse().transpose() * glam::Vec3A::from(local))
            .try_normalize()
            .map(Vec3::from)
    };
    let mut img = image::RgbImage::new(width, height);
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let rows: Vec<(u32, Vec<[u8; 3]>)> = std::thread::scope(|s| {
        let jobs: Vec<_> = (0..threads as u32)
            .map(|k| {
                let (caster, shading_normal) = (&caster, &shading_normal);
                let bar = bar.clone();
                s.spawn(move || {
                    let mut out = Vec::new();
                    for y in (k..height).step_by(threads) {
                        let row = (0..width)
                            .map(|x| {
                                let dir = camera.primary_dir(x, y, width, height);
                                let ray = Ray {
                                    origin: eye,
                                    dir,
                                    t_min: 0.0,
                                    t_max: f32::INFINITY,
                                };
                                let c = match caster.closest_hit(&ray) {
                                    None => Vec3::new(0.5, 0.6, 0.8),
                                    Some(h) => {
                                        let [a, b, c] = tris[h.primitive as usize];
                                        let mut n = (b - a).cross(c - a).normalize_or_zero();
                                        if n.dot(dir) > 0.0 {
                                            n = -n;
                                        }
                                        let p = eye + dir * h.t + n * offset;
                                        // Smooth shading from the vertex normals, turned to
                                        // the side the ray sees.
                                        let ns = shading_normal(h.primitive, h.u, h.v)
                                            .map_or(n, |s| if s.dot(n) < 0.0 { -s } else { s });
                                        let lit = ns.dot(sun).max(0.0);
                                        let shadow = Ray {
                                            origin: p,
                                            dir: sun,
                                            t_min: 0.0,
                                            t_max: f32::INFINITY,
                                        };
                                        let vis = if lit > 0.0 && caster.any_hit(&shadow) {
                                            0.0
                                        } else {
                                            1.0
                                        };
                                        scene.meshes[scene.instances
                                            [caster.owner[h.primitive as usize] as usize]
                                            .mesh]
                                            .color
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
                        bar.inc(1);
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
