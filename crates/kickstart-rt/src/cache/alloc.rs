//! The cache's GPU memory and its allocation: the `meta` buffer (headers per instance slot and
//! triangle records, CPU-allocated since their sizes are known) and the surfel pool (allocated on
//! the GPU, since the surfel count depends on the geometry the CPU never sees).

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use bytemuck::{Pod, Zeroable};

use super::{inject::Injector, transfer::Transferer, CacheParams};
use crate::error::{Error, Result};
use crate::gpu::buffers::storage;
use crate::gpu::reflect::{ReflectedLayout, ShaderReflection};
use crate::gpu::Recorder;
use crate::scene::pool::{Pool, Range};
use crate::scene::traversal::LeafTest;

/// Words per instance header and per triangle record in `meta`.
pub(crate) const HEADER_WORDS: u32 = 8;
pub(crate) const RECORD_WORDS: u32 = 8;
/// Bytes of one surfel.
pub(crate) const SURFEL_BYTES: u64 = 16;
/// Free blocks handed to the GPU per task, and allocations per task (the rest wait a task).
const MAX_FREE_BLOCKS: usize = 64;
pub(crate) const MAX_ALLOCS_PER_TASK: usize = 256;
/// Word offsets of the allocation state buffer (as `cache/alloc.wgsl`).
const ST_FREE: u64 = 4;
const ST_LOG: u64 = 132;

/// Surfels of a new context's pool (grown on demand).
pub(crate) const DEFAULT_INITIAL_SURFELS: u32 = 1 << 18;

/// One instance's allocation to record this task.
#[derive(Debug, Clone)]
pub(crate) struct AllocJob {
    pub slot: u32,
    /// First triangle slot of the geometry's BLAS in the triangle pool, and its triangle count.
    pub tri_base: u32,
    pub tri_count: u32,
    pub params: CacheParams,
    pub transform: glam::Affine3A,
    pub initial: glam::Vec4,
}

/// The WGSL of the allocation passes, labelled.
pub(crate) fn shader_variants() -> Vec<(String, String)> {
    vec![("cache allocation".into(), alloc_wgsl())]
}

/// The WGSL of the allocation passes (entry points `insert`, `count`, `allocate`, `write`).
fn alloc_wgsl() -> String {
    crate::gpu::compose::compose(&["cache/alloc"], &[])
}

#[repr(C)]
#[derive(Pod, Zeroable, Clone, Copy)]
struct AllocParams {
    rows: [[f32; 4]; 3],
    initial: [f32; 4],
    tri_count: u32,
    tri_base: u32,
    records: u32,
    header: u32,
    hash_size: u32,
    mesh_colors: u32,
    resolution_limit: u32,
    force_direct: u32,
    unit_length: f32,
    direct_threshold: f32,
    log_index: u32,
    pad: u32,
}

/// Where an instance's surfels are, as far as the CPU knows.
#[derive(Debug, Clone, Copy)]
enum Surfels {
    /// Allocated by task `serial`, entry `log` of its log; not read back yet.
    Pending { serial: u64, log: usize },
    /// Read back: `len` surfels at `start`; `level` 0 full, 1 coarse, 2 none.
    Known { start: u32, len: u32, level: u32 },
}

struct InstanceCache {
    records: Range,
    surfels: Surfels,
}

struct AllocReadback {
    serial: u64,
    buffer: wgpu::Buffer,
    mapped: Arc<AtomicBool>,
    /// Instance slot of each log entry.
    slots: Vec<u32>,
    started: bool,
}

struct Pipelines {
    /// The passes' one group, as the shader declares it (one layout for the four entry points,
    /// so one bind group serves them all).
    layout: ReflectedLayout,
    insert: wgpu::ComputePipeline,
    count: wgpu::ComputePipeline,
    allocate: wgpu::ComputePipeline,
    write: wgpu::ComputePipeline,
}

/// The direct lighting cache of a context (`State::cache`).
pub(crate) struct DirectLightingCache {
    device: wgpu::Device,
    max_binding: u64,
    /// Headers and triangle records (`u32` words). Words 0–1: header region start and slots.
    meta: Pool,
    headers: Range,
    header_slots: u32,
    surfels: wgpu::Buffer,
    capacity: u32,
    /// The allocation state: top, capacity, handed free blocks, the task's log.
    state: wgpu::Buffer,
    scratch: wgpu::Buffer,
    instances: HashMap<u32, InstanceCache>,
    /// Instance slots waiting for an allocation (geometry not built, or re-allocation). A set:
    /// registering a million instances in one task must not search a list per instance.
    waiting: BTreeSet<u32>,
    free: BTreeMap<u32, u32>,
    pending_free: Vec<(u64, u32, u32)>,
    readbacks: Vec<AllocReadback>,
    grow_to: Option<u32>,
    /// Caches released before their read-back arrived: (task, log entry, last use).
    orphans: Vec<(u64, usize, u64)>,
    /// Slots whose header must read "no cache" from the next task on.
    cleared: Vec<u32>,
    /// The pool's capacity was written to the allocation state.
    state_ready: bool,
    pipelines: Option<Pipelines>,
    pub(crate) injector: Injector,
    pub(crate) transferer: Transferer,
}

impl DirectLightingCache {
    /// An empty cache with a pool of `initial_surfels`, whose injection traces its visibility
    /// rays with `backend`.
    pub fn new(
        device: &wgpu::Device,
        encoder_free_init: u32,
        backend: crate::device::TraversalBackend,
    ) -> Self {
        let limits = device.limits();
        let max_binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        let capacity = encoder_free_init
            .max(64)
            .min((max_binding / SURFEL_BYTES) as u32);
        let mut meta = Pool::new(device, "kickstart-rt cache meta", 4);
        // The first range of an empty pool starts at 0: words 0–1 locate the header region.
        // (No copy is recorded: the pool has room for it.)
        let mut scratch_encoder = device.create_command_encoder(&Default::default());
        let first = meta.alloc(device, &mut scratch_encoder, 2, u64::MAX);
        debug_assert_eq!(first.map(|r| r.start), Some(0));
        drop(scratch_encoder);
        let state_words = ST_LOG + 4 * MAX_ALLOCS_PER_TASK as u64;
        let state = storage(
            device,
            "kickstart-rt cache allocation state",
            state_words * 4,
        );
        DirectLightingCache {
            device: device.clone(),
            max_binding,
            meta,
            headers: Range { start: 0, len: 0 },
            header_slots: 0,
            surfels: storage(
                device,
                "kickstart-rt cache surfels",
                capacity as u64 * SURFEL_BYTES,
            ),
            capacity,
            state,
            scratch: storage(device, "kickstart-rt cache allocation scratch", 4),
            instances: HashMap::new(),
            waiting: BTreeSet::new(),
            free: BTreeMap::new(),
            pending_free: Vec::new(),
            readbacks: Vec::new(),
            grow_to: None,
            orphans: Vec::new(),
            cleared: Vec::new(),
            state_ready: false,
            pipelines: None,
            injector: Injector::new(backend),
            transferer: Transferer::default(),
        }
    }

    /// The sampling bindings by the names `cache/sample` gives them (valid before any instance
    /// exists).
    pub fn sample_resources(&self) -> [(&'static str, wgpu::BindingResource<'_>); 2] {
        [
            ("cache_meta", self.meta.buffer().as_entire_binding()),
            ("cache_surfels", self.surfels.as_entire_binding()),
        ]
    }

    pub(crate) fn meta_buffer(&self) -> &wgpu::Buffer {
        self.meta.buffer()
    }

    pub(crate) fn surfel_buffer(&self) -> &wgpu::Buffer {
        &self.surfels
    }

    /// Surfels the pool holds.
    pub(crate) fn capacity(&self) -> u32 {
        self.capacity
    }

    /// The surfel capacity the next task records with: today's, or the growth a read-back asked
    /// for, which that task's preparation applies first.
    pub(crate) fn planned_capacity(&self) -> u32 {
        self.grow_to.unwrap_or(self.capacity)
    }

    /// GPU bytes of the cache (meta, surfel pool, allocation and injection buffers).
    pub fn bytes(&self) -> u64 {
        self.meta.buffer().size()
            + self.surfels.size()
            + self.state.size()
            + self.scratch.size()
            + self.injector.bytes()
    }

    /// A (re-)registered instance: its old cache is released, a new one waits for allocation.
    pub fn register(&mut self, slot: u32, last_used: u64) {
        self.release(slot, last_used);
        self.waiting.insert(slot);
    }

    /// The slots waiting for an allocation.
    pub fn waiting(&self) -> &BTreeSet<u32> {
        &self.waiting
    }

    /// Releases the cache of instance slot `slot` once task `last_used` has completed (the header
    /// is cleared by the next [`Self::record_allocations`] call that allocates the slot, or by
    /// `clear_headers`).
    pub fn release(&mut self, slot: u32, last_used: u64) {
        self.waiting.remove(&slot);
        let Some(c) = self.instances.remove(&slot) else {
            return;
        };
        if c.records.len > 0 {
            self.meta.free_after(c.records, last_used);
        }
        match c.surfels {
            Surfels::Known { start, len, .. } => {
                if len > 0 {
                    self.pending_free.push((last_used, start, len));
                }
            }
            // Freed when its read-back says where it is.
            Surfels::Pending { serial, log } => self.orphans.push((serial, log, last_used)),
        }
        self.cleared.push(slot);
    }

    /// Frees ranges no in-flight task can read; applies allocation read-backs that arrived.
    pub fn collect(&mut self, oldest_in_flight: u64) {
        self.meta.collect(oldest_in_flight);
        let mut i = 0;
        while i < self.pending_free.len() {
            let (last, start, len) = self.pending_free[i];
            if last < oldest_in_flight {
                self.pending_free.swap_remove(i);
                free_insert(&mut self.free, start, len);
            } else {
                i += 1;
            }
        }
        let mut k = 0;
        while k < self.readbacks.len() {
            if !self.readbacks[k].mapped.load(Ordering::Acquire) {
                k += 1;
                continue;
            }
            let r = self.readbacks.swap_remove(k);
            let words: Vec<u32> = match r.buffer.slice(..).get_mapped_range() {
                Ok(view) => bytemuck::pod_collect_to_vec(&view),
                Err(_) => continue,
            };
            self.apply_log(&r, &words);
        }
    }

    fn apply_log(&mut self, r: &AllocReadback, words: &[u32]) {
        let w = |i: u64| words.get(i as usize).copied().unwrap_or(0);
        // Blocks the GPU did not use return to the free list.
        for b in 0..MAX_FREE_BLOCKS as u64 {
            let (start, len) = (w(ST_FREE + 2 * b), w(ST_FREE + 2 * b + 1));
            if len > 0 && b < w(2) as u64 {
                free_insert(&mut self.free, start, len);
            }
        }
        let top = w(0);
        let mut shortfall = 0u64;
        for (i, slot) in r.slots.iter().enumerate() {
            let l = ST_LOG + 4 * i as u64;
            let (start, len, level, full) = (w(l), w(l + 1), w(l + 2), w(l + 3));
            let known = Surfels::Known { start, len, level };
            if let Some(k) = self
                .orphans
                .iter()
                .position(|&(s, log, _)| s == r.serial && log == i)
            {
                let (_, _, last) = self.orphans.swap_remove(k);
                if len > 0 {
                    self.pending_free.push((last, start, len));
                }
                continue;
            }
            if let Some(c) = self.instances.get_mut(slot) {
                if matches!(c.surfels, Surfels::Pending { serial, log } if serial == r.serial && log == i)
                {
                    c.surfels = known;
                    if level > 0 {
                        shortfall += full as u64;
                    }
                }
            }
        }
        if shortfall > 0 {
            let need = top as u64 + shortfall;
            let want = (need + need / 4)
                .max(self.capacity as u64 * 2)
                .min(self.max_binding / SURFEL_BYTES)
                .min(u32::MAX as u64) as u32;
            if want > self.capacity {
                self.grow_to = Some(self.grow_to.map_or(want, |g| g.max(want)));
            }
        }
    }

    /// Starts reading back the allocation log of a completed task.
    pub fn task_completed(&mut self, serial: u64) {
        for r in self.readbacks.iter_mut().filter(|r| r.serial == serial) {
            if r.started {
                continue;
            }
            r.started = true;
            let flag = r.mapped.clone();
            r.buffer.map_async(wgpu::MapMode::Read, .., move |res| {
                if res.is_ok() {
                    flag.store(true, Ordering::Release);
                }
            });
        }
    }

    fn pipelines(&mut self) -> &Pipelines {
        let device = &self.device;
        self.pipelines.get_or_insert_with(|| {
            let source = alloc_wgsl();
            let reflection = ShaderReflection::new(&source)
                .unwrap_or_else(|e| panic!("cache allocation: composed WGSL is invalid: {e}"));
            let layout =
                ReflectedLayout::new(device, "kickstart-rt cache allocation", &reflection, 0);
            let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("kickstart-rt cache allocation"),
                bind_group_layouts: &[Some(layout.layout())],
                immediate_size: 0,
            });
            let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("kickstart-rt cache allocation"),
                source: wgpu::ShaderSource::Wgsl(source.as_str().into()),
            });
            let make = |entry: &str| {
                device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some("kickstart-rt cache allocation"),
                    layout: Some(&pl),
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    cache: None,
                })
            };
            Pipelines {
                insert: make("insert"),
                count: make("count"),
                allocate: make("allocate"),
                write: make("write"),
                layout,
            }
        })
    }

    /// Creates the pipelines now, the injection's tracing with the traversal build `leaf`.
    pub fn prepare_pipelines(&mut self, leaf: LeafTest) {
        self.pipelines();
        self.injector.prepare(&self.device, leaf);
        self.transferer.prepare(&self.device);
    }

    /// Refuses a task whose `slots` instance slots would grow the header region past the
    /// device's binding size: the plan's check of [`Self::prepare_task`], on a copy of the meta
    /// pool's ledger as that task will find it: collected from `oldest_in_flight` on
    /// ([`Self::collect`]), and nothing else allocated from it before.
    pub fn check_headers(&self, slots: u32, oldest_in_flight: u64) -> Result<()> {
        if slots <= self.header_slots {
            return Ok(());
        }
        let (_, words) = header_region(slots);
        let mut meta = self.meta.ledger().clone();
        meta.collect(oldest_in_flight);
        match meta.alloc(words, self.max_binding) {
            Some(_) => Ok(()),
            None => Err(Error::OutOfDeviceMemory {
                what: "lighting cache headers".into(),
                bytes: words as u64 * 4,
                limit: self.max_binding,
            }),
        }
    }

    /// Refuses an instance whose geometry has `triangles` triangles when the allocation passes'
    /// scratch for it would exceed the device's binding size: checked by the plan for every
    /// instance task, so that [`Self::record_allocations`], which allocates the instance's
    /// cache in this or a later task, cannot fail.
    pub fn check_allocation(&self, triangles: u32) -> Result<()> {
        let (_, words) = scratch_words(triangles.max(1));
        if words * 4 > self.max_binding {
            return Err(Error::OutOfDeviceMemory {
                what: "lighting cache allocation scratch".into(),
                bytes: words * 4,
                limit: self.max_binding,
            });
        }
        Ok(())
    }

    /// Grows the header region to `slots` instance slots ([`Self::check_headers`] admitted them)
    /// and the pool when a read-back asked for it (degraded caches are re-allocated). Records
    /// copies into `encoder`.
    pub fn prepare_task(&mut self, encoder: &mut wgpu::CommandEncoder, slots: u32, serial: u64) {
        let device = self.device.clone();
        if slots > self.header_slots {
            let (new_slots, words) = header_region(slots);
            let range = self
                .meta
                .alloc(&self.device, encoder, words, self.max_binding)
                .expect("the plan reserved the headers (DirectLightingCache::check_headers)");
            let meta = self.meta.buffer().clone();
            if self.header_slots > 0 {
                // Same-buffer copies are not allowed: go through a temporary buffer.
                let bytes = self.headers.len as u64 * 4;
                let tmp = storage(&self.device, "kickstart-rt cache header copy", bytes);
                encoder.copy_buffer_to_buffer(&meta, self.headers.start as u64 * 4, &tmp, 0, bytes);
                encoder.copy_buffer_to_buffer(&tmp, 0, &meta, range.start as u64 * 4, bytes);
                self.meta.free_after(self.headers, serial);
            }
            encoder.clear_buffer(
                &meta,
                (range.start + self.header_slots * HEADER_WORDS) as u64 * 4,
                Some(((new_slots - self.header_slots) * HEADER_WORDS) as u64 * 4),
            );
            upload(&device, encoder, &meta, 0, &[range.start, new_slots]);
            self.headers = range;
            self.header_slots = new_slots;
        }
        if let Some(new_cap) = self.grow_to.take() {
            let new = storage(
                &self.device,
                "kickstart-rt cache surfels",
                new_cap as u64 * SURFEL_BYTES,
            );
            encoder.copy_buffer_to_buffer(&self.surfels, 0, &new, 0, self.surfels.size());
            self.surfels = new;
            self.capacity = new_cap;
            upload(&device, encoder, &self.state, 4, &[new_cap]);
            // Degraded caches are allocated again at full resolution.
            let degraded: Vec<u32> = self
                .instances
                .iter()
                .filter(|(_, c)| matches!(c.surfels, Surfels::Known { level, .. } if level > 0))
                .map(|(k, _)| *k)
                .collect();
            for slot in degraded {
                self.register(slot, serial);
            }
        }
        if !self.state_ready {
            upload(&device, encoder, &self.state, 0, &[0, self.capacity]);
            self.state_ready = true;
        }
        // Headers of released slots read "no cache" from this task on.
        for slot in std::mem::take(&mut self.cleared) {
            if slot < self.header_slots {
                encoder.clear_buffer(
                    self.meta.buffer(),
                    (self.headers.start + slot * HEADER_WORDS) as u64 * 4,
                    Some(HEADER_WORDS as u64 * 4),
                );
            }
        }
    }

    /// Gives back what only allocations use once none waits: the allocation scratch (no task in
    /// flight uses it then, so it is freed at once). The meta pool keeps its size: trimming it
    /// means copying it, and the old buffer would live beside the new one until the copy is
    /// done — a peak of its own. The next allocation takes what it needs again.
    pub fn give_back_idle_memory(&mut self) {
        if !self.waiting.is_empty() {
            return;
        }
        // `storage` makes buffers of at least 256 bytes: the empty cache's.
        if self.scratch.size() > 256 {
            self.scratch = storage(&self.device, "kickstart-rt cache allocation scratch", 4);
        }
    }

    /// Records the GPU allocation of `jobs` (instances whose geometry's BLAS is built; the plan
    /// checked each with [`Self::check_allocation`] when its instance task came). Jobs past the
    /// per-task limit stay waiting.
    pub fn record_allocations(
        &mut self,
        rec: &mut Recorder<'_>,
        triangles: &wgpu::Buffer,
        jobs: &[AllocJob],
        serial: u64,
    ) {
        let jobs = &jobs[..jobs.len().min(MAX_ALLOCS_PER_TASK)];
        if jobs.is_empty() {
            return;
        }
        // Triangle records (CPU-allocated) and scratch big enough for the largest job.
        let (fitted, records) = self.allocate_records(rec, jobs);
        let jobs = &fitted[..];
        if jobs.is_empty() {
            return;
        }
        let max_tris = jobs.iter().map(|j| j.tri_count).max().unwrap_or(1).max(1);
        let (hash_size, scratch_words) = scratch_words(max_tris);
        debug_assert!(
            self.check_allocation(max_tris).is_ok(),
            "the plan checked every instance's allocation scratch"
        );
        if self.scratch.size() < scratch_words * 4 {
            self.scratch = storage(
                &self.device,
                "kickstart-rt cache allocation scratch",
                scratch_words * 4,
            );
        }
        self.hand_free_blocks_to_gpu(rec);

        let headers_start = self.headers.start;
        let meta = self.meta.buffer().clone();
        let surfels = self.surfels.clone();
        let state = self.state.clone();
        let scratch = self.scratch.clone();
        let pipes = self.pipelines();
        let layout = pipes.layout.clone();
        let p = (
            pipes.insert.clone(),
            pipes.count.clone(),
            pipes.allocate.clone(),
            pipes.write.clone(),
        );
        rec.scope = "cache allocation";
        let mut slots = Vec::with_capacity(jobs.len());
        for (i, (j, r)) in jobs.iter().zip(&records).enumerate() {
            let rows = glam::Mat4::from(j.transform).transpose().to_cols_array_2d();
            let params = rec.uniform(
                "kickstart-rt cache allocation params",
                &AllocParams {
                    rows: [rows[0], rows[1], rows[2]],
                    initial: j.initial.to_array(),
                    tri_count: j.tri_count,
                    tri_base: j.tri_base,
                    records: r.start,
                    header: headers_start + j.slot * HEADER_WORDS,
                    hash_size,
                    mesh_colors: j.params.mesh_colors as u32,
                    resolution_limit: j.params.tile_resolution_limit,
                    force_direct: j.params.force_direct_tile_mapping as u32,
                    unit_length: j.params.tile_unit_length,
                    direct_threshold: j.params.direct_tile_mapping_threshold,
                    log_index: i as u32,
                    pad: 0,
                },
            );
            let bg = layout.bind_group(
                &self.device,
                &[
                    ("triangles", triangles.as_entire_binding()),
                    ("meta_words", meta.as_entire_binding()),
                    ("surfels", surfels.as_entire_binding()),
                    ("scratch", scratch.as_entire_binding()),
                    ("state", state.as_entire_binding()),
                    ("params", params.as_entire_binding()),
                ],
            );
            let words = 4 + 13 * j.tri_count as u64 + 2 * hash_size as u64;
            rec.encoder.clear_buffer(&scratch, 0, Some(words * 4));
            let corners = (3 * j.tri_count).div_ceil(64);
            rec.dispatch("cache insert", &p.0, &[&bg], corners);
            rec.dispatch("cache count", &p.1, &[&bg], corners);
            rec.dispatch("cache allocate", &p.2, &[&bg], 1);
            rec.dispatch("cache write", &p.3, &[&bg], j.tri_count.div_ceil(64));
            slots.push(j.slot);
            self.instances.insert(
                j.slot,
                InstanceCache {
                    records: *r,
                    surfels: Surfels::Pending { serial, log: i },
                },
            );
            self.waiting.remove(&j.slot);
        }
        self.read_back_allocations(rec, slots, serial);
    }

    /// Allocates the triangle records of each job in the meta pool: the jobs that fit and their
    /// records (a job that does not fit gets no cache; see `no_room_for_records`).
    fn allocate_records(
        &mut self,
        rec: &mut Recorder<'_>,
        jobs: &[AllocJob],
    ) -> (Vec<AllocJob>, Vec<Range>) {
        let mut fitted = Vec::with_capacity(jobs.len());
        let mut records = Vec::with_capacity(jobs.len());
        // Room for every job's records at once: one growth to what they need, not doublings.
        let total: u64 = jobs
            .iter()
            .map(|j| u64::from(j.tri_count.max(1)) * u64::from(RECORD_WORDS))
            .sum();
        self.meta
            .reserve(&self.device, rec.encoder, total, self.max_binding);
        for j in jobs {
            let words = j.tri_count.max(1) * RECORD_WORDS;
            match self
                .meta
                .alloc(&self.device, rec.encoder, words, self.max_binding)
            {
                Some(r) => {
                    fitted.push(j.clone());
                    records.push(r);
                }
                None => self.no_room_for_records(j.slot, words),
            }
        }
        (fitted, records)
    }

    /// Hands the free blocks to this task's allocation passes (the largest first); what the GPU
    /// leaves comes back with the read-back.
    fn hand_free_blocks_to_gpu(&mut self, rec: &mut Recorder<'_>) {
        let mut blocks: Vec<(u32, u32)> = self.free.iter().map(|(s, l)| (*s, *l)).collect();
        blocks.sort_by_key(|b| std::cmp::Reverse(b.1));
        blocks.truncate(MAX_FREE_BLOCKS);
        for (s, _) in &blocks {
            self.free.remove(s);
        }
        let mut head = vec![blocks.len() as u32, 0];
        for (s, l) in &blocks {
            head.extend([*s, *l]);
        }
        upload(&self.device, rec.encoder, &self.state, 8, &head);
    }

    /// Copies the allocation state and log of `slots` (this task's jobs, in order) to a
    /// read-back buffer, read once task `serial` completes.
    fn read_back_allocations(&mut self, rec: &mut Recorder<'_>, slots: Vec<u32>, serial: u64) {
        let bytes = (ST_LOG + 4 * slots.len() as u64) * 4;
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("kickstart-rt cache allocation read-back"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        rec.encoder
            .copy_buffer_to_buffer(&self.state, 0, &buffer, 0, bytes);
        self.readbacks.push(AllocReadback {
            serial,
            buffer,
            mapped: Arc::new(AtomicBool::new(false)),
            slots,
            started: false,
        });
    }

    /// An instance whose triangle records do not fit the cache's meta binding gets no cache
    /// ([`super::CacheLevel::None`]) instead of failing its task, as an instance the surfel pool
    /// has no room for is degraded: its rays and injections simply find no cache. Logged.
    fn no_room_for_records(&mut self, slot: u32, words: u32) {
        log::warn!(
            "lighting cache of instance slot {slot}: its triangle records ({} bytes) do not fit \
             the cache's records binding (max_storage_buffer_binding_size {} bytes, shared by \
             every instance's records); the instance gets no cache",
            words as u64 * 4,
            self.max_binding
        );
        self.waiting.remove(&slot);
        self.instances.insert(
            slot,
            InstanceCache {
                records: Range { start: 0, len: 0 },
                surfels: Surfels::Known {
                    start: 0,
                    len: 0,
                    level: 2,
                },
            },
        );
        self.cleared.push(slot);
    }

    /// The allocation of instance `slot` as read back: `(surfels, level)` with level 0 full,
    /// 1 coarse, 2 none; `None` before its read-back arrived.
    pub fn allocation(&self, slot: u32) -> Option<super::CacheAllocation> {
        match self.instances.get(&slot)?.surfels {
            Surfels::Known { len, level, .. } => Some(super::CacheAllocation {
                surfels: len,
                level: match level {
                    0 => super::CacheLevel::Full,
                    1 => super::CacheLevel::Coarse,
                    _ => super::CacheLevel::None,
                },
            }),
            Surfels::Pending { .. } => None,
        }
    }
}

/// The header region for `slots` instance slots: the slots it holds and its words.
fn header_region(slots: u32) -> (u32, u32) {
    let new_slots = slots.next_power_of_two().max(64);
    (new_slots, new_slots * HEADER_WORDS)
}

/// The allocation passes' hash table size and scratch words for jobs of up to `max_tris`
/// triangles (at least 1).
fn scratch_words(max_tris: u32) -> (u32, u64) {
    let hash_size = (6 * max_tris).next_power_of_two();
    (hash_size, 4 + 13 * max_tris as u64 + 2 * hash_size as u64)
}

/// Copies `words` into `dst` at byte `offset` inside `encoder`, through a buffer written at
/// creation (never `queue.write_buffer`: earlier unsubmitted work may read `dst`).
fn upload(
    device: &wgpu::Device,
    encoder: &mut wgpu::CommandEncoder,
    dst: &wgpu::Buffer,
    offset: u64,
    words: &[u32],
) {
    let src = crate::gpu::buffers::buffer_init(
        device,
        "kickstart-rt cache upload",
        bytemuck::cast_slice(words),
        wgpu::BufferUsages::COPY_SRC,
    );
    encoder.copy_buffer_to_buffer(&src, 0, dst, offset, words.len() as u64 * 4);
}

/// Inserts a free range, merged with its neighbours.
fn free_insert(free: &mut BTreeMap<u32, u32>, start: u32, len: u32) {
    let (mut s, mut l) = (start, len);
    if let Some((&ps, &pl)) = free.range(..s).next_back() {
        if ps + pl == s {
            free.remove(&ps);
            s = ps;
            l += pl;
        }
    }
    if let Some(&nl) = free.get(&(start + len)) {
        free.remove(&(start + len));
        l += nl;
    }
    free.insert(s, l);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::{CacheLevel, CacheParams};
    use crate::gpu::testing::{buffer, gpu, run};

    /// The allocation passes' WGSL validated with naga without a device; the uniform, the surfel
    /// stride and the allocation state's word offsets against it.
    #[test]
    fn the_wgsl_validates_and_matches_the_rust_layouts() {
        use crate::gpu::wgsl_check::{assert_wgsl_layout, const_u32, storage_stride, validate};
        let module = validate("cache allocation", &alloc_wgsl());
        for entry in ["insert", "count", "allocate", "write"] {
            assert!(
                module.entry_points.iter().any(|e| e.name == entry),
                "{entry}"
            );
        }
        assert_wgsl_layout!(
            module,
            "AllocParams",
            AllocParams {
                rows => "row0",
                initial,
                tri_count,
                tri_base,
                records,
                header,
                hash_size,
                mesh_colors,
                resolution_limit,
                force_direct,
                unit_length,
                direct_threshold,
                log_index,
                pad,
            }
        );
        assert_eq!(storage_stride(&module, "surfels") as u64, SURFEL_BYTES);
        assert_eq!(const_u32(&module, "ST_FREE") as u64, ST_FREE);
        assert_eq!(const_u32(&module, "ST_LOG") as u64, ST_LOG);
        assert_eq!(const_u32(&module, "ST_MAX_FREE") as usize, MAX_FREE_BLOCKS);
    }

    fn job(slot: u32, tri_count: u32) -> AllocJob {
        AllocJob {
            slot,
            tri_base: 0,
            tri_count,
            params: CacheParams {
                mesh_colors: false,
                tile_unit_length: 1.0,
                tile_resolution_limit: 4,
                direct_tile_mapping_threshold: 0.5,
                force_direct_tile_mapping: false,
            },
            transform: glam::Affine3A::IDENTITY,
            initial: glam::Vec4::ZERO,
        }
    }

    #[test]
    fn an_instance_whose_records_do_not_fit_gets_no_cache_and_the_task_goes_on() {
        let g = gpu();
        let mut cache =
            DirectLightingCache::new(&g.device, 1024, crate::device::TraversalBackend::Software);
        // A binding of 64 KiB: one triangle's records fit, 10 000 triangles' (320 KB) never do.
        cache.max_binding = 64 * 1024;
        let triangles = buffer(4 * 48);
        cache.register(0, 0);
        cache.register(1, 0);
        assert!(cache.check_headers(2, u64::MAX).is_ok());
        run(|rec| {
            cache.prepare_task(rec.encoder, 2, 1);
            cache.record_allocations(rec, &triangles, &[job(0, 1), job(1, 10_000)], 1);
        });
        assert!(
            cache.waiting().is_empty(),
            "neither instance waits any more"
        );
        let none = cache.allocation(1).map(|a| (a.surfels, a.level));
        assert_eq!(none, Some((0, CacheLevel::None)));
        // The instance that fits was allocated on the GPU (its read-back is still pending).
        assert!(matches!(
            cache.instances.get(&0).map(|c| &c.surfels),
            Some(Surfels::Pending { .. })
        ));
        // Releasing the cache-less instance returns nothing to the records pool.
        let used = cache.meta.used_bytes();
        cache.release(1, 1);
        assert_eq!(cache.meta.used_bytes(), used);
    }
}
