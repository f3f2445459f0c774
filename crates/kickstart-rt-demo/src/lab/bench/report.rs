//! What `ksrt bench` reports: the types of the `--json` report (their field names are its keys)
//! and the printed figures of a scene.

use serde::Serialize;

use super::profile::{self as prof, PassProfile};
use super::Stats;
use kickstart_rt_renderer::scene::{Camera, Scene};

/// Lanes of the subgroup that [`WorkPerRay::subgroup_busy`] models (NVIDIA's warp).
pub(super) const SUBGROUP_LANES: usize = 32;

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
    /// Every mesh skinned to a new pose on the GPU, then re-ingested and refit, in one task.
    pub skinned_refit: Option<SkinnedRefitReport>,
    /// TLAS rebuild over the scene's instances (`tlas build` passes).
    pub tlas_build: Option<Stats>,
    /// Where the last timed TLAS rebuild's GPU time went.
    pub tlas_build_profile: Vec<PassProfile>,
    /// BVH quality of the largest geometry.
    pub sah: Option<SahReport>,
    /// Our fast-trace BLASes' memory, as built and once compacted.
    pub blas_memory: Option<BlasMemoryReport>,
    /// Primary, AO and diffuse batches.
    pub rays: Vec<RayBatch>,
    /// (pixels + primary hits) / (primary batch time + diffuse batch time), millions of rays per
    /// second: the workload the issue compares with its peers.
    pub peer_mrays_per_s: Option<f64>,
    /// Primary rays checked against the CPU reference BVH on this GPU (untimed).
    pub oracle: Option<OracleCheck>,
    /// Direct lighting cache: bytes, injection time, cache error (`cache`).
    pub cache: Option<CacheReport>,
    /// The SDK's trace tasks on a G-buffer of the primary hits (`trace …` passes).
    pub trace_tasks: Vec<TraceTaskTime>,
    /// Specular + diffuse + AO + one shadow in one GPU task, full resolution (first trace pass's
    /// start to the last one's end).
    pub trace_combined: Option<Stats>,
    /// The peer's figures on the same meshes and rays (`--peer`), or why it was skipped.
    pub peer: Option<PeerReport>,
    /// The traversal backend of this scene's figures.
    pub traversal_backend: Option<String>,
    /// Where the device has both backends: the other one on the same scene and rays.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub backends: Option<BackendComparison>,
    /// `--tree-work`: other builders' trees on the same rays.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub tree_work: Vec<TreeWork>,
    /// Measurements that failed, and why.
    pub errors: Vec<String>,
}

impl SceneReport {
    /// The report of `scene` before anything is measured.
    pub(super) fn new(name: &str, scene: &Scene, camera: &Camera) -> SceneReport {
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
            skinned_refit: None,
            tlas_build: None,
            tlas_build_profile: Vec::new(),
            sah: None,
            blas_memory: None,
            rays: Vec::new(),
            peer_mrays_per_s: None,
            oracle: None,
            cache: None,
            trace_tasks: Vec::new(),
            trace_combined: None,
            peer: None,
            traversal_backend: None,
            backends: None,
            tree_work: Vec::new(),
            errors: Vec::new(),
        }
    }
}

/// The skinned refit (`skinned`): every mesh of the scene posed by a `SkinningTask` of a rig
/// generated by the bench, its geometry updated and every BLAS refit, all in one task.
#[derive(Debug, Clone, Serialize)]
pub struct SkinnedRefitReport {
    /// Joints of each mesh's rig (stacked up its height; two influences a vertex).
    pub joints: u32,
    /// Vertices posed a repetition, over every mesh.
    pub vertices: u64,
    /// GPU span of the task's `skinning`, `ingest` and `blas refit` passes.
    pub time: Stats,
    /// Summed GPU time of the `skinning` passes alone, of the same repetitions.
    pub skinning: Stats,
    /// Median skinning time / median span.
    pub skinning_share: f64,
    /// Where the last timed repetition's GPU time went.
    pub profile: Vec<PassProfile>,
    /// The last pose read back from one BLAS and compared with a CPU skinning.
    pub check: PoseCheck,
    /// The same span with a rest-pose, influence and posed buffer per mesh instead of pooled
    /// buffers (one skinning dispatch and one barrier a mesh).
    pub per_mesh_buffers: Stats,
}

impl SkinnedRefitReport {
    /// The printed figure.
    pub fn line(&self) -> String {
        format!(
            "skinning + refit {} (skinning {:.3} ms, {:.0} %; {} vertices, {} joints a mesh; \
             pooled buffers, {:.3} ms with a buffer set a mesh)",
            self.time.show(),
            self.skinning.median_ms,
            self.skinning_share * 100.0,
            self.vertices,
            self.joints,
            self.per_mesh_buffers.median_ms
        )
    }
}

/// One mesh's BLAS after the last skinned refit, against a CPU skinning of the same pose.
#[derive(Debug, Clone, Serialize)]
pub struct PoseCheck {
    /// The mesh (the scene's one with the most vertices).
    pub mesh: String,
    /// Triangles of its BLAS compared.
    pub triangles: usize,
    /// Largest difference of a BLAS vertex from the CPU's, over the mesh's size (largest box
    /// extent).
    pub max_error: f64,
    /// Largest distance of a BLAS vertex from its rest position, over the mesh's size: the pose
    /// is not the rest pose.
    pub max_displacement: f64,
}

impl PoseCheck {
    /// The printed check.
    pub fn line(&self) -> String {
        format!(
            "{}: {} BLAS triangles at the CPU skinning's pose \
             (max error {:.1e}, moved up to {:.1} % of its size)",
            self.mesh,
            self.triangles,
            self.max_error,
            self.max_displacement * 100.0
        )
    }
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

/// Prints one scene's figures at the ray batches' size `w`×`h`.
pub(super) fn print_scene(r: &SceneReport, (w, h): (u32, u32)) {
    let opt = |s: &Option<Stats>| s.as_ref().map_or("—".to_string(), Stats::show);
    println!(
        "\n{}: {} geometries, {} instances, {} geometry triangles ({} in the world)",
        r.scene, r.meshes, r.instances, r.geometry_triangles, r.world_triangles
    );
    if let Some(b) = &r.traversal_backend {
        println!("  traversal backend: {b}");
    }
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
    if let Some(s) = &r.skinned_refit {
        println!("  {}", s.line());
        println!("    profile    {}", prof::show(&s.profile));
        println!("    pose check {}", s.check.line());
    }
    println!("  TLAS build   {}", opt(&r.tlas_build));
    if !r.tlas_build_profile.is_empty() {
        println!("    profile    {}", prof::show(&r.tlas_build_profile));
    }
    if let Some(m) = &r.blas_memory {
        println!("  BLAS memory  {}", m.line());
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

/// The cache measurements of one scene.
#[derive(Debug, Clone, Serialize)]
pub struct CacheReport {
    /// Σ surfels × 16 bytes over the instances (full resolution).
    pub surfel_bytes: u64,
    /// `resource_allocations().cache`: the surfel pool (with its reserve), triangle records,
    /// headers, allocation and injection buffers.
    pub cache_bytes: u64,
    /// Instances still coarse after the pool grew (should be 0).
    pub degraded_instances: usize,
    /// (stride, injection time).
    pub injection: Vec<(u32, Stats)>,
    /// (injection tasks, mean relative error).
    pub error: Vec<(u32, f64)>,
}

/// A GPU time, ours against theirs.
#[derive(Debug, Clone, Serialize)]
pub struct TimeComparison {
    /// Our median, milliseconds (`None` where our measurement failed).
    pub ours_ms: Option<f64>,
    /// Their times.
    pub theirs: Stats,
    /// Their median / ours: our speed-up (above 1: we are faster).
    pub ratio: Option<f64>,
}

/// Where the two tracers disagree on one batch (`kickstart_rt_peer_vulkan::compare_hits`).
#[derive(Debug, Clone, Serialize)]
pub struct AgreementReport {
    /// Disagreeing rays: hit vs miss, or (closest hit) another triangle beyond a tie.
    pub disagreements: u64,
    /// Disagreements in percent of the batch (the goal: at most 0.01 %).
    pub disagreement_percent: f64,
    /// One hit, the other missed.
    pub hit_miss: u64,
    /// Both hit, other triangles at distances beyond the tie tolerance.
    pub different_triangle: u64,
    /// Both hit other triangles at equal distances (agreeing: shared edges, coincident faces).
    pub ties: u64,
    /// Same triangle, distances beyond 1e-3 relative (agreeing on the hit; counted apart).
    pub distance_mismatches: u64,
}

/// One ray batch, ours against theirs.
#[derive(Debug, Clone, Serialize)]
pub struct RayComparison {
    /// `primary`, `ao` or `diffuse`.
    pub kind: &'static str,
    /// Rays in the batch (the same rays for both).
    pub rays: u64,
    /// Our rays per second, millions.
    pub ours_mrays_per_s: Option<f64>,
    /// Theirs.
    pub theirs_mrays_per_s: f64,
    /// Ours / theirs (above 1: we are faster).
    pub ratio: Option<f64>,
    /// Their GPU times (`vkCmdTraceRaysKHR`).
    pub theirs_time: Stats,
    /// Their misses.
    pub theirs_misses: u64,
    /// Ray-by-ray comparison of the hits.
    pub agreement: AgreementReport,
}

/// A rate, ours against theirs.
#[derive(Debug, Clone, Serialize)]
pub struct RateComparison {
    /// Ours, millions per second.
    pub ours: Option<f64>,
    /// Theirs.
    pub theirs: f64,
    /// Ours / theirs (above 1: we are faster).
    pub ratio: Option<f64>,
}

/// The peer's figures on one scene.
#[derive(Debug, Clone, Serialize)]
pub struct PeerReport {
    /// `vulkan-rt`.
    pub peer: &'static str,
    /// The peer's device, when it ran.
    pub device: Option<String>,
    /// Its driver.
    pub driver: Option<String>,
    /// Why the peer was skipped, when it was.
    pub skipped: Option<String>,
    /// Every BLAS in one build command, `PREFER_FAST_TRACE`, against our BLAS build.
    pub blas_build_fast_trace: Option<TimeComparison>,
    /// The same with `PREFER_FAST_BUILD`.
    pub blas_build_fast_build: Option<TimeComparison>,
    /// Bytes of their fast-trace BLASes (uncompacted).
    pub blas_bytes_fast_trace: Option<u64>,
    /// The driver's compacted size of the same BLASes (its compacted-size query, summed without
    /// the 256-byte alignment padding that `blas_bytes_fast_trace` counts; the peer does not
    /// compact them).
    pub blas_compacted_bytes_fast_trace: Option<u64>,
    /// Our fast-trace BLASes' bytes once compacted (triangles and nodes; the scene report's
    /// `blas_memory`), beside theirs.
    pub ours_blas_bytes: Option<u64>,
    /// The triangles those BLASes hold (the scene's `geometry_triangles`; 0 without a fast-trace
    /// build), for the printed bytes per triangle; left out of the JSON, which has them with the
    /// scene.
    #[serde(skip)]
    pub blas_triangles: usize,
    /// TLAS build over the scene's instances, against our TLAS rebuild of the same instances.
    pub tlas_build: Option<TimeComparison>,
    /// Primary, AO and diffuse: the same rays, traced against their fast-trace BLASes.
    pub rays: Vec<RayComparison>,
    /// The peer workload, (pixels + primary hits) / (primary time + diffuse time), Mrays/s.
    pub workload: Option<RateComparison>,
    /// Measurements that failed, and why.
    pub errors: Vec<String>,
}

/// One ray batch on both backends.
#[derive(Debug, Clone, Serialize)]
pub struct BackendRays {
    /// `primary`, `ao` or `diffuse`.
    pub kind: &'static str,
    /// Rays in the batch (the same for both).
    pub rays: u64,
    /// The measured backend's rays per second, millions (the scene's own figure).
    pub this_mrays_per_s: f64,
    /// The other backend's.
    pub other_mrays_per_s: f64,
    /// The other backend's GPU times.
    pub other_time: Stats,
    /// Ray-by-ray comparison of the hits (the other backend as "theirs").
    pub agreement: AgreementReport,
    /// The largest |t − t'| / max(|t|, 1) over rays both backends hit on the same triangle.
    pub max_relative_distance: f64,
}

/// The scene traced by the other backend, against the measured one.
#[derive(Debug, Clone, Serialize)]
pub struct BackendComparison {
    /// The backend of the scene's own figures.
    pub this: String,
    /// The backend measured here.
    pub other: String,
    /// Every BLAS in one task (fast-trace), the other backend; the scene's `blas_build` is this
    /// backend's.
    pub other_blas_build: Option<Stats>,
    /// The TLAS rebuild over the scene's instances, the measured backend.
    pub this_tlas_build: Option<Stats>,
    /// The same, the other backend.
    pub other_tlas_build: Option<Stats>,
    /// The ray batches.
    pub rays: Vec<BackendRays>,
    /// Measurements that failed, and why.
    pub errors: Vec<String>,
}

/// The work of one tree on every batch of rays.
#[derive(Debug, Clone, Serialize)]
pub struct TreeWork {
    /// The builder.
    pub tree: String,
    /// CPU time of its build, seconds (16 threads for obvhs, one for ours).
    pub build_s: f64,
    /// SAH cost with our constants (`BlasReadback::sah_cost`).
    pub sah_cost: f64,
    /// `(batch kind, work per ray)` for each batch.
    pub batches: Vec<(String, WorkPerRay)>,
}

/// Our BLASes' memory after the fast-trace build of every geometry
/// (`ExecuteContext::geometry_blas_memory`, summed).
#[derive(Debug, Clone, Serialize)]
pub struct BlasMemoryReport {
    /// Geometry triangles.
    pub triangles: usize,
    /// Triangles in leaf order: 48 bytes each.
    pub triangle_bytes: u64,
    /// Nodes as the builds wrote them: 64 bytes for each of a geometry's `n - 1` inner nodes.
    pub built_node_bytes: u64,
    /// Nodes once compacted (the nodes collapsed leaves left unreferenced given back).
    pub node_bytes: u64,
}

impl BlasMemoryReport {
    /// Triangles and compacted nodes.
    pub fn total(&self) -> u64 {
        self.triangle_bytes + self.node_bytes
    }

    /// One printed line: bytes per triangle of the nodes (built, compacted) and in all.
    pub fn line(&self) -> String {
        let per = |b: u64| b as f64 / self.triangles.max(1) as f64;
        format!(
            "{:.1} MiB, {:.1} B/tri: nodes {:.1} B/tri ({:.1} as built), triangles {:.1} B/tri",
            self.total() as f64 / (1024.0 * 1024.0),
            per(self.total()),
            per(self.node_bytes),
            per(self.built_node_bytes),
            per(self.triangle_bytes)
        )
    }
}
