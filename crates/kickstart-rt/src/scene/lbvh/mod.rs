//! GPU LBVH (Karras 2012) over primitive AABBs, and its refit. Shaders: `shaders/scene/lbvh/`, one module a
//! pass (`lbvh.wgsl` imports them all);
//! layouts: `docs/ray-tracing-core.md` (AABB input, BVH2 node format).
//!
//! Build, all recorded into the caller's encoder:
//! 1. clear the arrival counters, and the centroid-bounds words when step 2 runs (`clear_buffer`);
//! 2. `lbvh bounds`: bounds of the valid centroids (workgroup reduce, then device atomics), unless
//!    the caller's primitive pass merged them already ([`LbvhBuild::centroid_bounds`]: the
//!    TLAS's instance boxes, one dependent dispatch fewer);
//! 3. `lbvh morton`: Morton keys of [`LbvhBuild::key_bits`] bits (`min(key_bits / 3, 10)`
//!    bits per axis); empty primitives get the all-ones key so they sort last. Above 1024
//!    primitives it also counts the keys' first sort digit into the sort's histogram
//!    (`lbvh_morton_histogram`, [`RadixSort::first_histogram`]): one dependent dispatch fewer;
//! 4. [`RadixSort::record`] (`key_bits`, stable), values = primitive indices: 31 bits and 4
//!    digit passes for a BLAS ([`BLAS_KEY_BITS`]), 24 bits and 3 passes for a TLAS
//!    ([`TLAS_KEY_BITS`]), whose sorted pairs stay in the sort's scratch (no copy back);
//! 5. `lbvh hierarchy`: `order`, children and parents (Karras, with the index tie-break, so
//!    equal keys are fine); a parent ref says whether the parent's leaves all lie in one climb
//!    workgroup's block;
//! 6. `lbvh climb`: bottom-up boxes without waiting on anyone (see the shader), writes the nodes
//!    and `bounds_out`. Nodes within one workgroup's block are joined in workgroup memory; only
//!    the few that straddle blocks pay device-scope fences. With `max_leaf` > 1 it also
//!    computes each subtree's SAH cost and turns every subtree of at most `max_leaf` primitives
//!    that is cheaper as one leaf into a leaf ref (the fast-trace build; its inner nodes stay in
//!    the buffer, unreferenced).
//!
//! With [`LbvhBuild::clustered`] (the fast-trace BLAS), step 5 writes the Karras hierarchy to
//! the builder's scratch and step 6 is `hploc climb` instead (`shaders/scene/lbvh/hploc.wgsl`, workgroups of
//! 32): the same bottom-up walk, merging clusters by PLOC at every node that covers more than 16
//! leaves (H-PLOC), writing the nodes and the caller's topology of the clustered tree (whose parent
//! refs never carry the block-local bit, so a refit of it runs the climb's device-scope phase
//! only). Its subtrees need not be ranges of sorted positions; only those that are may become
//! one leaf.
//!
//! Refit runs steps 1 (arrival counters only) and 6 over the stored topology; a BLAS refit's
//! boxes come in sorted order ([`LbvhRefit::sorted_boxes`]).
//!
//! The refit of a fast-build BLAS (a Karras tree, one triangle a leaf) is the *range refit*
//! instead ([`Lbvh::refit_triangles`]), which starts from the re-ingested triangles: every inner
//! node covers one range of sorted positions (the hierarchy pass stores each node's other range
//! end in the topology), and the box of a range is the union of at most two boxes per level of a
//! pyramid over the sorted leaf boxes (`shaders/scene/lbvh/range_refit.wgsl`). `lbvh refit gather`
//! gathers the triangles into sorted order, makes the pyramid's lowest 8 levels over each block of
//! 256 in workgroup memory, writes every node whose range lies inside its block, lists the others
//! and merges its top box into the levels above with atomics. `lbvh range refit` then writes the
//! listed nodes, which straddle blocks, walking each node's two children side by side. Two
//! passes, no arrival counters, fences or waiting, no chains of device-scope round trips from the
//! leaves to the root (what bounds the climb: docs/decisions/range-refit.md); the nodes are
//! bit-identical to the climb's. With [`RefitSource::Raw`], `lbvh refit ingest` takes the
//! gather's place and decodes the triangles from the application's bytes itself: the ingestion
//! fused into the refit.
//!
//! The build passes read their `Params` from the `segs` table (a single build is a batch of
//! one); [`Lbvh::build_batch`] runs them once for every fast-trace build of a task (`batch.rs`:
//! builds padded to blocks of 256 positions, a sort by Morton key then by build). The range
//! refits of a task are one batch too ([`Lbvh::refit_triangles_batch`]: each refit's blocks
//! from a multiple of 256 positions, its `Params` in a uniform table). The climb's refit and
//! `lbvh climb` read the `params` uniform.
//!
//! Files: this one holds the inputs, the builder and its sizes; `build.rs` the build (steps 1–6),
//! `batch.rs` a batch of builds, `refit.rs` both refits, `cpu.rs` the CPU helpers of the tests,
//! `tests/` the tests.

mod batch;
mod build;
mod compact;
#[cfg(test)]
mod cpu;
mod refit;
#[cfg(test)]
mod tests;

use crate::gpu::radix_sort::RadixSort;
use crate::gpu::reflect::{ReflectedPipeline, ReflectedShader};
use crate::gpu::Recorder;
pub(crate) use batch::{batch_runs, BatchBuild, BatchKind, LbvhBatch};
use bytemuck::{Pod, Zeroable};

// The builder's scratch that only grows (gpu layer); the scene's tables use it too.
use crate::gpu::buffers::Grown;
#[cfg(test)]
pub(crate) use cpu::cpu_centroid_bounds;
#[cfg(test)]
use refit::{
    chunk_len, pyramid_boxes, pyramid_level_count, REFIT_BATCH, REFIT_BATCH_POSITIONS,
    REFIT_GATHER_LEVELS,
};

/// Invocations per workgroup of every LBVH pass (the shader's `WG`).
const WORKGROUP: u32 = 256;
/// Sort key bits of a BLAS build: 10 Morton bits per axis and a spare bit above them, so the
/// all-ones "empty" key is above every Morton code (4 digit passes of the sort). A BLAS has up
/// to millions of triangles, which need the fine grid to be ordered well.
pub(crate) const BLAS_KEY_BITS: u32 = 31;
/// Sort key bits of a TLAS build: 8 Morton bits per axis, 3 digit passes instead of 4, and an
/// odd pass count leaves the result in the sort's scratch, so a TLAS build records 5 sort
/// dispatches instead of 7 (up to 65536 refs; 8 instead of 11 above; the morton pass makes the
/// first histogram either way), each a dependent pass: on the H100 about 10 µs of gap plus its
/// own time. A TLAS has far fewer primitives than a large BLAS (2^24 cells, 168 per instance at
/// 100k instances), and instances sharing a cell are still split, by index (the hierarchy's
/// tie-break), so the tree stays valid and only its order within a cell is arbitrary. The cost
/// is where instances crowd into few cells: a dense cluster in a scene stretched by a far
/// instance gets a worse tree than with 10 bits per axis (3.6 times the SAH cost below the root
/// in the `lbvh_tlas_keys_*` test, 10 times with 7 bits per axis and the "empty" bit).
pub(crate) const TLAS_KEY_BITS: u32 = 24;
/// Sort key bits accepted: 1 Morton bit per axis at least, and the "empty" key `2^bits - 1`
/// must fit a u32 shift.
const KEY_BITS_RANGE: std::ops::RangeInclusive<u32> = 3..=31;
/// Params flag: leaf refs are primitive indices.
const FLAG_PRIMITIVE_REFS: u32 = 1;
/// Params flag: write the root box to `bounds_out`.
const FLAG_BOUNDS_OUT: u32 = 2;
/// Params flag: the boxes are in sorted order ([`LbvhRefit::sorted_boxes`]).
const FLAG_SORTED_BOXES: u32 = 4;
/// Params flag: primitive boxes come from the staged triangles (a batch's builds).
const FLAG_TRIANGLE_BOXES: u32 = 8;
/// First word of the inner-node boxes in the work buffer (after the centroid-bounds header).
const BOXES_AT: u64 = 8;
/// Largest primitive count: a leaf ref has 28 bits for its first primitive.
const MAX_COUNT: u32 = 1 << 28;
/// Largest leaf: a leaf ref has 3 bits for its count − 1.
pub(crate) const MAX_LEAF: u32 = 8;

/// What a leaf's `first` field refers to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum LeafRefs {
    /// Sorted position `k` (BLAS: the triangles are gathered into sorted order by the caller).
    SortedPosition,
    /// The primitive index `order[k]` (TLAS: instance indices).
    PrimitiveIndex,
}

/// Inputs and outputs of one build. Buffers are bound whole; the bases are element indices.
pub(crate) struct LbvhBuild<'a> {
    /// Primitive boxes: two `vec4` per primitive, primitive `i` at vec4 `2 * (aabb_base + i)`.
    pub aabbs: &'a wgpu::Buffer,
    /// First primitive in `aabbs`.
    pub aabb_base: u32,
    /// Number of primitives (at most 2^28).
    pub count: u32,
    /// Output: [`Lbvh::node_count`] nodes (64 bytes each) from node index `node_base`.
    pub nodes: &'a wgpu::Buffer,
    /// First node of this BVH; child refs are relative to it.
    pub node_base: u32,
    /// Output: `order[order_base + k]` = primitive index at sorted position `k`.
    pub order: &'a wgpu::Buffer,
    /// First u32 of `order`.
    pub order_base: u32,
    /// Output: [`Lbvh::topology_words`] u32s from the given base, needed by [`Lbvh::refit`].
    /// `None`: kept in the builder's scratch (no refit possible later).
    pub topology: Option<(&'a wgpu::Buffer, u32)>,
    /// What leaf refs point at.
    pub leaf_refs: LeafRefs,
    /// Largest leaf made by collapsing subtrees by SAH (1..=[`MAX_LEAF`]; 1 = one primitive per
    /// leaf). Only honoured with [`LeafRefs::SortedPosition`].
    pub max_leaf: u32,
    /// Output: the root box as two `vec4` (min, max; `w` = 0) at this vec4 index.
    pub bounds_out: Option<(&'a wgpu::Buffer, u32)>,
    /// Bits of the sort keys (clamped to 3..=31): `min(key_bits / 3, 10)` Morton bits per axis,
    /// and the sort takes one pass per 8 bits, so fewer bits cost fewer dispatches and give a
    /// coarser spatial order ([`BLAS_KEY_BITS`], [`TLAS_KEY_BITS`]). Empty primitives get the
    /// all-ones key; when the Morton bits fill the key (a multiple of 3), the one Morton code
    /// equal to it (the far corner cell) is lowered into its neighbour's.
    pub key_bits: u32,
    /// Centroid bounds the caller's pass merged while writing `aabbs` (buffer, first u32 word):
    /// 6 words in the encoding of `shaders/scene/centroid_bounds.wgsl`, which that pass must include
    /// (same primitives counted, same words), so the build skips its `lbvh bounds` pass. `None`:
    /// the build computes them. The words must be ready (zeroed, then merged) before the build's
    /// passes run; the buffer needs STORAGE usage.
    pub centroid_bounds: Option<(&'a wgpu::Buffer, u32)>,
    /// After a clustered build with collapsed leaves and no kept `topology`: compact its nodes
    /// in place ([`Lbvh::compact`]) and write their count to word 0 of this buffer (STORAGE and
    /// COPY_SRC usage), from which the caller learns what of its node range it may give back.
    /// `None`: the nodes stay as the climb wrote them.
    pub compact_counts: Option<&'a wgpu::Buffer>,
    /// Cluster the Morton-ordered primitives by PLOC (`hploc climb`) instead of taking the
    /// Karras tree as it is: a lower SAH cost for a slower build. With
    /// [`LeafRefs::PrimitiveIndex`] (the TLAS) no leaf is collapsed, whatever `max_leaf` says.
    pub clustered: bool,
    /// Stop after the hierarchy: the caller writes the nodes and `bounds_out` itself with
    /// [`Lbvh::refit_triangles`] over this build's `order` and `topology` (a fast-build BLAS of
    /// at least two triangles: the range refit's two passes replace the climb and the triangle
    /// gather, with bit-identical nodes). So it needs a `topology`, `max_leaf` 1 and no
    /// clustering; the caller decides and nothing here second-guesses it.
    pub hierarchy_only: bool,
}

/// Inputs and outputs of one refit: the same topology as a previous build, new boxes. Leaf `k`
/// gets the box `aabbs[order[k]]`; every node's boxes are rewritten, refs stay as they are.
pub(crate) struct LbvhRefit<'a> {
    /// Primitive boxes, as in [`LbvhBuild::aabbs`].
    pub aabbs: &'a wgpu::Buffer,
    /// First primitive in `aabbs`.
    pub aabb_base: u32,
    /// Number of primitives (as built).
    pub count: u32,
    /// The nodes written by the build.
    pub nodes: &'a wgpu::Buffer,
    /// First node of this BVH.
    pub node_base: u32,
    /// The order written by the build.
    pub order: &'a wgpu::Buffer,
    /// First u32 of `order`.
    pub order_base: u32,
    /// The topology written by the build (buffer, base).
    pub topology: (&'a wgpu::Buffer, u32),
    /// What leaf refs point at (as built).
    pub leaf_refs: LeafRefs,
    /// Leaf collapsing, as [`LbvhBuild::max_leaf`] (the decisions are made again for the new
    /// boxes; a subtree's primitives stay one range, so any decision is valid).
    pub max_leaf: u32,
    /// Output: the root box as two `vec4` at this vec4 index.
    pub bounds_out: Option<(&'a wgpu::Buffer, u32)>,
    /// `aabbs` holds the boxes in sorted order already (leaf `k`'s at `aabb_base + k`, as
    /// [`crate::scene::prims::Prims::gather_triangles`] writes them), so the climb reads each
    /// with one coalesced load instead of going through `order`.
    pub sorted_boxes: bool,
}

/// Inputs and outputs of the range refit of a BLAS built as a Karras tree (not clustered) with
/// one triangle a leaf and its topology kept: the re-ingested triangles are gathered into
/// sorted order and every node is refit from its leaf range ([`Lbvh::refit_triangles`]).
pub(crate) struct LbvhTriangleRefit<'a> {
    /// Where the new triangles come from.
    pub source: RefitSource<'a>,
    /// Output: the BLAS's triangles in sorted order.
    pub dst: &'a wgpu::Buffer,
    /// First triangle of the BLAS in `dst`.
    pub dst_base: u32,
    /// Number of triangles (as built, at least 2).
    pub count: u32,
    /// The nodes written by the build.
    pub nodes: &'a wgpu::Buffer,
    /// First node of this BVH.
    pub node_base: u32,
    /// The order written by the build.
    pub order: &'a wgpu::Buffer,
    /// First u32 of `order`.
    pub order_base: u32,
    /// The topology written by the build (buffer, base).
    pub topology: (&'a wgpu::Buffer, u32),
    /// Output: the root box as two `vec4` at this vec4 index.
    pub bounds_out: Option<(&'a wgpu::Buffer, u32)>,
}

/// The triangles a range refit takes.
pub(crate) enum RefitSource<'a> {
    /// Re-ingested (staged) triangles in primitive order (3 `vec4` each), the geometry's first
    /// at triangle `base` of `triangles`.
    Staged {
        /// The staged-triangle pool.
        triangles: &'a wgpu::Buffer,
        /// First triangle of the geometry.
        base: u32,
    },
    /// The application's bytes, decoded by the refit itself (`lbvh refit ingest`): the
    /// ingestion fused into the refit, for an update refit in the task that ingests it. Needs
    /// more than one block of triangles ([`Lbvh::can_refit_from_raw`]).
    Raw(RawTriangles<'a>),
}

/// The application's bytes of one geometry, as the ingestion pass would decode them.
pub(crate) struct RawTriangles<'a> {
    /// The raw copy of the vertex and index bytes.
    pub raw: &'a wgpu::Buffer,
    /// The geometry's component rows (`crate::scene::ingest::component_rows`, its triangle
    /// indices starting at 0), at most [`REFIT_INGEST_ROWS`].
    pub rows: &'a [u32],
    /// The dropped-triangle counters.
    pub counters: &'a wgpu::Buffer,
    /// First of the geometry's two counters (out-of-range index, non-finite position).
    pub counter_base: u32,
}

/// Component rows one `lbvh refit ingest` dispatch takes, for all of its refits
/// (`REFIT_INGEST_ROWS` in `shaders/scene/lbvh/range_refit.wgsl`: its uniform table, 56 KiB of WebGPU's
/// default 64 KiB uniform binding), and so the most one refit from raw bytes may have.
pub(crate) const REFIT_INGEST_ROWS: usize = 512;

/// Per-dispatch parameters (the shader's `Params`).
#[repr(C)]
#[derive(Debug, Clone, Copy, Pod, Zeroable)]
struct Params {
    count: u32,
    aabb_base: u32,
    node_base: u32,
    order_base: u32,
    topo_base: u32,
    bounds_base: u32,
    flags: u32,
    max_leaf: u32,
    /// Sort key bits (build only; refits leave it 0).
    key_bits: u32,
    /// First centroid-bounds word in the buffer `lbvh_morton` binds at 2.
    centroid_base: u32,
    /// First word of the build's region of `work` (its own in a batch).
    work_base: u32,
    /// First position of the build's keys and values in a batch's sort (a multiple of
    /// [`WORKGROUP`]).
    key_base: u32,
    /// `lbvh refit gather`: first staged triangle.
    tri_src_base: u32,
    /// `lbvh refit gather`: first BLAS triangle.
    tri_dst_base: u32,
    /// `lbvh refit ingest`: component rows in use.
    ingest_row_count: u32,
    /// `lbvh refit ingest`: first of the geometry's two dropped-triangle counters.
    ingest_counter: u32,
    /// Where `lbvh hierarchy` writes the Karras topology: `topo_base`, or the builder's scratch
    /// for a clustered build (which `hploc climb` reads).
    karras_base: u32,
    /// Range refits: the refit's first box in the box pyramid (its own region in a batch).
    pyramid_base: u32,
    /// `lbvh refit ingest`: the refit's first row in the batch's component rows.
    row_base: u32,
    pad: u32,
}

/// The LBVH builder: its pipelines, the radix sort, and scratch grown on demand.
pub(crate) struct Lbvh {
    bounds: ReflectedPipeline,
    morton: ReflectedPipeline,
    /// `lbvh_morton_histogram`: the keys and the sort's first histogram in one pass.
    morton_histogram: ReflectedPipeline,
    hierarchy: ReflectedPipeline,
    climb: ReflectedPipeline,
    hploc: ReflectedPipeline,
    /// `lbvh_refit_gather`: the range refit's gather, box pyramid and in-block nodes.
    refit_gather: ReflectedPipeline,
    /// `lbvh_refit_ingest`: `lbvh_refit_gather` decoding its triangles from the application's
    /// bytes (the ingestion fused into the refit).
    refit_ingest: ReflectedPipeline,
    /// `lbvh_range_refit`: the nodes that straddle blocks, from their leaf ranges.
    range_refit: ReflectedPipeline,
    /// A batch's passes ([`Lbvh::build_batch`]): keys by build, Morton keys again, and the
    /// triangles gathered into each build's sorted order.
    segment_keys: ReflectedPipeline,
    rekey: ReflectedPipeline,
    gather: ReflectedPipeline,
    /// The compaction after a clustered BLAS build ([`Lbvh::compact`]).
    compact: compact::CompactPipelines,
    sort: RadixSort,
    /// Centroid bounds, inner boxes during the climb, arrival counters; for a clustered build
    /// also the cluster counts and lists ([`clustered_work_words`]).
    work: Grown,
    keys: Grown,
    values: Grown,
    /// Topology of builds whose caller does not keep it; the Karras hierarchy of clustered
    /// builds.
    topology: Grown,
    /// Topology of clustered builds whose caller does not keep it.
    clustered_topology: Grown,
    /// Bound in place of a missing `bounds_out` (never written: the flag is off).
    dummy: Grown,
    /// The range refit's box pyramid above level 0 ([`pyramid_boxes`] − n boxes of 32 bytes).
    pyramid_boxes: Grown,
    /// A batch's sort order (its builds' orders are not kept).
    batch_order: Grown,
    /// The compaction's per-block counts and first new indices (a word per 256 positions).
    compact_blocks: Grown,
}

/// Invocations of a `hploc_climb` workgroup (`HP_WG` in `shaders/scene/lbvh/hploc.wgsl`).
const HPLOC_WORKGROUP: u32 = 32;

/// Buffers of one dispatch by the shader's names for them (`shaders/scene/lbvh/common.wgsl`
/// declares most, `shaders/scene/lbvh/hploc.wgsl` one): each pass binds those its entry point uses, at the binding numbers the
/// shader declares ([`ReflectedPipeline::bind_group`]); a later entry of a name overrides an
/// earlier one.
type Buffers<'a> = Vec<(&'static str, &'a wgpu::Buffer)>;

/// Workgroups covering `n` invocations (at least one: the small-count path needs a thread).
fn groups(n: u32) -> u32 {
    n.div_ceil(WORKGROUP).max(1)
}

/// Words of the work buffer for `n` primitives: header, then per inner node 6 for its box, 1
/// arrival counter and 3 for its SAH summary (cost, count, first).
fn work_words(n: u32) -> u64 {
    BOXES_AT + 10 * u64::from(n.saturating_sub(1))
}

/// Words of the work buffer of a clustered build (`shaders/scene/lbvh/hploc.wgsl`): [`work_words`], then a
/// cluster count per Karras node, a cluster-list slot and a free-slot-list slot per primitive;
/// and at least what the compaction after the climb needs there (`shaders/scene/lbvh/compact.wgsl`: a
/// copy of every inner node, 16 words, and its new index).
fn clustered_work_words(n: u32) -> u64 {
    let inner = u64::from(n.saturating_sub(1));
    let climb = work_words(n) + inner + 2 * u64::from(n);
    climb.max(BOXES_AT + 17 * inner)
}

/// The `max_leaf` a dispatch uses: clamped to 1..=MAX_LEAF, and 1 for primitive-index refs
/// (a TLAS leaf's instances are not one range).
fn effective_max_leaf(max_leaf: u32, leaf_refs: LeafRefs) -> u32 {
    match leaf_refs {
        LeafRefs::SortedPosition => max_leaf.clamp(1, MAX_LEAF),
        LeafRefs::PrimitiveIndex => 1,
    }
}

/// The modules of the builder's one shader: the LBVH's passes (`lbvh` imports each pass's module)
/// and the clustered climb, with the digit counting, centroid bounds, triangle boxes and vertex
/// decoding they share with other passes.
const SHADER_ROOTS: &[&str] = &["scene/lbvh/lbvh", "scene/lbvh/hploc"];

/// The WGSL of the builder's passes, labelled.
pub(crate) fn shader_variants() -> Vec<(String, String)> {
    let shader = ReflectedShader::compose(SHADER_ROOTS, &[]);
    vec![("scene/lbvh".into(), shader.source().to_string())]
}

impl Lbvh {
    /// Creates the pipelines (no buffers until the first build).
    pub fn new(device: &wgpu::Device) -> Self {
        let shader = ReflectedShader::compose(SHADER_ROOTS, &[]);
        let pipeline = |label, entry| shader.pipeline(device, label, entry);
        Lbvh {
            bounds: pipeline("lbvh bounds", "lbvh_bounds"),
            morton: pipeline("lbvh morton", "lbvh_morton"),
            morton_histogram: pipeline("lbvh morton", "lbvh_morton_histogram"),
            hierarchy: pipeline("lbvh hierarchy", "lbvh_hierarchy"),
            climb: pipeline("lbvh climb", "lbvh_climb"),
            hploc: pipeline("hploc climb", "hploc_climb"),
            refit_gather: pipeline("lbvh refit gather", "lbvh_refit_gather"),
            refit_ingest: pipeline("lbvh refit ingest", "lbvh_refit_ingest"),
            range_refit: pipeline("lbvh range refit", "lbvh_range_refit"),
            segment_keys: pipeline("lbvh segment keys", "lbvh_segment_keys"),
            rekey: pipeline("lbvh rekey", "lbvh_rekey"),
            gather: pipeline("lbvh gather", "lbvh_gather"),
            compact: compact::CompactPipelines::new(&shader, device),
            sort: RadixSort::new(device),
            work: Grown::default(),
            keys: Grown::default(),
            values: Grown::default(),
            topology: Grown::default(),
            clustered_topology: Grown::default(),
            dummy: Grown::default(),
            pyramid_boxes: Grown::default(),
            batch_order: Grown::default(),
            compact_blocks: Grown::default(),
        }
    }

    /// Nodes of a BVH over `count` primitives: `count - 1` inner nodes, and always a root.
    pub fn node_count(count: u32) -> u32 {
        count.saturating_sub(1).max(1)
    }

    /// u32 words of the topology: children (2 per inner node), parents of inner nodes and of
    /// leaves, and the inner nodes' range ends (the range refit's). At least 1 so a topology
    /// buffer is never empty.
    pub fn topology_words(count: u32) -> u32 {
        (5 * count).saturating_sub(4).max(1)
    }

    /// Bytes of the largest scratch buffer a build of `count` triangles binds whole, whatever
    /// its strategy: a clustered build's `work` (the largest, about 68 bytes a triangle). A
    /// build whose scratch passes the device's largest storage binding cannot run.
    pub fn largest_build_binding_bytes(count: u32) -> u64 {
        4 * clustered_work_words(count)
            .max(work_words(count))
            .max(u64::from(Self::topology_words(count)))
    }

    /// Drops every scratch buffer (the next build allocates what it needs).
    pub fn release_scratch(&mut self) {
        for g in [
            &mut self.work,
            &mut self.keys,
            &mut self.values,
            &mut self.topology,
            &mut self.clustered_topology,
            &mut self.dummy,
            &mut self.pyramid_boxes,
            &mut self.batch_order,
            &mut self.compact_blocks,
        ] {
            g.release();
        }
        self.sort.release_scratch();
    }

    /// Scratch bytes currently held (grows with the largest build, until released).
    pub fn scratch_bytes(&self) -> u64 {
        self.work.bytes()
            + self.keys.bytes()
            + self.values.bytes()
            + self.topology.bytes()
            + self.clustered_topology.bytes()
            + self.dummy.bytes()
            + self.pyramid_boxes.bytes()
            + self.batch_order.bytes()
            + self.compact_blocks.bytes()
            + self.sort.scratch_bytes()
    }

    /// The flags word of the params.
    fn flags(leaf_refs: LeafRefs, bounds_out: bool) -> u32 {
        let mut f = 0;
        if leaf_refs == LeafRefs::PrimitiveIndex {
            f |= FLAG_PRIMITIVE_REFS;
        }
        if bounds_out {
            f |= FLAG_BOUNDS_OUT;
        }
        f
    }

    /// Zeroes the arrival counters of `n` primitives in `work` (before every climb).
    fn clear_arrivals(rec: &mut Recorder<'_>, work: &wgpu::Buffer, n: u32) {
        if n >= 2 {
            let inner = u64::from(n - 1);
            rec.encoder
                .clear_buffer(work, (BOXES_AT + 6 * inner) * 4, Some(inner * 4));
        }
    }
}
