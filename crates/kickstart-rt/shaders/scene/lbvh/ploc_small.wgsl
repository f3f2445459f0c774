// A small clustered build in one workgroup: PLOC (Meister & Bittner 2018) over the Morton-sorted
// primitives of a build of at most PS_MAX of them (the clustered TLAS of opened instances),
// every step behind workgroup barriers. The climb of scene/lbvh/hploc.wgsl pays device-scope
// round trips at every level of the Karras tree, plus the separate bounds, Morton, sort and
// hierarchy dispatches (the apartment's 2,010 refs: 0.41 ms on an H200; see
// docs/decisions/tlas-build.md). Here one dispatch does all of it, with the clusters in workgroup
// memory.
//
// Entry point (PS_WG invocations, one workgroup, in place of every pass of the build):
//   ploc_small  1. centroid and box bounds of the primitives (workgroup atomics);
//               2. Morton keys (10 bits an axis) and a bitonic sort of (key, index) pairs;
//               3. `order`, each leaf's exact box (in `pyramid`) and its cluster: a box
//                  quantised to PS_CELLS cells an axis of the primitives' bounds, conservative
//                  (the cells it touches), which is all the neighbour search reads;
//               4. PLOC rounds until one cluster is left: every cluster finds the neighbour
//                  within HP_RADIUS whose union covers the least cell area (ties as
//                  hp_tie_before orders them, so the pair of least area is mutual and every
//                  round merges); mutual pairs merge into a new node, the clusters left close
//                  ranks (a prefix sum over the workgroup). Merges get temporary ids in creation
//                  order (the leaves are 0..n-1, merges n..2n-2); each stores its children, its
//                  leaf count and its exact box;
//               5. the nodes numbered depth first: a node's subtree is one range of indices from
//                  its own (the root is 0), as the climb numbers them. Traversal reads a subtree's
//                  nodes close together; numbering by round, as merges are made, scattered them
//                  and rays traced 8 % slower (docs/decisions/tlas-build.md). Positions go top
//                  down, a round at a time (a node's parent is made in a later round);
//               6. the nodes in the final format and, in `topo_out`, the topology of
//                  scene/lbvh/lbvh.wgsl (so lbvh_climb refits it), and `bounds_out`.
//
// Why quantised clusters: a round reads 2 HP_RADIUS boxes a cluster. From storage, behind the
// storage barriers, that is a chain of L2 loads per invocation on one SM (the first version of
// this pass took 2.7 ms); from workgroup memory it is a few cycles a box. Three words a cluster
// (two 12-bit cells and 8 bits of the cluster's id in the first word, two cells and 4 bits of
// the id in the second, two cells in the third) put 2048 clusters in 24 KiB, and the whole pass
// in PS_WORKGROUP_BYTES, within the 32 KiB that software Vulkan, Metal and browsers offer. The
// cells only steer the pairing; every written box is exact.
//
// `work` (u32 words from seg.work_base, n primitives):
//   [PS_CHILD_AT, + 2 (n-1))   children (temporary ids) of merge n + t at 2t, 2t + 1
//   [PS_SIZE_AT(n), + (n-1))   leaf count of merge n + t
//   [PS_ROUND_AT(n), + n)      first temporary id of round r, then the end of the last round
// `pyramid`: the exact box of temporary id x as two vec4 (lo, hi) at 2x.

#import scene/lbvh/hploc

// Invocations of the one workgroup, the most primitives it builds over, and the clusters each
// invocation decides and moves in a round (a contiguous run, so the prefix sum is over PS_WG
// partials).
const PS_WG: u32 = 256u;
const PS_MAX: u32 = 2048u;
const PS_PER: u32 = 8u;
// Cells an axis of the quantised cluster boxes.
const PS_CELLS: f32 = 4096.0;
const PS_CELL_MASK: u32 = 0xfffu;
// Sort key of empty primitives and of the padding past n: after every Morton code.
const PS_EMPTY_KEY: u32 = 0xffffffffu;
const PS_CHILD_AT: u32 = BOXES_AT;

// The clusters, three words each, word w of cluster i at w * PS_MAX + i (so neighbouring
// invocations read neighbouring words). Before the rounds, the sort's keys ([0, PS_MAX)) and
// indices ([PS_MAX, 2 PS_MAX)); after them, each merge's position ([0, n - 1)) and leaf count
// ([PS_MAX, PS_MAX + n - 1)).
var<workgroup> ps_cluster: array<u32, 6144>;
// Nearest neighbour of cluster i: half i / 1024 of word i % 1024 (the one invocation that
// searches for i also searches for i + 1024, so no word has two writers).
var<workgroup> ps_near: array<u32, 1024>;
// Per invocation, its run's clusters kept (low 16 bits) and merges (high 16 bits), scanned.
var<workgroup> ps_scan: array<u32, PS_WG>;
// Union of the primitives' boxes (the quantisation's frame), encoded as scene/centroid_bounds.
var<workgroup> ps_bounds: array<atomic<u32>, 6>;
// Clusters left, and the next temporary id.
var<workgroup> ps_count: u32;
var<workgroup> ps_next: u32;
// The primitives' box bounds, decoded.
var<private> ps_frame: Box;

fn ps_size_at(n: u32) -> u32 {
    return PS_CHILD_AT + 2u * (n - 1u);
}

fn ps_round_at(n: u32) -> u32 {
    return ps_size_at(n) + n - 1u;
}

// A quantised box: the first and last cell an axis (lo > hi on every axis when empty).
struct PsBox {
    lo: vec3<u32>,
    hi: vec3<u32>,
}

fn ps_load(i: u32) -> vec3<u32> {
    return vec3<u32>(ps_cluster[i], ps_cluster[PS_MAX + i], ps_cluster[2u * PS_MAX + i]);
}

fn ps_store(i: u32, w: vec3<u32>) {
    ps_cluster[i] = w.x;
    ps_cluster[PS_MAX + i] = w.y;
    ps_cluster[2u * PS_MAX + i] = w.z;
}

fn ps_unpack(w: vec3<u32>) -> PsBox {
    return PsBox(vec3<u32>(w.x & PS_CELL_MASK, (w.x >> 12u) & PS_CELL_MASK, w.y & PS_CELL_MASK),
                 vec3<u32>((w.y >> 12u) & PS_CELL_MASK, w.z & PS_CELL_MASK, (w.z >> 12u) & PS_CELL_MASK));
}

// The cluster's id: a temporary id below 2 PS_MAX - 1 (12 bits).
fn ps_id(w: vec3<u32>) -> u32 {
    return (w.x >> 24u) | ((w.y >> 24u) << 8u);
}

fn ps_pack(b: PsBox, id: u32) -> vec3<u32> {
    return vec3<u32>(b.lo.x | (b.lo.y << 12u) | ((id & 0xffu) << 24u),
                     b.lo.z | (b.hi.x << 12u) | ((id >> 8u) << 24u),
                     b.hi.y | (b.hi.z << 12u));
}

fn ps_union(a: PsBox, b: PsBox) -> PsBox {
    return PsBox(min(a.lo, b.lo), max(a.hi, b.hi));
}

// Half the surface area in cells: the cells covered an axis (none where the box is empty).
fn ps_area(b: PsBox) -> f32 {
    let d = vec3<f32>(select(vec3<u32>(0u), b.hi - b.lo + 1u, b.hi >= b.lo));
    return d.x * d.y + d.y * d.z + d.z * d.x;
}

fn ps_quantise(b: Box) -> PsBox {
    if is_empty(b) {
        return PsBox(vec3<u32>(PS_CELL_MASK), vec3<u32>(0u));
    }
    let f = ps_frame;
    return PsBox(vec3<u32>(cell(b.lo.x, f.lo.x, f.hi.x, PS_CELLS), cell(b.lo.y, f.lo.y, f.hi.y, PS_CELLS),
                           cell(b.lo.z, f.lo.z, f.hi.z, PS_CELLS)),
                 vec3<u32>(cell(b.hi.x, f.lo.x, f.hi.x, PS_CELLS), cell(b.hi.y, f.lo.y, f.hi.y, PS_CELLS),
                           cell(b.hi.z, f.lo.z, f.hi.z, PS_CELLS)));
}

fn ps_set_near(i: u32, m: u32) {
    let w = i & 1023u;
    let shift = (i >> 10u) * 16u;
    ps_near[w] = (ps_near[w] & ~(0xffffu << shift)) | (m << shift);
}

fn ps_get_near(i: u32) -> u32 {
    return (ps_near[i & 1023u] >> ((i >> 10u) * 16u)) & 0xffffu;
}

// The nearest neighbour of cluster i of `count` (a total order: see hp_tie_before).
fn ps_nearest(i: u32, count: u32) -> u32 {
    let b = ps_unpack(ps_load(i));
    var best = HP_NONE;
    var best_area = 0.0;
    let m_end = min(count, i + HP_RADIUS + 1u);
    for (var m = select(0u, i - HP_RADIUS, i > HP_RADIUS); m < m_end; m++) {
        if m == i {
            continue;
        }
        let a = ps_area(ps_union(b, ps_unpack(ps_load(m))));
        if best == HP_NONE || a < best_area || (a == best_area && hp_tie_before(i, m, best)) {
            best = m;
            best_area = a;
        }
    }
    return best;
}

fn ps_exact(x: u32) -> Box {
    return Box(pyramid[2u * x].xyz, pyramid[2u * x + 1u].xyz);
}

fn ps_put_exact(x: u32, b: Box) {
    pyramid[2u * x] = vec4<f32>(b.lo, 0.0);
    pyramid[2u * x + 1u] = vec4<f32>(b.hi, 0.0);
}

fn ps_child(n: u32, x: u32, side: u32) -> u32 {
    return atomicLoad(&work[seg.work_base + PS_CHILD_AT + 2u * (x - n) + side]);
}

// Leaves under temporary id x.
fn ps_leaves(n: u32, x: u32) -> u32 {
    if x < n {
        return 1u;
    }
    return atomicLoad(&work[seg.work_base + ps_size_at(n) + x - n]);
}

// Steps 1-3: bounds, keys, the sort, the leaves.
fn ps_leaves_in_order(lid: u32, n: u32) {
    wg_bounds_clear(lid);
    if lid < 6u {
        atomicStore(&ps_bounds[lid], 0u);
    }
    workgroupBarrier();
    for (var j = 0u; j < PS_PER; j++) {
        let i = j * PS_WG + lid;
        if i < n {
            let b = prim_box(i);
            if !is_empty(b) {
                wg_bounds_add(b.lo, b.hi);
                atomicMax(&ps_bounds[0], ~enc(b.lo.x));
                atomicMax(&ps_bounds[1], ~enc(b.lo.y));
                atomicMax(&ps_bounds[2], ~enc(b.lo.z));
                atomicMax(&ps_bounds[3], enc(b.hi.x));
                atomicMax(&ps_bounds[4], enc(b.hi.y));
                atomicMax(&ps_bounds[5], enc(b.hi.z));
            }
        }
    }
    workgroupBarrier();
    // With nothing counted the words stay 0 and decode to NaN: `cell` then gives cell 0.
    let clo = vec3<f32>(dec(~wg_bounds_word(0u)), dec(~wg_bounds_word(1u)), dec(~wg_bounds_word(2u)));
    let chi = vec3<f32>(dec(wg_bounds_word(3u)), dec(wg_bounds_word(4u)), dec(wg_bounds_word(5u)));
    ps_frame = Box(vec3<f32>(dec(~atomicLoad(&ps_bounds[0])), dec(~atomicLoad(&ps_bounds[1])),
                             dec(~atomicLoad(&ps_bounds[2]))),
                   vec3<f32>(dec(atomicLoad(&ps_bounds[3])), dec(atomicLoad(&ps_bounds[4])),
                             dec(atomicLoad(&ps_bounds[5]))));
    for (var j = 0u; j < PS_PER; j++) {
        let i = j * PS_WG + lid;
        var key = PS_EMPTY_KEY;
        if i < n {
            let b = prim_box(i);
            if !is_empty(b) {
                let c = centroid(b);
                key = (spread3(cell(c.x, clo.x, chi.x, 1024.0)) << 2u)
                    | (spread3(cell(c.y, clo.y, chi.y, 1024.0)) << 1u) | spread3(cell(c.z, clo.z, chi.z, 1024.0));
            }
        }
        ps_cluster[i] = key;
        ps_cluster[PS_MAX + i] = i;
    }
    // Bitonic sort of the PS_MAX (key, index) pairs, ascending; the index breaks ties, so the
    // order is the same on every build of the same input.
    for (var k = 2u; k <= PS_MAX; k <<= 1u) {
        for (var d = k >> 1u; d > 0u; d >>= 1u) {
            workgroupBarrier();
            for (var t = 0u; t < PS_MAX / (2u * PS_WG); t++) {
                let p = t * PS_WG + lid;
                let a = 2u * p - (p & (d - 1u));
                let b = a + d;
                let ka = ps_cluster[a];
                let kb = ps_cluster[b];
                let ia = ps_cluster[PS_MAX + a];
                let ib = ps_cluster[PS_MAX + b];
                let a_after = ka > kb || (ka == kb && ia > ib);
                if a_after == ((a & k) == 0u) {
                    ps_cluster[a] = kb;
                    ps_cluster[b] = ka;
                    ps_cluster[PS_MAX + a] = ib;
                    ps_cluster[PS_MAX + b] = ia;
                }
            }
        }
    }
    workgroupBarrier();
    // Position k's index lies in the slot of its cluster's second word: the same invocation
    // reads it and then overwrites it.
    for (var j = 0u; j < PS_PER; j++) {
        let k = j * PS_WG + lid;
        if k < n {
            let p = ps_cluster[PS_MAX + k];
            order[seg.order_base + k] = p;
            let b = prim_box(p);
            ps_put_exact(k, b);
            ps_store(k, ps_pack(ps_quantise(b), k));
        }
    }
}

// One PLOC round over `count` clusters (at least 2), its merges numbered from `next`; returns
// the clusters kept (low 16 bits) and the merges made (high 16 bits).
fn ps_round(lid: u32, n: u32, count: u32, next: u32) -> u32 {
    for (var j = 0u; j < PS_PER; j++) {
        let i = j * PS_WG + lid;
        if i < count {
            ps_set_near(i, ps_nearest(i, count));
        }
    }
    workgroupBarrier();
    // Every read of this round's clusters, into registers, before the prefix sum's barriers:
    // the moves below overwrite them.
    var kept = 0u;
    var merged = 0u;
    var words: array<vec3<u32>, PS_PER>;
    var other: array<u32, PS_PER>;
    let first = lid * PS_PER;
    for (var j = 0u; j < PS_PER; j++) {
        let i = first + j;
        if i < count {
            let m = ps_get_near(i);
            let mutual = ps_get_near(m) == i;
            if !mutual || i < m {
                kept |= 1u << j;
                words[j] = ps_load(i);
                if mutual {
                    merged |= 1u << j;
                    let o = ps_load(m);
                    other[j] = ps_id(o);
                    // The union's cells, and this cluster's id until the merge's is known.
                    words[j] = ps_pack(ps_union(ps_unpack(words[j]), ps_unpack(o)), ps_id(words[j]));
                }
            }
        }
    }
    let mine = countOneBits(kept) | (countOneBits(merged) << 16u);
    ps_scan[lid] = mine;
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
    let before = ps_scan[lid] - mine;
    let total = ps_scan[PS_WG - 1u];
    var at = before & 0xffffu;
    var x = next + (before >> 16u);
    for (var j = 0u; j < PS_PER; j++) {
        if (kept & (1u << j)) != 0u {
            var w = words[j];
            if (merged & (1u << j)) != 0u {
                let a = ps_id(w);
                let b = other[j];
                let t = x - n;
                atomicStore(&work[seg.work_base + PS_CHILD_AT + 2u * t], a);
                atomicStore(&work[seg.work_base + PS_CHILD_AT + 2u * t + 1u], b);
                atomicStore(&work[seg.work_base + ps_size_at(n) + t], ps_leaves(n, a) + ps_leaves(n, b));
                ps_put_exact(x, union_box(ps_exact(a), ps_exact(b)));
                w = ps_pack(ps_unpack(w), x);
                x += 1u;
            }
            ps_store(at, w);
            at += 1u;
        }
    }
    return total;
}

// Step 5: each merge's depth-first position into ps_cluster[x - n].
fn ps_number_depth_first(lid: u32, n: u32, rounds: u32) {
    for (var t = lid; t + 1u < n; t += PS_WG) {
        ps_cluster[PS_MAX + t] = atomicLoad(&work[seg.work_base + ps_size_at(n) + t]);
    }
    if lid == 0u {
        // The last merge is the root.
        ps_cluster[n - 2u] = 0u;
    }
    let rounds_at = seg.work_base + ps_round_at(n);
    for (var r = rounds; r > 0u; r--) {
        workgroupBarrier();
        let end = atomicLoad(&work[rounds_at + r]);
        for (var x = atomicLoad(&work[rounds_at + r - 1u]) + lid; x < end; x += PS_WG) {
            let p = ps_cluster[x - n];
            let a = ps_child(n, x, 0u);
            let b = ps_child(n, x, 1u);
            // Preorder: the node, its first child's subtree (leaves - 1 nodes), the second's.
            var skip = 0u;
            if a >= n {
                ps_cluster[a - n] = p + 1u;
                skip = ps_cluster[PS_MAX + a - n] - 1u;
            }
            if b >= n {
                ps_cluster[b - n] = p + 1u + skip;
            }
        }
    }
    workgroupBarrier();
}

// The child ref of temporary id c in the topology encoding: its node or its leaf.
fn ps_topology_ref(n: u32, c: u32) -> u32 {
    if c < n {
        return LEAF_BIT | c;
    }
    return ps_cluster[c - n];
}

@compute @workgroup_size(256)
fn ploc_small(@builtin(local_invocation_index) lid: u32) {
    // A single build (`segs` would be a ninth storage buffer). Uniform: the count.
    seg = params;
    let n = min(params.count, PS_MAX);
    ps_leaves_in_order(lid, n);
    if lid == 0u {
        ps_count = n;
        ps_next = n;
    }
    // The leaves' exact boxes, for the first round's merges.
    storageBarrier();
    workgroupBarrier();

    // Every round merges at least once, so n - 1 rounds always suffice.
    var rounds = 0u;
    for (var round = 0u; round + 1u < n; round++) {
        let count = workgroupUniformLoad(&ps_count);
        if count <= 1u {
            break;
        }
        let next = ps_next;
        if lid == 0u {
            atomicStore(&work[seg.work_base + ps_round_at(n) + round], next);
        }
        let total = ps_round(lid, n, count, next);
        // Every invocation has read ps_next and the totals before they change.
        workgroupBarrier();
        if lid == 0u {
            ps_count = total & 0xffffu;
            ps_next = next + (total >> 16u);
        }
        rounds = round + 1u;
        // This round's exact boxes, children and leaf counts, for the next round's merges.
        storageBarrier();
        workgroupBarrier();
    }
    if lid == 0u {
        atomicStore(&work[seg.work_base + ps_round_at(n) + rounds], 2u * n - 1u);
    }
    storageBarrier();
    ps_number_depth_first(lid, n, rounds);

    // Step 6: the nodes at their positions, the topology, the root's box.
    for (var x = n + lid; x + 1u < 2u * n; x += PS_WG) {
        let p = ps_cluster[x - n];
        let a = ps_child(n, x, 0u);
        let b = ps_child(n, x, 1u);
        let ta = ps_topology_ref(n, a);
        let tb = ps_topology_ref(n, b);
        let ba = ps_exact(a);
        let bb = ps_exact(b);
        write_node(p, ba, out_ref(ta), bb, out_ref(tb));
        topo_out[seg.topo_base + 2u * p] = ta;
        topo_out[seg.topo_base + 2u * p + 1u] = tb;
        topo_out[hp_parent_slot(ta)] = p;
        topo_out[hp_parent_slot(tb)] = p;
        if p == 0u {
            write_bounds(union_box(ba, bb));
            topo_out[seg.topo_base + 2u * (n - 1u)] = NO_PARENT;
        }
    }
}
