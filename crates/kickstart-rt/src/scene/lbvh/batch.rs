//! A batch of BLAS builds ([`Lbvh::build_batch`]): every fast-trace build of a task in one chain
//! of dispatches, whatever their number and sizes, and every fast-build build in another. A build's cost is mostly its chain of
//! dependent dispatches, not its triangles (the apartment's 67 meshes built one by one take many
//! times what the same triangles take as one mesh), so a batch runs each pass once over all of
//! its builds:
//!
//! - the builds lie one after the other in the batch's positions, each from a multiple of
//!   [`WORKGROUP`] (the rest of its last block is padding), so every workgroup of a pass works
//!   on one build and its workgroup-local steps (bounds, the climb's blocks) are those of a
//!   build alone; each pass finds its build in the `segs` table, one `Params` per build;
//! - the boxes come from each build's staged triangles (no box pass);
//! - one sort of all keys by Morton code, then a stable sort by build (`lbvh segment keys`, one
//!   or two digit passes), so each build's primitives are back in its range in Morton order, and
//!   `lbvh rekey` restores the Morton keys the hierarchy reads;
//! - hierarchy per build, then for fast-trace builds the clustered climb and the triangle gather,
//!   for fast-build builds (Karras trees, one triangle a leaf) the batched range refit
//!   ([`Lbvh::refit_triangles_batch`]: triangle gather and nodes in two passes), as a single build
//!   does them.

use super::{
    clustered_work_words, effective_max_leaf, groups, Buffers, Lbvh, LbvhTriangleRefit, LeafRefs,
    Params, RefitSource, BLAS_KEY_BITS, BOXES_AT, FLAG_BOUNDS_OUT, FLAG_TRIANGLE_BOXES,
    HPLOC_WORKGROUP, MAX_COUNT, WORKGROUP,
};
use crate::gpu::Recorder;

/// One build of a batch: a BLAS with leaves of sorted positions, its triangles gathered into
/// sorted order.
#[derive(Debug, Clone, Copy)]
pub(crate) struct BatchBuild {
    /// Triangles (at least 1; at least 2 in a fast-build batch).
    pub count: u32,
    /// First of its staged triangles in [`LbvhBatch::staged`].
    pub tri_src_base: u32,
    /// First of its BLAS triangles in [`LbvhBatch::triangles`] (output, sorted order).
    pub tri_dst_base: u32,
    /// First of its [`Lbvh::node_count`] nodes in [`LbvhBatch::nodes`].
    pub node_base: u32,
    /// Where its root box goes in [`LbvhBatch::bounds_out`] (vec4 index).
    pub bounds_base: u32,
    /// Largest collapsed leaf (fast-trace builds).
    pub max_leaf: u32,
    /// Fast-build builds of a batch with [`BatchKind::FastBuild`]'s kept buffers: the first
    /// word of its sort order and of its topology there, kept for its refits.
    pub kept: Option<(u32, u32)>,
}

/// The trees a batch builds.
#[derive(Debug, Clone, Copy)]
pub(crate) enum BatchKind<'a> {
    /// Clustered (`hploc climb`), leaves collapsed up to each build's `max_leaf`; order and
    /// topology not kept. The nodes are then compacted ([`Lbvh::compact`]): build `k`'s node
    /// count goes to word `k` of `counts` (STORAGE and COPY_SRC usage).
    FastTrace {
        /// The builds' node counts after the compaction.
        counts: &'a wgpu::Buffer,
    },
    /// The Karras tree, one triangle a leaf, its nodes by the range refit. `kept`: the buffers
    /// of sort orders and topologies every build's `kept` bases point into (its
    /// `allow_update` geometries'); `None`: the builder's scratch (no build keeps them).
    FastBuild {
        /// (orders, topologies).
        kept: Option<(&'a wgpu::Buffer, &'a wgpu::Buffer)>,
    },
}

/// The shared buffers of a batch and its builds.
pub(crate) struct LbvhBatch<'a> {
    /// The staged-triangle pool (3 `vec4` a triangle).
    pub staged: &'a wgpu::Buffer,
    /// The BLAS triangle pool (output).
    pub triangles: &'a wgpu::Buffer,
    /// The BLAS node pool (output).
    pub nodes: &'a wgpu::Buffer,
    /// The geometry table (root boxes, output).
    pub bounds_out: &'a wgpu::Buffer,
    /// The builds, at least two.
    pub builds: &'a [BatchBuild],
    /// The trees they are.
    pub kind: BatchKind<'a>,
}

/// Where each build of a batch lies in the batch's scratch.
struct Layout {
    segs: Vec<Params>,
    /// Positions of the batch (the builds' padded counts, summed).
    positions: u32,
    /// Words of `work`, of the Karras topology, of the clustered topology.
    work_words: u64,
    topology_words: u64,
}

/// What one build adds to a batch's scratch: positions (its count padded to whole
/// workgroups), words of `work`, and words of the Karras topology (none when the build keeps
/// its own).
fn footprint(b: &BatchBuild, clustered: bool) -> (u64, u64, u64) {
    let workgroup = u64::from(WORKGROUP);
    let positions = u64::from(b.count).div_ceil(workgroup) * workgroup;
    let work = if clustered {
        clustered_work_words(b.count)
    } else {
        BOXES_AT
    };
    let topology = match b.kept {
        Some(_) => 0,
        None => u64::from(Lbvh::topology_words(b.count)),
    };
    (positions, work, topology)
}

/// Splits `builds` into runs of consecutive builds whose batch scratch fits bindings of
/// `max_binding` bytes: every buffer a batch binds whole (its keys, values and order, a word a
/// position; its `work`; its topology) must stay within the device's largest storage binding,
/// and a scene's builds together easily pass it. A build too large to share a batch is a run
/// of its own (the caller builds it alone; the plan checked it fits by itself).
pub(crate) fn batch_runs(
    builds: &[BatchBuild],
    clustered: bool,
    max_binding: u64,
) -> Vec<std::ops::Range<usize>> {
    let max_words = max_binding / 4;
    let mut runs = Vec::new();
    let (mut start, mut sums) = (0, (0u64, 0u64, 0u64));
    for (i, b) in builds.iter().enumerate() {
        let (p, w, t) = footprint(b, clustered);
        let grown = (sums.0 + p, sums.1 + w, sums.2 + t);
        let fits = grown.0 <= max_words.min(u64::from(MAX_COUNT))
            && grown.1 <= max_words
            && grown.2 <= max_words;
        if i > start && !fits {
            runs.push(start..i);
            start = i;
            sums = (p, w, t);
        } else {
            sums = grown;
        }
    }
    if start < builds.len() {
        runs.push(start..builds.len());
    }
    runs
}

/// Sort key bits of the build index of `builds` builds (at least 1).
fn segment_bits(builds: usize) -> u32 {
    (usize::BITS - builds.saturating_sub(1).leading_zeros()).max(1)
}

impl Layout {
    /// The layout of `builds`; `clustered` for fast-trace builds, whose climb needs scratch of
    /// its own (a fast-build build's work is its centroid bounds only, and its order and
    /// topology are its kept ones or in the scratch).
    fn of(builds: &[BatchBuild], clustered: bool) -> Option<Layout> {
        let mut segs = Vec::with_capacity(builds.len());
        let (mut positions, mut work, mut topology) = (0u64, 0u64, 0u64);
        for b in builds {
            let n = b.count;
            let (order_base, topo_base) = match b.kept {
                Some(kept) => kept,
                None => (
                    u32::try_from(positions).ok()?,
                    u32::try_from(topology).ok()?,
                ),
            };
            segs.push(Params {
                count: n,
                aabb_base: 0,
                node_base: b.node_base,
                order_base,
                topo_base,
                bounds_base: b.bounds_base,
                flags: FLAG_BOUNDS_OUT | FLAG_TRIANGLE_BOXES,
                max_leaf: effective_max_leaf(b.max_leaf, LeafRefs::SortedPosition),
                key_bits: BLAS_KEY_BITS,
                centroid_base: 0,
                work_base: u32::try_from(work).ok()?,
                key_base: u32::try_from(positions).ok()?,
                tri_src_base: b.tri_src_base,
                tri_dst_base: b.tri_dst_base,
                ingest_row_count: 0,
                ingest_counter: 0,
                // A clustered build's Karras tree goes to the scratch, a fast-build's is its
                // topology.
                karras_base: if clustered {
                    u32::try_from(topology).ok()?
                } else {
                    topo_base
                },
                pyramid_base: 0,
                row_base: 0,
                pad: 0,
            });
            let (p, w, t) = footprint(b, clustered);
            positions += p;
            work += w;
            topology += t;
        }
        let positions = u32::try_from(positions).ok().filter(|&p| p <= MAX_COUNT)?;
        Some(Layout {
            segs,
            positions,
            work_words: work,
            topology_words: topology,
        })
    }

    /// Bytes of the largest buffer the batch binds whole ([`batch_runs`] keeps it within the
    /// device's largest storage binding).
    fn largest_binding_bytes(&self) -> u64 {
        4 * u64::from(self.positions)
            .max(self.work_words)
            .max(self.topology_words)
    }
}

impl Lbvh {
    /// Records the builds of `b` as one batch (see the module docs). Returns `false`, recording
    /// nothing, when the batch has fewer than two builds, a build of no triangle (of fewer than
    /// two in a fast-build batch: a range refit's tree has inner nodes), a fast-build build
    /// whose `kept` disagrees with the batch's, or more positions than a build may have: the
    /// caller builds those one by one. So does a batch whose scratch would pass the device's
    /// largest storage binding ([`batch_runs`] splits a scene's builds into batches that fit).
    pub fn build_batch(&mut self, rec: &mut Recorder<'_>, b: &LbvhBatch<'_>) -> bool {
        let (compact_counts, kept) = match b.kind {
            BatchKind::FastTrace { counts } => (Some(counts), None),
            BatchKind::FastBuild { kept } => (None, kept),
        };
        let clustered = compact_counts.is_some();
        let least = if clustered { 1 } else { 2 };
        let kept_agree = |x: &BatchBuild| match b.kind {
            BatchKind::FastTrace { .. } => x.kept.is_none(),
            BatchKind::FastBuild { kept } => x.kept.is_some() == kept.is_some(),
        };
        if b.builds.len() < 2 || b.builds.iter().any(|x| x.count < least || !kept_agree(x)) {
            return false;
        }
        let Some(layout) = Layout::of(b.builds, clustered) else {
            return false;
        };
        let device = rec.device;
        if layout.largest_binding_bytes() > crate::gpu::buffers::max_binding(device) {
            return false;
        }
        let total = layout.positions;
        let work = self
            .work
            .get(device, "kickstart-rt lbvh work", layout.work_words * 4);
        let keys = self
            .keys
            .get(device, "kickstart-rt lbvh keys", u64::from(total) * 4);
        let values = self
            .values
            .get(device, "kickstart-rt lbvh values", u64::from(total) * 4);
        let order = self.batch_order.get(
            device,
            "kickstart-rt lbvh batch order",
            u64::from(total) * 4,
        );
        let karras = self.topology.get(
            device,
            "kickstart-rt lbvh topology",
            layout.topology_words.max(1) * 4,
        );
        let clustered_topology = self.clustered_topology.get(
            device,
            "kickstart-rt hploc topology",
            layout.topology_words.max(1) * 4,
        );
        // A fast-build batch writes the orders and topologies its builds keep.
        let (order, karras) = match kept {
            Some((orders, topologies)) => (orders.clone(), topologies.clone()),
            None => (order, karras),
        };
        let segs = rec.storage_init("lbvh batch segments", bytemuck::cast_slice(&layout.segs));
        // The batch's own params: every position, the Morton keys' bits.
        let params = rec.uniform(
            "lbvh batch params",
            &Params {
                count: total,
                key_bits: BLAS_KEY_BITS,
                ..bytemuck::Zeroable::zeroed()
            },
        );
        // Centroid bounds (zero is the identity of their atomicMax) and arrival counters.
        rec.encoder
            .clear_buffer(&work, 0, Some(layout.work_words * 4));
        let mut bind: Buffers<'_> = vec![
            ("params", &params),
            ("segs", &segs),
            // The staged triangles, read as boxes' source (FLAG_TRIANGLE_BOXES).
            ("aabbs", b.staged),
            ("work", &work),
            ("keys", &keys),
            ("values", &values),
            ("order", &order),
            ("topology", &karras),
            ("nodes", b.nodes),
            ("bounds_out", b.bounds_out),
            ("topo_out", &clustered_topology),
            ("refit_src", b.staged),
            ("refit_dst", b.triangles),
        ];
        let bg = self.bounds.bind_group(device, "lbvh", 0, &bind);
        rec.dispatch("lbvh bounds", &self.bounds.pipeline, &[&bg], groups(total));
        let (sorted_keys, sorted_values) =
            self.record_batch_sort(rec, &bind, (&keys, &values), total, b.builds.len());
        bind.push(("keys", &sorted_keys));
        bind.push(("values", &sorted_values));
        let bg = self.hierarchy.bind_group(device, "lbvh", 0, &bind);
        rec.dispatch(
            "lbvh hierarchy",
            &self.hierarchy.pipeline,
            &[&bg],
            groups(total),
        );
        if !clustered {
            // The nodes and the gathered triangles from each build's leaf ranges.
            let refits: Vec<LbvhTriangleRefit<'_>> = b
                .builds
                .iter()
                .zip(&layout.segs)
                .map(|(x, seg)| LbvhTriangleRefit {
                    source: RefitSource::Staged {
                        triangles: b.staged,
                        base: x.tri_src_base,
                    },
                    dst: b.triangles,
                    dst_base: x.tri_dst_base,
                    count: x.count,
                    nodes: b.nodes,
                    node_base: x.node_base,
                    order: &order,
                    order_base: seg.order_base,
                    topology: (&karras, seg.topo_base),
                    bounds_out: Some((b.bounds_out, x.bounds_base)),
                })
                .collect();
            self.refit_triangles_batch(rec, &refits);
            return true;
        }
        if let Some(counts) = compact_counts {
            self.record_clustered_batch(rec, &bind, (total, b.builds.len()), counts);
        }
        true
    }

    /// The rest of a fast-trace batch after its hierarchy: the clustered climb, the triangle
    /// gather and the compaction, over `total` positions of `builds` builds.
    fn record_clustered_batch(
        &mut self,
        rec: &mut Recorder<'_>,
        bind: &Buffers<'_>,
        (total, builds): (u32, usize),
        counts: &wgpu::Buffer,
    ) {
        let device = rec.device;
        let bg = self.hploc.bind_group(device, "lbvh", 0, bind);
        rec.dispatch(
            "hploc climb",
            &self.hploc.pipeline,
            &[&bg],
            total / HPLOC_WORKGROUP,
        );
        let bg = self.gather.bind_group(device, "lbvh", 0, bind);
        rec.dispatch("lbvh gather", &self.gather.pipeline, &[&bg], groups(total));
        // At most MAX_COUNT / WORKGROUP builds: each takes a block of positions at least.
        let builds = u32::try_from(builds).unwrap_or(u32::MAX);
        self.compact(rec, bind, (total, builds), counts);
    }

    /// The Morton keys of a batch's `total` positions sorted within each of its `builds`
    /// builds: by key, then stably by build (keys rewritten between and after). Returns the
    /// buffers of the sorted pairs.
    fn record_batch_sort(
        &mut self,
        rec: &mut Recorder<'_>,
        bind: &Buffers<'_>,
        (keys, values): (&wgpu::Buffer, &wgpu::Buffer),
        total: u32,
        builds: usize,
    ) -> (wgpu::Buffer, wgpu::Buffer) {
        let device = rec.device;
        let sorted = match self.sort.first_histogram(device, total, BLAS_KEY_BITS) {
            Some((hist, nblocks)) => {
                let mut with_hist = bind.clone();
                with_hist.push(("sort_hist", &hist));
                let pass = &self.morton_histogram;
                let bg = pass.bind_group(device, "lbvh", 0, &with_hist);
                rec.dispatch("lbvh morton", &pass.pipeline, &[&bg], nblocks);
                self.sort
                    .record_after_first_histogram(rec, keys, values, total, BLAS_KEY_BITS)
            }
            None => {
                let bg = self.morton.bind_group(device, "lbvh", 0, bind);
                rec.dispatch("lbvh morton", &self.morton.pipeline, &[&bg], groups(total));
                self.sort.record(rec, keys, values, total, BLAS_KEY_BITS)
            }
        };
        // An even number of digit passes (31 bits: 4) leaves the pairs in `keys` and `values`;
        // the sort by build then moves them between those and the sort's scratch as it needs.
        if &sorted.0 != keys {
            let bytes = u64::from(total) * 4;
            rec.encoder
                .copy_buffer_to_buffer(&sorted.0, 0, keys, 0, bytes);
            rec.encoder
                .copy_buffer_to_buffer(&sorted.1, 0, values, 0, bytes);
        }
        let mut rekey = bind.clone();
        let bg = self.segment_keys.bind_group(device, "lbvh", 0, &rekey);
        rec.dispatch(
            "lbvh segment keys",
            &self.segment_keys.pipeline,
            &[&bg],
            groups(total),
        );
        let by_build = self
            .sort
            .record(rec, keys, values, total, segment_bits(builds));
        rekey.push(("keys", &by_build.0));
        rekey.push(("values", &by_build.1));
        let bg = self.rekey.bind_group(device, "lbvh", 0, &rekey);
        rec.dispatch("lbvh rekey", &self.rekey.pipeline, &[&bg], groups(total));
        by_build
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn build_indices_sort_on_as_few_bits_as_they_need() {
        assert_eq!(segment_bits(2), 1);
        assert_eq!(segment_bits(3), 2);
        assert_eq!(segment_bits(256), 8);
        assert_eq!(segment_bits(257), 9);
        assert_eq!(segment_bits(1000), 10);
    }

    /// A build of `count` triangles, keeping its order and topology or not.
    fn build_of(count: u32, kept: bool) -> BatchBuild {
        BatchBuild {
            count,
            tri_src_base: 0,
            tri_dst_base: 0,
            node_base: 0,
            bounds_base: 0,
            max_leaf: 4,
            kept: kept.then_some((0, 0)),
        }
    }

    #[test]
    fn a_scenes_builds_split_into_batches_whose_scratch_fits_the_binding() {
        // Clustered work is the largest buffer: 5091 words for 300 triangles.
        assert_eq!(clustered_work_words(300), 5091);
        let builds = vec![build_of(300, false); 5];
        // Room for two builds' work (and more than their keys and topologies) a batch.
        let max = 4 * 2 * 5091 + 100;
        let runs = batch_runs(&builds, true, max);
        assert_eq!(runs, [0..2, 2..4, 4..5]);
        for run in &runs {
            let layout = Layout::of(&builds[run.clone()], true).unwrap();
            assert!(layout.largest_binding_bytes() <= max, "{run:?}");
        }
        // Everything in one batch where it fits, and nothing lost or repeated.
        assert_eq!(batch_runs(&builds, true, 1 << 27), vec![0..5]);
        assert_eq!(batch_runs(&[], true, 1 << 27), []);
        // A build too large to share a batch is a run of its own, between batches that fit.
        let mixed = [
            build_of(300, false),
            build_of(300, false),
            build_of(4000, false),
            build_of(300, false),
        ];
        assert_eq!(batch_runs(&mixed, true, max), [0..2, 2..3, 3..4]);
    }

    #[test]
    fn fast_build_batches_count_positions_and_topologies_not_clustered_work() {
        // A fast-build build's work is its bounds only: its keys (a word a padded position) and
        // topology (5n - 4 words, in the scratch unless kept) are what fill a batch.
        let scratch = vec![build_of(256, false); 4];
        let max = 4 * (2 * (5 * 256 - 4));
        assert_eq!(batch_runs(&scratch, false, max), [0..2, 2..4]);
        // Kept topologies are the pool's: only the positions count.
        let kept = vec![build_of(256, true); 4];
        assert_eq!(batch_runs(&kept, false, 4 * 2 * 256), [0..2, 2..4]);
        assert_eq!(batch_runs(&kept, false, 4 * 4 * 256), vec![0..4]);
    }

    #[test]
    fn builds_start_at_workgroup_multiples_with_their_own_scratch() {
        let build = |count| BatchBuild {
            count,
            tri_src_base: 7,
            tri_dst_base: 9,
            node_base: 11,
            bounds_base: 13,
            max_leaf: 4,
            kept: None,
        };
        let l = Layout::of(&[build(1), build(300), build(256)], true).unwrap();
        let starts: Vec<u32> = l.segs.iter().map(|s| s.key_base).collect();
        assert_eq!(starts, [0, 256, 768]);
        assert_eq!(l.positions, 1024);
        let work: Vec<u32> = l.segs.iter().map(|s| s.work_base).collect();
        assert_eq!(
            work,
            [
                0,
                clustered_work_words(1) as u32,
                (clustered_work_words(1) + clustered_work_words(300)) as u32
            ]
        );
        assert!(l.segs.iter().all(|s| s.karras_base == s.topo_base));
        assert!(Layout::of(&[build(MAX_COUNT), build(1)], true).is_none());
    }
}
