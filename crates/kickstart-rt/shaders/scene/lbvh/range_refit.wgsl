// Range refit of a BLAS: the refit of a Karras tree (one triangle a leaf, sorted-position refs)
// from its re-ingested triangles, without the climb (docs/ray-tracing-core.md, "Refit").
//
// Every inner node of a Karras tree covers one range of sorted positions (the other end than
// its own index is in the topology), and the box of any range is the union of at most two boxes
// per level of the *box pyramid* over the sorted leaf boxes: level 0 is the n leaf boxes, level
// L >= 1 holds ceil(n / 2^L) boxes, box i of it the union of boxes 2i and 2i + 1 of level L - 1
// (only 2i at the end of an odd level). Levels 1..=REFIT_WG_LEVELS follow each other in `pyramid`
// (two vec4 a box: min, max; level 0 is never stored), the levels above are in `work`;
// src/scene/lbvh/refit.rs sizes `pyramid` by the same sum (`pyramid_boxes` less level 0). So each
// node's boxes are computed on their own, in two passes and without arrival counters per node
// or chains of device-scope round trips:
//   lbvh_refit_gather  per sorted position, workgroups of WG: gathers the triangle into sorted
//                      order (as gather_triangles), makes its box and levels 0..=REFIT_WG_LEVELS
//                      of the pyramid over the workgroup's block in workgroup memory, writes
//                      levels 1.. out, writes every node whose range lies inside the block (most
//                      nodes: a node of s leaves straddles a block boundary with probability
//                      ~ s / WG), lists the others, and merges its top box into every level
//                      above with atomicMax (no pass of its own, no fence, no waiting)
//   lbvh_range_refit   per block, its listed nodes (those straddling blocks), from `pyramid`,
//                      the upper levels and the gathered triangles (leaf boxes), one
//                      invocation a node walking its two children side by side (range_boxes;
//                      spreading a node's levels over invocations joined through workgroup
//                      memory measured slower on the H100: docs/decisions/range-refit.md)
//   lbvh_refit_ingest  lbvh_refit_gather decoding each triangle from the application's bytes
//                      (the ingestion fused into the refit)
// The boxes are the same unions of the same leaf boxes as the climb's, so the nodes are
// bit-identical to a climb's.

#import scene/lbvh/common
#import scene/ingest_decode

// Levels the gather's workgroup makes of its block (WG = 2^8 leaves, down to one box).
const REFIT_WG_LEVELS: u32 = 8u;

// Boxes of the level above a level of `count` boxes (n <= 2^28: no overflow).
fn pyramid_parent_count(count: u32) -> u32 {
    return (count + 1u) / 2u;
}

// Boxes in level `level` of the pyramid over n boxes.
fn pyramid_level_count(n: u32, level: u32) -> u32 {
    var count = n;
    for (var l = 0u; l < level; l++) {
        count = pyramid_parent_count(count);
    }
    return count;
}

@group(0) @binding(11) var<storage, read_write> pyramid: array<vec4<f32>>;

// Box `at` of the pyramid (counted from level 0's first box, so at >= n: level 0 itself is never
// stored, as leaf boxes come from the gathered triangles and workgroup memory), canonical when
// empty.
fn pyramid_box(at: u32) -> Box {
    let i = 2u * (seg.pyramid_base + at - seg.count);
    return stored_box(pyramid[i].xyz, pyramid[i + 1u].xyz);
}

fn pyramid_store(at: u32, b: Box) {
    let i = 2u * (seg.pyramid_base + at - seg.count);
    pyramid[i] = vec4<f32>(b.lo, 0.0);
    pyramid[i + 1u] = vec4<f32>(b.hi, 0.0);
}

// The block's pyramid: level L (0..=REFIT_WG_LEVELS) at slots [2 WG - 2 WG / 2^L, + WG / 2^L),
// 2 WG - 1 slots in all (the top box at 2 WG - 2). Not one more: with wg_straddlers the gather's
// workgroup memory stays within WebGPU's default 16384 bytes (Dawn rounds each variable up to 16
// bytes: 2 x 511 x 16 + 16 = 16368; with 512 slots, 16400 failed pipeline creation).
var<workgroup> wg_pyramid_lo: array<vec3<f32>, 511>;
var<workgroup> wg_pyramid_hi: array<vec3<f32>, 511>;

fn wg_pyramid_box(slot: u32) -> Box {
    return Box(wg_pyramid_lo[slot], wg_pyramid_hi[slot]);
}

// First slot of level `level` of the block's pyramid.
fn wg_level_slot(level: u32) -> u32 {
    return 2u * WG - ((2u * WG) >> level);
}

// The union of leaf boxes [a, b] (a <= b), positions relative to the block, from the block's
// pyramid; the same steps as range_box.
fn wg_range_box(a: u32, b: u32) -> Box {
    var acc = empty_box();
    var l = a;
    var r = b + 1u;
    var level = 0u;
    while l < r {
        let at = wg_level_slot(level);
        if (l & 1u) != 0u {
            acc = union_box(acc, wg_pyramid_box(at + l));
            l += 1u;
        }
        if (r & 1u) != 0u {
            r -= 1u;
            acc = union_box(acc, wg_pyramid_box(at + r));
        }
        l >>= 1u;
        r >>= 1u;
        level += 1u;
    }
    return acc;
}

// Inner node i's leaf range [first, last] (Karras tree, n >= 2, i < n - 1).
fn node_range(i: u32) -> vec2<u32> {
    let j = topology[range_ends_at() + i];
    return vec2<u32>(min(i, j), max(i, j));
}

// Writes inner node i (children lc, rc: left over [first, g], right over [g + 1, last]) from
// its children's boxes, and the root's box to bounds_out.
fn write_ranged_node(i: u32, lc: u32, rc: u32, lb: Box, rb: Box) {
    write_node(i, lb, out_ref(lc), rb, out_ref(rc));
    if i == 0u {
        write_bounds(union_box(lb, rb));
    }
}

// `work` during a range refit (u32 words, atomic), nb = ceil(n / WG) blocks:
//   [8, 8 + WG nb)                 per block, its inner nodes whose range straddles blocks
//   [8 + WG nb, 8 + (WG + 1) nb)   per block, how many
//   [8 + (WG + 1) nb, + 6 U)       the pyramid's levels above REFIT_WG_LEVELS (U boxes in all),
//                                  6 words a box in scene/centroid_bounds.wgsl's encoding (~enc(min),
//                                  enc(max)): every block merges its top box into each of its
//                                  ancestors with atomicMax, so they need no pass, no fence and
//                                  no waiting (cleared before the refit: zero is the identity)
// All from the refit's seg.work_base (its own region in a batch). src/scene/lbvh/refit.rs's
// `range_refit_work` is the same layout.
fn straddle_list_at() -> u32 {
    return 8u;
}

fn straddle_counts_at(nb: u32) -> u32 {
    return 8u + WG * nb;
}

// Word of box i of pyramid level `level` (> REFIT_WG_LEVELS) in `work`.
fn upper_box_at(level: u32, i: u32) -> u32 {
    let n = seg.count;
    var start = 0u;
    var count = pyramid_level_count(n, REFIT_WG_LEVELS + 1u);
    for (var l = REFIT_WG_LEVELS + 1u; l < level; l++) {
        start += count;
        count = pyramid_parent_count(count);
    }
    let nb = (n + WG - 1u) / WG;
    return 8u + (WG + 1u) * nb + 6u * (start + i);
}

// lbvh_range_refit reads `work` through this read-only binding of the same buffer instead of
// binding 2: plain loads may be served by the L1 cache, where atomic loads of binding 2 always
// go to L2, and the upper levels and the list are read-only by then (the gather is done).
@group(0) @binding(17) var<storage, read> work_read: array<u32>;

fn upper_box(at: u32) -> Box {
    return Box(
        vec3<f32>(dec(~work_read[at]), dec(~work_read[at + 1u]), dec(~work_read[at + 2u])),
        vec3<f32>(dec(work_read[at + 3u]), dec(work_read[at + 4u]), dec(work_read[at + 5u])));
}

var<workgroup> wg_straddlers: atomic<u32>;

// lbvh_refit_ingest: the application's bytes (scene/ingest_decode.wgsl reads them as `raw`), the
// geometries' component rows (as scene/ingest.wgsl's table, each refit's from its row_base; at
// most REFIT_INGEST_ROWS a dispatch: a uniform keeps the entry point within 8 storage buffers)
// and their dropped-triangle counters.
const REFIT_INGEST_ROWS: u32 = 512u;
@group(0) @binding(14) var<storage, read> raw: array<u32>;
@group(0) @binding(15) var<uniform> ingest_rows: array<Component, REFIT_INGEST_ROWS>;
@group(0) @binding(16) var<storage, read_write> ingest_counters: array<atomic<u32>>;

// A batch of range refits (src/scene/lbvh/refit.rs): every refit of a task in the same two
// passes, whatever their number. Each refit takes ceil(count / WG) whole workgroups from its
// key_base (a multiple of WG: the batch's positions), so a workgroup's blocks, pyramid and
// straddling list are those of one refit, and every workgroup finds its refit here. A uniform,
// not a storage buffer: the gather and the fused ingestion bind 8 storage buffers already.
// params.count is the number of refits in use.
const REFIT_BATCH: u32 = 512u;
@group(0) @binding(19) var<uniform> refit_segs: array<Params, REFIT_BATCH>;

// Sets `seg` to the refit that batch position g belongs to (the last whose key_base <= g) and
// returns g's sorted position within it.
fn enter_refit(g: u32) -> u32 {
    var lo = 0u;
    var hi = min(params.count, REFIT_BATCH);
    while hi - lo > 1u {
        let mid = (lo + hi) / 2u;
        if refit_segs[mid].key_base <= g {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    seg = refit_segs[lo];
    return g - seg.key_base;
}

@compute @workgroup_size(256)
fn lbvh_refit_gather(@builtin(local_invocation_index) lid: u32,
                     @builtin(workgroup_id) wid: vec3<u32>,
                     @builtin(num_workgroups) nwg: vec3<u32>) {
    let k = enter_refit(linear_id(lid, wid, nwg));
    let n = seg.count;
    let node = node_topology(k);
    // Past the end (and for dropped triangles): the empty box.
    var b = empty_box();
    if k < n {
        let s = 3u * (seg.tri_src_base + order[seg.order_base + k]);
        b = store_gathered(k, refit_src[s], refit_src[s + 1u], refit_src[s + 2u]);
    }
    let root = refit_block(lid, k, b, node);
    // With one block the root lies inside it (with more, lbvh_range_refit writes it).
    if k == 0u && n <= WG {
        write_bounds(root);
    }
}

// lbvh_refit_gather fused with the ingestion, for a refit in the task that ingests the geometry
// (n > WG: the root is written by lbvh_range_refit, so there is no bounds_out here): each
// invocation decodes its sorted position's triangle from the application's bytes, as
// scene/ingest.wgsl would have into the staged triangles, and counts it if dropped. The staged
// triangles are not written: the ingestion pass, its writes and the gather's random reads of
// them are saved.
@compute @workgroup_size(256)
fn lbvh_refit_ingest(@builtin(local_invocation_index) lid: u32,
                     @builtin(workgroup_id) wid: vec3<u32>,
                     @builtin(num_workgroups) nwg: vec3<u32>) {
    let k = enter_refit(linear_id(lid, wid, nwg));
    let n = seg.count;
    let node = node_topology(k);
    var b = empty_box();
    if k < n {
        let p = order[seg.order_base + k];
        // The refit's last row whose tri_start <= p (its rows are sorted by tri_start, the first
        // starts at 0; a geometry's triangle index is its ingestion index).
        var lo = seg.row_base;
        var hi = min(seg.row_base + seg.ingest_row_count, REFIT_INGEST_ROWS);
        while hi - lo > 1u {
            let mid = (lo + hi) / 2u;
            if ingest_rows[mid].tri_start <= p {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let tri = ingest_triangle(ingest_rows[lo], p - ingest_rows[lo].tri_start);
        if tri.dropped != 0u {
            atomicAdd(&ingest_counters[seg.ingest_counter + tri.dropped - 1u], 1u);
        }
        b = store_gathered(k, bitcast<vec4<u32>>(tri.v0), bitcast<vec4<u32>>(tri.v1),
                           bitcast<vec4<u32>>(tri.v2));
    }
    refit_block(lid, k, b, node);
}

// Inner node k's topology words for refit_block (k < n - 1), loaded before the triangle so
// their latency overlaps its fetch instead of following the workgroup's barriers.
struct NodeTopology {
    other_end: u32,
    lc: u32,
    rc: u32,
}

fn node_topology(k: u32) -> NodeTopology {
    if k + 1u >= seg.count {
        return NodeTopology(0u, 0u, 0u);
    }
    return NodeTopology(topology[range_ends_at() + k], topology[seg.topo_base + 2u * k],
                        topology[seg.topo_base + 2u * k + 1u]);
}

// The rest of the refit gather, after invocation lid's leaf box b (sorted position k; the empty
// box past the end, reached by the whole workgroup for its barriers): the block's pyramid, its
// in-block nodes, the straddling list and the upper levels. Returns the root's box when this
// invocation wrote the root (only with one block), else the empty box.
fn refit_block(lid: u32, k: u32, b: Box, node: NodeTopology) -> Box {
    // The workgroup's refit (the same in all its invocations, but `seg` is a private variable,
    // not uniform: no barrier below depends on it).
    let n = seg.count;
    let block = k - lid;
    let nb = (n + WG - 1u) / WG;
    if lid == 0u {
        atomicStore(&wg_straddlers, 0u);
    }
    // Level 0 stays in workgroup memory only: lbvh_range_refit reads a leaf's box from its
    // gathered triangle (it needs few).
    wg_pyramid_lo[lid] = b.lo;
    wg_pyramid_hi[lid] = b.hi;
    var start = 0u;
    var count = n;
    for (var level = 1u; level <= REFIT_WG_LEVELS; level++) {
        workgroupBarrier();
        // The pyramid ends at its level of one box, and no range needs more.
        if count > 1u {
            start += count;
            count = pyramid_parent_count(count);
            if lid < (WG >> level) {
                let below = wg_level_slot(level - 1u) + 2u * lid;
                let up = union_box(wg_pyramid_box(below), wg_pyramid_box(below + 1u));
                let slot = wg_level_slot(level) + lid;
                wg_pyramid_lo[slot] = up.lo;
                wg_pyramid_hi[slot] = up.hi;
                let i = (block >> level) + lid;
                if i < count {
                    pyramid_store(start + i, up);
                }
            }
        }
    }
    workgroupBarrier();
    // Inner node k: from workgroup memory when its range lies inside the block (k is one end of
    // it, so the block is k's); otherwise it goes on the block's list for lbvh_range_refit.
    let w = block / WG;
    var root = empty_box();
    if k + 1u < n {
        let range = vec2<u32>(min(k, node.other_end), max(k, node.other_end));
        if range.x >= block && range.y < block + WG {
            let lc = node.lc;
            let rc = node.rc;
            let g = lc & 0x7fffffffu;
            let lb = wg_range_box(range.x - block, g - block);
            let rb = wg_range_box(g + 1u - block, range.y - block);
            write_node(k, lb, out_ref(lc), rb, out_ref(rc));
            if k == 0u {
                root = union_box(lb, rb);
            }
        } else {
            let slot = atomicAdd(&wg_straddlers, 1u);
            atomicStore(&work[seg.work_base + straddle_list_at() + block + slot], k);
        }
    }
    workgroupBarrier();
    if lid == 0u {
        atomicStore(&work[seg.work_base + straddle_counts_at(nb) + w], atomicLoad(&wg_straddlers));
    }
    // The levels above the block's: its top box (level REFIT_WG_LEVELS; with one block the
    // pyramid is complete) merged into each ancestor, one word an invocation.
    if nb > 1u {
        let top = wg_pyramid_box(wg_level_slot(REFIT_WG_LEVELS));
        let up = lid / 6u;
        let word = lid % 6u;
        let level = REFIT_WG_LEVELS + 1u + up;
        if pyramid_level_count(n, level - 1u) > 1u {
            let at = upper_box_at(level, w >> (up + 1u)) + word;
            let bounds = array<f32, 6>(top.lo.x, top.lo.y, top.lo.z, top.hi.x, top.hi.y, top.hi.z);
            let v = enc(bounds[word]);
            atomicMax(&work[seg.work_base + at], select(v, ~v, word < 3u));
        }
    }
    return root;
}

// Writes sorted position k's triangle into the BLAS's triangles and returns its box.
fn store_gathered(k: u32, v0: vec4<u32>, v1: vec4<u32>, v2: vec4<u32>) -> Box {
    let d = 3u * (seg.tri_dst_base + k);
    refit_dst[d] = v0;
    refit_dst[d + 1u] = v1;
    refit_dst[d + 2u] = v2;
    return leaf_triangle_box(v0, v1, v2);
}

// A gathered triangle's box (scene/triangle_box.wgsl's rule), canonical when empty.
fn leaf_triangle_box(v0: vec4<u32>, v1: vec4<u32>, v2: vec4<u32>) -> Box {
    let stored = triangle_box(bitcast<vec4<f32>>(v0), bitcast<vec4<f32>>(v1),
                              bitcast<vec4<f32>>(v2));
    return stored_box(stored.lo.xyz, stored.hi.xyz);
}

// The box of leaf k from its gathered triangle (lbvh_refit_gather wrote it).
fn gathered_leaf_box(k: u32) -> Box {
    let d = 3u * (seg.tri_dst_base + k);
    return leaf_triangle_box(refit_dst[d], refit_dst[d + 1u], refit_dst[d + 2u]);
}

// A bottom-up walk over the pyramid for the union of leaf boxes [a, b] (sorted positions,
// a <= b): l = a, r = b + 1; at each level the range's odd first box (l) and even last box
// (r - 1, when r is odd) are taken and the rest is left to the level above (l, r halved).
struct Walk {
    l: u32,
    r: u32,
    acc: Box,
}

fn walk_takes_l(w: Walk) -> bool {
    return w.l < w.r && (w.l & 1u) != 0u;
}

fn walk_takes_r(w: Walk) -> bool {
    return w.l < w.r && (w.r & 1u) != 0u;
}

// The level's boxes a walk may take (index 0 in place of one it does not take): the caller
// loads both unconditionally, so all its loads of a level are issued before any is waited for.
fn walk_l(w: Walk) -> u32 {
    return select(0u, w.l, walk_takes_l(w));
}

fn walk_r(w: Walk) -> u32 {
    return select(0u, w.r - 1u, walk_takes_r(w));
}

// One level of a walk, given the boxes at walk_l and walk_r (l and r - 1 are distinct when
// both are taken: both odd and l < r).
fn walk_step(w: Walk, lbox: Box, rbox: Box) -> Walk {
    var acc = w.acc;
    let take_l = walk_takes_l(w);
    let take_r = walk_takes_r(w);
    if take_l {
        acc = union_box(acc, lbox);
    }
    if take_r {
        acc = union_box(acc, rbox);
    }
    return Walk(select(w.l, w.l + 1u, take_l) >> 1u, select(w.r, w.r - 1u, take_r) >> 1u, acc);
}

fn walks_live(w0: Walk, w1: Walk) -> bool {
    return w0.l < w0.r || w1.l < w1.r;
}

// The unions of leaf boxes [a0, b0] and [a1, b1] (a node's two children), walked side by side
// so that each level's up to four box loads are in flight together: one node's walk was a
// chain of dependent loads, about 40 for the root's children, and the longest chain was what
// lbvh range refit took (docs/decisions/range-refit.md). Level 0 comes from the gathered
// triangles, the blocks' levels from `pyramid`, the levels above from `work_read`; a loop each
// (one loop choosing the source per box measured slower on the H100).
fn range_boxes(a0: u32, b0: u32, a1: u32, b1: u32) -> array<Box, 2> {
    var w0 = Walk(a0, b0 + 1u, empty_box());
    var w1 = Walk(a1, b1 + 1u, empty_box());
    {
        let l0 = gathered_leaf_box(walk_l(w0));
        let r0 = gathered_leaf_box(walk_r(w0));
        let l1 = gathered_leaf_box(walk_l(w1));
        let r1 = gathered_leaf_box(walk_r(w1));
        w0 = walk_step(w0, l0, r0);
        w1 = walk_step(w1, l1, r1);
    }
    var start = seg.count;
    var count = pyramid_parent_count(seg.count);
    var level = 1u;
    // The walks end when their ranges are used up, at the latest at the level of one box.
    while walks_live(w0, w1) && level <= REFIT_WG_LEVELS {
        let l0 = pyramid_box(start + walk_l(w0));
        let r0 = pyramid_box(start + walk_r(w0));
        let l1 = pyramid_box(start + walk_l(w1));
        let r1 = pyramid_box(start + walk_r(w1));
        w0 = walk_step(w0, l0, r0);
        w1 = walk_step(w1, l1, r1);
        start += count;
        count = pyramid_parent_count(count);
        level += 1u;
    }
    // Above the blocks' levels: box i of a level 6 words after box i - 1.
    if walks_live(w0, w1) {
        var at = seg.work_base + upper_box_at(level, 0u);
        while walks_live(w0, w1) {
            let l0 = upper_box(at + 6u * walk_l(w0));
            let r0 = upper_box(at + 6u * walk_r(w0));
            let l1 = upper_box(at + 6u * walk_l(w1));
            let r1 = upper_box(at + 6u * walk_r(w1));
            w0 = walk_step(w0, l0, r0);
            w1 = walk_step(w1, l1, r1);
            at += 6u * count;
            count = pyramid_parent_count(count);
        }
    }
    return array<Box, 2>(w0.acc, w1.acc);
}

// One workgroup per block of every refit of the batch (a refit of one block has none): the
// block's inner nodes whose range straddles blocks, from the list lbvh_refit_gather made, so the invocations that work are packed into few subgroups
// (about one node in eight straddles on the dragon).
@compute @workgroup_size(256)
fn lbvh_range_refit(@builtin(local_invocation_index) lid: u32,
                    @builtin(workgroup_id) wid: vec3<u32>,
                    @builtin(num_workgroups) nwg: vec3<u32>) {
    let w = enter_refit((wid.y * nwg.x + wid.x) * WG) / WG;
    let nb = (seg.count + WG - 1u) / WG;
    if w >= nb || lid >= work_read[seg.work_base + straddle_counts_at(nb) + w] {
        return;
    }
    let i = work_read[seg.work_base + straddle_list_at() + w * WG + lid];
    let range = node_range(i);
    let lc = topology[seg.topo_base + 2u * i];
    let rc = topology[seg.topo_base + 2u * i + 1u];
    let g = lc & 0x7fffffffu;
    let boxes = range_boxes(range.x, g, g + 1u, range.y);
    write_ranged_node(i, lc, rc, boxes[0], boxes[1]);
}
