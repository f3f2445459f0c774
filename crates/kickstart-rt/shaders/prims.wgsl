// Small per-primitive passes of the BVH builds (docs/ray-tracing-core.md): triangle AABBs,
// triangle gather into sorted order, instance world AABBs for the TLAS. Each entry point binds
// only what it uses (automatic layouts are per entry point).

struct Params {
    a: u32,     // triangle_aabbs: tri_base; gather: src_base; instance_aabbs: count
    b: u32,     // triangle_aabbs: count;    gather: order_base; instance_aabbs: flags
    c: u32,     // triangle_aabbs: aabb_base; gather: count; instance_aabbs: first bounds word
    d: u32,     // gather: dst_base
}

@group(0) @binding(0) var<uniform> params: Params;

const WG: u32 = 64u;
const EMPTY_MIN: vec4<f32> = vec4<f32>(1e30, 1e30, 1e30, 0.0);
const EMPTY_MAX: vec4<f32> = vec4<f32>(-1e30, -1e30, -1e30, 0.0);

fn linear_id(wid: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wid.y * nwg.x + wid.x) * WG + lid;
}

fn is_non_finite(v: vec3<f32>) -> bool {
    let bits = bitcast<vec3<u32>>(v);
    return any((bits & vec3<u32>(0x7f800000u)) == vec3<u32>(0x7f800000u));
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
    let out = 2u * (params.c + k);
    // Dropped triangles (flag in the second vertex's w) get the empty box; so would a non-finite
    // one, which ingestion never writes, rather than poisoning the build with NaN bounds.
    let dropped = bitcast<u32>(v1.w) == 1u;
    if dropped || is_non_finite(v0.xyz) || is_non_finite(v1.xyz) || is_non_finite(v2.xyz) {
        tri_aabbs[out] = EMPTY_MIN;
        tri_aabbs[out + 1u] = EMPTY_MAX;
        return;
    }
    tri_aabbs[out] = vec4<f32>(min(min(v0.xyz, v1.xyz), v2.xyz), 0.0);
    tri_aabbs[out + 1u] = vec4<f32>(max(max(v0.xyz, v1.xyz), v2.xyz), 0.0);
}

// ---- gather_triangles -----------------------------------------------------------------------

// Copied as u32 bits: the w fields hold integers (primitive index, dropped flag) that are
// subnormal or NaN patterns as floats.
@group(0) @binding(1) var<storage, read> gather_src: array<vec4<u32>>;
@group(0) @binding(2) var<storage, read> gather_order: array<u32>;
@group(0) @binding(3) var<storage, read_write> gather_dst: array<vec4<u32>>;

@compute @workgroup_size(64)
fn gather_triangles(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let k = linear_id(wid, nwg, lid);
    if k >= params.c {
        return;
    }
    let s = 3u * (params.a + gather_order[params.b + k]);
    let d = 3u * (params.d + k);
    gather_dst[d] = gather_src[s];
    gather_dst[d + 1u] = gather_src[s + 1u];
    gather_dst[d + 2u] = gather_src[s + 2u];
}

// ---- instance_aabbs -------------------------------------------------------------------------
// Also merges the boxes' centroid bounds (centroid_bounds.wgsl) when asked (params.b bit 0, the
// TLAS build): the LBVH then skips its own bounds pass over the boxes, a dependent dispatch
// fewer. Params: a = count, b = flags, c = first centroid-bounds word.

@group(0) @binding(1) var<storage, read> instances: array<InstanceGpu>;
@group(0) @binding(2) var<storage, read> geometries: array<GeometryGpu>;
@group(0) @binding(3) var<storage, read_write> instance_boxes: array<vec4<f32>>;
@group(0) @binding(4) var<storage, read_write> instance_centroid_bounds: array<atomic<u32>>;

// 256 rather than WG: a quarter of the device atomics on the six bounds words.
const INSTANCE_WG: u32 = 256u;
const MERGE_CENTROID_BOUNDS: u32 = 1u;

struct StoredBox {
    lo: vec4<f32>,
    hi: vec4<f32>,
}

// World box of instance slot i as the TLAS stores it (the documented empty box when hidden).
fn instance_box(i: u32) -> StoredBox {
    let inst = instances[i];
    var visible = (inst.flags & 1u) != 0u && inst.geometry < arrayLength(&geometries);
    var g: GeometryGpu;
    if visible {
        g = geometries[inst.geometry];
        // Built with triangles, and a non-empty root box (all triangles dropped leaves it empty).
        visible = (g.flags & 1u) != 0u && g.tri_count > 0u && all(g.bounds_min.xyz <= g.bounds_max.xyz);
    }
    if !visible {
        return StoredBox(EMPTY_MIN, EMPTY_MAX);
    }
    let m = inst.object_to_world;
    var lo = vec3<f32>(3.0e38);
    var hi = vec3<f32>(-3.0e38);
    for (var c = 0u; c < 8u; c++) {
        let p = vec4<f32>(
            select(g.bounds_min.x, g.bounds_max.x, (c & 1u) != 0u),
            select(g.bounds_min.y, g.bounds_max.y, (c & 2u) != 0u),
            select(g.bounds_min.z, g.bounds_max.z, (c & 4u) != 0u),
            1.0,
        );
        let q = vec3<f32>(dot(m[0], p), dot(m[1], p), dot(m[2], p));
        lo = min(lo, q);
        hi = max(hi, q);
    }
    // Rounding of the transform (≤ 3 ulp of the sum of the terms' magnitudes, on the GPU or the
    // CPU, fused or not) could shrink the box past a corner: pad by 8 ulp of that sum so the box
    // contains the exactly transformed geometry box.
    let extent = max(abs(g.bounds_min.xyz), abs(g.bounds_max.xyz));
    let mag = vec3<f32>(
        dot(abs(m[0].xyz), extent) + abs(m[0].w),
        dot(abs(m[1].xyz), extent) + abs(m[1].w),
        dot(abs(m[2].xyz), extent) + abs(m[2].w),
    );
    let pad = mag * 4.76837158203125e-7; // 2^-21
    return StoredBox(vec4<f32>(lo - pad, 0.0), vec4<f32>(hi + pad, 0.0));
}

@compute @workgroup_size(256)
fn instance_aabbs(
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let i = (wid.y * nwg.x + wid.x) * INSTANCE_WG + lid;
    wg_bounds_clear(lid);
    workgroupBarrier();
    // No early return: the barriers must be reached by the whole workgroup.
    if i < params.a {
        let b = instance_box(i);
        instance_boxes[2u * i] = b.lo;
        instance_boxes[2u * i + 1u] = b.hi;
        // From the stored values, as the LBVH's own bounds pass would read them back.
        wg_bounds_add(b.lo.xyz, b.hi.xyz);
    }
    workgroupBarrier();
    if (params.b & MERGE_CENTROID_BOUNDS) != 0u && lid < 6u {
        let v = wg_bounds_word(lid);
        if v != 0u {
            atomicMax(&instance_centroid_bounds[params.c + lid], v);
        }
    }
}
