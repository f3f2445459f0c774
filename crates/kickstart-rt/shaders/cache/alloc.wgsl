// Direct lighting cache allocation of one instance, on the GPU (src/cache/alloc.rs):
// `insert` finds the vertices and edges shared by position (hash tables keyed by position bits),
// `count` gives each unique vertex, edge and face its local samples, `allocate` (one invocation)
// places the instance in the surfel pool (full, else coarse, else none) and writes its header,
// `write` writes the per-triangle records and fills the new surfels with the initial colour.

struct AllocParams {
    // Object-to-world rows of the instance.
    row0: vec4<f32>,
    row1: vec4<f32>,
    row2: vec4<f32>,
    initial: vec4<f32>,
    // Triangles, first triangle slot of the geometry in the triangle pool.
    tri_count: u32,
    tri_base: u32,
    // Word index of the triangle records in the meta buffer; header word index.
    records: u32,
    header: u32,
    // Hash table size (power of two).
    hash_size: u32,
    // 1: MeshColors.
    mesh_colors: u32,
    resolution_limit: u32,
    force_direct: u32,
    unit_length: f32,
    direct_threshold: f32,
    // Index of this allocation in the task's log.
    log_index: u32,
    pad: u32,
}

@group(0) @binding(0) var<storage, read> triangles: array<vec4<f32>>;
@group(0) @binding(1) var<storage, read_write> meta_words: array<u32>;
@group(0) @binding(2) var<storage, read_write> surfels: array<vec4<f32>>;
@group(0) @binding(3) var<storage, read_write> scratch: array<atomic<u32>>;
@group(0) @binding(4) var<storage, read_write> state: array<u32>;
@group(0) @binding(5) var<uniform> params: AllocParams;

// Scratch layout (words): counters, then per-corner arrays, per-triangle faces, hash tables.
const S_VCOUNT: u32 = 0u;
const S_ECOUNT: u32 = 1u;
const S_HEAD: u32 = 4u;
fn s_vowner(c: u32) -> u32 { return S_HEAD + c; }
fn s_eowner(c: u32) -> u32 { return S_HEAD + 3u * params.tri_count + c; }
fn s_vlocal(c: u32) -> u32 { return S_HEAD + 6u * params.tri_count + c; }
fn s_elocal(c: u32) -> u32 { return S_HEAD + 9u * params.tri_count + c; }
fn s_flocal(j: u32) -> u32 { return S_HEAD + 12u * params.tri_count + j; }
fn s_vhash(h: u32) -> u32 { return S_HEAD + 13u * params.tri_count + h; }
fn s_ehash(h: u32) -> u32 { return S_HEAD + 13u * params.tri_count + params.hash_size + h; }

// State layout (words): top, capacity, free block count, pad, 64 free blocks (start, len), then
// the log: 4 words per allocation (base, count, level, full count).
const ST_TOP: u32 = 0u;
const ST_CAPACITY: u32 = 1u;
const ST_FREE_COUNT: u32 = 2u;
const ST_FREE: u32 = 4u;
const ST_MAX_FREE: u32 = 64u;
const ST_LOG: u32 = 132u;

fn linear_id(wid: vec3<u32>, nwg: vec3<u32>, lid: u32) -> u32 {
    return (wid.y * nwg.x + wid.x) * 64u + lid;
}

fn corner_pos(c: u32) -> vec3<f32> {
    return triangles[params.tri_base * 3u + c].xyz;
}

// Position bits with -0 folded into +0, so equal positions have equal keys.
fn pos_bits(p: vec3<f32>) -> vec3<u32> {
    var b = bitcast<vec3<u32>>(p);
    b = select(b, vec3<u32>(0u), b == vec3<u32>(0x80000000u));
    return b;
}

fn hash_u32(x: u32) -> u32 {
    let state = x * 747796405u + 2891336453u;
    let word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

fn hash_pos(b: vec3<u32>) -> u32 {
    return hash_u32(b.x ^ hash_u32(b.y ^ hash_u32(b.z)));
}

fn next_corner(c: u32) -> u32 {
    return c - c % 3u + (c % 3u + 1u) % 3u;
}

// Lexicographic order of position bits: the canonical direction of an edge runs from the lesser
// endpoint to the greater.
fn bits_less(a: vec3<u32>, b: vec3<u32>) -> bool {
    if a.x != b.x { return a.x < b.x; }
    if a.y != b.y { return a.y < b.y; }
    return a.z < b.z;
}

fn same(a: vec3<u32>, b: vec3<u32>) -> bool {
    return all(a == b);
}

fn world(p: vec3<f32>) -> vec3<f32> {
    let q = vec4<f32>(p, 1.0);
    return vec3<f32>(dot(params.row0, q), dot(params.row1, q), dot(params.row2, q));
}

// The owner corner of the vertex at corner c (the first corner with its position to claim it).
fn insert_vertex(c: u32) -> u32 {
    let key = pos_bits(corner_pos(c));
    let mask = params.hash_size - 1u;
    var h = hash_pos(key) & mask;
    for (var probe = 0u; probe < params.hash_size * 2u; probe++) {
        let r = atomicCompareExchangeWeak(&scratch[s_vhash(h)], 0u, c + 1u);
        if r.exchanged {
            return c;
        }
        if r.old_value == 0u {
            continue; // spurious failure: retry the same slot
        }
        let other = r.old_value - 1u;
        if same(pos_bits(corner_pos(other)), key) {
            return other;
        }
        h = (h + 1u) & mask;
    }
    return c;
}

// The owner corner of the edge from corner c to the next corner (unordered endpoints).
fn insert_edge(c: u32) -> u32 {
    let a = pos_bits(corner_pos(c));
    let b = pos_bits(corner_pos(next_corner(c)));
    var lo = a;
    var hi = b;
    if bits_less(b, a) {
        lo = b;
        hi = a;
    }
    let mask = params.hash_size - 1u;
    var h = hash_u32(hash_pos(lo) ^ (hash_pos(hi) * 0x9e3779b9u)) & mask;
    for (var probe = 0u; probe < params.hash_size * 2u; probe++) {
        let r = atomicCompareExchangeWeak(&scratch[s_ehash(h)], 0u, c + 1u);
        if r.exchanged {
            return c;
        }
        if r.old_value == 0u {
            continue;
        }
        let other = r.old_value - 1u;
        let oa = pos_bits(corner_pos(other));
        let ob = pos_bits(corner_pos(next_corner(other)));
        if (same(oa, lo) && same(ob, hi)) || (same(oa, hi) && same(ob, lo)) {
            return other;
        }
        h = (h + 1u) & mask;
    }
    return c;
}

// Tiles along a world length (both layouts): ceil(length / tile_unit_length) in
// 1..=tile_resolution_limit.
fn tiles_along(len: f32) -> u32 {
    let n = ceil(len / params.unit_length);
    if !(n >= 1.0) {
        return 1u;
    }
    return u32(min(n, f32(params.resolution_limit)));
}

// log2 of a MeshColors edge resolution: tiles_along rounded up to a power of two, at most the
// largest power of two ≤ tile_resolution_limit.
fn mc_edge_log2(c: u32) -> u32 {
    if params.force_direct != 0u {
        return 0u;
    }
    let a = corner_pos(c);
    let b = corner_pos(next_corner(c));
    // Canonical order, so both triangles of the edge compute the same length.
    var lo = a;
    var hi = b;
    if bits_less(pos_bits(b), pos_bits(a)) {
        lo = b;
        hi = a;
    }
    let n = tiles_along(length(world(hi) - world(lo)));
    let max_log = firstLeadingBit(max(params.resolution_limit, 1u));
    let l = firstLeadingBit(n);
    var log2 = l;
    if (1u << l) < n {
        log2 = l + 1u;
    }
    return min(log2, max_log);
}

fn mc_face_log2(j: u32) -> u32 {
    return max(mc_edge_log2(3u * j), max(mc_edge_log2(3u * j + 1u), mc_edge_log2(3u * j + 2u)));
}

// Tiles per edge of a WarpedBarycentricStorage triangle: 1 (direct mapping) when forced or when
// its area is below direct_tile_mapping_threshold tiles, else tiles_along(longest edge).
fn wb_resolution(j: u32) -> u32 {
    if params.force_direct != 0u {
        return 1u;
    }
    let a = world(corner_pos(3u * j));
    let b = world(corner_pos(3u * j + 1u));
    let c = world(corner_pos(3u * j + 2u));
    let area = 0.5 * length(cross(b - a, c - a));
    let unit2 = params.unit_length * params.unit_length;
    if !(area >= params.direct_threshold * unit2) {
        return 1u;
    }
    let longest = max(length(b - a), max(length(c - b), length(a - c)));
    return tiles_along(longest);
}

@compute @workgroup_size(64)
fn insert(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
          @builtin(local_invocation_index) lid: u32) {
    let c = linear_id(wid, nwg, lid);
    if c >= 3u * params.tri_count {
        return;
    }
    if params.mesh_colors != 0u {
        atomicStore(&scratch[s_vowner(c)], insert_vertex(c));
        atomicStore(&scratch[s_eowner(c)], insert_edge(c));
    }
}

@compute @workgroup_size(64)
fn count(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    let c = linear_id(wid, nwg, lid);
    if c >= 3u * params.tri_count {
        return;
    }
    let j = c / 3u;
    if params.mesh_colors == 0u {
        if c % 3u == 0u {
            let n = wb_resolution(j);
            atomicStore(&scratch[s_flocal(j)], atomicAdd(&scratch[S_ECOUNT], n * n));
        }
        return;
    }
    if atomicLoad(&scratch[s_vowner(c)]) == c {
        atomicStore(&scratch[s_vlocal(c)], atomicAdd(&scratch[S_VCOUNT], 1u));
    }
    if atomicLoad(&scratch[s_eowner(c)]) == c {
        let e = 1u << mc_edge_log2(c);
        if e > 1u {
            atomicStore(&scratch[s_elocal(c)], atomicAdd(&scratch[S_ECOUNT], e - 1u));
        }
    }
    if c % 3u == 0u {
        let r = 1u << mc_face_log2(j);
        let inner = ((r - 1u) * (r - 2u)) / 2u;
        if r > 2u {
            atomicStore(&scratch[s_flocal(j)], atomicAdd(&scratch[S_ECOUNT], inner));
        }
    }
}

// First fit in the free blocks the CPU handed over, else the pool's top; CACHE_NO_SURFEL when
// neither has room.
fn take(n: u32) -> u32 {
    let blocks = min(state[ST_FREE_COUNT], ST_MAX_FREE);
    for (var b = 0u; b < blocks; b++) {
        let start = state[ST_FREE + 2u * b];
        let len = state[ST_FREE + 2u * b + 1u];
        if len >= n {
            state[ST_FREE + 2u * b] = start + n;
            state[ST_FREE + 2u * b + 1u] = len - n;
            return start;
        }
    }
    let top = state[ST_TOP];
    if n <= state[ST_CAPACITY] && top <= state[ST_CAPACITY] - n {
        state[ST_TOP] = top + n;
        return top;
    }
    return 0xffffffffu;
}

@compute @workgroup_size(1)
fn allocate() {
    let vcount = atomicLoad(&scratch[S_VCOUNT]);
    let ecount = atomicLoad(&scratch[S_ECOUNT]);
    var full = ecount;
    var coarse = params.tri_count;
    if params.mesh_colors != 0u {
        full = vcount + ecount;
        coarse = vcount;
    }
    var level = 0u;
    var n = full;
    var base = take(full);
    if base == 0xffffffffu {
        level = 1u;
        n = coarse;
        base = take(coarse);
    }
    if base == 0xffffffffu {
        level = 2u;
        n = 0u;
        base = 0u;
    }
    var flags = 0u;
    if level < 2u {
        flags = 1u;
    }
    if params.mesh_colors != 0u {
        flags |= 2u;
    }
    if level == 1u {
        flags |= 4u;
    }
    let o = params.header;
    meta_words[o] = params.records;
    meta_words[o + 1u] = params.tri_count;
    meta_words[o + 2u] = flags;
    meta_words[o + 3u] = base;
    meta_words[o + 4u] = vcount;
    meta_words[o + 5u] = bitcast<u32>(params.initial.x);
    meta_words[o + 6u] = bitcast<u32>(params.initial.y);
    meta_words[o + 7u] = bitcast<u32>(params.initial.z);
    let l = ST_LOG + 4u * params.log_index;
    state[l] = base;
    state[l + 1u] = n;
    state[l + 2u] = level;
    state[l + 3u] = full;
}

fn fill(s: u32) {
    surfels[s] = vec4<f32>(params.initial.xyz, 0.0);
}

@compute @workgroup_size(64)
fn write(@builtin(workgroup_id) wid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>,
         @builtin(local_invocation_index) lid: u32) {
    let j = linear_id(wid, nwg, lid);
    if j >= params.tri_count {
        return;
    }
    let o = params.header;
    let flags = meta_words[o + 2u];
    let base = meta_words[o + 3u];
    let vcount = meta_words[o + 4u];
    let prim = bitcast<u32>(triangles[(params.tri_base + j) * 3u].w);
    if prim >= params.tri_count {
        return;
    }
    let rec = params.records + prim * 8u;
    let valid = (flags & 1u) != 0u;
    let coarse = (flags & 4u) != 0u;
    if params.mesh_colors == 0u {
        let n = wb_resolution(j);
        let local = atomicLoad(&scratch[s_flocal(j)]);
        meta_words[rec] = local;
        meta_words[rec + 1u] = n;
        for (var k = 2u; k < 8u; k++) {
            meta_words[rec + k] = 0u;
        }
        if valid {
            if coarse {
                fill(base + prim);
            } else {
                for (var t = 0u; t < n * n; t++) {
                    fill(base + local + t);
                }
            }
        }
        return;
    }
    let flog = mc_face_log2(j);
    var packed = flog;
    for (var k = 0u; k < 3u; k++) {
        let c = 3u * j + k;
        let vo = atomicLoad(&scratch[s_vowner(c)]);
        let vl = atomicLoad(&scratch[s_vlocal(vo)]);
        meta_words[rec + k] = vl;
        let eo = atomicLoad(&scratch[s_eowner(c)]);
        let elog = mc_edge_log2(c);
        let e = 1u << elog;
        var el = 0u;
        if e > 1u {
            el = atomicLoad(&scratch[s_elocal(eo)]);
        }
        meta_words[rec + 3u + k] = el;
        packed |= elog << (4u + 4u * k);
        let a = pos_bits(corner_pos(c));
        let b = pos_bits(corner_pos(next_corner(c)));
        if bits_less(b, a) {
            packed |= 1u << (16u + k);
        }
        if valid && vo == c {
            fill(base + vl);
        }
        if valid && !coarse && eo == c {
            for (var t = 1u; t < e; t++) {
                fill(base + vcount + el + t - 1u);
            }
        }
    }
    let r = 1u << flog;
    var fl = 0u;
    if r > 2u {
        fl = atomicLoad(&scratch[s_flocal(j)]);
        if valid && !coarse {
            for (var t = 0u; t < ((r - 1u) * (r - 2u)) / 2u; t++) {
                fill(base + vcount + fl + t);
            }
        }
    }
    meta_words[rec + 6u] = fl;
    meta_words[rec + 7u] = packed;
}
