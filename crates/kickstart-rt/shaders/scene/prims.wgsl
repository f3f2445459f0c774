// Small per-primitive passes of the BVH builds (docs/ray-tracing-core.md): triangle AABBs,
// triangle gather into sorted order, instance world AABBs for the TLAS. Each entry point binds
// only what it uses (automatic layouts are per entry point). Triangle boxes: scene/triangle_box.wgsl.

#import scene/types
#import scene/centroid_bounds
#import scene/triangle_box
#param MAX_REFS

struct Params {
    a: u32,     // triangle_aabbs: tri_base; gather: src_base; instance_aabbs: count
    b: u32,     // triangle_aabbs: count;    gather: order_base; instance_aabbs: flags
    c: u32,     // triangle_aabbs: aabb_base; gather: count; instance_aabbs: first bounds word
    d: u32,     // gather: dst_base
}

@group(0) @binding(0) var<uniform> params: Params;

const WG: u32 = 64u;

fn linear_id(wid: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wid.y * nwg.x + wid.x) * WG + lid;
}

// ---- triangle_aabbs -------------------------------------------------------------------------

@group(0) @binding(1) var<storage, read> aabb_tris: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> tri_aabbs: array<vec4<f32>>;

@compute @workgroup_size(64)
fn triangle_aabbs(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let k = linear_id(wid, nwg, lid);
    if k >= params.b {
        return;
    }
    let t = 3u * (params.a + k);
    let v0 = aabb_tris[t];
    let v1 = aabb_tris[t + 1u];
    let v2 = aabb_tris[t + 2u];
    let b = triangle_box(v0, v1, v2);
    let out = 2u * (params.c + k);
    tri_aabbs[out] = b.lo;
    tri_aabbs[out + 1u] = b.hi;
}

// ---- gather_triangles -----------------------------------------------------------------------

// Copied as u32 bits: the w fields hold integers (primitive index, dropped flag) that are
// subnormal or NaN patterns as floats.
@group(0) @binding(1) var<storage, read> gather_src: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read> gather_order: array<u32>;
@group(0) @binding(3) var<storage, read_write> gather_dst: array<vec4<u32>>;

struct GatheredTriangle {
    v0: vec4<u32>,
    v1: vec4<u32>,
    v2: vec4<u32>,
}

// Copies the triangle of sorted position k into place; returns it.
fn gather_one(k: u32) -> GatheredTriangle {
    let s = 3u * (params.a + gather_order[params.b + k]);
    let d = 3u * (params.d + k);
    let t = GatheredTriangle(gather_src[s], gather_src[s + 1u], gather_src[s + 2u]);
    gather_dst[d] = t.v0;
    gather_dst[d + 1u] = t.v1;
    gather_dst[d + 2u] = t.v2;
    return t;
}

@compute @workgroup_size(64)
fn gather_triangles(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let k = linear_id(wid, nwg, lid);
    if k < params.c {
        _ = gather_one(k);
    }
}

// ---- gather_triangles_boxes -----------------------------------------------------------------
// gather_triangles that also writes each triangle's box at its sorted position k
// (gather_boxes[2k..2k+1], as triangle_aabbs would at its primitive index): a BLAS refit's one
// pass before the climb, which then reads the boxes in order (the LBVH's sorted-boxes flag).

@group(0) @binding(4) var<storage, read_write> gather_boxes: array<vec4<f32>>;

@compute @workgroup_size(64)
fn gather_triangles_boxes(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let k = linear_id(wid, nwg, lid);
    if k >= params.c {
        return;
    }
    let t = gather_one(k);
    let b = triangle_box(bitcast<vec4<f32>>(t.v0), bitcast<vec4<f32>>(t.v1),
                         bitcast<vec4<f32>>(t.v2));
    gather_boxes[2u * k] = b.lo;
    gather_boxes[2u * k + 1u] = b.hi;
}

// ---- instance_refs -------------------------------------------------------------------------
// The TLAS's primitives are instance *refs*: params.b >> 8 = K refs per instance slot (1..32),
// ref i * K + j naming (slot i, an entry into its BLAS: an inner node index or a leaf reference).
// With K = 1 the one ref is the BLAS root (node 0) and its box is the instance's world box.
// With K > 1 the instance's BLAS is opened from the root, largest world-box area first, until K
// refs (or only leaves) remain: a big instance whose box spans much of the scene is split into
// subtrees with tighter world boxes, so rays enter fewer instances ("rebraiding", Benthin et al.
// 2017; measured faster on the H100 for the apartment's few big instances, more so with more
// refs over the clustered TLAS: docs/decisions/instance-refs.md). Unused refs
// get the empty box. Each ref's world box goes to instance_boxes[2r..2r+1] and (slot, entry,
// stamp) to the ref table in the TLAS node buffer (after its node slots: see `ref_table_base`).
// The stamp is the BLAS build's (geometry flags bits 8-31): a ref whose stamp is no longer its
// geometry's (the BLAS was rebuilt while the TLAS update was deferred) is entered at the BLAS
// root by the traversal, so stale entries never index another build's nodes.
// Also merges the boxes' centroid bounds (scene/centroid_bounds.wgsl) when asked (params.b bit 0, the
// TLAS build): the LBVH then skips its own bounds pass over the boxes, a dependent dispatch
// fewer. Params: a = instance slots, b = flags | K << 8, c = first centroid-bounds word.
// Entry points: `instance_refs` for K = 1 (an invocation an instance), `instance_refs_opened`
// for K > 1 (a workgroup an instance).

@group(0) @binding(1) var<storage, read> instances: array<InstanceGpu>;
@group(0) @binding(2) var<storage, read> geometries: array<GeometryGpu>;
@group(0) @binding(3) var<storage, read_write> instance_boxes: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> instance_centroid_bounds: array<atomic<u32>>;
@group(0) @binding(5) var<storage, read> ref_blas_nodes: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> ref_table: array<vec4<u32>>;

// 256 rather than WG: a quarter of the device atomics on the six bounds words.
const INSTANCE_WG: u32 = 256u;
const MERGE_CENTROID_BOUNDS: u32 = 1u;
// Most refs one instance is opened into, sizing the ref arrays below: src/scene/prims.rs gives
// MAX_REFS_PER_INSTANCE, which also sizes the TLAS on the CPU side.
const MAX_REFS: u32 = {{MAX_REFS}}u;
const REF_LEAF_BIT: u32 = 0x80000000u;

struct StoredBox {
    lo: vec4<f32>,
    hi: vec4<f32>,
}

// The ref table's first vec4 in a TLAS node buffer of C node slots then C table entries (5 C
// vec4 in all; scene/traversal.wgsl computes the same).
fn ref_table_base() -> u32 {
    return (arrayLength(&ref_table) / 5u) * 4u;
}

// Whether instance slot i is traced, and its geometry.
struct Traced {
    visible: bool,
    g: GeometryGpu,
}

fn traced(i: u32) -> Traced {
    let inst = instances[i];
    var t: Traced;
    t.visible = (inst.flags & 1u) != 0u && inst.geometry < arrayLength(&geometries);
    if t.visible {
        t.g = geometries[inst.geometry];
        // Built with triangles, and a non-empty root box (all triangles dropped leaves it empty).
        t.visible = (t.g.flags & 1u) != 0u && t.g.tri_count > 0u
            && all(t.g.bounds_min.xyz <= t.g.bounds_max.xyz);
    }
    return t;
}

// World box of the object-space box [bmin, bmax] under `m` (object to world), padded.
fn world_box(m: mat3x4<f32>, bmin: vec3<f32>, bmax: vec3<f32>) -> StoredBox {
    var lo = vec3<f32>(3.0e38);
    var hi = vec3<f32>(-3.0e38);
    for (var c = 0u; c < 8u; c++) {
        let p = vec4<f32>(
            select(bmin.x, bmax.x, (c & 1u) != 0u),
            select(bmin.y, bmax.y, (c & 2u) != 0u),
            select(bmin.z, bmax.z, (c & 4u) != 0u),
            1.0,
        );
        let q = vec3<f32>(dot(m[0], p), dot(m[1], p), dot(m[2], p));
        lo = min(lo, q);
        hi = max(hi, q);
    }
    // Rounding of the transform (≤ 3 ulp of the sum of the terms' magnitudes, on the GPU or the
    // CPU, fused or not) could shrink the box past a corner: pad by 8 ulp of that sum so the box
    // contains the exactly transformed object box.
    let extent = max(abs(bmin), abs(bmax));
    let mag = vec3<f32>(
        dot(abs(m[0].xyz), extent) + abs(m[0].w),
        dot(abs(m[1].xyz), extent) + abs(m[1].w),
        dot(abs(m[2].xyz), extent) + abs(m[2].w),
    );
    let pad = mag * 4.76837158203125e-7; // 2^-21
    return StoredBox(vec4<f32>(lo - pad, 0.0), vec4<f32>(hi + pad, 0.0));
}

fn box_area(b: StoredBox) -> f32 {
    let d = max(b.hi.xyz - b.lo.xyz, vec3<f32>(0.0));
    return d.x * d.y + d.y * d.z + d.z * d.x;
}

// The instance being opened by an `instance_refs_opened` workgroup: its refs so far (entry, world
// box), how many, and each step's pick. One lane per ref slot.
var<workgroup> open_entry: array<u32, MAX_REFS>;
var<workgroup> open_lo: array<vec4<f32>, MAX_REFS>;
var<workgroup> open_hi: array<vec4<f32>, MAX_REFS>;
var<workgroup> open_count: u32;
// Largest area + 1 (as bits: non-negative floats order like their bits) among the inner refs,
// 0 when there is none; then the lowest slot holding it.
var<workgroup> open_best: atomic<u32>;
var<workgroup> open_pick: atomic<u32>;
var<workgroup> open_go: u32;

fn open_put(j: u32, entry: u32, b: StoredBox) {
    open_entry[j] = entry;
    open_lo[j] = b.lo;
    open_hi[j] = b.hi;
}

// One opening step of `instance_refs_opened` (lane 0): ref `pick`, an inner node of the BLAS,
// is replaced by its non-empty children (at most two; none: the last ref takes its slot).
fn open_step(m: mat3x4<f32>, node_base: u32, pick: u32) {
    let at = 4u * (node_base + open_entry[pick]);
    let n0 = ref_blas_nodes[at];
    let n1 = ref_blas_nodes[at + 1u];
    let n2 = ref_blas_nodes[at + 2u];
    let n3 = ref_blas_nodes[at + 3u];
    var n = open_count;
    // Left child: box (n0.xyz, n1.xyz), ref n0.w; right: (n2.xyz, n3.xyz), ref n1.w. An empty
    // child (min > max) is never entered and is dropped.
    var kept = 0u;
    if all(n0.xyz <= n1.xyz) {
        open_put(pick, bitcast<u32>(n0.w), world_box(m, n0.xyz, n1.xyz));
        kept = 1u;
    }
    if all(n2.xyz <= n3.xyz) {
        open_put(select(pick, n, kept == 1u), bitcast<u32>(n1.w), world_box(m, n2.xyz, n3.xyz));
        n += kept;
        kept += 1u;
    }
    if kept == 0u {
        n -= 1u;
        open_put(pick, open_entry[n], StoredBox(open_lo[n], open_hi[n]));
    }
    open_count = n;
}

// Ref r of instance slot i: its world box and table entry; a used ref's box also joins the
// centroid bounds (from the stored values, as the LBVH's own bounds pass would read them back).
fn write_ref(r: u32, i: u32, b: StoredBox, entry: u32, stamp: u32, used: bool) {
    instance_boxes[2u * r] = b.lo;
    instance_boxes[2u * r + 1u] = b.hi;
    ref_table[ref_table_base() + r] = vec4<u32>(i, entry, stamp, 0u);
    if used {
        wg_bounds_add(b.lo.xyz, b.hi.xyz);
    }
}

// K > 1: one workgroup per instance slot, one lane per ref. The BLAS is opened from the root,
// largest world-box area first (the lowest slot among equal areas), until K refs or only leaves
// remain: each step the lanes find the largest inner ref together (two workgroup atomics), and
// one lane loads that node and puts its children in. With one invocation per instance each of
// the K - 1 dependent steps scanned every ref held so far in local memory, and each invocation
// merged all K refs' centroids into the same six workgroup words: a scene of few big instances
// (the TLAS's common case for opening) ran that long chain on a few threads.
@compute @workgroup_size(MAX_REFS)
fn instance_refs_opened(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lane: u32,
) {
    let i = wid.y * nwg.x + wid.x;
    let k = clamp(params.b >> 8u, 1u, MAX_REFS);
    wg_bounds_clear(lane);
    // Uniform: the same slot for the whole workgroup.
    if i >= params.a {
        return;
    }
    let t = traced(i);
    let m = instances[i].object_to_world;
    if lane == 0u {
        open_count = 0u;
        if t.visible {
            open_put(0u, 0u, world_box(m, t.g.bounds_min.xyz, t.g.bounds_max.xyz));
            open_count = 1u;
        }
    }
    // Bounded: a chain of one-child nodes (trees of one triangle) would not raise the count.
    for (var it = 0u; it < 4u * MAX_REFS; it++) {
        if lane == 0u {
            atomicStore(&open_best, 0u);
            atomicStore(&open_pick, MAX_REFS);
        }
        workgroupBarrier();
        var key = 0u;
        if lane < open_count && (open_entry[lane] & REF_LEAF_BIT) == 0u {
            let a = box_area(StoredBox(open_lo[lane], open_hi[lane]));
            if !is_nan(a) {
                key = bitcast<u32>(a) + 1u;
                atomicMax(&open_best, key);
            }
        }
        workgroupBarrier();
        if key != 0u && key == atomicLoad(&open_best) {
            atomicMin(&open_pick, lane);
        }
        workgroupBarrier();
        if lane == 0u {
            open_go = select(0u, 1u, open_count < k && atomicLoad(&open_pick) != MAX_REFS);
        }
        if workgroupUniformLoad(&open_go) == 0u {
            break;
        }
        if lane == 0u {
            open_step(m, t.g.node_base, atomicLoad(&open_pick));
        }
    }
    workgroupBarrier();
    let stamp = select(0u, t.g.flags >> 8u, t.visible);
    if lane < k {
        let used = lane < open_count;
        var b = StoredBox(EMPTY_MIN, EMPTY_MAX);
        var entry = 0u;
        if used {
            b = StoredBox(open_lo[lane], open_hi[lane]);
            entry = open_entry[lane];
        }
        write_ref(i * k + lane, i, b, entry, stamp, used);
    }
    workgroupBarrier();
    if (params.b & MERGE_CENTROID_BOUNDS) != 0u && lane < 6u {
        let v = wg_bounds_word(lane);
        if v != 0u {
            atomicMax(&instance_centroid_bounds[params.c + lane], v);
        }
    }
}

// K = 1: one invocation per instance slot, its one ref the BLAS root.
@compute @workgroup_size(256)
fn instance_refs(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = (wid.y * nwg.x + wid.x) * INSTANCE_WG + lid;
    wg_bounds_clear(lid);
    workgroupBarrier();
    // No early return: the barriers must be reached by the whole workgroup.
    if i < params.a {
        let t = traced(i);
        // The BLAS build the entries belong to (0 for a hidden instance: its refs are empty).
        let stamp = select(0u, t.g.flags >> 8u, t.visible);
        // The instance as a whole: its BLAS root and world box.
        var b = StoredBox(EMPTY_MIN, EMPTY_MAX);
        if t.visible {
            b = world_box(instances[i].object_to_world, t.g.bounds_min.xyz, t.g.bounds_max.xyz);
        }
        write_ref(i, i, b, 0u, stamp, t.visible);
    }
    workgroupBarrier();
    if (params.b & MERGE_CENTROID_BOUNDS) != 0u && lid < 6u {
        let v = wg_bounds_word(lid);
        if v != 0u {
            atomicMax(&instance_centroid_bounds[params.c + lid], v);
        }
    }
}
