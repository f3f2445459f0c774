//! The scene on the GPU: the shared pools (staged triangles, BLAS triangles, BLAS nodes, refit
//! data), the geometry and instance tables, the TLAS, and the passes that fill them. Layouts:
//! `docs/ray-tracing-core.md`. The context decides *what* to do each task; this module records it.

use crate::device::TraversalBackend;
use crate::error::{Error, Result};
use crate::scene::hardware::HardwareScene;
// Generic buffer helpers live in the gpu layer; re-exported here for the modules that still
// import them from the scene.
use crate::allocations::BlasCompaction;
use crate::gpu::buffers::{read_back, storage, Grown};
use crate::gpu::Recorder;
use crate::scene::ingest::{ComponentIngest, Ingest};
use crate::scene::lbvh::{
    batch_runs, BatchBuild, BatchKind, Lbvh, LbvhBatch, LbvhBuild, LbvhRefit, LbvhTriangleRefit,
    LeafRefs, RawTriangles, RefitSource, BLAS_KEY_BITS, TLAS_KEY_BITS,
};
use crate::scene::opacity::{OpacityBaker, OpacityMaps};
use crate::scene::pool::{Move, Pool, Range};
use crate::scene::prims::{Prims, MAX_REFS_PER_INSTANCE};
use crate::scene::skinning::Skinner;
use crate::scene::strategy::BuildStrategy;
use crate::scene::traversal::{LeafTest, SceneBuffers};
use crate::staging::{StagingBuffer, StagingPool};
use crate::tasks::SkinningTask;

/// Bytes of one triangle of the soup (three `vec4<f32>`); opacity micro-maps count their
/// pool elements in the same 12 words.
pub(crate) const TRIANGLE_BYTES: u64 = 48;
/// Bytes of one BVH2 node.
pub(crate) const NODE_BYTES: u64 = 64;
/// Bytes of one geometry table record.
pub(crate) const GEOMETRY_RECORD_SIZE: u64 = 64;
/// The geometry record in `vec4`s (its root box is the second and third: `slot * 4 + 1`).
const GEOMETRY_RECORD_VEC4: u32 = 4;
/// Byte offset of the opacity words in a geometry record (`GeometryGpu::opacity`).
pub(crate) const GEOMETRY_OPACITY_AT: u64 = 48;
/// Bytes of one instance table record.
pub(crate) const INSTANCE_RECORD_BYTES: u64 = 128;
/// Bytes of one primitive's AABB (two `vec4<f32>`).
const AABB_BYTES: u64 = 32;

/// BVH work a geometry waits for (in the context's queue).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum PendingBvh {
    /// First build (or rebuild after re-registration).
    Build,
    /// New vertices of a built `allow_update` geometry: refit.
    Refit,
}

/// A build allocated by [`GpuScene::build_blas`] whose passes wait for the task's batch of its
/// strategy ([`GpuScene::record_batch`]).
pub(crate) struct DeferredBuild {
    slot: u32,
    staged: Range,
    tris: Range,
    nodes: Range,
    count: u32,
    strategy: BuildStrategy,
    /// Its sort order and topology, kept for refits (`allow_update`).
    kept: Option<(Range, Range)>,
}

/// A range refit [`GpuScene::refit_blas`] left to the task's batch
/// ([`GpuScene::record_refit_batch`]).
pub(crate) struct DeferredRefit {
    slot: u32,
    staged: Range,
    tris: Range,
    nodes: Range,
    order: Range,
    topology: Range,
    count: u32,
    /// The ingestion the refit decodes itself ([`GpuScene::can_refit_from_raw`]).
    fused: Option<DeferredIngest>,
}

/// A new BLAS's pool ranges: triangles, nodes, and (sort order, refit topology) when kept.
type BlasAlloc = (Range, Range, Option<(Range, Range)>);

/// Where a built BLAS lives in the pools.
#[derive(Debug, Clone, Copy)]
pub(crate) struct BlasRanges {
    pub tris: Range,
    pub nodes: Range,
    /// The tree the build made (refits make their decisions with the same leaves).
    pub strategy: BuildStrategy,
    /// Sort order (`n` words; `orders` pool) and refit topology (`topologies` pool), kept for
    /// `allow_update` geometry only. Separate pools: the builder binds them in one dispatch.
    pub refit: Option<(Range, Range)>,
    /// The build's stamp (the geometry header's flags bits 8-31): which build a late
    /// compaction read-back is about.
    pub stamp: u32,
    /// Where its node range stands with compaction (`nodes` is the compacted range once done).
    pub compaction: BlasCompaction,
}

/// An ingestion left to its geometry's refit in the same task: [`GpuScene::refit_blas`]
/// decodes the triangles from the application's bytes itself (`lbvh refit ingest`), which saves
/// the ingestion pass, its staged writes and the refit's gather of them.
pub(crate) struct DeferredIngest {
    /// The raw copy of the task's vertex and index bytes.
    pub raw: wgpu::Buffer,
    /// The geometry's components in `raw`.
    pub components: Vec<ComponentIngest>,
    /// Their table rows ([`crate::scene::ingest::component_rows`]).
    pub rows: Vec<u32>,
    /// The geometry's staged range (where a plain ingestion writes).
    pub staged: Range,
    /// The ingestion's index in the task (its pair of dropped-triangle counters).
    pub ingestion: u32,
}

/// The GPU side of one geometry.
#[derive(Debug, Default)]
pub(crate) struct GeometryGpu {
    pub triangles: u32,
    /// Ingested, unsorted triangles (kept after the build only when `allow_update`). A refit
    /// that decodes its own triangles ([`DeferredIngest`]) leaves them as they were: they are
    /// read by builds and clustered refits only, which always follow an ingestion into them.
    pub staged: Option<Range>,
    pub blas: Option<BlasRanges>,
    pub pending: Option<PendingBvh>,
    /// Opacity micro-maps of cutout geometry (in the triangle pool), baked at ingestion.
    pub opacity: Option<OpacityMaps>,
}

impl GeometryGpu {
    /// Returns every range to its pool once the GPU task `last_used` has completed.
    pub fn free_after(&mut self, scene: &mut GpuScene, last_used: u64) {
        if let Some(r) = self.staged.take() {
            scene.staged.free_after(r, last_used);
        }
        if let Some(m) = self.opacity.take() {
            scene.triangles.free_after(m.range, last_used);
            scene.note_cutout_geometry(true, false);
        }
        if let Some(b) = self.blas.take() {
            scene.triangles.free_after(b.tris, last_used);
            scene.nodes.free_after(b.nodes, last_used);
            if let Some((o, t)) = b.refit {
                scene.orders.free_after(o, last_used);
                scene.topologies.free_after(t, last_used);
            }
        }
    }
}

/// A table of fixed-size records indexed by a handle's slot, grown (contents kept) on demand.
pub(crate) struct Table {
    label: &'static str,
    record: u64,
    pub buffer: wgpu::Buffer,
}

impl Table {
    fn new(device: &wgpu::Device, label: &'static str, record: u64) -> Self {
        Table {
            label,
            record,
            buffer: storage(device, label, 64 * record),
        }
    }

    fn slots(&self) -> u64 {
        self.buffer.size() / self.record
    }

    /// Refuses `slots` records past `max_bytes` (the plan's check before [`Table::ensure`]).
    fn check(&self, slots: u64, max_bytes: u64) -> Result<()> {
        // The growth check counts records of the real size (the instance-id bug report's
        // buffer-growth bug compared against the wrong element size).
        if self.slots() < slots && slots * self.record > max_bytes {
            return Err(Error::OutOfDeviceMemory {
                what: self.label.to_string(),
                bytes: slots * self.record,
                limit: max_bytes,
            });
        }
        Ok(())
    }

    /// Grows the table to `slots` records, which [`Table::check`] admitted.
    fn ensure(
        &mut self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        slots: u64,
        max_bytes: u64,
    ) {
        if self.slots() >= slots {
            return;
        }
        debug_assert!(self.check(slots, max_bytes).is_ok(), "the plan checked it");
        let bytes = slots.next_power_of_two().max(64) * self.record;
        let new = storage(device, self.label, bytes.min(max_bytes));
        encoder.copy_buffer_to_buffer(&self.buffer, 0, &new, 0, self.buffer.size());
        self.buffer = new;
    }
}

/// CPU-written bytes for GPU buffers, gathered and then copied through one staging buffer in the
/// engine's encoder (never `queue.write_buffer`: the engine may not have submitted earlier work
/// that reads these buffers).
#[derive(Default)]
pub(crate) struct Uploads {
    data: Vec<u8>,
    copies: Vec<(wgpu::Buffer, u64, u64, u64)>,
}

impl Uploads {
    /// Queues `bytes` (a multiple of 4) for `dst` at `offset` (a multiple of 4). A write that
    /// continues the previous one in `dst` extends its copy: wgpu tracks and barriers every copy,
    /// and a million instance records written in slot order would otherwise be a million copies.
    pub fn push(&mut self, dst: &wgpu::Buffer, offset: u64, bytes: &[u8]) {
        let src = self.data.len() as u64;
        let len = bytes.len() as u64;
        self.data.extend_from_slice(bytes);
        if let Some(last) = self.copies.last_mut() {
            if last.0 == *dst && continues((last.1, last.2, last.3), offset, src) {
                last.3 += len;
                return;
            }
        }
        self.copies.push((dst.clone(), offset, src, len));
    }

    /// Records the copies; the staging buffer returned belongs to the task's working set.
    pub fn flush(
        self,
        device: &wgpu::Device,
        staging: &mut StagingPool,
        encoder: &mut wgpu::CommandEncoder,
    ) -> Option<StagingBuffer> {
        if self.copies.is_empty() {
            return None;
        }
        let buffer = staging.acquire(device, self.data.len() as u64);
        if !buffer.write(0, &self.data) {
            log::error!("kickstart-rt: staging buffer was not mapped; upload skipped");
        }
        buffer.buffer.unmap();
        for (dst, offset, src, len) in self.copies {
            encoder.copy_buffer_to_buffer(&buffer.buffer, src, &dst, offset, len);
        }
        Some(buffer)
    }
}

/// Whether a write of staging bytes at `src` to `offset` directly follows the copy
/// `(offset, src, len)` in both buffers, so one copy can carry both.
fn continues((last_offset, last_src, last_len): (u64, u64, u64), offset: u64, src: u64) -> bool {
    last_offset + last_len == offset && last_src + last_len == src
}

/// Lazily created pipelines: a context that never traces never compiles the trace shaders.
#[derive(Default)]
struct Passes {
    ingest: Option<Ingest>,
    prims: Option<Prims>,
    lbvh: Option<Lbvh>,
    /// The opacity micro-map bake (cutout geometry only).
    opacity: Option<OpacityBaker>,
    /// The skinning pass (skinning tasks only).
    skinning: Option<Skinner>,
}

impl Passes {
    fn ingest(&mut self, d: &wgpu::Device) -> &Ingest {
        self.ingest.get_or_insert_with(|| Ingest::new(d))
    }

    /// The two passes every BVH build and refit uses (borrowed together).
    fn build(&mut self, d: &wgpu::Device) -> (&Prims, &mut Lbvh) {
        let prims = self.prims.get_or_insert_with(|| Prims::new(d));
        let lbvh = self.lbvh.get_or_insert_with(|| Lbvh::new(d));
        (prims, lbvh)
    }
}

/// The TLAS and its build buffers.
struct Tlas {
    nodes: wgpu::Buffer,
    order: wgpu::Buffer,
    topology: wgpu::Buffer,
    aabbs: wgpu::Buffer,
    /// Centroid bounds of the instance boxes (6 u32 words), merged by the instance-box pass
    /// of a build for the LBVH, which then skips its own bounds pass.
    centroid_bounds: wgpu::Buffer,
    /// Instance slots the buffers hold.
    capacity: u32,
    /// Instance slots of the last build (0 before the first).
    slots: u32,
    built: bool,
    refits_since_rebuild: u32,
}

/// Everything the SDK keeps on the GPU for ray tracing.
pub(crate) struct GpuScene {
    device: wgpu::Device,
    max_binding: u64,
    /// Ingested triangles waiting for (or kept for) their BLAS build: "vertex copies".
    pub staged: Pool,
    /// BLAS triangles in leaf order.
    pub triangles: Pool,
    /// BLAS nodes.
    pub nodes: Pool,
    /// Sort orders and refit topology of `allow_update` BLASes.
    pub orders: Pool,
    /// Refit topology of `allow_update` BLASes.
    pub topologies: Pool,
    pub geometry_table: Table,
    pub instance_table: Table,
    tlas: Tlas,
    /// BLAS builds so far (wrapping): the stamp each build writes into its geometry's header.
    blas_builds: u32,
    scratch_aabbs: wgpu::Buffer,
    scratch_order: wgpu::Buffer,
    /// Topology of a fast-build BLAS built without `allow_update`: its range refit reads it.
    scratch_topology: Grown,
    /// Dropped-triangle counters of this task's ingestions (two per ingestion).
    pub counters: wgpu::Buffer,
    passes: Passes,
    /// The driver's acceleration structures, on the hardware backend only.
    pub hardware: Option<HardwareScene>,
    /// Whether the build memory was given back since the last task with BLAS work.
    build_memory_released: bool,
    /// Geometries holding opacity micro-maps (cutout geometry): while there are none, the
    /// software traversal traces with the build without the opacity test (`LeafTest`).
    cutout_geometries: usize,
}

impl GpuScene {
    /// An empty scene for `backend`.
    pub fn new(device: &wgpu::Device, backend: TraversalBackend, context_id: u32) -> Self {
        let hardware = backend == TraversalBackend::HardwareRayQuery;
        // The driver's BLASes are built from the triangle pool.
        let triangle_usage = if hardware {
            wgpu::BufferUsages::BLAS_INPUT
        } else {
            wgpu::BufferUsages::empty()
        };
        let max_binding = crate::gpu::buffers::max_binding(device);
        let tlas_nodes = empty_root(device);
        GpuScene {
            device: device.clone(),
            max_binding,
            staged: Pool::new(device, "kickstart-rt staged triangles", TRIANGLE_BYTES),
            triangles: Pool::with_usage(
                device,
                "kickstart-rt BLAS triangles",
                TRIANGLE_BYTES,
                triangle_usage,
            ),
            nodes: Pool::new(device, "kickstart-rt BLAS nodes", NODE_BYTES),
            orders: Pool::new(device, "kickstart-rt BLAS sort orders", 4),
            topologies: Pool::new(device, "kickstart-rt BLAS refit topology", 4),
            geometry_table: Table::new(device, "kickstart-rt geometry table", GEOMETRY_RECORD_SIZE),
            instance_table: Table::new(
                device,
                "kickstart-rt instance table",
                INSTANCE_RECORD_BYTES,
            ),
            blas_builds: 0,
            tlas: Tlas {
                nodes: tlas_nodes,
                order: storage(device, "kickstart-rt TLAS order", 4),
                topology: storage(device, "kickstart-rt TLAS topology", 4),
                aabbs: storage(device, "kickstart-rt TLAS instance boxes", AABB_BYTES),
                centroid_bounds: storage(device, "kickstart-rt TLAS centroid bounds", 6 * 4),
                capacity: 0,
                slots: 0,
                built: false,
                refits_since_rebuild: 0,
            },
            scratch_aabbs: storage(device, "kickstart-rt build boxes", AABB_BYTES),
            scratch_order: storage(device, "kickstart-rt build order", 4),
            scratch_topology: Grown::default(),
            counters: storage(device, "kickstart-rt ingestion counters", 8),
            passes: Passes::default(),
            hardware: hardware.then(|| HardwareScene::new(device, context_id)),
            build_memory_released: true,
            cutout_geometries: 0,
        }
    }

    /// Creates every pipeline now.
    pub fn prepare_pipelines(&mut self) {
        let d = &self.device;
        self.passes.ingest(d);
        self.passes.build(d);
    }

    /// Bytes of build scratch held.
    pub fn scratch_bytes(&self) -> u64 {
        self.scratch_aabbs.size()
            + self.scratch_order.size()
            + self.scratch_topology.bytes()
            + self.counters.size()
            + self.passes.lbvh.as_ref().map_or(0, |l| l.scratch_bytes())
    }

    /// Bytes of the TLAS and its build buffers.
    pub fn tlas_bytes(&self) -> u64 {
        self.tlas.nodes.size()
            + self.tlas.order.size()
            + self.tlas.topology.size()
            + self.tlas.aabbs.size()
            + self.tlas.centroid_bounds.size()
    }

    /// Gives back what only builds use, once a scene's builds are done (the first GPU task
    /// without BLAS work after some; see [`Self::note_build_work`]): the free tails of
    /// the BLAS pools (the ranges in use are copied into smaller buffers inside `encoder`) and
    /// every build scratch buffer. The next build allocates what it needs again.
    ///
    /// The node pool is packed first ([`Pool::pack`]): the ranges compaction and destroyed
    /// geometry left free between BLASes go too. Returns how the BLASes' node ranges moved: the
    /// caller updates their geometries (`BlasRanges::nodes`, and the headers' node base) before
    /// anything reads them.
    pub fn release_build_memory(&mut self, encoder: &mut wgpu::CommandEncoder) -> Vec<Move> {
        if self.build_memory_released {
            return Vec::new();
        }
        let moves = self.nodes.pack(&self.device, encoder).unwrap_or_default();
        self.give_back_build_memory(encoder);
        moves
    }

    /// Gives back the nodes the compaction of `blas` left unused, now that its node count
    /// `count` was read back from the task `serial` that built it, and marks it compacted. The
    /// next task without build work packs the pool ([`Self::release_build_memory`]).
    pub fn shrink_compacted(&mut self, blas: &mut BlasRanges, count: u32, serial: u64) {
        if blas.compaction != BlasCompaction::Pending {
            return;
        }
        blas.compaction = BlasCompaction::Done;
        if count == 0 || count >= blas.nodes.len {
            return;
        }
        let tail = Range {
            start: blas.nodes.start + count,
            len: blas.nodes.len - count,
        };
        // No task reads the tail: the compacted tree's refs stay below `count`.
        self.nodes.free_after(tail, serial);
        blas.nodes.len = count;
        self.build_memory_released = false;
    }

    /// What [`Self::release_build_memory`] gives back, now, whether or not it has since the
    /// last build.
    /// Ranges still waiting for in-flight tasks cannot go yet: the next quiet task tries again.
    pub fn give_back_build_memory(&mut self, encoder: &mut wgpu::CommandEncoder) {
        let device = self.device.clone();
        let mut waiting = false;
        for pool in [
            &mut self.staged,
            &mut self.triangles,
            &mut self.nodes,
            &mut self.orders,
            &mut self.topologies,
        ] {
            pool.trim(&device, encoder);
            waiting |= pool.ledger().has_pending();
        }
        self.build_memory_released = !waiting;
        self.release_build_scratch();
    }

    /// Drops every build scratch buffer (the next build allocates what it needs).
    fn release_build_scratch(&mut self) {
        let device = &self.device;
        // `storage` makes buffers of at least 256 bytes: those are the empty scene's.
        if self.scratch_aabbs.size() > 256 {
            self.scratch_aabbs = storage(device, "kickstart-rt build boxes", AABB_BYTES);
        }
        if self.scratch_order.size() > 256 {
            self.scratch_order = storage(device, "kickstart-rt build order", 4);
        }
        self.scratch_topology.release();
        if let Some(lbvh) = self.passes.lbvh.as_mut() {
            lbvh.release_scratch();
        }
    }

    /// Notes that pool ranges were freed (a geometry destroyed): the next task without build
    /// work gives the space back ([`Self::release_build_memory`]).
    pub fn note_pool_frees(&mut self) {
        self.build_memory_released = false;
    }

    /// Notes that a GPU task ingests geometry or builds BLASes: the next task without such work
    /// gives the build memory back ([`Self::release_build_memory`]), once per quiet spell, so
    /// that a TLAS rebuilt every frame keeps its own small scratch.
    pub fn note_build_work(&mut self) {
        self.build_memory_released = false;
    }

    /// Releases pool ranges no in-flight task can read.
    pub fn collect(&mut self, oldest_in_flight: u64) {
        self.staged.collect(oldest_in_flight);
        self.triangles.collect(oldest_in_flight);
        self.nodes.collect(oldest_in_flight);
        self.orders.collect(oldest_in_flight);
        self.topologies.collect(oldest_in_flight);
    }

    /// The most bytes one pool or table may bind.
    pub fn max_binding(&self) -> u64 {
        self.max_binding
    }

    /// `len` elements of `pool`, which the plan reserved on a copy of its ledger
    /// (`SceneReservation`, in the sibling module `reserve`): the same allocations in the same
    /// order, so this one fits.
    fn reserved(
        pool: &mut Pool,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        len: u32,
        max: u64,
    ) -> Range {
        pool.alloc(device, encoder, len, max)
            .expect("the plan reserved this range (SceneReservation)")
    }

    /// Space for `triangles` ingested triangles (reserved by the plan).
    /// Makes room for a task's staged allocations of `triangles` in all, before them (one
    /// growth instead of doublings; see `Ledger::reserve`).
    pub fn reserve_staged(&mut self, encoder: &mut wgpu::CommandEncoder, triangles: u64) {
        let (max, d) = (self.max_binding, &self.device);
        self.staged.reserve(d, encoder, triangles, max);
    }

    /// Makes room for a task's BLAS builds (`(triangles, keep_for_refit)` each), before them.
    pub fn reserve_blas(&mut self, encoder: &mut wgpu::CommandEncoder, builds: &[(u32, bool)]) {
        let totals = BlasTotals::of(builds);
        let (max, d) = (self.max_binding, &self.device);
        self.triangles.reserve(d, encoder, totals.triangles, max);
        self.nodes.reserve(d, encoder, totals.nodes, max);
        self.orders.reserve(d, encoder, totals.orders, max);
        self.topologies
            .reserve(d, encoder, totals.topology_words, max);
    }

    pub fn alloc_staged(&mut self, encoder: &mut wgpu::CommandEncoder, triangles: u32) -> Range {
        let max = self.max_binding;
        Self::reserved(&mut self.staged, &self.device, encoder, triangles, max)
    }

    /// Triangle-pool space for opacity micro-maps of `elements` elements (reserved by the plan:
    /// `SceneReservation::opacity`).
    pub fn alloc_opacity(&mut self, encoder: &mut wgpu::CommandEncoder, elements: u32) -> Range {
        let max = self.max_binding;
        Self::reserved(&mut self.triangles, &self.device, encoder, elements, max)
    }

    /// Bakes the opacity micro-maps `maps` of one geometry's `components` from the task's raw
    /// copy (`shaders/scene/opacity.wgsl`).
    pub fn bake_opacity(
        &mut self,
        rec: &mut Recorder<'_>,
        raw: &wgpu::Buffer,
        components: &[ComponentIngest],
        maps: OpacityMaps,
    ) {
        let device = &self.device;
        let baker = self
            .passes
            .opacity
            .get_or_insert_with(|| OpacityBaker::new(device));
        baker.record(rec, raw, components, (self.triangles.buffer(), maps));
    }

    /// Poses the meshes of a task's skinning `tasks` (`shaders/scene/skinning.wgsl`).
    pub fn record_skinning(&mut self, rec: &mut Recorder<'_>, tasks: &[&SkinningTask]) {
        let device = &self.device;
        let skinner = self
            .passes
            .skinning
            .get_or_insert_with(|| Skinner::new(device));
        skinner.record(rec, tasks);
    }

    /// Refuses table sizes past the device's limit (the plan's check of
    /// [`GpuScene::ensure_tables`]).
    pub fn check_tables(&self, geometry_slots: u32, instance_slots: u32) -> Result<()> {
        let max = self.max_binding;
        self.geometry_table.check(geometry_slots as u64, max)?;
        self.instance_table.check(instance_slots as u64, max)
    }

    /// Makes the geometry and instance tables hold the given slots ([`GpuScene::check_tables`]
    /// admitted them).
    pub fn ensure_tables(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        geometry_slots: u32,
        instance_slots: u32,
    ) {
        let max = self.max_binding;
        self.geometry_table
            .ensure(&self.device, encoder, geometry_slots as u64, max);
        self.instance_table
            .ensure(&self.device, encoder, instance_slots as u64, max);
    }

    /// Makes the counters buffer hold `ingestions` pairs and zeroes them.
    pub fn reset_counters(&mut self, encoder: &mut wgpu::CommandEncoder, ingestions: u32) {
        let bytes = (ingestions as u64 * 8).max(8);
        if self.counters.size() < bytes {
            self.counters = storage(
                &self.device,
                "kickstart-rt ingestion counters",
                bytes.next_power_of_two(),
            );
        }
        encoder.clear_buffer(&self.counters, 0, Some(bytes.div_ceil(4) * 4));
    }

    /// Decodes the components of several geometries `(components, staged range, ingestion
    /// index)` from `raw` into their staged ranges, in one pass.
    pub fn record_ingests(
        &mut self,
        rec: &mut Recorder<'_>,
        raw: &wgpu::Buffer,
        ingestions: &[(&[ComponentIngest], Range, u32)],
    ) {
        if ingestions.is_empty() {
            return;
        }
        let ingest = self.passes.ingest(&self.device);
        let (tris, counters) = (self.staged.buffer(), &self.counters);
        rec.scope = "ingest";
        let rows: Vec<(&[ComponentIngest], u32, u32)> = ingestions
            .iter()
            .map(|&(c, staged, i)| (c, staged.start, i * 2))
            .collect();
        ingest.record_many(rec, raw, &rows, tris, counters);
    }

    /// Decodes one geometry's components from `raw` into its staged range.
    pub fn record_ingest(
        &mut self,
        rec: &mut Recorder<'_>,
        raw: &wgpu::Buffer,
        components: &[ComponentIngest],
        staged: Range,
        ingestion: u32,
    ) {
        let ingest = self.passes.ingest(&self.device);
        let (tris, counters) = (self.staged.buffer(), &self.counters);
        rec.scope = "ingest";
        ingest.record(
            rec,
            raw,
            components,
            tris,
            staged.start,
            counters,
            ingestion * 2,
        );
    }

    fn ensure_scratch(&mut self, prims: u32) {
        let n = prims.max(1) as u64;
        if self.scratch_aabbs.size() < n * AABB_BYTES {
            self.scratch_aabbs = storage(
                &self.device,
                "kickstart-rt build boxes",
                n.next_power_of_two() * AABB_BYTES,
            );
        }
        if self.scratch_order.size() < n * 4 {
            self.scratch_order = storage(
                &self.device,
                "kickstart-rt build order",
                n.next_power_of_two() * 4,
            );
        }
    }

    /// Pool space for a BLAS of `n` triangles (reserved by the plan, in this order): its
    /// triangles and nodes, and with `keep_for_refit` its sort order and refit topology.
    fn alloc_blas(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        n: u32,
        keep_for_refit: bool,
    ) -> BlasAlloc {
        let (max, d) = (self.max_binding, &self.device);
        let tris = Self::reserved(&mut self.triangles, d, encoder, n, max);
        let nodes = Self::reserved(&mut self.nodes, d, encoder, Lbvh::node_count(n), max);
        let refit = keep_for_refit.then(|| {
            let order = Self::reserved(&mut self.orders, d, encoder, n, max);
            let words = Lbvh::topology_words(n);
            let topology = Self::reserved(&mut self.topologies, d, encoder, words, max);
            (order, topology)
        });
        (tris, nodes, refit)
    }

    /// Builds the BLAS of geometry slot `slot` from its staged triangles `staged` into pool
    /// space the plan reserved. Returns the geometry table header (first 16 bytes of its
    /// record) to upload. A fast-trace build whose order and topology are not kept, and a
    /// fast-build build of at least two triangles, only allocate here: their passes are
    /// recorded with the task's other builds of their kind, as one batch, by
    /// [`GpuScene::record_batch`] (pushed onto `batch`).
    pub fn build_blas(
        &mut self,
        rec: &mut Recorder<'_>,
        (slot, staged): (u32, Range),
        g: &mut GeometryGpu,
        keep_for_refit: bool,
        strategy: BuildStrategy,
        batch: &mut Vec<DeferredBuild>,
    ) -> [u32; 4] {
        let n = g.triangles;
        let (tris, nodes, refit) = self.alloc_blas(rec.encoder, n, keep_for_refit);
        let batched = match strategy {
            BuildStrategy::FastTrace => refit.is_none() && n >= 1,
            BuildStrategy::FastBuild => n >= 2,
        };
        if batched {
            batch.push(DeferredBuild {
                slot,
                staged,
                tris,
                nodes,
                count: n,
                strategy,
                kept: refit,
            });
        } else {
            // Not batched: kept for refits, or no triangle; neither is compacted.
            let no_counts = None;
            self.record_blas_passes(
                rec,
                (slot, staged),
                n,
                (tris, nodes, refit),
                (strategy, no_counts),
            );
        }
        // The build's stamp (flags bits 8-31): the TLAS's refs name nodes of one build of this
        // BLAS, so the traversal enters a ref whose stamp is not the geometry's current one at
        // the BLAS root instead (a TLAS update deferred past a rebuild; see instance_refs).
        self.blas_builds = self.blas_builds.wrapping_add(1);
        let stamp = self.blas_builds & 0x00ff_ffff;
        g.blas = Some(BlasRanges {
            tris,
            nodes,
            strategy,
            refit,
            stamp,
            compaction: compaction_of(strategy, refit.is_some(), n),
        });
        [nodes.start, tris.start, n, 1 | (stamp << 8)]
    }

    /// Records the builds [`GpuScene::build_blas`] deferred, as one batch of each kind
    /// ([`Lbvh::build_batch`]): fast-trace builds, fast-build builds that keep their order and
    /// topology (`allow_update`), and those that do not. A kind the batch cannot take (fewer
    /// than two builds) is built one by one.
    ///
    /// Returns where the fast-trace builds' node counts after compaction are, for the caller to
    /// read back ([`GpuScene::shrink_compacted`]).
    pub fn record_batch(
        &mut self,
        rec: &mut Recorder<'_>,
        batch: Vec<DeferredBuild>,
    ) -> NodeCounts {
        let mut counts = NodeCounts::default();
        if batch.is_empty() {
            return counts;
        }
        rec.scope = "blas build";
        let (fast_trace, fast_build): (Vec<DeferredBuild>, Vec<DeferredBuild>) = batch
            .into_iter()
            .partition(|d| d.strategy == BuildStrategy::FastTrace);
        let (kept, scratch): (Vec<DeferredBuild>, Vec<DeferredBuild>) =
            fast_build.into_iter().partition(|d| d.kept.is_some());
        for builds in [fast_trace, kept, scratch] {
            self.record_batch_of(rec, builds, &mut counts);
        }
        counts
    }

    /// Records deferred builds of one kind (one strategy, all kept or none) as batches whose
    /// scratch fits the device's largest binding ([`batch_runs`]), or one by one.
    fn record_batch_of(
        &mut self,
        rec: &mut Recorder<'_>,
        batch: Vec<DeferredBuild>,
        counts: &mut NodeCounts,
    ) {
        let Some(first) = batch.first() else {
            return;
        };
        let strategy = first.strategy;
        let clustered = strategy == BuildStrategy::FastTrace;
        let builds: Vec<BatchBuild> = batch
            .iter()
            .map(|d| BatchBuild {
                count: d.count,
                tri_src_base: d.staged.start,
                tri_dst_base: d.tris.start,
                node_base: d.nodes.start,
                bounds_base: d.slot * GEOMETRY_RECORD_VEC4 + 1,
                max_leaf: d.strategy.max_leaf(),
                kept: d
                    .kept
                    .map(|(order, topology)| (order.start, topology.start)),
            })
            .collect();
        let mut alone = Vec::new();
        for run in batch_runs(&builds, clustered, self.max_binding) {
            let slots: Vec<u32> = batch[run.clone()].iter().map(|d| d.slot).collect();
            let run_builds = (&builds[run.clone()], slots.as_slice());
            if !self.record_batch_run(rec, strategy, run_builds, counts) {
                alone.extend(run);
            }
        }
        for d in alone.into_iter().filter_map(|i| batch.get(i)) {
            self.record_blas_passes(
                rec,
                (d.slot, d.staged),
                d.count,
                (d.tris, d.nodes, d.kept),
                (d.strategy, Some(&mut *counts)),
            );
        }
    }

    /// Records one run of [`GpuScene::record_batch_of`]'s builds (of `strategy`, of geometry
    /// `slots`) as a batch; `false`, recording nothing, where the batch cannot take them.
    fn record_batch_run(
        &mut self,
        rec: &mut Recorder<'_>,
        strategy: BuildStrategy,
        (builds, slots): (&[BatchBuild], &[u32]),
        counts: &mut NodeCounts,
    ) -> bool {
        let Some(first) = builds.first() else {
            return true;
        };
        let count_buffer = node_count_buffer(&self.device, builds.len());
        let kind = match (strategy, first.kept) {
            (BuildStrategy::FastTrace, _) => BatchKind::FastTrace {
                counts: &count_buffer,
            },
            (BuildStrategy::FastBuild, Some(_)) => BatchKind::FastBuild {
                kept: Some((self.orders.buffer(), self.topologies.buffer())),
            },
            (BuildStrategy::FastBuild, None) => BatchKind::FastBuild { kept: None },
        };
        let (_, lbvh) = self.passes.build(&self.device);
        let batched = lbvh.build_batch(
            rec,
            &LbvhBatch {
                staged: self.staged.buffer(),
                triangles: self.triangles.buffer(),
                nodes: self.nodes.buffer(),
                bounds_out: &self.geometry_table.buffer,
                builds,
                kind,
            },
        );
        if batched && strategy == BuildStrategy::FastTrace {
            counts.parts.push((count_buffer, builds.len()));
            counts.slots.extend_from_slice(slots);
        }
        batched
    }

    /// The passes of one BLAS build into its allocated ranges. A fast-trace build that keeps
    /// no topology is compacted, its node count added to `counts`.
    fn record_blas_passes(
        &mut self,
        rec: &mut Recorder<'_>,
        (slot, staged): (u32, Range),
        n: u32,
        (tris, nodes, refit): BlasAlloc,
        (strategy, counts): (BuildStrategy, Option<&mut NodeCounts>),
    ) {
        let max_leaf = strategy.max_leaf();
        let compacted = compaction_of(strategy, refit.is_some(), n) == BlasCompaction::Pending;
        let count_buffer = counts
            .filter(|_| compacted)
            .map(|c| (c, node_count_buffer(&self.device, 1)));
        self.ensure_scratch(n);
        rec.scope = "blas build";
        let (prims, lbvh) = self.passes.build(&self.device);
        prims.triangle_aabbs(
            rec,
            self.staged.buffer(),
            staged.start,
            n,
            &self.scratch_aabbs,
            0,
        );
        let (order, order_base) = match refit {
            Some((o, _)) => (self.orders.buffer(), o.start),
            None => (&self.scratch_order, 0),
        };
        // A fast-build tree (the Karras tree, one triangle a leaf) gets its nodes and sorted
        // triangles from the range refit's two passes instead of the climb and the gather: the
        // same nodes, without the climb's chains of device-scope round trips (measured faster on
        // the H100; see docs/decisions/range-refit.md).
        let by_ranges = strategy == BuildStrategy::FastBuild && n >= 2;
        let scratch_topology = (by_ranges && refit.is_none()).then(|| {
            self.scratch_topology.get(
                &self.device,
                "kickstart-rt build topology",
                u64::from(Lbvh::topology_words(n)) * 4,
            )
        });
        let topology = match (refit, &scratch_topology) {
            (Some((_, t)), _) => Some((self.topologies.buffer(), t.start)),
            (None, Some(scratch)) => Some((scratch, 0)),
            (None, None) => None,
        };
        lbvh.build(
            rec,
            &LbvhBuild {
                aabbs: &self.scratch_aabbs,
                aabb_base: 0,
                count: n,
                nodes: self.nodes.buffer(),
                node_base: nodes.start,
                order,
                order_base,
                topology,
                leaf_refs: LeafRefs::SortedPosition,
                max_leaf,
                bounds_out: Some((&self.geometry_table.buffer, slot * GEOMETRY_RECORD_VEC4 + 1)),
                key_bits: BLAS_KEY_BITS,
                centroid_bounds: None,
                // Fast-trace (leaves collapsed) is also the clustered build: the two together
                // are what `BuildHint::PreferFastTrace` promises.
                clustered: strategy == BuildStrategy::FastTrace,
                hierarchy_only: by_ranges,
                compact_counts: count_buffer.as_ref().map(|(_, b)| b),
            },
        );
        if let Some((counts, buffer)) = count_buffer {
            counts.parts.push((buffer, 1));
            counts.slots.push(slot);
        }
        match topology.filter(|_| by_ranges) {
            Some(topology) => lbvh.refit_triangles(
                rec,
                &LbvhTriangleRefit {
                    source: RefitSource::Staged {
                        triangles: self.staged.buffer(),
                        base: staged.start,
                    },
                    dst: self.triangles.buffer(),
                    dst_base: tris.start,
                    count: n,
                    nodes: self.nodes.buffer(),
                    node_base: nodes.start,
                    order,
                    order_base,
                    topology,
                    bounds_out: Some((
                        &self.geometry_table.buffer,
                        slot * GEOMETRY_RECORD_VEC4 + 1,
                    )),
                },
            ),
            None => prims.gather_triangles(
                rec,
                self.staged.buffer(),
                staged.start,
                order,
                order_base,
                n,
                self.triangles.buffer(),
                tris.start,
                None,
            ),
        }
    }

    /// Whether [`GpuScene::refit_blas`] can decode `triangles` triangles of these component
    /// rows itself ([`DeferredIngest`]): a fast-build tree (the Karras tree, one triangle a
    /// leaf) of the same count, with more than one block and few enough rows.
    pub fn can_refit_from_raw(g: &GeometryGpu, triangles: u32, rows: &[u32]) -> bool {
        matches!(
            g.blas,
            Some(BlasRanges {
                strategy: BuildStrategy::FastBuild,
                refit: Some(_),
                ..
            })
        ) && g.staged.is_some()
            && g.triangles == triangles
            && Lbvh::can_refit_from_raw(triangles, rows)
    }

    /// Refits a built `allow_update` BLAS to its re-ingested triangles: a fast-build tree by the
    /// range refit, pushed onto `refits` for the task's batch ([`GpuScene::record_refit_batch`]),
    /// a fast-trace (clustered) tree by gathering the triangles and their boxes and climbing.
    /// With `deferred`, the triangles are decoded from the application's bytes by the refit
    /// itself when [`GpuScene::can_refit_from_raw`], and ingested first otherwise.
    pub fn refit_blas(
        &mut self,
        rec: &mut Recorder<'_>,
        slot: u32,
        g: &GeometryGpu,
        deferred: Option<DeferredIngest>,
        refits: &mut Vec<DeferredRefit>,
    ) {
        let fused = deferred.and_then(|d| {
            if Self::can_refit_from_raw(g, g.triangles, &d.rows) {
                Some(d)
            } else {
                self.record_ingest(rec, &d.raw, &d.components, d.staged, d.ingestion);
                None
            }
        });
        let (
            Some(staged),
            Some(BlasRanges {
                tris,
                nodes,
                strategy,
                refit: Some((order, topology)),
                ..
            }),
        ) = (g.staged, g.blas)
        else {
            return;
        };
        let max_leaf = strategy.max_leaf();
        let n = g.triangles;
        rec.scope = "blas refit";
        // A fast-build tree (the Karras tree, one triangle a leaf) is refit from its nodes' leaf
        // ranges, straight from the re-ingested triangles, with the task's other range refits.
        if strategy == BuildStrategy::FastBuild && n >= 2 {
            refits.push(DeferredRefit {
                slot,
                staged,
                tris,
                nodes,
                order,
                topology,
                count: n,
                fused,
            });
            return;
        }
        self.ensure_scratch(n);
        let (prims, lbvh) = self.passes.build(&self.device);
        // The gather comes first and also writes the boxes in sorted order: one pass fewer than
        // a build's boxes-then-gather, and the climb reads its leaves' boxes coalesced.
        prims.gather_triangles(
            rec,
            self.staged.buffer(),
            staged.start,
            self.orders.buffer(),
            order.start,
            n,
            self.triangles.buffer(),
            tris.start,
            Some(&self.scratch_aabbs),
        );
        lbvh.refit(
            rec,
            &LbvhRefit {
                aabbs: &self.scratch_aabbs,
                aabb_base: 0,
                count: n,
                nodes: self.nodes.buffer(),
                node_base: nodes.start,
                order: self.orders.buffer(),
                order_base: order.start,
                topology: (self.topologies.buffer(), topology.start),
                leaf_refs: LeafRefs::SortedPosition,
                max_leaf,
                bounds_out: Some((&self.geometry_table.buffer, slot * GEOMETRY_RECORD_VEC4 + 1)),
                sorted_boxes: true,
            },
        );
    }

    /// Records the range refits [`GpuScene::refit_blas`] deferred, as one batch
    /// ([`Lbvh::refit_triangles_batch`]): those decoding the application's bytes first, then
    /// those of staged triangles, so each kind shares its dispatches.
    pub fn record_refit_batch(&mut self, rec: &mut Recorder<'_>, mut refits: Vec<DeferredRefit>) {
        if refits.is_empty() {
            return;
        }
        rec.scope = "blas refit";
        refits.sort_by_key(|r| r.fused.is_none());
        let staged = self.staged.buffer();
        let batch: Vec<LbvhTriangleRefit<'_>> = refits
            .iter()
            .map(|r| LbvhTriangleRefit {
                source: match &r.fused {
                    Some(d) => RefitSource::Raw(RawTriangles {
                        raw: &d.raw,
                        rows: &d.rows,
                        counters: &self.counters,
                        counter_base: d.ingestion * 2,
                    }),
                    None => RefitSource::Staged {
                        triangles: staged,
                        base: r.staged.start,
                    },
                },
                dst: self.triangles.buffer(),
                dst_base: r.tris.start,
                count: r.count,
                nodes: self.nodes.buffer(),
                node_base: r.nodes.start,
                order: self.orders.buffer(),
                order_base: r.order.start,
                topology: (self.topologies.buffer(), r.topology.start),
                bounds_out: Some((
                    &self.geometry_table.buffer,
                    r.slot * GEOMETRY_RECORD_VEC4 + 1,
                )),
            })
            .collect();
        let (_, lbvh) = self.passes.build(&self.device);
        lbvh.refit_triangles_batch(rec, &batch);
    }

    /// Whether the next TLAS update must rebuild rather than refit.
    pub fn tlas_needs_rebuild(&self, slots: u32) -> bool {
        !self.tlas.built || self.tlas.slots != slots
    }

    /// Refits since the last rebuild.
    pub fn tlas_refits_since_rebuild(&self) -> u32 {
        self.tlas.refits_since_rebuild
    }

    /// The capacity (refs) and node buffer bytes the TLAS buffers grow to for `slots` instance
    /// slots; `None` when they hold them already.
    fn tlas_growth(&self, slots: u32) -> Option<(u32, u64)> {
        let refs = slots.saturating_mul(refs_per_instance(slots));
        (refs > self.tlas.capacity).then(|| {
            let cap = refs.next_power_of_two().max(64);
            // Node slots, then the ref table (one vec4 a ref; scene/traversal.wgsl finds it from the
            // buffer's length).
            (cap, cap as u64 * (NODE_BYTES + REF_BYTES))
        })
    }

    /// Refuses a TLAS over `slots` instance slots past the device's limit (the plan's check of
    /// [`GpuScene::update_tlas`]).
    pub fn check_tlas(&self, slots: u32) -> Result<()> {
        match self.tlas_growth(slots) {
            Some((_, need)) if need > self.max_binding => Err(Error::OutOfDeviceMemory {
                what: "TLAS nodes".into(),
                bytes: need,
                limit: self.max_binding,
            }),
            _ => Ok(()),
        }
    }

    /// Builds (`refit == false`) or refits the TLAS over instance slots `0..slots`
    /// ([`GpuScene::check_tlas`] admitted them).
    pub fn update_tlas(&mut self, rec: &mut Recorder<'_>, slots: u32, refit: bool) {
        let refit = refit && !self.tlas_needs_rebuild(slots);
        let per_instance = refs_per_instance(slots);
        let refs = slots.saturating_mul(per_instance);
        if let Some((cap, need)) = self.tlas_growth(slots) {
            debug_assert!(need <= self.max_binding, "the plan checked the TLAS fits");
            let d = &self.device;
            self.tlas.nodes = storage(d, "kickstart-rt TLAS nodes", need);
            self.tlas.order = storage(d, "kickstart-rt TLAS order", cap as u64 * 4);
            self.tlas.topology = storage(
                d,
                "kickstart-rt TLAS topology",
                Lbvh::topology_words(cap).max(1) as u64 * 4,
            );
            self.tlas.aabbs = storage(
                d,
                "kickstart-rt TLAS instance boxes",
                cap as u64 * AABB_BYTES,
            );
            self.tlas.capacity = cap;
        }
        let (prims, lbvh) = self.passes.build(&self.device);
        rec.scope = if refit { "tlas refit" } else { "tlas build" };
        // A refit keeps the tree and needs no centroid bounds.
        let centroid_bounds = (!refit).then_some((&self.tlas.centroid_bounds, 0));
        prims.instance_refs(
            rec,
            &self.instance_table.buffer,
            &self.geometry_table.buffer,
            self.nodes.buffer(),
            slots,
            per_instance,
            &self.tlas.aabbs,
            &self.tlas.nodes,
            centroid_bounds,
        );
        if refit {
            lbvh.refit(
                rec,
                &LbvhRefit {
                    aabbs: &self.tlas.aabbs,
                    aabb_base: 0,
                    count: refs,
                    nodes: &self.tlas.nodes,
                    node_base: 0,
                    order: &self.tlas.order,
                    order_base: 0,
                    topology: (&self.tlas.topology, 0),
                    leaf_refs: LeafRefs::PrimitiveIndex,
                    max_leaf: 1,
                    bounds_out: None,
                    sorted_boxes: false,
                },
            );
            self.tlas.refits_since_rebuild += 1;
        } else {
            lbvh.build(
                rec,
                &LbvhBuild {
                    aabbs: &self.tlas.aabbs,
                    aabb_base: 0,
                    count: refs,
                    nodes: &self.tlas.nodes,
                    node_base: 0,
                    order: &self.tlas.order,
                    order_base: 0,
                    topology: Some((&self.tlas.topology, 0)),
                    leaf_refs: LeafRefs::PrimitiveIndex,
                    max_leaf: 1,
                    bounds_out: None,
                    key_bits: TLAS_KEY_BITS,
                    centroid_bounds,
                    clustered: tlas_clustered(refs),
                    hierarchy_only: false,
                    compact_counts: None,
                },
            );
            self.tlas.refits_since_rebuild = 0;
            self.tlas.slots = slots;
            self.tlas.built = true;
        }
    }

    /// Counts a geometry whose opacity micro-maps went from `had` to `has` (present or not).
    pub fn note_cutout_geometry(&mut self, had: bool, has: bool) {
        match (had, has) {
            (false, true) => self.cutout_geometries += 1,
            (true, false) => self.cutout_geometries = self.cutout_geometries.saturating_sub(1),
            _ => {}
        }
    }

    /// The traversal build that traces the scene as registered now.
    pub fn leaf_test(&self) -> LeafTest {
        self.scene_buffers().leaf_test()
    }

    /// The scene as every tracing pass binds it.
    pub fn scene_buffers(&self) -> SceneBuffers<'_> {
        SceneBuffers {
            tlas_nodes: &self.tlas.nodes,
            instances: &self.instance_table.buffer,
            geometries: &self.geometry_table.buffer,
            blas_nodes: self.nodes.buffer(),
            triangles: self.triangles.buffer(),
            tlas: self.hardware.as_ref().map(HardwareScene::tlas),
            cutouts: self.cutout_geometries > 0,
        }
    }

    /// Reads back a BLAS (blocks on the device; tools and tests only).
    pub fn read_back_blas(&self, queue: &wgpu::Queue, g: &GeometryGpu) -> Result<RawBlas> {
        let Some(b) = g.blas else {
            return Err(Error::ReadBack(
                "the geometry's BLAS is not built yet".into(),
            ));
        };
        let nodes = read_back(
            &self.device,
            queue,
            self.nodes.buffer(),
            b.nodes.start as u64 * NODE_BYTES,
            b.nodes.len as u64 * NODE_BYTES,
        )?;
        let tris = read_back(
            &self.device,
            queue,
            self.triangles.buffer(),
            b.tris.start as u64 * TRIANGLE_BYTES,
            b.tris.len as u64 * TRIANGLE_BYTES,
        )?;
        Ok((
            bytemuck::pod_collect_to_vec(&nodes),
            bytemuck::pod_collect_to_vec(&tris),
        ))
    }
}

/// Bytes of one ref-table entry of the TLAS node buffer: (instance slot, BLAS entry, build
/// stamp, 0).
const REF_BYTES: u64 = 16;

/// Refs the TLAS's instances are opened into, at most, when an instance is opened at all.
/// Opening more refs lets rays skip more of big instances, up to a point where the traces stop
/// gaining while the TLAS builds over many instances keep paying (more refs each, past the
/// one-workgroup sort); 2048 is where the apartment's traces stopped gaining on the H100 (see
/// docs/decisions/instance-refs.md).
const TLAS_REF_BUDGET: u32 = 2048;

/// Refs each instance slot is opened into (`instance_refs` in `shaders/scene/prims.wgsl`): up to
/// [`MAX_REFS_PER_INSTANCE`] while the TLAS stays within [`TLAS_REF_BUDGET`] refs, then fewer,
/// down to one (the instance as a whole) from 1025 slots on, and one for a lone instance. Opening
/// lets rays skip the parts of big instances they do not pass near (a scene of a few big
/// instances, such as the apartment: docs/decisions/instance-refs.md); a TLAS of many instances
/// keeps its build cost.
pub(crate) fn refs_per_instance(slots: u32) -> u32 {
    if slots <= 1 {
        // Nothing to be entered instead: a lone instance is the whole scene, and opening it
        // only adds TLAS levels above its BLAS's (measured slower on the dragon; see
        // docs/decisions/instance-refs.md).
        return 1;
    }
    (TLAS_REF_BUDGET / slots).clamp(1, MAX_REFS_PER_INSTANCE)
}

/// Most refs a TLAS build clusters (`hploc climb`, as the fast-trace BLAS) instead of taking
/// the LBVH's Karras tree: the TLAS of opened instances (at most [`TLAS_REF_BUDGET`] refs).
/// Clustering a TLAS of a few big instances' refs makes its rays faster for a small build cost;
/// at 10k and 100k instances it would about double the build, so those TLASes stay LBVHs
/// (measured on the H100; see docs/decisions/tlas-build.md).
const TLAS_CLUSTERED_MAX_REFS: u32 = TLAS_REF_BUDGET;

/// Whether a TLAS build over `refs` refs clusters them.
fn tlas_clustered(refs: u32) -> bool {
    refs <= TLAS_CLUSTERED_MAX_REFS
}

/// A TLAS node buffer holding one root with two empty children: before the first TLAS build,
/// every ray misses at once (a zeroed node would be a self-referencing inner node).
fn empty_root(device: &wgpu::Device) -> wgpu::Buffer {
    let e = f32::from_bits(0x8000_0000);
    let root: [f32; 16] = [
        1e30, 1e30, 1e30, e, -1e30, -1e30, -1e30, e, 1e30, 1e30, 1e30, 0.0, -1e30, -1e30, -1e30,
        0.0,
    ];
    crate::gpu::buffers::buffer_init(
        device,
        "kickstart-rt TLAS nodes",
        bytemuck::cast_slice(&root),
        wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
    )
}

/// Where a new BLAS's nodes stand with compaction: a fast-trace tree (leaves collapsed) that
/// keeps no refit topology and has inner nodes is compacted by its build, and its unused nodes
/// given back once the count is read back; the others have no unreferenced node.
fn compaction_of(strategy: BuildStrategy, kept: bool, triangles: u32) -> BlasCompaction {
    if strategy == BuildStrategy::FastTrace && !kept && triangles >= 2 {
        BlasCompaction::Pending
    } else {
        BlasCompaction::NotApplicable
    }
}

/// The node counts a task's compactions write, for the context to read back: the first `words`
/// words of each part's buffer, in order, are the counts of the geometry slots in `slots`.
#[derive(Default)]
pub(crate) struct NodeCounts {
    /// (buffer, words), in order.
    pub parts: Vec<(wgpu::Buffer, usize)>,
    /// The geometry slot of each count, in order.
    pub slots: Vec<u32>,
}

/// A buffer for `words` node counts of compactions (copied out to a read-back).
fn node_count_buffer(device: &wgpu::Device, words: usize) -> wgpu::Buffer {
    device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("kickstart-rt BLAS node counts"),
        size: (words as u64 * 4).max(4),
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        mapped_at_creation: false,
    })
}

/// A BLAS as read back: raw nodes (16 floats each) and triangles (12 floats each).
pub(crate) type RawBlas = (Vec<[f32; 16]>, Vec<[f32; 12]>);

/// Elements a task's BLAS builds allocate from each pool, in all.
pub(crate) struct BlasTotals {
    pub triangles: u64,
    pub nodes: u64,
    pub orders: u64,
    pub topology_words: u64,
}

impl BlasTotals {
    /// The totals of `builds` (`(triangles, keep_for_refit)` each), as
    /// [`GpuScene::build_blas`] allocates them (at least one element each).
    pub fn of(builds: &[(u32, bool)]) -> Self {
        let mut t = BlasTotals {
            triangles: 0,
            nodes: 0,
            orders: 0,
            topology_words: 0,
        };
        for &(n, keep) in builds {
            t.triangles += u64::from(n.max(1));
            t.nodes += u64::from(Lbvh::node_count(n).max(1));
            if keep {
                t.orders += u64::from(n.max(1));
                t.topology_words += u64::from(Lbvh::topology_words(n).max(1));
            }
        }
        t
    }
}

#[cfg(test)]
mod tests {
    use super::{continues, refs_per_instance, TLAS_REF_BUDGET};

    #[test]
    fn instances_are_opened_into_at_most_thirty_two_refs_within_the_budget() {
        // A lone instance (or none) is not opened.
        assert_eq!(refs_per_instance(0), 1);
        assert_eq!(refs_per_instance(1), 1);
        assert_eq!(refs_per_instance(2), 32);
        assert_eq!(refs_per_instance(64), 32);
        assert_eq!(refs_per_instance(65), 31);
        assert_eq!(refs_per_instance(67), 30);
        assert_eq!(refs_per_instance(256), 8);
        assert_eq!(refs_per_instance(257), 7);
        assert_eq!(refs_per_instance(1024), 2);
        assert_eq!(refs_per_instance(1025), 1);
        assert_eq!(refs_per_instance(100_000), 1);
        for slots in 1..5000 {
            let k = refs_per_instance(slots);
            assert!((1..=32).contains(&k));
            assert!(
                k == 1 || slots * k <= TLAS_REF_BUDGET,
                "{slots} slots: {k} refs each"
            );
        }
    }

    #[test]
    fn only_writes_adjacent_in_both_buffers_share_a_copy() {
        // Slot records of 128 bytes written in order: each continues the last.
        assert!(continues((0, 0, 128), 128, 128));
        assert!(continues((256, 512, 128), 384, 640));
        // A gap in the destination, or bytes staged in between, starts a new copy.
        assert!(!continues((0, 0, 128), 256, 128));
        assert!(!continues((0, 0, 128), 128, 256));
        // Backwards (a lower slot after a higher one) too.
        assert!(!continues((128, 0, 128), 0, 128));
    }
}
