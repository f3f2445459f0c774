//! The build ([`Lbvh::build`]): scratch and parameters, then the passes of the module docs of
//! [`super`] (bounds, morton keys, sort, hierarchy, and the climb or the clustered climb).

use super::{
    clustered_work_words, effective_max_leaf, groups, work_words, Buffers, Lbvh, LbvhBuild, Params,
    BOXES_AT, HPLOC_WORKGROUP, KEY_BITS_RANGE, MAX_COUNT,
};
use crate::gpu::radix_sort::SMALL_POSITIONS_SORT_MAX;
use crate::gpu::Recorder;

/// What one build binds besides the caller's buffers: the builder's scratch, sized for it, and
/// its parameters.
struct BuildScratch {
    /// Centroid bounds, inner boxes, arrival counters (and a clustered build's cluster lists).
    work: wgpu::Buffer,
    /// Sort keys.
    keys: wgpu::Buffer,
    /// Sort values (primitive indices).
    values: wgpu::Buffer,
    /// Bound in place of a missing `bounds_out`.
    dummy: wgpu::Buffer,
    /// The output topology (the caller's or the builder's scratch).
    topology: wgpu::Buffer,
    /// Where the hierarchy pass writes the Karras tree: the output topology unless the build is
    /// clustered (then the builder's scratch).
    karras: wgpu::Buffer,
    /// Params of every pass (a uniform).
    params: wgpu::Buffer,
    /// The same params as a batch of one build (the build passes read `segs`).
    segs: wgpu::Buffer,
    /// Sort key bits, clamped.
    key_bits: u32,
}

impl Lbvh {
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
        let s = self.build_scratch(rec, b, clustered);
        let device = rec.device;
        let bounds_out = b.bounds_out.map_or(&s.dummy, |(buffer, _)| buffer);
        let mut bind: Buffers<'_> = vec![
            ("params", &s.params),
            ("segs", &s.segs),
            ("aabbs", b.aabbs),
            ("work", &s.work),
            ("keys", &s.keys),
            ("values", &s.values),
            ("order", b.order),
            // The hierarchy's Karras tree; `topo_out` is the clustered tree's topology.
            ("topology", &s.karras),
            ("nodes", b.nodes),
            ("bounds_out", bounds_out),
            ("topo_out", &s.topology),
        ];
        // Where the sorted pairs end up (the sort's scratch after an odd number of passes).
        let sorted;
        if n >= 2 {
            sorted = self.record_keys_and_sort(rec, b, &s, &bind);
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
            if let Some(counts) = b.compact_counts {
                // The new-index words (the batch clears its whole work buffer instead).
                let inner = u64::from(n - 1);
                rec.encoder
                    .clear_buffer(&s.work, (BOXES_AT + 16 * inner) * 4, Some(inner * 4));
                self.compact(rec, &bind, (n, 1), counts);
            }
        } else {
            let bg = self.climb.bind_group(device, "lbvh", 0, &bind);
            rec.dispatch("lbvh climb", &self.climb.pipeline, &[&bg], groups(n));
        }
    }

    /// The scratch of a build of `b.count` primitives (grown as needed) and its params.
    fn build_scratch(
        &mut self,
        rec: &Recorder<'_>,
        b: &LbvhBuild<'_>,
        clustered: bool,
    ) -> BuildScratch {
        let n = b.count;
        let device = rec.device;
        let words = if clustered {
            clustered_work_words(n)
        } else {
            work_words(n)
        };
        let work = self.work.get(device, "kickstart-rt lbvh work", words * 4);
        let keys = self
            .keys
            .get(device, "kickstart-rt lbvh keys", u64::from(n) * 4);
        let values = self
            .values
            .get(device, "kickstart-rt lbvh values", u64::from(n) * 4);
        let dummy = self.dummy.get(device, "kickstart-rt lbvh no bounds", 32);
        let topo_bytes = u64::from(Self::topology_words(n)) * 4;
        // The output topology, and where the hierarchy pass writes the Karras tree: the same
        // place unless the build is clustered (then the builder's scratch, at base 0).
        let (topology, topo_base) = match b.topology {
            Some((t, base)) => (t.clone(), base),
            None if clustered => (
                self.clustered_topology
                    .get(device, "kickstart-rt hploc topology", topo_bytes),
                0,
            ),
            None => (
                self.topology
                    .get(device, "kickstart-rt lbvh topology", topo_bytes),
                0,
            ),
        };
        let (karras, karras_base) = if clustered {
            (
                self.topology
                    .get(device, "kickstart-rt lbvh topology", topo_bytes),
                0,
            )
        } else {
            (topology.clone(), topo_base)
        };
        let bounds_base = b.bounds_out.map_or(0, |(_, base)| base);
        let key_bits = b
            .key_bits
            .clamp(*KEY_BITS_RANGE.start(), *KEY_BITS_RANGE.end());
        let params = Params {
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
            work_base: 0,
            key_base: 0,
            tri_src_base: 0,
            tri_dst_base: 0,
            ingest_row_count: 0,
            ingest_counter: 0,
            karras_base,
            pyramid_base: 0,
            row_base: 0,
            pad: 0,
        };
        let segs = rec.storage_init("lbvh segments", bytemuck::bytes_of(&params));
        let params = rec.uniform("lbvh params", &params);
        BuildScratch {
            work,
            keys,
            values,
            dummy,
            topology,
            karras,
            params,
            segs,
            key_bits,
        }
    }

    /// Clears the arrival counters, then records the centroid bounds (unless the caller merged
    /// them), the Morton keys and the sort of `b.count` (at least 2) primitives; returns where
    /// the sorted pairs are.
    fn record_keys_and_sort(
        &mut self,
        rec: &mut Recorder<'_>,
        b: &LbvhBuild<'_>,
        s: &BuildScratch,
        bind: &Buffers<'_>,
    ) -> (wgpu::Buffer, wgpu::Buffer) {
        let (n, key_bits, device) = (b.count, s.key_bits, rec.device);
        Self::clear_arrivals(rec, &s.work, n);
        let mut morton_bind = bind.clone();
        match b.centroid_bounds {
            // The caller's words take the work buffer's place in the morton pass.
            Some((given, _)) => morton_bind.push(("work", given)),
            None => {
                // Centroid-bounds header (zero is the identity of the encoded atomicMax).
                rec.encoder.clear_buffer(&s.work, 0, Some(BOXES_AT * 4));
                let bg = self.bounds.bind_group(device, "lbvh", 0, bind);
                rec.dispatch("lbvh bounds", &self.bounds.pipeline, &[&bg], groups(n));
            }
        }
        // The morton pass writes each value as its position, so up to SMALL_POSITIONS_SORT_MAX
        // keys the sort is one workgroup; a larger sort of digit passes takes its first
        // histogram from the morton pass (one dependent dispatch fewer).
        let first_histogram = if n <= SMALL_POSITIONS_SORT_MAX {
            None
        } else {
            self.sort.first_histogram(device, n, key_bits)
        };
        match first_histogram {
            Some((hist, nblocks)) => {
                morton_bind.push(("sort_hist", &hist));
                let pass = &self.morton_histogram;
                let bg = pass.bind_group(device, "lbvh", 0, &morton_bind);
                rec.dispatch("lbvh morton", &pass.pipeline, &[&bg], nblocks);
                self.sort
                    .record_after_first_histogram(rec, &s.keys, &s.values, n, key_bits)
            }
            None => {
                let bg = self.morton.bind_group(device, "lbvh", 0, &morton_bind);
                rec.dispatch("lbvh morton", &self.morton.pipeline, &[&bg], groups(n));
                self.sort
                    .record_positions(rec, &s.keys, &s.values, n, key_bits)
            }
        }
    }
}
