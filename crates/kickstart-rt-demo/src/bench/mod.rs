//! `ksrt bench`: BLAS build and refit times, BVH quality (SAH cost against the CPU reference
//! builder), TLAS build and refit times, and ray throughput, all timed on the GPU with the SDK's
//! timestamp queries, and the trace tasks (each alone at full and checkerboard resolution, multi-light
//! shadows against the light count, the four together). Ray generation and other CPU work between
//! batches is not timed.

use std::collections::HashMap;
use std::path::PathBuf;

use glam::{Affine3A, Quat, Vec3};
use kickstart_rt as ksrt;
use serde::{Deserialize, Serialize};
use wgpu::util::DeviceExt;

use crate::gpu::{self, UploadedMesh};
use crate::scene::{self, Camera, Scene};
use crate::sdk_glue::{self as glue, GpuHit, GpuRay, Query, Tlas};
use crate::AnyResult;

mod busy;
mod cache;
pub mod denoise;
pub mod extras;
mod peer;
mod profile;
mod tree_work;

pub use peer::PeerKind;
use profile::{self as prof, PassProfile};

/// Scenes benchmarked when no `--scene` is given.
pub const DEFAULT_SCENES: [&str; 2] = ["dragon", "apartment"];

/// Instance counts of the TLAS measurements.
pub const TLAS_INSTANCE_COUNTS: [u32; 3] = [1_000, 10_000, 100_000];

/// The cameras of the ray tracing core issue for its benchmark scenes (eye, target, fov).
pub fn issue_camera(scene: &str) -> Option<Camera> {
    let c = match scene {
        "dragon" => "-0.006,0.125,0.32,-0.006,0.125,-0.005,30",
        "apartment" => "9.2,1.6,-7.3,9.2,1.0,-3.0,75",
        _ => return None,
    };
    scene::parse_camera(c).ok()
}

/// Options of `ksrt bench`.
pub struct BenchOptions {
    /// The scenes folder.
    pub scenes_dir: PathBuf,
    /// Scene names or paths.
    pub scenes: Vec<String>,
    /// Where to write the JSON report, if anywhere.
    pub json: Option<PathBuf>,
    /// Camera for every scene, overriding the issue's and the files'.
    pub camera: Option<Camera>,
    /// Timed repetitions of each measurement (after one untimed warm-up).
    pub iterations: u32,
    /// Ray batch image size.
    pub size: (u32, u32),
    /// The optional passes (`extras`).
    pub extras: extras::ExtraArgs,
    /// A peer to compare with on the same rays (`--peer`), if any.
    pub peer: Option<PeerKind>,
}

/// Median, minimum and maximum of the timed repetitions, milliseconds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Stats {
    /// Median.
    pub median_ms: f64,
    /// Fastest.
    pub min_ms: f64,
    /// Slowest.
    pub max_ms: f64,
    /// Every repetition, in order.
    pub samples_ms: Vec<f64>,
}

impl Stats {
    /// Statistics of `samples` (at least one).
    pub fn new(samples: Vec<f64>) -> Stats {
        let mut sorted = samples.clone();
        sorted.sort_by(f64::total_cmp);
        let n = sorted.len();
        let median = match n {
            0 => f64::NAN,
            _ if n % 2 == 1 => sorted[n / 2],
            _ => (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0,
        };
        Stats {
            median_ms: median,
            min_ms: sorted.first().copied().unwrap_or(f64::NAN),
            max_ms: sorted.last().copied().unwrap_or(f64::NAN),
            samples_ms: samples,
        }
    }

    fn show(&self) -> String {
        format!(
            "{:.3} ms ({:.3}..{:.3})",
            self.median_ms, self.min_ms, self.max_ms
        )
    }
}

/// BVH quality of the largest geometry.
#[derive(Debug, Clone, Serialize)]
pub struct SahReport {
    /// The geometry's name.
    pub geometry: String,
    /// Its triangles.
    pub triangles: usize,
    /// SAH cost of the SDK's GPU BLAS.
    pub gpu_sah_cost: f64,
    /// SAH cost of `kickstart_rt::cpu::CpuBvh` (binned SAH) on the same triangles.
    pub cpu_sah_cost: f64,
    /// GPU / CPU: 1 = as good as the reference builder; higher traces slower.
    pub ratio: f64,
}

/// One timed ray batch.
#[derive(Debug, Clone, Serialize)]
pub struct RayBatch {
    /// `primary`, `ao` or `diffuse`.
    pub kind: &'static str,
    /// Rays in the batch.
    pub rays: u64,
    /// Rays that hit nothing.
    pub misses: u64,
    /// GPU time of the batch (`trace rays` passes).
    pub time: Stats,
    /// Rays per second at the median time, millions.
    pub mrays_per_s: f64,
    /// Mean traversal work per ray (scenes of one instance only), from the read-back BLAS
    /// traced on the CPU in the GPU's order: with the time, the cost of one traversal step.
    pub work: Option<WorkPerRay>,
}

/// Mean work per ray of a sample of a batch's rays in the scene's one BLAS.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct WorkPerRay {
    /// Rays traced on the CPU (every n-th ray of the batch).
    pub sampled: u64,
    /// Inner BLAS nodes fetched per ray (each tests its two child boxes).
    pub nodes: f64,
    /// Ray/triangle tests per ray.
    pub triangles: f64,
    /// Share of the lanes of a [`SUBGROUP_LANES`]-lane subgroup that have work in an iteration of
    /// the traversal loop, when consecutive rays of the batch share a subgroup and it runs until
    /// its longest ray is done (one loop iteration a node or a triangle test), from about 20 000
    /// rays in whole groups; 1 means every ray of a subgroup takes as many steps as the longest.
    pub subgroup_busy: f64,
}

/// Lanes of the subgroup that [`WorkPerRay::subgroup_busy`] models (NVIDIA's warp).
const SUBGROUP_LANES: usize = 32;

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
fn work_per_ray(
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

/// Everything measured on one scene; a measurement that failed is `None` with its error in
/// `errors`.
#[derive(Debug, Clone, Serialize)]
pub struct SceneReport {
    /// Scene name or path.
    pub scene: String,
    /// Geometries (one BLAS each).
    pub meshes: usize,
    /// Instances.
    pub instances: usize,
    /// Triangles of the geometries, each counted once (what the BLAS builds process).
    pub geometry_triangles: usize,
    /// Triangles in the world (instanced ones counted per instance).
    pub world_triangles: usize,
    /// Camera of the ray batches: eye, target, vertical fov (degrees).
    pub camera: [f32; 7],
    /// All BLASes built in one task (`ingest` + `blas build` passes), fast-trace (`BuildHint::Auto`
    /// without `allow_update`).
    pub blas_build: Option<Stats>,
    /// Where the last timed BLAS build's GPU time went.
    pub blas_build_profile: Vec<PassProfile>,
    /// Geometry triangles / median BLAS build time, millions per second.
    pub blas_build_mtri_per_s: Option<f64>,
    /// The same build with `BuildHint::PreferFastBuild` (the Karras tree, one triangle a leaf).
    pub blas_build_fast_build: Option<Stats>,
    /// Where the last timed fast-build BLAS build's GPU time went.
    pub blas_build_fast_build_profile: Vec<PassProfile>,
    /// All BLASes refit after a vertex update (`ingest` + `blas refit` passes).
    pub blas_refit: Option<Stats>,
    /// Where the last timed refit's GPU time went.
    pub blas_refit_profile: Vec<PassProfile>,
    /// BVH quality of the largest geometry.
    pub sah: Option<SahReport>,
    /// Primary, AO and diffuse batches.
    pub rays: Vec<RayBatch>,
    /// (pixels + primary hits) / (primary batch time + diffuse batch time), millions of rays per
    /// second: the workload the issue compares with its peers.
    pub peer_mrays_per_s: Option<f64>,
    /// Primary rays checked against the CPU reference BVH on this GPU (untimed).
    pub oracle: Option<OracleCheck>,
    /// Direct lighting cache: bytes, injection time, cache error (`cache`).
    pub cache: Option<cache::CacheReport>,
    /// The SDK's trace tasks on a G-buffer of the primary hits (`trace …` passes).
    pub trace_tasks: Vec<TraceTaskTime>,
    /// Specular + diffuse + AO + one shadow in one GPU task, full resolution (first trace pass's
    /// start to the last one's end).
    pub trace_combined: Option<Stats>,
    /// The peer's figures on the same meshes and rays (`--peer`), or why it was skipped.
    pub peer: Option<peer::PeerReport>,
    /// `--tree-work`: other builders' trees on the same rays.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub tree_work: Vec<tree_work::TreeWork>,
    /// Measurements that failed, and why.
    pub errors: Vec<String>,
}

/// GPU time of one trace task at the bench size.
#[derive(Debug, Clone, Serialize)]
pub struct TraceTaskTime {
    /// `specular`, `diffuse`, `ao`, `shadow` or `multi_shadow`.
    pub task: &'static str,
    /// Checkerboard half resolution.
    pub checkerboard: bool,
    /// Lights (shadow tasks; 0 otherwise).
    pub lights: u32,
    /// GPU time of the task's pass.
    pub time: Stats,
}

/// A sample of primary rays traced again on the CPU reference BVH (world-space triangles): the
/// evidence that the measured tracer is also right on this GPU.
#[derive(Debug, Clone, Serialize)]
pub struct OracleCheck {
    /// Rays compared.
    pub rays: usize,
    /// Rays where hit/miss differs, or the distances differ by more than 1e-3 relative.
    pub disagreements: usize,
}

/// TLAS build and refit over `instances` instances of one small mesh with random transforms.
#[derive(Debug, Clone, Serialize)]
pub struct TlasReport {
    /// Instances.
    pub instances: u32,
    /// Rebuild after every transform changed (`tlas build` passes).
    pub build: Option<Stats>,
    /// Where the last timed rebuild's GPU time went.
    pub build_profile: Vec<PassProfile>,
    /// Refit after every transform changed (`tlas refit` passes).
    pub refit: Option<Stats>,
    /// Where the last timed refit's GPU time went.
    pub refit_profile: Vec<PassProfile>,
    /// Measurements that failed, and why.
    pub errors: Vec<String>,
}

/// The whole `--json` report.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// kickstart-rt version.
    pub sdk_version: String,
    /// Adapter name.
    pub adapter: String,
    /// Driver name and version, as wgpu reports them.
    pub driver: String,
    /// The commit `ksrt` was built from (embedded at build time; `-dirty` with local changes).
    pub commit: String,
    /// wgpu backend.
    pub backend: String,
    /// Whether the device has timestamp queries (without them nothing is timed).
    pub timestamp_query: bool,
    /// Ray batch image width.
    pub width: u32,
    /// Ray batch image height.
    pub height: u32,
    /// Timed repetitions per measurement.
    pub iterations: u32,
    /// Order of the ray batches' primary rays.
    pub ray_order: extras::RayOrder,
    /// GPU work (milliseconds at full clocks) submitted untimed before each timed task
    /// (`--busy-gpu-ms`; 0: none).
    pub busy_gpu_ms: f64,
    /// Per scene.
    pub scenes: Vec<SceneReport>,
    /// Per instance count.
    pub tlas: Vec<TlasReport>,
    /// The optional passes' results (`cpu_peers`, `scaling`, `frames_in_flight`).
    #[serde(flatten)]
    pub extras: extras::ExtrasReport,
}

/// Runs `f`, keeping its error as text in `errors` (labelled `what`) so that one failed
/// measurement does not hide the others.
fn attempt<T>(errors: &mut Vec<String>, what: &str, f: impl FnOnce() -> AnyResult<T>) -> Option<T> {
    match f() {
        Ok(v) => Some(v),
        Err(e) => {
            // Printed with the scene's results; the log gets it at once for long runs.
            log::debug!("{what}: {e}");
            errors.push(format!("{what}: {e}"));
            None
        }
    }
}

/// A small deterministic generator (SplitMix64): benchmark inputs are the same on every run.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1).
    fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }

    /// A cosine-weighted direction about the unit vector `n`.
    fn cosine(&mut self, n: Vec3) -> Vec3 {
        let (t, b) = n.any_orthonormal_pair();
        let (r1, r2) = (self.f32(), self.f32());
        let phi = std::f32::consts::TAU * r1;
        let r = r2.sqrt();
        (t * (r * phi.cos()) + b * (r * phi.sin()) + n * (1.0 - r2).max(0.0).sqrt()).normalize()
    }
}

/// The shared device state of one benchmark run.
struct Bench<'a> {
    device: &'a wgpu::Device,
    queue: &'a wgpu::Queue,
    iterations: u32,
    /// Order of the primary rays of the ray batches (`--ray-order`).
    ray_order: extras::RayOrder,
    /// The passes of the last task `timed` measured, for the figure's profile.
    last_passes: std::cell::RefCell<Vec<ksrt::PassTiming>>,
    /// Whether a measurement ran already (the first warms up longer, see [`Bench::repeat`]).
    warmed: std::cell::Cell<bool>,
    /// Submitted before each timed task (`--busy-gpu-ms`).
    busy: Option<busy::BusyGpu>,
    /// The measurements to run (`--sections`; empty: all).
    sections: Vec<extras::Section>,
}

impl<'a> Bench<'a> {
    /// A bench on `device`, timing `iterations` repetitions of each measurement.
    fn new(device: &'a wgpu::Device, queue: &'a wgpu::Queue, iterations: u32) -> Self {
        Bench {
            device,
            queue,
            iterations,
            ray_order: extras::RayOrder::Rows,
            last_passes: Default::default(),
            warmed: Default::default(),
            busy: None,
            sections: Vec::new(),
        }
    }

    /// TLAS rebuild over `scene`'s instances, every transform updated (to the same values: the
    /// rebuild does the same work whatever they are), span `tlas build`.
    fn tlas_rebuild(&self, scene: &Scene, uploads: &[UploadedMesh]) -> AnyResult<Stats> {
        let (ctx, h) = self.registered(scene, uploads, false, true)?;
        self.repeat(|_| {
            let mut c = ctx.create_task_container();
            for (inst, &handle) in scene.instances.iter().zip(&h.instances) {
                c.schedule_bvh_task(ksrt::InstanceTask {
                    operation: ksrt::TaskOperation::Update,
                    handle,
                    input: ksrt::InstanceInput::new(h.geometries[inst.mesh], inst.transform),
                });
            }
            c.schedule_bvh_task(glue::bvh_build_task(1, Some(Tlas::Rebuild)));
            self.timed(&ctx, c, &["tlas build"], |_| {})
        })
    }

    fn context(&self) -> AnyResult<ksrt::ExecuteContext> {
        let ctx = ksrt::ExecuteContext::new(self.device, self.queue, glue::init_settings(true))?;
        glue::prepare_pipelines(&ctx)?;
        Ok(ctx)
    }

    /// Submits `container`, waits, and returns the GPU time of the passes `span` names.
    fn timed(
        &self,
        ctx: &ksrt::ExecuteContext,
        container: ksrt::TaskContainer,
        span: &[&str],
        after: impl FnOnce(&mut wgpu::CommandEncoder),
    ) -> AnyResult<f64> {
        if let Some(busy) = &self.busy {
            busy.submit(self.device, self.queue);
        }
        let task = gpu::submit(ctx, self.device, self.queue, container, after)?;
        let timings = ctx.wait_for_gpu_timings(task);
        gpu::complete(ctx, self.device, task)?;
        let timings = timings?;
        let ms = glue::span_ms(&timings, span)?;
        *self.last_passes.borrow_mut() = prof::within(timings.passes, span);
        Ok(ms)
    }

    /// The profile of the last task `timed` measured.
    fn last_profile(&self) -> Vec<PassProfile> {
        prof::profile(&self.last_passes.borrow())
    }

    /// Runs `one` untimed for at least half a second (warm-up: GPU clocks ramp up from idle,
    /// and one short run left them low enough to skew sub-millisecond passes 2–4× on the H100),
    /// then `iterations` times timed.
    ///
    /// The first measurement of a run warms up for 2 s instead: on a freshly started H100 the
    /// first figure (the dragon's BLAS build) measured 1.66 ms after 0.5 s, every pass about
    /// 1.8× slower than the same binary's 0.93 ms in another run, while later figures agreed.
    fn repeat(&self, mut one: impl FnMut(bool) -> AnyResult<f64>) -> AnyResult<Stats> {
        let warm_up_ms = if self.warmed.replace(true) { 500 } else { 2000 };
        let start = std::time::Instant::now();
        one(false)?;
        while start.elapsed() < std::time::Duration::from_millis(warm_up_ms) {
            one(false)?;
        }
        let samples = (0..self.iterations)
            .map(|_| one(true))
            .collect::<AnyResult<Vec<f64>>>()?;
        Ok(Stats::new(samples))
    }

    /// Registers the scene's geometries (and instances) and builds every BVH, untimed.
    fn registered(
        &self,
        scene: &Scene,
        uploads: &[UploadedMesh],
        allow_update: bool,
        instances: bool,
    ) -> AnyResult<(ksrt::ExecuteContext, gpu::SceneHandles)> {
        let ctx = self.context()?;
        let mut c = ctx.create_task_container();
        let h = gpu::schedule_scene(
            &ctx,
            &mut c,
            scene,
            uploads,
            allow_update,
            ksrt::BuildHint::Auto,
            instances,
        );
        c.schedule_bvh_task(glue::bvh_build_task(
            uploads.len() as u32,
            instances.then_some(Tlas::Auto),
        ));
        let task = gpu::submit(&ctx, self.device, self.queue, c, |_| {})?;
        gpu::complete(&ctx, self.device, task)?;
        Ok((ctx, h))
    }

    /// (a) Every BLAS built in one task with `build_hint`, from newly registered geometry each
    /// time (the previous repetition's geometry destroyed first). Returns the context and the last
    /// handles for the SAH read-back.
    ///
    /// One context serves every repetition: with a fresh context per build, its set-up (pipelines,
    /// pools) left the GPU idle between builds, its clocks fell, and the same build measured
    /// 1.25 ms in one H100 run and 4.2 ms in another.
    fn blas_build(
        &self,
        scene: &Scene,
        uploads: &[UploadedMesh],
        build_hint: ksrt::BuildHint,
    ) -> AnyResult<(Stats, ksrt::ExecuteContext, gpu::SceneHandles)> {
        let ctx = self.context()?;
        let mut last: Option<gpu::SceneHandles> = None;
        let stats = self.repeat(|_| {
            if let Some(old) = last.take() {
                ctx.destroy_geometry_handles(&old.geometries)?;
            }
            let mut c = ctx.create_task_container();
            let h = gpu::schedule_scene(&ctx, &mut c, scene, uploads, false, build_hint, false);
            c.schedule_bvh_task(glue::bvh_build_task(uploads.len() as u32, None));
            let ms = self.timed(&ctx, c, &["ingest", "blas build"], |_| {})?;
            last = Some(h);
            Ok(ms)
        })?;
        let h = last.ok_or("no BLAS build ran")?;
        Ok((stats, ctx, h))
    }

    /// (b) Every BLAS refit after an update of all its vertices (the same positions again: the
    /// refit does the same work whatever they are).
    fn blas_refit(&self, scene: &Scene, uploads: &[UploadedMesh]) -> AnyResult<Stats> {
        let (ctx, h) = self.registered(scene, uploads, true, false)?;
        self.repeat(|_| {
            let mut c = ctx.create_task_container();
            for (m, &handle) in uploads.iter().zip(&h.geometries) {
                c.schedule_bvh_task(ksrt::GeometryTask {
                    operation: ksrt::TaskOperation::Update,
                    handle,
                    input: gpu::geometry_input(m, true),
                });
            }
            c.schedule_bvh_task(glue::bvh_build_task(uploads.len() as u32, None));
            self.timed(&ctx, c, &["ingest", "blas refit"], |_| {})
        })
    }

    /// Traces `rays` (`iterations` timed times after a warm-up) and returns the last hits.
    fn trace(
        &self,
        ctx: &ksrt::ExecuteContext,
        rays: &[GpuRay],
        query: Query,
    ) -> AnyResult<(Stats, Vec<GpuHit>)> {
        if rays.is_empty() {
            return Ok((Stats::new(vec![0.0]), Vec::new()));
        }
        let limits = self.device.limits();
        let bytes = std::mem::size_of_val(rays) as u64;
        if bytes > limits.max_buffer_size {
            return Err(format!(
                "{} rays need {bytes} bytes, more than the device's largest buffer ({}); use a smaller --size",
                rays.len(),
                limits.max_buffer_size
            )
            .into());
        }
        // One task per chunk that fits a storage binding; chunk offsets keep the device's
        // storage offset alignment.
        let align_rays = (limits.min_storage_buffer_offset_alignment as u64 / 32).max(1);
        let chunk = (limits.max_storage_buffer_binding_size / 32) / align_rays * align_rays;
        let ray_buffer = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("ksrt bench rays"),
                contents: bytemuck::cast_slice(rays),
                usage: wgpu::BufferUsages::STORAGE,
            });
        let hit_buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ksrt bench hits"),
            size: bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let readback = gpu::readback_buffer(self.device, bytes);
        let count = rays.len() as u64;
        let mut timed_runs = 0;
        let stats = self.repeat(|timed| {
            if timed {
                timed_runs += 1;
            }
            let mut c = ctx.create_task_container();
            let mut first = 0u64;
            while first < count {
                let n = chunk.min(count - first);
                c.schedule_render_task(glue::trace_rays_task(
                    &ray_buffer,
                    &hit_buffer,
                    first * 32,
                    n as u32,
                    query,
                )?);
                first += n;
            }
            // Only the last repetition's hits are read back; the copy is outside the timed passes.
            let read = timed && timed_runs == self.iterations;
            self.timed(ctx, c, &["trace rays"], |e| {
                if read {
                    e.copy_buffer_to_buffer(&hit_buffer, 0, &readback, 0, bytes);
                }
            })
        })?;
        let hits = gpu::map_read(self.device, &readback)?
            .chunks_exact(std::mem::size_of::<GpuHit>())
            .map(bytemuck::pod_read_unaligned::<GpuHit>)
            .collect();
        Ok((stats, hits))
    }
}

/// Where a primary hit is and which way its surface faces (against the ray).
struct Surface {
    point: Vec3,
    normal: Vec3,
}

/// The geometric normal of a primary hit, from the mesh's triangle on the CPU; `None` when the
/// hit's instance or primitive is not one the scene has.
fn surface(
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

fn batch(kind: &'static str, rays: usize, hits: &[GpuHit], time: Stats) -> RayBatch {
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
fn rays(
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
struct RayBatches {
    /// Our instance slot index of each scene instance (what hits report).
    slots: Vec<u32>,
    /// Width of the primary rays' image (their row length).
    width: u32,
    /// Kind, query, rays and our hits of each batch, in the order measured.
    batches: Vec<(&'static str, Query, Vec<GpuRay>, Vec<GpuHit>)>,
    /// The scene's one BLAS as read back (scenes of one instance).
    blas: Option<ksrt::cpu::BlasReadback>,
}

/// One primary ray per pixel through `camera`, row by row from the top: their directions and the
/// rays (from the eye, t in [0, ∞)).
fn primary_rays(camera: &Camera, size: (u32, u32)) -> (Vec<Vec3>, Vec<GpuRay>) {
    primary_rays_in(camera, size, extras::RayOrder::Rows)
}

/// [`primary_rays`] with the pixels in `order`.
fn primary_rays_in(
    camera: &Camera,
    (width, height): (u32, u32),
    order: extras::RayOrder,
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
fn secondary_rays(surfaces: &[Surface], offset: f32, rng: &mut Rng, t_max: f32) -> Vec<GpuRay> {
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

/// Compares about 20 000 primary hits with the CPU reference BVH over the world's triangles.
fn oracle_check(scene: &Scene, rays: &[GpuRay], hits: &[GpuHit]) -> OracleCheck {
    let world: Vec<[Vec3; 3]> = scene
        .instances
        .iter()
        .flat_map(|i| scene.meshes[i.mesh].triangles(i.transform))
        .collect();
    let bvh = ksrt::cpu::CpuBvh::build(&world);
    let step = (rays.len() / 20_000).max(1);
    let mut check = OracleCheck {
        rays: 0,
        disagreements: 0,
    };
    for (r, h) in rays.iter().zip(hits).step_by(step) {
        let cpu = bvh.closest_hit(
            &world,
            &ksrt::cpu::Ray {
                origin: Vec3::from(r.origin),
                dir: Vec3::from(r.dir),
                t_min: r.t_min,
                t_max: r.t_max,
            },
        );
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

impl SceneReport {
    /// The report of `scene` before anything is measured.
    fn new(name: &str, scene: &Scene, camera: &Camera) -> SceneReport {
        SceneReport {
            scene: name.to_string(),
            meshes: scene.meshes.len(),
            instances: scene.instances.len(),
            geometry_triangles: scene.meshes.iter().map(|m| m.triangle_count()).sum(),
            world_triangles: scene.triangle_count(),
            camera: [
                camera.eye.x,
                camera.eye.y,
                camera.eye.z,
                camera.at.x,
                camera.at.y,
                camera.at.z,
                camera.fov_y_deg,
            ],
            blas_build: None,
            blas_build_profile: Vec::new(),
            blas_build_mtri_per_s: None,
            blas_build_fast_build: None,
            blas_build_fast_build_profile: Vec::new(),
            blas_refit: None,
            blas_refit_profile: Vec::new(),
            sah: None,
            rays: Vec::new(),
            peer_mrays_per_s: None,
            oracle: None,
            cache: None,
            trace_tasks: Vec::new(),
            trace_combined: None,
            peer: None,
            tree_work: Vec::new(),
            errors: Vec::new(),
        }
    }
}

/// Benchmarks one scene.
fn bench_scene(
    bench: &Bench,
    name: &str,
    scene: &Scene,
    camera: Camera,
    size: (u32, u32),
    peer: Option<&mut peer::PeerState>,
    measure_tree_work: bool,
) -> SceneReport {
    let mut r = SceneReport::new(name, scene, &camera);
    let uploads = gpu::upload_scene(bench.device, scene);
    let mut errors = Vec::new();
    let runs = |s: extras::Section| s.runs_in(&bench.sections);
    let builds = runs(extras::Section::Builds);
    if let Some((stats, ctx, h)) = builds
        .then(|| {
            attempt(&mut errors, "BLAS build", || {
                bench.blas_build(scene, &uploads, ksrt::BuildHint::Auto)
            })
        })
        .flatten()
    {
        r.blas_build_profile = bench.last_profile();
        r.blas_build_mtri_per_s = Some(r.geometry_triangles as f64 / (stats.median_ms * 1e3));
        r.blas_build = Some(stats);
        r.sah = attempt(&mut errors, "SAH cost", || {
            let (k, mesh) = scene
                .meshes
                .iter()
                .enumerate()
                .max_by_key(|(_, m)| m.triangle_count())
                .ok_or("the scene has no geometry")?;
            let gpu_sah_cost = glue::blas_sah_cost(&ctx, h.geometries[k])?;
            let tris: Vec<[Vec3; 3]> = mesh.triangles(Affine3A::IDENTITY).collect();
            let cpu = ksrt::cpu::CpuBvh::build(&tris);
            if cpu.nodes.is_empty() {
                return Err(
                    format!("{}: no finite triangle to build a CPU BVH over", mesh.name).into(),
                );
            }
            let cpu_sah_cost = cpu.sah_cost() as f64;
            Ok(SahReport {
                geometry: mesh.name.clone(),
                triangles: tris.len(),
                gpu_sah_cost,
                cpu_sah_cost,
                ratio: gpu_sah_cost / cpu_sah_cost,
            })
        });
    }
    if builds {
        r.blas_build_fast_build = attempt(&mut errors, "BLAS build (fast-build)", || {
            Ok(bench
                .blas_build(scene, &uploads, ksrt::BuildHint::PreferFastBuild)?
                .0)
        });
        if r.blas_build_fast_build.is_some() {
            r.blas_build_fast_build_profile = bench.last_profile();
        }
        r.blas_refit = attempt(&mut errors, "BLAS refit", || {
            bench.blas_refit(scene, &uploads)
        });
        if r.blas_refit.is_some() {
            r.blas_refit_profile = bench.last_profile();
        }
    }
    let batches = runs(extras::Section::Rays)
        .then(|| {
            attempt(&mut errors, "rays", || {
                rays(bench, scene, &uploads, &camera, size, &mut r)
            })
        })
        .flatten();
    if let (true, Some(b)) = (measure_tree_work, &batches) {
        let rays: Vec<(&'static str, bool, &[GpuRay])> = b
            .batches
            .iter()
            .map(|(kind, query, rays, _)| (*kind, matches!(query, Query::Any), rays.as_slice()))
            .collect();
        if let Some(trees) = attempt(&mut errors, "tree work", || {
            tree_work::measure(scene, &rays, b.blas.as_ref())
        }) {
            let gpu: Vec<(String, Option<WorkPerRay>)> = r
                .rays
                .iter()
                .map(|b| (b.kind.to_string(), b.work))
                .collect();
            tree_work::print(&gpu, &trees);
            r.tree_work = trees;
        }
    }
    if let Some(p) = peer {
        r.peer = Some(peer::compare(
            bench,
            p,
            scene,
            &uploads,
            batches.as_ref(),
            &r,
        ));
    }
    if runs(extras::Section::Cache) {
        r.cache = attempt(&mut errors, "lighting cache", || {
            cache::cache_bench(bench, scene, &uploads, &camera, size)
        });
    }
    if runs(extras::Section::Tasks) {
        attempt(&mut errors, "trace tasks", || {
            trace_tasks(bench, scene, &uploads, &camera, size, &mut r)
        });
    }
    r.errors = errors;
    r
}

/// (d) TLAS build and refit over `count` random instances of a small sphere.
fn bench_tlas(bench: &Bench, count: u32) -> TlasReport {
    let mut errors = Vec::new();
    let sphere = {
        let (p, i) = crate::scene::builtin::icosphere(1);
        crate::scene::Mesh::new("tlas sphere", p, i, Vec3::ONE)
    };
    let run = |tlas: Tlas, span: &'static str| -> AnyResult<Stats> {
        let mesh = sphere.clone()?;
        let upload = gpu::upload(bench.device, &mesh);
        let ctx = bench.context()?;
        let geometry = ctx.create_geometry_handle();
        let instances = ctx.create_instance_handles(count as usize);
        let mut rng = Rng(u64::from(count));
        // Spread the instances through a cube that holds them about 3 radii apart.
        let extent = (count as f32).cbrt() * 3.0;
        let mut random = move || {
            let axis = Vec3::new(rng.f32() - 0.5, rng.f32() - 0.5, rng.f32() - 0.5)
                .try_normalize()
                .unwrap_or(Vec3::Y);
            Affine3A::from_scale_rotation_translation(
                Vec3::splat(0.5 + rng.f32()),
                Quat::from_axis_angle(axis, rng.f32() * std::f32::consts::TAU),
                (Vec3::new(rng.f32(), rng.f32(), rng.f32()) - 0.5) * extent,
            )
        };
        let mut c = ctx.create_task_container();
        c.schedule_bvh_task(ksrt::GeometryTask {
            operation: ksrt::TaskOperation::Register,
            handle: geometry,
            input: gpu::geometry_input(&upload, false),
        });
        for &h in &instances {
            c.schedule_bvh_task(ksrt::InstanceTask {
                operation: ksrt::TaskOperation::Register,
                handle: h,
                input: ksrt::InstanceInput::new(geometry, random()),
            });
        }
        c.schedule_bvh_task(glue::bvh_build_task(1, Some(Tlas::Rebuild)));
        let task = gpu::submit(&ctx, bench.device, bench.queue, c, |_| {})?;
        gpu::complete(&ctx, bench.device, task)?;
        // Each repetition moves every instance, so the SDK has a TLAS to rebuild or refit.
        bench.repeat(|_| {
            let mut c = ctx.create_task_container();
            for &h in &instances {
                c.schedule_bvh_task(ksrt::InstanceTask {
                    operation: ksrt::TaskOperation::Update,
                    handle: h,
                    input: ksrt::InstanceInput::new(geometry, random()),
                });
            }
            c.schedule_bvh_task(glue::bvh_build_task(1, Some(tlas)));
            bench.timed(&ctx, c, &[span], |_| {})
        })
    };
    let build = attempt(
        &mut errors,
        &format!("TLAS build, {count} instances"),
        || run(Tlas::Rebuild, "tlas build"),
    );
    let build_profile = build.as_ref().map_or(Vec::new(), |_| bench.last_profile());
    let refit = attempt(
        &mut errors,
        &format!("TLAS refit, {count} instances"),
        || run(Tlas::Refit, "tlas refit"),
    );
    let refit_profile = refit.as_ref().map_or(Vec::new(), |_| bench.last_profile());
    TlasReport {
        instances: count,
        build,
        build_profile,
        refit,
        refit_profile,
        errors,
    }
}

fn print_scene(r: &SceneReport, (w, h): (u32, u32)) {
    let opt = |s: &Option<Stats>| s.as_ref().map_or("—".to_string(), Stats::show);
    println!(
        "\n{}: {} geometries, {} instances, {} geometry triangles ({} in the world)",
        r.scene, r.meshes, r.instances, r.geometry_triangles, r.world_triangles
    );
    println!(
        "  BLAS build   {}{}",
        opt(&r.blas_build),
        r.blas_build_mtri_per_s
            .map_or(String::new(), |m| format!("  {m:.1} Mtri/s"))
    );
    if !r.blas_build_profile.is_empty() {
        println!("    profile    {}", prof::show(&r.blas_build_profile));
    }
    println!("  fast-build   {}", opt(&r.blas_build_fast_build));
    if !r.blas_build_fast_build_profile.is_empty() {
        println!(
            "    profile    {}",
            prof::show(&r.blas_build_fast_build_profile)
        );
    }
    println!("  BLAS refit   {}", opt(&r.blas_refit));
    if !r.blas_refit_profile.is_empty() {
        println!("    profile    {}", prof::show(&r.blas_refit_profile));
    }
    match &r.sah {
        Some(s) => println!(
            "  SAH cost     GPU {:.2} / CPU {:.2} = {:.3} ({}, {} triangles)",
            s.gpu_sah_cost, s.cpu_sah_cost, s.ratio, s.geometry, s.triangles
        ),
        None => println!("  SAH cost     —"),
    }
    println!("  rays at {w}x{h}:");
    for b in &r.rays {
        println!(
            "    {:<8} {:>9} rays {:>9} misses  {}  {:.1} Mrays/s",
            b.kind,
            b.rays,
            b.misses,
            b.time.show(),
            b.mrays_per_s
        );
        if let Some(w) = b.work {
            // Node fetches of the whole batch per second: the traversal's step rate.
            let g_nodes_per_s = b.rays as f64 * w.nodes / (b.time.median_ms * 1e6);
            println!(
                "      work     {:.1} BLAS nodes + {:.1} triangle tests per ray ({} sampled): \
                 {:.1} G node fetches/s; {}-lane subgroups {:.0} % busy",
                w.nodes,
                w.triangles,
                w.sampled,
                g_nodes_per_s,
                SUBGROUP_LANES,
                w.subgroup_busy * 100.0
            );
        }
    }
    if let Some(p) = r.peer_mrays_per_s {
        println!("    peer workload (primary + diffuse from hits): {p:.1} Mrays/s");
    }
    if let Some(o) = &r.oracle {
        println!(
            "  CPU oracle   {} of {} sampled primary rays disagree (hit/miss, or t beyond 1e-3)",
            o.disagreements, o.rays
        );
    }
    if let Some(c) = &r.cache {
        println!(
            "  cache        {:.1} MiB of surfels ({:.1} MiB held), {} degraded instances",
            c.surfel_bytes as f64 / 1048576.0,
            c.cache_bytes as f64 / 1048576.0,
            c.degraded_instances
        );
        for (stride, t) in &c.injection {
            println!("  injection    stride {stride}: {}", t.show());
        }
        for (tasks, e) in &c.error {
            println!("  cache error  after {tasks:>2} injections: {:.4}", e);
        }
    }
    if !r.trace_tasks.is_empty() {
        println!("  trace tasks at {w}x{h} (G-buffer of the primary hits):");
    }
    for t in &r.trace_tasks {
        let lights = if t.lights > 0 {
            format!(" {:>2} lights", t.lights)
        } else {
            String::new()
        };
        println!(
            "    {:<12}{:<10}{}  {}",
            t.task,
            lights,
            if t.checkerboard { " checkerboard" } else { "" },
            t.time.show()
        );
    }
    if let Some(c) = &r.trace_combined {
        println!(
            "    specular + diffuse + AO + shadow together: {}",
            c.show()
        );
    }
    for e in &r.errors {
        println!("  failed: {e}");
    }
}

/// Light counts of the multi-shadow measurement.
pub const SHADOW_LIGHT_COUNTS: [u32; 6] = [1, 2, 4, 8, 16, 32];

/// A G-buffer texture (Rgba32Float, sampled) holding `texels`.
fn gbuffer_texture(bench: &Bench, (w, h): (u32, u32), texels: &[[f32; 4]]) -> wgpu::TextureView {
    bench
        .device
        .create_texture_with_data(
            bench.queue,
            &wgpu::TextureDescriptor {
                label: Some("bench g-buffer"),
                size: wgpu::Extent3d {
                    width: w,
                    height: h,
                    depth_or_array_layers: 1,
                },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba32Float,
                usage: wgpu::TextureUsages::TEXTURE_BINDING,
                view_formats: &[],
            },
            wgpu::util::TextureDataOrder::LayerMajor,
            bytemuck::cast_slice(texels),
        )
        .create_view(&Default::default())
}

/// A trace output of `format` at the bench size.
fn trace_output(
    bench: &Bench,
    (w, h): (u32, u32),
    format: wgpu::TextureFormat,
) -> wgpu::TextureView {
    bench
        .device
        .create_texture(&wgpu::TextureDescriptor {
            label: Some("bench trace output"),
            size: wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: wgpu::TextureUsages::STORAGE_BINDING,
            view_formats: &[],
        })
        .create_view(&Default::default())
}

/// (f) The trace tasks on a G-buffer made from primary rays traced through the SDK (world
/// positions and geometric normals of the hits, computed on the CPU from the hit records: no
/// rasteriser involved). Each task alone at full and checkerboard resolution, multi-light
/// shadows against the light count, and specular + diffuse + AO + one shadow together.
fn trace_tasks(
    bench: &Bench,
    scene: &Scene,
    uploads: &[UploadedMesh],
    camera: &Camera,
    (width, height): (u32, u32),
    report: &mut SceneReport,
) -> AnyResult<()> {
    let (ctx, handles) = bench.registered(scene, uploads, false, true)?;
    let slots = handles.instance_of_slot();
    let (dirs, primary) = primary_rays(camera, (width, height));
    let (_, hits) = bench.trace(&ctx, &primary, Query::Closest)?;
    let mut positions = vec![[f32::NAN; 4]; hits.len()];
    let mut normals = vec![[0.0f32; 4]; hits.len()];
    for (i, (h, d)) in hits.iter().zip(&dirs).enumerate() {
        if let Some(s) = h.is_hit().then(|| surface(scene, &slots, h, *d)).flatten() {
            positions[i] = s.point.extend(1.0).to_array();
            normals[i] = s.normal.extend(0.0).to_array();
        }
    }
    let size = (width, height);
    let depth = gbuffer_texture(bench, size, &positions);
    let normal = gbuffer_texture(bench, size, &normals);
    let extent = scene.size();
    let (world_to_view, view_to_clip) =
        camera.matrices(width as f32 / height as f32, extent * 1e-4, extent * 4.0);
    let mut common = ksrt::TraceTaskCommon::new(
        ksrt::DepthInput {
            texture: depth,
            depth_type: ksrt::DepthType::RgbWorldSpace,
        },
        ksrt::NormalInput {
            texture: normal,
            normal_type: ksrt::NormalType::RgbVector,
            normal_to_world: glam::Mat4::IDENTITY,
        },
    );
    common.view.world_to_view = world_to_view;
    common.view.view_to_clip = view_to_clip;
    common.view.prev_world_to_view = world_to_view;
    common.view.prev_view_to_clip = view_to_clip;
    common.ray_offset.offset_type = ksrt::RayOffsetType::WorldPosition;
    let radiance = trace_output(bench, size, wgpu::TextureFormat::Rgba16Float);
    let radiance2 = trace_output(bench, size, wgpu::TextureFormat::Rgba16Float);
    let scalar = trace_output(bench, size, wgpu::TextureFormat::R32Float);
    let scalar2 = trace_output(bench, size, wgpu::TextureFormat::R32Float);
    let packed = trace_output(bench, size, wgpu::TextureFormat::Rgba16Float);
    // Lights around the camera, at a tenth of the view distance, so every light matters.
    let reach = (camera.at - camera.eye).length().max(extent * 0.01);
    let mut rng = Rng(0x5348_4457);
    let lights: Vec<ksrt::LightInfo> = (0..32)
        .map(|_| {
            let d = Vec3::new(rng.f32() - 0.5, rng.f32() * 0.5, rng.f32() - 0.5);
            ksrt::LightInfo::Point {
                position: camera.eye + d * reach * 0.5,
                radius: reach * 0.01,
                range: extent * 4.0,
            }
        })
        .collect();
    let sun = ksrt::LightInfo::Directional {
        direction: Vec3::new(0.3, -1.0, 0.2).normalize(),
        angular_extent: 0.0093,
    };
    let tasks = |c: &ksrt::TraceTaskCommon| {
        vec![
            (
                "specular",
                0,
                ksrt::RenderTask::TraceSpecular(ksrt::TraceSpecularTask {
                    common: c.clone(),
                    output: radiance.clone(),
                    demodulate_specular: false,
                    demodulation_output: None,
                }),
            ),
            (
                "diffuse",
                0,
                ksrt::RenderTask::TraceDiffuse(ksrt::TraceDiffuseTask {
                    common: c.clone(),
                    output: radiance2.clone(),
                    diffuse_brdf: ksrt::DiffuseBrdf::Lambertian,
                }),
            ),
            (
                "ao",
                0,
                ksrt::RenderTask::TraceAmbientOcclusion(ksrt::TraceAmbientOcclusionTask {
                    common: c.clone(),
                    output: scalar.clone(),
                    ao_radius: extent * 0.05,
                }),
            ),
            (
                "shadow",
                1,
                ksrt::RenderTask::TraceShadow(ksrt::TraceShadowTask {
                    common: c.clone(),
                    output: scalar2.clone(),
                    light: sun,
                    enable_first_hit_and_end_search: true,
                }),
            ),
        ]
    };
    let multi = |c: &ksrt::TraceTaskCommon, n: u32| {
        ksrt::RenderTask::TraceMultiShadow(ksrt::TraceMultiShadowTask {
            common: c.clone(),
            output0: packed.clone(),
            output1: radiance2.clone(),
            lights: lights[..n as usize].to_vec(),
            enable_first_hit_and_end_search: true,
        })
    };
    let time_one = |task: &ksrt::RenderTask| {
        bench.repeat(|_| {
            let mut c = ctx.create_task_container();
            c.schedule_render_task(task.clone());
            // The trace tasks' passes are timed under the scope "trace" (their pass names say
            // which task); these containers hold no ray batches ("trace rays").
            bench.timed(&ctx, c, &["trace"], |_| {})
        })
    };
    for checkerboard in [false, true] {
        let mut c = common.clone();
        if checkerboard {
            c.half_resolution_mode = ksrt::HalfResolutionMode::Checkerboard;
        }
        for (name, lights, task) in tasks(&c) {
            report.trace_tasks.push(TraceTaskTime {
                task: name,
                checkerboard,
                lights,
                time: time_one(&task)?,
            });
        }
        report.trace_tasks.push(TraceTaskTime {
            task: "multi_shadow",
            checkerboard,
            lights: 4,
            time: time_one(&multi(&c, 4))?,
        });
    }
    for n in SHADOW_LIGHT_COUNTS {
        report.trace_tasks.push(TraceTaskTime {
            task: "multi_shadow",
            checkerboard: false,
            lights: n,
            time: time_one(&multi(&common, n))?,
        });
    }
    report.trace_combined = Some(bench.repeat(|_| {
        let mut c = ctx.create_task_container();
        for (_, _, t) in tasks(&common) {
            c.schedule_render_task(t);
        }
        bench.timed(&ctx, c, &["trace"], |_| {})
    })?);
    Ok(())
}

/// `ksrt bench`.
pub fn run(opts: BenchOptions) -> AnyResult<()> {
    if opts.iterations == 0 {
        return Err("--iterations must be at least 1".into());
    }
    // Load every scene first: a wrong name fails before minutes of GPU work.
    opts.extras.check()?;
    if opts.peer.is_some() && opts.extras.ray_order != extras::RayOrder::Rows {
        // The driver peer launches the rays as a 2-D image of rows (its own tiling of the launch
        // then decides their grouping), so tiled rays would be compared in a scrambled order.
        return Err("--peer needs --ray-order rows (the peer's launch is row by row)".into());
    }
    let names: Vec<String> = if opts.extras.skip_scenes {
        Vec::new()
    } else if opts.scenes.is_empty() {
        DEFAULT_SCENES.iter().map(|s| s.to_string()).collect()
    } else {
        opts.scenes.clone()
    };
    let mut scenes = Vec::new();
    for name in &names {
        let start = std::time::Instant::now();
        let loaded = scene::load(name, &opts.scenes_dir)?;
        scenes.push(if opts.extras.flatten {
            loaded.flattened()?
        } else {
            loaded
        });
        println!("loaded {name} in {:.2} s", start.elapsed().as_secs_f64());
    }
    let adapter = gpu::adapter()?;
    let timestamp_query = adapter.features().contains(wgpu::Features::TIMESTAMP_QUERY);
    if !timestamp_query {
        log::warn!("the adapter has no TIMESTAMP_QUERY: GPU times cannot be measured");
    }
    let (device, queue) = gpu::device(&adapter)?;
    let info = adapter.get_info();
    println!(
        "kickstart-rt {} (commit {}) bench on {} ({:?}, driver {} {}), {} iterations after a warm-up",
        ksrt::VERSION,
        env!("KSRT_COMMIT"),
        info.name,
        info.backend,
        info.driver,
        info.driver_info,
        opts.iterations
    );
    let mut bench = Bench::new(&device, &queue, opts.iterations);
    bench.ray_order = opts.extras.ray_order;
    bench.sections = opts.extras.sections.clone();
    if opts.extras.busy_gpu_ms > 0.0 {
        bench.busy = Some(busy::BusyGpu::new(&device, opts.extras.busy_gpu_ms));
        println!(
            "each timed task follows ~{} ms of untimed GPU work (--busy-gpu-ms)",
            opts.extras.busy_gpu_ms
        );
    }
    let mut peer = opts.peer.map(|kind| peer::open(kind, &info));
    let mut report = Report {
        sdk_version: ksrt::VERSION.to_string(),
        adapter: info.name.clone(),
        driver: format!("{} {}", info.driver, info.driver_info),
        commit: env!("KSRT_COMMIT").to_string(),
        backend: format!("{:?}", info.backend),
        timestamp_query,
        width: opts.size.0,
        height: opts.size.1,
        iterations: opts.iterations,
        ray_order: opts.extras.ray_order,
        busy_gpu_ms: opts.extras.busy_gpu_ms,
        scenes: Vec::new(),
        tlas: Vec::new(),
        extras: Default::default(),
    };
    for (name, scene) in names.iter().zip(&scenes) {
        let camera = opts
            .camera
            .or_else(|| issue_camera(name))
            .unwrap_or_else(|| scene.camera_or_default(None));
        let r = bench_scene(
            &bench,
            name,
            scene,
            camera,
            opts.size,
            peer.as_mut(),
            opts.extras.tree_work,
        );
        print_scene(&r, opts.size);
        if let Some(p) = &r.peer {
            peer::print(p);
        }
        report.scenes.push(r);
    }
    let tlas_counts: &[u32] =
        if opts.extras.skip_scenes || !extras::Section::Tlas.runs_in(&opts.extras.sections) {
            &[]
        } else {
            println!("\nTLAS (instances of an 80-triangle sphere, random transforms):");
            &TLAS_INSTANCE_COUNTS
        };
    for &count in tlas_counts {
        let t = bench_tlas(&bench, count);
        let opt = |s: &Option<Stats>| s.as_ref().map_or("—".to_string(), Stats::show);
        println!(
            "  {:>7} instances  build {}  refit {}",
            count,
            opt(&t.build),
            opt(&t.refit)
        );
        for p in [&t.build_profile, &t.refit_profile] {
            if !p.is_empty() {
                println!("    profile    {}", prof::show(p));
            }
        }
        for e in &t.errors {
            println!("    failed: {e}");
        }
        report.tlas.push(t);
    }
    extras::run(
        &bench,
        &opts.scenes_dir,
        opts.size,
        &opts.extras,
        &mut report.extras,
    )?;
    if let Some(path) = &opts.json {
        let text = serde_json::to_string_pretty(&report)?;
        std::fs::write(path, text)
            .map_err(|e| format!("--json {}: cannot write: {e}", path.display()))?;
        println!("wrote {}", path.display());
    }
    let failed = report.scenes.iter().map(|s| s.errors.len()).sum::<usize>()
        + report.tlas.iter().map(|t| t.errors.len()).sum::<usize>()
        + report.extras.failures();
    if failed > 0 {
        return Err(format!("{failed} measurements failed (listed above)").into());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_driver_peer_with_tiled_rays_is_refused_before_any_gpu_work() {
        let opts = BenchOptions {
            scenes_dir: PathBuf::from("/nonexistent"),
            scenes: vec!["dragon".into()],
            json: None,
            camera: None,
            iterations: 1,
            size: (16, 16),
            extras: extras::ExtraArgs {
                ray_order: extras::RayOrder::Tiles,
                ..Default::default()
            },
            peer: Some(PeerKind::VulkanRt),
        };
        let err = run(opts).expect_err("refused").to_string();
        assert!(
            err.contains("--peer") && err.contains("--ray-order rows"),
            "{err}"
        );
    }

    #[test]
    fn busy_gpu_ms_outside_0_to_1000_is_refused() {
        for bad in [-1.0, 1000.5, f64::NAN] {
            let args = extras::ExtraArgs {
                busy_gpu_ms: bad,
                ..Default::default()
            };
            let err = args.check().expect_err("refused").to_string();
            assert!(err.contains("--busy-gpu-ms"), "{err}");
        }
        let ok = extras::ExtraArgs {
            busy_gpu_ms: 2.0,
            ..Default::default()
        };
        assert!(ok.check().is_ok());
    }

    #[test]
    fn stats_median_min_max() {
        let s = Stats::new(vec![3.0, 1.0, 2.0, 10.0]);
        assert_eq!((s.median_ms, s.min_ms, s.max_ms), (2.5, 1.0, 10.0));
        assert_eq!(Stats::new(vec![4.0, 1.0, 2.0]).median_ms, 2.0);
    }

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

    #[test]
    fn issue_cameras_parse() {
        assert!(issue_camera("dragon").is_some());
        assert!(issue_camera("apartment").is_some());
        assert!(issue_camera("bunny").is_none());
    }
}
