// In-place compaction of clustered BLAS builds whose leaves were collapsed (the fast-trace
// builds that keep no topology): the collapsed subtrees' inner nodes stay in the node range,
// unreferenced, so the reachable nodes are renumbered in their order and moved to the front of
// the range, and the caller reads back how many there are to give the rest of the range back.
// Runs after `hploc climb`, with the same bindings (a single build is a batch of one).
//
// Entry points (256 invocations, one per position of the batch; `lbvh_compact_scan`: one
// workgroup per build):
//   lbvh_compact_mark     per inner node: copies the node into `work`, and where one of its
//                         refs is a leaf but its topology child is an inner node (a collapsed
//                         subtree), marks that subtree's inner nodes dead (at most
//                         MAX_LEAF - 1 of them: a collapsed subtree holds at most MAX_LEAF
//                         leaves)
//   lbvh_compact_count    per block of 256 positions: its live inner nodes other than the root
//   lbvh_compact_scan     per build: each block's first new index (after the root's 0) and the
//                         build's node count, into compact_counts[build]
//   lbvh_compact_assign   per inner node: its new index (the root keeps 0)
//   lbvh_compact_scatter  per live inner node: the copy, its inner refs renamed, at its new index
//
// Why a scan rather than a global atomic counter: new indices follow the old order, so the
// compacted tree is the same on every build of the same input, and nodes built near each other
// (the clustered climb's merges of one region) stay near each other.
//
// `work` layout of a build (u32 words from seg.work_base, m = count - 1 inner nodes), after the
// climb is done with it:
//   [8, 8 + 16 m)            copy of inner node i at 8 + 16 i (4 vec4, as in `nodes`)
//   [8 + 16 m, 8 + 17 m)     inner node i's new index, DEAD, or 0 (live, before the assign)
//                            (zero before the mark pass: the climb does not use this region)

#import scene/lbvh/common

// Per block of 256 positions of the batch: its live count, then its first new index.
@group(0) @binding(20) var<storage, read_write> compact_blocks: array<u32>;
// Per build of the batch: the compacted node count.
@group(0) @binding(21) var<storage, read_write> compact_counts: array<u32>;

const DEAD: u32 = 0xFFFFFFFFu;
// Inner nodes of a collapsed subtree are at most MAX_LEAF - 1 (7); the walk's stack and its
// bound leave room, and only guard against a malformed topology.
const CP_STACK: u32 = 8u;
const CP_STEPS: u32 = 16u;

var<workgroup> cp_scan: array<u32, 256>;
var<workgroup> cp_blocks: u32;

fn cp_copy_at(i: u32) -> u32 {
    return seg.work_base + BOXES_AT + 16u * i;
}

fn cp_remap_at(i: u32) -> u32 {
    return seg.work_base + BOXES_AT + 16u * (seg.count - 1u) + i;
}

// Whether position `g` of the batch is an inner node of its build (seg must be set).
fn cp_inner(g: u32) -> bool {
    return g < params.count && seg.count >= 2u && g - seg.key_base < seg.count - 1u;
}

// Whether position `g` is a live inner node other than the root (after the mark pass).
fn cp_moves(g: u32) -> bool {
    if !cp_inner(g) {
        return false;
    }
    let i = g - seg.key_base;
    return i != 0u && atomicLoad(&work[cp_remap_at(i)]) != DEAD;
}

// Inclusive sum of `v` over the lanes up to `lid` (Hillis-Steele in workgroup memory); every
// lane must call it.
fn cp_workgroup_scan(lid: u32, v: u32) -> u32 {
    cp_scan[lid] = v;
    workgroupBarrier();
    for (var d = 1u; d < WG; d <<= 1u) {
        var x = cp_scan[lid];
        if lid >= d {
            x += cp_scan[lid - d];
        }
        workgroupBarrier();
        cp_scan[lid] = x;
        workgroupBarrier();
    }
    return cp_scan[lid];
}

// Marks the inner nodes of the collapsed subtree rooted at inner node `root` dead.
fn cp_kill(root: u32) {
    var stack: array<u32, CP_STACK>;
    stack[0] = root;
    var top = 1u;
    for (var step = 0u; step < CP_STEPS && top > 0u; step++) {
        top -= 1u;
        let x = stack[top];
        atomicStore(&work[cp_remap_at(x)], DEAD);
        for (var side = 0u; side < 2u; side++) {
            let t = topo_out[seg.topo_base + 2u * x + side];
            if (t & LEAF_BIT) == 0u && top < CP_STACK {
                stack[top] = t;
                top += 1u;
            }
        }
    }
}

@compute @workgroup_size(256)
fn lbvh_compact_mark(@builtin(local_invocation_index) lid: u32,
                     @builtin(workgroup_id) wid: vec3<u32>,
                     @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = linear_id(lid, wid, nwg);
    seg = segs[segment_at(g)];
    if !cp_inner(g) {
        return;
    }
    let i = g - seg.key_base;
    let at = 4u * (seg.node_base + i);
    for (var e = 0u; e < 4u; e++) {
        let v = nodes[at + e];
        for (var k = 0u; k < 4u; k++) {
            atomicStore(&work[cp_copy_at(i) + 4u * e + k], v[k]);
        }
    }
    let refs = vec2<u32>(nodes[at].w, nodes[at + 1u].w);
    for (var side = 0u; side < 2u; side++) {
        let t = topo_out[seg.topo_base + 2u * i + side];
        if (refs[side] & LEAF_BIT) != 0u && (t & LEAF_BIT) == 0u {
            cp_kill(t);
        }
    }
}

@compute @workgroup_size(256)
fn lbvh_compact_count(@builtin(local_invocation_index) lid: u32,
                      @builtin(workgroup_id) wid: vec3<u32>,
                      @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = linear_id(lid, wid, nwg);
    seg = segs[segment_at(g)];
    let total = cp_workgroup_scan(lid, select(0u, 1u, cp_moves(g)));
    if lid == WG - 1u {
        compact_blocks[g / WG] = total;
    }
}

@compute @workgroup_size(256)
fn lbvh_compact_scan(@builtin(local_invocation_index) lid: u32,
                     @builtin(workgroup_id) wid: vec3<u32>,
                     @builtin(num_workgroups) nwg: vec3<u32>) {
    let k = wid.y * nwg.x + wid.x;
    let builds = arrayLength(&segs);
    let s = segs[min(k, builds - 1u)];
    if lid == 0u {
        // Blocks holding the build's inner nodes (a build starts at a multiple of WG).
        cp_blocks = select(0u, (s.count - 1u + WG - 1u) / WG, k < builds && s.count >= 2u);
    }
    let blocks = workgroupUniformLoad(&cp_blocks);
    let first = s.key_base / WG;
    // Node 0 is the root: the others are numbered from 1.
    var next = 1u;
    for (var c = 0u; c < blocks; c += WG) {
        let b = c + lid;
        var v = 0u;
        if b < blocks {
            v = compact_blocks[first + b];
        }
        let inclusive = cp_workgroup_scan(lid, v);
        if b < blocks {
            compact_blocks[first + b] = next + inclusive - v;
        }
        next += cp_scan[WG - 1u];
        // Every lane has read the total before the next chunk's scan overwrites it.
        workgroupBarrier();
    }
    if lid == 0u && k < builds {
        compact_counts[k] = next;
    }
}

@compute @workgroup_size(256)
fn lbvh_compact_assign(@builtin(local_invocation_index) lid: u32,
                       @builtin(workgroup_id) wid: vec3<u32>,
                       @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = linear_id(lid, wid, nwg);
    seg = segs[segment_at(g)];
    let moves = cp_moves(g);
    let inclusive = cp_workgroup_scan(lid, select(0u, 1u, moves));
    if moves {
        let i = g - seg.key_base;
        atomicStore(&work[cp_remap_at(i)], compact_blocks[g / WG] + inclusive - 1u);
    }
}

@compute @workgroup_size(256)
fn lbvh_compact_scatter(@builtin(local_invocation_index) lid: u32,
                        @builtin(workgroup_id) wid: vec3<u32>,
                        @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = linear_id(lid, wid, nwg);
    seg = segs[segment_at(g)];
    if !cp_inner(g) {
        return;
    }
    let i = g - seg.key_base;
    // The root keeps 0 (its remap word is 0: live, never assigned).
    let to = atomicLoad(&work[cp_remap_at(i)]);
    if to == DEAD {
        return;
    }
    var node: array<vec4<u32>, 4>;
    for (var e = 0u; e < 4u; e++) {
        for (var k = 0u; k < 4u; k++) {
            node[e][k] = atomicLoad(&work[cp_copy_at(i) + 4u * e + k]);
        }
    }
    for (var side = 0u; side < 2u; side++) {
        let r = node[side].w;
        if (r & LEAF_BIT) == 0u {
            node[side].w = atomicLoad(&work[cp_remap_at(r)]);
        }
    }
    let at = 4u * (seg.node_base + to);
    for (var e = 0u; e < 4u; e++) {
        nodes[at + e] = node[e];
    }
}
