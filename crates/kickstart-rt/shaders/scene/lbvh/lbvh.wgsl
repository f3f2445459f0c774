// GPU LBVH (Karras 2012, "Maximizing Parallelism in the Construction of BVHs, Octrees, and k-d
// Trees") over primitive AABBs, and its refit. Layouts: docs/ray-tracing-core.md. Driven by
// src/scene/lbvh.rs, which documents the pass order.
//
// Entry points (all 256 invocations, 1-D workgroups split into 2-D by the Recorder):
//   lbvh_bounds    per primitive: centroid bounds of the valid primitives -> work[seg.work_base + 0..6] (not run
//                  when the caller's pass merged them: the TLAS's instance boxes)
//   lbvh_morton    per primitive: Morton key of key_bits bits, min(key_bits / 3, 10) per axis
//                  (empty: all ones, sorts last), value = index
//   (radix sort of (keys, values), key_bits bits, by the caller)
//   lbvh_hierarchy per sorted position: order[], and for inner nodes children + parents
//   lbvh_climb     per leaf: bottom-up boxes, writes the final nodes and bounds_out (build and
//                  refit share it)
//   lbvh_refit_gather, lbvh_range_refit
//                  the range refit of a BLAS (a Karras tree, one triangle a leaf) from its
//                  re-ingested triangles: every node's boxes from its leaf range, each node on
//                  its own (see the section at the end)
//
// `work` layout (u32 words, all accessed atomically):
//   [0, 6)                       centroid bounds: ~enc(min.xyz), enc(max.xyz) (atomicMax only;
//                                scene/centroid_bounds.wgsl)
//   [8, 8 + 6 (n-1))             inner node boxes during the climb (min.xyz, max.xyz bit patterns)
//   [8 + 6 (n-1), 8 + 7 (n-1))   arrival counters of the inner nodes (cleared before the climb)
//   [8 + 7 (n-1), 8 + 10 (n-1))  per inner node during the climb: SAH cost (f32 bits), primitive
//                                count | COLLAPSED_BIT, first sorted position (leaf collapsing)
//
// Topology layout (u32 words from topo_base), n >= 2:
//   [0, 2 (n-1))           children of inner node i at 2i, 2i+1: inner index, or 0x80000000 | k
//                          for the leaf at sorted position k
//   [2 (n-1), 3 (n-1))     parent ref of inner node i (0xFFFFFFFF for the root)
//   [3 (n-1), 4n - 3)      parent ref of leaf k
//   [4n - 3, 5n - 4)       the other end of inner node i's leaf range (one end is i itself):
//                          node i covers sorted positions [min(i, j), max(i, j)], its left child
//                          [.., g] and its right child [g + 1, ..], g = left child's index (a
//                          Karras tree's; a clustered tree's topology has no such section)
//   A parent ref is the parent's inner index | PARENT_LOCAL_BIT (0x40000000) when all of the
//   parent's leaves lie in one block of 256 sorted positions [256 b, 256 b + 256).

#import gpu/digit_histogram
#import scene/centroid_bounds
#import scene/triangle_box
#import scene/ingest_decode

struct Params {
    count: u32,
    aabb_base: u32,
    node_base: u32,
    order_base: u32,
    topo_base: u32,
    bounds_base: u32,
    // bit 0: leaf refs are primitive indices (order[k]) instead of sorted positions k;
    // bit 1: write the root box to bounds_out.
    flags: u32,
    // Largest leaf the climb may make by collapsing a subtree (1: every leaf holds one
    // primitive). Only with sorted-position refs: a subtree's primitives are then one range.
    max_leaf: u32,
    // Bits of the sort keys (3..=31; builds only): 31 for a BLAS, 24 for a TLAS, whose sort then
    // needs one digit pass fewer (src/scene/lbvh.rs says why).
    key_bits: u32,
    // First of the 6 centroid-bounds words lbvh_morton reads from binding 2: 0 (work's header),
    // or where the caller's pass merged them in the buffer bound there instead.
    centroid_base: u32,
    // First word of this build's region of `work` (a batch gives each build its own).
    work_base: u32,
    // First position of this build's keys and values in the sort's arrays: its primitives'
    // place in a batch (a multiple of WG), 0 for a single build.
    key_base: u32,
    // lbvh_refit_gather: first staged triangle (binding 12) and first BLAS triangle (13).
    tri_src_base: u32,
    tri_dst_base: u32,
    // lbvh_refit_ingest: rows of ingest_rows in use, and the first of its two counters.
    ingest_row_count: u32,
    ingest_counter: u32,
    // Where lbvh_hierarchy writes the Karras tree's topology (topo_base, unless the build is
    // clustered: then the builder's scratch, which hploc_climb reads).
    karras_base: u32,
    // Range refits: the refit's first box in `pyramid` (boxes above level 0, its own region in a
    // batch), and its first row in ingest_rows (lbvh_refit_ingest).
    pyramid_base: u32,
    row_base: u32,
    pad5: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
// The builds of a batch, one Params each, in increasing key_base (build passes; a single build
// is a batch of one). The range refits read theirs from refit_segs; lbvh_climb reads `params`
// only.
@group(0) @binding(18) var<storage, read> segs: array<Params>;
// The Params of the build (or refit) this invocation works on: every entry point sets it first,
// from `segs` (build passes) or `params` (refits, lbvh_climb). Its values are never used in
// control flow that reaches a barrier (a private variable is not uniform).
var<private> seg: Params;

// The build of a batch that sorted position (or primitive) `g` of the whole batch belongs to:
// the last whose key_base <= g.
fn segment_at(g: u32) -> u32 {
    var lo = 0u;
    var hi = arrayLength(&segs);
    while hi - lo > 1u {
        let mid = (lo + hi) / 2u;
        if segs[mid].key_base <= g {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    return lo;
}
@group(0) @binding(1) var<storage, read> aabbs: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> work: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> keys: array<u32>;
@group(0) @binding(4) var<storage, read_write> values: array<u32>;
@group(0) @binding(5) var<storage, read_write> order: array<u32>;
@group(0) @binding(6) var<storage, read_write> topology: array<u32>;
// Nodes and bounds are written as bit patterns (u32) so child refs stored in the `w` lanes are
// never touched by float handling (they are denormals or NaNs as f32).
@group(0) @binding(7) var<storage, read_write> nodes: array<vec4<u32>>;
@group(0) @binding(8) var<storage, read_write> bounds_out: array<vec4<u32>>;

const WG: u32 = 256u;
const FLAG_PRIMITIVE_REFS: u32 = 1u;
const FLAG_BOUNDS_OUT: u32 = 2u;
// Leaf k's box is aabbs[aabb_base + k] (already in sorted order: a BLAS refit's gather writes
// them so), not aabbs[aabb_base + order[k]]: one coalesced load instead of two dependent ones.
const FLAG_SORTED_BOXES: u32 = 4u;
// Primitive boxes come from staged triangles (3 vec4 each, from tri_src_base) bound at `aabbs`
// instead of boxes: a batch's builds read their own geometry's triangles where they lie. (The
// same binding, so the clustered climb stays within 8 storage buffers.)
const FLAG_TRIANGLE_BOXES: u32 = 8u;
const LEAF_BIT: u32 = 0x80000000u;
const NO_PARENT: u32 = 0xFFFFFFFFu;
// In a parent ref: the parent's leaves all lie in one block of WG sorted positions (one climb
// workgroup's). Indices stay below 2^28, so the bit is free.
const PARENT_LOCAL_BIT: u32 = 0x40000000u;
const PARENT_INDEX_MASK: u32 = 0x0fffffffu;
// Empty box while climbing: the largest finite floats, so a union with it is exact for every
// finite coordinate. Written out as the documented (+1e30, -1e30).
const BIG: f32 = 0x1.fffffep+127f; // the largest finite f32
const EMPTY_OUT: f32 = 1e30;
const BOXES_AT: u32 = 8u;
// SAH constants of the collapse decision: the CPU builder's (src/cpu/bvh.rs), so the GPU tree's
// SAH cost is minimised in the same terms the benchmark compares it in.
const SAH_TRAVERSAL: f32 = 1.0;
const SAH_INTERSECTION: f32 = 1.0;
// In the count word of a subtree: the subtree is cheaper as one leaf (its parent refers to it as
// a leaf of `count` primitives from `first`).
const COLLAPSED_BIT: u32 = 0x80000000u;
// In the count word of a subtree: its leaves are not one range of sorted positions, so neither it
// nor any subtree above it can become one leaf. Never set in a Karras tree (every subtree is a
// range); a clustered tree (scene/lbvh/hploc.wgsl) merges clusters that need not be neighbours.
const SCATTERED_BIT: u32 = 0x40000000u;
const COUNT_MASK: u32 = 0x0fffffffu;

fn linear_id(lid: u32, wid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return (wid.y * nwg.x + wid.x) * WG + lid;
}

struct Box {
    lo: vec3<f32>,
    hi: vec3<f32>,
}

fn empty_box() -> Box {
    return Box(vec3<f32>(BIG), vec3<f32>(-BIG));
}

fn is_empty(b: Box) -> bool {
    return b.lo.x > b.hi.x;
}

// Primitive `prim`'s box; empty (min.x > max.x, or any NaN) becomes the canonical empty box so
// it never enlarges a parent.
fn prim_box(prim: u32) -> Box {
    if (seg.flags & FLAG_TRIANGLE_BOXES) != 0u {
        let t = 3u * (seg.tri_src_base + prim);
        let b = triangle_box(aabbs[t], aabbs[t + 1u], aabbs[t + 2u]);
        return stored_box(b.lo.xyz, b.hi.xyz);
    }
    let i = 2u * (seg.aabb_base + prim);
    return stored_box(aabbs[i].xyz, aabbs[i + 1u].xyz);
}

// A box as stored (min, max), with every empty one (min.x > max.x, or any NaN) canonical.
fn stored_box(lo: vec3<f32>, hi: vec3<f32>) -> Box {
    if stored_box_is_empty(lo, hi) {
        return empty_box();
    }
    return Box(lo, hi);
}

fn union_box(a: Box, b: Box) -> Box {
    return Box(min(a.lo, b.lo), max(a.hi, b.hi));
}

fn centroid(b: Box) -> vec3<f32> {
    return box_centroid(b.lo, b.hi);
}

// ---------------------------------------------------------------------------------------------
// Scene bounds of the valid centroids (scene/centroid_bounds.wgsl): workgroup reduce in shared atomics,
// then one device atomicMax per word into work[seg.work_base + 0..6]. Skipped when the caller's primitive pass
// merged them already (the TLAS's instance boxes): lbvh_morton then reads the caller's words.

@compute @workgroup_size(256)
fn lbvh_bounds(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>,
               @builtin(num_workgroups) nwg: vec3<u32>) {
    // A block of WG positions lies in one build of a batch (builds start at multiples of WG).
    let g = linear_id(lid, wid, nwg);
    seg = segs[segment_at(g - lid)];
    let i = g - seg.key_base;
    wg_bounds_clear(lid);
    workgroupBarrier();
    // No early return: the barriers below must be reached by the whole workgroup.
    if i < seg.count {
        let b = prim_box(i);
        if !is_empty(b) {
            wg_bounds_add(b.lo, b.hi);
        }
    }
    workgroupBarrier();
    if lid < 6u {
        let v = wg_bounds_word(lid);
        if v != 0u {
            atomicMax(&work[seg.work_base + lid], v);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Morton keys.

// Spreads the low 10 bits of v to every third bit.
fn spread3(v: u32) -> u32 {
    var x = v & 0x3ffu;
    x = (x | (x << 16u)) & 0x030000ffu;
    x = (x | (x << 8u)) & 0x0300f00fu;
    x = (x | (x << 4u)) & 0x030c30c3u;
    x = (x | (x << 2u)) & 0x09249249u;
    return x;
}

// Cell 0..cells-1 of c in [lo, hi]; a zero or non-finite extent, or a non-finite c, gives cell 0
// (such primitives still get a leaf; only their place in the order is arbitrary).
fn cell(c: f32, lo: f32, hi: f32, cells: f32) -> u32 {
    let extent = hi - lo;
    let t = (c - lo) / extent * cells;
    // Finite first: only then is the comparison meaningful (NaN may be assumed away).
    if !is_finite(extent) || !(extent > 0.0) || !is_finite(t) {
        return 0u;
    }
    return u32(clamp(t, 0.0, cells - 1.0));
}

@compute @workgroup_size(256)
fn lbvh_morton(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>,
               @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = linear_id(lid, wid, nwg);
    // params.count: every position of the batch, the builds' padding included.
    if g >= params.count {
        return;
    }
    keys[g] = batch_morton_key(g);
    values[g] = g;
}

// The sort key of position g of a batch: its build's Morton key of primitive g - key_base, or
// the empty key in the padding after the build's primitives (sorted last within the build).
fn batch_morton_key(g: u32) -> u32 {
    seg = segs[segment_at(g)];
    return morton_key(g - seg.key_base);
}

// Primitive i's sort key.
fn morton_key(i: u32) -> u32 {
    // Empty primitives (and a batch's padding past the build's primitives): all ones, the
    // largest key, so they sort last.
    let empty_key = (1u << seg.key_bits) - 1u;
    if i >= seg.count {
        return empty_key;
    }
    let b = prim_box(i);
    var key = empty_key;
    if !is_empty(b) {
        // work[seg.work_base + 0..6], or the caller's words bound in its place (see lbvh_bounds).
        let cb = seg.centroid_base;
        let lo = vec3<f32>(dec(~atomicLoad(&work[seg.work_base + cb])), dec(~atomicLoad(&work[seg.work_base + cb + 1u])),
                           dec(~atomicLoad(&work[seg.work_base + cb + 2u])));
        let hi = vec3<f32>(dec(atomicLoad(&work[seg.work_base + cb + 3u])), dec(atomicLoad(&work[seg.work_base + cb + 4u])),
                           dec(atomicLoad(&work[seg.work_base + cb + 5u])));
        let c = centroid(b);
        // Exact power of two (at most 1024): the same cells as a literal would give.
        let cells = f32(1u << min(seg.key_bits / 3u, 10u));
        let morton = (spread3(cell(c.x, lo.x, hi.x, cells)) << 2u)
            | (spread3(cell(c.y, lo.y, hi.y, cells)) << 1u) | spread3(cell(c.z, lo.z, hi.z, cells));
        // Below the empty key: only when the Morton bits fill the key (24 bits: 8 per axis) can
        // they equal it, and then the far corner cell joins its neighbour, the next lower code.
        // With a spare bit (31 = 3 x 10 + 1) no code is lowered.
        key = min(morton, empty_key - 1u);
    }
    return key;
}

// lbvh_morton and the radix sort's first histogram (its digit 0: key bits 0..7) in one pass,
// for sorts of more than one block (gpu/digit_histogram: the sort's counters and
// layout), so the sort skips its first histogram dispatch (RadixSort::first_histogram).
@group(0) @binding(10) var<storage, read_write> sort_hist: array<u32>;

@compute @workgroup_size(256)
fn lbvh_morton_histogram(@builtin(local_invocation_index) lid: u32,
                         @builtin(workgroup_id) wid: vec3<u32>,
                         @builtin(num_workgroups) nwg: vec3<u32>) {
    let block = wid.y * nwg.x + wid.x;
    let nblocks = (params.count + DIGIT_BLOCK - 1u) / DIGIT_BLOCK;
    if block >= nblocks {
        return;
    }
    digit_bins_clear(lid);
    for (var j = 0u; j < DIGIT_BLOCK / WG; j++) {
        let i = block * DIGIT_BLOCK + j * WG + lid;
        if i < params.count {
            let key = batch_morton_key(i);
            keys[i] = key;
            values[i] = i;
            digit_bins_count(key & (DIGIT_VALUES - 1u), lid);
        }
    }
    sort_hist[digit_hist_at(lid, block, nblocks)] = digit_bins_total(lid);
}

// ---------------------------------------------------------------------------------------------
// A batch of builds sorts all of their keys at once: by Morton key first, then (stably) by
// build, so each build's primitives are back in its own range, in Morton order. Between the two
// sorts the keys become build indices (lbvh_segment_keys), after them Morton keys again
// (lbvh_rekey), which the hierarchy reads.

@compute @workgroup_size(256)
fn lbvh_segment_keys(@builtin(local_invocation_index) lid: u32,
                     @builtin(workgroup_id) wid: vec3<u32>,
                     @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = linear_id(lid, wid, nwg);
    if g < params.count {
        keys[g] = segment_at(values[g]);
    }
}

@compute @workgroup_size(256)
fn lbvh_rekey(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>,
              @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = linear_id(lid, wid, nwg);
    if g < params.count {
        keys[g] = batch_morton_key(values[g]);
    }
}

// The triangles of each build of a batch in its sorted order (leaf refs are sorted positions):
// BLAS triangle k of a build is its staged triangle order[k].
@compute @workgroup_size(256)
fn lbvh_gather(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>,
               @builtin(num_workgroups) nwg: vec3<u32>) {
    let g = linear_id(lid, wid, nwg);
    seg = segs[segment_at(g)];
    let k = g - seg.key_base;
    if g >= params.count || k >= seg.count {
        return;
    }
    let s = 3u * (seg.tri_src_base + order[seg.order_base + k]);
    let d = 3u * (seg.tri_dst_base + k);
    refit_dst[d] = refit_src[s];
    refit_dst[d + 1u] = refit_src[s + 1u];
    refit_dst[d + 2u] = refit_src[s + 2u];
}

// ---------------------------------------------------------------------------------------------
// Hierarchy (Karras 2012, section 4): inner node i covers a key range starting or ending at i.

// Length of the common prefix of sorted keys i and j, or -1 when j is outside [0, n). Equal keys
// fall back to the indices (32 + clz(i ^ j)), so duplicates still give a valid binary tree.
fn delta(i: i32, j: i32) -> i32 {
    let n = i32(seg.count);
    if j < 0 || j >= n {
        return -1;
    }
    let a = keys[seg.key_base + u32(i)];
    let b = keys[seg.key_base + u32(j)];
    if a == b {
        return 32 + i32(countLeadingZeros(u32(i) ^ u32(j)));
    }
    return i32(countLeadingZeros(a ^ b));
}

@compute @workgroup_size(256)
fn lbvh_hierarchy(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>,
                  @builtin(num_workgroups) nwg: vec3<u32>) {
    let pos = linear_id(lid, wid, nwg);
    seg = segs[segment_at(pos)];
    let k = pos - seg.key_base;
    let n = seg.count;
    if k >= n {
        return;
    }
    // One primitive is never sorted (no keys were made): its order is the identity. Sorted
    // values are positions of the batch: the build's own start taken off.
    order[seg.order_base + k] = select(values[pos] - seg.key_base, k, n < 2u);
    if k + 1u >= n {
        return; // n - 1 inner nodes
    }
    let i = i32(k);
    // The Karras tree goes to karras_base (topo_base unless the build is clustered).
    let inner_parents = seg.karras_base + 2u * (n - 1u);
    let leaf_parents = seg.karras_base + 3u * (n - 1u);
    if k == 0u {
        topology[inner_parents] = NO_PARENT;
    }
    // Direction of the range: towards the neighbour sharing the longer prefix.
    let d = select(-1, 1, delta(i, i + 1) - delta(i, i - 1) > 0);
    let delta_min = delta(i, i - d);
    // Upper bound of the range length, then binary search for the other end.
    var l_max = 2;
    while delta(i, i + l_max * d) > delta_min {
        l_max *= 2;
    }
    var l = 0;
    var t = l_max / 2;
    while t >= 1 {
        if delta(i, i + (l + t) * d) > delta_min {
            l += t;
        }
        t /= 2;
    }
    let j = i + l * d;
    // Split: the last position sharing more than the node's prefix with i.
    let delta_node = delta(i, j);
    var s = 0;
    var div = 2;
    t = (l + div - 1) / div;
    loop {
        if delta(i, i + (s + t) * d) > delta_node {
            s += t;
        }
        if t <= 1 {
            break;
        }
        div *= 2;
        t = (l + div - 1) / div;
    }
    let gamma = i + s * d + min(d, 0);
    let first = u32(min(i, j));
    let last = u32(max(i, j));
    let g = u32(gamma);
    var left = g;
    var right = g + 1u;
    // The children's parent ref says whether this node's leaves all lie in one climb
    // workgroup's block: the climb then joins it in workgroup memory (see lbvh_climb).
    let ref_k = k | select(0u, PARENT_LOCAL_BIT, first / WG == last / WG);
    if first == g {
        left = LEAF_BIT | g;
        topology[leaf_parents + g] = ref_k;
    } else {
        topology[inner_parents + g] = ref_k;
    }
    if last == g + 1u {
        right = LEAF_BIT | (g + 1u);
        topology[leaf_parents + g + 1u] = ref_k;
    } else {
        topology[inner_parents + g + 1u] = ref_k;
    }
    topology[seg.karras_base + 2u * k] = left;
    topology[seg.karras_base + 2u * k + 1u] = right;
    topology[range_ends_at() + k] = u32(j);
}

// First topology word of the inner nodes' range ends (n >= 2).
fn range_ends_at() -> u32 {
    return seg.karras_base + 4u * seg.count - 3u;
}

// ---------------------------------------------------------------------------------------------
// Bottom-up boxes (build and refit), one invocation per leaf.
//
// WGSL promises no forward progress between workgroups and only relaxed atomics, so nothing here
// waits on another invocation. Each invocation climbs from its leaf; at every inner node the
// FIRST to arrive stops and the SECOND continues with the union of both children. The second
// must see the first's box, hence:
//   1. boxes live in `work` and are written/read with atomicStore/atomicLoad (device-coherent);
//   2. write box -> storageBarrier() -> atomicAdd(arrival) -> storageBarrier() -> read sibling.
//      storageBarrier() is an OpControlBarrier with Device memory scope and AcquireRelease |
//      UniformMemory semantics: the first one is a release fence before the arrival increment,
//      the second an acquire fence after it, so when the second arriver's atomicAdd reads the
//      first's increment, the first's box stores happen-before the second's loads.
// storageBarrier() is also a workgroup control barrier, so it must be reached in
// workgroup-uniform control flow: the climb is a loop whose trip count is uniform (it runs while
// ANY invocation of the workgroup is still climbing, read through workgroupUniformLoad), and
// each invocation carries its own `climbing` flag. Inactive invocations just pass the barriers.

var<workgroup> wg_active: atomic<u32>;
var<workgroup> wg_go: u32;

// Whether `flag` is set in any invocation of the workgroup: the same answer in all of them, so
// the climb's loops keep a uniform trip count. Every invocation must call it (it has barriers).
fn wg_any(flag: bool, lid: u32) -> bool {
    if lid == 0u {
        atomicStore(&wg_active, 0u);
    }
    workgroupBarrier();
    if flag {
        atomicAdd(&wg_active, 1u);
    }
    workgroupBarrier();
    if lid == 0u {
        wg_go = atomicLoad(&wg_active);
    }
    return workgroupUniformLoad(&wg_go) != 0u;
}

// The child ref as written into a node: inner index as is; leaf k -> k or order[k].
fn out_ref(c: u32) -> u32 {
    if (c & LEAF_BIT) == 0u || (seg.flags & FLAG_PRIMITIVE_REFS) == 0u {
        return c;
    }
    return LEAF_BIT | order[seg.order_base + (c & 0x7fffffffu)];
}

// Box lanes as stored in nodes/bounds_out: the documented (+1e30, -1e30) when empty.
fn out_lo(b: Box) -> vec3<u32> {
    return bitcast<vec3<u32>>(select(b.lo, vec3<f32>(EMPTY_OUT), is_empty(b)));
}

fn out_hi(b: Box) -> vec3<u32> {
    return bitcast<vec3<u32>>(select(b.hi, vec3<f32>(-EMPTY_OUT), is_empty(b)));
}

fn write_node(node: u32, l: Box, lref: u32, r: Box, rref: u32) {
    let at = 4u * (seg.node_base + node);
    nodes[at] = vec4<u32>(out_lo(l), lref);
    nodes[at + 1u] = vec4<u32>(out_hi(l), rref);
    nodes[at + 2u] = vec4<u32>(out_lo(r), 0u);
    nodes[at + 3u] = vec4<u32>(out_hi(r), 0u);
}

fn write_bounds(b: Box) {
    if (seg.flags & FLAG_BOUNDS_OUT) != 0u {
        bounds_out[seg.bounds_base] = vec4<u32>(out_lo(b), 0u);
        bounds_out[seg.bounds_base + 1u] = vec4<u32>(out_hi(b), 0u);
    }
}

fn leaf_box(k: u32) -> Box {
    if (seg.flags & FLAG_SORTED_BOXES) != 0u {
        return prim_box(k);
    }
    return prim_box(order[seg.order_base + k]);
}

fn store_box(node: u32, b: Box) {
    let at = BOXES_AT + 6u * node;
    atomicStore(&work[seg.work_base + at], bitcast<u32>(b.lo.x));
    atomicStore(&work[seg.work_base + at + 1u], bitcast<u32>(b.lo.y));
    atomicStore(&work[seg.work_base + at + 2u], bitcast<u32>(b.lo.z));
    atomicStore(&work[seg.work_base + at + 3u], bitcast<u32>(b.hi.x));
    atomicStore(&work[seg.work_base + at + 4u], bitcast<u32>(b.hi.y));
    atomicStore(&work[seg.work_base + at + 5u], bitcast<u32>(b.hi.z));
}

fn load_box(node: u32) -> Box {
    let at = BOXES_AT + 6u * node;
    return Box(
        vec3<f32>(bitcast<f32>(atomicLoad(&work[seg.work_base + at])), bitcast<f32>(atomicLoad(&work[seg.work_base + at + 1u])),
                  bitcast<f32>(atomicLoad(&work[seg.work_base + at + 2u]))),
        vec3<f32>(bitcast<f32>(atomicLoad(&work[seg.work_base + at + 3u])),
                  bitcast<f32>(atomicLoad(&work[seg.work_base + at + 4u])),
                  bitcast<f32>(atomicLoad(&work[seg.work_base + at + 5u]))));
}

// Summary of child ref c whose box is `b`: a leaf's is computed, an inner node's was published
// by its climber (with its box, under the same release/acquire protocol).
fn child_subtree(c: u32, b: Box) -> Subtree {
    // Without collapsing no summary was published (and none is needed: nothing collapses).
    if (c & LEAF_BIT) != 0u || !collapsing() {
        return leaf_subtree(c & 0x7fffffffu, b);
    }
    return load_subtree(c);
}

// Box of child ref c (topology encoding): leaves from the input, inner nodes from `work`.
fn child_box(c: u32) -> Box {
    if (c & LEAF_BIT) != 0u {
        return leaf_box(c & 0x7fffffffu);
    }
    return load_box(c);
}

// SAH summary of a subtree: its cost (area-weighted, not normalised), primitive count and first
// sorted position, whether it is cheaper as a single leaf, and whether its leaves are the sorted
// positions [first, first + count) (only then can it be one leaf).
struct Subtree {
    cost: f32,
    count: u32,
    first: u32,
    collapsed: bool,
    contiguous: bool,
}

// The count word of a summary as stored: count and the two flags.
fn subtree_word(s: Subtree) -> u32 {
    return s.count | select(0u, COLLAPSED_BIT, s.collapsed) | select(SCATTERED_BIT, 0u, s.contiguous);
}

fn subtree_from(cost: u32, word: u32, first: u32) -> Subtree {
    return Subtree(bitcast<f32>(cost), word & COUNT_MASK, first, (word & COLLAPSED_BIT) != 0u,
                   (word & SCATTERED_BIT) == 0u);
}

// Surface area, 0 for an empty box, capped at BIG so sums of costs stay comparable (a non-finite
// value may be assumed away by the compiler).
fn area(b: Box) -> f32 {
    let d = max(b.hi - b.lo, vec3<f32>(0.0));
    return min(2.0 * (d.x * d.y + d.y * d.z + d.z * d.x), BIG);
}

fn leaf_subtree(k: u32, b: Box) -> Subtree {
    return Subtree(area(b) * SAH_INTERSECTION, 1u, k, false, true);
}

// The optimal cost of an inner node over children `l` and `r` (box `b`): split, or one leaf when
// collapsing is on, the leaf fits and it is no more expensive.
fn join_subtrees(b: Box, l: Subtree, r: Subtree) -> Subtree {
    let a = area(b);
    let count = l.count + r.count;
    let split = min(a * SAH_TRAVERSAL + l.cost + r.cost, BIG);
    let as_leaf = min(a * f32(count) * SAH_INTERSECTION, BIG);
    let contiguous = l.contiguous && r.contiguous
        && (l.first + l.count == r.first || r.first + r.count == l.first);
    let collapse = collapsing() && contiguous && count <= seg.max_leaf && as_leaf <= split;
    return Subtree(select(split, as_leaf, collapse), count, min(l.first, r.first), collapse,
                   contiguous);
}

// Whether this dispatch may collapse subtrees (uniform). Builds and refits that may not skip the
// summaries' stores and loads, which would otherwise add 3 words per inner node to the climb's
// device traffic for nothing.
fn collapsing() -> bool {
    return (seg.flags & FLAG_PRIMITIVE_REFS) == 0u && seg.max_leaf > 1u;
}

fn subtree_at(node: u32) -> u32 {
    let n = seg.count;
    return BOXES_AT + 7u * (n - 1u) + 3u * node;
}

fn store_subtree(node: u32, s: Subtree) {
    let at = subtree_at(node);
    atomicStore(&work[seg.work_base + at], bitcast<u32>(s.cost));
    atomicStore(&work[seg.work_base + at + 1u], subtree_word(s));
    atomicStore(&work[seg.work_base + at + 2u], s.first);
}

fn load_subtree(node: u32) -> Subtree {
    let at = subtree_at(node);
    return subtree_from(atomicLoad(&work[seg.work_base + at]), atomicLoad(&work[seg.work_base + at + 1u]),
                        atomicLoad(&work[seg.work_base + at + 2u]));
}

// The ref a node stores for child `c` (topology encoding) with summary `s`: a collapsed inner
// child becomes a leaf of its whole range (count - 1 in bits 28..30).
fn child_ref(c: u32, s: Subtree) -> u32 {
    if (c & LEAF_BIT) == 0u && s.collapsed {
        return LEAF_BIT | ((s.count - 1u) << 28u) | s.first;
    }
    return out_ref(c);
}

// Parent ref (index | PARENT_LOCAL_BIT) of a node in topology encoding (n >= 2).
fn parent_ref(node: u32) -> u32 {
    let n = seg.count;
    if (node & LEAF_BIT) != 0u {
        return topology[seg.topo_base + 3u * (n - 1u) + (node & 0x7fffffffu)];
    }
    return topology[seg.topo_base + 2u * (n - 1u) + node];
}

// One invocation's climb: its current node (topology encoding: leaf bit + sorted position, or
// inner index), that subtree's box and SAH summary, and the node's parent ref (meaningful while
// climbing: the root is never the current node then).
struct Climber {
    node: u32,
    bx: Box,
    sub: Subtree,
    pref: u32,
    climbing: bool,
}

// The sibling of the climber's node under a parent whose children are `lc`, `rc`.
fn sibling(c: Climber, lc: u32, rc: u32) -> u32 {
    return select(lc, rc, lc == c.node);
}

// The second arriver at `parent` (children `lc`, `rc`, parent ref `up`) joins its subtree with
// the sibling's (box `sb`, summary `ss`), writes the parent's node and moves up to it, or stops
// at the root. Every phase of the climb ends a step this way; they differ in where the sibling
// and the topology come from.
fn climb_up(c: ptr<function, Climber>, parent: u32, lc: u32, rc: u32, sb: Box, ss: Subtree,
            up: u32) {
    var lb = sb;
    var ls = ss;
    var rb = (*c).bx;
    var rs = (*c).sub;
    if lc == (*c).node {
        lb = (*c).bx;
        ls = (*c).sub;
        rb = sb;
        rs = ss;
    }
    write_node(parent, lb, child_ref(lc, ls), rb, child_ref(rc, rs));
    (*c).bx = union_box(lb, rb);
    (*c).sub = join_subtrees((*c).bx, ls, rs);
    (*c).node = parent;
    if parent == 0u {
        write_bounds((*c).bx);
        (*c).climbing = false;
    } else {
        (*c).pref = up;
    }
}

// Phase 1 of the climb: per block-local inner node (slot = index - block start, < WG, since a
// Karras node's index is one end of its leaf range), its box (6 words) and SAH summary
// (3 words), and its arrival counter.
var<workgroup> wg_boxes: array<f32, 1536>;
var<workgroup> wg_subtrees: array<u32, 768>;
var<workgroup> wg_arrival: array<atomic<u32>, 256>;

fn wg_store(slot: u32, b: Box, s: Subtree) {
    let at = 6u * slot;
    wg_boxes[at] = b.lo.x;
    wg_boxes[at + 1u] = b.lo.y;
    wg_boxes[at + 2u] = b.lo.z;
    wg_boxes[at + 3u] = b.hi.x;
    wg_boxes[at + 4u] = b.hi.y;
    wg_boxes[at + 5u] = b.hi.z;
    if collapsing() {
        wg_subtrees[3u * slot] = bitcast<u32>(s.cost);
        wg_subtrees[3u * slot + 1u] = subtree_word(s);
        wg_subtrees[3u * slot + 2u] = s.first;
    }
}

// Box of child ref c of a block-local node: a leaf's from the input, an inner node's from
// workgroup memory.
fn wg_child_box(c: u32, block: u32) -> Box {
    if (c & LEAF_BIT) != 0u {
        return leaf_box(c & 0x7fffffffu);
    }
    let at = 6u * (c - block);
    return Box(vec3<f32>(wg_boxes[at], wg_boxes[at + 1u], wg_boxes[at + 2u]),
               vec3<f32>(wg_boxes[at + 3u], wg_boxes[at + 4u], wg_boxes[at + 5u]));
}

fn wg_child_subtree(c: u32, b: Box, block: u32) -> Subtree {
    if (c & LEAF_BIT) != 0u || !collapsing() {
        return leaf_subtree(c & 0x7fffffffu, b);
    }
    let at = 3u * (c - block);
    return subtree_from(wg_subtrees[at], wg_subtrees[at + 1u], wg_subtrees[at + 2u]);
}

@compute @workgroup_size(256)
fn lbvh_climb(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>,
              @builtin(num_workgroups) nwg: vec3<u32>) {
    seg = params;
    let n = params.count;
    let k = linear_id(lid, wid, nwg);
    // Fewer than two primitives: no inner nodes. (`n` is uniform, so this return keeps the rest
    // in uniform control flow.)
    if n < 2u {
        write_tiny_root(k);
        return;
    }
    var c = leaf_climber(k);

    // Phase 1, in workgroup memory: the nodes whose leaves all lie in this workgroup's block
    // (PARENT_LOCAL_BIT) have both children's climbers here, so their arrivals and boxes need
    // only workgroup barriers, not the device-scope fences of phase 2. Most inner nodes are
    // such nodes; a node straddling a block boundary is the exception (a node of s leaves
    // straddles one with probability about s / WG).
    let block = k - lid;
    atomicStore(&wg_arrival[lid], 0u);
    loop {
        let local = c.climbing && (c.pref & PARENT_LOCAL_BIT) != 0u;
        // Its first barrier also orders the arrival counters' clearing before their first use.
        if !wg_any(local, lid) {
            break;
        }
        let parent = c.pref & PARENT_INDEX_MASK;
        if local {
            if (c.node & LEAF_BIT) == 0u {
                wg_store(c.node - block, c.bx, c.sub);
            }
            // First to arrive: the sibling's climber (in this workgroup) takes over.
            c.climbing = atomicAdd(&wg_arrival[parent - block], 1u) != 0u;
        }
        // The first arriver's stores above happen-before the second's loads below, whichever
        // round the second arrives in.
        workgroupBarrier();
        if local && c.climbing {
            let lc = topology[seg.topo_base + 2u * parent];
            let rc = topology[seg.topo_base + 2u * parent + 1u];
            let sib = sibling(c, lc, rc);
            let sb = wg_child_box(sib, block);
            climb_up(&c, parent, lc, rc, sb, wg_child_subtree(sib, sb, block),
                     parent_ref(parent));
        }
    }

    climb_across(&c, lid);
}

// The whole BVH of fewer than two primitives: one invocation writes the fixed-shape root.
fn write_tiny_root(k: u32) {
    let n = seg.count;
    if k == 0u {
        let none = empty_box();
        var l = none;
        var lref = LEAF_BIT;
        if n == 1u {
            l = leaf_box(0u);
            lref = out_ref(LEAF_BIT);
        }
        write_node(0u, l, lref, none, LEAF_BIT);
        write_bounds(l);
    }
}

// The climber of leaf k (not climbing when k is past the primitives).
fn leaf_climber(k: u32) -> Climber {
    var c: Climber;
    c.climbing = k < seg.count;
    c.node = LEAF_BIT | k;
    c.bx = empty_box();
    c.pref = NO_PARENT;
    if c.climbing {
        c.bx = leaf_box(k);
        c.pref = parent_ref(c.node);
    }
    c.sub = leaf_subtree(k, c.bx);
    return c;
}

// The climb's device-scope phase: every climber left has a parent that straddles blocks (and so
// has every ancestor of it), or the topology has no block structure at all (a clustered tree's
// refit). Every invocation of the workgroup must call it (it has barriers).
fn climb_across(c: ptr<function, Climber>, lid: u32) {
    let arrival_at = BOXES_AT + 6u * (seg.count - 1u);
    loop {
        // Uniform trip count: continue while anyone in the workgroup is still climbing.
        if !wg_any((*c).climbing, lid) {
            break;
        }

        let parent = (*c).pref & PARENT_INDEX_MASK;
        // The parent's topology does not depend on who arrives second: loaded before the
        // fences, its latency overlaps theirs instead of following them.
        var lc = 0u;
        var rc = 0u;
        var up = NO_PARENT;
        if (*c).climbing {
            lc = topology[seg.topo_base + 2u * parent];
            rc = topology[seg.topo_base + 2u * parent + 1u];
            up = parent_ref(parent);
        }
        if (*c).climbing && ((*c).node & LEAF_BIT) == 0u {
            // Inner boxes are published for the sibling's climber (leaves are re-read from the
            // input instead).
            store_box((*c).node, (*c).bx);
            if collapsing() {
                store_subtree((*c).node, (*c).sub);
            }
        }
        // Release: the box above before the arrival below.
        storageBarrier();
        if (*c).climbing {
            let before = atomicAdd(&work[seg.work_base + arrival_at + parent], 1u);
            // First to arrive: the sibling's box may not exist yet; its climber takes over.
            (*c).climbing = before != 0u;
        }
        // Acquire: the sibling's box (stored before its arrival) is visible below.
        storageBarrier();
        if (*c).climbing {
            let sib = sibling(*c, lc, rc);
            let sb = child_box(sib);
            climb_up(c, parent, lc, rc, sb, child_subtree(sib, sb), up);
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Range refit of a BLAS: the refit of a Karras tree (one triangle a leaf, sorted-position refs)
// from its re-ingested triangles, without the climb (docs/ray-tracing-core.md, "Refit").
//
// Every inner node of a Karras tree covers one range of sorted positions (the other end than
// its own index is in the topology), and the box of any range is the union of at most two boxes
// per level of the *box pyramid* over the sorted leaf boxes: level 0 is the n leaf boxes, level
// L >= 1 holds ceil(n / 2^L) boxes, box i of it the union of boxes 2i and 2i + 1 of level L - 1
// (only 2i at the end of an odd level). Levels 1..=REFIT_WG_LEVELS follow each other in `pyramid`
// (two vec4 a box: min, max; level 0 is never stored), the levels above are in `work`;
// src/scene/lbvh.rs sizes `pyramid` by the same sum (`pyramid_boxes` less level 0). So each
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
// The staged (re-ingested) triangles in primitive order, and the BLAS's triangles in sorted order
// (3 vec4 each, copied as bits: the w lanes hold integers).
@group(0) @binding(12) var<storage, read> refit_src: array<vec4<u32>>;
@group(0) @binding(13) var<storage, read_write> refit_dst: array<vec4<u32>>;

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
