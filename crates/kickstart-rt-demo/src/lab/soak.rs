//! `ksrt soak`: many frames of every effect (injection, traces, denoisers) while the scene
//! churns — geometries registered, updated and destroyed, instances registered, moved, hidden and
//! destroyed, BLAS builds throttled to a random count per frame — through the SDK's public API
//! only. It fails on the first error the SDK returns, and runs the same churn twice: after each
//! round, once every extra object is destroyed, the memory of destroyed objects (vertex copies,
//! BLASes, denoiser histories) must be back where it was before the churn, and the pools (the
//! lighting cache's surfels, TLAS and scratch, staging) must not have grown in the second round. `--frames` sets the length; the test of this module runs a short soak on
//! whatever adapter there is (software Vulkan in CI).

use crate::app::frames::RendererExt;
use crate::app::gpu;
use glam::{Affine3A, Quat, Vec3};
use kickstart_rt as ksrt;
use kickstart_rt_renderer::error::AnyResult;
use kickstart_rt_renderer::renderer::Renderer;
use kickstart_rt_renderer::scene::{Camera, Mesh, Scene};
use kickstart_rt_renderer::sdk_glue;
use kickstart_rt_renderer::upload::{self, UploadedMesh};

/// Bytes an allocation's reported size may differ by between two placements of the same buffer
/// in wgpu's allocator (alignment padding).
const WGPU_PLACEMENT_PADDING: u64 = 64;

/// What to soak.
#[derive(Debug, Clone)]
pub struct SoakOptions {
    /// Frames of churn, in two rounds of the same churn (a few quiet frames come before and
    /// after each).
    pub frames: u32,
    /// Image size.
    pub size: (u32, u32),
    /// Seed of the churn's random choices.
    pub seed: u64,
    /// Most extra geometries alive at once.
    pub max_geometries: usize,
}

/// What a soak did and the memory it saw.
#[derive(Debug, Clone, Default)]
pub struct SoakReport {
    /// Frames rendered with churn.
    pub frames: u32,
    /// Geometries registered, updated (refit) and destroyed.
    pub geometries: [u32; 3],
    /// Instances registered, updated (moved or hidden) and destroyed.
    pub instances: [u32; 3],
    /// `ResourceAllocations::total()` before the churn, at its peak, and after it (the pools keep
    /// their high-water capacity; see [`run`]).
    pub bytes: [u64; 3],
    /// wgpu's allocator (see [`gpu::wgpu_allocated`]) before the churn and after each round
    /// (`None`: the backend gives no report).
    pub wgpu: Option<[gpu::WgpuAllocated; 3]>,
    /// The traversal backend the SDK context took.
    pub backend: Option<ksrt::TraversalBackend>,
    /// Wall time, seconds.
    pub seconds: f64,
}

/// Quiet frames before measuring the baseline and after destroying everything (lazy
/// destruction releases memory at the first build after the GPU finished with it).
const QUIET_FRAMES: u32 = 3;

/// A tiny deterministic generator (xorshift64*), so a seed replays the same churn.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    /// Uniform in `[0, n)`.
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n.max(1) as u64) as usize
    }
    /// Uniform in `[lo, hi)`.
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
    fn chance(&mut self, p: f32) -> bool {
        self.range(0.0, 1.0) < p
    }
}

/// One extra geometry: its buffers (kept alive while the SDK may copy from them), handle,
/// whether it may be updated, and its instances.
struct Extra {
    mesh: Mesh,
    upload: UploadedMesh,
    handle: ksrt::GeometryHandle,
    allow_update: bool,
    instances: Vec<ksrt::InstanceHandle>,
}

/// A random small mesh: a box of random proportions made of `2 · n²` triangles per face.
fn random_mesh(rng: &mut Rng, k: u64) -> AnyResult<Mesh> {
    let n = 1 + rng.below(6) as u32;
    let half = Vec3::new(
        rng.range(0.1, 0.6),
        rng.range(0.1, 0.6),
        rng.range(0.1, 0.6),
    );
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
            let base = positions.len() as u32;
            for j in 0..=n {
                for i in 0..=n {
                    let mut p = Vec3::ZERO;
                    p[axis] = sign * half[axis];
                    p[u] = (2.0 * i as f32 / n as f32 - 1.0) * half[u];
                    p[v] = (2.0 * j as f32 / n as f32 - 1.0) * half[v];
                    positions.push(p.to_array());
                }
            }
            for j in 0..n {
                for i in 0..n {
                    let a = base + j * (n + 1) + i;
                    let (b, c, d) = (a + 1, a + n + 1, a + n + 2);
                    indices.extend([a, b, d, a, d, c]);
                }
            }
        }
    }
    let color = Vec3::new(
        rng.range(0.2, 0.9),
        rng.range(0.2, 0.9),
        rng.range(0.2, 0.9),
    );
    Ok(Mesh::new(
        format!("soak box {k}"),
        positions,
        indices,
        color,
    )?)
}

/// A random placement inside `bounds` (centre, half extent), turned and scaled.
fn random_transform(rng: &mut Rng, centre: Vec3, half: Vec3) -> Affine3A {
    let p = centre
        + Vec3::new(
            rng.range(-1.0, 1.0) * half.x,
            rng.range(-1.0, 1.0) * half.y,
            rng.range(-1.0, 1.0) * half.z,
        );
    let turn = Quat::from_rotation_y(rng.range(0.0, std::f32::consts::TAU));
    Affine3A::from_scale_rotation_translation(Vec3::splat(rng.range(0.5, 1.5)), turn, p)
}

/// The churn of one frame, scheduled into `c`; `report` counts it.
struct Churn {
    rng: Rng,
    extras: Vec<Extra>,
    next_mesh: u64,
    centre: Vec3,
    half: Vec3,
    max_geometries: usize,
}

impl Churn {
    fn instance(&mut self, c: &mut ksrt::TaskContainer, ctx: &ksrt::ExecuteContext, g: usize) {
        let handle = ctx.create_instance_handle();
        let t = random_transform(&mut self.rng, self.centre, self.half);
        c.schedule_bvh_task(ksrt::InstanceTask {
            operation: ksrt::TaskOperation::Register,
            handle,
            input: ksrt::InstanceInput::new(self.extras[g].handle, t),
        });
        self.extras[g].instances.push(handle);
    }

    fn frame(
        &mut self,
        device: &wgpu::Device,
        ctx: &ksrt::ExecuteContext,
        c: &mut ksrt::TaskContainer,
        report: &mut SoakReport,
    ) -> AnyResult<()> {
        // Destruction first: a handle destroyed after its registration was scheduled in the
        // same container would leave the container naming a dead handle (refused, as it should
        // be: the soak is not testing that).
        if !self.extras.is_empty() {
            // Destroy an instance, or a geometry with its instances.
            if self.rng.chance(0.15) {
                let g = self.rng.below(self.extras.len());
                if let Some(handle) = self.extras[g].instances.pop() {
                    ctx.destroy_instance_handle(handle)?;
                    report.instances[2] += 1;
                }
            }
            if self.rng.chance(0.2) {
                let g = self.rng.below(self.extras.len());
                let e = self.extras.swap_remove(g);
                for handle in e.instances {
                    ctx.destroy_instance_handle(handle)?;
                    report.instances[2] += 1;
                }
                ctx.destroy_geometry_handle(e.handle)?;
                report.geometries[2] += 1;
            }
        }
        if !self.extras.is_empty() {
            // Another instance of an existing geometry.
            if self.rng.chance(0.2) {
                let g = self.rng.below(self.extras.len());
                self.instance(c, ctx, g);
                report.instances[0] += 1;
            }
            // Move or hide a few instances.
            for _ in 0..self.rng.below(4) {
                let g = self.rng.below(self.extras.len());
                let Some(&handle) = self.extras[g].instances.first() else {
                    continue;
                };
                let mut input = ksrt::InstanceInput::new(
                    self.extras[g].handle,
                    random_transform(&mut self.rng, self.centre, self.half),
                );
                input.participating_in_tlas = !self.rng.chance(0.2);
                c.schedule_bvh_task(ksrt::InstanceTask {
                    operation: ksrt::TaskOperation::Update,
                    handle,
                    input,
                });
                report.instances[1] += 1;
            }
            // Deform an updatable geometry (same vertex count: a refit).
            if self.rng.chance(0.25) {
                let g = self.rng.below(self.extras.len());
                if self.extras[g].allow_update {
                    let s = self.rng.range(0.8, 1.2);
                    let e = &mut self.extras[g];
                    for p in &mut e.mesh.positions {
                        p[1] *= s;
                    }
                    e.upload = upload::upload(device, &e.mesh);
                    c.schedule_bvh_task(ksrt::GeometryTask {
                        operation: ksrt::TaskOperation::Update,
                        handle: e.handle,
                        input: upload::geometry_input(&e.upload, true),
                    });
                    report.geometries[1] += 1;
                }
            }
        }
        // Register a geometry and one to three instances of it.
        if self.extras.len() < self.max_geometries && self.rng.chance(0.35) {
            let mesh = random_mesh(&mut self.rng, self.next_mesh)?;
            self.next_mesh += 1;
            let upload = upload::upload(device, &mesh);
            let allow_update = self.rng.chance(0.5);
            let handle = ctx.create_geometry_handle();
            c.schedule_bvh_task(ksrt::GeometryTask {
                operation: ksrt::TaskOperation::Register,
                handle,
                input: upload::geometry_input(&upload, allow_update),
            });
            self.extras.push(Extra {
                mesh,
                upload,
                handle,
                allow_update,
                instances: Vec::new(),
            });
            report.geometries[0] += 1;
            for _ in 0..1 + self.rng.below(3) {
                self.instance(c, ctx, self.extras.len() - 1);
                report.instances[0] += 1;
            }
        }
        Ok(())
    }

    /// Destroys every extra instance and geometry.
    fn clear(&mut self, ctx: &ksrt::ExecuteContext, report: &mut SoakReport) -> AnyResult<()> {
        for e in self.extras.drain(..) {
            for handle in e.instances {
                ctx.destroy_instance_handle(handle)?;
                report.instances[2] += 1;
            }
            ctx.destroy_geometry_handle(e.handle)?;
            report.geometries[2] += 1;
        }
        Ok(())
    }
}

/// Renders one frame of `renderer` with `churn`'s tasks (when `Some`) recorded before it, waits
/// for the GPU and retires the frame's tasks.
fn frame(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    renderer: &mut Renderer,
    camera: &Camera,
    churn: Option<ksrt::TaskContainer>,
    max_blas_build_count: u32,
) -> AnyResult<()> {
    let ctx = &renderer.sdk.ctx;
    let mut c = churn.unwrap_or_else(|| ctx.create_task_container());
    c.schedule_bvh_task(sdk_glue::bvh_build_task(
        max_blas_build_count,
        Some(sdk_glue::Tlas::Auto),
    ));
    let mut encoder = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
        label: Some("ksrt soak"),
    });
    let mut tasks = vec![ctx.build_gpu_task(c, &mut encoder)?];
    tasks.extend(renderer.record_frame(device, queue, &mut encoder, camera)?);
    queue.submit([encoder.finish()]);
    renderer.finish(device, &tasks, false)?;
    Ok(())
}

/// Soaks `scene` (its camera: `camera`) on `device`.
pub fn run(
    device: &wgpu::Device,
    queue: &wgpu::Queue,
    scene: &Scene,
    camera: &Camera,
    opts: &SoakOptions,
    mut progress: impl FnMut(u32),
) -> AnyResult<SoakReport> {
    // Each of the two rounds needs a frame of churn, or the soak would pass having tested nothing.
    if opts.frames < 2 {
        return Err(format!("soak: {} frames; at least 2 (one a round)", opts.frames).into());
    }
    let start = std::time::Instant::now();
    let mut renderer = crate::app::frames::new_renderer(
        device,
        queue,
        scene,
        &crate::app::frames::renderer_options(opts.size),
    )?;
    let (lo, hi) = scene.bounds();
    let mut churn = Churn {
        rng: Rng(opts.seed | 1),
        extras: Vec::new(),
        next_mesh: 0,
        centre: (lo + hi) * 0.5,
        half: (hi - lo) * 0.4,
        max_geometries: opts.max_geometries,
    };
    let mut report = SoakReport {
        backend: Some(renderer.sdk.ctx.traversal_backend().backend),
        ..SoakReport::default()
    };
    let allocations = |r: &Renderer| r.sdk.ctx.resource_allocations();
    for _ in 0..QUIET_FRAMES {
        frame(device, queue, &mut renderer, camera, None, 1)?;
    }
    renderer.sdk.ctx.release_device_resources_immediately()?;
    let baseline = allocations(&renderer);
    let wgpu_baseline = gpu::wgpu_allocated(device)?;
    let mut wgpu_after = Vec::new();
    let mut peak = baseline.total();
    // Two rounds of the same churn (the same seed): per-object memory (vertex copies, BLASes,
    // denoiser histories) must be back at the baseline after each; the pools (lighting cache
    // surfels, TLAS and build scratch, staging, pool reserve) keep the capacity their peak
    // needed, and the second round must not need more: memory stays bounded however long the
    // churn goes on.
    let mut after = Vec::new();
    for round in 0..2 {
        churn.rng = Rng(opts.seed | 1);
        for f in 0..opts.frames / 2 {
            let mut c = renderer.sdk.ctx.create_task_container();
            churn.frame(device, &renderer.sdk.ctx, &mut c, &mut report)?;
            let max_blas = 1 + churn.rng.below(4) as u32;
            frame(device, queue, &mut renderer, camera, Some(c), max_blas)?;
            peak = peak.max(allocations(&renderer).total());
            report.frames += 1;
            progress(round * (opts.frames / 2) + f + 1);
        }
        churn.clear(&renderer.sdk.ctx, &mut report)?;
        for _ in 0..QUIET_FRAMES {
            // Enough BLAS builds for anything still queued, so nothing waits.
            frame(device, queue, &mut renderer, camera, None, 64)?;
        }
        renderer.sdk.ctx.release_device_resources_immediately()?;
        let a = allocations(&renderer);
        let per_object = |x: &ksrt::ResourceAllocations| (x.vertex_copies, x.blas, x.denoiser);
        if per_object(&a) != per_object(&baseline) {
            return Err(format!(
                "round {round}: the destroyed objects' memory was not released:\n  before {baseline:?}\n  after  {a:?}"
            )
            .into());
        }
        after.push(a);
        wgpu_after.push(gpu::wgpu_allocated(device)?);
    }
    // The driver's structures are wgpu's allocator's sizes, padding included: checked with
    // wgpu's own count below.
    let own = |a: &ksrt::ResourceAllocations| ksrt::ResourceAllocations {
        driver_acceleration_structures: 0,
        ..*a
    };
    if own(&after[1]) != own(&after[0]) {
        return Err(format!(
            "the same churn again grew the SDK's memory:\n  after round 1 {:?}\n  after round 2 {:?}",
            after[0], after[1]
        )
        .into());
    }
    // wgpu's own count, which sees what the SDK's does not (the driver's acceleration
    // structures): the second round may not leave more allocations than the first left, nor
    // more bytes than their placement explains. (Not exactly the same bytes: the SDK gives
    // build memory back and allocates it again, and wgpu's allocator reports an allocation's
    // size with the padding of where it landed, a few bytes either way.)
    let grew = |r0: gpu::WgpuAllocated, r1: gpu::WgpuAllocated| {
        let padding = WGPU_PLACEMENT_PADDING * r0.allocations as u64;
        r1.bytes > r0.bytes + padding || r1.allocations > r0.allocations
    };
    let differs = match (wgpu_after[0], wgpu_after[1]) {
        (Some(r0), Some(r1)) => grew(r0, r1),
        (a, b) => a.is_some() != b.is_some(),
    };
    if differs {
        return Err(format!(
            "the same churn again grew wgpu's allocations:\n  after round 1 {:?}\n  after round 2 {:?}",
            wgpu_after[0], wgpu_after[1]
        )
        .into());
    }
    report.wgpu = match (wgpu_baseline, wgpu_after[0], wgpu_after[1]) {
        (Some(b), Some(r0), Some(r1)) => Some([b, r0, r1]),
        _ => None,
    };
    report.bytes = [baseline.total(), peak, after[1].total()];
    report.seconds = start.elapsed().as_secs_f64();
    Ok(report)
}

/// `ksrt soak`: loads `scene`, soaks it for `frames` frames at `size` and prints the report.
pub fn command(
    scene: &str,
    scenes: Option<std::path::PathBuf>,
    frames: u32,
    size: &str,
    seed: u64,
) -> AnyResult<()> {
    let size = crate::app::args::parse_size(size)?;
    let adapter = gpu::adapter()?;
    let (device, queue) = gpu::device(&adapter)?;
    let mut scene = crate::app::scenes::load_scene(scene, scenes)?;
    let camera = scene.prepare_view(None);
    let opts = SoakOptions {
        frames,
        size,
        seed,
        max_geometries: 48,
    };
    println!(
        "soaking {} at {}x{} for {frames} frames on {}",
        scene.name,
        size.0,
        size.1,
        adapter.get_info().name
    );
    let bar = crate::app::progress::bar(true, frames as u64, "soak", "frames");
    let r = run(&device, &queue, &scene, &camera, &opts, |f| {
        bar.set_position(f as u64)
    })?;
    bar.finish_and_clear();
    let mib = |b: u64| b as f64 / (1024.0 * 1024.0);
    let backend = r.backend.map_or("?".to_string(), |b| b.to_string());
    println!(
        "{} frames in {:.1} s on the {backend} backend, no error",
        r.frames, r.seconds
    );
    println!(
        "  geometries: {} registered, {} updated, {} destroyed",
        r.geometries[0], r.geometries[1], r.geometries[2]
    );
    println!(
        "  instances: {} registered, {} updated, {} destroyed",
        r.instances[0], r.instances[1], r.instances[2]
    );
    println!(
        "  SDK memory: {:.2} MiB before, {:.2} MiB at the peak, {:.2} MiB after (destroyed \
         objects' memory back at the baseline, the same after both rounds)",
        mib(r.bytes[0]),
        mib(r.bytes[1]),
        mib(r.bytes[2])
    );
    if let Some([b, r0, r1]) = r.wgpu {
        println!(
            "  wgpu's allocator: {:.2} MiB in {} allocations before, {:.2} MiB in {} after round 1, \
             {:.2} MiB in {} after round 2",
            mib(b.bytes),
            b.allocations,
            mib(r0.bytes),
            r0.allocations,
            mib(r1.bytes),
            r1.allocations
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A short soak on the default scene: every frame of churn renders without an error, the
    /// churn really happened, and the allocations come back to the baseline.
    #[test]
    fn short_soak_renders_every_frame_and_gives_its_memory_back() {
        let (device, queue) = crate::app::testing::device();
        let mut scene = kickstart_rt_renderer::scene::builtin::default_scene();
        let camera = scene.prepare_view(None);
        let opts = SoakOptions {
            frames: 60,
            size: (64, 36),
            seed: 7,
            max_geometries: 12,
        };
        let r = run(device, queue, &scene, &camera, &opts, |_| {})
            .unwrap_or_else(|e| panic!("soak failed: {e}"));
        eprintln!("{r:?}");
        assert_eq!(r.frames, 60);
        // `run` itself fails when memory is not given back or grows in the second round.
        assert!(r.geometries[0] >= 10, "too little churn: {r:?}");
        assert!(
            r.geometries[1] >= 2 && r.instances[1] >= 20,
            "too little churn: {r:?}"
        );
        assert_eq!(
            r.geometries[0], r.geometries[2],
            "every geometry destroyed: {r:?}"
        );
        assert_eq!(
            r.instances[0], r.instances[2],
            "every instance destroyed: {r:?}"
        );
        assert!(
            r.bytes[1] > r.bytes[0],
            "the churn allocated nothing: {r:?}"
        );
        assert!(r.bytes[2] <= r.bytes[1], "{r:?}");
        // Vulkan reports wgpu's allocator: `run` compared the rounds by it as well.
        let Some([before, round1, _]) = r.wgpu else {
            panic!("no allocator report on a Vulkan device: {r:?}");
        };
        assert!(
            round1.allocations >= before.allocations && round1.bytes >= before.bytes,
            "{r:?}"
        );
    }
}
