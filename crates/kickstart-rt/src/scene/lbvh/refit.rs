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

/// Boxes of the box pyramid over `n` boxes (`shaders/scene/lbvh/range_refit.wgsl`): level 0 (the
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

/// Words of the range refit's layout in `work` (`shaders/scene/lbvh/range_refit.wgsl`, above
/// `straddle_list_at`) for `n` triangles in `nb` blocks of 256: the header, the straddling nodes'
/// lists and counts, then the pyramid's levels above the blocks' 8 (6 words a box).
fn range_refit_work(n: u32) -> u64 {
    let nb = u64::from(n.div_ceil(WORKGROUP));
    let block = u64::from(WORKGROUP);
    let mut upper = 0;
    let mut count = nb;
    while count > 1 {
        count = count.div_ceil(2);
        upper += count;
    }
    8 + (block + 1) * nb + 6 * upper
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
        let work = self
            .work
            .get(device, "kickstart-rt lbvh work", work_words(n) * 4);
        let dummy = self.dummy.get(device, "kickstart-rt lbvh no bounds", 32);
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

    /// Records the range refit of a BLAS (see the module docs): a batch of one
    /// ([`Lbvh::refit_triangles_batch`]).
    pub fn refit_triangles(&mut self, rec: &mut Recorder<'_>, r: &LbvhTriangleRefit<'_>) {
        self.refit_triangles_batch(rec, std::slice::from_ref(r));
    }

    /// Records the range refits of a task as one batch: `lbvh refit gather` (or `lbvh refit
    /// ingest` for [`RefitSource::Raw`]) over every refit's blocks, then `lbvh range refit` when
    /// some refit has more than one block of 256 triangles. A refit's cost is mostly its two
    /// dependent dispatches, not its triangles, so a hundred small refits take about what one
    /// refit of their triangles takes. Refits that share their source's kind and buffers go in
    /// one pair of dispatches, up to [`REFIT_BATCH`] refits, [`REFIT_INGEST_ROWS`] component rows
    /// and [`REFIT_BATCH_POSITIONS`] positions a pair (the shader's uniform tables and the
    /// scratch's size); the caller keeps refits of the same kind together. A refit of fewer
    /// than 2 triangles (a refit's tree has inner nodes), or from raw bytes that
    /// [`Lbvh::can_refit_from_raw`] refuses, is skipped with an error.
    pub fn refit_triangles_batch(
        &mut self,
        rec: &mut Recorder<'_>,
        refits: &[LbvhTriangleRefit<'_>],
    ) {
        let valid: Vec<&LbvhTriangleRefit<'_>> = refits
            .iter()
            .filter(|r| Self::range_refit_accepts(r))
            .collect();
        let mut start = 0;
        while start < valid.len() {
            let end = start + chunk_len(&valid[start..]);
            self.record_refit_chunk(rec, &valid[start..end]);
            start = end;
        }
    }

    /// Whether a range refit can run, logging why not.
    fn range_refit_accepts(r: &LbvhTriangleRefit<'_>) -> bool {
        let n = r.count;
        if !(2..=MAX_COUNT).contains(&n) {
            log::error!("LBVH range refit of {n} triangles skipped: it needs 2..={MAX_COUNT}");
            return false;
        }
        if let RefitSource::Raw(raw) = &r.source {
            if !Self::can_refit_from_raw(n, raw.rows) {
                log::error!(
                    "LBVH range refit of {n} triangles ({} component rows) from raw bytes skipped: \
                     it needs more than {WORKGROUP} triangles and at most {REFIT_INGEST_ROWS} rows",
                    raw.rows.len() / ROW_WORDS
                );
                return false;
            }
        }
        true
    }

    /// Records one pair of dispatches over refits that [`chunk_len`] grouped.
    fn record_refit_chunk(&mut self, rec: &mut Recorder<'_>, chunk: &[&LbvhTriangleRefit<'_>]) {
        let Some(first) = chunk.first() else {
            return;
        };
        let device = rec.device;
        let layout = RefitLayout::of(chunk);
        let work = self
            .work
            .get(device, "kickstart-rt lbvh work", layout.work_words * 4);
        let dummy = self.dummy.get(device, "kickstart-rt lbvh no bounds", 32);
        let pyramid = self.pyramid_boxes.get(
            device,
            "kickstart-rt lbvh box pyramid",
            layout.pyramid_boxes.max(1) * 32,
        );
        let bounds_out = first.bounds_out.map_or(&dummy, |(b, _)| b);
        let mut segs = layout.segs;
        segs.resize(REFIT_BATCH, Params::zeroed());
        let segs = crate::gpu::buffers::buffer_init(
            device,
            "lbvh refit segments",
            bytemuck::cast_slice(&segs),
            wgpu::BufferUsages::UNIFORM,
        );
        let params = rec.uniform(
            "lbvh params",
            &Params {
                count: chunk.len() as u32,
                ..Params::zeroed()
            },
        );
        let mut bind: Buffers<'_> = vec![
            ("params", &params),
            ("refit_segs", &segs),
            ("work", &work),
            ("order", first.order),
            ("topology", first.topology.0),
            ("nodes", first.nodes),
            ("bounds_out", bounds_out),
            ("pyramid", &pyramid),
            ("refit_dst", first.dst),
            // The work buffer again, read-only, for the range pass.
            ("work_read", &work),
        ];
        let rows = match &first.source {
            RefitSource::Staged { triangles, .. } => {
                bind.push(("refit_src", triangles));
                None
            }
            RefitSource::Raw(t) => Some((t, ingest_rows(device, &layout.rows))),
        };
        if let Some((t, rows)) = &rows {
            bind.extend([
                ("raw", t.raw),
                ("ingest_rows", rows),
                ("ingest_counters", t.counters),
            ]);
        }
        // The pyramid's levels above the blocks' are merged with atomicMax from zero (the
        // straddling lists need no clearing, but one clear of the chunk's words is one command).
        rec.encoder
            .clear_buffer(&work, 0, Some(layout.work_words * 4));
        let (label, gather) = if rows.is_some() {
            ("lbvh refit ingest", &self.refit_ingest)
        } else {
            ("lbvh refit gather", &self.refit_gather)
        };
        let groups = layout.positions / WORKGROUP;
        let bg = gather.bind_group(device, "lbvh", 0, &bind);
        rec.dispatch(label, &gather.pipeline, &[&bg], groups);
        // Up to one block every node lies inside it: the gather wrote them all.
        if chunk.iter().any(|r| r.count > WORKGROUP) {
            let bg = self.range_refit.bind_group(device, "lbvh", 0, &bind);
            rec.dispatch(
                "lbvh range refit",
                &self.range_refit.pipeline,
                &[&bg],
                groups,
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

/// Range refits one dispatch takes (`REFIT_BATCH` in `shaders/scene/lbvh/range_refit.wgsl`: the size of
/// its uniform table of refits, 40 KiB of WebGPU's default 64 KiB uniform binding).
pub(crate) const REFIT_BATCH: usize = 512;

/// Positions (triangles, each refit's padded to whole blocks of 256) one dispatch of a batch
/// takes, unless a single refit has more: the box pyramid (32 bytes a position) stays within
/// 128 MiB, WebGPU's default largest storage binding.
pub(crate) const REFIT_BATCH_POSITIONS: u32 = 1 << 22;

/// How many of `refits` (at least one) go in the next pair of dispatches: those that share the
/// first's buffers and source kind, within the tables' and the scratch's sizes.
pub(super) fn chunk_len(refits: &[&LbvhTriangleRefit<'_>]) -> usize {
    let Some(first) = refits.first() else {
        return 0;
    };
    let (mut rows, mut positions) = (0usize, 0u32);
    for (i, r) in refits.iter().enumerate() {
        rows += refit_rows(r).len() / ROW_WORDS;
        positions = positions.saturating_add(padded(r.count));
        let fits =
            i < REFIT_BATCH && rows <= REFIT_INGEST_ROWS && positions <= REFIT_BATCH_POSITIONS;
        if i > 0 && !(fits && same_buffers(first, r)) {
            return i;
        }
    }
    refits.len()
}

/// `n` positions rounded up to whole workgroups.
fn padded(n: u32) -> u32 {
    n.div_ceil(WORKGROUP) * WORKGROUP
}

/// A raw refit's component rows (none for staged triangles).
fn refit_rows<'a>(r: &LbvhTriangleRefit<'a>) -> &'a [u32] {
    match &r.source {
        RefitSource::Raw(t) => t.rows,
        RefitSource::Staged { .. } => &[],
    }
}

/// Whether two refits bind the same buffers (and so can share dispatches).
fn same_buffers(a: &LbvhTriangleRefit<'_>, b: &LbvhTriangleRefit<'_>) -> bool {
    let sources = match (&a.source, &b.source) {
        (RefitSource::Staged { triangles: x, .. }, RefitSource::Staged { triangles: y, .. }) => {
            x == y
        }
        (RefitSource::Raw(x), RefitSource::Raw(y)) => x.raw == y.raw && x.counters == y.counters,
        _ => false,
    };
    sources
        && a.dst == b.dst
        && a.nodes == b.nodes
        && a.order == b.order
        && a.topology.0 == b.topology.0
        && a.bounds_out.map(|(x, _)| x) == b.bounds_out.map(|(x, _)| x)
}

/// Where each refit of a chunk lies in the chunk's scratch.
struct RefitLayout {
    segs: Vec<Params>,
    /// The refits' component rows, one after the other.
    rows: Vec<u32>,
    /// Positions of the chunk (the refits' padded counts, summed).
    positions: u32,
    /// Words of `work`, boxes of the pyramid.
    work_words: u64,
    pyramid_boxes: u64,
}

impl RefitLayout {
    /// The layout of refits that [`chunk_len`] grouped (their positions, rows and scratch fit
    /// u32 offsets by its limits).
    fn of(chunk: &[&LbvhTriangleRefit<'_>]) -> RefitLayout {
        let mut l = RefitLayout {
            segs: Vec::with_capacity(chunk.len()),
            rows: Vec::new(),
            positions: 0,
            work_words: 0,
            pyramid_boxes: 0,
        };
        for r in chunk {
            let n = r.count;
            let (src_base, row_count, counter) = match &r.source {
                RefitSource::Staged { base, .. } => (*base, 0, 0),
                RefitSource::Raw(t) => (0, (t.rows.len() / ROW_WORDS) as u32, t.counter_base),
            };
            let (bounds_base, flags) = match r.bounds_out {
                Some((_, base)) => (base, Lbvh::flags(LeafRefs::SortedPosition, true)),
                None => (0, Lbvh::flags(LeafRefs::SortedPosition, false)),
            };
            l.segs.push(Params {
                count: n,
                node_base: r.node_base,
                order_base: r.order_base,
                topo_base: r.topology.1,
                bounds_base,
                flags,
                max_leaf: 1,
                work_base: l.work_words as u32,
                key_base: l.positions,
                tri_src_base: src_base,
                tri_dst_base: r.dst_base,
                ingest_row_count: row_count,
                ingest_counter: counter,
                karras_base: r.topology.1,
                pyramid_base: l.pyramid_boxes as u32,
                row_base: (l.rows.len() / ROW_WORDS) as u32,
                ..Params::zeroed()
            });
            l.rows.extend_from_slice(refit_rows(r));
            l.positions += padded(n);
            l.work_words += range_refit_work(n);
            l.pyramid_boxes += pyramid_boxes(n) - u64::from(n);
        }
        l
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
