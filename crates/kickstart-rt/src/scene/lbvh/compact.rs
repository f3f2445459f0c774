//! BLAS compaction ([`Lbvh::compact`]): after a clustered build with collapsed leaves, the inner
//! nodes of the collapsed subtrees are unreferenced (a fast-trace BLAS's leaves of up to 4
//! triangles leave well over half of its `n - 1` nodes so). The passes of
//! `shaders/scene/lbvh/compact.wgsl` move the reachable nodes to the front of the build's node
//! range, in their old order (the root stays node 0), and write their count, which the caller
//! reads back to give the rest of the range back to the pool. In place, within the same task as
//! the build: nothing else has read the nodes yet, so no reference to them needs updating.

use super::{groups, Buffers, Lbvh};
use crate::gpu::reflect::{ReflectedPipeline, ReflectedShader};
use crate::gpu::Recorder;

/// The compaction's passes, in order.
pub(super) struct CompactPipelines {
    mark: ReflectedPipeline,
    count: ReflectedPipeline,
    scan: ReflectedPipeline,
    assign: ReflectedPipeline,
    scatter: ReflectedPipeline,
}

impl CompactPipelines {
    /// The pipelines of the builder's shader's compaction entry points.
    pub fn new(shader: &ReflectedShader, device: &wgpu::Device) -> Self {
        let pipeline = |label, entry| shader.pipeline(device, label, entry);
        CompactPipelines {
            mark: pipeline("lbvh compact mark", "lbvh_compact_mark"),
            count: pipeline("lbvh compact count", "lbvh_compact_count"),
            scan: pipeline("lbvh compact scan", "lbvh_compact_scan"),
            assign: pipeline("lbvh compact assign", "lbvh_compact_assign"),
            scatter: pipeline("lbvh compact scatter", "lbvh_compact_scatter"),
        }
    }
}

impl Lbvh {
    /// Records the compaction of the clustered builds just climbed, `builds` of them over
    /// `positions` positions of the batch (a single build: one over its count). `bind` is the
    /// climb's: `params`, `segs`, `work` (each build's region zeroed from word
    /// `8 + 16 (n - 1)` for `n - 1` words, which the climb leaves alone), `nodes` and
    /// `topo_out`. Writes build `k`'s node count to word `k` of `counts`.
    pub(super) fn compact(
        &mut self,
        rec: &mut Recorder<'_>,
        bind: &Buffers<'_>,
        (positions, builds): (u32, u32),
        counts: &wgpu::Buffer,
    ) {
        let device = rec.device;
        let blocks = groups(positions);
        let block_words = self.compact_blocks.get(
            device,
            "kickstart-rt lbvh compaction blocks",
            u64::from(blocks) * 4,
        );
        let mut bind = bind.clone();
        bind.push(("compact_blocks", &block_words));
        bind.push(("compact_counts", counts));
        let p = &self.compact;
        for (label, pass, workgroups) in [
            ("lbvh compact mark", &p.mark, blocks),
            ("lbvh compact count", &p.count, blocks),
            ("lbvh compact scan", &p.scan, builds),
            ("lbvh compact assign", &p.assign, blocks),
            ("lbvh compact scatter", &p.scatter, blocks),
        ] {
            let bg = pass.bind_group(device, "lbvh", 0, &bind);
            rec.dispatch(label, &pass.pipeline, &[&bg], workgroups);
        }
    }
}
