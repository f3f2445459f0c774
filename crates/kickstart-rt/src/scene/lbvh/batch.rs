//! A batch of BLAS builds ([`Lbvh::build_batch`]): every fast-trace build of a task in one chain
//! of dispatches, whatever their number and sizes. A build's cost is mostly its chain of
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
//! - hierarchy, clustered climb and triangle gather per build, as a single build does them.

use super::{
    clustered_work_words, effective_max_leaf, groups, Buffers, Lbvh, LeafRefs, Params,
    BLAS_KEY_BITS, FLAG_BOUNDS_OUT, FLAG_TRIANGLE_BOXES, HPLOC_WORKGROUP, MAX_COUNT, WORKGROUP,
};
use crate::gpu::Recorder;

/// One build of a batch: a fast-trace BLAS (clustered, leaves of sorted positions, the
/// triangles gathered into sorted order) whose order and topology are not kept.
#[derive(Debug, Clone, Copy)]
pub(crate) struct BatchBuild {
    /// Triangles (at least 1).
    pub count: u32,
    /// First of its staged triangles in [`LbvhBatch::staged`].
    pub tri_src_base: u32,
    /// First of its BLAS triangles in [`LbvhBatch::triangles`] (output, sorted order).
    pub tri_dst_base: u32,
    /// First of its [`Lbvh::node_count`] nodes in [`LbvhBatch::nodes`].
    pub node_base: u32,
    /// Where its root box goes in [`LbvhBatch::bounds_out`] (vec4 index).
    pub bounds_base: u32,
    /// Largest collapsed leaf.
    pub max_leaf: u32,
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

/// Sort key bits of the build index of `builds` builds (at least 1).
fn segment_bits(builds: usize) -> u32 {
    (usize::BITS - builds.saturating_sub(1).leading_zeros()).max(1)
}

impl Layout {
    fn of(builds: &[BatchBuild]) -> Option<Layout> {
        let mut segs = Vec::with_capacity(builds.len());
        let (mut positions, mut work, mut topology) = (0u64, 0u64, 0u64);
        for b in builds {
            let n = b.count;
            let words = u64::from(Lbvh::topology_words(n));
            segs.push(Params {
                count: n,
                aabb_base: 0,
                node_base: b.node_base,
                order_base: u32::try_from(positions).ok()?,
                topo_base: u32::try_from(topology).ok()?,
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
                karras_base: u32::try_from(topology).ok()?,
                pyramid_base: 0,
                row_base: 0,
                pad: 0,
            });
            positions += u64::from(n.div_ceil(WORKGROUP) * WORKGROUP);
            work += clustered_work_words(n);
            topology += words;
        }
        let positions = u32::try_from(positions).ok().filter(|&p| p <= MAX_COUNT)?;
        Some(Layout {
            segs,
            positions,
            work_words: work,
            topology_words: topology,
        })
    }
}

impl Lbvh {
    /// Records the builds of `b` as one batch (see the module docs). Returns `false`, recording
    /// nothing, when the batch has fewer than two builds, a build of no triangle, or more
    /// positions than a build may have: the caller builds those one by one.
    pub fn build_batch(&mut self, rec: &mut Recorder<'_>, b: &LbvhBatch<'_>) -> bool {
        if b.builds.len() < 2 || b.builds.iter().any(|x| x.count == 0) {
            return false;
        }
        let Some(layout) = Layout::of(b.builds) else {
            return false;
        };
        let device = rec.device;
        let total = layout.positions;
        let work = self.work.get(device, "lbvh work", layout.work_words * 4);
        let keys = self.keys.get(device, "lbvh keys", u64::from(total) * 4);
        let values = self.values.get(device, "lbvh values", u64::from(total) * 4);
        let order = self
            .batch_order
            .get(device, "lbvh batch order", u64::from(total) * 4);
        let karras = self
            .topology
            .get(device, "lbvh topology", layout.topology_words * 4);
        let clustered =
            self.clustered_topology
                .get(device, "hploc topology", layout.topology_words * 4);
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
            ("topo_out", &clustered),
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
        let bg = self.hploc.bind_group(device, "lbvh", 0, &bind);
        rec.dispatch(
            "hploc climb",
            &self.hploc.pipeline,
            &[&bg],
            total / HPLOC_WORKGROUP,
        );
        let bg = self.gather.bind_group(device, "lbvh", 0, &bind);
        rec.dispatch("lbvh gather", &self.gather.pipeline, &[&bg], groups(total));
        true
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

    #[test]
    fn builds_start_at_workgroup_multiples_with_their_own_scratch() {
        let build = |count| BatchBuild {
            count,
            tri_src_base: 7,
            tri_dst_base: 9,
            node_base: 11,
            bounds_base: 13,
            max_leaf: 4,
        };
        let l = Layout::of(&[build(1), build(300), build(256)]).unwrap();
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
        assert!(Layout::of(&[build(MAX_COUNT), build(1)]).is_none());
    }
}
