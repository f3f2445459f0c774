//! The refits: the climb over a stored topology ([`Lbvh::refit`]) and the range refit of a
//! fast-build BLAS from its triangles ([`Lbvh::refit_triangles`]; see the module docs of
//! [`super`]).

use super::{
    effective_max_leaf, groups, work_words, Buffers, Lbvh, LbvhRefit, LbvhTriangleRefit, LeafRefs,
    Params, RefitSource, FLAG_SORTED_BOXES, MAX_COUNT, REFIT_INGEST_ROWS, WORKGROUP,
};
use crate::gpu::Recorder;
use crate::scene::ingest::ROW_WORDS;
use bytemuck::Zeroable;

/// Boxes of the box pyramid over `n` boxes (`shaders/scene/lbvh/lbvh.wgsl`, "Range refit"): level 0 (the
/// boxes), then `ceil(n / 2^L)` a level up to the level of one box.
pub(super) fn pyramid_boxes(n: u32) -> u64 {
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
pub(super) const REFIT_GATHER_LEVELS: u32 = WORKGROUP.trailing_zeros();

/// The range refit's layout in `work` (`shaders/scene/lbvh/lbvh.wgsl`, above `straddle_list_at`), for `n`
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
pub(super) fn pyramid_level_count(n: u32, level: u32) -> u32 {
    (0..level).fold(n, |count, _| count.div_ceil(2))
}

impl Lbvh {
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
                karras_base: r.topology.1,
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
            RefitSource::Raw(t) => Some(ingest_rows(device, t.rows)),
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
                karras_base: r.topology.1,
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

/// The uniform of `lbvh refit ingest`'s component rows: `rows` padded to the shader's
/// fixed-length array.
fn ingest_rows(device: &wgpu::Device, rows: &[u32]) -> wgpu::Buffer {
    let mut table = rows.to_vec();
    table.resize(REFIT_INGEST_ROWS * ROW_WORDS, 0);
    crate::gpu::buffers::buffer_init(
        device,
        "lbvh refit ingest rows",
        bytemuck::cast_slice(&table),
        wgpu::BufferUsages::UNIFORM,
    )
}
