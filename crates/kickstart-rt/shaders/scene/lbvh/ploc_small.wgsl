// A small clustered build in one workgroup: PLOC (Meister & Bittner 2018) over the Morton-sorted
// primitives of a build of at most PS_MAX of them (the clustered TLAS of opened instances), every
// round behind workgroup barriers. The climb of scene/lbvh/hploc.wgsl pays device-scope round
// trips at every level of the Karras tree and ran 0.33 ms on the apartment's 2,010 refs on an
// H200 (docs/decisions/tlas-build.md); here one workgroup holds the whole build, so a round costs
// a few barriers and the loads of its neighbours' boxes from the L1 cache.
//
// Entry point (PS_WG invocations, one workgroup; after the sort, in place of lbvh_hierarchy and
// hploc_climb; the sorted pairs bound at `keys` and `values`):
//   ploc_small  writes `order` (the sorted values), then clusters: at first every sorted position
//               is one (its leaf), then rounds of PLOC until one is left. A round: every cluster
//               finds the neighbour within HP_RADIUS (in cluster order) whose union box has the
//               least area (ties as hp_tie_before orders them, so the pair of least area overall
//               is mutual and every round merges); mutual pairs merge into a new node, the left
//               one holding it, the right one leaving; the clusters left close ranks (a prefix
//               sum over the workgroup). Each merge writes its node in the final format and, in
//               `topo_out`, the topology of scene/lbvh/lbvh.wgsl (so lbvh_climb refits it).
//
// Output node slots: the n - 1 merges take slots from n - 2 down, each round's in the order of its
// clusters, so the last merge (the root) is node 0, where traversal starts, and the tree is the
// same on every build of the same input.
//
// Scratch: the clusters' boxes in `pyramid` (two vec4 a cluster: lo, hi; round parity picks the
// half [0, 2n) or [2n, 4n)), their refs (output node index, or LEAF_BIT | sorted position) in
// `work` from BOXES_AT (the halves [0, n) and [n, 2n)), each cluster's nearest neighbour in `keys`
// (the sorted keys are not needed once the order is written). Boxes and neighbours are plain
// loads and stores, ordered by storageBarrier within the one workgroup.

#import scene/lbvh/hploc

// Invocations of the one workgroup, and the most primitives it builds over.
const PS_WG: u32 = 256u;
const PS_MAX: u32 = 2048u;
// Clusters each invocation holds: a contiguous run, so the prefix sum is over PS_WG partials.
const PS_PER: u32 = PS_MAX / PS_WG;

// Per invocation, its run's clusters kept (low 16 bits) and merges (high 16 bits), scanned.
var<workgroup> ps_scan: array<u32, PS_WG>;
// Clusters left, and the slot below which this round's merges take theirs.
var<workgroup> ps_count: u32;
var<workgroup> ps_next: u32;

fn ps_box(half: u32, i: u32) -> Box {
    let at = 2u * (half * seg.count + i);
    return Box(pyramid[at].xyz, pyramid[at + 1u].xyz);
}

fn ps_put_box(half: u32, i: u32, b: Box) {
    let at = 2u * (half * seg.count + i);
    pyramid[at] = vec4<f32>(b.lo, 0.0);
    pyramid[at + 1u] = vec4<f32>(b.hi, 0.0);
}

fn ps_ref(half: u32, i: u32) -> u32 {
    return atomicLoad(&work[seg.work_base + BOXES_AT + half * seg.count + i]);
}

fn ps_put_ref(half: u32, i: u32, r: u32) {
    atomicStore(&work[seg.work_base + BOXES_AT + half * seg.count + i], r);
}

// The nearest neighbour of cluster i of `count` (a total order: see hp_tie_before).
fn ps_nearest(half: u32, i: u32, count: u32) -> u32 {
    let b = ps_box(half, i);
    var best = HP_NONE;
    var best_area = 0.0;
    let m_end = min(count, i + HP_RADIUS + 1u);
    for (var m = select(0u, i - HP_RADIUS, i > HP_RADIUS); m < m_end; m++) {
        if m == i {
            continue;
        }
        let a = hp_area(union_box(b, ps_box(half, m)));
        if best == HP_NONE || a < best_area || (a == best_area && hp_tie_before(i, m, best)) {
            best = m;
            best_area = a;
        }
    }
    return best;
}

@compute @workgroup_size(256)
fn ploc_small(@builtin(local_invocation_index) lid: u32) {
    // A single build (its params: `segs` would be a ninth storage buffer). Uniform: the count.
    seg = params;
    let n = min(params.count, PS_MAX);
    let first = lid * PS_PER;
    for (var j = 0u; j < PS_PER; j++) {
        let k = first + j;
        if k < n {
            order[seg.order_base + k] = values[k];
        }
    }
    // The order is read by every leaf's box and by out_ref below.
    storageBarrier();
    for (var j = 0u; j < PS_PER; j++) {
        let k = first + j;
        if k < n {
            ps_put_box(0u, k, leaf_box(k));
            ps_put_ref(0u, k, LEAF_BIT | k);
        }
    }
    if lid == 0u {
        ps_count = n;
        ps_next = n - 1u;
    }
    storageBarrier();

    // Every round merges at least once, so n - 1 rounds always suffice.
    for (var round = 0u; round + 1u < n; round++) {
        let count = workgroupUniformLoad(&ps_count);
        if count <= 1u {
            break;
        }
        let cur = round & 1u;
        let nxt = cur ^ 1u;
        for (var j = 0u; j < PS_PER; j++) {
            let i = first + j;
            if i < count {
                keys[i] = ps_nearest(cur, i, count);
            }
        }
        storageBarrier();
        // This run's clusters: kept (bit j) and merging (bit 8 + j), then their counts.
        var kept = 0u;
        var merged = 0u;
        for (var j = 0u; j < PS_PER; j++) {
            let i = first + j;
            if i < count {
                let m = keys[i];
                let mutual = keys[m] == i;
                if !mutual || i < m {
                    kept |= 1u << j;
                }
                if mutual && i < m {
                    merged |= 1u << j;
                }
            }
        }
        ps_scan[lid] = countOneBits(kept) | (countOneBits(merged) << 16u);
        // Inclusive prefix sum (Hillis-Steele) over the runs.
        for (var d = 1u; d < PS_WG; d <<= 1u) {
            workgroupBarrier();
            var add = 0u;
            if lid >= d {
                add = ps_scan[lid - d];
            }
            workgroupBarrier();
            ps_scan[lid] += add;
        }
        workgroupBarrier();
        let mine = countOneBits(kept) | (countOneBits(merged) << 16u);
        let before = ps_scan[lid] - mine;
        let total = ps_scan[PS_WG - 1u];
        let next = ps_next;
        var at = before & 0xffffu;
        var rank = before >> 16u;
        for (var j = 0u; j < PS_PER; j++) {
            let i = first + j;
            if (kept & (1u << j)) != 0u {
                var r = ps_ref(cur, i);
                var b = ps_box(cur, i);
                if (merged & (1u << j)) != 0u {
                    let m = keys[i];
                    let mr = ps_ref(cur, m);
                    let mb = ps_box(cur, m);
                    let x = next - 1u - rank;
                    rank += 1u;
                    write_node(x, b, out_ref(r), mb, out_ref(mr));
                    topo_out[seg.topo_base + 2u * x] = r;
                    topo_out[seg.topo_base + 2u * x + 1u] = mr;
                    topo_out[hp_parent_slot(r)] = x;
                    topo_out[hp_parent_slot(mr)] = x;
                    r = x;
                    b = union_box(b, mb);
                }
                ps_put_box(nxt, at, b);
                ps_put_ref(nxt, at, r);
                at += 1u;
            }
        }
        // Every invocation has read ps_next and the totals before they change.
        workgroupBarrier();
        if lid == 0u {
            ps_count = total & 0xffffu;
            ps_next = next - (total >> 16u);
        }
        storageBarrier();
    }
    if lid == 0u {
        // The root (node 0) has no parent.
        topo_out[seg.topo_base + 2u * (n - 1u)] = NO_PARENT;
    }
}
