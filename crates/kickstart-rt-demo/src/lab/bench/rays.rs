//! The ray batches of `ksrt bench`: one primary ray per pixel, AO and diffuse rays from the
//! primary hits (generated on the CPU, untimed), a sample of the primary hits checked against
//! the CPU reference BVH, and the traversal work per ray from the read-back BLAS.

use std::collections::HashMap;

use glam::{Affine3A, Vec3};
use kickstart_rt as ksrt;

use super::harness::Bench;
use super::options::RayOrder;
use super::report::{OracleCheck, RayBatch, SceneReport, WorkPerRay, SUBGROUP_LANES};
use super::Stats;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::rng::Rng;
use kickstart_rt_renderer::scene::{Camera, Scene};
use kickstart_rt_renderer::sdk_glue::{GpuHit, GpuRay, Query};
use kickstart_rt_renderer::upload::UploadedMesh;

/// The CPU ray of `r` in the instance's object space.
fn object_ray(r: &GpuRay, world_to_object: Affine3A) -> ksrt::cpu::Ray {
    ksrt::cpu::Ray {
        origin: world_to_object.transform_point3(Vec3::from(r.origin)),
        dir: world_to_object.transform_vector3(Vec3::from(r.dir)),
        t_min: r.t_min,
        t_max: r.t_max,
    }
}

/// [`WorkPerRay`] of about 20 000 of `rays`, traced through `blas` in the instance's object
/// space.
pub(super) fn work_per_ray(
    blas: &ksrt::cpu::BlasReadback,
    world_to_object: Affine3A,
    rays: &[GpuRay],
    any: bool,
) -> WorkPerRay {
    let step = (rays.len() / 20_000).max(1);
    let mut total = ksrt::cpu::TraversalCounts::default();
    let mut sampled = 0u64;
    for r in rays.iter().step_by(step) {
        total += blas.trace(&object_ray(r, world_to_object), any).1;
        sampled += 1;
    }
    // Whole groups of consecutive rays, every n-th group: the loop iterations of each ray.
    let group_step = (rays.len().div_ceil(SUBGROUP_LANES) / (20_000 / SUBGROUP_LANES)).max(1);
    let steps: Vec<Vec<u64>> = rays
        .chunks(SUBGROUP_LANES)
        .step_by(group_step)
        .map(|group| {
            group
                .iter()
                .map(|r| {
                    let c = blas.trace(&object_ray(r, world_to_object), any).1;
                    c.nodes + c.triangles
                })
                .collect()
        })
        .collect();
    let per = |x: u64| x as f64 / sampled.max(1) as f64;
    WorkPerRay {
        sampled,
        nodes: per(total.nodes),
        triangles: per(total.triangles),
        subgroup_busy: subgroup_busy(&steps, SUBGROUP_LANES),
    }
}

/// Σ steps / Σ (lanes × the group's longest): the share of a subgroup's lane-iterations that do
/// work when each group of rays runs on one `lanes`-lane subgroup until its longest ray is done
/// (the lanes of a group shorter than `lanes` idle). 1 for no steps at all.
fn subgroup_busy(groups: &[Vec<u64>], lanes: usize) -> f64 {
    let work: u64 = groups.iter().flatten().sum();
    let issued: u64 = groups
        .iter()
        .map(|g| g.iter().copied().max().unwrap_or(0) * lanes as u64)
        .sum();
    if issued == 0 {
        1.0
    } else {
        work as f64 / issued as f64
    }
}

/// Where a primary hit is and which way its surface faces (against the ray).
pub(super) struct Surface {
    pub(super) point: Vec3,
    pub(super) normal: Vec3,
}

/// The geometric normal of a primary hit, from the mesh's triangle on the CPU; `None` when the
/// hit's instance or primitive is not one the scene has.
pub(super) fn surface(
    scene: &Scene,
    slots: &HashMap<u32, usize>,
    hit: &GpuHit,
    ray_dir: Vec3,
) -> Option<Surface> {
    let inst = &scene.instances[*slots.get(&hit.instance)?];
    let mesh = &scene.meshes[inst.mesh];
    let first = hit.primitive as usize * 3;
    let idx = mesh.indices.get(first..first + 3)?;
    let [a, b, c] = [idx[0], idx[1], idx[2]].map(|i| {
        inst.transform
            .transform_point3(Vec3::from(mesh.positions[i as usize]))
    });
    let mut normal = (b - a).cross(c - a).try_normalize()?;
    if normal.dot(ray_dir) > 0.0 {
        normal = -normal;
    }
    // From the barycentrics rather than the ray's t: exact on the triangle's plane.
    let point = a * (1.0 - hit.u - hit.v) + b * hit.u + c * hit.v;
    Some(Surface { point, normal })
}

pub(super) fn batch(kind: &'static str, rays: usize, hits: &[GpuHit], time: Stats) -> RayBatch {
    let misses = hits.iter().filter(|h| !h.is_hit()).count() as u64;
    let mrays_per_s = rays as f64 / (time.median_ms * 1e3);
    RayBatch {
        kind,
        rays: rays as u64,
        misses,
        time,
        mrays_per_s,
        work: None,
    }
}

/// (e) Primary, AO and diffuse batches and the peer workload.
pub(super) fn rays(
    bench: &Bench,
    scene: &Scene,
    uploads: &[UploadedMesh],
    camera: &Camera,
    (width, height): (u32, u32),
    report: &mut SceneReport,
) -> AnyResult<RayBatches> {
    let (ctx, handles) = bench.registered(scene, uploads, false, true)?;
    let slots = handles.instance_of_slot();
    // Work per ray needs the one BLAS every ray meets (scenes of one instance).
    let one_blas = match scene.instances.as_slice() {
        [only] => Some((
            ctx.read_back_blas(handles.geometries[only.mesh])?,
            only.transform.inverse(),
        )),
        _ => None,
    };
    let work = |rays: &[GpuRay], any: bool| {
        one_blas
            .as_ref()
            .map(|(blas, world_to_object)| work_per_ray(blas, *world_to_object, rays, any))
    };
    let (dirs, primary) = primary_rays_in(camera, (width, height), bench.ray_order);
    let (primary_time, primary_hits) = bench.trace(&ctx, &primary, Query::Closest)?;
    report.oracle = Some(oracle_check(scene, &primary, &primary_hits));
    let mut primary_batch = batch("primary", primary.len(), &primary_hits, primary_time);
    primary_batch.work = work(&primary, false);
    let pixels = primary.len() as f64;
    let primary_hit_count = (primary_batch.rays - primary_batch.misses) as f64;
    let primary_ms = primary_batch.time.median_ms;
    report.rays.push(primary_batch);

    // Secondary rays from the primary hits, generated on the CPU (untimed).
    let offset = 1e-4 * scene.size();
    let surfaces: Vec<Surface> = primary_hits
        .iter()
        .zip(&dirs)
        .filter(|(h, _)| h.is_hit())
        .filter_map(|(h, d)| surface(scene, &slots, h, *d))
        .collect();
    let mut rng = Rng(0x6b73_7274);
    let ao = secondary_rays(&surfaces, offset, &mut rng, 1.0);
    let (ao_time, ao_hits) = bench.trace(&ctx, &ao, Query::Any)?;
    let mut ao_batch = batch("ao", ao.len(), &ao_hits, ao_time);
    ao_batch.work = work(&ao, true);
    report.rays.push(ao_batch);
    let diffuse = secondary_rays(&surfaces, offset, &mut rng, f32::INFINITY);
    let (diffuse_time, diffuse_hits) = bench.trace(&ctx, &diffuse, Query::Closest)?;
    let diffuse_ms = diffuse_time.median_ms;
    let mut diffuse_batch = batch("diffuse", diffuse.len(), &diffuse_hits, diffuse_time);
    diffuse_batch.work = work(&diffuse, false);
    report.rays.push(diffuse_batch);
    report.peer_mrays_per_s =
        Some((pixels + primary_hit_count) / ((primary_ms + diffuse_ms) * 1e3));
    Ok(RayBatches {
        slots: handles.instances.iter().map(|h| h.index()).collect(),
        width,
        batches: vec![
            ("primary", Query::Closest, primary, primary_hits),
            ("ao", Query::Any, ao, ao_hits),
            ("diffuse", Query::Closest, diffuse, diffuse_hits),
        ],
        blas: one_blas.map(|(b, _)| b),
    })
}

/// The rays of [`rays`] and our hits, kept so a peer traces exactly the same rays.
pub(super) struct RayBatches {
    /// Our instance slot index of each scene instance (what hits report).
    pub(super) slots: Vec<u32>,
    /// Width of the primary rays' image (their row length).
    pub(super) width: u32,
    /// Kind, query, rays and our hits of each batch, in the order measured.
    pub(super) batches: Vec<(&'static str, Query, Vec<GpuRay>, Vec<GpuHit>)>,
    /// The scene's one BLAS as read back (scenes of one instance).
    pub(super) blas: Option<ksrt::cpu::BlasReadback>,
}

/// One primary ray per pixel through `camera`, row by row from the top: their directions and the
/// rays (from the eye, t in [0, ∞)).
pub(super) fn primary_rays(camera: &Camera, size: (u32, u32)) -> (Vec<Vec3>, Vec<GpuRay>) {
    primary_rays_in(camera, size, RayOrder::Rows)
}

/// [`primary_rays`] with the pixels in `order`.
fn primary_rays_in(
    camera: &Camera,
    (width, height): (u32, u32),
    order: RayOrder,
) -> (Vec<Vec3>, Vec<GpuRay>) {
    let dirs: Vec<Vec3> = order
        .pixels((width, height))
        .into_iter()
        .map(|(x, y)| camera.primary_dir(x, y, width, height))
        .collect();
    let rays = dirs
        .iter()
        .map(|d| GpuRay {
            origin: camera.eye.to_array(),
            t_min: 0.0,
            dir: d.to_array(),
            t_max: f32::INFINITY,
        })
        .collect();
    (dirs, rays)
}

/// One cosine-distributed ray about each surface's normal, from the surface point moved
/// `offset` along the normal (so it does not hit its own triangle), t in [0, `t_max`].
pub(super) fn secondary_rays(
    surfaces: &[Surface],
    offset: f32,
    rng: &mut Rng,
    t_max: f32,
) -> Vec<GpuRay> {
    surfaces
        .iter()
        .map(|s| GpuRay {
            origin: (s.point + s.normal * offset).to_array(),
            t_min: 0.0,
            dir: rng.cosine(s.normal).to_array(),
            t_max,
        })
        .collect()
}

/// Compares about 20 000 primary hits with the CPU reference BVH over the world's triangles
/// (through the cutouts' transparent texels, as the SDK traces them).
fn oracle_check(scene: &Scene, rays: &[GpuRay], hits: &[GpuHit]) -> OracleCheck {
    let caster = kickstart_rt_renderer::scene::cutout::CutoutCaster::new(scene);
    let step = (rays.len() / 20_000).max(1);
    let mut check = OracleCheck {
        rays: 0,
        disagreements: 0,
    };
    for (r, h) in rays.iter().zip(hits).step_by(step) {
        let cpu = caster.closest_hit(&ksrt::cpu::Ray {
            origin: Vec3::from(r.origin),
            dir: Vec3::from(r.dir),
            t_min: r.t_min,
            t_max: r.t_max,
        });
        let agree = match (cpu, h.is_hit()) {
            (None, false) => true,
            (Some(c), true) => (c.t - h.t).abs() <= 1e-3 * c.t.abs().max(1e-3),
            _ => false,
        };
        check.rays += 1;
        check.disagreements += usize::from(!agree);
    }
    check
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn subgroup_busy_is_work_over_lanes_times_each_groups_longest() {
        // Equal rays keep every lane busy.
        assert_eq!(subgroup_busy(&[vec![3, 3], vec![5, 5]], 2), 1.0);
        // One long ray: its partner idles for 2 of 3 steps.
        assert!((subgroup_busy(&[vec![1, 3]], 2) - 4.0 / 6.0).abs() < 1e-12);
        // A short last group pays for its missing lanes too.
        assert!((subgroup_busy(&[vec![2, 2], vec![2]], 2) - 6.0 / 8.0).abs() < 1e-12);
        // Groups weigh by their length: (1 + 3 + 10 + 10) / (2×3 + 2×10).
        assert!((subgroup_busy(&[vec![1, 3], vec![10, 10]], 2) - 24.0 / 26.0).abs() < 1e-12);
        assert_eq!(subgroup_busy(&[], 32), 1.0);
        assert_eq!(subgroup_busy(&[vec![0, 0]], 2), 1.0);
    }

    #[test]
    fn cosine_directions_are_unit_and_in_the_hemisphere() {
        let mut rng = Rng(7);
        let n = Vec3::new(0.3, -0.8, 0.2).normalize();
        let mut mean_cos = 0.0;
        for _ in 0..4096 {
            let d = rng.cosine(n);
            assert!((d.length() - 1.0).abs() < 1e-4);
            assert!(d.dot(n) >= 0.0);
            mean_cos += d.dot(n) / 4096.0;
        }
        // E[cos θ] under a cosine-weighted density is 2/3.
        assert!((mean_cos - 2.0 / 3.0).abs() < 0.03, "{mean_cos}");
    }
}
