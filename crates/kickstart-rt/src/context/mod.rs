//! The SDK instance: handles, working sets, and recording GPU tasks into the engine's encoder.

use std::collections::{BTreeMap, HashMap, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use crate::allocations::ResourceAllocations;
use crate::container::TaskContainer;
use crate::error::{Error, Result};
use crate::gpu::recorder::Timestamps;
use crate::gpu::Recorder;
use crate::handles::*;
use crate::logging::{LogCallback, Logger, Severity};
use crate::scene::gpu_scene::{
    DeferredIngest, GeometryGpu, GpuScene, PendingBvh, Uploads, GEOMETRY_RECORD_SIZE,
    INSTANCE_RECORD_BYTES,
};
use crate::scene::ingest::ComponentIngest;
use crate::staging::{StagingBuffer, StagingPool};
use crate::tasks::*;
use crate::timing::{GpuTimings, TimingReadback};
use crate::trace::tasks::TracePasses;
use crate::validate;
use crate::version::Version;

static NEXT_CONTEXT_ID: AtomicU32 = AtomicU32::new(1);

/// Bytes of one instance's record in the instance data table. The table is indexed by the
/// instance handle's slot index, which is the instance index a ray hit reports. Layout (32-bit
/// words): 0–11 object-to-world 3×4 (three rows), 12–23 world-to-object 3×4 (rows), 24 geometry
/// slot index, 25 inclusion mask, 26 flags (bit 0: live and participating in the TLAS).
pub const INSTANCE_RECORD_SIZE: u64 = INSTANCE_RECORD_BYTES;

/// Settings of [`ExecuteContext::new`].
#[derive(Clone)]
pub struct InitSettings {
    /// GPU tasks that may be built and not yet marked complete at once (the reference's
    /// `supportedWorkingsets`): typically tasks per frame × frames in flight. Building one more
    /// returns [`Error::WorkingSetsExhausted`] at once. ≥ 1; default 4.
    pub supported_working_sets: u32,
    /// The SDK version the application was built against; leave at the default.
    pub version: Version,
    /// Receives SDK messages at or above `min_log_severity` (they also go to the `log` crate).
    pub log_callback: Option<LogCallback>,
    /// Least severe message delivered.
    pub min_log_severity: Severity,
    /// Measure every SDK pass with GPU timestamp queries (read them with
    /// [`ExecuteContext::wait_for_gpu_timings`]). Needs `Features::TIMESTAMP_QUERY` on the
    /// device; without it a warning is logged and timing stays off. Default off.
    pub gpu_timing: bool,
    /// Initial size of the direct lighting cache's surfel pool, bytes (16 per surfel; default
    /// 4 MiB). The pool grows by itself when instances need more (their caches are coarse until
    /// then); a size near the scene's need avoids that first coarse frame.
    pub lighting_cache_pool_bytes: u64,
}

impl Default for InitSettings {
    fn default() -> Self {
        InitSettings {
            supported_working_sets: 4,
            version: crate::VERSION,
            log_callback: None,
            min_log_severity: Severity::Warning,
            gpu_timing: false,
            lighting_cache_pool_bytes: crate::cache::alloc::DEFAULT_INITIAL_SURFELS as u64 * 16,
        }
    }
}

impl std::fmt::Debug for InitSettings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("InitSettings")
            .field("supported_working_sets", &self.supported_working_sets)
            .field("version", &self.version)
            .field("log_callback", &self.log_callback.is_some())
            .field("min_log_severity", &self.min_log_severity)
            .field("gpu_timing", &self.gpu_timing)
            .finish()
    }
}

/// Settings of a denoising context.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DenoisingContextInput {
    /// Largest width it will denoise, pixels (> 0).
    pub max_width: u32,
    /// Largest height it will denoise, pixels (> 0).
    pub max_height: u32,
    /// Which signal it denoises.
    pub signal_type: SignalType,
    /// Which denoiser.
    pub method: DenoisingMethod,
}

/// The signal a denoising context is for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SignalType {
    /// Specular reflections.
    Specular,
    /// Diffuse GI.
    Diffuse,
    /// Both, in one pass.
    SpecularAndDiffuse,
    /// Ambient occlusion.
    DiffuseOcclusion,
    /// One shadow.
    Shadow,
    /// Up to 32 shadows.
    MultiShadow,
}

/// Which denoiser a context uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum DenoisingMethod {
    /// The cheaper filter.
    Fast,
    /// The higher-quality filter.
    #[default]
    HighQuality,
}

struct GeometryData {
    name: String,
    allow_update: bool,
    /// Leaf collapsing of its BLAS builds, from `build_hint` ([`BuildHint::max_leaf`]).
    max_leaf: u32,
    triangles: u32,
    gpu: GeometryGpu,
    dropped: Option<DroppedTriangles>,
    cache: crate::cache::CacheParams,
    allow_light_transfer_target: bool,
}

/// Triangles ingestion dropped from a geometry (they are never hit); also logged as a warning
/// naming the geometry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct DroppedTriangles {
    /// Triangles with an index ≥ the component's vertex count.
    pub out_of_range_indices: u32,
    /// Triangles with a NaN or infinite position (as given, or after the component transform).
    pub non_finite_positions: u32,
}

/// Dropped-triangle counters of one task's ingestions, read back after it completes.
struct DroppedReadback {
    buffer: wgpu::Buffer,
    mapped: Arc<AtomicBool>,
    geometries: Vec<(GeometryHandle, String)>,
}

#[derive(Default)]
struct GeometrySlot {
    data: Option<GeometryData>,
    last_used: u64,
}

#[derive(Default)]
struct InstanceSlot {
    input: Option<InstanceInput>,
    last_used: u64,
}

struct DenoisingSlot {
    input: DenoisingContextInput,
}

/// Resources one in-flight GPU task holds until it is marked complete.
struct WorkingSet {
    staging: Vec<StagingBuffer>,
    /// Inputs the task reads and the raw copies it made, kept alive while the GPU may read them.
    _inputs: Vec<wgpu::Buffer>,
    dropped: Option<DroppedReadback>,
}

/// Counts of what `build_gpu_task` has recorded, since the context was created.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct RecordedTaskCounts {
    /// Geometry registrations and updates recorded.
    pub geometry_tasks: u64,
    /// Instance registrations and updates recorded.
    pub instance_tasks: u64,
    /// GPU tasks built.
    pub gpu_tasks: u64,
}

struct State {
    geometries: HandlePool<GeometryHandle, GeometrySlot>,
    instances: HandlePool<InstanceHandle, InstanceSlot>,
    denoisers: HandlePool<DenoisingContextHandle, DenoisingSlot>,
    /// The denoisers' history per context and their passes.
    denoise: crate::denoise::Denoisers,
    in_flight: BTreeMap<u64, WorkingSet>,
    invoked: Vec<(u64, Arc<AtomicBool>)>,
    staging: StagingPool,
    scene: GpuScene,
    /// The trace tasks' passes (created on first use: they generate the blue-noise tile).
    trace: Option<TracePasses>,
    /// Geometries waiting for a BLAS build or refit, in the order they were scheduled.
    blas_queue: VecDeque<GeometryHandle>,
    /// Instance slots whose records must be rewritten as dead (destroyed instances, instances of
    /// destroyed geometry).
    dead_instance_slots: Vec<u32>,
    /// Geometry slots whose table record must be cleared (destroyed geometry).
    dead_geometry_slots: Vec<u32>,
    /// Instance records to write when the TLAS is next updated: rays always see the instance
    /// table that matches the TLAS, also while a BvhBuildTask defers the TLAS.
    pending_records: BTreeMap<u32, [u8; INSTANCE_RECORD_SIZE as usize]>,
    /// The set of TLAS leaves changed (instances added/removed, participation, a BLAS built).
    tlas_rebuild: bool,
    /// Only instance transforms (or refitted BLASes) changed since the last TLAS update.
    tlas_refit: bool,
    any_instance: bool,
    dropped_readbacks: Vec<DroppedReadback>,
    timings: BTreeMap<u64, TimingReadback>,
    next_serial: u64,
    counts: RecordedTaskCounts,
    /// The direct lighting cache (sampling contract in `crate::cache`).
    cache: crate::cache::DirectLightingCache,
}

/// The SDK instance (the reference's `ExecuteContext`). One per device; `Send + Sync`: handle
/// creation and destruction may happen on any thread, and `build_gpu_task` serialises internally
/// because GPU tasks must execute in the order they were built.
pub struct ExecuteContext {
    id: u32,
    device: wgpu::Device,
    queue: wgpu::Queue,
    working_sets: u32,
    gpu_timing: bool,
    logger: Logger,
    state: Mutex<State>,
}

impl std::fmt::Debug for ExecuteContext {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ExecuteContext")
            .field("id", &self.id)
            .field("working_sets", &self.working_sets)
            .finish()
    }
}

impl ExecuteContext {
    /// Creates the SDK on an application's device and queue.
    ///
    /// Fails with [`Error::MissingFeatures`] / [`Error::InsufficientLimit`] when the device was
    /// created without [`crate::required_features`] / [`crate::required_limits`], and with
    /// [`Error::IncompatibleVersion`] when `settings.version` has another major version (a minor
    /// difference is logged as a warning).
    pub fn new(device: &wgpu::Device, queue: &wgpu::Queue, settings: InitSettings) -> Result<Self> {
        let logger = Logger::new(settings.log_callback.clone(), settings.min_log_severity);
        if settings.version.major != crate::VERSION.major {
            return Err(Error::IncompatibleVersion {
                app: settings.version,
                library: crate::VERSION,
            });
        }
        if settings.version.minor != crate::VERSION.minor {
            logger.message(
                Severity::Warning,
                &format!(
                    "application built against kickstart-rt {}, library is {}",
                    settings.version,
                    crate::VERSION
                ),
            );
        }
        if settings.supported_working_sets == 0 {
            return Err(Error::input(
                "InitSettings",
                "supported_working_sets",
                0,
                "must be ≥ 1",
            ));
        }
        crate::device::check_device(device)?;
        let gpu_timing =
            settings.gpu_timing && device.features().contains(wgpu::Features::TIMESTAMP_QUERY);
        if settings.gpu_timing && !gpu_timing {
            logger.message(
                Severity::Warning,
                "InitSettings::gpu_timing needs Features::TIMESTAMP_QUERY on the device; timing is off",
            );
        }
        let id = NEXT_CONTEXT_ID.fetch_add(1, Ordering::Relaxed);
        Ok(ExecuteContext {
            id,
            device: device.clone(),
            queue: queue.clone(),
            working_sets: settings.supported_working_sets,
            gpu_timing,
            logger,
            state: Mutex::new(State {
                geometries: HandlePool::new(id),
                instances: HandlePool::new(id),
                denoisers: HandlePool::new(id),
                denoise: crate::denoise::Denoisers::new(device),
                in_flight: BTreeMap::new(),
                invoked: Vec::new(),
                staging: StagingPool::default(),
                scene: GpuScene::new(device),
                trace: None,
                blas_queue: VecDeque::new(),
                dead_instance_slots: Vec::new(),
                dead_geometry_slots: Vec::new(),
                pending_records: BTreeMap::new(),
                tlas_rebuild: false,
                tlas_refit: false,
                any_instance: false,
                dropped_readbacks: Vec::new(),
                timings: BTreeMap::new(),
                next_serial: 1,
                counts: RecordedTaskCounts::default(),
                cache: crate::cache::DirectLightingCache::new(
                    device,
                    (settings.lighting_cache_pool_bytes / 16).min(u32::MAX as u64) as u32,
                ),
            }),
        })
    }

    fn state(&self) -> MutexGuard<'_, State> {
        // A panic inside the SDK while locked must not make the context unusable forever.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Replaces the log callback.
    pub fn set_log_callback(&self, callback: Option<LogCallback>) {
        self.logger.set_callback(callback);
    }

    /// Changes the least severe message delivered.
    pub fn set_min_log_severity(&self, severity: Severity) {
        self.logger.set_min_severity(severity);
    }

    /// A new, empty task container for this context.
    pub fn create_task_container(&self) -> TaskContainer {
        TaskContainer::new(self.id)
    }

    /// A new geometry handle; register its mesh with a [`GeometryTask`].
    pub fn create_geometry_handle(&self) -> GeometryHandle {
        self.state().geometries.insert(GeometrySlot::default())
    }

    /// `count` new geometry handles.
    pub fn create_geometry_handles(&self, count: usize) -> Vec<GeometryHandle> {
        let mut s = self.state();
        (0..count)
            .map(|_| s.geometries.insert(GeometrySlot::default()))
            .collect()
    }

    /// A new instance handle; place it with an [`InstanceTask`]. Its slot index is the instance
    /// index ray hits report.
    pub fn create_instance_handle(&self) -> InstanceHandle {
        self.state().instances.insert(InstanceSlot::default())
    }

    /// `count` new instance handles.
    pub fn create_instance_handles(&self, count: usize) -> Vec<InstanceHandle> {
        let mut s = self.state();
        (0..count)
            .map(|_| s.instances.insert(InstanceSlot::default()))
            .collect()
    }

    /// A new denoising context; its history is created lazily by the next `build_gpu_task`.
    pub fn create_denoising_context_handle(
        &self,
        input: DenoisingContextInput,
    ) -> Result<DenoisingContextHandle> {
        if input.max_width == 0
            || input.max_height == 0
            || input.max_width > 16384
            || input.max_height > 16384
        {
            return Err(Error::input(
                "DenoisingContextInput",
                "max_width/max_height",
                (input.max_width, input.max_height),
                "each must be in 1..=16384",
            ));
        }
        crate::denoise::check_context(&input, &self.device.limits())?;
        Ok(self.state().denoisers.insert(DenoisingSlot { input }))
    }

    /// Destroys a geometry. The handle is invalid at once; its GPU memory is released in the first
    /// `build_gpu_task` after every GPU task that used it has been marked complete.
    pub fn destroy_geometry_handle(&self, handle: GeometryHandle) -> Result<()> {
        let mut s = self.state();
        let slot = s.geometries.remove(handle)?;
        if let Some(mut d) = slot.data {
            d.gpu.free_after(&mut s.scene, slot.last_used);
        }
        s.dead_geometry_slots.push(handle.index);
        Ok(())
    }

    /// Destroys several geometries; stops at the first invalid handle (those before it are
    /// destroyed, the rest untouched).
    pub fn destroy_geometry_handles(&self, handles: &[GeometryHandle]) -> Result<()> {
        handles
            .iter()
            .try_for_each(|h| self.destroy_geometry_handle(*h))
    }

    /// Destroys every geometry.
    pub fn destroy_all_geometry_handles(&self) {
        let all = self.state().geometries.handles();
        for h in all {
            let _ = self.destroy_geometry_handle(h);
        }
    }

    /// Destroys an instance (lazily released, as geometries). It leaves the TLAS in the next
    /// GPU task with a [`BvhBuildTask`].
    pub fn destroy_instance_handle(&self, handle: InstanceHandle) -> Result<()> {
        let mut s = self.state();
        let slot = s.instances.remove(handle)?;
        if slot.input.is_some() {
            s.dead_instance_slots.push(handle.index);
        }
        let last = s.next_serial - 1;
        s.cache.release(handle.index, last);
        Ok(())
    }

    /// Destroys several instances; stops at the first invalid handle.
    pub fn destroy_instance_handles(&self, handles: &[InstanceHandle]) -> Result<()> {
        handles
            .iter()
            .try_for_each(|h| self.destroy_instance_handle(*h))
    }

    /// Destroys every instance.
    pub fn destroy_all_instance_handles(&self) {
        let all = self.state().instances.handles();
        for h in all {
            let _ = self.destroy_instance_handle(h);
        }
    }

    /// Destroys a denoising context (lazily released, as geometries).
    pub fn destroy_denoising_context_handle(&self, handle: DenoisingContextHandle) -> Result<()> {
        self.state().denoisers.remove(handle).map(|_| ())
    }

    /// Destroys several denoising contexts; stops at the first invalid handle.
    pub fn destroy_denoising_context_handles(
        &self,
        handles: &[DenoisingContextHandle],
    ) -> Result<()> {
        handles
            .iter()
            .try_for_each(|h| self.destroy_denoising_context_handle(*h))
    }

    /// Destroys every denoising context.
    pub fn destroy_all_denoising_context_handles(&self) {
        let all = self.state().denoisers.handles();
        for h in all {
            let _ = self.destroy_denoising_context_handle(h);
        }
    }

    /// Releases the memory of destroyed handles and pooled staging now. Refused with
    /// [`Error::TasksInFlight`] while any built GPU task is not marked complete.
    pub fn release_device_resources_immediately(&self) -> Result<()> {
        let mut s = self.state();
        self.collect_invoked(&mut s);
        if !s.in_flight.is_empty() {
            return Err(Error::TasksInFlight {
                operation: "release_device_resources_immediately",
                in_flight: s.in_flight.len(),
            });
        }
        s.scene.collect(u64::MAX);
        s.cache.collect(u64::MAX);
        s.denoise.collect(u64::MAX);
        s.staging.clear();
        Ok(())
    }

    /// GPU memory held, by kind.
    pub fn resource_allocations(&self) -> ResourceAllocations {
        let s = self.state();
        let sc = &s.scene;
        let mut a = ResourceAllocations {
            vertex_copies: sc.staged.used_bytes(),
            blas: sc.triangles.used_bytes()
                + sc.nodes.used_bytes()
                + sc.orders.used_bytes()
                + sc.topologies.used_bytes()
                + sc.geometry_table.buffer.size(),
            tlas: sc.tlas_bytes() + sc.instance_table.buffer.size(),
            cache: s.cache.bytes(),
            scratch: sc.scratch_bytes(),
            pool_reserve: sc.staged.reserve_bytes()
                + sc.triangles.reserve_bytes()
                + sc.nodes.reserve_bytes()
                + sc.orders.reserve_bytes()
                + sc.topologies.reserve_bytes(),
            denoiser: s.denoise.bytes(),
            ..Default::default()
        };
        a.staging = s.staging.bytes()
            + s.in_flight
                .values()
                .flat_map(|w| w.staging.iter())
                .map(|b| b.buffer.size())
                .sum::<u64>();
        a
    }

    /// An instance's lighting cache as the GPU allocated it: `None` until the allocating task has
    /// been marked complete and its log has been read back (asynchronously: a later call after a
    /// device poll sees it), or while the instance waits for its geometry's BLAS.
    pub fn lighting_cache_allocation(
        &self,
        handle: InstanceHandle,
    ) -> Result<Option<crate::CacheAllocation>> {
        let mut s = self.state();
        self.collect_invoked(&mut s);
        s.instances.get(handle)?;
        let oldest = s.in_flight.keys().next().copied().unwrap_or(u64::MAX);
        s.cache.collect(oldest);
        Ok(s.cache.allocation(handle.index))
    }

    /// Number of built GPU tasks not yet marked complete.
    pub fn in_flight_task_count(&self) -> usize {
        let mut s = self.state();
        self.collect_invoked(&mut s);
        s.in_flight.len()
    }

    /// What `build_gpu_task` has recorded so far.
    pub fn recorded_task_counts(&self) -> RecordedTaskCounts {
        self.state().counts
    }

    /// Triangles of a registered geometry (after its index ranges), for tools and tests.
    pub fn geometry_triangle_count(&self, handle: GeometryHandle) -> Result<Option<u32>> {
        let s = self.state();
        Ok(s.geometries.get(handle)?.data.as_ref().map(|d| d.triangles))
    }

    /// The instance data table (one [`INSTANCE_RECORD_SIZE`]-byte record per instance slot:
    /// object-to-world 3×4 row-major, then geometry slot, inclusion mask, flags), for tools and
    /// tests that read it back. `None` before the first instance is registered.
    pub fn instance_table(&self) -> Option<wgpu::Buffer> {
        let s = self.state();
        s.any_instance
            .then(|| s.scene.instance_table.buffer.clone())
    }

    /// Marks a GPU task built by [`Self::build_gpu_task`] as executed by the GPU, so its working
    /// set is reused and memory it used can be released. Call it once the queue reports the
    /// submission done (e.g. `queue.on_submitted_work_done`, or a fence your engine already has).
    pub fn mark_gpu_task_completed(&self, handle: GpuTaskHandle) -> Result<()> {
        let mut s = self.state();
        let ws = s
            .in_flight
            .remove(&handle.0)
            .ok_or(Error::InvalidGpuTaskHandle(handle.0))?;
        Self::retire(&mut s, handle.0, ws);
        Ok(())
    }

    /// Returns a completed task's staging to the pool and starts reading back its counters.
    fn retire(s: &mut State, serial: u64, ws: WorkingSet) {
        s.cache.task_completed(serial);
        for b in ws.staging {
            s.staging.release(b);
        }
        if let Some(r) = ws.dropped {
            let flag = r.mapped.clone();
            r.buffer.map_async(wgpu::MapMode::Read, .., move |res| {
                if res.is_ok() {
                    flag.store(true, Ordering::Release);
                }
            });
            s.dropped_readbacks.push(r);
        }
    }

    /// Logs and records the dropped-triangle counts whose read-back has arrived.
    fn collect_dropped(&self, s: &mut State) {
        let mut i = 0;
        while i < s.dropped_readbacks.len() {
            if !s.dropped_readbacks[i].mapped.load(Ordering::Acquire) {
                i += 1;
                continue;
            }
            let r = s.dropped_readbacks.swap_remove(i);
            let words: Vec<u32> = match r.buffer.slice(..).get_mapped_range() {
                Ok(view) => bytemuck::pod_collect_to_vec(&view),
                Err(_) => continue,
            };
            for (k, (handle, name)) in r.geometries.iter().enumerate() {
                let d = DroppedTriangles {
                    out_of_range_indices: words.get(2 * k).copied().unwrap_or(0),
                    non_finite_positions: words.get(2 * k + 1).copied().unwrap_or(0),
                };
                if d != DroppedTriangles::default() {
                    self.logger.message(
                        Severity::Warning,
                        &format!(
                            "GeometryTask: geometry `{name}` ({handle:?}): dropped {} triangle(s) with out-of-range indices and {} with NaN/infinite positions; they are never hit",
                            d.out_of_range_indices, d.non_finite_positions
                        ),
                    );
                }
                if let Ok(GeometrySlot { data: Some(g), .. }) = s.geometries.get_mut(*handle) {
                    g.dropped = Some(d);
                }
            }
        }
    }

    /// Triangles ingestion dropped from a geometry: `None` until the GPU task that ingested it
    /// has been marked complete and its counters have been read back (asynchronously; any later
    /// call to the context after a device poll picks them up). Also logged as a warning.
    pub fn geometry_dropped_triangles(
        &self,
        handle: GeometryHandle,
    ) -> Result<Option<DroppedTriangles>> {
        let mut s = self.state();
        self.collect_invoked(&mut s);
        Ok(s.geometries
            .get(handle)?
            .data
            .as_ref()
            .and_then(|d| d.dropped))
    }

    /// Whether a geometry's BLAS is built and not waiting for a rebuild or refit.
    pub fn geometry_is_built(&self, handle: GeometryHandle) -> Result<bool> {
        let s = self.state();
        Ok(s.geometries
            .get(handle)?
            .data
            .as_ref()
            .is_some_and(|d| d.gpu.blas.is_some() && d.gpu.pending.is_none()))
    }

    /// Reads a built BLAS back to the CPU: its nodes, its triangles in leaf order, and its SAH
    /// cost. **Blocks** until the device is idle: for tools, benchmarks and tests, not frames.
    /// Submit the task that built it first.
    pub fn read_back_blas(&self, handle: GeometryHandle) -> Result<crate::cpu::BlasReadback> {
        let s = self.state();
        let g = s.geometries.get(handle)?;
        let Some(d) = &g.data else {
            return Err(Error::ReadBack("the geometry is not registered".into()));
        };
        let (nodes, tris) = s.scene.read_back_blas(&self.queue, &d.gpu)?;
        Ok(crate::cpu::BlasReadback::new(nodes, tris))
    }

    /// Creates every compute pipeline now, so the first frame that needs one does not stall.
    pub fn prepare_pipelines(&self) {
        let mut s = self.state();
        s.scene.prepare_pipelines();
        s.trace
            .get_or_insert_with(|| TracePasses::new(&self.device, &self.queue))
            .prepare(&self.device);
        s.cache.prepare_pipelines();
        s.denoise.prepare_pipelines();
    }

    /// The GPU time of each SDK pass of `task` (built with [`InitSettings::gpu_timing`]).
    /// **Blocks** until the device has executed it: for tools and benchmarks. Submit the task's
    /// encoder first. Each task's timings can be read once.
    pub fn wait_for_gpu_timings(&self, task: GpuTaskHandle) -> Result<GpuTimings> {
        let readback = self.state().timings.remove(&task.0).ok_or_else(|| {
            Error::ReadBack(format!(
                "no GPU timings for task {}: InitSettings::gpu_timing off, no timestamp support, or already read",
                task.0
            ))
        })?;
        readback.wait(&self.device, self.queue.get_timestamp_period())
    }

    /// For applications that don't manage encoders: builds the container into a new encoder,
    /// submits it, and marks it complete by itself once the queue reports the submission done.
    /// That report arrives through wgpu's callbacks, which run when the device is polled (any
    /// `device.poll`, or the next `invoke_gpu_task`/`build_gpu_task`, which poll without waiting);
    /// nothing here blocks.
    pub fn invoke_gpu_task(&self, container: TaskContainer) -> Result<()> {
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("kickstart-rt invoke_gpu_task"),
            });
        let handle = self.build_gpu_task(container, &mut encoder)?;
        self.queue.submit([encoder.finish()]);
        let done = Arc::new(AtomicBool::new(false));
        let flag = done.clone();
        self.queue
            .on_submitted_work_done(move || flag.store(true, Ordering::Release));
        self.state().invoked.push((handle.0, done));
        Ok(())
    }

    /// Polls the device once without waiting, which runs wgpu's callbacks (submission-done for
    /// invoked tasks, re-maps of recycled staging), then retires the invoked tasks that finished.
    fn collect_invoked(&self, s: &mut State) {
        let _ = self.device.poll(wgpu::PollType::Poll);
        let mut done = Vec::new();
        s.invoked.retain(|(serial, flag)| {
            let d = flag.load(Ordering::Acquire);
            if d {
                done.push(*serial);
            }
            !d
        });
        for serial in done {
            if let Some(ws) = s.in_flight.remove(&serial) {
                Self::retire(s, serial, ws);
            }
        }
        self.collect_dropped(s);
    }

    /// Validates the whole container, then records its GPU work into the engine's `encoder`.
    /// Never submits and never waits on the GPU. On error nothing is recorded and the context is
    /// unchanged. Submit the encoder, then call [`Self::mark_gpu_task_completed`] with the
    /// returned handle once the GPU has executed it.
    pub fn build_gpu_task(
        &self,
        container: TaskContainer,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Result<GpuTaskHandle> {
        let mut s = self.state();
        self.collect_invoked(&mut s);
        if container.context != self.id {
            return Err(Error::input(
                "TaskContainer",
                "context",
                container.context,
                "the container was created by another ExecuteContext",
            ));
        }
        if s.in_flight.len() >= self.working_sets as usize {
            return Err(Error::WorkingSetsExhausted {
                supported: self.working_sets,
            });
        }
        let plan = self.validate(&s, &container)?;
        let s = &mut *s;

        // 1. Deferred destruction: release what no in-flight task can still read.
        let oldest = s.in_flight.keys().next().copied().unwrap_or(u64::MAX);
        s.scene.collect(oldest);
        s.cache.collect(oldest);
        // Denoiser histories: created for new contexts, retired for destroyed ones.
        let live: Vec<_> = s
            .denoisers
            .handles()
            .into_iter()
            .filter_map(|h| s.denoisers.get(h).ok().map(|d| (h, d.input)))
            .collect();
        s.denoise.sync(&live);
        s.denoise.collect(oldest);

        let serial = s.next_serial;
        s.next_serial += 1;
        let mut ws = WorkingSet {
            staging: Vec::new(),
            _inputs: Vec::new(),
            dropped: None,
        };
        let mut timestamps = self.gpu_timing.then(|| Timestamps::new(&self.device));

        // Tables large enough for every live slot; staged space for every registration.
        s.scene
            .ensure_tables(encoder, s.geometries.slot_count(), s.instances.slot_count())?;
        let mut uploads = Uploads::default();
        let mut ingestions = Vec::new();
        for (task, extents) in &plan.geometries {
            let triangles: u32 = extents.iter().map(|e| e.triangles).sum();
            let Ok(slot) = s.geometries.get_mut(task.handle) else {
                continue;
            };
            let staged = match (&mut slot.data, task.operation) {
                (Some(d), TaskOperation::Update) => d.gpu.staged,
                _ => None,
            };
            let staged = match staged {
                Some(r) => r,
                None => s.scene.alloc_staged(encoder, triangles, &task.input.name)?,
            };
            ingestions.push((*task, extents, staged, triangles));
        }

        // 2. Destroyed objects leave the tables; registrations reset their geometry record.
        if !s.dead_geometry_slots.is_empty() {
            for slot in std::mem::take(&mut s.dead_geometry_slots) {
                uploads.push(
                    &s.scene.geometry_table.buffer,
                    slot as u64 * GEOMETRY_RECORD_SIZE,
                    bytemuck::bytes_of(&[0u32; 4]),
                );
            }
            // Instances of destroyed geometry must not trace a geometry that reuses its slot.
            let dead: Vec<u32> = s
                .instances
                .handles()
                .into_iter()
                .filter(|h| {
                    s.instances
                        .get(*h)
                        .ok()
                        .and_then(|i| i.input.as_ref())
                        .is_some_and(|i| s.geometries.get(i.geometry).is_err())
                })
                .map(|h| h.index)
                .collect();
            s.dead_instance_slots.extend(dead);
        }
        if !s.dead_instance_slots.is_empty() {
            for slot in std::mem::take(&mut s.dead_instance_slots) {
                s.cache.release(slot, serial);
                s.pending_records
                    .insert(slot, [0u8; INSTANCE_RECORD_SIZE as usize]);
            }
            s.tlas_rebuild = true;
        }
        for (task, _, _, _) in &ingestions {
            if task.operation == TaskOperation::Register {
                uploads.push(
                    &s.scene.geometry_table.buffer,
                    task.handle.index as u64 * GEOMETRY_RECORD_SIZE,
                    bytemuck::bytes_of(&[0u32; 4]),
                );
            }
        }

        // 3. Instance records, at the instance's slot index (the invariant of the instance-id
        //    bug report: the index a hit reports is the index of the instance's data).
        for t in &plan.instances {
            // Only a move keeps the TLAS's leaves; compared in place (this runs for every
            // instance update of every frame).
            let moved_only = s
                .instances
                .get(t.handle)
                .ok()
                .and_then(|i| i.input.as_ref())
                .is_some_and(|o| {
                    o.geometry == t.input.geometry
                        && o.participating_in_tlas == t.input.participating_in_tlas
                });
            if moved_only {
                s.tlas_refit = true;
            } else {
                s.tlas_rebuild = true;
            }
            s.pending_records
                .insert(t.handle.index, instance_record(&t.input));
        }
        ws.staging
            .extend(uploads.flush(&self.device, &mut s.staging, encoder));

        // 4. Geometry ingestion: copy the application's bytes (inside its encoder), then decode
        //    them into the shared staged-triangle pool.
        let mut deferred: HashMap<GeometryHandle, DeferredIngest> = HashMap::new();
        if !ingestions.is_empty() {
            let raw_bytes: u64 = ingestions
                .iter()
                .flat_map(|(_, e, _, _)| e.iter())
                .map(|e| {
                    (e.vertex_bytes.1 - e.vertex_bytes.0) + e.index_bytes.map_or(0, |(a, b)| b - a)
                })
                .sum();
            let raw = crate::scene::gpu_scene::storage(
                &self.device,
                "kickstart-rt raw geometry copy",
                raw_bytes,
            );
            s.scene.reset_counters(encoder, ingestions.len() as u32);
            let mut cursor = 0u64;
            let mut plans = Vec::new();
            for (task, extents, _, _) in &ingestions {
                let mut comps = Vec::new();
                let mut prim_base = 0u32;
                for (c, e) in task.input.components.iter().zip(extents.iter()) {
                    let vb = &c.vertex_buffer;
                    let (vs, ve) = e.vertex_bytes;
                    encoder.copy_buffer_to_buffer(&vb.buffer, vs, &raw, cursor, ve - vs);
                    ws._inputs.push(vb.buffer.clone());
                    let vertex_byte_offset = cursor + (vb.offset - vs);
                    cursor += ve - vs;
                    let index = match (&c.index_buffer, e.index_bytes) {
                        (Some(ib), Some((is, ie))) => {
                            encoder.copy_buffer_to_buffer(&ib.buffer, is, &raw, cursor, ie - is);
                            ws._inputs.push(ib.buffer.clone());
                            let off = cursor + (ib.offset - is);
                            cursor += ie - is;
                            Some((off, ib.format))
                        }
                        _ => None,
                    };
                    comps.push(ComponentIngest {
                        vertex_byte_offset,
                        vertex_stride: vb.stride,
                        vertex_format: vb.format,
                        vertex_count: vb.count,
                        index,
                        first_index: c.index_range.map_or(0, |(first, _)| first),
                        triangle_count: e.triangles,
                        transform: c.transform,
                        primitive_base: prim_base,
                    });
                    prim_base += e.triangles;
                }
                plans.push(comps);
            }
            let mut rec = Recorder {
                device: &self.device,
                encoder,
                timestamps: timestamps.as_mut(),
                scope: "ingest",
                dispatches: 0,
            };
            // Geometries ingested once in this task (a second ingestion must follow the first).
            let mut ingested: HashMap<GeometryHandle, u32> = HashMap::new();
            for (t, _, _, _) in &ingestions {
                *ingested.entry(t.handle).or_default() += 1;
            }
            for (i, ((task, _, staged, triangles), comps)) in
                ingestions.iter().zip(plans).enumerate()
            {
                // An update refit in this task decodes its own triangles (the ingestion fused
                // into the refit): deferred to step 5, and recorded after it if the refit
                // waits for a later task (max_blas_build_count).
                let candidate = plan.build.is_some()
                    && task.operation == TaskOperation::Update
                    && ingested.get(&task.handle) == Some(&1);
                let rows = candidate
                    .then(|| crate::scene::ingest::component_rows(&comps, staged.start))
                    .flatten()
                    .filter(|rows| {
                        s.geometries.get(task.handle).is_ok_and(|slot| {
                            slot.data.as_ref().is_some_and(|d| {
                                d.gpu.pending != Some(PendingBvh::Build)
                                    && GpuScene::can_refit_from_raw(&d.gpu, *triangles, rows)
                            })
                        })
                    });
                match rows {
                    Some(rows) => {
                        deferred.insert(
                            task.handle,
                            DeferredIngest {
                                raw: raw.clone(),
                                components: comps,
                                rows,
                                staged: *staged,
                                ingestion: i as u32,
                            },
                        );
                    }
                    None => s
                        .scene
                        .record_ingest(&mut rec, &raw, &comps, *staged, i as u32),
                }
            }
            ws._inputs.push(raw);
            let readback = self.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("kickstart-rt ingestion counters read-back"),
                size: ingestions.len() as u64 * 8,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            ws.dropped = Some(DroppedReadback {
                buffer: readback,
                mapped: Arc::new(AtomicBool::new(false)),
                geometries: ingestions
                    .iter()
                    .map(|(t, _, _, _)| (t.handle, t.input.name.clone()))
                    .collect(),
            });
        }
        for (task, _, staged, triangles) in ingestions {
            let Ok(slot) = s.geometries.get_mut(task.handle) else {
                continue;
            };
            slot.last_used = serial;
            let pending = match (&slot.data, task.operation) {
                (Some(d), TaskOperation::Update) if d.gpu.blas.is_some() => PendingBvh::Refit,
                _ => PendingBvh::Build,
            };
            let data = slot.data.get_or_insert_with(|| GeometryData {
                name: task.input.name.clone(),
                allow_update: task.input.allow_update,
                max_leaf: task.input.build_hint.max_leaf(task.input.allow_update),
                triangles,
                gpu: GeometryGpu::default(),
                dropped: None,
                cache: crate::cache::CacheParams::of(&task.input),
                allow_light_transfer_target: task.input.allow_light_transfer_target,
            });
            data.gpu.triangles = triangles;
            data.gpu.staged = Some(staged);
            if data.gpu.pending.is_none() {
                s.blas_queue.push_back(task.handle);
            }
            // A queued build stays a build (the refit needs a built tree).
            if data.gpu.pending != Some(PendingBvh::Build) {
                data.gpu.pending = Some(pending);
            }
            s.counts.geometry_tasks += 1;
        }

        // 5. BLAS builds and refits, at most max_blas_build_count, in queue order.
        if let Some(build) = plan.build {
            let mut headers = Uploads::default();
            let mut rec = Recorder {
                device: &self.device,
                encoder,
                timestamps: timestamps.as_mut(),
                scope: "blas build",
                dispatches: 0,
            };
            let mut done = 0;
            while done < build.max_blas_build_count {
                let Some(h) = s.blas_queue.pop_front() else {
                    break;
                };
                let Ok(slot) = s.geometries.get_mut(h) else {
                    continue; // destroyed while queued
                };
                let Some(d) = slot.data.as_mut() else {
                    continue;
                };
                slot.last_used = serial;
                match d.gpu.pending.take() {
                    Some(PendingBvh::Build) => {
                        if let Some(old) = d.gpu.blas.take() {
                            let mut previous = GeometryGpu {
                                blas: Some(old),
                                ..Default::default()
                            };
                            previous.free_after(&mut s.scene, serial);
                        }
                        let header = s.scene.build_blas(
                            &mut rec,
                            h.index,
                            &mut d.gpu,
                            d.allow_update,
                            d.max_leaf,
                            &d.name,
                        )?;
                        headers.push(
                            &s.scene.geometry_table.buffer,
                            h.index as u64 * GEOMETRY_RECORD_SIZE,
                            bytemuck::bytes_of(&header),
                        );
                        if !d.allow_update {
                            // Static geometry: its staged copy is not needed after the build.
                            if let Some(r) = d.gpu.staged.take() {
                                s.scene.staged.free_after(r, serial);
                            }
                        }
                        s.tlas_rebuild = true;
                    }
                    Some(PendingBvh::Refit) => {
                        let fused = deferred.remove(&h);
                        s.scene
                            .refit_blas(&mut rec, h.index, &d.gpu, fused.as_ref());
                        s.tlas_refit = true;
                    }
                    None => continue,
                }
                done += 1;
            }
            ws.staging
                .extend(headers.flush(&self.device, &mut s.staging, encoder));
        }
        // Ingestions deferred for refits that step 5 left to a later task.
        if !deferred.is_empty() {
            let mut rec = Recorder {
                device: &self.device,
                encoder,
                timestamps: timestamps.as_mut(),
                scope: "ingest",
                dispatches: 0,
            };
            // In ingestion order, as they would have been recorded in step 4.
            let mut rest: Vec<DeferredIngest> = deferred.into_values().collect();
            rest.sort_by_key(|d| d.ingestion);
            for d in rest {
                s.scene
                    .record_ingest(&mut rec, &d.raw, &d.components, d.staged, d.ingestion);
            }
        }
        // The dropped-triangle counts, after every pass that counts them.
        if let Some(dropped) = &ws.dropped {
            encoder.copy_buffer_to_buffer(
                &s.scene.counters,
                0,
                &dropped.buffer,
                0,
                dropped.buffer.size(),
            );
        }

        // 6. TLAS over every instance slot, in every task that changed something it depends on
        //    (DESIGN.md's data flow), unless a BvhBuildTask opts out with `build_tlas: false`.
        let tlas_update = plan.build.map_or(Some(TlasUpdate::Auto), |b| {
            b.build_tlas.then_some(b.tlas_update)
        });
        if let Some(mode) = tlas_update.filter(|_| s.tlas_rebuild || s.tlas_refit) {
            let slots = s.instances.slot_count();
            let refit = !s.tlas_rebuild
                && match mode {
                    TlasUpdate::Rebuild => false,
                    TlasUpdate::Refit => true,
                    TlasUpdate::Auto => {
                        s.scene.tlas_refits_since_rebuild() < TlasUpdate::AUTO_REBUILD_AFTER_REFITS
                    }
                };
            let mut records = Uploads::default();
            for (slot, bytes) in std::mem::take(&mut s.pending_records) {
                records.push(
                    &s.scene.instance_table.buffer,
                    slot as u64 * INSTANCE_RECORD_SIZE,
                    &bytes,
                );
            }
            ws.staging
                .extend(records.flush(&self.device, &mut s.staging, encoder));
            let mut rec = Recorder {
                device: &self.device,
                encoder,
                timestamps: timestamps.as_mut(),
                scope: "tlas build",
                dispatches: 0,
            };
            s.scene.update_tlas(&mut rec, slots, refit)?;
            s.tlas_rebuild = false;
            s.tlas_refit = false;
        }

        // Instance bookkeeping (after the records are recorded).
        for t in plan.instances {
            if let Ok(g) = s.geometries.get_mut(t.input.geometry) {
                g.last_used = serial;
            }
            if let Ok(slot) = s.instances.get_mut(t.handle) {
                // A new instance, or another geometry: a new cache (a move keeps it).
                let new_cache = slot
                    .input
                    .as_ref()
                    .is_none_or(|o| o.geometry != t.input.geometry);
                slot.input = Some(t.input.clone());
                slot.last_used = serial;
                if new_cache {
                    s.cache.register(t.handle.index, serial);
                }
            }
            s.any_instance = true;
            s.counts.instance_tasks += 1;
        }

        // Direct lighting cache: grow what a read-back asked for, allocate waiting instances
        // whose BLAS is built (DESIGN.md data flow step 5).
        s.cache
            .prepare_task(encoder, s.instances.slot_count(), serial)?;
        let jobs = Self::cache_jobs(s);
        if !jobs.is_empty() {
            let mut rec = Recorder {
                device: &self.device,
                encoder,
                timestamps: timestamps.as_mut(),
                scope: "cache allocation",
                dispatches: 0,
            };
            s.cache
                .record_allocations(&mut rec, s.scene.triangles.buffer(), &jobs, serial)?;
        }

        // 7. Render tasks, in the order scheduled.
        for task in &container.render_tasks {
            let mut rec = Recorder {
                device: &self.device,
                encoder,
                timestamps: timestamps.as_mut(),
                scope: "",
                dispatches: 0,
            };
            match task {
                RenderTask::TraceRays(t) => {
                    ws._inputs.push(t.rays.clone());
                    ws._inputs.push(t.hits.clone());
                    s.scene.trace_rays(&mut rec, t);
                }
                RenderTask::DirectLightingInjection(t) => {
                    let meta = s.cache.meta_buffer().clone();
                    let surfels = s.cache.surfel_buffer().clone();
                    let capacity = s.cache.capacity();
                    s.cache.injector.record(
                        &mut rec,
                        &s.scene.scene_buffers(),
                        (&meta, &surfels, capacity),
                        t,
                    )?;
                }
                RenderTask::DirectLightTransfer(t) => {
                    let tris = s
                        .instances
                        .get(t.target)
                        .ok()
                        .and_then(|i| i.input.as_ref())
                        .and_then(|i| s.geometries.get(i.geometry).ok())
                        .and_then(|g| g.data.as_ref())
                        .map_or(0, |d| d.triangles);
                    let meta = s.cache.meta_buffer().clone();
                    let surfels = s.cache.surfel_buffer().clone();
                    s.cache.transferer.record(
                        &mut rec,
                        (&meta, &surfels),
                        t.source.index,
                        t.target.index,
                        tris,
                    );
                }
                other if TracePasses::handles(other) && is_default_output(other) => {
                    let st = &mut *s;
                    let passes = st
                        .trace
                        .get_or_insert_with(|| TracePasses::new(&self.device, &self.queue));
                    rec.scope = "trace";
                    let cache = st.cache.sample_bind_group_entries();
                    passes.record(&mut rec, &st.scene.scene_buffers(), &cache, other)?;
                }
                t if t.denoise_common().is_some() => s.denoise.record(&mut rec, t, serial),
                other => {
                    if let Some((common, output)) = other.trace_common() {
                        let size = output.texture().size();
                        let vp = common.viewport.unwrap_or(Viewport {
                            x: 0,
                            y: 0,
                            width: size.width,
                            height: size.height,
                        });
                        s.scene.debug_view_pass(
                            &mut rec,
                            output,
                            (vp.x, vp.y, vp.width, vp.height),
                            &common.view,
                            common.debug_parameters.debug_output_type,
                            (&s.cache, common.use_bilinear_sampling),
                        )?;
                    }
                }
            }
        }

        if let Some(ts) = timestamps {
            if let Some(r) = TimingReadback::record(&self.device, encoder, ts) {
                s.timings.insert(serial, r);
                // Timings nobody reads must not accumulate.
                while s.timings.len() > 64 {
                    s.timings.pop_first();
                }
            }
        }

        s.counts.gpu_tasks += 1;
        s.in_flight.insert(serial, ws);
        Ok(GpuTaskHandle(serial))
    }

    /// Checks every task of the container against the context's handles and the field rules.
    fn validate<'c>(&self, s: &State, c: &'c TaskContainer) -> Result<Plan<'c>> {
        let mut plan = Plan::default();
        let mut registered_here = std::collections::HashSet::new();
        let mut instances_here = std::collections::HashSet::new();
        let mut unsupported = None;
        for task in &c.bvh_tasks {
            match task {
                BvhTask::Geometry(t) => {
                    let slot = s.geometries.get(t.handle)?;
                    let extents = validate::geometry_input(&t.input)?;
                    match t.operation {
                        TaskOperation::Register
                            if slot.data.is_some() || registered_here.contains(&t.handle) =>
                        {
                            return Err(Error::input(
                                "GeometryTask",
                                "operation",
                                t.operation,
                                "this geometry is already registered; use TaskOperation::Update",
                            ));
                        }
                        TaskOperation::Update => match &slot.data {
                            None => {
                                return Err(Error::input(
                                    "GeometryTask",
                                    "operation",
                                    t.operation,
                                    "the geometry was never registered",
                                ))
                            }
                            Some(d) if !d.allow_update => {
                                return Err(Error::input(
                                    "GeometryTask",
                                    "operation",
                                    t.operation,
                                    format!(
                                        "geometry `{}` was registered without allow_update",
                                        d.name
                                    ),
                                ));
                            }
                            Some(d) => {
                                let n: u32 = extents.iter().map(|e| e.triangles).sum();
                                if n != d.triangles {
                                    return Err(Error::input(
                                        "GeometryTask",
                                        "input.components",
                                        format!("{n} triangles"),
                                        format!(
                                            "an Update of geometry `{}` must keep its {} triangles (its BVH is refitted); register a new geometry to change the topology",
                                            d.name, d.triangles
                                        ),
                                    ));
                                }
                            }
                        },
                        _ => {}
                    }
                    registered_here.insert(t.handle);
                    plan.geometries.push((t, extents));
                }
                BvhTask::Instance(t) => {
                    let slot = s.instances.get(t.handle)?;
                    let known = slot.input.is_some() || instances_here.contains(&t.handle);
                    match t.operation {
                        TaskOperation::Register if known => {
                            return Err(Error::input(
                                "InstanceTask",
                                "operation",
                                t.operation,
                                "this instance is already registered; use TaskOperation::Update",
                            ));
                        }
                        TaskOperation::Update if !known => {
                            return Err(Error::input(
                                "InstanceTask",
                                "operation",
                                t.operation,
                                "the instance was never registered",
                            ));
                        }
                        _ => {}
                    }
                    instances_here.insert(t.handle);
                    let g = s.geometries.get(t.input.geometry)?;
                    if g.data.is_none() && !registered_here.contains(&t.input.geometry) {
                        return Err(Error::input(
                            "InstanceTask",
                            "input.geometry",
                            t.input.geometry,
                            "the geometry has no registered mesh: schedule its GeometryTask first",
                        ));
                    }
                    validate::instance_input(&t.input)?;
                    plan.instances.push(t);
                }
                BvhTask::Build(t) => {
                    validate::bvh_build(t)?;
                    // The last BvhBuildTask of a container decides.
                    plan.build = Some(*t);
                }
            }
        }
        let limits = self.device.limits();
        for task in &c.render_tasks {
            validate::render_task(task, &limits)?;
            self.render_handles(s, task)?;
            let supported = match task {
                RenderTask::TraceRays(_)
                | RenderTask::DirectLightingInjection(_)
                | RenderTask::DirectLightTransfer(_) => true,
                t if TracePasses::handles(t) && is_default_output(t) => true,
                t if t.denoise_common().is_some() => true,
                other => other.trace_common().is_some_and(|(c, _)| {
                    matches!(
                        c.debug_parameters.debug_output_type,
                        DebugOutputType::HitT
                            | DebugOutputType::Barycentrics
                            | DebugOutputType::RandomMeshColor
                            | DebugOutputType::RandomTileColor
                            | DebugOutputType::DirectLightingCache
                    )
                }),
            };
            if !supported {
                unsupported.get_or_insert(task.name());
            }
        }
        match unsupported {
            Some(task) => Err(Error::Unsupported { task }),
            None => Ok(plan),
        }
    }

    fn render_handles(&self, s: &State, task: &RenderTask) -> Result<()> {
        if let RenderTask::DirectLightTransfer(t) = task {
            self.transfer_instances(s, t)?;
        }
        if let Some(c) = task.denoise_common() {
            crate::denoise::check_task(task, &s.denoisers.get(c.context)?.input)?;
        }
        Ok(())
    }
}

/// A trace task asking for its normal output (not a debug view).
fn is_default_output(task: &RenderTask) -> bool {
    task.trace_common()
        .is_some_and(|(c, _)| c.debug_parameters.debug_output_type == DebugOutputType::Default)
}

impl ExecuteContext {
    /// Checks a transfer: both instances registered (in an earlier task), distinct, the target's
    /// geometry allows transfer, and both geometries have the same triangle count.
    fn transfer_instances(&self, s: &State, t: &DirectLightTransferTask) -> Result<()> {
        const TASK: &str = "DirectLightTransferTask";
        let geometry = |h: InstanceHandle, field: &'static str| -> Result<&GeometryData> {
            s.instances
                .get(h)?
                .input
                .as_ref()
                .and_then(|i| s.geometries.get(i.geometry).ok())
                .and_then(|g| g.data.as_ref())
                .ok_or_else(|| {
                    Error::input(
                        TASK,
                        field,
                        h,
                        "the instance must be registered by an earlier GPU task",
                    )
                })
        };
        let src = geometry(t.source, "source")?;
        let dst = geometry(t.target, "target")?;
        if t.source == t.target {
            return Err(Error::input(
                TASK,
                "target",
                t.target,
                "must differ from the source",
            ));
        }
        if !dst.allow_light_transfer_target {
            return Err(Error::input(
                TASK,
                "target",
                t.target,
                format!(
                    "geometry `{}` was registered without allow_light_transfer_target",
                    dst.name
                ),
            ));
        }
        if src.triangles != dst.triangles {
            return Err(Error::input(
                TASK,
                "target",
                t.target,
                format!(
                    "the target's geometry has {} triangles, the source's {}: transfer maps primitive i to primitive i, so both need the same triangles in the same order",
                    dst.triangles, src.triangles
                ),
            ));
        }
        Ok(())
    }

    /// Allocation jobs of the instances waiting for a cache whose geometry's BLAS is built.
    fn cache_jobs(s: &State) -> Vec<crate::cache::AllocJob> {
        if s.cache.waiting().is_empty() {
            return Vec::new();
        }
        let mut jobs = Vec::new();
        for h in s.instances.handles() {
            if !s.cache.waiting().contains(&h.index) {
                continue;
            }
            let Some(input) = s.instances.get(h).ok().and_then(|i| i.input.as_ref()) else {
                continue;
            };
            let Some(d) = s
                .geometries
                .get(input.geometry)
                .ok()
                .and_then(|g| g.data.as_ref())
            else {
                continue;
            };
            let Some(blas) = d
                .gpu
                .blas
                .filter(|_| d.gpu.pending != Some(PendingBvh::Build))
            else {
                continue;
            };
            jobs.push(crate::cache::AllocJob {
                slot: h.index,
                tri_base: blas.tris.start,
                tri_count: d.triangles,
                params: d.cache,
                transform: input.transform,
                initial: input.initial_tile_color,
            });
            // One task allocates at most this many (the rest wait for the next tasks): with a
            // million instances waiting, collecting them all every task would dominate it.
            if jobs.len() == crate::cache::alloc::MAX_ALLOCS_PER_TASK {
                break;
            }
        }
        jobs
    }
}

#[derive(Default)]
struct Plan<'c> {
    geometries: Vec<(&'c GeometryTask, Vec<validate::ComponentExtent>)>,
    instances: Vec<&'c InstanceTask>,
    build: Option<BvhBuildTask>,
}

/// The instance's record (layout at [`INSTANCE_RECORD_SIZE`]).
fn instance_record(input: &InstanceInput) -> [u8; INSTANCE_RECORD_SIZE as usize] {
    // Rows of the 3×4 affine: transposing the 4×4 turns its columns into rows.
    let rows = glam::Mat4::from(input.transform)
        .transpose()
        .to_cols_array();
    let inv = glam::Mat4::from(input.transform.inverse())
        .transpose()
        .to_cols_array();
    let mut words = [0u32; 32];
    for i in 0..12 {
        words[i] = rows[i].to_bits();
        words[12 + i] = inv[i].to_bits();
    }
    words[24] = input.geometry.index;
    words[25] = input.inclusion_mask.0;
    words[26] = input.participating_in_tlas as u32;
    bytemuck::cast(words)
}

// The threading contract of DESIGN.md, checked by the compiler.
const _: () = {
    const fn send_sync<T: Send + Sync>() {}
    const fn send<T: Send>() {}
    send_sync::<ExecuteContext>();
    send::<TaskContainer>();
};
