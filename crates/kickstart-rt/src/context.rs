//! The SDK instance: handles, working sets, and recording GPU tasks into the engine's encoder.

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use crate::allocations::ResourceAllocations;
use crate::container::TaskContainer;
use crate::error::{Error, Result};
use crate::handles::*;
use crate::logging::{LogCallback, Logger, Severity};
use crate::staging::{StagingBuffer, StagingPool};
use crate::tasks::*;
use crate::validate;
use crate::version::Version;

static NEXT_CONTEXT_ID: AtomicU32 = AtomicU32::new(1);

/// Bytes of one instance's record in the instance data table. The table is indexed by the
/// instance handle's slot index, which is the instance index a ray hit reports.
pub const INSTANCE_RECORD_SIZE: u64 = 64;

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
}

impl Default for InitSettings {
    fn default() -> Self {
        InitSettings {
            supported_working_sets: 4,
            version: crate::VERSION,
            log_callback: None,
            min_log_severity: Severity::Warning,
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

/// GPU memory of a destroyed object, waiting for the tasks that used it.
struct Retired {
    last_used: u64,
    kind: AllocKind,
    buffers: Vec<wgpu::Buffer>,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum AllocKind {
    VertexCopies,
    Tlas,
}

struct GeometryData {
    name: String,
    allow_update: bool,
    triangles: u32,
    /// SDK-owned copies: per component, its vertex bytes and, when indexed, its index bytes.
    buffers: Vec<wgpu::Buffer>,
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
    #[allow(dead_code)]
    input: DenoisingContextInput,
}

/// Resources one in-flight GPU task holds until it is marked complete.
struct WorkingSet {
    staging: Vec<StagingBuffer>,
    /// Inputs the task reads, kept alive while the GPU may read them.
    _inputs: Vec<wgpu::Buffer>,
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
    retired: Vec<Retired>,
    in_flight: BTreeMap<u64, WorkingSet>,
    invoked: Vec<(u64, Arc<AtomicBool>)>,
    staging: StagingPool,
    instance_table: Option<wgpu::Buffer>,
    next_serial: u64,
    counts: RecordedTaskCounts,
}

/// The SDK instance (the reference's `ExecuteContext`). One per device; `Send + Sync`: handle
/// creation and destruction may happen on any thread, and `build_gpu_task` serialises internally
/// because GPU tasks must execute in the order they were built.
pub struct ExecuteContext {
    id: u32,
    device: wgpu::Device,
    queue: wgpu::Queue,
    working_sets: u32,
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
        let id = NEXT_CONTEXT_ID.fetch_add(1, Ordering::Relaxed);
        Ok(ExecuteContext {
            id,
            device: device.clone(),
            queue: queue.clone(),
            working_sets: settings.supported_working_sets,
            logger,
            state: Mutex::new(State {
                geometries: HandlePool::new(id),
                instances: HandlePool::new(id),
                denoisers: HandlePool::new(id),
                retired: Vec::new(),
                in_flight: BTreeMap::new(),
                invoked: Vec::new(),
                staging: StagingPool::default(),
                instance_table: None,
                next_serial: 1,
                counts: RecordedTaskCounts::default(),
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
        Ok(self.state().denoisers.insert(DenoisingSlot { input }))
    }

    /// Destroys a geometry. The handle is invalid at once; its GPU memory is released in the first
    /// `build_gpu_task` after every GPU task that used it has been marked complete.
    pub fn destroy_geometry_handle(&self, handle: GeometryHandle) -> Result<()> {
        let mut s = self.state();
        let slot = s.geometries.remove(handle)?;
        if let Some(d) = slot.data {
            s.retired.push(Retired {
                last_used: slot.last_used,
                kind: AllocKind::VertexCopies,
                buffers: d.buffers,
            });
        }
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

    /// Destroys an instance (lazily released, as geometries).
    pub fn destroy_instance_handle(&self, handle: InstanceHandle) -> Result<()> {
        self.state().instances.remove(handle).map(|_| ())
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
        s.retired.clear();
        s.staging.clear();
        Ok(())
    }

    /// GPU memory held, by kind.
    pub fn resource_allocations(&self) -> ResourceAllocations {
        let s = self.state();
        let mut a = ResourceAllocations::default();
        for d in s.geometries.values().filter_map(|g| g.data.as_ref()) {
            a.vertex_copies += d.buffers.iter().map(|b| b.size()).sum::<u64>();
        }
        for r in &s.retired {
            let bytes: u64 = r.buffers.iter().map(|b| b.size()).sum();
            match r.kind {
                AllocKind::VertexCopies => a.vertex_copies += bytes,
                AllocKind::Tlas => a.tlas += bytes,
            }
        }
        a.tlas += s.instance_table.as_ref().map_or(0, |b| b.size());
        a.staging = s.staging.bytes()
            + s.in_flight
                .values()
                .flat_map(|w| w.staging.iter())
                .map(|b| b.buffer.size())
                .sum::<u64>();
        a
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
        self.state().instance_table.clone()
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
        for b in ws.staging {
            s.staging.release(b);
        }
        Ok(())
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
                for b in ws.staging {
                    s.staging.release(b);
                }
            }
        }
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

        // 1. Deferred destruction: release what no in-flight task can still read.
        let oldest = s.in_flight.keys().next().copied().unwrap_or(u64::MAX);
        s.retired.retain(|r| r.last_used >= oldest);

        let serial = s.next_serial;
        s.next_serial += 1;
        let mut ws = WorkingSet {
            staging: Vec::new(),
            _inputs: Vec::new(),
        };

        // 2. Geometry ingestion: copy the application's bytes into SDK memory.
        for (task, extents) in plan.geometries {
            let mut buffers = Vec::new();
            for (c, e) in task.input.components.iter().zip(&extents) {
                let vb = &c.vertex_buffer.buffer;
                buffers.push(self.copy_in(encoder, vb, e.vertex_bytes, "vertices"));
                ws._inputs.push(vb.clone());
                if let (Some(ib), Some(r)) = (&c.index_buffer, e.index_bytes) {
                    buffers.push(self.copy_in(encoder, &ib.buffer, r, "indices"));
                    ws._inputs.push(ib.buffer.clone());
                }
            }
            let triangles = extents.iter().map(|e| e.triangles).sum();
            // Validated above: the handle is live.
            let Ok(slot) = s.geometries.get_mut(task.handle) else {
                continue;
            };
            let old = slot.data.replace(GeometryData {
                name: task.input.name.clone(),
                allow_update: task.input.allow_update,
                triangles,
                buffers,
            });
            let last_used = slot.last_used;
            slot.last_used = serial;
            if let Some(old) = old {
                s.retired.push(Retired {
                    last_used,
                    kind: AllocKind::VertexCopies,
                    buffers: old.buffers,
                });
            }
            s.counts.geometry_tasks += 1;
        }

        // 3. Instance data: written through this task's staging at the instance's slot index.
        if !plan.instances.is_empty() {
            let max_index = plan
                .instances
                .iter()
                .map(|t| t.handle.index)
                .max()
                .unwrap_or(0);
            self.ensure_instance_table(&mut s, encoder, max_index as u64 + 1, serial);
            let mut bytes =
                Vec::with_capacity(plan.instances.len() * INSTANCE_RECORD_SIZE as usize);
            for t in &plan.instances {
                bytes.extend_from_slice(&instance_record(&t.input));
            }
            let staging = s.staging.acquire(&self.device, bytes.len() as u64);
            if !staging.write(0, &bytes) {
                self.logger.message(
                    Severity::Error,
                    "kickstart-rt: staging buffer was not mapped; instance data not uploaded",
                );
            }
            staging.buffer.unmap();
            if let Some(table) = &s.instance_table {
                for (i, t) in plan.instances.iter().enumerate() {
                    encoder.copy_buffer_to_buffer(
                        &staging.buffer,
                        i as u64 * INSTANCE_RECORD_SIZE,
                        table,
                        t.handle.index as u64 * INSTANCE_RECORD_SIZE,
                        INSTANCE_RECORD_SIZE,
                    );
                }
            }
            ws.staging.push(staging);
            // Handles were validated above: these lookups cannot fail.
            for t in plan.instances {
                if let Ok(g) = s.geometries.get_mut(t.input.geometry) {
                    g.last_used = serial;
                }
                if let Ok(slot) = s.instances.get_mut(t.handle) {
                    slot.input = Some(t.input.clone());
                    slot.last_used = serial;
                }
                s.counts.instance_tasks += 1;
            }
        }

        s.counts.gpu_tasks += 1;
        s.in_flight.insert(serial, ws);
        Ok(GpuTaskHandle(serial))
    }

    fn copy_in(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        src: &wgpu::Buffer,
        (start, end): (u64, u64),
        what: &str,
    ) -> wgpu::Buffer {
        let dst = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(&format!("kickstart-rt geometry {what}")),
            size: end - start,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_DST
                | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        encoder.copy_buffer_to_buffer(src, start, &dst, 0, end - start);
        dst
    }

    /// Grows the instance table to hold `needed` records, carrying old records over in the
    /// encoder. The check counts records of the real size (see the instance-id bug report's
    /// growth bug).
    fn ensure_instance_table(
        &self,
        s: &mut State,
        encoder: &mut wgpu::CommandEncoder,
        needed: u64,
        serial: u64,
    ) {
        let have = s
            .instance_table
            .as_ref()
            .map_or(0, |b| b.size() / INSTANCE_RECORD_SIZE);
        if have >= needed {
            return;
        }
        let capacity = needed.next_power_of_two().max(64);
        let table = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("kickstart-rt instance table"),
            size: capacity * INSTANCE_RECORD_SIZE,
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_DST
                | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        if let Some(old) = s.instance_table.replace(table.clone()) {
            encoder.copy_buffer_to_buffer(&old, 0, &table, 0, old.size());
            s.retired.push(Retired {
                last_used: serial,
                kind: AllocKind::Tlas,
                buffers: vec![old],
            });
        }
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
                            _ => {}
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
                    unsupported.get_or_insert("BvhBuildTask (BLAS/TLAS builds)");
                }
            }
        }
        for task in &c.render_tasks {
            validate::render_task(task)?;
            self.render_handles(s, task)?;
            unsupported.get_or_insert(task.name());
        }
        match unsupported {
            Some(task) => Err(Error::Unsupported { task }),
            None => Ok(plan),
        }
    }

    fn render_handles(&self, s: &State, task: &RenderTask) -> Result<()> {
        if let RenderTask::DirectLightTransfer(t) = task {
            s.instances.get(t.source)?;
            s.instances.get(t.target)?;
        }
        if let Some(c) = task.denoise_common() {
            s.denoisers.get(c.context)?;
        }
        Ok(())
    }
}

#[derive(Default)]
struct Plan<'c> {
    geometries: Vec<(&'c GeometryTask, Vec<validate::ComponentExtent>)>,
    instances: Vec<&'c InstanceTask>,
}

fn instance_record(input: &InstanceInput) -> [u8; INSTANCE_RECORD_SIZE as usize] {
    let m = glam::Mat4::from(input.transform)
        .transpose()
        .to_cols_array();
    let mut words = [0u32; 16];
    for i in 0..12 {
        words[i] = m[i].to_bits();
    }
    words[12] = input.geometry.index;
    words[13] = input.inclusion_mask.0;
    words[14] = input.participating_in_tlas as u32;
    bytemuck::cast(words)
}

// The threading contract of DESIGN.md, checked by the compiler.
const _: () = {
    const fn send_sync<T: Send + Sync>() {}
    const fn send<T: Send>() {}
    send_sync::<ExecuteContext>();
    send::<TaskContainer>();
};
