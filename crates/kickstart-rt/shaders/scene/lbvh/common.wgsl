// Declarations every LBVH pass shares (scene/lbvh/lbvh.wgsl lists the passes): the bindings of
// group 0 (each pass binds those its entry points use), the builds' Params, the constants, boxes,
// and the writers of the node format.
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

#import scene/centroid_bounds
#import scene/triangle_box

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
// The staged (re-ingested) triangles in primitive order, and the BLAS's triangles in sorted order
// (3 vec4 each, copied as bits: the w lanes hold integers): lbvh_gather and the range refit.
// The topology a clustered climb writes (scene/lbvh/hploc.wgsl), which the compaction reads.
@group(0) @binding(9) var<storage, read_write> topo_out: array<u32>;
@group(0) @binding(12) var<storage, read> refit_src: array<vec4<u32>>;
@group(0) @binding(13) var<storage, read_write> refit_dst: array<vec4<u32>>;

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

// First topology word of the inner nodes' range ends (n >= 2).
fn range_ends_at() -> u32 {
    return seg.karras_base + 4u * seg.count - 3u;
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
