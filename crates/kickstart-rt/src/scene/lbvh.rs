//! GPU LBVH (Karras 2012) over primitive AABBs, and its refit. Shaders: `shaders/lbvh.wgsl`;
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
//! the builder's scratch and step 6 is `hploc climb` instead (`shaders/hploc.wgsl`, workgroups of
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
//! pyramid over the sorted leaf boxes (`shaders/lbvh.wgsl`, "Range refit"). `lbvh refit gather`
//! gathers the triangles into sorted order, makes the pyramid's lowest 8 levels over each block of
//! 256 in workgroup memory, writes every node whose range lies inside its block, lists the others
//! and merges its top box into the levels above with atomics. `lbvh range refit` then writes the
//! listed nodes, which straddle blocks, walking each node's two children side by side. Two
//! passes, no arrival counters, fences or waiting, no chains of device-scope round trips from the
//! leaves to the root (what bounds the climb: docs/decisions/range-refit.md); the nodes are
//! bit-identical to the climb's. With [`RefitSource::Raw`], `lbvh refit ingest` takes the
//! gather's place and decodes the triangles from the application's bytes itself: the ingestion
//! fused into the refit.

use crate::gpu::reflect::{ReflectedPipeline, ShaderReflection};
use crate::gpu::Recorder;
use crate::scene::ingest::ROW_WORDS;
use bytemuck::{Pod, Zeroable};
use wgpu::util::DeviceExt;

use crate::gpu::radix_sort::RadixSort;

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
    /// 6 words in the encoding of `shaders/centroid_bounds.wgsl`, which that pass must include
    /// (same primitives counted, same words), so the build skips its `lbvh bounds` pass. `None`:
    /// the build computes them. The words must be ready (zeroed, then merged) before the build's
    /// passes run; the buffer needs STORAGE usage.
    pub centroid_bounds: Option<(&'a wgpu::Buffer, u32)>,
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

/// Component rows `lbvh refit ingest` takes (`REFIT_INGEST_ROWS` in `shaders/lbvh.wgsl`).
pub(crate) const REFIT_INGEST_ROWS: usize = 32;

/// Boxes of the box pyramid over `n` boxes (`shaders/lbvh.wgsl`, "Range refit"): level 0 (the
/// boxes), then `ceil(n / 2^L)` a level up to the level of one box.
pub(crate) fn pyramid_boxes(n: u32) -> u64 {
    let mut total = u64::from(n);
    let mut count = n;
    while count > 1 {
        count = count.div_ceil(2);
        total += u64::from(count);
    }
    total
}

/// Pyramid levels `lbvh refit gather` makes of each block of 256 in workgroup memory (the
/// shader's `REFIT_WG_LEVELS`).
#[cfg(test)]
const REFIT_GATHER_LEVELS: u32 = WORKGROUP.trailing_zeros();

/// The range refit's layout in `work` (`shaders/lbvh.wgsl`, above `straddle_list_at`), for `n`
/// triangles in `nb` blocks of 256: the straddling nodes' lists and counts, then the pyramid's
/// levels above the blocks' 8 (6 words a box; returned as the word range to clear). Returns
/// (words, that range).
fn range_refit_work(n: u32) -> (u64, std::ops::Range<u64>) {
    let nb = u64::from(n.div_ceil(WORKGROUP));
    let block = u64::from(WORKGROUP);
    let mut upper = 0;
    let mut count = nb;
    while count > 1 {
        count = count.div_ceil(2);
        upper += count;
    }
    let start = 8 + (block + 1) * nb;
    (start + 6 * upper, start..start + 6 * upper)
}

/// Boxes in level `level` of the pyramid over `n` boxes.
#[cfg(test)]
fn pyramid_level_count(n: u32, level: u32) -> u32 {
    (0..level).fold(n, |count, _| count.div_ceil(2))
}

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
    pad: [u32; 2],
    /// `lbvh refit gather`: first staged triangle.
    tri_src_base: u32,
    /// `lbvh refit gather`: first BLAS triangle.
    tri_dst_base: u32,
    /// `lbvh refit ingest`: component rows in use.
    ingest_row_count: u32,
    /// `lbvh refit ingest`: first of the geometry's two dropped-triangle counters.
    ingest_counter: u32,
}

/// A scratch buffer that only grows (recorded commands keep older buffers alive).
#[derive(Default)]
pub(crate) struct Grown {
    buffer: Option<wgpu::Buffer>,
}

impl Grown {
    /// A buffer of at least `size` bytes (at least 32, so every binding has a valid minimum).
    pub(crate) fn get(
        &mut self,
        device: &wgpu::Device,
        label: &'static str,
        size: u64,
    ) -> wgpu::Buffer {
        let size = size.max(32);
        if let Some(b) = &self.buffer {
            if b.size() >= size {
                return b.clone();
            }
        }
        // Round up so that slowly growing scenes do not reallocate on every build.
        let b = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: size.next_power_of_two(),
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.buffer = Some(b.clone());
        b
    }

    /// Bytes held.
    pub(crate) fn bytes(&self) -> u64 {
        self.buffer.as_ref().map_or(0, |b| b.size())
    }
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
}

/// Invocations of a `hploc_climb` workgroup (`HP_WG` in `shaders/hploc.wgsl`).
const HPLOC_WORKGROUP: u32 = 32;

/// Buffers of one dispatch by the shader's names for them (`shaders/lbvh.wgsl`,
/// `shaders/hploc.wgsl`): each pass binds those its entry point uses, at the binding numbers the
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

/// Words of the work buffer of a clustered build (`shaders/hploc.wgsl`): [`work_words`], then a
/// cluster count per Karras node, a cluster-list slot and a free-slot-list slot per primitive.
fn clustered_work_words(n: u32) -> u64 {
    work_words(n) + u64::from(n.saturating_sub(1)) + 2 * u64::from(n)
}

/// The `max_leaf` a dispatch uses: clamped to 1..=MAX_LEAF, and 1 for primitive-index refs
/// (a TLAS leaf's instances are not one range).
fn effective_max_leaf(max_leaf: u32, leaf_refs: LeafRefs) -> u32 {
    match leaf_refs {
        LeafRefs::SortedPosition => max_leaf.clamp(1, MAX_LEAF),
        LeafRefs::PrimitiveIndex => 1,
    }
}

impl Lbvh {
    /// Creates the pipelines (no buffers until the first build).
    pub fn new(device: &wgpu::Device) -> Self {
        let src = concat!(
            include_str!("../../shaders/digit_histogram.wgsl"),
            include_str!("../../shaders/centroid_bounds.wgsl"),
            include_str!("../../shaders/triangle_box.wgsl"),
            include_str!("../../shaders/ingest_decode.wgsl"),
            include_str!("../../shaders/lbvh.wgsl"),
            include_str!("../../shaders/hploc.wgsl")
        );
        let shader = ShaderReflection::new(src).expect("shaders/lbvh.wgsl is valid WGSL");
        let pipeline = |label, entry| ReflectedPipeline::new(device, label, src, &shader, entry);
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
            sort: RadixSort::new(device),
            work: Grown::default(),
            keys: Grown::default(),
            values: Grown::default(),
            topology: Grown::default(),
            clustered_topology: Grown::default(),
            dummy: Grown::default(),
            pyramid_boxes: Grown::default(),
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

    /// Scratch bytes currently held (grows with the largest build).
    pub fn scratch_bytes(&self) -> u64 {
        self.work.bytes()
            + self.keys.bytes()
            + self.values.bytes()
            + self.topology.bytes()
            + self.clustered_topology.bytes()
            + self.dummy.bytes()
            + self.pyramid_boxes.bytes()
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

    /// Records a build of `b.count` primitives (see the module docs for the passes).
    pub fn build(&mut self, rec: &mut Recorder<'_>, b: &LbvhBuild<'_>) {
        let n = b.count;
        if n > MAX_COUNT {
            log::error!("LBVH build of {n} primitives skipped: at most {MAX_COUNT} are supported");
            return;
        }
        // Below two primitives there is nothing to cluster: lbvh_climb writes the fixed root.
        // Primitive-index leaves (the TLAS's) cluster too; they are never collapsed.
        let clustered = b.clustered && n >= 2;
        let device = rec.device;
        let words = if clustered {
            clustered_work_words(n)
        } else {
            work_words(n)
        };
        let work = self.work.get(device, "lbvh work", words * 4);
        let keys = self.keys.get(device, "lbvh keys", u64::from(n) * 4);
        let values = self.values.get(device, "lbvh values", u64::from(n) * 4);
        let dummy = self.dummy.get(device, "lbvh no bounds", 32);
        let topo_bytes = u64::from(Self::topology_words(n)) * 4;
        // The output topology, and where the hierarchy pass writes the Karras tree: the same
        // place unless the build is clustered (then the builder's scratch, at base 0).
        let (topology, topo_base) = match b.topology {
            Some((t, base)) => (t.clone(), base),
            None if clustered => (
                self.clustered_topology
                    .get(device, "hploc topology", topo_bytes),
                0,
            ),
            None => (self.topology.get(device, "lbvh topology", topo_bytes), 0),
        };
        let (karras, karras_base) = if clustered {
            (self.topology.get(device, "lbvh topology", topo_bytes), 0)
        } else {
            (topology.clone(), topo_base)
        };
        let (bounds_out, bounds_base) = b.bounds_out.unwrap_or((&dummy, 0));
        let key_bits = b
            .key_bits
            .clamp(*KEY_BITS_RANGE.start(), *KEY_BITS_RANGE.end());
        let params_at = |topo_base: u32| Params {
            count: n,
            aabb_base: b.aabb_base,
            node_base: b.node_base,
            order_base: b.order_base,
            topo_base,
            bounds_base,
            flags: Self::flags(b.leaf_refs, b.bounds_out.is_some()),
            max_leaf: effective_max_leaf(b.max_leaf, b.leaf_refs),
            key_bits,
            centroid_base: b.centroid_bounds.map_or(0, |(_, base)| base),
            pad: [0; 2],
            tri_src_base: 0,
            tri_dst_base: 0,
            ingest_row_count: 0,
            ingest_counter: 0,
        };
        let params = rec.uniform("lbvh params", &params_at(topo_base));
        let karras_params = if clustered {
            rec.uniform("lbvh hierarchy params", &params_at(karras_base))
        } else {
            params.clone()
        };
        let mut bind: Buffers<'_> = vec![
            ("params", &karras_params),
            ("aabbs", b.aabbs),
            ("work", &work),
            ("keys", &keys),
            ("values", &values),
            ("order", b.order),
            // The hierarchy's Karras tree; `topo_out` is the clustered tree's topology.
            ("topology", &karras),
            ("nodes", b.nodes),
            ("bounds_out", bounds_out),
            ("topo_out", &topology),
        ];
        // Where the sorted pairs end up (the sort's scratch after an odd number of passes).
        let sorted;
        if n >= 2 {
            Self::clear_arrivals(rec, &work, n);
            let mut morton_bind = bind.clone();
            match b.centroid_bounds {
                // The caller's words take the work buffer's place in the morton pass.
                Some((given, _)) => morton_bind.push(("work", given)),
                None => {
                    // Centroid-bounds header (zero is the identity of the encoded atomicMax).
                    rec.encoder.clear_buffer(&work, 0, Some(BOXES_AT * 4));
                    let bg = self.bounds.bind_group(device, "lbvh", 0, &bind);
                    rec.dispatch("lbvh bounds", &self.bounds.pipeline, &[&bg], groups(n));
                }
            }
            // A sort of more than one workgroup takes its first histogram from the morton pass
            // (one dependent dispatch fewer).
            sorted = match self.sort.first_histogram(device, n, key_bits) {
                Some((hist, nblocks)) => {
                    morton_bind.push(("sort_hist", &hist));
                    let pass = &self.morton_histogram;
                    let bg = pass.bind_group(device, "lbvh", 0, &morton_bind);
                    rec.dispatch("lbvh morton", &pass.pipeline, &[&bg], nblocks);
                    self.sort
                        .record_after_first_histogram(rec, &keys, &values, n, key_bits)
                }
                None => {
                    let bg = self.morton.bind_group(device, "lbvh", 0, &morton_bind);
                    rec.dispatch("lbvh morton", &self.morton.pipeline, &[&bg], groups(n));
                    self.sort.record(rec, &keys, &values, n, key_bits)
                }
            };
            bind.push(("keys", &sorted.0));
            bind.push(("values", &sorted.1));
        }
        if n >= 1 {
            let bg = self.hierarchy.bind_group(device, "lbvh", 0, &bind);
            rec.dispatch(
                "lbvh hierarchy",
                &self.hierarchy.pipeline,
                &[&bg],
                groups(n),
            );
        }
        bind.push(("params", &params));
        if b.hierarchy_only {
            return;
        }
        if clustered {
            let bg = self.hploc.bind_group(device, "lbvh", 0, &bind);
            rec.dispatch(
                "hploc climb",
                &self.hploc.pipeline,
                &[&bg],
                n.div_ceil(HPLOC_WORKGROUP).max(1),
            );
        } else {
            let bg = self.climb.bind_group(device, "lbvh", 0, &bind);
            rec.dispatch("lbvh climb", &self.climb.pipeline, &[&bg], groups(n));
        }
    }

    /// Records a refit: new boxes over the topology of an earlier build with the same count.
    pub fn refit(&mut self, rec: &mut Recorder<'_>, r: &LbvhRefit<'_>) {
        let n = r.count;
        if n > MAX_COUNT {
            log::error!("LBVH refit of {n} primitives skipped: at most {MAX_COUNT} are supported");
            return;
        }
        let device = rec.device;
        let work = self.work.get(device, "lbvh work", work_words(n) * 4);
        let dummy = self.dummy.get(device, "lbvh no bounds", 32);
        let (bounds_out, bounds_base) = r.bounds_out.unwrap_or((&dummy, 0));
        let mut flags = Self::flags(r.leaf_refs, r.bounds_out.is_some());
        if r.sorted_boxes {
            flags |= FLAG_SORTED_BOXES;
        }
        let params = rec.uniform(
            "lbvh params",
            &Params {
                count: n,
                aabb_base: r.aabb_base,
                node_base: r.node_base,
                order_base: r.order_base,
                topo_base: r.topology.1,
                bounds_base,
                flags,
                max_leaf: effective_max_leaf(r.max_leaf, r.leaf_refs),
                ..Params::zeroed()
            },
        );
        let bind: Buffers<'_> = vec![
            ("params", &params),
            ("aabbs", r.aabbs),
            ("work", &work),
            ("order", r.order),
            ("topology", r.topology.0),
            ("nodes", r.nodes),
            ("bounds_out", bounds_out),
        ];
        Self::clear_arrivals(rec, &work, n);
        let bg = self.climb.bind_group(device, "lbvh", 0, &bind);
        rec.dispatch("lbvh refit", &self.climb.pipeline, &[&bg], groups(n));
    }

    /// Records the range refit of a BLAS (see the module docs): `lbvh refit gather`, then
    /// `lbvh range refit` when there is more than one block of 256 triangles. Counts below 2 are
    /// skipped with an error (a refit's tree has inner nodes).
    pub fn refit_triangles(&mut self, rec: &mut Recorder<'_>, r: &LbvhTriangleRefit<'_>) {
        let n = r.count;
        if !(2..=MAX_COUNT).contains(&n) {
            log::error!("LBVH range refit of {n} triangles skipped: it needs 2..={MAX_COUNT}");
            return;
        }
        if let RefitSource::Raw(raw) = &r.source {
            if !Self::can_refit_from_raw(n, raw.rows) {
                log::error!(
                    "LBVH range refit of {n} triangles ({} component rows) from raw bytes skipped: \
                     it needs more than {WORKGROUP} triangles and at most {REFIT_INGEST_ROWS} rows",
                    raw.rows.len() / ROW_WORDS
                );
                return;
            }
        }
        let device = rec.device;
        let (words, upper) = range_refit_work(n);
        let work = self
            .work
            .get(device, "lbvh work", words.max(work_words(n)) * 4);
        let dummy = self.dummy.get(device, "lbvh no bounds", 32);
        let pyramid = self.pyramid_boxes.get(
            device,
            "lbvh box pyramid",
            (pyramid_boxes(n) - u64::from(n)) * 32,
        );
        let (bounds_out, bounds_base) = r.bounds_out.unwrap_or((&dummy, 0));
        // Staged triangles, or raw bytes with their rows (padded to the shader's fixed-length
        // uniform array) and the counters.
        let (src_base, ingest_row_count, ingest_counter) = match &r.source {
            RefitSource::Staged { base, .. } => (*base, 0, 0),
            RefitSource::Raw(t) => (0, (t.rows.len() / ROW_WORDS) as u32, t.counter_base),
        };
        let rows = match &r.source {
            RefitSource::Staged { .. } => None,
            RefitSource::Raw(t) => {
                let mut table = t.rows.to_vec();
                table.resize(REFIT_INGEST_ROWS * ROW_WORDS, 0);
                Some(
                    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                        label: Some("lbvh refit ingest rows"),
                        contents: bytemuck::cast_slice(&table),
                        usage: wgpu::BufferUsages::UNIFORM,
                    }),
                )
            }
        };
        let params = rec.uniform(
            "lbvh params",
            &Params {
                count: n,
                node_base: r.node_base,
                order_base: r.order_base,
                topo_base: r.topology.1,
                bounds_base,
                flags: Self::flags(LeafRefs::SortedPosition, r.bounds_out.is_some()),
                max_leaf: 1,
                tri_src_base: src_base,
                tri_dst_base: r.dst_base,
                ingest_row_count,
                ingest_counter,
                ..Params::zeroed()
            },
        );
        let mut bind: Buffers<'_> = vec![
            ("params", &params),
            ("work", &work),
            ("order", r.order),
            ("topology", r.topology.0),
            ("nodes", r.nodes),
            ("bounds_out", bounds_out),
            ("pyramid", &pyramid),
            ("refit_dst", r.dst),
            // The work buffer again, read-only, for the range pass.
            ("work_read", &work),
        ];
        if let RefitSource::Staged { triangles, .. } = &r.source {
            bind.push(("refit_src", triangles));
        }
        if let (RefitSource::Raw(t), Some(rows)) = (&r.source, &rows) {
            bind.extend([
                ("raw", t.raw),
                ("ingest_rows", rows),
                ("ingest_counters", t.counters),
            ]);
        }
        if !upper.is_empty() {
            rec.encoder
                .clear_buffer(&work, upper.start * 4, Some((upper.end - upper.start) * 4));
        }
        let (label, first) = if rows.is_some() {
            ("lbvh refit ingest", &self.refit_ingest)
        } else {
            ("lbvh refit gather", &self.refit_gather)
        };
        let bg = first.bind_group(device, "lbvh", 0, &bind);
        rec.dispatch(label, &first.pipeline, &[&bg], groups(n));
        // Up to one block every node lies inside it: the gather wrote them all.
        if n > WORKGROUP {
            let bg = self.range_refit.bind_group(device, "lbvh", 0, &bind);
            rec.dispatch(
                "lbvh range refit",
                &self.range_refit.pipeline,
                &[&bg],
                groups(n),
            );
        }
    }

    /// Whether [`RefitSource::Raw`] can refit `n` triangles of these component rows: more than
    /// one block (the fused pass leaves the root's box to the range pass) and at most
    /// [`REFIT_INGEST_ROWS`] rows.
    pub fn can_refit_from_raw(n: u32, rows: &[u32]) -> bool {
        n > WORKGROUP && rows.len() <= REFIT_INGEST_ROWS * ROW_WORDS && !rows.is_empty()
    }
}

/// The centroid-bounds words (`shaders/centroid_bounds.wgsl`) of stored boxes `(min, max)`, as
/// the GPU merges them: the CPU oracle of both passes that merge them.
#[cfg(test)]
pub(crate) fn cpu_centroid_bounds(boxes: impl Iterator<Item = ([f32; 3], [f32; 3])>) -> [u32; 6] {
    // A float as a u32 that sorts like it (the shader's `enc`).
    let enc = |x: f32| {
        let b = x.to_bits();
        if b & 0x8000_0000 != 0 {
            !b
        } else {
            b | 0x8000_0000
        }
    };
    let mut words = [0u32; 6];
    for (lo, hi) in boxes {
        let empty = lo.iter().chain(&hi).any(|v| v.is_nan()) || lo[0] > hi[0];
        let c: [f32; 3] = std::array::from_fn(|a| lo[a] * 0.5 + hi[a] * 0.5);
        if empty || c.iter().any(|v| !v.is_finite()) {
            continue;
        }
        for a in 0..3 {
            words[a] = words[a].max(!enc(c[a]));
            words[3 + a] = words[3 + a].max(enc(c[a]));
        }
    }
    words
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cpu::{CpuBvh, SAH_INTERSECTION_COST, SAH_TRAVERSAL_COST};
    use crate::gpu::testing::{buffer_with, gpu, read_back, run};
    use crate::scene::ingest::{component_rows, ComponentIngest, Ingest};
    use glam::Vec3;

    /// A primitive box (min, max) as the AABB input holds it.
    type Aabb = ([f32; 3], [f32; 3]);

    /// The documented empty box.
    const EMPTY: Aabb = ([1e30; 3], [-1e30; 3]);
    /// Fill of every output word the builder must not touch.
    const SENTINEL: u32 = 0xDEAD_BEEF;

    /// Deterministic xorshift64* for test data.
    struct Rng(u64);

    impl Rng {
        fn next_u32(&mut self) -> u32 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 32) as u32
        }
        fn f(&mut self) -> f32 {
            (self.next_u32() >> 8) as f32 / (1u32 << 24) as f32
        }
        fn range(&mut self, lo: f32, hi: f32) -> f32 {
            lo + (hi - lo) * self.f()
        }
        fn vec(&mut self, lo: f32, hi: f32) -> [f32; 3] {
            [self.range(lo, hi), self.range(lo, hi), self.range(lo, hi)]
        }
    }

    fn random_box(rng: &mut Rng) -> Aabb {
        let c = rng.vec(-10.0, 10.0);
        let h = rng.vec(0.0, 1.0);
        (
            [c[0] - h[0], c[1] - h[1], c[2] - h[2]],
            [c[0] + h[0], c[1] + h[1], c[2] + h[2]],
        )
    }

    /// Empty as the builder defines it: min.x > max.x or any NaN.
    fn is_empty(b: &Aabb) -> bool {
        b.0.iter().chain(b.1.iter()).any(|v| v.is_nan()) || b.0[0] > b.1[0]
    }

    fn union(a: Option<Aabb>, b: Option<Aabb>) -> Option<Aabb> {
        match (a, b) {
            (Some(a), Some(b)) => Some((
                [0, 1, 2].map(|i| a.0[i].min(b.0[i])),
                [0, 1, 2].map(|i| a.1[i].max(b.1[i])),
            )),
            (a, None) => a,
            (None, b) => b,
        }
    }

    /// The box as the nodes store it: empty (None) → (+1e30, −1e30).
    fn stored(b: Option<Aabb>) -> Aabb {
        b.unwrap_or(EMPTY)
    }

    fn words_to_box(w: &[u32]) -> Aabb {
        (
            [0, 1, 2].map(|i| f32::from_bits(w[i])),
            [4, 5, 6].map(|i| f32::from_bits(w[i])),
        )
    }

    fn area(b: &Aabb) -> f64 {
        let d = [0, 1, 2].map(|i| f64::from((b.1[i] - b.0[i]).max(0.0)));
        2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0])
    }

    /// Where one test build puts things (all bases non-zero to catch offset mistakes).
    #[derive(Clone, Copy)]
    struct Bases {
        aabb: u32,
        node: u32,
        order: u32,
        topo: u32,
        bounds: u32,
    }

    const BASES: Bases = Bases {
        aabb: 3,
        node: 5,
        order: 7,
        topo: 11,
        bounds: 2,
    };

    /// GPU buffers of one test BVH and what was read back.
    struct GpuTree {
        n: u32,
        bases: Bases,
        leaf_refs: LeafRefs,
        max_leaf: u32,
        nodes: wgpu::Buffer,
        order: wgpu::Buffer,
        topology: wgpu::Buffer,
        bounds: wgpu::Buffer,
        node_words: Vec<u32>,
        order_words: Vec<u32>,
    }

    fn words(data: &[u8]) -> Vec<u32> {
        bytemuck::cast_slice(data).to_vec()
    }

    fn sentinel_buffer(words: u64) -> wgpu::Buffer {
        buffer_with(bytemuck::cast_slice(&vec![SENTINEL; words as usize]))
    }

    /// The AABB buffer: `bases.aabb` junk primitives, then `aabbs`, then one more junk.
    fn aabb_buffer(aabbs: &[Aabb], base: u32) -> wgpu::Buffer {
        let junk = ([-5e3f32; 3], [5e3f32; 3]);
        let mut data: Vec<f32> = Vec::new();
        let all = std::iter::repeat_n(&junk, base as usize)
            .chain(aabbs.iter())
            .chain(std::iter::once(&junk));
        for b in all {
            data.extend_from_slice(&[b.0[0], b.0[1], b.0[2], 0.0, b.1[0], b.1[1], b.1[2], 0.0]);
        }
        buffer_with(bytemuck::cast_slice(&data))
    }

    /// Asserts every word outside `[start, start + len)` is still the sentinel.
    fn assert_untouched(all: &[u32], start: usize, len: usize, what: &str) {
        for (i, &w) in all.iter().enumerate() {
            if i < start || i >= start + len {
                assert_eq!(
                    w, SENTINEL,
                    "{what}: word {i} outside [{start}, +{len}) written"
                );
            }
        }
    }

    fn read_words(b: &wgpu::Buffer) -> Vec<u32> {
        words(&read_back(b, 0, b.size()))
    }

    /// Builds over `aabbs` on the GPU (one primitive per leaf), checks everything and returns
    /// the tree and its SAH cost.
    fn build_and_check(lbvh: &mut Lbvh, aabbs: &[Aabb], leaf_refs: LeafRefs) -> (GpuTree, f64) {
        build_and_check_leaves(lbvh, aabbs, leaf_refs, 1)
    }

    /// [`build_and_check`] with leaves collapsed up to `max_leaf` primitives.
    fn build_and_check_leaves(
        lbvh: &mut Lbvh,
        aabbs: &[Aabb],
        leaf_refs: LeafRefs,
        max_leaf: u32,
    ) -> (GpuTree, f64) {
        build_and_check_with(lbvh, aabbs, leaf_refs, max_leaf, BLAS_KEY_BITS)
    }

    /// [`build_and_check_leaves`] with sort keys of `key_bits` bits.
    fn build_and_check_with(
        lbvh: &mut Lbvh,
        aabbs: &[Aabb],
        leaf_refs: LeafRefs,
        max_leaf: u32,
        key_bits: u32,
    ) -> (GpuTree, f64) {
        build_and_check_opts(lbvh, aabbs, leaf_refs, max_leaf, key_bits, false)
    }

    /// A clustered BLAS build (`hploc climb`) over `aabbs`, checked like every build.
    fn build_and_check_clustered(lbvh: &mut Lbvh, aabbs: &[Aabb], max_leaf: u32) -> (GpuTree, f64) {
        let refs = LeafRefs::SortedPosition;
        build_and_check_opts(lbvh, aabbs, refs, max_leaf, BLAS_KEY_BITS, true)
    }

    /// A clustered build with primitive-index leaves (the TLAS's), checked like every build.
    fn build_and_check_clustered_refs(lbvh: &mut Lbvh, aabbs: &[Aabb]) -> (GpuTree, f64) {
        let refs = LeafRefs::PrimitiveIndex;
        build_and_check_opts(lbvh, aabbs, refs, 1, TLAS_KEY_BITS, true)
    }

    /// [`build_and_check_with`], clustered or not.
    fn build_and_check_opts(
        lbvh: &mut Lbvh,
        aabbs: &[Aabb],
        leaf_refs: LeafRefs,
        max_leaf: u32,
        key_bits: u32,
        clustered: bool,
    ) -> (GpuTree, f64) {
        let bases = BASES;
        let n = aabbs.len() as u32;
        let node_count = u64::from(Lbvh::node_count(n));
        let topo_words = u64::from(Lbvh::topology_words(n));
        let input = aabb_buffer(aabbs, bases.aabb);
        let tree = GpuTree {
            n,
            bases,
            leaf_refs,
            max_leaf,
            nodes: sentinel_buffer((u64::from(bases.node) + node_count + 1) * 16),
            order: sentinel_buffer(u64::from(bases.order + n) + 1),
            topology: sentinel_buffer(u64::from(bases.topo) + topo_words + 1),
            bounds: sentinel_buffer((u64::from(bases.bounds) + 3) * 4),
            node_words: Vec::new(),
            order_words: Vec::new(),
        };
        run(|rec| {
            lbvh.build(
                rec,
                &LbvhBuild {
                    aabbs: &input,
                    aabb_base: bases.aabb,
                    count: n,
                    nodes: &tree.nodes,
                    node_base: bases.node,
                    order: &tree.order,
                    order_base: bases.order,
                    topology: Some((&tree.topology, bases.topo)),
                    leaf_refs,
                    max_leaf,
                    bounds_out: Some((&tree.bounds, bases.bounds)),
                    key_bits,
                    centroid_bounds: None,
                    clustered,
                    hierarchy_only: false,
                },
            )
        });
        let topo = read_words(&tree.topology);
        assert_untouched(
            &topo,
            bases.topo as usize,
            if n >= 2 { topo_words as usize } else { 0 },
            "topology",
        );
        if n >= 2 {
            check_parent_refs(&topo[bases.topo as usize..], n, clustered);
        }
        check_read_back(tree, aabbs, true)
    }

    /// Every parent ref in the topology names the node that lists the child, with the
    /// block-local bit exactly when the parent's leaves lie in one block of `WORKGROUP` sorted
    /// positions (the climb's workgroup-memory phase relies on it; a wrong bit deadlocks a node's
    /// two climbers or only slows the climb). A clustered tree's node indices say nothing of
    /// blocks: the bit is never set there.
    fn check_parent_refs(topo: &[u32], n: u32, clustered: bool) {
        const LEAF: u32 = 0x8000_0000;
        const LOCAL: u32 = 0x4000_0000;
        let inner = (n - 1) as usize;
        // Leaf range of every inner node, children before parents (iterative post-order).
        let mut range = vec![(u32::MAX, 0u32); inner];
        let mut stack = vec![(0usize, false)];
        while let Some((i, children_done)) = stack.pop() {
            let kids = [topo[2 * i], topo[2 * i + 1]];
            if children_done {
                let r = kids.map(|c| {
                    if c & LEAF != 0 {
                        (c & !LEAF, c & !LEAF)
                    } else {
                        range[c as usize]
                    }
                });
                range[i] = (r[0].0.min(r[1].0), r[0].1.max(r[1].1));
                continue;
            }
            stack.push((i, true));
            stack.extend(
                kids.iter()
                    .filter(|&&c| c & LEAF == 0)
                    .map(|&c| (c as usize, false)),
            );
        }
        assert_eq!(topo[2 * inner], u32::MAX, "root's parent ref");
        for (i, &(first, last)) in range.iter().enumerate() {
            let local = !clustered && first / WORKGROUP == last / WORKGROUP;
            let expected = i as u32 | if local { LOCAL } else { 0 };
            for c in [topo[2 * i], topo[2 * i + 1]] {
                let at = if c & LEAF != 0 {
                    3 * inner + (c & !LEAF) as usize
                } else {
                    2 * inner + c as usize
                };
                assert_eq!(
                    topo[at], expected,
                    "parent ref of child {c:#x} of node {i} {first}..={last}"
                );
            }
        }
    }

    /// `b` moved by `d`.
    fn shifted(b: &Aabb, d: [f32; 3]) -> Aabb {
        (
            [0, 1, 2].map(|a| b.0[a] + d[a]),
            [0, 1, 2].map(|a| b.1[a] + d[a]),
        )
    }

    /// Refits `tree` (as built) to the primitive boxes `after`, collapsing up to `max_leaf`.
    fn refit_to(lbvh: &mut Lbvh, tree: &GpuTree, after: &[Aabb], max_leaf: u32) {
        refit_to_with(lbvh, tree, after, max_leaf, false);
    }

    /// [`refit_to`], the boxes given in sorted order (`after[order[k]]` at `k`) when
    /// `sorted_boxes`, as a BLAS refit's gather writes them.
    fn refit_to_with(
        lbvh: &mut Lbvh,
        tree: &GpuTree,
        after: &[Aabb],
        max_leaf: u32,
        sorted_boxes: bool,
    ) {
        let input = if sorted_boxes {
            let sorted: Vec<Aabb> = tree
                .order_words
                .iter()
                .map(|&p| after[p as usize])
                .collect();
            aabb_buffer(&sorted, tree.bases.aabb)
        } else {
            aabb_buffer(after, tree.bases.aabb)
        };
        run(|rec| {
            lbvh.refit(
                rec,
                &LbvhRefit {
                    aabbs: &input,
                    aabb_base: tree.bases.aabb,
                    count: tree.n,
                    nodes: &tree.nodes,
                    node_base: tree.bases.node,
                    order: &tree.order,
                    order_base: tree.bases.order,
                    topology: (&tree.topology, tree.bases.topo),
                    leaf_refs: tree.leaf_refs,
                    max_leaf,
                    bounds_out: Some((&tree.bounds, tree.bases.bounds)),
                    sorted_boxes,
                },
            )
        });
    }

    /// Reads back nodes, order and bounds of `tree` and checks them against `aabbs`.
    fn check_read_back(mut tree: GpuTree, aabbs: &[Aabb], empties_last: bool) -> (GpuTree, f64) {
        let n = tree.n;
        let b = tree.bases;
        let node_words = read_words(&tree.nodes);
        assert_untouched(
            &node_words,
            b.node as usize * 16,
            Lbvh::node_count(n) as usize * 16,
            "nodes",
        );
        let order_words = read_words(&tree.order);
        assert_untouched(&order_words, b.order as usize, n as usize, "order");
        let bounds = read_words(&tree.bounds);
        assert_untouched(&bounds, b.bounds as usize * 4, 8, "bounds_out");
        tree.node_words =
            node_words[b.node as usize * 16..][..Lbvh::node_count(n) as usize * 16].to_vec();
        tree.order_words = order_words[b.order as usize..][..n as usize].to_vec();
        let (root, sah) = check_tree(
            aabbs,
            &tree.node_words,
            &tree.order_words,
            tree.leaf_refs,
            empties_last,
            effective_max_leaf(tree.max_leaf, tree.leaf_refs),
        );
        let bw = &bounds[b.bounds as usize * 4..][..8];
        assert_eq!(words_to_box(bw), stored(root), "bounds_out is the union");
        assert_eq!((bw[3], bw[7]), (0, 0), "bounds_out w");
        (tree, sah)
    }

    /// State of the recursive tree check.
    struct Walk<'a> {
        /// (ref, box as stored) of a node's left (false) or right (true) child.
        child: &'a dyn Fn(usize, bool) -> (u32, Aabb),
        /// Primitive boxes (None: empty).
        boxes: &'a [Option<Aabb>],
        order: &'a [u32],
        leaf_refs: LeafRefs,
        /// Largest leaf allowed.
        max_leaf: u32,
        /// Primitives found in a leaf.
        seen: Vec<bool>,
        /// Inner nodes reached.
        visited: Vec<bool>,
        /// Every child's stored box and its primitive count (0: inner), for the SAH.
        children: Vec<(Aabb, u32)>,
    }

    impl Walk<'_> {
        /// Checks the subtree of inner node `node`; returns its exact box (None: empty).
        fn visit(&mut self, node: usize) -> Option<Aabb> {
            assert!(!self.visited[node], "inner node {node} reached twice");
            self.visited[node] = true;
            let mut total = None;
            for right in [false, true] {
                let (r, stored_box) = (self.child)(node, right);
                let leaf = r & 0x8000_0000 != 0;
                let count = if leaf { ((r >> 28) & 7) + 1 } else { 0 };
                let subtree = if leaf {
                    assert!(
                        count <= self.max_leaf,
                        "leaf {r:#x}: more than {}",
                        self.max_leaf
                    );
                    let first = (r & 0x0fff_ffff) as usize;
                    assert!(
                        first + count as usize <= self.boxes.len(),
                        "leaf ref {r:#x} out of range"
                    );
                    let mut b = None;
                    for k in first..first + count as usize {
                        let prim = match self.leaf_refs {
                            LeafRefs::SortedPosition => self.order[k] as usize,
                            LeafRefs::PrimitiveIndex => k,
                        };
                        assert!(!self.seen[prim], "primitive {prim} in two leaves");
                        self.seen[prim] = true;
                        b = union(b, self.boxes[prim]);
                    }
                    b
                } else {
                    assert!(
                        (r as usize) < self.visited.len(),
                        "inner ref {r} out of range"
                    );
                    self.visit(r as usize)
                };
                assert_eq!(
                    stored_box,
                    stored(subtree),
                    "node {node} child {right}: exact union"
                );
                self.children.push((stored_box, count));
                total = union(total, subtree);
            }
            total
        }
    }

    /// Checks a read-back tree: structure, exact boxes, leaf refs. Returns the root box (None:
    /// empty) and the SAH cost computed like `CpuBvh::sah_cost`.
    fn check_tree(
        aabbs: &[Aabb],
        nodes: &[u32],
        order: &[u32],
        leaf_refs: LeafRefs,
        empties_last: bool,
        max_leaf: u32,
    ) -> (Option<Aabb>, f64) {
        let n = aabbs.len();
        let boxes: Vec<Option<Aabb>> = aabbs.iter().map(|b| (!is_empty(b)).then_some(*b)).collect();
        // order: a permutation, empty primitives last.
        let mut sorted = order.to_vec();
        sorted.sort_unstable();
        assert!(
            sorted.iter().copied().eq(0..n as u32),
            "order is a permutation"
        );
        let valid = boxes.iter().filter(|b| b.is_some()).count();
        for (k, &p) in order.iter().enumerate() {
            if empties_last {
                assert_eq!(
                    boxes[p as usize].is_none(),
                    k >= valid,
                    "empties sort last ({k})"
                );
            }
        }
        let child = |node: usize, right: bool| -> (u32, Aabb) {
            let w = &nodes[node * 16..][..16];
            let (r, b) = if right {
                (w[7], [&w[8..11], &w[12..15]].concat())
            } else {
                (w[3], [&w[0..3], &w[4..7]].concat())
            };
            assert_eq!((w[11], w[15]), (0, 0), "node {node}: w of entries 2 and 3");
            (r, words_to_box(&[b[0], b[1], b[2], 0, b[3], b[4], b[5], 0]))
        };
        if n < 2 {
            let (lr, lb) = child(0, false);
            let (rr, rb) = child(0, true);
            assert_eq!(
                (rr, rb),
                (0x8000_0000, EMPTY),
                "right child of a small root"
            );
            assert_eq!(lr, 0x8000_0000, "left child ref of a small root");
            let root = boxes.first().copied().flatten();
            assert_eq!(lb, stored(root));
            return (root, 1.0);
        }
        let mut walk = Walk {
            child: &child,
            boxes: &boxes,
            order,
            leaf_refs,
            max_leaf,
            seen: vec![false; n],
            visited: vec![false; n - 1],
            children: Vec::new(),
        };
        let root = walk.visit(0);
        // Collapsed subtrees' inner nodes stay in the buffer, unreferenced.
        assert!(
            max_leaf > 1 || walk.visited.iter().all(|&v| v),
            "every inner node reachable"
        );
        assert!(walk.seen.iter().all(|&s| s), "every primitive in a leaf");
        // As CpuBvh::sah_cost: the root, then every child (inner: traversal cost; leaf: one
        // intersection per primitive), areas relative to the root's.
        let ra = area(&stored(root)).max(f64::from(f32::MIN_POSITIVE));
        let sah = f64::from(SAH_TRAVERSAL_COST)
            + walk
                .children
                .iter()
                .map(|&(b, count)| {
                    let cost = if count > 0 {
                        f64::from(SAH_INTERSECTION_COST) * f64::from(count)
                    } else {
                        f64::from(SAH_TRAVERSAL_COST)
                    };
                    area(&b) / ra * cost
                })
                .sum::<f64>();
        (root, sah)
    }

    #[test]
    fn lbvh_tiny_counts_both_leaf_refs() {
        let mut lbvh = Lbvh::new(&gpu().device);
        let mut rng = Rng(7);
        for n in 0..=3 {
            let aabbs: Vec<Aabb> = (0..n).map(|_| random_box(&mut rng)).collect();
            for refs in [LeafRefs::SortedPosition, LeafRefs::PrimitiveIndex] {
                build_and_check(&mut lbvh, &aabbs, refs);
            }
        }
        // One empty primitive, two identical ones, an empty and a real one.
        let b = random_box(&mut rng);
        for aabbs in [vec![EMPTY], vec![b, b], vec![EMPTY, b], vec![b, EMPTY, b]] {
            build_and_check(&mut lbvh, &aabbs, LeafRefs::PrimitiveIndex);
        }
    }

    #[test]
    fn lbvh_random_1000_both_leaf_refs() {
        let mut lbvh = Lbvh::new(&gpu().device);
        let mut rng = Rng(1000);
        let aabbs: Vec<Aabb> = (0..1000).map(|_| random_box(&mut rng)).collect();
        for refs in [LeafRefs::SortedPosition, LeafRefs::PrimitiveIndex] {
            build_and_check(&mut lbvh, &aabbs, refs);
        }
    }

    /// ~20k primitives: many identical boxes (equal Morton keys), flat boxes, several kinds of
    /// empty ones (documented empty, min.x > max.x only, NaN lanes), a few huge ones.
    fn hard_soup(n: usize, seed: u64) -> Vec<Aabb> {
        let mut rng = Rng(seed);
        let dups: Vec<Aabb> = (0..4).map(|_| random_box(&mut rng)).collect();
        (0..n)
            .map(|i| match rng.next_u32() % 10 {
                0..=3 => dups[i % dups.len()],
                4 => {
                    let mut b = random_box(&mut rng);
                    b.1[i % 3] = b.0[i % 3]; // flat
                    b
                }
                5 => match i % 4 {
                    0 => EMPTY,
                    1 => ([1.0, 0.0, 0.0], [0.0, 1.0, 1.0]),
                    2 => ([0.0, f32::NAN, 0.0], [1.0, 1.0, 1.0]),
                    _ => ([0.0, 0.0, 0.0], [1.0, 1.0, f32::NAN]),
                },
                6 if i % 97 == 0 => ([-1e6, -1e6, 0.0], [1e6, 1e6, 0.0]),
                _ => random_box(&mut rng),
            })
            .collect()
    }

    #[test]
    fn lbvh_20k_duplicates_flat_and_empty() {
        let mut lbvh = Lbvh::new(&gpu().device);
        let aabbs = hard_soup(20_011, 20);
        build_and_check(&mut lbvh, &aabbs, LeafRefs::SortedPosition);
        // All identical, and all empty.
        let same = vec![([1.0, 2.0, 3.0], [1.0, 2.5, 3.0]); 3000];
        build_and_check(&mut lbvh, &same, LeafRefs::PrimitiveIndex);
        build_and_check(&mut lbvh, &vec![EMPTY; 700], LeafRefs::SortedPosition);
    }

    #[test]
    fn lbvh_three_builds_in_one_encoder_grow_scratch() {
        // Each build needs more scratch than the one before, and the TLAS-key builds (3 sort
        // passes) leave their sorted pairs in the sort's scratch, which the next build's sort
        // overwrites or replaces: every build must still be correct.
        let mut lbvh = Lbvh::new(&gpu().device);
        let sets = [
            (hard_soup(300, 1), BLAS_KEY_BITS),
            (hard_soup(5000, 2), TLAS_KEY_BITS),
            (hard_soup(9000, 3), TLAS_KEY_BITS),
        ];
        let n = sets.each_ref().map(|(a, _)| a.len() as u32);
        let inputs = sets.each_ref().map(|(a, _)| aabb_buffer(a, 0));
        let nodes = n.map(|n| sentinel_buffer(u64::from(Lbvh::node_count(n)) * 16));
        let order = n.map(|n| sentinel_buffer(u64::from(n)));
        run(|rec| {
            for i in 0..sets.len() {
                lbvh.build(
                    rec,
                    &LbvhBuild {
                        aabbs: &inputs[i],
                        aabb_base: 0,
                        count: n[i],
                        nodes: &nodes[i],
                        node_base: 0,
                        order: &order[i],
                        order_base: 0,
                        topology: None,
                        leaf_refs: LeafRefs::SortedPosition,
                        max_leaf: 1,
                        bounds_out: None,
                        key_bits: sets[i].1,
                        centroid_bounds: None,
                        clustered: false,
                        hierarchy_only: false,
                    },
                );
            }
        });
        // Scratch covers the largest build (work words, keys, values, topology).
        assert!(lbvh.scratch_bytes() >= 4 * (10 * 9000 + 2 * 9000 + 4 * 9000));
        for (i, (aabbs, _)) in sets.iter().enumerate() {
            check_tree(
                aabbs,
                &read_words(&nodes[i]),
                &read_words(&order[i]),
                LeafRefs::SortedPosition,
                true,
                1,
            );
        }
    }

    /// The sort key `lbvh_morton` makes for cells `c` with `key_bits`: the Morton code of
    /// `min(key_bits / 3, 10)` bits per axis (x in the highest bit of each triple), below the
    /// all-ones key of empty primitives.
    fn morton_key(c: [u32; 3], key_bits: u32) -> u32 {
        let mut key = 0;
        for b in 0..(key_bits / 3).min(10) {
            for (axis, shift) in [(0, 2), (1, 1), (2, 0)] {
                key |= ((c[axis] >> b) & 1) << (3 * b + shift);
            }
        }
        key.min(empty_key(key_bits) - 1)
    }

    fn empty_key(key_bits: u32) -> u32 {
        (1 << key_bits) - 1
    }

    /// Boxes whose centroids sit at cell centres of the grid of `key_bits` keys over
    /// `[0, cells]` per axis (two anchors at the corners fix the centroid bounds), so every cell
    /// is exact in f32 and the GPU's keys can be predicted: random cells, many primitives
    /// sharing a cell (equal keys), empty ones, and the far corner cell (whose code is lowered
    /// when the Morton bits fill the key). Returns the boxes and each one's expected key.
    fn grid_boxes(n: usize, key_bits: u32, seed: u64) -> (Vec<Aabb>, Vec<u32>) {
        let mut rng = Rng(seed);
        let g = 1u32 << (key_bits / 3).min(10);
        let half = 0.25f32;
        let at = |c: [f32; 3]| -> Aabb { (c.map(|v| v - half), c.map(|v| v + half)) };
        let mut boxes = vec![at([0.0; 3]), at([g as f32; 3])];
        let mut keys = vec![0, morton_key([g - 1; 3], key_bits)];
        let shared: Vec<[u32; 3]> = (0..5)
            .map(|_| [0; 3].map(|_| rng.next_u32() % g))
            .chain([[g - 1, g - 1, g - 2], [g - 1; 3]]) // the corner and its Morton neighbour
            .collect();
        while boxes.len() < n {
            let cell = match rng.next_u32() % 8 {
                0 => {
                    boxes.push(if boxes.len() % 2 == 0 {
                        EMPTY
                    } else {
                        ([f32::NAN, 0.0, 0.0], [1.0; 3])
                    });
                    keys.push(empty_key(key_bits));
                    continue;
                }
                1..=2 => shared[rng.next_u32() as usize % shared.len()],
                _ => [0; 3].map(|_| rng.next_u32() % g),
            };
            boxes.push(at(cell.map(|c| c as f32 + 0.5)));
            keys.push(morton_key(cell, key_bits));
        }
        (boxes, keys)
    }

    #[test]
    fn lbvh_order_is_the_stable_sort_of_the_morton_keys_of_every_key_width() {
        // TLAS keys (24 bits, 8 per axis: 3 sort passes ending in the sort's scratch, the
        // corner cell lowered), BLAS keys (31 bits, 10 per axis and a spare bit: 4 passes),
        // 4 bits (one pass), and the one-workgroup sort below 1025 primitives: the order must be
        // exactly the stable sort of the predicted keys (equal keys in primitive order, empties
        // last).
        let mut lbvh = Lbvh::new(&gpu().device);
        for (n, bits, refs) in [
            (6000, TLAS_KEY_BITS, LeafRefs::PrimitiveIndex),
            (4100, BLAS_KEY_BITS, LeafRefs::SortedPosition),
            (3000, 4, LeafRefs::PrimitiveIndex),
            (900, TLAS_KEY_BITS, LeafRefs::PrimitiveIndex),
        ] {
            let (boxes, keys) = grid_boxes(n, bits, u64::from(bits) * 31 + n as u64);
            let (tree, _) = build_and_check_with(&mut lbvh, &boxes, refs, 1, bits);
            let mut expected: Vec<u32> = (0..n as u32).collect();
            expected.sort_by_key(|&i| keys[i as usize]); // stable
            assert_eq!(tree.order_words, expected, "n {n}, {bits} key bits");
        }
    }

    #[test]
    fn lbvh_tlas_keys_keep_the_tree_exact_and_its_sah_close() {
        // Coarser keys only change the order within a cell: the tree is still exact (checked by
        // check_tree) over clustered boxes, coincident ones and empties, and not much worse.
        let mut lbvh = Lbvh::new(&gpu().device);
        let mut coincident = clustered_boxes(2000, 9);
        coincident.extend(vec![([1.0, 2.0, 3.0], [1.5, 2.5, 3.5]); 1500]);
        coincident.extend(vec![EMPTY; 300]);
        // A dense cluster in a scene stretched by one far box: many boxes share a coarse cell.
        let mut stretched = clustered_boxes(6000, 10);
        stretched.push(([3000.0; 3], [3001.0; 3]));
        for (aabbs, name) in [
            (clustered_boxes(8000, 7), "clustered"),
            (hard_soup(6007, 11), "hard soup"),
            (coincident, "coincident"),
            (stretched, "stretched"),
        ] {
            let (_, fine) = build_and_check_with(
                &mut lbvh,
                &aabbs,
                LeafRefs::PrimitiveIndex,
                1,
                BLAS_KEY_BITS,
            );
            let (_, coarse) = build_and_check_with(
                &mut lbvh,
                &aabbs,
                LeafRefs::PrimitiveIndex,
                1,
                TLAS_KEY_BITS,
            );
            eprintln!("{name}: SAH with 10 bits per axis {fine:.4}, with 8 {coarse:.4}");
            assert!(coarse <= 1.05 * fine, "{name}: SAH {coarse} vs {fine}");
            if name == "stretched" {
                // The price of coarse keys, documented at TLAS_KEY_BITS: below the root (cost
                // 1), the cluster's subtree costs 3.6 times as much on this input (10 times with
                // 7 bits per axis).
                assert!(coarse - 1.0 <= 4.0 * (fine - 1.0), "SAH {coarse} vs {fine}");
            }
        }
    }

    /// Builds `aabbs` (one primitive per leaf) into fresh node and order buffers, with no
    /// topology or bounds output, as a TLAS build does; returns those buffers and the number of
    /// dispatches recorded.
    fn build_minimal(
        lbvh: &mut Lbvh,
        aabbs: &[Aabb],
        leaf_refs: LeafRefs,
        key_bits: u32,
        centroid_bounds: Option<(&wgpu::Buffer, u32)>,
    ) -> (wgpu::Buffer, wgpu::Buffer, u32) {
        let n = aabbs.len() as u32;
        let input = aabb_buffer(aabbs, 0);
        let nodes = sentinel_buffer(u64::from(Lbvh::node_count(n)) * 16);
        let order = sentinel_buffer(u64::from(n));
        let mut dispatches = 0;
        run(|rec| {
            lbvh.build(
                rec,
                &LbvhBuild {
                    aabbs: &input,
                    aabb_base: 0,
                    count: n,
                    nodes: &nodes,
                    node_base: 0,
                    order: &order,
                    order_base: 0,
                    topology: None,
                    leaf_refs,
                    max_leaf: 1,
                    bounds_out: None,
                    key_bits,
                    centroid_bounds,
                    clustered: false,
                    hierarchy_only: false,
                },
            );
            dispatches = rec.dispatches;
        });
        (nodes, order, dispatches)
    }

    #[test]
    fn lbvh_given_centroid_bounds_build_the_same_tree() {
        // The TLAS's instance pass merges the centroid bounds and the build skips its bounds
        // pass: given the same words (here from the CPU oracle, at a non-zero base, in a buffer
        // of their own), the build must make the same order and nodes, bit for bit.
        let mut lbvh = Lbvh::new(&gpu().device);
        for (aabbs, refs) in [
            (hard_soup(5003, 21), LeafRefs::PrimitiveIndex),
            (clustered_boxes(900, 22), LeafRefs::SortedPosition),
        ] {
            let n = aabbs.len() as u32;
            let (own, _) = build_and_check_with(&mut lbvh, &aabbs, refs, 1, TLAS_KEY_BITS);
            let mut words = vec![SENTINEL; 3];
            words.extend(cpu_centroid_bounds(aabbs.iter().copied()));
            let given = buffer_with(bytemuck::cast_slice(&words));
            let (nodes, order, dispatches) =
                build_minimal(&mut lbvh, &aabbs, refs, TLAS_KEY_BITS, Some((&given, 3)));
            assert_eq!(read_words(&order), own.order_words, "order, {n} primitives");
            assert_eq!(read_words(&nodes), own.node_words, "nodes, {n} primitives");
            assert_eq!(read_words(&given), words, "the given words are only read");
            // Morton, sort (5 dispatches: the first histogram is the morton pass's; or 1 up to
            // 1024 primitives), hierarchy, climb.
            assert_eq!(dispatches, if n > 1024 { 8 } else { 4 });
        }
    }

    #[test]
    fn lbvh_build_dispatch_counts() {
        // A BLAS build of more than 1024 primitives: bounds, morton, 4 sort passes, hierarchy,
        // climb; a sort pass is 2 dispatches up to SUMMING_MAX_BLOCKS blocks of 1024 (the
        // scatter sums the histogram rows), 3 above, and the morton pass makes the first pass's
        // histogram. A TLAS build: 3 sort passes and no copy back. Up to 1024: one sort
        // dispatch.
        let limit = crate::gpu::radix_sort::SUMMING_MAX_BLOCKS as usize * 1024;
        let mut lbvh = Lbvh::new(&gpu().device);
        for (n, bits, expected) in [
            (5000, BLAS_KEY_BITS, 11),
            (5000, TLAS_KEY_BITS, 9),
            (1000, TLAS_KEY_BITS, 5),
            (limit, TLAS_KEY_BITS, 9),
            (limit + 1, TLAS_KEY_BITS, 12),
        ] {
            let aabbs = hard_soup(n, 12);
            let (_, _, dispatches) =
                build_minimal(&mut lbvh, &aabbs, LeafRefs::PrimitiveIndex, bits, None);
            assert_eq!(dispatches, expected, "{n} primitives, {bits} key bits");
        }
    }

    #[test]
    fn lbvh_refit_equals_exact_boxes_on_same_topology() {
        let mut lbvh = Lbvh::new(&gpu().device);
        let mut rng = Rng(5);
        for (n, refs, sorted_boxes) in [
            (1usize, LeafRefs::PrimitiveIndex, false),
            (2, LeafRefs::SortedPosition, false),
            (1000, LeafRefs::SortedPosition, false),
            (3001, LeafRefs::PrimitiveIndex, false),
            // Boxes in sorted order (a BLAS refit's): leaf k reads box k, not box order[k].
            (1, LeafRefs::SortedPosition, true),
            (3001, LeafRefs::SortedPosition, true),
            (700, LeafRefs::PrimitiveIndex, true),
        ] {
            let before = hard_soup(n, n as u64);
            let (tree, _) = build_and_check(&mut lbvh, &before, refs);
            let refs_before: Vec<u32> = tree
                .node_words
                .chunks(16)
                .flat_map(|w| [w[3], w[7]])
                .collect();
            // Move every box; some empties become real and some real ones empty.
            let after: Vec<Aabb> = before
                .iter()
                .enumerate()
                .map(|(i, b)| match i % 13 {
                    0 => EMPTY,
                    1 => random_box(&mut rng),
                    _ if is_empty(b) => *b,
                    _ => shifted(b, rng.vec(-3.0, 3.0)),
                })
                .collect();
            refit_to_with(&mut lbvh, &tree, &after, 1, sorted_boxes);
            // Exact boxes of the new primitives over the same tree (the order was made for
            // the old boxes, so empties need not be last any more).
            let order_before = tree.order_words.clone();
            let (tree, _) = check_read_back(tree, &after, false);
            assert_eq!(tree.order_words, order_before, "refit keeps the order");
            let refs_after: Vec<u32> = tree
                .node_words
                .chunks(16)
                .flat_map(|w| [w[3], w[7]])
                .collect();
            assert_eq!(refs_after, refs_before, "refit keeps every ref");
        }
    }

    #[test]
    fn lbvh_sah_within_2x_of_cpu_sah() {
        let mut lbvh = Lbvh::new(&gpu().device);
        let mut rng = Rng(99);
        for (n, spread) in [(2000usize, 100.0f32), (4000, 20.0)] {
            let tris: Vec<[Vec3; 3]> = (0..n)
                .map(|_| {
                    let c = Vec3::from(rng.vec(0.0, spread));
                    [0; 3].map(|_| c + Vec3::from(rng.vec(-1.0, 1.0)))
                })
                .collect();
            let aabbs: Vec<Aabb> = tris
                .iter()
                .map(|t| {
                    let lo = t[0].min(t[1]).min(t[2]);
                    let hi = t[0].max(t[1]).max(t[2]);
                    (lo.to_array(), hi.to_array())
                })
                .collect();
            let (_, gpu_sah) = build_and_check(&mut lbvh, &aabbs, LeafRefs::SortedPosition);
            let cpu_sah = f64::from(CpuBvh::build(&tris).sah_cost());
            eprintln!("SAH n={n}: gpu lbvh {gpu_sah:.2}, cpu binned {cpu_sah:.2}");
            assert!(
                gpu_sah <= 2.0 * cpu_sah,
                "LBVH SAH {gpu_sah} vs CPU {cpu_sah}"
            );
        }
    }

    /// A subtree in the collapse oracle: box, primitive count, optimal cost, and its sorted
    /// positions as one range `(first, count)` when they are one.
    type Solved = (Option<Aabb>, u32, f64, Option<u32>);

    /// The optimal SAH cost (relative to the root's area, as `check_tree`) of collapsing
    /// subtrees of the read-back topology into leaves of at most `max_leaf` primitives, a
    /// subtree only when its leaves are one range of sorted positions (always in a Karras tree):
    /// the CPU oracle of the climb's decisions, in f64.
    fn optimal_collapsed_sah(tree: &GpuTree, aabbs: &[Aabb], max_leaf: u32) -> f64 {
        let topo = read_words(&tree.topology);
        let topo = &topo[tree.bases.topo as usize..];
        let n = tree.n as usize;
        let boxes: Vec<Option<Aabb>> = aabbs.iter().map(|b| (!is_empty(b)).then_some(*b)).collect();
        // The subtree of topology ref `c` (depth is small for these inputs: recursion is fine
        // in a test).
        fn solve(
            c: u32,
            topo: &[u32],
            tree: &GpuTree,
            boxes: &[Option<Aabb>],
            max_leaf: u32,
        ) -> Solved {
            if c & 0x8000_0000 != 0 {
                let k = c & 0x7fff_ffff;
                let b = boxes[tree.order_words[k as usize] as usize];
                let a = b.as_ref().map_or(0.0, area);
                return (b, 1, a * f64::from(SAH_INTERSECTION_COST), Some(k));
            }
            let i = c as usize;
            let l = solve(topo[2 * i], topo, tree, boxes, max_leaf);
            let r = solve(topo[2 * i + 1], topo, tree, boxes, max_leaf);
            let b = union(l.0, r.0);
            let a = b.as_ref().map_or(0.0, area);
            let count = l.1 + r.1;
            let range = match (l.3, r.3) {
                (Some(lf), Some(rf)) if lf + l.1 == rf || rf + r.1 == lf => Some(lf.min(rf)),
                _ => None,
            };
            let split = a * f64::from(SAH_TRAVERSAL_COST) + l.2 + r.2;
            let leaf = a * f64::from(count) * f64::from(SAH_INTERSECTION_COST);
            let cost = if range.is_some() && count <= max_leaf && leaf <= split {
                leaf
            } else {
                split
            };
            (b, count, cost, range)
        }
        assert!(n >= 2);
        let l = solve(topo[0], topo, tree, &boxes, max_leaf);
        let r = solve(topo[1], topo, tree, &boxes, max_leaf);
        let root = union(l.0, r.0);
        let ra = area(&stored(root)).max(f64::from(f32::MIN_POSITIVE));
        f64::from(SAH_TRAVERSAL_COST) + (l.2 + r.2) / ra
    }

    /// Clustered random triangles' boxes (the shape of a mesh: many small, overlapping boxes).
    fn clustered_boxes(n: usize, seed: u64) -> Vec<Aabb> {
        let mut rng = Rng(seed);
        (0..n)
            .map(|_| {
                let c = rng.vec(0.0, 30.0);
                let d = rng.vec(0.05, 1.0);
                (
                    [0, 1, 2].map(|i| c[i] - d[i]),
                    [0, 1, 2].map(|i| c[i] + d[i]),
                )
            })
            .collect()
    }

    #[test]
    fn lbvh_collapsed_leaves_are_the_sah_optimum_of_the_topology() {
        collapsed_leaves_are_the_optimum(false);
    }

    /// Builds (clustered or not) over two box sets with leaves of up to 2, 4 and 8: each SAH
    /// cost must be the collapse optimum of its topology, and below one primitive per leaf.
    fn collapsed_leaves_are_the_optimum(clustered: bool) {
        let mut lbvh = Lbvh::new(&gpu().device);
        let refs = LeafRefs::SortedPosition;
        for (aabbs, name) in [
            (clustered_boxes(6000, 3), "clustered"),
            (hard_soup(5003, 8), "hard soup"),
        ] {
            let mut build = |max_leaf| {
                build_and_check_opts(&mut lbvh, &aabbs, refs, max_leaf, BLAS_KEY_BITS, clustered)
            };
            let (_, single) = build(1);
            for max_leaf in [2, 4, 8] {
                // check_tree: every primitive in exactly one leaf of ≤ max_leaf, exact boxes.
                let (tree, sah) = build(max_leaf);
                let optimum = optimal_collapsed_sah(&tree, &aabbs, max_leaf);
                eprintln!("{name} max_leaf {max_leaf}: SAH {sah:.3} (one per leaf {single:.3})");
                assert_is_optimum(sah, optimum, &format!("{name} max_leaf {max_leaf}"));
                assert!(sah < single, "{name}: collapsing must lower the SAH cost");
            }
        }
    }

    /// `sah` equals the oracle's `optimum` (f32 boxes against f64 sums).
    fn assert_is_optimum(sah: f64, optimum: f64, what: &str) {
        assert!(
            (sah - optimum).abs() <= 1e-4 * optimum,
            "{what}: SAH {sah} but the optimum is {optimum}"
        );
    }

    /// `before` with every third box moved up to 200 away: decisions made for the old boxes
    /// no longer hold.
    fn scatter_a_third(before: &[Aabb], seed: u64) -> Vec<Aabb> {
        let mut rng = Rng(seed);
        before
            .iter()
            .enumerate()
            .map(|(i, b)| {
                if i % 3 == 0 {
                    shifted(b, rng.vec(-200.0, 200.0))
                } else {
                    *b
                }
            })
            .collect()
    }

    #[test]
    fn lbvh_collapse_is_off_for_primitive_index_refs() {
        // A TLAS leaf's instances are not one range: max_leaf is ignored there.
        let mut lbvh = Lbvh::new(&gpu().device);
        let aabbs = clustered_boxes(3000, 4);
        let (tree, _) = build_and_check_leaves(&mut lbvh, &aabbs, LeafRefs::PrimitiveIndex, 8);
        let counts_one = tree
            .node_words
            .chunks(16)
            .flat_map(|w| [w[3], w[7]])
            .filter(|r| r & 0x8000_0000 != 0)
            .all(|r| r & 0x7000_0000 == 0);
        assert!(counts_one, "every TLAS leaf holds one instance");
    }

    #[test]
    fn lbvh_refit_with_collapse_makes_the_optimum_for_the_new_boxes() {
        let mut lbvh = Lbvh::new(&gpu().device);
        let before = clustered_boxes(4000, 5);
        let (tree, _) = build_and_check_leaves(&mut lbvh, &before, LeafRefs::SortedPosition, 4);
        let after = scatter_a_third(&before, 6);
        refit_to(&mut lbvh, &tree, &after, 4);
        let (tree, sah) = check_read_back(tree, &after, false);
        let optimum = optimal_collapsed_sah(&tree, &after, 4);
        assert_is_optimum(sah, optimum, "refit for the new boxes");
    }

    /// Depth of the tree (root = 1) from its read-back topology.
    fn topology_depth(tree: &GpuTree) -> usize {
        let topo = read_words(&tree.topology);
        let topo = &topo[tree.bases.topo as usize..];
        let mut deepest = 0;
        let mut stack = vec![(0u32, 1usize)];
        while let Some((i, d)) = stack.pop() {
            deepest = deepest.max(d);
            for c in [topo[2 * i as usize], topo[2 * i as usize + 1]] {
                if c & 0x8000_0000 == 0 {
                    stack.push((c, d + 1));
                }
            }
        }
        deepest
    }

    #[test]
    fn hploc_small_and_random_counts_make_valid_trees() {
        // Every count up to past two clusters' worth (the root's merge alone, then merges
        // below it), and a few across workgroups: exact boxes, every primitive once, parent
        // refs, root at node 0 (check_tree walks from there).
        let mut lbvh = Lbvh::new(&gpu().device);
        let mut rng = Rng(17);
        for n in (0..=40).chain([255, 256, 257, 1000, 3001]) {
            let aabbs: Vec<Aabb> = (0..n).map(|_| random_box(&mut rng)).collect();
            for max_leaf in [1, 4] {
                build_and_check_clustered(&mut lbvh, &aabbs, max_leaf);
            }
        }
    }

    #[test]
    fn hploc_with_primitive_index_leaves_as_the_tlas_builds() {
        // The TLAS's leaves name primitives, not sorted positions: every count from none to
        // past two clusters' worth and across workgroups gives a valid tree over the same
        // boxes, far-apart groups (instances in rooms) a lower SAH cost than the LBVH's, and a
        // refit (instances moved) exact boxes with every ref kept.
        let mut lbvh = Lbvh::new(&gpu().device);
        let mut rng = Rng(19);
        for n in (0..=40).chain([255, 256, 257, 1000, 1024]) {
            let aabbs: Vec<Aabb> = (0..n).map(|_| random_box(&mut rng)).collect();
            build_and_check_clustered_refs(&mut lbvh, &aabbs);
        }
        let centres: Vec<[f32; 3]> = (0..8).map(|_| rng.vec(-500.0, 500.0)).collect();
        let mut rooms: Vec<Aabb> = clustered_boxes(1000, 20);
        for (i, b) in rooms.iter_mut().enumerate() {
            *b = shifted(b, centres[i % centres.len()]);
        }
        let (_, lbvh_sah) = build_and_check_with(
            &mut lbvh,
            &rooms,
            LeafRefs::PrimitiveIndex,
            1,
            TLAS_KEY_BITS,
        );
        let (tree, ploc_sah) = build_and_check_clustered_refs(&mut lbvh, &rooms);
        assert!(
            ploc_sah < 0.9 * lbvh_sah,
            "clustered TLAS SAH {ploc_sah} vs LBVH {lbvh_sah}"
        );
        let refs = |t: &GpuTree| -> Vec<u32> {
            t.node_words.chunks(16).flat_map(|w| [w[3], w[7]]).collect()
        };
        let refs_before = refs(&tree);
        let after = scatter_a_third(&rooms, 22);
        refit_to(&mut lbvh, &tree, &after, 1);
        let (tree, _) = check_read_back(tree, &after, false);
        assert_eq!(refs(&tree), refs_before, "refit keeps every ref");
    }

    #[test]
    fn hploc_hard_soup_and_identical_boxes() {
        // Duplicates, flat, empty, NaN and huge boxes; then 20k identical boxes, where every
        // merge ties: the tie rule must pair them up, not chain them (the traversal's stack
        // holds 64 entries per level).
        let mut lbvh = Lbvh::new(&gpu().device);
        for max_leaf in [1, 4] {
            build_and_check_clustered(&mut lbvh, &hard_soup(20_000, 21), max_leaf);
        }
        let same = vec![([1.0, 2.0, 3.0], [2.0, 3.0, 4.0]); 20_000];
        let (tree, _) = build_and_check_clustered(&mut lbvh, &same, 1);
        let depth = topology_depth(&tree);
        assert!(depth <= 40, "20k identical boxes: depth {depth}");
    }

    #[test]
    fn hploc_lowers_the_sah_cost_of_the_lbvh() {
        // Boxes in a few far-apart groups (rooms of a building): where a Karras split falls
        // by Morton bit, not by geometry, clustering pays most.
        let mut lbvh = Lbvh::new(&gpu().device);
        let mut rng = Rng(23);
        let centres: Vec<[f32; 3]> = (0..12).map(|_| rng.vec(-500.0, 500.0)).collect();
        let mut aabbs: Vec<Aabb> = clustered_boxes(8000, 24);
        for (i, b) in aabbs.iter_mut().enumerate() {
            *b = shifted(b, centres[i % centres.len()]);
        }
        // A soup of overlapping boxes leaves little to gain (lavapipe: 91.9 → 90.1), but the
        // clustered tree must not be worse; the groups gain a quarter (4.19 → 3.08).
        let soup = clustered_boxes(8000, 25);
        for (aabbs, name, most) in [(aabbs, "groups", 0.85), (soup, "soup", 1.0)] {
            let (_, lbvh_sah) =
                build_and_check_leaves(&mut lbvh, &aabbs, LeafRefs::SortedPosition, 1);
            let (_, ploc_sah) = build_and_check_clustered(&mut lbvh, &aabbs, 1);
            eprintln!("{name}: SAH lbvh {lbvh_sah:.3}, clustered {ploc_sah:.3}");
            assert!(
                ploc_sah < most * lbvh_sah,
                "{name}: clustered SAH {ploc_sah} vs LBVH {lbvh_sah}"
            );
        }
    }

    #[test]
    fn hploc_builds_the_same_tree_every_time() {
        // Output slots come from each node's pool, in the order of its merging lanes, not from
        // a device-wide counter: the same input gives the same nodes and topology word for word,
        // whatever order the workgroups ran in. Between the builds the builder runs another
        // input, so nothing is left over from the first.
        let mut lbvh = Lbvh::new(&gpu().device);
        let mut rng = Rng(41);
        let aabbs: Vec<Aabb> = (0..20_000).map(|_| random_box(&mut rng)).collect();
        let other: Vec<Aabb> = (0..20_000).map(|_| random_box(&mut rng)).collect();
        for max_leaf in [1, 4] {
            let (first, _) = build_and_check_clustered(&mut lbvh, &aabbs, max_leaf);
            let topo_first = read_words(&first.topology);
            build_and_check_clustered(&mut lbvh, &other, max_leaf);
            let (second, _) = build_and_check_clustered(&mut lbvh, &aabbs, max_leaf);
            assert!(
                first.node_words == second.node_words,
                "max_leaf {max_leaf}: the nodes differ between two builds of the same boxes"
            );
            assert!(
                topo_first == read_words(&second.topology),
                "max_leaf {max_leaf}: the topology differs between two builds of the same boxes"
            );
        }
    }

    #[test]
    fn hploc_collapsed_leaves_are_the_sah_optimum_of_ranges() {
        // Only subtrees whose leaves are one range of sorted positions may be one leaf (a leaf
        // ref is a range); among those the build must take every collapse that pays.
        collapsed_leaves_are_the_optimum(true);
    }

    #[test]
    fn hploc_refit_keeps_the_clustered_topology() {
        // A refit runs lbvh_climb over the clustered topology (device-scope phase only): exact
        // boxes for moved primitives, refs unchanged without collapsing, the collapse optimum
        // with it.
        let mut lbvh = Lbvh::new(&gpu().device);
        let before = clustered_boxes(5000, 31);
        let after = scatter_a_third(&before, 32);
        let (tree, _) = build_and_check_clustered(&mut lbvh, &before, 1);
        let refs = |t: &GpuTree| -> Vec<u32> {
            t.node_words.chunks(16).flat_map(|w| [w[3], w[7]]).collect()
        };
        let refs_before = refs(&tree);
        refit_to(&mut lbvh, &tree, &after, 1);
        let (tree, _) = check_read_back(tree, &after, false);
        assert_eq!(refs(&tree), refs_before, "refit keeps every ref");
        let (tree, _) = build_and_check_clustered(&mut lbvh, &before, 4);
        // As a fast-trace BLAS is refit: the boxes in sorted order.
        refit_to_with(&mut lbvh, &tree, &after, 4, true);
        let (tree, sah) = check_read_back(tree, &after, false);
        let optimum = optimal_collapsed_sah(&tree, &after, 4);
        assert_is_optimum(sah, optimum, "clustered refit for the new boxes");
    }

    /// `n` random staged triangles (3 `vec4`: xyz, w 0; the second vertex's w = 1 marks a
    /// dropped triangle), every 11th dropped and every 7th degenerate (a point).
    fn staged_triangles(rng: &mut Rng, n: usize, spread: f32) -> Vec<[f32; 4]> {
        let mut tris = Vec::with_capacity(3 * n);
        for t in 0..n {
            let c = rng.vec(-spread, spread);
            let mut v: [[f32; 4]; 3] = std::array::from_fn(|_| {
                let d = rng.vec(-1.0, 1.0);
                [c[0] + d[0], c[1] + d[1], c[2] + d[2], 0.0]
            });
            if t % 7 == 3 {
                v[1] = v[0];
                v[2] = v[0];
            }
            if t % 11 == 5 {
                v[1][3] = f32::from_bits(1);
            }
            tris.extend(v);
        }
        tris
    }

    /// Each staged triangle's box as `triangle_box.wgsl` makes it (dropped: the empty box).
    fn staged_boxes(tris: &[[f32; 4]]) -> Vec<Aabb> {
        tris.chunks(3)
            .map(|v| {
                if v[1][3].to_bits() == 1 {
                    return EMPTY;
                }
                let lo = [0, 1, 2].map(|a| v[0][a].min(v[1][a]).min(v[2][a]));
                let hi = [0, 1, 2].map(|a| v[0][a].max(v[1][a]).max(v[2][a]));
                (lo, hi)
            })
            .collect()
    }

    /// Builds a fast-build tree over `before`'s boxes, range-refits it to the triangles `after`
    /// and checks everything: the refit's dispatches, exact node boxes and root box over the
    /// same refs, and the triangles gathered bit-exactly into sorted order.
    fn range_refit_and_check(lbvh: &mut Lbvh, before: &[[f32; 4]], after: &[[f32; 4]]) {
        let n = (before.len() / 3) as u32;
        let (tree, _) = build_and_check(lbvh, &staged_boxes(before), LeafRefs::SortedPosition);
        let refs = |t: &GpuTree| -> Vec<u32> {
            t.node_words.chunks(16).flat_map(|w| [w[3], w[7]]).collect()
        };
        let refs_before = refs(&tree);
        let (src_base, dst_base) = (5u32, 3u32);
        let mut src = vec![[7.0f32; 4]; 3 * src_base as usize];
        src.extend_from_slice(after);
        let src = buffer_with(bytemuck::cast_slice(&src));
        let dst = sentinel_buffer((u64::from(dst_base + n) + 1) * 12);
        let mut dispatches = 0;
        run(|rec| {
            lbvh.refit_triangles(
                rec,
                &LbvhTriangleRefit {
                    source: RefitSource::Staged {
                        triangles: &src,
                        base: src_base,
                    },
                    dst: &dst,
                    dst_base,
                    count: n,
                    nodes: &tree.nodes,
                    node_base: tree.bases.node,
                    order: &tree.order,
                    order_base: tree.bases.order,
                    topology: (&tree.topology, tree.bases.topo),
                    bounds_out: Some((&tree.bounds, tree.bases.bounds)),
                },
            );
            dispatches = rec.dispatches;
        });
        // The gather (which also makes the pyramid); the nodes that straddle blocks of 256.
        let expected = if n > 256 { 2 } else { 1 };
        assert_eq!(dispatches, expected, "{n} triangles: dispatches");
        let order = tree.order_words.clone();
        let (tree, _) = check_read_back(tree, &staged_boxes(after), false);
        assert_eq!(
            refs(&tree),
            refs_before,
            "{n} triangles: the refit keeps every ref"
        );
        let got = read_words(&dst);
        let after_words: &[u32] = bytemuck::cast_slice(after);
        let base = 12 * dst_base as usize;
        assert_untouched(&got, base, 12 * n as usize, "gathered triangles");
        for (k, &p) in order.iter().enumerate() {
            let p = p as usize;
            assert_eq!(
                &got[base + 12 * k..base + 12 * k + 12],
                &after_words[12 * p..12 * p + 12],
                "{n} triangles: sorted position {k}"
            );
        }
    }

    #[test]
    fn range_refit_of_triangles_equals_exact_boxes_and_gathers_them() {
        let mut lbvh = Lbvh::new(&gpu().device);
        let mut rng = Rng(41);
        // One node; one partial block; exactly one block; one more than a block; several
        // blocks (one group: its last block makes the pyramid's top); more than 256 blocks (two
        // groups, then a last stage over them); every level odd somewhere.
        for (n, spread) in [
            (2usize, 1.0f32),
            (3, 1.0),
            (100, 5.0),
            (256, 20.0),
            (257, 20.0),
            (3001, 40.0),
            (40_000, 100.0),
            (70_001, 150.0),
        ] {
            let before = staged_triangles(&mut rng, n, spread);
            // Move every triangle; a few jump across the scene, a few become dropped and a
            // few dropped ones come back.
            let mut after = before.clone();
            for (t, v) in after.chunks_mut(3).enumerate() {
                let d = if t % 17 == 0 {
                    rng.vec(-spread, spread)
                } else {
                    rng.vec(-0.5, 0.5)
                };
                for x in v.iter_mut() {
                    for a in 0..3 {
                        x[a] += d[a];
                    }
                }
                match t % 23 {
                    4 => v[1][3] = f32::from_bits(1),
                    16 => v[1][3] = 0.0,
                    _ => {}
                }
            }
            range_refit_and_check(&mut lbvh, &before, &after);
        }
    }

    /// The application's bytes of a geometry of `n` triangles in two components, and how many
    /// of its triangles the ingestion must drop (out-of-range index, non-finite position):
    /// component A is a strip of Float32x3 vertices (stride 16, at an unaligned offset) with u32
    /// indices, every 13th triangle with an index past the end and every 97th vertex NaN;
    /// component B holds the rest, non-indexed (stride 12) and transformed.
    fn raw_geometry(
        rng: &mut Rng,
        n: u32,
        spread: f32,
    ) -> (Vec<u8>, Vec<ComponentIngest>, [u32; 2]) {
        let n_a = n * 2 / 3;
        let n_b = n - n_a;
        let verts_a = n_a + 2;
        let mut raw = vec![0xABu8; 6];
        let a_offset = raw.len() as u64;
        let mut walk = rng.vec(-spread, spread);
        let mut positions_a = Vec::new();
        for v in 0..verts_a {
            let d = rng.vec(-1.0, 1.0);
            walk = [0, 1, 2].map(|a| (walk[a] + d[a]).clamp(-spread, spread));
            let p = if v % 97 == 40 {
                [f32::NAN, 0.0, 0.0]
            } else {
                walk
            };
            positions_a.push(p);
            for x in p.iter().chain(&[9.0]) {
                raw.extend_from_slice(&x.to_le_bytes());
            }
        }
        raw.resize(raw.len().div_ceil(4) * 4, 0xCD);
        let index_offset = raw.len() as u64;
        let mut dropped = [0u32; 2];
        for t in 0..n_a {
            let mut idx = [t, t + 1, t + 2];
            if t % 13 == 6 {
                idx[1] = verts_a + 5;
            }
            for i in idx {
                raw.extend_from_slice(&i.to_le_bytes());
            }
            if idx.iter().any(|&i| i >= verts_a) {
                dropped[0] += 1;
            } else if idx.iter().any(|&i| positions_a[i as usize][0].is_nan()) {
                dropped[1] += 1;
            }
        }
        let b_offset = raw.len() as u64;
        for _ in 0..n_b {
            let c = rng.vec(-spread, spread);
            for _ in 0..3 {
                let d = rng.vec(-1.0, 1.0);
                for a in 0..3 {
                    raw.extend_from_slice(&(c[a] + d[a]).to_le_bytes());
                }
            }
        }
        let component =
            |offset, stride, count, index, triangles, transform, base| ComponentIngest {
                vertex_byte_offset: offset,
                vertex_stride: stride,
                vertex_format: crate::VertexFormat::Float32x3,
                vertex_count: count,
                index,
                first_index: 0,
                triangle_count: triangles,
                transform,
                primitive_base: base,
            };
        let transform = glam::Affine3A::from_scale_rotation_translation(
            glam::Vec3::new(0.5, 2.0, 1.0),
            glam::Quat::from_rotation_y(0.3),
            glam::Vec3::new(10.0, -3.0, 1.0),
        );
        let comps = vec![
            component(
                a_offset,
                16,
                verts_a,
                Some((index_offset, crate::IndexFormat::Uint32)),
                n_a,
                None,
                0,
            ),
            component(b_offset, 12, 3 * n_b, None, n_b, Some(transform), n_a),
        ];
        (raw, comps, dropped)
    }

    #[test]
    fn range_refit_from_raw_bytes_equals_ingestion_then_refit() {
        // The fused refit decodes each sorted position's triangle itself: the same triangles,
        // nodes, root box and dropped-triangle counts as the ingestion pass followed by the
        // refit of the staged triangles, in two passes instead of three; exact boxes.
        let g = gpu();
        let mut lbvh = Lbvh::new(&g.device);
        let ingest = Ingest::new(&g.device);
        let mut rng = Rng(47);
        for (n, spread) in [(257u32, 20.0f32), (3001, 40.0), (40_000, 100.0)] {
            let (raw, comps, dropped) = raw_geometry(&mut rng, n, spread);
            assert!(dropped[0] > 0 && dropped[1] > 0, "the data drops both ways");
            let raw = buffer_with(&raw);
            let boxes = staged_boxes(&staged_triangles(&mut rng, n as usize, spread));
            let (src_base, dst_base, counter_base) = (5u32, 3u32, 2u32);
            let words = (u64::from(dst_base + n) + 1) * 12;
            // Ingestion into staged triangles, then the refit of them.
            let (staged_tree, _) = build_and_check(&mut lbvh, &boxes, LeafRefs::SortedPosition);
            let staged = sentinel_buffer((u64::from(src_base + n) + 1) * 12);
            let (staged_dst, staged_counters) = (sentinel_buffer(words), buffer_with(&[0u8; 16]));
            run(|rec| {
                ingest.record(
                    rec,
                    &raw,
                    &comps,
                    &staged,
                    src_base,
                    &staged_counters,
                    counter_base,
                );
                lbvh.refit_triangles(
                    rec,
                    &refit_of(
                        &staged_tree,
                        RefitSource::Staged {
                            triangles: &staged,
                            base: src_base,
                        },
                        &staged_dst,
                        dst_base,
                    ),
                );
            });
            // The fused refit.
            let (tree, _) = build_and_check(&mut lbvh, &boxes, LeafRefs::SortedPosition);
            let (dst, counters) = (sentinel_buffer(words), buffer_with(&[0u8; 16]));
            let rows = component_rows(&comps, 0).expect("the components fit");
            assert!(Lbvh::can_refit_from_raw(n, &rows));
            let mut dispatches = 0;
            run(|rec| {
                let source = RefitSource::Raw(RawTriangles {
                    raw: &raw,
                    rows: &rows,
                    counters: &counters,
                    counter_base,
                });
                lbvh.refit_triangles(rec, &refit_of(&tree, source, &dst, dst_base));
                dispatches = rec.dispatches;
            });
            assert_eq!(dispatches, 2, "{n} triangles: refit ingest, range refit");
            let counts = read_words(&counters);
            assert_eq!(counts, read_words(&staged_counters), "{n}: dropped counts");
            assert_eq!(
                counts,
                [0, 0, dropped[0], dropped[1]],
                "{n}: dropped counts"
            );
            let got = read_words(&dst);
            assert_untouched(&got, 12 * dst_base as usize, 12 * n as usize, "triangles");
            assert_eq!(got, read_words(&staged_dst), "{n}: the gathered triangles");
            let staged_words = read_words(&staged);
            let staged_tris: &[[f32; 4]] =
                bytemuck::cast_slice(&staged_words[12 * src_base as usize..][..12 * n as usize]);
            let (staged_tree, _) = check_read_back(staged_tree, &staged_boxes(staged_tris), false);
            let (tree, _) = check_read_back(tree, &staged_boxes(staged_tris), false);
            assert_eq!(tree.node_words, staged_tree.node_words, "{n}: nodes");
            assert_eq!(
                read_words(&tree.bounds),
                read_words(&staged_tree.bounds),
                "{n}: root box"
            );
        }
        // Too few triangles for the fused pass (one block: the root would need bounds_out).
        assert!(!Lbvh::can_refit_from_raw(256, &[0; ROW_WORDS]));
        assert!(!Lbvh::can_refit_from_raw(
            1000,
            &vec![0; (REFIT_INGEST_ROWS + 1) * ROW_WORDS]
        ));
    }

    /// The range refit of `tree` from `source` into `dst` at triangle `dst_base`.
    fn refit_of<'a>(
        tree: &'a GpuTree,
        source: RefitSource<'a>,
        dst: &'a wgpu::Buffer,
        dst_base: u32,
    ) -> LbvhTriangleRefit<'a> {
        LbvhTriangleRefit {
            source,
            dst,
            dst_base,
            count: tree.n,
            nodes: &tree.nodes,
            node_base: tree.bases.node,
            order: &tree.order,
            order_base: tree.bases.order,
            topology: (&tree.topology, tree.bases.topo),
            bounds_out: Some((&tree.bounds, tree.bases.bounds)),
        }
    }

    /// A million triangles: 4100 blocks, 17 groups at the pyramid's first stage. Slow on
    /// software Vulkan: run with `--ignored` (the H100 runs).
    #[test]
    #[ignore]
    fn range_refit_of_a_million_triangles() {
        let mut lbvh = Lbvh::new(&gpu().device);
        let mut rng = Rng(43);
        let n = (1 << 20) + 4097 * 256 / 1024;
        let before = staged_triangles(&mut rng, n, 500.0);
        let mut after = before.clone();
        for v in after.chunks_mut(3) {
            let d = rng.vec(-1.0, 1.0);
            for x in v.iter_mut() {
                for a in 0..3 {
                    x[a] += d[a];
                }
            }
        }
        assert_eq!(pyramid_level_count(n as u32, 2 * REFIT_GATHER_LEVELS), 17);
        range_refit_and_check(&mut lbvh, &before, &after);
    }

    #[test]
    fn pyramid_boxes_sum_the_levels() {
        for (n, levels) in [
            (1u32, vec![1]),
            (2, vec![2, 1]),
            (5, vec![5, 3, 2, 1]),
            (8, vec![8, 4, 2, 1]),
        ] {
            let counts: Vec<u32> = (0..levels.len() as u32)
                .map(|l| pyramid_level_count(n, l))
                .collect();
            assert_eq!(counts, levels, "{n} boxes");
            assert_eq!(
                pyramid_boxes(n),
                levels.iter().map(|&c| u64::from(c)).sum::<u64>()
            );
        }
    }
}
