//! The SDK instance: handles, working sets, and GPU tasks recorded into the engine's encoder.
//!
//! `build_gpu_task` runs in two phases: [`plan`] checks every task of a container against the
//! context's state without changing anything (including, in [`reserve`], that the memory the
//! task allocates fits the device), and [`record`] carries the checked plan out, one function
//! per step of the data flow; it cannot fail, so a refused task never changes the context. The render effects live in [`effects`], the state kept
//! between tasks in [`state`].

mod compaction;
mod effects;
mod plan;
mod raw_copy;
mod record;
mod reserve;
mod settings;
mod shaders;
mod state;
mod validate;

use std::collections::{BTreeMap, VecDeque};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use crate::allocations::{BlasMemory, ResourceAllocations};
use crate::container::TaskContainer;
use crate::device::BackendReport;
use crate::error::{Error, Result};
use crate::gpu::recorder::Timestamps;
use crate::handles::*;
use crate::logging::{LogCallback, Logger, Severity};
use crate::scene::gpu_scene::{GpuScene, NODE_BYTES, TRIANGLE_BYTES};
use crate::staging::StagingPool;
use crate::tasks::*;
use crate::timing::{GpuTimings, TimingReadback};
use effects::Effects;
use record::Frame;
pub use settings::{DroppedTriangles, InitSettings, RecordedTaskCounts, INSTANCE_RECORD_SIZE};
pub use shaders::{shader_variants, ShaderVariant};
use state::{DenoisingSlot, GeometrySlot, InstanceSlot, State, WorkingSet};

static NEXT_CONTEXT_ID: AtomicU32 = AtomicU32::new(1);

/// The SDK instance (the reference's `ExecuteContext`). One per device; `Send + Sync`: handle
/// creation and destruction may happen on any thread, and `build_gpu_task` serialises internally
/// because GPU tasks must execute in the order they were built.
pub struct ExecuteContext {
    id: u32,
    device: wgpu::Device,
    queue: wgpu::Queue,
    working_sets: u32,
    gpu_timing: bool,
    /// The traversal backend and why it was chosen.
    backend: BackendReport,
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
        if settings.version.major != crate::version::VERSION.major {
            return Err(Error::IncompatibleVersion {
                app: settings.version,
                library: crate::version::VERSION,
            });
        }
        if settings.version.minor != crate::version::VERSION.minor {
            logger.message(
                Severity::Warning,
                &format!(
                    "application built against kickstart-rt {}, library is {}",
                    settings.version,
                    crate::version::VERSION
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
        let backend = crate::device::choose_backend(device, settings.backend)?;
        logger.message(
            Severity::Info,
            &format!(
                "kickstart-rt traces with the {} backend ({})",
                backend.backend, backend.reason
            ),
        );
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
            backend: backend.clone(),
            logger,
            state: Mutex::new(State {
                geometries: HandlePool::new(id),
                instances: HandlePool::new(id),
                denoisers: HandlePool::new(id),
                in_flight: BTreeMap::new(),
                invoked: Vec::new(),
                staging: StagingPool::default(),
                scene: GpuScene::new(device, backend.backend, id),
                effects: Effects::new(device, backend.backend),
                blas_queue: VecDeque::new(),
                dead_instance_slots: Vec::new(),
                dead_geometry_slots: Vec::new(),
                pending_records: BTreeMap::new(),
                tlas_rebuild: false,
                tlas_refit: false,
                any_instance: false,
                dropped_readbacks: Vec::new(),
                node_count_readbacks: Vec::new(),
                timings: BTreeMap::new(),
                next_serial: 1,
                device_error: None,
                counts: RecordedTaskCounts::default(),
                cache: crate::cache::DirectLightingCache::new(
                    device,
                    (settings.lighting_cache_pool_bytes / 16).min(u32::MAX as u64) as u32,
                    backend.backend,
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
            s.scene.note_pool_frees();
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

    /// Releases the memory of destroyed handles and pooled staging now, and what only BLAS
    /// builds use: the build scratch and the free space of the BLAS pools (their ranges in use
    /// are copied into smaller buffers by a submission of its own on the context's queue).
    /// Refused with [`Error::TasksInFlight`] while any built GPU task is not marked complete.
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
        // Destroyed denoising contexts are otherwise retired only by the next build.
        let live = s.denoisers.handles();
        s.effects.denoisers.retire_destroyed(&live);
        s.effects.denoisers.collect(u64::MAX);
        s.staging.clear();
        let mut encoder = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("kickstart-rt release"),
            });
        s.scene.give_back_build_memory(&mut encoder);
        self.queue.submit([encoder.finish()]);
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
            denoiser: s.effects.denoisers.bytes(),
            ..Default::default()
        };
        if sc.hardware.is_some() {
            a.driver_acceleration_structures = driver_structure_bytes(&self.device, self.id);
        }
        a.staging = s.staging.bytes()
            + s.in_flight
                .values()
                .flat_map(|w| w.staging.iter())
                .map(|b| b.buffer.size())
                .sum::<u64>();
        a
    }

    /// GPU bytes of one denoising context: its guides and signal histories, sized for the grid
    /// of its last frame (0 before its first frame). The filter intermediate all contexts share
    /// is not in it (see [`ResourceAllocations::denoiser`]).
    pub fn denoising_context_bytes(&self, handle: DenoisingContextHandle) -> Result<u64> {
        let s = self.state();
        s.denoisers.get(handle)?;
        Ok(s.effects.denoisers.context_bytes(&handle))
    }

    /// An instance's lighting cache as the GPU allocated it: `None` until the allocating task has
    /// been marked complete and its log has been read back (asynchronously: a later call after a
    /// device poll sees it), or while the instance waits for its geometry's BLAS.
    pub fn lighting_cache_allocation(
        &self,
        handle: InstanceHandle,
    ) -> Result<Option<crate::cache::CacheAllocation>> {
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
        s.retire(handle.0, ws);
        Ok(())
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

    /// GPU memory of a geometry's BLAS (its triangles, nodes and refit data), or `None` until
    /// it is built. A fast-trace BLAS (`BuildHint::PreferFastTrace`, or `Auto` without
    /// `allow_update`) is compacted: its build drops the nodes its collapsed leaves left
    /// unreferenced, and its node range shrinks once the build's node count is read back (the
    /// first call to the context after its task completed and a device poll);
    /// [`BlasMemory::compaction`] says which applies. The memory given back returns to the
    /// driver when the next task without geometry work packs the node pool.
    pub fn geometry_blas_memory(&self, handle: GeometryHandle) -> Result<Option<BlasMemory>> {
        let mut s = self.state();
        self.collect_invoked(&mut s);
        let Some(blas) = s
            .geometries
            .get(handle)?
            .data
            .as_ref()
            .and_then(|d| d.gpu.blas)
        else {
            return Ok(None);
        };
        let (order, topology) = blas.refit.map_or((0, 0), |(o, t)| (o.len, t.len));
        Ok(Some(BlasMemory {
            triangle_bytes: u64::from(blas.tris.len) * TRIANGLE_BYTES,
            node_bytes: u64::from(blas.nodes.len) * NODE_BYTES,
            refit_bytes: (u64::from(order) + u64::from(topology)) * 4,
            compaction: blas.compaction,
        }))
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

    /// The traversal backend every trace of this context uses, and why it was chosen
    /// ([`InitSettings::backend`] and what the device offers).
    pub fn traversal_backend(&self) -> &BackendReport {
        &self.backend
    }

    /// Creates every compute pipeline now, so the first frame that needs one does not stall.
    ///
    /// The software traversal has two builds: one that tests cutout geometry's opacity, and one
    /// without the test, which traces while the scene holds no cutout geometry (so opaque scenes
    /// pay nothing for cutouts). This prepares the build the scene needs as registered now: call
    /// it once the level's geometry is registered. The other build is created on first use,
    /// when the scene gains its first cutout geometry or loses its last.
    pub fn prepare_pipelines(&self) {
        let mut s = self.state();
        let leaf = s.scene.leaf_test();
        s.scene.prepare_pipelines();
        s.effects.prepare_pipelines(&self.device, &self.queue, leaf);
        s.cache.prepare_pipelines(leaf);
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
    /// nothing here blocks. When several threads poll one device, the callback runs on whichever
    /// thread's poll took it, which may finish a moment after another thread's waiting poll has
    /// returned: the task counts as in flight until then.
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
                s.retire(serial, ws);
            }
        }
        s.collect_dropped(&self.logger);
        s.collect_node_counts();
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
        if let Some(message) = &s.device_error {
            return Err(Error::Device {
                operation: "build_gpu_task",
                message: message.clone(),
            });
        }
        // Whatever the device reports while this call runs is this task's error, returned to
        // the caller, not a panic of wgpu's default error handler (a lost device makes every
        // later command fail).
        let scopes = DeviceErrorScopes::push(&self.device);
        // Retiring the work the GPU has finished is not part of this task: it runs whether or
        // not the task is accepted.
        self.collect_invoked(&mut s);
        if let Some(message) = scopes.pop() {
            return Err(s.device_lost("build_gpu_task", message));
        }
        let scopes = DeviceErrorScopes::push(&self.device);
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
        let mut plan = plan::plan(&s, &container, &self.device.limits())?;
        // Last: every input is valid; the device memory the record phase allocates must fit.
        plan.reserved = reserve::check(&s, &plan)?;
        let s = &mut *s;
        let serial = s.next_serial;
        s.next_serial += 1;
        let mut frame = Frame {
            device: &self.device,
            queue: &self.queue,
            encoder,
            timestamps: self.gpu_timing.then(|| Timestamps::new(&self.device)),
            ws: WorkingSet {
                staging: Vec::new(),
                held: Vec::new(),
                dropped: None,
                node_counts: None,
            },
            serial,
        };
        record::record(&mut frame, s, &plan);
        if let Some(ts) = frame.timestamps.take() {
            if let Some(r) = TimingReadback::record(&self.device, frame.encoder, ts) {
                s.timings.insert(serial, r);
                // Timings nobody reads must not accumulate.
                while s.timings.len() > 64 {
                    s.timings.pop_first();
                }
            }
        }
        if let Some(message) = scopes.pop() {
            return Err(s.device_lost("build_gpu_task", message));
        }
        s.counts.gpu_tasks += 1;
        s.in_flight.insert(serial, frame.ws);
        Ok(GpuTaskHandle(serial))
    }
}

/// Error scopes for every kind of device error, pushed around a call that records; popped,
/// they say what the device reported inside them. wgpu requires scopes to be popped in reverse
/// order, also when a call returns early and drops them: the fields are declared innermost
/// first, and Rust drops fields in declaration order.
struct DeviceErrorScopes {
    internal: wgpu::ErrorScopeGuard,
    oom: wgpu::ErrorScopeGuard,
    validation: wgpu::ErrorScopeGuard,
}

impl DeviceErrorScopes {
    fn push(device: &wgpu::Device) -> Self {
        let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let oom = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let internal = device.push_error_scope(wgpu::ErrorFilter::Internal);
        DeviceErrorScopes {
            internal,
            oom,
            validation,
        }
    }

    /// Pops the scopes (innermost first); the first error any of them caught. On native
    /// backends the result is known at once; a backend that answers later reports nothing here
    /// (its errors reach the application's uncaptured-error handler as before).
    fn pop(self) -> Option<String> {
        let DeviceErrorScopes {
            internal,
            oom,
            validation,
        } = self;
        let mut first = None;
        for guard in [internal, oom, validation] {
            let future = std::pin::pin!(guard.pop());
            let mut cx = std::task::Context::from_waker(std::task::Waker::noop());
            if let std::task::Poll::Ready(Some(e)) = std::future::Future::poll(future, &mut cx) {
                first.get_or_insert_with(|| e.to_string());
            }
        }
        first
    }
}

/// Bytes of the driver acceleration structures the hardware backend made, by wgpu's allocator
/// report (their sizes are the driver's; wgpu does not tell them otherwise). 0 where wgpu has no
/// report.
fn driver_structure_bytes(device: &wgpu::Device, context_id: u32) -> u64 {
    let prefix = crate::scene::hardware::driver_label_prefix(context_id);
    device.generate_allocator_report().map_or(0, |r| {
        r.allocations
            .iter()
            .filter(|a| a.name.starts_with(&prefix))
            .map(|a| a.size)
            .sum()
    })
}
